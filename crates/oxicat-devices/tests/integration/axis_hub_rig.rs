//! The axis communication hub end to end: firmware (`oxicat-devices`), plant
//! (`oxicat-plant`) and an ethercrab master on the virtual segment.

use oxicat_devices::axis_hub::rig::{run_scenario, HubSync, ScenarioConfig, Script, SimOneWire};
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

fn scripted(script: Script) -> (oxicat_devices::axis_hub::rig::ScenarioReport, String) {
    let cfg = ScenarioConfig {
        script,
        ..ScenarioConfig::default()
    };
    let mut lines = Vec::new();
    let r = run_scenario(sii(), &cfg, &mut |l| lines.push(l.to_string())).expect("runs");
    (r, lines.join("\n"))
}

#[test]
fn master_commands_end_to_end_and_the_init_warning_colour() {
    let (r, log) = scripted(Script::Commands);
    assert!(r.ok(), "{log}");
    for code in [
        codes::ERR_ECAT_CMD_FAULT,
        codes::ERR_ECAT_CMD_SOFTFAULT,
        codes::ERR_TEMP_SENS_OVERHEAT,
    ] {
        assert!(r.errors_seen.contains(&code), "{code} at the master\n{log}");
    }
    for code in [
        codes::EV_ECAT_CMD_ACK,
        codes::EV_ECAT_CMD_LED_TOGGLE,
        codes::EV_ECAT_APP_OP,
    ] {
        assert!(r.events_seen.contains(&code), "{code} at the master\n{log}");
    }
}

#[test]
fn led_faults_restart_the_channels_and_escalate_to_the_task_fault() {
    let (r, log) = scripted(Script::LedFaults);
    assert!(r.ok(), "{log}");
    for code in [
        codes::ERR_LED_OSTIM,
        codes::ERR_LED_INIT,
        codes::ERR_LED_TIMEOUT,
        codes::ERR_LED_DSM_FAULT,
    ] {
        assert!(r.errors_seen.contains(&code), "{code} at the master\n{log}");
    }
}

#[test]
fn the_whole_sensor_bus_lost_is_the_temperature_task_fault() {
    let (r, log) = scripted(Script::TempBusLost);
    assert!(r.ok(), "{log}");
    assert!(r.errors_seen.contains(&codes::ERR_TEMP_DSM_FAULT), "{log}");
}

#[test]
fn an_esc_state_out_of_step_with_the_stack_is_the_ecat_task_fault() {
    let (r, log) = scripted(Script::EscStateGlitch);
    assert!(r.ok(), "{log}");
    assert!(r.errors_seen.contains(&codes::ERR_ECAT_DSM_FAULT), "{log}");
}

#[test]
fn dc_bring_up_err_1302_comes_from_a_sync0_start_time_in_the_past() {
    // The rig's default start delay (two cycles): SYNC0 starts before OP, no 1302.
    let cfg = ScenarioConfig {
        sync: HubSync::Dc,
        bring_up_only: true,
        ..ScenarioConfig::default()
    };
    let mut lines = Vec::new();
    let r = run_scenario(sii(), &cfg, &mut |l| lines.push(l.to_string())).expect("runs");
    assert!(r.ok(), "{}", lines.join("\n"));
    assert_eq!(r.errors_seen, Vec::<u16>::new(), "{}", lines.join("\n"));
    // 0x0990 reads the next SYNC0 pulse: on the master's 10 ms grid.
    let (next, now) = r.dc_start.expect("DC registers");
    assert_eq!(next % cfg.cycle_ns, 0, "next pulse {next}");
    assert!(
        next > now && next - now <= cfg.cycle_ns,
        "next {next} now {now}"
    );
    // 1 ms, under the 10 ms cycle (the value the rig used before): ethercrab rounds the
    // start time down into the past, the ESC's 32-bit compare reaches it only after the
    // wrap (start time moved by 2^32 ns), the node is in OP without SYNC0 and says 1302 —
    // cleared once SYNC0 runs.
    let cfg = ScenarioConfig {
        dc_start_delay_ns: 1_000_000,
        ..cfg
    };
    let mut lines = Vec::new();
    let r = run_scenario(sii(), &cfg, &mut |l| lines.push(l.to_string())).expect("runs");
    assert!(r.ok(), "{}", lines.join("\n"));
    assert_eq!(r.errors_seen, vec![codes::ERR_ECAT_COMM_LOST]);
    // The pulses are 2^32 ns after the master's grid: their phase is 2^32 mod 10 ms.
    let (next, _) = r.dc_start.expect("DC registers");
    assert_eq!(
        next % cfg.cycle_ns,
        (1u64 << 32) % cfg.cycle_ns,
        "next pulse {next}"
    );
}

