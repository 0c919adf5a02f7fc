//! The two joint encoders as the leg node's `EncoderIn`: position from a timer in encoder
//! mode, and the STM32 counterpart of the F28379D eQEP capture unit for the speed estimate.
//!
//! The eQEP latches a capture timer into `QCPRD` at every unit position event (2^UPPS
//! quadrature edges). Here:
//!
//! - **Unit event.** The encoder timer (TIM2 knee, TIM3 hip) has channel 1 on TI1 (the A
//!   line, as encoder mode needs) with its capture enabled, so every rising edge of A —
//!   one per quadrature cycle, i.e. per 4 counts: UPPS = 2 — latches the encoder count into
//!   its CCR1 and sets CC1IF. Its master mode is "compare pulse" (CR2.MMS = 011): TRGO
//!   pulses on each of those captures.
//! - **Capture timer.** A free-running timer clocked at TIMCLK1 / 2^CCPS (TIM5 for the
//!   knee, TIM4 for the hip; 16-bit wrap like `QCTMR`) has CC1 on TRC (CC1S = 11), its
//!   trigger input being the encoder timer's TRGO (TIM5: ITR0 = TIM2, TIM4: ITR2 = TIM3).
//!   So the same A edge latches the time into the capture timer's CCR1, in hardware, without
//!   extra pins and without an interrupt per edge.
//! - **Per 10 kHz sample** ([`EncoderIn::sample`]): if the capture timer's CC1IF is set there
//!   was at least one unit event since the last sample; the latest (time, count) pair is read
//!   (re-read if another edge landed in between). The period is the time between this edge
//!   and the previous captured edge divided by the number of unit events between them
//!   (count difference / 4): exactly `QCPRD` when one event happened per sample (every motor
//!   speed below ≈ 2π·10 kHz/500 = 125 rad/s), their mean above that.
//! - **Flags.** `QDF` is the encoder timer's DIR bit; `COEF` (capture overflow) when the
//!   period exceeds 0xFFFF ticks or the previous event is older than the capture range;
//!   `CDEF` (direction change) when DIR differed from the last event's direction at any sample
//!   since, or the two edges' counts are not 4·k apart (A rises at another count going
//!   backwards).
//!
//! TIM3 is 16 bits; its count is extended to the free-running 32-bit `QPOSCNT` the
//! application expects (≤ 32767 counts per 100 µs).

use oxicat_devices::laelaps::{CaptureConfig, EncoderIn, Joint, QepSample};
use stm32f4xx_hal::{
    pac,
    qei::Qei,
    rcc::{Enable, Reset},
};

/// Capture timer prescaler: TIMCLK1 / 2^CCPS (90 MHz / 64 = 1.40625 MHz, 0.711 µs per tick;
/// the thesis' eQEP: 200 MHz / 128 = 0.64 µs).
pub const CCPS: u8 = 6;
/// One unit event per rising edge of A: every 4 quadrature counts, fixed by the wiring.
pub const UPPS: u8 = 2;

/// The capture configuration the application's speed estimate must use, for capture timers
/// clocked at `timclk_hz`.
pub fn capture_config(timclk_hz: u32) -> CaptureConfig {
    CaptureConfig {
        sysclk_hz: timclk_hz as f32,
        ccps: CCPS,
        upps: UPPS,
    }
}

/// One read of a joint's registers.
#[derive(Debug, Clone, Copy)]
struct Raw {
    /// Encoder counter CNT.
    count: u32,
    /// Encoder counter DIR (true: down-counting, reverse).
    down: bool,
    /// Capture timer CNT, read last.
    now: u16,
    /// The latest unit event since the previous read: (capture time, encoder count).
    edge: Option<(u16, u16)>,
}

