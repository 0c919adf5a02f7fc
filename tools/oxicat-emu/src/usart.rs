//! USART1..3, UART4/5, USART6 at register level (RM0390 §25): SR, DR, BRR, CR1..3, GTPR.
//!
//! A byte written to DR goes to the transmit data register and from there to the shift
//! register, which needs one frame (start bit, 8 or 9 data bits, 1 or 2 stop bits) at the
//! baud rate BRR sets on the USART's APB clock (oversampling by 16: baud = PCLK / BRR);
//! TXE, TC and RXNE follow in time, polled or as the USART's interrupt (CR1.RXNEIE: RXNE or
//! ORE; CR1.TCIE: TC). DMA requests, the TXE/parity/idle interrupts, parity, 8× oversampling,
//! LIN/IrDA/smartcard/synchronous modes stop the image with the register, the value and
//! "not modelled".
//!
//! Receive: in half-duplex (CR3.HDSEL) the receiver reads the TX line back. With a 1-Wire
//! bus on the line ([`crate::Board::attach_onewire`]) the byte is decoded the way the bus
//! sees it — the low time from the start bit through the leading zero bits is a reset
//! (≥ 480 µs: the devices answer with a presence pulse 30 µs after the line rises, for
//! 120 µs), a write-0 slot (60..120 µs) or a 1/read slot (1..15 µs: a device that sends a 0
//! holds the line low to 30 µs after the falling edge) — and each received bit is the
//! line's level at the middle of its bit time. Without a bus, the line idles high and the
//! byte reads back as sent. In full duplex nothing drives RX.

use std::sync::{Arc, Mutex};

use oxicat_plant::onewire::OneWireNet;

/// NVIC interrupt numbers of USART1..3, UART4/5, USART6 (RM0390 table 38).
const IRQS: [(u8, u16); 6] = [(1, 37), (2, 38), (3, 39), (4, 52), (5, 53), (6, 71)];

/// The U(S)ARTs: base, number, on APB2.
pub(crate) const USARTS: [(u64, u8, bool); 6] = [
    (0x4001_1000, 1, true),
    (0x4000_4400, 2, false),
    (0x4000_4800, 3, false),
    (0x4000_4C00, 4, false),
    (0x4000_5000, 5, false),
    (0x4001_1400, 6, true),
];

const SR_RXNE: u32 = 1 << 5;
const SR_TC: u32 = 1 << 6;
const SR_TXE: u32 = 1 << 7;

const CR1_UE: u32 = 1 << 13;
const CR1_M: u32 = 1 << 12;
const CR1_TE: u32 = 1 << 3;
const CR1_RE: u32 = 1 << 2;
/// RXNE interrupt enable (RXNE or ORE raise the USART's interrupt line).
const CR1_RXNEIE: u32 = 1 << 5;
/// Transmission-complete interrupt enable.
const CR1_TCIE: u32 = 1 << 6;
/// CR1 bits modelled (UE, M, TE, RE, RXNEIE, TCIE).
const CR1_OK: u32 = CR1_UE | CR1_M | CR1_TE | CR1_RE | CR1_RXNEIE | CR1_TCIE;
/// CR2 bits modelled (STOP; ADD is stored, it only matters in multiprocessor mode).
const CR2_OK: u32 = (3 << 12) | 0xF;
const CR3_HDSEL: u32 = 1 << 3;

/// 1-Wire timing the decoder applies \[ns\].
const RESET_MIN_NS: u64 = 480_000;
const ZERO_MIN_NS: u64 = 60_000;
const ZERO_MAX_NS: u64 = 120_000;
const ONE_MIN_NS: u64 = 1_000;
const ONE_MAX_NS: u64 = 15_000;
const PRESENCE_WAIT_NS: u64 = 30_000;
const PRESENCE_NS: u64 = 120_000;
const READ_ZERO_HOLD_NS: u64 = 30_000;

