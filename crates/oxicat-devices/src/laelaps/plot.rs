//! The seven figures of thesis §4.1 from a trot run, as PNG and SVG (`plotters`): toe
//! paths against the desired path per leg; knee and hip angles, desired and measured; knee
//! and hip PWM against their limits; knee and hip joint speeds against the motor limits.
//! Legs in the thesis' figure order (FR, FL, HR, HL), angles in the kinematic frame.
//!
//! Text is drawn with DejaVu Sans built into the binary (`assets/fonts`, `ab_glyph`), so
//! the figures look the same on a machine without system fonts.

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::FontStyle;

use crate::laelaps::rig::LegId;

use crate::laelaps::experiment::{table_index, TrotRun};
use crate::laelaps::results::{
    sample, steady_window, LegSample, HIP_MAX_SPEED, HIP_PWM_LIMIT, KNEE_MAX_SPEED, KNEE_PWM_LIMIT,
};
use oxicat_master::MasterError;

static FONT: &[u8] = include_bytes!("../../../../assets/fonts/DejaVuSans.ttf");

/// The thesis' figure order of the legs.
pub const FIGURE_ORDER: [LegId; 4] = [
    LegId::ForeRight,
    LegId::ForeLeft,
    LegId::HindRight,
    LegId::HindLeft,
];

/// Registers the built-in font as plotters' "sans-serif" family (once per process).
pub(crate) fn font_ready() -> Result<(), MasterError> {
    use std::sync::OnceLock;
    static OK: OnceLock<bool> = OnceLock::new();
    let ok = *OK.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, FONT).is_ok()
    });
    if ok {
        Ok(())
    } else {
        Err(MasterError::Usage("the built-in font did not load".into()))
    }
}

type DrawResult = Result<(), Box<dyn std::error::Error>>;

/// Length of the plotted time window \[s\] (the thesis plots 5000 samples = 2 s).
pub const WINDOW_S: f64 = 2.0;

struct Data {
    /// Per leg (Table 4-1 order), samples over the plotted window.
    legs: [Vec<LegSample>; 4],
    /// Time of each sample \[s\] since `State_Machine = 1`.
    t: Vec<f64>,
    /// Toe paths over the whole steady window.
    toe: [Vec<LegSample>; 4],
    /// Phase boundaries to mark \[s\] (whole-run figures).
    marks: Vec<f64>,
}

/// Most samples a whole-run series keeps: per bucket of the run, the samples with the
/// lowest and the highest value (so peaks and PWM limits survive the thinning).
const WHOLE_RUN_POINTS: usize = 4000;

/// Samples per bucket of [`thin_min_max`].
fn bucket_len(n: usize, max_points: usize) -> usize {
    n.div_ceil((max_points / 2).max(1)).max(1)
}

/// Thins `n` samples to at most `max_points` (≥ 2) by buckets: per bucket the index of its
/// lowest and of its highest `value` (in that order), so every bucket's extremes — peaks,
/// limits reached — survive.
pub fn thin_min_max(n: usize, max_points: usize, value: impl Fn(usize) -> f64) -> Vec<usize> {
    let bucket = bucket_len(n, max_points);
    let mut out = Vec::with_capacity(2 * n.div_ceil(bucket));
    for start in (0..n).step_by(bucket) {
        let end = (start + bucket).min(n);
        let by = |a: &usize, b: &usize| value(*a).total_cmp(&value(*b));
        out.push((start..end).min_by(by).unwrap_or(start));
        out.push((start..end).max_by(by).unwrap_or(start));
    }
    out
}

