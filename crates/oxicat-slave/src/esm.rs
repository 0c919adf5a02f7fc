//! EtherCAT state machine types: AL states and AL status codes.

/// An EtherCAT application-layer state (AL control / AL status bits 0..3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum AlState {
    /// INIT (1).
    Init,
    /// PRE-OPERATIONAL (2): mailbox running.
    PreOp,
    /// BOOTSTRAP (3): firmware update mailbox only.
    Boot,
    /// SAFE-OPERATIONAL (4): inputs running, outputs safe.
    SafeOp,
    /// OPERATIONAL (8).
    Op,
}

impl AlState {
    /// Decodes the 4-bit state code.
    pub const fn from_code(v: u8) -> Option<Self> {
        match v & 0x0F {
            1 => Some(Self::Init),
            2 => Some(Self::PreOp),
            3 => Some(Self::Boot),
            4 => Some(Self::SafeOp),
            8 => Some(Self::Op),
            _ => None,
        }
    }

    /// The 4-bit state code.
    pub const fn code(self) -> u8 {
        match self {
            Self::Init => 1,
            Self::PreOp => 2,
            Self::Boot => 3,
            Self::SafeOp => 4,
            Self::Op => 8,
        }
    }

    /// True when the mailbox runs in this state.
    pub const fn mailbox(self) -> bool {
        !matches!(self, Self::Init)
    }

    /// The IgH-style name (`INIT`, `PREOP`, `BOOT`, `SAFEOP`, `OP`).
    pub const fn name(self) -> &'static str {
        match self {
            Self::Init => "INIT",
            Self::PreOp => "PREOP",
            Self::Boot => "BOOT",
            Self::SafeOp => "SAFEOP",
            Self::Op => "OP",
        }
    }
}

impl core::fmt::Display for AlState {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// An AL status code (register 0x0134), ETG.1000.6 table 11.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AlStatusCode(pub u16);

impl AlStatusCode {
    /// No error.
    pub const NONE: Self = Self(0x0000);
    /// Unspecified error.
    pub const UNSPECIFIED: Self = Self(0x0001);
    /// Invalid requested state change.
    pub const INVALID_STATE_CHANGE: Self = Self(0x0011);
    /// Unknown requested state.
    pub const UNKNOWN_STATE: Self = Self(0x0012);
    /// Bootstrap not supported.
    pub const BOOT_NOT_SUPPORTED: Self = Self(0x0013);
    /// Invalid mailbox configuration (bootstrap).
    pub const INVALID_BOOT_MBX_CONFIG: Self = Self(0x0015);
    /// Invalid mailbox configuration.
    pub const INVALID_MBX_CONFIG: Self = Self(0x0016);
    /// Invalid sync manager configuration.
    pub const INVALID_SM_CONFIG: Self = Self(0x0017);
    /// Sync manager watchdog.
    pub const SM_WATCHDOG: Self = Self(0x001B);
    /// Invalid output configuration (SM2).
    pub const INVALID_OUTPUT_CONFIG: Self = Self(0x001D);
    /// Invalid input configuration (SM3).
    pub const INVALID_INPUT_CONFIG: Self = Self(0x001E);
    /// Invalid input mapping.
    pub const INVALID_INPUT_MAPPING: Self = Self(0x0024);
    /// Invalid output mapping.
    pub const INVALID_OUTPUT_MAPPING: Self = Self(0x0025);
    /// Free run not supported.
    pub const FREERUN_NOT_SUPPORTED: Self = Self(0x0027);
    /// Synchronisation not supported.
    pub const SYNC_NOT_SUPPORTED: Self = Self(0x0028);
    /// Cycle time too small.
    pub const CYCLE_TIME_TOO_SMALL: Self = Self(0x002E);
    /// Invalid DC SYNC configuration.
    pub const INVALID_DC_SYNC_CONFIG: Self = Self(0x0030);
}
