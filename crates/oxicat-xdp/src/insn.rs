//! eBPF instructions and the one XDP program oxicat loads, assembled by hand.
//!
//! The program steers EtherCAT frames to the AF_XDP socket of the queue they arrived on and
//! passes everything else to the kernel's stack, so the interface keeps working for other
//! traffic:
//!
//! ```text
//!  0: r2 = *(u32 *)(r1 + 0)        data
//!  1: r3 = *(u32 *)(r1 + 4)        data_end
//!  2: r4 = r2
//!  3: r4 += 14                     Ethernet header
//!  4: if r4 > r3 goto pass         (the verifier wants the bound before the load)
//!  5: r5 = *(u16 *)(r2 + 12)       EtherType, as the bytes lie (little-endian load)
//!  6: if r5 == 0xA488 goto steer   0x88A4
//!  7: if r5 != 0x0081 goto pass    0x8100: an 802.1Q tag, the EtherType follows it
//!  8: r4 = r2
//!  9: r4 += 18
//! 10: if r4 > r3 goto pass
//! 11: r5 = *(u16 *)(r2 + 16)
//! 12: if r5 != 0xA488 goto pass
//! steer:
//! 13: r2 = *(u32 *)(r1 + 16)       rx_queue_index: the XSKMAP key
//! 14: r1 = map fd (ld_imm64, two slots)
//! 16: r3 = XDP_PASS                bpf_redirect_map's action when the queue has no socket
//! 17: call bpf_redirect_map
//! 18: exit
//! pass:
//! 19: r0 = XDP_PASS
//! 20: exit
//! ```

/// One eBPF instruction (`struct bpf_insn`): opcode, destination and source registers,
/// signed offset, signed immediate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(C)]
pub struct Insn {
    /// Operation code: class | size/source | mode/operation.
    pub code: u8,
    /// Destination register in the low nibble, source register in the high one.
    pub regs: u8,
    /// Offset: memory displacement, or jump distance in instructions after the next.
    pub off: i16,
    /// Immediate operand.
    pub imm: i32,
}

/// Registers (r0 result, r1–r5 arguments, r6–r9 callee-saved, r10 frame pointer).
pub mod reg {
    /// Return value.
    pub const R0: u8 = 0;
    /// First argument (the context, `struct xdp_md *`, on entry).
    pub const R1: u8 = 1;
    /// Second argument.
    pub const R2: u8 = 2;
    /// Third argument.
    pub const R3: u8 = 3;
    /// Fourth argument.
    pub const R4: u8 = 4;
    /// Fifth argument.
    pub const R5: u8 = 5;
}

// Opcode parts (linux/bpf_common.h, linux/bpf.h).
const LD: u8 = 0x00;
const LDX: u8 = 0x01;
const JMP: u8 = 0x05;
const ALU64: u8 = 0x07;
const W: u8 = 0x00;
const H: u8 = 0x08;
const DW: u8 = 0x18;
const IMM: u8 = 0x00;
const MEM: u8 = 0x60;
const K: u8 = 0x00;
const X: u8 = 0x08;
const ADD: u8 = 0x00;
const MOV: u8 = 0xb0;
const JEQ: u8 = 0x10;
const JGT: u8 = 0x20;
const JNE: u8 = 0x50;
const CALL: u8 = 0x80;
const EXIT: u8 = 0x90;
/// `src_reg` of an ld_imm64 whose immediate is a map file descriptor.
const PSEUDO_MAP_FD: u8 = 1;

/// XDP verdict: hand the frame to the kernel's stack.
pub const XDP_PASS: i32 = 2;
/// Helper number of `bpf_redirect_map`.
pub const FUNC_REDIRECT_MAP: i32 = 51;

/// Offsets in `struct xdp_md`.
mod xdp_md {
    pub const DATA: i16 = 0;
    pub const DATA_END: i16 = 4;
    pub const RX_QUEUE_INDEX: i16 = 16;
}

const fn regs(dst: u8, src: u8) -> u8 {
    (src << 4) | (dst & 0x0f)
}

impl Insn {
    const fn new(code: u8, dst: u8, src: u8, off: i16, imm: i32) -> Self {
        Self {
            code,
            regs: regs(dst, src),
            off,
            imm,
        }
    }

