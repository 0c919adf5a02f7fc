//! The Laelaps II leg node (`oxicat_devices::laelaps::LegNode`, the same application the
//! virtual segment hosts in `laelaps::rig`) on the oxicat slave stack, on an STM32F446 with a
//! LAN9252 on SPI1, two motor amplifiers on TIM1 and two incremental encoders on TIM2/TIM3.
//! This file and its modules are board glue only. Wiring, pin map, priorities: README.md.
//!
//! What runs where (as the rig's table, on interrupts):
//!
//! | event | handler | priority | runs |
//! |---|---|---|---|
//! | TIM6 update, 10 kHz | `TIM6_DAC` | 0x10 | `LegNode::joint_loop` (encoders, two PIV loops, PWM) |
//! | SYNC0 rising (PB3) | `EXTI3` | 0x20 | `Slave::on_sync0` (outputs, application cycle: trajectory + IK, inputs) |
//! | SYNC1 rising (PB5) | `EXTI9_5` | 0x20 | `Slave::on_sync1` |
//! | PDI IRQ falling (PA10) | `EXTI15_10` | 0x20 | `Slave::on_pdi_irq` |
//! | every 4th joint-loop tick (400 µs) | thread | — | `Slave::poll` (ESM, mailbox; free run: the cycle), then WFI |
//!
//! Sharing: the stack and the ESC driver are used only at priority 0x20 — the three ESC
//! handlers, which cannot preempt one another — and by the thread with BASEPRI raised to
//! 0x20 ([`with_esc_from_thread`]), so their SPI transactions never interleave and never hold
//! off the joint loop. The application is shared between the joint loop and the stack's
//! hooks: it lives in a `cortex_m::interrupt::Mutex`, and every hook the stack calls
//! ([`NodeHooks`]) takes it in a short critical section (the application's own code, no SPI).
#![no_std]
#![no_main]

mod board;
mod qep;

use core::cell::RefCell;
use core::sync::atomic::{AtomicU32, Ordering};

use board::{BoardLeds, BoardPwm};
use cortex_m::interrupt::{self as irq, Mutex};
use cortex_m::peripheral::NVIC;
use cortex_m_rt::entry;
use oxicat_board_support::{
    clear_exti, clocks_180mhz, esc_exti, esc_spi1, halt_on_fault, with_basepri, EscSpi, PrioCell,
};
use oxicat_devices::demo::Leds;
use oxicat_devices::laelaps::{device, CaptureConfig, LegNode, Side};
use oxicat_pdi::{Lan9252, Lan9252Config};
use oxicat_slave::{AlState, AlStatusCode, Application, CheckedDef, Od, Slave, SlaveSlot};
use qep::Encoders;
use stm32f4xx_hal::{
    pac::{self, interrupt, Interrupt},
    prelude::*,
    qei::Qei,
    timer::Event,
};

/// The build's leg side (thesis `LEFT_LEG` / `RIGHT_LEG`; cargo feature `left-leg`).
#[cfg(feature = "left-leg")]
const SIDE: Side = Side::Left;
#[cfg(not(feature = "left-leg"))]
const SIDE: Side = Side::Right;

/// The build's side where tools that load the image can read it (ASCII `L` or `R`, symbol
/// `OXICAT_LEG_SIDE`): oxicat-emu refuses an image on the wrong side's leg, which would
/// drive it against its sign conventions. Read once at start-up, so the link keeps it.
#[no_mangle]
pub static OXICAT_LEG_SIDE: u8 = match SIDE {
    Side::Left => b'L',
    Side::Right => b'R',
};

/// Mailbox buffer size of the stack: the leg node's mailboxes are 128 bytes.
const MBX: usize = 128;
/// Copy steps per direction of the stack's compiled PDO mappings, sized to the device
/// (`pdo::map_steps`: 14 output steps, 5 input steps; both legs have the same PDOs; the
/// default of 64 would be 2 × 50 × 8 = 800 B more RAM).
const MAP: usize = oxicat_slave::pdo::map_steps(&device::LEFT);

