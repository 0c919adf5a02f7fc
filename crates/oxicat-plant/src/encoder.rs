//! Incremental motor encoder (2000 quadrature counts per motor revolution) with the edge
//! timing an eQEP-style capture unit sees. The speed estimator itself belongs to firmware.

use core::f64::consts::PI;

/// Quadrature counts per motor revolution (thesis §6.10: "2000 counts per revolution").
pub const COUNTS_PER_REV: f64 = 2000.0;

/// One unit-position capture, as eQEP latches QCPRD on a unit position event (UPEVNT).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UnitCapture {
    /// Time between this unit position event and the previous one [s] (QCPRD × capture tick).
    pub period: f64,
    /// Virtual time of this unit position event [s].
    pub time: f64,
    /// Direction changed since the previous unit event (eQEP CDEF).
    pub direction_changed: bool,
}

/// State of one encoder channel as the firmware can read it.
#[derive(Clone, Debug, PartialEq)]
pub struct Encoder {
    count: i64,
    zero_angle: f64,
    upps: u32,
    edges_since_unit: u32,
    last_edge_time: f64,
    last_unit_time: f64,
    forward: bool,
    dir_changed: bool,
    capture: Option<UnitCapture>,
    edges_total: u64,
}

/// `x.floor() as i64`, bit for bit (NaN → 0, saturating outside the `i64` range), without
/// the call to libm's `floor` that the baseline x86-64 target makes (no SSE4.1 `roundsd`):
/// the encoder runs it twice per plant substep.
#[inline(always)]
fn floor_i64(x: f64) -> i64 {
    let i = x as i64;
    // Truncation rounds towards zero; below zero a fractional part makes it one too high.
    // Saturated above or NaN: `i as f64 > x` is false; saturated below it is true and
    // the subtraction saturates too.
    if (i as f64) > x {
        i.saturating_sub(1)
    } else {
        i
    }
}

impl Encoder {
    /// Encoder zeroed at motor angle `zero_angle` [rad], unit event every `upps` edges.
    pub fn new(zero_angle: f64, upps: u32) -> Self {
        Encoder {
            count: 0,
            zero_angle,
            upps: upps.max(1),
            edges_since_unit: 0,
            last_edge_time: 0.0,
            last_unit_time: 0.0,
            forward: true,
            dir_changed: false,
            capture: None,
            edges_total: 0,
        }
    }

    /// Position counter relative to the reset pose (QPOSCNT, wraps like a 32-bit counter).
    pub fn count(&self) -> i32 {
        self.count as i32
    }

    /// Direction of the last edge: `true` when counting up (eQEP QDF = 1).
    pub fn forward(&self) -> bool {
        self.forward
    }

    /// Virtual time of the last quadrature edge [s] (interpolated within the substep).
    pub fn last_edge_time(&self) -> f64 {
        self.last_edge_time
    }

    /// Edges per unit position event (eQEP UPPS prescaler).
    pub fn unit_prescaler(&self) -> u32 {
        self.upps
    }

    /// Latest unit capture not yet taken (eQEP UPEVNT flag set), without clearing it.
    pub fn peek_capture(&self) -> Option<UnitCapture> {
        self.capture
    }

    /// Take the latest unit capture and clear the UPEVNT flag (as firmware writes 1 to clear).
    pub fn take_capture(&mut self) -> Option<UnitCapture> {
        self.capture.take()
    }

    /// Total number of edges seen since construction (either direction).
    pub fn edges_total(&self) -> u64 {
        self.edges_total
    }

    /// Zero the counter at motor angle `angle` (the thesis' Reset button).
    pub fn reset(&mut self, angle: f64) {
        self.zero_angle = angle;
        self.count = 0;
        self.edges_since_unit = 0;
        self.capture = None;
        self.dir_changed = false;
    }

    #[inline]
    fn count_at(&self, angle: f64) -> i64 {
        // Edges half a count either side of the reset angle.
        floor_i64((angle - self.zero_angle) * (COUNTS_PER_REV / (2.0 * PI)) + 0.5)
    }

    /// Move the shaft from `a0` at `t0` to `a1` at `t0 + h`; records every edge crossed.
    ///
    /// Of the edges crossed only the last one's time and the unit events' times are seen
    /// (the last edge time, the latest capture and its period), so only those edges' times
    /// are computed, each with the expression [`update_every_edge`](Self::update_every_edge)
    /// evaluates for every edge (the same operations on the same values: the same bits;
    /// tested side by side). The others only count.
    #[inline]
    pub(crate) fn update(&mut self, a0: f64, a1: f64, t0: f64, h: f64) {
        let c1 = self.count_at(a1);
        let c0 = self.count;
        if c1 == c0 {
            return;
        }
        let k = COUNTS_PER_REV / (2.0 * PI);
        let up = c1 > c0;
        let n = (c1 - c0).unsigned_abs();
        let da = a1 - a0;
        let zero = self.zero_angle;
        // The time of edge `e` (1..=n), as the edge loop computes it.
        let edge_time = |e: u64| {
            let c = if up { c0 + e as i64 } else { c0 - e as i64 };
            let edge_angle = zero + (c as f64 - if up { 0.5 } else { -0.5 }) / k;
            let frac = if da != 0.0 {
                ((edge_angle - a0) / da).clamp(0.0, 1.0)
            } else {
                1.0
            };
            t0 + h * frac
        };
        // The direction is the same for every edge of one move: only the first can flip it.
        if up != self.forward {
            self.dir_changed = true;
            self.forward = up;
        }
        self.edges_total = self.edges_total.wrapping_add(n);
        // Unit events fall on the edges where the count since the last one reaches
        // `upps` (`edges_since_unit < upps` between moves): edges `j·upps − before`.
        let upps = u64::from(self.upps);
        let before = u64::from(self.edges_since_unit);
        let units = (before + n) / upps;
        if units > 0 {
            let last = units * upps - before;
            let t = edge_time(last);
            // The capture before it: this move's previous unit edge, else the last one's.
            let (prev, dir_changed) = if units > 1 {
                // The first unit event of this move cleared the flag; no later edge sets it.
                (edge_time(last - upps), false)
            } else {
                (self.last_unit_time, self.dir_changed)
            };
            self.capture = Some(UnitCapture {
                period: t - prev,
                time: t,
                direction_changed: dir_changed,
            });
            self.dir_changed = false;
            self.last_unit_time = t;
        }
        self.edges_since_unit = ((before + n) % upps) as u32;
        self.last_edge_time = edge_time(n);
        self.count = c1;
    }

