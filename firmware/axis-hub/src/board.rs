//! The hub board's peripherals behind the application's seams: the 1-Wire master on USART3
//! (half-duplex, AN214's reset at 9600 baud and bit slots at 115200; the temperature task's
//! transactions run slot by slot in USART3's interrupt), and the two WS2812
//! rings fed by DMA into a timer's compare register (TIM8 CH1 on PC6 through DMA2 stream 1
//! channel 7 on TIM8_UP, TIM3 CH2 on PC7 through DMA1 stream 2 channel 5 on TIM3_UP;
//! RM0390 tables 28/29). Register-level: the HAL has no half-duplex USART or timer-DMA
//! burst for these parts, and the emulator models exactly these registers.

use core::cell::RefCell;
use core::ptr::{read_volatile, write_volatile};

use cortex_m::interrupt::Mutex;

use oxicat_devices::axis_hub::ws2812::{HUB_TIMING, RING_SLOTS};
use oxicat_devices::axis_hub::LedStrip;
use oxicat_devices::axis_hub::{OneWireBus, Slot, Txn};
use oxicat_devices::demo::Leds;
use stm32f4xx_hal::gpio::{Output, Pin};

const RCC: usize = 0x4002_3800;
const RCC_AHB1ENR: usize = RCC + 0x30;
const RCC_APB1ENR: usize = RCC + 0x40;
const RCC_APB2ENR: usize = RCC + 0x44;

const USART3: usize = 0x4000_4800;
const SR: usize = 0x00;
const DR: usize = 0x04;
const BRR: usize = 0x08;
const CR1: usize = 0x0C;
const CR3: usize = 0x14;
const SR_ORE: u32 = 1 << 3;
const SR_RXNE: u32 = 1 << 5;
const SR_TXE: u32 = 1 << 7;

const TIM3: usize = 0x4000_0400;
const TIM8: usize = 0x4001_0400;
const DMA1: usize = 0x4002_6000;
const DMA2: usize = 0x4002_6400;

fn rd(addr: usize) -> u32 {
    // SAFETY: a peripheral register of the STM32F446 (addresses above, RM0390).
    unsafe { read_volatile(addr as *const u32) }
}

fn wr(addr: usize, v: u32) {
    // SAFETY: as `rd`; only this module owns these peripherals.
    unsafe { write_volatile(addr as *mut u32, v) }
}

fn set_bits(addr: usize, bits: u32) {
    wr(addr, rd(addr) | bits);
}

/// Busy-wait bound of one UART byte in the polled slots: well above a byte at 9600 baud
/// (≈ 1.04 ms, 187,500 cycles at 180 MHz; one loop pass is several cycles).
const SPIN: u32 = 200_000;
/// Ticks (ms) a transaction may run in the background before it is abandoned as
/// [`OwError::NoEcho`]: the longest (a search: reset + 8 + 192 slots) takes ≈ 18 ms.
const TXN_TICKS: u32 = 100;

const CR1_ON: u32 = (1 << 13) | (1 << 3) | (1 << 2);
const CR1_RXNEIE: u32 = 1 << 5;

/// Why a 1-Wire slot failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OwError {
    /// TXE did not come up: the USART does not run.
    TxTimeout,
    /// The byte did not come back on the half-duplex line (no echo).
    NoEcho,
    /// A transaction still runs in the background.
    Busy,
}

/// The 1-Wire transaction the USART3 interrupt runs, slot by slot: each slot one UART byte
/// (a reset 0xF0 at 9600 baud, a slot 0xFF / 0x00 at 115200), the echo its result.
struct Engine {
    txn: Option<Txn>,
    /// The slot whose byte is on the line.
    slot: Option<Slot>,
    brr_reset: u32,
    brr_bits: u32,
    /// Ticks the transaction has been collected without having finished.
    polls: u32,
}

static ENGINE: Mutex<RefCell<Engine>> = Mutex::new(RefCell::new(Engine {
    txn: None,
    slot: None,
    brr_reset: 0,
    brr_bits: 0,
    polls: 0,
}));

impl Engine {
    fn running(&self) -> bool {
        self.slot.is_some()
    }

    /// Puts `slot`'s byte on the line at its rate, the RXNE interrupt on.
    fn send(&mut self, slot: Slot) {
        let (brr, byte) = match slot {
            Slot::Reset => (self.brr_reset, 0xF0u8),
            Slot::Write(false) => (self.brr_bits, 0x00),
            Slot::Write(true) | Slot::Read => (self.brr_bits, 0xFF),
        };
        if rd(USART3 + BRR) != brr {
            // UE off while the rate changes.
            wr(USART3 + CR1, (1 << 3) | (1 << 2));
            wr(USART3 + BRR, brr);
        }
        wr(USART3 + CR1, CR1_ON | CR1_RXNEIE);
        self.slot = Some(slot);
        wr(USART3 + DR, u32::from(byte));
    }

