//! Every `unsafe` block of oxicat's AF_XDP path: the `bpf()` and socket system calls, the
//! memory maps of the UMEM and the four rings, and the rings' shared producer/consumer
//! words. Each function checks what it hands the kernel (sizes from the kernel's own
//! offsets, indices masked to the ring) so that the rest of the crate is safe code.
#![allow(unsafe_code)]

use std::ffi::CString;
use std::io;
use std::mem::size_of;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd, RawFd};
use std::ptr::NonNull;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

use crate::insn::Insn;

/// `bpf()` commands (linux/bpf.h `enum bpf_cmd`).
const BPF_MAP_CREATE: i32 = 0;
const BPF_MAP_UPDATE_ELEM: i32 = 2;
const BPF_PROG_LOAD: i32 = 5;
const BPF_LINK_CREATE: i32 = 28;
/// `enum bpf_map_type`.
const BPF_MAP_TYPE_XSKMAP: u32 = 17;
/// `enum bpf_prog_type`.
const BPF_PROG_TYPE_XDP: u32 = 6;
/// `enum bpf_attach_type`.
const BPF_XDP: u32 = 37;

fn bpf<T>(cmd: i32, attr: &mut T) -> io::Result<i64> {
    // SAFETY: `attr` is a #[repr(C)] prefix of `union bpf_attr` for `cmd`, valid for its
    // size; the kernel copies at most that many bytes and zero-fills the rest.
    let r = unsafe {
        libc::syscall(
            libc::SYS_bpf,
            cmd,
            attr as *mut T as *mut libc::c_void,
            size_of::<T>() as libc::c_uint,
        )
    };
    if r < 0 {
        Err(io::Error::last_os_error())
    } else {
        Ok(r)
    }
}

fn owned(fd: i64) -> OwnedFd {
    // SAFETY: `fd` was just returned by the kernel as a new descriptor that nothing else owns.
    unsafe { OwnedFd::from_raw_fd(fd as RawFd) }
}

/// A BPF object name (at most 15 bytes and the NUL; `bpftool` shows it).
fn object_name(name: &str) -> [u8; 16] {
    let mut n = [0u8; 16];
    for (d, s) in n.iter_mut().zip(name.bytes().take(15)) {
        *d = s;
    }
    n
}

#[repr(C)]
struct MapCreate {
    map_type: u32,
    key_size: u32,
    value_size: u32,
    max_entries: u32,
    map_flags: u32,
    inner_map_fd: u32,
    numa_node: u32,
    map_name: [u8; 16],
}

/// Creates an XSKMAP of `entries` (key: queue index, value: socket fd).
pub fn xskmap_create(entries: u32) -> io::Result<OwnedFd> {
    let mut a = MapCreate {
        map_type: BPF_MAP_TYPE_XSKMAP,
        key_size: 4,
        value_size: 4,
        max_entries: entries,
        map_flags: 0,
        inner_map_fd: 0,
        numa_node: 0,
        map_name: object_name("oxicat_xsks"),
    };
    bpf(BPF_MAP_CREATE, &mut a).map(owned)
}

#[repr(C)]
struct MapElem {
    map_fd: u32,
    _pad: u32,
    key: u64,
    value: u64,
    flags: u64,
}

/// Puts socket `value` at `key` in the map.
pub fn map_update(map: &OwnedFd, key: u32, value: &OwnedFd) -> io::Result<()> {
    let k = key;
    let v = value.as_raw_fd() as u32;
    let mut a = MapElem {
        map_fd: map.as_raw_fd() as u32,
        _pad: 0,
        key: &k as *const u32 as u64,
        value: &v as *const u32 as u64,
        flags: 0,
    };
    bpf(BPF_MAP_UPDATE_ELEM, &mut a).map(|_| ())
}

#[repr(C)]
struct ProgLoad {
    prog_type: u32,
    insn_cnt: u32,
    insns: u64,
    license: u64,
    log_level: u32,
    log_size: u32,
    log_buf: u64,
    kern_version: u32,
    prog_flags: u32,
    prog_name: [u8; 16],
    prog_ifindex: u32,
    expected_attach_type: u32,
}

