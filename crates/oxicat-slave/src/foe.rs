//! File access over EtherCAT (FoE): the server state machine, the application's file hooks
//! ([`FoeFiles`]) and a generic firmware update flow ([`FirmwareUpdate`]) on a
//! [`FirmwareStore`].
//!
//! # Protocol (server side)
//!
//! - **Write** (`WRQ` with file name and password): [`FoeFiles::open_write`]; on success the
//!   server acknowledges packet 0 and expects data packet 1, 2, … A data packet carries at
//!   most the segment size (receive mailbox length − 6 mailbox header − 6 FoE header); a
//!   packet shorter than that (possibly empty) is the last one. Every packet is
//!   acknowledged with its number after [`FoeFiles::write`] took it; the last one after
//!   [`FoeFiles::close_write`] accepted the file.
//! - **Busy**: a hook that cannot take the packet now (flash erase or programming running)
//!   answers [`FoeError::Busy`]; the server replies BUSY and does not consume the packet.
//!   The client sends the same packet (same number) again, as SOEM and TwinCAT do.
//! - **Packet numbers**: a data packet whose number is not the expected one aborts the
//!   transfer with 0x8005 "packet number wrong" — also the repeat of the last, already
//!   acknowledged packet, as SOES's `FOE_data` does (the mailbox layer already drops a
//!   repeated mailbox with the same counter).
//! - **Read** (`RRQ`): [`FoeFiles::open_read`], then data packets of the segment size
//!   (send mailbox length − 12) from [`FoeFiles::read`]; each is sent after the client's
//!   ACK of the previous one; a short packet ends the file. A BUSY from the client makes
//!   the server send the last packet again (SOES `FOE_busy`); an ACK with another number
//!   than the last packet sent is 0x8005.
//! - A request that does not fit the server's state (DATA while idle, ACK while writing,
//!   a new request in the middle of a transfer) aborts with 0x8004 "illegal". An ERROR
//!   from the client ends the transfer silently; a change to INIT (and every mailbox
//!   restart) ends it too, with [`FoeFiles::abort`].
//!
//! # Firmware update flow
//!
//! [`FirmwareUpdate`] serves two files:
//!
//! - the **firmware file** (name from [`UpdateConfig::file_name`]): written only in BOOT
//!   (0x8008 "bootstrap only" otherwise). The image streams into an inactive slot of the
//!   [`FirmwareStore`] (erased first: BUSY while the erase runs), never into the bootable
//!   one. When the last packet arrived the slot is read back and checked: length, CRC-32 of
//!   the payload and device identity from the [`ImageHeader`]; only then it is marked
//!   bootable. An interrupted transfer (BOOT→INIT, client ERROR), a truncated, corrupted
//!   or wrong-device image leaves the bootable slot as it was. In BOOT it may be read back
//!   when [`UpdateConfig::read_back`] is set.
//! - **`version.txt`** (read-only, in every mailbox state): the identity of the current
//!   bootable image, one `key=value` per line.
//!
//! Error codes of the flow:
//!
//! | condition | code |
//! |---|---|
//! | unknown file outside BOOT / reading a file that does not exist | 0x8001 not found |
//! | writing `version.txt`; reading the firmware with read-back off | 0x8002 access denied |
//! | image larger than a slot (header or data) | 0x8003 disk full |
//! | the same image (identity, length, CRC) is already bootable | 0x8006 already exists |
//! | password configured, request without one (0) | 0x8007 no user |
//! | firmware written or read outside BOOT | 0x8008 bootstrap only |
//! | any other file requested in BOOT | 0x8009 not bootstrap |
//! | wrong password | 0x800A no rights |
//! | not an image (magic, header version), truncated or too long, wrong device, flash error | 0x800B program error |
//! | payload CRC-32 differs from the header's | 0x800C checksum error |
//!
//! # Image format
//!
//! An image is a 32-byte header followed by the payload (little endian):
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `"OXFW"` (0x4F 0x58 0x46 0x57) |
//! | 4 | 2 | header version (1) |
//! | 6 | 2 | header length (32) |
//! | 8 | 4 | vendor id (0x1018:01) |
//! | 12 | 4 | product code (0x1018:02) |
//! | 16 | 4 | revision (0x1018:03) of the firmware in the payload |
//! | 20 | 4 | payload length in bytes |
//! | 24 | 4 | CRC-32 of the payload (IEEE 802.3 / zlib: reflected 0x04C11DB7, init and final XOR 0xFFFFFFFF) |
//! | 28 | 4 | reserved, 0 |
//!
//! An image fits a device when vendor id and product code equal the device's and the
//! revision's major part (high 16 bits) equals the device's (same hardware family).

use oxicat_wire::foe::{FoeHeader, FoeRef, FOE_HEADER_LEN};
use oxicat_wire::mailbox::{MailboxErrorDetail, MailboxType, MAILBOX_HEADER_LEN};

pub use oxicat_wire::foe::FoeErrorCode;

use crate::device::Identity;
use crate::pdi::Pdi;
use crate::slave::{Application, Slave};

/// A refusal with its FoE error code and a short text for the ERROR reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FoeFault {
    /// The error code.
    pub code: FoeErrorCode,
    /// Error text sent after the code (may be empty).
    pub text: &'static str,
}

