//! Profiling driver for the lrw_chain benchmark: `lrw_profile <escs> <iterations> [checks]`
//! sends a 64-byte LRW through a chain (for callgrind / perf; prints nothing but a
//! checksum); with `checks`, the frame also carries that many FPRDs of AL status, one per
//! slave, as ethercrab's `tx_rx` sends them. `<escs>` 0: the harness loop alone (the
//! working counter cleared, no ESC), to subtract from the chains.

#[path = "../benches/common/lrw.rs"]
mod lrw;
use lrw::{lrw_frame, lrw_with_state_checks, Line};

/// The measured loop (out of line, as criterion's: `main`'s setup state stays out of it):
/// `iters` cycles from t = 1 µs on, 1 µs apart; returns the last time.
#[inline(never)]
fn run(line: &mut Line, frame: &mut [u8], iters: u64) -> u64 {
    let mut t = 1000u64;
    for _ in 0..iters {
        t += 1000;
        std::hint::black_box(line.cycle(std::hint::black_box(&mut *frame), t));
    }
    t
}

/// `run` without ESCs (`lrw_profile 0 N`): the harness's own instructions per frame.
#[inline(never)]
fn run_harness(frame: &mut [u8], iters: u64) -> u64 {
    let mut t = 1000u64;
    for _ in 0..iters {
        t += 1000;
        std::hint::black_box(Line::harness_only(std::hint::black_box(&mut *frame), t));
    }
    t
}

fn main() {
    let mut args = std::env::args().skip(1);
    let n: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(256);
    let iters: u64 = args.next().and_then(|a| a.parse().ok()).unwrap_or(1000);
    if n == 0 {
        let mut frame = lrw_frame();
        println!("t {}", run_harness(&mut frame, iters));
        return;
    }
    let checks: Option<usize> = args.next().and_then(|a| a.parse().ok());
    let mut line = Line::new(n.max(1));
    let mut frame = lrw_frame();
    line.check(&mut frame, 1000);
    if let Some(c) = checks {
        frame = lrw_with_state_checks(c);
    }
    let t = run(&mut line, &mut frame, iters);
    if checks.is_some() {
        frame = lrw_frame();
    }
    line.check(&mut frame, t + 1000);
    println!(
        "wkc {}",
        u16::from_le_bytes([frame[frame.len() - 2], frame[frame.len() - 1]])
    );
}
