//! ADC1 of the STM32F446 (RM0390 §13): the injected group, as a motor-control image
//! uses it.
//!
//! - CR2.ADON powers the ADC; CR1.SCAN, RES (12/10/8/6 bits), JEOCIE; CR2.ALIGN,
//!   JEXTEN/JEXTSEL, JSWSTART; SMPR1/SMPR2 sampling times; JSQR (JL, JSQ1..4); JOFR1..4.
//! - An injected sequence starts on JSWSTART or on the rising edge of its external
//!   trigger — modelled: JEXTSEL = 0001, TIM1_TRGO, with TIM1 in a master mode whose
//!   edges the timer model computes (CR2.MMS = 010, the update event, with the repetition
//!   counter; or OC1REF..OC4REF in PWM mode 1/2). A trigger
//!   while a sequence converts is ignored (RM0390 §13.3.10).
//! - Every channel of the sequence is sampled at the trigger (the plant holds its
//!   voltages over its period, see [`crate::plant`]); the sequence lasts Σ (SMPx +
//!   resolution) ADCCLK cycles, ADCCLK = PCLK2 / (2 · (ADC_CCR.ADCPRE + 1)); at its end
//!   JDR1.. hold the results (minus JOFRx, right- or left-aligned) and SR.JEOC is set,
//!   which with JEOCIE raises IRQ 18 (`ADC`). SR is rc_w0.
//! - The regular group, single conversion by software: SWSTART with SQR1.L = 0 (one
//!   channel, SQ1), CONT, EXTEN and DMA off, converts SQ1 in SMPx + resolution ADCCLK
//!   cycles; then DR holds the result and SR.EOC is set (IRQ 18 with EOCIE), cleared by a
//!   read of DR. An injected trigger while it converts is a fault (on silicon it would
//!   interrupt and restart the regular conversion).
//! - Voltages come from the board's analog inputs ([`crate::Board::set_analog`]); a
//!   conversion of a channel that nothing drives, regular sequences, continuous or
//!   triggered regular conversions, the other trigger sources, JAUTO/DISCEN/DMA and
//!   ADC2/ADC3 are not modelled: the image stops with a fault naming the register, never
//!   a silent zero.

/// ADC1's register block.
pub(crate) const ADC1: u64 = 0x4001_2000;
/// The ADCs and the common registers: 0x4001_2000..0x4001_2400.
pub(crate) const ADC_END: u64 = 0x4001_2400;
/// Input channels (IN0..IN15, temperature, VREFINT, VBAT).
pub(crate) const CHANNELS: usize = 19;
/// Analogue reference (VDDA) of the boards \[V\].
pub const VREF: f64 = 3.3;
/// NVIC line of ADC1..3.
pub const IRQ: u16 = 18;

const SR: usize = 0x00;
const CR1: usize = 0x04;
const CR2: usize = 0x08;
const SMPR1: usize = 0x0C;
const SMPR2: usize = 0x10;
const JOFR1: usize = 0x14;
const SQR1: usize = 0x2C;
const SQR3: usize = 0x34;
const JSQR: usize = 0x38;
const JDR1: usize = 0x3C;
const DR: usize = 0x4C;

const JEOC: u32 = 1 << 2;
const JSTRT: u32 = 1 << 3;
const EOC: u32 = 1 << 1;
const AWD: u32 = 1;
const OVR: u32 = 1 << 5;
const ADON: u32 = 1;
const JSWSTART: u32 = 1 << 22;
const SWSTART: u32 = 1 << 30;

/// Sampling times in ADCCLK cycles by SMPx code.
const SMP_CYCLES: [u64; 8] = [3, 15, 28, 56, 84, 112, 144, 480];

/// The pin of input channel `ch` (for messages).
pub(crate) fn channel_pin(ch: usize) -> &'static str {
    const PINS: [&str; CHANNELS] = [
        "PA0",
        "PA1",
        "PA2",
        "PA3",
        "PA4",
        "PA5",
        "PA6",
        "PA7",
        "PB0",
        "PB1",
        "PC0",
        "PC1",
        "PC2",
        "PC3",
        "PC4",
        "PC5",
        "temperature sensor",
        "VREFINT",
        "VBAT",
    ];
    PINS.get(ch).copied().unwrap_or("?")
}

