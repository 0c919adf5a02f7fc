//! The master verbs of `oxicat`, after the IgH `ethercat` tool: `slaves`, `scan`, `states`,
//! `sii-read`, `sii-write`, `alias`, `upload`, `download`, `sdos`, `pdos`, `cstruct`,
//! `data`, `graph`, `xml`, `reg-read`, `reg-write`, `watch`, `write`, `record`. Each runs on `--iface <if>` (or `OXICAT_IFACE`),
//! on a segment served with EtherCAT over UDP `--udp host:port`, or, for tests and trying
//! things out, on an in-process virtual segment `--sim demo:2`.
//!
//! `--sim` knows the devices of `oxicat sim --list` (one registry, `oxicat_devices::registry`).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use clap::{Args, Subcommand};
use oxicat_master::cyclic::{CycleOptions, Cycling, Exchange, SyncMode};
use oxicat_master::pdo::Variable;
use oxicat_master::value::{parse_int, parse_u16, ValueType};
use oxicat_master::{AlState, Link, Master, MasterError, MasterOptions};

use crate::{CliError, UsageError};

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

/// The master verbs, each with its arguments (`SlavesArgs`, …, whose fields are documented
/// by their `--help` text); [`run`] hands them to the verb's function.
#[derive(Debug, Subcommand)]
pub enum MasterCommand {
    /// List the slaves: position, address, alias, AL state, name, identity, ports.
    Slaves(SlavesArgs),
    /// Read every slave (identity, SII, CoE dictionary); with --save DIR record the machine
    /// so that `oxicat sim --segment DIR` serves it again.
    Scan(crate::scan_cmd::ScanArgs),
    /// Request an AL state (INIT, PREOP, SAFEOP, OP, BOOT) for all slaves or one.
    States(StatesArgs),
    /// Read a slave's SII EEPROM (decoded by default).
    #[command(alias = "sii_read")]
    SiiRead(SiiReadArgs),
    /// Write an SII image (a file, or one generated for a device) and verify it.
    #[command(alias = "sii_write")]
    SiiWrite(SiiWriteArgs),
    /// SDO upload (read) of index:subindex.
    Upload(UploadArgs),
    /// SDO download (write) of a typed value to index:subindex.
    Download(DownloadArgs),
    /// List the CoE dictionary (SDO information).
    Sdos(SdosArgs),
    /// Show the PDO assignment and mapping.
    Pdos(PdosArgs),
    /// The PDO configuration as C arrays for the IgH application interface (`ecrt.h`), as
    /// `ethercat cstruct`; with --rust as structs for ethercrab's wire derive.
    Cstruct(CstructArgs),
    /// The process-data image, as `ethercat data`: the slaves are brought to OP, cycle a few
    /// times, and the image of the last cycle is shown (slave by slave: outputs, then inputs).
    Data(DataArgs),
    /// Write the station alias into a slave's SII (word 4, with the configuration-area CRC),
    /// as `ethercat alias`; the ESC reloads it into 0x0012.
    Alias(AliasArgs),
    /// The topology as Graphviz DOT (ports and links from the DL status), as `ethercat graph`.
    Graph(GraphArgs),
    /// Write an ESI (EtherCATInfo XML) for a live slave.
    Xml(XmlArgs),
    /// Read ESC registers (FPRD).
    #[command(alias = "reg_read")]
    RegRead(RegReadArgs),
    /// Write ESC registers (FPWR).
    #[command(alias = "reg_write")]
    RegWrite(RegWriteArgs),
    /// Show process-data variables live (`<pos>.<entry>` or `<device>.<entry>`).
    Watch(WatchArgs),
    /// Write a process-data output while cycling (to every slave the name links).
    Write(WriteArgs),
    /// Record variables every cycle (DC-synchronous) into a CSV file.
    Record(RecordArgs),
}

/// The arguments of `slaves`.
#[allow(missing_docs)]
#[derive(Debug, Args)]
pub struct SlavesArgs {
    #[command(flatten)]
    pub link: LinkArgs,
    #[command(flatten)]
    pub pos: PosArgs,
    /// Verbose: a block per slave (identity, state, ports, DC delay), as `ethercat slaves -v`.
    #[arg(long, short = 'v')]
    pub verbose: bool,
}

/// The arguments of `states`.
#[allow(missing_docs)]
#[derive(Debug, Args)]
pub struct StatesArgs {
    /// INIT | PREOP | SAFEOP | OP | BOOT.
    pub state: String,
    #[command(flatten)]
    pub link: LinkArgs,
    #[command(flatten)]
    pub pos: PosArgs,
}

/// The arguments of `sii-read`.
#[allow(missing_docs)]
#[derive(Debug, Args)]
pub struct SiiReadArgs {
    #[command(flatten)]
    pub link: LinkArgs,
    #[command(flatten)]
    pub pos: PosArgs,
    /// Raw binary to standard output (or -o).
    #[arg(long, conflicts_with_all = ["hex", "decode"])]
    pub raw: bool,
    /// Hex dump.
    #[arg(long, conflicts_with = "decode")]
    pub hex: bool,
    /// Decoded categories (default).
    #[arg(long)]
    pub decode: bool,
    /// The whole EEPROM, not only up to the end of the categories.
    #[arg(long)]
    pub full: bool,
    /// Output file.
    #[arg(long, short = 'o')]
    pub output: Option<PathBuf>,
}

