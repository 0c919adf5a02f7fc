//! Driver tests against the simulated chips: every command byte-exact, malformed replies
//! and dead chips end in errors (bounded retries), never in a hang.

use embedded_hal::spi::{ErrorType, Operation, SpiDevice};
use oxicat_esc::{Esc, EscConfig};
use oxicat_pdi::et1100::{address_phase, cmd as ecmd};
use oxicat_pdi::lan9252::{cmd as lcmd, reg};
use oxicat_pdi::sim::{
    BusConfig, Et1100Model, Fault, Handle, Lan9252Model, Model, PinKind, SimSpi,
};
use oxicat_pdi::{
    AddressMode, Error, Et1100Config, Et1100Spi, Lan9252, Lan9252Config, NoLines, Pins, ReadMode,
};
use oxicat_slave::Pdi;
use oxicat_testkit::device::{eeprom, DEF};
use std::cell::RefCell;
use std::rc::Rc;

/// Records the MOSI bytes of every transaction, then forwards it.
struct Rec<S> {
    inner: S,
    log: Rc<RefCell<Vec<Vec<u8>>>>,
}

impl<S: ErrorType> ErrorType for Rec<S> {
    type Error = S::Error;
}

impl<S: SpiDevice> SpiDevice for Rec<S> {
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), S::Error> {
        let mut m = Vec::new();
        for op in ops.iter() {
            match op {
                Operation::Read(b) => m.extend(std::iter::repeat_n(0, b.len())),
                Operation::Write(w) => m.extend_from_slice(w),
                Operation::Transfer(_, w) => m.extend_from_slice(w),
                Operation::TransferInPlace(b) => m.extend_from_slice(b),
                Operation::DelayNs(_) => {}
            }
        }
        self.log.borrow_mut().push(m);
        self.inner.transaction(ops)
    }
}

type Log = Rc<RefCell<Vec<Vec<u8>>>>;

fn esc(cfg: EscConfig) -> Esc {
    Esc::new(cfg, eeprom(&DEF))
}

fn lan_with(
    cfg: Lan9252Config,
    fault: Fault,
) -> (
    Lan9252<Rec<SimSpi<Lan9252Model>>, NoLines>,
    Handle<Lan9252Model>,
    Log,
) {
    let h = Lan9252Model::handle(esc(EscConfig::lan9252()), BusConfig::mhz(20));
    h.set_fault(fault);
    let log = Log::default();
    let spi = Rec {
        inner: h.spi(),
        log: log.clone(),
    };
    (Lan9252::new(spi, NoLines, cfg), h, log)
}

fn lan() -> (
    Lan9252<Rec<SimSpi<Lan9252Model>>, NoLines>,
    Handle<Lan9252Model>,
    Log,
) {
    let (mut d, h, log) = lan_with(Lan9252Config::default(), Fault::None);
    assert_eq!(d.init(), Ok(0x9252_0001));
    log.borrow_mut().clear();
    h.reset_stats();
    (d, h, log)
}

// ------------------------------------------------------------------ LAN9252

#[test]
fn lan9252_read_and_fast_read_frames() {
    let (mut d, _h, log) = lan();
    assert_eq!(d.read_reg(reg::BYTE_TEST), Ok(0x8765_4321));
    assert_eq!(log.borrow()[0], [lcmd::READ, 0x40, 0x64, 0, 0, 0, 0]);
    let (mut f, _h, log) = lan_with(
        Lan9252Config {
            fast_read: true,
            ..Default::default()
        },
        Fault::None,
    );
    assert_eq!(f.read_reg(reg::BYTE_TEST), Ok(0x8765_4321));
    assert_eq!(
        log.borrow()[0],
        [lcmd::FAST_READ, 0x40, 0x64, 0, 0, 0, 0, 0]
    );
    assert_eq!(f.read_reg(reg::ID_REV), Ok(0x9252_0001));
}

