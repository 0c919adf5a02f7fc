//! The segment as the next master session finds it: one in-process segment of demo nodes,
//! several `Master` sessions one after the other (as `oxicat` invocations would be).
//! Opening a master does not reset the slaves; `states` leaves them where it put them; a
//! free-run verb after a DC recording resets the sync mode it needs.

mod common;

use std::time::Duration;

use oxicat_master::cyclic::CycleOptions;
use oxicat_master::{AlState, Link, Master};

fn session(seg: &std::sync::Arc<std::sync::Mutex<oxicat_sim::segment::Segment>>) -> Master {
    Master::open(Link::Sim(seg.clone())).expect("master opens")
}

fn states(m: &Master) -> Vec<Option<AlState>> {
    m.scan()
        .unwrap()
        .iter()
        .map(|s| {
            assert!(!s.status.error(), "{s:?}");
            s.status.state()
        })
        .collect()
}

#[test]
fn states_op_then_slaves_in_a_new_session_shows_op() {
    let (seg, _fws, _) = common::demo_segment(2);
    let first = session(&seg);
    // A fresh segment (no station addresses yet) is brought to PRE-OP by the first scan.
    assert_eq!(states(&first), vec![Some(AlState::PreOp); 2]);
    let addresses: Vec<u16> = (0..2).map(|p| first.address(p).unwrap()).collect();
    drop(first);

    let mut m = session(&seg);
    let r = m.request_state(&[0, 1], AlState::Op).unwrap();
    assert!(
        r.iter().all(|(_, s)| s.state() == Some(AlState::Op)),
        "{r:?}"
    );
    drop(m);

    // Time passes without a cyclic master (longer than the default SM watchdog of 100 ms).
    {
        let mut s = seg.lock().unwrap();
        let t = s.now() + 1_000_000_000;
        s.advance_to(t);
    }
    let m = session(&seg);
    assert_eq!(states(&m), vec![Some(AlState::Op); 2]);
    // Inspection verbs leave them there.
    assert_eq!(
        (0..2).map(|p| m.address(p).unwrap()).collect::<Vec<_>>(),
        addresses
    );
    let v = m.sdo_upload(0, 0x1018, 1).unwrap();
    assert_eq!(
        u32::from_le_bytes([v[0], v[1], v[2], v[3]]),
        oxicat_devices::demo::DEF.identity.vendor_id
    );
    m.sii_read(1, false).unwrap();
    m.reg_read(1, 0x0130, 2).unwrap();
    m.pdos(0).unwrap();
    drop(m);
    let mut m = session(&seg);
    assert_eq!(states(&m), vec![Some(AlState::Op); 2]);

    // INIT sticks too (the slaves have addresses: no new bring-up to PRE-OP).
    m.request_state(&[1], AlState::Init).unwrap();
    drop(m);
    let mut m = session(&seg);
    assert_eq!(states(&m), vec![Some(AlState::Op), Some(AlState::Init)]);
    // A mailbox verb on a slave in INIT says why it cannot.
    let e = m.sdo_upload(1, 0x1018, 1).unwrap_err().to_string();
    assert!(e.contains("INIT") && e.contains("PREOP"), "{e}");
    // And back up from INIT: mailbox from the SII, then process data.
    m.request_state(&[1], AlState::Op).unwrap();
    drop(m);
    assert_eq!(states(&session(&seg)), vec![Some(AlState::Op); 2]);
}

#[test]
fn free_run_after_a_dc_recording_resets_the_sync_mode() {
    // ethercrab's futures and the state walk after cycling need more than a test
    // thread's stack in debug builds.
    std::thread::Builder::new()
        .stack_size(64 << 20)
        .spawn(free_run_after_a_dc_recording_resets_the_sync_mode_body)
        .unwrap()
        .join()
        .unwrap_or_else(|e| std::panic::resume_unwind(e));
}

fn free_run_after_a_dc_recording_resets_the_sync_mode_body() {
    let (seg, _fws, _) = common::demo_segment(2);
    let mut m = session(&seg);
    let layouts = m.layouts().unwrap();
    let vars: Vec<_> = m
        .resolve(&["0.InINT32Var1".into()], &layouts)
        .unwrap()
        .into_iter()
        .flatten()
        .collect();
    let dc = CycleOptions {
        cycle: Duration::from_micros(400),
        dc: true,
    };
    let stats = m
        .record(dc, &vars, 20, &mut Vec::new(), &mut |_, _| {})
        .unwrap();
    assert_eq!(stats.cycles, 20);
    drop(m);
    let m = session(&seg);
    assert_eq!(
        m.sdo_upload(0, 0x1C32, 1).unwrap(),
        2u16.to_le_bytes(),
        "DC SYNC0 after record"
    );
    drop(m);

    // `watch` (free run) in a new session reaches OP and cycles.
    let mut m = session(&seg);
    let mut lines = Vec::new();
    m.watch(CycleOptions::default(), &vars, 5, 2, &mut |l| {
        lines.push(l.to_string());
        true
    })
    .unwrap();
    assert_eq!(lines.len(), 2);
    drop(m);

    // Record again, then `states op` (free run, its own configuration) reaches OP too.
    let mut m = session(&seg);
    m.record(dc, &vars, 10, &mut Vec::new(), &mut |_, _| {})
        .unwrap();
    drop(m);
    // Nobody cycles any more: the record took the slaves back to PRE-OP, so no SM watchdog
    // sets an error; the DC sync mode stays.
    {
        let mut s = seg.lock().unwrap();
        let t = s.now() + 1_000_000_000;
        s.advance_to(t);
    }
    let m = session(&seg);
    for s in m.scan().unwrap() {
        assert_eq!(s.status.state(), Some(AlState::PreOp), "{s:?}");
        assert!(!s.status.error(), "{s:?}");
        assert_eq!(m.sync_mode(s.position).unwrap(), Some(2));
    }
    drop(m);
    let mut m = session(&seg);
    let r = m.request_state(&[0, 1], AlState::Op).unwrap();
    assert!(
        r.iter().all(|(_, s)| s.state() == Some(AlState::Op)),
        "{r:?}"
    );
    for p in 0..2 {
        assert_eq!(m.sync_mode(p).unwrap(), Some(0), "free run");
    }
}
