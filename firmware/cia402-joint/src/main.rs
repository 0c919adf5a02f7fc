//! The CiA402 joint drive (`oxicat_devices::cia402::Cia402Drive`, the same application the
//! virtual segment hosts in `cia402::rig`) on the oxicat slave stack, on an STM32F446 with
//! an ET1100 on SPI1, a three-phase bridge on TIM1, an incremental encoder with index on
//! TIM2, phase currents, joint torque and bus voltage on ADC1. This file and its modules
//! are board glue only. Wiring, pin map, priorities: README.md.
//!
//! What runs where (the rig's table, on interrupts):
//!
//! | event | handler | priority | runs |
//! |---|---|---|---|
//! | ADC1 injected sequence done, 20 kHz (TIM1 PWM centre) | `ADC` | 0x10 | `CurrentLoop::step` on the [`board::Bridge`] (currents → i_q, PI, SVPWM) |
//! | SYNC0 rising (PB3) | `EXTI3` | 0x20 | `Slave::on_sync0` (outputs, application cycle: `run_cycle`, inputs) |
//! | SYNC1 rising (PB5) | `EXTI9_5` | 0x20 | `Slave::on_sync1` |
//! | PDI IRQ falling (PA10) | `EXTI15_10` | 0x20 | `Slave::on_pdi_irq` |
//! | every 20th current-loop tick (1 ms) | thread | — | `Slave::poll` (ESM, mailbox, emergencies; free run: the cycle), LEDs, then WFI |
//!
//! Sharing, by priority: the stack, the ESC driver and the drive (with the joint's
//! [`board::Sensors`]) are used only at priority 0x20 — the three ESC handlers, which
//! cannot preempt one another — and by the thread with BASEPRI raised to 0x20
//! ([`with_esc_from_thread`]), so their SPI transactions never interleave and never hold
//! off the current loop. The current loop and the [`board::Bridge`] belong to the `ADC`
//! interrupt alone. The two sides share only [`HANDOVER`]: the drive's current command
//! and the loop's feedback, a few words copied in a critical section at each end
//! ([`DriveHooks`] around every hook, the `ADC` handler around every tick).
#![no_std]
#![no_main]

mod board;
mod foc;

use core::cell::Cell;
use core::sync::atomic::{AtomicU32, Ordering};

use board::{BoardLeds, Bridge, Motor, Sensors};
use cortex_m::interrupt::{self as irq, Mutex};
use cortex_m::peripheral::NVIC;
use cortex_m_rt::entry;
use oxicat_board_support::{
    clear_exti, clocks_180mhz, esc_exti, esc_spi1, halt_on_fault, with_basepri, EscSpi, PrioCell,
};
use oxicat_devices::cia402::{
    device, Cia402Drive, CurrentCommand, CurrentFeedback, CurrentLoop, DriveParams, CURRENT_LOOP_HZ,
};
use oxicat_pdi::{Et1100Config, Et1100Spi};
use oxicat_slave::{AlState, AlStatusCode, Application, CheckedDef, Od, Slave, SlaveSlot};
use stm32f4xx_hal::{
    pac::{self, interrupt, Interrupt},
    prelude::*,
};

/// Mailbox buffer size of the stack: the drive's mailboxes are 128 bytes.
const MBX: usize = 128;
/// Copy steps per direction of the stack's compiled PDO mappings, sized to the device
/// (`pdo::map_steps`: 31, the entries of one configurable PDO; the default of 64 would be
/// 528 B more RAM, 2 × 33 × 8).
const MAP: usize = oxicat_slave::pdo::map_steps(&device::DEF);

/// The device's definition as the image links it: without the ESI/SII description
/// (`DeviceDef::for_image`), which the stack does not read.
static IMAGE_DEF: oxicat_slave::DeviceDef = device::DEF.for_image();
/// The main loop polls the stack every 20 current-loop ticks (1 ms). In free run that is
/// also the application cycle, which matches the cycle the drive assumes when 0x1C32:02
/// does not say (`DriveParams::cycle_s`, 1 ms).
const POLL_EVERY_TICKS: u32 = CURRENT_LOOP_HZ / 1000;
/// Start-up: how long to wait for the ET1100's EEPROM_LOADED \[ms\].
const EEPROM_WAIT_MS: u32 = 1000;

/// NVIC priorities (upper nibble: the F446 implements 4 bits; lower = more urgent).
const PRIO_CURRENT_LOOP: u8 = 0x10;
/// SYNC0, SYNC1 and the PDI IRQ share one level so they never preempt one another.
const PRIO_ESC: u8 = 0x20;

