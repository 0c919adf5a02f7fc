//! The comparable device model that ESI, SII and a definition are all reduced to, and the
//! field-by-field comparison producing typed [`Finding`]s.

use oxicat_slave::{DataType, DeviceDef, PdoDef};

/// Use of a sync manager.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SmKind {
    /// Mailbox master → slave (SM0).
    MBoxOut,
    /// Mailbox slave → master (SM1).
    MBoxIn,
    /// Process data outputs.
    Outputs,
    /// Process data inputs.
    Inputs,
    /// Unused or unknown.
    Other,
}

/// Use of an FMMU.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FmmuKind {
    /// Outputs.
    Outputs,
    /// Inputs.
    Inputs,
    /// Mailbox state polling.
    MBoxState,
    /// Unused or unknown.
    Other,
}

/// One sync manager.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SmModel {
    /// What it is used for.
    pub kind: SmKind,
    /// Physical start address.
    pub start: u16,
    /// Default size in bytes, if the description gives one.
    pub default_size: Option<u16>,
    /// Control byte.
    pub control: u8,
    /// Enabled by default.
    pub enable: bool,
}

/// One PDO entry.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EntryModel {
    /// Mapped index (0: gap).
    pub index: u16,
    /// Mapped subindex.
    pub sub: u8,
    /// Bit length.
    pub bits: u8,
    /// Name, if any.
    pub name: Option<String>,
    /// CoE data type code (0x0001 BOOL …), if known.
    pub data_type: Option<u16>,
}

/// One PDO.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PdoModel {
    /// Mapping object index.
    pub index: u16,
    /// Name.
    pub name: Option<String>,
    /// Sync manager it is assigned to by default.
    pub sm: Option<u8>,
    /// Fixed content.
    pub fixed: bool,
    /// Mandatory.
    pub mandatory: bool,
    /// Entries.
    pub entries: Vec<EntryModel>,
}

/// CoE details.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CoeModel {
    /// SDO information.
    pub sdo_info: bool,
    /// PDO assignment writable.
    pub pdo_assign: bool,
    /// PDO configuration writable.
    pub pdo_config: bool,
    /// Upload PDO configuration at start-up.
    pub pdo_upload: bool,
    /// Complete access.
    pub complete_access: bool,
}

/// Mailbox protocols.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct MailboxModel {
    /// CoE details, if CoE is supported.
    pub coe: Option<CoeModel>,
    /// FoE supported.
    pub foe: bool,
    /// EoE supported.
    pub eoe: bool,
    /// SoE supported.
    pub soe: bool,
}

/// One DC operation mode.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DcModel {
    /// Name.
    pub name: Option<String>,
    /// Description.
    pub desc: Option<String>,
    /// AssignActivate (0x0980).
    pub assign_activate: u16,
    /// SYNC0 cycle time in ns.
    pub cycle0: u32,
    /// SYNC0 shift in ns.
    pub shift0: i64,
    /// SYNC0 cycle factor.
    pub sync0_factor: i16,
    /// SYNC1 cycle factor.
    pub sync1_factor: i16,
    /// SYNC1 shift in ns.
    pub shift1: i64,
}

/// EEPROM description.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EepromModel {
    /// Size in bytes.
    pub byte_size: u32,
    /// Configuration area bytes as given (at most the 14 CRC-covered bytes compared).
    pub config_data: Vec<u8>,
    /// Bootstrap mailbox (rx offset, rx size, tx offset, tx size), if any.
    pub bootstrap: Option<[u16; 4]>,
}

/// One object of an ESI dictionary (SII images carry none).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ObjectModel {
    /// Index.
    pub index: u16,
    /// Name.
    pub name: String,
    /// Type name (e.g. `UDINT`, `DT1018`).
    pub type_name: String,
    /// Bit size.
    pub bit_size: u32,
    /// Subitem names (subindex order) for records/arrays.
    pub sub_names: Vec<String>,
}

