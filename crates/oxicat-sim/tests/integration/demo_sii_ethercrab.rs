//! ethercrab parses the SII that `oxicat-esi` generates from the demo device's one
//! definition (`oxicat_esi::sii::generate(&demo::DEF)`): it names and identifies the node from
//! it, takes the mailbox and process-data SyncManagers and the FMMU usage from it, and the
//! firmware (the `oxicat-slave` stack with the `Demo` application) accepts what ethercrab
//! configures into the ESC on PRE-OP -> SAFE-OP. Checked on the ESC's registers.
//!
//! Two runs:
//! - the SII as generated (CoE in the mailbox protocols): ethercrab sizes SM2/SM3 from the
//!   PDO assignment it uploads over CoE, everything else comes from the SII;
//! - the same SII with only the CoE bit of the mailbox protocols word cleared: ethercrab then
//!   sizes SM2/SM3 from the SII's RxPDO/TxPDO categories (entries, bit lengths, SM index),
//!   so the PDO categories themselves are what gives 24 output and 22 input bytes.

use crate::stack_common;

use std::sync::{Arc, Mutex};

use ethercrab::PduStorage;
use oxicat_devices::demo;
use oxicat_esc::{Esc, EscConfig};
use oxicat_sim::firmware::{attach_firmware, FirmwareConfig};
use oxicat_sim::segment::Segment;
use oxicat_slave::AlState;
use stack_common::*;

type Pdu = PduStorage<8, { PduStorage::element_size(1100) }>;

/// One SyncManager as ethercrab configured it: start, length, control byte, enabled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Sm(u16, u16, u8, bool);

/// One enabled FMMU: logical start, length, physical start, type (1 read, 2 write).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Fmmu {
    logical: u32,
    len: u16,
    physical: u16,
    kind: u8,
}

/// What the test saw: from ethercrab's API and from the ESC registers after SAFE-OP.
#[derive(Debug)]
struct Seen {
    name: String,
    description: Option<String>,
    identity: (u32, u32, u32, u32),
    sms: Vec<Sm>,
    fmmus: Vec<Fmmu>,
    inputs: usize,
    outputs: usize,
    fw_state: AlState,
    fw_out: usize,
    fw_in: usize,
}

fn run(sii: Vec<u8>, pdu: &'static Pdu) -> Seen {
    let _ = env_logger::builder().is_test(true).try_init();
    let mut seg = Segment::new();
    let id = seg.add(Esc::new(EscConfig::et1100(), sii));
    let app = Probe {
        inner: demo::Demo::new(NoLeds, FixedButtons(0x5A)),
        seen: 0,
        gaps: 0,
        last: 0,
    };
    let fw = attach_firmware::<_, DEMO_IMG, MBX>(
        &mut seg,
        id,
        &demo::DEF,
        app,
        &FirmwareConfig::default(),
    )
    .expect("firmware boots");
    let segment = Arc::new(Mutex::new(seg));
    let (md, _transport, clock) = start_master(pdu, &segment);

    futures_lite::future::block_on(async {
        let group = md
            .init_single_group::<4, 256>(move || clock.now())
            .await
            .expect("discovery");
        assert_eq!(group.len(), 1);
        let (name, description, identity) = {
            let sd = group.iter(&md).next().expect("one node");
            let i = sd.identity();
            (
                sd.name().to_string(),
                sd.description()
                    .await
                    .expect("description")
                    .map(|s| s.to_string()),
                (i.vendor_id, i.product_id, i.revision, i.serial),
            )
        };
        let group = group.into_safe_op(&md).await.expect("PRE-OP -> SAFE-OP");
        let sd = group.iter(&md).next().expect("one node");
        let mut sms = Vec::new();
        for n in 0..4u16 {
            let r: [u8; 8] = sd.register_read(0x0800 + 8 * n).await.expect("SM");
            sms.push(Sm(
                u16::from_le_bytes([r[0], r[1]]),
                u16::from_le_bytes([r[2], r[3]]),
                r[4],
                r[6] & 1 != 0,
            ));
        }
        let mut fmmus = Vec::new();
        for n in 0..8u16 {
            let r: [u8; 16] = sd.register_read(0x0600 + 16 * n).await.expect("FMMU");
            if r[12] & 1 != 0 {
                fmmus.push(Fmmu {
                    logical: u32::from_le_bytes([r[0], r[1], r[2], r[3]]),
                    len: u16::from_le_bytes([r[4], r[5]]),
                    physical: u16::from_le_bytes([r[8], r[9]]),
                    kind: r[11],
                });
            }
        }
        let (inputs, outputs) = (sd.inputs_raw().len(), sd.outputs_raw().len());
        let f = fw.lock();
        Seen {
            name,
            description,
            identity,
            sms,
            fmmus,
            inputs,
            outputs,
            fw_state: f.slave.state(),
            fw_out: f.slave.output_bytes(),
            fw_in: f.slave.input_bytes(),
        }
    })
}