    /// `dst = *(u32 *)(src + off)`.
    pub const fn ldx_w(dst: u8, src: u8, off: i16) -> Self {
        Self::new(LDX | MEM | W, dst, src, off, 0)
    }

    /// `dst = *(u16 *)(src + off)`.
    pub const fn ldx_h(dst: u8, src: u8, off: i16) -> Self {
        Self::new(LDX | MEM | H, dst, src, off, 0)
    }

    /// `dst = src` (64 bit).
    pub const fn mov64_reg(dst: u8, src: u8) -> Self {
        Self::new(ALU64 | MOV | X, dst, src, 0, 0)
    }

    /// `dst = imm` (64 bit, sign-extended).
    pub const fn mov64_imm(dst: u8, imm: i32) -> Self {
        Self::new(ALU64 | MOV | K, dst, 0, 0, imm)
    }

    /// `dst += imm` (64 bit).
    pub const fn add64_imm(dst: u8, imm: i32) -> Self {
        Self::new(ALU64 | ADD | K, dst, 0, 0, imm)
    }

    /// `if dst > src goto +off` (unsigned).
    pub const fn jgt_reg(dst: u8, src: u8, off: i16) -> Self {
        Self::new(JMP | JGT | X, dst, src, off, 0)
    }

    /// `if dst == imm goto +off`.
    pub const fn jeq_imm(dst: u8, imm: i32, off: i16) -> Self {
        Self::new(JMP | JEQ | K, dst, 0, off, imm)
    }

    /// `if dst != imm goto +off`.
    pub const fn jne_imm(dst: u8, imm: i32, off: i16) -> Self {
        Self::new(JMP | JNE | K, dst, 0, off, imm)
    }

    /// `call helper`.
    pub const fn call(helper: i32) -> Self {
        Self::new(JMP | CALL, 0, 0, 0, helper)
    }

    /// `exit` (returns r0).
    pub const fn exit() -> Self {
        Self::new(JMP | EXIT, 0, 0, 0, 0)
    }

    /// `dst = map` (ld_imm64 with a map fd): two instruction slots.
    pub const fn ld_map_fd(dst: u8, fd: i32) -> [Self; 2] {
        [
            Self::new(LD | DW | IMM, dst, PSEUDO_MAP_FD, 0, fd),
            Self::new(0, 0, 0, 0, 0),
        ]
    }

    /// The 8 bytes the kernel reads (little-endian host).
    pub fn to_bytes(self) -> [u8; 8] {
        let off = self.off.to_le_bytes();
        let imm = self.imm.to_le_bytes();
        [
            self.code, self.regs, off[0], off[1], imm[0], imm[1], imm[2], imm[3],
        ]
    }
}

/// EtherType 0x88A4 as a little-endian `u16` load of its two wire bytes sees it.
const ETHERCAT_LE: i32 = 0xA488;
/// EtherType 0x8100 (802.1Q) likewise.
const VLAN_LE: i32 = 0x0081;

/// The XDP program: EtherCAT frames (plain or 802.1Q-tagged) to the socket in `xskmap_fd`
/// at the frame's rx queue, everything else `XDP_PASS`.
pub fn ethercat_redirect(xskmap_fd: i32) -> Vec<Insn> {
    use reg::*;
    // Jump offsets count from the instruction after the jump; `pass` is at 19, `steer` at 13.
    let to = |from: i16, target: i16| target - from - 1;
    const STEER: i16 = 13;
    const PASS: i16 = 19;
    let mut p = vec![
        Insn::ldx_w(R2, R1, xdp_md::DATA),
        Insn::ldx_w(R3, R1, xdp_md::DATA_END),
        Insn::mov64_reg(R4, R2),
        Insn::add64_imm(R4, 14),
        Insn::jgt_reg(R4, R3, to(4, PASS)),
        Insn::ldx_h(R5, R2, 12),
        Insn::jeq_imm(R5, ETHERCAT_LE, to(6, STEER)),
        Insn::jne_imm(R5, VLAN_LE, to(7, PASS)),
        Insn::mov64_reg(R4, R2),
        Insn::add64_imm(R4, 18),
        Insn::jgt_reg(R4, R3, to(10, PASS)),
        Insn::ldx_h(R5, R2, 16),
        Insn::jne_imm(R5, ETHERCAT_LE, to(12, PASS)),
        Insn::ldx_w(R2, R1, xdp_md::RX_QUEUE_INDEX),
    ];
    p.extend(Insn::ld_map_fd(R1, xskmap_fd));
    p.extend([
        Insn::mov64_imm(R3, XDP_PASS),
        Insn::call(FUNC_REDIRECT_MAP),
        Insn::exit(),
        Insn::mov64_imm(R0, XDP_PASS),
        Insn::exit(),
    ]);
    debug_assert_eq!(p.len(), PASS as usize + 2);
    p
}

