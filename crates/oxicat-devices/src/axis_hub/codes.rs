//! Event and error codes (report appendix E.1), their hard/soft classification, the 32-bit
//! system status word, and the event handler that turns posted codes into the system state.
//!
//! The report's event handler got codes through RTOS event-flag bits (24 usable bits, codes
//! shifted into bits 10–23) and lost them silently when two arrived before it ran or when a
//! bit above 23 was used. Here a code is a value in a bounded queue ([`EventQueue`]): every
//! code posted is handled, in order; a full queue is counted ([`SystemState::dropped`]) and
//! raises `ERR_SYS_UNKNOWN`, never silently.
//!
//! Where a code is raised: the report's listings say it for some (`ERR_LED_INIT` in
//! `L_config`, `ERR_LED_OSTIM` when an osTimer cannot be started, `ERR_ECAT_INIT` in
//! `ec_config`, `ERR_ECAT_COMM_LOST` in `ec_connected`); for the others it only names the
//! code or marks it "currently being implemented", and the condition here is the one a
//! firmware engineer would choose, said at each constant: the `*_DSM_FAULT` codes mean a
//! task whose own recovery failed (LED channels restarted 3 times without a frame, no
//! sensor answering on 3 read-outs, the stack out of step with its ESC's AL status), as
//! the report's task manager detected stuck threads and re-created them;
//! `ERR_ECAT_CMD_FAULT` a command understood but not executable (argument out of range),
//! against `ERR_ECAT_CMD_SOFTFAULT` for a command not understood.

/// No error.
pub const ERR_SYS_NONE: u16 = 0;
/// Unknown system error (also: an event could not be queued).
pub const ERR_SYS_UNKNOWN: u16 = 101;
/// No 1-Wire device found at start.
pub const ERR_TEMP_SENS_INIT: u16 = 1101;
/// A sensor stopped answering (soft).
pub const ERR_TEMP_SENS_LOST: u16 = 1102;
/// The 1-Wire bus driver timed out.
pub const ERR_TEMP_SENS_TIMEOUT: u16 = 1103;
/// A sensor is over the overheat threshold (hard).
pub const ERR_TEMP_SENS_OVERHEAT: u16 = 1104;
/// The temperature task failed: sensors were found but no read-out of any of them succeeded
/// [`super::onewire::TEMP_DSM_FAULT_RUNS`] times in a row; the task restarts (ROM search).
/// Hard.
pub const ERR_TEMP_DSM_FAULT: u16 = 1105;
/// oxicat addition: a scratchpad failed its CRC-8 (soft).
pub const ERR_TEMP_SENS_CRC: u16 = 1106;
/// An LED channel (PWM timer + DMA stream) could not be configured (`L_config`).
pub const ERR_LED_INIT: u16 = 1201;
/// An LED DMA transfer did not complete in time.
pub const ERR_LED_TIMEOUT: u16 = 1202;
/// An LED DMA transfer could not be started.
pub const ERR_LED_SEND: u16 = 1203;
/// The one-shot guard timer of the LED transfers could not be armed (the report's osTimer
/// errors).
pub const ERR_LED_OSTIM: u16 = 1204;
/// The LED task failed: [`super::ws2812::LED_DSM_FAULT_RESTARTS`] channel restarts in a row
/// without a frame delivered (hard).
pub const ERR_LED_DSM_FAULT: u16 = 1205;
/// The ESC answers on the PDI but cannot be used: DL status 0x0110 bit 0 clear (its EEPROM
/// configuration not loaded: blank or CRC error), retried every [`super::app::RESTART_MS`]
/// (hard).
pub const ERR_ECAT_INIT: u16 = 1301;
/// EtherCAT communication lost: link down, SM watchdog, or no process data (hard).
pub const ERR_ECAT_COMM_LOST: u16 = 1302;
/// A PDI (SPI) access to the ESC timed out (hard).
pub const ERR_ECAT_TIMEOUT: u16 = 1303;
/// The EtherCAT task is out of step with the ESC: AL status 0x0130 shows another state than
/// the stack's ESM on two supervisor passes in a row; the stack is re-created (hard).
pub const ERR_ECAT_DSM_FAULT: u16 = 1304;
/// A master command was understood but cannot be carried out: an argument out of its range
/// (hard: the node is not in the state the master commanded).
pub const ERR_ECAT_CMD_FAULT: u16 = 1305;
/// A master command was not understood: unknown COMMAND code, ignored (soft).
pub const ERR_ECAT_CMD_SOFTFAULT: u16 = 1306;

