//! Refusals with their reasons, the selector, and the two kinds of twin, on small ESIs.

use super::*;

/// An ESI with the devices `devices` (each a `<Device>…</Device>` text).
fn esi(devices: &str) -> String {
    format!(
        r##"<?xml version="1.0" encoding="UTF-8"?>
<EtherCATInfo><Vendor><Id>#x00000B95</Id><Name>Test vendor</Name></Vendor>
<Descriptions><Groups><Group><Type>IO</Type><Name>I/O</Name></Group></Groups>
<Devices>{devices}</Devices></Descriptions></EtherCATInfo>"##
    )
}

/// A CoE device `ty` with one 16-bit input 0x6000:01 mapped with `bitlen` bits.
fn coe_device(ty: &str, pc: u32, rev: u32, bitlen: u8) -> String {
    format!(
        r##"<Device Physics="YY"><Type ProductCode="#x{pc:08X}" RevisionNo="#x{rev:08X}">{ty}</Type>
<Name LcId="1031">Deutsch</Name><Name LcId="1033">{ty} analog input</Name><GroupType>IO</GroupType>
<Profile><ProfileNo>5001</ProfileNo><Dictionary>
 <DataTypes>
  <DataType><Name>DT6000</Name><BitSize>32</BitSize>
   <SubItem><SubIdx>0</SubIdx><Name>SubIndex 000</Name><Type>USINT</Type><BitSize>8</BitSize><Flags><Access>ro</Access></Flags></SubItem>
   <SubItem><SubIdx>1</SubIdx><Name>Value</Name><Type>INT</Type><BitSize>16</BitSize><Flags><Access>ro</Access><PdoMapping>T</PdoMapping></Flags></SubItem>
  </DataType>
 </DataTypes>
 <Objects>
  <Object><Index>#x1008</Index><Name>Device name</Name><Type>STRING(6)</Type><BitSize>48</BitSize><Info><DefaultString>{ty}</DefaultString></Info></Object>
  <Object><Index>#x6000</Index><Name>AI Inputs</Name><Type>DT6000</Type><BitSize>32</BitSize>
   <Info><SubItem><Name>SubIndex 000</Name><Info><DefaultData>01</DefaultData></Info></SubItem>
         <SubItem><Name>Value</Name><Info><DefaultData>3412</DefaultData></Info></SubItem></Info>
   <Flags><Access>ro</Access></Flags></Object>
  <Object><Index>#x8000</Index><Name>Gain</Name><Type>UDINT</Type><BitSize>32</BitSize><Info><DefaultValue>#x1000</DefaultValue></Info><Flags><Access WriteRestrictions="PreOP">rw</Access></Flags></Object>
 </Objects>
</Dictionary></Profile>
<Fmmu>Outputs</Fmmu><Fmmu>Inputs</Fmmu><Fmmu>MBoxState</Fmmu>
<Sm DefaultSize="128" StartAddress="#x1000" ControlByte="#x26" Enable="1">MBoxOut</Sm>
<Sm DefaultSize="128" StartAddress="#x1080" ControlByte="#x22" Enable="1">MBoxIn</Sm>
<Sm StartAddress="#x1100" ControlByte="#x64" Enable="0">Outputs</Sm>
<Sm StartAddress="#x1180" ControlByte="#x20" Enable="1">Inputs</Sm>
<TxPdo Fixed="1" Sm="3"><Index>#x1A00</Index><Name>AI</Name>
 <Entry><Index>#x6000</Index><SubIndex>1</SubIndex><BitLen>{bitlen}</BitLen><Name>Value</Name><DataType>INT</DataType></Entry></TxPdo>
<Mailbox><CoE SdoInfo="true" PdoAssign="false"/></Mailbox>
<Eeprom><ByteSize>2048</ByteSize><ConfigData>0500</ConfigData></Eeprom>
</Device>"##
    )
}

/// A digital output terminal without mailbox (outputs in SM0 at 0x0F00, as Beckhoff's).
const DIG_OUT: &str = r##"<Device Physics="KK"><Type ProductCode="#x07D83052" RevisionNo="#x00100000">EL2008</Type>
<Name>EL2008 8Ch. Dig. Output</Name><GroupType>IO</GroupType>
<Fmmu>Outputs</Fmmu>
<Sm StartAddress="#x0f00" ControlByte="#x44" Enable="1">Outputs</Sm>
<RxPdo Fixed="1" Mandatory="1" Sm="0"><Index>#x1600</Index><Name>Channel 1</Name>
 <Entry><Index>#x7000</Index><SubIndex>1</SubIndex><BitLen>1</BitLen><Name>Output</Name><DataType>BOOL</DataType></Entry></RxPdo>
<RxPdo Fixed="1" Mandatory="1" Sm="0"><Index>#x1601</Index><Name>Channel 2</Name>
 <Entry><Index>#x7010</Index><SubIndex>1</SubIndex><BitLen>1</BitLen><Name>Output</Name><DataType>BOOL</DataType></Entry>
 <Entry><Index>#x0</Index><BitLen>6</BitLen></Entry></RxPdo>
