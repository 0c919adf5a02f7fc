//! Unit tests of the hub firmware pieces that need no plant (the 1-Wire bus model and the
//! LED decoder are in `oxicat-plant`; end-to-end tests in `oxicat-sim`).

extern crate std;

use super::codes::*;
use super::onewire::*;
use super::ws2812::*;
use super::*;
use oxicat_esc::{Esc, EscConfig, PdiError};
use oxicat_slave::{IrqLines, Pdi};

#[test]
fn crc8_matches_the_maxim_example() {
    // Maxim AN27 example ROM: family 0x02, serial 00 00 00 01 B8 1C, CRC 0xA2.
    let rom = [0x02, 0x1C, 0xB8, 0x01, 0x00, 0x00, 0x00, 0xA2];
    assert_eq!(crc8(&rom[..7]), 0xA2);
    assert_eq!(crc8(&rom), 0);
}

#[test]
fn resolution_conversion_times_and_masks() {
    assert_eq!(Resolution::from_config(0x7F), Resolution::Bits12);
    assert_eq!(Resolution::from_config(0x1F), Resolution::Bits9);
    assert_eq!(Resolution::Bits9.conversion_us(), 93_750);
    assert_eq!(Resolution::Bits10.conversion_us(), 187_500);
    assert_eq!(Resolution::Bits11.conversion_us(), 375_000);
    assert_eq!(Resolution::Bits12.conversion_us(), 750_000);
    assert_eq!(Resolution::Bits9.raw_mask(), !7);
    assert_eq!(Resolution::Bits12.raw_mask(), -1);
    // +25.0625 °C at 12 bits: 0x0191; at 9 bits the low three bits are undefined.
    let mut sp = [0x91, 0x01, 0x4B, 0x46, 0x7F, 0xFF, 0x0C, 0x10, 0];
    sp[8] = crc8(&sp[..8]);
    assert_eq!(centi_celsius(&sp).0, 2506);
    sp[4] = 0x1F;
    assert_eq!(centi_celsius(&sp).0, 2500);
    // −10.125 °C: 0xFF5E (0.01 °C truncated toward zero).
    let sp = [0x5E, 0xFF, 0, 0, 0x7F, 0, 0, 0, 0];
    assert_eq!(centi_celsius(&sp).0, -1012);
}

#[test]
fn status_word_layout() {
    let w = StatusWord::new(STATUS_SOFT_ERRORS, ERR_TEMP_SENS_LOST, EV_ECAT_APP_OP);
    assert_eq!(w.0 & 0xF, 5);
    assert_eq!((w.0 >> 4) & 0x3FFF, 1102);
    assert_eq!(w.0 >> 18, 2311);
    assert_eq!(
        (w.general(), w.last_error(), w.last_event()),
        (5, 1102, 2311)
    );
}

#[test]
fn event_handler_hard_soft_and_clearing() {
    let mut s = SystemState::default();
    for c in [EV_TEMP_DSM_INIT, EV_LED_DSM_INIT, EV_ECAT_DSM_INIT] {
        s.post(c);
    }
    s.handle_events();
    assert_eq!(s.general(), STATUS_STARTED);
    s.post(EV_ECAT_APP_OP);
    s.handle_events();
    assert_eq!(s.general(), STATUS_NO_ERRORS);
    s.post(ERR_TEMP_SENS_LOST);
    s.handle_events();
    assert!(s.soft() && !s.hard());
    assert_eq!(s.general(), STATUS_SOFT_ERRORS);
    s.post(ERR_TEMP_SENS_OVERHEAT);
    s.handle_events();
    assert!(s.hard());
    assert_eq!(s.active_error(), ERR_TEMP_SENS_OVERHEAT);
    assert_eq!(s.general(), STATUS_HARD_ERRORS);
    s.post(EV_TEMP_OVERHEAT_CLEARED);
    s.handle_events();
    assert!(!s.hard());
    assert_eq!(s.active_error(), ERR_TEMP_SENS_LOST);
    assert_eq!(
        s.word().last_error(),
        ERR_TEMP_SENS_OVERHEAT,
        "history kept"
    );
    s.post(EV_TEMP_SENS_BACK);
    s.handle_events();
    assert_eq!(s.active_error(), ERR_SYS_NONE);
    assert_eq!(s.general(), STATUS_NO_ERRORS);
    assert_eq!(classify(ERR_ECAT_COMM_LOST), Kind::Hard);
    assert_eq!(classify(ERR_ECAT_CMD_SOFTFAULT), Kind::Soft);
    assert_eq!(classify(EV_ECAT_CMD_ACK), Kind::Event);
}

