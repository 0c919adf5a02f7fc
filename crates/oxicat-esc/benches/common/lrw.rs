//! The setup shared by the `lrw_chain` benchmark and the `lrw_profile` example: a line of
//! ESCs as a master leaves it for cyclic operation, and the 64-byte LRW that goes through it.
//!
//! Each ESC is configured over the wire as a master does it: station address by APWR
//! (0x1000 + position), SM2 (0x1000, 32 bytes, 3-buffer, written by ECAT) and SM3 (0x1100,
//! 32 bytes, 3-buffer, read by ECAT) and two FMMUs mapping the halves of the logical window
//! 0x0001_0000..+64 by FPWR, then INIT → PREOP → SAFEOP → OP by FPWR of AL control (device
//! emulation on, as on an EK1100-like ESC without firmware). Port 1 is open on every ESC
//! but the last, so a frame goes out on port 1 to the next ESC, the last ESC closes the
//! loop, and the frame comes back through every ESC's port 1 → port 0 path, as on a cable.
//!
//! [`Line::check`] runs one cycle and asserts what the master would see: the frame back on
//! port 0 of the first ESC, the working counter 3 per ESC (LRW: read +1, write +2), the
//! outputs in every ESC's SM2 and the last ESC's inputs in the frame.

use oxicat_esc::{Esc, EscConfig, Forward};
use oxicat_wire::frame::FrameBuilder;
use oxicat_wire::{Command, DatagramHeader};

/// The output byte the LRW carries.
pub const OUT: u8 = 0x5A;

fn eeprom_with_device_emulation() -> Vec<u8> {
    let mut e = vec![0u8; 2048];
    // PDI control: SPI (0x05) with device emulation (bit 8): AL status follows AL control.
    e[0..2].copy_from_slice(&0x0105u16.to_le_bytes());
    e[14] = oxicat_esc::sii::crc8(&e[..14]);
    e
}

/// Sends one datagram into port 0 of `esc` and returns its working counter.
fn send(esc: &mut Esc, h: DatagramHeader, data: &[u8]) -> u16 {
    let mut buf = vec![0u8; 128];
    let mut b = FrameBuilder::new_bare(&mut buf).unwrap();
    b.push(h, data).unwrap();
    let n = b.finish();
    esc.forward(0, &mut buf[..n], 0, true);
    // Single datagram: the WKC is the frame's last two bytes.
    u16::from_le_bytes([buf[n - 2], buf[n - 1]])
}

fn apwr(esc: &mut Esc, ado: u16, data: &[u8]) {
    let h = DatagramHeader::physical(Command::Apwr, 0, 0, ado, data.len() as u16);
    assert_eq!(send(esc, h, data), 1, "APWR 0x{ado:04x}");
}

fn fpwr(esc: &mut Esc, station: u16, ado: u16, data: &[u8]) {
    let h = DatagramHeader::physical(Command::Fpwr, 0, station, ado, data.len() as u16);
    assert_eq!(send(esc, h, data), 1, "FPWR 0x{ado:04x}");
}

/// One ESC at `position` of the line, configured and in OP.
pub fn make_esc(position: u16) -> Esc {
    let mut e = Esc::new(EscConfig::et1100(), eeprom_with_device_emulation());
    let station = 0x1000 + position;
    apwr(&mut e, 0x0010, &station.to_le_bytes());
    let sm = |start: u16, ctrl: u8| {
        let mut r = [0u8; 8];
        r[0..2].copy_from_slice(&start.to_le_bytes());
        r[2..4].copy_from_slice(&32u16.to_le_bytes());
        r[4] = ctrl;
        r[6] = 1;
        r
    };
    fpwr(&mut e, station, 0x0810, &sm(0x1000, 0x64));
    fpwr(&mut e, station, 0x0818, &sm(0x1100, 0x20));
    let fmmu = |log: u32, phys: u16, ty: u8| {
        let mut r = [0u8; 16];
        r[0..4].copy_from_slice(&log.to_le_bytes());
        r[4..6].copy_from_slice(&32u16.to_le_bytes());
        r[7] = 7;
        r[8..10].copy_from_slice(&phys.to_le_bytes());
        r[11] = ty;
        r[12] = 1;
        r
    };
    fpwr(&mut e, station, 0x0600, &fmmu(0x0001_0000, 0x1000, 2));
    fpwr(&mut e, station, 0x0610, &fmmu(0x0001_0020, 0x1100, 1));
    for state in [2u8, 4, 8] {
        fpwr(&mut e, station, 0x0120, &[state, 0]);
        assert_eq!(e.al_status(), state as u16, "AL state of ESC {position}");
    }
    // The application's inputs: one byte pattern per ESC, committed as a whole buffer.
    e.pdi_write(0x1100, &[position as u8; 32]).unwrap();
    e
}

/// A line of `n` configured ESCs in OP, linked port 1 → port 0.
pub struct Line {
    /// The ESCs in line order.
    pub escs: Vec<Esc>,
}

impl Line {
    /// `n` ESCs in OP with port 1 open on all but the last.
    pub fn new(n: usize) -> Self {
        let mut escs: Vec<Esc> = (0..n).map(|i| make_esc(i as u16)).collect();
        let last = n - 1;
        for (i, e) in escs.iter_mut().enumerate() {
            e.set_link(1, i != last);
        }
        Self { escs }
    }

