//! The machine-code route: a board image as a node of oxicat-sim's virtual segment.
//!
//! The segment owns each ESC; a node runs the firmware against it. Here the firmware is
//! the image on the emulated STM32F446, reaching the ESC through the board's chip model (a
//! LAN9252, or an ET1100: [`EmulatedNode::with_chip`]) on its SPI1: at every segment event and every `slice_ns` of virtual time the node lends the
//! segment's ESC to the chip, lets the CPU run until the board's clock reaches the
//! segment's time, and takes the ESC back. Unicorn is not `Send`, so each board runs on a
//! thread of its own and the node (which the segment needs `Send`) talks to it by channel.
//! A [`BoardPlant`] given to [`EmulatedNode::with_plant`] runs on that thread in lockstep
//! with the CPU ([`crate::plant`]); a [`NodeHandle`] asks the board for its figures
//! ([`NodeReport`]) from outside the segment.

use std::sync::mpsc::{channel, Receiver, Sender};
use std::thread::JoinHandle;

use oxicat_esc::{Esc, EscConfig};
use oxicat_pdi::sim::{BusConfig, Et1100Model, Lan9252Model};
use oxicat_sim::node::{EscEvent, Node};

use crate::chip::{ChipKind, EscChip};
use crate::plant::{run_with_plant, BoardPlant};
use crate::{Board, EmuError, HandlerStats, ImageSize, LostEdge, MaskedSpan, SpiStats, StackStats};

/// What the board thread is asked to do.
enum Cmd {
    /// Run to this time \[ns\] and report progress.
    Run(u64),
    /// Send the full figures.
    Report(Sender<NodeReport>),
    /// Clear the handler times and repaint the stack below the current SP.
    ResetStats,
    /// Replace SPI1's clock (what-if study; `None`: the image's).
    SpiClock(Option<u32>),
    /// Drive an input pin (port, pin, level).
    Input(char, u8, bool),
    /// Read image memory (address, length).
    Memory(u32, usize, Sender<Result<Vec<u8>, EmuError>>),
    /// End the board thread.
    Stop,
}

/// The figures of an emulated board (see [`Board::handler_stats`], [`Board::stack_stats`],
/// [`Board::image_size`]).
#[derive(Debug, Clone, Default)]
pub struct NodeReport {
    /// The board's clock \[ns\].
    pub time_ns: u64,
    /// CPU cycles so far, and of them asleep.
    pub cycles: u64,
    /// Cycles asleep (WFI).
    pub slept_cycles: u64,
    /// Instructions executed.
    pub instructions: u64,
    /// Handler times by exception number (IPSR numbering), since reset or the last
    /// [`NodeHandle::reset_stats`].
    pub handlers: Vec<HandlerStats>,
    /// Cycle count at the last reset of the handler times.
    pub stats_since_cycle: u64,
    /// Times each exception was entered since reset (IPSR numbering).
    pub taken: Vec<u64>,
    /// Painted-stack figures.
    pub stack: StackStats,
    /// Flash and static RAM of the image.
    pub image: ImageSize,
    /// SPI traffic.
    pub spi: SpiStats,
    /// SPI1's clock as the image set it \[Hz\].
    pub spi_sclk_hz: u32,
    /// ADC1 injected sequences started since reset.
    pub adc_sequences: u64,
    /// Longest JEOC → ADC handler entry since reset or [`NodeHandle::reset_stats`] \[cycles\] ([`Board::adc_irq_latency_max`]).
    pub adc_irq_latency_max: u64,
    /// System resets by the independent watchdog so far ([`Board::watchdog_resets`]).
    pub watchdog_resets: u64,
    /// The board's time of the last of them \[ns\].
    pub last_watchdog_reset_ns: Option<u64>,
    /// The longest span the thread held each priority level masked, since boot, by level
    /// (the priority's upper nibble: [`NodeReport::masked`]).
    pub masked: Vec<MaskedSpan>,
    /// The function each of those spans began in ([`Board::function_at`]).
    pub masked_functions: Vec<Option<String>>,
    /// EXTI edges lost since boot, the first 64 with their cycle ([`Board::lost_edges`]).
    pub lost_edges: Vec<LostEdge>,
    /// EXTI edges lost since boot, by line 0..=15.
    pub lost_edge_count: Vec<u64>,
    /// What the FLASH model did ([`Board::flash_stats`]).
    pub flash: crate::FlashStats,
    /// The fault that stopped the image, if it stopped.
    pub fault: Option<EmuError>,
}

