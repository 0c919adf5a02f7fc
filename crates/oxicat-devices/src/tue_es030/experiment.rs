//! The TUeES030 from the master, what the manual's Simulink S-functions and `ec.c` do:
//! switch the PDO mode (`ec_Set_TUeES030mode`: PRE-OP, reassign 0x1C12/0x1C13, back to
//! OP), write and read back the motor parameters (`ec_Set_TUeES030params`), run the normal
//! 1 kHz cycle (`ec_TU_ES_030`), and the FRF experiment (`ec_TU_ES_030FRF`): stream a
//! current excitation at up to 22 setpoints per 1 ms cycle with the manual's buffer-level
//! flow control (22 below 50 queued, 20 at 50, 18 above), record the measured currents,
//! check that none was lost, and compute the closed-loop frequency response at the
//! excitation lines (own DFT), with bandwidth and phase margin, and Bode plots.

use std::path::{Path, PathBuf};

use oxicat_master::cyclic::{CycleOptions, Flow};
use oxicat_master::{Link, Master, MasterError};

/// PDO mode of the board.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TueMode {
    /// 0x1600 / 0x1A00 (`mode` 1).
    Normal,
    /// 0x1601 / 0x1A01 (`mode` 2).
    Frf,
}

impl TueMode {
    /// (RxPDO, TxPDO) mapping indices.
    pub const fn pdos(self) -> (u16, u16) {
        match self {
            TueMode::Normal => (0x1600, 0x1A00),
            TueMode::Frf => (0x1601, 0x1A01),
        }
    }
}

/// The motor parameters of the three channels, as the Simulink mask holds them.
#[derive(Debug, Clone, PartialEq)]
pub struct TueParams {
    /// Resistance \[Ω\] (sub 1).
    pub r: [f32; 3],
    /// KV \[V s/rad\] (sub 2).
    pub kv: [f32; 3],
    /// P gain \[V/A\] (sub 3).
    pub pgain: [f32; 3],
    /// I gain (sub 4).
    pub igain: [f32; 3],
    /// Integrator limit \[A s\] (sub 5).
    pub ilimit: [f32; 3],
    /// Encoder direction (sub 6).
    pub encdir: [i8; 3],
    /// Encoder resolution (sub 7).
    pub encres: [u16; 3],
    /// Current zero (sub 8).
    pub czero: [i16; 3],
}

impl Default for TueParams {
    /// The Simulink mask defaults (manual Fig. 5.2).
    fn default() -> Self {
        Self {
            r: [0.61; 3],
            kv: [0.03; 3],
            pgain: [2.0; 3],
            igain: [2.0; 3],
            ilimit: [0.2; 3],
            encdir: [1; 3],
            encres: [1024; 3],
            czero: [2168; 3],
        }
    }
}

impl TueParams {
    fn encode(&self, k: usize, sub: u8) -> Vec<u8> {
        match sub {
            1 => self.r[k].to_le_bytes().to_vec(),
            2 => self.kv[k].to_le_bytes().to_vec(),
            3 => self.pgain[k].to_le_bytes().to_vec(),
            4 => self.igain[k].to_le_bytes().to_vec(),
            5 => self.ilimit[k].to_le_bytes().to_vec(),
            6 => self.encdir[k].to_le_bytes().to_vec(),
            7 => self.encres[k].to_le_bytes().to_vec(),
            _ => self.czero[k].to_le_bytes().to_vec(),
        }
    }

    fn decode(&mut self, k: usize, sub: u8, b: &[u8]) -> Result<(), MasterError> {
        let bad = || MasterError::Usage(format!("0x{:04X}:{sub}: short reply", 0x8000 + k));
        let f =
            |b: &[u8]| -> Option<f32> { Some(f32::from_le_bytes(b.get(..4)?.try_into().ok()?)) };
        match sub {
            1 => self.r[k] = f(b).ok_or_else(bad)?,
            2 => self.kv[k] = f(b).ok_or_else(bad)?,
            3 => self.pgain[k] = f(b).ok_or_else(bad)?,
            4 => self.igain[k] = f(b).ok_or_else(bad)?,
            5 => self.ilimit[k] = f(b).ok_or_else(bad)?,
            6 => self.encdir[k] = *b.first().ok_or_else(bad)? as i8,
            7 => {
                self.encres[k] =
                    u16::from_le_bytes(b.get(..2).ok_or_else(bad)?.try_into().map_err(|_| bad())?)
            }
            _ => {
                self.czero[k] =
                    i16::from_le_bytes(b.get(..2).ok_or_else(bad)?.try_into().map_err(|_| bad())?)
            }
        }
        Ok(())
    }
}

/// Normal-mode inputs of one cycle (`txpdo1_t`, 64 bytes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct NormalIn {
    /// mstate per motor (bit 0 enabled, 1 fault, 2 OTW).
    pub mstate: [u8; 3],
    /// Encoder counts.
    pub count: [u32; 3],
    /// Encoder timestamps (40 MHz).
    pub timestamp: [u32; 3],
    /// Velocity \[0.1 rad/s\].
    pub velocity: [i16; 3],
    /// Current \[mA\].
    pub current: [i16; 3],
    /// Digital inputs.
    pub digital: u8,
    /// caliper1, caliper2, force1..3, pos1..3, analog1..2.
    pub analog: [u16; 10],
    /// Line voltage \[10 mV\].
    pub linevoltage: u16,
    /// 1 kHz tick counter.
    pub ectime: u16,
}

fn u16at(b: &[u8], o: usize) -> u16 {
    b.get(o..o + 2)
        .map(|x| u16::from_le_bytes([x[0], x[1]]))
        .unwrap_or(0)
}
fn u32at(b: &[u8], o: usize) -> u32 {
    b.get(o..o + 4)
        .map(|x| u32::from_le_bytes([x[0], x[1], x[2], x[3]]))
        .unwrap_or(0)
}

