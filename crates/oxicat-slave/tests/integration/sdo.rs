use oxicat_testkit::device::*;
use oxicat_testkit::{Bench, Port};
use oxicat_wire::coe::{
    write_sdo, write_sdo_abort, write_sdo_segment, CoeService, SdoAbortCode, SdoHeader, SdoInfoRef,
    SdoInfoService,
};
use oxicat_wire::mailbox::{MailboxErrorReply, MailboxHeader, MailboxType};

fn abort_of(r: Result<impl Sized, u32>) -> u32 {
    match r {
        Ok(_) => 0,
        Err(c) => c,
    }
}

fn every_data_type_round_trips<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    let vals: &[(u8, Vec<u8>)] = &[
        (1, vec![1]),
        (2, (-3i8).to_le_bytes().to_vec()),
        (3, (-300i16).to_le_bytes().to_vec()),
        (4, (-70000i32).to_le_bytes().to_vec()),
        (5, (-5_000_000_000i64).to_le_bytes().to_vec()),
        (6, 200u8.to_le_bytes().to_vec()),
        (7, 60000u16.to_le_bytes().to_vec()),
        (8, 4_000_000_000u32.to_le_bytes().to_vec()),
        (9, u64::MAX.to_le_bytes().to_vec()),
        (10, 3.25f32.to_le_bytes().to_vec()),
        (11, (-1.5e300f64).to_le_bytes().to_vec()),
    ];
    for (sub, v) in vals {
        b.download(0x2005, *sub, false, v).unwrap();
        assert_eq!(&b.upload(0x2005, *sub, false).unwrap(), v, "sub {sub}");
    }
    assert_eq!(b.s.od().get::<i64>(0x2005, 5), Ok(-5_000_000_000));
    assert_eq!(b.s.od().get::<f64>(0x2005, 11), Ok(-1.5e300));
    assert_eq!(b.s.od().get::<bool>(0x2005, 1), Ok(true));
    // Strings: visible string uploads its current length.
    assert_eq!(b.upload(0x2006, 0, false).unwrap(), b"hello");
    b.download(0x2006, 0, false, b"a longer label").unwrap();
    assert_eq!(b.upload(0x2006, 0, false).unwrap(), b"a longer label");
    // Standard objects derived from the definition.
    assert_eq!(b.upload(0x1008, 0, false).unwrap(), b"oxicat test device");
    assert_eq!(b.upload(0x1018, 1, false).unwrap(), 0x0A5Cu32.to_le_bytes());
    assert_eq!(b.upload(0x1018, 4, false).unwrap(), 42u32.to_le_bytes());
    assert_eq!(b.upload(0x1000, 0, false).unwrap(), 0x1389u32.to_le_bytes());
    assert_eq!(b.upload(0x1C00, 3, false).unwrap(), [3]);
    assert_eq!(
        b.upload(0x1C32, 5, false).unwrap(),
        100_000u32.to_le_bytes()
    );
    assert_eq!(b.upload(0x1A00, 0, false).unwrap(), [5]);
    assert_eq!(
        b.upload(0x1A00, 4, false).unwrap(),
        0x6000_0310u32.to_le_bytes()
    );
    assert_eq!(b.upload(0x10F1, 2, false).unwrap(), 4u16.to_le_bytes());
}

fn segmented_1k_both_directions<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    let data: Vec<u8> = (0..1100u32).map(|i| (i * 7 + 3) as u8).collect();
    b.download(0x2001, 0, false, &data).unwrap();
    assert_eq!(b.s.od().bytes(0x2001, 0).unwrap(), &data[..]);
    assert_eq!(b.upload(0x2001, 0, false).unwrap(), data);
    assert!(b.app.written.contains(&(0x2001, 0)));
}

fn complete_access<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    // 0x1018: sub0 padded to 16 bits, then four u32.
    let id = b.upload(0x1018, 0, true).unwrap();
    assert_eq!(id.len(), 2 + 16);
    assert_eq!(&id[..2], &[4, 0]);
    assert_eq!(&id[2..6], &0x0A5Cu32.to_le_bytes());
    // From subindex 1.
    assert_eq!(b.upload(0x1018, 1, true).unwrap().len(), 16);
    // 0x6000 packs two BOOLs into bits; INT16 realigned to a byte.
    b.s.od_mut().set(0x6000, 1, true).unwrap();
    b.s.od_mut().set(0x6000, 3, -2i16).unwrap();
    let v = b.upload(0x6000, 0, true).unwrap();
    assert_eq!(v, vec![4, 0, 0x01, 0xFE, 0xFF, 0, 0, 0, 0]);
    // CA download of the RxPDO mapping with the count: new mapping in one go.
    let mut m = vec![2u8, 0];
    m.extend_from_slice(&0x7000_0210u32.to_le_bytes());
    m.extend_from_slice(&0x7000_0308u32.to_le_bytes());
    m.extend(std::iter::repeat_n(0u8, 4 * 29));
    b.download(0x1600, 0, true, &m).unwrap();
    assert_eq!(b.upload(0x1600, 0, false).unwrap(), [2]);
    assert_eq!(
        b.upload(0x1600, 2, false).unwrap(),
        0x7000_0308u32.to_le_bytes()
    );
    // CA on a string object is not supported, and must start at subindex 0 or 1.
    assert_eq!(abort_of(b.upload(0x2006, 0, true)), 0x0601_0004);
    assert_eq!(abort_of(b.upload(0x1018, 2, true)), 0x0601_0000);
}