#[test]
fn two_codes_before_the_handler_runs_are_both_handled_and_overflow_is_not_silent() {
    let mut s = SystemState::default();
    s.post(ERR_TEMP_SENS_LOST);
    s.post(ERR_LED_TIMEOUT);
    s.handle_events();
    assert!(s.is_active(ERR_TEMP_SENS_LOST) && s.is_active(ERR_LED_TIMEOUT));
    for _ in 0..QUEUE + 3 {
        s.post(EV_LED_UPTD);
    }
    s.handle_events();
    assert_eq!(s.dropped, 3);
    assert!(s.is_active(ERR_SYS_UNKNOWN));
}

#[test]
fn ws2812_encoding_is_grb_msb_first_with_reset() {
    let t = HUB_TIMING;
    assert_eq!((t.period, t.t0h, t.t1h), (113, 36, 72));
    let mut buf = [0xFFFFu16; 24 + 48];
    let n = encode(&[Rgb::new(0x01, 0x80, 0x00)], &t, &mut buf).unwrap();
    assert_eq!(n, 24 + t.reset_slots as usize);
    // G = 0x80: first bit 1, then seven 0.
    assert_eq!(buf[0], t.t1h);
    assert!(buf[1..8].iter().all(|&d| d == t.t0h));
    // R = 0x01: last bit of the second byte is 1.
    assert_eq!(buf[15], t.t1h);
    assert!(buf[24..n].iter().all(|&d| d == 0));
    assert!(t.ns(t.reset_slots * t.period) > RESET_NS);
    assert!(encode(&[Rgb::default(); 3], &t, &mut buf).is_none());
}

#[test]
fn led_colour_priority() {
    let mut s = SystemState::default();
    assert_eq!(choose(&s, true, None, true), Shown::PreOp);
    for c in [
        EV_TEMP_DSM_INIT,
        EV_LED_DSM_INIT,
        EV_ECAT_DSM_INIT,
        EV_ECAT_APP_OP,
    ] {
        s.post(c);
    }
    s.handle_events();
    assert_eq!(choose(&s, false, None, true), Shown::PreOp);
    assert_eq!(choose(&s, true, None, true), Shown::Normal);
    let c = Rgb::new(1, 2, 3);
    assert_eq!(choose(&s, true, Some(c), true), Shown::Custom(c));
    s.post(ERR_TEMP_SENS_LOST);
    s.handle_events();
    assert_eq!(choose(&s, true, None, true), Shown::Warning);
    s.post(ERR_ECAT_COMM_LOST);
    s.handle_events();
    assert_eq!(choose(&s, true, Some(c), true), Shown::Error);
}

