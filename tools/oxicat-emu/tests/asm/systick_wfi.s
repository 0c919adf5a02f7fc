@ SysTick every 1,000 cycles with TICKINT; the thread sleeps in WFI until ten ticks.
@ RAM: 0x00 done, 0x04 ticks.
.include "common.inc"
  vectors_start
  vector 15, systick_handler
  code_start

.thumb_func
reset:
  poke SYST_RVR, 999
  poke SYST_CSR, 7             @ ENABLE | TICKINT | CLKSOURCE = processor clock
loop:
  wfi
  load32 r0, RAM + 4
  cmp r0, #10
  blt loop
  movs r0, #1
  put 0x00, r0
  poke SYST_CSR, 0
done:
  wfi
  b done

.thumb_func
systick_handler:
  bump 0x04
  bx lr
  .ltorg
