@ SVC → SVCall, which pends PendSV (same priority: it waits and tail-chains after SVCall);
@ the interrupted thread's caller-saved registers and flags survive both.
@ RAM: 0x00 done, 0x04 SVCall count, 0x08 PendSV count, 0x0C VECTACTIVE in SVCall,
@ 0x10 VECTACTIVE in PendSV, 0x14 SP in SVCall, 0x18 SP in PendSV, 0x1C LR in SVCall,
@ 0x20 ICSR in PendSV, 0x24.. thread r0 r1 r2 r3 r12 APSR after the SVC,
@ 0x3C PendSV count seen by the thread right after the SVC, 0x40 SVC count at PendSV.
.include "common.inc"
  vectors_start
  vector 11, svc_handler
  vector 14, pendsv_handler
  code_start

.thumb_func
reset:
  movs r0, #0x11
  movs r1, #0x22
  movs r2, #0x33
  movs r3, #0x44
  movw r12, #0x5555
  movs r4, #0
  cmp r4, #0          @ Z and C set
  svc #7
  mrs r4, apsr
  mov r5, r12
  put 0x24, r0
  put 0x28, r1
  put 0x2C, r2
  put 0x30, r3
  put 0x34, r5
  put 0x38, r4
  load32 r0, RAM + 0x08
  put 0x3C, r0
  movs r0, #1
  put 0x00, r0
done:
  b done

.thumb_func
svc_handler:
  mov r0, sp
  put 0x14, r0
  put 0x1C, lr
  load32 r0, ICSR
  ubfx r0, r0, #0, #9
  put 0x0C, r0
  bump 0x04
  poke ICSR, 0x10000000  @ PENDSVSET
  movs r0, #0
  movs r1, #0
  movs r2, #0
  movs r3, #0
  mov r12, r0
  cmp r0, #5          @ N set, Z and C clear
  bx lr

.thumb_func
pendsv_handler:
  mov r0, sp
  put 0x18, r0
  load32 r0, ICSR
  put 0x20, r0
  ubfx r0, r0, #0, #9
  put 0x10, r0
  load32 r0, RAM + 0x04
  put 0x40, r0
  bump 0x08
  bx lr
  .ltorg