impl NormalIn {
    /// Decodes the 64-byte input image (short images read as zeros).
    pub fn decode(b: &[u8]) -> Self {
        let mut s = Self::default();
        for k in 0..3 {
            let o = 13 * k;
            s.mstate[k] = b.get(o).copied().unwrap_or(0);
            s.count[k] = u32at(b, o + 1);
            s.timestamp[k] = u32at(b, o + 5);
            s.velocity[k] = u16at(b, o + 9) as i16;
            s.current[k] = u16at(b, o + 11) as i16;
        }
        s.digital = b.get(39).copied().unwrap_or(0);
        for j in 0..10 {
            s.analog[j] = u16at(b, 40 + 2 * j);
        }
        s.linevoltage = u16at(b, 60);
        s.ectime = u16at(b, 62);
        s
    }
}

/// Normal-mode outputs (`rxpdo1_t`, 20 bytes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct NormalOut {
    /// mcom per motor (0 braked, 1 controlled, 2 tristate).
    pub mcom: [u8; 3],
    /// Current setpoints \[mA\].
    pub setpoint: [i16; 3],
    /// Voltage feed-forward \[10 mV\].
    pub ff: [i16; 3],
    /// Digital outputs (bits 0–3).
    pub digital: u8,
    /// DAC outputs (−2048..2047).
    pub aout: [i16; 2],
}

impl NormalOut {
    /// Encodes into the 20-byte output image.
    pub fn encode(&self, b: &mut [u8]) {
        if b.len() < 20 {
            return;
        }
        for k in 0..3 {
            let o = 5 * k;
            b[o] = self.mcom[k];
            b[o + 1..o + 3].copy_from_slice(&self.setpoint[k].to_le_bytes());
            b[o + 3..o + 5].copy_from_slice(&self.ff[k].to_le_bytes());
        }
        b[15] = self.digital;
        b[16..18].copy_from_slice(&self.aout[0].to_le_bytes());
        b[18..20].copy_from_slice(&self.aout[1].to_le_bytes());
    }
}

const FRF_N: usize = 22;

/// Reads the running assignment (0x1C12:01, 0x1C13:01).
pub fn mode(m: &Master, position: usize) -> Result<Option<TueMode>, MasterError> {
    let rx = m.sdo_upload(position, 0x1C12, 1)?;
    let tx = m.sdo_upload(position, 0x1C13, 1)?;
    let (rx, tx) = (u16at(&rx, 0), u16at(&tx, 0));
    Ok([TueMode::Normal, TueMode::Frf]
        .into_iter()
        .find(|md| md.pdos() == (rx, tx)))
}

/// `ec_Set_TUeES030mode`: if the board is not in `target`, brings the slaves to PRE-OP,
/// writes 0x1C12/0x1C13 (sub 0 = 0, sub 1, sub 0 = 1), reads them back, and opens a new
/// master on `link` (ethercrab's group is configured once, so "remap" is a new discovery;
/// the board keeps its assignment through INIT). Returns the master to use and whether
/// it switched. The next cyclic run brings the slaves to SAFE-OP and OP with the new
/// process data.
pub fn set_mode(
    link: &Link,
    mut m: Master,
    position: usize,
    target: TueMode,
) -> Result<(Master, bool), MasterError> {
    if mode(&m, position)? == Some(target) {
        log::info!("slave {position} is already in the correct mode");
        return Ok((m, false));
    }
    let all: Vec<usize> = (0..m.len()).collect();
    m.request_state(&all, oxicat_master::AlState::PreOp)?;
    let (rx, tx) = target.pdos();
    m.sdo_download(position, 0x1C12, 0, &[0])?;
    m.sdo_download(position, 0x1C12, 1, &rx.to_le_bytes())?;
    m.sdo_download(position, 0x1C12, 0, &[1])?;
    m.sdo_download(position, 0x1C13, 0, &[0])?;
    m.sdo_download(position, 0x1C13, 1, &tx.to_le_bytes())?;
    m.sdo_download(position, 0x1C13, 0, &[1])?;
    if mode(&m, position)? != Some(target) {
        return Err(MasterError::Usage(format!(
            "slave {position} did not switch mode"
        )));
    }
    drop(m);
    let m = Master::open(link.clone())?;
    Ok((m, true))
}

/// `ec_Set_TUeES030params` for every subindex 1–8: writes each channel's value and reads
/// it back; returns what the board holds afterwards.
pub fn write_params(m: &Master, position: usize, p: &TueParams) -> Result<TueParams, MasterError> {
    let mut back = p.clone();
    for sub in 1..=8u8 {
        for k in 0..3 {
            let idx = 0x8000 + k as u16;
            m.sdo_download(position, idx, sub, &p.encode(k, sub))?;
            let b = m.sdo_upload(position, idx, sub)?;
            back.decode(k, sub, &b)?;
        }
    }
    Ok(back)
}

/// Reads the motor parameters.
pub fn read_params(m: &Master, position: usize) -> Result<TueParams, MasterError> {
    let mut p = TueParams::default();
    for sub in 1..=8u8 {
        for k in 0..3 {
            let b = m.sdo_upload(position, 0x8000 + k as u16, sub)?;
            p.decode(k, sub, &b)?;
        }
    }
    Ok(p)
}

/// One normal-mode cycle as recorded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NormalRow {
    /// Cycle.
    pub cycle: u64,
    /// Time \[s\].
    pub time: f64,
    /// What came back.
    pub input: NormalIn,
    /// What was sent.
    pub output: NormalOut,
}

/// The normal 1 kHz cycle: `control(cycle, inputs)` gives the outputs of the next cycle;
/// runs `cycles` cycles in OP and records every one.
pub fn run_normal(
    m: &mut Master,
    position: usize,
    cycles: u64,
    mut control: impl FnMut(u64, &NormalIn) -> NormalOut,
) -> Result<Vec<NormalRow>, MasterError> {
    let mut rows = Vec::with_capacity(cycles as usize);
    m.run_cyclic(CycleOptions::default(), |io| {
        let inp = NormalIn::decode(io.inputs.get(position).map(|v| &v[..]).unwrap_or(&[]));
        let out = control(io.cycle, &inp);
        if let Some(o) = io.outputs.get_mut(position) {
            out.encode(o);
        }
        rows.push(NormalRow {
            cycle: io.cycle,
            time: io.time_ns as f64 * 1e-9,
            input: inp,
            output: out,
        });
        Ok(if io.cycle + 1 >= cycles {
            Flow::Stop
        } else {
            Flow::Continue
        })
    })?;
    Ok(rows)
}

