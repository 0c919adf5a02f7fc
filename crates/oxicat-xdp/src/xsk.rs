//! The AF_XDP socket: UMEM, rings, bind, XSKMAP, program and link, and the frame exchange
//! over them. Safe code over the `sys` module.

use std::fmt;
use std::io;
use std::os::fd::OwnedFd;
use std::time::Duration;

use crate::insn;
use crate::sys::{self, Mmap, Ring, RingKind};

/// Size of a UMEM frame (chunk); frames up to this minus the kernel's headroom are received.
const FRAME: u32 = 2048;
/// `XDP_FLAGS_SKB_MODE`: generic XDP, in the stack after the driver built an skb.
const XDP_FLAGS_SKB_MODE: u32 = 1 << 1;
/// `XDP_FLAGS_DRV_MODE`: native XDP, in the driver.
const XDP_FLAGS_DRV_MODE: u32 = 1 << 2;
/// Times a TX kick is retried when the kernel is busy, before the frame is left in the ring
/// for the next kick.
const KICK_TRIES: u32 = 8;

/// Where the XDP program runs, and whether frames are copied.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Mode {
    /// Native (in the driver) if the driver has XDP, else generic; copy mode.
    #[default]
    Auto,
    /// Generic XDP (`XDP_FLAGS_SKB_MODE`): any interface; copy mode.
    Generic,
    /// Native XDP (`XDP_FLAGS_DRV_MODE`); copy mode.
    Native,
    /// Native XDP and a zero-copy bind (`XDP_ZEROCOPY`): drivers with AF_XDP zero-copy only.
    ZeroCopy,
}

impl fmt::Display for Mode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Auto => "auto",
            Self::Generic => "generic (skb) XDP, copy mode",
            Self::Native => "native XDP, copy mode",
            Self::ZeroCopy => "native XDP, zero-copy",
        })
    }
}

/// Options of [`XdpSocket::open`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Config {
    /// Where the program runs and whether frames are copied.
    pub mode: Mode,
    /// The interface queue the socket binds to.
    pub queue: u32,
    /// UMEM frames (a power of two, at least 64): half receive, half send.
    pub frames: u32,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            mode: Mode::Auto,
            queue: 0,
            frames: 4096,
        }
    }
}

/// The step of [`XdpSocket::open`] the kernel refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// No interface of that name (`if_nametoindex`).
    Interface,
    /// The queue is not one of the interface's rx queues.
    Queue,
    /// `socket(AF_XDP, SOCK_RAW, 0)`.
    Socket,
    /// The UMEM: `mmap` of its memory or `setsockopt(XDP_UMEM_REG)`.
    Umem,
    /// Sizing or mapping the fill, completion, RX or TX ring.
    Rings,
    /// `bind()` of the socket to the interface queue.
    Bind,
    /// `bpf(BPF_MAP_CREATE)` of the XSKMAP, or `bpf(BPF_MAP_UPDATE_ELEM)` putting the socket in it.
    Map,
    /// `bpf(BPF_PROG_LOAD)` of the XDP program (the verifier's log comes with it).
    Program,
    /// `bpf(BPF_LINK_CREATE)` attaching the program to the interface.
    Attach,
}

/// Why an AF_XDP socket could not be set up: the step, what the kernel said, and details.
#[derive(Debug)]
pub struct XdpError {
    /// What was refused.
    pub step: Step,
    /// The kernel's error.
    pub source: io::Error,
    /// More about it: the mode asked for, the verifier's log, the queues there are.
    pub detail: String,
}

impl XdpError {
    fn new(step: Step, source: io::Error, detail: impl Into<String>) -> Self {
        Self {
            step,
            source,
            detail: detail.into(),
        }
    }

