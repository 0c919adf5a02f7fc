//! The firmware of a twin served by the stack: its process data does what its
//! [`Behaviour`] says, on the segment's virtual clock.
//!
//! | event | what runs |
//! |---|---|
//! | PREOP → SAFEOP (the PDO layout is fixed from here until PREOP) | the active mapping is read from 0x1C12/0x1C13 and 0x16xx/0x1Axx and every input entry the behaviour writes is resolved to its place in the dictionary once ([`oxicat_slave::EntryRef`]): loop-back pairs, signals, held values |
//! | tick every 50 µs (timer [`CURRENT_LOOP_TIMER`]) | [`TwinBench`] takes the virtual time; a drive twin steps its motor plant 50 µs, then runs the drive's 20 kHz current loop |
//! | ESC event (SYNC0, PDI IRQ) | [`TwinBench`] takes the event's virtual time |
//! | application cycle (free run: the main loop after the tick; SM-synchronous: PDI IRQ; DC: SYNC0) | a drive twin runs oxicat's CiA402 drive ([`Cia402Drive`], on the objects it locates in the twin's dictionary); then every resolved place: copy, signal value at the virtual time, held value |
//!
//! The drive's plant is [`crate::cia402::rig`]'s joint with its default parameters
//! (BLDC motor, 16384 counts per motor turn, harmonic gear).

use oxicat_sim::firmware::{Bench, FirmwareConfig, Stack};
use oxicat_sim::node::EscEvent;
use oxicat_slave::{
    AlState, AlStatusCode, Application, DataType, DeviceDef, EntryRef, Od, Pdi, PdoEntry,
};

use super::behaviour::{range, Behaviour, Mode, Rule, Signal};
use crate::cia402::rig::{new_app, BldcJointParams, JointApp, TICK_NS};
use crate::cia402::{Cia402Drive, CURRENT_LOOP_TIMER};

/// What a place does each cycle.
#[derive(Debug, Clone)]
enum Action {
    /// Copies the output entry's bits.
    Copy(EntryRef),
    /// Writes the signal's value at the virtual time.
    Signal(Signal),
}

/// One input entry the behaviour writes, resolved.
#[derive(Debug, Clone)]
struct Place {
    index: u16,
    sub: u8,
    to: EntryRef,
    dtype: DataType,
    action: Action,
}

/// The twin's application.
pub struct TwinApp {
    def: &'static DeviceDef,
    behaviour: &'static Behaviour,
    /// The CiA402 drive on its plant, for a drive twin.
    pub drive: Option<Box<JointApp>>,
    /// Virtual time of the event being handled \[ns\].
    pub now_ns: u64,
    /// Virtual time of the previous application cycle \[ns\].
    last_cycle_ns: Option<u64>,
    places: Vec<Place>,
}

impl TwinApp {
    /// The application of a twin of `def` with `behaviour`; `drive` runs the CiA402 drive.
    pub fn new(def: &'static DeviceDef, behaviour: &'static Behaviour, drive: bool) -> Self {
        Self {
            def,
            behaviour,
            drive: drive.then(|| Box::new(new_app(BldcJointParams::default()))),
            now_ns: 0,
            last_cycle_ns: None,
            places: Vec::new(),
        }
    }

    /// Input entries written each cycle, `(index, sub)`, in the order they are written.
    pub fn places(&self) -> Vec<(u16, u8)> {
        self.places.iter().map(|p| (p.index, p.sub)).collect()
    }

    /// Resolves the places for the active mapping of `od`.
    fn resolve<const N: usize>(&mut self, od: &Od<N>) {
        self.places.clear();
        let def = self.def;
        let place = |(index, sub): (u16, u8), action: Action| -> Option<Place> {
            let e = def.entry_def(index, sub)?;
            (e.bits <= 64 && !e.dtype.is_string()).then_some(())?;
            Some(Place {
                index,
                sub,
                to: od.entry(index, sub).ok()?,
                dtype: e.dtype,
                action,
            })
        };
        let outs = active(od, 0x1C12);
        let ins = active(od, 0x1C13);
        let looped = matches!(self.behaviour.mode, Mode::Auto | Mode::Loop) && self.drive.is_none();
        if looped {
            for (o, i) in oxicat_esi::twin::loop_pairs(def, &outs, &ins) {
                if let Ok(from) = od.entry(o.index, o.sub) {
                    self.places
                        .extend(place((i.index, i.sub), Action::Copy(from)));
                }
            }
        }
        if self.behaviour.mode == Mode::Auto && self.drive.is_none() {
            for i in ins.iter().filter(|i| i.index != 0 && i.bits >= 16) {
                if self
                    .places
                    .iter()
                    .any(|p| (p.index, p.sub) == (i.index, i.sub))
                {
                    continue;
                }
                let Some(e) = def.entry_def(i.index, i.sub) else {
                    continue;
                };
                if e.dtype.is_integer() || matches!(e.dtype, DataType::Real32 | DataType::Real64) {
                    let s = Signal::default_for(e.dtype, e.bits);
                    self.places
                        .extend(place((i.index, i.sub), Action::Signal(s)));
                }
            }
        }
        for (at, rule) in &self.behaviour.entries {
            self.places.retain(|p| (p.index, p.sub) != *at);
            let action = match rule {
                Rule::Loop(i, s) => match od.entry(*i, *s) {
                    Ok(from) => Action::Copy(from),
                    Err(_) => continue,
                },
                Rule::Hold(v) => Action::Signal(Signal::Constant(*v)),
                Rule::Signal(s) => Action::Signal(s.clone()),
            };
            self.places.extend(place(*at, action));
        }
    }
}