type Esc = Et1100Spi<EscSpi>;
type JointSlave = Slave<Esc, { device::IMAGE }, MBX, MAP>;
/// Where [`JointSlave`] is built in place: `main`'s `static mut`, all zero in `.bss` until
/// [`start_stack`] starts it (no `Slave` value on the stack, no copy of one).
type StackSlot = SlaveSlot<Esc, { device::IMAGE }, MBX, MAP>;
type Drive = Cia402Drive<Sensors>;

/// The stack, its ESC driver and the drive (the application the stack's hooks call).
struct EscSide {
    /// The stack, built in place in `main`'s [`StackSlot`] (`.bss`).
    slave: &'static mut JointSlave,
    esc: Esc,
    drive: Drive,
}

/// The current loop on its power stage.
struct LoopSide {
    current: CurrentLoop,
    bridge: Bridge,
}

/// The ESC side, at priority [`PRIO_ESC`].
static ESC: PrioCell<EscSide> = PrioCell::uninit();
/// The current loop, the `ADC` handler's alone.
static LOOP: PrioCell<LoopSide> = PrioCell::uninit();
/// Current-loop ticks since start (the main loop's poll schedule and LED clock).
static TICKS: AtomicU32 = AtomicU32::new(0);

/// What the drive's hooks and the current loop share: the command the drive last left
/// and the loop's feedback since the drive last took it. Each side copies its part in or
/// out in a critical section of a few words; neither side's computation is inside one,
/// so the current loop is held off for a copy, never for a drive cycle.
struct Handover {
    cmd: Mutex<Cell<CurrentCommand>>,
    fb: Mutex<Cell<CurrentFeedback>>,
}

impl Handover {
    /// The drive's command (the `ADC` handler, before its tick).
    fn command(&self) -> CurrentCommand {
        irq::free(|cs| self.cmd.borrow(cs).get())
    }

    /// Stores the drive's command (a hook, after the drive ran).
    fn put_command(&self, c: CurrentCommand) {
        irq::free(|cs| self.cmd.borrow(cs).set(c));
    }

    /// Adds a tick's feedback: its current replaces the last, an over-current is kept
    /// until taken (the `ADC` handler, after its tick).
    fn publish(&self, f: CurrentFeedback) {
        irq::free(|cs| {
            let cell = self.fb.borrow(cs);
            let old = cell.get();
            cell.set(CurrentFeedback {
                iq: f.iq,
                overcurrent: old.overcurrent || f.overcurrent,
            });
        });
    }

    /// The feedback since the last take; clears the over-current (a hook, before the
    /// drive runs).
    fn take_feedback(&self) -> CurrentFeedback {
        irq::free(|cs| {
            let cell = self.fb.borrow(cs);
            let f = cell.get();
            cell.set(CurrentFeedback {
                overcurrent: false,
                ..f
            });
            f
        })
    }
}

/// The command and feedback between the drive's hooks and the current loop.
static HANDOVER: Handover = Handover {
    cmd: Mutex::new(Cell::new(CurrentCommand {
        power: false,
        iq_ref: 0.0,
        kp: device::gains::CURRENT_KP,
        ki: device::gains::CURRENT_KI,
    })),
    fb: Mutex::new(Cell::new(CurrentFeedback {
        iq: 0.0,
        overcurrent: false,
    })),
};

/// Runs `f` on the stack from the thread, with the ESC handlers masked (BASEPRI) and the
/// current loop still running.
fn with_esc_from_thread<R>(f: impl FnOnce(&mut EscSide) -> R) -> R {
    // SAFETY: BASEPRI masks every ESC handler; `main` stored the ESC side first.
    with_basepri(PRIO_ESC, || f(unsafe { ESC.get() }))
}

/// The application as the stack sees it: every hook runs the drive (at the ESC priority,
/// the current loop running) between a take of the current loop's feedback and a
/// hand-over of the drive's current command ([`HANDOVER`]).
/// (`foe` keeps the default `None`: the drive has no FoE files.)
struct DriveHooks<'a>(&'a mut Drive);

impl DriveHooks<'_> {
    /// Runs `f` on the drive with the current loop's latest feedback, then hands the
    /// command over.
    fn with<R>(&mut self, f: impl FnOnce(&mut Drive) -> R) -> R {
        self.0.current_feedback(HANDOVER.take_feedback());
        let r = f(self.0);
        HANDOVER.put_command(self.0.current_command());
        r
    }
}

