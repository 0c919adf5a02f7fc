//! The TUeES030's hardware on an STM32F446 as the firmware's [`Board`]
//! (`oxicat_devices::tue_es030`): three H-bridges on TIM1/TIM8, the motor currents and the
//! line voltage on ADC1's injected group, three encoders on TIM2/TIM3/TIM4 with a 40 MHz
//! time base on TIM5, the DRV8412 FAULT/OTW lines and four digital inputs and outputs.
//!
//! Register set-up is done with the PAC, not the HAL's PWM/ADC drivers: the HAL has no
//! centre-aligned PWM with an ADC trigger, and naming every register written keeps the
//! image's peripheral use explicit (README, "Pin map" and "What maps to what").
//!
//! [`Board`]: oxicat_devices::tue_es030::Board

use oxicat_devices::tue_es030::control::PWMPER;
use oxicat_devices::tue_es030::{app, Adcs, Bridges, Encoders, Io};
use stm32f4xx_hal::{
    pac,
    rcc::{Enable, Reset},
};

/// PWM carrier of the bridges (the manual's 80 kHz, `control::PWM_HZ`).
pub const PWM_HZ: u32 = oxicat_devices::tue_es030::control::PWM_HZ;
/// Current-loop rate: one TIM1 update event (ADC trigger) per 4 PWM periods.
pub const CURRENT_LOOP_HZ: u32 = oxicat_devices::tue_es030::control::CURRENT_LOOP_HZ;
/// TIM1 repetition counter: an update event every RCR + 1 = 8 half periods (over- and
/// underflows of the centre-aligned count), i.e. every 4 PWM periods = 50 µs.
pub const RCR: u32 = 2 * PWM_HZ / CURRENT_LOOP_HZ - 1;
/// TIM5 prescaler: 90 MHz / 9 = 10 MHz, four of the FPGA's 40 MHz timestamp ticks per count.
const TIM5_PSC: u32 = 8;

/// ADC1 injected sequence: JDR1..JDR3 the motor currents M1..M3, JDR4 the line voltage.
pub mod ch {
    /// M1 current (LT1999 through its RC filter), PC0 = ADC123_IN10.
    pub const I1: u8 = 10;
    /// M2 current, PC1 = ADC123_IN11.
    pub const I2: u8 = 11;
    /// M3 current, PC2 = ADC123_IN12.
    pub const I3: u8 = 12;
    /// Line voltage through the 1:11 divider, PC3 = ADC123_IN13.
    pub const LINE: u8 = 13;
    /// The 5 V reference through its 1:2 divider (`control::VREF5_DIVIDER`), PC4 =
    /// ADC12_IN14: ADC1's regular group, one conversion per current-loop tick.
    pub const VREF5: u8 = 14;
}

/// GPIO pins (port, number) of the board's discrete lines.
pub mod pins {
    /// DRV8412 enable (RESET_AB/RESET_CD high) of M1, M2, M3; low = tristate.
    pub const ENABLE: [(char, u8); 3] = [('C', 10), ('C', 11), ('C', 12)];
    /// M1 FAULT#, M1 OTW#, M2/M3 FAULT#, M2/M3 OTW# (open drain, active low, pull-ups).
    pub const DRIVER: [(char, u8); 4] = [('B', 12), ('B', 13), ('B', 14), ('B', 15)];
    /// Digital inputs 0..3: PD0..PD3; outputs 0..3: PD4..PD7; FRUN LED PD14.
    pub const DIGIN0: u8 = 0;
    /// First digital output pin on port D.
    pub const DIGOUT0: u8 = 4;
    /// The service routine's `FRUN` toggle (digital output bit 4) on an LED.
    pub const FRUN_LED: u8 = 14;
}

