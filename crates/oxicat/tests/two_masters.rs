//! Two masters on one segment (in-process, the segment of `--sim`): one cycling (`record`),
//! the other inspecting or changing states meanwhile.

use oxicat_master::cyclic::CycleOptions;
use oxicat_master::{AlState, Link, Master};

fn in_op(m: &Master, p: usize) -> bool {
    m.al_status(p).is_ok_and(|s| s.state() == Some(AlState::Op))
}

/// Runs a free-run `record` of `cycles` cycles on its own master in a thread.
fn record(
    seg: &std::sync::Arc<std::sync::Mutex<oxicat_sim::segment::Segment>>,
    cycles: u64,
) -> std::thread::JoinHandle<Result<oxicat_master::cyclic::CycleStats, String>> {
    let seg = seg.clone();
    std::thread::Builder::new()
        .stack_size(16 << 20)
        .spawn(move || {
            let mut m = Master::open(Link::Sim(seg)).map_err(|e| e.to_string())?;
            m.prepare_cyclic().map_err(|e| e.to_string())?;
            let layouts = m.layouts().map_err(|e| e.to_string())?;
            let vars: Vec<_> = m
                .resolve(&["0.InINT32Var3".to_string()], &layouts)
                .map_err(|e| e.to_string())?
                .into_iter()
                .flatten()
                .collect();
            let mut sink = Vec::new();
            m.record(
                CycleOptions {
                    cycle: std::time::Duration::from_millis(1),
                    dc: false,
                },
                &vars,
                cycles,
                &mut sink,
                &mut |_, _| {},
            )
            .map_err(|e| e.to_string())
        })
        .unwrap()
}

#[test]
fn a_second_master_during_record() {
    let seg = oxicat::master_cmd::build_sim("demo:2").unwrap();
    let other = Master::open(Link::Sim(seg.clone())).unwrap();
    // `slaves` during a record: reads only, the record goes on undisturbed.
    let rec = record(&seg, 200);
    while !in_op(&other, 1) {
        std::thread::yield_now();
    }
    let list = other.scan().unwrap();
    assert_eq!(list.len(), 2);
    let stats = rec.join().unwrap().unwrap();
    assert_eq!(stats.wkc_errors, 0, "{stats:?}");

    // `states init` of one slave during a record: the record stops and says so.
    let rec = record(&seg, 2000);
    while !in_op(&other, 1) {
        std::thread::yield_now();
    }
    let mut other = Master::open(Link::Sim(seg.clone())).unwrap();
    other.request_state(&[1], AlState::Init).unwrap();
    let err = rec.join().unwrap().unwrap_err();
    assert!(err.contains("another master changed the segment"), "{err}");
    assert!(err.contains("slave 1 is in INIT"), "{err}");
}
