//! The slave-stack test device: object dictionary, process data, SII image and an
//! application that records what the stack hands it.

use oxicat_slave::*;
use oxicat_wire::sii::{MailboxArea, SiiConfig, SiiIdentity, SiiMailboxConfig};

pub const MBX: usize = 128;
pub const SM0: u16 = 0x1000;
pub const SM1: u16 = 0x1080;
pub const SM2: u16 = 0x1100;
pub const SM3: u16 = 0x1180;
pub const STATION: u16 = 0x1001;

const B: DataType = DataType::Bool;

pub static OBJECTS: &[ObjectDef] = &[
    ObjectDef {
        index: 0x2000,
        name: "Param",
        code: ObjectCode::Var,
        entries: &[EntryDef::new(0, "Param", DataType::Unsigned32, Access::RW)
            .default_bits(7)
            .limits(&Limits::range(0, 1000).with_unit(0xFD04_0000))],
    },
    ObjectDef {
        index: 0x2001,
        name: "Blob",
        code: ObjectCode::Var,
        entries: &[EntryDef::octets(0, "Blob", 1100, Access::RW)],
    },
    ObjectDef {
        index: 0x2002,
        name: "Const",
        code: ObjectCode::Var,
        entries: &[EntryDef::new(0, "Const", DataType::Int8, Access::RO).default_i64(-5)],
    },
    ObjectDef {
        index: 0x2003,
        name: "Secret",
        code: ObjectCode::Var,
        entries: &[EntryDef::new(0, "Secret", DataType::Unsigned16, Access::WO)],
    },
    ObjectDef {
        index: 0x2004,
        name: "Gain",
        code: ObjectCode::Var,
        entries: &[EntryDef::new(0, "Gain", DataType::Real32, Access::RW_PREOP).default_f32(1.5)],
    },
    ObjectDef {
        index: 0x2005,
        name: "Types",
        code: ObjectCode::Record,
        entries: &[
            EntryDef::new(0, "Number of entries", DataType::Unsigned8, Access::RO),
            EntryDef::new(1, "b", B, Access::RW),
            EntryDef::new(2, "i8", DataType::Int8, Access::RW),
            EntryDef::new(3, "i16", DataType::Int16, Access::RW),
            EntryDef::new(4, "i32", DataType::Int32, Access::RW),
            EntryDef::new(5, "i64", DataType::Int64, Access::RW),
            EntryDef::new(6, "u8", DataType::Unsigned8, Access::RW),
            EntryDef::new(7, "u16", DataType::Unsigned16, Access::RW),
            EntryDef::new(8, "u32", DataType::Unsigned32, Access::RW),
            EntryDef::new(9, "u64", DataType::Unsigned64, Access::RW),
            EntryDef::new(10, "r32", DataType::Real32, Access::RW),
            EntryDef::new(11, "r64", DataType::Real64, Access::RW),
        ],
    },
    ObjectDef {
        index: 0x2006,
        name: "Label",
        code: ObjectCode::Var,
        entries: &[EntryDef::string(0, "Label", 16, Access::RW)
            .limits(&Limits::NONE.with_default(DefaultValue::Bytes(b"hello")))],
    },
    ObjectDef {
        index: 0x6000,
        name: "Inputs",
        code: ObjectCode::Record,
        entries: &[
            EntryDef::new(0, "Number of entries", DataType::Unsigned8, Access::RO),
            EntryDef::new(1, "Button 1", B, Access::RO).pdo(PdoMapping::Tx),
            EntryDef::new(2, "Button 2", B, Access::RO).pdo(PdoMapping::Tx),
            EntryDef::new(3, "Analog", DataType::Int16, Access::RO).pdo(PdoMapping::Tx),
            EntryDef::new(4, "Counter", DataType::Unsigned32, Access::RO).pdo(PdoMapping::Tx),
        ],
    },
    ObjectDef {
        index: 0x7000,
        name: "Outputs",
        code: ObjectCode::Record,
        entries: &[
            EntryDef::new(0, "Number of entries", DataType::Unsigned8, Access::RO),
            EntryDef::new(1, "LED", B, Access::RW).pdo(PdoMapping::Rx),
            EntryDef::new(2, "Setpoint", DataType::Int16, Access::RW).pdo(PdoMapping::Rx),
            EntryDef::new(3, "Mode", DataType::Unsigned8, Access::RW).pdo(PdoMapping::Rx),
        ],
    },
];

pub const IMG: usize = image_size(OBJECTS);

