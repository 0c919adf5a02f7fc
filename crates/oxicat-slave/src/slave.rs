//! The slave stack: one struct the application owns, generic over the [`Pdi`], driven by
//! events (`poll`, `on_pdi_irq`, `on_sync0`, `on_sync1`, `on_timer`).

use core::marker::PhantomData;

use oxicat_wire::coe::Emergency;
use oxicat_wire::mailbox::{
    MailboxErrorDetail, MailboxErrorReply, MailboxHeader, MailboxType, MAILBOX_HEADER_LEN,
};

use crate::coe::SdoState;
use crate::device::{DeviceDef, MailboxDef, SyncMode};
use crate::esm::{AlState, AlStatusCode};
use crate::foe::{FoeFiles, FoeState};
use crate::od::{check_def, CheckedDef, DefError, EntryRef, Od};
use crate::pdi::{reg, Pdi};
use crate::pdo::{self, Dir, Mapping, MAX_ITEMS, MAX_PD_BYTES};

/// Hooks through which the stack calls the application.
pub trait Application<const N: usize> {
    /// A state change is about to happen; an upward change may be refused with a code.
    fn state_change(
        &mut self,
        _from: AlState,
        _to: AlState,
        _od: &mut Od<N>,
    ) -> Result<(), AlStatusCode> {
        Ok(())
    }

    /// Outputs must go to their safe values (leaving OP, watchdog).
    fn safe_outputs(&mut self, _od: &mut Od<N>) {}

    /// One application cycle between output and input mapping.
    fn cycle(&mut self, _od: &mut Od<N>) {}

    /// A local timer fired.
    fn timer(&mut self, _id: u8, _od: &mut Od<N>) {}

    /// An SDO download changed `index:sub` (subindex 0 for complete access).
    fn sdo_written(&mut self, _index: u16, _sub: u8, _od: &mut Od<N>) {}

    /// The application's FoE files; `None` (the default): FoE is not supported.
    fn foe(&mut self) -> Option<&mut dyn FoeFiles> {
        None
    }

    /// A CoE emergency the application raised (error code, error register, 5 bytes of
    /// manufacturer data). The stack asks after each of its handlers ran and queues what it
    /// gets ([`Slave::emergency`]), since a hook cannot reach the stack itself.
    fn next_emergency(&mut self) -> Option<(u16, u8, [u8; 5])> {
        None
    }
}

/// An application without hooks.
impl<const N: usize> Application<N> for () {}

/// Why the stack could not be created.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InitError<E> {
    /// The device definition is inconsistent.
    Def(DefError),
    /// A mailbox of the definition is larger than the stack's buffer `M` or too small.
    MailboxSize,
    /// The definition's default PDO mapping of one direction (`assign`: 0x1C12 outputs,
    /// 0x1C13 inputs) compiles to more copy steps than the stack holds (its `K`; size it
    /// with [`crate::pdo::map_steps`]).
    MappingCapacity {
        /// The assignment object of the direction (0x1C12 or 0x1C13).
        assign: u16,
        /// Copy steps the mapping needs.
        needed: usize,
        /// Copy steps the stack holds (`K`).
        capacity: usize,
    },
    /// The ESC could not be accessed.
    Pdi(E),
}

/// Counters for diagnostics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Stats {
    /// Mailbox requests processed.
    pub mbx_requests: u32,
    /// Duplicate mailbox requests dropped (same counter).
    pub mbx_duplicates: u32,
    /// Repeat requests served.
    pub mbx_repeats: u32,
    /// Process data cycles run.
    pub cycles: u32,
    /// Output updates taken from SM2.
    pub outputs: u32,
}

/// The sync-manager parameter entries the stack keeps up to date each DC cycle
/// (ETG.1020: 0x1C32/0x1C33 subindices 0x0B, 0x0C, 0x20; limit 0x10F1:02), resolved once.
#[derive(Debug, Clone, Copy)]
struct SyncDiag {
    missed: [EntryRef; 2],
    exceeded: [EntryRef; 2],
    error: [EntryRef; 2],
    limit: EntryRef,
    /// SM event missed counter (ETG.1020 / SSC: +3 per SYNC0 without an SM event, -1 per
    /// SM event, not incremented beyond the limit).
    missed_count: u16,
    /// Cycle exceeded ("cycle time too small") counter.
    exceeded_count: u16,
}

impl SyncDiag {
    /// Unresolved (all bytes zero; [`Slave::init`] resolves it).
    const BLANK: Self = Self {
        missed: [EntryRef::BLANK; 2],
        exceeded: [EntryRef::BLANK; 2],
        error: [EntryRef::BLANK; 2],
        limit: EntryRef::BLANK,
        missed_count: 0,
        exceeded_count: 0,
    };

    fn new<const N: usize>(od: &Od<N>) -> Result<Self, DefError> {
        // One lookup loop over a table instead of seven lookups each with its own error
        // path (flash).
        const AT: [(u16, u8); 7] = [
            (0x1C32, 0x0B),
            (0x1C33, 0x0B),
            (0x1C32, 0x0C),
            (0x1C33, 0x0C),
            (0x1C32, 0x20),
            (0x1C33, 0x20),
            (0x10F1, 2),
        ];
        let mut r = [EntryRef::BLANK; 7];
        for (k, &(i, s)) in AT.iter().enumerate() {
            r[k] = od.entry(i, s).map_err(|_| DefError::BadEntries(i))?;
        }
        Ok(Self {
            missed: [r[0], r[1]],
            exceeded: [r[2], r[3]],
            error: [r[4], r[5]],
            limit: r[6],
            missed_count: 0,
            exceeded_count: 0,
        })
    }

    /// Writes the counters and the sync error flag (counter > 0x10F1:02) into the dictionary.
    fn publish<const N: usize>(&self, od: &mut Od<N>) {
        let limit: u16 = od.read(self.limit);
        for k in 0..2 {
            od.write(self.missed[k], self.missed_count);
            od.write(self.exceeded[k], self.exceeded_count);
            od.write(self.error[k], self.missed_count > limit);
        }
    }
}

/// The mailbox side of the stack. One reply buffer: a reply is built in `last` and written
/// to SM1 at once, and nothing new is served while the master has not read the previous
/// reply (`posted`), so `last` is always the reply a repeat request asks for.
pub(crate) struct MbxState<const M: usize> {
    pub running: bool,
    pub boot: bool,
    /// A reply built in `last` and not written to SM1 yet (its length).
    pub out_len: usize,
    pub last: [u8; M],
    pub last_len: usize,
    pub posted: bool,
    pub toggle: bool,
    pub out_counter: u8,
    pub in_counter: u8,
    pub rx: [u8; M],
    pub stage: [u8; M],
    pub emcy: [Option<Emergency>; 4],
}