fn dynamic_pdo_assignment<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    // Subindex-0 protocol: writing an entry while sub0 != 0 is refused.
    assert_eq!(
        abort_of(b.download(0x1C13, 2, false, &0x1A01u16.to_le_bytes())),
        0x0601_0003
    );
    b.download(0x1C13, 0, false, &[0]).unwrap();
    b.download(0x1C13, 1, false, &0x1A01u16.to_le_bytes())
        .unwrap();
    b.download(0x1C13, 2, false, &0x1A00u16.to_le_bytes())
        .unwrap();
    b.download(0x1C13, 0, false, &[2]).unwrap();
    // Remap 0x1600 to Setpoint only.
    b.download(0x1600, 0, false, &[0]).unwrap();
    b.download(0x1600, 1, false, &0x7000_0210u32.to_le_bytes())
        .unwrap();
    b.download(0x1600, 0, false, &[1]).unwrap();
    assert_eq!((b.expected_out(), b.expected_in()), (2, 9));
    b.config_pd();
    assert_eq!(b.request(4), (4, 0));
    assert_eq!((b.s.output_bytes(), b.s.input_bytes()), (2, 9));
    // Assignment is PREOP-only.
    assert_eq!(abort_of(b.download(0x1C13, 0, false, &[1])), 0x0800_0022);
    assert_eq!(b.request(8), (8, 0));
    b.wr(SM2, &50i16.to_le_bytes());
    b.poll();
    let (d, _) = b.rd(SM3, 9);
    // 0x1A01 first: Analog = 100, then 0x1A00.
    assert_eq!(i16::from_le_bytes([d[0], d[1]]), 100);
    assert_eq!(i16::from_le_bytes([d[3], d[4]]), 100);
}

/// A PREOP -> SAFEOP refused after the mappings were checked (SM2 sized for the old
/// mapping) leaves the active mappings as they were: the stack compiles a new mapping into
/// its own only when the transition is taken.
fn refused_safeop_keeps_the_active_mapping<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_safeop();
    let (out, inp) = (b.s.output_bytes(), b.s.input_bytes());
    assert_eq!(out, b.expected_out() as usize);
    assert_eq!(b.request(2), (2, 0));
    // Remap 0x1600 to Setpoint only (2 bytes), SMs left as they were.
    b.download(0x1600, 0, false, &[0]).unwrap();
    b.download(0x1600, 1, false, &0x7000_0210u32.to_le_bytes())
        .unwrap();
    b.download(0x1600, 0, false, &[1]).unwrap();
    assert_ne!(b.expected_out() as usize, out);
    // SM2 still has the old length: refused (invalid output configuration).
    assert_eq!(b.request(4), (0x12, 0x001D));
    assert_eq!((b.s.output_bytes(), b.s.input_bytes()), (out, inp));
    // With SM2 sized for the new mapping it is taken, and the new mapping is active.
    b.config_pd();
    assert_eq!(b.request(0x14), (4, 0));
    assert_eq!(b.s.output_bytes(), 2);
}

