//! Distributed Clocks of one ESC: local clock with drift, port receive times, system time
//! with offset and delay, the time-control loop, SYNC0/SYNC1 generation and latch inputs.
//!
//! CONTRACT (the ESC core calls exactly these; `regs` is the ESC's register file
//! 0x0000..0x1000, `t` is global (virtual) time in ns, monotonic across calls):
//! - `Dc::new(cfg)`
//! - `frame_arrival(regs, port, t)`: first bit of a frame reaches `port` at `t` (called for
//!   every port a frame enters, before any processing; port 0 = processing-unit direction).
//! - `before_read(regs, addr, len, t)`: the ESC is about to read `regs[addr..addr+len]`
//!   (ECAT or PDI) for a frame/access at `t`: refresh live DC registers in that range.
//!   For ECAT accesses `t` should be the frame's arrival time at port 0 (the ESC latches
//!   the system time read by a frame at the frame's start, as the datasheet says).
//! - `after_write(regs, addr, len, t, from_ecat)`: bytes `regs[addr..addr+len]` were just
//!   written (the ESC core already stored them, honouring write permissions).
//! - `advance(regs, t) -> DcEvents`: move to time `t`; SYNC/latch events that happened in
//!   (previous t, t] are returned with their global times.
//! - `next_event(&self) -> Option<u64>`: global time of the next SYNC edge, if any.
//! - `local_time(t)`: the ESC's local time at global time `t`.
//!
//! ADDITIONS (also to be called by the ESC core):
//! - `after_read(regs, addr, len, t, from_ecat)`: bytes were read. Needed for the
//!   read-to-clear registers: a PDI read of 0x098E/0x098F acknowledges SYNC0/SYNC1 in
//!   acknowledge mode (pulse length 0x0982 = 0); a read of a latch time (0x09B0/0x09B8/
//!   0x09C0/0x09C8) by the side owning that latch unit (0x0980 bits 4/5) clears the
//!   single-event status bit in 0x09AE/0x09AF.
//! - `latch_input(regs, n, level, t)`: LATCH0/LATCH1 input pin `n` has `level` from `t` on.
//! - `sync_levels()`: SYNC0/SYNC1 output levels (for `Esc::sync_lines`).
//! - `al_event_bits()` / `ecat_event_bits()`: what the core ORs into the AL event request
//!   0x0220 (bit 1 DC latch event of PDI-owned latch units, bit 2 SYNC0 status 0x098E.0,
//!   bit 3 SYNC1 status 0x098F.0; the core gates bits 2/3 with 0x0151 bits 3/7) and the
//!   ECAT event request 0x0210 (bit 0 DC latch event of ECAT-owned latch units). The core
//!   refreshes them after every `advance`, `after_read`, `after_write` and `latch_input`.
//! - `reset(regs)`: power-on values of the DC registers (done lazily on the first call that
//!   gets `regs` otherwise). 0x0982 (pulse length, from the EEPROM) is never written here.
//!
//! MODEL
//! - Oscillator: `osc(t) = start_offset_ns + t + floor(t * drift)`, exact in integers
//!   (drift kept in parts per 10^12).
//! - Local time = oscillator + correction of the time-control loop. The correction is an
//!   exact fixed-point integral of a rate (2^-40 ns per oscillator ns) and is applied in
//!   whole nanoseconds, like silicon adding 9 or 11 ns instead of 10 ns on some ticks.
//!   Its magnitude is limited to one nanosecond per 127 ticks of 10 ns (≈787 ppm), the
//!   shortest speed-counter period (0x0932 range ±(0x0930 − 0x7F)).
//! - System time = local time + offset (0x0920), 64 bit wrapping.
//! - An ECAT write to 0x0910..0x0913 feeds the loop: Δt = (system time at the frame's
//!   arrival − delay 0x0928) − written value, compared in 32 bit; positive = local copy
//!   ahead. 0x092C holds the mean Δt (exponential average of depth 2^0x0934[3:0]) in
//!   sign-magnitude form (bit 31 set = local copy smaller than received). The rate is set by
//!   a proportional-integral law with time constant τ = 0x0930 × 24 414 ns (≈100 ms at the
//!   reset value 0x1000; larger value = smaller bandwidth, as documented): rate =
//!   −(2/τ·Δt + 1/τ²·Σ Δt·h) with h the time since the previous write (h limited to τ/4,
//!   the proportional gain limited to 1/(2h) so sparse writes stay stable). No step
//!   correction is ever applied: convergence from ±100 ppm takes on the order of a thousand
//!   1 ms writes. 0x0932 shows the rate as a speed-counter value: ±(0x0930 − P) where P is
//!   the number of 10 ns ticks between 1 ns corrections (0 when P ≥ 0x0930).
//!   Writing 0x0930 resets the mean, the integral and the rate.
//! - SYNC: on activation (0x0981.0 0→1) the first SYNC0 pulse is at the start time 0x0990
//!   if it is in the near future; ET1100 compares the start time in 32 bit, so a start time
//!   in the past fires only when the lower 32 bits of the system time come round again
//!   (≈4.3 s later) — see [`Dc::set_start_time_compare_bits`]. With the plausibility check
//!   (0x0981.5) a start time outside the near future fires immediately and sets 0x0984.2.
//!   Pulses then follow every SYNC0 cycle time (0 = single shot). SYNC1: cycle time 0 =
//!   copy of SYNC0; otherwise a SYNC1 pulse SYNC1-cycle-time after the SYNC0 pulse that
//!   armed it, re-armed by the first SYNC0 pulse at or after that SYNC1 pulse. Pulse length
//!   0x0982 in 10 ns (system time); 0 = acknowledge mode (signal and status stay set until a
//!   PDI read of 0x098E/0x098F). If the system time jumps over several pulses (offset write)
//!   only one pulse is produced and the schedule continues from the next slot.
//! - 0x0990 reads back the system time of the next SYNC0 pulse while the unit is active,
//!   0x0998 the next SYNC1 pulse.

/// How an ESC's local oscillator deviates from ideal time.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ClockConfig {
    /// Oscillator error in parts per million (positive runs fast).
    pub drift_ppm: f64,
    /// Local time at global time zero, in ns (the ESC's power-on offset).
    pub start_offset_ns: u64,
}

/// The DC unit reports its SYNC edges in the ESC's one events type (the watchdog flags
/// stay false here).
pub use crate::EscEvents as DcEvents;

/// DC register addresses (0x0900..0x09FF): `oxicat_wire::regs::dc`.
pub mod reg {
    pub use oxicat_wire::regs::dc::*;
}

const BASE: usize = 0x0900;
const SHADOW_LEN: usize = 0x100;
/// Fixed-point shift of the correction rate (rate unit: 2^-40 ns per ns).
const Q: u32 = 40;
const ONE_Q: i128 = 1 << Q;
/// Largest correction rate: 1 ns per 127 ticks of 10 ns.
const MAX_RATE_Q: i64 = (1i64 << Q) / 1270;
/// τ per unit of Speed Counter Start, in ns (0x1000 → ≈100 ms).
const TAU_PER_UNIT_NS: u64 = 24_414;
/// Largest accepted oscillator error, in parts per 10^12 (±1 %).
const MAX_DRIFT_PPT: i64 = 10_000_000_000;
/// 10^12 (the drift's unit), signed.
const E12_I: i64 = 1_000_000_000_000;

/// The registers this unit maintains in its shadow (inclusive absolute address ranges).
const OWNED: [(usize, usize); 3] = [(0x0900, 0x0935), (0x0980, 0x0981), (0x0984, 0x09CF)];

/// Is `a` (absolute address) a register this unit maintains in its shadow?
#[cfg(test)]
fn owned(a: usize) -> bool {
    OWNED.iter().any(|&(lo, hi)| (lo..=hi).contains(&a))
}

/// `floor(t · drift_ppt / 10^12)`, exactly, without a 128-bit division: the quotient of
/// [`drift_split`].
#[inline]
fn drift_ns(t: u64, drift_ppt: i64) -> i64 {
    drift_split(t, drift_ppt).0
}

/// `t · drift_ppt` split as `q · 10^12 + r` with `0 ≤ r < 10^12`: `q` is
/// [`drift_ns`]`(t, drift_ppt)`, `r` what the clock's 64-bit evaluation relative to an
/// anchor needs ([`Dc::local_rel`]). With `t = a·10^12 + b` and `drift = h·10^6 + l`
/// (`0 ≤ b < 10^12`, `0 ≤ l < 10^6`, |h| ≤ 10^4 since |drift| ≤ 10^10):
/// `t·drift = a·drift·10^12 + b·h·10^6 + b·l`, and by nested flooring, keeping the
/// remainders: with `z = b·h + floor(b·l / 10^6) = w·10^6 + w_r` and `b·l mod 10^6 = y_r`,
/// `t·drift = (a·drift + w)·10^12 + w_r·10^6 + y_r`. Every product fits in 64 bits.
#[inline]
fn drift_split(t: u64, drift_ppt: i64) -> (i64, i64) {
    const E6: i64 = 1_000_000;
    const E12: u64 = 1_000_000_000_000;
    debug_assert!(drift_ppt.abs() <= MAX_DRIFT_PPT);
    let a = (t / E12) as i64;
    let b = (t % E12) as i64;
    let h = drift_ppt.div_euclid(E6);
    let l = drift_ppt.rem_euclid(E6);
    let bl = b as u64 * l as u64;
    let (y, yr) = ((bl / E6 as u64) as i64, (bl % E6 as u64) as i64);
    let z = b * h + y;
    let (w, wr) = (z.div_euclid(E6), z.rem_euclid(E6));
    (a * drift_ppt + w, wr * E6 + yr)
}

/// `t - anchor` as a signed distance when it is within ±2^62 (the range in which the
/// 64-bit clock evaluation is exact), else `None`.
#[inline(always)]
fn rel_time(t: u64, anchor: u64) -> Option<i64> {
    let k = t.wrapping_sub(anchor) as i64;
    // The wrapped difference is the true one iff the signs agree (|true difference| < 2^63).
    if (t >= anchor) != (k >= 0) || k.unsigned_abs() > 1 << 62 {
        return None;
    }
    Some(k)
}

