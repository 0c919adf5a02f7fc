@ The IWDG of iwdg_starve.s (10 ms) fed: SysTick every 1 ms (180,000 cycles) reloads it
@ in its handler and counts; the thread sleeps. RAM: 0x04 boots, 0x08 SysTick ticks.
.include "common.inc"
.equ IWDG_KR, 0x40003000
.equ IWDG_PR, 0x40003004
.equ IWDG_RLR, 0x40003008
  vectors_start
  vector 15, systick_handler
  code_start

.thumb_func
reset:
  bump 0x04
  poke IWDG_KR, 0x5555
  poke IWDG_PR, 0
  poke IWDG_RLR, 79
  poke IWDG_KR, 0xCCCC
  poke SYST_RVR, 179999
  poke SYST_CSR, 7             @ ENABLE | TICKINT | processor clock
loop:
  wfi
  b loop

.thumb_func
systick_handler:
  poke IWDG_KR, 0xAAAA
  bump 0x08
  bx lr
  .ltorg
