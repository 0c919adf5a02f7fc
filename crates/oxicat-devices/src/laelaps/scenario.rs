//! Experiment scenarios: the thesis' Table 4-1 and its procedure as a TOML file
//! (`scenarios/laelaps-trot.toml`, built into the binary as [`DEFAULT_TOML`]).

use serde::Deserialize;

use crate::laelaps::piv::ControlLaw;
use crate::laelaps::rig::LegId;
use oxicat_master::MasterError;
use oxicat_sim::exec_time::ExecTiming;
use oxicat_sim::pdi_path::{PdiRoute, DEFAULT_SPI_MHZ};

/// The shipped scenario: Laelaps II trotting experiment 1 (thesis Table 4-1).
pub const DEFAULT_TOML: &str = include_str!("../../../../scenarios/laelaps-trot.toml");

/// A trotting experiment.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Title (goes into the summary).
    pub name: String,
    /// Bus timing.
    pub bus: Bus,
    /// The thesis' procedure, phase lengths.
    pub procedure: Procedure,
    /// Gains and filter.
    pub control: Control,
    /// Treadmill and plant.
    pub rig: Rig,
    /// Table 4-1, one entry per leg.
    #[serde(rename = "leg")]
    pub legs: Vec<LegTable>,
    /// How each leg node's firmware reaches its ESC (optional; default: directly).
    #[serde(default)]
    pub pdi: PdiSettings,
    /// The whole robot: body on its support, per-leg tolerances (optional; absent: each
    /// leg alone with its hip fixed, nominal parameters).
    #[serde(default)]
    pub robot: Robot,
}

/// The `[robot]` table: the legs on one body on the treadmill's support, and how far each
/// leg's masses and motors are from nominal (seeded). See `crate::laelaps::robot`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Robot {
    /// `true`: the four hips are on one body on its support (the legs coupled through it);
    /// `false`: each leg alone with its hip fixed.
    pub body: bool,
    /// Whole robot, legs included \[kg\] (assumed; the thesis gives no mass).
    pub mass_kg: f64,
    /// Fore to hind hip axes \[cm\] (assumed).
    pub hip_spacing_cm: f64,
    /// Centre of mass behind the midpoint of the hips \[cm\] (assumed: toward the hind legs).
    pub com_behind_cm: f64,
    /// Share of the robot's weight the treadmill support carries at the release height.
    pub support_share: f64,
    /// Each leg's link masses within ± this of nominal \[%\] (uniform, seeded).
    pub mass_tolerance_pct: f64,
    /// Each leg's motor torque constants and resistances within ± this of nominal \[%\].
    pub motor_tolerance_pct: f64,
    /// Seed of the tolerances.
    pub seed: u64,
}

impl Default for Robot {
    /// No `[robot]` table: each leg alone with its hip fixed, nominal masses and motors (the
    /// body's numbers are the shipped file's, unused).
    fn default() -> Self {
        Self {
            body: false,
            mass_kg: 40.0,
            hip_spacing_cm: 70.0,
            com_behind_cm: 5.0,
            support_share: 0.2,
            mass_tolerance_pct: 0.0,
            motor_tolerance_pct: 0.0,
            seed: 0,
        }
    }
}

/// Which way the leg nodes' firmware reaches its ESC.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PdiChip {
    /// The software ESC is the firmware's `Pdi`.
    #[default]
    Direct,
    /// The LAN9252 driver over a simulated SPI LAN9252 (ESC: the LAN9252 preset).
    Lan9252,
    /// The ET1100 SPI PDI driver over a simulated ET1100.
    Et1100,
}

impl PdiChip {
    /// Parses `direct`, `lan9252` or `et1100` (any case).
    pub fn parse(s: &str) -> Option<Self> {
        match s.to_ascii_lowercase().as_str() {
            "direct" => Some(PdiChip::Direct),
            "lan9252" => Some(PdiChip::Lan9252),
            "et1100" => Some(PdiChip::Et1100),
            _ => None,
        }
    }
}

/// Whether the leg nodes' firmware runs under the execution-time model
/// ([`oxicat_sim::exec_time`]) — `[pdi] exec_time`, `oxicat trot --bus-time`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ExecTime {
    /// Firmware in zero virtual time (the default).
    #[default]
    Off,
    /// A handler takes its SPI bus time, nothing for the CPU.
    Bus,
    /// The thesis' application: SPI bus time + 1 µs CPU per SYNC0 ([`ExecTiming::thesis`]).
    Thesis,
}

impl ExecTime {
    /// Parses `off`, `bus` or `thesis` (any case).
    pub fn parse(s: &str) -> Option<Self> {
        match s.to_ascii_lowercase().as_str() {
            "off" => Some(ExecTime::Off),
            "bus" => Some(ExecTime::Bus),
            "thesis" => Some(ExecTime::Thesis),
            _ => None,
        }
    }

