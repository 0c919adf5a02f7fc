//! Twins of a live slave as a master recorded it (`oxicat scan --save`): its SII image, served
//! byte for byte, and — where it has CoE — the dictionary read by SDO information (objects,
//! entry descriptions and the values of the readable entries).
//!
//! The application objects become the definition's objects, their saved values the
//! defaults. The stack serves its own communication objects (0x1000…0x1018, 0x10F1, the PDO
//! mapping and assignment objects, 0x1C00, 0x1C32/0x1C33) from the definition, which takes
//! their saved values: device type, name and versions, identity, each mapping object's
//! name, mapping and whether it is writable, the assignment, the sync modes. A slave served
//! by this stack therefore comes back as it was; of another slave's communication objects
//! the stack's own names and layout are served (said in [`Twin::left_out`]).

use oxicat_slave::device::{CoeInfo, DeviceInfo, Identity, MailboxDef, SmControl, SyncDef};
use oxicat_slave::od::{image_size, DefaultValue, MAX_ASSIGN, MAX_PDOS, MAX_PDO_ENTRIES};
use oxicat_slave::{
    Access, DataType, DeviceDef, EntryDef, Limits, ObjectCode, ObjectDef, PdoDef, PdoEntry,
    PdoMapping, SyncMode,
};
use oxicat_wire::sii::SiiImage;

use super::{
    check_stack_sms, hx, leak, loopback_of, set_default, stack_owned, Candidate, EscSpec, Served,
    Twin, TwinError,
};
use super::{MAX_IMAGE, MAX_MAILBOX};
use crate::model::SmKind;

/// One object of a saved dictionary (SDO information: object description, entries).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SavedObject {
    /// Index.
    pub index: u16,
    /// Name.
    pub name: String,
    /// Object code (7 VAR, 8 ARRAY, 9 RECORD).
    pub object_code: u8,
    /// Data type code of the object description.
    pub data_type: u16,
    /// Highest subindex.
    pub max_sub: u8,
    /// The entries the slave described, in subindex order.
    pub entries: Vec<SavedEntry>,
}

/// One entry of a [`SavedObject`] (SDO information entry description and value).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SavedEntry {
    /// Subindex.
    pub sub: u8,
    /// Data type code.
    pub data_type: u16,
    /// Bit length.
    pub bits: u16,
    /// Access flags as described (bits 0..5 read/write per state, 6 RxPDO, 7 TxPDO).
    pub access: u16,
    /// Unit (ETG.1004), if the slave gave one.
    pub unit: Option<u32>,
    /// Name.
    pub name: String,
    /// The value read by SDO upload (`None`: not readable, or the read was refused).
    pub value: Option<Vec<u8>>,
}

impl SavedEntry {
    fn writable(&self) -> bool {
        self.access & 0x38 != 0
    }

    fn u64(&self) -> Option<u64> {
        let v = self.value.as_ref()?;
        let mut b = [0u8; 8];
        let n = v.len().min(8);
        b[..n].copy_from_slice(&v[..n]);
        Some(u64::from_le_bytes(b))
    }

    fn text(&self) -> Option<String> {
        let v = self.value.as_ref()?;
        let end = v.iter().position(|c| *c == 0).unwrap_or(v.len());
        Some(String::from_utf8_lossy(&v[..end]).into_owned())
    }
}

fn entry_of(o: &SavedObject, sub: u8) -> Option<&SavedEntry> {
    o.entries.iter().find(|e| e.sub == sub)
}

/// The stack's type for a CoE data type code of `bits` bits, and whether it is the type
/// the slave reported (else the nearest the stack holds).
fn dtype_of(code: u16, bits: u16) -> (DataType, bool) {
    use DataType::*;
    let exact = match code {
        0x0001 if bits == 1 => Some(Bool),
        0x0002 => Some(Int8),
        0x0003 => Some(Int16),
        0x0004 => Some(Int32),
        0x0005 => Some(Unsigned8),
        0x0006 => Some(Unsigned16),
        0x0007 => Some(Unsigned32),
        0x0008 => Some(Real32),
        0x0009 => Some(VisibleString),
        0x000A => Some(OctetString),
        0x0011 => Some(Real64),
        0x0015 => Some(Int64),
        0x001B => Some(Unsigned64),
        _ => None,
    };
    match exact {
        // A scalar type no wider than its own width (BITn are reported as UNSIGNED8 with n bits).
        Some(t) if t.is_string() || (bits > 0 && bits <= t.bits()) => (t, true),
        _ => {
            let t = match bits {
                1 => Bool,
                2..=8 => Unsigned8,
                9..=16 => Unsigned16,
                17..=32 => Unsigned32,
                33..=64 => Unsigned64,
                _ => OctetString,
            };
            (t, false)
        }
    }
}

