//! ESI XML (ETG.2000 `EtherCATInfo`) from a definition, and ESI XML → [`DeviceModel`]s.
//!
//! Element names and order follow the ESI files of SSC/SOES/KickCAT devices (and so what
//! TwinCAT reads): `Vendor`, `Descriptions/Groups/Group`, `Devices/Device` with `Type`,
//! `Name`, `Comment`, `Info`, `GroupType`, `Profile/Dictionary` (`DataTypes`, `Objects`),
//! `Fmmu`, `Sm`, `RxPdo`, `TxPdo`, `Mailbox`, `Dc`, `Eeprom`.

use quick_xml::events::{BytesDecl, BytesEnd, BytesStart, BytesText, Event};
use quick_xml::Writer;

use oxicat_slave::device::DeviceDef;
use oxicat_slave::od::ObjectInfo;
use oxicat_slave::{Access, DataType, EntryDef, ObjectCode, PdoMapping};
use roxmltree::Node;

use crate::model::{
    config_bytes, esi_type_name, hex, type_code, CoeModel, DcModel, DeviceModel, EepromModel,
    EntryModel, FmmuKind, MailboxModel, ObjectModel, PdoModel, SmKind, SmModel,
};
use crate::od::{objects, value_text, OdSnapshot};
use crate::Error;

/// Escapes text for XML element content and attribute values (all five of `&<>"'`); a
/// character XML 1.0 cannot carry at all (a control character but tab, newline and carriage
/// return; U+FFFE, U+FFFF) becomes U+FFFD ([`xml_chars`]).
pub fn escape(s: &str) -> String {
    quick_xml::escape::escape(&*xml_chars(s)).into_owned()
}

/// `s` with every character XML 1.0 cannot carry replaced by U+FFFD: strings from a
/// vendor's ESI or a slave's SII reach definitions as they are, and one control character
/// would make the whole generated document unreadable.
pub fn xml_chars(s: &str) -> std::borrow::Cow<'_, str> {
    let ok = |c: char| {
        matches!(c, '\t' | '\n' | '\r') || (c >= ' ' && c != '\u{FFFE}' && c != '\u{FFFF}')
    };
    if s.chars().all(ok) {
        std::borrow::Cow::Borrowed(s)
    } else {
        std::borrow::Cow::Owned(
            s.chars()
                .map(|c| if ok(c) { c } else { '\u{FFFD}' })
                .collect(),
        )
    }
}

/// An indenting XML writer on `quick-xml` (two spaces a level, one element a line, text
/// inline); also used by `oxicat-master`'s ESI of a live slave. Its bytes are those of the
/// hand-written writer it replaced (`benches/esi_xml.rs` compares them).
pub struct Xml {
    w: Writer<Vec<u8>>,
    stack: Vec<&'static str>,
}

impl Default for Xml {
    fn default() -> Self {
        Self::new()
    }
}

fn start<'a>(name: &'a str, attrs: &'a [(&str, String)]) -> BytesStart<'a> {
    let mut b = BytesStart::new(name);
    for (k, v) in attrs {
        b.push_attribute((*k, &*xml_chars(v)));
    }
    b
}

impl Xml {
    /// A document holding only the XML declaration.
    pub fn new() -> Self {
        let mut x = Self {
            w: Writer::new_with_indent(Vec::new(), b' ', 2),
            stack: Vec::new(),
        };
        x.put(Event::Decl(BytesDecl::new("1.0", Some("UTF-8"), None)));
        x
    }
    fn put(&mut self, e: Event) {
        // Writing into a Vec cannot fail.
        self.w.write_event(e).expect("XML into a Vec");
    }
    /// Writes `<name attrs>` and indents what follows until [`close`](Self::close).
    pub fn open(&mut self, name: &'static str, attrs: &[(&str, String)]) {
        self.put(Event::Start(start(name, attrs)));
        self.stack.push(name);
    }
    /// Closes the innermost open element.
    pub fn close(&mut self) {
        if let Some(n) = self.stack.pop() {
            self.put(Event::End(BytesEnd::new(n)));
        }
    }
    /// Writes `<name attrs>text</name>` on one line.
    pub fn leaf(&mut self, name: &str, attrs: &[(&str, String)], text: &str) {
        self.put(Event::Start(start(name, attrs)));
        self.put(Event::Text(BytesText::new(&xml_chars(text))));
        self.put(Event::End(BytesEnd::new(name)));
    }
    /// Writes `<name attrs/>`.
    pub fn empty(&mut self, name: &str, attrs: &[(&str, String)]) {
        self.put(Event::Empty(start(name, attrs)));
    }
    /// Writes `<name>text</name>`.
    pub fn text(&mut self, name: &str, text: &str) {
        self.leaf(name, &[], text);
    }
    /// Closes every open element and returns the document (ending in a newline).
    pub fn finish(mut self) -> String {
        while !self.stack.is_empty() {
            self.close();
        }
        let mut b = self.w.into_inner();
        b.push(b'\n');
        String::from_utf8(b).expect("UTF-8 in, UTF-8 out")
    }
}