/// What [`ethercat_redirect`] decides for `frame`, by reading the program as an interpreter
/// would (for tests: the instructions, not a copy of the rule, are what is checked).
pub fn verdict(program: &[Insn], frame: &[u8], rx_queue: u32) -> Verdict {
    let mut r = [0u64; 11];
    // The context is modelled with data at 0x1000 and data_end after the frame.
    const DATA: u64 = 0x1000;
    let mut pc = 0usize;
    let mut steps = 0;
    while let Some(&i) = program.get(pc) {
        steps += 1;
        if steps > 1000 {
            return Verdict::Invalid;
        }
        let dst = (i.regs & 0x0f) as usize;
        let src = (i.regs >> 4) as usize;
        if dst > 10 || src > 10 {
            return Verdict::Invalid;
        }
        let jump = |pc: usize, off: i16| (pc as i64 + 1 + off as i64) as usize;
        pc = match i.code {
            c if c == LDX | MEM | W && r[src] == 0 => {
                // The context pointer (r1 on entry is 0 here).
                r[dst] = match i.off {
                    xdp_md::DATA => DATA,
                    xdp_md::DATA_END => DATA + frame.len() as u64,
                    xdp_md::RX_QUEUE_INDEX => rx_queue as u64,
                    _ => return Verdict::Invalid,
                };
                pc + 1
            }
            c if c == LDX | MEM | H => {
                let at = r[src].wrapping_add(i.off as u64).wrapping_sub(DATA) as usize;
                match frame.get(at..at + 2) {
                    Some(b) => r[dst] = u16::from_le_bytes([b[0], b[1]]) as u64,
                    None => return Verdict::OutOfBounds,
                }
                pc + 1
            }
            c if c == ALU64 | MOV | X => {
                r[dst] = r[src];
                pc + 1
            }
            c if c == ALU64 | MOV | K => {
                r[dst] = i.imm as i64 as u64;
                pc + 1
            }
            c if c == ALU64 | ADD | K => {
                r[dst] = r[dst].wrapping_add(i.imm as i64 as u64);
                pc + 1
            }
            c if c == JMP | JGT | X => {
                if r[dst] > r[src] {
                    jump(pc, i.off)
                } else {
                    pc + 1
                }
            }
            c if c == JMP | JEQ | K => {
                if r[dst] == i.imm as i64 as u64 {
                    jump(pc, i.off)
                } else {
                    pc + 1
                }
            }
            c if c == JMP | JNE | K => {
                if r[dst] != i.imm as i64 as u64 {
                    jump(pc, i.off)
                } else {
                    pc + 1
                }
            }
            c if c == LD | DW | IMM => {
                r[dst] = 0xfd00_0000 | i.imm as u32 as u64;
                pc + 2
            }
            c if c == JMP | CALL && i.imm == FUNC_REDIRECT_MAP => {
                return Verdict::Redirect {
                    key: r[2] as u32,
                    fallback: r[3] as i32,
                };
            }
            c if c == JMP | EXIT => {
                return if r[0] == XDP_PASS as u64 {
                    Verdict::Pass
                } else {
                    Verdict::Invalid
                };
            }
            _ => return Verdict::Invalid,
        };
    }
    Verdict::Invalid
}

