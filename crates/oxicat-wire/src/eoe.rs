//! Ethernet over EtherCAT: the 4-byte EoE header.
//!
//! Word 0: bits 0..=3 frame type, 4..=7 port, 8 last fragment, 9 time appended, 10 time
//! request, 11..=15 reserved. Word 1: bits 0..=5 fragment number, 6..=11 offset (in 32-byte
//! blocks; the complete size in the first fragment), 12..=15 frame number.

use crate::error::{need, WireError};

/// Length of the EoE header.
pub const EOE_HEADER_LEN: usize = 4;

/// The EoE frame type (4 bits).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EoeFrameType {
    /// 0: fragment of an Ethernet frame.
    Fragment,
    /// 1: initiate / time stamp response.
    Timestamp,
    /// 2: set IP parameter request.
    SetIpRequest,
    /// 3: set IP parameter response.
    SetIpResponse,
    /// 4: set address filter request.
    SetFilterRequest,
    /// 5: set address filter response.
    SetFilterResponse,
    /// 6: get IP parameter request.
    GetIpRequest,
    /// 7: get IP parameter response.
    GetIpResponse,
    /// 8: get address filter request.
    GetFilterRequest,
    /// 9: get address filter response.
    GetFilterResponse,
    /// A reserved code (10..=15).
    Reserved(u8),
}

impl EoeFrameType {
    /// Decodes the low 4 bits of `v`.
    pub const fn from_u8(v: u8) -> Self {
        match v & 0xF {
            0 => Self::Fragment,
            1 => Self::Timestamp,
            2 => Self::SetIpRequest,
            3 => Self::SetIpResponse,
            4 => Self::SetFilterRequest,
            5 => Self::SetFilterResponse,
            6 => Self::GetIpRequest,
            7 => Self::GetIpResponse,
            8 => Self::GetFilterRequest,
            9 => Self::GetFilterResponse,
            o => Self::Reserved(o),
        }
    }

    /// The 4-bit code.
    pub const fn code(self) -> u8 {
        match self {
            Self::Fragment => 0,
            Self::Timestamp => 1,
            Self::SetIpRequest => 2,
            Self::SetIpResponse => 3,
            Self::SetFilterRequest => 4,
            Self::SetFilterResponse => 5,
            Self::GetIpRequest => 6,
            Self::GetIpResponse => 7,
            Self::GetFilterRequest => 8,
            Self::GetFilterResponse => 9,
            Self::Reserved(o) => o & 0xF,
        }
    }
}

/// The decoded EoE header.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct EoeHeader {
    /// Frame type.
    pub frame_type: EoeFrameType,
    /// Port (4 bits).
    pub port: u8,
    /// This is the last fragment.
    pub last_fragment: bool,
    /// A 32-bit time stamp is appended after the data.
    pub time_appended: bool,
    /// A time stamp is requested.
    pub time_request: bool,
    /// Reserved bits 11..=15 of word 0, kept for round trips.
    pub reserved: u8,
    /// Fragment number (6 bits).
    pub fragment: u8,
    /// Offset in 32-byte blocks, or the complete size in blocks in fragment 0 (6 bits).
    pub offset: u8,
    /// Frame number (4 bits).
    pub frame_number: u8,
}

impl EoeHeader {
    /// Parses the header from the first 4 bytes of `buf` (after the mailbox header).
    pub fn parse(buf: &[u8]) -> Result<Self, WireError> {
        need(buf, EOE_HEADER_LEN)?;
        let w0 = u16::from_le_bytes([buf[0], buf[1]]);
        let w1 = u16::from_le_bytes([buf[2], buf[3]]);
        Ok(Self {
            frame_type: EoeFrameType::from_u8(w0 as u8),
            port: ((w0 >> 4) & 0xF) as u8,
            last_fragment: w0 & 0x0100 != 0,
            time_appended: w0 & 0x0200 != 0,
            time_request: w0 & 0x0400 != 0,
            reserved: (w0 >> 11) as u8,
            fragment: (w1 & 0x3F) as u8,
            offset: ((w1 >> 6) & 0x3F) as u8,
            frame_number: (w1 >> 12) as u8,
        })
    }

    /// Writes the header; fields out of their bit range are an error.
    pub fn write(&self, buf: &mut [u8]) -> Result<usize, WireError> {
        if self.port > 0xF
            || self.reserved > 0x1F
            || self.fragment > 0x3F
            || self.offset > 0x3F
            || self.frame_number > 0xF
            || matches!(self.frame_type, EoeFrameType::Reserved(r) if !(10..=15).contains(&r))
        {
            return Err(WireError::InvalidField("eoe header"));
        }
        if buf.len() < EOE_HEADER_LEN {
            return Err(WireError::BufferFull);
        }
        let w0 = (self.frame_type.code() as u16)
            | ((self.port as u16) << 4)
            | if self.last_fragment { 0x0100 } else { 0 }
            | if self.time_appended { 0x0200 } else { 0 }
            | if self.time_request { 0x0400 } else { 0 }
            | ((self.reserved as u16) << 11);
        let w1 = (self.fragment as u16)
            | ((self.offset as u16) << 6)
            | ((self.frame_number as u16) << 12);
        buf[0..2].copy_from_slice(&w0.to_le_bytes());
        buf[2..4].copy_from_slice(&w1.to_le_bytes());
        Ok(EOE_HEADER_LEN)
    }
}

/// A view of an EoE message: header and the bytes after it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EoeRef<'a> {
    /// The decoded header.
    pub header: EoeHeader,
    /// The bytes after the header (frame fragment or parameters).
    pub data: &'a [u8],
}

impl<'a> EoeRef<'a> {
    /// Parses an EoE message from mailbox service data.
    pub fn parse(payload: &'a [u8]) -> Result<Self, WireError> {
        let header = EoeHeader::parse(payload)?;
        Ok(Self {
            header,
            data: &payload[EOE_HEADER_LEN..],
        })
    }
}
