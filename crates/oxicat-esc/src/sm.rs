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

/// [`Sm::state`], low byte: the status register's bits 0 (interrupt write), 1 (interrupt
/// read), 3 (mailbox full), 6 (read open) and 7 (write open), and in bits 4..5 the last
/// completely written buffer (3 = none; the register shows them in buffered mode).
const ST_LAST_SHIFT: u16 = 4;
const ST_LAST: u16 = 0x30;
const ST_IRQ_WRITE: u16 = STATUS_IRQ_WRITE as u16;
const ST_IRQ_READ: u16 = STATUS_IRQ_READ as u16;
const ST_MBX_FULL: u16 = STATUS_MBX_FULL as u16;
const ST_READ_OPEN: u16 = STATUS_READ_OPEN as u16;
const ST_WRITE_OPEN: u16 = STATUS_WRITE_OPEN as u16;
/// [`Sm::state`], high byte: the buffered-mode buffer indices (bits 8..9 the producer's,
/// 10..11 the consumer's, 12..13 the next one) and bit 14 the pending commit.
const B_WRITE: u16 = 8;
const B_USER: u16 = 10;
const B_NEXT: u16 = 12;
const B_PENDING: u16 = 1 << 14;

/// The producer's commit in buffered mode, per high byte of [`Sm::state`]: the new high
/// byte (the written buffer becomes the newest, the producer continues in the buffer that
/// is neither the newest nor the consumer's, `3 - w - user` as [`Sm::commit`] always
/// computed it, wrapping within two bits for codes that never occur; no commit pending),
/// with the written buffer as last written and interrupt write in the low byte.
static COMMIT: [u16; 256] = {
    let mut t = [0u16; 256];
    let mut h = 0;
    while h < 256 {
        let s = (h as u16) << 8;
        let w = (s >> B_WRITE) & 3;
        let u = (s >> B_USER) & 3;
        let nw = 3u16.wrapping_sub(w).wrapping_sub(u) & 3;
        t[h] = nw << B_WRITE | u << B_USER | w << B_NEXT | w << ST_LAST_SHIFT | ST_IRQ_WRITE;
        h += 1;
    }
    t
};

/// The consumer takes the next buffer (`user = next`), per high byte of [`Sm::state`]:
/// the new high byte.
static TAKE: [u16; 256] = {
    let mut t = [0u16; 256];
    let mut h = 0;
    while h < 256 {
        let s = (h as u16) << 8;
        let n = (s >> B_NEXT) & 3;
        t[h] = (s & !(3 << B_USER)) | n << B_USER;
        h += 1;
    }
    t
};

/// One SyncManager channel (16 bytes: the fused path finds one with a shift).
///
/// The run-time state is one 16-bit word ([`Sm::state`]; the fused path updates it with
/// one table look-up and one mask): the low byte in the layout of the status register
/// 0x0805 + 8n, the high byte the three buffer indices of buffered mode and the pending
/// commit.
#[derive(Debug, Clone, Default)]
#[repr(C, align(16))]
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
    /// Low byte: status bits 0 (interrupt write), 1 (interrupt read), 3 (mailbox full),
    /// the last written buffer in bits 4..5 (3 = none), read open (bit 6), write open
    /// (bit 7). High byte, buffered mode: the buffer the producer writes into (bits
    /// 8..9), the one the consumer reads, locked while opened (10..11), and the one the
    /// consumer takes when it next opens one (12..13): the newest completely written
    /// buffer, which is the consumer's own when none was written since it last took one
    /// (so that taking needs no test); bit 14: a producer write was completed by ECAT in
    /// the current frame (commit at frame end).
    state: u16,
}

impl Sm {
    /// Status byte: interrupt write/read and mailbox full (bits 0, 1, 3).
    #[inline]
    pub fn status(&self) -> u8 {
        (self.state & (ST_IRQ_WRITE | ST_IRQ_READ | ST_MBX_FULL)) as u8
    }

    /// Buffered mode: buffer the producer writes into.
    #[inline]
    pub fn write_buf(&self) -> u8 {
        ((self.state >> B_WRITE) & 3) as u8
    }

    /// Buffered mode: buffer the consumer reads (locked while opened).
    #[inline]
    pub fn user_buf(&self) -> u8 {
        ((self.state >> B_USER) & 3) as u8
    }

    /// Buffered mode: the buffer the consumer takes when it next opens one.
    #[inline]
    pub fn next_buf(&self) -> u8 {
        ((self.state >> B_NEXT) & 3) as u8
    }

    /// Last completely written buffer (status bits 4..5), 3 = none.
    #[inline]
    pub fn last_written(&self) -> u8 {
        ((self.state & ST_LAST) >> ST_LAST_SHIFT) as u8
    }

    /// Producer has accessed the start address (buffer opened for writing).
    #[inline]
    pub fn write_open(&self) -> bool {
        self.state & ST_WRITE_OPEN != 0
    }