impl<const M: usize> MbxState<M> {
    const fn new() -> Self {
        Self {
            running: false,
            boot: false,
            out_len: 0,
            last: [0; M],
            last_len: 0,
            posted: false,
            toggle: false,
            out_counter: 0,
            in_counter: 0,
            rx: [0; M],
            stage: [0; M],
            emcy: [None; 4],
        }
    }

    /// Back to [`MbxState::new`] in place.
    fn clear(&mut self) {
        self.boot = false;
        self.last.fill(0);
        self.out_counter = 0;
        self.rx.fill(0);
        self.stage.fill(0);
        self.reset();
    }

    fn reset(&mut self) {
        self.running = false;
        self.out_len = 0;
        self.last_len = 0;
        self.posted = false;
        self.toggle = false;
        self.in_counter = 0;
        self.emcy = [None; 4];
    }
}

/// Storage for a stack built in place, for a `static` on a microcontroller: all bytes
/// zero until [`SlaveSlot::start`] (so it lives in `.bss`, no flash copy), and the stack is
/// built where it lies — no `Slave` value, image or mailbox buffer is ever on the stack.
///
/// ```ignore
/// #[entry]
/// fn main() -> ! {
///     // cortex-m-rt makes this a `&'static mut` (one per program).
///     static mut SLOT: SlaveSlot<MyPdi, { demo::IMAGE }, 128> = SlaveSlot::new();
///     let slave = SLOT.start(&demo::DEF, &mut pdi).unwrap();
///     loop { slave.poll(&mut pdi, &mut app).ok(); }
/// }
/// ```
pub struct SlaveSlot<P: Pdi, const N: usize, const M: usize = 256, const K: usize = MAX_ITEMS> {
    slave: Slave<P, N, M, K>,
    /// The last [`SlaveSlot::start`] succeeded and no [`SlaveSlot::stop`] followed.
    running: bool,
}

impl<P: Pdi, const N: usize, const M: usize, const K: usize> SlaveSlot<P, N, M, K> {
    /// An empty slot (usable in a `static`).
    pub const fn new() -> Self {
        Self {
            slave: Slave::blank(),
            running: false,
        }
    }

    /// Builds the stack in the slot, as [`Slave::new`] does, and returns it. A second call
    /// starts it afresh; a failed one leaves the slot stopped.
    pub fn start(
        &mut self,
        def: &'static DeviceDef,
        pdi: &mut P,
    ) -> Result<&mut Slave<P, N, M, K>, InitError<P::Error>> {
        self.running = false;
        self.slave.init(def, pdi)?;
        self.running = true;
        Ok(&mut self.slave)
    }

    /// [`SlaveSlot::start`] of a definition checked when the image was built
    /// (`SLOT.start_checked(const { CheckedDef::new(&DEF) }, pdi)`): the same start-up
    /// without [`check_def`]'s code in the image.
    pub fn start_checked(
        &mut self,
        def: CheckedDef<N>,
        pdi: &mut P,
    ) -> Result<&mut Slave<P, N, M, K>, InitError<P::Error>> {
        self.running = false;
        self.slave.init_checked(def, pdi)?;
        self.running = true;
        Ok(&mut self.slave)
    }

    /// Marks the stack gone (a firmware that takes it down when its ESC stops answering and
    /// starts it again later): [`SlaveSlot::slave`] is `None` until the next start.
    pub fn stop(&mut self) {
        self.running = false;
    }

    /// The stack, when the last [`SlaveSlot::start`] succeeded and no stop followed.
    pub fn slave(&self) -> Option<&Slave<P, N, M, K>> {
        self.running.then_some(&self.slave)
    }

    /// The stack, mutably, when it runs (as [`SlaveSlot::slave`]).
    pub fn slave_mut(&mut self) -> Option<&mut Slave<P, N, M, K>> {
        self.running.then_some(&mut self.slave)
    }
}

impl<P: Pdi, const N: usize, const M: usize, const K: usize> Default for SlaveSlot<P, N, M, K> {
    fn default() -> Self {
        Self::new()
    }
}

/// The EtherCAT slave stack.
///
/// `N` is the application image size (at least [`crate::od::image_size`] of the
/// definition's objects), `M` the mailbox buffer size (at least both mailbox lengths), `K`
/// the copy steps a compiled PDO mapping of one direction holds (8 bytes each; a board
/// image sizes it to its device with [`crate::pdo::map_steps`], the default
/// [`MAX_ITEMS`] takes any mapping the stack accepts).
///
/// The stack does not own its [`Pdi`]: every event takes it (`slave.poll(&mut pdi, &mut
/// app)`), so the firmware's main (or the simulator, which owns the ESC) keeps the ESC
/// access and lends it per call. `P` fixes which PDI type (and error type) the stack is
/// used with.
pub struct Slave<P: Pdi, const N: usize, const M: usize = 256, const K: usize = MAX_ITEMS> {
    _pdi: PhantomData<fn() -> P>,
    pub(crate) od: Od<N>,
    pub(crate) state: AlState,
    pub(crate) error: bool,
    pub(crate) code: AlStatusCode,
    pub(crate) mbx: MbxState<M>,
    pub(crate) sdo: SdoState,
    pub(crate) foe: FoeState,
    rx_map: Mapping<K>,
    tx_map: Mapping<K>,
    sync: SyncMode,
    pd: [u8; MAX_PD_BYTES],
    stats: Stats,
    diag: SyncDiag,
    /// The TxPDO mapping writes every bit of SM3 (no clearing needed).
    tx_full: bool,
    /// DC SYNC1 mode: the PDI interrupt took a new SM2 buffer since the last SYNC0.
    sm2_taken: bool,
    /// PREOP → SAFEOP in steps ([`Slave::set_stepwise_safeop`]).
    stepwise: bool,
    /// The step of a stepwise PREOP → SAFEOP in progress.
    pd_step: PdStep,
}

/// Where a stepwise PREOP → SAFEOP stands: the AL control request was read and the
/// RxPDO mapping compiled (`Rx`), then the TxPDO mapping too (`Tx`); the next poll makes
/// the transition.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum PdStep {
    Idle,
    Rx,
    Tx,
}

type R<P> = Result<(), <P as Pdi>::Error>;

impl<P: Pdi, const N: usize, const M: usize, const K: usize> Slave<P, N, M, K> {
    /// Creates the stack: checks the definition, fills the dictionary with defaults,
    /// deactivates every SyncManager, sets the AL event mask and AL status INIT through
    /// `pdi`. The value is several KB: a microcontroller builds it in place in a static
    /// [`SlaveSlot`] instead (no copy of it on the stack).
    pub fn new(def: &'static DeviceDef, pdi: &mut P) -> Result<Self, InitError<P::Error>> {
        let mut s = Self::blank();
        s.init(def, pdi)?;
        Ok(s)
    }

