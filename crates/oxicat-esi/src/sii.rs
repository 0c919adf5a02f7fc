//! SII EEPROM image (ETG.2010) from a definition, and SII image → [`DeviceModel`]. All byte
//! layouts come from `oxicat_wire::sii`.

use ihex::{ReaderError, Record};
use oxicat_slave::DeviceDef;
use oxicat_wire::sii::{
    general_flags, write_category, write_strings, CategoryType, MailboxArea, SiiConfig, SiiDc,
    SiiGeneral, SiiIdentity, SiiImage, SiiMailboxConfig, SiiPdoEntry, SiiPdoHeader, SiiSyncManager,
    SmType, FIXED_AREA_LEN, GENERAL_LEN, WORD_EEPROM_SIZE, WORD_VERSION,
};

use crate::model::{
    fmmu_kind, CoeModel, DcModel, DeviceModel, EepromModel, EntryModel, MailboxModel, PdoModel,
    SmKind, SmModel,
};
use crate::Error;

/// PDO flag: mandatory (ETG.2010 PDO flags bit 0).
pub const PDO_MANDATORY: u16 = 0x0001;
/// PDO flag: default (assigned by default).
pub const PDO_DEFAULT: u16 = 0x0002;
/// PDO flag: fixed content.
pub const PDO_FIXED: u16 = 0x0010;

/// Deduplicating string table of the strings category (1-based indices).
#[derive(Default)]
struct Strings(Vec<String>);

impl Strings {
    fn idx(&mut self, s: &str) -> Result<u8, Error> {
        if s.is_empty() {
            return Ok(0);
        }
        let s: String = s.chars().take(255).collect();
        if let Some(i) = self.0.iter().position(|x| *x == s) {
            return Ok(i as u8 + 1);
        }
        if self.0.len() >= 255 {
            return Err(Error::DoesNotFit("more than 255 strings"));
        }
        self.0.push(s);
        Ok(self.0.len() as u8)
    }
}

/// Port type nibble of an ESI physics letter (`Y` MII, `K` E-bus, `H` fast hot connect).
fn port_type(c: char) -> u16 {
    match c {
        'Y' => 1,
        'K' => 3,
        'H' => 4,
        _ => 0,
    }
}

/// The sync managers of an SII image and which one each assigned PDO goes to, when they
/// are not the stack's standard four (SM0/SM1 mailbox, SM2 outputs, SM3 inputs): a twin
/// built from a vendor's ESI ([`crate::twin`]) lays them out as its ESI says (a digital
/// terminal without a mailbox has only `Outputs` at 0x0F00, say).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SmLayout {
    /// The sync managers in SM order.
    pub sms: Vec<SiiSyncManager>,
    /// `(PDO index, SM)` of every PDO assigned by default (the others are written with SM
    /// 0xFF).
    pub pdo_sm: Vec<(u16, u8)>,
    /// The device has a mailbox (SII words 0x18..0x1B and the mailbox DLL flag); without
    /// one both are 0.
    pub mailbox: bool,
}

/// Generates the SII image of a definition (`info.eeprom_bytes` long, unused space 0xFF).
pub fn generate(def: &DeviceDef) -> Result<Vec<u8>, Error> {
    generate_with(def, None)
}

