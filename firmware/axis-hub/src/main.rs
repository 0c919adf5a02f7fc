//! The axis communication hub (`oxicat_devices::axis_hub::HubFirmware`, the same firmware
//! main the virtual segment hosts in `axis_hub::rig`) on an STM32F446 with a LAN9252 on
//! SPI1, 15 DS18B20 on a 1-Wire bus over USART3 and two WS2812 rings on TIM8/TIM3 + DMA.
//! This file and `board.rs` are board glue only. Wiring, pin map, priorities: README.md.
//!
//! What runs where:
//!
//! | event | handler | priority | runs |
//! |---|---|---|---|
//! | TIM6 update, 1 kHz | `TIM6_DAC` | 0x20 | the report's tasks when due (time from TIM2, 1 MHz), in priority order: APP 10 ms, LED 33 ms, supervisor 100 ms, temperature 1 s (`HubFirmware::on_timer`) |
//! | PDI IRQ falling (PA10) | `EXTI15_10` | 0x20 | `HubFirmware::on_pdi_irq` (SM-synchronous cycle, ESM) |
//! | SYNC0 rising (PB3) | `EXTI3` | 0x20 | `HubFirmware::on_sync0` |
//! | — | thread | — | re-pends the PDI IRQ while the line stays low, then WFI |
//!
//! Every handler that touches the firmware runs at the one level 0x20, so none preempts
//! another and the firmware needs no lock: it lives in [`FwCell`], accessed only there.
#![no_std]
#![no_main]

mod board;

use core::cell::UnsafeCell;
use core::mem::MaybeUninit;
use core::ptr::addr_of_mut;
use core::sync::atomic::{AtomicU32, Ordering};

use board::{BoardLeds, DmaRings, UartOneWire};
use cortex_m::peripheral::NVIC;
use cortex_m_rt::entry;
use oxicat_board_support::{clear_exti, clocks_180mhz, esc_exti, esc_spi1, halt_on_fault, EscSpi};
use oxicat_devices::axis_hub::{HubFirmware, HubSlot, TASKS};
use oxicat_devices::demo::Leds;
use oxicat_pdi::{Lan9252, Lan9252Config};
use stm32f4xx_hal::{
    gpio::PB5,
    pac::{self, interrupt, Interrupt},
    prelude::*,
    timer::Event,
};

/// Task tick (TIM6): 1 kHz, the resolution of the report's periods.
const TICK_HZ: u32 = 1_000;
/// The one NVIC level of everything that touches the firmware (upper nibble).
const PRIO_FW: u8 = 0x20;
/// USART3's level (the 1-Wire slots): above [`PRIO_FW`]; it touches only the bus engine,
/// under a critical section.
const PRIO_ONEWIRE: u8 = 0x10;

type Esc = Lan9252<EscSpi>;
type Fw = HubFirmware<Esc, UartOneWire, DmaRings, &'static mut HubSlot<Esc>>;

/// The firmware and its ESC driver.
struct Hub {
    fw: Fw,
    esc: Esc,
    leds: BoardLeds,
    clock: TaskClock,
}

/// The tasks' time base: TIM2, free running at 1 MHz (32 bits), read at every tick. A tick
/// held back by a long task (the 1-Wire read-out blocks for up to ~0.2 s at 115200 baud)
/// loses no time: a task whose period boundary passed meanwhile runs once at the next tick.
struct TaskClock {
    last_cnt: u32,
    us: u64,
    last_ms: u64,
}

impl TaskClock {
    fn now_us() -> u32 {
        // SAFETY: a read of TIM2's counter, which only `start_time_base` configures.
        unsafe { (*pac::TIM2::ptr()).cnt().read().bits() }
    }

    /// (ms before, ms now) since the start.
    fn advance(&mut self) -> (u64, u64) {
        let cnt = Self::now_us();
        self.us += u64::from(cnt.wrapping_sub(self.last_cnt));
        self.last_cnt = cnt;
        let before = self.last_ms;
        self.last_ms = self.us / 1000;
        (before, self.last_ms)
    }
}

/// TIM2 as a free-running 1 MHz counter (APB1 timer clock `timclk` Hz).
fn start_time_base(timclk: u32) {
    // SAFETY: TIM2 is used for nothing else; RCC bit set read-modify-write before the
    // interrupts run.
    unsafe {
        let rcc = &*pac::RCC::ptr();
        rcc.apb1enr().modify(|r, w| w.bits(r.bits() | 1));
        let _ = rcc.apb1enr().read();
        let t = &*pac::TIM2::ptr();
        t.psc().write(|w| w.bits(timclk / 1_000_000 - 1));
        t.arr().write(|w| w.bits(u32::MAX));
        t.egr().write(|w| w.bits(1));
        t.cr1().write(|w| w.bits(1));
    }
}

