//! Identification on the master side (manual §6.2): excitations (chirp, white Gaussian
//! noise, a user's own setpoint file), the Welch/CPSD estimator with coherence
//! (H1 = P_yu/P_uu, γ² = |P_yu|²/(P_uu P_yy), Hann windows, overlap), the firmware's PI as a
//! transfer function C, and the manual's plant model H = M·LP (eq. 6.5–6.7) to compare the
//! estimate H = L/C (eq. 6.17) with, plus R and L fitted from the estimate.

use core::f64::consts::PI;

/// Current-loop sample rate \[Hz\].
pub const FS: f64 = 20_000.0;

/// A complex number as (re, im).
pub type C64 = (f64, f64);

fn cmul(a: C64, b: C64) -> C64 {
    (a.0 * b.0 - a.1 * b.1, a.0 * b.1 + a.1 * b.0)
}

/// a / b.
pub fn cdiv(a: C64, b: C64) -> C64 {
    let d = b.0 * b.0 + b.1 * b.1;
    ((a.0 * b.0 + a.1 * b.1) / d, (a.1 * b.0 - a.0 * b.1) / d)
}

fn cabs2(a: C64) -> f64 {
    a.0 * a.0 + a.1 * a.1
}

/// A logarithmic chirp (swept sine) from `f0` to `f1` \[Hz\] over `n` samples at 20 kHz,
/// amplitude `amp_ma`, in mA.
pub fn chirp(n: usize, f0: f64, f1: f64, amp_ma: f64) -> Vec<i16> {
    let t_end = n as f64 / FS;
    let k = (f1 / f0).ln();
    (0..n)
        .map(|j| {
            let t = j as f64 / FS;
            let ph = 2.0 * PI * f0 * t_end / k * ((k * t / t_end).exp() - 1.0);
            (amp_ma * ph.sin()).round() as i16
        })
        .collect()
}

/// White Gaussian noise of standard deviation `sigma_ma` \[mA\], clipped at ±3σ, `n`
/// samples, from `seed` (xorshift64* + Box–Muller: the same seed gives the same samples).
pub fn white_noise(n: usize, sigma_ma: f64, seed: u64) -> Vec<i16> {
    let mut s = seed.max(1);
    let mut next = || {
        s ^= s >> 12;
        s ^= s << 25;
        s ^= s >> 27;
        let v = s.wrapping_mul(0x2545_F491_4F6C_DD1D);
        ((v >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    (0..n)
        .map(|_| {
            let (u1, u2) = (next(), next());
            let g = (-2.0 * u1.ln()).sqrt() * (2.0 * PI * u2).cos();
            (g.clamp(-3.0, 3.0) * sigma_ma).round() as i16
        })
        .collect()
}

/// In-place radix-2 FFT (`x.len()` a power of two).
pub fn fft(x: &mut [C64]) {
    let n = x.len();
    if n < 2 {
        return;
    }
    let mut j = 0;
    for i in 1..n {
        let mut bit = n >> 1;
        while j & bit != 0 {
            j ^= bit;
            bit >>= 1;
        }
        j |= bit;
        if i < j {
            x.swap(i, j);
        }
    }
    let mut len = 2;
    while len <= n {
        let a = -2.0 * PI / len as f64;
        for start in (0..n).step_by(len) {
            for k in 0..len / 2 {
                let w = ((a * k as f64).cos(), (a * k as f64).sin());
                let u = x[start + k];
                let v = cmul(x[start + k + len / 2], w);
                x[start + k] = (u.0 + v.0, u.1 + v.1);
                x[start + k + len / 2] = (u.0 - v.0, u.1 - v.1);
            }
        }
        len <<= 1;
    }
}

/// One line of a Welch estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spectral {
    /// Frequency \[Hz\].
    pub f: f64,
    /// H1 = P_yu / P_uu.
    pub h: C64,
    /// Coherence γ² = |P_yu|² / (P_uu P_yy), 0..1.
    pub coherence: f64,
}

/// Why a Welch estimate cannot be made.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum WelchError {
    /// `nfft` is not a power of two ≥ 16.
    Nfft(usize),
    /// `overlap` is not below `nfft`.
    Overlap(usize),
    /// Fewer samples than two segments need.
    TooShort {
        /// Samples given.
        n: usize,
        /// Samples needed.
        need: usize,
    },
}

impl core::fmt::Display for WelchError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            WelchError::Nfft(n) => write!(f, "segment length {n} is not a power of two >= 16"),
            WelchError::Overlap(o) => write!(f, "overlap {o} is not below the segment length"),
            WelchError::TooShort { n, need } => {
                write!(f, "{n} samples are too few: two segments need {need}")
            }
        }
    }
}