    /// `off`, `bus` or `thesis`.
    pub fn name(self) -> &'static str {
        match self {
            ExecTime::Off => "off",
            ExecTime::Bus => "bus",
            ExecTime::Thesis => "thesis",
        }
    }

    /// The model's settings (`None`: off).
    pub fn timing(self) -> Option<ExecTiming> {
        match self {
            ExecTime::Off => None,
            ExecTime::Bus => Some(ExecTiming::bus_only()),
            ExecTime::Thesis => Some(ExecTiming::thesis()),
        }
    }
}

/// The `[pdi]` table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PdiSettings {
    /// `direct`, `lan9252` or `et1100`.
    pub route: PdiChip,
    /// SPI clock \[MHz\] (1 … 100) of the driver routes.
    pub spi_mhz: u32,
    /// Execution-time model of the leg nodes' firmware: `off` (default), `bus` or `thesis`.
    pub exec_time: ExecTime,
}

impl Default for PdiSettings {
    fn default() -> Self {
        Self {
            route: PdiChip::Direct,
            spi_mhz: DEFAULT_SPI_MHZ,
            exec_time: ExecTime::Off,
        }
    }
}

/// DC cycle.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Bus {
    /// SYNC0 period \[µs\].
    pub cycle_us: u32,
    /// Master frame after SYNC0 \[µs\].
    pub sync0_shift_us: u32,
    /// The thesis' DC split (§2.4.3, "SyncManager/Sync0/Sync1"): the leg nodes map their
    /// outputs on the SM2 event, run the application on SYNC0 and latch their inputs on
    /// SYNC1 (0x1C32:01 = 3, ETG.1020 DC SYNC1 mode). `false` (default): outputs,
    /// application and inputs on SYNC0.
    #[serde(default)]
    pub sync1: bool,
    /// With `sync1`: SYNC1 this long after SYNC0 \[µs\] (0x1C33:03); 0 (default, the
    /// thesis' delay times) fires it with SYNC0.
    #[serde(default)]
    pub sync1_shift_us: u32,
}

/// Phase lengths of the procedure \[s\].
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Procedure {
    /// Configuration state before the start (not recorded).
    pub settle_s: f64,
    /// Standing with a = b = 0 before and after the trot.
    pub stand_s: f64,
    /// `Transition_time` \[s\] (INT8 in the PDO).
    pub transition_time_s: i8,
    /// Steady trot with full a and b.
    pub trot_s: f64,
    /// Recorded time after `State_Machine = 0`.
    pub stop_s: f64,
}

/// PIV gains of one joint.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GainSet {
    /// Proportional gain.
    pub kp: f64,
    /// Velocity (derivative-on-feedback) gain.
    pub kd: f64,
    /// Integral gain.
    pub ki: f64,
}

/// Controller settings for all legs.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Control {
    /// Knee gains.
    pub knee: GainSet,
    /// Hip gains.
    pub hip: GainSet,
    /// Derivative filter bandwidth \[Hz\].
    pub filter_hz: u16,
    /// Joint control law: `"piv"` (the thesis' `DCL_runPID_C1`, the default) or
    /// `"dcl-pid"` (the parallel C4 PID: `kp` [1/rev], `ki` [1/(rev·s)], `kd` [s/rev], not
    /// multiplied by `kp`). Same PDO gains, filter and output limits either way.
    #[serde(default)]
    pub law: Option<String>,
}

impl Control {
    /// The law of `law` (PIV when absent or unknown; [`Scenario::parse`] refuses unknown).
    pub fn law(&self) -> ControlLaw {
        self.law
            .as_deref()
            .and_then(ControlLaw::parse)
            .unwrap_or_default()
    }
}

/// Treadmill and plant.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rig {
    /// Belt surface below the hip axis \[m\].
    pub belt_depth_m: f64,
    /// Belt speed during the trot \[m/s\].
    pub belt_speed_m_s: f64,
    /// Plant integration rate \[Hz\] (10 000 … 1 000 000, dividing 1 s in whole ns).
    pub plant_rate_hz: u32,
}

/// One leg's column of Table 4-1.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LegTable {
    /// `FL`, `FR`, `HL` or `HR`.
    pub leg: String,
    /// Ellipse centre x \[cm\].
    pub x_centre_cm: f64,
    /// Ellipse centre y \[cm\] (down from the hip).
    pub y_centre_cm: f64,
    /// Semi-axis a (step length) \[cm\].
    pub a_cm: f64,
    /// Semi-axis b (ground clearance) \[cm\].
    pub b_cm: f64,
    /// Stepping frequency \[Hz\].
    pub freq_hz: f64,
    /// Initial phase \[deg\].
    pub phase_deg: f64,
    /// Flatness parameter.
    pub flatness: f64,
}