    /// A stack without a definition, all bytes zero (so a `static` of it is in `.bss`, not
    /// copied from flash); [`Slave::init`] makes it a stack. Only [`SlaveSlot`] hands one
    /// out, after `init`.
    const fn blank() -> Self {
        Self {
            _pdi: PhantomData,
            od: Od::blank(),
            state: AlState::Init,
            error: false,
            code: AlStatusCode::NONE,
            mbx: MbxState::new(),
            sdo: SdoState::Idle,
            foe: FoeState::Idle,
            rx_map: Mapping::EMPTY,
            tx_map: Mapping::EMPTY,
            sync: SyncMode::FreeRun,
            pd: [0; MAX_PD_BYTES],
            stats: Stats {
                mbx_requests: 0,
                mbx_duplicates: 0,
                mbx_repeats: 0,
                cycles: 0,
                outputs: 0,
            },
            diag: SyncDiag::BLANK,
            tx_full: false,
            sm2_taken: false,
            stepwise: false,
            pd_step: PdStep::Idle,
        }
    }

    /// [`Slave::new`] in place: every field set where it is (no temporary `Slave`, image or
    /// mailbox buffer on the stack). On an error the value is not a usable stack. Not
    /// inlined: start-up runs once, and its buffers (the mapping walk's) would join the
    /// frame of the firmware's `main`, which the request handlers stand on.
    #[inline(never)]
    fn init(&mut self, def: &'static DeviceDef, pdi: &mut P) -> Result<(), InitError<P::Error>> {
        check_def(def, N).map_err(InitError::Def)?;
        self.init_checked(CheckedDef(def), pdi)
    }

    /// [`Slave::init`] of a definition checked when the image was built.
    #[inline(never)]
    fn init_checked(&mut self, def: CheckedDef<N>, pdi: &mut P) -> Result<(), InitError<P::Error>> {
        let def = def.0;
        self.od.init_checked(CheckedDef(def));
        self.diag = SyncDiag::new(&self.od).map_err(InitError::Def)?;
        let fits = |m: &MailboxDef| {
            (m.rx_len as usize) <= M && (m.tx_len as usize) <= M && m.rx_len >= 16 && m.tx_len >= 16
        };
        if !fits(&def.mailbox) || def.boot_mailbox.is_some_and(|m| !fits(&m)) {
            return Err(InitError::MailboxSize);
        }
        // The default mappings must compile into `K` steps (a mapping that does not check
        // at all is refused as before, when the master requests SAFEOP).
        for (dir, assign) in [(Dir::Rx, 0x1C12), (Dir::Tx, 0x1C13)] {
            // `pdo::steps`, as the one mapping walk of the image.
            if let Ok((_, needed)) = pdo::check::<N, K>(&self.od, dir, usize::MAX) {
                if needed > K {
                    return Err(InitError::MappingCapacity {
                        assign,
                        needed,
                        capacity: K,
                    });
                }
            }
        }
        self.state = AlState::Init;
        self.error = false;
        self.code = AlStatusCode::NONE;
        self.mbx.clear();
        self.sdo = SdoState::Idle;
        self.foe = FoeState::Idle;
        self.rx_map.clear();
        self.tx_map.clear();
        self.sync = SyncMode::FreeRun;
        self.pd.fill(0);
        self.stats = Stats::default();
        self.tx_full = false;
        self.sm2_taken = false;
        self.stepwise = false;
        self.pd_step = PdStep::Idle;
        for n in 0..4 {
            Self::sm_enable(pdi, n, false).map_err(InitError::Pdi)?;
        }
        Self::set_event_mask(pdi, reg::EV_AL_CONTROL).map_err(InitError::Pdi)?;
        self.write_status(pdi).map_err(InitError::Pdi)?;
        Ok(())
    }

    /// PREOP → SAFEOP in three [`Slave::poll`] calls instead of one: the request and the
    /// RxPDO mapping, the TxPDO mapping, then the checks and the transition (and the AL
    /// status). For a main loop that holds the ESC interrupts off while it polls (a board
    /// whose handlers share the stack): each call then holds them off for a part of the
    /// work, not for the whole transition, which on a 180 MHz Cortex-M4 with the Laelaps
    /// leg's mapping outlasts a 400 µs SYNC0 cycle. The polls in between do only that step
    /// (the mailbox and an AL control request that arrives meanwhile wait for the
    /// transition). Off by default: the transition in one poll.
    pub fn set_stepwise_safeop(&mut self, on: bool) {
        self.stepwise = on;
    }

    /// The object dictionary.
    pub fn od(&self) -> &Od<N> {
        &self.od
    }

    /// The object dictionary, mutable (application data).
    pub fn od_mut(&mut self) -> &mut Od<N> {
        &mut self.od
    }

    /// Current AL state.
    pub fn state(&self) -> AlState {
        self.state
    }

    /// Current AL status code (0 when no error is indicated).
    pub fn status_code(&self) -> AlStatusCode {
        self.code
    }

    /// True while an error is indicated in AL status.
    pub fn error_indicated(&self) -> bool {
        self.error
    }

    /// The sync mode the stack runs in (decided on PREOP → SAFEOP).
    pub fn sync_mode(&self) -> SyncMode {
        self.sync
    }

    /// Diagnostics counters.
    pub fn stats(&self) -> Stats {
        self.stats
    }

    /// Output (RxPDO) process data size in bytes of the active mapping.
    pub fn output_bytes(&self) -> usize {
        self.rx_map.bytes()
    }

    pub(crate) fn rx_mapping(&self) -> &Mapping<K> {
        &self.rx_map
    }

    /// Input (TxPDO) process data size in bytes of the active mapping.
    pub fn input_bytes(&self) -> usize {
        self.tx_map.bytes()
    }

    // ------------------------------------------------------------------ events

    /// Main-loop work: AL control, watchdog, mailbox; in free run also the process data.
    pub fn poll<A: Application<N>>(&mut self, pdi: &mut P, app: &mut A) -> R<P> {
        let r = self.poll_inner(pdi, app);
        self.queue_app_emergencies(app);
        r
    }

