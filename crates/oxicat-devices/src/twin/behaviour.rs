//! What a twin's process data does: per device (`auto`, `loop`, `hold`, `drive`) and per
//! input entry (loop from an output, hold a value, or a signal generator), as a segment file
//! gives it; checked against the twin's dictionary before anything is built.
//!
//! | device `behaviour` | inputs |
//! |---|---|
//! | `auto` (default) | by profile: a CiA402 device (ESI `ProfileNo` 402 or 0x1000 low word 402, with a 16-bit 0x6040 and 0x6041) runs the drive; otherwise outputs loop to inputs where they pair up ([`oxicat_esi::twin::loop_pairs`]: digital I/O) and every other numeric input of 16 bits or more (an analog value) gets [`Signal::default_for`]: a 1 Hz sine over a quarter of the type's range; bits and bytes hold their ESI default |
//! | `loop` | the loop-back pairs; everything else holds its ESI default |
//! | `hold` | every input holds its ESI default |
//! | `drive` | the CiA402 drive (refused without a 16-bit 0x6040 and 0x6041) |
//!
//! Per entry, after the device's behaviour (so it overrides it, the drive's entries too):
//! `loop` (copy an output entry of the same bit length), `hold` (a value written once, when
//! the process data starts), `constant`, `sine`, `ramp`, `noise` or `csv` (written every
//! cycle). Signals are functions of the segment's virtual time `t` in seconds (0 when the
//! segment was made), never of wall time or of how many cycles ran, so a run is
//! reproducible: `noise` is a hash of its seed and `t`. Values are raw process-data numbers,
//! rounded and saturated to the entry's type (REAL entries take them as they are).

use std::path::PathBuf;
use std::sync::Arc;

use oxicat_slave::{DataType, DeviceDef, EntryDef};
use serde::Deserialize;

/// How a device's process data behaves (the `behaviour` key of a `[[device]]`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Mode {
    /// By profile (see the module table).
    #[default]
    Auto,
    /// Outputs looped to inputs where they pair up.
    Loop,
    /// Inputs keep their ESI defaults.
    Hold,
    /// The CiA402 drive on the default motor plant.
    Drive,
}

impl Mode {
    /// Parses `auto`, `loop`, `hold` or `drive`.
    pub fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "auto" => Self::Auto,
            "loop" => Self::Loop,
            "hold" => Self::Hold,
            "drive" => Self::Drive,
            _ => return None,
        })
    }
}

/// One `[[device.entry]]` of a segment file: the entry and exactly one behaviour.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EntrySpec {
    /// `INDEX:SUB` (`0x6000:0x11`, `#x6000:17`) or the entry's name in the dictionary
    /// (the object's name for a variable, else `OBJECT/ENTRY` or an entry name that is
    /// unique among the inputs).
    pub entry: String,
    /// Copy this output entry (`INDEX:SUB` or name) every cycle.
    #[serde(rename = "loop")]
    pub loop_from: Option<String>,
    /// Hold this value.
    pub hold: Option<f64>,
    /// This value, written every cycle.
    pub constant: Option<f64>,
    /// `offset + amplitude · sin(2π · frequency_hz · t + phase_deg)`.
    pub sine: Option<SineSpec>,
    /// `start + slope_per_s · t`, wrapping within `[min, max)` when both are given.
    pub ramp: Option<RampSpec>,
    /// `offset` ± `amplitude`, uniform, a function of `seed` and `t`.
    pub noise: Option<NoiseSpec>,
    /// Samples `time_s,value` from a CSV file, each held until the next.
    pub csv: Option<CsvSpec>,
    /// The count of an encoder on a motor plant ([`EncoderSpec`]).
    pub encoder: Option<EncoderSpec>,
}

/// See [`EntrySpec::encoder`]: an encoder count from a motor plant, a Maxon RE 30 (part
/// 310007) with a HEDL 5540 encoder (500 lines, 2000 counts per turn;
/// [`oxicat_plant::re30`]) on a full bridge, stepped every 50 µs of virtual time. Its
/// terminal voltage is `volts`, or output entry `from` times `volts_per_unit` (what the
/// master commands, held between cycles). The count wraps at the entry's width, as a
/// hardware counter does.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EncoderSpec {
    /// A constant terminal voltage \[V\].
    pub volts: Option<f64>,
    /// The output entry (`INDEX:SUB` or name) that sets the voltage.
    pub from: Option<String>,
    /// Volts per raw unit of `from` (default 1).
    pub volts_per_unit: Option<f64>,
    /// Bridge supply \[V\] (default 24, the motor's nominal voltage): the voltage saturates
    /// at ± this.
    pub supply: Option<f64>,
}

