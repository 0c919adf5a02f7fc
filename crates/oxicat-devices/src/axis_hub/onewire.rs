//! 1-Wire master for DS18B20 sensors over a bit-level [`OneWireBus`]: reset/presence, ROM
//! search (Maxim AN187), MATCH ROM, CONVERT T, READ SCRATCHPAD with its CRC-8, the
//! resolution from the configuration register and the conversion time per resolution; and
//! the temperature task built on it.
//!
//! The bus driver (on the report's board: USART3 at 9600/115200 bit/s, one UART byte per
//! slot) returns an error instead of waiting forever; every call here is bounded.

use super::codes::{self, SystemState};
use super::device::{SENSORS, TEMP_INVALID};

/// A 64-bit ROM code: family, 48-bit serial, CRC-8 (LSB first on the wire).
pub type Rom = [u8; 8];

/// Family code of the DS18B20.
pub const FAMILY_DS18B20: u8 = 0x28;
/// ROM command SEARCH ROM.
pub const CMD_SEARCH_ROM: u8 = 0xF0;
/// ROM command READ ROM (one device only).
pub const CMD_READ_ROM: u8 = 0x33;
/// ROM command MATCH ROM.
pub const CMD_MATCH_ROM: u8 = 0x55;
/// ROM command SKIP ROM.
pub const CMD_SKIP_ROM: u8 = 0xCC;
/// Function command CONVERT T.
pub const CMD_CONVERT_T: u8 = 0x44;
/// Function command WRITE SCRATCHPAD (TH, TL, configuration).
pub const CMD_WRITE_SCRATCHPAD: u8 = 0x4E;
/// Function command READ SCRATCHPAD (9 bytes).
pub const CMD_READ_SCRATCHPAD: u8 = 0xBE;

/// Bit-level access to a 1-Wire bus (a UART-based or GPIO master).
pub trait OneWireBus {
    /// Why a slot failed (e.g. the UART did not echo in time).
    type Error: core::fmt::Debug;

    /// Reset pulse; true when at least one device answered with a presence pulse.
    fn reset(&mut self) -> Result<bool, Self::Error>;

    /// A write slot.
    fn write_bit(&mut self, bit: bool) -> Result<(), Self::Error>;

    /// A read slot (the wired-AND of what every device drives; 1 if none drives).
    fn read_bit(&mut self) -> Result<bool, Self::Error>;

    /// Eight write slots, LSB first.
    fn write_byte(&mut self, b: u8) -> Result<(), Self::Error> {
        for i in 0..8 {
            self.write_bit(b >> i & 1 != 0)?;
        }
        Ok(())
    }

    /// Eight read slots, LSB first.
    fn read_byte(&mut self) -> Result<u8, Self::Error> {
        let mut b = 0u8;
        for i in 0..8 {
            if self.read_bit()? {
                b |= 1 << i;
            }
        }
        Ok(b)
    }

    /// Starts the transaction `t`; `Ok(true)` when it has finished already. The default
    /// runs it to its end now, slot by slot, with the methods above (a blocking bus); an
    /// interrupt-driven bus takes it over, runs its slots in the background and gives it
    /// back through [`OneWireBus::collect`].
    fn begin(&mut self, t: &mut Txn) -> Result<bool, Self::Error> {
        while let Some(slot) = t.next_slot() {
            let r = match slot {
                Slot::Reset => self.reset()?,
                Slot::Write(b) => {
                    self.write_bit(b)?;
                    b
                }
                Slot::Read => self.read_bit()?,
            };
            t.feed(r);
        }
        Ok(true)
    }

    /// The transaction [`OneWireBus::begin`] started, when it has finished: copied into `t`
    /// and `Ok(true)`; `Ok(false)` while it runs (the default: never, it ran in `begin`).
    fn collect(&mut self, _t: &mut Txn) -> Result<bool, Self::Error> {
        Ok(true)
    }
}

/// One 1-Wire time slot of a [`Txn`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Slot {
    /// Reset pulse and presence detect.
    Reset,
    /// Write slot.
    Write(bool),
    /// Read slot.
    Read,
}

/// What a [`Txn`] does after its reset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TxnKind {
    /// SKIP ROM, CONVERT T.
    Convert,
    /// MATCH ROM, READ SCRATCHPAD (9 bytes).
    ReadScratchpad,
    /// SEARCH ROM: the next ROM after `rom` / `last_discrepancy` (Maxim AN187).
    Search,
}