/// CSV of a normal-mode run: cycle, time, then per motor mcom, setpoint, count, velocity,
/// current, and the line voltage. Scaled columns are in the units the device declares
/// (setpoint and current in A, velocity in rad/s, line voltage in V), with the decimals of
/// one raw step.
pub fn normal_csv(rows: &[NormalRow]) -> String {
    use oxicat_master::value::format_scaled;
    let sc = |index: u16, sub: u8| {
        super::device::DEF
            .scale(index, sub)
            .expect("the TUeES030 declares this entry's unit")
    };
    let (setpoint, velocity, current) = (sc(0x7000, 2), sc(0x6000, 4), sc(0x6000, 5));
    let line = sc(0x6010, 12);
    let mut h = vec!["cycle".to_string(), "time [s]".into()];
    for k in 1..=3 {
        h.extend([
            format!("mcom{k}"),
            format!("setpoint{k} [{}]", setpoint.unit),
            format!("count{k}"),
            format!("timestamp{k}"),
            format!("velocity{k} [{}]", velocity.unit),
            format!("current{k} [{}]", current.unit),
        ]);
    }
    h.extend([format!("linevoltage [{}]", line.unit), "ectime".into()]);
    let body = rows.iter().map(|r| {
        let mut f = vec![r.cycle.to_string(), format!("{:.6}", r.time)];
        for k in 0..3 {
            f.extend([
                r.output.mcom[k].to_string(),
                format_scaled(r.output.setpoint[k].into(), &setpoint),
                r.input.count[k].to_string(),
                r.input.timestamp[k].to_string(),
                format_scaled(r.input.velocity[k].into(), &velocity),
                format_scaled(r.input.current[k].into(), &current),
            ]);
        }
        f.extend([
            format_scaled(r.input.linevoltage.into(), &line),
            r.input.ectime.to_string(),
        ]);
        f
    });
    crate::csv_text(std::iter::once(h).chain(body)).expect("fixed columns")
}

/// The manual's flow control: entries to send for the fill level `buf`.
pub const fn frf_entries(buf: u8) -> usize {
    if buf < 50 {
        22
    } else if buf == 50 {
        20
    } else {
        18
    }
}

/// An FRF run.
#[derive(Debug, Clone, PartialEq)]
pub struct FrfRun {
    /// Setpoints sent \[mA\] (20 kHz samples).
    pub setpoints: Vec<i16>,
    /// Currents received \[mA\], one per consumed setpoint.
    pub currents: Vec<i16>,
    /// Buffer fill level reported each cycle.
    pub buffer: Vec<u8>,
    /// Cycles run.
    pub cycles: u64,
}

impl FrfRun {
    /// True when as many currents came back as setpoints were sent.
    pub fn complete(&self) -> bool {
        self.currents.len() == self.setpoints.len()
    }
}

/// Streams `setpoints` to motor `channel` (0-based) in FRF mode (`mcom` = channel |
/// enable), with the manual's flow control, and collects the measured currents.
pub fn run_frf(
    m: &mut Master,
    position: usize,
    channel: u8,
    setpoints: &[i16],
    progress: &mut dyn FnMut(usize, usize),
) -> Result<FrfRun, MasterError> {
    let n = setpoints.len();
    let warm = 10u64;
    let limit = warm + (n as u64) / 18 + 200;
    let mut run = FrfRun {
        setpoints: setpoints.to_vec(),
        currents: Vec::with_capacity(n),
        buffer: Vec::new(),
        cycles: 0,
    };
    let mut sent = 0usize;
    let mcom = (channel & 0x03) | 0x04;
    m.run_cyclic(CycleOptions::default(), |io| {
        let inp = io.inputs.get(position).cloned().unwrap_or_default();
        let buf = inp.get(1).copied().unwrap_or(0);
        let got = (inp.get(2).copied().unwrap_or(0) as usize).min(FRF_N);
        if io.cycle >= warm {
            for j in 0..got {
                run.currents.push(u16at(&inp, 5 + 2 * j) as i16);
            }
            run.buffer.push(buf);
        }
        let go = io.cycle >= warm;
        let entries = if go {
            frf_entries(buf).min(n - sent)
        } else {
            0
        };
        if let Some(o) = io.outputs.get_mut(position) {
            if o.len() >= 46 {
                o[0] = mcom;
                o[1] = entries as u8;
                for j in 0..FRF_N {
                    let v = if j < entries { setpoints[sent + j] } else { 0 };
                    o[2 + 2 * j..4 + 2 * j].copy_from_slice(&v.to_le_bytes());
                }
            }
        }
        sent += entries;
        run.cycles = io.cycle + 1;
        progress(run.currents.len(), n);
        Ok(if run.currents.len() >= n || io.cycle >= limit {
            Flow::Stop
        } else {
            Flow::Continue
        })
    })?;
    Ok(run)
}

/// A multisine: `periods` periods of `period` samples at 20 kHz, lines log-spaced between
/// `f_lo` and `f_hi` (distinct DFT bins), Schroeder phases, peak-normalised to `amp_ma`.
/// Returns the samples and the excited bins.
pub fn multisine(
    period: usize,
    periods: usize,
    f_lo: f64,
    f_hi: f64,
    lines: usize,
    amp_ma: f64,
) -> (Vec<i16>, Vec<usize>) {
    let fs = 20_000.0;
    let df = fs / period as f64;
    let mut bins: Vec<usize> = (0..lines)
        .map(|j| {
            let f = f_lo * (f_hi / f_lo).powf(j as f64 / (lines.max(2) - 1) as f64);
            ((f / df).round() as usize).clamp(1, period / 2 - 1)
        })
        .collect();
    bins.dedup();
    let nl = bins.len() as f64;
    let one: Vec<f64> = (0..period)
        .map(|t| {
            bins.iter()
                .enumerate()
                .map(|(j, &b)| {
                    let ph = -std::f64::consts::PI * (j as f64) * (j as f64 + 1.0) / nl;
                    (2.0 * std::f64::consts::PI * b as f64 * t as f64 / period as f64 + ph).cos()
                })
                .sum()
        })
        .collect();
    let peak = one.iter().fold(0.0f64, |a, &x| a.max(x.abs())).max(1e-9);
    let mut out = Vec::with_capacity(period * periods);
    for _ in 0..periods {
        out.extend(one.iter().map(|&x| (x / peak * amp_ma).round() as i16));
    }
    (out, bins)
}

