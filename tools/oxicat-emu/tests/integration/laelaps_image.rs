//! The Laelaps II leg-node board image (`firmware/laelaps-leg`), the bytes that would be
//! flashed, in the loop: executed instruction by instruction on the emulated STM32F446
//! with its LAN9252 on SPI1 and the leg (`oxicat_plant::Leg`, the host rig's plant and
//! configuration) on its PWM, direction and encoder pins (`oxicat_emu::laelaps`).
//!
//! - it boots, reaches PREOP and answers an SDO upload of 0x1018 with the leg node's
//!   identity;
//! - ethercrab (through `oxicat-master`) runs two emulated leg nodes in OP in DC mode with
//!   SYNC0 every 400 µs (the leg node's kit cycle) for 1,000 cycles, the right working
//!   counter every cycle, and the image's SYNC0 handler ran once per SYNC0 pulse;
//! - with `State_Machine = 1` and the thesis' trot parameters (Table 4-1, shortened), the
//!   joint angles the image reports follow the desired ones within the bound the host
//!   trot test derives for the PV loop: PWM → plant → encoder → eQEP capture → PIV, in
//!   machine code.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use oxicat_devices::laelaps::experiment::{pdo_place, var, PdoPlace, INPUTS};
use oxicat_devices::laelaps::hw::{U_MAX_HIP, U_MAX_KNEE};
use oxicat_devices::laelaps::results::sample;
use oxicat_devices::laelaps::rig::{LegId, RigConfig, KIT};
use oxicat_devices::laelaps::{device, Side};
use oxicat_emu::laelaps::LegBoardPlant;
use oxicat_emu::node::{EmulatedNode, NodeHandle};
use oxicat_emu::Board;
use oxicat_esc::{Esc, EscConfig};
use oxicat_master::cyclic::{CycleIo, CycleOptions, Flow};
use oxicat_master::{Link, Master};
use oxicat_pdi::sim::{BusConfig, Lan9252Model};
use oxicat_sim::segment::Segment;

/// SYNC0 of the image: EXTI3, IRQ 9.
const EXTI3: u16 = 16 + 9;
/// The priority of the image's ESC handlers (`PRIO_ESC`), which the main loop masks
/// while it polls the stack.
const PRIO_ESC: u8 = 0x20;
/// The image's build (the default, `RIGHT_LEG`).
const SIDE: Side = Side::Right;

use crate::common;

use common::Direct;

/// The board image (`firmware/laelaps-leg`, or `OXICAT_LAELAPS_IMAGE`).
fn image() -> Option<Vec<u8>> {
    common::image("laelaps-leg", "OXICAT_LAELAPS_IMAGE")
}

#[test]
fn the_leg_image_boots_reaches_preop_and_answers_its_identity() {
    let Some(img) = image() else { return };
    let def = device::device(SIDE);
    let esc = Esc::new(
        EscConfig::lan9252(),
        oxicat_esi::sii::generate(def).expect("SII of the leg node"),
    );
    let chip = Lan9252Model::handle(esc, BusConfig::mhz(22));
    let mut b = Board::new(&img, chip.clone()).expect("the image loads");
    let m = Direct { chip: chip.into() };
    // Boot: clocks, the 50 ms power-on wait, the LAN9252's init over SPI, the stack's
    // start-up, then the main loop polling every 400 µs (the SPI frame count keeps rising)
    // and the joint loop at 10 kHz.
    let up = b
        .run_until(200_000, 200_000_000, |b| {
            b.spi_stats().frames > 200 && b.exceptions_taken(16 + 54) > 100
        })
        .unwrap_or_else(|e| panic!("{e}"));
    let s = b.spi_stats();
    assert!(
        up,
        "the image did not reach its main loop: {s:?}, TIM6 {} ticks, PC {:#010x}",
        b.exceptions_taken(16 + 54),
        b.pc()
    );
    assert_eq!(s.bytes_without_cs, 0, "every byte inside a CS frame");
    assert!(b.time_ns() >= 50_000_000, "the 50 ms power-on wait ran");
    assert_eq!(m.chip.stats().protocol_errors, 0);
    assert_eq!(m.al_status(&b) & 0x1F, 0x01, "INIT after start-up");
    assert_eq!(b.pwm_duty(1, 1), Some(0.0), "knee amplifier at zero duty");
    assert_eq!(b.pwm_duty(1, 2), Some(0.0), "hip amplifier at zero duty");

    m.to_preop(&mut b, 20_000_000);
    m.assert_identity(&mut b, def.identity);
    eprintln!(
        "leg image: {} instructions, {:.1} ms simulated, SPI {:?}, TIM6 {} ticks",
        b.instructions(),
        b.time_ns() as f64 * 1e-6,
        b.spi_stats(),
        b.exceptions_taken(16 + 54)
    );
}

