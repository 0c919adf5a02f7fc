//! The exception, interrupt and timer models against small Thumb-2 programs
//! (`tests/asm/*.s`, assembled into the committed `*.elf` by `tests/asm/build.sh`): each
//! program has its own vector table and leaves its observations in SRAM from 0x2000_0000.

use oxicat_emu::{Board, EmuError};
use oxicat_esc::{Esc, EscConfig};
use oxicat_pdi::sim::{BusConfig, Lan9252Model};

fn board(elf: &[u8]) -> Board {
    let esc = Esc::new(EscConfig::lan9252(), vec![0; 128]);
    Board::new(elf, Lan9252Model::handle(esc, BusConfig::mhz(22))).expect("the program loads")
}

fn word(b: &Board, off: u32) -> u32 {
    let mut w = [0u8; 4];
    b.read_memory(0x2000_0000 + off, &mut w).unwrap();
    u32::from_le_bytes(w)
}

/// Runs until the program sets its done word (RAM + 0).
fn run_done(b: &mut Board) {
    let done = b
        .run_until(50, 2_000_000, |b| word(b, 0) == 1)
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(done, "the program did not finish: PC {:#010x}", b.pc());
}

#[test]
fn svc_enters_svcall_and_pendsv_tail_chains_with_the_thread_state_intact() {
    let mut b = board(include_bytes!("../asm/svc_pendsv.elf"));
    run_done(&mut b);
    assert_eq!((word(&b, 0x04), word(&b, 0x08)), (1, 1), "one of each");
    assert_eq!(word(&b, 0x0C), 11, "VECTACTIVE in SVCall");
    assert_eq!(word(&b, 0x10), 14, "VECTACTIVE in PendSV");
    assert_eq!(
        word(&b, 0x1C),
        0xFFFF_FFF9,
        "EXC_RETURN: thread, MSP, basic frame"
    );
    assert_eq!(
        word(&b, 0x14),
        0x2002_0000 - 32,
        "an 8-word frame below the stack top"
    );
    assert_eq!(
        word(&b, 0x18),
        word(&b, 0x14),
        "PendSV runs on the same frame"
    );
    assert_eq!(word(&b, 0x40), 1, "PendSV after SVCall");
    assert_ne!(word(&b, 0x20) & (1 << 11), 0, "RETTOBASE in PendSV");
    assert_eq!(word(&b, 0x3C), 1, "PendSV ran before the thread resumed");
    let regs: Vec<u32> = (0..5).map(|k| word(&b, 0x24 + 4 * k)).collect();
    assert_eq!(
        regs,
        [0x11, 0x22, 0x33, 0x44, 0x5555],
        "r0-r3, r12 unstacked"
    );
    assert_eq!(
        word(&b, 0x38) >> 28,
        0b0110,
        "Z and C back in the thread's APSR"
    );
    assert_eq!(b.exceptions_taken(11), 1);
    assert_eq!(b.exceptions_taken(14), 1);
    assert_eq!(b.active_exception(), 0, "back in thread mode");
}

#[test]
fn a_higher_priority_irq_preempts_and_basepri_and_primask_hold_irqs_back() {
    let mut b = board(include_bytes!("../asm/preempt.elf"));
    run_done(&mut b);
    let n = word(&b, 0x04);
    let log: Vec<u32> = (0..n).map(|k| word(&b, 0x08 + 4 * k)).collect();
    assert_eq!(
        log,
        [
            0x10, 0x20, 0x11, // IRQ0, preempted by IRQ1
            0x01, 0x02, // BASEPRI 0x80 holds IRQ0 (0x80) back ...
            0x10, 0x20, 0x11, // ... until cleared
            0x03, 0x04, // PRIMASK holds IRQ1 back ...
            0x20, // ... until cpsie
            0x05,
        ]
    );
    assert_eq!(word(&b, 0x64), 0b11, "IRQ0 and IRQ1 active while nested");
    assert_eq!(word(&b, 0x80) & (1 << 11), 0, "no RETTOBASE while nested");
    assert_eq!(word(&b, 0x80) & 0x1FF, 17, "VECTACTIVE = IRQ1");
    assert_eq!(word(&b, 0x6C), 0b10, "IRQ1 alone the third time");
    let taken = b.interrupts_taken();
    assert_eq!((taken[0], taken[1]), (2, 3));
}