/// An ESI hex number: `#x` and `digits` upper-case hex digits.
pub fn hx(v: u32, digits: usize) -> String {
    format!("#x{v:0digits$X}")
}

/// An ESI boolean attribute value: `true` or `false`.
pub fn bool_attr(v: bool) -> String {
    if v { "true" } else { "false" }.to_string()
}

fn access_flags(x: &mut Xml, a: Access, pdo: PdoMapping) {
    x.open("Flags", &[]);
    let text = if a.writable() && a.readable() {
        "rw"
    } else if a.writable() {
        "wo"
    } else {
        "ro"
    };
    let mut attrs = Vec::new();
    if a.writable() {
        let w = a.0 >> 3 & 7;
        let r = match w {
            1 => Some("PreOP"),
            3 => Some("PreOP_SafeOP"),
            2 => Some("SafeOP"),
            6 => Some("SafeOP_OP"),
            4 => Some("OP"),
            _ => None,
        };
        if let Some(r) = r {
            attrs.push(("WriteRestrictions", r.to_string()));
        }
    }
    x.leaf("Access", &attrs, text);
    match pdo {
        PdoMapping::None => {}
        PdoMapping::Rx => x.text("PdoMapping", "R"),
        PdoMapping::Tx => x.text("PdoMapping", "T"),
        PdoMapping::RxTx => x.text("PdoMapping", "RT"),
    }
    x.close();
}

/// What the head of an ESI names: the vendor, the device's group and its identity.
pub struct Head<'a> {
    /// Vendor ID.
    pub vendor_id: u32,
    /// Vendor name.
    pub vendor_name: &'a str,
    /// Group `Type` (also the device's `GroupType`).
    pub group_type: &'a str,
    /// Group name.
    pub group_name: &'a str,
    /// The device's `Physics` attribute (`YY` for two EBUS/MII ports).
    pub physics: &'a str,
    /// Product code.
    pub product_code: u32,
    /// Revision number.
    pub revision: u32,
    /// The device `Type` text (the order code).
    pub order_code: &'a str,
    /// The device name.
    pub name: &'a str,
}

/// Opens `EtherCATInfo`, writes `Vendor` and `Descriptions/Groups`, opens `Devices/Device`
/// and writes its `Type` and `Name`; [`Xml::finish`] closes what is left open.
pub fn head(x: &mut Xml, h: &Head) {
    x.open(
        "EtherCATInfo",
        &[
            (
                "xmlns:xsi",
                "http://www.w3.org/2001/XMLSchema-instance".into(),
            ),
            ("xsi:noNamespaceSchemaLocation", "EtherCATInfo.xsd".into()),
            ("Version", "1.6".into()),
        ],
    );
    x.open("Vendor", &[]);
    x.text("Id", &hx(h.vendor_id, 8));
    x.leaf("Name", &[("LcId", "1033".into())], h.vendor_name);
    x.close();
    x.open("Descriptions", &[]);
    x.open("Groups", &[]);
    x.open("Group", &[]);
    x.text("Type", h.group_type);
    x.leaf("Name", &[("LcId", "1033".into())], h.group_name);
    x.close();
    x.close();
    x.open("Devices", &[]);
    x.open("Device", &[("Physics", h.physics.into())]);
    x.leaf(
        "Type",
        &[
            ("ProductCode", hx(h.product_code, 8)),
            ("RevisionNo", hx(h.revision, 8)),
        ],
        h.order_code,
    );
    x.leaf("Name", &[("LcId", "1033".into())], h.name);
}

/// Bit offset layout of a record/array as SSC and TwinCAT lay it out: subindex 0 at 0,
/// entries from bit 16 on, byte-sized entries byte-aligned, BOOLs packed.
fn layout(entries: &[EntryDef]) -> (Vec<u32>, u32) {
    let mut offs = Vec::with_capacity(entries.len());
    let mut pos = 0u32;
    for (i, e) in entries.iter().enumerate() {
        if i == 1 {
            pos = 16;
        }
        if e.bits & 7 == 0 {
            pos = pos.div_ceil(8) * 8;
        }
        offs.push(pos);
        pos += e.bits as u32;
    }
    (offs, pos.div_ceil(8) * 8)
}

