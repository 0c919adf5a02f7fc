//! EtherCAT over UDP (ETG.1000.4: UDP port 34980 = 0x88A4): each datagram carries one
//! EtherCAT frame (EtherCAT header + datagrams); it is walked through the segment and the
//! processed frame is sent back to the sender.

use std::io;
use std::net::{SocketAddr, ToSocketAddrs, UdpSocket};
use std::time::Duration;

use oxicat_wire::ethernet::{ETHERCAT_ETHERTYPE, ETHERNET_HEADER_LEN};
use oxicat_wire::frame::EcatHeader;
pub use oxicat_wire::udp::ETHERCAT_UDP_PORT;

use crate::net::{transient, NetError};
use crate::realtime::FramePort;

/// Source MAC of the Ethernet header put around UDP payloads inside the segment.
const INNER_SRC: [u8; 6] = [0x10, 0x10, 0x10, 0x10, 0x10, 0x10];

/// A UDP socket serving EtherCAT frames.
#[derive(Debug)]
pub struct UdpPort {
    socket: UdpSocket,
    local: SocketAddr,
    wait: Option<Duration>,
}

impl UdpPort {
    /// Binds `addr` (e.g. `0.0.0.0:34980`).
    pub fn bind(addr: &str) -> Result<Self, NetError> {
        let bind_err = |source| NetError::Bind {
            addr: addr.to_string(),
            source,
        };
        let addrs: Vec<SocketAddr> = addr.to_socket_addrs().map_err(bind_err)?.collect();
        let socket = UdpSocket::bind(&addrs[..]).map_err(bind_err)?;
        let local = socket.local_addr().map_err(bind_err)?;
        // `wait: None` below is non-blocking: make it so (a fresh socket blocks forever, and
        // a first `recv` without a wait would never return).
        socket.set_nonblocking(true).map_err(bind_err)?;
        Ok(Self {
            socket,
            local,
            wait: None,
        })
    }

    /// The bound address (with the port the system chose for port 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.local
    }
}

/// Whether `payload` starts with a plausible EtherCAT header whose length fits.
fn is_ecat_payload(payload: &[u8]) -> bool {
    EcatHeader::parse(payload).is_ok_and(|h| 2 + h.len as usize <= payload.len())
}

impl FramePort for UdpPort {
    type Peer = SocketAddr;

    fn recv(
        &mut self,
        buf: &mut Vec<u8>,
        timeout: Duration,
    ) -> Result<Option<SocketAddr>, NetError> {
        // A zero read timeout means "block forever" to the OS: use non-blocking instead.
        let want = (!timeout.is_zero()).then_some(timeout);
        if want != self.wait {
            let r = match want {
                Some(t) => self
                    .socket
                    .set_nonblocking(false)
                    .and_then(|()| self.socket.set_read_timeout(Some(t))),
                None => self.socket.set_nonblocking(true),
            };
            r.map_err(|source| NetError::Io {
                what: "configuring the UDP socket",
                source,
            })?;
            self.wait = want;
        }
        buf.clear();
        buf.resize(ETHERNET_HEADER_LEN + 2048, 0);
        match self.socket.recv_from(&mut buf[ETHERNET_HEADER_LEN..]) {
            Ok((n, from)) => {
                buf.truncate(ETHERNET_HEADER_LEN + n);
                if !is_ecat_payload(&buf[ETHERNET_HEADER_LEN..]) {
                    log::debug!("ignored a UDP datagram from {from}: not an EtherCAT frame");
                    return Ok(None);
                }
                buf[..6].fill(0xFF);
                buf[6..12].copy_from_slice(&INNER_SRC);
                buf[12..14].copy_from_slice(&ETHERCAT_ETHERTYPE.to_be_bytes());
                Ok(Some(from))
            }
            Err(e) if transient(&e) => Ok(None),
            // An ICMP "port unreachable" from an earlier reply surfaces here on Linux.
            Err(e) if e.kind() == io::ErrorKind::ConnectionRefused => Ok(None),
            Err(source) => Err(NetError::Io {
                what: "receiving on the UDP socket",
                source,
            }),
        }
    }

    fn send(&mut self, frame: &[u8], peer: &SocketAddr) -> Result<(), NetError> {
        let payload = frame.get(ETHERNET_HEADER_LEN..).unwrap_or_default();
        self.socket
            .send_to(payload, peer)
            .map(|_| ())
            .map_err(|source| NetError::Io {
                what: "sending on the UDP socket",
                source,
            })
    }

    fn describe(&self) -> String {
        format!("EtherCAT over UDP on {}", self.local)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn payload_check() {
        // 12 bytes of datagrams, type 1.
        let mut p = (12u16 | 0x1000).to_le_bytes().to_vec();
        assert!(!is_ecat_payload(&p), "length beyond the datagram");
        p.resize(14, 0);
        assert!(is_ecat_payload(&p));
        assert!(!is_ecat_payload(&[1]));
    }

    /// A first `recv` without a wait (`serve`'s spin mode) returns at once when nothing
    /// came in; it used to block until a frame arrived (the socket was left blocking while
    /// the port took it for non-blocking), so a spinning server with no master never saw
    /// its stop flag.
    #[test]
    fn a_first_recv_without_a_wait_does_not_block() {
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let mut p = UdpPort::bind("127.0.0.1:0").unwrap();
            let mut buf = Vec::new();
            let _ = tx.send(p.recv(&mut buf, Duration::ZERO).map(|r| r.is_none()));
        });
        let got = rx
            .recv_timeout(Duration::from_secs(30))
            .expect("recv returned (it blocked waiting for a frame)");
        assert!(got.expect("no error"), "nothing was sent");
    }

    #[test]
    fn bind_error_names_the_address() {
        let a = UdpPort::bind("127.0.0.1:0").unwrap();
        let taken = a.local_addr().to_string();
        match UdpPort::bind(&taken) {
            Err(e @ NetError::Bind { .. }) => assert!(e.to_string().contains(&taken)),
            other => panic!("unexpected: {other:?}"),
        }
    }
}
