//! Test bench: a software ESC driven by master frames, the stack polled between them.
#![allow(dead_code)]

use oxicat_esc::{Esc, EscConfig};
use oxicat_slave::*;
use oxicat_wire::coe::{
    write_sdo, write_sdo_segment, CoeService, SdoHeader, SdoRef, SdoResponseCommand,
};
use oxicat_wire::frame::FrameBuilder;
use oxicat_wire::mailbox::{write_mailbox, MailboxHeader, MailboxRef, MailboxType};
use oxicat_wire::{Command, DatagramHeader, EcatFrame};

pub mod device;
pub use device::*;

pub struct Bench<A = App> {
    pub esc: Esc,
    pub s: Slave<Esc, IMG, MBX>,
    pub app: A,
    pub t: u64,
    pub counter: u8,
}

impl Bench {
    pub fn new() -> Self {
        Bench::with_app(App::default())
    }
}

impl<A: Application<IMG>> Bench<A> {
    /// A bench whose firmware runs `app`.
    pub fn with_app(app: A) -> Self {
        let mut esc = Esc::new(EscConfig::et1100(), eeprom(&DEF));
        let s = Slave::new(&DEF, &mut esc).unwrap();
        let mut b = Bench {
            esc,
            s,
            app,
            t: 0,
            counter: 0,
        };
        b.frame(Command::Apwr, 0, 0x0010, &STATION.to_le_bytes());
        b
    }

    pub fn frame(&mut self, cmd: Command, adp: u16, ado: u16, data: &[u8]) -> (Vec<u8>, u16) {
        let mut buf = vec![0u8; 1600];
        let mut fb = FrameBuilder::new_bare(&mut buf).unwrap();
        fb.push(
            DatagramHeader::physical(cmd, 0, adp, ado, data.len() as u16),
            data,
        )
        .unwrap();
        let n = fb.finish();
        buf.truncate(n);
        self.t += 10_000;
        self.esc.forward(0, &mut buf, self.t, true);
        let f = EcatFrame::parse(&buf).unwrap();
        let d = f.datagrams().next().unwrap().unwrap();
        (d.data.to_vec(), d.wkc)
    }

    pub fn wr(&mut self, ado: u16, data: &[u8]) -> u16 {
        self.frame(Command::Fpwr, STATION, ado, data).1
    }

    pub fn rd(&mut self, ado: u16, len: usize) -> (Vec<u8>, u16) {
        self.frame(Command::Fprd, STATION, ado, &vec![0u8; len])
    }

    pub fn poll(&mut self) {
        for _ in 0..3 {
            self.s.poll(&mut self.esc, &mut self.app).unwrap();
        }
    }

    /// Advances ESC time (watchdogs, SYNC) and delivers SYNC events.
    pub fn advance(&mut self, dt: u64) {
        self.t += dt;
        let ev = self.esc.advance(self.t);
        if ev.sync0.is_some() {
            self.s.on_sync0(&mut self.esc, &mut self.app).unwrap();
        }
        if ev.sync1.is_some() {
            self.s.on_sync1(&mut self.esc, &mut self.app).unwrap();
        }
    }

    pub fn al_status(&mut self) -> (u16, u16) {
        let (d, _) = self.rd(0x0130, 6);
        (
            u16::from_le_bytes([d[0], d[1]]),
            u16::from_le_bytes([d[4], d[5]]),
        )
    }

    pub fn request(&mut self, state: u16) -> (u16, u16) {
        self.wr(0x0120, &state.to_le_bytes());
        self.poll();
        self.al_status()
    }

    pub fn config_sm(&mut self, n: u16, start: u16, len: u16, ctrl: u8) {
        let mut r = [0u8; 8];
        r[0..2].copy_from_slice(&start.to_le_bytes());
        r[2..4].copy_from_slice(&len.to_le_bytes());
        r[4] = ctrl;
        r[6] = u8::from(len > 0);
        self.wr(0x0800 + 8 * n, &r);
    }

