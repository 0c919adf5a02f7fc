//! Segments served by a child process (`oxicat sim --udp`, `oxicat-emu sim --udp`), and the
//! reference data beside the repository.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

/// A serving child process, killed when dropped.
pub struct Served(Child);

impl Served {
    /// The child's process id (to look at its threads in `/proc`).
    pub fn id(&self) -> u32 {
        self.0.id()
    }
}

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

/// The ESI files of the reference (`esi/` and `esi-vendor/`), sorted.
pub fn esi_files() -> Vec<PathBuf> {
    let mut v = Vec::new();
    for dir in ["esi", "esi-vendor"] {
        let d = reference().join(dir);
        let rd = std::fs::read_dir(&d)
            .unwrap_or_else(|e| panic!("reference dir {} missing: {e}", d.display()));
        v.extend(
            rd.filter_map(|e| e.ok())
                .map(|e| e.path())
                .filter(|p| p.extension().is_some_and(|x| x.eq_ignore_ascii_case("xml"))),
        );
    }
    v.sort();
    v
}

/// Twin refusals that are limits of the twins, each with why it is right to refuse rather than
/// serve a device that is not what its ESI says (the stack's capacities no longer refuse a
/// catalogue type: twins run it with the `twin-capacity` feature's). A
/// refusal's message holds the first text of its pair (the tests that walk the ESI files
/// of the reference accept these and no other).
pub const TWIN_REFUSALS_ALLOWED: &[(&str, &str)] = &[
    (
        "twins do not model virtual sync managers",
        "EL2252 maps DC registers (0x0981, 0x0990) through virtual SMs: a timestamped output \
         whose registers no twin models",
    ),
    (
        "PDO index is listed twice",
        "the ESI lists one PDO index twice with different contents (EL2252 rev 0x00110000): \
         no slave can serve both",
    ),
];
