//! The hub's process data and device definition (report §4.3/§4.4): TxPDO 0x1A00 maps
//! Temperature 0x6000 (15 × INT16) and SystemStatus 0x6001 (STATUS, EVENT, ERROR); RxPDO
//! 0x1600 maps MasterCMDs 0x7000 (COMMAND, TEST VALUE0–2); 0xF000 is the modular device
//! profile. SM addresses as the report's ESI (SM2 0x1100, SM3 0x1400), LAN9252 chip.
//!
//! Scaling at the PDO boundary (the one place): temperatures in 0.01 °C (`i16`, so
//! −55…125 °C fit), [`TEMP_INVALID`] for a sensor without a valid reading. STATUS is the
//! full 32-bit status word ([`super::codes::StatusWord`]: 4-bit general state, 14-bit last
//! error, 14-bit last event), so it is UNSIGNED32, not the report's 16 bits (a 32-bit word
//! does not fit 16); EVENT is the last event code, ERROR the most severe *active* error
//! code (0 once every error cleared).

use oxicat_slave::device::{CoeInfo, DcOpMode, DeviceInfo, EscConfigArea, Group, Timeouts};
use oxicat_slave::{
    Access, DataType, DeviceDef, EntryDef, Identity, Limits, MailboxDef, ObjectCode, ObjectDef,
    PdoDef, PdoEntry, PdoMapping, Scale, SyncDef, SyncMode,
};

/// Number of temperature channels (the report's `NUM_OF_SENSORS 15u`).
pub const SENSORS: usize = 15;
/// Temperature value of a channel without a valid reading.
pub const TEMP_INVALID: i16 = i16::MIN;
/// Mailbox size (bytes) of both mailboxes.
pub const MBX: usize = 128;

/// Vendor ID of the report's ESI (`#x00485247`, ASCII "HRG"; not a registered ID).
pub const VENDOR_ID: u32 = 0x0048_5247;
/// Product code of the report's ESI.
pub const PRODUCT_CODE: u32 = 0x1278_3456;

/// COMMAND: no command.
pub const CMD_NONE: u16 = 0;
/// COMMAND: show a custom LED colour, TEST VALUE0/1/2 = red/green/blue (0–255; a value
/// above 255 refuses the command with `ERR_ECAT_CMD_FAULT`).
pub const CMD_LED_CUSTOM: u16 = 1;
/// COMMAND: LEDs back to the state colours.
pub const CMD_LED_AUTO: u16 = 2;
/// COMMAND: overheat threshold = TEST VALUE0 in 0.01 °C (as INT16; outside
/// [`THRESHOLD_RANGE`] refuses the command with `ERR_ECAT_CMD_FAULT`).
pub const CMD_SET_THRESHOLD: u16 = 3;
/// COMMAND: toggle the LED rings off / on again (`EV_ECAT_CMD_LED_TOGGLE`); a hard error
/// still shows red while they are off. Commands act when the four output words change, so
/// a second toggle is COMMAND 0 then 4 again.
pub const CMD_LED_TOGGLE: u16 = 4;
/// The thresholds [`CMD_SET_THRESHOLD`] accepts: the DS18B20's range, −55 … 125 °C, in
/// 0.01 °C.
pub const THRESHOLD_RANGE: core::ops::RangeInclusive<i16> = -5500..=12500;

const fn tx(sub: u8, name: &'static str, t: DataType) -> EntryDef {
    EntryDef::new(sub, name, t, Access::RO).pdo(PdoMapping::Tx)
}

const fn rx(sub: u8, name: &'static str) -> EntryDef {
    EntryDef::new(sub, name, DataType::Unsigned16, Access::RW).pdo(PdoMapping::Rx)
}

/// Temperatures: 0.01 °C steps.
const CENTI_DEG_C: Scale = Scale::per("°C", 100);

const SUB0: EntryDef = EntryDef::new(0, "SubIndex 000", DataType::Unsigned8, Access::RO);

