@ A floating-point instruction with CPACR left at its reset value (CP10/CP11 off): a
@ UsageFault (NOCP) on the Cortex-M4.
.include "common.inc"
  vectors_start
  code_start

.thumb_func
reset:
  movs r0, #1
  vmov s0, r0
  movs r0, #1
  put 0x00, r0
done:
  b done
  .ltorg
