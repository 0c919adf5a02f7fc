//! The SII EEPROM layout (ETG.2010): configuration area, identity, mailbox configuration,
//! and the category list starting at word 0x40 with decoded views of the standard categories.
//!
//! All offsets in the EEPROM are word (16-bit) addresses; values are little endian. Views
//! borrow the image and decode on access; malformed content yields a [`WireError`].

use crate::error::{need, WireError};

/// Word address of the PDI control word.
pub const WORD_PDI_CONTROL: u16 = 0x00;
/// Word address of the PDI configuration word.
pub const WORD_PDI_CONFIG: u16 = 0x01;
/// Word address of the SYNC impulse length (in 10 ns units).
pub const WORD_SYNC_IMPULSE: u16 = 0x02;
/// Word address of the extended PDI configuration word.
pub const WORD_PDI_CONFIG2: u16 = 0x03;
/// Word address of the configured station alias.
pub const WORD_STATION_ALIAS: u16 = 0x04;
/// Word address of the configuration-area checksum (CRC in the low byte).
pub const WORD_CHECKSUM: u16 = 0x07;
/// Word address of the vendor ID (u32).
pub const WORD_VENDOR_ID: u16 = 0x08;
/// Word address of the product code (u32).
pub const WORD_PRODUCT_CODE: u16 = 0x0A;
/// Word address of the revision number (u32).
pub const WORD_REVISION: u16 = 0x0C;
/// Word address of the serial number (u32).
pub const WORD_SERIAL: u16 = 0x0E;
/// Word address of the bootstrap receive mailbox offset.
pub const WORD_BOOTSTRAP_RX_OFFSET: u16 = 0x14;
/// Word address of the standard receive mailbox offset.
pub const WORD_STANDARD_RX_OFFSET: u16 = 0x18;
/// Word address of the supported mailbox protocols.
pub const WORD_MAILBOX_PROTOCOLS: u16 = 0x1C;
/// Word address of the EEPROM size ((KiBit) − 1).
pub const WORD_EEPROM_SIZE: u16 = 0x3E;
/// Word address of the SII version.
pub const WORD_VERSION: u16 = 0x3F;
/// Word address of the first category header.
pub const WORD_FIRST_CATEGORY: u16 = 0x40;
/// Bytes of the fixed area before the categories.
pub const FIXED_AREA_LEN: usize = 0x80;
/// Category type that ends the list.
pub const CATEGORY_END: u16 = 0xFFFF;

pub use crate::crc::sii_crc8;

/// The configuration area, words 0..=7, loaded into ESC registers at power-on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SiiConfig {
    /// Initial value of PDI control (0x0140).
    pub pdi_control: u16,
    /// Initial value of PDI configuration (0x0150).
    pub pdi_config: u16,
    /// SYNC impulse length in 10 ns units (0x0982).
    pub sync_impulse_len: u16,
    /// Initial value of the extended PDI configuration (0x0152).
    pub pdi_config2: u16,
    /// Configured station alias (0x0012).
    pub station_alias: u16,
    /// Words 5 and 6 (reserved).
    pub reserved: [u16; 2],
    /// Word 7: the CRC in the low byte, the high byte reserved.
    pub checksum: u16,
}

impl SiiConfig {
    /// Parses words 0..=7 from the first 16 bytes of `buf`.
    pub fn parse(buf: &[u8]) -> Result<Self, WireError> {
        need(buf, 16)?;
        let w = |i: usize| u16::from_le_bytes([buf[2 * i], buf[2 * i + 1]]);
        Ok(Self {
            pdi_control: w(0),
            pdi_config: w(1),
            sync_impulse_len: w(2),
            pdi_config2: w(3),
            station_alias: w(4),
            reserved: [w(5), w(6)],
            checksum: w(7),
        })
    }

    /// The 14 bytes covered by the CRC.
    pub fn crc_bytes(&self) -> [u8; 14] {
        let mut b = [0u8; 14];
        let words = [
            self.pdi_control,
            self.pdi_config,
            self.sync_impulse_len,
            self.pdi_config2,
            self.station_alias,
            self.reserved[0],
            self.reserved[1],
        ];
        for (i, w) in words.iter().enumerate() {
            b[2 * i..2 * i + 2].copy_from_slice(&w.to_le_bytes());
        }
        b
    }

    /// True when the low byte of word 7 is the CRC of words 0..=6.
    pub fn crc_ok(&self) -> bool {
        self.checksum as u8 == sii_crc8(&self.crc_bytes())
    }

    /// Writes words 0..=7 into `buf`, with a freshly computed CRC (the high byte of word 7
    /// is kept from `checksum`).
    pub fn write(&self, buf: &mut [u8]) -> Result<usize, WireError> {
        if buf.len() < 16 {
            return Err(WireError::BufferFull);
        }
        let b = self.crc_bytes();
        buf[..14].copy_from_slice(&b);
        buf[14] = sii_crc8(&b);
        buf[15] = (self.checksum >> 8) as u8;
        Ok(16)
    }
}

