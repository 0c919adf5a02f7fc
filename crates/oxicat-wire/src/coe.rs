//! CANopen over EtherCAT: the CoE header, SDO command bytes, SDO abort codes, SDO
//! information service headers and the emergency message.
//!
//! Every type here starts after the 6-byte mailbox header. The CoE header is a little-endian
//! word: bits 0..=8 number, 9..=11 reserved, 12..=15 service.

use crate::error::{need, WireError};

/// Length of the CoE header.
pub const COE_HEADER_LEN: usize = 2;
/// Length of an SDO initiate/abort header after the CoE header: command, index, subindex.
pub const SDO_HEADER_LEN: usize = 4;
/// Length of the CoE service data of an expedited SDO or an abort: CoE + SDO header + 4 bytes.
pub const SDO_EXPEDITED_LEN: usize = COE_HEADER_LEN + SDO_HEADER_LEN + 4;
/// Length of the SDO information header after the CoE header.
pub const SDO_INFO_HEADER_LEN: usize = 4;
/// Length of an emergency message's data after the CoE header.
pub const EMERGENCY_LEN: usize = 8;

/// The CoE service (4-bit field of the CoE header).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CoeService {
    /// 1: emergency message.
    Emergency,
    /// 2: SDO request.
    SdoRequest,
    /// 3: SDO response.
    SdoResponse,
    /// 4: TxPDO.
    TxPdo,
    /// 5: RxPDO.
    RxPdo,
    /// 6: TxPDO remote request.
    TxPdoRemoteRequest,
    /// 7: RxPDO remote request.
    RxPdoRemoteRequest,
    /// 8: SDO information.
    SdoInformation,
    /// A reserved code (0, 9..=15).
    Reserved(u8),
}

impl CoeService {
    /// Decodes the low 4 bits of `v`.
    pub const fn from_u8(v: u8) -> Self {
        match v & 0xF {
            1 => Self::Emergency,
            2 => Self::SdoRequest,
            3 => Self::SdoResponse,
            4 => Self::TxPdo,
            5 => Self::RxPdo,
            6 => Self::TxPdoRemoteRequest,
            7 => Self::RxPdoRemoteRequest,
            8 => Self::SdoInformation,
            o => Self::Reserved(o),
        }
    }

    /// The 4-bit code: a named service's is its position + 1 (computed: a match with a
    /// constant per service is a jump table on a Cortex-M).
    pub const fn code(self) -> u8 {
        1 + match self {
            Self::Emergency => 0,
            Self::SdoRequest => 1,
            Self::SdoResponse => 2,
            Self::TxPdo => 3,
            Self::RxPdo => 4,
            Self::TxPdoRemoteRequest => 5,
            Self::RxPdoRemoteRequest => 6,
            Self::SdoInformation => 7,
            Self::Reserved(o) => return o & 0xF,
        }
    }
}

/// The decoded CoE header.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct CoeHeader {
    /// Number (9 bits): PDO number for PDO services, 0 otherwise.
    pub number: u16,
    /// The three reserved bits, kept for round trips.
    pub reserved: u8,
    /// The CoE service.
    pub service: CoeService,
}

impl CoeHeader {
    /// A header with number 0 for `service`.
    pub const fn new(service: CoeService) -> Self {
        Self {
            number: 0,
            reserved: 0,
            service,
        }
    }

    /// Parses the header from the first two bytes of `buf`.
    pub fn parse(buf: &[u8]) -> Result<Self, WireError> {
        need(buf, COE_HEADER_LEN)?;
        let w = u16::from_le_bytes([buf[0], buf[1]]);
        Ok(Self {
            number: w & 0x1FF,
            reserved: ((w >> 9) & 0x7) as u8,
            service: CoeService::from_u8((w >> 12) as u8),
        })
    }

    /// Writes the header; fields out of their bit range are an error.
    pub fn write(&self, buf: &mut [u8]) -> Result<usize, WireError> {
        if self.number > 0x1FF {
            return Err(WireError::InvalidField("coe number"));
        }
        if self.reserved > 7 {
            return Err(WireError::InvalidField("coe reserved"));
        }
        if let CoeService::Reserved(r) = self.service {
            // What `CoeService::from_u8(r) != self.service` says: a code of a named service
            // or wider than 4 bits (without the decode, in each board image's replies).
            if r > 0xF || (1..=8).contains(&r) {
                return Err(WireError::InvalidField("coe service"));
            }
        }
        if buf.len() < COE_HEADER_LEN {
            return Err(WireError::BufferFull);
        }
        let w = self.number | ((self.reserved as u16) << 9) | ((self.service.code() as u16) << 12);
        buf[0..2].copy_from_slice(&w.to_le_bytes());
        Ok(COE_HEADER_LEN)
    }
}

