//! Transports that put a [`Segment`](crate::segment::Segment) on a real network: raw
//! Ethernet on an interface ([`raw`], EtherType 0x88A4), the same through an AF_XDP socket
//! ([`xdp`], Linux) and EtherCAT over UDP ([`udp`], port 34980). All implement
//! [`FramePort`](crate::realtime::FramePort) and are served in real time by
//! [`realtime::serve`](crate::realtime::serve).

use std::fmt;
use std::io;

#[cfg(unix)]
pub mod raw;
pub mod udp;
#[cfg(target_os = "linux")]
pub mod xdp;

/// Why a network transport could not start or stopped.
#[derive(Debug)]
pub enum NetError {
    /// No interface of that name.
    NoSuchInterface {
        /// The name asked for.
        name: String,
        /// Interfaces that exist.
        available: Vec<String>,
    },
    /// The interface exists but is down.
    InterfaceDown(String),
    /// Opening a raw socket was refused: the process lacks CAP_NET_RAW.
    NoPermission {
        /// The interface.
        iface: String,
    },
    /// The interface is not an Ethernet-like (layer 2) interface.
    NotEthernet(String),
    /// A UDP address could not be bound.
    Bind {
        /// The address.
        addr: String,
        /// The cause.
        source: io::Error,
    },
    /// The kernel refused a step of setting up AF_XDP on the interface (`--xdp`).
    #[cfg(target_os = "linux")]
    Xdp {
        /// The interface.
        iface: String,
        /// The step and what the kernel said.
        error: oxicat_xdp::XdpError,
    },
    /// Receiving or sending failed.
    Io {
        /// What was being done.
        what: &'static str,
        /// The cause.
        source: io::Error,
    },
}

impl fmt::Display for NetError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NoSuchInterface { name, available } => {
                write!(f, "no network interface {name:?}")?;
                if available.is_empty() {
                    write!(f, " (no interfaces found)")
                } else {
                    write!(f, "; interfaces here: {}", available.join(", "))
                }
            }
            Self::InterfaceDown(n) => {
                write!(
                    f,
                    "interface {n:?} is down; bring it up with `ip link set {n} up`"
                )
            }
            Self::NoPermission { iface } => write!(
                f,
                "no permission to open a raw socket on {iface:?}: needs CAP_NET_RAW (run as root, \
                 or `sudo setcap cap_net_raw,cap_net_admin+ep <binary>`)"
            ),
            Self::NotEthernet(n) => write!(f, "interface {n:?} does not carry Ethernet frames"),
            Self::Bind { addr, source } => write!(f, "cannot bind UDP address {addr}: {source}"),
            #[cfg(target_os = "linux")]
            Self::Xdp { iface, error } => write!(
                f,
                "AF_XDP on {iface:?}: {error}. Serve with the raw socket instead: `--iface \
                 {iface}` without --xdp"
            ),
            Self::Io { what, source } => write!(f, "{what} failed: {source}"),
        }
    }
}

impl std::error::Error for NetError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Bind { source, .. } | Self::Io { source, .. } => Some(source),
            #[cfg(target_os = "linux")]
            Self::Xdp { error, .. } => Some(error),
            _ => None,
        }
    }
}

/// Whether an I/O error is transient for a frame loop (retry rather than stop).
pub(crate) fn transient(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::Interrupted | io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
    ) || matches!(e.raw_os_error(), Some(105)) // ENOBUFS: the queue was full, the frame is lost
}