/// The board.
pub struct TueBoard {
    tim1: pac::TIM1,
    tim8: pac::TIM8,
    tim2: pac::TIM2,
    tim3: pac::TIM3,
    tim4: pac::TIM4,
    tim5: pac::TIM5,
    adc: pac::ADC1,
    /// The last conversion of the 5 V reference (counts).
    vref5: u16,
    /// Auto-reload of TIM1/TIM8: compare `arr` = duty 1.
    arr: u32,
    /// 16-bit TIM3/TIM4 counts extended to 32 bits: (last raw count, extended count).
    ext: [(u16, u32); 2],
}

impl TueBoard {
    /// Sets up TIM1 and TIM8 (80 kHz centre-aligned, compares at 50 %), TIM2/3/4 (encoders),
    /// TIM5 (timestamp clock) and ADC1 (injected sequence on TIM1's update event, JEOC
    /// interrupt enabled in the ADC; the NVIC line stays masked), and starts them.
    /// `timclk2_hz`: the APB2 timer clock (TIM1, TIM8).
    ///
    /// The pins must already be in their modes (main.rs).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        tim1: pac::TIM1,
        tim8: pac::TIM8,
        tim2: pac::TIM2,
        tim3: pac::TIM3,
        tim4: pac::TIM4,
        tim5: pac::TIM5,
        adc: pac::ADC1,
        timclk2_hz: u32,
    ) -> Self {
        // SAFETY: the peripherals are owned (passed in by value); enabling and resetting
        // their clocks touches only their own RCC bits.
        unsafe {
            pac::TIM1::enable_unchecked();
            pac::TIM1::reset_unchecked();
            pac::TIM8::enable_unchecked();
            pac::TIM8::reset_unchecked();
            pac::TIM2::enable_unchecked();
            pac::TIM2::reset_unchecked();
            pac::TIM3::enable_unchecked();
            pac::TIM3::reset_unchecked();
            pac::TIM4::enable_unchecked();
            pac::TIM4::reset_unchecked();
            pac::TIM5::enable_unchecked();
            pac::TIM5::reset_unchecked();
            pac::ADC1::enable_unchecked();
            pac::ADC1::reset_unchecked();
        }
        let arr = timclk2_hz / (2 * PWM_HZ);
        setup_encoder_tim2(&tim2);
        setup_encoder_16(&tim3);
        setup_encoder_16(&tim4);
        setup_timestamp(&tim5);
        setup_bridges(&tim1, &tim8, arr);
        // The ADC listens only after TIM1's UG above: the trigger is the update events of
        // the running count.
        setup_adc(&adc);
        let ext = [
            (tim3.cnt().read().bits() as u16, 0),
            (tim4.cnt().read().bits() as u16, 0),
        ];
        Self {
            tim1,
            tim8,
            tim2,
            tim3,
            tim4,
            tim5,
            adc,
            arr,
            ext,
            vref5: 0,
        }
    }

    /// Clears the injected end-of-conversion flag (the ADC interrupt's acknowledge), takes
    /// the 5 V reference's regular conversion started at the previous tick (done 1.2 µs
    /// after it) and starts the next one: the ADC is idle until the next injected trigger.
    pub fn ack_conversion(&mut self) {
        // SR bits are rc_w0: writing 1 leaves the others unchanged.
        self.adc.sr().write(|w| unsafe { w.bits(!(1 << 2)) });
        if self.adc.sr().read().eoc().bit_is_set() {
            self.vref5 = (self.adc.dr().read().bits() & 0xFFF) as u16;
        }
        self.adc.cr2().modify(|_, w| w.swstart().set_bit());
    }

    /// The firmware's comparator value (0..=PWMPER of its 40 MHz / 80 kHz counter) on this
    /// board's counter (0..=ARR): ×ARR/PWMPER, rounded.
    fn compare(&self, cmp: u16) -> u32 {
        let top = PWMPER as u32;
        ((u32::from(cmp).min(top) * self.arr + top / 2) / top).min(self.arr)
    }
}

