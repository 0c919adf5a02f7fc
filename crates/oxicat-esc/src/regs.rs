//! Register addresses of the ESC register file (0x0000..0x0FFF) and the per-byte
//! access-permission table (which side may write which byte).

/// ESC type.
pub const TYPE: u16 = 0x0000;
/// ESC revision.
pub const REVISION: u16 = 0x0001;
/// ESC build.
pub const BUILD: u16 = 0x0002;
/// Number of FMMUs supported.
pub const FMMU_COUNT: u16 = 0x0004;
/// Number of SyncManagers supported.
pub const SM_COUNT: u16 = 0x0005;
/// Process RAM size in KiB.
pub const RAM_SIZE: u16 = 0x0006;
/// Port descriptor.
pub const PORT_DESC: u16 = 0x0007;
/// ESC features supported.
pub const FEATURES: u16 = 0x0008;
/// Configured station address.
pub const STATION_ADDR: u16 = 0x0010;
/// Configured station alias (PDI-writable, loaded from SII word 4).
pub const STATION_ALIAS: u16 = 0x0012;
/// Write register enable.
pub const WRITE_REG_ENABLE: u16 = 0x0020;
/// Write register protection.
pub const WRITE_REG_PROTECT: u16 = 0x0021;
/// ESC write enable.
pub const ESC_WRITE_ENABLE: u16 = 0x0030;
/// ESC write protection.
pub const ESC_WRITE_PROTECT: u16 = 0x0031;
/// ESC reset ECAT.
pub const ESC_RESET_ECAT: u16 = 0x0040;
/// ESC reset PDI.
pub const ESC_RESET_PDI: u16 = 0x0041;
/// DL control (32 bit): forwarding rule, loop control per port (0x0101), alias enable (bit 24).
pub const DL_CONTROL: u16 = 0x0100;
/// Loop control byte of DL control (2 bits per port).
pub const DL_LOOP_CONTROL: u16 = 0x0101;
/// Byte of DL control that holds the station-alias enable (bit 0).
pub const DL_ALIAS_ENABLE: u16 = 0x0103;
/// Physical read/write offset.
pub const PHYS_RW_OFFSET: u16 = 0x0108;
/// DL status.
pub const DL_STATUS: u16 = 0x0110;
/// AL control (ECAT writes the requested state).
pub const AL_CONTROL: u16 = 0x0120;
/// AL status (PDI writes the current state).
pub const AL_STATUS: u16 = 0x0130;
/// AL status code.
pub const AL_STATUS_CODE: u16 = 0x0134;
/// RUN LED override.
pub const RUN_LED_OVERRIDE: u16 = 0x0138;
/// ERR LED override.
pub const ERR_LED_OVERRIDE: u16 = 0x0139;
/// PDI control (PDI type, from SII word 0 low byte).
pub const PDI_CONTROL: u16 = 0x0140;
/// ESC configuration (device emulation bit 0, from SII word 0 high byte).
pub const ESC_CONFIG: u16 = 0x0141;
/// PDI information.
pub const PDI_INFO: u16 = 0x014E;
/// PDI configuration (SII word 1).
pub const PDI_CONFIG: u16 = 0x0150;
/// Extended PDI configuration (SII word 3).
pub const PDI_CONFIG_EXT: u16 = 0x0152;
/// ECAT event mask.
pub const ECAT_EVENT_MASK: u16 = 0x0200;
/// AL event mask (PDI writable).
pub const AL_EVENT_MASK: u16 = 0x0204;
/// ECAT event request (read only).
pub const ECAT_EVENT_REQ: u16 = 0x0210;
/// AL event request (read only).
pub const AL_EVENT_REQ: u16 = 0x0220;
/// RX error counters, 2 bytes per port (invalid frame, RX error).
pub const RX_ERROR_COUNTER: u16 = 0x0300;
/// Forwarded RX error counters, 1 byte per port.
pub const FWD_RX_ERROR_COUNTER: u16 = 0x0308;
/// ECAT processing unit error counter.
pub const EPU_ERROR_COUNTER: u16 = 0x030C;
/// PDI error counter.
pub const PDI_ERROR_COUNTER: u16 = 0x030D;
/// PDI error code.
pub const PDI_ERROR_CODE: u16 = 0x030E;
/// Lost link counters, 1 byte per port.
pub const LOST_LINK_COUNTER: u16 = 0x0310;
/// Watchdog divider.
pub const WD_DIVIDER: u16 = 0x0400;
/// PDI watchdog time.
pub const WD_TIME_PDI: u16 = 0x0410;
/// Process-data watchdog time.
pub const WD_TIME_PD: u16 = 0x0420;
/// Process-data watchdog status.
pub const WD_STATUS_PD: u16 = 0x0440;
/// Process-data watchdog counter.
pub const WD_COUNTER_PD: u16 = 0x0442;
/// PDI watchdog counter.
pub const WD_COUNTER_PDI: u16 = 0x0443;
/// SII EEPROM configuration (ECAT/PDI assignment).
pub const SII_CONFIG: u16 = 0x0500;
/// SII EEPROM PDI access state.
pub const SII_PDI_ACCESS: u16 = 0x0501;
/// SII EEPROM control/status.
pub const SII_CONTROL: u16 = 0x0502;
/// SII EEPROM word address.
pub const SII_ADDRESS: u16 = 0x0504;
/// SII EEPROM data (4 or 8 bytes).
pub const SII_DATA: u16 = 0x0508;
/// MII management control/status.
pub const MII_CONTROL: u16 = 0x0510;
/// First FMMU register (16 bytes each).
pub const FMMU_BASE: u16 = 0x0600;
/// First SyncManager register (8 bytes each).
pub const SM_BASE: u16 = 0x0800;
/// First DC register.
pub const DC_BASE: u16 = 0x0900;
/// DC: SYNC0 status.
pub const DC_SYNC0_STATUS: u16 = 0x098E;
/// DC: SYNC1 status.
pub const DC_SYNC1_STATUS: u16 = 0x098F;
/// DC: SYNC pulse length (SII word 2).
pub const DC_SYNC_PULSE_LEN: u16 = 0x0982;
/// Digital I/O output data.
pub const DIGITAL_OUT: u16 = 0x0F00;
/// General-purpose outputs.
pub const GP_OUT: u16 = 0x0F10;
/// General-purpose inputs.
pub const GP_IN: u16 = 0x0F18;
/// User RAM.
pub const USER_RAM: u16 = 0x0F80;
/// Start of process RAM (digital inputs are at 0x1000..0x1003).
pub const PROCESS_RAM: u16 = 0x1000;

