//! The joint drive's object dictionary, default PDO mapping and device definition.
//!
//! Units: positions in motor encoder increments, velocities in increments/s, torques in
//! ‰ of the motor rated torque 0x6076 (motor side), currents in ‰ of the motor rated
//! current 0x6075. The joint torque sensor (output side of the gear) is reported in the
//! manufacturer object **0x2002 "Joint torque sensor" (INTEGER32, mN·m, TxPDO-mappable)**;
//! 0x6077 stays the CiA402 motor torque (k_t · i_q).
//!
//! | PDO | default entries |
//! |---|---|
//! | RxPDO 0x1600 (configurable) | 0x6040 controlword, 0x6060 mode, 0x607A target position, 0x60FF target velocity, 0x6071 target torque |
//! | TxPDO 0x1A00 (configurable) | 0x6041 statusword, 0x6061 mode display, 0x6064 position, 0x606C velocity, 0x6077 torque, 0x603F error code |

use oxicat_slave::device::{DcOpMode, DeviceInfo, Group};
use oxicat_slave::{
    Access as A, DataType as T, DeviceDef, EntryDef as E, Identity, Limits, MailboxDef, ObjectCode,
    ObjectDef, PdoDef, PdoEntry as PE, PdoMapping as M, SyncDef, SyncMode,
};

/// 0x1000 device type: CiA402 (0x0192), servo drive (type 0x02 in bits 16–23).
pub const DEVICE_TYPE: u32 = 0x0002_0192;

/// Product code of the joint drive.
pub const PRODUCT_CODE: u32 = 0x0402_0001;

/// Supported drive modes 0x6502: PP (bit 0), PV (2), PT (3), HM (5), IP (6), CSP (7),
/// CSV (8), CST (9).
pub const SUPPORTED_MODES: u32 =
    (1 << 0) | (1 << 2) | (1 << 3) | (1 << 5) | (1 << 6) | (1 << 7) | (1 << 8) | (1 << 9);

/// Abort connection option code 0x6007 at power-on: 3, quick stop (README: why not the
/// 1 of CiA 402-2).
pub const ABORT_CONNECTION_DEFAULT: i16 = 3;

const SUB0: E = E::new(0, "SubIndex 000", T::Unsigned8, A::RO);

const fn var(index: u16, name: &'static str, entries: &'static [E]) -> ObjectDef {
    ObjectDef {
        index,
        name,
        code: ObjectCode::Var,
        entries,
    }
}

macro_rules! v {
    ($name:literal, $t:ident, $a:ident) => {
        &[E::new(0, $name, T::$t, A::$a)]
    };
    ($name:literal, $t:ident, $a:ident, $m:ident) => {
        &[E::new(0, $name, T::$t, A::$a).pdo(M::$m)]
    };
    ($name:literal, $t:ident, $a:ident, def $d:expr) => {
        &[E::new(0, $name, T::$t, A::$a).default_i64($d)]
    };
    ($name:literal, $t:ident, $a:ident, $m:ident, [$u:literal / $den:literal]) => {
        &[E::new(0, $name, T::$t, A::$a)
            .pdo(M::$m)
            .limits(&oxicat_slave::Limits::scale(&oxicat_slave::Scale {
                unit: $u,
                num: 1,
                den: $den,
            }))]
    };
    ($name:literal, $t:ident, $a:ident, $m:ident, def $d:expr) => {
        &[E::new(0, $name, T::$t, A::$a).pdo(M::$m).default_i64($d)]
    };
}

/// Control-loop gains 0x2000 (REAL32, writable in every state).
pub mod gains {
    /// Current loop proportional gain \[V/A\].
    pub const CURRENT_KP: f32 = 1.9;
    /// Current loop integral gain \[V/(A·s)\].
    pub const CURRENT_KI: f32 = 3000.0;
    /// Velocity loop proportional gain \[N·m/(rad/s)\], motor side.
    pub const VELOCITY_KP: f32 = 0.008;
    /// Velocity loop integral gain \[N·m/rad\].
    pub const VELOCITY_KI: f32 = 0.25;
    /// Position loop proportional gain \[1/s\].
    pub const POSITION_KP: f32 = 30.0;
}