/// [`generate`] with the sync managers of `layout` instead of the stack's standard four.
pub fn generate_with(def: &DeviceDef, layout: Option<&SmLayout>) -> Result<Vec<u8>, Error> {
    let info = def.info();
    let size = info.eeprom_bytes as usize;
    if size < 256 || !size.is_power_of_two() {
        return Err(Error::DoesNotFit(
            "eeprom_bytes must be a power of two >= 256",
        ));
    }
    let mut img = vec![0xFFu8; size];
    img[..FIXED_AREA_LEN].fill(0);
    let e = info.esc;
    SiiConfig {
        pdi_control: e.pdi_control,
        pdi_config: e.pdi_config,
        sync_impulse_len: e.sync_impulse_len,
        pdi_config2: e.pdi_config2,
        station_alias: e.station_alias,
        ..Default::default()
    }
    .write(&mut img)?;
    SiiIdentity {
        vendor_id: def.identity.vendor_id,
        product_code: def.identity.product_code,
        revision: def.identity.revision,
        serial: def.identity.serial,
    }
    .write(&mut img)?;
    let m = def.mailbox;
    let area = |o, s| MailboxArea { offset: o, size: s };
    let boot = def.boot_mailbox;
    let has_mailbox = layout.is_none_or(|l| l.mailbox);
    let (std_rx, std_tx) = if has_mailbox {
        (area(m.rx_start, m.rx_len), area(m.tx_start, m.tx_len))
    } else {
        (area(0, 0), area(0, 0))
    };
    SiiMailboxConfig {
        bootstrap_rx: boot.map_or(area(0, 0), |b| area(b.rx_start, b.rx_len)),
        bootstrap_tx: boot.map_or(area(0, 0), |b| area(b.tx_start, b.tx_len)),
        standard_rx: std_rx,
        standard_tx: std_tx,
        protocols: if has_mailbox {
            def.mailbox_protocols()
        } else {
            0
        },
    }
    .write(&mut img)?;
    let w = |img: &mut [u8], word: u16, v: u16| {
        let o = word as usize * 2;
        img[o..o + 2].copy_from_slice(&v.to_le_bytes());
    };
    w(&mut img, WORD_EEPROM_SIZE, (size / 128 - 1) as u16);
    w(&mut img, WORD_VERSION, info.sii_version);

    let mut st = Strings::default();
    // Category bodies first (they allocate strings), then strings go first in the image.
    // String order as in Beckhoff's images: 1 the type (order code), then group, image and
    // the device name. SOEM names a slave by string 1 whatever the general category says;
    // IgH and TwinCAT by the name index.
    let order = st.idx(info.order_code)?;
    let group = st.idx(info.group.type_name)?;
    let image = st.idx(info.image.unwrap_or(""))?;
    let name = st.idx(def.name)?;
    let mut physical_port = 0u16;
    for (i, c) in info.physics.chars().take(4).enumerate() {
        physical_port |= port_type(c) << (4 * i);
    }
    let mut general = [0u8; GENERAL_LEN];
    SiiGeneral {
        group_idx: group,
        image_idx: image,
        order_idx: order,
        name_idx: name,
        coe_details: def.coe_details(),
        foe_details: u8::from(info.foe),
        eoe_details: u8::from(info.eoe),
        flags: if has_mailbox {
            general_flags::MBOX_DLL
        } else {
            0
        },
        current_on_ebus: info.ebus_current_ma,
        group_idx2: group,
        physical_port,
        ..Default::default()
    }
    .write(&mut general)?;

    let fmmu: Vec<u8> = info.fmmus.iter().map(|u| u.code()).collect();

    let ob = def.default_output_bits().div_ceil(8) as u16;
    let ib = def.default_input_bits().div_ceil(8) as u16;
    let c = info.sm_control;
    let sms = match layout {
        Some(l) => l.sms.clone(),
        None => [
            (m.rx_start, m.rx_len, c.mbx_out, 1u8, SmType::MailboxOut),
            (m.tx_start, m.tx_len, c.mbx_in, 1, SmType::MailboxIn),
            (
                def.sm2_start,
                ob,
                c.outputs,
                u8::from(ob > 0),
                SmType::Outputs,
            ),
            (
                def.sm3_start,
                ib,
                c.inputs,
                u8::from(ib > 0),
                SmType::Inputs,
            ),
        ]
        .into_iter()
        .map(|(start, length, control, enable, sm_type)| SiiSyncManager {
            start,
            length,
            control,
            status: 0,
            enable,
            sm_type,
        })
        .collect(),
    };
    let mut sm = vec![0u8; 8 * sms.len()];
    for (k, s) in sms.into_iter().enumerate() {
        s.write(&mut sm[8 * k..])?;
    }
    // The SM of an assigned PDO: the layout's, or SM2 (outputs) / SM3 (inputs).
    let sm_of = |index: u16, standard: u8| match layout {
        Some(l) => l.pdo_sm.iter().find(|(p, _)| *p == index).map(|(_, s)| *s),
        None => Some(standard),
    };

    let mut pdo_cat = |pdos: &[oxicat_slave::PdoDef], smn: u8, assign: &[u16]| {
        let mut out = Vec::new();
        for p in pdos {
            let assigned = assign.contains(&p.index);
            let smn = if assigned {
                sm_of(p.index, smn).unwrap_or(0xFF)
            } else {
                0xFF
            };
            let mut flags = 0;
            if assigned {
                flags |= PDO_DEFAULT;
                if !def.assign_configurable {
                    flags |= PDO_MANDATORY;
                }
            }
            if !p.configurable {
                flags |= PDO_FIXED;
            }
            let mut h = [0u8; 8];
            SiiPdoHeader {
                index: p.index,
                entry_count: u8::try_from(p.entries.len())
                    .map_err(|_| Error::DoesNotFit("PDO entries"))?,
                sync_manager: smn,
                dc_sync: 0,
                name_idx: st.idx(p.name)?,
                flags,
            }
            .write(&mut h)?;
            out.extend_from_slice(&h);
            for e in p.entries {
                let (n, t) = def
                    .object(e.index)
                    .and_then(|o| o.entries.iter().find(|x| x.sub == e.sub))
                    .map_or(("", 0), |x| (x.name, x.dtype.code() as u8));
                let mut b = [0u8; 8];
                SiiPdoEntry {
                    index: e.index,
                    subindex: e.sub,
                    name_idx: st.idx(n)?,
                    data_type: t,
                    bit_len: e.bits,
                    flags: 0,
                }
                .write(&mut b)?;
                out.extend_from_slice(&b);
            }
        }
        Ok::<_, Error>(out)
    };
    let tx = pdo_cat(def.tx_pdos, 3, def.tx_assign)?;
    let rx = pdo_cat(def.rx_pdos, 2, def.rx_assign)?;

    let mut dc = Vec::new();
    for md in info.dc_modes {
        let mut b = [0u8; 24];
        SiiDc {
            cycle_time0: md.cycle_sync0,
            shift_time0: md.shift_sync0,
            shift_time1: md.shift_sync1,
            sync1_cycle_factor: md.sync1_factor,
            assign_activate: md.assign_activate,
            sync0_cycle_factor: md.sync0_factor,
            name_idx: st.idx(md.name)?,
            desc_idx: st.idx(md.desc)?,
            reserved: [0; 4],
        }
        .write(&mut b)?;
        dc.extend_from_slice(&b);
    }

    let strs: Vec<&[u8]> = st.0.iter().map(|s| s.as_bytes()).collect();
    let mut sbuf = vec![0u8; 1 + strs.iter().map(|s| s.len() + 1).sum::<usize>()];
    let n = write_strings(&mut sbuf, &strs)?;
    let full = |_| Error::DoesNotFit("categories exceed the EEPROM size");
    let mut o = FIXED_AREA_LEN;
    o = write_category(&mut img, o, CategoryType::Strings, &sbuf[..n]).map_err(full)?;
    o = write_category(&mut img, o, CategoryType::General, &general).map_err(full)?;
    o = write_category(&mut img, o, CategoryType::Fmmu, &fmmu).map_err(full)?;
    o = write_category(&mut img, o, CategoryType::SyncManager, &sm).map_err(full)?;
    if !tx.is_empty() {
        o = write_category(&mut img, o, CategoryType::TxPdo, &tx).map_err(full)?;
    }
    if !rx.is_empty() {
        o = write_category(&mut img, o, CategoryType::RxPdo, &rx).map_err(full)?;
    }
    if !dc.is_empty() {
        o = write_category(&mut img, o, CategoryType::Dc, &dc).map_err(full)?;
    }
    // End marker (the image is 0xFF-filled, but make it explicit).
    if img.len() < o + 2 {
        return Err(Error::DoesNotFit("no room for the end marker"));
    }
    img[o..o + 2].copy_from_slice(&0xFFFFu16.to_le_bytes());
    Ok(img)
}