/// What a USART did on its 1-Wire line.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct OneWireStats {
    /// Reset pulses.
    pub resets: u64,
    /// Resets answered with a presence pulse.
    pub presences: u64,
    /// Write-0 slots.
    pub zero_slots: u64,
    /// 1 / read slots.
    pub one_slots: u64,
    /// Bytes whose low time is none of the above (the devices ignore them).
    pub invalid: u64,
}

/// A byte in the shift register.
#[derive(Debug, Clone, Copy)]
struct Shift {
    end: u64,
    echo: Option<u8>,
}

/// One U(S)ART.
pub(crate) struct Usart {
    pub base: u64,
    pub number: u8,
    pub apb2: bool,
    cr1: u32,
    cr2: u32,
    cr3: u32,
    brr: u32,
    gtpr: u32,
    rdr: u8,
    /// SR's RXNE, ORE, TC as software left them (TXE follows the data register).
    rxne: bool,
    ore: bool,
    tc: bool,
    tdr: Option<u8>,
    shift: Option<Shift>,
    /// The 1-Wire bus on the TX line.
    pub line: Option<Arc<Mutex<OneWireNet>>>,
    pub ow: OneWireStats,
    /// Bytes sent.
    pub sent: u64,
}

impl Usart {
    pub fn new(base: u64, number: u8, apb2: bool) -> Self {
        Self {
            base,
            number,
            apb2,
            cr1: 0,
            cr2: 0,
            cr3: 0,
            brr: 0,
            gtpr: 0,
            rdr: 0,
            rxne: false,
            ore: false,
            tc: true,
            tdr: None,
            shift: None,
            line: None,
            ow: OneWireStats::default(),
            sent: 0,
        }
    }

    fn name(&self) -> String {
        if matches!(self.number, 4 | 5) {
            format!("UART{}", self.number)
        } else {
            format!("USART{}", self.number)
        }
    }

    /// Cycles of one frame at the present settings (`div`: CPU cycles per PCLK).
    fn frame_cycles(&self, div: u64) -> u64 {
        let data = if self.cr1 & CR1_M != 0 { 9 } else { 8 };
        let stop = match (self.cr2 >> 12) & 3 {
            2 => 2,
            _ => 1, // 0.5 and 1.5 stop bits count as one here
        };
        (1 + data + stop) * u64::from(self.brr) * div
    }

    /// The cycle the byte in the shift register finishes, if one is.
    pub fn busy_until(&self) -> Option<u64> {
        self.shift.map(|s| s.end)
    }

    /// When the byte in flight ends and an interrupt is enabled that its end may raise:
    /// the board stops there.
    pub fn next_event(&self) -> Option<u64> {
        if self.cr1 & (CR1_RXNEIE | CR1_TCIE) == 0 {
            return None;
        }
        self.busy_until()
    }

    /// The USART's interrupt line (as of the last sync): RXNE or ORE with RXNEIE, TC with
    /// TCIE.
    pub fn irq_lines(&self) -> u128 {
        let rx = self.cr1 & CR1_RXNEIE != 0 && (self.rxne || self.ore);
        let tc = self.cr1 & CR1_TCIE != 0 && self.tc;
        match IRQS.iter().find(|(n, _)| *n == self.number) {
            Some(&(_, irq)) if rx || tc => crate::nvic::bit(16 + irq),
            _ => 0,
        }
    }

    /// Brings the transmitter and receiver up to cycle `now`.
    pub fn sync(&mut self, now: u64, div: u64) {
        while let Some(s) = self.shift {
            if s.end > now {
                break;
            }
            self.shift = None;
            if let Some(b) = s.echo {
                if self.cr1 & CR1_RE != 0 {
                    if self.rxne {
                        self.ore = true;
                    } else {
                        self.rdr = b;
                        self.rxne = true;
                    }
                }
            }
            match self.tdr.take() {
                Some(next) => self.start(next, s.end, div),
                None => self.tc = true,
            }
        }
    }