impl<const N: usize> Application<N> for DriveHooks<'_> {
    fn state_change(
        &mut self,
        from: AlState,
        to: AlState,
        od: &mut Od<N>,
    ) -> Result<(), AlStatusCode> {
        self.with(|d| d.state_change(from, to, od))
    }

    fn safe_outputs(&mut self, od: &mut Od<N>) {
        self.with(|d| Application::<N>::safe_outputs(d, od))
    }

    fn cycle(&mut self, od: &mut Od<N>) {
        self.with(|d| Application::<N>::cycle(d, od))
    }

    fn timer(&mut self, id: u8, od: &mut Od<N>) {
        self.with(|d| Application::<N>::timer(d, id, od))
    }

    fn sdo_written(&mut self, index: u16, sub: u8, od: &mut Od<N>) {
        self.with(|d| Application::<N>::sdo_written(d, index, sub, od))
    }

    fn next_emergency(&mut self) -> Option<(u16, u8, [u8; 5])> {
        self.with(Application::<N>::next_emergency)
    }
}

/// 20 kHz current loop: ADC1's injected sequence (triggered by TIM1 at the PWM centre)
/// is done; the drive's command in, currents → i_q → PI → duties for the next PWM
/// period, the feedback out.
#[interrupt]
fn ADC() {
    // SAFETY: the ADC handler, LOOP's only user; main stored it before unmasking ADC.
    let l = unsafe { LOOP.get() };
    l.bridge.ack_conversion();
    l.current.set_command(HANDOVER.command());
    l.current.step(&mut l.bridge);
    HANDOVER.publish(l.current.take_feedback());
    TICKS.fetch_add(1, Ordering::Relaxed);
}

/// SYNC0: the application cycle (outputs, `run_cycle`, inputs).
#[interrupt]
fn EXTI3() {
    clear_exti(3);
    // SAFETY: ESC handler at PRIO_ESC.
    let e = unsafe { ESC.get() };
    let _ = e.slave.on_sync0(&mut e.esc, &mut DriveHooks(&mut e.drive));
}

/// SYNC1 (PB5, the only line enabled in 5..9).
#[interrupt]
fn EXTI9_5() {
    clear_exti(5);
    // SAFETY: ESC handler at PRIO_ESC.
    let e = unsafe { ESC.get() };
    let _ = e.slave.on_sync1(&mut e.esc, &mut DriveHooks(&mut e.drive));
}

/// PDI IRQ (PA10, the only line enabled in 10..15).
#[interrupt]
fn EXTI15_10() {
    clear_exti(10);
    // SAFETY: ESC handler at PRIO_ESC.
    let e = unsafe { ESC.get() };
    let _ = e
        .slave
        .on_pdi_irq(&mut e.esc, &mut DriveHooks(&mut e.drive));
}

/// Blinks ERR forever: the ESC did not come up at start-up.
fn fail(leds: &mut BoardLeds, delay: &mut impl embedded_hal::delay::DelayNs) -> ! {
    board::bridge_emergency_off();
    loop {
        leds.set(false, true);
        delay.delay_ms(100);
        leds.set(false, false);
        delay.delay_ms(100);
    }
}

/// ETG.1300 RUN indicator from the AL state at `ms`: off (INIT), blinking 2.5 Hz (PREOP),
/// single flash 200 ms per 1.2 s (SAFEOP), on (OP); BOOT flickers.
fn run_led(state: AlState, ms: u32) -> bool {
    match state {
        AlState::Init => false,
        AlState::PreOp => (ms / 200).is_multiple_of(2),
        AlState::SafeOp => ms % 1200 < 200,
        AlState::Op => true,
        AlState::Boot => (ms / 50).is_multiple_of(2),
    }
}

/// Starts the slave stack on the ET1100 in `slot` and stores it with the driver and the
/// drive on `sensors` in [`ESC`]. The stack is built where it lies ([`SlaveSlot`]); a
/// function of its own, not inlined: the drive and its move live in this frame, gone when
/// it returns (built in `main`, which never returns, the stack and the drive held about
/// 22 KB of stack for good under every interrupt; `sub sp` in `main` was 22,144 B).
#[inline(never)]
fn start_stack(
    slot: &'static mut StackSlot,
    mut esc: Esc,
    sensors: Sensors,
    params: DriveParams,
) -> Result<(), ()> {
    // The definition checked when the image is built (`check_def` is not in the image).
    let def = const { CheckedDef::new(&IMAGE_DEF) };
    let slave = slot.start_checked(def, &mut esc).map_err(|_| ())?;
    let drive = Cia402Drive::new(sensors, params);
    HANDOVER.put_command(drive.current_command());
    // SAFETY: once, before any ESC interrupt is unmasked (main enables them afterwards).
    unsafe { ESC.init(EscSide { slave, esc, drive }) };
    Ok(())
}

