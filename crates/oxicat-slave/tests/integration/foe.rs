//! FoE server and firmware update flow on the software-ESC bench: every error path, busy,
//! packet numbers, password, and the update outcomes (good, truncated, corrupted, wrong
//! device, interrupted) with the bootable firmware checked after each.

use oxicat_slave::foe::{
    FirmwareStore, FirmwareUpdate, FoeErrorCode, ImageHeader, RamStore, UpdateConfig, UpdateResult,
    WithFoe, IMAGE_HEADER_LEN,
};
use oxicat_slave::Identity;
use oxicat_testkit::device::*;
use oxicat_testkit::{Bench, Port};
use oxicat_wire::foe::{FoeHeader, FoeRef};
use oxicat_wire::mailbox::MailboxType;

type Store = RamStore<2, 1024>;
type FwApp = WithFoe<App, FirmwareUpdate<Store>>;

/// Data bytes per FoE packet with the bench's 128-byte mailboxes.
const SEG: usize = MBX - 12;
const FILE: &str = "firmware.bin";

fn image(id: &Identity, payload: &[u8]) -> Vec<u8> {
    let mut v = ImageHeader::for_payload(id, payload).to_bytes().to_vec();
    v.extend_from_slice(payload);
    v
}

fn payload(n: usize, seed: u8) -> Vec<u8> {
    (0..n)
        .map(|i| (i as u8).wrapping_mul(31).wrapping_add(seed))
        .collect()
}

fn factory() -> Vec<u8> {
    image(&DEF.identity, &payload(200, 1))
}

fn new_identity() -> Identity {
    Identity {
        revision: DEF.identity.revision + 1,
        ..DEF.identity
    }
}

fn bench_with<P: Port>(cfg: UpdateConfig, store: Store) -> Bench<P, FwApp> {
    Bench::with_app(WithFoe {
        app: App::default(),
        files: FirmwareUpdate::new(store, cfg),
    })
}

fn cfg() -> UpdateConfig {
    UpdateConfig {
        identity: DEF.identity,
        file_name: FILE,
        password: 0,
        read_back: true,
    }
}

fn bench<P: Port>() -> Bench<P, FwApp> {
    bench_with(cfg(), Store::with_image(&factory()).unwrap())
}

fn enter_boot<P: Port>(b: &mut Bench<P, FwApp>) {
    b.config_mailbox();
    assert_eq!(b.request(3), (3, 0));
}

/// Sends one FoE message, returns the FoE reply.
fn foe<P: Port>(b: &mut Bench<P, FwApp>, h: FoeHeader, data: &[u8]) -> (FoeHeader, Vec<u8>) {
    let mut p = vec![0u8; MBX];
    let n = FoeRef::write(&h, data, &mut p).unwrap();
    assert_eq!(b.mbx_write(MailboxType::Foe, &p[..n]), 1);
    let (mh, r) = b.mbx_read().expect("FoE reply");
    assert_eq!(mh.mailbox_type, MailboxType::Foe, "reply {r:02x?}");
    let f = FoeRef::parse(&r).unwrap();
    (f.header, f.data.to_vec())
}

#[derive(Debug, PartialEq)]
struct Refused(FoeErrorCode, String);

fn refused(h: FoeHeader, text: &[u8]) -> Refused {
    match h {
        FoeHeader::Error { code } => Refused(code, String::from_utf8_lossy(text).into()),
        o => panic!("expected an FoE error, got {o:?}"),
    }
}

/// Writes a file like SOEM: packets of SEG bytes, a short (possibly empty) last one,
/// BUSY → the same packet again. Returns the number of BUSY replies.
fn write_file<P: Port>(
    b: &mut Bench<P, FwApp>,
    name: &str,
    password: u32,
    data: &[u8],
) -> Result<u32, Refused> {
    let (h, t) = foe(b, FoeHeader::Write { password }, name.as_bytes());
    if h != (FoeHeader::Ack { packet: 0 }) {
        return Err(refused(h, &t));
    }
    let mut busy = 0;
    let mut packet = 1u32;
    let mut off = 0usize;
    loop {
        let n = (data.len() - off).min(SEG);
        let (h, t) = foe(b, FoeHeader::Data { packet }, &data[off..off + n]);
        match h {
            FoeHeader::Ack { packet: p } => assert_eq!(p, packet),
            FoeHeader::Busy { .. } => {
                busy += 1;
                assert!(busy < 100, "busy forever");
                continue;
            }
            _ => return Err(refused(h, &t)),
        }
        off += n;
        packet += 1;
        if n < SEG {
            return Ok(busy);
        }
    }
}

