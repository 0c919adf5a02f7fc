//! The object dictionary exactly as the stack serves it (built with `oxicat_slave::Od`
//! from the definition), listed for the ESI dictionary and as a text table.

use std::fmt::Write as _;

use oxicat_slave::od::ObjectInfo;
use oxicat_slave::{DataType, DeviceDef, EntryDef, ObjectCode, Od};

use crate::model::{esi_type_name, hex};
use crate::Error;

/// Largest application object image the tooling accepts.
pub const MAX_IMAGE: usize = 16 * 1024;

/// A stack object dictionary of a definition with its default values.
pub struct OdSnapshot {
    od: Box<Od<MAX_IMAGE>>,
}

impl OdSnapshot {
    /// Builds the stack's OD for `def` (rejected definitions are an error).
    pub fn new(def: &'static DeviceDef) -> Result<Self, Error> {
        let od = Od::<MAX_IMAGE>::new(def).map_err(|e| Error::Definition(e.to_string()))?;
        Ok(Self { od: Box::new(od) })
    }

    /// The stack's OD.
    pub fn od(&self) -> &Od<MAX_IMAGE> {
        &self.od
    }

    /// Default value bytes of `index:sub` as ESI `DefaultData` (little-endian hex).
    pub fn default_data(&self, index: u16, sub: u8) -> String {
        self.od.bytes(index, sub).map(hex).unwrap_or_default()
    }
}

/// All objects in index order.
pub fn objects(od: &OdSnapshot) -> Vec<ObjectInfo> {
    (0..od.od.object_count())
        .filter_map(|n| od.od.object_info(n))
        .collect()
}

/// Human-readable value of an entry (integers decimal, strings as text, reals as float).
pub fn value_text(od: &OdSnapshot, index: u16, e: &EntryDef) -> String {
    let Ok(b) = od.od.bytes(index, e.sub) else {
        return String::new();
    };
    let mut a = [0u8; 8];
    let n = b.len().min(8);
    a[..n].copy_from_slice(&b[..n]);
    let u = u64::from_le_bytes(a);
    let bits = e.bits.min(64) as u32;
    let sext = |u: u64| -> i64 {
        if bits == 0 || bits >= 64 {
            u as i64
        } else {
            ((u << (64 - bits)) as i64) >> (64 - bits)
        }
    };
    match e.dtype {
        DataType::VisibleString => {
            let end = b.iter().position(|c| *c == 0).unwrap_or(b.len());
            String::from_utf8_lossy(&b[..end]).into_owned()
        }
        DataType::OctetString => hex(b),
        DataType::Bool => (u & 1).to_string(),
        DataType::Real32 => f32::from_bits(u as u32).to_string(),
        DataType::Real64 => f64::from_bits(u).to_string(),
        t if t.is_signed() => sext(u).to_string(),
        _ if bits >= 16 => format!("{u:#x}"),
        _ => u.to_string(),
    }
}

fn access_text(e: &EntryDef) -> &'static str {
    match (e.access.readable(), e.access.writable()) {
        (true, true) => "rw",
        (false, true) => "wo",
        _ => "ro",
    }
}

/// The object dictionary as a text table: index, sub, name, type, bits, access, PDO
/// mapping, default value.
pub fn table(def: &'static DeviceDef) -> Result<String, Error> {
    let od = OdSnapshot::new(def)?;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:<7} {:<4} {:<36} {:<12} {:>5} {:<3} {:<3} default",
        "index", "sub", "name", "type", "bits", "acc", "pdo"
    );
    for o in objects(&od) {
        let code = match o.code {
            ObjectCode::Var => "VAR",
            ObjectCode::Array => "ARRAY",
            ObjectCode::Record => "RECORD",
        };
        if o.code != ObjectCode::Var {
            let _ = writeln!(s, "{:#06x}  {:<4} {:<36} {}", o.index, "", o.name, code);
        }
        for e in o.entries {
            let pdo = match (e.pdo.rx(), e.pdo.tx()) {
                (true, true) => "RT",
                (true, false) => "R",
                (false, true) => "T",
                _ => "",
            };
            let name = if o.code == ObjectCode::Var {
                o.name
            } else {
                e.name
            };
            let _ = writeln!(
                s,
                "{:#06x}  {:<4} {:<36} {:<12} {:>5} {:<3} {:<3} {}",
                o.index,
                format!("{:02}", e.sub),
                name,
                esi_type_name(e.dtype, e.bits),
                e.bits,
                access_text(e),
                pdo,
                value_text(&od, o.index, e)
            );
        }
    }
    Ok(s)
}