/// A device as ESI, SII or a definition describe it.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct DeviceModel {
    /// Vendor ID.
    pub vendor_id: u32,
    /// Vendor name (ESI only).
    pub vendor_name: Option<String>,
    /// Product code.
    pub product_code: u32,
    /// Revision.
    pub revision: u32,
    /// Device name.
    pub name: Option<String>,
    /// Order code / type name.
    pub order_code: Option<String>,
    /// Group type.
    pub group_type: Option<String>,
    /// FMMUs.
    pub fmmus: Vec<FmmuKind>,
    /// Sync managers.
    pub sms: Vec<SmModel>,
    /// RxPDOs.
    pub rx_pdos: Vec<PdoModel>,
    /// TxPDOs.
    pub tx_pdos: Vec<PdoModel>,
    /// Mailbox protocols (`None`: no mailbox).
    pub mailbox: Option<MailboxModel>,
    /// DC operation modes.
    pub dc: Vec<DcModel>,
    /// EEPROM.
    pub eeprom: Option<EepromModel>,
    /// Dictionary objects (ESI only; empty otherwise).
    pub objects: Vec<ObjectModel>,
    /// The identity strings a master reads over CoE, `(index, text)` for 0x1008 (name),
    /// 0x1009 (hardware version) and 0x100A (software version), as far as the description
    /// carries them: the definition all three, an ESI the `DefaultString` of its objects
    /// (what the OD serves), an SII only the name (0x1008 = its general name string).
    pub id_strings: Vec<(u16, String)>,
    /// CoE profile number: the low word of 0x1000 for a definition, `Profile/ProfileNo` in
    /// an ESI (SII images carry none).
    pub profile_no: Option<u32>,
    /// The device type 0x1000: the definition's, the `DefaultData` of an ESI's object
    /// 0x1000 (SII images carry none).
    pub device_type: Option<u32>,
    /// State-machine and mailbox timeouts (definition, ESI `Info`; SII images carry none).
    pub timeouts: Option<oxicat_slave::device::Timeouts>,
}

/// A difference between two descriptions of a device (left vs right).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Finding {
    /// Vendor ID, product code or revision differ.
    Identity {
        /// `vendor_id`, `product_code`, `revision` or `profile_no`.
        field: &'static str,
        /// Left value.
        left: u32,
        /// Right value.
        right: u32,
    },
    /// A text (name, order code, group) differs.
    Text {
        /// Which text.
        field: &'static str,
        /// Left value.
        left: String,
        /// Right value.
        right: String,
    },
    /// FMMU usage lists differ.
    Fmmus {
        /// Left list.
        left: Vec<FmmuKind>,
        /// Right list.
        right: Vec<FmmuKind>,
    },
    /// Different numbers of sync managers.
    SmCount {
        /// Left count.
        left: usize,
        /// Right count.
        right: usize,
    },
    /// A sync manager field differs.
    Sm {
        /// SM number.
        sm: usize,
        /// `kind`, `start`, `default_size`, `control` or `enable`.
        field: &'static str,
        /// Left value.
        left: String,
        /// Right value.
        right: String,
    },
    /// A PDO exists on one side only.
    PdoMissing {
        /// PDO index.
        index: u16,
        /// True: missing on the right; false: missing on the left.
        on_right: bool,
    },
    /// A PDO field differs.
    Pdo {
        /// PDO index.
        index: u16,
        /// `name`, `sm`, `fixed`, `mandatory`, `entry_count`.
        field: &'static str,
        /// Left value.
        left: String,
        /// Right value.
        right: String,
    },
    /// A PDO entry differs.
    PdoEntry {
        /// PDO index.
        pdo: u16,
        /// Entry position.
        entry: usize,
        /// `index`, `sub`, `bits`, `name`, `data_type`.
        field: &'static str,
        /// Left value.
        left: String,
        /// Right value.
        right: String,
    },
    /// Mailbox protocol support differs.
    Mailbox {
        /// Which flag.
        field: &'static str,
        /// Left value.
        left: bool,
        /// Right value.
        right: bool,
    },
    /// Different numbers of DC op modes.
    DcCount {
        /// Left count.
        left: usize,
        /// Right count.
        right: usize,
    },
    /// A DC op mode field differs.
    Dc {
        /// Mode position.
        mode: usize,
        /// Which field.
        field: &'static str,
        /// Left value.
        left: String,
        /// Right value.
        right: String,
    },
    /// EEPROM size or configuration data differ.
    Eeprom {
        /// `byte_size`, `config_data` or `bootstrap`.
        field: &'static str,
        /// Left value.
        left: String,
        /// Right value.
        right: String,
    },
    /// State-machine or mailbox timeouts differ.
    Timeouts {
        /// Left value.
        left: Option<oxicat_slave::device::Timeouts>,
        /// Right value.
        right: Option<oxicat_slave::device::Timeouts>,
    },
    /// One description disagrees with itself on its CoE profile: the profile number it
    /// states (`Profile/ProfileNo`, the low word of 0x1000) against the profile its
    /// dictionary implements or the other place that states it.
    Profile {
        /// The profile number stated (ESI `ProfileNo`, or the low word of 0x1000).
        stated: u32,
        /// Where it is stated.
        stated_by: &'static str,
        /// The profile number the other place implies.
        implied: u32,
        /// What implies it.
        implied_by: &'static str,
    },
}