/// Reads encoder timer `$enc` and its capture timer `$cap` (the register blocks differ in
/// type between the 32- and 16-bit timers, hence a macro).
macro_rules! read_raw {
    ($enc:ty, $cap:ty) => {{
        // SAFETY: after set-up only the joint loop touches these registers: reads, and the
        // read-to-clear / write-0-to-clear of the capture flags.
        let enc = unsafe { &*<$enc>::ptr() };
        let cap = unsafe { &*<$cap>::ptr() };
        let mut edge = None;
        if cap.sr().read().cc1if().bit_is_set() {
            // Reading CCR1 clears CC1IF; a pair is consistent when no new capture landed
            // while it was read. Edges are ≥ 0.7 µs apart at 19,000 rad/s: a retry or two.
            for _ in 0..4 {
                let stamp = cap.ccr1().read().bits() as u16;
                let pos = enc.ccr1().read().bits() as u16;
                edge = Some((stamp, pos));
                if cap.sr().read().cc1if().bit_is_clear() {
                    break;
                }
            }
            // Over-capture (more than one event since the last read) is expected above
            // 125 rad/s and accounted for by the count difference; clear CC1OF.
            cap.sr().write(|w| unsafe { w.bits(!(1 << 9)) });
        }
        Raw {
            count: enc.cnt().read().bits(),
            down: enc.cr1().read().dir().bit_is_set(),
            // After the capture registers: `now` is never before the edge read above.
            now: cap.cnt().read().bits() as u16,
            edge,
        }
    }};
}

/// The software side of one joint's capture: extended time and count, the previous event.
#[derive(Debug, Clone, Copy)]
struct QepState {
    /// The counter has 32 bits (TIM2); else 16 (TIM3) and is extended here.
    wide: bool,
    /// `QPOSCNT`: free-running 32-bit count.
    pos: u32,
    last_count: u32,
    /// Capture-timer time extended to 32 bits at the last sample.
    time: u32,
    last_now: u16,
    /// The previous unit event: extended time, encoder count at the edge.
    last_event: Option<(u32, u16)>,
    /// The previous event is older than the capture range (`COEF` on the next one).
    stale: bool,
    /// Direction at the previous event, and whether it changed since.
    dir_at_event: bool,
    dir_changed: bool,
}

impl QepState {
    fn new(wide: bool, r: Raw) -> Self {
        Self {
            wide,
            pos: r.count,
            last_count: r.count,
            time: 0,
            last_now: r.now,
            last_event: None,
            stale: false,
            dir_at_event: !r.down,
            dir_changed: false,
        }
    }

    fn update(&mut self, r: Raw) -> QepSample {
        self.pos = if self.wide {
            r.count
        } else {
            let d = (r.count as u16).wrapping_sub(self.last_count as u16) as i16;
            self.pos.wrapping_add(d as i32 as u32)
        };
        self.last_count = r.count;
        self.time = self
            .time
            .wrapping_add(u32::from(r.now.wrapping_sub(self.last_now)));
        self.last_now = r.now;
        let forward = !r.down;
        if forward != self.dir_at_event {
            self.dir_changed = true;
        }
        let mut s = QepSample {
            position: self.pos,
            forward,
            ..QepSample::default()
        };
        match r.edge {
            Some((stamp, edge_count)) => {
                let t = self.time.wrapping_sub(u32::from(r.now.wrapping_sub(stamp)));
                s.unit_event = true;
                let period = match self.last_event {
                    Some((t0, c0)) if !self.stale => {
                        let dc = edge_count.wrapping_sub(c0) as i16 as i32;
                        let events = (dc.unsigned_abs() + 2) >> UPPS;
                        s.direction_change = self.dir_changed || dc % 4 != 0 || events == 0;
                        Some(t.wrapping_sub(t0) / events.max(1))
                    }
                    _ => None,
                };
                match period {
                    Some(p) if p <= 0xFFFF => s.capture_period = p as u16,
                    _ => {
                        s.capture_overflow = true;
                        s.capture_period = 0xFFFF;
                    }
                }
                self.last_event = Some((t, edge_count));
                self.stale = false;
                self.dir_at_event = forward;
                self.dir_changed = false;
            }
            None => {
                if let Some((t0, _)) = self.last_event {
                    if self.time.wrapping_sub(t0) > 0xFFFF {
                        self.stale = true;
                    }
                }
            }
        }
        s
    }
}

