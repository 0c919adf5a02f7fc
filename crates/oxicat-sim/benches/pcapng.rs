//! The pcapng writer: our hand-written `oxicat_sim::pcapng::PcapngWriter` against the same
//! writer on the `pcap-file` crate (below), on EtherCAT-sized frames. Both must write the
//! same bytes (asserted before timing); the figures are per 1000 packets into a `Vec` and
//! through a `BufWriter` (as `PcapngCapture::create` writes).
//!
//! - Time: `cargo bench -p oxicat-sim --features compare-crates --bench pcapng`.
//! - Instructions (not swayed by the load of a shared machine):
//!   `scripts/ir-per-call.sh target/release/deps/pcapng-<hash> pcap-file/122 hand-written/122`
//!   (per 1000 packets).

use criterion::{black_box, criterion_group, BenchmarkId, Criterion, Throughput};
use oxicat_sim::pcapng::PcapngWriter;
use std::io::{BufWriter, Write};

/// The same writer on the `pcap-file` crate (measured in issue 14 and not adopted:
/// README "Hand-written or a crate").
mod crate_writer {
    use pcap_file::pcapng::blocks::enhanced_packet::{EnhancedPacketBlock, EnhancedPacketOption};
    use pcap_file::pcapng::blocks::interface_description::{
        InterfaceDescriptionBlock, InterfaceDescriptionOption,
    };
    use pcap_file::pcapng::blocks::section_header::SectionHeaderBlock;
    use pcap_file::pcapng::PcapNgWriter;
    use pcap_file::{DataLink, Endianness, PcapError};
    use std::borrow::Cow;
    use std::io::{self, Write};
    use std::time::Duration;

    const MAX_BLOCK_LEN: usize = 64 * 1024 * 1024;

    fn pcap_err(e: PcapError) -> io::Error {
        match e {
            PcapError::IoError(e) => e,
            e => io::Error::other(e),
        }
    }

    pub struct PcapngWriter<W: Write> {
        out: PcapNgWriter<W>,
    }

    impl<W: Write> PcapngWriter<W> {
        pub fn new(out: W) -> io::Result<Self> {
            let shb = SectionHeaderBlock {
                endianness: Endianness::Little,
                ..Default::default()
            };
            let mut out = PcapNgWriter::with_section_header(out, shb).map_err(pcap_err)?;
            out.write_pcapng_block(InterfaceDescriptionBlock {
                linktype: DataLink::ETHERNET,
                snaplen: 0,
                options: vec![InterfaceDescriptionOption::IfTsResol(9)],
            })
            .map_err(pcap_err)?;
            Ok(Self { out })
        }

        pub fn write_packet(&mut self, ts_ns: u64, data: &[u8], outbound: bool) -> io::Result<()> {
            let len = u32::try_from(data.len())
                .ok()
                .filter(|n| *n <= (MAX_BLOCK_LEN as u32) - 64)
                .ok_or_else(|| io::Error::other("packet too large"))?;
            self.out
                .write_pcapng_block(EnhancedPacketBlock {
                    interface_id: 0,
                    timestamp: Duration::from_nanos(ts_ns),
                    original_len: len,
                    data: Cow::Borrowed(data),
                    options: vec![EnhancedPacketOption::Flags(if outbound { 2 } else { 1 })],
                })
                .map_err(pcap_err)?;
            Ok(())
        }

        pub fn into_inner(self) -> W {
            self.out.into_inner()
        }
    }
}

/// `n` frames of `len` bytes (the Ethernet minimum 60, a trot-sized 122, a full 1514).
fn frames(n: usize, len: usize) -> Vec<(u64, Vec<u8>, bool)> {
    (0..n)
        .map(|i| {
            let d = (0..len).map(|b| (b ^ i) as u8).collect();
            (
                1_700_000_000_000_000_000 + i as u64 * 100_000,
                d,
                i % 2 == 0,
            )
        })
        .collect()
}