    /// The shift register takes `b` at cycle `at`.
    fn start(&mut self, b: u8, at: u64, div: u64) {
        self.sent += 1;
        self.tc = false;
        let bit_cycles = u64::from(self.brr) * div;
        let half = self.cr3 & CR3_HDSEL != 0;
        let echo = match (&self.line, half) {
            (Some(line), true) => {
                let line = line.clone();
                Some(self.one_wire(&line, b, at, bit_cycles))
            }
            (None, true) => Some(b),
            (_, false) => None,
        };
        self.shift = Some(Shift {
            end: at + self.frame_cycles(div),
            echo,
        });
    }

    /// The byte `b` on the 1-Wire line at cycle `at`: what the devices do and what the
    /// receiver samples.
    fn one_wire(&mut self, line: &Mutex<OneWireNet>, b: u8, at: u64, bit_cycles: u64) -> u8 {
        let ns = |c: u64| (u128::from(c) * 1_000_000_000 / u128::from(crate::CPU_HZ)) as u64;
        let bit_ns = ns(bit_cycles);
        let low_ns = (1 + u64::from(b.trailing_zeros())) * bit_ns;
        let Ok(mut net) = line.lock() else {
            return b;
        };
        net.set_time(ns(at));
        // (start, end) of a time the devices hold the line low, from the start bit's edge.
        let held: Option<(u64, u64)> = if low_ns >= RESET_MIN_NS {
            self.ow.resets += 1;
            if net.reset() {
                self.ow.presences += 1;
                let from = low_ns + PRESENCE_WAIT_NS;
                Some((from, from + PRESENCE_NS))
            } else {
                None
            }
        } else if (ZERO_MIN_NS..=ZERO_MAX_NS).contains(&low_ns) {
            self.ow.zero_slots += 1;
            net.slot(false);
            None
        } else if (ONE_MIN_NS..ONE_MAX_NS).contains(&low_ns) {
            self.ow.one_slots += 1;
            if net.slot(true) {
                None
            } else {
                Some((0, READ_ZERO_HOLD_NS))
            }
        } else {
            self.ow.invalid += 1;
            None
        };
        let mut echo = b;
        if let Some((from, to)) = held {
            for i in 0..8u64 {
                let t = (2 * (1 + i) + 1) * bit_ns / 2;
                if (from..to).contains(&t) {
                    echo &= !(1 << i);
                }
            }
        }
        echo
    }

    /// A register read at offset `off`.
    pub fn read(&mut self, off: u64, now: u64, div: u64) -> Result<u32, String> {
        self.sync(now, div);
        Ok(match off {
            0x00 => {
                let bit = |on: bool, b: u32| if on { b } else { 0 };
                bit(self.rxne, SR_RXNE)
                    | bit(self.tc, SR_TC)
                    | bit(self.tdr.is_none(), SR_TXE)
                    | bit(self.ore, 1 << 3)
            }
            0x04 => {
                self.rxne = false;
                self.ore = false;
                u32::from(self.rdr)
            }
            0x08 => self.brr,
            0x0C => self.cr1,
            0x10 => self.cr2,
            0x14 => self.cr3,
            0x18 => self.gtpr,
            _ => return Err(self.unmodelled("read of", off, None)),
        })
    }

    fn unmodelled(&self, what: &str, off: u64, v: Option<u32>) -> String {
        let v = v.map(|v| format!(" {v:#010x}")).unwrap_or_default();
        format!(
            "{what}{v} {} at {:#010x}: not modelled (polled 8N1/9N1/2-stop frames, \
             half-duplex, RXNE/TC interrupts, no DMA)",
            self.name(),
            self.base + off
        )
    }

