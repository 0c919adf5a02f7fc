//! The hub's tasks: the application ([`HubApp`], the stack's [`Application`]) and the
//! firmware main ([`HubFirmware`]) that owns the slave stack and runs the EtherCAT
//! supervisor.

use core::borrow::BorrowMut;

use oxicat_slave::{AlState, AlStatusCode, Application, Od, Pdi, Slave, SlaveSlot, Var};

use super::codes::{self, SystemState};
use super::device::{self, IMAGE, MBX, SENSORS, TEMP_INVALID};
use super::onewire::{OneWireBus, TempFrame, TempTask, TEMP_PERIOD_MS};
use super::ws2812::{self, LedStrip, LedTask, Rgb, LED_PERIOD_MS};

/// The hub's definition as its stack runs it (board image and host twin alike): without
/// the ESI/SII description (`DeviceDef::for_image`), which the stack does not read, so a
/// board image does not carry it.
static IMAGE_DEF: oxicat_slave::DeviceDef = device::DEF.for_image();

/// CMSIS-RTOS priority of a task (higher runs first when several are due at once).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Priority {
    /// `osPriorityNormal` (24).
    Normal = 24,
    /// `osPriorityAboveNormal` (32).
    AboveNormal = 32,
    /// `osPriorityHigh` (40).
    High = 40,
}

/// A periodic task: the timer id the firmware's `on_timer` is called with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Task {
    /// Timer id.
    pub id: u8,
    /// The report's thread name.
    pub name: &'static str,
    /// Priority.
    pub priority: Priority,
    /// Release period in ns.
    pub period_ns: u64,
}

/// Timer id of the application task (SOES APP SDM: stack poll + process data).
pub const TIMER_APP: u8 = 1;
/// Timer id of the LED task.
pub const TIMER_LED: u8 = 2;
/// Timer id of the EtherCAT supervisor (ECAT SDM).
pub const TIMER_SUPERVISOR: u8 = 3;
/// Timer id of the temperature task.
pub const TIMER_TEMP: u8 = 4;

/// The periodic tasks in priority order (report Table 5.3 / Table 4.2). The event handler
/// (AboveNormal, event driven) is not a timer: it runs after every task that posted.
pub const TASKS: [Task; 4] = [
    Task {
        id: TIMER_APP,
        name: "SOES APP SDM",
        priority: Priority::AboveNormal,
        period_ns: 10_000_000,
    },
    Task {
        id: TIMER_LED,
        name: "LED SDM",
        priority: Priority::Normal,
        period_ns: LED_PERIOD_MS as u64 * 1_000_000,
    },
    Task {
        id: TIMER_SUPERVISOR,
        name: "ECAT SDM",
        priority: Priority::Normal,
        period_ns: SUPERVISOR_PERIOD_MS as u64 * 1_000_000,
    },
    Task {
        id: TIMER_TEMP,
        name: "Temperature SDM",
        priority: Priority::Normal,
        period_ns: TEMP_PERIOD_MS as u64 * 1_000_000,
    },
];

/// The supervisor's period (report: 100 ms in the connected state).
pub const SUPERVISOR_PERIOD_MS: u32 = 100;
/// No new outputs in OP for this long is communication loss.
pub const QUIET_LIMIT_MS: u32 = 300;
/// Consecutive failed PDI accesses that make the ESC "gone".
pub const PDI_FAULT_LIMIT: u32 = 3;
/// Time between attempts to restart the stack after a PDI fault.
pub const RESTART_MS: u32 = 1000;

#[derive(Debug, Clone, Copy)]
struct HubIo {
    temps: [Var<i16>; SENSORS],
    status: Var<u32>,
    event: Var<u16>,
    error: Var<u16>,
    cmd: [Var<u16>; 4],
}

impl HubIo {
    /// The handles, from the declaration ([`device::OBJECTS`]): offsets and types checked
    /// when the crate builds.
    const VARS: Self = Self {
        temps: Var::subs(device::OBJECTS, 0x6000, 1),
        status: Var::of(device::OBJECTS, 0x6001, 1),
        event: Var::of(device::OBJECTS, 0x6001, 2),
        error: Var::of(device::OBJECTS, 0x6001, 3),
        cmd: Var::subs(device::OBJECTS, 0x7000, 1),
    };

