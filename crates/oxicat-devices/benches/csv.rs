//! CSV written by hand against the `csv` crate, each writing the same fields formatted the
//! same way (the crate only joins, quotes and ends them):
//!
//! - `trot_csv`: the Laelaps trot's CSV of the default scenario (61,250 rows of 64 fields,
//!   22 MB; `laelaps::results::csv`, fixed-point formatting straight into one `String`)
//!   against the same rows through `csv::Writer`.
//! - `record_rows`: rows shaped as `Master::record` writes them (cycle, time, eight
//!   variables), 10,000 rows, joined by hand with `writeln!` (as it did before it moved to
//!   the crate) against `csv::Writer::write_record`.
//!
//! Both sides must give the same bytes (asserted before timing).
//!
//! - Time: `cargo bench -p oxicat-devices --bench csv`.
//! - Instructions: `scripts/ir-per-call.sh target/release/deps/csv-<hash> trot/csv-crate
//!   trot/hand-written record/csv-crate record/hand-written -- 2` (one CSV of each).

use criterion::{black_box, criterion_group, Criterion};
use oxicat_devices::laelaps::experiment::{run_trot, TrotRun, INPUTS};
use oxicat_devices::laelaps::results::{self, sample};
use oxicat_devices::laelaps::rig::LegId;
use oxicat_devices::laelaps::scenario::Scenario;
use std::fmt::Write as _;
use std::io::Write as _;

/// `raw / 10^decimals` as `results::csv` writes it.
fn fixed(out: &mut String, raw: i64, decimals: u32) {
    let d = 10u64.pow(decimals);
    let sign = if raw < 0 { "-" } else { "" };
    let a = raw.unsigned_abs();
    if decimals == 0 {
        let _ = write!(out, "{sign}{a}");
    } else {
        let _ = write!(out, "{sign}{}.{:0w$}", a / d, a % d, w = decimals as usize);
    }
}

/// One fixed-point field into the writer, through the reused buffer `f`.
fn put(w: &mut csv::Writer<Vec<u8>>, f: &mut String, raw: i64, decimals: u32) {
    f.clear();
    fixed(f, raw, decimals);
    w.write_field(&*f).unwrap();
}

/// The trot CSV through `csv::Writer`: every field formatted into `f` as `results::csv`
/// formats it, then handed to the writer.
fn trot_with_crate(run: &TrotRun) -> String {
    let cyc_ns = run.scenario.cycle_ns();
    let mut w = csv::Writer::from_writer(Vec::with_capacity(run.rows.len() * 420));
    let mut h = vec![
        "cycle".to_string(),
        "t [s]".into(),
        "State_Machine".into(),
        "wkc".into(),
    ];
    for leg in LegId::TABLE {
        let c = leg.code();
        h.push(format!("{c}.a_ellipse [cm]"));
        h.push(format!("{c}.b_ellipse [cm]"));
        for v in INPUTS {
            h.push(format!("{c}.{} [{}]", v.name, v.unit));
        }
        for n in ["toe_x_desired", "toe_y_desired", "toe_x", "toe_y"] {
            h.push(format!("{c}.{n} [mm]"));
        }
    }
    w.write_record(&h).unwrap();
    let mut f = String::with_capacity(32);
    for (k, r) in run.rows.iter().enumerate() {
        put(&mut w, &mut f, k as i64, 0);
        put(&mut w, &mut f, (k as u64 * cyc_ns / 1000) as i64, 6);
        put(&mut w, &mut f, i64::from(u8::from(r.state_machine)), 0);
        put(&mut w, &mut f, i64::from(r.wkc), 0);
        for (li, leg) in LegId::TABLE.into_iter().enumerate() {
            put(&mut w, &mut f, i64::from(r.a_cmd[li]), 0);
            put(&mut w, &mut f, i64::from(r.b_cmd[li]), 0);
            for (v, iv) in INPUTS.iter().enumerate() {
                put(
                    &mut w,
                    &mut f,
                    i64::from(r.inputs[li][v]),
                    iv.divisor.ilog10(),
                );
            }
            let s = sample(&r.inputs[li], leg);
            for m in [s.toe_des.0, s.toe_des.1, s.toe.0, s.toe.1] {
                put(&mut w, &mut f, (m * 100_000.0).round() as i64, 2);
            }
        }
        w.write_record(None::<&[u8]>).unwrap();
    }
    String::from_utf8(w.into_inner().unwrap()).unwrap()
}

