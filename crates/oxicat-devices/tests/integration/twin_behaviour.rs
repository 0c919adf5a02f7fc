//! Issue 16 item 2: behaviour of a twin's process data, seen by ethercrab (through
//! `oxicat-master`, in process) on twins made from vendor ESIs in `reference/`.
//!
//! - A CiA402 twin of Synapticon's SOMANET ESI (ProfileNo 402; its PDOs carry 0x6040,
//!   0x6060, 0x6071, 0x607A, 0x60FF out and 0x6041, 0x6061, 0x6064, 0x606C, 0x6077 in) runs
//!   oxicat's drive on the default motor plant: 0x06/0x07/0x0F walk the statusword through
//!   Ready to switch on, Switched on, Operation enabled; 0x6060 = 8 shows in 0x6061; a CSP
//!   position ramp is followed.
//! - Loop-back: an output written in one cycle's frame comes back as the paired input in
//!   the next cycle's frame.
//! - Signals: a sine input equals the formula at the virtual time of the main-loop pass that
//!   wrote it; a held input keeps its value; `hold` as device behaviour leaves the ESI
//!   defaults alone.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use oxicat_devices::cia402::State;
use oxicat_devices::registry::{add_device_node, Device};
use oxicat_devices::twin::behaviour::{Behaviour, EntrySpec, Rule, SineSpec};
use oxicat_devices::twin::{load, with_behaviour, Twin};
use oxicat_master::cyclic::{CycleOptions, Flow};
use oxicat_master::pdo::{variables, Dir, Variable};
use oxicat_master::{Link, Master};
use oxicat_sim::pdi_path::PdiRoute;
use oxicat_sim::segment::Segment;
use oxicat_testkit::served::reference;

use oxicat_testkit::big;

fn twin(file: &str) -> &'static Twin {
    let p = reference().join(file);
    load(&p.display().to_string()).unwrap_or_else(|e| panic!("{e}"))
}

/// One twin on a segment, the master on it, and the segment to read its clock.
fn open(t: &'static Twin) -> (Master, Arc<Mutex<Segment>>, Vec<Variable>) {
    let mut seg = Segment::new();
    add_device_node(&mut seg, Device::Twin(t), 0, 0.0, PdiRoute::Direct).unwrap();
    let seg = Arc::new(Mutex::new(seg));
    let mut m = Master::open(Link::Sim(seg.clone())).unwrap();
    m.prepare_cyclic().unwrap();
    let vars = variables(&m.pdos(0).unwrap());
    (m, seg, vars)
}

fn var(vars: &[Variable], dir: Dir, object: (u16, u8)) -> Variable {
    vars.iter()
        .find(|v| v.dir == dir && v.object == object)
        .unwrap_or_else(|| panic!("{dir:?} {object:04x?} is not mapped"))
        .clone()
}

fn int(b: &[u8], signed: bool) -> i64 {
    let mut a = [0u8; 8];
    a[..b.len().min(8)].copy_from_slice(&b[..b.len().min(8)]);
    let v = u64::from_le_bytes(a);
    let bits = 8 * b.len().min(8) as u32;
    if signed && bits < 64 && v >> (bits - 1) & 1 == 1 {
        (v | (u64::MAX << bits)) as i64
    } else {
        v as i64
    }
}

/// What [`enable_and_ramp`] saw.
struct DriveRun {
    /// (controlword, state reached) per step of the enable sequence.
    seen: Vec<(u16, State)>,
    /// 0x6061 in the last cycle.
    mode_display: i64,
    /// Largest |set-point sent last cycle − actual position| during the ramp.
    max_err: i64,
    /// Final position − final target.
    end_err: i64,
}

const STEPS: [(u16, State); 3] = [
    (0x06, State::ReadyToSwitchOn),
    (0x07, State::SwitchedOn),
    (0x0F, State::OperationEnabled),
];
const MOVE: i64 = 40_000;
const RAMP: u64 = 800;

