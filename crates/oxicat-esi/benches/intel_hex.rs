//! The Intel HEX reader of SII dumps: `oxicat_esi::sii::intel_hex` (records read by the
//! `ihex` crate) against the hand-written reader it replaced (kept below as it was), on
//! the Intel HEX of every registry device's SII image and of the four reference images
//! (16-byte records as dump tools write them). Both must give the same image.
//!
//! - Time: `cargo bench -p oxicat-esi --bench intel_hex`.
//! - Instructions: `scripts/ir-per-call.sh target/release/deps/intel_hex-<hash> ihex
//!   hand-written` (one decode of all ten files).
//! - Where the two disagree: `OXICAT_DIFF=<n> target/release/deps/intel_hex-<hash>` mutates
//!   the files `n` times (bytes flipped, inserted, deleted, lines swapped) and counts the
//!   inputs one accepts and the other refuses, and any where both accept with different
//!   images.

use criterion::{black_box, criterion_group, Criterion};
use oxicat_esi::sii;

/// The hand-written reader of `oxicat_esi::sii` before it moved to `ihex`.
mod hand {
    pub fn intel_hex(text: &[u8]) -> Result<Vec<u8>, String> {
        let bad = |t: &str| t.to_string();
        let text = std::str::from_utf8(text).map_err(|_| bad("not UTF-8"))?;
        let mut out = Vec::new();
        let mut base = 0usize;
        for line in text.lines().map(str::trim).filter(|l| !l.is_empty()) {
            let hexpart = line.strip_prefix(':').ok_or_else(|| bad(line))?;
            if !hexpart.is_ascii() || hexpart.len() & 1 != 0 || hexpart.len() < 10 {
                return Err(bad(line));
            }
            let b: Vec<u8> = (0..hexpart.len() / 2)
                .map(|i| u8::from_str_radix(&hexpart[2 * i..2 * i + 2], 16))
                .collect::<Result<_, _>>()
                .map_err(|_| bad(line))?;
            let n = b[0] as usize;
            if b.len() != n + 5 {
                return Err(bad(line));
            }
            let sum = b.iter().fold(0u8, |a, x| a.wrapping_add(*x));
            if sum != 0 {
                return Err(bad(line));
            }
            let addr = u16::from_be_bytes([b[1], b[2]]) as usize;
            match b[3] {
                0 => {
                    let at = base + addr;
                    if at + n > 1 << 20 {
                        return Err(bad(line));
                    }
                    if out.len() < at + n {
                        out.resize(at + n, 0xFF);
                    }
                    out[at..at + n].copy_from_slice(&b[4..4 + n]);
                }
                1 => break,
                2 if n == 2 => base = (u16::from_be_bytes([b[4], b[5]]) as usize) << 4,
                4 if n == 2 => base = (u16::from_be_bytes([b[4], b[5]]) as usize) << 16,
                _ => {}
            }
        }
        Ok(out)
    }
}

/// `img` as Intel HEX: 16-byte data records, then end of file.
fn to_hex(img: &[u8]) -> String {
    let mut s = String::new();
    for (k, c) in img.chunks(16).enumerate() {
        let a = (k * 16) as u16;
        let mut rec = vec![c.len() as u8, (a >> 8) as u8, a as u8, 0];
        rec.extend_from_slice(c);
        let sum = rec
            .iter()
            .fold(0u8, |x, y| x.wrapping_add(*y))
            .wrapping_neg();
        rec.push(sum);
        s.push(':');
        for b in rec {
            s.push_str(&format!("{b:02X}"));
        }
        s.push_str("\r\n");
    }
    s.push_str(":00000001FF\r\n");
    s
}

fn corpus() -> Vec<String> {
    let mut files = Vec::new();
    for k in oxicat_devices::registry::kits() {
        files.push(to_hex(&sii::generate((k.def)(0)).expect("SII")));
    }
    let dir = std::env::var_os("OXICAT_REFERENCE")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| {
            std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/reference")
        })
        .join("sii");
    for n in ["ek1100", "el2828", "el2889", "akd"] {
        // The reference `.hex` files are binary dumps (SOEM's naming); written as Intel HEX.
        let img = std::fs::read(dir.join(format!("{n}.hex"))).expect("reference SII");
        files.push(to_hex(&img));
    }
    for f in &files {
        let a = sii::intel_hex(f.as_bytes()).expect("ihex decodes");
        let b = hand::intel_hex(f.as_bytes()).expect("hand-written decodes");
        assert_eq!(a, b, "the two readers give different images");
    }
    files
}

