//! ethercrab's PDU loop over an in-process segment: frames go through a
//! [`FramePipe`] and back, exactly as they would through a NIC and a cable, and time is the
//! segment's virtual clock.
//!
//! ```no_run
//! # use std::sync::{Arc, Mutex};
//! # use ethercrab::{MainDevice, MainDeviceConfig, PduStorage};
//! # use oxicat_master::inprocess::{spawn_inprocess, virtual_timeouts};
//! # fn segment() -> Arc<Mutex<dyn oxicat_wire::pipe::FramePipe + Send>> { unimplemented!() }
//! static PDU_STORAGE: PduStorage<16, 1100> = PduStorage::new();
//! let segment = segment(); // e.g. an `oxicat_sim::segment::Segment`
//! let (tx, rx, pdu_loop) = PDU_STORAGE.try_split().expect("split once");
//! let _thread = spawn_inprocess(segment.clone(), tx, rx);
//! let maindevice = MainDevice::new(pdu_loop, virtual_timeouts(), MainDeviceConfig::default());
//! ```

use std::future::Future;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::thread::JoinHandle;

use ethercrab::{PduRx, PduTx, Timeouts};
use oxicat_wire::pipe::FramePipe;

/// ethercrab timeouts for a master on a virtual segment.
///
/// ethercrab measures its timeouts in real time, while the segment answers in virtual
/// time at once; on a busy host (a 2-core CI box compiling in parallel) its defaults —
/// 10 ms for an EEPROM read — can expire although nothing is wrong. These are generous
/// in every field, so only a real hang fails, and one definition serves every test and
/// tool that drives a virtual segment.
///
/// `wait_loop_delay` is zero (ethercrab's own default): a wait loop's pause is real time,
/// in which the virtual segment does not move (its clock advances with the frames), so a
/// pause only made the run slower. Each turn of a wait loop sends a frame, so it still
/// yields to the transport every time. With 200 µs the trot's bring-up spent 0.7 s of its
/// 0.75 s asleep in about 2,900 such pauses, for the same frames and the same bytes.
pub fn virtual_timeouts() -> Timeouts {
    use std::time::Duration;
    Timeouts {
        wait_loop_delay: Duration::ZERO,
        state_transition: Duration::from_secs(60),
        pdu: Duration::from_secs(10),
        eeprom: Duration::from_secs(10),
        mailbox_echo: Duration::from_secs(10),
        mailbox_response: Duration::from_secs(10),
    }
}

/// Why the in-process transport stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TransportError {
    /// ethercrab refused a frame hand-over.
    Send(ethercrab::error::Error),
}

impl core::fmt::Display for TransportError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Send(e) => write!(f, "sending a frame failed: {e}"),
        }
    }
}

impl std::error::Error for TransportError {}

/// Options of the in-process transport.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct InProcessConfig {
    /// Virtual time (ns) that passes before each frame is sent: the master's own time between
    /// frames. 0 means frames follow each other back to back.
    pub frame_gap_ns: u64,
}

/// The TX/RX adapters given back when ethercrab asks the loop to exit.
pub type Released = (PduTx<'static>, PduRx<'static>);

/// The future that moves frames between ethercrab's PDU loop and a segment; see
/// [`inprocess_task`].
pub struct InProcessTask<P: FramePipe + Send + ?Sized + 'static> {
    segment: Arc<Mutex<P>>,
    tx: Option<PduTx<'static>>,
    rx: Option<PduRx<'static>>,
    config: InProcessConfig,
    /// The frames on their way through the segment (reused: no allocation per frame).
    bufs: Vec<Vec<u8>>,
    /// Which of them came back.
    back: Vec<bool>,
}

impl<P: FramePipe + Send + ?Sized + 'static> Future for InProcessTask<P> {
    type Output = Result<Released, TransportError>;

    fn poll(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Self::Output> {
        let this = &mut *self;
        let (Some(tx), Some(rx)) = (this.tx.as_mut(), this.rx.as_mut()) else {
            return Poll::Pending;
        };
        tx.replace_waker(cx.waker());
        if tx.should_exit() {
            let (Some(tx), Some(rx)) = (this.tx.take(), this.rx.take()) else {
                return Poll::Pending;
            };
            return Poll::Ready(Ok((tx.release(), rx.release())));
        }
        // Every frame ethercrab has ready goes out as one train, as a NIC sends its queue
        // (the segment has them on the line together), the master's own time before each.
        let mut n = 0;
        while let Some(frame) = tx.next_sendable_frame() {
            if n == this.bufs.len() {
                this.bufs.push(Vec::with_capacity(1600));
            }
            let buf = &mut this.bufs[n];
            frame
                .send_blocking(|bytes| {
                    buf.clear();
                    buf.extend_from_slice(bytes);
                    Ok(bytes.len())
                })
                .map_err(TransportError::Send)?;
            n += 1;
        }
        if n == 0 {
            return Poll::Pending;
        }
        let gap = this.config.frame_gap_ns;
        this.back.clear();
        this.back.resize(n, false);
        {
            let mut seg = this.segment.lock().unwrap_or_else(|e| e.into_inner());
            if gap > 0 {
                seg.advance_by(gap);
            }
            if n == 1 {
                this.back[0] = seg.exchange_in_place(&mut this.bufs[0]);
            } else {
                let mut frames: Vec<&mut [u8]> =
                    this.bufs[..n].iter_mut().map(Vec::as_mut_slice).collect();
                seg.exchange_train(&mut frames, &mut this.back, gap);
            }
        }
        for (buf, &back) in this.bufs[..n].iter().zip(&this.back) {
            if back {
                if let Err(e) = rx.receive_frame(buf) {
                    log::warn!("ethercrab did not accept a returned frame: {e}");
                }
            }
        }
        Poll::Pending
    }
}

