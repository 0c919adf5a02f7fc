//! The axis hub board image (`firmware/axis-hub`), the bytes that would be flashed, in the
//! loop: executed instruction by instruction on the emulated STM32F446 with its LAN9252 on
//! SPI1.
//!
//! - it boots, reaches PREOP and answers SDO uploads of 0x1018:01..03 with the hub's
//!   identity;
//! - ethercrab (through `oxicat-master`) brings it to OP in free run (the hub's default
//!   sync mode, 10 ms cycle) and runs 1,000 cycles with the right working counter every
//!   cycle, the image's task tick running all along;
//! - with the hub's plant on its pins (`oxicat_emu::axis_hub::HubBoardPlant`: the rig's 15
//!   DS18B20 on USART3's half-duplex line, the rings decoded from what DMA wrote into
//!   TIM8 CCR1 / TIM3 CCR2), the temperatures in 0x6000 match the sensors' die
//!   temperatures within the DS18B20's 12-bit resolution after the first conversion, and
//!   both rings show the OP colour, decoded against the WS2812B timing;
//! - a sensor unplugged on the board's bus in OP is ERROR 1102 in 0x6001:03, its slot in
//!   0x6000 invalid, the others kept, and the rings turn to the warning colour.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use oxicat_devices::axis_hub::device::{DEF, SENSORS, TEMP_INVALID};
use oxicat_devices::axis_hub::rig::HubInputs;
use oxicat_devices::axis_hub::Shown;
use oxicat_emu::axis_hub::{HubBoardPlant, HubView};
use oxicat_emu::node::{EmulatedNode, NodeHandle};
use oxicat_emu::Board;
use oxicat_esc::{Esc, EscConfig};
use oxicat_master::cyclic::{CycleOptions, Flow, SyncMode};
use oxicat_master::{Link, Master};
use oxicat_pdi::sim::{BusConfig, Lan9252Model};
use oxicat_sim::segment::Segment;

use crate::common;

use common::Direct;

/// The task tick of the image: TIM6_DAC, IRQ 54.
const TIM6: u16 = 16 + 54;
/// The PDI IRQ (PA10): EXTI15_10, IRQ 40 (`HubFirmware::on_pdi_irq`).
const EXTI15_10: u16 = 16 + 40;
/// SYNC0 (PB3): EXTI3, IRQ 9 (`HubFirmware::on_sync0`).
const EXTI3: u16 = 16 + 9;
/// USART3's interrupt (IRQ 39): the 1-Wire slots.
const USART3: u16 = 16 + 39;
/// Bound of the task tick handler in OP with the 15 sensors: half the 1 ms tick (and of
/// the hub's 1 ms minimum cycle, 0x1C32:05), so no tick is lost and a PDI IRQ or SYNC0
/// waiting behind a tick still runs its cycle in the first half of the shortest cycle.
/// Measured: 296 µs max (the 1 s boundary, where the application task's free-run cycle
/// over SPI, the supervisor and the temperature release fall on one tick; 233 µs without
/// sensors), 29 µs mean; with the 1-Wire traffic inside it, before: 491 ms.
const TICK_MAX_US: u64 = 500;
/// The synchronous runs' cycle: shorter than the application task's 10 ms, so that only a
/// cycle run by the synchronous handler answers every master cycle.
const SYNC_CYCLE_NS: u64 = 4_000_000;
/// The hub's free-run cycle (its rig's default).
const CYCLE_NS: u64 = 10_000_000;

/// The board image (`firmware/axis-hub`, or `OXICAT_AXIS_HUB_IMAGE`).
fn image() -> Option<Vec<u8>> {
    common::image("axis-hub", "OXICAT_AXIS_HUB_IMAGE")
}

