//! Apache Parquet beside CSV: the same table, columnar and typed, for pandas/polars.
//!
//! [`csv_to_parquet`] takes the CSV an experiment writes (header `name [unit]`, one row per
//! sample) and writes the same table: a column per CSV column with the same name, INT64
//! where every value is a whole number, DOUBLE where every value is a number, UTF-8 text
//! otherwise, empty fields as nulls. The values are the CSV's (parsed from its text), so a
//! reader sees exactly what the CSV holds. Units go into the file's key-value metadata
//! (`oxicat.units`: a JSON object column → unit, from the `[unit]` of each header) and each
//! column name keeps its `[unit]` as in the CSV. Doubles are stored byte-stream-split and
//! every page Snappy-compressed.

use std::path::Path;
use std::sync::Arc;

use parquet::basic::{Compression, Encoding, LogicalType, Repetition, Type as Physical};
use parquet::data_type::{ByteArray, ByteArrayType, DoubleType, Int64Type};
use parquet::file::metadata::KeyValue;
use parquet::file::properties::WriterProperties;
use parquet::file::writer::SerializedFileWriter;
use parquet::schema::types::{ColumnPath, Type};

use crate::CliError;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Kind {
    Int,
    Double,
    Text,
}

fn kind(values: &[&str]) -> Kind {
    let present = values.iter().filter(|v| !v.is_empty());
    if present.clone().all(|v| v.parse::<i64>().is_ok()) {
        Kind::Int
    } else if present.clone().all(|v| v.parse::<f64>().is_ok()) {
        Kind::Double
    } else {
        Kind::Text
    }
}

/// `name [unit]` → `unit`.
fn unit(header: &str) -> Option<&str> {
    let h = header.trim_end();
    let open = h.rfind(" [")?;
    h.ends_with(']').then(|| &h[open + 2..h.len() - 1])
}

/// Splits one CSV line into fields (double quotes around a field allowed, `""` inside).
fn fields(line: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut cur = String::new();
    let mut quoted = false;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                cur.push('"');
                chars.next();
            }
            ('"', _) => quoted = !quoted,
            (',', false) => out.push(std::mem::take(&mut cur)),
            (c, _) => cur.push(c),
        }
    }
    out.push(cur);
    out
}

/// Writes the table of `csv` (header line first) as a Parquet file at `path` (atomically:
/// a file that exists is replaced only when the new one is complete).
pub fn csv_to_parquet(csv: &str, path: &Path) -> Result<(), CliError> {
    let bytes = csv_to_parquet_bytes(csv).map_err(|error| CliError::Parquet {
        path: path.to_path_buf(),
        error,
    })?;
    crate::output::write_file(path, &bytes)
}