/// Loads an XDP program; on refusal the verifier's log comes with the error.
pub fn prog_load_xdp(program: &[Insn], license: &str) -> Result<OwnedFd, (io::Error, String)> {
    let license = CString::new(license).map_err(|_| {
        (
            io::Error::from(io::ErrorKind::InvalidInput),
            String::from("licence string with a NUL"),
        )
    })?;
    let mut log = vec![0u8; 64 * 1024];
    let mut a = ProgLoad {
        prog_type: BPF_PROG_TYPE_XDP,
        insn_cnt: program.len() as u32,
        insns: program.as_ptr() as u64,
        license: license.as_ptr() as u64,
        log_level: 1,
        log_size: log.len() as u32,
        log_buf: log.as_mut_ptr() as u64,
        kern_version: 0,
        prog_flags: 0,
        prog_name: object_name("oxicat_ecat"),
        prog_ifindex: 0,
        expected_attach_type: BPF_XDP,
    };
    match bpf(BPF_PROG_LOAD, &mut a) {
        Ok(fd) => Ok(owned(fd)),
        Err(e) => {
            let end = log.iter().position(|&b| b == 0).unwrap_or(log.len());
            Err((e, String::from_utf8_lossy(&log[..end]).trim().to_string()))
        }
    }
}

#[repr(C)]
struct LinkCreate {
    prog_fd: u32,
    target_ifindex: u32,
    attach_type: u32,
    flags: u32,
}

/// Attaches an XDP program to an interface as a BPF link (closing the link detaches it).
/// `flags`: `XDP_FLAGS_SKB_MODE` (2) or `XDP_FLAGS_DRV_MODE` (4).
pub fn xdp_link_create(prog: &OwnedFd, ifindex: u32, flags: u32) -> io::Result<OwnedFd> {
    let mut a = LinkCreate {
        prog_fd: prog.as_raw_fd() as u32,
        target_ifindex: ifindex,
        attach_type: BPF_XDP,
        flags,
    };
    bpf(BPF_LINK_CREATE, &mut a).map(owned)
}

/// The index of interface `name` (None: no such interface).
pub fn ifindex(name: &str) -> Option<u32> {
    let c = CString::new(name).ok()?;
    // SAFETY: `c` is a NUL-terminated string that outlives the call.
    let i = unsafe { libc::if_nametoindex(c.as_ptr()) };
    (i != 0).then_some(i)
}

/// A system call's result: negative is the failure `errno` describes.
fn check<R: Default + PartialOrd>(r: R) -> io::Result<()> {
    if r < R::default() {
        Err(io::Error::last_os_error())
    } else {
        Ok(())
    }
}

/// A new AF_XDP socket.
pub fn xsk_socket() -> io::Result<OwnedFd> {
    // SAFETY: plain system call without pointers.
    let fd = unsafe { libc::socket(libc::AF_XDP, libc::SOCK_RAW | libc::SOCK_CLOEXEC, 0) };
    if fd < 0 {
        Err(io::Error::last_os_error())
    } else {
        Ok(owned(fd as i64))
    }
}

fn setsockopt<T>(fd: &OwnedFd, name: libc::c_int, value: &T) -> io::Result<()> {
    // SAFETY: `value` is valid for size_of::<T>() bytes during the call.
    check(unsafe {
        libc::setsockopt(
            fd.as_raw_fd(),
            libc::SOL_XDP,
            name,
            value as *const T as *const libc::c_void,
            size_of::<T>() as libc::socklen_t,
        )
    })
}

/// Registers `umem` as the socket's UMEM in chunks of `chunk` bytes.
pub fn umem_register(fd: &OwnedFd, umem: &Mmap, chunk: u32) -> io::Result<()> {
    let reg = libc::xdp_umem_reg {
        addr: umem.ptr.as_ptr() as u64,
        len: umem.len as u64,
        chunk_size: chunk,
        headroom: 0,
        flags: 0,
        tx_metadata_len: 0,
    };
    setsockopt(fd, libc::XDP_UMEM_REG, &reg)
}

