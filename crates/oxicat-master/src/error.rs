//! The errors of the master functions, each with a message a user can act on.

use oxicat_wire::coe::SdoAbortCode;

use crate::value::ValueType;

/// Why a master function failed.
#[derive(Debug)]
pub enum MasterError {
    /// The network interface does not exist.
    NoInterface(String),
    /// Opening a raw socket was refused (no CAP_NET_RAW).
    NoPermission(String),
    /// Another I/O error on the interface.
    Io(String, std::io::Error),
    /// A UDP socket to a segment served with EtherCAT over UDP could not be opened.
    Udp {
        /// The address given (`host:port`).
        addr: String,
        /// The cause.
        source: std::io::Error,
    },
    /// Nothing answered on the segment.
    NoSlaves(String),
    /// No slave at that position.
    NoSuchSlave {
        /// Requested position.
        position: usize,
        /// Slaves found.
        count: usize,
    },
    /// A slave did not answer a datagram (working counter 0) or timed out.
    NotAnswering {
        /// Position of the slave.
        position: usize,
        /// What was asked.
        what: String,
    },
    /// An SDO transfer was aborted by the slave.
    SdoAbort {
        /// Position of the slave.
        position: usize,
        /// Index.
        index: u16,
        /// Subindex.
        sub: u8,
        /// The abort code.
        code: SdoAbortCode,
    },
    /// The slave has no CoE mailbox.
    NoCoe(usize),
    /// The mailbox exchange broke the protocol.
    Mailbox {
        /// Position of the slave.
        position: usize,
        /// What went wrong.
        what: String,
    },
    /// An FoE transfer was refused by the slave.
    Foe {
        /// Position of the slave.
        position: usize,
        /// The FoE error code (0x8000..).
        code: u32,
        /// Standard description and the slave's error text.
        text: String,
    },
    /// A value could not be parsed for its type.
    BadValue {
        /// The text given.
        value: String,
        /// The type it was parsed as.
        ty: ValueType,
        /// Why it was refused.
        why: String,
    },
    /// An unknown type name.
    UnknownType(String),
    /// A state change was refused or did not complete.
    StateChange {
        /// Position of the slave.
        position: usize,
        /// Requested state.
        requested: crate::al::AlState,
        /// The AL status seen.
        status: crate::al::AlStatus,
    },
    /// A slave supports neither free run nor SM-synchronous operation (0x1C32:04), which
    /// is all `states` can leave running without a master that cycles.
    SyncUnsupported {
        /// Position of the slave.
        position: usize,
        /// Its name (SII).
        name: String,
        /// 0x1C32:04 (sync modes supported).
        supported: u16,
    },
    /// A cyclic run asked for a sync mode a slave does not offer: its 0x1C32:04 (sync modes
    /// supported) lacks it, or (DC) its ESC has no SYNC0 unit. Nothing was changed.
    SyncModeUnsupported {
        /// Position of the slave.
        position: usize,
        /// Its name (SII).
        name: String,
        /// The mode asked for.
        mode: crate::cyclic::SyncMode,
        /// 0x1C32:04, `None` when the slave has no such object.
        supported: Option<u16>,
        /// Whether its ESC generates SYNC0 (the DC unit).
        esc_dc: bool,
    },
    /// The segment changed under a cyclic verb (slaves left OP, frames stopped coming back):
    /// another master, or a cable/power fault.
    Disturbed {
        /// Cycles run before.
        cycles: u64,
        /// What the master saw.
        what: String,
    },
    /// An SII image is for another device than the slave.
    SiiOtherDevice {
        /// Position of the slave.
        position: usize,
        /// Identity in the image (vendor, product, revision).
        image: (u32, u32, u32),
        /// Identity of the slave.
        slave: (u32, u32, u32),
    },
    /// The configuration area checksum of an SII image is wrong.
    SiiCrc {
        /// Stored CRC (word 7 low byte).
        stored: u8,
        /// CRC computed over words 0..6.
        computed: u8,
    },
    /// An SII image is not valid.
    SiiImage(String),
    /// The SII interface reported an error or the EEPROM is held by the PDI.
    SiiInterface {
        /// Position of the slave.
        position: usize,
        /// What happened.
        what: String,
    },
    /// A word read back after writing differs.
    SiiVerify {
        /// Position of the slave.
        position: usize,
        /// Word address.
        word: u16,
        /// Written value.
        wrote: u16,
        /// Value read back.
        read: u16,
    },
    /// A variable name matched nothing.
    UnknownVariable {
        /// The name.
        name: String,
        /// Some names that exist.
        known: Vec<String>,
    },
    /// A device name for an SII image is not known.
    UnknownDevice(String),
    /// Another ethercrab error.
    Ethercrab(String, ethercrab::error::Error),
    /// A bad argument.
    Usage(String),
    /// Writing an output file failed.
    Output(std::io::Error),
    /// Reading or writing a file failed (the path says which).
    File(std::path::PathBuf, std::io::Error),
}

impl MasterError {
    /// The FoE error code (0x8000..) of a transfer the slave refused ([`MasterError::Foe`]);
    /// `None` for any other error.
    pub fn foe_code(&self) -> Option<u32> {
        match self {
            MasterError::Foe { code, .. } => Some(*code),
            _ => None,
        }
    }
}

