//! `oxicat` for Python: serve a virtual EtherCAT segment (the devices of `oxicat sim`) on a
//! network interface or a UDP port from a background thread, look at its slaves' process
//! data and inject faults while a master (pysoem, an application under test) drives it.
//!
//! Building and serving are `oxicat::sim_cmd`'s (`describe`, `build_segment`,
//! `serve_segment_until`); this crate only holds the shared segment, the stop flag and the
//! thread. Errors are `oxicat.OxicatError` with the Rust message; a panic in the serving
//! thread is reported by `stop()`, never unwinds into Python.
#![forbid(unsafe_code)]

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;

use oxicat::sim_cmd::{self, SimArgs, SimError};
use oxicat_sim::realtime::RealtimeConfig;
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyIndexError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyBytes;

type SimSegment = oxicat_sim::segment::Segment;

create_exception!(
    oxicat,
    OxicatError,
    PyException,
    "An error of the oxicat segment (building, serving or a fault on it), with oxicat's message."
);

fn err(e: impl std::fmt::Display) -> PyErr {
    OxicatError::new_err(e.to_string())
}

/// SyncManager registers: 8 bytes each from 0x0800 (start, length, control, status,
/// activate, PDI control).
const SM_BASE: usize = 0x0800;
/// SyncManagers looked at for process data.
const SM_COUNT: usize = 16;

/// The process data an ESC holds in its buffered SyncManagers of one direction (`ecat_writes`:
/// outputs, written by the master; otherwise inputs), in SyncManager order: each SM's
/// newest completely written buffer, read from memory without touching the buffer state.
fn process_image(mem: &[u8], ecat_writes: bool) -> Vec<u8> {
    let mut out = Vec::new();
    for i in 0..SM_COUNT {
        let r = SM_BASE + 8 * i;
        let Some(regs) = mem.get(r..r + 8) else { break };
        let start = usize::from(u16::from_le_bytes([regs[0], regs[1]]));
        let len = usize::from(u16::from_le_bytes([regs[2], regs[3]]));
        let (ctrl, status, activate) = (regs[4], regs[5], regs[6]);
        let buffered = ctrl & 0x03 == 0;
        let dir_write = (ctrl >> 2) & 0x03 == 1;
        if activate & 1 == 0 || !buffered || len == 0 || dir_write != ecat_writes {
            continue;
        }
        // Status bits 4..5: the last buffer written completely (3: none yet, buffer 0).
        let b = match (status >> 4) & 0x03 {
            3 => 0,
            b => usize::from(b),
        };
        let at = start + b * len;
        if let Some(data) = mem.get(at..at + len) {
            out.extend_from_slice(data);
        }
    }
    out
}

/// The buffered SyncManager areas (start, length) the PDI writes (the inputs), in order.
fn input_areas(mem: &[u8]) -> Vec<(u16, usize)> {
    let mut v = Vec::new();
    for i in 0..SM_COUNT {
        let r = SM_BASE + 8 * i;
        let Some(regs) = mem.get(r..r + 8) else { break };
        let start = u16::from_le_bytes([regs[0], regs[1]]);
        let len = usize::from(u16::from_le_bytes([regs[2], regs[3]]));
        let (ctrl, activate) = (regs[4], regs[6]);
        if activate & 1 != 0 && ctrl & 0x03 == 0 && (ctrl >> 2) & 0x03 == 0 && len > 0 {
            v.push((start, len));
        }
    }
    v
}

/// A virtual EtherCAT segment served on a UDP port or a network interface from a
/// background thread until `stop()` (or the end of a `with` block).
///
/// `Segment(["demo:2"])` serves two demo slaves on a free UDP port of 127.0.0.1 (its
/// `address`); `Segment(esi=["EL2008.xml"], iface="veth1")` serves a twin of a vendor's
/// device on raw Ethernet (root or CAP_NET_RAW). Devices are those of `oxicat sim`
/// (`oxicat sim --list`), `segment_file` a TOML segment file or an `oxicat scan --save`
/// directory, `slowdown` runs the segment K times slower than real time.
#[pyclass(module = "oxicat")]
struct Segment {
    segment: Arc<Mutex<SimSegment>>,
    names: Vec<String>,
    address: Option<String>,
    iface: Option<String>,
    stop: Arc<AtomicBool>,
    thread: Mutex<Option<JoinHandle<Result<(), SimError>>>>,
}

impl Segment {
    fn lock(&self) -> MutexGuard<'_, SimSegment> {
        self.segment.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn check(&self, position: usize) -> PyResult<()> {
        if position < self.names.len() {
            Ok(())
        } else {
            Err(PyIndexError::new_err(format!(
                "no slave at position {position} (the segment has {})",
                self.names.len()
            )))
        }
    }

