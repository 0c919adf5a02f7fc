mod common;
use common::*;
use oxicat_slave::SyncMode;

#[test]
fn sm_synchronous() {
    let mut b = Bench::new();
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
    assert!(oxicat_slave::Pdi::irq_lines(&mut b.esc).pdi_irq);
    b.s.on_pdi_irq(&mut b.esc, &mut b.app).unwrap();
    assert_eq!(b.app.cycles, c0 + 1);
    assert_eq!(b.s.od().get::<i16>(0x7000, 2), Ok(5));
    // No new outputs: no cycle.
    b.s.on_pdi_irq(&mut b.esc, &mut b.app).unwrap();
    assert_eq!(b.app.cycles, c0 + 1);
    let (d, _) = b.rd(SM3, 7);
    assert_eq!(i16::from_le_bytes([d[1], d[2]]), 10);
}

fn activate_dc(b: &mut Bench, cycle: u32, sync1: bool) {
    let (st, _) = b.rd(0x0910, 8);
    let now = u64::from_le_bytes(st.try_into().unwrap());
    b.wr(0x09A0, &cycle.to_le_bytes());
    b.wr(0x0990, &(now + 1_000_000).to_le_bytes());
    b.wr(0x0981, &[if sync1 { 0x07 } else { 0x03 }]);
}

#[test]
fn dc_sync0() {
    let mut b = Bench::new();
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

#[test]
fn dc_cycle_too_small() {
    let mut b = Bench::new();
    b.enter_preop();
    b.config_pd();
    activate_dc(&mut b, 50_000, false);
    assert_eq!(b.request(4), (0x12, 0x002E));
}

#[test]
fn dc_sync1_mode_needs_sync1() {
    let mut b = Bench::new();
    b.enter_preop();
    b.config_pd();
    b.download(0x1C32, 1, false, &3u16.to_le_bytes()).unwrap();
    activate_dc(&mut b, 200_000, false);
    assert_eq!(b.request(4), (0x12, 0x0030));
    activate_dc(&mut b, 200_000, true);
    assert_eq!(b.request(0x14), (4, 0));
    assert_eq!(b.s.sync_mode(), SyncMode::DcSync1);
}
