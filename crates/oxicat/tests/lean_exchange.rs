//! The master's lean free-run exchange (`oxicat_master::cyclic::Exchange`): the process
//! image in LRWs sent together plus one BRD of AL status, against ethercrab's `tx_rx`, on
//! a segment of 150 AX58100 DIO twins whose output pins are wired to their input pins.

use std::sync::{Arc, Mutex};

use oxicat_master::cyclic::{CycleOptions, CycleStats, Exchange, Flow};
use oxicat_master::{Link, Master, MasterError};
use oxicat_sim::segment::Segment;

const N: usize = 150;

/// `n` AX58100 DIO twins.
fn segment(n: usize) -> Arc<Mutex<Segment>> {
    let esi = oxicat_testkit::served::reference()
        .join("esi-vendor/AX58100_EVB_DIO_ESI_00010200_00000001_20220323.xml");
    oxicat::master_cmd::build_sim(&format!("esi={}*{n}", esi.display())).unwrap()
}

/// What a run saw: its statistics, the frames the segment got per cycle, and per cycle
/// every slave's inputs and the working counter.
struct Run {
    stats: CycleStats,
    frames_per_cycle: f64,
    seen: Vec<(Vec<Vec<u8>>, u16)>,
}

/// Cycles `cycles` times with `exchange`, each slave's outputs set to its own pattern
/// from the first cycle on.
fn run(exchange: Exchange, cycles: u64) -> Run {
    let seg = segment(N);
    let seg2 = seg.clone();
    std::thread::Builder::new()
        .stack_size(64 << 20)
        .spawn(move || {
            let mut m = Master::open(Link::Sim(seg2)).unwrap();
            m.set_exchange(exchange);
            let mut seen = Vec::new();
            let (mut sent0, mut sent) = (0, 0);
            let stats = m
                .run_cyclic(CycleOptions::default(), |io| {
                    // Frames between the first and the last cycle's end: cycles − 1 exchanges.
                    if io.cycle == 0 {
                        sent0 = seg.lock().unwrap().stats().sent;
                    }
                    if io.cycle + 1 == cycles {
                        sent = seg.lock().unwrap().stats().sent - sent0;
                    }
                    for (p, o) in io.outputs.iter_mut().enumerate() {
                        for (k, b) in o.iter_mut().enumerate() {
                            *b = (p as u8).wrapping_mul(7) ^ (k as u8) << 5;
                        }
                    }
                    seen.push((io.inputs.clone(), io.working_counter));
                    Ok(if io.cycle + 1 >= cycles {
                        Flow::Stop
                    } else {
                        Flow::Continue
                    })
                })
                .unwrap();
            Run {
                stats,
                frames_per_cycle: sent as f64 / (cycles - 1) as f64,
                seen,
            }
        })
        .unwrap()
        .join()
        .unwrap()
}

#[test]
fn the_lean_exchange_sends_two_frames_and_sees_what_ethercrabs_sees() {
    let cycles = 30;
    let lean = run(Exchange::Auto, cycles);
    let crab = run(Exchange::Ethercrab, cycles);
    // ethercrab: the 600-byte image with 35 status reads, then two frames of reads.
    assert_eq!(crab.stats.exchange, Exchange::Ethercrab);
    assert_eq!(crab.stats.frames_per_cycle, 3);
    assert_eq!(crab.frames_per_cycle, 3.0);
    // Auto takes the lean exchange: one LRW and the BRD.
    assert_eq!(lean.stats.exchange, Exchange::Lean);
    assert_eq!(lean.stats.frames_per_cycle, 2);
    assert_eq!(lean.frames_per_cycle, 2.0);
    for r in [&lean, &crab] {
        assert_eq!(r.stats.cycles, cycles);
        assert_eq!(r.stats.wkc_errors, 0);
        // Every slave's outputs came back on its inputs (pins wired), in both runs.
        let (inputs, wkc) = r.seen.last().unwrap();
        assert_eq!(*wkc, 3 * N as u16, "every slave read and written");
        for (p, i) in inputs.iter().enumerate() {
            assert!(!i.is_empty());
            let want: Vec<u8> = (0..i.len())
                .map(|k| (p as u8).wrapping_mul(7) ^ (k as u8) << 5)
                .collect();
            assert_eq!(*i, want, "slave {p}");
        }
    }
    assert_eq!(
        lean.seen.iter().map(|s| s.1).collect::<Vec<_>>(),
        crab.seen.iter().map(|s| s.1).collect::<Vec<_>>(),
        "the same working counter every cycle"
    );
}

