//! Cyclic process data: bring the slaves to OP (free run, or DC SYNC0-synchronous), exchange
//! the process image every cycle, and give each cycle's inputs/outputs to a callback —
//! the base of `watch`, `write` and `record`.

use oxicat_wire::regs;
use std::io::Write;
use std::time::Duration;

use ethercrab::subdevice_group::DcConfiguration;
use ethercrab::DcSync;

use crate::pdo::{Dir, SlavePdos, Variable};
use crate::{Master, MasterError, Slot};

/// How the master cycles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CycleOptions {
    /// Cycle time.
    pub cycle: Duration,
    /// DC SYNC0-synchronous (every slave with DC support); otherwise each slave free run,
    /// or SM-synchronous (0x1C32:01 = 1) where its 0x1C32:04 offers that and not free run.
    pub dc: bool,
}

/// Longest DC cycle: the SYNC0 cycle time (0x09A0) and the start time, four cycles ahead,
/// are 32-bit ns in the ESC's DC unit and in ethercrab's configuration.
pub const MAX_DC_CYCLE: Duration = Duration::from_secs(1);

impl CycleOptions {
    /// Refuses a cycle that cannot work: 0, or a DC cycle above [`MAX_DC_CYCLE`].
    pub fn check(&self) -> Result<(), MasterError> {
        if self.cycle.is_zero() {
            return Err(MasterError::Usage("the cycle time must be above 0".into()));
        }
        if self.dc && self.cycle > MAX_DC_CYCLE {
            return Err(MasterError::Usage(format!(
                "a DC cycle of {:?} does not fit: the SYNC0 cycle and start time are 32-bit ns, \
                 at most {:?} (use --free-run for slower cycles)",
                self.cycle, MAX_DC_CYCLE
            )));
        }
        Ok(())
    }
}

/// How the slaves synchronise their application to the master's cycle (ETG.1020: the sync
/// mode 0x1C32:01 each slave is given, checked against its 0x1C32:04 "sync modes
/// supported"). [`SyncMode::Auto`] is what [`CycleOptions`] alone does; the others are
/// explicit and refused, before any slave is changed, when a slave's 0x1C32:04 does not
/// offer them ([`MasterError::SyncModeUnsupported`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SyncMode {
    /// As [`CycleOptions::dc`] says: with `dc`, DC SYNC0 on every slave whose ESC has the DC
    /// unit (free run when none has); without, each slave free run, or SM-synchronous where
    /// its 0x1C32:04 offers that and not free run.
    #[default]
    Auto,
    /// Free run (0x1C32:01 = 0, 0x1C32:04 bit 0): the slave runs its cycle on its own timer.
    FreeRun,
    /// SM-synchronous (0x1C32:01 = 1, 0x1C32:04 bit 1): the slave runs its cycle on the SM2
    /// event (PDI interrupt) when the master's frame has written its outputs.
    SmSync,
    /// DC SYNC0-synchronous (0x1C32:01 = 2, 0x1C32:04 bits 2..3) on every slave: SYNC0 at the
    /// cycle time, half a cycle after the frame.
    Dc,
}

impl SyncMode {
    /// 0x1C32:01 of the mode (`None` for [`SyncMode::Auto`], which is chosen per slave).
    pub fn code(self) -> Option<u16> {
        match self {
            Self::Auto => None,
            Self::FreeRun => Some(crate::bringup::FREE_RUN),
            Self::SmSync => Some(crate::bringup::SM_SYNC),
            Self::Dc => Some(2),
        }
    }

    /// Whether a slave whose 0x1C32:04 reads `supported` offers the mode (0 or no object:
    /// the slave does not say, and is taken at its word).
    pub fn offered_by(self, supported: Option<u16>) -> bool {
        let Some(s) = supported.filter(|&s| s != 0) else {
            return true;
        };
        match self {
            Self::Auto => true,
            Self::FreeRun => s & 0x0001 != 0,
            Self::SmSync => s & 0x0002 != 0,
            Self::Dc => s & 0x000C != 0,
        }
    }
}

impl std::fmt::Display for SyncMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Auto => {
                "automatic (free run, or SM-synchronous where that is all a slave offers)"
            }
            Self::FreeRun => "free run (0x1C32:01 = 0)",
            Self::SmSync => "SM-synchronous (0x1C32:01 = 1)",
            Self::Dc => "DC SYNC0 (0x1C32:01 = 2)",
        })
    }
}

/// [`CycleOptions`] with an explicit [`SyncMode`]: what the cyclic functions take
/// (`CycleOptions` converts to it with [`SyncMode::Auto`], so existing callers are unchanged).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Cycling {
    /// Cycle time and the DC flag [`SyncMode::Auto`] follows.
    pub options: CycleOptions,
    /// The sync mode.
    pub sync: SyncMode,
}

