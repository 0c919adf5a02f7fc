//! `oxicat-master`: master functions on `ethercrab`, the way the IgH `ethercat` tool offers
//! them — scan, state requests, SII read/write, SDO upload/download and information, PDO
//! assignment/mapping, an ESI from a live slave, register access, and cyclic process data
//! (watch, online write, DC-synchronous recording).
//!
//! A [`Master`] runs on a network interface ([`Link::Iface`], ethercrab's raw socket) or on
//! an in-process [`oxicat_sim::segment::Segment`] ([`Link::Sim`]); the functions do not
//! know how frames travel.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod al;
pub mod coe;
pub mod cyclic;
mod error;
pub mod esi;
pub mod experiment;
pub mod foe;
pub mod pdo;
pub mod plot;
pub mod results;
pub mod scenario;
pub mod sii;
pub mod tue_es030;
pub mod value;

use std::cell::Cell;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use ethercrab::subdevice_group::SubDeviceGroup;
use ethercrab::{Command, MainDevice, MainDeviceConfig, PduStorage, Timeouts};
use oxicat_sim::segment::Segment;
use oxicat_sim::transport::{spawn_inprocess_with, InProcessConfig};

pub use al::{AlState, AlStatus};
pub use error::MasterError;
pub use value::ValueType;

/// Most slaves a master handles.
pub const MAX_SLAVES: usize = 64;
/// Most process-data bytes (inputs + outputs) of all slaves.
pub const MAX_PDI: usize = 4096;

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

/// Where ethercrab's group is.
pub(crate) enum Slot {
    /// PRE-OP (after discovery).
    PreOp(Group),
    /// PRE-OP with FMMUs and process-data SyncManagers configured.
    Pdi(PdiGroup),
}

/// What discovery found about one slave (does not change while the master runs).
#[derive(Debug, Clone)]
pub(crate) struct Found {
    pub(crate) address: u16,
    pub(crate) alias: u16,
    pub(crate) name: String,
    pub(crate) identity: ethercrab::SubDeviceIdentity,
    pub(crate) delay_ns: u32,
}

/// How frames reach the slaves.
#[derive(Clone)]
pub enum Link {
    /// A network interface (raw Ethernet, EtherType 0x88A4).
    Iface(String),
    /// A virtual segment in this process (virtual time advances with every frame).
    Sim(Arc<Mutex<Segment>>),
}

impl Link {
    fn describe(&self) -> String {
        match self {
            Link::Iface(i) => format!("interface {i}"),
            Link::Sim(_) => "the virtual segment".to_string(),
        }
    }
}

/// Virtual time between the frames the master sends on a virtual segment.
pub const SIM_FRAME_GAP_NS: u64 = 10_000;

/// Time as the master sees it: the segment's virtual clock or the host's clock.
#[derive(Clone)]
pub(crate) enum Time {
    Sim(Arc<Mutex<Segment>>),
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
                timeouts: oxicat_sim::transport::virtual_timeouts(),
                mailbox_timeout: Duration::from_secs(5),
            },
            Link::Iface(_) => Self {
                timeouts: Timeouts {
                    state_transition: Duration::from_secs(10),
                    pdu: Duration::from_millis(100),
                    mailbox_response: Duration::from_secs(2),
                    wait_loop_delay: Duration::from_micros(500),
                    eeprom: Duration::from_millis(500),
                    ..Timeouts::default()
                },
                mailbox_timeout: Duration::from_secs(2),
            },
        }
    }
}

/// A master on one link: the slaves were discovered and are in PRE-OP.
pub struct Master {
    pub(crate) md: MainDevice<'static>,
    pub(crate) slot: Option<Slot>,
    pub(crate) time: Time,
    pub(crate) found: Vec<Found>,
    pub(crate) addresses: Vec<u16>,
    pub(crate) options: MasterOptions,
    pub(crate) mbx_counter: Cell<u8>,
    pub(crate) link_name: String,
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
            Link::Sim(seg) => {
                spawn_inprocess_with(
                    seg.clone(),
                    tx,
                    rx,
                    InProcessConfig {
                        frame_gap_ns: SIM_FRAME_GAP_NS,
                    },
                )
                .map_err(|e| MasterError::Io("in-process".into(), e))?;
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
            time,
            found: Vec::new(),
            addresses: Vec::new(),
            options,
            mbx_counter: Cell::new(1),
            link_name,
        };
        let group = futures_lite::future::block_on(m.init())?;
        m.found = group
            .iter(&m.md)
            .map(|s| Found {
                address: s.configured_address(),
                alias: s.alias_address(),
                name: s.name().to_string(),
                identity: s.identity(),
                delay_ns: s.propagation_delay(),
            })
            .collect();
        m.addresses = m.found.iter().map(|f| f.address).collect();
        m.slot = Some(Slot::PreOp(group));
        Ok(m)
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

