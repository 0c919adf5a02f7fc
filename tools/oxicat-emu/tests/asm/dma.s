@ DMA1 stream 2 channel 5 on TIM3's update request feeds TIM3 CCR2 (PWM mode 1, preload)
@ from an 8-entry half-word table in flash; its transfer-complete interrupt records TIM3's
@ update count (counted by its UIF interrupt) and the
@ stream's NDTR and EN. APB1 at HCLK/4: TIM3 at 90 MHz, PSC 0, ARR 89 (1 µs periods).
@ RAM: 0x04 TC interrupts, 0x08 updates at TC, 0x0C NDTR at TC, 0x10 CR at TC,
@ 0x14 LISR at TC, 0x18 TIM3 updates so far.
.include "common.inc"
.equ RCC_CFGR, 0x40023808
.equ TIM3, 0x40000400
.equ DMA1, 0x40026000
.equ S2CR, DMA1 + 0x10 + 0x18 * 2
  vectors_start
  vector 16 + 13, dma_handler
  vector 16 + 29, tim3_handler
  code_start

.thumb_func
reset:
  poke RCC_CFGR, (5 << 10) | (4 << 13)  @ PPRE1 /4, PPRE2 /2
  poke TIM3 + 0x28, 0          @ PSC
  poke TIM3 + 0x2C, 89         @ ARR
  poke TIM3 + 0x18, (6 << 12) | (1 << 11)  @ CH2 PWM mode 1, preload
  poke TIM3 + 0x20, 1 << 4     @ CC2E
  poke TIM3 + 0x14, 1          @ UG
  poke TIM3 + 0x10, 0
  poke TIM3 + 0x0C, (1 << 8) | 1  @ UDE, UIE
  poke S2CR + 4, 8             @ NDTR
  poke S2CR + 8, TIM3 + 0x38   @ PAR: CCR2
  ldr r0, =S2CR + 12
  adr r1, table
  str r1, [r0]                 @ M0AR
  @ CHSEL 5, MSIZE = PSIZE = 16 bit, MINC, memory to peripheral, TCIE
  poke S2CR, (5 << 25) | (1 << 13) | (1 << 11) | (1 << 10) | (1 << 6) | (1 << 4)
  poke S2CR, (5 << 25) | (1 << 13) | (1 << 11) | (1 << 10) | (1 << 6) | (1 << 4) | 1
  poke NVIC_ISER0, (1 << 13) | (1 << 29)
  poke TIM3, 1                 @ CEN
loop:
  wfi
  b loop

.thumb_func
tim3_handler:
  bump 0x18
  poke TIM3 + 0x10, 0
  bx lr

.thumb_func
dma_handler:
  bump 0x04
  load32 r0, RAM + 0x18
  put 0x08, r0
  load32 r0, S2CR + 4
  put 0x0C, r0
  load32 r0, S2CR
  put 0x10, r0
  load32 r0, DMA1
  put 0x14, r0
  poke DMA1 + 0x08, 0x3D << 16  @ clear stream 2's flags
  bx lr
  .ltorg
  .align 2
table:
  .hword 10, 20, 30, 40, 50, 60, 70, 0