/// The entries the assignment object `assign` (0x1C12 / 0x1C13) maps now, gaps included.
fn active<const N: usize>(od: &Od<N>, assign: u16) -> Vec<PdoEntry> {
    let mut v = Vec::new();
    for k in 1..=od.get::<u8>(assign, 0).unwrap_or(0) {
        let Ok(pdo) = od.get::<u16>(assign, k) else {
            continue;
        };
        for j in 1..=od.get::<u8>(pdo, 0).unwrap_or(0) {
            if let Ok(x) = od.get::<u32>(pdo, j) {
                v.push(PdoEntry::decode(x));
            }
        }
    }
    v
}

/// The raw bits of `v` in an entry of type `dtype` and `bits`: REAL as IEEE bits, integers
/// rounded and saturated to the type's range.
pub(super) fn encode(v: f64, dtype: DataType, bits: u16) -> u64 {
    match dtype {
        DataType::Real32 => (v as f32).to_bits() as u64,
        DataType::Real64 => v.to_bits(),
        _ => {
            let (lo, hi) = range(dtype, bits);
            let r = v.round().clamp(lo, hi);
            let raw = if dtype.is_signed() {
                r as i64 as u64
            } else {
                r as u64
            };
            raw & mask(bits)
        }
    }
}

fn mask(bits: u16) -> u64 {
    if bits >= 64 {
        u64::MAX
    } else {
        (1u64 << bits) - 1
    }
}

impl<const N: usize> Application<N> for TwinApp {
    fn state_change(
        &mut self,
        from: AlState,
        to: AlState,
        od: &mut Od<N>,
    ) -> Result<(), AlStatusCode> {
        if let Some(d) = &mut self.drive {
            d.state_change(from, to, od)?;
        }
        if to == AlState::SafeOp && from < AlState::SafeOp {
            self.resolve(od);
            self.last_cycle_ns = None;
        }
        Ok(())
    }

    fn safe_outputs(&mut self, od: &mut Od<N>) {
        if let Some(d) = &mut self.drive {
            Application::<N>::safe_outputs(d.as_mut(), od);
        }
    }

    fn cycle(&mut self, od: &mut Od<N>) {
        if let Some(d) = &mut self.drive {
            // The drive's period is the virtual time between cycles (free run: every main
            // loop; DC: every SYNC0), from the second cycle on.
            let dt = self
                .last_cycle_ns
                .filter(|&l| self.now_ns > l)
                .map(|l| ((self.now_ns - l) as f64 * 1e-9) as f32);
            if dt.is_some() {
                d.set_cycle_time(dt);
            }
            d.run_cycle(od);
        }
        self.last_cycle_ns = Some(self.now_ns);
        let t = self.now_ns as f64 * 1e-9;
        for p in &self.places {
            let bits = p.to.bits();
            let raw = match &p.action {
                Action::Copy(from) => od.read::<u64>(*from) & mask(bits),
                Action::Signal(s) => encode(s.value(t), p.dtype, bits),
            };
            od.write::<u64>(p.to, raw);
        }
    }

    fn timer(&mut self, id: u8, _od: &mut Od<N>) {
        if id == CURRENT_LOOP_TIMER {
            if let Some(d) = &mut self.drive {
                d.run_current_loop();
            }
        }
    }

    fn next_emergency(&mut self) -> Option<(u16, u8, [u8; 5])> {
        self.drive
            .as_mut()
            .and_then(|d| Cia402Drive::take_emergency(d))
            .map(|(code, reg)| (code, reg, [0; 5]))
    }
}