    fn poll_inner<A: Application<N>>(&mut self, pdi: &mut P, app: &mut A) -> R<P> {
        match self.pd_step {
            PdStep::Idle => {}
            PdStep::Rx => {
                self.pd_step = PdStep::Tx;
                // In place (no Mapping on the stack); below SAFEOP the mapping is unused, so a
                // refused one may leave a part of it there.
                match pdo::compile_into(&self.od, Dir::Tx, &mut self.tx_map) {
                    Ok(()) => {}
                    Err(_) => {
                        self.pd_step = PdStep::Idle;
                        return self.set_error(pdi, AlStatusCode::INVALID_INPUT_MAPPING);
                    }
                }
                return Ok(());
            }
            PdStep::Tx => {
                self.pd_step = PdStep::Idle;
                let (rx, tx) = (self.rx_map.bytes(), self.tx_map.bytes());
                return match self.start_pd_with(pdi, app, rx, tx, false)? {
                    Ok(()) => self.write_status(pdi),
                    Err(c) => self.set_error(pdi, c),
                };
            }
        }
        let ev = pdi.al_event_request()?;
        if ev & reg::EV_AL_CONTROL != 0 {
            self.al_control(pdi, app)?;
            if self.pd_step != PdStep::Idle {
                return Ok(()); // a stepwise PREOP -> SAFEOP began: nothing else this poll
            }
        } else if ev & reg::EV_SM_CHANGE != 0 {
            self.sm_change(pdi, app)?;
        }
        if ev & reg::EV_WATCHDOG != 0 {
            self.check_watchdog(pdi, app)?;
        }
        if self.mbx.running {
            self.mailbox(pdi, app)?;
        }
        if self.sync == SyncMode::FreeRun && self.state >= AlState::SafeOp {
            self.cycle(pdi, app, true, true)?;
        }
        Ok(())
    }

    /// PDI interrupt: in SM-synchronous mode runs the cycle on the SM2 (or SM3) event.
    pub fn on_pdi_irq<A: Application<N>>(&mut self, pdi: &mut P, app: &mut A) -> R<P> {
        let r = self.on_pdi_irq_inner(pdi, app);
        self.queue_app_emergencies(app);
        r
    }

    fn on_pdi_irq_inner<A: Application<N>>(&mut self, pdi: &mut P, app: &mut A) -> R<P> {
        if self.sync == SyncMode::DcSync1 && self.state >= AlState::SafeOp {
            // DC with SYNC1 (the SSC's and the Laelaps thesis' split): the outputs are
            // mapped on the SM2 event, the application runs on SYNC0, the inputs on SYNC1.
            let ev = pdi.al_event_request()?;
            if self.rx_map.bytes() > 0 && ev & reg::ev_sm(2) != 0 {
                self.read_outputs(pdi, ev)?;
                self.sm2_taken = true;
            }
            return Ok(());
        }
        if self.sync != SyncMode::SmSync || self.state < AlState::SafeOp {
            return Ok(());
        }
        let ev = pdi.al_event_request()?;
        let trig = if self.rx_map.bytes() > 0 {
            ev & reg::ev_sm(2) != 0
        } else {
            ev & reg::ev_sm(3) != 0
        };
        if trig {
            self.cycle_ev(pdi, app, ev, true, true)?;
            self.check_exceeded(pdi)?;
        }
        Ok(())
    }

    /// DC SYNC0: outputs, application and (unless SYNC1 latches them) inputs.
    ///
    /// Keeps the ETG.1020 diagnostics of 0x1C32/0x1C33 as the SSC does: a SYNC0 without a
    /// new SM2 buffer since the previous one (input-only devices: SM3 not read by the master)
    /// adds 3 to the SM event missed counter (0x0B; not beyond the sync error counter limit
    /// 0x10F1:02), every SYNC0 with one subtracts 1; the sync error flag (0x20) is set while
    /// the counter exceeds the limit. A new SM2 buffer that arrives while the cycle runs
    /// counts in the cycle time too small counter (0x0C).
    pub fn on_sync0<A: Application<N>>(&mut self, pdi: &mut P, app: &mut A) -> R<P> {
        let r = self.on_sync0_inner(pdi, app);
        self.queue_app_emergencies(app);
        r
    }

    fn on_sync0_inner<A: Application<N>>(&mut self, pdi: &mut P, app: &mut A) -> R<P> {
        let _ack = pdi.read_u8(reg::DC_SYNC0_STATUS)?;
        let inputs = match self.sync {
            SyncMode::DcSync0 => true,
            SyncMode::DcSync1 => false,
            _ => return Ok(()),
        };
        if self.state < AlState::SafeOp {
            return Ok(());
        }
        let ev = pdi.al_event_request()?;
        let sm_event = if self.rx_map.bytes() > 0 {
            let taken = core::mem::take(&mut self.sm2_taken);
            Some(ev & reg::ev_sm(2) != 0 || taken)
        } else if self.tx_map.bytes() > 0 {
            Some(ev & reg::ev_sm(3) != 0)
        } else {
            None
        };
        if let Some(seen) = sm_event {
            let d = &mut self.diag;
            let before = d.missed_count;
            if seen {
                d.missed_count = d.missed_count.saturating_sub(1);
            } else if d.missed_count <= self.od.read::<u16>(d.limit) {
                d.missed_count = d.missed_count.saturating_add(3);
            }
            if d.missed_count != before {
                d.publish(&mut self.od);
            }
        }
        // SYNC0 alone maps the outputs too; with SYNC1 the SM2 interrupt did.
        self.cycle_ev(pdi, app, ev, inputs, inputs)?;
        if inputs && self.rx_map.bytes() > 0 {
            self.check_exceeded(pdi)?;
        }
        Ok(())
    }

    /// After a synchronous cycle: a new SM2 buffer already waiting means the next output
    /// update arrived while the cycle ran (0x1C32:0C / 0x1C33:0C).
    fn check_exceeded(&mut self, pdi: &mut P) -> R<P> {
        if self.rx_map.bytes() == 0 {
            return Ok(());
        }
        if pdi.al_event_request()? & reg::ev_sm(2) != 0 {
            self.diag.exceeded_count = self.diag.exceeded_count.wrapping_add(1);
            self.diag.publish(&mut self.od);
        }
        Ok(())
    }

    /// DC SYNC1: input latch in SYNC0+SYNC1 mode.
    pub fn on_sync1<A: Application<N>>(&mut self, pdi: &mut P, _app: &mut A) -> R<P> {
        let _ack = pdi.read_u8(reg::DC_SYNC1_STATUS)?;
        if self.sync == SyncMode::DcSync1 && self.state >= AlState::SafeOp {
            self.write_inputs(pdi)?;
        }
        Ok(())
    }

    /// A local timer fired (e.g. the control loop); the application's hook does not touch
    /// the ESC, so no PDI is needed.
    pub fn on_timer<A: Application<N>>(&mut self, id: u8, app: &mut A) {
        app.timer(id, &mut self.od);
        self.queue_app_emergencies(app);
    }

