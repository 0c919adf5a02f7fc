//! The Laelaps II trot with the four leg nodes' board images in the loop (the machine-code
//! route, `oxicat-emu trot`): both builds of `firmware/laelaps-leg` (left and right legs),
//! executed instruction by instruction, under the experiment's own master at 400 µs DC.
//!
//! - wrong-side or foreign images are refused before anything boots;
//! - (long, `--ignored`) a shortened trot: 0 WKC errors, no SYNC0 lost on any node, each
//!   joint within the host trot test's PV-loop bound, the gait's diagonals in phase, and
//!   the per-node figures the summary prints (SYNC0 handler time, joint-loop load, stack,
//!   flash and RAM).

use oxicat_devices::laelaps::experiment::TrotRun;
use oxicat_devices::laelaps::results::{pv_bound_deg, summarize};
use oxicat_devices::laelaps::rig::LegId;
use oxicat_devices::laelaps::scenario::{Scenario, DEFAULT_TOML};
use oxicat_emu::trot::{markdown, run, LegImages, EXC_JOINT_LOOP, EXC_SYNC0};
use oxicat_emu::EmuError;

use crate::common;

/// The right build (`.ci/run`'s plain build) and the left build (`--features left-leg`,
/// target dir `firmware/target/left`).
fn images() -> Option<(Vec<u8>, Vec<u8>)> {
    let right = common::image("laelaps-leg", "OXICAT_LAELAPS_IMAGE")?;
    let left = common::image_in("laelaps-leg", "left", "OXICAT_LAELAPS_LEFT_IMAGE")?;
    Some((left, right))
}

#[test]
fn leg_images_are_checked_for_their_side() {
    let Some((left, right)) = images() else {
        return;
    };
    assert!(LegImages::new(left.clone(), right.clone()).is_ok());
    let swapped = LegImages::new(right.clone(), left.clone()).err();
    assert!(
        matches!(&swapped, Some(EmuError::BadImage(w)) if w.contains("left leg's image is the right build")),
        "{swapped:?}"
    );
    // An image that is not a leg-node build (the demo board's) has no side.
    if let Some(demo) = common::image("stm32f446-lan9252", "OXICAT_BOARD_IMAGE") {
        let e = LegImages::new(demo, right).err();
        assert!(
            matches!(&e, Some(EmuError::BadImage(w)) if w.contains("no OXICAT_LEG_SIDE")),
            "{e:?}"
        );
    }
    let e = LegImages::new(b"not an ELF".to_vec(), left).err();
    assert!(matches!(e, Some(EmuError::BadImage(_))), "{e:?}");
}

/// The host trot test's shortened procedure (tests/trot.rs in oxicat-devices).
fn short(trot_s: f64) -> Scenario {
    let text = DEFAULT_TOML
        .replace("settle_s = 3.5", "settle_s = 1.1")
        .replace("stand_s = 1.0", "stand_s = 0.2")
        .replace("transition_time_s = 3", "transition_time_s = 1")
        .replace("stop_s = 0.5", "stop_s = 0.1");
    Scenario::parse(&text).expect("scenario").with_trot(trot_s)
}

/// About 14,000 cycles of four emulated boards: a minute or two of wall time in a test
/// build. `cargo test -p oxicat-emu --test integration laelaps_trot:: -- --ignored`.
#[test]
#[ignore = "long: four emulated boards for 5.7 s of segment time"]
fn four_leg_images_trot_within_the_host_bounds_without_losing_a_sync0() {
    let Some((left, right)) = images() else {
        return;
    };
    let images = LegImages::new(left, right).expect("the two builds");
    let s = short(0.5);
    let wall = std::time::Instant::now();
    let (r, figures) = run(&s, &images, &mut |_| {}).unwrap_or_else(|e| panic!("{e}"));
    eprintln!("{}", markdown(&r, &figures));
    eprintln!(
        "{} cycles recorded, {:.1} s simulated, {:.1} s wall",
        r.bus.cycles,
        r.simulated_s,
        wall.elapsed().as_secs_f64()
    );
    assert!(r.pdi.machine_code);
    assert_eq!(r.bus.wkc_errors, 0, "{:?}", r.bus);
    assert_eq!(r.bus.sync0_missed, 0, "{:?}", r.bus);
    assert_eq!(figures.len(), 4);
    for f in &figures {
        let code = f.leg.code();
        assert!(f.sync0_pulses >= r.bus.cycles, "{code}: {}", f.sync0_pulses);
        assert_eq!(f.sync0_lost(), 0, "{code}: a SYNC0 was lost");
        let s0 = f.report.handler(EXC_SYNC0);
        let jl = f.report.handler(EXC_JOINT_LOOP);
        assert!(
            s0.runs >= r.bus.cycles && s0.max_cycles > 0,
            "{code}: {s0:?}"
        );
        // Four joint-loop ticks per 400 µs cycle over the recorded part.
        assert!(jl.runs >= 4 * r.bus.cycles, "{code}: {jl:?}");
        assert!(f.report.stack.max_depth > 0 && f.report.stack.max_depth <= 12 * 1024);
        assert!(
            f.leg_state.released_at_ns.is_some(),
            "{code}: leg never let go"
        );
        for n in &r.pdi.nodes {
            let spi = n.spi.expect("SPI figures");
            assert_eq!(spi.protocol_errors, 0);
            assert!(spi.transactions >= r.bus.cycles);
        }
    }
    tracks(&s, &r);
}

/// Each joint within the host trot test's bound, the legs move, the diagonals in phase.
fn tracks(s: &Scenario, r: &TrotRun) {
    let sum = summarize(r);
    for (li, leg) in LegId::TABLE.into_iter().enumerate() {
        let l = &sum.legs[li];
        let (knee_bound, hip_bound) = pv_bound_deg(s, l);
        eprintln!(
            "{}: knee max {:.2}° (bound {knee_bound:.2}°, RMS {:.2}°), hip max {:.2}° \
             (bound {hip_bound:.2}°, RMS {:.2}°)",
            leg.code(),
            l.knee_max_deg,
            l.knee_rms_deg,
            l.hip_max_deg,
            l.hip_rms_deg,
        );
        assert!(
            l.knee_peak_speed > 0.5 && l.hip_peak_speed > 0.5,
            "{}: the leg moves",
            leg.code()
        );
        assert!(l.knee_max_deg <= knee_bound, "{}: knee", leg.code());
        assert!(l.hip_max_deg <= hip_bound, "{}: hip", leg.code());
    }
    for (a, b, rho) in &sum.toe_height_correlation {
        let diagonal = matches!(
            (a, b),
            (LegId::ForeLeft, LegId::HindRight) | (LegId::ForeRight, LegId::HindLeft)
        );
        if diagonal {
            assert!(*rho > 0.9, "{a:?}–{b:?}: r = {rho}");
        } else {
            assert!(*rho < -0.5, "{a:?}–{b:?}: r = {rho}");
        }
    }
}
