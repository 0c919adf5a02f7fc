@ TIM6 update interrupt at 10 kHz: APB1 at HCLK/4 (timer clock 2 × PCLK1 = 90 MHz at
@ 180 MHz), PSC 8, ARR 999. The handler records CNT on entry and clears UIF; the thread
@ sleeps. RAM: 0x04 count, 0x44.. CNT on entries 1..16.
.include "common.inc"
.equ RCC_CFGR, 0x40023808
.equ TIM6, 0x40001000
  vectors_start
  vector 16 + 54, tim6_handler
  code_start

.thumb_func
reset:
  poke RCC_CFGR, (5 << 10) | (4 << 13)  @ PPRE1 /4, PPRE2 /2
  poke TIM6 + 0x28, 8          @ PSC
  poke TIM6 + 0x2C, 999        @ ARR
  poke TIM6 + 0x14, 1          @ UG: load PSC
  poke TIM6 + 0x10, 0          @ clear UIF
  poke TIM6 + 0x0C, 1          @ UIE
  poke NVIC_ISER1, 1 << 22     @ IRQ 54
  poke TIM6, 1                 @ CEN
loop:
  wfi
  b loop

.thumb_func
tim6_handler:
  load32 r0, TIM6 + 0x24
  ldr r3, =RAM + 4
  ldr r2, [r3]
  adds r2, #1
  str r2, [r3]
  cmp r2, #16
  bhi 1f
  ldr r1, =RAM + 0x40
  str r0, [r1, r2, lsl #2]
1:
  poke TIM6 + 0x10, 0          @ clear UIF
  bx lr
  .ltorg
