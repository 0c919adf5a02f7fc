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
/// Eight bytes (a mapping of [`MAX_ITEMS`] steps is part of the `Slave` value): the
/// image position carries the two flags in its top bits.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Op {
    /// Byte-aligned: byte offset in the image; else bit position; bit 31: aligned, bit 30:
    /// application image (else the communication image).
    img: u32,
    /// Byte-aligned: byte offset in the buffer; else bit position.
    pd: u16,
    /// Byte-aligned: bytes; else bits.
    len: u16,
}

const OP_ALIGNED: u32 = 1 << 31;
const OP_APP: u32 = 1 << 30;
const OP_POS: u32 = OP_APP - 1;
// Every buffer bit position fits `pd`, every bit length `len` (a mappable entry has at most
// 255 bits: longer strings cannot be mapped).
const _: () = assert!(MAX_ITEMS * 255 <= u16::MAX as usize);

impl Op {
    fn aligned(&self) -> bool {
        self.img & OP_ALIGNED != 0
    }
    fn app(&self) -> bool {
        self.img & OP_APP != 0
    }
    fn img(&self) -> usize {
        (self.img & OP_POS) as usize
    }
    /// Image bytes `[start, end)` the step touches.
    fn img_bytes(&self) -> (usize, usize) {
        if self.aligned() {
            (self.img(), self.img() + self.len as usize)
        } else {
            (self.img() / 8, (self.img() + self.len as usize).div_ceil(8))
        }
    }
}

/// A compiled mapping of one direction: its copy steps (the entries are not kept).
#[derive(Debug, Clone, Copy)]
pub struct Mapping {
    ops: [Op; MAX_ITEMS],
    n_ops: usize,
    /// Mapped entries, gaps included.
    n: usize,
    bits: usize,
    /// A gap (index 0) is mapped.
    gaps: bool,
}

impl Default for Mapping {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl Mapping {
    /// The empty mapping (all bytes zero).
    pub(crate) const EMPTY: Self = Self {
        ops: [Op {
            img: 0,
            pd: 0,
            len: 0,
        }; MAX_ITEMS],
        n_ops: 0,
        n: 0,
        bits: 0,
        gaps: false,
    };

    /// Back to the empty mapping (in place).
    pub(crate) fn clear(&mut self) {
        self.n_ops = 0;
        self.n = 0;
        self.bits = 0;
        self.gaps = false;
    }

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
        self.bits & 7 == 0 && !self.gaps
    }

    /// Copies image values into `buf` (inputs → SM3); gaps are left as they are.
    pub(crate) fn pack<const N: usize>(&self, od: &Od<N>, buf: &mut [u8]) {
        for op in &self.ops[..self.n_ops] {
            let src = if op.app() { &od.app[..] } else { &od.comm[..] };
            let (pd, img, len) = (op.pd as usize, op.img(), op.len as usize);
            if op.aligned() {
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
            let dst = if op.app() {
                &mut od.app[..]
            } else {
                &mut od.comm[..]
            };
            let (pd, img, len) = (op.pd as usize, op.img(), op.len as usize);
            if op.aligned() {
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

    /// Appends one mapped entry at the end of the buffer, as a copy step (merged into the
    /// previous one when both are byte-aligned and follow each other in buffer and image).
    /// The caller checked [`MAX_ITEMS`]: at most `MAX_ITEMS` entries of at most 255 bits
    /// each, so every position fits the step's 16-bit fields.
    fn push(&mut self, it: Item) {
        let pos = self.bits;
        let bits = it.bits as usize;
        self.n += 1;
        self.bits += bits;
        if it.off == usize::MAX {
            self.gaps = true;
            return;
        }
        let aligned = pos & 7 == 0 && bits & 7 == 0;
        let app = if it.app { OP_APP } else { 0 };
        let op = if aligned {
            Op {
                img: (it.off as u32 & OP_POS) | OP_ALIGNED | app,
                pd: (pos / 8) as u16,
                len: (bits / 8) as u16,
            }
        } else {
            Op {
                img: ((it.off * 8) as u32 & OP_POS) | app,
                pd: pos as u16,
                len: bits as u16,
            }
        };
        if let Some(last) = self.n_ops.checked_sub(1).map(|i| &mut self.ops[i]) {
            if aligned
                && last.aligned()
                && last.app() == it.app
                && last.pd as usize + last.len as usize == pos / 8
                && last.img() + last.len as usize == it.off
            {
                last.len += op.len;
                return;
            }
        }
        self.ops[self.n_ops] = op;
        self.n_ops += 1;
    }

    /// True when the image bytes `[off, off+len)` of the application image are mapped.
    pub(crate) fn maps(&self, app: bool, off: usize, len: usize) -> bool {
        self.ops[..self.n_ops].iter().any(|op| {
            let (start, end) = op.img_bytes();
            op.app() == app && start < off + len && off < end
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
    // At most the subindexes the object stores (a fixed mapping's count, a configurable
    // one's shown slots).
    let cnt = (od.comm[base] as usize)
        .min(MAX_PDO_ENTRIES)
        .min(o.max_sub() as usize);
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

/// Walks the PDOs assigned in 0x1C12 (`Rx`) or 0x1C13 (`Tx`), checks every mapped entry
/// and hands it to `sink` resolved; the capacity checks ([`MAX_ITEMS`], [`MAX_PD_BYTES`])
/// included. Returns the process data bytes.
fn walk<const N: usize>(
    od: &Od<N>,
    dir: Dir,
    mut sink: impl FnMut(Item),
) -> Result<usize, SdoAbortCode> {
    let assign = match dir {
        Dir::Rx => 0x1C12,
        Dir::Tx => 0x1C13,
    };
    let cnt: u8 = od.get(assign, 0).map_err(|_| SdoAbortCode::GeneralError)?;
    let mut f = od.finder();
    let (mut n, mut bits) = (0usize, 0usize);
    for k in 1..=cnt {
        let pdo: u16 = od
            .get(assign, k)
            .map_err(|_| SdoAbortCode::SubindexDoesNotExist)?;
        // Each entry checked as an SDO write of the mapping would check it (the PDO's
        // index range first), and resolved with the same lookup.
        pdo_range(dir, pdo)?;
        let (cnt, v) = pdo_entries(od, pdo).ok_or(SdoAbortCode::ParameterIncompatible)?;
        for x in &v[..cnt] {
            let pe = PdoEntry::decode(*x);
            let item = entry_item(&mut f, dir, pe)?;
            if n >= MAX_ITEMS {
                return Err(SdoAbortCode::PdoLengthExceeded);
            }
            n += 1;
            bits += pe.bits as usize;
            sink(item);
        }
    }
    if bits.div_ceil(8) > MAX_PD_BYTES {
        return Err(SdoAbortCode::PdoLengthExceeded);
    }
    Ok(bits.div_ceil(8))
}

/// Checks the mapping of `dir` as [`compile`] does and returns its process data bytes,
/// without building it (nothing stored).
pub(crate) fn check<const N: usize>(od: &Od<N>, dir: Dir) -> Result<usize, SdoAbortCode> {
    walk(od, dir, |_| {})
}

/// Compiles the mapping of `dir` into `m` (in place: no [`Mapping`] on the stack). On an
/// error `m` holds a part of the mapping.
pub(crate) fn compile_into<const N: usize>(
    od: &Od<N>,
    dir: Dir,
    m: &mut Mapping,
) -> Result<(), SdoAbortCode> {
    m.clear();
    walk(od, dir, |it| m.push(it)).map(|_| ())
}
