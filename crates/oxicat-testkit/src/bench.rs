//! A master's side of one ESC, driven with single-datagram frames, and the slave stack
//! with its firmware polled between them; generic over how the firmware reaches the ESC.

use crate::device::{eeprom, App, DEF, IMG, MBX, STATION};
use crate::ports::Port;
use oxicat_esc::{Esc, EscConfig};
use oxicat_pdi::sim::{BusConfig, BusStats};
use oxicat_slave::*;
use oxicat_wire::coe::{
    write_sdo, write_sdo_segment, CoeService, SdoHeader, SdoRef, SdoResponseCommand,
};
use oxicat_wire::frame::FrameBuilder;
use oxicat_wire::mailbox::{write_mailbox, MailboxHeader, MailboxRef, MailboxType};
use oxicat_wire::{Command, DatagramHeader, EcatFrame};

/// The bench: an ESC with station address [`STATION`], the firmware's PDI to it, the stack
/// and the application. Every frame advances ESC time by 10 µs. `K`: the stack's copy steps
/// per compiled mapping (its default: any mapping the stack accepts).
pub struct Bench<P: Port, A = App, const N: usize = IMG, const K: usize = { pdo::MAX_ITEMS }> {
    /// The firmware's PDI (the ESC itself, or a driver).
    pub drv: P::Pdi,
    /// The master's access to the ESC (and the SPI counters).
    pub port: P,
    /// The slave stack.
    pub s: Slave<P::Pdi, N, MBX, K>,
    /// The application.
    pub app: A,
    /// ESC time in ns.
    pub t: u64,
    /// Mailbox counter of the last request.
    pub counter: u8,
    /// SYNC0 events delivered.
    pub sync0: u64,
}

impl<P: Port, A, const N: usize, const K: usize> Bench<P, A, N, K> {
    /// SPI traffic since the last reset (`None` on the software ESC).
    pub fn bus_stats(&self) -> Option<BusStats> {
        self.port.bus_stats()
    }

    /// Asserts the simulated chip saw no malformed SPI frame.
    pub fn assert_no_protocol_errors(&self) {
        if let Some(s) = self.bus_stats() {
            assert_eq!(s.protocol_errors, 0, "{}", P::NAME);
        }
    }
}

/// Every bench checks at the end that the simulated SPI chip saw no malformed frame.
impl<P: Port, A, const N: usize, const K: usize> Drop for Bench<P, A, N, K> {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            self.assert_no_protocol_errors();
        }
    }
}

impl<P: Port> Bench<P> {
    /// The test device with its default application.
    pub fn new() -> Self {
        Bench::with_app(App::default())
    }
}

impl<P: Port> Default for Bench<P> {
    fn default() -> Self {
        Self::new()
    }
}

impl<P: Port, const K: usize> Bench<P, App, IMG, K> {
    /// The test device with its default application, on a stack whose compiled mappings
    /// hold `K` copy steps per direction.
    pub fn with_steps() -> Self {
        Bench::on(&DEF, App::default())
    }
}

impl<P: Port, A: Application<IMG>> Bench<P, A> {
    /// The test device whose firmware runs `app`.
    pub fn with_app(app: A) -> Self {
        Bench::with(&DEF, app, P::esc_config(), BusConfig::mhz(20))
    }
}

impl<P: Port, A: Application<N>, const N: usize, const K: usize> Bench<P, A, N, K> {
    /// Device `def` running `app` on the port's ESC and an SII image of `def` ([`Bench::with`]
    /// with the port's configuration and a 20 MHz bus).
    pub fn on(def: &'static DeviceDef, app: A) -> Self {
        Bench::with(def, app, P::esc_config(), BusConfig::mhz(20))
    }

    /// Device `def` running `app` on an ESC built from `cfg` and an SII image of `def`; SPI
    /// ports clock at `bus`. The station address is set.
    pub fn with(def: &'static DeviceDef, app: A, cfg: EscConfig, bus: BusConfig) -> Self {
        let esc = Esc::new(cfg, eeprom(def));
        let (mut drv, port) = P::build(esc, bus);
        let s = Slave::new(def, &mut drv).expect("the stack starts");
        let mut b = Bench {
            drv,
            port,
            s,
            app,
            t: 0,
            counter: 0,
            sync0: 0,
        };
        b.frame(Command::Apwr, 0, 0x0010, &STATION.to_le_bytes());
        b
    }

