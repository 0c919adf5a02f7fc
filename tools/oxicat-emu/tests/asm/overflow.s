@ Unbounded recursion: a function that pushes a frame and calls itself, until the main
@ stack runs off the bottom of SRAM. The board reports a stack overflow with the PC.
.include "common.inc"
  vectors_start
  code_start

.thumb_func
reset:
  movs r0, #0
  bl recurse
done:
  b done

.thumb_func
recurse:
  push {r4-r7, lr}
  adds r0, #1
  put 0x00, r0
  bl recurse
  pop {r4-r7, pc}
  .ltorg
