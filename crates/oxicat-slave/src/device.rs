//! The static device definition: identity, mailbox and SM layout, objects, PDOs and
//! supported sync modes. One `static` value per device; the object dictionary, the PDO
//! layout and the ESM checks are all derived from it.

use crate::od::{EntryDef, ObjectDef};
pub use oxicat_wire::sii::FmmuUsage;

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

impl MailboxDef {
    /// The usual layout: 128-byte mailboxes at 0x1000 (SM0) and 0x1080 (SM1).
    pub const STANDARD: MailboxDef = MailboxDef {
        rx_start: 0x1000,
        rx_len: 128,
        tx_start: 0x1080,
        tx_len: 128,
    };
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

    /// The entry `index:sub` of `objects`, its bit length taken from its definition (no
    /// hand-written sizes). In a `const`/`static` a missing entry stops the build.
    pub const fn of(objects: &'static [ObjectDef], index: u16, sub: u8) -> Self {
        match crate::od::find_entry(objects, index, sub) {
            Some(e) => {
                assert!(e.bits <= 255, "a mapped entry has at most 255 bits");
                Self::new(index, sub, e.bits as u8)
            }
            None => panic!("PdoEntry::of: no such object entry"),
        }
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

/// Bits of the process data of the PDOs `assign` (in that order) of `pdos`, and whether
/// every assigned PDO was found (a missing one adds nothing).
const fn assigned_bits(pdos: &[PdoDef], assign: &[u16]) -> (u32, bool) {
    let mut bits = 0u32;
    let mut all = true;
    let mut a = 0;
    while a < assign.len() {
        let mut p = 0;
        let mut found = false;
        while p < pdos.len() {
            if pdos[p].index == assign[a] {
                let mut e = 0;
                while e < pdos[p].entries.len() {
                    bits += pdos[p].entries[e].bits as u32;
                    e += 1;
                }
                found = true;
            }
            p += 1;
        }
        all &= found;
        a += 1;
    }
    (bits, all)
}

/// Bytes of the process data of the PDOs `assign` (in that order) of `pdos`: the SM2/SM3
/// size a layout gives, derived from the mappings (no hand-written sizes). In a `const` an
/// assigned PDO missing from `pdos` stops the build.
pub const fn pdo_bytes(pdos: &[PdoDef], assign: &[u16]) -> usize {
    let (bits, all) = assigned_bits(pdos, assign);
    assert!(all, "pdo_bytes: an assigned PDO is not defined");
    (bits as usize).div_ceil(8)
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
    /// DC SYNC1: outputs mapped on the SM2 event, the application on SYNC0, the inputs
    /// latched on SYNC1 (0x1C33:03 = the SYNC1 delay).
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
    /// What the ESI and the SII need beyond the stack (names, groups, ESC configuration,
    /// DC op modes, FMMU usage, mailbox protocol details); the stack reads none of it.
    /// `None` in a board image's definition ([`DeviceDef::for_image`]): read it with
    /// [`DeviceDef::info`].
    pub info: Option<&'static DeviceInfo>,
}

impl DeviceDef {
    /// This definition as a board image links it: the same device for the stack (every
    /// object, PDO, mailbox, sync and identity field) without its [`DeviceInfo`], which only
    /// the ESI and the SII need, so none of it is in the image's flash
    /// (`static DEF: DeviceDef = demo::DEF.for_image();`). The ESI and the EEPROM are made
    /// from the full definition on the host.
    pub const fn for_image(&self) -> DeviceDef {
        DeviceDef {
            info: None,
            ..*self
        }
    }

    /// The device's [`DeviceInfo`]; [`DeviceInfo::DEFAULT`] for a definition without one
    /// (an image's, [`DeviceDef::for_image`]).
    pub fn info(&self) -> &'static DeviceInfo {
        self.info.unwrap_or(&DeviceInfo::DEFAULT)
    }

    /// A base definition with empty lists and [`DeviceInfo::DEFAULT`]: start a device with
    /// `DeviceDef { identity, name, objects, .., ..DeviceDef::BASE }`.
    pub const BASE: DeviceDef = DeviceDef {
        identity: Identity {
            vendor_id: 0,
            product_code: 0,
            revision: 0,
            serial: 0,
        },
        device_type: 0,
        name: "",
        hw_version: "",
        sw_version: "",
        mailbox: MailboxDef::STANDARD,
        boot_mailbox: None,
        sm2_start: 0x1100,
        sm3_start: 0x1180,
        objects: &[],
        rx_pdos: &[],
        tx_pdos: &[],
        rx_assign: &[],
        tx_assign: &[],
        assign_configurable: false,
        sync: SyncDef {
            supported: 0x0001,
            default_mode: SyncMode::FreeRun,
            min_cycle_ns: 1_000_000,
            calc_copy_ns: 0,
        },
        info: Some(&DeviceInfo::DEFAULT),
    };

    /// The PDO with mapping index `index` (RxPDOs and TxPDOs).
    pub fn pdo(&self, index: u16) -> Option<&'static PdoDef> {
        self.rx_pdos
            .iter()
            .chain(self.tx_pdos.iter())
            .find(|p| p.index == index)
    }

