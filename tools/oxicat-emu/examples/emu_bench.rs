//! Emulator throughput: one and four demo board images (`firmware/stm32f446-lan9252`, built
//! first) booted and run for 200 ms of their own time each; prints emulated instructions
//! per wall second and simulated seconds per wall second.
//!
//! `cargo run --release -p oxicat-emu --example emu_bench [elf]`

use std::time::Instant;

use oxicat_emu::Board;
use oxicat_esc::{Esc, EscConfig};
use oxicat_pdi::sim::{BusConfig, Lan9252Model};

fn main() {
    let path = std::env::args().nth(1).unwrap_or_else(|| {
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../firmware/target/thumbv7em-none-eabihf/release/oxicat-firmware-stm32f446-lan9252"
        )
        .to_string()
    });
    let img = match std::fs::read(&path) {
        Ok(b) => b,
        Err(e) => {
            eprintln!(
                "{path}: {e} (build it: cd firmware/stm32f446-lan9252 && cargo build --release)"
            );
            std::process::exit(2);
        }
    };
    for boards in [1usize, 4] {
        let mut bs: Vec<Board> = (0..boards)
            .map(|_| {
                let esc = Esc::new(EscConfig::lan9252(), vec![0; 128]);
                Board::new(&img, Lan9252Model::handle(esc, BusConfig::mhz(22))).expect("image")
            })
            .collect();
        let t0 = Instant::now();
        let until = 200_000_000u64; // 200 ms of each board's time
                                    // Round-robin in 100 µs slices, as the segment advances its nodes.
        let mut t = 0;
        while t < until {
            t += 100_000;
            for b in &mut bs {
                while b.time_ns() < t {
                    if let Err(e) = b.run(2_000) {
                        eprintln!("{e}");
                        std::process::exit(1);
                    }
                }
            }
        }
        let wall = t0.elapsed().as_secs_f64();
        let instr: u64 = bs.iter().map(|b| b.instructions()).sum();
        println!(
            "{boards} board(s): {:.1} M instructions/s, {:.3} simulated s per wall s (each board {:.0} ms in {:.2} s)",
            instr as f64 / wall / 1e6,
            0.2 / wall,
            until as f64 * 1e-6,
            wall
        );
    }
}
