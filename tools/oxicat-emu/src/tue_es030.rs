//! The TUeES030 motor board on the pins of its board image (`firmware/tue-es030`): the host
//! rig's three motor channels (`oxicat_plant::re30::Re30Drive`, configured by
//! [`TueConfig`] as `tue_es030::rig` does) as a [`BoardPlant`].
//!
//! | image side | pins / registers | plant side |
//! |---|---|---|
//! | M1 bridge | TIM1 CH1 (PA8) phase A, CH2 (PA9) phase B; enable PC10 | `BridgeCommand { duty_a, duty_b, enabled }` of drive 0: the motor sees `(d_a − d_b) · V_supply` |
//! | M2 bridge | TIM1 CH3 (PE13), CH4 (PE14); enable PC11 | drive 1 |
//! | M3 bridge | TIM8 CH3 (PC8), CH4 (PC9); enable PC12 | drive 2 |
//! | encoders | TIM2 (PA0/PA1), TIM3 (PC6/PC7), TIM4 (PD12/PD13), encoder mode ×4 | the drive's quadrature count (`4 · lines` per turn) |
//! | currents | ADC1 IN10 (PC0), IN11 (PC1), IN12 (PC2) | the LT1999 output after its RC filter (`Re30Drive::sense_out`), the voltage the host's ADC2 reads |
//! | line voltage | ADC1 IN13 (PC3) | `V_supply / 11` (the board's divider, `control::LINE_DIVIDER`) |
//! | 5 V reference | ADC1 IN14 (PC4), a regular conversion per tick | [`RAIL_5V`] / 2 (the board's divider, `control::VREF5_DIVIDER`), the host rig's `rail_5v` |
//! | driver lines | PB12 M1 FAULT#, PB13 M1 OTW#, PB14 M2/M3 FAULT#, PB15 M2/M3 OTW# (active low) | `Re30Drive::fault` / `otw` |
//!
//! A channel whose PWM is not an enabled output (timer stopped, MOE off) or whose enable
//! pin is low is tristate, as the DRV8412 with its inputs floating or reset low.
//!
//! Every plant period (6.25 µs: half an 80 kHz PWM period, eight per current-loop tick) the
//! adapter reads the outputs, advances the drives in [`TueConfig::substeps`] / 8 exact steps
//! each (the host rig's step, 1.5625 µs with the default 32) and schedules at the period's
//! end the encoder counts, the sense voltages, the line voltage and the driver lines. ADC1
//! samples at its trigger what the last step set (a sample-and-hold up to 6.25 µs old; the
//! host's ADC2 reads the filter output at the tick itself).

use std::f64::consts::TAU;
use std::sync::{Arc, Mutex};

use oxicat_devices::tue_es030::control::{LINE_DIVIDER, VREF5_DIVIDER};
pub use oxicat_devices::tue_es030::rig::TueConfig;
use oxicat_plant::re30::{BridgeCommand, Re30Drive};

use crate::plant::BoardPlant;
use crate::{Board, Stimulus};

/// The board's 5 V rail \[V\] (the host rig's `BenchBoard::rail_5v`).
pub const RAIL_5V: f64 = 5.0;

/// Plant period \[ns\]: half an 80 kHz PWM period.
pub const PERIOD_NS: u64 = 6_250;

/// The board's pins (README of `firmware/tue-es030`, "Pin map").
pub mod pins {
    /// Bridge timer and channels (phase A, phase B) of M1..M3.
    pub const BRIDGE: [(u8, u8, u8); 3] = [(1, 1, 2), (1, 3, 4), (8, 3, 4)];
    /// DRV8412 enable of M1..M3 (output, high = enabled).
    pub const ENABLE: [(char, u8); 3] = [('C', 10), ('C', 11), ('C', 12)];
    /// Encoder timers of M1..M3.
    pub const ENCODER: [u8; 3] = [2, 3, 4];
    /// ADC1 channels of the current-sense outputs of M1..M3 (PC0..PC2).
    pub const CURRENT: [u8; 3] = [10, 11, 12];
    /// ADC1 channel of the line-voltage divider (PC3).
    pub const LINE: u8 = 13;
    /// ADC1 channel of the 5 V reference's divider (PC4).
    pub const VREF5: u8 = 14;
    /// M1 FAULT#, M1 OTW#, M2/M3 FAULT#, M2/M3 OTW# (inputs, active low).
    pub const DRIVER: [(char, u8); 4] = [('B', 12), ('B', 13), ('B', 14), ('B', 15)];
}

