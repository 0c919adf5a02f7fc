//! SII EEPROM emulation: the EEPROM interface registers 0x0500..0x050F and loading of
//! the configuration area (words 0..7) into the register file.

use crate::regs;

pub use oxicat_wire::crc::sii_crc8 as crc8;
pub use oxicat_wire::regs::sii_control::{
    ACK_ERROR as CTL_ACK_ERROR, ADDR_2BYTES as CTL_ADDR_2BYTES, BUSY as CTL_BUSY,
    CMD_MASK as CTL_CMD_MASK, CMD_READ, CMD_RELOAD, CMD_WRITE, CRC_ERROR as CTL_CRC_ERROR,
    NOT_LOADED as CTL_NOT_LOADED, READ_8 as CTL_READ_8, WE_ERROR as CTL_WE_ERROR,
    WRITE_ENABLE as CTL_WRITE_ENABLE,
};

/// How long the EEPROM interface stays busy after a write command (ns): the I²C EEPROM's
/// internal write cycle t_WR, 5 ms maximum for the 24C-series parts ESCs are built with
/// (Microchip/Atmel AT24C256B datasheet, AC characteristics: "t_WR Write Cycle Time 5 ms";
/// the same figure for the 24C02/24C04 class). Beckhoff ESC datasheet section I, 11.2.1.1
/// "Missing Acknowledge": after a write the EEPROM chip is "internally busy transferring data
/// from input buffer to storage area" and "does not acknowledge any access until internal
/// transfer has finished (may take up to several ms)"; a command issued then ends with
/// 0x0502 bit 13 "Error Acknowledge/Command" (table 40: "Missing acknowledge from EEPROM
/// chip ... EEPROM chip is busy performing operations internally"). The model shows the
/// whole cycle as 0x0502 bit 15 (busy), so a master that waits for busy to clear before its
/// next command never sees the error; silicon may clear busy after the I²C transfer and
/// only then refuse the next command (the case 11.2.1.1 describes).
pub const WRITE_CYCLE_NS: u64 = 5_000_000;

/// Byte `i` of the EEPROM, 0xFF beyond its end (an erased EEPROM).
#[inline]
fn ee(eeprom: &[u8], i: usize) -> u8 {
    eeprom.get(i).copied().unwrap_or(0xFF)
}

/// True when the CRC of words 0..6 matches the low byte of word 7.
pub fn config_crc_ok(eeprom: &[u8]) -> bool {
    let mut b = [0u8; 14];
    for (i, x) in b.iter_mut().enumerate() {
        *x = ee(eeprom, i);
    }
    crc8(&b) == ee(eeprom, 14)
}

fn put(regs: &mut [u8], addr: u16, v: &[u8]) {
    let a = addr as usize;
    if let Some(d) = regs.get_mut(a..a + v.len()) {
        d.copy_from_slice(v);
    }
}

/// Loads the configuration area into the registers (PDI control, PDI configuration,
/// SYNC pulse length, extended PDI configuration, station alias) if its CRC is right.
/// Sets/clears the checksum-error and not-loaded bits of 0x0502. Returns true when loaded.
pub fn load_config(regs: &mut [u8], eeprom: &[u8]) -> bool {
    let ok = config_crc_ok(eeprom);
    let mut ctl = read_ctl(regs);
    if ok {
        put(regs, regs::PDI_CONTROL, &[ee(eeprom, 0), ee(eeprom, 1)]);
        put(regs, regs::PDI_CONFIG, &[ee(eeprom, 2), ee(eeprom, 3)]);
        put(
            regs,
            regs::DC_SYNC_PULSE_LEN,
            &[ee(eeprom, 4), ee(eeprom, 5)],
        );
        put(regs, regs::PDI_CONFIG_EXT, &[ee(eeprom, 6), ee(eeprom, 7)]);
        put(regs, regs::STATION_ALIAS, &[ee(eeprom, 8), ee(eeprom, 9)]);
        ctl &= !(CTL_CRC_ERROR | CTL_NOT_LOADED);
    } else {
        ctl |= CTL_CRC_ERROR | CTL_NOT_LOADED;
    }
    write_ctl(regs, ctl);
    ok
}

/// Current value of 0x0502.
pub fn read_ctl(regs: &[u8]) -> u16 {
    let a = regs::SII_CONTROL as usize;
    u16::from_le_bytes([regs[a], regs[a + 1]])
}

/// Stores `v` into 0x0502.
pub fn write_ctl(regs: &mut [u8], v: u16) {
    put(regs, regs::SII_CONTROL, &v.to_le_bytes());
}

/// True when the PDI owns the EEPROM interface (0x0500 bit 0 or 0x0501 bit 0).
pub fn pdi_owns(regs: &[u8]) -> bool {
    regs[regs::SII_CONFIG as usize] & 1 != 0 || regs[regs::SII_PDI_ACCESS as usize] & 1 != 0
}

/// What an SII command did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SiiOutcome {
    /// Nothing to do.
    None,
    /// A read completed.
    Read,
    /// A word was written.
    Written,
    /// The configuration area was reloaded (true when the CRC was right).
    Reloaded(bool),
    /// The command was refused (error bits set).
    Error,
}

