//! EtherCAT datagrams: the 10-byte header, the data and the working counter.
//!
//! Layout (little endian): `cmd:u8 idx:u8 address:u32 len_flags:u16 irq:u16 data[len] wkc:u16`,
//! where `len_flags` holds the 11-bit length, three reserved bits, the circulating bit
//! (bit 14) and the more-follows bit (bit 15).

use crate::error::{need, WireError};

/// Length of a datagram header.
pub const DATAGRAM_HEADER_LEN: usize = 10;
/// Length of the working counter that ends every datagram.
pub const WKC_LEN: usize = 2;
/// Largest length the 11-bit length field can express.
pub const MAX_DATA_LEN: usize = 0x7FF;

/// The 15 EtherCAT datagram commands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Command {
    /// No operation.
    Nop = 0,
    /// Auto-increment physical read.
    Aprd = 1,
    /// Auto-increment physical write.
    Apwr = 2,
    /// Auto-increment physical read-write.
    Aprw = 3,
    /// Configured-address physical read.
    Fprd = 4,
    /// Configured-address physical write.
    Fpwr = 5,
    /// Configured-address physical read-write.
    Fprw = 6,
    /// Broadcast read.
    Brd = 7,
    /// Broadcast write.
    Bwr = 8,
    /// Broadcast read-write.
    Brw = 9,
    /// Logical read.
    Lrd = 10,
    /// Logical write.
    Lwr = 11,
    /// Logical read-write.
    Lrw = 12,
    /// Auto-increment physical read, multiple write.
    Armw = 13,
    /// Configured-address physical read, multiple write.
    Frmw = 14,
}

/// How a command addresses slaves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Addressing {
    /// No addressing (NOP).
    None,
    /// Position (auto-increment) addressing: the slave whose ADP reaches zero.
    AutoIncrement,
    /// Configured station address or alias.
    Configured,
    /// Every slave.
    Broadcast,
    /// Logical addressing through FMMUs.
    Logical,
}

impl Command {
    /// Decodes a command byte; `None` for the reserved codes 15–255.
    #[inline]
    pub const fn from_u8(v: u8) -> Option<Self> {
        Some(match v {
            0 => Self::Nop,
            1 => Self::Aprd,
            2 => Self::Apwr,
            3 => Self::Aprw,
            4 => Self::Fprd,
            5 => Self::Fpwr,
            6 => Self::Fprw,
            7 => Self::Brd,
            8 => Self::Bwr,
            9 => Self::Brw,
            10 => Self::Lrd,
            11 => Self::Lwr,
            12 => Self::Lrw,
            13 => Self::Armw,
            14 => Self::Frmw,
            _ => return None,
        })
    }

    /// How this command selects the slaves it acts on.
    #[inline]
    pub const fn addressing(self) -> Addressing {
        match self {
            Self::Nop => Addressing::None,
            Self::Aprd | Self::Apwr | Self::Aprw | Self::Armw => Addressing::AutoIncrement,
            Self::Fprd | Self::Fpwr | Self::Fprw | Self::Frmw => Addressing::Configured,
            Self::Brd | Self::Bwr | Self::Brw => Addressing::Broadcast,
            Self::Lrd | Self::Lwr | Self::Lrw => Addressing::Logical,
        }
    }

    /// True when the command reads memory into the datagram (ARMW/FRMW read at the addressed slave).
    #[inline]
    pub const fn reads(self) -> bool {
        matches!(
            self,
            Self::Aprd
                | Self::Aprw
                | Self::Fprd
                | Self::Fprw
                | Self::Brd
                | Self::Brw
                | Self::Lrd
                | Self::Lrw
                | Self::Armw
                | Self::Frmw
        )
    }

