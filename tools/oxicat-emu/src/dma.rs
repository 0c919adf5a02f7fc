//! DMA1/DMA2 at register level (RM0390 §9): LISR/HISR, LIFCR/HIFCR and the eight streams'
//! CR, NDTR, PAR, M0AR, M1AR, FCR.
//!
//! Modelled: memory-to-peripheral transfers in direct mode (FIFO off), normal (not
//! circular, not double-buffer) mode, DMA as flow controller, equal memory and peripheral
//! data sizes, requested by a timer's update event (the TIMx_UP rows of RM0390 tables
//! 28/29) into that timer's registers (PAR inside the timer's page: a compare register for
//! WS2812-style PWM streams). The stream fetches its NDTR items from memory when it is
//! enabled (the buffer is not expected to change while it runs), then writes item k at the
//! k-th update event after that while the timer's DIER.UDE is set; after the last one NDTR
//! is 0, EN clears and HTIF/TCIF rise (the TC interrupt when TCIE). Every other
//! configuration or request stops the image with the register, the value and "not
//! modelled".

/// DMA controllers: base, number.
pub(crate) const DMAS: [(u64, u8); 2] = [(0x4002_6000, 1), (0x4002_6400, 2)];

/// (DMA, stream, channel) → timer whose update event is the request.
const UPDATE_REQUESTS: [(u8, u8, u8, u8); 12] = [
    (1, 1, 3, 2),
    (1, 7, 3, 2),
    (1, 2, 5, 3),
    (1, 6, 2, 4),
    (1, 0, 6, 5),
    (1, 6, 6, 5),
    (1, 1, 7, 6),
    (1, 2, 1, 7),
    (1, 4, 1, 7),
    (2, 5, 6, 1),
    (2, 1, 7, 8),
    (2, 2, 7, 8),
];

/// Bits of a stream's flag group: FEIF, DMEIF, TEIF, HTIF, TCIF.
pub(crate) const TCIF: u32 = 1 << 5;
pub(crate) const HTIF: u32 = 1 << 4;
/// Position of stream `s`'s flag group in LISR/HISR.
fn flag_shift(s: usize) -> u32 {
    [0, 6, 16, 22][s % 4]
}

pub(crate) const CR_EN: u32 = 1;
pub(crate) const CR_TCIE: u32 = 1 << 4;
pub(crate) const CR_HTIE: u32 = 1 << 3;
/// CR bits modelled: EN, DMEIE, TEIE, HTIE, TCIE, DIR, MINC, PSIZE, MSIZE, PL, CHSEL
/// (no transfer or direct-mode error occurs in the model). Not: PFCTRL, CIRC, PINC,
/// PINCOS, DBM, CT, PBURST, MBURST.
const CR_OK: u32 = 0x1F | 0xC0 | 0x400 | 0x1800 | 0x6000 | 0x3_0000 | 0x0E00_0000;

/// A stream that runs: what it writes where.
#[derive(Debug, Clone)]
pub(crate) struct Run {
    /// Index into the board's timers.
    pub tim: usize,
    /// Register offset in the timer's page.
    pub off: usize,
    /// The items fetched at enable.
    pub values: Vec<u32>,
    /// Items written so far.
    pub done: usize,
    /// The timer's update count at enable.
    pub start_updates: u64,
    /// Cycle of enable.
    pub start: u64,
}

/// One finished transfer: what a stream wrote into a timer register.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DmaBurst {
    /// DMA controller (1, 2).
    pub dma: u8,
    /// Stream (0..7).
    pub stream: u8,
    /// Timer number.
    pub tim: u8,
    /// Register offset written in the timer's page.
    pub reg: u64,
    /// The items, in the order written (one per update event).
    pub values: Vec<u32>,
    /// Cycle of enable.
    pub start: u64,
    /// Cycle the end was seen (the last write, or the access that found it done).
    pub end: u64,
}

#[derive(Debug, Clone, Default)]
pub(crate) struct Stream {
    pub cr: u32,
    pub ndtr: u32,
    pub par: u32,
    pub m0ar: u32,
    pub m1ar: u32,
    pub fcr: u32,
    pub run: Option<Run>,
}