fn abort_codes_table<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    type Case = (&'static str, u16, u8, bool, Option<Vec<u8>>, u32);
    let cases: Vec<Case> = vec![
        (
            "object does not exist (upload)",
            0x5555,
            0,
            false,
            None,
            0x0602_0000,
        ),
        (
            "object does not exist (download)",
            0x5555,
            0,
            false,
            Some(vec![1]),
            0x0602_0000,
        ),
        (
            "subindex does not exist",
            0x1018,
            9,
            false,
            None,
            0x0609_0011,
        ),
        (
            "read a write-only object",
            0x2003,
            0,
            false,
            None,
            0x0601_0001,
        ),
        (
            "write a read-only object",
            0x2002,
            0,
            false,
            Some(vec![1]),
            0x0601_0002,
        ),
        (
            "write identity",
            0x1018,
            1,
            false,
            Some(vec![1, 2, 3, 4]),
            0x0601_0002,
        ),
        (
            "length too high",
            0x2000,
            0,
            false,
            Some(vec![1, 0, 0, 0, 0, 0]),
            0x0607_0012,
        ),
        (
            "length too low",
            0x2000,
            0,
            false,
            Some(vec![1, 0]),
            0x0607_0013,
        ),
        (
            "string too long",
            0x2006,
            0,
            false,
            Some(vec![b'x'; 17]),
            0x0607_0012,
        ),
        (
            "value too high",
            0x2000,
            0,
            false,
            Some(1001u32.to_le_bytes().to_vec()),
            0x0609_0031,
        ),
        (
            "bool out of range",
            0x2005,
            1,
            false,
            Some(vec![2]),
            0x0609_0030,
        ),
        (
            "cannot be mapped",
            0x1600,
            1,
            false,
            Some(0x2000_0020u32.to_le_bytes().to_vec()),
            0x0601_0003,
        ),
        (
            "assign unknown PDO",
            0x1C12,
            0,
            false,
            Some(vec![9]),
            0x0609_0030,
        ),
        (
            "sync mode unsupported",
            0x1C32,
            1,
            false,
            Some(9u16.to_le_bytes().to_vec()),
            0x0609_0030,
        ),
        ("CA on a VAR", 0x2000, 0, true, None, 0x0601_0004),
    ];
    for (what, index, sub, ca, data, code) in cases {
        let got = match data {
            None => abort_of(b.upload(index, sub, ca)),
            Some(d) => abort_of(b.download(index, sub, ca, &d)),
        };
        assert_eq!(got, code, "{what}: got {got:#010x}");
    }
    // Mapping rules with sub0 = 0 (subindex-0 protocol followed).
    b.download(0x1600, 0, false, &[0]).unwrap();
    let table: &[(u32, u32)] = &[
        (0x2000_0020, 0x0604_0041), // not mappable
        (0x6000_0310, 0x0604_0041), // TxPDO entry in an RxPDO
        (0x7000_0208, 0x0604_0043), // wrong bit length
        (0x7777_0008, 0x0602_0000), // no such object
        (0x7000_0908, 0x0609_0011), // no such subindex
    ];
    for (v, code) in table {
        assert_eq!(
            abort_of(b.download(0x1600, 1, false, &v.to_le_bytes())),
            *code,
            "{v:#x}"
        );
    }
    assert_eq!(abort_of(b.download(0x1600, 0, false, &[32])), 0x0609_0030);
    // Fixed PDO mapping is read-only.
    assert_eq!(abort_of(b.download(0x1A00, 0, false, &[0])), 0x0601_0002);
    // Assigning a PDO of the wrong direction.
    b.download(0x1C12, 0, false, &[0]).unwrap();
    assert_eq!(
        abort_of(b.download(0x1C12, 1, false, &0x1A00u16.to_le_bytes())),
        0x0604_0043
    );
    // RW in PREOP only: wrong state in SAFEOP; mapped to RxPDO in SAFEOP/OP.
    b.download(0x1C12, 1, false, &0x1600u16.to_le_bytes())
        .unwrap();
    b.download(0x1600, 1, false, &0x7000_0210u32.to_le_bytes())
        .unwrap();
    b.download(0x1600, 0, false, &[1]).unwrap();
    b.download(0x1C12, 0, false, &[1]).unwrap();
    b.config_pd();
    assert_eq!(b.request(4), (4, 0));
    assert_eq!(
        abort_of(b.download(0x2004, 0, false, &1f32.to_le_bytes())),
        0x0800_0022
    );
    assert_eq!(abort_of(b.download(0x7000, 2, false, &[1, 0])), 0x0601_0006);
    assert_eq!(abort_of(b.download(0x7000, 3, false, &[1])), 0);
}

fn raw_sdo<P: Port>(b: &mut Bench<P>, cmd: u8, index: u16, sub: u8, d: [u8; 4]) -> Vec<u8> {
    let mut p = [0u8; 10];
    let h = SdoHeader {
        command: cmd,
        index,
        subindex: sub,
    };
    write_sdo(&mut p, CoeService::SdoRequest, &h, d, &[]).unwrap();
    b.coe(&p)
}

fn abort_in(r: &[u8]) -> u32 {
    assert_eq!(r[2], 0x80, "not an abort: {r:02x?}");
    u32::from_le_bytes([r[6], r[7], r[8], r[9]])
}

