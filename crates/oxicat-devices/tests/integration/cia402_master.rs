//! CiA402 joint drives on the virtual segment, driven by the master through ethercrab:
//! the paper's enable sequence checked on the statusword at every step, CSP moves at 1 kHz
//! DC with the joint plants tracking, fault reset.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use oxicat_devices::cia402::master::{self as cia402, Action, State};
use oxicat_devices::cia402::rig::{attach, BldcJointParams, JointHandle};
use oxicat_master::{Link, Master};
use oxicat_sim::segment::Segment;

use oxicat_testkit::big;

fn segment(n: usize) -> (Link, Vec<JointHandle>) {
    let mut seg = Segment::new();
    let sii = oxicat_esi::sii::generate(&oxicat_devices::cia402::DEF).unwrap();
    let mut hs = Vec::new();
    for _ in 0..n {
        let id = seg.add(oxicat_esc::Esc::new(
            oxicat_esc::EscConfig::et1100(),
            sii.clone(),
        ));
        hs.push(attach(&mut seg, id, BldcJointParams::default()).unwrap());
    }
    (Link::Sim(Arc::new(Mutex::new(seg))), hs)
}

#[test]
fn enable_sequence_and_csp_move_through_ethercrab_at_1khz_dc() {
    big(|| {
        let (link, hs) = segment(2);
        let mut m = Master::open(link).unwrap();
        assert_eq!(
            m.sdo_upload(0, 0x1000, 0).unwrap(),
            0x0002_0192u32.to_le_bytes()
        );
        let run = cia402::run(
            &mut m,
            &[0, 1],
            &[
                Action::ClearFault,
                Action::Mode(cia402::mode::CSP),
                Action::Enable,
                Action::Move {
                    target: 40_000,
                    relative: true,
                    duration: Duration::from_millis(800),
                },
            ],
            Duration::from_millis(1),
            true,
        )
        .unwrap();
        // Each drive: 0x06 → Ready to switch on, 0x07 → Switched on, 0x0F → Operation
        // enabled, read back from the TxPDO statusword.
        for d in 0..2 {
            let st: Vec<_> = run
                .steps
                .iter()
                .filter(|s| s.drive == d && s.what.starts_with("controlword"))
                .map(|s| (s.what.clone(), s.state))
                .collect();
            assert_eq!(
                st,
                vec![
                    (
                        "controlword 0x0006".to_string(),
                        Some(State::ReadyToSwitchOn)
                    ),
                    ("controlword 0x0007".to_string(), Some(State::SwitchedOn)),
                    (
                        "controlword 0x000F".to_string(),
                        Some(State::OperationEnabled)
                    ),
                ]
            );
        }
        let fe = run.following_error(2);
        eprintln!("CSP following error per drive (RMS, max) [counts]: {fe:?}");
        for (d, (rms, max)) in fe.iter().enumerate() {
            assert!(*max < 400, "drive {d}: max following error {max} counts");
            assert!(*rms < 200.0, "drive {d}: RMS {rms}");
        }
        // The plants moved: 40000 counts = 2.44 motor turns = 0.153 rad at the link.
        for h in &hs {
            let d = h.lock();
            let link = d.app.hw.joint.link_angle;
            assert!(
                (link - 40_000.0 / 16_384.0 * std::f64::consts::TAU / 100.0).abs() < 0.005,
                "{link}"
            );
        }
        assert!(run.csv().lines().count() > 800);
    });
}