fn dt_name(o: &ObjectInfo) -> String {
    match o.code {
        ObjectCode::Var => o
            .entries
            .first()
            .map_or_else(|| "USINT".into(), |e| esi_type_name(e.dtype, e.bits)),
        _ => format!("DT{:04X}", o.index),
    }
}

fn data_types(x: &mut Xml, objs: &[ObjectInfo]) {
    x.open("DataTypes", &[]);
    let mut base: Vec<(String, u16)> = Vec::new();
    let mut add_base = |t: DataType, bits: u16| {
        let n = esi_type_name(t, bits);
        if !base.iter().any(|(m, _)| *m == n) {
            base.push((n, bits));
        }
    };
    for o in objs {
        for e in o.entries {
            add_base(e.dtype, e.bits);
        }
    }
    for o in objs.iter().filter(|o| o.code != ObjectCode::Var) {
        let name = dt_name(o);
        if o.code == ObjectCode::Array {
            let el = &o.entries[1..];
            let (t, bits) = el
                .first()
                .map_or((DataType::Unsigned8, 8), |e| (e.dtype, e.bits));
            let n = el.len() as u32;
            x.open("DataType", &[]);
            x.text("Name", &format!("{name}ARR"));
            x.text("BaseType", &esi_type_name(t, bits));
            x.text("BitSize", &(n * bits as u32).to_string());
            x.open("ArrayInfo", &[]);
            x.text("LBound", "1");
            x.text("Elements", &n.to_string());
            x.close();
            x.close();
            x.open("DataType", &[]);
            x.text("Name", &name);
            x.text("BitSize", &(16 + n * bits as u32).to_string());
            sub_item(x, 0, &o.entries[0], "USINT", 8, 0);
            let a = el.first().map_or(Access::RO, |e| e.access);
            x.open("SubItem", &[]);
            x.text("Name", "Elements");
            x.text("Type", &format!("{name}ARR"));
            x.text("BitSize", &(n * bits as u32).to_string());
            x.text("BitOffs", "16");
            access_flags(x, a, el.first().map_or(PdoMapping::None, |e| e.pdo));
            x.close();
            x.close();
        } else {
            let (offs, total) = layout(o.entries);
            x.open("DataType", &[]);
            x.text("Name", &name);
            x.text("BitSize", &total.to_string());
            for (e, off) in o.entries.iter().zip(offs) {
                let t = esi_type_name(e.dtype, e.bits);
                sub_item(x, e.sub, e, &t, e.bits as u32, off);
            }
            x.close();
        }
    }
    for (n, bits) in base {
        x.open("DataType", &[]);
        x.text("Name", &n);
        x.text("BitSize", &bits.to_string());
        x.close();
    }
    x.close();
}

fn sub_item(x: &mut Xml, sub: u8, e: &EntryDef, t: &str, bits: u32, off: u32) {
    x.open("SubItem", &[]);
    x.text("SubIdx", &sub.to_string());
    x.text("Name", e.name);
    x.text("Type", t);
    x.text("BitSize", &bits.to_string());
    x.text("BitOffs", &off.to_string());
    access_flags(x, e.access, e.pdo);
    x.close();
}

fn default_info(x: &mut Xml, od: &OdSnapshot, index: u16, e: &EntryDef) {
    x.open("Info", &[]);
    let v = value_text(od, index, e);
    if e.dtype == DataType::VisibleString {
        x.text("DefaultString", &v);
    } else {
        x.text("DefaultData", &od.default_data(index, e.sub));
    }
    x.close();
}

fn objects_xml(x: &mut Xml, od: &OdSnapshot, objs: &[ObjectInfo]) {
    x.open("Objects", &[]);
    for o in objs {
        x.open("Object", &[]);
        x.text("Index", &hx(o.index as u32, 4));
        x.text("Name", o.name);
        let (bits, ty) = match o.code {
            ObjectCode::Var => (o.entries.first().map_or(0, |e| e.bits as u32), dt_name(o)),
            ObjectCode::Array => {
                let n = (o.entries.len() - 1) as u32;
                let b = o.entries.get(1).map_or(0, |e| e.bits as u32);
                (16 + n * b, dt_name(o))
            }
            ObjectCode::Record => (layout(o.entries).1, dt_name(o)),
        };
        x.text("Type", &ty);
        x.text("BitSize", &bits.to_string());
        match o.code {
            ObjectCode::Var => {
                if let Some(e) = o.entries.first() {
                    default_info(x, od, o.index, e);
                    access_flags(x, e.access, e.pdo);
                }
            }
            _ => {
                x.open("Info", &[]);
                for e in o.entries {
                    x.open("SubItem", &[]);
                    x.text("Name", e.name);
                    x.open("Info", &[]);
                    if e.dtype == DataType::VisibleString {
                        x.text("DefaultString", &value_text(od, o.index, e));
                    } else {
                        x.text("DefaultData", &od.default_data(o.index, e.sub));
                    }
                    x.close();
                    x.close();
                }
                x.close();
                x.open("Flags", &[]);
                x.text("Access", "ro");
                x.close();
            }
        }
        x.close();
    }
    x.close();
}

