//! The demo device (thesis Table 2-2) on the oxicat slave stack, on an STM32F446
//! (Nucleo-F446RE) with a LAN9252 EtherCAT slave controller on SPI1, reached through
//! `oxicat_pdi::Lan9252`. Wiring and flashing: README.md.
//!
//! Main loop as on the seeds' boards: the LAN9252 IRQ (active low, open drain), SYNC0 and
//! SYNC1 pins are polled; SYNC0/SYNC1 act on their rising edge, the IRQ while asserted;
//! `poll` runs the ESM and the mailbox every pass.
//!
//! The independent watchdog runs from boot with a 200 ms timeout and is fed once per pass
//! of the main loop (every handler runs from it): a firmware that hangs is reset into INIT.
//! After such a reset (RCC_CSR.IWDGRSTF) the image reports it to the master with a CoE
//! emergency 0x6010 once its mailbox runs (PREOP). The hang jumper (PC0 to GND, pull-up on)
//! makes the image hang in OP on purpose, to try that path on a bench or in the emulator.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use embedded_hal::digital::InputPin;
use oxicat_board_support::{clocks_180mhz, esc_spi1, EscSpi};
use oxicat_devices::demo::{self, Buttons, Demo, Leds};
use oxicat_pdi::{Lan9252, Lan9252Config, Pins};
use oxicat_slave::{AlState, CheckedDef, DeviceDef, Pdi, SlaveSlot};
use panic_halt as _;
use stm32f4xx_hal::{
    gpio::{Input, Output, Pin},
    pac,
    prelude::*,
    watchdog::IndependentWatchdog,
};

/// Mailbox buffer size of the stack: the demo's mailboxes are 128 bytes.
const MBX: usize = 128;

/// Copy steps per direction of the stack's compiled PDO mappings: what the demo device's
/// fixed mapping compiles to (13 outputs, 5 inputs; the default of 64 would be 1 KB of RAM).
const MAP: usize = oxicat_slave::pdo::map_steps(&demo::DEF);

/// The ESC: the LAN9252 on SPI1, IRQ on PA10, SYNC0 on PB3, SYNC1 on PB5.
type Esc = Lan9252<EscSpi, Pins<Pin<'A', 10, Input>, Pin<'B', 3, Input>, Pin<'B', 5, Input>>>;

/// The demo device as the image links it: the stack's part of `demo::DEF`, without the
/// texts only its ESI and SII carry (vendor, group, description, DC mode names).
static DEF: DeviceDef = demo::DEF.for_image();

/// IWDG timeout: a hang resets the MCU this long after the last feed (at the LSI's nominal
/// 32 kHz; the LSI's 17–47 kHz spread makes it 136..376 ms on a given part).
const WATCHDOG_MS: u32 = 200;

/// CoE emergency error code after a watchdog reset (CiA 301: "software reset (watchdog)").
const EMCY_WATCHDOG_RESET: u16 = 0x6010;

/// LD2-style indicator LEDs on PC8 (blue) and PC9 (red), active high.
struct BoardLeds {
    blue: Pin<'C', 8, Output>,
    red: Pin<'C', 9, Output>,
}

impl Leds for BoardLeds {
    fn set(&mut self, blue: bool, red: bool) {
        self.blue.set_state(blue.into());
        self.red.set_state(red.into());
    }
}

/// The user button B1 (PC13, active low) as button 1.
struct BoardButtons<P: InputPin>(P);

