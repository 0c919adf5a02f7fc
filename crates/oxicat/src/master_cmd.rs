//! The master verbs of `oxicat`, after the IgH `ethercat` tool: `slaves`, `states`,
//! `sii-read`, `sii-write`, `alias`, `upload`, `download`, `sdos`, `pdos`, `cstruct`,
//! `data`, `graph`, `xml`, `reg-read`, `reg-write`, `watch`, `write`, `record`. Each runs on `--iface <if>` (or `OXICAT_IFACE`),
//! on a segment served with EtherCAT over UDP `--udp host:port`, or, for tests and trying
//! things out, on an in-process virtual segment `--sim demo:2`.
//!
//! `--sim` knows the devices of `oxicat sim --list` (one registry, `oxicat_devices::registry`).

use std::io::Write;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use clap::{Args, Subcommand};
use oxicat_master::cyclic::CycleOptions;
use oxicat_master::pdo::Variable;
use oxicat_master::value::{parse_int, parse_u16, ValueType};
use oxicat_master::{AlState, Link, Master, MasterError, MasterOptions};

/// Where the slaves are.
#[derive(Debug, Clone, Args)]
pub struct LinkArgs {
    /// Network interface with the EtherCAT segment (default: $OXICAT_IFACE).
    #[arg(long, short = 'i')]
    pub iface: Option<String>,
    /// Run against an in-process virtual segment instead: devices of `oxicat sim --list` by
    /// name with a count, separated by commas or spaces (e.g. `demo:2,tue-es030:1`), each
    /// optionally `@lan9252` or `@et1100` (firmware through that chip's SPI driver). The
    /// segment lives for this one command.
    #[arg(long, conflicts_with_all = ["iface", "udp"])]
    pub sim: Option<String>,
    /// Reach a segment served with EtherCAT over UDP (`oxicat sim --udp <host:port>`), e.g.
    /// 127.0.0.1:34980.
    #[arg(long, conflicts_with = "iface", value_name = "HOST:PORT")]
    pub udp: Option<String>,
    /// How long to wait for a frame to come back on an interface, in ms (default 250, or
    /// $OXICAT_TIMEOUT_MS). Raise it on a busy host or for a virtual segment on a loaded
    /// machine; EEPROM and mailbox waits scale with it.
    #[arg(long, value_name = "MS")]
    pub timeout: Option<u64>,
}

/// Slave selection.
#[derive(Debug, Clone, Args)]
pub struct PosArgs {
    /// Slave position (0 = first).
    #[arg(long, short = 'p')]
    pub position: Option<usize>,
}