    /// A register write at offset `off`.
    pub fn write(&mut self, off: u64, v: u32, now: u64, div: u64) -> Result<(), String> {
        self.sync(now, div);
        match off {
            0x00 => {
                // rc_w0: RXNE and TC clear when written 0; the error flags are read-only.
                if v & SR_RXNE == 0 {
                    self.rxne = false;
                }
                if v & SR_TC == 0 {
                    self.tc = false;
                }
            }
            0x04 => {
                if self.cr1 & (CR1_UE | CR1_TE) != CR1_UE | CR1_TE {
                    return Err(self.unmodelled(
                        "write to DR with UE/TE off: the byte would be lost; write of",
                        off,
                        Some(v),
                    ));
                }
                if self.brr == 0 {
                    return Err(self.unmodelled("transmit with BRR = 0: write of", off, Some(v)));
                }
                let b = v as u8;
                if self.shift.is_none() {
                    self.start(b, now, div);
                } else {
                    // Into TDR (with TXE clear, the byte overwrites the one waiting, as on
                    // silicon).
                    self.tdr = Some(b);
                }
            }
            0x08 => self.brr = v & 0xFFFF,
            0x0C => {
                if v & !CR1_OK != 0 {
                    return Err(self.unmodelled("write of", off, Some(v)));
                }
                if v & CR1_UE == 0 {
                    // UE off: the prescalers stop at the end of the current byte; what is
                    // queued is dropped.
                    self.tdr = None;
                }
                self.cr1 = v;
            }
            0x10 => {
                if v & !CR2_OK != 0 {
                    return Err(self.unmodelled("write of", off, Some(v)));
                }
                self.cr2 = v;
            }
            0x14 => {
                if v & !CR3_HDSEL != 0 {
                    return Err(self.unmodelled("write of", off, Some(v)));
                }
                self.cr3 = v;
            }
            0x18 => self.gtpr = v,
            _ => return Err(self.unmodelled("write of", off, Some(v))),
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use oxicat_plant::onewire::{ds18b20_rom, Ds18b20};

    /// USART3 on a 45 MHz APB1 (4 CPU cycles per PCLK at 180 MHz), half-duplex, on `net`.
    fn uart(net: Option<Arc<Mutex<OneWireNet>>>) -> Usart {
        let mut u = Usart::new(0x4000_4800, 3, false);
        u.line = net;
        u.write(0x14, CR3_HDSEL, 0, 4).unwrap();
        u.write(0x0C, CR1_UE | CR1_TE | CR1_RE, 0, 4).unwrap();
        u
    }

    /// Sends `b` at `brr` and returns the byte received and when RXNE rose.
    fn xfer(u: &mut Usart, brr: u32, b: u8, now: &mut u64) -> (u8, u64) {
        u.write(0x08, brr, *now, 4).unwrap();
        u.write(0x04, u32::from(b), *now, 4).unwrap();
        let start = *now;
        while u.read(0x00, *now, 4).unwrap() & SR_RXNE == 0 {
            *now += 100;
            assert!(*now - start < 10_000_000, "no RXNE");
        }
        (u.read(0x04, *now, 4).unwrap() as u8, *now - start)
    }

    #[test]
    fn a_frame_takes_ten_bit_times_at_the_brr_rate() {
        let mut u = uart(None);
        let mut now = 0;
        // 45 MHz / 391 = 115,090 baud: 10 bits = 15,640 cycles at 180 MHz.
        let (b, dt) = xfer(&mut u, 391, 0x5A, &mut now);
        assert_eq!(b, 0x5A, "an idle half-duplex line reads back what was sent");
        assert!((15_640..15_640 + 100).contains(&dt), "{dt} cycles");
        assert_ne!(u.read(0, now, 4).unwrap() & SR_TC, 0);
        // Full duplex: nothing on RX.
        u.write(0x14, 0, now, 4).unwrap();
        u.write(0x04, 0x33, now, 4).unwrap();
        now += 20_000;
        assert_eq!(u.read(0, now, 4).unwrap() & SR_RXNE, 0);
        // The TXE interrupt and DMA are refused with the address.
        let e = u.write(0x0C, CR1_UE | (1 << 7), now, 4).unwrap_err();
        assert!(e.contains("0x4000480c"), "{e}");
        let e = u.write(0x14, 1 << 7, now, 4).unwrap_err();
        assert!(
            e.contains("0x40004814") && e.contains("not modelled"),
            "{e}"
        );
    }

    #[test]
    fn rxne_and_tc_raise_the_usarts_interrupt_line_when_enabled() {
        let line = crate::nvic::bit(16 + 39);
        let mut u = uart(None);
        u.write(0x08, 391, 0, 4).unwrap();
        u.write(0x0C, CR1_UE | CR1_TE | CR1_RE | CR1_RXNEIE, 0, 4)
            .unwrap();
        assert_eq!(u.next_event(), None, "nothing in flight");
        u.write(0x04, 0xA5, 0, 4).unwrap();
        // The board stops where the byte ends: RXNE rises there.
        let end = u.next_event().expect("a byte in flight");
        u.sync(end - 1, 4);
        assert_eq!(u.irq_lines(), 0, "not before the byte's end");
        u.sync(end, 4);
        assert_eq!(u.irq_lines(), line, "USART3 = IRQ 39");
        assert_eq!(u.read(0x04, end, 4).unwrap(), 0xA5);
        assert_eq!(u.irq_lines(), 0, "reading DR clears RXNE and the line");
        // TC with TCIE: the line stays up until TC is cleared.
        u.write(0x0C, CR1_UE | CR1_TE | CR1_TCIE, end, 4).unwrap();
        assert_eq!(u.irq_lines(), line, "TC is set after the byte");
        u.write(0x00, 0, end, 4).unwrap();
        assert_eq!(u.irq_lines(), 0);
        // Without the enables, no line.
        u.write(0x0C, CR1_UE | CR1_TE | CR1_RE, end, 4).unwrap();
        u.write(0x04, 0x5A, end, 4).unwrap();
        assert_eq!(u.next_event(), None);
        u.sync(end + 20_000, 4);
        assert_eq!(u.irq_lines(), 0);
    }

    #[test]
    fn reset_presence_and_slots_reach_the_bus_as_1_wire_timing() {
        let rom = ds18b20_rom(0x42);
        let net = Arc::new(Mutex::new(OneWireNet::new(vec![Ds18b20::new(rom)])));
        let mut u = uart(Some(net.clone()));
        let mut now = 0;
        // 9600 baud: 0xF0 holds the line low 520 µs; presence pulls bits 4.. low.
        let (echo, _) = xfer(&mut u, 4688, 0xF0, &mut now);
        assert_ne!(echo, 0xF0, "presence: {echo:#04x}");
        assert_eq!(echo & 0x0F, 0, "the master's own low time");
        // READ ROM at 115200: 0x33, then 64 read slots.
        for i in 0..8 {
            xfer(
                &mut u,
                391,
                if 0x33 >> i & 1 != 0 { 0xFF } else { 0x00 },
                &mut now,
            );
        }
        let mut got = [0u8; 8];
        for byte in &mut got {
            for i in 0..8 {
                if xfer(&mut u, 391, 0xFF, &mut now).0 == 0xFF {
                    *byte |= 1 << i;
                }
            }
        }
        assert_eq!(got, rom);
        assert_eq!(u.ow.resets, 1);
        assert_eq!(u.ow.presences, 1);
        assert_eq!(u.ow.zero_slots + u.ow.one_slots, 72);
        // No device: no presence (the echo is what was sent).
        net.lock().unwrap().devices[0].plugged = false;
        assert_eq!(xfer(&mut u, 4688, 0xF0, &mut now).0, 0xF0);
        // A byte at a rate that is no 1-Wire slot is ignored by the devices.
        xfer(&mut u, 1000, 0xFE, &mut now);
        assert_eq!(u.ow.invalid, 1);
    }
}