/// [`csv_to_parquet`] into memory.
pub fn csv_to_parquet_bytes(csv: &str) -> Result<Vec<u8>, String> {
    let mut lines = csv.lines();
    let header = fields(lines.next().ok_or("no header line")?);
    let rows: Vec<Vec<String>> = lines.filter(|l| !l.is_empty()).map(fields).collect();
    for (i, r) in rows.iter().enumerate() {
        if r.len() != header.len() {
            return Err(format!(
                "row {} has {} fields, the header {}",
                i + 1,
                r.len(),
                header.len()
            ));
        }
    }
    let columns: Vec<Vec<&str>> = (0..header.len())
        .map(|c| rows.iter().map(|r| r[c].as_str()).collect())
        .collect();
    let kinds: Vec<Kind> = columns.iter().map(|c| kind(c)).collect();
    let mut fields_t = Vec::new();
    for (name, k) in header.iter().zip(&kinds) {
        let (physical, logical) = match k {
            Kind::Int => (Physical::INT64, None),
            Kind::Double => (Physical::DOUBLE, None),
            Kind::Text => (Physical::BYTE_ARRAY, Some(LogicalType::String)),
        };
        let t = Type::primitive_type_builder(name, physical)
            .with_repetition(Repetition::OPTIONAL)
            .with_logical_type(logical)
            .build()
            .map_err(|e| e.to_string())?;
        fields_t.push(Arc::new(t));
    }
    let schema = Type::group_type_builder("oxicat")
        .with_fields(fields_t)
        .build()
        .map_err(|e| e.to_string())?;
    let units: Vec<String> = header
        .iter()
        .filter_map(|h| {
            unit(h).map(|u| {
                format!(
                    "{}:{}",
                    crate::output::json_string(h),
                    crate::output::json_string(u)
                )
            })
        })
        .collect();
    let mut props = WriterProperties::builder()
        .set_compression(Compression::SNAPPY)
        .set_key_value_metadata(Some(vec![KeyValue::new(
            "oxicat.units".to_string(),
            format!("{{{}}}", units.join(",")),
        )]));
    for (name, k) in header.iter().zip(&kinds) {
        if *k == Kind::Double {
            let col = ColumnPath::new(vec![name.clone()]);
            props = props
                .set_column_dictionary_enabled(col.clone(), false)
                .set_column_encoding(col, Encoding::BYTE_STREAM_SPLIT);
        }
    }
    let mut out = Vec::new();
    let mut w = SerializedFileWriter::new(&mut out, Arc::new(schema), Arc::new(props.build()))
        .map_err(|e| e.to_string())?;
    let mut rg = w.next_row_group().map_err(|e| e.to_string())?;
    for (col, k) in columns.iter().zip(&kinds) {
        let mut cw = rg
            .next_column()
            .map_err(|e| e.to_string())?
            .ok_or("fewer columns than the schema")?;
        let def: Vec<i16> = col.iter().map(|v| i16::from(!v.is_empty())).collect();
        let present = col.iter().filter(|v| !v.is_empty());
        let r = match k {
            Kind::Int => {
                let v: Vec<i64> = present.map(|v| v.parse().unwrap_or_default()).collect();
                cw.typed::<Int64Type>().write_batch(&v, Some(&def), None)
            }
            Kind::Double => {
                let v: Vec<f64> = present.map(|v| v.parse().unwrap_or_default()).collect();
                cw.typed::<DoubleType>().write_batch(&v, Some(&def), None)
            }
            Kind::Text => {
                let v: Vec<ByteArray> = present.map(|v| ByteArray::from(*v)).collect();
                cw.typed::<ByteArrayType>()
                    .write_batch(&v, Some(&def), None)
            }
        };
        r.map_err(|e| e.to_string())?;
        cw.close().map_err(|e| e.to_string())?;
    }
    rg.close().map_err(|e| e.to_string())?;
    w.close().map_err(|e| e.to_string())?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_and_fields() {
        assert_eq!(unit("t [s]"), Some("s"));
        assert_eq!(unit("FL.knee [deg]"), Some("deg"));
        assert_eq!(unit("cycle"), None);
        assert_eq!(fields(r#"a,"b,c",,"d""e""#), ["a", "b,c", "", "d\"e"]);
    }

    #[test]
    fn types_nulls_and_bad_tables() {
        let csv = "cycle,t [s],name,x [m]\n0,0.0,a,1.5\n1,0.0004,\"b,c\",\n";
        let b = csv_to_parquet_bytes(csv).expect("parquet");
        assert_eq!(&b[..4], b"PAR1");
        assert_eq!(&b[b.len() - 4..], b"PAR1");
        let kinds: Vec<Kind> = [["0", "1"], ["0.0", "0.0004"], ["a", "b,c"], ["1.5", ""]]
            .iter()
            .map(|c| kind(c))
            .collect();
        assert_eq!(kinds, [Kind::Int, Kind::Double, Kind::Text, Kind::Double]);
        assert!(csv_to_parquet_bytes("a,b\n1\n")
            .unwrap_err()
            .contains("row 1"));
        assert!(csv_to_parquet_bytes("").is_err());
    }
}
