//! SII EEPROM access through the ESC's SII interface (0x0500 ownership, 0x0502 control/
//! status, 0x0504 address, 0x0508 data): read, decode, check and write an image.

use oxicat_wire::regs;
use oxicat_wire::sii::{sii_crc8, CategoryType, SiiImage};

use crate::{Master, MasterError};

use oxicat_wire::regs::sii_control::{
    ACK_ERROR as ERR_ACK, BUSY, READ_8 as READ8, WE_ERROR as ERR_WE,
};
use oxicat_wire::regs::{SII_ADDRESS as ADDR, SII_CONTROL as CTL, SII_DATA as DATA};

/// What to do with an SII image before writing it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct WriteOptions {
    /// Write even when the image's identity differs from the slave's.
    pub force: bool,
}

fn sii_err(position: usize, what: impl Into<String>) -> MasterError {
    MasterError::SiiInterface {
        position,
        what: what.into(),
    }
}

/// Checks an image before it is written: even length, fixed area present, configuration
/// area CRC (word 7) right.
pub fn check_image(img: &[u8]) -> Result<(), MasterError> {
    if img.len() < 0x80 {
        return Err(MasterError::SiiImage(format!(
            "{} bytes; an SII image has at least the 128-byte fixed area",
            img.len()
        )));
    }
    if img.len() & 1 != 0 {
        return Err(MasterError::SiiImage(
            "odd length; the SII is 16-bit words".into(),
        ));
    }
    let computed = sii_crc8(&img[..14]);
    if img[14] != computed {
        return Err(MasterError::SiiCrc {
            stored: img[14],
            computed,
        });
    }
    Ok(())
}

/// Identity (vendor, product, revision) of an image.
pub fn image_identity(img: &[u8]) -> Result<(u32, u32, u32), MasterError> {
    let im = SiiImage::new(img).map_err(|e| MasterError::SiiImage(format!("{e}")))?;
    let id = im.identity();
    Ok((id.vendor_id, id.product_code, id.revision))
}

/// Virtual time between two polls of a busy EEPROM interface (the real-time pause).
const SII_POLL_NS: u64 = 200_000;

impl Master {
    async fn sii_take(&self, position: usize) -> Result<u16, MasterError> {
        // The master owns the EEPROM when 0x0500 bit 0 is 0; the PDI may hold it (0x0501).
        let own = self.fprd(position, regs::SII_CONFIG, 2).await?;
        if own[0] & 1 != 0 {
            if own[1] & 1 != 0 {
                return Err(sii_err(
                    position,
                    "the EEPROM is being accessed by the PDI (0x0501)",
                ));
            }
            self.fpwr(position, regs::SII_CONFIG, &[0]).await?;
        }
        self.sii_wait(position).await
    }

    async fn sii_wait(&self, position: usize) -> Result<u16, MasterError> {
        let deadline = std::time::Instant::now()
            + self
                .options
                .timeouts
                .eeprom
                .max(std::time::Duration::from_millis(100));
        loop {
            let c = self.read_u16(position, CTL).await?;
            if c & BUSY == 0 {
                return Ok(c);
            }
            if std::time::Instant::now() > deadline {
                return Err(sii_err(position, "stays busy (0x0502 bit 15)"));
            }
            if self.time.is_sim() {
                // An EEPROM write cycle lasts milliseconds of the segment's virtual clock,
                // which frames alone advance by microseconds: let the poll interval pass
                // there, as it passes in real time on hardware.
                let t = self.time.now();
                self.time.wait_until(t + SII_POLL_NS);
            } else {
                self.pause().await;
            }
        }
    }

    async fn sii_read_chunk(&self, position: usize, word: u16) -> Result<Vec<u8>, MasterError> {
        self.fpwr(position, ADDR, &(word as u32).to_le_bytes())
            .await?;
        self.fpwr(position, CTL, &0x0100u16.to_le_bytes()).await?;
        let c = self.sii_wait(position).await?;
        if c & ERR_ACK != 0 {
            return Err(sii_err(
                position,
                format!("read of word 0x{word:04X} not acknowledged (0x0502 = 0x{c:04X})"),
            ));
        }
        let n = if c & READ8 != 0 { 8 } else { 4 };
        self.fprd(position, DATA, n).await
    }

    async fn sii_read_words(
        &self,
        position: usize,
        buf: &mut Vec<u8>,
        upto: usize,
    ) -> Result<(), MasterError> {
        while buf.len() < upto {
            let w = (buf.len() / 2) as u16;
            let d = self.sii_read_chunk(position, w).await?;
            buf.extend_from_slice(&d);
        }
        Ok(())
    }

