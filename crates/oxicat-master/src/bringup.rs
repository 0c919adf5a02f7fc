//! What a state change needs, configured by the master itself with FPRD/FPWR and no reset
//! (ethercrab's own initialisation resets every slave to INIT): the mailbox SyncManagers
//! from the SII before PRE-OP (or BOOT), free run, process-data SyncManagers and FMMUs
//! before SAFE-OP.

use oxicat_esi::model::SmKind;
use oxicat_wire::regs;

use crate::{AlState, Master, MasterError};

/// SM control byte of a mailbox written by the master (mailbox mode, ECAT writes, IRQ).
const SM_MBX_OUT: u8 = 0x26;
/// SM control byte of a mailbox read by the master.
const SM_MBX_IN: u8 = 0x22;
/// SM control byte of the outputs (3-buffer, ECAT writes, IRQ, watchdog trigger).
const SM_PD_OUT: u8 = 0x64;
/// SM control byte of the inputs (3-buffer, ECAT reads).
const SM_PD_IN: u8 = 0x20;
/// Logical address space given to each slave's process data (`position` × this).
pub const LOGICAL_PER_SLAVE: u32 = 0x0800;

/// The sync mode a master's free-run verbs use: 0x1C32:01 = 0.
pub const FREE_RUN: u16 = 0;
/// SM2-synchronous (0x1C32:01 = 1): what `states` uses for a slave that does not run free.
pub const SM_SYNC: u16 = 1;

/// The sync mode without DC for a slave whose 0x1C32:04 (sync modes supported, ETG.1020)
/// reads `supported`: free run where offered (or not told: no 0x1C32:04, or 0), else
/// SM2-synchronous where offered; `Err(supported)` when neither is (DC only).
pub(crate) fn plain_mode_for(supported: Option<u16>) -> Result<u16, u16> {
    match supported {
        None | Some(0) => Ok(FREE_RUN),
        Some(s) if s & 0x0001 != 0 => Ok(FREE_RUN),
        Some(s) if s & 0x0002 != 0 => Ok(SM_SYNC),
        Some(s) => Err(s),
    }
}

impl Master {
    async fn write_sm(
        &self,
        position: usize,
        sm: u16,
        start: u16,
        len: u16,
        control: u8,
    ) -> Result<(), MasterError> {
        let reg = oxicat_wire::regs::sm(sm as u8, 0);
        // An active SM takes no new configuration: deactivate it first.
        self.fpwr(position, reg + 6, &[0]).await?;
        let s = start.to_le_bytes();
        let l = len.to_le_bytes();
        let on = u8::from(len > 0);
        self.fpwr(position, reg, &[s[0], s[1], l[0], l[1], control, 0, on, 0])
            .await
    }

    /// Mailbox offsets and sizes from the SII fixed area: words 0x18..0x1B (standard) or
    /// 0x14..0x17 (bootstrap).
    async fn sii_mailbox(
        &self,
        position: usize,
        boot: bool,
    ) -> Result<(u16, u16, u16, u16), MasterError> {
        let w = self
            .sii_read_at(position, if boot { 0x14 } else { 0x18 }, 8)
            .await?;
        let u = |k: usize| u16::from_le_bytes([w[k], w[k + 1]]);
        Ok((u(0), u(2), u(4), u(6)))
    }

    /// Configures SM0/SM1 for the mailbox from the SII when they are not, or always with
    /// `fresh` (INIT -> PRE-OP: empty mailbox buffers, as a master does on that step); the
    /// AL state is not touched. Nothing for a slave without a mailbox.
    pub(crate) async fn configure_mailbox(
        &self,
        position: usize,
        fresh: bool,
    ) -> Result<(), MasterError> {
        let (out_start, out_len, in_start, in_len) = self.sii_mailbox(position, false).await?;
        if out_len == 0 || in_len == 0 {
            return Ok(());
        }
        let b = self.fprd(position, 0x0800, 16).await?;
        let u = |i: usize| u16::from_le_bytes([b[i], b[i + 1]]);
        let same = u(0) == out_start
            && u(2) == out_len
            && b[6] & 1 != 0
            && u(8) == in_start
            && u(10) == in_len
            && b[14] & 1 != 0;
        if same && !fresh {
            return Ok(());
        }
        log::info!("slave {position}: configuring the mailbox (SM0/SM1) from the SII");
        self.write_sm(position, 0, out_start, out_len, SM_MBX_OUT)
            .await?;
        self.write_sm(position, 1, in_start, in_len, SM_MBX_IN)
            .await
    }