impl From<CycleOptions> for Cycling {
    fn from(options: CycleOptions) -> Self {
        Self {
            options,
            sync: SyncMode::Auto,
        }
    }
}

impl CycleOptions {
    /// These options with the sync mode `sync` (`dc` then only matters for [`SyncMode::Auto`]).
    pub fn with_sync(self, sync: SyncMode) -> Cycling {
        Cycling {
            options: self,
            sync,
        }
    }
}

impl Cycling {
    /// Whether the run is DC-synchronous.
    pub fn dc(&self) -> bool {
        match self.sync {
            SyncMode::Auto => self.options.dc,
            SyncMode::Dc => true,
            SyncMode::FreeRun | SyncMode::SmSync => false,
        }
    }

    /// [`CycleOptions::check`] for the mode; `dc` set with an explicit mode without DC is
    /// refused as a contradiction.
    pub fn check(&self) -> Result<(), MasterError> {
        if self.options.dc && matches!(self.sync, SyncMode::FreeRun | SyncMode::SmSync) {
            return Err(MasterError::Usage(format!(
                "DC cycling (dc = true) and the sync mode {} contradict each other",
                self.sync
            )));
        }
        CycleOptions {
            cycle: self.options.cycle,
            dc: self.dc(),
        }
        .check()
    }
}

impl Default for CycleOptions {
    fn default() -> Self {
        Self {
            cycle: Duration::from_millis(1),
            dc: false,
        }
    }
}

/// How a free-running cycle exchanges the process image (DC cycles always use ethercrab's
/// `tx_rx_dc`: its FRMW of the reference clock's time rides in the same frame).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Exchange {
    /// [`Exchange::Lean`] when ethercrab's exchange would need more than one frame and the
    /// lean one needs no more frames than it, else [`Exchange::Ethercrab`] (a small
    /// segment's image and status reads fit one frame, which the lean exchange would make
    /// two).
    #[default]
    Auto,
    /// The image in LRWs of up to 1,100 bytes sent together, and one BRD of AL status
    /// that every slave answers (SOEM's pattern): a frame per 1,100 bytes of process data
    /// plus one, whatever the number of slaves. The working counter of each LRW is planned
    /// from the slaves' FMMUs; a segment whose FMMUs are not the group's image cycles as
    /// [`Exchange::Ethercrab`].
    Lean,
    /// [`Exchange::Lean`] with every slave's inputs on the logical bytes of its outputs
    /// (SOEM's overlapped IO map, `ecx_config_overlap_map`): before the first cycle each
    /// slave's FMMUs are moved so that it gets max(outputs, inputs) bytes of the image
    /// instead of their sum, and each ESC takes its outputs from the bytes as they arrive
    /// and puts its inputs in their place; the FMMUs are moved back when the run ends. A
    /// demo device's 24 output and 22 input bytes take 24 bytes of an LRW instead of 46.
    /// Segments whose FMMUs cannot be moved (bit-wise FMMUs) cycle as [`Exchange::Lean`].
    Overlapped,
    /// ethercrab's `tx_rx`: frames one after the other, each with as many per-slave FPRDs
    /// of AL status as fit (at 1,000 slaves, 11 frames and 14 KB of status reads a cycle).
    Ethercrab,
}

/// The process image of one cycle, per slave.
pub struct CycleIo {
    /// Cycle number (0 = first cycle in OP).
    pub cycle: u64,
    /// Time of the cycle in ns (virtual on a simulated segment), from the first cycle.
    pub time_ns: u64,
    /// Outputs the master sends (per slave), kept from cycle to cycle.
    pub outputs: Vec<Vec<u8>>,
    /// Inputs received in this cycle (per slave).
    pub inputs: Vec<Vec<u8>>,
    /// Working counter of the cycle.
    pub working_counter: u16,
}

impl CycleIo {
    /// The current value of a variable (outputs: what the master sends).
    pub fn get(&self, v: &Variable) -> Vec<u8> {
        let img = match v.dir {
            Dir::Output => self.outputs.get(v.position),
            Dir::Input => self.inputs.get(v.position),
        };
        img.map(|i| v.get(i)).unwrap_or_default()
    }

    /// Sets an output variable (inputs cannot be written).
    pub fn set(&mut self, v: &Variable, value: &[u8]) -> Result<(), MasterError> {
        if v.dir != Dir::Output {
            return Err(MasterError::Usage(format!(
                "{} is an input (TxPDO) of slave {}; only outputs can be written",
                v.name, v.position
            )));
        }
        if let Some(img) = self.outputs.get_mut(v.position) {
            v.set(img, value);
        }
        Ok(())
    }
}

