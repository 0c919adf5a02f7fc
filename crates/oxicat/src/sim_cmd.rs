//! `oxicat sim`: a virtual segment served in real time on a network interface (raw
//! Ethernet, EtherType 0x88A4) or on UDP (EtherCAT over UDP, port 34980), for any master.
//!
//! Devices come from the command line (`demo:4`, a name with a count) or from a TOML
//! segment file:
//!
//! ```toml
//! master_link_delay_ns = 50   # optional, cable master → first slave
//! esc_delay_ns = 450          # optional, default forwarding delay of every ESC
//! link_delay_ns = 50          # optional, default cable delay between slaves
//!
//! [[device]]
//! name = "demo"
//! count = 2
//! drift_ppm = 40.0            # optional, oscillator error of these nodes
//! esc_delay_ns = 600          # optional, overrides the default for these nodes
//! link_delay_ns = 120         # optional, cable in front of each of these nodes
//! ```
//!
//! The nodes form a line in the order given (port 1 of one to port 0 of the next).
//!
//! A twin of a vendor's device, built from its ESI (`oxicat_devices::twin`), is a device
//! like the others: `esi=FILE[:TYPE or PRODUCT CODE[:REVISION]]` on the command line (a
//! count as `*N`: `esi=Beckhoff-EL2xxx.xml:EL2008*4`; `oxicat sim --esi FILE:TYPE` adds one
//! node), and `esi = "FILE:TYPE"` instead of `name` in a `[[device]]`.
//!
//! A slave's SII image is a device too: `sii=FILE` (binary or Intel HEX) on the command line,
//! `sii = "FILE"` in a `[[device]]` (with `dictionary = "FILE"`, a CoE dictionary as `oxicat
//! scan --save` writes it, and `esc_registers = "11 00 …"`, the ESC's registers
//! 0x0000..0x0009): the ESC with that EEPROM, and the slave stack when the SII has a mailbox.
//!
//! A whole machine:
//! - `--segment DIR`, a directory `oxicat scan --save DIR` wrote
//!   ([`oxicat_devices::saved`]): each recorded slave from its SII image and dictionary;
//! - `--eni FILE [--esi-dir DIR …]`, or `eni = "FILE"` (and `esi_dirs = ["DIR", …]`) in a
//!   segment file: the slaves of an ENI (EtherCATConfig), each a twin of the ESI that the
//!   search of the ESI directories (default: the ENI's directory) finds for its identity
//!   ([`oxicat_esi::eni`]); they come before the file's `[[device]]`s.
//!
//! Paths in a segment file are taken as given (relative to the working directory).
//!
//! What a twin's process data does (twins served by the stack, i.e. with a mailbox;
//! [`oxicat_devices::twin::behaviour`]) is `behaviour` in its `[[device]]` and one
//! `[[device.entry]]` per input entry that should do something else:
//!
//! ```toml
//! [[device]]
//! esi = "SOMANET_CiA_402.xml"
//! behaviour = "auto"          # by profile (default): CiA402 → drive, digital I/O → loop,
//!                             # analog inputs → a 1 Hz sine; or "loop", "hold", "drive"
//!
//! [[device]]
//! esi = "kickcat-freedom-k64f.xml"
//! [[device.entry]]
//! entry = "0x6001:0"          # INDEX:SUB, or the entry's name in the dictionary
//! sine = { amplitude = 1000, frequency_hz = 2.0, offset = 0, phase_deg = 0 }
//! [[device.entry]]
//! entry = "0x6000:0"
//! hold = -1234                # or: constant = 5
//! [[device.entry]]
//! entry = "0x6002:0"
//! ramp = { slope_per_s = 100, start = 0, min = -500, max = 500 }   # min/max: wraps
//! [[device.entry]]
//! entry = "0x6003:0"
//! noise = { amplitude = 20, seed = 7, offset = 0 }
//! [[device.entry]]
//! entry = "0x6004:0"
//! csv = { file = "profile.csv", repeat = true }   # lines time_s,value
//! [[device.entry]]
//! entry = "0x6005:0"
//! loop = "0x7000:0"           # copy an output entry of the same bit length
//! ```
//!
//! Signals run on the segment's virtual time (seconds since it was made) and write raw
//! values, rounded and saturated to the entry's type. Each entry takes exactly one of
//! `loop`, `hold`, `constant`, `sine`, `ramp`, `noise`, `csv`; an unknown entry, a number
//! that is not finite, an unreadable or malformed CSV file, `behaviour` on a device that is
//! not a twin or on a twin without a mailbox are refused, naming the key
//! (`device[1].entry[0].sine.amplitude`).
//!
//! Limits (checked before anything is built, with the key and the range in the message):
//! at most [`MAX_SIM_SLAVES`] nodes in all; delays 0 … [`MAX_DELAY_NS`] ns; drift
//! −[`MAX_DRIFT_PPM`] … [`MAX_DRIFT_PPM`] ppm.

use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use oxicat_sim::net::NetError;
use oxicat_sim::realtime::{serve, FramePort, RealtimeConfig, RealtimeStats};
use oxicat_sim::segment::{Segment, TopologyError};
use serde::Deserialize;

use oxicat_devices::registry::{add_device_node, Device, NodeError, ResolveError};
use oxicat_devices::twin::behaviour::{Behaviour, EntrySpec, Mode};
use oxicat_sim::pdi_path::PdiRoute;

/// Most nodes on a served segment: a frame passes every ESC twice (processing on the way
/// out, forwarding on the way back), about 1 µs per node with an ESC's ~0.5 µs delay, so
/// 1000 nodes take the whole of a 1 kHz cycle; each node also holds its 64 KiB ESC memory
/// and firmware (about 80 MB for 1000).
pub const MAX_SIM_SLAVES: usize = 1000;

/// Most firmware-hosting devices (every device but an ESC twin: their firmware runs in the
/// segment, its main loop every 50 µs of virtual time) that `oxicat sim` serves in real
/// time; more are refused before anything is built (see [`check_served`]). Measured with
/// `segment_scale` (README, "Scale"): 128 demo devices come up and cycle at 1 kHz; 256 come
/// up, but their 12 frames per cycle take 1.87 ms of the segment's virtual time even on the
/// line together (their 11,776 B of process data alone are 0.94 ms at 100 Mbit/s, plus
/// one trip through 256 ESCs) and 2.1 ms of the serving thread's CPU, so every cycle is
/// late. With the overlapped exchange (each node's inputs on its outputs' bytes) the
/// cycle fits the line (0.79 ms), but not the CPU: 1.9 ms per cycle in one process with
/// the master, SM-synchronous, and a served bring-up of 256 falls behind real time.
pub const MAX_SERVED_FIRMWARE_NODES: usize = 128;

/// Largest ESC or cable delay of a segment file, ns (1 ms: a whole 1 kHz cycle; a real ESC
/// forwards in ~0.5 µs, a 100 m cable takes ~0.5 µs).
pub const MAX_DELAY_NS: u64 = 1_000_000;

/// Largest oscillator error of a segment file, ppm (crystals are within ±100 ppm; the DC
/// model is exact up to ±10 000).
pub const MAX_DRIFT_PPM: f64 = 1000.0;

