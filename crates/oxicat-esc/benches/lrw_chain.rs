//! A 64-byte LRW through chains of 1, 16 and 256 ESCs, each with SM2/SM3 (32 bytes,
//! 3-buffer) and two FMMUs mapping the datagram's halves (the KickCAT benchmark).
//!
//! Run: `nice -n -5 cargo bench -p oxicat-esc --bench lrw_chain`. The time per iteration
//! is one datagram through the whole chain, so ns per ESC per datagram = time / chain
//! length (criterion's `thrpt` line shows ESCs per second: 1e9 / thrpt = ns per ESC).
//!
//! Instructions per ESC per datagram (load-independent, see `examples/lrw_profile.rs`):
//! `valgrind --tool=callgrind <target>/release/examples/lrw_profile 256 N` for N = 100 and
//! 300; (Ir(300) - Ir(100)) / (200 * 256).
//!
//! Figures (2-core shared box, load average 4-7 while measuring; wall-clock is noisy, see
//! the crate README "Performance" for all runs):
//!
//! | version                        | Ir/ESC/dg | ns/ESC/dg 1 / 16 / 256, best | median of 3        |
//! |--------------------------------|-----------|------------------------------|--------------------|
//! | before (generic datagram path) | 592       | ~50 (previous engineer)      |                    |
//! | logical fast path + plan       | 495       | 43.8 / 53.6 / 47.3           | 54.6 / 55.0 / 71.3 |
//! | fused path from `forward`      | 262       | 19.3 / 21.2 / 22.3           | 22.2 / 24.1 / 27.4 |

use criterion::{black_box, criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use oxicat_esc::{Esc, EscConfig};
use oxicat_wire::frame::FrameBuilder;
use oxicat_wire::{Command, DatagramHeader};

fn pdi_config_eeprom() -> Vec<u8> {
    let mut e = vec![0u8; 2048];
    e[0] = 0x05; // SPI PDI
    e[14] = oxicat_esc::sii::crc8(&e[..14]);
    e
}

fn fpwr(esc: &mut Esc, ado: u16, data: &[u8]) {
    let mut buf = vec![0u8; 128];
    let mut b = FrameBuilder::new_bare(&mut buf).unwrap();
    b.push(
        DatagramHeader::physical(Command::Apwr, 0, 0, ado, data.len() as u16),
        data,
    )
    .unwrap();
    let n = b.finish();
    esc.forward(0, &mut buf[..n], 0, true);
}

fn make_esc() -> Esc {
    let mut e = Esc::new(EscConfig::et1100(), pdi_config_eeprom());
    let sm = |start: u16, ctrl: u8| {
        let mut r = [0u8; 8];
        r[0..2].copy_from_slice(&start.to_le_bytes());
        r[2..4].copy_from_slice(&32u16.to_le_bytes());
        r[4] = ctrl;
        r[6] = 1;
        r
    };
    fpwr(&mut e, 0x0810, &sm(0x1000, 0x64));
    fpwr(&mut e, 0x0818, &sm(0x1100, 0x20));
    let fmmu = |log: u32, phys: u16, ty: u8| {
        let mut r = [0u8; 16];
        r[0..4].copy_from_slice(&log.to_le_bytes());
        r[4..6].copy_from_slice(&32u16.to_le_bytes());
        r[7] = 7;
        r[8..10].copy_from_slice(&phys.to_le_bytes());
        r[11] = ty;
        r[12] = 1;
        r
    };
    fpwr(&mut e, 0x0600, &fmmu(0x0001_0000, 0x1000, 2));
    fpwr(&mut e, 0x0610, &fmmu(0x0001_0020, 0x1100, 1));
    e
}

fn lrw_frame() -> Vec<u8> {
    let mut buf = vec![0u8; 128];
    let mut b = FrameBuilder::new_bare(&mut buf).unwrap();
    b.push(
        DatagramHeader::logical(Command::Lrw, 0, 0x0001_0000, 64),
        &[0x5A; 64],
    )
    .unwrap();
    let n = b.finish();
    buf.truncate(n);
    buf
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("lrw_chain");
    for n in [1usize, 16, 256] {
        let mut chain: Vec<Esc> = (0..n).map(|_| make_esc()).collect();
        let mut frame = lrw_frame();
        let mut t = 0u64;
        g.throughput(Throughput::Elements(n as u64));
        g.bench_with_input(BenchmarkId::from_parameter(n), &n, |b, _| {
            b.iter(|| {
                t += 1000;
                for esc in chain.iter_mut() {
                    black_box(esc.forward(0, black_box(&mut frame), t, true));
                }
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