fn read_file<P: Port>(
    b: &mut Bench<P, FwApp>,
    name: &str,
    password: u32,
) -> Result<Vec<u8>, Refused> {
    let mut out = Vec::new();
    let (mut h, mut t) = foe(b, FoeHeader::Read { password }, name.as_bytes());
    let mut expect = 1;
    loop {
        match h {
            FoeHeader::Data { packet } => {
                assert_eq!(packet, expect);
                out.extend_from_slice(&t);
                if t.len() < SEG {
                    // The final ACK gets no reply.
                    let mut p = vec![0u8; 16];
                    let n = FoeRef::write(&FoeHeader::Ack { packet }, &[], &mut p).unwrap();
                    b.mbx_write(MailboxType::Foe, &p[..n]);
                    assert!(b.mbx_read().is_none());
                    return Ok(out);
                }
                (h, t) = foe(b, FoeHeader::Ack { packet }, &[]);
                expect += 1;
            }
            _ => return Err(refused(h, &t)),
        }
    }
}

fn bootable_is_factory<P: Port>(b: &mut Bench<P, FwApp>) {
    let f = factory();
    let store = &mut b.app.files.store;
    assert_eq!(store.bootable(), Some(0));
    assert_eq!(&store.slot(0).unwrap()[..f.len()], &f[..]);
    assert_eq!(b.app.files.current(), Some(ImageHeader::parse(&f).unwrap()));
}

fn good_image_installs_and_reports_its_identity<P: Port>() {
    let mut b = bench::<P>();
    enter_boot(&mut b);
    let img = image(&new_identity(), &payload(500, 7));
    assert_eq!(write_file(&mut b, FILE, 0, &img), Ok(0));
    let h = ImageHeader::parse(&img).unwrap();
    assert_eq!(b.app.files.last, Some(UpdateResult::Installed(h)));
    assert_eq!(b.app.files.store.bootable(), Some(1));
    assert_eq!(b.app.files.current(), Some(h));
    assert_eq!(&b.app.files.store.slot(1).unwrap()[..img.len()], &img[..]);
    // The old image is still in its slot (fallback), untouched.
    let f = factory();
    assert_eq!(&b.app.files.store.slot(0).unwrap()[..f.len()], &f[..]);
    // The device reports the new identity, in BOOT and after it.
    let v = String::from_utf8(read_file(&mut b, "version.txt", 0).unwrap()).unwrap();
    assert!(v.contains("revision=0x00010001"), "{v}");
    assert!(v.contains("length=500"), "{v}");
    assert_eq!(read_file(&mut b, FILE, 0).unwrap(), img);
    // Out of BOOT (INIT) and to PREOP: version.txt is served there too.
    assert_eq!(b.request(1), (1, 0));
    b.enter_preop();
    let v2 = String::from_utf8(read_file(&mut b, "version.txt", 0).unwrap()).unwrap();
    assert_eq!(v, v2);
}

fn image_of_exactly_whole_segments_ends_with_an_empty_packet<P: Port>() {
    let mut b = bench::<P>();
    enter_boot(&mut b);
    let img = image(&new_identity(), &payload(3 * SEG - IMAGE_HEADER_LEN, 3));
    assert_eq!(img.len() % SEG, 0);
    assert_eq!(write_file(&mut b, FILE, 0, &img), Ok(0));
    assert_eq!(b.app.files.store.bootable(), Some(1));
    assert_eq!(read_file(&mut b, FILE, 0).unwrap(), img);
}

