//! What oxicat's STM32F446 board images (`firmware/<board>`) share, written once:
//!
//! - [`PrioCell`]: the ESC side (stack and driver) shared between the ESC interrupt
//!   handlers and the thread by interrupt priority instead of a lock;
//! - [`with_basepri`]: a section of thread code during which the handlers at or below a
//!   priority wait (BASEPRI), the more urgent ones (a joint or current loop) still run;
//! - [`esc_spi1`]: the ESC's SPI bus, SPI1 on PA5/PA6/PA7 with chip select PB6, mode 0,
//!   as every board wires its LAN9252 or ET1100;
//! - [`esc_exti`]: the ESC's interrupt lines (PDI IRQ PA10, SYNC0 PB3, SYNC1 PB5) on EXTI,
//!   and [`clear_exti`] for their handlers;
//! - [`clocks_180mhz`]: the clock tree every board runs (8 MHz HSE, 180 MHz SYSCLK);
//! - [`halt_on_fault!`]: a panic and a HardFault both make the outputs safe, then halt.
//!
//! Each image keeps what is its own: pins beyond the ESC's, timers, the application.

#![no_std]

// The images' memcpy / memset / memcmp (the crate's README): linked by naming it.
use oxicat_fw_mem as _;

use core::cell::UnsafeCell;
use core::mem::MaybeUninit;
use core::sync::atomic::{compiler_fence, Ordering};

use cortex_m::register::{basepri, basepri_max};
use embedded_hal_bus::spi::{ExclusiveDevice, NoDelay};
use stm32f4xx_hal::gpio::{
    Edge, ExtiPin, Input, Output, PinMode, PushPull, PA10, PA5, PA6, PA7, PB3, PB5, PB6,
};
use stm32f4xx_hal::pac::{EXTI, RCC, SPI1};
use stm32f4xx_hal::prelude::*;
use stm32f4xx_hal::rcc::Clocks;
use stm32f4xx_hal::spi::{Mode, Phase, Polarity, Spi};
use stm32f4xx_hal::syscfg::SysCfg;
use stm32f4xx_hal::time::Hertz;

/// A value shared by interrupt priority rather than by a lock: stored once before the
/// interrupts that use it are unmasked, then used by code that runs at one priority (the
/// handlers of one level never preempt one another) or holds that level off
/// ([`with_basepri`]).
pub struct PrioCell<T>(UnsafeCell<MaybeUninit<T>>);

// SAFETY: access is serialised by interrupt priority (`PrioCell::get`'s contract); the
// value moves between contexts of one core, so it must be `Send`.
unsafe impl<T: Send> Sync for PrioCell<T> {}

impl<T> PrioCell<T> {
    /// An empty cell (for a `static`).
    pub const fn uninit() -> Self {
        Self(UnsafeCell::new(MaybeUninit::uninit()))
    }

    /// Stores the value.
    ///
    /// # Safety
    /// Called once, before the interrupts that use the cell are unmasked.
    pub unsafe fn init(&self, value: T) {
        unsafe { (*self.0.get()).write(value) };
    }

    /// The value.
    ///
    /// # Safety
    /// The caller runs at the cell's priority (one of the handlers that share it) or has
    /// BASEPRI at that priority or more urgent ([`with_basepri`]); it does not keep the
    /// reference beyond that; [`PrioCell::init`] ran before.
    #[allow(clippy::mut_from_ref)]
    pub unsafe fn get(&self) -> &mut T {
        unsafe { (*self.0.get()).assume_init_mut() }
    }
}

/// Runs `f` with BASEPRI raised to `priority` (never lowered: `basepri_max`): exceptions
/// of that priority and less urgent wait, the more urgent ones still run. Restores the
/// level it found.
pub fn with_basepri<R>(priority: u8, f: impl FnOnce() -> R) -> R {
    let old = basepri::read();
    basepri_max::write(priority);
    compiler_fence(Ordering::SeqCst);
    let r = f();
    compiler_fence(Ordering::SeqCst);
    // SAFETY: restores the level this function found.
    unsafe { basepri::write(old) };
    r
}

/// The ESC's SPI bus as a device with its chip select.
pub type EscSpi = ExclusiveDevice<Spi<SPI1>, PB6<Output<PushPull>>, NoDelay>;