    /// True when the command writes datagram data into memory.
    #[inline]
    pub const fn writes(self) -> bool {
        matches!(
            self,
            Self::Apwr
                | Self::Aprw
                | Self::Fpwr
                | Self::Fprw
                | Self::Bwr
                | Self::Brw
                | Self::Lwr
                | Self::Lrw
                | Self::Armw
                | Self::Frmw
        )
    }

    /// The mnemonic used by Wireshark and the ETG documents.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Nop => "NOP",
            Self::Aprd => "APRD",
            Self::Apwr => "APWR",
            Self::Aprw => "APRW",
            Self::Fprd => "FPRD",
            Self::Fpwr => "FPWR",
            Self::Fprw => "FPRW",
            Self::Brd => "BRD",
            Self::Bwr => "BWR",
            Self::Brw => "BRW",
            Self::Lrd => "LRD",
            Self::Lwr => "LWR",
            Self::Lrw => "LRW",
            Self::Armw => "ARMW",
            Self::Frmw => "FRMW",
        }
    }
}

/// The decoded 10-byte datagram header.
///
/// `command` is kept raw so that reserved command codes survive a parse/write round trip
/// (an ESC forwards such datagrams untouched).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct DatagramHeader {
    /// Raw command byte; see [`DatagramHeader::command`].
    pub command: u8,
    /// Index chosen by the master to match replies.
    pub index: u8,
    /// The 32-bit address: ADP in the low half and ADO in the high half, or a logical address.
    pub address: u32,
    /// Data length in bytes (11 bits).
    pub len: u16,
    /// Reserved bits 11–13 of the length word, kept for round trips.
    pub reserved: u8,
    /// The circulating-frame bit.
    pub circulating: bool,
    /// The more-datagrams-follow bit.
    pub more_follows: bool,
    /// The IRQ field (ECAT event request bits ORed in by every slave).
    pub irq: u16,
}

impl DatagramHeader {
    /// Builds a header for a physical (position/configured/broadcast) address.
    pub const fn physical(command: Command, index: u8, adp: u16, ado: u16, len: u16) -> Self {
        Self {
            command: command as u8,
            index,
            address: (adp as u32) | ((ado as u32) << 16),
            len,
            reserved: 0,
            circulating: false,
            more_follows: false,
            irq: 0,
        }
    }

    /// Builds a header for a logical address.
    pub const fn logical(command: Command, index: u8, address: u32, len: u16) -> Self {
        Self {
            command: command as u8,
            index,
            address,
            len,
            reserved: 0,
            circulating: false,
            more_follows: false,
            irq: 0,
        }
    }

    /// Parses a header from the first 10 bytes of `buf`.
    #[inline]
    pub fn parse(buf: &[u8]) -> Result<Self, WireError> {
        need(buf, DATAGRAM_HEADER_LEN)?;
        let lf = u16::from_le_bytes([buf[6], buf[7]]);
        Ok(Self {
            command: buf[0],
            index: buf[1],
            address: u32::from_le_bytes([buf[2], buf[3], buf[4], buf[5]]),
            len: lf & 0x07FF,
            reserved: ((lf >> 11) & 0x7) as u8,
            circulating: lf & 0x4000 != 0,
            more_follows: lf & 0x8000 != 0,
            irq: u16::from_le_bytes([buf[8], buf[9]]),
        })
    }

    /// Writes the header into the first 10 bytes of `buf`.
    #[inline]
    pub fn write(&self, buf: &mut [u8]) -> Result<(), WireError> {
        if buf.len() < DATAGRAM_HEADER_LEN {
            return Err(WireError::BufferFull);
        }
        buf[0] = self.command;
        buf[1] = self.index;
        buf[2..6].copy_from_slice(&self.address.to_le_bytes());
        buf[6..8].copy_from_slice(&self.len_flags().to_le_bytes());
        buf[8..10].copy_from_slice(&self.irq.to_le_bytes());
        Ok(())
    }

