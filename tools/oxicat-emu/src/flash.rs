//! The STM32F446's embedded flash and its interface (RM0390 §3, "Embedded Flash memory
//! interface"; times from the STM32F446xC/E datasheet DS10693, "Flash memory programming").
//!
//! - **Sectors** (RM0390 Table 4, 512 KiB): 0..3 16 KiB, 4 64 KiB, 5..7 128 KiB from
//!   0x0800_0000 ([`SECTORS`]).
//! - **Lock**: FLASH_CR starts locked (LOCK = 1); KEYR takes [`KEY1`] then [`KEY2`] to
//!   unlock it. Any other sequence (a wrong key, or a key while CR is unlocked) is a bus
//!   error and locks CR until the next reset (§3.5.1): the model returns it as an error,
//!   the board stops the image with it (faults are reported, not taken), and CR stays
//!   locked for the rest of the run. Writes to CR while it is locked are ignored; setting
//!   LOCK locks it again. OPTCR the same with OPTKEYR ([`OPTKEY1`], [`OPTKEY2`]) and
//!   OPTLOCK; its nWRP bits (one per sector, 0 = write-protected) apply as written.
//! - **Erase** (§3.6.3): CR.SER with SNB and STRT erases a sector (every byte 0xFF); BSY
//!   for the datasheet's typical sector erase time at the PSIZE parallelism
//!   ([`erase_ns`]: 16 KiB 400/300/250 ms, 64 KiB 1200/700/550 ms, 128 KiB 2/1.3/1 s at
//!   x8/x16/x32). A protected sector: WRPERR, nothing erased. MER (mass erase) and an SNB
//!   beyond sector 7 are not modelled (errors).
//! - **Program** (§3.6.4): with CR.PG set, a CPU write of the PSIZE width (byte x8,
//!   halfword x16, word x32) to a flash address programs it; programming only clears bits
//!   (the cell becomes old & new); BSY for [`PROGRAM_NS`] (16 µs typical). A write while
//!   PG is clear (CR locked included): PGSERR, nothing written; of another width than
//!   PSIZE (x64 needs VPP: every CPU write): PGPERR; not aligned to its width: PGAERR; to
//!   a protected sector: WRPERR.
//! - **SR**: EOP (only with EOPIE, §3.8.4), OPERR, WRPERR, PGAERR, PGPERR, PGSERR are
//!   write-1-to-clear; BSY reads 1 until the operation's end on the board's clock. STRT
//!   reads 1 while the erase runs.
//! - **Stall** (§3.5: no read-while-write on the single bank): while BSY, a read of the
//!   flash, a fetch from it, a write to it and a write of CR wait until the operation
//!   ends — the board's clock jumps to BSY's end at the access ([`Flash::stall_until`]);
//!   a program that runs from flash (every image) stops for the whole erase, its
//!   interrupts included.
//!
//! The sectors that hold the image (from 0x0800_0000 to the sector that ends the image's
//! flash segments) are the engine's memory, executable; the sectors after them are served
//! through this model ([`Flash::model_from`]). A write or erase of an image sector is
//! not modelled: the image stops with a fault naming the sector.

/// Flash base address.
pub const BASE: u64 = 0x0800_0000;
/// Flash size \[bytes\] (STM32F446xE).
pub const SIZE: usize = 512 * 1024;
/// The FLASH interface registers.
pub(crate) const REGS: u64 = 0x4002_3C00;

/// Sector start offsets and sizes (RM0390 Table 4).
pub const SECTORS: [(u32, u32); 8] = [
    (0x0_0000, 16 << 10),
    (0x0_4000, 16 << 10),
    (0x0_8000, 16 << 10),
    (0x0_C000, 16 << 10),
    (0x1_0000, 64 << 10),
    (0x2_0000, 128 << 10),
    (0x4_0000, 128 << 10),
    (0x6_0000, 128 << 10),
];