/// Sets (`true`) or resets pin `pin` of GPIO port `port` (C or D here) atomically.
fn write_pin(port: char, pin: u8, high: bool) {
    let bit = if high {
        1u32 << pin
    } else {
        1u32 << (16 + pin)
    };
    // SAFETY: BSRR is write-only and atomic: only this pin changes.
    unsafe {
        match port {
            'B' => (*pac::GPIOB::ptr()).bsrr().write(|w| w.bits(bit)),
            'C' => (*pac::GPIOC::ptr()).bsrr().write(|w| w.bits(bit)),
            _ => (*pac::GPIOD::ptr()).bsrr().write(|w| w.bits(bit)),
        }
    }
}

/// Reads pin `pin` of port B or D.
fn read_pin(port: char, pin: u8) -> bool {
    // SAFETY: a read of IDR.
    let idr = unsafe {
        match port {
            'B' => (*pac::GPIOB::ptr()).idr().read().bits(),
            _ => (*pac::GPIOD::ptr()).idr().read().bits(),
        }
    };
    idr & (1 << pin) != 0
}

impl Bridges for TueBoard {
    /// Phase A / B of channel `ch` on their compare registers (M1: TIM1 CH1/CH2, M2:
    /// TIM1 CH3/CH4, M3: TIM8 CH3/CH4), and the DRV8412 enable.
    fn set_bridge(&mut self, ch: usize, cmp_a: u16, cmp_b: u16, enable: bool) {
        let (a, b) = (self.compare(cmp_a), self.compare(cmp_b));
        // Unbuffered compares (OCxPE = 0): the new duty acts in the running period, as the
        // current loop's output should (see setup_bridges).
        match ch {
            0 => {
                self.tim1.ccr1().write(|w| unsafe { w.bits(a) });
                self.tim1.ccr2().write(|w| unsafe { w.bits(b) });
            }
            1 => {
                self.tim1.ccr3().write(|w| unsafe { w.bits(a) });
                self.tim1.ccr4().write(|w| unsafe { w.bits(b) });
            }
            2 => {
                self.tim8.ccr3().write(|w| unsafe { w.bits(a) });
                self.tim8.ccr4().write(|w| unsafe { w.bits(b) });
            }
            _ => return,
        }
        let (port, pin) = pins::ENABLE[ch];
        write_pin(port, pin, enable);
    }
}

impl Adcs for TueBoard {
    /// The manual's second ADC (the AS154x on the bridges' side) is ADC1's injected
    /// group here: channels 3..5 the currents, 2 the line voltage; 1, the 5 V reference,
    /// its regular group (PC4); the others are not fitted (0).
    fn adc2(&mut self, ch: usize) -> u16 {
        let jdr = |k: u8| -> u16 {
            (match k {
                1 => self.adc.jdr1().read().bits(),
                2 => self.adc.jdr2().read().bits(),
                3 => self.adc.jdr3().read().bits(),
                _ => self.adc.jdr4().read().bits(),
            } & 0xFFF) as u16
        };
        match ch {
            app::ADC2_LINE => jdr(4),
            app::ADC2_VREF5 => self.vref5,
            c if app::ADC2_CURRENT.contains(&c) => jdr((c - app::ADC2_CURRENT[0]) as u8 + 1),
            _ => 0,
        }
    }

    /// The manual's first ADC (hall positions, forces, spare analog inputs): not fitted
    /// on this board (README), reads 0.
    fn adc1(&mut self, _ch: usize) -> u16 {
        0
    }
}

impl Encoders for TueBoard {
    /// The count of M1 (TIM2, 32 bits), M2 (TIM3) or M3 (TIM4, both extended to 32 bits)
    /// and the 40 MHz time it was read at (TIM5 × 4).
    fn latch(&mut self, ch: usize) -> (u32, u32) {
        let count = match ch {
            0 => self.tim2.cnt().read().bits(),
            1 | 2 => {
                let raw = if ch == 1 {
                    self.tim3.cnt().read().bits()
                } else {
                    self.tim4.cnt().read().bits()
                } as u16;
                let (last, ext) = &mut self.ext[ch - 1];
                // Read at 1 kHz: far fewer than 32,768 counts between two reads.
                *ext = ext.wrapping_add(raw.wrapping_sub(*last) as i16 as i32 as u32);
                *last = raw;
                *ext
            }
            _ => return (0, 0),
        };
        let t = self.tim5.cnt().read().bits().wrapping_mul(4);
        (count, t)
    }
}

