//! Results of a trot run: the CSV (one row per cycle, `<leg>.<variable> [unit]` columns),
//! the derived quantities the thesis' post-processing computes (kinematic-frame angles,
//! toe positions, joint speeds), and the summary table.
//!
//! Everything here is a pure function of the recorded integers, formatted with fixed
//! decimals, so equal runs give equal bytes.

use std::fmt::Write as _;

use crate::laelaps::hw::{JOINT_RATIO_HIP, JOINT_RATIO_KNEE, L1, L2, U_MAX_HIP, U_MAX_KNEE};
use crate::laelaps::rig::LegId;
use oxicat_sim::exec_time::Work;

use crate::laelaps::experiment::{var, TrotRun, INPUTS};

/// Hip joint speed limit \[rad/s\]: 75.83 rpm (the thesis' post-processing,
/// `Hip_max_velocity`; the EC 45's maximum speed through 79.15).
pub const HIP_MAX_SPEED: f64 = 75.83 * std::f64::consts::TAU / 60.0;
/// Knee joint speed limit \[rad/s\]: 55.5 rpm (`Knee_max_velocity`).
pub const KNEE_MAX_SPEED: f64 = 55.5 * std::f64::consts::TAU / 60.0;
/// Knee PWM limit \[%\].
pub const KNEE_PWM_LIMIT: f64 = U_MAX_KNEE as f64 * 100.0;
/// Hip PWM limit \[%\].
pub const HIP_PWM_LIMIT: f64 = U_MAX_HIP as f64 * 100.0;

/// Sign from the joint (PDO) frame to the kinematic frame: the right legs' angles are
/// negated, as the thesis' post-processing does.
pub fn frame_sign(leg: LegId) -> f64 {
    match leg.side() {
        crate::laelaps::Side::Left => 1.0,
        crate::laelaps::Side::Right => -1.0,
    }
}

/// Toe position `(x, y)` \[m\] of kinematic-frame angles (hip, knee) \[rad\] (thesis eq. 3-1).
pub fn toe(hip: f64, knee: f64) -> (f64, f64) {
    let (l1, l2) = (f64::from(L1), f64::from(L2));
    (
        l1 * hip.sin() + l2 * knee.sin(),
        l1 * hip.cos() + l2 * knee.cos(),
    )
}

/// One leg in one cycle, in SI units and the kinematic frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LegSample {
    /// Hip angle \[rad\].
    pub hip: f64,
    /// Desired hip angle \[rad\].
    pub hip_des: f64,
    /// Knee angle \[rad\].
    pub knee: f64,
    /// Desired knee angle \[rad\].
    pub knee_des: f64,
    /// Knee PWM \[%\] (signed, joint frame as sent).
    pub pwm_knee: f64,
    /// Hip PWM \[%\].
    pub pwm_hip: f64,
    /// Knee joint speed \[rad/s\] (motor speed / ratio, kinematic frame).
    pub speed_knee: f64,
    /// Hip joint speed \[rad/s\].
    pub speed_hip: f64,
    /// Trajectory clock \[s\].
    pub time: f64,
    /// Toe from the measured angles \[m\].
    pub toe: (f64, f64),
    /// Toe from the desired angles \[m\].
    pub toe_des: (f64, f64),
}

/// Decodes leg `li` (Table 4-1 order) of a row.
pub fn sample(raw: &[i32; 9], leg: LegId) -> LegSample {
    let s = frame_sign(leg);
    let deg = |v: usize| f64::from(raw[v]) / 100.0;
    let rad = |v: usize| s * deg(v).to_radians();
    let (hip, hip_des, knee, knee_des) = (
        rad(var::HIP),
        rad(var::HIP_DES),
        rad(var::KNEE),
        rad(var::KNEE_DES),
    );
    LegSample {
        hip,
        hip_des,
        knee,
        knee_des,
        pwm_knee: f64::from(raw[var::PWM_KNEE]) / 100.0,
        pwm_hip: f64::from(raw[var::PWM_HIP]) / 100.0,
        speed_knee: s * f64::from(raw[var::VEL_KNEE]) / 1000.0 / f64::from(JOINT_RATIO_KNEE),
        speed_hip: s * f64::from(raw[var::VEL_HIP]) / 1000.0 / f64::from(JOINT_RATIO_HIP),
        time: f64::from(raw[var::TIME]) / 100.0,
        toe: toe(hip, knee),
        toe_des: toe(hip_des, knee_des),
    }
}

