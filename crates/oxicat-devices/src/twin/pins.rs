//! The digital I/O of a twin its ESC serves alone: terminals without a microcontroller
//! (EL1xxx/EL2xxx-style, the AX58100 DIO board, the EK1101's ID switch) run no firmware;
//! the ESC's digital-I/O PDI drives output pins from 0x0F00..0x0F03 and samples input pins
//! into 0x1000..0x1003 (ET1100 datasheet section II, registers 0x0F00 "Digital I/O output
//! data" and 0x1000 "Digital I/O input data"; section I, "Digital I/O interface").
//!
//! What the input pins see is the twin's [`Behaviour`]: `auto` and `loop` wire output pins
//! to input pins where the default mapping pairs them ([`oxicat_esi::twin::loop_pairs`],
//! the k-th output entry to the k-th input entry of the same width), `hold` leaves them at
//! 0, and per-entry rules (`loop` from an output entry, `hold`, or a signal of the
//! segment's virtual time) override that. There is no CoE, so the layout is the SII's:
//! each process-data SM's PDOs in order from the SM's start address.
//!
//! The pins are sampled every [`SAMPLE_NS`] of virtual time (a real ESC samples at the
//! start of each frame or at SYNC0/SYNC1, register 0x0150): an output written by one frame
//! is on the input pins well before the next cycle's frame.

use oxicat_esi::model::{DeviceModel, SmKind};
use oxicat_sim::node::{EscEvent, Node};
use oxicat_slave::{DataType, DeviceDef, PdoEntry};

use super::behaviour::{Behaviour, Mode, Rule, Signal};
use super::firmware::encode;

/// Sampling period of the input pins \[ns\].
pub const SAMPLE_NS: u64 = 50_000;

/// Digital outputs: 0x0F00..0x0F03.
const DOUT: u16 = 0x0F00;
/// Digital inputs: 0x1000..0x1003.
const DIN: u16 = 0x1000;

/// One mapped entry and where its bits sit in the 32-bit pin word.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Pin {
    /// The entry.
    pub entry: PdoEntry,
    /// First bit in the pin word (outputs: 0x0F00 bit 0 = bit 0; inputs: 0x1000 bit 0).
    pub bit: u32,
}

/// The entries of a digital-I/O twin on its pins, from its SII.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Layout {
    /// Output entries within 0x0F00..0x0F03, in mapping order.
    pub outputs: Vec<Pin>,
    /// Input entries within 0x1000..0x1003, in mapping order.
    pub inputs: Vec<Pin>,
}

/// Entries of the SMs of `kind` whose start lies at `base`..`base + 4`, with their bit in
/// the pin word (entries beyond the 32 pins are left out).
fn pins(m: &DeviceModel, kind: SmKind, base: u16) -> Vec<Pin> {
    let mut out = Vec::new();
    for (k, sm) in m.sms.iter().enumerate() {
        if sm.kind != kind || !(base..base + 4).contains(&sm.start) {
            continue;
        }
        let mut bit = u32::from(sm.start - base) * 8;
        let pdos = m.rx_pdos.iter().chain(&m.tx_pdos);
        for p in pdos.filter(|p| p.sm == Some(k as u8)) {
            for e in &p.entries {
                let entry = PdoEntry {
                    index: e.index,
                    sub: e.sub,
                    bits: e.bits,
                };
                if e.index != 0 && bit + u32::from(e.bits) <= 32 {
                    out.push(Pin { entry, bit });
                }
                bit += u32::from(e.bits);
            }
        }
    }
    out
}

impl Layout {
    /// The layout of the device whose SII image is `sii`.
    pub fn of_sii(sii: &[u8]) -> Result<Self, String> {
        let m = oxicat_esi::sii::parse(sii).map_err(|e| format!("its SII: {e}"))?;
        Ok(Self {
            outputs: pins(&m, SmKind::Outputs, DOUT),
            inputs: pins(&m, SmKind::Inputs, DIN),
        })
    }

    fn input(&self, at: (u16, u8)) -> Option<Pin> {
        self.inputs
            .iter()
            .copied()
            .find(|p| (p.entry.index, p.entry.sub) == at)
    }

    fn output(&self, at: (u16, u8)) -> Option<Pin> {
        self.outputs
            .iter()
            .copied()
            .find(|p| (p.entry.index, p.entry.sub) == at)
    }
}