    /// What to do about it, when the error says.
    pub fn hint(&self) -> Option<&'static str> {
        let errno = self.source.raw_os_error()?;
        Some(match (self.step, errno) {
            (_, libc::EPERM) | (_, libc::EACCES) => {
                "needs CAP_NET_ADMIN, CAP_NET_RAW and CAP_BPF (run as root)"
            }
            (Step::Socket, libc::EAFNOSUPPORT) => {
                "this kernel has no AF_XDP sockets (CONFIG_XDP_SOCKETS)"
            }
            (Step::Attach, libc::EBUSY) | (Step::Attach, libc::EEXIST) => {
                "another XDP program is attached to the interface (`ip link show` names it; \
                 `ip link set dev IFACE xdp off` removes one attached without a link)"
            }
            (Step::Attach, libc::EOPNOTSUPP) | (Step::Attach, libc::EINVAL) => {
                "the driver has no native XDP: use generic XDP (--xdp=generic)"
            }
            (Step::Bind, libc::EOPNOTSUPP) => {
                "the driver has no AF_XDP zero-copy: use copy mode (--xdp)"
            }
            (Step::Bind, libc::EBUSY) => "another AF_XDP socket is bound to this queue",
            (Step::Umem, libc::ENOMEM) | (Step::Rings, libc::ENOMEM) => {
                "locked memory limit too low (`ulimit -l`)"
            }
            _ => return None,
        })
    }
}

impl fmt::Display for XdpError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let what = match self.step {
            Step::Interface => "if_nametoindex",
            Step::Queue => "choosing the rx queue",
            Step::Socket => "socket(AF_XDP, SOCK_RAW)",
            Step::Umem => "the UMEM (setsockopt XDP_UMEM_REG)",
            Step::Rings => "the rings (setsockopt and mmap of XDP_MMAP_OFFSETS)",
            Step::Bind => "bind() of the AF_XDP socket",
            Step::Map => "bpf(BPF_MAP_CREATE / BPF_MAP_UPDATE_ELEM) of the XSKMAP",
            Step::Program => "bpf(BPF_PROG_LOAD) of the XDP program",
            Step::Attach => "bpf(BPF_LINK_CREATE) attaching the XDP program",
        };
        write!(f, "{what} refused: {}", self.source)?;
        if !self.detail.is_empty() {
            write!(f, " ({})", self.detail)?;
        }
        if let Some(h) = self.hint() {
            write!(f, "; {h}")?;
        }
        Ok(())
    }
}

impl std::error::Error for XdpError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        Some(&self.source)
    }
}

/// The number of rx queues of an interface, from sysfs (`/sys/class/net/IF/queues/rx-*`).
fn rx_queues(name: &str) -> Option<u32> {
    let dir = std::fs::read_dir(format!("/sys/class/net/{name}/queues")).ok()?;
    let n = dir
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with("rx-"))
        .count();
    u32::try_from(n).ok().filter(|&n| n > 0)
}

/// An AF_XDP socket on one interface queue with the EtherCAT-steering program attached.
/// Dropping it detaches the program.
pub struct XdpSocket {
    // Fields drop in this order: the link first (detaches the program), the socket last.
    _link: OwnedFd,
    _prog: OwnedFd,
    _map: OwnedFd,
    rx: Ring<libc::xdp_desc>,
    tx: Ring<libc::xdp_desc>,
    fill: Ring<u64>,
    comp: Ring<u64>,
    fd: OwnedFd,
    umem: Mmap,
    rx_cons: u32,
    fill_prod: u32,
    tx_prod: u32,
    comp_cons: u32,
    /// Frames free for sending.
    tx_free: Vec<u64>,
    /// Received frames not yet back in the fill ring (only if it was full).
    rx_spare: Vec<u64>,
    /// The mode the program was attached in (never `Auto`).
    mode: Mode,
    queue: u32,
    /// Bound zero-copy (else copy mode, where `sendto` is what sends: every send kicks).
    zero_copy: bool,
    /// Frames the kernel handed back with an address outside the UMEM (never expected).
    bad_descs: u64,
}

impl fmt::Debug for XdpSocket {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("XdpSocket")
            .field("mode", &self.mode)
            .field("queue", &self.queue)
            .finish_non_exhaustive()
    }
}