/// Which ring to size and map.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RingKind {
    /// Frames given to the kernel to receive into.
    Fill,
    /// Frames the kernel has sent.
    Completion,
    /// Received frames.
    Rx,
    /// Frames to send.
    Tx,
}

impl RingKind {
    fn opt(self) -> libc::c_int {
        match self {
            Self::Fill => libc::XDP_UMEM_FILL_RING,
            Self::Completion => libc::XDP_UMEM_COMPLETION_RING,
            Self::Rx => libc::XDP_RX_RING,
            Self::Tx => libc::XDP_TX_RING,
        }
    }

    fn pgoff(self) -> libc::off_t {
        match self {
            Self::Fill => libc::XDP_UMEM_PGOFF_FILL_RING as libc::off_t,
            Self::Completion => libc::XDP_UMEM_PGOFF_COMPLETION_RING as libc::off_t,
            Self::Rx => libc::XDP_PGOFF_RX_RING,
            Self::Tx => libc::XDP_PGOFF_TX_RING,
        }
    }

    fn offsets(self, o: &libc::xdp_mmap_offsets) -> libc::xdp_ring_offset {
        let r = match self {
            Self::Fill => &o.fr,
            Self::Completion => &o.cr,
            Self::Rx => &o.rx,
            Self::Tx => &o.tx,
        };
        libc::xdp_ring_offset {
            producer: r.producer,
            consumer: r.consumer,
            desc: r.desc,
            flags: r.flags,
        }
    }
}

/// Sets the number of entries of a ring (a power of two).
pub fn ring_size(fd: &OwnedFd, kind: RingKind, entries: u32) -> io::Result<()> {
    setsockopt(fd, kind.opt(), &entries)
}

/// The kernel's offsets of the rings' words in their maps.
pub fn mmap_offsets(fd: &OwnedFd) -> io::Result<libc::xdp_mmap_offsets> {
    // SAFETY: all-zero is a valid value of this plain-integer struct.
    let mut o: libc::xdp_mmap_offsets = unsafe { std::mem::zeroed() };
    let mut len = size_of::<libc::xdp_mmap_offsets>() as libc::socklen_t;
    // SAFETY: `o` is writable for `len` bytes; the kernel writes at most that.
    check(unsafe {
        libc::getsockopt(
            fd.as_raw_fd(),
            libc::SOL_XDP,
            libc::XDP_MMAP_OFFSETS,
            &mut o as *mut _ as *mut libc::c_void,
            &mut len,
        )
    })?;
    if (len as usize) < size_of::<libc::xdp_mmap_offsets>() {
        // A kernel before 5.4 (no flags word, so no need_wakeup): not supported here.
        return Err(io::Error::from(io::ErrorKind::Unsupported));
    }
    Ok(o)
}

/// A memory map, unmapped on drop.
#[derive(Debug)]
pub struct Mmap {
    ptr: NonNull<u8>,
    len: usize,
}

// SAFETY: the map is plain memory owned by this value; moving it between threads is fine.
unsafe impl Send for Mmap {}

impl Mmap {
    /// Anonymous, private, populated memory of `len` bytes (the UMEM).
    pub fn anonymous(len: usize) -> io::Result<Self> {
        // SAFETY: a new anonymous mapping; no existing memory is touched.
        let p = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                len,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_PRIVATE | libc::MAP_ANONYMOUS | libc::MAP_POPULATE,
                -1,
                0,
            )
        };
        Self::from_raw(p, len)
    }

    fn from_raw(p: *mut libc::c_void, len: usize) -> io::Result<Self> {
        if p == libc::MAP_FAILED {
            return Err(io::Error::last_os_error());
        }
        NonNull::new(p as *mut u8)
            .map(|ptr| Self { ptr, len })
            .ok_or_else(|| io::Error::other("mmap returned null"))
    }

    /// `len` bytes at `at`, if inside the map.
    pub fn slice(&self, at: usize, len: usize) -> Option<&[u8]> {
        let end = at.checked_add(len)?;
        // SAFETY: bounds checked; the bytes belong to a frame the kernel handed back (the
        // caller only asks for frames it owns), so nothing writes them meanwhile.
        (end <= self.len)
            .then(|| unsafe { std::slice::from_raw_parts(self.ptr.as_ptr().add(at), len) })
    }

    /// `len` writable bytes at `at`, if inside the map.
    pub fn slice_mut(&mut self, at: usize, len: usize) -> Option<&mut [u8]> {
        let end = at.checked_add(len)?;
        // SAFETY: bounds checked; as in `slice`, the frame is owned by the caller.
        (end <= self.len)
            .then(|| unsafe { std::slice::from_raw_parts_mut(self.ptr.as_ptr().add(at), len) })
    }
}