/// `Master::record`-shaped rows: cycle, time with 9 decimals, eight formatted variables.
fn record_rows(n: u64) -> Vec<Vec<String>> {
    (0..n)
        .map(|c| {
            let mut r = vec![c.to_string(), format!("{:.9}", c as f64 * 1e-3)];
            r.extend((0..8).map(|v| match v % 4 {
                0 => format!("{}", (c as i64 * 37 - 5000) * (v + 1)),
                1 => format!("0x{:04x}", (c * 7 + v as u64) & 0xFFFF),
                2 => format!("{:.3}", (c as f64 * 0.01).sin() * 100.0),
                _ => ((c + v as u64) & 1 == 0).to_string(),
            }));
            r
        })
        .collect()
}

fn record_hand(header: &[String], rows: &[Vec<String>]) -> Vec<u8> {
    let mut out = Vec::with_capacity(rows.len() * 100);
    writeln!(out, "{}", header.join(",")).unwrap();
    for r in rows {
        writeln!(out, "{}", r.join(",")).unwrap();
    }
    out
}

fn record_crate(header: &[String], rows: &[Vec<String>]) -> Vec<u8> {
    let mut w = csv::Writer::from_writer(Vec::with_capacity(rows.len() * 100));
    w.write_record(header).unwrap();
    for r in rows {
        w.write_record(r).unwrap();
    }
    w.into_inner().unwrap()
}

struct Data {
    run: Option<TrotRun>,
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

fn data(trot: bool) -> Data {
    let run = trot.then(|| run_trot(&Scenario::thesis(), &mut |_| {}).expect("trot"));
    if let Some(run) = &run {
        assert_eq!(
            trot_with_crate(run),
            results::csv(run),
            "csv crate and hand-written trot CSV differ"
        );
    }
    let mut header = vec!["cycle".to_string(), "time [s]".into()];
    header.extend((0..8).map(|v| format!("var{v} [unit]")));
    let rows = record_rows(10_000);
    assert_eq!(record_crate(&header, &rows), record_hand(&header, &rows));
    Data { run, header, rows }
}

fn bench(c: &mut Criterion) {
    let d = data(true);
    let run = d.run.as_ref().unwrap();
    let mut g = c.benchmark_group("trot_csv");
    g.sample_size(10);
    g.bench_function("csv-crate", |b| b.iter(|| black_box(trot_with_crate(run))));
    g.bench_function("hand-written", |b| b.iter(|| black_box(results::csv(run))));
    g.finish();
    let mut g = c.benchmark_group("record_rows_10000");
    g.bench_function("csv-crate", |b| {
        b.iter(|| black_box(record_crate(&d.header, black_box(&d.rows))))
    });
    g.bench_function("hand-written", |b| {
        b.iter(|| black_box(record_hand(&d.header, black_box(&d.rows))))
    });
    g.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .sample_size(20)
        .warm_up_time(std::time::Duration::from_secs(1))
        .measurement_time(std::time::Duration::from_secs(8));
    targets = bench
}

/// `OXICAT_CALLGRIND=<trot|record>/<csv-crate|hand-written>:<reps>`: writes the CSV `reps`
/// times, for `scripts/ir-per-call.sh`.
fn callgrind(spec: &str) {
    let (v, reps) = spec.rsplit_once(':').expect("variant:reps");
    let d = data(v.starts_with("trot"));
    let run = d.run.as_ref();
    for _ in 0..reps.parse::<u32>().expect("reps") {
        match v {
            "trot/csv-crate" => drop(black_box(trot_with_crate(black_box(run.unwrap())))),
            "trot/hand-written" => drop(black_box(results::csv(black_box(run.unwrap())))),
            "record/csv-crate" => drop(black_box(record_crate(&d.header, black_box(&d.rows)))),
            "record/hand-written" => drop(black_box(record_hand(&d.header, black_box(&d.rows)))),
            _ => panic!("unknown variant {v}"),
        }
    }
}

fn main() {
    if let Ok(spec) = std::env::var("OXICAT_CALLGRIND") {
        return callgrind(&spec);
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
}
