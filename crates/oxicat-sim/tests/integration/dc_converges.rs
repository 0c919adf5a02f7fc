//! Distributed Clocks converge: drifting ESC oscillators (±100 ppm, different power-on
//! offsets) on links with unequal delays, synchronised by ethercrab's DC start-up (static
//! drift compensation, FRMW alignment loop, SYNC0 configuration, cyclic `tx_rx_dc`) through
//! the in-process transport in virtual time. Afterwards every ESC's system-time difference
//! (0x092C) is under 100 ns and the SYNC0 edges of all ESCs fall within 100 ns.

use crate::segment_common;
use segment_common as common;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use ethercrab::error::Error;
use ethercrab::subdevice_group::DcConfiguration;
use ethercrab::{DcSync, MainDevice, MainDeviceConfig, PduStorage, RegisterAddress};
use oxicat_esc::dc::ClockConfig;
use oxicat_esc::Esc;
use oxicat_master::inprocess::{spawn_inprocess_with, InProcessConfig};
use oxicat_sim::node::EscEvent;
use oxicat_sim::segment::Segment;

static PDU_STORAGE: PduStorage<16, { PduStorage::element_size(1100) }> = PduStorage::new();

const CYCLE_NS: u64 = 1_000_000;

/// EK1100 + EL2004 + EL2828 + EL2889 + EL2262 with drifting clocks and unequal cables.
fn drifting_segment() -> Segment {
    let drift = [100.0, -100.0, 50.0, -30.0, 75.0];
    let offsets = [1_234_567_u64, 987_654_321, 42, 5_000_000_000, 77_777];
    let mut seg = Segment::new();
    for (k, (_, file, _)) in common::DEVICES.iter().enumerate() {
        let mut cfg = if k == 0 {
            common::ek1100_config()
        } else {
            common::terminal_config()
        };
        cfg.clock = ClockConfig {
            drift_ppm: drift[k],
            start_offset_ns: offsets[k],
        };
        let id = seg.add_unwired(Esc::new(cfg, common::sii(file)));
        if k > 0 {
            let from = if k == 1 { (0, 3) } else { (k - 1, 1) };
            // Unequal cable delays: 20, 130, 55, 310 ns.
            let delay = [0, 20, 130, 55, 310][k];
            seg.connect_with_delay(from.0, from.1, id, 0, delay)
                .expect("wiring");
        }
    }
    seg.set_link_delay(0, 0, 250).unwrap();
    seg
}

/// Sign-magnitude decode of 0x092C (bit 31: local copy is greater than received time).
fn sign_magnitude(v: u32) -> i64 {
    let mag = i64::from(v & 0x7FFF_FFFF);
    if v & 0x8000_0000 != 0 {
        -mag
    } else {
        mag
    }
}

#[test]
fn dc_converges_with_drift_and_unequal_delays() {
    let _ = env_logger::builder().is_test(true).try_init();
    let segment = Arc::new(Mutex::new(drifting_segment()));
    let (tx, rx, pdu_loop) = PDU_STORAGE.try_split().expect("split once");
    // A master spends some time between frames; 20 µs of virtual time per frame.
    let _transport = spawn_inprocess_with(
        segment.clone(),
        tx,
        rx,
        InProcessConfig {
            frame_gap_ns: 20_000,
        },
    )
    .expect("transport thread");
    let maindevice = MainDevice::new(
        pdu_loop,
        common::timeouts(),
        MainDeviceConfig {
            dc_static_sync_iterations: 10_000,
            ..MainDeviceConfig::default()
        },
    );
    let clock = segment.lock().unwrap().clock();

    let (diffs, n) = futures_lite::future::block_on(async {
        let mut group = maindevice
            .init_single_group::<16, 64>(move || clock.now())
            .await
            .expect("discovery + DC static sync");
        for mut sd in group.iter_mut(&maindevice) {
            sd.set_dc_sync(DcSync::Sync0);
        }
        let group = group
            .into_pre_op_pdi(&maindevice)
            .await
            .expect("PRE-OP with PDI");

        // Alignment loop: FRMW system time + PDI, one cycle of virtual time per iteration.
        for _ in 0..2000 {
            group
                .tx_rx_sync_system_time(&maindevice)
                .await
                .expect("sync system time");
            segment.lock().unwrap().advance_by(CYCLE_NS);
        }

        let group = group
            .configure_dc_sync(
                &maindevice,
                DcConfiguration {
                    start_delay: Duration::from_millis(10),
                    sync0_period: Duration::from_nanos(CYCLE_NS),
                    sync0_shift: Duration::ZERO,
                },
            )
            .await
            .expect("configure DC sync");
        let group = group.into_safe_op(&maindevice).await.expect("SAFE-OP");
        let group = group
            .request_into_op(&maindevice)
            .await
            .expect("request OP");

        let mut all_op = false;
        for _ in 0..1000 {
            let r = group.tx_rx_dc(&maindevice).await.expect("tx_rx_dc");
            all_op |= r.all_op();
            let wait = r.extra.next_cycle_wait.as_nanos() as u64;
            segment
                .lock()
                .unwrap()
                .advance_by(if wait == 0 { CYCLE_NS } else { wait });
        }
        assert!(all_op, "group reached OP");

        let mut diffs = Vec::new();
        for sd in group.iter(&maindevice) {
            let v = match sd
                .register_read::<u32>(RegisterAddress::DcSystemTimeDifference)
                .await
            {
                Ok(v) => v,
                Err(Error::WorkingCounter { .. }) => panic!("{} has no DC", sd.name()),
                Err(e) => panic!("reading 0x092C of {}: {e}", sd.name()),
            };
            diffs.push((sd.name().to_string(), sign_magnitude(v)));
        }
        (diffs, group.len())
    });

    eprintln!("0x092C after sync: {diffs:?}");
    assert_eq!(n, 5);
    for (name, d) in &diffs {
        assert!(
            d.abs() < 100,
            "{name}: system time difference {d} ns (all: {diffs:?})"
        );
    }

    // SYNC0 edges of all ESCs over a few cycles of virtual time, grouped by cycle.
    let mut seg = segment.lock().unwrap();
    seg.log_events(true);
    seg.advance_by(5 * CYCLE_NS);
    let edges: Vec<(usize, u64)> = seg
        .take_events()
        .into_iter()
        .filter(|e| e.event == EscEvent::Sync0)
        .map(|e| (e.slave, e.t))
        .collect();
    for s in 0..seg.len() {
        assert!(
            edges.iter().filter(|e| e.0 == s).count() >= 4,
            "ESC {s} produces SYNC0 every cycle: {edges:?}"
        );
    }
    let first = edges.iter().map(|e| e.1).min().expect("SYNC0 edges");
    for cycle in 0..4u64 {
        let lo = first + cycle * CYCLE_NS - CYCLE_NS / 2;
        let this: Vec<&(usize, u64)> = edges
            .iter()
            .filter(|e| e.1 >= lo && e.1 < lo + CYCLE_NS)
            .collect();
        assert_eq!(
            this.len(),
            seg.len(),
            "one edge per ESC in cycle {cycle}: {edges:?}"
        );
        let min = this.iter().map(|e| e.1).min().unwrap();
        let max = this.iter().map(|e| e.1).max().unwrap();
        eprintln!(
            "cycle {cycle}: SYNC0 edges {this:?}, spread {} ns",
            max - min
        );
        assert!(
            max - min < 100,
            "SYNC0 spread {} ns in cycle {cycle}: {this:?}",
            max - min
        );
    }
}
