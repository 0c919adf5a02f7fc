//! The joint drive's hardware, split by priority: the power stage ([`Bridge`], the drive's
//! `PowerStage`: TIM1 three-phase centre-aligned PWM, ADC1 injected conversions of the
//! phase currents and bus voltage at the PWM centre, bridge enable), used by the current
//! loop in the ADC interrupt; the sensors ([`Sensors`], the drive's `JointHw`: TIM2 encoder
//! with a hardware index latch, home switch, the joint torque conversion), used by the
//! drive's cycle at the ESC priority. And the RUN/ERR LEDs.
//!
//! Register set-up is done here with the PAC, not the HAL's PWM/ADC drivers: the HAL has
//! no centre-aligned PWM with an ADC trigger, and naming every register written keeps the
//! image's peripheral use explicit (README, "Peripherals and registers").

use crate::foc::{self, ElecAngle};
use oxicat_devices::cia402::{JointHw, NoPowerStage, PowerStage};
use stm32f4xx_hal::{
    gpio::{Input, Output, Pin},
    pac,
    rcc::{Enable, Reset},
};

/// PWM frequency (= current-loop rate, `cia402::CURRENT_LOOP_HZ`).
pub const PWM_HZ: u32 = oxicat_devices::cia402::CURRENT_LOOP_HZ;
/// Largest high-side duty. At the PWM centre all three low sides must be on long enough
/// for the shunt amplifiers to settle and for the two current samples (≈ ±0.95 µs around
/// the centre, [`ADC_LEAD_TICKS`]): (1 − 0.9) · 50 µs = 5 µs of low-side time.
pub const MAX_DUTY: f32 = 0.9;
/// TIM1 ticks (180 MHz) by which the ADC trigger leads the counter's top, so that the
/// centre of the two phase-current sample windows (a: 0 … 0.67 µs, b: 1.2 … 1.87 µs after
/// the trigger at ADCCLK 22.5 MHz, 15-cycle sampling) falls on the PWM centre: 0.93 µs.
pub const ADC_LEAD_TICKS: u32 = 168;

// ---- Board assumptions: analogue front end (named, so a real board changes them here) ----

/// ADC reference (VDDA = VREF+) \[V\].
pub const VREF: f32 = 3.3;
/// ADC full scale (12 bits).
pub const ADC_FULL: f32 = 4096.0;
/// Phase shunt resistance \[Ω\] (low-side shunts in phases a and b).
pub const R_SHUNT: f32 = 0.002;
/// Current-sense amplifier gain \[V/V\]; its output is `VREF/2 + G · R_SHUNT · i`, with `i`
/// positive into the motor: ±41 A over the ADC range.
pub const CSA_GAIN: f32 = 20.0;
/// Phase current per ADC count \[A\].
pub const AMPS_PER_COUNT: f32 = VREF / ADC_FULL / (R_SHUNT * CSA_GAIN);
/// Bus-voltage divider ratio (V_bus / V_pin): 69.3 V full scale.
pub const VBUS_DIVIDER: f32 = 21.0;
/// Below this measured bus voltage the nominal one (`DriveParams::bus_voltage`) is used for
/// the duty scaling (no bus yet, or the divider not fitted) \[V\].
pub const VBUS_MIN: f32 = 8.0;
/// Joint torque sensor amplifier: output at zero torque \[V\].
pub const TORQUE_ZERO_V: f32 = 1.65;
/// Joint torque sensor amplifier: torque per volt from [`TORQUE_ZERO_V`] \[N·m/V\]
/// (±100 N·m over ±1.65 V).
pub const TORQUE_NM_PER_V: f32 = 100.0 / 1.65;
/// Home switch: active low (a switch or opto output to ground, internal pull-up).
pub const HOME_ACTIVE_LOW: bool = true;

/// Zero-current calibration: conversions averaged at start-up with the bridge off.
const CAL_SAMPLES: u32 = 256;
/// Start-up alignment: d-axis voltage \[V\] (≈ 2 A in a 0.5 Ω winding), ramp and hold \[ms\].
pub const ALIGN_VOLTS: f32 = 1.0;
const ALIGN_RAMP_MS: u32 = 200;
const ALIGN_HOLD_MS: u32 = 300;

