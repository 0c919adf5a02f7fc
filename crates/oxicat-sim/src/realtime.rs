//! Real-time mode: the segment's virtual clock follows the host's monotonic clock
//! (virtual time = time at start + elapsed real time) and frames come from a
//! [`FramePort`] (an interface or a UDP socket, see [`crate::net`]).
//!
//! [`serve`] loops: bring the segment to "now" (SYNC0/SYNC1, firmware timers and main loop
//! run at their times on the way), wait for a frame at most [`RealtimeConfig::idle`] (or
//! not at all when spinning), bring the segment to the arrival time, walk the frame through
//! the ESCs — with the frames already waiting behind it, as one train on the line
//! ([`Segment::exchange_train`]) — and send the replies back where the frames came from. The event latency is the
//! wait granularity; what the master sees does not depend on it, because each frame meets
//! ESCs that were advanced to its arrival time first.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::model::SegmentEsc;
use crate::net::NetError;
use crate::segment::{FrameFate, Segment};

/// Most frames [`serve`] takes from its port at once as one train (a cycle of 1,000
/// twins' process data is a few dozen frames).
pub const MAX_TRAIN: usize = 64;

/// A source and sink of EtherCAT frames for [`serve`].
pub trait FramePort {
    /// Where a reply goes (the UDP sender; nothing for an interface).
    type Peer;

    /// Waits at most `timeout` (zero: do not wait) for the next EtherCAT frame and puts it
    /// in `buf` as a whole Ethernet frame; `Ok(None)` when none came in time.
    fn recv(
        &mut self,
        buf: &mut Vec<u8>,
        timeout: Duration,
    ) -> Result<Option<Self::Peer>, NetError>;

    /// Sends the returned Ethernet `frame` back to `peer`.
    fn send(&mut self, frame: &[u8], peer: &Self::Peer) -> Result<(), NetError>;

    /// One line saying where the port listens (for logs and status).
    fn describe(&self) -> String;
}

/// Options of [`serve`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RealtimeConfig {
    /// Longest wait for a frame before the segment is advanced again.
    pub idle: Duration,
    /// Poll without sleeping (one core at 100 %, lowest latency).
    pub spin: bool,
    /// Real time per virtual time: 1 follows the host's clock; `k` runs the segment `k`
    /// times slower (a virtual millisecond every `k` real ones), for firmware that cannot
    /// keep real time on this host (a board image executed instruction by instruction, a
    /// debug build under load). A master sees a slower segment: its DC cycles, watchdogs
    /// and firmware timers all stretch by `k`. 0 is taken as 1.
    pub slowdown: u32,
}

impl Default for RealtimeConfig {
    fn default() -> Self {
        Self {
            idle: Duration::from_millis(1),
            spin: false,
            slowdown: 1,
        }
    }
}

/// Counters of a running [`serve`], readable from other threads.
#[derive(Debug, Default)]
pub struct RealtimeStats {
    /// EtherCAT frames received.
    pub frames: AtomicU64,
    /// Frames answered.
    pub replies: AtomicU64,
    /// Frames that did not come back from the segment (lost, dropped by a fault, ignored).
    pub lost: AtomicU64,
    /// Replies that could not be sent.
    pub send_errors: AtomicU64,
    /// Longest time from a frame's arrival to its reply leaving, in ns.
    pub max_turnaround_ns: AtomicU64,
}

impl RealtimeStats {
    /// Frames received so far.
    pub fn frames(&self) -> u64 {
        self.frames.load(Ordering::Relaxed)
    }
}

