//! `oxicat-emu`: board images executed instruction by instruction on the virtual segment.
//!
//! The bytes that would be flashed — a board firmware's ELF — run on a Cortex-M4 in the
//! Unicorn engine; the STM32F446 peripherals the images use are modelled here at register
//! level (from RM0390), and its SPI1 is wired to `oxicat-pdi`'s LAN9252 chip model in front
//! of a software ESC, so a master on the ECAT side talks to the *image*, not to
//! host-compiled Rust.
//!
//! This crate is GPL-2.0-or-later because Unicorn is GPL-2.0; nothing in the MIT/Apache
//! workspace depends on it.
//!
//! What is modelled (exactly what `firmware/stm32f446-lan9252` touches):
//!
//! | block | model |
//! |---|---|
//! | flash, SRAM | 512 KiB at 0x0800_0000 (the ELF's load segments at their load addresses), 128 KiB at 0x2000_0000 |
//! | RCC | reset values; HSE/PLL/PLLI2S/PLLSAI/LSE/LSI ready flags follow their enables, SWS follows SW |
//! | PWR | VOSRDY set; over-drive ready flags follow ODEN/ODSWEN |
//! | FLASH | ACR stored (latency reads back) |
//! | bit-band alias | 0x4200_0000.. : a word per peripheral bit, read-modify-write of the register |
//! | GPIOA..C | registers stored; BSRR sets/resets ODR; IDR = ODR for outputs, PA10 = LAN9252 IRQ, PB3/PB5 = SYNC0/SYNC1, PC13 = button released |
//! | SPI1 | a byte per DR write clocked through the chip (`Lan9252Model::clock_byte`) while PB6 (CS) is low; TXE always set, RXNE until DR is read; bus time counted at the CR1 baud rate |
//! | SysTick | CSR/RVR/CVR/CALIB, COUNTFLAG from the cycle count (processor clock or HCLK/8) |
//! | SCB | CPACR and the rest of the SCS page stored (no exceptions are taken yet) |
//!
//! Time: the CPU's cycle count is the number of instructions executed (one cycle per
//! instruction, counted per translated block), at 180 MHz. Anything the image touches
//! outside these blocks is reported as a fault with its PC and address, never a hang.

#![warn(missing_docs)]

pub mod node;

use std::cell::RefCell;
use std::rc::Rc;

use oxicat_pdi::sim::{Handle, Lan9252Frame, Lan9252Model, Model, PinKind};
use unicorn_engine::unicorn_const::{Arch, Mode, Prot};
use unicorn_engine::{ArmCpuModel, RegisterARM, Unicorn};

/// Flash base and size (STM32F446RE).
pub const FLASH: (u64, u64) = (0x0800_0000, 512 * 1024);
/// SRAM base and size (SRAM1 + SRAM2).
pub const SRAM: (u64, u64) = (0x2000_0000, 128 * 1024);
/// Peripheral space modelled (APB1, APB2, AHB1).
const PERIPH: (u64, u64) = (0x4000_0000, 0x8_0000);
/// The peripheral bit-band alias (one word per bit of `PERIPH`).
const BITBAND: (u64, u64) = (0x4200_0000, PERIPH.1 * 32);
/// The System Control Space page (SysTick, NVIC, SCB).
const SCS: (u64, u64) = (0xE000_E000, 0x1000);
/// CPU clock of the images (180 MHz SYSCLK).
pub const CPU_HZ: u64 = 180_000_000;

const RCC: u64 = 0x4002_3800;
const FLASH_R: u64 = 0x4002_3C00;
const PWR: u64 = 0x4000_7000;
const GPIOA: u64 = 0x4002_0000;
const GPIOB: u64 = 0x4002_0400;
const GPIOC: u64 = 0x4002_0800;
const SPI1: u64 = 0x4001_3000;
const SYST: u64 = 0xE000_E010;

/// Why an image stopped.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum EmuError {
    /// The file is not a 32-bit little-endian ARM ELF with loadable segments in flash/SRAM.
    BadImage(String),
    /// The CPU faulted: an access outside every modelled block, an undefined instruction, …
    Fault {
        /// Program counter when it stopped.
        pc: u32,
        /// The engine's reason.
        reason: String,
    },
}

