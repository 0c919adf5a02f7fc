//! PDO assignment (0x1C12/0x1C13) and mapping (0x16xx/0x1Axx) of a slave, read over CoE or
//! taken from the SII when the slave has no CoE; process-data variables named after the
//! slaves' own descriptions and placed in ethercrab's process image.

use oxicat_esi::DeviceModel;

use crate::value::ValueType;
use crate::{Master, MasterError};

/// One mapped entry.
#[derive(Debug, Clone, PartialEq)]
pub struct MappedEntry {
    /// Object index (0: a gap).
    pub index: u16,
    /// Subindex.
    pub sub: u8,
    /// Bit length.
    pub bits: u16,
    /// Name (SII or SDO information; `0xIIII:SS` when neither has one).
    pub name: String,
    /// Value type.
    pub ty: ValueType,
    /// CoE data type code, if known.
    pub type_code: Option<u16>,
}

/// One assigned PDO.
#[derive(Debug, Clone, PartialEq)]
pub struct Pdo {
    /// Mapping object index.
    pub index: u16,
    /// Name (SII).
    pub name: String,
    /// Entries in order.
    pub entries: Vec<MappedEntry>,
}

/// Where a slave's PDO layout came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PdoSource {
    /// 0x1C12/0x1C13 and the mapping objects, read over CoE.
    Coe,
    /// The SII's RxPDO/TxPDO categories (no CoE).
    Sii,
}

/// The process-data layout of one slave.
#[derive(Debug, Clone, PartialEq)]
pub struct SlavePdos {
    /// Position.
    pub position: usize,
    /// Source.
    pub source: PdoSource,
    /// RxPDOs (outputs, SM2) in assignment order.
    pub rx: Vec<Pdo>,
    /// TxPDOs (inputs, SM3) in assignment order.
    pub tx: Vec<Pdo>,
}

/// Output (master → slave) or input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dir {
    /// RxPDO data: written by the master.
    Output,
    /// TxPDO data: read by the master.
    Input,
}

/// A process-data variable of one slave.
#[derive(Debug, Clone, PartialEq)]
pub struct Variable {
    /// Full name (`<pos>.<entry>`).
    pub name: String,
    /// Slave position.
    pub position: usize,
    /// Direction.
    pub dir: Dir,
    /// Bit offset in the slave's outputs or inputs.
    pub bit_offset: usize,
    /// Bit length.
    pub bits: u16,
    /// Value type.
    pub ty: ValueType,
    /// Object index and subindex.
    pub object: (u16, u8),
    /// Unit text for CSV headers: the declared physical unit when `scale` is set, else the
    /// CoE type name.
    pub unit: String,
    /// The entry's physical scaling, when its device declares one ([`Variable::with_scale`]).
    pub scale: Option<oxicat_slave::Scale>,
}

impl Variable {
    /// Reads the variable from the slave's outputs or inputs bytes.
    pub fn get(&self, image: &[u8]) -> Vec<u8> {
        let nbytes = (self.bits as usize).div_ceil(8);
        let mut out = vec![0u8; nbytes];
        for i in 0..self.bits as usize {
            let b = self.bit_offset + i;
            let Some(byte) = image.get(b / 8) else { break };
            if byte >> (b % 8) & 1 != 0 {
                out[i / 8] |= 1 << (i % 8);
            }
        }
        out
    }

    /// Writes `value` (little-endian, at least the variable's size) into `image`.
    pub fn set(&self, image: &mut [u8], value: &[u8]) {
        for i in 0..self.bits as usize {
            let bit = value.get(i / 8).is_some_and(|v| v >> (i % 8) & 1 != 0);
            let b = self.bit_offset + i;
            if let Some(byte) = image.get_mut(b / 8) {
                if bit {
                    *byte |= 1 << (b % 8);
                } else {
                    *byte &= !(1 << (b % 8));
                }
            }
        }
    }

    /// The variable decoded with its device's declared scaling: values in `scale.unit`,
    /// the CSV header says that unit instead of the CoE type.
    pub fn with_scale(mut self, scale: oxicat_slave::Scale) -> Self {
        if self.ty.is_integer() {
            self.unit = scale.unit.to_string();
            self.scale = Some(scale);
        }
        self
    }

    /// Formats bytes read by [`Variable::get`] (in the physical unit when scaled).
    pub fn format(&self, b: &[u8]) -> String {
        match (self.scale, self.ty.integer(b)) {
            (Some(s), Some(raw)) => crate::value::format_scaled(raw, &s),
            _ => self.ty.format_plain(b),
        }
    }

