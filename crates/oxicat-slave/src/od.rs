//! The object dictionary: static definitions ([`ObjectDef`], [`EntryDef`]) and one byte
//! image per area holding the values, with typed access for the application.
//!
//! Values of application objects live in one fixed-size byte image owned by the stack
//! (`N` bytes, at least [`image_size`] of the definition's objects); every entry occupies
//! `max(1, bits / 8)` bytes at an offset that follows from the definition order, so there
//! is no second copy of the dictionary. The standard communication objects (0x1000..0x1C33)
//! are defined in this crate and derived from the [`DeviceDef`] at start-up; their values
//! live in a second, internal image.

use crate::device::{DeviceDef, PdoDef, SyncMode};
use crate::esm::AlState;

/// CoE basic data types (ETG.1000.6 data type indices).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataType {
    /// BOOL (0x0001), 1 bit.
    Bool,
    /// INTEGER8 (0x0002).
    Int8,
    /// INTEGER16 (0x0003).
    Int16,
    /// INTEGER32 (0x0004).
    Int32,
    /// INTEGER64 (0x0015).
    Int64,
    /// UNSIGNED8 (0x0005).
    Unsigned8,
    /// UNSIGNED16 (0x0006).
    Unsigned16,
    /// UNSIGNED32 (0x0007).
    Unsigned32,
    /// UNSIGNED64 (0x001B).
    Unsigned64,
    /// REAL32 (0x0008).
    Real32,
    /// REAL64 (0x0011).
    Real64,
    /// VISIBLE_STRING (0x0009), bit length = 8 x maximum length.
    VisibleString,
    /// OCTET_STRING (0x000A), bit length = 8 x length.
    OctetString,
}

impl DataType {
    /// The data type index used in SDO information.
    pub const fn code(self) -> u16 {
        match self {
            Self::Bool => 0x0001,
            Self::Int8 => 0x0002,
            Self::Int16 => 0x0003,
            Self::Int32 => 0x0004,
            Self::Unsigned8 => 0x0005,
            Self::Unsigned16 => 0x0006,
            Self::Unsigned32 => 0x0007,
            Self::Real32 => 0x0008,
            Self::VisibleString => 0x0009,
            Self::OctetString => 0x000A,
            Self::Real64 => 0x0011,
            Self::Int64 => 0x0015,
            Self::Unsigned64 => 0x001B,
        }
    }

    /// Bit length of the scalar types; 0 for strings.
    pub const fn bits(self) -> u16 {
        match self {
            Self::Bool => 1,
            Self::Int8 | Self::Unsigned8 => 8,
            Self::Int16 | Self::Unsigned16 => 16,
            Self::Int32 | Self::Unsigned32 | Self::Real32 => 32,
            Self::Int64 | Self::Unsigned64 | Self::Real64 => 64,
            Self::VisibleString | Self::OctetString => 0,
        }
    }

    /// True for the string types (variable length on the wire).
    pub const fn is_string(self) -> bool {
        matches!(self, Self::VisibleString | Self::OctetString)
    }

    /// True for the signed integer types.
    pub const fn is_signed(self) -> bool {
        matches!(self, Self::Int8 | Self::Int16 | Self::Int32 | Self::Int64)
    }

    /// True for the integer types (signed or unsigned).
    pub const fn is_integer(self) -> bool {
        matches!(
            self,
            Self::Int8
                | Self::Int16
                | Self::Int32
                | Self::Int64
                | Self::Unsigned8
                | Self::Unsigned16
                | Self::Unsigned32
                | Self::Unsigned64
        )
    }
}

/// Access rights per state, in the ETG.1000.6 object-access bit layout (bits 0..2 read in
/// PREOP/SAFEOP/OP, bits 3..5 write in PREOP/SAFEOP/OP).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Access(pub u16);

impl Access {
    /// Read-only in every state.
    pub const RO: Access = Access(0x0007);
    /// Read and write in every state.
    pub const RW: Access = Access(0x003F);
    /// Write-only in every state.
    pub const WO: Access = Access(0x0038);
    /// Readable always, writable only in PREOP.
    pub const RW_PREOP: Access = Access(0x000F);
    /// Readable always, writable in PREOP and SAFEOP.
    pub const RW_PREOP_SAFEOP: Access = Access(0x001F);

    fn state_bit(state: AlState) -> u16 {
        match state {
            AlState::PreOp => 1,
            AlState::SafeOp => 2,
            AlState::Op => 4,
            _ => 0,
        }
    }

    /// Readable in some state.
    pub const fn readable(self) -> bool {
        self.0 & 0x07 != 0
    }

    /// Writable in some state.
    pub const fn writable(self) -> bool {
        self.0 & 0x38 != 0
    }

    /// Readable in `state`.
    pub fn read_in(self, state: AlState) -> bool {
        self.0 & Self::state_bit(state) != 0
    }

    /// Writable in `state`.
    pub fn write_in(self, state: AlState) -> bool {
        self.0 & (Self::state_bit(state) << 3) != 0
    }
}

/// Whether an entry may be mapped into PDOs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PdoMapping {
    /// Not mappable.
    None,
    /// Mappable into RxPDOs (outputs).
    Rx,
    /// Mappable into TxPDOs (inputs).
    Tx,
    /// Mappable into both.
    RxTx,
}

impl PdoMapping {
    /// Mappable into RxPDOs.
    pub const fn rx(self) -> bool {
        matches!(self, Self::Rx | Self::RxTx)
    }

    /// Mappable into TxPDOs.
    pub const fn tx(self) -> bool {
        matches!(self, Self::Tx | Self::RxTx)
    }
}

/// Default value of an entry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DefaultValue {
    /// Little-endian bits of a scalar (two's complement for signed, IEEE bits for reals),
    /// low and high 32-bit halves: a `u64` would make every [`EntryDef`] 8-byte aligned
    /// (48 instead of 44 bytes of flash per entry). Built with [`DefaultValue::bits`], read
    /// with [`DefaultValue::as_bits`].
    Bits([u32; 2]),
    /// Bytes of a string entry (shorter than its length: rest zero).
    Bytes(&'static [u8]),
}

impl DefaultValue {
    /// A scalar default from its little-endian bits.
    pub const fn bits(v: u64) -> Self {
        Self::Bits([v as u32, (v >> 32) as u32])
    }

    /// A scalar default's bits (`None` for a string default).
    pub const fn as_bits(&self) -> Option<u64> {
        match *self {
            Self::Bits([lo, hi]) => Some(lo as u64 | (hi as u64) << 32),
            Self::Bytes(_) => None,
        }
    }
}

/// One subindex of an object.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EntryDef {
    /// Subindex.
    pub sub: u8,
    /// Name (SDO information).
    pub name: &'static str,
    /// Data type.
    pub dtype: DataType,
    /// Bit length (for strings 8 x maximum length).
    pub bits: u16,
    /// Access rights per state.
    pub access: Access,
    /// PDO mappability.
    pub pdo: PdoMapping,
    /// The default's low 32 bits, extended as the type says (sign for a signed type, zero
    /// else) when [`Limits::default`] is `None`: every default the board devices declare
    /// fits; a string default or a wider one is in the limits ([`EntryDef::default`] reads
    /// either). 4 bytes per entry instead of a 12-byte [`DefaultValue`].
    default_word: u32,
    /// Unit, allowed range and physical scaling, the fields few entries set, behind one
    /// reference ([`Limits::NONE`] when unset, [`EntryDef::limits`]): 4 bytes per entry in
    /// flash instead of 16. Also a default that does not fit the entry's own word.
    pub limits: &'static Limits,
}

// An entry's size in a microcontroller's flash (every object description of the image is
// one): 24 bytes on a 32-bit target (was 56 with 64-bit range bounds, 48 with a `u64`
// default, 44 with unit, range and scale in the entry, 32 with a `DefaultValue` in it).
const _: () =
    assert!(cfg!(not(target_pointer_width = "32")) || core::mem::size_of::<EntryDef>() <= 24);

/// An entry's unit, allowed range and physical scaling ([`EntryDef::limits`]):
/// `.limits(&Limits::range(0, 1000).with_unit(0xFD04_0000))` or
/// `.limits(&Limits::scale(&CENTI_DEG))` in a `static` or `const` definition (in a `const
/// fn` body: `const { &Limits::range(..) }`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Unit (ETG.1004 unit code; 0 = none).
    pub unit: u32,
    /// Allowed range for integer entries (`min > max`: no check). 32-bit bounds (every
    /// range the devices declare fits): 8 bytes less per entry in flash than 64-bit ones.
    pub range: (i32, i32),
    /// How the integer maps to a physical value (process data: what a master's
    /// recordings show); `None`: a plain number.
    pub scale: Option<&'static Scale>,
    /// A default the entry's own 32-bit word cannot hold (a string's bytes, a 64-bit value
    /// beyond the sign or zero extension of its low half): [`Limits::with_default`]; `None`:
    /// the entry's word is its default.
    pub default: Option<DefaultValue>,
}

impl Limits {
    /// No unit, no range, no scaling.
    pub const NONE: Limits = Limits {
        unit: 0,
        range: (1, 0),
        scale: None,
        default: None,
    };

    /// With a default value held here instead of in the entry (a string default:
    /// `.limits(&Limits::NONE.with_default(DefaultValue::Bytes(b"hello")))`).
    pub const fn with_default(mut self, d: DefaultValue) -> Self {
        self.default = Some(d);
        self
    }

    /// An allowed value range `min..=max`, nothing else.
    pub const fn range(min: i32, max: i32) -> Self {
        let mut l = Self::NONE;
        l.range = (min, max);
        l
    }

    /// A unit (ETG.1004 unit code), nothing else.
    pub const fn unit(u: u32) -> Self {
        let mut l = Self::NONE;
        l.unit = u;
        l
    }

    /// A physical scaling (`Limits::scale(&CENTI_DEG)` with `const CENTI_DEG: Scale =
    /// Scale::per("deg", 100)`: hundredths of a degree), nothing else.
    pub const fn scale(s: &'static Scale) -> Self {
        let mut l = Self::NONE;
        l.scale = Some(s);
        l
    }

    /// With a unit.
    pub const fn with_unit(mut self, u: u32) -> Self {
        self.unit = u;
        self
    }

    /// Whether a range is declared (`min <= max`).
    pub const fn has_range(&self) -> bool {
        self.range.0 <= self.range.1
    }
}

/// How a process-data integer maps to a physical value: `value = raw × num / den`, in
/// `unit`. Declared once on the entry ([`Limits::scale`]); the master decodes with it
/// (CSV headers in physical units), the firmware encodes with it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Scale {
    /// Unit of the scaled value (`"deg"`, `"A"`, `"%"`).
    pub unit: &'static str,
    /// Numerator of the factor from raw to unit.
    pub num: u32,
    /// Denominator of the factor from raw to unit.
    pub den: u32,
}

