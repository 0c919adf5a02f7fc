//! File access over EtherCAT: the 6-byte FoE header and the standard FoE error codes.
//!
//! Layout after the mailbox header: `opcode:u8 reserved:u8` and a 4-byte field whose meaning
//! depends on the opcode (password, packet number, error code, or busy done + entire),
//! followed by the file name, data or error text.

use crate::error::{need, WireError};

/// Length of the FoE header.
pub const FOE_HEADER_LEN: usize = 6;

/// The FoE opcodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum FoeOpcode {
    /// Read request.
    Read = 1,
    /// Write request.
    Write = 2,
    /// Data packet.
    Data = 3,
    /// Acknowledge.
    Ack = 4,
    /// Error.
    Error = 5,
    /// Busy.
    Busy = 6,
}

impl FoeOpcode {
    /// Decodes an opcode byte.
    pub const fn from_u8(v: u8) -> Result<Self, WireError> {
        Ok(match v {
            1 => Self::Read,
            2 => Self::Write,
            3 => Self::Data,
            4 => Self::Ack,
            5 => Self::Error,
            6 => Self::Busy,
            o => return Err(WireError::UnknownType(o)),
        })
    }
}

/// The decoded FoE header.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FoeHeader {
    /// Read request; the file name follows.
    Read {
        /// Password (0 = none).
        password: u32,
    },
    /// Write request; the file name follows.
    Write {
        /// Password (0 = none).
        password: u32,
    },
    /// Data packet; the data follows.
    Data {
        /// Packet number, starting at 1.
        packet: u32,
    },
    /// Acknowledge of a data packet.
    Ack {
        /// Packet number acknowledged.
        packet: u32,
    },
    /// Error; an optional error text follows.
    Error {
        /// The error code.
        code: FoeErrorCode,
    },
    /// Busy: the slave is still working (e.g. erasing flash).
    Busy {
        /// Progress done.
        done: u16,
        /// Progress total.
        entire: u16,
    },
}

impl FoeHeader {
    /// The opcode of this header.
    pub const fn opcode(&self) -> FoeOpcode {
        match self {
            Self::Read { .. } => FoeOpcode::Read,
            Self::Write { .. } => FoeOpcode::Write,
            Self::Data { .. } => FoeOpcode::Data,
            Self::Ack { .. } => FoeOpcode::Ack,
            Self::Error { .. } => FoeOpcode::Error,
            Self::Busy { .. } => FoeOpcode::Busy,
        }
    }

    /// Parses the header from the first 6 bytes of `buf` (after the mailbox header).
    pub fn parse(buf: &[u8]) -> Result<Self, WireError> {
        need(buf, FOE_HEADER_LEN)?;
        let v = u32::from_le_bytes([buf[2], buf[3], buf[4], buf[5]]);
        Ok(match FoeOpcode::from_u8(buf[0])? {
            FoeOpcode::Read => Self::Read { password: v },
            FoeOpcode::Write => Self::Write { password: v },
            FoeOpcode::Data => Self::Data { packet: v },
            FoeOpcode::Ack => Self::Ack { packet: v },
            FoeOpcode::Error => Self::Error {
                code: FoeErrorCode::from_u32(v),
            },
            FoeOpcode::Busy => Self::Busy {
                done: u16::from_le_bytes([buf[2], buf[3]]),
                entire: u16::from_le_bytes([buf[4], buf[5]]),
            },
        })
    }

    /// Writes the header into the first 6 bytes of `buf`.
    pub fn write(&self, buf: &mut [u8]) -> Result<usize, WireError> {
        if buf.len() < FOE_HEADER_LEN {
            return Err(WireError::BufferFull);
        }
        let v = match *self {
            Self::Read { password } | Self::Write { password } => password,
            Self::Data { packet } | Self::Ack { packet } => packet,
            Self::Error { code } => code.code(),
            Self::Busy { done, entire } => (done as u32) | ((entire as u32) << 16),
        };
        buf[0] = self.opcode() as u8;
        buf[1] = 0;
        buf[2..6].copy_from_slice(&v.to_le_bytes());
        Ok(FOE_HEADER_LEN)
    }
}

/// A view of an FoE message: header and what follows it (file name, data or error text).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FoeRef<'a> {
    /// The decoded header.
    pub header: FoeHeader,
    /// The bytes after the header.
    pub data: &'a [u8],
}

impl<'a> FoeRef<'a> {
    /// Parses an FoE message from mailbox service data.
    pub fn parse(payload: &'a [u8]) -> Result<Self, WireError> {
        let header = FoeHeader::parse(payload)?;
        Ok(Self {
            header,
            data: &payload[FOE_HEADER_LEN..],
        })
    }

