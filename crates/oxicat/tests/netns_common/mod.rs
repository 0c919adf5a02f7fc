//! Network-namespace test bench: a fresh network namespace and a veth pair, `oxicat sim`
//! serving a virtual segment on the namespace's end, the other end left to the test in the
//! test's own namespace. Everything is removed when the [`NetnsSim`] is dropped, also when
//! the test fails.
//!
//! Needs root (CAP_NET_ADMIN for the namespace and veth, CAP_NET_RAW for the sockets) and
//! `ip`. Without them [`NetnsSim::start`] prints why the test is skipped and returns `None`;
//! when the environment variable `CI` is set (CI runs as root) it panics instead, so the
//! tests cannot silently not run there.
//!
//! ```ignore
//! mod netns_common;
//! let Some(bench) = netns_common::NetnsSim::start(&["demo:2"]) else { return };
//! // talk EtherCAT on bench.master_if() …
//! ```
#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// What a skipped test prints.
pub const SKIP_MESSAGE: &str = "skipped: needs root for netns/veth (CAP_NET_ADMIN)";

static COUNTER: AtomicUsize = AtomicUsize::new(0);

/// Namespaces of this bench are called `oxicat-test-<pid>-<n>`.
const NS_PREFIX: &str = "oxicat-test-";

/// Removes namespaces left by test processes that were killed before they could clean up
/// (deleting a namespace removes its veth end, and with it the peer).
fn remove_stale_namespaces() {
    let Ok(out) = Command::new("ip").args(["netns", "list"]).output() else {
        return;
    };
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        let name = line.split_whitespace().next().unwrap_or_default();
        let Some(rest) = name.strip_prefix(NS_PREFIX) else {
            continue;
        };
        let Some(pid) = rest.split('-').next().and_then(|p| p.parse::<u32>().ok()) else {
            continue;
        };
        if !std::path::Path::new(&format!("/proc/{pid}")).exists() {
            let _ = ip(&["netns", "del", name]);
        }
    }
}

/// ethercrab timeouts for a master talking to `oxicat sim` across a veth: generous, since
/// the simulator is a debug build sharing a loaded machine with the test (ethercrab's
/// defaults, e.g. 10 ms for an EEPROM read, assume dedicated hardware).
pub fn relaxed_timeouts() -> ethercrab::Timeouts {
    ethercrab::Timeouts {
        state_transition: Duration::from_secs(20),
        pdu: Duration::from_secs(1),
        eeprom: Duration::from_secs(1),
        wait_loop_delay: Duration::from_micros(100),
        mailbox_echo: Duration::from_secs(1),
        mailbox_response: Duration::from_secs(5),
    }
}

/// ethercrab configuration for the bench: a PDU lost on a loaded machine (the simulator
/// starved of CPU, a full socket queue) is sent again, up to 3 times, as a real master
/// would, instead of failing the test on a timing artefact.
pub fn relaxed_config() -> ethercrab::MainDeviceConfig {
    ethercrab::MainDeviceConfig {
        retry_behaviour: ethercrab::RetryBehaviour::Count(3),
        ..ethercrab::MainDeviceConfig::default()
    }
}

/// An ethercrab master on the bench's veth end: the test's own static PDU storage split,
/// its tx/rx task on a thread of its own, [`relaxed_timeouts`] and [`relaxed_config`].
pub fn master_on<const N: usize>(
    bench: &NetnsSim,
    storage: &'static ethercrab::PduStorage<16, N>,
) -> ethercrab::MainDevice<'static> {
    let (tx, rx, pdu_loop) = storage.try_split().expect("split once");
    let task =
        ethercrab::std::tx_rx_task(bench.master_if(), tx, rx).expect("raw socket on the veth end");
    std::thread::spawn(move || futures_lite::future::block_on(task));
    ethercrab::MainDevice::new(pdu_loop, relaxed_timeouts(), relaxed_config())
}