fn protocol_aborts<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    // Unknown command specifier (block download 6).
    assert_eq!(
        abort_in(&raw_sdo(&mut b, 0xC0, 0x2000, 0, [0; 4])),
        0x0504_0001
    );
    // Upload segment without an upload in progress.
    assert_eq!(abort_in(&raw_sdo(&mut b, 0x60, 0, 0, [0; 4])), 0x0504_0001);
    // Toggle bit not alternated: start a segmented upload of 0x2001, send toggle 1 first.
    let r = raw_sdo(&mut b, 0x40, 0x2001, 0, [0; 4]);
    assert_eq!(r[2], 0x41);
    assert_eq!(abort_in(&raw_sdo(&mut b, 0x70, 0, 0, [0; 4])), 0x0503_0000);
    // Segmented download of the 16-byte label; first segment with toggle 1.
    let mut p = vec![0u8; 16];
    let h = SdoHeader {
        command: 0x21,
        index: 0x2006,
        subindex: 0,
    };
    let n = write_sdo(&mut p, CoeService::SdoRequest, &h, 16u32.to_le_bytes(), &[]).unwrap();
    let r = b.coe(&p[..n]);
    assert_eq!(r[2], 0x60);
    let r = raw_sdo(&mut b, 0x10, 0, 0, [0; 4]);
    assert_eq!(abort_in(&r), 0x0503_0000);
}

/// The upload replies byte for byte, as `write_sdo` and `write_sdo_segment` make them: an
/// expedited upload, a normal upload in one initiate response (a string, a complete access) and a segmented one
/// (initiate response with the size, then segments with the toggle bit, the unused count of
/// a short one padded to 7 bytes, and the last bit).
fn upload_frames_byte_for_byte<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    let initiate = |cmd: u8, index: u16, sub: u8, size: usize, data: &[u8]| {
        let mut f = vec![0u8; 10 + data.len()];
        let h = SdoHeader {
            command: cmd,
            index,
            subindex: sub,
        };
        let size = (size as u32).to_le_bytes();
        let n = write_sdo(&mut f, CoeService::SdoResponse, &h, size, data).unwrap();
        f.truncate(n);
        f
    };
    // Expedited: 4 and 2 bytes in the header's data field, the unused count in the command.
    for (index, sub, cmd, d) in [
        (0x1018, 1, 0x43, 0x0A5Cu32.to_le_bytes()),
        (0x10F1, 2, 0x4B, [4, 0, 0, 0]),
    ] {
        let mut f = vec![0u8; 10];
        let h = SdoHeader {
            command: cmd,
            index,
            subindex: sub,
        };
        write_sdo(&mut f, CoeService::SdoResponse, &h, d, &[]).unwrap();
        assert_eq!(raw_sdo(&mut b, 0x40, index, sub, [0; 4]), f);
    }
    let name = b"oxicat test device";
    let r = raw_sdo(&mut b, 0x40, 0x1008, 0, [0; 4]);
    assert_eq!(r, initiate(0x41, 0x1008, 0, name.len(), name));
    b.s.od_mut().set(0x6000, 1, true).unwrap();
    b.s.od_mut().set(0x6000, 3, -2i16).unwrap();
    let ca = [4, 0, 0x01, 0xFE, 0xFF, 0, 0, 0, 0];
    let r = raw_sdo(&mut b, 0x50, 0x6000, 0, [0; 4]);
    assert_eq!(r, initiate(0x51, 0x6000, 0, ca.len(), &ca));
    // Segmented: 1100 bytes of 0x2001.
    let data: Vec<u8> = (0..1100u32).map(|i| (i * 5 + 1) as u8).collect();
    b.download(0x2001, 0, false, &data).unwrap();
    let r = raw_sdo(&mut b, 0x40, 0x2001, 0, [0; 4]);
    let first = r.len() - 10;
    assert!(first < data.len());
    assert_eq!(r, initiate(0x41, 0x2001, 0, data.len(), &data[..first]));
    let (mut sent, mut toggle, mut segments) = (first, false, 0);
    while sent < data.len() {
        let r = raw_sdo(&mut b, 0x60 | if toggle { 0x10 } else { 0 }, 0, 0, [0; 4]);
        let n = (data.len() - sent).min(first + 7);
        let last = sent + n == data.len();
        let unused = if n < 7 { (7 - n) as u8 } else { 0 };
        let cmd = (if toggle { 0x10 } else { 0 }) | (unused << 1) | u8::from(last);
        let mut f = vec![0u8; 10 + n];
        let len =
            write_sdo_segment(&mut f, CoeService::SdoResponse, cmd, &data[sent..sent + n]).unwrap();
        assert_eq!(r, f[..len], "segment {segments}");
        sent += n;
        toggle = !toggle;
        segments += 1;
    }
    assert!(segments > 1);
    // The transfer is over: another segment request is refused.
    assert_eq!(abort_in(&raw_sdo(&mut b, 0x60, 0, 0, [0; 4])), 0x0504_0001);
}