impl FoeFault {
    /// A fault with the code's standard text.
    pub const fn new(code: FoeErrorCode) -> Self {
        Self {
            code,
            text: code.text(),
        }
    }

    /// A fault with an own text.
    pub const fn with_text(code: FoeErrorCode, text: &'static str) -> Self {
        Self { code, text }
    }
}

/// Why a write hook did not take the data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FoeError {
    /// Not now (flash busy): the server answers BUSY, the client sends the packet again.
    Busy {
        /// Progress done (e.g. erased sectors).
        done: u16,
        /// Progress total.
        entire: u16,
    },
    /// Refused: the transfer ends with an FoE ERROR.
    Fault(FoeFault),
}

impl From<FoeFault> for FoeError {
    fn from(f: FoeFault) -> Self {
        Self::Fault(f)
    }
}

/// The application's files, as the FoE server sees them. `boot` tells whether the request
/// came through the bootstrap mailbox (AL state BOOT).
pub trait FoeFiles {
    /// Opens `name` for reading.
    fn open_read(&mut self, name: &[u8], password: u32, boot: bool) -> Result<(), FoeFault>;
    /// Reads the file at `offset` into `buf`; returns the bytes read (fewer than
    /// `buf.len()` only at the end of the file).
    fn read(&mut self, offset: u32, buf: &mut [u8]) -> Result<usize, FoeFault>;
    /// Opens `name` for writing.
    fn open_write(&mut self, name: &[u8], password: u32, boot: bool) -> Result<(), FoeFault>;
    /// Takes `data` at `offset` of the file being written.
    fn write(&mut self, offset: u32, data: &[u8]) -> Result<(), FoeError>;
    /// The last packet arrived, `len` bytes in all: check and commit the file.
    fn close_write(&mut self, len: u32) -> Result<(), FoeError>;
    /// The transfer ended without completing: drop what was written.
    fn abort(&mut self);
}

/// Where the server is in a transfer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(crate) enum FoeState {
    /// No transfer.
    #[default]
    Idle,
    /// Receiving a file: `next` is the expected packet number, `offset` where it goes.
    Writing {
        next: u32,
        offset: u32,
        /// The last packet's data is written; `close_write` still answers BUSY.
        closing: bool,
    },
    /// Sending a file: `packet` was sent last, from `offset`, with `len` bytes.
    Reading { packet: u32, offset: u32, len: u32 },
}

impl<P: Pdi, const N: usize, const M: usize, const K: usize> Slave<P, N, M, K> {
    /// Ends a running FoE transfer (state change to INIT, mailbox restart).
    pub(crate) fn foe_reset<A: Application<N>>(&mut self, app: &mut A) {
        if self.foe != FoeState::Idle {
            if let Some(f) = app.foe() {
                f.abort();
            }
        }
        self.foe = FoeState::Idle;
    }

    /// Data bytes per FoE packet received (SM0).
    fn foe_rx_segment(&self) -> usize {
        (self.mbx_def().rx_len as usize).min(M) - MAILBOX_HEADER_LEN - FOE_HEADER_LEN
    }

    /// Data bytes per FoE packet sent (SM1).
    fn foe_tx_segment(&self) -> usize {
        self.reply_capacity() - FOE_HEADER_LEN
    }

    fn foe_send(&mut self, h: FoeHeader, data: &[u8]) {
        let mut b = [0u8; M];
        if let Ok(n) = FoeRef::write(&h, data, &mut b) {
            self.queue_reply(MailboxType::Foe, &b[..n]);
        }
    }

    fn foe_fail<A: Application<N>>(&mut self, app: &mut A, f: FoeFault) {
        self.foe_reset(app);
        let cap = self.reply_capacity() - FOE_HEADER_LEN;
        let text = f.text.as_bytes();
        let text = &text[..text.len().min(cap)];
        self.foe_send(FoeHeader::Error { code: f.code }, text);
    }

    fn foe_illegal<A: Application<N>>(&mut self, app: &mut A) {
        self.foe_fail(app, FoeFault::new(FoeErrorCode::Illegal));
    }

