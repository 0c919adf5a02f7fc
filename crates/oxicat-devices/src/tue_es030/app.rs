//! The TUeES030 application ([`TuEs030`]): `handle_RXPDO`/`handle_TXPDO` on every RxPDO
//! (SM-synchronous), `i_handler_pwm` on the 20 kHz timer, `i_handler_ec` on the 1 kHz
//! timer. Hardware only through the small traits below.

use oxicat_slave::{AlState, AlStatusCode, Application, Od, Var};

use super::control::q8mul;
use super::control::{
    line_10mv, param2int_rev, phases, u2pwm, vref5_10mv, BoardRev, IntParams, Motor, MotorParams,
    KILLVOLTAGE, R2IGAINCH1_Q8, R2IGAIN_Q8, R2U_FP,
};
use super::device::{FRF_PER_CYCLE, OBJECTS};
use super::ring::Ring;

/// Timer id of the 20 kHz current loop (`INTPWM` → `i_handler_pwm`).
pub const CURRENT_TIMER: u8 = 0;
/// Timer id of the 1 kHz service routine (`INTEC` → `i_handler_ec`).
pub const SERVICE_TIMER: u8 = 1;

/// Normal-mode `mcom` bit: controlled (public driver header: 0 braked, 1/3 controlled,
/// 2 tristate).
pub const MCOM_ENABLE: u8 = 0x01;
/// Normal-mode `mcom` bit: tristate when not controlled.
pub const MCOM_TRISTATE: u8 = 0x02;
/// FRF `mcom` bits 0–1: motor channel (0-based, clamped to 2).
pub const MCOM_FRF_MMASK: u8 = 0x03;
/// FRF `mcom` bit 2: controlled.
pub const MCOM_FRF_ENABLE: u8 = 0x04;
/// FRF `mcom` bit 3: tristate.
pub const MCOM_FRF_TRISTATE: u8 = 0x08;

/// `mstate` bit 0: enabled.
pub const MSTATE_ENABLED: u8 = 0x01;
/// `mstate` bit 1: driver FAULT.
pub const MSTATE_FAULT: u8 = 0x02;
/// `mstate` bit 2: driver over-temperature warning.
pub const MSTATE_OTW: u8 = 0x04;
/// `mstate` bit 3 (oxicat; the manual's firmware reports nothing): the over-voltage kill
/// disabled the motors at least once since the previous TxPDO.
pub const MSTATE_KILLED: u8 = 0x08;
/// Digital input bit of `M1_FAULT` (derived from the firmware's shifts).
pub const DI_M1_FAULT: u8 = 0x10;
/// Digital input bit of `M1_OTW`.
pub const DI_M1_OTW: u8 = 0x20;
/// Digital input bit of `M2_M3_FAULT`.
pub const DI_M23_FAULT: u8 = 0x40;
/// Digital input bit of `M2_M3_OTW`.
pub const DI_M23_OTW: u8 = 0x80;
/// Internal digital output toggled by the service routine (`FRUN`), in the upper nibble
/// the firmware keeps for itself.
pub const DO_FRUN: u8 = 0x10;

/// ADC2 channel of the line voltage.
pub const ADC2_LINE: usize = 2;
/// ADC2 channel of the 5 V reference (chosen; the manual says ADC2 checks it).
pub const ADC2_VREF5: usize = 1;
/// ADC2 channels of the motor currents 1..3.
pub const ADC2_CURRENT: [usize; 3] = [3, 4, 5];
/// ADC1 channels: hall positions 1..3 (0–2), forces 1..3 (3–5), analog 1..2 (6–7); the
/// manual names the signals, not the channel order.
pub const ADC1_POS: [usize; 3] = [0, 1, 2];
/// ADC1 channels of the force sensors.
pub const ADC1_FORCE: [usize; 3] = [3, 4, 5];
/// ADC1 channels of the spare analog inputs.
pub const ADC1_ANALOG: [usize; 2] = [6, 7];