    /// The handles for `od`; `None` if it is not the hub's dictionary.
    fn resolve<const N: usize>(od: &Od<N>) -> Option<Self> {
        od.built_on(device::OBJECTS).then_some(Self::VARS)
    }
}

/// The hub application: temperature task, LED task, event handler and the process data.
///
/// The temperature task hands its readings to the application task **by value** through
/// `temp_slot` (a one-element mailbox); see the module documentation for why this cannot
/// race.
pub struct HubApp<B: OneWireBus, L: LedStrip> {
    /// System state and event handler.
    pub sys: SystemState,
    /// Temperature task state.
    pub temp: TempTask,
    /// LED task state.
    pub led: LedTask,
    /// The 1-Wire bus.
    pub bus: B,
    /// The LED strips.
    pub strip: L,
    temp_slot: Option<TempFrame>,
    published: [i16; SENSORS],
    last_cmd: [u16; 4],
    /// The master's custom colour, if one is commanded.
    pub custom: Option<Rgb>,
    /// False while the master has toggled the LED rings off.
    pub lit: bool,
    /// The node is in OP (kept by the state-change hook).
    pub op: bool,
    /// Application cycles run.
    pub cycles: u32,
    io: Option<HubIo>,
}

impl<B: OneWireBus, L: LedStrip> HubApp<B, L> {
    /// The application on its hardware.
    pub fn new(bus: B, strip: L) -> Self {
        Self {
            sys: SystemState::default(),
            temp: TempTask::default(),
            led: LedTask::default(),
            bus,
            strip,
            temp_slot: None,
            published: [TEMP_INVALID; SENSORS],
            last_cmd: [0; 4],
            custom: None,
            lit: true,
            op: false,
            cycles: 0,
            io: None,
        }
    }

    /// The temperatures the process data carries (0.01 °C).
    pub fn published(&self) -> &[i16; SENSORS] {
        &self.published
    }

    /// Executes a changed master command: `EV_ECAT_CMD_ACK` (or `EV_ECAT_CMD_LED_TOGGLE`)
    /// when done, `ERR_ECAT_CMD_FAULT` when a known command's argument is out of range
    /// (nothing changes), `ERR_ECAT_CMD_SOFTFAULT` for an unknown code (ignored).
    fn command(&mut self, cmd: [u16; 4]) {
        if cmd == self.last_cmd {
            return;
        }
        self.last_cmd = cmd;
        let [c, v0, v1, v2] = cmd;
        let byte = |v: u16| u8::try_from(v).ok();
        let code = match c {
            device::CMD_NONE => return,
            device::CMD_LED_CUSTOM => match (byte(v0), byte(v1), byte(v2)) {
                (Some(r), Some(g), Some(b)) => {
                    self.custom = Some(Rgb::new(r, g, b));
                    codes::EV_ECAT_CMD_ACK
                }
                _ => codes::ERR_ECAT_CMD_FAULT,
            },
            device::CMD_LED_AUTO => {
                self.custom = None;
                codes::EV_ECAT_CMD_ACK
            }
            device::CMD_SET_THRESHOLD => {
                let t = v0 as i16;
                if device::THRESHOLD_RANGE.contains(&t) {
                    self.temp.threshold = t;
                    codes::EV_ECAT_CMD_ACK
                } else {
                    codes::ERR_ECAT_CMD_FAULT
                }
            }
            device::CMD_LED_TOGGLE => {
                self.lit = !self.lit;
                codes::EV_ECAT_CMD_LED_TOGGLE
            }
            _ => codes::ERR_ECAT_CMD_SOFTFAULT,
        };
        self.sys.post(code);
    }
}

impl<const N: usize, B: OneWireBus, L: LedStrip> Application<N> for HubApp<B, L> {
    fn state_change(
        &mut self,
        _from: AlState,
        to: AlState,
        _od: &mut Od<N>,
    ) -> Result<(), AlStatusCode> {
        self.op = to == AlState::Op;
        Ok(())
    }