impl Scale {
    /// `raw / den` in `unit` (`Scale::per("deg", 100)`: the integer is hundredths of a degree).
    pub const fn per(unit: &'static str, den: u32) -> Self {
        Self { unit, num: 1, den }
    }

    /// `raw × num / den` in `unit`.
    pub const fn ratio(unit: &'static str, num: u32, den: u32) -> Self {
        Self { unit, num, den }
    }

    /// The physical value of a raw integer.
    pub fn value(&self, raw: f64) -> f64 {
        raw * f64::from(self.num) / f64::from(self.den)
    }

    /// The raw integer (unrounded) of a physical value.
    pub fn raw(&self, value: f64) -> f64 {
        value * f64::from(self.den) / f64::from(self.num)
    }

    /// Decimals that show every raw step exactly: `k` when the factor is `1 / 10^k`, else
    /// `None` (print the shortest exact form).
    pub const fn decimals(&self) -> Option<usize> {
        if self.num != 1 {
            return None;
        }
        let (mut d, mut k) = (self.den, 0);
        while d % 10 == 0 {
            d /= 10;
            k += 1;
        }
        if d == 1 {
            Some(k)
        } else {
            None
        }
    }
}

impl EntryDef {
    /// An entry of a scalar type with default 0.
    pub const fn new(sub: u8, name: &'static str, dtype: DataType, access: Access) -> Self {
        Self {
            sub,
            name,
            dtype,
            bits: dtype.bits(),
            access,
            pdo: PdoMapping::None,
            default_word: 0,
            limits: &Limits::NONE,
        }
    }

    /// A VISIBLE_STRING of at most `max_len` bytes.
    pub const fn string(sub: u8, name: &'static str, max_len: u16, access: Access) -> Self {
        let mut e = Self::new(sub, name, DataType::VisibleString, access);
        e.bits = max_len * 8;
        e
    }

    /// An OCTET_STRING of `len` bytes.
    pub const fn octets(sub: u8, name: &'static str, len: u16, access: Access) -> Self {
        let mut e = Self::new(sub, name, DataType::OctetString, access);
        e.bits = len * 8;
        e
    }

    /// With a default value given as raw little-endian bits. `v` must be what the entry's
    /// word extends to ([`EntryDef::fits_word`]: the low 32 bits sign-extended for a signed
    /// type, zero-extended else), else this panics (a build error in a `static`
    /// definition): a wider default goes in the limits ([`Limits::with_default`]).
    pub const fn default_bits(mut self, v: u64) -> Self {
        assert!(
            self.set_default_word(v),
            "a default beyond the entry's 32-bit word: use Limits::with_default"
        );
        self
    }

    /// With a signed default value ([`EntryDef::default_bits`] of its two's complement).
    pub const fn default_i64(self, v: i64) -> Self {
        self.default_bits(v as u64)
    }

    /// With a REAL32 default value.
    pub const fn default_f32(self, v: f32) -> Self {
        self.default_bits(v.to_bits() as u64)
    }

    /// Whether the entry's own word holds default `v`: `v` is its low 32 bits extended as
    /// the type says (sign for a signed type, zero else).
    pub const fn fits_word(&self, v: u64) -> bool {
        self.extend(v as u32) == v
    }

    /// Sets the default to `v` in the entry's word if it fits there ([`EntryDef::fits_word`];
    /// `true`), else leaves the entry unchanged (`false`: hand it in the limits,
    /// [`Limits::with_default`]). The entry's limits must not hold a default of their own.
    pub const fn set_default_word(&mut self, v: u64) -> bool {
        if !self.fits_word(v) {
            return false;
        }
        self.default_word = v as u32;
        true
    }

    /// A word extended as this entry's type says.
    const fn extend(&self, w: u32) -> u64 {
        if self.dtype.is_signed() {
            w as i32 as i64 as u64
        } else {
            w as u64
        }
    }

    /// The default value: the limits' ([`Limits::default`]) if they hold one, else the
    /// entry's word extended as its type says.
    pub const fn default(&self) -> DefaultValue {
        match self.limits.default {
            Some(d) => d,
            None => DefaultValue::bits(self.extend(self.default_word)),
        }
    }

    /// With PDO mappability.
    pub const fn pdo(mut self, m: PdoMapping) -> Self {
        self.pdo = m;
        self
    }

    /// With a unit and/or an allowed value range (integer entries), see [`Limits`].
    pub const fn limits(mut self, l: &'static Limits) -> Self {
        self.limits = l;
        self
    }

    /// Its physical scaling ([`Limits::scale`]), if any.
    pub const fn scale(&self) -> Option<&'static Scale> {
        self.limits.scale
    }

    /// Bytes this entry occupies in the image. Not inlined in a board image: every
    /// dictionary walk needs it (184 B of the demo image's flash as inlined copies); the
    /// two walks every lookup by index makes ([`ObjectDef::storage_len`] over the objects
    /// before it, [`Obj::entry`] over its entries) inline it ([`EntryDef::len_inline`]).
    #[cfg_attr(target_os = "none", inline(never))]
    pub const fn storage_len(&self) -> usize {
        self.len_inline()
    }

    /// [`EntryDef::storage_len`], inlined: for the walks on the path of a lookup by index
    /// (an application reads and writes its entries so, some on every cycle).
    #[inline(always)]
    pub(crate) const fn len_inline(&self) -> usize {
        if self.bits < 8 {
            1
        } else {
            self.bits.div_ceil(8) as usize
        }
    }
}

/// Entry `index:sub` of `objects`, usable in a `const` (a definition's tables are
/// `'static`): how generated tables and master-side decoders reach one declaration.
pub const fn find_entry(
    objects: &'static [ObjectDef],
    index: u16,
    sub: u8,
) -> Option<&'static EntryDef> {
    let mut i = 0;
    while i < objects.len() {
        if objects[i].index == index {
            let entries = objects[i].entries;
            let mut k = 0;
            while k < entries.len() {
                if entries[k].sub == sub {
                    return Some(&entries[k]);
                }
                k += 1;
            }
        }
        i += 1;
    }
    None
}

/// Object code (SDO information).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ObjectCode {
    /// A single value (7).
    Var,
    /// An array of entries of one type (8).
    Array,
    /// A record of entries (9).
    Record,
}

impl ObjectCode {
    /// The ETG object code.
    pub const fn code(self) -> u8 {
        match self {
            Self::Var => 7,
            Self::Array => 8,
            Self::Record => 9,
        }
    }
}

/// One object of the dictionary.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ObjectDef {
    /// Index.
    pub index: u16,
    /// Name.
    pub name: &'static str,
    /// Object code.
    pub code: ObjectCode,
    /// Entries in subindex order; a VAR has exactly one entry with subindex 0, ARRAY and
    /// RECORD start with subindex 0 (UNSIGNED8, highest subindex).
    pub entries: &'static [EntryDef],
}

impl ObjectDef {
    /// Bytes this object occupies in the image.
    pub const fn storage_len(&self) -> usize {
        let mut n = 0;
        let mut i = 0;
        while i < self.entries.len() {
            n += self.entries[i].len_inline();
            i += 1;
        }
        n
    }

    /// Highest subindex.
    pub const fn max_sub(&self) -> u8 {
        match self.entries.last() {
            Some(e) => e.sub,
            None => 0,
        }
    }

    /// Data type reported for the object (the entry type of a VAR/ARRAY, 0x2A-ish record
    /// types are not modelled: records report 0).
    pub const fn data_type(&self) -> u16 {
        match self.code {
            ObjectCode::Var => match self.entries.first() {
                Some(e) => e.dtype.code(),
                None => 0,
            },
            ObjectCode::Array => match self.entries.last() {
                Some(e) => e.dtype.code(),
                None => 0,
            },
            ObjectCode::Record => 0,
        }
    }
}

/// Image bytes needed for `objects` (use it to size the stack's image: `Slave<_, N>`).
pub const fn image_size(objects: &[ObjectDef]) -> usize {
    let mut n = 0;
    let mut i = 0;
    while i < objects.len() {
        n += objects[i].storage_len();
        i += 1;
    }
    n
}

/// Capacities of the stack. A microcontroller build keeps them small (the `Slave` value lives
/// in its RAM); the `twin-capacity` feature, which the std crates that serve twins of vendor
/// devices turn on, raises them to what vendor catalogues declare (EL3008's 8 × 10 mapped
/// entries, EL2819's 64-entry PDO, eleven PDOs assigned by default). Cargo features unify only
/// within one build: a board image, built on its own, keeps the small capacities. What a
/// device's dictionary *shows* does not depend on them (see [`MAP_SHOWN`], [`ASSIGN_SHOWN`]),
/// so the ESI generated on a host describes the dictionary of the board image.
#[cfg(not(feature = "twin-capacity"))]
mod cap {
    pub const PDOS: usize = 8;
    pub const PDO_ENTRIES: usize = 31;
    pub const ASSIGN: usize = 8;
}
#[cfg(feature = "twin-capacity")]
mod cap {
    pub const PDOS: usize = 32;
    pub const PDO_ENTRIES: usize = 80;
    pub const ASSIGN: usize = 32;
}

/// Maximum PDOs per direction.
pub const MAX_PDOS: usize = cap::PDOS;
/// Maximum entries per PDO mapping object (the TUeES030's 0x1A00 maps 28; 31 keeps a
/// mapping object, 1 + 4 × 31 bytes, within a 128-byte mailbox).
pub const MAX_PDO_ENTRIES: usize = cap::PDO_ENTRIES;
/// Maximum PDOs in one assignment object.
pub const MAX_ASSIGN: usize = cap::ASSIGN;
/// Subindexes a configurable PDO mapping object shows and accepts (unless its default
/// mapping has more): the same on every build, whatever [`MAX_PDO_ENTRIES`] is.
pub const MAP_SHOWN: usize = 31;
/// Subindexes a configurable assignment object (0x1C12/0x1C13) shows and accepts (unless
/// its default assignment has more): the same on every build, whatever [`MAX_ASSIGN`] is.
pub const ASSIGN_SHOWN: usize = 8;
const _: () = assert!(MAP_SHOWN <= MAX_PDO_ENTRIES && ASSIGN_SHOWN <= MAX_ASSIGN);
/// Maximum length in bytes of the 0x1008/0x1009/0x100A strings (the definition's name,
/// hardware and software version). [`Od::new`] refuses a longer one rather than serving it
/// cut, since ESI and SII carry the whole name.
pub const STR_MAX: u16 = 64;