/// How a [`Txn`] ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TxnStatus {
    /// Slots left to run.
    Running,
    /// All slots ran.
    Done,
    /// No presence pulse after the reset (nothing more was sent).
    NoPresence,
    /// A search bit that nobody answered (a device left during the search).
    SearchLost,
    /// The bus driver failed (no echo, timeout).
    BusFault,
}

/// One 1-Wire transaction as a state machine of slots, so that a bus can run it slot by
/// slot from its interrupt (each slot's result fed back with [`Txn::feed`]) as well as in
/// one go: a reset, the command bytes, then the scratchpad's read slots or the search's
/// 64 bit triplets. The slot sequences are those of [`convert_all`], [`read_scratchpad`]
/// and [`Search::next`].
#[derive(Debug, Clone, Copy)]
pub struct Txn {
    /// What it does.
    pub kind: TxnKind,
    /// How it ended (or that it runs).
    pub status: TxnStatus,
    tx: [u8; 10],
    tx_len: u8,
    pos: u16,
    /// The scratchpad read (ReadScratchpad).
    pub rx: [u8; 9],
    /// The ROM being found (Search: the previous one on entry, the new one at the end).
    pub rom: Rom,
    /// AN187's last discrepancy (Search: the previous search's on entry, this one's at
    /// the end).
    pub last_discrepancy: u8,
    last_zero: u8,
    id_bit: bool,
    dir: bool,
}

impl Txn {
    fn new(kind: TxnKind, tx: &[u8]) -> Self {
        let mut buf = [0u8; 10];
        buf[..tx.len()].copy_from_slice(tx);
        Self {
            kind,
            status: TxnStatus::Running,
            tx: buf,
            tx_len: tx.len() as u8,
            pos: 0,
            rx: [0; 9],
            rom: [0; 8],
            last_discrepancy: 0,
            last_zero: 0,
            id_bit: false,
            dir: false,
        }
    }

    /// CONVERT T on every device (SKIP ROM).
    pub fn convert() -> Self {
        Self::new(TxnKind::Convert, &[CMD_SKIP_ROM, CMD_CONVERT_T])
    }

    /// READ SCRATCHPAD of `rom` (MATCH ROM).
    pub fn read_scratchpad(rom: &Rom) -> Self {
        let mut tx = [0u8; 10];
        tx[0] = CMD_MATCH_ROM;
        tx[1..9].copy_from_slice(rom);
        tx[9] = CMD_READ_SCRATCHPAD;
        Self::new(TxnKind::ReadScratchpad, &tx)
    }

    /// SEARCH ROM after the ROM `rom` with the last discrepancy `last_discrepancy` (both 0
    /// for the first).
    pub fn search(rom: Rom, last_discrepancy: u8) -> Self {
        let mut t = Self::new(TxnKind::Search, &[CMD_SEARCH_ROM]);
        t.rom = rom;
        t.last_discrepancy = last_discrepancy;
        t
    }

    /// A transaction that ended as `status` without running (e.g. the bus failed).
    pub fn ended(mut self, status: TxnStatus) -> Self {
        self.status = status;
        self
    }

    fn tx_slots(&self) -> u16 {
        8 * u16::from(self.tx_len)
    }

    /// The next slot to run, `None` when the transaction has ended.
    pub fn next_slot(&self) -> Option<Slot> {
        if self.status != TxnStatus::Running {
            return None;
        }
        let p = self.pos;
        if p == 0 {
            return Some(Slot::Reset);
        }
        let k = p - 1;
        if k < self.tx_slots() {
            let b = self.tx[usize::from(k / 8)];
            return Some(Slot::Write(b >> (k % 8) & 1 != 0));
        }
        let k = k - self.tx_slots();
        match self.kind {
            TxnKind::Convert => None,
            TxnKind::ReadScratchpad => (k < 72).then_some(Slot::Read),
            TxnKind::Search => match (k < 64 * 3, k % 3) {
                (false, _) => None,
                (true, 2) => Some(Slot::Write(self.dir)),
                (true, _) => Some(Slot::Read),
            },
        }
    }