/// The range of every number of a scenario: key (a leg's keys as `leg.<key>`), lowest,
/// highest, unit, and why. Where a value goes into an INT16 of the leg's PDO with a scale
/// (gains ×100 or ×1000, centre ×10, frequency ×100, flatness ×100), the range keeps it
/// inside the INT16 and inside what the rig can do.
pub const LIMITS: &[(&str, f64, f64, &str, &str)] = &[
    ("bus.cycle_us", 100.0, 10_000.0, " µs", "DC SYNC0 period"),
    ("bus.sync0_shift_us", 0.0, 9_999.0, " µs", "below cycle_us"),
    (
        "bus.sync1_shift_us",
        0.0,
        9_999.0,
        " µs",
        "SYNC1 after SYNC0, below cycle_us",
    ),
    ("procedure.settle_s", 0.0, 3600.0, " s", "phase length"),
    ("procedure.stand_s", 0.0, 3600.0, " s", "phase length"),
    (
        "procedure.transition_time_s",
        1.0,
        127.0,
        " s",
        "INT8 Transition_time",
    ),
    ("procedure.trot_s", 0.0, 3600.0, " s", "phase length"),
    ("procedure.stop_s", 0.0, 3600.0, " s", "phase length"),
    ("control.knee.kp", 0.0, 327.0, "", "Kp100 is an INT16"),
    ("control.knee.kd", 0.0, 32.0, "", "Kd1000 is an INT16"),
    ("control.knee.ki", 0.0, 327.0, "", "Ki100 is an INT16"),
    ("control.hip.kp", 0.0, 327.0, "", "Kp100 is an INT16"),
    ("control.hip.kd", 0.0, 32.0, "", "Kd1000 is an INT16"),
    ("control.hip.ki", 0.0, 327.0, "", "Ki100 is an INT16"),
    (
        "control.filter_hz",
        1.0,
        5000.0,
        " Hz",
        "below half the 10 kHz joint loop",
    ),
    (
        "rig.belt_depth_m",
        0.1,
        1.5,
        " m",
        "the treadmill below the hip axis",
    ),
    ("rig.belt_speed_m_s", 0.0, 5.0, " m/s", "treadmill belt"),
    (
        "rig.plant_rate_hz",
        10_000.0,
        1_000_000.0,
        " Hz",
        "plant integration rate",
    ),
    ("pdi.spi_mhz", 1.0, 100.0, " MHz", "SPI clock"),
    ("robot.mass_kg", 1.0, 500.0, " kg", "whole robot"),
    (
        "robot.hip_spacing_cm",
        10.0,
        300.0,
        " cm",
        "fore to hind hip axes",
    ),
    (
        "robot.com_behind_cm",
        -50.0,
        50.0,
        " cm",
        "centre of mass behind the hips' midpoint, inside the hips",
    ),
    (
        "robot.support_share",
        0.0,
        1.0,
        "",
        "share of the weight on the support",
    ),
    (
        "robot.mass_tolerance_pct",
        0.0,
        50.0,
        " %",
        "link masses around nominal",
    ),
    (
        "robot.motor_tolerance_pct",
        0.0,
        50.0,
        " %",
        "motor constants around nominal",
    ),
    ("robot.seed", 0.0, 999_999_999.0, "", "nine digits"),
    (
        "leg.x_centre_cm",
        -50.0,
        50.0,
        " cm",
        "ellipse centre ahead of the hip",
    ),
    (
        "leg.y_centre_cm",
        0.0,
        100.0,
        " cm",
        "ellipse centre below the hip",
    ),
    ("leg.a_cm", 0.0, 30.0, " cm", "step length semi-axis"),
    ("leg.b_cm", 0.0, 30.0, " cm", "ground clearance semi-axis"),
    ("leg.freq_hz", 0.01, 10.0, " Hz", "stepping frequency"),
    ("leg.phase_deg", -360.0, 360.0, "°", "initial phase"),
    (
        "leg.flatness",
        0.0,
        100.0,
        "",
        "flatness parameter, ×100 an INT16",
    ),
];

impl Scenario {
    /// The shipped Table 4-1 scenario.
    pub fn thesis() -> Self {
        Self::parse(DEFAULT_TOML).expect("the shipped scenario parses")
    }

    /// Parses and checks a scenario.
    pub fn parse(text: &str) -> Result<Self, MasterError> {
        let s: Scenario =
            toml::from_str(text).map_err(|e| MasterError::Usage(format!("scenario: {e}")))?;
        s.check()?;
        Ok(s)
    }

    /// Reads a scenario file.
    pub fn load(path: &std::path::Path) -> Result<Self, MasterError> {
        let text =
            std::fs::read_to_string(path).map_err(|e| MasterError::File(path.to_path_buf(), e))?;
        Self::parse(&text)
    }