/// The PWM2ph3 comparators of one H-bridge and the DRV8412 enable (`set_drvena`).
pub trait Bridges {
    /// Sets phase A/B compare values (0..=PWMPER, taken at the counter's bottom) and the
    /// driver enable of channel `ch` (0..3); `enable = false` is tristate.
    fn set_bridge(&mut self, ch: usize, cmp_a: u16, cmp_b: u16, enable: bool);
}

/// The two multiplexed 12-bit ADCs (AS154x).
pub trait Adcs {
    /// ADC1 channel `ch` (0..8).
    fn adc1(&mut self, ch: usize) -> u16;
    /// ADC2 channel `ch` (0..8), sampled at the PWM counter's top.
    fn adc2(&mut self, ch: usize) -> u16;
}

/// The three quadrature decoders.
pub trait Encoders {
    /// `ENCn_HOLD`: the count and its 40 MHz capture timestamp, latched together.
    fn latch(&mut self, ch: usize) -> (u32, u32);
}

/// GPIO, the AD5722R DAC and the caliper UART.
pub trait Io {
    /// Digital inputs (driver FAULT/OTW lines in bits 4–7).
    fn digin(&mut self) -> u8;
    /// Digital outputs.
    fn digout(&mut self, v: u8);
    /// DAC channel `ch` (0..2), 12-bit code.
    fn dac(&mut self, ch: usize, code: u16);
    /// Caliper readings \[0.01 mm\].
    fn calipers(&mut self) -> [u16; 2];
}

/// Everything the firmware touches.
pub trait Board: Bridges + Adcs + Encoders + Io {}
impl<T: Bridges + Adcs + Encoders + Io> Board for T {}

/// Operation mode, from the PDO assignment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Mode {
    /// `OPERATION_STD`: 0x1600 / 0x1A00.
    #[default]
    Normal,
    /// `OPERATION_FRF`: 0x1601 / 0x1A01.
    Frf,
}

#[derive(Debug, Clone, Copy)]
struct NormalIo {
    mcom: [Var<u8>; 3],
    sp: [Var<i16>; 3],
    ff: [Var<i16>; 3],
    dig_out: Var<u8>,
    aout: [Var<i16>; 2],
    mstate: [Var<u8>; 3],
    count: [Var<u32>; 3],
    ts: [Var<u32>; 3],
    vel: [Var<i16>; 3],
    cur: [Var<i16>; 3],
    dig_in: Var<u8>,
    others: [Var<u16>; 12],
}

#[derive(Debug, Clone, Copy)]
struct FrfIo {
    mcom: Var<u8>,
    entries: Var<u8>,
    sp: [Var<i16>; FRF_PER_CYCLE],
    mstate: Var<u8>,
    buffer: Var<u8>,
    entries_out: Var<u8>,
    ectime: Var<u16>,
    cur: [Var<i16>; FRF_PER_CYCLE],
}

/// The handles of 0x8040 "Internal voltages" (line, 5 V reference, line peak, kill
/// threshold).
#[derive(Debug, Clone, Copy)]
struct VoltIo {
    volts: [Var<u16>; 4],
}

impl VoltIo {
    const VARS: Self = Self {
        volts: Var::subs(OBJECTS, 0x8040, 1),
    };
}

impl NormalIo {
    /// The normal-mode handles, from the declaration ([`OBJECTS`]): offsets and types
    /// checked when the crate builds.
    const VARS: Self = Self {
        mcom: Var::across(OBJECTS, 0x7000, 1),
        sp: Var::across(OBJECTS, 0x7000, 2),
        ff: Var::across(OBJECTS, 0x7000, 3),
        dig_out: Var::of(OBJECTS, 0x7010, 1),
        aout: Var::subs(OBJECTS, 0x7010, 2),
        mstate: Var::across(OBJECTS, 0x6000, 1),
        count: Var::across(OBJECTS, 0x6000, 2),
        ts: Var::across(OBJECTS, 0x6000, 3),
        vel: Var::across(OBJECTS, 0x6000, 4),
        cur: Var::across(OBJECTS, 0x6000, 5),
        dig_in: Var::of(OBJECTS, 0x6010, 1),
        others: Var::subs(OBJECTS, 0x6010, 2),
    };
}