    fn safe_outputs(&mut self, _od: &mut Od<N>) {
        self.custom = None;
        self.lit = true;
        self.last_cmd = [0; 4];
    }

    /// The application task's process-data step: take the newest temperature frame (the one
    /// hand-over point), execute a changed master command, run the event handler, publish.
    fn cycle(&mut self, od: &mut Od<N>) {
        self.cycles = self.cycles.wrapping_add(1);
        if self.io.is_none() {
            self.io = HubIo::resolve(od);
        }
        let Some(io) = self.io else {
            return;
        };
        if let Some(frame) = self.temp_slot.take() {
            self.published = frame.values;
        }
        if self.op {
            let cmd = io.cmd.map(|v| od.load(v));
            self.command(cmd);
        }
        self.sys.handle_events();
        self.publish(od);
    }

    fn timer(&mut self, id: u8, _od: &mut Od<N>) {
        self.run_task(id);
    }
}

impl<B: OneWireBus, L: LedStrip> HubApp<B, L> {
    /// Writes the temperatures and STATUS/EVENT/ERROR into the object dictionary (after
    /// every process-data cycle, and after every task release so that an SDO upload of
    /// 0x6001 in PRE-OP, where no cycle runs, reads the current state).
    pub fn publish<const N: usize>(&mut self, od: &mut Od<N>) {
        if self.io.is_none() {
            self.io = HubIo::resolve(od);
        }
        let Some(io) = self.io else {
            return;
        };
        for (v, &t) in io.temps.iter().zip(self.published.iter()) {
            od.store(*v, t);
        }
        od.store(io.status, self.sys.word().0);
        od.store(io.event, self.sys.last_event());
        od.store(io.error, self.sys.active_error());
    }

    /// Lets the temperature task go on with its 1-Wire transactions (on an interrupt-driven
    /// bus a release runs in the background; call this while `temp.busy()`), then the event
    /// handler.
    pub fn resume_temp(&mut self) {
        if let Some(frame) = self.temp.resume(&mut self.bus, &mut self.sys) {
            self.temp_slot = Some(frame);
        }
        self.sys.handle_events();
    }

    /// One release of task `id` (temperature or LED), then the event handler.
    pub fn run_task(&mut self, id: u8) {
        match id {
            TIMER_TEMP => {
                if let Some(frame) = self.temp.run(&mut self.bus, &mut self.sys) {
                    // Newest wins: an unread older frame is replaced, never half-written.
                    self.temp_slot = Some(frame);
                }
            }
            TIMER_LED => {
                let shown = ws2812::choose(&self.sys, self.op, self.custom, self.lit);
                self.led.run(&mut self.strip, &mut self.sys, shown);
            }
            _ => {}
        }
        self.sys.handle_events();
    }
}

/// The supervisor's view of the EtherCAT side.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EcatPhase {
    /// The ESC does not answer on the PDI; the stack is down and retried.
    Fault,
    /// The stack runs; the master has not lost us.
    Connected,
    /// Link down, SM watchdog expired, or no outputs in OP: communication lost.
    CommLost,
}

/// The EtherCAT supervisor (ECAT SDM + the report's task manager).
#[derive(Debug, Clone)]
pub struct Supervisor {
    /// Current phase.
    pub phase: EcatPhase,
    /// PDI accesses that failed (all time).
    pub pdi_errors: u32,
    /// Stack restarts after a PDI fault.
    pub restarts: u32,
    /// Times communication was lost.
    pub losses: u32,
    /// Port 0 link as DL status last showed it.
    pub link_up: bool,
    /// Times the stack was re-created because it was out of step with the ESC
    /// (`ERR_ECAT_DSM_FAULT`).
    pub dsm_faults: u32,
    consecutive: u32,
    mismatch: u32,
    init_seen: bool,
    esc_init_fault: bool,
    fault_ms: u32,
    last_outputs: u32,
    quiet_ms: u32,
    op_reported: bool,
    was_op: bool,
}