/// The checks common to both runs.
fn check(s: &Seen) {
    let d = &demo::DEF;
    // Name (ethercrab: the order string), device name string, identity.
    assert_eq!(s.name, d.info().order_code);
    assert_eq!(s.name, "EtherCAT_Application_SPI");
    assert_eq!(s.description.as_deref(), Some(d.name));
    assert_eq!(
        s.identity,
        (
            d.identity.vendor_id,
            d.identity.product_code,
            d.identity.revision,
            d.identity.serial
        )
    );
    // SyncManagers as the SII's SM category defines them, SM2/SM3 sized for the mapping.
    let c = d.info().sm_control;
    assert_eq!(
        s.sms,
        vec![
            Sm(d.mailbox.rx_start, d.mailbox.rx_len, c.mbx_out, true),
            Sm(d.mailbox.tx_start, d.mailbox.tx_len, c.mbx_in, true),
            Sm(d.sm2_start, 24, c.outputs, true),
            Sm(d.sm3_start, 22, c.inputs, true),
        ]
    );
    assert_eq!(
        (d.default_output_bits(), d.default_input_bits()),
        (192, 176)
    );
    // FMMUs: one writing the 24 output bytes into SM2, one reading the 22 input bytes
    // from SM3, at distinct logical addresses.
    let out = s.fmmus.iter().find(|f| f.physical == d.sm2_start);
    let inp = s.fmmus.iter().find(|f| f.physical == d.sm3_start);
    let (out, inp) = (out.expect("output FMMU"), inp.expect("input FMMU"));
    assert_eq!((out.len, out.kind), (24, 2), "{out:?}");
    assert_eq!((inp.len, inp.kind), (22, 1), "{inp:?}");
    assert_ne!(out.logical, inp.logical);
    assert_eq!(s.fmmus.len(), 2, "{:?}", s.fmmus);
    // ethercrab's process image and the firmware agree.
    assert_eq!((s.outputs, s.inputs), (24, 22));
    assert_eq!(s.fw_state, AlState::SafeOp);
    assert_eq!((s.fw_out, s.fw_in), (24, 22));
}

#[test]
fn ethercrab_reads_generated_sii_coe() {
    static PDU: Pdu = PduStorage::new();
    let sii = oxicat_esi::sii::generate(&demo::DEF).expect("demo SII");
    let s = run(sii, &PDU);
    check(&s);
    // FMMU usage from the SII's FMMU category: outputs, then inputs.
    assert!(s.fmmus[0].physical == demo::DEF.sm2_start, "{:?}", s.fmmus);
}

#[test]
fn ethercrab_reads_generated_sii_pdo_categories() {
    static PDU: Pdu = PduStorage::new();
    let mut sii = oxicat_esi::sii::generate(&demo::DEF).expect("demo SII");
    // Mailbox protocols (word 0x1C, outside the CRC'd configuration area): drop CoE, so
    // ethercrab sizes the process data from the SII's RxPDO/TxPDO categories.
    let w = u16::from_le_bytes([sii[0x38], sii[0x39]]);
    assert_ne!(w & 0x0004, 0, "the generated SII announces CoE");
    sii[0x38..0x3A].copy_from_slice(&(w & !0x0004).to_le_bytes());
    let s = run(sii, &PDU);
    check(&s);
}