/// A segment of emulated leg nodes (LAN9252 ESCs with the leg node's SII), each with its
/// leg on the board's pins.
fn segment(img: &[u8], legs: &[LegId]) -> (Segment, Vec<NodeHandle>) {
    let mut seg = Segment::new();
    let mut handles = Vec::new();
    for &leg in legs {
        assert_eq!(leg.side(), SIDE, "the image is the {SIDE:?} build");
        let sii = oxicat_esi::sii::generate(device::device(SIDE)).unwrap();
        let id = seg.add(Esc::new(EscConfig::lan9252(), sii));
        let plant = LegBoardPlant::new(leg, RigConfig::laelaps(leg));
        let node = EmulatedNode::with_plant(img.to_vec(), 100_000, Some(Box::new(plant))).unwrap();
        handles.push(node.handle());
        seg.attach(id, Box::new(node)).unwrap();
    }
    (seg, handles)
}

#[test]
fn ethercrab_runs_two_emulated_leg_nodes_in_dc_op_without_losing_a_sync0() {
    dc_op(1_000);
}

/// The long run: 10,000 DC cycles (about 4 s of segment time, a couple of minutes
/// of wall time here), `cargo test -p oxicat-emu --test integration laelaps_image:: -- --ignored`.
#[test]
#[ignore = "long: 10,000 cycles of two emulated boards"]
fn ethercrab_runs_two_emulated_leg_nodes_for_10000_dc_cycles() {
    dc_op(10_000);
}

/// Two emulated leg nodes in DC OP at the bench's 400 µs for `cycles` cycles: the right
/// working counter every cycle, every SYNC0 handled, the stack in operation bounded.
fn dc_op(cycles: u64) {
    let Some(img) = image() else { return };
    assert_eq!(KIT.cycle_ns, 400_000u32, "the leg node's bench cycle");
    let (seg, nodes) = segment(&img, &[LegId::HindRight, LegId::ForeRight]);
    let wall = std::time::Instant::now();
    let mut m = Master::open(Link::Sim(Arc::new(Mutex::new(seg)))).expect("ethercrab scans");
    // From here on (booted, in the main loop): handler times and the painted stack.
    for n in &nodes {
        n.reset_stats();
    }
    let stats = m
        .run_cycles(
            CycleOptions {
                cycle: Duration::from_nanos(u64::from(KIT.cycle_ns)),
                dc: true,
            },
            cycles,
        )
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((stats.cycles, stats.wkc_errors), (cycles, 0), "{stats:?}");
    for (k, n) in nodes.iter().enumerate() {
        let r = n.report().expect("the board thread runs");
        assert_eq!(r.fault, None, "node {k}");
        let pulses = n.sync0_events();
        let handled = r.taken[usize::from(EXTI3)];
        eprintln!(
            "node {k}: {pulses} SYNC0 pulses, {handled} EXTI3 handler runs, SYNC0 handler max {:.1} µs",
            r.handler(EXTI3).max_cycles as f64 / 180.0
        );
        // SYNC0 starts at the DC start time oxicat-master sets, 4.5 cycles after it
        // configures DC and before SAFE-OP: the master may count up to five cycles before
        // the first pulse when the slaves reach OP quickly. From then on every cycle has one.
        assert!(
            pulses + 5 >= cycles,
            "node {k}: {pulses} SYNC0 pulses in {cycles} cycles"
        );
        assert_eq!(handled, pulses, "node {k}: a SYNC0 was lost");
        // Issue 15: the main loop polls the stack with the ESC handlers masked (BASEPRI
        // 0x20). A span longer than the SYNC0 cycle can swallow a SYNC0 edge whenever two
        // fall into it, as one did in the four-image trot; whether one does is a matter of
        // phase, so the span itself is bounded: bring-up (PREOP -> SAFEOP under SYNC0
        // included, since boot) holds them off for less than a cycle.
        assert_eq!(r.lost_edges_on(3), 0, "node {k}: {:?}", r.lost_edges);
        let (span, func) = r.masked(PRIO_ESC);
        let span_ns = span.max_cycles * 1_000_000_000 / oxicat_emu::CPU_HZ;
        eprintln!(
            "node {k}: ESC handlers masked by the thread {:.1} µs at most (from {:.2} ms, PC {:#010x} in {})",
            span_ns as f64 * 1e-3,
            span.start_cycle as f64 * 1e3 / oxicat_emu::CPU_HZ as f64,
            span.pc,
            func.unwrap_or("?")
        );
        assert!(
            span.max_cycles > 0,
            "node {k}: the thread masks the ESC handlers when it polls"
        );
        assert!(
            span_ns < u64::from(KIT.cycle_ns),
            "node {k}: the ESC handlers masked for {span_ns} ns, longer than a SYNC0 cycle"
        );
        // The stack in operation (main loop, the ESC handlers and the joint loop nested
        // on it): `main`'s own frame once held the stack and application for good
        // (21.9 KB: 23.1 KB deepest in operation); built in functions of their own they
        // leave it when started (8.6 KB: `main`'s 5.5 KB, the stack's poll inlined, plus
        // the handlers).
        let depth = r.stack.max_depth;
        eprintln!("node {k}: stack {depth} B deepest in operation");
        assert!(
            depth <= 12 * 1024,
            "node {k}: {depth} B of stack in operation"
        );
    }
    eprintln!(
        "two emulated leg nodes: {cycles} DC cycles of 400 µs in OP, {:.1} s wall",
        wall.elapsed().as_secs_f64()
    );
}