    /// The definition of application entry `index:sub`.
    pub fn entry_def(&self, index: u16, sub: u8) -> Option<&'static EntryDef> {
        crate::od::find_entry(self.objects, index, sub)
    }

    /// The physical scaling of application entry `index:sub`, if it declares one.
    pub fn scale(&self, index: u16, sub: u8) -> Option<crate::od::Scale> {
        self.entry_def(index, sub)?.scale().copied()
    }

    /// The application object with index `index`.
    pub fn object(&self, index: u16) -> Option<&'static ObjectDef> {
        self.objects.iter().find(|o| o.index == index)
    }

    /// Bits of the default RxPDO assignment (SM2 size in bits).
    pub fn default_output_bits(&self) -> u32 {
        assigned_bits(self.rx_pdos, self.rx_assign).0
    }

    /// Bits of the default TxPDO assignment (SM3 size in bits).
    pub fn default_input_bits(&self) -> u32 {
        assigned_bits(self.tx_pdos, self.tx_assign).0
    }

    /// CoE details as the SII general category encodes them (ETG.2010 bit layout).
    pub fn coe_details(&self) -> u8 {
        let c = self.info().coe;
        let mut v = 0;
        if c.enabled {
            v |= 0x01;
        }
        if c.sdo_info {
            v |= 0x02;
        }
        if self.assign_configurable {
            v |= 0x04;
        }
        if self
            .rx_pdos
            .iter()
            .chain(self.tx_pdos.iter())
            .any(|p| p.configurable)
        {
            v |= 0x08;
        }
        if c.pdo_upload {
            v |= 0x10;
        }
        if c.complete_access {
            v |= 0x20;
        }
        v
    }

    /// Mailbox protocols word (SII word 0x1C): AoE 1, EoE 2, CoE 4, FoE 8, SoE 16, VoE 32.
    pub fn mailbox_protocols(&self) -> u16 {
        let i = self.info();
        let mut v = 0;
        if i.eoe {
            v |= 0x02;
        }
        if i.coe.enabled {
            v |= 0x04;
        }
        if i.foe {
            v |= 0x08;
        }
        v
    }
}

/// A device group (ESI `Descriptions/Groups/Group`; the SII group string).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Group {
    /// Group type: the key devices refer to (`GroupType`).
    pub type_name: &'static str,
    /// Display name of the group.
    pub name: &'static str,
}

/// The ESC configuration area of the SII (words 0..6), loaded into ESC registers at power-on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EscConfigArea {
    /// PDI control (0x0140/0x0141), e.g. 0x0005 SPI, 0x0080 on-chip bus.
    pub pdi_control: u16,
    /// PDI configuration (0x0150/0x0151).
    pub pdi_config: u16,
    /// SYNC impulse length in 10 ns units (0x0982).
    pub sync_impulse_len: u16,
    /// Extended PDI configuration (0x0152/0x0153).
    pub pdi_config2: u16,
    /// Configured station alias (0x0012).
    pub station_alias: u16,
}

impl EscConfigArea {
    /// SPI PDI (LAN9252 / FB1111 style): PDI control 0x0005, SYNC0/1 push-pull active high
    /// outputs, 1 µs SYNC impulse.
    pub const SPI: EscConfigArea = EscConfigArea {
        pdi_control: 0x0005,
        pdi_config: 0xEE00,
        sync_impulse_len: 100,
        pdi_config2: 0x0000,
        station_alias: 0,
    };

