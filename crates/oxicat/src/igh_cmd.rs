//! Verbs and output formats after the IgH `ethercat` tool that stand on their own:
//! `slaves -v` blocks, `version`, `fw-image` (a firmware image for `foe-write`),
//! `device list`, `cstruct` (C arrays, and Rust structs for ethercrab-wire), `data`,
//! `graph` and the IgH format of `pdos`.

use std::path::Path;

use oxicat_master::SlaveInfo;

/// One slave as `ethercat slaves -v` shows it: a block of `Key: value` lines.
pub fn slave_verbose(s: &SlaveInfo) -> String {
    let mut t = format!("=== Slave {} ===\n", s.position);
    t.push_str(&format!("Device: {}\n", s.name));
    t.push_str(&format!("State: {}\n", s.status));
    t.push_str(&format!(
        "Station address: 0x{:04x}\nAlias: 0x{:04x}\n",
        s.address, s.alias
    ));
    t.push_str("Identity:\n");
    t.push_str(&format!("  Vendor Id:       0x{:08x}\n", s.vendor_id));
    t.push_str(&format!("  Product code:    0x{:08x}\n", s.product_code));
    t.push_str(&format!("  Revision number: 0x{:08x}\n", s.revision));
    t.push_str(&format!("  Serial number:   0x{:08x}\n", s.serial));
    t.push_str("Ports:\n  Port  Link  Loop\n");
    for p in 0..4 {
        t.push_str(&format!(
            "   {p}    {:<4}  {}\n",
            if s.links[p] { "up" } else { "down" },
            if s.open[p] { "open" } else { "closed" }
        ));
    }
    t.push_str(&format!("DC propagation delay: {} ns\n", s.delay_ns));
    t
}

/// `oxicat version`: the tool's name and version.
pub fn version() -> String {
    format!(
        "oxicat {} (EtherCAT master verbs on ethercrab 0.7, slave stack, virtual segment)\n",
        env!("CARGO_PKG_VERSION")
    )
}

/// `oxicat device list`: every device definition, one line each.
pub fn device_list() -> String {
    oxicat_devices::registry::kits()
        .iter()
        .map(|k| format!("{:<16} {}\n", k.name, k.description))
        .collect()
}

/// `oxicat fw-image <device> <payload> -o <image>`: the payload wrapped in the firmware image
/// header of `device` (identity, length, CRC-32), as `foe-write` sends it.
pub fn fw_image(device: &str, payload: &Path, output: &Path) -> Result<String, crate::CliError> {
    let def = crate::device_def(device)?;
    let data = std::fs::read(payload).map_err(|e| {
        crate::CliError::Io(std::io::Error::new(
            e.kind(),
            format!("{}: {e}", payload.display()),
        ))
    })?;
    let img = oxicat_esi::fwimage::build(def, &data);
    std::fs::write(output, &img).map_err(|e| {
        crate::CliError::Io(std::io::Error::new(
            e.kind(),
            format!("{}: {e}", output.display()),
        ))
    })?;
    Ok(format!(
        "{}: {} bytes ({} bytes of payload for {device})\n",
        output.display(),
        img.len(),
        data.len()
    ))
}

