//! WS2812B LED rings driven the report's way: a PWM timer whose compare register is fed by
//! DMA, one duty value per bit (GRB, MSB first), so a `0` is a short high pulse (T0H), a `1`
//! a long one (T1H), and a run of zero-duty periods at the end is the reset/latch (> 50 µs).
//! The encoder produces that buffer of duty values; the LED task chooses the colour from
//! the system state and restarts a transfer every 33 ms.

use super::codes::{self, SystemState};

/// A colour.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Rgb {
    /// Red 0–255.
    pub r: u8,
    /// Green 0–255.
    pub g: u8,
    /// Blue 0–255.
    pub b: u8,
}

impl Rgb {
    /// A colour from its components.
    pub const fn new(r: u8, g: u8, b: u8) -> Self {
        Self { r, g, b }
    }
}

/// Colour in PRE-OP / before every task started (blue).
pub const COLOR_PREOP: Rgb = Rgb::new(0, 0, 96);
/// Colour in OP without errors (green).
pub const COLOR_NORMAL: Rgb = Rgb::new(0, 96, 0);
/// Colour with a soft error (amber).
pub const COLOR_WARNING: Rgb = Rgb::new(128, 64, 0);
/// Colour with a hard error (red).
pub const COLOR_ERROR: Rgb = Rgb::new(160, 0, 0);

/// WS2812B nominal timing (datasheet): bit period 1.25 µs, T0H 0.4 µs, T1H 0.8 µs, reset
/// low above 50 µs; tolerance ±150 ns on the high and low times.
pub const T_BIT_NS: u64 = 1250;
/// Nominal high time of a 0 bit.
pub const T0H_NS: u64 = 400;
/// Nominal high time of a 1 bit.
pub const T1H_NS: u64 = 800;
/// Minimum reset (latch) low time.
pub const RESET_NS: u64 = 50_000;

/// A PWM timer set up for WS2812: its clock and the ticks per bit / per high time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PwmTiming {
    /// Timer clock in Hz.
    pub clock_hz: u32,
    /// Ticks per bit (ARR + 1).
    pub period: u16,
    /// Compare value of a 0.
    pub t0h: u16,
    /// Compare value of a 1.
    pub t1h: u16,
    /// Zero-duty periods appended as reset (≥ 60 µs, margin over 50 µs).
    pub reset_slots: u16,
}

const fn ticks(clock_hz: u32, ns: u64) -> u16 {
    ((clock_hz as u64 * ns + 500_000_000) / 1_000_000_000) as u16
}

impl PwmTiming {
    /// The timing for a timer clocked at `clock_hz` (rounded to whole ticks).
    pub const fn for_clock(clock_hz: u32) -> Self {
        let period = ticks(clock_hz, T_BIT_NS);
        Self {
            clock_hz,
            period,
            t0h: ticks(clock_hz, T0H_NS),
            t1h: ticks(clock_hz, T1H_NS),
            reset_slots: (60_000u64.div_ceil(T_BIT_NS)) as u16,
        }
    }

    /// Duration of `n` ticks in ns.
    pub const fn ns(&self, n: u16) -> u64 {
        n as u64 * 1_000_000_000 / self.clock_hz as u64
    }
}

/// The hub's timers (TIM3 on APB1 ×2 of the STM32F446 at 180 MHz: 90 MHz).
pub const HUB_TIMING: PwmTiming = PwmTiming::for_clock(90_000_000);

/// LEDs per ring (report `NUM_OF_LEDS_PER_RING 5`).
pub const LEDS_PER_RING: usize = 5;
/// Rings driven (report `NUM_OF_LEDRINGS 2`, at most `MAX_OF_LEDRINGS 4`).
pub const RINGS: usize = 2;
/// Duty values per ring buffer.
pub const RING_SLOTS: usize = LEDS_PER_RING * 24 + 48;