/// Writes `raw / 10^decimals` exactly (no float rounding): the text of
/// `format!("{sign}{}.{:0decimals$}", |raw| / 10^decimals, |raw| % 10^decimals)` (no point
/// for 0 decimals; at most 18 decimals), built from its digits on the stack — the CSV
/// writes 61,250 rows of 64 such fields, where `core::fmt` took a fifth of a whole trot's
/// CPU time. Inlined into its three callers, with the power of ten from a table: a call
/// and `u64::pow`'s loop cost as much as the digits of a short field.
#[inline(always)]
fn fixed(out: &mut Vec<u8>, raw: i64, decimals: u32) {
    /// "00" "01" … "99".
    const PAIRS: [[u8; 2]; 100] = {
        let mut t = [[0u8; 2]; 100];
        let mut k = 0;
        while k < 100 {
            t[k] = [b'0' + (k / 10) as u8, b'0' + (k % 10) as u8];
            k += 1;
        }
        t
    };
    /// 10^0 … 10^18.
    const POW10: [u64; 19] = {
        let mut t = [1u64; 19];
        let mut k = 1;
        while k < 19 {
            t[k] = t[k - 1] * 10;
            k += 1;
        }
        t
    };
    // |i64::MIN| has 19 digits; with 18 decimals, a leading zero, the point and the sign
    // at most 22 bytes, written from the end of the buffer backwards two digits at a time.
    const W: usize = 24;
    let mut buf = [0u8; W];
    let mut i = W;
    let dec = decimals.min(18);
    let a = raw.unsigned_abs();
    let mut int = a;
    if dec > 0 {
        let p = POW10[dec as usize];
        int = a / p;
        let mut frac = a % p;
        let mut k = dec;
        while k >= 2 {
            i -= 2;
            buf[i..i + 2].copy_from_slice(&PAIRS[(frac % 100) as usize]);
            frac /= 100;
            k -= 2;
        }
        if k == 1 {
            i -= 1;
            buf[i] = b'0' + (frac % 10) as u8;
        }
        i -= 1;
        buf[i] = b'.';
    }
    while int >= 100 {
        i -= 2;
        buf[i..i + 2].copy_from_slice(&PAIRS[(int % 100) as usize]);
        int /= 100;
    }
    if int >= 10 {
        i -= 2;
        buf[i..i + 2].copy_from_slice(&PAIRS[int as usize]);
    } else {
        i -= 1;
        buf[i] = b'0' + int as u8;
    }
    if raw < 0 {
        i -= 1;
        buf[i] = b'-';
    }
    out.extend_from_slice(&buf[i..]);
}

/// Millimetres with two decimals, `-0.00` written as `0.00`.
fn mm(out: &mut Vec<u8>, m: f64) {
    let v = (m * 100_000.0).round() as i64;
    fixed(out, v, 2);
}

/// The CSV of a run: one header line, one row per recorded cycle.
pub fn csv(run: &TrotRun) -> String {
    let cyc_ns = run.scenario.cycle_ns();
    let mut h = String::from("cycle,t [s],State_Machine,wkc");
    for leg in LegId::TABLE {
        let c = leg.code();
        let _ = write!(h, ",{c}.a_ellipse [cm],{c}.b_ellipse [cm]");
        for v in INPUTS {
            let _ = write!(h, ",{c}.{} [{}]", v.name, v.unit);
        }
        let _ = write!(
            h,
            ",{c}.toe_x_desired [mm],{c}.toe_y_desired [mm],{c}.toe_x [mm],{c}.toe_y [mm]"
        );
    }
    h.push('\n');
    let decimals = INPUTS.map(|iv| iv.divisor.ilog10());
    // Bytes, not a `String`: every field is ASCII digits, '-', '.' and ',' (checked once
    // at the end instead of per field).
    let mut out = Vec::with_capacity(h.len() + run.rows.len() * 420);
    out.extend_from_slice(h.as_bytes());
    for (k, r) in run.rows.iter().enumerate() {
        fixed(&mut out, k as i64, 0);
        out.push(b',');
        // t in µs resolution, exact.
        fixed(&mut out, (k as u64 * cyc_ns / 1000) as i64, 6);
        out.push(b',');
        out.push(if r.state_machine { b'1' } else { b'0' });
        out.push(b',');
        fixed(&mut out, i64::from(r.wkc), 0);
        for (li, leg) in LegId::TABLE.into_iter().enumerate() {
            out.push(b',');
            fixed(&mut out, i64::from(r.a_cmd[li]), 0);
            out.push(b',');
            fixed(&mut out, i64::from(r.b_cmd[li]), 0);
            for (v, dec) in decimals.iter().enumerate() {
                out.push(b',');
                fixed(&mut out, i64::from(r.inputs[li][v]), *dec);
            }
            let s = sample(&r.inputs[li], leg);
            for m in [s.toe_des.0, s.toe_des.1, s.toe.0, s.toe.1] {
                out.push(b',');
                mm(&mut out, m);
            }
        }
        out.push(b'\n');
    }
    String::from_utf8(out).unwrap_or_else(|e| String::from_utf8_lossy(e.as_bytes()).into_owned())
}