/// The proportional-integral law of the time-control loop (see the module's MODEL):
/// the new integral of Δt·h and the rate (2^-40 ns per ns, within ±[`MAX_RATE_Q`]) after a
/// sample `dt` (ns) `h_raw` ns after the previous one (0: first sample), with time constant
/// `tau` ns (`tau ≥ 0x80 · 24 414`, from [`Dc::tau_ns`]):
/// `h = min(h_raw, τ/4)`, `integ += dt·h` (limited to ±MAX_RATE·τ²), `kp = min(2/τ, 1/(2h))`,
/// `rate = −(dt·kp + integ/τ²)`, all in 2^-40 fixed point with truncating divisions, as
/// `rate_law_wide` (tests) computes it in 128 bits. Here the divisions are 64-bit ones:
/// `2^41/τ` and `2^40/(2h) = 2^39/h` fit, and `trunc(integ·2^40/τ²)` is
/// `floor(floor(|integ|·2^40/τ)/τ)` with the sign, the inner quotient by long division
/// in two 20-bit steps (it is below 2^64 because |integ| ≤ MAX_RATE·τ²/2^40 < τ·2^24).
fn rate_law(integ: i128, dt: i64, h_raw: u64, tau: u64) -> (i128, i64) {
    let tau_i = tau as i128;
    let h = h_raw.min(tau / 4);
    let integ_max = ((MAX_RATE_Q as i128) * tau_i * tau_i) >> Q;
    let integ = (integ + dt as i128 * h as i128).clamp(-integ_max, integ_max);
    let mut kp = (2u64 << Q) / tau;
    if let Some(k) = (1u64 << (Q - 1)).checked_div(h_raw) {
        kp = kp.min(k);
    }
    let n = integ.unsigned_abs();
    let i = if n < (tau as u128) << 24 {
        let n = n as u64;
        let (a, b) = (n / tau, n % tau);
        let (c, d) = ((b << 20) / tau, (b << 20) % tau);
        let m = (a << Q) + (c << 20) + (d << 20) / tau;
        let i = (m / tau) as i128;
        if integ < 0 {
            -i
        } else {
            i
        }
    } else {
        // Not reached (the limit above keeps |integ| below τ·2^24); the 128-bit form.
        (integ << Q) / (tau_i * tau_i)
    };
    let p = dt as i128 * kp as i128;
    let rate = (-(p + i)).clamp(-(MAX_RATE_Q as i128), MAX_RATE_Q as i128) as i64;
    (integ, rate)
}

/// The former 128-bit form of [`rate_law`], kept as its reference.
#[cfg(test)]
fn rate_law_wide(integ: i128, dt: i64, h_raw: u64, tau: u64) -> (i128, i64) {
    let tau = tau as i128;
    let h = (h_raw as i128).min(tau / 4);
    let integ_max = ((MAX_RATE_Q as i128) * tau * tau) >> Q;
    let integ = (integ + dt as i128 * h).clamp(-integ_max, integ_max);
    let mut kp = 2 * ONE_Q / tau;
    if h_raw > 0 {
        kp = kp.min(ONE_Q / (2 * h_raw as i128));
    }
    let p = dt as i128 * kp;
    let i = (integ << Q) / (tau * tau);
    let rate = (-(p + i)).clamp(-(MAX_RATE_Q as i128), MAX_RATE_Q as i128) as i64;
    (integ, rate)
}

/// 0x0932 for a rate `rate_q` and speed counter start `start` (0x80..=0x7FFF): the signed
/// speed-counter value `±(start − P)`, P = 10 ns ticks per 1 ns correction
/// (`2^40 / (10·|rate|)`), 0 when `P ≥ start`, at most `start − 0x7F`.
fn speed_diff(rate_q: i64, start: u16) -> i16 {
    let start = start as i64;
    let r = rate_q.unsigned_abs();
    let diff = if r == 0 {
        0
    } else {
        // |rate| ≤ MAX_RATE_Q < 2^30: 10·r fits, and so does the quotient.
        let period = ((1u64 << Q) / r.saturating_mul(10)).min(i64::MAX as u64) as i64;
        if period >= start {
            0
        } else {
            (start - period).min(start - 0x7F)
        }
    };
    (if rate_q < 0 { -diff } else { diff }) as i16
}

/// Write mask of a DC register byte for a side, or `None` if that side may not write it.
fn write_mask(a: usize, ecat: bool, ctrl: u8) -> Option<u8> {
    let cyclic_owner_ecat = ctrl & 0x01 == 0;
    let latch_owner_ecat = |n: u8| ctrl & (0x10 << n) == 0;
    match a {
        0x0920..=0x092B if ecat => Some(0xFF),
        0x0930 if ecat => Some(0xFF),
        0x0931 if ecat => Some(0x7F),
        0x0934..=0x0935 if ecat => Some(0x0F),
        0x0980 if ecat => Some(0x31),
        0x0981 | 0x0990..=0x0997 | 0x09A0..=0x09A7 if ecat == cyclic_owner_ecat => Some(0xFF),
        0x09A8 if ecat == latch_owner_ecat(0) => Some(0x03),
        0x09A9 if ecat == latch_owner_ecat(1) => Some(0x03),
        _ => None,
    }
}

/// Overlap of `addr..addr+len` with `lo..=hi`.
fn overlaps(addr: u16, len: u16, lo: u16, hi: u16) -> bool {
    let (s, e) = (addr as u32, addr as u32 + len as u32);
    s <= hi as u32 && e > lo as u32
}

/// Does `addr..addr+len` contain all of `lo..=hi`?
fn covers(addr: u16, len: u16, lo: u16, hi: u16) -> bool {
    let (s, e) = (addr as u32, addr as u32 + len as u32);
    s <= lo as u32 && e > hi as u32
}

/// `a - b` of two wrapping 64-bit times as a signed distance.
fn sdiff(a: u64, b: u64) -> i64 {
    a.wrapping_sub(b) as i64
}

/// The SYNC output unit.
#[derive(Debug, Clone, Default)]
struct SyncUnit {
    /// Cyclic unit activated (0x0981.0).
    active: bool,
    /// System time of the next internal SYNC0 pulse.
    next0: Option<u64>,
    /// System time of the next SYNC1 pulse (None: waiting to be armed by SYNC0).
    next1: Option<u64>,
    /// System time at which the SYNC0 pulse ends.
    fall0: Option<u64>,
    /// System time at which the SYNC1 pulse ends.
    fall1: Option<u64>,
    /// SYNC0 output level.
    level0: bool,
    /// SYNC1 output level.
    level1: bool,
    /// First SYNC0 pulse still pending (0x0984.0).
    first0_pending: bool,
    /// First SYNC1 pulse still pending (0x0984.1).
    first1_pending: bool,
    /// Start time out of near future at activation (0x0984.2).
    start_out_of_range: bool,
}

/// [`Dc`]'s start-of-frame time before the first frame at port 0.
const NO_SOF: u64 = u64::MAX;

/// The DC unit. `repr(C)`, cache-line aligned: what every frame's arrival touches first,
/// in one cache line.
#[derive(Debug, Clone)]
#[repr(C, align(64))]
pub struct Dc {
    /// Arrival time of the last frame at port 0 ([`NO_SOF`]: none yet).
    sof0: u64,
    /// Ports (bit n) still to latch the receive time of the latch frame.
    latch_pending: u8,
    inited: bool,
    /// Ports (bit n) where a frame's arrival needs the register file
    /// ([`Dc::arrival_needs_regs`]): all before the first contact, then the armed
    /// receive-time latches (`latch_pending`); kept in step by [`Dc::sync_slow`].
    slow_ports: u8,
    cfg: ClockConfig,
    drift_ppt: i64,
    /// Global time of the last rate change.
    anchor_t: u64,
    /// Oscillator value at `anchor_t`.
    anchor_osc: i128,
    /// Correction accumulator at `anchor_t` (2^-40 ns).
    anchor_acc: i128,
    /// Current correction rate (2^-40 ns per oscillator ns).
    rate_q: i64,
    /// Local time at `anchor_t` without the fraction of the accumulator, wrapped to 64 bits
    /// (`(anchor_osc + anchor_acc >> 40) as u64`): the base of [`Dc::local_rel`].
    base_local: u64,
    /// Fraction of the accumulator at `anchor_t`: `anchor_acc mod 2^40`.
    acc_frac: i64,
    /// `anchor_t · drift_ppt mod 10^12` ([`drift_split`]).
    drift_rem: i64,
    /// System time offset (0x0920).
    offset: u64,
    /// System time delay (0x0928).
    delay: u32,
    /// Mean system time difference, 2^-16 ns.
    mean_q: i64,
    /// Integral of Δt over time (ns²).
    integ: i128,
    /// Global time of the previous system time write.
    last_sample: Option<u64>,
    /// Authoritative copy of the owned registers 0x0900..0x09FF.
    shadow: [u8; SHADOW_LEN],
    /// Start time as last written (0x0990).
    start_written: u64,
    /// Pulse length in 10 ns units (copy of 0x0982, refreshed by `ensure_init` before
    /// every use).
    pulse_len: u16,
    sync: SyncUnit,
    /// Latch input levels.
    latch_level: [bool; 2],
    /// Time up to which SYNC edges were processed.
    t_done: u64,
    /// Events found but not yet returned by `advance`.
    pending: DcEvents,
    /// Cached `next_event`.
    next_cache: Option<u64>,
    /// Memo of the last [`Dc::global_at_sys`] answer that was the earliest global time of
    /// its target: `(target, global time)`, for the current global → system time mapping
    /// (forgotten by every change of it: [`Dc::set_rate`], an offset write).
    edge_memo: Option<(u64, u64)>,
    /// Width of the start-time comparison (32 for ET1100, 64 for 64-bit compare).
    compare_bits: u32,
    /// Tests: take the general (slow) path everywhere a fast path exists, and compute
    /// every edge time afresh (no memo), to compare both.
    #[cfg(test)]
    slow: bool,
}

impl Dc {
    /// A DC unit with the given oscillator.
    pub fn new(cfg: ClockConfig) -> Self {
        let drift_ppt = (cfg.drift_ppm * 1e6) as i64;
        let drift_ppt = drift_ppt.clamp(-MAX_DRIFT_PPT, MAX_DRIFT_PPT);
        let mut dc = Self {
            cfg,
            drift_ppt,
            anchor_t: 0,
            anchor_osc: 0,
            anchor_acc: 0,
            rate_q: 0,
            base_local: 0,
            acc_frac: 0,
            drift_rem: 0,
            offset: 0,
            delay: 0,
            mean_q: 0,
            integ: 0,
            last_sample: None,
            sof0: NO_SOF,
            latch_pending: 0,
            slow_ports: 0xF,
            shadow: [0; SHADOW_LEN],
            start_written: 0,
            pulse_len: 0,
            sync: SyncUnit::default(),
            latch_level: [false; 2],
            t_done: 0,
            pending: DcEvents::default(),
            next_cache: None,
            edge_memo: None,
            compare_bits: 32,
            inited: false,
            #[cfg(test)]
            slow: false,
        };
        dc.anchor_osc = dc.osc(0);
        dc.rebase();
        dc.shadow_reset();
        dc
    }

