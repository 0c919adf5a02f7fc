//! `oxicat scan [--save DIR [--force]]`: reads every slave of the segment — identity, station
//! address, alias, state, name, ESC registers 0x0000..0x0009, the whole SII EEPROM and, for a
//! slave with CoE and SDO information, its dictionary (object list, object and entry
//! descriptions, the values of the readable entries, PDO mapping and assignment included) —
//! prints a line per slave, and with `--save` records the machine in DIR in the format of
//! [`oxicat_devices::saved`], which `oxicat sim --segment DIR` serves again.
//!
//! DIR is created if missing; an existing DIR must be empty, or `--force` lets the scan
//! replace the files it writes there (each replaced file is named on standard error; no
//! other file is touched).

use std::io::Write;
use std::path::{Path, PathBuf};

use clap::Args;
use oxicat_devices::saved::{self, Manifest, SavedSlave};
use oxicat_esi::twin::{SavedEntry, SavedObject};
use oxicat_master::{Master, MasterError};

use crate::master_cmd::LinkArgs;
use crate::CliError;

/// The arguments of `scan`.
#[derive(Debug, Args)]
pub struct ScanArgs {
    #[command(flatten)]
    #[allow(missing_docs)]
    pub link: LinkArgs,
    /// Record the machine in this directory (created if missing; it must be empty).
    #[arg(long, value_name = "DIR")]
    pub save: Option<PathBuf>,
    /// With --save: use a directory that is not empty, replacing the files the scan writes.
    #[arg(long, requires = "save")]
    pub force: bool,
}

/// One slave as the scan read it.
struct Scanned {
    slave: SavedSlave,
    sii: Vec<u8>,
    dictionary: Option<Vec<SavedObject>>,
}

/// Checks that `dir` may receive a recording: missing, or an empty directory, or (with
/// `force`) any directory.
fn check_dir(dir: &Path, force: bool) -> Result<(), CliError> {
    let bad = |why: String| CliError::SaveDir {
        dir: dir.to_path_buf(),
        why,
    };
    match std::fs::metadata(dir) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(bad(e.to_string())),
        Ok(m) if !m.is_dir() => Err(bad("it exists and is not a directory".into())),
        Ok(_) => {
            let mut rd = std::fs::read_dir(dir).map_err(|e| bad(e.to_string()))?;
            if rd.next().is_some() && !force {
                return Err(bad(
                    "it is not empty; name a new or empty directory, or give --force to replace \
                     the files the scan writes there"
                        .into(),
                ));
            }
            Ok(())
        }
    }
}

/// The dictionary of the slave at `p`: every object's description, and each readable
/// entry's value (`None` where the slave refuses the upload).
fn dictionary(m: &Master, p: usize) -> Result<Vec<SavedObject>, MasterError> {
    let mut out = Vec::new();
    for o in m.dictionary(p)? {
        let mut entries = Vec::new();
        for e in &o.entries {
            let value = if e.access & 0x07 != 0 {
                match m.sdo_upload(p, o.index, e.sub) {
                    Ok(v) => Some(v),
                    Err(MasterError::SdoAbort { .. }) => None,
                    Err(err) => return Err(err),
                }
            } else {
                None
            };
            entries.push(SavedEntry {
                sub: e.sub,
                data_type: e.data_type,
                bits: e.bits,
                access: e.access,
                unit: e.unit,
                name: e.name.clone(),
                value,
            });
        }
        out.push(SavedObject {
            index: o.index,
            name: o.name,
            object_code: o.object_code,
            data_type: o.data_type,
            max_sub: o.max_sub,
            entries,
        });
    }
    Ok(out)
}

fn link_text(l: &LinkArgs) -> String {
    match (&l.udp, &l.iface, &l.sim) {
        (Some(u), _, _) => format!("--udp {u}"),
        (_, Some(i), _) => format!("--iface {i}"),
        (_, _, Some(s)) => format!("--sim {s}"),
        _ => std::env::var("OXICAT_IFACE")
            .map(|i| format!("--iface {i}"))
            .unwrap_or_default(),
    }
}

/// `scan`: a line per slave; with `--save`, the recording.
pub fn scan(a: ScanArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let ScanArgs { link, save, force } = a;
    if let Some(dir) = &save {
        check_dir(dir, force)?;
    }
    let m = crate::master_cmd::open(&link)?;
    let mut all = Vec::new();
    for s in m.scan()? {
        let p = s.position;
        let sii = m.sii_read(p, true)?;
        let regs = m.reg_read(p, 0x0000, 10)?;
        let sdo_info = oxicat_esi::sii::parse(&sii)
            .ok()
            .and_then(|d| d.mailbox)
            .and_then(|x| x.coe)
            .is_some_and(|c| c.sdo_info);
        let dict = if sdo_info {
            Some(dictionary(&m, p)?)
        } else {
            None
        };
        let line = format!(
            "{p:<4} 0x{:04x}  {:<24} SII {} bytes, {}\n",
            s.address,
            s.name,
            sii.len(),
            match &dict {
                Some(d) => format!("{} CoE objects", d.len()),
                None => "no CoE dictionary".into(),
            }
        );
        out.write_all(line.as_bytes())
            .map_err(MasterError::Output)?;
        all.push(Scanned {
            slave: SavedSlave {
                position: p,
                station_address: s.address,
                alias: s.alias,
                state: s.status.to_string(),
                name: s.name.clone(),
                vendor_id: s.vendor_id,
                product_code: s.product_code,
                revision: s.revision,
                serial: s.serial,
                esc_registers: saved::hex(&regs),
                sii: format!("slave-{p}-sii.bin"),
                dictionary: dict.as_ref().map(|_| format!("slave-{p}-dictionary.toml")),
            },
            sii,
            dictionary: dict,
        });
    }
    if let Some(dir) = save {
        write_dir(&dir, &link_text(&link), all)?;
        out.write_all(format!("saved in {}\n", dir.display()).as_bytes())
            .map_err(MasterError::Output)?;
    }
    Ok(())
}

fn write_dir(dir: &Path, from: &str, all: Vec<Scanned>) -> Result<(), CliError> {
    std::fs::create_dir_all(dir).map_err(|e| CliError::SaveDir {
        dir: dir.to_path_buf(),
        why: e.to_string(),
    })?;
    let put = |name: &str, bytes: &[u8]| -> Result<(), CliError> {
        let p = dir.join(name);
        if p.exists() {
            eprintln!("oxicat scan: replacing {}", p.display());
        }
        crate::output::write_file(&p, bytes)
    };
    let mut slaves = Vec::new();
    for s in all {
        put(&s.slave.sii, &s.sii)?;
        if let (Some(f), Some(d)) = (&s.slave.dictionary, &s.dictionary) {
            put(f, toml(&saved::dictionary_file(d))?.as_bytes())?;
        }
        slaves.push(s.slave);
    }
    let manifest = Manifest {
        format: saved::FORMAT,
        scanned_from: from.to_string(),
        slaves,
    };
    let text = format!(
        "# A machine recorded by `oxicat scan --save`; `oxicat sim --segment {}` serves it.\n{}",
        dir.display(),
        toml(&manifest)?
    );
    put(saved::MANIFEST, text.as_bytes())
}

/// TOML text of a manifest or dictionary file.
fn toml<T: serde::Serialize>(v: &T) -> Result<String, CliError> {
    toml::to_string(v)
        .map_err(|e| CliError::Io(std::io::Error::other(format!("TOML of the recording: {e}"))))
}
