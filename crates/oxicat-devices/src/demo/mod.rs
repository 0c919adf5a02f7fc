//! The thesis' generic "EtherCAT Application" demo device (Table 2-2 of the Laelaps II
//! thesis): the SSC demo on a TI F28379D with an FB1111-0141 SPI ESC.
//!
//! Outputs (RxPDO, 24 bytes): Buttons 0x7000 (8 BOOL + INT8 `Sync`, PDO 0x1600),
//! Output1INT32 0x7010 / OutputUINT16 0x7012 / Output2INT32 0x7014 (PDO 0x1601
//! "OutputMapping1"), OutputINT16 0x7020 (6 × INT16, PDO 0x1602). Inputs (TxPDO, 22 bytes):
//! Input1INT32 0x6010 / InputUINT16 0x6012 / Input2INT32 0x6014 (PDO 0x1A01
//! "InputMapping1"), InputINT16 0x6020 (PDO 0x1A02), Input3INT32 0x6030 (PDO 0x1A03).
//!
//! The whole device is the table in [`demo_device!`](crate::demo_device); [`additions`] is
//! the thesis' 16-step change (record "Additions" 0x7030 with two INT16 outputs) done as one
//! extra line in one place.

use oxicat_slave::{AlState, AlStatusCode, Application, Od};

/// The two LEDs of the LaunchPad (GPIO31 blue, GPIO34 red; the driver handles active-low).
pub trait Leds {
    /// Sets both LEDs (`true` = lit).
    fn set(&mut self, blue: bool, red: bool);
}

/// Local push buttons or switches of the board.
pub trait Buttons {
    /// Current state, one bit per button (bit 0 = button 1).
    fn read(&mut self) -> u8;
}

/// Declares a demo-device variant: the Table 2-2 process data plus `extra_rx` RxPDOs
/// (written like [`pd_table!`](crate::pd_table) entries), its `DEF` and its `IMAGE`.
#[macro_export]
macro_rules! demo_device {
    (
        name: $name:literal,
        revision: $rev:literal,
        extra_rx: { $( $extra:tt )* }
    ) => {
        $crate::pd_table! {
            tx {
                0x1A01 "InputMapping1" {
                    0x6010 "Input1INT32" { 1 "InINT32Var1": Int32 => i1 }
                    0x6012 "InputUINT16" { 1 "InUINT16Var1": Unsigned16 => iu1 }
                    0x6014 "Input2INT32" { 1 "InINT32Var2": Int32 => i2 }
                }
                0x1A02 "InputINT16" {
                    0x6020 "InputINT16" { 1 "InINT16Var1": Int16 => sum, 2 "InINT16Var2": Int16 => diff }
                }
                0x1A03 "Input3INT32" {
                    0x6030 "Input3INT32" { 1 "InINT32Var3": Int32 => counter, 2 "InINT32Var4": Int32 => buttons }
                }
            }
            rx {
                0x1600 "Buttons" {
                    0x7000 "Buttons" {
                        1 "Button1": Bool, 2 "Button2": Bool, 3 "Button3": Bool,
                        4 "Button4": Bool, 5 "Blue_LED": Bool => blue, 6 "Red_LED": Bool => red,
                        7 "Button7": Bool, 8 "Button8": Bool, 9 "Sync": Int8 => sync
                    }
                }
                0x1601 "OutputMapping1" {
                    0x7010 "Output1INT32" { 1 "OutINT32Var1": Int32 => o1 }
                    0x7012 "OutputUINT16" { 1 "OutUINT16Var1": Unsigned16 => u1 }
                    0x7014 "Output2INT32" { 1 "OutINT32Var2": Int32 => o2 }
                }
                0x1602 "OutputINT16" {
                    0x7020 "OutputINT16" {
                        1 "OutINT16Var1": Int16 => a, 2 "OutINT16Var2": Int16 => b,
                        3 "OutINT16Var3": Int16, 4 "OutINT16Var4": Int16,
                        5 "OutINT16Var5": Int16, 6 "OutINT16Var6": Int16
                    }
                }
                $( $extra )*
            }
        }

        /// The demo application's handles on this variant (its [`VARS`] in the base
        /// variant's type).
        pub const IO: $crate::demo::PdVars = $crate::demo::PdVars {
            blue: VARS.blue, red: VARS.red, sync: VARS.sync, o1: VARS.o1, u1: VARS.u1,
            o2: VARS.o2, a: VARS.a, b: VARS.b, i1: VARS.i1, iu1: VARS.iu1, i2: VARS.i2,
            sum: VARS.sum, diff: VARS.diff, counter: VARS.counter, buttons: VARS.buttons,
        };

        /// The device definition: the one source of OD, ESI and SII.
        pub static DEF: $crate::__slave::DeviceDef = $crate::__slave::DeviceDef {
            identity: $crate::__slave::Identity {
                vendor_id: $crate::demo::VENDOR_ID,
                product_code: 0x1111_0141,
                revision: $rev,
                serial: 0,
            },
            device_type: 0x0000_1389,
            name: $name,
            hw_version: "LAUNCHXL-F28379D + FB1111-0141",
            sw_version: env!("CARGO_PKG_VERSION"),
            mailbox: $crate::__slave::MailboxDef::STANDARD,
            // Bootstrap mailbox (FoE firmware download) on the standard mailbox's memory.
            boot_mailbox: Some($crate::__slave::MailboxDef::STANDARD),
            sm2_start: 0x1100,
            sm3_start: 0x1400,
            objects: OBJECTS,
            rx_pdos: RX_PDOS,
            tx_pdos: TX_PDOS,
            rx_assign: RX_ASSIGN,
            tx_assign: TX_ASSIGN,
            assign_configurable: false,
            sync: $crate::__slave::SyncDef {
                supported: 0x000F,
                default_mode: $crate::__slave::SyncMode::FreeRun,
                min_cycle_ns: 200_000,
                calc_copy_ns: 85_000,
            },
            info: Some(&$crate::demo::INFO),
        };
    };
}

