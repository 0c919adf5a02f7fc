//! `oxicat sim` on a veth pair in a network namespace, and ethercrab (an independent master,
//! its std raw-socket transport) on the other end: discovery, identities from the SII the
//! simulator generated, INIT → OP, process data both ways. Needs root; skipped (with the
//! reason) elsewhere, mandatory in CI.

mod netns_common;

use std::time::Duration;

use ethercrab::PduStorage;
use netns_common::NetnsSim;

const MAX_SUBDEVICES: usize = 8;
const PDI_LEN: usize = 128;
static PDU_STORAGE: PduStorage<16, { PduStorage::element_size(1100) }> = PduStorage::new();

#[test]
fn raw_ethernet_discovery_to_op_through_veth() {
    let Some(bench) = NetnsSim::start(&["demo:2"]) else {
        return;
    };
    let md = netns_common::master_on(&bench, &PDU_STORAGE);
    futures_lite::future::block_on(async {
        let group = netns_common::discover::<MAX_SUBDEVICES, PDI_LEN>(
            &md,
            &bench,
            2,
            oxicat_devices::demo::VENDOR_ID,
        )
        .await;
        for sd in group.iter(&md) {
            let id = sd.identity();
            assert_eq!(
                id.product_id,
                oxicat_devices::demo::DEF.identity.product_code
            );
            assert_eq!(sd.name(), "EtherCAT_Application_SPI");
        }
        let group = group.into_op(&md).await.expect("PRE-OP -> OP");
        for sd in group.iter(&md) {
            assert_eq!(
                sd.status().await.expect("AL status").0,
                ethercrab::SubDeviceState::Op
            );
        }
        // The demo application copies OutINT32Var1 (output bytes 2..6, after the buttons
        // PDO) to InINT32Var1 (input bytes 0..4).
        let mut matched = 0;
        for k in 1..=500i32 {
            for (n, sd) in group.iter(&md).enumerate() {
                let v = k * 16 + n as i32;
                sd.outputs_raw_mut()[2..6].copy_from_slice(&v.to_le_bytes());
            }
            let r = group.tx_rx(&md).await.expect("tx/rx");
            assert_eq!(r.working_counter, 3 * 2, "cycle {k}: LRW working counter");
            if k > 1 {
                for (n, sd) in group.iter(&md).enumerate() {
                    let i = sd.inputs_raw();
                    let got = i32::from_le_bytes([i[0], i[1], i[2], i[3]]);
                    if got == (k - 1) * 16 + n as i32 || got == k * 16 + n as i32 {
                        matched += 1;
                    }
                }
            }
            if matched >= 20 {
                break;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        assert!(matched >= 20, "inputs follow outputs through the firmware");
        let group = group.into_safe_op(&md).await.expect("OP -> SAFE-OP");
        let group = group.into_pre_op(&md).await.expect("SAFE-OP -> PRE-OP");
        let group = group.into_init(&md).await.expect("PRE-OP -> INIT");
        assert_eq!(group.len(), 2);
    });
    assert!(
        bench
            .sim_log()
            .iter()
            .any(|l| l.contains("serving 2 slaves")),
        "{:?}",
        bench.sim_log()
    );
}

/// Without CAP_NET_RAW, `oxicat sim --iface` says so (checked by dropping root's
/// privileges with `setpriv`; needs root to do that).
#[test]
fn no_permission_names_cap_net_raw() {
    let Some(bench) = NetnsSim::bare() else {
        return;
    };
    let out = std::process::Command::new("ip")
        .args(["netns", "exec", bench.netns(), "setpriv"])
        .args(["--reuid", "65534", "--regid", "65534", "--clear-groups"])
        .args(["--inh-caps=-all", "--bounding-set=-all"])
        .arg(netns_common::oxicat_bin())
        .args(["sim", "--iface", bench.sim_if(), "demo:1"])
        .output()
        .expect("run setpriv");
    let err = String::from_utf8_lossy(&out.stderr);
    if err.contains("setpriv") && !err.contains("oxicat") {
        eprintln!("skipped: setpriv could not drop privileges here: {err}");
        return;
    }
    assert!(!out.status.success());
    assert!(err.contains("CAP_NET_RAW"), "{err}");
}