#[test]
fn systick_interrupts_wake_wfi_and_sleep_skips_the_time_between() {
    let mut b = board(include_bytes!("../asm/systick_wfi.elf"));
    run_done(&mut b);
    assert_eq!(word(&b, 0x04), 10);
    assert_eq!(b.exceptions_taken(15), 10);
    let c = b.cycles();
    assert!(
        (10_000..10_200).contains(&c),
        "ten ticks of 1,000 cycles: {c}"
    );
    assert!(
        b.slept_cycles() > 8_000 && b.instructions() < 2_000,
        "asleep between ticks: slept {}, {} instructions",
        b.slept_cycles(),
        b.instructions()
    );
    // SysTick is off now: a sleeping board runs 1 s of time without executing.
    let i = b.instructions();
    b.run(180_000_000).unwrap();
    assert!(b.instructions() - i < 10);
    assert_eq!(word(&b, 0x04), 10);
}

#[test]
fn exti_lines_interrupt_on_their_selected_edge_of_an_injected_pin() {
    let mut b = board(include_bytes!("../asm/exti.elf"));
    b.set_input('C', 0, true);
    b.set_input('B', 12, false);
    b.run(2_000).unwrap();
    assert_eq!((word(&b, 0x04), word(&b, 0x08)), (0, 0));
    b.set_input('C', 0, false); // falling: selected
    b.run(1_000).unwrap();
    assert_eq!(word(&b, 0x04), 1);
    b.set_input('C', 0, true); // rising: not selected
    b.run(1_000).unwrap();
    assert_eq!(word(&b, 0x04), 1);
    b.set_input('B', 12, true); // rising on line 12
    b.run(1_000).unwrap();
    assert_eq!(word(&b, 0x08), 1);
    assert_eq!(word(&b, 0x0C), 1 << 12, "PR as the handler saw it");
    b.set_input('B', 12, false);
    b.set_input('C', 0, false);
    b.run(1_000).unwrap();
    assert_eq!((word(&b, 0x04), word(&b, 0x08)), (2, 1));
    let taken = b.interrupts_taken();
    assert_eq!((taken[6], taken[40]), (2, 1), "EXTI0, EXTI15_10");
}

#[test]
fn tim6_interrupts_at_each_update_of_its_90_mhz_clock_divided_by_psc_and_arr() {
    let mut b = board(include_bytes!("../asm/tim6.elf"));
    b.run(1_000).unwrap();
    let before = word(&b, 0x04);
    // 10 kHz: 18,000 cycles per update at 180 MHz.
    b.run(18_000 * 10).unwrap();
    assert_eq!(word(&b, 0x04) - before, 10);
    assert_eq!(b.interrupts_taken()[54], u64::from(word(&b, 0x04)));
    for k in 1..=word(&b, 0x04).min(16) {
        let cnt = word(&b, 0x40 + 4 * k);
        assert!(
            cnt < 5,
            "entry {k} read CNT {cnt}: the update had just happened"
        );
    }
    assert!(b.instructions() < 2_000, "asleep between updates");
}

#[test]
fn tim1_oc4ref_as_trgo_starts_adc1s_injected_sequence_once_per_pwm_period() {
    let mut b = board(include_bytes!("../asm/adc.elf"));
    b.set_analog(10, 1.65);
    b.set_analog(11, 0.33);
    b.run(2_000).unwrap();
    let before = word(&b, 0x04);
    // 20 kHz: 9,000 cycles per centre-aligned period of 2 × 4500 ticks at 180 MHz.
    b.run(9_000 * 20).unwrap();
    assert_eq!(word(&b, 0x04) - before, 20, "one sequence per PWM period");
    assert_eq!(b.interrupts_taken()[18], u64::from(word(&b, 0x04)));
    assert_eq!(b.adc_sequences(), u64::from(word(&b, 0x04)));
    // OC4REF rises counting up through 4332, 168 ticks before the top; the sequence takes
    // 2 × (15 + 12) ADCCLK at 8 cycles each = 432 cycles: JEOC counting down at 4500 −
    // (432 − 168) = 4236; the handler reads CNT after the 12-cycle entry and its block's
    // instructions (cycles are counted per block as it starts: about 30 here).
    let cnt = word(&b, 0x08);
    assert!(
        (4_236 - 60..=4_236).contains(&cnt),
        "CNT {cnt} on entry: just after JEOC"
    );
    assert_ne!(word(&b, 0x0C) & (1 << 4), 0, "counting down");
    assert_eq!(word(&b, 0x10), 2048, "1.65 V on IN10: mid-scale");
    assert_eq!(word(&b, 0x14), 409, "0.33 V on IN11");
    assert_eq!(word(&b, 0x18) & 0x04, 0, "JEOC cleared (rc_w0)");
    assert_ne!(word(&b, 0x18) & 0x08, 0, "JSTRT kept");
    assert!(b.instructions() < 2_000, "asleep between the conversions");
}