/// What the motors do, for tests and tools ([`TueBoardPlant::observer`]).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TueState {
    /// Plant steps so far.
    pub steps: u64,
    /// Board time at the end of the last step \[ns\].
    pub t_ns: u64,
    /// Winding currents of M1..M3 \[A\].
    pub current: [f64; 3],
    /// Rotor speeds \[rad/s\].
    pub speed: [f64; 3],
    /// Rotor angles \[rad\].
    pub angle: [f64; 3],
    /// Bridge voltages applied in the last step \[V\].
    pub voltage: [f64; 3],
    /// Steps with each channel's driver enabled.
    pub enabled_steps: [u64; 3],
}

/// The three motor channels on the board's pins (module docs).
pub struct TueBoardPlant {
    drives: [Re30Drive; 3],
    supply: f64,
    substeps: u32,
    state: Arc<Mutex<TueState>>,
}

impl TueBoardPlant {
    /// The host rig's bench `config` (motors, supply, plant step) on the image's pins.
    pub fn new(config: &TueConfig) -> Self {
        TueBoardPlant {
            drives: config.motors.map(Re30Drive::new),
            supply: config.supply,
            substeps: (config.substeps / 8).max(1),
            state: Arc::default(),
        }
    }

    /// A shared view of the motors, updated every plant step.
    pub fn observer(&self) -> Arc<Mutex<TueState>> {
        self.state.clone()
    }

    /// The drives.
    pub fn drives(&self) -> &[Re30Drive; 3] {
        &self.drives
    }

    /// What bridge `k` is commanded to by the image's pins.
    fn bridge(board: &Board, k: usize) -> BridgeCommand {
        let (tim, a, b) = pins::BRIDGE[k];
        let (port, pin) = pins::ENABLE[k];
        let duty = |ch| board.pwm_duty(tim, ch).filter(|d| d.is_finite());
        match (duty(a), duty(b)) {
            (Some(da), Some(db)) if board.output(port, pin) => BridgeCommand {
                duty_a: da.clamp(0.0, 1.0),
                duty_b: db.clamp(0.0, 1.0),
                enabled: true,
            },
            _ => BridgeCommand {
                duty_a: 0.5,
                duty_b: 0.5,
                enabled: false,
            },
        }
    }

    /// The sensors at `at_ns`: encoder counts, sense and line voltages, driver lines.
    fn sensors(&self, board: &mut Board, at_ns: u64) {
        for (k, d) in self.drives.iter().enumerate() {
            let lines = f64::from(d.params.encoder_lines);
            let edges = (d.angle * 4.0 * lines / TAU).floor() as i64;
            board.schedule(
                at_ns,
                Stimulus::Encoder {
                    tim: pins::ENCODER[k],
                    edges,
                },
            );
            board.schedule(
                at_ns,
                Stimulus::Analog {
                    channel: pins::CURRENT[k],
                    volts: d.sense_out,
                },
            );
        }
        board.schedule(
            at_ns,
            Stimulus::Analog {
                channel: pins::LINE,
                volts: self.supply / f64::from(LINE_DIVIDER),
            },
        );
        board.schedule(
            at_ns,
            Stimulus::Analog {
                channel: pins::VREF5,
                volts: RAIL_5V / f64::from(VREF5_DIVIDER),
            },
        );
        let d = &self.drives;
        let active = [
            d[0].fault,
            d[0].otw,
            d[1].fault || d[2].fault,
            d[1].otw || d[2].otw,
        ];
        for (&(port, pin), on) in pins::DRIVER.iter().zip(active) {
            board.schedule(
                at_ns,
                Stimulus::Input {
                    port,
                    pin,
                    level: !on,
                },
            );
        }
    }
}

impl BoardPlant for TueBoardPlant {
    fn period_ns(&self) -> u64 {
        PERIOD_NS
    }

    fn step(&mut self, board: &mut Board, t_ns: u64) {
        if t_ns == 0 {
            self.sensors(board, 0);
        }
        let mut voltage = [0.0; 3];
        let mut enabled = [false; 3];
        for k in 0..3 {
            let cmd = Self::bridge(board, k);
            enabled[k] = cmd.enabled;
            self.drives[k].bridge = cmd;
            voltage[k] = self.drives[k].bridge_voltage(self.supply);
        }
        let n = self.substeps;
        let h = PERIOD_NS as f64 * 1e-9 / f64::from(n);
        for _ in 0..n {
            for d in &mut self.drives {
                d.step(h, self.supply);
            }
        }
        let end = t_ns + PERIOD_NS;
        self.sensors(board, end);
        if let Ok(mut s) = self.state.lock() {
            s.steps += 1;
            s.t_ns = end;
            for (k, d) in self.drives.iter().enumerate() {
                s.current[k] = d.current;
                s.speed[k] = d.speed;
                s.angle[k] = d.angle;
                s.voltage[k] = voltage[k];
                s.enabled_steps[k] += u64::from(enabled[k]);
            }
        }
    }
}
