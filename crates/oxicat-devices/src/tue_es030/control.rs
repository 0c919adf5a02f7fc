//! The firmware's integer arithmetic, the 20 kHz current loop `currentPI` (Listing 4.7),
//! the 1 kHz encoder calculations (Listing 4.9) and `param2int`, in the manual's units:
//! currents in 1 mA, voltages in 10 mV, gains in q8 (`Q8f` = 256).
//!
//! Constants the manual names but does not give a value for are chosen here, once, and
//! said so (PWMPER, MAXVOLTAGE, MAXCONTROL, KILLVOLTAGE, LINEVOLTAGELIMIT, R2IGAIN,
//! R2U_FP, VELTIMELIMIT).

/// q8 fixed-point one (`Q8f`).
pub const Q8F: i32 = 256;
/// FPGA main clock, the encoder timestamp clock (`CPU_CLK`) \[Hz\].
pub const CPU_CLK_HZ: u32 = 40_000_000;
/// PWM carrier \[Hz\] (manual §2.10).
pub const PWM_HZ: u32 = 80_000;
/// Top of the PWM2ph3 up/down counter (`PWMPER`): 40 MHz / (2 · 80 kHz) = 250
/// (derived; the manual gives no value).
pub const PWMPER: i16 = 250;
/// Current-loop rate (`i_handler_pwm`) \[Hz\].
pub const CURRENT_LOOP_HZ: u32 = 20_000;
/// Service rate (`i_handler_ec`) \[Hz\].
pub const SERVICE_HZ: u32 = 1_000;
/// Current-loop sample time \[s\].
pub const TS: f32 = 1.0 / CURRENT_LOOP_HZ as f32;
/// Clip of the PI output and of the voltage feed-forward `ff` (`MAXVOLTAGE`), 10 mV:
/// 24 V, the board supply (chosen; not given).
pub const MAXVOLTAGE: i32 = 2400;
/// Clip of the PWM value (`MAXCONTROL`): 240 of ±250, so the DRV8412's bootstrap
/// capacitors are refreshed every period (chosen; not given).
pub const MAXCONTROL: i32 = 240;
/// Minimum line voltage in the u→pwm conversion (`LINEVOLTAGELIMIT`): 10 V (manual §4.8).
pub const LINEVOLTAGELIMIT: i32 = 1000;
/// ADC full scale \[V\] (manual §2.5: 0–3.3 V, 12 bits).
pub const ADC_VREF: f32 = 3.3;
/// ADC counts.
pub const ADC_COUNTS: f32 = 4096.0;
/// Line-voltage divider ratio onto ADC2_CH2: 1/11 (chosen: 24 V → 2.18 V, full scale 36.3 V).
pub const LINE_DIVIDER: f32 = 11.0;
/// ADC2_CH2 counts → 10 mV, q8 (`R2U_FP`): 3.3 · 11 / 4096 / 0.01 · 256 = 227.
pub const R2U_FP: i16 = 227;
/// Over-voltage kill threshold on the raw ADC2_CH2 counts (`KILLVOLTAGE`): 30 V
/// (chosen: above the 24 V supply, below the DRV8412's 52 V and the 36.3 V ADC range).
pub const KILLVOLTAGE: u16 = (30.0 / (ADC_VREF * LINE_DIVIDER) * ADC_COUNTS) as u16;
/// 5 V reference divider onto its ADC2 channel: 1/2 (chosen: 2.5 V, inside the 3.3 V
/// range; the manual names the check, not the channel or the divider).
pub const VREF5_DIVIDER: f32 = 2.0;

/// ADC2 counts of the 5 V reference → 10 mV: `raw · 3.3 · 2 / 4096 / 0.01 = raw · 165/1024`.
pub fn vref5_10mv(raw: u16) -> u16 {
    (raw as u32 * 165 / 1024) as u16
}

/// ADC2_CH2 counts → line voltage in 10 mV (`q8mul(ADC2_CH2, R2U_FP)`), 0 and up.
pub fn line_10mv(raw: u16) -> u16 {
    q8mul(raw as i32, R2U_FP as i32).max(0) as u16
}

