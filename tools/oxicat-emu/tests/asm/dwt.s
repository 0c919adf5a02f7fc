@ DWT CYCCNT: still without TRCENA, then counting a loop of 1,000 two-instruction passes.
@ RAM: 0x00 done, 0x04 CYCCNT at reset, 0x08 after a loop with CYCCNTENA only,
@ 0x0C and 0x10 around a loop with TRCENA.
.include "common.inc"
  vectors_start
  code_start

.thumb_func
reset:
  load32 r4, DWT_CYCCNT
  poke DWT_CTRL, 1             @ CYCCNTENA
  movw r0, #1000
1:
  subs r0, #1
  bne 1b
  load32 r5, DWT_CYCCNT
  poke DEMCR, 1 << 24          @ TRCENA
  load32 r6, DWT_CYCCNT
  movw r0, #1000
2:
  subs r0, #1
  bne 2b
  load32 r7, DWT_CYCCNT
  put 0x04, r4
  put 0x08, r5
  put 0x0C, r6
  put 0x10, r7
  movs r0, #1
  put 0x00, r0
done:
  b done
  .ltorg
