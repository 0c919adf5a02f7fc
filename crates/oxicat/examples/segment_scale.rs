//! Segment scale in real time (issue 18 item 1): N slaves served over UDP on the loopback
//! (`oxicat sim`'s own serving, on a thread of this process) and an `oxicat-master`
//! (ethercrab) cycling them in free run; one table row per (kind, N).
//!
//! ```text
//! cargo run --release -p oxicat --example segment_scale -- [--kind demo,twin] \
//!     [--n 16,64,256,1000] [--seconds 10] [--cycle-us 1000] [--rt] [--spin] [--per-esc-walk]
//!     [--idle] [--virtual] [--exchange auto,lean,overlap,ethercrab] [--beyond-limit] [--rt-master]
//!     [--pin] [--sm-sync] [--idle-preop]
//! ```
//!
//! Columns: late cycles (an exchange that ended after the next cycle was due), the round
//! trip of each exchange as the master sees it (from its start — the due time, or the end
//! of a late predecessor — to its end; includes ethercrab's own work), the serving thread's
//! CPU time per cycle (`/proc/self/task/TID/stat`, 10 ms ticks, so read it over ≥ 10 s),
//! the virtual time the segment's clock moved per cycle (above the cycle when the cycle's
//! frames, on the line together one wire time apart, do not fit in it: the served clock
//! then runs ahead of the host's), and the resident memory the segment added per slave. `demo` is the firmware-hosting
//! demo device; `twin` an EL2008 twin built from Beckhoff's ESI (an ESC with its SII and
//! SM/FMMU set-up, no firmware), from `../shared/reference/esi-vendor` or
//! `OXICAT_REFERENCE`. `--rt` serves from a SCHED_FIFO thread (root), `--rt-master` runs the
//! master's thread (and the UDP threads it starts) SCHED_FIFO too, `--pin` puts the serving
//! thread on CPU 1 and the master's on CPU 0; `--spin` busy-polls
//! for frames (`oxicat sim --spin`: no wakeup per frame, one core at 100 %, so the CPU
//! column is the whole cycle); `--per-esc-walk` turns
//! the segment's configured-address dispatch off (every ESC walks every datagram, as before
//! it), for before/after figures from one binary. `--idle` runs no master: it advances the
//! segment's virtual time 1 ms at a time and prints the CPU time per ms (the nodes' main
//! loops and timers, the scheduler). `--virtual` runs the master in this process on the
//! segment's virtual clock (`Link::Sim`, no network, no real time): the CPU time the
//! bring-up and each 1 ms cycle cost, load-independent, and a digest of every input byte
//! and working counter the master saw, so two builds can be compared for both speed and
//! sameness.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use oxicat::sim_cmd::{self, SimArgs};
use oxicat_master::cyclic::{CycleOptions, Exchange, Flow, SyncMode};
use oxicat_master::{Link, Master};

fn fail(msg: &str) -> ! {
    eprintln!("segment_scale: {msg}");
    std::process::exit(2)
}

fn status_kb(path: &str, key: &str) -> u64 {
    std::fs::read_to_string(path)
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with(key))
                .and_then(|l| l.split_whitespace().nth(1).map(str::to_string))
        })
        .and_then(|v| v.parse().ok())
        .unwrap_or(0)
}

/// utime + stime of thread `tid` of this process (`self`: the calling thread), in clock
/// ticks (100 per second); `process`: the whole process.
fn thread_ticks(tid: &str) -> u64 {
    let path = if tid == "self" {
        "/proc/thread-self/stat".to_string()
    } else if tid == "process" {
        "/proc/self/stat".to_string()
    } else {
        format!("/proc/self/task/{tid}/stat")
    };
    let stat = std::fs::read_to_string(path).unwrap_or_default();
    let rest = stat.rsplit_once(')').map(|(_, r)| r).unwrap_or_default();
    let f: Vec<&str> = rest.split_whitespace().collect();
    // Fields 14 and 15 (utime, stime), counted from 1 with the state as field 3.
    let get = |n: usize| {
        f.get(n - 3)
            .and_then(|v| v.parse::<u64>().ok())
            .unwrap_or(0)
    };
    get(14) + get(15)
}