/// The default PDO layout of a device definition (its default assignment and mappings,
/// entry names and data types from its dictionary), as `Master::pdos` reads it from a slave.
pub fn def_pdos(def: &oxicat_slave::DeviceDef) -> oxicat_master::pdo::SlavePdos {
    use oxicat_master::pdo::{MappedEntry, Pdo, PdoSource, SlavePdos};
    use oxicat_master::value::ValueType;
    let conv = |assign: &[u16]| -> Vec<Pdo> {
        assign
            .iter()
            .filter_map(|&i| def.pdo(i))
            .map(|p| Pdo {
                index: p.index,
                name: p.name.to_string(),
                entries: p
                    .entries
                    .iter()
                    .map(|e| {
                        let od = def.object(e.index).and_then(|o| {
                            o.entries.iter().find(|x| x.sub == e.sub).map(|x| (o, x))
                        });
                        let type_code = od.map(|(_, x)| x.dtype.code());
                        let name = match od {
                            Some((o, x)) if x.sub == 0 => o.name.to_string(),
                            Some((_, x)) => x.name.to_string(),
                            None if e.index == 0 => String::new(),
                            None => format!("0x{:04X}:{:02X}", e.index, e.sub),
                        };
                        MappedEntry {
                            index: e.index,
                            sub: e.sub,
                            bits: u16::from(e.bits),
                            name,
                            ty: type_code
                                .and_then(ValueType::from_coe)
                                .unwrap_or(ValueType::Hex),
                            type_code,
                        }
                    })
                    .collect(),
            })
            .collect()
    };
    SlavePdos {
        position: 0,
        source: PdoSource::Coe,
        rx: conv(def.rx_assign),
        tx: conv(def.tx_assign),
    }
}

/// `ethercat cstruct` for one slave: the `ec_pdo_entry_info_t`, `ec_pdo_info_t` and
/// `ec_sync_info_t` arrays of the IgH master's application interface (`ecrt.h`), named
/// `slave_<p>_…`, with the slave's identity in the heading comment.
pub fn c_struct(
    p: usize,
    name: &str,
    identity: (u32, u32, u32),
    l: &oxicat_master::pdo::SlavePdos,
) -> String {
    let c = |s: &str| s.replace("*/", "* /");
    let mut t = format!(
        "/* Master 0, Slave {p}, \"{}\"\n * Vendor ID:       0x{:08x}\n * Product code:    0x{:08x}\n * Revision number: 0x{:08x}\n */\n\n",
        c(name),
        identity.0,
        identity.1,
        identity.2
    );
    let pdos: Vec<_> = l.rx.iter().chain(l.tx.iter()).collect();
    if pdos.iter().any(|p| !p.entries.is_empty()) {
        t.push_str(&format!(
            "ec_pdo_entry_info_t slave_{p}_pdo_entries[] = {{\n"
        ));
        for pdo in &pdos {
            for e in &pdo.entries {
                t.push_str(&format!(
                    "    {{0x{:04x}, 0x{:02x}, {}}}, /* {} */\n",
                    e.index,
                    e.sub,
                    e.bits,
                    c(if e.index == 0 { "Gap" } else { &e.name })
                ));
            }
        }
        t.push_str("};\n\n");
    }
    if !pdos.is_empty() {
        t.push_str(&format!("ec_pdo_info_t slave_{p}_pdos[] = {{\n"));
        let mut off = 0;
        for pdo in &pdos {
            let entries = match pdo.entries.is_empty() {
                true => "NULL".to_string(),
                false => format!("slave_{p}_pdo_entries + {off}"),
            };
            t.push_str(&format!(
                "    {{0x{:04x}, {}, {entries}}}, /* {} */\n",
                pdo.index,
                pdo.entries.len(),
                c(&pdo.name)
            ));
            off += pdo.entries.len();
        }
        t.push_str("};\n\n");
    }
    t.push_str(&format!("ec_sync_info_t slave_{p}_syncs[] = {{\n"));
    t.push_str("    {0, EC_DIR_OUTPUT, 0, NULL, EC_WD_DISABLE},\n");
    t.push_str("    {1, EC_DIR_INPUT, 0, NULL, EC_WD_DISABLE},\n");
    for (sm, dir, list, first, wd) in [
        (2, "EC_DIR_OUTPUT", &l.rx, 0, "EC_WD_ENABLE"),
        (3, "EC_DIR_INPUT", &l.tx, l.rx.len(), "EC_WD_DISABLE"),
    ] {
        match list.is_empty() {
            true => t.push_str(&format!("    {{{sm}, {dir}, 0, NULL, EC_WD_DISABLE}},\n")),
            false => t.push_str(&format!(
                "    {{{sm}, {dir}, {}, slave_{p}_pdos + {first}, {wd}}},\n",
                list.len()
            )),
        }
    }
    t.push_str("    {0xff}\n};\n");
    t
}

