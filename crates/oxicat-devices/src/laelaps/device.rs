//! The Laelaps II leg node's process data (thesis Tables 3-1 and 3-2), its device
//! definitions (left and right builds), and the **one place** where the PDO's scaled
//! integers meet SI units ([`Command::read`], [`Feedback::write`]).
//!
//! Outputs (RxPDO, master → node, 38 bytes), PDOs as in the demo device the firmware grew
//! from (Table 2-2 + the §6.7 "Additions" PDO 0x1603):
//!
//! | PDO | Index | Record | Entries |
//! |---|---|---|---|
//! | 0x1600 | 0x7000 | Buttons | 1 State_Machine, 2 Initialize_clock, 3 Initialize_angles, 4 Inverse_Kinematics, 5 Blue_LED, 6 Red_LED, 7 Button1, 8 Button2 (BOOL); 9 Transition_time (INT8, s) |
//! | 0x1601 | 0x7010 | Desired_x_value | 1 Desired_x_value (INT32, unused) |
//! | | 0x7012 | TargetMode | 1 FilterBandwidth (UINT16, Hz) |
//! | | 0x7014 | Desired_y_value | 1 Desired_y_value (INT32, unused) |
//! | 0x1602 | 0x7020 | ControlGains | 1 Kp100_knee, 2 Kd1000_knee, 3 Ki100_knee, 4 Kp100_hip, 5 Kd1000_hip, 6 Ki100_hip (INT16) |
//! | 0x1603 | 0x7030 | TrajectoryParameters | 1 x_cntr_traj1000 (mm), 2 y_cntr_traj1000 (mm), 3 a_ellipse100 (cm), 4 b_ellipse100 (cm), 5 traj_freq100 (Hz/100), 6 phase_deg (°), 7 FlatnessParam100 (/100) (INT16) |
//!
//! Inputs (TxPDO, node → master, 22 bytes):
//!
//! | PDO | Index | Record | Entries |
//! |---|---|---|---|
//! | 0x1A01 | 0x6010 | hip_angle | 1 hip_angle, 2 Desired_hip_angle (INT16, °×100) |
//! | | 0x6012 | FeedbackTime | 1 Time (UINT16, 0.01 s) |
//! | | 0x6014 | knee_angle | 1 knee_angle, 2 Desired_knee_angle (INT16, °×100) |
//! | 0x1A02 | 0x6020 | Commands | 1 PWM10000_knee, 2 PWM10000_hip (INT16, u×10000) |
//! | 0x1A03 | 0x6030 | Velocity | 1 velocity_knee1000, 2 velocity_hip1000 (INT32, motor rad/s×1000) |
//!
//! The PDO mapping indices are not printed in the thesis (its ESI is an image); we use the
//! demo's, which the Laelaps firmware was built from, and which give exactly the table
//! order and the 38/22-byte sizes. All angles, velocities and PWM values in the PDO are in
//! the joint (motor) frame of [`super::kinematics`] — as the thesis sends them, so its
//! post-processing (negate the right legs) applies unchanged. Velocities are motor-side,
//! as the thesis sends `Speed_pr × 1000`.

use super::hw::Joint;
use super::piv::Gains;
use super::trajectory::Ellipse;
use crate::laelaps::kinematics::Side;
use core::f32::consts::PI;
use oxicat_slave::device::{DcOpMode, DeviceInfo, Group};
use oxicat_slave::{DeviceDef, Identity, MailboxDef, Od, SyncDef, SyncMode, Var};