/// What the callback wants after a cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Flow {
    /// Run another cycle.
    Continue,
    /// Stop.
    Stop,
}

/// Statistics of a cyclic run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CycleStats {
    /// Cycles run in OP.
    pub cycles: u64,
    /// Cycles whose working counter was not the expected one.
    pub wkc_errors: u64,
    /// How the cycles exchanged the process image ([`Exchange::Lean`] or
    /// [`Exchange::Ethercrab`]; DC cycles: ethercrab's).
    pub exchange: Exchange,
    /// EtherCAT frames per cycle (free run; 0 for DC cycles, whose count ethercrab decides).
    pub frames_per_cycle: usize,
}

impl Master {
    /// The process-data watchdog of the slave at `position` (0x0400 divider, 0x0420 time:
    /// `(divider + 2) × 40 ns × time`), when its output SM triggers it (SII SM control bit
    /// 6) and it is on (time ≠ 0).
    pub fn pd_watchdog(&self, position: usize) -> Result<Option<Duration>, MasterError> {
        let triggers = self.sii_model(position).ok().is_some_and(|m| {
            m.sms
                .iter()
                .any(|sm| sm.kind == oxicat_esi::model::SmKind::Outputs && sm.control & 0x40 != 0)
        });
        if !triggers {
            return Ok(None);
        }
        let div = self.reg_read(position, regs::WD_DIVIDER, 2)?;
        let time = self.reg_read(position, regs::WD_TIME_PD, 2)?;
        let div = u64::from(u16::from_le_bytes([div[0], div[1]]));
        let time = u64::from(u16::from_le_bytes([time[0], time[1]]));
        Ok((time != 0).then(|| Duration::from_nanos((div + 2) * 40 * time)))
    }

    /// Refuses a cycle at or above a slave's process-data watchdog (the slave would clear
    /// its outputs and leave OP, AL status 0x001B, between two frames) or below its minimum
    /// cycle time 0x1C32:05 (it would refuse SAFE-OP and the transition time out).
    fn check_watchdogs(&self, cycle: Duration) -> Result<(), MasterError> {
        for p in 0..self.len() {
            if let Ok(b) = self.sdo_upload(p, 0x1C32, 5) {
                if let Ok(b) = <[u8; 4]>::try_from(b.as_slice()) {
                    let min = Duration::from_nanos(u64::from(u32::from_le_bytes(b)));
                    if cycle < min {
                        return Err(MasterError::Usage(format!(
                            "a cycle of {cycle:?} is below slave {p}'s minimum cycle time of \
                             {min:?} (0x1C32:05); use {min:?} or more"
                        )));
                    }
                }
            }
            if let Some(wd) = self.pd_watchdog(p)? {
                if cycle >= wd {
                    return Err(MasterError::Usage(format!(
                        "a cycle of {cycle:?} is not below slave {p}'s process-data watchdog of \
                         {wd:?} (0x0400/0x0420): it would drop its outputs and leave OP (AL \
                         status 0x001B) between two frames; use a cycle below {wd:?}"
                    )));
                }
            }
        }
        Ok(())
    }

    /// The error for slaves that did not reach OP: every slave's AL status.
    fn left_op(&self) -> MasterError {
        let mut states = Vec::new();
        for p in 0..self.len() {
            match self.al_status(p) {
                Ok(s) => states.push(format!("slave {p}: {s}")),
                Err(e) => states.push(format!("slave {p}: {e}")),
            }
        }
        MasterError::Usage(format!(
            "the slaves did not reach OP: {}",
            states.join("; ")
        ))
    }

    /// The PDO layouts of all slaves.
    pub fn layouts(&self) -> Result<Vec<SlavePdos>, MasterError> {
        (0..self.len()).map(|p| self.pdos(p)).collect()
    }

    /// Resolves variable names (see [`crate::pdo::resolve`]).
    pub fn resolve(
        &self,
        names: &[String],
        layouts: &[SlavePdos],
    ) -> Result<Vec<Vec<Variable>>, MasterError> {
        let slave_names = (0..self.len())
            .map(|p| self.name(p))
            .collect::<Result<Vec<String>, _>>()?;
        names
            .iter()
            .map(|n| crate::pdo::resolve(n, layouts, &slave_names))
            .collect()
    }

    /// How free-running cycles exchange the process image (default [`Exchange::Auto`]).
    pub fn set_exchange(&mut self, exchange: Exchange) {
        self.exchange = exchange;
    }