/// ADC1's state.
#[derive(Debug, Clone, Default)]
pub struct Adc {
    regs: [u32; 0x50 / 4],
    /// ADC_CCR (common).
    pub ccr: u32,
    /// Cycle up to which external triggers have been looked at.
    pub last: u64,
    /// A sequence converting: its end cycle and results (JDR1..).
    busy: Option<(u64, [u32; 4])>,
    /// Injected sequences started so far.
    pub sequences: u64,
    /// A regular conversion converting: its end cycle and result.
    regular: Option<(u64, u32)>,
    /// SWSTART was written: the board starts the regular conversion.
    regular_requested: bool,
    /// Regular conversions started so far.
    pub regular_conversions: u64,
    /// The end of the first sequence whose JEOC the ADC handler has not been entered for.
    pub jeoc_unhandled_since: Option<u64>,
    /// Longest time from a JEOC to the entry of the ADC handler (interrupt latency, with
    /// whatever held it back: masks, a handler of equal or higher priority) \[cycles\].
    pub max_latency: u64,
}

/// Where an injected sequence's trigger comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Trigger {
    /// None (JEXTEN = 00) or the ADC is off.
    Off,
    /// TIM1_TRGO, rising edge.
    Tim1TrgoRising,
}

impl Adc {
    fn r(&self, off: usize) -> u32 {
        self.regs.get(off / 4).copied().unwrap_or(0)
    }

    /// The external trigger the injected group listens to, or an error naming what is
    /// configured but not modelled.
    pub(crate) fn trigger(&self) -> Result<Trigger, String> {
        let cr2 = self.r(CR2);
        let jexten = (cr2 >> 20) & 3;
        let jextsel = (cr2 >> 16) & 0xF;
        if cr2 & ADON == 0 || jexten == 0 {
            return Ok(Trigger::Off);
        }
        match (jexten, jextsel) {
            (1, 1) => Ok(Trigger::Tim1TrgoRising),
            _ => Err(format!(
                "ADC1 CR2 {cr2:#010x}: injected trigger JEXTSEL {jextsel:#06b} on JEXTEN \
                 {jexten:#04b} is not modelled (only TIM1_TRGO, rising edge)"
            )),
        }
    }

    /// The channels of the injected sequence, in conversion order (JL + 1 of JSQ1..4,
    /// the last ones when JL < 3: RM0390 ADC_JSQR).
    fn sequence(&self) -> Vec<usize> {
        let jsqr = self.r(JSQR);
        let jl = ((jsqr >> 20) & 3) as usize;
        (3 - jl..4)
            .map(|k| ((jsqr >> (5 * k)) & 0x1F) as usize)
            .collect()
    }

    /// Sampling time of channel `ch` in ADCCLK cycles.
    fn smp(&self, ch: usize) -> u64 {
        let (reg, k) = if ch >= 10 {
            (self.r(SMPR1), ch - 10)
        } else {
            (self.r(SMPR2), ch)
        };
        SMP_CYCLES[((reg >> (3 * k)) & 7) as usize]
    }

    /// Resolution in bits (CR1.RES).
    fn bits(&self) -> u32 {
        12 - 2 * ((self.r(CR1) >> 24) & 3)
    }