/// ADC1 channels of the injected sequence (JSQ1..JSQ4 → JDR1..JDR4).
pub mod ch {
    /// Phase a current, PC0 = ADC123_IN10.
    pub const IA: u8 = 10;
    /// Phase b current, PC1 = ADC123_IN11.
    pub const IB: u8 = 11;
    /// Joint torque sensor, PC2 = ADC123_IN12.
    pub const TORQUE: u8 = 12;
    /// Bus voltage divider, PC3 = ADC123_IN13.
    pub const VBUS: u8 = 13;
}

/// TIM2's counter: the encoder count. Read by both sides — the bridge for the electrical
/// angle, the sensors for the position — as a read of CNT has no side effect; every other
/// TIM2 register is the sensors'.
fn encoder_count() -> u32 {
    // SAFETY: a read of CNT, which changes nothing (TIM2 is set up before either side
    // exists).
    unsafe { (*pac::TIM2::ptr()).cnt().read().bits() }
}

/// The power stage: TIM1's PWM, the bridge enable and ADC1 (phase currents, bus voltage).
/// Owned by the current loop (the `ADC` interrupt) once running.
pub struct Bridge {
    tim1: pac::TIM1,
    adc: pac::ADC1,
    enable: Pin<'C', 11, Output>,
    /// TIM1 auto-reload: duty 1.0 = `arr`.
    arr: u32,
    angle: ElecAngle,
    /// sin/cos of the electrical angle sampled with the last currents: the modulation uses
    /// the angle the current was measured at (one PWM period of delay, not compensated).
    sc: (f32, f32),
    /// Zero-current ADC readings of phases a and b (counts).
    zero: (f32, f32),
    /// Bus voltage for the duty scaling \[V\].
    vbus: f32,
    motor: Motor,
    enabled: bool,
}

/// The sensors the drive's cycle reads: TIM2 (encoder, index capture), the home switch
/// and the joint torque conversion (ADC1 JDR3).
pub struct Sensors {
    tim2: pac::TIM2,
    home: Pin<'C', 10, Input>,
}

/// What the board needs from the drive's parameters.
#[derive(Debug, Clone, Copy)]
pub struct Motor {
    /// Encoder increments per motor revolution.
    pub counts_per_rev: u32,
    /// Pole pairs.
    pub pole_pairs: u32,
    /// Nominal bus voltage \[V\].
    pub bus_voltage: f32,
}

/// Sets up TIM1 (PWM running, outputs at 50 %, bridge disabled), TIM2 (encoder, index
/// capture) and ADC1 (injected sequence on TIM1's trigger, JEOC interrupt enabled in the
/// ADC; the NVIC line stays masked), and splits them into the power stage and the
/// sensors. `timclk2_hz`: TIM1's clock.
///
/// The pins must already be in their modes (main.rs): PA8/PA9/PB15 AF1, PA0/PA1/PB10
/// AF1, PC0..PC3 analog.
pub fn setup(
    tim1: pac::TIM1,
    tim2: pac::TIM2,
    adc: pac::ADC1,
    home: Pin<'C', 10, Input>,
    mut enable: Pin<'C', 11, Output>,
    timclk2_hz: u32,
    motor: Motor,
) -> (Bridge, Sensors) {
    enable.set_low();
    // SAFETY: the peripherals are owned (passed in by value); enabling and resetting
    // their clocks touches only their own RCC bits.
    unsafe {
        pac::TIM1::enable_unchecked();
        pac::TIM1::reset_unchecked();
        pac::TIM2::enable_unchecked();
        pac::TIM2::reset_unchecked();
        pac::ADC1::enable_unchecked();
        pac::ADC1::reset_unchecked();
    }
    let arr = timclk2_hz / (2 * PWM_HZ);
    setup_encoder(&tim2);
    setup_adc(&adc);
    setup_pwm(&tim1, arr);
    let bridge = Bridge {
        tim1,
        adc,
        enable,
        arr,
        angle: ElecAngle::new(encoder_count(), motor.counts_per_rev, motor.pole_pairs),
        sc: (0.0, 1.0),
        zero: (ADC_FULL / 2.0, ADC_FULL / 2.0),
        vbus: motor.bus_voltage,
        motor,
        enabled: false,
    };
    (bridge, Sensors { tim2, home })
}

