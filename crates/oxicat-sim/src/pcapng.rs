//! pcapng capture files: writer (both directions, ns timestamps) and reader.
//!
//! The writer produces one section with one Ethernet interface (linktype 1) whose
//! timestamps are in nanoseconds (`if_tsresol = 9`); every packet is an Enhanced Packet
//! Block carrying its direction in `epb_flags`. The reader accepts what real tools write:
//! Section Header Blocks of either byte order (several sections per file), Interface
//! Description Blocks with `if_tsresol`/`if_tsoffset`, Enhanced and Simple Packet Blocks;
//! every other block type is skipped. Malformed input is a [`PcapngError`], never a panic.

use std::fmt;
use std::io::{self, Write};

/// Block type of a Section Header Block.
pub const BLOCK_SHB: u32 = 0x0A0D_0D0A;
/// Block type of an Interface Description Block.
pub const BLOCK_IDB: u32 = 0x0000_0001;
/// Block type of a Simple Packet Block.
pub const BLOCK_SPB: u32 = 0x0000_0003;
/// Block type of an Enhanced Packet Block.
pub const BLOCK_EPB: u32 = 0x0000_0006;
/// The byte-order magic of a Section Header Block.
pub const BYTE_ORDER_MAGIC: u32 = 0x1A2B_3C4D;
/// Linktype of Ethernet.
pub const LINKTYPE_ETHERNET: u16 = 1;

const OPT_ENDOFOPT: u16 = 0;
const OPT_IF_TSRESOL: u16 = 9;
const OPT_IF_TSOFFSET: u16 = 14;
const OPT_EPB_FLAGS: u16 = 2;
/// Largest block the reader accepts (guards against absurd length fields).
const MAX_BLOCK_LEN: usize = 64 * 1024 * 1024;

/// What went wrong while reading or writing a pcapng file.
#[derive(Debug)]
pub enum PcapngError {
    /// An I/O error of the underlying writer.
    Io(io::Error),
    /// The file does not start with a Section Header Block.
    NotPcapng,
    /// A Section Header Block has an unknown byte-order magic.
    BadByteOrderMagic(u32),
    /// A section has a major version other than 1.
    UnsupportedVersion(u16),
    /// A block ends before its declared length, or the file ends inside a block.
    Truncated {
        /// Byte offset of the block in the file.
        offset: usize,
    },
    /// A block length is too small, not a multiple of 4, too large, or its trailing copy differs.
    BadBlockLength {
        /// Byte offset of the block in the file.
        offset: usize,
        /// The declared length.
        len: u32,
    },
    /// A packet block refers to an interface that no IDB of its section described.
    UnknownInterface {
        /// Byte offset of the block in the file.
        offset: usize,
        /// The interface id.
        interface: u32,
    },
    /// A packet's captured length exceeds its block.
    BadPacketLength {
        /// Byte offset of the block in the file.
        offset: usize,
    },
    /// A packet is larger than the 32-bit length fields of pcapng allow.
    PacketTooLarge(usize),
}

impl fmt::Display for PcapngError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Io(e) => write!(f, "i/o error: {e}"),
            Self::NotPcapng => write!(f, "not a pcapng file (no section header block)"),
            Self::BadByteOrderMagic(m) => write!(f, "bad byte-order magic {m:#010x}"),
            Self::UnsupportedVersion(v) => write!(f, "unsupported pcapng major version {v}"),
            Self::Truncated { offset } => write!(f, "block at {offset:#x} is truncated"),
            Self::BadBlockLength { offset, len } => {
                write!(f, "block at {offset:#x} has bad length {len}")
            }
            Self::UnknownInterface { offset, interface } => {
                write!(
                    f,
                    "block at {offset:#x} refers to unknown interface {interface}"
                )
            }
            Self::BadPacketLength { offset } => {
                write!(f, "packet block at {offset:#x} has a bad captured length")
            }
            Self::PacketTooLarge(n) => write!(f, "packet of {n} bytes is too large"),
        }
    }
}

impl std::error::Error for PcapngError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Io(e) => Some(e),
            _ => None,
        }
    }
}

impl From<io::Error> for PcapngError {
    fn from(e: io::Error) -> Self {
        Self::Io(e)
    }
}

/// Direction of a packet as recorded in `epb_flags` bits 0–1.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// Direction not recorded.
    Unknown,
    /// Received by the capturing interface.
    Inbound,
    /// Sent by the capturing interface.
    Outbound,
}