impl std::error::Error for WelchError {}

/// Welch's averaged cross- and auto-spectra of input `u` and output `y` (sampled at `fs`):
/// segments of `nfft` samples, `overlap` shared with the previous one, each with its mean
/// removed and a Hann window; returns H1 and the coherence on the lines 1 … nfft/2 − 1.
pub fn welch(
    u: &[f64],
    y: &[f64],
    nfft: usize,
    overlap: usize,
    fs: f64,
) -> Result<Vec<Spectral>, WelchError> {
    if nfft < 16 || !nfft.is_power_of_two() {
        return Err(WelchError::Nfft(nfft));
    }
    if overlap >= nfft {
        return Err(WelchError::Overlap(overlap));
    }
    let n = u.len().min(y.len());
    let step = nfft - overlap;
    if n < nfft + step {
        return Err(WelchError::TooShort {
            n,
            need: nfft + step,
        });
    }
    let w: Vec<f64> = (0..nfft)
        .map(|k| 0.5 - 0.5 * (2.0 * PI * k as f64 / nfft as f64).cos())
        .collect();
    let half = nfft / 2;
    let mut puu = vec![0.0; half];
    let mut pyy = vec![0.0; half];
    let mut pyu = vec![(0.0, 0.0); half];
    let seg = |x: &[f64]| -> Vec<C64> {
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        let mut v: Vec<C64> = x
            .iter()
            .zip(&w)
            .map(|(&a, &wk)| ((a - mean) * wk, 0.0))
            .collect();
        fft(&mut v);
        v
    };
    let mut start = 0;
    while start + nfft <= n {
        let fu = seg(&u[start..start + nfft]);
        let fy = seg(&y[start..start + nfft]);
        for k in 1..half {
            puu[k] += cabs2(fu[k]);
            pyy[k] += cabs2(fy[k]);
            let c = cmul(fy[k], (fu[k].0, -fu[k].1));
            pyu[k] = (pyu[k].0 + c.0, pyu[k].1 + c.1);
        }
        start += step;
    }
    Ok((1..half)
        .map(|k| {
            let h = if puu[k] > 0.0 {
                (pyu[k].0 / puu[k], pyu[k].1 / puu[k])
            } else {
                (0.0, 0.0)
            };
            let den = puu[k] * pyy[k];
            Spectral {
                f: k as f64 * fs / nfft as f64,
                h,
                coherence: if den > 0.0 {
                    (cabs2(pyu[k]) / den).min(1.0)
                } else {
                    0.0
                },
            }
        })
        .collect())
}

/// The firmware's PI (`currentPI` with the gains `param2int` gave, `pgain`, `igain` in q8)
/// as seen from the current error \[A\] to the bridge voltage \[V\] at `line_v` volts:
/// `C(z) = (kp + ki/(1 − z⁻¹)) · g`, kp = 10·pgain/256 V/A, ki = 10·igain/16384 V/A per
/// sample (the integral of mA errors, `>> 6`, q8), g the `u2pwm` path (q8 truncation
/// included: 0.975 at 24 V).
pub fn controller(f: f64, pgain: i32, igain: i32, line_v: f64) -> C64 {
    let kp = 10.0 * pgain as f64 / 256.0;
    let ki = 10.0 * igain as f64 / 16384.0;
    let lv = (line_v * 100.0).round() as i32;
    let u2 = super::control::u2pwm(lv) as f64;
    let g = 100.0 * u2 / 256.0 / super::control::PWMPER as f64 * line_v;
    let w = 2.0 * PI * f / FS;
    let zi = (w.cos(), -w.sin()); // z^-1
    let integ = cdiv((ki, 0.0), (1.0 - zi.0, -zi.1));
    ((kp + integ.0) * g, integ.1 * g)
}

