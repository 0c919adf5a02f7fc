//! Minimal firmware image of the thesis' demo device for an STM32F446 (Cortex-M4F): the
//! `oxicat-slave` stack with `oxicat_devices::demo::DEF` and the `Demo` application, driven
//! the way an MCU drives it (interrupt lines polled in the main loop).
//!
//! **A size/link check, not a working board firmware.** The ESC is reached through
//! [`StubPdi`], a stand-in for the LAN9252 SPI driver of a later issue: reads return opaque
//! zeros and writes are swallowed (both through `core::hint::black_box`, so the optimiser
//! cannot prove anything about the ESC and keeps the whole stack: ESM, mailbox, CoE, PDO
//! mapping, sync modes). No clocks, GPIO, SPI or interrupts are set up. What it shows is
//! that the stack and the device link for `thumbv7em-none-eabihf` and how much flash and
//! RAM they take: `cargo build --release`, then `llvm-size` on
//! `../target/thumbv7em-none-eabihf/release/oxicat-firmware-minimal` (the images' shared
//! target directory, `firmware/target`).
//!
//! The device advertises FoE (firmware download in BOOT, `version.txt`), and the image
//! serves it: the stack's update flow ([`FirmwareUpdate`]: `firmware.bin` in BOOT, CRC and
//! identity checks, the FoE error codes, `version.txt`) on [`StubFlash`], a stand-in for a
//! flash driver such as `firmware/tue-es030/src/store.rs` (two 128 KiB slots), opaque to
//! the optimiser like [`StubPdi`]. The stack's state is built in place in a static
//! ([`SlaveSlot`]), so `main`'s frame holds no `Slave`.
#![no_std]
#![no_main]

use core::hint::black_box;

use cortex_m_rt::entry;
use oxicat_devices::demo::{self, Buttons, Demo, Leds};
use oxicat_fw_mem as _;
use oxicat_slave::foe::{FirmwareStore, FirmwareUpdate, StoreError, UpdateConfig, WithFoe};
use oxicat_slave::{CheckedDef, DeviceDef, IrqLines, Pdi, Slave, SlaveSlot};
use panic_halt as _;

/// The demo device as the image links it: the stack's part of `demo::DEF`, without the
/// texts only its ESI and SII carry (vendor, group, description, DC mode names).
static DEF: DeviceDef = demo::DEF.for_image();

/// Mailbox buffer size of the stack: the demo's mailboxes are 128 bytes.
const MBX: usize = 128;

/// Copy steps per direction of the stack's compiled PDO mappings: what the demo device's
/// fixed mapping compiles to (13 outputs, 5 inputs; the default of 64 would be 1 KB of RAM).
const MAP: usize = oxicat_slave::pdo::map_steps(&demo::DEF);

/// The stack type of this image.
type Stack = Slave<StubPdi, { demo::IMAGE }, MBX, MAP>;

/// Bytes of the stack's state (the `Slave` value), readable from the ELF symbol table.
#[no_mangle]
#[used]
pub static OXICAT_SLAVE_BYTES: usize = core::mem::size_of::<Stack>();

/// Stand-in for the ESC driver (LAN9252 over SPI in a later issue).
pub struct StubPdi;

/// Errors of the stub (none; a real SPI driver reports bus errors here).
#[derive(Debug)]
pub struct NoError;

impl Pdi for StubPdi {
    type Error = NoError;

    fn read(&mut self, addr: u16, buf: &mut [u8]) -> Result<(), NoError> {
        black_box(addr);
        for b in buf.iter_mut() {
            *b = black_box(0);
        }
        Ok(())
    }

    fn write(&mut self, addr: u16, data: &[u8]) -> Result<(), NoError> {
        black_box((addr, data));
        Ok(())
    }

    fn al_event_request(&mut self) -> Result<u32, NoError> {
        Ok(black_box(0))
    }

    fn irq_lines(&mut self) -> IrqLines {
        IrqLines {
            pdi_irq: black_box(false),
            sync0: black_box(false),
            sync1: black_box(false),
        }
    }
}