    /// Reads the SII of the slave at `position`: up to and including the end-of-categories
    /// marker, or the whole EEPROM with `full`.
    pub fn sii_read(&self, position: usize, full: bool) -> Result<Vec<u8>, MasterError> {
        self.runner.block_on(self.sii_read_async(position, full))
    }

    /// `len` bytes of the SII from word `word` on.
    pub(crate) async fn sii_read_at(
        &self,
        position: usize,
        word: u16,
        len: usize,
    ) -> Result<Vec<u8>, MasterError> {
        self.sii_take(position).await?;
        let mut b = Vec::new();
        while b.len() < len {
            let d = self
                .sii_read_chunk(position, word + (b.len() / 2) as u16)
                .await?;
            b.extend_from_slice(&d);
        }
        b.truncate(len);
        Ok(b)
    }

    pub(crate) async fn sii_read_async(
        &self,
        position: usize,
        full: bool,
    ) -> Result<Vec<u8>, MasterError> {
        {
            self.sii_take(position).await?;
            let mut b = Vec::new();
            self.sii_read_words(position, &mut b, 0x80).await?;
            let size_word = u16::from_le_bytes([b[0x7C], b[0x7D]]);
            let size = ((size_word as usize + 1) * 128).min(64 * 1024);
            let end = if full {
                size
            } else {
                let mut pos = 0x80usize;
                loop {
                    if pos + 2 > size {
                        break size;
                    }
                    self.sii_read_words(position, &mut b, pos + 4).await?;
                    let t = u16::from_le_bytes([b[pos], b[pos + 1]]);
                    if t == 0xFFFF {
                        break pos + 2;
                    }
                    let len = u16::from_le_bytes([b[pos + 2], b[pos + 3]]) as usize * 2;
                    pos += 4 + len;
                    if pos > size {
                        break size;
                    }
                }
            };
            self.sii_read_words(position, &mut b, end).await?;
            b.truncate(end);
            Ok(b)
        }
    }

    /// The size of the slave's EEPROM in bytes: the SII's own size word 0x3E (`(n + 1)` ×
    /// 1 Kbit), bounded by what the ESC's address width (0x0502 bit 7) reaches — 2 KiB
    /// (16 Kbit) with one address byte, 512 KiB (4 Mbit) with two — so a blank EEPROM
    /// (0xFFFF) does not claim more than the chip can hold.
    pub fn eeprom_bytes(&self, position: usize) -> Result<usize, MasterError> {
        let ctl = self.runner.block_on(self.read_u16(position, CTL))?;
        let chip = if ctl & 0x0080 != 0 { 512 * 1024 } else { 2048 };
        let w = self
            .runner
            .clone()
            .block_on(self.sii_read_at(position, 0x3E, 2))?;
        let sii = (usize::from(u16::from_le_bytes([w[0], w[1]])) + 1) * 128;
        Ok(sii.min(chip))
    }

    /// Writes one SII word (the EEPROM must be taken).
    async fn sii_write_word(
        &self,
        position: usize,
        w: u16,
        val: [u8; 2],
    ) -> Result<(), MasterError> {
        self.sii_wait(position).await?;
        self.fpwr(position, ADDR, &u32::from(w).to_le_bytes())
            .await?;
        self.fpwr(position, DATA, &val).await?;
        // Write enable (bit 0) with the write command (0x02 in bits 8..10).
        self.fpwr(position, CTL, &[0x01, 0x02]).await?;
        let c = self.sii_wait(position).await?;
        if c & (ERR_ACK | ERR_WE) != 0 {
            return Err(sii_err(
                position,
                format!("write of word 0x{w:04X} refused (0x0502 = 0x{c:04X})"),
            ));
        }
        Ok(())
    }

