//! Property tests: parse(write(x)) == x for every header type and for whole frames, and
//! arbitrary bytes never make a parser panic.

use oxicat_wire::coe::*;
use oxicat_wire::datagram::{DatagramHeader, DatagramRef, MAX_DATA_LEN};
use oxicat_wire::eoe::*;
use oxicat_wire::foe::*;
use oxicat_wire::frame::for_each_datagram_mut;
use oxicat_wire::mailbox::*;
use oxicat_wire::sii::*;
use oxicat_wire::soe::*;
use oxicat_wire::udp::*;
use oxicat_wire::*;
use proptest::prelude::*;

fn dg_header() -> impl Strategy<Value = DatagramHeader> {
    (
        any::<u8>(),
        any::<u8>(),
        any::<u32>(),
        0u16..=64,
        0u8..8,
        any::<bool>(),
        any::<u16>(),
    )
        .prop_map(
            |(command, index, address, len, reserved, circulating, irq)| DatagramHeader {
                command,
                index,
                address,
                len,
                reserved,
                circulating,
                more_follows: false,
                irq,
            },
        )
}

fn datagrams() -> impl Strategy<Value = Vec<(DatagramHeader, Vec<u8>)>> {
    prop::collection::vec(
        dg_header()
            .prop_flat_map(|h| (Just(h), prop::collection::vec(any::<u8>(), h.len as usize))),
        1..6,
    )
}

fn check_frame(frame: EcatFrame<'_>, dgs: &[(DatagramHeader, Vec<u8>)]) {
    let got: Vec<DatagramRef<'_>> = frame.datagrams().map(|d| d.unwrap()).collect();
    assert_eq!(got.len(), dgs.len());
    for (i, (g, (h, d))) in got.iter().zip(dgs).enumerate() {
        let mut want = *h;
        want.more_follows = i + 1 < dgs.len();
        assert_eq!(g.header, want);
        assert_eq!(g.data, &d[..]);
        assert_eq!(g.wkc, 0);
    }
}

fn mac() -> impl Strategy<Value = [u8; 6]> {
    any::<[u8; 6]>()
}

fn endpoints() -> impl Strategy<Value = UdpEndpoints> {
    (
        mac(),
        mac(),
        prop::option::of(any::<u16>()),
        any::<[u8; 4]>(),
        any::<[u8; 4]>(),
        any::<u16>(),
        any::<u8>(),
        any::<u16>(),
        any::<u8>(),
    )
        .prop_map(
            |(dst_mac, src_mac, vlan_tci, src_ip, dst_ip, src_port, ttl, identification, tos)| {
                UdpEndpoints {
                    dst_mac,
                    src_mac,
                    vlan_tci,
                    src_ip,
                    dst_ip,
                    src_port,
                    dst_port: ETHERCAT_UDP_PORT,
                    ttl,
                    identification,
                    tos,
                }
            },
        )
}

