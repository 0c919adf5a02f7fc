//! Register-level behaviour of the Distributed Clocks unit, driven directly with a plain
//! register array (as the ESC core does).

use oxicat_esc::dc::{ClockConfig, Dc};

type Regs = [u8; 0x1000];

fn regs() -> Regs {
    [0u8; 0x1000]
}

fn dc(drift_ppm: f64, start_offset_ns: u64) -> Dc {
    Dc::new(ClockConfig {
        drift_ppm,
        start_offset_ns,
    })
}

fn rd32(r: &Regs, a: usize) -> u32 {
    u32::from_le_bytes(r[a..a + 4].try_into().unwrap())
}

fn rd64(r: &Regs, a: usize) -> u64 {
    u64::from_le_bytes(r[a..a + 8].try_into().unwrap())
}

/// An ECAT write as the core performs it: store the bytes, then notify.
fn ecat_write(d: &mut Dc, r: &mut Regs, a: u16, data: &[u8], t: u64) {
    r[a as usize..a as usize + data.len()].copy_from_slice(data);
    d.after_write(r, a, data.len() as u16, t, true);
}

fn pdi_write(d: &mut Dc, r: &mut Regs, a: u16, data: &[u8], t: u64) {
    r[a as usize..a as usize + data.len()].copy_from_slice(data);
    d.after_write(r, a, data.len() as u16, t, false);
}

fn read64(d: &mut Dc, r: &mut Regs, a: u16, t: u64) -> u64 {
    d.before_read(r, a, 8, t);
    let v = rd64(r, a as usize);
    d.after_read(r, a, 8, t, true);
    v
}

/// 0x092C decoded as ethercrab does (sign-magnitude, bit 31 = local smaller).
fn sys_diff(d: &mut Dc, r: &mut Regs, t: u64) -> i64 {
    d.before_read(r, 0x092C, 4, t);
    let raw = rd32(r, 0x092C);
    let mag = (raw & 0x7FFF_FFFF) as i64;
    if raw & 0x8000_0000 != 0 {
        -mag
    } else {
        mag
    }
}

#[test]
fn reset_values() {
    let mut d = dc(0.0, 0);
    let mut r = regs();
    d.advance(&mut r, 0);
    assert_eq!(u16::from_le_bytes([r[0x0930], r[0x0931]]), 0x1000);
    assert_eq!(r[0x0934], 0x04);
    assert_eq!(r[0x0935], 0x0C);
    assert_eq!(d.next_event(), None);
}

#[test]
fn local_clock_drift_is_exact() {
    let d = dc(100.0, 5_000);
    assert_eq!(d.local_time(0), 5_000);
    assert_eq!(d.local_time(1_000_000_000), 5_000 + 1_000_100_000);
    let d = dc(-50.0, 0);
    assert_eq!(d.local_time(2_000_000_000), 2_000_000_000 - 100_000);
}

#[test]
fn receive_time_latching() {
    let mut d = dc(0.0, 1_000_000);
    let mut r = regs();
    // Latch frame: enters port 0, EPU processes the write, returns via port 3 then port 1.
    d.frame_arrival(&mut r, 0, 10_000);
    ecat_write(&mut d, &mut r, 0x0900, &[0xAA; 4], 10_000);
    d.frame_arrival(&mut r, 3, 10_400);
    d.frame_arrival(&mut r, 1, 10_900);
    assert_eq!(rd32(&r, 0x0900), 1_010_000);
    assert_eq!(rd32(&r, 0x090C), 1_010_400);
    assert_eq!(rd32(&r, 0x0904), 1_010_900);
    assert_eq!(rd32(&r, 0x0908), 0, "port 2 never saw the frame");
    assert_eq!(rd64(&r, 0x0918), 1_010_000);

    // A later frame without a write to 0x0900 latches nothing.
    d.frame_arrival(&mut r, 0, 20_000);
    d.frame_arrival(&mut r, 2, 20_500);
    d.frame_arrival(&mut r, 1, 21_000);
    assert_eq!(rd32(&r, 0x0904), 1_010_900);
    assert_eq!(rd32(&r, 0x0908), 0);

    // The PDI cannot latch, and cannot overwrite receive times.
    pdi_write(&mut d, &mut r, 0x0900, &[1, 2, 3, 4], 30_000);
    assert_eq!(rd32(&r, 0x0900), 1_010_000);
    // Nor can ECAT overwrite the read-only EPU receive time.
    ecat_write(&mut d, &mut r, 0x0918, &[9; 8], 31_000);
    assert_eq!(rd64(&r, 0x0918), 1_010_000);
}