    pub fn config_mailbox(&mut self) {
        self.config_sm(0, SM0, MBX as u16, 0x26);
        self.config_sm(1, SM1, MBX as u16, 0x22);
    }

    pub fn config_pd(&mut self) {
        let o = self.s.od().def().rx_pdos.len();
        let _ = o;
        let (ob, ib) = (self.expected_out(), self.expected_in());
        self.config_sm(2, SM2, ob, 0x64);
        self.config_sm(3, SM3, ib, 0x20);
    }

    /// Output/input sizes from the current 0x1C12/0x1C13 as a master computes them (SDO).
    pub fn expected_out(&mut self) -> u16 {
        self.pd_size(0x1C12)
    }
    pub fn expected_in(&mut self) -> u16 {
        self.pd_size(0x1C13)
    }
    fn pd_size(&mut self, assign: u16) -> u16 {
        let n = self.upload(assign, 0, false).unwrap()[0];
        let mut bits = 0u32;
        for k in 1..=n {
            let p = self.upload(assign, k, false).unwrap();
            let pdo = u16::from_le_bytes([p[0], p[1]]);
            let c = self.upload(pdo, 0, false).unwrap()[0];
            for j in 1..=c {
                let e = self.upload(pdo, j, false).unwrap();
                bits += e[0] as u32;
            }
        }
        bits.div_ceil(8) as u16
    }

    pub fn enter_preop(&mut self) {
        self.config_mailbox();
        assert_eq!(self.request(2), (2, 0));
    }

    pub fn enter_safeop(&mut self) {
        self.enter_preop();
        self.config_pd();
        assert_eq!(self.request(4), (4, 0));
    }

    pub fn enter_op(&mut self) {
        self.enter_safeop();
        assert_eq!(self.request(8), (8, 0));
    }

    // ---------------------------------------------------------------- mailbox

    pub fn next_counter(&mut self) -> u8 {
        self.counter = MailboxHeader::next_counter(self.counter);
        self.counter
    }

    /// Writes a raw mailbox (header + service data) into SM0; returns the WKC.
    pub fn mbx_write_raw(&mut self, bytes: &[u8]) -> u16 {
        let mut buf = vec![0u8; MBX];
        buf[..bytes.len()].copy_from_slice(bytes);
        self.wr(SM0, &buf)
    }

    pub fn mbx_write(&mut self, t: MailboxType, payload: &[u8]) -> u16 {
        let c = self.next_counter();
        let mut buf = vec![0u8; MBX];
        write_mailbox(&mut buf, &MailboxHeader::new(0, 0, t, c), payload).unwrap();
        self.wr(SM0, &buf)
    }

    /// Reads SM1 after polling; None if empty.
    pub fn mbx_read(&mut self) -> Option<(MailboxHeader, Vec<u8>)> {
        self.poll();
        let (d, wkc) = self.rd(SM1, MBX);
        if wkc != 1 {
            return None;
        }
        let m = MailboxRef::parse(&d).unwrap();
        Some((m.header, m.payload.to_vec()))
    }

    pub fn coe(&mut self, payload: &[u8]) -> Vec<u8> {
        assert_eq!(self.mbx_write(MailboxType::Coe, payload), 1);
        let (h, p) = self.mbx_read().expect("reply");
        assert_eq!(h.mailbox_type, MailboxType::Coe, "reply {p:02x?}");
        p
    }

    // ---------------------------------------------------------------- SDO client