    /// Width (32 or 64) of the start-time comparison of the SYNC unit (default 32, ET1100).
    pub fn set_start_time_compare_bits(&mut self, bits: u32) {
        self.compare_bits = if bits >= 64 { 64 } else { 32 };
    }

    fn shadow_reset(&mut self) {
        self.shadow = [0; SHADOW_LEN];
        self.put16(0x0930, 0x1000);
        self.shadow[0x34] = 0x04;
        self.shadow[0x35] = 0x0C;
    }

    /// Write the power-on values of the DC registers into `regs`.
    pub fn reset(&mut self, regs: &mut [u8]) {
        let cfg = self.cfg;
        let bits = self.compare_bits;
        #[cfg(test)]
        let slow = self.slow;
        *self = Self::new(cfg);
        self.compare_bits = bits;
        #[cfg(test)]
        {
            self.slow = slow;
        }
        self.inited = true;
        self.sync_slow();
        self.pulse_len = rd16(regs, 0x0982);
        self.publish(regs);
    }

    /// First contact with the register file: power-on values, except for bytes
    /// `keep.0..keep.1` that the caller is about to process.
    fn ensure_init_keep(&mut self, regs: &mut [u8], keep: (usize, usize)) {
        if !self.inited {
            self.inited = true;
            self.sync_slow();
            self.publish_range(regs, BASE, keep.0.clamp(BASE, BASE + SHADOW_LEN));
            self.publish_range(
                regs,
                keep.1.clamp(BASE, BASE + SHADOW_LEN),
                BASE + SHADOW_LEN,
            );
        }
        self.pulse_len = rd16(regs, 0x0982);
    }

    fn ensure_init(&mut self, regs: &mut [u8]) {
        self.ensure_init_keep(regs, (0, 0));
        self.pulse_len = rd16(regs, 0x0982);
    }

    // ---------------------------------------------------------------- clock

    /// Oscillator value (ns) at global time `t`.
    fn osc(&self, t: u64) -> i128 {
        self.cfg.start_offset_ns as i128 + t as i128 + drift_ns(t, self.drift_ppt) as i128
    }

    fn acc_at(&self, t: u64) -> i128 {
        self.anchor_acc + self.rate_q as i128 * (self.osc(t) - self.anchor_osc)
    }

    /// The ESC's local time (oscillator plus control-loop correction) at global time `t`.
    #[inline]
    pub fn local_time(&self, t: u64) -> u64 {
        match self.local_rel(t) {
            Some(f) => self.base_local.wrapping_add(f as u64),
            None => self.local_time_wide(t),
        }
    }

    /// [`local_time`](Self::local_time) in 128-bit arithmetic, for any `t` (the model's
    /// definition; [`Dc::local_rel`] is the same in 64 bits near the anchor).
    fn local_time_wide(&self, t: u64) -> u64 {
        (self.osc(t) + (self.acc_at(t) >> Q)) as u64
    }

    /// The derived anchor values of the 64-bit evaluation, after every change of the
    /// anchor ([`Dc::set_rate`], [`Dc::new`]).
    fn rebase(&mut self) {
        self.base_local = (self.anchor_osc + (self.anchor_acc >> Q)) as u64;
        self.acc_frac = (self.anchor_acc & (ONE_Q - 1)) as i64;
        self.drift_rem = drift_split(self.anchor_t, self.drift_ppt).1;
    }

    /// The local time at `t` relative to [`Dc::base_local`], exactly, in 64-bit
    /// arithmetic, or `None` where that does not fit (`t` more than 2^62 ns from the
    /// anchor or a product overflowing; then [`Dc::local_time_wide`] is used).
    ///
    /// With `k = t − anchor_t`: the oscillator advanced by
    /// `Δ = k + floor((drift_rem + k·drift) / 10^12)` (as `drift_ns(t) − drift_ns(anchor_t)`,
    /// by the split of [`drift_split`]), and the accumulator by `rate·Δ`, so
    /// `local(t) = base_local + Δ + floor((acc_frac + rate·Δ) / 2^40)`.
    #[inline(always)]
    fn local_rel(&self, t: u64) -> Option<i64> {
        let (dosc, _, p) = self.local_parts(t)?;
        Some(dosc + (p >> Q))
    }

    /// The parts of [`Dc::local_rel`]: `(Δ, drift_rem + k·drift, acc_frac + rate·Δ)`.
    #[inline(always)]
    fn local_parts(&self, t: u64) -> Option<(i64, i64, i64)> {
        if !self.fast_paths() {
            return None;
        }
        let k = rel_time(t, self.anchor_t)?;
        let (dosc, m) = if self.drift_ppt == 0 {
            (k, 0)
        } else {
            let m = k.checked_mul(self.drift_ppt)?.checked_add(self.drift_rem)?;
            (k + m.div_euclid(E12_I), m)
        };
        let p = self.rate_q.checked_mul(dosc)?.checked_add(self.acc_frac)?;
        Some((dosc, m, p))
    }

    /// The local copy of the system time (local time + offset) at global time `t`.
    pub fn system_time(&self, t: u64) -> u64 {
        self.local_time(t).wrapping_add(self.offset)
    }

    /// Current correction rate of the time-control loop, in parts per 10^9 (diagnostics).
    pub fn correction_ppb(&self) -> i64 {
        ((self.rate_q as i128 * 1_000_000_000) >> Q) as i64
    }

    fn set_rate(&mut self, t: u64, rate_q: i64) {
        self.edge_memo = None;
        let rate_q = rate_q.clamp(-MAX_RATE_Q, MAX_RATE_Q);
        if let Some((dosc, m, p)) = self.local_parts(t) {
            // Moving the anchor by the 64-bit parts (what `rebase` gives for the new
            // anchor): the oscillator and accumulator advance by Δ and rate·Δ, the new
            // fraction and base follow from `p = acc_frac + rate·Δ`, and the drift
            // remainder of `t` is that of `drift_rem + k·drift`.
            self.anchor_osc += dosc as i128;
            self.anchor_acc += self.rate_q as i128 * dosc as i128;
            self.base_local = self.base_local.wrapping_add((dosc + (p >> Q)) as u64);
            self.acc_frac = p & ((1i64 << Q) - 1);
            self.drift_rem = m.rem_euclid(E12_I);
            self.anchor_t = t;
            self.rate_q = rate_q;
            return;
        }
        self.anchor_acc = self.acc_at(t);
        self.anchor_osc = self.osc(t);
        self.anchor_t = t;
        self.rate_q = rate_q;
        self.rebase();
    }

    /// [`global_at_sys`](Self::global_at_sys), memoised: the system time is a
    /// non-decreasing function of global time for a given mapping (anchor, rate, offset),
    /// so if `g` is the earliest global time at which it reaches `target`, the answer for
    /// any `from` is `max(g, from)`. The SYNC unit asks for the same edge several times
    /// (finding it, then the next one, then `next_event`), each a bisection.
    fn global_at(&mut self, target: u64, from: u64) -> Option<u64> {
        if let Some((x, g)) = self.edge_memo {
            // (The general paths of the tests compute every answer, so that the
            // comparison checks the memo's invalidation too.)
            if x == target && self.fast_paths() {
                return Some(g.max(from));
            }
        }
        let g = self.global_at_sys(target, from)?;
        // `g > from`: the target was not reached at `from`, so `g` is its earliest time.
        if g > from {
            self.edge_memo = Some((target, g));
        }
        Some(g)
    }

    /// Earliest global time ≥ `from` at which the system time reaches `target`.
    fn global_at_sys(&self, target: u64, from: u64) -> Option<u64> {
        match self.global_at_sys_exact(target, from) {
            Some(g) => g,
            None => self.global_at_sys_search(target, from),
        }
    }

    /// [`global_at_sys`](Self::global_at_sys) solved in closed form, in 64-bit integers
    /// (`None`: out of that range, search instead).
    ///
    /// The local time relative to the anchor is `F(Δ) = Δ + floor((f + R·Δ) / 2^40)` of the
    /// oscillator's advance `Δ` (see [`Dc::local_rel`]; `f` = [`Dc::acc_frac`], `R` the
    /// rate), and `Δ(k) = k + floor((r + k·D) / 10^12)` of `k = g − anchor_t` (`r` =
    /// [`Dc::drift_rem`], `D` the drift). Both are floors of lines with positive slope
    /// (`2^40 + R > 0`, `10^12 + D > 0`), so the least `Δ` with `F(Δ) ≥ N` is
    /// `N − floor((N·R + f) / (2^40 + R))` and the least `k` with `Δ(k) ≥ Δ*` is
    /// `Δ* − floor((Δ*·D + r) / (10^12 + D))`. `N` is the target relative to the base:
    /// `F` at `from` plus the distance `d0` the search starts from.
    ///
    /// It is the search's answer: the search fails (`None`) only when a probe overflows
    /// `u64`, which cannot happen for `from ≤ 2^62` and `d0 ≤ 2^62` (slope ≥ 0.989, so every
    /// probe stays below `from + 1.012·d0 + 4`); above that the search runs.
    #[inline]
    fn global_at_sys_exact(&self, target: u64, from: u64) -> Option<Option<u64>> {
        if from > 1 << 62 {
            return None;
        }
        let f_from = self.local_rel(from)?;
        let s_from = self
            .base_local
            .wrapping_add(f_from as u64)
            .wrapping_add(self.offset);
        let d0 = sdiff(target, s_from);
        if d0 <= 0 {
            return Some(Some(from));
        }
        if d0 > (1i64 << 62) {
            return Some(None);
        }
        let n = f_from.checked_add(d0)?;
        let m = n.checked_mul(self.rate_q)?.checked_add(self.acc_frac)?;
        let dosc = n.checked_sub(m.div_euclid((1i64 << Q) + self.rate_q))?;
        let k = if self.drift_ppt == 0 {
            dosc
        } else {
            let m = dosc
                .checked_mul(self.drift_ppt)?
                .checked_add(self.drift_rem)?;
            dosc.checked_sub(m.div_euclid(E12_I + self.drift_ppt))?
        };
        let g = self.anchor_t.checked_add_signed(k)?;
        Some(Some(g.max(from)))
    }