fn pdo_xml(x: &mut Xml, def: &DeviceDef, tag: &'static str, p: &oxicat_slave::PdoDef, sm: u8) {
    let assign = if sm == 2 {
        def.rx_assign
    } else {
        def.tx_assign
    };
    let assigned = assign.contains(&p.index);
    let mut attrs = Vec::new();
    if !p.configurable {
        attrs.push(("Fixed", "true".to_string()));
    }
    if assigned && !def.assign_configurable {
        attrs.push(("Mandatory", "true".to_string()));
    }
    if assigned {
        attrs.push(("Sm", sm.to_string()));
    }
    x.open(tag, &attrs);
    x.text("Index", &hx(p.index as u32, 4));
    x.text("Name", p.name);
    for e in p.entries {
        x.open("Entry", &[]);
        x.text("Index", &hx(e.index as u32, 4));
        if e.index != 0 {
            x.text("SubIndex", &e.sub.to_string());
        }
        x.text("BitLen", &e.bits.to_string());
        if let Some(en) = def
            .object(e.index)
            .and_then(|o| o.entries.iter().find(|x| x.sub == e.sub))
        {
            x.text("Name", en.name);
            x.text("DataType", &esi_type_name(en.dtype, en.bits));
        }
        x.close();
    }
    x.close();
}

/// The CoE profile number of a definition: the low word of its device type 0x1000.
pub fn profile_no(def: &DeviceDef) -> Option<u32> {
    Some(def.device_type & 0xFFFF).filter(|p| *p != 0)
}