/// Summary of one leg over the steady trot.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LegSummary {
    /// Knee error RMS \[deg\].
    pub knee_rms_deg: f64,
    /// Knee error max \[deg\].
    pub knee_max_deg: f64,
    /// Hip error RMS \[deg\].
    pub hip_rms_deg: f64,
    /// Hip error max \[deg\].
    pub hip_max_deg: f64,
    /// Toe path error RMS \[mm\] (measured against desired toe, same cycle).
    pub toe_rms_mm: f64,
    /// Share of cycles with the knee PWM at its limit \[%\].
    pub knee_at_limit_pct: f64,
    /// Share of cycles with the hip PWM at its limit \[%\].
    pub hip_at_limit_pct: f64,
    /// Peak knee joint speed \[rad/s\].
    pub knee_peak_speed: f64,
    /// Peak hip joint speed \[rad/s\].
    pub hip_peak_speed: f64,
}

/// Summary of a run.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// Per leg, Table 4-1 order.
    pub legs: [LegSummary; 4],
    /// Correlation of toe heights (y) over the steady trot: `(a, b, r)`.
    pub toe_height_correlation: Vec<(LegId, LegId, f64)>,
    /// Window the summary covers: `[start, end)` cycles.
    pub window: (u64, u64),
}

/// The steady-trot window: from the first full period after a and b reached their values
/// to the start of the ramp back.
pub fn steady_window(run: &TrotRun) -> (u64, u64) {
    let p = &run.phases;
    let f = run
        .scenario
        .legs
        .iter()
        .map(|l| l.freq_hz)
        .fold(f64::INFINITY, f64::min);
    let settle = run.scenario.cycles(1.0 / f).min((p.back_a - p.trot) / 2);
    (p.trot + settle, p.back_a.min(run.rows.len() as u64))
}

fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len()) as f64;
    if n < 2.0 {
        return 0.0;
    }
    let ma = a.iter().sum::<f64>() / n;
    let mb = b.iter().sum::<f64>() / n;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    if saa == 0.0 || sbb == 0.0 {
        0.0
    } else {
        sab / (saa * sbb).sqrt()
    }
}