/// The device identity, words 0x08..=0x0F (same values as object 0x1018).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub struct SiiIdentity {
    /// Vendor ID.
    pub vendor_id: u32,
    /// Product code.
    pub product_code: u32,
    /// Revision number.
    pub revision: u32,
    /// Serial number.
    pub serial: u32,
}

impl SiiIdentity {
    /// Writes the identity into words 0x08..=0x0F of an image of at least 32 bytes.
    pub fn write(&self, image: &mut [u8]) -> Result<(), WireError> {
        if image.len() < 32 {
            return Err(WireError::BufferFull);
        }
        image[16..20].copy_from_slice(&self.vendor_id.to_le_bytes());
        image[20..24].copy_from_slice(&self.product_code.to_le_bytes());
        image[24..28].copy_from_slice(&self.revision.to_le_bytes());
        image[28..32].copy_from_slice(&self.serial.to_le_bytes());
        Ok(())
    }
}

/// A mailbox's offset and size in the ESC memory.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub struct MailboxArea {
    /// Physical start address.
    pub offset: u16,
    /// Size in bytes.
    pub size: u16,
}

/// The mailbox configuration, words 0x14..=0x1C.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub struct SiiMailboxConfig {
    /// Bootstrap receive mailbox (master → slave).
    pub bootstrap_rx: MailboxArea,
    /// Bootstrap send mailbox (slave → master).
    pub bootstrap_tx: MailboxArea,
    /// Standard receive mailbox (master → slave).
    pub standard_rx: MailboxArea,
    /// Standard send mailbox (slave → master).
    pub standard_tx: MailboxArea,
    /// Supported mailbox protocols (see [`crate::mailbox::protocols`]).
    pub protocols: u16,
}

impl SiiMailboxConfig {
    /// Writes words 0x14..=0x1C into an image of at least 58 bytes.
    pub fn write(&self, image: &mut [u8]) -> Result<(), WireError> {
        if image.len() < 0x3A {
            return Err(WireError::BufferFull);
        }
        let words = [
            self.bootstrap_rx.offset,
            self.bootstrap_rx.size,
            self.bootstrap_tx.offset,
            self.bootstrap_tx.size,
            self.standard_rx.offset,
            self.standard_rx.size,
            self.standard_tx.offset,
            self.standard_tx.size,
            self.protocols,
        ];
        for (i, w) in words.iter().enumerate() {
            let o = 0x28 + 2 * i;
            image[o..o + 2].copy_from_slice(&w.to_le_bytes());
        }
        Ok(())
    }
}

/// A view of a whole SII EEPROM image (at least the 128-byte fixed area).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SiiImage<'a> {
    bytes: &'a [u8],
}

impl<'a> SiiImage<'a> {
    /// Wraps an image; fewer than 128 bytes is an error.
    pub fn new(bytes: &'a [u8]) -> Result<Self, WireError> {
        need(bytes, FIXED_AREA_LEN)?;
        Ok(Self { bytes })
    }

