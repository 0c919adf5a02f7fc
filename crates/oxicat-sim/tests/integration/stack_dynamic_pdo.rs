//! Dynamic PDO assignment end to end: in PREOP ethercrab reassigns 0x1C12/0x1C13 by SDO
//! (fewer PDOs, other order); ethercrab sizes the process image from the new assignment,
//! the stack accepts the SM2/SM3 sizes, and the node runs with the new layout.

use crate::stack_common;

use ethercrab::PduStorage;
use oxicat_sim::segment::Segment;
use stack_common::*;
use std::sync::{Arc, Mutex};

const NEW_RX: &[u16] = &[0x1602, 0x1600];
const NEW_TX: &[u16] = &[0x1A02, 0x1A00];

/// What the firmware sees of `o` when only `NEW_RX` is mapped (the rest stays at its safe 0).
fn mapped(o: Outputs) -> Outputs {
    Outputs {
        o7010: 0,
        o7012: 0,
        o7014: 0,
        ..o
    }
}

type Pdu = PduStorage<16, { PduStorage::element_size(1100) }>;

#[test]
fn reassigned_pdos_in_preop_change_the_process_data_layout() {
    static PDU: Pdu = PduStorage::new();
    reassign(&PDU, flex_segment());
}

#[test]
fn lan9252_reassigned_pdos_in_preop_change_the_process_data_layout() {
    static PDU: Pdu = PduStorage::new();
    reassign(&PDU, flex_segment_via(PdiRoute::lan9252(20)));
}

#[test]
fn et1100_reassigned_pdos_in_preop_change_the_process_data_layout() {
    static PDU: Pdu = PduStorage::new();
    reassign(&PDU, flex_segment_via(PdiRoute::et1100(20)));
}

fn reassign<P: PdiPath>(pdu: &'static Pdu, (segment, fws): (Arc<Mutex<Segment>>, Vec<Fw<P>>)) {
    let _ = env_logger::builder().is_test(true).try_init();
    let (md, _transport, clock) = start_master(pdu, &segment);

    futures_lite::future::block_on(async {
        let group = md
            .init_single_group::<8, 256>(move || clock.now())
            .await
            .expect("discovery");
        for sd in group.iter(&md) {
            for (assign, pdos) in [(0x1C12u16, NEW_RX), (0x1C13, NEW_TX)] {
                sd.sdo_write(assign, 0, 0u8)
                    .await
                    .expect("clear assignment");
                for (i, &p) in pdos.iter().enumerate() {
                    sd.sdo_write(assign, i as u8 + 1, p)
                        .await
                        .expect("assign PDO");
                }
                sd.sdo_write(assign, 0, pdos.len() as u8)
                    .await
                    .expect("set count");
                assert_eq!(sd.sdo_read::<u16>(assign, 1).await.unwrap(), pdos[0]);
            }
        }
        let group = group.into_op(&md).await.expect("PRE-OP -> OP");
        for sd in group.iter(&md) {
            assert_eq!(sd.outputs_raw_mut().len(), 12 + 2, "0x1602 + 0x1600");
            assert_eq!(sd.inputs_raw().len(), 8 + 10, "0x1A02 + 0x1A00");
        }
        for fw in &fws {
            let f = fw.lock();
            assert_eq!((f.slave.output_bytes(), f.slave.input_bytes()), (14, 18));
        }
        let t0 = clock.now();
        for k in 1..=200u32 {
            for (n, sd) in group.iter(&md).enumerate() {
                Outputs::pattern(k, n).pack(NEW_RX, &mut sd.outputs_raw_mut());
            }
            segment.lock().unwrap().advance_to(t0 + k as u64 * CYCLE_NS);
            let r = group.tx_rx(&md).await.expect("tx/rx");
            assert_eq!(r.working_counter, 3 * NODES as u16, "cycle {k}");
            if k == 1 {
                continue;
            }
            for (n, sd) in group.iter(&md).enumerate() {
                let want = Inputs::derive(&mapped(Outputs::pattern(k - 1, n)), n).pack(NEW_TX);
                assert_eq!(&sd.inputs_raw()[..], &want[..], "node {n} cycle {k}");
            }
        }
    });
}