    /// [`global_at_sys`](Self::global_at_sys) by search, for any `from` and clock.
    #[cold]
    #[inline(never)]
    fn global_at_sys_search(&self, target: u64, from: u64) -> Option<u64> {
        let d0 = sdiff(target, self.system_time(from));
        if d0 <= 0 {
            return Some(from);
        }
        if d0 > (1i64 << 62) {
            return None;
        }
        let mut lo = from;
        let mut hi = from.checked_add(d0 as u64)?;
        let over = loop {
            let d = sdiff(target, self.system_time(hi));
            if d <= 0 {
                break d.unsigned_abs();
            }
            lo = hi;
            hi = hi.checked_add(d as u64)?;
        };
        // Now the system time is before `target` at `lo` and has reached it at `hi`; it is
        // non-decreasing, so the answer is the one step in (lo, hi]. The slope is one
        // within ±1 % (drift) and ±0.08 % (correction), so a probe `d` ns away from the
        // target puts the step about `d` ns away: probe there (Newton with slope one),
        // keeping the bracket (a guess outside it is moved to its nearest inner point), and
        // halve the bracket when that does not settle within a few probes.
        let mut guess = hi.saturating_sub(over.max(1));
        let mut newton = 0u32;
        while hi - lo > 1 {
            let x = if newton < 8 {
                newton += 1;
                guess.clamp(lo + 1, hi - 1)
            } else {
                lo + (hi - lo) / 2
            };
            let d = sdiff(target, self.system_time(x));
            if d <= 0 {
                hi = x;
                guess = x.saturating_sub(d.unsigned_abs().max(1));
            } else {
                lo = x;
                guess = x.saturating_add(d as u64);
            }
        }
        Some(hi)
    }

    // ------------------------------------------------------ time control loop

    fn tau_ns(&self) -> u64 {
        let start = (self.get16(0x0930) & 0x7FFF).max(0x80) as u64;
        start * TAU_PER_UNIT_NS
    }

    /// An ECAT write of `received` to the system time at global time `t`.
    fn time_control(&mut self, t: u64, received: u32) {
        let local = (self.system_time(t) as u32).wrapping_sub(self.delay);
        let dt = local.wrapping_sub(received) as i32 as i64;

        let depth = (self.shadow[0x34] & 0x0F) as u32;
        self.mean_q += ((dt << 16) - self.mean_q) >> depth;
        let mean = self.mean_q / (1 << 16);
        let mag = (mean.unsigned_abs()).min(0x7FFF_FFFF) as u32;
        let sm = if mean < 0 { mag | 0x8000_0000 } else { mag };
        self.put32(0x092C, sm);

        let tau = self.tau_ns();
        let h_raw = match self.last_sample {
            Some(p) if t > p => t - p,
            _ => 0,
        };
        self.last_sample = Some(t);
        #[cfg(test)]
        let (integ, rate) = if self.slow {
            rate_law_wide(self.integ, dt, h_raw, tau)
        } else {
            rate_law(self.integ, dt, h_raw, tau)
        };
        #[cfg(not(test))]
        let (integ, rate) = rate_law(self.integ, dt, h_raw, tau);
        self.integ = integ;
        self.set_rate(t, rate);
        self.publish_speed_diff();
    }

    fn publish_speed_diff(&mut self) {
        let start = (self.get16(0x0930) & 0x7FFF).max(0x80);
        let v = speed_diff(self.rate_q, start);
        self.put16(0x0932, v as u16);
    }

    fn reset_filters(&mut self, t: u64) {
        self.mean_q = 0;
        self.integ = 0;
        self.last_sample = None;
        self.set_rate(t, 0);
        self.put32(0x092C, 0);
        self.put16(0x0932, 0);
    }

    // ------------------------------------------------------------- contract

    /// Whether [`Dc::frame_arrival`] at `port` needs the register file: the unit's first
    /// contact, or a receive-time latch armed for the port (1..3). Otherwise
    /// [`Dc::frame_arrival_quiet`] has the same effect.
    #[inline(always)]
    pub(crate) fn arrival_needs_regs(&self, port: u8) -> bool {
        self.slow_ports & (1 << (port & 3)) != 0
    }

    /// Whether a frame's arrival at port 0 needs more than the start-of-frame time
    /// (which the ESC may then keep itself, [`Dc::set_sof0`]): before the first contact,
    /// or with a receive-time latch armed at any port (which port 0's arrival ends).
    #[inline(always)]
    pub(crate) fn arrival0_needs_more(&self) -> bool {
        self.slow_ports != 0
    }

    /// Sets the start-of-frame time at port 0 (the ESC keeps it for the frames whose
    /// arrival it handles itself, see [`Dc::arrival0_needs_more`], and hands it over
    /// before a register write that reads it).
    #[inline]
    pub(crate) fn set_sof0(&mut self, t: u64) {
        self.sof0 = t;
    }

    /// Brings [`Dc::slow_ports`] in step with `inited` and `latch_pending` (after every
    /// change of either).
    #[inline(always)]
    fn sync_slow(&mut self) {
        self.slow_ports = if self.inited {
            self.latch_pending & 0b1110
        } else {
            0xF
        };
    }

    /// [`Dc::frame_arrival`] when [`Dc::arrival_needs_regs`] is false: at port 0 the start
    /// of frame (and the end of the latch window), at the other ports nothing.
    #[inline(always)]
    pub(crate) fn frame_arrival_quiet(&mut self, port: u8, t: u64) {
        if port == 0 {
            self.sof0 = t;
            self.latch_pending = 0;
            self.slow_ports = 0;
        }
    }

    /// `frame_arrival` at port 0 (the ESC's fused frame path): the same effects, inlined.
    #[inline(always)]
    pub fn frame_arrival_port0(&mut self, regs: &mut [u8], t: u64) {
        if !self.inited {
            self.ensure_init(regs);
        }
        self.sof0 = t;
        self.latch_pending = 0;
        self.sync_slow();
    }

    /// First bit of a frame reached `port` at global time `t`. (The first contact
    /// initialises the unit; the pulse length copy is not refreshed here: every path that
    /// reads it — `catch_up` via `advance_slow`, `before_read`, `after_read`,
    /// `after_write` — refreshes it from 0x0982 first.)
    #[inline(always)]
    pub fn frame_arrival(&mut self, regs: &mut [u8], port: u8, t: u64) {
        if !self.inited {
            self.ensure_init(regs);
        }
        if port == 0 {
            self.sof0 = t;
            self.latch_pending = 0;
            self.sync_slow();
        } else if port < 4 && self.latch_pending & (1 << port) != 0 {
            self.latch_receive_time(regs, port, t);
        }
    }

    /// The receive time of the latch frame at `port` (1..3), armed by a write to 0x0900.
    #[cold]
    fn latch_receive_time(&mut self, regs: &mut [u8], port: u8, t: u64) {
        self.latch_pending &= !(1 << port);
        self.sync_slow();
        let lt = self.local_time(t) as u32;
        let a = 0x0900 + 4 * port as usize;
        self.put32(a, lt);
        self.publish_range(regs, a, a + 4);
    }

    /// Refresh live registers in `addr..addr+len` before they are read at `t`.
    pub fn before_read(&mut self, regs: &mut [u8], addr: u16, len: u16, t: u64) {
        if !overlaps(addr, len, 0x0900, 0x09FF) {
            return;
        }
        self.ensure_init(regs);
        self.catch_up(t);
        let time = overlaps(addr, len, 0x0910, 0x0917);
        if time {
            let s = self.system_time(t);
            self.put64(0x0910, s);
        }
        if self.fast_paths() {
            // Shadow and register file are in step (every change is published when it is
            // made, the first contact publishes everything) and catching up changes only
            // the SYNC unit's state, not the shadow: the system time is all that changed.
            if time {
                self.publish_range(regs, 0x0910, 0x0918);
            }
        } else {
            self.publish(regs);
        }
    }

    /// Bytes `addr..addr+len` were read at `t` by ECAT (`ecat`) or the PDI.
    pub fn after_read(&mut self, regs: &mut [u8], addr: u16, len: u16, t: u64, ecat: bool) {
        if !overlaps(addr, len, 0x0900, 0x09FF) {
            return;
        }
        self.ensure_init(regs);
        self.catch_up(t);
        let mut changed = false;
        if !ecat && self.pulse_len == 0 {
            if overlaps(addr, len, 0x098E, 0x098E) && self.sync.level0 {
                self.sync.level0 = false;
                changed = true;
            }
            if overlaps(addr, len, 0x098F, 0x098F) && self.sync.level1 {
                self.sync.level1 = false;
                changed = true;
            }
        }
        let ctrl = self.shadow[0x80];
        for n in 0..2u16 {
            let owner_ecat = ctrl & (0x10 << n) == 0;
            if owner_ecat != ecat {
                continue;
            }
            let st = 0xAE + n as usize;
            if overlaps(addr, len, 0x09B0 + 16 * n, 0x09B7 + 16 * n) && self.shadow[st] & 1 != 0 {
                self.shadow[st] &= !1;
                changed = true;
            }
            if overlaps(addr, len, 0x09B8 + 16 * n, 0x09BF + 16 * n) && self.shadow[st] & 2 != 0 {
                self.shadow[st] &= !2;
                changed = true;
            }
        }
        if changed {
            self.update_status();
            self.publish(regs);
            self.refresh_next();
        }
    }