/// Computes the summary over [`steady_window`].
pub fn summarize(run: &TrotRun) -> Summary {
    let (w0, w1) = steady_window(run);
    let rows = &run.rows[w0 as usize..w1 as usize];
    let n = rows.len().max(1) as f64;
    let mut legs = [LegSummary::default(); 4];
    let mut heights: Vec<Vec<f64>> = (0..4).map(|_| Vec::with_capacity(rows.len())).collect();
    for (li, leg) in LegId::TABLE.into_iter().enumerate() {
        let mut s = LegSummary::default();
        let (mut ek2, mut eh2, mut et2) = (0.0, 0.0, 0.0);
        let (mut kl, mut hl) = (0u64, 0u64);
        for r in rows {
            let x = sample(&r.inputs[li], leg);
            let ek = (x.knee_des - x.knee).to_degrees();
            let eh = (x.hip_des - x.hip).to_degrees();
            ek2 += ek * ek;
            eh2 += eh * eh;
            s.knee_max_deg = s.knee_max_deg.max(ek.abs());
            s.hip_max_deg = s.hip_max_deg.max(eh.abs());
            let (dx, dy) = (x.toe.0 - x.toe_des.0, x.toe.1 - x.toe_des.1);
            et2 += (dx * dx + dy * dy) * 1e6;
            // At the limit: within one PDO step (0.01 %) plus the f32 truncation.
            if x.pwm_knee.abs() >= KNEE_PWM_LIMIT - 0.02 {
                kl += 1;
            }
            if x.pwm_hip.abs() >= HIP_PWM_LIMIT - 0.02 {
                hl += 1;
            }
            s.knee_peak_speed = s.knee_peak_speed.max(x.speed_knee.abs());
            s.hip_peak_speed = s.hip_peak_speed.max(x.speed_hip.abs());
            heights[li].push(x.toe.1);
        }
        s.knee_rms_deg = (ek2 / n).sqrt();
        s.hip_rms_deg = (eh2 / n).sqrt();
        s.toe_rms_mm = (et2 / n).sqrt();
        s.knee_at_limit_pct = kl as f64 * 100.0 / n;
        s.hip_at_limit_pct = hl as f64 * 100.0 / n;
        legs[li] = s;
    }
    let t = LegId::TABLE;
    let mut toe_height_correlation = Vec::new();
    for (a, b) in [(0, 3), (1, 2), (0, 1), (2, 3), (0, 2), (1, 3)] {
        toe_height_correlation.push((t[a], t[b], correlation(&heights[a], &heights[b])));
    }
    Summary {
        legs,
        toe_height_correlation,
        window: (w0, w1),
    }
}

/// The summary as a Markdown document (tables), for `summary.md` and the terminal.
pub fn summary_markdown(run: &TrotRun, s: &Summary) -> String {
    let cyc = run.scenario.cycle_ns() as f64 * 1e-9;
    let mut o = String::new();
    let _ = writeln!(o, "# {}\n", run.scenario.name);
    let _ = writeln!(
        o,
        "Steady trot, cycles {}–{} ({:.1}–{:.1} s after `State_Machine = 1`); joint errors \
         desired − measured in the kinematic frame; toe error = distance between the toe of \
         the measured and of the desired angles in the same cycle.\n",
        s.window.0,
        s.window.1,
        s.window.0 as f64 * cyc,
        s.window.1 as f64 * cyc
    );
    let _ = writeln!(
        o,
        "| leg | knee RMS / max [deg] | hip RMS / max [deg] | toe RMS [mm] | knee PWM at limit | hip PWM at limit | peak knee speed [rad/s] (limit {KNEE_MAX_SPEED:.2}) | peak hip speed [rad/s] (limit {HIP_MAX_SPEED:.2}) |"
    );
    let _ = writeln!(o, "|---|---|---|---|---|---|---|---|");
    for (li, leg) in LegId::TABLE.into_iter().enumerate() {
        let l = &s.legs[li];
        let _ = writeln!(
            o,
            "| {} | {:.2} / {:.2} | {:.2} / {:.2} | {:.1} | {:.1} % | {:.1} % | {:.2} | {:.2} |",
            leg.code(),
            l.knee_rms_deg,
            l.knee_max_deg,
            l.hip_rms_deg,
            l.hip_max_deg,
            l.toe_rms_mm,
            l.knee_at_limit_pct,
            l.hip_at_limit_pct,
            l.knee_peak_speed,
            l.hip_peak_speed
        );
    }
    let _ = writeln!(
        o,
        "\nToe-height correlation (trot: diagonals +1, the others −1):\n"
    );
    let _ = writeln!(o, "| legs | r |\n|---|---|");
    for (a, b, r) in &s.toe_height_correlation {
        let _ = writeln!(o, "| {}–{} | {:+.3} |", a.code(), b.code(), r);
    }
    let b = &run.bus;
    let _ = writeln!(
        o,
        "\nBus (DC SYNC0 every {} µs):\n",
        run.scenario.bus.cycle_us
    );
    let _ = writeln!(o, "| cycles recorded | WKC errors | SYNC0 spread max [ns] | cycles without exactly one SYNC0 per node | trajectory clocks started at SYNC0 # (FL FR HL HR) |");
    let _ = writeln!(o, "|---|---|---|---|---|");
    let _ = writeln!(
        o,
        "| {} | {} | {} | {} | {} {} {} {} |",
        b.cycles,
        b.wkc_errors,
        b.sync0_spread_max_ns,
        b.sync0_missed,
        sync0_no(b.release_sync0[0]),
        sync0_no(b.release_sync0[1]),
        sync0_no(b.release_sync0[2]),
        sync0_no(b.release_sync0[3])
    );
    thesis_markdown(&mut o, run, s);
    pdi_markdown(&mut o, run);
    timing_markdown(&mut o, run);
    o
}