/// One line of a frequency response.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrfPoint {
    /// Frequency \[Hz\].
    pub f: f64,
    /// Closed loop T = Y/R (measured current over setpoint).
    pub t: (f64, f64),
    /// Loop gain L = T/(1 − T) (the manual's LRR).
    pub l: (f64, f64),
}

impl FrfPoint {
    /// |T| in dB.
    pub fn t_db(&self) -> f64 {
        20.0 * self.t.0.hypot(self.t.1).log10()
    }
    /// Phase of T in degrees.
    pub fn t_deg(&self) -> f64 {
        self.t.1.atan2(self.t.0).to_degrees()
    }
    /// |L| in dB.
    pub fn l_db(&self) -> f64 {
        20.0 * self.l.0.hypot(self.l.1).log10()
    }
}

fn dft(x: &[f64], bin: usize, n: usize) -> (f64, f64) {
    let (mut re, mut im) = (0.0, 0.0);
    for (t, &v) in x.iter().enumerate() {
        let a = -2.0 * std::f64::consts::PI * (bin * (t % n)) as f64 / n as f64;
        re += v * a.cos();
        im += v * a.sin();
    }
    (re, im)
}

fn cdiv(a: (f64, f64), b: (f64, f64)) -> (f64, f64) {
    let d = b.0 * b.0 + b.1 * b.1;
    ((a.0 * b.0 + a.1 * b.1) / d, (a.1 * b.0 - a.0 * b.1) / d)
}

/// The closed-loop response at the excited `bins`, averaging all periods after the first
/// (transient) one.
pub fn frequency_response(run: &FrfRun, period: usize, bins: &[usize]) -> Vec<FrfPoint> {
    let n = run.currents.len().min(run.setpoints.len());
    let periods = n / period;
    if periods < 2 {
        return Vec::new();
    }
    let r: Vec<f64> = run.setpoints[period..periods * period]
        .iter()
        .map(|&v| v as f64)
        .collect();
    let y: Vec<f64> = run.currents[period..periods * period]
        .iter()
        .map(|&v| v as f64)
        .collect();
    bins.iter()
        .map(|&b| {
            let t = cdiv(dft(&y, b, period), dft(&r, b, period));
            let l = cdiv(t, (1.0 - t.0, -t.1));
            FrfPoint {
                f: b as f64 * 20_000.0 / period as f64,
                t,
                l,
            }
        })
        .collect()
}

/// Share of the measured current's energy (periods after the first) that lies **outside**
/// the excited lines: near 0 for a stable linear loop (quantisation only), large for a
/// limit cycle or an unstable, saturating loop.
pub fn unexcited_share(run: &FrfRun, period: usize, bins: &[usize]) -> f64 {
    let n = run.currents.len().min(run.setpoints.len());
    let periods = n / period;
    let (mut on, mut off) = (0.0, 0.0);
    for p in 1..periods {
        let y: Vec<f64> = run.currents[p * period..(p + 1) * period]
            .iter()
            .map(|&v| v as f64)
            .collect();
        for k in 1..period / 2 {
            let (re, im) = dft(&y, k, period);
            let e = re * re + im * im;
            if bins.contains(&k) {
                on += e;
            } else {
                off += e;
            }
        }
    }
    if on + off > 0.0 {
        off / (on + off)
    } else {
        0.0
    }
}

/// Bandwidth, crossover and phase margin from a response.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Margins {
    /// First frequency where |T| falls below −3 dB \[Hz\] (None: not within the lines).
    pub bandwidth: Option<f64>,
    /// Peak of |T| \[dB\].
    pub peak_db: f64,
    /// Crossover of the loop gain |L| = 1 \[Hz\].
    pub crossover: Option<f64>,
    /// Phase margin at the crossover \[deg\].
    pub phase_margin: Option<f64>,
}

/// Finds the margins (log-linear interpolation between lines).
pub fn margins(pts: &[FrfPoint]) -> Margins {
    let mut out = Margins {
        bandwidth: None,
        peak_db: pts.iter().map(|p| p.t_db()).fold(f64::MIN, f64::max),
        crossover: None,
        phase_margin: None,
    };
    let interp = |a: &FrfPoint, b: &FrfPoint, ya: f64, yb: f64, y: f64| {
        let s = if yb != ya { (y - ya) / (yb - ya) } else { 0.0 };
        (a.f.ln() + s * (b.f.ln() - a.f.ln())).exp()
    };
    for w in pts.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        if out.bandwidth.is_none() && a.t_db() >= -3.0 && b.t_db() < -3.0 {
            out.bandwidth = Some(interp(a, b, a.t_db(), b.t_db(), -3.0));
        }
        if out.crossover.is_none() && a.l_db() >= 0.0 && b.l_db() < 0.0 {
            let fc = interp(a, b, a.l_db(), b.l_db(), 0.0);
            let s = (fc.ln() - a.f.ln()) / (b.f.ln() - a.f.ln());
            // Phase of L interpolated (unwrapped between the two lines).
            let pa = a.l.1.atan2(a.l.0);
            let mut pb = b.l.1.atan2(b.l.0);
            while pb - pa > std::f64::consts::PI {
                pb -= 2.0 * std::f64::consts::PI;
            }
            while pb - pa < -std::f64::consts::PI {
                pb += 2.0 * std::f64::consts::PI;
            }
            let ph = (pa + s * (pb - pa)).to_degrees();
            let mut pm = 180.0 + ph;
            while pm > 180.0 {
                pm -= 360.0;
            }
            while pm < -180.0 {
                pm += 360.0;
            }
            out.crossover = Some(fc);
            out.phase_margin = Some(pm);
        }
    }
    out
}