    /// [`update`](Self::update) as it was, walking every edge crossed (the reference its
    /// tests compare it with).
    #[cfg(test)]
    fn update_every_edge(&mut self, a0: f64, a1: f64, t0: f64, h: f64) {
        let c1 = self.count_at(a1);
        let c0 = self.count;
        if c1 == c0 {
            return;
        }
        let k = COUNTS_PER_REV / (2.0 * PI);
        let up = c1 > c0;
        let n = (c1 - c0).unsigned_abs();
        let da = a1 - a0;
        for e in 1..=n {
            // Edge between count c and c±1 lies at (c ± 0.5)/k from zero.
            let c = if up { c0 + e as i64 } else { c0 - e as i64 };
            let edge_angle = self.zero_angle + (c as f64 - if up { 0.5 } else { -0.5 }) / k;
            let frac = if da != 0.0 {
                ((edge_angle - a0) / da).clamp(0.0, 1.0)
            } else {
                1.0
            };
            let t = t0 + h * frac;
            if up != self.forward {
                self.dir_changed = true;
                self.forward = up;
            }
            self.last_edge_time = t;
            self.edges_total += 1;
            self.edges_since_unit += 1;
            if self.edges_since_unit >= self.upps {
                self.edges_since_unit = 0;
                self.capture = Some(UnitCapture {
                    period: t - self.last_unit_time,
                    time: t,
                    direction_changed: self.dir_changed,
                });
                self.dir_changed = false;
                self.last_unit_time = t;
            }
        }
        self.count = c1;
    }
}

#[cfg(test)]
mod tests {
    use super::{floor_i64, Encoder};

    /// `update` computes only the edge times that are seen; over random moves (small and
    /// large, either way, reversals, standstill, a zero-length move, every prescaler from 1
    /// to 40, captures taken or left, resets) the encoder is the one the every-edge loop
    /// leaves, field for field (floats by their bits, through `PartialEq` on equal values
    /// and the debug form).
    #[test]
    fn update_is_the_every_edge_loop() {
        let mut s = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        for upps in 1..=40u32 {
            let zero = (next() % 1000) as f64 * 1e-3 - 0.5;
            let mut fast = Encoder::new(zero, upps);
            let mut slow = fast.clone();
            let (mut a, mut t) = (zero, 0.0f64);
            for step in 0..4000 {
                let r = next();
                // Mostly a few edges (k ≈ 318 counts/rad), sometimes many, sometimes none.
                let scale = match r % 8 {
                    0 => 0.0,
                    1 => 0.5,
                    2 | 3 => 0.02,
                    _ => 0.005,
                };
                let da = ((r >> 8) % 20001) as f64 * 1e-4 - 1.0;
                let a1 = if r % 97 == 0 { a } else { a + da * scale };
                let h = 5e-5 * (1.0 + ((r >> 40) % 7) as f64 * 1e-9);
                fast.update(a, a1, t, h);
                slow.update_every_edge(a, a1, t, h);
                assert_eq!(
                    format!("{fast:?}"),
                    format!("{slow:?}"),
                    "upps {upps} step {step}"
                );
                assert_eq!(fast, slow);
                assert_eq!(fast.last_edge_time.to_bits(), slow.last_edge_time.to_bits());
                assert_eq!(fast.last_unit_time.to_bits(), slow.last_unit_time.to_bits());
                if r % 5 == 0 {
                    assert_eq!(fast.take_capture(), slow.take_capture());
                }
                if r % 1009 == 0 {
                    fast.reset(a1);
                    slow.reset(a1);
                }
                a = a1;
                t += h;
            }
            assert!(
                fast.edges_total() > 1000,
                "upps {upps}: the moves cross edges"
            );
        }
    }

    #[test]
    fn floor_i64_matches_floor_cast() {
        let specials = [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            -1.5,
            1e300,
            -1e300,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            9.2e18,
            -9.2e18,
            9.3e18,
            -9.3e18,
            i64::MAX as f64,
            i64::MIN as f64,
            -4503599627370495.5,
            4503599627370495.5,
        ];
        for x in specials {
            assert_eq!(floor_i64(x), x.floor() as i64, "{x}");
        }
        let mut s = 0x2545_F491_4F6C_DD1Du64;
        for _ in 0..200_000 {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let x = f64::from_bits(s);
            assert_eq!(floor_i64(x), x.floor() as i64, "{x}");
            let y = (s as i64 as f64) * 1e-6;
            assert_eq!(floor_i64(y), y.floor() as i64, "{y}");
            let z = y.fract() * 1e4;
            assert_eq!(floor_i64(z), z.floor() as i64, "{z}");
        }
    }
}