<Eeprom><ByteSize>2048</ByteSize><ConfigData>0401</ConfigData></Eeprom>
</Device>"##;

fn sel(s: &str) -> Selector {
    Selector::parse(s).expect("a selector")
}

#[test]
fn a_coe_device_becomes_a_stack_twin_with_its_dictionary() {
    let t = build(
        &esi(&coe_device("AI1", 0x1234, 2, 16)),
        &Selector::default(),
    )
    .unwrap();
    assert_eq!(t.served, Served::Stack);
    let d = t.def;
    assert_eq!(d.identity.vendor_id, 0x0B95);
    assert_eq!(d.name, "AI1 analog input", "the English name");
    assert_eq!(d.info().order_code, "AI1");
    assert_eq!(d.device_type, 5001);
    assert_eq!(d.tx_assign, &[0x1A00]);
    let v = d.entry_def(0x6000, 1).unwrap();
    assert_eq!(
        (v.dtype, v.bits, v.pdo),
        (DataType::Int16, 16, PdoMapping::Tx)
    );
    assert_eq!(v.default(), DefaultValue::bits(0x1234));
    let g = d.entry_def(0x8000, 0).unwrap();
    assert_eq!(g.default(), DefaultValue::bits(0x1000));
    assert_eq!(g.access, Access(0x07 | 0x08), "rw, written in PREOP only");
    // The SII says what the ESI says.
    let m = crate::sii::parse(&t.sii).unwrap();
    assert_eq!(
        (m.vendor_id, m.product_code, m.revision),
        (0x0B95, 0x1234, 2)
    );
    assert_eq!(m.name.as_deref(), Some("AI1 analog input"));
    assert_eq!(m.sms[3].default_size, Some(2));
    assert_eq!(t.mailbox_bytes, 128);
}

#[test]
fn a_device_without_mailbox_is_the_esc_alone_with_the_esis_sync_managers() {
    let t = build(&esi(DIG_OUT), &sel("EL2008")).unwrap();
    assert_eq!(t.served, Served::EscOnly);
    assert_ne!(t.def.info().esc.pdi_control & 0x0100, 0, "device emulation");
    let m = crate::sii::parse(&t.sii).unwrap();
    assert_eq!(m.sms.len(), 1);
    assert_eq!((m.sms[0].kind, m.sms[0].start), (SmKind::Outputs, 0x0F00));
    assert_eq!(m.sms[0].default_size, Some(1), "1 + 1 + 6 bits");
    assert_eq!(m.rx_pdos[0].sm, Some(0));
    assert!(m.mailbox.is_none());
}

#[test]
fn selectors_pick_by_type_or_product_code_and_the_highest_revision() {
    let x = esi(&[
        coe_device("AI1", 0x1234, 1, 16),
        coe_device("AI1", 0x1234, 3, 16),
        coe_device("AI2", 0x5678, 1, 16),
    ]
    .concat());
    assert_eq!(build(&x, &sel("AI1")).unwrap().def.identity.revision, 3);
    assert_eq!(build(&x, &sel("ai1:1")).unwrap().def.identity.revision, 1);
    assert_eq!(
        build(&x, &sel("#x5678")).unwrap().candidate.type_name,
        "AI2"
    );
    assert_eq!(build(&x, &sel("0x5678:#x1")).unwrap().candidate.revision, 1);
    match build(&x, &Selector::default()) {
        Err(TwinError::Ambiguous { choices, .. }) => assert_eq!(choices.len(), 3),
        other => panic!("{other:?}"),
    }
    let e = build(&x, &sel("EL9999")).unwrap_err();
    assert_eq!(
        e,
        TwinError::NoSuchType {
            asked: "EL9999".into(),
            choices: vec!["AI1".into(), "AI2".into()]
        }
    );
    assert!(e.to_string().contains("it has: AI1, AI2"), "{e}");
    let e = build(&x, &sel("AI1:7")).unwrap_err();
    assert!(
        matches!(&e, TwinError::NoSuchRevision { asked: 7, choices, .. } if choices == &[1, 3]),
        "{e:?}"
    );
    assert!(matches!(
        Selector::parse("AI1:seven"),
        Err(TwinError::BadSelector(_))
    ));
}

#[test]
fn malformed_xml_is_refused_with_the_parsers_reason() {
    let e = build("<EtherCATInfo><Vendor>", &Selector::default()).unwrap_err();
    assert!(
        matches!(&e, TwinError::Xml(m) if m.contains("never closed")),
        "{e:?}"
    );
    let e = build("<EtherCATInfo><Vendor></Vedor>", &Selector::default()).unwrap_err();
    assert!(matches!(&e, TwinError::Xml(m) if m.contains("1:")), "{e:?}");
    let e = build("<Other/>", &Selector::default()).unwrap_err();
    assert!(e.to_string().contains("not <EtherCATInfo>"), "{e}");
    let e = build(&esi(""), &Selector::default()).unwrap_err();
    assert_eq!(e, TwinError::NoDevices);
    let bad =
        esi(&coe_device("AI1", 1, 1, 16)).replace("#x6000</Index><Name>AI", "#xZZ</Index><Name>AI");
    assert!(matches!(
        build(&bad, &Selector::default()),
        Err(TwinError::Esi(_))
    ));
}

