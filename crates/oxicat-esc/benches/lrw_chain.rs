//! A 64-byte LRW through chains of 1, 16 and 256 ESCs, each with SM2/SM3 (32 bytes,
//! 3-buffer) and two FMMUs mapping the datagram's halves (the KickCAT benchmark).
//!
//! Run: `nice -n -5 cargo bench -p oxicat-esc --bench lrw_chain`. The time per iteration
//! is one datagram through the whole chain, so ns per ESC per datagram = time / chain
//! length (criterion's `thrpt` line shows ESCs per second: 1e9 / thrpt = ns per ESC).
//!
//! Instructions per ESC per datagram (load-independent, see `examples/lrw_profile.rs`):
//! `valgrind --tool=callgrind <target>/release/examples/lrw_profile 256 N` for N = 100 and
//! 300; (Ir(300) - Ir(100)) / (200 * 256). `lrw_chain/harness` (and `lrw_profile 0 N`) is
//! the measuring loop without ESCs, to read the chain of 1 net of it.
//!
//! Figures (2-core shared box, load average 4-7 while measuring; wall-clock is noisy, see
//! the crate README "Performance" for all runs). Up to the fused path the ESCs were the
//! end of the line (outbound pass only); from "honest line" on, a line in OP with the way
//! back, Ir/ESC/dg for the chain of 256 (chains 1 / 16 in brackets):
//!
//! | version                        | Ir/ESC/dg | ns/ESC/dg 1 / 16 / 256, best | median of 3        |
//! |--------------------------------|-----------|------------------------------|--------------------|
//! | before (generic datagram path) | 592       | ~50 (previous engineer)      |                    |
//! | logical fast path + plan       | 495       | 43.8 / 53.6 / 47.3           | 54.6 / 55.0 / 71.3 |
//! | fused path from `forward`      | 262       | 19.3 / 21.2 / 22.3           | 22.2 / 24.1 / 27.4 |
//! | honest line (main, A/B below)  | 336 (302 / 334) | 37.6 / 34.6 / 37.2     | 38.7 / 37.7 / 38.8 |
//! | pass-through, `FusedKey`       | 270 (287 / 272) | 31.2 / 26.6 / 36.4     | 36.6 / 29.0 / 36.9 |
//! | key words, one step loop, inlined, hot fields first | 195 (234 / 198) | 21.4 / 14.4 / 15.8 | 23.3 / 15.8 / 17.2 (of 4) |
//! | steps with the key, gated routes, fused path without the DC unit | 172 (198 / 174) | see the crate README | (second pass of item 6) |
//! | packed SM state, unrolled steps, one memory slice | 144 (170 / 146) | 9.5 / 6.5 / 9.4 (load 2-3) | 10.1 / 7.4 / 10.1 (of 6; third pass) |
//!
//! (The "honest line" and `FusedKey` rows: A/B in one session, both bench binaries
//! alternately, three runs each, load average 5.7-6.1 on the 2 cores, so about twice the
//! quiet-box figures; the same code measured 18.5 / 18.4 / 20.6 ns on a quiet box before
//! that change. The last row: A/B against the `FusedKey` row's binary, four runs each,
//! load average 4.3-6.8: that binary 22.0 / 18.5 / 24.2 best, 28.5 / 19.5 / 25.7 median.)

use criterion::{black_box, criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};

#[path = "common/lrw.rs"]
mod lrw;
use lrw::{lrw_frame, lrw_with_state_checks, Line};

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("lrw_chain");
    for n in [1usize, 16, 256] {
        let mut line = Line::new(n);
        let mut frame = lrw_frame();
        line.check(&mut frame, 1000);
        let mut t = 1000u64;
        g.throughput(Throughput::Elements(n as u64));
        g.bench_with_input(BenchmarkId::from_parameter(n), &n, |b, _| {
            b.iter(|| {
                t += 1000;
                black_box(line.cycle(black_box(&mut frame), t))
            })
        });
        // The line still answers as it should after the measured cycles.
        line.check(&mut frame, t + 1000);
    }
    // The harness alone (the same loop and frame, no ESC): subtract it from the chain of
    // 1 for the ESC's own time.
    let mut frame = lrw_frame();
    let mut t = 1000u64;
    g.throughput(Throughput::Elements(1));
    g.bench_function("harness", |b| {
        b.iter(|| {
            t += 1000;
            black_box(Line::harness_only(black_box(&mut frame), t))
        })
    });
    g.finish();
}

/// The frame ethercrab's `tx_rx` sends: the LRW plus one FPRD of AL status per slave, so
/// every ESC walks N datagrams addressed to the others (time per iteration / N = ns per ESC).
fn bench_state_checks(c: &mut Criterion) {
    let mut g = c.benchmark_group("lrw_state_checks");
    for n in [16usize, 64] {
        let mut line = Line::new(n);
        line.check(&mut lrw_frame(), 1000);
        let mut frame = lrw_with_state_checks(n);
        let mut t = 1000u64;
        g.throughput(Throughput::Elements(n as u64));
        g.bench_with_input(BenchmarkId::from_parameter(n), &n, |b, _| {
            b.iter(|| {
                t += 1000;
                black_box(line.cycle(black_box(&mut frame), t))
            })
        });
        line.check(&mut lrw_frame(), t + 1000);
    }
    g.finish();
}

criterion_group!(benches, bench, bench_state_checks);
criterion_main!(benches);
