//! ET1100 SPI PDI model.

use super::{BusConfig, Core, Fault, Handle, Model, PinKind};
use crate::et1100::cmd;
use oxicat_esc::Esc;
use std::vec::Vec;

/// An ET1100 SPI PDI in front of a software ESC.
pub struct Et1100Model {
    core: Core,
    /// Minimum pause between address and data phase of a plain read (ns).
    pub read_delay_ns: u32,
}

/// One CS-low frame in progress on a byte-clocked bus (see [`Et1100Model::clock_byte`]).
#[derive(Debug, Default, Clone)]
pub struct Et1100Frame {
    /// Bytes clocked so far.
    n: usize,
    /// The AL event request bytes the address phase shifts out (taken at its first byte).
    ev: [u8; 3],
    /// The address and the command, once the address phase is complete.
    addr: u16,
    command: u8,
    /// Bytes of the address phase (2, or 3 with the address extension), 0 until known.
    hdr: usize,
    /// Read: the byte fetched for the next data byte (the ESC's prefetch).
    next: Option<u8>,
    /// Read: data bytes fetched so far.
    fetched: u16,
    /// Read: the termination byte was seen.
    terminated: bool,
    /// The frame is broken (counted once): the rest of it is ignored.
    bad: bool,
    /// Write: the data phase.
    data: Vec<u8>,
}

impl Et1100Model {
    /// A chip in front of `esc` on `bus`.
    pub fn new(esc: Esc, bus: BusConfig) -> Self {
        Et1100Model {
            core: Core::new(esc, bus),
            read_delay_ns: 240,
        }
    }

    /// A shared handle to a new chip.
    pub fn handle(esc: Esc, bus: BusConfig) -> Handle<Self> {
        Handle::new(Self::new(esc, bus))
    }

    fn proto_err(&mut self) {
        self.core.stats.protocol_errors += 1;
    }

    /// Marks `f` broken, counting one protocol error.
    fn break_frame(&mut self, f: &mut Et1100Frame) {
        if !f.bad {
            f.bad = true;
            self.proto_err();
        }
    }

    /// Fetches the next read byte of `f` from the ESC.
    fn fetch(&mut self, f: &mut Et1100Frame) {
        let mut b = [0u8; 1];
        let at = f.addr.wrapping_add(f.fetched);
        if self.core.pdi_read(at, &mut b).is_err() {
            f.next = None;
            self.break_frame(f);
            return;
        }
        f.fetched += 1;
        f.next = Some(b[0]);
    }

    /// Clocks one byte of the frame `f` (CS low): MOSI in, MISO out, with the effects the
    /// chip has at that byte — how an emulated MCU's SPI peripheral, which moves a byte at
    /// a time and needs each read byte before it sends the next, drives the chip.
    /// `pause_ns` is the time the bus idled before this byte (a plain read needs
    /// [`Et1100Model::read_delay_ns`] before its data phase). The address phase shifts out
    /// the AL event request; a read fetches each byte before it is shifted out and, unless
    /// the master sends the termination 0xFF on it, the next one (the ESC's prefetch); a
    /// write reaches the ESC when the frame ends. [`Model::frame`] is exactly this over a
    /// whole frame; end it with [`Et1100Model::end_frame`] when CS goes high.
    pub fn clock_byte(&mut self, f: &mut Et1100Frame, mosi: u8, pause_ns: u32) -> u8 {
        let k = f.n;
        f.n += 1;
        if k == 0 {
            let ev = self.core.esc.al_event_request().to_le_bytes();
            f.ev = [ev[0], ev[1], ev[2]];
            f.addr = u16::from(mosi) << 5;
            return f.ev[0];
        }
        if k == 1 {
            f.addr |= u16::from(mosi >> 3);
            f.command = mosi & 7;
            if f.command != cmd::ADDR_EXT {
                f.hdr = 2;
            }
            return f.ev[1];
        }
        if f.hdr == 0 {
            // Third byte of a three-byte address.
            f.addr |= u16::from(mosi >> 5) << 13;
            f.command = (mosi >> 2) & 7;
            f.hdr = 3;
            return f.ev[2];
        }
        if f.bad {
            return 0xFF;
        }
        let i = k - f.hdr;
        match f.command {
            cmd::NOP => 0xFF,
            cmd::READ | cmd::READ_WS => {
                let j = if f.command == cmd::READ_WS {
                    if i == 0 {
                        if mosi != cmd::WAIT_STATE {
                            self.proto_err();
                        }
                        return 0xFF;
                    }
                    i - 1
                } else {
                    if i == 0 && pause_ns < self.read_delay_ns {
                        // Data not fetched in time: the bytes are garbage.
                        self.break_frame(f);
                        return 0xFF;
                    }
                    i
                };
                if f.terminated {
                    // Bytes after the termination: the ESC has stopped reading.
                    self.break_frame(f);
                    return 0xFF;
                }
                if j == 0 {
                    self.fetch(f);
                }
                let Some(out) = f.next.take() else {
                    return 0xFF;
                };
                if mosi == cmd::READ_TERMINATION {
                    f.terminated = true;
                } else {
                    self.fetch(f);
                }
                out
            }
            cmd::WRITE => {
                f.data.push(mosi);
                0xFF
            }
            _ => 0xFF,
        }
    }

    /// CS goes high: a frame too short for its address, an unknown command or a read
    /// without termination (the ESC prefetched a byte too many) counts as a protocol
    /// error, as in [`Model::frame`]; a write's data reaches the ESC now.
    pub fn end_frame(&mut self, f: Et1100Frame) {
        if f.n < 2 || (f.command == cmd::ADDR_EXT && f.hdr == 0) {
            self.proto_err();
            return;
        }
        if f.bad {
            return;
        }
        match f.command {
            cmd::NOP => {}
            cmd::READ | cmd::READ_WS => {
                if f.fetched > 0 && !f.terminated {
                    self.proto_err();
                }
            }
            cmd::WRITE => {
                if self.core.pdi_write(f.addr, &f.data).is_err() {
                    self.proto_err();
                }
            }
            _ => self.proto_err(),
        }
    }
}

impl Model for Et1100Model {
    fn core(&mut self) -> &mut Core {
        &mut self.core
    }

    fn frame(&mut self, mosi: &[u8], delays: &[(usize, u32)]) -> Vec<u8> {
        let mut f = Et1100Frame::default();
        let miso = mosi
            .iter()
            .enumerate()
            .map(|(k, &b)| {
                let pause: u32 = delays
                    .iter()
                    .filter(|(p, _)| *p == k)
                    .map(|(_, ns)| *ns)
                    .sum();
                self.clock_byte(&mut f, b, pause)
            })
            .collect();
        self.end_frame(f);
        miso
    }

    fn pin(&mut self, pin: PinKind) -> bool {
        match pin {
            // SPI_IRQ: active low.
            PinKind::Irq => !self.core.esc.irq_line(),
            PinKind::Sync0 => self.core.esc.sync_lines().0,
            PinKind::Sync1 => self.core.esc.sync_lines().1,
            PinKind::EepromLoaded => self.core.fault != Fault::EepromNotLoaded,
        }
    }
}