fn pct(v: &mut [u64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_unstable();
    v[((v.len() - 1) as f64 * q).round() as usize] as f64 / 1000.0
}

struct Row {
    kind: String,
    n: usize,
    cycles: u64,
    wkc_errors: u64,
    late: u64,
    rtt: Vec<u64>,
    cpu_us_per_cycle: f64,
    /// Virtual time the segment's clock moved per cycle [µs]: above the cycle when the
    /// frames' trips (each starts when the previous one is back) do not fit in it, so
    /// the served segment's clock runs ahead of the host's.
    virtual_us_per_cycle: f64,
    kb_per_slave: f64,
    /// The master's exchange and its frames per cycle.
    exchange: String,
    note: String,
}

fn devices(kind: &str, n: usize) -> Vec<String> {
    match kind {
        "demo" => vec![format!("demo:{n}")],
        "twin" => {
            let r = std::env::var_os("OXICAT_REFERENCE")
                .map(std::path::PathBuf::from)
                .unwrap_or_else(|| {
                    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                        .join("../../../shared/reference")
                });
            let esi = r.join("esi-vendor/Beckhoff-EL2xxx.xml");
            if !esi.exists() {
                fail(&format!(
                    "{} not found (set OXICAT_REFERENCE)",
                    esi.display()
                ));
            }
            vec![format!("esi={}:EL2008*{n}", esi.display())]
        }
        k => fail(&format!("--kind {k}: demo or twin")),
    }
}

/// The `oxicat sim` arguments of a row: `n` devices of `kind`, quiet, at real time.
fn sim_args(kind: &str, n: usize, udp: Option<String>, rt: Option<u8>) -> SimArgs {
    SimArgs {
        udp,
        rt,
        ..SimArgs::quiet(devices(kind, n))
    }
}

/// How a row serves: `--rt`, `--spin`, `--per-esc-walk`.
#[derive(Debug, Clone, Copy, Default)]
struct Serving {
    rt: bool,
    spin: bool,
    per_esc: bool,
    /// The master's free-run exchange (`--exchange auto|lean|ethercrab`).
    exchange: Exchange,
    /// `--beyond-limit`: serve more firmware-hosting devices than `oxicat sim` takes
    /// (`MAX_SERVED_FIRMWARE_NODES`), to measure where the limit should be.
    beyond_limit: bool,
    /// `--rt-master`: the master's thread (and the UDP threads it starts) SCHED_FIFO too.
    rt_master: bool,
    /// `--pin`: the serving thread on CPU 1, the master's on CPU 0 (with `--rt` /
    /// `--rt-master`).
    pin: bool,
    /// `--sm-sync`: every slave SM-synchronous (0x1C32:01 = 1: its cycle on the SM2 event,
    /// once per frame) instead of free run (every main-loop pass).
    sm_sync: bool,
}

/// The master's cycle: `cycle_us`, free run or SM-synchronous.
fn cycling(cycle_us: u64, sm_sync: bool) -> oxicat_master::cyclic::Cycling {
    CycleOptions {
        cycle: Duration::from_micros(cycle_us),
        dc: false,
    }
    .with_sync(if sm_sync {
        SyncMode::SmSync
    } else {
        SyncMode::FreeRun
    })
}

fn parse_exchange(v: &str) -> Exchange {
    match v {
        "auto" => Exchange::Auto,
        "lean" => Exchange::Lean,
        "ethercrab" => Exchange::Ethercrab,
        "overlap" | "overlapped" => Exchange::Overlapped,
        _ => fail(&format!("--exchange {v}: auto, lean, overlap or ethercrab")),
    }
}

fn exchange_name(e: Exchange) -> &'static str {
    match e {
        Exchange::Auto => "auto",
        Exchange::Lean => "lean",
        Exchange::Ethercrab => "ethercrab",
        Exchange::Overlapped => "overlapped",
    }
}

