//! The slave stack with each driver as its `Pdi`, over the simulated SPI chips: ESM to
//! OP, SDO upload/download (expedited and segmented), process data in free run, and the
//! Laelaps leg's DC cycle.

mod common;

use common::device::*;
use common::*;

fn esm_sdo_pd<C: Chip>() {
    let mut b = Bench::<C, App, IMG>::new();
    assert_eq!(b.al_status(), (1, 0), "{}", C::NAME);
    b.config_mailbox(&DEF);
    assert_eq!(b.request(2), (2, 0));
    // SDO: expedited upload/download, range check, segmented 1100-byte blob.
    assert_eq!(b.upload(0x2000, 0), Ok(7u32.to_le_bytes().to_vec()));
    assert_eq!(b.download(0x2000, 0, &500u32.to_le_bytes()), Ok(()));
    assert_eq!(b.upload(0x2000, 0), Ok(500u32.to_le_bytes().to_vec()));
    assert_eq!(
        b.download(0x2000, 0, &5000u32.to_le_bytes()),
        Err(0x0609_0031)
    );
    let blob: Vec<u8> = (0..1100u32).map(|i| (i * 7 + 3) as u8).collect();
    assert_eq!(b.download(0x2001, 0, &blob), Ok(()));
    assert_eq!(b.upload(0x2001, 0), Ok(blob));
    assert_eq!(b.upload(0x2006, 0), Ok(b"hello".to_vec()));
    assert!(b.app.written.contains(&(0x2000, 0)));
    // Process data: 4 output bytes, 7 input bytes.
    b.config_sm(2, SM2, 4, 0x64);
    b.config_sm(3, SM3, 7, 0x20);
    assert_eq!(b.request(4), (4, 0));
    assert_eq!(b.request(8), (8, 0), "{}", C::NAME);
    for k in 1..=20i16 {
        // LED on, Setpoint k*100, Mode 3.
        let sp = (k * 100).to_le_bytes();
        assert_eq!(b.wr(SM2, &[1, sp[0], sp[1], 3]), 1);
        b.poll();
        let (inp, wkc) = b.rd(SM3, 7);
        assert_eq!(wkc, 1);
        assert_eq!(inp[0] & 0x02, 0x02, "Button 2 mirrors the LED");
        assert_eq!(i16::from_le_bytes([inp[1], inp[2]]), k * 200);
        assert!(u32::from_le_bytes(inp[3..7].try_into().unwrap()) > 0);
    }
    assert!(b.app.cycles >= 20);
    // Back down.
    assert_eq!(b.request(2), (2, 0));
    assert_eq!(b.request(1), (1, 0));
    assert_eq!(b.h.stats().protocol_errors, 0, "{}", C::NAME);
}

#[test]
fn lan9252_esm_sdo_pd() {
    esm_sdo_pd::<Lan>();
}
#[test]
fn lan9252_fast_read_esm_sdo_pd() {
    esm_sdo_pd::<LanFast>();
}
#[test]
fn et1100_two_byte_esm_sdo_pd() {
    esm_sdo_pd::<Et2>();
}
#[test]
fn et1100_three_byte_esm_sdo_pd() {
    esm_sdo_pd::<Et3>();
}
#[test]
fn et1100_read_pause_esm_sdo_pd() {
    esm_sdo_pd::<EtDelay>();
}

use common::laelaps;

#[test]
fn lan9252_laelaps_dc_cycle() {
    laelaps::dc_cycle::<Lan>();
}
#[test]
fn et1100_laelaps_dc_cycle() {
    laelaps::dc_cycle::<Et2>();
}
#[test]
fn et1100_three_byte_laelaps_dc_cycle() {
    laelaps::dc_cycle::<Et3>();
}

/// SPI traffic of one Laelaps DC cycle (SYNC0 handler) through each driver: counts of
/// transactions and bytes (the bus time follows from them and the SCLK; see
/// examples/bus_time.rs).
fn cycle_traffic<C: Chip>() -> (u64, u64) {
    use oxicat_devices::laelaps::device::{self, OUTPUT_BYTES};
    use oxicat_devices::laelaps::hw::JOINT_LOOP_TIMER;
    use oxicat_devices::laelaps::kinematics::Side;
    use oxicat_esc::EscConfig;
    use oxicat_pdi::sim::BusConfig;
    let def = device::device(Side::Right);
    let mut b = laelaps::leg_to_op::<C>(EscConfig::et1100(), BusConfig::mhz(20), 400_000);
    let out = [0u8; OUTPUT_BYTES];
    for _ in 0..5 {
        b.advance(400_000, 1, Some(JOINT_LOOP_TIMER));
        b.wr(def.sm2_start, &out);
    }
    b.h.reset_stats();
    let s0 = b.sync0;
    while b.sync0 == s0 {
        b.advance(100_000, 1, Some(JOINT_LOOP_TIMER));
    }
    assert_eq!(b.sync0, s0 + 1);
    let s = b.h.stats();
    assert_eq!(s.protocol_errors, 0);
    (s.transactions, s.bytes)
}

#[test]
fn laelaps_cycle_traffic_per_driver() {
    // SYNC0 status (CSR: command, poll, data = 3 x 7 B), AL event (3 x 7 B), outputs
    // (PRAM start 11 B, poll 7 B, FIFO bursts 3 + 32 and 3 + 8 B), inputs (11 + 7 + 3 +
    // 24 B), AL event.
    assert_eq!(cycle_traffic::<Lan>(), (16, 172));
    // SYNC0 status read (2 + 1 + 1 B), NOP (3 B), outputs (2 + 1 + 38 B), inputs
    // (2 + 22 B), NOP (3 B).
    assert_eq!(cycle_traffic::<Et2>(), (5, 75));
    assert_eq!(cycle_traffic::<Et3>(), (5, 78));
}

/// SM-synchronous mode driven by the chip's IRQ pin as the MCU sees it (polarity as
/// configured), the cycle run from `on_pdi_irq`.
fn sm_sync_on_irq_pin<C: Chip>() {
    use oxicat_slave::{Pdi, SyncMode};
    let mut b = Bench::<C, App, IMG>::new();
    b.config_mailbox(&DEF);
    assert_eq!(b.request(2), (2, 0));
    assert_eq!(b.download(0x1C32, 1, &1u16.to_le_bytes()), Ok(()));
    b.config_sm(2, SM2, 4, 0x64);
    b.config_sm(3, SM3, 7, 0x20);
    assert_eq!(b.request(4), (4, 0));
    assert_eq!(b.s.sync_mode(), SyncMode::SmSync);
    assert_eq!(b.request(8), (8, 0));
    let c0 = b.app.cycles;
    for k in 1..=10u8 {
        assert!(!b.drv.irq_lines().pdi_irq, "{}", C::NAME);
        b.wr(SM2, &[0, k, 0, 0]);
        assert!(b.drv.irq_lines().pdi_irq, "{}", C::NAME);
        b.s.on_pdi_irq(&mut b.drv, &mut b.app).unwrap();
        assert_eq!(b.app.cycles, c0 + k as u32);
        let (d, _) = b.rd(SM3, 7);
        assert_eq!(i16::from_le_bytes([d[1], d[2]]), 2 * k as i16);
    }
    assert_eq!(b.h.stats().protocol_errors, 0);
}

#[test]
fn sm_sync_on_irq_pin_every_driver() {
    sm_sync_on_irq_pin::<Lan>();
    sm_sync_on_irq_pin::<LanFast>();
    sm_sync_on_irq_pin::<Et2>();
    sm_sync_on_irq_pin::<Et3>();
    sm_sync_on_irq_pin::<EtDelay>();
}