/// An application object of the saved dictionary as the stack holds it; `Err`: why not.
fn object(o: &SavedObject, left_out: &mut Vec<String>) -> Result<ObjectDef, String> {
    let code = match o.object_code {
        7 => ObjectCode::Var,
        8 => ObjectCode::Array,
        _ => ObjectCode::Record,
    };
    let mut entries: Vec<EntryDef> = Vec::new();
    for e in &o.entries {
        if e.bits == 0 {
            return Err(format!("entry {}:{} has 0 bits", hx(o.index), e.sub));
        }
        let (dtype, exact) = dtype_of(e.data_type, e.bits);
        if !exact {
            left_out.push(format!(
                "{}:{} of data type 0x{:04X} ({} bits): served as {:?}",
                hx(o.index),
                e.sub,
                e.data_type,
                e.bits,
                dtype
            ));
        }
        let mut d = EntryDef::new(e.sub, leak(&e.name), dtype, Access(e.access & 0x3F));
        d.bits = e.bits;
        d.pdo = match (e.access & 0x40 != 0, e.access & 0x80 != 0) {
            (true, true) => PdoMapping::RxTx,
            (true, false) => PdoMapping::Rx,
            (false, true) => PdoMapping::Tx,
            _ => PdoMapping::None,
        };
        if let Some(u) = e.unit.filter(|&u| u != 0) {
            d.limits = Box::leak(Box::new(Limits::unit(u)));
        }
        let default = match (&e.value, dtype.is_string()) {
            (Some(v), true) => DefaultValue::Bytes(Box::leak(v.clone().into_boxed_slice())),
            (Some(_), false) => DefaultValue::bits(e.u64().unwrap_or(0)),
            (None, _) => DefaultValue::bits(0),
        };
        set_default(&mut d, default);
        entries.push(d);
    }
    entries.sort_by_key(|e| e.sub);
    if entries.windows(2).any(|w| w[0].sub == w[1].sub) {
        return Err("two entries with one subindex".into());
    }
    match code {
        ObjectCode::Var if entries.len() != 1 || entries[0].sub != 0 => {
            return Err("a VAR with other than one entry at subindex 0".into())
        }
        ObjectCode::Var => {}
        _ => {
            if entries.first().is_none_or(|e| e.sub != 0) {
                // Subindex 0 not described: the highest subindex, as the object says.
                let mut e0 = EntryDef::new(0, "SubIndex 000", DataType::Unsigned8, Access::RO);
                set_default(&mut e0, DefaultValue::bits(u64::from(o.max_sub)));
                entries.insert(0, e0);
                left_out.push(format!(
                    "{}:0 was not described: served as UNSIGNED8 {}",
                    hx(o.index),
                    o.max_sub
                ));
            }
            if entries[0].bits != 8 {
                return Err(format!("subindex 0 has {} bits, not 8", entries[0].bits));
            }
        }
    }
    Ok(ObjectDef {
        index: o.index,
        name: leak(&o.name),
        code,
        entries: Box::leak(entries.into_boxed_slice()),
    })
}

/// The stack's communication objects of a saved dictionary, read back into the parts of a
/// definition the stack serves them from.
#[derive(Default)]
struct Comm {
    device_type: Option<u32>,
    name: Option<String>,
    hw: Option<String>,
    sw: Option<String>,
    identity: Option<Identity>,
    rx_pdos: Vec<PdoDef>,
    tx_pdos: Vec<PdoDef>,
    rx_assign: Vec<u16>,
    tx_assign: Vec<u16>,
    assign_configurable: bool,
    sync: Option<SyncDef>,
}