    /// Microchip LAN9252: PDI control 0x80 (the ESC core's PDI is the chip's on-chip bus;
    /// SPI/HBI is the LAN9252's own host interface, chosen by strap pins, so 0x05 would
    /// leave the core without a PDI), 0x0141 = 0x02 (enhanced link detection), SYNC0/1
    /// push-pull active low outputs mapped to the AL event request (0x0151 = 0xCC), 50 µs
    /// SYNC impulse, extended PDI configuration 0x00FF: the axis hub report's ConfigData
    /// `800200cc8813ff00` (Listing D.1).
    pub const LAN9252: EscConfigArea = EscConfigArea {
        pdi_control: 0x0280,
        pdi_config: 0xCC00,
        sync_impulse_len: 5000,
        pdi_config2: 0x00FF,
        station_alias: 0,
    };
}

/// ESI timeouts in ms (ETG.2000 `Info/StateMachine/Timeout`, `Info/Mailbox/Timeout`): how
/// long a configuration tool waits for a state change or a mailbox answer. ESI only (the SII
/// has no place for them).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Timeouts {
    /// INIT → PREOP (`PreopTimeout`).
    pub preop: u32,
    /// PREOP → SAFEOP and SAFEOP → OP (`SafeopOpTimeout`).
    pub safeop_op: u32,
    /// Any state → INIT (`BackToInitTimeout`).
    pub back_to_init: u32,
    /// OP → SAFEOP (`BackToSafeopTimeout`).
    pub back_to_safeop: u32,
    /// Mailbox request: the slave takes the master's mailbox (`RequestTimeout`).
    pub mailbox_request: u32,
    /// Mailbox response: the slave answers (`ResponseTimeout`).
    pub mailbox_response: u32,
}

/// CoE support details (ESI `Mailbox/CoE` attributes; SII general CoE details).
/// PdoAssign and PdoConfig follow from [`DeviceDef::assign_configurable`] and
/// [`PdoDef::configurable`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CoeInfo {
    /// CoE is supported at all.
    pub enabled: bool,
    /// SDO information service.
    pub sdo_info: bool,
    /// SDO complete access.
    pub complete_access: bool,
    /// The master should upload the PDO configuration at start-up.
    pub pdo_upload: bool,
    /// Segmented SDO transfers.
    pub segmented_sdo: bool,
}

impl CoeInfo {
    /// What the oxicat stack implements: SDO, SDO info, complete access, segmented SDO.
    pub const STACK: CoeInfo = CoeInfo {
        enabled: true,
        sdo_info: true,
        complete_access: true,
        pdo_upload: false,
        segmented_sdo: true,
    };
}

/// One DC operation mode (ESI `Dc/OpMode`, SII DC category entry).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DcOpMode {
    /// Short name (e.g. `DC_Sync0`).
    pub name: &'static str,
    /// Description shown by configuration tools.
    pub desc: &'static str,
    /// Value for the DC activation register 0x0980/0x0981 (0x0300: SYNC0, 0x0700: SYNC0+1).
    pub assign_activate: u16,
    /// SYNC0 cycle time in ns (0: the master's cycle time times `sync0_factor`).
    pub cycle_sync0: u32,
    /// SYNC0 cycle factor (multiples of the master cycle).
    pub sync0_factor: i16,
    /// SYNC0 shift time in ns.
    pub shift_sync0: u32,
    /// SYNC1 cycle factor.
    pub sync1_factor: i16,
    /// SYNC1 shift time in ns.
    pub shift_sync1: u32,
}