#[test]
fn offset_and_delay_apply_to_system_time() {
    let mut d = dc(0.0, 500);
    let mut r = regs();
    let off: u64 = 7_000_000_000;
    ecat_write(&mut d, &mut r, 0x0920, &off.to_le_bytes(), 1_000);
    ecat_write(&mut d, &mut r, 0x0928, &1234u32.to_le_bytes(), 1_000);
    assert_eq!(read64(&mut d, &mut r, 0x0910, 2_000), 2_500 + off);
    assert_eq!(rd32(&r, 0x0928), 1234);
    // Negative offset (two's complement), as ethercrab writes `now - receive_time`.
    let neg = (-2_000i64) as u64;
    ecat_write(&mut d, &mut r, 0x0920, &neg.to_le_bytes(), 3_000);
    assert_eq!(read64(&mut d, &mut r, 0x0910, 10_000), 10_500 - 2_000);
    // The PDI may not write the offset.
    pdi_write(&mut d, &mut r, 0x0920, &[0; 8], 11_000);
    assert_eq!(rd64(&r, 0x0920), neg);
    assert_eq!(read64(&mut d, &mut r, 0x0910, 12_000), 12_500 - 2_000);
}

#[test]
fn system_time_write_reports_difference_in_sign_magnitude() {
    let mut d = dc(0.0, 0);
    let mut r = regs();
    // Filter depth 0: 0x092C shows the last difference.
    ecat_write(&mut d, &mut r, 0x0934, &[0], 0);
    ecat_write(&mut d, &mut r, 0x0928, &100u32.to_le_bytes(), 0);
    // Local system time at t=1_000_000 is 1_000_000; minus delay 100 = 999_900.
    d.frame_arrival(&mut r, 0, 1_000_000);
    ecat_write(&mut d, &mut r, 0x0910, &999_000u64.to_le_bytes(), 1_000_000);
    assert_eq!(sys_diff(&mut d, &mut r, 1_000_000), 900);
    // Local copy smaller than received: bit 31 set.
    let mut d = dc(0.0, 0);
    let mut r = regs();
    ecat_write(&mut d, &mut r, 0x0934, &[0], 0);
    d.frame_arrival(&mut r, 0, 1_000_000);
    ecat_write(
        &mut d,
        &mut r,
        0x0910,
        &1_000_500u64.to_le_bytes(),
        1_000_000,
    );
    d.before_read(&mut r, 0x092C, 4, 1_000_000);
    assert_eq!(rd32(&r, 0x092C), 0x8000_0000 | 500);
    // Writing speed counter start resets the difference.
    ecat_write(&mut d, &mut r, 0x0930, &0x1000u16.to_le_bytes(), 1_000_100);
    assert_eq!(rd32(&r, 0x092C), 0);
    assert_eq!(d.correction_ppb(), 0);
}

/// A reference clock and a slave `hop` ns behind it; the master latches receive times,
/// writes offset and delay, then distributes the reference time every `period` ns.
struct Pair {
    rf: Dc,
    rr: Regs,
    sl: Dc,
    sr: Regs,
    hop: u64,
    t: u64,
}