/// LT1999 gain (manual §2.10).
pub const LT1999_GAIN: f32 = 20.0;
/// Sense resistor of M2/M3 after the board change (manual §2.10: 10 mΩ) \[Ω\].
pub const RSENSE_M23: f32 = 0.010;
/// Effective sense resistance of M1 \[Ω\]: the manual gives 33 A for M1 against 16.5 A
/// for M2/M3, i.e. half the resistance (two 10 mΩ legs of the parallel-mode driver).
pub const RSENSE_M1: f32 = 0.005;
/// mA per ADC count for M2/M3, q8 (`R2IGAIN·Q8f`): 3.3/4096/(20·0.01 Ω)·1000 = 4.028 mA.
pub const R2IGAIN_Q8: i16 = 1031;
/// mA per ADC count for M1, q8 (`R2IGAINCH1·Q8f`): 8.057 mA.
pub const R2IGAINCH1_Q8: i16 = 2063;
/// Below this many 40 MHz ticks between encoder captures the velocity is 0
/// (`VELTIMELIMIT`; chosen: 100 µs).
pub const VELTIMELIMIT: u32 = 4_000;

/// `q8mul`: 16-bit × q8 → 16-bit (saturating instead of wrapping).
pub fn q8mul(a: i32, b: i32) -> i16 {
    sat16((a * b) >> 8)
}

/// `q8mul32`: the same product, 32-bit result.
pub fn q8mul32(a: i32, b: i32) -> i32 {
    ((a as i64 * b as i64) >> 8).clamp(i32::MIN as i64, i32::MAX as i64) as i32
}

/// `clip32`: saturates; also says whether it clipped.
pub fn clip32(v: i32, lo: i32, hi: i32) -> (i32, bool) {
    if v < lo {
        (lo, true)
    } else if v > hi {
        (hi, true)
    } else {
        (v, false)
    }
}

fn sat16(v: i32) -> i16 {
    v.clamp(i16::MIN as i32, i16::MAX as i32) as i16
}

/// Rounds to the nearest integer (no `std`), saturating to `i32`.
pub fn round_i32(x: f32) -> i32 {
    let r = if x >= 0.0 { x + 0.5 } else { x - 0.5 };
    if r >= i32::MAX as f32 {
        i32::MAX
    } else if r <= i32::MIN as f32 {
        i32::MIN
    } else {
        r as i32
    }
}

/// One motor's parameters in SI (objects 0x8000–0x8002).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotorParams {
    /// Resistance \[Ω\] (resistance feed-forward).
    pub r: f32,
    /// KV \[V s/rad\] (back-EMF feed-forward).
    pub kv: f32,
    /// Current-loop P gain \[V/A\].
    pub pgain: f32,
    /// Current-loop I gain (see [`param2int`]).
    pub igain: f32,
    /// Integrator limit \[A s\].
    pub ilimit: f32,
    /// Encoder direction (−1 or 1).
    pub encdir: i8,
    /// Encoder lines per revolution (×4 quadrature edges).
    pub encres: u16,
    /// ADC counts at zero current.
    pub czero: i16,
}

impl MotorParams {
    /// The manual's defaults.
    pub const DEFAULT: Self = {
        use super::device::defaults::*;
        Self {
            r: R,
            kv: KV,
            pgain: P,
            igain: I,
            ilimit: ILIMIT,
            encdir: ENCDIR,
            encres: ENCRES,
            czero: CZERO,
        }
    };
}

/// The parameters in the firmware's internal units (`param2int`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct IntParams {
    /// q8, mA → 10 mV.
    pub pgain: i32,
    /// q8 gain on `integral >> 6`.
    pub igain: i32,
    /// Integrator clamp, mA·samples.
    pub ilimit: i32,
    /// Resistance feed-forward, q8, mA → 10 mV.
    pub rm2u: i32,
    /// Back-EMF feed-forward, q8, 0.1 rad/s → 10 mV.
    pub kv: i32,
    /// Encoder direction.
    pub encdir: i32,
    /// Quadrature edges per revolution.
    pub increments: i32,
    /// ADC zero.
    pub czero: i32,
}

