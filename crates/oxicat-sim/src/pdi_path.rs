//! How firmware on the virtual segment reaches its ESC: directly (the software ESC is the
//! firmware's [`Pdi`], as before) or through an `oxicat-pdi` chip driver over the simulated
//! SPI peripheral (`oxicat_pdi::sim`) — the driver the firmware uses on hardware, byte for
//! byte, with its bus traffic counted.
//!
//! The segment owns every ESC and lends it to the node for one event (`&mut Esc`). A
//! [`PdiPath`] turns that into the firmware's [`Pdi`] for the event:
//!
//! - [`Direct`]: the `&mut Esc` itself (zero cost, the default everywhere);
//! - [`SpiPath`]: the ESC is swapped into the chip model (`Handle::swap_esc`; `Esc` is
//!   ~1.4 KB, its memories are on the heap), the event runs with the driver
//!   ([`oxicat_pdi::Lan9252`] or [`oxicat_pdi::Et1100Spi`]) as its `Pdi`, and the ESC is
//!   swapped back. Between events the chip holds a small stand-in ESC that nobody reads.
//!
//! By default the firmware runs in zero virtual time either way: the SPI bus time is
//! counted ([`SpiPath::bus_stats`]), not simulated, so a driver that does its job is
//! transparent to the master. The opt-in execution-time model ([`crate::exec_time`])
//! turns the bus time into virtual time; it needs a path that can hold the firmware's ESC
//! writes back ([`PdiPath::hold_writes`]: the SPI paths can, the direct path cannot).

use core::convert::Infallible;

use oxicat_esc::{Esc, EscConfig, PdiError};
use oxicat_pdi::sim::{Et1100Model, Handle, Lan9252Model, PinKind, SimPin, SimSpi};
use oxicat_pdi::{Et1100Config, Et1100Spi, Lan9252, Lan9252Config, Pins};
use oxicat_slave::{InitError, IrqLines, Pdi};

pub use oxicat_pdi::sim::{BusConfig, BusStats, HeldWrite};
pub use oxicat_pdi::{AddressMode, ReadMode};

/// What a driver over the simulated SPI reports (the simulated bus itself never fails).
pub type SpiError = oxicat_pdi::Error<Infallible>;

/// Which way firmware reaches its ESC (a scenario / command-line choice).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PdiRoute {
    /// The software ESC is the firmware's `Pdi`.
    #[default]
    Direct,
    /// A Microchip LAN9252 in SPI mode, through [`oxicat_pdi::Lan9252`].
    Lan9252 {
        /// SPI clock and CS overhead.
        bus: BusConfig,
        /// Fast read (0x0B, one dummy byte) instead of read (0x03).
        fast_read: bool,
    },
    /// A Beckhoff ET1100 SPI PDI, through [`oxicat_pdi::Et1100Spi`].
    Et1100 {
        /// SPI clock and CS overhead.
        bus: BusConfig,
        /// Two-byte (three above 0x1FFF) or always three-byte addresses.
        address_mode: AddressMode,
        /// Wait-state byte or a pause before read data.
        read_mode: ReadMode,
    },
}

/// The SPI clock the routes use unless told otherwise: 20 MHz, the Laelaps node's target.
pub const DEFAULT_SPI_MHZ: u32 = 20;

impl PdiRoute {
    /// LAN9252, read 0x03, at `mhz` MHz.
    pub fn lan9252(mhz: u32) -> Self {
        PdiRoute::Lan9252 {
            bus: BusConfig::mhz(mhz),
            fast_read: false,
        }
    }

    /// ET1100, two-byte addresses, wait-state reads, at `mhz` MHz.
    pub fn et1100(mhz: u32) -> Self {
        PdiRoute::Et1100 {
            bus: BusConfig::mhz(mhz),
            address_mode: AddressMode::TwoByte,
            read_mode: ReadMode::WaitState,
        }
    }

    /// Parses `direct`, `lan9252` or `et1100` (any case); the SPI routes at `mhz` MHz.
    pub fn parse(name: &str, mhz: u32) -> Option<Self> {
        match name.to_ascii_lowercase().as_str() {
            "direct" => Some(PdiRoute::Direct),
            "lan9252" => Some(PdiRoute::lan9252(mhz)),
            "et1100" => Some(PdiRoute::et1100(mhz)),
            _ => None,
        }
    }