    fn halt(&self, py: Python<'_>) -> PyResult<()> {
        self.stop.store(true, Ordering::Relaxed);
        let handle = self.thread.lock().unwrap_or_else(|e| e.into_inner()).take();
        let Some(h) = handle else { return Ok(()) };
        match py.allow_threads(|| h.join()) {
            Ok(Ok(())) => Ok(()),
            Ok(Err(e)) => Err(err(e)),
            Err(_) => Err(OxicatError::new_err("the serving thread panicked")),
        }
    }
}

#[pymethods]
impl Segment {
    #[new]
    #[pyo3(signature = (devices=None, *, esi=None, segment_file=None, udp=None, iface=None, slowdown=1, quiet=true))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        devices: Option<Vec<String>>,
        esi: Option<Vec<String>>,
        segment_file: Option<PathBuf>,
        udp: Option<String>,
        iface: Option<String>,
        slowdown: u32,
        quiet: bool,
    ) -> PyResult<Self> {
        if !(1..=10_000).contains(&slowdown) {
            return Err(PyValueError::new_err(format!(
                "slowdown {slowdown} is not in 1..=10000"
            )));
        }
        if udp.is_some() && iface.is_some() {
            return Err(PyValueError::new_err("give udp or iface, not both"));
        }
        let udp = match (&udp, &iface) {
            (None, None) => Some("127.0.0.1:0".to_string()),
            _ => udp,
        };
        let args = SimArgs {
            iface: iface.clone(),
            udp: udp.clone(),
            segment: segment_file,
            eni: None,
            esi_dir: Vec::new(),
            devices: devices.unwrap_or_default(),
            esi: esi.unwrap_or_default(),
            list: false,
            spin: false,
            quiet,
            slowdown,
            rt: None,
            rt_cpu: None,
            xdp: None,
        };
        let (seg, names) = py
            .allow_threads(|| {
                let desc = sim_cmd::describe(&args)?;
                sim_cmd::build_segment(&desc)
            })
            .map_err(err)?;
        let segment = Arc::new(Mutex::new(seg));
        let stop = Arc::new(AtomicBool::new(false));
        let (shared, flag, names2) = (segment.clone(), stop.clone(), names.clone());
        let (address, thread) = match &iface {
            Some(name) => {
                let port =
                    oxicat_sim::net::raw::RawPort::open(name, RealtimeConfig::default().idle)
                        .map_err(err)?;
                let h = std::thread::spawn(move || {
                    sim_cmd::serve_segment_until(&args, port, shared, &names2, flag)
                });
                (None, h)
            }
            None => {
                let port = oxicat_sim::net::udp::UdpPort::bind(udp.as_deref().unwrap_or_default())
                    .map_err(err)?;
                let addr = port.local_addr().to_string();
                let h = std::thread::spawn(move || {
                    sim_cmd::serve_segment_until(&args, port, shared, &names2, flag)
                });
                (Some(addr), h)
            }
        };
        Ok(Self {
            segment,
            names,
            address,
            iface,
            stop,
            thread: Mutex::new(Some(thread)),
        })
    }

    /// The UDP address served ("127.0.0.1:PORT"), None on an interface.
    #[getter]
    fn address(&self) -> Option<String> {
        self.address.clone()
    }

    /// The network interface served, None on UDP.
    #[getter]
    fn iface(&self) -> Option<String> {
        self.iface.clone()
    }

    /// The device name of every slave, in line order.
    #[getter]
    fn slaves(&self) -> Vec<String> {
        self.names.clone()
    }

    /// Whether the serving thread still runs.
    #[getter]
    fn running(&self) -> bool {
        self.thread
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .as_ref()
            .is_some_and(|h| !h.is_finished())
    }

    fn __len__(&self) -> usize {
        self.names.len()
    }

    fn __repr__(&self) -> String {
        let at = self
            .address
            .clone()
            .or_else(|| self.iface.clone())
            .unwrap_or_default();
        format!("oxicat.Segment({:?} on {at})", self.names)
    }

    /// Stops serving and waits for the thread; raises OxicatError if serving failed.
    fn stop(&self, py: Python<'_>) -> PyResult<()> {
        self.halt(py)
    }

    fn __enter__(slf: Py<Self>) -> Py<Self> {
        slf
    }

    #[pyo3(signature = (*_exc))]
    fn __exit__(&self, py: Python<'_>, _exc: &Bound<'_, pyo3::types::PyTuple>) -> PyResult<bool> {
        self.halt(py)?;
        Ok(false)
    }

    /// AL state of the slave at `position`: "INIT", "PREOP", "SAFEOP", "OP" (+ "+ERR").
    fn al_state(&self, position: usize) -> PyResult<String> {
        self.check(position)?;
        let seg = self.lock();
        Ok(seg
            .esc(position)
            .map(|e| sim_cmd::al_state_name(e.al_status()))
            .unwrap_or_default())
    }

    /// The station address the master gave the slave at `position` (0x0010).
    fn station_address(&self, position: usize) -> PyResult<u16> {
        self.check(position)?;
        Ok(self.lock().esc(position).map_or(0, |e| e.station_address()))
    }

    /// (vendor id, product code, revision) of the slave at `position`, from its SII EEPROM
    /// (words 0x0008..0x000D, what a master's scan reads).
    fn identity(&self, position: usize) -> PyResult<(u32, u32, u32)> {
        self.check(position)?;
        let seg = self.lock();
        let e = seg.esc(position).map(|e| e.eeprom()).unwrap_or_default();
        let word = |at: usize| {
            e.get(at..at + 4)
                .map_or(0, |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        };
        Ok((word(0x10), word(0x14), word(0x18)))
    }

    /// The outputs the master last wrote to the slave at `position` (its buffered
    /// SyncManagers the master writes, newest complete buffer each, in SM order).
    fn read_outputs<'py>(&self, py: Python<'py>, position: usize) -> PyResult<Bound<'py, PyBytes>> {
        self.check(position)?;
        let v = self
            .lock()
            .esc(position)
            .map(|e| process_image(e.memory(), true))
            .unwrap_or_default();
        Ok(PyBytes::new(py, &v))
    }

    /// The inputs the slave at `position` last offered the master (SMs the master reads).
    fn read_inputs<'py>(&self, py: Python<'py>, position: usize) -> PyResult<Bound<'py, PyBytes>> {
        self.check(position)?;
        let v = self
            .lock()
            .esc(position)
            .map(|e| process_image(e.memory(), false))
            .unwrap_or_default();
        Ok(PyBytes::new(py, &v))
    }

    /// Writes `data` as the slave's inputs through its PDI, as its firmware would (one
    /// complete buffer per input SyncManager, in SM order; `data` must be their total
    /// length). A slave with firmware overwrites them in its next cycle; a twin served by
    /// its ESC alone keeps them.
    fn write_inputs(&self, position: usize, data: &[u8]) -> PyResult<()> {
        self.check(position)?;
        let mut seg = self.lock();
        let Some(esc) = seg.esc_mut(position) else {
            return Ok(());
        };
        let areas = input_areas(esc.memory());
        let total: usize = areas.iter().map(|a| a.1).sum();
        if data.len() != total {
            return Err(PyValueError::new_err(format!(
                "slave {position} has {total} input byte(s) (its SyncManagers as configured now), not {}",
                data.len()
            )));
        }
        let mut at = 0;
        for (start, len) in areas {
            esc.pdi_write(start, &data[at..at + len])
                .map_err(|e| err(format!("{e:?}")))?;
            at += len;
        }
        Ok(())
    }

    /// Fault: pulls (`plugged=False`) or re-plugs the cable at port `port` of the slave at
    /// `position`; both ends see the link change. Slave 0 port 0 is the master's link.
    #[pyo3(signature = (position, port=0, plugged=false))]
    fn set_cable(&self, position: usize, port: u8, plugged: bool) -> PyResult<()> {
        self.check(position)?;
        self.lock().set_cable(position, port, plugged).map_err(err)
    }

    /// Fault: the process-data (SM) watchdog of the slave at `position` expires now, as
    /// when the master's outputs stop for longer than the watchdog time: 0x0440 bit 0
    /// clears, and a slave with firmware goes to SAFEOP+ERR 0x001B until the master
    /// acknowledges. Raises OxicatError when its watchdog is not running (no outputs
    /// written yet, or no watchdog).
    fn expire_watchdog(&self, position: usize) -> PyResult<()> {
        self.check(position)?;
        let mut seg = self.lock();
        let esc = seg
            .esc_mut(position)
            .ok_or_else(|| err(format!("no slave at {position}")))?;
        if esc.expire_pd_watchdog() {
            Ok(())
        } else {
            Err(err(format!(
                "slave {position}: its process-data watchdog is not running (no outputs \
                 written yet, or watchdog time 0)"
            )))
        }
    }

    /// Fault: the next `n` frames are lost on the master link (never reach a slave).
    fn drop_frames(&self, n: u64) {
        self.lock().drop_next_frames(n);
    }

    /// Fault: the next frame reaching port `port` of the slave at `position` has byte
    /// `offset` (from the EtherCAT header) inverted on the cable; that slave and those after
    /// it see a bad FCS.
    #[pyo3(signature = (position, port=0, offset=2))]
    fn corrupt_next(&self, position: usize, port: u8, offset: usize) -> PyResult<()> {
        self.check(position)?;
        self.lock()
            .corrupt_next_at(position, port, offset)
            .map_err(err)
    }
}

impl Drop for Segment {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self
            .thread
            .get_mut()
            .unwrap_or_else(|e| e.into_inner())
            .take()
        {
            let _ = h.join();
        }
    }
}

/// Devices `oxicat sim` can serve (one "NAME  description" line each).
#[pyfunction]
fn device_list() -> String {
    oxicat::igh_cmd::device_list()
}

/// The native part of the `oxicat` Python package (`oxicat._oxicat`).
#[pymodule]
fn _oxicat(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Segment>()?;
    m.add_function(wrap_pyfunction!(device_list, m)?)?;
    m.add("OxicatError", m.py().get_type::<OxicatError>())?;
    Ok(())
}