/// Temperature task initialised (sensors found).
pub const EV_TEMP_DSM_INIT: u16 = 2101;
/// oxicat addition: every sensor is below the threshold minus the hysteresis again.
pub const EV_TEMP_OVERHEAT_CLEARED: u16 = 2102;
/// oxicat addition: every sensor answers with a good CRC again.
pub const EV_TEMP_SENS_BACK: u16 = 2103;
/// LED task initialised.
pub const EV_LED_DSM_INIT: u16 = 2201;
/// LED rings updated after an LED error.
pub const EV_LED_UPTD: u16 = 2211;
/// The ESC answered and the stack started.
pub const EV_ECAT_ESC_INIT: u16 = 2301;
/// The node is in OP with process data flowing.
pub const EV_ECAT_APP_OP: u16 = 2311;
/// The node went back to INIT.
pub const EV_ECAT_APP_INIT: u16 = 2312;
/// The node left OP on the master's request.
pub const EV_ECAT_APP_NOOP: u16 = 2313;
/// EtherCAT task initialised.
pub const EV_ECAT_DSM_INIT: u16 = 2321;
/// The stack was re-created after a PDI fault (the report's SOES thread respawn).
pub const EV_SOES_RESPAWNED: u16 = 2331;
/// A master command was executed.
pub const EV_ECAT_CMD_ACK: u16 = 2351;
/// The master's LED toggle command was executed (rings off, or on again).
pub const EV_ECAT_CMD_LED_TOGGLE: u16 = 2352;

/// Codes above this are errors (report `ERR_OFFSET`).
pub const ERR_OFFSET: u16 = 1000;
/// Codes above this are events (report `EV_OFFSET`).
pub const EV_OFFSET: u16 = 2000;

/// General state `STATUS_INIT`.
pub const STATUS_INIT: u8 = 1;
/// General state `STATUS_STARTED` (every task initialised).
pub const STATUS_STARTED: u8 = 2;
/// General state `STATUS_NO_ERRORS` (started, was in OP, nothing active).
pub const STATUS_NO_ERRORS: u8 = 4;
/// General state `STATUS_SOFT_ERRORS` (a soft error is active).
pub const STATUS_SOFT_ERRORS: u8 = 5;
/// oxicat addition: a hard error is active (the report shows it only by the red LEDs).
pub const STATUS_HARD_ERRORS: u8 = 6;

/// What a code is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// An event (> 2000).
    Event,
    /// A hard error: red LEDs, general state [`STATUS_HARD_ERRORS`].
    Hard,
    /// A soft error: warning colour, general state [`STATUS_SOFT_ERRORS`].
    Soft,
    /// Neither (≤ 1000 or unknown).
    Unknown,
}

/// Classifies a code as the report's event handler does (`evH_errHandling`); error codes the
/// report does not list as hard or soft are soft here (the report set the warning flag).
pub const fn classify(code: u16) -> Kind {
    match code {
        ERR_ECAT_DSM_FAULT
        | ERR_ECAT_CMD_FAULT
        | ERR_LED_DSM_FAULT
        | ERR_TEMP_DSM_FAULT
        | ERR_TEMP_SENS_OVERHEAT
        | ERR_ECAT_COMM_LOST
        | ERR_ECAT_TIMEOUT
        | ERR_ECAT_INIT => Kind::Hard,
        c if c > EV_OFFSET && c < 3000 => Kind::Event,
        c if c > ERR_OFFSET && c < EV_OFFSET => Kind::Soft,
        _ => Kind::Unknown,
    }
}

/// The error codes the handler keeps as "active" (one bit each, in this order).
pub const TRACKED: [u16; 18] = [
    ERR_TEMP_SENS_INIT,
    ERR_TEMP_SENS_LOST,
    ERR_TEMP_SENS_TIMEOUT,
    ERR_TEMP_SENS_OVERHEAT,
    ERR_TEMP_DSM_FAULT,
    ERR_TEMP_SENS_CRC,
    ERR_LED_INIT,
    ERR_LED_TIMEOUT,
    ERR_LED_SEND,
    ERR_LED_OSTIM,
    ERR_LED_DSM_FAULT,
    ERR_ECAT_INIT,
    ERR_ECAT_COMM_LOST,
    ERR_ECAT_TIMEOUT,
    ERR_ECAT_DSM_FAULT,
    ERR_ECAT_CMD_FAULT,
    ERR_ECAT_CMD_SOFTFAULT,
    ERR_SYS_UNKNOWN,
];

