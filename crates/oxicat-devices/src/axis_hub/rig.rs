//! The axis communication hub on the virtual segment: the firmware host of `oxicat-sim`
//! runs the hub firmware (`crate::axis_hub`) behind its ESC with its plant (`HubPlant`) — thermal
//! nodes (four motor housings in ambient air), fifteen DS18B20 on a bit-level 1-Wire bus
//! (`oxicat_plant::onewire`), and the WS2812 rings whose bit stream is decoded back into
//! colours (`oxicat_plant::ws2812`).
//!
//! | event | what runs |
//! |---|---|
//! | ESC PDI IRQ | `HubFirmware::on_pdi_irq` (SM-synchronous cycle) |
//! | ESC SYNC0 / SYNC1 | `HubFirmware::on_sync0` / `on_sync1` (DC cycle) |
//! | every 1 ms | the idle loop: `HubFirmware::poll` (ESM, mailbox) |
//! | a task's release time | the plant catches up to now (thermal step, sensor dies, 1-Wire clock, DMA done), then every task due, in priority order ([`TASKS`]) |
//!
//! [`run_scenario`] is the must-show: an ethercrab master in the same process brings the hub
//! to OP (free run, SM-synchronous or DC) at a 10 ms cycle and walks it through an
//! overheat, an unplugged sensor, a CRC fault and a cable opened for 2 s.

use std::borrow::BorrowMut;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use crate::axis_hub::{
    self, codes, device, onewire, ws2812, HubFirmware, LedStrip, OneWireBus, TASKS,
};
use ethercrab::subdevice_group::DcConfiguration;
use ethercrab::{DcSync, MainDevice, MainDeviceConfig, PduStorage};
use oxicat_esc::{Esc, EscConfig};
use oxicat_plant::onewire::{ds18b20_rom, Ds18b20, OneWireNet};
use oxicat_plant::thermal::{Mount, TempSensor, ThermalNet, ThermalNode};
use oxicat_plant::ws2812::{decode, Decoded};

use oxicat_master::inprocess::{inprocess_task, virtual_timeouts, InProcessConfig, Runner};
use oxicat_sim::firmware::{
    attach_host, AttachError, Bench, FirmwareConfig, Host, HostHandle, Image,
};
use oxicat_sim::pdi_path::{Direct, PdiPath, PdiRoute, SpiPath};
use oxicat_sim::segment::{Segment, SlaveId};

/// The firmware's 1-Wire bus on the plant's bus model (slots never fail here).
#[derive(Debug, Clone, Default)]
pub struct SimOneWire(pub OneWireNet);

impl OneWireBus for SimOneWire {
    type Error = core::convert::Infallible;

    fn reset(&mut self) -> Result<bool, Self::Error> {
        Ok(self.0.reset())
    }

    fn write_bit(&mut self, bit: bool) -> Result<(), Self::Error> {
        self.0.write_bit(bit);
        Ok(())
    }

    fn read_bit(&mut self) -> Result<bool, Self::Error> {
        Ok(self.0.read_bit())
    }
}

/// The PWM+DMA channels: the last duty buffer per ring and when its transfer ends, the
/// guard timer, and fault injection (a channel that cannot be configured, a DMA stream
/// that never completes, a timer queue that refuses the guard).
#[derive(Debug, Clone, Default)]
pub struct SimLeds {
    /// Last buffer sent per ring.
    pub buffers: [Vec<u16>; ws2812::RINGS],
    busy_until: [u64; ws2812::RINGS],
    now: u64,
    guard_at: Option<u64>,
    /// Fault injection: the next this many `configure` calls fail.
    pub fail_configure: u32,
    /// Fault injection: the next this many guard timers cannot be armed.
    pub fail_guard: u32,
    /// Fault injection: rings whose DMA transfers never complete (until restarted and
    /// un-stalled).
    pub stalled: [bool; ws2812::RINGS],
    /// `configure` calls (per ring).
    pub configured: [u32; ws2812::RINGS],
    /// `restart` calls (per ring).
    pub restarted: [u32; ws2812::RINGS],
}

impl LedStrip for SimLeds {
    type Error = &'static str;

    fn configure(&mut self, ring: usize) -> Result<(), Self::Error> {
        if self.fail_configure > 0 {
            self.fail_configure -= 1;
            return Err("PWM/DMA channel set-up failed");
        }
        if let Some(c) = self.configured.get_mut(ring) {
            *c += 1;
        }
        Ok(())
    }

    fn restart(&mut self, ring: usize) {
        if let Some(c) = self.restarted.get_mut(ring) {
            *c += 1;
        }
        if let Some(b) = self.busy_until.get_mut(ring) {
            *b = self.now;
        }
        self.guard_at = None;
    }

    fn start(&mut self, ring: usize, duties: &[u16]) -> Result<(), Self::Error> {
        let stalled = self.stalled.get(ring).copied().unwrap_or(false);
        if let Some(b) = self.buffers.get_mut(ring) {
            let t = ws2812::HUB_TIMING;
            self.busy_until[ring] = if stalled {
                u64::MAX
            } else {
                // The bits go out as the DMA feeds them: a stalled stream sends nothing.
                b.clear();
                b.extend_from_slice(duties);
                self.now + duties.len() as u64 * t.ns(t.period)
            };
        }
        Ok(())
    }

    fn done(&mut self, ring: usize) -> bool {
        self.busy_until.get(ring).is_none_or(|&t| self.now >= t)
    }

    fn arm_guard(&mut self, ms: u32) -> Result<(), Self::Error> {
        if self.fail_guard > 0 {
            self.fail_guard -= 1;
            self.guard_at = None;
            return Err("timer queue full");
        }
        self.guard_at = Some(self.now + ms as u64 * 1_000_000);
        Ok(())
    }

    fn guard_expired(&mut self) -> bool {
        self.guard_at.is_some_and(|t| self.now >= t)
    }
}

/// The hub firmware on the `Pdi` of path `P` (the software ESC by default) with the
/// simulated hardware.
pub type HubFw<P = Direct> =
    HubFirmware<<P as PdiPath>::Pdi, SimOneWire, SimLeds, Box<super::HubSlot<<P as PdiPath>::Pdi>>>;

/// Plant set-up of a hub.
#[derive(Debug, Clone, PartialEq)]
pub struct HubConfig {
    /// DS18B20 on the bus (at most 15 are read).
    pub sensors: usize,
    /// Ambient temperature \[°C\].
    pub ambient: f64,
    /// Motor housings (sensors are mounted round-robin: 3 per motor, the rest in air).
    pub motors: usize,
    /// Winding resistance \[Ω\], thermal resistance to ambient \[K/W\], time constant \[s\].
    pub motor_params: (f64, f64, f64),
    /// Sensor noise \[K\] (standard deviation).
    pub noise: f64,
    /// Seed of the sensor noise.
    pub seed: u64,
}