/// The twin's bench: the virtual clock for its signals and, for a drive twin, the motor
/// plant (stepped 50 µs at each tick before the current loop reads it, as
/// [`crate::cia402::rig::JointPlant`]).
#[derive(Debug, Clone, Copy, Default)]
pub struct TwinBench;

impl<Pd: Pdi, const N: usize, const M: usize> Bench<Stack<Pd, TwinApp, N, M>> for TwinBench {
    fn before_timers(&mut self, image: &mut Stack<Pd, TwinApp, N, M>, t: u64) {
        image.app.now_ns = t;
        if let Some(d) = &mut image.app.drive {
            d.hw.joint.step(TICK_NS as f64 * 1e-9);
        }
    }

    fn before_event(&mut self, image: &mut Stack<Pd, TwinApp, N, M>, _ev: EscEvent, t: u64) {
        image.app.now_ns = t;
    }
}

/// The twin's schedule: the tick (the drive's current loop, or the clock alone) and the
/// main loop every 50 µs on the 50 µs grid, the tick first.
pub fn schedule() -> FirmwareConfig {
    FirmwareConfig::default()
        .aligned(TICK_NS)
        .timer_from(CURRENT_LOOP_TIMER, TICK_NS, 0)
        .poll_every(TICK_NS)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cia402::device::{DEF, IMAGE, OBJECTS};
    use crate::cia402::State;

    /// A dictionary with only 0x6040, 0x6041, 0x607A and 0x6064 of the joint's objects (a
    /// foreign layout: not the drive's own, no 0x6060): the drive locates them, runs CSP,
    /// the mode fixed by the set-point it has.
    #[test]
    fn the_drive_runs_csp_on_a_dictionary_with_four_of_its_objects() {
        let objects: Vec<_> = OBJECTS
            .iter()
            .filter(|o| matches!(o.index, 0x6040 | 0x6041 | 0x607A | 0x6064))
            .copied()
            .collect();
        let def: &'static DeviceDef = Box::leak(Box::new(DeviceDef {
            objects: Box::leak(objects.into_boxed_slice()),
            rx_pdos: &[],
            tx_pdos: &[],
            rx_assign: &[],
            tx_assign: &[],
            ..DEF
        }));
        let mut od = Od::<IMAGE>::new(def).unwrap();
        assert!(!od.built_on(OBJECTS));
        let mut app = new_app(BldcJointParams::default());
        let cycle = |app: &mut JointApp, od: &mut Od<IMAGE>| {
            for _ in 0..20 {
                app.hw.joint.step(TICK_NS as f64 * 1e-9);
                app.run_current_loop();
            }
            app.run_cycle(od);
            State::decode(od.get::<u16>(0x6041, 0).unwrap())
        };
        assert_eq!(cycle(&mut app, &mut od), Some(State::SwitchOnDisabled));
        for (cw, want) in [
            (0x06u16, State::ReadyToSwitchOn),
            (0x07, State::SwitchedOn),
            (0x0F, State::OperationEnabled),
        ] {
            od.set(0x6040, 0, cw).unwrap();
            assert_eq!(cycle(&mut app, &mut od), Some(want), "after {cw:#04x}");
        }
        let start = od.get::<i32>(0x6064, 0).unwrap();
        for k in 1..=500 {
            od.set(0x607A, 0, start + 20 * k).unwrap();
            cycle(&mut app, &mut od);
        }
        for _ in 0..100 {
            cycle(&mut app, &mut od);
        }
        let end = od.get::<i32>(0x6064, 0).unwrap();
        assert!((end - (start + 10_000)).abs() < 50, "{start} → {end}");
    }

    #[test]
    fn values_are_rounded_and_saturated_to_the_entry_type() {
        assert_eq!(encode(1.6, DataType::Int16, 16), 2);
        assert_eq!(encode(-1.0, DataType::Int16, 16), 0xFFFF);
        assert_eq!(encode(1e9, DataType::Int16, 16), 0x7FFF);
        assert_eq!(encode(-1e9, DataType::Int16, 16), 0x8000);
        assert_eq!(encode(-5.0, DataType::Unsigned8, 8), 0);
        assert_eq!(encode(300.0, DataType::Unsigned8, 8), 255);
        assert_eq!(encode(9.0, DataType::Unsigned8, 3), 7);
        assert_eq!(encode(0.7, DataType::Bool, 1), 1);
        assert_eq!(encode(1.5, DataType::Real32, 32), 1.5f32.to_bits() as u64);
        assert_eq!(encode(-3.0, DataType::Int32, 24), 0xFF_FFFD);
    }
}