/// One of the thesis' per-leg observations of its trotting experiment (§4.1, Figures 4-1
/// to 4-7) beside what a run shows.
#[derive(Debug, Clone, PartialEq)]
pub struct Observation {
    /// What is observed.
    pub what: &'static str,
    /// What the thesis says.
    pub thesis: &'static str,
    /// This run's figures.
    pub run: String,
    /// Whether the run shows what the thesis saw.
    pub agrees: bool,
}

/// The fore legs' and the hind legs' mean of `f` over a summary's legs.
fn fore_hind(s: &Summary, f: impl Fn(&LegSummary) -> f64) -> (f64, f64) {
    let mut fore = 0.0;
    let mut hind = 0.0;
    for (li, leg) in LegId::TABLE.into_iter().enumerate() {
        match leg {
            LegId::ForeLeft | LegId::ForeRight => fore += 0.5 * f(&s.legs[li]),
            LegId::HindLeft | LegId::HindRight => hind += 0.5 * f(&s.legs[li]),
        }
    }
    (fore, hind)
}

/// The thesis' observations (§4.1) against the summary of a run. Per leg the figures are
/// in Table 4-1 order (FL / FR / HL / HR).
pub fn thesis_observations(s: &Summary) -> Vec<Observation> {
    let per_leg = |f: &dyn Fn(&LegSummary) -> f64, dec: usize, unit: &str| {
        let v: Vec<String> = s.legs.iter().map(|l| format!("{:.dec$}", f(l))).collect();
        format!("{}{unit}", v.join(" / "))
    };
    let (toe_f, toe_h) = fore_hind(s, |l| l.toe_rms_mm);
    let (kl_f, kl_h) = fore_hind(s, |l| l.knee_at_limit_pct);
    let (hl_f, hl_h) = fore_hind(s, |l| l.hip_at_limit_pct);
    let hip_worse = s.legs.iter().all(|l| l.hip_rms_deg > l.knee_rms_deg);
    let within = s
        .legs
        .iter()
        .all(|l| l.knee_peak_speed <= KNEE_MAX_SPEED && l.hip_peak_speed <= HIP_MAX_SPEED);
    vec![
        Observation {
            what: "toe path tracking (Fig. 4-1)",
            thesis: "not closely tracked, especially the hind legs",
            run: format!("toe RMS {}", per_leg(&|l| l.toe_rms_mm, 1, " mm")),
            agrees: toe_h > toe_f,
        },
        Observation {
            what: "hip against knee errors (Figs. 4-2, 4-3)",
            thesis: "hip errors larger than knee errors",
            run: format!(
                "hip RMS {} against knee RMS {}",
                per_leg(&|l| l.hip_rms_deg, 2, "°"),
                per_leg(&|l| l.knee_rms_deg, 2, "°")
            ),
            agrees: hip_worse,
        },
        Observation {
            what: "knee PWM at its limit (Fig. 4-4)",
            thesis: "fore legs several times, briefly; hind legs always within",
            run: format!(
                "{} of the steady trot",
                per_leg(&|l| l.knee_at_limit_pct, 1, " %")
            ),
            agrees: kl_f > kl_h,
        },
        Observation {
            what: "hip PWM at its limit (Fig. 4-5)",
            thesis: "recurrently, especially the hind legs",
            run: format!(
                "{} of the steady trot",
                per_leg(&|l| l.hip_at_limit_pct, 1, " %")
            ),
            agrees: hl_h > hl_f,
        },
        Observation {
            what: "joint speeds (Figs. 4-6, 4-7)",
            thesis: "all within the motors' limits",
            run: format!(
                "peak knee {} (limit {KNEE_MAX_SPEED:.2}), hip {} (limit {HIP_MAX_SPEED:.2}) rad/s",
                per_leg(&|l| l.knee_peak_speed, 2, ""),
                per_leg(&|l| l.hip_peak_speed, 2, "")
            ),
            agrees: within,
        },
    ]
}