    /// Ends the transaction in the background: the interrupt off.
    fn stop(&mut self) {
        self.slot = None;
        wr(USART3 + CR1, CR1_ON);
    }
}

/// USART3's interrupt (RXNE: the echo of a slot's byte): feeds the slot's result to the
/// transaction and puts its next slot on the line, or ends it. A few µs per byte; the
/// temperature task sees the result at its next tick ([`UartOneWire::collect`]).
pub fn onewire_irq() {
    cortex_m::interrupt::free(|cs| {
        let mut e = ENGINE.borrow(cs).borrow_mut();
        let sr = rd(USART3 + SR);
        if sr & (SR_RXNE | SR_ORE) == 0 {
            return;
        }
        // Reading DR clears RXNE (and ORE after the SR read).
        let echo = rd(USART3 + DR) as u8;
        let Some(slot) = e.slot else {
            e.stop();
            return;
        };
        let r = match slot {
            // A presence pulse pulls the echo's upper bits low.
            Slot::Reset => echo != 0xF0,
            Slot::Write(b) => b,
            // The echo is 0xFF when no device held the line.
            Slot::Read => echo == 0xFF,
        };
        let next = e.txn.as_mut().and_then(|t| {
            t.feed(r);
            t.next_slot()
        });
        match next {
            Some(s) => e.send(s),
            None => e.stop(),
        }
    });
}

/// 1-Wire master on USART3, single wire on TX (PB10, open drain, external 4.7 kΩ pull-up):
/// a reset is 0xF0 at 9600 baud (a presence pulse pulls the echo's upper bits low), a slot
/// is one byte at 115200 baud (0xFF writes a 1 / samples the bus, 0x00 writes a 0). The
/// temperature task's transactions run in USART3's interrupt ([`onewire_irq`]); the single
/// slots of [`OneWireBus`] are polled (bounded).
pub struct UartOneWire {
    brr_reset: u32,
    brr_bits: u32,
}

impl UartOneWire {
    /// Enables USART3 on an APB1 clock of `pclk1` Hz: 8 data bits, no parity, one stop
    /// bit, half-duplex (CR3.HDSEL), TX and RX on, its interrupt off until a transaction.
    pub fn new(pclk1: u32) -> Self {
        set_bits(RCC_APB1ENR, 1 << 18);
        let _ = rd(RCC_APB1ENR);
        let s = Self {
            brr_reset: (pclk1 + 4800) / 9600,
            brr_bits: (pclk1 + 57_600) / 115_200,
        };
        wr(USART3 + CR1, 0);
        wr(USART3 + CR3, 1 << 3);
        wr(USART3 + BRR, s.brr_bits);
        wr(USART3 + CR1, CR1_ON);
        cortex_m::interrupt::free(|cs| {
            let mut e = ENGINE.borrow(cs).borrow_mut();
            e.brr_reset = s.brr_reset;
            e.brr_bits = s.brr_bits;
        });
        s
    }

    fn baud(&mut self, brr: u32) {
        if rd(USART3 + BRR) != brr {
            // UE off while the rate changes.
            wr(USART3 + CR1, (1 << 3) | (1 << 2));
            wr(USART3 + BRR, brr);
            wr(USART3 + CR1, CR1_ON);
        }
    }

    /// Sends `b` and returns what the line read back (polled; not while a transaction
    /// runs in the background).
    fn xfer(&mut self, b: u8) -> Result<u8, OwError> {
        if cortex_m::interrupt::free(|cs| ENGINE.borrow(cs).borrow().running()) {
            return Err(OwError::Busy);
        }
        // Drop a stale byte (RXNE cleared by reading DR).
        if rd(USART3 + SR) & SR_RXNE != 0 {
            let _ = rd(USART3 + DR);
        }
        let mut n = 0;
        while rd(USART3 + SR) & SR_TXE == 0 {
            n += 1;
            if n > SPIN {
                return Err(OwError::TxTimeout);
            }
        }
        wr(USART3 + DR, u32::from(b));
        let mut n = 0;
        while rd(USART3 + SR) & SR_RXNE == 0 {
            n += 1;
            if n > SPIN {
                return Err(OwError::NoEcho);
            }
        }
        Ok(rd(USART3 + DR) as u8)
    }
}

impl OneWireBus for UartOneWire {
    type Error = OwError;

