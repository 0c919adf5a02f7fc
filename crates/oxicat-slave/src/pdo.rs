//! PDO mapping compiled from 0x1C12/0x1C13 and 0x16xx/0x1Axx into a flat list of image
//! slices, and bit-exact packing into / unpacking from the SM2/SM3 buffers.

use oxicat_wire::coe::SdoAbortCode;

use crate::device::PdoEntry;
use crate::od::{Area, Finder, Od, MAX_PDO_ENTRIES};

/// Maximum process data bytes per direction (1024 with the `twin-capacity` feature; see
/// [`crate::od::MAX_PDOS`] on capacities).
pub const MAX_PD_BYTES: usize = if cfg!(feature = "twin-capacity") {
    1024
} else {
    256
};
/// Maximum mapped entries per direction (256 with the `twin-capacity` feature: EL2258 maps
/// 224).
pub const MAX_ITEMS: usize = if cfg!(feature = "twin-capacity") {
    256
} else {
    64
};

/// Direction of a mapping.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dir {
    /// RxPDO: outputs (master → slave, SM2).
    Rx,
    /// TxPDO: inputs (slave → master, SM3).
    Tx,
}

#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Item {
    /// Image offset (application image); `usize::MAX` for a gap.
    off: usize,
    app: bool,
    bits: u16,
}

/// One copy step between the process data buffer and an image, resolved when the mapping
/// is compiled (PREOP -> SAFEOP): byte-aligned entries that follow each other in both the
/// buffer and the image are merged into one byte copy; everything else is a bit copy.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Op {
    /// Byte-aligned: byte offset in the buffer; else bit position.
    pd: u32,
    /// Byte-aligned: byte offset in the image; else bit position.
    img: u32,
    /// Byte-aligned: bytes; else bits.
    len: u16,
    aligned: bool,
    app: bool,
}

/// A compiled mapping of one direction.
#[derive(Debug, Clone, Copy)]
pub struct Mapping {
    items: [Item; MAX_ITEMS],
    n: usize,
    bits: usize,
    ops: [Op; MAX_ITEMS],
    n_ops: usize,
}

impl Default for Mapping {
    fn default() -> Self {
        Self {
            items: [Item::default(); MAX_ITEMS],
            n: 0,
            bits: 0,
            ops: [Op::default(); MAX_ITEMS],
            n_ops: 0,
        }
    }
}

impl Mapping {
    /// Process data size in bytes.
    pub fn bytes(&self) -> usize {
        self.bits.div_ceil(8)
    }

    /// Process data size in bits.
    pub fn bits(&self) -> usize {
        self.bits
    }

    /// True when the copy steps write every bit of the buffer (no gaps, whole bytes), so
    /// the buffer need not be cleared before [`Mapping::pack`].
    pub(crate) fn covers_all(&self) -> bool {
        self.bits & 7 == 0 && self.items[..self.n].iter().all(|it| it.off != usize::MAX)
    }

    /// Copies image values into `buf` (inputs → SM3); gaps are left as they are.
    pub(crate) fn pack<const N: usize>(&self, od: &Od<N>, buf: &mut [u8]) {
        for op in &self.ops[..self.n_ops] {
            let src = if op.app { &od.app[..] } else { &od.comm[..] };
            let (pd, img, len) = (op.pd as usize, op.img as usize, op.len as usize);
            if op.aligned {
                if let (Some(d), Some(s)) = (buf.get_mut(pd..pd + len), src.get(img..img + len)) {
                    d.copy_from_slice(s);
                }
            } else {
                for k in 0..len {
                    set_bit(buf, pd + k, get_bit(src, img + k));
                }
            }
        }
    }

    /// Copies `buf` (SM2 outputs) into the image.
    pub(crate) fn unpack<const N: usize>(&self, od: &mut Od<N>, buf: &[u8]) {
        for op in &self.ops[..self.n_ops] {
            let dst = if op.app {
                &mut od.app[..]
            } else {
                &mut od.comm[..]
            };
            let (pd, img, len) = (op.pd as usize, op.img as usize, op.len as usize);
            if op.aligned {
                if let (Some(d), Some(s)) = (dst.get_mut(img..img + len), buf.get(pd..pd + len)) {
                    d.copy_from_slice(s);
                }
            } else {
                for k in 0..len {
                    set_bit(dst, img + k, get_bit(buf, pd + k));
                }
            }
        }
    }

    /// Resolves the items into copy steps (see [`Op`]).
    fn build_ops(&mut self) {
        let mut pos = 0usize;
        self.n_ops = 0;
        for it in &self.items[..self.n] {
            let bits = it.bits as usize;
            if it.off != usize::MAX {
                let aligned = pos & 7 == 0 && bits & 7 == 0;
                let op = if aligned {
                    Op {
                        pd: (pos / 8) as u32,
                        img: it.off as u32,
                        len: (bits / 8) as u16,
                        aligned,
                        app: it.app,
                    }
                } else {
                    Op {
                        pd: pos as u32,
                        img: (it.off * 8) as u32,
                        len: bits as u16,
                        aligned,
                        app: it.app,
                    }
                };
                let merged = match self.n_ops.checked_sub(1).map(|i| &mut self.ops[i]) {
                    Some(last)
                        if aligned
                            && last.aligned
                            && last.app == op.app
                            && last.pd + last.len as u32 == op.pd
                            && last.img + last.len as u32 == op.img =>
                    {
                        last.len += op.len;
                        true
                    }
                    _ => false,
                };
                if !merged {
                    self.ops[self.n_ops] = op;
                    self.n_ops += 1;
                }
            }
            pos += bits;
        }
    }