/// Decodes an SII image (binary) into the comparable model.
pub fn parse(bytes: &[u8]) -> Result<DeviceModel, Error> {
    let im = SiiImage::new(bytes)?;
    let id = im.identity();
    let strings = im.strings()?;
    // Strings are UTF-8 or, in Beckhoff EEPROMs, Latin-1 (e.g. "µs").
    let s = |i: u8| {
        strings
            .and_then(|t| t.get(i))
            .map(|b| match std::str::from_utf8(b) {
                Ok(v) => v.to_string(),
                Err(_) => b.iter().map(|c| *c as char).collect(),
            })
    };
    let mut m = DeviceModel {
        vendor_id: id.vendor_id,
        product_code: id.product_code,
        revision: id.revision,
        ..Default::default()
    };
    let mbx = im.mailbox();
    let mut general = None;
    for c in im.categories() {
        let c = c?;
        match c.kind {
            CategoryType::General => {
                let g = c.general()?;
                m.name = s(g.name_idx);
                if let Some(n) = &m.name {
                    m.id_strings.push((0x1008, n.clone()));
                }
                m.order_code = s(g.order_idx);
                m.group_type = s(g.group_idx);
                general = Some(g);
            }
            CategoryType::Fmmu => {
                m.fmmus = c.fmmus().map(|u| fmmu_kind(u.code())).collect();
                while m.fmmus.last() == Some(&crate::model::FmmuKind::Other) {
                    m.fmmus.pop();
                }
            }
            CategoryType::SyncManager => {
                for e in c.sync_managers() {
                    let e = e?;
                    m.sms.push(SmModel {
                        kind: match e.sm_type {
                            SmType::MailboxOut => SmKind::MBoxOut,
                            SmType::MailboxIn => SmKind::MBoxIn,
                            SmType::Outputs => SmKind::Outputs,
                            SmType::Inputs => SmKind::Inputs,
                            _ => SmKind::Other,
                        },
                        start: e.start,
                        default_size: Some(e.length),
                        control: e.control,
                        enable: e.enable & 1 != 0,
                    });
                }
            }
            CategoryType::TxPdo | CategoryType::RxPdo => {
                let mut list = Vec::new();
                for p in c.pdos() {
                    let p = p?;
                    let h = p.header;
                    let mut entries = Vec::new();
                    for e in p.entries() {
                        let e = e?;
                        entries.push(EntryModel {
                            index: e.index,
                            sub: e.subindex,
                            bits: e.bit_len,
                            name: s(e.name_idx),
                            data_type: (e.data_type != 0).then_some(e.data_type as u16),
                        });
                    }
                    list.push(PdoModel {
                        index: h.index,
                        name: s(h.name_idx),
                        sm: (h.sync_manager != 0xFF).then_some(h.sync_manager),
                        fixed: h.flags & PDO_FIXED != 0,
                        mandatory: h.flags & PDO_MANDATORY != 0,
                        entries,
                    });
                }
                if c.kind == CategoryType::TxPdo {
                    m.tx_pdos.extend(list);
                } else {
                    m.rx_pdos.extend(list);
                }
            }
            CategoryType::Dc => {
                for d in c.dc() {
                    let d = d?;
                    m.dc.push(DcModel {
                        name: s(d.name_idx),
                        desc: s(d.desc_idx),
                        assign_activate: d.assign_activate,
                        cycle0: d.cycle_time0,
                        shift0: d.shift_time0 as i32 as i64,
                        sync0_factor: d.sync0_cycle_factor,
                        sync1_factor: d.sync1_cycle_factor,
                        shift1: d.shift_time1 as i32 as i64,
                    });
                }
            }
            _ => {}
        }
    }
    if mbx.protocols != 0 || mbx.standard_rx.size != 0 {
        let g = general.unwrap_or_default();
        let c = g.coe_details;
        m.mailbox = Some(MailboxModel {
            coe: (mbx.protocols & 0x04 != 0).then_some(CoeModel {
                sdo_info: c & 0x02 != 0,
                pdo_assign: c & 0x04 != 0,
                pdo_config: c & 0x08 != 0,
                pdo_upload: c & 0x10 != 0,
                complete_access: c & 0x20 != 0,
            }),
            foe: mbx.protocols & 0x08 != 0,
            eoe: mbx.protocols & 0x02 != 0,
            soe: mbx.protocols & 0x10 != 0,
        });
    }
    let b = (mbx.bootstrap_rx, mbx.bootstrap_tx);
    m.eeprom = Some(EepromModel {
        byte_size: im.eeprom_size_bytes() as u32,
        config_data: im.config().crc_bytes().to_vec(),
        bootstrap: (b.0.size != 0 || b.1.size != 0)
            .then_some([b.0.offset, b.0.size, b.1.offset, b.1.size]),
    });
    Ok(m)
}