/// Storage for [`Hub`], shared by priority rather than by a lock: see [`FwCell::get`].
struct FwCell(UnsafeCell<MaybeUninit<Hub>>);

// SAFETY: access is serialised by interrupt priority (FwCell::get's contract).
unsafe impl Sync for FwCell {}

impl FwCell {
    /// # Safety
    /// The caller runs at priority [`PRIO_FW`], does not keep the reference beyond that,
    /// and [`FwCell::init`] ran before those interrupts were unmasked.
    #[allow(clippy::mut_from_ref)]
    unsafe fn get(&self) -> &mut Hub {
        unsafe { (*self.0.get()).assume_init_mut() }
    }

    /// # Safety
    /// Called once, before the interrupts at [`PRIO_FW`] are unmasked; `f` writes every
    /// field of the `Hub` it is given.
    unsafe fn init_with(&self, f: impl FnOnce(*mut Hub)) {
        unsafe { f((*self.0.get()).as_mut_ptr()) };
    }
}

static HUB: FwCell = FwCell(UnsafeCell::new(MaybeUninit::uninit()));
/// Milliseconds since the tick started.
static MS: AtomicU32 = AtomicU32::new(0);

/// 1 kHz task tick: runs every task of [`TASKS`] whose period has elapsed, higher
/// priority first (TASKS is in priority order), as the report's scheduler would.
#[interrupt]
fn TIM6_DAC() {
    // SAFETY: TIM6 SR: clearing UIF is this handler's only access after set-up.
    unsafe { (*pac::TIM6::ptr()).sr().write(|w| w.bits(0)) };
    MS.fetch_add(1, Ordering::Relaxed);
    // SAFETY: handler at PRIO_FW.
    let h = unsafe { HUB.get() };
    let (before, now) = h.clock.advance();
    for t in &TASKS {
        let period_ms = t.period_ns / 1_000_000;
        if period_ms != 0 && now / period_ms > before / period_ms {
            h.fw.on_timer(t.id, &mut h.esc);
        }
    }
    // The temperature task's 1-Wire transactions run in USART3's interrupt: take a finished
    // one and start the next (a few µs; the tick never waits for the bus).
    h.fw.on_onewire();
    // Green: the stack runs; red: the ESC does not answer.
    let up = h.fw.slave().is_some();
    h.leds.set(up, !up);
}

/// USART3: the 1-Wire slot in flight ended (its echo arrived); the next one goes out.
#[interrupt]
fn USART3() {
    board::onewire_irq();
}

/// SYNC0 (DC-synchronous cycle).
#[interrupt]
fn EXTI3() {
    clear_exti(3);
    // SAFETY: handler at PRIO_FW.
    let h = unsafe { HUB.get() };
    h.fw.on_sync0(&mut h.esc);
}

/// PDI IRQ (PA10, the only line enabled in 10..15).
#[interrupt]
fn EXTI15_10() {
    clear_exti(10);
    // SAFETY: handler at PRIO_FW.
    let h = unsafe { HUB.get() };
    h.fw.on_pdi_irq(&mut h.esc);
}

/// Builds the firmware into [`HUB`] in a frame of its own. The slave stack is built in
/// `slot` where it lies (`HubSlot`, main's `static mut`, in `.bss`): built as a value and
/// kept in an `Option` inside the firmware, it and its moves took an 18 KB frame here and
/// 6.6 KB in every restart from the supervisor's timer handler.
#[inline(never)]
fn start(
    mut esc: Esc,
    slot: &'static mut HubSlot<Esc>,
    bus: UartOneWire,
    rings: DmaRings,
    leds: BoardLeds,
) {
    // SAFETY: once, before any PRIO_FW interrupt is unmasked (main enables them afterwards).
    // Each field is written where it lies (the firmware, 2.2 KB, is not built in this
    // frame and then copied).
    unsafe {
        HUB.init_with(|hub| {
            addr_of_mut!((*hub).fw).write(Fw::new(&mut esc, slot, bus, rings));
            addr_of_mut!((*hub).esc).write(esc);
            addr_of_mut!((*hub).leds).write(leds);
            addr_of_mut!((*hub).clock).write(TaskClock {
                last_cnt: TaskClock::now_us(),
                us: 0,
                last_ms: 0,
            });
        })
    };
}