#[test]
fn inconsistent_sizes_are_refused_with_the_entry_and_both_sizes() {
    let e = build(&esi(&coe_device("AI1", 1, 1, 32)), &Selector::default()).unwrap_err();
    assert_eq!(
        e.to_string(),
        "inconsistent ESI: inconsistent sizes: PDO 0x1A00 maps 0x6000:1 with BitLen 32, the \
         dictionary gives it 16 bits"
    );
    // A PDO entry its object does not have.
    let x = esi(&coe_device("AI1", 1, 1, 16)).replace(
        "<SubIndex>1</SubIndex><BitLen>16",
        "<SubIndex>5</SubIndex><BitLen>16",
    );
    assert!(
        matches!(build(&x, &Selector::default()), Err(TwinError::Inconsistent(m)) if m.contains("0x6000:5")),
    );
}

#[test]
fn what_the_stack_cannot_represent_is_refused_with_the_limit() {
    // Process data in SM2 of a mailbox device assigned to SM3's place.
    let x = esi(&coe_device("AI1", 1, 1, 16)).replace(
        r##"<TxPdo Fixed="1" Sm="3">"##,
        r##"<TxPdo Fixed="1" Sm="2">"##,
    );
    let e = build(&x, &Selector::default()).unwrap_err();
    assert!(
        matches!(&e, TwinError::Inconsistent(m) if m.contains("SM2")),
        "{e:?}"
    );
    // More entries in one PDO than the stack maps (its host capacity).
    let n = oxicat_slave::od::MAX_PDO_ENTRIES + 1;
    let many: String = (1..=n)
        .map(|k| {
            format!(
                "<Entry><Index>#x7000</Index><SubIndex>{k}</SubIndex><BitLen>1</BitLen></Entry>"
            )
        })
        .collect();
    let x = esi(&coe_device("AI1", 1, 1, 16)).replace(
        r##"<Mailbox>"##,
        &format!(
            r##"<RxPdo Sm="2"><Index>#x1600</Index><Name>Many</Name>{many}</RxPdo><Mailbox>"##
        ),
    );
    let e = build(&x, &Selector::default()).unwrap_err();
    assert_eq!(
        e.to_string(),
        format!(
            "cannot be served: PDO 0x1600 has {n} entries; the stack maps at most {}",
            n - 1
        )
    );
}

#[test]
fn outputs_loop_back_to_inputs_of_the_same_width() {
    let x = esi(&coe_device("AI1", 1, 1, 16)).replace(
        r##"<Mailbox>"##,
        r##"<RxPdo Sm="2"><Index>#x1600</Index><Name>Out</Name><Entry><Index>#x7000</Index><SubIndex>1</SubIndex><BitLen>16</BitLen><DataType>INT</DataType></Entry></RxPdo><Mailbox>"##,
    );
    let t = build(&x, &Selector::default()).unwrap();
    assert_eq!(
        t.loopback,
        vec![(PdoEntry::new(0x7000, 1, 16), PdoEntry::new(0x6000, 1, 16))]
    );
    assert!(
        t.left_out.iter().any(|l| l.contains("0x7000")),
        "{:?}",
        t.left_out
    );
}

#[test]
fn latin1_and_bom_files_decode() {
    assert_eq!(decode(b"\xEF\xBB\xBFab"), "ab");
    assert_eq!(decode(b"\xB5s"), "\u{b5}s");
    assert_eq!(decode(&[0xFF, 0xFE, b'a', 0]), "a");
}

#[test]
fn a_default_the_entry_word_cannot_hold_goes_in_leaked_limits_that_keep_the_unit() {
    use oxicat_slave::od::Limits;
    let mut e = EntryDef::new(1, "w", DataType::Unsigned64, Access::RW);
    e.limits = Box::leak(Box::new(Limits::unit(0x00D2_0000)));
    set_default(&mut e, DefaultValue::bits(1 << 40));
    assert_eq!(e.default(), DefaultValue::bits(1 << 40));
    assert_eq!(e.limits.unit, 0x00D2_0000);
    // A later default that fits the word replaces the one in the limits.
    set_default(&mut e, DefaultValue::bits(7));
    assert_eq!(e.default(), DefaultValue::bits(7));
    assert_eq!(e.limits.unit, 0x00D2_0000);
    let mut s = EntryDef::string(0, "s", 8, Access::RW);
    set_default(&mut s, DefaultValue::Bytes(b"ab"));
    assert_eq!(s.default(), DefaultValue::Bytes(b"ab"));
    // One that fits stays in the entry: no limits leaked for it.
    let mut u = EntryDef::new(1, "u", DataType::Int16, Access::RW);
    set_default(&mut u, DefaultValue::bits(-2i64 as u64));
    assert_eq!(u.default(), DefaultValue::bits(-2i64 as u64));
    assert!(u.limits.default.is_none());
}