impl FrfIo {
    /// The FRF-mode handles, as [`NormalIo::VARS`].
    const VARS: Self = Self {
        mcom: Var::of(OBJECTS, 0x7020, 1),
        entries: Var::of(OBJECTS, 0x7020, 2),
        sp: Var::subs(OBJECTS, 0x7020, 3),
        mstate: Var::of(OBJECTS, 0x6020, 1),
        buffer: Var::of(OBJECTS, 0x6020, 2),
        entries_out: Var::of(OBJECTS, 0x6020, 3),
        ectime: Var::of(OBJECTS, 0x6020, 4),
        cur: Var::subs(OBJECTS, 0x6021, 1),
    };
}

/// Counters for diagnostics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Counters {
    /// Current-loop runs.
    pub current_loops: u64,
    /// Service-routine runs.
    pub services: u64,
    /// RxPDOs handled in OP.
    pub rx_pdos: u64,
    /// Current-loop runs with the line voltage above the kill threshold.
    pub kills: u64,
    /// FRF setpoints dropped because the buffer was full.
    pub frf_dropped: u64,
}

/// The TUeES030 firmware.
pub struct TuEs030<B: Board> {
    /// The hardware.
    pub board: B,
    /// The three motor channels.
    pub motors: [Motor; 3],
    /// Motor parameters in SI (mirrors 0x8000–0x8002).
    pub params: [MotorParams; 3],
    /// Mode of the running PDO assignment.
    pub mode: Mode,
    /// FRF setpoints (master → current loop), `rx_buffer`.
    pub rx: Ring,
    /// FRF measured currents (current loop → master), `tx_buffer`.
    pub tx: Ring,
    /// FRF motor channel (0-based).
    pub frf_channel: usize,
    /// Line voltage \[10 mV\] (`linevoltage_i`).
    pub linevoltage: i16,
    /// The 1 kHz tick counter (`icnt`, reported as `ectime`).
    pub icnt: u16,
    /// What ran.
    pub counters: Counters,
    /// The current scaling the PI gains are converted with ([`BoardRev`]).
    pub board_rev: BoardRev,
    /// Over-voltage kill threshold on the raw ADC2_CH2 counts (`KILLVOLTAGE`; a bench
    /// sets `u16::MAX` to run the firmware without the kill).
    pub kill_counts: u16,
    /// Highest ADC2_CH2 count the current loop saw since reset (0x8040:03).
    pub line_peak_counts: u16,
    u2pwm: i32,
    killed: bool,
    kill_seen: bool,
    output: bool,
    input: bool,
    dostate: u8,
    ledcnt: u16,
    /// The dictionary is the TUeES030's: the build-time handles apply.
    dict: bool,
}

impl<B: Board> TuEs030<B> {
    /// The firmware on `board`, parameters at the manual's defaults, motors braked, the
    /// default board revision ([`BoardRev::Sense42`]).
    pub fn new(board: B) -> Self {
        Self::with_rev(board, BoardRev::default())
    }

    /// [`TuEs030::new`] with the PI gains converted for the board revision `rev`.
    pub fn with_rev(board: B, rev: BoardRev) -> Self {
        let par = param2int_rev(&MotorParams::DEFAULT, rev);
        let mut motors = [Motor::default(); 3];
        for m in &mut motors {
            m.par = par;
        }
        let mut s = Self {
            board,
            motors,
            params: [MotorParams::DEFAULT; 3],
            mode: Mode::Normal,
            rx: Ring::new(),
            tx: Ring::new(),
            frf_channel: 0,
            linevoltage: 2400,
            icnt: 0,
            counters: Counters::default(),
            board_rev: rev,
            kill_counts: KILLVOLTAGE,
            line_peak_counts: 0,
            u2pwm: u2pwm(2400),
            killed: false,
            kill_seen: false,
            output: false,
            input: false,
            dostate: 0,
            ledcnt: 0,
            dict: false,
        };
        s.clear_pwm();
        s
    }

