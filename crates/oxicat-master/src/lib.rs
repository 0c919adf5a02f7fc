//! `oxicat-master`: master functions on `ethercrab`, the way the IgH `ethercat` tool offers
//! them — scan, state requests, SII read/write, SDO upload/download and information, PDO
//! assignment/mapping, an ESI from a live slave, register access, and cyclic process data
//! (watch, online write, DC-synchronous recording).
//!
//! A [`Master`] runs on a network interface ([`Link::Iface`], ethercrab's raw socket), on a
//! segment served with EtherCAT over UDP ([`Link::Udp`]) or on a segment in this process
//! ([`Link::Sim`], any [`FramePipe`], e.g. `oxicat-sim`'s `Segment`); the functions do not
//! know how frames travel, and the master knows no simulator and no device.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod al;
mod bringup;
pub mod coe;
pub mod cyclic;
mod error;
pub mod esi;
mod exchange;
pub mod foe;
pub mod inprocess;
pub mod pdo;
pub mod sii;
mod udp;
pub mod value;

use oxicat_wire::regs;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use ethercrab::subdevice_group::SubDeviceGroup;
use ethercrab::{Command, MainDevice, MainDeviceConfig, PduStorage, Timeouts};
use inprocess::{inprocess_task, InProcessConfig, Runner};
pub use oxicat_wire::pipe::FramePipe;

pub use al::{AlState, AlStatus};
pub use error::MasterError;
pub use value::ValueType;

/// Most slaves a master handles (ethercrab's group capacity: a power of two). A segment of a
/// thousand twins, as a machine's configuration lists them, fits.
pub const MAX_SLAVES: usize = 1024;
/// Most process-data bytes (inputs + outputs) of all slaves; ethercrab splits an image
/// longer than a frame over several LRW frames per cycle.
pub const MAX_PDI: usize = 65536;

type Storage = PduStorage<16, { PduStorage::element_size(1100) }>;
/// The ethercrab group of all slaves, in PRE-OP.
pub(crate) type Group = SubDeviceGroup<MAX_SLAVES, MAX_PDI>;
/// The group in PRE-OP with its process data configured.
pub(crate) type PdiGroup = SubDeviceGroup<
    MAX_SLAVES,
    MAX_PDI,
    ethercrab::DefaultLock,
    ethercrab::subdevice_group::PreOpPdi,
>;

/// Stack given to an operation on ethercrab's group (see [`on_group_stack`]): debug builds
/// copy the ~300 KB group many times within one poll (ethercrab's discovery of a 1,024-slot
/// group took more than the main thread's 8 MB). Address space only: pages are touched as
/// the operation uses them.
const GROUP_STACK: usize = 64 << 20;

/// Runs `f`, an operation on ethercrab's group, on a stack of [`GROUP_STACK`] bytes
/// allocated for it (unless the thread's own has that much left).
pub(crate) fn on_group_stack<R>(f: impl FnOnce() -> R) -> R {
    stacker::maybe_grow(GROUP_STACK, GROUP_STACK, f)
}

/// Where ethercrab's group is. Boxed: a group holds [`MAX_SLAVES`] subdevices and the
/// [`MAX_PDI`]-byte image inline (hundreds of KB), too much to carry in a `Master` or move
/// on a thread's stack.
pub(crate) enum Slot {
    /// PRE-OP (after ethercrab's discovery).
    PreOp(Box<Group>),
    /// PRE-OP with FMMUs and process-data SyncManagers configured.
    Pdi(Box<PdiGroup>),
}

/// What discovery found about one slave.
#[derive(Debug, Clone)]
pub(crate) struct Found {
    pub(crate) alias: u16,
    /// Vendor, product, revision, serial (SII words 0x08..0x0F).
    pub(crate) identity: (u32, u32, u32, u32),
    /// System time delay (0x0928) as the last DC configuration left it.
    pub(crate) delay_ns: u32,
}

/// How frames reach the slaves.
#[derive(Clone)]
pub enum Link {
    /// A network interface (raw Ethernet, EtherType 0x88A4).
    Iface(String),
    /// A virtual segment in this process (virtual time advances with every frame).
    Sim(SharedPipe),
    /// A segment served with EtherCAT over UDP (`host:port`, e.g. `oxicat sim --udp`).
    Udp(String),
}

impl Link {
    fn describe(&self) -> String {
        match self {
            Link::Iface(i) => format!("interface {i}"),
            Link::Sim(_) => "the virtual segment".to_string(),
            Link::Udp(a) => format!("EtherCAT over UDP to {a}"),
        }
    }
}

