//! SyncManagers: decoded configuration plus the run-time state of mailbox (one buffer)
//! and buffered (three buffers) mode.
//!
//! Register layout at 0x0800 + 8n: start (u16), length (u16), control (u8), status (u8),
//! activate (u8), PDI control (u8).

/// Control bits 0..1: operation mode (00 buffered, 10 mailbox).
pub const CTRL_MODE_MASK: u8 = 0x03;
/// Control bits 2..3: direction (00 ECAT reads / PDI writes, 01 ECAT writes / PDI reads).
pub const CTRL_DIR_MASK: u8 = 0x0C;
/// Control bit 4: interrupt in ECAT event request register.
pub const CTRL_ECAT_IRQ: u8 = 0x10;
/// Control bit 5: interrupt in AL event request register.
pub const CTRL_AL_IRQ: u8 = 0x20;
/// Control bit 6: watchdog trigger enable.
pub const CTRL_WD_TRIGGER: u8 = 0x40;

/// Status bit 0: interrupt write (buffer completely written).
pub const STATUS_IRQ_WRITE: u8 = 0x01;
/// Status bit 1: interrupt read (buffer completely read).
pub const STATUS_IRQ_READ: u8 = 0x02;
/// Status bit 3: mailbox full.
pub const STATUS_MBX_FULL: u8 = 0x08;
/// Status bit 6: read buffer in use (opened).
pub const STATUS_READ_OPEN: u8 = 0x40;
/// Status bit 7: write buffer in use (opened).
pub const STATUS_WRITE_OPEN: u8 = 0x80;

/// Which side of the ESC performs an access.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// The EtherCAT side (datagrams).
    Ecat,
    /// The process data interface (the MCU).
    Pdi,
}

/// One SyncManager channel (16 bytes: the fused path finds one with a shift).
#[derive(Debug, Clone, Default)]
pub struct Sm {
    /// Physical start address.
    pub start: u16,
    /// Length in bytes (0 = disabled).
    pub len: u16,
    /// Control byte.
    pub ctrl: u8,
    /// Activate byte as written by ECAT.
    pub activate: u8,
    /// PDI control byte as written by the PDI.
    pub pdi_ctrl: u8,
    /// Effective enable (activate bit 0, not deactivated by PDI, length > 0).
    pub enabled: bool,
    /// Status byte (interrupt write/read, mailbox full, buffer state, open flags).
    pub status: u8,
    /// Buffered mode: buffer the producer writes into.
    pub write_buf: u8,
    /// Buffered mode: buffer the consumer reads (locked while opened).
    pub user_buf: u8,
    /// Buffered mode: the buffer the consumer takes when it next opens one: the newest
    /// completely written buffer, which is `user_buf` itself when none was written since
    /// the consumer last took one (so that taking needs no test).
    pub next_buf: u8,
    /// Last completely written buffer (status bits 4..5), 3 = none.
    pub last_written: u8,
    /// Producer has accessed the start address (buffer opened for writing).
    pub write_open: bool,
    /// Consumer has accessed the start address (buffer opened for reading).
    pub read_open: bool,
    /// A producer write was completed by ECAT in the current frame (commit at frame end).
    pub pending_commit: bool,
}

impl Sm {
    /// The consumer takes the newest completely written buffer (its own when none is
    /// newer, see [`Sm::next_buf`]).
    #[inline(always)]
    fn take_next(&mut self) {
        self.user_buf = self.next_buf;
    }

    /// Decodes the 8 register bytes of one SM (keeps run-time state).
    pub fn load_regs(&mut self, r: &[u8]) {
        if r.len() < 8 {
            return;
        }
        self.start = u16::from_le_bytes([r[0], r[1]]);
        self.len = u16::from_le_bytes([r[2], r[3]]);
        self.ctrl = r[4];
        self.activate = r[6];
        self.pdi_ctrl = r[7];
    }