const fn bit(code: u16) -> u32 {
    let mut i = 0;
    while i < TRACKED.len() {
        if TRACKED[i] == code {
            return 1 << i;
        }
        i += 1;
    }
    0
}

/// The errors an event clears (the report clears `ERR_ECAT_COMM_LOST` on `EV_ECAT_APP_OP`;
/// the others follow the same rule for the conditions oxicat can see end).
const fn clears(event: u16) -> u32 {
    match event {
        EV_TEMP_DSM_INIT => bit(ERR_TEMP_SENS_INIT) | bit(ERR_TEMP_DSM_FAULT),
        EV_TEMP_OVERHEAT_CLEARED => bit(ERR_TEMP_SENS_OVERHEAT),
        EV_TEMP_SENS_BACK => {
            bit(ERR_TEMP_SENS_LOST) | bit(ERR_TEMP_SENS_CRC) | bit(ERR_TEMP_SENS_TIMEOUT)
        }
        EV_LED_UPTD | EV_LED_DSM_INIT => {
            bit(ERR_LED_INIT)
                | bit(ERR_LED_TIMEOUT)
                | bit(ERR_LED_SEND)
                | bit(ERR_LED_OSTIM)
                | bit(ERR_LED_DSM_FAULT)
        }
        EV_ECAT_APP_OP => {
            bit(ERR_ECAT_COMM_LOST)
                | bit(ERR_ECAT_TIMEOUT)
                | bit(ERR_ECAT_INIT)
                | bit(ERR_ECAT_DSM_FAULT)
        }
        EV_ECAT_ESC_INIT | EV_SOES_RESPAWNED => bit(ERR_ECAT_TIMEOUT) | bit(ERR_ECAT_INIT),
        EV_ECAT_CMD_ACK | EV_ECAT_CMD_LED_TOGGLE => {
            bit(ERR_ECAT_CMD_SOFTFAULT) | bit(ERR_ECAT_CMD_FAULT)
        }
        _ => 0,
    }
}

/// The report's `sysState`: `| 14 bits last event | 14 bits last error | 4 bits general state |`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StatusWord(pub u32);

impl StatusWord {
    /// `STATUS_OFFSET_FOR_ERR`.
    pub const ERR_SHIFT: u32 = 4;
    /// `STATUS_OFFSET_FOR_EV`.
    pub const EV_SHIFT: u32 = 18;
    /// `STATUS_DATA_MASK`.
    pub const DATA_MASK: u32 = 0x3FFF;
    /// `STATUS_SHORT_MASK`.
    pub const SHORT_MASK: u32 = 0x0F;

    /// Packs the three fields (codes are masked to 14 bits, the state to 4).
    pub const fn new(general: u8, last_error: u16, last_event: u16) -> Self {
        Self(
            (general as u32 & Self::SHORT_MASK)
                | ((last_error as u32 & Self::DATA_MASK) << Self::ERR_SHIFT)
                | ((last_event as u32 & Self::DATA_MASK) << Self::EV_SHIFT),
        )
    }

    /// The 4-bit general state.
    pub const fn general(self) -> u8 {
        (self.0 & Self::SHORT_MASK) as u8
    }

    /// The last error code.
    pub const fn last_error(self) -> u16 {
        ((self.0 >> Self::ERR_SHIFT) & Self::DATA_MASK) as u16
    }

    /// The last event code.
    pub const fn last_event(self) -> u16 {
        ((self.0 >> Self::EV_SHIFT) & Self::DATA_MASK) as u16
    }
}

/// Capacity of the event queue; every task posts at most a few codes per run and the
/// handler drains the queue after each task, so it never fills in normal operation.
pub const QUEUE: usize = 32;

/// Bounded FIFO of posted codes (single producer per call, the handler is the consumer).
#[derive(Debug, Clone)]
pub struct EventQueue {
    buf: [u16; QUEUE],
    head: usize,
    len: usize,
    dropped: u32,
}

impl Default for EventQueue {
    fn default() -> Self {
        Self {
            buf: [0; QUEUE],
            head: 0,
            len: 0,
            dropped: 0,
        }
    }
}

impl EventQueue {
    /// Posts `code`; false (and counted) if the queue is full.
    pub fn post(&mut self, code: u16) -> bool {
        if self.len == QUEUE {
            self.dropped = self.dropped.saturating_add(1);
            return false;
        }
        self.buf[(self.head + self.len) % QUEUE] = code;
        self.len += 1;
        true
    }