fn truncated_image_is_rejected_and_old_firmware_stays<P: Port>() {
    let mut b = bench::<P>();
    enter_boot(&mut b);
    let img = image(&new_identity(), &payload(500, 7));
    let r = write_file(&mut b, FILE, 0, &img[..300]).unwrap_err();
    assert_eq!(r.0, FoeErrorCode::ProgramError);
    assert!(r.1.contains("truncated"), "{r:?}");
    assert_eq!(
        b.app.files.last,
        Some(UpdateResult::Rejected(FoeErrorCode::ProgramError))
    );
    bootable_is_factory(&mut b);
    // Shorter than the header.
    let r = write_file(&mut b, FILE, 0, &img[..20]).unwrap_err();
    assert_eq!(r.0, FoeErrorCode::ProgramError);
    bootable_is_factory(&mut b);
    // Longer than the header says.
    let mut long = img.clone();
    long.extend_from_slice(b"trailing");
    let r = write_file(&mut b, FILE, 0, &long).unwrap_err();
    assert_eq!(r.0, FoeErrorCode::ProgramError);
    bootable_is_factory(&mut b);
}

fn corrupted_image_fails_the_crc_and_old_firmware_stays<P: Port>() {
    let mut b = bench::<P>();
    enter_boot(&mut b);
    let mut img = image(&new_identity(), &payload(500, 7));
    img[IMAGE_HEADER_LEN + 250] ^= 0x10;
    let r = write_file(&mut b, FILE, 0, &img).unwrap_err();
    assert_eq!(r.0, FoeErrorCode::ChecksumError);
    assert_eq!(r.0.code(), 0x800C);
    bootable_is_factory(&mut b);
    // A good image installs afterwards.
    let img = image(&new_identity(), &payload(500, 7));
    assert_eq!(write_file(&mut b, FILE, 0, &img), Ok(0));
    assert_eq!(b.app.files.store.bootable(), Some(1));
}

fn wrong_device_image_is_rejected_at_its_first_packet<P: Port>() {
    let mut b = bench::<P>();
    enter_boot(&mut b);
    for id in [
        Identity {
            product_code: DEF.identity.product_code + 1,
            ..DEF.identity
        },
        Identity {
            vendor_id: 0x1234,
            ..DEF.identity
        },
        Identity {
            revision: DEF.identity.revision + 0x0001_0000,
            ..DEF.identity
        },
    ] {
        let img = image(&id, &payload(500, 9));
        // Rejected with the first data packet, before anything is erased or written.
        assert_eq!(
            foe(&mut b, FoeHeader::Write { password: 0 }, FILE.as_bytes()).0,
            FoeHeader::Ack { packet: 0 }
        );
        let (h, t) = foe(&mut b, FoeHeader::Data { packet: 1 }, &img[..SEG]);
        let r = refused(h, &t);
        assert_eq!(r.0, FoeErrorCode::ProgramError);
        assert!(r.1.contains("another device"), "{r:?}");
        bootable_is_factory(&mut b);
    }
    // Not an image at all.
    let r = write_file(&mut b, FILE, 0, &[0x55; 300]).unwrap_err();
    assert_eq!(
        r,
        Refused(FoeErrorCode::ProgramError, "not a firmware image".into())
    );
    bootable_is_factory(&mut b);
}

fn interrupted_download_boot_to_init_keeps_old_firmware<P: Port>() {
    let mut b = bench::<P>();
    enter_boot(&mut b);
    let img = image(&new_identity(), &payload(600, 7));
    assert_eq!(
        foe(&mut b, FoeHeader::Write { password: 0 }, FILE.as_bytes()).0,
        FoeHeader::Ack { packet: 0 }
    );
    for p in 0..3u32 {
        let s = p as usize * SEG;
        let (h, _) = foe(&mut b, FoeHeader::Data { packet: p + 1 }, &img[s..s + SEG]);
        assert_eq!(h, FoeHeader::Ack { packet: p + 1 });
    }
    // The master gives up: BOOT -> INIT mid-transfer.
    assert_eq!(b.request(1), (1, 0));
    assert_eq!(b.app.files.last, Some(UpdateResult::Aborted));
    bootable_is_factory(&mut b);
    // Back in BOOT, the old transfer is gone: its next packet is illegal.
    enter_boot(&mut b);
    let (h, t) = foe(
        &mut b,
        FoeHeader::Data { packet: 4 },
        &img[3 * SEG..4 * SEG],
    );
    assert_eq!(refused(h, &t).0, FoeErrorCode::Illegal);
    bootable_is_factory(&mut b);
    // An ERROR from the client also ends a transfer without a reply and without damage.
    assert_eq!(
        foe(&mut b, FoeHeader::Write { password: 0 }, FILE.as_bytes()).0,
        FoeHeader::Ack { packet: 0 }
    );
    let (h, _) = foe(&mut b, FoeHeader::Data { packet: 1 }, &img[..SEG]);
    assert_eq!(h, FoeHeader::Ack { packet: 1 });
    let mut p = vec![0u8; 16];
    let n = FoeRef::write(
        &FoeHeader::Error {
            code: FoeErrorCode::NotDefined,
        },
        b"",
        &mut p,
    )
    .unwrap();
    b.mbx_write(MailboxType::Foe, &p[..n]);
    assert!(b.mbx_read().is_none());
    assert_eq!(b.app.files.last, Some(UpdateResult::Aborted));
    bootable_is_factory(&mut b);
}