fn run(kind: &str, n: usize, seconds: u64, cycle_us: u64, how: Serving) -> Row {
    let Serving {
        rt,
        spin,
        per_esc,
        exchange,
        beyond_limit,
        rt_master,
        pin,
        sm_sync,
    } = how;
    let args = SimArgs {
        spin,
        rt_cpu: (rt && pin).then_some(1),
        ..sim_args(
            kind,
            n,
            Some("127.0.0.1:0".into()),
            rt.then_some(oxicat_sim::rt::DEFAULT_PRIORITY),
        )
    };
    let rss0 = status_kb("/proc/self/status", "VmRSS:");
    let desc = sim_cmd::describe(&args).unwrap_or_else(|e| fail(&e.to_string()));
    sim_cmd::check_segment(&desc).unwrap_or_else(|e| fail(&e.to_string()));
    if !beyond_limit {
        sim_cmd::check_served(&desc).unwrap_or_else(|e| fail(&e.to_string()));
    }
    let (mut seg, names) = sim_cmd::build_segment(&desc).unwrap_or_else(|e| fail(&e.to_string()));
    seg.set_configured_dispatch(!per_esc);
    let clock = seg.clock();
    let kb_per_slave =
        status_kb("/proc/self/status", "VmRSS:").saturating_sub(rss0) as f64 / n as f64;
    let port =
        oxicat_sim::net::udp::UdpPort::bind("127.0.0.1:0").unwrap_or_else(|e| fail(&e.to_string()));
    let addr = port.local_addr().to_string();
    let stop = Arc::new(AtomicBool::new(false));
    let (tid_tx, tid_rx) = std::sync::mpsc::channel();
    let server = {
        let stop = stop.clone();
        std::thread::spawn(move || {
            let tid = std::fs::read_link("/proc/thread-self")
                .ok()
                .and_then(|p| p.file_name().map(|f| f.to_string_lossy().into_owned()))
                .unwrap_or_default();
            let _ = tid_tx.send(tid);
            sim_cmd::serve_segment_until(&args, port, Arc::new(Mutex::new(seg)), &names, stop)
        })
    };
    let tid = tid_rx.recv().unwrap_or_default();
    let period = cycle_us * 1000;
    let cycles = seconds * 1_000_000 / cycle_us;
    let (mut late, mut prev_end) = (0u64, 0u64);
    let mut rtt = Vec::with_capacity(cycles as usize);
    let (mut ticks0, mut v0) = (0, 0);
    let mut last = (0, 0);
    let run = std::thread::Builder::new()
        .stack_size(64 << 20)
        .spawn(move || {
            if rt_master {
                let o = oxicat_sim::rt::RtOptions {
                    cpu: pin.then_some(0),
                    ..oxicat_sim::rt::RtOptions::fifo(oxicat_sim::rt::DEFAULT_PRIORITY)
                };
                if let Err(e) = oxicat_sim::rt::enter(&o) {
                    fail(&format!("--rt-master: {e}"));
                }
            }
            let mut m = Master::open(Link::Udp(addr))?;
            m.set_exchange(exchange);
            let _ = m.scan()?;
            let stats = m.run_cyclic(cycling(period / 1000, sm_sync), |io| {
                if io.cycle == 0 {
                    ticks0 = thread_ticks(&tid);
                    v0 = clock.now();
                }
                let due = io.cycle * period;
                let end = io.time_ns;
                rtt.push(end.saturating_sub(due.max(prev_end)));
                if end > due + period {
                    late += 1;
                }
                prev_end = end;
                // The cycles' end: not the way back to PRE-OP after them.
                if io.cycle + 1 >= cycles {
                    last = (thread_ticks(&tid), clock.now());
                }
                Ok(if io.cycle + 1 >= cycles {
                    Flow::Stop
                } else {
                    Flow::Continue
                })
            });
            let ticks = last.0.saturating_sub(ticks0);
            let virt = last.1.saturating_sub(v0);
            stats.map(|s| (s, late, rtt, ticks, virt))
        })
        .unwrap_or_else(|e| fail(&e.to_string()));
    let result = run
        .join()
        .unwrap_or_else(|_| fail("master thread panicked"));
    stop.store(true, Ordering::Relaxed);
    let _ = server.join();
    match result {
        Ok((s, late, rtt, ticks, virt)) => Row {
            kind: kind.into(),
            n,
            cycles: s.cycles,
            wkc_errors: s.wkc_errors,
            late,
            rtt,
            cpu_us_per_cycle: ticks as f64 * 10_000.0 / s.cycles.saturating_sub(1).max(1) as f64,
            virtual_us_per_cycle: virt as f64 / 1000.0 / s.cycles.saturating_sub(1).max(1) as f64,
            kb_per_slave,
            exchange: format!("{}, {}", exchange_name(s.exchange), s.frames_per_cycle),
            note: String::new(),
        },
        Err(e) => Row {
            kind: kind.into(),
            n,
            cycles: 0,
            wkc_errors: 0,
            late: 0,
            rtt: Vec::new(),
            cpu_us_per_cycle: f64::NAN,
            virtual_us_per_cycle: f64::NAN,
            kb_per_slave,
            exchange: "–".into(),
            // The first clause says what failed; a list of every slave does not fit a row.
            note: e.to_string().chars().take(140).collect(),
        },
    }
}

