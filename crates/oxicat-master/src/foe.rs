//! FoE (file access over EtherCAT) client over the slave's mailbox: file read and write
//! with busy handling, error decoding and a progress callback, and the bootstrap walk
//! (INIT → BOOT with the SII's bootstrap mailbox, back to INIT) a firmware download uses,
//! as TwinCAT does.

use std::time::{Duration, Instant};

use oxicat_wire::foe::{FoeErrorCode, FoeHeader, FoeRef, FOE_HEADER_LEN};
use oxicat_wire::mailbox::{MailboxType, MAILBOX_HEADER_LEN};

use crate::coe::Mbx;
use crate::{AlState, Master, MasterError};

/// Progress of a transfer: bytes done and total (total 0 when unknown, i.e. reads).
pub type Progress<'a> = &'a mut dyn FnMut(usize, usize);

fn foe_err(position: usize, code: FoeErrorCode, text: &[u8]) -> MasterError {
    let t = String::from_utf8_lossy(text)
        .trim_end_matches('\0')
        .to_string();
    MasterError::Foe {
        position,
        code: code.code(),
        text: if t.is_empty() || t == code.text() {
            code.text().to_string()
        } else {
            format!("{}: {t}", code.text())
        },
    }
}

fn protocol(position: usize, what: impl Into<String>) -> MasterError {
    MasterError::Mailbox {
        position,
        what: what.into(),
    }
}

impl Master {
    /// Sends one FoE message; with `reply`, waits for the FoE answer (header + data).
    async fn foe_exchange(
        &self,
        position: usize,
        m: &Mbx,
        h: FoeHeader,
        data: &[u8],
        reply: bool,
    ) -> Result<Option<(FoeHeader, Vec<u8>)>, MasterError> {
        let mut p = vec![0u8; FOE_HEADER_LEN + data.len()];
        FoeRef::write(&h, data, &mut p).map_err(|e| protocol(position, format!("{e}")))?;
        let counter = self.next_counter(position);
        self.mbx_send(position, m, MailboxType::Foe, &p, counter)
            .await?;
        if !reply {
            return Ok(None);
        }
        let r = self
            .mbx_receive(position, m, MailboxType::Foe, self.options.mailbox_timeout)
            .await?
            .ok_or_else(|| MasterError::NotAnswering {
                position,
                what: "no FoE reply".into(),
            })?;
        let f = FoeRef::parse(&r).map_err(|e| protocol(position, format!("bad FoE reply: {e}")))?;
        Ok(Some((f.header, f.data.to_vec())))
    }

    async fn foe_open(&self, position: usize) -> Result<Mbx, MasterError> {
        let m = self.mbx_for(position).await?;
        // Drop a stale reply.
        let st = self.fprd(position, 0x080D, 1).await?;
        if st[0] & 0x08 != 0 {
            self.fprd(position, m.in_start, m.in_len).await?;
        }
        Ok(m)
    }

    /// Writes `data` as file `name` to the slave at `position` (FoE write). A BUSY reply
    /// makes the same packet go again (for up to the mailbox timeout of no progress);
    /// `progress(done, total)` follows the acknowledged bytes.
    pub fn foe_write(
        &self,
        position: usize,
        name: &str,
        password: u32,
        data: &[u8],
        progress: Progress<'_>,
    ) -> Result<(), MasterError> {
        self.runner.block_on(async {
            let m = self.foe_open(position).await?;
            let seg = m.out_len as usize - MAILBOX_HEADER_LEN - FOE_HEADER_LEN;
            let total = data.len();
            let mut packet = 0u32;
            let mut off = 0usize;
            let mut busy_since: Option<Instant> = None;
            loop {
                let (h, n) = if packet == 0 {
                    (FoeHeader::Write { password }, 0)
                } else {
                    (FoeHeader::Data { packet }, (total - off).min(seg))
                };
                let body = if packet == 0 {
                    name.as_bytes()
                } else {
                    &data[off..off + n]
                };
                let r = self.foe_exchange(position, &m, h, body, true).await?;
                let (rh, rd) = r.ok_or_else(|| protocol(position, "no FoE reply"))?;
                match rh {
                    FoeHeader::Ack { packet: p } if p == packet => {
                        busy_since = None;
                        off += n;
                        progress(off, total);
                        if packet > 0 && n < seg {
                            return Ok(());
                        }
                        packet += 1;
                    }
                    FoeHeader::Busy { done, entire } => {
                        log::debug!("slave {position}: FoE busy {done}/{entire}");
                        let t0 = *busy_since.get_or_insert_with(Instant::now);
                        if t0.elapsed() > self.options.mailbox_timeout.max(Duration::from_secs(10))
                        {
                            return Err(MasterError::NotAnswering {
                                position,
                                what: "the slave stays busy (FoE)".into(),
                            });
                        }
                        self.pause().await;
                    }
                    FoeHeader::Error { code } => return Err(foe_err(position, code, &rd)),
                    o => {
                        return Err(protocol(
                            position,
                            format!("unexpected FoE reply {o:?} to packet {packet}"),
                        ))
                    }
                }
            }
        })
    }

