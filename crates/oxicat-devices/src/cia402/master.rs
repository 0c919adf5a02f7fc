//! CiA402 drives from the master: bring a drive to Operation enabled the way the paper's
//! experiment does (controlword 0x06 → 0x07 → 0x0F, the statusword checked after each
//! step), clear faults (a rising edge of controlword bit 7), switch the mode of operation
//! (0x6060, checked in 0x6061), and stream cyclic synchronous position set-points.
//!
//! Everything runs in the cyclic exchange (the controlword is process data; drives run
//! their state machine in their cycle), on the ETG.6010 default PDOs of
//! `crate::cia402` (RxPDO 0x1600: 0x6040, 0x6060, 0x607A, 0x60FF, 0x6071; TxPDO
//! 0x1A00: 0x6041, 0x6061, 0x6064, 0x606C, 0x6077, 0x603F).

use std::time::Duration;

use oxicat_master::cyclic::{CycleOptions, Flow};
use oxicat_master::{Master, MasterError};

pub use crate::cia402::fsm::State;

/// Modes of operation.
pub use crate::cia402::mode;

/// Inputs of one drive (TxPDO 0x1A00).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DriveIn {
    /// 0x6041.
    pub statusword: u16,
    /// 0x6061.
    pub mode_display: i8,
    /// 0x6064 \[inc\].
    pub position: i32,
    /// 0x606C \[inc/s\].
    pub velocity: i32,
    /// 0x6077 \[‰ rated torque\].
    pub torque: i16,
    /// 0x603F.
    pub error_code: u16,
}

impl DriveIn {
    /// Decodes the default TxPDO (15 bytes; short images read as zero).
    pub fn decode(b: &[u8]) -> Self {
        let g = |o: usize, n: usize| -> u32 {
            let mut v = [0u8; 4];
            if let Some(s) = b.get(o..o + n) {
                v[..n].copy_from_slice(s);
            }
            u32::from_le_bytes(v)
        };
        Self {
            statusword: g(0, 2) as u16,
            mode_display: g(2, 1) as u8 as i8,
            position: g(3, 4) as i32,
            velocity: g(7, 4) as i32,
            torque: g(11, 2) as u16 as i16,
            error_code: g(13, 2) as u16,
        }
    }

    /// The state the statusword decodes to.
    pub fn state(&self) -> Option<State> {
        State::decode(self.statusword)
    }
}

/// Outputs of one drive (RxPDO 0x1600).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DriveOut {
    /// 0x6040.
    pub controlword: u16,
    /// 0x6060.
    pub mode: i8,
    /// 0x607A \[inc\].
    pub target_position: i32,
    /// 0x60FF \[inc/s\].
    pub target_velocity: i32,
    /// 0x6071 \[‰\].
    pub target_torque: i16,
}

impl DriveOut {
    /// Encodes the default RxPDO (13 bytes) into `b`.
    pub fn encode(&self, b: &mut [u8]) {
        let mut put = |o: usize, v: &[u8]| {
            if let Some(d) = b.get_mut(o..o + v.len()) {
                d.copy_from_slice(v);
            }
        };
        put(0, &self.controlword.to_le_bytes());
        put(2, &self.mode.to_le_bytes());
        put(3, &self.target_position.to_le_bytes());
        put(7, &self.target_velocity.to_le_bytes());
        put(11, &self.target_torque.to_le_bytes());
    }
}

/// What to do with the drives, in order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Action {
    /// Fault reset if in Fault (0x00, then 0x80: Switch on disabled expected).
    ClearFault,
    /// 0x06 (Ready to switch on), 0x07 (Switched on), 0x0F (Operation enabled).
    Enable,
    /// 0x07 (Switched on: disable operation), then 0x00 (Switch on disabled).
    Disable,
    /// Mode of operation (0x6060) until 0x6061 shows it.
    Mode(i8),
    /// CSP: from the actual position to `target` (relative to the start of the move when
    /// `relative`) on a smooth (cosine) profile over `duration`, then `settle` cycles.
    Move {
        /// Target \[inc\].
        target: i32,
        /// Relative to the position at the start of the move.
        relative: bool,
        /// Duration of the profile.
        duration: Duration,
    },
}