fn comm(dict: &[SavedObject], left_out: &mut Vec<String>) -> Result<Comm, TwinError> {
    let mut c = Comm::default();
    for o in dict.iter().filter(|o| stack_owned(o.index)) {
        let val = |sub: u8| entry_of(o, sub).and_then(SavedEntry::u64);
        match o.index {
            0x1000 => c.device_type = val(0).map(|v| v as u32),
            0x1008 => c.name = entry_of(o, 0).and_then(SavedEntry::text),
            0x1009 => c.hw = entry_of(o, 0).and_then(SavedEntry::text),
            0x100A => c.sw = entry_of(o, 0).and_then(SavedEntry::text),
            0x1018 => {
                let g = |s| val(s).unwrap_or(0) as u32;
                c.identity = Some(Identity {
                    vendor_id: g(1),
                    product_code: g(2),
                    revision: g(3),
                    serial: g(4),
                })
            }
            0x1600..=0x17FF | 0x1A00..=0x1BFF => {
                let n = val(0).unwrap_or(0) as u8;
                let mut entries = Vec::new();
                for s in 1..=n {
                    match val(s) {
                        Some(v) => entries.push(PdoEntry::decode(v as u32)),
                        None => {
                            return Err(TwinError::Inconsistent(format!(
                                "PDO {} maps {n} entries, entry {s} has no saved value",
                                hx(o.index)
                            )))
                        }
                    }
                }
                if entries.len() > MAX_PDO_ENTRIES {
                    return Err(TwinError::Unsupported(format!(
                        "PDO {} maps {} entries; the stack maps at most {MAX_PDO_ENTRIES}",
                        hx(o.index),
                        entries.len()
                    )));
                }
                let p = PdoDef {
                    index: o.index,
                    name: leak(&o.name),
                    entries: Box::leak(entries.into_boxed_slice()),
                    configurable: entry_of(o, 0).is_some_and(SavedEntry::writable),
                };
                if o.index < 0x1A00 {
                    c.rx_pdos.push(p);
                } else {
                    c.tx_pdos.push(p);
                }
            }
            0x1C12 | 0x1C13 => {
                let n = val(0).unwrap_or(0) as u8;
                let list: Vec<u16> = (1..=n).filter_map(|s| val(s).map(|v| v as u16)).collect();
                c.assign_configurable |= entry_of(o, 0).is_some_and(SavedEntry::writable);
                if o.index == 0x1C12 {
                    c.rx_assign = list;
                } else {
                    c.tx_assign = list;
                }
            }
            0x1C32 => {
                c.sync = Some(SyncDef {
                    supported: val(4).map_or(1, |v| v as u16),
                    default_mode: val(1)
                        .and_then(|v| SyncMode::from_u16(v as u16))
                        .unwrap_or(SyncMode::FreeRun),
                    min_cycle_ns: val(5).map_or(100_000, |v| v as u32),
                    calc_copy_ns: val(6).map_or(0, |v| v as u32),
                })
            }
            0x1001 | 0x10F1 | 0x1C00 | 0x1C33 => {}
            i => left_out.push(format!(
                "object {} (the stack serves its own communication objects only)",
                hx(i)
            )),
        }
    }
    for (list, what) in [(&c.rx_pdos, "Rx"), (&c.tx_pdos, "Tx")] {
        if list.len() > MAX_PDOS {
            return Err(TwinError::Unsupported(format!(
                "{} {what}PDO mapping objects; the stack holds at most {MAX_PDOS}",
                list.len()
            )));
        }
    }
    for (list, what) in [(&c.rx_assign, "Rx"), (&c.tx_assign, "Tx")] {
        if list.len() > MAX_ASSIGN {
            return Err(TwinError::Unsupported(format!(
                "{} {what}PDOs assigned; the stack assigns at most {MAX_ASSIGN}",
                list.len()
            )));
        }
    }
    Ok(c)
}

/// PDOs and assignment from the SII's categories (a mailbox slave saved without a
/// dictionary), and objects made from the entries they map.
fn from_sii_pdos(m: &crate::DeviceModel, c: &mut Comm, objects: &mut Vec<ObjectDef>) {
    let mut made: Vec<(u16, String, Vec<EntryDef>)> = Vec::new();
    for (list, rx) in [(&m.rx_pdos, true), (&m.tx_pdos, false)] {
        for p in list.iter().take(MAX_PDOS) {
            let entries: Vec<PdoEntry> = p
                .entries
                .iter()
                .take(MAX_PDO_ENTRIES)
                .map(|e| PdoEntry::new(e.index, if e.index == 0 { 0 } else { e.sub }, e.bits))
                .collect();
            for e in p
                .entries
                .iter()
                .filter(|e| e.index != 0 && !stack_owned(e.index))
            {
                let (dtype, _) = dtype_of(e.data_type.unwrap_or(0), u16::from(e.bits));
                let access = if rx { Access::RW } else { Access::RO };
                let name = e.name.as_deref().unwrap_or("");
                let mut d = EntryDef::new(e.sub, leak(name), dtype, access);
                d.bits = u16::from(e.bits);
                d.pdo = if rx { PdoMapping::Rx } else { PdoMapping::Tx };
                match made.iter_mut().find(|(i, _, _)| *i == e.index) {
                    Some((_, _, v)) if v.iter().any(|x| x.sub == e.sub) => {}
                    Some((_, _, v)) => v.push(d),
                    None => made.push((e.index, p.name.clone().unwrap_or_default(), vec![d])),
                }
            }
            let def = PdoDef {
                index: p.index,
                name: leak(p.name.as_deref().unwrap_or("")),
                entries: Box::leak(entries.into_boxed_slice()),
                configurable: !p.fixed,
            };
            let (defs, assign) = if rx {
                (&mut c.rx_pdos, &mut c.rx_assign)
            } else {
                (&mut c.tx_pdos, &mut c.tx_assign)
            };
            if p.sm.is_some() && assign.len() < MAX_ASSIGN {
                assign.push(p.index);
            }
            defs.push(def);
        }
    }
    for (index, name, mut v) in made {
        v.sort_by_key(|e| e.sub);
        let code = if v.len() == 1 && v[0].sub == 0 {
            ObjectCode::Var
        } else {
            if v[0].sub != 0 {
                let mut e0 = EntryDef::new(0, "SubIndex 000", DataType::Unsigned8, Access::RO);
                set_default(
                    &mut e0,
                    DefaultValue::bits(v.last().map_or(0, |e| u64::from(e.sub))),
                );
                v.insert(0, e0);
            }
            ObjectCode::Record
        };
        objects.push(ObjectDef {
            index,
            name: leak(&name),
            code,
            entries: Box::leak(v.into_boxed_slice()),
        });
    }
}