/// Arguments of `oxicat sim`.
#[derive(Debug, clap::Args)]
pub struct SimArgs {
    /// Serve on this network interface (raw Ethernet; needs CAP_NET_RAW), e.g. veth1.
    #[arg(long, conflicts_with = "udp")]
    pub iface: Option<String>,
    /// Serve EtherCAT over UDP on this address, e.g. 127.0.0.1:34980.
    #[arg(long)]
    pub udp: Option<String>,
    /// A TOML segment file (devices with counts, delays, drift) instead of DEVICES, or a
    /// directory `oxicat scan --save` wrote (the recorded machine).
    #[arg(long, conflicts_with = "devices")]
    pub segment: Option<PathBuf>,
    /// The slaves of an ENI (EtherCATConfig XML), each a twin of the ESI found for its
    /// identity in the --esi-dir directories; before DEVICES in the line.
    #[arg(long, conflicts_with = "segment")]
    pub eni: Option<PathBuf>,
    /// Where --eni looks for ESI files (repeat for more; default: the ENI's directory).
    #[arg(long, value_name = "DIR", requires = "eni")]
    pub esi_dir: Vec<PathBuf>,
    /// Devices in line order, each NAME or NAME:COUNT (see --list), e.g. demo:4; @lan9252 or
    /// @et1100 after it runs the firmware through that chip's SPI driver (demo:4@lan9252).
    pub devices: Vec<String>,
    /// A twin of a vendor's device from its ESI, FILE[:TYPE or PRODUCT CODE[:REVISION]]
    /// (one node each; repeat for more); after DEVICES in the line.
    #[arg(long, conflicts_with = "segment")]
    pub esi: Vec<String>,
    /// List the devices that can be simulated and exit.
    #[arg(long)]
    pub list: bool,
    /// Busy-poll for frames (one core at 100 %, lowest latency) instead of sleeping.
    #[arg(long)]
    pub spin: bool,
    /// No live status line.
    #[arg(short, long)]
    pub quiet: bool,
    /// Run the segment K times slower than real time (its DC cycles, watchdogs and firmware
    /// timers stretch by K), for firmware that cannot keep real time on this host.
    #[arg(long, value_name = "K", default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=10_000))]
    pub slowdown: u32,
    /// Serve from a SCHED_FIFO thread at priority PRIO (1–99; 49 when no value is given) with
    /// the process's memory locked; needs root or CAP_SYS_NICE. Written `--rt` or `--rt=PRIO`.
    #[arg(long, value_name = "PRIO", num_args = 0..=1, require_equals = true,
          default_missing_value = "49", value_parser = clap::value_parser!(u8).range(1..=99))]
    pub rt: Option<u8>,
    /// Pin the serving thread to CPU N (with --rt; isolate that core for the best figures).
    #[arg(long, value_name = "N", requires = "rt")]
    pub rt_cpu: Option<usize>,
    /// Serve --iface through an AF_XDP socket (Linux; root): an XDP program steers the
    /// interface's EtherCAT frames to the segment past the kernel's stack, other traffic
    /// passes. MODE: auto (native XDP if the driver has it, else generic; the default),
    /// generic, native, zero-copy. Written `--xdp` or `--xdp=MODE`.
    #[arg(long, value_name = "MODE", num_args = 0..=1, require_equals = true,
          default_missing_value = "auto", requires = "iface", value_enum)]
    pub xdp: Option<XdpMode>,
}

/// How `--xdp` attaches its program and binds its socket.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum XdpMode {
    /// Native XDP if the driver has it, else generic; copy mode.
    Auto,
    /// Generic (skb) XDP, any interface; copy mode.
    Generic,
    /// Native (driver) XDP; copy mode.
    Native,
    /// Native XDP with a zero-copy socket (drivers with AF_XDP zero-copy only).
    ZeroCopy,
}

#[cfg(target_os = "linux")]
impl From<XdpMode> for oxicat_sim::net::xdp::Mode {
    fn from(m: XdpMode) -> Self {
        match m {
            XdpMode::Auto => Self::Auto,
            XdpMode::Generic => Self::Generic,
            XdpMode::Native => Self::Native,
            XdpMode::ZeroCopy => Self::ZeroCopy,
        }
    }
}

/// Puts node `k` of a registered device on the segment (with its oscillator off by
/// `drift_ppm`, its firmware reaching the ESC through `route`): [`host_node`] runs the
/// host-compiled firmware; the board-image emulator's binary passes its own.
pub type AddNode<'a> = &'a dyn Fn(
    &mut Segment,
    Device,
    usize,
    f64,
    PdiRoute,
) -> Result<oxicat_sim::segment::SlaveId, NodeError>;

/// The host-compiled firmware of the registry, or a twin ([`add_device_node`]).
pub fn host_node(
    seg: &mut Segment,
    dev: Device,
    k: usize,
    drift_ppm: f64,
    route: PdiRoute,
) -> Result<oxicat_sim::segment::SlaveId, NodeError> {
    add_device_node(seg, dev, k, drift_ppm, route)
}

impl SimArgs {
    /// `oxicat sim -q DEVICES…` with every other option at its default (no interface, no
    /// UDP address, no segment file, slowdown 1, normal scheduling): the base of the
    /// arguments a program or a test serves a segment with (`SimArgs { udp, ..quiet(…) }`).
    pub fn quiet(devices: Vec<String>) -> Self {
        Self {
            iface: None,
            udp: None,
            segment: None,
            eni: None,
            esi_dir: Vec::new(),
            devices,
            esi: Vec::new(),
            list: false,
            spin: false,
            quiet: true,
            slowdown: 1,
            rt: None,
            rt_cpu: None,
            xdp: None,
        }
    }

    /// The real-time options of `--rt` and `--rt-cpu`, if asked.
    pub fn rt_options(&self) -> Option<oxicat_sim::rt::RtOptions> {
        self.rt.map(|priority| oxicat_sim::rt::RtOptions {
            cpu: self.rt_cpu,
            ..oxicat_sim::rt::RtOptions::fifo(priority)
        })
    }

    /// DEVICES, then one `esi=…` per `--esi`.
    pub fn all_devices(&self) -> Vec<String> {
        let mut v = self.devices.clone();
        v.extend(
            self.esi
                .iter()
                .map(|e| format!("{}{e}", oxicat_devices::twin::PREFIX)),
        );
        v
    }
}