const U8: DataType = DataType::Unsigned8;
const U16: DataType = DataType::Unsigned16;
const U32: DataType = DataType::Unsigned32;

const fn e(sub: u8, name: &'static str, t: DataType, a: Access) -> EntryDef {
    EntryDef::new(sub, name, t, a)
}

const MAP_NAMES: [&str; 80] = [
    "Mapped object 1",
    "Mapped object 2",
    "Mapped object 3",
    "Mapped object 4",
    "Mapped object 5",
    "Mapped object 6",
    "Mapped object 7",
    "Mapped object 8",
    "Mapped object 9",
    "Mapped object 10",
    "Mapped object 11",
    "Mapped object 12",
    "Mapped object 13",
    "Mapped object 14",
    "Mapped object 15",
    "Mapped object 16",
    "Mapped object 17",
    "Mapped object 18",
    "Mapped object 19",
    "Mapped object 20",
    "Mapped object 21",
    "Mapped object 22",
    "Mapped object 23",
    "Mapped object 24",
    "Mapped object 25",
    "Mapped object 26",
    "Mapped object 27",
    "Mapped object 28",
    "Mapped object 29",
    "Mapped object 30",
    "Mapped object 31",
    "Mapped object 32",
    "Mapped object 33",
    "Mapped object 34",
    "Mapped object 35",
    "Mapped object 36",
    "Mapped object 37",
    "Mapped object 38",
    "Mapped object 39",
    "Mapped object 40",
    "Mapped object 41",
    "Mapped object 42",
    "Mapped object 43",
    "Mapped object 44",
    "Mapped object 45",
    "Mapped object 46",
    "Mapped object 47",
    "Mapped object 48",
    "Mapped object 49",
    "Mapped object 50",
    "Mapped object 51",
    "Mapped object 52",
    "Mapped object 53",
    "Mapped object 54",
    "Mapped object 55",
    "Mapped object 56",
    "Mapped object 57",
    "Mapped object 58",
    "Mapped object 59",
    "Mapped object 60",
    "Mapped object 61",
    "Mapped object 62",
    "Mapped object 63",
    "Mapped object 64",
    "Mapped object 65",
    "Mapped object 66",
    "Mapped object 67",
    "Mapped object 68",
    "Mapped object 69",
    "Mapped object 70",
    "Mapped object 71",
    "Mapped object 72",
    "Mapped object 73",
    "Mapped object 74",
    "Mapped object 75",
    "Mapped object 76",
    "Mapped object 77",
    "Mapped object 78",
    "Mapped object 79",
    "Mapped object 80",
];

const ASSIGN_NAMES: [&str; 32] = [
    "PDO 1", "PDO 2", "PDO 3", "PDO 4", "PDO 5", "PDO 6", "PDO 7", "PDO 8", "PDO 9", "PDO 10",
    "PDO 11", "PDO 12", "PDO 13", "PDO 14", "PDO 15", "PDO 16", "PDO 17", "PDO 18", "PDO 19",
    "PDO 20", "PDO 21", "PDO 22", "PDO 23", "PDO 24", "PDO 25", "PDO 26", "PDO 27", "PDO 28",
    "PDO 29", "PDO 30", "PDO 31", "PDO 32",
];

const fn map_entries(a: Access) -> [EntryDef; MAX_PDO_ENTRIES + 1] {
    let mut out = [e(0, "Number of entries", U8, a); MAX_PDO_ENTRIES + 1];
    let mut i = 0;
    while i < MAX_PDO_ENTRIES {
        out[i + 1] = e(i as u8 + 1, MAP_NAMES[i], U32, a);
        i += 1;
    }
    out
}

const fn assign_entries(a: Access) -> [EntryDef; MAX_ASSIGN + 1] {
    let mut out = [e(0, "Number of assigned PDOs", U8, a); MAX_ASSIGN + 1];
    let mut i = 0;
    while i < MAX_ASSIGN {
        out[i + 1] = e(i as u8 + 1, ASSIGN_NAMES[i], U16, a);
        i += 1;
    }
    out
}

/// A template (subindex 0 and the entry standing for 1..n) describes its table's entries:
/// subindex 0 the same, and the entry the same type, size and access as subindex 1.
const fn template_matches(t: &[EntryDef; 2], r: &[EntryDef]) -> bool {
    t[0].sub == r[0].sub
        && t[0].bits == r[0].bits
        && t[0].access.0 == r[0].access.0
        && t[0].dtype.code() == r[0].dtype.code()
        && t[1].bits == r[1].bits
        && t[1].access.0 == r[1].access.0
        && t[1].dtype.code() == r[1].dtype.code()
}

/// A mapping object's entries, one per subindex, as the dictionary listing
/// ([`Od::object_info`], what the ESI is generated from) shows them: a table only host
/// tools link. The stack serves the same entries from [`MAP_TEMPLATE`].
static MAP_RW: [EntryDef; MAX_PDO_ENTRIES + 1] = map_entries(Access::RW_PREOP);
static MAP_RO: [EntryDef; MAX_PDO_ENTRIES + 1] = map_entries(Access::RO);
/// What the stack serves a mapping object from: subindex 0 and one entry that stands for
/// subindexes 1..=n, named "Mapped object N" (its name followed by the subindex): two
/// entries in a board image's flash instead of 32 (1.4 KB) and 31 names.
static MAP_TEMPLATE: [EntryDef; 2] = [
    e(0, "Number of entries", U8, Access::RW_PREOP),
    e(1, "Mapped object ", U32, Access::RW_PREOP),
];
// The template is the table: the same entry but for the subindex and the name's number.
const _: () = assert!(template_matches(
    &MAP_TEMPLATE,
    &map_entries(Access::RW_PREOP)
));
/// An assignment object's entries, one per subindex, as the dictionary listing shows them
/// (host tools only, as [`MAP_RW`]); the stack serves them from [`ASSIGN_TEMPLATE`].
static ASSIGN_RW: [EntryDef; MAX_ASSIGN + 1] = assign_entries(Access::RW_PREOP);
static ASSIGN_RO: [EntryDef; MAX_ASSIGN + 1] = assign_entries(Access::RO);
/// What the stack serves 0x1C12/0x1C13 from: subindex 0 and one entry for subindexes
/// 1..=n, named "PDO N".
static ASSIGN_TEMPLATE: [EntryDef; 2] = [
    e(0, "Number of assigned PDOs", U8, Access::RW_PREOP),
    e(1, "PDO ", U16, Access::RW_PREOP),
];
/// Bytes an assignment object takes in the communication image (room for [`MAX_ASSIGN`]).
const ASSIGN_STORAGE: usize = 1 + 2 * MAX_ASSIGN;
const _: () = {
    let (t, r) = (&ASSIGN_TEMPLATE, &assign_entries(Access::RW_PREOP));
    assert!(template_matches(t, r));
    let mut n = 0;
    let mut i = 0;
    while i < r.len() {
        n += r[i].storage_len();
        i += 1;
    }
    assert!(n == ASSIGN_STORAGE);
};

const fn sync_par_entries() -> [EntryDef; 12] {
    [
        e(0, "Number of entries", U8, Access::RO).default_bits(0x20),
        e(1, "Sync mode", U16, Access::RW_PREOP),
        e(2, "Cycle time", U32, Access::RW_PREOP),
        e(3, "Shift time", U32, Access::RO),
        e(4, "Sync modes supported", U16, Access::RO),
        e(5, "Minimum cycle time", U32, Access::RO),
        e(6, "Calc and copy time", U32, Access::RO),
        e(8, "Get cycle time", U16, Access::RW),
        e(9, "Delay time", U32, Access::RO),
        e(0x0B, "SM event missed counter", U16, Access::RO),
        e(0x0C, "Cycle time too small counter", U16, Access::RO),
        // Mappable into TxPDOs (ETG.1020; Beckhoff's encoder terminals map 0x1C32:20).
        e(0x20, "Sync error", DataType::Bool, Access::RO).pdo(PdoMapping::Tx),
    ]
}

static SYNC_PAR: [EntryDef; 12] = sync_par_entries();

/// The communication objects defined by the stack (values derived from the definition).
static COMM_LOW: [ObjectDef; 7] = [
    ObjectDef {
        index: 0x1000,
        name: "Device type",
        code: ObjectCode::Var,
        entries: &[e(0, "Device type", U32, Access::RO)],
    },
    ObjectDef {
        index: 0x1001,
        name: "Error register",
        code: ObjectCode::Var,
        entries: &[e(0, "Error register", U8, Access::RO)],
    },
    ObjectDef {
        index: 0x1008,
        name: "Device name",
        code: ObjectCode::Var,
        entries: &[EntryDef::string(0, "Device name", STR_MAX, Access::RO)],
    },
    ObjectDef {
        index: 0x1009,
        name: "Hardware version",
        code: ObjectCode::Var,
        entries: &[EntryDef::string(0, "Hardware version", STR_MAX, Access::RO)],
    },
    ObjectDef {
        index: 0x100A,
        name: "Software version",
        code: ObjectCode::Var,
        entries: &[EntryDef::string(0, "Software version", STR_MAX, Access::RO)],
    },
    ObjectDef {
        index: 0x1018,
        name: "Identity",
        code: ObjectCode::Record,
        entries: &[
            e(0, "Number of entries", U8, Access::RO).default_bits(4),
            e(1, "Vendor ID", U32, Access::RO),
            e(2, "Product code", U32, Access::RO),
            e(3, "Revision", U32, Access::RO),
            e(4, "Serial number", U32, Access::RO),
        ],
    },
    ObjectDef {
        index: 0x10F1,
        name: "Error settings",
        code: ObjectCode::Record,
        entries: &[
            e(0, "Number of entries", U8, Access::RO).default_bits(2),
            e(1, "Local error reaction", U32, Access::RW),
            e(2, "Sync error counter limit", U16, Access::RW).default_bits(4),
        ],
    },
];

static COMM_HIGH: [ObjectDef; 5] = [
    ObjectDef {
        index: 0x1C00,
        name: "Sync manager type",
        code: ObjectCode::Array,
        entries: &[
            e(0, "Number of used sync manager channels", U8, Access::RO).default_bits(4),
            e(1, "SM 0", U8, Access::RO).default_bits(1),
            e(2, "SM 1", U8, Access::RO).default_bits(2),
            e(3, "SM 2", U8, Access::RO).default_bits(3),
            e(4, "SM 3", U8, Access::RO).default_bits(4),
        ],
    },
    ObjectDef {
        index: 0x1C12,
        name: "RxPDO assign",
        code: ObjectCode::Array,
        entries: &ASSIGN_TEMPLATE,
    },
    ObjectDef {
        index: 0x1C13,
        name: "TxPDO assign",
        code: ObjectCode::Array,
        entries: &ASSIGN_TEMPLATE,
    },
    ObjectDef {
        index: 0x1C32,
        name: "SM output parameter",
        code: ObjectCode::Record,
        entries: &SYNC_PAR,
    },
    ObjectDef {
        index: 0x1C33,
        name: "SM input parameter",
        code: ObjectCode::Record,
        entries: &SYNC_PAR,
    },
];