/// The command specifier of an SDO request (client → server), decoded from the command byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SdoRequestCommand {
    /// ccs 1: initiate download (write).
    InitiateDownload {
        /// The size is indicated (in the 4 data bytes, or by `unused` if expedited).
        size_indicated: bool,
        /// Expedited: the data (1..=4 bytes) is in the header.
        expedited: bool,
        /// For expedited transfers, the number of the 4 data bytes that carry no data (2 bits).
        unused: u8,
        /// Complete access: the whole object from `subindex` on.
        complete_access: bool,
    },
    /// ccs 0: download segment.
    DownloadSegment {
        /// The toggle bit, alternating per segment starting at 0.
        toggle: bool,
        /// No more segments follow.
        last: bool,
        /// Bytes of the minimum 7-byte segment that carry no data (3 bits).
        unused: u8,
    },
    /// ccs 2: initiate upload (read).
    InitiateUpload {
        /// Complete access: the whole object from `subindex` on.
        complete_access: bool,
    },
    /// ccs 3: upload segment.
    UploadSegment {
        /// The toggle bit.
        toggle: bool,
    },
    /// ccs 4: abort transfer.
    Abort,
}

impl SdoRequestCommand {
    /// Decodes a request command byte; block transfer specifiers (5, 6) and 7 are errors.
    pub const fn from_u8(b: u8) -> Result<Self, WireError> {
        Ok(match b >> 5 {
            0 => Self::DownloadSegment {
                toggle: b & 0x10 != 0,
                last: b & 0x01 != 0,
                unused: (b >> 1) & 0x7,
            },
            1 => Self::InitiateDownload {
                size_indicated: b & 0x01 != 0,
                expedited: b & 0x02 != 0,
                unused: (b >> 2) & 0x3,
                complete_access: b & 0x10 != 0,
            },
            2 => Self::InitiateUpload {
                complete_access: b & 0x10 != 0,
            },
            3 => Self::UploadSegment {
                toggle: b & 0x10 != 0,
            },
            4 => Self::Abort,
            o => return Err(WireError::UnknownType(o)),
        })
    }

    /// Encodes the command byte; fields out of their bit range are an error.
    pub const fn to_u8(self) -> Result<u8, WireError> {
        Ok(match self {
            Self::DownloadSegment {
                toggle,
                last,
                unused,
            } => {
                if unused > 7 {
                    return Err(WireError::InvalidField("sdo segment size"));
                }
                (if toggle { 0x10 } else { 0 }) | (unused << 1) | (if last { 1 } else { 0 })
            }
            Self::InitiateDownload {
                size_indicated,
                expedited,
                unused,
                complete_access,
            } => {
                if unused > 3 {
                    return Err(WireError::InvalidField("sdo expedited size"));
                }
                0x20 | (if complete_access { 0x10 } else { 0 })
                    | (unused << 2)
                    | (if expedited { 2 } else { 0 })
                    | (if size_indicated { 1 } else { 0 })
            }
            Self::InitiateUpload { complete_access } => {
                0x40 | if complete_access { 0x10 } else { 0 }
            }
            Self::UploadSegment { toggle } => 0x60 | if toggle { 0x10 } else { 0 },
            Self::Abort => 0x80,
        })
    }
}

/// The command specifier of an SDO response (server → client), decoded from the command byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SdoResponseCommand {
    /// scs 0: upload segment response carrying data.
    UploadSegment {
        /// The toggle bit, echoing the request.
        toggle: bool,
        /// No more segments follow.
        last: bool,
        /// Bytes of the minimum 7-byte segment that carry no data (3 bits).
        unused: u8,
    },
    /// scs 1: download segment response.
    DownloadSegment {
        /// The toggle bit, echoing the request.
        toggle: bool,
    },
    /// scs 2: initiate upload response.
    InitiateUpload {
        /// The size is indicated.
        size_indicated: bool,
        /// Expedited: the data (1..=4 bytes) is in the header.
        expedited: bool,
        /// For expedited transfers, data bytes of the 4 that carry no data (2 bits).
        unused: u8,
        /// Complete access (bit 4, set by some servers to echo the request).
        complete_access: bool,
    },
    /// scs 3: initiate download response.
    InitiateDownload,
    /// 4: abort transfer.
    Abort,
}

impl SdoResponseCommand {
    /// Decodes a response command byte; specifiers 5..=7 are errors.
    pub const fn from_u8(b: u8) -> Result<Self, WireError> {
        Ok(match b >> 5 {
            0 => Self::UploadSegment {
                toggle: b & 0x10 != 0,
                last: b & 0x01 != 0,
                unused: (b >> 1) & 0x7,
            },
            1 => Self::DownloadSegment {
                toggle: b & 0x10 != 0,
            },
            2 => Self::InitiateUpload {
                size_indicated: b & 0x01 != 0,
                expedited: b & 0x02 != 0,
                unused: (b >> 2) & 0x3,
                complete_access: b & 0x10 != 0,
            },
            3 => Self::InitiateDownload,
            4 => Self::Abort,
            o => return Err(WireError::UnknownType(o)),
        })
    }

