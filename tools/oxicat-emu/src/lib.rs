//! `oxicat-emu`: board images executed instruction by instruction on the virtual segment.
//!
//! The bytes that would be flashed — a board firmware's ELF — run on a Cortex-M4 in the
//! Unicorn engine; the STM32F446 peripherals the images use are modelled here at register
//! level (from RM0390 and the ARMv7-M architecture reference), and its SPI1 is wired to
//! `oxicat-pdi`'s LAN9252 or ET1100 chip model (the board's choice, [`EscChip`]) in front
//! of a software ESC, so a master on the ECAT side talks to the *image*, not to
//! host-compiled Rust.
//!
//! This crate is GPL-2.0-or-later because Unicorn is GPL-2.0; nothing in the MIT/Apache
//! workspace depends on it.
//!
//! What is modelled (what `firmware/stm32f446-lan9252`, `firmware/laelaps-leg`,
//! `firmware/cia402-joint`, `firmware/axis-hub` and `firmware/tue-es030` touch):
//!
//! | block | model |
//! |---|---|
//! | flash, SRAM | 512 KiB at 0x0800_0000 (the ELF's load segments at their load addresses), 128 KiB at 0x2000_0000; the sectors that hold the image are the engine's memory, the sectors after them ([`Board::flash_stats`]`.model_from`) are served by the FLASH model |
//! | RCC | reset values; HSE/PLL/PLLI2S/PLLSAI/LSE/LSI ready flags follow their enables, SWS follows SW; CFGR's APB prescalers (and DCKCFGR.TIMPRE) set the timer clocks; CSR's reset flags read-only (power-on: POR, PIN, BOR; a watchdog reset adds IWDGRSTF and PINRSTF), RMVF clears them |
//! | IWDG | [`iwdg`]: KR keys (0xCCCC start from 0xFFF, 0xAAAA reload from RLR, 0x5555 unlock), PR /4../256, RLR, SR PVU/RVU for 5 LSI periods after a write; counts at the LSI ([`iwdg::LSI_HZ`] = 32 kHz unless [`Board::set_lsi_hz`]); on expiry a system reset: the core restarts from the vector table (SP, reset vector, thread mode, masks clear), every peripheral returns to its reset values, SRAM, the ESC chip, the board's clock and what the board's world drives stay ([`Board::watchdog_resets`]). WWDG: any access is a fault |
//! | PWR | VOSRDY set; over-drive ready flags follow ODEN/ODSWEN |
//! | FLASH | [`flash`]: ACR stored; KEYR unlock (KEY1, KEY2; a wrong key or a key while unlocked is a bus error — a fault — and locks CR until reset), OPTKEYR/OPTCR (nWRP per sector); sector erase (SER/SNB/STRT: 0xFF) and programming (PG: a CPU write of the PSIZE width, old & new: only clears bits) of the sectors after the image, BSY for the datasheet's typical times on the board's clock (128 KiB: 1 s at x32; 16 µs a word); PGSERR (PG clear or locked), PGPERR (width ≠ PSIZE), PGAERR (unaligned), WRPERR (protected sector); EOP with EOPIE; while BSY a fetch, read or write of flash and a write of CR stall the core to BSY's end (no read-while-write). A write or erase of the image's own sectors, MER: faults |
//! | bit-band alias | 0x4200_0000.. : a word per peripheral bit, read-modify-write of the register (through its read, as the bus does) |
//! | GPIOA..H | registers stored (MODER, AFR …); BSRR sets/resets ODR; IDR: PA10 = the chip's IRQ, PB3/PB5 = SYNC0/SYNC1, PB4 = an ET1100's EEPROM_LOADED, then levels injected with [`Board::set_input`], PC13 = button released, ODR for outputs, pull-ups high |
//! | SPI1 | a byte per DR write clocked through the chip (`Lan9252Model::clock_byte`, `Et1100Model::clock_byte` with the idle time before the byte) while PB6 (CS) is low; TXE always set, RXNE until DR is read; bus time counted at the CR1 baud rate (or a what-if clock, [`Board::set_spi_sclk_hz`]) |
//! | ADC1 | the injected group ([`adc`]): JSQR/JL, SMPRx, RES, ALIGN, JOFRx; started by JSWSTART or TIM1_TRGO rising edges (OCxREF or update event), every channel sampled at the trigger from [`Board::set_analog`], JEOC after Σ(SMP + resolution) ADCCLK cycles (PCLK2 / ADCPRE), IRQ 18 with JEOCIE; the regular group's single software-started conversion of one channel (SWSTART, SQ1 → DR, EOC cleared by reading DR); regular sequences, CONT, EXTEN, other triggers, ADC2/3, and a channel nothing drives are faults |
//! | EXTI, SYSCFG | EXTICR1..4 select the port of lines 0..15; RTSR/FTSR edges on IMR lines set PR (write-1-to-clear), SWIER; pins sampled after every engine run, SPI frame and GPIO write; IRQs EXTI0..4, EXTI9_5, EXTI15_10 |
//! | TIM1..TIM14 | one model (`timers`): PSC/ARR (preloaded)/CNT from the cycle count at the APB timer clock, up/down/center-aligned, RCR (TIM1/8), UDIS/URS/OPM, UG; UIF → update IRQ; CCR/CCMR/CCER stored, PWM duty ([`Board::pwm_duty`]); encoder mode (SMS 1/2/3) from [`Board::set_encoder`]; input capture with CCxIF/CCxOF from [`Board::capture`]; timer links: TRGO in compare-pulse mode (CR2.MMS = 011) on a CH1 capture → the timers whose SMCR.TS selects it (ITR0..3, RM0390's table) capture on TRC (CCxS = 11); TRGO = OC1REF..OC4REF (MMS = 1xx) in PWM mode 1/2 or the update event (MMS = 010, with RCR) as ADC1's trigger, its rising edges computed from the counter (UG's pulse included); a complementary output alone (CCxE = 0, CCxNE = 1) as the channel's PWM. No output-compare match flags, no other master/slave modes |
//! | plant | a [`BoardPlant`] stepped in lockstep with the CPU ([`plant::run_with_plant`], [`node::EmulatedNode::with_plant`]) schedules [`Stimulus`]es (encoder positions, capture edges, input levels, analogue voltages) at their times of the board's clock; [`laelaps`]: the Laelaps II leg on the leg image's pins; [`cia402`]: the CiA402 joint on the joint image's; [`tue_es030`]: the TUeES030's three RE 30 channels on its image's |
//! | profile | handler time per exception from entry to return, preemption counted apart ([`Board::handler_stats`]); painted stack high-water mark ([`Board::stack_stats`]); flash/RAM from the ELF ([`Board::image_size`]) |
//! | NVIC, SCB | ISER/ICER/ISPR/ICPR/IABR, IPR (4 bits), STIR; ICSR (VECTACTIVE/VECTPENDING/RETTOBASE, PENDSV/PENDST/NMIPEND set/clear), VTOR, AIRCR (PRIGROUP; SYSRESETREQ stops the image with a fault: only the IWDG resets the MCU), SCR.SLEEPONEXIT, CCR, SHPR1..3, SHCSR enables, CPACR, FPCCR; the rest of the page stored |
//! | exceptions | taken at translated-block boundaries by the board (`cpu`): 8-word frame, or 26 with S0..S15/FPSCR when CONTROL.FPCA (stacked eagerly although FPCCR resets with LSPEN/ASPEN set: same result for both sides), 8-byte alignment, EXC_RETURN, MSP/PSP, tail-chaining, preemption by group priority, PRIMASK/BASEPRI/FAULTMASK, SVC → SVCall, PendSV, SysTick. Inside the engine the core stays in thread mode: `mrs rX, ipsr` reads 0 (ICSR has the number); unprivileged thread mode is refused |
//! | SysTick | CSR/RVR/CVR/CALIB from the cycle count (processor clock or HCLK/8); COUNTFLAG; TICKINT pends SysTick at each wrap |
//! | DWT | CTRL (CYCCNTENA), CYCCNT counting the cycles the core runs (not sleeps) while DEMCR.TRCENA; other registers stored |
//! | DBGMCU | IDCODE (STM32F446, 0x421); the rest stored |
//! | sleep | WFI (and WFE without a pending event) skips time to the next timer/SysTick event or the end of the run, waking on a pending exception that would preempt (PRIMASK does not stop the wake-up); a delay loop spinning on SysTick's COUNTFLAG (the same CSR read again within 64 cycles, no other register access between) skips to the next wrap ([`Board::polled_cycles`]) |
//!
//! Faults are reported, never taken: an access outside these blocks, an undefined
//! instruction, BKPT, a floating-point instruction with CPACR's CP10/CP11 off (found when
//! the engine returns, so the PC is near, not at, the instruction), an SVC that cannot
//! preempt, a bad vector or EXC_RETURN, a stack the frame does not fit — each is an
//! [`EmuError::Fault`] with the PC and the reason, never a hang.
//!
//! Time: the CPU's cycle count is the number of instructions executed (one cycle per
//! instruction, counted per translated block as it starts), plus SPI wait, exception
//! entry/return (12/10, tail-chain 6) and sleep, at 180 MHz.