impl XdpSocket {
    /// Sets up AF_XDP on queue `config.queue` of interface `iface` and attaches the program.
    pub fn open(iface: &str, config: &Config) -> Result<Self, XdpError> {
        let ifindex = sys::ifindex(iface).ok_or_else(|| {
            XdpError::new(
                Step::Interface,
                io::Error::from(io::ErrorKind::NotFound),
                format!("no interface {iface:?}"),
            )
        })?;
        if let Some(n) = rx_queues(iface) {
            if config.queue >= n {
                return Err(XdpError::new(
                    Step::Queue,
                    io::Error::from(io::ErrorKind::InvalidInput),
                    format!("{iface} has rx queues 0..{n}, not {}", config.queue),
                ));
            }
        }
        let frames = config.frames;
        if !frames.is_power_of_two() || frames < 64 {
            return Err(XdpError::new(
                Step::Umem,
                io::Error::from(io::ErrorKind::InvalidInput),
                format!("{frames} frames: a power of two of at least 64"),
            ));
        }
        let half = frames / 2;
        let fd = sys::xsk_socket().map_err(|e| XdpError::new(Step::Socket, e, ""))?;
        let umem = Mmap::anonymous(frames as usize * FRAME as usize)
            .map_err(|e| XdpError::new(Step::Umem, e, "mmap"))?;
        sys::umem_register(&fd, &umem, FRAME)
            .map_err(|e| XdpError::new(Step::Umem, e, format!("{frames} frames of {FRAME} B")))?;
        let rings = [
            RingKind::Fill,
            RingKind::Completion,
            RingKind::Rx,
            RingKind::Tx,
        ];
        for k in rings {
            sys::ring_size(&fd, k, half)
                .map_err(|e| XdpError::new(Step::Rings, e, format!("{k:?} ring of {half}")))?;
        }
        let off = sys::mmap_offsets(&fd)
            .map_err(|e| XdpError::new(Step::Rings, e, "getsockopt XDP_MMAP_OFFSETS"))?;
        let ring_err = |k: RingKind| move |e| XdpError::new(Step::Rings, e, format!("mmap {k:?}"));
        let mut fill: Ring<u64> =
            Ring::map(&fd, RingKind::Fill, half, &off).map_err(ring_err(RingKind::Fill))?;
        let comp: Ring<u64> = Ring::map(&fd, RingKind::Completion, half, &off)
            .map_err(ring_err(RingKind::Completion))?;
        let rx = Ring::map(&fd, RingKind::Rx, half, &off).map_err(ring_err(RingKind::Rx))?;
        let tx = Ring::map(&fd, RingKind::Tx, half, &off).map_err(ring_err(RingKind::Tx))?;
        // The first half of the UMEM receives, the second half sends.
        for k in 0..half {
            fill.write(k, u64::from(k) * u64::from(FRAME));
        }
        fill.set_producer(half);
        let tx_free = (half..frames)
            .rev()
            .map(|k| u64::from(k) * u64::from(FRAME))
            .collect();

        let zero_copy = config.mode == Mode::ZeroCopy;
        let copy = if zero_copy {
            libc::XDP_ZEROCOPY
        } else {
            libc::XDP_COPY
        };
        sys::bind(&fd, ifindex, config.queue, copy | libc::XDP_USE_NEED_WAKEUP).map_err(|e| {
            XdpError::new(
                Step::Bind,
                e,
                format!(
                    "{iface} queue {}, {}",
                    config.queue,
                    if zero_copy { "zero-copy" } else { "copy mode" }
                ),
            )
        })?;

        let entries = rx_queues(iface).unwrap_or(1).max(config.queue + 1);
        let map = sys::xskmap_create(entries)
            .map_err(|e| XdpError::new(Step::Map, e, format!("XSKMAP of {entries}")))?;
        sys::map_update(&map, config.queue, &fd)
            .map_err(|e| XdpError::new(Step::Map, e, "putting the socket in the XSKMAP"))?;
        let program = insn::ethercat_redirect(std::os::fd::AsRawFd::as_raw_fd(&map));
        let prog = sys::prog_load_xdp(&program, "Dual MIT/GPL")
            .map_err(|(e, log)| XdpError::new(Step::Program, e, format!("verifier: {log}")))?;
        let attach = |flags: u32| sys::xdp_link_create(&prog, ifindex, flags);
        let (link, mode) = match config.mode {
            Mode::Generic => (attach(XDP_FLAGS_SKB_MODE), Mode::Generic),
            Mode::Native => (attach(XDP_FLAGS_DRV_MODE), Mode::Native),
            Mode::ZeroCopy => (attach(XDP_FLAGS_DRV_MODE), Mode::ZeroCopy),
            Mode::Auto => match attach(XDP_FLAGS_DRV_MODE) {
                Ok(l) => (Ok(l), Mode::Native),
                Err(e)
                    if matches!(
                        e.raw_os_error(),
                        Some(libc::EOPNOTSUPP) | Some(libc::EINVAL)
                    ) =>
                {
                    // No native XDP in this driver: generic; `mode()` tells the caller.
                    let _ = e;
                    (attach(XDP_FLAGS_SKB_MODE), Mode::Generic)
                }
                Err(e) => (Err(e), Mode::Native),
            },
        };
        let link = link.map_err(|e| XdpError::new(Step::Attach, e, format!("{iface}, {mode}")))?;
        Ok(Self {
            _link: link,
            _prog: prog,
            _map: map,
            rx,
            tx,
            fill,
            comp,
            fd,
            umem,
            rx_cons: 0,
            fill_prod: half,
            tx_prod: 0,
            comp_cons: 0,
            tx_free,
            rx_spare: Vec::new(),
            mode,
            queue: config.queue,
            zero_copy,
            bad_descs: 0,
        })
    }

