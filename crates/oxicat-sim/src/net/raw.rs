//! Raw Ethernet on an interface: EtherCAT frames (EtherType 0x88A4, also 802.1Q-tagged)
//! received on the interface are walked through the segment and sent back out of the same
//! interface, as the last slave of a line would return them. Uses `pnet_datalink`'s
//! AF_PACKET channel (promiscuous), so this module has no `unsafe` of its own.
//!
//! Frames the segment sent itself are not taken as new frames: Linux does not loop a
//! packet socket's own transmissions back to it, and as a second guard the port remembers
//! the last frames it sent and drops an identical frame seen right after.

use std::collections::VecDeque;
use std::io;
use std::time::{Duration, Instant};

use pnet_datalink::{Channel, DataLinkReceiver, DataLinkSender, NetworkInterface};

use crate::net::{transient, NetError};
use crate::realtime::FramePort;

const ETHERCAT: [u8; 2] = [0x88, 0xA4];
const VLAN: [u8; 2] = [0x81, 0x00];
/// Frames remembered for the echo guard.
const ECHO_MEMORY: usize = 32;
/// How long a sent frame may take to show up as an echo.
const ECHO_WINDOW: Duration = Duration::from_millis(20);

/// The names of the interfaces of this host (network namespace).
pub fn interface_names() -> Vec<String> {
    pnet_datalink::interfaces()
        .into_iter()
        .map(|i| i.name)
        .collect()
}

/// A raw Ethernet port on one interface.
pub struct RawPort {
    name: String,
    tx: Box<dyn DataLinkSender>,
    rx: Box<dyn DataLinkReceiver>,
    /// The wait the receiver was opened with (pnet fixes it per channel).
    wait: Duration,
    sent: VecDeque<(u64, Instant)>,
}

impl core::fmt::Debug for RawPort {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("RawPort")
            .field("iface", &self.name)
            .finish()
    }
}

pub(crate) fn find(name: &str) -> Result<NetworkInterface, NetError> {
    let all = pnet_datalink::interfaces();
    match all.iter().find(|i| i.name == name) {
        Some(i) => Ok(i.clone()),
        None => Err(NetError::NoSuchInterface {
            name: name.to_string(),
            available: all.into_iter().map(|i| i.name).collect(),
        }),
    }
}

fn hash(frame: &[u8]) -> u64 {
    // FNV-1a: enough to recognise a frame we just sent.
    frame.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x0100_0000_01b3)
    })
}

pub(crate) fn is_ethercat(frame: &[u8]) -> bool {
    match frame.get(12..14) {
        Some(t) if t == ETHERCAT => true,
        Some(t) if t == VLAN => frame.get(16..18) == Some(&ETHERCAT[..]),
        _ => false,
    }
}

impl RawPort {
    /// Opens interface `name`; the receiver waits at most `wait` for a frame (pnet counts
    /// in whole milliseconds; below 1 ms it polls without sleeping).
    pub fn open(name: &str, wait: Duration) -> Result<Self, NetError> {
        let iface = find(name)?;
        if !iface.is_up() {
            return Err(NetError::InterfaceDown(name.to_string()));
        }
        let config = pnet_datalink::Config {
            read_timeout: Some(wait),
            write_buffer_size: 4096,
            read_buffer_size: 4096,
            promiscuous: true,
            ..Default::default()
        };
        let (tx, rx) = match pnet_datalink::channel(&iface, config) {
            Ok(Channel::Ethernet(tx, rx)) => (tx, rx),
            Ok(_) => return Err(NetError::NotEthernet(name.to_string())),
            Err(e) if e.kind() == io::ErrorKind::PermissionDenied => {
                return Err(NetError::NoPermission {
                    iface: name.to_string(),
                })
            }
            Err(e) => {
                return Err(NetError::Io {
                    what: "opening a raw socket",
                    source: e,
                })
            }
        };
        Ok(Self {
            name: name.to_string(),
            tx,
            rx,
            wait,
            sent: VecDeque::with_capacity(ECHO_MEMORY),
        })
    }

    /// The interface name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Whether `frame` is one this port sent a moment ago (and forgets it).
    fn is_echo(&mut self, frame: &[u8]) -> bool {
        let now = Instant::now();
        while self
            .sent
            .front()
            .is_some_and(|(_, t)| now.duration_since(*t) > ECHO_WINDOW)
        {
            self.sent.pop_front();
        }
        let h = hash(frame);
        match self.sent.iter().position(|(x, _)| *x == h) {
            Some(k) => {
                self.sent.remove(k);
                true
            }
            None => false,
        }
    }
}

impl FramePort for RawPort {
    type Peer = ();

    /// pnet's receiver waits its read timeout (the channel's, `wait`) whatever it is asked,
    /// so a zero `timeout` ("do not wait") on a port that waits brings nothing; a port that
    /// polls (`wait` below 1 ms, `--spin`) looks. Any other `timeout` waits `wait`.
    fn recv(&mut self, buf: &mut Vec<u8>, timeout: Duration) -> Result<Option<()>, NetError> {
        if timeout.is_zero() && self.wait >= Duration::from_millis(1) {
            return Ok(None);
        }
        let deadline = Instant::now() + self.wait;
        loop {
            match self.rx.next() {
                Ok(frame) => {
                    if is_ethercat(frame) {
                        buf.clear();
                        buf.extend_from_slice(frame);
                        if !self.is_echo(buf) {
                            return Ok(Some(()));
                        }
                    }
                    // Another protocol or our own echo: keep waiting until the deadline.
                    if Instant::now() >= deadline {
                        return Ok(None);
                    }
                }
                Err(e) if transient(&e) => return Ok(None),
                Err(e) => {
                    return Err(NetError::Io {
                        what: "receiving on the interface",
                        source: e,
                    })
                }
            }
        }
    }

    fn send(&mut self, frame: &[u8], _peer: &()) -> Result<(), NetError> {
        let r = self
            .tx
            .send_to(frame, None)
            .unwrap_or_else(|| Err(io::Error::other("the interface refused the frame")));
        match r {
            Ok(()) => {
                if self.sent.len() == ECHO_MEMORY {
                    self.sent.pop_front();
                }
                self.sent.push_back((hash(frame), Instant::now()));
                Ok(())
            }
            Err(e) => Err(NetError::Io {
                what: "sending on the interface",
                source: e,
            }),
        }
    }

    fn describe(&self) -> String {
        format!("raw Ethernet on {}", self.name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ethertype_filter() {
        let mut f = vec![0u8; 60];
        f[12] = 0x88;
        f[13] = 0xA4;
        assert!(is_ethercat(&f));
        f[12] = 0x08;
        f[13] = 0x00;
        assert!(!is_ethercat(&f));
        f[12] = 0x81;
        f[13] = 0x00;
        f[16] = 0x88;
        f[17] = 0xA4;
        assert!(is_ethercat(&f));
        assert!(!is_ethercat(&f[..10]));
    }

    #[test]
    fn missing_interface_is_named() {
        match RawPort::open("oxicat-nope0", Duration::from_millis(1)) {
            Err(NetError::NoSuchInterface { name, .. }) => assert_eq!(name, "oxicat-nope0"),
            other => panic!("unexpected: {other:?}"),
        }
        let msg = NetError::NoPermission {
            iface: "veth1".into(),
        }
        .to_string();
        assert!(msg.contains("CAP_NET_RAW"), "{msg}");
    }
}
