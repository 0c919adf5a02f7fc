//! The ESC's interrupt/SYNC outputs as the MCU sees them.

use embedded_hal::digital::InputPin;
use oxicat_slave::IrqLines;

/// Source of the interrupt lines (PDI IRQ, SYNC0, SYNC1), already as logical levels.
pub trait Lines {
    /// Which lines are active now (a pin that cannot be read counts as inactive).
    fn lines(&mut self) -> IrqLines;
}

/// No lines wired: the firmware polls.
#[derive(Debug, Default, Clone, Copy)]
pub struct NoLines;

impl Lines for NoLines {
    fn lines(&mut self) -> IrqLines {
        IrqLines::default()
    }
}

/// Three input pins with their polarities (`true` = active low, as LAN9252 IRQ in its
/// default open-drain/active-low configuration and ET1100 SPI_IRQ).
pub struct Pins<IRQ, S0, S1> {
    /// PDI interrupt pin.
    pub irq: IRQ,
    /// SYNC0 pin.
    pub sync0: S0,
    /// SYNC1 pin.
    pub sync1: S1,
    /// IRQ is active low.
    pub irq_active_low: bool,
    /// SYNC0/SYNC1 are active low.
    pub sync_active_low: bool,
}

fn level<P: InputPin>(p: &mut P, active_low: bool) -> bool {
    match p.is_high() {
        Ok(h) => h != active_low,
        Err(_) => false,
    }
}

impl<IRQ: InputPin, S0: InputPin, S1: InputPin> Lines for Pins<IRQ, S0, S1> {
    fn lines(&mut self) -> IrqLines {
        IrqLines {
            pdi_irq: level(&mut self.irq, self.irq_active_low),
            sync0: level(&mut self.sync0, self.sync_active_low),
            sync1: level(&mut self.sync1, self.sync_active_low),
        }
    }
}