/// Bytes a communication object takes in the communication image: an assignment object
/// room for [`MAX_ASSIGN`] PDOs (its definition is the template), the others their entries.
const fn comm_storage(o: &ObjectDef) -> usize {
    if is_assign(o.index) {
        ASSIGN_STORAGE
    } else {
        o.storage_len()
    }
}

/// 0x1C12 or 0x1C13.
const fn is_assign(index: u16) -> bool {
    index == 0x1C12 || index == 0x1C13
}

/// Bytes `objs` take in the communication image.
const fn comm_size(objs: &[ObjectDef]) -> usize {
    let mut n = 0;
    let mut i = 0;
    while i < objs.len() {
        n += comm_storage(&objs[i]);
        i += 1;
    }
    n
}

const COMM_LOW_SIZE: usize = comm_size(&COMM_LOW);
const COMM_HIGH_SIZE: usize = comm_size(&COMM_HIGH);

/// Image offset of each object of `objs` (the sum of the sizes before it), at build time.
const fn bases<const K: usize>(objs: &[ObjectDef; K]) -> [usize; K] {
    let mut b = [0; K];
    let mut i = 1;
    while i < K {
        b[i] = b[i - 1] + comm_storage(&objs[i - 1]);
        i += 1;
    }
    b
}
/// Image offsets of [`COMM_LOW`]'s objects.
static COMM_LOW_BASE: [usize; COMM_LOW.len()] = bases(&COMM_LOW);
/// Image offsets of [`COMM_HIGH`]'s objects (from the end of [`COMM_LOW`]'s).
static COMM_HIGH_BASE: [usize; COMM_HIGH.len()] = bases(&COMM_HIGH);
/// Bytes the PDO mapping objects of a definition may take in the communication image, a
/// pool each definition lays its own out in ([`map_storage`]): a fixed mapping takes
/// 1 + 4 bytes per entry, a configurable one 1 + 4 × [`MAP_SHOWN`] (or its default's count).
/// 512 bytes on a microcontroller build (the devices here need 90..364: TUeES030 364,
/// testkit 271, CiA402 250, Laelaps 143, demo 106, hub 90; was 16 slots of 31 entries,
/// 2,000 bytes, whatever the device); with `twin-capacity` every PDO at the full capacity.
pub const MAP_POOL: usize = if cfg!(feature = "twin-capacity") {
    2 * MAX_PDOS * (1 + 4 * MAX_PDO_ENTRIES)
} else {
    MAP_POOL_MCU
};
/// [`MAP_POOL`] of a microcontroller build (without `twin-capacity`), whatever this build's
/// is: a board's device must fit it (host tests check the devices of `oxicat-devices`).
pub const MAP_POOL_MCU: usize = 512;
/// Bytes of the internal image of the communication objects.
pub const COMM_IMAGE_SIZE: usize = COMM_LOW_SIZE + COMM_HIGH_SIZE + MAP_POOL;

/// Subindexes (after 0) the mapping object of `p` shows and stores.
pub(crate) const fn map_shown(p: &PdoDef) -> usize {
    let n = p.entries.len();
    if !p.configurable {
        n
    } else if n < MAP_SHOWN {
        MAP_SHOWN
    } else if n > MAX_PDO_ENTRIES {
        MAX_PDO_ENTRIES
    } else {
        n
    }
}

/// Bytes one mapping object of `p` takes in the communication image.
const fn map_obj_size(p: &PdoDef) -> usize {
    1 + 4 * map_shown(p)
}

/// Bytes `def`'s PDO mapping objects take in the communication image (at most
/// [`MAP_POOL`]).
pub const fn map_storage(def: &DeviceDef) -> usize {
    let mut n = 0;
    let mut i = 0;
    while i < def.rx_pdos.len() {
        n += map_obj_size(&def.rx_pdos[i]);
        i += 1;
    }
    i = 0;
    while i < def.tx_pdos.len() {
        n += map_obj_size(&def.tx_pdos[i]);
        i += 1;
    }
    n
}

/// Which image an object's values live in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Area {
    App,
    Comm,
}

/// What an object is, for the special write rules.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Kind {
    Plain,
    RxMap,
    TxMap,
    RxAssign,
    TxAssign,
    SyncPar,
}

/// The entries of a resolved object ([`Obj`]): a table of one [`EntryDef`] per subindex,
/// or (a PDO mapping object) subindex 0 and one template entry that stands for subindexes
/// 1..=n, each with its own subindex and named as the template followed by the subindex.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Entries {
    table: &'static [EntryDef],
    /// `table` is subindex 0 and a template (`table[1]`) …
    template: bool,
    /// … that stands for subindexes 1..=n.
    n: u8,
}

impl Entries {
    /// One entry per subindex.
    pub const fn table(table: &'static [EntryDef]) -> Self {
        Self {
            table,
            template: false,
            n: 0,
        }
    }

    /// Subindex 0 (`t[0]`) and subindexes 1..=`n` from the template `t[1]`.
    const fn template(t: &'static [EntryDef; 2], n: u8) -> Self {
        Self {
            table: t,
            template: true,
            n,
        }
    }

    /// Number of entries.
    pub fn len(self) -> usize {
        if !self.template {
            self.table.len()
        } else {
            1 + self.n as usize
        }
    }

    /// The `i`-th entry: its subindex and definition (for a template entry the template's,
    /// whose own subindex is not the entry's).
    pub fn get(self, i: usize) -> Option<(u8, &'static EntryDef)> {
        if !self.template {
            self.table.get(i).map(|e| (e.sub, e))
        } else if i == 0 {
            self.table.first().map(|e| (0, e))
        } else if i <= self.n as usize {
            self.table.get(1).map(|e| (i as u8, e))
        } else {
            None
        }
    }

    /// The entries in subindex order, with their subindexes.
    pub fn iter(self) -> impl Iterator<Item = (u8, &'static EntryDef)> {
        (0..self.len()).filter_map(move |i| self.get(i))
    }

    /// The distinct definitions of the entries (each once: a template's once for all its
    /// subindexes), for a question about any entry of the object.
    pub fn defs(self) -> &'static [EntryDef] {
        if self.template && self.n == 0 {
            &self.table[..1]
        } else {
            self.table
        }
    }

    /// The last entry.
    pub fn last(self) -> Option<(u8, &'static EntryDef)> {
        self.len().checked_sub(1).and_then(|i| self.get(i))
    }

    /// Writes the name of entry `sub` (`e`, as [`Entries::get`] gives it) into `out`, cut
    /// to its length; returns the bytes written. A template entry's name is the template's
    /// followed by the subindex in decimal ("Mapped object 7").
    pub fn name_into(self, sub: u8, e: &EntryDef, out: &mut [u8]) -> usize {
        let name = e.name.as_bytes();
        let mut n = name.len().min(out.len());
        out[..n].copy_from_slice(&name[..n]);
        if self.template && sub != 0 {
            let digits = [sub / 100, sub / 10 % 10, sub % 10];
            let first = if sub >= 100 {
                0
            } else if sub >= 10 {
                1
            } else {
                2
            };
            for d in &digits[first..] {
                if n < out.len() {
                    out[n] = b'0' + d;
                    n += 1;
                }
            }
        }
        n
    }
}

/// A resolved object: its definition and where its values are.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Obj {
    pub index: u16,
    pub name: &'static str,
    pub code: ObjectCode,
    pub entries: Entries,
    pub area: Area,
    pub base: usize,
    pub kind: Kind,
    /// Read-only in every state whatever its entries say: the mapping and assignment
    /// objects of a fixed mapping or assignment share one table with the configurable
    /// ones (one copy in flash instead of a read-only and a read-write one).
    pub read_only: bool,
}

impl Obj {
    /// Position and image offset of subindex `sub`.
    pub fn entry(&self, sub: u8) -> Option<(usize, &'static EntryDef, usize)> {
        let mut off = self.base;
        for (i, (s, e)) in self.entries.iter().enumerate() {
            if s == sub {
                return Some((i, e, off));
            }
            off += e.len_inline();
        }
        None
    }

    /// Highest defined subindex.
    pub fn max_sub(&self) -> u8 {
        self.entries.last().map_or(0, |(s, _)| s)
    }

    /// Access rights of entry `e` of this object.
    pub fn access(&self, e: &EntryDef) -> Access {
        if self.read_only {
            Access::RO
        } else {
            e.access
        }
    }
}

/// Result of [`Od::locate`].
enum Located {
    /// A communication object (its image offset is known at build time).
    Comm(Obj),
    /// The application object at this position of the definition.
    App(usize),
}

/// [`Od::find`] for a run of lookups, such as compiling a PDO mapping when the master
/// requests SAFEOP. An application object's image offset is the sum of the sizes of the
/// objects before it; a finder keeps where its last lookup ended and walks on from there,
/// so lookups in index order (a mapping's usual order) walk the application objects once
/// in all instead of once each. On a 180 MHz Cortex-M4 the per-lookup walk made PREOP →
/// SAFEOP of the Laelaps leg outlast a 400 µs SYNC0 cycle.
pub(crate) struct Finder<'a, const N: usize> {
    od: &'a Od<N>,
    /// Position of the application object the walk stands at …
    at: usize,
    /// … and its image offset.
    base: usize,
}

impl<const N: usize> Finder<'_, N> {
    /// Object `index`, as [`Od::find`] gives it. Not inlined in a board image: it is
    /// [`Od::find`] too.
    #[cfg_attr(target_os = "none", inline(never))]
    pub(crate) fn find(&mut self, index: u16) -> Option<Obj> {
        match self.od.locate(index)? {
            Located::Comm(o) => Some(o),
            Located::App(i) => {
                if i < self.at {
                    (self.at, self.base) = (0, 0);
                }
                let objects = self.od.def().objects;
                self.base += objects[self.at..i]
                    .iter()
                    .map(|o| o.storage_len())
                    .sum::<usize>();
                self.at = i;
                Some(self.od.app_obj(i, self.base))
            }
        }
    }
}

/// Public description of one object of an [`Od`] ([`Od::object_info`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ObjectInfo {
    /// Index.
    pub index: u16,
    /// Name.
    pub name: &'static str,
    /// Object code.
    pub code: ObjectCode,
    /// Entries in subindex order.
    pub entries: &'static [EntryDef],
}

