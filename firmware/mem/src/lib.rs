//! The memory functions of oxicat's Cortex-M board images, small: `memcpy`, `memmove`,
//! `memset`, `memcmp` / `bcmp` and their ARM EABI forms (`__aeabi_memcpy{,4,8}`,
//! `__aeabi_memmove{,4,8}`, `__aeabi_memset{,4,8}`, `__aeabi_memclr{,4,8}`), 178 B of Thumb-2
//! in all.
//!
//! The compiler calls these for slice copies, `fill` and array moves. `compiler_builtins`
//! defines them too, as weak symbols, tuned for speed: its `memcpy` alone is 730 B (it
//! copies misaligned buffers word by word with shifts), and each of `__aeabi_memcpy4`,
//! `__aeabi_memcpy8`, `__aeabi_memclr`, `__aeabi_memclr4`, `__aeabi_memclr8` is its own
//! 156-208 B copy: 1.2-1.6 KB of an image's flash. The strong definitions here replace
//! them at link time (issue 18 item 7; root README, Firmware footprint).
//!
//! What they do: a copy or fill moves whole words from the destination's first word
//! boundary on when source and destination are equally aligned (a fill always is), bytes
//! otherwise; `memmove` copies backwards, a byte at a time, only when the destination
//! overlaps the source from above; `memcmp` compares bytes and returns the difference of
//! the first pair that differs. The stack's copies are a mailbox frame at most (128-256
//! B): the byte loop of a copy between differently aligned buffers takes 4 cycles a byte
//! on a Cortex-M4.
//!
//! An image links them by naming the crate (`use oxicat_fw_mem as _;`); the board images
//! get them through `oxicat-board-support`.

#![no_std]
#![deny(unsafe_code)]

// The one unsafe item: functions in assembly, which the compiler cannot check. They touch
// only the memory their arguments name, as the C contract of each says.
#[cfg(target_arch = "arm")]
#[allow(unsafe_code)]
mod asm {
    core::arch::global_asm!(
        r#"
    .syntax unified
    .thumb
    .section .text.oxicat_fw_mem,"ax",%progbits
    .p2align 1

    .global memcpy, __aeabi_memcpy, __aeabi_memcpy4, __aeabi_memcpy8
    .global memmove, __aeabi_memmove, __aeabi_memmove4, __aeabi_memmove8
    .global memset, __aeabi_memset, __aeabi_memset4, __aeabi_memset8
    .global __aeabi_memclr, __aeabi_memclr4, __aeabi_memclr8
    .global memcmp, bcmp
    .type memcpy, %function
    .type __aeabi_memcpy, %function
    .type __aeabi_memcpy4, %function
    .type __aeabi_memcpy8, %function
    .type memmove, %function
    .type __aeabi_memmove, %function
    .type __aeabi_memmove4, %function
    .type __aeabi_memmove8, %function
    .type memset, %function
    .type __aeabi_memset, %function
    .type __aeabi_memset4, %function
    .type __aeabi_memset8, %function
    .type __aeabi_memclr, %function
    .type __aeabi_memclr4, %function
    .type __aeabi_memclr8, %function
    .type memcmp, %function
    .type bcmp, %function

    @ memcpy(dst r0, src r1, n r2) -> dst; __aeabi_memcpy: the same, no result.
    .thumb_func
memcpy:
    .thumb_func
__aeabi_memcpy:
    eor     r3, r0, r1
    lsls    r3, r3, #30             @ dst and src equally aligned: Z
    mov     r12, r0
    bne     .Lcpy_bytes
.Lcpy_head:                         @ bytes up to dst's next word boundary
    lsls.w  r3, r12, #30
    beq     .Lcpy_words
    subs    r2, #1
    blo     .Lret
    ldrb    r3, [r1], #1
    strb    r3, [r12], #1
    b       .Lcpy_head
    @ __aeabi_memcpy4/8: dst and src word-aligned.
    .thumb_func
__aeabi_memcpy4:
    .thumb_func
__aeabi_memcpy8:
    mov     r12, r0
.Lcpy_words:
    subs    r2, #4
    blo     .Lcpy_words_end         @ fewer than 4 left
    ldr     r3, [r1], #4
    str     r3, [r12], #4
    b       .Lcpy_words
.Lcpy_words_end:
    adds    r2, #4
.Lcpy_bytes:
    subs    r2, #1
    blo     .Lret
    ldrb    r3, [r1], #1
    strb    r3, [r12], #1
    b       .Lcpy_bytes
.Lret:
    bx      lr

    @ memmove(dst r0, src r1, n r2) -> dst: forwards (memcpy) unless dst lies in
    @ (src, src + n), then backwards a byte at a time.
    .thumb_func
memmove:
    .thumb_func
__aeabi_memmove:
    .thumb_func
__aeabi_memmove4:
    .thumb_func
__aeabi_memmove8:
    subs    r3, r0, r1
    cmp     r3, r2                  @ dst - src >= n (unsigned): no overlap from above
    bhs     memcpy
    add     r1, r1, r2
    add     r12, r0, r2
.Lmove_back:
    subs    r2, #1
    blo     .Lret
    ldrb    r3, [r1, #-1]!
    strb    r3, [r12, #-1]!
    b       .Lmove_back

    @ __aeabi_memclr(dst r0, n r1); __aeabi_memset(dst r0, n r1, c r2);
    @ memset(dst r0, c r1, n r2) -> dst.
    .thumb_func
__aeabi_memclr:
    .thumb_func
__aeabi_memclr4:
    .thumb_func
__aeabi_memclr8:
    movs    r2, #0
    .thumb_func
__aeabi_memset:
    .thumb_func
__aeabi_memset4:
    .thumb_func
__aeabi_memset8:
    mov     r3, r1
    mov     r1, r2
    mov     r2, r3
    .thumb_func
memset:
    mov     r12, r0
    uxtb    r1, r1
    orr     r1, r1, r1, lsl #8
    orr     r1, r1, r1, lsl #16
.Lset_head:                         @ bytes up to dst's next word boundary
    lsls.w  r3, r12, #30
    beq     .Lset_words
    subs    r2, #1
    blo     .Lret
    strb    r1, [r12], #1
    b       .Lset_head
.Lset_words:
    subs    r2, #4
    blo     .Lset_words_end
    str     r1, [r12], #4
    b       .Lset_words
.Lset_words_end:
    adds    r2, #4
.Lset_bytes:
    subs    r2, #1
    blo     .Lret
    strb    r1, [r12], #1
    b       .Lset_bytes

    @ memcmp(a r0, b r1, n r2) -> a[i] - b[i] at the first difference, else 0; bcmp: the
    @ same (zero when equal).
    .thumb_func
memcmp:
    .thumb_func
bcmp:
    subs    r2, #1
    blo     .Lcmp_equal
    ldrb    r3, [r0], #1
    ldrb    r12, [r1], #1
    subs    r3, r3, r12
    beq     memcmp
    mov     r0, r3
    bx      lr
.Lcmp_equal:
    movs    r0, #0
    bx      lr
    .size memcpy, . - memcpy
"#
    );
}
