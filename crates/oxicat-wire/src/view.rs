//! Zero-copy views: typed field accessors over the frame's own bytes, in the manner of
//! smoltcp's `wire` (a `Datagram<T: AsRef<[u8]>>` reads and writes its fields in place;
//! nothing is copied into a struct). The ESC's per-frame paths use these, so there is one
//! frame walker and one byte layout in the workspace; [`crate::DatagramHeader`] (a decoded
//! copy) stays for code that builds or keeps headers.
//!
//! `new_unchecked` views trust the caller about the length (accessors then panic on a
//! short buffer, as slice indexing does); `new_checked` checks it once so that every
//! accessor is in bounds.

use crate::datagram::{Command, DATAGRAM_HEADER_LEN, WKC_LEN};
use crate::error::WireError;
use crate::frame::{FrameType, ECAT_HEADER_LEN};

/// Byte positions of the fields.
pub mod field {
    use core::ops::Range;

    /// EtherCAT frame header word (length, reserved bit, type), from the frame's start.
    pub const ECAT_WORD: Range<usize> = 0..2;

    /// Datagram command byte, from the datagram's start.
    pub const CMD: usize = 0;
    /// Datagram index byte.
    pub const IDX: usize = 1;
    /// Datagram address (ADP low half, ADO high half, or logical address).
    pub const ADDR: Range<usize> = 2..6;
    /// Datagram length word (11-bit length, reserved, circulating, more-follows).
    pub const LEN: Range<usize> = 6..8;
    /// Datagram IRQ field.
    pub const IRQ: Range<usize> = 8..10;
    /// First data byte.
    pub const DATA: usize = 10;

    /// The working counter of a datagram with `data_len` data bytes.
    pub const fn wkc(data_len: usize) -> Range<usize> {
        DATA + data_len..DATA + data_len + 2
    }

    /// Length-word bit: the frame circulated once.
    pub const CIRCULATING: u16 = 0x4000;
    /// Length-word bit: another datagram follows.
    pub const MORE_FOLLOWS: u16 = 0x8000;
    /// Length-word mask of the data length.
    pub const LEN_MASK: u16 = 0x07FF;
}

/// The little-endian word at `r` (one bounds check, one load).
#[inline(always)]
fn word(b: &[u8], r: core::ops::Range<usize>) -> u16 {
    let a: [u8; 2] = b[r.start..r.start + 2].try_into().unwrap_or([0; 2]);
    u16::from_le_bytes(a)
}

#[inline(always)]
fn set_word(b: &mut [u8], at: usize, v: u16) {
    b[at..at + 2].copy_from_slice(&v.to_le_bytes());
}

/// A view of an EtherCAT frame starting at its 2-byte header (after Ethernet or UDP).
#[derive(Debug, Clone, Copy)]
pub struct Frame<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> Frame<T> {
    /// A view without checks.
    #[inline(always)]
    pub const fn new_unchecked(buffer: T) -> Self {
        Self { buffer }
    }

    /// A view whose header is present and whose declared length fits in the buffer.
    #[inline]
    pub fn new_checked(buffer: T) -> Result<Self, WireError> {
        let f = Self::new_unchecked(buffer);
        let b = f.buffer.as_ref();
        if b.len() < ECAT_HEADER_LEN {
            return Err(WireError::Truncated {
                needed: ECAT_HEADER_LEN,
                available: b.len(),
            });
        }
        let end = ECAT_HEADER_LEN + f.length();
        if b.len() < end {
            return Err(WireError::LengthMismatch {
                declared: f.length(),
                available: b.len() - ECAT_HEADER_LEN,
            });
        }
        Ok(f)
    }

    /// The header word.
    #[inline(always)]
    pub fn header_word(&self) -> u16 {
        word(self.buffer.as_ref(), field::ECAT_WORD)
    }

    /// Declared length of the datagrams (bytes after the header).
    #[inline(always)]
    pub fn length(&self) -> usize {
        (self.header_word() & field::LEN_MASK) as usize
    }

    /// The 4-bit protocol type.
    #[inline(always)]
    pub fn frame_type(&self) -> FrameType {
        FrameType::from_u8((self.header_word() >> 12) as u8)
    }

    /// True for a frame of datagrams (type 1).
    #[inline(always)]
    pub fn is_datagrams(&self) -> bool {
        self.header_word() >> 12 == FrameType::Datagrams.code() as u16
    }

    /// Byte index, in the buffer, where the declared datagrams end.
    #[inline(always)]
    pub fn end(&self) -> usize {
        ECAT_HEADER_LEN + self.length()
    }