crate::pd_table! {
    tx {
        0x1A01 "InputMapping1" {
            0x6010 "hip_angle" {
                1 "hip_angle": Int16 ["deg" / 100] => hip,
                2 "Desired_hip_angle": Int16 ["deg" / 100] => hip_desired
            }
            0x6012 "FeedbackTime" { 1 "Time": Unsigned16 ["s" / 100] => time }
            0x6014 "knee_angle" {
                1 "knee_angle": Int16 ["deg" / 100] => knee,
                2 "Desired_knee_angle": Int16 ["deg" / 100] => knee_desired
            }
        }
        0x1A02 "Commands" {
            0x6020 "Commands" {
                1 "PWM10000_knee": Int16 ["%" / 100] => pwm_knee,
                2 "PWM10000_hip": Int16 ["%" / 100] => pwm_hip
            }
        }
        0x1A03 "Velocity" {
            0x6030 "Velocity" {
                1 "velocity_knee1000": Int32 ["rad/s motor" / 1000] => velocity_knee,
                2 "velocity_hip1000": Int32 ["rad/s motor" / 1000] => velocity_hip
            }
        }
    }
    rx {
        0x1600 "Buttons" {
            0x7000 "Buttons" {
                1 "State_Machine": Bool => state_machine, 2 "Initialize_clock": Bool,
                3 "Initialize_angles": Bool, 4 "Inverse_Kinematics": Bool,
                5 "Blue_LED": Bool => blue_led, 6 "Red_LED": Bool => red_led,
                7 "Button1": Bool, 8 "Button2": Bool,
                9 "Transition_time": Int8 ["s" / 1] => transition_time
            }
        }
        0x1601 "OutputMapping1" {
            0x7010 "Desired_x_value" { 1 "Desired_x_value": Int32 }
            0x7012 "TargetMode" { 1 "FilterBandwidth": Unsigned16 ["Hz" / 1] => filter_bandwidth }
            0x7014 "Desired_y_value" { 1 "Desired_y_value": Int32 }
        }
        0x1602 "ControlGains" {
            0x7020 "ControlGains" {
                1 "Kp100_knee": Int16 ["1/rev" / 100] => kp_knee,
                2 "Kd1000_knee": Int16 ["s" / 1000] => kd_knee,
                3 "Ki100_knee": Int16 ["1/s" / 100] => ki_knee,
                4 "Kp100_hip": Int16 ["1/rev" / 100] => kp_hip,
                5 "Kd1000_hip": Int16 ["s" / 1000] => kd_hip,
                6 "Ki100_hip": Int16 ["1/s" / 100] => ki_hip
            }
        }
        0x1603 "TrajectoryParameters" {
            0x7030 "TrajectoryParameters" {
                1 "x_cntr_traj1000": Int16 ["m" / 1000] => x_centre,
                2 "y_cntr_traj1000": Int16 ["m" / 1000] => y_centre,
                3 "a_ellipse100": Int16 ["m" / 100] => a,
                4 "b_ellipse100": Int16 ["m" / 100] => b,
                5 "traj_freq100": Int16 ["Hz" / 100] => freq,
                6 "phase_deg": Int16 ["deg" / 1] => phase,
                7 "FlatnessParam100": Int16 ["1" / 100] => flatness
            }
        }
    }
}

/// ESI/SII description data of the leg node.
pub const INFO: DeviceInfo = DeviceInfo {
    vendor_name: "National Technical University of Athens",
    group: Group {
        type_name: "C28xxSlaveDevices",
        name: "TI C28xx Slave Devices",
    },
    order_code: "EtherCAT_Laelaps_Motion_Control_v4_SPI",
    description: Some(
        "Laelaps II leg node (thesis Tables 3-1/3-2): ellipse trajectory, IK, two PIV joints",
    ),
    mailbox_size_range: Some((34, 128)),
    dc_modes: &[
        DcOpMode::SM_SYNCHRON,
        DcOpMode::DC_SYNC0,
        DcOpMode::DC_SYNC01,
    ],
    ebus_current_ma: 0,
    ..DeviceInfo::DEFAULT
};

