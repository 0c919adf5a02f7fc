//! The CiA402 (IEC 61800-7-201, ETG.6010) drive state machine: controlword commands by
//! their masks, statusword bits and state decoding, every transition 0–16, the fault
//! reset edge, and the option codes 0x605A–0x605E that decide how each stop is done.
//!
//! The machine is pure: [`Fsm::step`] takes the controlword, whether a fault is pending
//! and whether the stop ramp in progress has finished, and returns the transition taken.
//! The drive ([`super::drive`]) runs the ramps the machine asks for ([`Fsm::stopping`]).

/// Controlword bits (0x6040).
pub mod cw {
    /// Switch on.
    pub const SWITCH_ON: u16 = 1 << 0;
    /// Enable voltage.
    pub const ENABLE_VOLTAGE: u16 = 1 << 1;
    /// Quick stop (active low).
    pub const QUICK_STOP: u16 = 1 << 2;
    /// Enable operation.
    pub const ENABLE_OPERATION: u16 = 1 << 3;
    /// PP: new set-point / HM: homing operation start (operation-mode specific bit 4).
    pub const NEW_SET_POINT: u16 = 1 << 4;
    /// PP: change set immediately (bit 5).
    pub const CHANGE_SET_IMMEDIATELY: u16 = 1 << 5;
    /// PP: relative target (bit 6).
    pub const RELATIVE: u16 = 1 << 6;
    /// Fault reset (rising edge).
    pub const FAULT_RESET: u16 = 1 << 7;
    /// Halt.
    pub const HALT: u16 = 1 << 8;
    /// PP: change on set-point (bit 9).
    pub const CHANGE_ON_SET_POINT: u16 = 1 << 9;
    /// Command "Shutdown".
    pub const SHUTDOWN: u16 = 0x0006;
    /// Command "Switch on".
    pub const SWITCH_ON_CMD: u16 = 0x0007;
    /// Command "Switch on + Enable operation" / "Enable operation".
    pub const ENABLE_OPERATION_CMD: u16 = 0x000F;
    /// Command "Disable voltage".
    pub const DISABLE_VOLTAGE: u16 = 0x0000;
    /// Command "Quick stop".
    pub const QUICK_STOP_CMD: u16 = 0x0002;
    /// Command "Disable operation" (same bits as Switch on).
    pub const DISABLE_OPERATION: u16 = 0x0007;
}

/// Statusword bits (0x6041).
pub mod sw {
    /// Ready to switch on.
    pub const READY_TO_SWITCH_ON: u16 = 1 << 0;
    /// Switched on.
    pub const SWITCHED_ON: u16 = 1 << 1;
    /// Operation enabled.
    pub const OPERATION_ENABLED: u16 = 1 << 2;
    /// Fault.
    pub const FAULT: u16 = 1 << 3;
    /// Voltage enabled.
    pub const VOLTAGE_ENABLED: u16 = 1 << 4;
    /// Quick stop (0 = quick stop active).
    pub const QUICK_STOP: u16 = 1 << 5;
    /// Switch on disabled.
    pub const SWITCH_ON_DISABLED: u16 = 1 << 6;
    /// Warning.
    pub const WARNING: u16 = 1 << 7;
    /// Remote (the controlword is processed).
    pub const REMOTE: u16 = 1 << 9;
    /// Target reached.
    pub const TARGET_REACHED: u16 = 1 << 10;
    /// Internal limit active.
    pub const INTERNAL_LIMIT: u16 = 1 << 11;
    /// Operation-mode specific bit 12 (PP set-point acknowledge, PV speed = 0, HM homing
    /// attained, CSx drive follows the command value).
    pub const OMS12: u16 = 1 << 12;
    /// Operation-mode specific bit 13 (PP/CSP following error, HM homing error).
    pub const OMS13: u16 = 1 << 13;
}

/// The eight states of the drive.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum State {
    /// Not ready to switch on (initialising; not visible to the master in practice).
    NotReadyToSwitchOn,
    /// Switch on disabled.
    SwitchOnDisabled,
    /// Ready to switch on.
    ReadyToSwitchOn,
    /// Switched on.
    SwitchedOn,
    /// Operation enabled.
    OperationEnabled,
    /// Quick stop active.
    QuickStopActive,
    /// Fault reaction active.
    FaultReactionActive,
    /// Fault.
    Fault,
}