    /// Consumer has accessed the start address (buffer opened for reading).
    #[inline]
    pub fn read_open(&self) -> bool {
        self.state & ST_READ_OPEN != 0
    }

    /// The producer has written the buffer's last byte: closed, the commit pending until
    /// the frame's end.
    #[inline]
    pub fn close_write_pending(&mut self) {
        self.state = (self.state & !ST_WRITE_OPEN) | B_PENDING;
    }

    /// A producer write was completed by ECAT in the current frame (commit at frame end).
    #[inline]
    pub fn pending_commit(&self) -> bool {
        self.state & B_PENDING != 0
    }

    /// Closes the producer's buffer: its last byte written (then committed, at once by
    /// the PDI or at the frame's end by ECAT), or abandoned (a bad frame).
    #[inline]
    pub fn close_write(&mut self) {
        self.state &= !ST_WRITE_OPEN;
    }

    /// The consumer takes the newest completely written buffer (its own when none is
    /// newer, see [`Sm::next_buf`]).
    #[inline(always)]
    fn take_next(&mut self) {
        self.state = (self.state & 0xFF) | TAKE[usize::from(self.state >> 8)];
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

    /// Resets the run-time state (on activation): status clear, nothing open, producer in
    /// buffer 0, consumer (and next) buffer 2, none written yet.
    pub fn reset_state(&mut self) {
        self.state = 3 << ST_LAST_SHIFT | 2 << B_USER | 2 << B_NEXT;
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

    /// The status byte as the register 0x0805 + 8n shows it: a mailbox shows mailbox full
    /// and no buffer, buffered mode the last written buffer and not mailbox full.
    #[inline]
    pub fn status_reg(&self) -> u8 {
        if self.is_mailbox() {
            (self.state & !ST_LAST) as u8
        } else {
            self.buffered_status_reg()
        }
    }

    /// Completes a producer write: mailbox becomes full / a new buffer becomes the newest.
    #[inline]
    pub fn commit(&mut self) {
        if self.is_mailbox() {
            self.state = (self.state & !B_PENDING) | ST_MBX_FULL | ST_IRQ_WRITE;
            return;
        }
        self.buffered_commit();
    }

    /// [`Sm::commit`] in buffered mode: the written buffer becomes the newest and the
    /// last written, interrupt write sets, the producer continues in the buffer that is
    /// neither the newest nor the consumer's, no commit pending ([`COMMIT`]). Returns the
    /// written buffer.
    #[inline(always)]
    fn buffered_commit(&mut self) -> u8 {
        let s = self.state;
        self.state = (s & (ST_IRQ_READ | ST_MBX_FULL | ST_READ_OPEN | ST_WRITE_OPEN))
            | COMMIT[usize::from(s >> 8)];
        ((s >> B_WRITE) & 3) as u8
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
        let b = self.buffered_read_whole();
        Some(b as u32 * self.len as u32)
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
            self.close_write_pending();
            return Some(0);
        }
        self.state = (self.state & !(ST_IRQ_READ | ST_WRITE_OPEN)) | B_PENDING;
        Some(self.write_buf() as u32 * self.len as u32)
    }

    /// Buffered mode, ECAT consumer: `read_whole` for an SM known to be in buffered mode
    /// (fused LRW path): the index of the buffer it reads. The consumer takes the next
    /// buffer, the read closes at once (read open clear), interrupt write clears and
    /// interrupt read sets.
    #[inline(always)]
    pub fn buffered_read_whole(&mut self) -> u8 {
        let s = self.state;
        let s = (s & (ST_IRQ_READ | ST_MBX_FULL | ST_LAST | ST_WRITE_OPEN))
            | ST_IRQ_READ
            | TAKE[usize::from(s >> 8)];
        self.state = s;
        ((s >> B_USER) & 3) as u8
    }

    /// Buffered mode, ECAT producer: `write_whole` immediately followed by `commit` (a
    /// good frame's end), for an SM known to be in buffered mode (fused LRW path): the
    /// index of the buffer written.
    #[inline(always)]
    pub fn buffered_write_commit(&mut self) -> u8 {
        self.state &= !(ST_IRQ_READ | ST_WRITE_OPEN);
        self.buffered_commit()
    }

    /// `status_reg` for an SM known to be in buffered mode.
    #[inline(always)]
    pub fn buffered_status_reg(&self) -> u8 {
        (self.state & !ST_MBX_FULL) as u8
    }

    /// Drops a producer write that was not committed (frame with bad FCS).
    pub fn discard(&mut self) {
        self.state &= !B_PENDING;
    }

    /// Consumer opens the buffer (first byte accessed). Returns false when the access is
    /// refused (empty mailbox).
    #[inline]
    pub fn open_read(&mut self) -> bool {
        if self.is_mailbox() {
            if self.state & ST_MBX_FULL == 0 {
                return false;
            }
        } else {
            self.take_next();
        }
        self.state = (self.state | ST_READ_OPEN) & !ST_IRQ_WRITE;
        true
    }

    /// Consumer has read the last byte.
    #[inline]
    pub fn close_read(&mut self) {
        self.state &= !ST_READ_OPEN;
        if self.is_mailbox() {
            self.state &= !ST_MBX_FULL;
        }
        self.state |= ST_IRQ_READ;
    }

    /// Producer opens the buffer (first byte written). Returns false when refused (full
    /// mailbox).
    #[inline]
    pub fn open_write(&mut self) -> bool {
        if self.is_mailbox() && self.state & ST_MBX_FULL != 0 {
            return false;
        }
        self.state = (self.state | ST_WRITE_OPEN) & !ST_IRQ_READ;
        true
    }

    /// The event this SM raises towards the PDI (AL event request bit 8 + n).
    #[inline]
    pub fn al_event(&self) -> bool {
        if !self.enabled || self.ctrl & CTRL_AL_IRQ == 0 {
            return false;
        }
        if self.ecat_writes() {
            self.state & ST_IRQ_WRITE != 0
        } else {
            self.state & ST_IRQ_READ != 0
        }
    }

    /// The event this SM raises towards ECAT (ECAT event request bit 4 + n).
    #[inline]
    pub fn ecat_event(&self) -> bool {
        if !self.enabled || self.ctrl & CTRL_ECAT_IRQ == 0 {
            return false;
        }
        if self.ecat_writes() {
            self.state & ST_IRQ_READ != 0
        } else {
            self.state & ST_IRQ_WRITE != 0
        }
    }
}

#[cfg(test)]
mod tests {
    //! The packed state against the field-per-flag `Sm` it replaced (kept here verbatim as
    //! the reference): every operation from every reachable state, same results and same
    //! observable state.
    #![allow(dead_code, missing_docs)]
    use super::*;
    use proptest::prelude::*;

