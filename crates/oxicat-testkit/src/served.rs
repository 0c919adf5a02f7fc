//! Segments served by a child process (`oxicat sim --udp`, `oxicat-emu sim --udp`), and the
//! reference data beside the repository.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

/// A serving child process, killed when dropped.
pub struct Served(Child);

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts `cmd` (a `sim … --udp 127.0.0.1:0` invocation) and returns it with the address
/// it printed that it serves on ("… on EtherCAT over UDP on ADDR; …" on standard error).
pub fn spawn_udp(mut cmd: Command) -> (Served, String) {
    let mut child = cmd
        .stdin(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn the simulator");
    let stderr = child.stderr.take().expect("stderr");
    let served = Served(child);
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    loop {
        let line = rx
            .recv_timeout(Duration::from_secs(120))
            .expect("the simulator prints where it serves");
        if let Some(rest) = line.split(" on EtherCAT over UDP on ").nth(1) {
            let addr = rest.split(';').next().unwrap_or_default().to_string();
            return (served, addr);
        }
    }
}

/// `../shared/reference` beside the repository, or `OXICAT_REFERENCE`.
pub fn reference() -> PathBuf {
    std::env::var_os("OXICAT_REFERENCE")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/reference")
        })
}
