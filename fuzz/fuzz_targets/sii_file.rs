//! SII EEPROM files a user hands the CLI (`sii-write`, `device check`, the replay bench):
//! binary images and Intel HEX text, through `oxicat_esi::sii::{parse_any, parse,
//! intel_hex}`. Nothing may panic; an image that decodes compares equal to itself, and an
//! Intel HEX file decodes to the image `parse` gets.
#![no_main]

use libfuzzer_sys::fuzz_target;
use oxicat_esi::sii;

fuzz_target!(|data: &[u8]| {
    let any = sii::parse_any(data);
    if let Ok(m) = &any {
        assert!(
            oxicat_esi::compare(m, m).is_empty(),
            "a model differs from itself"
        );
    }
    if data.first() == Some(&b':') {
        if let Ok(img) = sii::intel_hex(data) {
            assert_eq!(
                sii::parse(&img).ok(),
                any.ok(),
                "HEX and its image disagree"
            );
        }
    } else {
        assert_eq!(sii::parse(data).ok(), any.ok());
        let _ = sii::intel_hex(data);
    }
});