impl Default for Supervisor {
    fn default() -> Self {
        Self {
            phase: EcatPhase::Fault,
            pdi_errors: 0,
            restarts: 0,
            losses: 0,
            link_up: false,
            dsm_faults: 0,
            consecutive: 0,
            mismatch: 0,
            init_seen: false,
            esc_init_fault: false,
            fault_ms: 0,
            last_outputs: 0,
            quiet_ms: 0,
            op_reported: false,
            was_op: false,
        }
    }
}

/// Copy steps per direction of the hub stack's compiled PDO mappings, sized to the device:
/// `pdo::map_steps(&device::DEF)` (a test checks it; computed here, the constant formed a
/// query cycle with the stack type in some rustc runs); the default of 64 would be 992 B
/// more RAM in the board image.
pub const MAP: usize = 2;

/// The hub's stack type on PDI `P`.
pub type HubSlave<P> = Slave<P, IMAGE, MBX, MAP>;

/// Where the hub's stack is built, in place ([`SlaveSlot`]): a board image's
/// `static mut` (all zero, in `.bss`), a `Box` on a host. Built as a value and kept in an
/// `Option`, the stack and its moves took an 18 KB frame in the board image.
pub type HubSlot<P> = SlaveSlot<P, IMAGE, MBX, MAP>;

/// The firmware main: owns the slave stack (while the ESC answers) and the application,
/// lends the PDI to the stack per event, and supervises the EtherCAT side. Nothing in it
/// waits on an ESC register: every PDI access returns (the driver has a timeout) and a
/// failed one is counted; [`PDI_FAULT_LIMIT`] in a row take the stack down and it is
/// re-created every [`RESTART_MS`] until the ESC answers again — no MCU reset. The stack
/// is built in `S`, a [`HubSlot`] the firmware lends for good (`&'static mut` on a board,
/// `Box` on a host).
pub struct HubFirmware<P: Pdi, B: OneWireBus, L: LedStrip, S> {
    slot: S,
    /// The application.
    pub app: HubApp<B, L>,
    /// The supervisor.
    pub sup: Supervisor,
    /// The last PDI error.
    pub last_pdi_error: Option<P::Error>,
}

impl<P: Pdi, B: OneWireBus, L: LedStrip, S: BorrowMut<HubSlot<P>>> HubFirmware<P, B, L, S> {
    /// Boots: starts the stack in `slot` if the ESC answers (otherwise the supervisor
    /// retries).
    pub fn new(pdi: &mut P, mut slot: S, bus: B, strip: L) -> Self {
        slot.borrow_mut().stop();
        let mut fw = Self {
            slot,
            app: HubApp::new(bus, strip),
            sup: Supervisor::default(),
            last_pdi_error: None,
        };
        fw.app.sys.post(codes::EV_ECAT_DSM_INIT);
        fw.start_stack(pdi);
        fw.app.sys.handle_events();
        fw
    }

    /// `ec_config`: the ESC must answer (else `ERR_ECAT_TIMEOUT`) and be configured from its
    /// EEPROM, DL status 0x0110 bit 0 (else `ERR_ECAT_INIT`: a blank or corrupt EEPROM, as on
    /// the report's first bring-up), then the stack starts.
    fn start_stack(&mut self, pdi: &mut P) {
        let first = self.sup.phase != EcatPhase::Fault || self.sup.restarts == 0;
        match pdi.read_u16(0x0110) {
            Ok(dl) if dl & 1 == 0 => {
                if !self.sup.esc_init_fault {
                    self.sup.esc_init_fault = true;
                    self.app.sys.post(codes::ERR_ECAT_INIT);
                }
                self.enter_fault();
                return;
            }
            Ok(_) => {}
            Err(e) => {
                self.last_pdi_error = Some(e);
                self.sup.pdi_errors = self.sup.pdi_errors.saturating_add(1);
                if first {
                    self.app.sys.post(codes::ERR_ECAT_TIMEOUT);
                }
                self.enter_fault();
                return;
            }
        }
        // The definition checked when the image is built (`check_def` is not in a board
        // image); the same stack as `start` (the slave crate's tests/slot.rs).
        let def = const { oxicat_slave::CheckedDef::<IMAGE>::new(&IMAGE_DEF) };
        match self.slot.borrow_mut().start_checked(def, pdi) {
            Ok(_) => {
                self.sup.phase = EcatPhase::Connected;
                self.sup.consecutive = 0;
                self.sup.fault_ms = 0;
                self.sup.mismatch = 0;
                self.sup.init_seen = false;
                self.sup.esc_init_fault = false;
                self.app.op = false;
                self.app.sys.post(codes::EV_ECAT_ESC_INIT);
            }
            Err(oxicat_slave::InitError::Pdi(e)) => {
                self.last_pdi_error = Some(e);
                self.sup.pdi_errors = self.sup.pdi_errors.saturating_add(1);
                if first {
                    self.app.sys.post(codes::ERR_ECAT_TIMEOUT);
                }
                self.enter_fault();
            }
            Err(_) => {
                // The definition does not fit the stack: nothing a retry changes, but the
                // node keeps running and says so.
                if !self.sup.esc_init_fault {
                    self.sup.esc_init_fault = true;
                    self.app.sys.post(codes::ERR_ECAT_INIT);
                }
                self.enter_fault();
            }
        }
    }