    /// The plan of a [`Exchange::Lean`] cycle from every slave's active FMMUs (read from
    /// its ESC) and the group's image sizes; `None` (with the reason logged) when they do
    /// not match and the run should keep ethercrab's exchange.
    async fn lean_plan(
        &self,
        out_len: &[usize],
        in_len: &[usize],
        overlap: bool,
    ) -> Option<crate::exchange::Plan> {
        let mut fmmus = Vec::with_capacity(self.len());
        for p in 0..self.len() {
            let read = async {
                let count = self.fprd(p, regs::FMMU_COUNT, 1).await?[0].min(16);
                let b = self
                    .fprd(p, regs::FMMU_BASE, u16::from(count) * regs::FMMU_LEN)
                    .await?;
                Ok::<_, MasterError>(
                    b.chunks(usize::from(regs::FMMU_LEN))
                        .enumerate()
                        .filter_map(|(k, b)| crate::exchange::Fmmu::decode(k as u8, b))
                        .collect::<Vec<_>>(),
                )
            };
            match read.await {
                Ok(f) => fmmus.push(f),
                Err(e) => {
                    log::info!("slave {p}: FMMUs not read ({e}); cycling with ethercrab's tx_rx");
                    return None;
                }
            }
        }
        if overlap {
            match crate::exchange::overlapped(&fmmus) {
                Some((layout, moves)) => {
                    if let Some(mut plan) = crate::exchange::Plan::new(&layout, out_len, in_len) {
                        match self.move_fmmus(&moves).await {
                            Ok(()) => {
                                plan.moved = moves;
                                return Some(plan);
                            }
                            Err(e) => log::info!("FMMUs not moved ({e}); cycling without overlap"),
                        }
                    }
                }
                None => {
                    log::info!("some FMMU maps bits or both directions; cycling without overlap")
                }
            }
        }
        let plan = crate::exchange::Plan::new(&fmmus, out_len, in_len);
        if plan.is_none() {
            log::info!(
                "the slaves' FMMUs are not the group's process image; cycling with ethercrab's tx_rx"
            );
        }
        plan
    }

    /// Makes `moves`; when a slave does not answer, moves back the ones made before it.
    async fn move_fmmus(&self, moves: &[crate::exchange::Move]) -> Result<(), MasterError> {
        for (k, m) in moves.iter().enumerate() {
            if let Err(e) = self.move_fmmu(m.slave, m.index, m.to).await {
                self.move_fmmus_back(&moves[..k]).await;
                return Err(e);
            }
        }
        Ok(())
    }

    /// Writes the logical start address of FMMU `index` of the slave at `position`.
    async fn move_fmmu(&self, position: usize, index: u8, to: u32) -> Result<(), MasterError> {
        let reg = regs::FMMU_BASE + regs::FMMU_LEN * u16::from(index);
        self.fpwr(position, reg, &to.to_le_bytes()).await
    }

    /// Moves the FMMUs of `moves` back where ethercrab put them (its own exchange and
    /// every later user of the group expect them there); stops at the first slave that
    /// does not answer (a pulled cable would make every further write wait its timeout),
    /// and says so.
    async fn move_fmmus_back(&self, moves: &[crate::exchange::Move]) {
        for m in moves {
            if let Err(e) = self.move_fmmu(m.slave, m.index, m.from).await {
                log::warn!(
                    "overlapped FMMUs not moved back from slave {} on ({e}): its process \
                     data is not where ethercrab's image has it",
                    m.slave
                );
                return;
            }
        }
    }

    /// Cyclic runs end by just stopping, leaving the slaves in OP as a master that crashed
    /// or lost its link would (to test what a slave's watchdog does then); by default they
    /// take the slaves back to PRE-OP.
    pub fn stop_cycling_as_if_gone(&mut self) {
        self.preop_after_cycling = false;
    }

    /// Lets ethercrab initialise the segment for cyclic use (every slave through INIT to
    /// PRE-OP, whatever state it was in), so that the PDO layouts can be read from slaves
    /// that were in INIT; [`Master::run_cyclic`] does it itself when not done before.
    pub fn prepare_cyclic(&mut self) -> Result<(), MasterError> {
        self.ensure_group()
    }

    /// [`Master::run_cyclic`] for exactly `cycles` cycles with nothing to do between them
    /// (process data as the slaves and the master's defaults leave it).
    pub fn run_cycles(
        &mut self,
        opts: impl Into<Cycling>,
        cycles: u64,
    ) -> Result<CycleStats, MasterError> {
        self.run_cyclic(opts, |io| {
            Ok(if io.cycle + 1 >= cycles {
                Flow::Stop
            } else {
                Flow::Continue
            })
        })
    }