/// Writes the Bode plot of T (and L dashed) as PNG and SVG: `<stem>.png`, `<stem>.svg`.
pub fn plot_bode(
    curves: &[(&str, &[FrfPoint])],
    dir: &Path,
    stem: &str,
    title: &str,
) -> Result<Vec<PathBuf>, MasterError> {
    crate::laelaps::plot::font_ready()?;
    let png = dir.join(format!("{stem}.png"));
    let svg = dir.join(format!("{stem}.svg"));
    let err = |e: Box<dyn std::error::Error>| MasterError::Usage(format!("plot {stem}: {e}"));
    {
        let root = plotters::prelude::BitMapBackend::new(&png, (1000, 760));
        draw_bode(root, curves, title).map_err(err)?;
    }
    {
        let root = plotters::prelude::SVGBackend::new(&svg, (1000, 760));
        draw_bode(root, curves, title).map_err(err)?;
    }
    Ok(vec![png, svg])
}

fn draw_bode<DB: plotters::prelude::DrawingBackend>(
    backend: DB,
    curves: &[(&str, &[FrfPoint])],
    title: &str,
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    use plotters::prelude::*;
    let root = backend.into_drawing_area();
    root.fill(&WHITE)?;
    let root = root.titled(title, ("sans-serif", 22))?;
    let (top, bot) = root.split_vertically(360);
    let f0 = curves
        .iter()
        .flat_map(|c| c.1.iter().map(|p| p.f))
        .fold(f64::MAX, f64::min)
        .min(1e4);
    let f1 = curves
        .iter()
        .flat_map(|c| c.1.iter().map(|p| p.f))
        .fold(1.0, f64::max);
    let colors = [BLUE, RED, GREEN, MAGENTA];
    let mut ch = ChartBuilder::on(&top)
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(55)
        .build_cartesian_2d((f0..f1).log_scale(), -30.0f64..15.0)?;
    ch.configure_mesh()
        .x_desc("frequency [Hz]")
        .y_desc("|T| [dB]")
        .draw()?;
    for (k, (name, pts)) in curves.iter().enumerate() {
        let c = colors[k % colors.len()];
        ch.draw_series(LineSeries::new(
            pts.iter().map(|p| (p.f, p.t_db().clamp(-30.0, 15.0))),
            c.stroke_width(2),
        ))?
        .label(*name)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
    }
    ch.draw_series(LineSeries::new([(f0, -3.0), (f1, -3.0)], BLACK.mix(0.4)))?;
    ch.configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    let mut ch = ChartBuilder::on(&bot)
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(55)
        .build_cartesian_2d((f0..f1).log_scale(), -360.0f64..30.0)?;
    ch.configure_mesh()
        .x_desc("frequency [Hz]")
        .y_desc("phase T [deg]")
        .draw()?;
    for (k, (_, pts)) in curves.iter().enumerate() {
        let c = colors[k % colors.len()];
        let mut prev = 0.0f64;
        let unwrapped: Vec<(f64, f64)> = pts
            .iter()
            .map(|p| {
                let mut ph = p.t_deg();
                while ph - prev > 180.0 {
                    ph -= 360.0;
                }
                while ph - prev < -180.0 {
                    ph += 360.0;
                }
                prev = ph;
                (p.f, ph.clamp(-360.0, 30.0))
            })
            .collect();
        ch.draw_series(LineSeries::new(unwrapped, c.stroke_width(2)))?;
    }
    root.present()?;
    Ok(())
}

// ---- Time domain (manual §6.3, Figs. 6.5–6.8) -------------------------------------------

/// A current pulse at 20 kHz: `pre` samples at 0, `on` at `amp_ma`, `post` at 0 (the
/// manual's "pulse signal ... a single part of this pulse ... seen as a step response").
pub fn pulse(pre: usize, on: usize, post: usize, amp_ma: i16) -> Vec<i16> {
    let mut v = vec![0; pre + on + post];
    v[pre..pre + on].fill(amp_ma);
    v
}

/// What a step response shows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepMetrics {
    /// Setpoint of the step \[mA\].
    pub setpoint_ma: f64,
    /// Mean current over the last quarter of the step \[mA\].
    pub final_ma: f64,
    /// Highest current during the step \[mA\].
    pub peak_ma: f64,
    /// (peak − final)/final \[%\].
    pub overshoot_pct: f64,
    /// 10 → 90 % of the final value \[s\] (None: never reached).
    pub rise_s: Option<f64>,
    /// Setpoint − final \[mA\]: the steady-state error.
    pub error_ma: f64,
    /// RMS deviation from the final value over the second half of the step \[mA\]: an
    /// oscillating (unstable) loop has a large one.
    pub ripple_ma: f64,
}

impl StepMetrics {
    /// The loop oscillates: a ripple above 10 % of the setpoint in the step's second half.
    pub fn unstable(&self) -> bool {
        self.ripple_ma > 0.1 * self.setpoint_ma.abs()
    }
}

/// The metrics of the first step (first non-zero setpoint to the next change) of a run.
pub fn step_metrics(setpoints: &[i16], currents: &[i16]) -> Option<StepMetrics> {
    let n = setpoints.len().min(currents.len());
    let k0 = setpoints[..n].iter().position(|&s| s != 0)?;
    let sp = setpoints[k0];
    let k1 = k0
        + setpoints[k0..n]
            .iter()
            .position(|&s| s != sp)
            .unwrap_or(n - k0);
    let on: Vec<f64> = currents[k0..k1].iter().map(|&c| c as f64).collect();
    if on.len() < 8 {
        return None;
    }
    let q = on.len() * 3 / 4;
    let fin = on[q..].iter().sum::<f64>() / (on.len() - q) as f64;
    let sign = if sp < 0 { -1.0 } else { 1.0 };
    let peak = on.iter().map(|c| c * sign).fold(f64::MIN, f64::max) * sign;
    let h = on.len() / 2;
    let ripple =
        (on[h..].iter().map(|c| (c - fin).powi(2)).sum::<f64>() / (on.len() - h) as f64).sqrt();
    let first = |frac: f64| on.iter().position(|&c| c * sign >= frac * fin * sign);
    let rise = match (first(0.1), first(0.9)) {
        (Some(a), Some(b)) if fin * sign > 0.0 => Some((b - a) as f64 / 20_000.0),
        _ => None,
    };
    Some(StepMetrics {
        setpoint_ma: sp as f64,
        final_ma: fin,
        peak_ma: peak,
        overshoot_pct: if fin != 0.0 {
            (peak - fin) / fin * 100.0
        } else {
            0.0
        },
        rise_s: rise,
        error_ma: sp as f64 - fin,
        ripple_ma: ripple,
    })
}