    /// The result of the slot [`Txn::next_slot`] gave: the presence for a reset, the bit
    /// for a read slot (ignored for a write slot).
    pub fn feed(&mut self, r: bool) {
        let Some(slot) = self.next_slot() else {
            return;
        };
        let p = self.pos;
        self.pos += 1;
        if slot == Slot::Reset {
            if !r {
                self.status = TxnStatus::NoPresence;
            }
            return;
        }
        let k = p - 1;
        if k >= self.tx_slots() {
            let k = k - self.tx_slots();
            match self.kind {
                TxnKind::Convert => {}
                TxnKind::ReadScratchpad => {
                    if r {
                        self.rx[usize::from(k / 8)] |= 1 << (k % 8);
                    }
                }
                TxnKind::Search => self.search_slot(k, r),
            }
        }
        if self.next_slot().is_none() && self.status == TxnStatus::Running {
            self.status = TxnStatus::Done;
            if self.kind == TxnKind::Search {
                self.last_discrepancy = self.last_zero;
            }
        }
    }

    /// Slot `k` of the search's triplets (read id, read complement, write direction).
    fn search_slot(&mut self, k: u16, r: bool) {
        let n = (k / 3 + 1) as u8;
        let (byte, mask) = (usize::from((n - 1) / 8), 1u8 << ((n - 1) % 8));
        match k % 3 {
            0 => self.id_bit = r,
            1 => {
                let dir = match (self.id_bit, r) {
                    (true, true) => {
                        self.status = TxnStatus::SearchLost;
                        return;
                    }
                    (a, b) if a != b => a,
                    _ => {
                        let d = branch(&self.rom, byte, mask, n, self.last_discrepancy);
                        if !d {
                            self.last_zero = n;
                        }
                        d
                    }
                };
                if dir {
                    self.rom[byte] |= mask;
                } else {
                    self.rom[byte] &= !mask;
                }
                self.dir = dir;
            }
            _ => {}
        }
    }
}

pub use oxicat_wire::crc::onewire_crc8 as crc8;

/// Why a 1-Wire transaction failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OwError<E> {
    /// The bus driver failed (timeout).
    Bus(E),
    /// Nobody answered (no presence pulse, or all ones read).
    NoPresence,
    /// The CRC-8 did not match.
    Crc,
}

impl<E> From<E> for OwError<E> {
    fn from(e: E) -> Self {
        Self::Bus(e)
    }
}

/// DS18B20 resolution (configuration register bits 6..5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Resolution {
    /// 9 bits, 0.5 °C.
    Bits9,
    /// 10 bits, 0.25 °C.
    Bits10,
    /// 11 bits, 0.125 °C.
    Bits11,
    /// 12 bits, 0.0625 °C (power-on default).
    Bits12,
}

impl Resolution {
    /// From the configuration register.
    pub const fn from_config(c: u8) -> Self {
        match (c >> 5) & 3 {
            0 => Self::Bits9,
            1 => Self::Bits10,
            2 => Self::Bits11,
            _ => Self::Bits12,
        }
    }

    /// The configuration register value (reserved bits set as the datasheet reads them).
    pub const fn config(self) -> u8 {
        0x1F | (self as u8) << 5
    }

    /// Maximum conversion time in µs (datasheet: 93.75, 187.5, 375, 750 ms).
    pub const fn conversion_us(self) -> u32 {
        93_750 << (self as u32)
    }

    /// Mask of the defined bits of the raw temperature (undefined low bits cleared).
    pub const fn raw_mask(self) -> i16 {
        !((1i16 << (3 - self as i16)) - 1)
    }
}

/// AN187's choice at a discrepancy (both bit values present) at bit `n` of the search:
/// below the last discrepancy the previous ROM's bit (`rom[byte] & mask`), at it 1, above
/// it 0. The blocking [`Search`] and the background [`Txn`] take the same path.
fn branch(rom: &Rom, byte: usize, mask: u8, n: u8, last_discrepancy: u8) -> bool {
    if n < last_discrepancy {
        rom[byte] & mask != 0
    } else {
        n == last_discrepancy
    }
}

/// ROM search state (Maxim AN187).
#[derive(Debug, Clone, Copy, Default)]
pub struct Search {
    rom: Rom,
    last_discrepancy: u8,
    done: bool,
}

