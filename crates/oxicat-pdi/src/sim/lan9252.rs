//! LAN9252 SPI model: system registers, CSR indirect access, PRAM FIFOs.

use super::{BusConfig, Core, Fault, Handle, Model, PinKind};
use crate::lan9252::{cmd, reg};
use oxicat_esc::Esc;
use std::collections::VecDeque;
use std::vec;
use std::vec::Vec;

/// ID_REV the model reports.
pub const ID_REV: u32 = 0x9252_0001;

/// A LAN9252 (SPI mode) in front of a software ESC.
pub struct Lan9252Model {
    core: Core,
    irq_cfg: u32,
    int_en: u32,
    csr_data: u32,
    csr_cmd: u32,
    csr_busy_left: u32,
    /// CSR polls that still read busy after a command (default 0).
    pub csr_busy_polls: u32,
    /// What ID_REV reads (default [`ID_REV`]).
    pub id_rev: u32,
    /// HW_CFG reads that report not ready after a reset (default 1).
    pub reset_not_ready_polls: u32,
    not_ready_left: u32,
    rd_addr_len: u32,
    rd_fifo: VecDeque<u8>,
    rd_active: bool,
    wr_addr_len: u32,
    wr_active: bool,
    wr_buf: Vec<u8>,
    /// Write bytes collected per DWORD address of a frame, committed on its last byte.
    pend: [u8; 4],
}

impl Lan9252Model {
    /// A chip in front of `esc` on `bus`.
    pub fn new(esc: Esc, bus: BusConfig) -> Self {
        Lan9252Model {
            core: Core::new(esc, bus),
            irq_cfg: 0,
            int_en: 0,
            csr_data: 0,
            csr_cmd: 0,
            csr_busy_left: 0,
            csr_busy_polls: 0,
            id_rev: ID_REV,
            reset_not_ready_polls: 1,
            not_ready_left: 0,
            rd_addr_len: 0,
            rd_fifo: VecDeque::new(),
            rd_active: false,
            wr_addr_len: 0,
            wr_active: false,
            wr_buf: Vec::new(),
            pend: [0; 4],
        }
    }

    /// A shared handle to a new chip.
    pub fn handle(esc: Esc, bus: BusConfig) -> Handle<Self> {
        Handle::new(Self::new(esc, bus))
    }

    fn proto_err(&mut self) {
        self.core.stats.protocol_errors += 1;
    }

    fn read_reg(&mut self, a: u16) -> u32 {
        let fault = self.core.fault;
        match a {
            reg::ID_REV => self.id_rev,
            reg::IRQ_CFG => self.irq_cfg,
            reg::INT_STS => u32::from(self.core.esc.irq_line()),
            reg::INT_EN => self.int_en,
            reg::BYTE_TEST => reg::BYTE_TEST_VALUE,
            reg::HW_CFG => {
                if fault == Fault::NeverReady {
                    0
                } else if self.not_ready_left > 0 {
                    self.not_ready_left -= 1;
                    0
                } else {
                    reg::HW_CFG_READY
                }
            }
            reg::CSR_DATA => self.csr_data,
            reg::CSR_CMD => {
                let busy = if fault == Fault::CsrStuckBusy {
                    true
                } else if self.csr_busy_left > 0 {
                    self.csr_busy_left -= 1;
                    true
                } else {
                    false
                };
                (self.csr_cmd & !reg::CSR_BUSY) | if busy { reg::CSR_BUSY } else { 0 }
            }
            reg::PRAM_RD_ADDR_LEN => self.rd_addr_len,
            reg::PRAM_RD_CMD => {
                let dw = self.rd_fifo.len().div_ceil(4) as u32;
                match fault {
                    Fault::PramNeverReady => u32::from(self.rd_active) << 31,
                    Fault::PramBadCount if dw > 0 => reg::PRAM_AVAIL | (31 << 8),
                    _ if dw > 0 => {
                        let n = dw.min(reg::PRAM_FIFO_DWORDS);
                        reg::PRAM_AVAIL | n << 8 | u32::from(self.rd_active) << 31
                    }
                    _ => 0,
                }
            }
            reg::PRAM_WR_ADDR_LEN => self.wr_addr_len,
            reg::PRAM_WR_CMD => {
                if !self.wr_active {
                    return 0;
                }
                let need = self.wr_total() - self.wr_buf.len();
                let dw = (need.div_ceil(4) as u32).min(reg::PRAM_FIFO_DWORDS);
                match fault {
                    Fault::PramNeverReady => reg::PRAM_BUSY,
                    Fault::PramBadCount => reg::PRAM_BUSY | reg::PRAM_AVAIL | (31 << 8),
                    _ => reg::PRAM_BUSY | reg::PRAM_AVAIL | dw << 8,
                }
            }
            _ => 0,
        }
    }