/// The terminal voltage of a checked encoder plant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Volts {
    /// Constant \[V\].
    Constant(f64),
    /// Output entry `(index, sub)` times volts per unit.
    From(u16, u8, f64),
}

/// A checked encoder plant ([`EncoderSpec`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Encoder {
    /// Terminal voltage.
    pub volts: Volts,
    /// Bridge supply \[V\].
    pub supply: f64,
}

impl Encoder {
    /// The plant of a twin's encoder input by default (an input named like a counter or a
    /// position): the motor at 2 V, about 740 rpm, 24,700 counts per second.
    pub const DEFAULT: Encoder = Encoder {
        volts: Volts::Constant(2.0),
        supply: 24.0,
    };

    /// Whether an input entry named `name` (object or entry name) is an encoder count by
    /// profile: an integer of 16 bits or more whose name says counter value or position.
    pub fn by_name(name: &str, dtype: DataType, bits: u16) -> bool {
        let n = name.to_ascii_lowercase();
        dtype.is_integer()
            && bits >= 16
            && (n.contains("counter value") || n.contains("position") || n.contains("encoder"))
    }
}

/// See [`EntrySpec::sine`].
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SineSpec {
    /// Amplitude (raw units).
    pub amplitude: f64,
    /// Frequency \[Hz\].
    pub frequency_hz: f64,
    /// Offset (raw units).
    #[serde(default)]
    pub offset: f64,
    /// Phase at `t` = 0 \[degrees\].
    #[serde(default)]
    pub phase_deg: f64,
}

/// See [`EntrySpec::ramp`].
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RampSpec {
    /// Slope \[raw units per second\].
    pub slope_per_s: f64,
    /// Value at `t` = 0.
    #[serde(default)]
    pub start: f64,
    /// Lower end of the wrap range.
    pub min: Option<f64>,
    /// Upper end of the wrap range.
    pub max: Option<f64>,
}

/// See [`EntrySpec::noise`].
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseSpec {
    /// Half-width of the uniform distribution (raw units).
    pub amplitude: f64,
    /// Seed: the same seed gives the same values at the same times.
    pub seed: u64,
    /// Centre.
    #[serde(default)]
    pub offset: f64,
}

/// See [`EntrySpec::csv`].
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CsvSpec {
    /// The file (relative to the working directory): lines `time_s,value` with times
    /// rising; a first line that does not parse is a header; `#` starts a comment line.
    pub file: PathBuf,
    /// Start again from the first sample after the last one (else the last value holds).
    #[serde(default)]
    pub repeat: bool,
}

/// A signal generator: a value as a function of virtual time.
#[derive(Debug, Clone, PartialEq)]
pub enum Signal {
    /// A constant.
    Constant(f64),
    /// See [`SineSpec`].
    Sine {
        /// Amplitude.
        amplitude: f64,
        /// Frequency \[Hz\].
        frequency_hz: f64,
        /// Offset.
        offset: f64,
        /// Phase \[rad\].
        phase_rad: f64,
    },
    /// See [`RampSpec`].
    Ramp {
        /// Slope per second.
        slope_per_s: f64,
        /// Value at 0.
        start: f64,
        /// Wrap range.
        wrap: Option<(f64, f64)>,
    },
    /// See [`NoiseSpec`].
    Noise {
        /// Half-width.
        amplitude: f64,
        /// Seed.
        seed: u64,
        /// Centre.
        offset: f64,
    },
    /// CSV playback: `(time_s, value)` rising in time, and whether it repeats.
    Csv(Arc<[(f64, f64)]>, bool),
}