impl Default for HubConfig {
    fn default() -> Self {
        Self {
            sensors: 15,
            ambient: 25.0,
            motors: 4,
            motor_params: (1.0, 2.0, 4.0),
            noise: 0.05,
            seed: 1,
        }
    }
}

/// The ESC of a hub with the SII generated from `device::DEF` (`sii`): a LAN9252, as on the
/// report's STM32F446 board. (Its AL control register is locked until the PDI has read the
/// previous request, so the firmware must serve AL events promptly — from the PDI IRQ and
/// the 1 ms idle poll — which is what an early 10 ms-only poll got wrong.)
pub fn hub_esc(sii: Vec<u8>) -> Esc {
    Esc::new(EscConfig::lan9252(), sii)
}

impl<P: oxicat_slave::Pdi, B: OneWireBus, L: LedStrip, S: BorrowMut<super::HubSlot<P>>> Image<P>
    for HubFirmware<P, B, L, S>
{
    fn on_pdi_irq(&mut self, pdi: &mut P) -> Result<(), P::Error> {
        HubFirmware::on_pdi_irq(self, pdi);
        Ok(())
    }
    fn on_sync0(&mut self, pdi: &mut P) -> Result<(), P::Error> {
        HubFirmware::on_sync0(self, pdi);
        Ok(())
    }
    fn on_sync1(&mut self, pdi: &mut P) -> Result<(), P::Error> {
        HubFirmware::on_sync1(self, pdi);
        Ok(())
    }
    fn on_timer(&mut self, id: u8, pdi: &mut P) -> Result<(), P::Error> {
        HubFirmware::on_timer(self, id, pdi);
        Ok(())
    }
    fn poll(&mut self, pdi: &mut P) -> Result<(), P::Error> {
        HubFirmware::poll(self, pdi);
        Ok(())
    }
}

/// The hub's plant on the host: thermal nodes and the sensor models on the 1-Wire bus.
/// Before the tasks due at an instant run, it catches up to now (thermal step, sensor
/// dies, 1-Wire clock, DMA done).
pub struct HubPlant {
    /// Thermal nodes.
    pub thermal: ThermalNet,
    /// Sensor models, one per DS18B20 on the bus (same order).
    pub sensors: Vec<TempSensor>,
    plant_ns: u64,
}

impl<P: oxicat_slave::Pdi, S: BorrowMut<super::HubSlot<P>>>
    Bench<HubFirmware<P, SimOneWire, SimLeds, S>> for HubPlant
{
    fn before_timers(&mut self, fw: &mut HubFirmware<P, SimOneWire, SimLeds, S>, t: u64) {
        if t > self.plant_ns {
            self.thermal.advance((t - self.plant_ns) as f64 * 1e-9);
            self.plant_ns = t;
        }
        let bus = &mut fw.app.bus.0;
        for (s, d) in self.sensors.iter_mut().zip(bus.devices.iter_mut()) {
            d.die_temp = s.sample(&self.thermal);
            d.plugged = s.plugged;
        }
        bus.set_time(t);
        fw.app.strip.now = t;
    }
}

/// One hub on its host: firmware (`image`, or through `Deref` its fields) and plant
/// (`bench`), the firmware reaching its ESC through `P`.
pub type HubRig<P = Direct> = Host<HubFw<P>, P, HubPlant>;

/// The MCU's idle loop: `HubFirmware::poll` (ESM, mailbox) every 1 ms between the tasks.
pub const IDLE_POLL_NS: u64 = 1_000_000;

/// What a test or tool does to a hub on the segment.
pub trait HubBoard {
    /// What LED ring `ring` shows: its last bit stream decoded by the WS2812B model.
    fn ring(&self, ring: usize) -> Decoded;
    /// Sets the current through motor `m`'s winding \[A\].
    fn set_motor_current(&mut self, m: usize, amps: f64);
    /// Unplugs (`false`) or plugs sensor `i`.
    fn plug_sensor(&mut self, i: usize, plugged: bool);
    /// Corrupts the next `n` scratchpad reads of sensor `i` (CRC errors).
    fn corrupt_sensor(&mut self, i: usize, n: u32);
    /// Task releases delivered.
    fn releases(&self) -> u64;
}

impl<P: PdiPath> HubBoard for HubRig<P> {
    fn ring(&self, ring: usize) -> Decoded {
        let t = ws2812::HUB_TIMING;
        let buf = self.app.strip.buffers.get(ring).map_or(&[][..], |b| &b[..]);
        decode(buf, t.clock_hz as f64, t.period, ws2812::LEDS_PER_RING)
    }

    fn set_motor_current(&mut self, m: usize, amps: f64) {
        if let Some(n) = self.bench.thermal.nodes.get_mut(m) {
            n.current = amps;
        }
    }

    fn plug_sensor(&mut self, i: usize, plugged: bool) {
        if let Some(s) = self.bench.sensors.get_mut(i) {
            s.plugged = plugged;
        }
    }

    fn corrupt_sensor(&mut self, i: usize, n: u32) {
        if let Some(d) = self.image.app.bus.0.devices.get_mut(i) {
            d.corrupt_reads += n;
        }
    }

    fn releases(&self) -> u64 {
        self.counters.timers
    }
}

/// Access to a hub from outside the segment.
pub type HubHandle<P = Direct> = HostHandle<HubFw<P>, P, HubPlant>;

/// The host's schedule: the idle loop every 1 ms (before the tasks at the same instant),
/// the tasks of [`TASKS`] in priority order, each first one period after the start.
fn schedule() -> FirmwareConfig {
    let mut c = FirmwareConfig::default().poll_every(IDLE_POLL_NS);
    c.poll_first_ns = IDLE_POLL_NS;
    c.poll_before_timers = true;
    TASKS
        .iter()
        .fold(c, |c, task| c.timer(task.id, task.period_ns))
}

/// Boots the hub firmware on ESC `id` with its plant; the tasks start one period later.
pub fn attach_hub(
    segment: &mut Segment,
    id: SlaveId,
    config: &HubConfig,
) -> Result<HubHandle, AttachError> {
    attach_hub_with(segment, id, config, |_| Ok(Direct))
}

/// [`attach_hub`] with the firmware reaching its ESC through the chip driver of `route`
/// over the simulated SPI (`PdiRoute::Direct` is refused: use [`attach_hub`]).
pub fn attach_hub_via(
    segment: &mut Segment,
    id: SlaveId,
    config: &HubConfig,
    route: PdiRoute,
) -> Result<HubHandle<SpiPath>, AttachError> {
    attach_hub_with(segment, id, config, |esc| SpiPath::new(route, esc))
}