    /// Outputs are live (`APPSTATE_OUTPUT`: OP).
    pub fn outputs_active(&self) -> bool {
        self.output
    }

    /// Motor `k`'s parameters as 0x8000 + `k` holds them (a default where a read fails),
    /// and converted for board revision `rev`: the dictionary side of `init_param`.
    fn read_params<const N: usize>(od: &Od<N>, k: usize, rev: BoardRev) -> Params {
        let i = 0x8000 + k as u16;
        let d = MotorParams::DEFAULT;
        let p = MotorParams {
            r: od.get(i, 1).unwrap_or(d.r),
            kv: od.get(i, 2).unwrap_or(d.kv),
            pgain: od.get(i, 3).unwrap_or(d.pgain),
            igain: od.get(i, 4).unwrap_or(d.igain),
            ilimit: od.get(i, 5).unwrap_or(d.ilimit),
            encdir: od.get(i, 6).unwrap_or(d.encdir),
            encres: od.get(i, 7).unwrap_or(d.encres),
            czero: od.get(i, 8).unwrap_or(d.czero),
        };
        Params {
            k,
            si: p,
            int: param2int_rev(&p, rev),
        }
    }

    /// Takes over converted motor parameters (the firmware's side of `init_param`).
    fn set_params(&mut self, p: &Params) {
        self.params[p.k] = p.si;
        self.motors[p.k].par = p.int;
    }

    /// Brakes every motor (50/50, drivers enabled), the `clear_PWM` of a stopped output.
    fn clear_pwm(&mut self) {
        let (a, b) = phases(0);
        for ch in 0..3 {
            self.board.set_bridge(ch, a, b, true);
        }
    }

    fn stop_motors(&mut self) {
        for m in &mut self.motors {
            m.enabled = false;
            m.tristate = false;
            m.current_setpoint = 0;
            m.setpoint_ff = 0;
            m.idle();
        }
        self.rx.clear();
        self.tx.clear();
        self.clear_pwm();
    }

    fn mstate_bits(di: u8, fault: u8, otw: u8) -> u8 {
        (if di & fault != 0 { MSTATE_FAULT } else { 0 })
            | if di & otw != 0 { MSTATE_OTW } else { 0 }
    }

    /// [`MSTATE_KILLED`] if the kill acted since the last TxPDO (and forgets it).
    fn take_kill(&mut self) -> u8 {
        if core::mem::take(&mut self.kill_seen) {
            MSTATE_KILLED
        } else {
            0
        }
    }

    /// 0x8040 "Internal voltages" from the last readings: line, 5 V reference, line
    /// peak, kill threshold \[10 mV\].
    fn voltages(&mut self) -> [u16; 4] {
        let vref = vref5_10mv(self.board.adc2(ADC2_VREF5));
        [
            self.linevoltage.max(0) as u16,
            vref,
            line_10mv(self.line_peak_counts),
            line_10mv(self.kill_counts),
        ]
    }

    /// `handle_RXPDO` (normal mode: `update_actuators`), from the RxPDO as read.
    fn apply_rx_normal(&mut self, rx: &RxNormal) {
        for k in 0..3 {
            let m = &mut self.motors[k];
            m.current_setpoint = rx.sp[k];
            m.setpoint_ff = rx.ff[k];
            // The kill holds while the line voltage stays above the threshold.
            m.enabled = rx.mcom[k] & MCOM_ENABLE != 0 && !self.killed;
            m.tristate = rx.mcom[k] & MCOM_TRISTATE != 0;
        }
        self.board
            .digout((rx.dig_out & 0x0F) | (self.dostate & 0xF0));
        for k in 0..2 {
            self.board.dac(k, rx.dac[k]);
        }
    }