#[test]
fn lan9252_init_sequence() {
    let (mut d, h, log) = lan_with(Lan9252Config::default(), Fault::None);
    assert_eq!(d.init(), Ok(0x9252_0001));
    let l = log.borrow();
    // BYTE_TEST, HW_CFG, ID_REV, RESET_CTL write, BYTE_TEST, HW_CFG (not ready once),
    // HW_CFG, IRQ_CFG, INT_EN.
    assert_eq!(l[0][..3], [0x03, 0x40, 0x64]);
    assert_eq!(l[1][..3], [0x03, 0x40, 0x74]);
    assert_eq!(l[2][..3], [0x03, 0x40, 0x50]);
    assert_eq!(l[3], [0x02, 0x41, 0xF8, 1, 0, 0, 0]);
    assert_eq!(l[7], [0x02, 0x40, 0x54, 0x00, 0x01, 0, 0]);
    assert_eq!(l[8], [0x02, 0x40, 0x5C, 1, 0, 0, 0]);
    assert_eq!(h.stats().protocol_errors, 0);
}

#[test]
fn lan9252_csr_read_write() {
    let (mut d, h, log) = lan();
    // AL status via CSR: command, poll, data.
    let mut b = [0u8; 2];
    d.csr_read(0x0130, &mut b).unwrap();
    assert_eq!(b, [1, 0]);
    {
        let l = log.borrow();
        assert_eq!(l.len(), 3);
        let c: u32 = reg::CSR_BUSY | reg::CSR_READ | (2 << 16) | 0x0130;
        let mut want = vec![0x02, 0x43, 0x04];
        want.extend_from_slice(&c.to_le_bytes());
        assert_eq!(l[0], want);
        assert_eq!(l[1][..3], [0x03, 0x43, 0x04]);
        assert_eq!(l[2][..3], [0x03, 0x43, 0x00]);
    }
    log.borrow_mut().clear();
    // Write the AL event mask: data + command in one burst, then one poll.
    d.csr_write(0x0204, &[0x11, 0x22, 0x33, 0x44]).unwrap();
    {
        let l = log.borrow();
        assert_eq!(l.len(), 2);
        let c: u32 = reg::CSR_BUSY | (4 << 16) | 0x0204;
        let mut want = vec![0x02, 0x43, 0x00, 0x11, 0x22, 0x33, 0x44];
        want.extend_from_slice(&c.to_le_bytes());
        assert_eq!(l[0], want);
    }
    let mut m = [0u8; 4];
    h.with_esc(|e| e.pdi_read(0x0204, &mut m)).unwrap();
    assert_eq!(m, [0x11, 0x22, 0x33, 0x44]);
    // Odd address and length split into 1/2/4-byte CSR commands.
    d.csr_write(0x0F81, &[1, 2, 3, 4, 5, 6, 7]).unwrap();
    let mut r = [0u8; 7];
    d.csr_read(0x0F81, &mut r).unwrap();
    assert_eq!(r, [1, 2, 3, 4, 5, 6, 7]);
    assert_eq!(h.stats().protocol_errors, 0);
}