    /// Queues the emergencies the application raised in its hooks.
    fn queue_app_emergencies<A: Application<N>>(&mut self, app: &mut A) {
        while let Some((code, register, data)) = app.next_emergency() {
            let _ = self.emergency(code, register, data);
        }
    }

    /// Queues a CoE emergency (and sets 0x1001 to `error_register`); false if the queue
    /// is full or the mailbox is not running.
    pub fn emergency(&mut self, error_code: u16, error_register: u8, data: [u8; 5]) -> bool {
        let _ = self.od.set(0x1001, 0, error_register);
        if !self.mbx.running {
            return false;
        }
        match self.mbx.emcy.iter_mut().find(|e| e.is_none()) {
            Some(slot) => {
                *slot = Some(Emergency {
                    error_code,
                    error_register,
                    data,
                });
                true
            }
            None => false,
        }
    }

    // ------------------------------------------------------------------ process data

    fn cycle<A: Application<N>>(
        &mut self,
        pdi: &mut P,
        app: &mut A,
        outputs: bool,
        inputs: bool,
    ) -> R<P> {
        let ev = if outputs && self.rx_map.bytes() > 0 {
            pdi.al_event_request()?
        } else {
            0
        };
        self.cycle_ev(pdi, app, ev, outputs, inputs)
    }

    /// One cycle with the AL event request `ev` already read.
    fn cycle_ev<A: Application<N>>(
        &mut self,
        pdi: &mut P,
        app: &mut A,
        ev: u32,
        outputs: bool,
        inputs: bool,
    ) -> R<P> {
        if outputs {
            self.read_outputs(pdi, ev)?;
        }
        app.cycle(&mut self.od);
        if inputs {
            self.write_inputs(pdi)?;
        }
        self.stats.cycles = self.stats.cycles.wrapping_add(1);
        Ok(())
    }

    fn read_outputs(&mut self, pdi: &mut P, ev: u32) -> R<P> {
        let n = self.rx_map.bytes();
        if n == 0 {
            return Ok(());
        }
        if ev & reg::ev_sm(2) == 0 {
            return Ok(());
        }
        let start = self.od.def().sm2_start;
        pdi.read(start, &mut self.pd[..n])?;
        if self.state == AlState::Op {
            self.rx_map.unpack(&mut self.od, &self.pd[..n]);
            self.stats.outputs = self.stats.outputs.wrapping_add(1);
        }
        Ok(())
    }

    fn write_inputs(&mut self, pdi: &mut P) -> R<P> {
        let n = self.tx_map.bytes();
        if n == 0 {
            return Ok(());
        }
        if !self.tx_full {
            self.pd[..n].fill(0);
        }
        self.tx_map.pack(&self.od, &mut self.pd[..n]);
        let start = self.od.def().sm3_start;
        pdi.write(start, &self.pd[..n])
    }

    fn check_watchdog<A: Application<N>>(&mut self, pdi: &mut P, app: &mut A) -> R<P> {
        let st = pdi.read_u8(reg::WD_STATUS_PD)?;
        if self.state == AlState::Op && st & 1 == 0 {
            app.safe_outputs(&mut self.od);
            let _ = app.state_change(AlState::Op, AlState::SafeOp, &mut self.od);
            self.state = AlState::SafeOp;
            self.set_error(pdi, AlStatusCode::SM_WATCHDOG)?;
        }
        Ok(())
    }

    // ------------------------------------------------------------------ ESM

    fn set_error(&mut self, pdi: &mut P, code: AlStatusCode) -> R<P> {
        self.error = true;
        self.code = code;
        self.write_status(pdi)
    }

    fn write_status(&mut self, pdi: &mut P) -> R<P> {
        pdi.write_u16(reg::AL_STATUS_CODE, self.code.0)?;
        let st = self.state.code() as u16 | if self.error { 0x10 } else { 0 };
        pdi.write_u16(reg::AL_STATUS, st)
    }

    /// Sets the AL event mask (0x0204): which AL events drive the PDI interrupt line.
    fn set_event_mask(pdi: &mut P, mask: u32) -> R<P> {
        pdi.write(reg::AL_EVENT_MASK, &mask.to_le_bytes())
    }

    fn sm_enable(pdi: &mut P, n: u8, on: bool) -> R<P> {
        let a = reg::sm(n, 7);
        let cur = pdi.read_u8(a)?;
        let v = if on { cur & !1 } else { cur | 1 };
        pdi.write(a, &[v])
    }

    fn al_control<A: Application<N>>(&mut self, pdi: &mut P, app: &mut A) -> R<P> {
        let ctl = pdi.read_u16(reg::AL_CONTROL)?;
        let code = (ctl & 0x0F) as u8;
        let ack = ctl & 0x10 != 0;
        if self.error && !ack && code != AlState::Init.code() {
            // An indicated error must be acknowledged first; status stays.
            return self.write_status(pdi);
        }
        if ack || code == AlState::Init.code() {
            self.error = false;
            self.code = AlStatusCode::NONE;
        }
        let Some(req) = AlState::from_code(code) else {
            return self.set_error(pdi, AlStatusCode::UNKNOWN_STATE);
        };
        if req == self.state {
            return self.write_status(pdi);
        }
        use AlState::*;
        let res = match (self.state, req) {
            (_, Init) => {
                self.go_down(pdi, app, Init)?;
                Ok(())
            }
            (Init, PreOp) => self.start_mailbox(pdi, app, false)?,
            (Init, Boot) => {
                if self.od.def().boot_mailbox.is_none() {
                    Err(AlStatusCode::BOOT_NOT_SUPPORTED)
                } else {
                    self.start_mailbox(pdi, app, true)?
                }
            }
            (PreOp, SafeOp) if self.stepwise => {
                // The mappings are unused below SAFEOP: they hold the steps' results,
                // compiled in place.
                match pdo::compile_into(&self.od, Dir::Rx, &mut self.rx_map) {
                    Ok(()) => {
                        self.pd_step = PdStep::Rx;
                        return Ok(());
                    }
                    Err(_) => Err(AlStatusCode::INVALID_OUTPUT_MAPPING),
                }
            }
            (PreOp, SafeOp) => self.start_pd(pdi, app)?,
            (SafeOp, Op) => match app.state_change(SafeOp, Op, &mut self.od) {
                Ok(()) => {
                    self.state = Op;
                    Ok(())
                }
                Err(c) => Err(c),
            },
            (Op, SafeOp) => {
                app.safe_outputs(&mut self.od);
                let _ = app.state_change(Op, SafeOp, &mut self.od);
                self.state = SafeOp;
                Ok(())
            }
            (Op | SafeOp, PreOp) => {
                self.go_down(pdi, app, PreOp)?;
                Ok(())
            }
            _ => Err(AlStatusCode::INVALID_STATE_CHANGE),
        };
        match res {
            Ok(()) => self.write_status(pdi),
            Err(c) => self.set_error(pdi, c),
        }
    }