impl Search {
    /// The next ROM on the bus; `Ok(None)` when all were found (or nobody is there).
    pub fn next<B: OneWireBus>(&mut self, bus: &mut B) -> Result<Option<Rom>, OwError<B::Error>> {
        if self.done {
            return Ok(None);
        }
        if !bus.reset()? {
            self.done = true;
            return Ok(None);
        }
        bus.write_byte(CMD_SEARCH_ROM)?;
        let mut last_zero = 0u8;
        for n in 1..=64u8 {
            let id = bus.read_bit()?;
            let cmp = bus.read_bit()?;
            let (byte, mask) = (((n - 1) / 8) as usize, 1u8 << ((n - 1) % 8));
            let dir = match (id, cmp) {
                (true, true) => {
                    // Nobody took part (a device left during the search).
                    self.done = true;
                    return Err(OwError::NoPresence);
                }
                (a, b) if a != b => a,
                _ => {
                    let d = branch(&self.rom, byte, mask, n, self.last_discrepancy);
                    if !d {
                        last_zero = n;
                    }
                    d
                }
            };
            if dir {
                self.rom[byte] |= mask;
            } else {
                self.rom[byte] &= !mask;
            }
            bus.write_bit(dir)?;
        }
        self.last_discrepancy = last_zero;
        if last_zero == 0 {
            self.done = true;
        }
        if crc8(&self.rom) != 0 {
            return Err(OwError::Crc);
        }
        Ok(Some(self.rom))
    }
}

/// Finds up to `out.len()` ROMs; returns how many (a ROM with a bad CRC ends the search).
pub fn search_all<B: OneWireBus>(bus: &mut B, out: &mut [Rom]) -> Result<usize, OwError<B::Error>> {
    let mut s = Search::default();
    let mut n = 0;
    while n < out.len() {
        match s.next(bus)? {
            Some(rom) => {
                out[n] = rom;
                n += 1;
            }
            None => break,
        }
    }
    Ok(n)
}

/// CONVERT T on every device (SKIP ROM); false if nobody is present.
pub fn convert_all<B: OneWireBus>(bus: &mut B) -> Result<bool, B::Error> {
    if !bus.reset()? {
        return Ok(false);
    }
    bus.write_byte(CMD_SKIP_ROM)?;
    bus.write_byte(CMD_CONVERT_T)?;
    Ok(true)
}

/// MATCH ROM `rom`, then a function command.
pub fn select<B: OneWireBus>(bus: &mut B, rom: &Rom, cmd: u8) -> Result<(), OwError<B::Error>> {
    if !bus.reset()? {
        return Err(OwError::NoPresence);
    }
    bus.write_byte(CMD_MATCH_ROM)?;
    for &b in rom {
        bus.write_byte(b)?;
    }
    bus.write_byte(cmd)?;
    Ok(())
}

/// READ SCRATCHPAD of `rom`, CRC-checked.
pub fn read_scratchpad<B: OneWireBus>(
    bus: &mut B,
    rom: &Rom,
) -> Result<[u8; 9], OwError<B::Error>> {
    select(bus, rom, CMD_READ_SCRATCHPAD)?;
    let mut sp = [0u8; 9];
    for b in sp.iter_mut() {
        *b = bus.read_byte()?;
    }
    if sp.iter().all(|&b| b == 0xFF) {
        return Err(OwError::NoPresence);
    }
    if crc8(&sp[..8]) != sp[8] {
        return Err(OwError::Crc);
    }
    Ok(sp)
}

/// WRITE SCRATCHPAD (TH, TL, configuration) of `rom`.
pub fn write_config<B: OneWireBus>(
    bus: &mut B,
    rom: &Rom,
    th: u8,
    tl: u8,
    res: Resolution,
) -> Result<(), OwError<B::Error>> {
    select(bus, rom, CMD_WRITE_SCRATCHPAD)?;
    bus.write_byte(th)?;
    bus.write_byte(tl)?;
    bus.write_byte(res.config())?;
    Ok(())
}

/// Temperature of a scratchpad in 0.01 °C (undefined low bits of the resolution masked).
pub fn centi_celsius(sp: &[u8; 9]) -> (i16, Resolution) {
    let res = Resolution::from_config(sp[4]);
    let raw = i16::from_le_bytes([sp[0], sp[1]]) & res.raw_mask();
    // raw is in 1/16 °C: ×100/16 = ×25/4, within i16 for −55…125 °C.
    ((raw as i32 * 25 / 4) as i16, res)
}

/// The temperature task's period (report Table 4.2): 1 s.
pub const TEMP_PERIOD_MS: u32 = 1000;

