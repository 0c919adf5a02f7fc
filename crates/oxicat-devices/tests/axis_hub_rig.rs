//! The axis communication hub end to end: firmware (`oxicat-devices`), plant
//! (`oxicat-plant`) and an ethercrab master on the virtual segment.

use oxicat_devices::axis_hub::rig::{run_scenario, HubSync, ScenarioConfig, SimOneWire};
use oxicat_devices::axis_hub::{codes, device, onewire, ws2812};
use oxicat_plant::onewire::{ds18b20_rom, Ds18b20, OneWireNet};
use oxicat_plant::ws2812::decode;

fn sii() -> Vec<u8> {
    oxicat_esi::sii::generate(&device::DEF).expect("SII of the hub")
}

fn bus(n: usize) -> SimOneWire {
    SimOneWire(OneWireNet::new(
        (0..n)
            .map(|i| Ds18b20::new(ds18b20_rom(0x5EED_0000 ^ (i as u64 * 0x9E37_79B9))))
            .collect(),
    ))
}

#[test]
fn rom_search_finds_all_15_sensors() {
    let mut b = bus(15);
    let mut roms = [[0u8; 8]; 20];
    let n = onewire::search_all(&mut b, &mut roms).expect("search");
    assert_eq!(n, 15);
    let mut want: Vec<[u8; 8]> = b.0.devices.iter().map(|d| d.rom).collect();
    let mut got = roms[..n].to_vec();
    want.sort();
    got.sort();
    assert_eq!(got, want, "every ROM once");
    assert!(got
        .iter()
        .all(|r| r[0] == onewire::FAMILY_DS18B20 && onewire::crc8(r) == 0));
    // An unplugged sensor is not found.
    b.0.devices[7].plugged = false;
    assert_eq!(onewire::search_all(&mut b, &mut roms).unwrap(), 14);
}

#[test]
fn crc_errors_are_detected_and_resolution_sets_the_conversion_time() {
    let mut b = bus(3);
    let rom = b.0.devices[1].rom;
    b.0.devices[1].die_temp = 42.7;
    assert!(onewire::convert_all(&mut b).unwrap());
    b.0.set_time(750_000_000);
    let sp = onewire::read_scratchpad(&mut b, &rom).expect("good read");
    assert_eq!(onewire::centi_celsius(&sp).0, 4268, "42.6875 °C at 12 bits");
    b.0.devices[1].corrupt_reads = 1;
    assert_eq!(
        onewire::read_scratchpad(&mut b, &rom),
        Err(onewire::OwError::Crc)
    );
    assert!(
        onewire::read_scratchpad(&mut b, &rom).is_ok(),
        "next read good"
    );
    b.0.devices[1].plugged = false;
    assert_eq!(
        onewire::read_scratchpad(&mut b, &rom),
        Err(onewire::OwError::NoPresence)
    );
    b.0.devices[1].plugged = true;
    // 9 bits: 93.75 ms conversion, 0.5 °C steps.
    onewire::write_config(&mut b, &rom, 0x4B, 0x46, onewire::Resolution::Bits9).unwrap();
    let sp = onewire::read_scratchpad(&mut b, &rom).unwrap();
    let res = onewire::Resolution::from_config(sp[4]);
    assert_eq!(res, onewire::Resolution::Bits9);
    assert_eq!(res.conversion_us(), 93_750);
    assert!(onewire::convert_all(&mut b).unwrap());
    b.0.set_time(750_000_000 + 93_750_000);
    let sp = onewire::read_scratchpad(&mut b, &rom).unwrap();
    assert_eq!(onewire::centi_celsius(&sp).0, 4250);
}

#[test]
fn led_bit_stream_decodes_to_the_intended_colours_within_tolerance() {
    let t = ws2812::HUB_TIMING;
    for want in [
        ws2812::COLOR_PREOP,
        ws2812::COLOR_NORMAL,
        ws2812::COLOR_WARNING,
        ws2812::COLOR_ERROR,
        ws2812::Rgb::new(0xA5, 0x5A, 0xFF),
    ] {
        let mut buf = [0u16; ws2812::RING_SLOTS];
        let n = ws2812::encode(&[want; ws2812::LEDS_PER_RING], &t, &mut buf).unwrap();
        let d = decode(
            &buf[..n],
            t.clock_hz as f64,
            t.period,
            ws2812::LEDS_PER_RING,
        );
        assert!(d.latched, "reset > 50 µs");
        assert!(d.bad_bits.is_empty(), "{:?}", d.bad_bits.first());
        assert_eq!(d.colors.len(), ws2812::LEDS_PER_RING);
        for c in d.colors {
            assert_eq!((c.r, c.g, c.b), (want.r, want.g, want.b));
        }
    }
    // A timer set up with 0.6 µs for a 0 (200 ns over T0H) is out of tolerance.
    let bad = ws2812::PwmTiming {
        t0h: (0.6e-6 * t.clock_hz as f64) as u16,
        ..t
    };
    let mut buf = [0u16; ws2812::RING_SLOTS];
    let n = ws2812::encode(&[ws2812::COLOR_ERROR], &bad, &mut buf).unwrap();
    let d = decode(&buf[..n], t.clock_hz as f64, t.period, 1);
    assert!(!d.bad_bits.is_empty());
}

#[test]
fn scenario_overheat_sensor_loss_crc_and_cable_open_free_run() {
    let mut lines = Vec::new();
    let r = run_scenario(sii(), &ScenarioConfig::default(), &mut |l| {
        lines.push(l.to_string())
    })
    .expect("scenario runs");
    assert!(r.ok(), "{}", lines.join("\n"));
    assert_eq!(r.sensors_found, 15);
    for code in [
        codes::ERR_TEMP_SENS_OVERHEAT,
        codes::ERR_TEMP_SENS_LOST,
        codes::ERR_TEMP_SENS_CRC,
        codes::ERR_ECAT_COMM_LOST,
    ] {
        assert!(r.errors_seen.contains(&code), "{code} at the master");
    }
}

#[test]
fn bring_up_sm_synchronous_and_dc() {
    let _ = env_logger::builder().is_test(true).try_init();
    for sync in [HubSync::SmSync, HubSync::Dc] {
        let cfg = ScenarioConfig {
            sync,
            bring_up_only: true,
            ..ScenarioConfig::default()
        };
        let mut lines = Vec::new();
        let r = run_scenario(sii(), &cfg, &mut |l| lines.push(l.to_string())).expect("runs");
        assert!(r.ok(), "{sync:?}: {}", lines.join("\n"));
    }
}
