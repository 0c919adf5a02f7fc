//! Typed values for SDO and PDO access: parse a command-line value for a type, format bytes
//! read from a slave.

use crate::MasterError;

/// A value type the tool reads and writes (CoE basic data types).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ValueType {
    /// BOOL, one bit (in PDOs) or one byte (SDO).
    Bool,
    /// UNSIGNED8.
    U8,
    /// UNSIGNED16.
    U16,
    /// UNSIGNED32.
    U32,
    /// UNSIGNED64.
    U64,
    /// INTEGER8.
    I8,
    /// INTEGER16.
    I16,
    /// INTEGER32.
    I32,
    /// INTEGER64.
    I64,
    /// REAL32.
    F32,
    /// REAL64.
    F64,
    /// VISIBLE_STRING.
    String,
    /// OCTET_STRING / raw bytes, shown and given as hex.
    Hex,
}

impl ValueType {
    /// All type names accepted by `--type`.
    pub const NAMES: &'static str =
        "bool, u8, u16, u32, u64, i8, i16, i32, i64, f32, f64, string, hex";

    /// Parses a type name (`u16`, `int32`, `REAL`, `string`, `hex`, …).
    pub fn parse(s: &str) -> Result<Self, MasterError> {
        Ok(match s.to_ascii_lowercase().as_str() {
            "bool" | "bit" => Self::Bool,
            "u8" | "uint8" | "usint" | "byte" => Self::U8,
            "u16" | "uint16" | "uint" | "word" => Self::U16,
            "u32" | "uint32" | "udint" | "dword" => Self::U32,
            "u64" | "uint64" | "ulint" => Self::U64,
            "i8" | "int8" | "sint" => Self::I8,
            "i16" | "int16" | "int" => Self::I16,
            "i32" | "int32" | "dint" => Self::I32,
            "i64" | "int64" | "lint" => Self::I64,
            "f32" | "real" | "real32" | "float" => Self::F32,
            "f64" | "lreal" | "real64" | "double" => Self::F64,
            "string" | "str" | "visible_string" => Self::String,
            "hex" | "bytes" | "octet_string" | "raw" => Self::Hex,
            _ => {
                return Err(MasterError::UnknownType(s.to_string()));
            }
        })
    }

    /// The type of a CoE data type code (0x0001 BOOL …), if it is a basic type.
    pub fn from_coe(code: u16) -> Option<Self> {
        Some(match code {
            0x0001 => Self::Bool,
            0x0002 => Self::I8,
            0x0003 => Self::I16,
            0x0004 => Self::I32,
            0x0005 => Self::U8,
            0x0006 => Self::U16,
            0x0007 => Self::U32,
            0x0008 => Self::F32,
            0x0009 => Self::String,
            0x000A | 0x000B => Self::Hex,
            0x0011 => Self::F64,
            0x0015 => Self::I64,
            0x001B => Self::U64,
            _ => return None,
        })
    }

    /// A guess from a bit length alone (unsigned).
    pub fn from_bits(bits: u16) -> Self {
        match bits {
            1 => Self::Bool,
            8 => Self::U8,
            16 => Self::U16,
            32 => Self::U32,
            64 => Self::U64,
            _ => Self::Hex,
        }
    }

    /// Size in bytes of a fixed-size type (strings and hex: none).
    pub fn size(self) -> Option<usize> {
        Some(match self {
            Self::Bool | Self::U8 | Self::I8 => 1,
            Self::U16 | Self::I16 => 2,
            Self::U32 | Self::I32 | Self::F32 => 4,
            Self::U64 | Self::I64 | Self::F64 => 8,
            Self::String | Self::Hex => return None,
        })
    }

    /// The CoE data type code of the type.
    pub fn code(self) -> u16 {
        match self {
            Self::Bool => 0x0001,
            Self::I8 => 0x0002,
            Self::I16 => 0x0003,
            Self::I32 => 0x0004,
            Self::U8 => 0x0005,
            Self::U16 => 0x0006,
            Self::U32 => 0x0007,
            Self::F32 => 0x0008,
            Self::String => 0x0009,
            Self::Hex => 0x000A,
            Self::F64 => 0x0011,
            Self::I64 => 0x0015,
            Self::U64 => 0x001B,
        }
    }

