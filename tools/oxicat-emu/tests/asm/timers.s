@ TIM1 CH1 PWM (20 kHz at 180 MHz, 25 %), TIM2 and TIM3 in encoder mode (SMS = 3),
@ TIM4 CH1 input capture from TI1 with its interrupt.
@ RAM: 0x00 set-up done, 0x04 TIM2 CNT, 0x08 TIM3 CNT (copied continually),
@ 0x0C CCR1 read by the TIM4 handler, 0x10 TIM4 handler count, 0x14 SR after the read.
.include "common.inc"
.equ TIM1, 0x40010000
.equ TIM2, 0x40000000
.equ TIM3, 0x40000400
.equ TIM4, 0x40000800
  vectors_start
  vector 16 + 30, tim4_handler
  code_start

.thumb_func
reset:
  poke TIM1 + 0x2C, 8999       @ ARR
  poke TIM1 + 0x34, 2250       @ CCR1
  poke TIM1 + 0x18, 0x60       @ CCMR1: OC1M = PWM mode 1
  poke TIM1 + 0x20, 1          @ CCER: CC1E
  poke TIM1 + 0x44, 0x8000     @ BDTR: MOE
  poke TIM1, 1                 @ CEN
  poke TIM2 + 0x08, 3          @ SMCR: encoder mode 3
  poke TIM2 + 0x2C, 0xFFFFFFFF
  poke TIM2, 1
  poke TIM3 + 0x08, 3
  poke TIM3 + 0x2C, 999
  poke TIM3, 1
  poke TIM4 + 0x18, 1          @ CCMR1: CC1S = 01 (IC1 ← TI1)
  poke TIM4 + 0x20, 1          @ CCER: CC1E
  poke TIM4 + 0x0C, 2          @ DIER: CC1IE
  poke NVIC_ISER0, 1 << 30     @ IRQ 30
  poke TIM4, 1
  movs r0, #1
  put 0x00, r0
loop:
  load32 r0, TIM2 + 0x24
  put 0x04, r0
  load32 r0, TIM3 + 0x24
  put 0x08, r0
  b loop

.thumb_func
tim4_handler:
  load32 r0, TIM4 + 0x34       @ CCR1 (clears CC1IF)
  put 0x0C, r0
  load32 r0, TIM4 + 0x10
  put 0x14, r0
  bump 0x10
  bx lr
  .ltorg
