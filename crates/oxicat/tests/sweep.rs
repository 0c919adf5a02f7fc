//! `oxicat sweep`: a grid of trot scenarios over two workers, every point deterministic
//! (the same point gives the same CSV bytes run alone in another shard), the table complete.

use std::path::{Path, PathBuf};

use oxicat::sweep_cmd::{run, SweepArgs};

fn out_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("oxicat-sweep-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// A short trot (about 4.5 simulated s per point) and a 4 × 4 grid of knee and hip gains.
fn args(out: &Path, jobs: usize, shard: Option<&str>) -> SweepArgs {
    SweepArgs {
        scenario: None,
        set: [
            "control.knee.kp=40,60,80,100",
            "control.hip.kp=40,60,80,100",
            "procedure.settle_s=1",
            "procedure.transition_time_s=1",
            "procedure.stand_s=0.2",
            "procedure.trot_s=1",
            "procedure.stop_s=0.1",
        ]
        .map(String::from)
        .to_vec(),
        jobs: Some(jobs),
        shard: shard.map(String::from),
        out: out.to_path_buf(),
        csv: false,
        quiet: true,
    }
}

/// (point, gains, digest) of each point's first row in `sweep.csv`.
fn table(out: &Path) -> Vec<(usize, String, String)> {
    let text = std::fs::read_to_string(out.join("sweep.csv")).expect("sweep.csv");
    let mut rows: Vec<(usize, String, String)> = Vec::new();
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(f.len(), 1 + 7 + 10, "{line}");
        assert!(f[17].is_empty(), "no error: {line}");
        let p: usize = f[0].parse().expect("point");
        if rows.last().is_some_and(|r| r.0 == p) {
            assert_eq!(rows.last().unwrap().2, f[16], "one digest per point");
            continue;
        }
        rows.push((p, format!("{}/{}", f[1], f[2]), f[16].to_string()));
    }
    rows
}

#[test]
fn a_sixteen_point_sweep_over_two_workers_is_deterministic_per_point() {
    let all_dir = out_dir("all");
    let printed = run(args(&all_dir, 2, None)).expect("sweep");
    assert!(
        printed.contains("16 points (0 failed) on 2 workers"),
        "{printed}"
    );
    let all = table(&all_dir);
    assert_eq!(all.len(), 16);
    assert_eq!(
        all.iter().map(|r| r.0).collect::<Vec<_>>(),
        (0..16).collect::<Vec<_>>()
    );
    assert_eq!(all[0].1, "40.0/40.0");
    assert_eq!(all[6].1, "60.0/80.0");
    // The gains matter: the points do not all give the same run.
    let mut digests: Vec<&str> = all.iter().map(|r| r.2.as_str()).collect();
    digests.sort();
    digests.dedup();
    assert!(digests.len() > 8, "{digests:?}");

    // The second of four shards, alone on one worker: the same bytes for the same points.
    let shard_dir = out_dir("shard");
    run(args(&shard_dir, 1, Some("2/4"))).expect("shard");
    let shard = table(&shard_dir);
    assert_eq!(shard.iter().map(|r| r.0).collect::<Vec<_>>(), [1, 5, 9, 13]);
    for r in &shard {
        assert_eq!(r, &all[r.0], "point {} alone", r.0);
    }
    let _ = std::fs::remove_dir_all(all_dir);
    let _ = std::fs::remove_dir_all(shard_dir);
}

#[test]
fn bad_sweeps_are_refused_before_anything_runs() {
    let dir = out_dir("bad");
    for (set, shard, want) in [
        ("control.knee.kp=40,nan", None, "point 1"),
        ("control.knee.nope=1", None, "no such key"),
        ("control.knee.kp", None, "KEY=V1,V2"),
        ("control.knee.kp=40", Some("3/2"), "--shard 3/2"),
        ("control.knee.kp=40", Some("x"), "expected I/N"),
    ] {
        let mut a = args(&dir, 1, shard);
        a.set = vec![set.to_string()];
        let e = run(a).expect_err(set).to_string();
        assert!(e.contains(want), "{set}: {e}");
    }
    assert!(!dir.join("sweep.csv").exists());
}