impl Pair {
    fn new(ref_ppm: f64, slave_ppm: f64, hop: u64) -> Self {
        let mut p = Pair {
            rf: dc(ref_ppm, 3_000_000_123),
            rr: regs(),
            sl: dc(slave_ppm, 17_000_000_777),
            sr: regs(),
            hop,
            t: 1_000_000,
        };
        // BWR 0x0900 through both.
        let t0 = p.t;
        p.rf.frame_arrival(&mut p.rr, 0, t0);
        ecat_write(&mut p.rf, &mut p.rr, 0x0900, &[0; 4], t0);
        p.sl.frame_arrival(&mut p.sr, 0, t0 + hop);
        ecat_write(&mut p.sl, &mut p.sr, 0x0900, &[0; 4], t0 + hop);
        p.sl.frame_arrival(&mut p.sr, 1, t0 + hop + 300);
        p.rf.frame_arrival(&mut p.rr, 1, t0 + 2 * hop + 300);
        // Master: propagation delay from the reference's port times.
        let rp0 = rd32(&p.rr, 0x0900) as u64;
        let rp1 = rd32(&p.rr, 0x0904) as u64;
        let sp0 = rd32(&p.sr, 0x0900) as u64;
        let sp1 = rd32(&p.sr, 0x0904) as u64;
        let delay = ((rp1 - rp0) - (sp1 - sp0)) / 2;
        let t1 = t0 + 50_000;
        let ref_rx = read64(&mut p.rf, &mut p.rr, 0x0918, t1);
        let sl_rx = read64(&mut p.sl, &mut p.sr, 0x0918, t1);
        ecat_write(
            &mut p.rf,
            &mut p.rr,
            0x0920,
            &ref_rx.wrapping_neg().to_le_bytes(),
            t1,
        );
        ecat_write(
            &mut p.sl,
            &mut p.sr,
            0x0920,
            &sl_rx.wrapping_neg().to_le_bytes(),
            t1,
        );
        ecat_write(
            &mut p.sl,
            &mut p.sr,
            0x0928,
            &(delay as u32).to_le_bytes(),
            t1,
        );
        p.t = t1;
        p
    }

    /// One FRMW of 0x0910: reference reads at `t`, slave receives the write `hop` later.
    fn frmw(&mut self, t: u64) {
        self.t = t;
        self.rf.frame_arrival(&mut self.rr, 0, t);
        let v = read64(&mut self.rf, &mut self.rr, 0x0910, t);
        let ts = t + self.hop;
        self.sl.frame_arrival(&mut self.sr, 0, ts);
        ecat_write(&mut self.sl, &mut self.sr, 0x0910, &v.to_le_bytes(), ts);
        self.rf.advance(&mut self.rr, ts);
        self.sl.advance(&mut self.sr, ts);
    }

    /// Global-time disagreement of the two system times at `t`.
    fn sys_error(&self, t: u64) -> i64 {
        self.sl.system_time(t).wrapping_sub(self.rf.system_time(t)) as i64
    }
}

#[test]
fn drift_compensation_converges_and_stays() {
    for (a, b) in [
        (100.0, -100.0),
        (-100.0, 100.0),
        (0.0, 100.0),
        (37.5, -12.25),
    ] {
        let mut p = Pair::new(a, b, 1_150);
        // Static drift compensation: a burst of FRMWs back to back, then 1 ms cyclic.
        let mut t = p.t + 100_000;
        for _ in 0..1000 {
            p.frmw(t);
            t += 7_000;
        }
        for _ in 0..3000 {
            p.frmw(t);
            t += 1_000_000;
        }
        let tt = p.t + p.hop;
        let diff = sys_diff(&mut p.sl, &mut p.sr, tt);
        assert!(diff.abs() < 100, "{a}/{b}: 0x092C = {diff} ns after 3 s");
        let mut worst_reg = 0i64;
        let mut worst_true = 0i64;
        for _ in 0..5000 {
            p.frmw(t);
            let tt = p.t + p.hop;
            worst_reg = worst_reg.max(sys_diff(&mut p.sl, &mut p.sr, tt).abs());
            worst_true = worst_true.max(p.sys_error(t + 500_000).abs());
            t += 1_000_000;
        }
        assert!(worst_reg < 100, "{a}/{b}: 0x092C reached {worst_reg} ns");
        assert!(worst_true < 100, "{a}/{b}: clocks {worst_true} ns apart");
        // The loop really compensates drift (rate ≈ ref - slave drift).
        let want = ((1.0 + a * 1e-6) / (1.0 + b * 1e-6) - 1.0) * 1e9;
        let got = p.sl.correction_ppb() as f64;
        assert!(
            (got - want) < 2_000.0 && (want - got) < 2_000.0,
            "rate {got} ppb, want {want}"
        );
    }
}