/// Generates the ESI XML of a definition.
pub fn generate(def: &'static DeviceDef) -> Result<String, Error> {
    let od = OdSnapshot::new(def)?;
    let objs = objects(&od);
    let i = def.info();
    let mut x = Xml::new();
    head(
        &mut x,
        &Head {
            vendor_id: def.identity.vendor_id,
            vendor_name: i.vendor_name,
            group_type: i.group.type_name,
            group_name: i.group.name,
            physics: i.physics,
            product_code: def.identity.product_code,
            revision: def.identity.revision,
            order_code: i.order_code,
            name: def.name,
        },
    );
    if let Some(c) = i.description {
        x.text("Comment", c);
    }
    if i.ebus_current_ma != 0 || i.timeouts.is_some() {
        // ETG.2000 InfoType order: Electrical, StateMachine, Mailbox.
        x.open("Info", &[]);
        if i.ebus_current_ma != 0 {
            x.open("Electrical", &[]);
            x.text("EBusCurrent", &i.ebus_current_ma.to_string());
            x.close();
        }
        if let Some(t) = i.timeouts {
            x.open("StateMachine", &[]);
            x.open("Timeout", &[]);
            x.text("PreopTimeout", &t.preop.to_string());
            x.text("SafeopOpTimeout", &t.safeop_op.to_string());
            x.text("BackToInitTimeout", &t.back_to_init.to_string());
            x.text("BackToSafeopTimeout", &t.back_to_safeop.to_string());
            x.close();
            x.close();
            x.open("Mailbox", &[]);
            x.open("Timeout", &[]);
            x.text("RequestTimeout", &t.mailbox_request.to_string());
            x.text("ResponseTimeout", &t.mailbox_response.to_string());
            x.close();
            x.close();
        }
        x.close();
    }
    x.text("GroupType", i.group.type_name);
    x.open("Profile", &[]);
    // One source: the profile number is the low word of 0x1000 (402 for a CiA402 drive,
    // 5001 for a modular device); a device without a profile (0) has no ProfileNo.
    if let Some(p) = profile_no(def) {
        x.text("ProfileNo", &p.to_string());
    }
    x.text("AddInfo", "0");
    x.open("Dictionary", &[]);
    data_types(&mut x, &objs);
    objects_xml(&mut x, &od, &objs);
    x.close();
    x.close();
    for f in i.fmmus {
        let t = match f.code() {
            1 => "Outputs",
            2 => "Inputs",
            3 => "MBoxState",
            _ => continue,
        };
        x.text("Fmmu", t);
    }
    let m = def.mailbox;
    let c = i.sm_control;
    let ob = def.default_output_bits().div_ceil(8);
    let ib = def.default_input_bits().div_ceil(8);
    let mbx_attrs = |size: u16, start: u16, ctrl: u8| {
        let mut a = Vec::new();
        if let Some((lo, hi)) = i.mailbox_size_range {
            a.push(("MinSize", lo.to_string()));
            a.push(("MaxSize", hi.to_string()));
        }
        a.push(("DefaultSize", size.to_string()));
        a.push(("StartAddress", hx(start as u32, 4)));
        a.push(("ControlByte", hx(ctrl as u32, 2)));
        a.push(("Enable", "1".into()));
        a
    };
    x.leaf("Sm", &mbx_attrs(m.rx_len, m.rx_start, c.mbx_out), "MBoxOut");
    x.leaf("Sm", &mbx_attrs(m.tx_len, m.tx_start, c.mbx_in), "MBoxIn");
    for (size, start, ctrl, name) in [
        (ob, def.sm2_start, c.outputs, "Outputs"),
        (ib, def.sm3_start, c.inputs, "Inputs"),
    ] {
        x.leaf(
            "Sm",
            &[
                ("DefaultSize", size.to_string()),
                ("StartAddress", hx(start as u32, 4)),
                ("ControlByte", hx(ctrl as u32, 2)),
                ("Enable", u8::from(size > 0).to_string()),
            ],
            name,
        );
    }
    for p in def.rx_pdos {
        pdo_xml(&mut x, def, "RxPdo", p, 2);
    }
    for p in def.tx_pdos {
        pdo_xml(&mut x, def, "TxPdo", p, 3);
    }
    x.open("Mailbox", &[("DataLinkLayer", "true".into())]);
    if i.coe.enabled {
        let cd = def.coe_details();
        x.empty(
            "CoE",
            &[
                ("SdoInfo", bool_attr(cd & 0x02 != 0)),
                ("PdoAssign", bool_attr(cd & 0x04 != 0)),
                ("PdoConfig", bool_attr(cd & 0x08 != 0)),
                ("PdoUpload", bool_attr(cd & 0x10 != 0)),
                ("CompleteAccess", bool_attr(cd & 0x20 != 0)),
                ("SegmentedSdo", bool_attr(i.coe.segmented_sdo)),
            ],
        );
    }
    if i.eoe {
        x.empty("EoE", &[]);
    }
    if i.foe {
        x.empty("FoE", &[]);
    }
    x.close();
    if !i.dc_modes.is_empty() {
        x.open("Dc", &[]);
        for d in i.dc_modes {
            x.open("OpMode", &[]);
            x.text("Name", d.name);
            x.text("Desc", d.desc);
            x.text("AssignActivate", &hx(d.assign_activate as u32, 4));
            if d.assign_activate & 0x0300 != 0 {
                x.leaf(
                    "CycleTimeSync0",
                    &[("Factor", d.sync0_factor.to_string())],
                    &d.cycle_sync0.to_string(),
                );
                x.text("ShiftTimeSync0", &d.shift_sync0.to_string());
            }
            if d.assign_activate & 0x0400 != 0 {
                x.leaf(
                    "CycleTimeSync1",
                    &[("Factor", d.sync1_factor.to_string())],
                    "0",
                );
                x.text("ShiftTimeSync1", &d.shift_sync1.to_string());
            }
            x.close();
        }
        x.close();
    }
    x.open("Eeprom", &[]);
    x.text("ByteSize", &i.eeprom_bytes.to_string());
    x.text("ConfigData", &hex(&config_bytes(def)));
    if let Some(bm) = def.boot_mailbox {
        let mut v = Vec::new();
        for w in [bm.rx_start, bm.rx_len, bm.tx_start, bm.tx_len] {
            v.extend_from_slice(&w.to_le_bytes());
        }
        x.text("BootStrap", &hex(&v));
    }
    x.close();
    Ok(x.finish())
}

// ------------------------------------------------------------------------------ parser

