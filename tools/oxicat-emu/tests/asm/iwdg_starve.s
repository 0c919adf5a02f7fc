@ The IWDG started and starved: PR /4, RLR 79 (80 ticks × 4 / 32 kHz LSI = 10 ms), the
@ updates waited out on SR, started, reloaded once (so the count runs from RLR, not from
@ start's 0xFFF), then a tight loop that never feeds. Every boot counts itself (SRAM keeps
@ its contents through the reset) and keeps RCC_CSR before and after RMVF; the second boot
@ leaves the IWDG stopped and sleeps. RAM: 0x00 done (second boot), 0x04 boots,
@ 0x08 + 4n RCC_CSR at boot n, 0x10 + 4n after RMVF, 0x20 fed (the reload was written).
.include "common.inc"
.equ IWDG_KR, 0x40003000
.equ IWDG_PR, 0x40003004
.equ IWDG_RLR, 0x40003008
.equ IWDG_SR, 0x4000300C
.equ RCC_CSR, 0x40023874
  vectors_start
  code_start

.thumb_func
reset:
  ldr r3, =RAM + 4
  ldr r4, [r3]                 @ n: boots before this one
  adds r2, r4, #1
  str r2, [r3]
  load32 r0, RCC_CSR
  ldr r1, =RAM + 0x08
  str r0, [r1, r4, lsl #2]
  poke RCC_CSR, 1 << 24        @ RMVF
  load32 r0, RCC_CSR
  ldr r1, =RAM + 0x10
  str r0, [r1, r4, lsl #2]
  cmp r4, #0
  bne second
  poke IWDG_KR, 0x5555         @ unlock PR, RLR
  poke IWDG_PR, 0              @ /4
  poke IWDG_RLR, 79
1:
  load32 r0, IWDG_SR           @ PVU, RVU: the writes reach the LSI domain
  cmp r0, #0
  bne 1b
  poke IWDG_KR, 0xCCCC         @ start (from 0xFFF)
  poke IWDG_KR, 0xAAAA         @ reload from RLR
  movs r0, #1
  put 0x20, r0
starve:
  b starve
second:
  movs r0, #1
  put 0x00, r0
2:
  wfi
  b 2b
  .ltorg
