//! Scenario sweeps: the trot run for every point of a grid of scenario values (`--set
//! control.knee.kp=40,80,120`), in parallel on the local cores, each point deterministic
//! (the same point gives the same CSV bytes whatever else runs beside it), with one summary
//! table. `--shard i/n` runs every n-th point only, so any batch system can spread a large
//! sweep over machines and the tables concatenate.
//!
//! Keys are paths into the scenario TOML: `control.knee.kp`, `procedure.trot_s`, and for a
//! leg's Table 4-1 column `leg.FL.a_cm` (by leg) or `leg[0].a_cm` (by position). Every point
//! is checked like a scenario file before anything runs; a bad value names its point.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use oxicat_master::MasterError;

use crate::laelaps::experiment::run_trot;
use crate::laelaps::results::{csv, summarize, LegSummary};
use crate::laelaps::rig::LegId;
use crate::laelaps::scenario::Scenario;

/// One axis of the grid: a scenario key and its values.
#[derive(Debug, Clone, PartialEq)]
pub struct Axis {
    /// The key (a path into the scenario TOML).
    pub key: String,
    /// Its values, as TOML values.
    pub values: Vec<toml::Value>,
}

fn usage(m: String) -> MasterError {
    MasterError::Usage(m)
}

impl Axis {
    /// Parses `key=v1,v2,…` (each value a TOML value: `80`, `0.05`, `"lan9252"`).
    pub fn parse(arg: &str) -> Result<Self, MasterError> {
        let (key, list) = arg
            .split_once('=')
            .ok_or_else(|| usage(format!("--set {arg}: expected KEY=V1,V2,…")))?;
        let key = key.trim();
        if key.is_empty() {
            return Err(usage(format!("--set {arg}: no key")));
        }
        let mut values = Vec::new();
        for v in list.split(',').map(str::trim) {
            let doc: toml::Table = toml::from_str(&format!("v = {v}"))
                .map_err(|_| usage(format!("--set {arg}: {v:?} is not a value")))?;
            values.push(doc["v"].clone());
        }
        if values.is_empty() || list.trim().is_empty() {
            return Err(usage(format!("--set {arg}: no values")));
        }
        Ok(Self {
            key: key.to_string(),
            values,
        })
    }
}

/// The value at `key` in a scenario document.
fn leaf<'a>(doc: &'a mut toml::Value, key: &str) -> Result<&'a mut toml::Value, MasterError> {
    let unknown = || usage(format!("--set {key}: no such key in the scenario"));
    let mut parts = key.split('.').peekable();
    let mut v = doc;
    while let Some(p) = parts.next() {
        let (name, index) = match p.split_once('[') {
            Some((n, i)) => {
                let i = i
                    .strip_suffix(']')
                    .and_then(|i| i.parse::<usize>().ok())
                    .ok_or_else(unknown)?;
                (n, Some(i))
            }
            None => (p, None),
        };
        v = v.get_mut(name).ok_or_else(unknown)?;
        if let Some(i) = index {
            v = v.get_mut(i).ok_or_else(unknown)?;
        } else if let (Some(arr), Some(&leg)) = (v.as_array(), parts.peek()) {
            // `leg.FL.a_cm`: the array entry whose `leg` is FL.
            if arr.iter().any(|e| e.get("leg").is_some()) {
                let k = arr
                    .iter()
                    .position(|e| e.get("leg").and_then(toml::Value::as_str) == Some(leg))
                    .ok_or_else(unknown)?;
                parts.next();
                v = v.get_mut(k).ok_or_else(unknown)?;
            }
        }
    }
    if v.is_table() || v.is_array() {
        return Err(usage(format!("--set {key}: not a single value")));
    }
    Ok(v)
}

/// One point of the grid.
#[derive(Debug, Clone)]
pub struct Point {
    /// Index in the whole grid (the last axis varies fastest).
    pub index: usize,
    /// `(key, value)` per axis.
    pub values: Vec<(String, String)>,
    /// The scenario of this point.
    pub scenario: Scenario,
}

