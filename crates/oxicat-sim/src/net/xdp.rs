//! Raw Ethernet through an AF_XDP socket (Linux): the segment served as by [`raw`](super::raw),
//! but frames reach it through an XDP program that steers EtherCAT frames (EtherType 0x88A4,
//! also 802.1Q-tagged) of the interface's queue 0 into a UMEM ring, past the kernel's stack;
//! every other frame passes on to the stack, so the interface keeps working for other
//! traffic. The socket, the program and their `unsafe` code live in `oxicat-xdp`; this module
//! is safe code.
//!
//! No echo guard is needed (unlike [`RawPort`](super::raw::RawPort)): the program runs on
//! the interface's receive path only, and what the socket sends leaves through the
//! interface's transmit path, so the port never sees its own frames.
//!
//! The program is attached as a BPF link: it is detached when the port is dropped and, the
//! link being a file descriptor, when the process ends however it ends.
//!
//! While it serves, the EtherCAT frames it takes are not seen by packet sockets on the
//! interface (`tcpdump` on the served end shows other traffic only); capture on the master's
//! end instead. Multi-queue NICs: the socket binds queue 0, where NICs put frames without an
//! IP header (RSS hashes IP); EtherCAT frames arriving on another queue pass to the stack.
//!
//! 802.1Q: where the driver strips VLAN tags into the packet's metadata (veth does, as most
//! NICs with `rxvlan` on), the program sees a plain 0x88A4 frame and the reply leaves
//! untagged, as with the raw socket; the program's tagged branch serves drivers that leave
//! the tag in the frame.

use std::time::{Duration, Instant};

pub use oxicat_xdp::Mode;
use oxicat_xdp::{Config, XdpSocket};

use crate::net::raw::{find, is_ethercat};
use crate::net::{transient, NetError};
use crate::realtime::FramePort;

/// An AF_XDP port on queue 0 of one interface.
#[derive(Debug)]
pub struct XdpPort {
    name: String,
    socket: XdpSocket,
}

impl XdpPort {
    /// Opens interface `name` with the XDP program attached in `mode`.
    pub fn open(name: &str, mode: Mode) -> Result<Self, NetError> {
        let iface = find(name)?;
        if !iface.is_up() {
            return Err(NetError::InterfaceDown(name.to_string()));
        }
        let config = Config {
            mode,
            ..Config::default()
        };
        let socket = XdpSocket::open(name, &config).map_err(|error| NetError::Xdp {
            iface: name.to_string(),
            error,
        })?;
        Ok(Self {
            name: name.to_string(),
            socket,
        })
    }

    /// The interface name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The mode the program runs in (native or generic; zero-copy if asked).
    pub fn mode(&self) -> Mode {
        self.socket.mode()
    }
}

fn io(what: &'static str) -> impl FnOnce(std::io::Error) -> NetError {
    move |source| NetError::Io { what, source }
}

impl FramePort for XdpPort {
    type Peer = ();

    fn recv(&mut self, buf: &mut Vec<u8>, timeout: Duration) -> Result<Option<()>, NetError> {
        let deadline = Instant::now() + timeout;
        loop {
            match self.socket.try_recv(buf) {
                // The program steers EtherCAT frames only; the check costs nothing.
                Ok(true) if is_ethercat(buf) => return Ok(Some(())),
                Ok(true) => continue,
                Ok(false) => {}
                Err(e) if transient(&e) => {}
                Err(e) => return Err(io("receiving on the AF_XDP socket")(e)),
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(None);
            }
            match self.socket.wait(left) {
                Ok(_) => {}
                Err(e) if transient(&e) => {}
                Err(e) => return Err(io("waiting on the AF_XDP socket")(e)),
            }
        }
    }

    fn send(&mut self, frame: &[u8], _peer: &()) -> Result<(), NetError> {
        self.socket
            .send(frame)
            .map_err(io("sending on the AF_XDP socket"))
    }

    fn describe(&self) -> String {
        format!(
            "AF_XDP on {} queue {} ({})",
            self.name,
            self.socket.queue(),
            self.socket.mode()
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_interface_is_named() {
        match XdpPort::open("oxicat-nope0", Mode::Auto) {
            Err(NetError::NoSuchInterface { name, .. }) => assert_eq!(name, "oxicat-nope0"),
            other => panic!("unexpected: {other:?}"),
        }
    }

    #[test]
    fn refusals_name_the_step_and_the_raw_socket() {
        let e = NetError::Xdp {
            iface: "veth1".into(),
            error: oxicat_xdp::XdpError {
                step: oxicat_xdp::Step::Attach,
                source: std::io::Error::from_raw_os_error(16),
                detail: "veth1, native XDP, copy mode".into(),
            },
        };
        let m = e.to_string();
        assert!(m.contains("BPF_LINK_CREATE"), "{m}");
        assert!(m.contains("another XDP program"), "{m}");
        assert!(m.contains("--iface veth1"), "{m}");
    }
}