    /// Takes the oldest code.
    pub fn take(&mut self) -> Option<u16> {
        if self.len == 0 {
            return None;
        }
        let c = self.buf[self.head];
        self.head = (self.head + 1) % QUEUE;
        self.len -= 1;
        Some(c)
    }

    /// Codes waiting.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when nothing waits.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

/// The event handler's state (the report's `Event Handler SDM` and its flags).
#[derive(Debug, Clone, Default)]
pub struct SystemState {
    /// Pending codes.
    pub queue: EventQueue,
    active: u32,
    inits: u8,
    started: bool,
    was_op: bool,
    ecat_init: bool,
    last_error: u16,
    last_event: u16,
    /// Codes that could not be queued (the report lost these silently).
    pub dropped: u32,
    /// Codes handled.
    pub handled: u32,
}

impl SystemState {
    /// Posts a code for the handler.
    pub fn post(&mut self, code: u16) {
        self.queue.post(code);
    }

    /// The event handler: handles every queued code in order (runs after each task, above
    /// their priority, as the report's event-driven `eventH_SM`).
    pub fn handle_events(&mut self) {
        if self.queue.dropped != self.dropped {
            self.dropped = self.queue.dropped;
            self.active |= bit(ERR_SYS_UNKNOWN);
            self.last_error = ERR_SYS_UNKNOWN;
        }
        while let Some(code) = self.queue.take() {
            self.handled = self.handled.wrapping_add(1);
            match classify(code) {
                Kind::Event => {
                    self.last_event = code;
                    self.active &= !clears(code);
                    match code {
                        EV_TEMP_DSM_INIT => self.inits |= 1,
                        EV_LED_DSM_INIT => self.inits |= 2,
                        EV_ECAT_DSM_INIT => self.inits |= 4,
                        EV_ECAT_APP_OP => {
                            self.was_op = true;
                            self.ecat_init = false;
                        }
                        EV_ECAT_APP_INIT => {
                            self.was_op = false;
                            self.ecat_init = true;
                        }
                        EV_ECAT_APP_NOOP => self.was_op = false,
                        _ => {}
                    }
                    if self.inits == 7 {
                        self.started = true;
                    }
                }
                Kind::Hard | Kind::Soft => {
                    self.last_error = code;
                    self.active |= bit(code);
                }
                Kind::Unknown => {
                    self.last_error = ERR_SYS_UNKNOWN;
                    self.active |= bit(ERR_SYS_UNKNOWN);
                }
            }
        }
    }

    /// True while a hard error is active (LEDs red).
    pub fn hard(&self) -> bool {
        TRACKED
            .iter()
            .any(|&c| self.active & bit(c) != 0 && classify(c) == Kind::Hard)
    }

    /// True while a soft error is active (warning colour).
    pub fn soft(&self) -> bool {
        TRACKED
            .iter()
            .any(|&c| self.active & bit(c) != 0 && classify(c) != Kind::Hard)
    }

    /// True while `code` is active.
    pub fn is_active(&self, code: u16) -> bool {
        self.active & bit(code) != 0
    }

    /// The most severe active error: the first active hard one, else the first soft one,
    /// else 0 (the ERROR process-data entry).
    pub fn active_error(&self) -> u16 {
        let pick = |hard: bool| {
            TRACKED
                .iter()
                .copied()
                .find(|&c| self.active & bit(c) != 0 && (classify(c) == Kind::Hard) == hard)
        };
        pick(true).or_else(|| pick(false)).unwrap_or(ERR_SYS_NONE)
    }

    /// The report's INIT warning: the node's ESM was in INIT (`EV_ECAT_APP_INIT`) and has
    /// not reached OP since (`EV_ECAT_APP_OP`); the LEDs show the warning colour.
    pub fn ecat_init_warning(&self) -> bool {
        self.ecat_init
    }

    /// True once every task reported its initialisation (`STATUS_STARTED`).
    pub fn started(&self) -> bool {
        self.started
    }

    /// The general state.
    pub fn general(&self) -> u8 {
        if !self.started {
            STATUS_INIT
        } else if self.hard() {
            STATUS_HARD_ERRORS
        } else if self.soft() {
            STATUS_SOFT_ERRORS
        } else if self.was_op {
            STATUS_NO_ERRORS
        } else {
            STATUS_STARTED
        }
    }

    /// The last event code handled.
    pub fn last_event(&self) -> u16 {
        self.last_event
    }

    /// The last error code handled.
    pub fn last_error(&self) -> u16 {
        self.last_error
    }

    /// The status word.
    pub fn word(&self) -> StatusWord {
        StatusWord::new(self.general(), self.last_error, self.last_event)
    }
}