/// A six-joint arm on one segment at 1 kHz DC follows one CSP trajectory with each joint
/// moving its own share (signs alternating); per-joint RMS and max following error stay in
/// the same bound as the two-drive test, and every link ends at its own target.
#[test]
fn six_joint_arm_follows_a_csp_trajectory_at_1khz_dc() {
    big(|| {
        let (link, hs) = segment(6);
        let mut m = Master::open(link).unwrap();
        let amp = cia402::arm_amplitudes(6);
        let run = cia402::run_scaled(
            &mut m,
            &[0, 1, 2, 3, 4, 5],
            &[
                Action::ClearFault,
                Action::Mode(cia402::mode::CSP),
                Action::Enable,
                Action::Move {
                    target: 40_000,
                    relative: true,
                    duration: Duration::from_millis(800),
                },
            ],
            Duration::from_millis(1),
            true,
            &amp,
        )
        .unwrap();
        let fe = run.following_error(6);
        eprintln!("six-joint arm: CSP following error per joint (RMS, max) [counts]: {fe:?}");
        for (d, (rms, max)) in fe.iter().enumerate() {
            assert!(*max < 400, "joint {d}: max following error {max} counts");
            assert!(*rms < 200.0, "joint {d}: RMS {rms}");
            assert!(*max > 0, "joint {d} moved under CSP");
        }
        for (j, h) in hs.iter().enumerate() {
            let link = h.lock().app.hw.joint.link_angle;
            let want = amp[j] * 40_000.0 / 16_384.0 * std::f64::consts::TAU / 100.0;
            assert!(
                (link - want).abs() < 0.005,
                "joint {j}: link {link} rad, want {want}"
            );
        }
    });
}

/// The TxPDO is configurable in PREOP: appending the joint torque sensor 0x2002 and the
/// following error 0x60F4 to 0x1A00 makes the inputs 23 bytes, the new entries live.
#[test]
fn txpdo_mapping_is_configurable_in_preop() {
    big(|| {
        let (link, _hs) = segment(1);
        let m = Master::open(link.clone()).unwrap();
        m.sdo_download(0, 0x1A00, 0, &[0]).unwrap();
        m.sdo_download(0, 0x1A00, 7, &0x2002_0020u32.to_le_bytes())
            .unwrap();
        m.sdo_download(0, 0x1A00, 8, &0x60F4_0020u32.to_le_bytes())
            .unwrap();
        m.sdo_download(0, 0x1A00, 0, &[8]).unwrap();
        assert_eq!(m.sdo_upload(0, 0x1A00, 0).unwrap(), vec![8]);
        let l = m.pdos(0).unwrap();
        let entries: Vec<u16> = l.tx[0].entries.iter().map(|e| e.index).collect();
        assert_eq!(
            entries,
            vec![0x6041, 0x6061, 0x6064, 0x606C, 0x6077, 0x603F, 0x2002, 0x60F4]
        );
        drop(m);
        let mut m = Master::open(link).unwrap();
        let mut sizes = Vec::new();
        m.run_cyclic(oxicat_master::cyclic::CycleOptions::default(), |io| {
            sizes.push(io.inputs[0].len());
            Ok(if io.cycle >= 5 {
                oxicat_master::cyclic::Flow::Stop
            } else {
                oxicat_master::cyclic::Flow::Continue
            })
        })
        .unwrap();
        assert!(sizes.iter().all(|&n| n == 23), "{sizes:?}");
    });
}