/// The master verbs (fields are documented by their `--help` text).
#[allow(missing_docs)]
#[derive(Debug, Subcommand)]
pub enum MasterCommand {
    /// List the slaves: position, address, alias, AL state, name, identity, ports.
    Slaves {
        #[command(flatten)]
        link: LinkArgs,
        #[command(flatten)]
        pos: PosArgs,
        /// Verbose: a block per slave (identity, state, ports, DC delay), as `ethercat slaves -v`.
        #[arg(long, short = 'v')]
        verbose: bool,
    },
    /// Request an AL state (INIT, PREOP, SAFEOP, OP, BOOT) for all slaves or one.
    States {
        /// INIT | PREOP | SAFEOP | OP | BOOT.
        state: String,
        #[command(flatten)]
        link: LinkArgs,
        #[command(flatten)]
        pos: PosArgs,
    },
    /// Read a slave's SII EEPROM (decoded by default).
    #[command(alias = "sii_read")]
    SiiRead {
        #[command(flatten)]
        link: LinkArgs,
        #[command(flatten)]
        pos: PosArgs,
        /// Raw binary to standard output (or -o).
        #[arg(long, conflicts_with_all = ["hex", "decode"])]
        raw: bool,
        /// Hex dump.
        #[arg(long, conflicts_with = "decode")]
        hex: bool,
        /// Decoded categories (default).
        #[arg(long)]
        decode: bool,
        /// The whole EEPROM, not only up to the end of the categories.
        #[arg(long)]
        full: bool,
        /// Output file.
        #[arg(long, short = 'o')]
        output: Option<PathBuf>,
    },
    /// Write an SII image (a file, or one generated for a device) and verify it.
    #[command(alias = "sii_write")]
    SiiWrite {
        #[command(flatten)]
        link: LinkArgs,
        #[command(flatten)]
        pos: PosArgs,
        /// Image file (binary or Intel HEX).
        file: Option<PathBuf>,
        /// Generate the image of this device (see `oxicat device`).
        #[arg(long, conflicts_with = "file")]
        device: Option<String>,
        /// Write even when the image's identity differs from the slave's.
        #[arg(long)]
        force: bool,
    },
    /// SDO upload (read) of index:subindex.
    Upload {
        #[command(flatten)]
        link: LinkArgs,
        #[command(flatten)]
        pos: PosArgs,
        /// Object index (0x1018).
        index: String,
        /// Subindex.
        sub: String,
        /// Value type (default: from SDO information, else by size).
        #[arg(long, short = 't')]
        r#type: Option<String>,
    },
    /// SDO download (write) of a typed value to index:subindex.
    Download {
        #[command(flatten)]
        link: LinkArgs,
        #[command(flatten)]
        pos: PosArgs,
        /// Object index.
        index: String,
        /// Subindex.
        sub: String,
        /// The value.
        #[arg(allow_hyphen_values = true)]
        value: String,
        /// Value type (default: from SDO information).
        #[arg(long, short = 't')]
        r#type: Option<String>,
    },
    /// List the CoE dictionary (SDO information).
    Sdos {
        #[command(flatten)]
        link: LinkArgs,
        #[command(flatten)]
        pos: PosArgs,
    },
    /// Show the PDO assignment and mapping.
    Pdos {
        #[command(flatten)]
        link: LinkArgs,
        #[command(flatten)]
        pos: PosArgs,
    },
    /// The PDO configuration as C arrays for the IgH application interface (`ecrt.h`), as
    /// `ethercat cstruct`; with --rust as structs for ethercrab's wire derive.
    Cstruct {
        #[command(flatten)]
        link: LinkArgs,
        #[command(flatten)]
        pos: PosArgs,
        /// Rust structs (`EtherCrabWireReadWrite`) for the output and input images instead.
        #[arg(long)]
        rust: bool,
        /// From a device definition's default PDO assignment (see `oxicat device list`),
        /// without a bus.
        #[arg(long, conflicts_with_all = ["iface", "sim", "udp"])]
        device: Option<String>,
    },
    /// The process-data image, as `ethercat data`: the slaves are brought to OP, cycle a few
    /// times, and the image of the last cycle is shown (slave by slave: outputs, then inputs).
    Data {
        #[command(flatten)]
        link: LinkArgs,
        /// Raw bytes instead of a hex dump.
        #[arg(long)]
        binary: bool,
        /// Output file (default: standard output).
        #[arg(long, short = 'o')]
        output: Option<PathBuf>,
    },
    /// Write the station alias into a slave's SII (word 4, with the configuration-area CRC),
    /// as `ethercat alias`; the ESC reloads it into 0x0012.
    Alias {
        #[command(flatten)]
        link: LinkArgs,
        #[command(flatten)]
        pos: PosArgs,
        /// The alias, 0 … 0xFFFF (0: none).
        alias: String,
    },
    /// The topology as Graphviz DOT (ports and links from the DL status), as `ethercat graph`.
    Graph {
        #[command(flatten)]
        link: LinkArgs,
        /// Output file (default: standard output).
        #[arg(long, short = 'o')]
        output: Option<PathBuf>,
    },
    /// Write an ESI (EtherCATInfo XML) for a live slave.
    Xml {
        #[command(flatten)]
        link: LinkArgs,
        #[command(flatten)]
        pos: PosArgs,
        /// Output file.
        #[arg(long, short = 'o')]
        output: Option<PathBuf>,
    },
    /// Read ESC registers (FPRD).
    #[command(alias = "reg_read")]
    RegRead {
        #[command(flatten)]
        link: LinkArgs,
        #[command(flatten)]
        pos: PosArgs,
        /// Address.
        address: String,
        /// Length in bytes (default: the type's size, else 1).
        length: Option<String>,
        /// Show as this type.
        #[arg(long, short = 't')]
        r#type: Option<String>,
    },
    /// Write ESC registers (FPWR).
    #[command(alias = "reg_write")]
    RegWrite {
        #[command(flatten)]
        link: LinkArgs,
        #[command(flatten)]
        pos: PosArgs,
        /// Address.
        address: String,
        /// Value (hex bytes with --type hex).
        #[arg(allow_hyphen_values = true)]
        value: String,
        /// Value type (default u8).
        #[arg(long, short = 't')]
        r#type: Option<String>,
    },
    /// Show process-data variables live (`<pos>.<entry>` or `<device>.<entry>`).
    Watch {
        #[command(flatten)]
        link: LinkArgs,
        /// Variables.
        #[arg(required = true)]
        vars: Vec<String>,
        /// Cycle time (e.g. 1ms, 400us).
        #[arg(long, default_value = "1ms")]
        cycle: String,
        /// Refresh every this many cycles.
        #[arg(long, default_value_t = 100)]
        every: u64,
        /// Stop after this many refreshes (0: until Ctrl-C).
        #[arg(long, default_value_t = 0)]
        count: u64,
    },
    /// Write a process-data output while cycling (to every slave the name links).
    Write {
        #[command(flatten)]
        link: LinkArgs,
        /// Variable.
        var: String,
        /// Value.
        #[arg(allow_hyphen_values = true)]
        value: String,
        /// Cycle time.
        #[arg(long, default_value = "1ms")]
        cycle: String,
        /// Cycles to keep cycling after the write.
        #[arg(long, default_value_t = 20)]
        settle: u64,
    },
    /// Record variables every cycle (DC-synchronous) into a CSV file.
    Record {
        #[command(flatten)]
        link: LinkArgs,
        /// Variables.
        #[arg(required = true)]
        vars: Vec<String>,
        /// Cycle time.
        #[arg(long, default_value = "1ms")]
        cycle: String,
        /// Duration (e.g. 10s, 500ms).
        #[arg(long, default_value = "1s")]
        duration: String,
        /// Output CSV.
        #[arg(long, short = 'o')]
        output: PathBuf,
        /// Free run instead of DC SYNC0.
        #[arg(long)]
        free_run: bool,
    },
}