#![warn(missing_docs)]

pub mod adc;
pub mod axis_hub;
pub mod chip;
pub mod cia402;
mod cpu;
pub mod dma;
mod exti;
pub mod flash;
pub mod iwdg;
pub mod laelaps;
pub mod node;
mod nvic;
mod periph;
pub mod plant;
mod stats;
mod timers;
pub mod trot;
pub mod tue_es030;
pub mod usart;

pub use chip::{ChipKind, EscChip};
pub use plant::BoardPlant;
pub use stats::{image_size, HandlerStats, ImageSize, LostEdge, MaskedSpan, StackStats};

use std::cell::RefCell;
use std::rc::Rc;

use unicorn_engine::unicorn_const::{Arch, HookType, MemType, Mode, Prot};
use unicorn_engine::{ArmCpuModel, RegisterARM, Unicorn};

use nvic::{Masks, SVCALL};
use periph::{Periph, GPIOA, PERIPH, PORTS};

/// Flash base and size (STM32F446RE).
pub const FLASH: (u64, u64) = (0x0800_0000, 512 * 1024);
/// SRAM base and size (SRAM1 + SRAM2).
pub const SRAM: (u64, u64) = (0x2000_0000, 128 * 1024);
/// The peripheral bit-band alias (one word per bit of `PERIPH`).
const BITBAND: (u64, u64) = (0x4200_0000, PERIPH.1 * 32);
/// The System Control Space page (SysTick, NVIC, SCB).
const SCS: (u64, u64) = (nvic::SCS_BASE, 0x1000);
/// The DWT page.
const DWT: (u64, u64) = (nvic::DWT_BASE, 0x1000);
/// DBGMCU.
const DBGMCU: (u64, u64) = (0xE004_2000, 0x1000);
/// CPU clock of the images (180 MHz SYSCLK).
pub const CPU_HZ: u64 = 180_000_000;

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

/// Serves a DMA stream that was just enabled: its items from the engine's memory (an
/// unmapped buffer is a fault with its address).
fn dma_fetch(uc: &mut Unicorn<'_, ()>, p: &mut Periph) {
    let Some(f) = p.dma_fetch.take() else {
        return;
    };
    let (di, si, addr, items, size) = f;
    let mut buf = vec![0u8; items * size];
    match uc.mem_read(u64::from(addr), &mut buf) {
        Ok(()) => p.dma_loaded(f, &buf),
        Err(e) => {
            p.fault.get_or_insert(format!(
                "DMA{} stream {si}: fetch of {} bytes at {addr:#010x}: {e:?}",
                di + 1,
                buf.len()
            ));
            p.wake_at = 0;
        }
    }
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

/// The bytes of the symbol `name` of an image's symbol table, read from its loadable
/// segments (a constant in flash: `None` when the image has no such symbol or it does not
/// lie in a loaded segment, e.g. a stripped image).
pub fn elf_symbol_bytes(elf: &[u8], name: &str) -> Result<Option<Vec<u8>>, EmuError> {
    let segments = elf_segments(elf)?;
    let Some(sym) = elf_symbols(elf)?
        .into_iter()
        .find(|s| s.name == name.as_bytes())
    else {
        return Ok(None);
    };
    let (addr, len) = (u64::from(sym.addr), u64::from(sym.size));
    Ok(segments.iter().find_map(|s| {
        let start = u64::from(s.addr);
        (addr >= start && addr + len <= start + s.data.len() as u64).then(|| {
            let o = (addr - start) as usize;
            s.data[o..o + len as usize].to_vec()
        })
    }))
}

/// One entry of an ELF symbol table.
struct ElfSymbol {
    name: Vec<u8>,
    addr: u32,
    size: u32,
    /// STT_FUNC.
    function: bool,
}

/// The entries of an image's symbol tables (none for a stripped image).
fn elf_symbols(elf: &[u8]) -> Result<Vec<ElfSymbol>, EmuError> {
    let bad = || EmuError::BadImage("truncated section or symbol table".into());
    let u16_at = |o: usize| -> Result<usize, EmuError> {
        let b = elf.get(o..o + 2).ok_or_else(bad)?;
        Ok(usize::from(u16::from_le_bytes([b[0], b[1]])))
    };
    let u32_at = |o: usize| -> Result<usize, EmuError> {
        let b = elf.get(o..o + 4).ok_or_else(bad)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
    };
    let (shoff, shentsize, shnum) = (u32_at(32)?, u16_at(46)?, u16_at(48)?);
    let mut out = Vec::new();
    for k in 0..shnum {
        let sh = shoff + k * shentsize;
        if u32_at(sh + 4)? != 2 {
            continue; // not SHT_SYMTAB
        }
        let (off, size, link) = (u32_at(sh + 16)?, u32_at(sh + 20)?, u32_at(sh + 24)?);
        let strtab = shoff + link * shentsize;
        let (str_off, str_size) = (u32_at(strtab + 16)?, u32_at(strtab + 20)?);
        let strings = elf.get(str_off..str_off + str_size).ok_or_else(bad)?;
        for e in (off..off + size).step_by(16) {
            let n = u32_at(e)?;
            let sym = strings.get(n..).ok_or_else(bad)?;
            let end = sym.iter().position(|&c| c == 0).unwrap_or(sym.len());
            let info = elf.get(e + 12).copied().ok_or_else(bad)?;
            out.push(ElfSymbol {
                name: sym[..end].to_vec(),
                addr: u32_at(e + 4)? as u32,
                size: u32_at(e + 8)? as u32,
                function: info & 0xF == 2,
            });
        }
    }
    Ok(out)
}

/// The functions of an image (start without the Thumb bit, size, demangled name), by
/// start address: what [`Board::function_at`] looks addresses up in.
fn elf_functions(elf: &[u8]) -> Result<Vec<(u32, u32, String)>, EmuError> {
    let mut f: Vec<(u32, u32, String)> = elf_symbols(elf)?
        .into_iter()
        .filter(|s| s.function && s.size > 0)
        .map(|s| {
            (
                s.addr & !1,
                s.size,
                demangle(&String::from_utf8_lossy(&s.name)),
            )
        })
        .collect();
    f.sort_by_key(|e| e.0);
    Ok(f)
}

/// A Rust symbol in the legacy mangling (`_ZN…17h<hash>E`) as its path; other names as
/// they are.
fn demangle(name: &str) -> String {
    let Some(mut rest) = name.strip_prefix("_ZN") else {
        return name.to_string();
    };
    let mut parts: Vec<&str> = Vec::new();
    while let Some(d) = rest.find(|c: char| !c.is_ascii_digit()) {
        let Ok(n) = rest[..d].parse::<usize>() else {
            break;
        };
        let Some(part) = rest.get(d..d + n) else {
            return name.to_string();
        };
        parts.push(part);
        rest = &rest[d + n..];
    }
    if parts.last().is_some_and(|h| {
        h.len() == 17 && h.starts_with('h') && h[1..].chars().all(|c| c.is_ascii_hexdigit())
    }) {
        parts.pop();
    }
    if rest != "E" || parts.is_empty() {
        return name.to_string();
    }
    parts
        .iter()
        .map(|p| {
            p.replace("$LT$", "<")
                .replace("$GT$", ">")
                .replace("$u20$", " ")
                .replace("..", "::")
        })
        .collect::<Vec<_>>()
        .join("::")
}

/// What an MSR or CPS instruction does to the masks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum MaskOp {
    /// CPSID/CPSIE: `disable`, on PRIMASK (`i`) and/or FAULTMASK (`f`).
    Cps { disable: bool, i: bool, f: bool },
    /// MSR to special register SYSm (0x10 PRIMASK, 0x11 BASEPRI, 0x12 BASEPRI_MAX,
    /// 0x13 FAULTMASK) from register `rn`.
    Msr { rn: u8, sysm: u8 },
}

