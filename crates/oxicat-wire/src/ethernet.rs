//! Ethernet II framing of EtherCAT (EtherType 0x88A4), with an optional 802.1Q tag.

use crate::error::{need, WireError};

/// EtherType of EtherCAT frames (and the UDP port of EtherCAT over UDP).
pub const ETHERCAT_ETHERTYPE: u16 = 0x88A4;
/// EtherType of an IEEE 802.1Q VLAN tag.
pub const VLAN_ETHERTYPE: u16 = 0x8100;
/// Minimum Ethernet frame length without the FCS; shorter frames are padded.
pub const ETHERNET_MIN_LEN: usize = 60;
/// Length of an untagged Ethernet II header.
pub const ETHERNET_HEADER_LEN: usize = 14;

/// The decoded Ethernet II header of an EtherCAT frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EthernetHeader {
    /// Destination MAC address.
    pub dst: [u8; 6],
    /// Source MAC address.
    pub src: [u8; 6],
    /// The 802.1Q tag control information, when the frame carries a VLAN tag.
    pub vlan_tci: Option<u16>,
    /// Offset of the EtherCAT header (14, or 18 with a VLAN tag).
    pub payload_offset: usize,
}

impl EthernetHeader {
    /// Parses the header of an Ethernet frame that must carry EtherCAT.
    pub fn parse(buf: &[u8]) -> Result<Self, WireError> {
        need(buf, ETHERNET_HEADER_LEN)?;
        let mut dst = [0; 6];
        let mut src = [0; 6];
        dst.copy_from_slice(&buf[0..6]);
        src.copy_from_slice(&buf[6..12]);
        let ethertype = u16::from_be_bytes([buf[12], buf[13]]);
        match ethertype {
            ETHERCAT_ETHERTYPE => Ok(Self {
                dst,
                src,
                vlan_tci: None,
                payload_offset: ETHERNET_HEADER_LEN,
            }),
            VLAN_ETHERTYPE => {
                need(buf, ETHERNET_HEADER_LEN + 4)?;
                let tci = u16::from_be_bytes([buf[14], buf[15]]);
                let inner = u16::from_be_bytes([buf[16], buf[17]]);
                if inner != ETHERCAT_ETHERTYPE {
                    return Err(WireError::NotEtherCat(inner));
                }
                Ok(Self {
                    dst,
                    src,
                    vlan_tci: Some(tci),
                    payload_offset: ETHERNET_HEADER_LEN + 4,
                })
            }
            other => Err(WireError::NotEtherCat(other)),
        }
    }

    /// Writes this header into `buf` and returns its length (14 or 18).
    pub fn write(&self, buf: &mut [u8]) -> Result<usize, WireError> {
        let len = if self.vlan_tci.is_some() { 18 } else { 14 };
        if buf.len() < len {
            return Err(WireError::BufferFull);
        }
        buf[0..6].copy_from_slice(&self.dst);
        buf[6..12].copy_from_slice(&self.src);
        match self.vlan_tci {
            Some(tci) => {
                buf[12..14].copy_from_slice(&VLAN_ETHERTYPE.to_be_bytes());
                buf[14..16].copy_from_slice(&tci.to_be_bytes());
                buf[16..18].copy_from_slice(&ETHERCAT_ETHERTYPE.to_be_bytes());
            }
            None => buf[12..14].copy_from_slice(&ETHERCAT_ETHERTYPE.to_be_bytes()),
        }
        Ok(len)
    }
}