    /// Brings the slaves to OP, calls `step` after every cycle until it says stop, and
    /// takes them back to PRE-OP (no master cycles afterwards: in SAFE-OP/OP the
    /// process-data watchdog would leave them in SAFEOP+ERR 0x001B).
    pub fn run_cyclic(
        &mut self,
        opts: impl Into<Cycling>,
        step: impl FnMut(&mut CycleIo) -> Result<Flow, MasterError>,
    ) -> Result<CycleStats, MasterError> {
        let r = self.run_cyclic_op(opts.into(), step);
        // Not when another master changed the segment: leave it to that master.
        if self.preop_after_cycling && !matches!(r, Err(MasterError::Disturbed { .. })) {
            let all: Vec<usize> = (0..self.len()).collect();
            if let Err(e) = self.request_state(&all, crate::AlState::PreOp) {
                log::warn!("after cycling: the slaves did not all return to PRE-OP: {e}");
            }
        }
        r
    }

    /// After a cycle that went wrong (working counter off, or no frame back): the slaves
    /// that left OP under this master, as an error that says so; `None` when all are
    /// still in OP without error (a lost frame: counted, cycling goes on).
    async fn disturbed(&self, cycles: u64, cause: Option<String>) -> Option<MasterError> {
        let mut seen = Vec::new();
        for p in 0..self.len() {
            match self.al_status_async(p).await {
                Ok(st) if st.state() == Some(crate::AlState::Op) && !st.error() => {}
                Ok(st) => seen.push(format!("slave {p} is in {st}")),
                Err(e) => seen.push(format!("slave {p}: {e}")),
            }
        }
        if seen.is_empty() && cause.is_none() {
            return None;
        }
        let mut what = seen.join(", ");
        if let Some(c) = cause {
            if !what.is_empty() {
                what.push_str("; ");
            }
            what.push_str(&c);
        }
        Some(MasterError::Disturbed { cycles, what })
    }

    /// The error for a cyclic exchange whose frames did not come back after `cycles`
    /// good cycles: what [`Master::disturbed`] sees, with the lost frames as the cause.
    async fn frames_lost(&self, cycles: u64, err: ethercrab::error::Error) -> MasterError {
        let cause = format!(
            "cyclic exchange: {err} (frames did not come back: another master on the same interface takes them?)"
        );
        self.disturbed(cycles, Some(cause))
            .await
            .unwrap_or_else(|| MasterError::Ethercrab("cyclic exchange".into(), err))
    }

    /// 0x1C32:04 (sync modes supported) of the slave: `None` without CoE, without 0x1C32
    /// or without the subindex.
    async fn sync_supported(&self, position: usize) -> Result<Option<u16>, MasterError> {
        if self.sync_mode_async(position).await?.is_none() {
            return Ok(None);
        }
        match self.sdo_upload_async(position, 0x1C32, 4).await {
            Ok(b) if b.len() >= 2 => Ok(Some(u16::from_le_bytes([b[0], b[1]]))),
            Ok(_) | Err(MasterError::SdoAbort { .. }) => Ok(None),
            Err(e) => Err(e),
        }
    }

    /// Refuses an explicit sync mode a slave does not offer (its 0x1C32:04, or an ESC
    /// without SYNC0 for DC), before any slave is changed.
    fn check_sync(&self, sync: SyncMode, dc_support: &[bool]) -> Result<(), MasterError> {
        if sync == SyncMode::Auto {
            return Ok(());
        }
        for p in 0..self.len() {
            let supported = self.runner.block_on(self.sync_supported(p))?;
            let esc_dc = dc_support.get(p).copied().unwrap_or(false);
            if !sync.offered_by(supported) || (sync == SyncMode::Dc && !esc_dc) {
                return Err(MasterError::SyncModeUnsupported {
                    position: p,
                    name: self.name(p).unwrap_or_default(),
                    mode: sync,
                    supported,
                    esc_dc,
                });
            }
        }
        Ok(())
    }

