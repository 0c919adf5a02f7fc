//! Microchip LAN9252 over SPI.
//!
//! SPI frames (CS low for the whole transaction): `0x03 A[15:8] A[7:0] data…` (read),
//! `0x0B A[15:8] A[7:0] dummy data…` (fast read), `0x02 A[15:8] A[7:0] data…` (write).
//! Bit 14 of the address field is set for auto-increment on every access (as SOES's
//! `esc_hw.c` does); FIFO bursts stay inside the FIFO's 32-byte alias window, so they are
//! correct whether or not the chip increments. System registers are 32-bit little-endian.
//!
//! The EtherCAT core (ESC registers 0x0000..0x0FFF) is reached only indirectly: the CSR
//! data (0x0300) and command (0x0304: busy bit 31, read bit 30, size 18:16, address
//! 15:0) registers; process RAM (0x1000..) through the PRAM read/write FIFOs
//! (0x0000/0x0020) after programming address/length (0x0308/0x0310) and starting the
//! command (0x030C/0x0314). Every poll is bounded by [`Lan9252Config::retries`].

use crate::pins::{Lines, NoLines};
use crate::Error;
use embedded_hal::spi::{Operation, SpiDevice};
use oxicat_slave::{IrqLines, Pdi};

/// SPI instructions.
pub mod cmd {
    /// Serial read.
    pub const READ: u8 = 0x03;
    /// Fast read (one dummy byte after the address).
    pub const FAST_READ: u8 = 0x0B;
    /// Serial write.
    pub const WRITE: u8 = 0x02;
    /// Address field bit 14: auto-increment.
    pub const ADDR_INC: u16 = 1 << 14;
}

/// LAN9252 system registers (byte addresses of 32-bit registers).
pub mod reg {
    /// Process RAM read FIFO (0x0000..0x001F alias the FIFO port).
    pub const PRAM_RD_FIFO: u16 = 0x0000;
    /// Process RAM write FIFO (0x0020..0x003F alias the FIFO port).
    pub const PRAM_WR_FIFO: u16 = 0x0020;
    /// Chip ID and revision (0x9252_xxxx).
    pub const ID_REV: u16 = 0x0050;
    /// Interrupt configuration.
    pub const IRQ_CFG: u16 = 0x0054;
    /// Interrupt status.
    pub const INT_STS: u16 = 0x0058;
    /// Interrupt enable.
    pub const INT_EN: u16 = 0x005C;
    /// Byte order test (0x87654321).
    pub const BYTE_TEST: u16 = 0x0064;
    /// Hardware configuration (bit 27: READY).
    pub const HW_CFG: u16 = 0x0074;
    /// Reset control.
    pub const RESET_CTL: u16 = 0x01F8;
    /// EtherCAT CSR interface data.
    pub const CSR_DATA: u16 = 0x0300;
    /// EtherCAT CSR interface command.
    pub const CSR_CMD: u16 = 0x0304;
    /// PRAM read address and length.
    pub const PRAM_RD_ADDR_LEN: u16 = 0x0308;
    /// PRAM read command.
    pub const PRAM_RD_CMD: u16 = 0x030C;
    /// PRAM write address and length.
    pub const PRAM_WR_ADDR_LEN: u16 = 0x0310;
    /// PRAM write command.
    pub const PRAM_WR_CMD: u16 = 0x0314;

    /// BYTE_TEST value.
    pub const BYTE_TEST_VALUE: u32 = 0x8765_4321;
    /// HW_CFG: device ready.
    pub const HW_CFG_READY: u32 = 1 << 27;
    /// RESET_CTL: digital reset (whole chip but the PLL).
    pub const RESET_DIGITAL: u32 = 1 << 0;
    /// RESET_CTL: EtherCAT core reset.
    pub const RESET_ECAT: u32 = 1 << 6;
    /// CSR command: busy / start.
    pub const CSR_BUSY: u32 = 1 << 31;
    /// CSR command: read.
    pub const CSR_READ: u32 = 1 << 30;
    /// PRAM command: busy / start.
    pub const PRAM_BUSY: u32 = 1 << 31;
    /// PRAM command: abort.
    pub const PRAM_ABORT: u32 = 1 << 30;
    /// PRAM command: data available (read) / space available (write).
    pub const PRAM_AVAIL: u32 = 1 << 0;
    /// FIFO depth in DWORDs.
    pub const PRAM_FIFO_DWORDS: u32 = 16;
    /// PRAM command: DWORDs available (read) / free (write).
    pub const fn pram_count(v: u32) -> u32 {
        (v >> 8) & 0x1F
    }
    /// IRQ_CFG: IRQ output enable.
    pub const IRQ_EN: u32 = 1 << 8;
    /// IRQ_CFG: polarity (1 = active high).
    pub const IRQ_POL: u32 = 1 << 4;
    /// IRQ_CFG: buffer type (1 = push-pull).
    pub const IRQ_TYPE: u32 = 1 << 0;
    /// INT_EN / INT_STS: EtherCAT interrupt.
    pub const ECAT_INT: u32 = 1 << 0;
}