#[test]
fn convergence_is_gradual_not_a_step() {
    let mut p = Pair::new(100.0, -100.0, 800);
    let mut t = p.t + 20_000_000; // 200 ppm over 20 ms: ~4 µs apart
    let before = p.sys_error(t).abs();
    assert!(before > 3_000, "{before}");
    p.frmw(t);
    t += 1_000_000;
    p.frmw(t);
    let after = p.sys_error(t).abs();
    assert!(after > 2_000, "no step correction: {after}");
}

/// Collect SYNC edges until global time `until`, driving the unit by `next_event`.
fn collect(d: &mut Dc, r: &mut Regs, from: u64, until: u64) -> (Vec<u64>, Vec<u64>) {
    let (mut s0, mut s1) = (vec![], vec![]);
    let mut t = from;
    while let Some(n) = d.next_event() {
        if n > until {
            break;
        }
        assert!(n >= t, "next_event went back in time");
        t = n;
        let ev = d.advance(r, t);
        s0.extend(ev.sync0);
        s1.extend(ev.sync1);
    }
    d.advance(r, until);
    (s0, s1)
}

fn setup_sync(d: &mut Dc, r: &mut Regs, t: u64, start: u64, c0: u32, c1: u32, act: u8) {
    ecat_write(d, r, 0x09A0, &c0.to_le_bytes(), t);
    ecat_write(d, r, 0x09A4, &c1.to_le_bytes(), t);
    ecat_write(d, r, 0x0990, &start.to_le_bytes(), t);
    ecat_write(d, r, 0x0981, &[act], t);
}

#[test]
fn sync0_edges_at_start_plus_k_cycles() {
    let mut d = dc(-73.0, 99_999);
    let mut r = regs();
    r[0x0982] = 100; // 1 µs pulses
    ecat_write(&mut d, &mut r, 0x0920, &5_000_000_000u64.to_le_bytes(), 0);
    let now = d.system_time(1_000_000);
    let start = now + 2_000_000;
    setup_sync(&mut d, &mut r, 1_000_000, start, 250_000, 0, 0x03);
    assert_eq!(r[0x0984] & 0x01, 0x01, "first pulse pending");
    let (s0, _) = collect(&mut d, &mut r, 1_000_000, 100_000_000);
    assert!(s0.len() >= 380, "{}", s0.len());
    for (k, g) in s0.iter().enumerate() {
        let at = d.system_time(*g);
        let want = start + k as u64 * 250_000;
        assert!(
            at >= want && at <= want + 1,
            "edge {k}: system time {at}, want {want}"
        );
        assert!(d.system_time(g - 1) < want);
    }
    assert_eq!(r[0x0984] & 0x01, 0);
    // 0x0990 reads the next SYNC0 pulse while active.
    let next = read64(&mut d, &mut r, 0x0990, 100_000_000);
    assert_eq!((next - start) % 250_000, 0);
    assert!(next > d.system_time(100_000_000));
}