    /// Writes header and `data` into `buf`; returns the length (the mailbox length).
    pub fn write(header: &FoeHeader, data: &[u8], buf: &mut [u8]) -> Result<usize, WireError> {
        let total = FOE_HEADER_LEN + data.len();
        if buf.len() < total {
            return Err(WireError::BufferFull);
        }
        header.write(buf)?;
        buf[FOE_HEADER_LEN..total].copy_from_slice(data);
        Ok(total)
    }
}

/// The standard FoE error codes (ETG.1000.6).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FoeErrorCode {
    /// 0x8000: not defined (see error text).
    NotDefined,
    /// 0x8001: file not found.
    NotFound,
    /// 0x8002: access denied.
    AccessDenied,
    /// 0x8003: disk full.
    DiskFull,
    /// 0x8004: illegal operation.
    Illegal,
    /// 0x8005: packet number wrong.
    PacketNumberWrong,
    /// 0x8006: file already exists.
    AlreadyExists,
    /// 0x8007: no user.
    NoUser,
    /// 0x8008: bootstrap only.
    BootstrapOnly,
    /// 0x8009: not in bootstrap.
    NotBootstrap,
    /// 0x800A: no rights.
    NoRights,
    /// 0x800B: program error.
    ProgramError,
    /// 0x800C: checksum error.
    ChecksumError,
    /// Any other code.
    Other(u32),
}

impl FoeErrorCode {
    /// Every standard code, in numeric order.
    pub const ALL: &'static [FoeErrorCode] = &[
        Self::NotDefined,
        Self::NotFound,
        Self::AccessDenied,
        Self::DiskFull,
        Self::Illegal,
        Self::PacketNumberWrong,
        Self::AlreadyExists,
        Self::NoUser,
        Self::BootstrapOnly,
        Self::NotBootstrap,
        Self::NoRights,
        Self::ProgramError,
        Self::ChecksumError,
    ];

    /// Decodes an error code.
    pub const fn from_u32(v: u32) -> Self {
        match v {
            0x8000 => Self::NotDefined,
            0x8001 => Self::NotFound,
            0x8002 => Self::AccessDenied,
            0x8003 => Self::DiskFull,
            0x8004 => Self::Illegal,
            0x8005 => Self::PacketNumberWrong,
            0x8006 => Self::AlreadyExists,
            0x8007 => Self::NoUser,
            0x8008 => Self::BootstrapOnly,
            0x8009 => Self::NotBootstrap,
            0x800A => Self::NoRights,
            0x800B => Self::ProgramError,
            0x800C => Self::ChecksumError,
            o => Self::Other(o),
        }
    }

    /// The error code: a standard one is 0x8000 + its position (computed, not a jump table
    /// with a constant per code).
    pub const fn code(self) -> u32 {
        0x8000
            + match self {
                Self::NotDefined => 0x0,
                Self::NotFound => 0x1,
                Self::AccessDenied => 0x2,
                Self::DiskFull => 0x3,
                Self::Illegal => 0x4,
                Self::PacketNumberWrong => 0x5,
                Self::AlreadyExists => 0x6,
                Self::NoUser => 0x7,
                Self::BootstrapOnly => 0x8,
                Self::NotBootstrap => 0x9,
                Self::NoRights => 0xA,
                Self::ProgramError => 0xB,
                Self::ChecksumError => 0xC,
                Self::Other(o) => return o,
            }
    }

    /// The standard description.
    pub const fn text(self) -> &'static str {
        match self {
            Self::NotDefined => "Not defined",
            Self::NotFound => "Not found",
            Self::AccessDenied => "Access denied",
            Self::DiskFull => "Disk full",
            Self::Illegal => "Illegal",
            Self::PacketNumberWrong => "Packet number wrong",
            Self::AlreadyExists => "Already exists",
            Self::NoUser => "No user",
            Self::BootstrapOnly => "Bootstrap only",
            Self::NotBootstrap => "Not Bootstrap",
            Self::NoRights => "No rights",
            Self::ProgramError => "Program Error",
            Self::ChecksumError => "Checksum error",
            Self::Other(_) => "unknown FoE error",
        }
    }
}

impl core::fmt::Display for FoeErrorCode {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "FoE error {:#06x}: {}", self.code(), self.text())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn write_request() {
        let mut b = [0u8; 32];
        let n = FoeRef::write(&FoeHeader::Write { password: 0 }, b"app.bin", &mut b).unwrap();
        let f = FoeRef::parse(&b[..n]).unwrap();
        assert_eq!(f.header, FoeHeader::Write { password: 0 });
        assert_eq!(f.data, b"app.bin");
        assert!(FoeHeader::parse(&[9, 0, 0, 0, 0, 0]).is_err());
        for c in FoeErrorCode::ALL {
            assert_eq!(FoeErrorCode::from_u32(c.code()), *c);
        }
    }
}