    fn wr_total(&self) -> usize {
        let addr = self.wr_addr_len & 0xFFFF;
        let len = (self.wr_addr_len >> 16) as usize;
        ((addr & 3) as usize + len).div_ceil(4) * 4
    }

    fn write_reg(&mut self, a: u16, v: u32) {
        match a {
            reg::IRQ_CFG => self.irq_cfg = v,
            reg::INT_EN => self.int_en = v,
            reg::RESET_CTL if v & (reg::RESET_DIGITAL | reg::RESET_ECAT) != 0 => {
                self.irq_cfg = 0;
                self.int_en = 0;
                self.rd_fifo.clear();
                self.rd_active = false;
                self.wr_active = false;
                self.wr_buf.clear();
                self.not_ready_left = self.reset_not_ready_polls;
            }
            reg::CSR_DATA => self.csr_data = v,
            reg::CSR_CMD => {
                self.csr_cmd = v;
                if v & reg::CSR_BUSY != 0 {
                    self.csr_busy_left = self.csr_busy_polls;
                    self.csr_exec(v);
                }
            }
            reg::PRAM_RD_ADDR_LEN => self.rd_addr_len = v,
            reg::PRAM_RD_CMD => {
                if v & reg::PRAM_ABORT != 0 {
                    self.rd_fifo.clear();
                    self.rd_active = false;
                } else if v & reg::PRAM_BUSY != 0 {
                    self.pram_read_start();
                }
            }
            reg::PRAM_WR_ADDR_LEN => self.wr_addr_len = v,
            reg::PRAM_WR_CMD => {
                if v & reg::PRAM_ABORT != 0 {
                    self.wr_active = false;
                    self.wr_buf.clear();
                } else if v & reg::PRAM_BUSY != 0 {
                    self.wr_active = true;
                    self.wr_buf.clear();
                }
            }
            _ => {}
        }
    }

    fn csr_exec(&mut self, v: u32) {
        let addr = (v & 0xFFFF) as u16;
        let size = ((v >> 16) & 7) as usize;
        if !matches!(size, 1 | 2 | 4) || addr as usize + size > 0x1000 {
            self.proto_err();
            return;
        }
        if v & reg::CSR_READ != 0 {
            let mut b = [0u8; 4];
            if self.core.pdi_read(addr, &mut b[..size]).is_err() {
                self.proto_err();
            }
            self.csr_data = u32::from_le_bytes(b);
        } else {
            let b = self.csr_data.to_le_bytes();
            if self.core.pdi_write(addr, &b[..size]).is_err() {
                self.proto_err();
            }
        }
    }

    fn pram_read_start(&mut self) {
        let addr = (self.rd_addr_len & 0xFFFF) as u16;
        let len = (self.rd_addr_len >> 16) as usize;
        let lead = (addr & 3) as usize;
        let mut b = vec![0u8; (lead + len).div_ceil(4) * 4];
        if self.core.pdi_read(addr, &mut b[lead..lead + len]).is_err() {
            self.proto_err();
        }
        self.rd_fifo = b.into();
        self.rd_active = true;
    }

    fn fifo_push(&mut self, byte: u8) {
        if !self.wr_active {
            self.proto_err();
            return;
        }
        self.wr_buf.push(byte);
        if self.wr_buf.len() == self.wr_total() {
            let addr = (self.wr_addr_len & 0xFFFF) as u16;
            let len = (self.wr_addr_len >> 16) as usize;
            let lead = (addr & 3) as usize;
            let data = core::mem::take(&mut self.wr_buf);
            if self.core.pdi_write(addr, &data[lead..lead + len]).is_err() {
                self.proto_err();
            }
            self.wr_active = false;
        }
    }
}

/// One CS-low frame in progress on a byte-clocked bus (see [`Lan9252Model::clock_byte`]).
#[derive(Debug, Default, Clone)]
pub struct Lan9252Frame {
    /// Bytes clocked so far.
    n: usize,
    /// Command and address bytes.
    hdr: [u8; 3],
    /// The DWORD last read in this frame (a read frame reads each DWORD once).
    cache: Option<(u16, [u8; 4])>,
    /// A write frame left a DWORD incomplete.
    touched: bool,
}