/// The arguments of `sii-write`.
#[allow(missing_docs)]
#[derive(Debug, Args)]
pub struct SiiWriteArgs {
    #[command(flatten)]
    pub link: LinkArgs,
    #[command(flatten)]
    pub pos: PosArgs,
    /// Image file (binary or Intel HEX).
    pub file: Option<PathBuf>,
    /// Generate the image of this device (see `oxicat device`).
    #[arg(long, conflicts_with = "file")]
    pub device: Option<String>,
    /// Write even when the image's identity differs from the slave's.
    #[arg(long)]
    pub force: bool,
}

/// The arguments of `upload`.
#[allow(missing_docs)]
#[derive(Debug, Args)]
pub struct UploadArgs {
    #[command(flatten)]
    pub link: LinkArgs,
    #[command(flatten)]
    pub pos: PosArgs,
    /// Object index (0x1018).
    pub index: String,
    /// Subindex.
    pub sub: String,
    /// Value type (default: from SDO information, else by size).
    #[arg(long, short = 't')]
    pub r#type: Option<String>,
}

/// The arguments of `download`.
#[allow(missing_docs)]
#[derive(Debug, Args)]
pub struct DownloadArgs {
    #[command(flatten)]
    pub link: LinkArgs,
    #[command(flatten)]
    pub pos: PosArgs,
    /// Object index.
    pub index: String,
    /// Subindex.
    pub sub: String,
    /// The value.
    #[arg(allow_hyphen_values = true)]
    pub value: String,
    /// Value type (default: from SDO information).
    #[arg(long, short = 't')]
    pub r#type: Option<String>,
}

/// The arguments of `sdos`.
#[allow(missing_docs)]
#[derive(Debug, Args)]
pub struct SdosArgs {
    #[command(flatten)]
    pub link: LinkArgs,
    #[command(flatten)]
    pub pos: PosArgs,
}

/// The arguments of `pdos`.
#[allow(missing_docs)]
#[derive(Debug, Args)]
pub struct PdosArgs {
    #[command(flatten)]
    pub link: LinkArgs,
    #[command(flatten)]
    pub pos: PosArgs,
}

/// The arguments of `cstruct`.
#[allow(missing_docs)]
#[derive(Debug, Args)]
pub struct CstructArgs {
    #[command(flatten)]
    pub link: LinkArgs,
    #[command(flatten)]
    pub pos: PosArgs,
    /// Rust structs (`EtherCrabWireReadWrite`) for the output and input images instead.
    #[arg(long)]
    pub rust: bool,
    /// From a device definition's default PDO assignment (see `oxicat device list`),
    /// without a bus.
    #[arg(long, conflicts_with_all = ["iface", "sim", "udp"])]
    pub device: Option<String>,
}

/// The arguments of `data`.
#[allow(missing_docs)]
#[derive(Debug, Args)]
pub struct DataArgs {
    #[command(flatten)]
    pub link: LinkArgs,
    /// Raw bytes instead of a hex dump.
    #[arg(long)]
    pub binary: bool,
    /// Output file (default: standard output).
    #[arg(long, short = 'o')]
    pub output: Option<PathBuf>,
}

/// The arguments of `alias`.
#[allow(missing_docs)]
#[derive(Debug, Args)]
pub struct AliasArgs {
    #[command(flatten)]
    pub link: LinkArgs,
    #[command(flatten)]
    pub pos: PosArgs,
    /// The alias, 0 … 0xFFFF (0: none).
    pub alias: String,
}

/// The arguments of `graph`.
#[allow(missing_docs)]
#[derive(Debug, Args)]
pub struct GraphArgs {
    #[command(flatten)]
    pub link: LinkArgs,
    /// Output file (default: standard output).
    #[arg(long, short = 'o')]
    pub output: Option<PathBuf>,
}

/// The arguments of `xml`.
#[allow(missing_docs)]
#[derive(Debug, Args)]
pub struct XmlArgs {
    #[command(flatten)]
    pub link: LinkArgs,
    #[command(flatten)]
    pub pos: PosArgs,
    /// Output file.
    #[arg(long, short = 'o')]
    pub output: Option<PathBuf>,
}

/// The arguments of `reg-read`.
#[allow(missing_docs)]
#[derive(Debug, Args)]
pub struct RegReadArgs {
    #[command(flatten)]
    pub link: LinkArgs,
    #[command(flatten)]
    pub pos: PosArgs,
    /// Address.
    pub address: String,
    /// Length in bytes (default: the type's size, else 1).
    pub length: Option<String>,
    /// Show as this type.
    #[arg(long, short = 't')]
    pub r#type: Option<String>,
}