    /// One FoE request (`p` = FoE header + data).
    // Not inlined, as `coe_request`.
    #[inline(never)]
    pub(crate) fn foe_request<A: Application<N>>(&mut self, app: &mut A, p: &[u8]) {
        if app.foe().is_none() {
            self.mbx_error(MailboxErrorDetail::UnsupportedProtocol);
            return;
        }
        if p.len() < FOE_HEADER_LEN {
            self.mbx_error(MailboxErrorDetail::SizeTooShort);
            return;
        }
        let Ok(req) = FoeRef::parse(p) else {
            // Unknown opcode.
            self.foe_fail(app, FoeFault::new(FoeErrorCode::NotDefined));
            return;
        };
        let boot = self.mbx.boot;
        match req.header {
            FoeHeader::Write { password } => {
                if self.foe != FoeState::Idle {
                    return self.foe_illegal(app);
                }
                let r = match app.foe() {
                    Some(f) => f.open_write(req.data, password, boot),
                    None => return,
                };
                match r {
                    Ok(()) => {
                        self.foe = FoeState::Writing {
                            next: 1,
                            offset: 0,
                            closing: false,
                        };
                        self.foe_send(FoeHeader::Ack { packet: 0 }, &[]);
                    }
                    Err(f) => self.foe_fail(app, f),
                }
            }
            FoeHeader::Read { password } => {
                if self.foe != FoeState::Idle {
                    return self.foe_illegal(app);
                }
                let r = match app.foe() {
                    Some(f) => f.open_read(req.data, password, boot),
                    None => return,
                };
                match r {
                    Ok(()) => self.foe_send_data(app, 1, 0),
                    Err(f) => self.foe_fail(app, f),
                }
            }
            FoeHeader::Data { packet } => self.foe_data(app, packet, req.data),
            FoeHeader::Ack { packet } => match self.foe {
                FoeState::Reading {
                    packet: sent,
                    offset,
                    len,
                } => {
                    if packet != sent {
                        return self.foe_fail(app, FoeFault::new(FoeErrorCode::PacketNumberWrong));
                    }
                    if (len as usize) < self.foe_tx_segment() {
                        // The short packet was the last: done.
                        self.foe = FoeState::Idle;
                    } else {
                        self.foe_send_data(app, sent.wrapping_add(1), offset + len);
                    }
                }
                _ => self.foe_illegal(app),
            },
            FoeHeader::Busy { .. } => match self.foe {
                FoeState::Reading { packet, offset, .. } => self.foe_send_data(app, packet, offset),
                _ => self.foe_illegal(app),
            },
            FoeHeader::Error { .. } => self.foe_reset(app),
        }
    }

    /// Reads and sends data packet `packet` from `offset`.
    fn foe_send_data<A: Application<N>>(&mut self, app: &mut A, packet: u32, offset: u32) {
        let seg = self.foe_tx_segment();
        let mut buf = [0u8; M];
        let r = match app.foe() {
            Some(f) => f.read(offset, &mut buf[..seg]),
            None => return,
        };
        match r {
            Ok(n) => {
                let n = n.min(seg);
                self.foe = FoeState::Reading {
                    packet,
                    offset,
                    len: n as u32,
                };
                self.foe_send(FoeHeader::Data { packet }, &buf[..n]);
            }
            Err(f) => self.foe_fail(app, f),
        }
    }

    fn foe_data<A: Application<N>>(&mut self, app: &mut A, packet: u32, data: &[u8]) {
        let FoeState::Writing {
            next,
            offset,
            closing,
        } = self.foe
        else {
            return self.foe_illegal(app);
        };
        if packet != next {
            return self.foe_fail(app, FoeFault::new(FoeErrorCode::PacketNumberWrong));
        }
        let seg = self.foe_rx_segment();
        if data.len() > seg {
            return self.foe_fail(app, FoeFault::new(FoeErrorCode::Illegal));
        }
        let last = data.len() < seg;
        let Some(f) = app.foe() else { return };
        if !closing && !data.is_empty() {
            match f.write(offset, data) {
                Ok(()) => {}
                Err(FoeError::Busy { done, entire }) => {
                    return self.foe_send(FoeHeader::Busy { done, entire }, &[]);
                }
                Err(FoeError::Fault(x)) => return self.foe_fail(app, x),
            }
        }
        let end = offset.saturating_add(data.len() as u32);
        if !last {
            self.foe = FoeState::Writing {
                next: next.wrapping_add(1),
                offset: end,
                closing: false,
            };
            return self.foe_send(FoeHeader::Ack { packet }, &[]);
        }
        // Last packet: its data is in; the file is checked and committed.
        self.foe = FoeState::Writing {
            next,
            offset,
            closing: true,
        };
        let Some(f) = app.foe() else { return };
        match f.close_write(end) {
            Ok(()) => {
                self.foe = FoeState::Idle;
                self.foe_send(FoeHeader::Ack { packet }, &[]);
            }
            Err(FoeError::Busy { done, entire }) => {
                self.foe_send(FoeHeader::Busy { done, entire }, &[])
            }
            Err(FoeError::Fault(x)) => self.foe_fail(app, x),
        }
    }
}

// ---------------------------------------------------------------------- firmware images

/// Length of the image header.
pub const IMAGE_HEADER_LEN: usize = 32;
/// Image magic, `"OXFW"`.
pub const IMAGE_MAGIC: [u8; 4] = *b"OXFW";
/// The header version this stack writes and reads.
pub const IMAGE_HEADER_VERSION: u16 = 1;

/// The header in front of a firmware image (format in the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImageHeader {
    /// Vendor id the image is for.
    pub vendor_id: u32,
    /// Product code the image is for.
    pub product_code: u32,
    /// Revision of the firmware in the image.
    pub revision: u32,
    /// Payload length in bytes.
    pub length: u32,
    /// CRC-32 of the payload.
    pub crc: u32,
}

/// Why bytes are not an image header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageError {
    /// Fewer than [`IMAGE_HEADER_LEN`] bytes.
    Short,
    /// Wrong magic.
    Magic,
    /// Unknown header version or length.
    Version,
}