#[entry]
fn main() -> ! {
    // cortex-m-rt hands `main` this as a `&'static mut` (one per program).
    static mut SLOT: HubSlot<Esc> = HubSlot::new();
    static mut RING_BUFS: board::RingBufs = [[0; oxicat_devices::axis_hub::ws2812::RING_SLOTS]; 2];
    let Some(dp) = pac::Peripherals::take() else {
        loop {
            cortex_m::asm::wfi();
        }
    };
    let Some(cp) = cortex_m::Peripherals::take() else {
        loop {
            cortex_m::asm::wfi();
        }
    };
    let clocks = clocks_180mhz(dp.RCC);
    let mut delay = cp.SYST.delay(&clocks);
    dp.DBGMCU.cr().modify(|_, w| w.dbg_sleep().set_bit());

    let gpioa = dp.GPIOA.split();
    let gpiob = dp.GPIOB.split();
    let gpioc = dp.GPIOC.split();

    let leds = BoardLeds {
        green: gpioc.pc8.into_push_pull_output(),
        red: gpioc.pc9.into_push_pull_output(),
    };

    // 1-Wire: USART3 TX on PB10 (AF7), open drain, half-duplex.
    let _ow_pin = gpiob.pb10.into_alternate::<7>().set_open_drain();
    let bus = UartOneWire::new(clocks.pclk1().raw());
    // LED rings: PC6 = TIM8_CH1 (AF3), PC7 = TIM3_CH2 (AF2).
    let _ring1 = gpioc.pc6.into_alternate::<3>();
    let _ring2 = gpioc.pc7.into_alternate::<2>();
    let rings = DmaRings::new(RING_BUFS);

    // LAN9252 on SPI1: SCK PA5, MISO PA6, MOSI PA7, mode 0, 90 MHz / 4 = 22.5 MHz; CS PB6.
    let spi = esc_spi1(
        dp.SPI1,
        (gpioa.pa5, gpioa.pa6, gpioa.pa7),
        gpiob.pb6,
        22500.kHz(),
        &clocks,
    );
    let mut esc = Lan9252::new(spi, oxicat_pdi::NoLines, Lan9252Config::default());
    // The LAN9252 needs ~ 30 ms after power-on before the SPI answers. A failed init is
    // not fatal: the firmware's supervisor retries the stack every second.
    delay.delay_ms(50);
    let _ = esc.init();
    start_time_base(clocks.timclk1().raw());
    start(esc, SLOT, bus, rings, leds);

    // ESC lines on EXTI: IRQ PA10 falling (open drain, pull-up), SYNC0 PB3 rising.
    let mut syscfg = dp.SYSCFG.constrain();
    let mut exti = dp.EXTI;
    let lines = esc_exti(gpioa.pa10, gpiob.pb3, None::<PB5>, &mut syscfg, &mut exti);

    let mut tick = dp.TIM6.counter_hz(&clocks);
    if tick.start(TICK_HZ.Hz()).is_err() {
        loop {
            cortex_m::asm::wfi();
        }
    }
    tick.listen(Event::Update);

    // SAFETY: priorities are set before unmasking; the shared state is initialised.
    unsafe {
        let mut nvic = cp.NVIC;
        for i in [Interrupt::TIM6_DAC, Interrupt::EXTI3, Interrupt::EXTI15_10] {
            nvic.set_priority(i, PRIO_FW);
        }
        // Above the firmware's level: a slot's next byte goes out while a handler runs.
        nvic.set_priority(Interrupt::USART3, PRIO_ONEWIRE);
        NVIC::unmask(Interrupt::USART3);
        NVIC::unmask(Interrupt::TIM6_DAC);
        NVIC::unmask(Interrupt::EXTI3);
        NVIC::unmask(Interrupt::EXTI15_10);
    }

    let mut last_kick = MS.load(Ordering::Relaxed);
    loop {
        // The IRQ line is a level: a cause that arrives while it is still low from another
        // gives no new falling edge. Re-run the handler while the line stays low, once per
        // tick.
        let now = MS.load(Ordering::Relaxed);
        if lines.irq.is_low() && now != last_kick {
            last_kick = now;
            NVIC::pend(Interrupt::EXTI15_10);
        }
        cortex_m::asm::wfi();
    }
}

// Panics and hard faults make the outputs safe, then halt.
halt_on_fault!(board::rings_off);