/// A demo node whose watchdog expires goes to SAFE-OP and keeps counting its FMMUs (the working
/// counter does not change): the BRD of AL status shows it, and the run stops naming it;
/// a pulled cable changes the working counter and names every slave behind it.
#[test]
fn the_lean_exchange_sees_a_slave_leave_op_and_a_pulled_cable() {
    for pull in [false, true] {
        let seg = if pull {
            segment(40)
        } else {
            oxicat::master_cmd::build_sim("demo:3").unwrap()
        };
        let seg2 = seg.clone();
        let err = std::thread::Builder::new()
            .stack_size(64 << 20)
            .spawn(move || {
                let mut m = Master::open(Link::Sim(seg2.clone())).unwrap();
                m.set_exchange(Exchange::Lean);
                m.run_cyclic(CycleOptions::default(), |io| {
                    if io.cycle == 10 {
                        if pull {
                            seg2.lock().unwrap().set_cable(29, 1, false).unwrap();
                        } else {
                            // The node's process-data watchdog expires: its firmware
                            // goes to SAFE-OP with the error flag (0x001B).
                            let mut seg = seg2.lock().unwrap();
                            assert!(seg.esc_mut(1).unwrap().expire_pd_watchdog());
                        }
                    }
                    Ok(if io.cycle > 200 {
                        Flow::Stop
                    } else {
                        Flow::Continue
                    })
                })
            })
            .unwrap()
            .join()
            .unwrap();
        let _ = seg;
        match err {
            Err(e @ MasterError::Disturbed { .. }) => {
                let t = e.to_string();
                if pull {
                    assert!(t.contains("slave 30:") && t.contains("slave 39:"), "{t}");
                    assert!(!t.contains("slave 29"), "{t}");
                } else {
                    assert!(t.contains("slave 1 is in SAFEOP + ERROR (0x001B"), "{t}");
                }
            }
            other => panic!("pull {pull}: expected Disturbed, got {other:?}"),
        }
    }
}

/// 40 demo nodes: a 1,840-byte image in two LRWs sent together with the BRD, which
/// ethercrab puts on the wire in the order of its 16 storage slots (so, in every cycle where
/// the three frames wrap around the slots, not in the order they were made). No node's
/// SyncManager may be split over the two LRWs: a 3-buffer SM read in two parts, second part
/// first, counts no access. Every cycle's working counter is the planned one.
#[test]
fn lrws_sent_together_in_any_order_keep_every_working_counter() {
    let seg = oxicat::master_cmd::build_sim("demo:40").unwrap();
    let stats = std::thread::Builder::new()
        .stack_size(64 << 20)
        .spawn(move || {
            let mut m = Master::open(Link::Sim(seg)).unwrap();
            m.set_exchange(Exchange::Lean);
            m.run_cycles(CycleOptions::default(), 300).unwrap()
        })
        .unwrap()
        .join()
        .unwrap();
    assert_eq!(stats.exchange, Exchange::Lean);
    assert_eq!(stats.frames_per_cycle, 3, "two LRWs and the BRD");
    assert_eq!(stats.cycles, 300);
    assert_eq!(stats.wkc_errors, 0);
}

