//! Issue 13 item 16: the Rust structs `oxicat cstruct --rust` generates compile with
//! ethercrab's wire derive and lay their fields where the PDO mapping puts them.
//!
//! `generated/` holds the generator's output for the live mapping of a demo node and for the
//! cia402-joint definition; the first test checks they are exactly what `oxicat` prints
//! today (regenerate with the commands in its message), the others compile them here and
//! pack and unpack process data with them.

use ethercrab_wire::{EtherCrabWireRead, EtherCrabWireSized, EtherCrabWireWrite};

mod bin_common;

mod demo {
    include!("generated/demo_live.rs");
}
mod cia402 {
    include!("generated/cia402_joint.rs");
}

#[test]
fn the_compiled_structs_are_what_oxicat_generates() {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/generated");
    for (args, file) in [
        (
            &["cstruct", "--rust", "--sim", "demo:1"][..],
            "demo_live.rs",
        ),
        (
            &["cstruct", "--rust", "--device", "cia402-joint"][..],
            "cia402_joint.rs",
        ),
    ] {
        let (ok, out, err) = bin_common::oxicat_in(None, args);
        assert!(ok, "{err}");
        let kept = std::fs::read_to_string(format!("{dir}/{file}")).expect("generated file");
        assert!(
            out == kept,
            "tests/generated/{file} is not what `oxicat {}` prints now; regenerate it with \
             `oxicat {} > crates/oxicat/tests/generated/{file}`",
            args.join(" "),
            args.join(" ")
        );
    }
}

#[test]
fn demo_structs_read_the_live_process_image() {
    // `data` prints the image: the outputs (SM2), then the inputs (SM3).
    let (ok, out, err) = bin_common::oxicat_in(None, &["data", "--sim", "demo:1"]);
    assert!(ok, "{err}");
    let bytes: Vec<u8> = out
        .lines()
        .filter_map(|l| l.split_once(": "))
        .flat_map(|(_, hex)| hex.split_whitespace())
        .map(|b| u8::from_str_radix(b, 16).expect("hex byte"))
        .collect();
    let o = demo::Slave0Outputs::PACKED_LEN;
    let i = demo::Slave0Inputs::PACKED_LEN;
    assert_eq!(bytes.len(), o + i, "{out}");
    let inputs = demo::Slave0Inputs::unpack_from_slice(&bytes[o..]).expect("unpack");
    // InINT32Var4 (0x6030:02) carries node 0's buttons, 0xA0 on the virtual board, and the
    // echoed Sync byte (0 here) above them.
    assert_eq!(inputs.in_int32_var4, 0xA0, "{inputs:?}");
    // Packing what was unpacked gives the same bytes back.
    let mut again = vec![0u8; i];
    inputs.pack_to_slice(&mut again).expect("pack");
    assert_eq!(again, bytes[o..]);
}

#[test]
fn demo_outputs_pack_where_the_mapping_puts_them() {
    let out = demo::Slave0Outputs {
        blue_led: true,
        sync: -2,
        out_int32_var1: 0x1122_3344,
        out_int16_var6: -1,
        ..Default::default()
    };
    let mut b = vec![0u8; demo::Slave0Outputs::PACKED_LEN];
    out.pack_to_slice(&mut b).expect("pack");
    // 0x7000:01..08 are bits 0..7 of byte 0 (Blue_LED is :05), :09 is byte 1, then
    // 0x7010:01 (INT32) from byte 2; 0x7020:06 is the last two bytes.
    assert_eq!(b[0], 0x10);
    assert_eq!(b[1], 0xFE);
    assert_eq!(&b[2..6], &[0x44, 0x33, 0x22, 0x11]);
    assert_eq!(&b[b.len() - 2..], &[0xFF, 0xFF]);
    assert_eq!(
        demo::Slave0Outputs::unpack_from_slice(&b).expect("unpack"),
        out
    );
}

#[test]
fn cia402_structs_put_the_controlword_first() {
    let out = cia402::Cia402JointOutputs {
        controlword: 0x000F,
        modes_of_operation: 8,
        target_position: -1,
        ..Default::default()
    };
    let mut b = vec![0u8; cia402::Cia402JointOutputs::PACKED_LEN];
    out.pack_to_slice(&mut b).expect("pack");
    assert_eq!(b.len(), 13);
    assert_eq!(&b[..7], &[0x0F, 0x00, 0x08, 0xFF, 0xFF, 0xFF, 0xFF]);
    let inputs = cia402::Cia402JointInputs::unpack_from_slice(&[
        0x37, 0x06, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
    ])
    .expect("unpack");
    assert_eq!(inputs.statusword, 0x0637);
}