    /// One SyncManager channel (16 bytes: the fused path finds one with a shift).
    #[derive(Debug, Clone, Default)]
    pub(super) struct RefSm {
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

    impl RefSm {
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

    fn same(p: &Sm, r: &RefSm) -> Result<(), TestCaseError> {
        prop_assert_eq!(p.status_reg(), r.status_reg());
        prop_assert_eq!(p.buffered_status_reg(), r.buffered_status_reg());
        prop_assert_eq!(p.status(), r.status);
        prop_assert_eq!(p.write_buf(), r.write_buf);
        prop_assert_eq!(p.user_buf(), r.user_buf);
        prop_assert_eq!(p.next_buf(), r.next_buf);
        prop_assert_eq!(p.last_written(), r.last_written);
        prop_assert_eq!(p.write_open(), r.write_open);
        prop_assert_eq!(p.read_open(), r.read_open);
        prop_assert_eq!(p.pending_commit(), r.pending_commit);
        prop_assert_eq!(p.al_event(), r.al_event());
        prop_assert_eq!(p.ecat_event(), r.ecat_event());
        Ok(())
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]
        /// Random operation sequences from the reset state, with the mode, direction and
        /// interrupt bits changing under way (as a reconfiguration does).
        #[test]
        fn packed_state_equals_fields(ops in proptest::collection::vec((0u8..15, any::<u8>()), 1..80)) {
            let (mut p, mut r) = (Sm::default(), RefSm::default());
            p.len = 32;
            r.len = 32;
            p.reset_state();
            r.reset_state();
            same(&p, &r)?;
            for (op, v) in ops {
                match op {
                    0 => {
                        p.ctrl = v;
                        r.ctrl = v;
                        p.enabled = v & 0x80 != 0;
                        r.enabled = v & 0x80 != 0;
                    }
                    1 => { p.reset_state(); r.reset_state(); }
                    2 => { p.commit(); r.commit(); }
                    3 => prop_assert_eq!(p.read_whole(), r.read_whole()),
                    4 => prop_assert_eq!(p.write_whole(), r.write_whole()),
                    5 if !r.is_mailbox() => {
                        prop_assert_eq!(p.buffered_read_whole(), r.buffered_read_whole());
                    }
                    6 if !r.is_mailbox() => {
                        prop_assert_eq!(p.buffered_write_commit(), r.buffered_write_commit());
                    }
                    7 => { p.discard(); r.discard(); }
                    8 => prop_assert_eq!(p.open_read(), r.open_read()),
                    9 => { p.close_read(); r.close_read(); }
                    10 => prop_assert_eq!(p.open_write(), r.open_write()),
                    11 => { p.close_write(); r.write_open = false; }
                    12 => {
                        p.close_write_pending();
                        r.write_open = false;
                        r.pending_commit = true;
                    }
                    13 => prop_assert_eq!(p.buf_offset(v & 3), r.buf_offset(v & 3)),
                    _ => {
                        // A write that opens and completes at once (the PDI's whole
                        // buffer: open, close, commit).
                        prop_assert_eq!(p.open_write(), r.open_write());
                        p.close_write();
                        r.write_open = false;
                        p.commit();
                        r.commit();
                    }
                }
                same(&p, &r)?;
            }
        }
    }
}