    /// `direct`, `lan9252` or `et1100`.
    pub fn name(&self) -> &'static str {
        match self {
            PdiRoute::Direct => "direct",
            PdiRoute::Lan9252 { .. } => "lan9252",
            PdiRoute::Et1100 { .. } => "et1100",
        }
    }

    /// The SPI bus, if the route has one.
    pub fn bus(&self) -> Option<BusConfig> {
        match self {
            PdiRoute::Direct => None,
            PdiRoute::Lan9252 { bus, .. } | PdiRoute::Et1100 { bus, .. } => Some(*bus),
        }
    }

    /// The ESC model for a node on this route: the LAN9252 preset behind a LAN9252 (the
    /// real chip's ESC core: 3 FMMUs, 4 SMs, 4 KiB), `default` otherwise (an ET1100-class
    /// board keeps its ESC).
    pub fn esc_config(&self, default: EscConfig) -> EscConfig {
        match self {
            PdiRoute::Lan9252 { .. } => EscConfig::lan9252(),
            _ => default,
        }
    }
}

impl core::fmt::Display for PdiRoute {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            PdiRoute::Direct => write!(f, "direct (software ESC as the PDI)"),
            PdiRoute::Lan9252 { bus, fast_read } => write!(
                f,
                "LAN9252 over SPI at {} MHz ({})",
                f64::from(bus.sclk_hz) / 1e6,
                if *fast_read {
                    "fast read 0x0B"
                } else {
                    "read 0x03"
                }
            ),
            PdiRoute::Et1100 {
                bus,
                address_mode,
                read_mode,
            } => write!(
                f,
                "ET1100 SPI PDI at {} MHz ({}, {})",
                f64::from(bus.sclk_hz) / 1e6,
                match address_mode {
                    AddressMode::TwoByte => "2-byte address",
                    AddressMode::ThreeByte => "3-byte address",
                },
                match read_mode {
                    ReadMode::WaitState => "wait state".to_string(),
                    ReadMode::Delay { ns } => format!("{ns} ns read pause"),
                }
            ),
        }
    }
}

/// Why firmware could not start on its path.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PathInitError {
    /// The stack refused to start on the software ESC.
    Direct(InitError<PdiError>),
    /// The chip driver's start-up failed (BYTE_TEST, chip id, EEPROM_LOADED, PDI type …).
    Driver(SpiError),
    /// The stack refused to start through the driver.
    Stack(InitError<SpiError>),
    /// [`SpiPath::new`] was asked for the direct route.
    NotSpi,
}

impl core::fmt::Display for PathInitError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Direct(e) => write!(f, "the slave stack did not start: {e:?}"),
            Self::Driver(e) => write!(f, "the ESC chip driver did not start: {e}"),
            Self::Stack(e) => write!(f, "the slave stack did not start through the driver: {e:?}"),
            Self::NotSpi => write!(f, "the direct route has no SPI driver"),
        }
    }
}

impl std::error::Error for PathInitError {}

/// How a node's firmware gets its [`Pdi`] during an event; see the module documentation.
pub trait PdiPath: Send + 'static {
    /// The firmware's `Pdi` type on this path.
    type Pdi: Pdi<Error: Send + 'static>;

    /// Runs `f` with the firmware's `Pdi` for the ESC the segment lent (`esc`).
    fn with_pdi<T>(&mut self, esc: &mut Esc, f: impl FnOnce(&mut Self::Pdi) -> T) -> T;

    /// What the SPI bus carried since the last reset (`None`: no bus on this path).
    fn bus_stats(&self) -> Option<BusStats> {
        None
    }

    /// Clears the bus counters.
    fn reset_bus_stats(&self) {}

    /// Whether this path can hold the firmware's ESC writes back
    /// ([`hold_writes`](Self::hold_writes)); the execution-time model
    /// ([`crate::exec_time`]) needs it.
    fn can_hold_writes(&self) -> bool {
        false
    }

    /// Starts (`true`) or stops holding the firmware's ESC writes back: while held they
    /// are accepted (and read back by the firmware) but reach the ESC only when someone
    /// takes them ([`take_held_writes`](Self::take_held_writes)) and commits them.
    fn hold_writes(&mut self, _on: bool) {}

    /// The writes held back so far, in order.
    fn take_held_writes(&mut self) -> Vec<HeldWrite> {
        Vec::new()
    }

    /// A start-up error of the stack on this path, as a [`PathInitError`].
    fn init_error(e: InitError<<Self::Pdi as Pdi>::Error>) -> PathInitError;
}

/// The software ESC is the firmware's `Pdi` (the default path; no cost).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Direct;

impl PdiPath for Direct {
    type Pdi = Esc;

    #[inline]
    fn with_pdi<T>(&mut self, esc: &mut Esc, f: impl FnOnce(&mut Esc) -> T) -> T {
        f(esc)
    }

    fn init_error(e: InitError<PdiError>) -> PathInitError {
        PathInitError::Direct(e)
    }
}

/// The lines of a simulated chip as the driver reads them.
pub type SimLines<M> = Pins<SimPin<M>, SimPin<M>, SimPin<M>>;

