//! Static configuration of one ESC: what the chip is (ESC information registers
//! 0x0000..0x000B) and how its oscillator behaves.

use crate::dc::ClockConfig;

/// How much of the Distributed Clocks unit a chip implements. Registers of a missing part
/// read as 0 and are not counted in the working counter (they do not exist in the chip).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DcSupport {
    /// No DC registers at all (0x0900..0x09FF unimplemented).
    None,
    /// Only the port receive times 0x0900..0x090F (propagation-delay measurement); no
    /// system time, no ECAT receive time, no SYNC/latch unit. The ET1200 of the Beckhoff
    /// EL1004/EL2828/EL3004 behaves so in the reference captures (BWR 0x0910/0x0920/0x0981
    /// and FPRD 0x0918 not counted by it, BWR 0x0900 counted).
    ReceiveTimesOnly,
    /// The complete DC unit (receive times, system time, SYNC0/1, latch).
    Full,
}

/// The chip an ESC emulates: contents of the ESC information registers and sizes.
#[derive(Debug, Clone, PartialEq)]
pub struct EscConfig {
    /// ESC type, register 0x0000 (ET1100 = 0x11, ET1200 = 0x12, LAN9252 = 0xC0).
    pub esc_type: u8,
    /// ESC revision, register 0x0001.
    pub revision: u8,
    /// ESC build, register 0x0002..0x0003.
    pub build: u16,
    /// Number of FMMUs, register 0x0004 (1..=16).
    pub fmmu_count: u8,
    /// Number of SyncManagers, register 0x0005 (1..=16).
    pub sm_count: u8,
    /// Process RAM size in KiB, register 0x0006 (process RAM starts at 0x1000).
    pub ram_kib: u8,
    /// Port descriptor, register 0x0007: 2 bits per port (00 n/a, 01 n/c, 10 EBUS, 11 MII).
    pub port_descriptor: u8,
    /// ESC features supported, register 0x0008..0x0009.
    pub features: u16,
    /// SII EEPROM read size: 8 bytes (true) or 4 bytes (false); 0x0502 bit 6.
    pub sii_read_8_bytes: bool,
    /// Which parts of the DC unit exist (registers of missing parts are unimplemented).
    pub dc: DcSupport,
    /// Reserved bits of SII control 0x0502 (low byte) that this chip reads as 1. The ET1200
    /// of EL1004/EL2828/EL3004 reads bit 4 set (0x50 with 8-byte reads) in every capture.
    pub sii_control_extra: u8,
    /// Oscillator of the DC unit.
    pub clock: ClockConfig,
}

impl EscConfig {
    /// Beckhoff ET1100: 8 FMMUs, 8 SMs, 8 KiB process RAM, ports 0/1 MII, 8-byte SII reads.
    pub fn et1100() -> Self {
        Self {
            esc_type: 0x11,
            revision: 0x00,
            build: 0x0003,
            fmmu_count: 8,
            sm_count: 8,
            ram_kib: 8,
            port_descriptor: 0x0F,
            features: 0x01FC,
            sii_read_8_bytes: true,
            dc: DcSupport::Full,
            sii_control_extra: 0,
            clock: ClockConfig::default(),
        }
    }

    /// Beckhoff ET1200: 3 FMMUs, 4 SMs, 1 KiB process RAM, ports 0/1 EBUS, 4-byte SII reads.
    pub fn et1200() -> Self {
        Self {
            esc_type: 0x12,
            revision: 0x00,
            build: 0x0001,
            fmmu_count: 3,
            sm_count: 4,
            ram_kib: 1,
            port_descriptor: 0x0A,
            features: 0x01FC,
            sii_read_8_bytes: false,
            dc: DcSupport::Full,
            sii_control_extra: 0,
            clock: ClockConfig::default(),
        }
    }

    /// Microchip LAN9252: 3 FMMUs, 4 SMs, 4 KiB process RAM, ports 0/1 MII, 8-byte SII reads.
    pub fn lan9252() -> Self {
        Self {
            esc_type: 0xC0,
            revision: 0x01,
            build: 0x0001,
            fmmu_count: 3,
            sm_count: 4,
            ram_kib: 4,
            port_descriptor: 0x0F,
            features: 0x01CC,
            sii_read_8_bytes: true,
            dc: DcSupport::Full,
            sii_control_extra: 0,
            clock: ClockConfig::default(),
        }
    }

    /// End of implemented memory (0x1000 + process RAM size), exclusive.
    pub fn memory_end(&self) -> usize {
        0x1000 + self.ram_kib as usize * 1024
    }

    /// Port type of `port` from the port descriptor (0 n/a, 1 n/c, 2 EBUS, 3 MII).
    pub fn port_type(&self, port: u8) -> u8 {
        if port > 3 {
            return 0;
        }
        (self.port_descriptor >> (2 * port)) & 3
    }

    /// True when `port` exists and is configured (EBUS or MII).
    pub fn port_present(&self, port: u8) -> bool {
        self.port_type(port) >= 2
    }
}

impl Default for EscConfig {
    fn default() -> Self {
        Self::et1100()
    }
}