impl Io for TueBoard {
    /// Digital inputs 0..3 (PD0..PD3) and the DRV8412 lines in bits 4..7 (active low).
    fn digin(&mut self) -> u8 {
        let mut v = 0u8;
        for k in 0..4u8 {
            if read_pin('D', pins::DIGIN0 + k) {
                v |= 1 << k;
            }
        }
        for (k, &(port, pin)) in pins::DRIVER.iter().enumerate() {
            if !read_pin(port, pin) {
                v |= 0x10 << k;
            }
        }
        v
    }

    /// Digital outputs 0..3 on PD4..PD7, the FRUN bit on the LED PD14.
    fn digout(&mut self, v: u8) {
        for k in 0..4u8 {
            write_pin('D', pins::DIGOUT0 + k, v & (1 << k) != 0);
        }
        write_pin('D', pins::FRUN_LED, v & app::DO_FRUN != 0);
    }

    /// The AD5722R DAC is not fitted (README).
    fn dac(&mut self, _ch: usize, _code: u16) {}

    /// The caliper UART is not fitted (README).
    fn calipers(&mut self) -> [u16; 2] {
        [0; 2]
    }
}

/// TIM2: encoder mode 3 on TI1/TI2 (PA0/PA1), ×4 counting, 32 bits.
fn setup_encoder_tim2(t: &pac::TIM2) {
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
    t.ccer().write(|w| w.cc1e().set_bit().cc2e().set_bit());
    t.smcr().write(|w| w.sms().encoder_mode_3());
    t.arr().write(|w| unsafe { w.bits(u32::MAX) });
    t.egr().write(|w| w.ug().set_bit());
    t.sr().write(|w| unsafe { w.bits(0) });
    t.cr1().write(|w| w.cen().set_bit());
}

/// TIM3 (PC6/PC7) or TIM4 (PD12/PD13): encoder mode 3, 16 bits.
fn setup_encoder_16<T>(t: &T)
where
    T: core::ops::Deref<Target = pac::tim3::RegisterBlock>,
{
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
    t.ccer().write(|w| w.cc1e().set_bit().cc2e().set_bit());
    t.smcr().write(|w| w.sms().encoder_mode_3());
    t.arr().write(|w| unsafe { w.bits(0xFFFF) });
    t.egr().write(|w| w.ug().set_bit());
    t.sr().write(|w| unsafe { w.bits(0) });
    t.cr1().write(|w| w.cen().set_bit());
}

/// TIM5: free-running 32-bit count at 10 MHz (the encoder timestamps).
fn setup_timestamp(t: &pac::TIM5) {
    t.psc().write(|w| unsafe { w.bits(TIM5_PSC) });
    t.arr().write(|w| unsafe { w.bits(u32::MAX) });
    t.egr().write(|w| w.ug().set_bit());
    t.sr().write(|w| unsafe { w.bits(0) });
    t.cr1().write(|w| w.cen().set_bit());
}