proptest! {
    #[test]
    fn datagram_header_round_trip(h in dg_header(), m in any::<bool>(), len in 0u16..=MAX_DATA_LEN as u16) {
        let mut h = h;
        h.more_follows = m;
        h.len = len;
        let mut b = [0u8; 10];
        h.write(&mut b).unwrap();
        prop_assert_eq!(DatagramHeader::parse(&b).unwrap(), h);
    }

    #[test]
    fn ecat_header_round_trip(len in 0u16..0x800, r in any::<bool>(), t in 0u8..16) {
        let h = EcatHeader { len, reserved: r, frame_type: FrameType::from_u8(t) };
        let w = h.to_word().to_le_bytes();
        prop_assert_eq!(EcatHeader::parse(&w).unwrap(), h);
    }

    #[test]
    fn ethernet_header_round_trip(dst in mac(), src in mac(), vlan in prop::option::of(any::<u16>())) {
        let h = EthernetHeader { dst, src, vlan_tci: vlan, payload_offset: if vlan.is_some() { 18 } else { 14 } };
        let mut b = [0u8; 18];
        let n = h.write(&mut b).unwrap();
        prop_assert_eq!(n, h.payload_offset);
        prop_assert_eq!(EthernetHeader::parse(&b).unwrap(), h);
    }

    #[test]
    fn ethernet_frame_round_trip(dgs in datagrams(), vlan in prop::option::of(any::<u16>())) {
        let eth = EthernetHeader { dst: [0xff; 6], src: [2, 0, 0, 0, 0, 1], vlan_tci: vlan, payload_offset: 0 };
        let mut buf = [0u8; 1600];
        let mut b = FrameBuilder::new(&mut buf, &eth).unwrap();
        for (h, d) in &dgs {
            b.push(*h, d).unwrap();
        }
        let n = b.finish();
        prop_assert!(n >= 60);
        let (e, f) = EcatFrame::parse_ethernet(&buf[..n]).unwrap();
        prop_assert_eq!(e.vlan_tci, vlan);
        check_frame(f, &dgs);
        // The mutable walk visits the same datagrams.
        let off = e.payload_offset;
        let count = for_each_datagram_mut::<WireError>(&mut buf[off..n], |_| Ok(())).unwrap();
        prop_assert_eq!(count, dgs.len());
    }

    #[test]
    fn bare_frame_round_trip(dgs in datagrams()) {
        let mut buf = [0u8; 1600];
        let mut b = FrameBuilder::new_bare(&mut buf).unwrap();
        for (h, d) in &dgs {
            b.push(*h, d).unwrap();
        }
        let n = b.finish();
        check_frame(EcatFrame::parse(&buf[..n]).unwrap(), &dgs);
    }

    #[test]
    fn udp_frame_round_trip(dgs in datagrams(), ep in endpoints()) {
        let mut buf = [0u8; 1600];
        let mut b = FrameBuilder::new_udp(&mut buf, &ep).unwrap();
        for (h, d) in &dgs {
            b.push(*h, d).unwrap();
        }
        let n = b.finish();
        let f = EcatUdpFrame::parse(&buf[..n]).unwrap();
        prop_assert_eq!(f.endpoints(), ep);
        prop_assert_eq!(f.payload_offset, ep.payload_offset());
        prop_assert_eq!(udp_payload_offset(&buf[..n]).unwrap().0, ep.payload_offset());
        check_frame(f.ecat().unwrap(), &dgs);
    }

    #[test]
    fn mailbox_header_round_trip(length in any::<u16>(), address in any::<u16>(), channel in 0u8..64,
                                 priority in 0u8..4, t in 0u8..16, counter in 0u8..8, r in any::<bool>()) {
        let h = MailboxHeader { length, address, channel, priority, mailbox_type: MailboxType::from_u8(t), counter, reserved: r };
        let mut b = [0u8; 6];
        h.write(&mut b).unwrap();
        prop_assert_eq!(MailboxHeader::parse(&b).unwrap(), h);
    }

    #[test]
    fn mailbox_error_round_trip(d in any::<u16>(), address in any::<u16>(), counter in 0u8..8) {
        let e = MailboxErrorReply { detail: MailboxErrorDetail::from_u16(d) };
        let mut b = [0u8; 10];
        let n = e.write_mailbox(&mut b, address, counter).unwrap();
        let m = MailboxRef::parse(&b[..n]).unwrap();
        prop_assert_eq!(m.header.address, address);
        prop_assert_eq!(m.header.counter, counter);
        prop_assert_eq!(MailboxErrorReply::parse(m.payload).unwrap(), e);
    }

    #[test]
    fn coe_header_round_trip(number in 0u16..512, reserved in 0u8..8, s in 0u8..16) {
        let h = CoeHeader { number, reserved, service: CoeService::from_u8(s) };
        let mut b = [0u8; 2];
        h.write(&mut b).unwrap();
        prop_assert_eq!(CoeHeader::parse(&b).unwrap(), h);
    }

    #[test]
    fn sdo_command_bytes_round_trip(b in any::<u8>()) {
        // Decoding then encoding keeps every bit the command defines; re-decoding is stable.
        if let Ok(c) = SdoRequestCommand::from_u8(b) {
            let e = c.to_u8().unwrap();
            prop_assert_eq!(SdoRequestCommand::from_u8(e).unwrap(), c);
        }
        if let Ok(c) = SdoResponseCommand::from_u8(b) {
            let e = c.to_u8().unwrap();
            prop_assert_eq!(SdoResponseCommand::from_u8(e).unwrap(), c);
        }
    }

    #[test]
    fn sdo_expedited_round_trip(index in any::<u16>(), subindex in any::<u8>(), data in prop::collection::vec(any::<u8>(), 1..=4), ca in any::<bool>()) {
        let cmd = SdoRequestCommand::InitiateDownload { size_indicated: true, expedited: true, unused: (4 - data.len()) as u8, complete_access: ca };
        let mut hd = [0u8; 4];
        hd[..data.len()].copy_from_slice(&data);
        let mut b = [0u8; 16];
        let n = write_sdo(&mut b, CoeService::SdoRequest, &SdoHeader { command: cmd.to_u8().unwrap(), index, subindex }, hd, &[]).unwrap();
        let s = SdoRef::parse(&b[..n]).unwrap();
        prop_assert!(s.is_request());
        prop_assert_eq!(SdoRequestCommand::from_u8(s.command).unwrap(), cmd);
        prop_assert_eq!(s.index().unwrap(), (index, subindex));
        prop_assert_eq!(s.expedited_data().unwrap(), &data[..]);
    }

    #[test]
    fn sdo_normal_round_trip(index in any::<u16>(), subindex in any::<u8>(), data in prop::collection::vec(any::<u8>(), 0..100)) {
        let cmd = SdoResponseCommand::InitiateUpload { size_indicated: true, expedited: false, unused: 0, complete_access: false };
        let mut b = [0u8; 128];
        let n = write_sdo(&mut b, CoeService::SdoResponse, &SdoHeader { command: cmd.to_u8().unwrap(), index, subindex }, (data.len() as u32).to_le_bytes(), &data).unwrap();
        let s = SdoRef::parse(&b[..n]).unwrap();
        prop_assert_eq!(SdoResponseCommand::from_u8(s.command).unwrap(), cmd);
        let (size, d) = s.normal_data().unwrap();
        prop_assert_eq!(size as usize, data.len());
        prop_assert_eq!(d, &data[..]);
    }

    #[test]
    fn sdo_segment_round_trip(toggle in any::<bool>(), last in any::<bool>(), data in prop::collection::vec(any::<u8>(), 0..40)) {
        let unused = 7usize.saturating_sub(data.len()) as u8;
        let cmd = SdoRequestCommand::DownloadSegment { toggle, last, unused };
        let mut b = [0u8; 64];
        let n = write_sdo_segment(&mut b, CoeService::SdoRequest, cmd.to_u8().unwrap(), &data).unwrap();
        let s = SdoRef::parse(&b[..n]).unwrap();
        prop_assert_eq!(SdoRequestCommand::from_u8(s.command).unwrap(), cmd);
        prop_assert_eq!(s.segment_data().unwrap(), &data[..]);
    }

    #[test]
    fn sdo_abort_round_trip(code in any::<u32>(), index in any::<u16>(), subindex in any::<u8>()) {
        let mut b = [0u8; 10];
        let c = SdoAbortCode::from_u32(code);
        prop_assert_eq!(c.code(), code);
        let n = write_sdo_abort(&mut b, index, subindex, c).unwrap();
        let s = SdoRef::parse(&b[..n]).unwrap();
        // ETG.1000.6: an abort is an SDO request (CoE service 2) from either side.
        prop_assert_eq!(s.coe.service, CoeService::SdoRequest);
        prop_assert!(s.is_request());
        prop_assert_eq!(SdoRequestCommand::from_u8(s.command).unwrap(), SdoRequestCommand::Abort);
        prop_assert_eq!(s.index().unwrap(), (index, subindex));
        prop_assert_eq!(s.abort_code().unwrap(), c);
    }

    #[test]
    fn sdo_info_header_round_trip(op in 0u8..128, inc in any::<bool>(), r in any::<u8>(), left in any::<u16>()) {
        let h = SdoInfoHeader { opcode: SdoInfoOpcode::from_u8(op), incomplete: inc, reserved: r, fragments_left: left };
        let mut b = [0u8; 4];
        h.write(&mut b).unwrap();
        prop_assert_eq!(SdoInfoHeader::parse(&b).unwrap(), h);
    }

    #[test]
    fn sdo_info_service_round_trip(op in 1u8..=7, a in any::<u16>(), bb in any::<u16>(), c in any::<u8>(), d in any::<u8>(),
                                   e in any::<u16>(), f in any::<u32>(), tail in prop::collection::vec(any::<u8>(), 0..20)) {
        let mut even = tail.clone();
        even.truncate(tail.len() & !1);
        let s = match op {
            1 => SdoInfoService::GetOdListRequest { list_type: a },
            2 => SdoInfoService::GetOdListResponse { words: &even },
            3 => SdoInfoService::GetObjectDescriptionRequest { index: a },
            4 => SdoInfoService::GetObjectDescriptionResponse { index: a, data_type: bb, max_subindex: c, object_code: d, name: &tail },
            5 => SdoInfoService::GetEntryDescriptionRequest { index: a, subindex: c, value_info: d },
            6 => SdoInfoService::GetEntryDescriptionResponse { index: a, subindex: c, value_info: d, data_type: bb, bit_length: e, object_access: a ^ e, data: &tail },
            _ => SdoInfoService::Error { code: SdoAbortCode::from_u32(f) },
        };
        let mut buf = [0u8; 64];
        let n = s.write(&mut buf).unwrap();
        prop_assert_eq!(SdoInfoService::parse(s.opcode(), &buf[..n]).unwrap(), s);
    }

    #[test]
    fn emergency_round_trip(code in any::<u16>(), reg in any::<u8>(), data in any::<[u8; 5]>()) {
        let e = Emergency { error_code: code, error_register: reg, data };
        let mut b = [0u8; 10];
        let n = e.write_coe(&mut b).unwrap();
        prop_assert_eq!(Emergency::parse_coe(&b[..n]).unwrap(), e);
    }

    #[test]
    fn foe_round_trip(op in 1u8..=6, v in any::<u32>(), data in prop::collection::vec(any::<u8>(), 0..32)) {
        let h = match op {
            1 => FoeHeader::Read { password: v },
            2 => FoeHeader::Write { password: v },
            3 => FoeHeader::Data { packet: v },
            4 => FoeHeader::Ack { packet: v },
            5 => FoeHeader::Error { code: FoeErrorCode::from_u32(v) },
            _ => FoeHeader::Busy { done: v as u16, entire: (v >> 16) as u16 },
        };
        let mut b = [0u8; 64];
        let n = FoeRef::write(&h, &data, &mut b).unwrap();
        let f = FoeRef::parse(&b[..n]).unwrap();
        prop_assert_eq!(f.header, h);
        prop_assert_eq!(f.data, &data[..]);
    }

    #[test]
    fn eoe_round_trip(t in 0u8..16, port in 0u8..16, l in any::<bool>(), ta in any::<bool>(), tr in any::<bool>(),
                      r in 0u8..32, frag in 0u8..64, off in 0u8..64, num in 0u8..16) {
        let h = EoeHeader { frame_type: EoeFrameType::from_u8(t), port, last_fragment: l, time_appended: ta, time_request: tr,
                            reserved: r, fragment: frag, offset: off, frame_number: num };
        let mut b = [0u8; 4];
        h.write(&mut b).unwrap();
        prop_assert_eq!(EoeHeader::parse(&b).unwrap(), h);
    }

    #[test]
    fn soe_round_trip(op in 0u8..8, inc in any::<bool>(), err in any::<bool>(), drive in 0u8..8, el in any::<u8>(), idn in any::<u16>()) {
        let h = SoeHeader { opcode: SoeOpcode::from_u8(op), incomplete: inc, error: err, drive_no: drive, elements: el, idn };
        let mut b = [0u8; 4];
        h.write(&mut b).unwrap();
        prop_assert_eq!(SoeHeader::parse(&b).unwrap(), h);
    }

    #[test]
    fn sii_config_round_trip(w in any::<[u16; 7]>(), hi in any::<u8>()) {
        let mut c = SiiConfig { pdi_control: w[0], pdi_config: w[1], sync_impulse_len: w[2], pdi_config2: w[3],
                                station_alias: w[4], reserved: [w[5], w[6]], checksum: (hi as u16) << 8 };
        let mut b = [0u8; 16];
        c.write(&mut b).unwrap();
        let p = SiiConfig::parse(&b).unwrap();
        prop_assert!(p.crc_ok());
        c.checksum = p.checksum;
        prop_assert_eq!(p, c);
        prop_assert_eq!(p.checksum >> 8, hi as u16);
    }

    #[test]
    fn sii_general_round_trip(b in any::<[u8; 32]>()) {
        let g = SiiGeneral::parse(&b).unwrap();
        let mut o = [0u8; 32];
        g.write(&mut o).unwrap();
        prop_assert_eq!(o, b);
    }

    #[test]
    fn sii_entries_round_trip(b in any::<[u8; 8]>(), pdo in any::<[u8; 8]>()) {
        let sm = SiiSyncManager::decode(&b);
        let mut o = [0u8; 8];
        sm.write(&mut o).unwrap();
        prop_assert_eq!(o, b);
        let e = SiiPdoEntry::decode(&b);
        e.write(&mut o).unwrap();
        prop_assert_eq!(o, b);
        let h = SiiPdoHeader::parse(&pdo).unwrap();
        h.write(&mut o).unwrap();
        prop_assert_eq!(o, pdo);
    }

    #[test]
    fn sii_image_round_trip(id in any::<[u32; 4]>(), strings in prop::collection::vec(prop::collection::vec(any::<u8>(), 0..20), 0..6),
                           mbx in any::<[u16; 9]>()) {
        let mut img = [0u8; 512];
        SiiConfig::default().write(&mut img).unwrap();
        let ident = SiiIdentity { vendor_id: id[0], product_code: id[1], revision: id[2], serial: id[3] };
        ident.write(&mut img).unwrap();
        let area = |i: usize| MailboxArea { offset: mbx[i], size: mbx[i + 1] };
        let m = SiiMailboxConfig { bootstrap_rx: area(0), bootstrap_tx: area(2), standard_rx: area(4), standard_tx: area(6), protocols: mbx[8] };
        m.write(&mut img).unwrap();
        let refs: Vec<&[u8]> = strings.iter().map(|s| &s[..]).collect();
        let mut sbuf = [0u8; 200];
        let n = write_strings(&mut sbuf, &refs).unwrap();
        let o = write_category(&mut img, FIXED_AREA_LEN, CategoryType::Strings, &sbuf[..n]).unwrap();
        img[o..o + 2].copy_from_slice(&0xFFFFu16.to_le_bytes());
        let im = SiiImage::new(&img).unwrap();
        prop_assert!(im.crc_ok());
        prop_assert_eq!(im.identity(), ident);
        prop_assert_eq!(im.mailbox(), m);
        let st = im.strings().unwrap().unwrap();
        let got: Vec<&[u8]> = st.iter().map(|r| r.unwrap()).collect();
        prop_assert_eq!(got, refs);
        prop_assert_eq!(im.categories().count(), 1);
    }

    // ---- arbitrary bytes never panic ----

    #[test]
    fn any_bytes_frame_parsers(b in prop::collection::vec(any::<u8>(), 0..300)) {
        let _ = EthernetHeader::parse(&b);
        let _ = DatagramHeader::parse(&b);
        let _ = DatagramRef::parse(&b);
        let _ = EcatHeader::parse(&b);
        if let Ok(f) = EcatFrame::parse(&b) { for d in f.datagrams() { let _ = d; } }
        if let Ok((_, f)) = EcatFrame::parse_ethernet(&b) { for d in f.datagrams() { let _ = d; } }
        if let Ok(u) = EcatUdpFrame::parse(&b) { if let Ok(f) = u.ecat() { for d in f.datagrams() { let _ = d; } } }
        let _ = Ipv4Header::parse(&b);
        let _ = UdpHeader::parse(&b);
        let _ = udp_payload_offset(&b);
        let mut m = b.clone();
        let _ = for_each_datagram_mut::<WireError>(&mut m, |d| { let w = d.wkc(); d.set_wkc(w.wrapping_add(1)); d.commit_header(); Ok(()) });
    }

    #[test]
    fn any_bytes_mailbox_parsers(b in prop::collection::vec(any::<u8>(), 0..100)) {
        let _ = MailboxHeader::parse(&b);
        let _ = MailboxRef::parse(&b);
        let _ = MailboxErrorReply::parse(&b);
        let _ = CoeHeader::parse(&b);
        let _ = SdoHeader::parse(&b);
        if let Ok(s) = SdoRef::parse(&b) {
            let _ = (s.index(), s.header_data(), s.expedited_data(), s.normal_data(), s.segment_data(), s.abort_code());
        }
        if let Ok(i) = SdoInfoRef::parse(&b) { let _ = i.service(); }
        for op in 0..128u8 { let _ = SdoInfoService::parse(SdoInfoOpcode::from_u8(op), &b); }
        let _ = SdoInfoHeader::parse(&b);
        let _ = Emergency::parse(&b);
        let _ = Emergency::parse_coe(&b);
        let _ = FoeRef::parse(&b);
        let _ = EoeRef::parse(&b);
        let _ = SoeRef::parse(&b);
        if let Some(&c) = b.first() { let _ = (SdoRequestCommand::from_u8(c), SdoResponseCommand::from_u8(c)); }
    }

    #[test]
    fn any_bytes_sii(b in prop::collection::vec(any::<u8>(), 0..400)) {
        let _ = SiiConfig::parse(&b);
        let _ = SiiGeneral::parse(&b);
        let _ = SiiStrings::new(&b).map(|s| { for x in s.iter() { let _ = x; } for i in 0..=255u8 { let _ = s.get_str(i); } });
        if let Ok(im) = SiiImage::new(&b) {
            let _ = (im.config(), im.identity(), im.mailbox(), im.crc_ok(), im.eeprom_size_bytes(), im.version());
            let _ = (im.strings(), im.general());
            for c in im.categories().flatten() {
                let _ = (c.strings(), c.general());
                for x in c.sync_managers() { let _ = x; }
                for x in c.fmmus() { let _ = x; }
                for x in c.fmmus_extended() { let _ = x; }
                for x in c.dc() { let _ = x; }
                for p in c.pdos().flatten() { for e in p.entries() { let _ = e; } let _ = p.bit_len(); }
            }
        }
    }

    #[test]
    fn any_bytes_sii_categories(cats in prop::collection::vec((any::<u16>(), prop::collection::vec(any::<u8>(), 0..40)), 0..6), tail in prop::collection::vec(any::<u8>(), 0..6)) {
        // A well-formed fixed area followed by random categories and a random tail.
        let mut img = vec![0u8; FIXED_AREA_LEN];
        for (t, d) in &cats {
            img.extend_from_slice(&t.to_le_bytes());
            img.extend_from_slice(&((d.len() / 2) as u16).to_le_bytes());
            img.extend_from_slice(&d[..d.len() & !1]);
        }
        img.extend_from_slice(&tail);
        let im = SiiImage::new(&img).unwrap();
        for c in im.categories().flatten() {
            for p in c.pdos().flatten() { for e in p.entries() { let _ = e; } }
            if let Ok(s) = c.strings() { for x in s.iter() { let _ = x; } }
            let _ = c.general();
        }
    }
}

#[test]
fn push_rejects_oversized_length() {
    let mut buf = [0u8; 4096];
    let mut b = FrameBuilder::new_bare(&mut buf).unwrap();
    let h = DatagramHeader::logical(Command::Lrw, 0, 0, 0x800);
    assert!(b.push(h, &[]).is_err());
}