    /// True when the image bytes `[off, off+len)` of the application image are mapped.
    pub(crate) fn maps(&self, app: bool, off: usize, len: usize) -> bool {
        self.items[..self.n].iter().any(|it| {
            it.off != usize::MAX
                && it.app == app
                && it.off < off + len
                && off < it.off + (it.bits as usize).div_ceil(8)
        })
    }
}

fn get_bit(b: &[u8], i: usize) -> bool {
    b.get(i / 8).is_some_and(|x| (x >> (i % 8)) & 1 != 0)
}

fn set_bit(b: &mut [u8], i: usize, v: bool) {
    if let Some(x) = b.get_mut(i / 8) {
        if v {
            *x |= 1 << (i % 8);
        } else {
            *x &= !(1 << (i % 8));
        }
    }
}

/// Checks one mapping entry value against the dictionary; returns its bit length.
pub(crate) fn check_entry<const N: usize>(
    od: &Od<N>,
    dir: Dir,
    pe: PdoEntry,
) -> Result<usize, SdoAbortCode> {
    check_entry_in(&mut od.finder(), dir, pe)
}

/// [`check_entry`] with the lookups of a run of checks.
fn check_entry_in<const N: usize>(
    f: &mut Finder<'_, N>,
    dir: Dir,
    pe: PdoEntry,
) -> Result<usize, SdoAbortCode> {
    entry_item(f, dir, pe).map(|it| it.bits as usize)
}

/// Checks one mapping entry value against the dictionary and resolves it to its place in
/// the image (a gap for index 0).
fn entry_item<const N: usize>(
    f: &mut Finder<'_, N>,
    dir: Dir,
    pe: PdoEntry,
) -> Result<Item, SdoAbortCode> {
    if pe.index == 0 {
        return Ok(Item {
            off: usize::MAX,
            app: true,
            bits: pe.bits as u16,
        });
    }
    let o = f.find(pe.index).ok_or(SdoAbortCode::ObjectDoesNotExist)?;
    let (_, e, off) = o.entry(pe.sub).ok_or(SdoAbortCode::SubindexDoesNotExist)?;
    let ok = match dir {
        Dir::Rx => e.pdo.rx(),
        Dir::Tx => e.pdo.tx(),
    };
    if !ok || e.dtype.is_string() && e.bits > 255 {
        return Err(SdoAbortCode::CannotMap);
    }
    if e.bits != pe.bits as u16 {
        return Err(SdoAbortCode::ParameterIncompatible);
    }
    Ok(Item {
        off,
        app: o.area == Area::App,
        bits: pe.bits as u16,
    })
}

/// Mapping object entries (count, values) of the PDO `index` in the comm image.
pub(crate) fn pdo_entries<const N: usize>(
    od: &Od<N>,
    index: u16,
) -> Option<(usize, [u32; MAX_PDO_ENTRIES])> {
    let o = od.find(index)?;
    let base = o.base;
    let cnt = (od.comm[base] as usize).min(MAX_PDO_ENTRIES);
    let mut v = [0u32; MAX_PDO_ENTRIES];
    for (k, x) in v.iter_mut().enumerate().take(cnt) {
        let a = base + 1 + 4 * k;
        *x = u32::from_le_bytes([od.comm[a], od.comm[a + 1], od.comm[a + 2], od.comm[a + 3]]);
    }
    Some((cnt, v))
}

/// Bit length of one PDO's current mapping (validated).
pub(crate) fn pdo_bits<const N: usize>(
    od: &Od<N>,
    dir: Dir,
    index: u16,
) -> Result<usize, SdoAbortCode> {
    pdo_range(dir, index)?;
    let (cnt, v) = pdo_entries(od, index).ok_or(SdoAbortCode::ParameterIncompatible)?;
    let mut f = od.finder();
    let mut bits = 0;
    for x in &v[..cnt] {
        bits += check_entry_in(&mut f, dir, PdoEntry::decode(*x))?;
    }
    Ok(bits)
}

/// Refuses a PDO index outside `dir`'s mapping range.
fn pdo_range(dir: Dir, index: u16) -> Result<(), SdoAbortCode> {
    let in_range = match dir {
        Dir::Rx => (0x1600..=0x17FF).contains(&index),
        Dir::Tx => (0x1A00..=0x1BFF).contains(&index),
    };
    if in_range {
        Ok(())
    } else {
        Err(SdoAbortCode::ParameterIncompatible)
    }
}

/// Compiles the current assignment of `dir` into a [`Mapping`].
pub(crate) fn compile<const N: usize>(od: &Od<N>, dir: Dir) -> Result<Mapping, SdoAbortCode> {
    let assign = match dir {
        Dir::Rx => 0x1C12,
        Dir::Tx => 0x1C13,
    };
    let cnt: u8 = od.get(assign, 0).map_err(|_| SdoAbortCode::GeneralError)?;
    let mut m = Mapping::default();
    let mut f = od.finder();
    for k in 1..=cnt {
        let pdo: u16 = od
            .get(assign, k)
            .map_err(|_| SdoAbortCode::SubindexDoesNotExist)?;
        // Each entry checked as an SDO write of the mapping would check it (the PDO's
        // index range first), and resolved with the same lookup.
        pdo_range(dir, pdo)?;
        let (n, v) = pdo_entries(od, pdo).ok_or(SdoAbortCode::ParameterIncompatible)?;
        for x in &v[..n] {
            let pe = PdoEntry::decode(*x);
            let item = entry_item(&mut f, dir, pe)?;
            if m.n >= MAX_ITEMS {
                return Err(SdoAbortCode::PdoLengthExceeded);
            }
            m.items[m.n] = item;
            m.n += 1;
            m.bits += pe.bits as usize;
        }
    }
    if m.bytes() > MAX_PD_BYTES {
        return Err(SdoAbortCode::PdoLengthExceeded);
    }
    m.build_ops();
    Ok(m)
}