impl Bridge {
    /// Waits for the next injected sequence (JEOC, polled; bounded) and clears the flag.
    fn wait_conversion(&mut self) -> bool {
        // One PWM period is 9,000 core cycles; a loop pass is > 10.
        for _ in 0..20_000 {
            if self.adc.sr().read().jeoc().bit_is_set() {
                self.adc.sr().write(|w| unsafe { w.bits(!(1 << 2)) });
                return true;
            }
        }
        false
    }

    /// Zero-current offsets of the two current channels (bridge off), and the bus voltage.
    /// Returns false (and keeps the nominal mid-scale offsets) if the ADC does not convert.
    pub fn calibrate(&mut self) -> bool {
        let (mut a, mut b) = (0u32, 0u32);
        for _ in 0..CAL_SAMPLES {
            if !self.wait_conversion() {
                return false;
            }
            a += self.adc.jdr1().read().bits() & 0xFFF;
            b += self.adc.jdr2().read().bits() & 0xFFF;
        }
        self.zero = (a as f32 / CAL_SAMPLES as f32, b as f32 / CAL_SAMPLES as f32);
        self.read_vbus();
        true
    }

    fn read_vbus(&mut self) {
        let v = (self.adc.jdr4().read().bits() & 0xFFF) as f32 * (VREF / ADC_FULL) * VBUS_DIVIDER;
        self.vbus = if v >= VBUS_MIN {
            v
        } else {
            self.motor.bus_voltage
        };
    }

    /// Start-up alignment: the encoder counter is relative, so the electrical angle is
    /// found by pulling the rotor onto phase a's axis with a d-axis voltage (ramped up, then
    /// held) and taking that count as electrical angle 0. The motor turns by up to half an
    /// electrical revolution (1/8 motor turn at 4 pole pairs; 1/800 at the joint). Leaves
    /// the bridge disabled.
    pub fn align(&mut self, delay: &mut impl embedded_hal::delay::DelayNs) {
        self.enabled = true;
        for ms in 0..ALIGN_RAMP_MS + ALIGN_HOLD_MS {
            let vd = ALIGN_VOLTS * (ms.min(ALIGN_RAMP_MS) as f32 / ALIGN_RAMP_MS as f32);
            // v_d along phase a (θ = 0): v_α = v_d, v_β = 0.
            let v = [vd, -0.5 * vd, -0.5 * vd];
            self.write_duties(foc::svpwm(v, self.vbus, MAX_DUTY));
            self.enable.set_high();
            delay.delay_ms(1);
        }
        self.disable();
        self.angle = ElecAngle::new(
            encoder_count(),
            self.motor.counts_per_rev,
            self.motor.pole_pairs,
        );
    }

    fn write_duties(&mut self, d: [f32; 3]) {
        let arr = self.arr as f32;
        let c = d.map(|x| ((x * arr + 0.5) as u32).min(self.arr));
        // Preloaded (OCxPE): the three take effect together at the next update event.
        self.tim1.ccr1().write(|w| unsafe { w.bits(c[0]) });
        self.tim1.ccr2().write(|w| unsafe { w.bits(c[1]) });
        self.tim1.ccr3().write(|w| unsafe { w.bits(c[2]) });
    }

    fn disable(&mut self) {
        self.enable.set_low();
        self.enabled = false;
        let mid = self.arr / 2;
        self.tim1.ccr1().write(|w| unsafe { w.bits(mid) });
        self.tim1.ccr2().write(|w| unsafe { w.bits(mid) });
        self.tim1.ccr3().write(|w| unsafe { w.bits(mid) });
    }

    /// Clears the injected end-of-conversion flag (the ADC interrupt's acknowledge).
    pub fn ack_conversion(&mut self) {
        // SR bits are rc_w0: writing 1 leaves the others unchanged.
        self.adc.sr().write(|w| unsafe { w.bits(!(1 << 2)) });
    }
}

