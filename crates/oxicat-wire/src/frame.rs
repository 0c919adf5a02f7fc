//! The EtherCAT frame: a 2-byte header followed by datagrams, and a builder for whole
//! Ethernet frames.

use crate::datagram::{
    DatagramHeader, DatagramMut, DatagramRef, DATAGRAM_HEADER_LEN, MAX_DATA_LEN, WKC_LEN,
};
use crate::error::{need, WireError};
use crate::ethernet::{EthernetHeader, ETHERNET_MIN_LEN};
use crate::udp::UdpEndpoints;

/// Length of the EtherCAT frame header.
pub const ECAT_HEADER_LEN: usize = 2;

/// The protocol type in the EtherCAT frame header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameType {
    /// EtherCAT datagrams (DLPDUs), type 1.
    Datagrams,
    /// Network variables, type 4.
    NetworkVariables,
    /// Mailbox gateway, type 5.
    Mailbox,
    /// A reserved type code.
    Reserved(u8),
}

impl FrameType {
    /// Decodes the 4-bit type.
    pub const fn from_u8(v: u8) -> Self {
        match v {
            1 => Self::Datagrams,
            4 => Self::NetworkVariables,
            5 => Self::Mailbox,
            o => Self::Reserved(o),
        }
    }

    /// The 4-bit code.
    pub const fn code(self) -> u8 {
        match self {
            Self::Datagrams => 1,
            Self::NetworkVariables => 4,
            Self::Mailbox => 5,
            Self::Reserved(o) => o & 0xF,
        }
    }
}

/// The EtherCAT frame header: 11-bit length of what follows, reserved bit, 4-bit type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EcatHeader {
    /// Length of the datagrams that follow, in bytes.
    pub len: u16,
    /// The reserved bit 11.
    pub reserved: bool,
    /// Protocol type.
    pub frame_type: FrameType,
}

impl EcatHeader {
    /// Parses the header from the first two bytes of `buf`.
    pub fn parse(buf: &[u8]) -> Result<Self, WireError> {
        need(buf, ECAT_HEADER_LEN)?;
        let w = u16::from_le_bytes([buf[0], buf[1]]);
        Ok(Self {
            len: w & 0x07FF,
            reserved: w & 0x0800 != 0,
            frame_type: FrameType::from_u8((w >> 12) as u8),
        })
    }

    /// The header as a little-endian word.
    pub const fn to_word(&self) -> u16 {
        (self.len & 0x07FF)
            | if self.reserved { 0x0800 } else { 0 }
            | ((self.frame_type.code() as u16) << 12)
    }
}

/// A view of an EtherCAT frame: the bytes starting at the EtherCAT header (after Ethernet
/// or UDP framing). The frame may carry trailing padding beyond the declared length.
#[derive(Debug, Clone, Copy)]
pub struct EcatFrame<'a> {
    /// The decoded header.
    pub header: EcatHeader,
    /// The datagram bytes (exactly `header.len` of them).
    pub body: &'a [u8],
}

impl<'a> EcatFrame<'a> {
    /// Parses the EtherCAT header at the start of `buf` and checks the declared length fits.
    pub fn parse(buf: &'a [u8]) -> Result<Self, WireError> {
        let header = EcatHeader::parse(buf)?;
        let end = ECAT_HEADER_LEN + header.len as usize;
        if buf.len() < end {
            return Err(WireError::LengthMismatch {
                declared: header.len as usize,
                available: buf.len() - ECAT_HEADER_LEN,
            });
        }
        Ok(Self {
            header,
            body: &buf[ECAT_HEADER_LEN..end],
        })
    }

    /// Parses an Ethernet frame carrying EtherCAT (a VLAN tag is tolerated).
    pub fn parse_ethernet(buf: &'a [u8]) -> Result<(EthernetHeader, Self), WireError> {
        let eth = EthernetHeader::parse(buf)?;
        Ok((eth, Self::parse(&buf[eth.payload_offset..])?))
    }

    /// Iterates the datagrams of a type-1 frame. Iteration follows the more-follows bits
    /// and stops with an error item at the first malformed datagram.
    pub fn datagrams(&self) -> Datagrams<'a> {
        Datagrams {
            rest: self.body,
            done: self.header.frame_type != FrameType::Datagrams,
        }
    }
}

/// Iterator over the datagrams of a frame; see [`EcatFrame::datagrams`].
#[derive(Debug, Clone)]
pub struct Datagrams<'a> {
    rest: &'a [u8],
    done: bool,
}

impl<'a> Iterator for Datagrams<'a> {
    type Item = Result<DatagramRef<'a>, WireError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        match DatagramRef::parse(self.rest) {
            Ok((dg, used)) => {
                self.rest = &self.rest[used..];
                self.done = !dg.header.more_follows;
                Some(Ok(dg))
            }
            Err(e) => {
                self.done = true;
                Some(Err(e))
            }
        }
    }
}

/// Calls `f` for each datagram of the EtherCAT frame in `buf` (starting at the EtherCAT
/// header), with mutable access to data and working counter and a decoded copy of the
/// header. Returns the number of datagrams visited, or the error that stopped the walk
/// (datagrams before it were visited). The walk is [`crate::view::walk_datagrams`]'s.
pub fn for_each_datagram_mut<E: From<WireError>>(
    buf: &mut [u8],
    mut f: impl FnMut(&mut DatagramMut<'_>) -> Result<(), E>,
) -> Result<usize, E> {
    crate::view::walk_datagrams(buf, |v| {
        let (mut dg, _) = DatagramMut::parse(v.into_inner())?;
        f(&mut dg)
    })
}

/// Builds an Ethernet frame with one or more datagrams, padded to the Ethernet minimum.
#[derive(Debug)]
pub struct FrameBuilder<'a> {
    buf: &'a mut [u8],
    ecat_offset: usize,
    len: usize,
    last_header: Option<usize>,
    udp: Option<UdpEndpoints>,
}