/// The objects of the drive, in index order.
pub static OBJECTS: &[ObjectDef] = &[
    ObjectDef {
        index: 0x2000,
        name: "Control loop gains",
        code: ObjectCode::Record,
        entries: &[
            SUB0,
            E::new(1, "Current Kp", T::Real32, A::RW).default_f32(gains::CURRENT_KP),
            E::new(2, "Current Ki", T::Real32, A::RW).default_f32(gains::CURRENT_KI),
            E::new(3, "Velocity Kp", T::Real32, A::RW).default_f32(gains::VELOCITY_KP),
            E::new(4, "Velocity Ki", T::Real32, A::RW).default_f32(gains::VELOCITY_KI),
            E::new(5, "Position Kp", T::Real32, A::RW).default_f32(gains::POSITION_KP),
        ],
    },
    var(
        0x2002,
        "Joint torque sensor",
        v!("Joint torque sensor", Int32, RO, Tx, ["N m" / 1000]),
    ),
    var(
        0x6007,
        "Abort connection option code",
        &[E::new(0, "Abort connection option code", T::Int16, A::RW)
            .default_i64(ABORT_CONNECTION_DEFAULT as i64)
            .limits(&Limits::range(0, 3))],
    ),
    var(0x603F, "Error code", v!("Error code", Unsigned16, RO, Tx)),
    var(0x6040, "Controlword", v!("Controlword", Unsigned16, RW, Rx)),
    var(0x6041, "Statusword", v!("Statusword", Unsigned16, RO, Tx)),
    var(
        0x605A,
        "Quick stop option code",
        v!("Quick stop option code", Int16, RW, def 2),
    ),
    var(
        0x605B,
        "Shutdown option code",
        v!("Shutdown option code", Int16, RW, def 0),
    ),
    var(
        0x605C,
        "Disable operation option code",
        v!("Disable operation option code", Int16, RW, def 1),
    ),
    var(
        0x605D,
        "Halt option code",
        v!("Halt option code", Int16, RW, def 1),
    ),
    var(
        0x605E,
        "Fault reaction option code",
        v!("Fault reaction option code", Int16, RW, def 2),
    ),
    var(
        0x6060,
        "Modes of operation",
        v!("Modes of operation", Int8, RW, Rx, def 8),
    ),
    var(
        0x6061,
        "Modes of operation display",
        v!("Modes of operation display", Int8, RO, Tx),
    ),
    var(
        0x6062,
        "Position demand value",
        v!("Position demand value", Int32, RO, Tx),
    ),
    var(
        0x6064,
        "Position actual value",
        v!("Position actual value", Int32, RO, Tx, ["inc" / 1]),
    ),
    var(
        0x6065,
        "Following error window",
        v!("Following error window", Unsigned32, RW, def 20_000),
    ),
    var(
        0x6066,
        "Following error time out",
        v!("Following error time out", Unsigned16, RW, def 10),
    ),
    var(
        0x6067,
        "Position window",
        v!("Position window", Unsigned32, RW, def 200),
    ),
    var(
        0x6068,
        "Position window time",
        v!("Position window time", Unsigned16, RW, def 5),
    ),
    var(
        0x606C,
        "Velocity actual value",
        v!("Velocity actual value", Int32, RO, Tx, ["inc/s" / 1]),
    ),
    var(
        0x606D,
        "Velocity window",
        v!("Velocity window", Unsigned16, RW, def 2000),
    ),
    var(
        0x6071,
        "Target torque",
        v!("Target torque", Int16, RW, Rx, ["%" / 10]),
    ),
    var(
        0x6072,
        "Max torque",
        v!("Max torque", Unsigned16, RW, def 3000),
    ),
    var(
        0x6075,
        "Motor rated current",
        v!("Motor rated current", Unsigned32, RW, def 4000),
    ),
    var(
        0x6076,
        "Motor rated torque",
        v!("Motor rated torque", Unsigned32, RW, def 200),
    ),
    var(
        0x6077,
        "Torque actual value",
        v!("Torque actual value", Int16, RO, Tx, ["%" / 10]),
    ),
    var(
        0x6078,
        "Current actual value",
        v!("Current actual value", Int16, RO, Tx, ["%" / 10]),
    ),
    var(
        0x607A,
        "Target position",
        v!("Target position", Int32, RW, Rx, ["inc" / 1]),
    ),
    var(0x607C, "Home offset", v!("Home offset", Int32, RW, Rx)),
    ObjectDef {
        index: 0x607D,
        name: "Software position limit",
        code: ObjectCode::Array,
        entries: &[
            SUB0,
            E::new(1, "Min position limit", T::Int32, A::RW),
            E::new(2, "Max position limit", T::Int32, A::RW),
        ],
    },
    var(
        0x6080,
        "Max motor speed",
        v!("Max motor speed", Unsigned32, RW, def 1_000_000),
    ),
    var(
        0x6081,
        "Profile velocity",
        v!("Profile velocity", Unsigned32, RW, Rx, def 200_000),
    ),
    var(
        0x6083,
        "Profile acceleration",
        v!("Profile acceleration", Unsigned32, RW, def 2_000_000),
    ),
    var(
        0x6084,
        "Profile deceleration",
        v!("Profile deceleration", Unsigned32, RW, def 2_000_000),
    ),
    var(
        0x6085,
        "Quick stop deceleration",
        v!("Quick stop deceleration", Unsigned32, RW, def 8_000_000),
    ),
    var(
        0x6087,
        "Torque slope",
        v!("Torque slope", Unsigned32, RW, def 10_000),
    ),
    var(
        0x6098,
        "Homing method",
        v!("Homing method", Int8, RW, def 37),
    ),
    ObjectDef {
        index: 0x6099,
        name: "Homing speeds",
        code: ObjectCode::Array,
        entries: &[
            SUB0,
            E::new(1, "Speed during search for switch", T::Unsigned32, A::RW).default_i64(100_000),
            E::new(2, "Speed during search for zero", T::Unsigned32, A::RW).default_i64(20_000),
        ],
    },
    var(
        0x609A,
        "Homing acceleration",
        v!("Homing acceleration", Unsigned32, RW, def 1_000_000),
    ),
    var(
        0x60B0,
        "Position offset",
        v!("Position offset", Int32, RW, Rx, ["inc" / 1]),
    ),
    var(
        0x60B1,
        "Velocity offset",
        v!("Velocity offset", Int32, RW, Rx, ["inc/s" / 1]),
    ),
    var(
        0x60B2,
        "Torque offset",
        v!("Torque offset", Int16, RW, Rx, ["%" / 10]),
    ),
    var(
        0x60C0,
        "Interpolation sub mode select",
        &[E::new(0, "Interpolation sub mode select", T::Int16, A::RW)
            .default_i64(0)
            .limits(&Limits::range(0, 0))],
    ),
    ObjectDef {
        index: 0x60C1,
        name: "Interpolation data record",
        code: ObjectCode::Array,
        entries: &[
            SUB0,
            E::new(1, "Interpolation data record 1", T::Int32, A::RW).pdo(M::Rx),
        ],
    },
    ObjectDef {
        index: 0x60C2,
        name: "Interpolation time period",
        code: ObjectCode::Record,
        entries: &[
            SUB0,
            E::new(1, "Interpolation time period value", T::Unsigned8, A::RW)
                .default_i64(1)
                .limits(&Limits::range(1, 255)),
            E::new(2, "Interpolation time index", T::Int8, A::RW)
                .default_i64(-3)
                .limits(&Limits::range(-6, 0)),
        ],
    },
    var(
        0x60F4,
        "Following error actual value",
        v!("Following error actual value", Int32, RO, Tx, ["inc" / 1]),
    ),
    var(
        0x60FD,
        "Digital inputs",
        v!("Digital inputs", Unsigned32, RO, Tx),
    ),
    var(
        0x60FF,
        "Target velocity",
        v!("Target velocity", Int32, RW, Rx, ["inc/s" / 1]),
    ),
    var(
        0x6502,
        "Supported drive modes",
        v!("Supported drive modes", Unsigned32, RO, def SUPPORTED_MODES as i64),
    ),
];