    /// The raw image.
    pub fn bytes(&self) -> &'a [u8] {
        self.bytes
    }

    /// The word at word address `addr`, if inside the image.
    pub fn word(&self, addr: u16) -> Option<u16> {
        let i = addr as usize * 2;
        let b = self.bytes.get(i..i + 2)?;
        Some(u16::from_le_bytes([b[0], b[1]]))
    }

    fn fixed_word(&self, addr: u16) -> u16 {
        // Fixed-area words are always inside the image (checked in `new`).
        self.word(addr).unwrap_or(0)
    }

    fn fixed_dword(&self, addr: u16) -> u32 {
        (self.fixed_word(addr) as u32) | ((self.fixed_word(addr + 1) as u32) << 16)
    }

    /// The configuration area (words 0..=7).
    pub fn config(&self) -> SiiConfig {
        // `new` guarantees 128 bytes.
        SiiConfig::parse(self.bytes).unwrap_or_default()
    }

    /// True when the configuration-area CRC is correct.
    pub fn crc_ok(&self) -> bool {
        self.config().crc_ok()
    }

    /// The identity (words 0x08..=0x0F).
    pub fn identity(&self) -> SiiIdentity {
        SiiIdentity {
            vendor_id: self.fixed_dword(WORD_VENDOR_ID),
            product_code: self.fixed_dword(WORD_PRODUCT_CODE),
            revision: self.fixed_dword(WORD_REVISION),
            serial: self.fixed_dword(WORD_SERIAL),
        }
    }

    /// The mailbox configuration (words 0x14..=0x1C).
    pub fn mailbox(&self) -> SiiMailboxConfig {
        let a = |w: u16| MailboxArea {
            offset: self.fixed_word(w),
            size: self.fixed_word(w + 1),
        };
        SiiMailboxConfig {
            bootstrap_rx: a(WORD_BOOTSTRAP_RX_OFFSET),
            bootstrap_tx: a(WORD_BOOTSTRAP_RX_OFFSET + 2),
            standard_rx: a(WORD_STANDARD_RX_OFFSET),
            standard_tx: a(WORD_STANDARD_RX_OFFSET + 2),
            protocols: self.fixed_word(WORD_MAILBOX_PROTOCOLS),
        }
    }

    /// The EEPROM size word (size in KiBit − 1).
    pub fn eeprom_size_word(&self) -> u16 {
        self.fixed_word(WORD_EEPROM_SIZE)
    }

    /// The EEPROM size in bytes declared by word 0x3E.
    pub fn eeprom_size_bytes(&self) -> usize {
        (self.eeprom_size_word() as usize + 1) * 128
    }

    /// The SII version (word 0x3F).
    pub fn version(&self) -> u16 {
        self.fixed_word(WORD_VERSION)
    }

    /// Iterates the categories from word 0x40 until the end marker.
    pub fn categories(&self) -> Categories<'a> {
        Categories {
            bytes: self.bytes,
            offset: FIXED_AREA_LEN,
            done: false,
        }
    }

    /// The first category of `kind`, if any (errors in the list before it are returned).
    pub fn find(&self, kind: CategoryType) -> Result<Option<Category<'a>>, WireError> {
        for c in self.categories() {
            let c = c?;
            if c.kind == kind {
                return Ok(Some(c));
            }
        }
        Ok(None)
    }

    /// The strings category, if present.
    pub fn strings(&self) -> Result<Option<SiiStrings<'a>>, WireError> {
        match self.find(CategoryType::Strings)? {
            Some(c) => Ok(Some(SiiStrings::new(c.data)?)),
            None => Ok(None),
        }
    }

    /// The general category, if present.
    pub fn general(&self) -> Result<Option<SiiGeneral>, WireError> {
        match self.find(CategoryType::General)? {
            Some(c) => Ok(Some(SiiGeneral::parse(c.data)?)),
            None => Ok(None),
        }
    }
}

/// The type of a category.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CategoryType {
    /// 0: no operation.
    Nop,
    /// 10: strings.
    Strings,
    /// 20: data types.
    DataTypes,
    /// 30: general.
    General,
    /// 40: FMMU usage.
    Fmmu,
    /// 41: sync manager configuration.
    SyncManager,
    /// 42: FMMU extended.
    FmmuExtended,
    /// 43: sync unit.
    SyncUnit,
    /// 50: TxPDO description.
    TxPdo,
    /// 51: RxPDO description.
    RxPdo,
    /// 60: distributed clock.
    Dc,
    /// 0xFFFF: end of the list.
    End,
    /// Any other code (device or vendor specific).
    Other(u16),
}

impl CategoryType {
    /// Decodes a category type word.
    pub const fn from_u16(v: u16) -> Self {
        match v {
            0 => Self::Nop,
            10 => Self::Strings,
            20 => Self::DataTypes,
            30 => Self::General,
            40 => Self::Fmmu,
            41 => Self::SyncManager,
            42 => Self::FmmuExtended,
            43 => Self::SyncUnit,
            50 => Self::TxPdo,
            51 => Self::RxPdo,
            60 => Self::Dc,
            0xFFFF => Self::End,
            o => Self::Other(o),
        }
    }

    /// The category type word.
    pub const fn code(self) -> u16 {
        match self {
            Self::Nop => 0,
            Self::Strings => 10,
            Self::DataTypes => 20,
            Self::General => 30,
            Self::Fmmu => 40,
            Self::SyncManager => 41,
            Self::FmmuExtended => 42,
            Self::SyncUnit => 43,
            Self::TxPdo => 50,
            Self::RxPdo => 51,
            Self::Dc => 60,
            Self::End => 0xFFFF,
            Self::Other(o) => o,
        }
    }
}

/// One category: its type, its word address and its data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Category<'a> {
    /// The category type.
    pub kind: CategoryType,
    /// Word address of the category header.
    pub word_address: u16,
    /// The category data (size × 2 bytes).
    pub data: &'a [u8],
}

impl<'a> Category<'a> {
    /// Decodes the data as a strings category.
    pub fn strings(&self) -> Result<SiiStrings<'a>, WireError> {
        SiiStrings::new(self.data)
    }

    /// Decodes the data as a general category.
    pub fn general(&self) -> Result<SiiGeneral, WireError> {
        SiiGeneral::parse(self.data)
    }

    /// Iterates the data as sync manager entries.
    pub fn sync_managers(&self) -> Entries<'a, SiiSyncManager> {
        Entries::new(self.data)
    }

    /// Iterates the data as FMMU usage bytes.
    pub fn fmmus(&self) -> impl Iterator<Item = FmmuUsage> + 'a {
        self.data.iter().map(|b| FmmuUsage::from_u8(*b))
    }

    /// Iterates the data as FMMU extended entries.
    pub fn fmmus_extended(&self) -> Entries<'a, SiiFmmuExtended> {
        Entries::new(self.data)
    }

    /// Iterates the data as PDO descriptions.
    pub fn pdos(&self) -> Pdos<'a> {
        Pdos {
            rest: self.data,
            done: false,
        }
    }

    /// Iterates the data as DC operation modes.
    pub fn dc(&self) -> Entries<'a, SiiDc> {
        Entries::new(self.data)
    }
}

