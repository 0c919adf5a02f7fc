//! Driver-specific stack tests over the simulated SPI chips: the SPI traffic of one
//! Laelaps DC cycle per driver, and SM-synchronous mode run from the IRQ pin.
//!
//! The slave stack's whole test suite (ESM, mailbox, SDO, SDO info, FoE, sync modes) and
//! the Laelaps leg's DC test run through every driver too: see `oxicat-testkit`'s
//! `every_pdi!` in `oxicat-slave/tests` and `oxicat-devices/tests`.

use oxicat_testkit::device::*;
use oxicat_testkit::laelaps;
use oxicat_testkit::ports::{Et2, Et3, EtPause, Lan, LanFast};
use oxicat_testkit::{Bench, Port};

/// SPI traffic of one Laelaps DC cycle (SYNC0 handler) through each driver: counts of
/// transactions and bytes (the bus time follows from them and the SCLK; see
/// examples/bus_time.rs).
fn cycle_traffic<P: Port>() -> (u64, u64) {
    use oxicat_devices::laelaps::device::{self, OUTPUT_BYTES};
    use oxicat_devices::laelaps::hw::JOINT_LOOP_TIMER;
    use oxicat_devices::laelaps::kinematics::Side;
    use oxicat_pdi::sim::BusConfig;
    let def = device::device(Side::Right);
    let mut b = laelaps::leg_to_op::<P>(Side::Right, BusConfig::mhz(20), 400_000);
    let out = [0u8; OUTPUT_BYTES];
    for _ in 0..5 {
        b.advance_steps(400_000, 1, Some(JOINT_LOOP_TIMER));
        b.wr(def.sm2_start, &out);
    }
    b.port.reset_bus_stats();
    let s0 = b.sync0;
    while b.sync0 == s0 {
        b.advance_steps(100_000, 1, Some(JOINT_LOOP_TIMER));
    }
    assert_eq!(b.sync0, s0 + 1);
    let s = b.bus_stats().unwrap();
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
fn sm_sync_on_irq_pin<P: Port>() {
    use oxicat_slave::{Pdi, SyncMode};
    let mut b = Bench::<P>::new();
    b.config_mailbox();
    assert_eq!(b.request(2), (2, 0));
    assert_eq!(b.download(0x1C32, 1, false, &1u16.to_le_bytes()), Ok(()));
    b.config_sm(2, SM2, 4, 0x64);
    b.config_sm(3, SM3, 7, 0x20);
    assert_eq!(b.request(4), (4, 0));
    assert_eq!(b.s.sync_mode(), SyncMode::SmSync);
    assert_eq!(b.request(8), (8, 0));
    let c0 = b.app.cycles;
    for k in 1..=10u8 {
        assert!(!b.drv.irq_lines().pdi_irq, "{}", P::NAME);
        b.wr(SM2, &[0, k, 0, 0]);
        assert!(b.drv.irq_lines().pdi_irq, "{}", P::NAME);
        b.s.on_pdi_irq(&mut b.drv, &mut b.app).unwrap();
        assert_eq!(b.app.cycles, c0 + k as u32);
        let (d, _) = b.rd(SM3, 7);
        assert_eq!(i16::from_le_bytes([d[1], d[2]]), 2 * k as i16);
    }
}

#[test]
fn sm_sync_on_irq_pin_every_driver() {
    sm_sync_on_irq_pin::<Lan>();
    sm_sync_on_irq_pin::<LanFast>();
    sm_sync_on_irq_pin::<Et2>();
    sm_sync_on_irq_pin::<Et3>();
    sm_sync_on_irq_pin::<EtPause>();
}