/// TIM1 and TIM8: centre-aligned mode 1 at 80 kHz (ARR = TIMCLK / (2 · 80 kHz) = 1125),
/// PWM mode 1 on TIM1 CH1..CH4 and TIM8 CH3/CH4, compares unbuffered (OCxPE = 0: the
/// current loop's new duty acts at once, ≈ 7–11 µs after the sample (the 3.2 µs sequence
/// and the handler) where the FPGA's acts 6.25 µs after it, at its
/// counter bottom; with preload it would wait for the next update event, 50 µs), all at
/// 50 % (bridges braked). TIM1: repetition counter 7, one update event per 50 µs, as
/// TRGO (MMS = 010, update) ADC1's injected trigger. Main outputs enabled. Both
/// counters start back to back (a few cycles apart).
fn setup_bridges(t1: &pac::TIM1, t8: &pac::TIM8, arr: u32) {
    let mid = arr / 2;
    for t in [&**t1, &**t8] {
        t.cr1().write(|w| w.cms().center_aligned1());
        t.psc().write(|w| unsafe { w.bits(0) });
        t.arr().write(|w| unsafe { w.bits(arr) });
        t.ccmr1_output()
            .write(|w| w.oc1m().pwm_mode1().oc2m().pwm_mode1());
        t.ccmr2_output()
            .write(|w| w.oc3m().pwm_mode1().oc4m().pwm_mode1());
        t.ccr1().write(|w| unsafe { w.bits(mid) });
        t.ccr2().write(|w| unsafe { w.bits(mid) });
        t.ccr3().write(|w| unsafe { w.bits(mid) });
        t.ccr4().write(|w| unsafe { w.bits(mid) });
        t.bdtr().write(|w| w.moe().set_bit());
    }
    t1.rcr().write(|w| unsafe { w.bits(RCR) });
    t1.ccer().write(|w| {
        w.cc1e()
            .set_bit()
            .cc2e()
            .set_bit()
            .cc3e()
            .set_bit()
            .cc4e()
            .set_bit()
    });
    t8.ccer().write(|w| w.cc3e().set_bit().cc4e().set_bit());
    t1.cr2().write(|w| w.mms().update());
    // UG loads PSC, ARR and RCR.
    t1.egr().write(|w| w.ug().set_bit());
    t8.egr().write(|w| w.ug().set_bit());
    t1.sr().write(|w| unsafe { w.bits(0) });
    t8.sr().write(|w| unsafe { w.bits(0) });
    t1.cr1().modify(|_, w| w.cen().set_bit());
    t8.cr1().modify(|_, w| w.cen().set_bit());
}

/// ADC1: ADCCLK = PCLK2 / 4 (22.5 MHz), 12 bits, scan, injected sequence I1, I2, I3,
/// LINE (JL = 3) on TIM1_TRGO rising edges, JEOC interrupt enabled. Sampling: 3 ADCCLK
/// for the currents (the LT1999 outputs are held by their 10 nF filter capacitors, 2,500
/// times the ADC's sampling capacitor), 15 for the divider; the sequence takes
/// 3 · 15 + 27 = 72 ADCCLK = 3.2 µs.
fn setup_adc(adc: &pac::ADC1) {
    // SAFETY: ADC_CCR is shared by the three ADCs; only ADC1 is used by this image.
    let common = unsafe { &*pac::ADC_COMMON::ptr() };
    common.ccr().modify(|_, w| w.adcpre().div4());
    adc.cr1().write(|w| w.scan().set_bit().jeocie().set_bit());
    adc.smpr1().write(|w| {
        w.smp10()
            .cycles3()
            .smp11()
            .cycles3()
            .smp12()
            .cycles3()
            .smp13()
            .cycles15()
            .smp14()
            .cycles15()
    });
    // The regular group: one conversion of the 5 V reference, started by software.
    adc.sqr1().write(|w| unsafe { w.l().bits(0) });
    adc.sqr3().write(|w| unsafe { w.sq1().bits(ch::VREF5) });
    adc.jsqr().write(|w| unsafe {
        w.jsq1()
            .bits(ch::I1)
            .jsq2()
            .bits(ch::I2)
            .jsq3()
            .bits(ch::I3)
            .jsq4()
            .bits(ch::LINE)
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

/// Bridges off from any context (panic, fault): the three enable lines low (tristate,
/// the motors coast) and the main outputs of TIM1 and TIM8 disabled.
pub fn bridges_emergency_off() {
    for &(port, pin) in &pins::ENABLE {
        write_pin(port, pin, false);
    }
    // SAFETY: single register writes that only ever stop the outputs.
    unsafe {
        (*pac::TIM1::ptr())
            .bdtr()
            .modify(|_, w| w.aoe().clear_bit().moe().clear_bit());
        (*pac::TIM8::ptr())
            .bdtr()
            .modify(|_, w| w.aoe().clear_bit().moe().clear_bit());
    }
}