/// The arguments of `reg-write`.
#[allow(missing_docs)]
#[derive(Debug, Args)]
pub struct RegWriteArgs {
    #[command(flatten)]
    pub link: LinkArgs,
    #[command(flatten)]
    pub pos: PosArgs,
    /// Address.
    pub address: String,
    /// Value (hex bytes with --type hex).
    #[arg(allow_hyphen_values = true)]
    pub value: String,
    /// Value type (default u8).
    #[arg(long, short = 't')]
    pub r#type: Option<String>,
}

/// The arguments of `watch`.
#[allow(missing_docs)]
#[derive(Debug, Args)]
pub struct WatchArgs {
    #[command(flatten)]
    pub link: LinkArgs,
    /// Variables.
    #[arg(required = true)]
    pub vars: Vec<String>,
    /// Cycle time (e.g. 1ms, 400us).
    #[arg(long, default_value = "1ms")]
    pub cycle: String,
    /// Refresh every this many cycles.
    #[arg(long, default_value_t = 100)]
    pub every: u64,
    /// Stop after this many refreshes (0: until Ctrl-C).
    #[arg(long, default_value_t = 0)]
    pub count: u64,
    /// Sync mode (0x1C32:01) of every slave; refused when a slave's 0x1C32:04 does not
    /// offer it. Default: free run, or SM-synchronous where that is all a slave offers.
    #[arg(long, value_enum)]
    pub sync: Option<SyncArg>,
}

/// The arguments of `write`.
#[allow(missing_docs)]
#[derive(Debug, Args)]
pub struct WriteArgs {
    #[command(flatten)]
    pub link: LinkArgs,
    /// Variable.
    pub var: String,
    /// Value.
    #[arg(allow_hyphen_values = true)]
    pub value: String,
    /// Cycle time.
    #[arg(long, default_value = "1ms")]
    pub cycle: String,
    /// Cycles to keep cycling after the write.
    #[arg(long, default_value_t = 20)]
    pub settle: u64,
    /// Sync mode (0x1C32:01) of every slave, as for `watch`.
    #[arg(long, value_enum)]
    pub sync: Option<SyncArg>,
}

/// The arguments of `record`.
#[allow(missing_docs)]
#[derive(Debug, Args)]
pub struct RecordArgs {
    #[command(flatten)]
    pub link: LinkArgs,
    /// Variables.
    #[arg(required = true)]
    pub vars: Vec<String>,
    /// Cycle time.
    #[arg(long, default_value = "1ms")]
    pub cycle: String,
    /// Duration (e.g. 10s, 500ms).
    #[arg(long, default_value = "1s")]
    pub duration: String,
    /// Output CSV.
    #[arg(long, short = 'o')]
    pub output: PathBuf,
    /// Free run instead of DC SYNC0 (SM-synchronous where that is all a slave offers).
    #[arg(long, conflicts_with = "sync")]
    pub free_run: bool,
    /// Sync mode (0x1C32:01) of every slave instead of DC SYNC0 where the ESC has it;
    /// refused, naming the slave, when its 0x1C32:04 does not offer it.
    #[arg(long, value_enum)]
    pub sync: Option<SyncArg>,
    /// How a free-running or SM-synchronous cycle exchanges the process image (default:
    /// auto, the lean exchange where ethercrab's would need more than one frame). `overlap`
    /// puts every slave's inputs on its outputs' logical bytes (SOEM's overlapped IO map):
    /// an LRW then carries max(outputs, inputs) bytes per slave instead of their sum. A DC
    /// cycle is ethercrab's tx_rx_dc and takes no --exchange.
    #[arg(long, value_enum)]
    pub exchange: Option<ExchangeArg>,
}

/// `--exchange` of `record`: [`Exchange`] by name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ExchangeArg {
    /// The lean exchange where ethercrab's would need more than one frame.
    Auto,
    /// The image in LRWs of up to 1,100 bytes sent together, and one BRD of AL status.
    Lean,
    /// Lean, with every slave's inputs on its outputs' bytes.
    Overlap,
    /// ethercrab's tx_rx: frames one after the other, an FPRD of AL status per slave.
    Ethercrab,
}

impl From<ExchangeArg> for Exchange {
    fn from(a: ExchangeArg) -> Self {
        match a {
            ExchangeArg::Auto => Exchange::Auto,
            ExchangeArg::Lean => Exchange::Lean,
            ExchangeArg::Overlap => Exchange::Overlapped,
            ExchangeArg::Ethercrab => Exchange::Ethercrab,
        }
    }
}

/// `--sync` of the cyclic verbs: the sync mode every slave gets (ETG.1020 0x1C32:01).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SyncArg {
    /// Free run (0x1C32:01 = 0).
    FreeRun,
    /// SM-synchronous: the slave's cycle on the SM2 event (0x1C32:01 = 1).
    SmSync,
    /// DC SYNC0-synchronous (0x1C32:01 = 2).
    Dc,
}

impl From<SyncArg> for SyncMode {
    fn from(a: SyncArg) -> Self {
        match a {
            SyncArg::FreeRun => SyncMode::FreeRun,
            SyncArg::SmSync => SyncMode::SmSync,
            SyncArg::Dc => SyncMode::Dc,
        }
    }
}

