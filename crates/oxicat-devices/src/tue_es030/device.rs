//! The TUeES030's process data and parameters exactly as the manual lists them (Listings
//! 4.11–4.15, Fig. 7.4), its [`DEF`], and the one place where PDO integers are named.
//!
//! | mode | RxPDO (0x1C12:01) | bytes | TxPDO (0x1C13:01) | bytes |
//! |---|---|---|---|---|
//! | normal (`OPERATION_STD`) | 0x1600: 0x7000–0x7002 (mcom, setpoint, ff) + 0x7010 (digital, aout1, aout2) | 20 | 0x1A00: 0x6000–0x6002 (mstate, count, timestamp, velocity, current) + 0x6010 (13 others) | 64 |
//! | FRF (`OPERATION_FRF`) | 0x1601: 0x7020 (mcom, entries, setpoint\[22\]) | 46 | 0x1A01: 0x6020 (mstate, buffer, entries, ectime) + 0x6021 (current\[22\]) | 49 |
//!
//! The manual does not list the mapping objects' contents; the entries above are the
//! records of its object dictionary (Fig. 7.4) in listing order, which give exactly the
//! packed structs' byte layouts. The assignment is switched in PREOP (0x1C12/0x1C13
//! writable; sub 0 to 0, sub 1, sub 0 to 1), as `ec_Set_TUeES030mode` does.
//!
//! Motor parameters 0x8000/0x8001/0x8002, subindex 1–8 (Listing 4.15, SOEMw Fig. 7.4):
//! resistance \[Ω\] (REAL32, 0.61), KV \[V s/rad\] (REAL32, 0.03), CC p gain \[V/A\]
//! (REAL32, 2.0), CC i gain \[V/As\] (REAL32, 2.0), CC i limit \[As\] (REAL32, 0.2),
//! encoder direction (INT8, 1), encoder resolution (UINT16, 1024), current zero (INT16,
//! 2168).
//!
//! 0x8040 "Internal voltages" (Fig. 7.4 lists it with 4 entries, the manual does not
//! describe them): oxicat fills it with the four voltages the firmware knows, UINT16 in
//! 10 mV as `linevoltage`: 1 line voltage (ADC2_CH2, 1 kHz), 2 the 5 V reference (the
//! ADC2 check of §2.5), 3 the line's peak since reset (20 kHz samples of the kill test),
//! 4 the kill threshold (`KILLVOLTAGE`). Read-only.
//!
//! FoE: the firmware runs `foe_init()`/`ESC_foeprocess()` (Listing 4.1); the board takes
//! `firmware.bin` in BOOT (bootstrap mailbox = the standard one) through oxicat's
//! firmware update flow (`oxicat_slave::foe`).

use oxicat_slave::device::{DeviceInfo, Group};
use oxicat_slave::{
    Access as A, DataType as T, DeviceDef, EntryDef as E, Identity, Limits, MailboxDef, ObjectCode,
    ObjectDef, PdoDef, PdoEntry as PE, PdoMapping as M, Scale, SyncDef, SyncMode,
};

/// Velocities: 0.1 rad/s steps.
const DECI_RAD_S: Scale = Scale::per("rad/s", 10);
/// Currents: 1 mA steps.
const MILLI_A: Scale = Scale::per("A", 1000);
/// Voltages: 10 mV steps.
const CENTI_V: Scale = Scale::per("V", 100);

const SUB0: E = E::new(0, "SubIndex 000", T::Unsigned8, A::RO);

const fn tx(sub: u8, name: &'static str, t: T) -> E {
    E::new(sub, name, t, A::RO).pdo(M::Tx)
}
const fn rx(sub: u8, name: &'static str, t: T) -> E {
    E::new(sub, name, t, A::RW).pdo(M::Rx)
}

/// FRF samples per cycle in each direction (`FRFBUFFERSIZE`).
pub const FRF_PER_CYCLE: usize = 22;

static NUMBERED: [&str; FRF_PER_CYCLE] = [
    "1", "2", "3", "4", "5", "6", "7", "8", "9", "10", "11", "12", "13", "14", "15", "16", "17",
    "18", "19", "20", "21", "22",
];

const fn motor_tx() -> [E; 6] {
    [
        SUB0,
        tx(1, "State", T::Unsigned8),
        tx(2, "Count", T::Unsigned32),
        tx(3, "Timestamp", T::Unsigned32),
        tx(4, "Velocity", T::Int16).limits(const { &Limits::scale(&DECI_RAD_S) }),
        tx(5, "Current", T::Int16).limits(const { &Limits::scale(&MILLI_A) }),
    ]
}
static MOTOR_TX: [E; 6] = motor_tx();