impl std::fmt::Display for EmuError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            EmuError::BadImage(w) => write!(f, "not a board image: {w}"),
            EmuError::Fault { pc, reason } => {
                write!(f, "HardFault at PC {pc:#010x}: {reason}")
            }
        }
    }
}

impl std::error::Error for EmuError {}

/// A loadable segment of an ELF image: load address and bytes.
#[derive(Debug, Clone)]
pub struct Segment {
    /// Physical (load) address.
    pub addr: u32,
    /// Bytes in the file (the rest up to the memory size is zero).
    pub data: Vec<u8>,
    /// Size in memory.
    pub mem_size: u32,
}

/// The loadable segments of a 32-bit little-endian ARM ELF (`PT_LOAD`, at their load
/// addresses: `.data` is copied to RAM by the image's own reset code).
pub fn elf_segments(elf: &[u8]) -> Result<Vec<Segment>, EmuError> {
    let bad = |w: &str| EmuError::BadImage(w.to_string());
    let u16_at = |o: usize| -> Result<u16, EmuError> {
        Ok(u16::from_le_bytes(
            elf.get(o..o + 2)
                .ok_or_else(|| bad("truncated header"))?
                .try_into()
                .map_err(|_| bad("truncated header"))?,
        ))
    };
    let u32_at = |o: usize| -> Result<u32, EmuError> {
        Ok(u32::from_le_bytes(
            elf.get(o..o + 4)
                .ok_or_else(|| bad("truncated header"))?
                .try_into()
                .map_err(|_| bad("truncated header"))?,
        ))
    };
    if elf.get(..4) != Some(b"\x7fELF") {
        return Err(bad("no ELF magic"));
    }
    if elf.get(4) != Some(&1) || elf.get(5) != Some(&1) {
        return Err(bad("not a 32-bit little-endian ELF"));
    }
    if u16_at(18)? != 40 {
        return Err(bad("not an ARM ELF (e_machine != 40)"));
    }
    let (phoff, phentsize, phnum) = (u32_at(28)? as usize, u16_at(42)? as usize, u16_at(44)?);
    let mut out = Vec::new();
    for k in 0..phnum as usize {
        let p = phoff + k * phentsize;
        if u32_at(p)? != 1 {
            continue; // not PT_LOAD
        }
        let (off, paddr, filesz, memsz) = (
            u32_at(p + 4)? as usize,
            u32_at(p + 12)?,
            u32_at(p + 16)? as usize,
            u32_at(p + 20)?,
        );
        if filesz == 0 {
            continue;
        }
        let data = elf
            .get(off..off + filesz)
            .ok_or_else(|| bad("a segment lies past the end of the file"))?
            .to_vec();
        let inside = |(base, size): (u64, u64)| {
            u64::from(paddr) >= base && u64::from(paddr) + filesz as u64 <= base + size
        };
        if !inside(FLASH) && !inside(SRAM) {
            return Err(bad(&format!(
                "segment at {paddr:#010x} ({filesz} B) is outside flash and SRAM"
            )));
        }
        out.push(Segment {
            addr: paddr,
            data,
            mem_size: memsz,
        });
    }
    if out.is_empty() {
        return Err(bad("no loadable segment"));
    }
    Ok(out)
}

/// SPI traffic of the image, as counted on the emulated bus.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SpiStats {
    /// CS-low frames.
    pub frames: u64,
    /// Bytes clocked.
    pub bytes: u64,
    /// Bytes clocked while CS was high (the chip ignores them).
    pub bytes_without_cs: u64,
}

/// Peripheral state of the STM32F446 board.
struct Periph {
    chip: Handle<Lan9252Model>,
    regs: Vec<u32>,
    scs: Vec<u32>,
    frame: Option<Lan9252Frame>,
    spi_rx: u8,
    rxne: bool,
    spi: SpiStats,
    cycles: u64,
    /// Cycle count at SysTick's last reload.
    syst_ref: u64,
    countflag: bool,
}