    /// React to bytes `addr..addr+len` that were just written.
    pub fn after_write(&mut self, regs: &mut [u8], addr: u16, len: u16, t: u64, ecat: bool) {
        if !overlaps(addr, len, 0x0900, 0x09FF) {
            return;
        }
        if self.inited && addr >= 0x0910 && addr as u32 + len as u32 <= 0x0918 && self.fast_paths()
        {
            self.system_time_written(regs, addr, len, t, ecat);
            return;
        }
        self.ensure_init_keep(regs, (addr as usize, addr as usize + len as usize));
        self.catch_up(t);
        let old_act = self.shadow[0x81];
        let start_addr = (addr as usize).max(BASE);
        let end_addr = (addr as usize + len as usize).min(BASE + SHADOW_LEN);
        let ctrl = self.shadow[0x80];
        let mut wrote = [false; SHADOW_LEN];
        for a in start_addr..end_addr {
            if let (Some(m), Some(&v)) = (write_mask(a, ecat, ctrl), regs.get(a)) {
                let i = a - BASE;
                self.shadow[i] = v & m;
                wrote[i] = true;
                if (0x0990..0x0998).contains(&a) {
                    let sh = 8 * (a - 0x0990) as u32;
                    self.start_written =
                        (self.start_written & !(0xFFu64 << sh)) | ((v as u64) << sh);
                }
            }
        }
        // Frame time for ECAT writes: the frame's arrival at port 0.
        let tf = if ecat { self.ecat_frame_time(t) } else { t };
        if ecat && overlaps(addr, len, 0x0900, 0x0903) {
            let lt = self.local_time(tf);
            self.put32(0x0900, lt as u32);
            self.put64(0x0918, lt);
            self.latch_pending = 0b1110;
            self.sync_slow();
        }
        if ecat && covers(addr, len, 0x0910, 0x0913) {
            let rx = rd32(regs, 0x0910);
            self.time_control(tf, rx);
        }
        if wrote[0x20..0x28].iter().any(|&w| w) {
            self.offset = self.get64(0x0920);
            self.edge_memo = None;
        }
        if wrote[0x28..0x2C].iter().any(|&w| w) {
            self.delay = self.get32(0x0928);
        }
        if wrote[0x30] || wrote[0x31] {
            self.reset_filters(t);
        }
        if (0xA8..0xAA).any(|i| wrote[i]) {
            for n in 0..2 {
                if wrote[0xA8 + n] {
                    self.shadow[0xAE + n] &= !0x03;
                }
            }
        }
        if wrote[0x81] {
            let new = self.shadow[0x81];
            self.shadow[0x81] = new & 0x7F;
            self.activation_written(t, old_act, new);
        } else if (0x90..0x98).any(|i| wrote[i]) && self.shadow[0x81] & 0x08 != 0 {
            // Auto-activation by writing the start time.
            if self.shadow[0x81] & 0x10 != 0 && !(0x94..0x98).any(|i| wrote[i]) {
                let now = self.system_time(t);
                let mut s = (now & !0xFFFF_FFFF) | (self.start_written & 0xFFFF_FFFF);
                if sdiff(s, now) < 0 {
                    s = s.wrapping_add(1 << 32);
                }
                self.start_written = s;
            }
            let act = self.shadow[0x81];
            self.shadow[0x81] = act | 0x01;
            self.activation_written(t, act & !0x01, act | 0x01);
        }
        let s = self.system_time(t);
        self.put64(0x0910, s);
        self.update_status();
        self.publish(regs);
        self.refresh_next();
    }

    /// [`after_write`](Self::after_write) of bytes within the system time 0x0910..0x0917
    /// after the first contact (the FRMW that distributes the reference time, every
    /// cycle): what the general path does for it. No side may write those bytes (they
    /// show the local copy of the system time), so nothing is stored in the shadow; an
    /// ECAT write of 0x0910..0x0913 feeds the time-control loop. Republished are the
    /// registers that changed: the system time, the loop's 0x092C..0x0933 and the SYNC
    /// status 0x0984..0x099F (the rest is in step, as every change is published when it
    /// is made).
    fn system_time_written(&mut self, regs: &mut [u8], addr: u16, len: u16, t: u64, ecat: bool) {
        self.pulse_len = rd16(regs, 0x0982);
        self.catch_up(t);
        if ecat && covers(addr, len, 0x0910, 0x0913) {
            let tf = self.ecat_frame_time(t);
            let rx = rd32(regs, 0x0910);
            self.time_control(tf, rx);
        }
        let s = self.system_time(t);
        self.put64(0x0910, s);
        self.update_status();
        self.publish_range(regs, 0x0910, 0x0934);
        self.publish_range(regs, 0x0984, 0x09A0);
        self.refresh_next();
    }

    /// The time of an ECAT write at `t`: the frame's arrival at port 0, unless that is
    /// unknown or before the last rate change.
    /// (`NO_SOF` is never <= t unless t is that value too: then both give t.)
    #[inline]
    fn ecat_frame_time(&self, t: u64) -> u64 {
        let s = self.sof0;
        if s <= t && s >= self.anchor_t {
            s
        } else {
            t
        }
    }

    /// Tests: the general paths everywhere (`true`) or the fast paths (see [`Dc::slow`]).
    #[cfg(test)]
    pub(crate) fn set_slow(&mut self, slow: bool) {
        self.slow = slow;
    }

    /// Whether the fast paths may be taken (always, except in tests that compare them
    /// with the general paths).
    #[inline(always)]
    fn fast_paths(&self) -> bool {
        #[cfg(test)]
        {
            !self.slow
        }
        #[cfg(not(test))]
        {
            true
        }
    }

    /// Advance to global time `t`.
    pub fn advance(&mut self, regs: &mut [u8], t: u64) -> DcEvents {
        if self.advance_quiet(t) {
            return DcEvents::default();
        }
        self.advance_slow(regs, t)
    }

    /// The fast path of [`advance`](Self::advance): `true` when it moved to `t` with no
    /// SYNC edge to process and nothing pending (then nothing but the time changed).
    ///
    /// This is the common case: no SYNC edge in (t_done, t], nothing pending. The shadow
    /// and the register file are already in step (every change since the last publication
    /// was published), so catching up, refreshing the status and republishing would change
    /// nothing. `next_cache` is the exact global time of the next edge (system time is
    /// monotonic and only re-anchored by writes, which refresh it), or it is stale-early
    /// after `before_read`/`after_read` processed an edge, in which case the slow path runs.
    #[inline(always)]
    pub(crate) fn advance_quiet(&mut self, t: u64) -> bool {
        if self.inited
            && self.pending.sync0.is_none()
            && self.pending.sync1.is_none()
            && match self.next_cache {
                Some(n) => t < n,
                None => !self.sync.active,
            }
        {
            self.t_done = self.t_done.max(t);
            return true;
        }
        false
    }

    /// The rest of [`advance`](Self::advance) (after [`advance_quiet`](Self::advance_quiet)
    /// said no).
    pub(crate) fn advance_slow(&mut self, regs: &mut [u8], t: u64) -> DcEvents {
        let was_inited = self.inited;
        self.ensure_init(regs);
        self.catch_up(t);
        self.update_status();
        if was_inited {
            // Shadow and register file were in step (every change is published when it is
            // made); catching up changes only the SYNC unit, which `update_status` shows in
            // 0x0984..0x099F.
            self.publish_range(regs, 0x0984, 0x09A0);
        } else {
            self.publish(regs);
        }
        self.refresh_next();
        core::mem::take(&mut self.pending)
    }

    /// Global time of the next SYNC edge (rising or falling).
    pub fn next_event(&self) -> Option<u64> {
        self.next_cache
    }

    /// SYNC0 and SYNC1 output levels as of the last call.
    pub fn sync_levels(&self) -> (bool, bool) {
        (self.sync.level0, self.sync.level1)
    }

    /// Bits this unit contributes to the AL event request 0x0220 (bits 1, 2, 3; ungated).
    pub fn al_event_bits(&self) -> u32 {
        let ctrl = self.shadow[0x80];
        let mut v = 0;
        for n in 0..2 {
            if ctrl & (0x10 << n) != 0 && self.shadow[0xAE + n] & 0x03 != 0 {
                v |= 1 << 1;
            }
        }
        if self.shadow[0x8E] & 1 != 0 {
            v |= 1 << 2;
        }
        if self.shadow[0x8F] & 1 != 0 {
            v |= 1 << 3;
        }
        v
    }

    /// Bits this unit contributes to the ECAT event request 0x0210 (bit 0: DC latch event).
    pub fn ecat_event_bits(&self) -> u16 {
        let ctrl = self.shadow[0x80];
        let mut v = 0;
        for n in 0..2 {
            if ctrl & (0x10 << n) == 0 && self.shadow[0xAE + n] & 0x03 != 0 {
                v |= 1;
            }
        }
        v
    }

    /// `(ecat_event_bits(), al_event_bits())` in one pass (the ESC core asks for both).
    #[inline]
    pub(crate) fn event_bits(&self) -> (u16, u32) {
        let ctrl = self.shadow[0x80];
        let latched0 = self.shadow[0xAE] & 0x03 != 0;
        let latched1 = self.shadow[0xAF] & 0x03 != 0;
        let pdi0 = ctrl & 0x10 != 0;
        let pdi1 = ctrl & 0x20 != 0;
        let al = (((latched0 && pdi0) || (latched1 && pdi1)) as u32) << 1
            | ((self.shadow[0x8E] & 1) as u32) << 2
            | ((self.shadow[0x8F] & 1) as u32) << 3;
        let ecat = ((latched0 && !pdi0) || (latched1 && !pdi1)) as u16;
        (ecat, al)
    }

    /// LATCH input `n` (0 or 1) changes to `level` at global time `t`.
    pub fn latch_input(&mut self, regs: &mut [u8], n: u8, level: bool, t: u64) {
        self.ensure_init(regs);
        let n = (n & 1) as usize;
        if self.latch_level[n] == level {
            return;
        }
        self.latch_level[n] = level;
        let ctrl = self.shadow[0xA8 + n];
        let st = 0xAE + n;
        let (single, bit, time_reg) = if level {
            (ctrl & 0x01 != 0, 0x01, 0x09B0 + 16 * n)
        } else {
            (ctrl & 0x02 != 0, 0x02, 0x09B8 + 16 * n)
        };
        let time = self.system_time(t);
        if single {
            if self.shadow[st] & bit == 0 {
                self.shadow[st] |= bit;
                self.put64(time_reg, time);
            }
        } else {
            self.put64(time_reg, time);
        }
        if level {
            self.shadow[st] |= 0x04;
        } else {
            self.shadow[st] &= !0x04;
        }
        self.publish(regs);
    }

    // ------------------------------------------------------------ SYNC unit

    fn activation_written(&mut self, t: u64, old: u8, new: u8) {
        if new & 0x01 == 0 {
            self.sync = SyncUnit::default();
            return;
        }
        if old & 0x01 == 0 {
            // Activation.
            let now = self.system_time(t);
            let w = self.compare_bits;
            let mask = if w >= 64 { u64::MAX } else { (1u64 << w) - 1 };
            let delta = self.start_written.wrapping_sub(now) & mask;
            let near = if new & 0x40 != 0 || w < 64 {
                1u64 << 31
            } else {
                1u64 << 63
            };
            let out = delta >= near;
            let first = if out && new & 0x20 != 0 {
                Some(now)
            } else if delta >= 1u64 << 62 {
                // 64-bit compare and a start time in the past: reached only after the
                // 64-bit system time wraps (centuries).
                None
            } else {
                Some(now.wrapping_add(delta))
            };
            self.sync = SyncUnit {
                active: true,
                next0: first,
                first0_pending: true,
                first1_pending: true,
                start_out_of_range: out,
                ..SyncUnit::default()
            };
        }
        if new & 0x02 == 0 {
            self.sync.level0 = false;
            self.sync.fall0 = None;
        }
        if new & 0x04 == 0 {
            self.sync.level1 = false;
            self.sync.fall1 = None;
        }
        if new & 0x80 != 0 {
            // Debug pulse: one immediate pulse on the enabled outputs.
            let now = self.system_time(t);
            self.rise(0, now, t, new);
            self.rise(1, now, t, new);
        }
    }

