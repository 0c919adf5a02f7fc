//! Servo profile over EtherCAT: the 4-byte SoE header.
//!
//! Byte 0: bits 0..=2 opcode, 3 incomplete, 4 error, 5..=7 drive number. Byte 1: element
//! flags. Bytes 2..4: the IDN, or the fragments left when `incomplete` is set.

use crate::error::{need, WireError};

/// Length of the SoE header.
pub const SOE_HEADER_LEN: usize = 4;

/// The SoE opcode (3 bits).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SoeOpcode {
    /// 1: read request.
    ReadRequest,
    /// 2: read response.
    ReadResponse,
    /// 3: write request.
    WriteRequest,
    /// 4: write response.
    WriteResponse,
    /// 5: notification.
    Notification,
    /// 6: slave info.
    SlaveInfo,
    /// A reserved code (0, 7).
    Reserved(u8),
}

impl SoeOpcode {
    /// Decodes the low 3 bits of `v`.
    pub const fn from_u8(v: u8) -> Self {
        match v & 0x7 {
            1 => Self::ReadRequest,
            2 => Self::ReadResponse,
            3 => Self::WriteRequest,
            4 => Self::WriteResponse,
            5 => Self::Notification,
            6 => Self::SlaveInfo,
            o => Self::Reserved(o),
        }
    }

    /// The 3-bit code.
    pub const fn code(self) -> u8 {
        match self {
            Self::ReadRequest => 1,
            Self::ReadResponse => 2,
            Self::WriteRequest => 3,
            Self::WriteResponse => 4,
            Self::Notification => 5,
            Self::SlaveInfo => 6,
            Self::Reserved(o) => o & 0x7,
        }
    }
}

/// Bits of the SoE element flags byte.
pub mod elements {
    /// Data state.
    pub const DATA_STATE: u8 = 0x01;
    /// Name.
    pub const NAME: u8 = 0x02;
    /// Attribute.
    pub const ATTRIBUTE: u8 = 0x04;
    /// Unit.
    pub const UNIT: u8 = 0x08;
    /// Minimum.
    pub const MIN: u8 = 0x10;
    /// Maximum.
    pub const MAX: u8 = 0x20;
    /// Value.
    pub const VALUE: u8 = 0x40;
    /// Default.
    pub const DEFAULT: u8 = 0x80;
}

/// The decoded SoE header.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SoeHeader {
    /// The opcode.
    pub opcode: SoeOpcode,
    /// More fragments follow; `idn` then holds the fragments left.
    pub incomplete: bool,
    /// The response reports an error (a 16-bit error code follows).
    pub error: bool,
    /// Drive number (3 bits).
    pub drive_no: u8,
    /// Element flags (see [`elements`]).
    pub elements: u8,
    /// IDN, or fragments left when incomplete.
    pub idn: u16,
}

impl SoeHeader {
    /// Parses the header from the first 4 bytes of `buf` (after the mailbox header).
    pub fn parse(buf: &[u8]) -> Result<Self, WireError> {
        need(buf, SOE_HEADER_LEN)?;
        Ok(Self {
            opcode: SoeOpcode::from_u8(buf[0]),
            incomplete: buf[0] & 0x08 != 0,
            error: buf[0] & 0x10 != 0,
            drive_no: buf[0] >> 5,
            elements: buf[1],
            idn: u16::from_le_bytes([buf[2], buf[3]]),
        })
    }

    /// Writes the header; fields out of their bit range are an error.
    pub fn write(&self, buf: &mut [u8]) -> Result<usize, WireError> {
        if self.drive_no > 7 {
            return Err(WireError::InvalidField("soe drive number"));
        }
        if matches!(self.opcode, SoeOpcode::Reserved(r) if r != 0 && r != 7) {
            return Err(WireError::InvalidField("soe opcode"));
        }
        if buf.len() < SOE_HEADER_LEN {
            return Err(WireError::BufferFull);
        }
        buf[0] = self.opcode.code()
            | if self.incomplete { 0x08 } else { 0 }
            | if self.error { 0x10 } else { 0 }
            | (self.drive_no << 5);
        buf[1] = self.elements;
        buf[2..4].copy_from_slice(&self.idn.to_le_bytes());
        Ok(SOE_HEADER_LEN)
    }
}

/// A view of an SoE message: header and the bytes after it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SoeRef<'a> {
    /// The decoded header.
    pub header: SoeHeader,
    /// The bytes after the header.
    pub data: &'a [u8],
}

impl<'a> SoeRef<'a> {
    /// Parses an SoE message from mailbox service data.
    pub fn parse(payload: &'a [u8]) -> Result<Self, WireError> {
        let header = SoeHeader::parse(payload)?;
        Ok(Self {
            header,
            data: &payload[SOE_HEADER_LEN..],
        })
    }
}
