//! Exception entry and return on the engine (ARMv7-M ARM B1.5.6–B1.5.8).
//!
//! Unicorn has no NVIC, and its CPU never leaves thread mode here: IPSR stays 0 inside
//! the engine (so `mrs rX, ipsr` reads 0 — ICSR.VECTACTIVE has the real number), and the
//! board keeps the exception state (`nvic::Scs`). Entry pushes the frame in memory, moves
//! to the main stack (CONTROL.SPSEL = 0 in the engine), clears CONTROL.FPCA and the IT
//! bits, loads LR with EXC_RETURN and PC with the vector. A handler's return — `bx lr`,
//! `pop {pc}`, `ldr pc, …` loading 0xFFFFFFFx — is a plain branch to the System region to
//! the engine, whose fetch there faults (execute-never): the board recognises that fault
//! in handler mode as the exception return, tail-chains into a pending exception that
//! preempts the level being returned to, or pops the frame. QEMU's cached TB flags are
//! refreshed after the mode bits change (an APSR write), so the next block is translated
//! for the new state.

use unicorn_engine::RegisterARM;

use crate::nvic::{bit, Masks, NMI};
use crate::{Board, EmuError, FLASH, SRAM};

/// Cycles of exception entry (12 on the Cortex-M4 with zero-wait-state memory), of a
/// tail-chain (6) and of a return (10).
const ENTRY_CYCLES: u64 = 12;
const TAIL_CYCLES: u64 = 6;
const RETURN_CYCLES: u64 = 10;

/// IT bits of xPSR (and of the engine's CPSR: the same positions).
const IT_BITS: u32 = 0x0600_FC00;
/// APSR flags N Z C V Q and GE[3:0].
const APSR_BITS: u32 = 0xF80F_0000;

const CONTROL_SPSEL: u64 = 2;
const CONTROL_FPCA: u64 = 4;

fn fault(pc: u32, reason: impl Into<String>) -> EmuError {
    EmuError::Fault {
        pc,
        reason: reason.into(),
    }
}

impl Board {
    fn reg(&self, r: RegisterARM) -> Result<u32, EmuError> {
        self.uc
            .reg_read(r)
            .map(|v| v as u32)
            .map_err(|e| fault(self.pc, format!("register read: {e:?}")))
    }

    fn set_reg(&mut self, r: impl Into<i32>, v: u32) -> Result<(), EmuError> {
        let pc = self.pc;
        self.uc
            .reg_write(r, u64::from(v))
            .map_err(|e| fault(pc, format!("register write: {e:?}")))
    }

    /// The core after a system reset (ARMv7-M TakeReset): thread mode on the main stack,
    /// PRIMASK/BASEPRI/FAULTMASK clear, no FP context, flags and IT state clear, LR
    /// 0xFFFF_FFFF; SP and PC from the vector table at the start of flash (the boot memory;
    /// SYSCFG's remap is back at its reset value). R0..R12 keep what they held (UNKNOWN).
    pub(crate) fn reset_core(&mut self) -> Result<(), EmuError> {
        self.set_control(0)?;
        for r in [
            RegisterARM::PRIMASK,
            RegisterARM::BASEPRI,
            RegisterARM::FAULTMASK,
            RegisterARM::FPSCR,
        ] {
            self.set_reg(r, 0)?;
        }
        let cpsr = self.reg(RegisterARM::CPSR)?;
        self.set_reg(RegisterARM::CPSR, cpsr & !IT_BITS)?;
        self.set_reg(RegisterARM::APSR_NZCV, 0)?;
        let mut vt = [0u32; 2];
        self.read_words(FLASH.0 as u32, &mut vt)?;
        self.set_reg(RegisterARM::SP, vt[0] & !3)?;
        self.set_reg(RegisterARM::LR, 0xFFFF_FFFF)?;
        self.pc = vt[1];
        Ok(())
    }

    /// PRIMASK, BASEPRI, FAULTMASK as the core has them.
    pub(crate) fn masks(&self) -> Result<Masks, EmuError> {
        Ok(Masks {
            primask: self.reg(RegisterARM::PRIMASK)?,
            basepri: self.reg(RegisterARM::BASEPRI)?,
            faultmask: self.reg(RegisterARM::FAULTMASK)?,
        })
    }

    /// Writes CONTROL and has QEMU rebuild its cached mode flags (an APSR write does).
    fn set_control(&mut self, v: u32) -> Result<(), EmuError> {
        self.set_reg(RegisterARM::CONTROL, v)?;
        let nzcv = self.reg(RegisterARM::APSR_NZCV)?;
        self.set_reg(RegisterARM::APSR_NZCV, nzcv)
    }

    fn read_words(&self, addr: u32, out: &mut [u32]) -> Result<(), EmuError> {
        let mut b = vec![0u8; out.len() * 4];
        self.uc
            .mem_read(u64::from(addr), &mut b)
            .map_err(|e| fault(self.pc, format!("unstacking at {addr:#010x}: {e:?}")))?;
        for (w, c) in out.iter_mut().zip(b.chunks_exact(4)) {
            *w = u32::from_le_bytes([c[0], c[1], c[2], c[3]]);
        }
        Ok(())
    }