/// Image bytes of [`OBJECTS`].
pub const IMAGE: usize = oxicat_slave::image_size(OBJECTS);

/// RxPDOs: 0x1600 with the ETG.6010 default set, configurable in PREOP.
pub static RX_PDOS: &[PdoDef] = &[PdoDef {
    index: 0x1600,
    name: "RxPDO 1",
    entries: &[
        PE::of(OBJECTS, 0x6040, 0),
        PE::of(OBJECTS, 0x6060, 0),
        PE::of(OBJECTS, 0x607A, 0),
        PE::of(OBJECTS, 0x60FF, 0),
        PE::of(OBJECTS, 0x6071, 0),
    ],
    configurable: true,
}];

/// TxPDOs: 0x1A00 with the ETG.6010 default set, configurable in PREOP.
pub static TX_PDOS: &[PdoDef] = &[PdoDef {
    index: 0x1A00,
    name: "TxPDO 1",
    entries: &[
        PE::of(OBJECTS, 0x6041, 0),
        PE::of(OBJECTS, 0x6061, 0),
        PE::of(OBJECTS, 0x6064, 0),
        PE::of(OBJECTS, 0x606C, 0),
        PE::of(OBJECTS, 0x6077, 0),
        PE::of(OBJECTS, 0x603F, 0),
    ],
    configurable: true,
}];