/// First key of the CR unlock sequence.
pub const KEY1: u32 = 0x4567_0123;
/// Second key of the CR unlock sequence.
pub const KEY2: u32 = 0xCDEF_89AB;
/// First key of the OPTCR unlock sequence.
pub const OPTKEY1: u32 = 0x0819_2A3B;
/// Second key of the OPTCR unlock sequence.
pub const OPTKEY2: u32 = 0x4C5D_6E7F;

/// Register offsets.
const ACR: u64 = 0x00;
const KEYR: u64 = 0x04;
const OPTKEYR: u64 = 0x08;
const SR: u64 = 0x0C;
const CR: u64 = 0x10;
const OPTCR: u64 = 0x14;

/// SR.EOP.
pub const EOP: u32 = 1;
/// SR.OPERR.
pub const OPERR: u32 = 1 << 1;
/// SR.WRPERR.
pub const WRPERR: u32 = 1 << 4;
/// SR.PGAERR.
pub const PGAERR: u32 = 1 << 5;
/// SR.PGPERR.
pub const PGPERR: u32 = 1 << 6;
/// SR.PGSERR.
pub const PGSERR: u32 = 1 << 7;
/// SR.BSY.
pub const BSY: u32 = 1 << 16;
/// SR's write-1-to-clear flags.
const SR_W1C: u32 = EOP | OPERR | WRPERR | PGAERR | PGPERR | PGSERR | (1 << 8);

/// CR.PG.
pub const PG: u32 = 1;
/// CR.SER.
pub const SER: u32 = 1 << 1;
/// CR.MER.
pub const MER: u32 = 1 << 2;
/// CR.STRT.
pub const STRT: u32 = 1 << 16;
/// CR.EOPIE.
pub const EOPIE: u32 = 1 << 24;
/// CR.LOCK.
pub const LOCK: u32 = 1 << 31;
/// CR's read/write bits (PG, SER, MER, SNB, PSIZE, EOPIE, ERRIE).
const CR_RW: u32 = PG | SER | MER | (0xF << 3) | (3 << 8) | EOPIE | (1 << 25);
/// OPTCR after reset with erased option bytes (RM0390 §3.8.6), OPTLOCK set.
const OPTCR_RESET: u32 = 0x0FFF_AAED;

/// Typical word programming time \[ns\] (DS10693: 16 µs).
pub const PROGRAM_NS: u64 = 16_000;

/// Typical erase time of a sector of `bytes` at parallelism `psize` (0 x8, 1 x16, 2/3
/// x32) \[ns\] (DS10693).
pub fn erase_ns(bytes: u32, psize: u32) -> u64 {
    let ms: u64 = match (bytes >> 10, psize.min(2)) {
        (16, 0) => 400,
        (16, 1) => 300,
        (16, _) => 250,
        (64, 0) => 1_200,
        (64, 1) => 700,
        (64, _) => 550,
        (_, 0) => 2_000,
        (_, 1) => 1_300,
        _ => 1_000,
    };
    ms * 1_000_000
}

/// The sector holding flash offset `off`.
pub fn sector_of(off: u32) -> Option<usize> {
    SECTORS.iter().position(|&(s, n)| off >= s && off < s + n)
}

/// The flash interface and the cells of the sectors it serves.
#[derive(Debug, Clone)]
pub struct Flash {
    /// The cells (the whole 512 KiB; the image's sectors are the engine's memory).
    pub mem: Vec<u8>,
    /// First offset served by the model (the start of the sector after the image).
    pub model_from: u32,
    acr: u32,
    cr: u32,
    sr: u32,
    optcr: u32,
    /// KEYR has seen KEY1.
    key1: bool,
    /// OPTKEYR has seen OPTKEY1.
    optkey1: bool,
    /// A wrong key sequence locked CR until reset.
    locked_until_reset: bool,
    /// End of the operation running (cycle), if BSY.
    busy_until: Option<u64>,
    /// The running operation is an erase (STRT reads 1).
    erasing: bool,
    /// The board clock that BSY times count in \[Hz\].
    hz: u64,
    /// Sector erases done.
    pub erases: u64,
    /// Program operations done.
    pub programs: u64,
    /// Cycles the core waited on a busy flash.
    pub stalled: u64,
}