/// The outcome of [`verdict`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// `XDP_PASS`: the kernel's stack gets the frame.
    Pass,
    /// `bpf_redirect_map(map, key, fallback)`: to the socket at `key`.
    Redirect {
        /// The XSKMAP key (the rx queue).
        key: u32,
        /// The action when no socket is at `key`.
        fallback: i32,
    },
    /// A load outside the frame (the verifier would refuse the program).
    OutOfBounds,
    /// An instruction the interpreter does not know, or no exit.
    Invalid,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn instructions_encode_as_the_kernel_reads_them() {
        // Values as `llvm-objdump -d` prints them for the same instructions.
        assert_eq!(
            Insn::ldx_w(2, 1, 4).to_bytes(),
            [0x61, 0x12, 4, 0, 0, 0, 0, 0]
        );
        assert_eq!(
            Insn::ldx_h(5, 2, 12).to_bytes(),
            [0x69, 0x25, 12, 0, 0, 0, 0, 0]
        );
        assert_eq!(
            Insn::mov64_reg(4, 2).to_bytes(),
            [0xbf, 0x24, 0, 0, 0, 0, 0, 0]
        );
        assert_eq!(
            Insn::mov64_imm(0, 2).to_bytes(),
            [0xb7, 0, 0, 0, 2, 0, 0, 0]
        );
        assert_eq!(
            Insn::add64_imm(4, 14).to_bytes(),
            [0x07, 4, 0, 0, 14, 0, 0, 0]
        );
        assert_eq!(
            Insn::jgt_reg(4, 3, 14).to_bytes(),
            [0x2d, 0x34, 14, 0, 0, 0, 0, 0]
        );
        assert_eq!(
            Insn::jeq_imm(5, 0xA488, 6).to_bytes(),
            [0x15, 5, 6, 0, 0x88, 0xA4, 0, 0]
        );
        assert_eq!(
            Insn::jne_imm(5, 0x81, -1).to_bytes(),
            [0x55, 5, 0xff, 0xff, 0x81, 0, 0, 0]
        );
        assert_eq!(Insn::call(51).to_bytes(), [0x85, 0, 0, 0, 51, 0, 0, 0]);
        assert_eq!(Insn::exit().to_bytes(), [0x95, 0, 0, 0, 0, 0, 0, 0]);
        let [a, b] = Insn::ld_map_fd(1, 7);
        assert_eq!(a.to_bytes(), [0x18, 0x11, 0, 0, 7, 0, 0, 0]);
        assert_eq!(b.to_bytes(), [0; 8]);
        assert_eq!(core::mem::size_of::<Insn>(), 8);
    }

    fn frame(ethertype: [u8; 2], len: usize) -> Vec<u8> {
        let mut f = vec![0u8; len];
        if len >= 14 {
            f[12..14].copy_from_slice(&ethertype);
        }
        f
    }

    #[test]
    fn ethercat_frames_are_steered_to_their_queue() {
        let p = ethercat_redirect(9);
        let plain = frame([0x88, 0xA4], 60);
        assert_eq!(
            verdict(&p, &plain, 0),
            Verdict::Redirect {
                key: 0,
                fallback: XDP_PASS
            }
        );
        assert_eq!(
            verdict(&p, &plain, 3),
            Verdict::Redirect {
                key: 3,
                fallback: XDP_PASS
            }
        );
        let mut tagged = frame([0x81, 0x00], 64);
        tagged[16..18].copy_from_slice(&[0x88, 0xA4]);
        assert!(matches!(verdict(&p, &tagged, 0), Verdict::Redirect { .. }));
    }

    #[test]
    fn other_traffic_and_short_frames_pass() {
        let p = ethercat_redirect(9);
        assert_eq!(verdict(&p, &frame([0x08, 0x00], 60), 0), Verdict::Pass);
        assert_eq!(verdict(&p, &frame([0x08, 0x06], 60), 0), Verdict::Pass);
        assert_eq!(verdict(&p, &frame([0xA4, 0x88], 60), 0), Verdict::Pass);
        let mut tagged_ip = frame([0x81, 0x00], 64);
        tagged_ip[16..18].copy_from_slice(&[0x08, 0x00]);
        assert_eq!(verdict(&p, &tagged_ip, 0), Verdict::Pass);
        // Too short for the header, or for the tag: never a load past the end.
        for len in [0, 1, 13] {
            assert_eq!(verdict(&p, &frame([0x88, 0xA4], len), 0), Verdict::Pass);
        }
        let mut short_tag = frame([0x81, 0x00], 17);
        short_tag[16] = 0x88;
        assert_eq!(verdict(&p, &short_tag, 0), Verdict::Pass);
        assert_eq!(
            verdict(&p, &frame([0x88, 0xA4], 14), 0),
            verdict(&p, &frame([0x88, 0xA4], 60), 0)
        );
    }
}