/// One cycle of a drive as recorded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cia402Row {
    /// Cycle.
    pub cycle: u64,
    /// Time \[s\].
    pub time: f64,
    /// Drive position on the segment.
    pub drive: usize,
    /// Sent.
    pub out: DriveOut,
    /// Received.
    pub inp: DriveIn,
}

/// A step of the sequence and the statusword it led to.
#[derive(Debug, Clone, PartialEq)]
pub struct StepLog {
    /// Drive.
    pub drive: usize,
    /// What was done (e.g. "controlword 0x0006").
    pub what: String,
    /// Statusword read back once the step completed.
    pub statusword: u16,
    /// Its state.
    pub state: Option<State>,
}

/// Result of a run.
#[derive(Debug, Clone, Default)]
pub struct Cia402Run {
    /// Steps with their statuswords.
    pub steps: Vec<StepLog>,
    /// Every cycle of every drive.
    pub rows: Vec<Cia402Row>,
}

impl Cia402Run {
    /// (RMS, max) of the CSP following error (demand − actual) per drive during moves.
    pub fn following_error(&self, drives: usize) -> Vec<(f64, i32)> {
        (0..drives)
            .map(|d| {
                let e: Vec<i64> = self
                    .rows
                    .iter()
                    .filter(|r| {
                        r.drive == d && r.out.mode == mode::CSP && r.out.controlword == 0x0F
                    })
                    .map(|r| r.out.target_position as i64 - r.inp.position as i64)
                    .collect();
                if e.is_empty() {
                    return (0.0, 0);
                }
                let rms = (e.iter().map(|x| (x * x) as f64).sum::<f64>() / e.len() as f64).sqrt();
                (rms, e.iter().map(|x| x.abs()).max().unwrap_or(0) as i32)
            })
            .collect()
    }

    /// CSV: cycle, time, drive, controlword, mode, target position, statusword, mode display,
    /// position, velocity, torque, error code; positions, velocity and torque in the units
    /// the drive declares (increments, increments/s, % of rated torque).
    pub fn csv(&self) -> String {
        use oxicat_master::value::format_scaled;
        let sc = |index: u16| {
            super::DEF
                .scale(index, 0)
                .expect("the joint declares this entry's unit")
        };
        let (target, pos, vel, torque) = (sc(0x607A), sc(0x6064), sc(0x606C), sc(0x6077));
        let h = [
            "cycle".to_string(),
            "time [s]".into(),
            "drive".into(),
            "controlword".into(),
            "mode".into(),
            format!("target position [{}]", target.unit),
            "statusword".into(),
            "mode display".into(),
            format!("position [{}]", pos.unit),
            format!("velocity [{}]", vel.unit),
            format!("torque [{}]", torque.unit),
            "error code".into(),
        ];
        let body = self.rows.iter().map(|r| {
            vec![
                r.cycle.to_string(),
                format!("{:.6}", r.time),
                r.drive.to_string(),
                format!("0x{:04X}", r.out.controlword),
                r.out.mode.to_string(),
                format_scaled(r.out.target_position.into(), &target),
                format!("0x{:04X}", r.inp.statusword),
                r.inp.mode_display.to_string(),
                format_scaled(r.inp.position.into(), &pos),
                format_scaled(r.inp.velocity.into(), &vel),
                format_scaled(r.inp.torque.into(), &torque),
                format!("0x{:04X}", r.inp.error_code),
            ]
        });
        crate::csv_text(std::iter::once(h.to_vec()).chain(body)).expect("fixed columns")
    }
}

/// Cycles a step may take before the drive is declared not to follow.
pub const STEP_TIMEOUT_CYCLES: u32 = 200;

