//! The mailbox header shared by all mailbox protocols, and the mailbox error reply.
//!
//! Layout (little endian, 6 bytes): `length:u16 address:u16 chan_prio:u8 type_cnt:u8`, where
//! `chan_prio` holds the 6-bit channel and the 2-bit priority, and `type_cnt` holds the 4-bit
//! mailbox type, the 3-bit counter and one reserved bit. `length` counts the bytes after the
//! header.

use crate::error::{need, WireError};

/// Length of the mailbox header.
pub const MAILBOX_HEADER_LEN: usize = 6;

/// The mailbox protocol carried after the header (4-bit type field).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MailboxType {
    /// Mailbox error reply, type 0.
    Error,
    /// ADS over EtherCAT, type 1.
    Aoe,
    /// Ethernet over EtherCAT, type 2.
    Eoe,
    /// CANopen over EtherCAT, type 3.
    Coe,
    /// File access over EtherCAT, type 4.
    Foe,
    /// Servo profile over EtherCAT, type 5.
    Soe,
    /// Vendor specific, type 15.
    Voe,
    /// A reserved type code (6..=14).
    Reserved(u8),
}

impl MailboxType {
    /// Decodes the low 4 bits of `v`.
    pub const fn from_u8(v: u8) -> Self {
        match v & 0xF {
            0 => Self::Error,
            1 => Self::Aoe,
            2 => Self::Eoe,
            3 => Self::Coe,
            4 => Self::Foe,
            5 => Self::Soe,
            15 => Self::Voe,
            o => Self::Reserved(o),
        }
    }

    /// The 4-bit code.
    pub const fn code(self) -> u8 {
        match self {
            Self::Error => 0,
            Self::Aoe => 1,
            Self::Eoe => 2,
            Self::Coe => 3,
            Self::Foe => 4,
            Self::Soe => 5,
            Self::Voe => 15,
            Self::Reserved(o) => o & 0xF,
        }
    }
}

/// The decoded 6-byte mailbox header.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct MailboxHeader {
    /// Bytes of mailbox service data following the header.
    pub length: u16,
    /// Station address of the originator (master → slave) or destination.
    pub address: u16,
    /// Channel (6 bits, 0 for standard traffic).
    pub channel: u8,
    /// Priority (2 bits).
    pub priority: u8,
    /// Mailbox protocol type.
    pub mailbox_type: MailboxType,
    /// Counter 1..=7 used to detect repeated mailbox messages (0 = not used).
    pub counter: u8,
    /// The reserved bit 7 of the last byte, kept for round trips.
    pub reserved: bool,
}

impl MailboxHeader {
    /// A header with channel 0, priority 0 and the given fields.
    pub const fn new(length: u16, address: u16, mailbox_type: MailboxType, counter: u8) -> Self {
        Self {
            length,
            address,
            channel: 0,
            priority: 0,
            mailbox_type,
            counter,
            reserved: false,
        }
    }

    /// Parses the header from the first 6 bytes of `buf`.
    pub fn parse(buf: &[u8]) -> Result<Self, WireError> {
        need(buf, MAILBOX_HEADER_LEN)?;
        Ok(Self {
            length: u16::from_le_bytes([buf[0], buf[1]]),
            address: u16::from_le_bytes([buf[2], buf[3]]),
            channel: buf[4] & 0x3F,
            priority: buf[4] >> 6,
            mailbox_type: MailboxType::from_u8(buf[5]),
            counter: (buf[5] >> 4) & 0x7,
            reserved: buf[5] & 0x80 != 0,
        })
    }

    /// Writes the header into the first 6 bytes of `buf`; fields out of their bit range are
    /// an error.
    pub fn write(&self, buf: &mut [u8]) -> Result<usize, WireError> {
        if self.channel > 0x3F {
            return Err(WireError::InvalidField("mailbox channel"));
        }
        if self.priority > 3 {
            return Err(WireError::InvalidField("mailbox priority"));
        }
        if self.counter > 7 {
            return Err(WireError::InvalidField("mailbox counter"));
        }
        if let MailboxType::Reserved(r) = self.mailbox_type {
            if MailboxType::from_u8(r) != self.mailbox_type || r > 0xF {
                return Err(WireError::InvalidField("mailbox type"));
            }
        }
        if buf.len() < MAILBOX_HEADER_LEN {
            return Err(WireError::BufferFull);
        }
        buf[0..2].copy_from_slice(&self.length.to_le_bytes());
        buf[2..4].copy_from_slice(&self.address.to_le_bytes());
        buf[4] = self.channel | (self.priority << 6);
        buf[5] =
            self.mailbox_type.code() | (self.counter << 4) | if self.reserved { 0x80 } else { 0 };
        Ok(MAILBOX_HEADER_LEN)
    }