    /// Every number of the scenario with its key (`leg FL.a_cm` for a leg's column).
    fn numbers(&self) -> Vec<(String, f64)> {
        let (b, p, c, r) = (&self.bus, &self.procedure, &self.control, &self.rig);
        let mut v: Vec<(String, f64)> = vec![
            ("bus.cycle_us".into(), f64::from(b.cycle_us)),
            ("bus.sync0_shift_us".into(), f64::from(b.sync0_shift_us)),
            ("bus.sync1_shift_us".into(), f64::from(b.sync1_shift_us)),
            ("procedure.settle_s".into(), p.settle_s),
            ("procedure.stand_s".into(), p.stand_s),
            (
                "procedure.transition_time_s".into(),
                f64::from(p.transition_time_s),
            ),
            ("procedure.trot_s".into(), p.trot_s),
            ("procedure.stop_s".into(), p.stop_s),
            ("control.filter_hz".into(), f64::from(c.filter_hz)),
            ("rig.belt_depth_m".into(), r.belt_depth_m),
            ("rig.belt_speed_m_s".into(), r.belt_speed_m_s),
            ("rig.plant_rate_hz".into(), f64::from(r.plant_rate_hz)),
            ("pdi.spi_mhz".into(), f64::from(self.pdi.spi_mhz)),
            ("robot.mass_kg".into(), self.robot.mass_kg),
            ("robot.hip_spacing_cm".into(), self.robot.hip_spacing_cm),
            ("robot.com_behind_cm".into(), self.robot.com_behind_cm),
            ("robot.support_share".into(), self.robot.support_share),
            (
                "robot.mass_tolerance_pct".into(),
                self.robot.mass_tolerance_pct,
            ),
            (
                "robot.motor_tolerance_pct".into(),
                self.robot.motor_tolerance_pct,
            ),
            ("robot.seed".into(), self.robot.seed as f64),
        ];
        for (joint, g) in [("knee", &c.knee), ("hip", &c.hip)] {
            for (k, x) in [("kp", g.kp), ("kd", g.kd), ("ki", g.ki)] {
                v.push((format!("control.{joint}.{k}"), x));
            }
        }
        for l in &self.legs {
            for (k, x) in [
                ("x_centre_cm", l.x_centre_cm),
                ("y_centre_cm", l.y_centre_cm),
                ("a_cm", l.a_cm),
                ("b_cm", l.b_cm),
                ("freq_hz", l.freq_hz),
                ("phase_deg", l.phase_deg),
                ("flatness", l.flatness),
            ] {
                v.push((format!("leg {}.{k}", l.leg), x));
            }
        }
        v
    }

    fn check(&self) -> Result<(), MasterError> {
        let bad = |m: String| Err(MasterError::Usage(format!("scenario: {m}")));
        for (key, v) in self.numbers() {
            // `leg FL.a_cm` is checked as `leg.a_cm`.
            let class = match key.strip_prefix("leg ") {
                Some(rest) => format!("leg.{}", rest.split_once('.').map_or(rest, |x| x.1)),
                None => key.clone(),
            };
            let Some(&(_, lo, hi, unit, why)) = LIMITS.iter().find(|l| l.0 == class) else {
                return bad(format!("{key} has no range (internal: add it to LIMITS)"));
            };
            if !(v.is_finite() && (lo..=hi).contains(&v)) {
                return bad(format!("{key} = {v} is not in {lo} … {hi}{unit} ({why})"));
            }
        }
        if let Some(l) = &self.control.law {
            if ControlLaw::parse(l).is_none() {
                return bad(format!(
                    "control.law = {l:?} is not a control law (\"piv\" or \"dcl-pid\")"
                ));
            }
        }
        if self.bus.sync1_shift_us >= self.bus.cycle_us {
            return bad(format!(
                "bus.sync1_shift_us = {} must be below bus.cycle_us = {}",
                self.bus.sync1_shift_us, self.bus.cycle_us
            ));
        }
        if self.bus.sync0_shift_us >= self.bus.cycle_us {
            return bad(format!(
                "bus.sync0_shift_us = {} must be below bus.cycle_us = {}",
                self.bus.sync0_shift_us, self.bus.cycle_us
            ));
        }
        let r = &self.robot;
        if r.com_behind_cm.abs() >= 0.5 * r.hip_spacing_cm {
            return bad(format!(
                "robot.com_behind_cm = {} must lie between the hips (|…| < robot.hip_spacing_cm / 2 = {})",
                r.com_behind_cm,
                0.5 * r.hip_spacing_cm
            ));
        }
        let p = &self.procedure;
        if p.settle_s < f64::from(p.transition_time_s) {
            return bad("procedure.settle_s must be ≥ transition_time_s (gains ramp)".into());
        }
        let r = self.rig.plant_rate_hz;
        if 1_000_000_000 % r != 0 {
            return bad(format!(
                "rig.plant_rate_hz = {r} does not divide 1 s in whole ns"
            ));
        }
        let mut seen = Vec::new();
        for l in &self.legs {
            let Some(id) = LegId::parse(&l.leg) else {
                return bad(format!("unknown leg {:?} (FL, FR, HL, HR)", l.leg));
            };
            if seen.contains(&id) {
                return bad(format!("leg {} twice", l.leg));
            }
            seen.push(id);
            if l.freq_hz <= 0.0 {
                return bad(format!("leg {}.freq_hz must be > 0", l.leg));
            }
        }
        if seen.len() != 4 {
            return bad("all four legs (FL, FR, HL, HR) need a [[leg]] entry".into());
        }
        Ok(())
    }