#[test]
fn the_hub_image_boots_reaches_preop_and_answers_its_identity() {
    let Some(img) = image() else { return };
    let esc = Esc::new(
        EscConfig::lan9252(),
        oxicat_esi::sii::generate(&DEF).expect("SII of the hub"),
    );
    let chip = Lan9252Model::handle(esc, BusConfig::mhz(22));
    let mut b = Board::new(&img, chip.clone()).expect("the image loads");
    let m = Direct { chip: chip.into() };
    // Boot: clocks, the 50 ms power-on wait, the LAN9252's init over SPI, the stack's
    // start-up, then the task tick at 1 kHz (the application task polls every 10 ms).
    let up = b
        .run_until(200_000, 300_000_000, |b| {
            b.spi_stats().frames > 200 && b.exceptions_taken(TIM6) > 100
        })
        .unwrap_or_else(|e| panic!("{e}"));
    let s = b.spi_stats();
    assert!(
        up,
        "the image did not reach its main loop: {s:?}, TIM6 {} ticks, PC {:#010x}",
        b.exceptions_taken(TIM6),
        b.pc()
    );
    assert_eq!(s.bytes_without_cs, 0, "every byte inside a CS frame");
    assert!(b.time_ns() >= 50_000_000, "the 50 ms power-on wait ran");
    assert_eq!(m.chip.stats().protocol_errors, 0);
    assert_eq!(m.al_status(&b) & 0x1F, 0x01, "INIT after start-up");
    assert!(b.output('C', 8), "green LED: the stack runs");
    assert!(!b.output('C', 9), "red LED off: the ESC answered");
    // The task tick is 1 kHz: 100 ms of board time, 100 ticks.
    let t0 = b.exceptions_taken(TIM6);
    b.run_to_ns(b.time_ns() + 100_000_000)
        .unwrap_or_else(|e| panic!("{e}"));
    let dt = b.exceptions_taken(TIM6) - t0;
    assert!((99..=101).contains(&dt), "100 ms: {dt} task ticks");

    m.to_preop(&mut b, 50_000_000);
    m.assert_identity(&mut b, DEF.identity);
    eprintln!(
        "hub image: {} instructions, {:.1} ms simulated, SPI {:?}, TIM6 {} ticks",
        b.instructions(),
        b.time_ns() as f64 * 1e-6,
        b.spi_stats(),
        b.exceptions_taken(TIM6)
    );
}

/// One emulated hub (a LAN9252 ESC with the hub's SII) on a segment, with its plant if
/// given.
fn segment(img: &[u8], plant: Option<HubBoardPlant>) -> (Segment, NodeHandle) {
    let mut seg = Segment::new();
    let sii = oxicat_esi::sii::generate(&DEF).expect("SII of the hub");
    let id = seg.add(Esc::new(EscConfig::lan9252(), sii));
    let plant = plant.map(|p| Box::new(p) as Box<dyn oxicat_emu::plant::BoardPlant>);
    let node = EmulatedNode::with_plant(img.to_vec(), 1_000_000, plant).expect("the image loads");
    let h = node.handle();
    seg.attach(id, Box::new(node)).expect("attach");
    (seg, h)
}

#[test]
fn ethercrab_runs_the_emulated_hub_in_free_run_op() {
    free_run_op(1_000);
}

/// The long run: 10,000 cycles of 10 ms (100 s of board time),
/// `cargo test -p oxicat-emu --test integration axis_hub_image:: -- --ignored`.
#[test]
#[ignore = "long: 10,000 cycles of an emulated board"]
fn ethercrab_runs_the_emulated_hub_for_10000_free_run_cycles() {
    free_run_op(10_000);
}