/// The device's definition as the image links it: without the ESI/SII description
/// (`DeviceDef::for_image`), which the stack does not read.
static IMAGE_DEF: oxicat_slave::DeviceDef = device::device(SIDE).for_image();

/// Joint-loop rate (`laelaps::hw::CONTROL_PERIOD_S`).
const JOINT_LOOP_HZ: u32 = 10_000;
/// The main loop polls the stack every 4 joint-loop ticks (400 µs), as the rig does
/// (`RigConfig::poll_every`); in free run that is also the application cycle, which
/// matches the leg node's assumed cycle when none is configured (`DEFAULT_CYCLE_NS`).
const POLL_EVERY_TICKS: u32 = 4;

/// NVIC priorities (upper nibble: the F446 implements 4 bits; lower = more urgent).
const PRIO_JOINT_LOOP: u8 = 0x10;
/// SYNC0, SYNC1 and the PDI IRQ share one level so they never preempt one another.
const PRIO_ESC: u8 = 0x20;

type Esc = Lan9252<EscSpi>;
type LegSlave = Slave<Esc, { device::IMAGE }, MBX, MAP>;
/// Where [`LegSlave`] is built in place: `main`'s `static mut`, all zero in `.bss` until
/// [`start_stack`] starts it (no `Slave` value on the stack, no copy of one).
type StackSlot = SlaveSlot<Esc, { device::IMAGE }, MBX, MAP>;
type Node = LegNode<BoardPwm, Encoders, BoardLeds>;

/// The stack and its ESC driver.
struct EscSide {
    /// The stack, built in place in `main`'s [`StackSlot`] (`.bss`).
    slave: &'static mut LegSlave,
    esc: Esc,
}

/// The ESC side, shared by priority rather than by a lock ([`PrioCell::get`]'s contract:
/// the three ESC handlers at [`PRIO_ESC`], the thread through [`with_esc_from_thread`]).
static ESC: PrioCell<EscSide> = PrioCell::uninit();
/// The leg-node application, shared by the joint loop and the stack's hooks.
static NODE: Mutex<RefCell<Option<Node>>> = Mutex::new(RefCell::new(None));
/// Joint-loop ticks since start (the main loop's poll schedule).
static TICKS: AtomicU32 = AtomicU32::new(0);

/// Runs `f` on the application in a critical section.
fn with_node<R>(f: impl FnOnce(&mut Node) -> R) -> R {
    irq::free(|cs| {
        let mut node = NODE.borrow(cs).borrow_mut();
        f(node
            .as_mut()
            .expect("node is set before interrupts are enabled"))
    })
}

/// Runs `f` on the stack from the thread, with the ESC handlers masked (BASEPRI) and the
/// joint loop still running.
fn with_esc_from_thread<R>(f: impl FnOnce(&mut EscSide) -> R) -> R {
    // SAFETY: BASEPRI masks every ESC handler; `main` stored the ESC side first.
    with_basepri(PRIO_ESC, || f(unsafe { ESC.get() }))
}

/// The application as the stack sees it: every hook forwards to the shared [`LegNode`]
/// inside a critical section, so the SPI work of the stack's handlers runs with the joint
/// loop enabled and only the application's own computation excludes it. (`foe` keeps the
/// default `None`: the leg node has no FoE files, and a reference could not leave the
/// critical section anyway.)
struct NodeHooks;

impl<const N: usize> Application<N> for NodeHooks {
    fn state_change(
        &mut self,
        from: AlState,
        to: AlState,
        od: &mut Od<N>,
    ) -> Result<(), AlStatusCode> {
        with_node(|n| n.state_change(from, to, od))
    }

    fn safe_outputs(&mut self, od: &mut Od<N>) {
        with_node(|n| n.safe_outputs(od))
    }

    fn cycle(&mut self, od: &mut Od<N>) {
        with_node(|n| Application::<N>::cycle(n, od))
    }

    fn timer(&mut self, id: u8, od: &mut Od<N>) {
        with_node(|n| n.timer(id, od))
    }