impl State {
    /// The state bits of the statusword (bits 0–3, 5, 6; bit 4 "voltage enabled" is set
    /// from Ready to switch on on, as the bus is always up in this drive).
    pub const fn statusword_bits(self) -> u16 {
        match self {
            Self::NotReadyToSwitchOn => 0x0000,
            Self::SwitchOnDisabled => 0x0040,
            Self::ReadyToSwitchOn => 0x0031,
            Self::SwitchedOn => 0x0033,
            Self::OperationEnabled => 0x0037,
            Self::QuickStopActive => 0x0017,
            Self::FaultReactionActive => 0x001F,
            Self::Fault => 0x0018,
        }
    }

    /// Decodes a statusword by the standard masks (0x4F / 0x6F); `None` for bit
    /// patterns that are no state (such as the paper's 0x4663).
    pub const fn decode(sw: u16) -> Option<Self> {
        match sw & 0x004F {
            0x0000 => return Some(Self::NotReadyToSwitchOn),
            0x0040 => return Some(Self::SwitchOnDisabled),
            0x000F => return Some(Self::FaultReactionActive),
            0x0008 => return Some(Self::Fault),
            _ => {}
        }
        match sw & 0x006F {
            0x0021 => Some(Self::ReadyToSwitchOn),
            0x0023 => Some(Self::SwitchedOn),
            0x0027 => Some(Self::OperationEnabled),
            0x0007 => Some(Self::QuickStopActive),
            _ => None,
        }
    }

    /// Whether the power stage drives the motor in this state (a ramp may still be running
    /// in Quick stop active / Fault reaction active; see [`Fsm::stopping`]).
    pub const fn powered(self) -> bool {
        matches!(
            self,
            Self::OperationEnabled | Self::QuickStopActive | Self::FaultReactionActive
        )
    }
}

/// A device control command decoded from the controlword by its mask.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// Shutdown: `cw & 0x87 == 0x06`.
    Shutdown,
    /// Switch on (= Disable operation): `cw & 0x8F == 0x07`.
    SwitchOn,
    /// Enable operation (= Switch on + Enable operation): `cw & 0x8F == 0x0F`.
    EnableOperation,
    /// Disable voltage: `cw & 0x82 == 0x00`.
    DisableVoltage,
    /// Quick stop: `cw & 0x86 == 0x02`.
    QuickStop,
    /// Bit 7 set: fault reset (acts on its rising edge only).
    FaultReset,
}

impl Command {
    /// Decodes the device control bits of a controlword.
    pub const fn decode(cw: u16) -> Self {
        if cw & 0x0080 != 0 {
            Self::FaultReset
        } else if cw & 0x0082 == 0x0000 {
            Self::DisableVoltage
        } else if cw & 0x0086 == 0x0002 {
            Self::QuickStop
        } else if cw & 0x0087 == 0x0006 {
            Self::Shutdown
        } else if cw & 0x008F == 0x0007 {
            Self::SwitchOn
        } else {
            // cw & 0x8F == 0x0F: the only pattern left.
            Self::EnableOperation
        }
    }
}

/// How the drive brings the motor to a stop (the meaning of an option code).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ramp {
    /// Disable the drive function at once: the motor coasts.
    Coast,
    /// Slow down on the slow-down ramp (profile deceleration 0x6084).
    SlowDown,
    /// Slow down on the quick-stop ramp (quick stop deceleration 0x6085).
    QuickStop,
    /// Slow down at the current (torque) limit 0x6072.
    CurrentLimit,
    /// Slow down at the voltage limit: zero velocity demand with the full bus voltage
    /// (the current loop saturates; modelled as the velocity loop unclamped to the
    /// motor's peak torque, 3 × 0x6072).
    VoltageLimit,
}

/// A stop in progress.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stop {
    /// How.
    pub ramp: Ramp,
    /// The transition that completes the stop (5, 8, 12 or 14); `None`: stay (quick stop
    /// options 5–8, halt).
    pub then: Option<u8>,
}