/// The abort and download replies byte for byte, as `write_sdo_abort`, `write_sdo` and
/// `write_sdo_segment` make them: an abort, the expedited and the segmented download's
/// initiate response, the segment responses with their toggle bit.
fn download_and_abort_frames_byte_for_byte<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    let mut f = [0u8; 10];
    write_sdo_abort(&mut f, 0x2000, 3, SdoAbortCode::InvalidCommand).unwrap();
    assert_eq!(raw_sdo(&mut b, 0xC0, 0x2000, 3, [0; 4]), f);
    let initiated = |index: u16, sub: u8| {
        let mut f = [0u8; 10];
        let h = SdoHeader {
            command: 0x60,
            index,
            subindex: sub,
        };
        write_sdo(&mut f, CoeService::SdoResponse, &h, [0; 4], &[]).unwrap();
        f
    };
    assert_eq!(
        raw_sdo(&mut b, 0x2F, 0x2005, 6, [200, 0, 0, 0]),
        initiated(0x2005, 6)
    );
    assert_eq!(b.s.od().get::<u8>(0x2005, 6), Ok(200));
    // The 16-byte label in three segments (7, 7, then 2 bytes and the last bit).
    let r = raw_sdo(&mut b, 0x21, 0x2006, 0, 16u32.to_le_bytes());
    assert_eq!(r, initiated(0x2006, 0));
    let label = b"sixteen byte lbl";
    for (k, cmd) in [(0usize, 0x00u8), (1, 0x10), (2, 0x0B)] {
        let mut p = [0u8; 10];
        let n = write_sdo_segment(
            &mut p,
            CoeService::SdoRequest,
            cmd,
            &label[7 * k..(7 * k + 7).min(16)],
        )
        .unwrap();
        let mut f = [0u8; 10];
        write_sdo_segment(&mut f, CoeService::SdoResponse, 0x20 | (cmd & 0x10), &[]).unwrap();
        assert_eq!(b.coe(&p[..n]), f, "segment {k}");
    }
    assert_eq!(b.s.od().bytes(0x2006, 0).unwrap(), label);
}

/// The reply's mailbox header in every field (length, address 0, channel 0, priority 0, the
/// type, the counter 1..=7 wrapping to 1, the reserved bit clear), over more replies than
/// the counter has values and with a mailbox error among them.
fn reply_mailbox_headers<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    let mut counter = 0;
    for k in 0..10 {
        counter = MailboxHeader::next_counter(counter);
        let (t, len) = if k == 4 {
            // A CoE service the stack does not serve: a mailbox error reply.
            b.mbx_write(MailboxType::Coe, &[0x00, 0x50, 0, 0, 0, 0, 0, 0, 0, 0]);
            (MailboxType::Error, 4)
        } else {
            b.mbx_write(
                MailboxType::Coe,
                &[0x00, 0x20, 0x40, 0x18, 0x10, 1, 0, 0, 0, 0],
            );
            (MailboxType::Coe, 10)
        };
        let (h, _) = b.mbx_read().expect("reply");
        assert_eq!(h, MailboxHeader::new(len, 0, t, counter), "reply {k}");
    }
}

/// SDO information messages the stack does not serve: the responses' opcodes, the error
/// opcode, a reserved one and each request too short for its fields are a service not
/// supported (mailbox error 4); one shorter than the headers is too short (6); the
/// shortest well-formed requests are answered.
fn sdo_information_not_served<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    let mut reply = |op: u8, data: &[u8]| {
        let mut p = vec![0x00, 0x80, op, 0, 0, 0];
        p.extend_from_slice(data);
        b.mbx_write(MailboxType::Coe, &p);
        let (h, p) = b.mbx_read().expect("reply");
        match h.mailbox_type {
            MailboxType::Error => Some(MailboxErrorReply::parse(&p).unwrap().detail.code()),
            _ => None,
        }
    };
    for (op, data) in [
        (0x01u8, &[0u8][..]),
        (0x03, &[0x18][..]),
        (0x05, &[0x18, 0x10, 1][..]),
        (0x02, &[1, 0, 0, 0][..]),
        (0x04, &[0x18, 0x10, 0, 0, 0, 0][..]),
        (0x06, &[0x18, 0x10, 1, 0, 0, 0, 0, 0, 0, 0][..]),
        (0x07, &[0, 0, 0, 0][..]),
        (0x09, &[0, 0, 0, 0][..]),
    ] {
        assert_eq!(
            reply(op, data),
            Some(4),
            "opcode {op:#x} with {} bytes",
            data.len()
        );
    }
    let mut p = vec![0x00, 0x80, 0x03];
    b.mbx_write(MailboxType::Coe, &p);
    let (h, r) = b.mbx_read().expect("reply");
    assert_eq!(h.mailbox_type, MailboxType::Error);
    assert_eq!(MailboxErrorReply::parse(&r).unwrap().detail.code(), 6);
    p.extend_from_slice(&[0, 0, 0, 0x18, 0x10]);
    b.mbx_write(MailboxType::Coe, &p);
    assert_eq!(
        b.mbx_read().expect("reply").0.mailbox_type,
        MailboxType::Coe
    );
    for (op, data) in [(0x01u8, &[1u8, 0][..]), (0x05, &[0x18, 0x10, 1, 0][..])] {
        let mut p = vec![0x00, 0x80, op, 0, 0, 0];
        p.extend_from_slice(data);
        b.mbx_write(MailboxType::Coe, &p);
        assert_eq!(
            b.mbx_read().expect("reply").0.mailbox_type,
            MailboxType::Coe
        );
    }
}