    /// `handle_RXPDO` (FRF mode), from the RxPDO as read.
    fn apply_rx_frf(&mut self, rx: &RxFrf) {
        self.frf_channel = ((rx.mcom & MCOM_FRF_MMASK) as usize).min(2);
        for m in &mut self.motors {
            m.enabled = false;
        }
        let m = &mut self.motors[self.frf_channel];
        m.enabled = rx.mcom & MCOM_FRF_ENABLE != 0 && !self.killed;
        m.tristate = rx.mcom & MCOM_FRF_TRISTATE != 0;
        for &sp in &rx.sp[..rx.count] {
            if self.rx.free() > 0 {
                self.rx.write(sp);
            } else {
                self.counters.frf_dropped += 1;
            }
        }
    }

    /// `handle_TXPDO` (normal mode): the values, for [`TxNormal::store`].
    fn tx_normal(&mut self) -> TxNormal {
        let di = self.board.digin();
        let kill = self.take_kill();
        let drv = [
            Self::mstate_bits(di, DI_M1_FAULT, DI_M1_OTW) | kill,
            Self::mstate_bits(di, DI_M23_FAULT, DI_M23_OTW) | kill,
            Self::mstate_bits(di, DI_M23_FAULT, DI_M23_OTW) | kill,
        ];
        let mut tx = TxNormal {
            di,
            ..TxNormal::default()
        };
        for (k, (m, d)) in self.motors.iter().zip(drv).enumerate() {
            tx.mstate[k] = m.enabled as u8 | d;
            tx.count[k] = m.position;
            tx.ts[k] = m.poscaptime;
            tx.vel[k] = m.velocity;
            tx.cur[k] = m.current;
        }
        let cal = self.board.calipers();
        let v = &mut tx.others;
        v[0] = cal[0];
        v[1] = cal[1];
        for k in 0..3 {
            v[2 + k] = self.board.adc1(ADC1_FORCE[k]);
            v[5 + k] = self.board.adc1(ADC1_POS[k]);
        }
        v[8] = self.board.adc1(ADC1_ANALOG[0]);
        v[9] = self.board.adc1(ADC1_ANALOG[1]);
        v[10] = self.linevoltage.max(0) as u16;
        v[11] = self.icnt;
        tx
    }

    /// `handle_TXPDO` (FRF mode): up to 22 buffered currents per RxPDO, for
    /// [`TxFrf::store`].
    fn tx_frf(&mut self) -> TxFrf {
        let mut tx = TxFrf::default();
        while tx.n < FRF_PER_CYCLE {
            let Some(c) = self.tx.read() else { break };
            tx.cur[tx.n] = c;
            tx.n += 1;
        }
        let di = self.board.digin();
        let en = self.motors.iter().any(|m| m.enabled) as u8;
        let kill = self.take_kill();
        tx.mstate = en
            | Self::mstate_bits(di, DI_M1_FAULT, DI_M1_OTW)
            | Self::mstate_bits(di, DI_M23_FAULT, DI_M23_OTW)
            | kill;
        tx.buffer = self.rx.len().min(255) as u8;
        tx.ectime = self.icnt;
        tx
    }

    /// `i_handler_pwm`: the 20 kHz current loop.
    pub fn current_loop(&mut self) {
        self.counters.current_loops += 1;
        for (k, &ch) in ADC2_CURRENT.iter().enumerate() {
            let raw = self.board.adc2(ch) as i32;
            let m = &mut self.motors[k];
            let gain = if k == 0 { R2IGAINCH1_Q8 } else { R2IGAIN_Q8 };
            m.current = q8mul(raw - m.par.czero, gain as i32);
        }
        if self.mode == Mode::Frf && self.output {
            let ch = self.frf_channel;
            match self.rx.read() {
                Some(sp) => {
                    self.motors[ch].current_setpoint = sp;
                    self.tx.write(self.motors[ch].current);
                }
                None => self.motors[ch].current_setpoint = 0,
            }
        }
        let u2pwm = self.u2pwm;
        for m in &mut self.motors {
            m.current_pi(u2pwm);
        }
        let line = self.board.adc2(ADC2_LINE);
        self.line_peak_counts = self.line_peak_counts.max(line);
        self.killed = line > self.kill_counts;
        if self.killed {
            self.kill_seen = true;
            self.counters.kills += 1;
            for m in &mut self.motors {
                m.enabled = false;
            }
        }
        let output = self.output;
        for ch in 0..3 {
            let m = &mut self.motors[ch];
            if !m.enabled {
                m.idle();
            }
            let enable = m.enabled || !m.tristate;
            let (a, b) = if output { phases(m.cc_pwm) } else { phases(0) };
            self.board.set_bridge(ch, a, b, enable || !output);
        }
    }