/// Walks slave 0 through 0x06/0x07/0x0F (the statusword read back after each; CSP sent in
/// 0x6060 when the PDOs carry it), then streams an 800 ms cosine ramp of [`MOVE`] counts in
/// 0x607A at 1 kHz DC and lets it settle 150 ms.
fn enable_and_ramp(m: &mut Master, vars: &[Variable]) -> DriveRun {
    let cw = var(vars, Dir::Output, (0x6040, 0));
    let mode = vars
        .iter()
        .find(|v| v.dir == Dir::Output && v.object == (0x6060, 0))
        .cloned();
    let target = var(vars, Dir::Output, (0x607A, 0));
    let sw = var(vars, Dir::Input, (0x6041, 0));
    let mode_display = var(vars, Dir::Input, (0x6061, 0));
    let pos = var(vars, Dir::Input, (0x6064, 0));
    // Phases: 0 wait for Switch on disabled, 1..=3 the controlwords, 4 the ramp, 5 settle.
    let mut phase = 0usize;
    let mut since = 0u64;
    let mut run = DriveRun {
        seen: Vec::new(),
        mode_display: 0,
        max_err: 0,
        end_err: i64::MAX,
    };
    let mut start_pos = 0i64;
    let mut last_target = 0i64;
    let stats = m
        .run_cyclic(
            CycleOptions {
                cycle: Duration::from_millis(1),
                dc: true,
            },
            |io| {
                let s = int(&io.get(&sw), false) as u16;
                let state = State::decode(s);
                let p = int(&io.get(&pos), true);
                run.mode_display = int(&io.get(&mode_display), true);
                since += 1;
                assert!(
                    phase >= 4 || since < 200,
                    "phase {phase}: statusword {s:#06x} ({state:?})"
                );
                match phase {
                    0 => {
                        if let Some(mode) = &mode {
                            io.set(mode, &[8]).unwrap();
                        }
                        io.set(&cw, &0u16.to_le_bytes()).unwrap();
                        if state == Some(State::SwitchOnDisabled) {
                            phase = 1;
                            since = 0;
                            io.set(&cw, &STEPS[0].0.to_le_bytes()).unwrap();
                        }
                    }
                    1..=3 => {
                        let (c, want) = STEPS[phase - 1];
                        if state == Some(want) {
                            run.seen.push((c, want));
                            phase += 1;
                            since = 0;
                            if phase <= 3 {
                                io.set(&cw, &STEPS[phase - 1].0.to_le_bytes()).unwrap();
                            } else {
                                start_pos = p;
                                last_target = p;
                            }
                        }
                    }
                    4 => {
                        // The set-point sent last cycle against the position now: the
                        // drive runs one cycle behind the frame.
                        run.max_err = run.max_err.max((last_target - p).abs());
                        let k = since.min(RAMP) as f64 / RAMP as f64;
                        let x = 0.5 - 0.5 * (std::f64::consts::PI * k).cos();
                        let tp = start_pos + (MOVE as f64 * x).round() as i64;
                        io.set(&target, &(tp as i32).to_le_bytes()).unwrap();
                        last_target = tp;
                        if since >= RAMP {
                            phase = 5;
                            since = 0;
                        }
                    }
                    _ => {
                        run.end_err = p - (start_pos + MOVE);
                        if since >= 150 {
                            return Ok(Flow::Stop);
                        }
                    }
                }
                Ok(Flow::Continue)
            },
        )
        .unwrap();
    assert_eq!(stats.wkc_errors, 0);
    run
}

#[test]
fn a_cia402_twin_from_a_vendor_esi_enables_and_follows_a_csp_ramp_under_ethercrab() {
    big(|| {
        let t = twin("esi-vendor/SOMANET_CiA_402.xml");
        assert_eq!(t.esi.profile_no, Some(402));
        assert!(
            t.drives(),
            "the SOMANET twin runs the CiA402 drive by profile"
        );
        let (mut m, _seg, vars) = open(t);
        let run = enable_and_ramp(&mut m, &vars);
        assert_eq!(
            run.seen,
            STEPS.to_vec(),
            "statusword after 0x06, 0x07, 0x0F"
        );
        assert_eq!(run.mode_display, 8, "0x6061 shows CSP");
        eprintln!(
            "SOMANET twin, CSP ramp of {MOVE} counts: max following error {}, end {}",
            run.max_err, run.end_err
        );
        assert!(run.max_err < 400, "max following error {}", run.max_err);
        assert!(run.end_err.abs() < 50, "ended {} counts off", run.end_err);
    });
}