fn with_crate(fr: &[(u64, Vec<u8>, bool)], out: Vec<u8>) -> Vec<u8> {
    let mut w = crate_writer::PcapngWriter::new(out).unwrap();
    for (t, d, o) in fr {
        w.write_packet(*t, d, *o).unwrap();
    }
    w.into_inner()
}

fn by_hand(fr: &[(u64, Vec<u8>, bool)], out: Vec<u8>) -> Vec<u8> {
    let mut w = PcapngWriter::new(out).unwrap();
    for (t, d, o) in fr {
        w.write_packet(*t, d, *o).unwrap();
    }
    w.into_inner()
}

fn bench(c: &mut Criterion) {
    const N: usize = 1000;
    let mut g = c.benchmark_group("pcapng_write_1000_packets");
    for len in [60usize, 122, 1514] {
        let fr = frames(N, len);
        // Same bytes, or the comparison means nothing.
        let a = with_crate(&fr, Vec::new());
        let b = by_hand(&fr, Vec::new());
        assert_eq!(
            a, b,
            "pcap-file and the hand-written writer differ at {len} B"
        );
        let cap = a.len();
        g.throughput(Throughput::Elements(N as u64));
        g.bench_with_input(BenchmarkId::new("pcap-file", len), &fr, |bch, fr| {
            let mut buf = Vec::with_capacity(cap);
            bch.iter(|| {
                buf.clear();
                buf = with_crate(black_box(fr), std::mem::take(&mut buf));
            })
        });
        g.bench_with_input(BenchmarkId::new("hand-written", len), &fr, |bch, fr| {
            let mut buf = Vec::with_capacity(cap);
            bch.iter(|| {
                buf.clear();
                buf = by_hand(black_box(fr), std::mem::take(&mut buf));
            })
        });
    }
    g.finish();
    // Through a BufWriter, as `PcapngCapture::create` writes (onto a file; here onto a
    // sink, so that the file system's time does not drown the writers').
    let fr = frames(N, 122);
    let mut g = c.benchmark_group("pcapng_write_1000_packets_bufwriter");
    g.throughput(Throughput::Elements(N as u64));
    g.bench_function("pcap-file", |bch| {
        bch.iter(|| {
            let mut w = crate_writer::PcapngWriter::new(BufWriter::new(std::io::sink())).unwrap();
            for (t, d, o) in &fr {
                w.write_packet(*t, d, *o).unwrap();
            }
            w.into_inner().flush().unwrap();
        })
    });
    g.bench_function("hand-written", |bch| {
        bch.iter(|| {
            let mut w = PcapngWriter::new(BufWriter::new(std::io::sink())).unwrap();
            for (t, d, o) in &fr {
                w.write_packet(*t, d, *o).unwrap();
            }
            w.into_inner().flush().unwrap();
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

/// `OXICAT_CALLGRIND=<writer>/<len>:<reps>` (writer `pcap-file` or `hand-written`): writes
/// 1000 packets of `len` bytes into a `Vec`, `reps` times, for `scripts/ir-per-call.sh`.
fn callgrind(spec: &str) {
    let (v, reps) = spec.rsplit_once(':').expect("variant:reps");
    let (w, len) = v.split_once('/').expect("writer/len");
    let fr = frames(1000, len.parse().expect("len"));
    let mut buf = Vec::with_capacity(200_000);
    for _ in 0..reps.parse::<u32>().expect("reps") {
        buf.clear();
        buf = match w {
            "pcap-file" => with_crate(black_box(&fr), std::mem::take(&mut buf)),
            "hand-written" => by_hand(black_box(&fr), std::mem::take(&mut buf)),
            _ => panic!("unknown writer {w}"),
        };
    }
    black_box(&buf);
}

fn main() {
    if let Ok(spec) = std::env::var("OXICAT_CALLGRIND") {
        return callgrind(&spec);
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
}