/// A chip driver over a simulated SPI chip, as the firmware's `Pdi`.
pub enum SpiDriver {
    /// LAN9252.
    Lan9252(Lan9252<SimSpi<Lan9252Model>, SimLines<Lan9252Model>>),
    /// ET1100 SPI PDI.
    Et1100(Et1100Spi<SimSpi<Et1100Model>, SimLines<Et1100Model>>),
}

impl Pdi for SpiDriver {
    type Error = SpiError;

    fn read(&mut self, addr: u16, buf: &mut [u8]) -> Result<(), SpiError> {
        match self {
            SpiDriver::Lan9252(d) => d.read(addr, buf),
            SpiDriver::Et1100(d) => d.read(addr, buf),
        }
    }

    fn write(&mut self, addr: u16, data: &[u8]) -> Result<(), SpiError> {
        match self {
            SpiDriver::Lan9252(d) => d.write(addr, data),
            SpiDriver::Et1100(d) => d.write(addr, data),
        }
    }

    fn al_event_request(&mut self) -> Result<u32, SpiError> {
        match self {
            SpiDriver::Lan9252(d) => d.al_event_request(),
            SpiDriver::Et1100(d) => d.al_event_request(),
        }
    }

    fn irq_lines(&mut self) -> IrqLines {
        match self {
            SpiDriver::Lan9252(d) => d.irq_lines(),
            SpiDriver::Et1100(d) => d.irq_lines(),
        }
    }
}

/// The simulated chip behind an [`SpiDriver`].
#[derive(Clone)]
enum Chip {
    Lan9252(Handle<Lan9252Model>),
    Et1100(Handle<Et1100Model>),
}

impl Chip {
    fn swap_esc(&self, esc: &mut Esc) {
        match self {
            Chip::Lan9252(h) => h.swap_esc(esc),
            Chip::Et1100(h) => h.swap_esc(esc),
        }
    }
}

/// Firmware reaches its ESC through a chip driver over the simulated SPI; see the module
/// documentation.
pub struct SpiPath {
    driver: SpiDriver,
    chip: Chip,
    route: PdiRoute,
}

/// The ESC a chip holds while the segment's ESC is not lent to it (never accessed).
fn stand_in() -> Esc {
    Esc::new(EscConfig::et1200(), Vec::new())
}

/// Lends `esc` to a chip (`swap` exchanges it with the chip's) while `f` runs, and takes
/// it back afterwards, also when `f` unwinds.
fn lent<T>(swap: &dyn Fn(&mut Esc), esc: &mut Esc, f: impl FnOnce() -> T) -> T {
    struct Back<'a>(&'a dyn Fn(&mut Esc), &'a mut Esc);
    impl Drop for Back<'_> {
        fn drop(&mut self) {
            (self.0)(self.1);
        }
    }
    swap(esc);
    let _back = Back(swap, esc);
    f()
}

impl SpiPath {
    /// Puts the chip of `route` in front of `esc` and starts its driver (LAN9252: BYTE_TEST,
    /// READY, chip id, reset, interrupt enable; ET1100: EEPROM_LOADED, ESC type, PDI type =
    /// SPI) — the firmware's start-up on hardware. `esc` stays with the caller.
    pub fn new(route: PdiRoute, esc: &mut Esc) -> Result<Self, PathInitError> {
        let (driver, chip) = match route {
            PdiRoute::Direct => return Err(PathInitError::NotSpi),
            PdiRoute::Lan9252 { bus, fast_read } => {
                let cfg = Lan9252Config {
                    fast_read,
                    ..Lan9252Config::default()
                };
                let h = Lan9252Model::handle(stand_in(), bus);
                let pins = Pins {
                    irq: h.pin(PinKind::Irq),
                    sync0: h.pin(PinKind::Sync0),
                    sync1: h.pin(PinKind::Sync1),
                    irq_active_low: !cfg.irq_active_high,
                    sync_active_low: false,
                };
                let mut d = Lan9252::new(h.spi(), pins, cfg);
                lent(&|e| h.swap_esc(e), esc, || d.init()).map_err(PathInitError::Driver)?;
                (SpiDriver::Lan9252(d), Chip::Lan9252(h))
            }
            PdiRoute::Et1100 {
                bus,
                address_mode,
                read_mode,
            } => {
                let cfg = Et1100Config {
                    address_mode,
                    read_mode,
                    ..Et1100Config::default()
                };
                let h = Et1100Model::handle(stand_in(), bus);
                let pins = Pins {
                    irq: h.pin(PinKind::Irq),
                    sync0: h.pin(PinKind::Sync0),
                    sync1: h.pin(PinKind::Sync1),
                    irq_active_low: true,
                    sync_active_low: false,
                };
                let mut d = Et1100Spi::new(h.spi(), pins, cfg);
                let mut loaded = h.pin(PinKind::EepromLoaded);
                lent(&|e| h.swap_esc(e), esc, || d.init(&mut loaded))
                    .map_err(PathInitError::Driver)?;
                (SpiDriver::Et1100(d), Chip::Et1100(h))
            }
        };
        Ok(SpiPath {
            driver,
            chip,
            route,
        })
    }

