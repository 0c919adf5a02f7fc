//! A parallel of oxicat-slave's test bench: the ECAT side of a software ESC is driven
//! with master frames, the slave stack runs with an SPI chip driver as its `Pdi`, over a
//! simulated SPI peripheral in front of that ESC.
#![allow(dead_code)]

/// The slave stack's own test device, one file for both test benches.
#[path = "../../../oxicat-slave/tests/common/device.rs"]
pub mod device;
pub mod laelaps;

use device::*;
use oxicat_esc::{Esc, EscConfig};
use oxicat_pdi::sim::{BusConfig, Et1100Model, Handle, Lan9252Model, PinKind, SimPin, SimSpi};
use oxicat_pdi::{AddressMode, Et1100Config, Et1100Spi, Lan9252, Lan9252Config, Pins, ReadMode};
use oxicat_slave::*;
use oxicat_wire::coe::{
    write_sdo, write_sdo_segment, CoeService, SdoHeader, SdoRef, SdoResponseCommand,
};
use oxicat_wire::frame::FrameBuilder;
use oxicat_wire::mailbox::{write_mailbox, MailboxHeader, MailboxRef, MailboxType};
use oxicat_wire::{Command, DatagramHeader, EcatFrame};

pub type P<M> = Pins<SimPin<M>, SimPin<M>, SimPin<M>>;

fn pins<M: oxicat_pdi::sim::Model>(h: &Handle<M>, irq_active_low: bool) -> P<M> {
    Pins {
        irq: h.pin(PinKind::Irq),
        sync0: h.pin(PinKind::Sync0),
        sync1: h.pin(PinKind::Sync1),
        irq_active_low,
        sync_active_low: false,
    }
}

/// A chip + driver combination.
pub trait Chip {
    type M: oxicat_pdi::sim::Model;
    type D: Pdi;
    const NAME: &'static str;
    fn build(esc: Esc, bus: BusConfig) -> (Self::D, Handle<Self::M>);
}

pub struct Lan;
pub struct LanFast;
pub struct Et2;
pub struct Et3;
pub struct EtDelay;

pub type LanDrv = Lan9252<SimSpi<Lan9252Model>, P<Lan9252Model>>;
pub type EtDrv = Et1100Spi<SimSpi<Et1100Model>, P<Et1100Model>>;

fn lan(esc: Esc, bus: BusConfig, cfg: Lan9252Config) -> (LanDrv, Handle<Lan9252Model>) {
    let h = Lan9252Model::handle(esc, bus);
    let mut d = Lan9252::new(h.spi(), pins(&h, !cfg.irq_active_high), cfg);
    d.init().expect("LAN9252 init");
    (d, h)
}

fn et(esc: Esc, bus: BusConfig, cfg: Et1100Config) -> (EtDrv, Handle<Et1100Model>) {
    let h = Et1100Model::handle(esc, bus);
    let mut d = Et1100Spi::new(h.spi(), pins(&h, true), cfg);
    d.init(&mut h.pin(PinKind::EepromLoaded))
        .expect("ET1100 init");
    (d, h)
}

impl Chip for Lan {
    type M = Lan9252Model;
    type D = LanDrv;
    const NAME: &'static str = "LAN9252 (read 0x03)";
    fn build(esc: Esc, bus: BusConfig) -> (Self::D, Handle<Self::M>) {
        lan(esc, bus, Lan9252Config::default())
    }
}

impl Chip for LanFast {
    type M = Lan9252Model;
    type D = LanDrv;
    const NAME: &'static str = "LAN9252 (fast read 0x0B)";
    fn build(esc: Esc, bus: BusConfig) -> (Self::D, Handle<Self::M>) {
        let cfg = Lan9252Config {
            fast_read: true,
            irq_active_high: true,
            ..Default::default()
        };
        lan(esc, bus, cfg)
    }
}

impl Chip for Et2 {
    type M = Et1100Model;
    type D = EtDrv;
    const NAME: &'static str = "ET1100 (2-byte address, wait state)";
    fn build(esc: Esc, bus: BusConfig) -> (Self::D, Handle<Self::M>) {
        et(esc, bus, Et1100Config::default())
    }
}

impl Chip for Et3 {
    type M = Et1100Model;
    type D = EtDrv;
    const NAME: &'static str = "ET1100 (3-byte address, wait state)";
    fn build(esc: Esc, bus: BusConfig) -> (Self::D, Handle<Self::M>) {
        let cfg = Et1100Config {
            address_mode: AddressMode::ThreeByte,
            ..Default::default()
        };
        et(esc, bus, cfg)
    }
}