    /// Encodes the command byte; fields out of their bit range are an error.
    pub const fn to_u8(self) -> Result<u8, WireError> {
        Ok(match self {
            Self::UploadSegment {
                toggle,
                last,
                unused,
            } => {
                if unused > 7 {
                    return Err(WireError::InvalidField("sdo segment size"));
                }
                (if toggle { 0x10 } else { 0 }) | (unused << 1) | (if last { 1 } else { 0 })
            }
            Self::DownloadSegment { toggle } => 0x20 | if toggle { 0x10 } else { 0 },
            Self::InitiateUpload {
                size_indicated,
                expedited,
                unused,
                complete_access,
            } => {
                if unused > 3 {
                    return Err(WireError::InvalidField("sdo expedited size"));
                }
                0x40 | (if complete_access { 0x10 } else { 0 })
                    | (unused << 2)
                    | (if expedited { 2 } else { 0 })
                    | (if size_indicated { 1 } else { 0 })
            }
            Self::InitiateDownload => 0x60,
            Self::Abort => 0x80,
        })
    }
}

/// The 4-byte SDO header of initiate and abort messages: command byte, index, subindex.
///
/// The command byte is kept raw because its meaning depends on the direction; decode it with
/// [`SdoHeader::request`] or [`SdoHeader::response`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SdoHeader {
    /// The raw command byte.
    pub command: u8,
    /// Object index.
    pub index: u16,
    /// Object subindex.
    pub subindex: u8,
}

impl SdoHeader {
    /// Parses the header from the first 4 bytes of `buf` (after the CoE header).
    pub fn parse(buf: &[u8]) -> Result<Self, WireError> {
        need(buf, SDO_HEADER_LEN)?;
        Ok(Self {
            command: buf[0],
            index: u16::from_le_bytes([buf[1], buf[2]]),
            subindex: buf[3],
        })
    }

    /// Writes the header into the first 4 bytes of `buf`.
    pub fn write(&self, buf: &mut [u8]) -> Result<usize, WireError> {
        if buf.len() < SDO_HEADER_LEN {
            return Err(WireError::BufferFull);
        }
        buf[0] = self.command;
        buf[1..3].copy_from_slice(&self.index.to_le_bytes());
        buf[3] = self.subindex;
        Ok(SDO_HEADER_LEN)
    }

    /// The command byte read as a request.
    pub const fn request(&self) -> Result<SdoRequestCommand, WireError> {
        SdoRequestCommand::from_u8(self.command)
    }

    /// The command byte read as a response.
    pub const fn response(&self) -> Result<SdoResponseCommand, WireError> {
        SdoResponseCommand::from_u8(self.command)
    }
}

/// A view of an SDO message (CoE service 2 or 3) in a mailbox's service data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SdoRef<'a> {
    /// The CoE header.
    pub coe: CoeHeader,
    /// The command byte.
    pub command: u8,
    /// Everything after the command byte: index, subindex and data for initiate and abort
    /// messages, segment data for segment messages.
    pub rest: &'a [u8],
}

impl<'a> SdoRef<'a> {
    /// Parses the CoE header and SDO command byte of `payload` (the mailbox service data).
    pub fn parse(payload: &'a [u8]) -> Result<Self, WireError> {
        let coe = CoeHeader::parse(payload)?;
        match coe.service {
            CoeService::SdoRequest | CoeService::SdoResponse => {}
            other => return Err(WireError::UnknownType(other.code())),
        }
        need(payload, COE_HEADER_LEN + 1)?;
        Ok(Self {
            coe,
            command: payload[COE_HEADER_LEN],
            rest: &payload[COE_HEADER_LEN + 1..],
        })
    }

    /// True for a request (CoE service 2).
    pub fn is_request(&self) -> bool {
        self.coe.service == CoeService::SdoRequest
    }

    /// Index and subindex of an initiate or abort message.
    pub fn index(&self) -> Result<(u16, u8), WireError> {
        need(self.rest, 3)?;
        Ok((
            u16::from_le_bytes([self.rest[0], self.rest[1]]),
            self.rest[2],
        ))
    }

    /// The 4 data bytes of an initiate or abort message (expedited data, complete size or
    /// abort code).
    pub fn header_data(&self) -> Result<[u8; 4], WireError> {
        need(self.rest, 7)?;
        Ok([self.rest[3], self.rest[4], self.rest[5], self.rest[6]])
    }

