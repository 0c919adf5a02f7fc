//! What a master sees of every device's dictionary over SDO information and SDO upload is
//! what the dictionary listing says (`Od::object_info`, the tables the ESI is generated
//! from): every object's description, every entry's description (with and without value
//! info) and every readable entry's value, for every device a board image runs and the test
//! device. The stack serves its mapping and assignment objects from a template entry per
//! object kind; the listing keeps one table entry per subindex.
//!
//! `cargo test -p oxicat-slave --test integration sdo_info:: -- --nocapture` prints a digest of each
//! device's whole transcript (the reply bytes of every request above), for comparing two
//! trees byte for byte.

use oxicat_slave::{Application, DataType, DeviceDef, ObjectCode};
use oxicat_testkit::ports::Soft;
use oxicat_testkit::Bench;
use oxicat_wire::coe::{SdoInfoRef, SdoInfoService};
use oxicat_wire::mailbox::MailboxType;

/// FNV-1a, 64 bits.
struct Digest(u64);

impl Digest {
    fn add(&mut self, b: &[u8]) {
        for &x in b {
            self.0 = (self.0 ^ u64::from(x)).wrapping_mul(0x0000_0100_0000_01B3);
        }
        // Length-delimited, so that two transcripts differing only in where a reply ends
        // differ.
        self.0 = (self.0 ^ b.len() as u64).wrapping_mul(0x0000_0100_0000_01B3);
    }
}

/// One SDO information request, its reply's CoE payload.
fn info<A: Application<N>, const N: usize>(b: &mut Bench<Soft, A, N>, req: &[u8]) -> Vec<u8> {
    b.mbx_write(MailboxType::Coe, req);
    b.mbx_read().expect("a reply").1
}

/// Checks `def`'s SDO information and uploads against its listing; returns the transcript
/// digest.
fn check_device<const N: usize>(name: &str, def: &'static DeviceDef) -> u64 {
    let mut b = Bench::<Soft, (), N>::on(def, ());
    b.enter_preop();
    let mut dig = Digest(0xCBF2_9CE4_8422_2325);
    // The list lengths.
    dig.add(&info(&mut b, &[0x00, 0x80, 0x01, 0, 0, 0, 0x00, 0x00]));
    let od = b.s.od();
    let objects: Vec<_> = (0..od.object_count())
        .map(|n| od.object_info(n).expect("object"))
        .collect();
    for o in &objects {
        let i = o.index.to_le_bytes();
        let p = info(&mut b, &[0x00, 0x80, 0x03, 0, 0, 0, i[0], i[1]]);
        dig.add(&p);
        let last = o.entries.last().expect("entries");
        let dtype = match o.code {
            ObjectCode::Var => o.entries[0].dtype.code(),
            ObjectCode::Array => last.dtype.code(),
            ObjectCode::Record => 0x002A,
        };
        match SdoInfoRef::parse(&p).unwrap().service().unwrap() {
            SdoInfoService::GetObjectDescriptionResponse {
                index,
                data_type,
                max_subindex,
                object_code,
                name: n,
            } => {
                assert_eq!(
                    (index, data_type, max_subindex, object_code),
                    (o.index, dtype, last.sub, o.code.code()),
                    "{name} {:#06x}",
                    o.index
                );
                assert_eq!(n, o.name.as_bytes(), "{name} {:#06x}", o.index);
            }
            r => panic!("{name} {:#06x}: {r:?}", o.index),
        }
        for e in o.entries {
            let mut access = e.access.0;
            if e.pdo.rx() {
                access |= 0x40;
            }
            if e.pdo.tx() {
                access |= 0x80;
            }
            for vi in [0u8, 0x08, 0x10, 0x20, 0x40, 0x78] {
                let p = info(&mut b, &[0x00, 0x80, 0x05, 0, 0, 0, i[0], i[1], e.sub, vi]);
                dig.add(&p);
                match SdoInfoRef::parse(&p).unwrap().service().unwrap() {
                    SdoInfoService::GetEntryDescriptionResponse {
                        index,
                        subindex,
                        value_info,
                        data_type,
                        bit_length,
                        object_access,
                        data,
                    } => {
                        let at = format!("{name} {:#06x}:{} vi {vi:#x}", o.index, e.sub);
                        assert_eq!(
                            (index, subindex, data_type, bit_length, object_access),
                            (o.index, e.sub, e.dtype.code(), e.bits, access),
                            "{at}"
                        );
                        assert_eq!(value_info & !vi, 0, "{at}");
                        assert!(data.ends_with(e.name.as_bytes()), "{at}: {data:?}");
                        if vi == 0 {
                            assert_eq!(data, e.name.as_bytes(), "{at}");
                        }
                    }
                    r => panic!("{name} {:#06x}:{}: {r:?}", o.index, e.sub),
                }
            }
            if e.access.readable() {
                let v = b.upload(o.index, e.sub, false).expect("upload");
                dig.add(&v);
                let mut want = b.s.od().bytes(o.index, e.sub).expect("entry").to_vec();
                if e.dtype == DataType::VisibleString {
                    let end = want.iter().position(|&c| c == 0).unwrap_or(want.len());
                    want.truncate(end);
                }
                assert_eq!(v, want, "{name} {:#06x}:{}", o.index, e.sub);
            }
        }
    }
    dig.0
}

#[test]
fn every_device_describes_its_dictionary_as_its_listing_does() {
    use laelaps::kinematics::Side;
    use oxicat_devices::{axis_hub, cia402, demo, laelaps, tue_es030};
    use oxicat_testkit::device as testkit;
    let digests = [
        ("demo", check_device::<{ demo::IMAGE }>("demo", &demo::DEF)),
        (
            "demo additions",
            check_device::<{ demo::additions::IMAGE }>("demo additions", &demo::additions::DEF),
        ),
        (
            "laelaps left",
            check_device::<{ laelaps::device::IMAGE }>(
                "laelaps left",
                laelaps::device::device(Side::Left),
            ),
        ),
        (
            "laelaps right",
            check_device::<{ laelaps::device::IMAGE }>(
                "laelaps right",
                laelaps::device::device(Side::Right),
            ),
        ),
        (
            "cia402",
            check_device::<{ cia402::device::IMAGE }>("cia402", &cia402::device::DEF),
        ),
        (
            "tue-es030",
            check_device::<{ tue_es030::device::IMAGE }>("tue-es030", &tue_es030::device::DEF),
        ),
        (
            "axis hub",
            check_device::<{ axis_hub::device::IMAGE }>("axis hub", &axis_hub::device::DEF),
        ),
        (
            "test device",
            check_device::<{ testkit::IMG }>("test device", &testkit::DEF),
        ),
    ];
    for (name, digest) in digests {
        println!("{name}: transcript digest {digest:016x}");
    }
}
