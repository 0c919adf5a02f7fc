//! ENI: the EtherCAT Network Information a configuration tool (TwinCAT, the EC-Engineer, …)
//! exports as `EtherCATConfig` XML (ETG.2100): the slaves of a machine in line order with
//! their identities, process data, mailbox and init commands.
//!
//! An ENI names each slave's device by identity (vendor ID, product code, revision), not by
//! its ESI file: [`resolve`] searches ESI files for each identity, so a machine described
//! by its ENI can be served from the vendors' ESI files as twins ([`crate::twin`]).
//!
//! Read from each `Config/Slave`: `Info/Name`, `Info/VendorId`, `Info/ProductCode`,
//! `Info/RevisionNo` (required), `Info/SerialNo`, `Info/PhysAddr`, `Info/AutoIncAddr`, the
//! bit lengths of `ProcessData/Send` and `ProcessData/Recv`, the mailbox protocols
//! (`Mailbox/Protocol`), and the number of init commands (`InitCmds/InitCmd` and the CoE
//! ones, `Mailbox/CoE/InitCmds/InitCmd`). Numbers are decimal, `#x…` or `0x…`.

use std::path::{Path, PathBuf};

use roxmltree::Node;

use crate::esi::parse_num;
use crate::twin::{catalogue, decode, Candidate};

/// A parsed ENI.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Eni {
    /// The slaves in line order.
    pub slaves: Vec<EniSlave>,
}

/// One `Config/Slave` of an ENI.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EniSlave {
    /// `Info/Name` (the configuration tool's name, e.g. `Term 2 (EL2008)`).
    pub name: String,
    /// Vendor ID.
    pub vendor_id: u32,
    /// Product code.
    pub product_code: u32,
    /// Revision.
    pub revision: u32,
    /// Serial number, if given.
    pub serial: Option<u32>,
    /// Configured station address, if given.
    pub phys_addr: Option<u16>,
    /// Auto-increment address, if given (0, 0xFFFF, 0xFFFE, … for positions 0, 1, 2, …).
    pub auto_inc_addr: Option<u16>,
    /// Bits of output process data (`ProcessData/Send/BitLength`).
    pub out_bits: u32,
    /// Bits of input process data (`ProcessData/Recv/BitLength`).
    pub in_bits: u32,
    /// Mailbox protocols (`CoE`, `FoE`, …), empty without a mailbox.
    pub mailbox: Vec<String>,
    /// Init commands (ESC register and CoE ones).
    pub init_cmds: usize,
}

impl EniSlave {
    /// `vendor 0x…, product code 0x…, revision 0x…`.
    pub fn identity(&self) -> String {
        format!(
            "vendor 0x{:08x}, product code 0x{:08x}, revision 0x{:08x}",
            self.vendor_id, self.product_code, self.revision
        )
    }
}

/// Why an ENI cannot be read or served.
#[derive(Debug)]
pub enum EniError {
    /// Not well-formed XML, or not an `EtherCATConfig`.
    Xml(String),
    /// No `Config/Slave`.
    NoSlaves,
    /// A slave lacks a required element or has a value that does not parse.
    Slave {
        /// Position in the ENI (0 = first).
        position: usize,
        /// Its `Info/Name`, if it has one.
        name: String,
        /// What is wrong.
        what: String,
    },
    /// A directory of ESI files cannot be read.
    Dir(PathBuf, std::io::Error),
    /// No ESI file describes a slave's vendor and product code.
    Unresolved {
        /// Position in the ENI.
        position: usize,
        /// Its `Info/Name`.
        name: String,
        /// Its identity ([`EniSlave::identity`]).
        identity: String,
        /// The directories searched.
        searched: Vec<PathBuf>,
        /// How many ESI files they hold.
        files: usize,
    },
}

impl std::fmt::Display for EniError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Xml(e) => write!(f, "not a readable ENI (EtherCATConfig): {e}"),
            Self::NoSlaves => write!(f, "the ENI has no Config/Slave"),
            Self::Slave {
                position,
                name,
                what,
            } => write!(f, "ENI slave {position} ({name:?}): {what}"),
            Self::Dir(p, e) => write!(f, "cannot read the ESI directory {}: {e}", p.display()),
            Self::Unresolved {
                position,
                name,
                identity,
                searched,
                files,
            } => write!(
                f,
                "ENI slave {position} ({name:?}, {identity}): no ESI describes this vendor and \
                 product code; searched {files} ESI file(s) in {} (add the vendor's ESI there or \
                 name its directory with --esi-dir)",
                searched
                    .iter()
                    .map(|p| p.display().to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    }
}