#[test]
fn an_esc_without_its_eeprom_is_err_ecat_init_until_the_master_writes_it() {
    use oxicat_devices::axis_hub::rig::{attach_hub, hub_esc, HubConfig};
    use oxicat_master::{AlState, Link, Master};
    use oxicat_sim::segment::Segment;
    use std::sync::{Arc, Mutex};
    let good = sii();
    let mut bad = good.clone();
    bad[14] ^= 0xFF; // the configuration area's CRC: the ESC loads nothing
    let mut seg = Segment::new();
    let id = seg.add(hub_esc(bad));
    let hub = attach_hub(&mut seg, id, &HubConfig::default()).expect("attach");
    seg.advance_by(1_500_000_000);
    {
        let h = hub.lock();
        assert!(h.slave().is_none(), "no stack on an unconfigured ESC");
        assert!(h.app.sys.is_active(codes::ERR_ECAT_INIT));
        assert!(
            !h.app.sys.is_active(codes::ERR_ECAT_TIMEOUT),
            "the ESC answers"
        );
    }
    // The master (raw APWR datagrams: the slave has no station address yet) writes the
    // configuration area's CRC word back (0x0502 write command, word 7) and reloads the
    // area (command 0x04, as at power-up).
    let apwr = |seg: &mut Segment, reg: u16, data: &[u8]| {
        use oxicat_wire::{Command, DatagramHeader, EcatFrame, EthernetHeader, FrameBuilder};
        let mut buf = [0u8; 64];
        let eth = EthernetHeader {
            dst: [0xFF; 6],
            src: [0x10; 6],
            vlan_tci: None,
            payload_offset: 14,
        };
        let mut b = FrameBuilder::new(&mut buf, &eth).expect("frame");
        b.push(
            DatagramHeader::physical(Command::Apwr, 1, 0, reg, data.len() as u16),
            data,
        )
        .expect("datagram");
        let n = b.finish();
        let back = seg.exchange(&buf[..n]).expect("frame back");
        let (_, f) = EcatFrame::parse_ethernet(&back).expect("EtherCAT frame");
        let wkc = f.datagrams().next().expect("datagram").expect("parses").wkc;
        assert_eq!(wkc, 1, "APWR 0x{reg:04X}");
    };
    apwr(&mut seg, 0x0500, &[0]);
    apwr(&mut seg, 0x0504, &7u32.to_le_bytes());
    apwr(&mut seg, 0x0508, &[good[14], good[15]]);
    apwr(&mut seg, 0x0502, &[0x01, 0x02]);
    seg.advance_by(20_000_000);
    apwr(&mut seg, 0x0502, &[0x00, 0x04]);
    seg.advance_by(1_500_000_000);
    assert!(
        hub.lock().slave().is_some(),
        "the stack started on the retry"
    );
    let seg = Arc::new(Mutex::new(seg));
    let mut m = Master::open(Link::Sim(seg.clone())).expect("master");
    m.request_state(&[0], AlState::PreOp).expect("PRE-OP");
    let word = |b: Vec<u8>| b.iter().rev().fold(0u32, |a, &x| a << 8 | x as u32);
    let status = word(m.sdo_upload(0, 0x6001, 1).expect("STATUS"));
    let error = word(m.sdo_upload(0, 0x6001, 3).expect("ERROR"));
    let event = word(m.sdo_upload(0, 0x6001, 2).expect("EVENT"));
    assert_eq!(
        (status >> 4) & 0x3FFF,
        codes::ERR_ECAT_INIT as u32,
        "last error"
    );
    assert_eq!(error, 0, "cleared once the ESC was configured");
    assert!(
        [codes::EV_SOES_RESPAWNED, codes::EV_ECAT_APP_INIT].contains(&(event as u16)),
        "event {event}"
    );
}