/// Stores the current loop on `bridge` in [`LOOP`], in a frame of its own as
/// [`start_stack`].
#[inline(never)]
fn start_current_loop(bridge: Bridge, params: &DriveParams) {
    // SAFETY: once, before the ADC interrupt is unmasked (main enables it afterwards).
    unsafe {
        LOOP.init(LoopSide {
            current: CurrentLoop::new(params),
            bridge,
        })
    };
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
        run: gpioc.pc8.into_push_pull_output(),
        err: gpioc.pc9.into_push_pull_output(),
    };

    // Bridge first, disabled: enable line PC11 low before TIM1 drives anything. PWM
    // phase a PA8 (TIM1_CH1), b PA9 (TIM1_CH2), c PB15 (TIM1_CH3N), all AF1.
    let bridge_enable = gpioc.pc11.into_push_pull_output_in_state(false.into());
    let _pwm_a = gpioa.pa8.into_alternate::<1>();
    let _pwm_b = gpioa.pa9.into_alternate::<1>();
    let _pwm_c = gpiob.pb15.into_alternate::<1>();
    // Encoder A/B PA0/PA1 (TIM2_CH1/CH2), index PB10 (TIM2_CH3), AF1.
    let _enc_a = gpioa.pa0.into_alternate::<1>();
    let _enc_b = gpioa.pa1.into_alternate::<1>();
    let _enc_z = gpiob.pb10.into_alternate::<1>();
    // Analog inputs: PC0 i_a, PC1 i_b, PC2 joint torque, PC3 bus voltage.
    let _ia = gpioc.pc0.into_analog();
    let _ib = gpioc.pc1.into_analog();
    let _torque = gpioc.pc2.into_analog();
    let _vbus = gpioc.pc3.into_analog();
    let home = gpioc.pc10.into_pull_up_input();

    let params = DriveParams::default();
    let (mut bridge, sensors) = board::setup(
        dp.TIM1,
        dp.TIM2,
        dp.ADC1,
        home,
        bridge_enable,
        clocks.timclk2().raw(),
        Motor {
            counts_per_rev: params.counts_per_rev,
            pole_pairs: params.pole_pairs,
            bus_voltage: params.bus_voltage,
        },
    );
    // Current-sense offsets with the bridge off, then the rotor's electrical zero.
    let _ = bridge.calibrate();
    bridge.align(&mut delay);

    // ET1100 on SPI1: SCK PA5, MISO PA6, MOSI PA7, mode 0 (PDI config 0x0150 = 0x00 in
    // the drive's SII), 90 MHz / 8 = 11.25 MHz; CS PB6.
    let spi = esc_spi1(
        dp.SPI1,
        (gpioa.pa5, gpioa.pa6, gpioa.pa7),
        gpiob.pb6,
        11250.kHz(),
        &clocks,
    );
    // The lines go to EXTI below, not to the driver.
    let mut esc = Et1100Spi::new(spi, oxicat_pdi::NoLines, Et1100Config::default());
    // EEPROM_LOADED (PB4): the ET1100 configures its PDI from the SII first.
    let mut eeprom_loaded = gpiob.pb4.into_pull_down_input();
    for _ in 0..EEPROM_WAIT_MS {
        if eeprom_loaded.is_high() {
            break;
        }
        delay.delay_ms(1);
    }
    if esc.init(&mut eeprom_loaded).is_err() {
        fail(&mut leds, &mut delay);
    }
    if start_stack(SLOT, esc, sensors, params).is_err() {
        fail(&mut leds, &mut delay);
    }
    start_current_loop(bridge, &params);

    // ESC lines on EXTI: SPI_IRQ PA10 falling (active low; pull-up for an open-drain
    // configuration), SYNC0 PB3 and SYNC1 PB5 rising (push-pull, active high).
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
    // ADC line may be pending from the calibration's conversions: unpended first.
    unsafe {
        let mut nvic = cp.NVIC;
        nvic.set_priority(Interrupt::ADC, PRIO_CURRENT_LOOP);
        for i in [Interrupt::EXTI3, Interrupt::EXTI9_5, Interrupt::EXTI15_10] {
            nvic.set_priority(i, PRIO_ESC);
        }
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
            let (state, err) = with_esc_from_thread(|e| {
                let _ = e.slave.poll(&mut e.esc, &mut DriveHooks(&mut e.drive));
                (e.slave.state(), e.slave.error_indicated())
            });
            let ms = now / (CURRENT_LOOP_HZ / 1000);
            leds.set(run_led(state, ms), err);
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
halt_on_fault!(board::bridge_emergency_off);