fn attach_hub_with<P: PdiPath>(
    segment: &mut Segment,
    id: SlaveId,
    config: &HubConfig,
    path: impl FnOnce(&mut Esc) -> Result<P, oxicat_sim::pdi_path::PathInitError>,
) -> Result<HubHandle<P>, AttachError> {
    let now = segment.now();
    let (r, rth, tau) = config.motor_params;
    let nodes = (0..config.motors)
        .map(|_| ThermalNode::motor(config.ambient, r, rth, tau))
        .collect();
    let thermal = ThermalNet::new(config.ambient, nodes);
    let sensors = (0..config.sensors)
        .map(|i| {
            let mount = if i / 3 < config.motors {
                Mount::Node(i / 3)
            } else {
                Mount::Ambient
            };
            TempSensor::new(
                mount,
                config.noise,
                config.seed.wrapping_mul(1000) + i as u64,
            )
        })
        .collect();
    let devices = (0..config.sensors)
        .map(|i| {
            Ds18b20::new(ds18b20_rom(
                0x00A1_0000 + (i as u64) * 0x1_0101 + config.seed,
            ))
        })
        .collect();
    let plant = HubPlant {
        thermal,
        sensors,
        plant_ns: now,
    };
    attach_host(segment, id, &schedule(), plant, path, |esc, path| {
        Ok(path.with_pdi(esc, |pdi| {
            HubFirmware::new(
                pdi,
                Box::new(super::HubSlot::new()),
                SimOneWire(OneWireNet::new(devices)),
                SimLeds::default(),
            )
        }))
    })
}

// ------------------------------------------------------------------ the scenario

/// How the master synchronises the hub.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HubSync {
    /// Free run: the application task polls every 10 ms.
    FreeRun,
    /// SM-synchronous: the cycle runs on the SM2 interrupt.
    SmSync,
    /// DC: the cycle runs on SYNC0.
    Dc,
}

/// What the scenario runs.
#[derive(Debug, Clone, PartialEq)]
pub struct ScenarioConfig {
    /// Sync mode.
    pub sync: HubSync,
    /// Master cycle \[ns\] (the report: about 10 ms).
    pub cycle_ns: u64,
    /// Only bring up and check the temperatures (no faults).
    pub bring_up_only: bool,
    /// The hub's plant.
    pub hub: HubConfig,
    /// Current into motor 0 for the overheat \[A\].
    pub heat_amps: f64,
    /// What runs after the bring-up (unless `bring_up_only`).
    pub script: Script,
    /// DC: the master's `start_delay` of the first SYNC0 \[ns\]. ethercrab rounds
    /// `system time + start_delay` *down* to a whole cycle, so a delay under one cycle gives
    /// a start time in the past, which the ESC (32-bit start-time compare) reaches only when
    /// the lower 32 bits of the system time come round again, ≈4.29 s later: the node is in
    /// OP without SYNC0, takes no outputs, and its supervisor reports `ERR_ECAT_COMM_LOST`
    /// (1302) until SYNC0 starts. The default is two cycles.
    pub dc_start_delay_ns: u64,
}

/// The steps [`run_scenario`] runs after the bring-up.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Script {
    /// Overheat, a sensor unplugged, a CRC fault, the cable open for 2 s.
    #[default]
    Faults,
    /// Every COMMAND of 0x7000 (custom colour, LED toggle, state colours, threshold), a
    /// refused argument (1305), an unknown code (1306), and the master taking the node to
    /// INIT (warning colour, EVENT 2312) and back to OP.
    Commands,
    /// LED faults: a guard timer refused (1204) and a channel that cannot be configured
    /// (1201), a DMA stream that stalls (1202) and keeps stalling (1205); the channel
    /// restarts and the rings recover.
    LedFaults,
    /// Every sensor unplugged: 1102, then the temperature task faulty (1105) and restarting;
    /// plugged back: cleared.
    TempBusLost,
    /// The ESC's AL status changed behind the stack's back (a corrupted PDI write): the
    /// EtherCAT task is out of step (1304) and re-creates the stack; the master brings the
    /// node back to OP.
    EscStateGlitch,
}

impl Default for ScenarioConfig {
    fn default() -> Self {
        Self {
            sync: HubSync::FreeRun,
            cycle_ns: 10_000_000,
            bring_up_only: false,
            hub: HubConfig::default(),
            heat_amps: 6.0,
            script: Script::Faults,
            dc_start_delay_ns: 20_000_000,
        }
    }
}

/// The inputs of one cycle as the master decodes them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct HubInputs {
    /// 0x6000: temperatures in 0.01 °C.
    pub temps: [i16; device::SENSORS],
    /// 0x6001:01 STATUS.
    pub status: u32,
    /// 0x6001:02 EVENT.
    pub event: u16,
    /// 0x6001:03 ERROR.
    pub error: u16,
}

impl HubInputs {
    /// Decodes the 38 input bytes (shorter images give zeros).
    pub fn parse(b: &[u8]) -> Self {
        let u16_at = |i: usize| match b.get(i..i + 2) {
            Some(s) => u16::from_le_bytes([s[0], s[1]]),
            None => 0,
        };
        let mut temps = [0i16; device::SENSORS];
        for (k, t) in temps.iter_mut().enumerate() {
            *t = u16_at(2 * k) as i16;
        }
        Self {
            temps,
            status: u16_at(30) as u32 | (u16_at(32) as u32) << 16,
            event: u16_at(34),
            error: u16_at(36),
        }
    }
}

/// One checkpoint of the scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct Checkpoint {
    /// What was expected.
    pub what: String,
    /// Reached.
    pub ok: bool,
    /// Virtual time \[s\] when it was reached (or given up).
    pub t_s: f64,
    /// What the master and the node showed.
    pub detail: String,
}

/// The scenario's outcome.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ScenarioReport {
    /// Checkpoints in order.
    pub checkpoints: Vec<Checkpoint>,
    /// Cycles the master ran.
    pub cycles: u64,
    /// Sensors the hub's ROM search found.
    pub sensors_found: usize,
    /// Error codes the master saw in 0x6001:03, in order of appearance.
    pub errors_seen: Vec<u16>,
    /// Event codes the master saw in 0x6001:02, in order of appearance.
    pub events_seen: Vec<u16>,
    /// DC: the SYNC0 start time in the ESC (0x0990) at the end, and the system time then
    /// (0x0910) \[ns\].
    pub dc_start: Option<(u64, u64)>,
}

impl ScenarioReport {
    /// True when every checkpoint was reached.
    pub fn ok(&self) -> bool {
        !self.checkpoints.is_empty() && self.checkpoints.iter().all(|c| c.ok)
    }
}

enum Req {
    Cycle([u16; 4]),
    AckOp,
    /// Writes AL control.
    Al(u16),
    /// SDO upload.
    Sdo(u16, u8),
}