    /// `i_handler_ec`: the 1 kHz service routine.
    pub fn service(&mut self) {
        self.counters.services += 1;
        self.icnt = self.icnt.wrapping_add(1);
        for k in 0..3 {
            let (pos, t) = self.board.latch(k);
            let m = &mut self.motors[k];
            m.position = pos;
            m.poscaptime = t;
            m.encoder_calculations();
        }
        let raw = self.board.adc2(ADC2_LINE) as i32;
        self.linevoltage = q8mul(raw, R2U_FP as i32);
        self.u2pwm = u2pwm(self.linevoltage as i32);
        self.ledcnt = self.ledcnt.wrapping_add(1);
        if self.ledcnt & 0x100 != 0 {
            self.dostate ^= DO_FRUN;
        }
    }
}

/// Motor parameters read from the dictionary and converted: what `init_param` and
/// `sdo_written` hand the firmware.
#[derive(Debug, Clone, Copy)]
struct Params {
    k: usize,
    si: MotorParams,
    int: IntParams,
}

/// A normal-mode RxPDO as read from the dictionary (`ff` clamped, DAC codes converted).
#[derive(Debug, Clone, Copy)]
struct RxNormal {
    sp: [i16; 3],
    ff: [i16; 3],
    mcom: [u8; 3],
    dig_out: u8,
    dac: [u16; 2],
}

impl RxNormal {
    fn read<const N: usize>(od: &Od<N>, io: &NormalIo) -> Self {
        let max = super::control::MAXVOLTAGE as i16;
        Self {
            sp: io.sp.map(|v| od.load(v)),
            ff: io.ff.map(|v| od.load(v).clamp(-max, max)),
            mcom: io.mcom.map(|v| od.load(v)),
            dig_out: od.load(io.dig_out),
            dac: io
                .aout
                .map(|v| (od.load(v) as i32 + 2048).clamp(0, 4095) as u16),
        }
    }
}

/// The normal-mode TxPDO's values, taken from the firmware.
#[derive(Debug, Clone, Copy, Default)]
struct TxNormal {
    mstate: [u8; 3],
    count: [u32; 3],
    ts: [u32; 3],
    vel: [i16; 3],
    cur: [i16; 3],
    di: u8,
    others: [u16; 12],
}

impl TxNormal {
    fn store<const N: usize>(&self, od: &mut Od<N>, io: &NormalIo) {
        for k in 0..3 {
            od.store(io.mstate[k], self.mstate[k]);
            od.store(io.count[k], self.count[k]);
            od.store(io.ts[k], self.ts[k]);
            od.store(io.vel[k], self.vel[k]);
            od.store(io.cur[k], self.cur[k]);
        }
        od.store(io.dig_in, self.di);
        for (var, x) in io.others.iter().zip(self.others) {
            od.store(*var, x);
        }
    }
}

/// An FRF RxPDO as read: `mcom`, the setpoint count (clamped) and the setpoints.
#[derive(Debug, Clone, Copy)]
struct RxFrf {
    mcom: u8,
    count: usize,
    sp: [i16; FRF_PER_CYCLE],
}