/// Parses `400us`, `1ms`, `10s`, `250ns`, `2m`.
pub fn parse_duration(s: &str) -> Result<Duration, MasterError> {
    let t = s.trim();
    let split = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let v: f64 = num
        .parse()
        .map_err(|_| MasterError::Usage(format!("not a duration: {s:?} (e.g. 400us, 10s)")))?;
    let ns = match unit.trim() {
        "ns" => v,
        "us" | "µs" => v * 1e3,
        "ms" => v * 1e6,
        "s" | "" => v * 1e9,
        "m" | "min" => v * 60e9,
        u => {
            return Err(MasterError::Usage(format!(
                "unknown time unit {u:?} in {s:?}"
            )))
        }
    };
    Ok(Duration::from_nanos(ns.round() as u64))
}

/// The in-process segment of `--sim`: the devices of `oxicat sim --list`, in the same syntax
/// (`demo:2,tue-es030:1` or `"demo:2 tue-es030:1"`), at most
/// [`oxicat_master::MAX_SLAVES`] in all (what the master's group holds), checked before
/// anything is built.
pub fn build_sim(spec: &str) -> Result<Arc<Mutex<oxicat_sim::segment::Segment>>, MasterError> {
    let max = oxicat_master::MAX_SLAVES;
    let range = format!("1 … {max} slaves in all (the master's group holds {max})");
    let desc = crate::sim_cmd::parse_specs_within(&[spec.to_string()], max, &range)
        .map_err(|e| MasterError::Usage(format!("--sim: {e}")))?;
    if desc.devices.is_empty() {
        return Err(MasterError::Usage(format!(
            "--sim {spec:?} names no devices: give NAME:COUNT, e.g. demo:2"
        )));
    }
    let (seg, _) = crate::sim_cmd::build_segment(&desc)
        .map_err(|e| MasterError::Usage(format!("--sim: {e}")))?;
    Ok(Arc::new(Mutex::new(seg)))
}

/// Opens the master on `link` (an interface or an in-process `--sim` segment).
pub(crate) fn open(link: &LinkArgs) -> Result<Master, MasterError> {
    if let Some(spec) = &link.sim {
        return Master::open(Link::Sim(build_sim(spec)?));
    }
    let target = match &link.udp {
        Some(addr) => Link::Udp(addr.clone()),
        None => Link::Iface(link
        .iface
        .clone()
        .or_else(|| std::env::var("OXICAT_IFACE").ok())
        .ok_or_else(|| {
            MasterError::Usage(
                "no network interface: give --iface <if> (or set OXICAT_IFACE), --udp <host:port> for a segment served with `oxicat sim --udp`, or --sim demo:2 for a virtual segment"
                    .into(),
            )
        })?),
    };
    let timeout_ms = match link.timeout {
        Some(ms) => Some(ms),
        None => match std::env::var("OXICAT_TIMEOUT_MS") {
            Ok(v) => Some(v.trim().parse::<u64>().map_err(|_| {
                MasterError::Usage(format!(
                    "OXICAT_TIMEOUT_MS={v:?} is not a number of milliseconds"
                ))
            })?),
            Err(_) => None,
        },
    };
    let link = target;
    let mut options = MasterOptions::for_link(&link);
    if let Some(ms) = timeout_ms {
        if ms == 0 {
            return Err(MasterError::Usage("--timeout must be at least 1 ms".into()));
        }
        let pdu = std::time::Duration::from_millis(ms);
        options.timeouts.pdu = pdu;
        options.timeouts.eeprom = options.timeouts.eeprom.max(pdu * 2);
        options.timeouts.mailbox_response = options.timeouts.mailbox_response.max(pdu * 8);
        options.mailbox_timeout = options.mailbox_timeout.max(pdu * 8);
    }
    Master::open_with(link, options)
}