fn bench(c: &mut Criterion) {
    let files = corpus();
    let mut g = c.benchmark_group("intel_hex_decode_10_files");
    g.bench_function("ihex", |b| {
        b.iter(|| {
            for f in black_box(&files) {
                black_box(sii::intel_hex(f.as_bytes()).unwrap());
            }
        })
    });
    g.bench_function("hand-written", |b| {
        b.iter(|| {
            for f in black_box(&files) {
                black_box(hand::intel_hex(f.as_bytes()).unwrap());
            }
        })
    });
    g.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .sample_size(30)
        .warm_up_time(std::time::Duration::from_secs(1))
        .measurement_time(std::time::Duration::from_secs(5));
    targets = bench
}

/// A deterministic mutation of `f` (xorshift64 `seed`).
fn mutate(f: &str, seed: &mut u64) -> Vec<u8> {
    let mut next = || {
        *seed ^= *seed << 13;
        *seed ^= *seed >> 7;
        *seed ^= *seed << 17;
        *seed
    };
    let mut b = f.as_bytes().to_vec();
    for _ in 0..1 + next() % 3 {
        let i = (next() as usize) % b.len().max(1);
        match next() % 5 {
            0 => b[i] = next() as u8,
            1 => b[i] = b"0123456789ABCDEFabcdef: \r\n"[(next() % 26) as usize],
            2 => b.insert(i, b"0123456789ABCDEF:\n "[(next() % 19) as usize]),
            3 => {
                b.remove(i);
            }
            _ => {
                // Swap this line for another one (records out of order, doubled).
                let lines: Vec<&str> = f.lines().collect();
                let j = (next() as usize) % lines.len();
                b = f
                    .replacen(lines[j], lines[(next() as usize) % lines.len()], 1)
                    .into();
            }
        }
    }
    b
}

fn differential(n: u64) {
    let files = corpus();
    let mut seed = 0x9E37_79B9_7F4A_7C15u64;
    let (mut both_ok, mut both_err, mut only_ihex, mut only_hand, mut differ) = (0, 0, 0, 0, 0);
    let mut only_hand_plus = 0;
    let mut shown = 0;
    for k in 0..n {
        let input = mutate(&files[(k as usize) % files.len()], &mut seed);
        match (sii::intel_hex(&input), hand::intel_hex(&input)) {
            (Ok(a), Ok(b)) if a == b => both_ok += 1,
            (Ok(_), Ok(_)) => differ += 1,
            (Err(_), Err(_)) => both_err += 1,
            (Ok(_), Err(_)) => only_ihex += 1,
            (Err(e), Ok(_)) => {
                only_hand += 1;
                only_hand_plus += usize::from(input.contains(&b'+'));
                if shown < 5 {
                    shown += 1;
                    println!("only the hand-written reader accepts; ihex: {e}");
                }
            }
        }
    }
    println!(
        "{n} mutated inputs: both accept, same image {both_ok}; both refuse {both_err}; \
         only ihex accepts {only_ihex}; only hand-written accepts {only_hand} \
         ({only_hand_plus} of them with a '+'); both accept, different images {differ}"
    );
}

/// `OXICAT_CALLGRIND=<reader>:<reps>` (reader `ihex` or `hand-written`): decodes the ten
/// files `reps` times, for `scripts/ir-per-call.sh`.
fn callgrind(spec: &str) {
    let (r, reps) = spec.rsplit_once(':').expect("reader:reps");
    let files = corpus();
    for _ in 0..reps.parse::<u32>().expect("reps") {
        for f in &files {
            black_box(match r {
                "ihex" => sii::intel_hex(black_box(f.as_bytes())).unwrap(),
                "hand-written" => hand::intel_hex(black_box(f.as_bytes())).unwrap(),
                _ => panic!("unknown reader {r}"),
            });
        }
    }
}

fn main() {
    if let Ok(spec) = std::env::var("OXICAT_CALLGRIND") {
        return callgrind(&spec);
    }
    if let Ok(n) = std::env::var("OXICAT_DIFF") {
        return differential(n.parse().expect("OXICAT_DIFF=<count>"));
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
}
