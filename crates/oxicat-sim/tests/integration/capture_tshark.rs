//! A pcapng written during an ethercrab run is dissected by tshark with no malformed packet
//! and no expert error, and tshark sees EtherCAT in it.

use crate::segment_common;
use segment_common as common;

use std::process::Command;
use std::sync::{Arc, Mutex};

use ethercrab::{MainDevice, MainDeviceConfig, PduStorage};
use oxicat_master::inprocess::spawn_inprocess;
use oxicat_sim::capture::{Direction, MemoryCapture, PcapngCapture};
use oxicat_sim::segment::Segment;

static PDU_STORAGE: PduStorage<16, { PduStorage::element_size(1100) }> = PduStorage::new();

/// Whether tshark runs; with `CI` set a missing tshark is a failure.
fn have_tshark() -> bool {
    let ok = Command::new("tshark")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        assert!(
            std::env::var_os("CI").is_none(),
            "tshark is not installed (apt-get install -y tshark); required when CI is set"
        );
        eprintln!("SKIPPED: tshark is not installed (apt-get install -y tshark)");
    }
    ok
}

fn tshark(args: &[&str]) -> String {
    let out = Command::new("tshark")
        .args(args)
        .output()
        .expect("tshark runs");
    assert!(
        out.status.success(),
        "tshark {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn capture_of_an_ethercrab_run_is_valid_for_tshark() {
    if !have_tshark() {
        return;
    }
    let dir = std::env::temp_dir().join(format!("oxicat-sim-capture-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("run.pcapng");

    let mut seg = common::real_segment();
    seg.set_capture(Some(Box::new(
        PcapngCapture::create(&path).expect("create pcapng"),
    )));
    let segment: Arc<Mutex<Segment>> = Arc::new(Mutex::new(seg));
    let (tx, rx, pdu_loop) = PDU_STORAGE.try_split().expect("split once");
    let _transport = spawn_inprocess(segment.clone(), tx, rx).expect("transport thread");
    let maindevice = MainDevice::new(pdu_loop, common::timeouts(), MainDeviceConfig::default());
    let clock = segment.lock().unwrap().clock();
    futures_lite::future::block_on(async {
        let group = maindevice
            .init_single_group::<16, 64>(move || clock.now())
            .await
            .expect("discovery");
        let group = group.into_op(&maindevice).await.expect("OP");
        for _ in 0..5 {
            group.tx_rx(&maindevice).await.expect("cycle");
            segment.lock().unwrap().advance_by(1_000_000);
        }
    });
    // Take the sink out of the segment and flush it.
    let mut sink = segment
        .lock()
        .unwrap()
        .set_capture(None)
        .expect("a capture sink");
    sink.flush().expect("flush pcapng");
    drop(sink);

    let count = |filter: &str| -> usize {
        tshark(&["-r", path.to_str().unwrap(), "-Y", filter])
            .lines()
            .count()
    };
    let total = tshark(&["-r", path.to_str().unwrap()]).lines().count();
    assert!(total > 0, "capture has packets");
    assert_eq!(count("ecat"), total, "every packet is EtherCAT");
    let verbose = tshark(&["-r", path.to_str().unwrap(), "-V"]);
    assert!(
        !verbose.contains("[Malformed"),
        "malformed packet in capture"
    );
    assert!(
        !verbose.contains("Expert Info (Error"),
        "expert error in capture"
    );
    let expert = tshark(&["-r", path.to_str().unwrap(), "-q", "-z", "expert,error"]);
    assert!(
        !expert.lines().any(|l| l.trim_start().starts_with("Error")),
        "expert errors: {expert}"
    );
    // Both directions are there: replies carry the U/L bit in the source MAC.
    assert!(count("eth.src[0] & 0x02") > 0, "returned frames captured");
    assert!(count("!(eth.src[0] & 0x02)") > 0, "sent frames captured");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn memory_capture_records_both_directions_in_time_order() {
    let mut seg = common::real_segment();
    let mem = MemoryCapture::new();
    seg.set_capture(Some(Box::new(mem.clone())));
    // BRD of the ESC type register.
    let mut f = vec![0xFF; 6];
    f.extend_from_slice(&[0x10; 6]);
    f.extend_from_slice(&[
        0x88, 0xA4, 0x0E, 0x10, 7, 1, 0, 0, 0, 0, 2, 0, 0, 0, 0, 0, 0, 0,
    ]);
    f.resize(60, 0);
    let back = seg.exchange(&f).expect("frame returns");
    let frames = mem.frames();
    assert_eq!(frames.len(), 2);
    assert_eq!(frames[0].dir, Direction::ToSegment);
    assert_eq!(frames[1].dir, Direction::ToMaster);
    assert!(frames[1].t_ns > frames[0].t_ns);
    assert_eq!(frames[1].data, back);
    assert_eq!(back[6], 0x12);
    // WKC = number of ESCs.
    assert_eq!(u16::from_le_bytes([back[28], back[29]]), 6);
}