fn one(m: &Master, pos: &PosArgs) -> Result<usize, MasterError> {
    let p = pos.position.unwrap_or(0);
    m.address(p)?;
    Ok(p)
}

fn idx(s: &str) -> Result<u16, MasterError> {
    parse_u16(s).ok_or_else(|| MasterError::Usage(format!("not an index/address: {s:?}")))
}

fn sub(s: &str) -> Result<u8, MasterError> {
    parse_int(s)
        .and_then(|v| u8::try_from(v).ok())
        .ok_or_else(|| MasterError::Usage(format!("not a subindex: {s:?}")))
}

/// The bit length of `index:sub` from SDO information, if the slave tells.
fn sdo_bits(m: &Master, p: usize, index: u16, s: u8) -> Option<u16> {
    let o = m.sdo_describe(p, index).ok()?;
    o.entries.iter().find(|e| e.sub == s).map(|e| e.bits)
}

/// A fixed-size type must be the object's size (as in the IgH tool): `-t u8` of a 32-bit
/// object would show a quarter of it, `-t f64` of 4 bytes nothing but hex.
fn check_type_fits(t: ValueType, index: u16, sub: u8, len: usize) -> Result<(), MasterError> {
    match t.size() {
        Some(size) if size != len => Err(MasterError::Usage(format!(
            "0x{index:04X}:{sub:02X} holds {len} byte(s), type {t} is {size}: give the object's type (or none)"
        ))),
        _ => Ok(()),
    }
}

/// ESC registers and process RAM end at 0xFFFF: `address + length` past it is refused (a
/// slave cannot answer it), and so is length 0.
fn check_register_range(address: u16, len: usize) -> Result<(), MasterError> {
    if len == 0 {
        return Err(MasterError::Usage("length 0: give 1 … 65536 bytes".into()));
    }
    let end = usize::from(address) + len;
    if end > 0x1_0000 {
        return Err(MasterError::Usage(format!(
            "0x{address:04X} + {len} bytes ends at 0x{end:05X}, beyond the ESC's address space (registers and process RAM end at 0xFFFF)"
        )));
    }
    Ok(())
}

/// Where `sii-write` keeps the old image of slave `p`: `sii-backup-<p>.bin` in the current
/// directory, or `sii-backup-<p>-<k>.bin` when that exists (an earlier backup, maybe of the
/// original image, is never overwritten).
fn backup_path(p: usize) -> PathBuf {
    let first = PathBuf::from(format!("sii-backup-{p}.bin"));
    if !first.exists() {
        return first;
    }
    (1..)
        .map(|k| PathBuf::from(format!("sii-backup-{p}-{k}.bin")))
        .find(|f| !f.exists())
        .unwrap_or(first)
}

/// The type of `index:sub` from SDO information, if the slave tells.
fn sdo_type(m: &Master, p: usize, index: u16, s: u8) -> Option<ValueType> {
    let o = m.sdo_describe(p, index).ok()?;
    let e = o.entries.iter().find(|e| e.sub == s)?;
    ValueType::from_coe(e.data_type)
}

fn progress_bar(total: u64, what: &str) -> indicatif::ProgressBar {
    let pb = indicatif::ProgressBar::new(total);
    pb.set_style(
        indicatif::ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} ({eta} left)")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    pb.set_message(what.to_string());
    pb
}