    /// Starts an injected sequence at cycle `at`: samples `analog`, the conversion ends
    /// after its ADCCLK cycles (`cycles_per_adcclk` CPU cycles each). A channel nothing
    /// drives is an error.
    pub(crate) fn start(
        &mut self,
        at: u64,
        analog: &[Option<f64>; CHANNELS],
        cycles_per_adcclk: u64,
    ) -> Result<(), String> {
        if self.r(CR2) & ADON == 0 || self.busy.is_some() {
            return Ok(());
        }
        if self.regular.is_some() {
            return Err(
                "ADC1: an injected trigger while the regular conversion converts \
                        (it would interrupt and restart it): not modelled"
                    .into(),
            );
        }
        let bits = self.bits();
        let mut res = [0u32; 4];
        let mut adcclk = 0u64;
        for (k, ch) in self.sequence().into_iter().enumerate() {
            let Some(v) = analog.get(ch).copied().flatten() else {
                return Err(format!(
                    "ADC1 converts channel IN{ch} ({}), which nothing drives (a plant sets \
                     it with Board::set_analog)",
                    channel_pin(ch)
                ));
            };
            let full = f64::from(1u32 << bits);
            let code = (v / VREF * full).floor().clamp(0.0, full - 1.0) as i32;
            let offset = (self.r(JOFR1 + 4 * k) & 0xFFF) as i32 >> (12 - bits);
            let d = code - offset;
            res[k] = if self.r(CR2) & (1 << 11) != 0 {
                // Left-aligned: the sign in bit 15, data below it.
                ((d << (15 - bits)) as u32) & 0xFFFF
            } else {
                (d as u32) & 0xFFFF
            };
            adcclk += self.smp(ch) + u64::from(bits);
        }
        self.regs[SR / 4] |= JSTRT;
        self.sequences += 1;
        self.busy = Some((at + adcclk * cycles_per_adcclk.max(1), res));
        Ok(())
    }

    /// A software start of the regular group was written (and is taken now).
    pub(crate) fn take_regular_request(&mut self) -> bool {
        core::mem::take(&mut self.regular_requested)
    }

    /// Starts the regular conversion of SQ1 at cycle `at`.
    pub(crate) fn start_regular(
        &mut self,
        at: u64,
        analog: &[Option<f64>; CHANNELS],
        cycles_per_adcclk: u64,
    ) -> Result<(), String> {
        if self.r(CR2) & ADON == 0 || self.regular.is_some() {
            return Ok(());
        }
        if self.busy.is_some() {
            return Err("ADC1: SWSTART while the injected sequence converts: not modelled".into());
        }
        let ch = (self.r(SQR3) & 0x1F) as usize;
        let Some(v) = analog.get(ch).copied().flatten() else {
            return Err(format!(
                "ADC1 converts channel IN{ch} ({}), which nothing drives (a plant sets it \
                 with Board::set_analog)",
                channel_pin(ch)
            ));
        };
        let bits = self.bits();
        let full = f64::from(1u32 << bits);
        let code = (v / VREF * full).floor().clamp(0.0, full - 1.0) as u32;
        let d = if self.r(CR2) & (1 << 11) != 0 {
            (code << (16 - bits)) & 0xFFFF
        } else {
            code
        };
        self.regs[SR / 4] |= 1 << 4; // STRT
        self.regular_conversions += 1;
        let adcclk = self.smp(ch) + u64::from(bits);
        self.regular = Some((at + adcclk * cycles_per_adcclk.max(1), d));
        Ok(())
    }

    /// Completes the conversion if it ends by `now`.
    pub(crate) fn finish_by(&mut self, now: u64) {
        if let Some((end, d)) = self.regular {
            if end <= now {
                self.regs[DR / 4] = d;
                self.regs[SR / 4] |= EOC;
                self.regular = None;
            }
        }
        if let Some((end, res)) = self.busy {
            if end <= now {
                for (k, v) in res.into_iter().enumerate() {
                    self.regs[(JDR1 + 4 * k) / 4] = v;
                }
                self.regs[SR / 4] |= JEOC;
                self.busy = None;
                self.jeoc_unhandled_since.get_or_insert(end);
            }
        }
    }

    /// The ADC handler is entered at `now`.
    pub(crate) fn handler_entered(&mut self, now: u64) {
        if let Some(t) = self.jeoc_unhandled_since.take() {
            self.max_latency = self.max_latency.max(now.saturating_sub(t));
        }
    }

