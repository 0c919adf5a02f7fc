//! The paper's Experiment 2 on the virtual segment: the real-time task runs with a period of
//! 1000 µs and a timing analyzer on the wire (a Hilscher netANALYZER) shows that "almost
//! every sample concentrates on the point of 1000 µs". The paper gives a histogram and no
//! number (no mean, jitter, min/max, sample count or round trip).
//!
//! Here the master (ethercrab through `oxicat-master`) cycles CiA402 joint drives in DC
//! SYNC0 mode (or free run) while they follow a CSP move, the segment's capture taps the
//! master link (where the analyzer sat) and its event log the drives' SYNC0 pulses, all
//! in virtual time. [`run`] turns that into a table ([`PeriodTable`]): per quantity the
//! samples, mean, min, max, standard deviation and the share within ±1 µs of the
//! configured period.
//!
//! In virtual time the master sends every cycle's frame exactly on its period and the DC
//! unit fires SYNC0 exactly on its cycle, so the jitter is 0: what the virtual segment
//! reproduces is the distribution's centre and the round trip; the spread a real master's
//! operating system adds (the paper's "almost") is not modelled.

use std::fmt::Write as _;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use oxicat_master::{Link, Master, MasterError};
use oxicat_sim::capture::{Direction, MemoryCapture};
use oxicat_sim::node::EscEvent;
use oxicat_sim::segment::Segment;

use super::master::{self as cia402, mode, Action};
use super::rig::{attach, BldcJointParams};

/// One quantity of the table.
#[derive(Debug, Clone, PartialEq)]
pub struct PeriodRow {
    /// What was measured.
    pub what: &'static str,
    /// Number of samples.
    pub samples: usize,
    /// Mean \[µs\].
    pub mean_us: f64,
    /// Minimum \[µs\].
    pub min_us: f64,
    /// Maximum \[µs\].
    pub max_us: f64,
    /// Standard deviation (the jitter) \[µs\].
    pub std_us: f64,
    /// Share of the samples within ±1 µs of the configured period (`None`: not a period).
    pub within_1us: Option<f64>,
}

impl PeriodRow {
    fn of(what: &'static str, ns: &[u64], period_ns: Option<u64>) -> Self {
        let n = ns.len();
        let us: Vec<f64> = ns.iter().map(|&x| x as f64 / 1e3).collect();
        let mean = if n == 0 {
            0.0
        } else {
            us.iter().sum::<f64>() / n as f64
        };
        let var = if n == 0 {
            0.0
        } else {
            us.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n as f64
        };
        Self {
            what,
            samples: n,
            mean_us: mean,
            min_us: us.iter().copied().fold(f64::INFINITY, f64::min),
            max_us: us.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            std_us: var.sqrt(),
            within_1us: period_ns.map(|p| {
                let ok = ns.iter().filter(|&&x| x.abs_diff(p) <= 1_000).count();
                if n == 0 {
                    0.0
                } else {
                    ok as f64 / n as f64
                }
            }),
        }
    }
}

/// Rows: the cyclic frame period on the master link, each drive's SYNC0 period (its task
/// period; free run: none), the frame round trip.
#[derive(Debug, Clone, PartialEq)]
pub struct PeriodTable {
    /// The configured cycle \[ns\].
    pub cycle_ns: u64,
    /// DC SYNC0 (true) or free run.
    pub dc: bool,
    /// Drives on the segment.
    pub joints: usize,
    /// The rows.
    pub rows: Vec<PeriodRow>,
}

/// Row name: the period of the frames carrying the process data (LRW), at the master link.
pub const FRAME_PERIOD: &str = "cyclic frame period, master link";
/// Row name: the SYNC0 period of drive 0 (the drive's task period in DC mode).
pub const SYNC0_PERIOD: &str = "SYNC0 period, drive 0 (task period)";
/// Row name: the time from a cyclic frame leaving the master to its return.
pub const ROUND_TRIP: &str = "frame round trip, master link";

impl PeriodTable {
    /// The row named `what`.
    pub fn row(&self, what: &str) -> Option<&PeriodRow> {
        self.rows.iter().find(|r| r.what == what)
    }