/// Serves `segment` on `port` in real time until `stop` is set (checked at least every
/// [`RealtimeConfig::idle`]); returns the first fatal transport error. The segment is
/// locked only while it is advanced or walks a frame, so other threads can look at it.
pub fn serve<P: FramePort, E: SegmentEsc>(
    segment: &Arc<Mutex<Segment<E>>>,
    port: &mut P,
    config: &RealtimeConfig,
    stats: &RealtimeStats,
    stop: &AtomicBool,
) -> Result<(), NetError> {
    let lock = || segment.lock().unwrap_or_else(|e| e.into_inner());
    let base = lock().now();
    let start = Instant::now();
    let k = u64::from(config.slowdown.max(1));
    let now = |start: &Instant| base.saturating_add(start.elapsed().as_nanos() as u64 / k);
    let wait = if config.spin {
        Duration::ZERO
    } else {
        config.idle
    };
    // The frames of one train (see below), their senders and fates; reused.
    let mut bufs: Vec<Vec<u8>> = vec![Vec::with_capacity(2048)];
    let mut peers: Vec<P::Peer> = Vec::new();
    let mut fates: Vec<FrameFate> = Vec::new();
    // The segment is advanced on its own only after a wait that brought no frame (and at
    // the start); a frame is served with an advance to its arrival. Each advance visits
    // every slot: one more per frame is 11,000 slot visits per cycle at 1,000 twins.
    let mut idle = true;
    while !stop.load(Ordering::Relaxed) {
        if idle {
            lock().advance_to(now(&start));
        }
        let Some(peer) = port.recv(&mut bufs[0], wait)? else {
            idle = true;
            continue;
        };
        idle = false;
        let arrived = Instant::now();
        peers.clear();
        peers.push(peer);
        // The frames already waiting behind it go with it as one train: a master sends its
        // cycle's frames back to back, and on the line they follow each other one wire
        // time apart, not one trip (`Segment::exchange_train`).
        while peers.len() < MAX_TRAIN {
            if bufs.len() == peers.len() {
                bufs.push(Vec::with_capacity(2048));
            }
            match port.recv(&mut bufs[peers.len()], Duration::ZERO)? {
                Some(p) => peers.push(p),
                None => break,
            }
        }
        let n = peers.len();
        stats.frames.fetch_add(n as u64, Ordering::Relaxed);
        fates.clear();
        fates.resize(n, FrameFate::Lost);
        {
            let mut seg = lock();
            seg.advance_to(now(&start));
            seg.exchange_train(&mut bufs[..n], &mut fates, 0);
        }
        for ((buf, peer), fate) in bufs.iter().zip(&peers).zip(&fates) {
            if *fate != FrameFate::Returned {
                stats.lost.fetch_add(1, Ordering::Relaxed);
                continue;
            }
            match port.send(buf, peer) {
                Ok(()) => {
                    stats.replies.fetch_add(1, Ordering::Relaxed);
                    let dt = arrived.elapsed().as_nanos() as u64;
                    stats.max_turnaround_ns.fetch_max(dt, Ordering::Relaxed);
                }
                Err(e) => {
                    stats.send_errors.fetch_add(1, Ordering::Relaxed);
                    log::warn!("{e}");
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::VecDeque;

    /// A port fed from a queue; replies are collected.
    struct Queue {
        inbox: VecDeque<Vec<u8>>,
        sent: Arc<Mutex<Vec<Vec<u8>>>>,
        stop: Arc<AtomicBool>,
    }

    impl FramePort for Queue {
        type Peer = ();
        fn recv(&mut self, buf: &mut Vec<u8>, _t: Duration) -> Result<Option<()>, NetError> {
            match self.inbox.pop_front() {
                Some(f) => {
                    buf.clear();
                    buf.extend_from_slice(&f);
                    Ok(Some(()))
                }
                None => {
                    self.stop.store(true, Ordering::Relaxed);
                    Ok(None)
                }
            }
        }
        fn send(&mut self, frame: &[u8], _p: &()) -> Result<(), NetError> {
            self.sent.lock().unwrap().push(frame.to_vec());
            Ok(())
        }
        fn describe(&self) -> String {
            "queue".into()
        }
    }

    /// A line of `n` ET1100s with 256 bytes of SII each.
    fn line(n: usize) -> Segment {
        let mut seg = Segment::new();
        for _ in 0..n {
            seg.add(oxicat_esc::Esc::new(
                oxicat_esc::EscConfig::et1100(),
                vec![0; 256],
            ));
        }
        seg
    }

    fn brd_frame() -> Vec<u8> {
        let mut f = vec![0xFF; 6];
        f.extend_from_slice(&[0x10; 6]);
        f.extend_from_slice(&[0x88, 0xA4]);
        // EtherCAT header: 14 bytes of datagram, type 1.
        f.extend_from_slice(&(14u16 | 0x1000).to_le_bytes());
        // BRD 0x0000, 2 bytes.
        f.extend_from_slice(&[0x07, 0x01, 0, 0, 0, 0, 2, 0, 0, 0, 0, 0, 0, 0]);
        f.resize(60, 0);
        f
    }

    #[test]
    fn serves_frames_and_follows_real_time() {
        let seg = line(3);
        let seg = Arc::new(Mutex::new(seg));
        let stop = Arc::new(AtomicBool::new(false));
        let sent = Arc::new(Mutex::new(Vec::new()));
        let mut port = Queue {
            inbox: VecDeque::from(vec![brd_frame(), vec![1, 2, 3], brd_frame()]),
            sent: sent.clone(),
            stop: stop.clone(),
        };
        let stats = RealtimeStats::default();
        let t0 = Instant::now();
        serve(&seg, &mut port, &RealtimeConfig::default(), &stats, &stop).unwrap();
        let real = t0.elapsed().as_nanos() as u64;
        let sent = sent.lock().unwrap();
        assert_eq!(
            sent.len(),
            2,
            "two EtherCAT frames answered, garbage ignored"
        );
        for f in sent.iter() {
            assert_eq!(f[6], 0x12, "source MAC marked as returned");
            let wkc = u16::from_le_bytes([f[14 + 2 + 12], f[14 + 2 + 13]]);
            assert_eq!(wkc, 3, "every ESC answered the BRD");
        }
        assert_eq!(stats.frames(), 3);
        assert_eq!(stats.replies.load(Ordering::Relaxed), 2);
        assert_eq!(stats.lost.load(Ordering::Relaxed), 1);
        // Virtual time moved with real time, never beyond it by more than the frames' trips.
        let v = seg.lock().unwrap().now();
        assert!(v > 0);
        assert!(v <= real + 1_000_000);
    }

    #[test]
    fn a_slowdown_stretches_virtual_time() {
        let seg = line(1);
        let seg = Arc::new(Mutex::new(seg));
        let stop = Arc::new(AtomicBool::new(false));
        // Frames that each take a real millisecond to come: the segment is advanced to
        // "now" before each, which with a slowdown of 1000 is a thousandth of the time.
        struct Slow(Queue);
        impl FramePort for Slow {
            type Peer = ();
            fn recv(&mut self, buf: &mut Vec<u8>, t: Duration) -> Result<Option<()>, NetError> {
                std::thread::sleep(Duration::from_millis(1));
                self.0.recv(buf, t)
            }
            fn send(&mut self, frame: &[u8], p: &()) -> Result<(), NetError> {
                self.0.send(frame, p)
            }
            fn describe(&self) -> String {
                "slow queue".into()
            }
        }
        let mut port = Slow(Queue {
            inbox: VecDeque::from(vec![brd_frame(); 20]),
            sent: Arc::new(Mutex::new(Vec::new())),
            stop: stop.clone(),
        });
        let config = RealtimeConfig {
            slowdown: 1000,
            ..RealtimeConfig::default()
        };
        let t0 = Instant::now();
        serve(&seg, &mut port, &config, &RealtimeStats::default(), &stop).unwrap();
        let real = t0.elapsed().as_nanos() as u64;
        let v = seg.lock().unwrap().now();
        assert!(real >= 20_000_000, "twenty frames a real millisecond apart");
        assert!(v > 0, "virtual time moved");
        // At real time it would be at least `real`; slowed 1000 times it is a thousandth
        // of that plus the frames' own trips through the ESC (a few µs each).
        assert!(
            v <= real / 1000 + 20 * 20_000,
            "virtual {v} ns for {real} real ns at 1/1000"
        );
    }

    #[test]
    fn frames_waiting_together_go_as_one_train() {
        // One BRD's trip through 30 ESCs, from a segment of its own.
        let mut alone = line(30);
        alone.exchange(&brd_frame()).unwrap();
        let trip = alone.now();
        let seg = Arc::new(Mutex::new(line(30)));
        let stop = Arc::new(AtomicBool::new(false));
        let sent = Arc::new(Mutex::new(Vec::new()));
        let mut port = Queue {
            inbox: VecDeque::from(vec![brd_frame(); 3]),
            sent: sent.clone(),
            stop: stop.clone(),
        };
        // Virtual time all but stands still (a second of real time is a nanosecond).
        let config = RealtimeConfig {
            slowdown: 1_000_000_000,
            ..RealtimeConfig::default()
        };
        let stats = RealtimeStats::default();
        serve(&seg, &mut port, &config, &stats, &stop).unwrap();
        assert_eq!(sent.lock().unwrap().len(), 3);
        for f in sent.lock().unwrap().iter() {
            let wkc = u16::from_le_bytes([f[14 + 2 + 12], f[14 + 2 + 13]]);
            assert_eq!(wkc, 30);
        }
        // On the line together: two wire times and one trip, not three trips.
        let wire = Segment::<oxicat_esc::Esc>::wire_time_ns(60);
        let v = seg.lock().unwrap().now();
        assert!(v >= 2 * wire + trip, "{v} ns");
        assert!(
            v < 2 * wire + trip + 10,
            "{v} ns: the frames went one after the other"
        );
    }

    #[test]
    fn a_port_that_cannot_look_without_waiting_gets_each_reply_first() {
        // Like the raw socket's port: a `recv` that may wait waits its read timeout,
        // whatever it is asked, so a frame must be answered before the next such `recv`.
        struct Waits {
            q: Queue,
            owed: usize,
            waited_owing: Arc<AtomicBool>,
        }
        impl FramePort for Waits {
            type Peer = ();
            fn recv(&mut self, buf: &mut Vec<u8>, t: Duration) -> Result<Option<()>, NetError> {
                if t.is_zero() {
                    // It cannot look without waiting.
                    return Ok(None);
                }
                if self.owed > 0 {
                    self.waited_owing.store(true, Ordering::Relaxed);
                }
                let got = self.q.recv(buf, t)?;
                self.owed += usize::from(got.is_some());
                Ok(got)
            }
            fn send(&mut self, frame: &[u8], p: &()) -> Result<(), NetError> {
                self.owed -= 1;
                self.q.send(frame, p)
            }
            fn describe(&self) -> String {
                "waiting queue".into()
            }
        }
        let seg = line(1);
        let seg = Arc::new(Mutex::new(seg));
        let stop = Arc::new(AtomicBool::new(false));
        let sent = Arc::new(Mutex::new(Vec::new()));
        let waited_owing = Arc::new(AtomicBool::new(false));
        let mut port = Waits {
            q: Queue {
                inbox: VecDeque::from(vec![brd_frame(); 3]),
                sent: sent.clone(),
                stop: stop.clone(),
            },
            owed: 0,
            waited_owing: waited_owing.clone(),
        };
        serve(
            &seg,
            &mut port,
            &RealtimeConfig::default(),
            &RealtimeStats::default(),
            &stop,
        )
        .unwrap();
        assert_eq!(sent.lock().unwrap().len(), 3);
        assert!(
            !waited_owing.load(Ordering::Relaxed),
            "serve waited for a frame with a reply not yet sent"
        );
    }
}