static OTHERS_TX: [E; 14] = [
    SUB0,
    tx(1, "Digital", T::Unsigned8),
    tx(2, "Caliper1", T::Unsigned16),
    tx(3, "Caliper2", T::Unsigned16),
    tx(4, "Force1", T::Unsigned16),
    tx(5, "Force2", T::Unsigned16),
    tx(6, "Force3", T::Unsigned16),
    tx(7, "Pos1", T::Unsigned16),
    tx(8, "Pos2", T::Unsigned16),
    tx(9, "Pos3", T::Unsigned16),
    tx(10, "Analog1", T::Unsigned16),
    tx(11, "Analog2", T::Unsigned16),
    tx(12, "Linevoltage", T::Unsigned16).limits(&Limits::scale(&CENTI_V)),
    tx(13, "Ectime", T::Unsigned16),
];

static SEQ_TX: [E; 5] = [
    SUB0,
    tx(1, "State", T::Unsigned8),
    tx(2, "Buffer", T::Unsigned8),
    tx(3, "Entries", T::Unsigned8),
    tx(4, "Ectime", T::Unsigned16),
];

const fn current_buffer() -> [E; FRF_PER_CYCLE + 1] {
    let mut out = [SUB0; FRF_PER_CYCLE + 1];
    let mut i = 0;
    while i < FRF_PER_CYCLE {
        out[i + 1] = tx(i as u8 + 1, NUMBERED[i], T::Int16);
        i += 1;
    }
    out
}
static CURRENT_BUF: [E; FRF_PER_CYCLE + 1] = current_buffer();

static MOTOR_RX: [E; 4] = [
    SUB0,
    rx(1, "Mcom", T::Unsigned8),
    rx(2, "Setpoint", T::Int16).limits(&Limits::scale(&MILLI_A)),
    rx(3, "Ff", T::Int16).limits(&Limits::scale(&CENTI_V)),
];

static OTHERS_RX: [E; 4] = [
    SUB0,
    rx(1, "Digital", T::Unsigned8),
    rx(2, "Aout1", T::Int16),
    rx(3, "Aout2", T::Int16),
];

const fn sequencer_rx() -> [E; FRF_PER_CYCLE + 3] {
    let mut out = [SUB0; FRF_PER_CYCLE + 3];
    out[1] = rx(1, "Mcom", T::Unsigned8);
    out[2] = rx(2, "Entries", T::Unsigned8);
    let mut i = 0;
    while i < FRF_PER_CYCLE {
        out[i + 3] = rx(i as u8 + 3, NUMBERED[i], T::Int16);
        i += 1;
    }
    out
}
static SEQ_RX: [E; FRF_PER_CYCLE + 3] = sequencer_rx();

/// Manual defaults of one motor's parameters (Fig. 5.2 mask, Fig. 7.4 SOEMw).
pub mod defaults {
    /// Resistance \[Ω\].
    pub const R: f32 = 0.61;
    /// KV \[V s/rad\].
    pub const KV: f32 = 0.03;
    /// Current-loop P gain \[V/A\].
    pub const P: f32 = 2.0;
    /// Current-loop I gain (see [`super::super::control::param2int`]).
    pub const I: f32 = 2.0;
    /// Current-loop integrator limit \[A s\].
    pub const ILIMIT: f32 = 0.2;
    /// Encoder direction (±1).
    pub const ENCDIR: i8 = 1;
    /// Encoder resolution (lines per revolution).
    pub const ENCRES: u16 = 1024;
    /// Current zero (raw ADC counts, labelled "\[mA\]" in the OD).
    pub const CZERO: i16 = 2168;
}

const fn params() -> [E; 9] {
    use defaults::*;
    [
        SUB0.default_bits(8),
        E::new(1, "Resistance [ohm]", T::Real32, A::RW).default_f32(R),
        E::new(2, "KV [Vs/rad]", T::Real32, A::RW).default_f32(KV),
        E::new(3, "CC p_gain [V/A]", T::Real32, A::RW).default_f32(P),
        E::new(4, "CC i_gain [V/As]", T::Real32, A::RW).default_f32(I),
        E::new(5, "CC i_limit [As]", T::Real32, A::RW).default_f32(ILIMIT),
        E::new(6, "Encoder direction", T::Int8, A::RW)
            .default_i64(ENCDIR as i64)
            .limits(const { &Limits::range(-1, 1) }),
        E::new(7, "Encoder resolution", T::Unsigned16, A::RW)
            .default_bits(ENCRES as u64)
            .limits(const { &Limits::range(1, 65535) }),
        E::new(8, "Current zero [mA]", T::Int16, A::RW)
            .default_i64(CZERO as i64)
            .limits(const { &Limits::range(0, 4095) }),
    ]
}
static PARAMS: [E; 9] = params();

