//! `oxicat cia402`: the verbs on a virtual segment of CiA402 joint drives.

use oxicat::cia402_cmd::{run, Cia402Args, Cia402Verb};

use oxicat_testkit::big;

fn args(verb: Cia402Verb, joints: usize, out: std::path::PathBuf) -> Cia402Args {
    Cia402Args {
        format: oxicat::output::Format::Csv,
        verb,
        joints,
        iface: None,
        cycle_us: 1000,
        no_dc: false,
        out,
    }
}

#[test]
fn enable_prints_each_step_and_arm_move_writes_csv_png_and_svg() {
    big(|| {
        let dir = std::env::temp_dir().join(format!("oxicat-cia402-{}", std::process::id()));
        let text = run(args(Cia402Verb::Enable, 1, dir.clone())).unwrap();
        assert!(text.contains("controlword 0x0006") && text.contains("(ReadyToSwitchOn)"));
        assert!(text.contains("controlword 0x000F") && text.contains("(OperationEnabled)"));
        // The six-joint arm: one segment, 1 kHz DC, each joint its own CSP move.
        let text = run(args(
            Cia402Verb::Move {
                target: 20_000,
                relative: true,
                duration_ms: 500,
                arm: true,
            },
            6,
            dir.clone(),
        ))
        .unwrap();
        assert_eq!(text.matches("CSP following error RMS").count(), 6, "{text}");
        let csv = std::fs::read_to_string(dir.join("cia402.csv")).unwrap();
        for j in 0..6 {
            assert!(
                csv.lines()
                    .skip(1)
                    .filter(|l| l.split(',').nth(2) == Some(&j.to_string()))
                    .count()
                    > 500,
                "joint {j} recorded every cycle"
            );
        }
        let png = std::fs::read(dir.join("following-error.png")).unwrap();
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
        let svg = std::fs::read_to_string(dir.join("following-error.svg")).unwrap();
        assert!(svg.contains("<svg") && svg.contains("joint 0") && svg.contains("joint 5"));
        let text = run(args(Cia402Verb::Mode { mode: "pv".into() }, 1, dir.clone())).unwrap();
        assert!(text.contains("mode of operation 3"));
        let text = run(args(Cia402Verb::Disable, 1, dir.clone())).unwrap();
        assert!(text.contains("(SwitchOnDisabled)"));
        let _ = std::fs::remove_dir_all(dir);
    });
}

/// `oxicat cia402 task-period`: the output is the table (the paper's 1 ms experiment), its
/// mean period the configured cycle; bad counts and `--iface` are refused with the option
/// named.
#[test]
fn task_period_prints_the_table_and_refuses_bad_arguments() {
    big(|| {
        let dir = std::env::temp_dir();
        let text = run(args(Cia402Verb::TaskPeriod { cycles: 100 }, 1, dir.clone())).unwrap();
        let rows: Vec<&str> = text.lines().filter(|l| l.starts_with("| ")).collect();
        assert_eq!(rows.len(), 4, "header + 3 rows: {text}");
        assert!(
            rows[1].starts_with("| cyclic frame period, master link |"),
            "{text}"
        );
        assert_eq!(rows[1].split('|').nth(3).map(str::trim), Some("1000.000"));
        assert!(rows[2].starts_with("| SYNC0 period"), "{text}");
        assert!(rows[3].starts_with("| frame round trip"), "{text}");
        let e = run(args(Cia402Verb::TaskPeriod { cycles: 3 }, 1, dir.clone()))
            .unwrap_err()
            .to_string();
        assert!(e.contains("--cycles 3"), "{e}");
        let mut a = args(Cia402Verb::TaskPeriod { cycles: 100 }, 1, dir);
        a.iface = Some("eth9".into());
        let e = run(a).unwrap_err().to_string();
        assert!(e.contains("--iface"), "{e}");
    });
}
