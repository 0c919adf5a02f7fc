//! The leg animation of the trot (`legs.svg`): for each leg, the desired and the measured
//! leg (hip → knee → toe, link lengths [`L1`] and [`L2`] of the firmware) over a window of
//! the steady trot, as a self-contained SVG whose polylines step through one frame per
//! [`FRAME_CYCLES`] recorded cycles (SMIL `<animate calcMode="discrete">`, looping).

use std::fmt::Write as _;

use crate::laelaps::experiment::{Row, TrotRun};
use crate::laelaps::hw::{L1, L2};
use crate::laelaps::results::{sample, steady_window};
use crate::laelaps::rig::LegId;

/// Recorded cycles per animation frame (10 ms at the 400 µs cycle).
pub const FRAME_CYCLES: usize = 25;
/// Steps (trajectory periods) the animation shows.
pub const STEPS: f64 = 2.0;
/// Pixels per metre.
const SCALE: f64 = 400.0;
/// Width of one leg's panel \[px\].
const PANEL: f64 = 300.0;

/// Knee and toe `(x, y)` \[m\] of kinematic-frame angles (hip, knee) \[rad\]: x forward, y
/// down from the hip (thesis eq. 3-1, as `results::toe`).
pub fn joints(hip: f64, knee: f64) -> ((f64, f64), (f64, f64)) {
    let (l1, l2) = (f64::from(L1), f64::from(L2));
    let k = (l1 * hip.sin(), l1 * hip.cos());
    (k, (k.0 + l2 * knee.sin(), k.1 + l2 * knee.cos()))
}

/// The points of one leg drawing in panel coordinates: hip, knee, toe.
fn points(hip: f64, knee: f64, x0: f64) -> String {
    let (k, t) = joints(hip, knee);
    let p = |(x, y): (f64, f64)| format!("{:.2},{:.2}", x0 + x * SCALE, 40.0 + y * SCALE);
    format!("{} {} {}", p((0.0, 0.0)), p(k), p(t))
}

/// The animation over `rows` (one frame every [`FRAME_CYCLES`] rows), `cycle_s` apart.
pub fn svg(rows: &[Row], cycle_s: f64) -> String {
    let frames: Vec<&Row> = rows.iter().step_by(FRAME_CYCLES).collect();
    let dur = (frames.len() * FRAME_CYCLES) as f64 * cycle_s;
    let w = PANEL * LegId::TABLE.len() as f64;
    let mut o = String::new();
    let _ = writeln!(
        o,
        r#"<?xml version="1.0" encoding="UTF-8"?>
<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="340" viewBox="0 0 {w} 340">
<rect width="100%" height="100%" fill="white"/>"#
    );
    for (li, leg) in LegId::TABLE.into_iter().enumerate() {
        let x0 = PANEL * li as f64 + PANEL / 2.0;
        let _ = writeln!(
            o,
            r#"<text x="{x0}" y="20" text-anchor="middle" font-family="sans-serif" font-size="14">{}</text>"#,
            leg.code()
        );
        for (id, colour, des) in [("des", "#1f77b4", true), ("meas", "#d62728", false)] {
            let pts: Vec<String> = frames
                .iter()
                .map(|r| {
                    let s = sample(&r.inputs[li], leg);
                    if des {
                        points(s.hip_des, s.knee_des, x0)
                    } else {
                        points(s.hip, s.knee, x0)
                    }
                })
                .collect();
            let first = pts.first().cloned().unwrap_or_default();
            let _ = writeln!(
                o,
                r#"<polyline id="{}-{id}" points="{first}" fill="none" stroke="{colour}" stroke-width="4" stroke-linejoin="round"><animate attributeName="points" calcMode="discrete" dur="{dur:.3}s" repeatCount="indefinite" values="{}"/></polyline>"#,
                leg.code(),
                pts.join(";")
            );
        }
    }
    let _ = writeln!(
        o,
        r##"<text x="10" y="330" font-family="sans-serif" font-size="12"><tspan fill="#1f77b4">desired</tspan> / <tspan fill="#d62728">measured</tspan> leg, {} frames of {:.0} ms, {dur:.2} s of steady trot</text>
</svg>"##,
        frames.len(),
        FRAME_CYCLES as f64 * cycle_s * 1e3
    );
    o
}