    fn run_cyclic_op(
        &mut self,
        opts: Cycling,
        mut step: impl FnMut(&mut CycleIo) -> Result<Flow, MasterError>,
    ) -> Result<CycleStats, MasterError> {
        let n = self.len();
        opts.check()?;
        let sync = opts.sync;
        let opts_dc = opts.dc();
        let opts = opts.options;
        let period = opts.cycle.as_nanos() as u64;
        // ethercrab's group (a reset of every slave to INIT, then PRE-OP).
        self.ensure_group()?;
        self.check_watchdogs(opts.cycle)?;
        // Which slaves' ESCs generate SYNC0.
        let supports: Vec<bool> = match &self.slot {
            Some(Slot::PreOp(g)) => g
                .iter(&self.md)
                .map(|s| {
                    !matches!(
                        s.dc_support(),
                        ethercrab::DcSupport::None | ethercrab::DcSupport::RefOnly
                    )
                })
                .collect(),
            _ => vec![false; n],
        };
        self.check_sync(sync, &supports)?;
        let mut dc = opts_dc;
        if !dc {
            // Without DC: the explicit mode, or (Auto) free run, or SM-synchronous
            // (0x1C32:01 = 1) on a slave whose 0x1C32:04 offers that and not free run (the
            // TUeES030), as `states` does. A DC recording left 0x1C32:01 = 2 (DC SYNC0), with
            // which the slave would wait for SYNC0 pulses that never come and not reach OP.
            for p in 0..n {
                let r = self.runner.block_on(async {
                    let mode = match sync.code() {
                        Some(code) => self.sync_mode_async(p).await?.map(|_| code),
                        None => self.plain_sync_mode(p).await?,
                    };
                    match mode {
                        Some(mode) => self.set_sync_mode(p, mode).await,
                        // No CoE or no 0x1C32: SYNC0 generation off all the same.
                        None => self.set_free_run(p).await,
                    }
                });
                if let Err(e) = r {
                    if sync != SyncMode::Auto {
                        return Err(e);
                    }
                    log::warn!("slave {p}: sync mode not checked ({e})");
                }
            }
        }
        if dc {
            // DC-synchronous slaves: SYNC0 on, and (CoE) sync mode 0x1C32:01 = 2 (DC SYNC0).
            if !supports.iter().any(|&s| s) {
                log::warn!("no slave supports DC SYNC0: cycling in free run");
                dc = false;
            } else {
                for (p, &s) in supports.iter().enumerate() {
                    if s {
                        if let Err(e) = self.sdo_download(p, 0x1C32, 1, &2u16.to_le_bytes()) {
                            if sync == SyncMode::Dc && !matches!(e, MasterError::SdoAbort { .. }) {
                                return Err(e);
                            }
                            log::info!("slave {p}: sync mode not set ({e})");
                        }
                    }
                }
                if let Some(Slot::PreOp(g)) = &mut self.slot {
                    for (mut sd, &s) in g.iter_mut(&self.md).zip(supports.iter()) {
                        if s {
                            sd.set_dc_sync(DcSync::Sync0);
                        }
                    }
                }
            }
        }
        let group = self.take_pdi_group()?;
        let md = &self.md;
        let time = self.time.clone();
        let e = |what: &str| {
            let what = what.to_string();
            move |e| MasterError::Ethercrab(what, e)
        };
        let mut io = CycleIo {
            cycle: 0,
            time_ns: 0,
            outputs: vec![Vec::new(); n],
            inputs: vec![Vec::new(); n],
            working_counter: 0,
        };
        let mut stats = CycleStats {
            exchange: Exchange::Ethercrab,
            ..CycleStats::default()
        };
        let mut left = false;
        // On the heap: ethercrab's cyclic futures are large (debug builds).
        crate::on_group_stack(|| {
            self.runner.block_on(Box::pin(async {
                if dc {
                    let group = group
                        .configure_dc_sync(
                            md,
                            DcConfiguration {
                                start_delay: Duration::from_millis(1).max(opts.cycle * 4),
                                sync0_period: opts.cycle,
                                sync0_shift: opts.cycle / 2,
                            },
                        )
                        .await
                        .map_err(e("DC configuration"))?;
                    let group = group
                        .into_safe_op(md)
                        .await
                        .map_err(e("PRE-OP -> SAFE-OP"))?;
                    let group = group.request_into_op(md).await.map_err(e("request OP"))?;
                    for (p, sd) in group.iter(md).enumerate() {
                        io.outputs[p] = vec![0; sd.outputs_raw().len()];
                    }
                    let deadline =
                        std::time::Instant::now() + self.options.timeouts.state_transition;
                    let mut t0 = None;
                    loop {
                        for (p, sd) in group.iter(md).enumerate() {
                            let mut o = sd.outputs_raw_mut();
                            let l = o.len().min(io.outputs[p].len());
                            o[..l].copy_from_slice(&io.outputs[p][..l]);
                        }
                        let t = time.now();
                        let r = match group.tx_rx_dc(md).await {
                            Ok(r) => r,
                            Err(err) if t0.is_some() => {
                                return Err(self.frames_lost(stats.cycles, err).await)
                            }
                            Err(err) => {
                                return Err(MasterError::Ethercrab("cyclic exchange".into(), err))
                            }
                        };
                        let all_op = r.all_op();
                        if all_op {
                            // Row time: the DC system time of the cycle (the slaves' clock).
                            let dct = r.extra.dc_system_time;
                            let start = *t0.get_or_insert(dct);
                            for (p, sd) in group.iter(md).enumerate() {
                                io.inputs[p].clear();
                                io.inputs[p].extend_from_slice(&sd.inputs_raw());
                            }
                            io.working_counter = r.working_counter;
                            io.time_ns = dct.saturating_sub(start);
                            stats.cycles += 1;
                            let flow = step(&mut io)?;
                            io.cycle += 1;
                            if flow == Flow::Stop {
                                break;
                            }
                        } else if t0.is_some() {
                            stats.wkc_errors += 1;
                            // A slave left OP under us: nothing in this run takes it back, so
                            // say who changed what (another master, a watchdog) at once.
                            if let Some(d) = self.disturbed(stats.cycles, None).await {
                                return Err(d);
                            }
                        } else if std::time::Instant::now() > deadline {
                            left = true;
                            break;
                        }
                        time.wait_until(t + r.extra.next_cycle_wait.as_nanos() as u64);
                    }
                } else {
                    let group = group.into_op(md).await.map_err(e("PRE-OP -> OP"))?;
                    for (p, sd) in group.iter(md).enumerate() {
                        io.outputs[p] = vec![0; sd.outputs_raw().len()];
                    }
                    let (o, i): (Vec<usize>, Vec<usize>) = group
                        .iter(md)
                        .map(|sd| (sd.outputs_raw().len(), sd.inputs_raw().len()))
                        .unzip();
                    let ethercrab_frames =
                        crate::exchange::ethercrab_frames(o.iter().chain(&i).sum(), n);
                    let mut plan = match self.exchange {
                        Exchange::Ethercrab => None,
                        Exchange::Auto if ethercrab_frames <= 1 => None,
                        Exchange::Auto => self
                            .lean_plan(&o, &i, false)
                            .await
                            .filter(|p| p.frames() <= ethercrab_frames),
                        Exchange::Lean => self.lean_plan(&o, &i, false).await,
                        Exchange::Overlapped => self.lean_plan(&o, &i, true).await,
                    };
                    stats.exchange = match &plan {
                        Some(p) if p.overlapped => Exchange::Overlapped,
                        Some(_) => Exchange::Lean,
                        None => Exchange::Ethercrab,
                    };
                    stats.frames_per_cycle = plan.as_ref().map_or(ethercrab_frames, |p| p.frames());
                    let slaves = u16::try_from(n).unwrap_or(u16::MAX);
                    let t0 = time.now();
                    let mut expected = None;
                    let run = async {
                        loop {
                            let due = t0 + io.cycle * period;
                            // (working counter, it is not the expected one, all slaves in OP)
                            let (wkc, wkc_bad, all_op) = match &mut plan {
                                Some(plan) => {
                                    plan.put_outputs(&io.outputs);
                                    time.wait_until(due);
                                    let r = match plan.exchange(md, slaves).await {
                                        Ok(r) => r,
                                        Err(err) => {
                                            return Err(self.frames_lost(stats.cycles, err).await)
                                        }
                                    };
                                    plan.take_inputs(&mut io.inputs);
                                    (r.working_counter, r.wkc_bad, r.all_op)
                                }
                                None => {
                                    for (p, sd) in group.iter(md).enumerate() {
                                        let mut o = sd.outputs_raw_mut();
                                        let l = o.len().min(io.outputs[p].len());
                                        o[..l].copy_from_slice(&io.outputs[p][..l]);
                                    }
                                    time.wait_until(due);
                                    let r = match group.tx_rx(md).await {
                                        Ok(r) => r,
                                        Err(err) => {
                                            return Err(self.frames_lost(stats.cycles, err).await)
                                        }
                                    };
                                    for (p, sd) in group.iter(md).enumerate() {
                                        io.inputs[p].clear();
                                        io.inputs[p].extend_from_slice(&sd.inputs_raw());
                                    }
                                    // ethercrab's working counter is checked against the first
                                    // cycle's.
                                    let bad = *expected.get_or_insert(r.working_counter)
                                        != r.working_counter;
                                    (r.working_counter, bad, r.all_op())
                                }
                            };
                            io.working_counter = wkc;
                            // The AL status is read with each exchange: the working counter
                            // alone does not show a slave that left OP (its ESC still counts
                            // the FMMU access).
                            if wkc_bad {
                                stats.wkc_errors += 1;
                            }
                            if wkc_bad || !all_op {
                                if let Some(d) = self.disturbed(stats.cycles, None).await {
                                    return Err(d);
                                }
                            }
                            io.time_ns = time.now().saturating_sub(t0).max(io.cycle * period);
                            stats.cycles += 1;
                            let flow = step(&mut io)?;
                            io.cycle += 1;
                            if flow == Flow::Stop {
                                break;
                            }
                        }
                        Ok::<(), MasterError>(())
                    };
                    let run = run.await;
                    if let Some(p) = &plan {
                        self.move_fmmus_back(&p.moved).await;
                    }
                    run?;
                }
                Ok(stats)
            }))
        })?;
        if left {
            return Err(self.left_op());
        }
        Ok(stats)
    }