    fn reset(&mut self) -> Result<bool, OwError> {
        self.baud(self.brr_reset);
        let echo = self.xfer(0xF0);
        self.baud(self.brr_bits);
        Ok(echo? != 0xF0)
    }

    fn write_bit(&mut self, bit: bool) -> Result<(), OwError> {
        self.xfer(if bit { 0xFF } else { 0x00 }).map(|_| ())
    }

    fn read_bit(&mut self) -> Result<bool, OwError> {
        Ok(self.xfer(0xFF)? == 0xFF)
    }

    /// Hands `t` to USART3's interrupt and puts its first slot on the line.
    fn begin(&mut self, t: &mut Txn) -> Result<bool, OwError> {
        cortex_m::interrupt::free(|cs| {
            let mut e = ENGINE.borrow(cs).borrow_mut();
            if e.running() {
                return Err(OwError::Busy);
            }
            let Some(first) = t.next_slot() else {
                return Ok(true);
            };
            // Drop a stale byte (RXNE cleared by reading DR).
            if rd(USART3 + SR) & SR_RXNE != 0 {
                let _ = rd(USART3 + DR);
            }
            e.txn = Some(*t);
            e.polls = 0;
            e.send(first);
            Ok(false)
        })
    }

    /// The transaction back once USART3's interrupt has run its last slot; abandoned as
    /// [`OwError::NoEcho`] after [`TXN_TICKS`] calls (one per tick) without an end.
    fn collect(&mut self, t: &mut Txn) -> Result<bool, OwError> {
        cortex_m::interrupt::free(|cs| {
            let mut e = ENGINE.borrow(cs).borrow_mut();
            if e.running() {
                e.polls += 1;
                if e.polls > TXN_TICKS {
                    e.stop();
                    e.txn = None;
                    return Err(OwError::NoEcho);
                }
                return Ok(false);
            }
            match e.txn.take() {
                Some(done) => {
                    *t = done;
                    Ok(true)
                }
                None => Err(OwError::NoEcho),
            }
        })
    }
}

/// One ring's timer and DMA stream.
struct Ring {
    tim: usize,
    /// Offset of the compare register the duties go to.
    ccr: usize,
    dma: usize,
    stream: usize,
    channel: u32,
}

const RINGS: [Ring; 2] = [
    Ring {
        tim: TIM8,
        ccr: 0x34,
        dma: DMA2,
        stream: 1,
        channel: 7,
    },
    Ring {
        tim: TIM3,
        ccr: 0x38,
        dma: DMA1,
        stream: 2,
        channel: 5,
    },
];

impl Ring {
    fn scr(&self) -> usize {
        self.dma + 0x10 + 0x18 * self.stream
    }

    /// Bit position of the stream's flag group in LISR/LIFCR (streams 0..3).
    fn flag_shift(&self) -> u32 {
        [0, 6, 16, 22][self.stream]
    }
}

/// Why a ring could not start.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LedError {
    /// No such ring.
    NoRing,
    /// More duties than the ring's buffer holds.
    TooLong,
    /// The previous transfer still runs.
    Busy,
}

/// Two WS2812 rings: each bit is one PWM period of the ring's timer (HUB_TIMING at a
/// 90 MHz counter clock), its duty written into CCRx by DMA on every update event.
pub struct DmaRings {
    /// The DMA source of each ring: a static the firmware lends for good (fixed address,
    /// and not moved through the start-up frames as part of the value: 1.3 KB).
    buf: &'static mut RingBufs,
    /// The LED task's guard timer (the report's `timeoutLed`): when it was armed (TIM2, the
    /// tasks' 1 MHz time base) and for how long, in µs.
    guard: Option<(u32, u32)>,
}

/// The duty buffers of both rings.
pub type RingBufs = [[u16; RING_SLOTS]; 2];

/// TIM2's counter: the tasks' free-running 1 MHz time base (`main::start_time_base`).
const TIM2_CNT: usize = 0x4000_0024;