/// The emulated hub in OP in free run at 10 ms for `cycles` cycles: the right working
/// counter every cycle, no fault, the task tick running at 1 kHz.
fn free_run_op(cycles: u64) {
    let Some(img) = image() else { return };
    let (seg, node) = segment(&img, None);
    let wall = std::time::Instant::now();
    let mut m = Master::open(Link::Sim(Arc::new(Mutex::new(seg)))).expect("ethercrab scans");
    node.reset_stats();
    let stats = m
        .run_cycles(
            CycleOptions {
                cycle: Duration::from_nanos(CYCLE_NS),
                dc: false,
            },
            cycles,
        )
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((stats.cycles, stats.wkc_errors), (cycles, 0), "{stats:?}");
    let r = node.report().expect("the board thread runs");
    assert_eq!(r.fault, None);
    let ticks = r.taken[usize::from(TIM6)];
    // 1 kHz over the cycles run (10 per cycle), give or take the edges of the window.
    assert!(
        ticks + 20 >= cycles * 10,
        "{ticks} task ticks in {cycles} cycles of 10 ms"
    );
    eprintln!(
        "emulated hub: {cycles} free-run cycles of 10 ms in OP, {ticks} task ticks, tick handler \
         max {:.1} µs, {} PDI IRQs, stack {} B deepest, {:.1} s wall",
        r.handler(TIM6).max_cycles as f64 / 180.0,
        r.taken[usize::from(EXTI15_10)],
        r.stack.max_depth,
        wall.elapsed().as_secs_f64()
    );
}

#[test]
fn ethercrab_runs_the_emulated_hub_sm_synchronous() {
    synchronous_op(SyncMode::SmSync, 1_000);
}

#[test]
fn ethercrab_runs_the_emulated_hub_dc_synchronous() {
    synchronous_op(SyncMode::Dc, 1_000);
}

/// The control of the echo: in free run the same per-frame commands are acknowledged in
/// at most 80 % of the frames (the application task runs every 10 ms, the cycle is 4 ms).
#[test]
fn in_free_run_the_per_frame_command_echo_fails() {
    synchronous_op(SyncMode::FreeRun, 200);
}

/// `cargo test -p oxicat-emu --test integration axis_hub_image:: -- --ignored`: 10,000 SM-synchronous
/// cycles of 4 ms (40 s of board time).
#[test]
#[ignore = "long: 10,000 cycles of an emulated board"]
fn ethercrab_runs_the_emulated_hub_for_10000_sm_synchronous_cycles() {
    synchronous_op(SyncMode::SmSync, 10_000);
}

/// `--ignored`: 10,000 DC-synchronous cycles of 4 ms.
#[test]
#[ignore = "long: 10,000 cycles of an emulated board"]
fn ethercrab_runs_the_emulated_hub_for_10000_dc_synchronous_cycles() {
    synchronous_op(SyncMode::Dc, 10_000);
}