/// The cycling of a cyclic verb: `opts` with the `--sync` mode, if given.
fn cycling(opts: CycleOptions, sync: Option<SyncArg>) -> Cycling {
    opts.with_sync(sync.map_or(SyncMode::Auto, SyncMode::from))
}

/// Parses `400us`, `1ms`, `10s`, `250ns`, `2m`.
pub fn parse_duration(s: &str) -> Result<Duration, UsageError> {
    let t = s.trim();
    let split = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let v: f64 = num
        .parse()
        .map_err(|_| UsageError::NotADuration(s.to_string()))?;
    let ns = match unit.trim() {
        "ns" => v,
        "us" | "µs" => v * 1e3,
        "ms" => v * 1e6,
        "s" | "" => v * 1e9,
        "m" | "min" => v * 60e9,
        u => {
            return Err(UsageError::UnknownTimeUnit {
                unit: u.to_string(),
                value: s.to_string(),
            })
        }
    };
    Ok(Duration::from_nanos(ns.round() as u64))
}

/// Most slaves of an in-process segment with the master beside it: what a served segment
/// holds and what the master's group holds.
pub const MAX_IN_PROCESS_SLAVES: usize =
    if oxicat_master::MAX_SLAVES < crate::sim_cmd::MAX_SIM_SLAVES {
        oxicat_master::MAX_SLAVES
    } else {
        crate::sim_cmd::MAX_SIM_SLAVES
    };

/// The in-process segment of `--sim`: the devices of `oxicat sim --list`, in the same syntax
/// (`demo:2,tue-es030:1` or `"demo:2 tue-es030:1"`), at most what a served segment holds
/// ([`crate::sim_cmd::MAX_SIM_SLAVES`]) and the master's group holds
/// ([`oxicat_master::MAX_SLAVES`]), checked before anything is built.
pub fn build_sim(spec: &str) -> Result<Arc<Mutex<oxicat_sim::segment::Segment>>, UsageError> {
    let max = MAX_IN_PROCESS_SLAVES;
    let range = format!("1 … {max} slaves in all");
    let desc = crate::sim_cmd::parse_specs_within(&[spec.to_string()], max, &range)
        .map_err(UsageError::Sim)?;
    if desc.devices.is_empty() {
        return Err(UsageError::SimNoDevices(spec.to_string()));
    }
    let (seg, _) = crate::sim_cmd::build_segment(&desc).map_err(UsageError::Sim)?;
    Ok(Arc::new(Mutex::new(seg)))
}

/// Opens the master on `link` (an interface or an in-process `--sim` segment).
pub(crate) fn open(link: &LinkArgs) -> Result<Master, CliError> {
    if let Some(spec) = &link.sim {
        return Ok(Master::open(Link::Sim(build_sim(spec)?))?);
    }
    let target = match &link.udp {
        Some(addr) => Link::Udp(addr.clone()),
        None => Link::Iface(
            link.iface
                .clone()
                .or_else(|| std::env::var("OXICAT_IFACE").ok())
                .ok_or(UsageError::NoLink)?,
        ),
    };
    let timeout_ms = match link.timeout {
        Some(ms) => Some(ms),
        None => match std::env::var("OXICAT_TIMEOUT_MS") {
            Ok(v) => Some(
                v.trim()
                    .parse::<u64>()
                    .map_err(|_| UsageError::TimeoutEnv(v.clone()))?,
            ),
            Err(_) => None,
        },
    };
    let link = target;
    let mut options = MasterOptions::for_link(&link);
    if let Some(ms) = timeout_ms {
        if ms == 0 {
            return Err(UsageError::ZeroTimeout.into());
        }
        let pdu = std::time::Duration::from_millis(ms);
        options.timeouts.pdu = pdu;
        options.timeouts.eeprom = options.timeouts.eeprom.max(pdu * 2);
        options.timeouts.mailbox_response = options.timeouts.mailbox_response.max(pdu * 8);
        options.mailbox_timeout = options.mailbox_timeout.max(pdu * 8);
    }
    Ok(Master::open_with(link, options)?)
}

fn one(m: &Master, pos: &PosArgs) -> Result<usize, MasterError> {
    let p = pos.position.unwrap_or(0);
    m.address(p)?;
    Ok(p)
}

fn idx(s: &str) -> Result<u16, UsageError> {
    parse_u16(s).ok_or_else(|| UsageError::NotAnIndex(s.to_string()))
}

fn sub(s: &str) -> Result<u8, UsageError> {
    parse_int(s)
        .and_then(|v| u8::try_from(v).ok())
        .ok_or_else(|| UsageError::NotASubindex(s.to_string()))
}

/// The bit length of `index:sub` from SDO information, if the slave tells.
fn sdo_bits(m: &Master, p: usize, index: u16, s: u8) -> Option<u16> {
    let o = m.sdo_describe(p, index).ok()?;
    o.entries.iter().find(|e| e.sub == s).map(|e| e.bits)
}

