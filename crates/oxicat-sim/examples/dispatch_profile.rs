//! Profiling driver for configured-address dispatch (issue 18 item 1):
//! `dispatch_profile <escs> <cycles> [--per-esc-walk]` cycles a line of bare ESCs (station
//! addresses 0x1000 + k, one FMMU each over one byte of process RAM) as ethercrab's
//! `tx_rx` does: one LRW frame with every ESC's byte, then the per-slave state checks, an
//! FPRD of AL status (0x0130) per ESC, 100 to a frame. Each cycle's frames and working
//! counters are checked; it prints the cycles run and a checksum of the last frames. Run it
//! under `valgrind --tool=callgrind` with two cycle counts and take the difference per
//! cycle; `--per-esc-walk` is the reference walk (every ESC walks every datagram).

use oxicat_esc::{Esc, EscConfig};
use oxicat_sim::segment::Segment;

/// FPRDs per frame (ethercrab fills its frames up to its PDU and length limits).
const CHECKS_PER_FRAME: usize = 100;

fn fail(msg: &str) -> ! {
    eprintln!("dispatch_profile: {msg}");
    std::process::exit(2)
}

/// An Ethernet frame with the datagrams `(cmd, adp, ado, data length)`.
fn frame(dgs: &[(u8, u16, u16, usize)]) -> Vec<u8> {
    let mut f = vec![0xFF; 6];
    f.extend_from_slice(&[0x02, 0, 0, 0, 0, 1, 0x88, 0xA4]);
    let mut body = Vec::new();
    for (i, &(cmd, adp, ado, len)) in dgs.iter().enumerate() {
        let more = if i + 1 < dgs.len() { 0x8000u16 } else { 0 };
        body.extend_from_slice(&[cmd, i as u8]);
        body.extend_from_slice(&adp.to_le_bytes());
        body.extend_from_slice(&ado.to_le_bytes());
        body.extend_from_slice(&(len as u16 | more).to_le_bytes());
        body.extend_from_slice(&[0, 0]);
        body.extend(std::iter::repeat_n(0x5A, len));
        body.extend_from_slice(&[0, 0]);
    }
    f.extend_from_slice(&(0x1000 | body.len() as u16).to_le_bytes());
    f.extend_from_slice(&body);
    f
}

/// The working counters of a returned frame's datagrams.
fn wkcs(f: &[u8]) -> Vec<u16> {
    let mut out = Vec::new();
    let mut at = 16;
    while at + 12 <= f.len() {
        let len = (u16::from_le_bytes([f[at + 6], f[at + 7]]) & 0x07FF) as usize;
        let more = f[at + 7] & 0x80 != 0;
        let w = at + 10 + len;
        out.push(u16::from_le_bytes([f[w], f[w + 1]]));
        at = w + 2;
        if !more {
            break;
        }
    }
    out
}

fn main() {
    let mut args = std::env::args().skip(1);
    let n: usize = args
        .next()
        .and_then(|a| a.parse().ok())
        .filter(|&n| (1..=1000).contains(&n))
        .unwrap_or_else(|| {
            fail("usage: dispatch_profile <escs 1..=1000> <cycles> [--per-esc-walk]")
        });
    let cycles: u64 = args
        .next()
        .and_then(|a| a.parse().ok())
        .unwrap_or_else(|| fail("<cycles> missing"));
    let per_esc = args.next().as_deref() == Some("--per-esc-walk");
    let mut seg = Segment::line((0..n).map(|_| Esc::new(EscConfig::et1100(), vec![0; 256])));
    seg.set_configured_dispatch(!per_esc);
    // Set-up through auto-increment writes: station address, FMMU 0 (logical k ↔ 0x1000,
    // one byte, read and write, enabled).
    for k in 0..n {
        let adp = 0u16.wrapping_sub(k as u16);
        let mut f = frame(&[(0x02, adp, 0x0010, 2), (0x02, adp, 0x0600, 16)]);
        let d0 = 16 + 10;
        f[d0..d0 + 2].copy_from_slice(&(0x1000 + k as u16).to_le_bytes());
        let d1 = d0 + 2 + 2 + 10;
        let mut fmmu = [0u8; 16];
        fmmu[0..4].copy_from_slice(&(k as u32).to_le_bytes());
        fmmu[4..6].copy_from_slice(&1u16.to_le_bytes());
        fmmu[7] = 7;
        fmmu[8..10].copy_from_slice(&0x1000u16.to_le_bytes());
        fmmu[11] = 3;
        fmmu[12] = 1;
        f[d1..d1 + 16].copy_from_slice(&fmmu);
        if seg.exchange(&f).is_none() {
            fail("set-up frame lost");
        }
    }
    let mut frames = vec![frame(&[(0x0C, 0, 0, n)])];
    let checks: Vec<_> = (0..n)
        .map(|k| (0x04u8, 0x1000 + k as u16, 0x0130u16, 2usize))
        .collect();
    for c in checks.chunks(CHECKS_PER_FRAME) {
        frames.push(frame(c));
    }
    let mut sum = 0u64;
    let mut buf = Vec::new();
    for _ in 0..cycles {
        for (i, f) in frames.iter().enumerate() {
            buf.clear();
            buf.extend_from_slice(f);
            if !seg.exchange_in_place(&mut buf) {
                fail("frame lost");
            }
            let w = wkcs(&buf);
            let want = if i == 0 { 3 * n as u16 } else { 1 };
            if w.iter().any(|&x| x != want) {
                fail(&format!(
                    "frame {i}: working counters {w:?}, expected {want} each"
                ));
            }
            sum = sum.wrapping_add(buf.iter().map(|&b| b as u64).sum::<u64>());
        }
        seg.advance_by(1_000_000);
    }
    println!(
        "{cycles} cycles of {} frames through {n} ESCs, checksum {sum}",
        frames.len()
    );
}