/// Ingenia's EVS-NET-01 (ProfileNo 402, but 0x1000 = 4): the master assigns the alternative
/// RxPDO 0x1601 (controlword and target position only) in PREOP, so the mode goes by SDO
/// (0x6060 is in the dictionary, not in those PDOs); the twin resolves the new layout when
/// it enters SAFEOP. The ESI's following-error window (0x6065 = 100 counts for 0x6066 =
/// 10 ms) is the drive's, and the ramp stays within it.
#[test]
fn a_cia402_twin_runs_on_a_pdo_layout_the_master_chose() {
    big(|| {
        let t = twin("esi-vendor/ingenia_esi.xml");
        assert_eq!(t.esi.def.device_type & 0xFFFF, 4);
        assert!(t.drives(), "ProfileNo 402 with 0x6040/0x6041: the drive");
        let (mut m, _seg, _) = open(t);
        m.sdo_download(0, 0x1C12, 0, &[0]).unwrap();
        m.sdo_download(0, 0x1C12, 1, &0x1601u16.to_le_bytes())
            .unwrap();
        m.sdo_download(0, 0x1C12, 0, &[1]).unwrap();
        m.sdo_download(0, 0x6060, 0, &[8]).unwrap();
        let vars = variables(&m.pdos(0).unwrap());
        let outs: Vec<(u16, u8)> = vars
            .iter()
            .filter(|v| v.dir == Dir::Output)
            .map(|v| v.object)
            .collect();
        assert_eq!(outs, vec![(0x6040, 0), (0x607A, 0)]);
        let run = enable_and_ramp(&mut m, &vars);
        assert_eq!(
            run.seen,
            STEPS.to_vec(),
            "statusword after 0x06, 0x07, 0x0F"
        );
        assert_eq!(run.mode_display, 8, "0x6061 shows the mode set by SDO");
        eprintln!(
            "Ingenia twin on 0x1601, CSP ramp of {MOVE} counts: max following error {}, end {}",
            run.max_err, run.end_err
        );
        assert!(run.max_err < 400, "max following error {}", run.max_err);
        assert!(run.end_err.abs() < 50, "ended {} counts off", run.end_err);
    });
}

#[test]
fn loop_back_outputs_appear_in_the_inputs_of_the_next_cycle() {
    big(|| {
        let t = twin("esi/soes-linux_lan9252demo-slave.xml");
        assert!(!t.drives());
        let (mut m, _seg, vars) = open(t);
        let out = var(&vars, Dir::Output, (0x7000, 1));
        let inp = var(&vars, Dir::Input, (0x6000, 1));
        // sent[k]: the output in cycle k's frame (set after cycle k-1); got[k]: the input.
        let mut sent: Vec<u8> = Vec::new();
        let mut got: Vec<u8> = Vec::new();
        m.run_cyclic(CycleOptions::default(), |io| {
            sent.push(io.get(&out)[0]);
            got.push(io.get(&inp)[0]);
            io.set(&out, &[(io.cycle as u8).wrapping_mul(37).wrapping_add(1)])
                .unwrap();
            Ok(if io.cycle >= 60 {
                Flow::Stop
            } else {
                Flow::Continue
            })
        })
        .unwrap();
        for k in 2..got.len() {
            assert_eq!(got[k], sent[k - 1], "cycle {k}: {got:?} / {sent:?}");
        }
        assert!(got[2..].windows(2).all(|w| w[0] != w[1]), "{got:?}");
    });
}

/// The 50 µs grid instants at or before `now`, latest first: the main-loop passes that may
/// have written the inputs a frame at `now` read.
fn passes(now: u64) -> impl Iterator<Item = f64> {
    let last = now / 50_000 * 50_000;
    (0..6u64).map(move |j| last.saturating_sub(j * 50_000) as f64 * 1e-9)
}