/// Driver settings.
#[derive(Debug, Clone, Copy)]
pub struct Lan9252Config {
    /// Use fast read (0x0B, one dummy byte) instead of read (0x03).
    pub fast_read: bool,
    /// Polls of a busy/ready bit before [`Error::Timeout`].
    pub retries: u32,
    /// IRQ pin push-pull active high (else open drain, active low).
    pub irq_active_high: bool,
    /// Longest PRAM FIFO burst in DWORDs (1..=8). FIFO bursts use auto-increment
    /// addressing inside the FIFO's 32-byte alias window (0x00..0x1F read, 0x20..0x3F
    /// write), so 8 is the most one CS frame may carry.
    pub fifo_burst_dwords: u8,
}

impl Default for Lan9252Config {
    fn default() -> Self {
        Lan9252Config {
            fast_read: false,
            retries: 64,
            irq_active_high: false,
            fifo_burst_dwords: 8,
        }
    }
}

/// Process RAM starts here; below, accesses go through the CSR registers.
pub const PRAM_START: u16 = 0x1000;

/// A LAN9252 on an SPI bus, with its IRQ/SYNC lines.
pub struct Lan9252<SPI, L = NoLines> {
    spi: SPI,
    lines: L,
    cfg: Lan9252Config,
    rd_pending: bool,
    wr_pending: bool,
}

type R<T, SPI> = Result<T, Error<<SPI as embedded_hal::spi::ErrorType>::Error>>;

impl<SPI: SpiDevice, L: Lines> Lan9252<SPI, L> {
    /// A driver; call [`Lan9252::init`] before use.
    pub fn new(spi: SPI, lines: L, cfg: Lan9252Config) -> Self {
        Lan9252 {
            spi,
            lines,
            cfg,
            rd_pending: false,
            wr_pending: false,
        }
    }

    /// The SPI device (e.g. to reach a simulated chip).
    pub fn spi_mut(&mut self) -> &mut SPI {
        &mut self.spi
    }

    /// Gives back the bus and the lines.
    pub fn release(self) -> (SPI, L) {
        (self.spi, self.lines)
    }

    /// Start-up: wait for BYTE_TEST and READY, check ID_REV, digital reset, wait again,
    /// enable the EtherCAT interrupt on the IRQ pin. Returns ID_REV.
    pub fn init(&mut self) -> R<u32, SPI> {
        self.wait_ready()?;
        let id = self.read_reg(reg::ID_REV)?;
        if id >> 16 != 0x9252 {
            return Err(Error::ChipId(id));
        }
        self.reset()?;
        let mut irq_cfg = reg::IRQ_EN;
        if self.cfg.irq_active_high {
            irq_cfg |= reg::IRQ_POL | reg::IRQ_TYPE;
        }
        self.write_reg(reg::IRQ_CFG, irq_cfg)?;
        self.write_reg(reg::INT_EN, reg::ECAT_INT)?;
        Ok(id)
    }

    /// Digital reset through RESET_CTL, then waits for BYTE_TEST and READY.
    pub fn reset(&mut self) -> R<(), SPI> {
        self.write_reg(reg::RESET_CTL, reg::RESET_DIGITAL)?;
        self.rd_pending = false;
        self.wr_pending = false;
        self.wait_ready()
    }

    /// Polls BYTE_TEST until it reads 0x87654321, then HW_CFG until READY.
    fn wait_ready(&mut self) -> R<(), SPI> {
        let mut last = 0;
        let mut ok = false;
        for _ in 0..self.cfg.retries.max(1) {
            last = self.read_reg(reg::BYTE_TEST)?;
            if last == reg::BYTE_TEST_VALUE {
                ok = true;
                break;
            }
        }
        if !ok {
            return Err(Error::ByteTest(last));
        }
        for _ in 0..self.cfg.retries.max(1) {
            if self.read_reg(reg::HW_CFG)? & reg::HW_CFG_READY != 0 {
                return Ok(());
            }
        }
        Err(Error::Timeout)
    }