impl ImageHeader {
    /// The header for `payload` on device `id`.
    pub fn for_payload(id: &Identity, payload: &[u8]) -> Self {
        Self {
            vendor_id: id.vendor_id,
            product_code: id.product_code,
            revision: id.revision,
            length: payload.len() as u32,
            crc: crc32(payload),
        }
    }

    /// Parses the header from the start of `b`.
    pub fn parse(b: &[u8]) -> Result<Self, ImageError> {
        if b.len() < IMAGE_HEADER_LEN {
            return Err(ImageError::Short);
        }
        if b[0..4] != IMAGE_MAGIC {
            return Err(ImageError::Magic);
        }
        let u16_at = |i: usize| u16::from_le_bytes([b[i], b[i + 1]]);
        let u32_at = |i: usize| u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
        if u16_at(4) != IMAGE_HEADER_VERSION || u16_at(6) as usize != IMAGE_HEADER_LEN {
            return Err(ImageError::Version);
        }
        Ok(Self {
            vendor_id: u32_at(8),
            product_code: u32_at(12),
            revision: u32_at(16),
            length: u32_at(20),
            crc: u32_at(24),
        })
    }

    /// The 32 header bytes.
    pub fn to_bytes(&self) -> [u8; IMAGE_HEADER_LEN] {
        let mut b = [0u8; IMAGE_HEADER_LEN];
        b[0..4].copy_from_slice(&IMAGE_MAGIC);
        b[4..6].copy_from_slice(&IMAGE_HEADER_VERSION.to_le_bytes());
        b[6..8].copy_from_slice(&(IMAGE_HEADER_LEN as u16).to_le_bytes());
        b[8..12].copy_from_slice(&self.vendor_id.to_le_bytes());
        b[12..16].copy_from_slice(&self.product_code.to_le_bytes());
        b[16..20].copy_from_slice(&self.revision.to_le_bytes());
        b[20..24].copy_from_slice(&self.length.to_le_bytes());
        b[24..28].copy_from_slice(&self.crc.to_le_bytes());
        b
    }

    /// True when the image is for device `id` (vendor, product, revision major).
    pub fn fits(&self, id: &Identity) -> bool {
        self.vendor_id == id.vendor_id
            && self.product_code == id.product_code
            && self.revision >> 16 == id.revision >> 16
    }
}

pub use oxicat_wire::crc::{crc32, crc32_update};

// ---------------------------------------------------------------------- firmware store

/// Why a store operation did not complete.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StoreError {
    /// The flash is busy (erase or programming running): call again.
    Busy {
        /// Progress done.
        done: u16,
        /// Progress total.
        entire: u16,
    },
    /// Offset or slot outside the store.
    OutOfRange,
    /// The flash reported an error.
    Failed,
}

/// Firmware slots in the application's flash: what the update flow needs from it.
pub trait FirmwareStore {
    /// Number of slots (at least 2 for an update that keeps the running firmware).
    fn slots(&self) -> u8;
    /// Bytes per slot (header + payload).
    fn capacity(&self) -> u32;
    /// Erases `slot`; [`StoreError::Busy`] until the erase is done (call again).
    fn erase(&mut self, slot: u8) -> Result<(), StoreError>;
    /// Programs `data` at `offset` of an erased `slot`.
    fn write(&mut self, slot: u8, offset: u32, data: &[u8]) -> Result<(), StoreError>;
    /// Reads `buf.len()` bytes at `offset` of `slot`.
    fn read(&mut self, slot: u8, offset: u32, buf: &mut [u8]) -> Result<(), StoreError>;
    /// Makes `slot` the one the boot loader starts (the previous one stays as it is).
    fn mark_bootable(&mut self, slot: u8) -> Result<(), StoreError>;
    /// The slot the boot loader starts, if any.
    fn bootable(&self) -> Option<u8>;

    /// The header of the current (bootable) image: the identity the device reports.
    fn current_image(&mut self) -> Option<ImageHeader> {
        let s = self.bootable()?;
        let mut b = [0u8; IMAGE_HEADER_LEN];
        self.read(s, 0, &mut b).ok()?;
        ImageHeader::parse(&b).ok()
    }
}

/// An in-memory [`FirmwareStore`]: `S` slots of `C` bytes, no allocation. Erase can be made
/// to report busy a number of times (a slow flash), and a slot can be made to fail.
#[derive(Debug, Clone)]
pub struct RamStore<const S: usize, const C: usize> {
    slots: [[u8; C]; S],
    erased: [bool; S],
    bootable: Option<u8>,
    /// Each erase reports [`StoreError::Busy`] this many times before it completes.
    pub erase_busy: u16,
    busy_left: Option<(u8, u16)>,
    /// Writes fail with [`StoreError::Failed`] (a broken flash).
    pub fail_writes: bool,
}

impl<const S: usize, const C: usize> Default for RamStore<S, C> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const S: usize, const C: usize> RamStore<S, C> {
    /// An empty store: every slot erased (0xFF), none bootable.
    pub const fn new() -> Self {
        Self {
            slots: [[0xFF; C]; S],
            erased: [true; S],
            bootable: None,
            erase_busy: 0,
            busy_left: None,
            fail_writes: false,
        }
    }