/// Frames in flight together go through a virtual segment in one order whatever the
/// host does: two runs of the same segment give the same inputs and working counter
/// every cycle and end at the same virtual time (with a transport thread, which frames
/// it found sendable when it woke depended on thread timing, and so did the virtual
/// time between them: `segment_scale --virtual --kind demo --n 128` gave two digests in
/// two runs of one binary).
#[test]
fn a_virtual_segment_runs_the_same_every_time() {
    let once = || {
        let seg = oxicat::master_cmd::build_sim("demo:40").unwrap();
        let seg2 = seg.clone();
        std::thread::Builder::new()
            .stack_size(64 << 20)
            .spawn(move || {
                let mut m = Master::open(Link::Sim(seg2)).unwrap();
                m.set_exchange(Exchange::Lean);
                let mut seen = Vec::new();
                m.run_cyclic(CycleOptions::default(), |io| {
                    for (p, o) in io.outputs.iter_mut().enumerate() {
                        for (k, b) in o.iter_mut().enumerate() {
                            *b = (io.cycle as u8) ^ (p as u8).wrapping_mul(3) ^ k as u8;
                        }
                    }
                    seen.push((io.inputs.clone(), io.working_counter));
                    Ok(if io.cycle + 1 >= 100 {
                        Flow::Stop
                    } else {
                        Flow::Continue
                    })
                })
                .unwrap();
                let t = oxicat_wire::pipe::FramePipe::now(&*seg.lock().unwrap());
                (seen, t)
            })
            .unwrap()
            .join()
            .unwrap()
    };
    let (a, ta) = once();
    let (b, tb) = once();
    assert_eq!(a.len(), 100);
    assert_eq!(ta, tb, "the same virtual time at the end");
    assert!(a == b, "the same inputs and working counter every cycle");
}

#[test]
fn the_frames_of_a_cycle_are_on_the_line_together() {
    // demo:40's process image (1,840 B) takes two LRWs; the lean exchange sends them and
    // its BRD together, and the in-process transport hands them to the segment as one
    // train: the second frame leaves the master before the first is back.
    let seg = oxicat::master_cmd::build_sim("demo:40").unwrap();
    let cap = oxicat_sim::capture::MemoryCapture::new();
    let seg2 = seg.clone();
    let frames = std::thread::Builder::new()
        .stack_size(64 << 20)
        .spawn(move || {
            let mut m = Master::open(Link::Sim(seg2.clone())).unwrap();
            m.set_exchange(Exchange::Lean);
            let mut armed = false;
            m.run_cyclic(CycleOptions::default(), |io| {
                if !armed && io.cycle >= 10 {
                    seg2.lock()
                        .unwrap()
                        .set_capture(Some(Box::new(cap.clone())));
                    armed = true;
                }
                Ok(if io.cycle + 1 >= 20 {
                    Flow::Stop
                } else {
                    Flow::Continue
                })
            })
            .unwrap();
            cap.frames()
        })
        .unwrap()
        .join()
        .unwrap();
    assert!(frames.len() > 10, "{} frames captured", frames.len());
    use oxicat_sim::capture::Direction;
    // A request right after a request: on the line together.
    let together = frames
        .windows(2)
        .filter(|w| w[0].dir == Direction::ToSegment && w[1].dir == Direction::ToSegment)
        .count();
    assert!(
        together >= 9,
        "{together} requests sent behind another in 10 cycles"
    );
    // Each next one a wire time or more after the one before, before that one came back.
    let mut last_sent: Option<(u64, usize)> = None;
    for f in &frames {
        if f.dir == Direction::ToSegment {
            if let Some((t, len)) = last_sent {
                assert!(
                    f.t_ns
                        >= t + oxicat_sim::segment::Segment::<oxicat_esc::Esc>::wire_time_ns(len)
                );
            }
            last_sent = Some((f.t_ns, f.data.len()));
        } else {
            last_sent = None;
        }
    }
    drop(seg);
}

/// The logical start addresses of every active FMMU of every node (read off the ESCs).
fn fmmu_starts(seg: &Mutex<Segment>, n: usize) -> Vec<Vec<(u32, u8)>> {
    let seg = seg.lock().unwrap();
    (0..n)
        .map(|p| {
            let mem = seg.esc(p).unwrap().memory();
            (0..16)
                .map(|k| &mem[0x600 + 16 * k..0x610 + 16 * k])
                .filter(|b| b[12] & 1 != 0)
                .map(|b| (u32::from_le_bytes([b[0], b[1], b[2], b[3]]), b[11]))
                .collect()
        })
        .collect()
}