    fn header(&self, read: bool, addr: u16, inc: bool) -> ([u8; 4], usize) {
        let field = addr | if inc { cmd::ADDR_INC } else { 0 };
        let [hi, lo] = field.to_be_bytes();
        match (read, self.cfg.fast_read) {
            (true, true) => ([cmd::FAST_READ, hi, lo, 0x00], 4),
            (true, false) => ([cmd::READ, hi, lo, 0], 3),
            (false, _) => ([cmd::WRITE, hi, lo, 0], 3),
        }
    }

    /// Raw SPI read of `buf.len()` bytes at system address `addr`.
    pub fn read_raw(&mut self, addr: u16, inc: bool, buf: &mut [u8]) -> R<(), SPI> {
        let (h, n) = self.header(true, addr, inc);
        self.spi
            .transaction(&mut [Operation::Write(&h[..n]), Operation::Read(buf)])
            .map_err(Error::Spi)
    }

    /// Raw SPI write of `data` at system address `addr`.
    pub fn write_raw(&mut self, addr: u16, inc: bool, data: &[u8]) -> R<(), SPI> {
        let (h, n) = self.header(false, addr, inc);
        self.spi
            .transaction(&mut [Operation::Write(&h[..n]), Operation::Write(data)])
            .map_err(Error::Spi)
    }

    /// Reads a 32-bit system register.
    pub fn read_reg(&mut self, addr: u16) -> R<u32, SPI> {
        let mut b = [0u8; 4];
        self.read_raw(addr, true, &mut b)?;
        Ok(u32::from_le_bytes(b))
    }

    /// Writes a 32-bit system register.
    pub fn write_reg(&mut self, addr: u16, v: u32) -> R<(), SPI> {
        self.write_raw(addr, true, &v.to_le_bytes())
    }

    fn csr_wait(&mut self) -> R<(), SPI> {
        for _ in 0..self.cfg.retries.max(1) {
            if self.read_reg(reg::CSR_CMD)? & reg::CSR_BUSY == 0 {
                return Ok(());
            }
        }
        Err(Error::Timeout)
    }

    /// The chunk size the CSR allows at `addr` for `len` bytes (1, 2 or 4, aligned).
    fn csr_chunk(addr: u16, len: usize) -> usize {
        if addr & 1 != 0 || len == 1 {
            1
        } else if addr & 2 != 0 || len < 4 {
            2
        } else {
            4
        }
    }

    /// ESC register read (below 0x1000) through the CSR command/data registers.
    pub fn csr_read(&mut self, mut addr: u16, buf: &mut [u8]) -> R<(), SPI> {
        let mut off = 0;
        while off < buf.len() {
            let n = Self::csr_chunk(addr, buf.len() - off);
            let c = reg::CSR_BUSY | reg::CSR_READ | ((n as u32) << 16) | addr as u32;
            self.write_reg(reg::CSR_CMD, c)?;
            self.csr_wait()?;
            let d = self.read_reg(reg::CSR_DATA)?.to_le_bytes();
            buf[off..off + n].copy_from_slice(&d[..n]);
            off += n;
            addr = addr.wrapping_add(n as u16);
        }
        Ok(())
    }

    /// ESC register write (below 0x1000): data and command in one burst, then poll.
    pub fn csr_write(&mut self, mut addr: u16, data: &[u8]) -> R<(), SPI> {
        let mut off = 0;
        while off < data.len() {
            let n = Self::csr_chunk(addr, data.len() - off);
            let mut b = [0u8; 8];
            b[..n].copy_from_slice(&data[off..off + n]);
            let c = reg::CSR_BUSY | ((n as u32) << 16) | addr as u32;
            b[4..].copy_from_slice(&c.to_le_bytes());
            self.write_raw(reg::CSR_DATA, true, &b)?;
            self.csr_wait()?;
            off += n;
            addr = addr.wrapping_add(n as u16);
        }
        Ok(())
    }

    /// Polls a PRAM command register until data/space is available; returns the DWORD
    /// count.
    fn pram_wait(&mut self, cmd_reg: u16) -> R<usize, SPI> {
        for _ in 0..self.cfg.retries.max(1) {
            let v = self.read_reg(cmd_reg)?;
            if v & reg::PRAM_AVAIL != 0 {
                let n = reg::pram_count(v);
                if n == 0 || n > reg::PRAM_FIFO_DWORDS {
                    return Err(Error::Protocol);
                }
                return Ok(n as usize);
            }
        }
        Err(Error::Timeout)
    }