impl Signal {
    /// The value at virtual time `t_s` seconds.
    pub fn value(&self, t_s: f64) -> f64 {
        match self {
            Self::Constant(v) => *v,
            Self::Sine {
                amplitude,
                frequency_hz,
                offset,
                phase_rad,
            } => {
                offset + amplitude * (std::f64::consts::TAU * frequency_hz * t_s + phase_rad).sin()
            }
            Self::Ramp {
                slope_per_s,
                start,
                wrap,
            } => {
                let v = start + slope_per_s * t_s;
                match wrap {
                    Some((lo, hi)) => lo + (v - lo).rem_euclid(hi - lo),
                    None => v,
                }
            }
            Self::Noise {
                amplitude,
                seed,
                offset,
            } => {
                let h = splitmix64(seed ^ splitmix64((t_s * 1e9).round() as i64 as u64));
                // 53 random bits → [0, 1) → [-1, 1).
                let u = (h >> 11) as f64 / (1u64 << 53) as f64;
                offset + amplitude * (2.0 * u - 1.0)
            }
            Self::Csv(samples, repeat) => {
                let (Some(first), Some(last)) = (samples.first(), samples.last()) else {
                    return 0.0;
                };
                let span = last.0 - first.0;
                let t = if *repeat && span > 0.0 && t_s > last.0 {
                    first.0 + (t_s - first.0).rem_euclid(span)
                } else {
                    t_s
                };
                // The last sample at or before t (the first before the first sample).
                let k = samples.partition_point(|s| s.0 <= t);
                samples[k.saturating_sub(1)].1
            }
        }
    }

    /// The default signal of an analog input of type `dtype` and `bits` (see the module
    /// table): a 1 Hz sine over a quarter of the range, centred in it.
    pub fn default_for(dtype: DataType, bits: u16) -> Self {
        let (lo, hi) = range(dtype, bits);
        let (lo, hi) = if lo.is_finite() {
            (lo, hi)
        } else {
            (-1.0, 1.0)
        };
        Self::Sine {
            amplitude: (hi - lo) / 8.0,
            frequency_hz: 1.0,
            offset: lo / 2.0 + hi / 2.0,
            phase_rad: 0.0,
        }
    }
}

fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The raw range of an integer entry of `bits` (REAL: infinite).
pub fn range(dtype: DataType, bits: u16) -> (f64, f64) {
    let bits = bits.clamp(1, 64) as i32;
    match dtype {
        DataType::Real32 | DataType::Real64 => (f64::NEG_INFINITY, f64::INFINITY),
        DataType::Bool => (0.0, 1.0),
        d if d.is_signed() => (-(2f64.powi(bits - 1)), 2f64.powi(bits - 1) - 1.0),
        _ => (0.0, 2f64.powi(bits) - 1.0),
    }
}

/// What one input entry does.
#[derive(Debug, Clone, PartialEq)]
pub enum Rule {
    /// Copies output entry `(index, sub)` every cycle.
    Loop(u16, u8),
    /// Holds this value (written when the process data starts).
    Hold(f64),
    /// Written from the signal every cycle.
    Signal(Signal),
    /// The count of an encoder on a motor plant, every cycle.
    Encoder(Encoder),
}

/// The checked behaviour of one twin device.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Behaviour {
    /// The device's behaviour.
    pub mode: Mode,
    /// Per input entry `(index, sub)`, in the order given.
    pub entries: Vec<((u16, u8), Rule)>,
}

/// A behaviour the segment file gives that cannot be: the key and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BehaviourError {
    /// The key (`device[2].entry[0].sine.amplitude`).
    pub key: String,
    /// What is wrong with it.
    pub why: String,
}

impl std::fmt::Display for BehaviourError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.key, self.why)
    }
}

impl std::error::Error for BehaviourError {}

/// True when `def` has what the CiA402 drive needs: a 16-bit 0x6040:0 and 0x6041:0.
pub fn has_drive_objects(def: &DeviceDef) -> bool {
    [0x6040u16, 0x6041]
        .iter()
        .all(|&i| def.entry_def(i, 0).is_some_and(|e| e.bits == 16))
}

/// True when the ESI or the dictionary says CiA402 (`ProfileNo` 402, or 0x1000 with 402 in
/// its low word) and the drive's objects are there ([`has_drive_objects`]).
pub fn is_cia402(def: &DeviceDef, profile_no: Option<u32>) -> bool {
    (profile_no == Some(402) || def.device_type & 0xFFFF == 402) && has_drive_objects(def)
}

/// Parses `INDEX:SUB` (hex with `0x`/`#x`, or decimal).
fn parse_index_sub(s: &str) -> Option<(u16, u8)> {
    let num = |x: &str| -> Option<u64> {
        let x = x.trim();
        match x.strip_prefix("0x").or_else(|| x.strip_prefix("#x")) {
            Some(h) => u64::from_str_radix(h, 16).ok(),
            None => x.parse().ok(),
        }
    };
    let (i, s) = s.split_once(':')?;
    Some((u16::try_from(num(i)?).ok()?, u8::try_from(num(s)?).ok()?))
}