    /// A store with `image` (header + payload) installed in slot 0 and bootable (the
    /// factory image); false if it does not fit.
    pub fn with_image(image: &[u8]) -> Option<Self> {
        let mut s = Self::new();
        if S == 0 || image.len() > C {
            return None;
        }
        s.slots[0][..image.len()].copy_from_slice(image);
        s.erased[0] = false;
        s.bootable = Some(0);
        Some(s)
    }

    /// The bytes of `slot`.
    pub fn slot(&self, slot: u8) -> Option<&[u8; C]> {
        self.slots.get(slot as usize)
    }
}

impl<const S: usize, const C: usize> FirmwareStore for RamStore<S, C> {
    fn slots(&self) -> u8 {
        S as u8
    }

    fn capacity(&self) -> u32 {
        C as u32
    }

    fn erase(&mut self, slot: u8) -> Result<(), StoreError> {
        let i = slot as usize;
        if i >= S {
            return Err(StoreError::OutOfRange);
        }
        if self.erase_busy > 0 {
            let left = match self.busy_left {
                Some((s, n)) if s == slot => n,
                _ => self.erase_busy,
            };
            if left > 0 {
                self.busy_left = Some((slot, left - 1));
                return Err(StoreError::Busy {
                    done: self.erase_busy - left,
                    entire: self.erase_busy,
                });
            }
            self.busy_left = None;
        }
        self.slots[i] = [0xFF; C];
        self.erased[i] = true;
        Ok(())
    }

    fn write(&mut self, slot: u8, offset: u32, data: &[u8]) -> Result<(), StoreError> {
        let i = slot as usize;
        let o = offset as usize;
        if i >= S || o.checked_add(data.len()).is_none_or(|e| e > C) {
            return Err(StoreError::OutOfRange);
        }
        if self.fail_writes {
            return Err(StoreError::Failed);
        }
        // Flash programming only clears bits.
        for (d, s) in self.slots[i][o..o + data.len()].iter_mut().zip(data) {
            *d &= *s;
        }
        self.erased[i] = false;
        Ok(())
    }

    fn read(&mut self, slot: u8, offset: u32, buf: &mut [u8]) -> Result<(), StoreError> {
        let i = slot as usize;
        let o = offset as usize;
        if i >= S || o.checked_add(buf.len()).is_none_or(|e| e > C) {
            return Err(StoreError::OutOfRange);
        }
        buf.copy_from_slice(&self.slots[i][o..o + buf.len()]);
        Ok(())
    }

    fn mark_bootable(&mut self, slot: u8) -> Result<(), StoreError> {
        if slot as usize >= S {
            return Err(StoreError::OutOfRange);
        }
        self.bootable = Some(slot);
        Ok(())
    }

    fn bootable(&self) -> Option<u8> {
        self.bootable
    }
}

// ---------------------------------------------------------------------- update flow

/// Configuration of the update flow.
#[derive(Debug, Clone, Copy)]
pub struct UpdateConfig {
    /// The device's identity (images must fit it).
    pub identity: Identity,
    /// Name of the firmware file (e.g. `"firmware.bin"`).
    pub file_name: &'static str,
    /// Password for the firmware file; 0 = none.
    pub password: u32,
    /// The firmware file may be read back in BOOT.
    pub read_back: bool,
}

/// Name of the read-only version file.
pub const VERSION_FILE: &str = "version.txt";

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Open {
    None,
    /// Receiving an image into `slot`.
    Image {
        slot: u8,
        erased: bool,
        header: Option<ImageHeader>,
    },
    /// Sending the bootable image.
    ReadImage {
        slot: u8,
        len: u32,
    },
    /// Sending the version text (rendered into `text`).
    Version {
        len: usize,
    },
}

/// Outcome of the last finished update, for the application and tests.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UpdateResult {
    /// The image was verified and its slot marked bootable.
    Installed(ImageHeader),
    /// The image was rejected with this FoE code; nothing changed.
    Rejected(FoeErrorCode),
    /// The transfer was interrupted; nothing changed.
    Aborted,
}

/// The firmware update flow on a [`FirmwareStore`]: implements [`FoeFiles`] (see the module
/// documentation for the files, the checks and the error codes).
#[derive(Debug)]
pub struct FirmwareUpdate<S: FirmwareStore> {
    /// The store.
    pub store: S,
    cfg: UpdateConfig,
    open: Open,
    text: [u8; 160],
    /// The outcome of the last write of the firmware file.
    pub last: Option<UpdateResult>,
}

const VERSION_TEXT_MAX: usize = 160;

impl<S: FirmwareStore> FirmwareUpdate<S> {
    /// The flow on `store`.
    pub const fn new(store: S, cfg: UpdateConfig) -> Self {
        Self {
            store,
            cfg,
            open: Open::None,
            text: [0; VERSION_TEXT_MAX],
            last: None,
        }
    }

    /// The current (bootable) image's header.
    pub fn current(&mut self) -> Option<ImageHeader> {
        self.store.current_image()
    }

    fn check_password(&self, password: u32) -> Result<(), FoeFault> {
        match (self.cfg.password, password) {
            (0, _) => Ok(()),
            (_, 0) => Err(FoeFault::new(FoeErrorCode::NoUser)),
            (p, q) if p == q => Ok(()),
            _ => Err(FoeFault::new(FoeErrorCode::NoRights)),
        }
    }