    /// A rising edge of SYNC`n` at system time `at` (global `g`), if enabled in `act`.
    fn rise(&mut self, n: usize, at: u64, g: u64, act: u8) {
        if act & (0x02 << n) == 0 {
            return;
        }
        let len = self.pulse_len as u64 * 10;
        let fall = if len == 0 {
            None
        } else {
            Some(at.wrapping_add(len))
        };
        let ev = if n == 0 {
            self.sync.level0 = true;
            self.sync.fall0 = fall;
            &mut self.pending.sync0
        } else {
            self.sync.level1 = true;
            self.sync.fall1 = fall;
            &mut self.pending.sync1
        };
        if ev.is_none() {
            *ev = Some(g);
        }
    }

    /// The earliest pending edge: (system time, kind). Kinds: 0 fall0, 1 fall1, 2 sync1, 3 sync0.
    fn next_edge(&self) -> Option<(u64, u8)> {
        if !self.sync.active {
            return None;
        }
        self.next_edge_from(self.system_time(self.t_done))
    }

    /// [`next_edge`](Self::next_edge) with the system time at `t_done` known
    /// (`reference`).
    #[inline]
    fn next_edge_from(&self, reference: u64) -> Option<(u64, u8)> {
        if !self.sync.active {
            return None;
        }
        let cands = [
            (self.sync.fall0, 0u8),
            (self.sync.fall1, 1),
            (self.sync.next1, 2),
            (self.sync.next0, 3),
        ];
        let mut best: Option<(i64, u64, u8)> = None;
        for (c, k) in cands {
            if let Some(x) = c {
                let key = sdiff(x, reference);
                if best.is_none_or(|(bk, _, _)| key < bk) {
                    best = Some((key, x, k));
                }
            }
        }
        best.map(|(_, x, k)| (x, k))
    }

    /// Process all SYNC edges up to global time `t`.
    fn catch_up(&mut self, t: u64) {
        let t = t.max(self.t_done);
        // `next_cache` is the global time of the next edge, or stale-early (at or before
        // `t_done`) after an edge was processed here; either way an edge in (t_done, t]
        // means `t >= next_cache`.
        if self.pending_free_until(t) {
            self.t_done = t;
            return;
        }
        let mut guard = 0u32;
        let mut next = self.next_edge();
        while let Some((x, kind)) = next {
            let Some(g) = self.global_at(x, self.t_done) else {
                break;
            };
            if g > t {
                break;
            }
            self.t_done = g;
            // The edge leaves the clock alone: its system time at `g` is the next
            // search's reference.
            let now = self.edge(x, kind, g);
            next = self.next_edge_from(now);
            guard += 1;
            if guard > 1_000_000 {
                break;
            }
        }
        self.t_done = t;
    }

    /// Processes the edge `kind` at system time `x`, global time `g`; returns the system
    /// time at `g`.
    fn edge(&mut self, x: u64, kind: u8, g: u64) -> u64 {
        let act = self.shadow[0x81];
        let now = self.system_time(g);
        match kind {
            0 => {
                self.sync.fall0 = None;
                self.sync.level0 = false;
            }
            1 => {
                self.sync.fall1 = None;
                self.sync.level1 = false;
            }
            2 => {
                self.sync.next1 = None;
                self.sync.first1_pending = false;
                self.rise(1, x, g, act);
            }
            _ => {
                let c0 = self.get32(0x09A0) as u64;
                let c1 = self.get32(0x09A4) as u64;
                self.sync.first0_pending = false;
                self.sync.next0 = if c0 == 0 {
                    None
                } else {
                    let mut n = x.wrapping_add(c0);
                    if sdiff(n, now) <= 0 {
                        let behind = sdiff(now, x) as u64;
                        n = x.wrapping_add(c0 * (behind / c0 + 1));
                    }
                    Some(n)
                };
                self.rise(0, x, g, act);
                if c1 == 0 {
                    self.sync.first1_pending = false;
                    self.rise(1, x, g, act);
                } else if self.sync.next1.is_none() {
                    self.sync.next1 = Some(x.wrapping_add(c1));
                }
            }
        }
        now
    }

    fn update_status(&mut self) {
        let s = self.sync.clone();
        let st = (s.active && s.first0_pending) as u8
            | ((s.active && s.first1_pending) as u8) << 1
            | (s.start_out_of_range as u8) << 2;
        self.shadow[0x84] = st;
        self.shadow[0x8E] = s.level0 as u8;
        self.shadow[0x8F] = s.level1 as u8;
        if s.active {
            if let Some(n0) = s.next0 {
                self.put64(0x0990, n0);
            }
            let c1 = self.get32(0x09A4);
            let n1 = if c1 == 0 { s.next0 } else { s.next1 };
            if let Some(n1) = n1 {
                self.put64(0x0998, n1);
            }
        } else {
            let sw = self.start_written;
            self.put64(0x0990, sw);
        }
    }

    /// No SYNC edge can fall in (t_done, t]: `t` is before the cached next edge, or the
    /// unit is off and has none.
    #[inline(always)]
    fn pending_free_until(&self, t: u64) -> bool {
        match self.next_cache {
            Some(n) => t < n,
            None => !self.sync.active,
        }
    }

    fn refresh_next(&mut self) {
        self.next_cache = match self.next_edge() {
            Some((x, _)) => self.global_at(x, self.t_done),
            None => None,
        };
    }

    // -------------------------------------------------------- register file

    fn publish(&self, regs: &mut [u8]) {
        self.publish_range(regs, BASE, BASE + SHADOW_LEN);
    }

    fn publish_range(&self, regs: &mut [u8], from: usize, to: usize) {
        // The owned ranges (see `owned`), copied as whole slices.
        for (lo, hi) in OWNED {
            let a = from.max(lo);
            let b = to.min(hi + 1).min(regs.len());
            if a < b {
                regs[a..b].copy_from_slice(&self.shadow[a - BASE..b - BASE]);
            }
        }
    }

    fn get16(&self, a: usize) -> u16 {
        let i = a - BASE;
        u16::from_le_bytes([self.shadow[i], self.shadow[i + 1]])
    }

    fn get32(&self, a: usize) -> u32 {
        let i = a - BASE;
        let mut b = [0; 4];
        b.copy_from_slice(&self.shadow[i..i + 4]);
        u32::from_le_bytes(b)
    }

    fn get64(&self, a: usize) -> u64 {
        let i = a - BASE;
        let mut b = [0; 8];
        b.copy_from_slice(&self.shadow[i..i + 8]);
        u64::from_le_bytes(b)
    }

    fn put16(&mut self, a: usize, v: u16) {
        let i = a - BASE;
        self.shadow[i..i + 2].copy_from_slice(&v.to_le_bytes());
    }

    fn put32(&mut self, a: usize, v: u32) {
        let i = a - BASE;
        self.shadow[i..i + 4].copy_from_slice(&v.to_le_bytes());
    }

    fn put64(&mut self, a: usize, v: u64) {
        let i = a - BASE;
        self.shadow[i..i + 8].copy_from_slice(&v.to_le_bytes());
    }
}

fn rd16(regs: &[u8], a: usize) -> u16 {
    match regs.get(a..a + 2) {
        Some(b) => u16::from_le_bytes([b[0], b[1]]),
        None => 0,
    }
}