/// Finds an entry of `def` by `INDEX:SUB` or name among the entries `want` accepts.
fn find(
    def: &DeviceDef,
    name: &str,
    want: impl Fn(&EntryDef) -> bool,
) -> Result<(u16, u8, &'static EntryDef), String> {
    if let Some((i, s)) = parse_index_sub(name) {
        return match def.entry_def(i, s) {
            Some(e) if want(e) => Ok((i, s, e)),
            Some(_) => Err(format!(
                "{i:#06x}:{s:#04x} is not a mappable entry of that direction"
            )),
            None => Err(format!("the dictionary has no entry {i:#06x}:{s:#04x}")),
        };
    }
    let mut hits = Vec::new();
    for o in def.objects {
        for e in o.entries.iter().filter(|e| want(e)) {
            let var = o.entries.len() == 1 && e.sub == 0;
            let full = format!("{}/{}", o.name, e.name);
            if name == full || name == e.name || (var && name == o.name) {
                hits.push((o.index, e.sub, e, full));
            }
        }
    }
    match hits.len() {
        1 => Ok((hits[0].0, hits[0].1, hits[0].2)),
        0 => Err("no entry of that name (give INDEX:SUB, e.g. 0x6000:0x11)".into()),
        _ => Err(format!(
            "several entries have that name: {} (give OBJECT/ENTRY or INDEX:SUB)",
            hits.iter()
                .map(|h| format!("{:#06x}:{:#04x} {}", h.0, h.1, h.3))
                .collect::<Vec<_>>()
                .join(", ")
        )),
    }
}

fn finite(key: &str, what: &str, v: f64) -> Result<f64, BehaviourError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(BehaviourError {
            key: format!("{key}.{what}"),
            why: format!("{v} is not a finite number"),
        })
    }
}

/// Reads a CSV track (see [`CsvSpec`]); `Err` says which line and why.
pub fn read_csv(text: &str) -> Result<Vec<(f64, f64)>, String> {
    let mut out: Vec<(f64, f64)> = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let l = line.trim();
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        let mut f = l.split([',', ';', '\t']).map(str::trim);
        let parsed = match (f.next(), f.next()) {
            (Some(t), Some(v)) => t.parse::<f64>().ok().zip(v.parse::<f64>().ok()),
            _ => None,
        };
        let Some((t, v)) = parsed else {
            if out.is_empty() && n == 0 {
                continue; // a header
            }
            return Err(format!("line {}: {l:?} is not time_s,value", n + 1));
        };
        if !t.is_finite() || !v.is_finite() {
            return Err(format!("line {}: {l:?} is not finite", n + 1));
        }
        if out.last().is_some_and(|p| p.0 >= t) {
            return Err(format!("line {}: time {t} does not rise", n + 1));
        }
        out.push((t, v));
    }
    if out.is_empty() {
        return Err("no samples".into());
    }
    Ok(out)
}