/// An interface described by an Interface Description Block.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Interface {
    /// Link-layer type (1 = Ethernet).
    pub linktype: u16,
    /// Maximum captured length (0 = unlimited).
    pub snaplen: u32,
    /// Raw `if_tsresol` byte (bit 7 clear: 10^-n s, set: 2^-n s); 6 when absent.
    pub tsresol: u8,
    /// `if_tsoffset` in seconds, added to every timestamp.
    pub tsoffset: i64,
}

impl Interface {
    /// Converts a raw timestamp of this interface to nanoseconds since the epoch
    /// (saturating at the ends of `u64`).
    pub fn ts_to_ns(&self, raw: u64) -> u64 {
        let raw = raw as u128;
        let ns: u128 = if self.tsresol & 0x80 == 0 {
            let n = u32::from(self.tsresol);
            if n <= 9 {
                raw.saturating_mul(10u128.pow(9 - n))
            } else if n <= 38 {
                raw / 10u128.pow(n - 9)
            } else {
                0
            }
        } else {
            let n = u32::from(self.tsresol & 0x7F);
            if n < 64 {
                raw.saturating_mul(1_000_000_000) >> n
            } else {
                0
            }
        };
        let off = i128::from(self.tsoffset).saturating_mul(1_000_000_000);
        let total = (ns as i128).saturating_add(off);
        total.clamp(0, i128::from(u64::MAX)) as u64
    }
}

/// One packet read from a file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Packet {
    /// Index of the interface within its section.
    pub interface: u32,
    /// The interface's link-layer type.
    pub linktype: u16,
    /// Timestamp in ns since the epoch (`None` for Simple Packet Blocks).
    pub ts_ns: Option<u64>,
    /// The captured bytes.
    pub data: Vec<u8>,
    /// The packet's length on the wire.
    pub orig_len: u32,
    /// Direction from `epb_flags`.
    pub direction: Direction,
    /// Raw `epb_flags` value if present.
    pub flags: Option<u32>,
}

/// Reads the packets of a pcapng file held in memory.
#[derive(Debug, Clone)]
pub struct PcapngReader<'a> {
    buf: &'a [u8],
    pos: usize,
    big_endian: bool,
    interfaces: Vec<Interface>,
    started: bool,
    failed: bool,
}

fn rd_u16(b: &[u8], at: usize, be: bool) -> Option<u16> {
    let s: [u8; 2] = b.get(at..at.checked_add(2)?)?.try_into().ok()?;
    Some(if be {
        u16::from_be_bytes(s)
    } else {
        u16::from_le_bytes(s)
    })
}

fn rd_u32(b: &[u8], at: usize, be: bool) -> Option<u32> {
    let s: [u8; 4] = b.get(at..at.checked_add(4)?)?.try_into().ok()?;
    Some(if be {
        u32::from_be_bytes(s)
    } else {
        u32::from_le_bytes(s)
    })
}

fn rd_u64(b: &[u8], at: usize, be: bool) -> Option<u64> {
    let s: [u8; 8] = b.get(at..at.checked_add(8)?)?.try_into().ok()?;
    Some(if be {
        u64::from_be_bytes(s)
    } else {
        u64::from_le_bytes(s)
    })
}

/// Iterates the options `(code, value)` of an option area; stops at `opt_endofopt`, at
/// the end of the area, or at a malformed option.
fn options(area: &[u8], be: bool) -> impl Iterator<Item = (u16, &[u8])> {
    let mut pos = 0usize;
    core::iter::from_fn(move || {
        let code = rd_u16(area, pos, be)?;
        let len = usize::from(rd_u16(area, pos + 2, be)?);
        if code == OPT_ENDOFOPT {
            return None;
        }
        let start = pos + 4;
        let value = area.get(start..start + len)?;
        pos = start + len.div_ceil(4) * 4;
        Some((code, value))
    })
}

impl<'a> PcapngReader<'a> {
    /// Starts reading the pcapng file in `buf`; fails if it does not begin with a valid SHB.
    pub fn new(buf: &'a [u8]) -> Result<Self, PcapngError> {
        let mut r = Self {
            buf,
            pos: 0,
            big_endian: false,
            interfaces: Vec::new(),
            started: false,
            failed: false,
        };
        if rd_u32(buf, 0, false) != Some(BLOCK_SHB) {
            return Err(PcapngError::NotPcapng);
        }
        r.read_shb()?;
        r.started = true;
        Ok(r)
    }