    /// The length word as on the wire (length, reserved, C and M bits).
    #[inline]
    pub const fn len_flags(&self) -> u16 {
        (self.len & 0x07FF)
            | ((self.reserved as u16 & 0x7) << 11)
            | if self.circulating { 0x4000 } else { 0 }
            | if self.more_follows { 0x8000 } else { 0 }
    }

    /// The decoded command, `None` for a reserved code.
    #[inline]
    pub const fn command(&self) -> Option<Command> {
        Command::from_u8(self.command)
    }

    /// Position or configured station address (low 16 bits of the address).
    #[inline]
    pub const fn adp(&self) -> u16 {
        self.address as u16
    }

    /// Physical memory offset within the slave (high 16 bits of the address).
    #[inline]
    pub const fn ado(&self) -> u16 {
        (self.address >> 16) as u16
    }

    /// Total bytes of the datagram on the wire: header, data and working counter.
    #[inline]
    pub const fn wire_len(&self) -> usize {
        DATAGRAM_HEADER_LEN + self.len as usize + WKC_LEN
    }
}

/// A read-only view of one datagram inside a frame.
#[derive(Debug, Clone, Copy)]
pub struct DatagramRef<'a> {
    /// The decoded header.
    pub header: DatagramHeader,
    /// The data bytes.
    pub data: &'a [u8],
    /// The working counter.
    pub wkc: u16,
}

impl<'a> DatagramRef<'a> {
    /// Parses one datagram at the start of `buf`; returns it and the bytes it occupies.
    pub fn parse(buf: &'a [u8]) -> Result<(Self, usize), WireError> {
        let header = DatagramHeader::parse(buf)?;
        let total = header.wire_len();
        if buf.len() < total {
            return Err(WireError::LengthMismatch {
                declared: total,
                available: buf.len(),
            });
        }
        let data = &buf[DATAGRAM_HEADER_LEN..total - WKC_LEN];
        let wkc = u16::from_le_bytes([buf[total - 2], buf[total - 1]]);
        Ok((Self { header, data, wkc }, total))
    }
}

/// A mutable view of one datagram inside a frame (what an ESC works on).
#[derive(Debug)]
pub struct DatagramMut<'a> {
    /// The decoded header (write it back with [`DatagramMut::commit_header`]).
    pub header: DatagramHeader,
    /// Header bytes in the frame.
    raw_header: &'a mut [u8],
    /// The data bytes.
    pub data: &'a mut [u8],
    /// The working counter bytes.
    raw_wkc: &'a mut [u8],
}

impl<'a> DatagramMut<'a> {
    /// Parses one datagram at the start of `buf`; returns it and the remaining bytes.
    pub fn parse(buf: &'a mut [u8]) -> Result<(Self, &'a mut [u8]), WireError> {
        let header = DatagramHeader::parse(buf)?;
        let total = header.wire_len();
        if buf.len() < total {
            return Err(WireError::LengthMismatch {
                declared: total,
                available: buf.len(),
            });
        }
        let (dg, rest) = buf.split_at_mut(total);
        let (raw_header, tail) = dg.split_at_mut(DATAGRAM_HEADER_LEN);
        let (data, raw_wkc) = tail.split_at_mut(header.len as usize);
        Ok((
            Self {
                header,
                raw_header,
                data,
                raw_wkc,
            },
            rest,
        ))
    }

    /// The working counter.
    #[inline]
    pub fn wkc(&self) -> u16 {
        u16::from_le_bytes([self.raw_wkc[0], self.raw_wkc[1]])
    }

    /// Sets the working counter.
    #[inline]
    pub fn set_wkc(&mut self, wkc: u16) {
        self.raw_wkc.copy_from_slice(&wkc.to_le_bytes());
    }

    /// Writes the (possibly modified) header back into the frame.
    #[inline]
    pub fn commit_header(&mut self) {
        // The header slice is exactly DATAGRAM_HEADER_LEN long, so this cannot fail.
        let _ = self.header.write(self.raw_header);
    }
}