fn lock(s: &Arc<Mutex<Segment>>) -> MutexGuard<'_, Segment> {
    s.lock().unwrap_or_else(|e| e.into_inner())
}

/// A BRD of AL status straight onto the segment: `Some(wkc)` if a frame came back.
fn probe(seg: &Arc<Mutex<Segment>>) -> Option<u16> {
    use oxicat_wire::{Command, DatagramHeader, EcatFrame, EthernetHeader, FrameBuilder};
    let mut buf = [0u8; 64];
    let eth = EthernetHeader {
        dst: [0xFF; 6],
        src: [0x10; 6],
        vlan_tci: None,
        payload_offset: 14,
    };
    let mut b = FrameBuilder::new(&mut buf, &eth).ok()?;
    b.push(
        DatagramHeader::physical(Command::Brd, 0x7F, 0, 0x0130, 2),
        &[0, 0],
    )
    .ok()?;
    let n = b.finish();
    let back = lock(seg).exchange(&buf[..n])?;
    let (_, f) = EcatFrame::parse_ethernet(&back).ok()?;
    let wkc = f.datagrams().next()?.ok()?.wkc;
    Some(wkc)
}

struct Run<'a> {
    seg: Arc<Mutex<Segment>>,
    id: SlaveId,
    hub: HubHandle,
    cycle_ns: u64,
    out: [u16; 4],
    last: HubInputs,
    report: ScenarioReport,
    log: &'a mut dyn FnMut(&str),
}

impl Run<'_> {
    fn now_s(&self) -> f64 {
        lock(&self.seg).now() as f64 * 1e-9
    }

    fn shown(&self) -> String {
        let h = self.hub.lock();
        let d = h.ring(0);
        let c = d.colors.first().copied().unwrap_or_default();
        format!(
            "LED ring 0 ({:?}) rgb({},{},{}){}",
            h.app.led.shown,
            c.r,
            c.g,
            c.b,
            if d.bad_bits.is_empty() {
                ""
            } else {
                " BAD TIMING"
            }
        )
    }

    fn ring_is(&self, want: ws2812::Rgb) -> bool {
        let h = self.hub.lock();
        (0..ws2812::RINGS).all(|r| {
            let d = h.ring(r);
            d.latched
                && d.bad_bits.is_empty()
                && d.colors.len() == ws2812::LEDS_PER_RING
                && d.colors
                    .iter()
                    .all(|c| (c.r, c.g, c.b) == (want.r, want.g, want.b))
        })
    }

    fn note(&mut self, what: &str, ok: bool) {
        let detail = format!(
            "ERROR {} EVENT {} STATUS {:#010x} (state {}), {}",
            self.last.error,
            self.last.event,
            self.last.status,
            self.last.status & 0xF,
            self.shown()
        );
        let t_s = self.now_s();
        (self.log)(&format!(
            "[{t_s:7.2} s] {} {what}: {detail}",
            if ok { "ok  " } else { "FAIL" }
        ));
        self.report.checkpoints.push(Checkpoint {
            what: what.to_string(),
            ok,
            t_s,
            detail,
        });
    }

    fn seen(&mut self, i: &HubInputs) {
        if i.error != 0 && self.report.errors_seen.last() != Some(&i.error) {
            self.report.errors_seen.push(i.error);
        }
        if i.event != 0 && self.report.events_seen.last() != Some(&i.event) {
            self.report.events_seen.push(i.event);
        }
        self.last = *i;
    }
}