/// Where an input pin group takes its value from.
#[derive(Debug, Clone)]
enum Source {
    /// Output pins starting at this bit.
    Output(u32),
    /// A signal of virtual time, encoded to the entry's type.
    Signal(Signal, DataType),
}

/// One input entry on the pins and its source.
#[derive(Debug, Clone)]
struct Wire {
    to: Pin,
    from: Source,
}

/// The ESI-less half of a digital-I/O twin: drives its ESC's input pins.
pub struct Pins {
    wires: Vec<Wire>,
    next_ns: u64,
}

impl Pins {
    /// The pins of a twin of `def` with SII `sii` and `behaviour`; `Err` names an entry the
    /// behaviour gives that is not on the pins, or a behaviour an ESC alone cannot have.
    pub fn new(def: &DeviceDef, sii: &[u8], behaviour: &Behaviour) -> Result<Self, String> {
        let layout = Layout::of_sii(sii)?;
        if behaviour.mode == Mode::Drive {
            return Err("\"drive\" needs firmware; the ESC serves this device alone".into());
        }
        let mut wires = Vec::new();
        if matches!(behaviour.mode, Mode::Auto | Mode::Loop) {
            let outs: Vec<PdoEntry> = layout.outputs.iter().map(|p| p.entry).collect();
            let ins: Vec<PdoEntry> = layout.inputs.iter().map(|p| p.entry).collect();
            for (o, i) in oxicat_esi::twin::loop_pairs(def, &outs, &ins) {
                let (Some(o), Some(i)) = (
                    layout.output((o.index, o.sub)),
                    layout.input((i.index, i.sub)),
                ) else {
                    continue;
                };
                wires.push(Wire {
                    to: i,
                    from: Source::Output(o.bit),
                });
            }
        }
        for (at, rule) in &behaviour.entries {
            let to = layout.input(*at).ok_or_else(|| {
                format!(
                    "{:#06x}:{:#04x} is not on the ESC's input pins 0x1000..0x1003 (an ESC \
                     without firmware has no other inputs)",
                    at.0, at.1
                )
            })?;
            let dtype = def
                .entry_def(at.0, at.1)
                .map_or(DataType::Unsigned32, |e| e.dtype);
            let from = match rule {
                Rule::Loop(i, s) => {
                    let o = layout.output((*i, *s)).ok_or_else(|| {
                        format!("{i:#06x}:{s:#04x} is not on the ESC's output pins 0x0F00..0x0F03")
                    })?;
                    Source::Output(o.bit)
                }
                Rule::Hold(v) => Source::Signal(Signal::Constant(*v), dtype),
                Rule::Signal(s) => Source::Signal(s.clone(), dtype),
                Rule::Encoder(_) => {
                    return Err(format!(
                        "{:#06x}:{:#04x}: an encoder plant needs firmware to count; the ESC \
                         serves this device alone",
                        at.0, at.1
                    ))
                }
            };
            wires.retain(|w| w.to != to);
            wires.push(Wire { to, from });
        }
        Ok(Self { wires, next_ns: 0 })
    }

    /// Whether anything drives the input pins.
    pub fn is_empty(&self) -> bool {
        self.wires.is_empty()
    }

    /// The input pin word at virtual time `t` with output pins `dout`.
    pub fn inputs(&self, dout: u32, t_ns: u64) -> u32 {
        let mut word = 0u32;
        for w in &self.wires {
            let bits = u32::from(w.to.entry.bits);
            let mask = if bits >= 32 {
                u32::MAX
            } else {
                (1 << bits) - 1
            };
            let v = match &w.from {
                Source::Output(bit) => (dout >> bit) & mask,
                Source::Signal(s, dtype) => {
                    encode(s.value(t_ns as f64 * 1e-9), *dtype, bits as u16) as u32 & mask
                }
            };
            word = (word & !(mask << w.to.bit)) | (v << w.to.bit);
        }
        word
    }
}

impl Node for Pins {
    fn on_event(&mut self, _esc: &mut oxicat_esc::Esc, _ev: EscEvent, _t: u64) {}

    fn next_wakeup(&self) -> Option<u64> {
        Some(self.next_ns)
    }

    fn on_wakeup(&mut self, esc: &mut oxicat_esc::Esc, t: u64) {
        let word = self.inputs(esc.digital_outputs(), t);
        esc.set_digital_inputs(word);
        self.next_ns = (t / SAMPLE_NS + 1) * SAMPLE_NS;
    }
}