/// The manual's plant model (eq. 6.7), M·LP, with a pure delay `delay_s` for the sampled
/// loop: `M = (Js + b)/(LJs² + (Lb + RJ)s + Rb + Kv²)`, `LP = 1/(R_f C_f s + 1)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlantModel {
    /// Terminal resistance \[Ω\].
    pub r: f64,
    /// Terminal inductance \[H\].
    pub l: f64,
    /// Speed (torque) constant \[V s/rad\].
    pub kv: f64,
    /// Rotor inertia \[kg m²\].
    pub j: f64,
    /// Damping \[N m s/rad\].
    pub b: f64,
    /// R_f · C_f \[s\].
    pub filter_tau: f64,
    /// Delay of the sampled loop \[s\].
    pub delay_s: f64,
}

/// The bench's loop delay from the ADC sample to the average of the bridge voltage it
/// sets: 6.25 µs to the PWM counter's bottom + half the 50 µs hold.
pub const LOOP_DELAY_S: f64 = 6.25e-6 + 25.0e-6;

impl PlantModel {
    /// The model of an RE 30 channel (its parameters as the plant uses them), with the
    /// bench's loop delay.
    pub fn of(p: &oxicat_plant::re30::Re30Params) -> Self {
        Self {
            r: p.resistance,
            l: p.inductance,
            kv: p.torque_constant,
            j: if p.locked { f64::INFINITY } else { p.inertia },
            b: p.viscous,
            filter_tau: p.filter_tau,
            delay_s: LOOP_DELAY_S,
        }
    }

    /// H(j2πf), current out of the filter per bridge volt \[A/V\].
    pub fn h(&self, f: f64) -> C64 {
        let s = (0.0, 2.0 * PI * f);
        // 1/M = R + Ls + Kv²/(Js + b)
        let mech = if self.j.is_finite() {
            cdiv((self.kv * self.kv, 0.0), (self.b, self.j * s.1))
        } else {
            (0.0, 0.0)
        };
        let z = (self.r + mech.0, self.l * s.1 + mech.1);
        let m = cdiv((1.0, 0.0), z);
        let lp = cdiv((1.0, 0.0), (1.0, self.filter_tau * s.1));
        let d = (-s.1 * self.delay_s).sin_cos();
        cmul(cmul(m, lp), (d.1, d.0))
    }
}

/// R and L fitted from a plant estimate: `Z = LP·delay/H − Kv²/(Js+b)`, R the mean of
/// Re Z and L the least-squares slope of Im Z over ω, on the lines in `f_lo … f_hi`.
pub fn fit_r_l(est: &[(f64, C64)], model: &PlantModel, f_lo: f64, f_hi: f64) -> Option<(f64, f64)> {
    let (mut sr, mut n, mut sxy, mut sxx) = (0.0, 0.0, 0.0, 0.0);
    for &(f, h) in est {
        if f < f_lo || f > f_hi || cabs2(h) == 0.0 {
            continue;
        }
        let w = 2.0 * PI * f;
        let lp = cdiv((1.0, 0.0), (1.0, model.filter_tau * w));
        let d = (-w * model.delay_s).sin_cos();
        let z = cdiv(cmul(lp, (d.1, d.0)), h);
        let mech = if model.j.is_finite() {
            cdiv((model.kv * model.kv, 0.0), (model.b, model.j * w))
        } else {
            (0.0, 0.0)
        };
        sr += z.0 - mech.0;
        sxy += w * (z.1 - mech.1);
        sxx += w * w;
        n += 1.0;
    }
    (n >= 2.0).then(|| (sr / n, sxy / sxx))
}

