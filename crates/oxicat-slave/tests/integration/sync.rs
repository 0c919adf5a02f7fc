use oxicat_slave::SyncMode;
use oxicat_testkit::device::*;
use oxicat_testkit::{Bench, Port};

fn sm_synchronous<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    b.download(0x1C32, 1, false, &1u16.to_le_bytes()).unwrap();
    b.config_pd();
    assert_eq!(b.request(4), (4, 0));
    assert_eq!(b.s.sync_mode(), SyncMode::SmSync);
    assert_eq!(b.request(8), (8, 0));
    let c0 = b.app.cycles;
    b.poll();
    assert_eq!(
        b.app.cycles, c0,
        "poll does not run the cycle in SM-sync mode"
    );
    b.wr(SM2, &[0, 5, 0, 0]);
    assert!(oxicat_slave::Pdi::irq_lines(&mut b.drv).pdi_irq);
    b.s.on_pdi_irq(&mut b.drv, &mut b.app).unwrap();
    assert_eq!(b.app.cycles, c0 + 1);
    assert_eq!(b.s.od().get::<i16>(0x7000, 2), Ok(5));
    // No new outputs: no cycle.
    b.s.on_pdi_irq(&mut b.drv, &mut b.app).unwrap();
    assert_eq!(b.app.cycles, c0 + 1);
    let (d, _) = b.rd(SM3, 7);
    assert_eq!(i16::from_le_bytes([d[1], d[2]]), 10);
}

fn activate_dc<P: Port>(b: &mut Bench<P>, cycle: u32, sync1: bool) {
    let (st, _) = b.rd(0x0910, 8);
    let now = u64::from_le_bytes(st.try_into().unwrap());
    b.wr(0x09A0, &cycle.to_le_bytes());
    b.wr(0x0990, &(now + 1_000_000).to_le_bytes());
    b.wr(0x0981, &[if sync1 { 0x07 } else { 0x03 }]);
}

fn dc_sync0<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    b.config_pd();
    activate_dc(&mut b, 200_000, false);
    assert_eq!(b.request(4), (4, 0));
    assert_eq!(b.s.sync_mode(), SyncMode::DcSync0);
    assert_eq!(b.upload(0x1C32, 1, false).unwrap(), 2u16.to_le_bytes());
    assert_eq!(
        b.upload(0x1C32, 2, false).unwrap(),
        200_000u32.to_le_bytes()
    );
    assert_eq!(b.request(8), (8, 0));
    let c0 = b.app.cycles;
    b.poll();
    assert_eq!(b.app.cycles, c0);
    for k in 0..20i16 {
        b.wr(SM2, &[0, k as u8, 0, 0]);
        b.advance(200_000);
    }
    assert!(b.app.cycles >= c0 + 15, "cycles {}", b.app.cycles - c0);
    assert_eq!(b.s.od().get::<i16>(0x7000, 2), Ok(19));
}

fn dc_cycle_too_small<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    b.config_pd();
    activate_dc(&mut b, 50_000, false);
    assert_eq!(b.request(4), (0x12, 0x002E));
}

fn dc_sync1_mode_needs_sync1<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    b.config_pd();
    b.download(0x1C32, 1, false, &3u16.to_le_bytes()).unwrap();
    activate_dc(&mut b, 200_000, false);
    assert_eq!(b.request(4), (0x12, 0x0030));
    activate_dc(&mut b, 200_000, true);
    assert_eq!(b.request(0x14), (4, 0));
    assert_eq!(b.s.sync_mode(), SyncMode::DcSync1);
}

fn up_u16<P: Port>(b: &mut Bench<P>, index: u16, sub: u8) -> u16 {
    let v = b.upload(index, sub, false).unwrap();
    u16::from_le_bytes([v[0], v[1]])
}