    fn sdo_written(&mut self, index: u16, sub: u8, od: &mut Od<N>) {
        with_node(|n| n.sdo_written(index, sub, od))
    }

    fn next_emergency(&mut self) -> Option<(u16, u8, [u8; 5])> {
        with_node(Application::<N>::next_emergency)
    }
}

/// 10 kHz joint loop: both PIV loops on fresh encoder samples, PWM out.
#[interrupt]
fn TIM6_DAC() {
    // SAFETY: TIM6 SR: clearing UIF (write 0) is this handler's only access after set-up.
    unsafe { (*pac::TIM6::ptr()).sr().write(|w| w.bits(0)) };
    with_node(|n| n.joint_loop());
    TICKS.fetch_add(1, Ordering::Relaxed);
}

/// SYNC0: the application cycle (outputs, trajectory + IK, inputs).
#[interrupt]
fn EXTI3() {
    clear_exti(3);
    // SAFETY: ESC handler at PRIO_ESC.
    let e = unsafe { ESC.get() };
    let _ = e.slave.on_sync0(&mut e.esc, &mut NodeHooks);
}

/// SYNC1 (PB5, the only line enabled in 5..9).
#[interrupt]
fn EXTI9_5() {
    clear_exti(5);
    // SAFETY: ESC handler at PRIO_ESC.
    let e = unsafe { ESC.get() };
    let _ = e.slave.on_sync1(&mut e.esc, &mut NodeHooks);
}

/// PDI IRQ (PA10, the only line enabled in 10..15).
#[interrupt]
fn EXTI15_10() {
    clear_exti(10);
    // SAFETY: ESC handler at PRIO_ESC.
    let e = unsafe { ESC.get() };
    let _ = e.slave.on_pdi_irq(&mut e.esc, &mut NodeHooks);
}

/// Blinks the red LED forever: the ESC did not answer at start-up.
fn fail(leds: &mut BoardLeds, delay: &mut impl embedded_hal::delay::DelayNs) -> ! {
    loop {
        leds.set(false, true);
        delay.delay_ms(100);
        leds.set(false, false);
        delay.delay_ms(100);
    }
}

/// Starts the slave stack on the LAN9252 in `slot` and stores it with the driver in
/// [`ESC`]. The stack is built where it lies ([`SlaveSlot`]): built as a value in `main`,
/// the `Slave` and the moves of it held 21.9 KB of stack for good under every interrupt
/// (the emulator's painted stack, `tools/oxicat-emu`), and still 23.4 KB at start-up in a
/// frame of its own (`scripts/fw-footprint.py`).
#[inline(never)]
fn start_stack(slot: &'static mut StackSlot, mut esc: Esc) -> Result<(), ()> {
    // SAFETY: a plain read of an immutable static; volatile so the link keeps the symbol.
    let _side = unsafe { core::ptr::read_volatile(&OXICAT_LEG_SIDE) };
    // The definition checked when the image is built (`check_def` is not in the image).
    let def = const { CheckedDef::new(&IMAGE_DEF) };
    let slave = slot.start_checked(def, &mut esc).map_err(|_| ())?;
    // The main loop polls with the ESC handlers masked: PREOP -> SAFEOP (compiling both
    // PDO mappings) in one poll held them off for 770 µs, and a SYNC0 edge was lost when
    // two fell into it (issue 15). In three polls each holds them off for a part.
    slave.set_stepwise_safeop(true);
    // SAFETY: once, before any ESC interrupt is unmasked (main enables them afterwards).
    unsafe { ESC.init(EscSide { slave, esc }) };
    Ok(())
}

/// Builds the application into [`NODE`], in a frame of its own for the same reason as
/// [`start_stack`].
#[inline(never)]
fn start_node(pwm: BoardPwm, encoders: Encoders, leds: BoardLeds, capture: CaptureConfig) {
    let node = LegNode::with_capture(SIDE, pwm, encoders, leds, capture);
    irq::free(|cs| *NODE.borrow(cs).borrow_mut() = Some(node));
}