/// `UpperCamelCase` of a name (letters and digits kept, the rest separates words).
fn camel(s: &str) -> String {
    let mut out = String::new();
    for w in s
        .split(|c: char| !c.is_ascii_alphanumeric())
        .filter(|w| !w.is_empty())
    {
        let mut cs = w.chars();
        if let Some(f) = cs.next() {
            out.push(f.to_ascii_uppercase());
            out.extend(cs);
        }
    }
    if out.chars().next().is_none_or(|c| c.is_ascii_digit()) {
        out.insert(0, 'P');
    }
    out
}

/// A `snake_case` Rust field name for an entry name; never a keyword, never empty.
fn field_name(name: &str, index: u16, sub: u8) -> String {
    let mut out = String::new();
    let mut prev_lower = false;
    for c in name.chars() {
        if c.is_ascii_alphanumeric() {
            if c.is_ascii_uppercase() && prev_lower {
                out.push('_');
            }
            prev_lower = c.is_ascii_lowercase() || c.is_ascii_digit();
            out.push(c.to_ascii_lowercase());
        } else {
            if !out.ends_with('_') && !out.is_empty() {
                out.push('_');
            }
            prev_lower = false;
        }
    }
    let out = out.trim_end_matches('_').to_string();
    if out.is_empty() {
        return format!("obj_{index:04x}_{sub:02x}");
    }
    const KEYWORDS: &[&str] = &[
        "as", "async", "await", "break", "const", "continue", "crate", "dyn", "else", "enum",
        "extern", "false", "fn", "for", "if", "impl", "in", "let", "loop", "match", "mod", "move",
        "mut", "pub", "ref", "return", "self", "static", "struct", "super", "trait", "true",
        "type", "unsafe", "use", "where", "while", "abstract", "become", "box", "do", "final",
        "macro", "override", "priv", "try", "typeof", "unsized", "virtual", "yield", "gen",
    ];
    if out.starts_with(|c: char| c.is_ascii_digit()) {
        format!("v_{out}")
    } else if KEYWORDS.contains(&out.as_str()) {
        format!("{out}_")
    } else {
        out
    }
}

/// The Rust type of an entry of `bits` bits with CoE data type `code`.
fn rust_type(bits: u16, code: Option<u16>) -> String {
    let signed = matches!(code, Some(0x02 | 0x03 | 0x04 | 0x10 | 0x15));
    match (bits, code) {
        (1, _) => "bool".into(),
        (32, Some(0x08)) => "f32".into(),
        (64, Some(0x11)) => "f64".into(),
        (2..=8, _) if signed && bits == 8 => "i8".into(),
        (2..=8, _) => "u8".into(),
        (16 | 32 | 64, _) => format!("{}{bits}", if signed { "i" } else { "u" }),
        (b, _) if b % 8 == 0 => format!("[u8; {}]", b / 8),
        (b, _) if b < 16 => "u16".into(),
        (b, _) if b < 32 => "u32".into(),
        _ => "u64".into(),
    }
}