const fn def(name: &'static str) -> DeviceDef {
    DeviceDef {
        identity: Identity {
            vendor_id: crate::demo::VENDOR_ID,
            product_code: 0x1111_0141,
            revision: 4,
            serial: 0,
        },
        device_type: 0x0000_1389,
        name,
        hw_version: "LAUNCHXL-F28379D + FB1111-0141",
        sw_version: env!("CARGO_PKG_VERSION"),
        mailbox: MailboxDef::STANDARD,
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
            supported: 0x000F,
            default_mode: SyncMode::FreeRun,
            // The thesis ran the leg nodes at 400 µs (its measured 200 µs minimum and 85 µs
            // of stack time are for the demo application on its F28379D's byte-wise SPI).
            // The goal is a 100 µs cycle on a 20 MHz SPI, and the simulated bus
            // supports it: the SYNC0 handler (38 output + 22 input bytes) takes 70.4 µs of
            // bus time through a LAN9252 and 30.5 µs through an ET1100 at 20 MHz
            // (oxicat-pdi `bus_time`), and oxicat-sim's execution-time model runs it at
            // 100 µs with no SYNC0 lost (`tests/integration/exec_time.rs`). Slower boards (a LAN9252
            // at 10 MHz: 139 µs) must be run at a longer cycle.
            min_cycle_ns: 100_000,
            calc_copy_ns: 85_000,
        },
        info: Some(&INFO),
    }
}

/// Left-leg build (`LEFT_LEG`). Same identity and process data as [`RIGHT`]: as in the
/// thesis (one ESI, "EtherCAT Laelaps Motion Control v4 (SPI)", product 11110141 rev 4),
/// the side is a firmware build choice the master cannot see.
pub static LEFT: DeviceDef = def("EtherCAT Laelaps Motion Control v4 (SPI)");
/// Right-leg build (`RIGHT_LEG`); see [`LEFT`].
pub static RIGHT: DeviceDef = def("EtherCAT Laelaps Motion Control v4 (SPI)");

/// The device definition of a side's build.
pub const fn device(side: Side) -> &'static DeviceDef {
    match side {
        Side::Left => &LEFT,
        Side::Right => &RIGHT,
    }
}

/// Typed handles on the Laelaps process-data entries (generated with the table, [`VARS`])
/// and the SYNC0 cycle time 0x1C32:02 (a communication object, resolved once:
/// [`PdoVars::resolve`]) so that the SYNC0 cycle reads and writes the image by offset
/// instead of looking each entry up by index.
#[derive(Debug, Clone, Copy)]
pub struct PdoVars {
    /// The process-data entries.
    pub pd: PdVars,
    cycle_time: Var<u32>,
}

impl PdoVars {
    /// The handles for `od`; `None` if it is not built on the Laelaps objects.
    pub fn resolve<const N: usize>(od: &Od<N>) -> Option<Self> {
        if !od.built_on(OBJECTS) {
            return None;
        }
        Some(Self {
            pd: VARS,
            cycle_time: od.var(0x1C32, 2).ok()?,
        })
    }

    /// The SYNC0 cycle time 0x1C32:02 \[ns\].
    pub fn cycle_ns<const N: usize>(&self, od: &Od<N>) -> u32 {
        od.load(self.cycle_time)
    }
}

/// Everything the master commands, in SI units (decoded from Table 3-1).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Command {
    /// `State_Machine`: false = Configuration, true = Operational.
    pub operational: bool,
    /// Blue LED.
    pub blue_led: bool,
    /// Red LED.
    pub red_led: bool,
    /// `Transition_time` \[s\] (0: keep the previous one).
    pub transition_time_s: f32,
    /// `FilterBandwidth` \[Hz\] (0: keep the previous one).
    pub filter_hz: f32,
    /// Knee PIV gains.
    pub knee: Gains,
    /// Hip PIV gains.
    pub hip: Gains,
    /// Ellipse (`freq` 0 or negative: keep the previous one).
    pub ellipse: Ellipse,
}

impl Command {
    /// Reads and scales the outputs from the dictionary (entries missing → 0).
    pub fn read<const N: usize>(od: &Od<N>) -> Self {
        let b = |s: u8| od.get::<bool>(0x7000, s).unwrap_or(false);
        let g = |s: u8| od.get::<i16>(0x7020, s).unwrap_or(0) as f32;
        let tr = |s: u8| od.get::<i16>(0x7030, s).unwrap_or(0) as f32;
        Self {
            operational: b(1),
            blue_led: b(5),
            red_led: b(6),
            transition_time_s: od.get::<i8>(0x7000, 9).unwrap_or(0) as f32,
            filter_hz: od.get::<u16>(0x7012, 1).unwrap_or(0) as f32,
            knee: Gains {
                kp: g(1) / 100.0,
                kd: g(2) / 1000.0,
                ki: g(3) / 100.0,
            },
            hip: Gains {
                kp: g(4) / 100.0,
                kd: g(5) / 1000.0,
                ki: g(6) / 100.0,
            },
            ellipse: Ellipse {
                x_centre: tr(1) / 1000.0,
                y_centre: tr(2) / 1000.0,
                a: tr(3) / 100.0,
                b: tr(4) / 100.0,
                freq: tr(5) / 100.0,
                phase: tr(6) * (PI / 180.0),
                flatness: tr(7) / 100.0,
            },
        }
    }