    /// How the leg nodes reach their ESCs (`[pdi]`; LAN9252 read 0x03, ET1100 two-byte
    /// addresses with wait state).
    pub fn pdi_route(&self) -> PdiRoute {
        match self.pdi.route {
            PdiChip::Direct => PdiRoute::Direct,
            PdiChip::Lan9252 => PdiRoute::lan9252(self.pdi.spi_mhz),
            PdiChip::Et1100 => PdiRoute::et1100(self.pdi.spi_mhz),
        }
    }

    /// Sets the PDI route of every leg node (`--pdi`).
    pub fn with_pdi(mut self, route: PdiChip) -> Self {
        self.pdi.route = route;
        self
    }

    /// The thesis' DC split with SYNC1 `us` after SYNC0 (`bus.sync1 = true`,
    /// `bus.sync1_shift_us`; `--sync1`). `us` must stay below `bus.cycle_us`.
    pub fn with_sync1(mut self, us: u32) -> Self {
        self.bus.sync1 = true;
        self.bus.sync1_shift_us = us;
        self
    }

    /// Sets the execution-time model of every leg node (`--bus-time`).
    pub fn with_exec_time(mut self, e: ExecTime) -> Self {
        self.pdi.exec_time = e;
        self
    }

    /// The Table 4-1 column of `leg`.
    pub fn leg(&self, leg: LegId) -> &LegTable {
        self.legs
            .iter()
            .find(|l| LegId::parse(&l.leg) == Some(leg))
            .expect("checked: every leg present")
    }

    /// Bus cycle \[ns\].
    pub fn cycle_ns(&self) -> u64 {
        u64::from(self.bus.cycle_us) * 1000
    }

    /// Number of bus cycles in `s` seconds (rounded).
    pub fn cycles(&self, s: f64) -> u64 {
        (s * 1e9 / self.cycle_ns() as f64).round() as u64
    }