/// `--idle`: the segment's own cost with no master: virtual time advanced 1 ms at a time
/// for `seconds`, the thread's CPU time per ms (what the nodes' firmware main loops, timers
/// and the scheduler cost before a frame arrives).
/// With `preop` (`--idle-preop`) the master (in this process, on the virtual clock) first
/// brings every slave to PRE-OP as for cycling (ethercrab's initialisation: the SIIs read,
/// the mailboxes set up), and the idle time is measured there.
fn idle(kind: &str, n: usize, seconds: u64, preop: bool) {
    let args = sim_args(kind, n, None, None);
    let desc = sim_cmd::describe(&args).unwrap_or_else(|e| fail(&e.to_string()));
    let (seg, _) = sim_cmd::build_segment(&desc).unwrap_or_else(|e| fail(&e.to_string()));
    let seg = Arc::new(Mutex::new(seg));
    if preop {
        let link = Link::Sim(seg.clone());
        std::thread::Builder::new()
            .stack_size(64 << 20)
            .spawn(move || {
                let mut m = Master::open(link)?;
                m.prepare_cyclic()
            })
            .unwrap_or_else(|e| fail(&e.to_string()))
            .join()
            .unwrap_or_else(|_| fail("master thread panicked"))
            .unwrap_or_else(|e| fail(&e.to_string()));
    }
    let mut seg = seg.lock().unwrap_or_else(|e| e.into_inner());
    let ms = seconds * 1000;
    let t0 = thread_ticks("self");
    let w0 = std::time::Instant::now();
    for _ in 0..ms {
        seg.advance_by(1_000_000);
    }
    let wall = w0.elapsed().as_secs_f64();
    let cpu_us_per_ms = thread_ticks("self").saturating_sub(t0) as f64 * 10_000.0 / ms as f64;
    let state = if preop { "PRE-OP" } else { "as booted" };
    println!(
        "| {kind} | {n} | idle ({state}), {ms} ms of virtual time | {cpu_us_per_ms:.0} µs CPU per ms ({:.2} µs per node; {:.2} s wall) |",
        cpu_us_per_ms / n as f64,
        wall
    );
}

/// CPU time of this process (all threads), in clock ticks (100 per second).
fn process_ticks() -> u64 {
    thread_ticks("process")
}