/// The shipped scenario's Table 4-1 outputs for `leg` as raw PDO integers (the experiment's
/// scaling): gains ×100 / ×1000, ellipse in mm and whole cm, frequency ×100.
fn trot_outputs(io: &mut CycleIo, pos: usize, leg: LegId, operational: bool, ab: bool) {
    use oxicat_devices::laelaps::scenario::Scenario;
    let s = Scenario::thesis();
    let def = device::device(SIDE);
    let t = s.leg(leg);
    let c = &s.control;
    let p = |i: u16, sub: u8| pdo_place(def, true, i, sub).expect("a leg-node output");
    let r = |v: f64| v.round() as i64;
    let img = &mut io.outputs[pos];
    p(0x7000, 1).put(img, i64::from(operational));
    p(0x7000, 9).put(img, 1); // Transition_time 1 s (the host test's shortened run)
    p(0x7012, 1).put(img, i64::from(c.filter_hz));
    let gains = [
        c.knee.kp * 100.0,
        c.knee.kd * 1000.0,
        c.knee.ki * 100.0,
        c.hip.kp * 100.0,
        c.hip.kd * 1000.0,
        c.hip.ki * 100.0,
    ];
    for (k, g) in gains.into_iter().enumerate() {
        p(0x7020, k as u8 + 1).put(img, r(g));
    }
    let (a, b) = if ab { (t.a_cm, t.b_cm) } else { (0.0, 0.0) };
    let traj = [
        t.x_centre_cm * 10.0,
        t.y_centre_cm * 10.0,
        a,
        b,
        t.freq_hz * 100.0,
        t.phase_deg,
        t.flatness * 100.0,
    ];
    for (k, v) in traj.into_iter().enumerate() {
        p(0x7030, k as u8 + 1).put(img, r(v));
    }
}