    /// The data of an expedited transfer: `4 - unused` bytes (or all 4 without size).
    pub fn expedited_data(&self) -> Result<&'a [u8], WireError> {
        need(self.rest, 7)?;
        let (size_indicated, unused) = if self.is_request() {
            match SdoRequestCommand::from_u8(self.command)? {
                SdoRequestCommand::InitiateDownload {
                    expedited: true,
                    size_indicated,
                    unused,
                    ..
                } => (size_indicated, unused),
                _ => return Err(WireError::InvalidField("sdo not expedited")),
            }
        } else {
            match SdoResponseCommand::from_u8(self.command)? {
                SdoResponseCommand::InitiateUpload {
                    expedited: true,
                    size_indicated,
                    unused,
                    ..
                } => (size_indicated, unused),
                _ => return Err(WireError::InvalidField("sdo not expedited")),
            }
        };
        let n = if size_indicated {
            4 - unused as usize
        } else {
            4
        };
        Ok(&self.rest[3..3 + n])
    }

    /// For a normal (non-expedited) initiate: the complete size and the data that follows it.
    pub fn normal_data(&self) -> Result<(u32, &'a [u8]), WireError> {
        let d = self.header_data()?;
        Ok((u32::from_le_bytes(d), &self.rest[7..]))
    }

    /// The data of a segment message, trimmed by the command's `unused` count (which only
    /// applies to the 7-byte minimum segment).
    pub fn segment_data(&self) -> Result<&'a [u8], WireError> {
        let unused = (self.command >> 1) & 0x7;
        if unused == 0 {
            return Ok(self.rest);
        }
        need(self.rest, 7)?;
        Ok(&self.rest[..7 - unused as usize])
    }

    /// The abort code of an abort message.
    pub fn abort_code(&self) -> Result<SdoAbortCode, WireError> {
        Ok(SdoAbortCode::from_u32(u32::from_le_bytes(
            self.header_data()?,
        )))
    }
}

/// Writes the CoE service data of an SDO initiate or abort message: CoE header, SDO header
/// and the 4 header data bytes, followed by `data`; returns the length (the mailbox length).
pub fn write_sdo(
    buf: &mut [u8],
    service: CoeService,
    header: &SdoHeader,
    header_data: [u8; 4],
    data: &[u8],
) -> Result<usize, WireError> {
    let total = SDO_EXPEDITED_LEN + data.len();
    if buf.len() < total {
        return Err(WireError::BufferFull);
    }
    CoeHeader::new(service).write(buf)?;
    header.write(&mut buf[COE_HEADER_LEN..])?;
    buf[6..10].copy_from_slice(&header_data);
    buf[10..total].copy_from_slice(data);
    Ok(total)
}

/// Writes the CoE service data of an SDO segment message: CoE header, command byte and
/// `data` padded with zeros to the 7-byte minimum; returns the length.
pub fn write_sdo_segment(
    buf: &mut [u8],
    service: CoeService,
    command: u8,
    data: &[u8],
) -> Result<usize, WireError> {
    let total = COE_HEADER_LEN + 1 + data.len().max(7);
    if buf.len() < total {
        return Err(WireError::BufferFull);
    }
    CoeHeader::new(service).write(buf)?;
    buf[2] = command;
    buf[3..3 + data.len()].copy_from_slice(data);
    buf[3 + data.len()..total].fill(0);
    Ok(total)
}

/// Writes an SDO abort transfer for `index:subindex`; returns the length.
///
/// Client and server abort alike under CoE service 2 (SDO request): ETG.1000.6 defines
/// the abort as a request in either direction, and SOEM, SSC and SOES recognise it only
/// there (an abort under service 3 reads to SOEM as a successful transfer), so the service
/// is not a parameter.
pub fn write_sdo_abort(
    buf: &mut [u8],
    index: u16,
    subindex: u8,
    code: SdoAbortCode,
) -> Result<usize, WireError> {
    write_sdo(
        buf,
        CoeService::SdoRequest,
        &SdoHeader {
            command: 0x80,
            index,
            subindex,
        },
        code.code().to_le_bytes(),
        &[],
    )
}