    /// Encodes a value given as text: in the physical unit when scaled (rounded to the
    /// nearest step, checked against the type's range), else as [`ValueType::encode`].
    pub fn encode(&self, text: &str) -> Result<Vec<u8>, MasterError> {
        let Some(s) = self.scale else {
            return self.ty.encode(text);
        };
        let raw = crate::value::parse_scaled(text, &s).ok_or_else(|| MasterError::BadValue {
            value: text.to_string(),
            ty: self.ty,
            why: format!("not a number of {}", s.unit),
        })?;
        self.ty
            .encode(&raw.to_string())
            .map_err(|_| MasterError::BadValue {
                value: text.to_string(),
                ty: self.ty,
                why: format!(
                    "{text} {} is {raw} steps of {}/{} {}, out of the type's range",
                    s.unit, s.num, s.den, s.unit
                ),
            })
    }
}

fn sii_name(m: Option<&DeviceModel>, index: u16, sub: u8) -> (Option<String>, Option<u16>) {
    let Some(m) = m else { return (None, None) };
    for p in m.rx_pdos.iter().chain(m.tx_pdos.iter()) {
        for e in &p.entries {
            if e.index == index && e.sub == sub {
                return (e.name.clone(), e.data_type);
            }
        }
    }
    (None, None)
}

fn entry(index: u16, sub: u8, bits: u16, name: Option<String>, code: Option<u16>) -> MappedEntry {
    let ty = code
        .and_then(ValueType::from_coe)
        .filter(|t| {
            t.size()
                .is_none_or(|s| s * 8 == bits as usize || *t == ValueType::Bool)
        })
        .unwrap_or_else(|| ValueType::from_bits(bits));
    MappedEntry {
        index,
        sub,
        bits,
        name: name
            .filter(|n| !n.is_empty())
            .unwrap_or_else(|| format!("0x{index:04X}:{sub:02X}")),
        ty,
        type_code: code,
    }
}

impl Master {
    /// The SII of the slave decoded into the comparable model (names, PDOs, CoE details).
    pub fn sii_model(&self, position: usize) -> Result<DeviceModel, MasterError> {
        let img = self.runner.block_on(self.sii_image(position))?;
        oxicat_esi::sii::parse(&img).map_err(|e| MasterError::SiiImage(e.to_string()))
    }

    /// The PDO assignment and mapping of the slave at `position` (CoE when it has CoE,
    /// otherwise from the SII).
    pub fn pdos(&self, position: usize) -> Result<SlavePdos, MasterError> {
        let model = self.sii_model(position).ok();
        let has_coe = model
            .as_ref()
            .and_then(|m| m.mailbox)
            .and_then(|m| m.coe)
            .is_some();
        if has_coe {
            self.runner
                .block_on(self.pdos_coe(position, model.as_ref()))
        } else {
            let m = model.ok_or(MasterError::NoCoe(position))?;
            // The process-data SMs of this SII by kind, in SM order (a board may split
            // its outputs over several SMs, as the AX58100 DIO board's 0x0F02 and 0x0F03).
            let sms_of = |k: oxicat_esi::model::SmKind| -> Vec<u8> {
                m.sms
                    .iter()
                    .enumerate()
                    .filter(|(_, s)| s.kind == k)
                    .map(|(i, _)| i as u8)
                    .collect()
            };
            let conv = |list: &[oxicat_esi::model::PdoModel], sms: Vec<u8>| -> Vec<Pdo> {
                sms.iter()
                    .flat_map(|&sm| list.iter().filter(move |p| p.sm == Some(sm)))
                    .map(|p| Pdo {
                        index: p.index,
                        name: p.name.clone().unwrap_or_default(),
                        entries: p
                            .entries
                            .iter()
                            .map(|e| {
                                entry(e.index, e.sub, e.bits as u16, e.name.clone(), e.data_type)
                            })
                            .collect(),
                    })
                    .collect()
            };
            let or = |v: Vec<u8>, sm: u8| if v.is_empty() { vec![sm] } else { v };
            let out_sms = or(sms_of(oxicat_esi::model::SmKind::Outputs), 2);
            let in_sms = or(sms_of(oxicat_esi::model::SmKind::Inputs), 3);
            Ok(SlavePdos {
                position,
                source: PdoSource::Sii,
                rx: conv(&m.rx_pdos, out_sms),
                tx: conv(&m.tx_pdos, in_sms),
            })
        }
    }