impl std::error::Error for EniError {}

fn child<'a, 'i>(n: Node<'a, 'i>, name: &str) -> Option<Node<'a, 'i>> {
    n.children().find(|c| c.has_tag_name(name))
}

fn text<'a>(n: Option<Node<'a, '_>>) -> Option<&'a str> {
    n.map(|n| n.text().unwrap_or("").trim())
}

/// Parses the text of an ENI.
pub fn parse(xml: &str) -> Result<Eni, EniError> {
    let opts = roxmltree::ParsingOptions {
        allow_dtd: true,
        ..Default::default()
    };
    let doc = roxmltree::Document::parse_with_options(xml, opts)
        .map_err(|e| EniError::Xml(e.to_string()))?;
    let root = doc.root_element();
    if !root.has_tag_name("EtherCATConfig") {
        return Err(EniError::Xml(format!(
            "the root element is <{}>, not <EtherCATConfig>",
            root.tag_name().name()
        )));
    }
    let config = child(root, "Config").ok_or(EniError::NoSlaves)?;
    let mut slaves = Vec::new();
    for (position, s) in config
        .children()
        .filter(|c| c.has_tag_name("Slave"))
        .enumerate()
    {
        let info = child(s, "Info");
        let name = text(info.and_then(|i| child(i, "Name")))
            .unwrap_or("")
            .to_string();
        let err = |what: String| EniError::Slave {
            position,
            name: name.clone(),
            what,
        };
        let num = |key: &str| -> Result<Option<u64>, EniError> {
            match text(info.and_then(|i| child(i, key))) {
                None => Ok(None),
                Some(t) => parse_num(t)
                    .and_then(|v| u64::try_from(v).ok())
                    .map(Some)
                    .ok_or_else(|| err(format!("Info/{key} {t:?} is not a number"))),
            }
        };
        let u32_of = |key: &str| -> Result<Option<u32>, EniError> {
            num(key)?
                .map(|v| {
                    u32::try_from(v).map_err(|_| err(format!("Info/{key} {v} is above 32 bits")))
                })
                .transpose()
        };
        let need = |key: &str| -> Result<u32, EniError> {
            u32_of(key)?.ok_or_else(|| err(format!("no Info/{key}")))
        };
        let vendor_id = need("VendorId")?;
        let product_code = need("ProductCode")?;
        let revision = need("RevisionNo")?;
        let serial = u32_of("SerialNo")?;
        let addr16 = |key: &str| -> Result<Option<u16>, EniError> {
            // AutoIncAddr may be written as a negative number (-1 for position 1).
            if let Some(t) = text(info.and_then(|i| child(i, key))) {
                if let Some(v) = parse_num(t) {
                    if (-0x8000..=0xFFFF).contains(&v) {
                        return Ok(Some(v as u16));
                    }
                }
                return Err(err(format!("Info/{key} {t:?} is not a 16-bit address")));
            }
            Ok(None)
        };
        let phys_addr = addr16("PhysAddr")?;
        let auto_inc_addr = addr16("AutoIncAddr")?;
        let pd = child(s, "ProcessData");
        let bits = |dir: &str| -> Result<u32, EniError> {
            let mut total = 0u32;
            for n in pd
                .into_iter()
                .flat_map(|p| p.children())
                .filter(|c| c.has_tag_name(dir))
            {
                let t = text(child(n, "BitLength")).unwrap_or("0");
                let v = parse_num(t)
                    .and_then(|v| u32::try_from(v).ok())
                    .ok_or_else(|| {
                        err(format!("ProcessData/{dir}/BitLength {t:?} is not a number"))
                    })?;
                total = total.saturating_add(v);
            }
            Ok(total)
        };
        let out_bits = bits("Send")?;
        let in_bits = bits("Recv")?;
        let mbx = child(s, "Mailbox");
        let mailbox: Vec<String> = mbx
            .into_iter()
            .flat_map(|m| m.children())
            .filter(|c| c.has_tag_name("Protocol"))
            .filter_map(|c| c.text().map(|t| t.trim().to_string()))
            .collect();
        let count = |n: Option<Node>| {
            n.and_then(|n| child(n, "InitCmds")).map_or(0, |c| {
                c.children().filter(|x| x.has_tag_name("InitCmd")).count()
            })
        };
        let init_cmds = count(Some(s)) + count(mbx.and_then(|m| child(m, "CoE")));
        slaves.push(EniSlave {
            name,
            vendor_id,
            product_code,
            revision,
            serial,
            phys_addr,
            auto_inc_addr,
            out_bits,
            in_bits,
            mailbox,
            init_cmds,
        });
    }
    if slaves.is_empty() {
        return Err(EniError::NoSlaves);
    }
    Ok(Eni { slaves })
}

