//! The static device definition: identity, mailbox and SM layout, objects, PDOs and
//! supported sync modes. One `static` value per device; the object dictionary, the PDO
//! layout and the ESM checks are all derived from it.

use crate::od::ObjectDef;

/// Identity of a device (object 0x1018, SII words 0x08..0x0F).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Identity {
    /// Vendor ID.
    pub vendor_id: u32,
    /// Product code.
    pub product_code: u32,
    /// Revision number.
    pub revision: u32,
    /// Serial number.
    pub serial: u32,
}

/// Physical placement of a mailbox pair (SM0: master → slave, SM1: slave → master).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MailboxDef {
    /// SM0 start address (receive mailbox, written by the master).
    pub rx_start: u16,
    /// SM0 length.
    pub rx_len: u16,
    /// SM1 start address (send mailbox, read by the master).
    pub tx_start: u16,
    /// SM1 length.
    pub tx_len: u16,
}

/// One entry of a PDO mapping: object index, subindex and bit length (index 0 = gap).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PdoEntry {
    /// Mapped object index (0 for a padding gap).
    pub index: u16,
    /// Mapped subindex.
    pub sub: u8,
    /// Bit length.
    pub bits: u8,
}

impl PdoEntry {
    /// A mapped object entry.
    pub const fn new(index: u16, sub: u8, bits: u8) -> Self {
        Self { index, sub, bits }
    }

    /// A gap of `bits` bits.
    pub const fn gap(bits: u8) -> Self {
        Self {
            index: 0,
            sub: 0,
            bits,
        }
    }

    /// The 32-bit mapping value as in 0x16xx/0x1Axx (index << 16 | sub << 8 | bits).
    pub const fn encode(&self) -> u32 {
        ((self.index as u32) << 16) | ((self.sub as u32) << 8) | self.bits as u32
    }

    /// Decodes a 32-bit mapping value.
    pub const fn decode(v: u32) -> Self {
        Self {
            index: (v >> 16) as u16,
            sub: (v >> 8) as u8,
            bits: v as u8,
        }
    }
}

/// A PDO (mapping object 0x16xx RxPDO or 0x1Axx TxPDO) with its default mapping.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PdoDef {
    /// Mapping object index (0x1600..0x17FF or 0x1A00..0x1BFF).
    pub index: u16,
    /// Name of the PDO.
    pub name: &'static str,
    /// Default mapping.
    pub entries: &'static [PdoEntry],
    /// The master may change the mapping (in PREOP).
    pub configurable: bool,
}

/// Synchronisation modes (values of 0x1C32:01 / 0x1C33:01).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u16)]
pub enum SyncMode {
    /// Free run: the application runs on a local timer / in `poll`.
    FreeRun = 0,
    /// SM-synchronous: on the SM2 (outputs) or SM3 event.
    SmSync = 1,
    /// DC SYNC0.
    DcSync0 = 2,
    /// DC SYNC1 (SYNC0 for the application, SYNC1 for input latch).
    DcSync1 = 3,
}

impl SyncMode {
    /// Decodes a 0x1C32:01 value.
    pub const fn from_u16(v: u16) -> Option<Self> {
        match v {
            0 => Some(Self::FreeRun),
            1 => Some(Self::SmSync),
            2 => Some(Self::DcSync0),
            3 => Some(Self::DcSync1),
            _ => None,
        }
    }

    /// Bit of this mode in [`SyncDef::supported`] (0x1C32:04 layout).
    pub const fn support_bit(self) -> u16 {
        match self {
            Self::FreeRun => 0x0001,
            Self::SmSync => 0x0002,
            Self::DcSync0 => 0x0004,
            Self::DcSync1 => 0x0008,
        }
    }
}

/// What synchronisation the device supports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SyncDef {
    /// Bit set of supported modes ([`SyncMode::support_bit`]); written to 0x1C32:04 bits 0..3.
    pub supported: u16,
    /// Mode used when the master configures nothing.
    pub default_mode: SyncMode,
    /// Minimum cycle time in ns (0x1C32:05).
    pub min_cycle_ns: u32,
    /// Calc-and-copy time in ns (0x1C32:06).
    pub calc_copy_ns: u32,
}

/// The complete static definition of a device.
#[derive(Debug, Clone, Copy)]
pub struct DeviceDef {
    /// Identity (0x1018).
    pub identity: Identity,
    /// Device type (0x1000).
    pub device_type: u32,
    /// Device name (0x1008).
    pub name: &'static str,
    /// Hardware version (0x1009).
    pub hw_version: &'static str,
    /// Software version (0x100A).
    pub sw_version: &'static str,
    /// Standard mailbox layout.
    pub mailbox: MailboxDef,
    /// Bootstrap mailbox layout; `None` if BOOT is not supported.
    pub boot_mailbox: Option<MailboxDef>,
    /// SM2 (outputs) start address.
    pub sm2_start: u16,
    /// SM3 (inputs) start address.
    pub sm3_start: u16,
    /// Application objects (index >= 0x2000), sorted by index.
    pub objects: &'static [ObjectDef],
    /// RxPDOs (outputs, 0x16xx).
    pub rx_pdos: &'static [PdoDef],
    /// TxPDOs (inputs, 0x1Axx).
    pub tx_pdos: &'static [PdoDef],
    /// Default RxPDO assignment (0x1C12).
    pub rx_assign: &'static [u16],
    /// Default TxPDO assignment (0x1C13).
    pub tx_assign: &'static [u16],
    /// The master may change 0x1C12/0x1C13 (in PREOP).
    pub assign_configurable: bool,
    /// Synchronisation support.
    pub sync: SyncDef,
}