fn firmware_write_outside_boot_is_refused<P: Port>() {
    let mut b = bench::<P>();
    b.enter_preop();
    let img = image(&new_identity(), &payload(100, 7));
    assert_eq!(
        write_file(&mut b, FILE, 0, &img),
        Err(Refused(
            FoeErrorCode::BootstrapOnly,
            "Bootstrap only".into()
        ))
    );
    assert_eq!(
        read_file(&mut b, FILE, 0),
        Err(Refused(
            FoeErrorCode::BootstrapOnly,
            "Bootstrap only".into()
        ))
    );
    // Unknown files outside BOOT: not found.
    assert_eq!(
        read_file(&mut b, "nothing.txt", 0).unwrap_err().0,
        FoeErrorCode::NotFound
    );
    assert_eq!(
        write_file(&mut b, "nothing.txt", 0, b"x").unwrap_err().0,
        FoeErrorCode::NotFound
    );
    bootable_is_factory(&mut b);
}

fn file_errors_in_boot<P: Port>() {
    let mut b = bench::<P>();
    enter_boot(&mut b);
    // Other files are not served by the bootstrap mailbox.
    assert_eq!(
        read_file(&mut b, "config.bin", 0).unwrap_err().0,
        FoeErrorCode::NotBootstrap
    );
    assert_eq!(
        write_file(&mut b, "config.bin", 0, b"x").unwrap_err().0,
        FoeErrorCode::NotBootstrap
    );
    // version.txt is read-only.
    assert_eq!(
        write_file(&mut b, "version.txt", 0, b"x").unwrap_err().0,
        FoeErrorCode::AccessDenied
    );
    // Larger than a slot: disk full, from the header, before anything is written.
    let big = image(&new_identity(), &payload(2000, 1));
    let r = write_file(&mut b, FILE, 0, &big).unwrap_err();
    assert_eq!(r.0, FoeErrorCode::DiskFull);
    // The image already bootable: already exists.
    assert_eq!(
        write_file(&mut b, FILE, 0, &factory()).unwrap_err().0,
        FoeErrorCode::AlreadyExists
    );
    bootable_is_factory(&mut b);
}

fn read_back_can_be_denied_and_an_empty_store_has_no_image<P: Port>() {
    let mut b = bench_with::<P>(
        UpdateConfig {
            read_back: false,
            ..cfg()
        },
        Store::new(),
    );
    enter_boot(&mut b);
    assert_eq!(
        read_file(&mut b, FILE, 0).unwrap_err().0,
        FoeErrorCode::AccessDenied
    );
    let v = read_file(&mut b, "version.txt", 0).unwrap();
    assert_eq!(v, b"no image\n");
    // The first image goes into slot 0.
    let img = image(&DEF.identity, &payload(64, 2));
    assert_eq!(write_file(&mut b, FILE, 0, &img), Ok(0));
    assert_eq!(b.app.files.store.bootable(), Some(0));

    let mut b = bench_with::<P>(cfg(), Store::new());
    enter_boot(&mut b);
    assert_eq!(
        read_file(&mut b, FILE, 0).unwrap_err().0,
        FoeErrorCode::NotFound
    );
}