/// CSV of step responses: `time [s]` from the step, the setpoint, then one current column
/// per run (named by its label), in A; `from`..`to` are sample indices of the runs.
pub fn step_csv(runs: &[(String, &FrfRun)], step_at: usize, from: usize, to: usize) -> String {
    use oxicat_master::value::format_scaled;
    let cur = super::device::DEF
        .scale(0x6000, 5)
        .expect("the TUeES030 declares the current's unit");
    let mut h = vec!["time [s]".to_string(), format!("setpoint [{}]", cur.unit)];
    h.extend(
        runs.iter()
            .map(|(l, _)| format!("current {l} [{}]", cur.unit)),
    );
    let sp = runs.first().map(|r| &r.1.setpoints[..]).unwrap_or(&[]);
    let body = (from..to).map(|k| {
        let mut f = vec![
            format!("{:.5}", (k as f64 - step_at as f64) / 20_000.0),
            format_scaled(sp.get(k).copied().unwrap_or(0).into(), &cur),
        ];
        f.extend(runs.iter().map(|(_, r)| match r.currents.get(k) {
            Some(&c) => format_scaled(c.into(), &cur),
            None => String::new(),
        }));
        f
    });
    crate::csv_text(std::iter::once(h).chain(body)).expect("fixed columns")
}

/// The velocity trajectory of the back-EMF test \[rad/s\] at `t` seconds: 0.1 s at rest, a
/// 0.4 s ramp to 200 rad/s, 0.8 s there, a 0.4 s ramp down, then rest.
pub fn emf_trajectory(t: f64) -> f64 {
    let v = 200.0;
    if t < 0.1 {
        0.0
    } else if t < 0.5 {
        v * (t - 0.1) / 0.4
    } else if t < 1.3 {
        v
    } else if t < 1.7 {
        v * (1.7 - t) / 0.4
    } else {
        0.0
    }
}

/// Length of the back-EMF test \[cycles of 1 ms\].
pub const EMF_CYCLES: u64 = 2000;

/// The back-EMF feed-forward test (manual Fig. 6.8): a P velocity loop in the master
/// (`pv` in mA per 0.1 rad/s, the PDO's units; the manual's P_v = 1.0) follows
/// [`emf_trajectory`] on motor `channel` through current setpoints (clipped to ±3 A, the
/// channel's rating); every 1 ms cycle recorded.
pub fn run_velocity_loop(
    m: &mut Master,
    position: usize,
    channel: usize,
    pv: f64,
) -> Result<Vec<NormalRow>, MasterError> {
    let ch = channel.min(2);
    run_normal(m, position, EMF_CYCLES, |k, inp| {
        let mut o = NormalOut::default();
        let t = k as f64 * 1e-3;
        let e = emf_trajectory(t) * 10.0 - inp.velocity[ch] as f64;
        o.mcom[ch] = super::MCOM_ENABLE;
        o.setpoint[ch] = (pv * e).clamp(-3000.0, 3000.0) as i16;
        o
    })
}

/// RMS velocity error of a back-EMF run against [`emf_trajectory`] \[rad/s\] (the
/// velocity each cycle reports against the reference its setpoint was computed for).
pub fn emf_rms_error(rows: &[NormalRow], channel: usize) -> f64 {
    let ch = channel.min(2);
    let n = rows.len().max(1) as f64;
    (rows
        .iter()
        .map(|r| {
            (emf_trajectory(r.cycle as f64 * 1e-3) - r.input.velocity[ch] as f64 * 0.1).powi(2)
        })
        .sum::<f64>()
        / n)
        .sqrt()
}

/// CSV of back-EMF runs: `time [s]`, the reference velocity, then per run its velocity,
/// current setpoint and current, in the device's units.
pub fn emf_csv(runs: &[(String, &[NormalRow])], channel: usize) -> String {
    use oxicat_master::value::format_scaled;
    let ch = channel.min(2);
    let sc = |index: u16, sub: u8| {
        super::device::DEF
            .scale(index, sub)
            .expect("the TUeES030 declares this entry's unit")
    };
    let (sp, vel, cur) = (sc(0x7000, 2), sc(0x6000, 4), sc(0x6000, 5));
    let mut h = vec![
        "time [s]".to_string(),
        format!("velocity reference [{}]", vel.unit),
    ];
    for (l, _) in runs {
        h.extend([
            format!("velocity {l} [{}]", vel.unit),
            format!("setpoint {l} [{}]", sp.unit),
            format!("current {l} [{}]", cur.unit),
        ]);
    }
    let n = runs.iter().map(|r| r.1.len()).min().unwrap_or(0);
    let body = (0..n).map(|k| {
        let t = runs[0].1[k].cycle as f64 * 1e-3;
        let mut f = vec![format!("{t:.3}"), format!("{:.1}", emf_trajectory(t))];
        for (_, rows) in runs {
            let r = &rows[k];
            f.extend([
                format_scaled(r.input.velocity[ch].into(), &vel),
                format_scaled(r.output.setpoint[ch].into(), &sp),
                format_scaled(r.input.current[ch].into(), &cur),
            ]);
        }
        f
    });
    crate::csv_text(std::iter::once(h).chain(body)).expect("fixed columns")
}