/// The emulated hub in OP in `mode` (SM-synchronous: 0x1C32:01 = 1, the cycle in the PDI
/// IRQ's handler; DC: 0x1C32:01 = 2, the cycle in SYNC0's) at 4 ms for `cycles` cycles: the
/// right working counter every cycle, and the cycle run by that handler — the master
/// changes the COMMAND every cycle (LED toggle / LED auto in turn) and the frame after the
/// one that carried it reads that command's acknowledgement in EVENT, every time. The free-run application task
/// (10 ms) could answer at most every second or third of these cycles; the synchronous
/// handler runs once per cycle.
fn synchronous_op(mode: SyncMode, cycles: u64) {
    use oxicat_devices::axis_hub::codes::{EV_ECAT_CMD_ACK, EV_ECAT_CMD_LED_TOGGLE};
    use oxicat_devices::axis_hub::device::{CMD_LED_AUTO, CMD_LED_TOGGLE};
    let Some(img) = image() else { return };
    let (seg, node) = segment(&img, None);
    let wall = std::time::Instant::now();
    let mut m = Master::open(Link::Sim(Arc::new(Mutex::new(seg)))).expect("ethercrab scans");
    node.reset_stats();
    // After a short warm-up (the supervisor's OP event), from then on every cycle.
    let warm = 20u64;
    let (mut echoed, mut missed) = (0u64, Vec::new());
    // The commands set in the last two callbacks: one set after cycle k goes out with frame
    // k + 1, the slave's cycle behind that frame acknowledges it, frame k + 2 reads that.
    let mut sent: [Option<u16>; 2] = [None, None];
    let stats = m
        .run_cyclic(
            CycleOptions {
                cycle: Duration::from_nanos(SYNC_CYCLE_NS),
                dc: false,
            }
            .with_sync(mode),
            |io| {
                let ev = HubInputs::parse(&io.inputs[0]).event;
                if let Some(cmd) = sent[0] {
                    let want = if cmd == CMD_LED_TOGGLE {
                        EV_ECAT_CMD_LED_TOGGLE
                    } else {
                        EV_ECAT_CMD_ACK
                    };
                    if ev == want {
                        echoed += 1;
                    } else if missed.len() < 10 {
                        missed.push((io.cycle, ev, want));
                    }
                }
                let toggle = io.cycle % 2 == 0;
                let cmd = (io.cycle >= warm).then_some(if toggle {
                    CMD_LED_TOGGLE
                } else {
                    CMD_LED_AUTO
                });
                sent = [sent[1], cmd];
                io.outputs[0][..2].copy_from_slice(&cmd.unwrap_or(0).to_le_bytes());
                Ok(if io.cycle + 1 >= cycles {
                    Flow::Stop
                } else {
                    Flow::Continue
                })
            },
        )
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((stats.cycles, stats.wkc_errors), (cycles, 0), "{stats:?}");
    let echoes = cycles - warm - 2;
    if mode == SyncMode::FreeRun {
        // The control: the application task (10 ms) misses many of the 4 ms frames' commands
        // (the two acknowledgements alternate, so half match by chance alone; measured 107
        // of 178).
        assert!(
            echoed * 5 <= echoes * 4,
            "free run acknowledged {echoed} of {echoes} per-frame commands"
        );
        eprintln!("free run at 4 ms: {echoed} of {echoes} per-frame commands acknowledged");
        return;
    }
    // The sync mode the hub ran in (the master leaves 0x1C32:01 as it set it).
    let want_mode: u16 = if mode == SyncMode::Dc { 2 } else { 1 };
    assert_eq!(
        m.sdo_upload(0, 0x1C32, 1).expect("0x1C32:01"),
        want_mode.to_le_bytes(),
        "0x1C32:01"
    );
    let r = node.report().expect("the board thread runs");
    assert_eq!(r.fault, None);
    let (handler, name) = match mode {
        SyncMode::Dc => (EXTI3, "SYNC0 (EXTI3)"),
        _ => (EXTI15_10, "PDI IRQ (EXTI15_10)"),
    };
    let runs = r.taken[usize::from(handler)];
    assert!(runs >= cycles, "{name}: {runs} runs in {cycles} cycles");
    assert_eq!(
        echoed, echoes,
        "the COMMAND of every frame acknowledged in the next one; first misses (cycle, \
         EVENT, wanted): {missed:?}"
    );
    let ticks = r.taken[usize::from(TIM6)];
    eprintln!(
        "emulated hub: {cycles} {mode} cycles of 4 ms in OP, every COMMAND acknowledged in the \
         next frame ({echoed}); {name} {runs} runs, max {:.1} µs; {ticks} task ticks, tick \
         handler max {:.1} µs; stack {} B deepest; {:.1} s wall",
        r.handler(handler).max_cycles as f64 / 180.0,
        r.handler(TIM6).max_cycles as f64 / 180.0,
        r.stack.max_depth,
        wall.elapsed().as_secs_f64()
    );
}

/// Die temperatures of the 15 sensors: distinct, some below zero, none a multiple of the
/// 12-bit step.
fn die_temps() -> Vec<f64> {
    (0..SENSORS).map(|i| -7.3 + 4.71 * i as f64).collect()
}