/// The mask instruction whose first halfword is `hw1` (and second `hw2`), if it is one.
fn mask_op(hw1: u16, hw2: u16) -> Option<MaskOp> {
    if hw1 & 0xFFE8 == 0xB660 && hw1 & 3 != 0 {
        return Some(MaskOp::Cps {
            disable: hw1 & 0x10 != 0,
            i: hw1 & 2 != 0,
            f: hw1 & 1 != 0,
        });
    }
    let sysm = (hw2 & 0xFF) as u8;
    (hw1 & 0xFFF0 == 0xF380 && hw2 & 0xFF00 == 0x8800 && (0x10..=0x13).contains(&sysm)).then_some(
        MaskOp::Msr {
            rn: (hw1 & 0xF) as u8,
            sysm,
        },
    )
}

/// Every halfword of the image's flash segments that starts a mask instruction (data that
/// happens to look like one is never executed, so its hook never runs).
fn mask_sites(segs: &[Segment]) -> Vec<(u32, MaskOp)> {
    let mut out = Vec::new();
    for s in segs {
        if !(FLASH.0..FLASH.0 + FLASH.1).contains(&u64::from(s.addr)) {
            continue;
        }
        let half = |o: usize| {
            s.data
                .get(o..o + 2)
                .map_or(0, |b| u16::from_le_bytes([b[0], b[1]]))
        };
        for o in (0..s.data.len().saturating_sub(1)).step_by(2) {
            if let Some(op) = mask_op(half(o), half(o + 2)) {
                out.push((s.addr + o as u32, op));
            }
        }
    }
    out
}

/// An input event a plant schedules at a time of the board's clock
/// ([`Board::schedule`]): applied when the CPU's clock reaches it, between instructions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Stimulus {
    /// The shaft on timer `tim`'s encoder inputs is at `edges` quadrature edges
    /// ([`Board::set_encoder`]).
    Encoder {
        /// Timer number (TIM2 = 2).
        tim: u8,
        /// Position in quadrature edges (four per line).
        edges: i64,
    },
    /// An active edge on timer `tim`'s input TI`input` ([`Board::capture`]), with the
    /// TRGO pulse it causes routed to the linked timers.
    Capture {
        /// Timer number.
        tim: u8,
        /// Input 1..=4.
        input: u8,
    },
    /// ADC input channel `channel` (IN0..IN18) at `volts` ([`Board::set_analog`]).
    Analog {
        /// Channel number (IN10 = 10).
        channel: u8,
        /// Voltage on the pin \[V\].
        volts: f64,
    },
    /// Input pin `pin` of `port` ('A'..='H') driven to `level` ([`Board::set_input`]).
    Input {
        /// Port letter.
        port: char,
        /// Pin 0..=15.
        pin: u8,
        /// Level.
        level: bool,
    },
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

/// What the FLASH model did ([`Board::flash_stats`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FlashStats {
    /// Sector erases.
    pub erases: u64,
    /// Program operations (one per CPU write of the PSIZE width).
    pub programs: u64,
    /// CPU cycles the core waited on a busy flash (RM0390: no read-while-write).
    pub stalled_cycles: u64,
    /// First address the model serves: the sectors from here on are programmable.
    pub model_from: u32,
}