    /// The interfaces of the current section.
    pub fn interfaces(&self) -> &[Interface] {
        &self.interfaces
    }

    /// Parses the SHB at `self.pos`, sets the byte order and returns its total length.
    fn read_shb(&mut self) -> Result<(), PcapngError> {
        let off = self.pos;
        let b = self.buf;
        let magic_le = rd_u32(b, off + 8, false).ok_or(PcapngError::Truncated { offset: off })?;
        let be = match magic_le {
            BYTE_ORDER_MAGIC => false,
            0x4D3C_2B1A => true,
            m => return Err(PcapngError::BadByteOrderMagic(m)),
        };
        let len = rd_u32(b, off + 4, be).ok_or(PcapngError::Truncated { offset: off })?;
        let body = self.check_block(off, len, be, 28)?;
        let major = rd_u16(body, 4, be).ok_or(PcapngError::Truncated { offset: off })?;
        if major != 1 {
            return Err(PcapngError::UnsupportedVersion(major));
        }
        self.big_endian = be;
        self.interfaces.clear();
        self.pos = off + len as usize;
        Ok(())
    }

    /// Validates the block at `off` with declared length `len` and returns its body
    /// (between the 8-byte head and the 4-byte trailing length).
    fn check_block(
        &self,
        off: usize,
        len: u32,
        be: bool,
        min: usize,
    ) -> Result<&'a [u8], PcapngError> {
        let l = len as usize;
        if l < min.max(12) || l & 3 != 0 || l > MAX_BLOCK_LEN {
            return Err(PcapngError::BadBlockLength { offset: off, len });
        }
        let end = off
            .checked_add(l)
            .ok_or(PcapngError::Truncated { offset: off })?;
        if end > self.buf.len() {
            return Err(PcapngError::Truncated { offset: off });
        }
        if rd_u32(self.buf, end - 4, be) != Some(len) {
            return Err(PcapngError::BadBlockLength { offset: off, len });
        }
        Ok(&self.buf[off + 8..end - 4])
    }

    fn interface(&self, off: usize, id: u32) -> Result<Interface, PcapngError> {
        self.interfaces
            .get(id as usize)
            .copied()
            .ok_or(PcapngError::UnknownInterface {
                offset: off,
                interface: id,
            })
    }

    /// Reads the next packet; `Ok(None)` at the end of the file. After an error the
    /// reader returns `Ok(None)`.
    pub fn next_packet(&mut self) -> Result<Option<Packet>, PcapngError> {
        if self.failed || !self.started {
            return Ok(None);
        }
        let r = self.next_inner();
        if r.is_err() {
            self.failed = true;
        }
        r
    }

    fn next_inner(&mut self) -> Result<Option<Packet>, PcapngError> {
        loop {
            let off = self.pos;
            if off >= self.buf.len() {
                return Ok(None);
            }
            let be = self.big_endian;
            let btype = rd_u32(self.buf, off, be).ok_or(PcapngError::Truncated { offset: off })?;
            if btype == BLOCK_SHB {
                self.read_shb()?;
                continue;
            }
            let len =
                rd_u32(self.buf, off + 4, be).ok_or(PcapngError::Truncated { offset: off })?;
            let body = self.check_block(off, len, be, 12)?;
            self.pos = off + len as usize;
            match btype {
                BLOCK_IDB => {
                    let linktype =
                        rd_u16(body, 0, be).ok_or(PcapngError::Truncated { offset: off })?;
                    let snaplen =
                        rd_u32(body, 4, be).ok_or(PcapngError::Truncated { offset: off })?;
                    let mut itf = Interface {
                        linktype,
                        snaplen,
                        tsresol: 6,
                        tsoffset: 0,
                    };
                    for (code, v) in options(&body[8..], be) {
                        match code {
                            OPT_IF_TSRESOL if !v.is_empty() => itf.tsresol = v[0],
                            OPT_IF_TSOFFSET => {
                                if let Some(x) = rd_u64(v, 0, be) {
                                    itf.tsoffset = x as i64;
                                }
                            }
                            _ => {}
                        }
                    }
                    self.interfaces.push(itf);
                }
                BLOCK_EPB => {
                    let bad = PcapngError::BadPacketLength { offset: off };
                    let id = rd_u32(body, 0, be).ok_or(PcapngError::Truncated { offset: off })?;
                    let itf = self.interface(off, id)?;
                    let hi = rd_u32(body, 4, be).ok_or(PcapngError::Truncated { offset: off })?;
                    let lo = rd_u32(body, 8, be).ok_or(PcapngError::Truncated { offset: off })?;
                    let cap = rd_u32(body, 12, be).ok_or(PcapngError::Truncated { offset: off })?
                        as usize;
                    let orig =
                        rd_u32(body, 16, be).ok_or(PcapngError::Truncated { offset: off })?;
                    let data = body.get(20..20 + cap).ok_or(bad)?;
                    let opts = body.get(20 + cap.div_ceil(4) * 4..).unwrap_or(&[]);
                    let flags = options(opts, be)
                        .find(|(c, v)| *c == OPT_EPB_FLAGS && v.len() == 4)
                        .and_then(|(_, v)| rd_u32(v, 0, be));
                    let direction = match flags.map(|f| f & 3) {
                        Some(1) => Direction::Inbound,
                        Some(2) => Direction::Outbound,
                        _ => Direction::Unknown,
                    };
                    let raw = (u64::from(hi) << 32) | u64::from(lo);
                    return Ok(Some(Packet {
                        interface: id,
                        linktype: itf.linktype,
                        ts_ns: Some(itf.ts_to_ns(raw)),
                        data: data.to_vec(),
                        orig_len: orig,
                        direction,
                        flags,
                    }));
                }
                BLOCK_SPB => {
                    let itf = self.interface(off, 0)?;
                    let orig = rd_u32(body, 0, be).ok_or(PcapngError::Truncated { offset: off })?;
                    let avail = body.len() - 4;
                    let mut cap = (orig as usize).min(avail);
                    if itf.snaplen != 0 {
                        cap = cap.min(itf.snaplen as usize);
                    }
                    return Ok(Some(Packet {
                        interface: 0,
                        linktype: itf.linktype,
                        ts_ns: None,
                        data: body[4..4 + cap].to_vec(),
                        orig_len: orig,
                        direction: Direction::Unknown,
                        flags: None,
                    }));
                }
                _ => {}
            }
        }
    }
}