/// Why a typed dictionary access failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OdError {
    /// No such object.
    NoObject,
    /// No such subindex.
    NoSubindex,
    /// The entry's bit length does not match the requested type.
    TypeMismatch,
}

/// A resolved entry for fast repeated typed access ([`Od::read`], [`Od::write`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EntryRef {
    area_app: bool,
    offset: usize,
    len: usize,
    bits: u16,
}

impl EntryRef {
    /// A zero-length reference (all bytes zero), a placeholder until resolved.
    pub(crate) const BLANK: Self = Self {
        area_app: false,
        offset: 0,
        len: 0,
        bits: 0,
    };

    /// Bit length of the entry.
    pub fn bits(&self) -> u16 {
        self.bits
    }
}

/// A typed handle on one dictionary entry, resolved and type-checked once ([`Od::var`]):
/// [`Od::load`] and [`Od::store`] are then a plain offset access, no lookup by index.
/// Resolve handles when the application starts (e.g. on PREOP -> SAFEOP), not per cycle.
#[derive(Debug, PartialEq, Eq)]
pub struct Var<T: OdType> {
    r: EntryRef,
    _t: core::marker::PhantomData<fn() -> T>,
}

impl<T: OdType> Clone for Var<T> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<T: OdType> Copy for Var<T> {}

impl<T: OdType> Var<T> {
    /// The untyped entry reference.
    pub fn entry(&self) -> EntryRef {
        self.r
    }

    /// The handle on `index:sub` of a device's application objects (its
    /// [`DeviceDef::objects`](crate::DeviceDef)), computed from the declaration when the
    /// crate is built: no lookup at run time, and a missing entry or an entry whose CoE type
    /// is not `T`'s stops the build (in a `const`). Valid for the dictionary built from
    /// that definition ([`Od::new`] lays the application objects out in declaration order).
    ///
    /// ```
    /// use oxicat_slave::{Access, DataType, EntryDef, ObjectCode, ObjectDef, Var};
    /// static OBJECTS: &[ObjectDef] = &[ObjectDef {
    ///     index: 0x6000,
    ///     name: "Inputs",
    ///     code: ObjectCode::Record,
    ///     entries: &[
    ///         EntryDef::new(0, "SubIndex 000", DataType::Unsigned8, Access::RO),
    ///         EntryDef::new(1, "Angle", DataType::Int16, Access::RO),
    ///     ],
    /// }];
    /// const ANGLE: Var<i16> = Var::of(OBJECTS, 0x6000, 1);
    /// assert_eq!(ANGLE.entry().bits(), 16);
    /// ```
    ///
    /// A wrong type does not build:
    ///
    /// ```compile_fail
    /// # use oxicat_slave::{Access, DataType, EntryDef, ObjectCode, ObjectDef, Var};
    /// # static OBJECTS: &[ObjectDef] = &[ObjectDef { index: 0x6000, name: "Inputs",
    /// #     code: ObjectCode::Record, entries: &[
    /// #         EntryDef::new(0, "SubIndex 000", DataType::Unsigned8, Access::RO),
    /// #         EntryDef::new(1, "Angle", DataType::Int16, Access::RO)] }];
    /// const ANGLE: Var<u16> = Var::of(OBJECTS, 0x6000, 1);
    /// # let _ = ANGLE;
    /// ```
    pub const fn of(objects: &[ObjectDef], index: u16, sub: u8) -> Self {
        let mut base = 0;
        let mut i = 0;
        while i < objects.len() {
            let o = &objects[i];
            if o.index == index {
                let mut off = base;
                let mut j = 0;
                while j < o.entries.len() {
                    let e = &o.entries[j];
                    if e.sub == sub {
                        assert!(
                            e.dtype.code() == T::DTYPE.code() && e.bits == T::BITS,
                            "typed handle: the entry's CoE type is not the handle's"
                        );
                        return Var {
                            r: EntryRef {
                                area_app: true,
                                offset: off,
                                len: e.storage_len(),
                                bits: e.bits,
                            },
                            _t: core::marker::PhantomData,
                        };
                    }
                    off += e.storage_len();
                    j += 1;
                }
                panic!("typed handle: the object has no such subindex");
            }
            base += o.storage_len();
            i += 1;
        }
        panic!("typed handle: no such application object")
    }

    /// Handles on `N` consecutive subindexes of one object, from `first_sub` (an array of
    /// samples, a record's run of like entries); as [`Var::of`].
    pub const fn subs<const N: usize>(
        objects: &[ObjectDef],
        index: u16,
        first_sub: u8,
    ) -> [Self; N] {
        let mut out = [Self::of(objects, index, first_sub); N];
        let mut k = 1;
        while k < N {
            out[k] = Self::of(objects, index, first_sub + k as u8);
            k += 1;
        }
        out
    }

    /// Handles on subindex `sub` of `N` consecutive objects from `first_index` (records
    /// repeated per channel: motor 1, 2, 3); as [`Var::of`].
    pub const fn across<const N: usize>(
        objects: &[ObjectDef],
        first_index: u16,
        sub: u8,
    ) -> [Self; N] {
        let mut out = [Self::of(objects, first_index, sub); N];
        let mut k = 1;
        while k < N {
            out[k] = Self::of(objects, first_index + k as u16, sub);
            k += 1;
        }
        out
    }
}

/// Rust types that map onto CoE scalar types for typed access.
pub trait OdType: Copy {
    /// Bit length the entry must have.
    const BITS: u16;
    /// The CoE type a [`Var::of`] handle's entry must have.
    const DTYPE: DataType;
    /// Decodes from the little-endian image bytes (exactly the storage length).
    fn from_le(b: &[u8]) -> Self;
    /// Encodes into the image bytes.
    fn to_le(self, b: &mut [u8]);
}

macro_rules! od_type {
    ($t:ty, $bits:expr, $dt:ident) => {
        impl OdType for $t {
            const BITS: u16 = $bits;
            const DTYPE: DataType = DataType::$dt;
            #[inline]
            fn from_le(b: &[u8]) -> Self {
                // The common case, an entry of the type's size, as one load (the general
                // copy has a run-time length: a `memcpy` call per access on the host).
                if let Ok(a) = <[u8; core::mem::size_of::<$t>()]>::try_from(b) {
                    return <$t>::from_le_bytes(a);
                }
                let mut a = [0u8; core::mem::size_of::<$t>()];
                let n = a.len().min(b.len());
                a[..n].copy_from_slice(&b[..n]);
                <$t>::from_le_bytes(a)
            }
            #[inline]
            fn to_le(self, b: &mut [u8]) {
                let a = self.to_le_bytes();
                if let Ok(d) = <&mut [u8; core::mem::size_of::<$t>()]>::try_from(&mut *b) {
                    *d = a;
                    return;
                }
                let n = a.len().min(b.len());
                b[..n].copy_from_slice(&a[..n]);
            }
        }
    };
}
od_type!(u8, 8, Unsigned8);
od_type!(i8, 8, Int8);
od_type!(u16, 16, Unsigned16);
od_type!(i16, 16, Int16);
od_type!(u32, 32, Unsigned32);
od_type!(i32, 32, Int32);
od_type!(u64, 64, Unsigned64);
od_type!(i64, 64, Int64);
od_type!(f32, 32, Real32);
od_type!(f64, 64, Real64);

impl OdType for bool {
    const BITS: u16 = 1;
    const DTYPE: DataType = DataType::Bool;
    fn from_le(b: &[u8]) -> Self {
        b.first().is_some_and(|v| v & 1 != 0)
    }
    fn to_le(self, b: &mut [u8]) {
        if let Some(v) = b.first_mut() {
            *v = u8::from(self);
        }
    }
}

/// The Rust type of each scalar [`DataType`], under the variant's name, so that a
/// declaration naming the CoE type (`Int16`) can name its typed handle
/// (`Var<ty::Int16>` = `Var<i16>`); used by the devices' `pd_table!`.
pub mod ty {
    /// BOOLEAN.
    pub type Bool = bool;
    /// INTEGER8.
    pub type Int8 = i8;
    /// INTEGER16.
    pub type Int16 = i16;
    /// INTEGER32.
    pub type Int32 = i32;
    /// INTEGER64.
    pub type Int64 = i64;
    /// UNSIGNED8.
    pub type Unsigned8 = u8;
    /// UNSIGNED16.
    pub type Unsigned16 = u16;
    /// UNSIGNED32.
    pub type Unsigned32 = u32;
    /// UNSIGNED64.
    pub type Unsigned64 = u64;
    /// REAL32.
    pub type Real32 = f32;
    /// REAL64.
    pub type Real64 = f64;
}

/// Why a definition cannot be used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DefError {
    /// The image `N` is smaller than the definition needs.
    ImageTooSmall {
        /// Bytes needed.
        needed: usize,
    },
    /// Application objects must be sorted, unique and >= 0x2000.
    BadObjectOrder(u16),
    /// An object's entries are not in ascending subindex order / a VAR is malformed.
    BadEntries(u16),
    /// Too many PDOs, PDO entries or assigned PDOs, or a PDO index in the wrong range.
    BadPdo(u16),
    /// The string of 0x1008/0x1009/0x100A (name, hardware or software version) is longer
    /// than [`STR_MAX`] bytes.
    StringTooLong(u16),
    /// The PDO mapping objects need more than the stack's [`MAP_POOL`] bytes.
    MappingsTooLarge {
        /// Bytes the definition's mapping objects need ([`map_storage`]).
        needed: usize,
    },
}

impl core::fmt::Display for DefError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::ImageTooSmall { needed } => {
                write!(f, "the object image is too small: the definition needs {needed} bytes")
            }
            Self::BadObjectOrder(i) => write!(
                f,
                "object 0x{i:04X}: application objects must be sorted and unique, at 0x1000 or above and not where the stack's own objects are (0x1000/01/08/09/0A, 0x1018, 0x10F1, 0x1600-0x17FF, 0x1A00-0x1BFF, 0x1C00-0x1C3F)"
            ),
            Self::BadEntries(i) => write!(
                f,
                "object 0x{i:04X}: entries must be in ascending subindex order"
            ),
            Self::BadPdo(i) => write!(
                f,
                "PDO 0x{i:04X}: too many PDOs, entries or assigned PDOs, or an index outside 0x1600-0x17FF / 0x1A00-0x1BFF"
            ),
            Self::StringTooLong(i) => write!(
                f,
                "the string of 0x{i:04X} is longer than the {STR_MAX} bytes the object dictionary holds"
            ),
            Self::MappingsTooLarge { needed } => write!(
                f,
                "the PDO mapping objects need {needed} bytes; the stack holds {MAP_POOL} (a configurable PDO takes 1 + 4 x {MAP_SHOWN}, a fixed one 1 + 4 per entry)"
            ),
        }
    }
}