    fn is_firmware(&self, name: &[u8]) -> bool {
        name == self.cfg.file_name.as_bytes()
    }

    fn reject(&mut self, f: FoeFault) -> FoeError {
        if matches!(self.open, Open::Image { .. }) {
            self.last = Some(UpdateResult::Rejected(f.code));
        }
        self.open = Open::None;
        FoeError::Fault(f)
    }

    /// Writes `version.txt` into `self.text` (by hand, not with `core::fmt`: the formatting
    /// machinery would be most of the FoE code in a board image).
    fn render_version(&mut self) -> usize {
        let mut w = TextBuf {
            buf: &mut self.text,
            len: 0,
        };
        match self.store.current_image() {
            Some(h) => {
                w.hex("vendor_id=0x", h.vendor_id);
                w.hex("product_code=0x", h.product_code);
                w.hex("revision=0x", h.revision);
                w.str("length=");
                w.dec(h.length);
                w.str("\n");
                w.hex("crc32=0x", h.crc);
            }
            None => w.str("no image\n"),
        }
        w.len
    }

    /// Verifies the image in `slot` against `h` by reading it back.
    fn verify(&mut self, slot: u8, h: &ImageHeader, received: u32) -> Result<(), FoeFault> {
        let prog = |t| FoeFault::with_text(FoeErrorCode::ProgramError, t);
        let total = IMAGE_HEADER_LEN as u32 + h.length;
        if received < total {
            return Err(prog("image truncated"));
        }
        if received > total {
            return Err(prog("image longer than its header says"));
        }
        let mut crc = 0;
        let mut off = IMAGE_HEADER_LEN as u32;
        let mut buf = [0u8; 64];
        while off < total {
            let n = ((total - off) as usize).min(buf.len());
            self.store
                .read(slot, off, &mut buf[..n])
                .map_err(|_| prog("flash read error"))?;
            crc = crc32_update(crc, &buf[..n]);
            off += n as u32;
        }
        if crc != h.crc {
            return Err(FoeFault::with_text(
                FoeErrorCode::ChecksumError,
                "image CRC-32 mismatch",
            ));
        }
        Ok(())
    }
}

struct TextBuf<'a> {
    buf: &'a mut [u8],
    len: usize,
}

impl TextBuf<'_> {
    /// Appends `s` (nothing once the buffer is full).
    fn str(&mut self, s: &str) {
        self.bytes(s.as_bytes());
    }

    /// Appends the ASCII bytes `b` (nothing once the buffer is full): the digits go in as
    /// bytes, so the image needs no UTF-8 validation (`core::str::from_utf8`, 368 B).
    fn bytes(&mut self, b: &[u8]) {
        let end = self.len + b.len();
        if let Some(d) = self.buf.get_mut(self.len..end) {
            d.copy_from_slice(b);
            self.len = end;
        }
    }

    /// Appends `label`, `v` as 8 upper-case hex digits and a newline.
    fn hex(&mut self, label: &str, v: u32) {
        self.str(label);
        let mut d = [0u8; 9];
        for (k, x) in d[..8].iter_mut().enumerate() {
            let n = (v >> (28 - 4 * k)) & 0xF;
            *x = b"0123456789ABCDEF"[n as usize];
        }
        d[8] = b'\n';
        self.bytes(&d);
    }

    /// Appends `v` in decimal.
    fn dec(&mut self, mut v: u32) {
        let mut d = [0u8; 10];
        let mut i = d.len();
        loop {
            i -= 1;
            d[i] = b'0' + (v % 10) as u8;
            v /= 10;
            if v == 0 {
                break;
            }
        }
        self.bytes(&d[i..]);
    }
}

fn store_fault(e: StoreError) -> FoeError {
    match e {
        StoreError::Busy { done, entire } => FoeError::Busy { done, entire },
        StoreError::OutOfRange => FoeFault::new(FoeErrorCode::DiskFull).into(),
        StoreError::Failed => {
            FoeFault::with_text(FoeErrorCode::ProgramError, "flash programming failed").into()
        }
    }
}

impl<S: FirmwareStore> FoeFiles for FirmwareUpdate<S> {
    fn open_read(&mut self, name: &[u8], password: u32, boot: bool) -> Result<(), FoeFault> {
        self.open = Open::None;
        if name == VERSION_FILE.as_bytes() {
            let len = self.render_version();
            self.open = Open::Version { len };
            return Ok(());
        }
        if self.is_firmware(name) {
            if !boot {
                return Err(FoeFault::new(FoeErrorCode::BootstrapOnly));
            }
            self.check_password(password)?;
            if !self.cfg.read_back {
                return Err(FoeFault::new(FoeErrorCode::AccessDenied));
            }
            let slot = self.store.bootable();
            let h = self.store.current_image();
            return match (slot, h) {
                (Some(slot), Some(h)) => {
                    self.open = Open::ReadImage {
                        slot,
                        len: IMAGE_HEADER_LEN as u32 + h.length,
                    };
                    Ok(())
                }
                _ => Err(FoeFault::new(FoeErrorCode::NotFound)),
            };
        }
        if boot {
            Err(FoeFault::new(FoeErrorCode::NotBootstrap))
        } else {
            Err(FoeFault::new(FoeErrorCode::NotFound))
        }
    }