impl PowerStage for Bridge {
    /// Called first in each current-loop tick (the ADC interrupt, right after the
    /// injected sequence): phase currents → Clarke/Park at the encoder's electrical angle.
    fn current(&mut self) -> f32 {
        let ra = (self.adc.jdr1().read().bits() & 0xFFF) as f32;
        let rb = (self.adc.jdr2().read().bits() & 0xFFF) as f32;
        self.read_vbus();
        let ia = (ra - self.zero.0) * AMPS_PER_COUNT;
        let ib = (rb - self.zero.1) * AMPS_PER_COUNT;
        let theta = self.angle.update(encoder_count());
        self.sc = foc::sin_cos(theta);
        foc::iq_from_phases(ia, ib, self.sc)
    }

    fn set_voltage(&mut self, enable: bool, volts: f32) {
        if !enable {
            if self.enabled || self.enable.is_set_high() {
                self.disable();
            }
            return;
        }
        let v = foc::phase_voltages(volts, self.sc);
        self.write_duties(foc::svpwm(v, self.vbus, MAX_DUTY));
        if !self.enabled {
            self.enabled = true;
            self.enable.set_high();
        }
    }
}

impl JointHw for Sensors {
    /// The current loop runs in the ADC interrupt with the [`Bridge`], not in the drive.
    type Power = NoPowerStage;

    fn encoder(&mut self) -> i32 {
        encoder_count() as i32
    }

    fn index_latch(&mut self) -> Option<i32> {
        let sr = self.tim2.sr().read();
        if !sr.cc3if().bit_is_set() {
            return None;
        }
        // Reading CCR3 clears CC3IF; a second index since the last call (CC3OF) only
        // means the newer count is the one kept.
        let v = self.tim2.ccr3().read().bits() as i32;
        if sr.cc3of().bit_is_set() {
            self.tim2.sr().write(|w| unsafe { w.bits(!(1 << 11)) });
        }
        Some(v)
    }

    fn home_switch(&mut self) -> bool {
        self.home.is_low() == HOME_ACTIVE_LOW
    }

    /// The torque channel of the last injected sequence.
    fn joint_torque(&mut self) -> f32 {
        // SAFETY: a read of JDR3, which changes nothing; ADC1 is the bridge's, which
        // never writes JDR3.
        let raw = unsafe { (*pac::ADC1::ptr()).jdr3().read().bits() };
        let v = (raw & 0xFFF) as f32 * (VREF / ADC_FULL);
        (v - TORQUE_ZERO_V) * TORQUE_NM_PER_V
    }

    fn power_stage(&mut self) -> Option<&mut NoPowerStage> {
        None
    }
}

/// TIM2: encoder mode 3 on TI1/TI2 (PA0/PA1, ×4 counting, 32 bits), channel 3 input
/// capture on TI3 (PB10, the index, rising edge) — the hardware latches CNT into CCR3.
fn setup_encoder(t: &pac::TIM2) {
    t.ccmr1_input().write(|w| {
        w.cc1s()
            .ti1()
            .ic1f()
            .fck_int_n8()
            .cc2s()
            .ti2()
            .ic2f()
            .fck_int_n8()
    });
    // IC3F = 0011: fCK_INT, N = 8, as IC1F/IC2F.
    t.ccmr2_input().write(|w| w.cc3s().ti3().ic3f().set(0b0011));
    // CC1E/CC2E: inputs enabled, non-inverted (CCxP = CCxNP = 0); CC3E: capture enabled,
    // rising edge.
    t.ccer()
        .write(|w| w.cc1e().set_bit().cc2e().set_bit().cc3e().set_bit());
    t.smcr().write(|w| w.sms().encoder_mode_3());
    t.arr().write(|w| unsafe { w.bits(u32::MAX) });
    t.egr().write(|w| w.ug().set_bit());
    t.sr().write(|w| unsafe { w.bits(0) });
    t.cr1().write(|w| w.cen().set_bit());
}