/// Where an ENI slave's device is described.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Resolved {
    /// The ESI file.
    pub file: PathBuf,
    /// The device type in it (its `Type` and revision).
    pub candidate: Candidate,
    /// Set when the ENI's revision is in no ESI file and the newest one is served instead:
    /// what was asked and what is served.
    pub note: Option<String>,
}

/// One device type of an ESI file, as [`resolve`] indexes them.
type Indexed = (PathBuf, u32, Candidate);

/// The ESI files (`*.xml`, not recursive, in name order) of `dirs`, each with its vendor ID
/// and device types; files that are not ESI (an ENI beside them) are passed over.
pub fn index_dirs(dirs: &[PathBuf]) -> Result<Vec<Indexed>, EniError> {
    let mut files = Vec::new();
    for d in dirs {
        let rd = std::fs::read_dir(d).map_err(|e| EniError::Dir(d.clone(), e))?;
        let mut v: Vec<PathBuf> = rd
            .filter_map(|e| e.ok())
            .map(|e| e.path())
            .filter(|p| p.is_file() && p.extension().is_some_and(|x| x.eq_ignore_ascii_case("xml")))
            .collect();
        v.sort();
        files.extend(v);
    }
    let mut out = Vec::new();
    for f in files {
        let Ok(bytes) = std::fs::read(&f) else {
            continue;
        };
        let text = decode(&bytes);
        // Cheap test first: an ESI's root element is EtherCATInfo.
        if !text.contains("EtherCATInfo") {
            continue;
        }
        if let Ok((vendor, cands)) = catalogue(&text) {
            out.extend(cands.into_iter().map(|c| (f.clone(), vendor, c)));
        }
    }
    Ok(out)
}

/// Finds each slave of `eni` in the ESI files of `dirs`: the device type of its vendor,
/// product code and revision (the first file in name order that has it), else the newest
/// revision of its vendor and product code (with a [`Resolved::note`]); a slave that no
/// file describes is an error naming it and what was searched.
pub fn resolve(eni: &Eni, dirs: &[PathBuf]) -> Result<Vec<Resolved>, EniError> {
    let index = index_dirs(dirs)?;
    resolve_in(eni, &index, dirs)
}