    /// One frame from the master through the line and back; returns where it left the
    /// first ESC. The working counter is cleared first, as in a frame the master sends.
    /// Inlined into the measuring loop (no call per frame); the ports each ESC sends the
    /// frame out of are asserted by [`Line::check`], which walks the same hops.
    #[inline(always)]
    pub fn cycle(&mut self, frame: &mut [u8], t: u64) -> Forward {
        self.walk(frame, t, |_, _, _| {})
    }

    /// [`Line::cycle`] with `hop(position, ingress, egress)` told every hop.
    #[inline(always)]
    fn walk(
        &mut self,
        frame: &mut [u8],
        t: u64,
        mut hop: impl FnMut(usize, u8, Forward),
    ) -> Forward {
        let n = frame.len();
        frame[n - 2] = 0;
        frame[n - 1] = 0;
        let last = self.escs.len() - 1;
        for (i, e) in self.escs[..last].iter_mut().enumerate() {
            // Processed on the way out, leaves on port 1 to the next ESC.
            hop(i, 0, e.forward(0, frame, t, true));
        }
        let mut out = self.escs[last].forward(0, frame, t, true);
        hop(last, 0, out);
        for (i, e) in self.escs[..last].iter_mut().enumerate().rev() {
            // The way back: in on port 1, out on port 0, not processed.
            out = e.forward(1, frame, t, true);
            hop(i, 1, out);
        }
        out
    }

    /// What [`Line::cycle`] does around the ESCs (the working counter cleared, the frame
    /// handed on), with no ESC: the harness's own cost per frame, measured beside the
    /// chains (`lrw_chain/harness`, `lrw_profile 0 N`) so that the chain of 1, where it is
    /// a large part, can be read net of it.
    #[inline(always)]
    pub fn harness_only(frame: &mut [u8], t: u64) -> Forward {
        let n = frame.len();
        frame[n - 2] = 0;
        frame[n - 1] = 0;
        Forward::Port((t & 1) as u8)
    }

    /// Runs one cycle and asserts what the master sees (see the module docs).
    pub fn check(&mut self, frame: &mut [u8], t: u64) {
        let n = self.escs.len();
        let last = n - 1;
        let mut f = frame.to_vec();
        let mut hops = Vec::new();
        let out = self.walk(&mut f, t, |i, port, out| hops.push((i, port, out)));
        assert_eq!(out, Forward::Port(0), "frame back at the master");
        // Out through port 1 to the next ESC, the last ESC turns it back through port 0,
        // back from port 1 to port 0: 2n - 1 hops.
        let line: Vec<_> = (0..last)
            .map(|i| (i, 0, Forward::Port(1)))
            .chain([(last, 0, Forward::Port(0))])
            .chain((0..last).rev().map(|i| (i, 1, Forward::Port(0))))
            .collect();
        assert_eq!(hops, line, "hops (position, ingress, egress)");
        let wkc = u16::from_le_bytes([f[f.len() - 2], f[f.len() - 1]]);
        assert_eq!(wkc as usize, 3 * n, "LRW working counter of {n} ESCs");
        // Frame header (2) + datagram header (10): outputs, then inputs.
        let data = &f[12..12 + 64];
        assert!(data[..32].iter().all(|&b| b == OUT), "outputs unchanged");
        assert!(
            data[32..].iter().all(|&b| b == last as u8),
            "inputs of the last ESC: {:02x?}",
            &data[32..]
        );
        for (i, e) in self.escs.iter_mut().enumerate() {
            let mut sm2 = [0u8; 32];
            e.pdi_read(0x1000, &mut sm2).unwrap();
            assert_eq!(sm2, [OUT; 32], "outputs in SM2 of ESC {i}");
            assert_eq!(e.al_status(), 8, "ESC {i} still in OP");
        }
        // Port routing: out through port 1 except at the end of the line.
        for (i, e) in self.escs.iter().enumerate() {
            assert_eq!(e.port_open(1), i != last, "port 1 of ESC {i}");
        }
    }
}

/// The 64-byte LRW a master sends each cycle (outputs in the first half).
pub fn lrw_frame() -> Vec<u8> {
    let mut buf = vec![0u8; 128];
    let mut b = FrameBuilder::new_bare(&mut buf).unwrap();
    let mut data = [0u8; 64];
    data[..32].fill(OUT);
    b.push(
        DatagramHeader::logical(Command::Lrw, 0, 0x0001_0000, 64),
        &data,
    )
    .unwrap();
    let n = b.finish();
    buf.truncate(n);
    buf
}

/// The frame ethercrab's `tx_rx` sends each cycle: the LRW, then one FPRD of AL status
/// (0x0130, 2 bytes) per slave (`checks` of them, stations 0x1000 + k) — so every ESC of
/// the line also walks `checks` datagrams addressed to the others.
pub fn lrw_with_state_checks(checks: usize) -> Vec<u8> {
    let mut buf = vec![0u8; 14 + 64 + 16 * checks + 64];
    let mut b = FrameBuilder::new_bare(&mut buf).unwrap();
    let mut data = [0u8; 64];
    data[..32].fill(OUT);
    b.push(
        DatagramHeader::logical(Command::Lrw, 0, 0x0001_0000, 64),
        &data,
    )
    .unwrap();
    for k in 0..checks {
        let h = DatagramHeader::physical(Command::Fprd, 1, 0x1000 + k as u16, 0x0130, 2);
        b.push(h, &[0, 0]).unwrap();
    }
    let n = b.finish();
    buf.truncate(n);
    buf
}