/// Encodes `colors` into duty values (GRB, MSB first, then the reset slots); returns how
/// many were written, or `None` when `out` is too small.
pub fn encode(colors: &[Rgb], t: &PwmTiming, out: &mut [u16]) -> Option<usize> {
    let n = colors.len() * 24 + t.reset_slots as usize;
    if out.len() < n {
        return None;
    }
    let mut k = 0;
    for c in colors {
        for byte in [c.g, c.r, c.b] {
            for i in (0..8).rev() {
                out[k] = if byte >> i & 1 != 0 { t.t1h } else { t.t0h };
                k += 1;
            }
        }
    }
    out[k..n].fill(0);
    Some(n)
}

/// PWM + DMA channels of the LED rings, and the one-shot guard timer of their transfers.
pub trait LedStrip {
    /// Why a channel could not be set up, a transfer started or the guard timer armed.
    type Error: core::fmt::Debug;

    /// Sets up ring `ring`'s PWM timer channel and DMA stream (the report's
    /// `ledDMA_configCh`).
    fn configure(&mut self, ring: usize) -> Result<(), Self::Error>;

    /// Aborts ring `ring`'s transfer and resets its channel after a fault (the report's
    /// `ledDMA_restartCH`); it is configured again before the next transfer.
    fn restart(&mut self, ring: usize);

    /// Starts the DMA transfer of `duties` to ring `ring` (returns at once).
    fn start(&mut self, ring: usize, duties: &[u16]) -> Result<(), Self::Error>;

    /// True once the last transfer of `ring` completed (DMA transfer-complete flag).
    fn done(&mut self, ring: usize) -> bool;

    /// Arms the one-shot timer that bounds the transfers just started to `ms` (the report's
    /// `timeoutLed` osTimer; on the MCU an alarm of the timer queue, which can refuse).
    fn arm_guard(&mut self, ms: u32) -> Result<(), Self::Error>;

    /// True once the armed guard timer expired.
    fn guard_expired(&mut self) -> bool;
}

/// The LED task's period (report Table 4.2): 33 ms.
pub const LED_PERIOD_MS: u32 = 33;
/// A transfer not complete after this long is `ERR_LED_TIMEOUT` (report: 1000 ms).
pub const LED_TIMEOUT_MS: u32 = 1000;
/// Channel restarts in a row without a frame delivered that make the LED task itself
/// faulty (`ERR_LED_DSM_FAULT`, hard): the report's L_restart loop would spin for ever.
pub const LED_DSM_FAULT_RESTARTS: u32 = 3;

/// What the LEDs show.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shown {
    /// Not yet configured.
    Off,
    /// Pre-op colour.
    PreOp,
    /// Normal colour.
    Normal,
    /// Warning colour.
    Warning,
    /// Error colour.
    Error,
    /// The master's colour.
    Custom(Rgb),
}

impl Shown {
    /// The colour of this choice.
    pub const fn color(self) -> Rgb {
        match self {
            Shown::Off => Rgb::new(0, 0, 0),
            Shown::PreOp => COLOR_PREOP,
            Shown::Normal => COLOR_NORMAL,
            Shown::Warning => COLOR_WARNING,
            Shown::Error => COLOR_ERROR,
            Shown::Custom(c) => c,
        }
    }
}

/// The report's colour priority (`L_updateColorState`): error, then init (the pre-op
/// colour until every task started), then the master's commands (LEDs toggled off, a custom
/// colour), then warning, then normal. The ESC side adds the report's INIT warning: once
/// started, a node whose ESM is (or was, since it last reached OP) in INIT shows the
/// warning colour (`EV_ECAT_APP_INIT` sets the report's `warningFlag`, `EV_ECAT_APP_OP`
/// clears it); PRE-OP/SAFE-OP reached without passing INIT show the pre-op colour.
/// `lit` is false while the master has toggled the rings off (hard errors still show).
pub fn choose(sys: &SystemState, op: bool, custom: Option<Rgb>, lit: bool) -> Shown {
    if sys.hard() {
        Shown::Error
    } else if !sys.started() {
        Shown::PreOp
    } else if !op {
        if sys.ecat_init_warning() {
            Shown::Warning
        } else {
            Shown::PreOp
        }
    } else if !lit {
        Shown::Off
    } else if let Some(c) = custom {
        Shown::Custom(c)
    } else if sys.soft() {
        Shown::Warning
    } else {
        Shown::Normal
    }
}

