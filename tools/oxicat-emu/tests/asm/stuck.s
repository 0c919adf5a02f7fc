@ A firmware that talks to its LAN9252 once and then hangs: one indirect ESC register read
@ (CSR_CMD = busy | read | 2 bytes | 0x0130, AL status) over SPI1, then a tight loop with
@ no further PDI access. The ESC's PDI watchdog (0x0410) expires and a master sees it in
@ the DL status (0x0110 bit 1 cleared) and the PDI watchdog counter (0x0443).
.include "common.inc"

.equ GPIOB_ODR, 0x40020414
.equ SPI1_CR1, 0x40013000
.equ SPI1_DR, 0x4001300C

@ Clocks one byte out of SPI1 (the board model moves it at once).
.macro spi byte
  movs r5, #\byte
  str r5, [r4]
.endm

  vectors_start
  code_start

.thumb_func
reset:
  ldr r0, =GPIOB_ODR
  movs r1, #0x40          @ CS (PB6) high
  str r1, [r0]
  ldr r2, =SPI1_CR1
  ldr r3, =0x034C         @ SSM | SSI | SPE | BR = PCLK2/4 | MSTR
  str r3, [r2]
  ldr r4, =SPI1_DR
  movs r1, #0             @ CS low: WRITE 0x0304 (CSR_CMD) = 0xC0020130
  str r1, [r0]
  spi 0x02
  spi 0x03
  spi 0x04
  spi 0x30
  spi 0x01
  spi 0x02
  spi 0xC0
  movs r1, #0x40          @ CS high
  str r1, [r0]
  movs r1, #1
  put 0x00, r1            @ the access is done
stuck:
  b stuck
  .ltorg