impl Periph {
    fn reg(&self, addr: u64) -> u32 {
        self.regs[((addr - PERIPH.0) / 4) as usize]
    }

    fn set(&mut self, addr: u64, v: u32) {
        self.regs[((addr - PERIPH.0) / 4) as usize] = v;
    }

    /// Reset values the HAL relies on.
    fn reset(&mut self) {
        self.set(RCC, 0x0000_0083); // HSION, HSIRDY
        self.set(RCC + 0x04, 0x2400_3010); // PLLCFGR
        self.set(RCC + 0x74, 0x0E00_0000); // CSR: reset flags
        self.set(PWR + 0x04, 1 << 14); // CSR: VOSRDY
        self.set(GPIOA, 0xA800_0000);
        self.set(GPIOB, 0x0000_0280);
        self.set(SPI1 + 0x08, 0x0002); // SR: TXE
    }

    fn pin(&self, kind: PinKind) -> bool {
        self.chip.with(|m| m.pin(kind))
    }

    fn gpio_idr(&self, port: u64) -> u32 {
        let mut idr = self.reg(port + 0x14) & 0xFFFF;
        let mut put = |pin: u32, level: bool| {
            idr = (idr & !(1 << pin)) | (u32::from(level) << pin);
        };
        match port {
            GPIOA => put(10, self.pin(PinKind::Irq)),
            GPIOB => {
                put(3, self.pin(PinKind::Sync0));
                put(5, self.pin(PinKind::Sync1));
            }
            GPIOC => put(13, true),
            _ => {}
        }
        idr
    }

    /// PB6 (CS) changed to `high`.
    fn chip_select(&mut self, high: bool) {
        match (high, self.frame.take()) {
            (false, None) => {
                self.frame = Some(Lan9252Frame::default());
                self.spi.frames += 1;
            }
            (true, Some(f)) => self.chip.with(|m| m.end_frame(f)),
            (_, f) => self.frame = f,
        }
    }

    fn write_odr(&mut self, port: u64, odr: u32) {
        let old = self.reg(port + 0x14);
        self.set(port + 0x14, odr & 0xFFFF);
        if port == GPIOB && (old ^ odr) & (1 << 6) != 0 {
            self.chip_select(odr & (1 << 6) != 0);
        }
    }

    fn spi_dr_write(&mut self, v: u8) {
        self.spi.bytes += 1;
        self.spi_rx = match self.frame.as_mut() {
            Some(f) => self.chip.with(|m| m.clock_byte(f, v)),
            None => {
                self.spi.bytes_without_cs += 1;
                0xFF
            }
        };
        self.rxne = true;
        // The byte takes 8 SCLK periods at PCLK2 (90 MHz) / 2^(BR+1).
        let br = (self.reg(SPI1) >> 3) & 7;
        self.cycles += 8 * 2 * (2u64 << br);
    }

    fn read(&mut self, addr: u64) -> u32 {
        match addr {
            a if a == SPI1 + 0x08 => 0x0002 | u32::from(self.rxne),
            a if a == SPI1 + 0x0C => {
                self.rxne = false;
                u32::from(self.spi_rx)
            }
            a if a == GPIOA + 0x10 || a == GPIOB + 0x10 || a == GPIOC + 0x10 => {
                self.gpio_idr(a - 0x10)
            }
            a => self.reg(a),
        }
    }

    fn write(&mut self, addr: u64, v: u32) {
        match addr {
            a if a == RCC => {
                // Ready flags follow their enables: HSE 16/17, PLL 24/25, PLLI2S 26/27,
                // PLLSAI 28/29; HSI stays on.
                let mut r = (v & 0x5505_00F9) | 0x3;
                for en in [16, 24, 26, 28] {
                    if v & (1 << en) != 0 {
                        r |= 1 << (en + 1);
                    }
                }
                self.set(a, r);
            }
            a if a == RCC + 0x08 => self.set(a, (v & !0xC) | ((v & 3) << 2)),
            a if a == RCC + 0x70 => self.set(a, (v & !2) | ((v & 1) << 1)),
            a if a == RCC + 0x74 => self.set(a, (v & !2) | ((v & 1) << 1)),
            a if a == PWR => {
                self.set(a, v);
                let csr = (self.reg(PWR + 4) & !(3 << 16)) | (v & (3 << 16));
                self.set(PWR + 4, csr | (1 << 14));
            }
            a if a == FLASH_R => self.set(a, v),
            a if a == SPI1 + 0x0C => self.spi_dr_write(v as u8),
            a if a == SPI1 + 0x08 => {}
            a if [GPIOA, GPIOB, GPIOC].contains(&(a - 0x18)) => {
                let port = a - 0x18;
                let odr = (self.reg(port + 0x14) | (v & 0xFFFF)) & !(v >> 16);
                self.write_odr(port, odr);
            }
            a if [GPIOA, GPIOB, GPIOC].contains(&(a - 0x14)) => self.write_odr(a - 0x14, v),
            a => self.set(a, v),
        }
    }

