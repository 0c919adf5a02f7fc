//! SM watchdog end to end with the demo device in free run: the master stops sending; within
//! the SM watchdog time (virtual) the outputs are safe and AL status is SAFEOP + error
//! 0x001B, inputs keep updating; the master acknowledges, returns the nodes to OP and process
//! data flows again.

use crate::stack_common;

use ethercrab::PduStorage;
use oxicat_sim::segment::Segment;
use stack_common::*;
use std::sync::{Arc, Mutex};

type Pdu = PduStorage<16, { PduStorage::element_size(1100) }>;

#[test]
fn watchdog_safe_outputs_safeop_0x001b_then_acknowledge_back_to_op() {
    static PDU: Pdu = PduStorage::new();
    watchdog(&PDU, demo_segment());
}

#[test]
fn lan9252_watchdog_safe_outputs_safeop_0x001b_then_acknowledge_back_to_op() {
    static PDU: Pdu = PduStorage::new();
    watchdog(&PDU, demo_segment_via(PdiRoute::lan9252(20)));
}

#[test]
fn et1100_watchdog_safe_outputs_safeop_0x001b_then_acknowledge_back_to_op() {
    static PDU: Pdu = PduStorage::new();
    watchdog(&PDU, demo_segment_via(PdiRoute::et1100(20)));
}

fn watchdog<P: PdiPath>(
    pdu: &'static Pdu,
    (segment, fws): (Arc<Mutex<Segment>>, Vec<DemoHandle<P>>),
) {
    let _ = env_logger::builder().is_test(true).try_init();
    let (md, _transport, clock) = start_master(pdu, &segment);
    let al = |i: usize| {
        let mut seg = segment.lock().unwrap();
        let esc = seg.esc_mut(i).unwrap();
        let mut b = [0u8; 6];
        esc.pdi_read(0x0130, &mut b).unwrap();
        (
            u16::from_le_bytes([b[0], b[1]]),
            u16::from_le_bytes([b[4], b[5]]),
        )
    };

    futures_lite::future::block_on(async {
        let group = md
            .init_single_group::<8, 256>(move || clock.now())
            .await
            .expect("discovery");
        let group = group.into_op(&md).await.expect("PRE-OP -> OP");

        let cycles = |from: u32, to: u32| {
            let group = &group;
            let md = &md;
            let segment = &segment;
            async move {
                for k in from..=to {
                    for (n, sd) in group.iter(md).enumerate() {
                        Outputs::pattern(k, n).pack(DEMO_RX, &mut sd.outputs_raw_mut());
                    }
                    segment.lock().unwrap().advance_by(CYCLE_NS);
                    let r = group.tx_rx(md).await.expect("tx/rx");
                    assert_eq!(r.working_counter, 3 * NODES as u16, "cycle {k}");
                    if k > from {
                        for (n, sd) in group.iter(md).enumerate() {
                            let mut got = sd.inputs_raw().to_vec();
                            got[DEMO_COUNTER_AT..DEMO_COUNTER_AT + 4].fill(0);
                            assert_eq!(got, demo_inputs(&Outputs::pattern(k - 1, n), n));
                        }
                    }
                }
            }
        };
        cycles(1, 50).await;
        segment.lock().unwrap().advance_by(CYCLE_NS);
        for fw in &fws {
            assert_eq!(fw.lock().slave.od().get::<i32>(0x7010, 1), Ok(50));
        }

        // The master stops. SM watchdog time from the ESC registers (0x0400 divider,
        // 0x0420 process-data watchdog time), in ns: (divider + 2) × 40 ns × time.
        let wd_ns = {
            let mut seg = segment.lock().unwrap();
            let esc = seg.esc_mut(0).unwrap();
            let mut b = [0u8; 2];
            esc.pdi_read(0x0400, &mut b).unwrap();
            let div = u16::from_le_bytes(b) as u64;
            esc.pdi_read(0x0420, &mut b).unwrap();
            (div + 2) * 40 * u16::from_le_bytes(b) as u64
        };
        assert!(wd_ns > 0);
        let stop = clock.now();
        let step = 1_000_000;
        while (0..NODES).any(|i| al(i) != (0x14, 0x001B)) {
            assert!(
                clock.now() - stop <= wd_ns + step,
                "SAFEOP + 0x001B within the watchdog time ({wd_ns} ns); now {:?}",
                (0..NODES).map(al).collect::<Vec<_>>()
            );
            segment.lock().unwrap().advance_by(step);
        }
        assert!(clock.now() - stop >= wd_ns, "not before the watchdog time");
        for (n, fw) in fws.iter().enumerate() {
            let f = fw.lock();
            let od = f.slave.od();
            assert_eq!(od.get::<i32>(0x7010, 1), Ok(0), "node {n}: safe outputs");
            assert_eq!(od.get::<i16>(0x7020, 1), Ok(0), "node {n}: safe outputs");
            assert_eq!(
                od.get::<bool>(0x7000, 5),
                Ok(false),
                "node {n}: blue LED off"
            );
        }
        // Inputs keep updating in SAFEOP.
        let before: Vec<u32> = fws.iter().map(|f| f.lock().app.inner.cycles).collect();
        segment.lock().unwrap().advance_by(step);
        for (n, fw) in fws.iter().enumerate() {
            assert!(fw.lock().app.inner.cycles > before[n], "node {n}");
        }

        // Acknowledge and request OP again.
        for sd in group.iter(&md) {
            sd.register_write(0x0120u16, 0x0018u16)
                .await
                .expect("AL control");
        }
        segment.lock().unwrap().advance_by(step);
        for i in 0..NODES {
            assert_eq!(al(i), (0x08, 0), "node {i} back in OP without error");
        }
        cycles(51, 150).await;
        segment.lock().unwrap().advance_by(CYCLE_NS);
        for fw in &fws {
            let f = fw.lock();
            assert_eq!(f.slave.od().get::<i32>(0x7010, 1), Ok(150));
            assert_eq!(f.app.gaps, 1, "the one gap: cycles 51.. after the stop");
        }
    });
}