#[test]
fn converting_a_channel_nothing_drives_is_a_fault_naming_it() {
    let mut b = board(include_bytes!("../asm/adc.elf"));
    b.set_analog(11, 0.0);
    let e = b.run(9_000 * 2).unwrap_err();
    let EmuError::Fault { reason, .. } = e else {
        panic!("{e:?}")
    };
    assert!(reason.contains("IN10 (PC0)"), "{reason}");
}

#[test]
fn dwt_cyccnt_counts_cycles_only_with_trcena_and_cyccntena() {
    let mut b = board(include_bytes!("../asm/dwt.elf"));
    run_done(&mut b);
    assert_eq!(
        (word(&b, 0x04), word(&b, 0x08)),
        (0, 0),
        "no TRCENA: no count"
    );
    let d = word(&b, 0x10).wrapping_sub(word(&b, 0x0C));
    assert!(
        (2_000..2_030).contains(&d),
        "1,000 passes of two instructions: {d}"
    );
}

#[test]
fn timers_give_pwm_duty_encoder_counts_and_input_captures() {
    let mut b = board(include_bytes!("../asm/timers.elf"));
    run_done(&mut b);
    assert_eq!(b.pwm_duty(1, 1), Some(0.25));
    assert_eq!(b.pwm_duty(1, 2), None, "CH2 not enabled");
    b.set_encoder(2, 123_456);
    b.set_encoder(3, 1_005);
    b.run(200).unwrap();
    assert_eq!((word(&b, 0x04), word(&b, 0x08)), (123_456, 5));
    b.set_encoder(2, -1);
    b.run(200).unwrap();
    assert_eq!(word(&b, 0x04), u32::MAX, "wrapped below zero");
    assert_eq!(b.timer_count(2), Some(u32::MAX));
    let cnt = b.timer_count(4).unwrap();
    assert_eq!(b.capture(4, 1), 1);
    assert_eq!(b.capture(4, 2), 0, "nothing on TI2");
    b.run(200).unwrap();
    assert_eq!(word(&b, 0x10), 1, "one capture interrupt");
    assert_eq!(word(&b, 0x0C), cnt, "CCR1 latched CNT at the edge");
    assert_eq!(word(&b, 0x14) & 2, 0, "reading CCR1 cleared CC1IF");
    assert_eq!(b.interrupts_taken()[30], 1);
}

#[test]
fn an_isr_using_s0_leaves_the_threads_live_fp_registers_intact() {
    let mut b = board(include_bytes!("../asm/fp.elf"));
    run_done(&mut b);
    assert_eq!(word(&b, 0x04), 2);
    assert_eq!(word(&b, 0x08), 0xFFFF_FFF9, "no FP context: basic frame");
    assert_eq!(word(&b, 0x0C), 0xFFFF_FFE9, "FP context: extended frame");
    assert_eq!(word(&b, 0x10), 0x3FC0_0000, "S0 = 1.5 again");
    assert_eq!(word(&b, 0x14), 0x4049_0FDB, "S15 = pi again");
    assert_eq!(word(&b, 0x18), 0x0300_0000, "FPSCR again");
    assert_eq!(word(&b, 0x1C) & 4, 4, "CONTROL.FPCA back on in the thread");
    assert_eq!(
        word(&b, 0x20) & 4,
        0,
        "no FP context on entry to the handler"
    );
}

