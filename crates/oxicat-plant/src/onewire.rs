//! A 1-Wire bus with DS18B20 sensors, at the level of time slots: reset/presence, the ROM
//! commands (SEARCH ROM with each device driving its bit and its complement onto the
//! wired-AND bus and dropping out when the master writes the other direction, MATCH ROM,
//! SKIP ROM, READ ROM) and the function commands CONVERT T, READ SCRATCHPAD (9 bytes with
//! the device's CRC-8), WRITE SCRATCHPAD (TH, TL, configuration: resolution). A conversion
//! takes the datasheet's time for the resolution, in the bus's virtual time; reading before
//! it finished gives the previous result (85 °C after power-on). Sensors can be unplugged
//! and their next scratchpad reads corrupted (CRC faults).

pub use oxicat_wire::crc::onewire_crc8 as crc8;

/// Duration of a reset + presence sequence \[ns\].
pub const RESET_NS: u64 = 960_000;
/// Duration of a read or write slot \[ns\].
pub const SLOT_NS: u64 = 70_000;

/// The ROM code of a DS18B20 with serial `serial` (family 0x28, CRC appended).
pub fn ds18b20_rom(serial: u64) -> [u8; 8] {
    let mut r = [0u8; 8];
    r[0] = 0x28;
    r[1..7].copy_from_slice(&serial.to_le_bytes()[..6]);
    r[7] = crc8(&r[..7]);
    r
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    /// Not selected; waits for a reset.
    Idle,
    /// Receiving a ROM command.
    RomCmd { byte: u8, n: u8 },
    /// SEARCH ROM: bit `bit`, step 0 = send bit, 1 = send complement, 2 = take direction.
    Search { bit: u8, step: u8 },
    /// MATCH ROM: receiving the 64 bits.
    Match { rom: u64, n: u8 },
    /// Receiving a function command.
    FuncCmd { byte: u8, n: u8 },
    /// Sending `len` bits of `data` from `pos`.
    Send { data: [u8; 9], len: u8, pos: u8 },
    /// Receiving the three WRITE SCRATCHPAD bytes.
    Receive { data: [u8; 3], n: u8 },
    /// Converting (read slots answer 0 until done).
    Converting,
}

/// One DS18B20.
#[derive(Debug, Clone, PartialEq)]
pub struct Ds18b20 {
    /// ROM code.
    pub rom: [u8; 8],
    /// On the bus.
    pub plugged: bool,
    /// Temperature its die has now \[°C\] (set by whoever owns the thermal model).
    pub die_temp: f64,
    /// TH, TL, configuration register.
    pub th: u8,
    /// TL.
    pub tl: u8,
    /// Configuration register (bits 6..5: resolution).
    pub config: u8,
    /// The last converted raw temperature (1/16 °C).
    pub raw: i16,
    /// Scratchpad reads still to corrupt (one bit flipped: a CRC error).
    pub corrupt_reads: u32,
    /// Conversions done.
    pub conversions: u32,
    phase: Phase,
    conv_until: Option<(u64, i16)>,
}

impl Ds18b20 {
    /// A sensor with ROM `rom` at power-on (12 bits, 85 °C in the register).
    pub fn new(rom: [u8; 8]) -> Self {
        Self {
            rom,
            plugged: true,
            die_temp: 25.0,
            th: 0x4B,
            tl: 0x46,
            config: 0x7F,
            raw: 85 * 16,
            corrupt_reads: 0,
            conversions: 0,
            phase: Phase::Idle,
            conv_until: None,
        }
    }

    /// Conversion time for the configured resolution \[ns\].
    pub fn conversion_ns(&self) -> u64 {
        93_750_000 << ((self.config >> 5) & 3)
    }

    /// The 9-byte scratchpad as the device sends it.
    pub fn scratchpad(&self) -> [u8; 9] {
        let t = self.raw.to_le_bytes();
        let mut sp = [
            t[0],
            t[1],
            self.th,
            self.tl,
            self.config,
            0xFF,
            0x0C,
            0x10,
            0,
        ];
        sp[8] = crc8(&sp[..8]);
        sp
    }

    fn rom_bit(&self, i: u8) -> bool {
        self.rom[(i / 8) as usize] >> (i % 8) & 1 != 0
    }

    fn quantise(&self, t: f64) -> i16 {
        let res = (self.config >> 5) & 3;
        let raw = (t.clamp(-55.0, 125.0) * 16.0).floor() as i16;
        raw & !((1i16 << (3 - res)) - 1)
    }

    fn finish(&mut self, now: u64) {
        if let Some((until, raw)) = self.conv_until {
            if now >= until {
                self.raw = raw;
                self.conv_until = None;
                self.conversions += 1;
                if self.phase == Phase::Converting {
                    self.phase = Phase::Idle;
                }
            }
        }
    }

