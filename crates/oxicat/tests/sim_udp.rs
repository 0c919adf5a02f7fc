//! `oxicat sim --udp`: EtherCAT over UDP on the loopback interface (no privileges needed),
//! and the messages of `oxicat sim` for what cannot work.

use std::net::UdpSocket;
use std::process::{Command, Stdio};
use std::time::Duration;

use oxicat_testkit::served::{spawn_udp, Served};

use oxicat_wire::{Command as Cmd, DatagramHeader, FrameBuilder};

/// Starts `oxicat sim --udp 127.0.0.1:0 <devices>`; returns it and the address it bound.
fn start(devices: &[&str]) -> (Served, String) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_oxicat"));
    cmd.args(["sim", "--quiet", "--udp", "127.0.0.1:0"])
        .args(devices);
    spawn_udp(cmd)
}

fn brd_al_status(index: u8) -> Vec<u8> {
    let mut buf = [0u8; 64];
    let mut b = FrameBuilder::new_bare(&mut buf).unwrap();
    b.push(DatagramHeader::physical(Cmd::Brd, index, 0, 0x0130, 2), &[])
        .unwrap();
    let n = b.finish();
    buf[..n].to_vec()
}

#[test]
fn udp_brd_is_answered_with_the_working_counter() {
    let (_sim, addr) = start(&["demo:3"]);
    let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
    sock.set_read_timeout(Some(Duration::from_millis(500)))
        .unwrap();
    let mut reply = None;
    for attempt in 0..20u8 {
        let frame = brd_al_status(attempt);
        sock.send_to(&frame, &addr).unwrap();
        let mut buf = [0u8; 1500];
        if let Ok((n, _)) = sock.recv_from(&mut buf) {
            reply = Some((frame, buf[..n].to_vec()));
            break;
        }
    }
    let (sent, got) = reply.expect("a reply over UDP");
    assert_eq!(got.len(), sent.len(), "same frame length back");
    // EtherCAT header (2) + datagram header (10) + 2 data bytes, then the WKC.
    let wkc = u16::from_le_bytes([got[14], got[15]]);
    assert_eq!(wkc, 3, "each of the three ESCs counted the BRD");
    let al = u16::from_le_bytes([got[12], got[13]]);
    assert_eq!(al & 0x0F, 1, "the nodes are in INIT");
    // Garbage is ignored, the server keeps going.
    sock.send_to(&[0xFF; 3], &addr).unwrap();
    let frame = brd_al_status(99);
    let mut ok = false;
    for _ in 0..20 {
        sock.send_to(&frame, &addr).unwrap();
        let mut buf = [0u8; 1500];
        if let Ok((n, _)) = sock.recv_from(&mut buf) {
            ok = n == frame.len() && buf[1 + 2] == 99;
            break;
        }
    }
    assert!(ok, "still answering after a garbage datagram");
}

fn sim_error(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_oxicat"))
        .arg("sim")
        .args(args)
        .stdin(Stdio::null())
        .output()
        .expect("run oxicat");
    assert!(!out.status.success(), "{args:?} must fail");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn clear_messages_for_what_cannot_work() {
    let m = sim_error(&["--iface", "oxicat-nope0", "demo:1"]);
    assert!(m.contains("no network interface \"oxicat-nope0\""), "{m}");
    let m = sim_error(&["demo:1"]);
    assert!(m.contains("--iface") && m.contains("--udp"), "{m}");
    let m = sim_error(&["--udp", "127.0.0.1:0", "legs:4"]);
    assert!(
        m.contains("unknown device \"legs\"") && m.contains("demo"),
        "{m}"
    );
    let m = sim_error(&["--udp", "127.0.0.1:0"]);
    assert!(m.contains("no devices"), "{m}");
    let m = sim_error(&["--udp", "127.0.0.1:0", "--segment", "/nonexistent/seg.toml"]);
    assert!(m.contains("/nonexistent/seg.toml"), "{m}");
}