impl DmaRings {
    /// Sets up TIM8 (APB2, 180 MHz timer clock, prescaler 2) and TIM3 (APB1, 90 MHz) as
    /// PWM mode 1 with preload, duty 0 (line low), update DMA request on; the DMA clocks.
    pub fn new(buf: &'static mut RingBufs) -> Self {
        set_bits(RCC_AHB1ENR, (1 << 21) | (1 << 22));
        set_bits(RCC_APB1ENR, 1 << 1);
        set_bits(RCC_APB2ENR, 1 << 1);
        let _ = rd(RCC_APB2ENR);
        let arr = u32::from(HUB_TIMING.period) - 1;
        // TIM8: CH1, PSC 1 (180 -> 90 MHz).
        wr(TIM8 + 0x28, 1);
        wr(TIM8 + 0x2C, arr);
        wr(TIM8 + 0x34, 0);
        wr(TIM8 + 0x18, (0b110 << 4) | (1 << 3));
        wr(TIM8 + 0x20, 1);
        wr(TIM8 + 0x44, 1 << 15); // BDTR.MOE
        wr(TIM8 + 0x14, 1); // UG: load PSC/ARR
        wr(TIM8 + 0x10, 0);
        wr(TIM8 + 0x0C, 1 << 8); // UDE
        wr(TIM8, (1 << 7) | 1); // CR1: ARPE, CEN
                                // TIM3: CH2, PSC 0.
        wr(TIM3 + 0x28, 0);
        wr(TIM3 + 0x2C, arr);
        wr(TIM3 + 0x38, 0);
        wr(TIM3 + 0x18, (0b110 << 12) | (1 << 11));
        wr(TIM3 + 0x20, 1 << 4);
        wr(TIM3 + 0x14, 1);
        wr(TIM3 + 0x10, 0);
        wr(TIM3 + 0x0C, 1 << 8);
        wr(TIM3, (1 << 7) | 1); // CR1: ARPE, CEN
        Self { buf, guard: None }
    }
}

impl LedStrip for DmaRings {
    type Error = LedError;

    /// The timers and DMA clocks are set up once in [`DmaRings::new`]; a ring is ready when
    /// its stream is off (after [`LedStrip::restart`] or a completed transfer).
    fn configure(&mut self, ring: usize) -> Result<(), LedError> {
        let r = RINGS.get(ring).ok_or(LedError::NoRing)?;
        if rd(r.scr()) & 1 != 0 {
            return Err(LedError::Busy);
        }
        Ok(())
    }

    /// Stops the ring's stream, clears its flags and drives the line low (duty 0).
    fn restart(&mut self, ring: usize) {
        if let Some(r) = RINGS.get(ring) {
            wr(r.scr(), rd(r.scr()) & !1);
            wr(r.dma + 0x08, 0x3D << r.flag_shift());
            wr(r.tim + r.ccr, 0);
        }
    }

    fn arm_guard(&mut self, ms: u32) -> Result<(), LedError> {
        self.guard = Some((rd(TIM2_CNT), ms.saturating_mul(1000)));
        Ok(())
    }

    fn guard_expired(&mut self) -> bool {
        self.guard
            .is_some_and(|(t0, us)| rd(TIM2_CNT).wrapping_sub(t0) >= us)
    }

    fn start(&mut self, ring: usize, duties: &[u16]) -> Result<(), LedError> {
        let r = RINGS.get(ring).ok_or(LedError::NoRing)?;
        let buf = self.buf.get_mut(ring).ok_or(LedError::NoRing)?;
        if duties.len() > buf.len() {
            return Err(LedError::TooLong);
        }
        if rd(r.scr()) & 1 != 0 {
            return Err(LedError::Busy);
        }
        buf[..duties.len()].copy_from_slice(duties);
        // Clear the stream's flags (TCIF, HTIF, TEIF, DMEIF, FEIF).
        wr(r.dma + 0x08, 0x3D << r.flag_shift());
        wr(r.scr() + 0x04, duties.len() as u32); // NDTR
        wr(r.scr() + 0x08, (r.tim + r.ccr) as u32); // PAR
        wr(r.scr() + 0x0C, buf.as_ptr() as u32); // M0AR
        wr(r.scr() + 0x14, 0); // FCR: direct mode
                               // CHSEL, MSIZE = PSIZE = 16 bit, MINC, memory to peripheral.
        let cr = (r.channel << 25) | (1 << 13) | (1 << 11) | (1 << 10) | (1 << 6);
        wr(r.scr(), cr);
        wr(r.scr(), cr | 1);
        Ok(())
    }

    fn done(&mut self, ring: usize) -> bool {
        let Some(r) = RINGS.get(ring) else {
            return false;
        };
        rd(r.dma) & (1 << (r.flag_shift() + 5)) != 0
    }
}

/// Status LEDs on PC8 (green: stack running) and PC9 (red: ESC fault), active high.
pub struct BoardLeds {
    pub green: Pin<'C', 8, Output>,
    pub red: Pin<'C', 9, Output>,
}

impl Leds for BoardLeds {
    fn set(&mut self, green: bool, red: bool) {
        self.green.set_state(green.into());
        self.red.set_state(red.into());
    }
}

/// Rings dark from any context (panic, fault): both DMA streams and the compares off.
pub fn rings_off() {
    for r in &RINGS {
        wr(r.scr(), rd(r.scr()) & !1);
        wr(r.tim + r.ccr, 0);
    }
}