/// A bus that runs each transaction in the background, as the board's USART3 interrupt
/// does: `begin` only takes it, the slots run on the plant's bus at the third `collect`.
struct Background {
    bus: SimOneWire,
    txn: Option<onewire::Txn>,
    polls: u32,
    begun: u32,
}

impl onewire::OneWireBus for Background {
    type Error = core::convert::Infallible;
    fn reset(&mut self) -> Result<bool, Self::Error> {
        self.bus.reset()
    }
    fn write_bit(&mut self, bit: bool) -> Result<(), Self::Error> {
        self.bus.write_bit(bit)
    }
    fn read_bit(&mut self) -> Result<bool, Self::Error> {
        self.bus.read_bit()
    }
    fn begin(&mut self, t: &mut onewire::Txn) -> Result<bool, Self::Error> {
        assert!(self.txn.is_none(), "one transaction at a time");
        self.txn = Some(*t);
        self.polls = 0;
        self.begun += 1;
        Ok(false)
    }
    fn collect(&mut self, t: &mut onewire::Txn) -> Result<bool, Self::Error> {
        self.polls += 1;
        if self.polls < 3 {
            return Ok(false);
        }
        let mut done = self.txn.take().expect("a transaction runs");
        self.bus.begin(&mut done)?;
        *t = done;
        Ok(true)
    }
}

/// The temperature task on a bus whose transactions run in the background (the board
/// image's interrupt-driven USART) reads what it reads on a blocking bus — the same ROMs,
/// frames and events — with every call returning without waiting for the bus: a release
/// only starts its first transaction, `resume` (the board's tick) takes each result and
/// starts the next.
#[test]
fn the_temperature_task_on_a_background_bus_reads_what_it_reads_blocking() {
    use oxicat_devices::axis_hub::{SystemState, TempTask};
    let mut blocking = bus(15);
    let mut bg = Background {
        bus: bus(15),
        txn: None,
        polls: 0,
        begun: 0,
    };
    for (i, t) in [-7.3, 4.2, 19.9, 33.3, 85.0].iter().enumerate() {
        blocking.0.devices[i].die_temp = *t;
        bg.bus.0.devices[i].die_temp = *t;
    }
    let (mut ta, mut tb) = (TempTask::default(), TempTask::default());
    let (mut sa, mut sb) = (SystemState::default(), SystemState::default());
    let mut frames = 0;
    for release in 0..5u64 {
        let t = release * 1_000_000_000;
        blocking.0.set_time(t);
        bg.bus.0.set_time(t);
        let fa = ta.run(&mut blocking, &mut sa);
        assert!(!ta.busy(), "a blocking bus ends the release in the call");
        let begun = bg.begun;
        let mut fb = tb.run(&mut bg, &mut sb);
        assert!(fb.is_none(), "nothing read yet: the release only started");
        assert_eq!(bg.begun, begun + 1, "one transaction started");
        let mut ticks = 0;
        while tb.busy() {
            ticks += 1;
            assert!(ticks < 1000, "the release ends");
            if let Some(f) = tb.resume(&mut bg, &mut sb) {
                assert!(fb.is_none(), "one frame per release");
                fb = Some(f);
            }
        }
        assert!(ticks >= 2, "release {release}: {ticks} resumes");
        assert_eq!(fa, fb, "release {release}");
        frames += usize::from(fa.is_some());
        assert_eq!(ta.roms(), tb.roms());
        assert_eq!(ta.stats, tb.stats);
        sa.handle_events();
        sb.handle_events();
        assert_eq!(
            (sa.last_event(), sa.last_error()),
            (sb.last_event(), sb.last_error())
        );
    }
    assert_eq!(ta.roms().len(), 15);
    assert!(frames >= 3, "{frames} read-outs");
    // Sensor 4 at 85 °C: the overheat, on both.
    assert!(ta.overheat() && tb.overheat());
}