    fn read(&mut self, offset: u32, buf: &mut [u8]) -> Result<usize, FoeFault> {
        match self.open {
            Open::Version { len } => {
                let o = (offset as usize).min(len);
                let n = (len - o).min(buf.len());
                buf[..n].copy_from_slice(&self.text[o..o + n]);
                Ok(n)
            }
            Open::ReadImage { slot, len } => {
                let o = offset.min(len);
                let n = ((len - o) as usize).min(buf.len());
                self.store.read(slot, o, &mut buf[..n]).map_err(|_| {
                    FoeFault::with_text(FoeErrorCode::ProgramError, "flash read error")
                })?;
                Ok(n)
            }
            _ => Err(FoeFault::new(FoeErrorCode::Illegal)),
        }
    }

    fn open_write(&mut self, name: &[u8], password: u32, boot: bool) -> Result<(), FoeFault> {
        self.open = Open::None;
        if name == VERSION_FILE.as_bytes() {
            return Err(FoeFault::new(FoeErrorCode::AccessDenied));
        }
        if !self.is_firmware(name) {
            return Err(FoeFault::new(if boot {
                FoeErrorCode::NotBootstrap
            } else {
                FoeErrorCode::NotFound
            }));
        }
        if !boot {
            return Err(FoeFault::new(FoeErrorCode::BootstrapOnly));
        }
        self.check_password(password)?;
        // The target: the first slot that is not the bootable one.
        let bootable = self.store.bootable();
        let Some(slot) = (0..self.store.slots()).find(|s| Some(*s) != bootable) else {
            return Err(FoeFault::with_text(
                FoeErrorCode::DiskFull,
                "no free firmware slot",
            ));
        };
        self.open = Open::Image {
            slot,
            erased: false,
            header: None,
        };
        Ok(())
    }

    fn write(&mut self, offset: u32, data: &[u8]) -> Result<(), FoeError> {
        let Open::Image {
            slot,
            erased,
            header,
        } = self.open
        else {
            return Err(FoeFault::new(FoeErrorCode::Illegal).into());
        };
        let mut header = header;
        if header.is_none() {
            // The header must come whole in the first packet (every mailbox of >= 44 bytes
            // carries 32 data bytes).
            if offset != 0 {
                return Err(self.reject(FoeFault::new(FoeErrorCode::Illegal)));
            }
            let h = match ImageHeader::parse(data) {
                Ok(h) => h,
                Err(ImageError::Short) => {
                    return Err(self.reject(FoeFault::with_text(
                        FoeErrorCode::ProgramError,
                        "image truncated",
                    )))
                }
                Err(_) => {
                    return Err(self.reject(FoeFault::with_text(
                        FoeErrorCode::ProgramError,
                        "not a firmware image",
                    )))
                }
            };
            if !h.fits(&self.cfg.identity) {
                return Err(self.reject(FoeFault::with_text(
                    FoeErrorCode::ProgramError,
                    "image for another device",
                )));
            }
            if IMAGE_HEADER_LEN as u64 + h.length as u64 > self.store.capacity() as u64 {
                return Err(self.reject(FoeFault::with_text(
                    FoeErrorCode::DiskFull,
                    "image larger than a firmware slot",
                )));
            }
            if self.store.current_image() == Some(h) {
                return Err(self.reject(FoeFault::new(FoeErrorCode::AlreadyExists)));
            }
            header = Some(h);
        }
        if !erased {
            if let Err(e) = self.store.erase(slot) {
                // Keep the parsed header: the client sends this packet again.
                self.open = Open::Image {
                    slot,
                    erased: false,
                    header,
                };
                return match store_fault(e) {
                    b @ FoeError::Busy { .. } => Err(b),
                    FoeError::Fault(f) => Err(self.reject(f)),
                };
            }
        }
        self.open = Open::Image {
            slot,
            erased: true,
            header,
        };
        if offset as u64 + data.len() as u64 > self.store.capacity() as u64 {
            return Err(self.reject(FoeFault::with_text(
                FoeErrorCode::DiskFull,
                "image larger than a firmware slot",
            )));
        }
        match self.store.write(slot, offset, data) {
            Ok(()) => Ok(()),
            Err(e) => match store_fault(e) {
                b @ FoeError::Busy { .. } => Err(b),
                FoeError::Fault(f) => Err(self.reject(f)),
            },
        }
    }

    fn close_write(&mut self, len: u32) -> Result<(), FoeError> {
        let Open::Image { slot, header, .. } = self.open else {
            return Err(FoeFault::new(FoeErrorCode::Illegal).into());
        };
        let Some(h) = header else {
            return Err(self.reject(FoeFault::with_text(
                FoeErrorCode::ProgramError,
                "image truncated",
            )));
        };
        if let Err(f) = self.verify(slot, &h, len) {
            return Err(self.reject(f));
        }
        if let Err(e) = self.store.mark_bootable(slot) {
            return match store_fault(e) {
                b @ FoeError::Busy { .. } => Err(b),
                FoeError::Fault(f) => Err(self.reject(f)),
            };
        }
        self.open = Open::None;
        self.last = Some(UpdateResult::Installed(h));
        Ok(())
    }