/// The ESC's SPI bus: SPI1 with SCK PA5, MISO PA6, MOSI PA7, mode 0 (the LAN9252 takes
/// mode 0 or 3; the ET1100's PDI configuration 0x0150 = 0x00 in the SII is mode 0), at
/// `sck` (the APB2 clock divided by a power of two: 22.5 MHz or 11.25 MHz at 90 MHz), and
/// chip select PB6 under software control, one CS-low frame per transaction.
pub fn esc_spi1(
    spi1: SPI1,
    (sck, miso, mosi): (PA5, PA6, PA7),
    cs: PB6,
    sck_hz: Hertz,
    clocks: &Clocks,
) -> EscSpi {
    let spi = Spi::new(
        spi1,
        (sck, miso, mosi),
        Mode {
            polarity: Polarity::IdleLow,
            phase: Phase::CaptureOnFirstTransition,
        },
        sck_hz,
        clocks,
    );
    let cs = cs.into_push_pull_output_in_state(true.into());
    let Ok(dev) = ExclusiveDevice::new_no_delay(spi, cs);
    dev
}

/// The clock tree of every board: 8 MHz HSE → 180 MHz SYSCLK; APB1 45 MHz (its timers
/// 90 MHz), APB2 90 MHz (TIM1/TIM8 180 MHz, SPI1 from 90 MHz).
pub fn clocks_180mhz(rcc: RCC) -> Clocks {
    rcc.constrain()
        .cfgr
        .use_hse(8.MHz())
        .sysclk(180.MHz())
        .pclk1(45.MHz())
        .pclk2(90.MHz())
        .freeze()
}

/// The ESC's interrupt lines after [`esc_exti`].
pub struct EscLines {
    /// PDI IRQ (PA10, EXTI10): open drain, active low, pulled up.
    pub irq: PA10<Input>,
    /// SYNC0 (PB3, EXTI3): push-pull, active high.
    pub sync0: PB3<Input>,
    /// SYNC1 (PB5, EXTI5), where the image uses it.
    pub sync1: Option<PB5<Input>>,
}

/// Routes the ESC's lines to EXTI (from whatever mode the pins are in: PB3 leaves reset as
/// JTDO): the PDI IRQ on its falling edge (line 10), SYNC0 and
/// SYNC1 on their rising edges (lines 3 and 5), each line's pending bit cleared. The NVIC
/// lines (`EXTI15_10`, `EXTI3`, `EXTI9_5`) stay for the image to prioritise and unmask.
pub fn esc_exti<M10: PinMode, M3: PinMode, M5: PinMode>(
    irq: PA10<M10>,
    sync0: PB3<M3>,
    sync1: Option<PB5<M5>>,
    syscfg: &mut SysCfg,
    exti: &mut EXTI,
) -> EscLines {
    let mut irq = irq.into_pull_up_input();
    irq.make_interrupt_source(syscfg);
    irq.trigger_on_edge(exti, Edge::Falling);
    irq.enable_interrupt(exti);
    clear_exti(10);
    let mut sync0 = sync0.into_floating_input();
    sync0.make_interrupt_source(syscfg);
    sync0.trigger_on_edge(exti, Edge::Rising);
    sync0.enable_interrupt(exti);
    clear_exti(3);
    let sync1 = sync1.map(|p| {
        let mut p = p.into_floating_input();
        p.make_interrupt_source(syscfg);
        p.trigger_on_edge(exti, Edge::Rising);
        p.enable_interrupt(exti);
        clear_exti(5);
        p
    });
    EscLines { irq, sync0, sync1 }
}

/// Clears EXTI line `line`'s pending bit (a handler's first step).
pub fn clear_exti(line: u8) {
    // SAFETY: PR is write-1-to-clear; only this line's bit is written.
    unsafe { (*EXTI::ptr()).pr().write(|w| w.bits(1 << line)) };
}

/// Defines the image's panic handler and HardFault handler: both call `$safe` (a function
/// that puts the outputs in their safe state: bridges off, LEDs dark) and halt. A panic
/// masks the interrupts first; the HardFault handler runs above them anyway. The image
/// depends on `cortex-m-rt` for the `exception` attribute.
#[macro_export]
macro_rules! halt_on_fault {
    ($safe:path) => {
        /// Panics make the outputs safe, then halt.
        #[panic_handler]
        fn panic(_: &core::panic::PanicInfo) -> ! {
            cortex_m::interrupt::disable();
            $safe();
            loop {
                cortex_m::asm::nop();
            }
        }

        /// So do hard faults.
        #[cortex_m_rt::exception]
        unsafe fn HardFault(_: &cortex_m_rt::ExceptionFrame) -> ! {
            $safe();
            loop {
                cortex_m::asm::nop();
            }
        }
    };
}