#[derive(Debug, Clone, Copy)]
enum Step {
    Cw(u16, State),
    /// As `Cw`, skipped when the drive is not in Operation enabled.
    CwIfEnabled(u16, State),
    ClearIfFault,
    Mode(i8),
    Move {
        target: i32,
        relative: bool,
        cycles: u64,
    },
    Settle(u64),
}

fn expand(actions: &[Action], cycle: Duration) -> Vec<Step> {
    let mut v = Vec::new();
    for a in actions {
        match *a {
            Action::ClearFault => v.push(Step::ClearIfFault),
            Action::Enable => {
                v.push(Step::Cw(0x06, State::ReadyToSwitchOn));
                v.push(Step::Cw(0x07, State::SwitchedOn));
                v.push(Step::Cw(0x0F, State::OperationEnabled));
            }
            Action::Disable => {
                v.push(Step::CwIfEnabled(0x07, State::SwitchedOn));
                v.push(Step::Cw(0x00, State::SwitchOnDisabled));
            }
            Action::Mode(m) => v.push(Step::Mode(m)),
            Action::Move {
                target,
                relative,
                duration,
            } => {
                let cycles = (duration.as_nanos() / cycle.as_nanos().max(1)).max(1) as u64;
                v.push(Step::Move {
                    target,
                    relative,
                    cycles,
                });
                v.push(Step::Settle(100));
            }
        }
    }
    v
}

#[derive(Debug, Clone, Copy)]
struct Seq {
    step: usize,
    waited: u32,
    out: DriveOut,
    sub: u8,
    start: i32,
    k: u64,
    /// Scale of this drive's move targets (see [`run_scaled`]).
    amp: f64,
}

/// Runs `actions` on the drives at `drives` (segment positions) in one cyclic session,
/// all drives in step, each step checked on the statusword (or mode display) of every
/// drive; records every cycle. `dc`: DC SYNC0-synchronous.
pub fn run(
    m: &mut Master,
    drives: &[usize],
    actions: &[Action],
    cycle: Duration,
    dc: bool,
) -> Result<Cia402Run, MasterError> {
    run_scaled(m, drives, actions, cycle, dc, &[])
}

/// Relative joint motions of a six-axis arm for one CSP move (base, shoulder, elbow, three
/// wrist axes): each joint moves its own share of the commanded target, signs alternating,
/// so the joints follow different trajectories in the same cycles. Repeats after six.
pub fn arm_amplitudes(joints: usize) -> Vec<f64> {
    const ARM: [f64; 6] = [1.0, -0.75, 0.5, -1.0, 0.6, -0.3];
    (0..joints).map(|j| ARM[j % ARM.len()]).collect()
}