    fn go_down<A: Application<N>>(&mut self, pdi: &mut P, app: &mut A, to: AlState) -> R<P> {
        let from = self.state;
        if from >= AlState::SafeOp {
            app.safe_outputs(&mut self.od);
            Self::sm_enable(pdi, 2, false)?;
            Self::sm_enable(pdi, 3, false)?;
            self.sync = SyncMode::FreeRun;
            Self::set_event_mask(pdi, reg::EV_AL_CONTROL)?;
        }
        if to == AlState::Init {
            self.foe_reset(app);
            self.stop_mailbox(pdi)?;
        }
        let _ = app.state_change(from, to, &mut self.od);
        self.state = to;
        Ok(())
    }

    fn read_sm(pdi: &mut P, n: u8) -> Result<(u16, u16, u8, u8), P::Error> {
        let mut r = [0u8; 8];
        pdi.read(reg::sm(n, 0), &mut r)?;
        Ok((
            u16::from_le_bytes([r[0], r[1]]),
            u16::from_le_bytes([r[2], r[3]]),
            r[4],
            r[6],
        ))
    }

    /// SM0/SM1 as the mailbox definition `mb` requires; also returns SM1's activate byte.
    fn mbx_config_ok(pdi: &mut P, mb: MailboxDef) -> Result<(bool, u8), P::Error> {
        let (s0, l0, c0, a0) = Self::read_sm(pdi, 0)?;
        let (s1, l1, c1, a1) = Self::read_sm(pdi, 1)?;
        let ok = s0 == mb.rx_start
            && l0 == mb.rx_len
            && c0 & 0x0F == 0x06
            && a0 & 1 != 0
            && s1 == mb.tx_start
            && l1 == mb.tx_len
            && c1 & 0x0F == 0x02
            && a1 & 1 != 0;
        Ok((ok, a1))
    }

    /// SM2/SM3 against process data sizes `out`/`inp` (bytes): 0x001D / 0x001E if not.
    fn pd_config_ok(
        &self,
        pdi: &mut P,
        out: usize,
        inp: usize,
    ) -> Result<Result<(), AlStatusCode>, P::Error> {
        let def = self.od.def();
        let (s2, l2, c2, a2) = Self::read_sm(pdi, 2)?;
        let out_ok = if out == 0 {
            a2 & 1 == 0 || l2 == 0
        } else {
            s2 == def.sm2_start && l2 as usize == out && c2 & 0x0F == 0x04 && a2 & 1 != 0
        };
        if !out_ok {
            return Ok(Err(AlStatusCode::INVALID_OUTPUT_CONFIG));
        }
        let (s3, l3, c3, a3) = Self::read_sm(pdi, 3)?;
        let in_ok = if inp == 0 {
            a3 & 1 == 0 || l3 == 0
        } else {
            s3 == def.sm3_start && l3 as usize == inp && c3 & 0x0F == 0x00 && a3 & 1 != 0
        };
        if !in_ok {
            return Ok(Err(AlStatusCode::INVALID_INPUT_CONFIG));
        }
        Ok(Ok(()))
    }

    /// The SM change AL event (a master changed an SM activation) outside a state change,
    /// checked as SOES does: in PREOP and above the mailbox SMs against the definition
    /// (else INIT + 0x0016, BOOT: 0x0015); in SAFEOP/OP SM2/SM3 against the running mapping
    /// (else PREOP + 0x001D / 0x001E). Reading the SM registers clears the event.
    fn sm_change<A: Application<N>>(&mut self, pdi: &mut P, app: &mut A) -> R<P> {
        if !self.mbx.running {
            return Ok(());
        }
        let (ok, _) = Self::mbx_config_ok(pdi, self.mbx_def())?;
        if !ok {
            let code = if self.mbx.boot {
                AlStatusCode::INVALID_BOOT_MBX_CONFIG
            } else {
                AlStatusCode::INVALID_MBX_CONFIG
            };
            self.go_down(pdi, app, AlState::Init)?;
            return self.set_error(pdi, code);
        }
        if self.state >= AlState::SafeOp {
            let (out, inp) = (self.rx_map.bytes(), self.tx_map.bytes());
            if let Err(code) = self.pd_config_ok(pdi, out, inp)? {
                self.go_down(pdi, app, AlState::PreOp)?;
                return self.set_error(pdi, code);
            }
        }
        Ok(())
    }

    fn start_mailbox<A: Application<N>>(
        &mut self,
        pdi: &mut P,
        app: &mut A,
        boot: bool,
    ) -> Result<Result<(), AlStatusCode>, P::Error> {
        let def = if boot {
            self.od.def().boot_mailbox
        } else {
            Some(self.od.def().mailbox)
        };
        let bad = if boot {
            AlStatusCode::INVALID_BOOT_MBX_CONFIG
        } else {
            AlStatusCode::INVALID_MBX_CONFIG
        };
        let Some(mb) = def else {
            return Ok(Err(AlStatusCode::BOOT_NOT_SUPPORTED));
        };
        let (ok, a1) = Self::mbx_config_ok(pdi, mb)?;
        if !ok {
            return Ok(Err(bad));
        }
        let to = if boot { AlState::Boot } else { AlState::PreOp };
        if let Err(c) = app.state_change(AlState::Init, to, &mut self.od) {
            return Ok(Err(c));
        }
        Self::sm_enable(pdi, 0, true)?;
        Self::sm_enable(pdi, 1, true)?;
        self.mbx.reset();
        self.sdo = SdoState::default();
        self.foe_reset(app);
        self.mbx.running = true;
        self.mbx.boot = boot;
        self.mbx.toggle = a1 & 2 != 0;
        // Acknowledge state of the repeat bit follows the request bit at start.
        let p1 = pdi.read_u8(reg::sm(1, 7))?;
        let p1 = if self.mbx.toggle { p1 | 2 } else { p1 & !2 };
        pdi.write(reg::sm(1, 7), &[p1])?;
        self.state = to;
        Ok(Ok(()))
    }

    fn stop_mailbox(&mut self, pdi: &mut P) -> R<P> {
        Self::sm_enable(pdi, 0, false)?;
        Self::sm_enable(pdi, 1, false)?;
        self.mbx.reset();
        self.sdo = SdoState::default();
        Ok(())
    }