    /// True when this SM should be active given its registers.
    pub fn should_enable(&self) -> bool {
        self.activate & 1 != 0 && self.pdi_ctrl & 1 == 0 && self.len != 0
    }

    /// Resets the run-time state (on activation).
    pub fn reset_state(&mut self) {
        self.status = 0;
        self.write_buf = 0;
        self.user_buf = 2;
        self.next_buf = 2;
        self.last_written = 3;
        self.write_open = false;
        self.read_open = false;
        self.pending_commit = false;
    }

    /// Mailbox (single-buffer) mode.
    #[inline]
    pub fn is_mailbox(&self) -> bool {
        self.ctrl & CTRL_MODE_MASK == 0x02
    }

    /// ECAT writes, PDI reads (otherwise ECAT reads, PDI writes).
    #[inline]
    pub fn ecat_writes(&self) -> bool {
        self.ctrl & CTRL_DIR_MASK == 0x04
    }

    /// True when `side` is the producer (writer) of this SM.
    #[inline]
    pub fn is_producer(&self, side: Side) -> bool {
        (side == Side::Ecat) == self.ecat_writes()
    }

    /// Exclusive end address of the (first) buffer.
    #[inline]
    pub fn end(&self) -> u32 {
        self.start as u32 + self.len as u32
    }

    /// Offset added to an address in the SM area for the physical buffer `b`. A mailbox
    /// has one buffer; so has an SM over registers (below 0x1000, e.g. the digital outputs
    /// at 0x0F00): its buffering lives inside the ESC, the registers after it belong to
    /// others (a second SM over the next output byte, as the AX58100 DIO board's ESI lays
    /// them out), so every buffer is the registers themselves.
    #[inline]
    pub fn buf_offset(&self, b: u8) -> u32 {
        if self.is_mailbox() || self.start < crate::regs::PROCESS_RAM {
            0
        } else {
            b as u32 * self.len as u32
        }
    }

    /// The status byte as the register 0x0805 + 8n shows it.
    #[inline]
    pub fn status_reg(&self) -> u8 {
        let mut s = self.status & (STATUS_IRQ_WRITE | STATUS_IRQ_READ | STATUS_MBX_FULL);
        if !self.is_mailbox() {
            s &= !STATUS_MBX_FULL;
            s |= (self.last_written & 3) << 4;
        }
        if self.read_open {
            s |= STATUS_READ_OPEN;
        }
        if self.write_open {
            s |= STATUS_WRITE_OPEN;
        }
        s
    }

    /// Completes a producer write: mailbox becomes full / a new buffer becomes the newest.
    #[inline]
    pub fn commit(&mut self) {
        self.pending_commit = false;
        if self.is_mailbox() {
            self.status |= STATUS_MBX_FULL | STATUS_IRQ_WRITE;
            return;
        }
        let w = self.write_buf;
        self.next_buf = w;
        self.last_written = w;
        // The producer continues in the buffer that is neither the newest nor the consumer's.
        self.write_buf = 3 - w - self.user_buf;
        self.status |= STATUS_IRQ_WRITE;
    }

    /// The consumer reads the whole buffer in one access (open, read, close): the
    /// offset of the buffer it reads, or `None` when refused (empty mailbox). Same effect
    /// as `open_read` + `close_read`, with the buffered-mode case kept branch-light.
    #[inline(always)]
    pub fn read_whole(&mut self) -> Option<u32> {
        if self.is_mailbox() {
            if !self.open_read() {
                return None;
            }
            self.close_read();
            return Some(0);
        }
        self.take_next();
        self.read_open = false;
        self.status = (self.status & !STATUS_IRQ_WRITE) | STATUS_IRQ_READ;
        Some(self.user_buf as u32 * self.len as u32)
    }

