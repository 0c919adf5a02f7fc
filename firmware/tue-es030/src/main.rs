//! The TUeES030 motor I/O board (`oxicat_devices::tue_es030::TuEs030`, the same firmware
//! the virtual segment hosts in `tue_es030::rig`) on the oxicat slave stack, on an
//! STM32F446 with a LAN9252 on SPI1, three H-bridges on TIM1/TIM8, the motor currents and
//! line voltage on ADC1 and three encoders on TIM2/TIM3/TIM4. This file and `board.rs` are
//! board glue only. Wiring, pin map, what maps to the manual's ET1200 + Spartan-6:
//! README.md.
//!
//! What runs where (the rig's table, on interrupts):
//!
//! | event | handler | priority | runs |
//! |---|---|---|---|
//! | ADC1 injected sequence done, 20 kHz (TIM1 update event, RCR = 7) | `ADC` | 0x10 | every 20th tick first `TuEs030::service` (1 kHz: encoders, line voltage), then `TuEs030::current_loop` (currents → three PIs → duties) |
//! | PDI IRQ falling (PA10) | `EXTI15_10` | 0x20 | `Slave::on_pdi_irq` (SM-synchronous: RxPDO → application → TxPDO) |
//! | SYNC0 rising (PB3) | `EXTI3` | 0x20 | `Slave::on_sync0` (not used by the board's SM-synchronous mode) |
//! | SYNC1 rising (PB5) | `EXTI9_5` | 0x20 | `Slave::on_sync1` |
//! | every 20th current-loop tick (1 ms) | thread | — | `Slave::poll` (ESM, mailbox, watchdog, FoE), 0x8040 into the dictionary (`Hooks::store_voltages`), then WFI |
//!
//! Sharing: the stack and the ESC driver are used only at priority 0x20 — the three ESC
//! handlers, which cannot preempt one another — and by the thread with BASEPRI raised to
//! 0x20 ([`with_esc_from_thread`]), so their SPI transactions never interleave and never
//! hold off the current loop. The firmware is shared between the current loop and the
//! stack's hooks: it lives in a `cortex_m::interrupt::Mutex`; the hooks (`Hooks(FwCs)`)
//! read and convert the dictionary outside it and take it only to hand the results over
//! (motor parameters, the process data's setpoints and feedback), a few words in a
//! critical section, so the ADC interrupt is never held off for a dictionary read.
#![no_std]
#![no_main]

mod board;
mod store;

use core::cell::RefCell;
use core::sync::atomic::{AtomicU32, Ordering};

use board::TueBoard;
use cortex_m::interrupt::{self as irq, Mutex};
use cortex_m::peripheral::NVIC;
use cortex_m_rt::entry;
use oxicat_board_support::{
    clear_exti, clocks_180mhz, esc_exti, esc_spi1, halt_on_fault, with_basepri, EscSpi, PrioCell,
};
use oxicat_devices::tue_es030::{device, FwLock, Hooks, TuEs030};
use oxicat_pdi::{Lan9252, Lan9252Config};
use oxicat_slave::foe::{FirmwareUpdate, WithFoe};
use oxicat_slave::{CheckedDef, Slave, SlaveSlot};
use stm32f4xx_hal::{
    gpio::{Output, Pin},
    pac::{self, interrupt, Interrupt},
    prelude::*,
};
use store::FlashStore;

/// Mailbox buffer size of the stack: the board's mailboxes are 128 bytes.
const MBX: usize = 128;
/// Copy steps per direction of the stack's compiled PDO mappings, sized to the device
/// (`pdo::map_steps`: 54, every entry of the PDOs its configurable assignment can take; the
/// default of 64 would be 2 × 10 × 8 = 160 B more RAM).
const MAP: usize = oxicat_slave::pdo::map_steps(&device::DEF);

/// The device's definition as the image links it: without the ESI/SII description
/// (`DeviceDef::for_image`), which the stack does not read.
static IMAGE_DEF: oxicat_slave::DeviceDef = device::DEF.for_image();
/// Current-loop ticks per service-routine run (20 kHz / 1 kHz).
const TICKS_PER_SERVICE: u32 = board::CURRENT_LOOP_HZ / 1000;
/// The main loop polls the stack every 20 current-loop ticks (1 ms).
const POLL_EVERY_TICKS: u32 = TICKS_PER_SERVICE;

/// NVIC priorities (upper nibble: the F446 implements 4 bits; lower = more urgent).
const PRIO_CURRENT_LOOP: u8 = 0x10;
/// SYNC0, SYNC1 and the PDI IRQ share one level so they never preempt one another.
const PRIO_ESC: u8 = 0x20;