/// Why `oxicat sim` failed.
#[derive(Debug)]
pub enum SimError {
    /// Neither --iface nor --udp.
    NoTransport,
    /// No devices given.
    NoDevices,
    /// A device spec is not NAME, NAME:COUNT or NAME:COUNT@ROUTE.
    BadSpec(String),
    /// No device of that name.
    UnknownDevice(String),
    /// A twin of an ESI could not be built (the file, the type, or why it cannot be
    /// served).
    Twin(String),
    /// The segment file could not be read.
    SegmentFile(PathBuf, std::io::Error),
    /// The segment file is not valid.
    SegmentToml(PathBuf, String),
    /// An ENI cannot be read or its slaves not found in ESI files.
    Eni(PathBuf, oxicat_esi::eni::EniError),
    /// A saved machine (a directory of `oxicat scan --save`) cannot be read.
    Saved(oxicat_devices::saved::SavedError),
    /// A node could not be put on the segment.
    Node {
        /// Position on the segment.
        position: usize,
        /// Device name.
        device: String,
        /// The cause.
        error: NodeError,
    },
    /// A delay could not be set.
    Topology(TopologyError),
    /// The network transport failed.
    Net(NetError),
    /// The serving thread could not be made real-time (`--rt`).
    Rt(oxicat_sim::rt::RtError),
    /// A number of the segment description is out of its range.
    Range {
        /// The key (`device[1].drift_ppm`, or `demo:100000` for a command-line count).
        key: String,
        /// The value given.
        value: String,
        /// The allowed range and why.
        range: String,
    },
    /// Ctrl-C while the segment was being built.
    Interrupted,
    /// `--xdp` on a system without AF_XDP (not Linux).
    XdpUnavailable,
}

impl std::fmt::Display for SimError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NoTransport => write!(
                f,
                "say where to serve the segment: --iface <interface> (raw Ethernet) or --udp \
                 <addr:port> (EtherCAT over UDP)"
            ),
            Self::NoDevices => write!(
                f,
                "no devices: give NAME:COUNT (e.g. demo:4) or --segment file.toml; --list shows \
                 the devices"
            ),
            Self::BadSpec(s) => write!(
                f,
                "{s:?} is not NAME, NAME:COUNT or NAME:COUNT@ROUTE (e.g. demo:4, demo:4@lan9252)"
            ),
            Self::UnknownDevice(n) => {
                write!(
                    f,
                    "unknown device {n:?}; known: {}",
                    oxicat_devices::registry::names()
                )
            }
            Self::Twin(e) => write!(f, "{e}"),
            Self::SegmentFile(p, e) => write!(f, "cannot read {}: {e}", p.display()),
            Self::SegmentToml(p, e) => write!(f, "{}: {e}", p.display()),
            Self::Eni(p, e) => write!(f, "{}: {e}", p.display()),
            Self::Saved(e) => write!(f, "{e}"),
            Self::Node {
                position,
                device,
                error,
            } => write!(f, "node {position} ({device}): {error}"),
            Self::Topology(e) => write!(f, "{e}"),
            Self::Net(e) => write!(f, "{e}"),
            Self::XdpUnavailable => write!(
                f,
                "--xdp needs Linux (AF_XDP sockets); serve with the raw socket: --iface alone"
            ),
            Self::Rt(e) => write!(f, "--rt: {e}"),
            Self::Range { key, value, range } => {
                write!(f, "{key} = {value} is not in {range}")
            }
            Self::Interrupted => write!(f, "interrupted while building the segment"),
        }
    }
}

impl std::error::Error for SimError {}

/// A segment description (the TOML segment file, or the command-line devices).
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SegmentFile {
    /// Cable delay master → first slave, ns.
    pub master_link_delay_ns: Option<u64>,
    /// Default ESC forwarding delay, ns.
    pub esc_delay_ns: Option<u64>,
    /// Default cable delay between slaves, ns.
    pub link_delay_ns: Option<u64>,
    /// An ENI whose slaves come first in the line.
    pub eni: Option<String>,
    /// Where the ENI's ESI files are (default: the ENI's directory).
    #[serde(default)]
    pub esi_dirs: Vec<String>,
    /// The devices in line order.
    #[serde(default, rename = "device")]
    pub devices: Vec<DeviceEntry>,
}

/// One `[[device]]` of a segment file.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DeviceEntry {
    /// Device name (see `oxicat sim --list`), or `esi=FILE[:TYPE[:REVISION]]`.
    #[serde(default)]
    pub name: String,
    /// A twin from an ESI, `FILE[:TYPE or PRODUCT CODE[:REVISION]]` (instead of `name`).
    pub esi: Option<String>,
    /// A twin from a slave's SII image file (instead of `name`).
    pub sii: Option<String>,
    /// With `sii`: the slave's CoE dictionary (a dictionary file of `oxicat scan --save`).
    pub dictionary: Option<String>,
    /// With `sii`: the ESC's registers 0x0000..0x0009 as hex bytes (`11 00 03 00 08 08 08
    /// 0f fc 01`).
    pub esc_registers: Option<String>,
    /// How many in a row.
    #[serde(default = "one")]
    pub count: usize,
    /// Oscillator error in ppm.
    #[serde(default)]
    pub drift_ppm: f64,
    /// Forwarding delay of each of these ESCs, ns.
    pub esc_delay_ns: Option<u64>,
    /// Cable delay in front of each of these nodes, ns.
    pub link_delay_ns: Option<u64>,
    /// A fault: the SII EEPROM of these nodes acknowledges no write to this word or above
    /// (a write-protected or worn part; 0x0502 bit 13), so an `sii-write` stops half-way.
    pub eeprom_protect_from_word: Option<u16>,
    /// How the firmware reaches its ESC: `direct` (default), `lan9252` or `et1100` (the
    /// chip's SPI driver over the simulated SPI bus at [`SPI_MHZ`] MHz).
    pub pdi: Option<String>,
    /// Twins: what their process data does, `auto` (by profile, the default), `loop`,
    /// `hold` or `drive` ([`oxicat_devices::twin::behaviour`]).
    pub behaviour: Option<String>,
    /// Twins: what single input entries do (`[[device.entry]]`).
    #[serde(default, rename = "entry")]
    pub entries: Vec<EntrySpec>,
}

/// SPI clock of the `lan9252` / `et1100` routes of `sim` and `--sim`.
pub const SPI_MHZ: u32 = 20;

fn route_of(pdi: Option<&str>) -> Option<PdiRoute> {
    pdi.map_or(Some(PdiRoute::Direct), |p| PdiRoute::parse(p, SPI_MHZ))
}

fn one() -> usize {
    1
}

/// Parses `NAME` or `NAME:COUNT` specs into a segment description. Each argument may hold
/// several specs separated by commas or spaces (`demo:2,tue-es030:1`, `"demo:2 tue-es030"`),
/// so `oxicat sim` and the master verbs' `--sim` take the same syntax.
pub fn parse_specs(specs: &[String]) -> Result<SegmentFile, SimError> {
    parse_specs_within(specs, MAX_SIM_SLAVES, &count_range())
}