impl DcOpMode {
    /// Free run / SM-synchronous: no DC activation.
    pub const SM_SYNCHRON: DcOpMode = DcOpMode {
        name: "SM_Synchron",
        desc: "SM-Synchron",
        assign_activate: 0,
        cycle_sync0: 0,
        sync0_factor: 0,
        shift_sync0: 0,
        sync1_factor: 0,
        shift_sync1: 0,
    };
    /// DC SYNC0 with the master's cycle time.
    pub const DC_SYNC0: DcOpMode = DcOpMode {
        name: "DC_Sync0",
        desc: "DC-Synchron (SYNC0)",
        assign_activate: 0x0300,
        cycle_sync0: 0,
        sync0_factor: 1,
        shift_sync0: 0,
        sync1_factor: 0,
        shift_sync1: 0,
    };
    /// DC SYNC0 + SYNC1 (application on SYNC0, input latch on SYNC1), as in the thesis.
    pub const DC_SYNC01: DcOpMode = DcOpMode {
        name: "DC_Sync01",
        desc: "DC-Synchron (SYNC0 + SYNC1)",
        assign_activate: 0x0700,
        cycle_sync0: 0,
        sync0_factor: 1,
        shift_sync0: 0,
        sync1_factor: 1,
        shift_sync1: 0,
    };
}

/// Sync manager control bytes (register 0x0804) of the four standard SMs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SmControl {
    /// SM0, mailbox out (default 0x26: mailbox, write, PDI IRQ).
    pub mbx_out: u8,
    /// SM1, mailbox in (default 0x22).
    pub mbx_in: u8,
    /// SM2, outputs (default 0x64: 3-buffer, write, PDI IRQ, watchdog).
    pub outputs: u8,
    /// SM3, inputs (default 0x20: 3-buffer, read).
    pub inputs: u8,
}

/// Description data for ESI and SII that the stack itself does not use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeviceInfo {
    /// Vendor name (ESI `Vendor/Name`).
    pub vendor_name: &'static str,
    /// Group of the device.
    pub group: Group,
    /// Order code / device type name (ESI `Type` text; SII order string).
    pub order_code: &'static str,
    /// Optional description (ESI `Comment`).
    pub description: Option<&'static str>,
    /// Optional image name (SII image string; ESI `Image16x14`).
    pub image: Option<&'static str>,
    /// Port physics, one letter per port (`Y`: MII/100BASE-TX, `K`: E-bus).
    pub physics: &'static str,
    /// ESC configuration area.
    pub esc: EscConfigArea,
    /// EEPROM size in bytes (power of two, at least 256).
    pub eeprom_bytes: u32,
    /// SII version word (0x3F).
    pub sii_version: u16,
    /// FMMU usage, in FMMU order.
    pub fmmus: &'static [FmmuUsage],
    /// SM control bytes.
    pub sm_control: SmControl,
    /// Minimum and maximum mailbox sizes a master may configure (ESI `MinSize`/`MaxSize`).
    pub mailbox_size_range: Option<(u16, u16)>,
    /// CoE details.
    pub coe: CoeInfo,
    /// FoE supported.
    pub foe: bool,
    /// EoE supported.
    pub eoe: bool,
    /// DC operation modes (empty: no `Dc` element, no DC category).
    pub dc_modes: &'static [DcOpMode],
    /// Current consumption from the E-bus in mA (negative: feeds current).
    pub ebus_current_ma: i16,
    /// State-machine and mailbox timeouts for the ESI (`None`: no `Info/StateMachine`,
    /// `Info/Mailbox`; tools use their defaults).
    pub timeouts: Option<Timeouts>,
}

impl DeviceInfo {
    /// Defaults: SPI PDI, 2 KiB EEPROM, FMMUs Outputs/Inputs/MBoxState, standard SM control
    /// bytes, CoE as the stack implements it, no DC modes.
    pub const DEFAULT: DeviceInfo = DeviceInfo {
        vendor_name: "",
        group: Group {
            type_name: "",
            name: "",
        },
        order_code: "",
        description: None,
        image: None,
        physics: "YY",
        esc: EscConfigArea::SPI,
        eeprom_bytes: 2048,
        sii_version: 1,
        fmmus: &[
            FmmuUsage::Outputs,
            FmmuUsage::Inputs,
            FmmuUsage::SyncManagerStatus,
        ],
        sm_control: SmControl {
            mbx_out: 0x26,
            mbx_in: 0x22,
            outputs: 0x64,
            inputs: 0x20,
        },
        mailbox_size_range: None,
        coe: CoeInfo::STACK,
        foe: false,
        eoe: false,
        dc_modes: &[],
        ebus_current_ma: 0,
        timeouts: None,
    };
}
