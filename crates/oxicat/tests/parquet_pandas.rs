//! `oxicat trot --format both`: pandas reads `trot.parquet` as exactly the table of
//! `trot.csv` (same columns, dtypes and values), with the units in its metadata.
//!
//! Needs Python with pandas and pyarrow (`.ci/run` installs them into `.venv`;
//! `OXICAT_PYTHON` names another interpreter). Under `CI=1` a missing one fails the test;
//! elsewhere it is skipped with a message.

use std::path::{Path, PathBuf};
use std::process::Command;

use oxicat::output::Format;
use oxicat::trot_cmd::{run, TrotArgs};

fn python_with_pandas() -> Result<PathBuf, String> {
    let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../.venv/bin/python");
    let candidates: Vec<PathBuf> = match std::env::var_os("OXICAT_PYTHON") {
        Some(p) => vec![PathBuf::from(p)],
        None => vec![venv, PathBuf::from("python3")],
    };
    candidates
        .iter()
        .find(|py| {
            Command::new(py)
                .args(["-c", "import pandas, pyarrow"])
                .output()
                .is_ok_and(|o| o.status.success())
        })
        .cloned()
        .ok_or_else(|| "no Python with pandas and pyarrow (`.ci/run` installs them)".into())
}

const CHECK: &str = r#"
import json, sys
import pandas as pd, pyarrow.parquet as pq
d = sys.argv[1]
c = pd.read_csv(d + "/trot.csv")
p = pd.read_parquet(d + "/trot.parquet")
pd.testing.assert_frame_equal(c, p, check_exact=True)
units = json.loads(pq.read_metadata(d + "/trot.parquet").metadata[b"oxicat.units"])
assert units["t [s]"] == "s", units
assert sum(1 for k in units if k.endswith(".knee_angle [deg]")) == 4, units
print(len(p), len(p.columns))
"#;

#[test]
fn pandas_reads_the_parquet_recording_as_the_csv() {
    let py = match python_with_pandas() {
        Ok(p) => p,
        Err(e) if std::env::var_os("CI").is_some() => panic!("{e}"),
        Err(e) => {
            eprintln!("skipped: {e}");
            return;
        }
    };
    let out = std::env::temp_dir().join(format!("oxicat-parquet-{}", std::process::id()));
    let scenario = out.join("short.toml");
    std::fs::create_dir_all(&out).expect("temp dir");
    let text = oxicat_devices::laelaps::scenario::DEFAULT_TOML
        .replace("settle_s = 3.5", "settle_s = 1.1")
        .replace("stand_s = 1.0", "stand_s = 0.2")
        .replace("transition_time_s = 3", "transition_time_s = 1")
        .replace("trot_s = 10.0", "trot_s = 0.5")
        .replace("stop_s = 0.5", "stop_s = 0.1");
    std::fs::write(&scenario, text).expect("scenario");
    run(TrotArgs {
        scenario: Some(scenario),
        duration: None,
        pdi: None,
        spi_mhz: None,
        bus_time: false,
        sync1: None,
        out: out.clone(),
        no_plots: true,
        format: Format::Both,
        quiet: true,
    })
    .expect("trot");
    let o = Command::new(&py)
        .args(["-c", CHECK])
        .arg(&out)
        .output()
        .expect("python runs");
    assert!(
        o.status.success(),
        "pandas check failed:\n{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    let shape = String::from_utf8_lossy(&o.stdout);
    let rows: usize = shape.split_whitespace().next().unwrap().parse().unwrap();
    assert!(rows > 1000, "{shape}");
    let _ = std::fs::remove_dir_all(out);
}