    fn start_pd<A: Application<N>>(
        &mut self,
        pdi: &mut P,
        app: &mut A,
    ) -> Result<Result<(), AlStatusCode>, P::Error> {
        // Checked first and compiled into the stack's own mappings only when the transition
        // is taken: a refused one leaves the active mappings as they were, and no mapping
        // is built on the stack.
        let rx = match pdo::check::<N, K>(&self.od, Dir::Rx, K) {
            Ok((bytes, _)) => bytes,
            Err(_) => return Ok(Err(AlStatusCode::INVALID_OUTPUT_MAPPING)),
        };
        let tx = match pdo::check::<N, K>(&self.od, Dir::Tx, K) {
            Ok((bytes, _)) => bytes,
            Err(_) => return Ok(Err(AlStatusCode::INVALID_INPUT_MAPPING)),
        };
        self.start_pd_with(pdi, app, rx, tx, true)
    }

    /// PREOP → SAFEOP with mappings of `rx`, `tx` bytes: SM2/SM3 and the sync mode
    /// checked, the application asked, the process data started. `compile`: the mappings
    /// (checked) are compiled into the stack's when the transition is taken; else they are
    /// there already (stepwise).
    fn start_pd_with<A: Application<N>>(
        &mut self,
        pdi: &mut P,
        app: &mut A,
        rx: usize,
        tx: usize,
        compile: bool,
    ) -> Result<Result<(), AlStatusCode>, P::Error> {
        if let Err(c) = self.pd_config_ok(pdi, rx, tx)? {
            return Ok(Err(c));
        }
        let mode = match self.check_sync(pdi)? {
            Ok(m) => m,
            Err(c) => return Ok(Err(c)),
        };
        if let Err(c) = app.state_change(AlState::PreOp, AlState::SafeOp, &mut self.od) {
            return Ok(Err(c));
        }
        if compile {
            // Checked above on the same dictionary: does not fail.
            if pdo::compile_into(&self.od, Dir::Rx, &mut self.rx_map).is_err() {
                return Ok(Err(AlStatusCode::INVALID_OUTPUT_MAPPING));
            }
            if pdo::compile_into(&self.od, Dir::Tx, &mut self.tx_map).is_err() {
                return Ok(Err(AlStatusCode::INVALID_INPUT_MAPPING));
            }
        }
        self.tx_full = self.tx_map.covers_all();
        self.sync = mode;
        self.sm2_taken = false;
        self.diag.missed_count = 0;
        self.diag.exceeded_count = 0;
        self.diag.publish(&mut self.od);
        // The PDI interrupt carries exactly what `on_pdi_irq` serves: in SM-synchronous
        // mode the SM event that triggers the cycle (an AL control event still pending
        // would otherwise hold the line and hide the next edge); else AL control only.
        let mask = match mode {
            SyncMode::SmSync | SyncMode::DcSync1 if rx > 0 => reg::ev_sm(2),
            SyncMode::SmSync => reg::ev_sm(3),
            _ => reg::EV_AL_CONTROL,
        };
        Self::set_event_mask(pdi, mask)?;
        app.safe_outputs(&mut self.od);
        if rx > 0 {
            Self::sm_enable(pdi, 2, true)?;
        }
        if tx > 0 {
            Self::sm_enable(pdi, 3, true)?;
        }
        self.state = AlState::SafeOp;
        self.write_inputs(pdi)?;
        Ok(Ok(()))
    }

    /// Decides the sync mode from 0x1C32:01 and the ESC's DC activation.
    fn check_sync(&mut self, pdi: &mut P) -> Result<Result<SyncMode, AlStatusCode>, P::Error> {
        let def = self.od.def();
        let act = pdi.read_u8(reg::DC_ACTIVATION + 1)?;
        let dc_on = act & 0x03 == 0x03;
        let sync1 = act & 0x04 != 0;
        let mut mode = self.od.sync_mode();
        let supported = |m: SyncMode| def.sync.supported & m.support_bit() != 0;
        if dc_on {
            if !matches!(mode, SyncMode::DcSync0 | SyncMode::DcSync1) {
                mode = if sync1 {
                    SyncMode::DcSync1
                } else {
                    SyncMode::DcSync0
                };
            }
            if !supported(mode) {
                return Ok(Err(AlStatusCode::INVALID_DC_SYNC_CONFIG));
            }
            if mode == SyncMode::DcSync1 && !sync1 {
                return Ok(Err(AlStatusCode::INVALID_DC_SYNC_CONFIG));
            }
            let cyc = pdi.read_u32(reg::DC_SYNC0_CYCLE)?;
            if cyc != 0 && cyc < def.sync.min_cycle_ns {
                return Ok(Err(AlStatusCode::CYCLE_TIME_TOO_SMALL));
            }
            let _ = self.od.set(0x1C32, 2, cyc);
            let _ = self.od.set(0x1C33, 2, cyc);
            // ETG.1020: 0x1C33:03 shift time = from SYNC0 to the input latch, which with
            // SYNC1 is the SYNC1 cycle time register (a delay after SYNC0 when shorter
            // than the SYNC0 cycle); 0 without SYNC1.
            let shift = if mode == SyncMode::DcSync1 {
                pdi.read_u32(reg::DC_SYNC1_CYCLE)?
            } else {
                0
            };
            let _ = self.od.set(0x1C33, 3, shift);
        } else {
            match mode {
                SyncMode::DcSync0 | SyncMode::DcSync1 => {
                    return Ok(Err(AlStatusCode::INVALID_DC_SYNC_CONFIG))
                }
                SyncMode::FreeRun if !supported(mode) => {
                    return Ok(Err(AlStatusCode::FREERUN_NOT_SUPPORTED))
                }
                SyncMode::SmSync if !supported(mode) => {
                    return Ok(Err(AlStatusCode::SYNC_NOT_SUPPORTED))
                }
                _ => {}
            }
        }
        let _ = self.od.set(0x1C32, 1, mode as u16);
        let _ = self.od.set(0x1C33, 1, mode as u16);
        Ok(Ok(mode))
    }

    // ------------------------------------------------------------------ mailbox

    pub(crate) fn mbx_def(&self) -> MailboxDef {
        match (self.mbx.boot, self.od.def().boot_mailbox) {
            (true, Some(b)) => b,
            _ => self.od.def().mailbox,
        }
    }