/// Default overheat threshold: 80 °C.
pub const DEFAULT_THRESHOLD: i16 = 8000;
/// Hysteresis below the threshold before an overheat clears: 5 °C.
pub const HYSTERESIS: i16 = 500;

/// One set of readings the temperature task hands to the application task (by value).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TempFrame {
    /// Readings in 0.01 °C, [`TEMP_INVALID`] where none.
    pub values: [i16; SENSORS],
    /// Sequence number (one per read-out).
    pub seq: u32,
}

/// Counters of the temperature task.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct TempStats {
    /// Scratchpads read with a good CRC.
    pub reads: u32,
    /// Scratchpads that failed their CRC.
    pub crc_errors: u32,
    /// Reads nobody answered.
    pub no_answer: u32,
    /// Bus driver errors.
    pub bus_errors: u32,
    /// ROM searches run.
    pub searches: u32,
    /// Task restarts after `ERR_TEMP_DSM_FAULT`.
    pub restarts: u32,
}

/// Read-outs in a row in which no sensor of the bus answered with a good scratchpad that
/// make the temperature task itself faulty (`ERR_TEMP_DSM_FAULT`): not one sensor lost but
/// the whole bus (cable pulled, bus shorted). The task then restarts from its ROM search.
pub const TEMP_DSM_FAULT_RUNS: u32 = 3;

/// Where the temperature task's release is (each step one [`Txn`] on the bus).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Step {
    /// Nothing runs.
    Idle,
    /// ROM search: `found` ROMs so far.
    Search,
    /// Reading the resolution of sensor `i` after the search.
    Resolution(usize),
    /// Reading sensor `i`'s scratchpad.
    Read(usize),
    /// CONVERT T.
    Convert,
}

/// The temperature task (the report's Temperature SDM + owApp): scan until sensors are found,
/// then every period read the previous conversion of each sensor and start the next.
///
/// A release ([`TempTask::run`]) is a chain of 1-Wire transactions ([`Txn`]); on a blocking
/// bus it runs to its end in the call, on an interrupt-driven one each transaction runs in
/// the background and [`TempTask::resume`] (called until [`TempTask::busy`] is false)
/// takes its result and starts the next: the caller never waits for the bus.
#[derive(Debug, Clone)]
pub struct TempTask {
    roms: [Rom; SENSORS],
    res: [Resolution; SENSORS],
    failing: [bool; SENSORS],
    count: usize,
    converting: bool,
    since_convert_us: u32,
    overheat: bool,
    init_reported: bool,
    init_error: bool,
    dead_runs: u32,
    seq: u32,
    step: Step,
    txn: Txn,
    waiting: bool,
    found: usize,
    values: [i16; SENSORS],
    was_failing: bool,
    max: Option<i16>,
    /// Overheat threshold in 0.01 °C.
    pub threshold: i16,
    /// Counters.
    pub stats: TempStats,
}

impl Default for TempTask {
    fn default() -> Self {
        Self {
            roms: [[0; 8]; SENSORS],
            res: [Resolution::Bits12; SENSORS],
            failing: [false; SENSORS],
            count: 0,
            converting: false,
            since_convert_us: 0,
            overheat: false,
            init_reported: false,
            init_error: false,
            dead_runs: 0,
            seq: 0,
            step: Step::Idle,
            txn: Txn::convert(),
            waiting: false,
            found: 0,
            values: [TEMP_INVALID; SENSORS],
            was_failing: false,
            max: None,
            threshold: DEFAULT_THRESHOLD,
            stats: TempStats::default(),
        }
    }
}

impl TempTask {
    /// The ROMs found.
    pub fn roms(&self) -> &[Rom] {
        &self.roms[..self.count]
    }

    /// The resolution of sensor `i` as read from its configuration register.
    pub fn resolution(&self, i: usize) -> Option<Resolution> {
        (i < self.count).then(|| self.res[i])
    }

    /// True while an overheat is active.
    pub fn overheat(&self) -> bool {
        self.overheat
    }

    /// True while a release's transactions run (call [`TempTask::resume`]).
    pub fn busy(&self) -> bool {
        self.step != Step::Idle
    }

    fn longest_conversion_us(&self) -> u32 {
        self.res[..self.count]
            .iter()
            .map(|r| r.conversion_us())
            .max()
            .unwrap_or(Resolution::Bits12.conversion_us())
    }

