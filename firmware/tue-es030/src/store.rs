//! The FoE firmware store in the STM32F446's own flash: two slots, sectors 6 and 7
//! (128 KiB each, 0x0804_0000 and 0x0806_0000, outside the image: `memory.x` gives the
//! image sectors 0..5), behind `oxicat_slave::foe::FirmwareStore`, so the stack's update
//! flow (`FirmwareUpdate`: `firmware.bin` in BOOT, the CRC and identity checks, the FoE
//! error codes, `version.txt`) is the host rig's, only the storage differs.
//!
//! A slot: a 16-byte mark, then the image (header + payload). The mark's first word is
//! the slot's bootable sequence number (erased, 0xFFFF_FFFF: not bootable); the bootable
//! slot is the marked one with the later number. An update erases the other slot, programs
//! the image, and — only after the flow read it back and checked it — programs that slot's
//! mark with the next number: a download interrupted or refused at any point leaves the
//! previous slot the bootable one. The factory image (the host rig's, mark 1) is part of
//! the ELF, in sector 6.
//!
//! The FLASH interface per RM0390 §3: unlock with KEYR (KEY1, KEY2) when CR.LOCK is set,
//! sector erase (SER, SNB, STRT) and programming (PG) at PSIZE x32 (a word per write; the
//! unaligned head and tail of a packet at x8), BSY polled, then EOP/OPERR/WRPERR/PGAERR/
//! PGPERR/PGSERR checked and cleared; CR locked again after each operation. The F446 has
//! one bank: while it erases (about 1 s for 128 KiB) or programs, every fetch from flash
//! waits, so the CPU — interrupts included — stands still for the erase. The store is
//! written only in BOOT, where the bridges are braked and no process data runs.

use oxicat_slave::foe::{FirmwareStore, StoreError, IMAGE_HEADER_LEN};
use stm32f4xx_hal::pac;

/// Base address of each slot (sectors 6 and 7).
const SLOT_BASE: [u32; 2] = [0x0804_0000, 0x0806_0000];
/// The sector of each slot.
const SLOT_SECTOR: [u8; 2] = [6, 7];
/// Bytes per sector.
const SECTOR_BYTES: u32 = 128 * 1024;
/// The mark in front of the image.
const MARK_BYTES: u32 = 16;
/// An erased word.
const ERASED: u32 = 0xFFFF_FFFF;

const KEY1: u32 = 0x4567_0123;
const KEY2: u32 = 0xCDEF_89AB;
/// SR: EOP, OPERR, WRPERR, PGAERR, PGPERR, PGSERR, RDERR.
const SR_ERRORS: u32 = 0x1F2;
const SR_EOP: u32 = 1;
const SR_BSY: u32 = 1 << 16;
/// CR.PSIZE codes.
const X8: u8 = 0;
const X32: u8 = 2;

/// The factory image in sector 6: the mark (bootable, number 1) and the host rig's
/// factory image (`oxicat tue-es030 firmware <version>` for the board's identity).
#[link_section = ".foe_factory"]
#[used]
static FACTORY: [u8; FACTORY_LEN] = factory();

const PAYLOAD: &[u8] = oxicat_devices::tue_es030::FACTORY_PAYLOAD.as_bytes();
const FACTORY_LEN: usize = MARK_BYTES as usize + IMAGE_HEADER_LEN + PAYLOAD.len();

/// The bytes of [`FACTORY`] (`oxicat_slave::foe::ImageHeader`'s layout, built at compile
/// time).
const fn factory() -> [u8; FACTORY_LEN] {
    let id = oxicat_devices::tue_es030::device::IDENTITY;
    let mut b = [0xFFu8; FACTORY_LEN];
    let mut words = [0u32; 8];
    words[0] = u32::from_le_bytes(*b"OXFW");
    words[1] = 1 | ((IMAGE_HEADER_LEN as u32) << 16);
    words[2] = id.vendor_id;
    words[3] = id.product_code;
    words[4] = id.revision;
    words[5] = PAYLOAD.len() as u32;
    words[6] = oxicat_slave::foe::crc32(PAYLOAD);
    words[7] = 0;
    // The mark: bootable, number 1 (the rest of the 16 bytes erased).
    let m = 1u32.to_le_bytes();
    let mut i = 0;
    while i < 4 {
        b[i] = m[i];
        i += 1;
    }
    let mut w = 0;
    while w < 8 {
        let x = words[w].to_le_bytes();
        let mut k = 0;
        while k < 4 {
            b[MARK_BYTES as usize + 4 * w + k] = x[k];
            k += 1;
        }
        w += 1;
    }
    let mut p = 0;
    while p < PAYLOAD.len() {
        b[MARK_BYTES as usize + IMAGE_HEADER_LEN + p] = PAYLOAD[p];
        p += 1;
    }
    b
}

/// The two slots in sectors 6 and 7, through the FLASH interface.
pub struct FlashStore {
    flash: pac::FLASH,
}

impl FlashStore {
    /// The store on the FLASH peripheral.
    pub fn new(flash: pac::FLASH) -> Self {
        // Keep the factory image in the ELF (the linker would drop an unused static).
        // SAFETY: a read of a static.
        let _ = unsafe { core::ptr::read_volatile(&FACTORY[0]) };
        FlashStore { flash }
    }

    /// The mark's sequence number of `slot` (ERASED: not bootable).
    fn mark(slot: usize) -> u32 {
        // SAFETY: an aligned read of the flash slot's first word.
        unsafe { core::ptr::read_volatile(SLOT_BASE[slot] as *const u32) }
    }