impl NodeReport {
    /// The longest span since boot the thread held exceptions of `priority` back, and the
    /// function it began in ([`Board::masked_span`]).
    pub fn masked(&self, priority: u8) -> (MaskedSpan, Option<&str>) {
        let k = usize::from(priority >> 4);
        (
            self.masked.get(k).copied().unwrap_or_default(),
            self.masked_functions.get(k).and_then(|f| f.as_deref()),
        )
    }

    /// Edges EXTI line `line` lost since boot.
    pub fn lost_edges_on(&self, line: u8) -> u64 {
        self.lost_edge_count
            .get(usize::from(line))
            .copied()
            .unwrap_or(0)
    }

    /// The handler times of exception `number`.
    pub fn handler(&self, number: u16) -> HandlerStats {
        self.handlers
            .get(usize::from(number))
            .copied()
            .unwrap_or_default()
    }

    /// Share of the cycles since the last reset of the figures spent in exception
    /// `number`'s own handler code (preemptions excluded).
    pub fn load(&self, number: u16) -> f64 {
        let span = self.cycles.saturating_sub(self.stats_since_cycle);
        if span == 0 {
            return 0.0;
        }
        self.handler(number).own_cycles as f64 / span as f64
    }
}

fn report_of(board: &Board, since: u64, fault: &Option<EmuError>) -> NodeReport {
    let masked: Vec<(MaskedSpan, Option<String>)> = (0..16u8)
        .map(|k| {
            let m = board.masked_span(k << 4);
            let f = (m.max_cycles > 0)
                .then(|| board.function_at(m.pc).map(str::to_string))
                .flatten();
            (m, f)
        })
        .collect();
    NodeReport {
        time_ns: board.time_ns(),
        cycles: board.cycles(),
        slept_cycles: board.slept_cycles(),
        instructions: board.instructions(),
        handlers: (0..crate::nvic::NUM_EXC as u16)
            .map(|e| board.handler_stats(e))
            .collect(),
        stats_since_cycle: since,
        taken: (0..crate::nvic::NUM_EXC as u16)
            .map(|e| board.exceptions_taken(e))
            .collect(),
        stack: board.stack_stats(),
        image: board.image_size(),
        spi: board.spi_stats(),
        spi_sclk_hz: board.spi_sclk_hz(),
        adc_sequences: board.adc_sequences(),
        adc_irq_latency_max: board.adc_irq_latency_max(),
        watchdog_resets: board.watchdog_resets(),
        last_watchdog_reset_ns: board.last_watchdog_reset_ns(),
        masked: masked.iter().map(|m| m.0).collect(),
        masked_functions: masked.into_iter().map(|m| m.1).collect(),
        lost_edges: board.lost_edges(),
        lost_edge_count: (0..16).map(|l| board.lost_edge_count(l)).collect(),
        flash: board.flash_stats(),
        fault: fault.clone(),
    }
}

/// Asks an [`EmulatedNode`]'s board for its figures from outside the segment (a test, a
/// tool), also after the node went into the segment.
#[derive(Clone)]
pub struct NodeHandle {
    cmd: Sender<Cmd>,
    sync0: std::sync::Arc<std::sync::atomic::AtomicU64>,
    chip: EscChip,
}

impl NodeHandle {
    /// The board's figures now (`None` if the board thread has ended).
    pub fn report(&self) -> Option<NodeReport> {
        let (tx, rx) = channel();
        self.cmd.send(Cmd::Report(tx)).ok()?;
        rx.recv().ok()
    }

    /// Clears the handler times and repaints the stack below the current SP, so the
    /// figures cover what runs from now on.
    pub fn reset_stats(&self) {
        let _ = self.cmd.send(Cmd::ResetStats);
    }

    /// A what-if study: the board's SPI1 bytes take 8 periods of `hz` from now on instead of
    /// the clock the image sets ([`Board::set_spi_sclk_hz`]; `None`: the image's again).
    pub fn set_spi_sclk_hz(&self, hz: Option<u32>) {
        let _ = self.cmd.send(Cmd::SpiClock(hz));
    }