/// One controller.
pub(crate) struct Dma {
    pub base: u64,
    pub number: u8,
    /// LISR, HISR.
    pub isr: [u32; 2],
    pub streams: [Stream; 8],
    /// The last finished transfer per stream.
    pub bursts: [Option<DmaBurst>; 8],
}

impl Dma {
    pub fn new(base: u64, number: u8) -> Self {
        Self {
            base,
            number,
            isr: [0; 2],
            streams: Default::default(),
            bursts: Default::default(),
        }
    }

    fn err(&self, what: &str, off: u64, v: u32) -> String {
        format!(
            "{what} {v:#010x} to DMA{} at {:#010x}: not modelled (memory-to-peripheral, \
             direct mode, normal mode, on a timer update request into the timer's page)",
            self.number,
            self.base + off
        )
    }

    /// The timer (number) whose update event requests stream `s` on its channel.
    pub fn request_timer(&self, s: usize) -> Option<u8> {
        let ch = ((self.streams[s].cr >> 25) & 7) as u8;
        UPDATE_REQUESTS
            .iter()
            .find(|r| r.0 == self.number && usize::from(r.1) == s && r.2 == ch)
            .map(|r| r.3)
    }

    pub fn read(&self, off: u64) -> Result<u32, String> {
        Ok(match off {
            0x00 => self.isr[0],
            0x04 => self.isr[1],
            0x08 | 0x0C => 0,
            o if (0x10..0xD0).contains(&o) => {
                let s = &self.streams[((o - 0x10) / 0x18) as usize];
                match (o - 0x10) % 0x18 {
                    0x00 => s.cr,
                    0x04 => s.ndtr,
                    0x08 => s.par,
                    0x0C => s.m0ar,
                    0x10 => s.m1ar,
                    _ => s.fcr | 0x20, // FS: FIFO empty
                }
            }
            _ => return Err(self.err("read of", off, 0)),
        })
    }

    /// A register write; `Ok(Some((stream, address, items, item size)))` when a stream was
    /// enabled: the caller fetches its items from memory and starts the run.
    pub fn write(
        &mut self,
        off: u64,
        v: u32,
    ) -> Result<Option<(usize, u32, usize, usize)>, String> {
        match off {
            0x00 | 0x04 => {} // read-only
            0x08 => self.isr[0] &= !(v & 0x0F7D_0F7D),
            0x0C => self.isr[1] &= !(v & 0x0F7D_0F7D),
            o if (0x10..0xD0).contains(&o) => {
                let si = ((o - 0x10) / 0x18) as usize;
                let reg = (o - 0x10) % 0x18;
                let running = self.streams[si].cr & CR_EN != 0;
                if running && reg != 0 {
                    // RM0390: these are write-protected while EN is set.
                    return Ok(None);
                }
                let s = &mut self.streams[si];
                match reg {
                    0x00 => {
                        if v & !CR_OK != 0 {
                            return Err(self.err("write of", off, v));
                        }
                        if v & CR_EN == 0 {
                            // Disabling stops it (the items left stay in NDTR).
                            s.cr = v;
                            s.run = None;
                            return Ok(None);
                        }
                        if running {
                            return Ok(None);
                        }
                        let dir = (v >> 6) & 3;
                        let psize = (v >> 11) & 3;
                        let msize = (v >> 13) & 3;
                        if dir != 1 || psize != msize || psize == 3 || s.fcr & (1 << 2) != 0 {
                            return Err(self.err("write of", off, v));
                        }
                        s.cr = v;
                        let n = s.ndtr as usize;
                        let size = 1usize << psize;
                        let step = if v & (1 << 10) != 0 { size } else { 0 };
                        let m0 = s.m0ar;
                        if self.request_timer(si).is_none() {
                            return Err(self.err(
                                "enable with a request that is no timer update: write of",
                                off,
                                v,
                            ));
                        }
                        // Memory increment off: the same item n times.
                        let fetch_items = if step == 0 { 1 } else { n };
                        return Ok(Some((si, m0, fetch_items.max(1), size)));
                    }
                    0x04 => s.ndtr = v & 0xFFFF,
                    0x08 => s.par = v,
                    0x0C => s.m0ar = v,
                    0x10 => s.m1ar = v,
                    _ => {
                        if v & (1 << 2) != 0 || v & (1 << 7) != 0 {
                            // DMDIS (FIFO mode), FEIE.
                            return Err(self.err("write of", off, v));
                        }
                        s.fcr = v;
                    }
                }
            }
            _ => return Err(self.err("write of", off, v)),
        }
        Ok(None)
    }