/// The application objects, index order.
pub static OBJECTS: &[ObjectDef] = &[
    ObjectDef {
        index: 0x6000,
        name: "Temperature",
        code: ObjectCode::Record,
        entries: &[
            SUB0,
            tx(1, "TEMPERATURE0", DataType::Int16).limits(&Limits::scale(&CENTI_DEG_C)),
            tx(2, "TEMPERATURE1", DataType::Int16).limits(&Limits::scale(&CENTI_DEG_C)),
            tx(3, "TEMPERATURE2", DataType::Int16).limits(&Limits::scale(&CENTI_DEG_C)),
            tx(4, "TEMPERATURE3", DataType::Int16).limits(&Limits::scale(&CENTI_DEG_C)),
            tx(5, "TEMPERATURE4", DataType::Int16).limits(&Limits::scale(&CENTI_DEG_C)),
            tx(6, "TEMPERATURE5", DataType::Int16).limits(&Limits::scale(&CENTI_DEG_C)),
            tx(7, "TEMPERATURE6", DataType::Int16).limits(&Limits::scale(&CENTI_DEG_C)),
            tx(8, "TEMPERATURE7", DataType::Int16).limits(&Limits::scale(&CENTI_DEG_C)),
            tx(9, "TEMPERATURE8", DataType::Int16).limits(&Limits::scale(&CENTI_DEG_C)),
            tx(10, "TEMPERATURE9", DataType::Int16).limits(&Limits::scale(&CENTI_DEG_C)),
            tx(11, "TEMPERATURE10", DataType::Int16).limits(&Limits::scale(&CENTI_DEG_C)),
            tx(12, "TEMPERATURE11", DataType::Int16).limits(&Limits::scale(&CENTI_DEG_C)),
            tx(13, "TEMPERATURE12", DataType::Int16).limits(&Limits::scale(&CENTI_DEG_C)),
            tx(14, "TEMPERATURE13", DataType::Int16).limits(&Limits::scale(&CENTI_DEG_C)),
            tx(15, "TEMPERATURE14", DataType::Int16).limits(&Limits::scale(&CENTI_DEG_C)),
        ],
    },
    ObjectDef {
        index: 0x6001,
        name: "SystemStatus",
        code: ObjectCode::Record,
        entries: &[
            SUB0,
            tx(1, "STATUS", DataType::Unsigned32),
            tx(2, "EVENT", DataType::Unsigned16),
            tx(3, "ERROR", DataType::Unsigned16),
        ],
    },
    ObjectDef {
        index: 0x7000,
        name: "MasterCMDs",
        code: ObjectCode::Record,
        entries: &[
            SUB0,
            rx(1, "COMMAND"),
            rx(2, "TEST VALUE0"),
            rx(3, "TEST VALUE1"),
            rx(4, "TEST VALUE2"),
        ],
    },
    ObjectDef {
        index: 0xF000,
        name: "Modular Device Profile",
        code: ObjectCode::Record,
        entries: &[
            SUB0,
            EntryDef::new(1, "Module index distance", DataType::Unsigned16, Access::RO)
                .default_bits(0x0010),
            EntryDef::new(
                2,
                "Maximum number of modules",
                DataType::Unsigned16,
                Access::RO,
            )
            .default_bits(0),
        ],
    },
];

/// Object image size of [`OBJECTS`] (`HubSlot`'s `N`). A literal, checked against
/// `image_size(OBJECTS)` below: as a type-level constant computed from the static, rustc
/// found a query cycle through the rig's async closures once `HubSlot` appeared in a trait
/// bound.
pub const IMAGE: usize = 54;
const _: () = assert!(IMAGE == oxicat_slave::image_size(OBJECTS));

const fn t16(sub: u8) -> PdoEntry {
    PdoEntry::of(OBJECTS, 0x6000, sub)
}

/// TxPDO 0x1A00 "Input mapping 0": 15 temperatures + STATUS, EVENT, ERROR (38 bytes).
pub static TX_PDOS: &[PdoDef] = &[PdoDef {
    index: 0x1A00,
    name: "Input mapping 0",
    entries: &[
        t16(1),
        t16(2),
        t16(3),
        t16(4),
        t16(5),
        t16(6),
        t16(7),
        t16(8),
        t16(9),
        t16(10),
        t16(11),
        t16(12),
        t16(13),
        t16(14),
        t16(15),
        PdoEntry::of(OBJECTS, 0x6001, 1),
        PdoEntry::of(OBJECTS, 0x6001, 2),
        PdoEntry::of(OBJECTS, 0x6001, 3),
    ],
    configurable: false,
}];

