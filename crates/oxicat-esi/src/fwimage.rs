//! Firmware images for the FoE update flow of `oxicat_slave::foe`: the 32-byte header
//! (magic, header version, vendor id, product code, revision, payload length, CRC-32 of the
//! payload; format in `oxicat_slave::foe`) in front of the payload.

use oxicat_slave::foe::{ImageError, ImageHeader, IMAGE_HEADER_LEN};
use oxicat_slave::DeviceDef;

/// The image of `payload` for the device `def` (its vendor id, product code and revision).
pub fn build(def: &DeviceDef, payload: &[u8]) -> Vec<u8> {
    let h = ImageHeader::for_payload(&def.identity, payload);
    let mut v = Vec::with_capacity(IMAGE_HEADER_LEN + payload.len());
    v.extend_from_slice(&h.to_bytes());
    v.extend_from_slice(payload);
    v
}

/// The header of `image` and whether its payload matches it (length and CRC-32).
pub fn inspect(image: &[u8]) -> Result<(ImageHeader, bool), ImageError> {
    let h = ImageHeader::parse(image)?;
    let p = &image[IMAGE_HEADER_LEN..];
    let ok = p.len() == h.length as usize && oxicat_slave::foe::crc32(p) == h.crc;
    Ok((h, ok))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn build_and_inspect() {
        let def = &oxicat_devices::demo::DEF;
        let img = build(def, b"firmware");
        let (h, ok) = inspect(&img).unwrap();
        assert!(ok);
        assert!(h.fits(&def.identity));
        assert_eq!(h.length, 8);
        let mut bad = img.clone();
        bad[IMAGE_HEADER_LEN] ^= 1;
        assert!(!inspect(&bad).unwrap().1);
    }
}
