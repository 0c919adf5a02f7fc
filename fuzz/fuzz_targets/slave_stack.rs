//! The slave stack (ESM, mailbox, CoE SDO + SDO information, FoE firmware update, PDO
//! assignment, sync modes) on a software ESC, fed whatever a master could send: mailboxes
//! of any content (raw, or with a valid CoE/FoE mailbox header and arbitrary service
//! data), AL control requests, SyncManager/DC register writes, process data, time and
//! SYNC events. Nothing may panic, and the AL status must always be a valid state.
//!
//! Input: byte 0 picks the start state (INIT / PREOP / BOOT / SAFEOP with process data);
//! then records `[op, len, data[len]]` (see `step`).
#![no_main]

use libfuzzer_sys::fuzz_target;
use oxicat_esc::{Esc, EscConfig};
use oxicat_slave::foe::{FirmwareUpdate, ImageHeader, RamStore, UpdateConfig, WithFoe};
use oxicat_slave::{Pdi, Slave};
use oxicat_testkit::device::{eeprom, App, DEF, IMG, MBX, SM0, SM1, SM2, SM3, STATION};
use oxicat_wire::frame::FrameBuilder;
use oxicat_wire::mailbox::{write_mailbox, MailboxHeader, MailboxType};
use oxicat_wire::{Command, DatagramHeader};

type Fw = WithFoe<App, FirmwareUpdate<RamStore<2, 1024>>>;

struct Rig {
    esc: Esc,
    s: Slave<Esc, IMG, MBX>,
    app: Fw,
    t: u64,
    counter: u8,
}

impl Rig {
    fn new() -> Self {
        let mut esc = Esc::new(EscConfig::et1100(), eeprom(&DEF));
        let s = Slave::new(&DEF, &mut esc).expect("the stack starts on a blank ESC");
        let mut factory = ImageHeader::for_payload(&DEF.identity, &[7u8; 64])
            .to_bytes()
            .to_vec();
        factory.extend_from_slice(&[7u8; 64]);
        let cfg = UpdateConfig {
            identity: DEF.identity,
            file_name: "firmware.bin",
            password: 0,
            read_back: true,
        };
        let app = WithFoe {
            app: App::default(),
            files: FirmwareUpdate::new(RamStore::with_image(&factory).unwrap(), cfg),
        };
        let mut r = Rig {
            esc,
            s,
            app,
            t: 0,
            counter: 0,
        };
        r.frame(Command::Apwr, 0, 0x0010, &STATION.to_le_bytes());
        r
    }

    fn frame(&mut self, cmd: Command, adp: u16, ado: u16, data: &[u8]) {
        let mut buf = [0u8; 1600];
        let Ok(mut fb) = FrameBuilder::new_bare(&mut buf) else {
            return;
        };
        if fb
            .push(
                DatagramHeader::physical(cmd, 0, adp, ado, data.len() as u16),
                data,
            )
            .is_err()
        {
            return;
        }
        let n = fb.finish();
        self.t += 10_000;
        self.esc.forward(0, &mut buf[..n], self.t, true);
    }

    fn wr(&mut self, ado: u16, data: &[u8]) {
        self.frame(Command::Fpwr, STATION, ado, data);
    }

    /// Main loop passes; errors are the stack's to report, not panics.
    fn poll(&mut self) {
        for _ in 0..2 {
            let _ = self.s.poll(&mut self.esc, &mut self.app);
        }
        // The AL status register the stack writes is always one of the five states (plus
        // the error flag). Read from the ESC's memory: a master may lay a SyncManager over
        // the registers, and then PDI reads of 0x0130 go through its buffers.
        let st = &self.esc.memory()[0x0130..0x0132];
        let state = st[0] & 0x0F;
        assert!(
            matches!(state, 1 | 2 | 3 | 4 | 8),
            "AL status {:#06x}",
            u16::from_le_bytes([st[0], st[1]])
        );
    }

    fn sm(&mut self, n: u16, start: u16, len: u16, ctrl: u8) {
        let mut r = [0u8; 8];
        r[0..2].copy_from_slice(&start.to_le_bytes());
        r[2..4].copy_from_slice(&len.to_le_bytes());
        r[4] = ctrl;
        r[6] = u8::from(len > 0);
        self.wr(0x0800 + 8 * n, &r);
    }

    fn request(&mut self, state: u16) {
        self.wr(0x0120, &state.to_le_bytes());
        self.poll();
    }