fn rd32(regs: &[u8], a: usize) -> u32 {
    match regs.get(a..a + 4) {
        Some(b) => u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
        None => 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::vec;
    use std::vec::Vec;

    /// `arrival_needs_regs` (the ESC's shortcut test) says what `frame_arrival` needs:
    /// every port before the first contact, none after it, the armed latch ports after a
    /// write to 0x0900 until each latched or a frame reached port 0.
    #[test]
    fn arrival_needs_regs_follows_the_unit() {
        // The ports (bit n) whose arrival needs the register file.
        let slow = |dc: &Dc| (0..4u8).fold(0u8, |m, p| m | u8::from(dc.arrival_needs_regs(p)) << p);
        let mut regs = [0u8; 0x1000];
        let mut dc = Dc::new(ClockConfig::default());
        assert_eq!(slow(&dc), 0b1111, "before the first contact");
        dc.reset(&mut regs);
        assert_eq!(slow(&dc), 0, "after the reset");
        dc.frame_arrival(&mut regs, 0, 1_000);
        dc.after_write(&mut regs, 0x0900, 1, 1_100, true);
        assert_eq!(slow(&dc), 0b1110, "latch armed by the write to 0x0900");
        dc.frame_arrival(&mut regs, 2, 1_200);
        assert_eq!(slow(&dc), 0b1010, "port 2 latched");
        dc.frame_arrival(&mut regs, 0, 2_000);
        assert_eq!(slow(&dc), 0, "next frame at port 0");
    }

    #[test]
    fn event_bits_match_the_separate_queries() {
        let mut dc = Dc::new(ClockConfig::default());
        for v in 0..=u16::MAX {
            dc.shadow[0x80] = (v as u8 & 0x03) << 4;
            dc.shadow[0xAE] = (v >> 2) as u8 & 0x07;
            dc.shadow[0xAF] = (v >> 5) as u8 & 0x07;
            dc.shadow[0x8E] = (v >> 8) as u8 & 0x03;
            dc.shadow[0x8F] = (v >> 10) as u8 & 0x03;
            assert_eq!(dc.event_bits(), (dc.ecat_event_bits(), dc.al_event_bits()));
        }
    }

    /// The former pure bisection of `global_at_sys`, kept as the reference.
    fn global_at_sys_bisect(dc: &Dc, target: u64, from: u64) -> Option<u64> {
        let d0 = sdiff(target, dc.system_time(from));
        if d0 <= 0 {
            return Some(from);
        }
        if d0 > (1i64 << 62) {
            return None;
        }
        let mut lo = from;
        let mut hi = from.checked_add(d0 as u64)?;
        loop {
            let d = sdiff(target, dc.system_time(hi));
            if d <= 0 {
                break;
            }
            lo = hi;
            hi = hi.checked_add(d as u64)?;
        }
        while hi - lo > 1 {
            let mid = lo + (hi - lo) / 2;
            if sdiff(target, dc.system_time(mid)) <= 0 {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        Some(hi)
    }

    #[test]
    fn global_at_sys_matches_bisection() {
        let mut x = 0x9E37_79B9_7F4A_7C15u64;
        let mut rnd = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        for _ in 0..20_000 {
            let drift_ppm = match rnd() % 4 {
                0 => 0.0,
                1 => (rnd() % 201) as f64 - 100.0,
                2 => ((rnd() % 20_001) as f64 - 10_000.0) / 1.0,
                _ => ((rnd() % 2_000_001) as f64 - 1_000_000.0) / 1000.0,
            };
            let mut dc = Dc::new(ClockConfig {
                drift_ppm,
                start_offset_ns: rnd() % (1 << 40),
            });
            let t0 = rnd() % (1 << 36);
            let rate = (rnd() % (2 * MAX_RATE_Q as u64 + 1)) as i64 - MAX_RATE_Q;
            dc.set_rate(t0, rate);
            dc.offset = rnd();
            let from = t0 + rnd() % 1_000_000;
            let span = match rnd() % 3 {
                0 => rnd() % 100,
                1 => rnd() % 1_000_000,
                _ => rnd() % (1 << 34),
            };
            let target = dc
                .system_time(from)
                .wrapping_add(span)
                .wrapping_sub(rnd() % 8);
            assert_eq!(
                dc.global_at_sys(target, from),
                global_at_sys_bisect(&dc, target, from),
                "drift {drift_ppm} rate {rate} from {from} span {span}"
            );
        }
    }

    #[test]
    fn drift_matches_128_bit_formula() {
        let mut x = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        let drifts = [
            0,
            1,
            -1,
            999_999,
            -999_999,
            1_000_000,
            -1_000_000,
            100_000_000,
            -100_000_000,
            MAX_DRIFT_PPT,
            -MAX_DRIFT_PPT,
        ];
        for k in 0..200_000 {
            let d = if k < drifts.len() * 100 {
                drifts[k % drifts.len()]
            } else {
                (next() % (2 * MAX_DRIFT_PPT as u64 + 1)) as i64 - MAX_DRIFT_PPT
            };
            let t = match k % 4 {
                0 => next(),
                1 => next() % 1_000_000_000_000_000,
                2 => next() % 100_000_000_000,
                _ => (next() % 1000) * 1_000_000_000_000 + next() % 3,
            };
            let want = (t as i128 * d as i128).div_euclid(1_000_000_000_000);
            assert_eq!(drift_ns(t, d) as i128, want, "t {t} drift {d}");
        }
    }

    #[test]
    fn owned_ranges() {
        assert!(owned(0x0900) && owned(0x0935) && !owned(0x0936));
        assert!(!owned(0x097F) && owned(0x0980) && owned(0x0981) && !owned(0x0982));
        assert!(!owned(0x0983) && owned(0x0984) && owned(0x09CF) && !owned(0x09D0));
    }

    /// xorshift64: the random source of the tests below.
    struct Rnd(u64);

    impl Rnd {
        fn next(&mut self) -> u64 {
            let mut x = self.0;
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            self.0 = x;
            x
        }

        /// Uniform in `0..n` (n > 0).
        fn below(&mut self, n: u64) -> u64 {
            self.next() % n
        }
    }

    /// One step of a random master/firmware session against a DC unit.
    #[derive(Debug, Clone)]
    enum Op {
        Arrival(u8),
        EcatWrite(u16, Vec<u8>),
        PdiWrite(u16, Vec<u8>),
        /// An FRMW-like ECAT write of 0x0910: the unit's own system time plus `Δ`.
        SysWrite(i64, u16),
        /// The master starts the cyclic unit: start time = system time + `Δ`, activation.
        StartSync(u64, u8),
        Read(u16, u16, bool),
        Pulse(u16),
        Latch(u8, bool),
        Advance,
    }

    /// A random session: the ethercrab-like DC set-up, cyclic SYNC0/SYNC1 with random
    /// cycle times, FRMW distribution, and writes of random bytes anywhere in 0x0900..0x09FF.
    fn random_ops(r: &mut Rnd, n: usize) -> Vec<(u64, Op)> {
        let mut ops = Vec::new();
        let mut t = r.below(1 << 30);
        // Cycle times first, then the start.
        let c0 = [100_000, 400_000, 1_000_000, 1 + r.below(2_000_000)][r.below(4) as usize];
        ops.push((t, Op::EcatWrite(0x09A0, (c0 as u32).to_le_bytes().to_vec())));
        let c1 = [0, 0, 50_000, r.below(3 * c0)][r.below(4) as usize];
        ops.push((t, Op::EcatWrite(0x09A4, (c1 as u32).to_le_bytes().to_vec())));
        ops.push((t, Op::Pulse([0, 100, 1000][r.below(3) as usize])));
        ops.push((t, Op::StartSync(100_000 + r.below(1_000_000), 0x07)));
        let dc_addr = |r: &mut Rnd| -> u16 {
            let hot = [
                0x0900, 0x0910, 0x0918, 0x0920, 0x0928, 0x092C, 0x0930, 0x0934, 0x0980, 0x0981,
                0x0984, 0x098E, 0x098F, 0x0990, 0x0998, 0x09A0, 0x09A4, 0x09A8, 0x09AE, 0x09B0,
                0x09B8, 0x09C0,
            ];
            if r.below(3) == 0 {
                0x08F8 + r.below(0x110) as u16
            } else {
                hot[r.below(hot.len() as u64) as usize] + r.below(4) as u16
            }
        };
        let bytes =
            |r: &mut Rnd, len: usize| -> Vec<u8> { (0..len).map(|_| r.next() as u8).collect() };
        for _ in 0..n {
            t += match r.below(6) {
                0 => 0,
                1 => r.below(100),
                2 => r.below(10_000),
                3 => r.below(500_000),
                4 => r.below(5_000_000),
                _ => r.below(200_000_000),
            };
            let op = match r.below(26) {
                0..=2 => Op::Arrival(r.below(4) as u8),
                3..=4 => {
                    let a = dc_addr(r);
                    let len = 1 + r.below(12) as usize;
                    Op::EcatWrite(a, bytes(r, len))
                }
                5 => {
                    let a = dc_addr(r);
                    let len = 1 + r.below(12) as usize;
                    Op::PdiWrite(a, bytes(r, len))
                }
                6 => {
                    // Set-up writes with sensible values.
                    let (a, v): (u16, Vec<u8>) = match r.below(9) {
                        0 => (
                            0x0981,
                            vec![[0x03, 0x07, 0x01, 0x0F, 0x00, 0x27, 0x87][r.below(7) as usize]],
                        ),
                        1 => (
                            0x09A0,
                            (100_000 + r.below(1_000_000) as u32).to_le_bytes().to_vec(),
                        ),
                        2 => (
                            0x09A4,
                            [0, 0, 50_000, 130_000 + r.below(900_000) as u32][r.below(4) as usize]
                                .to_le_bytes()
                                .to_vec(),
                        ),
                        3 => (0x0990, r.next().to_le_bytes().to_vec()),
                        4 => (
                            0x0930,
                            (0x80 + r.below(0x8000) as u16).to_le_bytes().to_vec(),
                        ),
                        5 => (0x0934, vec![r.below(16) as u8, r.below(16) as u8]),
                        6 => (
                            0x0980,
                            vec![[0x00, 0x01, 0x10, 0x20, 0x30][r.below(5) as usize]],
                        ),
                        7 => (0x09A8, vec![r.below(4) as u8, r.below(4) as u8]),
                        _ => (0x0920, r.next().to_le_bytes().to_vec()),
                    };
                    if r.below(2) == 0 {
                        Op::EcatWrite(a, v)
                    } else {
                        Op::PdiWrite(a, v)
                    }
                }
                7..=10 => {
                    let d = match r.below(4) {
                        0 => r.below(200) as i64 - 100,
                        1 => r.below(20_000) as i64 - 10_000,
                        2 => r.below(2_000_000) as i64 - 1_000_000,
                        _ => r.next() as i64,
                    };
                    Op::SysWrite(d, [8, 8, 8, 4, 2, 6][r.below(6) as usize])
                }
                11..=12 => {
                    let a = dc_addr(r);
                    Op::Read(a, 1 + r.below(16) as u16, r.below(2) == 0)
                }
                13 => match r.below(4) {
                    0 => Op::StartSync(
                        r.below(1 << 33),
                        [0x03, 0x07, 0x27, 0x67][r.below(4) as usize],
                    ),
                    _ => Op::Pulse([0, 1, 10, 100, 1000, 40_000][r.below(6) as usize]),
                },
                14 => Op::Latch(r.below(2) as u8, r.below(2) == 0),
                _ => Op::Advance,
            };
            ops.push((t, op));
        }
        ops
    }

    /// Everything outside the unit can see of it after one step.
    type Seen = (
        Vec<u8>,
        Option<DcEvents>,
        Option<u64>,
        (bool, bool),
        (u16, u32),
        u64,
    );

    /// Runs `ops` on a unit, returning what is seen after each step. `t` of an `Advance`
    /// goes to the next edge when there is one before it (so edges are hit exactly too).
    macro_rules! run_ops {
        ($dc:expr, $ops:expr) => {{
            let dc = &mut $dc;
            let mut regs = [0u8; 0x1000];
            let mut seen: Vec<Seen> = Vec::new();
            let mut now = 0u64;
            for (t, op) in $ops.iter() {
                let t = (*t).max(now);
                let mut ev = None;
                match op.clone() {
                    Op::Arrival(p) => dc.frame_arrival(&mut regs, p, t),
                    Op::EcatWrite(a, v) | Op::PdiWrite(a, v) => {
                        let ecat = matches!(op, Op::EcatWrite(..));
                        // As the core stores them (the unit decides what it keeps).
                        let a0 = a as usize;
                        regs[a0..a0 + v.len()].copy_from_slice(&v);
                        dc.after_write(&mut regs, a, v.len() as u16, t, ecat);
                    }
                    Op::SysWrite(d, len) => {
                        let v = dc.system_time(t).wrapping_add(d as u64).to_le_bytes();
                        dc.frame_arrival(&mut regs, 0, t);
                        regs[0x0910..0x0910 + len as usize].copy_from_slice(&v[..len as usize]);
                        now = t + 300;
                        dc.after_write(&mut regs, 0x0910, len, now, true);
                    }
                    Op::Read(a, len, ecat) => {
                        dc.before_read(&mut regs, a, len, t);
                        dc.after_read(&mut regs, a, len, t, ecat);
                    }
                    Op::Pulse(p) => regs[0x0982..0x0984].copy_from_slice(&p.to_le_bytes()),
                    Op::StartSync(d, act) => {
                        let s = dc.system_time(t).wrapping_add(d).to_le_bytes();
                        regs[0x0990..0x0998].copy_from_slice(&s);
                        dc.after_write(&mut regs, 0x0990, 8, t, true);
                        regs[0x0981] = act;
                        dc.after_write(&mut regs, 0x0981, 1, t, true);
                    }
                    Op::Latch(n, level) => dc.latch_input(&mut regs, n, level, t),
                    Op::Advance => {
                        let to = match dc.next_event() {
                            Some(n) if n >= now && n < t => n,
                            _ => t,
                        };
                        ev = Some(dc.advance(&mut regs, to));
                        now = to;
                    }
                }
                now = now.max(t);
                seen.push((
                    regs[0x0900..0x0A00].to_vec(),
                    ev,
                    dc.next_event(),
                    dc.sync_levels(),
                    dc.event_bits(),
                    dc.local_time(now),
                ));
            }
            seen
        }};
    }

    /// A random oscillator: ideal, a crystal's ±100 ppm, or anything within the ±1 % the
    /// model accepts; power-on offsets small, large or near the 64-bit wrap.
    fn random_clock(r: &mut Rnd) -> ClockConfig {
        let drift_ppm = match r.below(4) {
            0 => 0.0,
            1 => r.below(201) as f64 - 100.0,
            2 => (r.below(2_000_001) as f64 - 1_000_000.0) / 1000.0,
            _ => (r.below(20_001) as f64 - 10_000.0) / 1.0,
        };
        let start_offset_ns = match r.below(3) {
            0 => r.below(1 << 40),
            1 => r.next(),
            _ => u64::MAX - r.below(1 << 34),
        };
        ClockConfig {
            drift_ppm,
            start_offset_ns,
        }
    }

    /// The fast paths (64-bit clock, closed-form edge times, the system-time write, the
    /// publication of what changed) against the general paths, over random sessions:
    /// everything the ESC core can see must be the same after every step.
    #[test]
    fn fast_paths_match_the_general_paths() {
        let mut r = Rnd(0x2545_F491_4F6C_DD1D);
        let mut edges = 0usize;
        for case in 0..400 {
            let cfg = random_clock(&mut r);
            let bits = if r.below(3) == 0 { 64 } else { 32 };
            let ops = random_ops(&mut r, 300);
            let mut fast = Dc::new(cfg);
            let mut slow = Dc::new(cfg);
            slow.slow = true;
            fast.set_start_time_compare_bits(bits);
            slow.set_start_time_compare_bits(bits);
            let a = run_ops!(fast, ops);
            let b = run_ops!(slow, ops);
            for (i, (x, y)) in a.iter().zip(&b).enumerate() {
                assert_eq!(x, y, "case {case} ({cfg:?}) step {i}: {:?}", ops[i]);
            }
            edges += a
                .iter()
                .filter(|s| s.1.is_some_and(|e| e.sync0.is_some()))
                .count();
        }
        // The sessions did run the SYNC unit.
        assert!(edges > 10_000, "{edges} SYNC0 edges");
    }

    /// A unit with a random clock mapping: anchor, rate and offset anywhere.
    fn random_mapping(r: &mut Rnd) -> Dc {
        let mut dc = Dc::new(random_clock(r));
        let t0 = match r.below(3) {
            0 => r.below(1 << 36),
            1 => r.below(1 << 50),
            _ => r.next(),
        };
        let rate = (r.below(2 * MAX_RATE_Q as u64 + 1)) as i64 - MAX_RATE_Q;
        dc.set_rate(t0, rate);
        dc.offset = r.next();
        dc
    }

    /// The 64-bit evaluation of the clock is the 128-bit one wherever it answers, and it
    /// answers near the anchor.
    #[test]
    fn local_time_matches_the_wide_form() {
        let mut r = Rnd(0x9E37_79B9_7F4A_7C15);
        let mut near = 0;
        for _ in 0..200_000 {
            let dc = random_mapping(&mut r);
            let span = match r.below(4) {
                0 => r.below(1000),
                1 => r.below(1 << 30),
                2 => r.below(1 << 40),
                _ => r.next(),
            };
            let (t, wrapped) = if r.below(2) == 0 {
                dc.anchor_t.overflowing_add(span)
            } else {
                dc.anchor_t.overflowing_sub(span)
            };
            assert_eq!(
                dc.local_time(t),
                dc.local_time_wide(t),
                "t {t} anchor {}",
                dc.anchor_t
            );
            if span < 1 << 26 && !wrapped {
                assert!(dc.local_rel(t).is_some(), "t {t} anchor {}", dc.anchor_t);
                near += 1;
            }
        }
        assert!(near > 50_000);
    }

    #[test]
    fn drift_split_matches_128_bit_formula() {
        let mut r = Rnd(0xD1B5_4A32_D192_ED03);
        for k in 0..200_000 {
            let d = match k % 3 {
                0 => r.below(2 * MAX_DRIFT_PPT as u64 + 1) as i64 - MAX_DRIFT_PPT,
                1 => [0, 1, -1, 999_999, -1_000_000, MAX_DRIFT_PPT, -MAX_DRIFT_PPT][k % 7],
                _ => r.below(200_000_001) as i64 - 100_000_000,
            };
            let t = match k % 4 {
                0 => r.next(),
                1 => r.below(1_000_000_000_000_000),
                2 => r.below(100_000_000_000),
                _ => r.below(1000) * 1_000_000_000_000 + r.below(3),
            };
            let p = t as i128 * d as i128;
            let want = (
                p.div_euclid(1_000_000_000_000) as i64,
                p.rem_euclid(1_000_000_000_000) as i64,
            );
            assert_eq!(drift_split(t, d), want, "t {t} drift {d}");
        }
    }

    /// The closed form of the edge time is the search's answer, and it is the one taken
    /// near the anchor; the search is the bisection's answer everywhere.
    #[test]
    fn edge_time_closed_form_matches_search() {
        let mut r = Rnd(0xA076_1D64_78BD_642F);
        let mut exact = 0;
        for _ in 0..100_000 {
            let dc = random_mapping(&mut r);
            let from = match r.below(3) {
                0 => dc.anchor_t.saturating_add(r.below(1_000_000)),
                1 => dc.anchor_t.wrapping_add(r.below(1 << 40)),
                _ => r.next(),
            };
            let span = match r.below(4) {
                0 => r.below(100),
                1 => r.below(1_000_000),
                2 => r.below(1 << 34),
                _ => r.next(),
            };
            let target = dc
                .system_time(from)
                .wrapping_add(span)
                .wrapping_sub(r.below(8));
            let search = dc.global_at_sys_search(target, from);
            if let Some(g) = dc.global_at_sys_exact(target, from) {
                assert_eq!(
                    g, search,
                    "target {target} from {from} anchor {}",
                    dc.anchor_t
                );
                exact += 1;
            }
            assert_eq!(dc.global_at_sys(target, from), search);
            if span < 1 << 34 {
                assert_eq!(search, global_at_sys_bisect(&dc, target, from));
            }
        }
        assert!(exact > 20_000, "{exact} closed-form answers");
        // The ends of the closed form's range: targets up to 2^62 ahead of a `from` up to
        // 2^62 past the anchor, at the extreme rates and drifts.
        for rate in [-MAX_RATE_Q, -1, 0, 1, MAX_RATE_Q] {
            for drift_ppm in [-10_000.0, -0.001, 0.0, 0.001, 10_000.0] {
                for from in [1 << 62, (1 << 62) - 1, 1 << 61, 0] {
                    for span in [1 << 62, (1 << 62) - 5, 1 << 61, 1] {
                        let mut dc = Dc::new(ClockConfig {
                            drift_ppm,
                            start_offset_ns: 0,
                        });
                        dc.set_rate(0, rate);
                        let target = dc.system_time(from).wrapping_add(span);
                        let search = dc.global_at_sys_search(target, from);
                        if let Some(g) = dc.global_at_sys_exact(target, from) {
                            assert_eq!(g, search, "rate {rate} drift {drift_ppm} from {from}");
                        }
                        assert_eq!(dc.global_at_sys(target, from), search);
                    }
                }
            }
        }
    }

    /// The 64-bit rate law is the 128-bit one, over the whole input range the loop can
    /// produce (integral within its limit, any sample distance and time constant).
    #[test]
    fn rate_law_matches_the_wide_form() {
        let mut r = Rnd(0xE703_7ED1_A0B4_28DB);
        for k in 0..300_000 {
            let start = match k % 3 {
                0 => 0x80,
                1 => 0x7FFF,
                _ => 0x80 + r.below(0x7F80),
            };
            let tau = start * TAU_PER_UNIT_NS;
            let integ_max = ((MAX_RATE_Q as i128) * (tau as i128) * (tau as i128)) >> Q;
            let integ = match r.below(4) {
                0 => 0,
                1 => integ_max,
                2 => -integ_max,
                _ => (r.next() as i128 % (integ_max + 1)) * if r.below(2) == 0 { 1 } else { -1 },
            };
            let dt = r.next() as i32 as i64 >> r.below(31);
            let h_raw = match r.below(4) {
                0 => 0,
                1 => r.below(1_000_000),
                2 => r.below(1 << 40),
                _ => r.next(),
            };
            assert_eq!(
                rate_law(integ, dt, h_raw, tau),
                rate_law_wide(integ, dt, h_raw, tau),
                "integ {integ} dt {dt} h {h_raw} tau {tau}"
            );
        }
    }

    #[test]
    fn speed_diff_matches_the_wide_form() {
        let wide = |rate_q: i64, start: u16| -> u16 {
            let start = start as i128;
            let r = (rate_q as i128).abs();
            let diff = if r == 0 {
                0
            } else {
                let period = ONE_Q / (10 * r);
                if period >= start {
                    0
                } else {
                    (start - period).min(start - 0x7F)
                }
            };
            let v = if rate_q < 0 { -diff } else { diff };
            v as i16 as u16
        };
        let mut r = Rnd(0x8CB9_2BA7_2F3D_8DD7);
        for k in 0..200_000 {
            let rate = match k % 3 {
                0 => r.below(2 * MAX_RATE_Q as u64 + 1) as i64 - MAX_RATE_Q,
                1 => r.below(2001) as i64 - 1000,
                _ => [0, 1, -1, MAX_RATE_Q, -MAX_RATE_Q][k % 5],
            };
            let start = 0x80 + r.below(0x7F80) as u16;
            assert_eq!(
                speed_diff(rate, start) as u16,
                wide(rate, start),
                "rate {rate} start {start}"
            );
        }
    }
}