#[test]
fn the_hub_image_reads_the_sensors_over_usart_and_lights_the_rings_by_dma() {
    let Some(img) = image() else { return };
    let temps = die_temps();
    let plant = HubBoardPlant::new(&temps);
    let view: HubView = plant.view();
    let (seg, node) = segment(&img, Some(plant));
    let mut m = Master::open(Link::Sim(Arc::new(Mutex::new(seg)))).expect("ethercrab scans");
    // 4 s in OP: the temperature task runs every second (search, CONVERT T, then the
    // read-out of the previous conversion a second later).
    let cycles = 400u64;
    let mut last = HubInputs::default();
    let mut first_valid: Option<u64> = None;
    let mut in_op = oxicat_emu::axis_hub::HubState::default();
    let stats = m
        .run_cyclic(
            CycleOptions {
                cycle: Duration::from_nanos(CYCLE_NS),
                dc: false,
            },
            |io| {
                if io.cycle == 0 {
                    // The handler times from here: in OP.
                    node.reset_stats();
                }
                last = HubInputs::parse(&io.inputs[0]);
                if first_valid.is_none() && last.temps.iter().all(|&t| t != TEMP_INVALID) {
                    first_valid = Some(io.cycle);
                }
                Ok(if io.cycle + 1 >= cycles {
                    // The plant as the last cycle in OP left it (after the run the master
                    // takes the node back to PREOP, and the rings follow).
                    in_op = view.lock().clone();
                    Flow::Stop
                } else {
                    Flow::Continue
                })
            },
        )
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(stats.wkc_errors, 0, "{stats:?}");
    let r = node.report().expect("the board thread runs");
    assert_eq!(r.fault, None);
    let st = in_op;
    // The tick in OP: the 1-Wire traffic runs in USART3's interrupt, the tick handler only
    // takes a finished transaction and starts the next; it stays far below the 1 ms tick
    // (no tick lost) and below the hub's 1 ms minimum cycle (0x1C32:05).
    let tick = r.handler(TIM6);
    let usart = r.handler(USART3);
    let op_ms = (r.cycles - r.stats_since_cycle) / 180_000;
    eprintln!(
        "with the plant, in OP ({op_ms} ms): task tick handler max {:.1} µs (own {:.1} µs), mean \
         {:.1} µs, {} ticks; USART3 (1-Wire slots) {} runs, max {:.1} µs",
        tick.max_cycles as f64 / 180.0,
        tick.max_own_cycles as f64 / 180.0,
        tick.mean_us(180_000_000),
        tick.runs,
        usart.runs,
        usart.max_cycles as f64 / 180.0
    );
    assert!(
        tick.max_cycles <= TICK_MAX_US * 180,
        "tick handler max {:.1} µs in OP (bound {TICK_MAX_US} µs)",
        tick.max_cycles as f64 / 180.0
    );
    assert!(
        tick.runs + 1 >= op_ms,
        "{} ticks in {op_ms} ms: ticks lost",
        tick.runs
    );
    assert!(
        usart.runs > 1000,
        "the slots ran in USART3's interrupt: {} runs",
        usart.runs
    );
    eprintln!(
        "1-Wire: {:?}, {} conversions; temperatures from cycle {first_valid:?}: {:?}; status \
         {:#010x} event {} error {}",
        st.onewire, st.conversions, last.temps, last.status, last.event, last.error
    );
    assert!(
        st.onewire.presences > 0,
        "the sensors answered: {:?}",
        st.onewire
    );
    assert!(st.conversions >= SENSORS as u64, "every sensor converted");
    assert!(
        first_valid.is_some(),
        "no complete read-out: {:?}",
        last.temps
    );
    // 0x6000 is in the order the ROM search found the sensors: each value is one sensor's
    // die temperature at 12 bits (1/16 °C, truncated; 0.01 °C in the PDO), each sensor once.
    let mut seen = [false; SENSORS];
    for (i, &got) in last.temps.iter().enumerate() {
        let got = f64::from(got) / 100.0;
        let k = temps
            .iter()
            .position(|&t| got <= t + 0.01 && got >= t - 0.0625 - 0.01)
            .unwrap_or_else(|| panic!("0x6000:{} = {got} °C matches no sensor {temps:?}", i + 1));
        assert!(!seen[k], "sensor {k} reported twice");
        seen[k] = true;
    }
    assert_eq!(last.error, 0, "no error in 0x6001:03");
    let want = Shown::Normal.color();
    for (k, ring) in st.rings.iter().enumerate() {
        let d = ring.as_ref().unwrap_or_else(|| {
            panic!(
                "ring {k}: no stream decoded ({} transfers)",
                st.transfers[k]
            )
        });
        assert!(
            d.bad_bits.is_empty(),
            "ring {k}: bits out of tolerance {:?}",
            d.bad_bits
        );
        assert!(d.latched, "ring {k}: no reset after the stream");
        assert_eq!(d.colors.len(), 5, "ring {k}: {:?}", d.colors);
        for c in &d.colors {
            assert_eq!((c.r, c.g, c.b), (want.r, want.g, want.b), "ring {k}");
        }
        assert!(
            st.transfers[k] > 10,
            "ring {k}: {} transfers",
            st.transfers[k]
        );
    }
}

