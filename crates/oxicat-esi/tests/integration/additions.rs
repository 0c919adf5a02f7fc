//! The thesis' 16-step change (section 6.7: record "Additions" 0x7030 with two INT16
//! outputs) is one line in `oxicat_devices::demo::additions`; here we check that ESI, SII,
//! object dictionary and process-data layout all contain it.

use oxicat_devices::demo;
use oxicat_esi::{esi, sii};
use oxicat_slave::Od;

/// Output bits as a master computes them from the OD (0x1C12 → 0x16xx → entry lengths).
fn output_bits<const N: usize>(od: &Od<N>) -> u32 {
    let n: u8 = od.get(0x1C12, 0).unwrap();
    let mut bits = 0;
    for k in 1..=n {
        let pdo: u16 = od.get(0x1C12, k).unwrap();
        let c: u8 = od.get(pdo, 0).unwrap();
        for j in 1..=c {
            let m: u32 = od.get(pdo, j).unwrap();
            bits += m & 0xFF;
        }
    }
    bits
}

#[test]
fn additions_0x7030_is_in_esi_sii_od_and_process_data() {
    let base = &demo::DEF;
    let add = &demo::additions::DEF;

    // ESI: data type, object, RxPDO, SM2 size 24 -> 28.
    let x = esi::generate(add).unwrap();
    assert!(x.contains("<Name>DT7030</Name>"));
    assert!(x.contains("<Index>#x7030</Index>"));
    assert!(x.contains("<Name>DT1603</Name>"));
    let m = esi::parse(&x).unwrap().remove(0);
    let p = m
        .rx_pdos
        .iter()
        .find(|p| p.index == 0x1603)
        .expect("RxPdo 0x1603");
    let names: Vec<_> = p.entries.iter().map(|e| e.name.clone().unwrap()).collect();
    assert_eq!(names, ["Out1", "Out2"]);
    assert!(p
        .entries
        .iter()
        .all(|e| e.bits == 16 && e.data_type == Some(0x0003)));
    assert_eq!(m.sms[2].default_size, Some(28));
    let o = m.objects.iter().find(|o| o.index == 0x7030).unwrap();
    assert_eq!(o.name, "Additions");
    assert_eq!(o.sub_names, ["SubIndex 000", "Out1", "Out2"]);
    let c12 = m.objects.iter().find(|o| o.index == 0x1C12).unwrap();
    assert_eq!(
        c12.bit_size, 80,
        "DT1C12 BitSize 80 with 4 PDOs, as thesis step 10"
    );

    // SII: RxPDO category and SM2 length.
    let s = sii::parse(&sii::generate(add).unwrap()).unwrap();
    let p = s
        .rx_pdos
        .iter()
        .find(|p| p.index == 0x1603)
        .expect("SII RxPDO 0x1603");
    assert_eq!(p.sm, Some(2));
    assert_eq!(
        p.entries
            .iter()
            .map(|e| (e.index, e.sub, e.bits))
            .collect::<Vec<_>>(),
        [(0x7030, 1, 16), (0x7030, 2, 16)]
    );
    assert_eq!(s.sms[2].default_size, Some(28));
    let s0 = sii::parse(&sii::generate(base).unwrap()).unwrap();
    assert_eq!(s0.sms[2].default_size, Some(24));
    assert!(!s0.rx_pdos.iter().any(|p| p.index == 0x1603));

    // OD (what the stack's SDO server and SDO information serve).
    let mut od = Od::<{ demo::additions::IMAGE }>::new(add).unwrap();
    let info = (0..od.object_count())
        .filter_map(|n| od.object_info(n))
        .find(|o| o.index == 0x7030)
        .expect("0x7030 in the OD");
    assert_eq!(info.name, "Additions");
    assert_eq!(info.entries[1].name, "Out1");
    assert!(info.entries[1].pdo.rx());
    od.set(0x7030, 2, -1234i16).unwrap();
    assert_eq!(od.get::<i16>(0x7030, 2), Ok(-1234));
    assert_eq!(od.get::<u16>(0x1C12, 4), Ok(0x1603));
    assert_eq!(od.get::<u32>(0x1603, 1), Ok(0x7030_0110));

    // Process data: the RxPDO image grows by 4 bytes (24 -> 28), inputs stay 22.
    let od0 = Od::<{ demo::IMAGE }>::new(base).unwrap();
    assert_eq!(output_bits(&od0), 24 * 8);
    assert_eq!(output_bits(&od), 28 * 8);
    assert_eq!(add.default_input_bits(), base.default_input_bits());
    assert!(
        Od::<{ demo::IMAGE }>::new(add).is_err(),
        "old image size is too small"
    );
}