    /// The table as Markdown, with the paper's figure beside it.
    pub fn markdown(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "CiA402 joint drive{} on the virtual segment, {} µs cycle, {}, CSP move; virtual time",
            if self.joints == 1 { "" } else { "s" },
            self.cycle_ns as f64 / 1e3,
            if self.dc { "DC SYNC0" } else { "free run" },
        );
        let _ = writeln!(s);
        let _ = writeln!(
            s,
            "| quantity | samples | mean µs | min µs | max µs | std dev (jitter) µs | within ±1 µs of the cycle |"
        );
        let _ = writeln!(s, "|---|---|---|---|---|---|---|");
        for r in &self.rows {
            let within = r
                .within_1us
                .map_or("–".to_string(), |w| format!("{:.1} %", 100.0 * w));
            let _ = writeln!(
                s,
                "| {} | {} | {:.3} | {:.3} | {:.3} | {:.3} | {within} |",
                r.what, r.samples, r.mean_us, r.min_us, r.max_us, r.std_us
            );
        }
        let _ = writeln!(s);
        let _ = writeln!(
            s,
            "Paper (Liu et al., Fig. 15, netANALYZER on the wire, TwinCAT on a PC): task period 1000 µs, \
             \"almost every sample concentrates on the point of 1000 µs\"; no mean, jitter, min/max, \
             sample count or round trip given. Virtual time has no operating-system jitter: the spread \
             a real master adds is not modelled."
        );
        s
    }
}

/// Whether an Ethernet frame carries an LRW datagram (the cyclic process data).
fn has_lrw(frame: &[u8]) -> bool {
    // Ethernet header 14 bytes (VLAN tags are not used on the master link), EtherCAT
    // header 2 bytes, then datagrams of 10 + len + 2 bytes.
    let mut o = 16;
    while let Some(h) = frame.get(o..o + 10) {
        if h[0] == 0x0C {
            return true;
        }
        let len_word = u16::from_le_bytes([h[6], h[7]]);
        let len = usize::from(len_word & 0x07FF);
        if len_word & 0x8000 == 0 {
            return false;
        }
        o += 10 + len + 2;
    }
    false
}