static VOLTAGES: [E; 5] = [
    SUB0.default_bits(4),
    E::new(1, "Line voltage", T::Unsigned16, A::RO).limits(&Limits::scale(&CENTI_V)),
    E::new(2, "5V reference", T::Unsigned16, A::RO).limits(&Limits::scale(&CENTI_V)),
    E::new(3, "Line peak", T::Unsigned16, A::RO).limits(&Limits::scale(&CENTI_V)),
    E::new(4, "Kill threshold", T::Unsigned16, A::RO).limits(&Limits::scale(&CENTI_V)),
];

const fn rec(index: u16, name: &'static str, entries: &'static [E]) -> ObjectDef {
    ObjectDef {
        index,
        name,
        code: ObjectCode::Record,
        entries,
    }
}

/// Application objects: inputs 0x60xx, outputs 0x70xx, parameters 0x800x, internal
/// voltages 0x8040.
pub static OBJECTS: &[ObjectDef] = &[
    rec(0x6000, "TXPDO motor 1", &MOTOR_TX),
    rec(0x6001, "TXPDO motor 2", &MOTOR_TX),
    rec(0x6002, "TXPDO motor 3", &MOTOR_TX),
    rec(0x6010, "TXPDO others", &OTHERS_TX),
    rec(0x6020, "TXPDO sequencer", &SEQ_TX),
    rec(0x6021, "TXPDO current buffer", &CURRENT_BUF),
    rec(0x7000, "RXPDO motor 1", &MOTOR_RX),
    rec(0x7001, "RXPDO motor 2", &MOTOR_RX),
    rec(0x7002, "RXPDO motor 3", &MOTOR_RX),
    rec(0x7010, "RXPDO others", &OTHERS_RX),
    rec(0x7020, "RXPDO sequencer", &SEQ_RX),
    rec(0x8000, "Motor 1 parameters", &PARAMS),
    rec(0x8001, "Motor 2 parameters", &PARAMS),
    rec(0x8002, "Motor 3 parameters", &PARAMS),
    rec(0x8040, "Internal voltages", &VOLTAGES),
];

/// Object image size of [`OBJECTS`].
pub const IMAGE: usize = oxicat_slave::image_size(OBJECTS);

/// Mapping entry `index:sub`, its size from the record's definition.
const fn e(index: u16, sub: u8) -> PE {
    PE::of(OBJECTS, index, sub)
}

const fn pdo_1a00() -> [PE; 28] {
    let mut out = [PE::gap(0); 28];
    let mut k = 0;
    let mut m = 0;
    while m < 3 {
        let mut j = 0;
        while j < 5 {
            out[k] = e(0x6000 + m, j as u8 + 1);
            k += 1;
            j += 1;
        }
        m += 1;
    }
    out[k] = e(0x6010, 1);
    k += 1;
    let mut s = 2;
    while s <= 13 {
        out[k] = e(0x6010, s);
        k += 1;
        s += 1;
    }
    out
}

const fn pdo_1600() -> [PE; 12] {
    let mut out = [PE::gap(0); 12];
    let mut m = 0;
    while m < 4 {
        let idx = if m < 3 { 0x7000 + m } else { 0x7010 };
        let k = 3 * m as usize;
        out[k] = e(idx, 1);
        out[k + 1] = e(idx, 2);
        out[k + 2] = e(idx, 3);
        m += 1;
    }
    out
}

const fn pdo_1601() -> [PE; FRF_PER_CYCLE + 2] {
    let mut out = [e(0x7020, 1); FRF_PER_CYCLE + 2];
    out[1] = e(0x7020, 2);
    let mut i = 0;
    while i < FRF_PER_CYCLE {
        out[i + 2] = e(0x7020, i as u8 + 3);
        i += 1;
    }
    out
}

const fn pdo_1a01() -> [PE; FRF_PER_CYCLE + 4] {
    let mut out = [e(0x6020, 1); FRF_PER_CYCLE + 4];
    out[1] = e(0x6020, 2);
    out[2] = e(0x6020, 3);
    out[3] = e(0x6020, 4);
    let mut i = 0;
    while i < FRF_PER_CYCLE {
        out[i + 4] = e(0x6021, i as u8 + 1);
        i += 1;
    }
    out
}

