//! TUeES030 board services beyond the manual's process data: 0x8040 "Internal voltages"
//! over SDO, the firmware update over FoE (refusals with their codes, a good install the
//! board reports), and hard braking against a supply that cannot sink: the line rises to
//! the kill threshold and the firmware kills the motors.

use std::sync::{Arc, Mutex};

use oxicat_devices::tue_es030::app::MSTATE_KILLED;
use oxicat_devices::tue_es030::control::{line_10mv, KILLVOLTAGE};
use oxicat_devices::tue_es030::device::{with_identity, DEF};
use oxicat_devices::tue_es030::experiment::{self as tue, Braking, NormalRow, TueParams};
use oxicat_devices::tue_es030::rig::{attach, TueConfig, TueHandle, FIRMWARE_FILE, SLOT_BYTES};
use oxicat_master::{Link, Master, MasterError};
use oxicat_plant::re30::LineParams;
use oxicat_sim::segment::Segment;
use oxicat_slave::foe::UpdateResult;

use oxicat_testkit::big;

fn bench_with(cfg: &TueConfig) -> (Link, Arc<Mutex<Segment>>, TueHandle) {
    let mut seg = Segment::new();
    let sii = oxicat_esi::sii::generate(&DEF).unwrap();
    let id = seg.add(oxicat_esc::Esc::new(oxicat_esc::EscConfig::et1200(), sii));
    let h = attach(&mut seg, id, cfg).unwrap();
    let seg = Arc::new(Mutex::new(seg));
    (Link::Sim(seg.clone()), seg, h)
}

/// Reads 0x8040 until `done` holds for it (the service routine refreshes it at 1 kHz of
/// virtual time, which advances with the frames); `None` if it never does.
fn voltages_until(m: &Master, done: impl Fn(&[u16; 4]) -> bool) -> Option<[u16; 4]> {
    for _ in 0..500 {
        let v = tue::internal_voltages(m, 0).unwrap();
        if done(&v) {
            return Some(v);
        }
    }
    None
}

#[test]
fn internal_voltages_over_sdo() {
    big(internal_voltages_over_sdo_body);
}

fn internal_voltages_over_sdo_body() {
    let (link, _seg, h) = bench_with(&TueConfig::default());
    let m = Master::open(link).unwrap();
    // 24 V line, 5 V reference, through the ADC (12 bit: 8.9 mV and 1.6 mV steps).
    let v = voltages_until(&m, |v| v[0] > 0).expect("the service routine fills 0x8040");
    assert!((v[0] as i32 - 2400).abs() <= 2, "line {v:?}");
    assert!((v[1] as i32 - 500).abs() <= 2, "5 V reference {v:?}");
    assert!(v[2] >= v[0], "peak below the line: {v:?}");
    assert_eq!(v[3], line_10mv(KILLVOLTAGE), "kill threshold");
    assert!((2990..=3010).contains(&v[3]), "KILLVOLTAGE is 30 V: {v:?}");
    // Read-only.
    match m.sdo_download(0, 0x8040, 1, &2400u16.to_le_bytes()) {
        Err(MasterError::SdoAbort { index, sub, .. }) => assert_eq!((index, sub), (0x8040, 1)),
        other => panic!("0x8040:01 written: {other:?}"),
    }
    // The supply up to 28 V and back: the line follows, the peak holds.
    h.lock().app.board.supply = 28.0;
    let up = voltages_until(&m, |v| v[0] > 2700).expect("line follows the supply");
    assert!((up[0] as i32 - 2800).abs() <= 2, "{up:?}");
    h.lock().app.board.supply = 24.0;
    let down = voltages_until(&m, |v| v[0] < 2500).expect("line follows the supply");
    assert!((down[0] as i32 - 2400).abs() <= 2, "{down:?}");
    assert!(
        down[2] >= up[0],
        "peak since reset kept: {down:?} after {up:?}"
    );
    assert!(!h.lock().app.motors.iter().any(|m| m.enabled));
}