    /// Reads file `name` from the slave at `position` (FoE read); `progress(done, 0)`
    /// follows the received bytes.
    pub fn foe_read(
        &self,
        position: usize,
        name: &str,
        password: u32,
        progress: Progress<'_>,
    ) -> Result<Vec<u8>, MasterError> {
        self.runner.block_on(async {
            let m = self.foe_open(position).await?;
            let seg = m.in_len as usize - MAILBOX_HEADER_LEN - FOE_HEADER_LEN;
            let mut out = Vec::new();
            let mut r = self
                .foe_exchange(
                    position,
                    &m,
                    FoeHeader::Read { password },
                    name.as_bytes(),
                    true,
                )
                .await?;
            let mut expect = 1u32;
            loop {
                let (h, d) = r.ok_or_else(|| protocol(position, "no FoE reply"))?;
                match h {
                    FoeHeader::Data { packet } if packet == expect => {
                        out.extend_from_slice(&d);
                        progress(out.len(), 0);
                        let last = d.len() < seg;
                        r = self
                            .foe_exchange(position, &m, FoeHeader::Ack { packet }, &[], !last)
                            .await?;
                        if last {
                            return Ok(out);
                        }
                        expect += 1;
                    }
                    FoeHeader::Error { code } => return Err(foe_err(position, code, &d)),
                    o => {
                        return Err(protocol(
                            position,
                            format!("unexpected FoE reply {o:?} (expected data packet {expect})"),
                        ))
                    }
                }
            }
        })
    }

    /// Takes the slave at `position` to BOOT: INIT first, SM0/SM1 set to the bootstrap
    /// mailbox of its SII (words 0x14..0x17), then BOOT.
    pub fn enter_boot(&mut self, position: usize) -> Result<(), MasterError> {
        self.request_state(&[position], AlState::Init)?;
        let sii = self.sii_read(position, false)?;
        let w = |i: usize| {
            sii.get(2 * i..2 * i + 2)
                .map(|b| u16::from_le_bytes([b[0], b[1]]))
                .unwrap_or(0)
        };
        let (rx, rxl, tx, txl) = (w(0x14), w(0x15), w(0x16), w(0x17));
        if rxl < 16 || txl < 16 {
            return Err(protocol(
                position,
                "the SII has no bootstrap mailbox (words 0x14..0x17): BOOT not supported",
            ));
        }
        let sm = |start: u16, len: u16, ctrl: u8| {
            let mut r = [0u8; 8];
            r[0..2].copy_from_slice(&start.to_le_bytes());
            r[2..4].copy_from_slice(&len.to_le_bytes());
            r[4] = ctrl;
            r[6] = 1;
            r
        };
        self.reg_write(position, 0x0800, &sm(rx, rxl, 0x26))?;
        self.reg_write(position, 0x0808, &sm(tx, txl, 0x22))?;
        self.request_state(&[position], AlState::Boot)?;
        Ok(())
    }

    /// Takes the slave at `position` from BOOT back to INIT and restores SM0/SM1 to the
    /// standard mailbox of its SII (words 0x18..0x1B).
    pub fn leave_boot(&mut self, position: usize) -> Result<(), MasterError> {
        self.request_state(&[position], AlState::Init)?;
        let sii = self.sii_read(position, false)?;
        let w = |i: usize| {
            sii.get(2 * i..2 * i + 2)
                .map(|b| u16::from_le_bytes([b[0], b[1]]))
                .unwrap_or(0)
        };
        let sm = |start: u16, len: u16, ctrl: u8| {
            let mut r = [0u8; 8];
            r[0..2].copy_from_slice(&start.to_le_bytes());
            r[2..4].copy_from_slice(&len.to_le_bytes());
            r[4] = ctrl;
            r[6] = u8::from(len > 0);
            r
        };
        self.reg_write(position, 0x0800, &sm(w(0x18), w(0x19), 0x26))?;
        self.reg_write(position, 0x0808, &sm(w(0x1A), w(0x1B), 0x22))?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_text() {
        let e = foe_err(3, FoeErrorCode::ProgramError, b"image for another device");
        assert_eq!(
            e.to_string(),
            "slave 3: FoE error 0x800B: Program Error: image for another device"
        );
        let e = foe_err(0, FoeErrorCode::NotBootstrap, b"Not Bootstrap");
        assert_eq!(e.to_string(), "slave 0: FoE error 0x8009: Not Bootstrap");
    }
}
