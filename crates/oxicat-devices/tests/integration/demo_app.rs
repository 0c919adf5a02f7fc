//! The demo application: LEDs follow Blue_LED/Red_LED, inputs echo outputs, safe outputs.

use oxicat_devices::demo::{self, Buttons, Demo, Leds};
use oxicat_slave::{Application, Od};

#[derive(Default)]
struct FakeLeds(Vec<(bool, bool)>);
impl Leds for FakeLeds {
    fn set(&mut self, blue: bool, red: bool) {
        self.0.push((blue, red));
    }
}
struct FakeButtons(u8);
impl Buttons for FakeButtons {
    fn read(&mut self) -> u8 {
        self.0
    }
}

#[test]
fn cycle_drives_leds_and_echoes_outputs() {
    let mut od = Od::<{ demo::IMAGE }>::new(&demo::DEF).unwrap();
    let mut app = Demo::new(FakeLeds::default(), FakeButtons(0b101));
    od.set(0x7000, 5, true).unwrap();
    od.set(0x7000, 9, -2i8).unwrap();
    od.set(0x7010, 1, -7i32).unwrap();
    od.set(0x7012, 1, 513u16).unwrap();
    od.set(0x7014, 1, 1 << 20).unwrap();
    od.set(0x7020, 1, 30i16).unwrap();
    od.set(0x7020, 2, 12i16).unwrap();
    app.cycle(&mut od);
    assert_eq!(app.leds.0.last(), Some(&(true, false)));
    assert_eq!(od.get::<i32>(0x6010, 1), Ok(-7));
    assert_eq!(od.get::<u16>(0x6012, 1), Ok(513));
    assert_eq!(od.get::<i32>(0x6014, 1), Ok(1 << 20));
    assert_eq!(od.get::<i16>(0x6020, 1), Ok(42));
    assert_eq!(od.get::<i16>(0x6020, 2), Ok(18));
    assert_eq!(od.get::<i32>(0x6030, 1), Ok(1));
    assert_eq!(od.get::<i32>(0x6030, 2), Ok(0xFE05));
    app.safe_outputs(&mut od);
    assert_eq!(app.leds.0.last(), Some(&(false, false)));
    assert_eq!(od.get::<bool>(0x7000, 5), Ok(false));
    assert_eq!(od.get::<i32>(0x7010, 1), Ok(0));
}

#[test]
fn additions_variant_runs_the_same_application() {
    let mut od = Od::<{ demo::additions::IMAGE }>::new(&demo::additions::DEF).unwrap();
    let mut app = Demo::new(FakeLeds::default(), FakeButtons(0));
    od.set(0x7030, 1, 5i16).unwrap();
    od.set(0x7000, 6, true).unwrap();
    app.cycle(&mut od);
    assert_eq!(app.leds.0.last(), Some(&(false, true)));
    app.safe_outputs(&mut od);
    assert_eq!(od.get::<i16>(0x7030, 1), Ok(0));
    assert_eq!(demo::additions::DEF.default_output_bits(), 28 * 8);
    assert_eq!(demo::DEF.default_output_bits(), 24 * 8);
    assert_eq!(demo::DEF.default_input_bits(), 22 * 8);
}