    /// The ETG name of the type (as in ESI files), from `oxicat_wire::datatype`.
    pub fn esi_name(self) -> &'static str {
        oxicat_wire::datatype::by_code(self.code()).map_or("?", |d| d.name)
    }

    /// Encodes `text` as this type (little-endian); an error names the value and the type.
    pub fn encode(self, text: &str) -> Result<Vec<u8>, MasterError> {
        let bad = |why: &str| MasterError::BadValue {
            value: text.to_string(),
            ty: self,
            why: why.to_string(),
        };
        let t = text.trim();
        macro_rules! int {
            ($t:ty) => {{
                let v = parse_int(t).ok_or_else(|| bad("not an integer"))?;
                let v = <$t>::try_from(v)
                    .map_err(|_| bad(&format!("out of range {}..={}", <$t>::MIN, <$t>::MAX)))?;
                v.to_le_bytes().to_vec()
            }};
        }
        Ok(match self {
            Self::Bool => match t.to_ascii_lowercase().as_str() {
                "1" | "true" | "on" => vec![1],
                "0" | "false" | "off" => vec![0],
                _ => return Err(bad("expected 0/1/true/false")),
            },
            Self::U8 => int!(u8),
            Self::U16 => int!(u16),
            Self::U32 => int!(u32),
            Self::U64 => int!(u64),
            Self::I8 => int!(i8),
            Self::I16 => int!(i16),
            Self::I32 => int!(i32),
            Self::I64 => int!(i64),
            Self::F32 => {
                let v: f32 = t.parse().map_err(|_| bad("not a number"))?;
                v.to_le_bytes().to_vec()
            }
            Self::F64 => {
                let v: f64 = t.parse().map_err(|_| bad("not a number"))?;
                v.to_le_bytes().to_vec()
            }
            Self::String => text.as_bytes().to_vec(),
            Self::Hex => {
                parse_hex(t).ok_or_else(|| bad("expected hex bytes like 01:ab:ff or 01ABFF"))?
            }
        })
    }

    /// Formats bytes read from a slave as this type (too short data is shown as hex).
    pub fn format(self, b: &[u8]) -> String {
        fn arr<const N: usize>(b: &[u8]) -> Option<[u8; N]> {
            b.get(..N).and_then(|s| s.try_into().ok())
        }
        let r = match self {
            Self::Bool => b.first().map(|v| (v & 1).to_string()),
            Self::U8 => arr::<1>(b).map(|a| format!("{0} (0x{0:02x})", u8::from_le_bytes(a))),
            Self::U16 => arr::<2>(b).map(|a| format!("{0} (0x{0:04x})", u16::from_le_bytes(a))),
            Self::U32 => arr::<4>(b).map(|a| format!("{0} (0x{0:08x})", u32::from_le_bytes(a))),
            Self::U64 => arr::<8>(b).map(|a| format!("{0} (0x{0:016x})", u64::from_le_bytes(a))),
            Self::I8 => arr::<1>(b).map(|a| i8::from_le_bytes(a).to_string()),
            Self::I16 => arr::<2>(b).map(|a| i16::from_le_bytes(a).to_string()),
            Self::I32 => arr::<4>(b).map(|a| i32::from_le_bytes(a).to_string()),
            Self::I64 => arr::<8>(b).map(|a| i64::from_le_bytes(a).to_string()),
            Self::F32 => arr::<4>(b).map(|a| f32::from_le_bytes(a).to_string()),
            Self::F64 => arr::<8>(b).map(|a| f64::from_le_bytes(a).to_string()),
            Self::String => {
                let end = b.iter().position(|&c| c == 0).unwrap_or(b.len());
                Some(String::from_utf8_lossy(&b[..end]).into_owned())
            }
            Self::Hex => None,
        };
        r.unwrap_or_else(|| hex(b))
    }

    /// True for the integer types (not BOOL, reals, strings, bytes).
    pub const fn is_integer(self) -> bool {
        matches!(
            self,
            Self::U8
                | Self::U16
                | Self::U32
                | Self::U64
                | Self::I8
                | Self::I16
                | Self::I32
                | Self::I64
        )
    }

    /// The integer in `b` if this is an integer type (sign-extended for signed types).
    pub fn integer(self, b: &[u8]) -> Option<i128> {
        fn arr<const N: usize>(b: &[u8]) -> Option<[u8; N]> {
            b.get(..N).and_then(|s| s.try_into().ok())
        }
        Some(match self {
            Self::Bool => i128::from(b.first()? & 1),
            Self::U8 => i128::from(u8::from_le_bytes(arr(b)?)),
            Self::U16 => i128::from(u16::from_le_bytes(arr(b)?)),
            Self::U32 => i128::from(u32::from_le_bytes(arr(b)?)),
            Self::U64 => i128::from(u64::from_le_bytes(arr(b)?)),
            Self::I8 => i128::from(i8::from_le_bytes(arr(b)?)),
            Self::I16 => i128::from(i16::from_le_bytes(arr(b)?)),
            Self::I32 => i128::from(i32::from_le_bytes(arr(b)?)),
            Self::I64 => i128::from(i64::from_le_bytes(arr(b)?)),
            _ => return None,
        })
    }

    /// The plain value (no hex in brackets), for CSV and watch lines.
    pub fn format_plain(self, b: &[u8]) -> String {
        let s = self.format(b);
        match s.split_once(" (0x") {
            Some((v, _)) => v.to_string(),
            None => s,
        }
    }
}

impl std::fmt::Display for ValueType {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let s = match self {
            Self::Bool => "bool",
            Self::U8 => "u8",
            Self::U16 => "u16",
            Self::U32 => "u32",
            Self::U64 => "u64",
            Self::I8 => "i8",
            Self::I16 => "i16",
            Self::I32 => "i32",
            Self::I64 => "i64",
            Self::F32 => "f32",
            Self::F64 => "f64",
            Self::String => "string",
            Self::Hex => "hex",
        };
        f.write_str(s)
    }
}