/// The option codes 0x605A–0x605E.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Options {
    /// Quick stop option code 0x605A (0–8).
    pub quick_stop: i16,
    /// Shutdown option code 0x605B (0–1).
    pub shutdown: i16,
    /// Disable operation option code 0x605C (0–1).
    pub disable_operation: i16,
    /// Halt option code 0x605D (1–4).
    pub halt: i16,
    /// Fault reaction option code 0x605E (0–4).
    pub fault_reaction: i16,
}

impl Default for Options {
    /// The defaults of CiA 402-2: quick stop 2, shutdown 0, disable operation 1, halt 1,
    /// fault reaction 2.
    fn default() -> Self {
        Self {
            quick_stop: 2,
            shutdown: 0,
            disable_operation: 1,
            halt: 1,
            fault_reaction: 2,
        }
    }
}

impl Options {
    /// Ramp of a shutdown (0x605B) or disable operation (0x605C) code: 0 coast, 1 slow down.
    pub const fn disable_ramp(code: i16) -> Ramp {
        if code == 1 {
            Ramp::SlowDown
        } else {
            Ramp::Coast
        }
    }

    /// Ramp of a quick stop option code (0x605A): 0 coast; 1/5 slow down, 2/6 quick stop,
    /// 3/7 current limit, 4/8 voltage limit.
    pub const fn quick_stop_ramp(code: i16) -> Ramp {
        match code {
            1 | 5 => Ramp::SlowDown,
            2 | 6 => Ramp::QuickStop,
            3 | 7 => Ramp::CurrentLimit,
            4 | 8 => Ramp::VoltageLimit,
            _ => Ramp::Coast,
        }
    }

    /// Whether the quick stop option code keeps the drive in Quick stop active after the
    /// stop (5–8; transition 16 allowed).
    pub const fn quick_stop_stays(code: i16) -> bool {
        matches!(code, 5..=8)
    }

    /// Ramp of a halt option code (0x605D): 1 slow down, 2 quick stop, 3 current limit,
    /// 4 voltage limit.
    pub const fn halt_ramp(code: i16) -> Ramp {
        match code {
            2 => Ramp::QuickStop,
            3 => Ramp::CurrentLimit,
            4 => Ramp::VoltageLimit,
            _ => Ramp::SlowDown,
        }
    }

    /// Ramp of a fault reaction option code (0x605E): 0 coast, 1 slow down, 2 quick stop,
    /// 3 current limit, 4 voltage limit.
    pub const fn fault_ramp(code: i16) -> Ramp {
        match code {
            1 => Ramp::SlowDown,
            2 => Ramp::QuickStop,
            3 => Ramp::CurrentLimit,
            4 => Ramp::VoltageLimit,
            _ => Ramp::Coast,
        }
    }
}

/// What happened outside the controlword since the last step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Events {
    /// A fault is present (latched by the drive until a fault reset clears it).
    pub fault: bool,
    /// The stop ramp in progress has brought the motor to rest.
    pub stopped: bool,
}

/// The state machine.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Fsm {
    state: State,
    stop: Option<Stop>,
    last_cw: u16,
    started: bool,
}

impl Default for Fsm {
    fn default() -> Self {
        Self::new()
    }
}

impl Fsm {
    /// Power on: transition 0 into Not ready to switch on.
    pub const fn new() -> Self {
        Self {
            state: State::NotReadyToSwitchOn,
            stop: None,
            last_cw: 0,
            started: false,
        }
    }

    /// The current state.
    pub const fn state(&self) -> State {
        self.state
    }

    /// The stop ramp the drive must run now (`None`: normal operation or not powered).
    pub const fn stopping(&self) -> Option<Stop> {
        self.stop
    }

    fn go(&mut self, to: State, t: u8) -> Option<u8> {
        self.state = to;
        self.stop = None;
        Some(t)
    }

    fn begin_stop(&mut self, ramp: Ramp, then: Option<u8>, to: State, t: u8) -> Option<u8> {
        // A coast stop completes at once.
        if ramp == Ramp::Coast {
            if let Some(next) = then {
                self.state = to;
                self.stop = None;
                return self.finish(next).or(Some(t));
            }
        }
        self.stop = Some(Stop { ramp, then });
        if to != self.state {
            self.state = to;
            return Some(t);
        }
        None
    }