/// Parses an ESI number: `#x1A00` hex, `0x..` hex, or decimal (optionally negative).
pub fn parse_num(s: &str) -> Option<i64> {
    let s = s.trim();
    if let Some(h) = s.strip_prefix("#x").or_else(|| s.strip_prefix("#X")) {
        i64::from_str_radix(h, 16).ok()
    } else if let Some(h) = s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        i64::from_str_radix(h, 16).ok()
    } else {
        s.parse().ok()
    }
}

fn parse_bool(s: &str) -> Option<bool> {
    match s.trim() {
        "1" | "true" => Some(true),
        "0" | "false" => Some(false),
        _ => None,
    }
}

pub(crate) fn parse_hex_bytes(s: &str) -> Option<Vec<u8>> {
    let s: String = s.chars().filter(|c| !c.is_whitespace()).collect();
    if s.len() & 1 != 0 {
        return None;
    }
    (0..s.len() / 2)
        .map(|i| u8::from_str_radix(&s[2 * i..2 * i + 2], 16).ok())
        .collect()
}

fn child<'a, 'i>(n: Node<'a, 'i>, name: &str) -> Option<Node<'a, 'i>> {
    n.children().find(|c| c.has_tag_name(name))
}

fn children<'a, 'i: 'a>(n: Node<'a, 'i>, name: &'a str) -> impl Iterator<Item = Node<'a, 'i>> + 'a {
    n.children().filter(move |c| c.has_tag_name(name))
}

fn text_of(n: Option<Node>) -> Option<String> {
    n.map(|n| n.text().unwrap_or("").trim().to_string())
}

fn num<T: TryFrom<i64>>(what: &'static str, s: &str) -> Result<T, Error> {
    parse_num(s)
        .and_then(|v| T::try_from(v).ok())
        .ok_or_else(|| Error::BadValue {
            what,
            text: s.to_string(),
        })
}

pub(crate) fn num_u32(what: &'static str, s: &str) -> Result<u32, Error> {
    // Product codes and vendor IDs may be written as negative decimals (signed 32-bit).
    let v = parse_num(s).ok_or_else(|| Error::BadValue {
        what,
        text: s.to_string(),
    })?;
    if (i32::MIN as i64..=u32::MAX as i64).contains(&v) {
        Ok(v as u32)
    } else {
        Err(Error::BadValue {
            what,
            text: s.to_string(),
        })
    }
}

fn attr_num<T: TryFrom<i64>>(n: Node, a: &'static str) -> Result<Option<T>, Error> {
    n.attribute(a).map(|v| num(a, v)).transpose()
}

fn attr_bool(n: Node, a: &'static str) -> Result<bool, Error> {
    match n.attribute(a) {
        None => Ok(false),
        Some(v) => parse_bool(v).ok_or_else(|| Error::BadValue {
            what: a,
            text: v.to_string(),
        }),
    }
}

fn pdo(n: Node) -> Result<PdoModel, Error> {
    let index = num(
        "Pdo/Index",
        &text_of(child(n, "Index")).ok_or(Error::Missing("Pdo/Index"))?,
    )?;
    let mut entries = Vec::new();
    for e in children(n, "Entry") {
        let idx = text_of(child(e, "Index")).ok_or(Error::Missing("Entry/Index"))?;
        let bits = text_of(child(e, "BitLen")).ok_or(Error::Missing("Entry/BitLen"))?;
        let sub = match text_of(child(e, "SubIndex")) {
            Some(s) => num("Entry/SubIndex", &s)?,
            None => 0,
        };
        entries.push(EntryModel {
            index: num("Entry/Index", &idx)?,
            sub,
            bits: num("Entry/BitLen", &bits)?,
            name: text_of(child(e, "Name")).filter(|s| !s.is_empty()),
            data_type: text_of(child(e, "DataType")).and_then(|t| type_code(&t)),
        });
    }
    Ok(PdoModel {
        index,
        name: text_of(child(n, "Name")),
        sm: attr_num(n, "Sm")?,
        fixed: attr_bool(n, "Fixed")?,
        mandatory: attr_bool(n, "Mandatory")?,
        entries,
    })
}