/// The points of the grid over `base` (scenario TOML text), every one checked. `shard`
/// `(i, n)` (1-based) keeps the points with `index % n == i - 1`.
pub fn points(
    base: &str,
    axes: &[Axis],
    shard: Option<(usize, usize)>,
) -> Result<Vec<Point>, MasterError> {
    let doc: toml::Value = toml::from_str(base).map_err(|e| usage(format!("scenario: {e}")))?;
    let total = axes
        .iter()
        .try_fold(1usize, |n, a| n.checked_mul(a.values.len()))
        .filter(|&n| n <= 100_000)
        .ok_or_else(|| usage("the sweep has more than 100000 points".into()))?;
    if let Some((i, n)) = shard {
        if n == 0 || i == 0 || i > n {
            return Err(usage(format!(
                "--shard {i}/{n}: expected i/n with 1 ≤ i ≤ n"
            )));
        }
    }
    let mut out = Vec::new();
    for index in 0..total {
        if let Some((i, n)) = shard {
            if index % n != i - 1 {
                continue;
            }
        }
        let mut d = doc.clone();
        let mut rest = index;
        let mut values = vec![(String::new(), String::new()); axes.len()];
        for (k, a) in axes.iter().enumerate().rev() {
            let v = a.values[rest % a.values.len()].clone();
            rest /= a.values.len();
            let slot = leaf(&mut d, &a.key)?;
            // A whole number where the scenario has a float stays a float.
            *slot = match (&*slot, v) {
                (toml::Value::Float(_), toml::Value::Integer(i)) => toml::Value::Float(i as f64),
                (_, v) => v,
            };
            values[k] = (a.key.clone(), slot.to_string());
        }
        let text = toml::to_string(&d).map_err(|e| usage(format!("scenario: {e}")))?;
        let scenario = Scenario::parse(&text).map_err(|e| {
            usage(format!(
                "point {index} ({}): {e}",
                values
                    .iter()
                    .map(|(k, v)| format!("{k}={v}"))
                    .collect::<Vec<_>>()
                    .join(" ")
            ))
        })?;
        out.push(Point {
            index,
            values,
            scenario,
        });
    }
    Ok(out)
}

/// What one point gave.
#[derive(Debug, Clone)]
pub struct PointResult {
    /// Grid index.
    pub index: usize,
    /// `(key, value)` per axis.
    pub values: Vec<(String, String)>,
    /// Per leg, Table 4-1 order, over the steady trot.
    pub legs: [LegSummary; 4],
    /// FNV-1a 64 of the point's `trot.csv` bytes (same point, same digest).
    pub csv_fnv64: u64,
    /// The CSV itself, when asked for.
    pub csv: Option<String>,
}

/// FNV-1a, 64 bit.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01B3)
    })
}

/// Runs every point on `jobs` worker threads (each point its own segment and master);
/// `done(k, total)` after each. Results in point order; a point that fails keeps its error.
pub fn run(
    points: &[Point],
    jobs: usize,
    keep_csv: bool,
    done: &(dyn Fn(usize, usize) + Sync),
) -> Vec<Result<PointResult, MasterError>> {
    let next = AtomicUsize::new(0);
    let finished = AtomicUsize::new(0);
    let slots: Vec<Mutex<Option<Result<PointResult, MasterError>>>> =
        points.iter().map(|_| Mutex::new(None)).collect();
    std::thread::scope(|s| {
        for _ in 0..jobs.clamp(1, points.len().max(1)) {
            s.spawn(|| loop {
                let k = next.fetch_add(1, Ordering::Relaxed);
                let Some(p) = points.get(k) else { break };
                let r = run_trot(&p.scenario, &mut |_| {}).map(|run| {
                    let text = csv(&run);
                    PointResult {
                        index: p.index,
                        values: p.values.clone(),
                        legs: summarize(&run).legs,
                        csv_fnv64: fnv1a64(text.as_bytes()),
                        csv: keep_csv.then_some(text),
                    }
                });
                *slots[k].lock().unwrap_or_else(|e| e.into_inner()) = Some(r);
                done(finished.fetch_add(1, Ordering::Relaxed) + 1, points.len());
            });
        }
    });
    slots
        .into_iter()
        .map(|m| {
            m.into_inner()
                .unwrap_or_else(|e| e.into_inner())
                .unwrap_or_else(|| Err(usage("a sweep worker stopped".into())))
        })
        .collect()
}