/// The experiment: `joints` drives (1 … 1024), `cycles` process-data cycles (10 …
/// 1,000,000) of `cycle`, DC SYNC0 when `dc`; the drives are enabled (0x06, 0x07, 0x0F) and
/// follow a CSP move of one motor turn over `cycles` cycles, then settle for 100; the table
/// covers both.
pub fn run(
    joints: usize,
    cycles: u64,
    cycle: Duration,
    dc: bool,
) -> Result<PeriodTable, MasterError> {
    if !(1..=oxicat_master::MAX_SLAVES).contains(&joints) {
        return Err(MasterError::Usage(format!(
            "joints = {joints}: 1 … {} drives",
            oxicat_master::MAX_SLAVES
        )));
    }
    if !(10..=1_000_000).contains(&cycles) {
        return Err(MasterError::Usage(format!(
            "cycles = {cycles}: 10 … 1000000"
        )));
    }
    let cycle_ns = u64::try_from(cycle.as_nanos()).unwrap_or(u64::MAX);
    let mut seg = Segment::new();
    let sii = oxicat_esi::sii::generate(&super::DEF)
        .map_err(|e| MasterError::Usage(format!("SII of the CiA402 joint: {e}")))?;
    let mut ids = Vec::new();
    for _ in 0..joints {
        let id = seg.add(oxicat_esc::Esc::new(
            oxicat_esc::EscConfig::et1100(),
            sii.clone(),
        ));
        attach(&mut seg, id, BldcJointParams::default())
            .map_err(|e| MasterError::Usage(format!("CiA402 joint firmware: {e}")))?;
        ids.push(id);
    }
    let capture = MemoryCapture::new();
    seg.set_capture(Some(Box::new(capture.clone())));
    seg.log_events(true);
    let seg = Arc::new(Mutex::new(seg));
    let mut m = Master::open(Link::Sim(seg.clone()))?;
    let drives: Vec<usize> = (0..m.len()).collect();
    let run = cia402::run(
        &mut m,
        &drives,
        &[
            Action::ClearFault,
            Action::Mode(mode::CSP),
            Action::Enable,
            Action::Move {
                target: 16_384,
                relative: true,
                duration: cycle.saturating_mul(u32::try_from(cycles).unwrap_or(u32::MAX)),
            },
        ],
        cycle,
        dc,
    )?;
    // The measured window: the cycles in Operation enabled in CSP (the move and its settling;
    // steady cyclic operation: the master's start-up, when it aligns its cycle to SYNC0, is
    // left out). Each cycle sends one LRW
    // frame, the last one the last cycle's, so cycle c is LRW frame `len - 1 - (last - c)`.
    let cycles_of_move: Vec<u64> = run
        .rows
        .iter()
        .filter(|r| r.drive == 0 && r.out.controlword == 0x0F && r.out.mode == mode::CSP)
        .map(|r| r.cycle)
        .collect();
    let last_cycle = run.rows.iter().map(|r| r.cycle).max().unwrap_or(0);
    let frames = capture.take();
    let sent: Vec<u64> = frames
        .iter()
        .filter(|f| f.dir == Direction::ToSegment && has_lrw(&f.data))
        .map(|f| f.t_ns)
        .collect();
    let frame_of = |c: u64| -> Option<u64> {
        let back = usize::try_from(last_cycle.checked_sub(c)?).ok()?;
        sent.len()
            .checked_sub(1 + back)
            .and_then(|i| sent.get(i).copied())
    };
    let (t0, t1) = match (
        cycles_of_move.first().and_then(|&c| frame_of(c)),
        cycles_of_move.last().and_then(|&c| frame_of(c)),
    ) {
        (Some(a), Some(b)) if b > a => (a, b),
        _ => {
            return Err(MasterError::Usage(
                "the drives did not run the move (nothing to measure)".into(),
            ))
        }
    };
    let lrw: Vec<_> = frames
        .iter()
        .filter(|f| f.t_ns >= t0 && f.t_ns <= t1 + cycle_ns && has_lrw(&f.data))
        .collect();
    let out_t: Vec<u64> = lrw
        .iter()
        .filter(|f| f.dir == Direction::ToSegment && f.t_ns <= t1)
        .map(|f| f.t_ns)
        .collect();
    let periods: Vec<u64> = out_t.windows(2).map(|w| w[1] - w[0]).collect();

    // Round trip: each frame sent, to the next frame back.
    let mut rtt = Vec::new();
    let mut pending: Option<u64> = None;
    for f in &lrw {
        match f.dir {
            Direction::ToSegment => pending = Some(f.t_ns),
            Direction::ToMaster => {
                if let Some(s) = pending.take() {
                    rtt.push(f.t_ns - s);
                }
            }
        }
    }
    let events = seg.lock().unwrap_or_else(|e| e.into_inner()).take_events();
    let sync0: Vec<u64> = events
        .iter()
        .filter(|e| e.slave == ids[0] && e.event == EscEvent::Sync0 && e.t >= t0 && e.t <= t1)
        .map(|e| e.t)
        .collect();
    let sync_periods: Vec<u64> = sync0.windows(2).map(|w| w[1] - w[0]).collect();
    let mut rows = vec![PeriodRow::of(FRAME_PERIOD, &periods, Some(cycle_ns))];
    if dc {
        rows.push(PeriodRow::of(SYNC0_PERIOD, &sync_periods, Some(cycle_ns)));
    }
    rows.push(PeriodRow::of(ROUND_TRIP, &rtt, None));
    Ok(PeriodTable {
        cycle_ns,
        dc,
        joints,
        rows,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lrw_is_found_after_other_datagrams_and_not_in_short_frames() {
        let mut f = vec![0u8; 16];
        // FRMW (0x0E), 8 bytes, more follows; then LRW.
        f.extend_from_slice(&[0x0E, 0, 0, 0, 0, 0, 8, 0x80, 0, 0]);
        f.extend_from_slice(&[0; 10]);
        f.extend_from_slice(&[0x0C, 0, 0, 0, 0, 0, 2, 0x00, 0, 0, 0, 0, 0, 0]);
        assert!(has_lrw(&f));
        f[16 + 20] = 0x07; // BRD instead of LRW
        assert!(!has_lrw(&f));
        assert!(!has_lrw(&f[..20]));
    }

    #[test]
    fn rows_of_exact_periods_have_no_jitter() {
        let r = PeriodRow::of("x", &[1_000_000; 5], Some(1_000_000));
        assert_eq!((r.samples, r.mean_us, r.std_us), (5, 1000.0, 0.0));
        assert_eq!(r.within_1us, Some(1.0));
        let r = PeriodRow::of("x", &[999_000, 1_001_000, 1_003_000], Some(1_000_000));
        assert_eq!(r.within_1us, Some(2.0 / 3.0));
        assert!(r.std_us > 1.0);
    }
}