    fn mailbox(&mut self, t: MailboxType, payload: &[u8]) {
        self.counter = MailboxHeader::next_counter(self.counter);
        let mut buf = [0u8; MBX];
        let n = payload.len().min(MBX - 6);
        let h = MailboxHeader::new(0, 0, t, self.counter);
        if write_mailbox(&mut buf, &h, &payload[..n]).is_ok() {
            self.wr(SM0, &buf);
        }
    }

    fn advance(&mut self, dt: u64) {
        self.t += dt;
        let ev = self.esc.advance(self.t);
        if ev.sync0.is_some() {
            let _ = self.s.on_sync0(&mut self.esc, &mut self.app);
        }
        if ev.sync1.is_some() {
            let _ = self.s.on_sync1(&mut self.esc, &mut self.app);
        }
        if Pdi::irq_lines(&mut self.esc).pdi_irq {
            let _ = self.s.on_pdi_irq(&mut self.esc, &mut self.app);
        }
    }

    /// SYNC0/SYNC1 cycle times below 10 µs become 10 µs longer. The software ESC runs every
    /// SYNC edge, as the chip does; a 1 ns cycle would spend the fuzzer's time there (70 % of
    /// it, measured with perf) instead of in the slave stack, which `esc_process` covers.
    fn min_cycles(&mut self) {
        for reg in [0x09A0u16, 0x09A4] {
            let m = &self.esc.memory()[usize::from(reg)..usize::from(reg) + 4];
            let c = u32::from_le_bytes([m[0], m[1], m[2], m[3]]);
            if c != 0 && c < 10_000 {
                self.wr(reg, &(c + 10_000).to_le_bytes());
            }
        }
    }

    /// One record: `op` selects what the master does with `d`.
    fn step(&mut self, op: u8, d: &[u8]) {
        match op % 9 {
            // A raw mailbox: any header, any content.
            0 => {
                let mut buf = [0u8; MBX];
                let n = d.len().min(MBX);
                buf[..n].copy_from_slice(&d[..n]);
                self.wr(SM0, &buf);
            }
            // A well-formed CoE mailbox with arbitrary CoE header and service data.
            1 => self.mailbox(MailboxType::Coe, d),
            // A well-formed FoE mailbox with arbitrary FoE content.
            2 => self.mailbox(MailboxType::Foe, d),
            // AL control.
            3 => {
                let v = u16::from_le_bytes([
                    d.first().copied().unwrap_or(0),
                    d.get(1).copied().unwrap_or(0),
                ]);
                self.request(v);
            }
            // A SyncManager register block (SM0..SM3), any bytes.
            4 if !d.is_empty() => {
                let n = u16::from(d[0] % 4);
                let len = (d.len() - 1).min(8);
                self.wr(0x0800 + 8 * n, &d[1..1 + len]);
            }
            // DC registers (cycle times, start time, activation, SYNC0/1 settings).
            5 if d.len() >= 2 => {
                let ado = 0x0980 + u16::from(d[0] % 0x30);
                let len = (d.len() - 1).min(16);
                self.wr(ado, &d[1..1 + len]);
                self.min_cycles();
            }
            // The master reads SM1 (frees the mailbox for the next reply).
            6 => self.frame(Command::Fprd, STATION, SM1, &[0u8; MBX]),
            // Process data in and out.
            7 => {
                self.wr(SM2, d);
                self.frame(Command::Fprd, STATION, SM3, &[0u8; 16]);
            }
            // Time passes (up to 2.55 ms): watchdogs, SYNC0/SYNC1, PDI interrupts.
            _ => {
                let dt = u64::from(d.first().copied().unwrap_or(1)) * 10_000;
                self.advance(dt);
            }
        }
        self.poll();
    }
}

fuzz_target!(|data: &[u8]| {
    let Some((&start, mut rest)) = data.split_first() else {
        return;
    };
    let mut r = Rig::new();
    if start & 0x03 != 0 {
        r.sm(0, SM0, MBX as u16, 0x26);
        r.sm(1, SM1, MBX as u16, 0x22);
        r.request(if start & 0x03 == 2 { 3 } else { 2 });
    }
    if start & 0x03 == 3 {
        r.sm(2, SM2, 4, 0x64);
        r.sm(3, SM3, 7, 0x20);
        r.request(4);
    }
    while rest.len() >= 2 {
        let (op, len) = (rest[0], usize::from(rest[1]));
        let n = len.min(rest.len() - 2);
        r.step(op, &rest[2..2 + n]);
        rest = &rest[2 + n..];
    }
});
