//! TUeES030 on the virtual segment with the master side: normal-mode position loop, mode
//! switch, parameter write/read-back, watchdog braking, line-voltage kill, FRF.

use std::sync::{Arc, Mutex};

use oxicat_devices::tue_es030::experiment::{self as tue, NormalOut, TueMode, TueParams};
use oxicat_devices::tue_es030::rig::{attach, TueConfig, TueHandle};
use oxicat_master::{Link, Master};
use oxicat_sim::segment::Segment;

/// Runs a test body on a thread with a large stack (the ethercrab master is big).
fn big<F: FnOnce() + Send + 'static>(f: F) {
    std::thread::Builder::new()
        .stack_size(64 << 20)
        .spawn(f)
        .unwrap()
        .join()
        .unwrap_or_else(|e| std::panic::resume_unwind(e));
}

fn bench() -> (Link, Arc<Mutex<Segment>>, TueHandle) {
    let mut seg = Segment::new();
    let sii = oxicat_esi::sii::generate(&oxicat_devices::tue_es030::device::DEF).unwrap();
    let id = seg.add(oxicat_esc::Esc::new(oxicat_esc::EscConfig::et1200(), sii));
    let h = attach(&mut seg, id, &TueConfig::default()).unwrap();
    let seg = Arc::new(Mutex::new(seg));
    (Link::Sim(seg.clone()), seg, h)
}

/// The bench parameters: the RE 30's R and KV, its 500-line encoder, P 2, I 2.
fn params() -> TueParams {
    TueParams {
        r: [0.611; 3],
        kv: [0.0259; 3],
        encres: [500; 3],
        ..TueParams::default()
    }
}

#[test]
fn normal_mode_position_loop_and_feedback_every_cycle() {
    big(normal_mode_position_loop_and_feedback_every_cycle_body);
}

fn normal_mode_position_loop_and_feedback_every_cycle_body() {
    let (link, _seg, h) = bench();
    let mut m = Master::open(link).unwrap();
    assert_eq!(tue::mode(&m, 0).unwrap(), Some(TueMode::Normal));
    let back = tue::write_params(&m, 0, &params()).unwrap();
    assert_eq!(back, params());
    // Position profile for M2: 0 -> 4 rev in a smooth 300 ms move, then hold.
    let target = |t: f64| {
        let s = (t / 0.3).clamp(0.0, 1.0);
        4.0 * 2.0 * std::f64::consts::PI * (3.0 * s * s - 2.0 * s * s * s)
    };
    let counts_per_rad = 2000.0 / (2.0 * std::f64::consts::PI);
    let start = 20u64;
    let mut c0 = None;
    let rows = tue::run_normal(&mut m, 0, 500, |k, inp| {
        let mut out = NormalOut::default();
        if k >= start {
            let c0 = *c0.get_or_insert(inp.count[1]);
            let pos = inp.count[1].wrapping_sub(c0) as i32 as f64 / counts_per_rad;
            let vel = inp.velocity[1] as f64 * 0.1;
            let t = (k - start) as f64 * 1e-3;
            // PD in current: kp 2 A/rad, kd 0.05 A s/rad.
            let i = 2.0 * (target(t) - pos) - 0.05 * vel;
            out.mcom[1] = 1;
            out.setpoint[1] = (i.clamp(-3.0, 3.0) * 1000.0) as i16;
        }
        out
    })
    .unwrap();
    // Feedback every cycle: the 1 kHz counter advances, line voltage is 24 V.
    let tail = &rows[start as usize..];
    for w in tail.windows(2) {
        assert_eq!(w[1].input.ectime.wrapping_sub(w[0].input.ectime), 1);
        assert!((w[1].input.linevoltage as i32 - 2400).abs() < 20);
    }
    assert!(tail.iter().any(|r| r.input.current[1].abs() > 200));
    assert!(tail.iter().any(|r| r.input.velocity[1].abs() > 100));
    assert!(tail[100..].iter().all(|r| r.input.mstate[1] & 1 == 1));
    let last = rows.last().unwrap();
    let c0 = c0.unwrap();
    let turns = last.input.count[1].wrapping_sub(c0) as i32 as f64 / 2000.0;
    assert!((turns - 4.0).abs() < 0.05, "ended at {turns} rev");
    let plant = h.lock().app.board.drives[1].angle / (2.0 * std::f64::consts::PI);
    assert!((plant - 4.0).abs() < 0.06, "plant at {plant} rev");
}

#[test]
fn watchdog_brakes_the_motors_and_drops_to_safeop_with_0x001b() {
    big(watchdog_brakes_the_motors_and_drops_to_safeop_with_0x001b_body);
}