/// A segment in this process, shared between the master's PDU loop and its clock.
pub type SharedPipe = Arc<Mutex<dyn FramePipe + Send>>;

/// Virtual time between the frames the master sends on a virtual segment.
pub const SIM_FRAME_GAP_NS: u64 = 10_000;

/// Time as the master sees it: the segment's virtual clock or the host's clock.
#[derive(Clone)]
pub(crate) enum Time {
    Sim(SharedPipe),
    Real,
}

impl Time {
    pub(crate) fn now(&self) -> u64 {
        match self {
            Time::Sim(s) => s.lock().unwrap_or_else(|e| e.into_inner()).now(),
            Time::Real => ethercrab::std::ethercat_now(),
        }
    }

    /// Waits until `t` (ns): advances the virtual clock, or sleeps.
    pub(crate) fn wait_until(&self, t: u64) {
        match self {
            Time::Sim(s) => s.lock().unwrap_or_else(|e| e.into_inner()).advance_to(t),
            Time::Real => {
                let now = ethercrab::std::ethercat_now();
                if t > now {
                    let d = t - now;
                    // Sleep most of it, spin the rest: the host is not a real-time kernel.
                    if d > 200_000 {
                        std::thread::sleep(Duration::from_nanos(d - 100_000));
                    }
                    while ethercrab::std::ethercat_now() < t {
                        std::hint::spin_loop();
                    }
                }
            }
        }
    }

    pub(crate) fn is_sim(&self) -> bool {
        matches!(self, Time::Sim(_))
    }
}

/// One slave as found by a scan.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SlaveInfo {
    /// Position in the segment (0 = first).
    pub position: usize,
    /// Configured station address.
    pub address: u16,
    /// Station alias.
    pub alias: u16,
    /// AL status and code.
    pub status: AlStatus,
    /// Name (SII).
    pub name: String,
    /// Vendor ID.
    pub vendor_id: u32,
    /// Product code.
    pub product_code: u32,
    /// Revision.
    pub revision: u32,
    /// Serial number.
    pub serial: u32,
    /// DL status (0x0110): per port (0..3) whether a link is detected.
    pub links: [bool; 4],
    /// DL status: per port whether the loop is open (communication passes on).
    pub open: [bool; 4],
    /// Propagation delay to this slave in ns (DC), 0 without DC.
    pub delay_ns: u32,
}

impl SlaveInfo {
    /// The ports column: `0:L 1:L 2:- 3:-` (L link and open, l link but closed, - none).
    pub fn ports(&self) -> String {
        (0..4)
            .map(|p| {
                let c = match (self.links[p], self.open[p]) {
                    (true, true) => "L",
                    (true, false) => "l",
                    _ => "-",
                };
                format!("{p}:{c}")
            })
            .collect::<Vec<_>>()
            .join(" ")
    }
}

/// Options of a master.
#[derive(Debug, Clone)]
pub struct MasterOptions {
    /// ethercrab timeouts.
    pub timeouts: Timeouts,
    /// Time to wait for a mailbox reply.
    pub mailbox_timeout: Duration,
}

impl MasterOptions {
    /// Defaults for a link: generous timeouts on the virtual segment (ethercrab waits in
    /// real time while the segment runs in virtual time).
    pub fn for_link(link: &Link) -> Self {
        match link {
            Link::Sim(_) => Self {
                timeouts: inprocess::virtual_timeouts(),
                mailbox_timeout: Duration::from_secs(5),
            },
            Link::Iface(_) | Link::Udp(_) => Self {
                timeouts: Timeouts {
                    state_transition: Duration::from_secs(10),
                    pdu: Duration::from_millis(250),
                    mailbox_response: Duration::from_secs(2),
                    wait_loop_delay: Duration::from_micros(500),
                    eeprom: Duration::from_millis(500),
                    ..Timeouts::default()
                },
                mailbox_timeout: Duration::from_secs(2),
            },
        }
    }

    /// These options for a segment that runs `k` times slower than real time (`oxicat sim
    /// --slowdown K`, `oxicat-emu sim --slowdown K`): every timeout, ethercrab's (PDU,
    /// EEPROM, mailbox echo and response, state transition) and the mailbox reply's, is
    /// `k` times longer, so each allows the segment the same time it would at real time.
    /// The wait between polls is kept. `k` of 0 or 1 changes nothing.
    pub fn stretched(mut self, k: u32) -> Self {
        let k = k.max(1);
        let t = &mut self.timeouts;
        for d in [
            &mut t.state_transition,
            &mut t.pdu,
            &mut t.eeprom,
            &mut t.mailbox_echo,
            &mut t.mailbox_response,
            &mut self.mailbox_timeout,
        ] {
            *d = d.saturating_mul(k);
        }
        self
    }
}