    /// The handler address of exception `e` from the vector table at VTOR.
    fn vector(&self, e: u16) -> Result<u32, EmuError> {
        let (vtor, remap) = {
            let p = self.periph.borrow();
            (p.scs.vtor(), p.exti.read(crate::exti::SYSCFG_BASE) & 3)
        };
        let mut at = vtor.wrapping_add(4 * u32::from(e));
        // 0x0000_0000 aliases the boot memory (SYSCFG_MEMRMP.MEM_MODE): main flash, or
        // SRAM1 in mode 3 (the system-memory boot loader is not modelled: flash).
        if u64::from(at) < FLASH.1 {
            at += if remap == 3 { SRAM.0 } else { FLASH.0 } as u32;
        }
        let mut w = [0u32];
        self.read_words(at, &mut w)
            .map_err(|_| fault(self.pc, format!("vector {e} at {at:#010x} is unreadable")))?;
        if w[0] & 1 == 0 {
            return Err(fault(
                self.pc,
                format!(
                    "exception {e}: vector {:#010x} is not a Thumb address (INVSTATE)",
                    w[0]
                ),
            ));
        }
        Ok(w[0])
    }

    /// Takes exception `e` now: stacks the state at the current PC (the return address)
    /// and branches to its handler.
    pub(crate) fn enter(&mut self, e: u16) -> Result<(), EmuError> {
        let vector = self.vector(e)?;
        let control = self.reg(RegisterARM::CONTROL)?;
        let ipsr = self.periph.borrow().scs.ipsr;
        let thread = ipsr == 0;
        if thread && control & 1 != 0 {
            return Err(fault(
                self.pc,
                "unprivileged thread mode (CONTROL.nPRIV) is not modelled",
            ));
        }
        let fpca = u64::from(control) & CONTROL_FPCA != 0;
        let psp = thread && u64::from(control) & CONTROL_SPSEL != 0;
        // PushStack: 8 words, or 26 with the FP context (eager: the Cortex-M4 would defer
        // S0-S15/FPSCR with FPCCR.LSPEN, with the same result for the handler and the
        // interrupted code); the frame 8-byte aligned (CCR.STKALIGN), the padding noted in
        // the stacked xPSR bit 9.
        let sp = self.reg(RegisterARM::SP)?;
        let size: u32 = if fpca { 0x68 } else { 0x20 };
        let pad = sp & 4;
        let frame = sp.wrapping_sub(size) & !4;
        let cpsr = self.reg(RegisterARM::CPSR)?;
        let xpsr = (cpsr & (APSR_BITS | IT_BITS)) | (1 << 24) | (pad << 7) | u32::from(ipsr);
        let mut words = vec![
            self.reg(RegisterARM::R0)?,
            self.reg(RegisterARM::R1)?,
            self.reg(RegisterARM::R2)?,
            self.reg(RegisterARM::R3)?,
            self.reg(RegisterARM::R12)?,
            self.reg(RegisterARM::LR)?,
            self.pc & !1,
            xpsr,
        ];
        if fpca {
            for k in 0..16 {
                words.push(self.reg_s(k)?);
            }
            words.push(self.reg(RegisterARM::FPSCR)?);
            words.push(0);
        }
        let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
        let pc = self.pc;
        self.uc.mem_write(u64::from(frame), &bytes).map_err(|err| {
            fault(
                pc,
                format!("stacking exception {e} at {frame:#010x} failed: {err:?}"),
            )
        })?;
        self.set_reg(RegisterARM::SP, frame)?;
        let mut exc_return: u32 = match (thread, psp) {
            (false, _) => 0xFFFF_FFF1,
            (true, false) => 0xFFFF_FFF9,
            (true, true) => 0xFFFF_FFFD,
        };
        if fpca {
            exc_return &= !0x10;
        }
        // Handler mode runs on MSP with no FP context of its own yet.
        self.set_control(control & !((CONTROL_SPSEL | CONTROL_FPCA) as u32))?;
        self.set_reg(RegisterARM::CPSR, cpsr & !IT_BITS)?;
        self.set_reg(RegisterARM::LR, exc_return)?;
        {
            let mut p = self.periph.borrow_mut();
            let now = p.cycles;
            p.profile.enter(e, now);
        }
        self.branch_to_handler(e, vector, ENTRY_CYCLES);
        Ok(())
    }

    fn reg_s(&self, k: i32) -> Result<u32, EmuError> {
        self.uc
            .reg_read(RegisterARM::S0 as i32 + k)
            .map(|v| v as u32)
            .map_err(|e| fault(self.pc, format!("register read: {e:?}")))
    }