impl Iterator for PcapngReader<'_> {
    type Item = Result<Packet, PcapngError>;

    fn next(&mut self) -> Option<Self::Item> {
        self.next_packet().transpose()
    }
}

/// Reads every packet of the pcapng file in `buf`.
pub fn read_all(buf: &[u8]) -> Result<Vec<Packet>, PcapngError> {
    PcapngReader::new(buf)?.collect()
}

/// Writes a pcapng file: one section, one Ethernet interface with ns timestamps.
#[derive(Debug)]
pub struct PcapngWriter<W: Write> {
    out: W,
}

impl<W: Write> PcapngWriter<W> {
    /// Writes the section header and the interface description to `out`.
    pub fn new(mut out: W) -> Result<Self, PcapngError> {
        // SHB: type, len, magic, version 1.0, section length -1 (unknown), len.
        let mut shb = Vec::with_capacity(28);
        shb.extend_from_slice(&BLOCK_SHB.to_le_bytes());
        shb.extend_from_slice(&28u32.to_le_bytes());
        shb.extend_from_slice(&BYTE_ORDER_MAGIC.to_le_bytes());
        shb.extend_from_slice(&1u16.to_le_bytes());
        shb.extend_from_slice(&0u16.to_le_bytes());
        shb.extend_from_slice(&u64::MAX.to_le_bytes());
        shb.extend_from_slice(&28u32.to_le_bytes());
        out.write_all(&shb)?;
        // IDB: linktype 1, reserved, snaplen 0, if_tsresol = 9, end of options.
        let mut idb = Vec::with_capacity(32);
        idb.extend_from_slice(&BLOCK_IDB.to_le_bytes());
        idb.extend_from_slice(&32u32.to_le_bytes());
        idb.extend_from_slice(&LINKTYPE_ETHERNET.to_le_bytes());
        idb.extend_from_slice(&0u16.to_le_bytes());
        idb.extend_from_slice(&0u32.to_le_bytes());
        idb.extend_from_slice(&OPT_IF_TSRESOL.to_le_bytes());
        idb.extend_from_slice(&1u16.to_le_bytes());
        idb.extend_from_slice(&[9, 0, 0, 0]);
        idb.extend_from_slice(&[0, 0, 0, 0]);
        idb.extend_from_slice(&32u32.to_le_bytes());
        out.write_all(&idb)?;
        Ok(Self { out })
    }