/// Vendor ID: the thesis' vendor ID is not legible; the ETG range for tests/prototypes.
pub const VENDOR_ID: u32 = 0xE000_0000;

/// ESI/SII description data shared by the demo variants.
pub const INFO: oxicat_slave::device::DeviceInfo = oxicat_slave::device::DeviceInfo {
    vendor_name: "National Technical University of Athens",
    group: oxicat_slave::device::Group {
        type_name: "C28xxSlaveDevices",
        name: "TI C28xx Slave Devices",
    },
    order_code: "EtherCAT_Application_SPI",
    description: Some("Generic SSC demo (thesis Table 2-2), F28379D + FB1111-0141 over SPI"),
    mailbox_size_range: Some((34, 128)),
    dc_modes: &[
        oxicat_slave::device::DcOpMode::SM_SYNCHRON,
        oxicat_slave::device::DcOpMode::DC_SYNC0,
        oxicat_slave::device::DcOpMode::DC_SYNC01,
    ],
    ebus_current_ma: 0,
    // FoE: firmware download in BOOT, version.txt (see `oxicat_slave::foe`).
    foe: true,
    ..oxicat_slave::device::DeviceInfo::DEFAULT
};

demo_device! {
    name: "EtherCAT Application (SPI)",
    revision: 1,
    extra_rx: {}
}

/// The board on the virtual segment and its FoE files (feature `bench`).
#[cfg(feature = "bench")]
pub mod rig;

/// The thesis' section 6.7 change: record "Additions" 0x7030 with two INT16 outputs
/// (`Out1`, `Out2`) in RxPDO 0x1603. The whole change is the one `extra_rx` line below;
/// OD, PDO assignment, SM2 size, ESI and SII all follow.
pub mod additions {
    crate::demo_device! {
        name: "EtherCAT Application (SPI) + Additions",
        revision: 2,
        extra_rx: { 0x1603 "Additions" { 0x7030 "Additions" { 1 "Out1": Int16, 2 "Out2": Int16 } } }
    }
}