impl Drop for Mmap {
    fn drop(&mut self) {
        // SAFETY: the map was made by mmap with this length and is unmapped once.
        unsafe {
            libc::munmap(self.ptr.as_ptr() as *mut libc::c_void, self.len);
        }
    }
}

/// One of the four rings, mapped from the socket: `T` is `u64` (fill, completion: frame
/// addresses) or `xdp_desc` (rx, tx).
#[derive(Debug)]
pub struct Ring<T: Copy> {
    map: Mmap,
    producer: usize,
    consumer: usize,
    flags: usize,
    desc: usize,
    mask: u32,
    _t: std::marker::PhantomData<T>,
}

impl<T: Copy> Ring<T> {
    /// Maps ring `kind` of `entries` (a power of two, as sized with [`ring_size`]).
    pub fn map(
        fd: &OwnedFd,
        kind: RingKind,
        entries: u32,
        offsets: &libc::xdp_mmap_offsets,
    ) -> io::Result<Self> {
        if !entries.is_power_of_two() {
            return Err(io::Error::from(io::ErrorKind::InvalidInput));
        }
        let o = kind.offsets(offsets);
        let len = o.desc as usize + entries as usize * size_of::<T>();
        for word in [o.producer, o.consumer, o.flags] {
            if word as usize + 4 > o.desc as usize || word & 3 != 0 {
                return Err(io::Error::other("ring offsets out of place"));
            }
        }
        if o.desc as usize & (std::mem::align_of::<T>() - 1) != 0 {
            return Err(io::Error::other("ring descriptors misaligned"));
        }
        // SAFETY: maps the socket's ring at the kernel's page offset for it; the length is
        // the kernel's descriptor offset plus the ring's entries.
        let p = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                len,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_SHARED | libc::MAP_POPULATE,
                fd.as_raw_fd(),
                kind.pgoff(),
            )
        };
        Ok(Self {
            map: Mmap::from_raw(p, len)?,
            producer: o.producer as usize,
            consumer: o.consumer as usize,
            flags: o.flags as usize,
            desc: o.desc as usize,
            mask: entries - 1,
            _t: std::marker::PhantomData,
        })
    }

    fn word(&self, at: usize) -> &AtomicU32 {
        // SAFETY: `at` was checked in `map` to be 4-aligned and inside the map, which lives
        // as long as `self`; the kernel accesses these words atomically too.
        unsafe { &*(self.map.ptr.as_ptr().add(at) as *const AtomicU32) }
    }

    /// The producer index (acquire: entries before it are visible).
    pub fn producer(&self) -> u32 {
        self.word(self.producer).load(Ordering::Acquire)
    }

    /// The consumer index.
    pub fn consumer(&self) -> u32 {
        self.word(self.consumer).load(Ordering::Acquire)
    }

    /// Publishes the producer index (release: entries written before it are visible).
    pub fn set_producer(&self, v: u32) {
        self.word(self.producer).store(v, Ordering::Release)
    }

    /// Publishes the consumer index.
    pub fn set_consumer(&self, v: u32) {
        self.word(self.consumer).store(v, Ordering::Release)
    }

    /// Whether the kernel asks for a wakeup (`XDP_RING_NEED_WAKEUP`).
    pub fn needs_wakeup(&self) -> bool {
        self.word(self.flags).load(Ordering::Relaxed) & libc::XDP_RING_NEED_WAKEUP != 0
    }

    /// Number of entries.
    pub fn entries(&self) -> u32 {
        self.mask + 1
    }

    fn slot(&self, index: u32) -> *mut T {
        let at = self.desc + (index & self.mask) as usize * size_of::<T>();
        // SAFETY: the slot lies in the map: `map` sized it as desc + entries × size_of::<T>().
        unsafe { self.map.ptr.as_ptr().add(at) as *mut T }
    }

    /// The entry at `index` (masked to the ring).
    pub fn read(&self, index: u32) -> T {
        // SAFETY: `slot` is in bounds and aligned (checked in `map`); the entry was
        // published by the kernel's producer store, which `producer` acquired.
        unsafe { self.slot(index).read_volatile() }
    }

    /// Writes the entry at `index` (masked), to be published with [`Ring::set_producer`].
    pub fn write(&mut self, index: u32, value: T) {
        // SAFETY: as in `read`; the slot is ours until the producer index passes it.
        unsafe { self.slot(index).write_volatile(value) }
    }
}