    /// The mode the program was attached in.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// The interface queue the socket is bound to.
    pub fn queue(&self) -> u32 {
        self.queue
    }

    /// Descriptors the kernel returned outside the UMEM (dropped; never expected).
    pub fn bad_descs(&self) -> u64 {
        self.bad_descs
    }

    /// Takes the next received frame into `buf` without waiting; `false` when the RX ring
    /// is empty.
    pub fn try_recv(&mut self, buf: &mut Vec<u8>) -> io::Result<bool> {
        self.flush_tx()?;
        loop {
            if self.rx.producer() == self.rx_cons {
                if self.fill.needs_wakeup() {
                    ignore_busy(sys::kick_rx(&self.fd))?;
                }
                return Ok(false);
            }
            let d = self.rx.read(self.rx_cons);
            self.rx_cons = self.rx_cons.wrapping_add(1);
            let got = match self.umem.slice(d.addr as usize, d.len as usize) {
                Some(frame) => {
                    buf.clear();
                    buf.extend_from_slice(frame);
                    true
                }
                None => {
                    self.bad_descs += 1;
                    false
                }
            };
            self.rx.set_consumer(self.rx_cons);
            self.refill(d.addr & !u64::from(FRAME - 1));
            if got {
                return Ok(true);
            }
        }
    }

    /// Gives a received frame back to the kernel to receive into.
    fn refill(&mut self, addr: u64) {
        self.rx_spare.push(addr);
        let free = self
            .fill
            .entries()
            .wrapping_sub(self.fill_prod.wrapping_sub(self.fill.consumer()));
        let n = (free as usize).min(self.rx_spare.len());
        for _ in 0..n {
            if let Some(a) = self.rx_spare.pop() {
                self.fill.write(self.fill_prod, a);
                self.fill_prod = self.fill_prod.wrapping_add(1);
            }
        }
        self.fill.set_producer(self.fill_prod);
    }

    /// Waits up to `timeout` for the RX ring to have a frame (`ppoll` on the socket).
    pub fn wait(&self, timeout: Duration) -> io::Result<bool> {
        if self.rx.producer() != self.rx_cons {
            return Ok(true);
        }
        sys::wait_readable(&self.fd, timeout)
    }

    /// Queues `frame` for sending and kicks the kernel.
    pub fn send(&mut self, frame: &[u8]) -> io::Result<()> {
        if frame.len() > FRAME as usize {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("a frame of {} B is larger than a UMEM frame", frame.len()),
            ));
        }
        self.reap();
        if self.tx_free.is_empty() {
            self.kick()?;
            self.reap();
        }
        let Some(addr) = self.tx_free.pop() else {
            return Err(io::Error::new(
                io::ErrorKind::WouldBlock,
                "every AF_XDP send frame is still with the kernel",
            ));
        };
        let Some(dst) = self.umem.slice_mut(addr as usize, frame.len()) else {
            self.bad_descs += 1;
            return Err(io::Error::other("a send frame outside the UMEM"));
        };
        dst.copy_from_slice(frame);
        // As many send frames as TX ring entries: the ring has room for every free frame.
        self.tx.write(
            self.tx_prod,
            libc::xdp_desc {
                addr,
                len: frame.len() as u32,
                options: 0,
            },
        );
        self.tx_prod = self.tx_prod.wrapping_add(1);
        self.tx.set_producer(self.tx_prod);
        self.kick()
    }

    /// Kicks TX if the kernel has not taken everything in the TX ring yet.
    fn flush_tx(&mut self) -> io::Result<()> {
        if self.tx.consumer() != self.tx_prod {
            self.kick()?;
        }
        self.reap();
        Ok(())
    }

    fn kick(&mut self) -> io::Result<()> {
        // Copy mode transmits inside `sendto` (or `poll`): kick whatever the flag says, or a
        // spinning server that never polls would never send.
        if self.zero_copy && !self.tx.needs_wakeup() {
            return Ok(());
        }
        for _ in 0..KICK_TRIES {
            match sys::kick_tx(&self.fd) {
                Ok(()) => return Ok(()),
                Err(e) if busy(&e) => {
                    self.reap();
                    std::hint::spin_loop();
                }
                Err(e) => return Err(e),
            }
        }
        // Still busy: the frame stays in the ring and goes with the next kick.
        Ok(())
    }

    /// Takes sent frames back from the completion ring.
    fn reap(&mut self) {
        let prod = self.comp.producer();
        if prod == self.comp_cons {
            return;
        }
        while self.comp_cons != prod {
            let a = self.comp.read(self.comp_cons);
            self.tx_free.push(a & !u64::from(FRAME - 1));
            self.comp_cons = self.comp_cons.wrapping_add(1);
        }
        self.comp.set_consumer(self.comp_cons);
    }
}