fn mailbox_errors_and_counters<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    let err = |b: &mut Bench<P>| {
        let (h, p) = b.mbx_read().expect("reply");
        assert_eq!(h.mailbox_type, MailboxType::Error);
        MailboxErrorReply::parse(&p).unwrap().detail.code()
    };
    // Unsupported protocol (FoE).
    b.mbx_write(MailboxType::Foe, &[1, 2, 3, 4]);
    assert_eq!(err(&mut b), 2);
    // Length beyond the mailbox: invalid size.
    b.mbx_write_raw(&[0xF0, 0x00, 0, 0, 0, 0x03]);
    assert_eq!(err(&mut b), 8);
    // Length 0: size too short.
    b.mbx_write_raw(&[0, 0, 0, 0, 0, 0x03]);
    assert_eq!(err(&mut b), 6);
    // CoE shorter than an SDO.
    b.mbx_write(MailboxType::Coe, &[0x00, 0x20, 0x40]);
    assert_eq!(err(&mut b), 6);
    // Channel != 0.
    b.mbx_write_raw(&[10, 0, 0, 0, 5, 0x03, 0, 0x20, 0x40, 0, 0x20, 0, 0, 0, 0, 0]);
    assert_eq!(err(&mut b), 3);
    // Type 0 from the master: syntax.
    b.mbx_write_raw(&[4, 0, 0, 0, 0, 0x00, 1, 0, 1, 0]);
    assert_eq!(err(&mut b), 1);
    // A repeated request (same counter) is not processed twice.
    let mut p = [0u8; 10];
    let h = SdoHeader {
        command: 0x40,
        index: 0x2000,
        subindex: 0,
    };
    write_sdo(&mut p, CoeService::SdoRequest, &h, [0; 4], &[]).unwrap();
    let mut raw = vec![10, 0, 0, 0, 0, 0x63];
    raw.extend_from_slice(&p);
    b.mbx_write_raw(&raw);
    assert!(b.mbx_read().is_some());
    let before = b.s.stats().mbx_requests;
    b.mbx_write_raw(&raw);
    assert!(b.mbx_read().is_none());
    assert_eq!(b.s.stats().mbx_duplicates, 1);
    assert_eq!(b.s.stats().mbx_requests, before + 1);
    // Reply counters run 1..7 and skip 0.
    let mut seen = vec![];
    for _ in 0..9 {
        b.mbx_write(MailboxType::Foe, &[0; 4]);
        seen.push(b.mbx_read().unwrap().0.counter);
    }
    assert!(seen.iter().all(|&c| (1..=7).contains(&c)));
}

fn repeat_request_resends_last_reply<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    let v = b.upload(0x1018, 2, false).unwrap();
    assert_eq!(v, 1u32.to_le_bytes());
    // The master lost the reply: toggle the repeat request bit of SM1.
    let (act, _) = b.rd(0x080E, 1);
    b.wr(0x080E, &[act[0] ^ 0x02]);
    b.poll();
    let (pc, _) = b.rd(0x080F, 1);
    assert_eq!(
        pc[0] & 0x02,
        (act[0] ^ 0x02) & 0x02,
        "repeat ack follows the request"
    );
    let (d, wkc) = b.rd(SM1, MBX);
    assert_eq!(wkc, 1);
    assert_eq!(&d[6 + 6..6 + 10], &1u32.to_le_bytes());
    assert_eq!(b.s.stats().mbx_repeats, 1);
}