/// The object dictionary of one device: definition plus value images.
pub struct Od<const N: usize> {
    /// `None` only in [`Od::blank`] (so a blank stack is all zero bytes).
    def: Option<&'static DeviceDef>,
    pub(crate) app: [u8; N],
    pub(crate) comm: [u8; COMM_IMAGE_SIZE],
}

impl<const N: usize> Od<N> {
    /// Checks the definition and fills both images with the default values.
    pub fn new(def: &'static DeviceDef) -> Result<Self, DefError> {
        let mut od = Self::blank();
        od.init(def)?;
        Ok(od)
    }

    /// An image without a definition, all bytes zero ([`Od::init`] makes it a dictionary).
    pub(crate) const fn blank() -> Self {
        Self {
            def: None,
            app: [0; N],
            comm: [0; COMM_IMAGE_SIZE],
        }
    }

    /// [`Od::new`] in place (the images filled where they are, no copy on the stack).
    pub(crate) fn init(&mut self, def: &'static DeviceDef) -> Result<(), DefError> {
        check_def(def, N)?;
        self.init_checked(CheckedDef(def));
        Ok(())
    }

    /// [`Od::init`] for a definition checked when the image was built.
    pub(crate) fn init_checked(&mut self, def: CheckedDef<N>) {
        self.def = Some(def.0);
        self.reset_defaults();
    }

    /// The device definition. Not inlined in a board image: its blank-dictionary branch
    /// was copied into every caller (140 B of the demo image's flash). Inlined on a host.
    ///
    /// A blank dictionary is never handed out (a [`crate::Slave`] is made by
    /// [`crate::Slave::new`], a [`crate::SlaveSlot`] hands its stack out after `init`, which
    /// sets the definition first): it has no definition to give, and this panics. It stood
    /// on a blank `DeviceDef` (256 B of flash in every image) before.
    #[cfg_attr(target_os = "none", inline(never))]
    pub fn def(&self) -> &'static DeviceDef {
        match self.def {
            Some(d) => d,
            None => unreachable!("a blank object dictionary has no definition"),
        }
    }

    /// True when this dictionary's application objects are laid out as `objects` (the
    /// same indices and, per entry, subindex, type and bit length): the condition under
    /// which build-time handles ([`Var::of`] on `objects`) are valid for it. Compared by
    /// content, since the address of a static's data is not a reliable identity.
    pub fn built_on(&self, objects: &[ObjectDef]) -> bool {
        let mine = self.def().objects;
        mine.len() == objects.len()
            && mine.iter().zip(objects).all(|(a, b)| {
                a.index == b.index
                    && a.entries.len() == b.entries.len()
                    && a.entries
                        .iter()
                        .zip(b.entries)
                        .all(|(x, y)| x.sub == y.sub && x.dtype == y.dtype && x.bits == y.bits)
            })
    }

    /// Resets every value (application and communication objects) to its default: each
    /// entry of each object the dictionary serves to what [`Od::default_of`] says (the one
    /// place the defaults are derived, for the images and for SDO information alike), the
    /// room no entry uses to zero.
    pub fn reset_defaults(&mut self) {
        self.app.fill(0);
        self.comm.fill(0);
        let d = self.def();
        let total = self.object_count();
        let comm = total - d.objects.len();
        // Application objects with a running image offset (`object_at` would sum the sizes
        // of the objects before each one again).
        let mut app_base = 0;
        for n in 0..total {
            let o = if n < comm {
                match self.object_at(n) {
                    Some(o) => o,
                    None => continue,
                }
            } else {
                let o = self.app_obj(n - comm, app_base);
                app_base += d.objects[n - comm].storage_len();
                o
            };
            let mut off = o.base;
            for (sub, e) in o.entries.iter() {
                let len = e.storage_len();
                let img: &mut [u8] = match o.area {
                    Area::App => &mut self.app,
                    Area::Comm => &mut self.comm,
                };
                if let Some(dst) = img.get_mut(off..off + len) {
                    default_into(d, &o, sub, e, dst);
                }
                off += len;
            }
        }
    }

    /// Number of objects (communication + application).
    pub fn object_count(&self) -> usize {
        COMM_LOW.len()
            + self.def().rx_pdos.len()
            + self.def().tx_pdos.len()
            + COMM_HIGH.len()
            + self.def().objects.len()
    }

    /// The `n`-th object in index order.
    pub(crate) fn object_at(&self, n: usize) -> Option<Obj> {
        let d = self.def();
        let mut n = n;
        if n < COMM_LOW.len() {
            return Some(self.comm_obj(&COMM_LOW[n], comm_low_base(n), Kind::Plain));
        }
        n -= COMM_LOW.len();
        if n < d.rx_pdos.len() {
            return Some(self.map_obj(&d.rx_pdos[n], n, Kind::RxMap));
        }
        n -= d.rx_pdos.len();
        if n < d.tx_pdos.len() {
            return Some(self.map_obj(&d.tx_pdos[n], d.rx_pdos.len() + n, Kind::TxMap));
        }
        n -= d.tx_pdos.len();
        if n < COMM_HIGH.len() {
            let o = &COMM_HIGH[n];
            let kind = match o.index {
                0x1C12 => Kind::RxAssign,
                0x1C13 => Kind::TxAssign,
                0x1C32 | 0x1C33 => Kind::SyncPar,
                _ => Kind::Plain,
            };
            let mut r = self.comm_obj(o, COMM_LOW_SIZE + comm_high_base(n), kind);
            if matches!(kind, Kind::RxAssign | Kind::TxAssign) {
                let len = if kind == Kind::RxAssign {
                    d.rx_assign.len()
                } else {
                    d.tx_assign.len()
                };
                // A fixed assignment shows only its entries, read-only; a configurable
                // one ASSIGN_SHOWN slots, or as many as its default assignment fills.
                r.read_only = !d.assign_configurable;
                let shown = if d.assign_configurable {
                    len.clamp(ASSIGN_SHOWN, MAX_ASSIGN)
                } else {
                    len
                };
                r.entries = Entries::template(&ASSIGN_TEMPLATE, shown as u8);
            }
            return Some(r);
        }
        n -= COMM_HIGH.len();
        (n < d.objects.len()).then(|| self.app_obj(n, self.app_base(n)))
    }

    /// Image offset of the `i`-th application object: the sizes of those before it.
    fn app_base(&self, i: usize) -> usize {
        self.def().objects[..i]
            .iter()
            .map(|o| o.storage_len())
            .sum()
    }

    /// The `i`-th application object, its image offset `base`.
    fn app_obj(&self, i: usize, base: usize) -> Obj {
        let o = &self.def().objects[i];
        Obj {
            index: o.index,
            name: o.name,
            code: o.code,
            entries: Entries::table(o.entries),
            area: Area::App,
            base,
            kind: Kind::Plain,
            read_only: false,
        }
    }

    fn comm_obj(&self, o: &'static ObjectDef, base: usize, kind: Kind) -> Obj {
        Obj {
            index: o.index,
            name: o.name,
            code: o.code,
            entries: Entries::table(o.entries),
            area: Area::Comm,
            base,
            kind,
            read_only: false,
        }
    }

    fn map_obj(&self, p: &'static PdoDef, slot: usize, kind: Kind) -> Obj {
        // One template for fixed and configurable mappings: a fixed one is read-only
        // through `Obj::read_only`.
        let entries = Entries::template(&MAP_TEMPLATE, map_shown(p) as u8);
        // The mapping objects lie in definition order (RxPDOs, then TxPDOs), each its size.
        let d = self.def();
        let before: usize = d
            .rx_pdos
            .iter()
            .chain(d.tx_pdos.iter())
            .take(slot)
            .map(map_obj_size)
            .sum();
        Obj {
            index: p.index,
            name: p.name,
            code: ObjectCode::Record,
            entries,
            area: Area::Comm,
            base: COMM_LOW_SIZE + COMM_HIGH_SIZE + before,
            kind,
            read_only: !p.configurable,
        }
    }

    /// Writes the default value of entry `sub` (`e`) of `o` (as [`Od::reset_defaults`] sets
    /// it: from the definition, including the values derived from the [`DeviceDef`]) into
    /// `out` (its storage length, little endian).
    pub(crate) fn default_of(&self, o: &Obj, sub: u8, e: &EntryDef, out: &mut [u8]) {
        default_into(self.def(), o, sub, e, out);
    }

    /// The `n`-th object in index order (communication and application objects), as the
    /// SDO information service lists it; for listings such as the ESI dictionary.
    pub fn object_info(&self, n: usize) -> Option<ObjectInfo> {
        let o = self.object_at(n)?;
        // The listing shows each entry with its access: a read-only mapping or assignment
        // object with the read-only table (a table only host tools link; the stack's SDO
        // server and SDO information take the access from `Obj::access`).
        let entries = match o.kind {
            Kind::RxMap | Kind::TxMap if o.read_only => &MAP_RO[..o.entries.len()],
            Kind::RxMap | Kind::TxMap => &MAP_RW[..o.entries.len()],
            Kind::RxAssign | Kind::TxAssign if o.read_only => &ASSIGN_RO[..o.entries.len()],
            Kind::RxAssign | Kind::TxAssign => &ASSIGN_RW[..o.entries.len()],
            _ => o.entries.table,
        };
        Some(ObjectInfo {
            index: o.index,
            name: o.name,
            code: o.code,
            entries,
        })
    }

    /// Finds an object by index.
    pub(crate) fn find(&self, index: u16) -> Option<Obj> {
        // A fresh finder walks the application objects from the first: the image offset
        // `app_base` gives, with one copy of the lookup in a board image.
        self.finder().find(index)
    }

    /// Where object `index` is: a communication object whole, an application object by its
    /// position in the definition (its image offset costs a walk: [`Od::app_base`]).
    fn locate(&self, index: u16) -> Option<Located> {
        let d = self.def();
        let comm = |n| self.object_at(n).map(Located::Comm);
        if let Some(i) = COMM_LOW.iter().position(|o| o.index == index) {
            return comm(i);
        }
        if let Some(i) = d.rx_pdos.iter().position(|p| p.index == index) {
            return comm(COMM_LOW.len() + i);
        }
        if let Some(i) = d.tx_pdos.iter().position(|p| p.index == index) {
            return comm(COMM_LOW.len() + d.rx_pdos.len() + i);
        }
        let hi0 = COMM_LOW.len() + d.rx_pdos.len() + d.tx_pdos.len();
        if let Some(i) = COMM_HIGH.iter().position(|o| o.index == index) {
            return comm(hi0 + i);
        }
        let i = d.objects.binary_search_by_key(&index, |o| o.index).ok()?;
        Some(Located::App(i))
    }

    /// A [`Finder`] for a run of lookups.
    pub(crate) fn finder(&self) -> Finder<'_, N> {
        Finder {
            od: self,
            at: 0,
            base: 0,
        }
    }

    /// Image bytes of an entry.
    pub(crate) fn bytes_of(&self, o: &Obj, off: usize, len: usize) -> &[u8] {
        match o.area {
            Area::App => &self.app[off..off + len],
            Area::Comm => &self.comm[off..off + len],
        }
    }

    /// Mutable image bytes of an entry.
    pub(crate) fn bytes_of_mut(&mut self, o: &Obj, off: usize, len: usize) -> &mut [u8] {
        match o.area {
            Area::App => &mut self.app[off..off + len],
            Area::Comm => &mut self.comm[off..off + len],
        }
    }

    /// Resolves `index:sub` once for repeated typed access.
    pub fn entry(&self, index: u16, sub: u8) -> Result<EntryRef, OdError> {
        let o = self.find(index).ok_or(OdError::NoObject)?;
        let (_, e, off) = o.entry(sub).ok_or(OdError::NoSubindex)?;
        Ok(EntryRef {
            area_app: o.area == Area::App,
            offset: off,
            len: e.storage_len(),
            bits: e.bits,
        })
    }

    #[inline]
    fn slice(&self, r: EntryRef) -> &[u8] {
        if r.area_app {
            &self.app[r.offset..r.offset + r.len]
        } else {
            &self.comm[r.offset..r.offset + r.len]
        }
    }

    #[inline]
    fn slice_mut(&mut self, r: EntryRef) -> &mut [u8] {
        if r.area_app {
            &mut self.app[r.offset..r.offset + r.len]
        } else {
            &mut self.comm[r.offset..r.offset + r.len]
        }
    }

    /// Typed read of a resolved entry (the type is not re-checked).
    pub fn read<T: OdType>(&self, r: EntryRef) -> T {
        T::from_le(self.slice(r))
    }

    /// Typed write of a resolved entry (the type is not re-checked).
    pub fn write<T: OdType>(&mut self, r: EntryRef, v: T) {
        v.to_le(self.slice_mut(r))
    }

    /// Resolves `index:sub` into a typed handle; the entry's bit length must match `T`.
    pub fn var<T: OdType>(&self, index: u16, sub: u8) -> Result<Var<T>, OdError> {
        let r = self.entry(index, sub)?;
        if r.bits != T::BITS {
            return Err(OdError::TypeMismatch);
        }
        Ok(Var {
            r,
            _t: core::marker::PhantomData,
        })
    }

    /// Reads the entry behind a handle.
    #[inline]
    pub fn load<T: OdType>(&self, v: Var<T>) -> T {
        self.read(v.r)
    }

    /// Writes the entry behind a handle.
    #[inline]
    pub fn store<T: OdType>(&mut self, v: Var<T>, x: T) {
        self.write(v.r, x)
    }

    /// Typed read of `index:sub`; the entry's bit length must match `T`.
    pub fn get<T: OdType>(&self, index: u16, sub: u8) -> Result<T, OdError> {
        let r = self.entry(index, sub)?;
        if r.bits != T::BITS {
            return Err(OdError::TypeMismatch);
        }
        Ok(self.read(r))
    }

    /// Typed write of `index:sub`; the entry's bit length must match `T`.
    pub fn set<T: OdType>(&mut self, index: u16, sub: u8, v: T) -> Result<(), OdError> {
        let r = self.entry(index, sub)?;
        if r.bits != T::BITS {
            return Err(OdError::TypeMismatch);
        }
        self.write(r, v);
        Ok(())
    }

    /// Raw image bytes of `index:sub` (strings, octet strings).
    pub fn bytes(&self, index: u16, sub: u8) -> Result<&[u8], OdError> {
        let r = self.entry(index, sub)?;
        Ok(self.slice(r))
    }

    /// Mutable raw image bytes of `index:sub`.
    pub fn bytes_mut(&mut self, index: u16, sub: u8) -> Result<&mut [u8], OdError> {
        let r = self.entry(index, sub)?;
        Ok(self.slice_mut(r))
    }

    /// The application image (all application object values).
    pub fn app_image(&self) -> &[u8] {
        &self.app
    }

    /// Sync mode configured in 0x1C32:01 (invalid values read as free run).
    pub fn sync_mode(&self) -> SyncMode {
        SyncMode::from_u16(self.get::<u16>(0x1C32, 1).unwrap_or(0)).unwrap_or(SyncMode::FreeRun)
    }
}