#[test]
fn lan9252_pram_fifo_read_write() {
    let (mut d, h, log) = lan();
    // Unaligned start and length: the FIFO carries whole DWORDs.
    let data: Vec<u8> = (0..71u8).map(|i| i.wrapping_mul(37)).collect();
    d.pram_write(0x1203, &data).unwrap();
    {
        let l = log.borrow();
        let al: u32 = (71 << 16) | 0x1203;
        let mut want = vec![0x02, 0x43, 0x10];
        want.extend_from_slice(&al.to_le_bytes());
        want.extend_from_slice(&reg::PRAM_BUSY.to_le_bytes());
        assert_eq!(l[0], want);
        assert_eq!(l[1][..3], [0x03, 0x43, 0x14]);
        // 19 DWORDs (3 pad bytes first): 16 free -> bursts of 8 + 8 inside the FIFO's
        // 32-byte window, poll again, the last 3.
        assert_eq!(l[2][..3], [0x02, 0x40, 0x20]);
        assert_eq!(l[2].len(), 3 + 32);
        assert_eq!(l[2][3..6], [0, 0, 0]);
        assert_eq!(l[2][6], data[0]);
        assert_eq!(l[3].len(), 3 + 32);
        assert_eq!(l[4][..3], [0x03, 0x43, 0x14]);
        assert_eq!(l[5].len(), 3 + 12);
        assert_eq!(l.len(), 6);
    }
    let mut back = vec![0u8; 71];
    h.with_esc(|e| e.pdi_read(0x1203, &mut back)).unwrap();
    assert_eq!(back, data);
    log.borrow_mut().clear();
    let mut r = vec![0u8; 71];
    d.pram_read(0x1203, &mut r).unwrap();
    assert_eq!(r, data);
    {
        let l = log.borrow();
        assert_eq!(l[0][..3], [0x02, 0x43, 0x08]);
        assert_eq!(l[2][..3], [0x03, 0x40, 0x00]);
        assert_eq!(l.len(), 6);
    }
    // Through Pdi: a range straddling 0x1000 splits into CSR and PRAM.
    d.write(0x0FFE, &[9, 8, 7, 6]).unwrap();
    let mut s = [0u8; 4];
    d.read(0x0FFE, &mut s).unwrap();
    assert_eq!(s, [9, 8, 7, 6]);
    assert_eq!(h.stats().protocol_errors, 0);
}

#[test]
fn lan9252_al_event_and_irq_pin() {
    let h = Lan9252Model::handle(esc(EscConfig::lan9252()), BusConfig::mhz(20));
    let pins = Pins {
        irq: h.pin(PinKind::Irq),
        sync0: h.pin(PinKind::Sync0),
        sync1: h.pin(PinKind::Sync1),
        irq_active_low: true,
        sync_active_low: false,
    };
    let mut d = Lan9252::new(h.spi(), pins, Lan9252Config::default());
    d.init().unwrap();
    assert!(!d.irq_lines().pdi_irq);
    // Unmask AL control, have the master write AL control (event bit 0).
    d.write(0x0204, &1u32.to_le_bytes()).unwrap();
    let mut f = vec![0u8; 64];
    let n = {
        use oxicat_wire::frame::FrameBuilder;
        use oxicat_wire::{Command, DatagramHeader};
        let mut fb = FrameBuilder::new_bare(&mut f).unwrap();
        fb.push(
            DatagramHeader::physical(Command::Apwr, 0, 0, 0x0120, 2),
            &2u16.to_le_bytes(),
        )
        .unwrap();
        fb.finish()
    };
    f.truncate(n);
    h.with_esc(|e| e.forward(0, &mut f, 1000, true));
    let want = h.with_esc(|e| Esc::al_event_request(e));
    assert_ne!(want & 1, 0);
    assert_eq!(d.al_event_request(), Ok(want));
    assert!(d.irq_lines().pdi_irq);
    // Reading AL control clears the event and the pin.
    assert_eq!(d.read_u16(0x0120), Ok(2));
    assert!(!d.irq_lines().pdi_irq);
}

#[test]
fn lan9252_dead_chip_is_an_init_error() {
    for (fault, want) in [
        (Fault::MisoStuckHigh, Error::ByteTest(0xFFFF_FFFF)),
        (Fault::MisoStuckLow, Error::ByteTest(0)),
        (Fault::NeverReady, Error::Timeout),
    ] {
        let (mut d, h, _) = lan_with(Lan9252Config::default(), fault);
        assert_eq!(d.init(), Err(want), "{fault:?}");
        // Bounded: BYTE_TEST (+ HW_CFG) polled `retries` times, no more.
        assert!(h.stats().transactions <= 2 * 64);
    }
    let (mut d, h, _) = lan_with(Lan9252Config::default(), Fault::None);
    h.with(|m| m.id_rev = 0x9253_0000);
    assert_eq!(d.init(), Err(Error::ChipId(0x9253_0000)));
}