/// The model of one `Device` element (shared with [`crate::twin`]).
pub(crate) fn device(
    vendor_id: u32,
    vendor_name: Option<String>,
    d: Node,
) -> Result<DeviceModel, Error> {
    let t = child(d, "Type").ok_or(Error::Missing("Device/Type"))?;
    let mut m = DeviceModel {
        vendor_id,
        vendor_name,
        product_code: t
            .attribute("ProductCode")
            .map(|v| num_u32("ProductCode", v))
            .transpose()?
            .unwrap_or(0),
        revision: t
            .attribute("RevisionNo")
            .map(|v| num_u32("RevisionNo", v))
            .transpose()?
            .unwrap_or(0),
        name: text_of(child(d, "Name")),
        order_code: Some(t.text().unwrap_or("").trim().to_string()),
        group_type: text_of(child(d, "GroupType")),
        ..Default::default()
    };
    for f in children(d, "Fmmu") {
        m.fmmus.push(match f.text().unwrap_or("").trim() {
            "Outputs" => FmmuKind::Outputs,
            "Inputs" => FmmuKind::Inputs,
            "MBoxState" => FmmuKind::MBoxState,
            _ => FmmuKind::Other,
        });
    }
    for s in children(d, "Sm") {
        m.sms.push(SmModel {
            kind: match s.text().unwrap_or("").trim() {
                "MBoxOut" => SmKind::MBoxOut,
                "MBoxIn" => SmKind::MBoxIn,
                "Outputs" => SmKind::Outputs,
                "Inputs" => SmKind::Inputs,
                _ => SmKind::Other,
            },
            start: attr_num(s, "StartAddress")?.unwrap_or(0),
            default_size: attr_num(s, "DefaultSize")?,
            control: attr_num(s, "ControlByte")?.unwrap_or(0),
            enable: attr_bool(s, "Enable")?,
        });
    }
    for p in children(d, "RxPdo") {
        m.rx_pdos.push(pdo(p)?);
    }
    for p in children(d, "TxPdo") {
        m.tx_pdos.push(pdo(p)?);
    }
    if let Some(mb) = child(d, "Mailbox") {
        let coe = match child(mb, "CoE") {
            Some(c) => Some(CoeModel {
                sdo_info: attr_bool(c, "SdoInfo")?,
                pdo_assign: attr_bool(c, "PdoAssign")?,
                pdo_config: attr_bool(c, "PdoConfig")?,
                pdo_upload: attr_bool(c, "PdoUpload")?,
                complete_access: attr_bool(c, "CompleteAccess")?,
            }),
            None => None,
        };
        m.mailbox = Some(MailboxModel {
            coe,
            foe: child(mb, "FoE").is_some(),
            eoe: child(mb, "EoE").is_some(),
            soe: child(mb, "SoE").is_some(),
        });
    }
    if let Some(dc) = child(d, "Dc") {
        for o in children(dc, "OpMode") {
            let n = |name: &'static str| -> Result<i64, Error> {
                match text_of(child(o, name)) {
                    Some(s) if !s.is_empty() => num(name, &s),
                    _ => Ok(0),
                }
            };
            let factor = |name: &str| -> Result<i16, Error> {
                match child(o, name) {
                    Some(c) => Ok(attr_num(c, "Factor")?.unwrap_or(1)),
                    None => Ok(0),
                }
            };
            m.dc.push(DcModel {
                name: text_of(child(o, "Name")),
                desc: text_of(child(o, "Desc")),
                assign_activate: num(
                    "AssignActivate",
                    &text_of(child(o, "AssignActivate")).unwrap_or_else(|| "0".into()),
                )?,
                cycle0: u32::try_from(n("CycleTimeSync0")?).unwrap_or(0),
                shift0: n("ShiftTimeSync0")?,
                sync0_factor: factor("CycleTimeSync0")?,
                sync1_factor: factor("CycleTimeSync1")?,
                shift1: n("ShiftTimeSync1")?,
            });
        }
    }
    if let Some(e) = child(d, "Eeprom") {
        let bad = |what: &'static str, t: String| Error::BadValue { what, text: t };
        let cd = text_of(child(e, "ConfigData")).unwrap_or_default();
        let bs = text_of(child(e, "BootStrap"));
        let bootstrap = match bs {
            Some(s) => {
                let v = parse_hex_bytes(&s)
                    .filter(|v| v.len() >= 8)
                    .ok_or_else(|| bad("BootStrap", s.clone()))?;
                let w = |i: usize| u16::from_le_bytes([v[2 * i], v[2 * i + 1]]);
                Some([w(0), w(1), w(2), w(3)])
            }
            None => None,
        };
        m.eeprom = Some(EepromModel {
            byte_size: match text_of(child(e, "ByteSize")) {
                Some(s) => num("ByteSize", &s)?,
                None => 0,
            },
            config_data: parse_hex_bytes(&cd).ok_or_else(|| bad("ConfigData", cd.clone()))?,
            bootstrap,
        });
    }
    if let Some(p) = child(d, "Profile").and_then(|p| text_of(child(p, "ProfileNo"))) {
        m.profile_no = Some(num_u32("Profile/ProfileNo", &p)?);
    }
    m.timeouts = timeouts(d)?;
    if let Some(dict) = child(d, "Profile").and_then(|p| child(p, "Dictionary")) {
        if let Some(objs) = child(dict, "Objects") {
            let types = child(dict, "DataTypes");
            for o in children(objs, "Object") {
                let idx = text_of(child(o, "Index")).ok_or(Error::Missing("Object/Index"))?;
                let type_name = text_of(child(o, "Type")).unwrap_or_default();
                let sub_names = types
                    .and_then(|t| {
                        children(t, "DataType")
                            .find(|dt| text_of(child(*dt, "Name")).as_deref() == Some(&type_name))
                    })
                    .map(|dt| {
                        children(dt, "SubItem")
                            .filter_map(|s| text_of(child(s, "Name")))
                            .collect()
                    })
                    .unwrap_or_default();
                let index = num("Object/Index", &idx)?;
                if index == 0x1000 {
                    // A default that is no UNSIGNED32 is not this model's business (a twin
                    // reads it on its own terms).
                    if let Some(b) = child(o, "Info")
                        .and_then(|i| text_of(child(i, "DefaultData")))
                        .and_then(|v| parse_hex_bytes(&v))
                        .filter(|b| !b.is_empty() && b.len() <= 4)
                    {
                        let mut w = [0u8; 4];
                        w[..b.len()].copy_from_slice(&b);
                        m.device_type = Some(u32::from_le_bytes(w));
                    }
                }
                if (0x1008..=0x100A).contains(&index) {
                    if let Some(v) =
                        child(o, "Info").and_then(|i| text_of(child(i, "DefaultString")))
                    {
                        m.id_strings.push((index, v));
                    }
                }
                m.objects.push(ObjectModel {
                    index,
                    name: text_of(child(o, "Name")).unwrap_or_default(),
                    type_name,
                    bit_size: match text_of(child(o, "BitSize")) {
                        Some(s) => num("Object/BitSize", &s)?,
                        None => 0,
                    },
                    sub_names,
                });
            }
        }
    }
    Ok(m)
}