    /// One release of the task (every [`TEMP_PERIOD_MS`]); posts events and errors to
    /// `sys`; returns a new frame when sensors were read (on an interrupt-driven bus the
    /// frame may come from a later [`TempTask::resume`]). A release while the previous one
    /// still runs only counts the time.
    pub fn run<B: OneWireBus>(&mut self, bus: &mut B, sys: &mut SystemState) -> Option<TempFrame> {
        self.since_convert_us = self.since_convert_us.saturating_add(TEMP_PERIOD_MS * 1000);
        if self.busy() {
            return self.resume(bus, sys);
        }
        if self.count == 0 {
            self.stats.searches += 1;
            self.found = 0;
            self.step = Step::Search;
            self.start(bus, Txn::search([0; 8], 0));
        } else if self.converting && self.since_convert_us >= self.longest_conversion_us() {
            self.values = [TEMP_INVALID; SENSORS];
            self.was_failing = self.failing.iter().any(|&f| f);
            self.max = None;
            self.step = Step::Read(0);
            self.start(bus, Txn::read_scratchpad(&self.roms[0]));
        } else if !self.converting {
            self.step = Step::Convert;
            self.start(bus, Txn::convert());
        } else {
            return None;
        }
        self.resume(bus, sys)
    }

    /// Starts `t` on the bus (a bus that fails to start it ends it as a bus error).
    fn start<B: OneWireBus>(&mut self, bus: &mut B, t: Txn) {
        self.txn = t;
        self.waiting = match bus.begin(&mut self.txn) {
            Ok(done) => !done,
            Err(_) => {
                self.txn = t.ended(TxnStatus::BusFault);
                false
            }
        };
    }
    /// Takes the result of the running transaction when it has finished and starts the
    /// next, as far as the bus allows without waiting; posts events and errors to `sys`;
    /// the frame when a read-out ended.
    pub fn resume<B: OneWireBus>(
        &mut self,
        bus: &mut B,
        sys: &mut SystemState,
    ) -> Option<TempFrame> {
        let mut frame = None;
        while self.step != Step::Idle {
            if self.waiting {
                match bus.collect(&mut self.txn) {
                    Ok(true) => self.waiting = false,
                    Ok(false) => break,
                    Err(_) => {
                        self.waiting = false;
                        self.txn.status = TxnStatus::BusFault;
                    }
                }
            }
            let t = self.txn;
            match self.step {
                Step::Idle => {}
                Step::Search => self.searched(bus, sys, &t),
                Step::Resolution(i) => {
                    self.res[i] = match scratchpad_of(&t) {
                        Ok(sp) => Resolution::from_config(sp[4]),
                        Err(_) => Resolution::Bits12,
                    };
                    if i + 1 < self.count {
                        self.step = Step::Resolution(i + 1);
                        self.start(bus, Txn::read_scratchpad(&self.roms[i + 1]));
                    } else {
                        if !self.init_reported {
                            self.init_reported = true;
                            sys.post(codes::EV_TEMP_DSM_INIT);
                        }
                        self.step = Step::Idle;
                    }
                }
                Step::Read(i) => {
                    self.read_one(i, &t, sys);
                    if i + 1 < self.count {
                        self.step = Step::Read(i + 1);
                        self.start(bus, Txn::read_scratchpad(&self.roms[i + 1]));
                    } else {
                        frame = Some(self.read_out(sys));
                        if self.count == 0 {
                            // The task restarts from the ROM search at the next release.
                            self.step = Step::Idle;
                        } else {
                            self.step = Step::Convert;
                            self.start(bus, Txn::convert());
                        }
                    }
                }
                Step::Convert => {
                    if t.status == TxnStatus::BusFault {
                        self.stats.bus_errors += 1;
                        sys.post(codes::ERR_TEMP_SENS_TIMEOUT);
                    } else {
                        self.converting = true;
                        self.since_convert_us = 0;
                    }
                    self.step = Step::Idle;
                }
            }
        }
        frame
    }

