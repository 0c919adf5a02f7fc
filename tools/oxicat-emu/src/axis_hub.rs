//! The axis hub on the pins of its board image (`firmware/axis-hub`) as a [`BoardPlant`]:
//! the host rig's 1-Wire bus (`oxicat_plant::onewire::OneWireNet`: DS18B20 models with ROM
//! search, conversions in virtual time and CRC-8) on USART3's half-duplex TX line, and the
//! two WS2812 rings decoded (`oxicat_plant::ws2812::decode`, the datasheet timing) from the
//! compare values DMA wrote into the rings' timers.
//!
//! | image side | pins / registers | plant side |
//! |---|---|---|
//! | 1-Wire master | USART3 TX (PB10), half-duplex; reset 0xF0 at 9600 baud, slots at 115200 | `OneWireNet` (15 DS18B20, the rig's ROM codes), die temperatures set by the test |
//! | LED ring 1 | TIM8 CH1 (PC6), CCR1 fed by DMA2 stream 1 on TIM8_UP | 5 WS2812B |
//! | LED ring 2 | TIM3 CH2 (PC7), CCR2 fed by DMA1 stream 2 on TIM3_UP | 5 WS2812B |
//!
//! The bus is attached at the first step (before the image's first byte: the first step is
//! at time 0). Every step (1 ms) sets the sensors' die temperatures and decodes the rings'
//! last finished DMA transfers; the test reads both through [`HubView`].

use std::sync::{Arc, Mutex, MutexGuard};

use oxicat_devices::axis_hub::device::SENSORS;
use oxicat_devices::axis_hub::ws2812::LEDS_PER_RING;
use oxicat_plant::onewire::{ds18b20_rom, Ds18b20, OneWireNet};
use oxicat_plant::ws2812::{decode, Decoded};

use crate::plant::BoardPlant;
use crate::Board;

/// USART of the 1-Wire bus.
pub const ONEWIRE_USART: u8 = 3;
/// The rings: (timer, compare register offset).
pub const RINGS: [(u8, u64); 2] = [(8, 0x34), (3, 0x38)];

/// What the test sets and reads while the board runs on its own thread.
#[derive(Debug, Clone, Default)]
pub struct HubState {
    /// Die temperature per sensor \[°C\].
    pub temps: Vec<f64>,
    /// Sensor plugged.
    pub plugged: Vec<bool>,
    /// Each ring's last decoded stream (`None`: no transfer finished yet, or the channel
    /// is not in PWM with its output on).
    pub rings: [Option<Decoded>; 2],
    /// Finished transfers seen per ring.
    pub transfers: [u64; 2],
    /// 1-Wire resets / presences / slots the USART put on the bus.
    pub onewire: crate::usart::OneWireStats,
    /// Conversions the sensors did.
    pub conversions: u64,
}

/// A handle on the plant's state.
#[derive(Debug, Clone)]
pub struct HubView(Arc<Mutex<HubState>>);

impl HubView {
    /// The state (poisoning ignored: the data stays usable).
    pub fn lock(&self) -> MutexGuard<'_, HubState> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// The hub's plant on the board's pins.
pub struct HubBoardPlant {
    net: Arc<Mutex<OneWireNet>>,
    view: HubView,
    attached: bool,
    last_end: [u64; 2],
}

/// The ROM code of sensor `i` (the rig's, seed 0).
pub fn sensor_rom(i: usize) -> [u8; 8] {
    ds18b20_rom(0x00A1_0000 + (i as u64) * 0x1_0101)
}

impl HubBoardPlant {
    /// 15 DS18B20 with the rig's ROM codes at `temps[i]` °C (missing ones at 25 °C).
    pub fn new(temps: &[f64]) -> Self {
        let devices = (0..SENSORS).map(|i| Ds18b20::new(sensor_rom(i))).collect();
        let temps: Vec<f64> = (0..SENSORS)
            .map(|i| temps.get(i).copied().unwrap_or(25.0))
            .collect();
        Self {
            net: Arc::new(Mutex::new(OneWireNet::new(devices))),
            view: HubView(Arc::new(Mutex::new(HubState {
                plugged: vec![true; temps.len()],
                temps,
                ..HubState::default()
            }))),
            attached: false,
            last_end: [0; 2],
        }
    }

    /// The handle the test keeps.
    pub fn view(&self) -> HubView {
        self.view.clone()
    }
}

impl BoardPlant for HubBoardPlant {
    fn period_ns(&self) -> u64 {
        1_000_000
    }

    fn step(&mut self, board: &mut Board, t_ns: u64) {
        if !self.attached {
            self.attached = board.attach_onewire(ONEWIRE_USART, self.net.clone());
        }
        let mut v = self.view.lock();
        {
            let mut net = self.net.lock().unwrap_or_else(|e| e.into_inner());
            net.set_time(t_ns);
            for (k, d) in net.devices.iter_mut().enumerate() {
                d.die_temp = v.temps.get(k).copied().unwrap_or(25.0);
                d.plugged = v.plugged.get(k).copied().unwrap_or(true);
            }
            v.conversions = net.devices.iter().map(|d| u64::from(d.conversions)).sum();
        }
        if let Some((s, _)) = board.onewire_stats(ONEWIRE_USART) {
            v.onewire = s;
        }
        for (r, &(tim, reg)) in RINGS.iter().enumerate() {
            let Some(burst) = board.dma_burst(tim, reg) else {
                continue;
            };
            if burst.end == self.last_end[r] {
                continue;
            }
            self.last_end[r] = burst.end;
            v.transfers[r] += 1;
            let ch = ((reg - 0x34) / 4 + 1) as u8;
            let on = board.pwm_duty(tim, ch).is_some();
            v.rings[r] = match (on, board.timer_period(tim)) {
                (true, Some((hz, period))) => {
                    let duties: Vec<u16> = burst
                        .values
                        .iter()
                        .map(|&x| x.min(u32::from(u16::MAX)) as u16)
                        .collect();
                    let period = period.min(u32::from(u16::MAX)) as u16;
                    Some(decode(&duties, hz, period, LEDS_PER_RING))
                }
                _ => None,
            };
        }
    }
}