/// The animation of `run`: [`STEPS`] steps from the start of the steady trot.
pub fn run_svg(run: &TrotRun) -> String {
    let (w0, w1) = steady_window(run);
    let f = run
        .scenario
        .legs
        .iter()
        .map(|l| l.freq_hz)
        .fold(f64::INFINITY, f64::min);
    let n = run.scenario.cycles(STEPS / f);
    let end = w1.min(w0.saturating_add(n)) as usize;
    let start = (w0 as usize).min(end);
    let cycle_s = run.scenario.cycle_ns() as f64 * 1e-9;
    svg(&run.rows[start..end], cycle_s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::laelaps::experiment::var;
    use crate::laelaps::results::toe;

    fn row(i: i32) -> Row {
        let mut inputs = [[0i32; 9]; 4];
        for (li, leg) in inputs.iter_mut().enumerate() {
            let li = li as i32;
            leg[var::HIP] = 1000 + 100 * i + 7 * li;
            leg[var::KNEE] = -2000 + 50 * i - 11 * li;
            leg[var::HIP_DES] = 1100 + 100 * i;
            leg[var::KNEE_DES] = -2100 + 50 * i;
        }
        Row {
            state_machine: true,
            a_cmd: [5; 4],
            b_cmd: [5; 4],
            inputs,
            wkc: 12,
        }
    }

    fn pair(s: &str) -> (f64, f64) {
        let (x, y) = s.split_once(',').expect("x,y");
        (x.parse().expect("x"), y.parse().expect("y"))
    }

    #[test]
    fn svg_is_xml_with_frames_starting_at_the_first_rows_kinematics() {
        let rows: Vec<Row> = (0..100).map(row).collect();
        let text = svg(&rows, 400e-6);
        let doc = roxmltree::Document::parse(&text).expect("valid XML");
        for (li, leg) in LegId::TABLE.into_iter().enumerate() {
            let s = sample(&rows[0].inputs[li], leg);
            for (id, (hip, knee)) in [("meas", (s.hip, s.knee)), ("des", (s.hip_des, s.knee_des))] {
                let name = format!("{}-{id}", leg.code());
                let pl = doc
                    .descendants()
                    .find(|n| n.attribute("id") == Some(name.as_str()))
                    .expect("a polyline per leg and kind");
                let anim = pl
                    .children()
                    .find(|n| n.has_tag_name("animate"))
                    .expect("animated");
                let values = anim.attribute("values").expect("frames");
                let frames: Vec<&str> = values.split(';').collect();
                // 100 rows, one frame every 25.
                assert_eq!(frames.len(), 4);
                assert_eq!(Some(frames[0]), pl.attribute("points"));
                let pts: Vec<(f64, f64)> = frames[0].split(' ').map(pair).collect();
                assert_eq!(pts.len(), 3);
                let hip_px = pts[0];
                let t = toe(hip, knee);
                let got = ((pts[2].0 - hip_px.0) / SCALE, (pts[2].1 - hip_px.1) / SCALE);
                assert!(
                    (got.0 - t.0).abs() < 1e-4 && (got.1 - t.1).abs() < 1e-4,
                    "{name}: toe {got:?} vs forward kinematics {t:?}"
                );
                // The knee is L1 from the hip.
                let k = ((pts[1].0 - hip_px.0) / SCALE, (pts[1].1 - hip_px.1) / SCALE);
                assert!(((k.0 * k.0 + k.1 * k.1).sqrt() - f64::from(L1)).abs() < 1e-4);
            }
        }
    }

    #[test]
    fn no_rows_still_gives_valid_xml() {
        let text = svg(&[], 400e-6);
        assert!(roxmltree::Document::parse(&text).is_ok());
    }
}