#[test]
fn lan9252_malformed_replies_are_errors() {
    let (mut d, h, _) = lan();
    h.set_fault(Fault::CsrStuckBusy);
    h.reset_stats();
    assert_eq!(d.read_u8(0x0130), Err(Error::Timeout));
    assert_eq!(h.stats().transactions, 1 + 64);
    assert_eq!(d.al_event_request(), Err(Error::Timeout));
    h.set_fault(Fault::PramNeverReady);
    let mut b = [0u8; 8];
    assert_eq!(d.read(0x1000, &mut b), Err(Error::Timeout));
    assert_eq!(d.write(0x1000, &b), Err(Error::Timeout));
    h.set_fault(Fault::PramBadCount);
    assert_eq!(d.read(0x1000, &mut b), Err(Error::Protocol));
    assert_eq!(d.write(0x1000, &b), Err(Error::Protocol));
    // Healthy again: the pending FIFO commands are aborted and access works.
    h.set_fault(Fault::None);
    d.write(0x1000, &[1, 2, 3, 4, 5, 6, 7, 8]).unwrap();
    d.read(0x1000, &mut b).unwrap();
    assert_eq!(b, [1, 2, 3, 4, 5, 6, 7, 8]);
    // Out of reach.
    assert_eq!(d.read(0xFFFE, &mut b), Err(Error::Address(0xFFFE)));
}

#[test]
fn lan9252_malformed_frames_answer_garbage() {
    let h = Lan9252Model::handle(esc(EscConfig::lan9252()), BusConfig::mhz(20));
    let mut spi = h.spi();
    // Unknown instruction: MISO stays high, the chip counts a protocol error.
    let mut b = [0x55u8, 0x40, 0x64, 0, 0, 0, 0];
    spi.transaction(&mut [Operation::TransferInPlace(&mut b)])
        .unwrap();
    assert_eq!(b[3..], [0xFF; 4]);
    // Too short, and a partial DWORD register write.
    let mut s = [0x03u8, 0x40];
    spi.transaction(&mut [Operation::TransferInPlace(&mut s)])
        .unwrap();
    spi.transaction(&mut [Operation::Write(&[0x02, 0x40, 0x54, 0x01])])
        .unwrap();
    assert_eq!(h.stats().protocol_errors, 3);
    // Reading the FIFO with nothing in it.
    let mut r = [0u8; 4];
    spi.transaction(&mut [
        Operation::Write(&[0x03, 0x00, 0x00]),
        Operation::Read(&mut r),
    ])
    .unwrap();
    assert_eq!(h.stats().protocol_errors, 7);
}

// ------------------------------------------------------------------ ET1100

fn et_with(
    cfg: Et1100Config,
    fault: Fault,
    esc_cfg: EscConfig,
) -> (
    Et1100Spi<Rec<SimSpi<Et1100Model>>, NoLines>,
    Handle<Et1100Model>,
    Log,
) {
    let h = Et1100Model::handle(esc(esc_cfg), BusConfig::mhz(20));
    h.set_fault(fault);
    let log = Log::default();
    let spi = Rec {
        inner: h.spi(),
        log: log.clone(),
    };
    (Et1100Spi::new(spi, NoLines, cfg), h, log)
}

fn et(
    cfg: Et1100Config,
) -> (
    Et1100Spi<Rec<SimSpi<Et1100Model>>, NoLines>,
    Handle<Et1100Model>,
    Log,
) {
    let (mut d, h, log) = et_with(cfg, Fault::None, EscConfig::et1100());
    assert_eq!(d.init(&mut h.pin(PinKind::EepromLoaded)), Ok(0x11));
    log.borrow_mut().clear();
    h.reset_stats();
    (d, h, log)
}