    /// The next counter value after `counter` in the 1..=7 sequence.
    pub const fn next_counter(counter: u8) -> u8 {
        if counter >= 7 {
            1
        } else {
            counter + 1
        }
    }
}

/// A view of one mailbox message: header and exactly `header.length` bytes of service data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MailboxRef<'a> {
    /// The decoded header.
    pub header: MailboxHeader,
    /// The service data (CoE/FoE/... header and payload).
    pub payload: &'a [u8],
}

impl<'a> MailboxRef<'a> {
    /// Parses a mailbox message at the start of `buf` (an SM buffer may be longer than the
    /// message; the rest is ignored).
    pub fn parse(buf: &'a [u8]) -> Result<Self, WireError> {
        let header = MailboxHeader::parse(buf)?;
        let end = MAILBOX_HEADER_LEN + header.length as usize;
        if buf.len() < end {
            return Err(WireError::LengthMismatch {
                declared: header.length as usize,
                available: buf.len() - MAILBOX_HEADER_LEN,
            });
        }
        Ok(Self {
            header,
            payload: &buf[MAILBOX_HEADER_LEN..end],
        })
    }
}

/// Writes a mailbox header with `length = payload.len()` followed by `payload` into `buf`;
/// returns the bytes written.
pub fn write_mailbox(
    buf: &mut [u8],
    header: &MailboxHeader,
    payload: &[u8],
) -> Result<usize, WireError> {
    let len = u16::try_from(payload.len()).map_err(|_| WireError::BufferFull)?;
    let total = MAILBOX_HEADER_LEN + payload.len();
    if buf.len() < total {
        return Err(WireError::BufferFull);
    }
    let mut h = *header;
    h.length = len;
    h.write(buf)?;
    buf[MAILBOX_HEADER_LEN..total].copy_from_slice(payload);
    Ok(total)
}

/// The service code of a mailbox error reply (the only one defined).
pub const MAILBOX_ERROR_SERVICE: u16 = 0x0001;
/// Length of a mailbox error reply's service data.
pub const MAILBOX_ERROR_LEN: usize = 4;

/// Why a slave rejected a mailbox message (detail code of the mailbox error reply).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MailboxErrorDetail {
    /// 1: syntax of the 6-byte mailbox header is wrong.
    Syntax,
    /// 2: the mailbox protocol is not supported.
    UnsupportedProtocol,
    /// 3: the channel field is not 0.
    InvalidChannel,
    /// 4: the service in the mailbox protocol is not supported.
    ServiceNotSupported,
    /// 5: the mailbox protocol header is wrong (without the 6-byte mailbox header).
    InvalidHeader,
    /// 6: the length of the received mailbox data is too short.
    SizeTooShort,
    /// 7: the mailbox protocol cannot be processed for lack of resources.
    NoMoreMemory,
    /// 8: the length of the data is inconsistent.
    InvalidSize,
    /// Any other detail code.
    Other(u16),
}

impl MailboxErrorDetail {
    /// Decodes a detail code.
    pub const fn from_u16(v: u16) -> Self {
        match v {
            1 => Self::Syntax,
            2 => Self::UnsupportedProtocol,
            3 => Self::InvalidChannel,
            4 => Self::ServiceNotSupported,
            5 => Self::InvalidHeader,
            6 => Self::SizeTooShort,
            7 => Self::NoMoreMemory,
            8 => Self::InvalidSize,
            o => Self::Other(o),
        }
    }

    /// The detail code: a named detail's is its position + 1 (computed: a match with a
    /// constant per detail is a jump table on a Cortex-M).
    pub const fn code(self) -> u16 {
        1 + match self {
            Self::Syntax => 0,
            Self::UnsupportedProtocol => 1,
            Self::InvalidChannel => 2,
            Self::ServiceNotSupported => 3,
            Self::InvalidHeader => 4,
            Self::SizeTooShort => 5,
            Self::NoMoreMemory => 6,
            Self::InvalidSize => 7,
            Self::Other(o) => return o,
        }
    }