#[test]
fn a_sine_input_follows_the_formula_at_virtual_time_and_held_inputs_hold() {
    big(|| {
        let base = twin("esi/kickcat-freedom-k64f.xml");
        let b = Behaviour::compile(
            None,
            &[
                EntrySpec {
                    entry: "0x6001:0".into(),
                    sine: Some(SineSpec {
                        amplitude: 1000.0,
                        frequency_hz: 2.0,
                        offset: 100.0,
                        phase_deg: 30.0,
                    }),
                    ..Default::default()
                },
                EntrySpec {
                    entry: "0x6000:0".into(),
                    hold: Some(-1234.0),
                    ..Default::default()
                },
            ],
            base.esi.def,
            "device[0]",
        )
        .unwrap();
        let sine = match &b.entries[0].1 {
            Rule::Signal(s) => s.clone(),
            r => panic!("{r:?}"),
        };
        let t = with_behaviour(base, b);
        let (mut m, seg, vars) = open(t);
        let s_var = var(&vars, Dir::Input, (0x6001, 0));
        let h_var = var(&vars, Dir::Input, (0x6000, 0));
        let auto_var = var(&vars, Dir::Input, (0x6002, 0));
        let mut checked = 0;
        let mut autos = Vec::new();
        m.run_cyclic(CycleOptions::default(), |io| {
            let now = seg.lock().unwrap().now();
            let v = int(&io.get(&s_var), true);
            let h = int(&io.get(&h_var), true);
            autos.push(int(&io.get(&auto_var), true));
            if io.cycle >= 2 {
                assert_eq!(h, -1234, "cycle {}", io.cycle);
                let hit = passes(now).find(|&t| sine.value(t).round() as i64 == v);
                assert!(
                    hit.is_some(),
                    "cycle {} at {now} ns: {v}, formula {:?}",
                    io.cycle,
                    passes(now)
                        .map(|t| sine.value(t).round())
                        .collect::<Vec<_>>()
                );
                checked += 1;
            }
            Ok(if io.cycle >= 1100 {
                Flow::Stop
            } else {
                Flow::Continue
            })
        })
        .unwrap();
        assert!(checked >= 1099);
        // An input the file does not name: by profile (no CiA402, no pair) an analog value
        // gets the default signal, a 1 Hz sine over a quarter of the INT range (±8192; the
        // run covers a period).
        let (lo, hi) = (
            *autos[2..].iter().min().unwrap(),
            *autos[2..].iter().max().unwrap(),
        );
        assert!(
            lo < -8000 && hi > 8000 && lo >= -8192 && hi <= 8192,
            "{lo} … {hi}"
        );
    });
}

#[test]
fn hold_as_device_behaviour_leaves_the_inputs_at_their_esi_defaults() {
    big(|| {
        let base = twin("esi/kickcat-freedom-k64f.xml");
        let b = Behaviour::compile(Some("hold"), &[], base.esi.def, "device[0]").unwrap();
        let t = with_behaviour(base, b);
        let (mut m, _seg, vars) = open(t);
        let ins: Vec<Variable> = vars
            .iter()
            .filter(|v| v.dir == Dir::Input)
            .cloned()
            .collect();
        assert!(!ins.is_empty());
        let mut first: Option<Vec<Vec<u8>>> = None;
        m.run_cyclic(CycleOptions::default(), |io| {
            let now: Vec<Vec<u8>> = ins.iter().map(|v| io.get(v)).collect();
            match &first {
                None => first = Some(now),
                Some(f) => assert_eq!(&now, f, "cycle {}", io.cycle),
            }
            Ok(if io.cycle >= 50 {
                Flow::Stop
            } else {
                Flow::Continue
            })
        })
        .unwrap();
    });
}