    fn finish(&mut self, t: u8) -> Option<u8> {
        let to = match t {
            5 => State::SwitchedOn,
            8 => State::ReadyToSwitchOn,
            12 => State::SwitchOnDisabled,
            14 => State::Fault,
            _ => return None,
        };
        self.go(to, t)
    }

    /// One step: returns the transition number taken, if any. Transition 0 happened in
    /// [`Fsm::new`]; transition 1 is taken by the first step (initialisation done).
    pub fn step(&mut self, cw: u16, ev: Events, opt: &Options) -> Option<u8> {
        let edge = cw & cw::FAULT_RESET != 0 && self.last_cw & cw::FAULT_RESET == 0;
        self.last_cw = cw;
        if !self.started {
            self.started = true;
            return self.go(State::SwitchOnDisabled, 1);
        }
        use State::*;
        // 13: a fault in any state but the fault states.
        if ev.fault && !matches!(self.state, FaultReactionActive | Fault) {
            let ramp = if self.state.powered() {
                Options::fault_ramp(opt.fault_reaction)
            } else {
                Ramp::Coast
            };
            self.state = FaultReactionActive;
            self.stop = Some(Stop {
                ramp,
                then: Some(14),
            });
            return Some(13);
        }
        // A stop that has come to rest completes its transition.
        if let Some(s) = self.stop {
            if ev.stopped || s.ramp == Ramp::Coast {
                if let Some(t) = s.then {
                    return self.finish(t);
                }
            }
        }
        let cmd = Command::decode(cw);
        match (self.state, cmd) {
            (NotReadyToSwitchOn, _) => None,
            (SwitchOnDisabled, Command::Shutdown) => self.go(ReadyToSwitchOn, 2),
            (ReadyToSwitchOn, Command::SwitchOn | Command::EnableOperation) => {
                self.go(SwitchedOn, 3)
            }
            (ReadyToSwitchOn, Command::DisableVoltage | Command::QuickStop) => {
                self.go(SwitchOnDisabled, 7)
            }
            (SwitchedOn, Command::EnableOperation) => self.go(OperationEnabled, 4),
            (SwitchedOn, Command::Shutdown) => self.go(ReadyToSwitchOn, 6),
            (SwitchedOn, Command::DisableVoltage | Command::QuickStop) => {
                self.go(SwitchOnDisabled, 10)
            }
            (OperationEnabled, Command::EnableOperation) => {
                // A new enable cancels a pending disable operation / shutdown ramp.
                self.stop = None;
                None
            }
            (OperationEnabled, Command::SwitchOn) => {
                if matches!(self.stop, Some(Stop { then: Some(5), .. })) {
                    return None;
                }
                let ramp = Options::disable_ramp(opt.disable_operation);
                self.begin_stop(ramp, Some(5), OperationEnabled, 5)
            }
            (OperationEnabled, Command::Shutdown) => {
                if matches!(self.stop, Some(Stop { then: Some(8), .. })) {
                    return None;
                }
                let ramp = Options::disable_ramp(opt.shutdown);
                self.begin_stop(ramp, Some(8), OperationEnabled, 8)
            }
            (OperationEnabled, Command::DisableVoltage) => self.go(SwitchOnDisabled, 9),
            (OperationEnabled, Command::QuickStop) => {
                let code = opt.quick_stop;
                let ramp = Options::quick_stop_ramp(code);
                if ramp == Ramp::Coast {
                    // Option 0: disable the drive function, straight through to SOD.
                    self.state = QuickStopActive;
                    self.stop = Some(Stop {
                        ramp,
                        then: Some(12),
                    });
                    return Some(11);
                }
                let then = if Options::quick_stop_stays(code) {
                    None
                } else {
                    Some(12)
                };
                self.begin_stop(ramp, then, QuickStopActive, 11)
            }
            (QuickStopActive, Command::DisableVoltage) => self.go(SwitchOnDisabled, 12),
            (QuickStopActive, Command::EnableOperation)
                if Options::quick_stop_stays(opt.quick_stop) =>
            {
                self.go(OperationEnabled, 16)
            }
            (Fault, Command::FaultReset) if edge && !ev.fault => self.go(SwitchOnDisabled, 15),
            _ => None,
        }
    }

    /// The state bits of the statusword.
    pub const fn statusword_bits(&self) -> u16 {
        self.state.statusword_bits()
    }
}