/// Runs a master verb, writing its output to `out`.
pub fn run(cmd: MasterCommand, out: &mut dyn Write) -> Result<(), MasterError> {
    let w = |out: &mut dyn Write, s: &str| out.write_all(s.as_bytes()).map_err(MasterError::Output);
    match cmd {
        MasterCommand::Slaves { link, pos, verbose } => {
            let m = open(&link)?;
            let list = m.scan()?;
            if verbose {
                for s in list
                    .iter()
                    .filter(|s| pos.position.is_none_or(|p| p == s.position))
                {
                    w(out, &crate::igh_cmd::slave_verbose(s))?;
                }
                if let Some(p) = pos.position {
                    m.address(p)?;
                }
                return Ok(());
            }
            w(out, "pos  addr    alias   state                 vendor      product     revision    serial      ports            name\n")?;
            for s in list
                .iter()
                .filter(|s| pos.position.is_none_or(|p| p == s.position))
            {
                w(
                    out,
                    &format!(
                        "{:<4} 0x{:04x}  0x{:04x}  {:<21} 0x{:08x}  0x{:08x}  0x{:08x}  0x{:08x}  {}  {}\n",
                        s.position,
                        s.address,
                        s.alias,
                        s.status.to_string(),
                        s.vendor_id,
                        s.product_code,
                        s.revision,
                        s.serial,
                        s.ports(),
                        s.name
                    ),
                )?;
            }
            if let Some(p) = pos.position {
                m.address(p)?;
            }
            Ok(())
        }
        MasterCommand::States { state, link, pos } => {
            let st = oxicat_master::al::parse_state(&state).ok_or_else(|| {
                MasterError::Usage(format!(
                    "unknown state {state:?}; one of INIT, PREOP, SAFEOP, OP, BOOT"
                ))
            })?;
            let mut m = open(&link)?;
            let ps = m.positions(pos.position)?;
            // SAFEOP/OP: free run (0x1C32:01 = 0, SYNC0 off); say what each slave runs.
            let sync = matches!(st, AlState::SafeOp | AlState::Op);
            for (p, s) in m.request_state(&ps, st)? {
                // Read 0x1C32 only where it matters (each read is mailbox traffic).
                let mode = match (sync, if sync { m.sync_mode(p)? } else { None }) {
                    (false, _) => String::new(),
                    (true, Some(0)) => ", free run (0x1C32:01 = 0)".into(),
                    (true, Some(1)) => match m.sync_modes_supported(p)? {
                        Some(s) if s & 1 == 0 => format!(
                            ", SM2 synchronous (0x1C32:01 = 1): the slave does not run free (0x1C32:04 = 0x{s:04X})"
                        ),
                        _ => ", SM2 synchronous (0x1C32:01 = 1)".into(),
                    },
                    (true, Some(2)) => ", DC SYNC0 (0x1C32:01 = 2)".into(),
                    (true, Some(3)) => ", DC SYNC1 (0x1C32:01 = 3)".into(),
                    (true, Some(v)) => format!(", sync mode 0x1C32:01 = {v}"),
                    (true, None) => ", free run (no 0x1C32)".into(),
                };
                w(out, &format!("{p}: {s}{mode}\n"))?;
            }
            Ok(())
        }
        MasterCommand::SiiRead {
            link,
            pos,
            raw,
            hex,
            decode: _,
            full,
            output,
        } => {
            let m = open(&link)?;
            let p = one(&m, &pos)?;
            let img = m.sii_read(p, full || raw)?;
            let bytes = if raw {
                img
            } else if hex {
                oxicat_master::sii::hex_dump(&img).into_bytes()
            } else {
                oxicat_master::sii::decode(&img)?.into_bytes()
            };
            crate::output::write_output(output.as_deref(), &bytes, out)
        }
        MasterCommand::SiiWrite {
            link,
            pos,
            file,
            device,
            force,
        } => {
            let img = match (file, device) {
                (Some(f), _) => {
                    let b = std::fs::read(&f).map_err(|e| {
                        MasterError::Usage(format!("cannot read {}: {e}", f.display()))
                    })?;
                    if b.first() == Some(&b':') {
                        oxicat_esi::sii::intel_hex(&b)
                            .map_err(|e| MasterError::SiiImage(e.to_string()))?
                    } else {
                        b
                    }
                }
                (None, Some(d)) => crate::device_output(&d, crate::DeviceOutput::Sii)
                    .map_err(|_| MasterError::UnknownDevice(d))?,
                (None, None) => {
                    return Err(MasterError::Usage(
                        "give an image file or --device <name>".into(),
                    ))
                }
            };
            oxicat_master::sii::check_image(&img)?;
            let m = open(&link)?;
            let p = one(&m, &pos)?;
            // Refused before a word is written: an image the EEPROM cannot hold.
            let size = m.eeprom_bytes(p)?;
            if img.len() > size {
                return Err(MasterError::SiiImage(format!(
                    "{} bytes do not fit slave {p}'s EEPROM of {size} bytes (SII word 0x3E, ESC 0x0502 bit 7); nothing was written",
                    img.len()
                )));
            }
            // An image for another device is refused before anything (the backup too).
            let image = oxicat_master::sii::image_identity(&img)?;
            let (v, pc, r, _) = m.identity(p)?;
            if image != (v, pc, r) && !force {
                return Err(MasterError::SiiOtherDevice {
                    position: p,
                    image,
                    slave: (v, pc, r),
                });
            }
            // The old image first, so a write that stops half-way can be undone.
            let old = m.sii_read(p, true)?;
            let backup = backup_path(p);
            crate::output::write_file(&backup, &old)?;
            let restore = format!(
                "the EEPROM of slave {p} is half written; the old image is in {b}: restore it with `oxicat sii-write -p {p} --force {b}` (and the same --iface/--sim)",
                b = backup.display()
            );
            let ctrl_c = crate::interrupt::say_on_ctrl_c(restore.clone());
            let pb = progress_bar((img.len() / 2) as u64, "writing SII");
            let mut written = 0usize;
            let r = m.sii_write(
                p,
                &img,
                oxicat_master::sii::WriteOptions { force },
                &mut |d, _| {
                    written = d;
                    pb.set_position(d as u64)
                },
            );
            pb.finish_and_clear();
            drop(ctrl_c);
            match r {
                Err(e) if written > 0 => {
                    return Err(MasterError::Usage(format!(
                        "{e}\n{restore} ({written} of {} words were written)",
                        img.len() / 2
                    )))
                }
                r => r?,
            }
            w(
                out,
                &format!(
                    "slave {p}: wrote and verified {} bytes of SII (the old image is in {})\n",
                    img.len(),
                    backup.display()
                ),
            )
        }
        MasterCommand::Upload {
            link,
            pos,
            index,
            sub: s,
            r#type,
        } => {
            let (i, s) = (idx(&index)?, sub(&s)?);
            let m = open(&link)?;
            let p = one(&m, &pos)?;
            let data = m.sdo_upload(p, i, s)?;
            let ty = match r#type {
                Some(t) => {
                    let t = ValueType::parse(&t)?;
                    check_type_fits(t, i, s, data.len())?;
                    t
                }
                None => sdo_type(&m, p, i, s).unwrap_or(match data.len() {
                    1 => ValueType::U8,
                    2 => ValueType::U16,
                    4 => ValueType::U32,
                    8 => ValueType::U64,
                    _ => ValueType::Hex,
                }),
            };
            w(out, &format!("{}\n", ty.format(&data)))
        }
        MasterCommand::Download {
            link,
            pos,
            index,
            sub: s,
            value,
            r#type,
        } => {
            let (i, s) = (idx(&index)?, sub(&s)?);
            // A type given on the command line is checked before the bus is touched.
            let given = r#type.map(|t| ValueType::parse(&t)).transpose()?;
            if let Some(t) = given {
                t.encode(&value)?;
            }
            let m = open(&link)?;
            let p = one(&m, &pos)?;
            let ty = match given {
                Some(t) => {
                    if let Some(bits) = sdo_bits(&m, p, i, s) {
                        check_type_fits(t, i, s, usize::from(bits).div_ceil(8))?;
                    }
                    t
                }
                None => sdo_type(&m, p, i, s).ok_or_else(|| {
                    MasterError::Usage(format!(
                        "the type of 0x{i:04X}:{s:02X} is not known from the slave; give --type ({})",
                        ValueType::NAMES
                    ))
                })?,
            };
            let data = ty.encode(&value)?;
            m.sdo_download(p, i, s, &data)
        }
        MasterCommand::Sdos { link, pos } => {
            // The IgH tool's layout: `SDO 0x1018, "Identity"` and per entry
            // `  0x1018:01, r-r-r-, uint32, 32 bit, "Vendor ID"` (read/write per PREOP,
            // SAFEOP, OP), so a listing pastes from one tool into the other.
            let m = open(&link)?;
            let ps = m.positions(pos.position)?;
            for &p in &ps {
                if ps.len() > 1 {
                    w(out, &format!("=== Master 0, Slave {p} ===\n"))?;
                }
                for o in m.dictionary(p)? {
                    w(out, &format!("SDO 0x{:04x}, \"{}\"\n", o.index, o.name))?;
                    for e in &o.entries {
                        w(
                            out,
                            &format!(
                                "  0x{:04x}:{:02x}, {}, {}, {} bit, \"{}\"\n",
                                o.index,
                                e.sub,
                                e.igh_access(),
                                oxicat_master::coe::igh_type_name(e.data_type),
                                e.bits,
                                e.name
                            ),
                        )?;
                    }
                }
            }
            Ok(())
        }
        MasterCommand::Pdos { link, pos } => {
            let m = open(&link)?;
            let ps = m.positions(pos.position)?;
            for &p in &ps {
                let l = m.pdos(p)?;
                // The sync managers from the SII, as the IgH tool shows them.
                let sms = m.sii_model(p).map(|d| d.sms).unwrap_or_default();
                w(out, &crate::igh_cmd::pdos_text(p, ps.len() > 1, &sms, &l))?;
            }
            Ok(())
        }
        MasterCommand::Cstruct {
            link,
            pos,
            rust,
            device,
        } => {
            if let Some(d) = device {
                let def =
                    crate::device_def(&d).map_err(|_| MasterError::UnknownDevice(d.clone()))?;
                let l = crate::igh_cmd::def_pdos(def);
                let id = &def.identity;
                let text = match rust {
                    true => crate::igh_cmd::rust_struct(
                        &d,
                        &format!("{d} ({}), default PDO assignment", def.name),
                        &l,
                    ),
                    false => crate::igh_cmd::c_struct(
                        pos.position.unwrap_or(0),
                        def.name,
                        (id.vendor_id, id.product_code, id.revision),
                        &l,
                    ),
                };
                return w(out, &text);
            }
            let m = open(&link)?;
            let infos = m.scan()?;
            for p in m.positions(pos.position)? {
                let l = m.pdos(p)?;
                let s = &infos[p];
                let text = match rust {
                    true => crate::igh_cmd::rust_struct(
                        &format!("slave{p}"),
                        &format!(
                            "slave {p}: {} (PDO mapping from {})",
                            s.name,
                            match l.source {
                                oxicat_master::pdo::PdoSource::Coe => "CoE",
                                oxicat_master::pdo::PdoSource::Sii => "the SII",
                            }
                        ),
                        &l,
                    ),
                    false => crate::igh_cmd::c_struct(
                        p,
                        &s.name,
                        (s.vendor_id, s.product_code, s.revision),
                        &l,
                    ),
                };
                w(out, &text)?;
                w(out, "\n")?;
            }
            Ok(())
        }
        MasterCommand::Data {
            link,
            binary,
            output,
        } => {
            let mut m = open(&link)?;
            let image = crate::igh_cmd::process_image(&mut m)?;
            let bytes = match binary {
                true => image,
                false => crate::igh_cmd::hex_lines(&image).into_bytes(),
            };
            crate::output::write_output(output.as_deref(), &bytes, out)
        }
        MasterCommand::Alias { link, pos, alias } => {
            let a = parse_u16(&alias).ok_or_else(|| {
                MasterError::Usage(format!("not an alias: {alias:?} (0 … 0xFFFF)"))
            })?;
            let m = open(&link)?;
            let p = one(&m, &pos)?;
            let now = m.sii_set_alias(p, a)?;
            let when = match now == a {
                true => "in effect (0x0012)".to_string(),
                false => {
                    format!("0x0012 still reads 0x{now:04x}: the ESC loads it at its next power-up")
                }
            };
            w(
                out,
                &format!(
                    "slave {p}: alias 0x{a:04x} written to the SII (word 4, CRC updated), {when}\n"
                ),
            )
        }
        MasterCommand::Graph { link, output } => {
            let m = open(&link)?;
            let dot = crate::igh_cmd::graph(&m.scan()?);
            crate::output::write_output(output.as_deref(), dot.as_bytes(), out)
        }
        MasterCommand::Xml { link, pos, output } => {
            let m = open(&link)?;
            let p = one(&m, &pos)?;
            let xml = m.esi(p)?;
            crate::output::write_output(output.as_deref(), xml.as_bytes(), out)
        }
        MasterCommand::RegRead {
            link,
            pos,
            address,
            length,
            r#type,
        } => {
            let a = idx(&address)?;
            let ty = r#type.map(|t| ValueType::parse(&t)).transpose()?;
            let len = match (&length, ty.and_then(|t| t.size())) {
                (Some(l), _) => idx(l)?,
                (None, Some(s)) => s as u16,
                (None, None) => 1,
            };
            check_register_range(a, usize::from(len))?;
            if let (Some(t), Some(size)) = (ty, ty.and_then(|t| t.size())) {
                if usize::from(len) != size {
                    return Err(MasterError::Usage(format!(
                        "type {t} is {size} byte(s), the length given is {len}: give one of them, or both alike"
                    )));
                }
            }
            let m = open(&link)?;
            let p = one(&m, &pos)?;
            let b = m.reg_read(p, a, len)?;
            match ty {
                Some(t) => w(out, &format!("{}\n", t.format(&b))),
                None => w(out, &format!("{}\n", oxicat_master::value::raw_bytes(&b))),
            }
        }
        MasterCommand::RegWrite {
            link,
            pos,
            address,
            value,
            r#type,
        } => {
            let a = idx(&address)?;
            let ty = match r#type {
                Some(t) => ValueType::parse(&t)?,
                None => ValueType::U8,
            };
            let data = ty.encode(&value)?;
            check_register_range(a, data.len())?;
            let m = open(&link)?;
            let p = one(&m, &pos)?;
            m.reg_write(p, a, &data)
        }
        MasterCommand::Watch {
            link,
            vars,
            cycle,
            every,
            count,
        } => {
            let cycle = parse_duration(&cycle)?;
            let mut m = open(&link)?;
            m.prepare_cyclic()?;
            let layouts = m.layouts()?;
            let vars = with_device_units(&m, m.resolve(&vars, &layouts)?.concat());
            let mut err = None;
            // A virtual segment runs as fast as the host can: show its lines at the pace of
            // the cycle (every × cycle per line) as on a real segment.
            let pace = link.sim.is_some();
            let started = std::time::Instant::now();
            let mut lines = 0u32;
            m.watch(
                CycleOptions { cycle, dc: false },
                &vars,
                every,
                count,
                &mut |line| {
                    lines += 1;
                    if pace {
                        let due = started + cycle * every.max(1) as u32 * lines;
                        if let Some(d) = due.checked_duration_since(std::time::Instant::now()) {
                            std::thread::sleep(d);
                        }
                    }
                    match writeln!(out, "{line}") {
                        Ok(()) => true,
                        Err(e) => {
                            err = Some(e);
                            false
                        }
                    }
                },
            )?;
            match err {
                Some(e) => Err(MasterError::Output(e)),
                None => Ok(()),
            }
        }
        MasterCommand::Write {
            link,
            var,
            value,
            cycle,
            settle,
        } => {
            let cycle = parse_duration(&cycle)?;
            let mut m = open(&link)?;
            m.prepare_cyclic()?;
            let layouts = m.layouts()?;
            let vars = with_device_units(
                &m,
                m.resolve(std::slice::from_ref(&var), &layouts)?.remove(0),
            );
            let data = vars[0].encode(&value)?;
            if let Some(v) = vars
                .iter()
                .find(|v| v.dir == oxicat_master::pdo::Dir::Input)
            {
                return Err(MasterError::Usage(format!(
                    "{} is an input (TxPDO) of slave {}; only outputs can be written",
                    var, v.position
                )));
            }
            let back = m.write_online(CycleOptions { cycle, dc: false }, &vars, &data, settle)?;
            for (v, b) in vars.iter().zip(back) {
                w(
                    out,
                    &format!(
                        "{}.{} = {b}\n",
                        v.position,
                        var.split_once('.').map(|x| x.1).unwrap_or(&var)
                    ),
                )?;
            }
            Ok(())
        }
        MasterCommand::Record {
            link,
            vars,
            cycle,
            duration,
            output,
            free_run,
        } => {
            // Every argument is checked before the output is touched; the CSV goes to a
            // temporary file renamed over `output` at the end, so a failure leaves it as it was.
            let cycle = parse_duration(&cycle)?;
            let duration = parse_duration(&duration)?;
            let opts = CycleOptions {
                cycle,
                dc: !free_run,
            };
            opts.check()?;
            if duration < cycle {
                return Err(MasterError::Usage(format!(
                    "--duration {duration:?} is shorter than one --cycle {cycle:?}"
                )));
            }
            let cycles = (duration.as_nanos() / cycle.as_nanos()) as u64;
            let mut m = open(&link)?;
            m.prepare_cyclic()?;
            let layouts = m.layouts()?;
            let vars = with_device_units(&m, m.resolve(&vars, &layouts)?.concat());
            let to_stdout = crate::output::is_stdout(&output);
            let mut file = match to_stdout {
                true => None,
                false => Some(crate::output::AtomicFile::create(&output)?),
            };
            let sink: &mut dyn Write = match &mut file {
                Some(f) => f,
                None => &mut *out,
            };
            let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
            let ctrl_c = crate::interrupt::stop_on_ctrl_c(stop.clone());
            let pb = progress_bar(cycles, "recording");
            let r = m.record_until(
                opts,
                &vars,
                cycles,
                sink,
                &mut |k, _| {
                    if k % 64 == 0 || k == cycles {
                        pb.set_position(k)
                    }
                },
                &stop,
            );
            pb.finish_and_clear();
            drop(ctrl_c);
            let stats = r?;
            let place = match file {
                Some(f) => {
                    f.commit()?;
                    output.display().to_string()
                }
                None => "standard output".to_string(),
            };
            let line = format!(
                "{} cycles of {} variables to {place} ({} working-counter errors){}\n",
                stats.cycles,
                vars.len(),
                stats.wkc_errors,
                if stats.cycles < cycles {
                    "; stopped by Ctrl-C"
                } else {
                    ""
                }
            );
            if to_stdout {
                eprint!("{line}");
                Ok(())
            } else {
                w(out, &line)
            }
        }
    }
}

/// Gives each variable the physical scaling its device declares (the registry's device with
/// the slave's vendor ID, product code and revision): `record` headers and values in units
/// (`0.hip_angle [deg]`, `-12.34`), `watch` values in units, `write` values given in units.
/// Slaves of other devices keep raw integers under their CoE type.
fn with_device_units(m: &Master, vars: Vec<Variable>) -> Vec<Variable> {
    vars.into_iter()
        .map(|v| {
            let scale = m
                .identity(v.position)
                .ok()
                .and_then(|(vendor, product, rev, _)| {
                    let kit = oxicat_devices::registry::by_identity(vendor, product, rev)?;
                    (kit.def)(0).scale(v.object.0, v.object.1)
                });
            match scale {
                Some(s) => v.with_scale(s),
                None => v,
            }
        })
        .collect()
}