/// The twin of a slave from its SII image `sii` (served as it is) and, for a slave with CoE,
/// the dictionary a master read from it. A slave without a mailbox is the ESC alone (its
/// SII sets device emulation); one with a mailbox runs the stack.
pub fn from_sii(sii: &[u8], dictionary: Option<&[SavedObject]>) -> Result<Twin, TwinError> {
    let im = SiiImage::new(sii).map_err(|e| TwinError::Sii(crate::Error::Sii(e)))?;
    let id = im.identity();
    let m = crate::sii::parse(sii).map_err(TwinError::Sii)?;
    let served = if m.mailbox.is_some() {
        Served::Stack
    } else {
        Served::EscOnly
    };
    let mut left_out = Vec::new();
    let name_sii = m.name.clone().unwrap_or_default();
    let candidate = Candidate {
        type_name: m.order_code.clone().unwrap_or_default(),
        product_code: id.product_code,
        revision: id.revision,
        name: name_sii.clone(),
    };
    let esc = EscSpec {
        fmmu_count: m.fmmus.len().clamp(3, 16) as u8,
        sm_count: m.sms.len().clamp(4, 16) as u8,
        ram_kib: 8,
        port_descriptor: 0x0F,
        from_esi: false,
    };
    let identity = Identity {
        vendor_id: id.vendor_id,
        product_code: id.product_code,
        revision: id.revision,
        serial: id.serial,
    };
    if served == Served::EscOnly {
        if dictionary.is_some_and(|d| !d.is_empty()) {
            left_out.push("the dictionary (the SII has no mailbox to serve it)".into());
        }
        let def: &'static DeviceDef = Box::leak(Box::new(DeviceDef {
            identity,
            name: leak(&name_sii),
            ..DeviceDef::BASE
        }));
        return Ok(Twin {
            candidate,
            def,
            sii: sii.to_vec(),
            esc,
            served,
            image_bytes: 0,
            mailbox_bytes: 0,
            loopback: Vec::new(),
            left_out,
            profile_no: None,
        });
    }

    let kinds: Vec<SmKind> = m.sms.iter().map(|s| s.kind).collect();
    check_stack_sms(&kinds, "SII")?;
    let mbx = im.mailbox();
    let mailbox = MailboxDef {
        rx_start: mbx.standard_rx.offset,
        rx_len: mbx.standard_rx.size,
        tx_start: mbx.standard_tx.offset,
        tx_len: mbx.standard_tx.size,
    };
    for len in [mailbox.rx_len, mailbox.tx_len] {
        if !(16..=MAX_MAILBOX).contains(&len) {
            return Err(TwinError::Unsupported(format!(
                "a mailbox of {len} bytes; a twin serves 16..{MAX_MAILBOX}"
            )));
        }
    }
    if mbx.bootstrap_rx.size != 0 {
        left_out.push("BOOT (bootstrap mailbox, firmware update)".into());
    }
    let mp = m.mailbox.unwrap_or_default();
    if mp.foe || mp.eoe || mp.soe {
        left_out.push("mailbox protocols other than CoE (EoE/FoE/SoE)".into());
    }

    let mut objects = Vec::new();
    let mut c = match dictionary {
        Some(dict) => {
            let c = comm(dict, &mut left_out)?;
            for o in dict.iter().filter(|o| !stack_owned(o.index)) {
                if objects.iter().any(|x: &ObjectDef| x.index == o.index) {
                    return Err(TwinError::Inconsistent(format!(
                        "object {} is in the dictionary twice",
                        hx(o.index)
                    )));
                }
                match object(o, &mut left_out) {
                    Ok(d) => objects.push(d),
                    Err(e) => left_out.push(format!("object {} ({e})", hx(o.index))),
                }
            }
            c
        }
        None => {
            let mut c = Comm::default();
            from_sii_pdos(&m, &mut c, &mut objects);
            c
        }
    };
    objects.sort_by_key(|o| o.index);
    c.rx_pdos.sort_by_key(|p| p.index);
    c.tx_pdos.sort_by_key(|p| p.index);
    let image_bytes = image_size(&objects);
    if image_bytes > MAX_IMAGE {
        return Err(TwinError::Unsupported(format!(
            "the object dictionary needs {image_bytes} bytes; a twin holds at most {MAX_IMAGE}"
        )));
    }
    let fit = |s: String, what: &str, left_out: &mut Vec<String>| -> &'static str {
        let mut n = s.len().min(64);
        while !s.is_char_boundary(n) {
            n -= 1;
        }
        if n < s.len() {
            left_out.push(format!("{what} beyond 64 bytes"));
        }
        leak(&s[..n])
    };
    let coe = m.mailbox.and_then(|x| x.coe);
    let sm = |k: usize| m.sms.get(k);
    let def = DeviceDef {
        identity: c.identity.unwrap_or(identity),
        device_type: c.device_type.unwrap_or(0),
        name: fit(c.name.take().unwrap_or(name_sii), "the name", &mut left_out),
        hw_version: fit(
            c.hw.take().unwrap_or_default(),
            "the hardware version",
            &mut left_out,
        ),
        sw_version: fit(
            c.sw.take().unwrap_or_default(),
            "the software version",
            &mut left_out,
        ),
        mailbox,
        boot_mailbox: None,
        sm2_start: sm(2).map_or(0x1100, |s| s.start),
        sm3_start: sm(3).map_or(0x1180, |s| s.start),
        objects: Box::leak(objects.into_boxed_slice()),
        rx_pdos: Box::leak(std::mem::take(&mut c.rx_pdos).into_boxed_slice()),
        tx_pdos: Box::leak(std::mem::take(&mut c.tx_pdos).into_boxed_slice()),
        rx_assign: Box::leak(std::mem::take(&mut c.rx_assign).into_boxed_slice()),
        tx_assign: Box::leak(std::mem::take(&mut c.tx_assign).into_boxed_slice()),
        assign_configurable: c.assign_configurable,
        sync: c.sync.unwrap_or(SyncDef {
            supported: SyncMode::FreeRun.support_bit() | SyncMode::SmSync.support_bit(),
            default_mode: SyncMode::FreeRun,
            min_cycle_ns: 100_000,
            calc_copy_ns: 0,
        }),
        info: Some(Box::leak(Box::new(DeviceInfo {
            order_code: leak(m.order_code.as_deref().unwrap_or("")),
            eeprom_bytes: sii.len() as u32,
            sm_control: SmControl {
                mbx_out: sm(0).map_or(0x26, |s| s.control),
                mbx_in: sm(1).map_or(0x22, |s| s.control),
                outputs: sm(2).map_or(0x64, |s| s.control),
                inputs: sm(3).map_or(0x20, |s| s.control),
            },
            coe: CoeInfo {
                enabled: coe.is_some(),
                sdo_info: coe.is_some_and(|c| c.sdo_info),
                complete_access: coe.is_some_and(|c| c.complete_access),
                pdo_upload: coe.is_some_and(|c| c.pdo_upload),
                segmented_sdo: coe.is_some(),
            },
            ..DeviceInfo::DEFAULT
        }))),
    };
    let def: &'static DeviceDef = Box::leak(Box::new(def));
    oxicat_slave::od::check_def(def, MAX_IMAGE)
        .map_err(|e| TwinError::Unsupported(format!("the slave stack refuses it: {e}")))?;
    Ok(Twin {
        candidate,
        def,
        sii: sii.to_vec(),
        esc,
        served,
        image_bytes,
        mailbox_bytes: mailbox.rx_len.max(mailbox.tx_len),
        loopback: loopback_of(def),
        left_out,
        // An SII has no profile number; the drive is recognised by its 0x1000 (device
        // type) in the dictionary.
        profile_no: None,
    })
}