/// The overlapped exchange (SOEM's overlapped IO map): 40 demo nodes' 24 output and 22 input
/// bytes take 960 bytes of LRW instead of 1,840, one LRW instead of two; every node echoes
/// its outputs into its inputs (Input1 = Output1, InputUINT16 = OutputUINT16, Input2 =
/// Output2) as under the lean exchange, with the planned working counter every cycle; the
/// FMMUs are moved for the run and moved back after it.
#[test]
fn the_overlapped_exchange_carries_each_node_once_and_moves_the_fmmus_back() {
    const N: usize = 40;
    let mut runs = Vec::new();
    for exchange in [Exchange::Lean, Exchange::Overlapped] {
        let seg = oxicat::master_cmd::build_sim(&format!("demo:{N}")).unwrap();
        let seg2 = seg.clone();
        let r = std::thread::Builder::new()
            .stack_size(64 << 20)
            .spawn(move || {
                let mut m = Master::open(Link::Sim(seg2.clone())).unwrap();
                m.set_exchange(exchange);
                m.prepare_cyclic().unwrap();
                let before = fmmu_starts(&seg2, N);

                let mut during = Vec::new();
                let mut last = (Vec::new(), Vec::new(), 0u16);
                let stats = m
                    .run_cyclic(CycleOptions::default(), |io| {
                        if io.cycle == 5 {
                            during = fmmu_starts(&seg2, N);
                        }
                        for (p, o) in io.outputs.iter_mut().enumerate() {
                            for (k, b) in o.iter_mut().enumerate() {
                                *b = (p as u8).wrapping_mul(11) ^ (k as u8).wrapping_mul(5);
                            }
                        }
                        last = (io.outputs.clone(), io.inputs.clone(), io.working_counter);
                        Ok(if io.cycle + 1 >= 40 {
                            Flow::Stop
                        } else {
                            Flow::Continue
                        })
                    })
                    .unwrap();
                let after = fmmu_starts(&seg2, N);
                (stats, before, during, after, last)
            })
            .unwrap()
            .join()
            .unwrap();
        runs.push(r);
    }
    let [(lean, lb, ld, la, lean_io), (over, ob, od, oa, over_io)] = &runs[..] else {
        unreachable!()
    };
    assert_eq!(lean.exchange, Exchange::Lean);
    assert_eq!(lean.frames_per_cycle, 3, "two LRWs and the BRD");
    assert_eq!(over.exchange, Exchange::Overlapped);
    assert_eq!(over.frames_per_cycle, 2, "one LRW and the BRD");
    for s in [lean, over] {
        assert_eq!(s.cycles, 40);
        assert_eq!(s.wkc_errors, 0);
    }
    // ethercrab activates the FMMUs on the way to SAFE-OP, not in PRE-OP.
    assert!(lb.iter().chain(ob).all(|f| f.is_empty()));
    // ethercrab's layout (every node's inputs, then every node's outputs) in the lean run
    // and after it; the overlapped run's segment has the same after it.
    assert_eq!(ld[0].len(), 2);
    assert_eq!(ld, la);
    assert_eq!(la, oa, "moved back");
    assert_ne!(od, oa);
    // During the overlapped run each node's read FMMU (type 1) starts where its write
    // FMMU (type 2) does, 24 bytes after the node before.
    let base = od[0][0].0;
    for (p, f) in od.iter().enumerate() {
        let w: Vec<u32> = f.iter().filter(|x| x.1 == 2).map(|x| x.0).collect();
        let r: Vec<u32> = f.iter().filter(|x| x.1 == 1).map(|x| x.0).collect();
        assert_eq!(w, vec![base + 24 * p as u32], "node {p}");
        assert_eq!(r, w, "node {p}");
    }
    for (outputs, inputs, wkc) in [lean_io, over_io] {
        assert_eq!(*wkc, 3 * N as u16);
        for p in 0..N {
            assert_eq!(outputs[p].len(), 24);
            assert_eq!(inputs[p].len(), 22);
            // Buttons (2 bytes), then Output1, OutputUINT16, Output2: echoed first.
            assert_eq!(inputs[p][..10], outputs[p][2..12], "node {p}");
        }
    }
}