    /// The underlying buffer.
    #[inline(always)]
    pub fn into_inner(self) -> T {
        self.buffer
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> Frame<T> {
    /// The declared datagram bytes (checked views only: `new_checked` made them fit).
    #[inline(always)]
    pub fn payload_mut(&mut self) -> &mut [u8] {
        let end = self.end();
        &mut self.buffer.as_mut()[ECAT_HEADER_LEN..end]
    }
}

/// A view of one datagram: header, data and working counter, in place.
#[derive(Debug, Clone, Copy)]
pub struct Datagram<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> Datagram<T> {
    /// A view without checks.
    #[inline(always)]
    pub const fn new_unchecked(buffer: T) -> Self {
        Self { buffer }
    }

    /// A view whose header, data and working counter all lie in the buffer.
    #[inline]
    pub fn new_checked(buffer: T) -> Result<Self, WireError> {
        let d = Self::new_unchecked(buffer);
        let have = d.buffer.as_ref().len();
        if have < DATAGRAM_HEADER_LEN {
            return Err(WireError::Truncated {
                needed: DATAGRAM_HEADER_LEN,
                available: have,
            });
        }
        if have < d.total_len() {
            return Err(WireError::LengthMismatch {
                declared: d.total_len(),
                available: have,
            });
        }
        Ok(d)
    }

    /// The raw command byte (reserved codes included).
    #[inline(always)]
    pub fn command_raw(&self) -> u8 {
        self.buffer.as_ref()[field::CMD]
    }

    /// The decoded command, `None` for a reserved code.
    #[inline(always)]
    pub fn command(&self) -> Option<Command> {
        Command::from_u8(self.command_raw())
    }

    /// The index byte.
    #[inline(always)]
    pub fn index(&self) -> u8 {
        self.buffer.as_ref()[field::IDX]
    }

    /// The 32-bit address.
    #[inline(always)]
    pub fn address(&self) -> u32 {
        let a: [u8; 4] = self.buffer.as_ref()[field::ADDR]
            .try_into()
            .unwrap_or([0; 4]);
        u32::from_le_bytes(a)
    }

    /// Position or configured station address (low half of the address).
    #[inline(always)]
    pub fn adp(&self) -> u16 {
        self.address() as u16
    }

    /// Offset in the slave's memory (high half of the address).
    #[inline(always)]
    pub fn ado(&self) -> u16 {
        (self.address() >> 16) as u16
    }

    /// The length word as on the wire.
    #[inline(always)]
    pub fn len_flags(&self) -> u16 {
        word(self.buffer.as_ref(), field::LEN)
    }

    /// Data length in bytes.
    #[inline(always)]
    pub fn data_len(&self) -> usize {
        (self.len_flags() & field::LEN_MASK) as usize
    }

    /// The more-follows bit.
    #[inline(always)]
    pub fn more_follows(&self) -> bool {
        self.len_flags() & field::MORE_FOLLOWS != 0
    }

    /// The circulating bit.
    #[inline(always)]
    pub fn circulating(&self) -> bool {
        self.len_flags() & field::CIRCULATING != 0
    }

    /// The IRQ field.
    #[inline(always)]
    pub fn irq(&self) -> u16 {
        word(self.buffer.as_ref(), field::IRQ)
    }

    /// Bytes of the whole datagram: header, data and working counter.
    #[inline(always)]
    pub fn total_len(&self) -> usize {
        DATAGRAM_HEADER_LEN + self.data_len() + WKC_LEN
    }

    /// The data.
    #[inline(always)]
    pub fn data(&self) -> &[u8] {
        &self.buffer.as_ref()[field::DATA..field::DATA + self.data_len()]
    }

    /// The working counter.
    #[inline(always)]
    pub fn wkc(&self) -> u16 {
        word(self.buffer.as_ref(), field::wkc(self.data_len()))
    }

    /// The underlying buffer.
    #[inline(always)]
    pub fn into_inner(self) -> T {
        self.buffer
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> Datagram<T> {
    /// Sets the IRQ field.
    #[inline(always)]
    pub fn set_irq(&mut self, v: u16) {
        set_word(self.buffer.as_mut(), field::IRQ.start, v);
    }

    /// ORs `bits` into the IRQ field (what every ESC does on the way), writing only when
    /// it changes something.
    #[inline(always)]
    pub fn or_irq(&mut self, bits: u16) {
        let irq = self.irq();
        if bits & !irq != 0 {
            self.set_irq(irq | bits);
        }
    }

    /// Sets the address.
    #[inline(always)]
    pub fn set_address(&mut self, v: u32) {
        self.buffer.as_mut()[field::ADDR].copy_from_slice(&v.to_le_bytes());
    }

    /// Sets the working counter.
    #[inline(always)]
    pub fn set_wkc(&mut self, v: u16) {
        let at = field::wkc(self.data_len()).start;
        set_word(self.buffer.as_mut(), at, v);
    }

    /// Adds `inc` to the working counter (wrapping, as the 16-bit counter does).
    #[inline(always)]
    pub fn add_wkc(&mut self, inc: u16) {
        if inc != 0 {
            let w = self.wkc().wrapping_add(inc);
            self.set_wkc(w);
        }
    }

    /// The data, writable.
    #[inline(always)]
    pub fn data_mut(&mut self) -> &mut [u8] {
        let n = self.data_len();
        &mut self.buffer.as_mut()[field::DATA..field::DATA + n]
    }
}

/// Calls `f` with a view of each datagram of the EtherCAT frame in `buf` (starting at the
/// EtherCAT header), following the more-follows bits. Returns the number of datagrams
/// visited, or the error that stopped the walk: not a datagram frame, a declared length
/// beyond the buffer, or a datagram that does not fit (datagrams before it were visited).
/// The one frame walker of the workspace: [`crate::frame::for_each_datagram_mut`] and the
/// ESC use it.
#[inline]
pub fn walk_datagrams<E: From<WireError>>(
    buf: &mut [u8],
    mut f: impl FnMut(Datagram<&mut [u8]>) -> Result<(), E>,
) -> Result<usize, E> {
    let mut frame = Frame::new_checked(buf)?;
    if !frame.is_datagrams() {
        return Err(WireError::UnknownType(frame.frame_type().code()).into());
    }
    let mut rest = frame.payload_mut();
    let mut n = 0;
    loop {
        let (more, total) = {
            let d = Datagram::new_checked(&*rest)?;
            (d.more_follows(), d.total_len())
        };
        let (dg, tail) = core::mem::take(&mut rest).split_at_mut(total);
        f(Datagram::new_unchecked(dg))?;
        n += 1;
        if !more {
            return Ok(n);
        }
        rest = tail;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::datagram::DatagramHeader;
    use crate::frame::FrameBuilder;

    fn two_datagram_frame() -> ([u8; 64], usize) {
        let mut buf = [0u8; 64];
        let mut b = FrameBuilder::new_bare(&mut buf).unwrap();
        b.push(
            DatagramHeader::logical(Command::Lrw, 7, 0x1000, 4),
            &[1, 2, 3, 4],
        )
        .unwrap();
        b.push(
            DatagramHeader::physical(Command::Fprd, 8, 0x1001, 0x0130, 2),
            &[0, 0],
        )
        .unwrap();
        let n = b.finish();
        (buf, n)
    }

    #[test]
    fn views_read_what_the_decoded_header_reads() {
        let (mut buf, n) = two_datagram_frame();
        type Seen = (Option<Command>, u16, u16, std::vec::Vec<u8>);
        let mut seen: [Option<Seen>; 2] = [None, None];
        let mut k = 0;
        let count = walk_datagrams::<WireError>(&mut buf[..n], |mut d| {
            let h = DatagramHeader::parse(d.buffer).unwrap();
            assert_eq!(d.command_raw(), h.command);
            assert_eq!(d.index(), h.index);
            assert_eq!(d.address(), h.address);
            assert_eq!(d.data_len(), h.len as usize);
            assert_eq!(d.more_follows(), h.more_follows);
            assert_eq!(d.irq(), h.irq);
            d.add_wkc(3);
            d.or_irq(0x0004);
            seen[k] = Some((d.command(), d.adp(), d.ado(), d.data().to_vec()));
            k += 1;
            Ok(())
        })
        .unwrap();
        assert_eq!(count, 2);
        assert_eq!(
            seen[0],
            Some((Some(Command::Lrw), 0x1000, 0, [1u8, 2, 3, 4].to_vec()))
        );
        assert_eq!(seen[1].as_ref().unwrap().1, 0x1001);
        assert_eq!(seen[1].as_ref().unwrap().2, 0x0130);
        // The writes landed in the frame: the decoding parser sees them.
        let f = crate::EcatFrame::parse(&buf[..n]).unwrap();
        for d in f.datagrams() {
            let d = d.unwrap();
            assert_eq!(d.wkc, 3);
            assert_eq!(d.header.irq, 0x0004);
        }
    }

    #[test]
    fn a_datagram_longer_than_the_frame_stops_the_walk_after_the_good_ones() {
        let (mut buf, n) = two_datagram_frame();
        // Second datagram claims 40 bytes of data.
        let second = ECAT_HEADER_LEN + DATAGRAM_HEADER_LEN + 4 + WKC_LEN;
        buf[second + 6] = 40;
        let mut visited = 0;
        let r = walk_datagrams::<WireError>(&mut buf[..n], |_| {
            visited += 1;
            Ok(())
        });
        assert!(matches!(r, Err(WireError::LengthMismatch { .. })), "{r:?}");
        assert_eq!(visited, 1);
        // A frame whose header declares more than the buffer holds: nothing visited.
        let (mut buf, n) = two_datagram_frame();
        buf[0] = 0xFF;
        buf[1] = 0x17;
        assert!(walk_datagrams::<WireError>(&mut buf[..n], |_| Ok(())).is_err());
        // Not a datagram frame.
        let (mut buf, n) = two_datagram_frame();
        buf[1] = (buf[1] & 0x0F) | 0x50;
        assert_eq!(
            walk_datagrams::<WireError>(&mut buf[..n], |_| Ok(())),
            Err(WireError::UnknownType(5))
        );
        assert!(Datagram::new_checked(&buf[..5]).is_err());
    }
}