/// A command written to 0x0502 (`written` = the value written) while a write cycle runs:
/// not executed. A read, write, reload or invalid command ends with bit 13 (the EEPROM does
/// not acknowledge, ESC datasheet section I table 40); writing 0 (no command) changes
/// nothing. 0x0502 keeps showing busy (bit 15) and the write command in bits 8..10
/// (section II, 0x0502 bits 8..10 read: "currently executed command").
pub fn refuse_while_busy(regs: &mut [u8], written: u16) {
    let mut ctl = read_ctl(regs) & !(CTL_CMD_MASK | CTL_WRITE_ENABLE);
    ctl |= CTL_BUSY | CMD_WRITE;
    if written & CTL_CMD_MASK != 0 {
        ctl |= CTL_ACK_ERROR;
    }
    write_ctl(regs, ctl);
}

/// Starts the write cycle of a word just written: busy (bit 15) with the write command
/// in bits 8..10 until [`end_write_cycle`].
pub fn begin_write_cycle(regs: &mut [u8]) {
    let ctl = read_ctl(regs) & !CTL_CMD_MASK;
    write_ctl(regs, ctl | CTL_BUSY | CMD_WRITE);
}

/// The write cycle is over: the interface is idle (bits 15 and 8..10 clear); error bits
/// set by commands refused meanwhile stay until the next command.
pub fn end_write_cycle(regs: &mut [u8]) {
    let ctl = read_ctl(regs) & !(CTL_CMD_MASK | CTL_BUSY);
    write_ctl(regs, ctl);
}

/// Executes the command just written to 0x0502 (`written` = the value written, `we` =
/// whether the write-enable bit was part of that write). Commands complete at once and
/// the busy bit reads 0 afterwards, except a write ([`SiiOutcome::Written`]), whose word is
/// stored at once but whose write cycle the caller runs ([`begin_write_cycle`],
/// [`WRITE_CYCLE_NS`]). Words at or above `writable_words` do not acknowledge a
/// write (a write-protected or worn part): the command ends with 0x0502 bit 13 set.
pub fn execute(
    regs: &mut [u8],
    eeprom: &mut [u8],
    written: u16,
    read8: bool,
    writable_words: usize,
) -> SiiOutcome {
    let cmd = written & CTL_CMD_MASK;
    let mut ctl = read_ctl(regs) & !(CTL_CMD_MASK | CTL_BUSY | CTL_WRITE_ENABLE);
    if cmd == 0 {
        // Writing 0 with no command clears the error bits (acknowledge).
        ctl &= !(CTL_ACK_ERROR | CTL_WE_ERROR);
        write_ctl(regs, ctl);
        return SiiOutcome::None;
    }
    ctl &= !(CTL_ACK_ERROR | CTL_WE_ERROR);
    let a = regs::SII_ADDRESS as usize;
    let word = u32::from_le_bytes([regs[a], regs[a + 1], regs[a + 2], regs[a + 3]]) as usize;
    let out = match cmd {
        CMD_READ => {
            if word * 2 >= eeprom.len() {
                ctl |= CTL_ACK_ERROR;
                SiiOutcome::Error
            } else {
                let n = if read8 { 8 } else { 4 };
                let mut d = [0u8; 8];
                for (i, x) in d.iter_mut().enumerate().take(n) {
                    *x = ee(eeprom, word * 2 + i);
                }
                put(regs, regs::SII_DATA, &d[..n]);
                SiiOutcome::Read
            }
        }
        CMD_WRITE => {
            if written & CTL_WRITE_ENABLE == 0 {
                ctl |= CTL_WE_ERROR;
                SiiOutcome::Error
            } else if word * 2 + 1 >= eeprom.len() || word >= writable_words {
                ctl |= CTL_ACK_ERROR;
                SiiOutcome::Error
            } else {
                let d = regs::SII_DATA as usize;
                eeprom[word * 2] = regs[d];
                eeprom[word * 2 + 1] = regs[d + 1];
                SiiOutcome::Written
            }
        }
        CMD_RELOAD => {
            write_ctl(regs, ctl);
            let ok = load_config(regs, eeprom);
            // After a reload the data register holds the first read chunk again.
            return SiiOutcome::Reloaded(ok);
        }
        _ => {
            ctl |= CTL_ACK_ERROR;
            SiiOutcome::Error
        }
    };
    write_ctl(regs, ctl);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_of_known_config_area() {
        // EK1100 config area from ETG examples: CRC over words 0..6.
        let area = [
            0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
        ];
        // CRC-8/0x07/0xFF over 14 zero bytes (reference value from a bitwise model).
        let mut crc: u8 = 0xFF;
        for _ in 0..14 {
            for _ in 0..8 {
                crc = if crc & 0x80 != 0 {
                    (crc << 1) ^ 7
                } else {
                    crc << 1
                };
            }
        }
        assert_eq!(crc8(&area), crc);
    }
}