    /// As [`Command::read`] through resolved handles (the per-cycle path).
    pub fn load<const N: usize>(od: &Od<N>, v: &PdoVars) -> Self {
        let v = &v.pd;
        let f = |h: Var<i16>| od.load(h) as f32;
        Self {
            operational: od.load(v.state_machine),
            blue_led: od.load(v.blue_led),
            red_led: od.load(v.red_led),
            transition_time_s: od.load(v.transition_time) as f32,
            filter_hz: od.load(v.filter_bandwidth) as f32,
            knee: Gains {
                kp: f(v.kp_knee) / 100.0,
                kd: f(v.kd_knee) / 1000.0,
                ki: f(v.ki_knee) / 100.0,
            },
            hip: Gains {
                kp: f(v.kp_hip) / 100.0,
                kd: f(v.kd_hip) / 1000.0,
                ki: f(v.ki_hip) / 100.0,
            },
            ellipse: Ellipse {
                x_centre: f(v.x_centre) / 1000.0,
                y_centre: f(v.y_centre) / 1000.0,
                a: f(v.a) / 100.0,
                b: f(v.b) / 100.0,
                freq: f(v.freq) / 100.0,
                phase: f(v.phase) * (PI / 180.0),
                flatness: f(v.flatness) / 100.0,
            },
        }
    }

    /// Writes the command into the dictionary, scaled (what a master writes; for tests
    /// and tools that build process data).
    pub fn write<const N: usize>(&self, od: &mut Od<N>) {
        let _ = od.set(0x7000, 1, self.operational);
        let _ = od.set(0x7000, 5, self.blue_led);
        let _ = od.set(0x7000, 6, self.red_led);
        let _ = od.set(0x7000, 9, round_i8(self.transition_time_s));
        let _ = od.set(0x7012, 1, round_u16(self.filter_hz));
        let gains = [
            self.knee.kp * 100.0,
            self.knee.kd * 1000.0,
            self.knee.ki * 100.0,
            self.hip.kp * 100.0,
            self.hip.kd * 1000.0,
            self.hip.ki * 100.0,
        ];
        for (i, v) in gains.into_iter().enumerate() {
            let _ = od.set(0x7020, i as u8 + 1, round_i16(v));
        }
        let e = &self.ellipse;
        let traj = [
            e.x_centre * 1000.0,
            e.y_centre * 1000.0,
            e.a * 100.0,
            e.b * 100.0,
            e.freq * 100.0,
            e.phase * (180.0 / PI),
            e.flatness * 100.0,
        ];
        for (i, v) in traj.into_iter().enumerate() {
            let _ = od.set(0x7030, i as u8 + 1, round_i16(v));
        }
    }
}

/// Everything the node reports, in SI units and the joint frame (encoded to Table 3-2).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Feedback {
    /// Measured hip angle \[rad\].
    pub hip: f32,
    /// Desired hip angle \[rad\].
    pub hip_desired: f32,
    /// Measured knee angle \[rad\].
    pub knee: f32,
    /// Desired knee angle \[rad\].
    pub knee_desired: f32,
    /// Trajectory clock \[s\].
    pub time_s: f32,
    /// Knee PIV output (signed PWM fraction).
    pub u_knee: f32,
    /// Hip PIV output (signed PWM fraction).
    pub u_hip: f32,
    /// Knee motor speed \[rad/s\].
    pub velocity_knee: f32,
    /// Hip motor speed \[rad/s\].
    pub velocity_hip: f32,
}