/// Why a setpoint file is refused: the line (1-based) and what is wrong with it.
#[derive(Debug, Clone, PartialEq)]
pub enum SetpointError {
    /// A line that is not a number.
    NotANumber {
        /// Line.
        line: usize,
        /// Its text.
        text: String,
    },
    /// NaN or an infinity.
    NotFinite {
        /// Line.
        line: usize,
        /// Its text.
        text: String,
    },
    /// Outside the channel's range.
    OutOfRange {
        /// Line.
        line: usize,
        /// The value \[mA\].
        value: f64,
        /// The range \[mA\].
        limit: f64,
    },
    /// Too few or too many setpoints.
    Length {
        /// Setpoints in the file.
        n: usize,
        /// At least.
        min: usize,
        /// At most.
        max: usize,
    },
}

impl core::fmt::Display for SetpointError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            SetpointError::NotANumber { line, text } => {
                write!(
                    f,
                    "line {line}: {text:?} is not a number (one setpoint in mA per line)"
                )
            }
            SetpointError::NotFinite { line, text } => {
                write!(f, "line {line}: {text} is not a finite current")
            }
            SetpointError::OutOfRange { line, value, limit } => write!(
                f,
                "line {line}: {value} mA is not in -{limit} … {limit} mA (the M2 current sense \
                 reads -8.7 … +7.6 A around its zero)"
            ),
            SetpointError::Length { n, min, max } => write!(
                f,
                "{n} setpoints: give {min} … {max} (two Welch segments at least, 100 s at most)"
            ),
        }
    }
}

impl std::error::Error for SetpointError {}

/// Largest setpoint a file may hold \[mA\].
pub const SETPOINT_LIMIT_MA: f64 = 7500.0;
/// Fewest setpoints a file may hold: two 2048-sample segments with 50 % overlap.
pub const SETPOINTS_MIN: usize = 3 * 1024;
/// Most setpoints a file may hold: 100 s at 20 kHz.
pub const SETPOINTS_MAX: usize = 2_000_000;