/// A fixed-size type must be the object's size (as in the IgH tool): `-t u8` of a 32-bit
/// object would show a quarter of it, `-t f64` of 4 bytes nothing but hex.
fn check_type_fits(t: ValueType, index: u16, sub: u8, len: usize) -> Result<(), UsageError> {
    match t.size() {
        Some(size) if size != len => Err(UsageError::ObjectSize {
            index,
            sub,
            len,
            ty: t,
            size,
        }),
        _ => Ok(()),
    }
}

/// ESC registers and process RAM end at 0xFFFF: `address + length` past it is refused (a
/// slave cannot answer it), and so is length 0.
fn check_register_range(address: u16, len: usize) -> Result<(), UsageError> {
    if len == 0 {
        return Err(UsageError::ZeroLength);
    }
    if usize::from(address) + len > 0x1_0000 {
        return Err(UsageError::BeyondAddressSpace { address, len });
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

/// What `sii-write` says when it stops half-way (an error, or Ctrl-C): where the old image
/// of slave `p` is and how to write it back.
pub fn restore_hint(p: usize, backup: &Path) -> String {
    format!(
        "the EEPROM of slave {p} is half written; the old image is in {b}: restore it with `oxicat sii-write -p {p} --force {b}` (and the same --iface/--sim)",
        b = backup.display()
    )
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

/// Writes `s` to the verb's output (a closed output is [`MasterError::Output`], which the
/// binary takes for a reader that has had enough).
fn w(out: &mut dyn Write, s: &str) -> Result<(), CliError> {
    Ok(out.write_all(s.as_bytes()).map_err(MasterError::Output)?)
}

/// Runs a master verb, writing its output to `out`: one function per verb below, each of
/// which checks its arguments before it opens the link or touches a file.
pub fn run(cmd: MasterCommand, out: &mut dyn Write) -> Result<(), CliError> {
    use MasterCommand as C;
    match cmd {
        C::Slaves(a) => slaves(a, out),
        C::Scan(a) => crate::scan_cmd::scan(a, out),
        C::States(a) => states(a, out),
        C::SiiRead(a) => sii_read(a, out),
        C::SiiWrite(a) => sii_write(a, out),
        C::Upload(a) => upload(a, out),
        C::Download(a) => download(a),
        C::Sdos(a) => sdos(a, out),
        C::Pdos(a) => pdos(a, out),
        C::Cstruct(a) => cstruct(a, out),
        C::Data(a) => data(a, out),
        C::Alias(a) => alias(a, out),
        C::Graph(a) => graph(a, out),
        C::Xml(a) => xml(a, out),
        C::RegRead(a) => reg_read(a, out),
        C::RegWrite(a) => reg_write(a),
        C::Watch(a) => watch(a, out),
        C::Write(a) => write(a, out),
        C::Record(a) => record(a, out),
    }
}

/// `slaves [-v]`: a line per slave (verbose: a block per slave); with `-p`, a position that
/// is not there is an error after the listing.
fn slaves(a: SlavesArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let SlavesArgs { link, pos, verbose } = a;
    let m = open(&link)?;
    let list = m.scan()?;
    let shown = list
        .iter()
        .filter(|s| pos.position.is_none_or(|p| p == s.position));
    if verbose {
        for s in shown {
            w(out, &crate::igh_cmd::slave_verbose(s))?;
        }
    } else {
        w(out, "pos  addr    alias   state                 vendor      product     revision    serial      ports            name\n")?;
        for s in shown {
            w(out, &slave_line(s))?;
        }
    }
    if let Some(p) = pos.position {
        m.address(p)?;
    }
    Ok(())
}

/// A slave's line of `slaves`.
fn slave_line(s: &oxicat_master::SlaveInfo) -> String {
    format!(
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
    )
}

/// `states <STATE>`: requests it of every slave (or `-p`'s) and says where each got, and in
/// SAFEOP/OP how it synchronises.
fn states(a: StatesArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let StatesArgs { state, link, pos } = a;
    let st = oxicat_master::al::parse_state(&state)
        .ok_or_else(|| UsageError::UnknownState(state.to_string()))?;
    let mut m = open(&link)?;
    let ps = m.positions(pos.position)?;
    // SAFEOP/OP: free run (0x1C32:01 = 0, SYNC0 off); say what each slave runs.
    let sync = matches!(st, AlState::SafeOp | AlState::Op);
    for (p, s) in m.request_state(&ps, st)? {
        let mode = match sync {
            true => sync_mode_text(&m, p)?,
            false => String::new(),
        };
        w(out, &format!("{p}: {s}{mode}\n"))?;
    }
    Ok(())
}

/// What slave `p` runs in SAFEOP/OP, from 0x1C32 (read only there: each read is mailbox
/// traffic).
fn sync_mode_text(m: &Master, p: usize) -> Result<String, MasterError> {
    Ok(match m.sync_mode(p)? {
        Some(0) => ", free run (0x1C32:01 = 0)".into(),
        Some(1) => match m.sync_modes_supported(p)? {
            Some(s) if s & 1 == 0 => format!(
                ", SM2 synchronous (0x1C32:01 = 1): the slave does not run free (0x1C32:04 = 0x{s:04X})"
            ),
            _ => ", SM2 synchronous (0x1C32:01 = 1)".into(),
        },
        Some(2) => ", DC SYNC0 (0x1C32:01 = 2)".into(),
        Some(3) => ", DC SYNC1 (0x1C32:01 = 3)".into(),
        Some(v) => format!(", sync mode 0x1C32:01 = {v}"),
        None => ", free run (no 0x1C32)".into(),
    })
}

/// `sii-read`: the EEPROM decoded, as a hex dump or raw.
fn sii_read(a: SiiReadArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let SiiReadArgs {
        link,
        pos,
        raw,
        hex,
        decode: _,
        full,
        output,
    } = a;
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

/// `sii-write`: refuses an image the slave's EEPROM cannot hold or (without `force`) one of
/// another device, keeps the old image in a backup file, then writes and verifies.
fn sii_write(a: SiiWriteArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let SiiWriteArgs {
        link,
        pos,
        file,
        device,
        force,
    } = a;
    let img = sii_image(file, device)?;
    oxicat_master::sii::check_image(&img)?;
    let m = open(&link)?;
    let p = one(&m, &pos)?;
    check_image_fits(&m, p, &img, force)?;
    // The old image first, so a write that stops half-way can be undone.
    let old = m.sii_read(p, true)?;
    let backup = backup_path(p);
    crate::output::write_file(&backup, &old)?;
    write_sii_words(&m, p, &img, force, &backup)?;
    w(
        out,
        &format!(
            "slave {p}: wrote and verified {} bytes of SII (the old image is in {})\n",
            img.len(),
            backup.display()
        ),
    )
}

/// Writes `img` into slave `p`'s EEPROM with a progress bar; stopped after the first word
/// (an error, Ctrl-C), it says how to restore the old image from `backup`.
fn write_sii_words(
    m: &Master,
    p: usize,
    img: &[u8],
    force: bool,
    backup: &Path,
) -> Result<(), CliError> {
    let ctrl_c = crate::interrupt::say_on_ctrl_c(restore_hint(p, backup));
    let pb = progress_bar((img.len() / 2) as u64, "writing SII");
    let mut written = 0usize;
    let r = m.sii_write(
        p,
        img,
        oxicat_master::sii::WriteOptions { force },
        &mut |d, _| {
            written = d;
            pb.set_position(d as u64)
        },
    );
    pb.finish_and_clear();
    drop(ctrl_c);
    match r {
        Err(error) if written > 0 => Err(CliError::SiiHalfWritten {
            error,
            position: p,
            backup: backup.to_path_buf(),
            written,
            words: img.len() / 2,
        }),
        r => Ok(r?),
    }
}

/// The image of `sii-write`: the file (binary or Intel HEX), or the one generated for
/// `device`.
fn sii_image(file: Option<PathBuf>, device: Option<String>) -> Result<Vec<u8>, CliError> {
    match (file, device) {
        (Some(f), _) => {
            let b = std::fs::read(&f).map_err(|error| UsageError::UnreadableFile {
                path: f.clone(),
                error,
            })?;
            if b.first() == Some(&b':') {
                Ok(oxicat_esi::sii::intel_hex(&b)
                    .map_err(|e| MasterError::SiiImage(e.to_string()))?)
            } else {
                Ok(b)
            }
        }
        (None, Some(d)) => crate::device_output(&d, crate::DeviceOutput::Sii)
            .map_err(|_| CliError::Master(MasterError::UnknownDevice(d))),
        (None, None) => Err(UsageError::NoImage.into()),
    }
}

/// Refused before a word is written: an image slave `p`'s EEPROM cannot hold, and (unless
/// `force`) one for another device (before the backup too).
fn check_image_fits(m: &Master, p: usize, img: &[u8], force: bool) -> Result<(), MasterError> {
    let size = m.eeprom_bytes(p)?;
    if img.len() > size {
        return Err(MasterError::SiiImage(format!(
            "{} bytes do not fit slave {p}'s EEPROM of {size} bytes (SII word 0x3E, ESC 0x0502 bit 7); nothing was written",
            img.len()
        )));
    }
    let image = oxicat_master::sii::image_identity(img)?;
    let (v, pc, r, _) = m.identity(p)?;
    if image != (v, pc, r) && !force {
        return Err(MasterError::SiiOtherDevice {
            position: p,
            image,
            slave: (v, pc, r),
        });
    }
    Ok(())
}

/// `upload <index> <sub>`: the value, as `--type`, the type SDO information gives, or by
/// its size.
fn upload(a: UploadArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let UploadArgs {
        link,
        pos,
        index,
        sub: subindex,
        r#type,
    } = a;
    let (i, s) = (idx(&index)?, sub(&subindex)?);
    let m = open(&link)?;
    let p = one(&m, &pos)?;
    let data = m.sdo_upload(p, i, s)?;
    let ty = match r#type.as_deref() {
        Some(t) => {
            let t = ValueType::parse(t)?;
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

/// `download <index> <sub> <value>`: the value encoded as `--type` or the type SDO
/// information gives.
fn download(a: DownloadArgs) -> Result<(), CliError> {
    let DownloadArgs {
        link,
        pos,
        index,
        sub: subindex,
        value,
        r#type,
    } = a;
    let (i, s) = (idx(&index)?, sub(&subindex)?);
    // A type given on the command line is checked before the bus is touched.
    let given = r#type.as_deref().map(ValueType::parse).transpose()?;
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
        None => sdo_type(&m, p, i, s).ok_or(UsageError::TypeUnknown { index: i, sub: s })?,
    };
    let data = ty.encode(&value)?;
    Ok(m.sdo_download(p, i, s, &data)?)
}

/// `sdos`: the CoE dictionary in the IgH tool's layout: `SDO 0x1018, "Identity"` and per
/// entry `  0x1018:01, r-r-r-, uint32, 32 bit, "Vendor ID"` (read/write per PREOP, SAFEOP,
/// OP), so a listing pastes from one tool into the other.
fn sdos(a: SdosArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let SdosArgs { link, pos } = a;
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

/// `pdos`: the PDO assignment and mapping, with the sync managers from the SII.
fn pdos(a: PdosArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let PdosArgs { link, pos } = a;
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

/// `cstruct [--rust]`: the PDO configuration of the live slaves (or of `--device`'s
/// definition) as C arrays, or as Rust structs.
fn cstruct(a: CstructArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let CstructArgs {
        link,
        pos,
        rust,
        device,
    } = a;
    if let Some(d) = device {
        return w(out, &device_cstruct(&d, &pos, rust)?);
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
            false => {
                crate::igh_cmd::c_struct(p, &s.name, (s.vendor_id, s.product_code, s.revision), &l)
            }
        };
        w(out, &text)?;
        w(out, "\n")?;
    }
    Ok(())
}

/// `cstruct --device <d>`: from the device definition's default PDO assignment, no bus.
fn device_cstruct(d: &str, pos: &PosArgs, rust: bool) -> Result<String, CliError> {
    let def = crate::device_def(d).map_err(|_| MasterError::UnknownDevice(d.to_string()))?;
    let l = crate::igh_cmd::def_pdos(def);
    let id = &def.identity;
    Ok(match rust {
        true => crate::igh_cmd::rust_struct(
            d,
            &format!("{d} ({}), default PDO assignment", def.name),
            &l,
        ),
        false => crate::igh_cmd::c_struct(
            pos.position.unwrap_or(0),
            def.name,
            (id.vendor_id, id.product_code, id.revision),
            &l,
        ),
    })
}

/// `data`: the process-data image of the last of a few cycles in OP, hex or raw.
fn data(a: DataArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let DataArgs {
        link,
        binary,
        output,
    } = a;
    let mut m = open(&link)?;
    let image = crate::igh_cmd::process_image(&mut m)?;
    let bytes = match binary {
        true => image,
        false => crate::igh_cmd::hex_lines(&image).into_bytes(),
    };
    crate::output::write_output(output.as_deref(), &bytes, out)
}

/// `alias <alias>`: written to the SII; says whether 0x0012 shows it yet.
fn alias(a: AliasArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let AliasArgs { link, pos, alias } = a;
    let a = parse_u16(&alias).ok_or_else(|| UsageError::NotAnAlias(alias.to_string()))?;
    let m = open(&link)?;
    let p = one(&m, &pos)?;
    let now = m.sii_set_alias(p, a)?;
    let when = match now == a {
        true => "in effect (0x0012)".to_string(),
        false => format!("0x0012 still reads 0x{now:04x}: the ESC loads it at its next power-up"),
    };
    w(
        out,
        &format!("slave {p}: alias 0x{a:04x} written to the SII (word 4, CRC updated), {when}\n"),
    )
}

/// `graph`: the topology as Graphviz DOT.
fn graph(a: GraphArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let GraphArgs { link, output } = a;
    let m = open(&link)?;
    let dot = crate::igh_cmd::graph(&m.scan()?);
    crate::output::write_output(output.as_deref(), dot.as_bytes(), out)
}

/// `xml`: an ESI for a live slave.
fn xml(a: XmlArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let XmlArgs { link, pos, output } = a;
    let m = open(&link)?;
    let p = one(&m, &pos)?;
    let xml = m.esi(p)?;
    crate::output::write_output(output.as_deref(), xml.as_bytes(), out)
}

/// `reg-read <address> [length]`: raw bytes, or the value as `--type`.
fn reg_read(a: RegReadArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let RegReadArgs {
        link,
        pos,
        address,
        length,
        r#type,
    } = a;
    let a = idx(&address)?;
    let ty = r#type.as_deref().map(ValueType::parse).transpose()?;
    let len = match (length.as_deref(), ty.and_then(|t| t.size())) {
        (Some(l), _) => idx(l)?,
        (None, Some(s)) => s as u16,
        (None, None) => 1,
    };
    check_register_range(a, usize::from(len))?;
    if let (Some(t), Some(size)) = (ty, ty.and_then(|t| t.size())) {
        if usize::from(len) != size {
            return Err(UsageError::TypeLength { ty: t, size, len }.into());
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

/// `reg-write <address> <value>`: the value encoded as `--type` (default u8).
fn reg_write(a: RegWriteArgs) -> Result<(), CliError> {
    let RegWriteArgs {
        link,
        pos,
        address,
        value,
        r#type,
    } = a;
    let a = idx(&address)?;
    let ty = match r#type.as_deref() {
        Some(t) => ValueType::parse(t)?,
        None => ValueType::U8,
    };
    let data = ty.encode(&value)?;
    check_register_range(a, data.len())?;
    let m = open(&link)?;
    let p = one(&m, &pos)?;
    Ok(m.reg_write(p, a, &data)?)
}

/// `watch <vars>`: a line of values every `every` cycles, `count` times (0: until Ctrl-C).
fn watch(a: WatchArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let WatchArgs {
        link,
        vars,
        cycle,
        every,
        count,
        sync,
    } = a;
    let cycle = parse_duration(&cycle)?;
    let opts = cycling(CycleOptions { cycle, dc: false }, sync);
    opts.check()?;
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
    m.watch(opts, &vars, every, count, &mut |line| {
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
    })?;
    match err {
        Some(e) => Err(MasterError::Output(e).into()),
        None => Ok(()),
    }
}

/// `write <var> <value>`: the output written while cycling, then `settle` cycles more; the
/// value each slave shows.
fn write(a: WriteArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let WriteArgs {
        link,
        var,
        value,
        cycle,
        settle,
        sync,
    } = a;
    let cycle = parse_duration(&cycle)?;
    let opts = cycling(CycleOptions { cycle, dc: false }, sync);
    opts.check()?;
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
        return Err(UsageError::NotAnOutput {
            var,
            position: v.position,
        }
        .into());
    }
    let back = m.write_online(opts, &vars, &data, settle)?;
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

/// `record <vars> -o <csv>`: every cycle (DC-synchronous unless `free_run`) for `duration`
/// or until Ctrl-C.
fn record(a: RecordArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let RecordArgs {
        link,
        vars,
        cycle,
        duration,
        output,
        free_run,
        sync,
        exchange,
    } = a;
    // Every argument is checked before the output is touched; the CSV goes to a
    // temporary file renamed over `output` at the end, so a failure leaves it as it was.
    let (opts, cycles) = record_plan(&cycle, &duration, free_run, sync)?;
    if let (Some(x), true) = (exchange, opts.dc()) {
        return Err(UsageError::OutOfRange {
            option: "--exchange",
            value: format!("{x:?}").to_lowercase(),
            allowed: "only with --free-run or --sync free-run|sm-sync (a DC cycle is \
                      ethercrab's tx_rx_dc, whose frame carries the reference clock's time)"
                .into(),
        }
        .into());
    }
    let mut m = open(&link)?;
    if let Some(x) = exchange {
        m.set_exchange(x.into());
    }
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
    let stats = record_cycles(&mut m, opts, &vars, cycles, sink)?;
    let place = match file {
        Some(f) => {
            f.commit()?;
            output.display().to_string()
        }
        None => "standard output".to_string(),
    };
    let how = match (exchange, stats.exchange) {
        (None, _) => String::new(),
        (Some(_), x) => format!(
            "; {} exchange, {} frames per cycle",
            match x {
                Exchange::Overlapped => "overlapped",
                Exchange::Lean | Exchange::Auto => "lean",
                Exchange::Ethercrab => "ethercrab's",
            },
            stats.frames_per_cycle
        ),
    };
    let line = format!(
        "{} cycles of {} variables to {place} ({} working-counter errors){how}{}\n",
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

/// Records `cycles` cycles of `vars` into `sink` with a progress bar; Ctrl-C ends it early
/// with the rows so far.
fn record_cycles(
    m: &mut Master,
    opts: Cycling,
    vars: &[oxicat_master::pdo::Variable],
    cycles: u64,
    sink: &mut dyn Write,
) -> Result<oxicat_master::cyclic::CycleStats, MasterError> {
    let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let ctrl_c = crate::interrupt::stop_on_ctrl_c(stop.clone());
    let pb = progress_bar(cycles, "recording");
    let r = m.record_until(
        opts,
        vars,
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
    r
}

/// `record`'s cycle options and number of cycles, checked before anything is opened.
fn record_plan(
    cycle: &str,
    duration: &str,
    free_run: bool,
    sync: Option<SyncArg>,
) -> Result<(Cycling, u64), CliError> {
    let cycle = parse_duration(cycle)?;
    let duration = parse_duration(duration)?;
    // DC SYNC0 by default; an explicit mode replaces it.
    let opts = cycling(
        CycleOptions {
            cycle,
            dc: !free_run && sync.is_none(),
        },
        sync,
    );
    opts.check()?;
    if duration < cycle {
        return Err(UsageError::DurationBelowCycle { duration, cycle }.into());
    }
    Ok((opts, (duration.as_nanos() / cycle.as_nanos()) as u64))
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