/// Waits up to `timeout` for the socket to be readable (`ppoll`, µs resolution).
pub fn wait_readable(fd: &OwnedFd, timeout: Duration) -> io::Result<bool> {
    let mut p = libc::pollfd {
        fd: fd.as_raw_fd(),
        events: libc::POLLIN,
        revents: 0,
    };
    let ts = libc::timespec {
        tv_sec: timeout.as_secs().min(i32::MAX as u64) as libc::time_t,
        tv_nsec: timeout.subsec_nanos() as libc::c_long,
    };
    // SAFETY: one pollfd and one timespec, both valid during the call.
    let r = unsafe { libc::ppoll(&mut p, 1, &ts, std::ptr::null()) };
    match r {
        r if r < 0 => {
            let e = io::Error::last_os_error();
            if e.kind() == io::ErrorKind::Interrupted {
                Ok(false)
            } else {
                Err(e)
            }
        }
        0 => Ok(false),
        _ => Ok(p.revents & libc::POLLIN != 0),
    }
}

/// Kicks the kernel to send what the TX ring holds (`sendto` with no data).
pub fn kick_tx(fd: &OwnedFd) -> io::Result<()> {
    // SAFETY: no buffer and no address are passed.
    check(unsafe {
        libc::sendto(
            fd.as_raw_fd(),
            std::ptr::null(),
            0,
            libc::MSG_DONTWAIT,
            std::ptr::null(),
            0,
        )
    })
}

/// Wakes the driver to refill from the fill ring (`recvfrom` with no data).
pub fn kick_rx(fd: &OwnedFd) -> io::Result<()> {
    // SAFETY: no buffer and no address are passed.
    check(unsafe {
        libc::recvfrom(
            fd.as_raw_fd(),
            std::ptr::null_mut(),
            0,
            libc::MSG_DONTWAIT,
            std::ptr::null_mut(),
            std::ptr::null_mut(),
        )
    })
}

/// Binds the socket to `queue` of interface `ifindex` with `flags` (`XDP_COPY`,
/// `XDP_ZEROCOPY`, `XDP_USE_NEED_WAKEUP`).
pub fn bind(fd: &OwnedFd, ifindex: u32, queue: u32, flags: u16) -> io::Result<()> {
    let a = libc::sockaddr_xdp {
        sxdp_family: libc::AF_XDP as u16,
        sxdp_flags: flags,
        sxdp_ifindex: ifindex,
        sxdp_queue_id: queue,
        sxdp_shared_umem_fd: 0,
    };
    // SAFETY: `a` is a valid sockaddr_xdp for the call's duration.
    check(unsafe {
        libc::bind(
            fd.as_raw_fd(),
            &a as *const _ as *const libc::sockaddr,
            size_of::<libc::sockaddr_xdp>() as libc::socklen_t,
        )
    })
}