/// Iterator over the categories of an image; see [`SiiImage::categories`].
#[derive(Debug, Clone)]
pub struct Categories<'a> {
    bytes: &'a [u8],
    offset: usize,
    done: bool,
}

impl<'a> Iterator for Categories<'a> {
    type Item = Result<Category<'a>, WireError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        let rest = &self.bytes[self.offset.min(self.bytes.len())..];
        if rest.is_empty() {
            // An image that ends exactly after a category (no end marker) ends the list.
            self.done = true;
            return None;
        }
        if rest.len() < 2 {
            self.done = true;
            return Some(Err(WireError::Truncated {
                needed: 2,
                available: rest.len(),
            }));
        }
        let t = u16::from_le_bytes([rest[0], rest[1]]);
        if t == CATEGORY_END {
            self.done = true;
            return None;
        }
        if rest.len() < 4 {
            self.done = true;
            return Some(Err(WireError::Truncated {
                needed: 4,
                available: rest.len(),
            }));
        }
        let size = u16::from_le_bytes([rest[2], rest[3]]) as usize * 2;
        if rest.len() < 4 + size {
            self.done = true;
            return Some(Err(WireError::LengthMismatch {
                declared: size,
                available: rest.len() - 4,
            }));
        }
        let word_address = match u16::try_from(self.offset / 2) {
            Ok(w) => w,
            Err(_) => {
                self.done = true;
                return Some(Err(WireError::InvalidField("category address")));
            }
        };
        let c = Category {
            kind: CategoryType::from_u16(t),
            word_address,
            data: &rest[4..4 + size],
        };
        self.offset += 4 + size;
        Some(Ok(c))
    }
}

/// Writes a category header (type, size in words) and `data` (padded to an even length)
/// at byte `offset` of `image`; returns the offset after it.
pub fn write_category(
    image: &mut [u8],
    offset: usize,
    kind: CategoryType,
    data: &[u8],
) -> Result<usize, WireError> {
    let padded = data.len() + (data.len() & 1);
    let words = u16::try_from(padded / 2).map_err(|_| WireError::BufferFull)?;
    let end = offset
        .checked_add(4 + padded)
        .ok_or(WireError::BufferFull)?;
    if image.len() < end || offset & 1 != 0 {
        return Err(WireError::BufferFull);
    }
    image[offset..offset + 2].copy_from_slice(&kind.code().to_le_bytes());
    image[offset + 2..offset + 4].copy_from_slice(&words.to_le_bytes());
    image[offset + 4..offset + 4 + data.len()].copy_from_slice(data);
    image[offset + 4 + data.len()..end].fill(0);
    Ok(end)
}

/// The strings category: a count followed by length-prefixed strings, indexed from 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SiiStrings<'a> {
    data: &'a [u8],
}

impl<'a> SiiStrings<'a> {
    /// Wraps strings category data (checked lazily; an empty category is an error).
    pub fn new(data: &'a [u8]) -> Result<Self, WireError> {
        need(data, 1)?;
        Ok(Self { data })
    }

    /// The declared number of strings.
    pub fn count(&self) -> u8 {
        self.data[0]
    }

    /// Iterates the strings as bytes; a string running past the category is an error item.
    pub fn iter(&self) -> SiiStringIter<'a> {
        SiiStringIter {
            rest: &self.data[1..],
            left: self.data[0],
        }
    }

    /// String `index` (1-based; 0 means "no string" and yields `None`).
    pub fn get(&self, index: u8) -> Option<&'a [u8]> {
        if index == 0 {
            return None;
        }
        self.iter().nth(index as usize - 1)?.ok()
    }

    /// String `index` as UTF-8 text, `None` if absent or not UTF-8.
    pub fn get_str(&self, index: u8) -> Option<&'a str> {
        core::str::from_utf8(self.get(index)?).ok()
    }
}

/// Iterator over the strings of a strings category.
#[derive(Debug, Clone)]
pub struct SiiStringIter<'a> {
    rest: &'a [u8],
    left: u8,
}

impl<'a> Iterator for SiiStringIter<'a> {
    type Item = Result<&'a [u8], WireError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.left == 0 {
            return None;
        }
        self.left -= 1;
        let Some((&len, tail)) = self.rest.split_first() else {
            self.left = 0;
            return Some(Err(WireError::Truncated {
                needed: 1,
                available: 0,
            }));
        };
        let len = len as usize;
        if tail.len() < len {
            self.left = 0;
            return Some(Err(WireError::LengthMismatch {
                declared: len,
                available: tail.len(),
            }));
        }
        let (s, rest) = tail.split_at(len);
        self.rest = rest;
        Some(Ok(s))
    }
}