    /// A search transaction ended: the next ROM, or the end of the search (then the
    /// resolution of each sensor).
    fn searched<B: OneWireBus>(&mut self, bus: &mut B, sys: &mut SystemState, t: &Txn) {
        let next = match t.status {
            TxnStatus::Done if crc8(&t.rom) != 0 => Err(()),
            TxnStatus::Done => {
                self.roms[self.found] = t.rom;
                self.found += 1;
                Ok(t.last_discrepancy != 0 && self.found < SENSORS)
            }
            // Nobody answered the reset: the search is over.
            TxnStatus::NoPresence => Ok(false),
            TxnStatus::BusFault => {
                self.stats.bus_errors += 1;
                Err(())
            }
            TxnStatus::SearchLost | TxnStatus::Running => Err(()),
        };
        match next {
            Ok(true) => {
                self.start(bus, Txn::search(t.rom, t.last_discrepancy));
                return;
            }
            Ok(false) => {}
            // A failed search finds nothing (as before: the ROMs so far are dropped).
            Err(()) => self.found = 0,
        }
        self.count = self.found;
        if self.count == 0 {
            if !self.init_error {
                self.init_error = true;
                sys.post(codes::ERR_TEMP_SENS_INIT);
            }
            self.step = Step::Idle;
            return;
        }
        self.step = Step::Resolution(0);
        self.start(bus, Txn::read_scratchpad(&self.roms[0]));
    }

    /// Sensor `i`'s scratchpad transaction ended.
    fn read_one(&mut self, i: usize, t: &Txn, sys: &mut SystemState) {
        let fail = match scratchpad_of(t) {
            Ok(sp) => {
                self.stats.reads += 1;
                let (v, res) = centi_celsius(&sp);
                self.res[i] = res;
                self.values[i] = v;
                self.max = Some(self.max.map_or(v, |m| m.max(v)));
                None
            }
            Err(OwError::Crc) => {
                self.stats.crc_errors += 1;
                Some(codes::ERR_TEMP_SENS_CRC)
            }
            Err(OwError::NoPresence) => {
                self.stats.no_answer += 1;
                Some(codes::ERR_TEMP_SENS_LOST)
            }
            Err(OwError::Bus(())) => {
                self.stats.bus_errors += 1;
                Some(codes::ERR_TEMP_SENS_TIMEOUT)
            }
        };
        match fail {
            Some(code) => {
                if !self.failing[i] {
                    sys.post(code);
                }
                self.failing[i] = true;
            }
            None => self.failing[i] = false,
        }
    }

    /// The read-out's end: recovery, overheat, the frame; a dead bus restarts the task.
    fn read_out(&mut self, sys: &mut SystemState) -> TempFrame {
        if self.was_failing && !self.failing.iter().any(|&f| f) {
            sys.post(codes::EV_TEMP_SENS_BACK);
        }
        if let Some(m) = self.max {
            if !self.overheat && m >= self.threshold {
                self.overheat = true;
                sys.post(codes::ERR_TEMP_SENS_OVERHEAT);
            } else if self.overheat && m < self.threshold.saturating_sub(HYSTERESIS) {
                self.overheat = false;
                sys.post(codes::EV_TEMP_OVERHEAT_CLEARED);
            }
        }
        self.seq = self.seq.wrapping_add(1);
        let f = TempFrame {
            values: self.values,
            seq: self.seq,
        };
        self.converting = false;
        if f.values[..self.count].iter().all(|&v| v == TEMP_INVALID) {
            self.dead_runs += 1;
        } else {
            self.dead_runs = 0;
        }
        if self.dead_runs >= TEMP_DSM_FAULT_RUNS {
            // The report's task manager re-created a faulty thread: start again from the
            // ROM search (sensor errors stay active until the sensors answer again).
            sys.post(codes::ERR_TEMP_DSM_FAULT);
            self.dead_runs = 0;
            self.count = 0;
            self.init_reported = false;
            self.init_error = true;
            self.stats.restarts += 1;
        }
        f
    }
}

/// The scratchpad a READ SCRATCHPAD transaction read, CRC-checked (as [`read_scratchpad`]).
fn scratchpad_of(t: &Txn) -> Result<[u8; 9], OwError<()>> {
    match t.status {
        TxnStatus::Done => {}
        TxnStatus::BusFault => return Err(OwError::Bus(())),
        _ => return Err(OwError::NoPresence),
    }
    let sp = t.rx;
    if sp.iter().all(|&b| b == 0xFF) {
        return Err(OwError::NoPresence);
    }
    if crc8(&sp[..8]) != sp[8] {
        return Err(OwError::Crc);
    }
    Ok(sp)
}
