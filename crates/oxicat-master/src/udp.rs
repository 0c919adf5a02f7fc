//! EtherCAT over UDP (ETG.1000.4: the EtherCAT frame, without its Ethernet header, as the
//! payload of a UDP datagram; port 34980 = 0x88A4): the transport of [`Link::Udp`](crate::Link)
//! for ethercrab's PDU loop, to reach a segment served with `oxicat sim --udp`.
//!
//! Two threads: one sends the frames ethercrab queues (woken by ethercrab's waker), one
//! hands the datagrams that come back to ethercrab with an Ethernet header put around them.
//! A reply can arrive before ethercrab has marked its frame as sent (it does so after the
//! send call returns, and refuses a reply to a frame not yet sent): one lock spans each send
//! and each hand-over, so a reply is handed over only after its frame's send completed.

use std::net::{SocketAddr, ToSocketAddrs, UdpSocket};
use std::sync::{Arc, Mutex};
use std::task::{Wake, Waker};
use std::thread::Thread;
use std::time::Duration;

use ethercrab::{PduRx, PduTx};

use crate::MasterError;

/// Ethernet header length.
const ETH: usize = 14;
/// Source MAC put on replies: not ethercrab's own (10:10:…), which it ignores as its echo.
const REPLY_SRC: [u8; 6] = [0x12, 0x10, 0x10, 0x10, 0x10, 0x10];

struct Unpark(Thread);
impl Wake for Unpark {
    fn wake(self: Arc<Self>) {
        self.0.unpark();
    }
}

/// Resolves `addr` (`host:port`) and connects a UDP socket to it.
pub(crate) fn connect(addr: &str) -> Result<UdpSocket, MasterError> {
    let err = |source| MasterError::Udp {
        addr: addr.to_string(),
        source,
    };
    let target: SocketAddr = addr
        .to_socket_addrs()
        .map_err(err)?
        .next()
        .ok_or_else(|| err(std::io::Error::other("the name resolves to no address")))?;
    let local = if target.is_ipv4() {
        "0.0.0.0:0"
    } else {
        "[::]:0"
    };
    let socket = UdpSocket::bind(local).map_err(err)?;
    socket.connect(target).map_err(err)?;
    socket
        .set_read_timeout(Some(Duration::from_millis(50)))
        .map_err(err)?;
    Ok(socket)
}

/// Starts the two threads that carry ethercrab's frames over `socket`.
pub(crate) fn spawn(
    socket: UdpSocket,
    mut tx: PduTx<'static>,
    mut rx: PduRx<'static>,
    addr: &str,
) -> Result<(), MasterError> {
    let err = |source| MasterError::Udp {
        addr: addr.to_string(),
        source,
    };
    let rsock = socket.try_clone().map_err(err)?;
    let order = Arc::new(Mutex::new(()));
    let rx_order = order.clone();
    std::thread::Builder::new()
        .name("oxicat-udp-tx".into())
        .spawn(move || {
            let waker = Waker::from(Arc::new(Unpark(std::thread::current())));
            loop {
                tx.replace_waker(&waker);
                if tx.should_exit() {
                    return;
                }
                while let Some(frame) = tx.next_sendable_frame() {
                    let _sending = order.lock().unwrap_or_else(|e| e.into_inner());
                    let r = frame.send_blocking(|bytes| {
                        // A lost datagram is a timeout for ethercrab, as a lost frame is.
                        if let Err(e) = socket.send(bytes.get(ETH..).unwrap_or_default()) {
                            log::debug!("EtherCAT over UDP: send failed: {e}");
                        }
                        Ok(bytes.len())
                    });
                    if let Err(e) = r {
                        log::warn!("EtherCAT over UDP: {e}");
                    }
                }
                std::thread::park_timeout(Duration::from_millis(20));
            }
        })
        .map_err(err)?;
    std::thread::Builder::new()
        .name("oxicat-udp-rx".into())
        .spawn(move || {
            let mut buf = vec![0u8; ETH + 2048];
            buf[..6].fill(0xFF);
            buf[6..12].copy_from_slice(&REPLY_SRC);
            buf[12..14].copy_from_slice(&0x88A4u16.to_be_bytes());
            loop {
                if rx.should_exit() {
                    return;
                }
                // Errors are timeouts, and ICMP "port unreachable" while nobody serves.
                if let Ok(n) = rsock.recv(&mut buf[ETH..]) {
                    let _sent = rx_order.lock().unwrap_or_else(|e| e.into_inner());
                    if let Err(e) = rx.receive_frame(&buf[..ETH + n]) {
                        log::debug!("EtherCAT over UDP: a datagram was not a reply: {e}");
                    }
                }
            }
        })
        .map_err(err)?;
    Ok(())
}