/// Default RxPDO bytes (2 + 1 + 4 + 4 + 2).
pub const OUTPUT_BYTES: usize = oxicat_slave::pdo_bytes(RX_PDOS, RX_ASSIGN);
/// Default TxPDO bytes (2 + 1 + 4 + 4 + 2 + 2).
pub const INPUT_BYTES: usize = oxicat_slave::pdo_bytes(TX_PDOS, TX_ASSIGN);

/// Default RxPDO assignment (0x1C12).
pub static RX_ASSIGN: &[u16] = &[0x1600];
/// Default TxPDO assignment (0x1C13).
pub static TX_ASSIGN: &[u16] = &[0x1A00];

/// ESI/SII description data.
pub const INFO: DeviceInfo = DeviceInfo {
    vendor_name: "oxicat",
    group: Group {
        type_name: "Cia402Drives",
        name: "CiA402 drives",
    },
    order_code: "CIA402-JOINT",
    description: Some(
        "CiA402 modular joint drive (BLDC, harmonic gear, joint torque sensor): PP, PV, PT, HM, \
         IP, CSP, CSV, CST",
    ),
    mailbox_size_range: Some((34, 128)),
    dc_modes: &[DcOpMode::SM_SYNCHRON, DcOpMode::DC_SYNC0],
    ebus_current_ma: 0,
    ..DeviceInfo::DEFAULT
};

/// The device definition: the one source of OD, ESI and SII.
pub static DEF: DeviceDef = DeviceDef {
    identity: Identity {
        vendor_id: crate::demo::VENDOR_ID,
        product_code: PRODUCT_CODE,
        revision: 1,
        serial: 0,
    },
    device_type: DEVICE_TYPE,
    name: "CiA402 joint drive",
    hw_version: "BLDC joint, 20 kHz current loop",
    sw_version: env!("CARGO_PKG_VERSION"),
    mailbox: MailboxDef::STANDARD,
    boot_mailbox: None,
    sm2_start: 0x1100,
    sm3_start: 0x1180,
    objects: OBJECTS,
    rx_pdos: RX_PDOS,
    tx_pdos: TX_PDOS,
    rx_assign: RX_ASSIGN,
    tx_assign: TX_ASSIGN,
    assign_configurable: false,
    sync: SyncDef {
        supported: 0x0007,
        default_mode: SyncMode::FreeRun,
        min_cycle_ns: 250_000,
        calc_copy_ns: 20_000,
    },
    info: Some(&INFO),
};
