//! One TUeES030 motor channel: a Maxon RE 30 brushed DC motor (part 310007) behind one
//! full bridge of a TI DRV8412, its LT1999 current-sense amplifier with the RC filter, and
//! a quadrature encoder (Maxon HEDL 5540, part 110512). Deterministic fixed step, `f64`.
//!
//! # Model
//!
//! - **Bridge** (DRV8412, PWM2ph3 centred drive): phase A is high for `duty_a` of the
//!   period, phase B for `duty_b`; the motor sees the period-average
//!   `(duty_a − duty_b) · V_supply` (the manual's own plant model neglects the H-bridge
//!   dynamics the same way: "PWM gives an average voltage"). The 2 × 80 kHz ripple is not
//!   integrated (with L/R = 195 µs it is a few mA). Driver disabled (tristate) or latched
//!   fault: the terminals float, the winding current decays through the body diodes
//!   against the supply (−sign(i)·(V_supply + 2 V_diode)) to zero and stays there.
//! - **Motor**: `L di/dt = u − R i − k ω`, `J dω/dt = k i − b ω − T_c sat(ω/ω_reg) − T_load`
//!   (the manual's eq. in §6 plus Coulomb friction). The electrical part is integrated
//!   exactly over each step (u, ω held), the mechanical part semi-implicitly.
//! - **Current sense** (manual §2.10): LT1999 gain 20 on the sense resistor, output around
//!   a reference, then R_f = 1 kΩ / C_f = 10 nF (≈ 16 kHz), integrated exactly with the
//!   current's step average; the ADC (12 bit, 0–3.3 V) samples the filter output.
//! - **Encoder**: 4 × lines counts per revolution, and the time of the last edge (the
//!   FPGA's 40 MHz capture timestamp).
//! - **Line** ([`Line`], optional): the board's 24 V line as its bulk capacitance, fed by a
//!   supply that sources but cannot sink current (a lab supply; the manual §2.1: "no
//!   overvoltage protection … most power supplies" cannot sink braking energy). The
//!   bridges' step-average line current ([`Re30Drive::bus_current`]: the power balance
//!   `u · i = V · I` of the averaged bridge, or the body diodes returning the winding current
//!   when the driver is off) and the board's own draw charge or drain the capacitor; the
//!   supply holds the line at its set voltage from below. Without it the line is the
//!   supply, which then also takes energy back (a battery).
//!
//! # Parameters ([`Re30Params::maxon_310007`])
//!
//! From the Maxon catalogue line of the RE 30 Ø30 mm graphite brushes 60 W, 24 V winding,
//! part 310007 (values recalled from the catalogue; the manual confirms R ≈ 0.61 Ω and
//! k = 0.0259 V s/rad as "manufacturer value", and a 39 A stall current): terminal
//! resistance 0.611 Ω, terminal inductance 0.119 mH, torque constant 25.9 mNm/A (speed
//! constant 369 rpm/V), rotor inertia 33.5 g cm², 113 mA no-load current (so ≈ 8830 rpm
//! no-load at 24 V). The friction split of the no-load torque (113 mA · 25.9 mNm/A =
//! 2.9 mNm at 925 rad/s) into Coulomb 2.0 mNm and viscous 1.0 µNm s/rad is **plausible,
//! not catalogue**. Encoder HEDL 5540 110512: 500 lines (catalogue).

use core::f64::consts::PI;

/// Motor, bridge and sensor constants of one channel (SI).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Re30Params {
    /// Terminal resistance \[Ω\].
    pub resistance: f64,
    /// Terminal inductance \[H\].
    pub inductance: f64,
    /// Torque constant = back-EMF constant \[N m/A\] = \[V s/rad\].
    pub torque_constant: f64,
    /// Rotor inertia plus load \[kg m²\].
    pub inertia: f64,
    /// Viscous friction \[N m s/rad\].
    pub viscous: f64,
    /// Coulomb friction \[N m\].
    pub coulomb: f64,
    /// Speed below which Coulomb friction is linear \[rad/s\].
    pub friction_reg: f64,
    /// Sense resistor \[Ω\].
    pub sense_resistance: f64,
    /// LT1999 gain.
    pub sense_gain: f64,
    /// LT1999 output at zero current \[V\].
    pub sense_offset: f64,
    /// RC filter time constant R_f · C_f \[s\].
    pub filter_tau: f64,
    /// Encoder lines per revolution.
    pub encoder_lines: u32,
    /// Driver over-current trip \[A\] (DRV8412 OC protection; fault latched, bridge off).
    pub overcurrent: f64,
    /// Rotor held (the manual's "axis fixed" step tests).
    pub locked: bool,
}