impl RxFrf {
    fn read<const N: usize>(od: &Od<N>, io: &FrfIo) -> Self {
        let count = (od.load(io.entries) as usize).min(FRF_PER_CYCLE);
        let mut sp = [0; FRF_PER_CYCLE];
        for (x, v) in sp.iter_mut().zip(&io.sp[..count]) {
            *x = od.load(*v);
        }
        Self {
            mcom: od.load(io.mcom),
            count,
            sp,
        }
    }
}

/// The FRF TxPDO's values, taken from the firmware.
#[derive(Debug, Clone, Copy, Default)]
struct TxFrf {
    cur: [i16; FRF_PER_CYCLE],
    n: usize,
    mstate: u8,
    buffer: u8,
    ectime: u16,
}

impl TxFrf {
    fn store<const N: usize>(&self, od: &mut Od<N>, io: &FrfIo) {
        for (var, c) in io.cur.iter().zip(self.cur) {
            od.store(*var, c);
        }
        // The listing stores the index of the last entry; we report the count (see README).
        od.store(io.entries_out, self.n as u8);
        od.store(io.mstate, self.mstate);
        od.store(io.buffer, self.buffer);
        od.store(io.ectime, self.ectime);
    }
}

/// How the stack's hooks reach the firmware: directly on the host; on a board whose
/// current loop runs in an interrupt, in a critical section. [`Hooks`] read and convert
/// the dictionary outside [`FwLock::with`] and only hand the results over inside it, so
/// the current loop waits for a copy of a few words, never for a dictionary read.
pub trait FwLock {
    /// The firmware's board.
    type Board: Board;
    /// Runs `f` on the firmware (on a board: with the current loop masked).
    fn with<R>(&mut self, f: impl FnOnce(&mut TuEs030<Self::Board>) -> R) -> R;
}

impl<B: Board> FwLock for &mut TuEs030<B> {
    type Board = B;
    fn with<R>(&mut self, f: impl FnOnce(&mut TuEs030<B>) -> R) -> R {
        f(self)
    }
}

/// The TUeES030's stack hooks on the firmware reached through `L` (the firmware itself
/// is its own [`Application`] through `Hooks<&mut TuEs030>`).
pub struct Hooks<L>(pub L);

impl<L: FwLock> Hooks<L> {
    /// The dictionary is the TUeES030's, so the build-time handles apply (checked once,
    /// outside the lock: it walks the whole declaration).
    /// The service routine's dictionary side alone: 0x8040 "Internal voltages" from the
    /// last readings, as the SERVICE_TIMER hook stores them after `service`. For a board
    /// that runs `TuEs030::service` in an interrupt of its own (the board image) and calls
    /// this from the stack's context, once per service period or less often.
    pub fn store_voltages<const N: usize>(&mut self, od: &mut Od<N>) {
        if !self.resolved(od) {
            return;
        }
        let v = self.0.with(|f| f.voltages());
        for (var, x) in VoltIo::VARS.volts.iter().zip(v) {
            od.store(*var, x);
        }
    }

    fn resolved<const N: usize>(&mut self, od: &Od<N>) -> bool {
        if self.0.with(|f| f.dict) {
            return true;
        }
        let dict = od.built_on(OBJECTS);
        if dict {
            self.0.with(|f| f.dict = true);
        }
        dict
    }
}

impl<const N: usize, L: FwLock> Application<N> for Hooks<L> {
    fn state_change(
        &mut self,
        _from: AlState,
        to: AlState,
        od: &mut Od<N>,
    ) -> Result<(), AlStatusCode> {
        self.resolved(od);
        match to {
            AlState::SafeOp => {
                let (input, rev) = self.0.with(|f| (f.input, f.board_rev));
                if !input {
                    // `init_param` at the start of the application; the assignment decides
                    // the mode.
                    let p = [0, 1, 2].map(|k| TuEs030::<L::Board>::read_params(od, k, rev));
                    let mode = match od.get::<u16>(0x1C12, 1) {
                        Ok(0x1601) => Mode::Frf,
                        _ => Mode::Normal,
                    };
                    self.0.with(|f| {
                        for q in &p {
                            f.set_params(q);
                        }
                        f.mode = mode;
                        f.rx.clear();
                        f.tx.clear();
                        f.input = true;
                    });
                }
            }
            AlState::Op => self.0.with(|f| f.output = true),
            _ => self.0.with(|f| {
                f.input = false;
                f.output = false;
                f.stop_motors();
            }),
        }
        Ok(())
    }

