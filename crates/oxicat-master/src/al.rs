//! EtherCAT state machine states and the AL status codes of ETG.1000.6 (Table 11).

/// An ESM state as written to AL control (0x0120) and read from AL status (0x0130):
/// the slave stack's type, so master and slave agree on codes and names.
pub use oxicat_slave::AlState;

/// Parses `INIT`, `PREOP`, `PRE-OP`, `SAFEOP`, `OP`, `BOOT` (any case) into an [`AlState`].
pub fn parse_state(s: &str) -> Option<AlState> {
    Some(
        match s.to_ascii_uppercase().replace(['-', '_'], "").as_str() {
            "INIT" | "I" => AlState::Init,
            "PREOP" | "P" => AlState::PreOp,
            "BOOT" | "BOOTSTRAP" | "B" => AlState::Boot,
            "SAFEOP" | "S" => AlState::SafeOp,
            "OP" | "O" => AlState::Op,
            _ => return None,
        },
    )
}

/// The AL status register (0x0130) and code (0x0134) of one slave.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AlStatus {
    /// Raw 0x0130 low byte.
    pub raw: u8,
    /// AL status code (0x0134).
    pub code: u16,
}

impl AlStatus {
    /// The state, if the code is a valid one.
    pub fn state(&self) -> Option<AlState> {
        AlState::from_code(self.raw)
    }

    /// The error indication bit (0x0130 bit 4).
    pub fn error(&self) -> bool {
        self.raw & 0x10 != 0
    }
}

impl std::fmt::Display for AlStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.state() {
            Some(s) => write!(f, "{s}")?,
            None => write!(f, "state 0x{:x}", self.raw & 0x0F)?,
        }
        if self.error() {
            write!(f, " + ERROR")?;
        }
        if self.error() || self.code != 0 {
            write!(f, " (0x{:04X}: {})", self.code, al_status_text(self.code))?;
        }
        Ok(())
    }
}

/// The ETG.1000.6 Table 11 AL status codes: `(code, text)`.
pub const AL_STATUS_CODES: &[(u16, &str)] = &[
    (0x0000, "No error"),
    (0x0001, "Unspecified error"),
    (0x0002, "No memory"),
    (0x0003, "Invalid device setup"),
    (0x0005, "Reserved due to compatibility reasons"),
    (0x0011, "Invalid requested state change"),
    (0x0012, "Unknown requested state"),
    (0x0013, "Bootstrap not supported"),
    (0x0014, "No valid firmware"),
    (0x0015, "Invalid mailbox configuration (BOOT)"),
    (0x0016, "Invalid mailbox configuration (PREOP)"),
    (0x0017, "Invalid sync manager configuration"),
    (0x0018, "No valid inputs available"),
    (0x0019, "No valid outputs"),
    (0x001A, "Synchronization error"),
    (0x001B, "Sync manager watchdog"),
    (0x001C, "Invalid sync manager types"),
    (0x001D, "Invalid output configuration"),
    (0x001E, "Invalid input configuration"),
    (0x001F, "Invalid watchdog configuration"),
    (0x0020, "Slave needs cold start"),
    (0x0021, "Slave needs INIT"),
    (0x0022, "Slave needs PREOP"),
    (0x0023, "Slave needs SAFEOP"),
    (0x0024, "Invalid input mapping"),
    (0x0025, "Invalid output mapping"),
    (0x0026, "Inconsistent settings"),
    (0x0027, "Free run not supported"),
    (0x0028, "Sync mode not supported"),
    (0x0029, "Free run needs 3-buffer mode"),
    (0x002A, "Background watchdog"),
    (0x002B, "No valid inputs and outputs"),
    (0x002C, "Fatal sync error"),
    (0x002D, "No sync error"),
    (0x002E, "Cycle time too small"),
    (0x0030, "Invalid DC SYNC configuration"),
    (0x0031, "Invalid DC latch configuration"),
    (0x0032, "PLL error"),
    (0x0033, "DC sync IO error"),
    (0x0034, "DC sync timeout error"),
    (0x0035, "DC invalid sync cycle time"),
    (0x0036, "DC SYNC0 cycle time"),
    (0x0037, "DC SYNC1 cycle time"),
    (0x0041, "Mailbox AoE"),
    (0x0042, "Mailbox EoE"),
    (0x0043, "Mailbox CoE"),
    (0x0044, "Mailbox FoE"),
    (0x0045, "Mailbox SoE"),
    (0x004F, "Mailbox VoE"),
    (0x0050, "EEPROM no access"),
    (0x0051, "EEPROM error"),
    (0x0052, "External hardware not ready"),
    (0x0060, "Slave restarted locally"),
    (0x0061, "Device identification value updated"),
    (0x00F0, "Application controller available"),
];

/// The text of an AL status code (`vendor specific` for 0x8000..=0xFFFF).
pub fn al_status_text(code: u16) -> &'static str {
    match AL_STATUS_CODES.iter().find(|c| c.0 == code) {
        Some(c) => c.1,
        None if code >= 0x8000 => "vendor specific",
        None => "unknown AL status code",
    }
}