    /// The route this path was built for.
    pub fn route(&self) -> PdiRoute {
        self.route
    }

    /// The driver (e.g. to look at its state).
    pub fn driver(&mut self) -> &mut SpiDriver {
        &mut self.driver
    }
}

impl PdiPath for SpiPath {
    type Pdi = SpiDriver;

    fn with_pdi<T>(&mut self, esc: &mut Esc, f: impl FnOnce(&mut SpiDriver) -> T) -> T {
        let SpiPath { driver, chip, .. } = self;
        lent(&|e| chip.swap_esc(e), esc, || f(driver))
    }

    fn bus_stats(&self) -> Option<BusStats> {
        Some(match &self.chip {
            Chip::Lan9252(h) => h.stats(),
            Chip::Et1100(h) => h.stats(),
        })
    }

    fn reset_bus_stats(&self) {
        match &self.chip {
            Chip::Lan9252(h) => h.reset_stats(),
            Chip::Et1100(h) => h.reset_stats(),
        }
    }

    fn can_hold_writes(&self) -> bool {
        true
    }

    fn hold_writes(&mut self, on: bool) {
        match &self.chip {
            Chip::Lan9252(h) => h.hold_writes(on),
            Chip::Et1100(h) => h.hold_writes(on),
        }
    }

    fn take_held_writes(&mut self) -> Vec<HeldWrite> {
        match &self.chip {
            Chip::Lan9252(h) => h.take_held_writes(),
            Chip::Et1100(h) => h.take_held_writes(),
        }
    }

    fn init_error(e: InitError<SpiError>) -> PathInitError {
        PathInitError::Stack(e)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn routes_parse_and_name() {
        for n in ["direct", "lan9252", "ET1100"] {
            let r = PdiRoute::parse(n, 20).expect(n);
            assert_eq!(r.name(), n.to_ascii_lowercase());
        }
        assert_eq!(PdiRoute::parse("spi", 20), None);
        assert_eq!(PdiRoute::Direct.bus(), None);
        assert_eq!(PdiRoute::lan9252(30).bus(), Some(BusConfig::mhz(30)));
        assert_eq!(
            PdiRoute::lan9252(20).esc_config(EscConfig::et1100()),
            EscConfig::lan9252()
        );
        assert_eq!(
            PdiRoute::et1100(20).esc_config(EscConfig::et1100()),
            EscConfig::et1100()
        );
    }

    #[test]
    fn the_path_is_send() {
        fn send<T: Send>() {}
        send::<SpiPath>();
    }

    #[test]
    fn drivers_start_and_lend_the_esc_back() {
        let def = oxicat_devices::laelaps::device::device(oxicat_devices::laelaps::Side::Left);
        let sii = oxicat_esi::sii::generate(def).expect("SII");
        for route in [
            PdiRoute::lan9252(20),
            PdiRoute::et1100(20),
            PdiRoute::Et1100 {
                bus: BusConfig::mhz(10),
                address_mode: AddressMode::ThreeByte,
                read_mode: ReadMode::Delay { ns: 240 },
            },
        ] {
            let cfg = route.esc_config(EscConfig::et1100());
            let mut esc = Esc::new(cfg.clone(), sii.clone());
            let mut p = SpiPath::new(route, &mut esc).expect("the driver starts");
            assert_eq!(p.route(), route);
            let ty = p.with_pdi(&mut esc, |d| d.read_u8(0x0000));
            assert_eq!(ty, Ok(cfg.esc_type), "{route}");
            let s = p.bus_stats().expect("a bus");
            assert!(s.transactions > 0 && s.bytes > 0 && s.ps > 0, "{s:?}");
            assert_eq!(s.protocol_errors, 0);
            p.reset_bus_stats();
            assert_eq!(p.bus_stats(), Some(BusStats::default()));
            // The segment's ESC is back with the caller.
            let mut b = [0u8; 1];
            esc.pdi_read(0x0000, &mut b).expect("ESC type");
            assert_eq!(b[0], cfg.esc_type);
        }
        // No SII: the ET1100's PDI control reads 0, not SPI.
        let mut esc = Esc::new(EscConfig::et1100(), Vec::new());
        assert!(matches!(
            SpiPath::new(PdiRoute::et1100(20), &mut esc),
            Err(PathInitError::Driver(oxicat_pdi::Error::PdiType(_)))
        ));
        assert!(matches!(
            SpiPath::new(PdiRoute::Direct, &mut esc),
            Err(PathInitError::NotSpi)
        ));
    }
}