/// RxPDO 0x1600 "MasterCMDs process data mapping" (8 bytes).
pub static RX_PDOS: &[PdoDef] = &[PdoDef {
    index: 0x1600,
    name: "MasterCMDs process data mapping",
    entries: &[
        PdoEntry::of(OBJECTS, 0x7000, 1),
        PdoEntry::of(OBJECTS, 0x7000, 2),
        PdoEntry::of(OBJECTS, 0x7000, 3),
        PdoEntry::of(OBJECTS, 0x7000, 4),
    ],
    configurable: false,
}];

/// Default RxPDO assignment (0x1C12).
pub static RX_ASSIGN: &[u16] = &[0x1600];
/// Default TxPDO assignment (0x1C13).
pub static TX_ASSIGN: &[u16] = &[0x1A00];
/// Output (RxPDO) bytes of the default assignment.
pub const OUTPUT_BYTES: usize = oxicat_slave::pdo_bytes(RX_PDOS, RX_ASSIGN);
/// Input (TxPDO) bytes of the default assignment.
pub const INPUT_BYTES: usize = oxicat_slave::pdo_bytes(TX_PDOS, TX_ASSIGN);

/// The report's ESI timeouts (Listing D.1, "4 Times from original value" of the SSC
/// defaults 2000/9000/5000/200 ms and 100/2000 ms), in ms.
pub const TIMEOUTS: Timeouts = Timeouts {
    preop: 8000,
    safeop_op: 36000,
    back_to_init: 20000,
    back_to_safeop: 800,
    mailbox_request: 400,
    mailbox_response: 8000,
};

/// ESI/SII description data: the report's LAN9252 EEPROM settings (Listing D.1): PDI
/// control 0x80 with the rest of its `ConfigData` ([`EscConfigArea::LAN9252`]), its
/// state-machine and mailbox timeouts and its CoE flags (PdoUpload), except where the hub's
/// README section says why not (EEPROM size, station alias, CompleteAccess, DC modes).
pub const INFO: DeviceInfo = DeviceInfo {
    vendor_name: "Hans Robot Germany GmbH",
    group: Group {
        type_name: "COMMBBOARD",
        name: "AXIS_COMM",
    },
    order_code: "axcommb",
    description: Some(
        "Axis communication hub: 15 DS18B20 on 1-Wire, WS2812 LED rings, STM32F446 + LAN9252 (SPI)",
    ),
    physics: "YY",
    esc: EscConfigArea::LAN9252,
    // The report's 512 bytes cannot hold the image (870 bytes with the PDO entry names):
    // the next size up (README).
    eeprom_bytes: 1024,
    mailbox_size_range: Some((34, 128)),
    coe: CoeInfo {
        pdo_upload: true,
        ..CoeInfo::STACK
    },
    dc_modes: &[DcOpMode::SM_SYNCHRON, DcOpMode::DC_SYNC0],
    ebus_current_ma: 0,
    timeouts: Some(TIMEOUTS),
    ..DeviceInfo::DEFAULT
};

/// The device definition: the one source of OD, ESI and SII.
pub static DEF: DeviceDef = DeviceDef {
    identity: Identity {
        vendor_id: VENDOR_ID,
        product_code: PRODUCT_CODE,
        revision: 1,
        serial: 0,
    },
    device_type: 0x0000_1389,
    name: "AxisCommBoard slave",
    hw_version: "PCBAB0001v01A (STM32F446ZE + LAN9252)",
    sw_version: env!("CARGO_PKG_VERSION"),
    mailbox: MailboxDef {
        rx_start: 0x1000,
        rx_len: MBX as u16,
        tx_start: 0x1080,
        tx_len: MBX as u16,
    },
    boot_mailbox: None,
    sm2_start: 0x1100,
    sm3_start: 0x1400,
    objects: OBJECTS,
    rx_pdos: RX_PDOS,
    tx_pdos: TX_PDOS,
    rx_assign: RX_ASSIGN,
    tx_assign: TX_ASSIGN,
    assign_configurable: false,
    sync: SyncDef {
        supported: 0x0007,
        default_mode: SyncMode::FreeRun,
        min_cycle_ns: 1_000_000,
        calc_copy_ns: 100_000,
    },
    info: Some(&INFO),
};