fn sdo_information<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    // List all objects (fragmented: 128-byte mailbox).
    b.mbx_write(MailboxType::Coe, &[0x00, 0x80, 0x01, 0, 0, 0, 0x01, 0x00]);
    let mut idx = vec![];
    let mut first = true;
    loop {
        let (_, p) = b.mbx_read().expect("fragment");
        let r = SdoInfoRef::parse(&p).unwrap();
        let SdoInfoService::GetOdListResponse { words } = r.service().unwrap() else {
            panic!()
        };
        let mut w: Vec<u16> = words
            .chunks(2)
            .map(|c| u16::from_le_bytes([c[0], c[1]]))
            .collect();
        if first {
            assert_eq!(w.remove(0), 1);
            first = false;
        }
        idx.extend(w);
        if !r.header.incomplete {
            break;
        }
    }
    assert_eq!(idx.len(), b.s.od().object_count());
    assert!(idx.windows(2).all(|w| w[0] < w[1]));
    assert!(idx.contains(&0x1C33) && idx.contains(&0x7000) && idx.contains(&0x1A01));
    // Object description.
    b.mbx_write(MailboxType::Coe, &[0x00, 0x80, 0x03, 0, 0, 0, 0x18, 0x10]);
    let (_, p) = b.mbx_read().unwrap();
    match SdoInfoRef::parse(&p).unwrap().service().unwrap() {
        SdoInfoService::GetObjectDescriptionResponse {
            index,
            max_subindex,
            object_code,
            name,
            ..
        } => {
            assert_eq!((index, max_subindex, object_code), (0x1018, 4, 9));
            assert_eq!(name, b"Identity");
        }
        o => panic!("{o:?}"),
    }
    // Entry description.
    b.mbx_write(
        MailboxType::Coe,
        &[0x00, 0x80, 0x05, 0, 0, 0, 0x00, 0x70, 0x02, 0],
    );
    let (_, p) = b.mbx_read().unwrap();
    match SdoInfoRef::parse(&p).unwrap().service().unwrap() {
        SdoInfoService::GetEntryDescriptionResponse {
            data_type,
            bit_length,
            object_access,
            data,
            ..
        } => {
            assert_eq!((data_type, bit_length), (3, 16));
            assert_eq!(object_access, 0x3F | 0x40);
            assert_eq!(data, b"Setpoint");
        }
        o => panic!("{o:?}"),
    }
    // Access of a mapping object's entry: a fixed mapping (0x1A00) read-only, a
    // configurable one (0x1600) writable in PREOP, though both share one entry table.
    for (index, want) in [(0x1A00u16, 0x07u16), (0x1600, 0x0F)] {
        let i = index.to_le_bytes();
        b.mbx_write(
            MailboxType::Coe,
            &[0x00, 0x80, 0x05, 0, 0, 0, i[0], i[1], 0x01, 0],
        );
        let (_, p) = b.mbx_read().unwrap();
        match SdoInfoRef::parse(&p).unwrap().service().unwrap() {
            SdoInfoService::GetEntryDescriptionResponse { object_access, .. } => {
                assert_eq!(object_access, want, "{index:#x}:1")
            }
            o => panic!("{o:?}"),
        }
        // The listing host tools build the ESI from says the same.
        let od = b.s.od();
        let info = (0..od.object_count())
            .filter_map(|n| od.object_info(n))
            .find(|o| o.index == index)
            .expect("mapping object");
        assert!(
            info.entries.iter().all(|e| e.access.0 == want),
            "{index:#x}"
        );
    }
    // Unknown object.
    b.mbx_write(MailboxType::Coe, &[0x00, 0x80, 0x03, 0, 0, 0, 0x55, 0x55]);
    let (_, p) = b.mbx_read().unwrap();
    match SdoInfoRef::parse(&p).unwrap().service().unwrap() {
        SdoInfoService::Error { code } => assert_eq!(code.code(), 0x0602_0000),
        o => panic!("{o:?}"),
    }
}

fn emergency_is_sent<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    assert!(b.s.emergency(0x5000, 0x81, [1, 2, 3, 4, 5]));
    let (h, p) = b.mbx_read().unwrap();
    assert_eq!(h.mailbox_type, MailboxType::Coe);
    let e = oxicat_wire::coe::Emergency::parse_coe(&p).unwrap();
    assert_eq!(
        (e.error_code, e.error_register, e.data),
        (0x5000, 0x81, [1, 2, 3, 4, 5])
    );
    assert_eq!(b.upload(0x1001, 0, false).unwrap(), [0x81]);
}

fn garbage_mailboxes_never_panic<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    let mut x: u32 = 0x1234_5678;
    for _ in 0..300 {
        let mut buf = vec![0u8; MBX];
        for v in buf.iter_mut() {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            *v = x as u8;
        }
        buf[0] = (x % 40) as u8;
        buf[1] = 0;
        buf[4] = 0;
        buf[5] = 0x03 | ((x as u8 % 7 + 1) << 4);
        buf[7] = (buf[7] & 0x0F) | 0x20 | if x & 1 == 0 { 0x80 } else { 0 };
        b.mbx_write_raw(&buf);
        let _ = b.mbx_read();
    }
    // Still serving.
    assert_eq!(b.upload(0x1018, 1, false).unwrap(), 0x0A5Cu32.to_le_bytes());
}

