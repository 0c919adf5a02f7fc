//! FMMUs: decoded logical-to-physical mappings (bit granular).
//!
//! Register layout at 0x0600 + 16n: logical start (u32), length (u16), logical start bit
//! (u8), logical stop bit (u8), physical start (u16), physical start bit (u8), type (u8:
//! bit 0 read, bit 1 write), activate (u8 bit 0).

/// One active FMMU, decoded for fast lookup.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Fmmu {
    /// First logical bit mapped (logical start address * 8 + start bit).
    pub log_bit_start: u64,
    /// One past the last logical bit mapped.
    pub log_bit_end: u64,
    /// First physical bit (physical start * 8 + physical start bit).
    pub phys_bit_start: u32,
    /// Logical start address (byte).
    pub log_start: u32,
    /// Logical end address (byte, exclusive) for the byte-aligned fast path.
    pub log_end: u64,
    /// Physical start address (byte).
    pub phys_start: u16,
    /// Maps for reading (LRD / LRW read part).
    pub read: bool,
    /// Maps for writing (LWR / LRW write part).
    pub write: bool,
    /// Whole bytes on both sides: byte copies suffice.
    pub aligned: bool,
    /// Logical length in bytes.
    pub len: u16,
    /// Fast path: the SM whose whole buffer this FMMU maps exactly (in a direction the SM
    /// allows for ECAT), set by the ESC when FMMUs or SMs change.
    pub sm: Option<u8>,
}

impl Fmmu {
    /// Decodes the 16 register bytes of one FMMU; `None` when inactive or empty.
    pub fn decode(r: &[u8]) -> Option<Self> {
        if r.len() < 16 || r[12] & 1 == 0 {
            return None;
        }
        let log_start = u32::from_le_bytes([r[0], r[1], r[2], r[3]]);
        let len = u16::from_le_bytes([r[4], r[5]]);
        let start_bit = r[6] & 7;
        let stop_bit = r[7] & 7;
        let phys_start = u16::from_le_bytes([r[8], r[9]]);
        let phys_bit = r[10] & 7;
        let ty = r[11];
        if len == 0 || ty & 3 == 0 {
            return None;
        }
        let log_bit_start = log_start as u64 * 8 + start_bit as u64;
        let log_bit_end = (log_start as u64 + len as u64 - 1) * 8 + stop_bit as u64 + 1;
        if log_bit_end <= log_bit_start {
            return None;
        }
        Some(Self {
            log_bit_start,
            log_bit_end,
            phys_bit_start: phys_start as u32 * 8 + phys_bit as u32,
            log_start,
            log_end: log_start as u64 + len as u64,
            phys_start,
            read: ty & 1 != 0,
            write: ty & 2 != 0,
            aligned: start_bit == 0 && stop_bit == 7 && phys_bit == 0,
            len,
            sm: None,
        })
    }

    /// True when the logical bit ranges of `self` and `o` overlap.
    pub fn overlaps(&self, o: &Fmmu) -> bool {
        self.log_bit_start < o.log_bit_end && o.log_bit_start < self.log_bit_end
    }
}

/// Reads bit `i` of `buf` (LSB first); 0 outside.
#[inline]
pub fn get_bit(buf: &[u8], i: usize) -> bool {
    buf.get(i / 8).is_some_and(|b| b & (1 << (i % 8)) != 0)
}

/// Sets bit `i` of `buf` (LSB first) to `v`; ignored outside.
#[inline]
pub fn set_bit(buf: &mut [u8], i: usize, v: bool) {
    if let Some(b) = buf.get_mut(i / 8) {
        if v {
            *b |= 1 << (i % 8);
        } else {
            *b &= !(1 << (i % 8));
        }
    }
}

/// Where a logical datagram meets one FMMU ([`Fmmu::overlap`]); offsets into the datagram.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Overlap {
    /// No byte or bit in common.
    None,
    /// The datagram covers the FMMU's whole logical range and the FMMU maps exactly the
    /// buffer of SyncManager `sm`: datagram bytes `at..at + len` are that buffer.
    WholeSm {
        /// SyncManager index.
        sm: usize,
        /// First datagram byte.
        at: usize,
    },
    /// Byte-aligned: datagram bytes `d0..d1` are physical bytes from `phys` on.
    Bytes {
        /// First physical byte.
        phys: u32,
        /// First datagram byte.
        d0: usize,
        /// One past the last datagram byte.
        d1: usize,
    },
    /// Bit-granular: `n` bits from datagram bit `dbit` are physical bits from `pbit0`
    /// (absolute bit address) on.
    Bits {
        /// Number of bits.
        n: usize,
        /// First datagram bit.
        dbit: usize,
        /// First physical bit (byte address × 8 + bit).
        pbit0: usize,
    },
}

impl Fmmu {
    /// How the logical datagram `[addr, addr + len)` meets this FMMU, the same for reads
    /// and writes.
    pub(crate) fn overlap(&self, addr: u32, len: usize) -> Overlap {
        let ds = addr as u64;
        let de = ds + len as u64;
        if self.aligned {
            let x0 = ds.max(self.log_start as u64);
            let x1 = de.min(self.log_end);
            if x0 >= x1 {
                return Overlap::None;
            }
            if let (Some(sm), true) = (self.sm, x0 == self.log_start as u64 && x1 == self.log_end) {
                return Overlap::WholeSm {
                    sm: sm as usize,
                    at: (x0 - ds) as usize,
                };
            }
            return Overlap::Bytes {
                phys: self.phys_start as u32 + (x0 - self.log_start as u64) as u32,
                d0: (x0 - ds) as usize,
                d1: (x1 - ds) as usize,
            };
        }
        let b0 = self.log_bit_start.max(ds * 8);
        let b1 = self.log_bit_end.min(de * 8);
        if b0 >= b1 {
            return Overlap::None;
        }
        Overlap::Bits {
            n: (b1 - b0) as usize,
            dbit: (b0 - ds * 8) as usize,
            pbit0: self.phys_bit_start as usize + (b0 - self.log_bit_start) as usize,
        }
    }
}
