//! The segment's event queue against the reference scheduler
//! (`Segment::set_reference_scheduler`: every slot read afresh at every pass, linear pick)
//! with real firmware: demo devices (the `oxicat-slave` stack on the software ESC, main loop
//! every 50 µs), twelve (the queue's heap layout) and four (its array layout), brought to
//! OP by ethercrab in the same process and cycled in free run and in DC SYNC0 mode. Both
//! schedulers must deliver the same events at the same times in the same order (the
//! segment's event log: SYNC0, IRQs) and the master must see the same inputs and working
//! counter in every cycle.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use oxicat_master::cyclic::{CycleOptions, Flow};
use oxicat_master::{Link, Master};
use oxicat_sim::segment::{LoggedEvent, Segment};

/// Nodes of the large segment (more than the queue's array layout takes).
const NODES: usize = 12;
/// Nodes of the small segment (the trot's four legs).
const FEW: usize = 4;
const CYCLES: u64 = 300;

/// What the master saw in one cycle: every slave's inputs and the working counter.
type Seen = (Vec<Vec<u8>>, u16);

/// Bring-up and `CYCLES` cycles of 500 µs: what the master saw in every cycle, and the
/// segment's event log.
fn run(reference: bool, dc: bool, nodes: usize) -> (Vec<Seen>, Vec<LoggedEvent>) {
    let kit = oxicat_devices::registry::find("demo").expect("the demo device");
    let mut seg = Segment::new();
    for k in 0..nodes {
        oxicat_devices::registry::add_node(&mut seg, kit, k, 0.0).expect("demo node");
    }
    seg.set_reference_scheduler(reference);
    seg.log_events(true);
    let seg = Arc::new(Mutex::new(seg));
    let seen = std::thread::Builder::new()
        .stack_size(64 << 20)
        .spawn({
            let seg = seg.clone();
            move || {
                let mut m = Master::open(Link::Sim(seg)).expect("bring-up");
                let mut seen = Vec::new();
                m.run_cyclic(
                    CycleOptions {
                        cycle: Duration::from_micros(500),
                        dc,
                    },
                    |io| {
                        seen.push((io.inputs.clone(), io.working_counter));
                        Ok(if io.cycle + 1 >= CYCLES {
                            Flow::Stop
                        } else {
                            Flow::Continue
                        })
                    },
                )
                .expect("cycling");
                seen
            }
        })
        .expect("master thread")
        .join()
        .expect("master thread ran");
    let events = seg.lock().unwrap().take_events();
    (seen, events)
}

#[test]
fn the_event_queue_runs_demo_firmware_as_the_reference_scheduler_does() {
    same_as_reference(NODES);
}

#[test]
fn the_small_event_queue_runs_demo_firmware_as_the_reference_scheduler_does() {
    same_as_reference(FEW);
}

fn same_as_reference(nodes: usize) {
    for dc in [false, true] {
        let (q_seen, q_events) = run(false, dc, nodes);
        let (r_seen, r_events) = run(true, dc, nodes);
        assert_eq!(q_seen.len(), CYCLES as usize);
        assert!(
            q_events
                .iter()
                .any(|e| e.event == oxicat_sim::node::EscEvent::Irq),
            "the firmware took interrupts"
        );
        if dc {
            assert!(
                q_events
                    .iter()
                    .filter(|e| e.event == oxicat_sim::node::EscEvent::Sync0)
                    .count()
                    > nodes * 100,
                "SYNC0 ran on every node"
            );
        }
        assert_eq!(q_events.len(), r_events.len(), "dc {dc}");
        assert!(
            q_events == r_events,
            "dc {dc}: the same events in the same order"
        );
        assert!(q_seen == r_seen, "dc {dc}: the same inputs in every cycle");
    }
}
