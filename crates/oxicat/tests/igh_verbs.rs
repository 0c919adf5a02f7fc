//! The verbs and spellings after the IgH `ethercat` tool, and the README's helper verbs:
//! `version`, `device list`, `fw-image`, `slaves -v`, `sii_read`/`reg_read`/`foe_read`.

mod bin_common;

fn oxicat(args: &[&str]) -> (bool, String, String) {
    bin_common::oxicat_in(None, args)
}

fn ok(args: &[&str]) -> String {
    let (s, out, err) = oxicat(args);
    assert!(s, "oxicat {args:?} failed: {err}");
    out
}

#[test]
fn version_and_device_list() {
    let out = ok(&["version"]);
    assert!(
        out.starts_with(&format!("oxicat {}", env!("CARGO_PKG_VERSION"))),
        "{out}"
    );
    let out = ok(&["device", "list"]);
    for name in [
        "demo",
        "demo-additions",
        "tue-es030",
        "cia402-joint",
        "axis-hub",
    ] {
        assert!(
            out.lines()
                .any(|l| l.split_whitespace().next() == Some(name)),
            "{out}"
        );
    }
}

#[test]
fn fw_image_builds_what_foe_write_installs() {
    let dir = std::env::temp_dir().join(format!("oxicat-fwimage-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let payload = dir.join("app.bin");
    std::fs::write(&payload, vec![0x5Au8; 1000]).unwrap();
    let img = dir.join("app.img");
    let out = ok(&[
        "fw-image",
        "demo",
        payload.to_str().unwrap(),
        "-o",
        img.to_str().unwrap(),
    ]);
    assert!(out.contains("1032 bytes"), "{out}");
    let built = std::fs::read(&img).unwrap();
    assert_eq!(
        built,
        oxicat_esi::fwimage::build(&oxicat_devices::demo::DEF, &[0x5A; 1000])
    );
    let out = ok(&[
        "foe-write",
        "--sim",
        "demo:1",
        img.to_str().unwrap(),
        "--name",
        "firmware.bin",
    ]);
    assert!(out.contains("length=1000"), "{out}");
    let (s, _, err) = oxicat(&[
        "fw-image",
        "nosuch",
        payload.to_str().unwrap(),
        "-o",
        "x.img",
    ]);
    assert!(!s && err.contains("nosuch"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn igh_spellings_and_slaves_verbose() {
    let out = ok(&["slaves", "-v", "--sim", "demo:2"]);
    assert_eq!(out.matches("=== Slave ").count(), 2, "{out}");
    assert!(out.contains("  Vendor Id:       0xe0000000"), "{out}");
    assert!(out.contains("State: PREOP"), "{out}");
    let out = ok(&["sii_read", "--sim", "demo:1"]);
    assert!(out.contains("Vendor"), "{out}");
    let out = ok(&["reg_read", "0x0130", "1", "--sim", "demo:1"]);
    assert_eq!(out, "0x02\n");
    let out = ok(&["foe_read", "version.txt", "--sim", "demo:1"]);
    assert!(out.contains("vendor_id=0xE0000000"), "{out}");
}

/// The `#[wire(...)]` bit widths (field bits and skips) of each generated struct, by name, and
/// the struct's declared size in bits; every field name is checked to be a Rust identifier.
fn wire_structs(rust: &str) -> Vec<(String, u32, u32)> {
    let attr = |l: &str, key: &str| -> u32 {
        l.trim_start_matches("#[wire(")
            .trim_end_matches(")]")
            .split(", ")
            .filter_map(|kv| kv.split_once(" = "))
            .filter(|(k, _)| *k == key)
            .map(|(_, v)| v.parse::<u32>().unwrap())
            .sum()
    };
    let lines: Vec<&str> = rust.lines().map(str::trim).collect();
    let mut out: Vec<(String, u32, u32)> = Vec::new();
    for (k, line) in lines.iter().enumerate() {
        let next = lines.get(k + 1).copied().unwrap_or("");
        if let Some(name) = next.strip_prefix("pub struct ") {
            assert!(line.starts_with("#[wire("), "struct without a size: {next}");
            let declared = attr(line, "bytes") * 8 + attr(line, "bits");
            out.push((name.trim_end_matches(" {").to_string(), declared, 0));
        } else if line.starts_with("#[wire(") {
            let f = next.strip_prefix("pub ").expect("a field after #[wire]");
            let name = f.split(':').next().unwrap();
            assert!(
                name.chars()
                    .next()
                    .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
                    && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_'),
                "not an identifier: {name:?}"
            );
            out.last_mut().expect("a field inside a struct").2 +=
                attr(line, "bits") + attr(line, "pre_skip") + attr(line, "post_skip");
        }
    }
    out
}

#[test]
fn cstruct_rust_from_a_device_adds_up_to_its_sync_managers() {
    for name in ["demo", "cia402-joint"] {
        let def = oxicat::device_def(name).unwrap();
        let rust = ok(&["cstruct", "--device", name, "--rust"]);
        let structs = wire_structs(&rust);
        assert_eq!(structs.len(), 2, "{rust}");
        let (o, i) = (&structs[0], &structs[1]);
        assert!(
            o.0.ends_with("Outputs") && i.0.ends_with("Inputs"),
            "{rust}"
        );
        assert_eq!(
            o.1,
            def.default_output_bits(),
            "{name} outputs declared\n{rust}"
        );
        assert_eq!(
            o.2,
            def.default_output_bits(),
            "{name} output fields\n{rust}"
        );
        assert_eq!(
            i.1,
            def.default_input_bits(),
            "{name} inputs declared\n{rust}"
        );
        assert_eq!(i.2, def.default_input_bits(), "{name} input fields\n{rust}");
        assert!(
            rust.contains("ethercrab_wire::EtherCrabWireReadWrite"),
            "{rust}"
        );
    }
    let rust = ok(&["cstruct", "--device", "cia402-joint", "--rust"]);
    assert!(
        rust.contains("#[wire(bits = 16)]\n    pub controlword: u16,"),
        "{rust}"
    );
    assert!(
        rust.contains("#[wire(bits = 32)]\n    pub target_position: i32,"),
        "{rust}"
    );
    let (s, _, err) = oxicat(&["cstruct", "--device", "nosuch"]);
    assert!(!s && err.contains("nosuch"), "{err}");
}

#[test]
fn cstruct_c_arrays_from_the_live_mapping() {
    let c = ok(&["cstruct", "--sim", "demo:2", "-p", "1"]);
    assert!(c.starts_with("/* Master 0, Slave 1, "), "{c}");
    assert!(
        c.contains("ec_pdo_entry_info_t slave_1_pdo_entries[] = {"),
        "{c}"
    );
    assert!(c.contains("ec_sync_info_t slave_1_syncs[] = {"), "{c}");
    // As many entry lines as the mapping has entries, each PDO pointing at its first.
    let def = &oxicat_devices::demo::DEF;
    let n: usize = def
        .rx_assign
        .iter()
        .chain(def.tx_assign)
        .map(|&i| def.pdo(i).unwrap().entries.len())
        .sum();
    assert_eq!(
        c.lines()
            .filter(|l| l.trim_start().starts_with("{0x") && l.trim() != "{0xff}")
            .count()
            - def.rx_assign.len()
            - def.tx_assign.len(),
        n,
        "{c}"
    );
    assert!(
        c.contains(&format!(
            "{{0x{:04x}, {}, slave_1_pdo_entries + 0}}",
            def.rx_assign[0],
            def.pdo(def.rx_assign[0]).unwrap().entries.len()
        )),
        "{c}"
    );
    assert!(
        c.contains(&format!(
            "{{2, EC_DIR_OUTPUT, {}, slave_1_pdos + 0, EC_WD_ENABLE}}",
            def.rx_assign.len()
        )),
        "{c}"
    );
    assert!(
        c.contains(&format!(
            "{{3, EC_DIR_INPUT, {}, slave_1_pdos + {}, EC_WD_DISABLE}}",
            def.tx_assign.len(),
            def.rx_assign.len()
        )),
        "{c}"
    );
    let rust = ok(&["cstruct", "--sim", "demo:1", "--rust"]);
    let structs = wire_structs(&rust);
    assert_eq!(structs[0].2, def.default_output_bits(), "{rust}");
    assert_eq!(structs[1].2, def.default_input_bits(), "{rust}");
}

/// Bytes of a `data` hex dump (`0010: 01 02 …` lines), offsets checked.
fn unhex(dump: &str) -> Vec<u8> {
    let mut b = Vec::new();
    for line in dump.lines() {
        let (off, bytes) = line.split_once(": ").expect("offset: bytes");
        assert_eq!(usize::from_str_radix(off, 16).unwrap(), b.len(), "{dump}");
        b.extend(
            bytes
                .split_whitespace()
                .map(|x| u8::from_str_radix(x, 16).unwrap()),
        );
    }
    b
}

#[test]
fn data_shows_the_process_image_of_every_slave() {
    let def = oxicat::device_def("demo").unwrap();
    let (o, i) = (
        def.default_output_bits().div_ceil(8) as usize,
        def.default_input_bits().div_ceil(8) as usize,
    );
    let img = unhex(&ok(&["data", "--sim", "demo:2"]));
    assert_eq!(img.len(), 2 * (o + i), "{img:02x?}");
    // The demo's inputs: InINT32Var3 (offset 14) counts the slave's cycles, InINT32Var4
    // (offset 18) holds the virtual board's buttons, 0xA0 + node; the outputs are zero.
    for k in 0..2 {
        let base = k * (o + i);
        assert!(img[base..base + o].iter().all(|&b| b == 0), "{img:02x?}");
        let inputs = &img[base + o..base + o + i];
        assert!(
            i32::from_le_bytes(inputs[14..18].try_into().unwrap()) > 0,
            "{inputs:02x?}"
        );
        assert_eq!(inputs[18], 0xA0 + k as u8, "{inputs:02x?}");
    }
    let dir = std::env::temp_dir().join(format!("oxicat-data-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let f = dir.join("image.bin");
    ok(&[
        "data",
        "--sim",
        "demo:1",
        "--binary",
        "-o",
        f.to_str().unwrap(),
    ]);
    let bin = std::fs::read(&f).unwrap();
    assert_eq!(bin.len(), o + i);
    assert_eq!(bin[o + 18], 0xA0);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn alias_verb_writes_and_refuses_bad_input() {
    let out = ok(&["alias", "-p", "1", "0x1234", "--sim", "demo:2"]);
    assert!(
        out.contains("alias 0x1234") && out.contains("in effect"),
        "{out}"
    );
    let (s, _, err) = oxicat(&["alias", "0x12345", "--sim", "demo:1"]);
    assert!(
        !s && err.contains("0x12345") && err.contains("0xFFFF"),
        "{err}"
    );
    let (s, _, err) = oxicat(&["alias", "-p", "3", "1", "--sim", "demo:1"]);
    assert!(!s && err.contains('3'), "{err}");
}

#[test]
fn graph_is_dot_of_the_line() {
    let dot = ok(&["graph", "--sim", "demo:3"]);
    assert!(
        dot.contains("strict graph bus {") && dot.trim_end().ends_with('}'),
        "{dot}"
    );
    let nodes: Vec<_> = dot
        .lines()
        .filter(|l| l.trim_start().starts_with("slave") && l.contains("shape=\"box\""))
        .collect();
    assert_eq!(nodes.len(), 3, "{dot}");
    assert!(
        nodes[2].contains("label=\"2\\nEtherCAT_Application_SPI\""),
        "{dot}"
    );
    let edges: Vec<_> = dot
        .lines()
        .map(str::trim)
        .filter(|l| l.contains(" -- "))
        .collect();
    assert_eq!(
        edges,
        [
            "master -- slave0 [headlabel=\"0\"]",
            "slave0 -- slave1 [taillabel=\"1\",headlabel=\"0\"]",
            "slave1 -- slave2 [taillabel=\"1\",headlabel=\"0\"]",
        ],
        "{dot}"
    );
}

#[test]
fn pdos_prints_as_the_igh_tool() {
    let out = ok(&["pdos", "--sim", "demo:2"]);
    assert_eq!(out.matches("=== Master 0, Slave ").count(), 2, "{out}");
    assert!(
        out.contains(
            "SM2: PhysAddr 0x1100, DefaultSize   24, ControlRegister 0x64, Enable 1\n  RxPDO 0x1600 \"Buttons\"\n    PDO entry 0x7000:01,  1 bit, \"Button1\"\n"
        ),
        "{out}"
    );
    assert!(out.contains("SM3: PhysAddr "), "{out}");
    assert!(
        out.contains("  TxPDO 0x1a01 \"")
            && out.contains("    PDO entry 0x6010:01, 32 bit, \"InINT32Var1\"\n"),
        "{out}"
    );
    // One slave: no heading, as in the IgH tool.
    let one = ok(&["pdos", "-p", "1", "--sim", "demo:2"]);
    assert!(
        one.starts_with("SM0: PhysAddr 0x1000, DefaultSize  128"),
        "{one}"
    );
}