    pub fn upload(&mut self, index: u16, sub: u8, ca: bool) -> Result<Vec<u8>, u32> {
        let mut b = [0u8; 10];
        let h = SdoHeader {
            command: 0x40 | if ca { 0x10 } else { 0 },
            index,
            subindex: sub,
        };
        write_sdo(&mut b, CoeService::SdoRequest, &h, [0; 4], &[]).unwrap();
        let r = self.coe(&b);
        let s = SdoRef::parse(&r).unwrap();
        match SdoResponseCommand::from_u8(s.command).unwrap() {
            SdoResponseCommand::Abort => Err(s.abort_code().unwrap().code()),
            SdoResponseCommand::InitiateUpload {
                expedited: true, ..
            } => Ok(s.expedited_data().unwrap().to_vec()),
            SdoResponseCommand::InitiateUpload { .. } => {
                let (size, d) = s.normal_data().unwrap();
                let mut out = d.to_vec();
                let mut toggle = false;
                while out.len() < size as usize {
                    let mut b = [0u8; 10];
                    let cmd = 0x60 | if toggle { 0x10 } else { 0 };
                    write_sdo_segment(&mut b, CoeService::SdoRequest, cmd, &[]).unwrap();
                    let r = self.coe(&b);
                    let s = SdoRef::parse(&r).unwrap();
                    match SdoResponseCommand::from_u8(s.command).unwrap() {
                        SdoResponseCommand::Abort => return Err(s.abort_code().unwrap().code()),
                        SdoResponseCommand::UploadSegment {
                            toggle: t, last, ..
                        } => {
                            assert_eq!(t, toggle);
                            out.extend_from_slice(s.segment_data().unwrap());
                            if last {
                                break;
                            }
                        }
                        o => panic!("unexpected {o:?}"),
                    }
                    toggle = !toggle;
                }
                assert_eq!(out.len(), size as usize);
                Ok(out)
            }
            o => panic!("unexpected {o:?}"),
        }
    }

    pub fn download(&mut self, index: u16, sub: u8, ca: bool, data: &[u8]) -> Result<(), u32> {
        let mut b = vec![0u8; MBX];
        let cab = if ca { 0x10 } else { 0 };
        let resp = if data.len() <= 4 && !ca {
            let mut d = [0u8; 4];
            d[..data.len()].copy_from_slice(data);
            let cmd = 0x23 | cab | (((4 - data.len()) as u8) << 2);
            let h = SdoHeader {
                command: cmd,
                index,
                subindex: sub,
            };
            let n = write_sdo(&mut b, CoeService::SdoRequest, &h, d, &[]).unwrap();
            self.coe(&b[..n])
        } else {
            let cap = MBX - 6 - 10;
            let first = data.len().min(cap);
            let h = SdoHeader {
                command: 0x21 | cab,
                index,
                subindex: sub,
            };
            let n = write_sdo(
                &mut b,
                CoeService::SdoRequest,
                &h,
                (data.len() as u32).to_le_bytes(),
                &data[..first],
            )
            .unwrap();
            let r = self.coe(&b[..n]);
            let mut sent = first;
            let mut toggle = false;
            let mut r = r;
            while sent < data.len() {
                let s = SdoRef::parse(&r).unwrap();
                if s.command == 0x80 {
                    return Err(s.abort_code().unwrap().code());
                }
                let cap = MBX - 6 - 3;
                let n = (data.len() - sent).min(cap);
                let last = sent + n == data.len();
                let unused = if n < 7 { (7 - n) as u8 } else { 0 };
                let cmd = (if toggle { 0x10 } else { 0 }) | (unused << 1) | u8::from(last);
                let len =
                    write_sdo_segment(&mut b, CoeService::SdoRequest, cmd, &data[sent..sent + n])
                        .unwrap();
                r = self.coe(&b[..len]);
                let s = SdoRef::parse(&r).unwrap();
                if s.command != 0x80 {
                    assert_eq!(s.command, 0x20 | if toggle { 0x10 } else { 0 });
                }
                sent += n;
                toggle = !toggle;
            }
            r
        };
        let s = SdoRef::parse(&resp).unwrap();
        match s.command {
            0x80 => Err(s.abort_code().unwrap().code()),
            0x60 | 0x20 | 0x30 => Ok(()),
            c => panic!("unexpected response {c:#x}"),
        }
    }
}