macro_rules! abort_codes {
    ($( $(#[$m:meta])* $name:ident = $code:literal, $text:literal; )*) => {
        /// The standard SDO abort codes of CiA 301 / ETG.1000.6.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum SdoAbortCode {
            $( $(#[$m])* $name, )*
            /// A code not in the standard list.
            Other(u32),
        }

        impl SdoAbortCode {
            /// Every standard code, in numeric order.
            pub const ALL: &'static [SdoAbortCode] = &[$( SdoAbortCode::$name, )*];

            /// Decodes a 32-bit abort code.
            pub const fn from_u32(v: u32) -> Self {
                match v {
                    $( $code => Self::$name, )*
                    o => Self::Other(o),
                }
            }

            /// The 32-bit abort code. A standard code is read from a table by the
            /// variant's position (a match on the codes compiles to a jump table with a
            /// load per code: 256 B of a board image's flash instead of 160).
            pub const fn code(self) -> u32 {
                /// The positions of the standard codes.
                #[allow(clippy::enum_variant_names)]
                enum Pos { $( $name, )* }
                const CODES: &[u32] = &[$( $code, )*];
                let i = match self {
                    $( Self::$name => Pos::$name as usize, )*
                    Self::Other(o) => return o,
                };
                CODES[i]
            }

            /// The standard description.
            pub const fn text(self) -> &'static str {
                match self {
                    $( Self::$name => $text, )*
                    Self::Other(_) => "unknown SDO abort code",
                }
            }
        }
    };
}

abort_codes! {
    /// 0x05030000.
    ToggleBit = 0x0503_0000, "Toggle bit not changed";
    /// 0x05040000.
    Timeout = 0x0504_0000, "SDO protocol timeout";
    /// 0x05040001.
    InvalidCommand = 0x0504_0001, "Client/Server command specifier not valid or unknown";
    /// 0x05040002.
    InvalidBlockSize = 0x0504_0002, "Invalid block size (block mode only)";
    /// 0x05040003.
    InvalidSequenceNumber = 0x0504_0003, "Invalid sequence number (block mode only)";
    /// 0x05040004.
    CrcError = 0x0504_0004, "CRC error (block mode only)";
    /// 0x05040005.
    OutOfMemory = 0x0504_0005, "Out of memory";
    /// 0x06010000.
    UnsupportedAccess = 0x0601_0000, "Unsupported access to an object";
    /// 0x06010001.
    WriteOnly = 0x0601_0001, "Attempt to read a write only object";
    /// 0x06010002.
    ReadOnly = 0x0601_0002, "Attempt to write a read only object";
    /// 0x06010003.
    SubindexCannotBeWritten = 0x0601_0003, "Subindex cannot be written, SI0 must be 0 for write access";
    /// 0x06010004.
    CompleteAccessUnsupported = 0x0601_0004, "SDO Complete access not supported for objects of variable length such as ENUM object types";
    /// 0x06010005.
    ObjectTooLong = 0x0601_0005, "Object length exceeds mailbox size";
    /// 0x06010006.
    MappedToRxPdo = 0x0601_0006, "Object mapped to RxPDO, SDO Download blocked";
    /// 0x06020000.
    ObjectDoesNotExist = 0x0602_0000, "The object does not exist in the object directory";
    /// 0x06040041.
    CannotMap = 0x0604_0041, "The object can not be mapped into the PDO";
    /// 0x06040042.
    PdoLengthExceeded = 0x0604_0042, "The number and length of the objects to be mapped would exceed the PDO length";
    /// 0x06040043.
    ParameterIncompatible = 0x0604_0043, "General parameter incompatibility reason";
    /// 0x06040047.
    DeviceIncompatible = 0x0604_0047, "General internal incompatibility in the device";
    /// 0x06060000.
    HardwareError = 0x0606_0000, "Access failed due to a hardware error";
    /// 0x06070010.
    LengthMismatch = 0x0607_0010, "Data type does not match, length of service parameter does not match";
    /// 0x06070012.
    LengthTooHigh = 0x0607_0012, "Data type does not match, length of service parameter too high";
    /// 0x06070013.
    LengthTooLow = 0x0607_0013, "Data type does not match, length of service parameter too low";
    /// 0x06090011.
    SubindexDoesNotExist = 0x0609_0011, "Subindex does not exist";
    /// 0x06090030.
    ValueRangeExceeded = 0x0609_0030, "Value range of parameter exceeded (only for write access)";
    /// 0x06090031.
    ValueTooHigh = 0x0609_0031, "Value of parameter written too high";
    /// 0x06090032.
    ValueTooLow = 0x0609_0032, "Value of parameter written too low";
    /// 0x06090036.
    MaxLessThanMin = 0x0609_0036, "Maximum value is less than minimum value";
    /// 0x060A0023.
    ResourceNotAvailable = 0x060A_0023, "Resource not available: SDO connection";
    /// 0x08000000.
    GeneralError = 0x0800_0000, "General error";
    /// 0x08000020.
    CannotTransfer = 0x0800_0020, "Data cannot be transferred or stored to the application";
    /// 0x08000021.
    CannotTransferLocalControl = 0x0800_0021, "Data cannot be transferred or stored to the application because of local control";
    /// 0x08000022.
    CannotTransferDeviceState = 0x0800_0022, "Data cannot be transferred or stored to the application because of the present device state";
    /// 0x08000023.
    NoObjectDictionary = 0x0800_0023, "Object dictionary dynamic generation fails or no object dictionary is present";
    /// 0x08000024.
    NoDataAvailable = 0x0800_0024, "No data available";
}

impl core::fmt::Display for SdoAbortCode {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{:#010x}: {}", self.code(), self.text())
    }
}

/// The SDO information service (7-bit opcode of the SDO information header).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SdoInfoOpcode {
    /// 1: get OD list request.
    GetOdListRequest,
    /// 2: get OD list response.
    GetOdListResponse,
    /// 3: get object description request.
    GetObjectDescriptionRequest,
    /// 4: get object description response.
    GetObjectDescriptionResponse,
    /// 5: get entry description request.
    GetEntryDescriptionRequest,
    /// 6: get entry description response.
    GetEntryDescriptionResponse,
    /// 7: SDO information error request.
    Error,
    /// A reserved opcode.
    Reserved(u8),
}

impl SdoInfoOpcode {
    /// Decodes the low 7 bits of `v`.
    pub const fn from_u8(v: u8) -> Self {
        match v & 0x7F {
            1 => Self::GetOdListRequest,
            2 => Self::GetOdListResponse,
            3 => Self::GetObjectDescriptionRequest,
            4 => Self::GetObjectDescriptionResponse,
            5 => Self::GetEntryDescriptionRequest,
            6 => Self::GetEntryDescriptionResponse,
            7 => Self::Error,
            o => Self::Reserved(o),
        }
    }

    /// The 7-bit code: a named opcode's is its position + 1 (computed, see
    /// [`CoeService::code`]).
    pub const fn code(self) -> u8 {
        1 + match self {
            Self::GetOdListRequest => 0,
            Self::GetOdListResponse => 1,
            Self::GetObjectDescriptionRequest => 2,
            Self::GetObjectDescriptionResponse => 3,
            Self::GetEntryDescriptionRequest => 4,
            Self::GetEntryDescriptionResponse => 5,
            Self::Error => 6,
            Self::Reserved(o) => return o & 0x7F,
        }
    }
}

/// The 4-byte SDO information header after the CoE header.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SdoInfoHeader {
    /// The service.
    pub opcode: SdoInfoOpcode,
    /// More fragments of this response follow.
    pub incomplete: bool,
    /// The reserved byte, kept for round trips.
    pub reserved: u8,
    /// Fragments still to come.
    pub fragments_left: u16,
}

