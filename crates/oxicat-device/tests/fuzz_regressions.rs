//! Inputs the fuzz targets (`fuzz/`) found crashing, kept so the bugs stay fixed.

/// `sii_file` (issue 13 item 19): an Intel HEX line with a multi-byte UTF-8 character
/// panicked ("byte index is not a char boundary") instead of being refused.
#[test]
fn intel_hex_with_non_ascii_is_an_error() {
    // fuzz/artifacts/sii_file/crash-8b22d4a5912f7f5891def690a8da2c4bc1ac1ddb
    let input: &[u8] = b":fffffff\xc3\x8d:\x0b";
    let e = oxicat_device::sii::intel_hex(input).expect_err("not Intel HEX");
    assert!(e.to_string().contains("Intel HEX"), "{e}");
    assert!(oxicat_device::sii::parse_any(input).is_err());
}