/// Which current scaling the firmware's PI gains are converted with: the manual's P = 6
/// loop (≈ 2.5 kHz, ≈ 60°) is only reproduced with a loop gain ≈ 4.2× below the literal
/// V/A, the ratio of the sense-resistor change of §2.10 (42 mΩ → 10 mΩ). The manual shows
/// neither `param2int` nor `R2IGAIN`, so both readings are offered and the user chooses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum BoardRev {
    /// The PI gains in V/A as the dictionary labels them, on the 10 mΩ board
    /// (`pgain = 25.6 P`).
    Literal,
    /// The hypothesis that reproduces the manual's FRF (the default): `param2int`
    /// converts P and I with the original board's 42 mΩ current scale while the current
    /// itself is read with the 10 mΩ one, so the loop sees P/4.2 and I/4.2. The
    /// feed-forwards (R, KV) act on the setpoint and the velocity and are not affected.
    #[default]
    Sense42,
}

impl BoardRev {
    /// The factor on the PI gains: 1 ([`BoardRev::Literal`]) or 10 mΩ / 42 mΩ.
    pub const fn pi_scale(self) -> f32 {
        match self {
            BoardRev::Literal => 1.0,
            BoardRev::Sense42 => RSENSE_M23 / RSENSE_ORIGINAL,
        }
    }
}

/// Sense resistor of the original board (manual §2.10: `3.3/(20·42·10⁻³) ≈ 4 A`) \[Ω\].
pub const RSENSE_ORIGINAL: f32 = 0.042;

/// [`param2int`] with the PI gains scaled for the board revision `rev`.
pub fn param2int_rev(p: &MotorParams, rev: BoardRev) -> IntParams {
    let k = rev.pi_scale();
    let mut i = param2int(p);
    i.pgain = round_i32(p.pgain * 25.6 * k);
    i.igain = round_i32(p.igain * Q8F as f32 * k);
    i
}

/// `param2int` (not listed in the manual; our reconstruction):
///
/// - P \[V/A\] → q8 mA→10 mV: `P · (1 mA / 10 mV) · 256 = 25.6 P`;
/// - R \[Ω\] and KV \[V s/rad\] likewise: `rm2u = 25.6 R`, `kv = 256 · KV · 10`
///   (0.1 rad/s · V s/rad = 0.1 V = 10 · 10 mV);
/// - I: the OD says V/As, but the code applies it as `q8mul32(integral >> 6, igain)` to a
///   sum of mA errors at 20 kHz, where a physical 4 V/As would round to 0 (it is 0.08 q8);
///   the manual's step responses change with I, so I is taken as the q8 gain itself:
///   `igain = 256 I`, i.e. Ki = I · 10 mV/mA / (64 · 50 µs) = 3125 · I V/(A s);
/// - i limit \[A s\] → the integrator's unit (mA · 50 µs): `ilimit · 2·10⁷`;
/// - encoder increments = 4 × lines (quadrature).
pub fn param2int(p: &MotorParams) -> IntParams {
    let sat = |x: f32| round_i32(x);
    IntParams {
        pgain: sat(p.pgain * 25.6),
        igain: sat(p.igain * Q8F as f32),
        ilimit: sat(p.ilimit * 1000.0 * CURRENT_LOOP_HZ as f32).max(0),
        rm2u: sat(p.r * 25.6),
        kv: sat(p.kv * 2560.0),
        encdir: if p.encdir < 0 { -1 } else { 1 },
        increments: 4 * (p.encres.max(1) as i32),
        czero: p.czero as i32,
    }
}