    fn safe_outputs(&mut self, od: &mut Od<N>) {
        // Leaving OP or the watchdog: outputs stop, the motors brake.
        self.0.with(|f| {
            f.output = false;
            f.stop_motors();
        });
        for k in 0..3u16 {
            let _ = od.set(0x7000 + k, 1, 0u8);
            let _ = od.set(0x7000 + k, 2, 0i16);
            let _ = od.set(0x7000 + k, 3, 0i16);
        }
        let _ = od.set(0x7010, 1, 0u8);
        let _ = od.set(0x7020, 1, 0u8);
        let _ = od.set(0x7020, 2, 0u8);
    }

    fn cycle(&mut self, od: &mut Od<N>) {
        if !self.resolved(od) {
            return;
        }
        let (mode, output, input) = self.0.with(|f| (f.mode, f.output, f.input));
        match mode {
            Mode::Normal => {
                let io = NormalIo::VARS;
                if output {
                    let rx = RxNormal::read(od, &io);
                    self.0.with(|f| {
                        f.counters.rx_pdos += 1;
                        f.apply_rx_normal(&rx);
                    });
                }
                if input {
                    self.0.with(|f| f.tx_normal()).store(od, &io);
                }
            }
            Mode::Frf => {
                let io = FrfIo::VARS;
                if output {
                    let rx = RxFrf::read(od, &io);
                    self.0.with(|f| {
                        f.counters.rx_pdos += 1;
                        f.apply_rx_frf(&rx);
                    });
                }
                if input {
                    self.0.with(|f| f.tx_frf()).store(od, &io);
                }
            }
        }
    }

    fn timer(&mut self, id: u8, od: &mut Od<N>) {
        match id {
            CURRENT_TIMER => self.0.with(|f| f.current_loop()),
            SERVICE_TIMER => {
                let dict = self.resolved(od);
                let v = self.0.with(|f| {
                    f.service();
                    dict.then(|| f.voltages())
                });
                if let Some(v) = v {
                    for (var, x) in VoltIo::VARS.volts.iter().zip(v) {
                        od.store(*var, x);
                    }
                }
            }
            _ => {}
        }
    }

    fn sdo_written(&mut self, index: u16, _sub: u8, od: &mut Od<N>) {
        if (0x8000..=0x8002).contains(&index) {
            let rev = self.0.with(|f| f.board_rev);
            let p = TuEs030::<L::Board>::read_params(od, (index - 0x8000) as usize, rev);
            self.0.with(|f| f.set_params(&p));
        }
    }
}

impl<const N: usize, B: Board> Application<N> for TuEs030<B> {
    fn state_change(
        &mut self,
        from: AlState,
        to: AlState,
        od: &mut Od<N>,
    ) -> Result<(), AlStatusCode> {
        Application::<N>::state_change(&mut Hooks(self), from, to, od)
    }

    fn safe_outputs(&mut self, od: &mut Od<N>) {
        Application::<N>::safe_outputs(&mut Hooks(self), od)
    }

    fn cycle(&mut self, od: &mut Od<N>) {
        Application::<N>::cycle(&mut Hooks(self), od)
    }

    fn timer(&mut self, id: u8, od: &mut Od<N>) {
        Application::<N>::timer(&mut Hooks(self), id, od)
    }

    fn sdo_written(&mut self, index: u16, sub: u8, od: &mut Od<N>) {
        Application::<N>::sdo_written(&mut Hooks(self), index, sub, od)
    }
}