impl Feedback {
    /// Scales and writes the inputs into the dictionary. Angles saturate at ±327.67° (the
    /// thesis' INT16 range), `Time` is rounded to the nearest 0.01 s (the thesis
    /// truncates its float clock) and wraps every 655.36 s (a UINT16).
    pub fn write<const N: usize>(&self, od: &mut Od<N>) {
        let deg100 = |rad: f32| (rad * (18_000.0 / PI)) as i16;
        let _ = od.set(0x6010, 1, deg100(self.hip));
        let _ = od.set(0x6010, 2, deg100(self.hip_desired));
        let _ = od.set(0x6012, 1, ((self.time_s * 100.0 + 0.5) as u32) as u16);
        let _ = od.set(0x6014, 1, deg100(self.knee));
        let _ = od.set(0x6014, 2, deg100(self.knee_desired));
        let _ = od.set(0x6020, 1, (self.u_knee * 10_000.0) as i16);
        let _ = od.set(0x6020, 2, (self.u_hip * 10_000.0) as i16);
        let _ = od.set(0x6030, 1, (self.velocity_knee * 1000.0) as i32);
        let _ = od.set(0x6030, 2, (self.velocity_hip * 1000.0) as i32);
    }

    /// As [`Feedback::write`] through resolved handles (the per-cycle path).
    pub fn store<const N: usize>(&self, od: &mut Od<N>, v: &PdoVars) {
        let v = &v.pd;
        let deg100 = |rad: f32| (rad * (18_000.0 / PI)) as i16;
        od.store(v.hip, deg100(self.hip));
        od.store(v.hip_desired, deg100(self.hip_desired));
        od.store(v.time, ((self.time_s * 100.0 + 0.5) as u32) as u16);
        od.store(v.knee, deg100(self.knee));
        od.store(v.knee_desired, deg100(self.knee_desired));
        od.store(v.pwm_knee, (self.u_knee * 10_000.0) as i16);
        od.store(v.pwm_hip, (self.u_hip * 10_000.0) as i16);
        od.store(v.velocity_knee, (self.velocity_knee * 1000.0) as i32);
        od.store(v.velocity_hip, (self.velocity_hip * 1000.0) as i32);
    }

    /// Reads the inputs back into SI units (what a master decodes).
    pub fn read<const N: usize>(od: &Od<N>) -> Self {
        let rad = |i: u16, s: u8| od.get::<i16>(i, s).unwrap_or(0) as f32 * (PI / 18_000.0);
        Self {
            hip: rad(0x6010, 1),
            hip_desired: rad(0x6010, 2),
            time_s: od.get::<u16>(0x6012, 1).unwrap_or(0) as f32 / 100.0,
            knee: rad(0x6014, 1),
            knee_desired: rad(0x6014, 2),
            u_knee: od.get::<i16>(0x6020, 1).unwrap_or(0) as f32 / 10_000.0,
            u_hip: od.get::<i16>(0x6020, 2).unwrap_or(0) as f32 / 10_000.0,
            velocity_knee: od.get::<i32>(0x6030, 1).unwrap_or(0) as f32 / 1000.0,
            velocity_hip: od.get::<i32>(0x6030, 2).unwrap_or(0) as f32 / 1000.0,
        }
    }

    /// The measured angle of `joint` \[rad\].
    pub fn angle(&self, joint: Joint) -> f32 {
        match joint {
            Joint::Hip => self.hip,
            Joint::Knee => self.knee,
        }
    }
}

fn round_i16(v: f32) -> i16 {
    (if v >= 0.0 { v + 0.5 } else { v - 0.5 }) as i16
}

fn round_i8(v: f32) -> i8 {
    (if v >= 0.0 { v + 0.5 } else { v - 0.5 }) as i8
}

fn round_u16(v: f32) -> u16 {
    (v + 0.5) as u16
}

#[cfg(test)]
mod tests {
    use super::*;
    use oxicat_slave::DataType;

    #[test]
    fn sizes_are_38_and_22_bytes() {
        for d in [&LEFT, &RIGHT] {
            // Tables 3-1 and 3-2; the sizes are derived from the declaration.
            assert_eq!(d.default_output_bits(), 38 * 8);
            assert_eq!(d.default_input_bits(), 22 * 8);
        }
        assert_eq!((OUTPUT_BYTES, INPUT_BYTES), (38, 22));
    }