/// What a flash access did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    /// Done.
    Ok,
    /// Refused: this SR flag was set, nothing written.
    Refused(u32),
}

impl Flash {
    /// An erased flash (0xFF) served from `model_from` on, at a `hz` board clock.
    pub fn new(model_from: u32, hz: u64) -> Self {
        Flash {
            mem: vec![0xFF; SIZE],
            model_from,
            acr: 0,
            cr: LOCK,
            sr: 0,
            optcr: OPTCR_RESET,
            key1: false,
            optkey1: false,
            locked_until_reset: false,
            busy_until: None,
            erasing: false,
            hz,
            erases: 0,
            programs: 0,
            stalled: 0,
        }
    }

    /// A system reset: registers to their reset values (OPTCR reloaded from the option
    /// bytes, locked), the cells as they are; an operation in flight finishes.
    pub fn reset(&mut self) {
        self.acr = 0;
        self.cr = LOCK;
        self.sr = 0;
        self.optcr |= 1;
        self.key1 = false;
        self.optkey1 = false;
        self.locked_until_reset = false;
        self.busy_until = None;
        self.erasing = false;
    }

    fn cycles(&self, ns: u64) -> u64 {
        (u128::from(ns) * u128::from(self.hz) / 1_000_000_000) as u64
    }

    /// Ends the operation if its time has come.
    fn sync(&mut self, now: u64) {
        if self.busy_until.is_some_and(|t| now >= t) {
            self.busy_until = None;
            self.erasing = false;
            if self.cr & EOPIE != 0 {
                self.sr |= EOP;
            }
        }
    }

    /// BSY at cycle `now`.
    pub fn busy(&mut self, now: u64) -> bool {
        self.sync(now);
        self.busy_until.is_some()
    }

    /// The cycle a flash access at `now` waits for (BSY's end), if it has to.
    pub fn stall_until(&mut self, now: u64) -> Option<u64> {
        self.sync(now);
        self.busy_until
    }

    /// CR is locked.
    pub fn locked(&self) -> bool {
        self.cr & LOCK != 0
    }

    fn psize(&self) -> u32 {
        (self.cr >> 8) & 3
    }

    fn protected(&self, sector: usize) -> bool {
        self.optcr & (1 << (16 + sector)) == 0
    }

    /// A register read at cycle `now`.
    pub fn read(&mut self, off: u64, now: u64) -> u32 {
        self.sync(now);
        match off {
            ACR => self.acr,
            SR => self.sr | if self.busy_until.is_some() { BSY } else { 0 },
            CR => self.cr | if self.erasing { STRT } else { 0 },
            OPTCR => self.optcr,
            _ => 0,
        }
    }

