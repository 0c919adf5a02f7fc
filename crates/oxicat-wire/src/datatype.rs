//! The CoE data types (ETG.1000.6 table 64): code, the ETG name ESI files use and the bit
//! length. One table for every side: the slave's object dictionary, the ESI generator and
//! parser, and the master's SDO information output.

/// One CoE data type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DataTypeInfo {
    /// The data type index (SDO information, ESI `DataType` of the dictionary).
    pub code: u16,
    /// The ETG name as ESI files write it (`UDINT`, `STRING(n)` for strings).
    pub name: &'static str,
    /// Bit length of a value; 0 when the length varies (strings, records).
    pub bits: u16,
    /// Other names ESI files use for the same type (`DWORD` for `UDINT`).
    pub aliases: &'static [&'static str],
}

const fn t(
    code: u16,
    name: &'static str,
    bits: u16,
    aliases: &'static [&'static str],
) -> DataTypeInfo {
    DataTypeInfo {
        code,
        name,
        bits,
        aliases,
    }
}

/// The data types oxicat knows, by code.
pub const DATA_TYPES: &[DataTypeInfo] = &[
    t(0x0001, "BOOL", 1, &["BIT"]),
    t(0x0002, "SINT", 8, &[]),
    t(0x0003, "INT", 16, &[]),
    t(0x0004, "DINT", 32, &[]),
    t(0x0005, "USINT", 8, &["BYTE"]),
    t(0x0006, "UINT", 16, &["WORD"]),
    t(0x0007, "UDINT", 32, &["DWORD"]),
    t(0x0008, "REAL", 32, &[]),
    t(0x0009, "STRING", 0, &[]),
    t(0x000A, "OCTET_STRING", 0, &[]),
    t(0x000B, "UNICODE_STRING", 0, &[]),
    t(0x0011, "LREAL", 64, &[]),
    t(0x0015, "LINT", 64, &[]),
    t(0x001B, "ULINT", 64, &["LWORD"]),
    t(0x0029, "PDO_MAPPING", 0, &[]),
    t(0x002A, "RECORD", 0, &[]),
];

/// The data type with code `code`.
pub fn by_code(code: u16) -> Option<&'static DataTypeInfo> {
    DATA_TYPES.iter().find(|d| d.code == code)
}

/// The data type an ESI names (`UDINT`, `DWORD`, `STRING(12)`; surrounding blanks
/// ignored). The structured types (`PDO_MAPPING`, `RECORD`) and unknown names give `None`.
pub fn by_name(name: &str) -> Option<&'static DataTypeInfo> {
    let n = name.trim();
    let base = match n.split_once('(') {
        Some((b, rest)) if rest.ends_with(')') => b,
        _ => n,
    };
    DATA_TYPES
        .iter()
        .filter(|d| d.bits > 0 || matches!(d.code, 0x0009..=0x000B))
        .find(|d| d.name == base || d.aliases.contains(&base))
        // A bare STRING / OCTET_STRING has no length: only with one.
        .filter(|d| d.bits > 0 || base != n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_codes_round_trip() {
        for d in DATA_TYPES {
            assert_eq!(by_code(d.code), Some(d));
        }
        assert_eq!(by_name("UDINT").map(|d| d.code), Some(0x0007));
        assert_eq!(by_name(" DWORD ").map(|d| d.code), Some(0x0007));
        assert_eq!(by_name("BIT").map(|d| d.code), Some(0x0001));
        assert_eq!(by_name("STRING(12)").map(|d| d.code), Some(0x0009));
        assert_eq!(by_name("STRING"), None);
        assert_eq!(by_name("RECORD"), None);
        assert_eq!(by_name("DT0800EN03"), None);
    }
}