    fn mailbox<A: Application<N>>(&mut self, pdi: &mut P, app: &mut A) -> R<P> {
        let mb = self.mbx_def();
        if self.mbx.posted {
            let st = pdi.read_u8(reg::sm(1, 5))?;
            if st & 0x08 == 0 {
                self.mbx.posted = false;
            }
        }
        // Repeat request: SM1 activate bit 1 toggled by the master.
        let act = pdi.read_u8(reg::sm(1, 6))?;
        let rep = act & 0x02 != 0;
        if rep != self.mbx.toggle {
            if self.mbx.last_len > 0 {
                if self.mbx.posted {
                    // The last reply is still in SM1: drop the buffer and write it again.
                    Self::sm_enable(pdi, 1, false)?;
                    Self::sm_enable(pdi, 1, true)?;
                }
                self.write_sm1_last(pdi, mb)?;
                self.stats.mbx_repeats = self.stats.mbx_repeats.wrapping_add(1);
            }
            self.mbx.toggle = rep;
            let p1 = pdi.read_u8(reg::sm(1, 7))?;
            let p1 = if rep { p1 | 2 } else { p1 & !2 };
            pdi.write(reg::sm(1, 7), &[p1])?;
        }
        for _ in 0..2 {
            // Nothing new while the master has not read the last reply (it stays in
            // `last` for a repeat request).
            if self.mbx.posted {
                break;
            }
            // Continuations (segmented SDO info lists) and emergencies before new requests.
            if !self.sdo_continue() {
                if let Some(e) = self.mbx.emcy.iter_mut().find_map(|e| e.take()) {
                    let mut p = [0u8; 10];
                    if e.write_coe(&mut p).is_ok() {
                        self.queue_reply(MailboxType::Coe, &p);
                    }
                } else {
                    let st = pdi.read_u8(reg::sm(0, 5))?;
                    if st & 0x08 == 0 {
                        break;
                    }
                    self.read_sm0(pdi, mb)?;
                    self.handle_request(app, mb);
                }
            }
            if self.mbx.out_len > 0 {
                self.mbx.last_len = core::mem::take(&mut self.mbx.out_len);
                self.write_sm1_last(pdi, mb)?;
            }
        }
        Ok(())
    }

    fn write_sm1_last(&mut self, pdi: &mut P, mb: MailboxDef) -> R<P> {
        let n = self.mbx.last_len.min(mb.tx_len as usize);
        pdi.write(mb.tx_start, &self.mbx.last[..n])?;
        if n < mb.tx_len as usize {
            pdi.write(mb.tx_start + mb.tx_len - 1, &[0])?;
        }
        self.mbx.posted = true;
        Ok(())
    }

    fn read_sm0(&mut self, pdi: &mut P, mb: MailboxDef) -> R<P> {
        let len = mb.rx_len as usize;
        pdi.read(mb.rx_start, &mut self.mbx.rx[..MAILBOX_HEADER_LEN])?;
        let l = u16::from_le_bytes([self.mbx.rx[0], self.mbx.rx[1]]) as usize;
        let body = l.min(len - MAILBOX_HEADER_LEN);
        pdi.read(
            mb.rx_start + MAILBOX_HEADER_LEN as u16,
            &mut self.mbx.rx[MAILBOX_HEADER_LEN..MAILBOX_HEADER_LEN + body],
        )?;
        if MAILBOX_HEADER_LEN + body < len {
            let mut last = [0u8; 1];
            pdi.read(mb.rx_start + mb.rx_len - 1, &mut last)?;
            self.mbx.rx[len - 1] = last[0];
        }
        Ok(())
    }

    /// Queues a reply (header written here with the next counter; built in the reply
    /// buffer, written to SM1 when the handler returns); the service data is `payload`.
    pub(crate) fn queue_reply(&mut self, t: MailboxType, payload: &[u8]) {
        let max = self.mbx_def().tx_len as usize;
        let n = MAILBOX_HEADER_LEN + payload.len();
        if n > max || n > M {
            return;
        }
        self.mbx.out_counter = MailboxHeader::next_counter(self.mbx.out_counter);
        // The header as `MailboxHeader::write` makes it (address 0, channel 0, priority 0),
        // without its checks of fields the stack never sets out of range (a named type, a
        // counter of 1..=7) and their error strings.
        let b = &mut self.mbx.last;
        b[0..2].copy_from_slice(&(payload.len() as u16).to_le_bytes());
        b[2..5].fill(0);
        b[5] = t.code() | (self.mbx.out_counter << 4);
        b[MAILBOX_HEADER_LEN..n].copy_from_slice(payload);
        self.mbx.out_len = n;
    }

    /// Room for service data in one reply.
    pub(crate) fn reply_capacity(&self) -> usize {
        (self.mbx_def().tx_len as usize).min(M) - MAILBOX_HEADER_LEN
    }

    pub(crate) fn mbx_error(&mut self, d: MailboxErrorDetail) {
        let mut p = [0u8; 4];
        if (MailboxErrorReply { detail: d }).write(&mut p).is_ok() {
            self.queue_reply(MailboxType::Error, &p);
        }
    }

    fn handle_request<A: Application<N>>(&mut self, app: &mut A, mb: MailboxDef) {
        let Ok(h) = MailboxHeader::parse(&self.mbx.rx[..]) else {
            self.mbx_error(MailboxErrorDetail::Syntax);
            return;
        };
        self.stats.mbx_requests = self.stats.mbx_requests.wrapping_add(1);
        let max_body = mb.rx_len as usize - MAILBOX_HEADER_LEN;
        if h.length as usize > max_body {
            self.mbx_error(MailboxErrorDetail::InvalidSize);
            return;
        }
        if h.counter != 0 && h.counter == self.mbx.in_counter {
            // A repeated request (the master did not see our read): already handled.
            self.stats.mbx_duplicates = self.stats.mbx_duplicates.wrapping_add(1);
            return;
        }
        self.mbx.in_counter = h.counter;
        if h.length == 0 {
            self.mbx_error(MailboxErrorDetail::SizeTooShort);
            return;
        }
        if h.channel != 0 {
            self.mbx_error(MailboxErrorDetail::InvalidChannel);
            return;
        }
        match h.mailbox_type {
            MailboxType::Error => self.mbx_error(MailboxErrorDetail::Syntax),
            MailboxType::Coe if !self.mbx.boot => {
                let end = MAILBOX_HEADER_LEN + h.length as usize;
                let mut req = [0u8; M];
                req[..end].copy_from_slice(&self.mbx.rx[..end]);
                self.coe_request(app, &req[MAILBOX_HEADER_LEN..end]);
            }
            MailboxType::Foe => {
                let end = MAILBOX_HEADER_LEN + h.length as usize;
                let mut req = [0u8; M];
                req[..end].copy_from_slice(&self.mbx.rx[..end]);
                self.foe_request(app, &req[MAILBOX_HEADER_LEN..end]);
            }
            _ => self.mbx_error(MailboxErrorDetail::UnsupportedProtocol),
        }
    }
}