impl Behaviour {
    /// Checks a segment file's `behaviour` and `[[device.entry]]`s against the twin's
    /// dictionary `def` (ESI `ProfileNo` `profile_no`); `key` is the device's key
    /// (`device[2]`), named in errors.
    pub fn compile(
        mode: Option<&str>,
        entries: &[EntrySpec],
        def: &DeviceDef,
        key: &str,
    ) -> Result<Self, BehaviourError> {
        let mode = match mode {
            None => Mode::Auto,
            Some(m) => Mode::parse(m).ok_or_else(|| BehaviourError {
                key: format!("{key}.behaviour"),
                why: format!("{m:?} is not auto, loop, hold or drive"),
            })?,
        };
        if mode == Mode::Drive && !has_drive_objects(def) {
            return Err(BehaviourError {
                key: format!("{key}.behaviour"),
                why: "\"drive\" needs a 16-bit controlword 0x6040 and statusword 0x6041; \
                      the dictionary has not both"
                    .into(),
            });
        }
        let input = |e: &EntryDef| e.pdo.tx() && !e.dtype.is_string() && e.bits <= 64;
        let output = |e: &EntryDef| e.pdo.rx() && !e.dtype.is_string() && e.bits <= 64;
        let mut out = Vec::new();
        for (j, s) in entries.iter().enumerate() {
            let k = format!("{key}.entry[{j}]");
            let (index, sub, e) = find(def, &s.entry, input).map_err(|why| BehaviourError {
                key: format!("{k}.entry"),
                why: format!("{:?}: {why}", s.entry),
            })?;
            let given = [
                s.loop_from.is_some(),
                s.hold.is_some(),
                s.constant.is_some(),
                s.sine.is_some(),
                s.ramp.is_some(),
                s.noise.is_some(),
                s.csv.is_some(),
                s.encoder.is_some(),
            ]
            .iter()
            .filter(|&&b| b)
            .count();
            if given != 1 {
                return Err(BehaviourError {
                    key: k,
                    why: format!(
                        "give exactly one of loop, hold, constant, sine, ramp, noise, csv, \
                         encoder ({given} given)"
                    ),
                });
            }
            let rule = if let Some(src) = &s.loop_from {
                let (oi, os, oe) = find(def, src, output).map_err(|why| BehaviourError {
                    key: format!("{k}.loop"),
                    why: format!("{src:?}: {why}"),
                })?;
                if oe.bits != e.bits {
                    return Err(BehaviourError {
                        key: format!("{k}.loop"),
                        why: format!(
                            "{src:?} has {} bits, the input {} has {}",
                            oe.bits, s.entry, e.bits
                        ),
                    });
                }
                Rule::Loop(oi, os)
            } else if let Some(v) = s.hold {
                Rule::Hold(finite(&k, "hold", v)?)
            } else if let Some(v) = s.constant {
                Rule::Signal(Signal::Constant(finite(&k, "constant", v)?))
            } else if let Some(x) = &s.sine {
                let k = format!("{k}.sine");
                let frequency_hz = finite(&k, "frequency_hz", x.frequency_hz)?;
                if frequency_hz < 0.0 {
                    return Err(BehaviourError {
                        key: format!("{k}.frequency_hz"),
                        why: format!("{frequency_hz} is below 0"),
                    });
                }
                Rule::Signal(Signal::Sine {
                    amplitude: finite(&k, "amplitude", x.amplitude)?,
                    frequency_hz,
                    offset: finite(&k, "offset", x.offset)?,
                    phase_rad: finite(&k, "phase_deg", x.phase_deg)?.to_radians(),
                })
            } else if let Some(x) = &s.ramp {
                let k = format!("{k}.ramp");
                let wrap = match (x.min, x.max) {
                    (None, None) => None,
                    (Some(lo), Some(hi)) => {
                        let (lo, hi) = (finite(&k, "min", lo)?, finite(&k, "max", hi)?);
                        if lo >= hi {
                            return Err(BehaviourError {
                                key: format!("{k}.max"),
                                why: format!("{hi} is not above min {lo}"),
                            });
                        }
                        Some((lo, hi))
                    }
                    _ => {
                        return Err(BehaviourError {
                            key: k,
                            why: "give both min and max (the wrap range) or neither".into(),
                        })
                    }
                };
                Rule::Signal(Signal::Ramp {
                    slope_per_s: finite(&k, "slope_per_s", x.slope_per_s)?,
                    start: finite(&k, "start", x.start)?,
                    wrap,
                })
            } else if let Some(x) = &s.noise {
                let k = format!("{k}.noise");
                Rule::Signal(Signal::Noise {
                    amplitude: finite(&k, "amplitude", x.amplitude)?,
                    seed: x.seed,
                    offset: finite(&k, "offset", x.offset)?,
                })
            } else if let Some(x) = &s.csv {
                let k = format!("{k}.csv.file");
                let text = std::fs::read_to_string(&x.file).map_err(|e| BehaviourError {
                    key: k.clone(),
                    why: format!("cannot read {}: {e}", x.file.display()),
                })?;
                let samples = read_csv(&text).map_err(|why| BehaviourError {
                    key: k,
                    why: format!("{}: {why}", x.file.display()),
                })?;
                Rule::Signal(Signal::Csv(samples.into(), x.repeat))
            } else if let Some(x) = &s.encoder {
                let k = format!("{k}.encoder");
                if !e.dtype.is_integer() {
                    return Err(BehaviourError {
                        key: k.clone(),
                        why: format!("{:?} is not an integer entry (a count)", s.entry),
                    });
                }
                let supply = finite(&k, "supply", x.supply.unwrap_or(24.0))?;
                if supply <= 0.0 {
                    return Err(BehaviourError {
                        key: format!("{k}.supply"),
                        why: format!("{supply} is not above 0"),
                    });
                }
                let volts = match (&x.volts, &x.from) {
                    (Some(v), None) => {
                        if x.volts_per_unit.is_some() {
                            return Err(BehaviourError {
                                key: format!("{k}.volts_per_unit"),
                                why: "goes with from, not with volts".into(),
                            });
                        }
                        Volts::Constant(finite(&k, "volts", *v)?)
                    }
                    (None, Some(src)) => {
                        let (oi, os, oe) =
                            find(def, src, output).map_err(|why| BehaviourError {
                                key: format!("{k}.from"),
                                why: format!("{src:?}: {why}"),
                            })?;
                        if !oe.dtype.is_integer() && !matches!(oe.dtype, DataType::Real32) {
                            return Err(BehaviourError {
                                key: format!("{k}.from"),
                                why: format!("{src:?} is not a number"),
                            });
                        }
                        let per = finite(&k, "volts_per_unit", x.volts_per_unit.unwrap_or(1.0))?;
                        Volts::From(oi, os, per)
                    }
                    _ => {
                        return Err(BehaviourError {
                            key: k,
                            why: "give volts or from (an output entry), one of them".into(),
                        })
                    }
                };
                Rule::Encoder(Encoder { volts, supply })
            } else {
                unreachable!("exactly one behaviour was checked above")
            };
            out.push(((index, sub), rule));
        }
        Ok(Self { mode, entries: out })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signals_are_the_formulas_of_virtual_time() {
        let s = Signal::Sine {
            amplitude: 100.0,
            frequency_hz: 2.0,
            offset: 5.0,
            phase_rad: 0.0,
        };
        assert!((s.value(0.125) - 105.0).abs() < 1e-9);
        assert!((s.value(0.375) + 95.0).abs() < 1e-9);
        let r = Signal::Ramp {
            slope_per_s: 10.0,
            start: 0.0,
            wrap: Some((0.0, 25.0)),
        };
        assert_eq!(r.value(2.0), 20.0);
        assert_eq!(r.value(3.0), 5.0);
        let c = Signal::Csv(vec![(0.0, 1.0), (1.0, 2.0), (2.0, 3.0)].into(), true);
        assert_eq!(c.value(0.5), 1.0);
        assert_eq!(c.value(1.0), 2.0);
        assert_eq!(c.value(2.5), 1.0);
        assert_eq!(c.value(3.5), 2.0);
        let n = Signal::Noise {
            amplitude: 10.0,
            seed: 7,
            offset: 0.0,
        };
        let vals: Vec<f64> = (0..1000).map(|k| n.value(k as f64 * 1e-3)).collect();
        assert!(vals.iter().all(|v| v.abs() <= 10.0));
        let mean = vals.iter().sum::<f64>() / 1000.0;
        assert!(mean.abs() < 1.0, "{mean}");
        assert!(vals.windows(2).any(|w| w[0] != w[1]));
        // Same seed, same time: same value; another seed: another sequence.
        assert_eq!(n.value(0.123), n.value(0.123));
        let m = Signal::Noise {
            amplitude: 10.0,
            seed: 8,
            offset: 0.0,
        };
        assert_ne!(n.value(0.123), m.value(0.123));
    }

    #[test]
    fn csv_tracks_are_checked() {
        assert_eq!(
            read_csv("time,value\n0,1\n0.5,2\n").unwrap(),
            vec![(0.0, 1.0), (0.5, 2.0)]
        );
        assert!(read_csv("0,1\n0,2\n").unwrap_err().contains("line 2"));
        assert!(read_csv("0,1\nx,2\n").unwrap_err().contains("line 2"));
        assert!(read_csv("t,v\n").unwrap_err().contains("no samples"));
        assert!(read_csv("0,nan\n").is_err());
    }

    #[test]
    fn index_sub_spellings() {
        assert_eq!(parse_index_sub("0x6000:0x11"), Some((0x6000, 0x11)));
        assert_eq!(parse_index_sub("#x6000:17"), Some((0x6000, 17)));
        assert_eq!(parse_index_sub("24576:1"), Some((0x6000, 1)));
        assert_eq!(parse_index_sub("0x16000:1"), None);
        assert_eq!(parse_index_sub("Value"), None);
    }
}