/// The abort connection option code 0x6007 decides what an enabled drive does when its
/// master goes away: the master brings the drive to Operation enabled in OP at 1 kHz DC,
/// then stops cycling as if it had crashed (the drive stays in OP); 100 ms later the SM
/// watchdog expires (SAFEOP + error 0x001B) and the drive reacts by its 0x6007: 0 no
/// action (still enabled), 1 a fault (0x8100, communication), 2 Disable voltage
/// (transition 9, coasting), 3 Quick stop (transition 11, ramp, then 12).
#[test]
fn abort_connection_option_code_0x6007_selects_the_reaction_to_a_lost_master() {
    big(|| {
        for code in [0i16, 1, 2, 3] {
            let mut seg = Segment::new();
            let sii = oxicat_esi::sii::generate(&oxicat_devices::cia402::DEF).unwrap();
            let id = seg.add(oxicat_esc::Esc::new(oxicat_esc::EscConfig::et1100(), sii));
            let h = attach(&mut seg, id, BldcJointParams::default()).unwrap();
            let seg = Arc::new(Mutex::new(seg));
            let mut m = Master::open(Link::Sim(seg.clone())).unwrap();
            m.sdo_download(0, 0x6007, 0, &code.to_le_bytes()).unwrap();
            assert_eq!(m.sdo_upload(0, 0x6007, 0).unwrap(), code.to_le_bytes());
            m.stop_cycling_as_if_gone();
            cia402::run(
                &mut m,
                &[0],
                &[Action::ClearFault, Action::Enable],
                Duration::from_millis(1),
                true,
            )
            .unwrap();
            assert_eq!(h.lock().app.state(), State::OperationEnabled, "code {code}");
            // No more frames: the SM watchdog (100 ms) expires, SYNC0 cycles go on.
            seg.lock().unwrap().advance_by(300_000_000);
            let (al, al_code) = {
                let s = seg.lock().unwrap();
                let e = s.esc(id).unwrap();
                let c = &e.memory()[0x0134..0x0136];
                (e.al_status(), u16::from_le_bytes([c[0], c[1]]))
            };
            assert_eq!(
                (al & 0x1F, al_code),
                (0x14, 0x001B),
                "code {code}: SAFEOP + ERR, SM watchdog"
            );
            let d = h.lock();
            let (state, fault, t) = (d.app.state(), d.app.fault(), d.app.last_transition());
            match code {
                0 => assert_eq!((state, fault), (State::OperationEnabled, None)),
                1 => assert_eq!(
                    (state, fault),
                    (
                        State::Fault,
                        Some(oxicat_devices::cia402::error::COMMUNICATION)
                    )
                ),
                2 => assert_eq!((state, fault, t), (State::SwitchOnDisabled, None, Some(9))),
                _ => assert_eq!((state, fault, t), (State::SwitchOnDisabled, None, Some(12))),
            }
        }
        // Out of range: refused by the SDO server, not taken.
        let (link, _hs) = segment(1);
        let m = Master::open(link).unwrap();
        assert!(m.sdo_download(0, 0x6007, 0, &7i16.to_le_bytes()).is_err());
        assert_eq!(m.sdo_upload(0, 0x6007, 0).unwrap(), 3i16.to_le_bytes());
    });
}

/// The paper's Experiment 2 (task period 1000 µs, analysed on the wire) on the virtual
/// segment: the table has its rows, and on the deterministic clock the frame period and the
/// drive's SYNC0 period are the configured cycle, every sample of them (the paper:
/// "almost every sample"); the round trip is shorter than a cycle. The configured cycle is
/// what comes out (500 µs too), and bad arguments are refused.
#[test]
fn task_period_table_reproduces_the_papers_1ms_experiment() {
    use oxicat_devices::cia402::task_period::{self, FRAME_PERIOD, ROUND_TRIP, SYNC0_PERIOD};
    big(|| {
        for (cycle_us, cycles) in [(1000u64, 400u64), (500, 200)] {
            let t = task_period::run(1, cycles, Duration::from_micros(cycle_us), true).unwrap();
            let names: Vec<_> = t.rows.iter().map(|r| r.what).collect();
            assert_eq!(names, [FRAME_PERIOD, SYNC0_PERIOD, ROUND_TRIP]);
            for what in [FRAME_PERIOD, SYNC0_PERIOD] {
                let r = t.row(what).unwrap();
                assert!(r.samples + 5 >= cycles as usize, "{what}: {r:?}");
                assert!((r.mean_us - cycle_us as f64).abs() < 1e-9, "{what}: {r:?}");
                assert_eq!((r.min_us, r.max_us), (cycle_us as f64, cycle_us as f64));
                assert_eq!(r.std_us, 0.0, "{what}");
                assert_eq!(r.within_1us, Some(1.0), "{what}");
            }
            let rtt = t.row(ROUND_TRIP).unwrap();
            assert!(rtt.samples + 5 >= cycles as usize, "{rtt:?}");
            assert!(rtt.min_us > 0.0 && rtt.max_us < cycle_us as f64, "{rtt:?}");
            let md = t.markdown();
            eprintln!("{md}");
            for what in [FRAME_PERIOD, SYNC0_PERIOD, ROUND_TRIP] {
                assert!(md.contains(what), "{md}");
            }
            assert!(md.contains(&format!("| {cycle_us}.000 |")), "{md}");
        }
        assert!(task_period::run(0, 100, Duration::from_millis(1), true).is_err());
        assert!(task_period::run(1, 5, Duration::from_millis(1), true).is_err());
    });
}