type Esc = Lan9252<EscSpi>;
type TueSlave = Slave<Esc, { device::IMAGE }, MBX, MAP>;
/// Where [`TueSlave`] is built in place: `main`'s `static mut`, all zero in `.bss` until
/// [`start_stack`] starts it (no `Slave` value on the stack, no copy of one).
type StackSlot = SlaveSlot<Esc, { device::IMAGE }, MBX, MAP>;
type Firmware = TuEs030<TueBoard>;
/// The stack's application: the device's hooks, and the FoE update flow on the flash
/// store (the host rig's `WithFoe<_, FirmwareUpdate<_>>`, on flash instead of RAM).
type App = WithFoe<Hooks<FwCs>, FirmwareUpdate<FlashStore>>;

/// The stack, its ESC driver and its application.
struct EscSide {
    /// The stack, built in place in `main`'s [`StackSlot`] (`.bss`).
    slave: &'static mut TueSlave,
    esc: Esc,
    app: App,
}

/// The ESC side, shared by priority rather than by a lock ([`PrioCell::get`]'s contract:
/// the three ESC handlers at [`PRIO_ESC`], the thread through [`with_esc_from_thread`]).
static ESC: PrioCell<EscSide> = PrioCell::uninit();
/// The board's firmware, shared by the current loop and the stack's hooks.
static FW: Mutex<RefCell<Option<Firmware>>> = Mutex::new(RefCell::new(None));
/// Current-loop ticks since start (service schedule, the main loop's poll schedule).
static TICKS: AtomicU32 = AtomicU32::new(0);

/// Runs `f` on the firmware in a critical section.
fn with_fw<R>(f: impl FnOnce(&mut Firmware) -> R) -> R {
    irq::free(|cs| {
        let mut fw = FW.borrow(cs).borrow_mut();
        f(fw.as_mut()
            .expect("the firmware is set before interrupts are enabled"))
    })
}

/// Runs `f` on the stack from the thread, with the ESC handlers masked (BASEPRI) and the
/// current loop still running.
fn with_esc_from_thread<R>(f: impl FnOnce(&mut EscSide) -> R) -> R {
    // SAFETY: BASEPRI masks every ESC handler; `main` stored the ESC side first.
    with_basepri(PRIO_ESC, || f(unsafe { ESC.get() }))
}

/// The firmware as the stack sees it: the device's own hooks (`tue_es030::Hooks`) read
/// and convert the dictionary outside any lock and hand only the results to the shared
/// [`TuEs030`] here, each in a critical section of a few words, so the SPI work of the
/// stack's handlers and the dictionary reads (`init_param` at PRE-OP → SAFE-OP, a motor
/// parameter's SDO write, the process data) run with the current loop enabled. FoE is
/// [`App`]'s: the update flow on the flash store (`store.rs`).
struct FwCs;

impl FwLock for FwCs {
    type Board = TueBoard;

    fn with<R>(&mut self, f: impl FnOnce(&mut Firmware) -> R) -> R {
        with_fw(f)
    }
}

/// 20 kHz: ADC1's injected sequence (triggered by TIM1's update event) is done. Every
/// 20th tick the 1 kHz service routine first (as the host rig orders them), then the
/// current loop: currents → PI → duties.
#[interrupt]
fn ADC() {
    let n = TICKS.load(Ordering::Relaxed);
    with_fw(|f| {
        f.board.ack_conversion();
        if n.is_multiple_of(TICKS_PER_SERVICE) {
            f.service();
        }
        f.current_loop();
    });
    TICKS.store(n.wrapping_add(1), Ordering::Relaxed);
}

/// SYNC0 (the board runs SM-synchronous; a master that configures DC gets the stack's
/// DC handling).
#[interrupt]
fn EXTI3() {
    clear_exti(3);
    // SAFETY: ESC handler at PRIO_ESC.
    let e = unsafe { ESC.get() };
    let _ = e.slave.on_sync0(&mut e.esc, &mut e.app);
}

/// SYNC1 (PB5, the only line enabled in 5..9).
#[interrupt]
fn EXTI9_5() {
    clear_exti(5);
    // SAFETY: ESC handler at PRIO_ESC.
    let e = unsafe { ESC.get() };
    let _ = e.slave.on_sync1(&mut e.esc, &mut e.app);
}

/// PDI IRQ (PA10, the only line enabled in 10..15): the process data on the SM2 event.
#[interrupt]
fn EXTI15_10() {
    clear_exti(10);
    // SAFETY: ESC handler at PRIO_ESC.
    let e = unsafe { ESC.get() };
    let _ = e.slave.on_pdi_irq(&mut e.esc, &mut e.app);
}

/// Blinks the FRUN LED fast forever: the ESC did not answer at start-up.
fn fail(led: &mut Pin<'D', 14, Output>, delay: &mut impl embedded_hal::delay::DelayNs) -> ! {
    board::bridges_emergency_off();
    loop {
        led.set_high();
        delay.delay_ms(100);
        led.set_low();
        delay.delay_ms(100);
    }
}