    fn syst_read(&mut self, off: u64) -> u32 {
        let rvr = u64::from(self.scs[(SYST - SCS.0 + 4) as usize / 4] & 0x00FF_FFFF);
        let csr = self.scs[(SYST - SCS.0) as usize / 4];
        // CLKSOURCE (bit 2): the processor clock, else the external reference HCLK/8; a
        // period is RVR + 1 ticks.
        let cycles_per_tick = if csr & 4 != 0 { 1 } else { 8 };
        let period = (rvr + 1) * cycles_per_tick;
        let enabled = csr & 1 != 0;
        let elapsed = self.cycles.saturating_sub(self.syst_ref);
        if enabled && elapsed >= period {
            self.countflag = true;
            self.syst_ref += elapsed / period * period;
        }
        match off {
            0 => {
                let v = csr | (u32::from(self.countflag) << 16);
                self.countflag = false;
                v
            }
            8 if enabled => {
                let left = period - (self.cycles - self.syst_ref) % period;
                ((left / cycles_per_tick) % (rvr + 1)) as u32
            }
            0xC => 0x4000_0000 | (CPU_HZ / 8 / 100) as u32, // CALIB: NOREF, 10 ms at HCLK/8
            _ => self.scs[(SYST - SCS.0 + off) as usize / 4],
        }
    }

    fn scs_read(&mut self, addr: u64) -> u32 {
        if (SYST..SYST + 0x10).contains(&addr) {
            return self.syst_read(addr - SYST);
        }
        self.scs[((addr - SCS.0) / 4) as usize]
    }

    fn scs_write(&mut self, addr: u64, v: u32) {
        if addr == SYST + 8 {
            // Any write clears CVR and COUNTFLAG.
            self.syst_ref = self.cycles;
            self.countflag = false;
            return;
        }
        if addr == SYST && v & 1 != 0 && self.scs[(SYST - SCS.0) as usize / 4] & 1 == 0 {
            self.syst_ref = self.cycles;
        }
        self.scs[((addr - SCS.0) / 4) as usize] = v;
    }
}

/// Sub-word access to a 32-bit register file.
fn read_sized(word: u32, addr: u64, size: usize) -> u64 {
    let shift = (addr & 3) * 8;
    let mask = if size >= 4 {
        u32::MAX
    } else {
        (1u32 << (size * 8)) - 1
    };
    u64::from((word >> shift) & mask)
}

fn merge_sized(old: u32, addr: u64, size: usize, v: u64) -> u32 {
    if size >= 4 {
        return v as u32;
    }
    let shift = (addr & 3) * 8;
    let mask = ((1u32 << (size * 8)) - 1) << shift;
    (old & !mask) | (((v as u32) << shift) & mask)
}

/// An STM32F446 running a board image, with a LAN9252 (the chip model `chip`) on SPI1.
pub struct Board {
    uc: Unicorn<'static, ()>,
    periph: Rc<RefCell<Periph>>,
    pc: u32,
    instructions: u64,
}