impl Re30Params {
    /// Maxon RE 30 310007 on an M2/M3 channel (10 mΩ sense), HEDL 5540 110512 encoder;
    /// see the module documentation for the sources.
    pub const fn maxon_310007() -> Self {
        Self {
            resistance: 0.611,
            inductance: 0.119e-3,
            torque_constant: 0.0259,
            inertia: 33.5e-7,
            viscous: 1.0e-6,
            coulomb: 2.0e-3,
            friction_reg: 1.0,
            sense_resistance: 0.010,
            sense_gain: 20.0,
            // 2168 counts of 4096 at 3.3 V: the manual's default `czero`.
            sense_offset: 2168.0 * 3.3 / 4096.0,
            filter_tau: 1.0e3 * 10.0e-9,
            encoder_lines: 500,
            // DRV8412 OC limit with its OC_ADJ resistor (plausible, not in the manual).
            overcurrent: 12.0,
            locked: false,
        }
    }

    /// The same motor on M1 (parallel-mode driver, 5 mΩ effective sense: the manual's 33 A
    /// range against 16.5 A on M2/M3).
    pub const fn maxon_310007_on_m1() -> Self {
        let mut p = Self::maxon_310007();
        p.sense_resistance = 0.005;
        p.overcurrent = 24.0;
        p
    }
}

/// ADC full scale \[V\].
pub const ADC_VREF: f64 = 3.3;
/// ADC counts.
pub const ADC_COUNTS: f64 = 4096.0;
/// Body-diode drop \[V\].
pub const DIODE_DROP: f64 = 0.7;
/// Encoder timestamp clock \[Hz\] (the FPGA's 40 MHz).
pub const TIMESTAMP_HZ: f64 = 40.0e6;

/// The line's constants.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LineParams {
    /// Bulk capacitance on the bridges' supply \[F\].
    pub capacitance: f64,
    /// Current the board draws from the line itself (12 V LDO, 5 V DC/DC) \[A\].
    pub quiescent: f64,
}

impl LineParams {
    /// The TUeES030 bench's line (chosen; the manual gives neither): 470 µF of bulk
    /// capacitance (a usual electrolytic on a 24 V, 6 A motor board) and 0.1 A of own draw
    /// (the 5 V DC/DC, rated 0.5 A at 5 V, lightly loaded, plus the 12 V LDO).
    pub const fn tue_es030() -> Self {
        Self {
            capacitance: 470e-6,
            quiescent: 0.1,
        }
    }
}

/// The line voltage over a bulk capacitor fed by a supply that cannot sink current.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Line {
    /// Constants.
    pub params: LineParams,
    /// Capacitor (= line) voltage \[V\].
    pub voltage: f64,
    /// Highest line voltage so far \[V\].
    pub peak: f64,
}

impl Line {
    /// A line charged to `supply` \[V\].
    pub fn new(params: LineParams, supply: f64) -> Self {
        Self {
            params,
            voltage: supply,
            peak: supply,
        }
    }

    /// Advances `h` seconds: the bridges draw `bridges` \[A\] (negative: regenerate), the
    /// board its own draw; the supply (`supply` \[V\]) sources whatever keeps the line at
    /// its voltage, and nothing above it.
    pub fn step(&mut self, h: f64, supply: f64, bridges: f64) {
        let p = self.params;
        let c = p.capacitance.max(1e-12);
        self.voltage = (self.voltage - h * (bridges + p.quiescent) / c).max(supply);
        self.peak = self.peak.max(self.voltage);
    }
}

/// What the firmware drives: the two phase duties and the driver enable.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BridgeCommand {
    /// Phase A duty (0..1).
    pub duty_a: f64,
    /// Phase B duty (0..1).
    pub duty_b: f64,
    /// Driver enabled (false: tristate).
    pub enabled: bool,
}