/// Entry description with value info (ETG.1000.6: 0x08 unit, 0x10 default, 0x20 minimum,
/// 0x40 maximum): the reply says which fields it carries, values from the definition.
fn entry_desc<P: Port>(b: &mut Bench<P>, index: u16, sub: u8, vi: u8) -> (u8, Vec<u8>) {
    let i = index.to_le_bytes();
    b.mbx_write(
        MailboxType::Coe,
        &[0x00, 0x80, 0x05, 0, 0, 0, i[0], i[1], sub, vi],
    );
    let (_, p) = b.mbx_read().unwrap();
    match SdoInfoRef::parse(&p).unwrap().service().unwrap() {
        SdoInfoService::GetEntryDescriptionResponse {
            index: ri,
            subindex,
            value_info,
            data,
            ..
        } => {
            assert_eq!((ri, subindex), (index, sub));
            (value_info, data.to_vec())
        }
        o => panic!("{o:?}"),
    }
}

fn entry_description_value_info<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    // UNSIGNED32 with unit (mA), default 7, range 0..=1000.
    let (vi, d) = entry_desc(&mut b, 0x2000, 0, 0x78);
    assert_eq!(vi, 0x78);
    let mut want = Vec::new();
    want.extend_from_slice(&0xFD04_0000u32.to_le_bytes());
    want.extend_from_slice(&7u32.to_le_bytes());
    want.extend_from_slice(&0u32.to_le_bytes());
    want.extend_from_slice(&1000u32.to_le_bytes());
    want.extend_from_slice(b"Param");
    assert_eq!(d, want);
    // Only some fields: maximum alone, then unit + minimum.
    let (vi, d) = entry_desc(&mut b, 0x2000, 0, 0x40);
    assert_eq!(
        (vi, &d[..4], &d[4..]),
        (0x40, &1000u32.to_le_bytes()[..], &b"Param"[..])
    );
    let (vi, d) = entry_desc(&mut b, 0x2000, 0, 0x28);
    assert_eq!(vi, 0x28);
    assert_eq!(&d[..8], &[0, 0, 0x04, 0xFD, 0, 0, 0, 0]);
    // No value info: the name only (as before).
    assert_eq!(entry_desc(&mut b, 0x2000, 0, 0), (0, b"Param".to_vec()));
    // INTEGER8 without a range: default -5, the type's limits; no unit (0).
    let (vi, d) = entry_desc(&mut b, 0x2002, 0, 0x78);
    assert_eq!(vi, 0x78);
    assert_eq!(
        d,
        [&[0u8, 0, 0, 0][..], &[0xFB, 0x80, 0x7F], b"Const"].concat()
    );
    // REAL32 default 1.5; limits of the type.
    let (_, d) = entry_desc(&mut b, 0x2004, 0, 0x70);
    assert_eq!(&d[..4], &1.5f32.to_le_bytes());
    assert_eq!(&d[4..8], &f32::MIN.to_le_bytes());
    assert_eq!(&d[8..12], &f32::MAX.to_le_bytes());
    // A string has a default (its full length) but no minimum/maximum.
    let (vi, d) = entry_desc(&mut b, 0x2006, 0, 0x78);
    assert_eq!(vi, 0x18);
    let mut label = b"hello".to_vec();
    label.resize(16, 0);
    assert_eq!(&d[4..20], &label[..]);
    assert_eq!(&d[20..], b"Label");
    // A BOOL: 0..1 in one byte each.
    let (vi, d) = entry_desc(&mut b, 0x7000, 1, 0x70);
    assert_eq!((vi, &d[..3]), (0x70, &[0u8, 0, 1][..]));
    // Standard objects: defaults derived from the device definition.
    let (_, d) = entry_desc(&mut b, 0x1018, 1, 0x10);
    assert_eq!(&d[..4], &0x0A5Cu32.to_le_bytes());
    let (_, d) = entry_desc(&mut b, 0x1C32, 5, 0x10);
    assert_eq!(&d[..4], &100_000u32.to_le_bytes());
    let (_, d) = entry_desc(&mut b, 0x1A00, 4, 0x10);
    assert_eq!(&d[..4], &0x6000_0310u32.to_le_bytes());
    let (_, d) = entry_desc(&mut b, 0x1C13, 0, 0x10);
    assert_eq!(d[0], 1);
}

oxicat_testkit::every_pdi!(
    every_data_type_round_trips,
    segmented_1k_both_directions,
    complete_access,
    dynamic_pdo_assignment,
    refused_safeop_keeps_the_active_mapping,
    abort_codes_table,
    protocol_aborts,
    upload_frames_byte_for_byte,
    download_and_abort_frames_byte_for_byte,
    reply_mailbox_headers,
    sdo_information_not_served,
    mailbox_errors_and_counters,
    repeat_request_resends_last_reply,
    sdo_information,
    emergency_is_sent,
    garbage_mailboxes_never_panic,
    entry_description_value_info,
);