/// One motor channel's firmware state (the manual's `motor_t`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Motor {
    /// Current setpoint \[mA\].
    pub current_setpoint: i16,
    /// Measured current \[mA\].
    pub current: i16,
    /// Voltage feed-forward from the master \[10 mV\].
    pub setpoint_ff: i16,
    /// Back-EMF feed-forward \[10 mV\] (1 kHz).
    pub backemf_ff: i16,
    /// Controlled (mcom enable).
    pub enabled: bool,
    /// Tristate (driver disabled) when not enabled.
    pub tristate: bool,
    /// PI integrator \[mA · samples\].
    pub cc_integral: i32,
    /// PI output \[10 mV\].
    pub cc_control: i16,
    /// PWM value (−MAXCONTROL..MAXCONTROL; PWMPER = full line voltage).
    pub cc_pwm: i16,
    /// The last PWM value was clipped: the integrator is frozen.
    pub cc_isclipped: bool,
    /// Parameters in internal units.
    pub par: IntParams,
    /// Encoder count (latched).
    pub position: u32,
    /// Encoder capture time (latched, 40 MHz ticks).
    pub poscaptime: u32,
    /// Previous count.
    pub prev_position: u32,
    /// Previous capture time.
    pub prev_poscaptime: u32,
    /// Velocity \[0.1 rad/s\].
    pub velocity: i16,
}

impl Motor {
    /// `currentPI` (Listing 4.7) with the line-voltage factor `u2pwm` (q8).
    pub fn current_pi(&mut self, u2pwm: i32) {
        let err = self.current_setpoint as i32 - self.current as i32;
        if !self.cc_isclipped {
            self.cc_integral = clip32(
                self.cc_integral.saturating_add(err),
                -self.par.ilimit,
                self.par.ilimit,
            )
            .0;
        }
        let u = q8mul32(err, self.par.pgain)
            .saturating_add(q8mul32(self.cc_integral >> 6, self.par.igain));
        self.cc_control = clip32(u, -MAXVOLTAGE, MAXVOLTAGE).0 as i16;
        let v = self.cc_control as i32
            + self.backemf_ff as i32
            + self.setpoint_ff as i32
            + q8mul(self.current_setpoint as i32, self.par.rm2u) as i32;
        let (pwm, clipped) = clip32(q8mul(v, u2pwm) as i32, -MAXCONTROL, MAXCONTROL);
        self.cc_pwm = pwm as i16;
        self.cc_isclipped = clipped;
    }

    /// `encoder_calculations` (Listing 4.9): velocity in 0.1 rad/s from the counts and
    /// capture times latched together, then the back-EMF feed-forward.
    pub fn encoder_calculations(&mut self) {
        let delta_pos =
            self.position.wrapping_sub(self.prev_position) as i32 as i64 * self.par.encdir as i64;
        let delta_time = self.poscaptime.wrapping_sub(self.prev_poscaptime);
        self.prev_position = self.position;
        self.prev_poscaptime = self.poscaptime;
        if delta_time > VELTIMELIMIT {
            // part = CPU_CLK · 2π / increments (as the firmware, an integer).
            let part = (CPU_CLK_HZ as f32 * 2.0 * core::f32::consts::PI
                / self.par.increments.max(1) as f32) as i64;
            let v = delta_pos * part * 10 / delta_time as i64;
            self.velocity = v.clamp(i16::MIN as i64, i16::MAX as i64) as i16;
        } else {
            // No new edge latched since the last service tick.
            self.velocity = 0;
        }
        self.backemf_ff = q8mul(self.velocity as i32, self.par.kv);
    }

    /// Not controlled: integrator and PWM to 0 (braking at 50/50, or tristate).
    pub fn idle(&mut self) {
        self.cc_integral = 0;
        self.cc_pwm = 0;
        self.cc_isclipped = false;
    }
}

/// `u2pwm = Q8f · PWMPER / max(linevoltage, LINEVOLTAGELIMIT)` (q8; line voltage in 10 mV).
pub fn u2pwm(linevoltage_10mv: i32) -> i32 {
    Q8F * PWMPER as i32 / linevoltage_10mv.max(LINEVOLTAGELIMIT)
}