impl SdoInfoHeader {
    /// Parses the header from the first 4 bytes of `buf` (after the CoE header).
    pub fn parse(buf: &[u8]) -> Result<Self, WireError> {
        need(buf, SDO_INFO_HEADER_LEN)?;
        Ok(Self {
            opcode: SdoInfoOpcode::from_u8(buf[0]),
            incomplete: buf[0] & 0x80 != 0,
            reserved: buf[1],
            fragments_left: u16::from_le_bytes([buf[2], buf[3]]),
        })
    }

    /// Writes the header; an opcode out of range is an error.
    pub fn write(&self, buf: &mut [u8]) -> Result<usize, WireError> {
        if let SdoInfoOpcode::Reserved(r) = self.opcode {
            if SdoInfoOpcode::from_u8(r) != self.opcode || r > 0x7F {
                return Err(WireError::InvalidField("sdo info opcode"));
            }
        }
        if buf.len() < SDO_INFO_HEADER_LEN {
            return Err(WireError::BufferFull);
        }
        buf[0] = self.opcode.code() | if self.incomplete { 0x80 } else { 0 };
        buf[1] = self.reserved;
        buf[2..4].copy_from_slice(&self.fragments_left.to_le_bytes());
        Ok(SDO_INFO_HEADER_LEN)
    }
}

/// A view of an SDO information message: CoE header, info header and the service data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SdoInfoRef<'a> {
    /// The CoE header (service 8).
    pub coe: CoeHeader,
    /// The SDO information header.
    pub header: SdoInfoHeader,
    /// The service data after the header.
    pub data: &'a [u8],
}

impl<'a> SdoInfoRef<'a> {
    /// Parses an SDO information message from mailbox service data.
    pub fn parse(payload: &'a [u8]) -> Result<Self, WireError> {
        let coe = CoeHeader::parse(payload)?;
        if coe.service != CoeService::SdoInformation {
            return Err(WireError::UnknownType(coe.service.code()));
        }
        let header = SdoInfoHeader::parse(&payload[COE_HEADER_LEN..])?;
        Ok(Self {
            coe,
            header,
            data: &payload[COE_HEADER_LEN + SDO_INFO_HEADER_LEN..],
        })
    }

    /// Decodes the service data according to the opcode.
    pub fn service(&self) -> Result<SdoInfoService<'a>, WireError> {
        SdoInfoService::parse(self.header.opcode, self.data)
    }
}

/// The list types of a get OD list request.
pub mod od_list_type {
    /// Number of objects in each of the five lists.
    pub const LENGTHS: u16 = 0;
    /// All objects.
    pub const ALL: u16 = 1;
    /// Objects mappable into an RxPDO.
    pub const RX_PDO_MAPPABLE: u16 = 2;
    /// Objects mappable into a TxPDO.
    pub const TX_PDO_MAPPABLE: u16 = 3;
    /// Objects to be stored for a device replacement.
    pub const BACKUP: u16 = 4;
    /// Objects usable as startup parameters.
    pub const SETTINGS: u16 = 5;
}

/// The decoded service data of an SDO information message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SdoInfoService<'a> {
    /// Get OD list request: which list.
    GetOdListRequest {
        /// The list type (see [`od_list_type`]).
        list_type: u16,
    },
    /// Get OD list response fragment: raw little-endian u16 entries (in the first fragment
    /// the first entry is the list type).
    GetOdListResponse {
        /// The u16 words of this fragment.
        words: &'a [u8],
    },
    /// Get object description request.
    GetObjectDescriptionRequest {
        /// Object index.
        index: u16,
    },
    /// Get object description response.
    GetObjectDescriptionResponse {
        /// Object index.
        index: u16,
        /// Data type index.
        data_type: u16,
        /// Highest subindex.
        max_subindex: u8,
        /// Object code (7 VAR, 8 ARRAY, 9 RECORD).
        object_code: u8,
        /// The object's name.
        name: &'a [u8],
    },
    /// Get entry description request.
    GetEntryDescriptionRequest {
        /// Object index.
        index: u16,
        /// Subindex.
        subindex: u8,
        /// Which optional fields to return.
        value_info: u8,
    },
    /// Get entry description response.
    GetEntryDescriptionResponse {
        /// Object index.
        index: u16,
        /// Subindex.
        subindex: u8,
        /// Which optional fields follow.
        value_info: u8,
        /// Data type index.
        data_type: u16,
        /// Length in bits.
        bit_length: u16,
        /// Object access flags.
        object_access: u16,
        /// Optional fields (unit, default, min, max) and the name.
        data: &'a [u8],
    },
    /// SDO information error: an abort code.
    Error {
        /// The abort code.
        code: SdoAbortCode,
    },
}