/// The demo application's typed handles: the table's [`PdVars`] of the variant whose
/// dictionary it runs on (every variant names the same entries; build-time offsets).
type DemoIo = PdVars;

/// Each variant's objects and its handles, in the base variant's type.
const VARIANTS: [(&[oxicat_slave::ObjectDef], DemoIo); 2] =
    [(OBJECTS, IO), (additions::OBJECTS, additions::IO)];

impl DemoIo {
    fn resolve<const N: usize>(od: &Od<N>) -> Option<Self> {
        VARIANTS
            .iter()
            .find(|(o, _)| od.built_on(o))
            .map(|&(_, io)| io)
    }
}

/// The demo application: LEDs follow `Blue_LED`/`Red_LED`, inputs echo outputs.
///
/// Each cycle: `InINT32Var1 = OutINT32Var1`, `InUINT16Var1 = OutUINT16Var1`,
/// `InINT32Var2 = OutINT32Var2`, `InINT16Var1/2 = OutINT16Var1 + OutINT16Var2` /
/// `OutINT16Var1 - OutINT16Var2` (wrapping), `InINT32Var3` = cycle counter,
/// `InINT32Var4` = local buttons (bits 0..7) and the echoed `Sync` byte (bits 8..15).
/// Safe outputs: LEDs off, all outputs zero (the SSC's `PDO_ResetOutputs`).
pub struct Demo<L: Leds, B: Buttons> {
    /// LED driver.
    pub leds: L,
    /// Button driver.
    pub buttons: B,
    /// Application cycles run.
    pub cycles: u32,
    io: Option<DemoIo>,
}

impl<L: Leds, B: Buttons> Demo<L, B> {
    /// A demo application on the given hardware.
    pub const fn new(leds: L, buttons: B) -> Self {
        Self {
            leds,
            buttons,
            cycles: 0,
            io: None,
        }
    }
}

impl<const N: usize, L: Leds, B: Buttons> Application<N> for Demo<L, B> {
    fn state_change(
        &mut self,
        _from: AlState,
        to: AlState,
        od: &mut Od<N>,
    ) -> Result<(), AlStatusCode> {
        if matches!(to, AlState::Init | AlState::PreOp) {
            self.leds.set(false, false);
        }
        if to == AlState::SafeOp && self.io.is_none() {
            self.io = DemoIo::resolve(od);
        }
        Ok(())
    }

    fn safe_outputs(&mut self, od: &mut Od<N>) {
        for sub in 1..=8u8 {
            let _ = od.set(0x7000, sub, false);
        }
        let _ = od.set(0x7000, 9, 0i8);
        let _ = od.set(0x7010, 1, 0i32);
        let _ = od.set(0x7012, 1, 0u16);
        let _ = od.set(0x7014, 1, 0i32);
        for sub in 1..=6u8 {
            let _ = od.set(0x7020, sub, 0i16);
        }
        // Variants with extra output records (e.g. 0x7030) reset them too.
        for sub in 1..=2u8 {
            let _ = od.set(0x7030, sub, 0i16);
        }
        self.leds.set(false, false);
    }

    fn cycle(&mut self, od: &mut Od<N>) {
        self.cycles = self.cycles.wrapping_add(1);
        if self.io.is_none() {
            self.io = DemoIo::resolve(od);
        }
        let Some(io) = self.io else {
            return;
        };
        self.leds.set(od.load(io.blue), od.load(io.red));
        let o1 = od.load(io.o1);
        let u1 = od.load(io.u1);
        let o2 = od.load(io.o2);
        let a = od.load(io.a);
        let b = od.load(io.b);
        let sync = od.load(io.sync);
        od.store(io.i1, o1);
        od.store(io.iu1, u1);
        od.store(io.i2, o2);
        od.store(io.sum, a.wrapping_add(b));
        od.store(io.diff, a.wrapping_sub(b));
        od.store(io.counter, self.cycles as i32);
        let buttons = self.buttons.read() as i32 | ((sync as u8 as i32) << 8);
        od.store(io.buttons, buttons);
    }
}