/// A master on one link.
///
/// Opening it does not disturb the segment: slaves keep their AL state, SyncManagers and
/// station addresses (as the IgH master keeps them between `ethercat` invocations). Only
/// slaves no master has touched since power-on (station address 0) get an address and are
/// brought from INIT to PRE-OP, as the IgH master's bus scan does. ethercrab's own
/// initialisation, which resets every slave to INIT, runs only for the cyclic verbs
/// (`watch`, `write`, `record`).
pub struct Master {
    pub(crate) md: MainDevice<'static>,
    /// ethercrab's group, created by the first cyclic use.
    pub(crate) slot: Option<Slot>,
    /// ethercrab's group was created and handed to a cyclic run.
    pub(crate) group_used: bool,
    /// SII images (up to the end of the categories) read so far, per position.
    pub(crate) sii_cache: std::cell::RefCell<Vec<Option<Vec<u8>>>>,
    pub(crate) time: Time,
    pub(crate) found: Vec<Found>,
    pub(crate) addresses: Vec<u16>,
    pub(crate) options: MasterOptions,
    /// Per slave, the counter of this master's last mailbox message (`None`: none yet).
    pub(crate) mbx_counter: std::cell::RefCell<Vec<Option<u8>>>,
    pub(crate) link_name: String,
    /// Cyclic runs take the slaves back to PRE-OP at their end (see
    /// [`Master::stop_cycling_as_if_gone`]).
    pub(crate) preop_after_cycling: bool,
    /// How a free-running cycle exchanges the process image.
    pub(crate) exchange: cyclic::Exchange,
    /// Runs the master's futures (with the in-process transport on a virtual segment).
    pub(crate) runner: Runner,
}

fn map_open_error(iface: &str, e: std::io::Error) -> MasterError {
    match e.raw_os_error() {
        Some(1) | Some(13) => MasterError::NoPermission(iface.to_string()),
        Some(19) => MasterError::NoInterface(iface.to_string()),
        _ if e.kind() == std::io::ErrorKind::PermissionDenied => {
            MasterError::NoPermission(iface.to_string())
        }
        _ => MasterError::Io(iface.to_string(), e),
    }
}

/// Opens a raw socket on `iface` the way [`Master::open`] does, to check access only.
pub fn check_interface(iface: &str) -> Result<(), MasterError> {
    if !std::path::Path::new("/sys/class/net").join(iface).exists() {
        return Err(MasterError::NoInterface(iface.to_string()));
    }
    Ok(())
}

impl Master {
    /// Opens `link`, discovers the slaves (ethercrab brings them to PRE-OP) and reads their
    /// addresses.
    pub fn open(link: Link) -> Result<Self, MasterError> {
        let options = MasterOptions::for_link(&link);
        Self::open_with(link, options)
    }

    /// [`Master::open`] with explicit options.
    pub fn open_with(link: Link, options: MasterOptions) -> Result<Self, MasterError> {
        // One PDU storage per master; it lives as long as the process.
        let storage: &'static Storage = Box::leak(Box::new(Storage::new()));
        let (tx, rx, pdu_loop) = storage
            .try_split()
            .map_err(|_| MasterError::Usage("PDU storage already in use".into()))?;
        let link_name = link.describe();
        let mut runner = Runner::default();
        let time = match &link {
            Link::Iface(iface) => {
                check_interface(iface)?;
                let task = ethercrab::std::tx_rx_task(iface, tx, rx)
                    .map_err(|e| map_open_error(iface, e))?;
                std::thread::Builder::new()
                    .name("oxicat-master-txrx".into())
                    .spawn(move || futures_lite::future::block_on(task))
                    .map_err(|e| MasterError::Io(iface.clone(), e))?;
                Time::Real
            }
            Link::Udp(addr) => {
                udp::spawn(udp::connect(addr)?, tx, rx, addr)?;
                Time::Real
            }
            Link::Sim(seg) => {
                // Polled on this thread inside every `Runner::block_on`: no transport
                // thread, no hand-over per frame.
                let task = inprocess_task(
                    seg.clone(),
                    tx,
                    rx,
                    InProcessConfig {
                        frame_gap_ns: SIM_FRAME_GAP_NS,
                    },
                );
                runner = Runner::with_task(task);
                Time::Sim(seg.clone())
            }
        };
        let md = MainDevice::new(
            pdu_loop,
            options.timeouts,
            MainDeviceConfig {
                dc_static_sync_iterations: 1000,
                ..MainDeviceConfig::default()
            },
        );
        let md: MainDevice<'static> = md;
        let mut m = Master {
            md,
            slot: None,
            group_used: false,
            sii_cache: Default::default(),
            time,
            found: Vec::new(),
            addresses: Vec::new(),
            options,
            mbx_counter: Default::default(),
            link_name,
            preop_after_cycling: true,
            exchange: cyclic::Exchange::default(),
            runner,
        };
        m.runner.clone().block_on(m.discover())?;
        Ok(m)
    }

