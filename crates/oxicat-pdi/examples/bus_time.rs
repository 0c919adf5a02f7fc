//! SPI bus time of one Laelaps leg DC cycle (38 output + 22 input bytes, plus the
//! SYNC0 status and AL event reads the stack does in its SYNC0 handler) through each
//! driver at 10, 20 and 30 MHz SCLK, measured on the simulated chips with the real
//! slave stack; and the node's minimum cycle time set against the thesis' 85 µs
//! (67 µs output mapping + 1 µs application + 17 µs input mapping, F28379D + ET1100).
//!
//! `cargo run -p oxicat-pdi --features sim --example bus_time`

use oxicat_devices::laelaps::device::{self, INPUT_BYTES, OUTPUT_BYTES};
use oxicat_devices::laelaps::hw::JOINT_LOOP_TIMER;
use oxicat_devices::laelaps::kinematics::Side;
use oxicat_pdi::sim::{BusConfig, BusStats};
use oxicat_slave::Pdi;
use oxicat_testkit::laelaps::{self, trot_outputs};
use oxicat_testkit::ports::{Et2, Et3, EtPause, Lan, LanFast};
use oxicat_testkit::Port;

/// The thesis' application time per cycle on the F28379D (Table 2-3).
const APP_US: f64 = 1.0;
/// The device accepts SYNC0 cycles from 200 µs (its 0x1C32:05); the bus time per cycle does
/// not depend on the cycle time, so it is measured at the thesis' 400 µs.
const CYCLE_NS: u32 = 400_000;

struct Row {
    cycle: BusStats,
    out: BusStats,
    inp: BusStats,
    poll: BusStats,
}

fn measure<P: Port>(mhz: u32) -> Row {
    let def = device::device(Side::Right);
    let mut b = laelaps::leg_to_op::<P>(Side::Right, BusConfig::mhz(mhz), CYCLE_NS);
    let out = trot_outputs();
    b.wr(def.sm2_start, &out);
    for _ in 0..20 {
        b.advance_steps(CYCLE_NS as u64, 1, Some(JOINT_LOOP_TIMER));
        b.wr(def.sm2_start, &out);
    }
    let n = 100;
    b.port.reset_bus_stats();
    let s0 = b.sync0;
    for _ in 0..n {
        b.advance_steps(CYCLE_NS as u64, 1, Some(JOINT_LOOP_TIMER));
        // The master's frame: new outputs (not on the SPI bus).
        let st = b.bus_stats().unwrap();
        b.wr(def.sm2_start, &out);
        assert_eq!(b.bus_stats().unwrap(), st);
    }
    let cycles = b.sync0 - s0;
    assert!(cycles >= n as u64);
    let t = b.bus_stats().unwrap();
    let per = |x: u64| x / cycles;
    let cycle = BusStats {
        transactions: per(t.transactions),
        bytes: per(t.bytes),
        ps: per(t.ps),
        protocol_errors: t.protocol_errors,
    };
    // The two mappings alone, as the stack does them.
    b.port.reset_bus_stats();
    let mut o = [0u8; OUTPUT_BYTES];
    b.drv.read(def.sm2_start, &mut o).unwrap();
    let out = b.bus_stats().unwrap();
    b.port.reset_bus_stats();
    b.drv.write(def.sm3_start, &[0u8; INPUT_BYTES]).unwrap();
    let inp = b.bus_stats().unwrap();
    b.port.reset_bus_stats();
    b.s.poll(&mut b.drv, &mut b.app).unwrap();
    let poll = b.bus_stats().unwrap();
    Row {
        cycle,
        out,
        inp,
        poll,
    }
}

fn table<P: Port>() {
    for mhz in [10, 20, 30] {
        let r = measure::<P>(mhz);
        let min = r.cycle.us() + APP_US;
        println!(
            "| {:<38} | {:>2} | {:>3} / {:>4} | {:>6.1} | {:>6.1} | {:>6.1} | {:>6.1} | {:>6.1} | {} |",
            P::NAME,
            mhz,
            r.cycle.transactions,
            r.cycle.bytes,
            r.out.us(),
            r.inp.us(),
            r.cycle.us(),
            min,
            r.poll.us(),
            if min <= 100.0 { "yes" } else { "no" },
        );
    }
}

fn main() {
    println!("Laelaps leg DC cycle (SYNC0 handler: SYNC0 status, AL event, 38 B outputs, 22 B inputs, AL event),");
    println!("SPI bus time per cycle; CS overhead 100 ns per transaction; min cycle = bus + 1 us application (thesis).");
    println!("Thesis (F28379D + ET1100, Table 2-3): 67 us output mapping + 1 us application + 17 us input mapping = 85 us.");
    println!();
    println!("| driver                                 | MHz | transactions / bytes per cycle | output mapping us | input mapping us | bus us per cycle | min cycle us | main-loop poll us | 100 us cycle |");
    println!("|---|---|---|---|---|---|---|---|---|");
    table::<Lan>();
    table::<LanFast>();
    table::<Et2>();
    table::<Et3>();
    table::<EtPause>();
}