/// The trot on one emulated leg node: Configuration with every Table 4-1 parameter for
/// 1.1 s (the gains ramp in over Transition_time = 1 s), then `State_Machine = 1` with the
/// ellipse's a and b (ramping in over 1 s) for 1.2 s: the measured angles the image reports
/// follow the desired ones within the host trot test's PV-loop bound.
#[test]
fn the_leg_image_tracks_the_trot_through_pwm_plant_and_encoders() {
    let Some(img) = image() else { return };
    let leg = LegId::ForeRight;
    let (seg, nodes) = segment(&img, &[leg]);
    let scenario = oxicat_devices::laelaps::scenario::Scenario::thesis();
    let (kp, kd) = (scenario.control.knee.kp, scenario.control.knee.kd);
    let def = device::device(SIDE);
    let places: Vec<(PdoPlace, bool)> = INPUTS
        .iter()
        .map(|v| {
            (
                pdo_place(def, false, v.index, v.sub).expect("an input"),
                v.signed,
            )
        })
        .collect();
    let mut m = Master::open(Link::Sim(Arc::new(Mutex::new(seg)))).expect("ethercrab scans");
    let cyc = 1e-9 * f64::from(KIT.cycle_ns);
    let settle = (1.1 / cyc) as u64;
    let end = settle + (1.2 / cyc) as u64;
    let mut rows: Vec<[i32; 9]> = Vec::new();
    let stats = m
        .run_cyclic(
            CycleOptions {
                cycle: Duration::from_nanos(u64::from(KIT.cycle_ns)),
                dc: true,
            },
            |io| {
                let k = io.cycle;
                if k >= settle {
                    let mut raw = [0i32; 9];
                    for (x, (p, signed)) in raw.iter_mut().zip(&places) {
                        *x = p.get(&io.inputs[0], *signed);
                    }
                    rows.push(raw);
                }
                trot_outputs(io, 0, leg, k + 1 >= settle, k + 1 >= settle);
                Ok(if k + 1 >= end {
                    Flow::Stop
                } else {
                    Flow::Continue
                })
            },
        )
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(stats.wkc_errors, 0, "{stats:?}");
    let r = nodes[0].report().expect("the board thread runs");
    assert_eq!(r.fault, None);

    // The trajectory clock runs; the leg was let go and moved.
    let last = sample(rows.last().expect("recorded cycles"), leg);
    assert!(last.time > 1.0, "trajectory clock {} s", last.time);
    let tau = std::f64::consts::TAU;
    let (mut knee_max, mut hip_max, mut knee_speed, mut hip_speed) = (0f64, 0f64, 0f64, 0f64);
    let (mut knee_span, mut hip_span) = ((f64::MAX, f64::MIN), (f64::MAX, f64::MIN));
    let (mut ek2, mut eh2) = (0.0, 0.0);
    for raw in &rows {
        let x = sample(raw, leg);
        let (ek, eh) = (
            (x.knee - x.knee_des).to_degrees(),
            (x.hip - x.hip_des).to_degrees(),
        );
        knee_max = knee_max.max(ek.abs());
        hip_max = hip_max.max(eh.abs());
        ek2 += ek * ek;
        eh2 += eh * eh;
        knee_speed = knee_speed.max(x.speed_knee.abs());
        hip_speed = hip_speed.max(x.speed_hip.abs());
        knee_span = (knee_span.0.min(x.knee), knee_span.1.max(x.knee));
        hip_span = (hip_span.0.min(x.hip), hip_span.1.max(x.hip));
    }
    let n = rows.len() as f64;
    let (knee_rms, hip_rms) = ((ek2 / n).sqrt(), (eh2 / n).sqrt());
    // The host trot test's bound (tests/trot.rs in oxicat-devices): |e| ≤ 2π·u_max/Kp +
    // Kd·max|θ̇| (the PV loop's velocity lag) + resolution + 0.5° at the PWM limit.
    let slack_deg = 0.01 + 0.01 + 0.5;
    let knee_bound = (tau * f64::from(U_MAX_KNEE) / kp + kd * knee_speed).to_degrees() + slack_deg;
    let hip_bound = (tau * f64::from(U_MAX_HIP) / kp + kd * hip_speed).to_degrees() + slack_deg;
    let st = nodes[0].report().map(|r| r.taken[16 + 54]).unwrap_or(0);
    eprintln!(
        "{}: knee max {knee_max:.2}° (bound {knee_bound:.2}°, RMS {knee_rms:.2}°, swing {:.1}°), \
         hip max {hip_max:.2}° (bound {hip_bound:.2}°, RMS {hip_rms:.2}°, swing {:.1}°), \
         peak joint speeds {knee_speed:.2} / {hip_speed:.2} rad/s, {st} joint-loop ticks",
        leg.code(),
        (knee_span.1 - knee_span.0).to_degrees(),
        (hip_span.1 - hip_span.0).to_degrees(),
    );
    assert!(
        knee_speed > 0.5 && hip_speed > 0.5,
        "the leg moves: {knee_speed} / {hip_speed} rad/s"
    );
    assert!(
        (knee_span.1 - knee_span.0).to_degrees() > 5.0
            && (hip_span.1 - hip_span.0).to_degrees() > 5.0,
        "the joints swing"
    );
    assert!(
        knee_max <= knee_bound,
        "knee: {knee_max:.2}° > {knee_bound:.2}°"
    );
    assert!(hip_max <= hip_bound, "hip: {hip_max:.2}° > {hip_bound:.2}°");
    assert!(
        knee_rms < 5.0 && hip_rms < 6.0,
        "RMS {knee_rms:.2}° / {hip_rms:.2}°"
    );
    let _ = var::TIME;
}