impl Chip for EtDelay {
    type M = Et1100Model;
    type D = EtDrv;
    const NAME: &'static str = "ET1100 (2-byte address, 240 ns pause)";
    fn build(esc: Esc, bus: BusConfig) -> (Self::D, Handle<Self::M>) {
        let cfg = Et1100Config {
            read_mode: ReadMode::Delay { ns: 240 },
            ..Default::default()
        };
        et(esc, bus, cfg)
    }
}

pub struct Bench<C: Chip, A, const N: usize> {
    pub drv: C::D,
    pub h: Handle<C::M>,
    pub s: Slave<C::D, N, MBX>,
    pub app: A,
    pub t: u64,
    pub counter: u8,
    pub sync0: u64,
}

impl<C: Chip> Bench<C, App, IMG> {
    pub fn new() -> Self {
        Bench::with(
            &DEF,
            App::default(),
            EscConfig::et1100(),
            BusConfig::mhz(20),
        )
    }
}

impl<C: Chip, A: Application<N>, const N: usize> Bench<C, A, N> {
    pub fn with(def: &'static DeviceDef, app: A, cfg: EscConfig, bus: BusConfig) -> Self {
        let esc = Esc::new(cfg, eeprom(def));
        let (mut drv, h) = C::build(esc, bus);
        let s = Slave::new(def, &mut drv).unwrap();
        let mut b = Bench {
            drv,
            h,
            s,
            app,
            t: 0,
            counter: 0,
            sync0: 0,
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
        let t = self.t;
        self.h.with_esc(|esc| esc.forward(0, &mut buf, t, true));
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
            self.s.poll(&mut self.drv, &mut self.app).unwrap();
        }
    }

    /// Advances ESC time in `steps` and delivers SYNC events (and the joint-loop timer).
    pub fn advance(&mut self, dt: u64, steps: u64, timer: Option<u8>) {
        for _ in 0..steps {
            self.t += dt / steps;
            let t = self.t;
            let ev = self.h.with_esc(|esc| esc.advance(t));
            if ev.sync0.is_some() {
                self.sync0 += 1;
                self.s.on_sync0(&mut self.drv, &mut self.app).unwrap();
            }
            if ev.sync1.is_some() {
                self.s.on_sync1(&mut self.drv, &mut self.app).unwrap();
            }
            if let Some(id) = timer {
                self.s.on_timer(id, &mut self.app);
            }
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

    pub fn config_mailbox(&mut self, def: &DeviceDef) {
        let m = def.mailbox;
        self.config_sm(0, m.rx_start, m.rx_len, 0x26);
        self.config_sm(1, m.tx_start, m.tx_len, 0x22);
    }

    // ---------------------------------------------------------------- mailbox

    pub fn mbx_write(&mut self, t: MailboxType, payload: &[u8]) -> u16 {
        self.counter = MailboxHeader::next_counter(self.counter);
        let mut buf = vec![0u8; MBX];
        write_mailbox(
            &mut buf,
            &MailboxHeader::new(0, 0, t, self.counter),
            payload,
        )
        .unwrap();
        self.wr(SM0, &buf)
    }

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

    pub fn upload(&mut self, index: u16, sub: u8) -> Result<Vec<u8>, u32> {
        let mut b = [0u8; 10];
        let h = SdoHeader {
            command: 0x40,
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

    pub fn download(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), u32> {
        let mut b = vec![0u8; MBX];
        let resp = if data.len() <= 4 {
            let mut d = [0u8; 4];
            d[..data.len()].copy_from_slice(data);
            let cmd = 0x23 | (((4 - data.len()) as u8) << 2);
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
                command: 0x21,
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
            let mut r = self.coe(&b[..n]);
            let mut sent = first;
            let mut toggle = false;
            while sent < data.len() {
                let s = SdoRef::parse(&r).unwrap();
                if s.command == 0x80 {
                    return Err(s.abort_code().unwrap().code());
                }
                let n = (data.len() - sent).min(MBX - 6 - 3);
                let last = sent + n == data.len();
                let unused = if n < 7 { (7 - n) as u8 } else { 0 };
                let cmd = (if toggle { 0x10 } else { 0 }) | (unused << 1) | u8::from(last);
                let len =
                    write_sdo_segment(&mut b, CoeService::SdoRequest, cmd, &data[sent..sent + n])
                        .unwrap();
                r = self.coe(&b[..len]);
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