#[test]
fn an_fp_instruction_with_cpacr_off_is_a_nocp_fault() {
    let mut b = board(include_bytes!("../asm/nocp.elf"));
    match b.run(1_000) {
        Err(EmuError::Fault { pc, reason }) => {
            assert!(reason.contains("NOCP"), "{reason}");
            assert!((0x0800_0140..0x0800_0160).contains(&pc), "{pc:#x}");
        }
        other => panic!("expected a NOCP fault, got {other:?}"),
    }
}

/// Unbounded recursion runs the main stack off the bottom of SRAM: a fault that names the
/// stack overflow, with the PC in the recursing function, not a hang or a bare
/// "WRITE_UNMAPPED".
#[test]
fn unbounded_recursion_is_a_stack_overflow_fault_with_its_pc() {
    let mut b = board(include_bytes!("../asm/overflow.elf"));
    assert_eq!(
        b.stack_limit(),
        0x2000_0000,
        "a bare program's stack may use all SRAM"
    );
    match b.run(10_000_000) {
        Err(EmuError::Fault { pc, reason }) => {
            assert!(reason.contains("stack overflow"), "{reason}");
            assert!(reason.contains("0x20000000"), "{reason}");
            // reset (0x0800_0140) calls recurse right after it.
            assert!((0x0800_0140..0x0800_0170).contains(&pc), "{pc:#x}");
        }
        other => panic!("expected a stack-overflow fault, got {other:?}"),
    }
}

/// The committed ELF files are what the sources assemble to (checked where the tools are).
#[test]
fn the_test_programs_match_their_sources() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/asm");
    if std::process::Command::new("llvm-mc")
        .arg("--version")
        .output()
        .is_err()
    {
        eprintln!("skipped: no llvm-mc");
        return;
    }
    let tmp = std::env::temp_dir().join(format!("oxicat-emu-asm-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    for e in std::fs::read_dir(&dir).unwrap() {
        let p = e.unwrap().path();
        if p.extension()
            .is_some_and(|x| x == "s" || x == "inc" || x == "ld" || x == "sh")
        {
            std::fs::copy(&p, tmp.join(p.file_name().unwrap())).unwrap();
        }
    }
    let ok = std::process::Command::new("sh")
        .arg(tmp.join("build.sh"))
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        eprintln!("skipped: the assembler or linker is missing");
        return;
    }
    for e in std::fs::read_dir(&tmp).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "elf") {
            let committed = std::fs::read(dir.join(p.file_name().unwrap())).unwrap();
            assert!(
                std::fs::read(&p).unwrap() == committed,
                "{} is stale: run tests/asm/build.sh",
                p.display()
            );
        }
    }
    let _ = std::fs::remove_dir_all(&tmp);
}

#[test]
fn dma_feeds_a_timer_compare_register_one_item_per_update_and_raises_transfer_complete() {
    let mut b = board(include_bytes!("../asm/dma.elf"));
    // 8 updates of 1 µs (180 cycles each), then well past.
    b.run(180 * 30).unwrap();
    assert_eq!(word(&b, 0x04), 1, "one transfer-complete interrupt");
    let at_tc = word(&b, 0x08);
    assert!(
        (7..=8).contains(&at_tc),
        "TC after the 8th update request: {at_tc} updates counted by then"
    );
    assert_eq!(word(&b, 0x0C), 0, "NDTR at TC");
    assert_eq!(word(&b, 0x10) & 1, 0, "EN cleared at the end");
    let lisr = word(&b, 0x14);
    assert_ne!(lisr & (1 << 21), 0, "TCIF2: {lisr:#010x}");
    assert_ne!(lisr & (1 << 20), 0, "HTIF2: {lisr:#010x}");
    let burst = b
        .dma_burst(3, 0x38)
        .expect("a finished transfer into TIM3 CCR2");
    assert_eq!((burst.dma, burst.stream), (1, 2));
    assert_eq!(burst.values, [10, 20, 30, 40, 50, 60, 70, 0]);
    assert_eq!(b.pwm_duty(3, 2), Some(0.0), "the last item stays in CCR2");
    // No more transfers: the stream is off.
    let n = word(&b, 0x18);
    b.run(180 * 20).unwrap();
    assert!(word(&b, 0x18) > n, "the timer runs on");
    assert_eq!(word(&b, 0x04), 1);
}

