//! The ways firmware reaches its ESC: the software ESC directly, or a chip driver over a
//! simulated SPI peripheral.

use oxicat_esc::{Esc, EscConfig};
use oxicat_pdi::sim::{
    BusConfig, BusStats, Et1100Model, Handle, Lan9252Model, Model, PinKind, SimPin, SimSpi,
};
use oxicat_pdi::{AddressMode, Et1100Config, Et1100Spi, Lan9252, Lan9252Config, Pins, ReadMode};
use oxicat_slave::Pdi;

/// One way for the firmware to reach its ESC. A port owns the master's access to the
/// ESC; the firmware's [`Pdi`] is handed out separately so the stack can borrow it while
/// the bench holds the port.
pub trait Port: Sized + 'static {
    /// What the firmware calls.
    type Pdi: Pdi;
    /// For failure messages.
    const NAME: &'static str;
    /// The ESC behind this PDI (the LAN9252 carries its own ESC core).
    fn esc_config() -> EscConfig;
    /// Puts the PDI in front of `esc` and brings the chip up as firmware does at boot.
    fn build(esc: Esc, bus: BusConfig) -> (Self::Pdi, Self);
    /// The ESC itself, for the master's side (frames, time).
    fn with_esc<T>(&mut self, pdi: &mut Self::Pdi, f: impl FnOnce(&mut Esc) -> T) -> T;
    /// SPI traffic since the last reset, for ports with a bus.
    fn bus_stats(&self) -> Option<BusStats> {
        None
    }
    /// Zeroes the SPI counters.
    fn reset_bus_stats(&self) {}
}

/// The software ESC as its own PDI (`impl Pdi for Esc`): what the simulator runs.
pub struct Soft;

impl Port for Soft {
    type Pdi = Esc;
    const NAME: &'static str = "software ESC";
    fn esc_config() -> EscConfig {
        EscConfig::et1100()
    }
    fn build(esc: Esc, _: BusConfig) -> (Esc, Self) {
        (esc, Soft)
    }
    fn with_esc<T>(&mut self, pdi: &mut Esc, f: impl FnOnce(&mut Esc) -> T) -> T {
        f(pdi)
    }
}

/// The pins a driver reads, wired to the simulated chip.
pub type SimPins<M> = Pins<SimPin<M>, SimPin<M>, SimPin<M>>;
/// The LAN9252 driver on the simulated LAN9252.
pub type LanDriver = Lan9252<SimSpi<Lan9252Model>, SimPins<Lan9252Model>>;
/// The ET1100 SPI driver on the simulated ET1100.
pub type EtDriver = Et1100Spi<SimSpi<Et1100Model>, SimPins<Et1100Model>>;

fn pins<M: Model>(h: &Handle<M>, irq_active_low: bool) -> SimPins<M> {
    Pins {
        irq: h.pin(PinKind::Irq),
        sync0: h.pin(PinKind::Sync0),
        sync1: h.pin(PinKind::Sync1),
        irq_active_low,
        sync_active_low: false,
    }
}

/// A chip driver and its simulated chip.
pub trait SpiChip: 'static {
    /// The chip model.
    type M: Model + 'static;
    /// The driver.
    type D: Pdi;
    /// For failure messages.
    const NAME: &'static str;
    /// The chip's ESC.
    fn esc_config() -> EscConfig;
    /// Wires the driver to a new chip model around `esc` and runs the driver's init.
    fn build(esc: Esc, bus: BusConfig) -> (Self::D, Handle<Self::M>);
}

/// A driver over simulated SPI as the firmware's PDI; the handle reaches the chip's ESC
/// and its bus counters.
pub struct Spi<C: SpiChip> {
    /// The simulated chip.
    pub h: Handle<C::M>,
}