/// Writes a strings category body (count + length-prefixed strings) into `buf`; returns its
/// length.
pub fn write_strings(buf: &mut [u8], strings: &[&[u8]]) -> Result<usize, WireError> {
    let count = u8::try_from(strings.len()).map_err(|_| WireError::InvalidField("string count"))?;
    if buf.is_empty() {
        return Err(WireError::BufferFull);
    }
    buf[0] = count;
    let mut o = 1;
    for s in strings {
        let l = u8::try_from(s.len()).map_err(|_| WireError::InvalidField("string length"))?;
        if buf.len() < o + 1 + s.len() {
            return Err(WireError::BufferFull);
        }
        buf[o] = l;
        buf[o + 1..o + 1 + s.len()].copy_from_slice(s);
        o += 1 + s.len();
    }
    Ok(o)
}

/// Length of the general category.
pub const GENERAL_LEN: usize = 32;

/// The general category (30).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub struct SiiGeneral {
    /// String index of the group type.
    pub group_idx: u8,
    /// String index of the image name.
    pub image_idx: u8,
    /// String index of the order number.
    pub order_idx: u8,
    /// String index of the device name.
    pub name_idx: u8,
    /// Reserved byte 4.
    pub reserved0: u8,
    /// CoE details (see [`coe_details`]).
    pub coe_details: u8,
    /// FoE details (bit 0: FoE supported).
    pub foe_details: u8,
    /// EoE details (bit 0: EoE supported).
    pub eoe_details: u8,
    /// SoE channels (reserved).
    pub soe_channels: u8,
    /// DS402 channels (reserved).
    pub ds402_channels: u8,
    /// SysmanClass (reserved).
    pub sysman_class: u8,
    /// Flags (see [`general_flags`]).
    pub flags: u8,
    /// Current consumption on the E-bus in mA (negative: the device feeds current).
    pub current_on_ebus: i16,
    /// Group string index (compatibility copy).
    pub group_idx2: u8,
    /// Reserved byte 15.
    pub reserved1: u8,
    /// Physical port types (4 bits per port).
    pub physical_port: u16,
    /// Physical memory address of the identification value.
    pub physical_memory_address: u16,
    /// Reserved bytes 20..32.
    pub reserved2: [u8; 12],
}

/// Bits of [`SiiGeneral::coe_details`].
pub mod coe_details {
    /// SDO supported.
    pub const SDO: u8 = 0x01;
    /// SDO information supported.
    pub const SDO_INFO: u8 = 0x02;
    /// PDO assignment writable.
    pub const PDO_ASSIGN: u8 = 0x04;
    /// PDO configuration writable.
    pub const PDO_CONFIG: u8 = 0x08;
    /// PDO configuration uploaded at startup.
    pub const PDO_UPLOAD: u8 = 0x10;
    /// SDO complete access supported.
    pub const COMPLETE_ACCESS: u8 = 0x20;
}

/// Bits of [`SiiGeneral::flags`].
pub mod general_flags {
    /// SafeOp must be enabled.
    pub const ENABLE_SAFEOP: u8 = 0x01;
    /// LRW is not supported.
    pub const ENABLE_NOT_LRW: u8 = 0x02;
    /// Mailbox data link layer supported.
    pub const MBOX_DLL: u8 = 0x04;
    /// Identification via AL status code.
    pub const IDENT_AL_STATUS: u8 = 0x08;
    /// Identification via physical memory.
    pub const IDENT_PHYS_MEMORY: u8 = 0x10;
}

impl SiiGeneral {
    /// Parses the 32-byte general category.
    pub fn parse(d: &[u8]) -> Result<Self, WireError> {
        need(d, GENERAL_LEN)?;
        let mut reserved2 = [0; 12];
        reserved2.copy_from_slice(&d[20..32]);
        Ok(Self {
            group_idx: d[0],
            image_idx: d[1],
            order_idx: d[2],
            name_idx: d[3],
            reserved0: d[4],
            coe_details: d[5],
            foe_details: d[6],
            eoe_details: d[7],
            soe_channels: d[8],
            ds402_channels: d[9],
            sysman_class: d[10],
            flags: d[11],
            current_on_ebus: i16::from_le_bytes([d[12], d[13]]),
            group_idx2: d[14],
            reserved1: d[15],
            physical_port: u16::from_le_bytes([d[16], d[17]]),
            physical_memory_address: u16::from_le_bytes([d[18], d[19]]),
            reserved2,
        })
    }