/// One Rust struct for a PDO image (`dir`: "Outputs" or "Inputs"), for ethercrab's
/// `EtherCrabWireReadWrite` derive: a field per mapped entry with its bit width, gaps as
/// `pre_skip`/`post_skip` of the neighbouring field. `None` when the image is empty.
fn rust_image(ty: &str, pdos: &[oxicat_master::pdo::Pdo]) -> Option<String> {
    let total: u32 = pdos
        .iter()
        .flat_map(|p| &p.entries)
        .map(|e| u32::from(e.bits))
        .sum();
    if total == 0 {
        return None;
    }
    let size = match total % 8 {
        0 => format!("bytes = {}", total / 8),
        _ => format!("bits = {total}"),
    };
    let mut fields: Vec<(String, String, String, u16, u32, u32)> = Vec::new(); // doc, name, type, bits, pre, post
    let mut names = std::collections::HashSet::new();
    let mut gap = 0u32;
    for pdo in pdos {
        for e in &pdo.entries {
            if e.index == 0 {
                gap += u32::from(e.bits);
                continue;
            }
            let base = field_name(&e.name, e.index, e.sub);
            let mut name = base.clone();
            let mut k = 2;
            while !names.insert(name.clone()) {
                name = format!("{base}_{k}");
                k += 1;
            }
            fields.push((
                format!(
                    "0x{:04X}:{:02X} {} (PDO 0x{:04X})",
                    e.index, e.sub, e.name, pdo.index
                ),
                name,
                rust_type(e.bits, e.type_code),
                e.bits,
                std::mem::take(&mut gap),
                0,
            ));
        }
    }
    match fields.last_mut() {
        Some(f) => f.5 = gap,
        None => return Some(format!("// {ty}: {total} bits of gaps only, no entries\n")),
    }
    let mut t = format!(
        "#[derive(Debug, Clone, Copy, PartialEq, Default, ethercrab_wire::EtherCrabWireReadWrite)]\n#[wire({size})]\npub struct {ty} {{\n"
    );
    for (doc, name, rt, bits, pre, post) in fields {
        let mut attr = format!("bits = {bits}");
        if pre > 0 {
            attr.push_str(&format!(", pre_skip = {pre}"));
        }
        if post > 0 {
            attr.push_str(&format!(", post_skip = {post}"));
        }
        t.push_str(&format!(
            "    /// {doc}\n    #[wire({attr})]\n    pub {name}: {rt},\n"
        ));
    }
    t.push_str("}\n");
    Some(t)
}

/// `cstruct --rust`: the slave's output (RxPDO, SM2) and input (TxPDO, SM3) images as Rust
/// structs that ethercrab-wire's derive packs and unpacks, named `<prefix>Outputs` and
/// `<prefix>Inputs`.
pub fn rust_struct(prefix: &str, heading: &str, l: &oxicat_master::pdo::SlavePdos) -> String {
    let prefix = camel(prefix);
    let mut t = format!("// {heading}\n");
    for (dir, list, what) in [
        ("Outputs", &l.rx, "RxPDO, SM2: written by the master"),
        ("Inputs", &l.tx, "TxPDO, SM3: read by the master"),
    ] {
        let name = format!("{prefix}{dir}");
        match rust_image(&name, list) {
            Some(s) => t.push_str(&format!("\n/// {what}.\n{s}")),
            None => t.push_str(&format!("\n// {name}: no {what}\n")),
        }
    }
    t
}

/// Cycles after which `data` takes the image: the slaves' inputs of the first OP cycle may
/// still be those of SAFE-OP; by the third their application has run on this master's outputs.
const DATA_CYCLES: u64 = 3;

/// `oxicat data`: brings the slaves to OP (free run, 1 ms), runs [`DATA_CYCLES`] cycles and
/// returns the process-data image of the last one, slave by slave its outputs (SM2, what
/// the master sent: zeros) then its inputs (SM3).
/// oxicat keeps no domain between commands, so the image is that of this one run; the
/// slaves are back in PRE-OP afterwards, as after `watch`.
pub fn process_image(m: &mut oxicat_master::Master) -> Result<Vec<u8>, oxicat_master::MasterError> {
    use oxicat_master::cyclic::{CycleOptions, Flow};
    m.prepare_cyclic()?;
    let mut image = Vec::new();
    m.run_cyclic(CycleOptions::default(), |io| {
        if io.cycle + 1 < DATA_CYCLES {
            return Ok(Flow::Continue);
        }
        for (o, i) in io.outputs.iter().zip(&io.inputs) {
            image.extend_from_slice(o);
            image.extend_from_slice(i);
        }
        Ok(Flow::Stop)
    })?;
    Ok(image)
}

/// A hex dump, 16 bytes a line with the byte offset: `0010: 01 02 …`.
pub fn hex_lines(b: &[u8]) -> String {
    b.chunks(16)
        .enumerate()
        .map(|(i, c)| format!("{:04x}: {}\n", i * 16, oxicat_master::value::hex(c)))
        .collect()
}