    /// The output image, entry by entry in PDO order, as Table 3-1.
    #[test]
    fn output_layout_is_table_3_1() {
        use DataType::*;
        let expect: &[(u16, u8, &str, DataType)] = &[
            (0x7000, 1, "State_Machine", Bool),
            (0x7000, 2, "Initialize_clock", Bool),
            (0x7000, 3, "Initialize_angles", Bool),
            (0x7000, 4, "Inverse_Kinematics", Bool),
            (0x7000, 5, "Blue_LED", Bool),
            (0x7000, 6, "Red_LED", Bool),
            (0x7000, 7, "Button1", Bool),
            (0x7000, 8, "Button2", Bool),
            (0x7000, 9, "Transition_time", Int8),
            (0x7010, 1, "Desired_x_value", Int32),
            (0x7012, 1, "FilterBandwidth", Unsigned16),
            (0x7014, 1, "Desired_y_value", Int32),
            (0x7020, 1, "Kp100_knee", Int16),
            (0x7020, 2, "Kd1000_knee", Int16),
            (0x7020, 3, "Ki100_knee", Int16),
            (0x7020, 4, "Kp100_hip", Int16),
            (0x7020, 5, "Kd1000_hip", Int16),
            (0x7020, 6, "Ki100_hip", Int16),
            (0x7030, 1, "x_cntr_traj1000", Int16),
            (0x7030, 2, "y_cntr_traj1000", Int16),
            (0x7030, 3, "a_ellipse100", Int16),
            (0x7030, 4, "b_ellipse100", Int16),
            (0x7030, 5, "traj_freq100", Int16),
            (0x7030, 6, "phase_deg", Int16),
            (0x7030, 7, "FlatnessParam100", Int16),
        ];
        check_layout(LEFT.rx_assign, expect, 38);
        let names: &[(u16, &str)] = &[
            (0x7000, "Buttons"),
            (0x7010, "Desired_x_value"),
            (0x7012, "TargetMode"),
            (0x7014, "Desired_y_value"),
            (0x7020, "ControlGains"),
            (0x7030, "TrajectoryParameters"),
        ];
        for (i, n) in names {
            assert_eq!(LEFT.object(*i).unwrap().name, *n);
        }
    }

    /// The input image, entry by entry in PDO order, as Table 3-2.
    #[test]
    fn input_layout_is_table_3_2() {
        use DataType::*;
        let expect: &[(u16, u8, &str, DataType)] = &[
            (0x6010, 1, "hip_angle", Int16),
            (0x6010, 2, "Desired_hip_angle", Int16),
            (0x6012, 1, "Time", Unsigned16),
            (0x6014, 1, "knee_angle", Int16),
            (0x6014, 2, "Desired_knee_angle", Int16),
            (0x6020, 1, "PWM10000_knee", Int16),
            (0x6020, 2, "PWM10000_hip", Int16),
            (0x6030, 1, "velocity_knee1000", Int32),
            (0x6030, 2, "velocity_hip1000", Int32),
        ];
        check_layout(LEFT.tx_assign, expect, 22);
        let names: &[(u16, &str)] = &[
            (0x6010, "hip_angle"),
            (0x6012, "FeedbackTime"),
            (0x6014, "knee_angle"),
            (0x6020, "Commands"),
            (0x6030, "Velocity"),
        ];
        for (i, n) in names {
            assert_eq!(LEFT.object(*i).unwrap().name, *n);
        }
    }

    fn check_layout(assign: &[u16], expect: &[(u16, u8, &str, DataType)], bytes: u32) {
        let mut k = 0;
        let mut bits = 0u32;
        for p in assign {
            for e in LEFT.pdo(*p).unwrap().entries {
                let (idx, sub, name, ty) = expect[k];
                assert_eq!((e.index, e.sub), (idx, sub), "entry {k}");
                assert_eq!(e.bits as u16, ty.bits(), "entry {k} bits");
                let obj = LEFT.object(idx).unwrap();
                let ent = obj.entries.iter().find(|x| x.sub == sub).unwrap();
                assert_eq!(ent.name, name);
                assert_eq!(ent.dtype, ty);
                bits += e.bits as u32;
                k += 1;
            }
        }
        assert_eq!(k, expect.len());
        assert_eq!(bits, bytes * 8);
    }