/// [`parse_specs`] with at most `max` slaves in all (`range` says so in the error).
pub fn parse_specs_within(
    specs: &[String],
    max: usize,
    range: &str,
) -> Result<SegmentFile, SimError> {
    let mut seg = SegmentFile::default();
    let mut total = 0u128;
    for s in specs
        .iter()
        .flat_map(|a| a.split(|c: char| c == ',' || c.is_whitespace()))
        .filter(|p| !p.is_empty())
    {
        let (spec, pdi) = match s.split_once('@') {
            Some((spec, route)) => (spec, Some(route.to_string())),
            None => (s, None),
        };
        if route_of(pdi.as_deref()).is_none() {
            return Err(SimError::Range {
                key: format!("the route of {s}"),
                value: pdi.unwrap_or_default(),
                range: "direct, lan9252 or et1100".into(),
            });
        }
        let twin = spec.starts_with(oxicat_devices::twin::PREFIX)
            || spec.starts_with(oxicat_devices::twin::SII_PREFIX);
        let split = if twin {
            spec.rsplit_once('*')
        } else {
            spec.split_once(':')
        };
        let (name, count) = match split {
            Some((n, c)) => (
                n,
                c.parse::<u128>()
                    .ok()
                    .filter(|&c| c > 0)
                    .ok_or_else(|| SimError::BadSpec(s.to_string()))?,
            ),
            None => (spec, 1),
        };
        total = total.saturating_add(count);
        if total > max as u128 {
            return Err(SimError::Range {
                key: format!("the count of {s}"),
                value: count.to_string(),
                range: range.to_string(),
            });
        }
        if name.is_empty() {
            return Err(SimError::BadSpec(s.to_string()));
        }
        seg.devices.push(DeviceEntry {
            name: name.to_string(),
            esi: None,
            sii: None,
            dictionary: None,
            esc_registers: None,
            count: count as usize,
            drift_ppm: 0.0,
            esc_delay_ns: None,
            link_delay_ns: None,
            eeprom_protect_from_word: None,
            pdi,
            behaviour: None,
            entries: Vec::new(),
        });
    }
    Ok(seg)
}

fn count_range() -> String {
    format!("1 … {MAX_SIM_SLAVES} slaves in all (a frame through {MAX_SIM_SLAVES} ESCs takes a whole 1 kHz cycle)")
}

/// Reads a TOML segment file, or the directory of a saved machine ([`read_saved_dir`]), and
/// checks its numbers.
pub fn read_segment_file(path: &Path) -> Result<SegmentFile, SimError> {
    if path.is_dir() {
        return read_saved_dir(path);
    }
    let text = std::fs::read_to_string(path).map_err(|e| SimError::SegmentFile(path.into(), e))?;
    parse_segment(&text, path)
}

/// Parses the text of a TOML segment file and checks its numbers (`path` is named in
/// errors); an `eni` puts the ENI's slaves first.
pub fn parse_segment(text: &str, path: &Path) -> Result<SegmentFile, SimError> {
    let mut desc: SegmentFile =
        toml::from_str(text).map_err(|e| SimError::SegmentToml(path.into(), e.to_string()))?;
    if let Some(eni) = desc.eni.take() {
        let dirs: Vec<PathBuf> = desc.esi_dirs.iter().map(PathBuf::from).collect();
        let (mut devices, notes) = eni_devices(Path::new(&eni), &dirs)?;
        for n in notes {
            eprintln!("oxicat sim: {n}");
        }
        devices.append(&mut desc.devices);
        desc.devices = devices;
    } else if !desc.esi_dirs.is_empty() {
        return Err(SimError::SegmentToml(
            path.into(),
            "esi_dirs is where an eni's ESI files are: give eni = \"FILE\" too".into(),
        ));
    }
    check_segment(&desc).map_err(|e| SimError::SegmentToml(path.into(), e.to_string()))?;
    Ok(desc)
}

fn device_entry(name: String) -> DeviceEntry {
    DeviceEntry {
        name,
        esi: None,
        sii: None,
        dictionary: None,
        esc_registers: None,
        count: 1,
        drift_ppm: 0.0,
        esc_delay_ns: None,
        link_delay_ns: None,
        eeprom_protect_from_word: None,
        pdi: None,
        behaviour: None,
        entries: Vec::new(),
    }
}

/// The slaves of the ENI `eni` as devices (twins of the ESI files of `dirs`, or of the ENI's
/// directory when `dirs` is empty), and notes on slaves served with another revision.
pub fn eni_devices(
    eni: &Path,
    dirs: &[PathBuf],
) -> Result<(Vec<DeviceEntry>, Vec<String>), SimError> {
    let text = std::fs::read(eni).map_err(|e| SimError::SegmentFile(eni.into(), e))?;
    let parsed = oxicat_esi::eni::parse(&oxicat_esi::twin::decode(&text))
        .map_err(|e| SimError::Eni(eni.into(), e))?;
    let dirs = if dirs.is_empty() {
        vec![match eni.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        }]
    } else {
        dirs.to_vec()
    };
    let found =
        oxicat_esi::eni::resolve(&parsed, &dirs).map_err(|e| SimError::Eni(eni.into(), e))?;
    let mut notes = Vec::new();
    let devices = found
        .into_iter()
        .map(|r| {
            notes.extend(r.note);
            let mut d = device_entry(String::new());
            d.esi = Some(format!(
                "{}:{}:{:#010x}",
                r.file.display(),
                r.candidate.type_name,
                r.candidate.revision
            ));
            d
        })
        .collect();
    Ok((devices, notes))
}

/// The machine `oxicat scan --save` recorded in `dir` ([`oxicat_devices::saved`]): one
/// device per slave, from its SII image, dictionary and ESC registers.
pub fn read_saved_dir(dir: &Path) -> Result<SegmentFile, SimError> {
    let m = oxicat_devices::saved::read_manifest(dir).map_err(SimError::Saved)?;
    let devices = m
        .slaves
        .iter()
        .map(|s| {
            let mut d = device_entry(String::new());
            d.sii = Some(dir.join(&s.sii).display().to_string());
            d.dictionary = s
                .dictionary
                .as_ref()
                .map(|f| dir.join(f).display().to_string());
            d.esc_registers = Some(s.esc_registers.clone());
            d
        })
        .collect();
    Ok(SegmentFile {
        devices,
        ..SegmentFile::default()
    })
}

/// The segment `args` describe: a segment file or saved machine, or the ENI's slaves, then
/// DEVICES and `--esi`s.
pub fn describe(args: &SimArgs) -> Result<SegmentFile, SimError> {
    let mut desc = match &args.segment {
        Some(p) => read_segment_file(p)?,
        None => parse_specs(&args.all_devices())?,
    };
    if let Some(eni) = &args.eni {
        let (mut devices, notes) = eni_devices(eni, &args.esi_dir)?;
        for n in notes {
            eprintln!("oxicat sim: {n}");
        }
        devices.append(&mut desc.devices);
        desc.devices = devices;
    }
    Ok(desc)
}