impl core::fmt::Display for Finding {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Finding::Profile {
                stated,
                stated_by,
                implied,
                implied_by,
            } => write!(
                f,
                "profile number: {stated_by} says {stated} ({}) but {implied_by} makes it {implied} \
                 ({}); the low word of 0x1000 and the ESI's Profile/ProfileNo must name the \
                 profile the dictionary implements",
                profile_name(*stated),
                profile_name(*implied)
            ),
            Finding::Identity { field, left, right } => {
                write!(f, "{field}: {left} ({left:#x}) against {right} ({right:#x})")
            }
            Finding::Text { field, left, right }
            | Finding::Eeprom { field, left, right }
            | Finding::Pdo {
                field, left, right, ..
            } => write!(f, "{field}: {left:?} against {right:?} ({self:?})"),
            other => write!(f, "{other:?}"),
        }
    }
}

/// The name of a CoE device profile number (ETG.1004 / CiA), for messages.
pub fn profile_name(p: u32) -> &'static str {
    match p {
        0 => "no profile",
        401 => "CiA401 generic I/O",
        402 => "CiA402 drive",
        404 => "CiA404 measuring device",
        5001 => "ETG.5001 modular device",
        _ => "another profile",
    }
}

/// What a description says about its profile against itself: the ESI's `ProfileNo`
/// against the low word of its own 0x1000 (`Finding::Profile`).
pub fn self_check(m: &DeviceModel) -> Vec<Finding> {
    let mut f = Vec::new();
    if let (Some(p), Some(t)) = (m.profile_no, m.device_type) {
        if p != t & 0xFFFF {
            f.push(Finding::Profile {
                stated: p,
                stated_by: "Profile/ProfileNo",
                implied: t & 0xFFFF,
                implied_by: "the low word of 0x1000",
            });
        }
    }
    f
}