    fn pram_start(&mut self, addr_len: u16, addr: u16, len: usize, abort: bool) -> R<(), SPI> {
        if abort {
            self.write_reg(addr_len + 4, reg::PRAM_ABORT)?;
        }
        let mut b = [0u8; 8];
        let al = ((len as u32) << 16) | addr as u32;
        b[..4].copy_from_slice(&al.to_le_bytes());
        b[4..].copy_from_slice(&reg::PRAM_BUSY.to_le_bytes());
        self.write_raw(addr_len, true, &b)
    }

    fn burst(&self) -> usize {
        usize::from(self.cfg.fifo_burst_dwords.clamp(1, 8))
    }

    /// Process RAM read through the read FIFO.
    pub fn pram_read(&mut self, addr: u16, buf: &mut [u8]) -> R<(), SPI> {
        if buf.is_empty() {
            return Ok(());
        }
        let abort = self.rd_pending;
        self.rd_pending = true;
        self.pram_start(reg::PRAM_RD_ADDR_LEN, addr, buf.len(), abort)?;
        let mut skip = (addr & 3) as usize;
        let mut total = (skip + buf.len()).div_ceil(4);
        let mut out = 0;
        let mut avail = 0;
        while total > 0 {
            if avail == 0 {
                avail = self.pram_wait(reg::PRAM_RD_CMD)?;
            }
            let n = avail.min(total).min(self.burst());
            let mut fifo = [0u8; 32];
            self.read_raw(reg::PRAM_RD_FIFO, true, &mut fifo[..4 * n])?;
            avail -= n;
            let take = (4 * n - skip).min(buf.len() - out);
            buf[out..out + take].copy_from_slice(&fifo[skip..skip + take]);
            out += take;
            skip = 0;
            total -= n;
        }
        self.rd_pending = false;
        Ok(())
    }

    /// Process RAM write through the write FIFO.
    pub fn pram_write(&mut self, addr: u16, data: &[u8]) -> R<(), SPI> {
        if data.is_empty() {
            return Ok(());
        }
        let abort = self.wr_pending;
        self.wr_pending = true;
        self.pram_start(reg::PRAM_WR_ADDR_LEN, addr, data.len(), abort)?;
        let mut lead = (addr & 3) as usize;
        let mut total = (lead + data.len()).div_ceil(4);
        let mut inp = 0;
        let mut free = 0;
        while total > 0 {
            if free == 0 {
                free = self.pram_wait(reg::PRAM_WR_CMD)?;
            }
            let n = free.min(total).min(self.burst());
            let mut fifo = [0u8; 32];
            let take = (4 * n - lead).min(data.len() - inp);
            fifo[lead..lead + take].copy_from_slice(&data[inp..inp + take]);
            self.write_raw(reg::PRAM_WR_FIFO, true, &fifo[..4 * n])?;
            free -= n;
            inp += take;
            lead = 0;
            total -= n;
        }
        self.wr_pending = false;
        Ok(())
    }
}

impl<SPI: SpiDevice, L: Lines> Pdi for Lan9252<SPI, L> {
    type Error = Error<SPI::Error>;

    fn read(&mut self, addr: u16, buf: &mut [u8]) -> Result<(), Self::Error> {
        if addr as usize + buf.len() > 0x1_0000 {
            return Err(Error::Address(addr));
        }
        let split = (PRAM_START.saturating_sub(addr) as usize).min(buf.len());
        let (csr, pram) = buf.split_at_mut(split);
        self.csr_read(addr, csr)?;
        self.pram_read(addr.max(PRAM_START), pram)
    }

    fn write(&mut self, addr: u16, data: &[u8]) -> Result<(), Self::Error> {
        if addr as usize + data.len() > 0x1_0000 {
            return Err(Error::Address(addr));
        }
        let split = (PRAM_START.saturating_sub(addr) as usize).min(data.len());
        let (csr, pram) = data.split_at(split);
        self.csr_write(addr, csr)?;
        self.pram_write(addr.max(PRAM_START), pram)
    }

    fn al_event_request(&mut self) -> Result<u32, Self::Error> {
        let mut b = [0u8; 4];
        self.csr_read(oxicat_slave::pdi::reg::AL_EVENT_REQ, &mut b)?;
        Ok(u32::from_le_bytes(b))
    }

    fn irq_lines(&mut self) -> IrqLines {
        self.lines.lines()
    }
}