    /// Writes one Ethernet frame captured at `ts_ns` (ns since the epoch), sent by the
    /// capturing side (`outbound`) or received by it.
    pub fn write_packet(
        &mut self,
        ts_ns: u64,
        data: &[u8],
        outbound: bool,
    ) -> Result<(), PcapngError> {
        let cap = u32::try_from(data.len())
            .ok()
            .filter(|n| *n <= (MAX_BLOCK_LEN as u32) - 64)
            .ok_or(PcapngError::PacketTooLarge(data.len()))?;
        let padded = data.len().div_ceil(4) * 4;
        // head 8 + fixed 20 + data + flags option 8 + endofopt 4 + trailer 4
        let total = 8 + 20 + padded + 8 + 4 + 4;
        let mut b = Vec::with_capacity(total);
        b.extend_from_slice(&BLOCK_EPB.to_le_bytes());
        b.extend_from_slice(&(total as u32).to_le_bytes());
        b.extend_from_slice(&0u32.to_le_bytes());
        b.extend_from_slice(&((ts_ns >> 32) as u32).to_le_bytes());
        b.extend_from_slice(&(ts_ns as u32).to_le_bytes());
        b.extend_from_slice(&cap.to_le_bytes());
        b.extend_from_slice(&cap.to_le_bytes());
        b.extend_from_slice(data);
        b.resize(8 + 20 + padded, 0);
        let flags: u32 = if outbound { 2 } else { 1 };
        b.extend_from_slice(&OPT_EPB_FLAGS.to_le_bytes());
        b.extend_from_slice(&4u16.to_le_bytes());
        b.extend_from_slice(&flags.to_le_bytes());
        b.extend_from_slice(&[0, 0, 0, 0]);
        b.extend_from_slice(&(total as u32).to_le_bytes());
        self.out.write_all(&b)?;
        Ok(())
    }

    /// Flushes the underlying writer.
    pub fn flush(&mut self) -> Result<(), PcapngError> {
        self.out.flush()?;
        Ok(())
    }