impl std::fmt::Display for MasterError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        use MasterError::*;
        match self {
            NoInterface(i) => write!(
                f,
                "network interface {i:?} does not exist (see `ip link`; for a virtual segment use --sim <devices>)"
            ),
            NoPermission(i) => write!(
                f,
                "no permission to open a raw socket on {i:?}: EtherCAT needs CAP_NET_RAW (run as root, or `sudo setcap cap_net_raw,cap_net_admin+ep $(which oxicat)`)"
            ),
            Io(i, e) => write!(f, "interface {i:?}: {e}"),
            Disturbed { cycles, what } => write!(
                f,
                "another master changed the segment (or a cable/power fault) after {cycles} cycles: {what}; stopped, the slaves are left as they are"
            ),
            SyncModeUnsupported {
                position,
                name,
                mode,
                supported,
                esc_dc,
            } => {
                let offers = match supported {
                    Some(s) => {
                        let mut m = Vec::new();
                        for (bit, what) in [
                            (0x0001, "free run"),
                            (0x0002, "SM-synchronous"),
                            (0x000C, "DC"),
                        ] {
                            if s & bit != 0 {
                                m.push(what);
                            }
                        }
                        format!("0x1C32:04 = 0x{s:04X}: {}", m.join(", "))
                    }
                    None => "no 0x1C32:04".to_string(),
                };
                let esc = if *esc_dc { "" } else { "; its ESC has no SYNC0 (DC unit)" };
                write!(
                    f,
                    "slave {position} ({name}) does not offer the sync mode {mode} ({offers}{esc}); \
                     choose a mode it offers; no slave was changed"
                )
            }
            SyncUnsupported {
                position,
                name,
                supported,
            } => write!(
                f,
                "slave {position} ({name}) runs only DC-synchronous (0x1C32:04 = 0x{supported:04X}: no free run, no SM-synchronous), \
                 which needs a master that keeps cycling: use `oxicat record` (DC SYNC0) or your \
                 cyclic master; no slave was changed"
            ),
            Udp { addr, source } => write!(
                f,
                "EtherCAT over UDP to {addr}: {source} (give host:port of `oxicat sim --udp`, e.g. 127.0.0.1:34980)"
            ),
            NoSlaves(w) => write!(
                f,
                "no slaves found on {w}: check the cable/link, that the slaves are powered, or that `oxicat sim` runs on the peer interface"
            ),
            NoSuchSlave { position, count } => write!(
                f,
                "no slave at position {position}: {count} slave(s) found (positions 0..{})",
                count.saturating_sub(1)
            ),
            NotAnswering { position, what } => {
                write!(f, "slave {position} is not answering ({what})")
            }
            SdoAbort {
                position,
                index,
                sub,
                code,
            } => write!(
                f,
                "SDO abort from slave {position} at 0x{index:04X}:{sub:02X}: 0x{:08X} {}",
                code.code(),
                code.text()
            ),
            NoCoe(p) => write!(f, "slave {p} has no CoE mailbox (SII mailbox protocols)"),
            Mailbox { position, what } => write!(f, "mailbox of slave {position}: {what}"),
            Foe {
                position,
                code,
                text,
            } => write!(f, "slave {position}: FoE error 0x{code:04X}: {text}"),
            BadValue { value, ty, why } => {
                write!(f, "value {value:?} is not valid for type {ty}: {why}")
            }
            UnknownType(t) => write!(
                f,
                "unknown type {t:?}; known: {}",
                crate::value::ValueType::NAMES
            ),
            StateChange {
                position,
                requested,
                status,
            } => write!(
                f,
                "slave {position} did not reach {requested}: AL status {status}"
            ),
            SiiOtherDevice {
                position,
                image,
                slave,
            } => write!(
                f,
                "the SII image is for another device (vendor 0x{:08X}, product 0x{:08X}, revision 0x{:08X}) than slave {position} (vendor 0x{:08X}, product 0x{:08X}, revision 0x{:08X}); use --force to write it anyway",
                image.0, image.1, image.2, slave.0, slave.1, slave.2
            ),
            SiiCrc { stored, computed } => write!(
                f,
                "SII image configuration area CRC is wrong: stored 0x{stored:02X}, computed 0x{computed:02X} over words 0..6"
            ),
            SiiImage(w) => write!(f, "SII image is not valid: {w}"),
            SiiInterface { position, what } => {
                write!(f, "SII interface of slave {position}: {what}")
            }
            SiiVerify {
                position,
                word,
                wrote,
                read,
            } => write!(
                f,
                "SII verify failed on slave {position} at word 0x{word:04X}: wrote 0x{wrote:04X}, read back 0x{read:04X}"
            ),
            UnknownVariable { name, known } => {
                write!(f, "no process data variable {name:?}")?;
                if !known.is_empty() {
                    let n = known.len().min(12);
                    write!(f, "; known: {}", known[..n].join(", "))?;
                    if known.len() > n {
                        write!(f, ", … ({} in all)", known.len())?;
                    }
                }
                Ok(())
            }
            UnknownDevice(n) => write!(f, "unknown device {n:?}"),
            Ethercrab(what, e) => write!(f, "{what}: {e}"),
            Usage(w) => f.write_str(w),
            Output(e) => write!(f, "writing the output failed: {e}"),
            File(p, e) => write!(f, "{}: {e}", p.display()),
        }
    }
}

impl std::error::Error for MasterError {}