    fn enter_fault(&mut self) {
        self.slot.borrow_mut().stop();
        self.sup.phase = EcatPhase::Fault;
        self.sup.fault_ms = 0;
        self.app.op = false;
        self.sup.op_reported = false;
    }

    /// The stack, while it runs.
    pub fn slave(&self) -> Option<&HubSlave<P>> {
        self.slot.borrow().slave()
    }

    fn note(&mut self, r: Result<(), P::Error>) {
        match r {
            Ok(()) => self.sup.consecutive = 0,
            Err(e) => {
                self.last_pdi_error = Some(e);
                self.sup.pdi_errors = self.sup.pdi_errors.saturating_add(1);
                self.sup.consecutive += 1;
                if self.sup.consecutive >= PDI_FAULT_LIMIT && self.sup.phase != EcatPhase::Fault {
                    self.app.sys.post(codes::ERR_ECAT_TIMEOUT);
                    self.enter_fault();
                    self.app.sys.handle_events();
                }
            }
        }
    }

    /// Main-loop pass (mailbox, ESM; the free-run cycle).
    pub fn poll(&mut self, pdi: &mut P) {
        if let Some(s) = self.slot.borrow_mut().slave_mut() {
            let r = s.poll(pdi, &mut self.app);
            self.note(r);
        }
    }

    /// PDI interrupt: the SM-synchronous cycle, then the ESM/mailbox work the interrupt
    /// announces (an AL control write is handled at once, not at the next poll).
    pub fn on_pdi_irq(&mut self, pdi: &mut P) {
        if let Some(s) = self.slot.borrow_mut().slave_mut() {
            let r = s.on_pdi_irq(pdi, &mut self.app);
            self.note(r);
        }
        self.poll(pdi);
    }

    /// SYNC0 (DC-synchronous cycle).
    pub fn on_sync0(&mut self, pdi: &mut P) {
        if let Some(s) = self.slot.borrow_mut().slave_mut() {
            let r = s.on_sync0(pdi, &mut self.app);
            self.note(r);
        }
    }

    /// SYNC1.
    pub fn on_sync1(&mut self, pdi: &mut P) {
        if let Some(s) = self.slot.borrow_mut().slave_mut() {
            let r = s.on_sync1(pdi, &mut self.app);
            self.note(r);
        }
    }

    /// The 1-Wire bus may have finished a transaction of the temperature task (a board
    /// whose bus runs in the background calls this every tick): the task takes the result
    /// and starts the next without waiting for the bus.
    pub fn on_onewire(&mut self) {
        if !self.app.temp.busy() {
            return;
        }
        self.app.resume_temp();
        if let Some(s) = self.slot.borrow_mut().slave_mut() {
            self.app.publish(s.od_mut());
        }
    }

