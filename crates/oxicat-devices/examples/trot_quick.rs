//! Runs the shipped trot scenario (optionally shortened: `trot_quick <trot_s>`) and prints
//! the summary and the speed.
use oxicat_devices::laelaps::experiment::run_trot;
use oxicat_devices::laelaps::results::{summarize, summary_markdown};
use oxicat_devices::laelaps::scenario::Scenario;

fn main() {
    let mut s = Scenario::thesis();
    if let Some(t) = std::env::args().nth(1) {
        s = s.with_trot(t.parse().expect("seconds"));
    }
    let run = run_trot(&s, &mut |_| {}).expect("run");
    if let Ok(p) = std::env::var("TROT_CSV") {
        std::fs::write(p, oxicat_devices::laelaps::results::csv(&run)).expect("csv");
    }
    let sum = summarize(&run);
    println!("{}", summary_markdown(&run, &sum));
    let rec_s = run.rows.len() as f64 * s.cycle_ns() as f64 * 1e-9;
    println!(
        "simulated {:.2} s ({:.2} s recorded) in {:.3} s wall ({:.3} s recorded part): {:.1}x real time (recorded part)",
        run.simulated_s,
        rec_s,
        run.wall.as_secs_f64(),
        run.wall_recorded.as_secs_f64(),
        rec_s / run.wall_recorded.as_secs_f64()
    );
}
