@ EXTI0 on PC0 (falling edge) and EXTI12 on PB12 (rising edge, EXTI15_10); the thread
@ sleeps. RAM: 0x04 EXTI0 count, 0x08 EXTI15_10 count, 0x0C PR seen by EXTI15_10.
.include "common.inc"
.equ SYSCFG_EXTICR1, 0x40013808
.equ SYSCFG_EXTICR4, 0x40013814
.equ EXTI_IMR, 0x40013C00
.equ EXTI_RTSR, 0x40013C08
.equ EXTI_FTSR, 0x40013C0C
.equ EXTI_PR, 0x40013C14
  vectors_start
  vector 16 + 6, exti0_handler
  vector 16 + 40, exti15_10_handler
  code_start

.thumb_func
reset:
  poke SYSCFG_EXTICR1, 2       @ line 0 ← port C
  poke SYSCFG_EXTICR4, 1       @ line 12 ← port B
  poke EXTI_FTSR, 1
  poke EXTI_RTSR, 1 << 12
  poke EXTI_IMR, 1 | (1 << 12)
  poke NVIC_ISER0, 1 << 6      @ EXTI0
  poke NVIC_ISER1, 1 << 8      @ EXTI15_10 (IRQ 40)
loop:
  wfi
  b loop

.thumb_func
exti0_handler:
  poke EXTI_PR, 1
  bump 0x04
  bx lr

.thumb_func
exti15_10_handler:
  load32 r0, EXTI_PR
  put 0x0C, r0
  poke EXTI_PR, 1 << 12
  bump 0x08
  bx lr
  .ltorg