    /// The interrupt lines of the streams whose TCIF/HTIF are set and enabled.
    pub fn irq_lines(&self) -> u128 {
        let mut lines = 0u128;
        for (si, s) in self.streams.iter().enumerate() {
            let flags = self.isr[si / 4] >> flag_shift(si);
            let on = (flags & TCIF != 0 && s.cr & CR_TCIE != 0)
                || (flags & HTIF != 0 && s.cr & CR_HTIE != 0);
            if on {
                lines |= crate::nvic::bit(16 + self.irq(si));
            }
        }
        lines
    }

    /// IRQ number of stream `s` (RM0390 table 38).
    pub fn irq(&self, s: usize) -> u16 {
        let s = s as u16;
        match (self.number, s) {
            (1, 0..=6) => 11 + s,
            (1, _) => 47,
            (_, 0..=4) => 56 + s,
            (_, _) => 68 + s - 5,
        }
    }

    /// Sets stream `s`'s flags.
    pub fn flag(&mut self, s: usize, bits: u32) {
        self.isr[s / 4] |= bits << flag_shift(s);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_enabled_stream_asks_for_its_items_and_unmodelled_modes_name_the_register() {
        let mut d = Dma::new(0x4002_6400, 2);
        let s1 = 0x10 + 0x18;
        d.write(s1 + 4, 168).unwrap();
        d.write(s1 + 8, 0x4001_0434).unwrap();
        d.write(s1 + 12, 0x2000_0100).unwrap();
        let cr = (7 << 25) | (1 << 13) | (1 << 11) | (1 << 10) | (1 << 6);
        assert_eq!(d.write(s1, cr).unwrap(), None, "not yet enabled");
        assert_eq!(
            d.write(s1, cr | 1).unwrap(),
            Some((1, 0x2000_0100, 168, 2)),
            "168 half-words from M0AR"
        );
        assert_eq!(d.request_timer(1), Some(8), "TIM8_UP");
        // While EN is set NDTR is write-protected.
        d.write(s1 + 4, 3).unwrap();
        assert_eq!(d.read(s1 + 4).unwrap(), 168);
        // Circular mode, peripheral-to-memory and FIFO mode are not modelled.
        d.write(s1, cr).unwrap();
        let e = d.write(s1, cr | (1 << 8)).unwrap_err();
        assert!(
            e.contains("0x40026428") && e.contains("not modelled"),
            "{e}"
        );
        let e = d.write(s1, (cr & !(3 << 6)) | 1).unwrap_err();
        assert!(e.contains("0x40026428"), "{e}");
        let e = d.write(s1 + 0x14, 1 << 2).unwrap_err();
        assert!(e.contains("0x4002643c"), "{e}");
        // A request that is no timer update (stream 1 channel 4 is USART3_RX on DMA1).
        let mut d1 = Dma::new(0x4002_6000, 1);
        d1.write(s1 + 4, 1).unwrap();
        let e = d1.write(s1, (4 << 25) | (1 << 6) | 1).unwrap_err();
        assert!(e.contains("no timer update"), "{e}");
        // Flags: set and cleared through LIFCR.
        d.flag(1, TCIF);
        assert_eq!(d.read(0).unwrap(), 1 << 11);
        d.write(0x08, 0x3D << 6).unwrap();
        assert_eq!(d.read(0).unwrap(), 0);
    }
}