/// `--virtual`: bring-up and `seconds` of 1 kHz cycles on the virtual clock, in this
/// process; prints CPU per cycle and a digest of what the master saw.
fn virtual_row(kind: &str, n: usize, seconds: u64, cycle_us: u64, how: Serving) {
    let (exchange, sm_sync) = (how.exchange, how.sm_sync);
    let args = sim_args(kind, n, None, None);
    let desc = sim_cmd::describe(&args).unwrap_or_else(|e| fail(&e.to_string()));
    let t0 = process_ticks();
    let (seg, _) = sim_cmd::build_segment(&desc).unwrap_or_else(|e| fail(&e.to_string()));
    let t_built = process_ticks();
    let clock = seg.clock();
    let seg = Arc::new(Mutex::new(seg));
    let period = cycle_us * 1000;
    let cycles = seconds * 1_000_000 / cycle_us;
    let r = std::thread::Builder::new()
        .stack_size(64 << 20)
        .spawn(move || {
            let mut m = Master::open(Link::Sim(seg))?;
            m.set_exchange(exchange);
            let _ = m.scan()?;
            let (mut ticks_op, mut image, mut t_op) = (0, 0, 0);
            // Virtual time from each cycle's due time to the end of its exchange.
            let mut took: Vec<u64> = Vec::new();
            let mut last = (0, 0);
            // FNV-1a over every cycle's inputs and working counter.
            let mut digest: u64 = 0xcbf2_9ce4_8422_2325;
            let mut eat = |b: u8| {
                digest ^= u64::from(b);
                digest = digest.wrapping_mul(0x0100_0000_01b3);
            };
            let stats = m.run_cyclic(cycling(period / 1000, sm_sync), |io| {
                if io.cycle == 0 {
                    ticks_op = process_ticks();
                    t_op = clock.now();
                    image = io.inputs.iter().chain(&io.outputs).map(Vec::len).sum();
                }
                took.push(io.time_ns.saturating_sub(io.cycle * period));
                // The cycles' end: not the way back to PRE-OP after them.
                if io.cycle + 1 >= cycles {
                    last = (process_ticks(), clock.now());
                }
                for i in &io.inputs {
                    i.iter().for_each(|&b| eat(b));
                }
                io.working_counter
                    .to_le_bytes()
                    .iter()
                    .for_each(|&b| eat(b));
                Ok(if io.cycle + 1 >= cycles {
                    Flow::Stop
                } else {
                    Flow::Continue
                })
            })?;
            // From the first cycle's end to the last's: cycles − 1 cycles.
            let (t_end, v_end) = last;
            let v_cycles = v_end.saturating_sub(t_op);
            // The first cycle's is its start; the others' their exchange.
            let mut took = took.split_off(1.min(took.len()));
            took.sort_unstable();
            let pick = |q: f64| {
                took.get(((took.len() as f64 - 1.0) * q) as usize)
                    .map_or(0.0, |&t| t as f64 / 1000.0)
            };
            let exchange = (pick(0.5), pick(1.0));
            Ok::<_, oxicat_master::MasterError>((
                stats, ticks_op, t_end, digest, image, t_op, v_cycles, exchange,
            ))
        })
        .unwrap_or_else(|e| fail(&e.to_string()))
        .join()
        .unwrap_or_else(|_| fail("master thread panicked"));
    match r {
        Ok((s, t_op, t_end, digest, image, v_op, v_cycles, (x50, xmax))) => println!(
            "| {kind} | {n} | virtual, {} exchange, {} frames per cycle | {} | {} | build {:.2} s, bring-up {:.2} s CPU for {:.2} s of virtual time ({:.0} µs CPU per ms, the master's included) | {:.1} µs CPU per cycle, {:.0} µs of virtual time, exchange p50 / max {x50:.0} / {xmax:.0} µs | {image} B of process data | digest {digest:016x} |",
            exchange_name(s.exchange),
            s.frames_per_cycle,
            s.cycles,
            s.wkc_errors,
            (t_built - t0) as f64 / 100.0,
            t_op.saturating_sub(t_built) as f64 / 100.0,
            v_op as f64 * 1e-9,
            t_op.saturating_sub(t_built) as f64 * 1e4 / (v_op as f64 * 1e-6).max(1e-9),
            t_end.saturating_sub(t_op) as f64 * 10_000.0 / s.cycles.saturating_sub(1).max(1) as f64,
            v_cycles as f64 / 1000.0 / s.cycles.saturating_sub(1).max(1) as f64,
        ),
        Err(e) => println!("| {kind} | {n} | virtual | failed: {e} |"),
    }
}

