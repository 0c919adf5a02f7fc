//! Real-time measurement: ethercrab cycles a segment served by `oxicat sim` on the other end
//! of a veth pair (or a real cable) and reports the cycle period and the round-trip time
//! (p50 / p99 / max) as the master sees them.
//!
//! ```text
//! ip link add veth0 type veth peer name veth1; ip link set veth0 up; ip link set veth1 up
//! oxicat sim --iface veth1 demo:4 &
//! cargo run --release -p oxicat --example rt_cycle -- veth0 400 60
//! ```
//!
//! Arguments: interface, cycle in µs (default 400), duration in s (default 10), then
//! optionally `--rt[=PRIO]` (the cycle thread and the tx/rx thread under SCHED_FIFO, memory
//! locked; `oxicat_sim::rt`) and `--rt-cpu A[,B]` (pin the cycle thread to A, tx/rx to B). The master
//! brings the slaves to OP in free run, then sends one LRW (ethercrab's `tx_rx`) per cycle
//! at absolute deadlines (sleep to the deadline; no catch-up bursts after an overrun).
//! Needs CAP_NET_RAW.

use std::time::{Duration, Instant};

use ethercrab::std::{ethercat_now, tx_rx_task};
use ethercrab::{MainDevice, MainDeviceConfig, PduStorage, Timeouts};
use oxicat_sim::rt::RtOptions;

static PDU_STORAGE: PduStorage<16, { PduStorage::element_size(1100) }> = PduStorage::new();

fn percentiles(name: &str, v: &mut [u64]) {
    if v.is_empty() {
        println!("{name}: no samples");
        return;
    }
    v.sort_unstable();
    let p = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize] as f64 / 1000.0;
    println!(
        "{name:<14} n={:<7} min {:>8.1} µs  p50 {:>8.1} µs  p99 {:>8.1} µs  p99.9 {:>8.1} µs  max {:>8.1} µs",
        v.len(),
        p(0.0),
        p(0.5),
        p(0.99),
        p(0.999),
        p(1.0)
    );
}

/// `--rt[=PRIO]` and `--rt-cpu A[,B]`: the options of the cycle thread and the tx/rx thread.
fn rt_options(flags: &[String]) -> (Option<RtOptions>, Option<RtOptions>) {
    let mut prio = None;
    let mut cpus: Vec<usize> = Vec::new();
    let mut it = flags.iter();
    while let Some(f) = it.next() {
        if f == "--rt" {
            prio = Some(oxicat_sim::rt::DEFAULT_PRIORITY);
        } else if let Some(p) = f.strip_prefix("--rt=") {
            prio = Some(
                p.parse()
                    .unwrap_or_else(|_| fail(&format!("--rt={p}: not 1..=99"))),
            );
        } else if f == "--rt-cpu" {
            let list = it.next().map(String::as_str).unwrap_or_default();
            cpus = list
                .split(',')
                .map(|c| {
                    c.parse()
                        .unwrap_or_else(|_| fail(&format!("--rt-cpu {list}")))
                })
                .collect();
        } else {
            fail(&format!("unknown option {f}"));
        }
    }
    let at = |cpu: Option<usize>| {
        prio.map(|p| RtOptions {
            cpu,
            ..RtOptions::fifo(p)
        })
    };
    (at(cpus.first().copied()), at(cpus.get(1).copied()))
}

fn fail(msg: &str) -> ! {
    eprintln!("rt_cycle: {msg}");
    std::process::exit(2)
}

fn enter_rt(what: &str, opts: Option<RtOptions>) {
    if let Some(o) = opts {
        match oxicat_sim::rt::enter(&o) {
            Ok(r) => println!("{what}: {r}"),
            Err(e) => fail(&format!("{what}: {e}")),
        }
    }
}

fn main() {
    let mut args = std::env::args().skip(1);
    let iface = args.next().unwrap_or_else(|| "veth0".into());
    let cycle_us: u64 = args.next().and_then(|a| a.parse().ok()).unwrap_or(400);
    let seconds: u64 = args.next().and_then(|a| a.parse().ok()).unwrap_or(10);
    let (rt_cycle, rt_txrx) = rt_options(&args.collect::<Vec<_>>());
    let cycle = Duration::from_micros(cycle_us);

    let (tx, rx, pdu_loop) = PDU_STORAGE.try_split().expect("split once");
    let task = match tx_rx_task(&iface, tx, rx) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("rt_cycle: cannot open {iface}: {e} (needs CAP_NET_RAW)");
            std::process::exit(1);
        }
    };
    std::thread::Builder::new()
        .name("ethercrab-txrx".into())
        .spawn(move || {
            enter_rt("tx/rx thread", rt_txrx);
            futures_lite::future::block_on(task)
        })
        .expect("tx/rx thread");
    enter_rt("cycle thread", rt_cycle);
    let md = MainDevice::new(
        pdu_loop,
        Timeouts {
            pdu: Duration::from_millis(100),
            eeprom: Duration::from_millis(100),
            state_transition: Duration::from_secs(10),
            ..Timeouts::default()
        },
        MainDeviceConfig::default(),
    );
    futures_lite::future::block_on(async {
        let group = md
            .init_single_group::<16, 1024>(ethercat_now)
            .await
            .expect("discovery");
        println!("{} slaves on {iface}", group.len());
        let group = group.into_op(&md).await.expect("PRE-OP -> OP");
        let n = (seconds * 1_000_000 / cycle_us) as usize;
        println!(
            "cycling at {cycle_us} µs for {seconds} s ({n} cycles; expected LRW WKC {})",
            3 * group.len()
        );
        let mut periods = Vec::with_capacity(n);
        let mut rtts = Vec::with_capacity(n);
        let (mut errors, mut bad_wkc, mut overruns) = (0u64, 0u64, 0u64);
        let start = Instant::now();
        let mut deadline = start;
        let mut last: Option<Instant> = None;
        for k in 0..n {
            let now = Instant::now();
            if deadline > now {
                std::thread::sleep(deadline - now);
            } else if k > 0 {
                overruns += 1;
            }
            let t0 = Instant::now();
            if let Some(l) = last {
                periods.push((t0 - l).as_nanos() as u64);
            }
            last = Some(t0);
            for sd in group.iter(&md) {
                let mut o = sd.outputs_raw_mut();
                if o.len() >= 6 {
                    o[2..6].copy_from_slice(&(k as i32).to_le_bytes());
                }
            }
            match group.tx_rx(&md).await {
                Ok(r) => {
                    rtts.push(t0.elapsed().as_nanos() as u64);
                    if r.working_counter != 3 * group.len() as u16 {
                        bad_wkc += 1;
                    }
                }
                Err(_) => errors += 1,
            }
            deadline += cycle;
            // After an overrun, restart the grid from now rather than bursting to catch up.
            let now = Instant::now();
            if deadline < now {
                deadline = now;
            }
        }
        println!("ran {:.1} s", start.elapsed().as_secs_f64());
        percentiles("cycle period", &mut periods);
        percentiles("round trip", &mut rtts);
        println!(
            "lost frames (PDU timeouts) {errors}, wrong WKC {bad_wkc}, late cycles {overruns}"
        );
    });
}
