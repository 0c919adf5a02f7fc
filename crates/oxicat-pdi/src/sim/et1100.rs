//! ET1100 SPI PDI model.

use super::{BusConfig, Core, Fault, Handle, Model, PinKind};
use crate::et1100::cmd;
use oxicat_esc::Esc;
use std::vec;
use std::vec::Vec;

/// An ET1100 SPI PDI in front of a software ESC.
pub struct Et1100Model {
    core: Core,
    /// Minimum pause between address and data phase of a plain read (ns).
    pub read_delay_ns: u32,
}

impl Et1100Model {
    /// A chip in front of `esc` on `bus`.
    pub fn new(esc: Esc, bus: BusConfig) -> Self {
        Et1100Model {
            core: Core::new(esc, bus),
            read_delay_ns: 240,
        }
    }

    /// A shared handle to a new chip.
    pub fn handle(esc: Esc, bus: BusConfig) -> Handle<Self> {
        Handle::new(Self::new(esc, bus))
    }

    fn proto_err(&mut self) {
        self.core.stats.protocol_errors += 1;
    }
}

impl Model for Et1100Model {
    fn core(&mut self) -> &mut Core {
        &mut self.core
    }

    fn frame(&mut self, mosi: &[u8], delays: &[(usize, u32)]) -> Vec<u8> {
        let mut miso = vec![0xFFu8; mosi.len()];
        let ev = self.core.esc.al_event_request().to_le_bytes();
        for (i, m) in miso.iter_mut().enumerate().take(3) {
            *m = ev[i];
        }
        if mosi.len() < 2 {
            self.proto_err();
            return miso;
        }
        let mut addr = u16::from(mosi[0]) << 5 | u16::from(mosi[1] >> 3);
        let mut command = mosi[1] & 7;
        let mut hdr = 2;
        if command == cmd::ADDR_EXT {
            if mosi.len() < 3 {
                self.proto_err();
                return miso;
            }
            addr |= u16::from(mosi[2] >> 5) << 13;
            command = (mosi[2] >> 2) & 7;
            hdr = 3;
        } else if mosi.len() > 2 {
            miso[2] = 0xFF;
        }
        match command {
            cmd::NOP => {}
            cmd::READ | cmd::READ_WS => {
                let mut start = hdr;
                if command == cmd::READ_WS {
                    if mosi.get(hdr) != Some(&cmd::WAIT_STATE) {
                        self.proto_err();
                    }
                    start += 1;
                } else {
                    let waited: u32 = delays
                        .iter()
                        .filter(|(p, _)| *p == hdr)
                        .map(|(_, ns)| *ns)
                        .sum();
                    if waited < self.read_delay_ns {
                        // Data not fetched in time: the first bytes are garbage.
                        self.proto_err();
                        return miso;
                    }
                }
                if start >= mosi.len() {
                    return miso;
                }
                let data = &mosi[start..];
                // The ESC reads up to and including the byte where the master sent the
                // termination 0xFF; without one it prefetches one byte too many.
                let (len, fetch) = match data.iter().position(|&b| b == cmd::READ_TERMINATION) {
                    Some(k) => (k + 1, k + 1),
                    None => (data.len(), data.len() + 1),
                };
                if len != data.len() || fetch != len {
                    self.proto_err();
                }
                let mut buf = vec![0u8; fetch];
                if self.core.pdi_read(addr, &mut buf).is_err() {
                    self.proto_err();
                    return miso;
                }
                miso[start..start + len].copy_from_slice(&buf[..len]);
            }
            cmd::WRITE => {
                if self.core.pdi_write(addr, &mosi[hdr..]).is_err() {
                    self.proto_err();
                }
            }
            _ => self.proto_err(),
        }
        miso
    }

    fn pin(&mut self, pin: PinKind) -> bool {
        match pin {
            // SPI_IRQ: active low.
            PinKind::Irq => !self.core.esc.irq_line(),
            PinKind::Sync0 => self.core.esc.sync_lines().0,
            PinKind::Sync1 => self.core.esc.sync_lines().1,
            PinKind::EepromLoaded => self.core.fault != Fault::EepromNotLoaded,
        }
    }
}