impl<P: InputPin> Buttons for BoardButtons<P> {
    fn read(&mut self) -> u8 {
        u8::from(self.0.is_low().unwrap_or(false))
    }
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

#[entry]
fn main() -> ! {
    // The stack's state, built in place in `.bss` (cortex-m-rt hands `main` a `&'static
    // mut`): no `Slave` value in `main`'s frame and no copy of one.
    static mut SLOT: SlaveSlot<Esc, { demo::IMAGE }, MBX, MAP> = SlaveSlot::new();
    let dp = pac::Peripherals::take().unwrap();
    let cp = cortex_m::Peripherals::take().unwrap();
    // Why the MCU (re)started: RCC_CSR's reset flags, cleared (RMVF) for the next reset.
    let csr = dp.RCC.csr().read();
    let (reset_flags, watchdog_reset) = (csr.bits(), csr.wdgrstf().bit_is_set()); // IWDGRSTF
    dp.RCC.csr().modify(|_, w| w.rmvf().set_bit());
    // The watchdog from here on: /256 and RLR 24, 25 LSI ticks of 8 ms. Start counts down
    // from 0xFFF (RM0390 §20.3.1: 32.8 s), the first feed below loads the 200 ms.
    let mut watchdog = IndependentWatchdog::new(dp.IWDG);
    watchdog.start(WATCHDOG_MS.millis());
    let clocks = clocks_180mhz(dp.RCC);
    let mut delay = cp.SYST.delay(&clocks);

    let gpioa = dp.GPIOA.split();
    let gpiob = dp.GPIOB.split();
    let gpioc = dp.GPIOC.split();

    let mut leds = BoardLeds {
        blue: gpioc.pc8.into_push_pull_output(),
        red: gpioc.pc9.into_push_pull_output(),
    };
    let buttons = BoardButtons(gpioc.pc13.into_floating_input());
    // The hang jumper: PC0 (A5: CN8-6, CN7-38) pulled to GND makes the image hang in OP.
    let hang = gpioc.pc0.into_pull_up_input();

    // SPI1: SCK PA5, MISO PA6, MOSI PA7, mode 0 (the LAN9252 also accepts mode 3),
    // 90 MHz / 4 = 22.5 MHz (the LAN9252's read 0x03 allows up to 30 MHz).
    let spi = esc_spi1(
        dp.SPI1,
        (gpioa.pa5, gpioa.pa6, gpioa.pa7),
        gpiob.pb6,
        22500.kHz(),
        &clocks,
    );

    // IRQ PA10 (open drain, active low: pull-up), SYNC0 PB3, SYNC1 PB5 (push-pull).
    let pins = Pins {
        irq: gpioa.pa10.into_pull_up_input(),
        sync0: gpiob.pb3.into_floating_input(),
        sync1: gpiob.pb5.into_floating_input(),
        irq_active_low: true,
        sync_active_low: false,
    };
    let mut esc = Lan9252::new(spi, pins, Lan9252Config::default());
    // The LAN9252 needs ~ 30 ms after power-on before the SPI answers; init's BYTE_TEST
    // polling covers the rest.
    delay.delay_ms(50);
    // From here a hang resets the MCU within 200 ms (an ESC that does not answer too:
    // `fail` does not feed, so the image retries the chip every ~250 ms).
    watchdog.feed();
    if esc.init().is_err() {
        fail(&mut leds, &mut delay);
    }

    let mut app = Demo::new(leds, buttons);
    // The definition checked when the image is built (`check_def` is not in the image).
    let slave = match SLOT.start_checked(const { CheckedDef::new(&DEF) }, &mut esc) {
        Ok(s) => s,
        Err(_) => fail(&mut app.leds, &mut delay),
    };

    let (mut sync0_was, mut sync1_was) = (false, false);
    let mut report_reset = watchdog_reset;
    loop {
        watchdog.feed();
        if slave.state() == AlState::Op && hang.is_low() {
            // On purpose: no more ESC access, no more feeding; the IWDG resets the MCU.
            #[allow(clippy::empty_loop)]
            loop {}
        }
        let lines = esc.irq_lines();
        if lines.pdi_irq {
            let _ = slave.on_pdi_irq(&mut esc, &mut app);
        }
        if lines.sync0 && !sync0_was {
            let _ = slave.on_sync0(&mut esc, &mut app);
        }
        if lines.sync1 && !sync1_was {
            let _ = slave.on_sync1(&mut esc, &mut app);
        }
        sync0_was = lines.sync0;
        sync1_was = lines.sync1;
        let _ = slave.poll(&mut esc, &mut app);
        // Queued once the mailbox runs (PREOP and up); the data carry RCC_CSR's reset
        // flags (bits 31..24). The error register stays 0: the fault is past.
        if report_reset {
            let data = [(reset_flags >> 24) as u8, 0, 0, 0, 0];
            report_reset = !slave.emergency(EMCY_WATCHDOG_RESET, 0, data);
        }
    }
}
