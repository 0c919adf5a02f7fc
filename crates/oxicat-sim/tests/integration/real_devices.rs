//! Real Beckhoff devices emulated from their SII EEPROMs, driven by ethercrab through the
//! in-process transport: discovery (names, identities), OP, outputs and inputs.

use crate::segment_common;
use segment_common as common;

use std::sync::{Arc, Mutex};

use ethercrab::{MainDevice, MainDeviceConfig, PduStorage};
use oxicat_master::inprocess::spawn_inprocess;
use oxicat_sim::segment::Segment;

const MAX_SUBDEVICES: usize = 16;
const PDI_LEN: usize = 64;
static PDU_STORAGE: PduStorage<16, { PduStorage::element_size(1100) }> = PduStorage::new();

#[test]
fn real_devices_discovered_brought_to_op_and_exchange_process_data() {
    let _ = env_logger::builder().is_test(true).try_init();
    let segment: Arc<Mutex<Segment>> = Arc::new(Mutex::new(common::real_segment()));
    let (tx, rx, pdu_loop) = PDU_STORAGE.try_split().expect("split once");
    let _transport = spawn_inprocess(segment.clone(), tx, rx).expect("transport thread");
    let maindevice = MainDevice::new(pdu_loop, common::timeouts(), MainDeviceConfig::default());
    let clock = segment.lock().unwrap().clock();

    futures_lite::future::block_on(async {
        let group = maindevice
            .init_single_group::<MAX_SUBDEVICES, PDI_LEN>(move || clock.now())
            .await
            .expect("discovery");

        let found: Vec<(String, u32, u32)> = group
            .iter(&maindevice)
            .map(|s| {
                let id = s.identity();
                (s.name().to_string(), id.vendor_id, id.product_id)
            })
            .collect();
        let mut expected: Vec<(String, u32, u32)> = common::DEVICES
            .iter()
            .map(|(n, _, p)| (n.to_string(), 2, *p))
            .collect();
        expected.push(("EL1004".to_string(), 2, 0x03EC_3052));
        assert_eq!(found, expected, "names and identities from the SII");

        let group = group.into_op(&maindevice).await.expect("PRE-OP -> OP");

        // Every ESC's AL status follows AL control (device emulation) into OP.
        {
            let seg = segment.lock().unwrap();
            for i in 0..seg.len() {
                assert_eq!(seg.esc(i).unwrap().al_status() & 0x0F, 8, "ESC {i} in OP");
            }
        }

        // (One PDI guard at a time: ethercrab's PDI lock is not re-entrant.)
        let sizes: Vec<(usize, usize)> = group
            .iter(&maindevice)
            .map(|s| {
                let i = s.inputs_raw().len();
                let o = s.outputs_raw_mut().len();
                (i, o)
            })
            .collect();
        // EK1100: none; EL2004: 4 bits; EL2828: 8 bits; EL2889: 16 bits; EL2262: outputs;
        // EL1004: 4 bits of inputs.
        assert_eq!(sizes[0], (0, 0));
        assert_eq!(sizes[1].1, 1);
        assert_eq!(sizes[2].1, 1);
        assert_eq!(sizes[3].1, 2);
        assert_eq!(sizes[5], (1, 0));

        // Outputs written through ethercrab's process image land in the emulated ESCs.
        for s in group.iter(&maindevice) {
            let mut o = s.outputs_raw_mut();
            match s.name() {
                "EL2004" => o[0] = 0x0A,
                "EL2828" => o[0] = 0xA5,
                "EL2889" => {
                    o[0] = 0x34;
                    o[1] = 0x12;
                }
                _ => {}
            }
        }
        // Inputs set on the PDI side of the EL1004.
        segment
            .lock()
            .unwrap()
            .esc_mut(5)
            .unwrap()
            .set_digital_inputs(0x0000_0006);
        for _ in 0..4 {
            group.tx_rx(&maindevice).await.expect("cycle");
            segment.lock().unwrap().advance_by(1_000_000);
        }
        {
            let seg = segment.lock().unwrap();
            assert_eq!(
                seg.esc(1).unwrap().digital_outputs() & 0x0F,
                0x0A,
                "EL2004 outputs"
            );
            assert_eq!(
                seg.esc(2).unwrap().digital_outputs() & 0xFF,
                0xA5,
                "EL2828 outputs"
            );
            assert_eq!(
                seg.esc(3).unwrap().digital_outputs() & 0xFFFF,
                0x1234,
                "EL2889 outputs"
            );
        }
        let el1004 = group.subdevice(&maindevice, 5).expect("EL1004");
        assert_eq!(
            el1004.inputs_raw()[0] & 0x0F,
            0x06,
            "EL1004 inputs reach the master"
        );

        // Change outputs and inputs again: values follow, not just the first ones.
        group.subdevice(&maindevice, 1).unwrap().outputs_raw_mut()[0] = 0x05;
        segment
            .lock()
            .unwrap()
            .esc_mut(5)
            .unwrap()
            .set_digital_inputs(0x9);
        for _ in 0..2 {
            group.tx_rx(&maindevice).await.expect("cycle");
        }
        assert_eq!(
            segment.lock().unwrap().esc(1).unwrap().digital_outputs() & 0x0F,
            0x05
        );
        let el1004 = group.subdevice(&maindevice, 5).expect("EL1004");
        assert_eq!(el1004.inputs_raw()[0] & 0x0F, 0x09);
    });
}