#[entry]
fn main() -> ! {
    // cortex-m-rt hands `main` this as a `&'static mut` (one per program).
    static mut SLOT: StackSlot = SlaveSlot::new();
    let dp = pac::Peripherals::take().unwrap();
    let cp = cortex_m::Peripherals::take().unwrap();
    let clocks = clocks_180mhz(dp.RCC);
    let mut delay = cp.SYST.delay(&clocks);
    // Keep the debug port alive through WFI (probe-rs attach while running).
    dp.DBGMCU.cr().modify(|_, w| w.dbg_sleep().set_bit());

    let gpioa = dp.GPIOA.split();
    let gpiob = dp.GPIOB.split();
    let gpioc = dp.GPIOC.split();

    let mut leds = BoardLeds {
        blue: gpioc.pc8.into_push_pull_output(),
        red: gpioc.pc9.into_push_pull_output(),
    };

    // Amplifiers first, at zero duty: TIM1 20 kHz edge-aligned, CH1 PA8 knee, CH2 PA9 hip;
    // direction PC10 knee, PC11 hip.
    let (timer, (ch1, ch2, ..)) = dp.TIM1.pwm_hz(20.kHz(), &clocks);
    let mut knee = ch1.with(gpioa.pa8);
    let mut hip = ch2.with(gpioa.pa9);
    knee.set_duty(0);
    hip.set_duty(0);
    knee.enable();
    hip.enable();
    let pwm = BoardPwm {
        timer,
        knee,
        hip,
        knee_dir: gpioc.pc10.into_push_pull_output(),
        hip_dir: gpioc.pc11.into_push_pull_output(),
    };

    // Encoders: TIM2 (PA0/PA1, AF1, 32-bit) knee, TIM3 (PC6/PC7, AF2) hip, with their
    // capture timers TIM5 and TIM4 (qep.rs).
    let encoders = Encoders::new(
        Qei::new(dp.TIM2, (gpioa.pa0, gpioa.pa1)),
        Qei::new(dp.TIM3, (gpioc.pc6, gpioc.pc7)),
        dp.TIM5,
        dp.TIM4,
    );
    let capture = qep::capture_config(clocks.timclk1().raw());

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
        fail(&mut leds, &mut delay);
    }
    if start_stack(SLOT, esc).is_err() {
        fail(&mut leds, &mut delay);
    }

    // The application; its encoders are zeroed here (the leg rests in its reset pose at
    // power-on, as on the thesis' boards).
    start_node(pwm, encoders, leds, capture);

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

    // 10 kHz joint-loop timer.
    let mut joint_timer = dp.TIM6.counter_hz(&clocks);
    joint_timer.start(JOINT_LOOP_HZ.Hz()).unwrap();
    joint_timer.listen(Event::Update);

    // SAFETY: priorities are set before unmasking; the shared state is initialised.
    unsafe {
        let mut nvic = cp.NVIC;
        nvic.set_priority(Interrupt::TIM6_DAC, PRIO_JOINT_LOOP);
        for i in [Interrupt::EXTI3, Interrupt::EXTI9_5, Interrupt::EXTI15_10] {
            nvic.set_priority(i, PRIO_ESC);
        }
        NVIC::unmask(Interrupt::TIM6_DAC);
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
                let _ = e.slave.poll(&mut e.esc, &mut NodeHooks);
            });
        }
        // The IRQ line is a level: a cause that arrives while it is still low from another
        // gives no new falling edge. Re-run the handler while the line stays low, once per
        // joint-loop tick (a cause only `poll` clears would otherwise make this spin).
        if lines.irq.is_low() && now != last_irq_kick {
            last_irq_kick = now;
            NVIC::pend(Interrupt::EXTI15_10);
        }
        // Every event is an interrupt (the joint loop at least every 100 µs): sleep.
        cortex_m::asm::wfi();
    }
}

// Panics and hard faults make the outputs safe, then halt.
halt_on_fault!(board::pwm_emergency_off);
