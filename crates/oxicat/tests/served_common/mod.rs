//! A segment served with EtherCAT over UDP on 127.0.0.1 in a thread of the test (as
//! `oxicat sim --udp` serves it), and the CLI's verb functions run against it with `--udp`,
//! each call its own master as each `oxicat` invocation is.
#![allow(dead_code)]

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;

use clap::Parser;
use oxicat::sim_cmd::{serve_udp_until, SimArgs};

/// A served segment; stops serving when dropped.
pub struct Served {
    /// `127.0.0.1:<port>`.
    pub addr: String,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Drop for Served {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Serves `devices` (e.g. `["demo:2"]`) on a free UDP port of 127.0.0.1.
pub fn serve(devices: &[&str]) -> Served {
    serve_with(None, devices)
}

/// Serves the segment described by the TOML file `segment`.
pub fn serve_file(segment: &std::path::Path) -> Served {
    serve_with(Some(segment.to_path_buf()), &[])
}

fn serve_with(segment: Option<std::path::PathBuf>, devices: &[&str]) -> Served {
    let port = oxicat_sim::net::udp::UdpPort::bind("127.0.0.1:0").expect("bind UDP");
    let addr = port.local_addr().to_string();
    let args = SimArgs {
        udp: Some(addr.clone()),
        segment,
        ..SimArgs::quiet(devices.iter().map(|s| s.to_string()).collect())
    };
    let stop = Arc::new(AtomicBool::new(false));
    let s = stop.clone();
    let thread = std::thread::spawn(move || {
        serve_udp_until(&args, port, s).expect("serves");
    });
    Served {
        addr,
        stop,
        thread: Some(thread),
    }
}

/// Runs `oxicat <args>` (a master or FoE verb) in this process, on a thread with a stack
/// as large as a program's main thread (ethercrab's futures are large in debug builds);
/// its output, or its error message.
pub fn cli(args: &[&str]) -> Result<String, String> {
    let args: Vec<String> = args.iter().map(|s| s.to_string()).collect();
    std::thread::Builder::new()
        .stack_size(16 << 20)
        .spawn(move || {
            let a: Vec<&str> = args.iter().map(String::as_str).collect();
            cli_here(&a)
        })
        .expect("spawn")
        .join()
        .expect("the verb does not panic")
}

fn cli_here(args: &[&str]) -> Result<String, String> {
    let c = oxicat::Cli::try_parse_from(std::iter::once("oxicat").chain(args.iter().copied()))
        .map_err(|e| e.to_string())?;
    let mut out = Vec::new();
    let r = match c.command {
        oxicat::Command::Master(m) => oxicat::master_cmd::run(m, &mut out),
        oxicat::Command::Foe(f) => oxicat::foe_cmd::run(f, &mut out),
        other => panic!("not a master verb: {other:?}"),
    };
    r.map_err(|e| e.to_string())?;
    Ok(String::from_utf8_lossy(&out).into_owned())
}

/// How long a frame may take to come back from the served segment, in ms (`--timeout`):
/// the segment runs in this debug-built test process in real time and falls behind on a
/// loaded CI machine (a TUeES030 node alone needs ~40 % of a core in a debug build), as the
/// README tells users of a busy host to raise it.
pub const TIMEOUT_MS: &str = "3000";

/// [`cli`] with `--udp <addr>` appended; panics with the message on failure.
pub fn ok(s: &Served, args: &[&str]) -> String {
    let mut a = args.to_vec();
    a.extend(["--udp", &s.addr, "--timeout", TIMEOUT_MS]);
    cli(&a).unwrap_or_else(|e| panic!("oxicat {a:?} failed: {e}"))
}

/// [`cli`] with `--udp <addr>` appended; the error message (panics if it succeeds).
pub fn fails(s: &Served, args: &[&str]) -> String {
    let mut a = args.to_vec();
    a.extend(["--udp", &s.addr, "--timeout", TIMEOUT_MS]);
    match cli(&a) {
        Ok(out) => panic!("oxicat {a:?} should fail, printed {out}"),
        Err(e) => e,
    }
}