fn main() {
    let mut kinds = vec!["demo".to_string(), "twin".to_string()];
    let mut ns = vec![16usize, 64, 256, 1000];
    let (mut seconds, mut cycle_us, mut one) = (10u64, 1000u64, false);
    let mut how = Serving::default();
    let (mut idle_only, mut virt, mut idle_preop) = (false, false, false);
    let mut it = std::env::args().skip(1);
    while let Some(a) = it.next() {
        let mut val = || {
            it.next()
                .unwrap_or_else(|| fail(&format!("{a} needs a value")))
        };
        match a.as_str() {
            "--kind" => kinds = val().split(',').map(str::to_string).collect(),
            "--n" => {
                ns = val()
                    .split(',')
                    .map(|v| v.parse().unwrap_or_else(|_| fail(&format!("--n {v}"))))
                    .collect()
            }
            "--seconds" => seconds = val().parse().unwrap_or_else(|_| fail("--seconds")),
            "--cycle-us" => cycle_us = val().parse().unwrap_or_else(|_| fail("--cycle-us")),
            "--rt" => how.rt = true,
            // The serving thread busy-polls for frames (`oxicat sim --spin`).
            "--spin" => how.spin = true,
            // The reference walk: every ESC walks every datagram (no configured-address
            // dispatch), for before/after figures from one binary.
            "--per-esc-walk" => how.per_esc = true,
            "--exchange" => how.exchange = parse_exchange(&val()),
            "--beyond-limit" => how.beyond_limit = true,
            "--rt-master" => how.rt_master = true,
            "--pin" => how.pin = true,
            "--sm-sync" => how.sm_sync = true,
            "--idle" => idle_only = true,
            "--idle-preop" => (idle_only, idle_preop) = (true, true),
            "--virtual" => virt = true,
            // One row in this process (each row runs in a process of its own, so that the
            // memory a segment adds is not hidden by what the previous one freed).
            "--one" => one = true,
            _ => fail(&format!("unknown argument {a}")),
        }
    }
    if seconds == 0 || cycle_us == 0 {
        fail("--seconds and --cycle-us must be above 0");
    }
    if virt {
        for kind in &kinds {
            for &n in &ns {
                virtual_row(kind, n, seconds, cycle_us, how);
            }
        }
        return;
    }
    if idle_only {
        for kind in &kinds {
            for &n in &ns {
                idle(kind, n, seconds, idle_preop);
            }
        }
        return;
    }
    if one {
        let (kind, n) = (&kinds[0], ns[0]);
        let mut r = run(kind, n, seconds, cycle_us, how);
        let (p50, p99, max) = (
            pct(&mut r.rtt, 0.5),
            pct(&mut r.rtt, 0.99),
            pct(&mut r.rtt, 1.0),
        );
        println!(
            "| {} | {} | {} | {} | {} | {:.0} / {:.0} / {:.0} | {:.1} | {:.0} | {:.0} | {} |{}",
            r.kind,
            r.n,
            r.cycles,
            r.wkc_errors,
            r.late,
            p50,
            p99,
            max,
            r.cpu_us_per_cycle,
            r.virtual_us_per_cycle,
            r.kb_per_slave,
            r.exchange,
            if r.note.is_empty() {
                String::new()
            } else {
                format!(" {}", r.note)
            }
        );
        return;
    }
    let exe = std::env::current_exe().unwrap_or_else(|e| fail(&e.to_string()));
    println!(
        "| kind | N | cycles | WKC errors | late cycles | RTT p50 / p99 / max [µs] | sim CPU per cycle [µs] | virtual time per cycle [µs] | memory per slave [KiB] | exchange, frames per cycle |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for kind in &kinds {
        for &n in &ns {
            let mut cmd = std::process::Command::new(&exe);
            cmd.args(["--one", "--kind", kind, "--n", &n.to_string()]);
            cmd.args([
                "--seconds",
                &seconds.to_string(),
                "--cycle-us",
                &cycle_us.to_string(),
            ]);
            cmd.args(["--exchange", exchange_name(how.exchange)]);
            for (on, flag) in [
                (how.rt, "--rt"),
                (how.spin, "--spin"),
                (how.per_esc, "--per-esc-walk"),
                (how.beyond_limit, "--beyond-limit"),
                (how.rt_master, "--rt-master"),
                (how.pin, "--pin"),
                (how.sm_sync, "--sm-sync"),
            ] {
                if on {
                    cmd.arg(flag);
                }
            }
            let out = cmd
                .stderr(std::process::Stdio::null())
                .output()
                .unwrap_or_else(|e| fail(&e.to_string()));
            let text = String::from_utf8_lossy(&out.stdout);
            match text.lines().find(|l| l.starts_with("| ")) {
                Some(row) => println!("{row}"),
                None => println!(
                    "| {kind} | {n} | – | – | – | – | – | – | – | – | failed: {}",
                    out.status
                ),
            }
        }
    }
}
