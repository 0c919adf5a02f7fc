//! The machine-code route: a board image as a node of oxicat-sim's virtual segment.
//!
//! The segment owns each ESC; a node runs the firmware against it. Here the firmware is
//! the image on the emulated STM32F446, reaching the ESC through the LAN9252 model on its
//! SPI1: at every segment event and every `slice_ns` of virtual time the node lends the
//! segment's ESC to the chip, lets the CPU run until the board's clock reaches the
//! segment's time, and takes the ESC back. Unicorn is not `Send`, so each board runs on a
//! thread of its own and the node (which the segment needs `Send`) talks to it by channel.

use std::sync::mpsc::{channel, Receiver, Sender};
use std::thread::JoinHandle;

use oxicat_esc::{Esc, EscConfig};
use oxicat_pdi::sim::{BusConfig, Handle, Lan9252Model};
use oxicat_sim::node::{EscEvent, Node};

use crate::{Board, EmuError, SpiStats};

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
    chip: Handle<Lan9252Model>,
    run: Sender<u64>,
    done: Receiver<Progress>,
    last: Progress,
    slice_ns: u64,
    next: u64,
    thread: Option<JoinHandle<()>>,
}

impl EmulatedNode {
    /// Boots `image` (an ELF) on its own thread with a LAN9252 on SPI1 clocked at
    /// `spi_mhz`; the node wakes the CPU every `slice_ns` of virtual time besides the
    /// segment's events. The ELF is checked here: a bad image is refused before anything
    /// runs.
    pub fn new(image: Vec<u8>, spi_mhz: u32, slice_ns: u64) -> Result<Self, EmuError> {
        crate::elf_segments(&image)?;
        // The chip's stand-in ESC until the segment lends it the real one.
        let chip = Lan9252Model::handle(
            Esc::new(EscConfig::lan9252(), vec![0; 128]),
            BusConfig::mhz(spi_mhz),
        );
        let (run, runs) = channel::<u64>();
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
                while let Ok(t) = runs.recv() {
                    if fault.is_none() {
                        if let Err(e) = board.run_to_ns(t) {
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
            done,
            last: Progress::default(),
            slice_ns: slice_ns.max(1_000),
            next: 0,
            thread: Some(thread),
        })
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
        let p = match self.run.send(t) {
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
    fn on_event(&mut self, esc: &mut Esc, _ev: EscEvent, t: u64) {
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
        // Closing the channel ends the board thread.
        let (dead, _) = channel();
        self.run = dead;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