#[test]
fn sync_pulse_length_and_levels() {
    let mut d = dc(0.0, 0);
    let mut r = regs();
    r[0x0982..0x0984].copy_from_slice(&200u16.to_le_bytes()); // 2 µs
    setup_sync(&mut d, &mut r, 0, 1_000_000, 1_000_000, 0, 0x07);
    assert_eq!(d.next_event(), Some(1_000_000));
    let ev = d.advance(&mut r, 1_000_000);
    assert_eq!(ev.sync0, Some(1_000_000));
    assert_eq!(
        ev.sync1,
        Some(1_000_000),
        "SYNC1 cycle 0: SYNC1 copies SYNC0"
    );
    assert_eq!(d.sync_levels(), (true, true));
    assert_eq!(r[0x098E], 1);
    assert_eq!(d.al_event_bits() & 0b1100, 0b1100);
    assert_eq!(d.next_event(), Some(1_002_000), "falling edge");
    let ev = d.advance(&mut r, 1_002_000);
    assert_eq!(ev.sync0, None);
    assert_eq!(d.sync_levels(), (false, false));
    assert_eq!(r[0x098E], 0);
    assert_eq!(d.next_event(), Some(2_000_000));
    // Deactivation stops everything.
    ecat_write(&mut d, &mut r, 0x0981, &[0], 1_500_000);
    assert_eq!(d.next_event(), None);
    assert_eq!(d.advance(&mut r, 5_000_000).sync0, None);
}

#[test]
fn sync1_relative_to_sync0() {
    // SYNC1 cycle < SYNC0 cycle: one SYNC1 per SYNC0, delayed.
    let mut d = dc(0.0, 0);
    let mut r = regs();
    r[0x0982] = 10;
    setup_sync(&mut d, &mut r, 0, 1_000_000, 1_000_000, 300_000, 0x07);
    let (s0, s1) = collect(&mut d, &mut r, 0, 5_500_000);
    assert_eq!(
        s0,
        vec![1_000_000, 2_000_000, 3_000_000, 4_000_000, 5_000_000]
    );
    assert_eq!(
        s1,
        vec![1_300_000, 2_300_000, 3_300_000, 4_300_000, 5_300_000]
    );

    // SYNC1 cycle = 2 × SYNC0 cycle: every other SYNC0.
    let mut d = dc(0.0, 0);
    let mut r = regs();
    r[0x0982] = 10;
    setup_sync(&mut d, &mut r, 0, 1_000_000, 1_000_000, 2_000_000, 0x07);
    let (_, s1) = collect(&mut d, &mut r, 0, 9_500_000);
    assert_eq!(s1, vec![3_000_000, 5_000_000, 7_000_000, 9_000_000]);

    // SYNC0 < SYNC1 cycle < 2 × SYNC0: re-armed by the next SYNC0 after each SYNC1.
    let mut d = dc(0.0, 0);
    let mut r = regs();
    r[0x0982] = 10;
    setup_sync(&mut d, &mut r, 0, 1_000_000, 1_000_000, 1_500_000, 0x07);
    let (_, s1) = collect(&mut d, &mut r, 0, 8_000_000);
    assert_eq!(s1, vec![2_500_000, 4_500_000, 6_500_000]);

    // SYNC1 disabled: only SYNC0 is reported.
    let mut d = dc(0.0, 0);
    let mut r = regs();
    r[0x0982] = 10;
    setup_sync(&mut d, &mut r, 0, 1_000_000, 1_000_000, 300_000, 0x03);
    let (s0, s1) = collect(&mut d, &mut r, 0, 3_500_000);
    assert_eq!(s0.len(), 3);
    assert!(s1.is_empty());
    // 0x0998 shows the next SYNC1 pulse time (internal schedule).
    assert_eq!(rd64(&r, 0x0998), 3_300_000);
}