/// The thesis' observations beside the run's (`summary.md`).
fn thesis_markdown(o: &mut String, run: &TrotRun, s: &Summary) {
    let r = &run.scenario.robot;
    let how = if r.body {
        format!(
            "the four legs on one body on its support ({} kg, hips {} cm apart, centre of mass \
             {} cm behind their midpoint, the support carrying {:.0} % of the weight; assumed), \
             link masses within ±{} % and motor constants within ±{} % of nominal, seed {}",
            r.mass_kg,
            r.hip_spacing_cm,
            r.com_behind_cm,
            100.0 * r.support_share,
            r.mass_tolerance_pct,
            r.motor_tolerance_pct,
            r.seed
        )
    } else {
        format!(
            "each leg alone with its hip fixed, link masses within ±{} % and motor constants \
             within ±{} % of nominal",
            r.mass_tolerance_pct, r.motor_tolerance_pct
        )
    };
    let _ = writeln!(
        o,
        "\nPer leg against the thesis' observations (§4.1; figures FL / FR / HL / HR). This \
         run: {how}.\n"
    );
    let _ = writeln!(o, "| observation | thesis | this run | agrees |");
    let _ = writeln!(o, "|---|---|---|---|");
    for ob in thesis_observations(s) {
        let _ = writeln!(
            o,
            "| {} | {} | {} | {} |",
            ob.what,
            ob.thesis,
            ob.run,
            if ob.agrees { "yes" } else { "no" }
        );
    }
    if let (Some(late), Some(b)) = (run.body_late, run.body_stats) {
        let l = b.mean_load();
        let _ = writeln!(
            o,
            "\nThe body over the steady trot: mean load carried FL / FR / HL / HR {:.1} / {:.1} / {:.1} / \
             {:.1} N, heave {:.2} … {:.2} mm (down), pitch {:.3} … {:.3}° (nose up); {late} body \
             steps asked for before every leg had reported (0: exact lock-step).",
            l[0],
            l[1],
            l[2],
            l[3],
            b.z_range.0 * 1e3,
            b.z_range.1 * 1e3,
            b.phi_range.0.to_degrees(),
            b.phi_range.1.to_degrees()
        );
    }
}

/// The bound a PV joint loop keeps the tracking error within, per joint of a leg's summary
/// (knee, hip) \[deg\], for the scenario's gains. Per joint, with r, y in revolutions:
/// v9 = Kp·(r − y − v4), v4 = the filtered Kd·ẏ, u = sat(v9, ±u_max). Whenever the output
/// is not saturated |v9| ≤ u_max, so |r − y| ≤ u_max/Kp + Kd·max|ẏ| (the filter's gain ≤ 1),
/// i.e. |e| ≤ 2π·u_max/Kp + Kd·max|θ̇| in radians: the V path makes the error grow with the
/// joint speed. Added: the measurement resolution (the 0.01° PDO step and one encoder
/// count) and 0.5° for the short intervals at the PWM limit, where the relation does not
/// hold. The trot tests (host-compiled and board images) assert it.
///
/// With `[control] law = "dcl-pid"` (the parallel C4 PID) v9 = Kp·(r − y) + i − v4 with v4
/// the filtered Kd·ẏ, not multiplied by Kp: the velocity lag is (Kd/Kp)·max|θ̇|. With
/// Ki > 0 the integrator `i` adds |i|/Kp; the clamp integrates only while |v9| ≤ u_max and
/// an |i| above u_max + Kd·|ẏ| would need an opposite Kp·e that drains it, so |i| ≤ u_max
/// outside the PWM-limit intervals and the bound doubles the u_max/Kp term.
pub fn pv_bound_deg(s: &crate::laelaps::scenario::Scenario, l: &LegSummary) -> (f64, f64) {
    let tau = std::f64::consts::TAU;
    let slack_deg = 0.01 + 0.01 + 0.5;
    let pid = s.control.law() == crate::laelaps::piv::ControlLaw::DclPid;
    let one = |g: &crate::laelaps::scenario::GainSet, u_max: f32, speed: f64| {
        let (lag, windup) = if pid {
            (g.kd / g.kp, if g.ki > 0.0 { 2.0 } else { 1.0 })
        } else {
            (g.kd, 1.0)
        };
        (windup * tau * f64::from(u_max) / g.kp + lag * speed).to_degrees() + slack_deg
    };
    (
        one(&s.control.knee, U_MAX_KNEE, l.knee_peak_speed),
        one(&s.control.hip, U_MAX_HIP, l.hip_peak_speed),
    )
}