    /// Timer `id` of [`TASKS`] fired.
    pub fn on_timer(&mut self, id: u8, pdi: &mut P) {
        match id {
            TIMER_APP => self.poll(pdi),
            TIMER_SUPERVISOR => self.supervise(pdi),
            // The tasks run with or without the stack (their data waits for it).
            _ => self.app.run_task(id),
        }
        if let Some(s) = self.slot.borrow_mut().slave_mut() {
            self.app.publish(s.od_mut());
        }
    }

    fn supervise(&mut self, pdi: &mut P) {
        let Some(slave) = self.slot.borrow().slave() else {
            self.sup.fault_ms += SUPERVISOR_PERIOD_MS;
            if self.sup.fault_ms >= RESTART_MS {
                self.sup.fault_ms = 0;
                let before = self.sup.restarts;
                self.sup.restarts += 1;
                self.start_stack(pdi);
                if self.slave().is_some() {
                    self.app.sys.post(codes::EV_SOES_RESPAWNED);
                } else {
                    self.sup.restarts = before.saturating_add(1);
                }
            }
            self.app.sys.handle_events();
            return;
        };
        let state = slave.state();
        let wd_error = slave.error_indicated() && slave.status_code() == AlStatusCode::SM_WATCHDOG;
        let outputs = slave.stats().outputs;
        let regs = pdi
            .read_u16(0x0110)
            .and_then(|dl| pdi.read_u16(0x0130).map(|al| (dl, al)));
        let (dl, al) = match regs {
            Ok(v) => {
                self.note(Ok(()));
                v
            }
            Err(e) => {
                self.note(Err(e));
                return;
            }
        };
        // The ESM and the ESC must agree on the state; a stack out of step with its ESC
        // (AL status changed behind its back, e.g. a corrupted PDI write) is re-created.
        if AlState::from_code((al & 0x0F) as u8) != Some(state) {
            self.sup.mismatch += 1;
        } else {
            self.sup.mismatch = 0;
        }
        if self.sup.mismatch >= 2 {
            self.sup.dsm_faults += 1;
            self.app.sys.post(codes::ERR_ECAT_DSM_FAULT);
            self.enter_fault();
            self.start_stack(pdi);
            if self.slave().is_some() {
                self.app.sys.post(codes::EV_SOES_RESPAWNED);
            }
            self.sup.was_op = false;
            self.app.sys.handle_events();
            return;
        }
        self.sup.link_up = dl & (1 << 4) != 0;
        if state == AlState::Op && outputs != self.sup.last_outputs {
            self.sup.quiet_ms = 0;
        } else if state == AlState::Op {
            self.sup.quiet_ms = self.sup.quiet_ms.saturating_add(SUPERVISOR_PERIOD_MS);
        }
        self.sup.last_outputs = outputs;
        let lost = !self.sup.link_up
            || wd_error
            || (state == AlState::Op && self.sup.quiet_ms >= QUIET_LIMIT_MS);
        let sys = &mut self.app.sys;
        match self.sup.phase {
            EcatPhase::Connected if lost && (self.sup.was_op || wd_error) => {
                self.sup.phase = EcatPhase::CommLost;
                self.sup.losses += 1;
                self.sup.op_reported = false;
                sys.post(codes::ERR_ECAT_COMM_LOST);
            }
            _ => {}
        }
        if state == AlState::Op && !lost && self.sup.quiet_ms == 0 && !self.sup.op_reported {
            self.sup.phase = EcatPhase::Connected;
            self.sup.op_reported = true;
            sys.post(codes::EV_ECAT_APP_OP);
        }
        if state == AlState::Init {
            // The report's ec_connected: ESC in INIT → EV_ECAT_APP_INIT (warning colour),
            // once per stay in INIT (at boot, after a restart, on the master's request).
            if !self.sup.init_seen {
                self.sup.init_seen = true;
                self.sup.op_reported = false;
                sys.post(codes::EV_ECAT_APP_INIT);
            }
        } else {
            self.sup.init_seen = false;
            if self.sup.was_op && state != AlState::Op && self.sup.phase == EcatPhase::Connected {
                self.sup.op_reported = false;
                sys.post(codes::EV_ECAT_APP_NOOP);
            }
        }
        self.sup.was_op = state == AlState::Op;
        sys.handle_events();
    }
}