    /// `alias`: writes `alias` into SII word 4 (configured station alias) of the slave at
    /// `position` with the configuration area's CRC (word 7 low byte, CRC-8 over words 0..6;
    /// ESCs load nothing from an area whose CRC is wrong), verifies both words, and reloads
    /// the configuration area (0x0502 command 0x04, as at power-up) so that the ESC's
    /// 0x0012 holds the new alias at once. Returns 0x0012 after the reload (an ESC that does
    /// not reload keeps the old value until its next power-up).
    pub fn sii_set_alias(&self, position: usize, alias: u16) -> Result<u16, MasterError> {
        self.address(position)?;
        if let Some(c) = self.sii_cache.borrow_mut().get_mut(position) {
            *c = None;
        }
        self.runner.block_on(async {
            let mut area = self.sii_read_at(position, 0, 16).await?;
            if sii_crc8(&area[..14]) != area[14] {
                return Err(sii_err(
                    position,
                    format!(
                        "the configuration area's CRC is wrong (word 7 = 0x{:02X}, computed 0x{:02X}): the SII holds no valid image to set an alias in; write one with sii-write first",
                        area[14],
                        sii_crc8(&area[..14])
                    ),
                ));
            }
            area[8..10].copy_from_slice(&alias.to_le_bytes());
            area[14] = sii_crc8(&area[..14]);
            // The alias first, then the CRC: between the two the area is invalid, as
            // in any word-by-word write of it.
            self.sii_write_word(position, 4, [area[8], area[9]]).await?;
            self.sii_write_word(position, 7, [area[14], area[15]])
                .await?;
            let back = self.sii_read_at(position, 0, 16).await?;
            verify_words(position, &area, &back, [4, 7])?;
            self.sii_wait(position).await?;
            self.fpwr(position, CTL, &[0x00, 0x04]).await?;
            self.sii_wait(position).await?;
            self.read_u16(position, 0x0012).await
        })
    }

    /// Writes `img` into the SII of the slave at `position` word by word and verifies it;
    /// `progress(done, total)` is called after each word.
    pub fn sii_write(
        &self,
        position: usize,
        img: &[u8],
        opts: WriteOptions,
        progress: &mut dyn FnMut(usize, usize),
    ) -> Result<(), MasterError> {
        check_image(img)?;
        let image = image_identity(img)?;
        let (v, p, r, _) = self.identity(position)?;
        if image != (v, p, r) && !opts.force {
            return Err(MasterError::SiiOtherDevice {
                position,
                image,
                slave: (v, p, r),
            });
        }
        if let Some(c) = self.sii_cache.borrow_mut().get_mut(position) {
            *c = None;
        }
        self.runner.block_on(async {
            self.sii_take(position).await?;
            let words = img.len() / 2;
            for w in 0..words {
                self.sii_write_word(position, w as u16, [img[2 * w], img[2 * w + 1]])
                    .await?;
                progress(w + 1, words);
            }
            // Verify.
            let mut back = Vec::new();
            self.sii_read_words(position, &mut back, img.len()).await?;
            verify_words(position, img, &back, 0..words)
        })
    }
}

/// A hex dump of an image, 16 bytes a line with the word address.
pub fn hex_dump(img: &[u8]) -> String {
    let mut s = String::new();
    for (i, c) in img.chunks(16).enumerate() {
        s.push_str(&format!("{:04x}: {}\n", i * 8, crate::value::hex(c)));
    }
    s
}