impl Board {
    /// Loads the ELF `image` into flash/SRAM and resets the CPU (SP and PC from the vector
    /// table at the start of flash). `chip` is the LAN9252 on SPI1.
    pub fn new(image: &[u8], chip: Handle<Lan9252Model>) -> Result<Self, EmuError> {
        let segs = elf_segments(image)?;
        let fault = |e: unicorn_engine::unicorn_const::uc_error| EmuError::Fault {
            pc: 0,
            reason: format!("engine set-up: {e:?}"),
        };
        let mut uc = Unicorn::new(Arch::ARM, Mode::THUMB).map_err(fault)?;
        uc.ctl_set_cpu_model(ArmCpuModel::CORTEX_M4 as i32)
            .map_err(fault)?;
        uc.mem_map(FLASH.0, FLASH.1, Prot::READ | Prot::EXEC)
            .map_err(fault)?;
        uc.mem_map(SRAM.0, SRAM.1, Prot::ALL).map_err(fault)?;
        for s in &segs {
            uc.mem_write(u64::from(s.addr), &s.data).map_err(fault)?;
        }
        let mut p = Periph {
            chip,
            regs: vec![0; (PERIPH.1 / 4) as usize],
            scs: vec![0; (SCS.1 / 4) as usize],
            frame: None,
            spi_rx: 0xFF,
            rxne: false,
            spi: SpiStats::default(),
            cycles: 0,
            syst_ref: 0,
            countflag: false,
        };
        p.reset();
        let periph = Rc::new(RefCell::new(p));
        let (r, w) = (periph.clone(), periph.clone());
        uc.mmio_map(
            PERIPH.0,
            PERIPH.1,
            Some(move |_: &mut Unicorn<'_, ()>, off: u64, size: usize| {
                let a = PERIPH.0 + off;
                let word = r.borrow_mut().read(a & !3);
                read_sized(word, a, size)
            }),
            Some(
                move |_: &mut Unicorn<'_, ()>, off: u64, size: usize, v: u64| {
                    let a = PERIPH.0 + off;
                    let mut p = w.borrow_mut();
                    let old = p.reg(a & !3);
                    p.write(a & !3, merge_sized(old, a, size, v));
                },
            ),
        )
        .map_err(fault)?;
        // Bit-band alias: word k of the alias is bit k % 32 of word k / 32 of the block.
        let (r, w) = (periph.clone(), periph.clone());
        let target = |off: u64| (PERIPH.0 + (off / 128) * 4, ((off / 4) % 32) as u32);
        uc.mmio_map(
            BITBAND.0,
            BITBAND.1,
            Some(move |_: &mut Unicorn<'_, ()>, off: u64, _size: usize| {
                let (a, bit) = target(off);
                u64::from((r.borrow_mut().read(a) >> bit) & 1)
            }),
            Some(
                move |_: &mut Unicorn<'_, ()>, off: u64, _size: usize, v: u64| {
                    let (a, bit) = target(off);
                    let mut p = w.borrow_mut();
                    let old = p.reg(a);
                    p.write(a, (old & !(1 << bit)) | (u32::from(v & 1 != 0) << bit));
                },
            ),
        )
        .map_err(fault)?;
        let (r, w) = (periph.clone(), periph.clone());
        uc.mmio_map(
            SCS.0,
            SCS.1,
            Some(move |_: &mut Unicorn<'_, ()>, off: u64, size: usize| {
                let a = SCS.0 + off;
                let word = r.borrow_mut().scs_read(a & !3);
                read_sized(word, a, size)
            }),
            Some(
                move |_: &mut Unicorn<'_, ()>, off: u64, size: usize, v: u64| {
                    let a = SCS.0 + off;
                    let mut p = w.borrow_mut();
                    let old = p.scs[((a & !3) - SCS.0) as usize / 4];
                    p.scs_write(a & !3, merge_sized(old, a, size, v));
                },
            ),
        )
        .map_err(fault)?;
        // Cycles: one per instruction, counted per translated block as it runs (Thumb-2
        // instructions are 2 or 4 bytes: the block's bytes / 3 on average).
        let c = periph.clone();
        uc.add_block_hook(
            1,
            0,
            move |_: &mut Unicorn<'_, ()>, _addr: u64, size: u32| {
                c.borrow_mut().cycles += u64::from(size.div_ceil(3));
            },
        )
        .map_err(fault)?;
        let mut vt = [0u8; 8];
        uc.mem_read(FLASH.0, &mut vt).map_err(fault)?;
        let sp = u32::from_le_bytes([vt[0], vt[1], vt[2], vt[3]]);
        let pc = u32::from_le_bytes([vt[4], vt[5], vt[6], vt[7]]);
        uc.reg_write(RegisterARM::SP, u64::from(sp))
            .map_err(fault)?;
        Ok(Board {
            uc,
            periph,
            pc,
            instructions: 0,
        })
    }

    /// Runs `n` instructions (fewer if the image stops). A fault is an error with the PC.
    pub fn run(&mut self, n: usize) -> Result<(), EmuError> {
        let r = self.uc.emu_start(u64::from(self.pc | 1), u64::MAX, 0, n);
        let pc = self.uc.reg_read(RegisterARM::PC).unwrap_or(0) as u32;
        self.instructions += n as u64;
        match r {
            Ok(()) => {
                self.pc = pc;
                Ok(())
            }
            Err(e) => Err(EmuError::Fault {
                pc,
                reason: format!("{e:?}"),
            }),
        }
    }

    /// Runs slices of `slice` instructions until `done` holds or `max` instructions ran;
    /// whether `done` held.
    pub fn run_until(
        &mut self,
        slice: usize,
        max: u64,
        mut done: impl FnMut(&mut Self) -> bool,
    ) -> Result<bool, EmuError> {
        let start = self.instructions;
        while self.instructions - start < max {
            self.run(slice)?;
            if done(self) {
                return Ok(true);
            }
        }
        Ok(false)
    }

    /// Instructions executed so far (as asked of the engine).
    pub fn instructions(&self) -> u64 {
        self.instructions
    }

    /// CPU cycles so far (instructions plus SPI wait), the image's time base.
    pub fn cycles(&self) -> u64 {
        self.periph.borrow().cycles
    }

    /// Simulated time in ns at [`CPU_HZ`].
    pub fn time_ns(&self) -> u64 {
        self.cycles() * 1_000_000_000 / CPU_HZ
    }

    /// The program counter where the last run stopped.
    pub fn pc(&self) -> u32 {
        self.pc
    }

    /// SPI traffic so far.
    pub fn spi_stats(&self) -> SpiStats {
        self.periph.borrow().spi
    }

    /// An output pin's level (`port` 'A'..='C').
    pub fn output(&self, port: char, pin: u8) -> bool {
        let base = match port {
            'A' => GPIOA,
            'B' => GPIOB,
            _ => GPIOC,
        };
        self.periph.borrow().reg(base + 0x14) & (1 << pin) != 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_that_is_not_an_arm_elf_is_refused_with_the_reason() {
        assert!(
            matches!(elf_segments(b"hello"), Err(EmuError::BadImage(w)) if w.contains("magic"))
        );
        let mut e = vec![0u8; 64];
        e[..4].copy_from_slice(b"\x7fELF");
        e[4] = 2;
        assert!(matches!(elf_segments(&e), Err(EmuError::BadImage(w)) if w.contains("32-bit")));
        e[4] = 1;
        e[5] = 1;
        e[18] = 62; // x86-64
        assert!(matches!(elf_segments(&e), Err(EmuError::BadImage(w)) if w.contains("ARM")));
        e[18] = 40;
        assert!(
            matches!(elf_segments(&e), Err(EmuError::BadImage(w)) if w.contains("no loadable"))
        );
        // A program header table past the end.
        e[28] = 200;
        e[44] = 1;
        assert!(matches!(elf_segments(&e), Err(EmuError::BadImage(w)) if w.contains("truncated")));
    }

    #[test]
    fn sub_word_register_access_reads_and_merges_bytes() {
        assert_eq!(read_sized(0x1234_5678, 0x4000_0001, 1), 0x56);
        assert_eq!(read_sized(0x1234_5678, 0x4000_0002, 2), 0x1234);
        assert_eq!(merge_sized(0x1234_5678, 0x4000_0002, 1, 0xAB), 0x12AB_5678);
        assert_eq!(merge_sized(0x1234_5678, 0x4000_0000, 4, 0xAB), 0xAB);
    }
}
