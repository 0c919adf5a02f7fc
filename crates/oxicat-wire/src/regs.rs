//! The ESC register map (Beckhoff ESC datasheet section II, ETG.1000.4): addresses of the
//! register file 0x0000..0x0FFF, the SyncManager and FMMU blocks, the SII EEPROM interface
//! bits and the AL event request bits. One table for every side: the software ESC
//! (`oxicat-esc`), the slave stack and its chip drivers (`oxicat-slave`, `oxicat-pdi`) and
//! the master (`oxicat-master`).

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
pub const DC_BASE: u16 = dc::RECV_TIME_PORT0;
/// DC: SYNC0 status.
pub const DC_SYNC0_STATUS: u16 = dc::SYNC0_STATUS;
/// DC: SYNC1 status.
pub const DC_SYNC1_STATUS: u16 = dc::SYNC1_STATUS;
/// DC: SYNC pulse length (SII word 2).
pub const DC_SYNC_PULSE_LEN: u16 = dc::PULSE_LENGTH;
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

/// Bytes per SyncManager register block.
pub const SM_LEN: u16 = 8;
/// Bytes per FMMU register block.
pub const FMMU_LEN: u16 = 16;
/// DC receive time of port 0 (latched by a write to it).
pub const DC_RECV_TIME_PORT0: u16 = dc::RECV_TIME_PORT0;
/// DC system time.
pub const DC_SYSTEM_TIME: u16 = dc::SYSTEM_TIME;
/// DC system time offset.
pub const DC_SYSTEM_TIME_OFFSET: u16 = dc::SYSTEM_TIME_OFFSET;
/// DC system time delay.
pub const DC_SYSTEM_TIME_DELAY: u16 = dc::SYSTEM_TIME_DELAY;
/// DC cyclic unit control (0x0980) and activation (0x0981).
pub const DC_ACTIVATION: u16 = dc::CYCLIC_UNIT_CONTROL;
/// SYNC0 start time / next SYNC0 pulse (u64, ns).
pub const DC_START_TIME: u16 = dc::START_TIME;
/// SYNC0 cycle time (u32, ns).
pub const DC_SYNC0_CYCLE: u16 = dc::SYNC0_CYCLE;
/// SYNC1 cycle time (u32, ns).
pub const DC_SYNC1_CYCLE: u16 = dc::SYNC1_CYCLE;

/// The Distributed Clocks registers (0x0900..0x09FF).
pub mod dc {
    /// Receive time port 0 (32 bit); an ECAT write latches all port receive times.
    pub const RECV_TIME_PORT0: u16 = 0x0900;
    /// Receive time port 1 (32 bit).
    pub const RECV_TIME_PORT1: u16 = 0x0904;
    /// Receive time port 2 (32 bit).
    pub const RECV_TIME_PORT2: u16 = 0x0908;
    /// Receive time port 3 (32 bit).
    pub const RECV_TIME_PORT3: u16 = 0x090C;
    /// System time (64 bit); an ECAT write feeds the time-control loop.
    pub const SYSTEM_TIME: u16 = 0x0910;
    /// Receive time of the processing unit (64 bit).
    pub const RECV_TIME_EPU: u16 = 0x0918;
    /// System time offset (64 bit).
    pub const SYSTEM_TIME_OFFSET: u16 = 0x0920;
    /// System time delay (32 bit).
    pub const SYSTEM_TIME_DELAY: u16 = 0x0928;
    /// System time difference (32 bit, sign-magnitude).
    pub const SYSTEM_TIME_DIFF: u16 = 0x092C;
    /// Speed counter start (16 bit).
    pub const SPEED_COUNTER_START: u16 = 0x0930;
    /// Speed counter diff (16 bit, two's complement).
    pub const SPEED_COUNTER_DIFF: u16 = 0x0932;
    /// System time difference filter depth.
    pub const SYSTEM_TIME_DIFF_FILTER_DEPTH: u16 = 0x0934;
    /// Speed counter filter depth.
    pub const SPEED_COUNTER_FILTER_DEPTH: u16 = 0x0935;
    /// Cyclic unit control (0: ECAT, 1: PDI for SYNC unit / latch units).
    pub const CYCLIC_UNIT_CONTROL: u16 = 0x0980;
    /// Activation register.
    pub const ACTIVATION: u16 = 0x0981;
    /// Pulse length of SYNC signals in 10 ns (from the EEPROM).
    pub const PULSE_LENGTH: u16 = 0x0982;
    /// Activation status.
    pub const ACTIVATION_STATUS: u16 = 0x0984;
    /// SYNC0 status.
    pub const SYNC0_STATUS: u16 = 0x098E;
    /// SYNC1 status.
    pub const SYNC1_STATUS: u16 = 0x098F;
    /// Start time cyclic operation (write) / next SYNC0 pulse (read), 64 bit.
    pub const START_TIME: u16 = 0x0990;
    /// Next SYNC1 pulse (64 bit).
    pub const NEXT_SYNC1: u16 = 0x0998;
    /// SYNC0 cycle time (32 bit).
    pub const SYNC0_CYCLE: u16 = 0x09A0;
    /// SYNC1 cycle time (32 bit).
    pub const SYNC1_CYCLE: u16 = 0x09A4;
    /// Latch0 control.
    pub const LATCH0_CONTROL: u16 = 0x09A8;
    /// Latch1 control.
    pub const LATCH1_CONTROL: u16 = 0x09A9;
    /// Latch0 status.
    pub const LATCH0_STATUS: u16 = 0x09AE;
    /// Latch1 status.
    pub const LATCH1_STATUS: u16 = 0x09AF;
    /// Latch0 time positive edge (64 bit).
    pub const LATCH0_POS: u16 = 0x09B0;
    /// Latch0 time negative edge (64 bit).
    pub const LATCH0_NEG: u16 = 0x09B8;
    /// Latch1 time positive edge (64 bit).
    pub const LATCH1_POS: u16 = 0x09C0;
    /// Latch1 time negative edge (64 bit).
    pub const LATCH1_NEG: u16 = 0x09C8;
}