/// Compares two models. Fields one side does not carry (`None`, empty ESI PD SM sizes, no
/// objects in SII) are not compared.
pub fn compare(a: &DeviceModel, b: &DeviceModel) -> Vec<Finding> {
    let mut f = Vec::new();
    for (field, l, r) in [
        ("vendor_id", a.vendor_id, b.vendor_id),
        ("product_code", a.product_code, b.product_code),
        ("revision", a.revision, b.revision),
    ] {
        if l != r {
            f.push(Finding::Identity {
                field,
                left: l,
                right: r,
            });
        }
    }
    for (field, l, r) in [
        ("vendor_name", &a.vendor_name, &b.vendor_name),
        ("name", &a.name, &b.name),
        ("order_code", &a.order_code, &b.order_code),
        ("group_type", &a.group_type, &b.group_type),
    ] {
        text(&mut f, field, l, r);
    }
    if let (Some(l), Some(r)) = (a.profile_no, b.profile_no) {
        if l != r {
            f.push(Finding::Identity {
                field: "profile_no",
                left: l,
                right: r,
            });
        }
    }
    if let (Some(l), Some(r)) = (a.device_type, b.device_type) {
        if l != r {
            f.push(Finding::Identity {
                field: "device_type",
                left: l,
                right: r,
            });
        }
    }
    if a.timeouts.is_some() && b.timeouts.is_some() && a.timeouts != b.timeouts {
        f.push(Finding::Timeouts {
            left: a.timeouts,
            right: b.timeouts,
        });
    }
    // The k-th string of an index on one side against the k-th of that index on the other
    // (an image may list an index twice; matching each with the first on the other side
    // made a model differ from itself).
    for (k, (index, l)) in a.id_strings.iter().enumerate() {
        let nth = a.id_strings[..k].iter().filter(|(i, _)| i == index).count();
        if let Some((_, r)) = b.id_strings.iter().filter(|(i, _)| i == index).nth(nth) {
            let field = match index {
                0x1008 => "0x1008",
                0x1009 => "0x1009",
                _ => "0x100A",
            };
            text(&mut f, field, &Some(l.clone()), &Some(r.clone()));
        }
    }
    if trim_fmmus(&a.fmmus) != trim_fmmus(&b.fmmus) {
        f.push(Finding::Fmmus {
            left: a.fmmus.clone(),
            right: b.fmmus.clone(),
        });
    }
    if a.sms.len() != b.sms.len() {
        f.push(Finding::SmCount {
            left: a.sms.len(),
            right: b.sms.len(),
        });
    }
    for (i, (l, r)) in a.sms.iter().zip(&b.sms).enumerate() {
        let mut d = |field, x: String, y: String| {
            if x != y {
                f.push(Finding::Sm {
                    sm: i,
                    field,
                    left: x,
                    right: y,
                });
            }
        };
        d("kind", format!("{:?}", l.kind), format!("{:?}", r.kind));
        d(
            "start",
            format!("{:#06x}", l.start),
            format!("{:#06x}", r.start),
        );
        if let (Some(x), Some(y)) = (l.default_size, r.default_size) {
            d("default_size", x.to_string(), y.to_string());
        }
        d(
            "control",
            format!("{:#04x}", l.control),
            format!("{:#04x}", r.control),
        );
        d("enable", l.enable.to_string(), r.enable.to_string());
    }
    pdos(&mut f, &a.rx_pdos, &b.rx_pdos);
    pdos(&mut f, &a.tx_pdos, &b.tx_pdos);
    match (&a.mailbox, &b.mailbox) {
        (Some(l), Some(r)) => {
            let lc = l.coe.unwrap_or_default();
            let rc = r.coe.unwrap_or_default();
            for (field, x, y) in [
                ("coe", l.coe.is_some(), r.coe.is_some()),
                ("foe", l.foe, r.foe),
                ("eoe", l.eoe, r.eoe),
                ("soe", l.soe, r.soe),
                ("coe.sdo_info", lc.sdo_info, rc.sdo_info),
                ("coe.pdo_assign", lc.pdo_assign, rc.pdo_assign),
                ("coe.pdo_config", lc.pdo_config, rc.pdo_config),
                ("coe.pdo_upload", lc.pdo_upload, rc.pdo_upload),
                (
                    "coe.complete_access",
                    lc.complete_access,
                    rc.complete_access,
                ),
            ] {
                if x != y {
                    f.push(Finding::Mailbox {
                        field,
                        left: x,
                        right: y,
                    });
                }
            }
        }
        (None, None) => {}
        (l, r) => f.push(Finding::Mailbox {
            field: "mailbox",
            left: l.is_some(),
            right: r.is_some(),
        }),
    }
    if a.dc.len() != b.dc.len() {
        f.push(Finding::DcCount {
            left: a.dc.len(),
            right: b.dc.len(),
        });
    }
    for (i, (l, r)) in a.dc.iter().zip(&b.dc).enumerate() {
        let mut d = |field, x: String, y: String| {
            if x != y {
                f.push(Finding::Dc {
                    mode: i,
                    field,
                    left: x,
                    right: y,
                });
            }
        };
        if let (Some(x), Some(y)) = (&l.name, &r.name) {
            d("name", x.clone(), y.clone());
        }
        if let (Some(x), Some(y)) = (&l.desc, &r.desc) {
            d("desc", x.clone(), y.clone());
        }
        d(
            "assign_activate",
            format!("{:#06x}", l.assign_activate),
            format!("{:#06x}", r.assign_activate),
        );
        d("cycle0", l.cycle0.to_string(), r.cycle0.to_string());
        d("shift0", l.shift0.to_string(), r.shift0.to_string());
        d(
            "sync0_factor",
            l.sync0_factor.to_string(),
            r.sync0_factor.to_string(),
        );
        d(
            "sync1_factor",
            l.sync1_factor.to_string(),
            r.sync1_factor.to_string(),
        );
        d("shift1", l.shift1.to_string(), r.shift1.to_string());
    }
    if let (Some(l), Some(r)) = (&a.eeprom, &b.eeprom) {
        let mut d = |field, x: String, y: String| {
            if x != y {
                f.push(Finding::Eeprom {
                    field,
                    left: x,
                    right: y,
                });
            }
        };
        d(
            "byte_size",
            l.byte_size.to_string(),
            r.byte_size.to_string(),
        );
        let n = l.config_data.len().min(r.config_data.len()).min(14);
        d(
            "config_data",
            hex(&l.config_data[..n]),
            hex(&r.config_data[..n]),
        );
        if let (Some(x), Some(y)) = (l.bootstrap, r.bootstrap) {
            d("bootstrap", format!("{x:04x?}"), format!("{y:04x?}"));
        }
    }
    f
}