/// The decoded categories of an image, as text.
pub fn decode(img: &[u8]) -> Result<String, MasterError> {
    use std::fmt::Write;
    let im = SiiImage::new(img).map_err(|e| MasterError::SiiImage(format!("{e}")))?;
    let m = oxicat_esi::sii::parse(img).map_err(|e| MasterError::SiiImage(e.to_string()))?;
    let cfg = im.config();
    let id = im.identity();
    let mut s = String::new();
    let _ = writeln!(s, "Configuration area:");
    let _ = writeln!(s, "  PDI control:     0x{:04x}", cfg.pdi_control);
    let _ = writeln!(s, "  PDI config:      0x{:04x}", cfg.pdi_config);
    let _ = writeln!(s, "  Station alias:   0x{:04x}", cfg.station_alias);
    let _ = writeln!(
        s,
        "  Checksum:        0x{:02x} ({})",
        img[14],
        if im.crc_ok() { "ok" } else { "WRONG" }
    );
    let _ = writeln!(s, "Identity:");
    let _ = writeln!(s, "  Vendor ID:       0x{:08x}", id.vendor_id);
    let _ = writeln!(s, "  Product code:    0x{:08x}", id.product_code);
    let _ = writeln!(s, "  Revision:        0x{:08x}", id.revision);
    let _ = writeln!(s, "  Serial:          0x{:08x}", id.serial);
    let mbx = im.mailbox();
    let _ = writeln!(s, "Mailbox:");
    let _ = writeln!(
        s,
        "  Standard:        rx 0x{:04x}/{} tx 0x{:04x}/{}",
        mbx.standard_rx.offset, mbx.standard_rx.size, mbx.standard_tx.offset, mbx.standard_tx.size
    );
    let _ = writeln!(
        s,
        "  Bootstrap:       rx 0x{:04x}/{} tx 0x{:04x}/{}",
        mbx.bootstrap_rx.offset,
        mbx.bootstrap_rx.size,
        mbx.bootstrap_tx.offset,
        mbx.bootstrap_tx.size
    );
    let mut protos = Vec::new();
    for (bit, n) in [
        (0x01, "AoE"),
        (0x02, "EoE"),
        (0x04, "CoE"),
        (0x08, "FoE"),
        (0x10, "SoE"),
        (0x20, "VoE"),
    ] {
        if mbx.protocols & bit != 0 {
            protos.push(n);
        }
    }
    let _ = writeln!(
        s,
        "  Protocols:       {}",
        if protos.is_empty() {
            "none".into()
        } else {
            protos.join(" ")
        }
    );
    let _ = writeln!(
        s,
        "EEPROM:            {} bytes, version {}",
        im.eeprom_size_bytes(),
        im.version()
    );
    let _ = writeln!(s, "Categories:");
    for c in im.categories() {
        let Ok(c) = c else {
            let _ = writeln!(s, "  (broken category list)");
            break;
        };
        let _ = writeln!(
            s,
            "  word 0x{:04x}: {:?} ({} bytes)",
            c.word_address,
            c.kind,
            c.data.len()
        );
        if c.kind == CategoryType::Strings {
            if let Ok(st) = c.strings() {
                for (i, t) in st.iter().enumerate() {
                    let t = t.unwrap_or(b"?");
                    let _ = writeln!(s, "    string {}: {:?}", i + 1, String::from_utf8_lossy(t));
                }
            }
        }
    }
    let _ = writeln!(s, "General:");
    let _ = writeln!(s, "  Name:            {}", m.name.as_deref().unwrap_or("-"));
    let _ = writeln!(
        s,
        "  Order:           {}",
        m.order_code.as_deref().unwrap_or("-")
    );
    let _ = writeln!(
        s,
        "  Group:           {}",
        m.group_type.as_deref().unwrap_or("-")
    );
    if let Some(c) = m.mailbox.and_then(|x| x.coe) {
        let _ = writeln!(
            s,
            "  CoE:             SDO info {}, PDO assign {}, PDO config {}, complete access {}",
            c.sdo_info, c.pdo_assign, c.pdo_config, c.complete_access
        );
    }
    if !m.fmmus.is_empty() {
        let _ = writeln!(s, "FMMUs:             {:?}", m.fmmus);
    }
    for (i, sm) in m.sms.iter().enumerate() {
        let _ = writeln!(
            s,
            "SM{i}: start 0x{:04x} size {} control 0x{:02x} {} {:?}",
            sm.start,
            sm.default_size.unwrap_or(0),
            sm.control,
            if sm.enable { "enabled" } else { "disabled" },
            sm.kind
        );
    }
    for (dir, list) in [("RxPDO", &m.rx_pdos), ("TxPDO", &m.tx_pdos)] {
        for p in list {
            let _ = writeln!(
                s,
                "{dir} 0x{:04x} \"{}\" SM{}{}",
                p.index,
                p.name.as_deref().unwrap_or(""),
                p.sm.map(|x| x.to_string()).unwrap_or("-".into()),
                if p.fixed { " fixed" } else { "" }
            );
            for e in &p.entries {
                let _ = writeln!(
                    s,
                    "  0x{:04x}:{:02x} {:>2} bit {} \"{}\"",
                    e.index,
                    e.sub,
                    e.bits,
                    e.data_type.map(crate::coe::type_name).unwrap_or_default(),
                    e.name.as_deref().unwrap_or("")
                );
            }
        }
    }
    for d in &m.dc {
        let _ = writeln!(
            s,
            "DC mode \"{}\": AssignActivate 0x{:04x}, cycle0 {}, shift0 {}",
            d.name.as_deref().unwrap_or(""),
            d.assign_activate,
            d.cycle0,
            d.shift0
        );
    }
    Ok(s)
}

/// Compares the `words` of what was written with what was read back; the first that
/// differs is [`MasterError::SiiVerify`].
fn verify_words(
    position: usize,
    wrote: &[u8],
    read: &[u8],
    words: impl IntoIterator<Item = usize>,
) -> Result<(), MasterError> {
    let word = |b: &[u8], w: usize| {
        b.get(2 * w..2 * w + 2)
            .map(|x| u16::from_le_bytes([x[0], x[1]]))
    };
    for w in words {
        let (a, b) = (word(wrote, w), word(read, w));
        if a != b {
            return Err(MasterError::SiiVerify {
                position,
                word: w as u16,
                wrote: a.unwrap_or(0),
                read: b.unwrap_or(0),
            });
        }
    }
    Ok(())
}
