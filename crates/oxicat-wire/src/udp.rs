//! EtherCAT over UDP: Ethernet II (optionally VLAN tagged) + IPv4 + UDP with destination port
//! 0x88A4, whose payload is an EtherCAT frame (header + datagrams).
//!
//! Build such frames with [`crate::FrameBuilder::new_udp`]; parse them with
//! [`EcatUdpFrame::parse`] or find just the payload offset with [`udp_payload_offset`].

use crate::error::{need, WireError};
use crate::ethernet::{ETHERNET_HEADER_LEN, VLAN_ETHERTYPE};
use crate::frame::EcatFrame;

/// UDP port of EtherCAT over UDP (0x88A4 = 34980).
pub const ETHERCAT_UDP_PORT: u16 = 0x88A4;
/// EtherType of IPv4.
pub const IPV4_ETHERTYPE: u16 = 0x0800;
/// Length of an IPv4 header without options.
pub const IPV4_HEADER_LEN: usize = 20;
/// Length of the UDP header.
pub const UDP_HEADER_LEN: usize = 8;
/// IP protocol number of UDP.
pub const IP_PROTO_UDP: u8 = 17;

/// The RFC 1071 ones'-complement checksum of `data` (odd lengths padded with a zero byte).
pub fn internet_checksum(data: &[u8]) -> u16 {
    let mut sum: u32 = 0;
    let mut chunks = data.chunks_exact(2);
    for c in &mut chunks {
        sum += u16::from_be_bytes([c[0], c[1]]) as u32;
    }
    if let [last] = chunks.remainder() {
        sum += (*last as u32) << 8;
    }
    while sum > 0xFFFF {
        sum = (sum & 0xFFFF) + (sum >> 16);
    }
    !(sum as u16)
}

/// The decoded IPv4 header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ipv4Header {
    /// Header length in bytes (IHL × 4, at least 20).
    pub header_len: usize,
    /// Type of service (DSCP + ECN).
    pub tos: u8,
    /// Total length of the IP packet (header + payload).
    pub total_len: u16,
    /// Identification.
    pub identification: u16,
    /// Flags (3 bits) and fragment offset (13 bits).
    pub flags_fragment: u16,
    /// Time to live.
    pub ttl: u8,
    /// Payload protocol (17 for UDP).
    pub protocol: u8,
    /// Header checksum as on the wire.
    pub checksum: u16,
    /// Source address.
    pub src: [u8; 4],
    /// Destination address.
    pub dst: [u8; 4],
}

impl Ipv4Header {
    /// Parses and validates an IPv4 header (version, IHL, checksum, no fragmentation).
    pub fn parse(buf: &[u8]) -> Result<Self, WireError> {
        need(buf, IPV4_HEADER_LEN)?;
        if buf[0] >> 4 != 4 {
            return Err(WireError::InvalidField("ipv4 version"));
        }
        let header_len = ((buf[0] & 0xF) as usize) * 4;
        if header_len < IPV4_HEADER_LEN {
            return Err(WireError::InvalidField("ipv4 ihl"));
        }
        need(buf, header_len)?;
        if internet_checksum(&buf[..header_len]) != 0 {
            return Err(WireError::InvalidField("ipv4 checksum"));
        }
        let h = Self {
            header_len,
            tos: buf[1],
            total_len: u16::from_be_bytes([buf[2], buf[3]]),
            identification: u16::from_be_bytes([buf[4], buf[5]]),
            flags_fragment: u16::from_be_bytes([buf[6], buf[7]]),
            ttl: buf[8],
            protocol: buf[9],
            checksum: u16::from_be_bytes([buf[10], buf[11]]),
            src: [buf[12], buf[13], buf[14], buf[15]],
            dst: [buf[16], buf[17], buf[18], buf[19]],
        };
        if (h.total_len as usize) < header_len {
            return Err(WireError::InvalidField("ipv4 total length"));
        }
        // More-fragments bit or a non-zero offset: EtherCAT frames are never fragmented.
        if h.flags_fragment & 0x3FFF != 0 {
            return Err(WireError::InvalidField("ipv4 fragment"));
        }
        Ok(h)
    }
}

/// The decoded UDP header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UdpHeader {
    /// Source port.
    pub src_port: u16,
    /// Destination port.
    pub dst_port: u16,
    /// Length of header + payload.
    pub length: u16,
    /// Checksum (0 = none).
    pub checksum: u16,
}

impl UdpHeader {
    /// Parses the 8-byte UDP header.
    pub fn parse(buf: &[u8]) -> Result<Self, WireError> {
        need(buf, UDP_HEADER_LEN)?;
        Ok(Self {
            src_port: u16::from_be_bytes([buf[0], buf[1]]),
            dst_port: u16::from_be_bytes([buf[2], buf[3]]),
            length: u16::from_be_bytes([buf[4], buf[5]]),
            checksum: u16::from_be_bytes([buf[6], buf[7]]),
        })
    }
}