/// The IWDG starved (`iwdg_starve.s`: PR /4, RLR 79, i.e. 80 ticks of 125 µs at the
/// nominal 32 kHz LSI = 10 ms): the MCU is reset the configured time after the last
/// reload, restarts from its vector table with SRAM intact, and RCC_CSR tells it why.
#[test]
fn a_starved_iwdg_resets_the_mcu_after_its_timeout_with_iwdgrstf_set() {
    let mut b = board(include_bytes!("../asm/iwdg_starve.elf"));
    assert_eq!(b.lsi_hz(), 32_000, "the nominal LSI");
    let fed = b
        .run_until(20, 1_000_000, |b| word(b, 0x20) == 1)
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(fed, "the program did not start its IWDG");
    let fed_ns = b.time_ns();
    let reset = b
        .run_until(1_000, 5_000_000, |b| b.watchdog_resets() == 1)
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(reset, "no reset in 5 M cycles: PC {:#010x}", b.pc());
    let after = b.time_ns() - fed_ns;
    assert!(
        (10_000_000..10_100_000).contains(&after),
        "reset {after} ns after the reload, not 10 ms"
    );
    run_done(&mut b);
    assert_eq!(
        word(&b, 0x04),
        2,
        "booted twice, SRAM kept across the reset"
    );
    assert_eq!(
        word(&b, 0x08),
        0x0E00_0000,
        "power-on: PORRSTF, PINRSTF, BORRSTF"
    );
    assert_eq!(word(&b, 0x10), 0, "RMVF cleared them");
    assert_eq!(
        word(&b, 0x0C),
        (1 << 29) | (1 << 26),
        "after the watchdog: IWDGRSTF (and PINRSTF, NRST driven low)"
    );
    assert_eq!(word(&b, 0x14), 0);
    // The reset stopped the IWDG: the second boot sleeps on without another.
    b.run_to_ns(b.time_ns() + 50_000_000).unwrap();
    assert_eq!(b.watchdog_resets(), 1);
    assert_eq!(word(&b, 0x04), 2);
}

/// The same IWDG reloaded every 1 ms from SysTick: no reset in 100 ms; and a slower LSI
/// (17 kHz, the datasheet's minimum) only stretches a starved one's timeout.
#[test]
fn a_fed_iwdg_never_resets_and_the_lsi_frequency_sets_the_timeout() {
    let mut b = board(include_bytes!("../asm/iwdg_feed.elf"));
    b.run_to_ns(100_000_000).unwrap();
    assert_eq!(b.watchdog_resets(), 0);
    assert_eq!(word(&b, 0x04), 1, "one boot");
    assert!(
        word(&b, 0x08) >= 99,
        "fed every ms: {} ticks",
        word(&b, 0x08)
    );

    let mut b = board(include_bytes!("../asm/iwdg_starve.elf"));
    b.set_lsi_hz(17_000);
    b.run_until(20, 1_000_000, |b| word(b, 0x20) == 1).unwrap();
    let fed_ns = b.time_ns();
    b.run_until(1_000, 10_000_000, |b| b.watchdog_resets() == 1)
        .unwrap();
    let after = b.time_ns() - fed_ns;
    // 320 LSI periods at 17 kHz: 18.8 ms.
    assert!(
        (18_820_000..18_900_000).contains(&after),
        "reset {after} ns after the reload"
    );
}

/// The window watchdog is not modelled: an image that touches it stops, naming the
/// register, instead of running on a watchdog that never fires.
#[test]
fn the_window_watchdog_is_a_fault_naming_its_register() {
    // The starve program with its first IWDG key write moved to WWDG_CR (0x4000_2C00).
    let mut elf = include_bytes!("../asm/iwdg_starve.elf").to_vec();
    let key = 0x4000_3000u32.to_le_bytes();
    let at = elf
        .windows(4)
        .position(|w| w == key)
        .expect("IWDG_KR in the literal pool");
    elf[at..at + 4].copy_from_slice(&0x4000_2C00u32.to_le_bytes());
    let mut b = board(&elf);
    match b.run(100_000) {
        Err(EmuError::Fault { reason, .. }) => {
            assert!(reason.contains("WWDG_CR (0x40002c00)"), "{reason}")
        }
        other => panic!("expected a fault, got {other:?}"),
    }
}