impl<'a> FrameBuilder<'a> {
    /// Starts an Ethernet frame in `buf` with the given Ethernet header.
    pub fn new(buf: &'a mut [u8], eth: &EthernetHeader) -> Result<Self, WireError> {
        let off = eth.write(buf)?;
        Self::start(buf, off)
    }

    /// Starts a bare EtherCAT frame (for EtherCAT over UDP): no Ethernet header.
    pub fn new_bare(buf: &'a mut [u8]) -> Result<Self, WireError> {
        Self::start(buf, 0)
    }

    /// Starts an EtherCAT-over-UDP frame: Ethernet, IPv4 and UDP headers are written by
    /// [`FrameBuilder::finish`] once the payload length is known.
    pub fn new_udp(buf: &'a mut [u8], endpoints: &UdpEndpoints) -> Result<Self, WireError> {
        let off = endpoints.payload_offset();
        let mut b = Self::start(buf, off)?;
        b.udp = Some(*endpoints);
        Ok(b)
    }

    fn start(buf: &'a mut [u8], ecat_offset: usize) -> Result<Self, WireError> {
        if buf.len() < ecat_offset + ECAT_HEADER_LEN {
            return Err(WireError::BufferFull);
        }
        Ok(Self {
            buf,
            ecat_offset,
            len: ecat_offset + ECAT_HEADER_LEN,
            last_header: None,
            udp: None,
        })
    }

    /// Appends a datagram with `header.len` data bytes taken from `data` (zero-filled if
    /// `data` is shorter) and working counter 0; sets the more-follows bit of the previous
    /// datagram. Returns the new datagram's data bytes for filling in. A length above 0x7FF
    /// is an error.
    pub fn push(&mut self, header: DatagramHeader, data: &[u8]) -> Result<&mut [u8], WireError> {
        if header.len as usize > MAX_DATA_LEN || header.reserved > 7 {
            return Err(WireError::InvalidField("datagram length or reserved bits"));
        }
        let total = header.wire_len();
        let start = self.len;
        if self.buf.len() < start + total || (start - self.ecat_offset + total) > 0x7FF + 2 {
            return Err(WireError::BufferFull);
        }
        if let Some(prev) = self.last_header {
            self.buf[prev + 7] |= 0x80;
        }
        let mut h = header;
        h.more_follows = false;
        h.write(&mut self.buf[start..])?;
        let d = &mut self.buf[start + DATAGRAM_HEADER_LEN..start + total - WKC_LEN];
        let n = data.len().min(d.len());
        d[..n].copy_from_slice(&data[..n]);
        d[n..].fill(0);
        self.buf[start + total - WKC_LEN..start + total].fill(0);
        self.last_header = Some(start);
        self.len = start + total;
        Ok(&mut self.buf[start + DATAGRAM_HEADER_LEN..start + total - WKC_LEN])
    }

    /// Writes the EtherCAT header, pads an Ethernet frame to 60 bytes, and returns the
    /// frame length.
    pub fn finish(self) -> usize {
        let body = (self.len - self.ecat_offset - ECAT_HEADER_LEN) as u16;
        let h = EcatHeader {
            len: body,
            reserved: false,
            frame_type: FrameType::Datagrams,
        };
        let o = self.ecat_offset;
        self.buf[o..o + 2].copy_from_slice(&h.to_word().to_le_bytes());
        if let Some(ep) = &self.udp {
            // The buffer was checked to hold the headers in `new_udp`, and the payload is at
            // most 0x801 bytes, so this cannot fail.
            let _ = ep.write_headers(self.buf, self.len - o);
        }
        let mut len = self.len;
        if self.ecat_offset > 0 && len < ETHERNET_MIN_LEN {
            let pad_to = ETHERNET_MIN_LEN.min(self.buf.len());
            self.buf[len..pad_to].fill(0);
            len = pad_to;
        }
        len
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::datagram::Command;

    #[test]
    fn build_and_parse_two_datagrams() {
        let mut buf = [0u8; 128];
        let eth = EthernetHeader {
            dst: [0xff; 6],
            src: [2, 0, 0, 0, 0, 1],
            vlan_tci: None,
            payload_offset: 14,
        };
        let mut b = FrameBuilder::new(&mut buf, &eth).unwrap();
        b.push(DatagramHeader::physical(Command::Brd, 1, 0, 0x130, 2), &[])
            .unwrap();
        b.push(
            DatagramHeader::logical(Command::Lrw, 2, 0x1000, 4),
            &[1, 2, 3, 4],
        )
        .unwrap();
        let n = b.finish();
        assert_eq!(n, 60);
        let (_, f) = EcatFrame::parse_ethernet(&buf[..n]).unwrap();
        let v: Result<std::vec::Vec<_>, _> = f.datagrams().collect();
        let v = v.unwrap();
        assert_eq!(v.len(), 2);
        assert!(v[0].header.more_follows);
        assert_eq!(v[0].header.command(), Some(Command::Brd));
        assert_eq!(v[0].header.ado(), 0x130);
        assert_eq!(v[1].data, &[1, 2, 3, 4]);
        assert!(!v[1].header.more_follows);
    }
}