    /// Finds the slaves without changing them: count (BRD), station addresses (APRD
    /// 0x0010; assigned with APWR only where 0), alias, identity (SII), DC delay; slaves
    /// that had no address are brought from INIT to PRE-OP.
    async fn discover(&mut self) -> Result<(), MasterError> {
        let n = self.count_slaves().await? as usize;
        if n == 0 {
            return Err(MasterError::NoSlaves(self.link_name.clone()));
        }
        if n > MAX_SLAVES {
            return Err(MasterError::Usage(format!(
                "{n} slaves answered; this master handles at most {MAX_SLAVES}"
            )));
        }
        let mut addresses = Vec::with_capacity(n);
        for i in 0..n {
            let b = Command::aprd(i as u16, 0x0010)
                .receive_slice(&self.md, 2)
                .await
                .map_err(|e| Self::not_answering(i, "APRD 0x0010 (station address)".into(), e))?;
            addresses.push(u16::from_le_bytes([b[0], b[1]]));
        }
        let mut fresh = vec![false; n];
        let mut seen = std::collections::HashSet::new();
        let duplicates = addresses.iter().any(|&a| a != 0 && !seen.insert(a));
        for i in 0..n {
            if addresses[i] == 0 || duplicates {
                fresh[i] = addresses[i] == 0;
                let a = 0x1000 + i as u16;
                Command::apwr(i as u16, 0x0010)
                    .send_receive_slice(&self.md, &a.to_le_bytes()[..])
                    .await
                    .map_err(|e| {
                        Self::not_answering(i, "APWR 0x0010 (station address)".into(), e)
                    })?;
                addresses[i] = a;
            }
        }
        self.addresses = addresses;
        *self.sii_cache.borrow_mut() = vec![None; n];
        let mut found = Vec::with_capacity(n);
        for p in 0..n {
            let alias = self.read_u16(p, 0x0012).await?;
            let w = self.sii_read_at(p, 0x0008, 16).await?;
            let u = |k: usize| u32::from_le_bytes([w[k], w[k + 1], w[k + 2], w[k + 3]]);
            let d = self.fprd(p, regs::DC_SYSTEM_TIME_DELAY, 4).await?;
            found.push(Found {
                alias,
                identity: (u(0), u(4), u(8), u(12)),
                delay_ns: u32::from_le_bytes([d[0], d[1], d[2], d[3]]),
            });
        }
        self.found = found;
        // Untouched slaves (no address before): INIT -> PRE-OP, as a master's bus scan does.
        let mut asked = Vec::new();
        for p in (0..n).filter(|&p| fresh[p]) {
            let st = self.al_status_async(p).await?;
            if st.state() == Some(AlState::Init) && !st.error() {
                match self.configure_mailbox(p, true).await {
                    Ok(()) => {
                        self.fpwr(p, regs::AL_CONTROL, &[AlState::PreOp.code(), 0])
                            .await?;
                        asked.push(p);
                    }
                    Err(e) => log::warn!("slave {p}: left in INIT: {e}"),
                }
            }
        }
        for p in asked {
            if let Err(e) = self.wait_state(p, AlState::PreOp).await {
                log::warn!("slave {p}: did not reach PRE-OP: {e}");
            }
        }
        Ok(())
    }

    /// Creates ethercrab's group (ethercrab resets every slave to INIT and brings them to
    /// PRE-OP), once; for the cyclic verbs.
    pub(crate) fn ensure_group(&mut self) -> Result<(), MasterError> {
        if self.slot.is_some() {
            return Ok(());
        }
        if self.group_used {
            return Err(MasterError::Usage(
                "the slaves already left PRE-OP for cyclic operation".into(),
            ));
        }
        // On the heap: ethercrab's initialisation is a large future (debug builds).
        let group = on_group_stack(|| self.runner.block_on(Box::pin(self.init())))?;
        let addresses: Vec<u16> = group
            .iter(&self.md)
            .map(|s| s.configured_address())
            .collect();
        if addresses.len() != self.addresses.len() {
            return Err(MasterError::Usage(format!(
                "{} slaves at the start, {} after ethercrab's initialisation",
                self.addresses.len(),
                addresses.len()
            )));
        }
        for (f, s) in self.found.iter_mut().zip(group.iter(&self.md)) {
            f.delay_ns = s.propagation_delay();
        }
        self.addresses = addresses;
        self.slot = Some(Slot::PreOp(group));
        Ok(())
    }