/// Checks every number of a segment description against its range (delays, drift, counts
/// and their total), naming the key.
pub fn check_segment(desc: &SegmentFile) -> Result<(), SimError> {
    let delay = |key: String, v: Option<u64>| match v {
        Some(v) if v > MAX_DELAY_NS => Err(SimError::Range {
            key,
            value: v.to_string(),
            range: format!("0 … {MAX_DELAY_NS} ns (a whole 1 kHz cycle)"),
        }),
        _ => Ok(()),
    };
    delay("master_link_delay_ns".into(), desc.master_link_delay_ns)?;
    delay("esc_delay_ns".into(), desc.esc_delay_ns)?;
    delay("link_delay_ns".into(), desc.link_delay_ns)?;
    let mut total = 0usize;
    for (k, d) in desc.devices.iter().enumerate() {
        let kinds = usize::from(!d.name.is_empty())
            + usize::from(d.esi.is_some())
            + usize::from(d.sii.is_some());
        if kinds != 1 {
            return Err(SimError::Range {
                key: format!("device[{k}].name / device[{k}].esi / device[{k}].sii"),
                value: if kinds == 0 { "none".into() } else { "several".into() },
                range: "one of them: name (a device of oxicat sim --list), esi (FILE[:TYPE[:REVISION]]) or sii (FILE)"
                    .into(),
            });
        }
        if d.sii.is_none() && (d.dictionary.is_some() || d.esc_registers.is_some()) {
            return Err(SimError::Range {
                key: format!("device[{k}].dictionary / device[{k}].esc_registers"),
                value: "without sii".into(),
                range: "a device given by sii = \"FILE\" (they describe a recorded slave)".into(),
            });
        }
        if let Some(r) = &d.esc_registers {
            if oxicat_devices::saved::unhex(r).is_none_or(|b| b.len() != 10) {
                return Err(SimError::Range {
                    key: format!("device[{k}].esc_registers"),
                    value: format!("{r:?}"),
                    range: "10 hex bytes (ESC registers 0x0000 … 0x0009)".into(),
                });
            }
        }
        if d.esi.is_none() && d.sii.is_none() && (d.behaviour.is_some() || !d.entries.is_empty()) {
            return Err(SimError::Twin(format!(
                "device[{k}].behaviour / device[{k}].entry: {:?} is not a twin; behaviour is for \
                 twins (esi = \"FILE:TYPE\", sii = \"FILE\"), a device of this repository runs its own firmware",
                d.name
            )));
        }
        if let Some(b) = d.behaviour.as_deref().filter(|b| Mode::parse(b).is_none()) {
            return Err(SimError::Range {
                key: format!("device[{k}].behaviour"),
                value: format!("{b:?}"),
                range: "auto, loop, hold or drive".into(),
            });
        }
        delay(format!("device[{k}].esc_delay_ns"), d.esc_delay_ns)?;
        delay(format!("device[{k}].link_delay_ns"), d.link_delay_ns)?;
        if !(d.drift_ppm.is_finite() && d.drift_ppm.abs() <= MAX_DRIFT_PPM) {
            return Err(SimError::Range {
                key: format!("device[{k}].drift_ppm"),
                value: d.drift_ppm.to_string(),
                range: format!("-{MAX_DRIFT_PPM} … {MAX_DRIFT_PPM} ppm"),
            });
        }
        if route_of(d.pdi.as_deref()).is_none() {
            return Err(SimError::Range {
                key: format!("device[{k}].pdi"),
                value: d.pdi.clone().unwrap_or_default(),
                range: "direct, lan9252 or et1100".into(),
            });
        }
        total = total.saturating_add(d.count);
        if d.count == 0 || total > MAX_SIM_SLAVES {
            return Err(SimError::Range {
                key: format!("device[{k}].count"),
                value: d.count.to_string(),
                range: count_range(),
            });
        }
    }
    Ok(())
}

/// Number of firmware-hosting devices in `desc` (every device but ESC twins from an ESI or
/// an SII image).
pub fn firmware_nodes(desc: &SegmentFile) -> usize {
    desc.devices
        .iter()
        .filter(|d| {
            d.esi.is_none()
                && d.sii.is_none()
                && !d.name.starts_with(oxicat_devices::twin::PREFIX)
                && !d.name.starts_with(oxicat_devices::twin::SII_PREFIX)
        })
        .map(|d| d.count)
        .sum()
}

/// Refuses a segment to be served in real time with more than
/// [`MAX_SERVED_FIRMWARE_NODES`] firmware-hosting devices, with the figure behind the limit.
/// (A segment driven in the same process runs on its virtual clock and has no such limit.)
pub fn check_served(desc: &SegmentFile) -> Result<(), SimError> {
    let n = firmware_nodes(desc);
    if n > MAX_SERVED_FIRMWARE_NODES {
        return Err(SimError::Range {
            key: "firmware-hosting devices".into(),
            value: n.to_string(),
            range: served_firmware_range(),
        });
    }
    Ok(())
}

fn served_firmware_range() -> String {
    format!(
        "at most {MAX_SERVED_FIRMWARE_NODES} served in real time: each runs its firmware's main \
         loop every 50 µs of virtual time, ≈ 1–1.3 µs of CPU per device per ms before any \
         frame; 256 demo devices' process data (11,776 B, 12 frames) take 1.87 ms of virtual \
         time per cycle on the line (0.94 ms of it the image's wire time at 100 Mbit/s) and \
         2.1 ms of the serving thread's CPU, so no 1 kHz cycle is in time (a master that \
         overlaps each node's inputs with its outputs, as SOEM's overlap map or \
         `oxicat record --exchange overlap` do, fits the line in 0.79 ms, not the CPU: \
         1.9 ms per cycle). ESC twins (esi=…) \
         do not count; a segment driven in the same process (--sim) runs on its virtual \
         clock and has no such limit"
    )
}

/// Builds the segment (firmware booted at virtual time 0); returns it with the device name
/// of every node.
pub fn build_segment(desc: &SegmentFile) -> Result<(Segment, Vec<String>), SimError> {
    build_segment_until(desc, &AtomicBool::new(false))
}

/// [`build_segment`] that gives up with [`SimError::Interrupted`] when `stop` is set (Ctrl-C
/// while a long segment boots).
pub fn build_segment_until(
    desc: &SegmentFile,
    stop: &AtomicBool,
) -> Result<(Segment, Vec<String>), SimError> {
    build_segment_with(desc, stop, &host_node)
}

/// [`build_segment_until`] with each node put on the segment by `add`.
pub fn build_segment_with(
    desc: &SegmentFile,
    stop: &AtomicBool,
    add: AddNode<'_>,
) -> Result<(Segment, Vec<String>), SimError> {
    if desc.devices.iter().all(|d| d.count == 0) {
        return Err(SimError::NoDevices);
    }
    check_segment(desc)?;
    let mut seg = Segment::new();
    let mut names = Vec::new();
    for (j, entry) in desc.devices.iter().enumerate() {
        let name = match (&entry.esi, &entry.sii) {
            (Some(e), _) => format!("{}{e}", oxicat_devices::twin::PREFIX),
            (_, Some(s)) => format!("{}{s}", oxicat_devices::twin::SII_PREFIX),
            _ => entry.name.clone(),
        };
        let dev = match &entry.sii {
            Some(sii) => {
                let regs = entry.esc_registers.as_deref().and_then(|r| {
                    let b = oxicat_devices::saved::unhex(r)?;
                    <[u8; 10]>::try_from(b.as_slice()).ok()
                });
                oxicat_devices::twin::load_sii(
                    Path::new(sii),
                    entry.dictionary.as_deref().map(Path::new),
                    regs,
                )
                .map(Device::Twin)
                .map_err(|e| SimError::Twin(e.to_string()))?
            }
            None => oxicat_devices::registry::resolve(&name).map_err(|e| match e {
                ResolveError::Unknown(n) => SimError::UnknownDevice(n),
                e => SimError::Twin(e.to_string()),
            })?,
        };
        let dev = with_behaviour(dev, entry, j)?;
        for k in 0..entry.count {
            if stop.load(Ordering::Relaxed) {
                return Err(SimError::Interrupted);
            }
            let position = seg.len();
            let route = route_of(entry.pdi.as_deref()).unwrap_or_default();
            let id =
                add(&mut seg, dev, k, entry.drift_ppm, route).map_err(|error| SimError::Node {
                    position,
                    device: name.clone(),
                    error,
                })?;
            if let (Some(w), Some(esc)) = (entry.eeprom_protect_from_word, seg.esc_mut(id)) {
                esc.protect_eeprom_from(w);
            }
            if let Some(d) = entry.esc_delay_ns.or(desc.esc_delay_ns) {
                seg.set_esc_delay(id, d).map_err(SimError::Topology)?;
            }
            if id > 0 {
                if let Some(d) = entry.link_delay_ns.or(desc.link_delay_ns) {
                    seg.set_link_delay(id, 0, d).map_err(SimError::Topology)?;
                }
            }
            names.push(name.clone());
        }
    }
    if let Some(d) = desc.master_link_delay_ns {
        seg.set_link_delay(0, 0, d).map_err(SimError::Topology)?;
    }
    Ok((seg, names))
}

