//! `oxicat cia402`: the verbs on a virtual segment of CiA402 joint drives.

use oxicat::cia402_cmd::{run, Cia402Args, Cia402Verb};

fn big<F: FnOnce() + Send + 'static>(f: F) {
    std::thread::Builder::new()
        .stack_size(64 << 20)
        .spawn(f)
        .unwrap()
        .join()
        .unwrap_or_else(|e| std::panic::resume_unwind(e));
}

fn args(verb: Cia402Verb, joints: usize, out: std::path::PathBuf) -> Cia402Args {
    Cia402Args {
        verb,
        joints,
        iface: None,
        cycle_us: 1000,
        no_dc: false,
        out,
    }
}

#[test]
fn enable_prints_each_step_and_move_writes_csv_and_svg() {
    big(|| {
        let dir = std::env::temp_dir().join(format!("oxicat-cia402-{}", std::process::id()));
        let text = run(args(Cia402Verb::Enable, 1, dir.clone())).unwrap();
        assert!(text.contains("controlword 0x0006") && text.contains("(ReadyToSwitchOn)"));
        assert!(text.contains("controlword 0x000F") && text.contains("(OperationEnabled)"));
        let text = run(args(
            Cia402Verb::Move {
                target: 20_000,
                relative: true,
                duration_ms: 500,
            },
            3,
            dir.clone(),
        ))
        .unwrap();
        assert_eq!(text.matches("CSP following error RMS").count(), 3, "{text}");
        assert!(dir.join("cia402.csv").exists());
        let svg = std::fs::read_to_string(dir.join("following-error.svg")).unwrap();
        assert_eq!(svg.matches("<polyline").count(), 3);
        let text = run(args(Cia402Verb::Mode { mode: "pv".into() }, 1, dir.clone())).unwrap();
        assert!(text.contains("mode of operation 3"));
        let text = run(args(Cia402Verb::Disable, 1, dir.clone())).unwrap();
        assert!(text.contains("(SwitchOnDisabled)"));
        let _ = std::fs::remove_dir_all(dir);
    });
}