    /// Writes the 32-byte general category body.
    pub fn write(&self, d: &mut [u8]) -> Result<usize, WireError> {
        if d.len() < GENERAL_LEN {
            return Err(WireError::BufferFull);
        }
        d[..12].copy_from_slice(&[
            self.group_idx,
            self.image_idx,
            self.order_idx,
            self.name_idx,
            self.reserved0,
            self.coe_details,
            self.foe_details,
            self.eoe_details,
            self.soe_channels,
            self.ds402_channels,
            self.sysman_class,
            self.flags,
        ]);
        d[12..14].copy_from_slice(&self.current_on_ebus.to_le_bytes());
        d[14] = self.group_idx2;
        d[15] = self.reserved1;
        d[16..18].copy_from_slice(&self.physical_port.to_le_bytes());
        d[18..20].copy_from_slice(&self.physical_memory_address.to_le_bytes());
        d[20..32].copy_from_slice(&self.reserved2);
        Ok(GENERAL_LEN)
    }
}

/// A fixed-size entry of a category.
pub trait SiiEntry: Sized {
    /// Bytes per entry.
    const LEN: usize;
    /// Decodes one entry from exactly `LEN` bytes.
    fn decode(b: &[u8]) -> Self;
}

/// Iterator over fixed-size entries; a trailing partial entry is an error item.
#[derive(Debug, Clone)]
pub struct Entries<'a, T> {
    rest: &'a [u8],
    _t: core::marker::PhantomData<T>,
}

impl<'a, T> Entries<'a, T> {
    fn new(data: &'a [u8]) -> Self {
        Self {
            rest: data,
            _t: core::marker::PhantomData,
        }
    }
}

impl<T: SiiEntry> Iterator for Entries<'_, T> {
    type Item = Result<T, WireError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.rest.is_empty() {
            return None;
        }
        if self.rest.len() < T::LEN {
            let available = self.rest.len();
            self.rest = &[];
            return Some(Err(WireError::Truncated {
                needed: T::LEN,
                available,
            }));
        }
        let (e, rest) = self.rest.split_at(T::LEN);
        self.rest = rest;
        Some(Ok(T::decode(e)))
    }
}

/// The type of a sync manager in the SII.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SmType {
    /// 0: not used.
    Unused,
    /// 1: mailbox out (master → slave).
    MailboxOut,
    /// 2: mailbox in (slave → master).
    MailboxIn,
    /// 3: process data outputs.
    Outputs,
    /// 4: process data inputs.
    Inputs,
    /// Any other code.
    Other(u8),
}

impl SmType {
    /// Decodes a type byte.
    pub const fn from_u8(v: u8) -> Self {
        match v {
            0 => Self::Unused,
            1 => Self::MailboxOut,
            2 => Self::MailboxIn,
            3 => Self::Outputs,
            4 => Self::Inputs,
            o => Self::Other(o),
        }
    }

    /// The type byte.
    pub const fn code(self) -> u8 {
        match self {
            Self::Unused => 0,
            Self::MailboxOut => 1,
            Self::MailboxIn => 2,
            Self::Outputs => 3,
            Self::Inputs => 4,
            Self::Other(o) => o,
        }
    }
}

/// One 8-byte sync manager entry of category 41.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SiiSyncManager {
    /// Physical start address.
    pub start: u16,
    /// Length in bytes.
    pub length: u16,
    /// Control register value (0x0804).
    pub control: u8,
    /// Status byte (reserved, don't care).
    pub status: u8,
    /// Enable flags: bit 0 enable, 1 fixed content, 2 virtual, 3 OP only.
    pub enable: u8,
    /// Usage type.
    pub sm_type: SmType,
}

impl SiiEntry for SiiSyncManager {
    const LEN: usize = 8;
    fn decode(b: &[u8]) -> Self {
        Self {
            start: u16::from_le_bytes([b[0], b[1]]),
            length: u16::from_le_bytes([b[2], b[3]]),
            control: b[4],
            status: b[5],
            enable: b[6],
            sm_type: SmType::from_u8(b[7]),
        }
    }
}

impl SiiSyncManager {
    /// Writes the 8-byte entry.
    pub fn write(&self, b: &mut [u8]) -> Result<usize, WireError> {
        if b.len() < 8 {
            return Err(WireError::BufferFull);
        }
        b[0..2].copy_from_slice(&self.start.to_le_bytes());
        b[2..4].copy_from_slice(&self.length.to_le_bytes());
        b[4] = self.control;
        b[5] = self.status;
        b[6] = self.enable;
        b[7] = self.sm_type.code();
        Ok(8)
    }
}

/// What an FMMU is used for (one byte per FMMU in category 40).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FmmuUsage {
    /// 0x00 or 0xFF: not used.
    Unused,
    /// 1: outputs.
    Outputs,
    /// 2: inputs.
    Inputs,
    /// 3: sync manager status (mailbox polling).
    SyncManagerStatus,
    /// Any other code.
    Other(u8),
}