fn trim_fmmus(v: &[FmmuKind]) -> &[FmmuKind] {
    let mut n = v.len();
    while n > 0 && v[n - 1] == FmmuKind::Other {
        n -= 1;
    }
    &v[..n]
}

fn text(f: &mut Vec<Finding>, field: &'static str, l: &Option<String>, r: &Option<String>) {
    if let (Some(x), Some(y)) = (l, r) {
        if x != y {
            f.push(Finding::Text {
                field,
                left: x.clone(),
                right: y.clone(),
            });
        }
    }
}

fn pdos(f: &mut Vec<Finding>, a: &[PdoModel], b: &[PdoModel]) {
    for (k, p) in a.iter().enumerate() {
        // A PDO index that a (broken) image lists twice: the n-th on the left against the
        // n-th on the right, so a model always equals itself.
        let nth = a[..k].iter().filter(|x| x.index == p.index).count();
        let Some(q) = b.iter().filter(|q| q.index == p.index).nth(nth) else {
            f.push(Finding::PdoMissing {
                index: p.index,
                on_right: true,
            });
            continue;
        };
        let mut d = |field, x: String, y: String| {
            if x != y {
                f.push(Finding::Pdo {
                    index: p.index,
                    field,
                    left: x,
                    right: y,
                });
            }
        };
        if let (Some(x), Some(y)) = (&p.name, &q.name) {
            d("name", x.clone(), y.clone());
        }
        if let (Some(x), Some(y)) = (p.sm, q.sm) {
            d("sm", x.to_string(), y.to_string());
        }
        d("fixed", p.fixed.to_string(), q.fixed.to_string());
        d(
            "mandatory",
            p.mandatory.to_string(),
            q.mandatory.to_string(),
        );
        d(
            "entry_count",
            p.entries.len().to_string(),
            q.entries.len().to_string(),
        );
        for (i, (x, y)) in p.entries.iter().zip(&q.entries).enumerate() {
            let mut e = |field, l: String, r: String| {
                if l != r {
                    f.push(Finding::PdoEntry {
                        pdo: p.index,
                        entry: i,
                        field,
                        left: l,
                        right: r,
                    });
                }
            };
            e(
                "index",
                format!("{:#06x}", x.index),
                format!("{:#06x}", y.index),
            );
            e("bits", x.bits.to_string(), y.bits.to_string());
            if x.index != 0 && y.index != 0 {
                e("sub", x.sub.to_string(), y.sub.to_string());
                if let (Some(l), Some(r)) = (&x.name, &y.name) {
                    e("name", l.clone(), r.clone());
                }
                if let (Some(l), Some(r)) = (x.data_type, y.data_type) {
                    e("data_type", format!("{l:#06x}"), format!("{r:#06x}"));
                }
            }
        }
    }
    for q in b {
        if !a.iter().any(|p| p.index == q.index) {
            f.push(Finding::PdoMissing {
                index: q.index,
                on_right: false,
            });
        }
    }
}

/// Upper-case hex of bytes.
/// Bytes as upper-case hex digits without separators, as ESI `ConfigData` writes them.
pub fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02X}")).collect()
}

/// ESI name of a CoE base data type.
pub fn esi_type_name(t: DataType, bits: u16) -> String {
    let name = oxicat_wire::datatype::by_code(t.code()).map_or("?", |d| d.name);
    if t.is_string() {
        format!("{name}({})", bits / 8)
    } else {
        name.into()
    }
}

/// CoE data type code of an ESI type name (`None` for unknown / structured names).
pub fn type_code(name: &str) -> Option<u16> {
    oxicat_wire::datatype::by_name(name).map(|d| d.code)
}

fn entry_data_type(def: &DeviceDef, index: u16, sub: u8) -> Option<(String, DataType)> {
    let o = def.object(index)?;
    let e = o.entries.iter().find(|e| e.sub == sub)?;
    Some((e.name.to_string(), e.dtype))
}

fn pdo_model(def: &DeviceDef, p: &PdoDef, sm: u8, assign: &[u16]) -> PdoModel {
    PdoModel {
        index: p.index,
        name: Some(p.name.to_string()),
        sm: assign.contains(&p.index).then_some(sm),
        fixed: !p.configurable,
        mandatory: assign.contains(&p.index) && !def.assign_configurable,
        entries: p
            .entries
            .iter()
            .map(|e| {
                let t = entry_data_type(def, e.index, e.sub);
                EntryModel {
                    index: e.index,
                    sub: e.sub,
                    bits: e.bits,
                    name: t.as_ref().map(|t| t.0.clone()),
                    data_type: t.map(|t| t.1.code()),
                }
            })
            .collect(),
    }
}