/// ADC1: ADCCLK = PCLK2 / 4 (22.5 MHz), 12 bits, scan, injected sequence IA, IB, TORQUE,
/// VBUS (JL = 3) on TIM1_TRGO rising edges, JEOC interrupt enabled.
fn setup_adc(adc: &pac::ADC1) {
    // SAFETY: ADC_CCR is shared by the three ADCs; only ADC1 is used by this image.
    let common = unsafe { &*pac::ADC_COMMON::ptr() };
    common.ccr().modify(|_, w| w.adcpre().div4());
    adc.cr1().write(|w| w.scan().set_bit().jeocie().set_bit());
    // 15 cycles for the amplifier outputs, 56 for the divider and the torque amplifier.
    adc.smpr1().write(|w| {
        w.smp10()
            .cycles15()
            .smp11()
            .cycles15()
            .smp12()
            .cycles56()
            .smp13()
            .cycles56()
    });
    adc.jsqr().write(|w| unsafe {
        w.jsq1()
            .bits(ch::IA)
            .jsq2()
            .bits(ch::IB)
            .jsq3()
            .bits(ch::TORQUE)
            .jsq4()
            .bits(ch::VBUS)
            .jl()
            .bits(3)
    });
    adc.cr2().write(|w| {
        w.adon()
            .set_bit()
            .jextsel()
            .tim1trgo()
            .jexten()
            .rising_edge()
    });
}

/// TIM1: centre-aligned mode 1, ARR = TIMCLK / (2 · 20 kHz), repetition counter 1 (one
/// update — compare preload transfer — per PWM period), PWM mode 1 with preload on CH1,
/// CH2, CH3, CH3 driven out on CH3N (CC3E = 0, CC3NE = 1: OC3N = OC3REF, not inverted,
/// since PA10 — CH3 — is the ESC's IRQ). CH4: PWM mode 2 at ARR − ADC_LEAD_TICKS,
/// OC4REF as TRGO (MMS = 111): it rises just before the top of the count, where all low
/// sides are on, and starts ADC1's injected sequence. No dead time: the gate driver
/// inserts it (3-PWM inputs). Main output enabled.
fn setup_pwm(t: &pac::TIM1, arr: u32) {
    t.cr1()
        .write(|w| w.cms().center_aligned1().arpe().enabled());
    t.psc().write(|w| unsafe { w.bits(0) });
    t.arr().write(|w| unsafe { w.bits(arr) });
    t.rcr().write(|w| unsafe { w.bits(1) });
    t.ccmr1_output().write(|w| {
        w.oc1m().pwm_mode1().oc1pe().enabled();
        w.oc2m().pwm_mode1().oc2pe().enabled()
    });
    t.ccmr2_output().write(|w| {
        w.oc3m().pwm_mode1().oc3pe().enabled();
        w.oc4m().pwm_mode2().oc4pe().enabled()
    });
    let mid = arr / 2;
    t.ccr1().write(|w| unsafe { w.bits(mid) });
    t.ccr2().write(|w| unsafe { w.bits(mid) });
    t.ccr3().write(|w| unsafe { w.bits(mid) });
    t.ccr4().write(|w| unsafe { w.bits(arr - ADC_LEAD_TICKS) });
    t.ccer()
        .write(|w| w.cc1e().set_bit().cc2e().set_bit().cc3ne().set_bit());
    t.cr2().write(|w| w.mms().compare_oc4());
    t.bdtr().write(|w| w.moe().set_bit());
    // UG loads PSC, ARR, RCR and the compares; RCR written before CEN puts the update
    // on the overflow (RM0390, repetition counter).
    t.egr().write(|w| w.ug().set_bit());
    t.sr().write(|w| unsafe { w.bits(0) });
    t.cr1().modify(|_, w| w.cen().set_bit());
}

/// Bridge off from any context (panic, fault): the enable line low (all half-bridges
/// Hi-Z, the motor coasts) and TIM1's main output disabled. AOE is cleared first, or the
/// next update event would set MOE again.
pub fn bridge_emergency_off() {
    // SAFETY: single register writes that only ever stop the outputs; racing with the
    // owner of TIM1 / GPIOC can at worst leave them stopped. BSRR is write-only and
    // atomic: bit 16 + 11 resets PC11 alone.
    unsafe {
        (*pac::GPIOC::ptr())
            .bsrr()
            .write(|w| w.bits(1 << (16 + 11)));
        (*pac::TIM1::ptr())
            .bdtr()
            .modify(|_, w| w.aoe().clear_bit().moe().clear_bit());
    }
}

/// RUN (PC8) and ERR (PC9) indicators, active high.
pub struct BoardLeds {
    pub run: Pin<'C', 8, Output>,
    pub err: Pin<'C', 9, Output>,
}

impl BoardLeds {
    pub fn set(&mut self, run: bool, err: bool) {
        self.run.set_state(run.into());
        self.err.set_state(err.into());
    }
}