pub static DEF: DeviceDef = DeviceDef {
    identity: Identity {
        vendor_id: 0x0000_0A5C,
        product_code: 0x0000_0001,
        revision: 0x0001_0000,
        serial: 42,
    },
    device_type: 0x0000_1389,
    name: "oxicat test device",
    hw_version: "1.0",
    sw_version: "0.1",
    mailbox: MailboxDef {
        rx_start: SM0,
        rx_len: MBX as u16,
        tx_start: SM1,
        tx_len: MBX as u16,
    },
    boot_mailbox: Some(MailboxDef {
        rx_start: SM0,
        rx_len: MBX as u16,
        tx_start: SM1,
        tx_len: MBX as u16,
    }),
    sm2_start: SM2,
    sm3_start: SM3,
    objects: OBJECTS,
    rx_pdos: &[PdoDef {
        index: 0x1600,
        name: "Outputs",
        entries: &[
            PdoEntry::new(0x7000, 1, 1),
            PdoEntry::gap(7),
            PdoEntry::new(0x7000, 2, 16),
            PdoEntry::new(0x7000, 3, 8),
        ],
        configurable: true,
    }],
    tx_pdos: &[
        PdoDef {
            index: 0x1A00,
            name: "Inputs",
            entries: &[
                PdoEntry::new(0x6000, 1, 1),
                PdoEntry::new(0x6000, 2, 1),
                PdoEntry::gap(6),
                PdoEntry::new(0x6000, 3, 16),
                PdoEntry::new(0x6000, 4, 32),
            ],
            configurable: false,
        },
        PdoDef {
            index: 0x1A01,
            name: "Extra",
            entries: &[PdoEntry::new(0x6000, 3, 16)],
            configurable: true,
        },
    ],
    rx_assign: &[0x1600],
    tx_assign: &[0x1A00],
    assign_configurable: true,
    sync: SyncDef {
        supported: 0x000F,
        default_mode: SyncMode::FreeRun,
        min_cycle_ns: 100_000,
        calc_copy_ns: 10_000,
    },
    info: Some(&device::DeviceInfo::DEFAULT),
};

/// SII image for a definition (config area, identity, mailbox layout).
pub fn eeprom(def: &DeviceDef) -> Vec<u8> {
    let mut e = vec![0u8; 2048];
    SiiConfig {
        pdi_control: 0x0005,
        ..Default::default()
    }
    .write(&mut e)
    .unwrap();
    SiiIdentity {
        vendor_id: def.identity.vendor_id,
        product_code: def.identity.product_code,
        revision: def.identity.revision,
        serial: def.identity.serial,
    }
    .write(&mut e)
    .unwrap();
    let m = def.mailbox;
    let b = def.boot_mailbox.unwrap_or(m);
    SiiMailboxConfig {
        bootstrap_rx: MailboxArea {
            offset: b.rx_start,
            size: b.rx_len,
        },
        bootstrap_tx: MailboxArea {
            offset: b.tx_start,
            size: b.tx_len,
        },
        standard_rx: MailboxArea {
            offset: m.rx_start,
            size: m.rx_len,
        },
        standard_tx: MailboxArea {
            offset: m.tx_start,
            size: m.tx_len,
        },
        protocols: oxicat_wire::mailbox::protocols::COE,
    }
    .write(&mut e)
    .unwrap();
    e[0x7C..0x7E].copy_from_slice(&15u16.to_le_bytes());
    e[0x80..0x82].copy_from_slice(&0xFFFFu16.to_le_bytes());
    e
}

/// Application used by the tests: counts cycles, copies Setpoint to Analog, refuses OP
/// when 0x2000 == 999.
#[derive(Default)]
pub struct App {
    pub cycles: u32,
    pub safe: u32,
    pub written: Vec<(u16, u8)>,
}

impl Application<IMG> for App {
    fn state_change(
        &mut self,
        _f: AlState,
        to: AlState,
        od: &mut Od<IMG>,
    ) -> Result<(), AlStatusCode> {
        if to == AlState::Op && od.get::<u32>(0x2000, 0) == Ok(999) {
            return Err(AlStatusCode(0x8001));
        }
        Ok(())
    }
    fn safe_outputs(&mut self, od: &mut Od<IMG>) {
        self.safe += 1;
        let _ = od.set(0x7000, 2, 0i16);
        let _ = od.set(0x7000, 1, false);
    }
    fn cycle(&mut self, od: &mut Od<IMG>) {
        self.cycles += 1;
        let sp: i16 = od.get(0x7000, 2).unwrap();
        od.set(0x6000, 3, sp.wrapping_mul(2)).unwrap();
        let led: bool = od.get(0x7000, 1).unwrap();
        od.set(0x6000, 2, led).unwrap();
        od.set(0x6000, 4, self.cycles).unwrap();
    }
    fn sdo_written(&mut self, index: u16, sub: u8, _od: &mut Od<IMG>) {
        self.written.push((index, sub));
    }
}