/// A twin its ESC serves alone (no mailbox, no firmware): the AX58100 evaluation board's
/// 16 digital outputs (SMs at 0x0F02 and 0x0F03) and 16 inputs (0x1000) on the ESC's
/// digital-I/O pins. By default the output pins are wired to the input pins in pairs.
#[test]
fn an_esc_only_digital_io_twin_loops_its_output_pins_to_its_input_pins() {
    big(|| {
        let t = twin("esi-vendor/AX58100_EVB_DIO_ESI_00010200_00000001_20220323.xml");
        assert_eq!(t.esi.served, oxicat_esi::twin::Served::EscOnly);
        let (mut m, _seg, vars) = open(t);
        let outs = [
            var(&vars, Dir::Output, (0x3101, 1)),
            var(&vars, Dir::Output, (0x3101, 2)),
        ];
        let ins = [
            var(&vars, Dir::Input, (0x3001, 1)),
            var(&vars, Dir::Input, (0x3001, 2)),
        ];
        let mut sent: Vec<[u8; 2]> = Vec::new();
        let mut got: Vec<[u8; 2]> = Vec::new();
        m.run_cyclic(CycleOptions::default(), |io| {
            sent.push([io.get(&outs[0])[0], io.get(&outs[1])[0]]);
            got.push([io.get(&ins[0])[0], io.get(&ins[1])[0]]);
            let c = io.cycle as u8;
            io.set(&outs[0], &[c.wrapping_mul(37).wrapping_add(1)])
                .unwrap();
            io.set(&outs[1], &[c.wrapping_mul(11) ^ 0x5A]).unwrap();
            Ok(if io.cycle >= 60 {
                Flow::Stop
            } else {
                Flow::Continue
            })
        })
        .unwrap();
        for k in 2..got.len() {
            assert_eq!(got[k], sent[k - 1], "cycle {k}: {got:?} / {sent:?}");
        }
        assert!(got[2..].windows(2).all(|w| w[0] != w[1]), "{got:?}");
    });
}

/// Per-entry rules on an ESC-only twin: a held value and a ramp on the input pins, the
/// other byte's loop replaced; an entry not on the pins, and `drive`, are refused.
#[test]
fn an_esc_only_twin_takes_held_and_signal_inputs_and_refuses_what_its_pins_cannot() {
    use oxicat_devices::twin::behaviour::RampSpec;
    use oxicat_devices::twin::pins::Pins;
    big(|| {
        let base = twin("esi-vendor/AX58100_EVB_DIO_ESI_00010200_00000001_20220323.xml");
        let b = Behaviour::compile(
            None,
            &[
                EntrySpec {
                    entry: "0x3001:1".into(),
                    hold: Some(0xA5 as f64),
                    ..Default::default()
                },
                EntrySpec {
                    entry: "0x3001:2".into(),
                    ramp: Some(RampSpec {
                        slope_per_s: 1000.0,
                        start: 0.0,
                        min: Some(0.0),
                        max: Some(256.0),
                    }),
                    ..Default::default()
                },
            ],
            base.esi.def,
            "device[0]",
        )
        .unwrap();
        let t = with_behaviour(base, b);
        let (mut m, seg, vars) = open(t);
        let held = var(&vars, Dir::Input, (0x3001, 1));
        let ramp = var(&vars, Dir::Input, (0x3001, 2));
        let out = var(&vars, Dir::Output, (0x3101, 1));
        let mut checked = 0;
        m.run_cyclic(CycleOptions::default(), |io| {
            io.set(&out, &[0x3C]).unwrap();
            if io.cycle >= 2 {
                let now = seg.lock().unwrap().now();
                assert_eq!(io.get(&held)[0], 0xA5, "cycle {}", io.cycle);
                // Sampled on the 50 µs grid before the frame: within one sample of now.
                let v = io.get(&ramp)[0] as f64;
                let hit = passes(now).any(|t| ((t * 1000.0).round() % 256.0) == v);
                assert!(hit, "cycle {} at {now} ns: {v}", io.cycle);
                checked += 1;
            }
            Ok(if io.cycle >= 300 {
                Flow::Stop
            } else {
                Flow::Continue
            })
        })
        .unwrap();
        assert!(checked >= 299);

        // An output entry is not an input pin; `drive` needs firmware.
        let def = base.esi.def;
        let out_rule = Behaviour {
            entries: vec![((0x3101, 1), Rule::Hold(1.0))],
            ..Default::default()
        };
        let e = Pins::new(def, &base.esi.sii, &out_rule).err().unwrap();
        assert!(e.contains("not on the ESC's input pins"), "{e}");
        let drive = Behaviour {
            mode: oxicat_devices::twin::behaviour::Mode::Drive,
            ..Default::default()
        };
        let e = Pins::new(def, &base.esi.sii, &drive).err().unwrap();
        assert!(e.contains("needs firmware"), "{e}");
    });
}

