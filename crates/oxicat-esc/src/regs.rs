//! The per-byte access-permission table of the ESC register file (which side may write
//! which byte). The register addresses are `oxicat_wire::regs`, re-exported here.

pub use oxicat_wire::regs::*;

/// Index of register byte `off` of SyncManager `n` in the register file ([`sm`]).
#[inline]
pub const fn sm_reg(n: usize, off: usize) -> usize {
    SM_BASE as usize + SM_LEN as usize * n + off
}

/// Index of register byte `off` of FMMU `n` in the register file ([`fmmu`]).
#[inline]
pub const fn fmmu_reg(n: usize, off: usize) -> usize {
    FMMU_BASE as usize + FMMU_LEN as usize * n + off
}

/// Permission bit: ECAT may write this byte.
pub const P_ECAT: u8 = 1;
/// Permission bit: PDI may write this byte.
pub const P_PDI: u8 = 2;
/// Permission bit: any write (of any value) clears this byte (error counters).
pub const P_CLEAR: u8 = 4;
/// Permission bit: the byte is implemented (reads return memory; otherwise 0).
pub const P_IMPL: u8 = 8;

const fn set(t: &mut [u8; 4096], from: usize, to_incl: usize, p: u8) {
    let mut i = from;
    while i <= to_incl {
        t[i] = p | P_IMPL;
        i += 1;
    }
}

const fn build_table() -> [u8; 4096] {
    let mut t = [0u8; 4096];
    let e = P_ECAT;
    let p = P_PDI;
    set(&mut t, 0x0000, 0x000F, 0);
    set(&mut t, 0x0010, 0x0011, e);
    set(&mut t, 0x0012, 0x0013, p);
    set(&mut t, 0x0020, 0x0021, e);
    set(&mut t, 0x0030, 0x0031, e);
    set(&mut t, 0x0040, 0x0040, e);
    set(&mut t, 0x0041, 0x0041, p);
    set(&mut t, 0x0100, 0x0103, e);
    set(&mut t, 0x0108, 0x0109, e);
    set(&mut t, 0x0110, 0x0111, 0);
    set(&mut t, 0x0120, 0x0121, e);
    set(&mut t, 0x0130, 0x0131, p);
    set(&mut t, 0x0134, 0x0135, p);
    set(&mut t, 0x0138, 0x0139, e | p);
    set(&mut t, 0x0140, 0x0141, 0);
    set(&mut t, 0x014E, 0x014F, 0);
    set(&mut t, 0x0150, 0x0153, 0);
    set(&mut t, 0x0200, 0x0201, e);
    set(&mut t, 0x0204, 0x0207, p);
    set(&mut t, 0x0210, 0x0211, 0);
    set(&mut t, 0x0220, 0x0223, 0);
    set(&mut t, 0x0300, 0x030D, e | P_CLEAR);
    set(&mut t, 0x030E, 0x030E, 0);
    set(&mut t, 0x0310, 0x0313, e | P_CLEAR);
    set(&mut t, 0x0400, 0x0401, e);
    set(&mut t, 0x0410, 0x0411, e);
    set(&mut t, 0x0420, 0x0421, e);
    set(&mut t, 0x0440, 0x0441, 0);
    set(&mut t, 0x0442, 0x0443, e | P_CLEAR);
    // SII interface: ownership is checked by the SII unit itself.
    set(&mut t, 0x0500, 0x0500, e);
    set(&mut t, 0x0501, 0x0501, p);
    set(&mut t, 0x0502, 0x050F, e | p);
    set(&mut t, 0x0510, 0x0515, e);
    // FMMUs 0..15.
    let mut f = 0;
    while f < 16 {
        let b = fmmu_reg(f, 0);
        set(&mut t, b, b + 12, e);
        set(&mut t, b + 13, b + 15, 0);
        f += 1;
    }
    // SyncManagers 0..15: start, length, control by ECAT; status RO; activate ECAT;
    // PDI control by PDI.
    let mut s = 0;
    while s < 16 {
        let b = sm_reg(s, 0);
        set(&mut t, b, b + 4, e);
        set(&mut t, b + 5, b + 5, 0);
        set(&mut t, b + 6, b + 6, e);
        set(&mut t, b + 7, b + 7, p);
        s += 1;
    }
    // Distributed clocks (the DC unit reacts in after_write / before_read).
    set(&mut t, 0x0900, 0x0917, e);
    set(&mut t, 0x0918, 0x091F, 0);
    set(&mut t, 0x0920, 0x092B, e);
    set(&mut t, 0x092C, 0x092F, 0);
    set(&mut t, 0x0930, 0x0931, e);
    set(&mut t, 0x0932, 0x0933, 0);
    set(&mut t, 0x0934, 0x0936, e);
    // SYNC/latch unit: 0x0981, 0x0990.., 0x09A0..0x09A9 are written by the side that
    // cyclic unit control 0x0980 assigns (checked by the core).
    set(&mut t, 0x0980, 0x0980, e);
    set(&mut t, 0x0981, 0x0981, e | p);
    set(&mut t, 0x0982, 0x0984, 0);
    set(&mut t, 0x098E, 0x098F, 0);
    set(&mut t, 0x0990, 0x0997, e | p);
    set(&mut t, 0x0998, 0x099F, 0);
    set(&mut t, 0x09A0, 0x09A9, e | p);
    set(&mut t, 0x09AE, 0x09AF, 0);
    set(&mut t, 0x09B0, 0x09CF, 0);
    set(&mut t, 0x09F0, 0x09F3, 0);
    set(&mut t, 0x09F8, 0x09FF, 0);
    // Digital I/O, GP I/O, user RAM.
    set(&mut t, 0x0F00, 0x0F03, e);
    set(&mut t, 0x0F10, 0x0F17, e | p);
    set(&mut t, 0x0F18, 0x0F1F, p);
    set(&mut t, 0x0F80, 0x0FFF, e | p);
    t
}

/// Per-byte permissions of the register file (P_ECAT | P_PDI | P_CLEAR | P_IMPL).
pub static PERMISSIONS: [u8; 4096] = build_table();

/// Permissions of register byte `addr` (0 for addresses >= 0x1000).
#[inline]
pub fn permissions(addr: usize) -> u8 {
    PERMISSIONS.get(addr).copied().unwrap_or(0)
}
