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
                    let d = if n < self.last_discrepancy {
                        self.rom[byte] & mask != 0
                    } else {
                        n == self.last_discrepancy
                    };
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

/// The temperature task (the report's Temperature SDM + owApp): scan until sensors are found,
/// then every period read the previous conversion of each sensor and start the next.
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

    fn longest_conversion_us(&self) -> u32 {
        self.res[..self.count]
            .iter()
            .map(|r| r.conversion_us())
            .max()
            .unwrap_or(Resolution::Bits12.conversion_us())
    }

    /// One release of the task (every [`TEMP_PERIOD_MS`]); posts events and errors to
    /// `sys`; returns a new frame when sensors were read.
    pub fn run<B: OneWireBus>(&mut self, bus: &mut B, sys: &mut SystemState) -> Option<TempFrame> {
        self.since_convert_us = self.since_convert_us.saturating_add(TEMP_PERIOD_MS * 1000);
        if self.count == 0 {
            self.scan(bus, sys);
            return None;
        }
        let mut frame = None;
        if self.converting && self.since_convert_us >= self.longest_conversion_us() {
            let f = self.read_all(bus, sys);
            self.converting = false;
            if f.values[..self.count].iter().all(|&v| v == TEMP_INVALID) {
                self.dead_runs += 1;
            } else {
                self.dead_runs = 0;
            }
            frame = Some(f);
            if self.dead_runs >= TEMP_DSM_FAULT_RUNS {
                // The report's task manager re-created a faulty thread: start again from the
                // ROM search (sensor errors stay active until the sensors answer again).
                sys.post(codes::ERR_TEMP_DSM_FAULT);
                self.dead_runs = 0;
                self.count = 0;
                self.init_reported = false;
                self.init_error = true;
                self.stats.restarts += 1;
                return frame;
            }
        }
        if !self.converting {
            match convert_all(bus) {
                Ok(_) => {
                    self.converting = true;
                    self.since_convert_us = 0;
                }
                Err(_) => {
                    self.stats.bus_errors += 1;
                    sys.post(codes::ERR_TEMP_SENS_TIMEOUT);
                }
            }
        }
        frame
    }

    #[allow(clippy::needless_range_loop)]
    fn scan<B: OneWireBus>(&mut self, bus: &mut B, sys: &mut SystemState) {
        self.stats.searches += 1;
        let n = match search_all(bus, &mut self.roms) {
            Ok(n) => n,
            Err(OwError::Bus(_)) => {
                self.stats.bus_errors += 1;
                0
            }
            Err(_) => 0,
        };
        self.count = n;
        if n == 0 {
            if !self.init_error {
                self.init_error = true;
                sys.post(codes::ERR_TEMP_SENS_INIT);
            }
            return;
        }
        for i in 0..n {
            self.res[i] = match read_scratchpad(bus, &self.roms[i]) {
                Ok(sp) => Resolution::from_config(sp[4]),
                Err(_) => Resolution::Bits12,
            };
        }
        if !self.init_reported {
            self.init_reported = true;
            sys.post(codes::EV_TEMP_DSM_INIT);
        }
    }

    // One index walks the ROM, resolution, failing and value tables together.
    #[allow(clippy::needless_range_loop)]
    fn read_all<B: OneWireBus>(&mut self, bus: &mut B, sys: &mut SystemState) -> TempFrame {
        let mut values = [TEMP_INVALID; SENSORS];
        let was_failing = self.failing.iter().any(|&f| f);
        let mut max: Option<i16> = None;
        for i in 0..self.count {
            let r = read_scratchpad(bus, &self.roms[i]);
            let fail = match r {
                Ok(sp) => {
                    self.stats.reads += 1;
                    let (t, res) = centi_celsius(&sp);
                    self.res[i] = res;
                    values[i] = t;
                    max = Some(max.map_or(t, |m| m.max(t)));
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
                Err(OwError::Bus(_)) => {
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
        if was_failing && !self.failing.iter().any(|&f| f) {
            sys.post(codes::EV_TEMP_SENS_BACK);
        }
        if let Some(m) = max {
            if !self.overheat && m >= self.threshold {
                self.overheat = true;
                sys.post(codes::ERR_TEMP_SENS_OVERHEAT);
            } else if self.overheat && m < self.threshold.saturating_sub(HYSTERESIS) {
                self.overheat = false;
                sys.post(codes::EV_TEMP_OVERHEAT_CLEARED);
            }
        }
        self.seq = self.seq.wrapping_add(1);
        TempFrame {
            values,
            seq: self.seq,
        }
    }
}