    /// Counts the slaves with a BRD of 0x0000 (its working counter); `Ok(0)` when the frame
    /// came back with nobody, an error when no frame came back at all.
    async fn count_slaves(&self) -> Result<u16, MasterError> {
        match Command::brd(0x0000)
            .with_wkc(0xFFFF)
            .receive_slice(&self.md, 1)
            .await
        {
            Ok(_) => Ok(0xFFFF),
            Err(ethercrab::error::Error::WorkingCounter { received, .. }) => Ok(received),
            Err(ethercrab::error::Error::Timeout(_)) => Err(MasterError::NoSlaves(format!(
                "{} (no frame came back: no link, or nothing connected)",
                self.link_name
            ))),
            Err(e) => Err(MasterError::Ethercrab(
                format!("first frame on {}", self.link_name),
                e,
            )),
        }
    }

    async fn init(&self) -> Result<Box<Group>, MasterError> {
        if self.count_slaves().await? == 0 {
            return Err(MasterError::NoSlaves(self.link_name.clone()));
        }
        let r = match &self.time {
            Time::Sim(seg) => {
                let clock = seg.lock().unwrap_or_else(|e| e.into_inner()).clock();
                self.md
                    .init_single_group::<MAX_SLAVES, MAX_PDI>(move || clock.now())
                    .await
            }
            Time::Real => {
                self.md
                    .init_single_group::<MAX_SLAVES, MAX_PDI>(ethercrab::std::ethercat_now)
                    .await
            }
        };
        match r {
            Ok(g) if g.is_empty() => Err(MasterError::NoSlaves(self.link_name.clone())),
            Ok(g) => Ok(Box::new(g)),
            Err(e) => Err(MasterError::Ethercrab(
                format!(
                    "discovery on {} (slaves answered but did not reach PRE-OP)",
                    self.link_name
                ),
                e,
            )),
        }
    }

    /// Number of slaves.
    pub fn len(&self) -> usize {
        self.addresses.len()
    }

    /// True when there are no slaves (never, after a successful open).
    pub fn is_empty(&self) -> bool {
        self.addresses.is_empty()
    }

    /// Configured address of the slave at `position`.
    pub fn address(&self, position: usize) -> Result<u16, MasterError> {
        self.addresses
            .get(position)
            .copied()
            .ok_or(MasterError::NoSuchSlave {
                position,
                count: self.addresses.len(),
            })
    }

    /// Positions selected by `-p` (all when `None`).
    pub fn positions(&self, position: Option<usize>) -> Result<Vec<usize>, MasterError> {
        match position {
            Some(p) => {
                self.address(p)?;
                Ok(vec![p])
            }
            None => Ok((0..self.len()).collect()),
        }
    }

    fn not_answering(position: usize, what: String, e: ethercrab::error::Error) -> MasterError {
        match e {
            e @ (ethercrab::error::Error::Timeout(_)
            | ethercrab::error::Error::WorkingCounter { .. }) => MasterError::NotAnswering {
                position,
                what: format!("{what}: {e}"),
            },
            e => MasterError::Ethercrab(format!("slave {position}: {what}"), e),
        }
    }

    /// Reads `len` bytes at ESC address `reg` of the slave at `position` (FPRD).
    pub fn reg_read(&self, position: usize, reg: u16, len: u16) -> Result<Vec<u8>, MasterError> {
        self.runner.block_on(self.fprd(position, reg, len))
    }

    /// Writes `data` at ESC address `reg` of the slave at `position` (FPWR).
    pub fn reg_write(&self, position: usize, reg: u16, data: &[u8]) -> Result<(), MasterError> {
        self.runner.block_on(self.fpwr(position, reg, data))
    }

    pub(crate) async fn fprd(
        &self,
        position: usize,
        reg: u16,
        len: u16,
    ) -> Result<Vec<u8>, MasterError> {
        let a = self.address(position)?;
        let mut out = Vec::with_capacity(len as usize);
        let mut off = 0u16;
        // ethercrab frames hold a bit over 1000 bytes of datagram data.
        while off < len {
            let n = (len - off).min(1024);
            let r = Command::fprd(a, reg.wrapping_add(off))
                .receive_slice(&self.md, n)
                .await
                .map_err(|e| {
                    Self::not_answering(position, format!("FPRD 0x{:04X}+{n}", reg + off), e)
                })?;
            out.extend_from_slice(&r);
            off += n;
        }
        Ok(out)
    }