/// One curve of a time plot.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend.
    pub name: String,
    /// (x, y) points.
    pub points: Vec<(f64, f64)>,
    /// Drawn thin and black (a reference or setpoint).
    pub reference: bool,
}

/// One panel of a time plot: its y label and curves.
#[derive(Debug, Clone, PartialEq)]
pub struct Panel {
    /// y-axis label with unit.
    pub y_desc: String,
    /// Curves.
    pub series: Vec<Series>,
}

/// Writes panels stacked over one x axis as `<stem>.png` and `<stem>.svg`.
pub fn plot_time(
    panels: &[Panel],
    x_desc: &str,
    dir: &Path,
    stem: &str,
    title: &str,
) -> Result<Vec<PathBuf>, MasterError> {
    crate::laelaps::plot::font_ready()?;
    let png = dir.join(format!("{stem}.png"));
    let svg = dir.join(format!("{stem}.svg"));
    let err = |e: Box<dyn std::error::Error>| MasterError::Usage(format!("plot {stem}: {e}"));
    let h = 120 + 330 * panels.len() as u32;
    {
        let root = plotters::prelude::BitMapBackend::new(&png, (1000, h));
        draw_time(root, panels, x_desc, title).map_err(err)?;
    }
    {
        let root = plotters::prelude::SVGBackend::new(&svg, (1000, h));
        draw_time(root, panels, x_desc, title).map_err(err)?;
    }
    Ok(vec![png, svg])
}

fn draw_time<DB: plotters::prelude::DrawingBackend>(
    backend: DB,
    panels: &[Panel],
    x_desc: &str,
    title: &str,
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    use plotters::prelude::*;
    let root = backend.into_drawing_area();
    root.fill(&WHITE)?;
    let root = root.titled(title, ("sans-serif", 22))?;
    let areas = root.split_evenly((panels.len().max(1), 1));
    let colors = [BLUE, RED, GREEN, MAGENTA, CYAN, RGBColor(255, 140, 0)];
    for (panel, area) in panels.iter().zip(areas) {
        let all = || panel.series.iter().flat_map(|s| s.points.iter());
        let (x0, x1) = all().fold((f64::MAX, f64::MIN), |a, p| (a.0.min(p.0), a.1.max(p.0)));
        let (y0, y1) = all().fold((f64::MAX, f64::MIN), |a, p| (a.0.min(p.1), a.1.max(p.1)));
        if x0 >= x1 {
            continue;
        }
        let pad = ((y1 - y0) * 0.08).max(1e-3);
        let mut ch = ChartBuilder::on(&area)
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(60)
            .build_cartesian_2d(x0..x1, (y0 - pad)..(y1 + pad))?;
        ch.configure_mesh()
            .x_desc(x_desc)
            .y_desc(panel.y_desc.as_str())
            .draw()?;
        let mut k = 0;
        for s in &panel.series {
            let style = if s.reference {
                BLACK.stroke_width(1)
            } else {
                k += 1;
                colors[(k - 1) % colors.len()].stroke_width(2)
            };
            let c = style.color;
            ch.draw_series(LineSeries::new(s.points.iter().copied(), style))?
                .label(s.name.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
        }
        ch.configure_series_labels()
            .position(SeriesLabelPosition::LowerRight)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
    }
    root.present()?;
    Ok(())
}

/// A Welch estimate as closed-loop response points (T = H1, L = T/(1 − T)), with the
/// coherence of each line.
pub fn welch_response(
    run: &FrfRun,
    nfft: usize,
    overlap: usize,
) -> Result<Vec<(FrfPoint, f64)>, super::ident::WelchError> {
    let n = run.currents.len().min(run.setpoints.len());
    let r: Vec<f64> = run.setpoints[..n].iter().map(|&v| v as f64).collect();
    let y: Vec<f64> = run.currents[..n].iter().map(|&v| v as f64).collect();
    Ok(super::ident::welch(&r, &y, nfft, overlap, 20_000.0)?
        .into_iter()
        .map(|s| {
            let t = s.h;
            let l = cdiv(t, (1.0 - t.0, -t.1));
            (FrfPoint { f: s.f, t, l }, s.coherence)
        })
        .collect())
}

/// A plant estimate: (frequency \[Hz\], H \[A/V\]) per line.
pub type PlantPoints = Vec<(f64, (f64, f64))>;

/// The plant estimate H = L/C (manual eq. 6.17) of response points, with C the firmware's
/// PI of the integer gains `pgain`, `igain` at `line_v` volts.
pub fn plant_estimate(
    pts: &[FrfPoint],
    pgain: i32,
    igain: i32,
    line_v: f64,
) -> Vec<(f64, (f64, f64))> {
    pts.iter()
        .map(|p| {
            let c = super::ident::controller(p.f, pgain, igain, line_v);
            (p.f, cdiv(p.l, c))
        })
        .collect()
}

/// Bode plot of plant estimates against the model (manual Fig. 6.4): `<stem>.png/.svg`.
pub fn plot_plant(
    estimates: &[(String, PlantPoints)],
    model: &super::ident::PlantModel,
    dir: &Path,
    stem: &str,
    title: &str,
) -> Result<Vec<PathBuf>, MasterError> {
    let db = |h: (f64, f64)| 20.0 * h.0.hypot(h.1).log10();
    let fs: Vec<f64> = estimates
        .iter()
        .flat_map(|e| e.1.iter().map(|p| p.0))
        .collect();
    let (f0, f1) = fs
        .iter()
        .fold((f64::MAX, f64::MIN), |a, &f| (a.0.min(f), a.1.max(f)));
    if f0 >= f1 {
        return Ok(Vec::new());
    }
    let grid: Vec<f64> = (0..200)
        .map(|k| f0 * (f1 / f0).powf(k as f64 / 199.0))
        .collect();
    let unwrap = |pts: &mut dyn Iterator<Item = (f64, (f64, f64))>| {
        let mut prev = 0.0f64;
        pts.map(|(f, h)| {
            let mut ph = h.1.atan2(h.0).to_degrees();
            while ph - prev > 180.0 {
                ph -= 360.0;
            }
            while ph - prev < -180.0 {
                ph += 360.0;
            }
            prev = ph;
            (f.log10(), ph)
        })
        .collect::<Vec<_>>()
    };
    let mut mag = Vec::new();
    let mut ph = Vec::new();
    for (name, e) in estimates {
        mag.push(Series {
            name: name.clone(),
            points: e.iter().map(|&(f, h)| (f.log10(), db(h))).collect(),
            reference: false,
        });
        ph.push(Series {
            name: name.clone(),
            points: unwrap(&mut e.iter().copied()),
            reference: false,
        });
    }
    let m: Vec<(f64, (f64, f64))> = grid.iter().map(|&f| (f, model.h(f))).collect();
    mag.push(Series {
        name: "model M·LP·delay".into(),
        points: m.iter().map(|&(f, h)| (f.log10(), db(h))).collect(),
        reference: true,
    });
    ph.push(Series {
        name: "model M·LP·delay".into(),
        points: unwrap(&mut m.iter().copied()),
        reference: true,
    });
    plot_time(
        &[
            Panel {
                y_desc: "|H| [dB A/V]".into(),
                series: mag,
            },
            Panel {
                y_desc: "phase H [deg]".into(),
                series: ph,
            },
        ],
        "log10(frequency [Hz])",
        dir,
        stem,
        title,
    )
}

/// Hard braking of M2 (the manual's §2.1 warning: "back EMF caused by braking can damage
/// the electronics"): from cycle 20 a velocity PI loop in the master (current setpoint
/// −1…3 A) spins M2 up to `speed`; at `brake_at` the setpoint jumps to `brake_ma` and
/// stays there until the measured speed is below `stop_speed`, then 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Braking {
    /// Speed before braking \[rad/s\].
    pub speed: f64,
    /// Braking current setpoint \[mA\] (negative: against the rotation).
    pub brake_ma: i16,
    /// Cycle of the brake command.
    pub brake_at: u64,
    /// Speed below which the brake is released \[rad/s\].
    pub stop_speed: f64,
    /// Cycles in all.
    pub cycles: u64,
}

