//! A segment file's `behaviour` and `[[device.entry]]` for twins: the segment built from it
//! serves what it says (a CSV track and a ramp read back by ethercrab in process), and every
//! bad value is refused with its key, without a panic.

use std::path::Path;
use std::sync::{Arc, Mutex};

use oxicat::sim_cmd::{build_segment, parse_segment, SimError};
use oxicat_master::cyclic::{CycleOptions, Flow};
use oxicat_master::pdo::{variables, Dir};
use oxicat_master::{Link, Master};
use oxicat_testkit::served::reference;

fn esi(file: &str) -> String {
    let p = reference().join(file);
    assert!(p.exists(), "reference file {} missing", p.display());
    // TOML basic strings: backslashes of Windows paths would need escaping.
    p.display().to_string().replace('\\', "/")
}

fn build(text: &str) -> Result<(oxicat_sim::segment::Segment, Vec<String>), SimError> {
    let desc = parse_segment(text, Path::new("test.toml"))?;
    build_segment(&desc)
}

fn k64f(entries: &str) -> String {
    format!(
        "[[device]]\nesi = \"{}\"\n{entries}",
        esi("esi/kickcat-freedom-k64f.xml")
    )
}

#[test]
fn csv_playback_and_a_ramp_from_a_segment_file_reach_the_master() {
    let dir = std::env::temp_dir().join(format!("oxicat-behaviour-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("track.csv");
    // 10 ms per sample: 7, -3, 250, repeated every 30 ms.
    std::fs::write(&csv, "time_s,value\n0,7\n0.010,-3\n0.020,250\n0.030,7\n").unwrap();
    let text = k64f(&format!(
        "[[device.entry]]\nentry = \"0x6000:0\"\ncsv = {{ file = \"{}\", repeat = true }}\n\
         [[device.entry]]\nentry = \"0x6001:0\"\nramp = {{ slope_per_s = 1000.0, start = 5.0 }}\n",
        csv.display().to_string().replace('\\', "/")
    ));
    let (seg, _) = build(&text).unwrap();
    let seg = Arc::new(Mutex::new(seg));
    let got = std::thread::Builder::new()
        .stack_size(64 << 20)
        .spawn({
            let seg = seg.clone();
            move || {
                let mut m = Master::open(Link::Sim(seg.clone())).unwrap();
                m.prepare_cyclic().unwrap();
                let vars = variables(&m.pdos(0).unwrap());
                let find = |o| {
                    vars.iter()
                        .find(|v| v.dir == Dir::Input && v.object == o)
                        .unwrap()
                        .clone()
                };
                let (c, r) = (find((0x6000, 0)), find((0x6001, 0)));
                let mut rows = Vec::new();
                m.run_cyclic(CycleOptions::default(), |io| {
                    let now = seg.lock().unwrap().now();
                    let g = |v| i16::from_le_bytes(io.get(v)[..2].try_into().unwrap());
                    rows.push((now, g(&c), g(&r)));
                    Ok(if io.cycle >= 80 {
                        Flow::Stop
                    } else {
                        Flow::Continue
                    })
                })
                .unwrap();
                rows
            }
        })
        .unwrap()
        .join()
        .unwrap();
    std::fs::remove_dir_all(&dir).ok();
    let mut seen = Vec::new();
    for &(now, c, r) in &got[2..] {
        // Written by a main-loop pass at most 300 µs before the frame (the 50 µs grid).
        let ok = |t_ns: u64| {
            let t = t_ns as f64 * 1e-9;
            let phase = t % 0.030;
            let want_c = if phase < 0.010 {
                7
            } else if phase < 0.020 {
                -3
            } else {
                250
            };
            let want_r = (5.0 + 1000.0 * t).round().min(i16::MAX as f64) as i16;
            c == want_c && r == want_r
        };
        let last = now / 50_000 * 50_000;
        assert!(
            (0..6u64).any(|j| ok(last.saturating_sub(j * 50_000))),
            "at {now} ns: csv {c}, ramp {r}"
        );
        if !seen.contains(&c) {
            seen.push(c);
        }
    }
    seen.sort();
    assert_eq!(
        seen,
        vec![-3, 7, 250],
        "every sample of the track was played"
    );
}

#[test]
fn bad_behaviour_is_refused_with_its_key() {
    let cases: Vec<(String, &str)> = vec![
        (
            k64f("[[device.entry]]\nentry = \"0x6FFF:0\"\nhold = 1\n"),
            "device[0].entry[0].entry",
        ),
        (
            k64f("[[device.entry]]\nentry = \"no such name\"\nhold = 1\n"),
            "device[0].entry[0].entry",
        ),
        (
            k64f("[[device.entry]]\nentry = \"0x6001:0\"\nsine = { amplitude = nan, frequency_hz = 1 }\n"),
            "device[0].entry[0].sine.amplitude",
        ),
        (
            k64f("[[device.entry]]\nentry = \"0x6001:0\"\nsine = { amplitude = 1, frequency_hz = inf }\n"),
            "device[0].entry[0].sine.frequency_hz",
        ),
        (
            k64f("[[device.entry]]\nentry = \"0x6001:0\"\nnoise = { amplitude = -inf, seed = 1 }\n"),
            "device[0].entry[0].noise.amplitude",
        ),
        (
            k64f("[[device.entry]]\nentry = \"0x6001:0\"\ncsv = { file = \"/nonexistent/track.csv\" }\n"),
            "device[0].entry[0].csv.file",
        ),
        (
            k64f("[[device.entry]]\nentry = \"0x6001:0\"\nhold = 1\nconstant = 2\n"),
            "device[0].entry[0]",
        ),
        (
            k64f("[[device.entry]]\nentry = \"0x6001:0\"\nramp = { slope_per_s = 1, min = 5, max = 1 }\n"),
            "device[0].entry[0].ramp.max",
        ),
        (
            k64f("[[device.entry]]\nentry = \"0x6001:0\"\nloop = \"0x7000:0\"\n"),
            "device[0].entry[0].loop",
        ),
        (
            k64f("[[device.entry]]\nentry = \"0x6001:0\"\nencoder = { volts = 1, from = \"0x7000:0\" }\n"),
            "device[0].entry[0].encoder",
        ),
        (
            k64f("[[device.entry]]\nentry = \"0x6001:0\"\nencoder = { volts = nan }\n"),
            "device[0].entry[0].encoder.volts",
        ),
        (
            k64f("[[device.entry]]\nentry = \"0x6001:0\"\nencoder = { from = \"0x7FFF:0\" }\n"),
            "device[0].entry[0].encoder.from",
        ),
        (
            k64f("[[device.entry]]\nentry = \"0x6001:0\"\nencoder = { volts = 2, supply = 0 }\n"),
            "device[0].entry[0].encoder.supply",
        ),
        (k64f("behaviour = \"drive\"\n"), "device[0].behaviour"),
        (k64f("behaviour = \"dance\"\n"), "device[0].behaviour"),
        (
            "[[device]]\nname = \"demo\"\nbehaviour = \"loop\"\n".to_string(),
            "device[0].behaviour",
        ),
        // Served by its ESC alone: no firmware to run a drive, and only input pins take
        // a rule (EL2008 has outputs only).
        (
            format!(
                "[[device]]\nesi = \"{}:EL2008\"\nbehaviour = \"drive\"\n",
                esi("esi-vendor/Beckhoff-EL2xxx.xml")
            ),
            "device[0].behaviour",
        ),
        (
            format!(
                "[[device]]\nesi = \"{}:EL2008\"\n[[device.entry]]\nentry = \"0x7000:1\"\nhold = 1\n",
                esi("esi-vendor/Beckhoff-EL2xxx.xml")
            ),
            "device[0].entry[0].entry",
        ),
    ];
    for (text, key) in cases {
        let e = std::panic::catch_unwind(|| build(&text))
            .unwrap_or_else(|_| panic!("panicked on\n{text}"))
            .err()
            .unwrap_or_else(|| panic!("accepted\n{text}"))
            .to_string();
        eprintln!("{e}");
        assert!(e.contains(key), "{key} not named in {e:?} for\n{text}");
    }
    // A bad CSV's line is named too.
    let bad = std::env::temp_dir().join(format!("oxicat-bad-{}.csv", std::process::id()));
    std::fs::write(&bad, "0,1\n0.5,x\n").unwrap();
    let text = k64f(&format!(
        "[[device.entry]]\nentry = \"0x6001:0\"\ncsv = {{ file = \"{}\" }}\n",
        bad.display().to_string().replace('\\', "/")
    ));
    let Err(e) = build(&text) else {
        panic!("a malformed CSV track was accepted");
    };
    let e = e.to_string();
    std::fs::remove_file(&bad).ok();
    assert!(
        e.contains("device[0].entry[0].csv.file") && e.contains("line 2"),
        "{e}"
    );
}

#[test]
fn a_drive_twin_and_a_loop_twin_build_from_a_file() {
    let text = format!(
        "[[device]]\nesi = \"{}\"\nbehaviour = \"drive\"\n\n[[device]]\nesi = \"{}\"\nbehaviour = \"loop\"\n",
        esi("esi-vendor/SOMANET_CiA_402.xml"),
        esi("esi/soes-linux_lan9252demo-slave.xml")
    );
    let (seg, names) = build(&text).unwrap();
    assert_eq!(seg.len(), 2);
    assert_eq!(names.len(), 2);
}