/// The links of a segment from the slaves' DL status (0x0110): `(parent, parent port,
/// child)` per slave, `None` as parent for the master. Frames pass the ports of a slave in
/// the order 0, 3, 1, 2 and the slaves in position order, so each slave hangs on the port
/// (with link, loop open) of the latest slave before it that still has one free, and the
/// first on the master; a slave is entered by port 0.
pub fn topology(slaves: &[SlaveInfo]) -> Vec<(Option<usize>, usize, usize)> {
    let mut free: Vec<(usize, Vec<usize>)> = Vec::new();
    let mut edges = Vec::new();
    for s in slaves {
        let parent = loop {
            match free.last_mut() {
                Some((p, ports)) if !ports.is_empty() => break Some((*p, ports.remove(0))),
                Some(_) => {
                    free.pop();
                }
                None => break None,
            }
        };
        match parent {
            Some((p, port)) => edges.push((Some(p), port, s.position)),
            None => edges.push((None, 0, s.position)),
        }
        let ports: Vec<usize> = [3, 1, 2]
            .into_iter()
            .filter(|&k| s.links[k] && s.open[k])
            .collect();
        free.push((s.position, ports));
    }
    edges
}

/// `oxicat graph`: the topology as Graphviz DOT, after `ethercat graph` (a master node, a
/// box per slave with its position and name, an edge per link labelled with the ports).
pub fn graph(slaves: &[SlaveInfo]) -> String {
    let esc = |s: &str| s.replace('\\', "\\\\").replace('"', "\\\"");
    let mut t = String::from(
        "/* EtherCAT bus graph. Generated by 'oxicat graph'. */\n\nstrict graph bus {\n    rankdir=\"LR\"\n    ranksep=0.8\n    nodesep=0.8\n    node [fontname=\"Helvetica\"]\n    edge [fontname=\"Helvetica\",fontsize=\"10\"]\n\n    master [label=\"EtherCAT\\nMaster\"]\n",
    );
    for s in slaves {
        t.push_str(&format!(
            "    slave{} [shape=\"box\",label=\"{}\\n{}\"]\n",
            s.position,
            s.position,
            esc(&s.name)
        ));
    }
    t.push('\n');
    for (parent, port, child) in topology(slaves) {
        match parent {
            None => t.push_str(&format!("    master -- slave{child} [headlabel=\"0\"]\n")),
            Some(p) => t.push_str(&format!(
                "    slave{p} -- slave{child} [taillabel=\"{port}\",headlabel=\"0\"]\n"
            )),
        }
    }
    t.push_str("}\n");
    t
}

/// `pdos` as the IgH tool prints it: each sync manager of the SII
/// (`SM2: PhysAddr 0x1100, DefaultSize    0, ControlRegister 0x64, Enable 1`), under the
/// process-data ones their PDOs (`  RxPDO 0x1600 "…"`) and entries
/// (`    PDO entry 0x7000:01,  1 bit, "…"`); a `=== Master 0, Slave <p> ===` heading when
/// several slaves are listed.
pub fn pdos_text(
    p: usize,
    heading: bool,
    sms: &[oxicat_esi::model::SmModel],
    l: &oxicat_master::pdo::SlavePdos,
) -> String {
    use oxicat_esi::model::SmKind;
    let mut t = String::new();
    if heading {
        t.push_str(&format!("=== Master 0, Slave {p} ===\n"));
    }
    let sm_of = |k: SmKind, d: usize| sms.iter().position(|s| s.kind == k).unwrap_or(d);
    let (out_sm, in_sm) = (sm_of(SmKind::Outputs, 2), sm_of(SmKind::Inputs, 3));
    let pdo_lines = |t: &mut String, kind: &str, list: &[oxicat_master::pdo::Pdo]| {
        for pdo in list {
            t.push_str(&format!("  {kind} 0x{:04x} \"{}\"\n", pdo.index, pdo.name));
            for e in &pdo.entries {
                t.push_str(&format!(
                    "    PDO entry 0x{:04x}:{:02x}, {:>2} bit, \"{}\"\n",
                    e.index, e.sub, e.bits, e.name
                ));
            }
        }
    };
    for i in 0..sms.len().max(out_sm + 1).max(in_sm + 1) {
        match sms.get(i) {
            Some(sm) => t.push_str(&format!(
                "SM{i}: PhysAddr 0x{:04x}, DefaultSize {:>4}, ControlRegister 0x{:02x}, Enable {}\n",
                sm.start,
                sm.default_size.unwrap_or(0),
                sm.control,
                u8::from(sm.enable)
            )),
            None if i == out_sm || i == in_sm => t.push_str(&format!("SM{i}:\n")),
            None => continue,
        }
        if i == out_sm {
            pdo_lines(&mut t, "RxPDO", &l.rx);
        }
        if i == in_sm {
            pdo_lines(&mut t, "TxPDO", &l.tx);
        }
    }
    t
}