#[test]
fn acknowledge_mode() {
    let mut d = dc(0.0, 0);
    let mut r = regs(); // pulse length 0 = acknowledge mode
    setup_sync(&mut d, &mut r, 0, 1_000_000, 1_000_000, 0, 0x03);
    let ev = d.advance(&mut r, 1_000_000);
    assert_eq!(ev.sync0, Some(1_000_000));
    assert_eq!(
        d.next_event(),
        Some(2_000_000),
        "no falling edge in acknowledge mode"
    );
    d.advance(&mut r, 1_700_000);
    assert!(d.sync_levels().0);
    // An ECAT read does not acknowledge.
    d.before_read(&mut r, 0x098E, 1, 1_700_000);
    assert_eq!(r[0x098E], 1);
    d.after_read(&mut r, 0x098E, 1, 1_700_000, true);
    assert!(d.sync_levels().0);
    // A PDI read returns 1 and acknowledges.
    d.before_read(&mut r, 0x098E, 1, 1_800_000);
    assert_eq!(r[0x098E], 1);
    d.after_read(&mut r, 0x098E, 1, 1_800_000, false);
    assert!(!d.sync_levels().0);
    assert_eq!(r[0x098E], 0);
    assert_eq!(d.al_event_bits() & 0b100, 0);
    let ev = d.advance(&mut r, 2_000_000);
    assert_eq!(ev.sync0, Some(2_000_000));
    assert_eq!(r[0x098E], 1);
}

#[test]
fn single_shot() {
    let mut d = dc(0.0, 0);
    let mut r = regs();
    r[0x0982] = 10;
    setup_sync(&mut d, &mut r, 0, 1_000_000, 0, 0, 0x03);
    let (s0, _) = collect(&mut d, &mut r, 0, 10_000_000);
    assert_eq!(s0, vec![1_000_000]);
    // Another pulse needs re-activation.
    ecat_write(&mut d, &mut r, 0x0981, &[0], 10_000_000);
    setup_sync(&mut d, &mut r, 10_000_000, 12_000_000, 0, 0, 0x03);
    let (s0, _) = collect(&mut d, &mut r, 10_000_000, 20_000_000);
    assert_eq!(s0, vec![12_000_000]);
}

#[test]
fn start_time_in_the_past_waits_for_32_bit_wrap() {
    let mut d = dc(0.0, 0);
    let mut r = regs();
    r[0x0982] = 10;
    let t = 10_000_000;
    setup_sync(&mut d, &mut r, t, 9_000_000, 1_000_000, 0, 0x03);
    assert_eq!(
        r[0x0984] & 0x05,
        0x05,
        "pending, start time out of near future"
    );
    let first = d.next_event().unwrap();
    assert_eq!(d.system_time(first), 9_000_000 + (1u64 << 32));
    let (s0, _) = collect(&mut d, &mut r, t, first - 1);
    assert!(s0.is_empty());
    let ev = d.advance(&mut r, first);
    assert_eq!(ev.sync0, Some(first));
    assert_eq!(r[0x0984] & 0x01, 0);
}

#[test]
fn start_time_in_the_past_with_plausibility_check_fires_immediately() {
    let mut d = dc(0.0, 0);
    let mut r = regs();
    r[0x0982] = 10;
    let t = 10_000_000;
    setup_sync(&mut d, &mut r, t, 9_000_000, 1_000_000, 0, 0x23);
    assert_eq!(d.next_event(), Some(t));
    let (s0, _) = collect(&mut d, &mut r, t, t + 2_500_000);
    assert_eq!(s0, vec![t, t + 1_000_000, t + 2_000_000]);
    // 64-bit compare without the check: never.
    let mut d = dc(0.0, 0);
    let mut r = regs();
    d.set_start_time_compare_bits(64);
    setup_sync(&mut d, &mut r, t, 9_000_000, 1_000_000, 0, 0x03);
    assert_eq!(d.next_event(), None);
}

#[test]
fn auto_activation_by_writing_start_time() {
    let mut d = dc(0.0, 0);
    let mut r = regs();
    r[0x0982] = 10;
    ecat_write(&mut d, &mut r, 0x09A0, &1_000_000u32.to_le_bytes(), 0);
    ecat_write(&mut d, &mut r, 0x0981, &[0x0A], 0);
    assert_eq!(d.next_event(), None);
    ecat_write(&mut d, &mut r, 0x0990, &3_000_000u64.to_le_bytes(), 0);
    assert_eq!(r[0x0981] & 0x01, 0x01);
    assert_eq!(d.next_event(), Some(3_000_000));
}