/// The end (offset from the flash base) of the sectors that hold the image: from the
/// first flash segment, the sectors its segments reach without a gap of 16 KiB (the
/// smallest sector) between them. Segments after a gap (data an image places in a sector
/// of its own, e.g. a factory file store) lie in the sectors the FLASH model serves.
fn image_sectors_end(segs: &[Segment]) -> u32 {
    let mut spans: Vec<(u32, u32)> = segs
        .iter()
        .filter(|s| (FLASH.0..FLASH.0 + FLASH.1).contains(&u64::from(s.addr)))
        .map(|s| {
            let o = (u64::from(s.addr) - FLASH.0) as u32;
            (o, o + s.data.len() as u32)
        })
        .collect();
    spans.sort_unstable();
    let sector_end = |off: u32| {
        flash::sector_of(off).map_or(FLASH.1 as u32, |k| {
            flash::SECTORS[k].0 + flash::SECTORS[k].1
        })
    };
    let mut end = 0u32;
    for (a, b) in spans {
        if end > 0 && a.saturating_sub(end) >= 16 << 10 {
            break;
        }
        end = end.max(b);
    }
    if end == 0 {
        FLASH.1 as u32
    } else {
        sector_end(end - 1)
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

/// A name for the engine's CPU exception numbers (QEMU's `EXCP_*`).
fn intr_name(n: u32) -> &'static str {
    match n {
        1 => "undefined instruction",
        2 => "SVC",
        3 => "prefetch abort",
        4 => "data abort",
        7 => "BKPT",
        9 => "exception exit",
        17 => "no coprocessor (NOCP)",
        18 => "invalid state (INVSTATE)",
        _ => "CPU exception",
    }
}

/// An STM32F446 running a board image, with an ESC chip (a LAN9252 or an ET1100 model) on
/// SPI1.
pub struct Board {
    uc: Unicorn<'static, ()>,
    periph: Rc<RefCell<Periph>>,
    pc: u32,
    /// Asleep in WFI/WFE (or SLEEPONEXIT).
    sleeping: bool,
    /// The event register WFE consumes (set by exception entry and return).
    event: bool,
    /// CONTROL.FPCA as last seen (the CPACR check looks for it rising).
    fpca: bool,
    /// Flash and static RAM of the image.
    size: ImageSize,
    /// The painted stack region: initial SP and the painting's lowest address.
    stack: StackStats,
    /// The image's functions by start address (start, size, name).
    functions: Vec<(u32, u32, String)>,
}

impl Board {
    /// Loads the ELF `image` into flash/SRAM and resets the CPU (SP and PC from the vector
    /// table at the start of flash). `chip` is the ESC chip on SPI1 (a
    /// `Handle<Lan9252Model>` or `Handle<Et1100Model>`).
    pub fn new(image: &[u8], chip: impl Into<EscChip>) -> Result<Self, EmuError> {
        let chip: EscChip = chip.into();
        let segs = elf_segments(image)?;
        let fault = |e: unicorn_engine::unicorn_const::uc_error| EmuError::Fault {
            pc: 0,
            reason: format!("engine set-up: {e:?}"),
        };
        let mut uc = Unicorn::new(Arch::ARM, Mode::THUMB).map_err(fault)?;
        uc.ctl_set_cpu_model(ArmCpuModel::CORTEX_M4 as i32)
            .map_err(fault)?;
        // The image's sectors are the engine's memory; the sectors after them are served
        // by the FLASH model (reads, programming, erase).
        let model_from = image_sectors_end(&segs);
        uc.mem_map(FLASH.0, u64::from(model_from), Prot::READ | Prot::EXEC)
            .map_err(fault)?;
        uc.mem_map(SRAM.0, SRAM.1, Prot::ALL).map_err(fault)?;
        let mut fl = flash::Flash::new(model_from, CPU_HZ);
        for s in &segs {
            let a = u64::from(s.addr);
            if a >= FLASH.0 + u64::from(model_from) && a < FLASH.0 + FLASH.1 {
                let o = (a - FLASH.0) as usize;
                fl.mem[o..o + s.data.len()].copy_from_slice(&s.data);
            } else {
                uc.mem_write(a, &s.data).map_err(fault)?;
            }
        }
        let mut p = Periph::new(chip);
        p.flash = fl;
        let periph = Rc::new(RefCell::new(p));
        if u64::from(model_from) < FLASH.1 {
            let (r, w) = (periph.clone(), periph.clone());
            let base = FLASH.0 + u64::from(model_from);
            uc.mmio_map(
                base,
                FLASH.1 - u64::from(model_from),
                Some(move |_: &mut Unicorn<'_, ()>, off: u64, size: usize| {
                    r.borrow_mut().flash_load(base + off, size)
                }),
                Some(
                    move |_: &mut Unicorn<'_, ()>, off: u64, size: usize, v: u64| {
                        w.borrow_mut().flash_store(base + off, size, v);
                    },
                ),
            )
            .map_err(fault)?;
        }
        // A write to the image's own sectors: not modelled, the image stops naming it.
        let c = periph.clone();
        uc.add_mem_hook(
            HookType::MEM_WRITE_PROT,
            FLASH.0,
            FLASH.0 + u64::from(model_from) - 1,
            move |_: &mut Unicorn<'_, ()>, _t: MemType, addr: u64, size: usize, _v: i64| {
                let sector = flash::sector_of((addr - FLASH.0) as u32).unwrap_or(0);
                c.borrow_mut().fault.get_or_insert(format!(
                    "a {size}-byte write to flash at {addr:#010x} (sector {sector}, which holds \
                     the image): the FLASH model programs only the sectors after the image"
                ));
                false
            },
        )
        .map_err(fault)?;
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
                move |uc: &mut Unicorn<'_, ()>, off: u64, size: usize, v: u64| {
                    let a = PERIPH.0 + off;
                    let mut p = w.borrow_mut();
                    let old = p.merge_base(a & !3);
                    p.write(a & !3, merge_sized(old, a, size, v));
                    dma_fetch(uc, &mut p);
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
                move |uc: &mut Unicorn<'_, ()>, off: u64, _size: usize, v: u64| {
                    let (a, bit) = target(off);
                    let mut p = w.borrow_mut();
                    let old = p.read(a);
                    p.write(a, (old & !(1 << bit)) | (u32::from(v & 1 != 0) << bit));
                    dma_fetch(uc, &mut p);
                },
            ),
        )
        .map_err(fault)?;
        for (base, size) in [SCS, DWT] {
            let (r, w) = (periph.clone(), periph.clone());
            uc.mmio_map(
                base,
                size,
                Some(move |_: &mut Unicorn<'_, ()>, off: u64, size: usize| {
                    let a = base + off;
                    let word = r.borrow_mut().scs_read(a & !3);
                    read_sized(word, a, size)
                }),
                Some(
                    move |_: &mut Unicorn<'_, ()>, off: u64, size: usize, v: u64| {
                        let a = base + off;
                        let mut p = w.borrow_mut();
                        let old = p.scs_merge_base(a & !3);
                        p.scs_write(a & !3, merge_sized(old, a, size, v));
                    },
                ),
            )
            .map_err(fault)?;
        }
        let (r, w) = (periph.clone(), periph.clone());
        uc.mmio_map(
            DBGMCU.0,
            DBGMCU.1,
            Some(move |_: &mut Unicorn<'_, ()>, off: u64, size: usize| {
                let word = match off & !3 {
                    0 => 0x1000_6421, // IDCODE: rev Z, DEV_ID 0x421 (STM32F446)
                    o => r
                        .borrow()
                        .dbgmcu
                        .get((o / 4) as usize)
                        .copied()
                        .unwrap_or(0),
                };
                read_sized(word, DBGMCU.0 + off, size)
            }),
            Some(
                move |_: &mut Unicorn<'_, ()>, off: u64, size: usize, v: u64| {
                    let mut p = w.borrow_mut();
                    if let Some(reg) = p.dbgmcu.get_mut((off / 4) as usize) {
                        *reg = merge_sized(*reg, DBGMCU.0 + off, size, v);
                    }
                },
            ),
        )
        .map_err(fault)?;
        // Cycles: one per instruction, counted per translated block as it starts
        // (Thumb-2 instructions are 2 or 4 bytes: the block's bytes / 3 on average). The
        // engine stops before the block where the board has work: a timer or SysTick event
        // due, the end of the run, a register write that may pend an interrupt, or a
        // change of PRIMASK/BASEPRI/FAULTMASK while an exception waits on them.
        let c = periph.clone();
        uc.add_block_hook(
            1,
            0,
            move |uc: &mut Unicorn<'_, ()>, addr: u64, size: u32| {
                let stop = {
                    let mut p = c.borrow_mut();
                    // A fetch from flash while it erases or programs waits for the end.
                    if (FLASH.0..FLASH.0 + FLASH.1).contains(&addr) {
                        p.flash_stall();
                    }
                    // The hook runs before the block: a stop here leaves it unexecuted.
                    let stop = p.cycles >= p.wake_at
                        || p.watch.is_some_and(|m| {
                            let now = Masks {
                                primask: uc.reg_read(RegisterARM::PRIMASK).unwrap_or(0) as u32,
                                basepri: uc.reg_read(RegisterARM::BASEPRI).unwrap_or(0) as u32,
                                faultmask: uc.reg_read(RegisterARM::FAULTMASK).unwrap_or(0) as u32,
                            };
                            now != m
                        });
                    if stop {
                        p.stopped = true;
                    } else {
                        let n = u64::from(size.div_ceil(3));
                        p.cycles += n;
                        p.insns += n;
                    }
                    stop
                };
                if stop {
                    let _ = uc.emu_stop();
                }
            },
        )
        .map_err(fault)?;
        // CPU exceptions (SVC, the fetch that is an exception return, BKPT …) stop the
        // engine; the board handles them.
        let c = periph.clone();
        uc.add_intr_hook(move |uc: &mut Unicorn<'_, ()>, intno: u32| {
            c.borrow_mut().intr = Some(intno);
            let _ = uc.emu_stop();
        })
        .map_err(fault)?;
        // WFE and YIELD reach the engine's "invalid instruction" path: WFE becomes a sleep,
        // YIELD a no-op; anything else stays an undefined-instruction fault.
        let c = periph.clone();
        uc.add_insn_invalid_hook(move |uc: &mut Unicorn<'_, ()>| {
            let pc = uc.reg_read(RegisterARM::PC).unwrap_or(0);
            let mut b = [0u8; 4];
            let half = |b: &[u8]| u16::from_le_bytes([b[0], b[1]]);
            let hint = if uc.mem_read(pc.wrapping_sub(2), &mut b[..2]).is_ok()
                && matches!(half(&b), 0xBF10 | 0xBF20)
            {
                Some(half(&b) == 0xBF20)
            } else if uc.mem_read(pc.wrapping_sub(4), &mut b).is_ok()
                && half(&b) == 0xF3AF
                && matches!(half(&b[2..]), 0x8001 | 0x8002)
            {
                Some(half(&b[2..]) == 0x8002)
            } else {
                None
            };
            match hint {
                Some(wfe) => {
                    c.borrow_mut().wait_event = Some(wfe);
                    let _ = uc.emu_stop();
                    true
                }
                None => false,
            }
        })
        .map_err(fault)?;
        // The thread's masked spans: a hook on each MSR PRIMASK/BASEPRI/BASEPRI_MAX/
        // FAULTMASK and CPSID/CPSIE of the image (only those instructions call back), which
        // works out the masks the instruction leaves and hands them to the tracker.
        const RN: [RegisterARM; 15] = [
            RegisterARM::R0,
            RegisterARM::R1,
            RegisterARM::R2,
            RegisterARM::R3,
            RegisterARM::R4,
            RegisterARM::R5,
            RegisterARM::R6,
            RegisterARM::R7,
            RegisterARM::R8,
            RegisterARM::R9,
            RegisterARM::R10,
            RegisterARM::R11,
            RegisterARM::R12,
            RegisterARM::SP,
            RegisterARM::LR,
        ];
        for (at, op) in mask_sites(&segs) {
            let c = periph.clone();
            uc.add_code_hook(
                u64::from(at),
                u64::from(at),
                move |uc: &mut Unicorn<'_, ()>, addr: u64, _size: u32| {
                    let mut p = c.borrow_mut();
                    if p.scs.ipsr != 0 {
                        return; // a handler's masks: not the thread's span
                    }
                    let r = |reg: RegisterARM| uc.reg_read(reg).unwrap_or(0) as u32;
                    let (mut pm, mut bp, mut fm) = (
                        r(RegisterARM::PRIMASK),
                        r(RegisterARM::BASEPRI),
                        r(RegisterARM::FAULTMASK),
                    );
                    match op {
                        MaskOp::Cps { disable, i, f } => {
                            if i {
                                pm = u32::from(disable);
                            }
                            if f {
                                fm = u32::from(disable);
                            }
                        }
                        MaskOp::Msr { rn, sysm } => {
                            let v = RN.get(usize::from(rn)).map_or(0, |&reg| r(reg));
                            match sysm {
                                0x10 => pm = v & 1,
                                0x11 => bp = v & 0xFF,
                                0x12 if v & 0xFF != 0 && (bp == 0 || v & 0xFF < bp) => {
                                    bp = v & 0xFF
                                }
                                0x13 => fm = v & 1,
                                _ => {}
                            }
                        }
                    }
                    let now = p.cycles;
                    p.masks
                        .set(stats::MaskTracker::level_of(pm, bp, fm), now, addr as u32);
                },
            )
            .map_err(fault)?;
        }
        let mut vt = [0u8; 8];
        uc.mem_read(FLASH.0, &mut vt).map_err(fault)?;
        let sp = u32::from_le_bytes([vt[0], vt[1], vt[2], vt[3]]);
        let pc = u32::from_le_bytes([vt[4], vt[5], vt[6], vt[7]]);
        uc.reg_write(RegisterARM::SP, u64::from(sp))
            .map_err(fault)?;
        let size = stats::image_size(image)?;
        // Only an image that declares its static RAM (`.data`/`.bss` segments) is painted:
        // a bare program may use SRAM it never declared, expecting it as it finds it.
        let bottom = if size.ram > 0 {
            size.ram_end.next_multiple_of(4)
        } else {
            sp
        };
        let mut board = Board {
            uc,
            periph,
            pc,
            sleeping: false,
            event: false,
            fpca: false,
            size,
            stack: StackStats {
                top: sp,
                bottom,
                max_depth: 0,
            },
            functions: elf_functions(image)?,
        };
        board.paint(bottom, sp);
        Ok(board)
    }

    /// Fills `[from, to)` of SRAM with the stack paint pattern (clamped to SRAM).
    fn paint(&mut self, from: u32, to: u32) {
        let lo = u64::from(from).max(SRAM.0);
        let hi = u64::from(to).min(SRAM.0 + SRAM.1) & !3;
        if hi > lo {
            let bytes: Vec<u8> =
                std::iter::repeat_n(stats::PAINT.to_le_bytes(), ((hi - lo) / 4) as usize)
                    .flatten()
                    .collect();
            let _ = self.uc.mem_write(lo, &bytes);
        }
    }

    /// Flash and static RAM of the image (from its ELF program headers).
    pub fn image_size(&self) -> ImageSize {
        self.size
    }

    /// The stack's high-water mark since reset (or since [`Board::repaint_stack`]): the
    /// region from the end of the static RAM to the initial SP is painted with a pattern
    /// at reset, and the lowest word that no longer holds it is the deepest the stack
    /// reached (a frame that skips words it never writes can hide a little of its depth).
    pub fn stack_stats(&self) -> StackStats {
        let (lo, hi) = (self.stack.bottom, self.stack.top);
        let mut s = self.stack;
        if hi <= lo || u64::from(lo) < SRAM.0 || u64::from(hi) > SRAM.0 + SRAM.1 {
            return s;
        }
        let mut buf = vec![0u8; (hi - lo) as usize & !3];
        if self.uc.mem_read(u64::from(lo), &mut buf).is_err() {
            return s;
        }
        let first = buf
            .chunks_exact(4)
            .position(|w| w != stats::PAINT.to_le_bytes());
        s.max_depth = first.map_or(0, |k| hi - (lo + 4 * k as u32));
        s
    }

    /// Paints the stack region below the current SP again, so [`Board::stack_stats`] then
    /// measures from now (e.g. the steady state after the start-up code's deeper frames).
    pub fn repaint_stack(&mut self) {
        let sp = self.uc.reg_read(RegisterARM::SP).unwrap_or(0) as u32;
        let (lo, hi) = (self.stack.bottom, sp.min(self.stack.top));
        self.paint(lo, hi);
    }

    /// The handler times of exception `number` (IPSR numbering: 15 SysTick, 16 + n IRQ n)
    /// since reset or [`Board::reset_handler_stats`].
    pub fn handler_stats(&self, number: u16) -> HandlerStats {
        self.periph.borrow().profile.get(number)
    }

    /// Clears the handler times (a handler running now counts from now) and ADC1's
    /// interrupt latency.
    pub fn reset_handler_stats(&mut self) {
        let mut p = self.periph.borrow_mut();
        let now = p.cycles;
        p.profile.reset(now);
        p.adc.max_latency = 0;
    }

    /// Schedules `s` at the board's time `at_ns` (applied when the CPU's clock reaches it,
    /// at once if it is past); stimuli at equal times apply in the order scheduled.
    pub fn schedule(&mut self, at_ns: u64, s: Stimulus) {
        let at = (u128::from(at_ns) * u128::from(CPU_HZ)).div_ceil(1_000_000_000);
        self.periph
            .borrow_mut()
            .schedule(u64::try_from(at).unwrap_or(u64::MAX), s);
    }

    /// Stimuli scheduled and not applied yet.
    pub fn scheduled(&self) -> usize {
        self.periph.borrow().stimuli.len()
    }

    /// The lowest address the main stack may reach: the end of the image's static RAM
    /// when the stack starts above it (cortex-m-rt's default layout), else the start of
    /// SRAM (a bare program that declares no statics, or a stack placed below them, as
    /// flip-link does).
    pub fn stack_limit(&self) -> u32 {
        if self.size.ram > 0 && self.stack.top > self.stack.bottom {
            self.stack.bottom
        } else {
            SRAM.0 as u32
        }
    }

    /// A main stack below its limit is a stack overflow: reported as a fault with the PC
    /// (checked whenever the engine stops, and when it stops on an error, which a push below
    /// SRAM is). On silicon without an MPU guard or flip-link the overflow would silently
    /// overwrite the statics; here the image stops and says so.
    fn check_stack(&self) -> Result<(), EmuError> {
        let control = self.uc.reg_read(RegisterARM::CONTROL).unwrap_or(0);
        if control & 2 != 0 {
            return Ok(()); // the thread runs on the process stack: not the main stack's limit
        }
        let sp = self.uc.reg_read(RegisterARM::SP).unwrap_or(u64::MAX);
        let limit = u64::from(self.stack_limit());
        if sp < limit {
            return Err(self.fault(format!(
                "stack overflow: SP {sp:#010x} is below the main stack's limit {limit:#010x} \
                 ({})",
                if limit > SRAM.0 {
                    "the end of .data/.bss, which it would overwrite"
                } else {
                    "the start of SRAM"
                }
            )));
        }
        Ok(())
    }

    /// The reason for an error of the engine: a failed access by an instruction with the
    /// main stack within a frame (a push of every register with the FP context: 128 bytes)
    /// of its limit is the stack overflowing (the faulting push did not move SP).
    fn engine_error(&self, e: unicorn_engine::unicorn_const::uc_error) -> String {
        let control = self.uc.reg_read(RegisterARM::CONTROL).unwrap_or(0);
        let sp = self.uc.reg_read(RegisterARM::SP).unwrap_or(u64::MAX);
        let limit = u64::from(self.stack_limit());
        let access = matches!(
            e,
            unicorn_engine::unicorn_const::uc_error::WRITE_UNMAPPED
                | unicorn_engine::unicorn_const::uc_error::WRITE_PROT
        );
        if access && control & 2 == 0 && sp < limit + 128 {
            format!(
                "stack overflow: a push below the main stack's limit {limit:#010x} (SP \
                 {sp:#010x}): {e:?}"
            )
        } else {
            format!("{e:?}")
        }
    }

    fn fault(&self, reason: impl Into<String>) -> EmuError {
        EmuError::Fault {
            pc: self.pc,
            reason: reason.into(),
        }
    }

    /// Runs the board for `n` CPU cycles (about `n` instructions; less while it sleeps),
    /// to the block boundary at or after them. A fault is an error with the PC.
    pub fn run(&mut self, n: usize) -> Result<(), EmuError> {
        let end = self.cycles() + n as u64;
        self.run_to(end)
    }

    /// Runs the board until its clock reaches `t_ns` (see [`Board::run`]).
    pub fn run_to_ns(&mut self, t_ns: u64) -> Result<(), EmuError> {
        let end = (u128::from(t_ns) * u128::from(CPU_HZ)).div_ceil(1_000_000_000);
        self.run_to(u64::try_from(end).unwrap_or(u64::MAX))
    }

    /// Runs until the cycle count reaches `end`: peripherals brought up to date, pending
    /// exceptions taken and sleep skipped between engine runs.
    fn run_to(&mut self, end: u64) -> Result<(), EmuError> {
        loop {
            self.service()?;
            let now = self.cycles();
            if now >= end {
                return Ok(());
            }
            if self.sleeping {
                let mut p = self.periph.borrow_mut();
                let next = p.next_event().unwrap_or(end).min(end).max(now + 1);
                p.slept += next - now;
                p.cycles = next;
                continue;
            }
            {
                let mut p = self.periph.borrow_mut();
                // At least one block runs: every event up to now has been handled.
                p.wake_at = p.next_event().unwrap_or(u64::MAX).min(end).max(now + 1);
                p.stopped = false;
                p.intr = None;
                p.wait_event = None;
            }
            let r = self.uc.emu_start(u64::from(self.pc | 1), u64::MAX, 0, 0);
            self.pc = self.uc.reg_read(RegisterARM::PC).unwrap_or(0) as u32;
            if let Err(e) = r {
                self.check_stack()?;
                if let Some(f) = self.periph.borrow_mut().fault.take() {
                    return Err(self.fault(f));
                }
                return Err(self.fault(self.engine_error(e)));
            }
            self.check_stack()?;
            self.check_fpu()?;
            let (intr, stopped, wait) = {
                let p = self.periph.borrow();
                (p.intr, p.stopped, p.wait_event)
            };
            match (intr, wait) {
                (Some(n), _) => self.on_intr(n)?,
                (None, Some(true)) if self.event => self.event = false,
                (None, Some(true)) => self.sleeping = true,
                (None, Some(false)) => {}
                // Stopped by neither the board nor an exception: WFI halted the engine.
                (None, None) if !stopped => self.sleeping = true,
                (None, None) => {}
            }
        }
    }

    /// Brings the peripherals up to now, pends what their interrupt lines raise, wakes
    /// the core if an exception would, and takes the exception that preempts, if any.
    fn service(&mut self) -> Result<(), EmuError> {
        let masks = self.masks()?;
        let take = {
            let mut p = self.periph.borrow_mut();
            p.apply_due();
            if p.scs.reset_requested {
                drop(p);
                return Err(self.fault("SYSRESETREQ: the image requested a system reset"));
            }
            p.sync_all();
            if let Some(e) = p.fault.take() {
                drop(p);
                return Err(self.fault(e));
            }
            if p.iwdg.expires().is_some_and(|t| t <= p.cycles) {
                // The IWDG ran out: a system reset of the MCU, the board's clock running on.
                p.watchdog_reset();
                // The reset clears PRIMASK/BASEPRI/FAULTMASK: a span the thread had open ends.
                let now = p.cycles;
                p.masks.set(stats::LEVELS, now, 0);
                drop(p);
                self.sleeping = false;
                self.event = false;
                self.fpca = false;
                return self.reset_core();
            }
            p.sample_pins();
            let lines = p.irq_lines();
            p.scs.assert_lines(lines);
            if self.sleeping && p.scs.wakes(masks) {
                self.sleeping = false;
            }
            let take = if self.sleeping {
                None
            } else {
                p.scs.takeable(masks)
            };
            // Blocked only by the masks: watch them from the block hook.
            p.watch =
                (take.is_none() && p.scs.takeable(Masks::default()).is_some()).then_some(masks);
            take
        };
        if let Some(e) = take {
            self.enter(e)?;
        }
        Ok(())
    }

    /// A CPU exception the engine raised.
    fn on_intr(&mut self, n: u32) -> Result<(), EmuError> {
        match n {
            2 => {
                // SVC is synchronous: SVCall must be able to preempt, else it escalates
                // to HardFault.
                let masks = self.masks()?;
                let mut p = self.periph.borrow_mut();
                let svc = p.scs.group(p.scs.priority(SVCALL));
                if svc >= p.scs.execution_priority(masks) {
                    drop(p);
                    return Err(
                        self.fault("SVC where SVCall cannot preempt (HardFault escalation)")
                    );
                }
                p.scs.pending |= nvic::bit(SVCALL);
                Ok(())
            }
            3 if self.pc >= 0xFFFF_FFE0 => self.exception_return(self.pc),
            n => Err(self.fault(format!("{} (engine exception {n})", intr_name(n)))),
        }
    }

    /// A floating-point instruction with CP10/CP11 off in CPACR is a UsageFault (NOCP)
    /// on the Cortex-M4; the engine runs it anyway but marks the FP context active.
    fn check_fpu(&mut self) -> Result<(), EmuError> {
        let control = self.uc.reg_read(RegisterARM::CONTROL).unwrap_or(0);
        let fpca = control & 4 != 0;
        if fpca && !self.fpca && !self.periph.borrow().scs.fpu_enabled() {
            return Err(self.fault(
                "UsageFault (NOCP): a floating-point instruction ran with CPACR.CP10/CP11 off",
            ));
        }
        self.fpca = fpca;
        Ok(())
    }

    /// Runs slices of `slice` cycles until `done` holds or `max` cycles ran; whether
    /// `done` held.
    pub fn run_until(
        &mut self,
        slice: usize,
        max: u64,
        mut done: impl FnMut(&mut Self) -> bool,
    ) -> Result<bool, EmuError> {
        let start = self.cycles();
        while self.cycles() - start < max {
            self.run(slice)?;
            if done(self) {
                return Ok(true);
            }
        }
        Ok(false)
    }

    /// System resets the independent watchdog caused so far ([`iwdg`]).
    pub fn watchdog_resets(&self) -> u64 {
        self.periph.borrow().watchdog_resets
    }

    /// The board's time of the last IWDG reset \[ns\].
    pub fn last_watchdog_reset_ns(&self) -> Option<u64> {
        let c = self.periph.borrow().last_watchdog_reset?;
        Some((u128::from(c) * 1_000_000_000 / u128::from(CPU_HZ)) as u64)
    }

    /// The LSI frequency that clocks the IWDG \[Hz\] ([`iwdg::LSI_HZ`] unless set).
    pub fn lsi_hz(&self) -> u32 {
        self.periph.borrow().iwdg.lsi_hz
    }

    /// Sets the LSI frequency \[Hz\] from now on (17–47 kHz on silicon; 32 kHz nominal,
    /// the default): the IWDG's count so far stays, the rest runs at the new rate.
    pub fn set_lsi_hz(&mut self, hz: u32) {
        let mut p = self.periph.borrow_mut();
        let now = p.cycles;
        p.iwdg.set_lsi_hz(hz, now);
        p.wake_at = 0;
    }

    /// Instructions executed so far (counted per translated block, like the cycles).
    pub fn instructions(&self) -> u64 {
        self.periph.borrow().insns
    }

    /// CPU cycles so far (instructions plus SPI wait, exception entry/return and sleep),
    /// the image's time base.
    pub fn cycles(&self) -> u64 {
        self.periph.borrow().cycles
    }

    /// Cycles the core spent asleep (WFI/WFE).
    pub fn slept_cycles(&self) -> u64 {
        self.periph.borrow().slept
    }

    /// Cycles of SysTick delay loops skipped forward instead of emulated (idle polling).
    pub fn polled_cycles(&self) -> u64 {
        self.periph.borrow().polled
    }

    /// Simulated time in ns at [`CPU_HZ`].
    pub fn time_ns(&self) -> u64 {
        (u128::from(self.cycles()) * 1_000_000_000 / u128::from(CPU_HZ)) as u64
    }

    /// The program counter where the last run stopped.
    pub fn pc(&self) -> u32 {
        self.pc
    }

    /// SPI traffic so far.
    pub fn spi_stats(&self) -> SpiStats {
        self.periph.borrow().spi
    }

    /// SCLK of SPI1 \[Hz\]: as the image configured it, PCLK2 (90 MHz) / 2^(BR+1), unless
    /// [`Board::set_spi_sclk_hz`] replaced it.
    pub fn spi_sclk_hz(&self) -> u32 {
        let p = self.periph.borrow();
        if let Some(hz) = p.spi_sclk_override {
            return hz;
        }
        let br = (p.reg(periph::SPI1) >> 3) & 7;
        90_000_000 / (2 << br)
    }

    /// A what-if study: SPI1's bytes take 8 periods of `hz` instead of the clock the image
    /// sets (`None`: the image's again) — e.g. an ET1100 at 20 MHz, which SPI1's prescalers
    /// from a 90 MHz PCLK2 cannot give (11.25 or 22.5 MHz).
    pub fn set_spi_sclk_hz(&mut self, hz: Option<u32>) {
        self.periph.borrow_mut().spi_sclk_override = hz.filter(|&h| h > 0);
    }

    /// Reads image memory (flash or SRAM) at `addr`, the flash sectors after the image
    /// from the FLASH model's cells (no stall, no access counted).
    pub fn read_memory(&self, addr: u32, buf: &mut [u8]) -> Result<(), EmuError> {
        let a = u64::from(addr);
        let p = self.periph.borrow();
        let from = FLASH.0 + u64::from(p.flash.model_from);
        if a >= from && a + buf.len() as u64 <= FLASH.0 + FLASH.1 {
            let o = (a - FLASH.0) as usize;
            buf.copy_from_slice(&p.flash.mem[o..o + buf.len()]);
            return Ok(());
        }
        drop(p);
        self.uc
            .mem_read(u64::from(addr), buf)
            .map_err(|e| self.fault(format!("read of {addr:#010x}: {e:?}")))
    }

    /// What the FLASH model did so far: sector erases, program operations, cycles the
    /// core waited on a busy flash; and the first flash address it serves (the sectors
    /// after the image).
    pub fn flash_stats(&self) -> FlashStats {
        let p = self.periph.borrow();
        FlashStats {
            erases: p.flash.erases,
            programs: p.flash.programs,
            stalled_cycles: p.flash.stalled,
            model_from: (FLASH.0 + u64::from(p.flash.model_from)) as u32,
        }
    }

    fn port(port: char) -> Option<u8> {
        let p = (port.to_ascii_uppercase() as u32).checked_sub('A' as u32)?;
        (u64::from(p) < PORTS).then_some(p as u8)
    }

    /// An output pin's level (`port` 'A'..='H'; false for another letter).
    pub fn output(&self, port: char, pin: u8) -> bool {
        let Some(p) = Self::port(port) else {
            return false;
        };
        let base = GPIOA + 0x400 * u64::from(p);
        self.periph.borrow().reg(base + 0x14) & (1 << (pin & 15)) != 0
    }

    /// Drives input pin `pin` of `port` ('A'..='H') to `level` (a plant's sensor, a
    /// button); EXTI sees the edge at the next run. The ESC chip's pins (PA10, PB3, PB5, and
    /// an ET1100's PB4) stay the chip's.
    pub fn set_input(&mut self, port: char, pin: u8, level: bool) {
        let Some(p) = Self::port(port) else {
            return;
        };
        let mut per = self.periph.borrow_mut();
        let (mask, levels) = &mut per.inputs[usize::from(p)];
        let b = 1u16 << (pin & 15);
        *mask |= b;
        *levels = if level { *levels | b } else { *levels & !b };
    }

    /// Drives ADC input channel `channel` (IN0..IN18; IN10 = PC0) to `volts` (a plant's
    /// sensor); ADC1 samples it at its next trigger. A channel nothing drives cannot be
    /// converted: the image stops with a fault naming it.
    pub fn set_analog(&mut self, channel: u8, volts: f64) {
        if let Some(a) = self
            .periph
            .borrow_mut()
            .analog
            .get_mut(usize::from(channel))
        {
            *a = Some(volts);
        }
    }

    /// Injected sequences ADC1 has started so far.
    pub fn adc_sequences(&self) -> u64 {
        self.periph.borrow().adc.sequences
    }

    /// The longest time from ADC1's JEOC to the entry of its interrupt handler since reset
    /// or [`Board::reset_handler_stats`] \[cycles\]: what masks (PRIMASK critical sections) and handlers of equal or higher
    /// priority held the conversion-complete interrupt back (entry cycles included).
    pub fn adc_irq_latency_max(&self) -> u64 {
        self.periph.borrow().adc.max_latency
    }

    /// The longest time since reset that thread mode held exceptions of priority
    /// `priority` back (PRIMASK, FAULTMASK, or BASEPRI at that priority or more urgent),
    /// with where it began; a span still open counts up to now. The handlers that preempted
    /// the thread meanwhile count in it: for that long an exception of `priority` could not
    /// be taken. Kept from boot on ([`Board::reset_handler_stats`] leaves it): start-up is
    /// where the long spans are.
    pub fn masked_span(&self, priority: u8) -> MaskedSpan {
        let p = self.periph.borrow();
        p.masks.longest(priority, p.cycles)
    }

    /// The image's function that holds address `pc` (its symbol, demangled), if the ELF
    /// has symbols.
    pub fn function_at(&self, pc: u32) -> Option<&str> {
        let pc = pc & !1;
        let k = self
            .functions
            .partition_point(|f| f.0 <= pc)
            .checked_sub(1)?;
        let (start, size, name) = &self.functions[k];
        (pc < start + size).then_some(name.as_str())
    }

    /// EXTI edges lost since reset (a selected edge on a line whose pending bit was still
    /// set): the first 64 with their cycle.
    pub fn lost_edges(&self) -> Vec<LostEdge> {
        self.periph.borrow().exti.lost.clone()
    }

    /// How many edges EXTI line `line` (0..=15) lost since reset.
    pub fn lost_edge_count(&self, line: u8) -> u64 {
        self.periph
            .borrow()
            .exti
            .lost_count
            .get(usize::from(line))
            .copied()
            .unwrap_or(0)
    }

    /// The duty (0..=1) of timer `tim`'s channel `ch` (TIM1 = 1, CH1 = 1) as a PWM output:
    /// CCRx / (ARR + 1) in PWM mode 1, inverted in PWM mode 2 and for an active-low
    /// channel; `None` unless the channel is an enabled PWM output on a running timer
    /// (with MOE on TIM1/TIM8).
    pub fn pwm_duty(&self, tim: u8, ch: u8) -> Option<f64> {
        self.periph.borrow_mut().timer(tim)?.pwm_duty(ch)
    }

    /// The shaft on timer `tim`'s encoder inputs is at `edges` quadrature edges (four per
    /// line): in encoder mode (SMCR.SMS = 1/2/3, CEN set) CNT follows, wrapping within
    /// ARR with an update event per wrap. Outside encoder mode only the position is kept.
    pub fn set_encoder(&mut self, tim: u8, edges: i64) {
        let mut p = self.periph.borrow_mut();
        let now = p.cycles;
        if let Some(t) = p.timer(tim) {
            t.sync(now);
            t.set_encoder(edges);
        }
    }

    /// An active edge on timer `tim`'s input TI`input` (1..=4) now: every channel in
    /// input-capture mode mapped to it latches CNT into CCRx and sets CCxIF (CCxOF if it
    /// was set). Returns how many channels captured.
    pub fn capture(&mut self, tim: u8, input: u8) -> usize {
        self.periph.borrow_mut().capture(tim, input)
    }

    /// The counter of timer `tim` now.
    pub fn timer_count(&self, tim: u8) -> Option<u32> {
        let mut p = self.periph.borrow_mut();
        let now = p.cycles;
        p.timer(tim).map(|t| t.read(0x24, now))
    }

    /// Interrupt handlers entered so far, by IRQ number (index 0..97).
    pub fn interrupts_taken(&self) -> Vec<u64> {
        self.periph.borrow().scs.taken[16..].to_vec()
    }

    /// Times exception `number` (IPSR numbering: 11 SVCall, 14 PendSV, 15 SysTick, 16 + n
    /// IRQ n) was entered.
    pub fn exceptions_taken(&self, number: u16) -> u64 {
        self.periph
            .borrow()
            .scs
            .taken
            .get(usize::from(number))
            .copied()
            .unwrap_or(0)
    }

    /// The exception being handled (IPSR), 0 in thread mode.
    pub fn active_exception(&self) -> u16 {
        self.periph.borrow().scs.ipsr
    }

    /// Puts the 1-Wire bus `net` on U(S)ART `number`'s TX line (1..6; the image runs it
    /// half-duplex): the bytes it sends become resets and slots at their baud rate
    /// ([`usart`]). False if there is no such U(S)ART.
    pub fn attach_onewire(
        &mut self,
        number: u8,
        net: std::sync::Arc<std::sync::Mutex<oxicat_plant::onewire::OneWireNet>>,
    ) -> bool {
        let mut p = self.periph.borrow_mut();
        match p.usarts.iter_mut().find(|u| u.number == number) {
            Some(u) => {
                u.line = Some(net);
                true
            }
            None => false,
        }
    }

    /// The last finished DMA transfer into timer `tim`'s register at offset `reg` (0x34
    /// CCR1 … 0x40 CCR4): the items in the order the update events wrote them.
    pub fn dma_burst(&self, tim: u8, reg: u64) -> Option<dma::DmaBurst> {
        self.periph.borrow().dma_burst(tim, reg).cloned()
    }

    /// Timer `tim`'s counter clock \[Hz\] and ticks per period (ARR + 1).
    pub fn timer_period(&self, tim: u8) -> Option<(f64, u32)> {
        let mut p = self.periph.borrow_mut();
        p.timer(tim).map(|t| t.period())
    }

    /// What U(S)ART `number` did on its 1-Wire line, and the bytes it sent.
    pub fn onewire_stats(&self, number: u8) -> Option<(usart::OneWireStats, u64)> {
        let p = self.periph.borrow();
        p.usarts
            .iter()
            .find(|u| u.number == number)
            .map(|u| (u.ow, u.sent))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mask_instructions_are_decoded_and_rust_symbols_demangled() {
        let cps = |disable, i, f| Some(MaskOp::Cps { disable, i, f });
        assert_eq!(mask_op(0xB672, 0), cps(true, true, false), "cpsid i");
        assert_eq!(mask_op(0xB662, 0), cps(false, true, false), "cpsie i");
        assert_eq!(mask_op(0xB661, 0), cps(false, false, true), "cpsie f");
        let msr = |rn, sysm| Some(MaskOp::Msr { rn, sysm });
        assert_eq!(mask_op(0xF380, 0x8811), msr(0, 0x11), "msr BASEPRI, r0");
        assert_eq!(mask_op(0xF383, 0x8812), msr(3, 0x12), "msr BASEPRI_MAX, r3");
        assert_eq!(mask_op(0xF381, 0x8810), msr(1, 0x10), "msr PRIMASK, r1");
        assert_eq!(mask_op(0xF380, 0x8800), None, "msr APSR_nzcvq");
        assert_eq!(mask_op(0xF380, 0x8808), None, "msr MSP");
        assert_eq!(mask_op(0xBF30, 0), None, "wfi");
        assert_eq!(
            demangle("_ZN4core3fmt5write17h0123456789abcdefE"),
            "core::fmt::write"
        );
        assert_eq!(demangle("main"), "main");
        assert_eq!(demangle("_ZN3bad"), "_ZN3bad", "malformed: as it is");
    }

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
    fn the_image_keeps_the_sectors_its_segments_reach_and_data_after_a_gap_is_the_models() {
        let seg = |addr: u32, len: usize| Segment {
            addr,
            data: vec![0; len],
            mem_size: len as u32,
        };
        // Code into sector 4, .data's load image right after it, a store in sector 6.
        let segs = [
            seg(0x0800_0000, 0x1_0040),
            seg(0x0801_0040, 0x338),
            seg(0x2000_0000, 0x338),
            seg(0x0804_0000, 79),
        ];
        assert_eq!(image_sectors_end(&segs), 0x2_0000, "sectors 0..4");
        assert_eq!(image_sectors_end(&segs[..1]), 0x2_0000);
        assert_eq!(image_sectors_end(&[seg(0x0800_0000, 0x100)]), 0x4000);
        assert_eq!(
            image_sectors_end(&[seg(0x2000_0000, 4)]),
            FLASH.1 as u32,
            "none"
        );
    }

    #[test]
    fn sub_word_register_access_reads_and_merges_bytes() {
        assert_eq!(read_sized(0x1234_5678, 0x4000_0001, 1), 0x56);
        assert_eq!(read_sized(0x1234_5678, 0x4000_0002, 2), 0x1234);
        assert_eq!(merge_sized(0x1234_5678, 0x4000_0002, 1, 0xAB), 0x12AB_5678);
        assert_eq!(merge_sized(0x1234_5678, 0x4000_0000, 4, 0xAB), 0xAB);
    }
}