/// `Info/StateMachine/Timeout` and `Info/Mailbox/Timeout` of a `Device` element (ms); `None`
/// without a state-machine timeout, a missing one of the six reads 0.
fn timeouts(d: Node) -> Result<Option<oxicat_slave::device::Timeouts>, Error> {
    let info = child(d, "Info");
    let Some(sm) = info
        .and_then(|i| child(i, "StateMachine"))
        .and_then(|s| child(s, "Timeout"))
    else {
        return Ok(None);
    };
    let mbx = info
        .and_then(|i| child(i, "Mailbox"))
        .and_then(|m| child(m, "Timeout"));
    let ms = |n: Option<Node>, name: &'static str| -> Result<u32, Error> {
        match n.and_then(|n| text_of(child(n, name))) {
            Some(s) => num_u32(name, &s),
            None => Ok(0),
        }
    };
    Ok(Some(oxicat_slave::device::Timeouts {
        preop: ms(Some(sm), "PreopTimeout")?,
        safeop_op: ms(Some(sm), "SafeopOpTimeout")?,
        back_to_init: ms(Some(sm), "BackToInitTimeout")?,
        back_to_safeop: ms(Some(sm), "BackToSafeopTimeout")?,
        mailbox_request: ms(mbx, "RequestTimeout")?,
        mailbox_response: ms(mbx, "ResponseTimeout")?,
    }))
}

/// Parses ESI XML into one model per `Device` element.
pub fn parse(xml: &str) -> Result<Vec<DeviceModel>, Error> {
    let doc = roxmltree::Document::parse(xml).map_err(|e| Error::Xml(e.to_string()))?;
    let root = doc.root_element();
    if !root.has_tag_name("EtherCATInfo") {
        return Err(Error::Missing("EtherCATInfo"));
    }
    let vendor = child(root, "Vendor").ok_or(Error::Missing("Vendor"))?;
    let vid = text_of(child(vendor, "Id")).ok_or(Error::Missing("Vendor/Id"))?;
    let vendor_id = num_u32("Vendor/Id", &vid)?;
    let vendor_name = text_of(child(vendor, "Name"));
    let devices = child(root, "Descriptions")
        .and_then(|d| child(d, "Devices"))
        .ok_or(Error::Missing("Descriptions/Devices"))?;
    children(devices, "Device")
        .map(|d| device(vendor_id, vendor_name.clone(), d))
        .collect()
}
