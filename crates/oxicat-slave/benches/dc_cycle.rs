//! One DC cycle of the stack for the thesis' demo device (`oxicat_devices::demo`: 24 bytes
//! of outputs, 22 of inputs) on the software ESC: `on_sync0` = output mapping (SM2 read +
//! unpack) + the `Demo` application + input mapping (pack + SM3 write). The thesis measured
//! 85 µs for this on an F28379D over SPI (67 + 1 + 17 µs, Table 2-3).
//!
//! - `cargo bench -p oxicat-slave --bench dc_cycle`: criterion; `dc_cycle/sync0` is the
//!   stack's cycle, `dc_cycle/master_write` the master's SM2 write alone (subtract it from
//!   `dc_cycle/write+sync0`).
//! - Instructions: `OXICAT_CYCLES=10000 valgrind --tool=callgrind
//!   --toggle-collect='dc_cycle::Rig::sync0' target/release/deps/dc_cycle-*` counts the
//!   instructions of 10 000 `on_sync0` calls (each after a fresh master write); run it at
//!   10 000 and 20 000 and divide the difference by 10 000 for one cycle. Measured: 16 956
//!   instructions per cycle with dictionary lookups by index in the PDO copy and the
//!   application, 9 391 with the mapping resolved to copy steps at PREOP -> SAFEOP and
//!   the application on typed handles ([`oxicat_slave::Var`]); of these about 7 500 are
//!   the software ESC's side of the PDI accesses (its DC time keeping on the SYNC0
//!   status read), about 1 900 the stack and the application.

use criterion::{criterion_group, Criterion};
use oxicat_devices::demo::{self, Buttons, Demo, Leds};
use oxicat_esc::{Esc, EscConfig};
use oxicat_slave::{AlState, Slave, SyncMode};
use oxicat_wire::frame::FrameBuilder;
use oxicat_wire::{Command, DatagramHeader};
use std::hint::black_box;

const STATION: u16 = 0x1001;
const IMG: usize = demo::IMAGE;

struct NoLeds;
impl Leds for NoLeds {
    fn set(&mut self, _b: bool, _r: bool) {}
}
struct NoButtons;
impl Buttons for NoButtons {
    fn read(&mut self) -> u8 {
        0x5A
    }
}

type App = Demo<NoLeds, NoButtons>;

struct Rig {
    esc: Esc,
    slave: Slave<Esc, IMG, 128>,
    app: App,
    t: u64,
    buf: Vec<u8>,
}

impl Rig {
    fn frame(&mut self, cmd: Command, adp: u16, ado: u16, data: &[u8]) {
        self.buf.clear();
        self.buf.resize(64 + data.len(), 0);
        let mut fb = FrameBuilder::new_bare(&mut self.buf).expect("frame");
        fb.push(
            DatagramHeader::physical(cmd, 0, adp, ado, data.len() as u16),
            data,
        )
        .expect("datagram");
        let n = fb.finish();
        self.t += 1_000;
        self.esc.forward(0, &mut self.buf[..n], self.t, true);
    }

    fn wr(&mut self, ado: u16, data: &[u8]) {
        self.frame(Command::Fpwr, STATION, ado, data);
    }

    fn sm(&mut self, n: u16, start: u16, len: u16, ctrl: u8) {
        let mut r = [0u8; 8];
        r[0..2].copy_from_slice(&start.to_le_bytes());
        r[2..4].copy_from_slice(&len.to_le_bytes());
        r[4] = ctrl;
        r[6] = 1;
        self.wr(0x0800 + 8 * n, &r);
    }

    fn request(&mut self, state: u16) {
        self.wr(0x0120, &state.to_le_bytes());
        for _ in 0..3 {
            self.slave.poll(&mut self.esc, &mut self.app).expect("poll");
        }
    }

    /// Demo device in OP, DC SYNC0 at 200 µs.
    fn new() -> Self {
        let mut eeprom = vec![0u8; 2048];
        eeprom[0x7C] = 15;
        let mut esc = Esc::new(EscConfig::et1100(), eeprom);
        let slave = Slave::new(&demo::DEF, &mut esc).expect("stack");
        let mut r = Rig {
            esc,
            slave,
            app: Demo::new(NoLeds, NoButtons),
            t: 0,
            buf: Vec::new(),
        };
        r.frame(Command::Apwr, 0, 0x0010, &STATION.to_le_bytes());
        let d = &demo::DEF;
        r.sm(0, d.mailbox.rx_start, d.mailbox.rx_len, 0x26);
        r.sm(1, d.mailbox.tx_start, d.mailbox.tx_len, 0x22);
        r.request(2);
        r.sm(2, d.sm2_start, 24, 0x64);
        r.sm(3, d.sm3_start, 22, 0x20);
        r.wr(0x09A0, &200_000u32.to_le_bytes());
        r.wr(0x0990, &1_000_000u64.to_le_bytes());
        r.wr(0x0981, &[0x03]);
        r.request(4);
        r.request(8);
        assert_eq!(r.slave.state(), AlState::Op, "{:?}", r.slave.status_code());
        assert_eq!(r.slave.sync_mode(), SyncMode::DcSync0);
        r
    }

    /// The master's LRW part for this node: new outputs into SM2.
    #[inline(never)]
    fn master_write(&mut self, k: u32) {
        let mut o = [0u8; 24];
        o[2..6].copy_from_slice(&k.to_le_bytes());
        o[12..14].copy_from_slice(&(k as u16).to_le_bytes());
        self.wr(demo::DEF.sm2_start, &o);
    }

    #[inline(never)]
    fn sync0(&mut self) {
        self.slave
            .on_sync0(&mut self.esc, &mut self.app)
            .expect("sync0");
    }
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("dc_cycle");
    let mut r = Rig::new();
    let mut k = 0u32;
    g.bench_function("sync0", |b| {
        b.iter(|| {
            // Without a new master write the output mapping still reads SM2 status and
            // finds no new buffer; see write+sync0 for the full path.
            r.sync0();
            black_box(&r.esc);
        })
    });
    g.bench_function("master_write", |b| {
        b.iter(|| {
            k = k.wrapping_add(1);
            r.master_write(k);
        })
    });
    g.bench_function("write+sync0", |b| {
        b.iter(|| {
            k = k.wrapping_add(1);
            r.master_write(k);
            r.sync0();
        })
    });
    g.finish();
    assert!(r.slave.stats().outputs > 0);
}

criterion_group!(benches, bench);

fn main() {
    if let Some(n) = std::env::var("OXICAT_CYCLES")
        .ok()
        .and_then(|v| v.parse::<u32>().ok())
    {
        // For callgrind: n full cycles; only on_sync0 is collected with --toggle-collect.
        let mut r = Rig::new();
        for k in 1..=n {
            r.master_write(k);
            r.sync0();
        }
        assert_eq!(r.slave.od().get::<i32>(0x7010, 1), Ok(n as i32));
        println!("cycles {n}, outputs taken {}", r.slave.stats().outputs);
        return;
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
}