impl Lan9252Frame {
    /// The chip address of data byte `i` (after the header) of this frame.
    fn at(&self, i: usize) -> u16 {
        let field = u16::from_be_bytes([self.hdr[1], self.hdr[2]]);
        let base = field & 0x3FFF;
        if field & cmd::ADDR_INC != 0 {
            base.wrapping_add(i as u16)
        } else if is_rd_fifo(base) || is_wr_fifo(base) {
            base
        } else {
            (base & !3) | ((base as usize + i) & 3) as u16
        }
    }
}

impl Lan9252Model {
    /// Clocks one byte of the frame `f` (CS low): MOSI in, MISO out, with the effects a
    /// real chip has at that byte — how an emulated MCU's SPI peripheral, which moves a
    /// byte at a time and needs each read byte before it sends the next, drives the chip.
    /// [`Model::frame`] is exactly this over a whole frame; end it with
    /// [`Lan9252Model::end_frame`] when CS goes high.
    pub fn clock_byte(&mut self, f: &mut Lan9252Frame, mosi: u8) -> u8 {
        let k = f.n;
        f.n += 1;
        if k < 3 {
            f.hdr[k] = mosi;
            return 0xFF;
        }
        match f.hdr[0] {
            cmd::READ | cmd::FAST_READ => {
                let start = if f.hdr[0] == cmd::FAST_READ { 4 } else { 3 };
                if k < start {
                    return 0xFF;
                }
                let a = f.at(k - start);
                if is_rd_fifo(a) {
                    match self.rd_fifo.pop_front() {
                        Some(b) => {
                            if self.rd_fifo.is_empty() {
                                self.rd_active = false;
                            }
                            b
                        }
                        None => {
                            self.proto_err();
                            0xFF
                        }
                    }
                } else {
                    let dw = a & !3;
                    let v = match f.cache {
                        Some((d, v)) if d == dw => v,
                        _ => {
                            let v = self.read_reg(dw).to_le_bytes();
                            f.cache = Some((dw, v));
                            v
                        }
                    };
                    v[(a & 3) as usize]
                }
            }
            cmd::WRITE => {
                let a = f.at(k - 3);
                if is_wr_fifo(a) {
                    self.fifo_push(mosi);
                } else {
                    self.pend[(a & 3) as usize] = mosi;
                    f.touched = true;
                    if a & 3 == 3 {
                        let v = u32::from_le_bytes(self.pend);
                        self.write_reg(a & !3, v);
                        f.touched = false;
                    }
                }
                0xFF
            }
            _ => 0xFF,
        }
    }

    /// CS goes high: a frame too short for a header, an unknown command or a partial DWORD
    /// write counts as a protocol error, as in [`Model::frame`].
    pub fn end_frame(&mut self, f: Lan9252Frame) {
        let known = matches!(f.hdr[0], cmd::READ | cmd::FAST_READ | cmd::WRITE);
        // A partial DWORD write: the LAN9252 requires whole DWORDs.
        if f.n < 3 || !known || f.touched {
            self.proto_err();
        }
    }
}

fn is_rd_fifo(a: u16) -> bool {
    a < 0x20
}
fn is_wr_fifo(a: u16) -> bool {
    (0x20..0x40).contains(&a)
}

impl Model for Lan9252Model {
    fn core(&mut self) -> &mut Core {
        &mut self.core
    }

    fn frame(&mut self, mosi: &[u8], _delays: &[(usize, u32)]) -> Vec<u8> {
        let mut f = Lan9252Frame::default();
        let miso = mosi.iter().map(|&b| self.clock_byte(&mut f, b)).collect();
        self.end_frame(f);
        miso
    }

    fn pin(&mut self, pin: PinKind) -> bool {
        match pin {
            PinKind::Irq => {
                let active = self.irq_cfg & reg::IRQ_EN != 0
                    && self.int_en & reg::ECAT_INT != 0
                    && self.core.esc.irq_line();
                let high_active = self.irq_cfg & reg::IRQ_POL != 0;
                active == high_active
            }
            PinKind::Sync0 => self.core.esc.sync_lines().0,
            PinKind::Sync1 => self.core.esc.sync_lines().1,
            PinKind::EepromLoaded => true,
        }
    }
}