    /// What the device drives in a read slot (None: releases the bus).
    fn read_slot(&mut self) -> Option<bool> {
        match self.phase {
            Phase::Search { bit, step: 0 } => {
                self.phase = Phase::Search { bit, step: 1 };
                Some(self.rom_bit(bit))
            }
            Phase::Search { bit, step: 1 } => {
                self.phase = Phase::Search { bit, step: 2 };
                Some(!self.rom_bit(bit))
            }
            Phase::Send { data, len, pos } if pos < len => {
                let b = data[(pos / 8) as usize] >> (pos % 8) & 1 != 0;
                self.phase = Phase::Send {
                    data,
                    len,
                    pos: pos + 1,
                };
                Some(b)
            }
            Phase::Converting => Some(false),
            _ => None,
        }
    }

    fn write_slot(&mut self, bit: bool, now: u64) {
        let v = bit as u8;
        self.phase = match self.phase {
            Phase::RomCmd { byte, n } => {
                let byte = byte | v << n;
                if n < 7 {
                    Phase::RomCmd { byte, n: n + 1 }
                } else {
                    match byte {
                        0xF0 => Phase::Search { bit: 0, step: 0 },
                        0x55 => Phase::Match { rom: 0, n: 0 },
                        0xCC => Phase::FuncCmd { byte: 0, n: 0 },
                        0x33 => {
                            let mut data = [0u8; 9];
                            data[..8].copy_from_slice(&self.rom);
                            Phase::Send {
                                data,
                                len: 64,
                                pos: 0,
                            }
                        }
                        _ => Phase::Idle,
                    }
                }
            }
            Phase::Search { bit: b, step: 2 } => {
                if bit != self.rom_bit(b) {
                    Phase::Idle
                } else if b == 63 {
                    Phase::FuncCmd { byte: 0, n: 0 }
                } else {
                    Phase::Search {
                        bit: b + 1,
                        step: 0,
                    }
                }
            }
            Phase::Match { rom, n } => {
                let rom = rom | (v as u64) << n;
                if n < 63 {
                    Phase::Match { rom, n: n + 1 }
                } else if rom == u64::from_le_bytes(self.rom) {
                    Phase::FuncCmd { byte: 0, n: 0 }
                } else {
                    Phase::Idle
                }
            }
            Phase::FuncCmd { byte, n } => {
                let byte = byte | v << n;
                if n < 7 {
                    Phase::FuncCmd { byte, n: n + 1 }
                } else {
                    self.function(byte, now)
                }
            }
            Phase::Receive { mut data, n } => {
                data[(n / 8) as usize] |= v << (n % 8);
                if n < 23 {
                    Phase::Receive { data, n: n + 1 }
                } else {
                    self.th = data[0];
                    self.tl = data[1];
                    self.config = (data[2] & 0x60) | 0x1F;
                    Phase::Idle
                }
            }
            // A write-1 slot is also how the master reads; writes elsewhere are ignored.
            p => p,
        };
    }

    fn function(&mut self, cmd: u8, now: u64) -> Phase {
        match cmd {
            0x44 => {
                let raw = self.quantise(self.die_temp);
                self.conv_until = Some((now + self.conversion_ns(), raw));
                Phase::Converting
            }
            0xBE => {
                let mut data = self.scratchpad();
                if self.corrupt_reads > 0 {
                    self.corrupt_reads -= 1;
                    data[0] ^= 0x04;
                }
                Phase::Send {
                    data,
                    len: 72,
                    pos: 0,
                }
            }
            0x4E => Phase::Receive { data: [0; 3], n: 0 },
            0xB4 => Phase::Send {
                data: [0xFF; 9],
                len: 8,
                pos: 0,
            },
            _ => Phase::Idle,
        }
    }
}

/// The bus: devices on one wire, a virtual clock, slot counters.
#[derive(Debug, Clone, Default)]
pub struct OneWireNet {
    /// The devices.
    pub devices: Vec<Ds18b20>,
    now_ns: u64,
    /// Time the master spent on the bus (resets and slots) \[ns\].
    pub bus_ns: u64,
    /// Resets issued.
    pub resets: u64,
}

impl OneWireNet {
    /// A bus with `devices`.
    pub fn new(devices: Vec<Ds18b20>) -> Self {
        Self {
            devices,
            ..Self::default()
        }
    }

    /// Sets the virtual time (conversions finish against it).
    pub fn set_time(&mut self, now_ns: u64) {
        self.now_ns = self.now_ns.max(now_ns);
        let now = self.now_ns;
        for d in &mut self.devices {
            d.finish(now);
        }
    }

    fn tick(&mut self, ns: u64) {
        self.bus_ns += ns;
    }