impl FmmuUsage {
    /// The usage byte (unused: 0x00).
    pub const fn code(self) -> u8 {
        match self {
            Self::Unused => 0,
            Self::Outputs => 1,
            Self::Inputs => 2,
            Self::SyncManagerStatus => 3,
            Self::Other(o) => o,
        }
    }

    /// Decodes a usage byte.
    pub const fn from_u8(v: u8) -> Self {
        match v {
            0 | 0xFF => Self::Unused,
            1 => Self::Outputs,
            2 => Self::Inputs,
            3 => Self::SyncManagerStatus,
            o => Self::Other(o),
        }
    }
}

/// One 3-byte entry of the FMMU extended category (42).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SiiFmmuExtended {
    /// Flags byte (bit 0: "op only"; others reserved).
    pub flags: u8,
    /// Sync manager this FMMU maps.
    pub sync_manager: u8,
    /// Sync unit this FMMU belongs to.
    pub sync_unit: u8,
}

impl SiiEntry for SiiFmmuExtended {
    const LEN: usize = 3;
    fn decode(b: &[u8]) -> Self {
        Self {
            flags: b[0],
            sync_manager: b[1],
            sync_unit: b[2],
        }
    }
}

/// One 24-byte operation mode of the DC category (60).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SiiDc {
    /// SYNC0 cycle time in ns.
    pub cycle_time0: u32,
    /// SYNC0 shift time in ns.
    pub shift_time0: u32,
    /// SYNC1 shift time in ns.
    pub shift_time1: u32,
    /// SYNC1 cycle factor.
    pub sync1_cycle_factor: i16,
    /// Value for the DC activation register (0x0980).
    pub assign_activate: u16,
    /// SYNC0 cycle factor.
    pub sync0_cycle_factor: i16,
    /// String index of the mode name.
    pub name_idx: u8,
    /// String index of the description.
    pub desc_idx: u8,
    /// Reserved bytes.
    pub reserved: [u8; 4],
}

impl SiiDc {
    /// Writes the 24-byte entry.
    pub fn write(&self, b: &mut [u8]) -> Result<usize, WireError> {
        if b.len() < Self::LEN {
            return Err(WireError::BufferFull);
        }
        b[0..4].copy_from_slice(&self.cycle_time0.to_le_bytes());
        b[4..8].copy_from_slice(&self.shift_time0.to_le_bytes());
        b[8..12].copy_from_slice(&self.shift_time1.to_le_bytes());
        b[12..14].copy_from_slice(&self.sync1_cycle_factor.to_le_bytes());
        b[14..16].copy_from_slice(&self.assign_activate.to_le_bytes());
        b[16..18].copy_from_slice(&self.sync0_cycle_factor.to_le_bytes());
        b[18] = self.name_idx;
        b[19] = self.desc_idx;
        b[20..24].copy_from_slice(&self.reserved);
        Ok(Self::LEN)
    }
}

impl SiiEntry for SiiDc {
    const LEN: usize = 24;
    fn decode(b: &[u8]) -> Self {
        let u32at = |i: usize| u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
        Self {
            cycle_time0: u32at(0),
            shift_time0: u32at(4),
            shift_time1: u32at(8),
            sync1_cycle_factor: i16::from_le_bytes([b[12], b[13]]),
            assign_activate: u16::from_le_bytes([b[14], b[15]]),
            sync0_cycle_factor: i16::from_le_bytes([b[16], b[17]]),
            name_idx: b[18],
            desc_idx: b[19],
            reserved: [b[20], b[21], b[22], b[23]],
        }
    }
}

/// The 8-byte header of a PDO description in categories 50/51.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SiiPdoHeader {
    /// PDO index (0x1600.. / 0x1A00..).
    pub index: u16,
    /// Number of entries that follow.
    pub entry_count: u8,
    /// Sync manager the PDO is assigned to (0xFF: none).
    pub sync_manager: u8,
    /// DC synchronization mode.
    pub dc_sync: u8,
    /// String index of the PDO name.
    pub name_idx: u8,
    /// PDO flags.
    pub flags: u16,
}

impl SiiPdoHeader {
    /// Parses the 8-byte header.
    pub fn parse(b: &[u8]) -> Result<Self, WireError> {
        need(b, 8)?;
        Ok(Self {
            index: u16::from_le_bytes([b[0], b[1]]),
            entry_count: b[2],
            sync_manager: b[3],
            dc_sync: b[4],
            name_idx: b[5],
            flags: u16::from_le_bytes([b[6], b[7]]),
        })
    }

    /// Writes the 8-byte header.
    pub fn write(&self, b: &mut [u8]) -> Result<usize, WireError> {
        if b.len() < 8 {
            return Err(WireError::BufferFull);
        }
        b[0..2].copy_from_slice(&self.index.to_le_bytes());
        b[2] = self.entry_count;
        b[3] = self.sync_manager;
        b[4] = self.dc_sync;
        b[5] = self.name_idx;
        b[6..8].copy_from_slice(&self.flags.to_le_bytes());
        Ok(8)
    }
}