/// The addresses and header fields needed to build an EtherCAT-over-UDP frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UdpEndpoints {
    /// Destination MAC address.
    pub dst_mac: [u8; 6],
    /// Source MAC address.
    pub src_mac: [u8; 6],
    /// 802.1Q tag control information, if the frame is VLAN tagged.
    pub vlan_tci: Option<u16>,
    /// Source IPv4 address.
    pub src_ip: [u8; 4],
    /// Destination IPv4 address.
    pub dst_ip: [u8; 4],
    /// Source UDP port.
    pub src_port: u16,
    /// Destination UDP port (0x88A4 for EtherCAT).
    pub dst_port: u16,
    /// IPv4 time to live.
    pub ttl: u8,
    /// IPv4 identification.
    pub identification: u16,
    /// IPv4 type of service.
    pub tos: u8,
}

impl UdpEndpoints {
    /// Endpoints with both UDP ports 0x88A4, TTL 64 and the given addresses.
    pub const fn new(src_mac: [u8; 6], dst_mac: [u8; 6], src_ip: [u8; 4], dst_ip: [u8; 4]) -> Self {
        Self {
            dst_mac,
            src_mac,
            vlan_tci: None,
            src_ip,
            dst_ip,
            src_port: ETHERCAT_UDP_PORT,
            dst_port: ETHERCAT_UDP_PORT,
            ttl: 64,
            identification: 0,
            tos: 0,
        }
    }

    /// Offset of the UDP payload (the EtherCAT header) in a frame built with these endpoints.
    pub const fn payload_offset(&self) -> usize {
        ETHERNET_HEADER_LEN
            + if self.vlan_tci.is_some() { 4 } else { 0 }
            + IPV4_HEADER_LEN
            + UDP_HEADER_LEN
    }

    /// Writes Ethernet, IPv4 (with checksum) and UDP (checksum 0) headers for a UDP payload of
    /// `payload_len` bytes at the start of `buf`; returns the payload offset.
    pub fn write_headers(&self, buf: &mut [u8], payload_len: usize) -> Result<usize, WireError> {
        let off = self.payload_offset();
        if buf.len() < off {
            return Err(WireError::BufferFull);
        }
        let udp_len =
            u16::try_from(UDP_HEADER_LEN + payload_len).map_err(|_| WireError::BufferFull)?;
        let ip_len = u16::try_from(IPV4_HEADER_LEN + UDP_HEADER_LEN + payload_len)
            .map_err(|_| WireError::BufferFull)?;
        buf[0..6].copy_from_slice(&self.dst_mac);
        buf[6..12].copy_from_slice(&self.src_mac);
        let mut o = 12;
        if let Some(tci) = self.vlan_tci {
            buf[12..14].copy_from_slice(&VLAN_ETHERTYPE.to_be_bytes());
            buf[14..16].copy_from_slice(&tci.to_be_bytes());
            o = 16;
        }
        buf[o..o + 2].copy_from_slice(&IPV4_ETHERTYPE.to_be_bytes());
        let ip = o + 2;
        let h = &mut buf[ip..ip + IPV4_HEADER_LEN];
        h[0] = 0x45;
        h[1] = self.tos;
        h[2..4].copy_from_slice(&ip_len.to_be_bytes());
        h[4..6].copy_from_slice(&self.identification.to_be_bytes());
        h[6..8].copy_from_slice(&0x4000u16.to_be_bytes()); // don't fragment
        h[8] = self.ttl;
        h[9] = IP_PROTO_UDP;
        h[10..12].fill(0);
        h[12..16].copy_from_slice(&self.src_ip);
        h[16..20].copy_from_slice(&self.dst_ip);
        let c = internet_checksum(h);
        h[10..12].copy_from_slice(&c.to_be_bytes());
        let u = &mut buf[ip + IPV4_HEADER_LEN..off];
        u[0..2].copy_from_slice(&self.src_port.to_be_bytes());
        u[2..4].copy_from_slice(&self.dst_port.to_be_bytes());
        u[4..6].copy_from_slice(&udp_len.to_be_bytes());
        u[6..8].fill(0);
        Ok(off)
    }
}

/// An Ethernet/IPv4/UDP frame carrying EtherCAT, parsed down to the EtherCAT frame.
#[derive(Debug, Clone, Copy)]
pub struct EcatUdpFrame<'a> {
    /// Destination MAC address.
    pub dst_mac: [u8; 6],
    /// Source MAC address.
    pub src_mac: [u8; 6],
    /// 802.1Q tag control information, if tagged.
    pub vlan_tci: Option<u16>,
    /// The IPv4 header.
    pub ip: Ipv4Header,
    /// The UDP header.
    pub udp: UdpHeader,
    /// Offset of the EtherCAT header within the parsed buffer.
    pub payload_offset: usize,
    /// The UDP payload: exactly `udp.length - 8` bytes.
    pub payload: &'a [u8],
}