    /// Reset pulse; true if a plugged device answered with presence.
    pub fn reset(&mut self) -> bool {
        self.tick(RESET_NS);
        self.resets += 1;
        let now = self.now_ns;
        let mut presence = false;
        for d in &mut self.devices {
            d.finish(now);
            if d.plugged {
                presence = true;
                // A reset ends any command, a running conversion carries on inside.
                d.phase = Phase::RomCmd { byte: 0, n: 0 };
            } else {
                d.phase = Phase::Idle;
            }
        }
        presence
    }

    /// A write slot.
    pub fn write_bit(&mut self, bit: bool) {
        self.tick(SLOT_NS);
        let now = self.now_ns;
        for d in self.devices.iter_mut().filter(|d| d.plugged) {
            d.write_slot(bit, now);
        }
    }

    /// One time slot as the wire carries it, when the master cannot say whether it reads or
    /// writes (a UART-driven master: a write-1 slot and a read slot are the same short low
    /// pulse). `false`: a write-0 slot (every device takes the 0; returns 0). `true`: each
    /// plugged device that has a bit to send drives it (a read slot for it), every other
    /// one takes a written 1; returns the wired-AND (1 when none drives).
    pub fn slot(&mut self, master: bool) -> bool {
        if !master {
            self.write_bit(false);
            return false;
        }
        self.tick(SLOT_NS);
        let now = self.now_ns;
        let mut level = true;
        for d in self.devices.iter_mut().filter(|d| d.plugged) {
            match d.read_slot() {
                Some(b) => level &= b,
                None => d.write_slot(true, now),
            }
        }
        level
    }

    /// A read slot: the wired-AND of what the plugged devices drive (1 when none does).
    pub fn read_bit(&mut self) -> bool {
        self.tick(SLOT_NS);
        let mut level = true;
        for d in self.devices.iter_mut().filter(|d| d.plugged) {
            if let Some(b) = d.read_slot() {
                level &= b;
            }
        }
        level
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn byte(net: &mut OneWireNet, b: u8) {
        for i in 0..8 {
            net.write_bit(b >> i & 1 != 0);
        }
    }

    fn read(net: &mut OneWireNet) -> u8 {
        (0..8).fold(0, |acc, i| acc | (net.read_bit() as u8) << i)
    }

    #[test]
    fn read_rom_convert_and_scratchpad_with_crc() {
        let rom = ds18b20_rom(0x1234_5678);
        let mut net = OneWireNet::new(vec![Ds18b20::new(rom)]);
        net.devices[0].die_temp = 21.3;
        assert!(net.reset());
        byte(&mut net, 0x33);
        let got: Vec<u8> = (0..8).map(|_| read(&mut net)).collect();
        assert_eq!(got, rom);
        assert_eq!(crc8(&got), 0);
        net.reset();
        byte(&mut net, 0xCC);
        byte(&mut net, 0x44);
        assert!(!net.read_bit(), "busy while converting");
        net.set_time(750_000_000);
        net.reset();
        byte(&mut net, 0xCC);
        byte(&mut net, 0xBE);
        let sp: Vec<u8> = (0..9).map(|_| read(&mut net)).collect();
        assert_eq!(crc8(&sp), 0);
        assert_eq!(
            i16::from_le_bytes([sp[0], sp[1]]),
            (21.3f64 * 16.0).floor() as i16
        );
        net.devices[0].plugged = false;
        assert!(!net.reset());
    }

    #[test]
    fn unified_slots_read_rom_and_scratchpad_as_split_slots_do() {
        // A UART master only has 0-slots and 1-slots: the device decides what a 1 is.
        let slot_byte = |net: &mut OneWireNet, b: u8| -> u8 {
            (0..8).fold(0, |acc, i| acc | (net.slot(b >> i & 1 != 0) as u8) << i)
        };
        let rom = ds18b20_rom(0x00AB_CDEF);
        let mut net = OneWireNet::new(vec![Ds18b20::new(rom)]);
        net.devices[0].die_temp = -10.25;
        assert!(net.reset());
        assert_eq!(
            slot_byte(&mut net, 0x33),
            0x33,
            "a written command reads back"
        );
        let got: Vec<u8> = (0..8).map(|_| slot_byte(&mut net, 0xFF)).collect();
        assert_eq!(got, rom);
        net.reset();
        slot_byte(&mut net, 0xCC);
        slot_byte(&mut net, 0x44);
        assert!(!net.slot(true), "busy while converting");
        net.set_time(750_000_000);
        assert!(net.slot(true), "done");
        net.reset();
        slot_byte(&mut net, 0xCC);
        slot_byte(&mut net, 0xBE);
        let sp: Vec<u8> = (0..9).map(|_| slot_byte(&mut net, 0xFF)).collect();
        assert_eq!(crc8(&sp), 0);
        assert_eq!(i16::from_le_bytes([sp[0], sp[1]]), -164);
    }
}