    /// Sets the steady-trot length (`--duration`).
    pub fn with_trot(mut self, s: f64) -> Self {
        self.procedure.trot_s = s;
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_scenario_is_table_4_1() {
        let s = Scenario::thesis();
        assert_eq!(s.cycle_ns(), 400_000);
        assert_eq!(s.procedure.transition_time_s, 3);
        assert_eq!(s.control.knee.kp, 80.0);
        assert_eq!(s.control.hip.kd, 0.05);
        assert_eq!(s.control.filter_hz, 20);
        let fl = s.leg(LegId::ForeLeft);
        assert_eq!((fl.y_centre_cm, fl.phase_deg), (59.9, 180.0));
        let hr = s.leg(LegId::HindRight);
        assert_eq!((hr.y_centre_cm, hr.phase_deg), (59.8, 180.0));
        assert_eq!(s.leg(LegId::ForeRight).phase_deg, 0.0);
        assert_eq!(s.leg(LegId::HindLeft).phase_deg, 0.0);
        for l in &s.legs {
            assert_eq!(
                (l.a_cm, l.b_cm, l.freq_hz, l.flatness),
                (5.0, 4.0, 1.0, 0.0)
            );
        }
    }

    #[test]
    fn bad_scenarios_are_refused() {
        let s = DEFAULT_TOML.replace("leg = \"HR\"", "leg = \"XX\"");
        assert!(Scenario::parse(&s).is_err());
        let s = DEFAULT_TOML.replace("cycle_us = 400", "cycle_us = 400\nfoo = 1");
        assert!(Scenario::parse(&s).is_err());
        let s = DEFAULT_TOML.replace("route = \"direct\"", "route = \"spi\"");
        assert!(Scenario::parse(&s).is_err());
        let s = DEFAULT_TOML.replace("spi_mhz = 20", "spi_mhz = 0");
        assert!(Scenario::parse(&s).is_err());
    }

    /// Every number in the shipped file (walked from the TOML, so a key added to the file
    /// and not to the checks fails here) is refused as NaN, ±inf and far out of range, with
    /// its key in the message (and the range where the value has the right type).
    #[test]
    fn every_number_is_range_checked_with_key_and_range() {
        fn leaves(v: &toml::Value, path: &str, out: &mut Vec<(String, bool)>) {
            match v {
                toml::Value::Table(t) => {
                    for (k, x) in t {
                        let p = if path.is_empty() {
                            k.clone()
                        } else {
                            format!("{path}.{k}")
                        };
                        leaves(x, &p, out);
                    }
                }
                toml::Value::Array(a) => {
                    for (i, x) in a.iter().enumerate() {
                        leaves(x, &format!("{path}[{i}]"), out);
                    }
                }
                toml::Value::Integer(_) => out.push((path.to_string(), false)),
                toml::Value::Float(_) => out.push((path.to_string(), true)),
                _ => {}
            }
        }
        fn set(v: &mut toml::Value, path: &[&str], new: toml::Value) {
            let (head, rest) = path.split_first().expect("a path");
            let next = match head.split_once('[') {
                Some((k, i)) => {
                    let i: usize = i.trim_end_matches(']').parse().expect("index");
                    &mut v[k][i]
                }
                None => &mut v[*head],
            };
            if rest.is_empty() {
                *next = new;
            } else {
                set(next, rest, new);
            }
        }
        let base: toml::Value = toml::from_str(DEFAULT_TOML).expect("shipped file");
        let mut keys = Vec::new();
        leaves(&base, "", &mut keys);
        assert!(keys.len() > 40, "{keys:?}");
        for (key, float) in &keys {
            let leaf = key.rsplit('.').next().expect("a key");
            let mut values = vec![
                toml::Value::Integer(-1_000_000_000),
                toml::Value::Integer(1_000_000_000),
            ];
            if *float {
                values = vec![
                    toml::Value::Float(f64::NAN),
                    toml::Value::Float(f64::INFINITY),
                    toml::Value::Float(f64::NEG_INFINITY),
                    toml::Value::Float(-1e9),
                    toml::Value::Float(1e9),
                ];
            }
            for x in values {
                let mut v = base.clone();
                let path: Vec<&str> = key.split('.').collect();
                set(&mut v, &path, x.clone());
                let text = toml::to_string(&v).expect("serialise");
                let e = match Scenario::parse(&text) {
                    Ok(_) => panic!("{key} = {x} was accepted"),
                    Err(e) => e.to_string(),
                };
                assert!(e.contains(leaf), "{key} = {x}: {e}");
                if *float {
                    assert!(e.contains(" … "), "{key} = {x}: no range in {e}");
                }
            }
        }
    }

    #[test]
    fn the_issue_s_values_are_refused_with_key_and_range() {
        for (from, to, want) in [
            (
                "belt_speed_m_s = 0.2",
                "belt_speed_m_s = nan",
                "rig.belt_speed_m_s = NaN is not in 0 … 5 m/s",
            ),
            (
                "belt_speed_m_s = 0.2",
                "belt_speed_m_s = inf",
                "rig.belt_speed_m_s = inf is not in 0 … 5 m/s",
            ),
            (
                "knee = { kp = 80.0",
                "knee = { kp = nan",
                "control.knee.kp = NaN is not in 0 … 327",
            ),
            (
                "a_cm = 5.0",
                "a_cm = nan",
                "leg FL.a_cm = NaN is not in 0 … 30 cm",
            ),
            (
                "freq_hz = 1.0",
                "freq_hz = nan",
                "leg FL.freq_hz = NaN is not in 0.01 … 10 Hz",
            ),
            (
                "cycle_us = 400",
                "cycle_us = 50",
                "bus.cycle_us = 50 is not in 100 … 10000 µs",
            ),
        ] {
            let e = Scenario::parse(&DEFAULT_TOML.replacen(from, to, 1)).expect_err(to);
            assert!(e.to_string().contains(want), "{to}: {e}");
        }
    }

    #[test]
    fn control_law_from_the_scenario_and_its_gains_range_checked() {
        use crate::laelaps::piv::ControlLaw;
        assert_eq!(Scenario::thesis().control.law(), ControlLaw::Piv);
        let pid = |text: &str| text.replace("filter_hz = 20", "filter_hz = 20\nlaw = \"dcl-pid\"");
        let s = Scenario::parse(&pid(DEFAULT_TOML)).expect("dcl-pid");
        assert_eq!(s.control.law(), ControlLaw::DclPid);
        let s = Scenario::parse(
            &DEFAULT_TOML.replace("filter_hz = 20", "filter_hz = 20\nlaw = \"piv\""),
        )
        .expect("piv");
        assert_eq!(s.control.law(), ControlLaw::Piv);
        for (from, to, want) in [
            (
                "knee = { kp = 80.0, kd = 0.05, ki = 0.0 }",
                "knee = { kp = 80.0, kd = 4.0, ki = 400.0 }",
                "control.knee.ki = 400 is not in 0 … 327",
            ),
            (
                "hip = { kp = 80.0, kd = 0.05, ki = 0.0 }",
                "hip = { kp = 80.0, kd = 40.0, ki = 20.0 }",
                "control.hip.kd = 40 is not in 0 … 32",
            ),
            (
                "hip = { kp = 80.0, kd = 0.05, ki = 0.0 }",
                "hip = { kp = -1.0, kd = 4.0, ki = 20.0 }",
                "control.hip.kp = -1 is not in 0 … 327",
            ),
            (
                "law = \"dcl-pid\"",
                "law = \"pid\"",
                "control.law = \"pid\" is not a control law (\"piv\" or \"dcl-pid\")",
            ),
        ] {
            let text = pid(DEFAULT_TOML).replacen(from, to, 1);
            let e = Scenario::parse(&text).expect_err(to);
            assert!(e.to_string().contains(want), "{to}: {e}");
        }
    }

    #[test]
    fn pdi_route_from_the_scenario() {
        let s = Scenario::thesis();
        assert_eq!(s.pdi, PdiSettings::default());
        assert_eq!(s.pdi_route(), PdiRoute::Direct);
        let s = Scenario::parse(&DEFAULT_TOML.replace("route = \"direct\"", "route = \"et1100\""))
            .expect("et1100");
        assert_eq!(s.pdi_route(), PdiRoute::et1100(20));
        // Without a [pdi] table: direct.
        let i = DEFAULT_TOML
            .find("[pdi]")
            .expect("[pdi] in the shipped file");
        let j = DEFAULT_TOML[i..].find("[[leg]]").expect("legs after [pdi]") + i;
        let text = format!("{}{}", &DEFAULT_TOML[..i], &DEFAULT_TOML[j..]);
        let s = Scenario::parse(&text).expect("no [pdi]");
        assert_eq!(s.pdi_route(), PdiRoute::Direct);
        assert_eq!(
            s.with_pdi(PdiChip::Lan9252).pdi_route(),
            PdiRoute::lan9252(20)
        );
        assert_eq!(PdiChip::parse("LAN9252"), Some(PdiChip::Lan9252));
        assert_eq!(PdiChip::parse("x"), None);
    }

    #[test]
    fn exec_time_from_the_scenario() {
        let s = Scenario::thesis();
        assert_eq!(s.pdi.exec_time, ExecTime::Off);
        assert_eq!(s.pdi.exec_time.timing(), None);
        let s =
            Scenario::parse(&DEFAULT_TOML.replace("exec_time = \"off\"", "exec_time = \"thesis\""))
                .expect("thesis");
        assert_eq!(s.pdi.exec_time.timing(), Some(ExecTiming::thesis()));
        let s = DEFAULT_TOML.replace("exec_time = \"off\"", "exec_time = \"fast\"");
        assert!(Scenario::parse(&s).is_err());
        assert_eq!(ExecTime::parse("Bus"), Some(ExecTime::Bus));
        assert_eq!(ExecTime::parse("on"), None);
        assert_eq!(
            Scenario::thesis()
                .with_exec_time(ExecTime::Bus)
                .pdi
                .exec_time
                .timing(),
            Some(ExecTiming::bus_only())
        );
    }
}

/// Where a leg's ellipse leaves the workspace the IK accepts (thesis equations 3-4, 3-5:
/// `√(l1² + l2²) < r < l1 + l2`); there the firmware holds the last reachable point.
#[derive(Debug, Clone, PartialEq)]
pub struct ReachWarning {
    /// `FL`, `FR`, `HL` or `HR`.
    pub leg: String,
    /// Each arc outside: from, to in ms after the ellipse's angle 0 (the leg's phase not
    /// added), and the toe target at both ends \[cm\].
    pub arcs: Vec<ReachArc>,
    /// Share of each step spent outside \[%\].
    pub share_pct: f64,
    /// Time outside over the steady trot \[s\].
    pub trot_s: f64,
}

/// One arc of a step outside the workspace.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReachArc {
    /// Start, end \[ms into the step\].
    pub ms: (f64, f64),
    /// Toe target at the start and at the end `(x, y)` \[cm\].
    pub toe_cm: ((f64, f64), (f64, f64)),
    /// Beyond the outer limit (`true`: r ≥ l1 + l2) or inside the inner one.
    pub too_far: bool,
}