    /// The ESC, for what a master or the wire does to it.
    pub fn with_esc<T>(&mut self, f: impl FnOnce(&mut Esc) -> T) -> T {
        self.port.with_esc(&mut self.drv, f)
    }

    /// One frame with one datagram through the ESC (port 0); the datagram's data and WKC.
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
        self.with_esc(|esc| esc.forward(0, &mut buf, t, true));
        let f = EcatFrame::parse(&buf).unwrap();
        let d = f.datagrams().next().unwrap().unwrap();
        (d.data.to_vec(), d.wkc)
    }

    /// FPWR; the WKC.
    pub fn wr(&mut self, ado: u16, data: &[u8]) -> u16 {
        self.frame(Command::Fpwr, STATION, ado, data).1
    }

    /// FPRD of `len` bytes; data and WKC.
    pub fn rd(&mut self, ado: u16, len: usize) -> (Vec<u8>, u16) {
        self.frame(Command::Fprd, STATION, ado, &vec![0u8; len])
    }

    /// Three passes of the firmware's main loop.
    pub fn poll(&mut self) {
        for _ in 0..3 {
            self.s.poll(&mut self.drv, &mut self.app).unwrap();
        }
    }

    /// Advances ESC time by `dt` (watchdogs, SYNC) and delivers SYNC events.
    pub fn advance(&mut self, dt: u64) {
        self.advance_steps(dt, 1, None);
    }

    /// Advances ESC time by `dt` in `steps` equal steps, delivering SYNC events and, after
    /// each step, the firmware timer `timer`.
    pub fn advance_steps(&mut self, dt: u64, steps: u64, timer: Option<u8>) {
        for _ in 0..steps {
            self.t += dt / steps;
            let t = self.t;
            let ev = self.with_esc(|esc| esc.advance(t));
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

    /// AL status and AL status code as the master reads them.
    pub fn al_status(&mut self) -> (u16, u16) {
        let (d, _) = self.rd(0x0130, 6);
        (
            u16::from_le_bytes([d[0], d[1]]),
            u16::from_le_bytes([d[4], d[5]]),
        )
    }

    /// Writes AL control, lets the firmware run, returns [`Self::al_status`].
    pub fn request(&mut self, state: u16) -> (u16, u16) {
        self.wr(0x0120, &state.to_le_bytes());
        self.poll();
        self.al_status()
    }

    /// Configures SyncManager `n` (activated when `len` > 0). As a master must, it first
    /// deactivates the SyncManager: an ESC takes start, length and control only while the
    /// SyncManager is disabled.
    pub fn config_sm(&mut self, n: u16, start: u16, len: u16, ctrl: u8) {
        self.wr(0x0806 + 8 * n, &[0]);
        let mut r = [0u8; 8];
        r[0..2].copy_from_slice(&start.to_le_bytes());
        r[2..4].copy_from_slice(&len.to_le_bytes());
        r[4] = ctrl;
        r[6] = u8::from(len > 0);
        self.wr(0x0800 + 8 * n, &r);
    }

    /// SM0/SM1 as the device definition's standard mailbox.
    pub fn config_mailbox(&mut self) {
        let m = self.s.od().def().mailbox;
        self.config_sm(0, m.rx_start, m.rx_len, 0x26);
        self.config_sm(1, m.tx_start, m.tx_len, 0x22);
    }

    /// SM2/SM3 at the definition's addresses, sized from 0x1C12/0x1C13 read over SDO.
    pub fn config_pd(&mut self) {
        let def = self.s.od().def();
        let (o, i) = (def.sm2_start, def.sm3_start);
        let (ob, ib) = (self.expected_out(), self.expected_in());
        self.config_sm(2, o, ob, 0x64);
        self.config_sm(3, i, ib, 0x20);
    }

    /// Output size from the current 0x1C12 as a master computes it (SDO).
    pub fn expected_out(&mut self) -> u16 {
        self.pd_size(0x1C12)
    }

    /// Input size from the current 0x1C13 as a master computes it (SDO).
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

    /// INIT → PREOP (mailbox configured).
    pub fn enter_preop(&mut self) {
        self.config_mailbox();
        assert_eq!(self.request(2), (2, 0), "{}", P::NAME);
    }

    /// → SAFEOP with process data configured.
    pub fn enter_safeop(&mut self) {
        self.enter_preop();
        self.config_pd();
        assert_eq!(self.request(4), (4, 0), "{}", P::NAME);
    }

    /// → OP.
    pub fn enter_op(&mut self) {
        self.enter_safeop();
        assert_eq!(self.request(8), (8, 0), "{}", P::NAME);
    }

    // ---------------------------------------------------------------- mailbox

    /// The next mailbox counter (1..=7).
    pub fn next_counter(&mut self) -> u8 {
        self.counter = MailboxHeader::next_counter(self.counter);
        self.counter
    }

    /// Writes a raw mailbox (header + service data) into SM0; returns the WKC.
    pub fn mbx_write_raw(&mut self, bytes: &[u8]) -> u16 {
        let m = self.s.od().def().mailbox;
        let mut buf = vec![0u8; m.rx_len as usize];
        let n = bytes.len().min(buf.len());
        buf[..n].copy_from_slice(&bytes[..n]);
        self.wr(m.rx_start, &buf)
    }

    /// Writes a mailbox of type `t` into SM0; returns the WKC.
    pub fn mbx_write(&mut self, t: MailboxType, payload: &[u8]) -> u16 {
        let c = self.next_counter();
        let m = self.s.od().def().mailbox;
        let mut buf = vec![0u8; m.rx_len as usize];
        write_mailbox(&mut buf, &MailboxHeader::new(0, 0, t, c), payload).unwrap();
        self.wr(m.rx_start, &buf)
    }

    /// Reads SM1 after polling; None if empty.
    pub fn mbx_read(&mut self) -> Option<(MailboxHeader, Vec<u8>)> {
        self.poll();
        let m = self.s.od().def().mailbox;
        let (d, wkc) = self.rd(m.tx_start, m.tx_len as usize);
        if wkc != 1 {
            return None;
        }
        let m = MailboxRef::parse(&d).unwrap();
        Some((m.header, m.payload.to_vec()))
    }

    /// A CoE request and its reply.
    pub fn coe(&mut self, payload: &[u8]) -> Vec<u8> {
        assert_eq!(self.mbx_write(MailboxType::Coe, payload), 1);
        let (h, p) = self.mbx_read().expect("reply");
        assert_eq!(h.mailbox_type, MailboxType::Coe, "reply {p:02x?}");
        p
    }

    // ---------------------------------------------------------------- SDO client

    /// SDO upload (expedited, normal or segmented; `ca`: complete access); abort code on
    /// failure.
    pub fn upload(&mut self, index: u16, sub: u8, ca: bool) -> Result<Vec<u8>, u32> {
        let mut b = [0u8; 10];
        let h = SdoHeader {
            command: 0x40 | if ca { 0x10 } else { 0 },
            index,
            subindex: sub,
        };
        write_sdo(&mut b, CoeService::SdoRequest, &h, [0; 4], &[]).unwrap();
        let r = self.coe(&b);
        if let Some(code) = abort_of(&r) {
            return Err(code);
        }
        let s = SdoRef::parse(&r).unwrap();
        match SdoResponseCommand::from_u8(s.command).unwrap() {
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
                    if let Some(code) = abort_of(&r) {
                        return Err(code);
                    }
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

    /// SDO download (expedited up to 4 bytes unless `ca`, else normal + segments); abort
    /// code on failure.
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
                if let Some(code) = abort_of(&r) {
                    return Err(code);
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
                if abort_of(&r).is_none() {
                    let s = SdoRef::parse(&r).unwrap();
                    assert_eq!(s.command, 0x20 | if toggle { 0x10 } else { 0 });
                }
                sent += n;
                toggle = !toggle;
            }
            r
        };
        if let Some(code) = abort_of(&resp) {
            return Err(code);
        }
        let s = SdoRef::parse(&resp).unwrap();
        match s.command {
            0x60 | 0x20 | 0x30 => Ok(()),
            c => panic!("unexpected response {c:#x}"),
        }
    }
}

/// The abort code of an SDO abort transfer, recognised as SOEM and the ETG.1000.6 state
/// machine do: command 0x80 under CoE service 2 (SDO request), whichever side aborts. An
/// abort sent as an SDO response (service 3) is a protocol error that SOEM reads as a
/// successful transfer or a packet error, so the bench fails on it.
pub fn abort_of(coe: &[u8]) -> Option<u32> {
    let s = SdoRef::parse(coe).ok()?;
    if s.command >> 5 != 4 {
        return None;
    }
    assert!(
        s.is_request(),
        "SDO abort {:08x?} sent under CoE service {:?}; ETG.1000.6 sends aborts as SDO requests (service 2)",
        s.abort_code().map(|c| c.code()),
        s.coe.service
    );
    Some(s.abort_code().unwrap().code())
}