    /// `write`: cycles in OP, sets every variable in `vars` to `value` in one cycle and keeps
    /// cycling `settle` more cycles so the slaves take it; returns the values read back.
    pub fn write_online(
        &mut self,
        opts: impl Into<Cycling>,
        vars: &[Variable],
        value: &[u8],
        settle: u64,
    ) -> Result<Vec<String>, MasterError> {
        let warm = 5u64;
        let mut back = Vec::new();
        self.run_cyclic(opts, |io| {
            if io.cycle == warm {
                for v in vars {
                    io.set(v, value)?;
                }
            }
            if io.cycle >= warm + settle {
                back = vars.iter().map(|v| v.format(&io.get(v))).collect();
                return Ok(Flow::Stop);
            }
            Ok(Flow::Continue)
        })?;
        Ok(back)
    }

    /// `record`: cycles `cycles` times in OP (DC-synchronous when `opts.dc`) and writes one
    /// CSV row per cycle: cycle, time in s, then each variable; the header carries units.
    pub fn record(
        &mut self,
        opts: impl Into<Cycling>,
        vars: &[Variable],
        cycles: u64,
        out: &mut dyn Write,
        progress: &mut dyn FnMut(u64, u64),
    ) -> Result<CycleStats, MasterError> {
        let stop = std::sync::atomic::AtomicBool::new(false);
        self.record_until(opts.into(), vars, cycles, out, progress, &stop)
    }

