//! The checksums EtherCAT devices use, once, on the `crc` crate (bitwise, no lookup
//! tables: the firmware pays no flash for them, and they run at `const` time too):
//!
//! - [`sii_crc8`]: the SII configuration area's CRC-8 (ETG.2010: polynomial x⁸+x²+x+1,
//!   initial value 0xFF, no reflection) in word 7, which an ESC checks when it loads the
//!   area; the `crc` catalogue has no name for it.
//! - [`onewire_crc8`]: Dallas/Maxim CRC-8 (`CRC-8/MAXIM-DOW`) of 1-Wire ROM codes and
//!   DS18B20 scratchpads; 0 over data followed by its CRC.
//! - [`crc32`] / [`crc32_update`]: CRC-32 as IEEE 802.3 and zlib (`CRC-32/ISO-HDLC`), the
//!   FoE firmware image's checksum.

use crc::{Algorithm, Crc, NoTable, CRC_32_ISO_HDLC, CRC_8_MAXIM_DOW};

/// The SII configuration area's CRC-8 (ETG.2010).
pub const SII_CRC8: Algorithm<u8> = Algorithm {
    width: 8,
    poly: 0x07,
    init: 0xFF,
    refin: false,
    refout: false,
    xorout: 0x00,
    check: 0xFB,
    residue: 0x00,
};

const SII: Crc<u8, NoTable> = Crc::<u8, NoTable>::new(&SII_CRC8);
const ONEWIRE: Crc<u8, NoTable> = Crc::<u8, NoTable>::new(&CRC_8_MAXIM_DOW);
const CRC32: Crc<u32, NoTable> = Crc::<u32, NoTable>::new(&CRC_32_ISO_HDLC);

/// CRC-8 of the SII configuration area (words 0..6 → the low byte of word 7).
pub const fn sii_crc8(bytes: &[u8]) -> u8 {
    SII.checksum(bytes)
}

/// Dallas/Maxim CRC-8 (x⁸+x⁵+x⁴+1, reflected) of 1-Wire data.
pub const fn onewire_crc8(bytes: &[u8]) -> u8 {
    ONEWIRE.checksum(bytes)
}

/// CRC-32 of `data` (IEEE 802.3 / zlib).
pub const fn crc32(data: &[u8]) -> u32 {
    CRC32.checksum(data)
}

/// Incremental CRC-32: `crc32_update(crc32(a), b) == crc32(a ++ b)`, and
/// `crc32_update(0, a) == crc32(a)`.
pub const fn crc32_update(crc: u32, data: &[u8]) -> u32 {
    // The register continues from the finished value with the final XOR undone; the crate
    // takes an initial value in unreflected form and reflects it for this algorithm.
    let mut d = CRC32.digest_with_initial((!crc).reverse_bits());
    d.update(data);
    d.finalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn check_values_of_the_catalogue() {
        assert_eq!(sii_crc8(b"123456789"), 0xFB);
        assert_eq!(onewire_crc8(b"123456789"), 0xA1);
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    }

    #[test]
    fn crc32_continues_where_it_stopped() {
        let (a, b) = (b"oxicat firmware ".as_slice(), b"image".as_slice());
        let whole = [a, b].concat();
        assert_eq!(crc32_update(crc32(a), b), crc32(&whole));
        assert_eq!(crc32_update(0, &whole), crc32(&whole));
        assert_eq!(crc32_update(0, b""), 0);
    }

    #[test]
    fn onewire_crc_over_data_and_its_crc_is_zero() {
        // A DS18B20 ROM code: family 0x28, serial, CRC.
        let mut rom = [0x28, 0xFF, 0x4C, 0x2A, 0x91, 0x16, 0x04, 0];
        rom[7] = onewire_crc8(&rom[..7]);
        assert_eq!(onewire_crc8(&rom), 0);
    }
}