    /// The producer writes the whole buffer in one access (open, write, close; commit at
    /// frame end): the offset of the buffer it writes, or `None` when refused (full
    /// mailbox). Same effect as `open_write` followed by closing the write.
    #[inline(always)]
    pub fn write_whole(&mut self) -> Option<u32> {
        if self.is_mailbox() {
            if !self.open_write() {
                return None;
            }
            self.write_open = false;
            self.pending_commit = true;
            return Some(0);
        }
        self.status &= !STATUS_IRQ_READ;
        self.write_open = false;
        self.pending_commit = true;
        Some(self.write_buf as u32 * self.len as u32)
    }

    /// Buffered mode, ECAT consumer: `read_whole` for an SM known to be in buffered mode
    /// (fused LRW path): the index of the buffer it reads.
    #[inline(always)]
    pub fn buffered_read_whole(&mut self) -> u8 {
        self.take_next();
        self.read_open = false;
        self.status = (self.status & !STATUS_IRQ_WRITE) | STATUS_IRQ_READ;
        self.user_buf
    }

    /// Buffered mode, ECAT producer: `write_whole` immediately followed by `commit` (a
    /// good frame's end), for an SM known to be in buffered mode (fused LRW path): the
    /// index of the buffer written.
    #[inline(always)]
    pub fn buffered_write_commit(&mut self) -> u8 {
        let w = self.write_buf;
        self.write_open = false;
        self.pending_commit = false;
        self.next_buf = w;
        self.last_written = w;
        self.write_buf = 3 - w - self.user_buf;
        self.status = (self.status & !STATUS_IRQ_READ) | STATUS_IRQ_WRITE;
        w
    }

    /// `status_reg` for an SM known to be in buffered mode.
    #[inline(always)]
    pub fn buffered_status_reg(&self) -> u8 {
        (self.status & (STATUS_IRQ_WRITE | STATUS_IRQ_READ))
            | ((self.last_written & 3) << 4)
            | (u8::from(self.read_open) << 6)
            | (u8::from(self.write_open) << 7)
    }

    /// Drops a producer write that was not committed (frame with bad FCS).
    pub fn discard(&mut self) {
        self.pending_commit = false;
    }

    /// Consumer opens the buffer (first byte accessed). Returns false when the access is
    /// refused (empty mailbox).
    #[inline]
    pub fn open_read(&mut self) -> bool {
        if self.is_mailbox() {
            if self.status & STATUS_MBX_FULL == 0 {
                return false;
            }
        } else {
            self.take_next();
        }
        self.read_open = true;
        self.status &= !STATUS_IRQ_WRITE;
        true
    }

    /// Consumer has read the last byte.
    #[inline]
    pub fn close_read(&mut self) {
        self.read_open = false;
        if self.is_mailbox() {
            self.status &= !STATUS_MBX_FULL;
        }
        self.status |= STATUS_IRQ_READ;
    }

    /// Producer opens the buffer (first byte written). Returns false when refused (full
    /// mailbox).
    #[inline]
    pub fn open_write(&mut self) -> bool {
        if self.is_mailbox() && self.status & STATUS_MBX_FULL != 0 {
            return false;
        }
        self.write_open = true;
        self.status &= !STATUS_IRQ_READ;
        true
    }

    /// The event this SM raises towards the PDI (AL event request bit 8 + n).
    #[inline]
    pub fn al_event(&self) -> bool {
        if !self.enabled || self.ctrl & CTRL_AL_IRQ == 0 {
            return false;
        }
        if self.ecat_writes() {
            self.status & STATUS_IRQ_WRITE != 0
        } else {
            self.status & STATUS_IRQ_READ != 0
        }
    }

    /// The event this SM raises towards ECAT (ECAT event request bit 4 + n).
    #[inline]
    pub fn ecat_event(&self) -> bool {
        if !self.enabled || self.ctrl & CTRL_ECAT_IRQ == 0 {
            return false;
        }
        if self.ecat_writes() {
            self.status & STATUS_IRQ_READ != 0
        } else {
            self.status & STATUS_IRQ_WRITE != 0
        }
    }
}