/// The summary table (CSV): one row per point and leg, the tracking errors over the steady
/// trot in degrees and millimetres, and the point's CSV digest.
pub fn table(axes: &[Axis], results: &[Result<PointResult, MasterError>]) -> String {
    let mut h = vec!["point".to_string()];
    h.extend(axes.iter().map(|a| a.key.clone()));
    h.extend(
        [
            "leg",
            "knee_rms [deg]",
            "knee_max [deg]",
            "hip_rms [deg]",
            "hip_max [deg]",
            "toe_rms [mm]",
            "knee_pwm_at_limit [%]",
            "hip_pwm_at_limit [%]",
            "trot_csv_fnv64",
            "error",
        ]
        .map(String::from),
    );
    let mut rows = vec![h];
    for r in results {
        match r {
            Ok(p) => {
                for (leg, l) in LegId::TABLE.iter().zip(&p.legs) {
                    let mut f = vec![p.index.to_string()];
                    f.extend(p.values.iter().map(|(_, v)| v.clone()));
                    f.extend([
                        leg.code().to_string(),
                        format!("{:.4}", l.knee_rms_deg),
                        format!("{:.4}", l.knee_max_deg),
                        format!("{:.4}", l.hip_rms_deg),
                        format!("{:.4}", l.hip_max_deg),
                        format!("{:.3}", l.toe_rms_mm),
                        format!("{:.2}", l.knee_at_limit_pct),
                        format!("{:.2}", l.hip_at_limit_pct),
                        format!("{:016x}", p.csv_fnv64),
                        String::new(),
                    ]);
                    rows.push(f);
                }
            }
            Err(e) => {
                // A failed point: its error in the last column, the others empty.
                let mut f = vec![String::new(); axes.len() + 11];
                f[0] = "?".into();
                f[axes.len() + 10] = e.to_string();
                rows.push(f);
            }
        }
    }
    crate::csv_text(rows).expect("fixed columns")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::laelaps::scenario::DEFAULT_TOML;

    /// A failed point fills the error column, the last one: every row has the header's
    /// fields (before the `csv` crate the error landed one column early, in the digest's).
    #[test]
    fn a_failed_point_has_its_error_in_the_last_column() {
        let axes = vec![Axis::parse("control.knee.kp=40,80").unwrap()];
        let t = table(&axes, &[Err(usage("no, \"this\" failed".into()))]);
        let mut lines = t.lines();
        let head = lines.next().unwrap();
        let row = lines.next().unwrap();
        assert_eq!(head.split(',').count(), 12, "{head}");
        assert!(head.ends_with(",error"), "{head}");
        assert_eq!(row, r#"?,,,,,,,,,,,"no, ""this"" failed""#);
    }

    #[test]
    fn axes_parse_and_refuse() {
        let a = Axis::parse("control.knee.kp=40, 80,120.5").unwrap();
        assert_eq!(a.key, "control.knee.kp");
        assert_eq!(a.values.len(), 3);
        for bad in ["control.knee.kp", "=1", "x=", "x=1,,2", "x=@"] {
            assert!(Axis::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn grid_order_shards_and_checks() {
        let axes = [
            Axis::parse("control.knee.kp=40,80").unwrap(),
            Axis::parse("leg.FL.a_cm=1,2,3").unwrap(),
        ];
        let all = points(DEFAULT_TOML, &axes, None).unwrap();
        assert_eq!(all.len(), 6);
        // The last axis varies fastest; integers become floats where the scenario has one.
        assert_eq!(all[1].values[1], ("leg.FL.a_cm".into(), "2.0".into()));
        assert_eq!(all[3].values[0].1, "80.0");
        assert_eq!(all[4].scenario.control.knee.kp, 80.0);
        let fl = all[4].scenario.legs.iter().find(|l| l.leg == "FL").unwrap();
        assert_eq!(fl.a_cm, 2.0);
        let idx: Vec<usize> = points(DEFAULT_TOML, &axes, Some((2, 4)))
            .unwrap()
            .iter()
            .map(|p| p.index)
            .collect();
        assert_eq!(idx, [1, 5]);
        // By position too.
        let p = points(DEFAULT_TOML, &[Axis::parse("leg[1].b_cm=3").unwrap()], None).unwrap();
        assert_eq!(p[0].scenario.legs[1].b_cm, 3.0);
        // Bad keys, values and shards are refused with the point named.
        for (axis, want) in [
            ("control.knee.nope=1", "no such key"),
            ("control.knee=1", "not a single value"),
            ("leg.XX.a_cm=1", "no such key"),
            ("control.knee.kp=nan", "point 0"),
            ("bus.cycle_us=1.5", "point 0"),
        ] {
            let e = points(DEFAULT_TOML, &[Axis::parse(axis).unwrap()], None).unwrap_err();
            assert!(e.to_string().contains(want), "{axis}: {e}");
        }
        assert!(points(DEFAULT_TOML, &axes, Some((0, 2))).is_err());
        assert!(points(DEFAULT_TOML, &axes, Some((3, 2))).is_err());
    }
}