/// The twin `dev` with the behaviour of segment-file entry `entry` (number `j`), checked
/// against its dictionary; `dev` itself when the entry gives none.
fn with_behaviour(dev: Device, entry: &DeviceEntry, j: usize) -> Result<Device, SimError> {
    let Device::Twin(t) = dev else {
        return Ok(dev);
    };
    if entry.behaviour.is_none() && entry.entries.is_empty() {
        return Ok(dev);
    }
    let key = format!("device[{j}]");
    let b = Behaviour::compile(entry.behaviour.as_deref(), &entry.entries, t.esi.def, &key)
        .map_err(|e| SimError::Twin(format!("{} ({})", e, t.spec)))?;
    if t.esi.served == oxicat_esi::twin::Served::EscOnly {
        // Served by its ESC alone: the behaviour drives the digital-I/O input pins.
        oxicat_devices::twin::pins::Pins::new(t.esi.def, &t.esi.sii, &b).map_err(|why| {
            SimError::Twin(format!(
                "{key}: {why} ({} has no mailbox and is served by its ESC alone)",
                t.spec
            ))
        })?;
    }
    Ok(Device::Twin(oxicat_devices::twin::with_behaviour(t, b)))
}

/// AL state name of an AL status register value (error flag as "+ERR").
pub fn al_state_name(al_status: u16) -> String {
    let s = match al_status & 0x0F {
        1 => "INIT",
        2 => "PREOP",
        3 => "BOOT",
        4 => "SAFEOP",
        8 => "OP",
        _ => "?",
    };
    if al_status & 0x10 != 0 {
        format!("{s}+ERR")
    } else {
        s.to_string()
    }
}

/// Text of an AL status code (ETG.1000.6 table 11), the code once: `0x001E Invalid input
/// configuration`.
pub fn al_code_text(code: u16) -> String {
    format!("0x{code:04X} {}", oxicat_master::al::al_status_text(code))
}

/// One status line: frames/s and every node's AL state (and AL status code if in error).
pub fn status_line(seg: &Segment, frames_per_s: f64) -> String {
    let mut s = format!("{frames_per_s:>7.0} frames/s |");
    for i in 0..seg.len() {
        let Some(esc) = seg.esc(i) else { continue };
        let st = esc.al_status();
        s.push_str(&format!(" {i}:{}", al_state_name(st)));
        if st & 0x10 != 0 {
            let code = esc
                .memory()
                .get(0x134..0x136)
                .map_or(0, |b| u16::from_le_bytes([b[0], b[1]]));
            s.push_str(&format!("({})", al_code_text(code)));
        }
    }
    s
}

fn status_thread(
    segment: Arc<Mutex<Segment>>,
    stats: Arc<RealtimeStats>,
    stop: Arc<AtomicBool>,
) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        let tty = std::io::stderr().is_terminal();
        let mut last = (Instant::now(), stats.frames());
        let mut last_printed = String::new();
        let mut last_print_at = Instant::now();
        while !stop.load(Ordering::Relaxed) {
            std::thread::sleep(Duration::from_millis(500));
            let now = (Instant::now(), stats.frames());
            let rate = (now.1 - last.1) as f64 / now.0.duration_since(last.0).as_secs_f64();
            last = now;
            let line = {
                let seg = segment.lock().unwrap_or_else(|e| e.into_inner());
                status_line(&seg, rate)
            };
            let mut err = std::io::stderr().lock();
            if tty {
                let _ = write!(err, "\r\x1b[K{line}");
            } else {
                // Logs: print when the states change, or every 10 s.
                let states = line.split_once('|').map_or("", |x| x.1);
                let old = last_printed.split_once('|').map_or("", |x| x.1);
                if states != old || last_print_at.elapsed() >= Duration::from_secs(10) {
                    let _ = writeln!(err, "{line}");
                    last_printed = line;
                    last_print_at = Instant::now();
                }
            }
            let _ = err.flush();
        }
        if tty {
            let _ = writeln!(std::io::stderr());
        }
    })
}

/// Serves the segment of `args` until `stop` is set.
pub fn serve_until(args: &SimArgs, stop: Arc<AtomicBool>) -> Result<(), SimError> {
    serve_until_with(args, stop, &host_node)
}

/// [`serve_until`] with each node put on the segment by `add`.
pub fn serve_until_with(
    args: &SimArgs,
    stop: Arc<AtomicBool>,
    add: AddNode<'_>,
) -> Result<(), SimError> {
    if args.iface.is_none() && args.udp.is_none() {
        return Err(SimError::NoTransport);
    }
    let desc = describe(args)?;
    check_segment(&desc)?;
    check_served(&desc)?;
    let total: usize = desc.devices.iter().map(|d| d.count).sum();
    eprintln!("oxicat sim: booting {total} slave(s); Ctrl-C to stop");
    let (seg, names) = build_segment_with(&desc, &stop, add)?;
    let n = seg.len();
    let segment = Arc::new(Mutex::new(seg));
    let config = RealtimeConfig {
        spin: args.spin,
        slowdown: args.slowdown,
        ..RealtimeConfig::default()
    };
    let wait = if config.spin {
        Duration::ZERO
    } else {
        config.idle
    };
    let summary = summarize(&names);
    if let Some(iface) = &args.iface {
        #[cfg(target_os = "linux")]
        if let Some(mode) = args.xdp {
            let port =
                oxicat_sim::net::xdp::XdpPort::open(iface, mode.into()).map_err(SimError::Net)?;
            return run_port(port, segment, &config, args, stop, n, &summary);
        }
        #[cfg(not(target_os = "linux"))]
        if args.xdp.is_some() {
            return Err(SimError::XdpUnavailable);
        }
        #[cfg(unix)]
        {
            let port = oxicat_sim::net::raw::RawPort::open(iface, wait).map_err(SimError::Net)?;
            run_port(port, segment, &config, args, stop, n, &summary)
        }
        #[cfg(not(unix))]
        {
            let _ = (iface, wait);
            Err(SimError::NoTransport)
        }
    } else {
        let addr = args.udp.as_deref().unwrap_or_default();
        let port = oxicat_sim::net::udp::UdpPort::bind(addr).map_err(SimError::Net)?;
        run_port(port, segment, &config, args, stop, n, &summary)
    }
}