impl<'a> EcatUdpFrame<'a> {
    /// Parses Ethernet, IPv4 and UDP headers; the destination port must be 0x88A4.
    pub fn parse(buf: &'a [u8]) -> Result<Self, WireError> {
        need(buf, ETHERNET_HEADER_LEN)?;
        let mut dst_mac = [0; 6];
        let mut src_mac = [0; 6];
        dst_mac.copy_from_slice(&buf[0..6]);
        src_mac.copy_from_slice(&buf[6..12]);
        let mut et = u16::from_be_bytes([buf[12], buf[13]]);
        let mut ip_off = ETHERNET_HEADER_LEN;
        let mut vlan_tci = None;
        if et == VLAN_ETHERTYPE {
            need(buf, ETHERNET_HEADER_LEN + 4)?;
            vlan_tci = Some(u16::from_be_bytes([buf[14], buf[15]]));
            et = u16::from_be_bytes([buf[16], buf[17]]);
            ip_off += 4;
        }
        if et != IPV4_ETHERTYPE {
            return Err(WireError::NotEtherCat(et));
        }
        let ip = Ipv4Header::parse(&buf[ip_off..])?;
        if ip.protocol != IP_PROTO_UDP {
            return Err(WireError::UnknownType(ip.protocol));
        }
        let ip_end = ip_off + ip.total_len as usize;
        if buf.len() < ip_end {
            return Err(WireError::LengthMismatch {
                declared: ip.total_len as usize,
                available: buf.len() - ip_off,
            });
        }
        let udp_off = ip_off + ip.header_len;
        let udp = UdpHeader::parse(&buf[udp_off..ip_end])?;
        if udp.dst_port != ETHERCAT_UDP_PORT {
            return Err(WireError::InvalidField("udp destination port"));
        }
        let udp_len = udp.length as usize;
        if udp_len < UDP_HEADER_LEN || udp_off + udp_len > ip_end {
            return Err(WireError::LengthMismatch {
                declared: udp_len,
                available: ip_end - udp_off,
            });
        }
        let payload_offset = udp_off + UDP_HEADER_LEN;
        Ok(Self {
            dst_mac,
            src_mac,
            vlan_tci,
            ip,
            udp,
            payload_offset,
            payload: &buf[payload_offset..udp_off + udp_len],
        })
    }

    /// The EtherCAT frame in the UDP payload.
    pub fn ecat(&self) -> Result<EcatFrame<'a>, WireError> {
        EcatFrame::parse(self.payload)
    }

    /// The endpoints this frame was sent with (the inverse of building with them).
    pub fn endpoints(&self) -> UdpEndpoints {
        UdpEndpoints {
            dst_mac: self.dst_mac,
            src_mac: self.src_mac,
            vlan_tci: self.vlan_tci,
            src_ip: self.ip.src,
            dst_ip: self.ip.dst,
            src_port: self.udp.src_port,
            dst_port: self.udp.dst_port,
            ttl: self.ip.ttl,
            identification: self.ip.identification,
            tos: self.ip.tos,
        }
    }
}

/// Parses an Ethernet/IPv4/UDP frame and returns the offset and length of its EtherCAT
/// payload.
pub fn udp_payload_offset(buf: &[u8]) -> Result<(usize, usize), WireError> {
    let f = EcatUdpFrame::parse(buf)?;
    Ok((f.payload_offset, f.payload.len()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Command, DatagramHeader, FrameBuilder};

    #[test]
    fn build_parse() {
        let ep = UdpEndpoints::new(
            [2, 0, 0, 0, 0, 1],
            [0xff; 6],
            [10, 0, 0, 1],
            [10, 0, 0, 255],
        );
        let mut buf = [0u8; 128];
        let mut b = FrameBuilder::new_udp(&mut buf, &ep).unwrap();
        b.push(DatagramHeader::physical(Command::Brd, 7, 0, 0, 2), &[])
            .unwrap();
        let n = b.finish();
        assert_eq!(n, 60); // 42 + 2 + 14 = 58, padded
        let f = EcatUdpFrame::parse(&buf[..n]).unwrap();
        assert_eq!(f.payload_offset, 42);
        assert_eq!(f.endpoints(), ep);
        let e = f.ecat().unwrap();
        let d = e.datagrams().next().unwrap().unwrap();
        assert_eq!(d.header.index, 7);
        // Corrupt the IP checksum.
        buf[24] ^= 1;
        assert_eq!(
            EcatUdpFrame::parse(&buf[..n]).unwrap_err(),
            WireError::InvalidField("ipv4 checksum")
        );
    }
}