/// Parses a decimal, `0x` hex, `0b` binary or negative integer into an i128.
pub fn parse_int(s: &str) -> Option<i128> {
    let s = s.trim().replace('_', "");
    let (neg, s) = match s.strip_prefix('-') {
        Some(r) => (true, r.to_string()),
        None => (false, s),
    };
    let v = if let Some(h) = s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        i128::from_str_radix(h, 16).ok()?
    } else if let Some(b) = s.strip_prefix("0b") {
        i128::from_str_radix(b, 2).ok()?
    } else {
        s.parse::<i128>().ok()?
    };
    Some(if neg { -v } else { v })
}

/// Parses a `u16` index/address written in hex (`0x1018`, `1018h`) or decimal.
pub fn parse_u16(s: &str) -> Option<u16> {
    let t = s.trim();
    if let Some(h) = t.strip_suffix('h').or_else(|| t.strip_suffix('H')) {
        return u16::from_str_radix(h, 16).ok();
    }
    parse_int(t).and_then(|v| u16::try_from(v).ok())
}

/// Parses hex bytes: `01:ab:ff`, `01 ab ff` or `01abff` (optionally `0x`-prefixed).
pub fn parse_hex(s: &str) -> Option<Vec<u8>> {
    let t: String = s
        .trim()
        .trim_start_matches("0x")
        .chars()
        .filter(|c| !matches!(c, ':' | ' ' | '-' | ','))
        .collect();
    if t.len() & 1 != 0 {
        return None;
    }
    (0..t.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&t[i..i + 2], 16).ok())
        .collect()
}

/// Formats bytes as `01 ab ff`.
pub fn hex(b: &[u8]) -> String {
    b.iter()
        .map(|x| format!("{x:02x}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// Raw register bytes as the IgH tool's `reg_read` prints them: `0x02 0x00`.
pub fn raw_bytes(b: &[u8]) -> String {
    b.iter()
        .map(|x| format!("0x{x:02x}"))
        .collect::<Vec<_>>()
        .join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encode_and_format_round_trip() {
        for (t, s) in [
            (ValueType::U8, "200"),
            (ValueType::I16, "-1234"),
            (ValueType::U32, "0xdeadbeef"),
            (ValueType::I64, "-9000000000"),
            (ValueType::F32, "1.5"),
            (ValueType::F64, "-2.25"),
            (ValueType::String, "hello"),
        ] {
            let b = t.encode(s).unwrap();
            let back = t.format_plain(&b);
            let again = t.encode(&back).unwrap();
            assert_eq!(b, again, "{t} {s}");
        }
        assert!(ValueType::U8.encode("256").is_err());
        assert!(ValueType::I8.encode("x").is_err());
        assert_eq!(ValueType::Hex.encode("01:ab").unwrap(), vec![1, 0xab]);
        assert_eq!(parse_u16("1018h"), Some(0x1018));
    }
}

/// `raw` in the unit of `scale`, exact: `raw / 10^k` printed with `k` decimals when the
/// factor is a power of ten (`-5` at 1/100 → `-0.05`), the shortest exact `f64` otherwise.
pub fn format_scaled(raw: i128, scale: &oxicat_slave::Scale) -> String {
    match scale.decimals() {
        Some(0) => raw.to_string(),
        Some(k) => {
            let den = 10i128.pow(k as u32);
            let sign = if raw < 0 { "-" } else { "" };
            let a = raw.unsigned_abs();
            let den = den as u128;
            format!("{sign}{}.{:0k$}", a / den, a % den)
        }
        None => scale.value(raw as f64).to_string(),
    }
}

/// The raw integer of a physical value given on the command line (`12.5` deg at 1/100 →
/// 1250), rounded to the nearest step.
pub fn parse_scaled(text: &str, scale: &oxicat_slave::Scale) -> Option<i128> {
    let v: f64 = text.trim().parse().ok()?;
    let raw = scale.raw(v).round();
    (raw.is_finite() && raw.abs() < 1e30).then_some(raw as i128)
}

#[cfg(test)]
mod scaled_tests {
    use super::*;
    use oxicat_slave::Scale;

    #[test]
    fn scaled_values_print_exactly_in_their_unit() {
        let deg = Scale::per("deg", 100);
        assert_eq!(format_scaled(-5, &deg), "-0.05");
        assert_eq!(format_scaled(12345, &deg), "123.45");
        assert_eq!(format_scaled(-32768, &deg), "-327.68");
        assert_eq!(format_scaled(7, &Scale::per("Hz", 1)), "7");
        assert_eq!(format_scaled(3, &Scale::ratio("x", 1, 4)), "0.75");
        assert_eq!(parse_scaled("12.5", &deg), Some(1250));
        assert_eq!(parse_scaled("-0.004", &deg), Some(0));
        assert_eq!(parse_scaled("nan", &deg), None);
    }
}