/// Stand-in for the flash driver of the FoE firmware store (two 128 KiB sectors on an
/// STM32F446, as `firmware/tue-es030/src/store.rs`): every operation goes through
/// `black_box`, so the update flow above it stays whole in the image.
pub struct StubFlash;

impl FirmwareStore for StubFlash {
    fn slots(&self) -> u8 {
        2
    }

    fn capacity(&self) -> u32 {
        128 * 1024
    }

    fn erase(&mut self, slot: u8) -> Result<(), StoreError> {
        black_box(slot);
        if black_box(false) {
            return Err(StoreError::Busy { done: 0, entire: 1 });
        }
        Ok(())
    }

    fn write(&mut self, slot: u8, offset: u32, data: &[u8]) -> Result<(), StoreError> {
        black_box((slot, offset, data));
        Ok(())
    }

    fn read(&mut self, slot: u8, offset: u32, buf: &mut [u8]) -> Result<(), StoreError> {
        black_box((slot, offset));
        for b in buf.iter_mut() {
            *b = black_box(0xFF);
        }
        Ok(())
    }

    fn mark_bootable(&mut self, slot: u8) -> Result<(), StoreError> {
        black_box(slot);
        Ok(())
    }

    fn bootable(&self) -> Option<u8> {
        black_box(Some(0))
    }
}

/// The FoE files the demo device advertises: `firmware.bin` writable in BOOT (and read
/// back), `version.txt` readable, as the host rig's demo devices serve them.
const UPDATE: UpdateConfig = UpdateConfig {
    identity: DEF.identity,
    file_name: "firmware.bin",
    password: 0,
    read_back: true,
};

/// The board's LEDs (GPIO writes on real hardware).
struct BoardLeds;
impl Leds for BoardLeds {
    fn set(&mut self, blue: bool, red: bool) {
        black_box((blue, red));
    }
}

/// The board's buttons (GPIO reads on real hardware).
struct BoardButtons;
impl Buttons for BoardButtons {
    fn read(&mut self) -> u8 {
        black_box(0)
    }
}

/// Interrupt vectors of the STM32F446 (IRQ 0..=96, RM0390; the board images' PAC table
/// has 90), each the default handler: this image enables none. cortex-m-rt without a
/// device crate would put 240 (960 B).
#[link_section = ".vector_table.interrupts"]
#[no_mangle]
static __INTERRUPTS: [unsafe extern "C" fn(); 97] = [DefaultHandler; 97];

extern "C" {
    /// cortex-m-rt's default exception handler (`link.x`).
    fn DefaultHandler();
}

#[entry]
fn main() -> ! {
    // The stack's state, built in place in `.bss` (cortex-m-rt hands `main` a `&'static
    // mut`): no `Slave` value on the stack and no copy of one.
    static mut SLOT: SlaveSlot<StubPdi, { demo::IMAGE }, MBX, MAP> = SlaveSlot::new();
    let mut pdi = StubPdi;
    let mut app = WithFoe {
        app: Demo::new(BoardLeds, BoardButtons),
        files: FirmwareUpdate::new(StubFlash, UPDATE),
    };
    // The definition checked when the image is built (`check_def` is not in the image).
    let Ok(slave) = SLOT.start_checked(const { CheckedDef::new(&DEF) }, &mut pdi) else {
        #[allow(clippy::empty_loop)]
        loop {}
    };
    loop {
        // On hardware: the PDI IRQ, SYNC0 and SYNC1 interrupt handlers and a 1 kHz timer.
        let lines = pdi.irq_lines();
        if lines.pdi_irq {
            let _ = slave.on_pdi_irq(&mut pdi, &mut app);
        }
        if lines.sync0 {
            let _ = slave.on_sync0(&mut pdi, &mut app);
        }
        if lines.sync1 {
            let _ = slave.on_sync1(&mut pdi, &mut app);
        }
        if black_box(false) {
            slave.on_timer(0, &mut app);
        }
        let _ = slave.poll(&mut pdi, &mut app);
    }
}