/// The model of a definition (what its ESI and SII must say).
pub fn from_def(def: &DeviceDef) -> DeviceModel {
    let i = def.info();
    let sm = |kind, start, size: u16, control, enable| SmModel {
        kind,
        start,
        default_size: Some(size),
        control,
        enable,
    };
    let ob = def.default_output_bits().div_ceil(8) as u16;
    let ib = def.default_input_bits().div_ceil(8) as u16;
    let c = def.coe_details();
    DeviceModel {
        vendor_id: def.identity.vendor_id,
        vendor_name: Some(i.vendor_name.to_string()),
        product_code: def.identity.product_code,
        revision: def.identity.revision,
        name: Some(def.name.to_string()),
        profile_no: crate::esi::profile_no(def),
        device_type: Some(def.device_type),
        timeouts: i.timeouts,
        id_strings: vec![
            (0x1008, def.name.to_string()),
            (0x1009, def.hw_version.to_string()),
            (0x100A, def.sw_version.to_string()),
        ],
        order_code: Some(i.order_code.to_string()),
        group_type: Some(i.group.type_name.to_string()),
        fmmus: i.fmmus.iter().map(|u| fmmu_kind(u.code())).collect(),
        sms: vec![
            sm(
                SmKind::MBoxOut,
                def.mailbox.rx_start,
                def.mailbox.rx_len,
                i.sm_control.mbx_out,
                true,
            ),
            sm(
                SmKind::MBoxIn,
                def.mailbox.tx_start,
                def.mailbox.tx_len,
                i.sm_control.mbx_in,
                true,
            ),
            sm(
                SmKind::Outputs,
                def.sm2_start,
                ob,
                i.sm_control.outputs,
                ob > 0,
            ),
            sm(
                SmKind::Inputs,
                def.sm3_start,
                ib,
                i.sm_control.inputs,
                ib > 0,
            ),
        ],
        rx_pdos: def
            .rx_pdos
            .iter()
            .map(|p| pdo_model(def, p, 2, def.rx_assign))
            .collect(),
        tx_pdos: def
            .tx_pdos
            .iter()
            .map(|p| pdo_model(def, p, 3, def.tx_assign))
            .collect(),
        mailbox: Some(MailboxModel {
            coe: i.coe.enabled.then_some(CoeModel {
                sdo_info: c & 0x02 != 0,
                pdo_assign: c & 0x04 != 0,
                pdo_config: c & 0x08 != 0,
                pdo_upload: c & 0x10 != 0,
                complete_access: c & 0x20 != 0,
            }),
            foe: i.foe,
            eoe: i.eoe,
            soe: false,
        }),
        dc: i
            .dc_modes
            .iter()
            .map(|m| DcModel {
                name: Some(m.name.to_string()),
                desc: Some(m.desc.to_string()),
                assign_activate: m.assign_activate,
                cycle0: m.cycle_sync0,
                shift0: m.shift_sync0 as i64,
                sync0_factor: m.sync0_factor,
                sync1_factor: m.sync1_factor,
                shift1: m.shift_sync1 as i64,
            })
            .collect(),
        eeprom: Some(EepromModel {
            byte_size: i.eeprom_bytes,
            config_data: config_bytes(def).to_vec(),
            bootstrap: def
                .boot_mailbox
                .map(|b| [b.rx_start, b.rx_len, b.tx_start, b.tx_len]),
        }),
        objects: Vec::new(),
    }
}

/// The 14 CRC-covered bytes of the SII configuration area of a definition.
pub fn config_bytes(def: &DeviceDef) -> [u8; 14] {
    let e = def.info().esc;
    oxicat_wire::sii::SiiConfig {
        pdi_control: e.pdi_control,
        pdi_config: e.pdi_config,
        sync_impulse_len: e.sync_impulse_len,
        pdi_config2: e.pdi_config2,
        station_alias: e.station_alias,
        ..Default::default()
    }
    .crc_bytes()
}

/// FMMU kind of an SII usage byte.
pub fn fmmu_kind(code: u8) -> FmmuKind {
    match code {
        1 => FmmuKind::Outputs,
        2 => FmmuKind::Inputs,
        3 => FmmuKind::MBoxState,
        _ => FmmuKind::Other,
    }
}
