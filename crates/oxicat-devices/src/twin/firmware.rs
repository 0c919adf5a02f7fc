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

use oxicat_plant::re30::{Re30Drive, Re30Params};

use super::behaviour::{range, Behaviour, Encoder, Mode, Rule, Signal, Volts};
use crate::cia402::rig::{new_app, BldcJointParams, JointApp, TICK_NS};
use crate::cia402::{Cia402Drive, CURRENT_LOOP_TIMER};

/// What a place does each cycle.
#[derive(Debug, Clone)]
enum Action {
    /// Copies the output entry's bits.
    Copy(EntryRef),
    /// Writes the signal's value at the virtual time.
    Signal(Signal),
    /// Writes the count of encoder plant `k` of [`TwinApp::plants`].
    Encoder(usize),
}

/// An encoder on a motor plant ([`Encoder`]): the motor, and the voltage in force.
#[derive(Debug, Clone)]
pub struct Plant {
    /// The input entry its count goes to.
    pub at: (u16, u8),
    /// What drives it.
    pub encoder: Encoder,
    /// The motor and its encoder.
    pub motor: Re30Drive,
    /// Terminal voltage commanded at the last cycle \[V\].
    pub volts: f64,
    /// The output entry the voltage comes from, resolved.
    from: Option<(EntryRef, DataType)>,
}

impl Plant {
    fn new(at: (u16, u8), encoder: Encoder) -> Self {
        let volts = match encoder.volts {
            Volts::Constant(v) => v,
            Volts::From(..) => 0.0,
        };
        Self {
            at,
            encoder,
            motor: Re30Drive::new(Re30Params::maxon_310007()),
            volts,
            from: None,
        }
    }

    /// Advances the motor `h` seconds on the voltage in force (the bridge's duty pair
    /// gives it, saturated at the supply).
    pub fn step(&mut self, h: f64) {
        let supply = self.encoder.supply;
        let d = (self.volts / supply).clamp(-1.0, 1.0) / 2.0;
        self.motor.bridge.duty_a = 0.5 + d;
        self.motor.bridge.duty_b = 0.5 - d;
        self.motor.step(h, supply);
    }
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
    /// Encoder plants, kept across PDO layouts (a counter keeps counting).
    pub plants: Vec<Plant>,
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
            plants: Vec::new(),
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
        // The plant of input `at` (kept when it exists: a counter keeps counting).
        let mut plant = |at: (u16, u8), enc: Encoder| -> usize {
            match self
                .plants
                .iter()
                .position(|p| p.at == at && p.encoder == enc)
            {
                Some(k) => k,
                None => {
                    self.plants.push(Plant::new(at, enc));
                    self.plants.len() - 1
                }
            }
        };
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
                let object = def.object(i.index).map_or("", |o| o.name);
                if Encoder::by_name(object, e.dtype, e.bits)
                    || Encoder::by_name(e.name, e.dtype, e.bits)
                {
                    let k = plant((i.index, i.sub), Encoder::DEFAULT);
                    self.places
                        .extend(place((i.index, i.sub), Action::Encoder(k)));
                } else if e.dtype.is_integer()
                    || matches!(e.dtype, DataType::Real32 | DataType::Real64)
                {
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
                Rule::Encoder(enc) => Action::Encoder(plant(*at, *enc)),
            };
            self.places.extend(place(*at, action));
        }
        for p in &mut self.plants {
            p.from = match p.encoder.volts {
                Volts::From(i, s, _) => od
                    .entry(i, s)
                    .ok()
                    .zip(def.entry_def(i, s).map(|e| e.dtype)),
                Volts::Constant(_) => None,
            };
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

/// The number in `raw`, an entry of type `dtype` and `bits` (sign-extended where signed).
fn decode(raw: u64, dtype: DataType, bits: u16) -> f64 {
    match dtype {
        DataType::Real32 => f32::from_bits(raw as u32) as f64,
        DataType::Real64 => f64::from_bits(raw),
        _ if dtype.is_signed() && (1..64).contains(&bits) => {
            let sh = 64 - bits as u32;
            ((raw << sh) as i64 >> sh) as f64
        }
        _ => (raw & mask(bits)) as f64,
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
        // The voltage the master commands now (held until the next cycle).
        for p in &mut self.plants {
            if let (Some((from, dtype)), Volts::From(_, _, per)) = (p.from, p.encoder.volts) {
                p.volts = decode(od.read::<u64>(from), dtype, from.bits()) * per;
            }
        }
        for p in &self.places {
            let bits = p.to.bits();
            let raw = match &p.action {
                Action::Copy(from) => od.read::<u64>(*from) & mask(bits),
                Action::Signal(s) => encode(s.value(t), p.dtype, bits),
                Action::Encoder(k) => self.plants[*k].motor.count() as i32 as u64 & mask(bits),
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
        for p in &mut image.app.plants {
            p.step(TICK_NS as f64 * 1e-9);
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