/// The whole run (every phase, from `State_Machine = 1`), each leg thinned by
/// [`thin_min_max`] of the series `s` (the time of a bucket's pair: its start and end), with
/// the phase boundaries.
fn whole_run(run: &TrotRun, s: Series) -> Data {
    let cyc = run.scenario.cycle_ns() as f64 * 1e-9;
    let n = run.rows.len();
    let mut legs: [Vec<LegSample>; 4] = Default::default();
    for (li, leg) in LegId::TABLE.into_iter().enumerate() {
        let all: Vec<LegSample> = run
            .rows
            .iter()
            .map(|r| sample(&r.inputs[li], leg))
            .collect();
        legs[li] = thin_min_max(n, WHOLE_RUN_POINTS, |k| s.values(&all[k]).0)
            .into_iter()
            .map(|k| all[k])
            .collect();
    }
    let bucket = bucket_len(n, WHOLE_RUN_POINTS);
    let t = (0..n)
        .step_by(bucket)
        .flat_map(|a| [a, (a + bucket).min(n) - 1])
        .map(|k| k as f64 * cyc)
        .collect();
    let p = &run.phases;
    let marks = [p.ramp_b, p.ramp_a, p.trot, p.back_a, p.back_b, p.stop]
        .iter()
        .map(|&k| k as f64 * cyc)
        .collect();
    Data {
        legs,
        t,
        toe: Default::default(),
        marks,
    }
}

#[cfg(test)]
mod tests {
    use super::thin_min_max;

    #[test]
    fn thinning_keeps_every_buckets_extremes() {
        let v: Vec<f64> = (0..61_250).map(|k| ((k * 7919) % 1000) as f64).collect();
        let idx = thin_min_max(v.len(), 4000, |k| v[k]);
        assert!(idx.len() <= 4000 && idx.len() > 3900, "{}", idx.len());
        assert!(
            idx.windows(2).all(|w| w[0] / 31 <= w[1] / 31),
            "in time order by bucket"
        );
        let kept_max = idx.iter().map(|&k| v[k]).fold(f64::MIN, f64::max);
        let kept_min = idx.iter().map(|&k| v[k]).fold(f64::MAX, f64::min);
        assert_eq!((kept_min, kept_max), (0.0, 999.0));
        // A lone spike survives.
        let mut w = vec![0.0; 61_250];
        w[12_345] = 38.25;
        assert!(thin_min_max(w.len(), 4000, |k| w[k]).contains(&12_345));
        // Few samples: all kept (twice each at most).
        assert_eq!(thin_min_max(3, 4000, |k| k as f64), vec![0, 0, 1, 1, 2, 2]);
    }
}

fn data(run: &TrotRun) -> Data {
    let cyc = run.scenario.cycle_ns() as f64 * 1e-9;
    let (w0, w1) = steady_window(run);
    let n = run.scenario.cycles(WINDOW_S);
    let p1 = w1;
    let p0 = p1.saturating_sub(n).max(w0);
    let pick = |a: u64, b: u64| -> [Vec<LegSample>; 4] {
        let mut out: [Vec<LegSample>; 4] = Default::default();
        for (li, leg) in LegId::TABLE.into_iter().enumerate() {
            out[li] = run.rows[a as usize..b as usize]
                .iter()
                .map(|r| sample(&r.inputs[li], leg))
                .collect();
        }
        out
    };
    Data {
        legs: pick(p0, p1),
        t: (p0..p1).map(|k| k as f64 * cyc).collect(),
        toe: pick(w0, w1),
        marks: Vec::new(),
    }
}

fn range(vals: impl Iterator<Item = f64>, pad: f64) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in vals {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (-1.0, 1.0);
    }
    let span = (hi - lo).max(1e-6);
    (lo - pad * span, hi + pad * span)
}

/// What a time-series figure shows.
#[derive(Clone, Copy)]
enum Series {
    KneeAngle,
    HipAngle,
    KneePwm,
    HipPwm,
    KneeSpeed,
    HipSpeed,
}