/// Runs `n` cycles or until `until` holds; returns whether it held.
async fn cycles_until<F>(
    run: &mut Run<'_>,
    xchg: &mut F,
    max_s: f64,
    mut until: impl FnMut(&Run<'_>, &HubInputs) -> bool,
) -> Result<bool, String>
where
    F: AsyncFnMut(Req) -> Result<Vec<u8>, String>,
{
    let n = (max_s * 1e9 / run.cycle_ns as f64).ceil() as u64;
    for _ in 0..n {
        lock(&run.seg).advance_by(run.cycle_ns);
        let raw = xchg(Req::Cycle(run.out)).await?;
        run.report.cycles += 1;
        let i = HubInputs::parse(&raw);
        run.seen(&i);
        if until(run, &i) {
            return Ok(true);
        }
    }
    Ok(false)
}

async fn run_script<F>(run: &mut Run<'_>, xchg: &mut F, cfg: &ScenarioConfig) -> Result<(), String>
where
    F: AsyncFnMut(Req) -> Result<Vec<u8>, String>,
{
    bring_up(run, xchg, cfg).await?;
    if cfg.bring_up_only {
        return Ok(());
    }
    match cfg.script {
        Script::Faults => faults(run, xchg, cfg).await,
        Script::Commands => commands(run, xchg).await,
        Script::LedFaults => led_faults(run, xchg).await,
        Script::TempBusLost => temp_bus_lost(run, xchg, cfg).await,
        Script::EscStateGlitch => esc_state_glitch(run, xchg).await,
    }
}

async fn bring_up<F>(run: &mut Run<'_>, xchg: &mut F, cfg: &ScenarioConfig) -> Result<(), String>
where
    F: AsyncFnMut(Req) -> Result<Vec<u8>, String>,
{
    use codes::*;
    use ws2812::COLOR_NORMAL;
    let ambient = (cfg.hub.ambient * 100.0) as i32;
    let sensors = cfg.hub.sensors.min(device::SENSORS);
    let ok = cycles_until(run, xchg, 6.0, |r, i| {
        i.status & 0xF == STATUS_NO_ERRORS as u32
            && i.temps[..sensors]
                .iter()
                .all(|&t| (t as i32 - ambient).abs() < 100)
            && r.ring_is(COLOR_NORMAL)
    })
    .await?;
    run.report.sensors_found = run.hub.lock().app.temp.roms().len();
    run.note(
        &format!(
            "OP, {} sensors found by ROM search, temperatures at ambient, LEDs normal",
            run.report.sensors_found
        ),
        ok && run.report.sensors_found == sensors,
    );
    Ok(())
}

async fn faults<F>(run: &mut Run<'_>, xchg: &mut F, cfg: &ScenarioConfig) -> Result<(), String>
where
    F: AsyncFnMut(Req) -> Result<Vec<u8>, String>,
{
    use codes::*;
    use ws2812::{COLOR_ERROR, COLOR_NORMAL, COLOR_WARNING};

    // 1. A motor heats: overheat (hard) -> red, 1104 at the master; it cools -> cleared.
    run.hub.lock().set_motor_current(0, cfg.heat_amps);
    (run.log)(&format!("motor 0: {} A through its winding", cfg.heat_amps));
    let ok = cycles_until(run, xchg, 30.0, |r, i| {
        i.error == ERR_TEMP_SENS_OVERHEAT && r.ring_is(COLOR_ERROR)
    })
    .await?;
    let hottest = run.last.temps.iter().copied().max().unwrap_or(0);
    run.note(
        &format!(
            "overheat: ERROR 1104 at the master, LEDs red (hottest {:.2} °C)",
            hottest as f64 / 100.0
        ),
        ok && run.last.status & 0xF == STATUS_HARD_ERRORS as u32,
    );
    run.hub.lock().set_motor_current(0, 0.0);
    (run.log)("motor 0: current off");
    let ok = cycles_until(run, xchg, 30.0, |r, i| {
        i.error == ERR_SYS_NONE && r.ring_is(COLOR_NORMAL)
    })
    .await?;
    run.note("cooled: error cleared, LEDs normal", ok);

    // 2. A sensor unplugged: soft error, warning colour; plugged back: cleared.
    run.hub.lock().plug_sensor(5, false);
    (run.log)("sensor 5 unplugged");
    let ok = cycles_until(run, xchg, 5.0, |r, i| {
        i.error == ERR_TEMP_SENS_LOST && r.ring_is(COLOR_WARNING)
    })
    .await?;
    run.note(
        "sensor lost: ERROR 1102 (soft), LEDs warning, its value invalid",
        ok && run.last.temps[5] == device::TEMP_INVALID
            && run.last.status & 0xF == STATUS_SOFT_ERRORS as u32,
    );
    run.hub.lock().plug_sensor(5, true);
    let ok = cycles_until(run, xchg, 5.0, |r, i| {
        i.error == ERR_SYS_NONE && i.temps[5] != device::TEMP_INVALID && r.ring_is(COLOR_NORMAL)
    })
    .await?;
    run.note("sensor plugged back: cleared", ok);

    // 3. A CRC fault on one read: detected (soft), the bad value is not published.
    let crc_before = run.hub.lock().app.temp.stats.crc_errors;
    run.hub.lock().corrupt_sensor(2, 1);
    let ok = cycles_until(run, xchg, 5.0, |_, i| i.error == ERR_TEMP_SENS_CRC).await?;
    let crc_after = run.hub.lock().app.temp.stats.crc_errors;
    run.note(
        "scratchpad CRC error: detected, ERROR 1106 (soft)",
        ok && crc_after == crc_before + 1,
    );
    let ok = cycles_until(run, xchg, 5.0, |_, i| i.error == ERR_SYS_NONE).await?;
    run.note("next read good: cleared", ok);

    // 4. The cable opened for 2 s.
    lock(&run.seg)
        .set_cable(0, 0, false)
        .map_err(|e| e.to_string())?;
    (run.log)("cable to the master opened");
    let t_open = lock(&run.seg).now();
    let releases_before = run.hub.lock().releases();
    let mut answered = 0;
    let step = run.cycle_ns;
    while lock(&run.seg).now() < t_open + 2_000_000_000 {
        lock(&run.seg).advance_by(step);
        if probe(&run.seg).is_some() {
            answered += 1;
        }
    }
    let (phase, active, releases, state) = {
        let h = run.hub.lock();
        (
            h.sup.phase,
            h.app.sys.is_active(ERR_ECAT_COMM_LOST),
            h.releases(),
            h.slave().map(|s| (s.state(), s.status_code())),
        )
    };
    let phase_text = match phase {
        axis_hub::EcatPhase::Fault => "ESC fault",
        axis_hub::EcatPhase::Connected => "connected",
        axis_hub::EcatPhase::CommLost => "communication lost",
    };
    let state = match state {
        Some((s, c)) => format!("{s}, AL status 0x{:04X}", c.0),
        None => "not running".to_string(),
    };
    run.note(
        &format!(
            "cable open 2 s: node reports communication lost (phase: {phase_text}; stack: {state}), \
             keeps running ({} task releases), LEDs red, no frame came back",
            releases - releases_before
        ),
        active
            && phase == axis_hub::EcatPhase::CommLost
            && releases > releases_before + 100
            && answered == 0
            && run.ring_is(COLOR_ERROR),
    );
    lock(&run.seg)
        .set_cable(0, 0, true)
        .map_err(|e| e.to_string())?;
    (run.log)("cable closed; the master resumes: acknowledges the error and requests OP");
    xchg(Req::AckOp).await?;
    let ok = cycles_until(run, xchg, 3.0, |_, i| i.error == ERR_ECAT_COMM_LOST).await?;
    run.note(
        "master reads ERROR 1302 (communication lost) from the node",
        ok,
    );
    let ok = cycles_until(run, xchg, 5.0, |r, i| {
        i.error == ERR_SYS_NONE
            && i.status >> 18 == EV_ECAT_APP_OP as u32
            && r.ring_is(COLOR_NORMAL)
    })
    .await?;
    let st = run.hub.lock().slave().map(|s| s.state());
    let st_text = st.map_or("stack not running".to_string(), |s| s.to_string());
    run.note(
        &format!("back in OP without a reset ({st_text}), error cleared, LEDs normal"),
        ok && st == Some(oxicat_slave::AlState::Op),
    );
    Ok(())
}

/// Runs cycles with outputs `out` until `until` holds (at most `max_s`), notes `what`.
async fn expect<F>(
    run: &mut Run<'_>,
    xchg: &mut F,
    what: &str,
    out: [u16; 4],
    max_s: f64,
    until: impl FnMut(&Run<'_>, &HubInputs) -> bool,
) -> Result<bool, String>
where
    F: AsyncFnMut(Req) -> Result<Vec<u8>, String>,
{
    run.out = out;
    let ok = cycles_until(run, xchg, max_s, until).await?;
    run.note(what, ok);
    Ok(ok)
}

/// Walks the node INIT → PRE-OP → SAFE-OP → OP with AL control writes, cycling between them.
async fn back_to_op<F>(run: &mut Run<'_>, xchg: &mut F) -> Result<(), String>
where
    F: AsyncFnMut(Req) -> Result<Vec<u8>, String>,
{
    for al in [0x0002, 0x0004, 0x0008] {
        xchg(Req::Al(al)).await?;
        cycles_until(run, xchg, 0.3, |_, _| false).await?;
    }
    Ok(())
}

async fn commands<F>(run: &mut Run<'_>, xchg: &mut F) -> Result<(), String>
where
    F: AsyncFnMut(Req) -> Result<Vec<u8>, String>,
{
    use codes::*;
    use device::{CMD_LED_AUTO, CMD_LED_CUSTOM, CMD_LED_TOGGLE, CMD_SET_THRESHOLD};
    use ws2812::{Rgb, COLOR_ERROR, COLOR_NORMAL, COLOR_WARNING};
    let custom = Rgb::new(10, 20, 30);
    let general = |i: &HubInputs| (i.status & 0xF) as u8;
    expect(
        run,
        xchg,
        "COMMAND 1 (10, 20, 30): EVENT 2351, rings show the custom colour",
        [CMD_LED_CUSTOM, 10, 20, 30],
        1.0,
        |r, i| i.event == EV_ECAT_CMD_ACK && i.error == 0 && r.ring_is(custom),
    )
    .await?;
    expect(
        run,
        xchg,
        "COMMAND 4: EVENT 2352, rings off",
        [CMD_LED_TOGGLE, 0, 0, 0],
        1.0,
        |r, i| i.event == EV_ECAT_CMD_LED_TOGGLE && r.ring_is(Rgb::new(0, 0, 0)),
    )
    .await?;
    run.out = [0; 4];
    cycles_until(run, xchg, 0.05, |_, _| false).await?;
    expect(
        run,
        xchg,
        "COMMAND 0 then 4 again: rings on again with the custom colour",
        [CMD_LED_TOGGLE, 0, 0, 0],
        1.0,
        |r, i| i.event == EV_ECAT_CMD_LED_TOGGLE && r.ring_is(custom),
    )
    .await?;
    expect(
        run,
        xchg,
        "COMMAND 2: EVENT 2351, state colours (normal)",
        [CMD_LED_AUTO, 0, 0, 0],
        1.0,
        |r, i| i.event == EV_ECAT_CMD_ACK && r.ring_is(COLOR_NORMAL),
    )
    .await?;
    expect(
        run,
        xchg,
        "COMMAND 1 (300, 0, 0): refused, ERROR 1305 (hard), rings red",
        [CMD_LED_CUSTOM, 300, 0, 0],
        1.0,
        |r, i| {
            i.error == ERR_ECAT_CMD_FAULT
                && general(i) == STATUS_HARD_ERRORS
                && r.ring_is(COLOR_ERROR)
        },
    )
    .await?;
    expect(
        run,
        xchg,
        "COMMAND 2: acknowledged, 1305 cleared, rings normal",
        [CMD_LED_AUTO, 0, 0, 0],
        1.0,
        |r, i| i.event == EV_ECAT_CMD_ACK && i.error == 0 && r.ring_is(COLOR_NORMAL),
    )
    .await?;
    expect(
        run,
        xchg,
        "COMMAND 99: not understood, ERROR 1306 (soft), rings warning",
        [99, 0, 0, 0],
        1.0,
        |r, i| {
            i.error == ERR_ECAT_CMD_SOFTFAULT
                && general(i) == STATUS_SOFT_ERRORS
                && r.ring_is(COLOR_WARNING)
        },
    )
    .await?;
    expect(
        run,
        xchg,
        "COMMAND 3 (24.00 °C): acknowledged, the sensors at 25 °C overheat: ERROR 1104",
        [CMD_SET_THRESHOLD, 2400, 0, 0],
        3.0,
        |r, i| i.error == ERR_TEMP_SENS_OVERHEAT && r.ring_is(COLOR_ERROR),
    )
    .await?;
    expect(
        run,
        xchg,
        "COMMAND 3 (80.00 °C): overheat cleared",
        [CMD_SET_THRESHOLD, 8000, 0, 0],
        3.0,
        |r, i| i.error == 0 && r.ring_is(COLOR_NORMAL),
    )
    .await?;
    expect(
        run,
        xchg,
        "COMMAND 3 (200.00 °C, outside −55 … 125 °C): refused, ERROR 1305",
        [CMD_SET_THRESHOLD, 20000, 0, 0],
        1.0,
        |_, i| i.error == ERR_ECAT_CMD_FAULT,
    )
    .await?;
    let kept = run.hub.lock().app.temp.threshold;
    run.note(
        "the refused threshold was not taken (80.00 °C kept)",
        kept == 8000,
    );
    expect(
        run,
        xchg,
        "COMMAND 2: cleared",
        [CMD_LED_AUTO, 0, 0, 0],
        1.0,
        |_, i| i.error == 0,
    )
    .await?;
    // The master takes the node to INIT: the report's INIT warning colour.
    xchg(Req::Al(0x0001)).await?;
    let ok = cycles_until(run, xchg, 1.0, |r, _| {
        let h = r.hub.lock();
        h.slave().map(|s| s.state()) == Some(oxicat_slave::AlState::Init)
            && h.app.sys.last_event() == EV_ECAT_APP_INIT
    })
    .await?;
    let ok = ok && cycles_until(run, xchg, 0.2, |r, _| r.ring_is(COLOR_WARNING)).await?;
    run.note(
        "master requests INIT: the rings show the warning colour",
        ok,
    );
    xchg(Req::Al(0x0002)).await?;
    cycles_until(run, xchg, 0.3, |_, _| false).await?;
    let ev = xchg(Req::Sdo(0x6001, 2)).await?;
    let st = xchg(Req::Sdo(0x6001, 1)).await?;
    let ev = ev.get(..2).map(|b| u16::from_le_bytes([b[0], b[1]]));
    let st = st
        .get(..4)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    let warm = run.ring_is(COLOR_WARNING);
    run.note(
        &format!(
            "PRE-OP: SDO 0x6001:02 EVENT = {ev:?} (2312), STATUS last event {:?}; still warning",
            st.map(|s| s >> 18)
        ),
        ev == Some(EV_ECAT_APP_INIT)
            && st.map(|s| s >> 18) == Some(EV_ECAT_APP_INIT as u32)
            && warm,
    );
    for al in [0x0004, 0x0008] {
        xchg(Req::Al(al)).await?;
        cycles_until(run, xchg, 0.3, |_, _| false).await?;
    }
    expect(
        run,
        xchg,
        "back in OP: EVENT 2311, rings normal",
        [0; 4],
        2.0,
        |r, i| i.event == EV_ECAT_APP_OP && i.error == 0 && r.ring_is(COLOR_NORMAL),
    )
    .await?;
    Ok(())
}

async fn led_faults<F>(run: &mut Run<'_>, xchg: &mut F) -> Result<(), String>
where
    F: AsyncFnMut(Req) -> Result<Vec<u8>, String>,
{
    use codes::*;
    use ws2812::{COLOR_ERROR, COLOR_NORMAL};
    let restarts = |r: &Run<'_>| r.hub.lock().app.strip.restarted;
    let before = restarts(run);
    {
        let mut h = run.hub.lock();
        h.app.strip.fail_guard = 1;
        h.app.strip.fail_configure = 1;
    }
    (run.log)("LED guard timer refused once, then one channel set-up fails");
    expect(
        run,
        xchg,
        "ERROR 1204 (guard timer could not be armed)",
        [0; 4],
        1.0,
        |_, i| i.error == ERR_LED_OSTIM,
    )
    .await?;
    expect(
        run,
        xchg,
        "ERROR 1201 (channel set-up failed on the restart)",
        [0; 4],
        1.0,
        |_, i| i.error == ERR_LED_INIT,
    )
    .await?;
    expect(
        run,
        xchg,
        "configured again: EVENT 2211, error cleared, rings normal",
        [0; 4],
        1.0,
        |r, i| i.event == EV_LED_UPTD && i.error == 0 && r.ring_is(COLOR_NORMAL),
    )
    .await?;
    let after = restarts(run);
    run.note(
        &format!("both channels restarted twice ({before:?} → {after:?})"),
        after.iter().zip(before.iter()).all(|(a, b)| *a == b + 2),
    );
    run.hub.lock().app.strip.stalled[1] = true;
    (run.log)("ring 1's DMA stream stalls");
    expect(
        run,
        xchg,
        "ERROR 1202 (transfer not complete in 1 s)",
        [0; 4],
        2.0,
        |_, i| i.error == ERR_LED_TIMEOUT,
    )
    .await?;
    expect(
        run,
        xchg,
        "still stalled after 3 restarts: ERROR 1205 (hard), ring 0 red",
        [0; 4],
        5.0,
        |r, i| {
            let d = r.hub.lock().ring(0);
            i.error == ERR_LED_DSM_FAULT
                && i.status & 0xF == STATUS_HARD_ERRORS as u32
                && d.colors
                    .iter()
                    .all(|c| (c.r, c.g, c.b) == (COLOR_ERROR.r, COLOR_ERROR.g, COLOR_ERROR.b))
        },
    )
    .await?;
    run.hub.lock().app.strip.stalled[1] = false;
    (run.log)("ring 1's DMA stream works again");
    expect(
        run,
        xchg,
        "next restart delivers: EVENT 2211, errors cleared, both rings normal",
        [0; 4],
        3.0,
        |r, i| i.error == 0 && i.event == EV_LED_UPTD && r.ring_is(COLOR_NORMAL),
    )
    .await?;
    Ok(())
}

async fn temp_bus_lost<F>(
    run: &mut Run<'_>,
    xchg: &mut F,
    cfg: &ScenarioConfig,
) -> Result<(), String>
where
    F: AsyncFnMut(Req) -> Result<Vec<u8>, String>,
{
    use codes::*;
    use ws2812::{COLOR_ERROR, COLOR_NORMAL};
    let n = cfg.hub.sensors;
    for k in 0..n {
        run.hub.lock().plug_sensor(k, false);
    }
    (run.log)("every sensor unplugged (the bus cable pulled)");
    expect(
        run,
        xchg,
        "ERROR 1102 (sensors lost, soft)",
        [0; 4],
        3.0,
        |_, i| i.error == ERR_TEMP_SENS_LOST,
    )
    .await?;
    expect(
        run,
        xchg,
        "no sensor for 3 read-outs: ERROR 1105 (hard), rings red, task restarted",
        [0; 4],
        6.0,
        |r, i| {
            i.error == ERR_TEMP_DSM_FAULT
                && r.ring_is(COLOR_ERROR)
                && r.hub.lock().app.temp.stats.restarts == 1
        },
    )
    .await?;
    for k in 0..n {
        run.hub.lock().plug_sensor(k, true);
    }
    (run.log)("sensors plugged back");
    expect(
        run,
        xchg,
        "ROM search finds them: errors cleared, temperatures valid, rings normal",
        [0; 4],
        6.0,
        |r, i| {
            i.error == 0
                && i.temps[..n.min(device::SENSORS)]
                    .iter()
                    .all(|&t| t != device::TEMP_INVALID)
                && r.ring_is(COLOR_NORMAL)
        },
    )
    .await?;
    Ok(())
}

async fn esc_state_glitch<F>(run: &mut Run<'_>, xchg: &mut F) -> Result<(), String>
where
    F: AsyncFnMut(Req) -> Result<Vec<u8>, String>,
{
    use codes::*;
    use ws2812::COLOR_NORMAL;
    {
        let mut g = lock(&run.seg);
        let esc = g.esc_mut(run.id).ok_or("no ESC")?;
        esc.pdi_write(0x0130, &[0x01, 0x00])
            .map_err(|e| format!("{e:?}"))?;
    }
    (run.log)("AL status 0x0130 overwritten with INIT behind the stack's back");
    let ok = cycles_until(run, xchg, 1.0, |r, _| r.hub.lock().sup.dsm_faults == 1).await?;
    let (state, active) = {
        let h = run.hub.lock();
        (
            h.slave().map(|s| s.state()),
            h.app.sys.is_active(ERR_ECAT_DSM_FAULT),
        )
    };
    run.note(
        "the EtherCAT task sees the mismatch and re-creates the stack (INIT)",
        ok && state == Some(oxicat_slave::AlState::Init) && active,
    );
    back_to_op(run, xchg).await?;
    let seen = run.report.errors_seen.contains(&ERR_ECAT_DSM_FAULT);
    run.note(
        "the master, walking the node back to OP, reads ERROR 1304",
        seen,
    );
    expect(
        run,
        xchg,
        "in OP again: EVENT 2311, error cleared, rings normal",
        [0; 4],
        2.0,
        |r, i| i.error == 0 && i.event == EV_ECAT_APP_OP && r.ring_is(COLOR_NORMAL),
    )
    .await?;
    Ok(())
}

/// Builds a segment with one hub (ESC from `sii`), brings it to OP with ethercrab in the
/// same process and runs the scenario; `log` gets one line per step.
pub fn run_scenario(
    sii: Vec<u8>,
    cfg: &ScenarioConfig,
    log: &mut dyn FnMut(&str),
) -> Result<ScenarioReport, String> {
    let mut seg = Segment::new();
    let id = seg.add(hub_esc(sii));
    let hub = attach_hub(&mut seg, id, &cfg.hub).map_err(|e| e.to_string())?;
    let seg = Arc::new(Mutex::new(seg));
    let storage: &'static PduStorage<16, { PduStorage::element_size(1100) }> =
        Box::leak(Box::new(PduStorage::new()));
    let (tx, rx, pdu_loop) = storage
        .try_split()
        .map_err(|_| "PDU storage in use".to_string())?;
    // The transport polled on this thread beside the scenario (no hand-over per frame).
    let pipe: Arc<Mutex<dyn oxicat_wire::pipe::FramePipe + Send>> = seg.clone();
    let task = inprocess_task(
        pipe,
        tx,
        rx,
        InProcessConfig {
            frame_gap_ns: 10_000,
        },
    );
    let runner = Runner::with_task(task);
    let md = MainDevice::new(
        pdu_loop,
        virtual_timeouts(),
        MainDeviceConfig {
            dc_static_sync_iterations: 100,
            ..MainDeviceConfig::default()
        },
    );
    let clock = lock(&seg).clock();
    let mut run = Run {
        seg: seg.clone(),
        id,
        hub,
        cycle_ns: cfg.cycle_ns,
        out: [0; 4],
        last: HubInputs::default(),
        report: ScenarioReport::default(),
        log,
    };
    let e = |w: &'static str| move |e: ethercrab::error::Error| format!("{w}: {e}");
    runner.block_on(async {
        let mut group = md
            .init_single_group::<2, 128>(move || clock.now())
            .await
            .map_err(e("discovery"))?;
        let mode: u16 = match cfg.sync {
            HubSync::FreeRun => 0,
            HubSync::SmSync => 1,
            HubSync::Dc => 2,
        };
        for mut sd in group.iter_mut(&md) {
            sd.sdo_write(0x1C32, 1, mode)
                .await
                .map_err(e("0x1C32:01 (sync type)"))?;
            if cfg.sync == HubSync::Dc {
                sd.set_dc_sync(DcSync::Sync0);
            }
        }
        let group = group
            .into_pre_op_pdi(&md)
            .await
            .map_err(e("PDO configuration"))?;
        if cfg.sync == HubSync::Dc {
            let group = group
                .configure_dc_sync(
                    &md,
                    DcConfiguration {
                        start_delay: Duration::from_nanos(cfg.dc_start_delay_ns),
                        sync0_period: Duration::from_nanos(cfg.cycle_ns),
                        sync0_shift: Duration::from_nanos(cfg.cycle_ns / 2),
                    },
                )
                .await
                .map_err(e("DC configuration"))?;
            let group = group.into_safe_op(&md).await.map_err(e("SAFE-OP"))?;
            let group = group.request_into_op(&md).await.map_err(e("OP request"))?;
            let mut xchg = async |r: Req| match r {
                Req::Cycle(out) => {
                    for sd in group.iter(&md) {
                        set_outputs(&mut sd.outputs_raw_mut(), out);
                    }
                    group.tx_rx_dc(&md).await.map_err(e("cycle"))?;
                    Ok(group
                        .iter(&md)
                        .next()
                        .map(|s| s.inputs_raw().to_vec())
                        .unwrap_or_default())
                }
                Req::AckOp => {
                    for sd in group.iter(&md) {
                        sd.register_write(0x0120u16, 0x0018u16)
                            .await
                            .map_err(e("AL control"))?;
                    }
                    Ok(Vec::new())
                }
                Req::Al(v) => {
                    for sd in group.iter(&md) {
                        sd.register_write(0x0120u16, v)
                            .await
                            .map_err(e("AL control"))?;
                    }
                    Ok(Vec::new())
                }
                Req::Sdo(index, sub) => match group.iter(&md).next() {
                    Some(sd) if sub == 1 => sd
                        .sdo_read::<u32>(index, sub)
                        .await
                        .map(|v| v.to_le_bytes().to_vec())
                        .map_err(e("SDO upload")),
                    Some(sd) => sd
                        .sdo_read::<u16>(index, sub)
                        .await
                        .map(|v| v.to_le_bytes().to_vec())
                        .map_err(e("SDO upload")),
                    None => Ok(Vec::new()),
                },
            };
            run_script(&mut run, &mut xchg, cfg).await
        } else {
            let group = group.into_op(&md).await.map_err(e("OP"))?;
            let mut xchg = async |r: Req| match r {
                Req::Cycle(out) => {
                    for sd in group.iter(&md) {
                        set_outputs(&mut sd.outputs_raw_mut(), out);
                    }
                    group.tx_rx(&md).await.map_err(e("cycle"))?;
                    Ok(group
                        .iter(&md)
                        .next()
                        .map(|s| s.inputs_raw().to_vec())
                        .unwrap_or_default())
                }
                Req::AckOp => {
                    for sd in group.iter(&md) {
                        sd.register_write(0x0120u16, 0x0018u16)
                            .await
                            .map_err(e("AL control"))?;
                    }
                    Ok(Vec::new())
                }
                Req::Al(v) => {
                    for sd in group.iter(&md) {
                        sd.register_write(0x0120u16, v)
                            .await
                            .map_err(e("AL control"))?;
                    }
                    Ok(Vec::new())
                }
                Req::Sdo(index, sub) => match group.iter(&md).next() {
                    Some(sd) if sub == 1 => sd
                        .sdo_read::<u32>(index, sub)
                        .await
                        .map(|v| v.to_le_bytes().to_vec())
                        .map_err(e("SDO upload")),
                    Some(sd) => sd
                        .sdo_read::<u16>(index, sub)
                        .await
                        .map(|v| v.to_le_bytes().to_vec())
                        .map_err(e("SDO upload")),
                    None => Ok(Vec::new()),
                },
            };
            run_script(&mut run, &mut xchg, cfg).await
        }
    })?;
    if cfg.sync == HubSync::Dc {
        let mut g = lock(&seg);
        if let Some(esc) = g.esc_mut(id) {
            let mut b = [0u8; 16];
            if esc.pdi_read(0x0990, &mut b[..8]).is_ok()
                && esc.pdi_read(0x0910, &mut b[8..]).is_ok()
            {
                let w = |k: usize| {
                    let mut x = [0u8; 8];
                    x.copy_from_slice(&b[k..k + 8]);
                    u64::from_le_bytes(x)
                };
                run.report.dc_start = Some((w(0), w(8)));
            }
        }
    }
    Ok(run.report)
}

fn set_outputs(o: &mut [u8], v: [u16; 4]) {
    for (k, x) in v.iter().enumerate() {
        if let Some(s) = o.get_mut(2 * k..2 * k + 2) {
            s.copy_from_slice(&x.to_le_bytes());
        }
    }
}

/// The resolution the firmware read from sensor `i`'s configuration register.
pub fn sensor_resolution(hub: &HubHandle, i: usize) -> Option<onewire::Resolution> {
    hub.lock().app.temp.resolution(i)
}

/// The axis communication hub in the registry.
pub const KIT: crate::registry::Kit = crate::registry::Kit {
    name: "axis-hub",
    description: "axis communication hub (LAN9252): 15 DS18B20 on 1-Wire in motor housings, \
                  WS2812 LED rings, status/event/error objects",
    def: |_| &crate::axis_hub::device::DEF,
    esc: EscConfig::lan9252,
    attach: |segment, id, _k, route| match route {
        PdiRoute::Direct => attach_hub(segment, id, &HubConfig::default()).map(drop),
        route => attach_hub_via(segment, id, &HubConfig::default(), route).map(drop),
    },
    sync: oxicat_slave::SyncMode::DcSync0,
    cycle_ns: 1_000_000,
};