fn foe_code(r: Result<(), MasterError>) -> u32 {
    r.err().and_then(|e| e.foe_code()).expect("an FoE refusal")
}

#[test]
fn foe_refuses_bad_images_and_installs_a_good_one() {
    big(foe_refuses_bad_images_and_installs_a_good_one_body);
}

fn foe_refuses_bad_images_and_installs_a_good_one_body() {
    let (link, _seg, h) = bench_with(&TueConfig::default());
    let mut m = Master::open(link).unwrap();
    let none = &mut |_: usize, _: usize| {};
    let v0 = String::from_utf8(m.foe_read(0, "version.txt", 0, none).unwrap()).unwrap();
    assert!(v0.contains("revision=0x00000001"), "factory image: {v0}");
    let good_def = with_identity(2, DEF.identity.product_code);
    let payload: Vec<u8> = (0..5000u32).map(|i| (i * 13 + 7) as u8).collect();
    let good = oxicat_esi::fwimage::build(&good_def, &payload);
    // Outside BOOT: bootstrap only.
    assert_eq!(
        foe_code(m.foe_write(0, FIRMWARE_FILE, 0, &good, none)),
        0x8008
    );
    m.enter_boot(0).unwrap();
    // Another file in BOOT: not bootstrap.
    assert_eq!(foe_code(m.foe_write(0, "app.bin", 0, &good, none)), 0x8009);
    // Another device's image: program error.
    let other = oxicat_esi::fwimage::build(&with_identity(2, 0x1234), &payload);
    assert_eq!(
        foe_code(m.foe_write(0, FIRMWARE_FILE, 0, &other, none)),
        0x800B
    );
    // A flipped payload byte: checksum error.
    let mut corrupt = good.clone();
    corrupt[1000] ^= 0xFF;
    assert_eq!(
        foe_code(m.foe_write(0, FIRMWARE_FILE, 0, &corrupt, none)),
        0x800C
    );
    // Larger than a slot: disk full (refused from the header).
    let huge = oxicat_esi::fwimage::build(&good_def, &vec![0x5A; SLOT_BYTES + 1]);
    assert_eq!(
        foe_code(m.foe_write(0, FIRMWARE_FILE, 0, &huge, none)),
        0x8003
    );
    // Nothing of that changed the bootable image.
    let v = String::from_utf8(m.foe_read(0, "version.txt", 0, none).unwrap()).unwrap();
    assert!(v.contains("revision=0x00000001"), "{v}");
    // The good image installs; the board reports it.
    m.foe_write(0, FIRMWARE_FILE, 0, &good, none).unwrap();
    assert!(matches!(
        h.lock().app.files.last,
        Some(UpdateResult::Installed(hd)) if hd.revision == 2 && hd.length == 5000
    ));
    let v = String::from_utf8(m.foe_read(0, "version.txt", 0, none).unwrap()).unwrap();
    assert!(
        v.contains("revision=0x00000002") && v.contains("length=5000"),
        "{v}"
    );
    assert_eq!(m.foe_read(0, FIRMWARE_FILE, 0, none).unwrap(), good);
    // The same image again: already exists.
    assert_eq!(
        foe_code(m.foe_write(0, FIRMWARE_FILE, 0, &good, none)),
        0x8006
    );
    m.leave_boot(0).unwrap();
    m.request_state(&[0], oxicat_master::AlState::PreOp)
        .unwrap();
    let v = String::from_utf8(m.foe_read(0, "version.txt", 0, none).unwrap()).unwrap();
    assert!(v.contains("revision=0x00000002"), "after BOOT: {v}");
}

/// The bench parameters: the RE 30's R and KV, its 500-line encoder.
fn params() -> TueParams {
    TueParams {
        r: [0.611; 3],
        kv: [0.0259; 3],
        encres: [500; 3],
        ..TueParams::default()
    }
}