/// ETG.1020 diagnostics of 0x1C32/0x1C33 after a DC run in which the master skips cycles:
/// +3 per SYNC0 without new outputs, -1 per SYNC0 with, sync error while above 0x10F1:02.
fn dc_sm_event_missed_counter<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    assert_eq!(up_u16(&mut b, 0x10F1, 2), 4, "sync error counter limit");
    b.config_pd();
    activate_dc(&mut b, 200_000, false);
    assert_eq!(b.request(4), (4, 0));
    assert_eq!(b.request(8), (8, 0));
    // Definition values.
    assert_eq!(
        b.upload(0x1C32, 5, false).unwrap(),
        100_000u32.to_le_bytes()
    );
    assert_eq!(b.upload(0x1C32, 6, false).unwrap(), 10_000u32.to_le_bytes());
    assert_eq!(b.upload(0x1C33, 6, false).unwrap(), 10_000u32.to_le_bytes());
    let mut k = 0i16;
    let mut good = |b: &mut Bench<P>, n: usize| {
        for _ in 0..n {
            k += 1;
            let v = k.to_le_bytes();
            b.wr(SM2, &[0, v[0], v[1], 0]);
            b.advance(200_000);
        }
    };
    // Outputs every cycle: whatever the start-up missed has decayed.
    good(&mut b, 20);
    assert_eq!(up_u16(&mut b, 0x1C32, 0x0B), 0);
    assert_eq!(b.upload(0x1C32, 0x20, false).unwrap(), [0]);
    // The master skips one cycle.
    b.advance(200_000);
    assert_eq!(up_u16(&mut b, 0x1C32, 0x0B), 3);
    assert_eq!(up_u16(&mut b, 0x1C33, 0x0B), 3);
    assert_eq!(b.upload(0x1C32, 0x20, false).unwrap(), [0], "3 <= limit 4");
    good(&mut b, 1);
    assert_eq!(up_u16(&mut b, 0x1C32, 0x0B), 2);
    // Two skipped cycles in a row: 2 + 3 = 5 > 4 is a sync error; no increment beyond.
    b.advance(200_000);
    b.advance(200_000);
    assert_eq!(up_u16(&mut b, 0x1C32, 0x0B), 5);
    assert_eq!(b.upload(0x1C32, 0x20, false).unwrap(), [1]);
    assert_eq!(b.upload(0x1C33, 0x20, false).unwrap(), [1]);
    // Outputs again: the counter decays and the error clears.
    good(&mut b, 1);
    assert_eq!(up_u16(&mut b, 0x1C32, 0x0B), 4);
    assert_eq!(b.upload(0x1C32, 0x20, false).unwrap(), [0]);
    good(&mut b, 10);
    assert_eq!(up_u16(&mut b, 0x1C32, 0x0B), 0);
    // No output update arrived while a cycle ran.
    assert_eq!(up_u16(&mut b, 0x1C32, 0x0C), 0);
    assert_eq!(b.s.od().get::<i16>(0x7000, 2), Ok(k));
    // Re-entering SAFEOP starts the counters afresh.
    b.advance(200_000);
    assert_eq!(up_u16(&mut b, 0x1C32, 0x0B), 3);
    assert_eq!(b.request(2), (2, 0));
    b.config_pd();
    assert_eq!(b.request(4), (4, 0));
    assert_eq!(up_u16(&mut b, 0x1C32, 0x0B), 0);
}

/// DC SYNC1 (ETG.1020 DC SYNC1 mode, the Laelaps thesis' split): the outputs are mapped on
/// the SM2 event, the application runs on SYNC0, the inputs are written on SYNC1 only;
/// 0x1C33:03 shows the SYNC1 delay (the shift time of the input latch).
fn dc_sync1_split<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    b.config_pd();
    b.download(0x1C32, 1, false, &3u16.to_le_bytes()).unwrap();
    b.wr(0x09A4, &50_000u32.to_le_bytes());
    activate_dc(&mut b, 200_000, true);
    assert_eq!(b.request(4), (4, 0));
    assert_eq!(b.s.sync_mode(), SyncMode::DcSync1);
    assert_eq!(b.upload(0x1C33, 1, false).unwrap(), 3u16.to_le_bytes());
    assert_eq!(b.upload(0x1C33, 3, false).unwrap(), 50_000u32.to_le_bytes());
    assert_eq!(b.request(8), (8, 0));
    // The SM2 event maps the outputs at once; the application does not run.
    let c0 = b.app.cycles;
    b.wr(SM2, &[0, 7, 0, 0]);
    b.s.on_pdi_irq(&mut b.drv, &mut b.app).unwrap();
    assert_eq!(b.s.od().get::<i16>(0x7000, 2), Ok(7));
    assert_eq!(b.app.cycles, c0);
    // SYNC0: the application runs, the inputs are not written yet.
    let s0 = b.sync0;
    while b.sync0 == s0 {
        b.advance(10_000);
    }
    assert_eq!(b.app.cycles, c0 + 1);
    assert_eq!(b.s.od().get::<i16>(0x6000, 3), Ok(14));
    let (d, _) = b.rd(SM3, 7);
    assert_eq!(i16::from_le_bytes([d[1], d[2]]), 0, "inputs before SYNC1");
    // SYNC1, 50 µs later: the inputs.
    b.advance(60_000);
    assert_eq!(b.app.cycles, c0 + 1);
    let (d, _) = b.rd(SM3, 7);
    assert_eq!(i16::from_le_bytes([d[1], d[2]]), 14, "inputs at SYNC1");
    // Outputs taken by the interrupt count as seen: no SM event missed.
    for k in 0..5u8 {
        b.wr(SM2, &[0, k, 0, 0]);
        b.s.on_pdi_irq(&mut b.drv, &mut b.app).unwrap();
        b.advance(200_000);
    }
    assert_eq!(up_u16(&mut b, 0x1C32, 0x0B), 0);
}

oxicat_testkit::every_pdi!(
    sm_synchronous,
    dc_sync0,
    dc_cycle_too_small,
    dc_sync1_mode_needs_sync1,
    dc_sm_event_missed_counter,
    dc_sync1_split,
);
