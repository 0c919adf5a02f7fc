//! TUeES030 on the virtual segment with the master side: normal-mode position loop, mode
//! switch, parameter write/read-back, watchdog braking, line-voltage kill, FRF.

use std::sync::{Arc, Mutex};

use oxicat_devices::tue_es030::experiment::{self as tue, NormalOut, TueMode, TueParams};
use oxicat_devices::tue_es030::rig::{attach, TueConfig, TueHandle};
use oxicat_devices::tue_es030::BoardRev;
use oxicat_master::{Link, Master};
use oxicat_sim::segment::Segment;

use oxicat_testkit::big;

fn bench() -> (Link, Arc<Mutex<Segment>>, TueHandle) {
    bench_with(&TueConfig::default())
}

fn bench_with(cfg: &TueConfig) -> (Link, Arc<Mutex<Segment>>, TueHandle) {
    let mut seg = Segment::new();
    let sii = oxicat_esi::sii::generate(&oxicat_devices::tue_es030::device::DEF).unwrap();
    let id = seg.add(oxicat_esc::Esc::new(oxicat_esc::EscConfig::et1200(), sii));
    let h = attach(&mut seg, id, cfg).unwrap();
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
    // The default board revision converts P with the 42 mOhm scale: 25.6 * 6 / 4.2.
    assert_eq!(b.app.board_rev, BoardRev::Sense42);
    assert_eq!(b.app.motors[0].par.pgain, 37);
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
fn identify(
    rev: BoardRev,
    p: f32,
    i: f32,
    lim: f32,
) -> (Vec<tue::FrfPoint>, tue::Margins, tue::FrfRun) {
    let (link, _seg, _h) = bench_with(&TueConfig::default().rev(rev));
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
    let bins = BINS.with(|b| b.clone());
    // The manual's settings: P = 6, I = 4, limit 1 (feed-forward off, axis free).
    // Literal gains (V/A as labelled): stable but lightly damped, crossover of several kHz.
    let (pts, mg, run) = identify(BoardRev::Literal, 6.0, 4.0, 1.0);
    assert!(run.complete(), "no sample lost");
    let share = tue::unexcited_share(&run, 1000, &bins);
    eprintln!("literal P=6: {mg:?}, unexcited share {share:.4}");
    for p in &pts {
        eprintln!(
            "{:8.1} Hz  T {:6.2} dB {:7.1} deg  L {:6.2} dB",
            p.f,
            p.t_db(),
            p.t_deg(),
            p.l_db()
        );
    }
    let pm = mg.phase_margin.unwrap();
    let fc = mg.crossover.unwrap();
    assert!(pm > 0.0 && pm < 30.0, "PM {pm}");
    assert!(fc > 3000.0, "crossover {fc}");
    assert!(mg.peak_db > 6.0);
    assert!(share < 0.05, "linear: {share}");
    // Literal P = 10: the model's loop is unstable: it oscillates at the PWM limit, most of
    // the current is at frequencies that were not excited.
    let (_, mg10, run10) = identify(BoardRev::Literal, 10.0, 4.0, 1.0);
    let share10 = tue::unexcited_share(&run10, 1000, &bins);
    let peak10 = run10
        .currents
        .iter()
        .map(|c| c.unsigned_abs())
        .max()
        .unwrap_or(0);
    eprintln!("literal P=10: {mg10:?}, unexcited share {share10:.4}, peak current {peak10} mA");
    assert!(run10.complete());
    assert!(share10 > 0.3, "P=10 unstable: {share10}");
    assert!(peak10 > 2000);
}

#[test]
fn board_revision_sense42_moves_the_p6_loop_towards_the_manual() {
    big(board_revision_body);
}

fn board_revision_body() {
    let bins = BINS.with(|b| b.clone());
    // The default revision (PI gains / 4.2): P = 6 crosses over near the manual's 2.5 kHz
    // with a margin of the manual's order (60 deg), where the literal one has < 30 deg.
    let (_, mg, run) = identify(BoardRev::Sense42, 6.0, 4.0, 1.0);
    let share = tue::unexcited_share(&run, 1000, &bins);
    eprintln!("sense42 P=6: {mg:?}, unexcited share {share:.4}");
    let pm = mg.phase_margin.unwrap();
    let fc = mg.crossover.unwrap();
    assert!((1000.0..3000.0).contains(&fc), "crossover {fc}");
    assert!(pm > 50.0 && pm < 90.0, "PM {pm}");
    assert!(mg.peak_db < 3.0, "well damped: {}", mg.peak_db);
    // ... and P = 10 stays stable (the manual's "P = 10 unstable" is not reproduced).
    let (_, mg10, run10) = identify(BoardRev::Sense42, 10.0, 4.0, 1.0);
    let share10 = tue::unexcited_share(&run10, 1000, &bins);
    eprintln!("sense42 P=10: {mg10:?}, unexcited share {share10:.4}");
    assert!(share10 < 0.05, "stable: {share10}");
    assert!(mg10.phase_margin.unwrap() > 30.0);
}

/// A current pulse (1 ms rest, 10 ms at `amp` mA, 3 ms rest) on locked M2 with `par`.
fn pulse_run(rev: BoardRev, par: &TueParams, amp: i16) -> tue::StepMetrics {
    let (link, _seg, h) = bench_with(&TueConfig::default().rev(rev).locked(true));
    let m = Master::open(link.clone()).unwrap();
    tue::write_params(&m, 0, par).unwrap();
    let (mut m, _) = tue::set_mode(&link, m, 0, TueMode::Frf).unwrap();
    let sp = tue::pulse(20, 200, 60, amp);
    let run = tue::run_frf(&mut m, 0, 1, &sp, &mut |_, _| {}).unwrap();
    assert!(run.complete());
    assert_eq!(h.lock().app.board.drives[1].angle, 0.0, "axis locked");
    tue::step_metrics(&run.setpoints, &run.currents).unwrap()
}

fn gains(p: f32, i: f32, r: f32, kv: f32) -> TueParams {
    TueParams {
        pgain: [p; 3],
        igain: [i; 3],
        ilimit: [1.0; 3],
        r: [r; 3],
        kv: [kv; 3],
        ..params()
    }
}

#[test]
fn step_responses_order_with_p_as_the_manual_describes() {
    big(step_body);
}

fn step_body() {
    // Manual Fig. 6.5: "a higher gain results in better steady-state tracking, but also in
    // a higher overshoot. A proportional gain of 10 already resulted in an unstable system".
    let lit: Vec<tue::StepMetrics> = [1.0, 2.0, 4.0, 6.0, 10.0]
        .iter()
        .map(|&p| pulse_run(BoardRev::Literal, &gains(p, 0.0, 0.0, 0.0), 1000))
        .collect();
    for (p, m) in [1, 2, 4, 6, 10].iter().zip(&lit) {
        eprintln!("literal P={p}: {m:?}");
    }
    for w in lit[..4].windows(2) {
        assert!(
            w[1].error_ma.abs() < w[0].error_ma.abs(),
            "tracking improves"
        );
        assert!(w[1].overshoot_pct > w[0].overshoot_pct, "overshoot grows");
        assert!(!w[1].unstable());
    }
    assert!(lit[4].unstable(), "P = 10 oscillates: {:?}", lit[4]);
    // The default revision (loop gain / 4.2): tracking still improves with P and P = 10
    // overshoots most, but stays stable.
    let s42: Vec<tue::StepMetrics> = [2.0, 6.0, 10.0]
        .iter()
        .map(|&p| pulse_run(BoardRev::Sense42, &gains(p, 0.0, 0.0, 0.0), 1000))
        .collect();
    for w in s42.windows(2) {
        assert!(w[1].error_ma.abs() < w[0].error_ma.abs());
    }
    assert!(
        s42[2].overshoot_pct > s42[1].overshoot_pct && s42[2].overshoot_pct > s42[0].overshoot_pct
    );
    assert!(!s42[2].unstable());
    // Fig. 6.6: I removes the steady-state error, a higher I is faster.
    let i: Vec<tue::StepMetrics> = [0.0, 1.0, 4.0]
        .iter()
        .map(|&i| pulse_run(BoardRev::Sense42, &gains(2.0, i, 0.0, 0.0), 1000))
        .collect();
    assert!(i[0].error_ma > 300.0, "P only: {:?}", i[0]);
    assert!(i[1].error_ma.abs() < 20.0 && i[2].error_ma.abs() < 20.0);
    assert!(i[2].rise_s.unwrap() < i[1].rise_s.unwrap());
}

#[test]
fn resistance_feed_forward_reduces_the_steady_state_error() {
    big(ff_r_body);
}

fn ff_r_body() {
    // Fig. 6.7: P = 0.2, increasing R raises the current; R = the motor's 0.611 Ohm makes
    // it follow the setpoint.
    let m: Vec<tue::StepMetrics> = [0.0, 0.3, 0.611, 1.5]
        .iter()
        .map(|&r| pulse_run(BoardRev::Sense42, &gains(0.2, 0.0, r, 0.0), 1000))
        .collect();
    for w in m.windows(2) {
        assert!(w[1].final_ma > w[0].final_ma, "more R, more current");
    }
    assert!(m[0].error_ma > 700.0, "{:?}", m[0]);
    assert!(
        m[2].error_ma.abs() < 0.1 * m[0].error_ma.abs(),
        "{:?}",
        m[2]
    );
    assert!(
        m[3].final_ma > 2000.0,
        "R = 1.5 over-compensates the model's 0.611 Ohm"
    );
}

#[test]
fn back_emf_feed_forward_reduces_the_velocity_error() {
    big(ff_emf_body);
}

fn ff_emf_body() {
    // Fig. 6.8: velocity loop P_v = 1 (mA per 0.1 rad/s) over the current loop P = 1,
    // I = 0, R = 0; KV feed-forward 0 against the manufacturer's 0.0259.
    let run = |kv: f32| {
        let (link, _seg, _h) = bench();
        let mut m = Master::open(link).unwrap();
        tue::write_params(&m, 0, &gains(1.0, 0.0, 0.0, kv)).unwrap();
        let rows = tue::run_velocity_loop(&mut m, 0, 1, 1.0).unwrap();
        assert_eq!(rows.len() as u64, tue::EMF_CYCLES);
        tue::emf_rms_error(&rows, 1)
    };
    let (e0, e1) = (run(0.0), run(0.0259));
    eprintln!("RMS velocity error: KV 0 {e0:.1} rad/s, KV 0.0259 {e1:.1} rad/s");
    assert!(e1 < 0.7 * e0, "{e1} vs {e0}");
}

thread_local! {
    static BINS: Vec<usize> = tue::multisine(1000, 1, 40.0, 9800.0, 30, 400.0).1;
}