impl Series {
    fn file(self) -> &'static str {
        match self {
            Series::KneeAngle => "knee_angles",
            Series::HipAngle => "hip_angles",
            Series::KneePwm => "knee_pwm",
            Series::HipPwm => "hip_pwm",
            Series::KneeSpeed => "knee_speed",
            Series::HipSpeed => "hip_speed",
        }
    }

    fn title(self) -> &'static str {
        match self {
            Series::KneeAngle => "Knee angle: desired (red) and measured (black)",
            Series::HipAngle => "Hip angle: desired (red) and measured (black)",
            Series::KneePwm => "Knee PWM and its limit (±38.25 %)",
            Series::HipPwm => "Hip PWM and its limit (±41.17 %)",
            Series::KneeSpeed => "Knee joint speed and the motor limit (55.5 rpm)",
            Series::HipSpeed => "Hip joint speed and the motor limit (75.83 rpm)",
        }
    }

    fn unit(self) -> &'static str {
        match self {
            Series::KneeAngle | Series::HipAngle => "deg",
            Series::KneePwm | Series::HipPwm => "%",
            Series::KneeSpeed | Series::HipSpeed => "rad/s",
        }
    }

    /// (measured, desired) of one sample.
    fn values(self, s: &LegSample) -> (f64, Option<f64>) {
        match self {
            Series::KneeAngle => (s.knee.to_degrees(), Some(s.knee_des.to_degrees())),
            Series::HipAngle => (s.hip.to_degrees(), Some(s.hip_des.to_degrees())),
            Series::KneePwm => (s.pwm_knee, None),
            Series::HipPwm => (s.pwm_hip, None),
            Series::KneeSpeed => (s.speed_knee, None),
            Series::HipSpeed => (s.speed_hip, None),
        }
    }

    fn limit(self) -> Option<f64> {
        match self {
            Series::KneeAngle | Series::HipAngle => None,
            Series::KneePwm => Some(KNEE_PWM_LIMIT),
            Series::HipPwm => Some(HIP_PWM_LIMIT),
            Series::KneeSpeed => Some(KNEE_MAX_SPEED),
            Series::HipSpeed => Some(HIP_MAX_SPEED),
        }
    }
}

fn draw_series<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, d: &Data, s: Series) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let root = root.titled(s.title(), ("sans-serif", 22))?;
    let panels = root.split_evenly((4, 1));
    let (t0, t1) = (
        d.t.first().copied().unwrap_or(0.0),
        d.t.last().copied().unwrap_or(1.0),
    );
    for (panel, leg) in panels.iter().zip(FIGURE_ORDER) {
        let li = table_index(leg);
        let pts: Vec<(f64, Option<f64>)> = d.legs[li].iter().map(|x| s.values(x)).collect();
        let mut vals: Vec<f64> = pts.iter().map(|p| p.0).collect();
        vals.extend(pts.iter().filter_map(|p| p.1));
        if let Some(l) = s.limit() {
            vals.push(l);
            vals.push(-l);
        }
        let (lo, hi) = range(vals.into_iter(), 0.08);
        let mut chart = ChartBuilder::on(panel)
            .margin(6)
            .x_label_area_size(28)
            .y_label_area_size(60)
            .caption(leg.code(), ("sans-serif", 16))
            .build_cartesian_2d(t0..t1.max(t0 + 1e-3), lo..hi)?;
        chart
            .configure_mesh()
            .x_desc("t [s]")
            .y_desc(s.unit())
            .label_style(("sans-serif", 12))
            .light_line_style(WHITE.mix(0.0))
            .draw()?;
        if let Some(l) = s.limit() {
            for v in [l, -l] {
                chart.draw_series(LineSeries::new(
                    [(t0, v), (t1, v)],
                    BLUE.mix(0.8).stroke_width(1),
                ))?;
            }
        }
        for &m in &d.marks {
            chart.draw_series(LineSeries::new(
                [(m, lo), (m, hi)],
                GREEN.mix(0.7).stroke_width(2),
            ))?;
        }
        if pts.iter().any(|p| p.1.is_some()) {
            chart.draw_series(LineSeries::new(
                d.t.iter()
                    .zip(&pts)
                    .filter_map(|(t, p)| p.1.map(|v| (*t, v))),
                RED.stroke_width(2),
            ))?;
        }
        chart.draw_series(LineSeries::new(
            d.t.iter().zip(&pts).map(|(t, p)| (*t, p.0)),
            BLACK.stroke_width(1),
        ))?;
    }
    root.present()?;
    Ok(())
}

