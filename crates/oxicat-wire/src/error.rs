//! The error type shared by all parsers and builders.

/// Why a byte sequence is not a valid instance of the format asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WireError {
    /// Fewer bytes than the format's fixed part needs.
    Truncated {
        /// Bytes needed.
        needed: usize,
        /// Bytes available.
        available: usize,
    },
    /// The EtherType is neither EtherCAT (0x88A4) nor a VLAN tag carrying it.
    NotEtherCat(u16),
    /// A length field disagrees with the bytes that follow it.
    LengthMismatch {
        /// Length declared by the header.
        declared: usize,
        /// Bytes actually present.
        available: usize,
    },
    /// A frame type / protocol type / command code that this format does not define.
    UnknownType(u8),
    /// A value in a field is outside the range the format allows.
    InvalidField(&'static str),
    /// A builder ran out of buffer space.
    BufferFull,
}

impl core::fmt::Display for WireError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            WireError::Truncated { needed, available } => {
                write!(f, "truncated: need {needed} bytes, have {available}")
            }
            WireError::NotEtherCat(t) => write!(f, "EtherType {t:#06x} is not EtherCAT"),
            WireError::LengthMismatch {
                declared,
                available,
            } => write!(f, "length field says {declared} bytes, {available} present"),
            WireError::UnknownType(t) => write!(f, "unknown type code {t:#04x}"),
            WireError::InvalidField(n) => write!(f, "invalid value in field {n}"),
            WireError::BufferFull => write!(f, "buffer too small"),
        }
    }
}

impl core::error::Error for WireError {}

/// Returns `Err(Truncated)` unless `buf` holds at least `needed` bytes.
#[inline]
pub(crate) fn need(buf: &[u8], needed: usize) -> Result<(), WireError> {
    if buf.len() < needed {
        Err(WireError::Truncated {
            needed,
            available: buf.len(),
        })
    } else {
        Ok(())
    }
}