/// Address of register byte `off` of SyncManager `n` (0x0800 + 8·n + off): +0 start, +2
/// length, +4 control, +5 status, +6 activate, +7 PDI control.
pub const fn sm(n: u8, off: u16) -> u16 {
    SM_BASE + SM_LEN * n as u16 + off
}

/// Address of register byte `off` of FMMU `n` (0x0600 + 16·n + off): +0 logical start,
/// +4 length, +6/+7 start/stop bit, +8 physical start, +10 physical start bit, +11 type,
/// +12 activate.
pub const fn fmmu(n: u8, off: u16) -> u16 {
    FMMU_BASE + FMMU_LEN * n as u16 + off
}

/// AL event request bit 0: AL control written.
pub const EV_AL_CONTROL: u32 = 1 << 0;
/// AL event request bit 2: SYNC0.
pub const EV_SYNC0: u32 = 1 << 2;
/// AL event request bit 3: SYNC1.
pub const EV_SYNC1: u32 = 1 << 3;
/// AL event request bit 4: SM activation changed.
pub const EV_SM_CHANGE: u32 = 1 << 4;
/// AL event request bit 6: process-data watchdog expired.
pub const EV_WATCHDOG: u32 = 1 << 6;
/// ECAT event request (0x0210) bit 2: DL status changed.
pub const ECAT_EV_DL_STATUS: u16 = 1 << 2;
/// ECAT event request (0x0210) bit 3: AL status changed.
pub const ECAT_EV_AL_STATUS: u16 = 1 << 3;
/// AL event request bit 8 + n: SyncManager n.
pub const fn ev_sm(n: u8) -> u32 {
    1 << (8 + n as u32)
}

/// Bits of SII control/status 0x0502.
pub mod sii_control {
    /// Bit 0: ECAT write enable (must accompany the write command).
    pub const WRITE_ENABLE: u16 = 0x0001;
    /// Bit 6: 8-byte read support.
    pub const READ_8: u16 = 0x0040;
    /// Bit 7: two address bytes (EEPROM larger than 16 Kbit).
    pub const ADDR_2BYTES: u16 = 0x0080;
    /// Bits 8..10: command (read 1, write 2, reload 4).
    pub const CMD_MASK: u16 = 0x0700;
    /// Read command.
    pub const CMD_READ: u16 = 0x0100;
    /// Write command.
    pub const CMD_WRITE: u16 = 0x0200;
    /// Reload command.
    pub const CMD_RELOAD: u16 = 0x0400;
    /// Bit 11: checksum error in the configuration area.
    pub const CRC_ERROR: u16 = 0x0800;
    /// Bit 12: device information not loaded.
    pub const NOT_LOADED: u16 = 0x1000;
    /// Bit 13: missing acknowledge / invalid command.
    pub const ACK_ERROR: u16 = 0x2000;
    /// Bit 14: write command without write enable.
    pub const WE_ERROR: u16 = 0x4000;
    /// Bit 15: busy.
    pub const BUSY: u16 = 0x8000;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_are_where_the_datasheet_puts_them() {
        assert_eq!(sm(0, 0), 0x0800);
        assert_eq!(sm(2, 6), 0x0816);
        assert_eq!(sm(7, 7), 0x083F);
        assert_eq!(fmmu(0, 0), 0x0600);
        assert_eq!(fmmu(2, 12), 0x062C);
        assert_eq!(ev_sm(3), 0x0800);
    }
}