#[test]
fn et1100_address_phase_encoding() {
    assert_eq!(
        address_phase(0x0130, ecmd::READ_WS, false),
        ([0x09, 0x83, 0], 2)
    );
    assert_eq!(
        address_phase(0x0130, ecmd::WRITE, false),
        ([0x09, 0x84, 0], 2)
    );
    assert_eq!(
        address_phase(0x1FFF, ecmd::READ, false),
        ([0xFF, 0xFA, 0], 2)
    );
    assert_eq!(
        address_phase(0x0130, ecmd::READ_WS, true),
        ([0x09, 0x86, 0x0C], 3)
    );
    assert_eq!(
        address_phase(0xE001, ecmd::WRITE, true),
        ([0x00, 0x0E, 0xF0], 3)
    );
    assert_eq!(address_phase(0, ecmd::NOP, true), ([0, 0x06, 0], 3));
}

#[test]
fn et1100_read_write_frames() {
    let (mut d, h, log) = et(Et1100Config::default());
    let mut b = [0u8; 2];
    d.read(0x0130, &mut b).unwrap();
    assert_eq!(b, [1, 0]);
    d.write(0x1000, &[0xAA, 0xBB]).unwrap();
    let mut r = [0u8; 3];
    d.read(0x1000, &mut r).unwrap();
    assert_eq!(r[..2], [0xAA, 0xBB]);
    d.al_event_request().unwrap();
    let l = log.borrow();
    assert_eq!(l[0], [0x09, 0x83, 0xFF, 0x00, 0xFF]);
    assert_eq!(l[1], [0x80, 0x04, 0xAA, 0xBB]);
    assert_eq!(l[2], [0x80, 0x03, 0xFF, 0x00, 0x00, 0xFF]);
    assert_eq!(l[3], [0x00, 0x06, 0x00]);
    assert_eq!(h.stats().protocol_errors, 0);
    drop(l);
    // Three-byte mode and the read with a pause instead of a wait state.
    let (mut d, h, log) = et(Et1100Config {
        address_mode: AddressMode::ThreeByte,
        read_mode: ReadMode::Delay { ns: 240 },
        ..Default::default()
    });
    d.read(0x0130, &mut b).unwrap();
    assert_eq!(b, [1, 0]);
    d.write(0x1000, &[0x11]).unwrap();
    d.read(0x1000, &mut b[..1]).unwrap();
    assert_eq!(b[0], 0x11);
    let l = log.borrow();
    assert_eq!(l[0], [0x09, 0x86, 0x08, 0x00, 0xFF]);
    assert_eq!(l[1], [0x80, 0x06, 0x10, 0x11]);
    assert_eq!(h.stats().protocol_errors, 0);
    // Beyond 13 bits in two-byte mode the driver switches to three bytes; beyond the
    // ESC's memory the chip cannot answer.
    let (mut d, h, log) = et(Et1100Config::default());
    assert!(d.read(0xE000, &mut b).is_ok());
    assert_eq!(log.borrow()[0][..3], [0x00, 0x06, 0xEC]);
    assert_eq!(h.stats().protocol_errors, 1);
    assert_eq!(d.read(0xFFFF, &mut b), Err(Error::Address(0xFFFF)));
}

#[test]
fn et1100_al_event_in_the_address_phase() {
    let h = Et1100Model::handle(esc(EscConfig::et1100()), BusConfig::mhz(20));
    let pins = Pins {
        irq: h.pin(PinKind::Irq),
        sync0: h.pin(PinKind::Sync0),
        sync1: h.pin(PinKind::Sync1),
        irq_active_low: true,
        sync_active_low: false,
    };
    let mut d = Et1100Spi::new(h.spi(), pins, Et1100Config::default());
    d.init(&mut h.pin(PinKind::EepromLoaded)).unwrap();
    d.write(0x0204, &1u32.to_le_bytes()).unwrap();
    assert!(!d.irq_lines().pdi_irq);
    let mut f = vec![0u8; 64];
    let n = {
        use oxicat_wire::frame::FrameBuilder;
        use oxicat_wire::{Command, DatagramHeader};
        let mut fb = FrameBuilder::new_bare(&mut f).unwrap();
        fb.push(
            DatagramHeader::physical(Command::Apwr, 0, 0, 0x0120, 2),
            &2u16.to_le_bytes(),
        )
        .unwrap();
        fb.finish()
    };
    f.truncate(n);
    h.with_esc(|e| e.forward(0, &mut f, 1000, true));
    assert!(d.irq_lines().pdi_irq);
    let want = h.with_esc(|e| Esc::al_event_request(e));
    // Any access brings the event bits along; the NOP costs three bytes.
    let mut b = [0u8; 2];
    d.read(0x0130, &mut b).unwrap();
    assert_eq!(d.last_al_event(), want & 0xFFFF);
    h.reset_stats();
    assert_eq!(d.al_event_request(), Ok(want & 0xFF_FFFF));
    assert_eq!(h.stats().bytes, 3);
    // Reading AL control clears the event; its own address phase still showed it.
    assert_eq!(d.read_u16(0x0120), Ok(2));
    assert_eq!(d.last_al_event() & 1, 1);
    assert_eq!(d.al_event_request().map(|e| e & 1), Ok(0));
    assert!(!d.irq_lines().pdi_irq);
}