    /// Drives input pin `pin` of `port` ('A'..='H') to `level` from the board's next run on
    /// ([`Board::set_input`]): a jumper, a button, a sensor line.
    pub fn set_input(&self, port: char, pin: u8, level: bool) {
        let _ = self.cmd.send(Cmd::Input(port, pin, level));
    }

    /// `len` bytes of the board's memory at `addr` (flash or SRAM; the flash sectors after
    /// the image as the FLASH model holds them); `None` if the board thread has ended.
    pub fn read_memory(&self, addr: u32, len: usize) -> Option<Result<Vec<u8>, EmuError>> {
        let (tx, rx) = channel();
        self.cmd.send(Cmd::Memory(addr, len, tx)).ok()?;
        rx.recv().ok()
    }

    /// SYNC0 events the segment delivered to this node so far.
    pub fn sync0_events(&self) -> u64 {
        self.sync0.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// What the board's SPI bus carried, as the ESC chip saw it (malformed frames) since
    /// the last [`NodeHandle::reset_bus_stats`].
    pub fn bus_stats(&self) -> oxicat_pdi::sim::BusStats {
        self.chip.stats()
    }

    /// Clears the chip's bus counters.
    pub fn reset_bus_stats(&self) {
        self.chip.reset_stats()
    }
}

/// What the board thread reports after each run.
#[derive(Debug, Clone, Default)]
pub struct Progress {
    /// Instructions executed so far.
    pub instructions: u64,
    /// The board's clock \[ns\].
    pub time_ns: u64,
    /// SPI traffic so far.
    pub spi: SpiStats,
    /// The fault that stopped the image, if it stopped.
    pub fault: Option<EmuError>,
}

/// A board image on the segment (see the module docs).
pub struct EmulatedNode {
    chip: EscChip,
    run: Sender<Cmd>,
    sync0: std::sync::Arc<std::sync::atomic::AtomicU64>,
    done: Receiver<Progress>,
    last: Progress,
    slice_ns: u64,
    next: u64,
    thread: Option<JoinHandle<()>>,
}

impl EmulatedNode {
    /// Boots `image` (an ELF) on its own thread with a LAN9252 on SPI1 (at the clock the
    /// image sets: bytes take their time at SPI1's prescaler); the node wakes the CPU every
    /// `slice_ns` of virtual time besides the segment's events. The ELF is checked here: a
    /// bad image is refused before anything runs.
    pub fn new(image: Vec<u8>, slice_ns: u64) -> Result<Self, EmuError> {
        Self::with_plant(image, slice_ns, None)
    }

    /// [`EmulatedNode::new`] with `plant` on the board's pins, stepped in lockstep with
    /// the CPU on the board's thread ([`crate::plant`]).
    pub fn with_plant(
        image: Vec<u8>,
        slice_ns: u64,
        plant: Option<Box<dyn BoardPlant>>,
    ) -> Result<Self, EmuError> {
        Self::with_chip(image, slice_ns, plant, ChipKind::Lan9252)
    }