/// Parses a setpoint file: one current setpoint in mA per line (decimals are rounded),
/// blank lines and `#` comments skipped.
pub fn parse_setpoints(text: &str) -> Result<Vec<i16>, SetpointError> {
    let mut out = Vec::new();
    for (k, raw) in text.lines().enumerate() {
        let line = k + 1;
        let s = raw.split('#').next().unwrap_or("").trim();
        if s.is_empty() {
            continue;
        }
        let v: f64 = s.parse().map_err(|_| SetpointError::NotANumber {
            line,
            text: s.to_string(),
        })?;
        if !v.is_finite() {
            return Err(SetpointError::NotFinite {
                line,
                text: s.to_string(),
            });
        }
        if v.abs() > SETPOINT_LIMIT_MA {
            return Err(SetpointError::OutOfRange {
                line,
                value: v,
                limit: SETPOINT_LIMIT_MA,
            });
        }
        if out.len() >= SETPOINTS_MAX {
            return Err(SetpointError::Length {
                n: out.len() + 1,
                min: SETPOINTS_MIN,
                max: SETPOINTS_MAX,
            });
        }
        out.push(v.round() as i16);
    }
    if out.len() < SETPOINTS_MIN {
        return Err(SetpointError::Length {
            n: out.len(),
            min: SETPOINTS_MIN,
            max: SETPOINTS_MAX,
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// y[k] = a·y[k−1] + (1 − a)·u[k]: H(e^{jω}) = (1 − a)/(1 − a e^{−jω}).
    fn first_order(u: &[f64], a: f64) -> Vec<f64> {
        let mut y = 0.0;
        u.iter()
            .map(|&x| {
                y = a * y + (1.0 - a) * x;
                y
            })
            .collect()
    }

    fn exact(f: f64, a: f64) -> C64 {
        let w = 2.0 * PI * f / FS;
        cdiv((1.0 - a, 0.0), (1.0 - a * w.cos(), a * w.sin()))
    }

    #[test]
    fn fft_of_a_cosine_is_two_lines() {
        let n = 64;
        let mut x: Vec<C64> = (0..n)
            .map(|t| ((2.0 * PI * 5.0 * t as f64 / n as f64).cos(), 0.0))
            .collect();
        fft(&mut x);
        assert!((x[5].0 - 32.0).abs() < 1e-9 && (x[59].0 - 32.0).abs() < 1e-9);
        assert!(x[6].0.hypot(x[6].1) < 1e-9);
    }

    #[test]
    fn welch_recovers_a_first_order_filter_with_coherence_one() {
        let a = 0.9; // corner ≈ 335 Hz at 20 kHz
        let u: Vec<f64> = white_noise(40_000, 300.0, 7)
            .iter()
            .map(|&v| v as f64)
            .collect();
        let y = first_order(&u, a);
        let est = welch(&u, &y, 1024, 512, FS).unwrap();
        for p in est.iter().filter(|p| p.f <= 5000.0) {
            let e = exact(p.f, a);
            let db = 20.0 * (p.h.0.hypot(p.h.1) / e.0.hypot(e.1)).log10();
            let deg = (p.h.1.atan2(p.h.0) - e.1.atan2(e.0)).to_degrees();
            assert!(db.abs() < 0.5, "{} Hz: {db} dB", p.f);
            assert!(deg.abs() < 3.0, "{} Hz: {deg} deg", p.f);
            assert!(p.coherence > 0.99, "{} Hz: {}", p.f, p.coherence);
        }
    }

    #[test]
    fn noise_on_the_output_lowers_the_coherence_not_h1() {
        let a = 0.9;
        let u: Vec<f64> = white_noise(40_000, 300.0, 7)
            .iter()
            .map(|&v| v as f64)
            .collect();
        let clean = first_order(&u, a);
        let noise = white_noise(40_000, 100.0, 99);
        let y: Vec<f64> = clean
            .iter()
            .zip(&noise)
            .map(|(c, &n)| c + n as f64)
            .collect();
        let est = welch(&u, &y, 1024, 512, FS).unwrap();
        let mean = |lo: f64, hi: f64| {
            let v: Vec<f64> = est
                .iter()
                .filter(|p| p.f >= lo && p.f < hi)
                .map(|p| p.coherence)
                .collect();
            v.iter().sum::<f64>() / v.len() as f64
        };
        // Below the corner the filter passes most of u: coherence stays high; far above
        // it the output is mostly noise.
        assert!(mean(20.0, 200.0) > 0.8, "{}", mean(20.0, 200.0));
        assert!(mean(3000.0, 9000.0) < 0.5, "{}", mean(3000.0, 9000.0));
        // H1 is unbiased by output noise: still close where the coherence is high.
        for p in est.iter().filter(|p| p.f < 200.0) {
            let e = exact(p.f, a);
            let db = 20.0 * (p.h.0.hypot(p.h.1) / e.0.hypot(e.1)).log10();
            assert!(db.abs() < 1.5, "{} Hz: {db} dB", p.f);
        }
    }

    #[test]
    fn welch_refuses_what_it_cannot_estimate() {
        let x = vec![0.0; 128];
        assert_eq!(welch(&x, &x, 100, 0, FS), Err(WelchError::Nfft(100)));
        assert_eq!(welch(&x, &x, 64, 64, FS), Err(WelchError::Overlap(64)));
        assert!(matches!(
            welch(&x, &x, 64, 0, FS),
            Ok(v) if v.len() == 31
        ));
        assert_eq!(
            welch(&x[..70], &x[..70], 64, 0, FS),
            Err(WelchError::TooShort { n: 70, need: 128 })
        );
    }

    #[test]
    fn chirp_sweeps_from_f0_to_f1() {
        let c = chirp(20_000, 10.0, 1000.0, 500.0);
        assert_eq!(c.len(), 20_000);
        assert!(c.iter().all(|v| v.abs() <= 500));
        let crossings = |s: &[i16]| s.windows(2).filter(|w| w[0] < 0 && w[1] >= 0).count();
        // First 10 ms near 10 Hz: at most one period; last 10 ms near 1 kHz: ~10.
        assert!(crossings(&c[..200]) <= 1);
        let end = crossings(&c[19_800..]);
        assert!((8..=11).contains(&end), "{end}");
    }

    #[test]
    fn noise_is_seeded_and_has_its_sigma() {
        let a = white_noise(20_000, 200.0, 1);
        assert_eq!(a, white_noise(20_000, 200.0, 1));
        assert_ne!(a, white_noise(20_000, 200.0, 2));
        let sd = (a.iter().map(|&v| (v as f64).powi(2)).sum::<f64>() / a.len() as f64).sqrt();
        assert!((sd - 200.0).abs() < 10.0, "{sd}");
        assert!(a.iter().all(|v| v.abs() <= 600));
    }

    #[test]
    fn plant_estimate_through_the_controller_gives_r_and_l_back() {
        let m = PlantModel::of(&oxicat_plant::re30::Re30Params::maxon_310007());
        let est: Vec<(f64, C64)> = (1..200)
            .map(|k| (k as f64 * 40.0, m.h(k as f64 * 40.0)))
            .collect();
        let (r, l) = fit_r_l(&est, &m, 200.0, 4000.0).unwrap();
        assert!(
            (r - 0.611).abs() < 1e-6 && (l - 0.119e-3).abs() < 1e-9,
            "{r} {l}"
        );
        // C at low frequency is dominated by the integrator, at high by P.
        let c_lo = controller(1.0, 154, 1024, 24.0);
        assert!(c_lo.0.hypot(c_lo.1) > 100.0);
        // 1/(1 − z⁻¹) = 1/2 − j·cot(ωT/2)/2; kp = 6.016 V/A, ki = 0.625 V/A per sample,
        // the u2pwm path 26·24/(256·250)·100 = 0.975.
        let c_hi = controller(9000.0, 154, 1024, 24.0);
        let w = 2.0 * PI * 9000.0 / FS;
        let want = (
            (6.015_625 + 0.625 * 0.5) * 0.975,
            -0.625 * 0.5 / (w / 2.0).tan() * 0.975,
        );
        assert!(
            (c_hi.0 - want.0).abs() < 1e-9 && (c_hi.1 - want.1).abs() < 1e-9,
            "{c_hi:?}"
        );
    }

    #[test]
    fn setpoint_files_are_checked_line_by_line() {
        let ok: String = (0..SETPOINTS_MIN)
            .map(|k| format!("{}\n", k % 100))
            .collect();
        assert_eq!(
            parse_setpoints(&format!("# header\n\n{ok}")).unwrap().len(),
            SETPOINTS_MIN
        );
        let with = |bad: &str| format!("# mA\n1\n2\n{bad}\n{ok}");
        assert_eq!(
            parse_setpoints(&with("abc")).unwrap_err().to_string(),
            "line 4: \"abc\" is not a number (one setpoint in mA per line)"
        );
        assert!(matches!(
            parse_setpoints(&with("NaN")),
            Err(SetpointError::NotFinite { line: 4, .. })
        ));
        assert!(matches!(
            parse_setpoints(&with("-inf")),
            Err(SetpointError::NotFinite { line: 4, .. })
        ));
        let e = parse_setpoints(&with("8000")).unwrap_err();
        assert_eq!(
            e,
            SetpointError::OutOfRange {
                line: 4,
                value: 8000.0,
                limit: 7500.0
            }
        );
        assert!(e
            .to_string()
            .starts_with("line 4: 8000 mA is not in -7500 … 7500 mA"));
        let e = parse_setpoints("1\n2\n3\n").unwrap_err();
        assert_eq!(
            e,
            SetpointError::Length {
                n: 3,
                min: SETPOINTS_MIN,
                max: SETPOINTS_MAX
            }
        );
    }
}