/// [`resolve`] over an index already built (`dirs` is named in errors).
pub fn resolve_in(
    eni: &Eni,
    index: &[Indexed],
    dirs: &[PathBuf],
) -> Result<Vec<Resolved>, EniError> {
    let files = {
        let mut f: Vec<&Path> = index.iter().map(|(p, _, _)| p.as_path()).collect();
        f.dedup();
        f.len()
    };
    eni.slaves
        .iter()
        .enumerate()
        .map(|(position, s)| {
            let same = |(_, v, c): &&Indexed| *v == s.vendor_id && c.product_code == s.product_code;
            if let Some((f, _, c)) = index
                .iter()
                .filter(same)
                .find(|(_, _, c)| c.revision == s.revision)
            {
                return Ok(Resolved {
                    file: f.clone(),
                    candidate: c.clone(),
                    note: None,
                });
            }
            let mut best: Option<&Indexed> = None;
            for i in index.iter().filter(same) {
                if best.is_none_or(|b| i.2.revision > b.2.revision) {
                    best = Some(i);
                }
            }
            match best {
                Some((f, _, c)) => Ok(Resolved {
                    file: f.clone(),
                    candidate: c.clone(),
                    note: Some(format!(
                        "ENI slave {position} ({:?}) asks revision 0x{:08x} of {}, which no ESI \
                         file has; serving its newest, 0x{:08x}, from {}",
                        s.name,
                        s.revision,
                        c.type_name,
                        c.revision,
                        f.display()
                    )),
                }),
                None => Err(EniError::Unresolved {
                    position,
                    name: s.name.clone(),
                    identity: s.identity(),
                    searched: dirs.to_vec(),
                    files,
                }),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const ENI: &str = r#"<?xml version="1.0"?>
<EtherCATConfig><Config>
  <Master><Info><Name>m</Name></Info></Master>
  <Slave><Info><Name>Term 1 (EK1100)</Name><PhysAddr>1001</PhysAddr><AutoIncAddr>0</AutoIncAddr>
    <VendorId>2</VendorId><ProductCode>#x044c2c52</ProductCode><RevisionNo>1114112</RevisionNo></Info></Slave>
  <Slave><Info><Name>Term 2</Name><AutoIncAddr>-1</AutoIncAddr><VendorId>2</VendorId>
    <ProductCode>0x07d83052</ProductCode><RevisionNo>0</RevisionNo></Info>
    <ProcessData><Send><BitStart>0</BitStart><BitLength>8</BitLength></Send></ProcessData>
    <Mailbox><Protocol>CoE</Protocol><CoE><InitCmds><InitCmd/><InitCmd/></InitCmds></CoE></Mailbox>
    <InitCmds><InitCmd/></InitCmds></Slave>
</Config></EtherCATConfig>"#;

    #[test]
    fn parses_slaves_in_order() {
        let e = parse(ENI).unwrap();
        assert_eq!(e.slaves.len(), 2);
        let s = &e.slaves[0];
        assert_eq!(
            (s.vendor_id, s.product_code, s.revision),
            (2, 0x044C_2C52, 0x0011_0000)
        );
        assert_eq!((s.phys_addr, s.auto_inc_addr), (Some(1001), Some(0)));
        let s = &e.slaves[1];
        assert_eq!(s.auto_inc_addr, Some(0xFFFF));
        assert_eq!((s.out_bits, s.in_bits, s.init_cmds), (8, 0, 3));
        assert_eq!(s.mailbox, vec!["CoE"]);
    }

    #[test]
    fn malformed_enis_say_what_and_where() {
        assert!(matches!(parse("<EtherCATConfig>"), Err(EniError::Xml(_))));
        assert!(
            matches!(parse("<EtherCATInfo/>"), Err(EniError::Xml(m)) if m.contains("EtherCATInfo"))
        );
        assert!(matches!(
            parse("<EtherCATConfig><Config/></EtherCATConfig>"),
            Err(EniError::NoSlaves)
        ));
        let e = parse(&ENI.replace("<ProductCode>0x07d83052</ProductCode>", ""))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("slave 1") && e.contains("Term 2") && e.contains("ProductCode"),
            "{e}"
        );
        let e = parse(&ENI.replace("1114112", "eleven"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("slave 0") && e.contains("\"eleven\""), "{e}");
    }

    #[test]
    fn resolves_exactly_else_the_newest_revision_else_says_what_was_searched() {
        let c = |rev| Candidate {
            type_name: "EL2008".into(),
            product_code: 0x07D8_3052,
            revision: rev,
            name: String::new(),
        };
        let ek = Candidate {
            type_name: "EK1100".into(),
            product_code: 0x044C_2C52,
            revision: 0x0011_0000,
            name: String::new(),
        };
        let index = vec![
            (PathBuf::from("a.xml"), 2, ek),
            (PathBuf::from("b.xml"), 2, c(0x0010_0000)),
            (PathBuf::from("b.xml"), 2, c(0x0012_0000)),
        ];
        let e = parse(ENI).unwrap();
        let r = resolve_in(&e, &index, &[PathBuf::from("dir")]).unwrap();
        assert_eq!(r[0].candidate.type_name, "EK1100");
        assert!(r[0].note.is_none());
        assert_eq!(r[1].candidate.revision, 0x0012_0000);
        let n = r[1].note.as_deref().unwrap();
        assert!(n.contains("0x00000000") && n.contains("0x00120000"), "{n}");
        let e = resolve_in(&e, &index[..1], &[PathBuf::from("dir")])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("slave 1")
                && e.contains("Term 2")
                && e.contains("0x07d83052")
                && e.contains("dir"),
            "{e}"
        );
    }
}