/// One 8-byte PDO entry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SiiPdoEntry {
    /// Mapped object index (0 for a gap).
    pub index: u16,
    /// Mapped subindex.
    pub subindex: u8,
    /// String index of the entry name.
    pub name_idx: u8,
    /// Data type index.
    pub data_type: u8,
    /// Length in bits.
    pub bit_len: u8,
    /// Entry flags.
    pub flags: u16,
}

impl SiiEntry for SiiPdoEntry {
    const LEN: usize = 8;
    fn decode(b: &[u8]) -> Self {
        Self {
            index: u16::from_le_bytes([b[0], b[1]]),
            subindex: b[2],
            name_idx: b[3],
            data_type: b[4],
            bit_len: b[5],
            flags: u16::from_le_bytes([b[6], b[7]]),
        }
    }
}

impl SiiPdoEntry {
    /// Writes the 8-byte entry.
    pub fn write(&self, b: &mut [u8]) -> Result<usize, WireError> {
        if b.len() < 8 {
            return Err(WireError::BufferFull);
        }
        b[0..2].copy_from_slice(&self.index.to_le_bytes());
        b[2] = self.subindex;
        b[3] = self.name_idx;
        b[4] = self.data_type;
        b[5] = self.bit_len;
        b[6..8].copy_from_slice(&self.flags.to_le_bytes());
        Ok(8)
    }
}

/// A PDO description: header and its entries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SiiPdo<'a> {
    /// The header.
    pub header: SiiPdoHeader,
    entries: &'a [u8],
}

impl<'a> SiiPdo<'a> {
    /// Iterates the entries.
    pub fn entries(&self) -> Entries<'a, SiiPdoEntry> {
        Entries::new(self.entries)
    }

    /// Total bits of all entries.
    pub fn bit_len(&self) -> u32 {
        self.entries()
            .filter_map(Result::ok)
            .map(|e| e.bit_len as u32)
            .sum()
    }
}

/// Iterator over the PDO descriptions of a TxPDO/RxPDO category.
#[derive(Debug, Clone)]
pub struct Pdos<'a> {
    rest: &'a [u8],
    done: bool,
}

impl<'a> Iterator for Pdos<'a> {
    type Item = Result<SiiPdo<'a>, WireError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done || self.rest.is_empty() {
            return None;
        }
        let header = match SiiPdoHeader::parse(self.rest) {
            Ok(h) => h,
            Err(e) => {
                self.done = true;
                return Some(Err(e));
            }
        };
        let n = 8 + header.entry_count as usize * 8;
        if self.rest.len() < n {
            self.done = true;
            return Some(Err(WireError::LengthMismatch {
                declared: n,
                available: self.rest.len(),
            }));
        }
        let pdo = SiiPdo {
            header,
            entries: &self.rest[8..n],
        };
        self.rest = &self.rest[n..];
        Some(Ok(pdo))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_known_value() {
        // ETG.2010 / SOES example: a zeroed configuration area has CRC 0xFF... check the
        // algorithm against a hand-computed value: crc8(0x00) with init 0xFF = 0xF3.
        assert_eq!(sii_crc8(&[0x00]), 0xF3);
        assert_eq!(sii_crc8(&[]), 0xFF);
    }

    #[test]
    fn build_and_walk() {
        let mut img = [0xFFu8; 256];
        img[..FIXED_AREA_LEN].fill(0);
        SiiConfig {
            pdi_control: 0x0005,
            station_alias: 7,
            ..Default::default()
        }
        .write(&mut img)
        .unwrap();
        SiiIdentity {
            vendor_id: 2,
            product_code: 0x1234,
            revision: 1,
            serial: 9,
        }
        .write(&mut img)
        .unwrap();
        let mut s = [0u8; 32];
        let n = write_strings(&mut s, &[b"Dev", b"Group"]).unwrap();
        let mut o =
            write_category(&mut img, FIXED_AREA_LEN, CategoryType::Strings, &s[..n]).unwrap();
        let mut g = [0u8; GENERAL_LEN];
        SiiGeneral {
            name_idx: 1,
            group_idx: 2,
            ..Default::default()
        }
        .write(&mut g)
        .unwrap();
        o = write_category(&mut img, o, CategoryType::General, &g).unwrap();
        assert!(o < 256);
        let im = SiiImage::new(&img).unwrap();
        assert!(im.crc_ok());
        assert_eq!(im.config().station_alias, 7);
        assert_eq!(im.identity().product_code, 0x1234);
        let st = im.strings().unwrap().unwrap();
        let gen = im.general().unwrap().unwrap();
        assert_eq!(st.get_str(gen.name_idx), Some("Dev"));
        assert_eq!(st.get_str(gen.group_idx), Some("Group"));
        assert_eq!(st.get(3), None);
        assert_eq!(im.categories().count(), 2);
    }
}
