//! Profiling driver for the lrw_chain benchmark: `lrw_profile <escs> <iterations>` sends
//! a 64-byte LRW through a chain (for callgrind / perf; prints nothing but a checksum).

#[path = "../benches/common/lrw.rs"]
mod lrw;
use lrw::{lrw_frame, make_esc};
use oxicat_esc::Esc;

fn main() {
    let mut args = std::env::args().skip(1);
    let n: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(256);
    let iters: u64 = args.next().and_then(|a| a.parse().ok()).unwrap_or(1000);
    let mut chain: Vec<Esc> = (0..n).map(|_| make_esc()).collect();
    let mut frame = lrw_frame();
    let mut t = 0u64;
    for _ in 0..iters {
        t += 1000;
        for esc in chain.iter_mut() {
            std::hint::black_box(esc.forward(0, std::hint::black_box(&mut frame), t, true));
        }
    }
    println!("wkc byte {}", frame[frame.len() - 2]);
}
