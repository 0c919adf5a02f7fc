//! Experiment scenarios: the thesis' Table 4-1 and its procedure as a TOML file
//! (`scenarios/laelaps-trot.toml`, built into the binary as [`DEFAULT_TOML`]).

use serde::Deserialize;

use crate::MasterError;
use oxicat_sim::exec_time::ExecTiming;
use oxicat_sim::laelaps::LegId;
use oxicat_sim::pdi_path::{PdiRoute, DEFAULT_SPI_MHZ};

/// The shipped scenario: Laelaps II trotting experiment 1 (thesis Table 4-1).
pub const DEFAULT_TOML: &str = include_str!("../../../scenarios/laelaps-trot.toml");

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
        let text = std::fs::read_to_string(path)
            .map_err(|e| MasterError::Io(path.display().to_string(), e))?;
        Self::parse(&text)
    }

    fn check(&self) -> Result<(), MasterError> {
        let bad = |m: String| Err(MasterError::Usage(format!("scenario: {m}")));
        if self.bus.cycle_us < 100 || self.bus.sync0_shift_us >= self.bus.cycle_us {
            return bad("bus.cycle_us ≥ 100 and sync0_shift_us < cycle_us".into());
        }
        let p = &self.procedure;
        for (n, v) in [
            ("settle_s", p.settle_s),
            ("stand_s", p.stand_s),
            ("trot_s", p.trot_s),
            ("stop_s", p.stop_s),
        ] {
            if !(0.0..=3600.0).contains(&v) {
                return bad(format!("procedure.{n} = {v} is not in 0…3600 s"));
            }
        }
        if p.transition_time_s <= 0 {
            return bad("procedure.transition_time_s must be ≥ 1 s".into());
        }
        if p.settle_s < f64::from(p.transition_time_s) {
            return bad("procedure.settle_s must be ≥ transition_time_s (gains ramp)".into());
        }
        let r = self.rig.plant_rate_hz;
        if !(10_000..=1_000_000).contains(&r) || 1_000_000_000 % r != 0 {
            return bad(format!("rig.plant_rate_hz = {r}"));
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
                return bad(format!("leg {}: freq_hz must be > 0", l.leg));
            }
        }
        if seen.len() != 4 {
            return bad("all four legs (FL, FR, HL, HR) need a [[leg]] entry".into());
        }
        if !(1..=100).contains(&self.pdi.spi_mhz) {
            return bad(format!(
                "pdi.spi_mhz = {} is not in 1…100",
                self.pdi.spi_mhz
            ));
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