    pub(crate) async fn fpwr(
        &self,
        position: usize,
        reg: u16,
        data: &[u8],
    ) -> Result<(), MasterError> {
        let a = self.address(position)?;
        let mut off = 0usize;
        while off < data.len() {
            let n = (data.len() - off).min(1024);
            let chunk = &data[off..off + n];
            Command::fpwr(a, reg.wrapping_add(off as u16))
                .send_receive_slice(&self.md, chunk)
                .await
                .map_err(|e| {
                    Self::not_answering(
                        position,
                        format!("FPWR 0x{:04X}+{n}", reg as usize + off),
                        e,
                    )
                })?;
            off += n;
        }
        Ok(())
    }

    pub(crate) async fn read_u16(&self, position: usize, reg: u16) -> Result<u16, MasterError> {
        let b = self.fprd(position, reg, 2).await?;
        Ok(u16::from_le_bytes([b[0], b[1]]))
    }

    /// AL status and code of the slave at `position`.
    pub fn al_status(&self, position: usize) -> Result<AlStatus, MasterError> {
        self.runner.block_on(self.al_status_async(position))
    }

    pub(crate) async fn al_status_async(&self, position: usize) -> Result<AlStatus, MasterError> {
        let b = self.fprd(position, regs::AL_STATUS, 6).await?;
        Ok(AlStatus {
            raw: b[0],
            code: u16::from_le_bytes([b[4], b[5]]),
        })
    }

    /// Scans the slaves: addresses, alias, state, name, identity, ports (reads only).
    pub fn scan(&self) -> Result<Vec<SlaveInfo>, MasterError> {
        self.runner.block_on(async {
            let mut out = Vec::new();
            for (position, sd) in self.found.iter().enumerate() {
                let (vendor_id, product_code, revision, serial) = sd.identity;
                let status = self.al_status_async(position).await?;
                let dl = self.read_u16(position, regs::DL_STATUS).await?;
                let links = std::array::from_fn(|p| dl & (1 << (4 + p)) != 0);
                let open = std::array::from_fn(|p| dl & (1 << (9 + 2 * p)) != 0);
                out.push(SlaveInfo {
                    position,
                    address: self.addresses[position],
                    alias: sd.alias,
                    status,
                    name: self.name_async(position).await?,
                    vendor_id,
                    product_code,
                    revision,
                    serial,
                    links,
                    open,
                    delay_ns: sd.delay_ns,
                });
            }
            Ok(out)
        })
    }