fn watchdog_brakes_the_motors_and_drops_to_safeop_with_0x001b_body() {
    let (link, seg, h) = bench();
    let mut m = Master::open(link).unwrap();
    m.stop_cycling_as_if_gone();
    tue::run_normal(&mut m, 0, 100, |_, _| {
        let mut o = NormalOut::default();
        o.mcom[0] = 1;
        o.setpoint[0] = 300;
        o
    })
    .unwrap();
    assert!(h.lock().app.board.drives[0].speed > 50.0);
    assert!(h.lock().app.motors[0].enabled);
    // The master stops sending; 300 ms of virtual time pass.
    {
        let mut s = seg.lock().unwrap();
        let t = s.now();
        s.advance_to(t + 300_000_000);
    }
    let st = m.al_status(0).unwrap();
    assert_eq!(st.raw & 0x0F, 4, "SAFEOP");
    assert!(st.error());
    assert_eq!(st.code, 0x001B);
    let b = h.lock();
    assert!(!b.app.motors[0].enabled);
    assert_eq!(b.app.board.drives[0].bridge.duty_a, 0.5, "braking: 50/50");
    assert_eq!(b.app.board.drives[0].bridge.duty_b, 0.5);
    assert!(b.app.board.drives[0].bridge.enabled);
    assert!(
        !b.app.board.drives[0].fault,
        "braking current below the driver's OC trip"
    );
    let w = b.app.board.drives[0].speed;
    assert!(
        w.abs() < 1.0,
        "braked to rest: {w} rad/s, i {}",
        b.app.board.drives[0].current
    );
}

#[test]
fn line_voltage_above_the_kill_threshold_disables_all_motors() {
    big(line_voltage_above_the_kill_threshold_disables_all_motors_body);
}

fn line_voltage_above_the_kill_threshold_disables_all_motors_body() {
    let (link, _seg, h) = bench();
    let mut m = Master::open(link).unwrap();
    let rows = tue::run_normal(&mut m, 0, 120, |k, _| {
        if k == 60 {
            h.lock().app.board.supply = 32.0;
        }
        NormalOut {
            mcom: [1, 1, 1],
            setpoint: [500, 500, 500],
            ..NormalOut::default()
        }
    })
    .unwrap();
    let before = &rows[50].input;
    assert!(before.mstate.iter().all(|s| s & 1 == 1));
    assert!(before.current.iter().all(|&c| c > 300));
    let after = &rows[110].input;
    assert!(after.linevoltage > 3000);
    assert!(
        after.mstate.iter().all(|s| s & 1 == 0),
        "{:?}",
        after.mstate
    );
    let b = h.lock();
    assert!(b.app.counters.kills > 0);
    for k in 0..3 {
        assert!(!b.app.motors[k].enabled);
        // Not controlled: braking at 50/50 (the spinning motors' back-EMF drives the
        // braking current through the bridge).
        assert_eq!(b.app.board.drives[k].bridge.duty_a, 0.5);
        assert_eq!(b.app.board.drives[k].bridge.duty_b, 0.5);
    }
}

#[test]
fn parameters_written_and_read_back_change_the_firmware() {
    big(parameters_written_and_read_back_change_the_firmware_body);
}

fn parameters_written_and_read_back_change_the_firmware_body() {
    let (link, _seg, h) = bench();
    let m = Master::open(link).unwrap();
    assert_eq!(tue::read_params(&m, 0).unwrap(), TueParams::default());
    let p = TueParams {
        pgain: [6.0, 6.0, 1.0],
        igain: [4.0, 4.0, 0.0],
        ilimit: [1.0; 3],
        encdir: [-1, 1, 1],
        encres: [500, 1000, 2000],
        czero: [2100, 2168, 2200],
        ..params()
    };
    assert_eq!(tue::write_params(&m, 0, &p).unwrap(), p);
    assert_eq!(tue::read_params(&m, 0).unwrap(), p);
    let b = h.lock();
    assert_eq!(b.app.params[0].pgain, 6.0);
    assert_eq!(b.app.motors[0].par.pgain, 154);
    assert_eq!(b.app.motors[0].par.encdir, -1);
    assert_eq!(b.app.motors[2].par.increments, 8000);
    assert_eq!(b.app.motors[2].par.czero, 2200);
}

#[test]
fn mode_switch_to_frf_and_back() {
    big(mode_switch_to_frf_and_back_body);
}

