//! `oxicat-emu sim --firmware`: board images served to a master outside the process.
//! The demo board image runs on two emulated boards of a segment served on UDP (slowed
//! down: a polling main loop is emulated in full and cannot keep real time here); an
//! ethercrab master in this process reaches it over the socket, brings both to OP and
//! exchanges process data with the right working counter every cycle; the CiA402 joint
//! image is served with its ET1100 and its joint (the board's own chip, not the LAN9252 of
//! the other boards): the master reads its identity and runs it in DC OP; the TUeES030
//! image is served with its three motors and runs SM-synchronous; bad `--firmware`
//! arguments are refused with the reason.

mod common;

use std::process::Command;
use std::time::Duration;

use oxicat_testkit::served::{spawn_udp, Served};

use oxicat_master::cyclic::CycleOptions;
use oxicat_master::{Link, Master, MasterOptions};

/// One served segment at a time: two slowed-down segments and their masters at once starve
/// each other on a loaded 2-core machine (frames past the master's timeouts).
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Starts `oxicat-emu sim --firmware FW --slowdown SLOWDOWN SEGMENT --udp 127.0.0.1:0`
/// and a master on it ([`open_served`], its timeouts stretched by the same slowdown).
fn serve(fw: &str, slowdown: u32, segment: &str) -> (Served, Master) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_oxicat-emu"));
    cmd.args(["sim", "--quiet", "--udp", "127.0.0.1:0", "--firmware", fw])
        .args(["--slowdown", &slowdown.to_string(), segment]);
    let (served, addr) = spawn_udp(cmd);
    (served, open_served(&addr, slowdown))
}

#[test]
fn ethercrab_runs_two_served_demo_board_images_in_op_over_udp() {
    let Some(img) = common::image("stm32f446-lan9252", "OXICAT_BOARD_IMAGE") else {
        return;
    };
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let path = std::env::temp_dir().join(format!("oxicat-emu-demo-{}.elf", std::process::id()));
    std::fs::write(&path, img).unwrap();
    let fw = format!("demo={}", path.display());
    // 20 times slower than real time: two boards emulated in full on a loaded 2-core box.
    let (_served, mut m) = serve(&fw, 20, "demo:2");
    let cycles = 300;
    let stats = m
        .run_cycles(
            CycleOptions {
                cycle: Duration::from_millis(2),
                dc: false,
            },
            cycles,
        )
        .unwrap_or_else(|e| panic!("{e}"));
    let _ = std::fs::remove_file(&path);
    assert_eq!((stats.cycles, stats.wkc_errors), (cycles, 0), "{stats:?}");
}

/// A master on a segment served `slowdown` times slower than real time, trying again while
/// the boards boot (until their clocks catch up with the segment's, frames can time out, as
/// one waits for a machine to power up).
///
/// Every timeout is the master's usual one stretched by the slowdown (the segment gets the
/// time it would have at real time), then twice more: the emulated boards are the
/// machine's heaviest load and fall further behind when other tests run beside them. The
/// mailbox echo timeout once was not stretched (100 ms of wall time, 5 ms of the boards'):
/// a board that missed it under load failed the bring-up with "timeout: mailbox echo".
fn open_served(addr: &str, slowdown: u32) -> Master {
    let options = || MasterOptions::for_link(&Link::Udp(addr.to_string())).stretched(2 * slowdown);
    let mut tries = 0;
    loop {
        match Master::open_with(Link::Udp(addr.to_string()), options()) {
            Ok(m) => break m,
            Err(e) if tries < 60 => {
                tries += 1;
                eprintln!("not yet ({e}); again");
                std::thread::sleep(Duration::from_secs(1));
            }
            Err(e) => panic!("ethercrab does not scan the served images: {e}"),
        }
    }
}

#[test]
fn a_served_cia402_joint_image_runs_on_its_et1100_in_dc_op_over_udp() {
    let Some(img) = common::image("cia402-joint", "OXICAT_CIA402_IMAGE") else {
        return;
    };
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let path = std::env::temp_dir().join(format!("oxicat-emu-joint-{}.elf", std::process::id()));
    std::fs::write(&path, img).unwrap();
    let fw = format!("cia402-joint={}", path.display());
    // The image sleeps between its interrupts: 20 times slower than real time is ample.
    let (_served, mut m) = serve(&fw, 20, "cia402-joint:1");
    let _ = std::fs::remove_file(&path);
    let id = oxicat_devices::cia402::DEF.identity;
    let product = m.sdo_upload(0, 0x1018, 2).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        product,
        id.product_code.to_le_bytes(),
        "the joint's identity"
    );
    let cycles = 100;
    let stats = m
        .run_cycles(
            CycleOptions {
                cycle: Duration::from_millis(1),
                dc: true,
            },
            cycles,
        )
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((stats.cycles, stats.wkc_errors), (cycles, 0), "{stats:?}");
}

#[test]
fn a_served_tue_es030_image_runs_sm_synchronous_over_udp() {
    let Some(img) = common::image("tue-es030", "OXICAT_TUE_ES030_IMAGE") else {
        return;
    };
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let path = std::env::temp_dir().join(format!("oxicat-emu-tue-{}.elf", std::process::id()));
    std::fs::write(&path, img).unwrap();
    let fw = format!("tue-es030={}", path.display());
    // Its 20 kHz current loop and the motors' 6.25 µs plant step run about 5 times slower
    // than real time here (debug): 20 times slower is ample.
    let (_served, mut m) = serve(&fw, 20, "tue-es030:1");
    let _ = std::fs::remove_file(&path);
    let id = oxicat_devices::tue_es030::device::DEF.identity;
    let product = m.sdo_upload(0, 0x1018, 2).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        product,
        id.product_code.to_le_bytes(),
        "the board's identity"
    );
    let cycles = 100;
    let stats = m
        .run_cycles(
            CycleOptions {
                cycle: Duration::from_millis(1),
                dc: false,
            },
            cycles,
        )
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((stats.cycles, stats.wkc_errors), (cycles, 0), "{stats:?}");
    assert_eq!(
        m.sdo_upload(0, 0x1C32, 1).unwrap_or_else(|e| panic!("{e}")),
        vec![1, 0],
        "SM-synchronous"
    );
}

#[test]
fn bad_firmware_arguments_are_refused_with_the_reason() {
    let run = |args: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_oxicat-emu"))
            .args(["sim", "--udp", "127.0.0.1:0"])
            .args(args)
            .output()
            .unwrap();
        assert!(!out.status.success(), "{args:?} was accepted");
        String::from_utf8_lossy(&out.stderr).to_string()
    };
    let e = run(&["--firmware", "nope=x.elf", "demo:1"]);
    assert!(e.contains("no device `nope`"), "{e}");
    let e = run(&["--firmware", "demo", "demo:1"]);
    assert!(e.contains("expected NAME=ELF"), "{e}");
    let e = run(&["--firmware", "demo=/nonexistent.elf", "demo:1"]);
    assert!(e.contains("/nonexistent.elf"), "{e}");
    // Not an ELF: refused before anything boots.
    let junk = std::env::temp_dir().join(format!("oxicat-emu-junk-{}.elf", std::process::id()));
    std::fs::write(&junk, b"not an image").unwrap();
    let e = run(&["--firmware", &format!("demo={}", junk.display()), "demo:1"]);
    let _ = std::fs::remove_file(&junk);
    assert!(e.contains("not a board image"), "{e}");
}