    /// Requests `state` from the slaves at `positions` through AL control (0x0120), one
    /// step at a time, and waits until each reaches it or reports an error; returns the
    /// final status of each. The slaves stay there when the master is gone.
    ///
    /// The master configures what each step needs itself, without resetting anything:
    /// the mailbox SyncManagers (SM0/SM1, or the bootstrap mailbox for BOOT) from the SII
    /// before PRE-OP; before SAFE-OP free run (0x1C32:01 = 0, where the slave has the
    /// object; SM2-synchronous, 1, where 0x1C32:04 says it does not run free; a slave that
    /// runs only DC-synchronous stops the request before any slave changed), SM2/SM3 sized from the PDO mapping, one output and one input FMMU, and the
    /// process-data watchdog off (0x0420 = 0: no cyclic master keeps it fed after the
    /// command).
    pub fn request_state(
        &mut self,
        positions: &[usize],
        state: AlState,
    ) -> Result<Vec<(usize, AlStatus)>, MasterError> {
        // On the heap: the walk is a large future in debug builds.
        self.runner.block_on(Box::pin(async {
            let mut out = Vec::new();
            for &p in positions {
                self.address(p)?;
            }
            // Up the state machine one step at a time (INIT -> PREOP -> SAFEOP -> OP), as a
            // slave refuses to skip a state (0x0011); down and BOOT (from INIT) directly.
            let rank = |s: AlState| match s {
                AlState::Init | AlState::Boot => 0,
                AlState::PreOp => 1,
                AlState::SafeOp => 2,
                AlState::Op => 3,
            };
            let ladder = [AlState::Init, AlState::PreOp, AlState::SafeOp, AlState::Op];
            // SAFE-OP/OP: the sync mode of every slave that can tell (PRE-OP and up) first, so
            // that a slave needing DC stops the request before any slave changed.
            let mut plan = std::collections::HashMap::new();
            if matches!(state, AlState::SafeOp | AlState::Op) {
                for &p in positions {
                    let st = self.al_status_async(p).await?.state();
                    if matches!(st, Some(AlState::PreOp | AlState::SafeOp | AlState::Op)) {
                        plan.insert(p, self.plain_sync_mode(p).await?);
                    }
                }
            }
            for &p in positions {
                let cur = self.al_status_async(p).await?;
                let from = cur.state().unwrap_or(AlState::Init);
                if from == state && !cur.error() {
                    out.push((p, cur));
                    continue;
                }
                // Back to SAFE-OP/OP from SAFE-OP (or OP with an error) with a sync mode other
                // than the planned one (a DC recording left it): through PRE-OP, where it can
                // change.
                let planned = plan.get(&p).copied().flatten().unwrap_or(bringup::FREE_RUN);
                let via_preop = matches!(state, AlState::SafeOp | AlState::Op)
                    && matches!(from, AlState::SafeOp | AlState::Op)
                    && (rank(state) > rank(from) || cur.error())
                    && self.sync_mode_async(p).await?.is_some_and(|m| m != planned);
                let steps: Vec<AlState> = if via_preop {
                    let mut v = vec![AlState::PreOp];
                    v.extend(ladder[2..=rank(state)].iter().copied());
                    v
                } else if state == AlState::Boot {
                    if from == AlState::Init || from == AlState::Boot {
                        vec![AlState::Boot]
                    } else {
                        vec![AlState::Init, AlState::Boot]
                    }
                } else if from == AlState::Boot {
                    let mut v = vec![AlState::Init];
                    v.extend(ladder[1..=rank(state)].iter().copied());
                    v
                } else if rank(state) > rank(from) {
                    ladder[rank(from) + 1..=rank(state)].to_vec()
                } else {
                    vec![state]
                };
                if cur.error() {
                    self.acknowledge(p, from).await?;
                }
                let mut last = cur;
                for s in steps {
                    match s {
                        AlState::PreOp if rank(from) == 0 || from == AlState::Boot => {
                            self.configure_mailbox(p, true).await?
                        }
                        AlState::Boot => self.configure_boot_mailbox(p).await?,
                        AlState::SafeOp => {
                            let mode = match plan.get(&p) {
                                Some(m) => *m,
                                None => self.plain_sync_mode(p).await?,
                            };
                            self.set_sync_mode(p, mode.unwrap_or(bringup::FREE_RUN))
                                .await?;
                            self.configure_pd(p).await?;
                        }
                        _ => {}
                    }
                    self.fpwr(p, regs::AL_CONTROL, &[s.code(), 0]).await?;
                    last = self.wait_state(p, s).await?;
                }
                out.push((p, last));
            }
            Ok(out)
        }))
    }

    /// Acknowledges a pending AL error (0x0120 = current state | 0x10) and waits until the
    /// slave clears it (a slave whose error stays keeps the flag: the next request says so).
    async fn acknowledge(&self, position: usize, state: AlState) -> Result<(), MasterError> {
        self.fpwr(position, regs::AL_CONTROL, &[state.code() | 0x10, 0])
            .await?;
        let deadline = std::time::Instant::now() + self.options.timeouts.state_transition;
        while self.al_status_async(position).await?.error() {
            if std::time::Instant::now() > deadline {
                break;
            }
            self.pause().await;
        }
        Ok(())
    }

    async fn wait_state(&self, position: usize, state: AlState) -> Result<AlStatus, MasterError> {
        let deadline = std::time::Instant::now() + self.options.timeouts.state_transition;
        loop {
            let st = self.al_status_async(position).await?;
            if st.state() == Some(state) && !st.error() {
                return Ok(st);
            }
            if st.error() {
                return Err(MasterError::StateChange {
                    position,
                    requested: state,
                    status: st,
                });
            }
            if std::time::Instant::now() > deadline {
                return Err(MasterError::StateChange {
                    position,
                    requested: state,
                    status: st,
                });
            }
            self.pause().await;
        }
    }

    /// A short pause between polls (real time; on the virtual segment time advances with
    /// the next frame anyway).
    pub(crate) async fn pause(&self) {
        if !self.time.is_sim() {
            std::thread::sleep(Duration::from_micros(200));
        }
    }