#[test]
fn cyclic_unit_assignment_controls_write_access() {
    let mut d = dc(0.0, 0);
    let mut r = regs();
    ecat_write(&mut d, &mut r, 0x0980, &[0x01], 0); // SYNC unit to PDI
    ecat_write(&mut d, &mut r, 0x09A0, &1_000_000u32.to_le_bytes(), 0);
    assert_eq!(rd32(&r, 0x09A0), 0, "ECAT may not write");
    pdi_write(&mut d, &mut r, 0x09A0, &1_000_000u32.to_le_bytes(), 0);
    pdi_write(&mut d, &mut r, 0x0990, &2_000_000u64.to_le_bytes(), 0);
    pdi_write(&mut d, &mut r, 0x0981, &[0x03], 0);
    assert_eq!(d.next_event(), Some(2_000_000));
    pdi_write(&mut d, &mut r, 0x0980, &[0x00], 0);
    assert_eq!(r[0x0980], 0x01, "the PDI may not write 0x0980");
}

#[test]
fn two_drifting_clocks_sync0_within_a_few_ns_after_convergence() {
    let mut p = Pair::new(80.0, -100.0, 2_345);
    let mut t = p.t + 1_000_000;
    for _ in 0..4000 {
        p.frmw(t);
        t += 1_000_000;
    }
    p.rr[0x0982] = 100;
    p.sr[0x0982] = 100;
    let now = p.rf.system_time(t);
    let start = (now / 1_000_000 + 20) * 1_000_000;
    setup_sync(&mut p.rf, &mut p.rr, t, start, 400_000, 0, 0x03);
    setup_sync(&mut p.sl, &mut p.sr, t, start, 400_000, 0, 0x03);
    let mut edges = (vec![], vec![]);
    // Keep distributing time while the SYNC units run.
    for _ in 0..200 {
        let until = t + 1_000_000;
        for (d, r, e) in [
            (&mut p.rf, &mut p.rr, &mut edges.0),
            (&mut p.sl, &mut p.sr, &mut edges.1),
        ] {
            while let Some(n) = d.next_event() {
                if n > until {
                    break;
                }
                e.extend(d.advance(r, n).sync0);
            }
        }
        t = until;
        p.frmw(t);
    }
    assert!(edges.0.len() > 400);
    assert_eq!(edges.0.len(), edges.1.len());
    for (a, b) in edges.0.iter().zip(&edges.1) {
        let d = *a as i64 - *b as i64;
        assert!(d.abs() < 20, "SYNC0 {a} vs {b}");
    }
}

#[test]
fn latch_inputs() {
    let mut d = dc(0.0, 0);
    let mut r = regs();
    ecat_write(&mut d, &mut r, 0x0920, &1_000u64.to_le_bytes(), 0);
    // Continuous mode (default): every edge overwrites, no event bits.
    d.latch_input(&mut r, 0, true, 10_000);
    d.latch_input(&mut r, 0, false, 20_000);
    d.latch_input(&mut r, 0, true, 30_000);
    assert_eq!(rd64(&r, 0x09B0), 31_000);
    assert_eq!(rd64(&r, 0x09B8), 21_000);
    assert_eq!(r[0x09AE], 0x04, "pin state only");
    assert_eq!(d.ecat_event_bits(), 0);
    // Single event mode on latch1, PDI-owned.
    ecat_write(&mut d, &mut r, 0x0980, &[0x20], 0);
    pdi_write(&mut d, &mut r, 0x09A9, &[0x03], 40_000);
    d.latch_input(&mut r, 1, true, 50_000);
    d.latch_input(&mut r, 1, false, 60_000);
    d.latch_input(&mut r, 1, true, 70_000);
    assert_eq!(rd64(&r, 0x09C0), 51_000, "first event kept");
    assert_eq!(rd64(&r, 0x09C8), 61_000);
    assert_eq!(r[0x09AF], 0x07);
    assert_eq!(d.al_event_bits() & 0b10, 0b10);
    assert_eq!(d.ecat_event_bits(), 0);
    // An ECAT read does not clear a PDI-owned latch; a PDI read does.
    d.after_read(&mut r, 0x09C0, 8, 80_000, true);
    assert_eq!(r[0x09AF] & 0x01, 0x01);
    d.after_read(&mut r, 0x09C0, 8, 80_000, false);
    assert_eq!(r[0x09AF] & 0x03, 0x02);
    d.latch_input(&mut r, 1, false, 90_000);
    d.latch_input(&mut r, 1, true, 100_000);
    assert_eq!(rd64(&r, 0x09C0), 101_000, "re-armed by the read");
    d.after_read(&mut r, 0x09C0, 16, 110_000, false);
    assert_eq!(d.al_event_bits() & 0b10, 0);
}