impl ReachWarning {
    /// One line per leg, e.g. for the trot's output and `summary.md`.
    pub fn line(&self) -> String {
        let arcs: Vec<String> = self
            .arcs
            .iter()
            .map(|a| {
                format!(
                    "{:.0}–{:.0} ms{} (toe {:.1},{:.1} → {:.1},{:.1} cm, {})",
                    a.ms.0,
                    a.ms.1,
                    if a.ms.1 < a.ms.0 {
                        " across the step's start"
                    } else {
                        ""
                    },
                    a.toe_cm.0 .0,
                    a.toe_cm.0 .1,
                    a.toe_cm.1 .0,
                    a.toe_cm.1 .1,
                    if a.too_far {
                        "beyond l1+l2"
                    } else {
                        "inside √(l1²+l2²)"
                    }
                )
            })
            .collect();
        format!(
            "workspace: leg {} leaves the reach for {:.1} % of each step ({:.2} s of the \
             steady trot), held at the last reachable point: {}",
            self.leg,
            self.share_pct,
            self.trot_s,
            arcs.join("; ")
        )
    }
}

impl Scenario {
    /// The workspace check of the thesis' planning (§3.3): every leg's full ellipse
    /// sampled over one step (3,600 points) with the firmware's own trajectory and
    /// workspace test; a warning per leg that leaves the reach, with where and how long.
    pub fn reach_check(&self) -> Vec<ReachWarning> {
        use crate::laelaps::kinematics::{reachable, R_MAX};
        use crate::laelaps::trajectory::Ellipse;
        const N: usize = 3600;
        let mut out = Vec::new();
        for l in &self.legs {
            let e = Ellipse {
                x_centre: (l.x_centre_cm / 100.0) as f32,
                y_centre: (l.y_centre_cm / 100.0) as f32,
                a: (l.a_cm / 100.0) as f32,
                b: (l.b_cm / 100.0) as f32,
                freq: l.freq_hz as f32,
                phase: 0.0,
                flatness: l.flatness as f32,
            };
            let period_ms = 1000.0 / l.freq_hz;
            let at = |k: usize| {
                let t = k as f64 / N as f64 / l.freq_hz;
                let (x, y) = e.point(t as f32);
                (k as f64 * period_ms / N as f64, x, y, !reachable(x, y))
            };
            let samples: Vec<_> = (0..N).map(at).collect();
            let outside = samples.iter().filter(|s| s.3).count();
            if outside == 0 {
                continue;
            }
            // Arcs, starting where a reachable sample precedes an outside one (wrapping).
            let start = (0..N).find(|&k| !samples[k].3).unwrap_or(0);
            let mut arcs = Vec::new();
            let mut k = 0;
            while k < N {
                let i = (start + k) % N;
                if samples[i].3 {
                    let first = samples[i];
                    let mut last = first;
                    while k + 1 < N && samples[(start + k + 1) % N].3 {
                        k += 1;
                        last = samples[(start + k) % N];
                    }
                    let r = (f64::from(first.1).powi(2) + f64::from(first.2).powi(2)).sqrt();
                    arcs.push(ReachArc {
                        ms: (first.0, last.0 + period_ms / N as f64),
                        toe_cm: (
                            (f64::from(first.1) * 100.0, f64::from(first.2) * 100.0),
                            (f64::from(last.1) * 100.0, f64::from(last.2) * 100.0),
                        ),
                        too_far: r >= f64::from(R_MAX) - 1e-3,
                    });
                }
                k += 1;
            }
            arcs.sort_by(|a, b| a.ms.0.total_cmp(&b.ms.0));
            let share = outside as f64 / N as f64;
            out.push(ReachWarning {
                leg: l.leg.clone(),
                arcs,
                share_pct: 100.0 * share,
                trot_s: share * self.procedure.trot_s,
            });
        }
        out
    }
}