#[test]
fn et1100_dead_or_unconfigured_chip_is_an_init_error() {
    for (fault, want) in [
        (Fault::MisoStuckHigh, Error::EscType(0xFF)),
        (Fault::MisoStuckLow, Error::EscType(0)),
        (Fault::EepromNotLoaded, Error::EepromNotLoaded),
    ] {
        let (mut d, h, _) = et_with(Et1100Config::default(), fault, EscConfig::et1100());
        assert_eq!(
            d.init(&mut h.pin(PinKind::EepromLoaded)),
            Err(want),
            "{fault:?}"
        );
        assert!(h.stats().transactions <= 2);
    }
    // PDI control not SPI (an SII configuring the 16-bit asynchronous µC PDI).
    let mut e = eeprom(&DEF);
    oxicat_wire::sii::SiiConfig {
        pdi_control: 0x0008,
        ..Default::default()
    }
    .write(&mut e)
    .unwrap();
    let h = Et1100Model::handle(Esc::new(EscConfig::et1100(), e), BusConfig::mhz(20));
    let mut d = Et1100Spi::new(h.spi(), NoLines, Et1100Config::default());
    assert_eq!(
        d.init(&mut h.pin(PinKind::EepromLoaded)),
        Err(Error::PdiType(0x08))
    );
}

#[test]
fn et1100_malformed_frames() {
    let h = Et1100Model::handle(esc(EscConfig::et1100()), BusConfig::mhz(20));
    let mut spi = h.spi();
    let mut ex = |h: &Handle<Et1100Model>, ops: &mut [Operation<'_, u8>]| {
        let before = h.stats().protocol_errors;
        spi.transaction(ops).unwrap();
        h.stats().protocol_errors - before
    };
    // Read without termination byte: the ESC prefetches one byte too many.
    let mut d = [0x09u8, 0x83, 0xFF, 0x00, 0x00];
    assert_eq!(ex(&h, &mut [Operation::TransferInPlace(&mut d)]), 1);
    // Missing wait-state byte.
    let mut d = [0x09u8, 0x83, 0x00, 0xFF];
    assert_eq!(ex(&h, &mut [Operation::TransferInPlace(&mut d)]), 1);
    // Plain read without the pause: garbage.
    let mut d = [0x09u8, 0x82, 0x00, 0xFF];
    assert_eq!(ex(&h, &mut [Operation::TransferInPlace(&mut d)]), 1);
    assert_eq!(d[2..], [0xFF, 0xFF]);
    // Reserved command, truncated address phases.
    assert_eq!(ex(&h, &mut [Operation::Write(&[0x09, 0x85, 0x00])]), 1);
    assert_eq!(ex(&h, &mut [Operation::Write(&[0x09])]), 1);
    assert_eq!(ex(&h, &mut [Operation::Write(&[0x09, 0x86])]), 1);
    // A well-formed read.
    let mut d = [0x09u8, 0x83, 0xFF, 0x00, 0xFF];
    assert_eq!(ex(&h, &mut [Operation::TransferInPlace(&mut d)]), 0);
    assert_eq!(d[3..], [1, 0]);
}