/// Serves the devices of `args` on an already bound UDP port until `stop` is set (for a
/// program, or a test, that needs the address before serving starts).
pub fn serve_udp_until(
    args: &SimArgs,
    port: oxicat_sim::net::udp::UdpPort,
    stop: Arc<AtomicBool>,
) -> Result<(), SimError> {
    serve_udp_until_with(args, port, stop, &host_node)
}

/// [`serve_udp_until`] with each node put on the segment by `add`.
pub fn serve_udp_until_with(
    args: &SimArgs,
    port: oxicat_sim::net::udp::UdpPort,
    stop: Arc<AtomicBool>,
    add: AddNode<'_>,
) -> Result<(), SimError> {
    let desc = describe(args)?;
    let (seg, names) = build_segment_with(&desc, &AtomicBool::new(false), add)?;
    serve_segment_until(args, port, Arc::new(Mutex::new(seg)), &names, stop)
}

/// Serves an already built `segment` on `port` until `stop` is set, with the options of
/// `args` (spin, slowdown, quiet); `names` are its nodes' device names (for the log). The
/// segment is shared: other threads (the Python package's process data and faults) lock it
/// between frames.
pub fn serve_segment_until<P: FramePort>(
    args: &SimArgs,
    port: P,
    segment: Arc<Mutex<Segment>>,
    names: &[String],
    stop: Arc<AtomicBool>,
) -> Result<(), SimError> {
    let n = segment.lock().unwrap_or_else(|e| e.into_inner()).len();
    let config = RealtimeConfig {
        spin: args.spin,
        slowdown: args.slowdown,
        ..RealtimeConfig::default()
    };
    run_port(port, segment, &config, args, stop, n, &summarize(names))
}

fn summarize(names: &[String]) -> String {
    let mut parts: Vec<(String, usize)> = Vec::new();
    for n in names {
        match parts.last_mut() {
            Some((last, c)) if last == n => *c += 1,
            _ => parts.push((n.clone(), 1)),
        }
    }
    parts
        .iter()
        .map(|(n, c)| format!("{n}:{c}"))
        .collect::<Vec<_>>()
        .join(" ")
}

fn run_port<P: FramePort>(
    mut port: P,
    segment: Arc<Mutex<Segment>>,
    config: &RealtimeConfig,
    args: &SimArgs,
    stop: Arc<AtomicBool>,
    n: usize,
    summary: &str,
) -> Result<(), SimError> {
    let stats = Arc::new(RealtimeStats::default());
    eprintln!(
        "oxicat sim: serving {n} slave{} ({summary}) on {}; Ctrl-C to stop",
        if n == 1 { "" } else { "s" },
        port.describe()
    );
    // The status thread is started first so that it stays a normal thread: threads
    // inherit their creator's scheduling policy.
    let status = (!args.quiet).then(|| status_thread(segment.clone(), stats.clone(), stop.clone()));
    let r = match args.rt_options().map(|o| oxicat_sim::rt::enter(&o)) {
        Some(Err(e)) => Err(SimError::Rt(e)),
        entered => {
            if let Some(Ok(report)) = entered {
                eprintln!("oxicat sim: serving thread: {report}");
            }
            serve(&segment, &mut port, config, &stats, &stop).map_err(SimError::Net)
        }
    };
    stop.store(true, Ordering::Relaxed);
    if let Some(h) = status {
        let _ = h.join();
    }
    eprintln!(
        "oxicat sim: {} frames, {} answered, {} lost, longest turnaround {} µs",
        stats.frames(),
        stats.replies.load(Ordering::Relaxed),
        stats.lost.load(Ordering::Relaxed),
        stats.max_turnaround_ns.load(Ordering::Relaxed) / 1000
    );
    r
}