/// A SYNC0 number, or `–` where the host does not know it.
fn sync0_no(n: Option<u64>) -> String {
    n.map_or_else(|| "–".into(), |n| n.to_string())
}

/// The execution-time model's figures per node (nothing when it is off).
fn timing_markdown(o: &mut String, run: &TrotRun) {
    let p = &run.pdi;
    if p.nodes.iter().all(|n| n.timing.is_none()) {
        return;
    }
    let cpu = run
        .scenario
        .pdi
        .exec_time
        .timing()
        .map_or(0, |t| t.cpu_ns(Work::Sync0));
    let _ = writeln!(
        o,
        "\nExecution time (`oxicat_sim::exec_time`, `{}`: SYNC0 handler = SPI bus time + {} ns \
         CPU; its inputs land in SM3 when it ends; whole run, bring-up included). Busy = bus + \
         CPU time of the SYNC0 handler, response = SYNC0 edge to its writes in the ESC \
         (the input latency); the master's frame leaves {} µs after SYNC0:\n",
        run.scenario.pdi.exec_time.name(),
        cpu,
        run.scenario.bus.sync0_shift_us
    );
    let _ = writeln!(o, "| leg | SYNC0 handlers | SYNC0 busy min / max [µs] | SYNC0 response max [µs] | SYNC0 delayed | SYNC0 lost | joint-loop ticks delayed / lost | joint-loop tick wait max [µs] |");
    let _ = writeln!(o, "|---|---|---|---|---|---|---|---|");
    for (li, leg) in LegId::TABLE.into_iter().enumerate() {
        let Some(t) = p.nodes[li].timing else {
            continue;
        };
        let s0 = t.get(Work::Sync0);
        let tm = t.get(Work::Timer);
        let _ = writeln!(
            o,
            "| {} | {} | {:.3} / {:.3} | {:.3} | {} | {} | {} / {} | {:.3} |",
            leg.code(),
            s0.runs,
            s0.min_busy_ns as f64 / 1e3,
            s0.max_busy_ns as f64 / 1e3,
            s0.max_response_ns as f64 / 1e3,
            s0.delayed,
            s0.lost,
            tm.delayed,
            tm.lost,
            tm.max_wait_ns as f64 / 1e3
        );
    }
}

/// The SPI table of a run whose leg nodes reached their ESCs through a chip driver (nothing
/// on the direct route).
fn pdi_markdown(o: &mut String, run: &TrotRun) {
    let p = &run.pdi;
    if p.nodes.iter().all(|n| n.spi.is_none()) {
        return;
    }
    let cycles = run.bus.cycles.max(1);
    let cycle_us = f64::from(run.scenario.bus.cycle_us);
    let how = if p.machine_code {
        "bus time = 8 bits per byte at the image's SCLK, simulated: the board images run \
         instruction by instruction and wait for every byte"
    } else if p.nodes.iter().any(|n| n.timing.is_some()) {
        "bus time = 8 bits per byte at SCLK + 100 ns CS per transaction, simulated: under \
         the execution-time model each handler keeps the MCU busy that long"
    } else {
        "bus time = 8 bits per byte at SCLK + 100 ns CS per transaction, counted, not \
         simulated: the firmware runs in zero virtual time"
    };
    let who = if p.machine_code {
        "board image's"
    } else {
        "node's firmware"
    };
    let _ = writeln!(
        o,
        "\nPDI: every leg {who} reaches its ESC through {} (the oxicat-pdi driver over \
         the simulated chip; {how}). Per node and recorded cycle:\n",
        p.route
    );
    let _ = writeln!(o, "| leg | SPI transactions | SPI bytes | SPI bus time [µs] | share of the {cycle_us:.0} µs cycle | PDI errors | SPI protocol errors |");
    let _ = writeln!(o, "|---|---|---|---|---|---|---|");
    for (li, leg) in LegId::TABLE.into_iter().enumerate() {
        let n = &p.nodes[li];
        let Some(spi) = n.spi else { continue };
        let us = n.spi_us_per_cycle(cycles).unwrap_or(0.0);
        let _ = writeln!(
            o,
            "| {} | {:.2} | {:.2} | {:.2} | {:.1} % | {} | {} |",
            leg.code(),
            spi.transactions as f64 / cycles as f64,
            spi.bytes as f64 / cycles as f64,
            us,
            100.0 * us / cycle_us,
            n.pdi_errors,
            spi.protocol_errors
        );
    }
}