impl<C: SpiChip> Port for Spi<C> {
    type Pdi = C::D;
    const NAME: &'static str = C::NAME;
    fn esc_config() -> EscConfig {
        C::esc_config()
    }
    fn build(esc: Esc, bus: BusConfig) -> (C::D, Self) {
        let (d, h) = C::build(esc, bus);
        (d, Spi { h })
    }
    fn with_esc<T>(&mut self, _: &mut C::D, f: impl FnOnce(&mut Esc) -> T) -> T {
        self.h.with_esc(f)
    }
    fn bus_stats(&self) -> Option<BusStats> {
        Some(self.h.stats())
    }
    fn reset_bus_stats(&self) {
        self.h.reset_stats()
    }
}

fn lan(esc: Esc, bus: BusConfig, cfg: Lan9252Config) -> (LanDriver, Handle<Lan9252Model>) {
    let h = Lan9252Model::handle(esc, bus);
    let mut d = Lan9252::new(h.spi(), pins(&h, !cfg.irq_active_high), cfg);
    d.init().expect("LAN9252 init");
    (d, h)
}

fn et(esc: Esc, bus: BusConfig, cfg: Et1100Config) -> (EtDriver, Handle<Et1100Model>) {
    let h = Et1100Model::handle(esc, bus);
    let mut d = Et1100Spi::new(h.spi(), pins(&h, true), cfg);
    d.init(&mut h.pin(PinKind::EepromLoaded))
        .expect("ET1100 init");
    (d, h)
}

macro_rules! chip {
    ($(#[$doc:meta])* $chip:ident, $port:ident, $model:ty, $drv:ty, $name:literal, $esc:expr,
     |$e:ident, $b:ident| $build:expr) => {
        $(#[$doc])*
        pub struct $chip;
        impl SpiChip for $chip {
            type M = $model;
            type D = $drv;
            const NAME: &'static str = $name;
            fn esc_config() -> EscConfig {
                $esc
            }
            fn build($e: Esc, $b: BusConfig) -> ($drv, Handle<$model>) {
                $build
            }
        }
        $(#[$doc])*
        pub type $port = Spi<$chip>;
    };
}

chip!(
    /// LAN9252, SPI read (0x03), active-low IRQ.
    LanRead, Lan, Lan9252Model, LanDriver, "LAN9252 (read 0x03)", EscConfig::lan9252(),
    |esc, bus| lan(esc, bus, Lan9252Config::default())
);
chip!(
    /// LAN9252, SPI fast read (0x0B) with its dummy byte, active-high IRQ.
    LanFastRead, LanFast, Lan9252Model, LanDriver, "LAN9252 (fast read 0x0B)",
    EscConfig::lan9252(),
    |esc, bus| lan(
        esc,
        bus,
        Lan9252Config {
            fast_read: true,
            irq_active_high: true,
            ..Default::default()
        }
    )
);
chip!(
    /// ET1100 SPI PDI, 2-byte addressing, read with wait state byte.
    EtTwoByte, Et2, Et1100Model, EtDriver, "ET1100 (2-byte address, wait state)",
    EscConfig::et1100(),
    |esc, bus| et(esc, bus, Et1100Config::default())
);
chip!(
    /// ET1100 SPI PDI, 3-byte addressing, read with wait state byte.
    EtThreeByte, Et3, Et1100Model, EtDriver, "ET1100 (3-byte address, wait state)",
    EscConfig::et1100(),
    |esc, bus| et(
        esc,
        bus,
        Et1100Config {
            address_mode: AddressMode::ThreeByte,
            ..Default::default()
        }
    )
);
chip!(
    /// ET1100 SPI PDI, 2-byte addressing, a 240 ns pause instead of the wait state byte.
    EtReadPause, EtPause, Et1100Model, EtDriver, "ET1100 (2-byte address, 240 ns pause)",
    EscConfig::et1100(),
    |esc, bus| et(
        esc,
        bus,
        Et1100Config {
            read_mode: ReadMode::Delay { ns: 240 },
            ..Default::default()
        }
    )
);
