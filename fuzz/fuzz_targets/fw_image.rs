//! Firmware images a user hands `foe-write` / `fw-image`: the 32-byte header
//! (`oxicat_slave::foe::ImageHeader`) and payload check of `oxicat_esi::fwimage`.
//! Nothing may panic; a header that parses writes back to the same 32 bytes, and an image
//! reported whole has exactly the payload length and CRC-32 its header states.
#![no_main]

use libfuzzer_sys::fuzz_target;
use oxicat_slave::foe::{crc32, ImageHeader, IMAGE_HEADER_LEN};

fuzz_target!(|data: &[u8]| {
    if let Ok(h) = ImageHeader::parse(data) {
        let bytes = h.to_bytes();
        assert_eq!(
            ImageHeader::parse(&bytes).ok(),
            Some(h),
            "header round trip"
        );
    }
    if let Ok((h, whole)) = oxicat_esi::fwimage::inspect(data) {
        let payload = &data[IMAGE_HEADER_LEN..];
        assert_eq!(
            whole,
            payload.len() == h.length as usize && crc32(payload) == h.crc,
            "payload check"
        );
    }
});