/// Starts the slave stack on the LAN9252 in `slot` and stores it with the driver in
/// [`ESC`]. The stack is built where it lies ([`SlaveSlot`]): as a value, the `Slave` and
/// the moves of it took 24 KB of stack at start-up (`scripts/fw-footprint.py`). A function
/// of its own, not inlined, for the FoE files' frame.
#[inline(never)]
fn start_stack(slot: &'static mut StackSlot, mut esc: Esc, flash: pac::FLASH) -> Result<(), ()> {
    // The definition checked when the image is built (`check_def` is not in the image).
    let def = const { CheckedDef::new(&IMAGE_DEF) };
    let slave = slot.start_checked(def, &mut esc).map_err(|_| ())?;
    let app = WithFoe {
        app: Hooks(FwCs),
        files: FirmwareUpdate::new(FlashStore::new(flash), oxicat_devices::tue_es030::UPDATE),
    };
    // SAFETY: once, before any ESC interrupt is unmasked (main enables them afterwards).
    unsafe { ESC.init(EscSide { slave, esc, app }) };
    Ok(())
}

/// Builds the firmware into [`FW`], in a frame of its own as [`start_stack`].
#[inline(never)]
fn start_firmware(board: TueBoard) {
    let fw = TuEs030::new(board);
    irq::free(|cs| *FW.borrow(cs).borrow_mut() = Some(fw));
}