/// Knee (TIM2 + TIM5) and hip (TIM3 + TIM4) encoders.
pub struct Encoders {
    _knee: Qei<pac::TIM2>,
    _hip: Qei<pac::TIM3>,
    knee: QepState,
    hip: QepState,
}

impl Encoders {
    /// Takes the two encoder timers (already in encoder mode with their pins) and the two
    /// capture timers, links them and starts the capture timers.
    pub fn new(
        knee: Qei<pac::TIM2>,
        hip: Qei<pac::TIM3>,
        _tim5: pac::TIM5,
        _tim4: pac::TIM4,
    ) -> Self {
        // SAFETY: TIM4/TIM5 are owned (passed in by value) and TIM2/TIM3 by the Qei values;
        // only CR2.MMS of the latter is changed, which the Qei does not use.
        unsafe {
            pac::TIM5::enable_unchecked();
            pac::TIM5::reset_unchecked();
            pac::TIM4::enable_unchecked();
            pac::TIM4::reset_unchecked();
            let tim2 = &*pac::TIM2::ptr();
            let tim3 = &*pac::TIM3::ptr();
            tim2.cr2().modify(|_, w| w.mms().compare_pulse());
            tim3.cr2().modify(|_, w| w.mms().compare_pulse());
            // Input filter on A and B: 8 samples at 90 MHz (89 ns), below the 160 ns between
            // counts at the fastest speed the capture can measure (19,600 rad/s).
            tim2.ccmr1_input()
                .modify(|_, w| w.ic1f().fck_int_n8().ic2f().fck_int_n8());
            tim3.ccmr1_input()
                .modify(|_, w| w.ic1f().fck_int_n8().ic2f().fck_int_n8());

            let t5 = &*pac::TIM5::ptr();
            t5.psc().write(|w| w.psc().set((1 << CCPS) - 1));
            t5.arr().write(|w| w.bits(0xFFFF));
            t5.smcr().write(|w| w.ts().itr0()); // ITR0 = TIM2 TRGO
            t5.ccmr1_input().write(|w| w.cc1s().trc());
            t5.ccer().write(|w| w.cc1e().set_bit());
            t5.egr().write(|w| w.ug().set_bit());
            t5.sr().write(|w| w.bits(0));
            t5.cr1().write(|w| w.cen().set_bit());

            let t4 = &*pac::TIM4::ptr();
            t4.psc().write(|w| w.psc().set((1 << CCPS) - 1));
            t4.arr().write(|w| w.bits(0xFFFF));
            t4.smcr().write(|w| w.ts().itr2()); // ITR2 = TIM3 TRGO
            t4.ccmr1_input().write(|w| w.cc1s().trc());
            t4.ccer().write(|w| w.cc1e().set_bit());
            t4.egr().write(|w| w.ug().set_bit());
            t4.sr().write(|w| w.bits(0));
            t4.cr1().write(|w| w.cen().set_bit());
        }
        let k = read_raw!(pac::TIM2, pac::TIM5);
        let h = read_raw!(pac::TIM3, pac::TIM4);
        Self {
            _knee: knee,
            _hip: hip,
            knee: QepState::new(true, k),
            hip: QepState::new(false, h),
        }
    }
}

impl EncoderIn for Encoders {
    fn sample(&mut self, joint: Joint) -> QepSample {
        match joint {
            Joint::Knee => {
                let r = read_raw!(pac::TIM2, pac::TIM5);
                self.knee.update(r)
            }
            Joint::Hip => {
                let r = read_raw!(pac::TIM3, pac::TIM4);
                self.hip.update(r)
            }
        }
    }
}
