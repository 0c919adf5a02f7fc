@ Priorities: IRQ0 at 0x80 pends IRQ1 at 0x40, which preempts it (nested); BASEPRI 0x80
@ holds IRQ0 back until it is cleared; PRIMASK holds IRQ1 back until `cpsie i`.
@ RAM: 0x00 done, 0x04 log length, 0x08.. log (one word per event),
@ 0x60 IRQ1 count, 0x64.. IABR0 seen by IRQ1 on each entry, 0x80.. ICSR seen by IRQ1.
.include "common.inc"
  vectors_start
  vector 16, irq0_handler
  vector 17, irq1_handler
  code_start

.macro log code
  ldr r3, =RAM + 4
  ldr r2, [r3]
  adds r2, #1
  str r2, [r3]
  add r3, r3, r2, lsl #2
  movs r2, #\code
  str r2, [r3]
.endm

.thumb_func
reset:
  poke NVIC_IPR0, 0x00004080   @ IRQ0 0x80, IRQ1 0x40
  poke NVIC_ISER0, 3
  poke NVIC_ISPR0, 1           @ IRQ0 now: logs 10 20 11
  isb
  log 0x01
  movs r0, #0x80
  msr basepri, r0
  poke NVIC_ISPR0, 1           @ held back by BASEPRI
  isb
  log 0x02
  movs r0, #0
  msr basepri, r0              @ IRQ0 now: 10 20 11
  isb
  log 0x03
  cpsid i
  poke STIR, 1                 @ held back by PRIMASK
  isb
  log 0x04
  cpsie i                      @ IRQ1 now: 20
  isb
  log 0x05
  movs r0, #1
  put 0x00, r0
done:
  b done

.thumb_func
irq0_handler:
  push {lr}
  log 0x10
  poke STIR, 1
  isb
  log 0x11
  pop {pc}

.thumb_func
irq1_handler:
  log 0x20
  ldr r3, =RAM + 0x60
  ldr r2, [r3]
  adds r2, #1
  str r2, [r3]
  load32 r0, NVIC_IABR0
  ldr r1, =RAM + 0x60
  str r0, [r1, r2, lsl #2]
  load32 r0, ICSR
  ldr r1, =RAM + 0x7C
  str r0, [r1, r2, lsl #2]
  bx lr
  .ltorg