/// The LED task (the report's LED SDM): `L_config` → `L_send` (arm the guard timer) →
/// wait for the DMA → colour → … ; any fault goes through `L_restart` (every channel
/// restarted, then configured again at the next release).
#[derive(Debug, Clone)]
pub struct LedTask {
    buf: [[u16; RING_SLOTS]; RINGS],
    configured: bool,
    in_flight: bool,
    init: bool,
    /// Codes posted in the current fault episode (each once), bit per code.
    episode: u8,
    faulted: bool,
    consecutive: u32,
    /// What the rings were last sent.
    pub shown: Shown,
    /// Transfers started.
    pub sent: u32,
    /// Channel restarts (`L_restart`) after a fault.
    pub restarts: u32,
}

impl Default for LedTask {
    fn default() -> Self {
        Self {
            buf: [[0; RING_SLOTS]; RINGS],
            configured: false,
            in_flight: false,
            init: false,
            episode: 0,
            faulted: false,
            consecutive: 0,
            shown: Shown::Off,
            sent: 0,
            restarts: 0,
        }
    }
}

impl LedTask {
    fn post_once(&mut self, sys: &mut SystemState, code: u16) {
        let bit = match code {
            codes::ERR_LED_INIT => 1,
            codes::ERR_LED_SEND => 2,
            codes::ERR_LED_OSTIM => 4,
            codes::ERR_LED_TIMEOUT => 8,
            _ => 16,
        };
        if self.episode & bit == 0 {
            self.episode |= bit;
            sys.post(code);
        }
    }

    /// `L_restart`: every channel restarted and configured again at the next release; too
    /// many restarts in a row make the task faulty.
    fn restart<L: LedStrip>(&mut self, strip: &mut L, sys: &mut SystemState, code: u16) {
        self.post_once(sys, code);
        for r in 0..RINGS {
            strip.restart(r);
        }
        self.configured = false;
        self.in_flight = false;
        self.faulted = true;
        self.restarts = self.restarts.wrapping_add(1);
        self.consecutive += 1;
        if self.consecutive == LED_DSM_FAULT_RESTARTS {
            sys.post(codes::ERR_LED_DSM_FAULT);
        }
    }

    /// True while the task is between a fault and the next frame delivered.
    pub fn faulted(&self) -> bool {
        self.faulted
    }

    /// One release (every [`LED_PERIOD_MS`]).
    pub fn run<L: LedStrip>(&mut self, strip: &mut L, sys: &mut SystemState, shown: Shown) {
        if !self.configured {
            // L_config: every ring, so that one bad channel does not hide another.
            let failed = (0..RINGS).filter(|&r| strip.configure(r).is_err()).count();
            let ok = failed == 0;
            if !ok {
                self.restart(strip, sys, codes::ERR_LED_INIT);
                return;
            }
            self.configured = true;
            if !self.init {
                self.init = true;
                sys.post(codes::EV_LED_DSM_INIT);
            }
        }
        if self.in_flight {
            if !(0..RINGS).all(|r| strip.done(r)) {
                if strip.guard_expired() {
                    self.restart(strip, sys, codes::ERR_LED_TIMEOUT);
                }
                return;
            }
            self.in_flight = false;
            if self.faulted {
                // A frame delivered after a fault: the channels work again.
                self.faulted = false;
                self.episode = 0;
                self.consecutive = 0;
                sys.post(codes::EV_LED_UPTD);
            }
        }
        let colors = [shown.color(); LEDS_PER_RING];
        let mut ok = true;
        for r in 0..RINGS {
            if encode(&colors, &HUB_TIMING, &mut self.buf[r]).is_none()
                || strip.start(r, &self.buf[r]).is_err()
            {
                ok = false;
            }
        }
        if !ok {
            self.restart(strip, sys, codes::ERR_LED_SEND);
            return;
        }
        self.in_flight = true;
        if strip.arm_guard(LED_TIMEOUT_MS).is_err() {
            // The report's l_waitRefresh: a timer that cannot be started is L_restart.
            self.restart(strip, sys, codes::ERR_LED_OSTIM);
            return;
        }
        self.sent = self.sent.wrapping_add(1);
        self.shown = shown;
    }
}
