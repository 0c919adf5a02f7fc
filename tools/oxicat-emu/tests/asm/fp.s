@ FP context across an interrupt: IRQ0 first with no FP context (basic frame, EXC_RETURN
@ 0xFFFFFFF9), then with S0/S15/FPSCR live in the thread (extended frame, 0xFFFFFFE9);
@ the handler overwrites S0, S15 and FPSCR, the thread must get its values back.
@ RAM: 0x00 done, 0x04 handler count, 0x08/0x0C LR in the handler (1st, 2nd),
@ 0x10 S0, 0x14 S15, 0x18 FPSCR after, 0x1C CONTROL after, 0x20 CONTROL in the handler.
.include "common.inc"
  vectors_start
  vector 16, irq0_handler
  code_start

.thumb_func
reset:
  poke CPACR, 0xF << 20        @ CP10, CP11 full access
  dsb
  isb
  poke NVIC_ISER0, 1
  poke NVIC_ISPR0, 1
  isb
  ldr r0, =0x3FC00000          @ 1.5
  vmov s0, r0
  ldr r0, =0x40490FDB          @ pi
  vmov s15, r0
  ldr r0, =0x03000000          @ DN | FZ
  vmsr fpscr, r0
  poke NVIC_ISPR0, 1
  isb
  vmov r4, s0
  vmov r5, s15
  vmrs r6, fpscr
  put 0x10, r4
  put 0x14, r5
  put 0x18, r6
  mrs r0, control
  put 0x1C, r0
  movs r0, #1
  put 0x00, r0
done:
  b done

.thumb_func
irq0_handler:
  mrs r0, control
  put 0x20, r0
  ldr r0, =RAM + 4
  ldr r1, [r0]
  adds r1, #1
  str r1, [r0]
  str lr, [r0, r1, lsl #2]
  ldr r0, =0xC0000000          @ -2.0
  vmov s0, r0
  vmov s15, r0
  vadd.f32 s0, s0, s15
  movs r0, #0
  vmsr fpscr, r0
  bx lr
  .ltorg