#[cfg(test)]
mod reach_tests {
    use super::Scenario;

    /// Table 4-1: the fore legs' stance line (59.9 cm) reaches l1 + l2 = 60 cm at
    /// |x| = √(60² − 59.9²) = 3.46 cm, so with a = 5 cm both stance ends are outside; the
    /// hind legs' (59.8 cm) reach 4.90 cm, just short of 5 cm.
    #[test]
    fn table_4_1_leaves_the_reach_at_the_stance_ends() {
        let s = Scenario::thesis();
        let w = s.reach_check();
        let fore: Vec<_> = w.iter().filter(|w| w.leg.starts_with('F')).collect();
        assert_eq!(fore.len(), 2, "{w:?}");
        for f in &fore {
            // cos(angle) > 3.46 / 5 on the flat half: 2 × 46.2° of 360° = 25.7 %, and a
            // little more where the swing half starts and ends near the stance line.
            assert!((25.7..27.5).contains(&f.share_pct), "{}", f.line());
            assert_eq!(f.arcs.len(), 2, "{}", f.line());
            assert!(f.arcs.iter().all(|a| a.too_far));
            for a in &f.arcs {
                // One end where the stance line crosses the reach, the other past x = ±a
                // on the swing half.
                let (p, q) = a.toe_cm;
                let (inner, outer) = if p.0.abs() < q.0.abs() {
                    (p, q)
                } else {
                    (q, p)
                };
                assert!((inner.0.abs() - 3.46).abs() < 0.05, "{}", f.line());
                assert!((inner.1 - 59.9).abs() < 0.01, "{}", f.line());
                assert!((outer.0.abs() - 5.0).abs() < 0.05, "{}", f.line());
            }
            assert!((f.trot_s - f.share_pct / 100.0 * s.procedure.trot_s).abs() < 1e-9);
        }
        for h in w.iter().filter(|w| w.leg.starts_with('H')) {
            // 2 × acos(4.90 / 5) = 2 × 11.5° of 360° = 6.4 % on the flat half, and more
            // where the swing half starts and ends.
            assert!((6.4..10.0).contains(&h.share_pct), "{}", h.line());
            assert!(h.share_pct < 0.5 * fore[0].share_pct, "{}", h.line());
        }
        // A smaller step stays inside.
        let small = Scenario::parse(
            &crate::laelaps::scenario::DEFAULT_TOML.replace("a_cm = 5.0", "a_cm = 3.0"),
        )
        .unwrap();
        assert!(small.reach_check().is_empty());
    }
}