    fn abort(&mut self) {
        if matches!(self.open, Open::Image { .. }) {
            self.last = Some(UpdateResult::Aborted);
        }
        self.open = Open::None;
    }
}

/// An application with FoE: `app`'s hooks plus `files` as its FoE server (e.g. a
/// [`FirmwareUpdate`] next to a device application that knows nothing of FoE).
#[derive(Debug)]
pub struct WithFoe<A, F> {
    /// The application.
    pub app: A,
    /// The files.
    pub files: F,
}

/// The application's fields and methods through the wrapper (a bench reaches its board
/// as `image.app.board` with or without FoE).
impl<A, F> core::ops::Deref for WithFoe<A, F> {
    type Target = A;
    fn deref(&self) -> &A {
        &self.app
    }
}

impl<A, F> core::ops::DerefMut for WithFoe<A, F> {
    fn deref_mut(&mut self) -> &mut A {
        &mut self.app
    }
}

impl<const N: usize, A: Application<N>, F: FoeFiles> Application<N> for WithFoe<A, F> {
    fn state_change(
        &mut self,
        from: crate::AlState,
        to: crate::AlState,
        od: &mut crate::Od<N>,
    ) -> Result<(), crate::AlStatusCode> {
        self.app.state_change(from, to, od)
    }
    fn safe_outputs(&mut self, od: &mut crate::Od<N>) {
        self.app.safe_outputs(od)
    }
    fn cycle(&mut self, od: &mut crate::Od<N>) {
        self.app.cycle(od)
    }
    fn timer(&mut self, id: u8, od: &mut crate::Od<N>) {
        self.app.timer(id, od)
    }
    fn sdo_written(&mut self, index: u16, sub: u8, od: &mut crate::Od<N>) {
        self.app.sdo_written(index, sub, od)
    }
    fn foe(&mut self) -> Option<&mut dyn FoeFiles> {
        Some(&mut self.files)
    }
    fn next_emergency(&mut self) -> Option<(u16, u8, [u8; 5])> {
        self.app.next_emergency()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32_check_value() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32_update(crc32(b"1234"), b"56789"), 0xCBF4_3926);
    }

    #[test]
    fn header_round_trip() {
        let id = Identity {
            vendor_id: 1,
            product_code: 2,
            revision: 0x0003_0004,
            serial: 0,
        };
        let h = ImageHeader::for_payload(&id, b"abc");
        assert_eq!(ImageHeader::parse(&h.to_bytes()), Ok(h));
        assert!(h.fits(&id));
        assert_eq!(ImageHeader::parse(&[0; 31]), Err(ImageError::Short));
        assert_eq!(ImageHeader::parse(&[0; 32]), Err(ImageError::Magic));
    }

    extern crate std;
    use std::format;

    /// `version.txt` is written by hand (no `core::fmt` in board images): its bytes are
    /// the ones `format!` gives for the same fields, extremes included.
    #[test]
    fn version_text_is_the_formatted_text() {
        let cfg = |identity| UpdateConfig {
            identity,
            file_name: "firmware.bin",
            password: 0,
            read_back: true,
        };
        for (id, payload) in [
            (
                Identity {
                    vendor_id: 0xE000_0000,
                    product_code: 0x1111_0141,
                    revision: 0x0001_0002,
                    serial: 0,
                },
                &b"oxicat demo firmware 0.1.0"[..],
            ),
            (
                Identity {
                    vendor_id: 0,
                    product_code: u32::MAX,
                    revision: 0xA,
                    serial: 0,
                },
                &[][..],
            ),
        ] {
            let h = ImageHeader::for_payload(&id, payload);
            let mut img = h.to_bytes().to_vec();
            img.extend_from_slice(payload);
            let mut fw =
                FirmwareUpdate::new(RamStore::<2, 256>::with_image(&img).unwrap(), cfg(id));
            let n = fw.render_version();
            let want = format!(
                "vendor_id=0x{:08X}\nproduct_code=0x{:08X}\nrevision=0x{:08X}\nlength={}\ncrc32=0x{:08X}\n",
                h.vendor_id, h.product_code, h.revision, h.length, h.crc
            );
            assert_eq!(&fw.text[..n], want.as_bytes());
        }
        let mut empty = FirmwareUpdate::new(
            RamStore::<2, 256>::new(),
            cfg(Identity {
                vendor_id: 1,
                product_code: 2,
                revision: 3,
                serial: 0,
            }),
        );
        let n = empty.render_version();
        assert_eq!(&empty.text[..n], b"no image\n");
    }

    #[test]
    fn decimal_digits() {
        let mut buf = [0u8; 32];
        for v in [0u32, 7, 10, 99, 100, 12345, u32::MAX] {
            let mut w = TextBuf {
                buf: &mut buf,
                len: 0,
            };
            w.dec(v);
            let n = w.len;
            assert_eq!(&buf[..n], format!("{v}").as_bytes());
        }
    }
}