fn draw_toe<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, d: &Data) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let root = root.titled(
        "Toe path: desired (red) and measured (black), steady trot",
        ("sans-serif", 22),
    )?;
    let panels = root.split_evenly((2, 2));
    let mm = |p: (f64, f64)| (p.0 * 1000.0, p.1 * 1000.0);
    for (panel, leg) in panels.iter().zip(FIGURE_ORDER) {
        let li = table_index(leg);
        let act: Vec<(f64, f64)> = d.toe[li].iter().map(|s| mm(s.toe)).collect();
        let des: Vec<(f64, f64)> = d.toe[li].iter().map(|s| mm(s.toe_des)).collect();
        let (x0, x1) = range(act.iter().chain(&des).map(|p| p.0), 0.1);
        let (y0, y1) = range(act.iter().chain(&des).map(|p| p.1), 0.1);
        // Same scale on both axes.
        let half = ((x1 - x0).max(y1 - y0)) / 2.0;
        let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
        let mut chart = ChartBuilder::on(panel)
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(50)
            .caption(leg.code(), ("sans-serif", 16))
            // y grows downward (thesis frame): the axis runs from the largest value at the
            // bottom… reversed so the foot is at the bottom of the picture.
            .build_cartesian_2d(cx - half..cx + half, (cy + half)..(cy - half))?;
        chart
            .configure_mesh()
            .x_desc("x [mm]")
            .y_desc("y [mm] (down)")
            .label_style(("sans-serif", 12))
            .light_line_style(WHITE.mix(0.0))
            .draw()?;
        chart.draw_series(LineSeries::new(des, RED.stroke_width(2)))?;
        chart.draw_series(LineSeries::new(act, BLACK.stroke_width(1)))?;
    }
    root.present()?;
    Ok(())
}

/// The figure files (stem names) [`write_figures`] produces, in the thesis' order.
pub const FIGURES: [&str; 7] = [
    "toe_paths",
    "knee_angles",
    "hip_angles",
    "knee_pwm",
    "hip_pwm",
    "knee_speed",
    "hip_speed",
];

/// Draws series `s` of `d` as `<stem>.png` and `<stem>.svg` in `dir`.
fn series_files(
    dir: &Path,
    stem: &str,
    size: (u32, u32),
    d: &Data,
    s: Series,
) -> Result<[PathBuf; 2], MasterError> {
    let err = |p: &Path, e: Box<dyn std::error::Error>| {
        MasterError::Usage(format!("figure {}: {e}", p.display()))
    };
    let png = dir.join(format!("{stem}.png"));
    draw_series(BitMapBackend::new(&png, size).into_drawing_area(), d, s)
        .map_err(|e| err(&png, e))?;
    let svg = dir.join(format!("{stem}.svg"));
    draw_series(SVGBackend::new(&svg, size).into_drawing_area(), d, s).map_err(|e| err(&svg, e))?;
    Ok([png, svg])
}

/// Writes the seven figures and the six whole-run ones as `<stem>.png` and `<stem>.svg`
/// into `dir`; returns the paths.
pub fn write_figures(run: &TrotRun, dir: &Path) -> Result<Vec<PathBuf>, MasterError> {
    font_ready()?;
    let d = data(run);
    let err = |p: &Path, e: Box<dyn std::error::Error>| {
        MasterError::Usage(format!("figure {}: {e}", p.display()))
    };
    let mut out = Vec::new();
    let series = [
        Series::KneeAngle,
        Series::HipAngle,
        Series::KneePwm,
        Series::HipPwm,
        Series::KneeSpeed,
        Series::HipSpeed,
    ];
    let png = dir.join("toe_paths.png");
    draw_toe(BitMapBackend::new(&png, (900, 900)).into_drawing_area(), &d)
        .map_err(|e| err(&png, e))?;
    let svg = dir.join("toe_paths.svg");
    draw_toe(SVGBackend::new(&svg, (900, 900)).into_drawing_area(), &d)
        .map_err(|e| err(&svg, e))?;
    out.extend([png, svg]);
    for s in series {
        out.extend(series_files(dir, s.file(), (900, 1000), &d, s)?);
        // The same series over the whole run, the phases marked (thesis figures 4-2 to
        // 4-7 show the whole experiment).
        let stem = format!("{}_whole_run", s.file());
        out.extend(series_files(
            dir,
            &stem,
            (1400, 1000),
            &whole_run(run, s),
            s,
        )?);
    }
    Ok(out)
}