    #[test]
    fn table_4_1_scaling_round_trip() {
        let mut od = Od::<IMAGE>::new(&LEFT).unwrap();
        // What the master writes for Table 4-1, FL.
        od.set(0x7000, 1, true).unwrap();
        od.set(0x7000, 9, 3i8).unwrap();
        od.set(0x7012, 1, 20u16).unwrap();
        for (s, v) in [(1, 8000i16), (2, 50), (3, 0), (4, 8000), (5, 50), (6, 0)] {
            od.set(0x7020, s, v).unwrap();
        }
        for (s, v) in [
            (1, 0i16),
            (2, 599),
            (3, 5),
            (4, 4),
            (5, 100),
            (6, 180),
            (7, 0),
        ] {
            od.set(0x7030, s, v).unwrap();
        }
        let c = Command::read(&od);
        assert_eq!(Command::load(&od, &PdoVars::resolve(&od).unwrap()), c);
        assert!(c.operational);
        assert_eq!(c.transition_time_s, 3.0);
        assert_eq!(c.filter_hz, 20.0);
        assert_eq!(c.knee.kp, 80.0);
        assert!((c.knee.kd - 0.05).abs() < 1e-7);
        assert_eq!(c.hip.ki, 0.0);
        assert!((c.ellipse.y_centre - 0.599).abs() < 1e-7);
        assert!((c.ellipse.a - 0.05).abs() < 1e-7);
        assert!((c.ellipse.b - 0.04).abs() < 1e-7);
        assert_eq!(c.ellipse.freq, 1.0);
        assert!((c.ellipse.phase - PI).abs() < 1e-6);
        // And back.
        let mut od2 = Od::<IMAGE>::new(&LEFT).unwrap();
        c.write(&mut od2);
        assert_eq!(Command::read(&od2), c);
        assert_eq!(od2.get::<i16>(0x7030, 2), Ok(599));
        assert_eq!(od2.get::<i16>(0x7020, 2), Ok(50));
    }

    #[test]
    fn feedback_scaling() {
        let mut od = Od::<IMAGE>::new(&RIGHT).unwrap();
        let f = Feedback {
            hip: 0.5,
            hip_desired: -0.25,
            knee: -1.0,
            knee_desired: 10.0, // beyond ±327.67°: saturates
            time_s: 656.0,      // beyond 655.35 s: wraps
            u_knee: -0.3825,
            u_hip: 0.4117,
            velocity_knee: 123.456,
            velocity_hip: -7.5,
        };
        f.write(&mut od);
        assert_eq!(od.get::<i16>(0x6010, 1), Ok(2864)); // 28.6479°
        assert_eq!(od.get::<i16>(0x6010, 2), Ok(-1432));
        assert_eq!(od.get::<i16>(0x6014, 1), Ok(-5729));
        assert_eq!(od.get::<i16>(0x6014, 2), Ok(i16::MAX));
        assert_eq!(od.get::<u16>(0x6012, 1), Ok(64));
        assert_eq!(od.get::<i16>(0x6020, 1), Ok(-3825));
        assert_eq!(od.get::<i16>(0x6020, 2), Ok(4117));
        assert_eq!(od.get::<i32>(0x6030, 1), Ok(123_456));
        assert_eq!(od.get::<i32>(0x6030, 2), Ok(-7500));
        let v = PdoVars::resolve(&od).unwrap();
        let mut od2 = Od::<IMAGE>::new(&RIGHT).unwrap();
        f.store(&mut od2, &v);
        assert_eq!(Feedback::read(&od2), Feedback::read(&od));
        let b = Feedback::read(&od);
        assert!((b.hip - 0.5).abs() < 1e-3);
        assert!((b.u_hip - 0.4117).abs() < 1e-6);
    }
}