    /// End of the conversion in progress.
    pub(crate) fn busy_until(&self) -> Option<u64> {
        match (self.busy.map(|b| b.0), self.regular.map(|r| r.0)) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// Whether the ADC interrupt line is high.
    pub(crate) fn irq(&self) -> bool {
        let (sr, cr1) = (self.r(SR), self.r(CR1));
        (sr & JEOC != 0 && cr1 & (1 << 7) != 0)
            || (sr & EOC != 0 && cr1 & (1 << 5) != 0)
            || (sr & AWD != 0 && cr1 & (1 << 6) != 0)
            || (sr & OVR != 0 && cr1 & (1 << 26) != 0)
    }

    /// A register read (offset in ADC1's block, or the common block's at 0x300..).
    pub(crate) fn read(&mut self, off: usize) -> Result<u32, String> {
        match off {
            DR => {
                self.regs[SR / 4] &= !EOC; // a read of DR clears EOC
                Ok(self.r(DR))
            }
            0x300 => Ok(self.r(SR) & 0x3F), // CSR: ADC1's flags
            0x304 => Ok(self.ccr),
            0x308 => Ok(0),
            o if o < 0x50 => Ok(self.r(o)),
            o => Err(format!(
                "read of ADC{} at {:#010x}: not modelled (only ADC1 and the common CCR)",
                o / 0x100 + 1,
                ADC1 + o as u64
            )),
        }
    }

    /// A register write; `Ok(true)` when it asks for a software start of the injected
    /// group (JSWSTART).
    pub(crate) fn write(&mut self, off: usize, v: u32) -> Result<bool, String> {
        match off {
            SR => {
                self.regs[SR / 4] &= v | !0x3F; // rc_w0
                Ok(false)
            }
            CR1 => {
                // JAUTO, JDISCEN, DISCEN: not modelled.
                if v & ((1 << 10) | (1 << 12) | (1 << 11)) != 0 {
                    return Err(format!(
                        "ADC1 CR1 {v:#010x}: JAUTO/JDISCEN/DISCEN are not modelled"
                    ));
                }
                self.regs[CR1 / 4] = v;
                Ok(false)
            }
            CR2 => {
                let single = (self.r(SQR1) >> 20) & 0xF == 0;
                if v & ((3 << 28) | (1 << 8) | (1 << 1)) != 0 || (v & SWSTART != 0 && !single) {
                    return Err(format!(
                        "ADC1 CR2 {v:#010x} (SQR1 {:#010x}): only single software-started \
                         regular conversions of one channel are modelled (no EXTEN, CONT, \
                         DMA, no sequence)",
                        self.r(SQR1)
                    ));
                }
                if v & SWSTART != 0 && v & ADON != 0 {
                    self.regular_requested = true;
                }
                self.regs[CR2 / 4] = v & !(JSWSTART | SWSTART);
                if v & ADON == 0 {
                    self.busy = None;
                    self.regular = None;
                }
                Ok(v & JSWSTART != 0 && v & ADON != 0)
            }
            o if (JDR1..JDR1 + 16).contains(&o) || o == 0x4C => Ok(false), // read-only
            o if o < 0x50 => {
                self.regs[o / 4] = v;
                Ok(false)
            }
            0x304 => {
                self.ccr = v;
                Ok(false)
            }
            0x300 | 0x308 => Ok(false),
            o => Err(format!(
                "write of {v:#010x} to ADC{} at {:#010x}: not modelled (only ADC1 and the \
                 common CCR)",
                o / 0x100 + 1,
                ADC1 + o as u64
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn adc() -> Adc {
        let mut a = Adc::default();
        a.write(CR1, (1 << 8) | (1 << 7)).ok();
        // IN10, IN11 at 15 cycles, IN12, IN13 at 56.
        a.write(SMPR1, 1 | (1 << 3) | (3 << 6) | (3 << 9)).ok();
        a.write(JSQR, 10 | (11 << 5) | (12 << 10) | (13 << 15) | (3 << 20))
            .ok();
        a.write(CR2, ADON | (1 << 16) | (1 << 20)).ok();
        a
    }

    #[test]
    fn an_injected_sequence_converts_its_channels_in_order_and_sets_jeoc_at_its_end() {
        let mut a = adc();
        assert_eq!(a.trigger(), Ok(Trigger::Tim1TrgoRising));
        let mut v = [None; CHANNELS];
        v[10] = Some(1.65);
        v[11] = Some(0.0);
        v[12] = Some(3.3);
        v[13] = Some(2.2857);
        // (15 + 12) · 2 + (56 + 12) · 2 = 190 ADCCLK at 8 CPU cycles each.
        a.start(1000, &v, 8).unwrap();
        assert_eq!(a.busy_until(), Some(1000 + 190 * 8));
        assert_eq!(a.read(SR).unwrap() & JSTRT, JSTRT);
        a.finish_by(1000 + 190 * 8 - 1);
        assert_eq!(a.read(SR).unwrap() & JEOC, 0);
        assert!(!a.irq());
        a.finish_by(1000 + 190 * 8);
        assert_eq!(a.read(SR).unwrap() & JEOC, JEOC);
        assert!(a.irq());
        assert_eq!(a.read(JDR1).unwrap(), 2048);
        assert_eq!(a.read(JDR1 + 4).unwrap(), 0);
        assert_eq!(a.read(JDR1 + 8).unwrap(), 4095, "clamped at full scale");
        assert_eq!(a.read(JDR1 + 12).unwrap(), 2837);
        a.write(SR, !JEOC).unwrap();
        assert!(!a.irq());
        assert_eq!(a.read(SR).unwrap() & JSTRT, JSTRT, "rc_w0 keeps the others");
    }

    #[test]
    fn a_software_started_regular_conversion_sets_dr_and_eoc_which_a_dr_read_clears() {
        let mut a = adc();
        a.write(SQR3, 14).unwrap(); // SQ1 = IN14 (PC4)
        a.write(SMPR1, 1 << 12).unwrap(); // IN14: 15 cycles
        a.write(CR2, ADON | (1 << 16) | (1 << 20) | SWSTART)
            .unwrap();
        assert!(a.take_regular_request());
        assert_eq!(a.read(CR2).unwrap() & SWSTART, 0, "SWSTART reads 0");
        let mut v = [None; CHANNELS];
        v[14] = Some(2.5);
        a.start_regular(100, &v, 8).unwrap();
        // 15 + 12 ADCCLK.
        a.finish_by(100 + 27 * 8 - 1);
        assert_eq!(a.read(SR).unwrap() & EOC, 0);
        a.finish_by(100 + 27 * 8);
        assert_eq!(a.read(SR).unwrap() & EOC, EOC);
        assert_eq!(a.read(DR).unwrap(), 3103, "2.5 V of 3.3 V in 12 bits");
        assert_eq!(a.read(SR).unwrap() & EOC, 0, "the DR read cleared EOC");
        // An injected trigger while a regular conversion runs: not modelled.
        a.start_regular(1000, &v, 8).unwrap();
        let mut all = [Some(1.0); CHANNELS];
        all[14] = Some(2.5);
        assert!(a.start(1001, &all, 8).is_err());
    }

    #[test]
    fn an_undriven_channel_or_an_unmodelled_mode_is_an_error_naming_it() {
        let mut a = adc();
        let e = a.start(0, &[None; CHANNELS], 8).unwrap_err();
        assert!(e.contains("IN10 (PC0)"), "{e}");
        a.write(SQR1, 1 << 20).unwrap(); // two regular conversions
        assert!(a.write(CR2, ADON | SWSTART).is_err());
        assert!(a.write(CR2, ADON | (1 << 1)).is_err(), "CONT");
        assert!(a.write(CR2, ADON | (2 << 16) | (1 << 20)).is_ok());
        assert!(a.trigger().is_err(), "TIM2_CH1 as trigger");
        assert!(a.read(0x100).is_err(), "ADC2");
    }
}