#[cfg(test)]
mod observation_tests {
    use super::*;

    fn summary(toe: [f64; 4], knee: [f64; 4], hip: [f64; 4]) -> Summary {
        let mut legs = [LegSummary::default(); 4];
        for (i, l) in legs.iter_mut().enumerate() {
            l.toe_rms_mm = toe[i];
            l.knee_at_limit_pct = knee[i];
            l.hip_at_limit_pct = hip[i];
            l.knee_rms_deg = 2.0;
            l.hip_rms_deg = 3.0;
            l.knee_peak_speed = 1.0;
            l.hip_peak_speed = 1.0;
        }
        Summary {
            legs,
            toe_height_correlation: Vec::new(),
            window: (0, 1),
        }
    }

    fn agrees(s: &Summary) -> Vec<bool> {
        thesis_observations(s).iter().map(|o| o.agrees).collect()
    }

    /// The thesis' pattern (hind legs track worst, knee PWM limit in the fore legs, hip PWM
    /// limit in the hind legs) agrees on every line; the mirror image on none of the three.
    #[test]
    fn observations_compare_fore_and_hind() {
        let thesis = summary(
            [12.0, 12.0, 17.0, 17.0],
            [9.0, 9.0, 0.0, 0.0],
            [4.0, 4.0, 21.0, 21.0],
        );
        assert_eq!(agrees(&thesis), [true, true, true, true, true]);
        let mirror = summary(
            [17.0, 17.0, 12.0, 12.0],
            [0.0, 0.0, 9.0, 9.0],
            [21.0, 21.0, 4.0, 4.0],
        );
        assert_eq!(agrees(&mirror), [false, true, false, false, true]);
        let o = thesis_observations(&thesis);
        assert_eq!(o[0].run, "toe RMS 12.0 / 12.0 / 17.0 / 17.0 mm");
        // A joint faster than its motor's limit is reported.
        let mut fast = thesis.clone();
        fast.legs[2].hip_peak_speed = HIP_MAX_SPEED + 0.1;
        assert!(!agrees(&fast)[4]);
    }

    /// The digit writer of the CSV writes what `core::fmt` wrote before it (the CSV's bytes
    /// are pinned by MD5): every sign, zero padding and width, both ends of `i64`.
    #[test]
    fn fixed_writes_what_fmt_wrote() {
        fn reference(raw: i64, decimals: u32) -> String {
            let sign = if raw < 0 { "-" } else { "" };
            let a = raw.unsigned_abs();
            let d = 10u64.pow(decimals);
            if decimals == 0 {
                format!("{sign}{a}")
            } else {
                format!("{sign}{}.{:0w$}", a / d, a % d, w = decimals as usize)
            }
        }
        let mut values = vec![i64::MIN, i64::MIN + 1, i64::MAX, 0, 1, -1];
        let mut p = 1i64;
        for _ in 0..18 {
            p *= 10;
            values.extend([p - 1, p, p + 1, -(p - 1), -p, -(p + 1), p / 3, -p / 7]);
        }
        for decimals in 0..=18 {
            for &v in &values {
                let mut out = b"x".to_vec();
                super::fixed(&mut out, v, decimals);
                assert_eq!(
                    out[1..],
                    *reference(v, decimals).as_bytes(),
                    "{v} with {decimals} decimals"
                );
            }
        }
    }
}