    async fn pdos_coe(
        &self,
        position: usize,
        model: Option<&DeviceModel>,
    ) -> Result<SlavePdos, MasterError> {
        let mut rx = Vec::new();
        let mut tx = Vec::new();
        for (assign, list) in [(0x1C12u16, &mut rx), (0x1C13u16, &mut tx)] {
            let n = match self.sdo_upload_async(position, assign, 0).await {
                Ok(b) => b.first().copied().unwrap_or(0),
                Err(MasterError::SdoAbort { .. }) => 0,
                Err(e) => return Err(e),
            };
            for k in 1..=n {
                let b = self.sdo_upload_async(position, assign, k).await?;
                let Some(pdo) = b.get(..2).map(|b| u16::from_le_bytes([b[0], b[1]])) else {
                    continue;
                };
                let cnt = self
                    .sdo_upload_async(position, pdo, 0)
                    .await?
                    .first()
                    .copied()
                    .unwrap_or(0);
                let mut entries = Vec::new();
                for s in 1..=cnt {
                    let b = self.sdo_upload_async(position, pdo, s).await?;
                    let Some(v) = b
                        .get(..4)
                        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                    else {
                        continue;
                    };
                    let (index, sub, bits) = ((v >> 16) as u16, (v >> 8) as u8, (v & 0xFF) as u16);
                    let (name, code) = sii_name(model, index, sub);
                    entries.push(entry(index, sub, bits, name, code));
                }
                let name = model
                    .and_then(|m| {
                        m.rx_pdos
                            .iter()
                            .chain(m.tx_pdos.iter())
                            .find(|p| p.index == pdo)
                            .and_then(|p| p.name.clone())
                    })
                    .unwrap_or_default();
                list.push(Pdo {
                    index: pdo,
                    name,
                    entries,
                });
            }
        }
        Ok(SlavePdos {
            position,
            source: PdoSource::Coe,
            rx,
            tx,
        })
    }
}

/// The variables of a slave's layout, with bit offsets in its outputs and inputs.
pub fn variables(p: &SlavePdos) -> Vec<Variable> {
    let mut out = Vec::new();
    for (dir, list) in [(Dir::Output, &p.rx), (Dir::Input, &p.tx)] {
        let mut bit = 0usize;
        for pdo in list {
            for e in &pdo.entries {
                if e.index != 0 {
                    out.push(Variable {
                        name: format!("{}.{}", p.position, e.name),
                        position: p.position,
                        dir,
                        bit_offset: bit,
                        bits: e.bits,
                        ty: e.ty,
                        object: (e.index, e.sub),
                        unit: e.ty.esi_name().to_string(),
                        scale: None,
                    });
                }
                bit += e.bits as usize;
            }
        }
    }
    out
}

/// Resolves a variable name against the slaves' layouts: `<pos>.<entry name>`,
/// `<pos>.<PDO name>.<entry name>`, `<pos>.0xIIII:SS`, or `<device name>.<entry>` for the
/// same entry of every slave of that name (one variable linked to several slaves).
pub fn resolve(
    name: &str,
    layouts: &[SlavePdos],
    slave_names: &[String],
) -> Result<Vec<Variable>, MasterError> {
    let all: Vec<Variable> = layouts.iter().flat_map(variables).collect();
    let unknown = || MasterError::UnknownVariable {
        name: name.to_string(),
        known: all.iter().map(|v| v.name.clone()).collect(),
    };
    let (head, tail) = name.split_once('.').ok_or_else(unknown)?;
    let positions: Vec<usize> = match head.parse::<usize>() {
        Ok(p) => vec![p],
        Err(_) => slave_names
            .iter()
            .enumerate()
            .filter(|(_, n)| n.eq_ignore_ascii_case(head))
            .map(|(i, _)| i)
            .collect(),
    };
    let mut found = Vec::new();
    // A device name that links several slaves: each variable gets its slave's position
    // (`0.Button1`, `1.Button1`), so CSV columns and watch lines have unique names.
    let several = positions.len() > 1;
    for p in positions {
        let Some(layout) = layouts.iter().find(|l| l.position == p) else {
            continue;
        };
        let vars = variables(layout);
        let obj = tail.strip_prefix("0x").and_then(|t| {
            let (i, s) = t.split_once(':')?;
            Some((
                u16::from_str_radix(i, 16).ok()?,
                u8::from_str_radix(s, 16).ok()?,
            ))
        });
        let hit = vars.iter().find(|v| {
            let entry_name = v.name.split_once('.').map(|x| x.1).unwrap_or("");
            if Some(v.object) == obj || entry_name == tail {
                return true;
            }
            // <PDO name>.<entry name>
            if let Some((pdo, en)) = tail.split_once('.') {
                let list = if v.dir == Dir::Output {
                    &layout.rx
                } else {
                    &layout.tx
                };
                return en == entry_name
                    && list.iter().any(|pd| {
                        pd.name == pdo && pd.entries.iter().any(|e| (e.index, e.sub) == v.object)
                    });
            }
            false
        });
        if let Some(v) = hit {
            let mut v = v.clone();
            v.name = if several {
                format!("{p}.{tail}")
            } else {
                name.to_string()
            };
            found.push(v);
        }
    }
    if found.is_empty() {
        return Err(unknown());
    }
    Ok(found)
}