#[entry]
fn main() -> ! {
    // cortex-m-rt hands `main` this as a `&'static mut` (one per program).
    static mut SLOT: StackSlot = SlaveSlot::new();
    let dp = pac::Peripherals::take().unwrap();
    let cp = cortex_m::Peripherals::take().unwrap();
    // 8 MHz HSE -> 180 MHz SYSCLK; APB1 45 MHz (its timers 90 MHz), APB2 90 MHz (TIM1 and
    let clocks = clocks_180mhz(dp.RCC);
    let mut delay = cp.SYST.delay(&clocks);
    // Keep the debug port alive through WFI (probe-rs attach while running).
    dp.DBGMCU.cr().modify(|_, w| w.dbg_sleep().set_bit());

    let gpioa = dp.GPIOA.split();
    let gpiob = dp.GPIOB.split();
    let gpioc = dp.GPIOC.split();
    let gpiod = dp.GPIOD.split();
    let gpioe = dp.GPIOE.split();

    // Driver enables first, low (tristate) before TIM1/TIM8 drive anything.
    let _en1 = gpioc.pc10.into_push_pull_output_in_state(false.into());
    let _en2 = gpioc.pc11.into_push_pull_output_in_state(false.into());
    let _en3 = gpioc.pc12.into_push_pull_output_in_state(false.into());
    // Bridges: M1 PA8/PA9 (TIM1_CH1/CH2, AF1), M2 PE13/PE14 (TIM1_CH3/CH4, AF1), M3
    // PC8/PC9 (TIM8_CH3/CH4, AF3).
    let _m1a = gpioa.pa8.into_alternate::<1>();
    let _m1b = gpioa.pa9.into_alternate::<1>();
    let _m2a = gpioe.pe13.into_alternate::<1>();
    let _m2b = gpioe.pe14.into_alternate::<1>();
    let _m3a = gpioc.pc8.into_alternate::<3>();
    let _m3b = gpioc.pc9.into_alternate::<3>();
    // Encoders: M1 PA0/PA1 (TIM2, AF1), M2 PC6/PC7 (TIM3, AF2), M3 PD12/PD13 (TIM4, AF2).
    let _e1a = gpioa.pa0.into_alternate::<1>();
    let _e1b = gpioa.pa1.into_alternate::<1>();
    let _e2a = gpioc.pc6.into_alternate::<2>();
    let _e2b = gpioc.pc7.into_alternate::<2>();
    let _e3a = gpiod.pd12.into_alternate::<2>();
    let _e3b = gpiod.pd13.into_alternate::<2>();
    // Analog: PC0..PC2 the three current-sense outputs, PC3 the line-voltage divider, PC4
    // the 5 V reference's.
    let _i1 = gpioc.pc0.into_analog();
    let _i2 = gpioc.pc1.into_analog();
    let _i3 = gpioc.pc2.into_analog();
    let _line = gpioc.pc3.into_analog();
    // PC4: the 5 V reference through its 1:2 divider.
    let _vref5 = gpioc.pc4.into_analog();
    // DRV8412 FAULT#/OTW# (open drain): PB12..PB15 with pull-ups; digital inputs PD0..PD3
    // (pull-downs), outputs PD4..PD7, FRUN LED PD14.
    let _flt1 = gpiob.pb12.into_pull_up_input();
    let _otw1 = gpiob.pb13.into_pull_up_input();
    let _flt23 = gpiob.pb14.into_pull_up_input();
    let _otw23 = gpiob.pb15.into_pull_up_input();
    let _di0 = gpiod.pd0.into_pull_down_input();
    let _di1 = gpiod.pd1.into_pull_down_input();
    let _di2 = gpiod.pd2.into_pull_down_input();
    let _di3 = gpiod.pd3.into_pull_down_input();
    let _do0 = gpiod.pd4.into_push_pull_output();
    let _do1 = gpiod.pd5.into_push_pull_output();
    let _do2 = gpiod.pd6.into_push_pull_output();
    let _do3 = gpiod.pd7.into_push_pull_output();
    let mut frun = gpiod.pd14.into_push_pull_output();

    let board = TueBoard::new(
        dp.TIM1,
        dp.TIM8,
        dp.TIM2,
        dp.TIM3,
        dp.TIM4,
        dp.TIM5,
        dp.ADC1,
        clocks.timclk2().raw(),
    );

    // LAN9252 on SPI1: SCK PA5, MISO PA6, MOSI PA7, mode 0, 90 MHz / 4 = 22.5 MHz; CS PB6.
    let spi = esc_spi1(
        dp.SPI1,
        (gpioa.pa5, gpioa.pa6, gpioa.pa7),
        gpiob.pb6,
        22500.kHz(),
        &clocks,
    );
    // The lines go to EXTI below, not to the driver.
    let mut esc = Lan9252::new(spi, oxicat_pdi::NoLines, Lan9252Config::default());
    // The LAN9252 needs ~ 30 ms after power-on before the SPI answers.
    delay.delay_ms(50);
    if esc.init().is_err() {
        fail(&mut frun, &mut delay);
    }
    if start_stack(SLOT, esc, dp.FLASH).is_err() {
        fail(&mut frun, &mut delay);
    }
    // The firmware brakes the three motors (50/50, drivers enabled) as it starts.
    start_firmware(board);

    // ESC lines on EXTI: IRQ PA10 falling (open drain, active low: pull-up), SYNC0 PB3 and
    // SYNC1 PB5 rising (push-pull, active high).
    let mut syscfg = dp.SYSCFG.constrain();
    let mut exti = dp.EXTI;
    let lines = esc_exti(
        gpioa.pa10,
        gpiob.pb3,
        Some(gpiob.pb5),
        &mut syscfg,
        &mut exti,
    );

    // SAFETY: priorities are set before unmasking; the shared state is initialised. The
    // ADC line may be pending from the sequences since TIM1 started: unpended first.
    unsafe {
        let mut nvic = cp.NVIC;
        nvic.set_priority(Interrupt::ADC, PRIO_CURRENT_LOOP);
        for i in [Interrupt::EXTI3, Interrupt::EXTI9_5, Interrupt::EXTI15_10] {
            nvic.set_priority(i, PRIO_ESC);
        }
        (*pac::ADC1::ptr()).sr().write(|w| w.bits(!(1 << 2)));
        NVIC::unpend(Interrupt::ADC);
        NVIC::unmask(Interrupt::ADC);
        NVIC::unmask(Interrupt::EXTI3);
        NVIC::unmask(Interrupt::EXTI9_5);
        NVIC::unmask(Interrupt::EXTI15_10);
    }

    let mut last_poll = TICKS.load(Ordering::Relaxed);
    let mut last_irq_kick = last_poll;
    loop {
        let now = TICKS.load(Ordering::Relaxed);
        if now.wrapping_sub(last_poll) >= POLL_EVERY_TICKS {
            last_poll = now;
            with_esc_from_thread(|e| {
                // The service routine runs in the ADC interrupt, not on the stack's
                // SERVICE_TIMER: its dictionary side (0x8040) is stored here, at 1 kHz —
                // before the poll, so an SDO upload the poll serves reads this tick's
                // values (after it, the first upload after PREOP could read 0x8040 before
                // it was ever stored: the emulator test saw 0 V when the start-up timing
                // moved).
                e.app.app.store_voltages(e.slave.od_mut());
                let _ = e.slave.poll(&mut e.esc, &mut e.app);
            });
        }
        // The IRQ line is a level: a cause that arrives while it is still low from another
        // gives no new falling edge. Re-run the handler while the line stays low, once per
        // current-loop tick (a cause only `poll` clears would otherwise make this spin).
        if lines.irq.is_low() && now != last_irq_kick {
            last_irq_kick = now;
            NVIC::pend(Interrupt::EXTI15_10);
        }
        // Every event is an interrupt (the current loop at least every 50 µs): sleep.
        cortex_m::asm::wfi();
    }
}

// Panics and hard faults make the outputs safe, then halt.
halt_on_fault!(board::bridges_emergency_off);