    async fn init(&self) -> Result<Group, MasterError> {
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
            Ok(g) => Ok(g),
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
            ethercrab::error::Error::Timeout(_)
            | ethercrab::error::Error::WorkingCounter { .. } => {
                MasterError::NotAnswering { position, what }
            }
            e => MasterError::Ethercrab(format!("slave {position}: {what}"), e),
        }
    }

    /// Reads `len` bytes at ESC address `reg` of the slave at `position` (FPRD).
    pub fn reg_read(&self, position: usize, reg: u16, len: u16) -> Result<Vec<u8>, MasterError> {
        futures_lite::future::block_on(self.fprd(position, reg, len))
    }

    /// Writes `data` at ESC address `reg` of the slave at `position` (FPWR).
    pub fn reg_write(&self, position: usize, reg: u16, data: &[u8]) -> Result<(), MasterError> {
        futures_lite::future::block_on(self.fpwr(position, reg, data))
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
        futures_lite::future::block_on(self.al_status_async(position))
    }

    pub(crate) async fn al_status_async(&self, position: usize) -> Result<AlStatus, MasterError> {
        let b = self.fprd(position, 0x0130, 6).await?;
        Ok(AlStatus {
            raw: b[0],
            code: u16::from_le_bytes([b[4], b[5]]),
        })
    }

    /// Scans the slaves: addresses, alias, state, name, identity, ports.
    pub fn scan(&self) -> Result<Vec<SlaveInfo>, MasterError> {
        futures_lite::future::block_on(async {
            let mut out = Vec::new();
            for (position, sd) in self.found.iter().enumerate() {
                let id = sd.identity;
                let status = self.al_status_async(position).await?;
                let dl = self.read_u16(position, 0x0110).await?;
                let links = std::array::from_fn(|p| dl & (1 << (4 + p)) != 0);
                let open = std::array::from_fn(|p| dl & (1 << (9 + 2 * p)) != 0);
                out.push(SlaveInfo {
                    position,
                    address: sd.address,
                    alias: sd.alias,
                    status,
                    name: sd.name.clone(),
                    vendor_id: id.vendor_id,
                    product_code: id.product_id,
                    revision: id.revision,
                    serial: id.serial,
                    links,
                    open,
                    delay_ns: sd.delay_ns,
                });
            }
            Ok(out)
        })
    }

    /// Requests `state` from the slaves at `positions` through AL control (0x0120) and waits
    /// until each reaches it or reports an error; returns the final status of each.
    ///
    /// Requesting SAFEOP or OP first lets ethercrab configure the process data FMMUs and
    /// SyncManagers (as `ethercat states` relies on the master's configuration).
    pub fn request_state(
        &mut self,
        positions: &[usize],
        state: AlState,
    ) -> Result<Vec<(usize, AlStatus)>, MasterError> {
        if matches!(state, AlState::SafeOp | AlState::Op) {
            self.configure_process_data()?;
        }
        futures_lite::future::block_on(async {
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
            for &p in positions {
                let cur = self.al_status_async(p).await?;
                let from = cur.state().unwrap_or(AlState::Init);
                let steps: Vec<AlState> = if state == AlState::Boot {
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
                let mut ack = cur.error();
                let mut last = cur;
                for s in steps {
                    // Acknowledge a pending error together with the request.
                    let a = if ack { 0x10 } else { 0 };
                    self.fpwr(p, 0x0120, &[s.code() | a, 0]).await?;
                    last = self.wait_state(p, s).await?;
                    ack = false;
                }
                out.push((p, last));
            }
            Ok(out)
        })
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
    /// PRE-OP), once.
    pub(crate) fn configure_process_data(&mut self) -> Result<(), MasterError> {
        match self.slot.take() {
            Some(Slot::PreOp(g)) => {
                let g =
                    futures_lite::future::block_on(g.into_pre_op_pdi(&self.md)).map_err(|e| {
                        MasterError::Ethercrab("configuring the process data (PRE-OP)".into(), e)
                    })?;
                self.slot = Some(Slot::Pdi(g));
                Ok(())
            }
            Some(s) => {
                self.slot = Some(s);
                Ok(())
            }
            None => Err(MasterError::Usage(
                "the slaves already left PRE-OP for cyclic operation".into(),
            )),
        }
    }

    /// The slot's PDI group, configuring it first; the master gives it up (cyclic use).
    pub(crate) fn take_pdi_group(&mut self) -> Result<PdiGroup, MasterError> {
        self.configure_process_data()?;
        match self.slot.take() {
            Some(Slot::Pdi(g)) => Ok(g),
            _ => Err(MasterError::Usage("no process data group".into())),
        }
    }

    /// Name (SII) of the slave at `position`.
    pub fn name(&self, position: usize) -> Result<&str, MasterError> {
        self.address(position)?;
        Ok(&self.found[position].name)
    }

    /// Identity (vendor, product, revision, serial) of the slave at `position`.
    pub fn identity(&self, position: usize) -> Result<(u32, u32, u32, u32), MasterError> {
        self.address(position)?;
        let i = self.found[position].identity;
        Ok((i.vendor_id, i.product_id, i.revision, i.serial))
    }
}