#[test]
fn pins_follow_the_esc() {
    let h = Et1100Model::handle(esc(EscConfig::et1100()), BusConfig::mhz(20));
    let mut irq = h.pin(PinKind::Irq);
    use embedded_hal::digital::InputPin;
    assert_eq!(irq.is_high(), Ok(true), "SPI_IRQ idles high (active low)");
    assert_eq!(h.pin(PinKind::EepromLoaded).is_high(), Ok(true));
    h.set_fault(Fault::EepromNotLoaded);
    assert_eq!(h.pin(PinKind::EepromLoaded).is_low(), Ok(true));
    let _ = h.with(|m| m.pin(PinKind::Sync0));
}

/// The byte-clocked ET1100 (how an emulated MCU's SPI peripheral drives it, a byte per DR
/// write): a write reaches the ESC when CS rises, a read fetches each byte as it is shifted
/// out and stops at the termination 0xFF, a plain read needs its pause before the data phase —
/// the same chip as whole frames (`Model::frame` is this over a frame).
#[test]
fn et1100_byte_clocked_frames_match_the_frame_model() {
    use oxicat_pdi::sim::Et1100Frame;
    let h = Et1100Model::handle(esc(EscConfig::et1100()), BusConfig::mhz(20));
    let errors = |h: &Handle<Et1100Model>| h.stats().protocol_errors;
    // Write 0x1400..0x1402 = 1, 2, 3: two-byte address A[12:5], A[4:0] 100.
    let (a0, a1) = ((0x1400u16 >> 5) as u8, ((0x1400u16 & 0x1F) as u8) << 3);
    let mut f = Et1100Frame::default();
    h.with(|m| {
        for b in [a0, a1 | 0b100, 1, 2, 3] {
            m.clock_byte(&mut f, b, 0);
        }
    });
    let mut b = [0u8; 3];
    h.with_esc(|e| e.pdi_read(0x1400, &mut b)).unwrap();
    assert_eq!(b, [0, 0, 0], "not before CS rises");
    h.with(|m| m.end_frame(f));
    h.with_esc(|e| e.pdi_read(0x1400, &mut b)).unwrap();
    assert_eq!(b, [1, 2, 3]);
    // Read with wait state, byte by byte: the data as each byte goes out.
    let mut f = Et1100Frame::default();
    let miso: Vec<u8> = h.with(|m| {
        [a0, a1 | 0b011, 0xFF, 0x00, 0x00, 0xFF]
            .into_iter()
            .map(|b| m.clock_byte(&mut f, b, 0))
            .collect()
    });
    h.with(|m| m.end_frame(f));
    assert_eq!(miso[3..], [1, 2, 3]);
    assert_eq!(errors(&h), 0);
    // The same read as one frame gives the same bytes.
    let mut d = [a0, a1 | 0b011, 0xFF, 0x00, 0x00, 0xFF];
    h.spi()
        .transaction(&mut [Operation::TransferInPlace(&mut d)])
        .unwrap();
    assert_eq!(d[3..], [1, 2, 3]);
    // A plain read: the pause before the data phase decides.
    for (pause, ok) in [(240, true), (100, false)] {
        let mut f = Et1100Frame::default();
        let before = errors(&h);
        let miso: Vec<u8> = h.with(|m| {
            [(a0, 0), (a1 | 0b010, 0), (0x00, pause), (0xFF, 0)]
                .into_iter()
                .map(|(b, p)| m.clock_byte(&mut f, b, p))
                .collect()
        });
        h.with(|m| m.end_frame(f));
        if ok {
            assert_eq!((miso[2..].to_vec(), errors(&h) - before), (vec![1, 2], 0));
        } else {
            assert_eq!(
                (miso[2..].to_vec(), errors(&h) - before),
                (vec![0xFF, 0xFF], 1)
            );
        }
    }
}