fn busy(e: &io::Error) -> bool {
    matches!(
        e.raw_os_error(),
        Some(libc::EAGAIN) | Some(libc::EBUSY) | Some(libc::ENOBUFS) | Some(libc::EINTR)
    )
}

fn ignore_busy(r: io::Result<()>) -> io::Result<()> {
    match r {
        Err(e) if busy(&e) => Ok(()),
        r => r,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::insn::{reg::*, Insn};
    use std::os::fd::AsRawFd;

    /// Root (CAP_BPF) or skipped with the reason; in CI (which runs as root) never skipped.
    fn root() -> bool {
        let euid = std::fs::read_to_string("/proc/self/status")
            .ok()
            .and_then(|s| {
                s.lines()
                    .find(|l| l.starts_with("Uid:"))
                    .and_then(|l| l.split_whitespace().nth(2).map(|e| e == "0"))
            })
            .unwrap_or(false);
        let ci = std::env::var_os("CI").is_some_and(|v| !v.is_empty() && v != "false" && v != "0");
        if !euid {
            assert!(!ci, "needs root in CI");
            eprintln!("skipped: needs root for bpf() (CAP_BPF)");
        }
        euid
    }

    #[test]
    fn the_kernel_verifier_accepts_the_program() {
        if !root() {
            return;
        }
        let map = sys::xskmap_create(1).expect("BPF_MAP_CREATE of an XSKMAP");
        let p = insn::ethercat_redirect(map.as_raw_fd());
        if let Err((e, log)) = sys::prog_load_xdp(&p, "Dual MIT/GPL") {
            panic!("BPF_PROG_LOAD refused: {e}\n{log}");
        }
    }

    #[test]
    fn a_refused_program_comes_with_the_verifier_log() {
        if !root() {
            return;
        }
        // Reads the EtherType without checking data_end first.
        let p = [
            Insn::ldx_w(R2, R1, 0),
            Insn::ldx_h(R0, R2, 12),
            Insn::mov64_imm(R0, insn::XDP_PASS),
            Insn::exit(),
        ];
        match sys::prog_load_xdp(&p, "Dual MIT/GPL") {
            Ok(_) => panic!("the verifier took an unchecked packet read"),
            Err((e, log)) => {
                assert_eq!(e.raw_os_error(), Some(libc::EACCES), "{e}");
                assert!(log.contains("invalid access to packet"), "{log}");
            }
        }
    }

    #[test]
    fn open_names_what_is_wrong() {
        let e = XdpSocket::open("oxicat-nope0", &Config::default()).unwrap_err();
        assert_eq!(e.step, Step::Interface);
        assert!(e.to_string().contains("oxicat-nope0"), "{e}");
        let e = XdpSocket::open(
            "lo",
            &Config {
                frames: 100,
                ..Config::default()
            },
        )
        .unwrap_err();
        assert_eq!(e.step, Step::Umem, "{e}");
        let e = XdpSocket::open(
            "lo",
            &Config {
                queue: 4096,
                ..Config::default()
            },
        )
        .unwrap_err();
        assert_eq!(e.step, Step::Queue, "{e}");
    }
}