static PDO_1600: [PE; 12] = pdo_1600();
static PDO_1601: [PE; FRF_PER_CYCLE + 2] = pdo_1601();
static PDO_1A00: [PE; 28] = pdo_1a00();
static PDO_1A01: [PE; FRF_PER_CYCLE + 4] = pdo_1a01();

/// RxPDOs: 0x1600 normal (20 bytes), 0x1601 FRF (46 bytes).
pub static RX_PDOS: &[PdoDef] = &[
    PdoDef {
        index: 0x1600,
        name: "RXPDO normal",
        entries: &PDO_1600,
        configurable: false,
    },
    PdoDef {
        index: 0x1601,
        name: "RXPDO FRF",
        entries: &PDO_1601,
        configurable: false,
    },
];

/// TxPDOs: 0x1A00 normal (64 bytes), 0x1A01 FRF (49 bytes).
pub static TX_PDOS: &[PdoDef] = &[
    PdoDef {
        index: 0x1A00,
        name: "TXPDO normal",
        entries: &PDO_1A00,
        configurable: false,
    },
    PdoDef {
        index: 0x1A01,
        name: "TXPDO FRF",
        entries: &PDO_1A01,
        configurable: false,
    },
];

/// Normal-mode output bytes (`rxpdo1_t`, 20).
pub const NORMAL_RX_BYTES: usize = oxicat_slave::pdo_bytes(RX_PDOS, &[0x1600]);
/// Normal-mode input bytes (`txpdo1_t`, 64).
pub const NORMAL_TX_BYTES: usize = oxicat_slave::pdo_bytes(TX_PDOS, &[0x1A00]);
/// FRF-mode output bytes (`rxpdo2_t`, 46).
pub const FRF_RX_BYTES: usize = oxicat_slave::pdo_bytes(RX_PDOS, &[0x1601]);
/// FRF-mode input bytes (`txpdo2_t`, 49).
pub const FRF_TX_BYTES: usize = oxicat_slave::pdo_bytes(TX_PDOS, &[0x1A01]);

/// ESI/SII description data.
pub const INFO: DeviceInfo = DeviceInfo {
    vendor_name: "TU Eindhoven, Control Systems Technology",
    group: Group {
        type_name: "TUeES030",
        name: "TU/e motor I/O boards",
    },
    order_code: "TUeES030",
    description: Some(
        "TUeES030 motor I/O board (manual CST 2016.141): 3 current-controlled DC motor channels, \
         encoders, ADC/DAC/digital I/O; normal and FRF PDO modes",
    ),
    mailbox_size_range: Some((34, 128)),
    dc_modes: &[],
    ebus_current_ma: 0,
    // FoE: `firmware.bin` in BOOT, `version.txt` (see `oxicat_slave::foe`).
    foe: true,
    ..DeviceInfo::DEFAULT
};

/// The board's identity (0x1018), usable in constants (the factory image of the board
/// image's FoE store).
pub const IDENTITY: Identity = Identity {
    vendor_id: crate::demo::VENDOR_ID,
    product_code: 0x0000_E030,
    revision: 1,
    serial: 0,
};

/// The device definition: the one source of OD, ESI and SII. Vendor ID: none is given in
/// the manual; the ETG test range (as the other oxicat devices).
pub static DEF: DeviceDef = DeviceDef {
    identity: IDENTITY,
    device_type: 0x0000_0000,
    name: "TUeES030",
    hw_version: "TUeES030 (Spartan-6 soft core, ET1200)",
    sw_version: env!("CARGO_PKG_VERSION"),
    mailbox: MailboxDef::STANDARD,
    boot_mailbox: Some(MailboxDef::STANDARD),
    sm2_start: 0x1100,
    sm3_start: 0x1180,
    objects: OBJECTS,
    rx_pdos: RX_PDOS,
    tx_pdos: TX_PDOS,
    rx_assign: &[0x1600],
    tx_assign: &[0x1A00],
    assign_configurable: true,
    sync: SyncDef {
        // The firmware handles outputs on the SM2 event (Listing 4.3): SM-synchronous only
        // (the FRF mode must see each RxPDO exactly once).
        supported: 0x0002,
        default_mode: SyncMode::SmSync,
        min_cycle_ns: 1_000_000,
        calc_copy_ns: 0,
    },
    info: Some(&INFO),
};

/// The board's definition under another revision and product code: what a firmware image
/// built for another revision or another device carries (an FoE update must refuse it).
pub fn with_identity(revision: u32, product_code: u32) -> DeviceDef {
    DeviceDef {
        identity: Identity {
            revision,
            product_code,
            ..DEF.identity
        },
        ..DEF
    }
}