    /// A register write at cycle `now` (the caller stalled a CR write while BSY). An
    /// error: a bus error (a wrong key sequence) or what the model does not serve.
    pub fn write(&mut self, off: u64, v: u32, now: u64) -> Result<(), String> {
        self.sync(now);
        match off {
            ACR => self.acr = v & 0x1F0F,
            KEYR => {
                let expected = if self.key1 { KEY2 } else { KEY1 };
                if self.locked_until_reset || !self.locked() || v != expected {
                    self.key1 = false;
                    self.locked_until_reset = true;
                    self.cr |= LOCK;
                    return Err(format!(
                        "FLASH_KEYR: {v:#010x} is not the next key of the unlock sequence \
                         (expected {expected:#010x}{}): a bus error, FLASH_CR locked until \
                         reset (RM0390 §3.5.1)",
                        if self.locked() {
                            ""
                        } else {
                            "; CR was unlocked"
                        }
                    ));
                }
                if self.key1 {
                    self.cr &= !LOCK;
                }
                self.key1 = !self.key1;
            }
            OPTKEYR => {
                let expected = if self.optkey1 { OPTKEY2 } else { OPTKEY1 };
                if self.optcr & 1 == 0 || v != expected {
                    self.optkey1 = false;
                    return Err(format!(
                        "FLASH_OPTKEYR: {v:#010x} is not the next key (expected \
                         {expected:#010x}): a bus error"
                    ));
                }
                if self.optkey1 {
                    self.optcr &= !1;
                }
                self.optkey1 = !self.optkey1;
            }
            SR => self.sr &= !(v & SR_W1C),
            CR => {
                if self.locked() {
                    return Ok(()); // ignored while locked
                }
                self.cr = (self.cr & !CR_RW) | (v & CR_RW) | (v & LOCK);
                if v & STRT != 0 && v & LOCK == 0 {
                    return self.start(now);
                }
            }
            OPTCR => {
                if self.optcr & 1 != 0 {
                    return Ok(());
                }
                // OPTSTRT (bit 1) programs the option bytes: the values written apply.
                self.optcr = v & !2;
            }
            _ => {}
        }
        Ok(())
    }

    /// STRT: a sector erase.
    fn start(&mut self, now: u64) -> Result<(), String> {
        if self.cr & MER != 0 {
            return Err("FLASH_CR.MER: a mass erase erases the running image; not modelled".into());
        }
        if self.cr & SER == 0 {
            self.sr |= PGSERR;
            return Ok(());
        }
        let snb = ((self.cr >> 3) & 0xF) as usize;
        let Some(&(start, len)) = SECTORS.get(snb) else {
            return Err(format!(
                "FLASH_CR.SNB = {snb}: the STM32F446 has sectors 0..7"
            ));
        };
        if start < self.model_from {
            return Err(format!(
                "erase of flash sector {snb} ({:#010x}), which holds the image: not modelled",
                BASE + u64::from(start)
            ));
        }
        if self.protected(snb) {
            self.sr |= WRPERR;
            return Ok(());
        }
        self.mem[start as usize..(start + len) as usize].fill(0xFF);
        self.erases += 1;
        self.erasing = true;
        self.busy_until = Some(now + self.cycles(erase_ns(len, self.psize())));
        Ok(())
    }

    /// A CPU read of `size` bytes at flash offset `off` (little endian).
    pub fn load(&self, off: u32, size: usize) -> u64 {
        let o = off as usize;
        (0..size.min(8)).rev().fold(0u64, |v, k| {
            (v << 8) | u64::from(self.mem.get(o + k).copied().unwrap_or(0xFF))
        })
    }