    /// The description from ETG.1000.
    pub const fn text(self) -> &'static str {
        match self {
            Self::Syntax => "syntax of 6 octet mailbox header is wrong",
            Self::UnsupportedProtocol => "the mailbox protocol is not supported",
            Self::InvalidChannel => "field contains wrong value",
            Self::ServiceNotSupported => "the service in the mailbox protocol is not supported",
            Self::InvalidHeader => "the mailbox protocol header is wrong",
            Self::SizeTooShort => "length of received mailbox data is too short",
            Self::NoMoreMemory => "mailbox protocol cannot be processed: no more memory",
            Self::InvalidSize => "length of data is inconsistent",
            Self::Other(_) => "unknown mailbox error",
        }
    }
}

impl core::fmt::Display for MailboxErrorDetail {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "mailbox error {:#06x}: {}", self.code(), self.text())
    }
}

/// The service data of a mailbox error reply (mailbox type 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct MailboxErrorReply {
    /// The detail code.
    pub detail: MailboxErrorDetail,
}

impl MailboxErrorReply {
    /// Parses the 4-byte service data (service 0x0001 + detail) of a type-0 mailbox.
    pub fn parse(payload: &[u8]) -> Result<Self, WireError> {
        need(payload, MAILBOX_ERROR_LEN)?;
        let service = u16::from_le_bytes([payload[0], payload[1]]);
        if service != MAILBOX_ERROR_SERVICE {
            return Err(WireError::InvalidField("mailbox error service"));
        }
        Ok(Self {
            detail: MailboxErrorDetail::from_u16(u16::from_le_bytes([payload[2], payload[3]])),
        })
    }

    /// Writes the 4-byte service data.
    pub fn write(&self, buf: &mut [u8]) -> Result<usize, WireError> {
        if buf.len() < MAILBOX_ERROR_LEN {
            return Err(WireError::BufferFull);
        }
        buf[0..2].copy_from_slice(&MAILBOX_ERROR_SERVICE.to_le_bytes());
        buf[2..4].copy_from_slice(&self.detail.code().to_le_bytes());
        Ok(MAILBOX_ERROR_LEN)
    }

    /// Writes a whole mailbox error message (header + service data); returns its length.
    pub fn write_mailbox(
        &self,
        buf: &mut [u8],
        address: u16,
        counter: u8,
    ) -> Result<usize, WireError> {
        let mut p = [0u8; MAILBOX_ERROR_LEN];
        self.write(&mut p)?;
        write_mailbox(
            buf,
            &MailboxHeader::new(0, address, MailboxType::Error, counter),
            &p,
        )
    }
}

/// Bits of the SII "mailbox protocols" word and the general category's flags.
pub mod protocols {
    /// ADS over EtherCAT supported.
    pub const AOE: u16 = 0x0001;
    /// Ethernet over EtherCAT supported.
    pub const EOE: u16 = 0x0002;
    /// CANopen over EtherCAT supported.
    pub const COE: u16 = 0x0004;
    /// File access over EtherCAT supported.
    pub const FOE: u16 = 0x0008;
    /// Servo profile over EtherCAT supported.
    pub const SOE: u16 = 0x0010;
    /// Vendor specific protocol over EtherCAT supported.
    pub const VOE: u16 = 0x0020;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_bits() {
        let b = [0x0a, 0x00, 0x00, 0x00, 0x00, 0x23];
        let h = MailboxHeader::parse(&b).unwrap();
        assert_eq!(h.length, 10);
        assert_eq!(h.mailbox_type, MailboxType::Coe);
        assert_eq!(h.counter, 2);
        let mut o = [0u8; 6];
        h.write(&mut o).unwrap();
        assert_eq!(o, b);
    }

    #[test]
    fn error_reply() {
        let mut buf = [0u8; 16];
        let n = MailboxErrorReply {
            detail: MailboxErrorDetail::InvalidSize,
        }
        .write_mailbox(&mut buf, 0x1001, 3)
        .unwrap();
        assert_eq!(n, 10);
        let m = MailboxRef::parse(&buf[..n]).unwrap();
        assert_eq!(m.header.mailbox_type, MailboxType::Error);
        assert_eq!(
            MailboxErrorReply::parse(m.payload).unwrap().detail,
            MailboxErrorDetail::InvalidSize
        );
        assert!(MailboxRef::parse(&buf[..8]).is_err());
    }
}