/// ethercrab's discovery of the bench's segment, which must hold `n` slaves of `vendor`.
pub async fn discover<const S: usize, const P: usize>(
    md: &ethercrab::MainDevice<'static>,
    bench: &NetnsSim,
    n: usize,
    vendor: u32,
) -> ethercrab::subdevice_group::SubDeviceGroup<S, P> {
    let group = md
        .init_single_group::<S, P>(ethercrab::std::ethercat_now)
        .await
        .unwrap_or_else(|e| panic!("discovery failed: {e}; sim log: {:?}", bench.sim_log()));
    assert_eq!(group.len(), n, "{n} nodes on the segment");
    for sd in group.iter(md) {
        assert_eq!(sd.identity().vendor_id, vendor);
    }
    group
}

/// The `oxicat` binary under test (`None` in another crate's tests, which include this
/// module by path and name their own binary: [`NetnsSim::spawn_bin_in_ns`]).
pub fn oxicat_bin() -> &'static str {
    match option_env!("CARGO_BIN_EXE_oxicat") {
        Some(bin) => bin,
        None => panic!("the oxicat binary is the oxicat crate's; name yours (spawn_bin_in_ns)"),
    }
}

fn is_root() -> bool {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("Uid:"))
                .and_then(|l| l.split_whitespace().nth(2).map(|e| e == "0"))
        })
        .unwrap_or(false)
}

pub fn in_ci() -> bool {
    std::env::var_os("CI").is_some_and(|v| !v.is_empty() && v != "false" && v != "0")
}

/// Not able to run here: skip (print and `None`) or, in CI, fail.
fn skip<T>(why: &str) -> Option<T> {
    if in_ci() {
        panic!("netns test cannot run in CI: {why}");
    }
    eprintln!("{SKIP_MESSAGE}: {why}");
    None
}

fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new("ip")
        .args(args)
        .output()
        .map_err(|e| format!("running `ip`: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "`ip {}` failed: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

/// A namespace + veth pair with `oxicat sim` on one end.
pub struct NetnsSim {
    ns: String,
    master_if: String,
    sim_if: String,
    ns_created: bool,
    link_created: bool,
    child: Option<Child>,
    log: Arc<Mutex<Vec<String>>>,
}

impl NetnsSim {
    /// Creates the namespace and veth pair only (no simulator), or `None` when skipped.
    pub fn bare() -> Option<Self> {
        if !is_root() {
            return skip("not running as root");
        }
        if Command::new("ip").arg("-V").output().is_err() {
            return skip("the `ip` tool (iproute2) is not installed");
        }
        remove_stale_namespaces();
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let pid = std::process::id();
        let id = format!("{}{}", pid % 100_000, n);
        let mut me = Self {
            ns: format!("{NS_PREFIX}{pid}-{n}"),
            master_if: format!("oxm{id}"),
            sim_if: format!("oxs{id}"),
            ns_created: false,
            link_created: false,
            child: None,
            log: Arc::new(Mutex::new(Vec::new())),
        };
        if let Err(e) = me.setup() {
            // `me` is dropped here: whatever was created is removed.
            return skip(&e);
        }
        Some(me)
    }

    fn setup(&mut self) -> Result<(), String> {
        ip(&["netns", "add", &self.ns])?;
        self.ns_created = true;
        ip(&[
            "link",
            "add",
            &self.master_if,
            "type",
            "veth",
            "peer",
            "name",
            &self.sim_if,
            "netns",
            &self.ns,
        ])?;
        self.link_created = true;
        // No IPv6 chatter on the test's end (the EtherCAT sockets would skip it anyway).
        let _ = std::fs::write(
            format!("/proc/sys/net/ipv6/conf/{}/disable_ipv6", self.master_if),
            "1",
        );
        ip(&["link", "set", &self.master_if, "up"])?;
        ip(&["-n", &self.ns, "link", "set", &self.sim_if, "up"])?;
        ip(&["-n", &self.ns, "link", "set", "lo", "up"])?;
        Ok(())
    }

    /// Creates the namespace and veth pair and starts `oxicat sim --iface <sim end>
    /// <devices…>` inside the namespace; returns once it serves. `None` when skipped.
    pub fn start(devices: &[&str]) -> Option<Self> {
        let mut me = Self::bare()?;
        let mut args = vec!["sim", "--iface", &me.sim_if];
        args.extend_from_slice(devices);
        let args: Vec<String> = args.into_iter().map(String::from).collect();
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        me.spawn_in_ns(&refs);
        Some(me)
    }

    /// Runs `oxicat <args>` inside the namespace as the simulator process (one per bench);
    /// waits until it prints that it serves, panics (with its output) if it does not.
    pub fn spawn_in_ns(&mut self, args: &[&str]) {
        self.spawn_bin_in_ns(oxicat_bin(), args)
    }

    /// [`NetnsSim::spawn_in_ns`] with another simulator binary (`oxicat-emu`).
    pub fn spawn_bin_in_ns(&mut self, bin: &str, args: &[&str]) {
        assert!(self.child.is_none(), "one simulator per bench");
        let mut child = Command::new("ip")
            .args(["netns", "exec", &self.ns, bin])
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn oxicat sim");
        let stderr = child.stderr.take().expect("piped stderr");
        self.child = Some(child);
        let (tx, rx) = mpsc::channel();
        let log = self.log.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines() {
                let Ok(line) = line else { break };
                // Stored before the waiting test is told, so it finds the line in the log.
                let serving = line.contains("serving");
                log.lock().unwrap().push(line);
                if serving {
                    let _ = tx.send(());
                }
            }
        });
        if rx.recv_timeout(Duration::from_secs(60)).is_err() {
            let status = self
                .child
                .as_mut()
                .and_then(|c| c.try_wait().ok().flatten());
            panic!(
                "oxicat sim did not start (exit: {status:?}); its output:\n{}",
                self.log.lock().unwrap().join("\n")
            );
        }
    }

    /// The interface the test talks EtherCAT on (in the test's namespace).
    pub fn master_if(&self) -> &str {
        &self.master_if
    }

    /// The interface the simulator serves (inside the namespace).
    pub fn sim_if(&self) -> &str {
        &self.sim_if
    }

    /// The namespace's name (for `ip netns exec`).
    pub fn netns(&self) -> &str {
        &self.ns
    }

    /// What the simulator printed on stderr so far.
    pub fn sim_log(&self) -> Vec<String> {
        self.log.lock().unwrap().clone()
    }

    /// Whether the simulator is still running.
    pub fn sim_running(&mut self) -> bool {
        self.child
            .as_mut()
            .is_some_and(|c| matches!(c.try_wait(), Ok(None)))
    }
}

impl NetnsSim {
    /// Ctrl-C to the simulator, then (after 2 s) a kill; its exit status (`None`: it was
    /// not running, or had to be killed).
    pub fn interrupt(&mut self) -> Option<std::process::ExitStatus> {
        let mut c = self.child.take()?;
        let _ = Command::new("kill")
            .args(["-INT", &c.id().to_string()])
            .status();
        for _ in 0..40 {
            if let Ok(Some(status)) = c.try_wait() {
                return Some(status);
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        let _ = c.kill();
        let _ = c.wait();
        None
    }
}

impl Drop for NetnsSim {
    fn drop(&mut self) {
        // Ctrl-C first, so the simulator prints its frame counters; then make sure.
        if self.child.is_some() {
            self.interrupt();
            if std::thread::panicking() {
                // Give the reader thread a moment to collect the last lines.
                std::thread::sleep(Duration::from_millis(100));
                eprintln!(
                    "oxicat sim output:\n{}",
                    self.log.lock().unwrap().join("\n")
                );
            }
        }
        if self.link_created {
            let _ = ip(&["link", "del", &self.master_if]);
        }
        if self.ns_created {
            let _ = ip(&["netns", "del", &self.ns]);
        }
    }
}