    /// A CPU write of `size` bytes of `v` at flash offset `off` at cycle `now` (the caller
    /// stalled it while BSY): programmed, or refused with the flag RM0390 names.
    pub fn store(&mut self, off: u32, size: usize, v: u64, now: u64) -> Access {
        self.sync(now);
        if self.cr & PG == 0 || self.locked() || self.cr & (SER | MER) != 0 {
            self.sr |= PGSERR;
            return Access::Refused(PGSERR);
        }
        let psize = self.psize();
        if psize == 3 || size != 1 << psize {
            self.sr |= PGPERR;
            return Access::Refused(PGPERR);
        }
        if !(off as usize).is_multiple_of(size) {
            self.sr |= PGAERR;
            return Access::Refused(PGAERR);
        }
        if sector_of(off).is_none_or(|s| self.protected(s)) {
            self.sr |= WRPERR;
            return Access::Refused(WRPERR);
        }
        for k in 0..size {
            if let Some(c) = self.mem.get_mut(off as usize + k) {
                *c &= (v >> (8 * k)) as u8;
            }
        }
        self.programs += 1;
        self.busy_until = Some(now + self.cycles(PROGRAM_NS));
        Access::Ok
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const HZ: u64 = 180_000_000;
    /// Sector 6's offset.
    const S6: u32 = 0x4_0000;

    fn unlocked() -> Flash {
        let mut f = Flash::new(S6, HZ);
        f.write(KEYR, KEY1, 0).unwrap();
        f.write(KEYR, KEY2, 0).unwrap();
        assert!(!f.locked());
        f
    }

    /// PSIZE x32 (the 2.7–3.6 V range).
    const X32: u32 = 2 << 8;

    fn erase(f: &mut Flash, sector: u32, now: u64) {
        f.write(CR, SER | X32 | (sector << 3), now).unwrap();
        f.write(CR, SER | X32 | (sector << 3) | STRT, now).unwrap();
    }

    #[test]
    fn erase_sets_every_byte_of_the_sector_and_bsy_lasts_the_datasheet_time() {
        let mut f = unlocked();
        f.mem[S6 as usize..S6 as usize + 4].copy_from_slice(&[1, 2, 3, 4]);
        f.mem[0x6_0000] = 0; // sector 7: untouched
        erase(&mut f, 6, 1000);
        assert!(f.mem[S6 as usize..0x6_0000].iter().all(|&b| b == 0xFF));
        assert_eq!(f.mem[0x6_0000], 0);
        assert_ne!(f.read(SR, 1000) & BSY, 0);
        assert_ne!(f.read(CR, 1000) & STRT, 0, "STRT reads 1 while erasing");
        // 128 KiB at x32: 1 s typical.
        let end = 1000 + HZ;
        assert_ne!(f.read(SR, end - 1) & BSY, 0);
        assert_eq!(f.read(SR, end) & BSY, 0);
        assert_eq!(f.read(SR, end) & EOP, 0, "EOP only with EOPIE");
        assert_eq!(f.erases, 1);
    }

    #[test]
    fn programming_only_clears_bits_a_program_without_erase_cannot_set_them() {
        let mut f = unlocked();
        f.write(CR, PG | X32, 0).unwrap();
        assert_eq!(f.store(S6, 4, 0x1234_5678, 0), Access::Ok);
        assert_eq!(f.load(S6, 4), 0x1234_5678);
        let t = f.cycles(PROGRAM_NS);
        assert!(f.busy(t - 1) && !f.busy(t), "16 µs per word");
        // Over it without an erase: 0x1234_5678 & 0xFFFF_0000 — the bits set stay clear.
        assert_eq!(f.store(S6, 4, 0xFFFF_0000, t), Access::Ok);
        assert_eq!(f.load(S6, 4), 0x1234_0000);
        assert_eq!(f.store(S6, 4, 0xFFFF_FFFF, 2 * t), Access::Ok);
        assert_eq!(
            f.load(S6, 4),
            0x1234_0000,
            "no bit comes back without an erase"
        );
        // The erase brings them back.
        f.write(CR, X32, 3 * t).unwrap();
        erase(&mut f, 6, 3 * t);
        assert_eq!(f.load(S6, 4), 0xFFFF_FFFF);
        assert_eq!(
            f.read(SR, 4 * t + HZ) & (PGSERR | PGPERR | PGAERR | WRPERR),
            0
        );
    }

    #[test]
    fn a_locked_flash_refuses_programs_with_pgserr_and_ignores_cr() {
        let mut f = Flash::new(S6, HZ);
        assert!(f.locked());
        f.write(CR, PG | X32, 0).unwrap();
        assert_eq!(f.read(CR, 0), LOCK, "CR writes ignored while locked");
        assert_eq!(f.store(S6, 4, 0, 0), Access::Refused(PGSERR));
        assert_eq!(f.load(S6, 4), 0xFFFF_FFFF, "nothing written");
        assert_ne!(f.read(SR, 0) & PGSERR, 0);
        f.write(SR, PGSERR, 0).unwrap();
        assert_eq!(f.read(SR, 0) & PGSERR, 0, "write 1 to clear");
        // Unlocked, but PG clear: the same.
        let mut f = unlocked();
        assert_eq!(f.store(S6, 4, 0, 0), Access::Refused(PGSERR));
        // LOCK set again locks.
        f.write(CR, LOCK, 0).unwrap();
        assert!(f.locked());
    }

    #[test]
    fn a_wrong_key_is_a_bus_error_and_locks_cr_until_reset() {
        let mut f = Flash::new(S6, HZ);
        f.write(KEYR, KEY1, 0).unwrap();
        let e = f.write(KEYR, 0x1234_5678, 0).unwrap_err();
        assert!(e.contains("locked until reset"), "{e}");
        // The right sequence no longer unlocks.
        assert!(f.write(KEYR, KEY1, 0).is_err());
        assert!(f.write(KEYR, KEY2, 0).is_err());
        assert!(f.locked());
        f.reset();
        f.write(KEYR, KEY1, 0).unwrap();
        f.write(KEYR, KEY2, 0).unwrap();
        assert!(!f.locked(), "a reset ends the lock-up");
        // A key while unlocked is a wrong sequence too.
        assert!(f.write(KEYR, KEY1, 0).is_err());
        assert!(f.locked());
    }

    #[test]
    fn width_alignment_and_protection_errors_are_the_reference_manuals() {
        let mut f = unlocked();
        f.write(CR, PG | X32, 0).unwrap();
        assert_eq!(
            f.store(S6, 2, 0, 0),
            Access::Refused(PGPERR),
            "halfword at x32"
        );
        assert_eq!(f.store(S6 + 2, 4, 0, 0), Access::Refused(PGAERR));
        f.write(CR, PG | (1 << 8), 0).unwrap(); // x16
        assert_eq!(f.store(S6, 2, 0xAB00, 0), Access::Ok);
        f.write(CR, PG | (3 << 8), f.cycles(PROGRAM_NS)).unwrap(); // x64: VPP only
        assert_eq!(f.store(S6 + 8, 4, 0, 0), Access::Refused(PGPERR));
        // Sector 7 write-protected through the option bytes: WRPERR on program and erase.
        f.write(OPTKEYR, OPTKEY1, 0).unwrap();
        f.write(OPTKEYR, OPTKEY2, 0).unwrap();
        f.write(OPTCR, OPTCR_RESET & !1 & !(1 << (16 + 7)), 0)
            .unwrap();
        f.write(CR, PG | X32, f.cycles(PROGRAM_NS)).unwrap();
        assert_eq!(f.store(0x6_0000, 4, 0, 0), Access::Refused(WRPERR));
        f.write(CR, X32, 0).unwrap();
        erase(&mut f, 7, 0);
        assert_ne!(f.read(SR, 0) & WRPERR, 0);
        assert!(!f.busy(0), "nothing started");
        assert_eq!(f.load(S6, 2), 0xAB00, "the x16 program landed");
    }

    #[test]
    fn erasing_the_images_own_sectors_or_all_of_flash_is_refused_by_name() {
        let mut f = unlocked();
        f.write(CR, SER | X32 | (5 << 3), 0).unwrap();
        let e = f.write(CR, SER | X32 | (5 << 3) | STRT, 0).unwrap_err();
        assert!(e.contains("sector 5") && e.contains("image"), "{e}");
        let e = f.write(CR, MER | STRT, 0).unwrap_err();
        assert!(e.contains("MER"), "{e}");
    }

    #[test]
    fn sector_map_and_erase_times_follow_the_reference_and_datasheet() {
        assert_eq!(sector_of(0x3FFF), Some(0));
        assert_eq!(sector_of(0x1_0000), Some(4));
        assert_eq!(sector_of(0x7_FFFF), Some(7));
        assert_eq!(sector_of(0x8_0000), None);
        assert_eq!(erase_ns(16 << 10, 0), 400_000_000);
        assert_eq!(erase_ns(128 << 10, 2), 1_000_000_000);
    }
}