#[test]
fn ethercrab_init_sequence_then_converges() {
    // ethercrab blanks DC registers with BWR (including a write of 0 to 0x0910, which feeds
    // the loop garbage), then writes 0x0934 = 0x0C00 and 0x0930 = 0x1000 to reset the loop.
    let mut sl = dc(-100.0, 42_000_000);
    let mut sr = regs();
    let mut rf = dc(100.0, 9_000_000);
    let mut rr = regs();
    for (d, r) in [(&mut sl, &mut sr), (&mut rf, &mut rr)] {
        d.frame_arrival(r, 0, 100_000);
        ecat_write(d, r, 0x0910, &[0; 8], 100_000);
        ecat_write(d, r, 0x0920, &[0; 8], 110_000);
        ecat_write(d, r, 0x092C, &[0; 4], 120_000);
        ecat_write(d, r, 0x0934, &0x0C00u16.to_le_bytes(), 130_000);
        ecat_write(d, r, 0x0930, &0x1000u16.to_le_bytes(), 140_000);
        assert_eq!(d.correction_ppb(), 0, "loop reset");
        assert_eq!(r[0x0934], 0);
        assert_eq!(r[0x0935], 0x0C);
    }
    let mut p = Pair {
        rf,
        rr,
        sl,
        sr,
        hop: 640,
        t: 0,
    };
    // Latch, offsets and delay as in Pair::new.
    let t0 = 5_000_000;
    p.rf.frame_arrival(&mut p.rr, 0, t0);
    ecat_write(&mut p.rf, &mut p.rr, 0x0900, &[0; 4], t0);
    p.sl.frame_arrival(&mut p.sr, 0, t0 + 640);
    ecat_write(&mut p.sl, &mut p.sr, 0x0900, &[0; 4], t0 + 640);
    let ref_rx = read64(&mut p.rf, &mut p.rr, 0x0918, t0 + 10_000);
    let sl_rx = read64(&mut p.sl, &mut p.sr, 0x0918, t0 + 10_000);
    ecat_write(
        &mut p.rf,
        &mut p.rr,
        0x0920,
        &ref_rx.wrapping_neg().to_le_bytes(),
        t0 + 10_000,
    );
    ecat_write(
        &mut p.sl,
        &mut p.sr,
        0x0920,
        &sl_rx.wrapping_neg().to_le_bytes(),
        t0 + 10_000,
    );
    ecat_write(
        &mut p.sl,
        &mut p.sr,
        0x0928,
        &640u32.to_le_bytes(),
        t0 + 10_000,
    );
    let mut t = t0 + 1_000_000;
    for _ in 0..3000 {
        p.frmw(t);
        t += 1_000_000;
    }
    // Filter depth 0: 0x092C is the last difference itself.
    for _ in 0..1000 {
        p.frmw(t);
        let d = sys_diff(&mut p.sl, &mut p.sr, t + 640);
        assert!(d.abs() < 100, "{d}");
        t += 1_000_000;
    }
}