    /// Configures SM0/SM1 as the bootstrap mailbox from the SII (before BOOT).
    pub(crate) async fn configure_boot_mailbox(&self, position: usize) -> Result<(), MasterError> {
        let (out_start, out_len, in_start, in_len) = self.sii_mailbox(position, true).await?;
        if out_len == 0 || in_len == 0 {
            return self.configure_mailbox(position, true).await;
        }
        self.write_sm(position, 0, out_start, out_len, SM_MBX_OUT)
            .await?;
        self.write_sm(position, 1, in_start, in_len, SM_MBX_IN)
            .await
    }

    /// Sets free run (0x1C32:01 = 0) on a slave whose 0x1C32:01 says otherwise (a DC
    /// recording leaves it at 2 = DC SYNC0); nothing when the slave has no such object.
    /// Returns whether it changed it.
    /// SYNC0/SYNC1 generation (0x0981) is switched off as well: a slave takes DC mode
    /// whenever it sees it on.
    pub(crate) async fn set_free_run(&self, position: usize) -> Result<bool, MasterError> {
        self.set_sync_mode(position, FREE_RUN).await
    }

    /// The sync mode `states` gives a slave for SAFE-OP/OP (no master cycles afterwards), from
    /// 0x1C32:04 (sync modes supported, ETG.1020: bit 0 free run, bit 1 SM-synchronous, bits
    /// 2/3 DC): free run where supported, else SM2-synchronous; `None` without CoE or 0x1C32.
    /// A slave that supports neither (DC only) is [`MasterError::SyncUnsupported`].
    pub(crate) async fn plain_sync_mode(
        &self,
        position: usize,
    ) -> Result<Option<u16>, MasterError> {
        if !self.has_coe(position).await {
            return Ok(None);
        }
        let read = |sub| async move {
            match self.sdo_upload_async(position, 0x1C32, sub).await {
                Ok(b) if b.len() >= 2 => Ok(Some(u16::from_le_bytes([b[0], b[1]]))),
                Ok(_) | Err(MasterError::SdoAbort { .. }) => Ok(None),
                Err(e) => Err(e),
            }
        };
        if read(1).await?.is_none() {
            return Ok(None);
        }
        match plain_mode_for(read(4).await?) {
            Ok(mode) => Ok(Some(mode)),
            Err(s) => Err(MasterError::SyncUnsupported {
                position,
                name: self.name_async(position).await.unwrap_or_default(),
                supported: s,
            }),
        }
    }

    /// Sets 0x1C32:01 (and 0x1C33:01 where it follows DC) to `mode` where it differs and
    /// switches SYNC0/SYNC1 generation (0x0981) off; returns whether it changed the mode.
    pub(crate) async fn set_sync_mode(
        &self,
        position: usize,
        mode: u16,
    ) -> Result<bool, MasterError> {
        if self.fprd(position, regs::DC_ACTIVATION + 1, 1).await?[0] != 0 {
            self.fpwr(position, regs::DC_ACTIVATION + 1, &[0]).await?;
        }
        if !self.has_coe(position).await {
            return Ok(false);
        }
        match self.sdo_upload_async(position, 0x1C32, 1).await {
            Ok(b) if b.len() >= 2 && u16::from_le_bytes([b[0], b[1]]) != mode => {
                log::info!(
                    "slave {position}: sync mode 0x1C32:01 = {} -> {mode}",
                    u16::from_le_bytes([b[0], b[1]])
                );
                self.sdo_download_async(position, 0x1C32, 1, &mode.to_le_bytes())
                    .await?;
                // Outputs follow the inputs' sync mode where 0x1C33 exists.
                if let Ok(b) = self.sdo_upload_async(position, 0x1C33, 1).await {
                    if b.len() >= 2 && u16::from_le_bytes([b[0], b[1]]) == 2 {
                        let _ = self
                            .sdo_download_async(position, 0x1C33, 1, &mode.to_le_bytes())
                            .await;
                    }
                }
                Ok(true)
            }
            Ok(_) => Ok(false),
            Err(MasterError::SdoAbort { .. }) => Ok(false),
            Err(e) => Err(e),
        }
    }

    /// 0x1C32:01 of the slave, `None` without CoE, in INIT, or without the object.
    pub(crate) async fn sync_mode_async(
        &self,
        position: usize,
    ) -> Result<Option<u16>, MasterError> {
        if !self.has_coe(position).await {
            return Ok(None);
        }
        match self.sdo_upload_async(position, 0x1C32, 1).await {
            Ok(b) if b.len() >= 2 => Ok(Some(u16::from_le_bytes([b[0], b[1]]))),
            Ok(_) | Err(MasterError::SdoAbort { .. }) => Ok(None),
            Err(e) => Err(e),
        }
    }