/// [`run`] with the move targets of drive `i` scaled by `amplitude[i]` (1 where missing),
/// e.g. [`arm_amplitudes`] for an arm whose joints move differently.
pub fn run_scaled(
    m: &mut Master,
    drives: &[usize],
    actions: &[Action],
    cycle: Duration,
    dc: bool,
    amplitude: &[f64],
) -> Result<Cia402Run, MasterError> {
    let steps = expand(actions, cycle);
    let mut run = Cia402Run::default();
    let mut seq: Vec<Seq> = drives
        .iter()
        .enumerate()
        .map(|(i, _)| Seq {
            step: 0,
            waited: 0,
            out: DriveOut {
                mode: mode::CSP,
                ..DriveOut::default()
            },
            sub: 0,
            start: 0,
            k: 0,
            amp: amplitude.get(i).copied().unwrap_or(1.0),
        })
        .collect();
    let mut failure: Option<String> = None;
    let mut started = false;
    m.run_cyclic(CycleOptions { cycle, dc }, |io| {
        // Hold the first cycles: the drives' state machines start (transition 1).
        if !started {
            for (i, &p) in drives.iter().enumerate() {
                let inp = DriveIn::decode(io.inputs.get(p).map(|v| &v[..]).unwrap_or(&[]));
                seq[i].out.target_position = inp.position;
                seq[i].out.mode = if inp.mode_display != 0 { inp.mode_display } else { mode::CSP };
            }
            if io.cycle >= 5 {
                started = true;
            }
        } else {
            for (i, &p) in drives.iter().enumerate() {
                let inp = DriveIn::decode(io.inputs.get(p).map(|v| &v[..]).unwrap_or(&[]));
                let s = &mut seq[i];
                let Some(step) = steps.get(s.step).copied() else {
                    continue;
                };
                let mut done = false;
                let step = match step {
                    Step::CwIfEnabled(cw, want) => {
                        if s.waited == 0 && inp.state() != Some(State::OperationEnabled) {
                            s.step += 1;
                            continue;
                        }
                        Step::Cw(cw, want)
                    }
                    other => other,
                };
                match step {
                    Step::Cw(cw, want) => {
                        if s.waited == 0 {
                            s.out.controlword = cw;
                            // Enabling: take the actual position as the CSP set-point.
                            s.out.target_position = inp.position;
                        } else if inp.state() == Some(want) {
                            done = true;
                        }
                        if !done && s.waited >= STEP_TIMEOUT_CYCLES {
                            failure = Some(format!(
                                "drive {p}: controlword 0x{cw:04X} did not reach {want:?}; statusword 0x{:04X} ({:?}), error code 0x{:04X}",
                                inp.statusword,
                                inp.state(),
                                inp.error_code
                            ));
                        }
                        if done {
                            run.steps.push(StepLog {
                                drive: p,
                                what: format!("controlword 0x{cw:04X}"),
                                statusword: inp.statusword,
                                state: inp.state(),
                            });
                        }
                    }
                    Step::ClearIfFault => match (s.sub, inp.state()) {
                        (0, Some(State::Fault | State::FaultReactionActive)) => {
                            s.out.controlword = 0x00;
                            s.sub = 1;
                        }
                        (0, _) => done = true,
                        (1, _) => {
                            s.out.controlword = 0x80;
                            s.sub = 2;
                        }
                        (_, st) => {
                            if st == Some(State::SwitchOnDisabled) {
                                run.steps.push(StepLog {
                                    drive: p,
                                    what: "fault reset (controlword 0x0080)".into(),
                                    statusword: inp.statusword,
                                    state: st,
                                });
                                s.out.controlword = 0x00;
                                done = true;
                            } else if s.waited >= STEP_TIMEOUT_CYCLES {
                                failure = Some(format!(
                                    "drive {p}: fault reset failed; statusword 0x{:04X}, error code 0x{:04X}",
                                    inp.statusword, inp.error_code
                                ));
                            }
                        }
                    },
                    Step::Mode(md) => {
                        s.out.mode = md;
                        s.out.target_position = inp.position;
                        if s.waited > 0 && inp.mode_display == md {
                            run.steps.push(StepLog {
                                drive: p,
                                what: format!("mode of operation {md}"),
                                statusword: inp.statusword,
                                state: inp.state(),
                            });
                            done = true;
                        } else if s.waited >= STEP_TIMEOUT_CYCLES {
                            failure = Some(format!(
                                "drive {p}: mode {md} not taken; 0x6061 = {}",
                                inp.mode_display
                            ));
                        }
                    }
                    Step::Move {
                        target,
                        relative,
                        cycles,
                    } => {
                        if s.k == 0 {
                            s.start = s.out.target_position;
                        }
                        let target = (f64::from(target) * s.amp).round() as i32;
                        let goal = if relative {
                            s.start.wrapping_add(target)
                        } else {
                            target
                        };
                        s.k += 1;
                        let x = (s.k as f64 / cycles as f64).min(1.0);
                        let shape = (1.0 - (std::f64::consts::PI * x).cos()) / 2.0;
                        s.out.target_position =
                            (s.start as f64 + (goal as f64 - s.start as f64) * shape).round() as i32;
                        if inp.state() != Some(State::OperationEnabled) && s.k > 2 {
                            failure = Some(format!(
                                "drive {p}: left Operation enabled during the move; statusword 0x{:04X}, error code 0x{:04X}",
                                inp.statusword, inp.error_code
                            ));
                        }
                        if s.k >= cycles {
                            s.k = 0;
                            done = true;
                        }
                    }
                    Step::CwIfEnabled(..) => {}
                    Step::Settle(n) => {
                        s.k += 1;
                        if s.k >= n {
                            s.k = 0;
                            run.steps.push(StepLog {
                                drive: p,
                                what: format!("move to {}", s.out.target_position),
                                statusword: inp.statusword,
                                state: inp.state(),
                            });
                            done = true;
                        }
                    }
                }
                if done {
                    s.step += 1;
                    s.waited = 0;
                    s.sub = 0;
                } else {
                    s.waited += 1;
                }
            }
        }
        for (i, &p) in drives.iter().enumerate() {
            let inp = DriveIn::decode(io.inputs.get(p).map(|v| &v[..]).unwrap_or(&[]));
            if let Some(o) = io.outputs.get_mut(p) {
                seq[i].out.encode(o);
            }
            run.rows.push(Cia402Row {
                cycle: io.cycle,
                time: io.time_ns as f64 * 1e-9,
                drive: p,
                out: seq[i].out,
                inp,
            });
        }
        let all_done = seq.iter().all(|s| s.step >= steps.len());
        Ok(if failure.is_some() || (started && all_done) {
            Flow::Stop
        } else {
            Flow::Continue
        })
    })?;
    match failure {
        Some(f) => Err(MasterError::Usage(f)),
        None => Ok(run),
    }
}