struct Braked {
    rows: Vec<NormalRow>,
    /// The plant's line peak [V].
    peak: f64,
    /// 0x8040 after the run.
    volts: [u16; 4],
    kills: u64,
}

fn brake(cfg: &TueConfig) -> Braked {
    let (link, _seg, h) = bench_with(cfg);
    let mut m = Master::open(link).unwrap();
    tue::write_params(&m, 0, &params()).unwrap();
    let rows = tue::run_normal(
        &mut m,
        0,
        Braking::default().cycles,
        Braking::default().control(),
    )
    .unwrap();
    let volts = tue::internal_voltages(&m, 0).unwrap();
    let b = h.lock();
    Braked {
        rows,
        peak: b
            .app
            .board
            .line
            .map(|l| l.peak)
            .unwrap_or(b.app.board.supply),
        volts,
        kills: b.app.counters.kills,
    }
}

#[test]
fn hard_braking_raises_the_line_to_the_kill_threshold_and_the_firmware_kills() {
    big(hard_braking_raises_the_line_to_the_kill_threshold_and_the_firmware_kills_body);
}

fn hard_braking_raises_the_line_to_the_kill_threshold_and_the_firmware_kills_body() {
    let line = TueConfig::default().line(Some(LineParams::tue_es030()));
    let kill_v = line_10mv(KILLVOLTAGE) as f64 * 0.01;
    let plan = Braking::default();
    let killed = |r: &NormalRow| r.input.mstate[1] & MSTATE_KILLED != 0;

    // Without the kill the braking energy takes the line well above the threshold.
    let free = brake(&line.clone().kill(false));
    let w0 = free.rows[plan.brake_at as usize].input.velocity[1] as f64 * 0.1;
    assert!((w0 - plan.speed).abs() < 20.0, "spun up to {w0} rad/s");
    assert!(free.peak > kill_v + 1.0, "line peak {} V", free.peak);
    assert!(
        (free.volts[2] as f64 * 0.01 - free.peak).abs() < 0.05,
        "0x8040:03 {} against the plant's {} V",
        free.volts[2],
        free.peak
    );
    assert_eq!(free.kills, 0);
    assert!(!free.rows.iter().any(killed));
    assert_eq!(free.volts[3], i16::MAX as u16, "no threshold");

    // With it the firmware disables the motors as the line crosses 30 V. It checks at
    // every 50 µs current loop and the bridge takes the new duty half a PWM period later,
    // so the line can overshoot by at most what the bridge returns at the driver's
    // current limit in that time.
    let kill = brake(&line);
    let c = LineParams::tue_es030().capacitance;
    let one_loop = line.motors[1].overcurrent * 56.25e-6 / c;
    assert!(
        kill.peak > kill_v,
        "line reached the threshold: {}",
        kill.peak
    );
    assert!(
        kill.peak < kill_v + one_loop && kill.peak < free.peak - 1.0,
        "line peak {} V (threshold {kill_v} V, one loop {one_loop} V, without the kill {} V)",
        kill.peak,
        free.peak
    );
    assert!(kill.kills > 0);
    let first = kill
        .rows
        .iter()
        .position(killed)
        .expect("mstate reports the kill");
    assert!(
        first as u64 > plan.brake_at,
        "only while braking: cycle {first}"
    );
    assert!(
        (kill.volts[2] as f64 * 0.01 - kill.peak).abs() < 0.05,
        "0x8040:03 {} against the plant's {} V",
        kill.volts[2],
        kill.peak
    );

    // A battery takes the energy back: the line stays at the supply, nothing is killed.
    let battery = brake(&TueConfig::default());
    assert_eq!(battery.kills, 0);
    let filled = battery.rows.iter().filter(|r| r.input.ectime != 0);
    assert!(filled
        .inspect(|r| assert!(!killed(r), "cycle {}", r.cycle))
        .all(|r| (r.input.linevoltage as i32 - 2400).abs() <= 2));
    assert!(battery.volts[2] <= 2402, "peak {:?}", battery.volts);
}
