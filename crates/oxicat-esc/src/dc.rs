//! Distributed Clocks of one ESC: local clock with drift, port receive times, system time
//! with offset and delay, the time-control loop, SYNC0/SYNC1 generation and latch inputs.
//!
//! CONTRACT (the ESC core calls exactly these; `regs` is the ESC's register file
//! 0x0000..0x1000, `t` is global (virtual) time in ns, monotonic across calls):
//! - `Dc::new(cfg)`
//! - `frame_arrival(regs, port, t)`: first bit of a frame reaches `port` at `t` (called for
//!   every port a frame enters, before any processing; port 0 = processing-unit direction).
//! - `before_read(regs, addr, len, t)`: the ESC is about to read `regs[addr..addr+len]`
//!   (ECAT or PDI) for a frame/access at `t`: refresh live DC registers in that range.
//! - `after_write(regs, addr, len, t, from_ecat)`: bytes `regs[addr..addr+len]` were just
//!   written (the ESC core already stored them, honouring write permissions).
//! - `advance(regs, t) -> DcEvents`: move to time `t`; SYNC/latch events that happened in
//!   (previous t, t] are returned with their global times.
//! - `next_event(&self) -> Option<u64>`: global time of the next SYNC edge, if any.
//! - `local_time(t)`: the free-running local clock at global time `t`.

/// How an ESC's local oscillator deviates from ideal time.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ClockConfig {
    /// Oscillator error in parts per million (positive runs fast).
    pub drift_ppm: f64,
    /// Local time at global time zero, in ns (the ESC's power-on offset).
    pub start_offset_ns: u64,
}

/// SYNC and latch events produced while advancing time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DcEvents {
    /// Global time of a SYNC0 rising edge in the advanced interval.
    pub sync0: Option<u64>,
    /// Global time of a SYNC1 rising edge in the advanced interval.
    pub sync1: Option<u64>,
}

/// The DC unit.
#[derive(Debug, Clone)]
pub struct Dc {
    cfg: ClockConfig,
}

impl Dc {
    /// A DC unit with the given oscillator.
    pub fn new(cfg: ClockConfig) -> Self {
        Self { cfg }
    }

    /// The free-running local clock at global time `t`.
    pub fn local_time(&self, t: u64) -> u64 {
        let drift = (t as f64) * self.cfg.drift_ppm * 1e-6;
        (t as i64 + drift as i64) as u64 + self.cfg.start_offset_ns
    }

    /// First bit of a frame reached `port` at global time `t`.
    pub fn frame_arrival(&mut self, _regs: &mut [u8], _port: u8, _t: u64) {}

    /// Refresh live registers in `addr..addr+len` before they are read at `t`.
    pub fn before_read(&mut self, _regs: &mut [u8], _addr: u16, _len: u16, _t: u64) {}

    /// React to bytes `addr..addr+len` that were just written.
    pub fn after_write(&mut self, _regs: &mut [u8], _addr: u16, _len: u16, _t: u64, _ecat: bool) {}

    /// Advance to global time `t`.
    pub fn advance(&mut self, _regs: &mut [u8], _t: u64) -> DcEvents {
        DcEvents::default()
    }

    /// Global time of the next SYNC edge.
    pub fn next_event(&self) -> Option<u64> {
        None
    }
}