/// A sensor unplugged on the board's bus while in OP: the image reports
/// `ERR_TEMP_SENS_LOST` (1102) in 0x6001:03, that sensor's slot in 0x6000 becomes
/// `TEMP_INVALID` while the others keep their values, and the rings switch to the warning
/// colour.
#[test]
fn an_unplugged_sensor_on_the_board_is_error_1102_and_the_warning_colour() {
    use oxicat_devices::axis_hub::codes::ERR_TEMP_SENS_LOST;
    let Some(img) = image() else { return };
    let temps = die_temps();
    let plant = HubBoardPlant::new(&temps);
    let view: HubView = plant.view();
    let (seg, node) = segment(&img, Some(plant));
    let mut m = Master::open(Link::Sim(Arc::new(Mutex::new(seg)))).expect("ethercrab scans");
    // Unplugged 1 s after the first complete read-out; 3 s more for the next ones.
    let mut unplug_at: Option<u64> = None;
    let mut in_op = oxicat_emu::axis_hub::HubState::default();
    let mut before = HubInputs::default();
    let mut last = HubInputs::default();
    let stats = m
        .run_cyclic(
            CycleOptions {
                cycle: Duration::from_nanos(CYCLE_NS),
                dc: false,
            },
            |io| {
                last = HubInputs::parse(&io.inputs[0]);
                if unplug_at.is_none() && last.temps.iter().all(|&t| t != TEMP_INVALID) {
                    unplug_at = Some(io.cycle + 100);
                }
                if unplug_at == Some(io.cycle) {
                    before = last;
                    view.lock().plugged[4] = false;
                }
                let end = unplug_at.map_or(1_000, |u| u + 300);
                Ok(if io.cycle + 1 >= end {
                    in_op = view.lock().clone();
                    Flow::Stop
                } else {
                    Flow::Continue
                })
            },
        )
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(
        unplug_at.is_some(),
        "no complete read-out in 10 s: {last:?}"
    );
    assert_eq!(stats.wkc_errors, 0, "{stats:?}");
    assert_eq!(node.report().expect("the board runs").fault, None);
    assert_eq!(before.error, 0, "no error before: {before:?}");
    assert!(
        before.temps.iter().all(|&t| t != TEMP_INVALID),
        "{before:?}"
    );
    assert_eq!(last.error, ERR_TEMP_SENS_LOST, "{last:?}");
    let invalid: Vec<usize> = (0..SENSORS)
        .filter(|&i| last.temps[i] == TEMP_INVALID)
        .collect();
    assert_eq!(invalid.len(), 1, "one slot invalid: {:?}", last.temps);
    for i in (0..SENSORS).filter(|i| !invalid.contains(i)) {
        assert_eq!(last.temps[i], before.temps[i], "0x6000:{} kept", i + 1);
    }
    let want = Shown::Warning.color();
    let st = in_op;
    for (k, ring) in st.rings.iter().enumerate() {
        let d = ring.as_ref().expect("a decoded stream");
        assert!(d.bad_bits.is_empty() && d.latched, "ring {k}: {d:?}");
        assert!(
            d.colors
                .iter()
                .all(|c| (c.r, c.g, c.b) == (want.r, want.g, want.b)),
            "ring {k}: {:?}, want {want:?}",
            d.colors
        );
    }
}