impl Default for BridgeCommand {
    fn default() -> Self {
        Self {
            duty_a: 0.5,
            duty_b: 0.5,
            enabled: true,
        }
    }
}

/// One channel's state.
#[derive(Clone, Debug, PartialEq)]
pub struct Re30Drive {
    /// Constants.
    pub params: Re30Params,
    /// Bridge command in force.
    pub bridge: BridgeCommand,
    /// Winding current \[A\].
    pub current: f64,
    /// Rotor speed \[rad/s\].
    pub speed: f64,
    /// Rotor angle \[rad\].
    pub angle: f64,
    /// Load torque on the shaft \[N m\].
    pub load_torque: f64,
    /// Filtered current-sense output \[V\].
    pub sense_out: f64,
    /// Driver fault latched (over-current), bridge off until cleared.
    pub fault: bool,
    /// Over-temperature warning (set by the bench; not modelled thermally).
    pub otw: bool,
    /// Virtual time \[s\].
    pub time: f64,
    /// Current the bridge drew from the line over the last step, step average \[A\]:
    /// `(duty_a − duty_b) · i` with the driver on, `−|i|` through the body diodes with it
    /// off; negative = regenerated into the line.
    pub bus_current: f64,
    count: i64,
    edge_time: f64,
}

impl Re30Drive {
    /// A channel at rest, bridge at 50/50.
    pub fn new(params: Re30Params) -> Self {
        Self {
            params,
            bridge: BridgeCommand::default(),
            current: 0.0,
            speed: 0.0,
            angle: 0.0,
            load_torque: 0.0,
            sense_out: params.sense_offset,
            fault: false,
            otw: false,
            time: 0.0,
            bus_current: 0.0,
            count: 0,
            edge_time: 0.0,
        }
    }

    /// Bridge voltage the motor sees now at `supply` \[V\] (tristate: the diode clamp).
    pub fn bridge_voltage(&self, supply: f64) -> f64 {
        if self.bridge.enabled && !self.fault {
            (self.bridge.duty_a - self.bridge.duty_b).clamp(-1.0, 1.0) * supply
        } else if self.current != 0.0 {
            -self.current.signum() * (supply + 2.0 * DIODE_DROP)
        } else {
            0.0
        }
    }

    /// Advances `h` seconds with the bridge on `supply` volts.
    pub fn step(&mut self, h: f64, supply: f64) {
        let p = self.params;
        let floating = !self.bridge.enabled || self.fault;
        let u = self.bridge_voltage(supply);
        let emf = p.torque_constant * self.speed;
        let a = (-p.resistance * h / p.inductance).exp();
        let i0 = self.current;
        let iss = (u - emf) / p.resistance;
        let mut i1 = iss + (i0 - iss) * a;
        if floating && (i0 == 0.0 || i1.signum() != i0.signum()) {
            i1 = 0.0;
        }
        // Step average of the current (exact for the exponential), for torque and filter.
        let i_avg = if floating {
            0.5 * (i0 + i1)
        } else {
            iss + (i0 - iss) * (1.0 - a) * p.inductance / (p.resistance * h)
        };
        self.bus_current = if floating {
            -i_avg.abs()
        } else {
            (self.bridge.duty_a - self.bridge.duty_b).clamp(-1.0, 1.0) * i_avg
        };
        self.current = i1;
        if self.current.abs() > p.overcurrent {
            self.fault = true;
        }
        if !p.locked {
            let fric = p.coulomb * (self.speed / p.friction_reg).clamp(-1.0, 1.0);
            let tq = p.torque_constant * i_avg - p.viscous * self.speed - fric - self.load_torque;
            self.speed += h * tq / p.inertia;
            self.angle += h * self.speed;
        } else {
            self.speed = 0.0;
        }
        let target = p.sense_offset + p.sense_gain * p.sense_resistance * i_avg;
        let b = (-h / p.filter_tau).exp();
        self.sense_out = target + (self.sense_out - target) * b;
        self.time += h;
        let c = (self.angle * 4.0 * p.encoder_lines as f64 / (2.0 * PI)).floor() as i64;
        if c != self.count {
            self.count = c;
            self.edge_time = self.time;
        }
    }