    /// Whether the slave's SII names CoE and it is in a state with CoE (PREOP, SAFEOP, OP:
    /// INIT has no mailbox, BOOT only FoE, ETG.1000.6).
    pub(crate) async fn has_coe(&self, position: usize) -> bool {
        let Ok(img) = self.sii_image(position).await else {
            return false;
        };
        let Ok(m) = oxicat_esi::sii::parse(&img) else {
            return false;
        };
        m.mailbox.and_then(|m| m.coe).is_some()
            && self
                .al_status_async(position)
                .await
                .ok()
                .and_then(|s| s.state())
                .is_some_and(|s| matches!(s, AlState::PreOp | AlState::SafeOp | AlState::Op))
    }

    /// Configures SM2/SM3 (sized from the PDO mapping, start and control from the SII) and
    /// FMMU0 (outputs) / FMMU1 (inputs) at logical `position × LOGICAL_PER_SLAVE`, and turns
    /// the process-data watchdog off; in PRE-OP, before SAFE-OP.
    pub(crate) async fn configure_pd(&self, position: usize) -> Result<(), MasterError> {
        let img = self.sii_image(position).await?;
        let model =
            oxicat_esi::sii::parse(&img).map_err(|e| MasterError::SiiImage(e.to_string()))?;
        let layout = self.pdos(position)?;
        let bytes = |list: &[crate::pdo::Pdo]| -> u16 {
            let bits: u32 = list
                .iter()
                .flat_map(|p| p.entries.iter())
                .map(|e| e.bits as u32)
                .sum();
            bits.div_ceil(8) as u16
        };
        let (out_len, in_len) = (bytes(&layout.rx), bytes(&layout.tx));
        let logical = position as u32 * LOGICAL_PER_SLAVE;
        let mut fmmu = 0u16;
        for (kind, len, control, ty, log_off) in [
            (SmKind::Outputs, out_len, SM_PD_OUT, 2u8, 0u32),
            (SmKind::Inputs, in_len, SM_PD_IN, 1u8, out_len as u32),
        ] {
            let (sm, start, control) = match model.sms.iter().position(|s| s.kind == kind) {
                Some(i) => {
                    let s = &model.sms[i];
                    (
                        i as u16,
                        s.start,
                        if s.control != 0 { s.control } else { control },
                    )
                }
                None if len == 0 => continue,
                None => {
                    return Err(MasterError::SiiImage(format!(
                        "slave {position}: the SII has no {kind:?} SyncManager for {len} bytes"
                    )))
                }
            };
            self.write_sm(position, sm, start, len, control).await?;
            if len == 0 {
                continue;
            }
            let reg = oxicat_wire::regs::fmmu(fmmu as u8, 0);
            let mut f = [0u8; 16];
            f[0..4].copy_from_slice(&(logical + log_off).to_le_bytes());
            f[4..6].copy_from_slice(&len.to_le_bytes());
            f[6] = 0; // logical start bit
            f[7] = 7; // logical end bit
            f[8..10].copy_from_slice(&start.to_le_bytes());
            f[10] = 0; // physical start bit
            f[11] = ty; // 1 read (inputs), 2 write (outputs)
            f[12] = 1; // active
            self.fpwr(position, reg + 12, &[0]).await?;
            self.fpwr(position, reg, &f).await?;
            fmmu += 1;
        }
        // No cyclic master keeps the SM watchdog fed once the command has ended.
        self.fpwr(position, regs::WD_TIME_PD, &[0, 0]).await
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn without_dc_a_slave_runs_free_where_it_can_else_sm_synchronous() {
        assert_eq!(plain_mode_for(None), Ok(FREE_RUN), "not told");
        assert_eq!(plain_mode_for(Some(0)), Ok(FREE_RUN));
        assert_eq!(plain_mode_for(Some(0x000F)), Ok(FREE_RUN));
        // The TUeES030: SM-synchronous only (0x1C32:04 = 0x0002).
        assert_eq!(plain_mode_for(Some(0x0002)), Ok(SM_SYNC));
        assert_eq!(plain_mode_for(Some(0x000E)), Ok(SM_SYNC));
        assert_eq!(plain_mode_for(Some(0x000C)), Err(0x000C), "DC only");
    }
}