/// The input of a counter by profile (EL5151's 0x6000:0x11 "Counter value") counts the
/// encoder of a motor plant: by default the RE 30 at 2 V, which runs up to about 12 rev/s
/// (2000 counts per turn). Per entry, the voltage can come from an output the master sets
/// (`encoder = { from, volts_per_unit }`): at 0 V the count stands, at 6 V it runs about
/// three times as fast as at 2 V.
#[test]
fn encoder_counts_come_from_a_motor_plant() {
    use oxicat_devices::twin::behaviour::EncoderSpec;
    /// Counts per second over the last `n` cycles (1 ms each) of `counts`.
    fn rate(counts: &[u32], n: usize) -> f64 {
        let w = &counts[counts.len() - n..];
        w[n - 1].wrapping_sub(w[0]) as i32 as f64 / ((n - 1) as f64 * 1e-3)
    }
    big(|| {
        let base = twin("esi-vendor/Beckhoff-EL5xxx.xml:EL5151");
        // By profile.
        let (mut m, _seg, vars) = open(base);
        let cv = var(&vars, Dir::Input, (0x6000, 0x11));
        let mut counts = Vec::new();
        m.run_cyclic(CycleOptions::default(), |io| {
            counts.push(u32::from_le_bytes(io.get(&cv)[..4].try_into().unwrap()));
            Ok(if io.cycle >= 800 {
                Flow::Stop
            } else {
                Flow::Continue
            })
        })
        .unwrap();
        let r = rate(&counts, 200);
        // No-load speed at 2 V: (2 V − R·I₀)/k ≈ 75 rad/s ≈ 24,000 counts/s, less friction.
        assert!((18_000.0..26_000.0).contains(&r), "{r} counts/s");
        assert!(
            counts.windows(2).skip(100).all(|w| w[1] > w[0]),
            "{counts:?}"
        );

        // From the master's output.
        let b = Behaviour::compile(
            None,
            &[EntrySpec {
                entry: "0x6000:0x11".into(),
                encoder: Some(EncoderSpec {
                    volts: None,
                    from: Some("0x7000:0x11".into()),
                    volts_per_unit: Some(0.001),
                    supply: None,
                }),
                ..Default::default()
            }],
            base.esi.def,
            "device[0]",
        )
        .unwrap();
        let t = with_behaviour(base, b);
        let (mut m, _seg, vars) = open(t);
        let cv = var(&vars, Dir::Input, (0x6000, 0x11));
        let set = var(&vars, Dir::Output, (0x7000, 0x11));
        let mut counts = Vec::new();
        let mut at_rest = Vec::new();
        m.run_cyclic(CycleOptions::default(), |io| {
            let c = u32::from_le_bytes(io.get(&cv)[..4].try_into().unwrap());
            if io.cycle < 300 {
                at_rest.push(c);
            } else {
                counts.push(c);
            }
            let mv: u32 = if io.cycle < 300 { 0 } else { 6000 };
            io.set(&set, &mv.to_le_bytes()).unwrap();
            Ok(if io.cycle >= 1100 {
                Flow::Stop
            } else {
                Flow::Continue
            })
        })
        .unwrap();
        assert!(at_rest.iter().all(|&c| c == at_rest[0]), "{at_rest:?}");
        let r6 = rate(&counts, 200);
        assert!(
            (2.5 * r..3.2 * r).contains(&r6),
            "{r6} counts/s at 6 V, {r} at 2 V"
        );
    });
}
