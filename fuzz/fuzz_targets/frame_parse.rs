//! Arbitrary bytes → Ethernet / EtherCAT-over-UDP / bare EtherCAT parse, every datagram,
//! and every mailbox, CoE, FoE, EoE, SoE and SII structure that could sit in the data.
//! Round trip: the datagrams of a frame that parses, built again with `FrameBuilder`,
//! parse to the same headers, data and working counters.
#![no_main]

use libfuzzer_sys::fuzz_target;
use oxicat_wire::coe::{Emergency, SdoInfoOpcode, SdoInfoRef, SdoInfoService, SdoRef};
use oxicat_wire::eoe::EoeRef;
use oxicat_wire::foe::FoeRef;
use oxicat_wire::frame::{for_each_datagram_mut, FrameBuilder, FrameType};
use oxicat_wire::mailbox::{MailboxErrorReply, MailboxRef, MailboxType};
use oxicat_wire::sii::SiiImage;
use oxicat_wire::soe::SoeRef;
use oxicat_wire::{EcatFrame, EcatUdpFrame, WireError};

fn mailbox(data: &[u8]) {
    let Ok(m) = MailboxRef::parse(data) else {
        return;
    };
    let p = m.payload;
    match m.header.mailbox_type {
        MailboxType::Error => {
            let _ = MailboxErrorReply::parse(p);
        }
        MailboxType::Coe => {
            if let Ok(s) = SdoRef::parse(p) {
                let _ = (
                    s.index(),
                    s.header_data(),
                    s.expedited_data(),
                    s.normal_data(),
                );
                let _ = (s.segment_data(), s.abort_code());
            }
            if let Ok(i) = SdoInfoRef::parse(p) {
                let _ = i.service();
            }
            let _ = Emergency::parse_coe(p);
        }
        MailboxType::Foe => {
            let _ = FoeRef::parse(p);
        }
        MailboxType::Eoe => {
            let _ = EoeRef::parse(p);
        }
        MailboxType::Soe => {
            let _ = SoeRef::parse(p);
        }
        _ => {}
    }
    // Whatever the type says, every decoder must cope with any payload.
    let _ = (FoeRef::parse(p), EoeRef::parse(p), SoeRef::parse(p));
    if let Some(&op) = p.first() {
        let _ = SdoInfoService::parse(SdoInfoOpcode::from_u8(op), p);
    }
}

fn sii(data: &[u8]) {
    let Ok(img) = SiiImage::new(data) else { return };
    let _ = (
        img.config().crc_ok(),
        img.identity(),
        img.mailbox(),
        img.eeprom_size_bytes(),
    );
    if let Ok(Some(s)) = img.strings() {
        for i in 0..=s.count() {
            let _ = s.get_str(i);
        }
    }
    let _ = img.general();
    for c in img.categories().flatten() {
        let _ = (c.strings(), c.general());
        c.sync_managers().for_each(drop);
        c.fmmus().for_each(drop);
        c.fmmus_extended().for_each(drop);
        c.dc().for_each(drop);
        for p in c.pdos().flatten() {
            p.entries().for_each(drop);
        }
    }
}

fn ecat(f: EcatFrame<'_>) {
    for d in f.datagrams() {
        let Ok(d) = d else { break };
        mailbox(d.data);
        sii(d.data);
    }
}

/// Build → parse → same, for the datagrams `f` yields.
fn round_trip(f: EcatFrame<'_>) {
    if f.header.frame_type != FrameType::Datagrams {
        return;
    }
    let Ok(parsed) = f.datagrams().collect::<Result<Vec<_>, _>>() else {
        return;
    };
    let mut buf = vec![0u8; 4096];
    let Ok(mut fb) = FrameBuilder::new_bare(&mut buf) else {
        return;
    };
    for d in &parsed {
        if fb.push(d.header, d.data).is_err() {
            return;
        }
    }
    let n = fb.finish();
    let mut k = 0;
    for_each_datagram_mut::<WireError>(&mut buf[..n], |d| {
        d.set_wkc(parsed[k].wkc);
        k += 1;
        Ok(())
    })
    .expect("a frame FrameBuilder made walks");
    let again = EcatFrame::parse(&buf[..n]).expect("a frame FrameBuilder made parses");
    let again: Vec<_> = again
        .datagrams()
        .collect::<Result<_, _>>()
        .expect("its datagrams parse");
    assert_eq!(again.len(), parsed.len(), "datagram count");
    for (a, b) in parsed.iter().zip(&again) {
        assert_eq!(a.header, b.header);
        assert_eq!(a.data, b.data);
        assert_eq!(a.wkc, b.wkc);
    }
}

fuzz_target!(|data: &[u8]| {
    if let Ok(f) = EcatFrame::parse(data) {
        round_trip(f);
    }
    if let Ok((_, f)) = EcatFrame::parse_ethernet(data) {
        ecat(f);
    }
    if let Ok(u) = EcatUdpFrame::parse(data) {
        if let Ok(f) = u.ecat() {
            ecat(f);
        }
    }
    if let Ok(f) = EcatFrame::parse(data) {
        ecat(f);
    }
    let mut copy = data.to_vec();
    let _ = for_each_datagram_mut::<WireError>(&mut copy, |d| {
        d.header.irq |= 1;
        d.commit_header();
        let w = d.wkc().wrapping_add(1);
        d.set_wkc(w);
        Ok(())
    });
    mailbox(data);
    sii(data);
});