/// The checks [`Od::new`] makes of a definition, for an application image of `image` bytes:
/// the image is large enough, the strings fit, application objects are sorted, unique and
/// in free places, entries well formed, PDOs and assignments within the stack's limits.
/// A definition built at run time (a twin from an ESI) is checked so before it is booted;
/// a `static` one can be checked when the image is built ([`CheckedDef`]: a `const fn`).
pub const fn check_def(def: &DeviceDef, image: usize) -> Result<(), DefError> {
    let needed = image_size(def.objects);
    if needed > image {
        return Err(DefError::ImageTooSmall { needed });
    }
    let texts = [
        (0x1008, def.name),
        (0x1009, def.hw_version),
        (0x100A, def.sw_version),
    ];
    let mut i = 0;
    while i < texts.len() {
        if texts[i].1.len() > STR_MAX as usize {
            return Err(DefError::StringTooLong(texts[i].0));
        }
        i += 1;
    }
    let mut i = 0;
    while i < def.objects.len() {
        let o = &def.objects[i];
        if !app_index_free(def, o.index) || (i > 0 && def.objects[i - 1].index >= o.index) {
            return Err(DefError::BadObjectOrder(o.index));
        }
        if let Err(e) = check_entries(o) {
            return Err(e);
        }
        i += 1;
    }
    let lists = [
        (def.rx_pdos, 0x1600u16, 0x17FFu16),
        (def.tx_pdos, 0x1A00, 0x1BFF),
    ];
    let mut l = 0;
    while l < lists.len() {
        let (list, lo, hi) = lists[l];
        if list.len() > MAX_PDOS {
            return Err(DefError::BadPdo(lo));
        }
        let mut i = 0;
        while i < list.len() {
            let p = &list[i];
            if p.index < lo
                || p.index > hi
                || p.entries.len() > MAX_PDO_ENTRIES
                || (i > 0 && list[i - 1].index >= p.index)
            {
                return Err(DefError::BadPdo(p.index));
            }
            i += 1;
        }
        l += 1;
    }
    if def.rx_assign.len() > MAX_ASSIGN || def.tx_assign.len() > MAX_ASSIGN {
        return Err(DefError::BadPdo(0x1C12));
    }
    let needed = map_storage(def);
    if needed > MAP_POOL {
        return Err(DefError::MappingsTooLarge { needed });
    }
    Ok(())
}

/// A `static` definition that passed [`check_def`] for an `N`-byte application image when
/// the image was built: `const { CheckedDef::new(&DEF) }` (a definition the checks refuse
/// fails the build) for [`crate::SlaveSlot::start_checked`], whose start-up then does not
/// carry the checks (0.6 KB of the demo image's flash).
#[derive(Debug, Clone, Copy)]
pub struct CheckedDef<const N: usize>(pub(crate) &'static DeviceDef);

impl<const N: usize> CheckedDef<N> {
    /// `def` checked for an `N`-byte image; panics (in a `const`: the build fails) if
    /// [`check_def`] refuses it.
    pub const fn new(def: &'static DeviceDef) -> Self {
        if check_def(def, N).is_err() {
            panic!("check_def refuses the device definition");
        }
        Self(def)
    }

    /// The definition.
    pub const fn def(self) -> &'static DeviceDef {
        self.0
    }
}

/// Whether an application object may have `index`: at 0x1000 or above and not where the
/// stack keeps its own communication objects (those of [`COMM_LOW`], the PDO mapping and
/// assignment ranges, the SM objects 0x1C00..0x1C3F). Devices of this repository keep
/// theirs at 0x2000 and above; a twin of a vendor's ESI also serves objects such as the
/// TxPDO parameters 0x1800 that Beckhoff terminals map into their PDOs. Such objects come
/// after 0x1C33 in the SDO information object list.
const fn app_index_free(def: &DeviceDef, index: u16) -> bool {
    if index < 0x1000
        || (index >= 0x1600 && index <= 0x17FF)
        || (index >= 0x1A00 && index <= 0x1BFF)
        || (index >= 0x1C00 && index <= 0x1C3F)
    {
        return false;
    }
    let mut i = 0;
    while i < COMM_LOW.len() {
        if COMM_LOW[i].index == index {
            return false;
        }
        i += 1;
    }
    let mut i = 0;
    while i < def.rx_pdos.len() {
        if def.rx_pdos[i].index == index {
            return false;
        }
        i += 1;
    }
    let mut i = 0;
    while i < def.tx_pdos.len() {
        if def.tx_pdos[i].index == index {
            return false;
        }
        i += 1;
    }
    true
}

const fn check_entries(o: &ObjectDef) -> Result<(), DefError> {
    let bad = DefError::BadEntries(o.index);
    let es = o.entries;
    if es.is_empty() {
        return Err(bad);
    }
    if matches!(o.code, ObjectCode::Var) && (es.len() != 1 || es[0].sub != 0) {
        return Err(bad);
    }
    if !matches!(o.code, ObjectCode::Var) && (es[0].sub != 0 || es[0].bits != 8) {
        return Err(bad);
    }
    let mut i = 0;
    while i < es.len() {
        let en = &es[i];
        if i > 0 && es[i - 1].sub >= en.sub {
            return Err(bad);
        }
        if en.bits == 0 || (en.bits > 64 && !en.dtype.is_string()) {
            return Err(bad);
        }
        i += 1;
    }
    Ok(())
}

fn comm_low_base(n: usize) -> usize {
    COMM_LOW_BASE[n]
}

fn comm_high_base(n: usize) -> usize {
    COMM_HIGH_BASE[n]
}

