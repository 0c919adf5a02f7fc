//! What oxicat's STM32F446 board images (`firmware/<board>`) share, written once:
//!
//! - [`PrioCell`]: the ESC side (stack and driver) shared between the ESC interrupt
//!   handlers and the thread by interrupt priority instead of a lock;
//! - [`with_basepri`]: a section of thread code during which the handlers at or below a
//!   priority wait (BASEPRI), the more urgent ones (a joint or current loop) still run;
//! - [`esc_spi1`]: the ESC's SPI bus, SPI1 on PA5/PA6/PA7 with chip select PB6, mode 0,
//!   as every board wires its LAN9252 or ET1100;
//! - [`halt_on_fault!`]: a panic and a HardFault both make the outputs safe, then halt.
//!
//! Each image keeps what is its own: pins beyond the ESC's, timers, the application.

#![no_std]

use core::cell::UnsafeCell;
use core::mem::MaybeUninit;
use core::sync::atomic::{compiler_fence, Ordering};

use cortex_m::register::{basepri, basepri_max};
use embedded_hal_bus::spi::{ExclusiveDevice, NoDelay};
use stm32f4xx_hal::gpio::{Output, PushPull, PA5, PA6, PA7, PB6};
use stm32f4xx_hal::pac::SPI1;
use stm32f4xx_hal::rcc::Clocks;
use stm32f4xx_hal::spi::{Mode, Phase, Polarity, Spi};
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