    /// [`EmulatedNode::with_plant`] on a board whose SPI1 carries the ESC chip `kind`
    /// (the segment's ESC for this node should be of that chip's configuration, e.g.
    /// `EscConfig::et1100()`).
    pub fn with_chip(
        image: Vec<u8>,
        slice_ns: u64,
        mut plant: Option<Box<dyn BoardPlant>>,
        kind: ChipKind,
    ) -> Result<Self, EmuError> {
        crate::elf_segments(&image)?;
        // The chip's stand-in ESC until the segment lends it the real one. (Its bus
        // configuration times whole-frame transfers only; the emulated SPI1 clocks bytes.)
        let chip: EscChip = match kind {
            ChipKind::Lan9252 => Lan9252Model::handle(
                Esc::new(EscConfig::lan9252(), vec![0; 128]),
                BusConfig::mhz(22),
            )
            .into(),
            ChipKind::Et1100 => Et1100Model::handle(
                Esc::new(EscConfig::et1100(), vec![0; 128]),
                BusConfig::mhz(11),
            )
            .into(),
        };
        let (run, runs) = channel::<Cmd>();
        let (report, done) = channel::<Progress>();
        let c = chip.clone();
        let thread = std::thread::Builder::new()
            .name("oxicat-emu board".into())
            .spawn(move || {
                let mut board = match Board::new(&image, c) {
                    Ok(b) => b,
                    Err(e) => {
                        let _ = report.send(Progress {
                            fault: Some(e),
                            ..Progress::default()
                        });
                        return;
                    }
                };
                let mut fault = None;
                let mut next_step = 0u64;
                let mut since = 0u64;
                while let Ok(cmd) = runs.recv() {
                    let t = match cmd {
                        Cmd::Run(t) => t,
                        Cmd::Report(to) => {
                            let _ = to.send(report_of(&board, since, &fault));
                            continue;
                        }
                        Cmd::Stop => return,
                        Cmd::SpiClock(hz) => {
                            board.set_spi_sclk_hz(hz);
                            continue;
                        }
                        Cmd::Input(port, pin, level) => {
                            board.set_input(port, pin, level);
                            continue;
                        }
                        Cmd::Memory(addr, len, to) => {
                            let mut buf = vec![0u8; len];
                            let r = board.read_memory(addr, &mut buf).map(|()| buf);
                            let _ = to.send(r);
                            continue;
                        }
                        Cmd::ResetStats => {
                            board.reset_handler_stats();
                            board.repaint_stack();
                            since = board.cycles();
                            continue;
                        }
                    };
                    if fault.is_none() {
                        let r = match plant.as_deref_mut() {
                            Some(p) => run_with_plant(&mut board, p, &mut next_step, t),
                            None => board.run_to_ns(t),
                        };
                        if let Err(e) = r {
                            fault = Some(e);
                        }
                    }
                    let p = Progress {
                        instructions: board.instructions(),
                        time_ns: board.time_ns(),
                        spi: board.spi_stats(),
                        fault: fault.clone(),
                    };
                    if report.send(p).is_err() {
                        return;
                    }
                }
            })
            .map_err(|e| EmuError::Fault {
                pc: 0,
                reason: format!("no thread for the board: {e}"),
            })?;
        Ok(EmulatedNode {
            chip,
            run,
            sync0: Default::default(),
            done,
            last: Progress::default(),
            slice_ns: slice_ns.max(1_000),
            next: 0,
            thread: Some(thread),
        })
    }

    /// A handle that asks the board for its figures ([`NodeReport`]).
    pub fn handle(&self) -> NodeHandle {
        NodeHandle {
            cmd: self.run.clone(),
            sync0: self.sync0.clone(),
            chip: self.chip.clone(),
        }
    }

    /// What the board reported last.
    pub fn progress(&self) -> &Progress {
        &self.last
    }

    /// Lends `esc` to the chip while the CPU runs up to `t`.
    fn advance(&mut self, esc: &mut Esc, t: u64) {
        if self.last.fault.is_some() || t <= self.last.time_ns {
            return;
        }
        self.chip.swap_esc(esc);
        let p = match self.run.send(Cmd::Run(t)) {
            Ok(()) => self.done.recv().ok(),
            Err(_) => None,
        };
        self.chip.swap_esc(esc);
        match p {
            Some(p) => {
                if let Some(f) = &p.fault {
                    log_fault(f);
                }
                self.last = p;
            }
            None => {
                self.last.fault = Some(EmuError::Fault {
                    pc: 0,
                    reason: "the board thread ended".into(),
                })
            }
        }
    }
}

fn log_fault(f: &EmuError) {
    eprintln!("oxicat-emu: board image stopped: {f}");
}

impl Node for EmulatedNode {
    fn on_event(&mut self, esc: &mut Esc, ev: EscEvent, t: u64) {
        if ev == EscEvent::Sync0 {
            self.sync0
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        }
        self.advance(esc, t);
    }

    fn next_wakeup(&self) -> Option<u64> {
        self.last.fault.is_none().then_some(self.next)
    }

    fn on_wakeup(&mut self, esc: &mut Esc, t: u64) {
        self.advance(esc, t);
        self.next = t + self.slice_ns;
    }
}

impl Drop for EmulatedNode {
    fn drop(&mut self) {
        // Ends the board thread (handles keep the channel open).
        let _ = self.run.send(Cmd::Stop);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