#[cfg(test)]
mod tests {
    use oxicat_master::pdo::{MappedEntry, Pdo};
    use oxicat_master::value::ValueType;

    fn e(index: u16, sub: u8, bits: u16, name: &str, code: Option<u16>) -> MappedEntry {
        MappedEntry {
            index,
            sub,
            bits,
            name: name.into(),
            ty: ValueType::Hex,
            type_code: code,
        }
    }

    #[test]
    fn gaps_become_skips_and_names_identifiers() {
        let pdo = Pdo {
            index: 0x1A00,
            name: "x".into(),
            entries: vec![
                e(0x6000, 1, 1, "Input 1", Some(1)),
                e(0, 0, 7, "", None),
                e(0x6001, 0, 16, "type", Some(3)),
                e(0x6001, 0, 16, "type", Some(3)),
                e(0x6002, 0, 8, "1st value", Some(5)),
                e(0, 0, 8, "", None),
            ],
        };
        let t = super::rust_image("XInputs", &[pdo]).unwrap();
        assert!(t.contains("#[wire(bytes = 7)]"), "{t}");
        assert!(
            t.contains("#[wire(bits = 1)]\n    pub input_1: bool,"),
            "{t}"
        );
        assert!(
            t.contains("#[wire(bits = 16, pre_skip = 7)]\n    pub type_: i16,"),
            "{t}"
        );
        assert!(t.contains("pub type__2: i16,"), "{t}");
        assert!(
            t.contains("#[wire(bits = 8, post_skip = 8)]\n    pub v_1st_value: u8,"),
            "{t}"
        );
    }

    fn slave(position: usize, ports: [bool; 4]) -> oxicat_master::SlaveInfo {
        oxicat_master::SlaveInfo {
            position,
            address: 0x1000 + position as u16,
            alias: 0,
            status: oxicat_master::al::AlStatus { raw: 2, code: 0 },
            name: format!("s{position}"),
            vendor_id: 0,
            product_code: 0,
            revision: 0,
            serial: 0,
            links: ports,
            open: ports,
            delay_ns: 0,
        }
    }

    #[test]
    fn topology_follows_the_processing_order_through_a_branch() {
        // 0: a junction with ports 0, 3 and 1; 1 hangs on its port 3 and has port 1 on to 2;
        // 3 comes back to the junction's port 1.
        let s = [
            slave(0, [true, true, false, true]),
            slave(1, [true, true, false, false]),
            slave(2, [true, false, false, false]),
            slave(3, [true, false, false, false]),
        ];
        assert_eq!(
            super::topology(&s),
            [
                (None, 0, 0),
                (Some(0), 3, 1),
                (Some(1), 1, 2),
                (Some(0), 1, 3)
            ]
        );
        let dot = super::graph(&s);
        assert!(
            dot.contains("slave0 -- slave3 [taillabel=\"1\",headlabel=\"0\"]"),
            "{dot}"
        );
    }
}
