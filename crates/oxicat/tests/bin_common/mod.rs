//! Runs the `oxicat` binary of this build for the CLI tests: (success, stdout, stderr).
#![allow(dead_code)]

use std::path::Path;
use std::process::Command;

/// `oxicat args` in the working directory `dir` (the test's own, when it writes files),
/// without `OXICAT_IFACE` from the environment.
pub fn oxicat_in(dir: Option<&Path>, args: &[&str]) -> (bool, String, String) {
    let mut c = Command::new(env!("CARGO_BIN_EXE_oxicat"));
    c.args(args).env_remove("OXICAT_IFACE");
    if let Some(d) = dir {
        c.current_dir(d);
    }
    let o = c.output().expect("oxicat runs");
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}