impl Default for Braking {
    /// 400 rad/s, −5 A at cycle 300, released below 80 rad/s (the measured speed is a
    /// cycle or two late: lower would reverse the rotor), 500 cycles.
    fn default() -> Self {
        Self {
            speed: 400.0,
            brake_ma: -5000,
            brake_at: 300,
            stop_speed: 80.0,
            cycles: 500,
        }
    }
}

impl Braking {
    /// The master's control law of this experiment, for [`run_normal`].
    pub fn control(self) -> impl FnMut(u64, &NormalIn) -> NormalOut {
        // PI on the velocity: 0.02 A per rad/s (crossover ≈ 150 rad/s with the RE 30's
        // inertia, well inside the 1 kHz loop), integral 25 rad/s.
        let (kp, ki) = (0.02, 0.5);
        let mut integral = 0.0f64;
        let mut released = false;
        move |k, inp| {
            let mut o = NormalOut::default();
            if k < 20 {
                return o;
            }
            let w = inp.velocity[1] as f64 * 0.1;
            o.mcom[1] = MCOM_CONTROLLED;
            let i = if k < self.brake_at {
                let e = self.speed - w;
                integral = (integral + e * 1e-3).clamp(-2.0, 2.0);
                (kp * e + ki * integral).clamp(-1.0, 3.0)
            } else {
                released |= w < self.stop_speed;
                if released {
                    0.0
                } else {
                    self.brake_ma as f64 * 1e-3
                }
            };
            o.setpoint[1] = (i * 1000.0).round() as i16;
            o
        }
    }
}

/// Normal-mode `mcom`: controlled.
const MCOM_CONTROLLED: u8 = super::MCOM_ENABLE;

/// Reads 0x8040 "Internal voltages" (line, 5 V reference, line peak since reset, kill
/// threshold), in 10 mV.
pub fn internal_voltages(m: &Master, position: usize) -> Result<[u16; 4], MasterError> {
    let mut v = [0u16; 4];
    for (k, x) in v.iter_mut().enumerate() {
        let b = m.sdo_upload(position, 0x8040, k as u8 + 1)?;
        if b.len() < 2 {
            return Err(MasterError::Usage(format!(
                "0x8040:{}: short reply ({} bytes)",
                k + 1,
                b.len()
            )));
        }
        *x = u16at(&b, 0);
    }
    Ok(v)
}

/// CSV of a braking run (M2): cycle, time, mcom, setpoint, velocity, current, the line
/// voltage, mstate and its kill bit, in the units the device declares.
pub fn regen_csv(rows: &[NormalRow]) -> String {
    use oxicat_master::value::format_scaled;
    let sc = |index: u16, sub: u8| {
        super::device::DEF
            .scale(index, sub)
            .expect("the TUeES030 declares this entry's unit")
    };
    let (setpoint, velocity, current) = (sc(0x7001, 2), sc(0x6001, 4), sc(0x6001, 5));
    let line = sc(0x6010, 12);
    let h = vec![
        "cycle".to_string(),
        "time [s]".into(),
        "mcom2".into(),
        format!("setpoint2 [{}]", setpoint.unit),
        format!("velocity2 [{}]", velocity.unit),
        format!("current2 [{}]", current.unit),
        format!("linevoltage [{}]", line.unit),
        "mstate2".into(),
        "killed".into(),
    ];
    let body = rows.iter().map(|r| {
        vec![
            r.cycle.to_string(),
            format!("{:.6}", r.time),
            r.output.mcom[1].to_string(),
            format_scaled(r.output.setpoint[1].into(), &setpoint),
            format_scaled(r.input.velocity[1].into(), &velocity),
            format_scaled(r.input.current[1].into(), &current),
            format_scaled(r.input.linevoltage.into(), &line),
            r.input.mstate[1].to_string(),
            u8::from(r.input.mstate[1] & super::app::MSTATE_KILLED != 0).to_string(),
        ]
    });
    crate::csv_text(std::iter::once(h).chain(body)).expect("fixed columns")
}
