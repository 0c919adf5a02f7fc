//! Linear transitions of gains and ellipse semi-axes over `Transition_time` (thesis §3.3:
//! `calculateAdder` / `UpdateValue`).
//!
//! When the commanded value changes, the value moves from where it is to the new target in
//! equal steps, one per application (SYNC0) cycle, reaching it after
//! `round(Transition_time / dt)` cycles. The thesis adds a constant `adder` each cycle and
//! stops at the target; we compute `start + (target − start)·k/n` instead, which is the
//! same straight line without accumulated rounding, and lands exactly on the target.

/// A value that follows its commanded target linearly in time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ramp {
    value: f32,
    start: f32,
    target: f32,
    steps: u32,
    left: u32,
}

impl Ramp {
    /// A ramp resting at `value`.
    pub const fn new(value: f32) -> Self {
        Self {
            value,
            start: value,
            target: value,
            steps: 0,
            left: 0,
        }
    }

    /// The current value.
    pub fn value(&self) -> f32 {
        self.value
    }

    /// The target being approached.
    pub fn target(&self) -> f32 {
        self.target
    }

    /// True while the value is still moving.
    pub fn active(&self) -> bool {
        self.left > 0
    }

    /// One application cycle: takes the commanded `target` (a new one starts a ramp of
    /// `transition_s` seconds from the current value, at `cycle_ns` per cycle), then
    /// advances one step.
    pub fn update(&mut self, target: f32, transition_s: f32, cycle_ns: u32) -> f32 {
        if target != self.target && target.is_finite() {
            let n = if transition_s > 0.0 && cycle_ns > 0 {
                let n = transition_s * 1.0e9 / cycle_ns as f32 + 0.5;
                if n >= u32::MAX as f32 {
                    u32::MAX
                } else {
                    (n as u32).max(1)
                }
            } else {
                1
            };
            self.start = self.value;
            self.target = target;
            self.steps = n;
            self.left = n;
        }
        if self.left > 0 {
            self.left -= 1;
            let k = self.left as f32 / self.steps as f32;
            self.value = if self.left == 0 {
                self.target
            } else {
                self.target + (self.start - self.target) * k
            };
        }
        self.value
    }

    /// Jumps to `value` (no ramp), e.g. on reset.
    pub fn set(&mut self, value: f32) {
        *self = Self::new(value);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linear_over_transition_time() {
        // b: 0 → 4 cm over 3 s at 400 µs: 7500 cycles.
        let mut r = Ramp::new(0.0);
        let mut prev = 0.0;
        for k in 1..=7500u32 {
            let v = r.update(0.04, 3.0, 400_000);
            let expect = 0.04 * k as f32 / 7500.0;
            assert!((v - expect).abs() < 1e-7, "cycle {k}: {v} vs {expect}");
            assert!(v > prev);
            prev = v;
            assert_eq!(r.active(), k < 7500);
        }
        assert_eq!(r.value(), 0.04);
        for _ in 0..10 {
            assert_eq!(r.update(0.04, 3.0, 400_000), 0.04);
        }
    }

    #[test]
    fn retarget_mid_ramp_starts_from_current_value() {
        let mut r = Ramp::new(80.0);
        for _ in 0..2500 {
            r.update(20.0, 1.0, 400_000);
        }
        // Half-way through 2500 cycles? 1 s = 2500 cycles: done.
        assert_eq!(r.value(), 20.0);
        for _ in 0..1250 {
            r.update(80.0, 1.0, 400_000);
        }
        let mid = r.value();
        assert!((mid - 50.0).abs() < 1e-3, "{mid}");
        // New target from the middle: 50 → 0 over 2 s (5000 cycles).
        let v1 = r.update(0.0, 2.0, 400_000);
        assert!((v1 - (mid - mid / 5000.0)).abs() < 1e-3);
        for _ in 1..5000 {
            r.update(0.0, 2.0, 400_000);
        }
        assert_eq!(r.value(), 0.0);
        assert!(!r.active());
    }

    #[test]
    fn zero_transition_time_jumps() {
        let mut r = Ramp::new(1.0);
        assert_eq!(r.update(2.0, 0.0, 400_000), 2.0);
        assert_eq!(r.update(f32::NAN, 1.0, 400_000), 2.0);
    }
}