/// Decodes an SII image given either as binary or as Intel HEX text (`.hex` dumps).
pub fn parse_any(bytes: &[u8]) -> Result<DeviceModel, Error> {
    if bytes.first() == Some(&b':') {
        parse(&intel_hex(bytes)?)
    } else {
        parse(bytes)
    }
}

/// Decodes Intel HEX (records read by the `ihex` crate; types 00–05, 03 and 05 ignored)
/// into a flat image, gaps filled with 0xFF; lines are trimmed and blank lines skipped.
pub fn intel_hex(text: &[u8]) -> Result<Vec<u8>, Error> {
    let bad = |what, line: &str| Error::BadValue {
        what,
        text: line.to_string(),
    };
    let text = std::str::from_utf8(text).map_err(|_| bad("Intel HEX record", "not UTF-8"))?;
    let mut out = Vec::new();
    let mut base = 0usize;
    for line in text.lines().map(str::trim).filter(|l| !l.is_empty()) {
        let what = |e| match e {
            ReaderError::ChecksumMismatch(..) => {
                "Intel HEX record (checksum wrong: the bytes do not sum to 0 mod 256)"
            }
            ReaderError::PayloadLengthMismatch => {
                "Intel HEX record (its length byte does not match the record)"
            }
            ReaderError::UnsupportedRecordType(_) => "Intel HEX record (type not 00 to 05)",
            ReaderError::InvalidLengthForType => "Intel HEX record (wrong length for its type)",
            _ => "Intel HEX record",
        };
        match Record::from_record_string(line).map_err(|e| bad(what(e), line))? {
            Record::Data { offset, value } => {
                let at = base + usize::from(offset);
                if at + value.len() > 1 << 20 {
                    return Err(bad("Intel HEX record", line));
                }
                if out.len() < at + value.len() {
                    out.resize(at + value.len(), 0xFF);
                }
                out[at..at + value.len()].copy_from_slice(&value);
            }
            Record::EndOfFile => break,
            Record::ExtendedSegmentAddress(a) => base = usize::from(a) << 4,
            Record::ExtendedLinearAddress(a) => base = usize::from(a) << 16,
            Record::StartSegmentAddress { .. } | Record::StartLinearAddress(_) => {}
        }
    }
    Ok(out)
}