/// An SPI link to an ESC that can be unplugged: every access then fails (the driver's
/// timeout), none hangs.
struct FlakySpi {
    esc: Esc,
    dead: bool,
    accesses: u32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum SpiError {
    Timeout,
    Esc(PdiError),
}

impl Pdi for FlakySpi {
    type Error = SpiError;
    fn read(&mut self, addr: u16, buf: &mut [u8]) -> Result<(), SpiError> {
        self.accesses += 1;
        if self.dead {
            return Err(SpiError::Timeout);
        }
        self.esc.pdi_read(addr, buf).map_err(SpiError::Esc)
    }
    fn write(&mut self, addr: u16, data: &[u8]) -> Result<(), SpiError> {
        self.accesses += 1;
        if self.dead {
            return Err(SpiError::Timeout);
        }
        self.esc.pdi_write(addr, data).map_err(SpiError::Esc)
    }
    fn al_event_request(&mut self) -> Result<u32, SpiError> {
        self.accesses += 1;
        if self.dead {
            return Err(SpiError::Timeout);
        }
        Ok(self.esc.al_event_request())
    }
    fn irq_lines(&mut self) -> IrqLines {
        IrqLines::default()
    }
}

struct NoBus;
impl OneWireBus for NoBus {
    type Error = ();
    fn reset(&mut self) -> Result<bool, ()> {
        Ok(false)
    }
    fn write_bit(&mut self, _: bool) -> Result<(), ()> {
        Ok(())
    }
    fn read_bit(&mut self) -> Result<bool, ()> {
        Ok(true)
    }
}

#[derive(Default)]
struct Dma {
    started: u32,
}
impl LedStrip for Dma {
    type Error = ();
    fn configure(&mut self, _: usize) -> Result<(), ()> {
        Ok(())
    }
    fn restart(&mut self, _: usize) {}
    fn start(&mut self, _: usize, _: &[u16]) -> Result<(), ()> {
        self.started += 1;
        Ok(())
    }
    fn done(&mut self, _: usize) -> bool {
        true
    }
    fn arm_guard(&mut self, _: u32) -> Result<(), ()> {
        Ok(())
    }
    fn guard_expired(&mut self) -> bool {
        false
    }
}

/// An EEPROM whose configuration area has the right CRC (so the ESC loads it).
fn loaded_eeprom() -> std::vec::Vec<u8> {
    let mut ee = std::vec![0u8; 2048];
    ee[0] = 0x80; // PDI control: SPI
    ee[14] = oxicat_esc::sii::crc8(&ee[..14]);
    ee
}

#[test]
fn a_missing_esc_never_hangs_and_the_stack_comes_back_without_a_reset() {
    let mut spi = FlakySpi {
        esc: Esc::new(EscConfig::lan9252(), loaded_eeprom()),
        dead: true,
        accesses: 0,
    };
    // Boot with the ESC absent: the stack does not start, nothing waits.
    let mut fw = HubFirmware::new(&mut spi, Box::new(HubSlot::new()), NoBus, Dma::default());
    assert!(fw.slave().is_none());
    assert_eq!(fw.sup.phase, EcatPhase::Fault);
    assert!(fw.app.sys.is_active(ERR_ECAT_TIMEOUT));
    // Two seconds of tasks with the ESC gone: each release returns.
    for k in 0..200u32 {
        fw.on_timer(TIMER_APP, &mut spi);
        if k % 10 == 0 {
            fw.on_timer(TIMER_SUPERVISOR, &mut spi);
        }
        if k % 3 == 0 {
            fw.on_timer(TIMER_LED, &mut spi);
        }
    }
    assert!(fw.slave().is_none());
    assert!(fw.sup.restarts >= 1, "restart attempted");
    assert!(fw.app.strip.started > 0, "the LED task kept running");
    assert_eq!(fw.app.led.shown, Shown::Error);
    // The ESC answers again: the supervisor re-creates the stack.
    spi.dead = false;
    for _ in 0..(app::RESTART_MS / app::SUPERVISOR_PERIOD_MS) {
        fw.on_timer(TIMER_SUPERVISOR, &mut spi);
    }
    assert!(fw.slave().is_some());
    assert_eq!(fw.sup.phase, EcatPhase::Connected);
    assert!(!fw.app.sys.is_active(ERR_ECAT_TIMEOUT));
    assert_eq!(fw.app.sys.last_event(), EV_SOES_RESPAWNED);
    // And it goes down again after PDI_FAULT_LIMIT failed accesses.
    spi.dead = true;
    for _ in 0..PDI_FAULT_LIMIT {
        fw.on_timer(TIMER_APP, &mut spi);
    }
    assert!(fw.slave().is_none());
    assert!(fw.app.sys.is_active(ERR_ECAT_TIMEOUT));
}

#[test]
fn device_definition_builds() {
    let od = oxicat_slave::Od::<{ device::IMAGE }>::new(&device::DEF).expect("definition");
    assert_eq!(od.get::<u16>(0xF000, 1), Ok(0x0010));
}

#[test]
fn pdo_sizes_are_the_reports_and_temperatures_carry_their_unit() {
    use super::device;
    // 15 × INT16 + UDINT + 2 × UINT = 38 bytes in, 4 × UINT = 8 bytes out (derived).
    assert_eq!((device::OUTPUT_BYTES, device::INPUT_BYTES), (8, 38));
    let s = device::DEF
        .scale(0x6000, 15)
        .expect("temperatures are scaled");
    assert_eq!((s.unit, s.value(2512.0)), ("°C", 25.12));
    assert_eq!(device::DEF.scale(0x6001, 1), None);
}

#[test]
fn an_esc_without_its_eeprom_configuration_is_err_ecat_init_and_retried() {
    // Blank EEPROM: the ESC answers but DL status 0x0110 bit 0 (EEPROM loaded) is clear.
    let mut spi = FlakySpi {
        esc: Esc::new(EscConfig::lan9252(), std::vec![0u8; 2048]),
        dead: false,
        accesses: 0,
    };
    let mut fw = HubFirmware::new(&mut spi, Box::new(HubSlot::new()), NoBus, Dma::default());
    assert!(fw.slave().is_none());
    assert!(fw.app.sys.is_active(ERR_ECAT_INIT));
    assert!(
        !fw.app.sys.is_active(ERR_ECAT_TIMEOUT),
        "the ESC did answer"
    );
    assert_eq!(fw.app.sys.active_error(), ERR_ECAT_INIT);
    // Retried every RESTART_MS: still not loaded, reported once.
    let handled = fw.app.sys.handled;
    for _ in 0..3 * (app::RESTART_MS / app::SUPERVISOR_PERIOD_MS) {
        fw.on_timer(TIMER_SUPERVISOR, &mut spi);
    }
    assert!(fw.slave().is_none());
    assert!(fw.sup.restarts >= 3);
    assert_eq!(fw.app.sys.handled, handled, "no second ERR_ECAT_INIT");
}