impl<'a> SdoInfoService<'a> {
    /// Decodes `data` as the service data of `opcode`.
    pub fn parse(opcode: SdoInfoOpcode, data: &'a [u8]) -> Result<Self, WireError> {
        let u16at = |i: usize| u16::from_le_bytes([data[i], data[i + 1]]);
        Ok(match opcode {
            SdoInfoOpcode::GetOdListRequest => {
                need(data, 2)?;
                Self::GetOdListRequest {
                    list_type: u16at(0),
                }
            }
            SdoInfoOpcode::GetOdListResponse => {
                if data.len() & 1 != 0 {
                    return Err(WireError::InvalidField("od list length"));
                }
                Self::GetOdListResponse { words: data }
            }
            SdoInfoOpcode::GetObjectDescriptionRequest => {
                need(data, 2)?;
                Self::GetObjectDescriptionRequest { index: u16at(0) }
            }
            SdoInfoOpcode::GetObjectDescriptionResponse => {
                need(data, 6)?;
                Self::GetObjectDescriptionResponse {
                    index: u16at(0),
                    data_type: u16at(2),
                    max_subindex: data[4],
                    object_code: data[5],
                    name: &data[6..],
                }
            }
            SdoInfoOpcode::GetEntryDescriptionRequest => {
                need(data, 4)?;
                Self::GetEntryDescriptionRequest {
                    index: u16at(0),
                    subindex: data[2],
                    value_info: data[3],
                }
            }
            SdoInfoOpcode::GetEntryDescriptionResponse => {
                need(data, 10)?;
                Self::GetEntryDescriptionResponse {
                    index: u16at(0),
                    subindex: data[2],
                    value_info: data[3],
                    data_type: u16at(4),
                    bit_length: u16at(6),
                    object_access: u16at(8),
                    data: &data[10..],
                }
            }
            SdoInfoOpcode::Error => {
                need(data, 4)?;
                Self::Error {
                    code: SdoAbortCode::from_u32(u32::from_le_bytes([
                        data[0], data[1], data[2], data[3],
                    ])),
                }
            }
            SdoInfoOpcode::Reserved(o) => return Err(WireError::UnknownType(o)),
        })
    }

    /// The opcode of this service.
    pub const fn opcode(&self) -> SdoInfoOpcode {
        match self {
            Self::GetOdListRequest { .. } => SdoInfoOpcode::GetOdListRequest,
            Self::GetOdListResponse { .. } => SdoInfoOpcode::GetOdListResponse,
            Self::GetObjectDescriptionRequest { .. } => SdoInfoOpcode::GetObjectDescriptionRequest,
            Self::GetObjectDescriptionResponse { .. } => {
                SdoInfoOpcode::GetObjectDescriptionResponse
            }
            Self::GetEntryDescriptionRequest { .. } => SdoInfoOpcode::GetEntryDescriptionRequest,
            Self::GetEntryDescriptionResponse { .. } => SdoInfoOpcode::GetEntryDescriptionResponse,
            Self::Error { .. } => SdoInfoOpcode::Error,
        }
    }

    /// Writes the service data into `buf`; returns its length.
    pub fn write(&self, buf: &mut [u8]) -> Result<usize, WireError> {
        let mut fixed = [0u8; 10];
        let (n, tail): (usize, &[u8]) = match *self {
            Self::GetOdListRequest { list_type } => {
                fixed[..2].copy_from_slice(&list_type.to_le_bytes());
                (2, &[])
            }
            Self::GetOdListResponse { words } => {
                if words.len() & 1 != 0 {
                    return Err(WireError::InvalidField("od list length"));
                }
                (0, words)
            }
            Self::GetObjectDescriptionRequest { index } => {
                fixed[..2].copy_from_slice(&index.to_le_bytes());
                (2, &[])
            }
            Self::GetObjectDescriptionResponse {
                index,
                data_type,
                max_subindex,
                object_code,
                name,
            } => {
                fixed[..2].copy_from_slice(&index.to_le_bytes());
                fixed[2..4].copy_from_slice(&data_type.to_le_bytes());
                fixed[4] = max_subindex;
                fixed[5] = object_code;
                (6, name)
            }
            Self::GetEntryDescriptionRequest {
                index,
                subindex,
                value_info,
            } => {
                fixed[..2].copy_from_slice(&index.to_le_bytes());
                fixed[2] = subindex;
                fixed[3] = value_info;
                (4, &[])
            }
            Self::GetEntryDescriptionResponse {
                index,
                subindex,
                value_info,
                data_type,
                bit_length,
                object_access,
                data,
            } => {
                fixed[..2].copy_from_slice(&index.to_le_bytes());
                fixed[2] = subindex;
                fixed[3] = value_info;
                fixed[4..6].copy_from_slice(&data_type.to_le_bytes());
                fixed[6..8].copy_from_slice(&bit_length.to_le_bytes());
                fixed[8..10].copy_from_slice(&object_access.to_le_bytes());
                (10, data)
            }
            Self::Error { code } => {
                fixed[..4].copy_from_slice(&code.code().to_le_bytes());
                (4, &[])
            }
        };
        let total = n + tail.len();
        if buf.len() < total {
            return Err(WireError::BufferFull);
        }
        buf[..n].copy_from_slice(&fixed[..n]);
        buf[n..total].copy_from_slice(tail);
        Ok(total)
    }
}