/// Comparator values of the two phases for a PWM value, centred at 50/50 (PWM2ph3):
/// phase A at `(PWMPER + pwm + 1) / 2`, phase B at `A − pwm`; the bridge sees
/// `(A − B) / PWMPER = pwm / PWMPER` of the line voltage, every PWM count (B at
/// `PWMPER − A` would drop the odd counts: half the resolution).
pub fn phases(pwm: i16) -> (u16, u16) {
    let top = PWMPER as i32;
    let p = (pwm as i32).clamp(-top, top);
    let a = ((top + p + 1) / 2).clamp(0, top);
    (a as u16, (a - p).clamp(0, top) as u16)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn param2int_of_the_defaults() {
        let p = param2int(&MotorParams::DEFAULT);
        assert_eq!(p.pgain, 51);
        assert_eq!(p.igain, 512);
        assert_eq!(p.rm2u, 16);
        assert_eq!(p.kv, 77);
        assert_eq!(p.increments, 4096);
        assert_eq!(p.ilimit, 4_000_000);
    }

    #[test]
    fn board_revision_scales_only_the_pi_gains() {
        let p = MotorParams {
            pgain: 6.0,
            igain: 4.0,
            ..MotorParams::DEFAULT
        };
        let lit = param2int_rev(&p, BoardRev::Literal);
        assert_eq!(lit, param2int(&p));
        let s42 = param2int_rev(&p, BoardRev::Sense42);
        assert_eq!(lit.pgain, 154);
        assert_eq!(s42.pgain, 37, "25.6 * 6 / 4.2");
        assert_eq!(s42.igain, 244, "256 * 4 / 4.2");
        assert_eq!(
            (s42.rm2u, s42.kv, s42.ilimit),
            (lit.rm2u, lit.kv, lit.ilimit)
        );
    }

    #[test]
    fn pi_freezes_integrator_while_clipped() {
        let mut m = Motor {
            par: param2int(&MotorParams::DEFAULT),
            current_setpoint: 30000,
            ..Motor::default()
        };
        let k = u2pwm(2400);
        m.current_pi(k);
        assert!(m.cc_isclipped);
        assert_eq!(m.cc_pwm as i32, MAXCONTROL);
        let i1 = m.cc_integral;
        m.current_pi(k);
        assert_eq!(m.cc_integral, i1, "frozen while the PWM is clipped");
        // Small error: not clipped, integrates.
        m.current_setpoint = 10;
        m.current_pi(k);
        m.current_pi(k);
        assert!(m.cc_integral > i1);
    }

    #[test]
    fn integrator_clamp() {
        let mut m = Motor {
            par: IntParams {
                ilimit: 100,
                ..param2int(&MotorParams::DEFAULT)
            },
            current_setpoint: 50,
            ..Motor::default()
        };
        for _ in 0..10 {
            m.current_pi(u2pwm(2400));
        }
        assert_eq!(m.cc_integral, 100);
    }

    #[test]
    fn centred_phases() {
        assert_eq!(phases(0), (125, 125));
        let (a, b) = phases(124);
        assert_eq!(a as i32 - b as i32, 124);
        assert_eq!(phases(i16::MAX), (250, 0));
        assert_eq!(phases(i16::MIN), (0, 250));
        for pwm in -240..=240i16 {
            let (a, b) = phases(pwm);
            assert_eq!(
                a as i32 - b as i32,
                pwm as i32,
                "every count reaches the bridge"
            );
            assert!((a as i32 + b as i32 - 250).abs() <= 1, "centred");
        }
    }

    #[test]
    fn velocity_in_0_1_rad_s() {
        let mut m = Motor {
            par: param2int(&MotorParams::DEFAULT),
            ..Motor::default()
        };
        // 4096 edges per rev; 4096 edges in 1 ms = 1000 rev/s... use 41 edges in 1 ms:
        // 41/4096 rev per ms = 62.9 rad/s → 629.
        m.position = 41;
        m.poscaptime = 40_000;
        m.encoder_calculations();
        assert!((m.velocity - 629).abs() <= 1, "{}", m.velocity);
    }
}