fn mode_switch_to_frf_and_back_body() {
    let (link, _seg, h) = bench();
    let m = Master::open(link.clone()).unwrap();
    let (m, switched) = tue::set_mode(&link, m, 0, TueMode::Frf).unwrap();
    assert!(switched);
    let (mut m, again) = tue::set_mode(&link, m, 0, TueMode::Frf).unwrap();
    assert!(!again, "already in FRF mode");
    // A short FRF burst: 300 setpoints of 200 mA on M2.
    let sp = vec![200i16; 300];
    let run = tue::run_frf(&mut m, 0, 1, &sp, &mut |_, _| {}).unwrap();
    assert!(run.complete(), "{} of {}", run.currents.len(), sp.len());
    assert_eq!(h.lock().app.mode, oxicat_devices::tue_es030::Mode::Frf);
    assert_eq!(h.lock().slave.output_bytes(), 46);
    assert_eq!(h.lock().slave.input_bytes(), 49);
    let (mut m, switched) = tue::set_mode(&link, m, 0, TueMode::Normal).unwrap();
    assert!(switched);
    let rows = tue::run_normal(&mut m, 0, 20, |_, _| NormalOut::default()).unwrap();
    assert_eq!(rows.len(), 20);
    assert_eq!(h.lock().app.mode, oxicat_devices::tue_es030::Mode::Normal);
    assert_eq!(h.lock().slave.output_bytes(), 20);
    assert_eq!(h.lock().slave.input_bytes(), 64);
}

/// Identifies the closed current loop of M2 with gains (P, I, limit) from a short
/// multisine; returns the response and its margins.
fn identify(p: f32, i: f32, lim: f32) -> (Vec<tue::FrfPoint>, tue::Margins, tue::FrfRun) {
    let (link, _seg, _h) = bench();
    let m = Master::open(link.clone()).unwrap();
    let par = TueParams {
        pgain: [p; 3],
        igain: [i; 3],
        ilimit: [lim; 3],
        // Feed-forward off, as in the manual's identification.
        r: [0.0; 3],
        kv: [0.0; 3],
        encres: [500; 3],
        ..TueParams::default()
    };
    tue::write_params(&m, 0, &par).unwrap();
    let (mut m, _) = tue::set_mode(&link, m, 0, TueMode::Frf).unwrap();
    let period = 1000;
    let (sp, bins) = tue::multisine(period, 3, 40.0, 9800.0, 30, 400.0);
    let run = tue::run_frf(&mut m, 0, 1, &sp, &mut |_, _| {}).unwrap();
    let pts = tue::frequency_response(&run, period, &bins);
    let mg = tue::margins(&pts);
    (pts, mg, run)
}

#[test]
fn frf_identifies_the_closed_current_loop() {
    big(frf_body);
}

fn frf_body() {
    // The manual's settings: P = 6, I = 4, limit 1 (feed-forward off, axis free).
    let (pts, mg, run) = identify(6.0, 4.0, 1.0);
    assert!(run.complete(), "no sample lost");
    let share = tue::unexcited_share(&run, 1000, &BINS.with(|b| b.clone()));
    eprintln!("P=6: {mg:?}, unexcited share {share:.4}");
    for p in &pts {
        eprintln!(
            "{:8.1} Hz  T {:6.2} dB {:7.1} deg  L {:6.2} dB",
            p.f,
            p.t_db(),
            p.t_deg(),
            p.l_db()
        );
    }
    // Stable but lightly damped in the model: crossover of several kHz, small margin.
    let pm = mg.phase_margin.unwrap();
    let fc = mg.crossover.unwrap();
    assert!(pm > 0.0 && pm < 30.0, "PM {pm}");
    assert!(fc > 3000.0, "crossover {fc}");
    assert!(mg.peak_db > 6.0);
    assert!(share < 0.05, "linear: {share}");
    // P = 6/4.2 (the hardware's loop gain if its current scaling was for 42 mOhm).
    let (_, mg14, run14) = identify(6.0 / 4.2, 4.0, 1.0);
    let share14 = tue::unexcited_share(&run14, 1000, &BINS.with(|b| b.clone()));
    eprintln!("P=1.43: {mg14:?}, unexcited share {share14:.4}");
    let pm14 = mg14.phase_margin.unwrap();
    assert!(pm14 > 40.0 && pm14 < 70.0, "PM {pm14}");
    // P = 10: the model's loop is unstable: it oscillates at the PWM limit, most of the
    // current is at frequencies that were not excited.
    let (_, mg10, run10) = identify(10.0, 4.0, 1.0);
    let share10 = tue::unexcited_share(&run10, 1000, &BINS.with(|b| b.clone()));
    let peak10 = run10
        .currents
        .iter()
        .map(|c| c.unsigned_abs())
        .max()
        .unwrap_or(0);
    eprintln!("P=10: {mg10:?}, unexcited share {share10:.4}, peak current {peak10} mA");
    assert!(run10.complete());
    assert!(share10 > 0.3, "P=10 unstable: {share10}");
    assert!(peak10 > 2000);
}

thread_local! {
    static BINS: Vec<usize> = tue::multisine(1000, 1, 40.0, 9800.0, 30, 400.0).1;
}