    /// [`Master::record`] that ends early, with the rows so far, when `stop` is set (Ctrl-C).
    pub fn record_until(
        &mut self,
        opts: impl Into<Cycling>,
        vars: &[Variable],
        cycles: u64,
        out: &mut dyn Write,
        progress: &mut dyn FnMut(u64, u64),
        stop: &std::sync::atomic::AtomicBool,
    ) -> Result<CycleStats, MasterError> {
        // The csv crate joins the fields and quotes those that need it (a variable name,
        // unit or string value with a comma or a quote); it buffers, so the rows reach
        // `out` in blocks and once more at the end, whatever ended the run.
        let mut w = csv::Writer::from_writer(out);
        let mut header = vec!["cycle".to_string(), "time [s]".to_string()];
        header.extend(vars.iter().map(|v| format!("{} [{}]", v.name, v.unit)));
        w.write_record(&header)
            .map_err(|e| MasterError::Output(e.into()))?;
        let mut err: Option<std::io::Error> = None;
        let stats = self.run_cyclic(opts, |io| {
            let mut row = vec![
                io.cycle.to_string(),
                format!("{:.9}", io.time_ns as f64 * 1e-9),
            ];
            row.extend(vars.iter().map(|v| v.format(&io.get(v))));
            if let Err(e) = w.write_record(&row) {
                err = Some(e.into());
                return Ok(Flow::Stop);
            }
            progress(io.cycle + 1, cycles);
            let stopped = stop.load(std::sync::atomic::Ordering::Relaxed);
            Ok(if stopped || io.cycle + 1 >= cycles {
                Flow::Stop
            } else {
                Flow::Continue
            })
        });
        let flushed = w.flush();
        let stats = stats?;
        if let Some(e) = err.or(flushed.err()) {
            return Err(MasterError::Output(e));
        }
        Ok(stats)
    }

    /// `watch`: cycles in OP and calls `line` every `every` cycles with `name=value` pairs,
    /// `count` times (0: until the callback returns false).
    pub fn watch(
        &mut self,
        opts: impl Into<Cycling>,
        vars: &[Variable],
        every: u64,
        count: u64,
        line: &mut dyn FnMut(&str) -> bool,
    ) -> Result<CycleStats, MasterError> {
        let every = every.max(1);
        let mut shown = 0u64;
        self.run_cyclic(opts, |io| {
            if io.cycle % every == every - 1 {
                let s: Vec<String> = vars
                    .iter()
                    .map(|v| format!("{}={}", v.name, v.format(&io.get(v))))
                    .collect();
                shown += 1;
                let go_on = line(&s.join("  "));
                if !go_on || (count > 0 && shown >= count) {
                    return Ok(Flow::Stop);
                }
            }
            Ok(Flow::Continue)
        })
    }
}