fn password_no_user_and_no_rights<P: Port>() {
    let mut b = bench_with::<P>(
        UpdateConfig {
            password: 0x1234_5678,
            ..cfg()
        },
        Store::with_image(&factory()).unwrap(),
    );
    enter_boot(&mut b);
    let img = image(&new_identity(), &payload(300, 4));
    assert_eq!(
        write_file(&mut b, FILE, 0, &img).unwrap_err().0,
        FoeErrorCode::NoUser
    );
    assert_eq!(
        write_file(&mut b, FILE, 0x1111, &img).unwrap_err().0,
        FoeErrorCode::NoRights
    );
    assert_eq!(
        read_file(&mut b, FILE, 0x1111).unwrap_err().0,
        FoeErrorCode::NoRights
    );
    bootable_is_factory(&mut b);
    assert_eq!(write_file(&mut b, FILE, 0x1234_5678, &img), Ok(0));
    assert_eq!(b.app.files.store.bootable(), Some(1));
    // version.txt needs no password.
    assert!(read_file(&mut b, "version.txt", 0).is_ok());
}

fn busy_while_the_flash_erases_then_the_same_packet_again<P: Port>() {
    let mut store = Store::with_image(&factory()).unwrap();
    store.erase_busy = 3;
    let mut b = bench_with::<P>(cfg(), store);
    enter_boot(&mut b);
    let img = image(&new_identity(), &payload(400, 5));
    assert_eq!(
        foe(&mut b, FoeHeader::Write { password: 0 }, FILE.as_bytes()).0,
        FoeHeader::Ack { packet: 0 }
    );
    for k in 0..3u16 {
        let (h, _) = foe(&mut b, FoeHeader::Data { packet: 1 }, &img[..SEG]);
        assert_eq!(h, FoeHeader::Busy { done: k, entire: 3 });
    }
    let (h, _) = foe(&mut b, FoeHeader::Data { packet: 1 }, &img[..SEG]);
    assert_eq!(h, FoeHeader::Ack { packet: 1 });
    // A whole download with a busy erase, through the client loop.
    let img2 = image(
        &Identity {
            revision: DEF.identity.revision + 2,
            ..DEF.identity
        },
        &payload(400, 6),
    );
    b.request(1);
    enter_boot(&mut b);
    assert_eq!(write_file(&mut b, FILE, 0, &img2), Ok(3));
    assert_eq!(
        b.app.files.current(),
        Some(ImageHeader::parse(&img2).unwrap())
    );
}

fn flash_failure_is_a_program_error<P: Port>() {
    let mut store = Store::with_image(&factory()).unwrap();
    store.fail_writes = true;
    let mut b = bench_with::<P>(cfg(), store);
    enter_boot(&mut b);
    let img = image(&new_identity(), &payload(300, 5));
    let r = write_file(&mut b, FILE, 0, &img).unwrap_err();
    assert_eq!(r.0, FoeErrorCode::ProgramError);
    assert!(r.1.contains("flash"), "{r:?}");
    bootable_is_factory(&mut b);
}

fn packet_number_wrong_and_the_repeated_last_packet<P: Port>() {
    let mut b = bench::<P>();
    enter_boot(&mut b);
    let img = image(&new_identity(), &payload(500, 7));
    // Skipping a packet.
    assert_eq!(
        foe(&mut b, FoeHeader::Write { password: 0 }, FILE.as_bytes()).0,
        FoeHeader::Ack { packet: 0 }
    );
    let (h, t) = foe(&mut b, FoeHeader::Data { packet: 2 }, &img[..SEG]);
    assert_eq!(refused(h, &t).0, FoeErrorCode::PacketNumberWrong);
    assert_eq!(b.app.files.last, Some(UpdateResult::Aborted));
    // The last packet again (as SOES: packet number wrong, transfer aborted).
    assert_eq!(
        foe(&mut b, FoeHeader::Write { password: 0 }, FILE.as_bytes()).0,
        FoeHeader::Ack { packet: 0 }
    );
    let (h, _) = foe(&mut b, FoeHeader::Data { packet: 1 }, &img[..SEG]);
    assert_eq!(h, FoeHeader::Ack { packet: 1 });
    let (h, t) = foe(&mut b, FoeHeader::Data { packet: 1 }, &img[..SEG]);
    assert_eq!(refused(h, &t).0, FoeErrorCode::PacketNumberWrong);
    bootable_is_factory(&mut b);
    // A read ACK with the wrong number.
    let (h, _) = foe(&mut b, FoeHeader::Read { password: 0 }, FILE.as_bytes());
    assert_eq!(h, FoeHeader::Data { packet: 1 });
    let (h, t) = foe(&mut b, FoeHeader::Ack { packet: 7 }, &[]);
    assert_eq!(refused(h, &t).0, FoeErrorCode::PacketNumberWrong);
}

