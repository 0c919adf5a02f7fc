@ ADC1's injected group started by TIM1_TRGO = OC4REF (the CiA402 joint image's scheme):
@ TIM1 centre-aligned mode 1, ARR 4500 at 180 MHz (20 kHz), CH4 PWM mode 2 at CCR4 4332
@ (OC4REF rises counting up through 4332), CR2.MMS = 111. ADC1: ADCCLK = PCLK2 (90 MHz)
@ / 4, IN10 and IN11 at 15 cycles (JL = 1), JEXTSEL 0001 (TIM1_TRGO) on rising edges,
@ JEOCIE. The ADC handler records TIM1's CNT and CR1 (DIR) on entry, JDR1 and JDR2, and
@ clears JEOC; the thread sleeps.
@ RAM: 0x04 count, 0x08 CNT on entry, 0x0C CR1 on entry, 0x10 JDR1, 0x14 JDR2,
@ 0x18 SR after the clear.
.include "common.inc"
.equ RCC_CFGR, 0x40023808
.equ TIM1, 0x40010000
.equ ADC1, 0x40012000
.equ ADC_CCR, 0x40012304
  vectors_start
  vector 16 + 18, adc_handler
  code_start

.thumb_func
reset:
  poke RCC_CFGR, (5 << 10) | (4 << 13)  @ PPRE1 /4, PPRE2 /2
  poke ADC_CCR, 1 << 16        @ ADCPRE: PCLK2 / 4
  poke ADC1 + 0x04, (1 << 8) | (1 << 7)  @ CR1: SCAN, JEOCIE
  poke ADC1 + 0x0C, 1 | (1 << 3)  @ SMPR1: SMP10, SMP11 = 15 cycles
  poke ADC1 + 0x38, (10 << 10) | (11 << 15) | (1 << 20)  @ JSQR: JL 1, JSQ3 10, JSQ4 11
  poke ADC1 + 0x08, 1 | (1 << 16) | (1 << 20)  @ CR2: ADON, JEXTSEL TIM1_TRGO, JEXTEN rising
  poke TIM1 + 0x2C, 4500       @ ARR
  poke TIM1 + 0x1C, (7 << 12) | (1 << 11)  @ CCMR2: OC4M PWM 2, OC4PE
  poke TIM1 + 0x40, 4332       @ CCR4
  poke TIM1 + 0x04, 7 << 4     @ CR2: MMS = OC4REF
  poke TIM1 + 0x14, 1          @ UG
  poke NVIC_ISER0, 1 << 18     @ IRQ 18
  poke TIM1, 1 | (1 << 5)      @ CEN, CMS centre-aligned 1
loop:
  wfi
  b loop

.thumb_func
adc_handler:
  load32 r0, TIM1 + 0x24
  put 0x08, r0
  load32 r0, TIM1
  put 0x0C, r0
  load32 r0, ADC1 + 0x3C
  put 0x10, r0
  load32 r0, ADC1 + 0x40
  put 0x14, r0
  bump 0x04
  ldr r0, =ADC1
  mvn r1, #4                   @ SR: rc_w0, clear JEOC only
  str r1, [r0]
  ldr r1, [r0]
  put 0x18, r1
  bx lr
  .ltorg