/// A future that serves ethercrab's PDU loop through `segment` until ethercrab asks it to
/// exit (`MainDevice::release_all`); run it on any executor.
pub fn inprocess_task<P: FramePipe + Send + ?Sized + 'static>(
    segment: Arc<Mutex<P>>,
    tx: PduTx<'static>,
    rx: PduRx<'static>,
    config: InProcessConfig,
) -> InProcessTask<P> {
    InProcessTask {
        segment,
        tx: Some(tx),
        rx: Some(rx),
        config,
        bufs: vec![Vec::with_capacity(1600)],
        back: Vec::with_capacity(1),
    }
}

/// Runs [`inprocess_task`] with default options on its own thread (error: the thread could
/// not be spawned).
pub fn spawn_inprocess<P: FramePipe + Send + ?Sized + 'static>(
    segment: Arc<Mutex<P>>,
    tx: PduTx<'static>,
    rx: PduRx<'static>,
) -> std::io::Result<JoinHandle<Result<Released, TransportError>>> {
    spawn_inprocess_with(segment, tx, rx, InProcessConfig::default())
}

/// Runs [`inprocess_task`] with `config` on its own thread.
pub fn spawn_inprocess_with<P: FramePipe + Send + ?Sized + 'static>(
    segment: Arc<Mutex<P>>,
    tx: PduTx<'static>,
    rx: PduRx<'static>,
    config: InProcessConfig,
) -> std::io::Result<JoinHandle<Result<Released, TransportError>>> {
    std::thread::Builder::new()
        .name("oxicat-inprocess".into())
        .spawn(move || futures_lite::future::block_on(inprocess_task(segment, tx, rx, config)))
}

/// The in-process transport driven on the caller's thread: [`Runner::block_on`] polls it
/// beside the future it runs, so a frame goes through the segment in the same poll that
/// queued it, with no thread hand-over (two context switches and a handful of futex calls
/// per frame on a transport thread, [`spawn_inprocess_with`]).
type SharedTask = Arc<Mutex<Pin<Box<InProcessTask<dyn FramePipe + Send>>>>>;

/// Runs futures to completion on the calling thread, with the in-process transport (if
/// any) polled beside each.
#[derive(Clone, Default)]
pub struct Runner(Option<SharedTask>);

impl Runner {
    /// A runner that polls `task` beside every future it runs.
    pub fn with_task(task: InProcessTask<dyn FramePipe + Send>) -> Self {
        Self(Some(Arc::new(Mutex::new(Box::pin(task)))))
    }

    /// `futures_lite::future::block_on(f)`, the transport polled after `f` in every turn
    /// (a frame `f` queued is exchanged in the same turn; the reply wakes `f`, which is
    /// polled again at once: the parker was notified while the thread ran).
    pub fn block_on<F: Future>(&self, f: F) -> F::Output {
        match &self.0 {
            None => futures_lite::future::block_on(f),
            Some(task) => futures_lite::future::block_on(futures_lite::future::or(
                f,
                Pump {
                    task,
                    done: false,
                    _out: std::marker::PhantomData,
                },
            )),
        }
    }
}

/// Polls the transport; never ready (its output type is only there for `or`).
struct Pump<'a, T> {
    task: &'a SharedTask,
    done: bool,
    _out: std::marker::PhantomData<fn() -> T>,
}

impl<T> Future for Pump<'_, T> {
    type Output = T;

    fn poll(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<T> {
        if !self.done {
            let mut task = self.task.lock().unwrap_or_else(|e| e.into_inner());
            match task.as_mut().poll(cx) {
                Poll::Pending => {}
                Poll::Ready(r) => {
                    // ethercrab asked the loop to exit, or a hand-over failed: the master's
                    // futures then end with ethercrab's own errors (timeouts).
                    if let Err(e) = r {
                        log::warn!("in-process transport stopped: {e}");
                    }
                    drop(task);
                    self.done = true;
                }
            }
        }
        Poll::Pending
    }
}