/// Permission bit: ECAT may write this byte.
pub const P_ECAT: u8 = 1;
/// Permission bit: PDI may write this byte.
pub const P_PDI: u8 = 2;
/// Permission bit: any write (of any value) clears this byte (error counters).
pub const P_CLEAR: u8 = 4;
/// Permission bit: the byte is implemented (reads return memory; otherwise 0).
pub const P_IMPL: u8 = 8;

const fn set(t: &mut [u8; 4096], from: usize, to_incl: usize, p: u8) {
    let mut i = from;
    while i <= to_incl {
        t[i] = p | P_IMPL;
        i += 1;
    }
}

const fn build_table() -> [u8; 4096] {
    let mut t = [0u8; 4096];
    let e = P_ECAT;
    let p = P_PDI;
    set(&mut t, 0x0000, 0x000F, 0);
    set(&mut t, 0x0010, 0x0011, e);
    set(&mut t, 0x0012, 0x0013, p);
    set(&mut t, 0x0020, 0x0021, e);
    set(&mut t, 0x0030, 0x0031, e);
    set(&mut t, 0x0040, 0x0040, e);
    set(&mut t, 0x0041, 0x0041, p);
    set(&mut t, 0x0100, 0x0103, e);
    set(&mut t, 0x0108, 0x0109, e);
    set(&mut t, 0x0110, 0x0111, 0);
    set(&mut t, 0x0120, 0x0121, e);
    set(&mut t, 0x0130, 0x0131, p);
    set(&mut t, 0x0134, 0x0135, p);
    set(&mut t, 0x0138, 0x0139, e | p);
    set(&mut t, 0x0140, 0x0141, 0);
    set(&mut t, 0x014E, 0x014F, 0);
    set(&mut t, 0x0150, 0x0153, 0);
    set(&mut t, 0x0200, 0x0201, e);
    set(&mut t, 0x0204, 0x0207, p);
    set(&mut t, 0x0210, 0x0211, 0);
    set(&mut t, 0x0220, 0x0223, 0);
    set(&mut t, 0x0300, 0x030D, e | P_CLEAR);
    set(&mut t, 0x030E, 0x030E, 0);
    set(&mut t, 0x0310, 0x0313, e | P_CLEAR);
    set(&mut t, 0x0400, 0x0401, e);
    set(&mut t, 0x0410, 0x0411, e);
    set(&mut t, 0x0420, 0x0421, e);
    set(&mut t, 0x0440, 0x0441, 0);
    set(&mut t, 0x0442, 0x0443, e | P_CLEAR);
    // SII interface: ownership is checked by the SII unit itself.
    set(&mut t, 0x0500, 0x0500, e);
    set(&mut t, 0x0501, 0x0501, p);
    set(&mut t, 0x0502, 0x050F, e | p);
    set(&mut t, 0x0510, 0x0515, e);
    // FMMUs 0..15.
    let mut f = 0;
    while f < 16 {
        let b = 0x0600 + 16 * f;
        set(&mut t, b, b + 12, e);
        set(&mut t, b + 13, b + 15, 0);
        f += 1;
    }
    // SyncManagers 0..15: start, length, control by ECAT; status RO; activate ECAT;
    // PDI control by PDI.
    let mut s = 0;
    while s < 16 {
        let b = 0x0800 + 8 * s;
        set(&mut t, b, b + 4, e);
        set(&mut t, b + 5, b + 5, 0);
        set(&mut t, b + 6, b + 6, e);
        set(&mut t, b + 7, b + 7, p);
        s += 1;
    }
    // Distributed clocks (the DC unit reacts in after_write / before_read).
    set(&mut t, 0x0900, 0x0917, e);
    set(&mut t, 0x0918, 0x091F, 0);
    set(&mut t, 0x0920, 0x092B, e);
    set(&mut t, 0x092C, 0x092F, 0);
    set(&mut t, 0x0930, 0x0931, e);
    set(&mut t, 0x0932, 0x0933, 0);
    set(&mut t, 0x0934, 0x0936, e);
    // SYNC/latch unit: 0x0981, 0x0990.., 0x09A0..0x09A9 are written by the side that
    // cyclic unit control 0x0980 assigns (checked by the core).
    set(&mut t, 0x0980, 0x0980, e);
    set(&mut t, 0x0981, 0x0981, e | p);
    set(&mut t, 0x0982, 0x0984, 0);
    set(&mut t, 0x098E, 0x098F, 0);
    set(&mut t, 0x0990, 0x0997, e | p);
    set(&mut t, 0x0998, 0x099F, 0);
    set(&mut t, 0x09A0, 0x09A9, e | p);
    set(&mut t, 0x09AE, 0x09AF, 0);
    set(&mut t, 0x09B0, 0x09CF, 0);
    set(&mut t, 0x09F0, 0x09F3, 0);
    set(&mut t, 0x09F8, 0x09FF, 0);
    // Digital I/O, GP I/O, user RAM.
    set(&mut t, 0x0F00, 0x0F03, e);
    set(&mut t, 0x0F10, 0x0F17, e | p);
    set(&mut t, 0x0F18, 0x0F1F, p);
    set(&mut t, 0x0F80, 0x0FFF, e | p);
    t
}

/// Per-byte permissions of the register file (P_ECAT | P_PDI | P_CLEAR | P_IMPL).
pub static PERMISSIONS: [u8; 4096] = build_table();

/// Permissions of register byte `addr` (0 for addresses >= 0x1000).
#[inline]
pub fn permissions(addr: usize) -> u8 {
    PERMISSIONS.get(addr).copied().unwrap_or(0)
}