    fn branch_to_handler(&mut self, e: u16, vector: u32, cycles: u64) {
        let mut p = self.periph.borrow_mut();
        p.scs.activate(e);
        p.cycles += cycles;
        if e == 16 + crate::adc::IRQ {
            let now = p.cycles;
            p.adc.handler_entered(now);
        }
        self.pc = vector & !1;
        self.event = true;
    }

    /// The engine branched to `target` in the System region (0xFFFFFFE0..): in handler
    /// mode, an exception return with EXC_RETURN = `target | 1`.
    pub(crate) fn exception_return(&mut self, target: u32) -> Result<(), EmuError> {
        let exc_return = target | 1;
        let ipsr = self.periph.borrow().scs.ipsr;
        if ipsr == 0 {
            return Err(fault(
                target,
                "instruction fetch from the execute-never System region in thread mode",
            ));
        }
        let (to_thread, psp) = match exc_return & 0xF {
            0x1 => (false, false),
            0x9 => (true, false),
            0xD => (true, true),
            _ => {
                return Err(fault(
                    target,
                    format!("invalid EXC_RETURN {exc_return:#010x} (INVPC)"),
                ))
            }
        };
        let extended = exc_return & 0x10 == 0;
        // Deactivate; FAULTMASK clears on return from anything but NMI.
        {
            let mut p = self.periph.borrow_mut();
            p.scs.active &= !bit(ipsr);
        }
        if ipsr != NMI {
            self.set_reg(RegisterARM::FAULTMASK, 0)?;
        }
        // Tail-chain: a pending exception that preempts the level being returned to runs
        // on the same frame.
        let masks = self.masks()?;
        let chain = {
            let mut p = self.periph.borrow_mut();
            p.sync_all();
            p.sample_pins();
            let lines = p.irq_lines();
            p.scs.assert_lines(lines);
            p.scs.takeable(masks)
        };
        if let Some(e) = chain {
            let vector = self.vector(e)?;
            let control = self.reg(RegisterARM::CONTROL)?;
            self.set_control(control & !(CONTROL_FPCA as u32))?;
            self.set_reg(RegisterARM::LR, exc_return)?;
            {
                let mut p = self.periph.borrow_mut();
                let now = p.cycles;
                p.profile.leave(now);
                p.profile.enter(e, now);
            }
            self.branch_to_handler(e, vector, TAIL_CYCLES);
            return Ok(());
        }
        // PopStack from the stack EXC_RETURN names.
        let control = self.reg(RegisterARM::CONTROL)?;
        if to_thread && psp {
            // The engine is in thread mode: SPSEL = 1 banks MSP and makes SP the PSP.
            self.set_control(control | CONTROL_SPSEL as u32)?;
        }
        let frame = self.reg(RegisterARM::SP)?;
        let mut w = [0u32; 26];
        let n = if extended { 26 } else { 8 };
        self.read_words(frame, &mut w[..n])?;
        let xpsr = w[7];
        let stacked_ipsr = (xpsr & 0x1FF) as u16;
        if to_thread != (stacked_ipsr == 0) || usize::from(stacked_ipsr) >= crate::nvic::NUM_EXC {
            return Err(fault(
                target,
                format!(
                    "EXC_RETURN {exc_return:#010x} returns to {} but the stacked IPSR is {stacked_ipsr} (INVPC)",
                    if to_thread { "thread mode" } else { "handler mode" }
                ),
            ));
        }
        for (r, v) in [
            RegisterARM::R0,
            RegisterARM::R1,
            RegisterARM::R2,
            RegisterARM::R3,
            RegisterARM::R12,
            RegisterARM::LR,
        ]
        .into_iter()
        .zip(w)
        {
            self.set_reg(r, v)?;
        }
        if extended {
            for k in 0..16 {
                self.set_reg(RegisterARM::S0 as i32 + k, w[8 + k as usize])?;
            }
            self.set_reg(RegisterARM::FPSCR, w[24])?;
        }
        let size: u32 = if extended { 0x68 } else { 0x20 };
        let sp = frame
            .wrapping_add(size)
            .wrapping_add(if xpsr & (1 << 9) != 0 { 4 } else { 0 });
        self.set_reg(RegisterARM::SP, sp)?;
        let control = self.reg(RegisterARM::CONTROL)?;
        let control = if extended {
            control | CONTROL_FPCA as u32
        } else {
            control & !(CONTROL_FPCA as u32)
        };
        self.set_control(control)?;
        let cpsr = self.reg(RegisterARM::CPSR)?;
        let cpsr = (cpsr & !(APSR_BITS | IT_BITS)) | (xpsr & (APSR_BITS | IT_BITS));
        self.set_reg(RegisterARM::CPSR, cpsr)?;
        self.pc = w[6] & !1;
        self.fpca = extended;
        self.event = true;
        let sleep = {
            let mut p = self.periph.borrow_mut();
            p.scs.ipsr = stacked_ipsr;
            p.cycles += RETURN_CYCLES;
            let now = p.cycles;
            p.profile.leave(now);
            to_thread && p.scs.sleep_on_exit()
        };
        if sleep {
            self.sleeping = true;
        }
        Ok(())
    }
}