/// The CSP following error (demand − actual, counts) of each drive over time during moves,
/// one line per drive, as `following-error.png` and `following-error.svg` in `dir`.
pub fn write_following_error_plots(
    run: &Cia402Run,
    drives: usize,
    dir: &std::path::Path,
) -> Result<Vec<std::path::PathBuf>, MasterError> {
    use plotters::prelude::*;
    crate::laelaps::plot::font_ready()?;
    let series: Vec<Vec<(f64, f64)>> = (0..drives)
        .map(|d| {
            run.rows
                .iter()
                .filter(|r| r.drive == d && r.out.mode == mode::CSP && r.out.controlword == 0x0F)
                .map(|r| (r.time, r.out.target_position as f64 - r.inp.position as f64))
                .collect()
        })
        .collect();
    let all = series.iter().flatten();
    let (t0, t1) = all
        .clone()
        .fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.0), b.max(p.0)));
    let (t0, t1) = if t0 < t1 { (t0, t1) } else { (0.0, 1.0) };
    let emax = all.fold(1.0f64, |a, p| a.max(p.1.abs())) * 1.1;
    fn draw<DB: DrawingBackend>(
        root: DrawingArea<DB, plotters::coord::Shift>,
        series: &[Vec<(f64, f64)>],
        (t0, t1, emax): (f64, f64, f64),
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>>
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption("CSP following error per joint", ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(t0..t1, -emax..emax)?;
        chart
            .configure_mesh()
            .x_desc("time [s]")
            .y_desc("demand - actual [counts]")
            .draw()?;
        for (d, pts) in series.iter().enumerate() {
            let colour = Palette99::pick(d).to_rgba();
            chart
                .draw_series(LineSeries::new(pts.iter().copied(), colour))?
                .label(format!("joint {d}"))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], colour));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
        root.present()
    }
    let png = dir.join("following-error.png");
    let svg = dir.join("following-error.svg");
    let fail = |p: &std::path::Path, e: String| {
        MasterError::File(p.to_path_buf(), std::io::Error::other(e))
    };
    draw(
        BitMapBackend::new(&png, (1000, 500)).into_drawing_area(),
        &series,
        (t0, t1, emax),
    )
    .map_err(|e| fail(&png, e.to_string()))?;
    draw(
        SVGBackend::new(&svg, (1000, 500)).into_drawing_area(),
        &series,
        (t0, t1, emax),
    )
    .map_err(|e| fail(&svg, e.to_string()))?;
    Ok(vec![png, svg])
}