fn client_busy_on_read_sends_the_last_packet_again<P: Port>() {
    let mut b = bench::<P>();
    enter_boot(&mut b);
    let f = factory();
    let (h, d1) = foe(&mut b, FoeHeader::Read { password: 0 }, FILE.as_bytes());
    assert_eq!(h, FoeHeader::Data { packet: 1 });
    assert_eq!(d1, f[..SEG]);
    let (h, d) = foe(&mut b, FoeHeader::Busy { done: 0, entire: 0 }, &[]);
    assert_eq!(h, FoeHeader::Data { packet: 1 });
    assert_eq!(d, d1);
    let (h, d2) = foe(&mut b, FoeHeader::Ack { packet: 1 }, &[]);
    assert_eq!(h, FoeHeader::Data { packet: 2 });
    assert_eq!(d2, f[SEG..]);
}

fn illegal_requests_and_unknown_opcode<P: Port>() {
    let mut b = bench::<P>();
    enter_boot(&mut b);
    let (h, t) = foe(&mut b, FoeHeader::Data { packet: 1 }, b"abc");
    assert_eq!(
        refused(h, &t),
        Refused(FoeErrorCode::Illegal, "Illegal".into())
    );
    let (h, t) = foe(&mut b, FoeHeader::Ack { packet: 1 }, &[]);
    assert_eq!(refused(h, &t).0, FoeErrorCode::Illegal);
    let (h, t) = foe(&mut b, FoeHeader::Busy { done: 0, entire: 0 }, &[]);
    assert_eq!(refused(h, &t).0, FoeErrorCode::Illegal);
    // A second request in the middle of a transfer.
    assert_eq!(
        foe(&mut b, FoeHeader::Write { password: 0 }, FILE.as_bytes()).0,
        FoeHeader::Ack { packet: 0 }
    );
    let (h, t) = foe(&mut b, FoeHeader::Read { password: 0 }, b"version.txt");
    assert_eq!(refused(h, &t).0, FoeErrorCode::Illegal);
    assert_eq!(b.app.files.last, Some(UpdateResult::Aborted));
    // Unknown opcode 9: not defined.
    b.mbx_write(MailboxType::Foe, &[9, 0, 0, 0, 0, 0]);
    let (_, r) = b.mbx_read().unwrap();
    let f = FoeRef::parse(&r).unwrap();
    assert_eq!(
        f.header,
        FoeHeader::Error {
            code: FoeErrorCode::NotDefined
        }
    );
    // Shorter than the FoE header: mailbox error.
    b.mbx_write(MailboxType::Foe, &[3, 0, 1]);
    let (h, _) = b.mbx_read().unwrap();
    assert_eq!(h.mailbox_type, MailboxType::Error);
    bootable_is_factory(&mut b);
}

fn a_device_without_foe_answers_unsupported_protocol<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    let mut p = vec![0u8; 32];
    let n = FoeRef::write(&FoeHeader::Read { password: 0 }, b"version.txt", &mut p).unwrap();
    b.mbx_write(MailboxType::Foe, &p[..n]);
    let (h, r) = b.mbx_read().unwrap();
    assert_eq!(h.mailbox_type, MailboxType::Error);
    // Detail 0x0002: unsupported protocol.
    assert_eq!(u16::from_le_bytes([r[2], r[3]]), 0x0002);
}

oxicat_testkit::every_pdi!(
    good_image_installs_and_reports_its_identity,
    image_of_exactly_whole_segments_ends_with_an_empty_packet,
    truncated_image_is_rejected_and_old_firmware_stays,
    corrupted_image_fails_the_crc_and_old_firmware_stays,
    wrong_device_image_is_rejected_at_its_first_packet,
    interrupted_download_boot_to_init_keeps_old_firmware,
    firmware_write_outside_boot_is_refused,
    file_errors_in_boot,
    read_back_can_be_denied_and_an_empty_store_has_no_image,
    password_no_user_and_no_rights,
    busy_while_the_flash_erases_then_the_same_packet_again,
    flash_failure_is_a_program_error,
    packet_number_wrong_and_the_repeated_last_packet,
    client_busy_on_read_sends_the_last_packet_again,
    illegal_requests_and_unknown_opcode,
    a_device_without_foe_answers_unsupported_protocol,
);