    /// Returns the underlying writer.
    pub fn into_inner(self) -> W {
        self.out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    fn reference_dir() -> PathBuf {
        std::env::var_os("OXICAT_REFERENCE")
            .map(PathBuf::from)
            .unwrap_or_else(|| {
                PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/reference")
            })
    }

    #[test]
    fn round_trip() {
        let mut w = PcapngWriter::new(Vec::new()).unwrap();
        let frames: Vec<(u64, Vec<u8>, bool)> = (0..20u8)
            .map(|i| {
                (
                    1_700_000_000_123_456_789 + u64::from(i) * 1_001,
                    (0..(60 + usize::from(i))).map(|b| b as u8 ^ i).collect(),
                    i % 2 == 0,
                )
            })
            .collect();
        for (t, d, o) in &frames {
            w.write_packet(*t, d, *o).unwrap();
        }
        w.write_packet(0, &[], true).unwrap();
        let bytes = w.into_inner();
        let pk = read_all(&bytes).unwrap();
        assert_eq!(pk.len(), frames.len() + 1);
        for (p, (t, d, o)) in pk.iter().zip(&frames) {
            assert_eq!(p.ts_ns, Some(*t));
            assert_eq!(&p.data, d);
            assert_eq!(p.orig_len as usize, d.len());
            assert_eq!(p.linktype, LINKTYPE_ETHERNET);
            let want = if *o {
                Direction::Outbound
            } else {
                Direction::Inbound
            };
            assert_eq!(p.direction, want);
        }
        assert!(pk[20].data.is_empty());
    }

    /// Builds a big-endian file by hand: SHB, IDB (µs), an unknown block, EPB, SPB.
    #[test]
    fn big_endian_and_simple_packets() {
        fn block(t: u32, body: &[u8]) -> Vec<u8> {
            let len = (12 + body.len()) as u32;
            let mut b = t.to_be_bytes().to_vec();
            b.extend_from_slice(&len.to_be_bytes());
            b.extend_from_slice(body);
            b.extend_from_slice(&len.to_be_bytes());
            b
        }
        let mut f = Vec::new();
        let mut shb = BYTE_ORDER_MAGIC.to_be_bytes().to_vec();
        shb.extend_from_slice(&[0, 1, 0, 0]);
        shb.extend_from_slice(&u64::MAX.to_be_bytes());
        f.extend(block(BLOCK_SHB, &shb));
        let mut idb = vec![0, 1, 0, 0, 0, 0, 0, 0];
        idb.extend_from_slice(&[0, 9, 0, 1, 3, 0, 0, 0, 0, 0, 0, 0]); // tsresol ms
        f.extend(block(BLOCK_IDB, &idb));
        f.extend(block(0x0BAD_0001, &[1, 2, 3, 4]));
        let mut epb = vec![0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 5, 0, 0, 0, 3, 0, 0, 0, 3];
        epb.extend_from_slice(&[7, 8, 9, 0]);
        f.extend(block(BLOCK_EPB, &epb));
        f.extend(block(BLOCK_SPB, &[0, 0, 0, 2, 0xAA, 0xBB, 0, 0]));
        let pk = read_all(&f).unwrap();
        assert_eq!(pk.len(), 2);
        assert_eq!(pk[0].ts_ns, Some(5_000_000));
        assert_eq!(pk[0].data, vec![7, 8, 9]);
        assert_eq!(pk[1].ts_ns, None);
        assert_eq!(pk[1].data, vec![0xAA, 0xBB]);
    }

    #[test]
    fn malformed_inputs_are_errors() {
        assert!(matches!(read_all(&[]), Err(PcapngError::NotPcapng)));
        let mut w = PcapngWriter::new(Vec::new()).unwrap();
        w.write_packet(1, &[1, 2, 3, 4, 5], false).unwrap();
        let good = w.into_inner();
        // Every truncation and every single-byte corruption: an error or packets, no panic.
        for n in 0..good.len() {
            let _ = read_all(&good[..n]);
        }
        for i in 0..good.len() {
            for v in [0x00, 0xFF, 0x7F, 0x80] {
                let mut b = good.clone();
                b[i] = v;
                let _ = read_all(&b);
            }
        }
        // A packet block before any IDB.
        let mut b = good[..28].to_vec();
        b.extend_from_slice(&good[60..]);
        assert!(matches!(
            read_all(&b),
            Err(PcapngError::UnknownInterface { .. })
        ));
        // Captured length larger than the block.
        let mut b = good.clone();
        b[60 + 20..60 + 24].copy_from_slice(&1000u32.to_le_bytes());
        assert!(matches!(
            read_all(&b),
            Err(PcapngError::BadPacketLength { .. })
        ));
    }

    #[test]
    fn timestamp_resolutions() {
        let mut i = Interface {
            linktype: 1,
            snaplen: 0,
            tsresol: 6,
            tsoffset: 0,
        };
        assert_eq!(i.ts_to_ns(3), 3_000);
        i.tsresol = 12;
        assert_eq!(i.ts_to_ns(3_000), 3);
        i.tsresol = 0x80 | 10;
        assert_eq!(i.ts_to_ns(1024), 1_000_000_000);
        i.tsresol = 9;
        i.tsoffset = 2;
        assert_eq!(i.ts_to_ns(1), 2_000_000_001);
        i.tsresol = 0xFF;
        let _ = i.ts_to_ns(u64::MAX);
    }

    #[test]
    fn reads_every_reference_capture() {
        let dir = reference_dir().join("captures");
        let mut n = 0;
        let entries = std::fs::read_dir(&dir)
            .unwrap_or_else(|e| panic!("reference captures {}: {e}", dir.display()));
        for e in entries {
            let p = e.unwrap().path();
            if p.extension().and_then(|x| x.to_str()) != Some("pcapng") {
                continue;
            }
            let bytes = std::fs::read(&p).unwrap();
            let pk = read_all(&bytes).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            assert!(!pk.is_empty(), "{}", p.display());
            // Every packet is Ethernet; the EtherCAT ones (some captures also hold mDNS,
            // LLMNR and truncated frames of the host) parse as EtherCAT frames.
            let mut ecat = 0;
            for k in &pk {
                assert_eq!(k.linktype, LINKTYPE_ETHERNET);
                assert!(k.ts_ns.is_some());
                if k.data.get(12..14) != Some(&[0x88, 0xA4][..]) {
                    continue;
                }
                let (_, f) = oxicat_wire::EcatFrame::parse_ethernet(&k.data)
                    .unwrap_or_else(|e| panic!("{}: {e:?}", p.display()));
                assert!(f.datagrams().all(|d| d.is_ok()), "{}", p.display());
                ecat += 1;
            }
            assert!(ecat > 0, "{}: no EtherCAT frames", p.display());
            n += 1;
        }
        assert!(n >= 9, "expected the reference captures, found {n}");
    }
}
