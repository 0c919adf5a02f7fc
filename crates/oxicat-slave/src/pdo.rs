//! PDO mapping compiled from 0x1C12/0x1C13 and 0x16xx/0x1Axx into a flat list of image
//! slices, and bit-exact packing into / unpacking from the SM2/SM3 buffers.

use oxicat_wire::coe::SdoAbortCode;

use crate::device::{DeviceDef, PdoDef, PdoEntry};
use crate::od::{map_shown, Area, Finder, ObjectDef, Od, MAX_PDO_ENTRIES};

/// Maximum process data bytes per direction (1024 with the `twin-capacity` feature; see
/// [`crate::od::MAX_PDOS`] on capacities).
pub const MAX_PD_BYTES: usize = if cfg!(feature = "twin-capacity") {
    1024
} else {
    256
};
/// Maximum mapped entries per direction (256 with the `twin-capacity` feature: EL2258 maps
/// 224), and the stack's default capacity of copy steps per direction (the `K` of
/// [`crate::Slave`]; a board image sizes it to its device with [`map_steps`]).
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
/// Eight bytes (a mapping of `K` steps is part of the `Slave` value): the image position
/// carries the two flags in its top bits.
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
    /// Copies the step's bytes or bits from `src` to `dst`: `to_buf`, from the image
    /// `src` into the process data buffer `dst` ([`Mapping::pack`]); else from the buffer
    /// `src` into the image `dst` ([`Mapping::unpack`]). Out-of-range positions copy
    /// nothing. One copy loop for both directions in a board image.
    #[cfg_attr(target_os = "none", inline(never))]
    fn copy(&self, src: &[u8], dst: &mut [u8], to_buf: bool) {
        let (pd, img, len) = (self.pd as usize, self.img(), self.len as usize);
        let (from, to) = if to_buf { (img, pd) } else { (pd, img) };
        if self.aligned() {
            if let (Some(d), Some(s)) = (dst.get_mut(to..to + len), src.get(from..from + len)) {
                d.copy_from_slice(s);
            }
        } else {
            for k in 0..len {
                set_bit(dst, to + k, get_bit(src, from + k));
            }
        }
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

/// A compiled mapping of one direction: its copy steps (the entries are not kept), at most
/// `K` of them.
#[derive(Debug, Clone, Copy)]
pub struct Mapping<const K: usize> {
    ops: [Op; K],
    n_ops: u16,
    /// A gap (index 0) is mapped.
    gaps: bool,
    bits: u32,
}

impl<const K: usize> Default for Mapping<K> {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl<const K: usize> Mapping<K> {
    /// The empty mapping (all bytes zero).
    pub(crate) const EMPTY: Self = Self {
        ops: [Op {
            img: 0,
            pd: 0,
            len: 0,
        }; K],
        n_ops: 0,
        gaps: false,
        bits: 0,
    };

    /// Back to the empty mapping (in place).
    pub(crate) fn clear(&mut self) {
        self.n_ops = 0;
        self.bits = 0;
        self.gaps = false;
    }

    /// Process data size in bytes.
    pub fn bytes(&self) -> usize {
        self.bits().div_ceil(8)
    }

    /// Process data size in bits.
    pub fn bits(&self) -> usize {
        self.bits as usize
    }

    /// The copy steps.
    fn ops(&self) -> &[Op] {
        &self.ops[..self.n_ops as usize]
    }

    /// True when the copy steps write every bit of the buffer (no gaps, whole bytes), so
    /// the buffer need not be cleared before [`Mapping::pack`].
    pub(crate) fn covers_all(&self) -> bool {
        self.bits & 7 == 0 && !self.gaps
    }

    /// Copies image values into `buf` (inputs → SM3); gaps are left as they are.
    pub(crate) fn pack<const N: usize>(&self, od: &Od<N>, buf: &mut [u8]) {
        for op in self.ops() {
            let src = if op.app() { &od.app[..] } else { &od.comm[..] };
            op.copy(src, buf, true);
        }
    }

    /// Copies `buf` (SM2 outputs) into the image.
    pub(crate) fn unpack<const N: usize>(&self, od: &mut Od<N>, buf: &[u8]) {
        for op in self.ops() {
            let dst = if op.app() {
                &mut od.app[..]
            } else {
                &mut od.comm[..]
            };
            op.copy(buf, dst, false);
        }
    }

    /// Applies one step of [`walk`] (which checked the capacity `K`).
    fn push(&mut self, step: Step, bits: usize) {
        self.bits += bits as u32;
        match step {
            Step::Gap => self.gaps = true,
            Step::Extend(len) => {
                if let Some(last) = (self.n_ops as usize)
                    .checked_sub(1)
                    .and_then(|i| self.ops.get_mut(i))
                {
                    last.len += len;
                }
            }
            Step::New(op) => {
                if let Some(slot) = self.ops.get_mut(self.n_ops as usize) {
                    *slot = op;
                    self.n_ops += 1;
                }
            }
        }
    }

    /// True when the image bytes `[off, off+len)` of the application image are mapped.
    pub(crate) fn maps(&self, app: bool, off: usize, len: usize) -> bool {
        self.ops().iter().any(|op| {
            let (start, end) = op.img_bytes();
            op.app() == app && start < off + len && off < end
        })
    }
}

/// What one mapped entry adds to a compiled mapping.
#[derive(Debug, Clone, Copy)]
enum Step {
    /// A gap: bits of the buffer no step writes.
    Gap,
    /// A new copy step.
    New(Op),
    /// The previous step extended by this many bytes (byte-aligned entries that follow
    /// each other in both the buffer and the image).
    Extend(u16),
}

/// The copy step of an entry at buffer bit `pos`, or how it extends the step `last`: the
/// one merge rule of compiling and of counting the steps ([`walk`]). Every entry has at most
/// 255 bits and a mapping at most [`MAX_ITEMS`] entries, so every position fits the step's
/// 16-bit fields.
fn step(last: Option<&Op>, pos: usize, it: Item) -> Step {
    let bits = it.bits as usize;
    if it.off == usize::MAX {
        return Step::Gap;
    }
    let aligned = pos & 7 == 0 && bits & 7 == 0;
    if let Some(last) = last {
        if aligned
            && last.aligned()
            && last.app() == it.app
            && last.pd as usize + last.len as usize == pos / 8
            && last.img() + last.len as usize == it.off
        {
            return Step::Extend((bits / 8) as u16);
        }
    }
    let app = if it.app { OP_APP } else { 0 };
    Step::New(if aligned {
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
    })
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

/// Mapping object entries (their values, read from the comm image) of the PDO `index`:
/// read one at a time, so no array of a mapping object's capacity is on the stack (a
/// mapping object's write checks its new mapping on the deepest stack path of a board
/// image).
pub(crate) fn pdo_entries<const N: usize>(
    od: &Od<N>,
    index: u16,
) -> Option<impl Iterator<Item = u32> + '_> {
    let o = od.find(index)?;
    let base = o.base;
    // At most the subindexes the object stores (a fixed mapping's count, a configurable
    // one's shown slots).
    let cnt = (od.comm[base] as usize)
        .min(MAX_PDO_ENTRIES)
        .min(o.max_sub() as usize);
    Some((0..cnt).map(move |k| {
        let a = base + 1 + 4 * k;
        u32::from_le_bytes([od.comm[a], od.comm[a + 1], od.comm[a + 2], od.comm[a + 3]])
    }))
}

/// Bit length of one PDO's current mapping (validated).
pub(crate) fn pdo_bits<const N: usize>(
    od: &Od<N>,
    dir: Dir,
    index: u16,
) -> Result<usize, SdoAbortCode> {
    pdo_range(dir, index)?;
    let entries = pdo_entries(od, index).ok_or(SdoAbortCode::ParameterIncompatible)?;
    let mut f = od.finder();
    let mut bits = 0;
    for x in entries {
        bits += check_entry_in(&mut f, dir, PdoEntry::decode(x))?;
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
/// and pushes it onto `m` (if given) as a copy step with its bits; the capacity checks
/// ([`MAX_ITEMS`] entries, [`MAX_PD_BYTES`], `cap` copy steps) included. Returns the
/// process data bytes and the copy steps. One function for checking and compiling (a
/// closure per use made two copies of it in a board image, 490 B each).
fn walk<const N: usize, const K: usize>(
    od: &Od<N>,
    dir: Dir,
    cap: usize,
    mut m: Option<&mut Mapping<K>>,
) -> Result<(usize, usize), SdoAbortCode> {
    let assign = match dir {
        Dir::Rx => 0x1C12,
        Dir::Tx => 0x1C13,
    };
    let cnt: u8 = od.get(assign, 0).map_err(|_| SdoAbortCode::GeneralError)?;
    let mut f = od.finder();
    let (mut n, mut bits, mut steps) = (0usize, 0usize, 0usize);
    // The last copy step, extended as entries merge into it.
    let mut last: Option<Op> = None;
    for k in 1..=cnt {
        let pdo: u16 = od
            .get(assign, k)
            .map_err(|_| SdoAbortCode::SubindexDoesNotExist)?;
        // Each entry checked as an SDO write of the mapping would check it (the PDO's
        // index range first), and resolved with the same lookup.
        pdo_range(dir, pdo)?;
        let entries = pdo_entries(od, pdo).ok_or(SdoAbortCode::ParameterIncompatible)?;
        for x in entries {
            let pe = PdoEntry::decode(x);
            let item = entry_item(&mut f, dir, pe)?;
            if n >= MAX_ITEMS {
                return Err(SdoAbortCode::PdoLengthExceeded);
            }
            let s = step(last.as_ref(), bits, item);
            match s {
                Step::Gap => {}
                Step::Extend(len) => {
                    if let Some(l) = last.as_mut() {
                        l.len += len;
                    }
                }
                Step::New(op) => {
                    if steps >= cap {
                        return Err(SdoAbortCode::PdoLengthExceeded);
                    }
                    steps += 1;
                    last = Some(op);
                }
            }
            n += 1;
            bits += pe.bits as usize;
            if let Some(m) = m.as_deref_mut() {
                m.push(s, pe.bits as usize);
            }
        }
    }
    if bits.div_ceil(8) > MAX_PD_BYTES {
        return Err(SdoAbortCode::PdoLengthExceeded);
    }
    Ok((bits.div_ceil(8), steps))
}

/// Checks the mapping of `dir` as [`compile_into`] does for a mapping of `cap` copy steps
/// and returns its process data bytes and copy steps, without building it (nothing stored).
/// `K`: the capacity of the stack's mappings, so that checking and compiling are one
/// function ([`walk`]) in the image.
pub(crate) fn check<const N: usize, const K: usize>(
    od: &Od<N>,
    dir: Dir,
    cap: usize,
) -> Result<(usize, usize), SdoAbortCode> {
    walk::<N, K>(od, dir, cap, None)
}

/// The copy steps the current mapping of `dir` (0x1C12/0x1C13 and the mapping objects of
/// `od`) compiles to, checked as PREOP → SAFEOP checks it but without a capacity of steps:
/// what a stack's `K` must hold for it.
pub fn steps<const N: usize>(od: &Od<N>, dir: Dir) -> Result<usize, SdoAbortCode> {
    check::<N, 0>(od, dir, usize::MAX).map(|(_, steps)| steps)
}

/// Compiles the mapping of `dir` into `m` (in place: no [`Mapping`] on the stack). On an
/// error `m` holds a part of the mapping.
pub(crate) fn compile_into<const N: usize, const K: usize>(
    od: &Od<N>,
    dir: Dir,
    m: &mut Mapping<K>,
) -> Result<(), SdoAbortCode> {
    m.clear();
    walk(od, dir, K, Some(m)).map(|_| ())
}

/// Copy steps per direction enough for every mapping `def` can run: the `K` a board image
/// gives its stack (`Slave<_, N, M, { map_steps(&DEF) }>`), computed when the image is
/// built. A fixed assignment of fixed mappings gives exactly the steps its mapping compiles
/// to (entries that follow each other byte-aligned in the buffer and the image share a
/// step); a configurable mapping or assignment one step per entry it can hold, at most
/// [`MAX_ITEMS`].
pub const fn map_steps(def: &DeviceDef) -> usize {
    let rx = dir_steps(def, def.rx_pdos, def.rx_assign);
    let tx = dir_steps(def, def.tx_pdos, def.tx_assign);
    let k = if rx > tx { rx } else { tx };
    if k > MAX_ITEMS {
        MAX_ITEMS
    } else {
        k
    }
}

/// [`map_steps`] of one direction.
const fn dir_steps(def: &DeviceDef, pdos: &[PdoDef], assign: &[u16]) -> usize {
    let mut steps = 0;
    if def.assign_configurable {
        // Any PDOs in any order: one step per entry.
        let mut i = 0;
        while i < pdos.len() {
            steps += pdo_slots(&pdos[i]);
            i += 1;
        }
        return steps;
    }
    let mut any_configurable = false;
    let mut a = 0;
    while a < assign.len() {
        if let Some(p) = pdo_by_index(pdos, assign[a]) {
            any_configurable |= p.configurable;
            steps += pdo_slots(p);
        }
        a += 1;
    }
    if any_configurable {
        return steps;
    }
    // Fixed: the steps the mapping compiles to, by the merge rule of `step`; an entry of a
    // communication object (such as 0x1C32:20) always a step of its own.
    steps = 0;
    let (mut pos, mut last_end) = (0usize, None::<(usize, usize)>);
    a = 0;
    while a < assign.len() {
        if let Some(p) = pdo_by_index(pdos, assign[a]) {
            let mut k = 0;
            while k < p.entries.len() {
                let pe = p.entries[k];
                let bits = pe.bits as usize;
                if pe.index != 0 {
                    let aligned = pos & 7 == 0 && bits & 7 == 0;
                    let off = app_offset(def.objects, pe.index, pe.sub);
                    let merged = match (last_end, off) {
                        (Some((pd_end, img_end)), Some(off)) => {
                            aligned && pd_end == pos / 8 && img_end == off
                        }
                        _ => false,
                    };
                    if !merged {
                        steps += 1;
                    }
                    last_end = match off {
                        Some(off) if aligned => Some((pos / 8 + bits / 8, off + bits / 8)),
                        _ => None,
                    };
                }
                pos += bits;
                k += 1;
            }
        }
        a += 1;
    }
    steps
}

/// Entries a mapping object of `p` can hold (gaps are not steps, but count here).
const fn pdo_slots(p: &PdoDef) -> usize {
    if p.configurable {
        map_shown(p)
    } else {
        p.entries.len()
    }
}

/// The PDO `index` of `pdos`.
const fn pdo_by_index(pdos: &[PdoDef], index: u16) -> Option<&PdoDef> {
    let mut i = 0;
    while i < pdos.len() {
        if pdos[i].index == index {
            return Some(&pdos[i]);
        }
        i += 1;
    }
    None
}

/// Image offset of the application entry `index:sub` (as [`Od::new`] lays the objects out),
/// `None` if `objects` have no such entry.
const fn app_offset(objects: &[ObjectDef], index: u16, sub: u8) -> Option<usize> {
    let mut base = 0;
    let mut i = 0;
    while i < objects.len() {
        let o = &objects[i];
        if o.index == index {
            let mut j = 0;
            while j < o.entries.len() {
                if o.entries[j].sub == sub {
                    return Some(base);
                }
                base += o.entries[j].storage_len();
                j += 1;
            }
            return None;
        }
        base += o.storage_len();
        i += 1;
    }
    None
}