/// [`Od::default_of`] on definition `d`: the default value of entry `sub` (`e`) of `o` into
/// `out` (its storage length, little endian).
fn default_into(d: &DeviceDef, o: &Obj, sub: u8, e: &EntryDef, out: &mut [u8]) {
    out.fill(0);
    let put = |out: &mut [u8], v: u64| {
        let b = v.to_le_bytes();
        let n = out.len().min(8);
        out[..n].copy_from_slice(&b[..n]);
    };
    let put_str = |out: &mut [u8], s: &str| {
        let n = out.len().min(s.len());
        out[..n].copy_from_slice(&s.as_bytes()[..n]);
    };
    match (o.kind, o.index, sub) {
        (Kind::Plain, 0x1000, 0) => put(out, d.device_type as u64),
        (Kind::Plain, 0x1008, 0) => put_str(out, d.name),
        (Kind::Plain, 0x1009, 0) => put_str(out, d.hw_version),
        (Kind::Plain, 0x100A, 0) => put_str(out, d.sw_version),
        (Kind::Plain, 0x1018, 1) => put(out, d.identity.vendor_id as u64),
        (Kind::Plain, 0x1018, 2) => put(out, d.identity.product_code as u64),
        (Kind::Plain, 0x1018, 3) => put(out, d.identity.revision as u64),
        (Kind::Plain, 0x1018, 4) => put(out, d.identity.serial as u64),
        (Kind::RxMap | Kind::TxMap, _, sub) => {
            if let Some(p) = d.pdo(o.index) {
                match sub {
                    0 => put(out, p.entries.len() as u64),
                    k => {
                        if let Some(pe) = p.entries.get(k as usize - 1) {
                            put(out, pe.encode() as u64);
                        }
                    }
                }
            }
        }
        (Kind::RxAssign | Kind::TxAssign, _, sub) => {
            let list = if o.kind == Kind::RxAssign {
                d.rx_assign
            } else {
                d.tx_assign
            };
            match sub {
                0 => put(out, list.len() as u64),
                k => {
                    if let Some(p) = list.get(k as usize - 1) {
                        put(out, *p as u64);
                    }
                }
            }
        }
        (Kind::SyncPar, _, 1) => put(out, d.sync.default_mode as u64),
        (Kind::SyncPar, _, 4) => put(out, d.sync.supported as u64),
        (Kind::SyncPar, _, 5) => put(out, d.sync.min_cycle_ns as u64),
        (Kind::SyncPar, _, 6) => put(out, d.sync.calc_copy_ns as u64),
        _ => match e.default() {
            DefaultValue::Bits([lo, hi]) => {
                let v = lo as u64 | (hi as u64) << 32;
                let v = if sub == 0 && o.code != ObjectCode::Var && v == 0 {
                    o.max_sub() as u64
                } else {
                    v
                };
                put(out, v);
            }
            DefaultValue::Bytes(b) => {
                let n = out.len().min(b.len());
                out[..n].copy_from_slice(&b[..n]);
            }
        },
    }
}

#[cfg(test)]
mod tests {
    use super::DataType;

    #[test]
    fn data_types_agree_with_the_wire_table() {
        use DataType::*;
        for t in [
            Bool,
            Int8,
            Int16,
            Int32,
            Int64,
            Unsigned8,
            Unsigned16,
            Unsigned32,
            Unsigned64,
            Real32,
            Real64,
            VisibleString,
            OctetString,
        ] {
            let d = oxicat_wire::datatype::by_code(t.code()).expect("in the table");
            assert_eq!(d.bits, t.bits(), "{t:?}");
        }
    }
}

#[cfg(test)]
mod default_tests {
    use super::*;

    #[test]
    fn a_default_reads_back_as_it_was_given_in_the_word_or_in_the_limits() {
        let i16e = EntryDef::new(1, "s", DataType::Int16, Access::RW);
        assert_eq!(
            i16e.default_i64(-5).default(),
            DefaultValue::bits(-5i64 as u64)
        );
        // Raw bits of -1 as an INTEGER16, as an ESI's `DefaultData` gives them.
        assert_eq!(
            i16e.default_bits(0xFFFF).default(),
            DefaultValue::bits(0xFFFF)
        );
        let u32e = EntryDef::new(1, "u", DataType::Unsigned32, Access::RW);
        assert_eq!(
            u32e.default_bits(0xFFFF_FFFF).default(),
            DefaultValue::bits(0xFFFF_FFFF)
        );
        assert_eq!(
            EntryDef::new(1, "r", DataType::Real32, Access::RW)
                .default_f32(-1.5)
                .default(),
            DefaultValue::bits(u64::from((-1.5f32).to_bits()))
        );
        // Beyond the word: refused in it, held by the limits.
        let mut u64e = EntryDef::new(1, "w", DataType::Unsigned64, Access::RW);
        assert!(!u64e.fits_word(1 << 40));
        assert!(!u64e.set_default_word(1 << 40));
        assert!(
            !u32e.fits_word(u64::MAX),
            "zero extension for an unsigned type"
        );
        assert!(i16e.fits_word(u64::MAX), "sign extension for a signed type");
        static WIDE: Limits = Limits::NONE.with_default(DefaultValue::bits(1 << 40));
        u64e = u64e.limits(&WIDE);
        assert_eq!(u64e.default(), DefaultValue::bits(1 << 40));
        static TEXT: Limits = Limits::NONE.with_default(DefaultValue::Bytes(b"hi"));
        let s = EntryDef::string(0, "t", 8, Access::RW).limits(&TEXT);
        assert_eq!(s.default(), DefaultValue::Bytes(b"hi"));
    }

    #[test]
    #[should_panic(expected = "beyond the entry's 32-bit word")]
    fn a_default_beyond_the_word_is_refused_by_the_builder() {
        let _ = EntryDef::new(1, "w", DataType::Unsigned64, Access::RW).default_bits(1 << 40);
    }
}

#[cfg(test)]
mod app_index_tests {
    use super::*;
    use crate::device::DeviceDef;

    static OBJ_1800: [ObjectDef; 2] = [
        ObjectDef {
            index: 0x1800,
            name: "TxPDO-Par",
            code: ObjectCode::Record,
            entries: &[
                EntryDef::new(0, "SubIndex 000", DataType::Unsigned8, Access::RO),
                EntryDef::new(7, "TxPDO State", DataType::Bool, Access::RO),
            ],
        },
        ObjectDef {
            index: 0x6000,
            name: "Inputs",
            code: ObjectCode::Var,
            entries: &[EntryDef::new(0, "Value", DataType::Int16, Access::RO)],
        },
    ];
    static DEF_1800: DeviceDef = DeviceDef {
        objects: &OBJ_1800,
        ..DeviceDef::BASE
    };
    static OBJ_1018: [ObjectDef; 1] = [ObjectDef {
        index: 0x1018,
        name: "Identity again",
        code: ObjectCode::Var,
        entries: &[EntryDef::new(0, "x", DataType::Unsigned8, Access::RO)],
    }];
    static DEF_1018: DeviceDef = DeviceDef {
        objects: &OBJ_1018,
        ..DeviceDef::BASE
    };
    static OBJ_1C12: [ObjectDef; 1] = [ObjectDef {
        index: 0x1C20,
        name: "in the SM range",
        code: ObjectCode::Var,
        entries: &[EntryDef::new(0, "x", DataType::Unsigned8, Access::RO)],
    }];
    static DEF_1C12: DeviceDef = DeviceDef {
        objects: &OBJ_1C12,
        ..DeviceDef::BASE
    };

    #[test]
    fn application_objects_may_fill_free_places_of_the_communication_area() {
        let od = Od::<64>::new(&DEF_1800).expect("0x1800 is free");
        assert_eq!(od.get::<u8>(0x1800, 0), Ok(7));
        assert_eq!(od.get::<u16>(0x6000, 0), Ok(0));
        assert_eq!(
            Od::<64>::new(&DEF_1018).err(),
            Some(DefError::BadObjectOrder(0x1018))
        );
        assert_eq!(
            Od::<64>::new(&DEF_1C12).err(),
            Some(DefError::BadObjectOrder(0x1C20))
        );
    }
}

#[cfg(test)]
mod finder_tests {
    use super::*;
    use crate::device::DeviceDef;

    static I16: [EntryDef; 1] = [EntryDef::new(0, "v", DataType::Int16, Access::RW)];
    static I32: [EntryDef; 1] = [EntryDef::new(0, "v", DataType::Int32, Access::RW)];
    static BIT: [EntryDef; 1] = [EntryDef::new(0, "v", DataType::Bool, Access::RW)];
    const fn var(index: u16, entries: &'static [EntryDef]) -> ObjectDef {
        ObjectDef {
            index,
            name: "v",
            code: ObjectCode::Var,
            entries,
        }
    }
    static OBJS: [ObjectDef; 7] = [
        var(0x1800, &I16),
        var(0x2000, &I32),
        ObjectDef {
            index: 0x2001,
            name: "r",
            code: ObjectCode::Record,
            entries: &[
                EntryDef::new(0, "n", DataType::Unsigned8, Access::RO),
                EntryDef::new(1, "a", DataType::Int32, Access::RW),
                EntryDef::new(3, "b", DataType::Bool, Access::RW),
            ],
        },
        var(0x6000, &BIT),
        var(0x6001, &I16),
        var(0x7000, &I32),
        var(0x7001, &I16),
    ];
    static DEF: DeviceDef = DeviceDef {
        objects: &OBJS,
        ..DeviceDef::BASE
    };

    /// A finder's lookups in any order (forward, backward, repeated, communication objects
    /// in between, missing ones) give exactly what `Od::find` gives.
    #[test]
    fn a_finder_finds_what_find_finds_in_any_order() {
        let od = Od::<64>::new(&DEF).expect("a valid definition");
        const K: usize = 15;
        let mut fwd = [0u16; K];
        for (k, o) in OBJS.iter().enumerate() {
            fwd[k] = o.index;
        }
        fwd[OBJS.len()..].copy_from_slice(&[
            0x1000, 0x1018, 0x1C12, 0x1C33, 0x1600, 0x1A00, 0x5000, 0xFFFF,
        ]);
        let mut rev = fwd;
        rev.reverse();
        // A fixed permutation by a stride coprime to the length.
        let perm: [u16; K] = core::array::from_fn(|k| fwd[(k * 7) % K]);
        for order in [fwd, rev, perm] {
            let mut f = od.finder();
            for &i in order.iter().chain(order.iter()) {
                let (a, b) = (f.find(i), od.find(i));
                assert_eq!(a.is_some(), b.is_some(), "{i:#06x}");
                if let (Some(a), Some(b)) = (a, b) {
                    assert_eq!(
                        (a.index, a.base, a.area, a.entries.len()),
                        (b.index, b.base, b.area, b.entries.len()),
                        "{i:#06x}"
                    );
                }
            }
        }
        // The offsets are the image layout: each application object after the one before.
        let mut base = 0;
        for o in &OBJS {
            assert_eq!(od.find(o.index).map(|x| x.base), Some(base));
            base += o.storage_len();
        }
    }
}