    /// The ADC2 counts of the current sense now.
    pub fn adc_counts(&self) -> u16 {
        (self.sense_out / ADC_VREF * ADC_COUNTS).clamp(0.0, ADC_COUNTS - 1.0) as u16
    }

    /// Encoder count (wraps like the FPGA's 32-bit counter).
    pub fn count(&self) -> u32 {
        self.count as u32
    }

    /// 40 MHz timestamp of the last encoder edge (wraps at 32 bits).
    pub fn edge_timestamp(&self) -> u32 {
        ((self.edge_time * TIMESTAMP_HZ) as u64) as u32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn electrical_time_constant_and_stall_current() {
        let mut d = Re30Drive::new(Re30Params {
            locked: true,
            overcurrent: 1e9,
            ..Re30Params::maxon_310007()
        });
        d.bridge = BridgeCommand {
            duty_a: 0.55,
            duty_b: 0.45,
            enabled: true,
        };
        let tau: f64 = 0.119e-3 / 0.611;
        let h = 1e-6;
        let n = (tau / h).round() as usize;
        for _ in 0..n {
            d.step(h, 24.0);
        }
        let ifinal = 2.4 / 0.611;
        assert!((d.current / ifinal - (1.0 - (-1.0f64).exp())).abs() < 0.01);
        for _ in 0..20 * n {
            d.step(h, 24.0);
        }
        assert!((d.current - ifinal).abs() < 1e-3);
        // Sense: 20 × 10 mΩ = 0.2 V/A above the offset.
        let v = d.sense_out - d.params.sense_offset;
        assert!((v - 0.2 * ifinal).abs() < 1e-3);
    }

    #[test]
    fn no_load_speed_from_the_catalogue() {
        let mut d = Re30Drive::new(Re30Params {
            overcurrent: 1e9,
            ..Re30Params::maxon_310007()
        });
        d.bridge = BridgeCommand {
            duty_a: 1.0,
            duty_b: 0.0,
            enabled: true,
        };
        for _ in 0..400_000 {
            d.step(2.5e-6, 24.0);
        }
        let rpm = d.speed * 60.0 / (2.0 * PI);
        assert!((rpm - 8830.0).abs() < 100.0, "{rpm}");
        assert!((d.current - 0.113).abs() < 0.03, "{}", d.current);
        assert!(d.count() > 0 && d.edge_timestamp() > 0);
    }

    #[test]
    fn braking_returns_energy_to_the_line_and_the_supply_does_not_take_it() {
        // A spinning free rotor braked at -5 A through a bridge at the duty that holds it:
        // the bridge current is negative (regenerating) and charges the line above the
        // supply; motor power u·i equals line power V·I each step.
        let mut d = Re30Drive::new(Re30Params::maxon_310007());
        d.speed = 400.0;
        d.current = -5.0;
        let emf = d.params.torque_constant * d.speed;
        let u = emf - 5.0 * d.params.resistance;
        let duty = u / 24.0;
        d.bridge = BridgeCommand {
            duty_a: 0.5 + duty / 2.0,
            duty_b: 0.5 - duty / 2.0,
            enabled: true,
        };
        let mut line = Line::new(LineParams::tue_es030(), 24.0);
        for _ in 0..100 {
            d.step(1e-6, line.voltage);
            line.step(1e-6, 24.0, d.bus_current);
        }
        assert!(d.bus_current < -1.0, "{}", d.bus_current);
        assert!(line.voltage > 24.0 && line.peak == line.voltage);
        // With the bridge braking at 50/50 nothing reaches the line: the own draw brings it
        // back to the supply, and the supply holds it there.
        d.bridge = BridgeCommand::default();
        for _ in 0..200_000 {
            d.step(1e-6, line.voltage);
            line.step(1e-6, 24.0, d.bus_current);
        }
        assert_eq!(d.bus_current, 0.0);
        assert_eq!(line.voltage, 24.0);
    }

    #[test]
    fn tristate_current_decays_to_zero() {
        let mut d = Re30Drive::new(Re30Params::maxon_310007());
        d.current = 2.0;
        d.bridge.enabled = false;
        for _ in 0..100 {
            d.step(1e-6, 24.0);
        }
        assert_eq!(d.current, 0.0);
    }
}