    /// Lets ethercrab configure the process-data SyncManagers and FMMUs (slaves stay in
    /// PRE-OP), once; creates ethercrab's group first (a reset of every slave).
    pub(crate) fn configure_process_data(&mut self) -> Result<(), MasterError> {
        self.ensure_group()?;
        match self.slot.take() {
            Some(Slot::PreOp(g)) => {
                let md = &self.md;
                // The group moves out of its box inside a future on the heap.
                let g = on_group_stack(|| {
                    self.runner.block_on(Box::pin(async move {
                        (*g).into_pre_op_pdi(md).await.map(Box::new)
                    }))
                })
                .map_err(|e| {
                    MasterError::Ethercrab("configuring the process data (PRE-OP)".into(), e)
                })?;
                self.slot = Some(Slot::Pdi(g));
                Ok(())
            }
            Some(s) => {
                self.slot = Some(s);
                Ok(())
            }
            None => Err(MasterError::Usage("no process data group".into())),
        }
    }

    /// The slot's PDI group, configuring it first; the master gives it up (cyclic use).
    pub(crate) fn take_pdi_group(&mut self) -> Result<Box<PdiGroup>, MasterError> {
        self.configure_process_data()?;
        match self.slot.take() {
            Some(Slot::Pdi(g)) => {
                self.group_used = true;
                Ok(g)
            }
            _ => Err(MasterError::Usage("no process data group".into())),
        }
    }

    /// The SII image of the slave at `position` up to the end of its categories (read once
    /// per master).
    pub(crate) async fn sii_image(&self, position: usize) -> Result<Vec<u8>, MasterError> {
        self.address(position)?;
        if let Some(img) = self
            .sii_cache
            .borrow()
            .get(position)
            .and_then(|c| c.clone())
        {
            return Ok(img);
        }
        let img = self.sii_read_async(position, false).await?;
        if let Some(c) = self.sii_cache.borrow_mut().get_mut(position) {
            *c = Some(img.clone());
        }
        Ok(img)
    }

    pub(crate) async fn name_async(&self, position: usize) -> Result<String, MasterError> {
        let img = self.sii_image(position).await?;
        Ok(oxicat_esi::sii::parse(&img)
            .ok()
            // The order string (general category), as ethercrab and IgH name a slave.
            .and_then(|m| m.order_code.or(m.name))
            .unwrap_or_default())
    }

    /// Name (SII) of the slave at `position`.
    pub fn name(&self, position: usize) -> Result<String, MasterError> {
        self.runner.block_on(self.name_async(position))
    }

    /// The sync mode of the slave at `position` (0x1C32:01: 0 free run, 1 SM2
    /// synchronous, 2 DC SYNC0, 3 DC SYNC1), `None` when it has no such object.
    pub fn sync_mode(&self, position: usize) -> Result<Option<u16>, MasterError> {
        self.runner.block_on(self.sync_mode_async(position))
    }

    /// 0x1C32:04 (sync modes supported: bit 0 free run, 1 SM-synchronous, 2/3 DC) of the
    /// slave at `position`, `None` when it has no such object or no CoE now.
    pub fn sync_modes_supported(&self, position: usize) -> Result<Option<u16>, MasterError> {
        self.runner.block_on(async {
            if !self.has_coe(position).await {
                return Ok(None);
            }
            match self.sdo_upload_async(position, 0x1C32, 4).await {
                Ok(b) if b.len() >= 2 => Ok(Some(u16::from_le_bytes([b[0], b[1]]))),
                Ok(_) | Err(MasterError::SdoAbort { .. }) => Ok(None),
                Err(e) => Err(e),
            }
        })
    }

    /// Identity (vendor, product, revision, serial) of the slave at `position`.
    pub fn identity(&self, position: usize) -> Result<(u32, u32, u32, u32), MasterError> {
        self.address(position)?;
        Ok(self.found[position].identity)
    }
}

#[cfg(test)]
mod options_tests {
    use super::*;

    #[test]
    fn stretched_options_allow_a_slowed_segment_the_same_time() {
        let link = Link::Udp("127.0.0.1:1".into());
        let o = MasterOptions::for_link(&link);
        let s = o.clone().stretched(20);
        let (a, b) = (o.timeouts, s.timeouts);
        assert_eq!(b.pdu, a.pdu * 20);
        assert_eq!(b.eeprom, a.eeprom * 20);
        assert_eq!(b.mailbox_echo, a.mailbox_echo * 20);
        assert_eq!(b.mailbox_response, a.mailbox_response * 20);
        assert_eq!(b.state_transition, a.state_transition * 20);
        assert_eq!(s.mailbox_timeout, o.mailbox_timeout * 20);
        assert_eq!(
            b.wait_loop_delay, a.wait_loop_delay,
            "the poll interval is kept"
        );
        let same = o.clone().stretched(0);
        assert_eq!(
            (same.timeouts.pdu, same.mailbox_timeout),
            (a.pdu, o.mailbox_timeout)
        );
    }
}