/// A CoE emergency message (after the CoE header).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Emergency {
    /// CiA 301 emergency error code.
    pub error_code: u16,
    /// The error register (object 0x1001).
    pub error_register: u8,
    /// Manufacturer-specific data.
    pub data: [u8; 5],
}

impl Emergency {
    /// Parses the 8 bytes after the CoE header.
    pub fn parse(buf: &[u8]) -> Result<Self, WireError> {
        need(buf, EMERGENCY_LEN)?;
        let mut data = [0; 5];
        data.copy_from_slice(&buf[3..8]);
        Ok(Self {
            error_code: u16::from_le_bytes([buf[0], buf[1]]),
            error_register: buf[2],
            data,
        })
    }

    /// Parses a whole emergency message from mailbox service data (CoE header included).
    pub fn parse_coe(payload: &[u8]) -> Result<Self, WireError> {
        let coe = CoeHeader::parse(payload)?;
        if coe.service != CoeService::Emergency {
            return Err(WireError::UnknownType(coe.service.code()));
        }
        Self::parse(&payload[COE_HEADER_LEN..])
    }

    /// Writes the 8 bytes after the CoE header.
    pub fn write(&self, buf: &mut [u8]) -> Result<usize, WireError> {
        if buf.len() < EMERGENCY_LEN {
            return Err(WireError::BufferFull);
        }
        buf[0..2].copy_from_slice(&self.error_code.to_le_bytes());
        buf[2] = self.error_register;
        buf[3..8].copy_from_slice(&self.data);
        Ok(EMERGENCY_LEN)
    }

    /// Writes CoE header (service 1) and message; returns 10.
    pub fn write_coe(&self, buf: &mut [u8]) -> Result<usize, WireError> {
        if buf.len() < COE_HEADER_LEN + EMERGENCY_LEN {
            return Err(WireError::BufferFull);
        }
        CoeHeader::new(CoeService::Emergency).write(buf)?;
        self.write(&mut buf[COE_HEADER_LEN..])?;
        Ok(COE_HEADER_LEN + EMERGENCY_LEN)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn expedited_upload_response() {
        // SOEM-style upload response of 0x1018:01 = 2 (vendor id), 4 bytes.
        let p = [0x00, 0x30, 0x43, 0x18, 0x10, 0x01, 0x02, 0x00, 0x00, 0x00];
        let s = SdoRef::parse(&p).unwrap();
        assert!(!s.is_request());
        assert_eq!(s.index().unwrap(), (0x1018, 1));
        assert_eq!(
            SdoResponseCommand::from_u8(s.command).unwrap(),
            SdoResponseCommand::InitiateUpload {
                size_indicated: true,
                expedited: true,
                unused: 0,
                complete_access: false
            }
        );
        assert_eq!(s.expedited_data().unwrap(), &[2, 0, 0, 0]);
    }

    #[test]
    fn abort_round_trip() {
        let mut b = [0u8; 10];
        let n = write_sdo_abort(&mut b, 0x6040, 0, SdoAbortCode::ReadOnly).unwrap();
        let s = SdoRef::parse(&b[..n]).unwrap();
        assert_eq!(s.abort_code().unwrap(), SdoAbortCode::ReadOnly);
        assert_eq!(s.abort_code().unwrap().code(), 0x0601_0002);
        for c in SdoAbortCode::ALL {
            assert_eq!(SdoAbortCode::from_u32(c.code()), *c);
        }
        assert_eq!(SdoAbortCode::ALL.len(), 35);
    }

    #[test]
    fn segment_trim() {
        let mut b = [0u8; 10];
        let cmd = SdoRequestCommand::DownloadSegment {
            toggle: true,
            last: true,
            unused: 4,
        }
        .to_u8()
        .unwrap();
        let n = write_sdo_segment(&mut b, CoeService::SdoRequest, cmd, &[1, 2, 3]).unwrap();
        assert_eq!(n, 10);
        let s = SdoRef::parse(&b[..n]).unwrap();
        assert_eq!(s.segment_data().unwrap(), &[1, 2, 3]);
    }
}