    /// Unlocks CR if locked (a key while unlocked would lock it until reset).
    fn unlock(&mut self) {
        if self.flash.cr().read().lock().bit_is_set() {
            // SAFETY: the unlock keys of RM0390 §3.5.1, in order.
            self.flash.keyr().write(|w| unsafe { w.bits(KEY1) });
            self.flash.keyr().write(|w| unsafe { w.bits(KEY2) });
        }
    }

    fn lock(&mut self) {
        self.flash.cr().modify(|_, w| w.lock().set_bit());
    }

    /// Waits while BSY, then takes the error flags: any set fails the operation.
    fn finish(&mut self) -> Result<(), StoreError> {
        while self.flash.sr().read().bits() & SR_BSY != 0 {}
        let sr = self.flash.sr().read().bits();
        // SAFETY: SR's flags are write-1-to-clear.
        self.flash
            .sr()
            .write(|w| unsafe { w.bits(sr & (SR_ERRORS | SR_EOP)) });
        if sr & SR_ERRORS & !SR_EOP != 0 {
            Err(StoreError::Failed)
        } else {
            Ok(())
        }
    }

    /// Clears stale error flags (a program refused earlier).
    fn clear_flags(&mut self) {
        // SAFETY: write-1-to-clear.
        self.flash
            .sr()
            .write(|w| unsafe { w.bits(SR_ERRORS | SR_EOP) });
    }

    /// Programs `data` at flash address `addr` (in a slot): whole aligned words at x32,
    /// the bytes before and after them at x8.
    fn program(&mut self, mut addr: u32, mut data: &[u8]) -> Result<(), StoreError> {
        self.unlock();
        self.clear_flags();
        let r = (|| {
            while !data.is_empty() {
                if addr.is_multiple_of(4) && data.len() >= 4 {
                    self.set_pg(X32);
                    let w = u32::from_le_bytes([data[0], data[1], data[2], data[3]]);
                    // SAFETY: an aligned word in a slot, PG set at x32.
                    unsafe { core::ptr::write_volatile(addr as *mut u32, w) };
                    self.finish()?;
                    addr += 4;
                    data = &data[4..];
                } else {
                    self.set_pg(X8);
                    // SAFETY: a byte in a slot, PG set at x8.
                    unsafe { core::ptr::write_volatile(addr as *mut u8, data[0]) };
                    self.finish()?;
                    addr += 1;
                    data = &data[1..];
                }
            }
            Ok(())
        })();
        self.flash.cr().write(|w| w.lock().set_bit());
        r
    }

    fn set_pg(&mut self, psize: u8) {
        // SAFETY: PSIZE codes 0..=2, PG alone (raw bits: the register's reset value has
        // LOCK set, which a write would set again).
        self.flash
            .cr()
            .write(|w| unsafe { w.bits((u32::from(psize) << 8) | 1) });
    }

    fn slot_index(slot: u8) -> Result<usize, StoreError> {
        let s = usize::from(slot);
        if s < SLOT_BASE.len() {
            Ok(s)
        } else {
            Err(StoreError::OutOfRange)
        }
    }
}

impl FirmwareStore for FlashStore {
    fn slots(&self) -> u8 {
        SLOT_BASE.len() as u8
    }

    fn capacity(&self) -> u32 {
        SECTOR_BYTES - MARK_BYTES
    }

    /// Erases the slot's sector; blocking (the CPU stalls on the flash anyway).
    fn erase(&mut self, slot: u8) -> Result<(), StoreError> {
        let s = Self::slot_index(slot)?;
        self.unlock();
        self.clear_flags();
        // SAFETY: SER, SNB 6 or 7, PSIZE x32 (2.7–3.6 V); raw bits, LOCK clear.
        self.flash.cr().write(|w| unsafe {
            w.bits((u32::from(X32) << 8) | (u32::from(SLOT_SECTOR[s]) << 3) | 2)
        });
        self.flash.cr().modify(|_, w| w.strt().set_bit());
        let r = self.finish();
        self.lock();
        r
    }

    fn write(&mut self, slot: u8, offset: u32, data: &[u8]) -> Result<(), StoreError> {
        let s = Self::slot_index(slot)?;
        if u64::from(offset) + data.len() as u64 > u64::from(self.capacity()) {
            return Err(StoreError::OutOfRange);
        }
        self.program(SLOT_BASE[s] + MARK_BYTES + offset, data)
    }

    fn read(&mut self, slot: u8, offset: u32, buf: &mut [u8]) -> Result<(), StoreError> {
        let s = Self::slot_index(slot)?;
        if u64::from(offset) + buf.len() as u64 > u64::from(self.capacity()) {
            return Err(StoreError::OutOfRange);
        }
        let from = SLOT_BASE[s] + MARK_BYTES + offset;
        for (k, b) in buf.iter_mut().enumerate() {
            // SAFETY: a byte inside the slot (checked above).
            *b = unsafe { core::ptr::read_volatile((from as usize + k) as *const u8) };
        }
        Ok(())
    }

    /// Programs the slot's mark with the number after the other slot's.
    fn mark_bootable(&mut self, slot: u8) -> Result<(), StoreError> {
        let s = Self::slot_index(slot)?;
        let other = Self::mark(1 - s);
        let next = match other {
            ERASED => 1,
            n if n.wrapping_add(1) == ERASED => 1,
            n => n.wrapping_add(1),
        };
        self.program(SLOT_BASE[s], &next.to_le_bytes())?;
        if Self::mark(s) == next {
            Ok(())
        } else {
            Err(StoreError::Failed)
        }
    }

    fn bootable(&self) -> Option<u8> {
        match (Self::mark(0), Self::mark(1)) {
            (ERASED, ERASED) => None,
            (_, ERASED) => Some(0),
            (ERASED, _) => Some(1),
            (a, b) => Some(if (b.wrapping_sub(a) as i32) > 0 { 1 } else { 0 }),
        }
    }
}