/// `oxicat sim`: lists devices, or serves until Ctrl-C.
pub fn run(args: SimArgs) -> Result<(), SimError> {
    if args.list {
        print!("{}", crate::igh_cmd::device_list());
        return Ok(());
    }
    let _ = env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn"))
        .try_init();
    let stop = Arc::new(AtomicBool::new(false));
    // Ctrl-C also while the segment is being built.
    let _ctrl_c = crate::interrupt::stop_on_ctrl_c(stop.clone());
    serve_until(&args, stop)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs() {
        let s = parse_specs(&["demo:4".into(), "demo".into()]).unwrap();
        assert_eq!(s.devices.len(), 2);
        assert_eq!(s.devices[0].count, 4);
        assert_eq!(s.devices[1].count, 1);
        for bad in ["demo:0", "demo:x", ":3", "demo:-1"] {
            assert!(matches!(
                parse_specs(&[bad.into()]),
                Err(SimError::BadSpec(_))
            ));
        }
    }

    #[test]
    fn unknown_device_lists_known_ones() {
        let e = build_segment(&parse_specs(&["nope:2".into()]).unwrap()).unwrap_err();
        let m = e.to_string();
        assert!(m.contains("nope") && m.contains("demo"), "{m}");
        assert!(matches!(
            build_segment(&SegmentFile::default()),
            Err(SimError::NoDevices)
        ));
    }

    #[test]
    fn segment_file_builds_line_with_delays_and_drift() {
        let desc: SegmentFile = toml::from_str(
            r#"
            master_link_delay_ns = 70
            esc_delay_ns = 500
            [[device]]
            name = "demo"
            count = 2
            drift_ppm = 25.0
            [[device]]
            name = "demo-additions"
            link_delay_ns = 300
            "#,
        )
        .unwrap();
        let (seg, names) = build_segment(&desc).unwrap();
        assert_eq!(seg.len(), 3);
        assert_eq!(names, vec!["demo", "demo", "demo-additions"]);
        assert_eq!(summarize(&names), "demo:2 demo-additions:1");
        assert_eq!(seg.peer(1, 1), Some((2, 0)));
        assert_eq!(seg.esc(0).unwrap().config().clock.drift_ppm, 25.0);
        assert_eq!(seg.esc(2).unwrap().config().clock.drift_ppm, 0.0);
        let bad: Result<SegmentFile, _> = toml::from_str("[[device]]\nnmae = \"demo\"\n");
        assert!(bad.is_err(), "unknown keys are refused");
    }

    /// Every number of a full segment file (walked from the TOML, so a key added later and
    /// not checked fails here) is refused as NaN, ±inf or far out of range, naming its key.
    #[test]
    fn every_number_of_a_segment_file_is_range_checked() {
        const FULL: &str = r#"
            master_link_delay_ns = 70
            esc_delay_ns = 500
            link_delay_ns = 60
            [[device]]
            name = "demo"
            count = 2
            drift_ppm = 25.0
            esc_delay_ns = 600
            link_delay_ns = 120
        "#;
        let base: toml::Value = toml::from_str(FULL).unwrap();
        let desc: SegmentFile = toml::from_str(FULL).unwrap();
        check_segment(&desc).expect("the full file is fine");
        let mut keys = Vec::new();
        for (k, v) in base.as_table().unwrap() {
            match v {
                toml::Value::Array(a) => {
                    for (k2, v2) in a[0].as_table().unwrap() {
                        if v2.is_integer() || v2.is_float() {
                            keys.push((Some(k.clone()), k2.clone(), v2.is_float()));
                        }
                    }
                }
                v if v.is_integer() || v.is_float() => keys.push((None, k.clone(), v.is_float())),
                _ => {}
            }
        }
        assert_eq!(keys.len(), 7, "{keys:?}");
        for (table, key, float) in keys {
            let values: Vec<toml::Value> = if float {
                [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e9, -1e9]
                    .into_iter()
                    .map(toml::Value::Float)
                    .collect()
            } else {
                [-1i64, 1_000_000_000_000]
                    .into_iter()
                    .map(toml::Value::Integer)
                    .collect()
            };
            for x in values {
                let mut v = base.clone();
                match &table {
                    Some(t) => v[t.as_str()][0][key.as_str()] = x.clone(),
                    None => v[key.as_str()] = x.clone(),
                }
                let text = toml::to_string(&v).unwrap();
                let e = match toml::from_str::<SegmentFile>(&text) {
                    Err(e) => e.to_string(),
                    Ok(d) => match check_segment(&d) {
                        Err(e) => {
                            let m = e.to_string();
                            assert!(m.contains(" … "), "{key} = {x}: no range in {m}");
                            m
                        }
                        Ok(()) => panic!("{key} = {x} was accepted"),
                    },
                };
                assert!(e.contains(&key), "{key} = {x}: {e}");
            }
        }
        // The issue's values, through the file reader (the path in the message).
        let dir = std::env::temp_dir().join(format!("oxicat-seg-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("seg.toml");
        std::fs::write(&f, "[[device]]\nname = \"demo\"\ndrift_ppm = nan\n").unwrap();
        let e = read_segment_file(&f).unwrap_err().to_string();
        assert!(
            e.contains("seg.toml")
                && e.contains("device[0].drift_ppm = NaN is not in -1000 … 1000 ppm"),
            "{e}"
        );
        std::fs::write(
            &f,
            "[[device]]\nname = \"demo\"\nesc_delay_ns = 10000000000\n",
        )
        .unwrap();
        let e = read_segment_file(&f).unwrap_err().to_string();
        assert!(
            e.contains("device[0].esc_delay_ns = 10000000000 is not in 0 … 1000000 ns"),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn counts_beyond_the_limit_are_refused_before_building() {
        let e = parse_specs(&["demo:100000".into()])
            .unwrap_err()
            .to_string();
        assert!(e.contains("100000") && e.contains("1 … 1000"), "{e}");
        // The total counts, on the command line and in a segment file.
        let e = parse_specs(&["demo:600".into(), "demo:600".into()])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("the count of demo:600") && e.contains("1 … 1000"),
            "{e}"
        );
        let mut desc = parse_specs(&["demo:600".into()]).unwrap();
        desc.devices.push(desc.devices[0].clone());
        let e = build_segment(&desc).unwrap_err().to_string();
        assert!(
            e.contains("device[1].count") && e.contains("1 … 1000"),
            "{e}"
        );
    }

    #[test]
    fn served_firmware_nodes_beyond_the_limit_are_refused_with_the_figure() {
        let over = format!("demo:{}", MAX_SERVED_FIRMWARE_NODES + 1);
        let desc = parse_specs(std::slice::from_ref(&over)).unwrap();
        assert_eq!(firmware_nodes(&desc), MAX_SERVED_FIRMWARE_NODES + 1);
        let e = check_served(&desc).unwrap_err().to_string();
        assert!(
            e.contains(&(MAX_SERVED_FIRMWARE_NODES + 1).to_string())
                && e.contains(&format!("at most {MAX_SERVED_FIRMWARE_NODES}"))
                && e.contains("µs of CPU per device"),
            "{e}"
        );
        // The total counts, across entries; ESC twins do not.
        let half = MAX_SERVED_FIRMWARE_NODES / 2;
        let desc = parse_specs(&[format!("demo:{half},tue-es030:{}", half + 1)]).unwrap();
        assert!(check_served(&desc).is_err());
        let mut desc = parse_specs(&[format!("demo:{MAX_SERVED_FIRMWARE_NODES}")]).unwrap();
        assert!(check_served(&desc).is_ok());
        desc.devices.push(DeviceEntry {
            esi: Some("EL2008.xml".into()),
            name: String::new(),
            count: 100,
            ..desc.devices[0].clone()
        });
        assert_eq!(firmware_nodes(&desc), MAX_SERVED_FIRMWARE_NODES);
        assert!(check_served(&desc).is_ok());
        // Refused before anything is built or bound.
        let args = SimArgs {
            udp: Some("127.0.0.1:0".into()),
            ..SimArgs::quiet(vec![over])
        };
        let e = serve_until(&args, Arc::new(AtomicBool::new(false)))
            .unwrap_err()
            .to_string();
        assert!(e.contains("firmware-hosting devices"), "{e}");
    }

    #[test]
    fn a_spec_may_name_the_pdi_route() {
        let desc = parse_specs(&["demo:2@lan9252,tue-es030@ET1100 cia402-joint".into()]).unwrap();
        let routes: Vec<_> = desc.devices.iter().map(|d| d.pdi.as_deref()).collect();
        assert_eq!(routes, vec![Some("lan9252"), Some("ET1100"), None]);
        assert_eq!(desc.devices[0].count, 2);
        let (seg, names) = build_segment(&desc).unwrap();
        assert_eq!(seg.len(), 4);
        assert_eq!(names[3], "cia402-joint");
        let e = parse_specs(&["demo@spi".into()]).unwrap_err().to_string();
        assert!(
            e.contains("the route of demo@spi = spi") && e.contains("direct, lan9252 or et1100"),
            "{e}"
        );
        let e = parse_segment(
            "[[device]]\nname = \"demo\"\npdi = \"usb\"\n",
            Path::new("s.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("device[0].pdi = usb"), "{e}");
    }

    #[test]
    fn laelaps_legs_boot_in_chain_order() {
        let (seg, names) = build_segment(&parse_specs(&["laelaps-leg:4".into()]).unwrap()).unwrap();
        assert_eq!(seg.len(), 4);
        assert_eq!(summarize(&names), "laelaps-leg:4");
        let l = status_line(&seg, 0.0);
        assert!((0..4).all(|i| l.contains(&format!("{i}:INIT"))), "{l}");
    }

    #[test]
    fn status_shows_states() {
        let (seg, _) = build_segment(&parse_specs(&["demo:2".into()]).unwrap()).unwrap();
        let l = status_line(&seg, 2500.0);
        assert!(l.contains("2500 frames/s"), "{l}");
        assert!(l.contains("0:INIT") && l.contains("1:INIT"), "{l}");
        assert_eq!(al_state_name(0x14), "SAFEOP+ERR");
        assert!(al_code_text(0x001B).starts_with("0x001B "));
        // The code once, then its text (ethercrab's Display repeats the code).
        assert_eq!(al_code_text(0x001E), "0x001E Invalid input configuration");
    }
}
