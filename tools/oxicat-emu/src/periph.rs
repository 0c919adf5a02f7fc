//! The STM32F446's peripheral bus as the image sees it: RCC, PWR, FLASH, GPIOA..H, SPI1
//! (wired to the board's ESC chip model, LAN9252 or ET1100), EXTI/SYSCFG, the timers, ADC1,
//! USART1..6 (`usart`), DMA1/2 (`dma`: streams on timer update requests),
//! and the Cortex-M4's System Control Space. One `Periph` is shared by the engine's MMIO callbacks and hooks and by
//! the board between engine runs.

use oxicat_pdi::sim::PinKind;

use crate::adc::{self, Adc};
use crate::chip::{ChipFrame, ChipKind, EscChip};

use crate::dma::{self, Dma, DmaBurst, Run, DMAS};
use crate::exti::{Exti, EXTI_BASE, SYSCFG_BASE};
use crate::flash::{self, Flash};
use crate::iwdg::{self, Iwdg, IWDG_BASE, WWDG_BASE};
use crate::nvic::{Masks, Scs, DWT_BASE};
use crate::timers::{Timer, TIMERS};
use crate::usart::{Usart, USARTS};
use crate::{SpiStats, Stimulus};

/// Peripheral space modelled (APB1, APB2, AHB1).
pub(crate) const PERIPH: (u64, u64) = (0x4000_0000, 0x8_0000);

pub(crate) const RCC: u64 = 0x4002_3800;
const RCC_CFGR: u64 = RCC + 0x08;
const RCC_DCKCFGR: u64 = RCC + 0x8C;
/// RCC_CSR: LSION/LSIRDY, RMVF and the reset flags.
pub(crate) const RCC_CSR: u64 = RCC + 0x74;
/// RCC_CSR reset flags (bits 25..31: BOR, PIN, POR, SFT, IWDG, WWDG, LPWR) and RMVF.
const CSR_FLAGS: u32 = 0xFE00_0000;
const CSR_RMVF: u32 = 1 << 24;
/// RCC_CSR.IWDGRSTF.
pub(crate) const CSR_IWDGRSTF: u32 = 1 << 29;
/// RCC_CSR.PINRSTF: set with every reset, as an internal reset drives NRST low.
pub(crate) const CSR_PINRSTF: u32 = 1 << 26;
const PWR: u64 = 0x4000_7000;
/// GPIOA; ports B..H follow every 0x400.
pub(crate) const GPIOA: u64 = 0x4002_0000;
/// Ports A..H.
pub(crate) const PORTS: u64 = 8;
pub(crate) const SPI1: u64 = 0x4001_3000;
/// SysTick's control and status register.
const SYST_CSR: u64 = 0xE000_E010;
/// Most cycles between two reads of SysTick's CSR that still make a spinning delay loop.
const POLL_WINDOW: u64 = 64;

/// Peripheral state of the STM32F446 board.
pub(crate) struct Periph {
    chip: EscChip,
    regs: Vec<u32>,
    pub scs: Scs,
    pub exti: Exti,
    pub timers: Vec<Timer>,
    frame: Option<ChipFrame>,
    /// Cycle at which the last SPI byte finished (the bus idles from then on).
    spi_idle_from: u64,
    /// SCLK replacing the image's prescaler setting (what-if studies) \[Hz\].
    pub spi_sclk_override: Option<u32>,
    spi_rx: u8,
    rxne: bool,
    pub spi: SpiStats,
    /// CPU cycles: the board's time base.
    pub cycles: u64,
    /// Instructions executed (estimated per block like `cycles`).
    pub insns: u64,
    /// Cycles spent asleep (WFI/WFE skipped forward).
    pub slept: u64,
    /// Cycles of a SysTick delay loop skipped forward (see [`Periph::scs_read`]).
    pub polled: u64,
    /// Register accesses so far (reads and writes of the peripherals and the SCS).
    mmio_seq: u64,
    /// The last read of SysTick's CSR that found COUNTFLAG clear: (access number, cycle).
    syst_poll: Option<(u64, u64)>,
    /// Input levels injected per port: (mask of driven pins, levels).
    pub inputs: [(u16, u16); PORTS as usize],
    /// The block hook stops the engine at this cycle (0: at the next block).
    pub wake_at: u64,
    /// The block hook stopped the engine.
    pub stopped: bool,
    /// A CPU exception the engine raised (`intno`), which stopped it.
    pub intr: Option<u32>,
    /// WFE/YIELD stopped the engine (true for WFE).
    pub wait_event: Option<bool>,
    /// While an exception is blocked only by these mask values, the block hook stops the
    /// engine when they change.
    pub watch: Option<Masks>,
    /// DBGMCU registers after IDCODE (CR, APB1_FZ, APB2_FZ), stored.
    pub dbgmcu: [u32; 4],
    /// Stimuli scheduled by a plant, by cycle (equal cycles in the order scheduled).
    pub stimuli: std::collections::VecDeque<(u64, Stimulus)>,
    /// Exception profile (handler times).
    pub profile: crate::stats::Profile,
    /// The thread's masked spans per priority level.
    pub masks: crate::stats::MaskTracker,
    /// ADC1.
    pub adc: Adc,
    /// Voltages on the ADC input channels (`None`: nothing drives the pin).
    pub analog: [Option<f64>; adc::CHANNELS],
    /// An access or configuration the models cannot serve: the image stops with it.
    pub fault: Option<String>,
    /// USART1..3, UART4/5, USART6.
    pub usarts: Vec<Usart>,
    /// The last read of a USART's SR that found RXNE and TXE as they were: (access number,
    /// cycle, address) — a polling loop, skipped forward like SysTick's.
    usart_poll: Option<(u64, u64, u64)>,
    /// DMA1, DMA2.
    pub dmas: Vec<Dma>,
    /// A stream just enabled whose items the engine fetches from memory: (DMA index,
    /// stream, address, items, item size).
    pub dma_fetch: Option<(usize, usize, u32, usize, usize)>,
    /// The independent watchdog.
    pub iwdg: Iwdg,
    /// The embedded flash's interface and the sectors after the image ([`flash`]).
    pub flash: Flash,
    /// System resets the IWDG caused, and the cycle of the last.
    pub watchdog_resets: u64,
    pub last_watchdog_reset: Option<u64>,
}

impl Periph {
    pub fn new(chip: EscChip) -> Self {
        let mut p = Periph {
            chip,
            adc: Adc::default(),
            analog: [None; adc::CHANNELS],
            fault: None,
            usarts: USARTS
                .iter()
                .map(|&(b, n, a)| Usart::new(b, n, a))
                .collect(),
            usart_poll: None,
            dmas: DMAS.iter().map(|&(b, n)| Dma::new(b, n)).collect(),
            dma_fetch: None,
            iwdg: Iwdg::default(),
            flash: Flash::new(flash::SIZE as u32, crate::CPU_HZ),
            watchdog_resets: 0,
            last_watchdog_reset: None,
            spi_idle_from: 0,
            spi_sclk_override: None,
            regs: vec![0; (PERIPH.1 / 4) as usize],
            scs: Scs::new(),
            exti: Exti::default(),
            timers: TIMERS.iter().map(|k| Timer::new(*k)).collect(),
            frame: None,
            spi_rx: 0xFF,
            rxne: false,
            spi: SpiStats::default(),
            cycles: 0,
            insns: 0,
            slept: 0,
            polled: 0,
            mmio_seq: 0,
            syst_poll: None,
            inputs: [(0, 0); PORTS as usize],
            wake_at: u64::MAX,
            stopped: false,
            intr: None,
            wait_event: None,
            watch: None,
            dbgmcu: [0; 4],
            stimuli: std::collections::VecDeque::new(),
            profile: crate::stats::Profile::default(),
            masks: crate::stats::MaskTracker::default(),
        };
        p.reset();
        p
    }

    pub fn reg(&self, addr: u64) -> u32 {
        self.regs[((addr - PERIPH.0) / 4) as usize]
    }

    fn set(&mut self, addr: u64, v: u32) {
        self.regs[((addr - PERIPH.0) / 4) as usize] = v;
    }

    /// Reset values the HAL relies on.
    fn reset(&mut self) {
        self.set(RCC, 0x0000_0083); // HSION, HSIRDY
        self.set(RCC + 0x04, 0x2400_3010); // PLLCFGR
        self.set(RCC_CSR, 0x0E00_0000); // CSR: reset flags (power-on: POR, PIN, BOR)
        self.set(PWR + 0x04, 1 << 14); // CSR: VOSRDY
        self.set(GPIOA, 0xA800_0000);
        self.set(GPIOA + 0x400, 0x0000_0280);
        self.set(SPI1 + 0x08, 0x0002); // SR: TXE
    }

    /// A system reset by the IWDG (RM0390 §6.1.2): every peripheral back to its reset
    /// values, RCC_CSR's flags kept with IWDGRSTF and PINRSTF added. What is not the MCU's
    /// stays: the ESC chip (a CS-low frame in flight ends, as CS goes high), the pins the
    /// board's world drives, scheduled stimuli, the 1-Wire lines, the board's clock and
    /// counters, DBGMCU (reset by power-on only) and the LSI frequency.
    pub fn watchdog_reset(&mut self) {
        let flags = self.reg(RCC_CSR) & CSR_FLAGS;
        if let Some(f) = self.frame.take() {
            self.chip.end(f);
        }
        let taken = self.scs.taken;
        let lines: Vec<_> = self.usarts.iter_mut().map(|u| u.line.take()).collect();
        self.regs.iter_mut().for_each(|r| *r = 0);
        self.reset();
        self.set(RCC_CSR, flags | CSR_IWDGRSTF | CSR_PINRSTF);
        self.scs = Scs::new();
        self.scs.taken = taken;
        self.exti = Exti::default();
        self.timers = TIMERS.iter().map(|k| Timer::new(*k)).collect();
        self.adc = Adc::default();
        self.usarts = USARTS
            .iter()
            .zip(lines)
            .map(|(&(b, n, a), line)| {
                let mut u = Usart::new(b, n, a);
                u.line = line;
                u
            })
            .collect();
        self.usart_poll = None;
        self.dmas = DMAS.iter().map(|&(b, n)| Dma::new(b, n)).collect();
        self.dma_fetch = None;
        self.iwdg.reset();
        self.flash.reset();
        self.spi_rx = 0xFF;
        self.rxne = false;
        self.spi_idle_from = self.cycles;
        self.syst_poll = None;
        self.watch = None;
        self.profile.abandon();
        self.wake_at = 0;
        self.watchdog_resets += 1;
        self.last_watchdog_reset = Some(self.cycles);
    }

    /// Cycles the core ran (not asleep): what DWT CYCCNT counts.
    pub fn active_cycles(&self) -> u64 {
        self.cycles - self.slept
    }

    fn pin(&self, kind: PinKind) -> bool {
        self.chip.pin(kind)
    }

    /// Port index (0 = A) of a GPIO register address, if it is one.
    fn port_of(addr: u64) -> Option<u64> {
        let rel = addr.checked_sub(GPIOA)?;
        (rel < PORTS * 0x400).then_some(rel / 0x400)
    }

    /// The level of pin `pin` of port `port` (0 = A): the ESC chip's pins (PA10 IRQ, PB3
    /// SYNC0, PB5 SYNC1; an ET1100's EEPROM_LOADED on PB4), then injected inputs, PC13 (the
    /// button, released), outputs at their ODR level, inputs with a pull-up high, else low.
    pub fn pin_level(&self, port: u8, pin: u32) -> bool {
        match (port, pin) {
            (0, 10) => return self.pin(PinKind::Irq),
            (1, 3) => return self.pin(PinKind::Sync0),
            (1, 5) => return self.pin(PinKind::Sync1),
            (1, 4) if self.chip.kind() == ChipKind::Et1100 => {
                return self.pin(PinKind::EepromLoaded)
            }
            _ => {}
        }
        let (mask, levels) = self
            .inputs
            .get(usize::from(port))
            .copied()
            .unwrap_or((0, 0));
        if mask & (1 << pin) != 0 {
            return levels & (1 << pin) != 0;
        }
        if (port, pin) == (2, 13) {
            return true;
        }
        let base = GPIOA + 0x400 * u64::from(port);
        let mode = (self.reg(base) >> (2 * pin)) & 3;
        let pull = (self.reg(base + 0x0C) >> (2 * pin)) & 3;
        if mode == 0 && pull == 1 {
            return true;
        }
        if mode == 0 && pull == 2 {
            return false;
        }
        self.reg(base + 0x14) & (1 << pin) != 0
    }

    fn gpio_idr(&self, port: u64) -> u32 {
        // The chip's pins cost a lock each: only ports A and B have them.
        (0..16).fold(0, |idr, pin| {
            idr | (u32::from(self.pin_level(port as u8, pin)) << pin)
        })
    }

    /// Samples the EXTI lines' pins; whether an interrupt line may have risen.
    pub fn sample_pins(&mut self) -> bool {
        if !self.exti.watching() {
            return false;
        }
        let mut exti = std::mem::take(&mut self.exti);
        let changed = exti.sample(self.cycles, |port, line| self.pin_level(port, line));
        self.exti = exti;
        changed
    }

    /// PB6 (CS) changed to `high`.
    fn chip_select(&mut self, high: bool) {
        match (high, self.frame.take()) {
            (false, None) => {
                self.frame = Some(self.chip.begin());
                self.spi.frames += 1;
                self.spi_idle_from = self.cycles;
            }
            (true, Some(f)) => {
                self.chip.end(f);
                // The chip's IRQ/SYNC pins may have changed with the frame.
                if self.sample_pins() {
                    self.wake_at = 0;
                }
            }
            (_, f) => self.frame = f,
        }
    }

    fn write_odr(&mut self, port: u64, odr: u32) {
        let base = GPIOA + 0x400 * port;
        let old = self.reg(base + 0x14);
        self.set(base + 0x14, odr & 0xFFFF);
        if port == 1 && (old ^ odr) & (1 << 6) != 0 {
            self.chip_select(odr & (1 << 6) != 0);
        }
        if self.exti.watching() && self.sample_pins() {
            self.wake_at = 0;
        }
    }

    fn spi_dr_write(&mut self, v: u8) {
        self.spi.bytes += 1;
        // The time the bus idled since the last byte (or CS falling) [ns].
        let pause_ns = u32::try_from(
            self.cycles.saturating_sub(self.spi_idle_from) * 1_000_000_000 / crate::CPU_HZ,
        )
        .unwrap_or(u32::MAX);
        self.spi_rx = match self.frame.as_mut() {
            Some(f) => self.chip.clock_byte(f, v, pause_ns),
            None => {
                self.spi.bytes_without_cs += 1;
                0xFF
            }
        };
        self.rxne = true;
        // The byte takes 8 SCLK periods at PCLK2 (90 MHz) / 2^(BR+1), or at the clock a
        // what-if study set ([`crate::Board::set_spi_sclk_hz`]).
        self.cycles += match self.spi_sclk_override {
            Some(hz) => (8 * crate::CPU_HZ).div_ceil(u64::from(hz.max(1))),
            None => 8 * 2 * (2u64 << ((self.reg(SPI1) >> 3) & 7)),
        };
        self.spi_idle_from = self.cycles;
    }

    /// CPU cycles per tick of the APB1 (or APB2) timer clock: TIMxCLK is PCLKx when the
    /// APB prescaler is 1, else 2 × PCLKx (4 × with DCKCFGR.TIMPRE, up to HCLK).
    fn timer_div(&self, apb2: bool) -> u64 {
        let cfgr = self.reg(RCC_CFGR);
        let ppre = if apb2 {
            (cfgr >> 13) & 7
        } else {
            (cfgr >> 10) & 7
        };
        let div: u64 = if ppre < 4 { 1 } else { 2 << (ppre - 4) };
        let mul = if self.reg(RCC_DCKCFGR) & (1 << 24) != 0 {
            4
        } else {
            2
        };
        (div / mul).max(1)
    }

    fn timer_index(addr: u64) -> Option<usize> {
        let base = addr & !0x3FF;
        if !(0x4000_0000..0x4000_2400).contains(&base)
            && !(0x4001_0000..0x4001_0800).contains(&base)
            && !(0x4001_4000..0x4001_4C00).contains(&base)
        {
            return None;
        }
        TIMERS.iter().position(|k| k.base == base)
    }

    /// The timer `number` (1 = TIM1), with its clock divider brought up to date.
    pub fn timer(&mut self, number: u8) -> Option<&mut Timer> {
        let apb1 = self.timer_div(false);
        let apb2 = self.timer_div(true);
        let t = self.timers.iter_mut().find(|t| t.kind.number == number)?;
        t.clk_div = if t.kind.apb2 { apb2 } else { apb1 };
        Some(t)
    }

    fn timer_at(&mut self, i: usize) -> &mut Timer {
        let div = self.timer_div(self.timers[i].kind.apb2);
        let t = &mut self.timers[i];
        if t.clk_div != div {
            // A new clock tree: the time so far counted at the old rate.
            t.clk_div = div;
        }
        t
    }

    /// Brings SysTick and the timers up to now.
    pub fn sync_all(&mut self) {
        let now = self.cycles;
        self.scs.syst_sync(now);
        for i in 0..self.timers.len() {
            self.timer_at(i).sync(now);
        }
        self.adc_sync(now);
        self.dma_sync();
        for i in 0..self.usarts.len() {
            let div = self.pclk_div(self.usarts[i].apb2);
            self.usarts[i].sync(now, div);
        }
    }

    /// CPU cycles per ADCCLK: PCLK2 / (2 · (ADC_CCR.ADCPRE + 1)).
    fn cycles_per_adcclk(&self) -> u64 {
        let ppre2 = (self.reg(RCC_CFGR) >> 13) & 7;
        let apb2: u64 = if ppre2 < 4 { 1 } else { 2 << (ppre2 - 4) };
        apb2 * 2 * (u64::from((self.adc.ccr >> 16) & 3) + 1)
    }

    /// The next rising edge of ADC1's injected trigger after cycle `after`, if it listens
    /// to one (an error: a trigger that is not modelled).
    fn adc_trigger_after(&self, after: u64) -> Result<Option<u64>, String> {
        match self.adc.trigger()? {
            adc::Trigger::Off => Ok(None),
            adc::Trigger::Tim1TrgoRising => {
                let Some(t) = self.timers.iter().find(|t| t.kind.number == 1) else {
                    return Ok(None);
                };
                if !t.counting() {
                    return Ok(None);
                }
                if !t.trgo_edges_modelled() {
                    return Err(format!(
                        "ADC1 is triggered by TIM1_TRGO, and TIM1 CR2.MMS = {:#05b} as \
                         TRGO is not modelled (only the update event, 010, and OC1REF..OC4REF \
                         in PWM mode 1/2)",
                        t.mms()
                    ));
                }
                Ok(t.next_trgo_rise(after))
            }
        }
    }

    /// Brings ADC1 up to `now`: the sequences its trigger started, the conversions that
    /// ended.
    fn adc_sync(&mut self, now: u64) {
        if let Some(t) = self.timer(1) {
            t.sync(now);
        }
        // Bounded: the board stops at every trigger (next_event), so few are due here.
        for _ in 0..10_000 {
            let next = match self.adc_trigger_after(self.adc.last) {
                Ok(n) => n,
                Err(e) => {
                    self.fault.get_or_insert(e);
                    None
                }
            };
            let Some(at) = next.filter(|&at| at <= now) else {
                break;
            };
            self.adc.finish_by(at);
            self.adc.last = at;
            let cyc = self.cycles_per_adcclk();
            if let Err(e) = self.adc.start(at, &self.analog, cyc) {
                self.fault.get_or_insert(e);
                break;
            }
        }
        self.adc.last = self.adc.last.max(now);
        self.adc.finish_by(now);
    }

    /// TIM1's EGR.UG with CR2.MMS = 010: the update event it generates pulses TRGO, which
    /// starts ADC1's injected sequence when it listens to TIM1_TRGO (RM0390 TIMx_CR2: "the
    /// update event is selected as trigger output").
    fn tim1_ug_trgo(&mut self, now: u64) {
        self.adc_sync(now);
        if self.adc.trigger() == Ok(adc::Trigger::Tim1TrgoRising) {
            let cyc = self.cycles_per_adcclk();
            if let Err(e) = self.adc.start(now, &self.analog, cyc) {
                self.fault.get_or_insert(e);
            }
            self.adc.last = self.adc.last.max(now);
            self.wake_at = 0;
        }
    }

    /// The interrupt lines the peripherals drive high.
    pub fn irq_lines(&self) -> u128 {
        let adc = if self.adc.irq() {
            crate::nvic::bit(16 + adc::IRQ)
        } else {
            0
        };
        let dma = self.dmas.iter().fold(0, |l, d| l | d.irq_lines());
        let dma = self.usarts.iter().fold(dma, |l, u| l | u.irq_lines());
        self.timers
            .iter()
            .fold(self.exti.irq_lines() | adc | dma, |l, t| l | t.irq_lines())
    }

    /// The cycle of the next timer or SysTick event that raises an interrupt, or of the
    /// next scheduled stimulus.
    pub fn next_event(&self) -> Option<u64> {
        self.timers
            .iter()
            .filter_map(|t| t.next_event())
            .chain(self.scs.syst_next())
            .chain(self.stimuli.front().map(|s| s.0))
            .chain(self.adc.busy_until())
            .chain(self.adc_trigger_after(self.adc.last).ok().flatten())
            .chain(self.dma_next_event())
            .chain(self.usarts.iter().filter_map(|u| u.next_event()))
            .chain(self.iwdg.expires())
            .min()
    }

    /// Schedules `s` at cycle `at` (after the stimuli already scheduled at that cycle).
    pub fn schedule(&mut self, at: u64, s: Stimulus) {
        let i = self.stimuli.partition_point(|(c, _)| *c <= at);
        self.stimuli.insert(i, (at, s));
    }

    /// Applies the stimuli due by now, in order.
    pub fn apply_due(&mut self) {
        while self.stimuli.front().is_some_and(|s| s.0 <= self.cycles) {
            let Some((_, s)) = self.stimuli.pop_front() else {
                break;
            };
            self.apply(s);
        }
    }

    /// Applies one stimulus now.
    pub fn apply(&mut self, s: Stimulus) {
        let now = self.cycles;
        match s {
            Stimulus::Encoder { tim, edges } => {
                if let Some(t) = self.timer(tim) {
                    t.sync(now);
                    t.set_encoder(edges);
                }
            }
            Stimulus::Capture { tim, input } => {
                self.capture(tim, input);
            }
            Stimulus::Analog { channel, volts } => {
                if let Some(a) = self.analog.get_mut(usize::from(channel)) {
                    *a = Some(volts);
                }
            }
            Stimulus::Input { port, pin, level } => {
                let p = (port.to_ascii_uppercase() as u32).wrapping_sub('A' as u32);
                if let Some((mask, levels)) = self.inputs.get_mut(p as usize) {
                    let b = 1u16 << (pin & 15);
                    *mask |= b;
                    *levels = if level { *levels | b } else { *levels & !b };
                }
            }
        }
    }

    /// An edge on timer `tim`'s input TI`input` now, with the TRGO pulses it causes routed
    /// to the linked timers; how many channels of `tim` captured.
    pub fn capture(&mut self, tim: u8, input: u8) -> usize {
        let now = self.cycles;
        let n = self.timer(tim).map_or(0, |t| t.capture(input, now));
        self.route_trgo();
        n
    }

    /// Delivers pending TRGO pulses to the timers whose SMCR.TS selects their source
    /// (bounded: a loop of links cannot spin).
    pub fn route_trgo(&mut self) {
        let now = self.cycles;
        for _ in 0..4 {
            let mut pulses: Vec<(u8, u32)> = Vec::new();
            for t in &mut self.timers {
                let n = t.take_trgo();
                if n > 0 {
                    pulses.push((t.kind.number, n));
                }
            }
            if pulses.is_empty() {
                return;
            }
            for i in 0..self.timers.len() {
                let Some(src) = self.timers[i].trigger_source() else {
                    continue;
                };
                for &(from, n) in &pulses {
                    if from == src {
                        for _ in 0..n {
                            self.timer_at(i).trigger(now);
                        }
                    }
                }
            }
        }
        for t in &mut self.timers {
            t.take_trgo();
        }
    }

    /// The word a sub-word write merges into.
    pub fn merge_base(&self, addr: u64) -> u32 {
        if (EXTI_BASE..EXTI_BASE + 0x18).contains(&addr) {
            return self.exti.merge_base(addr);
        }
        if Self::port_of(addr).is_some() && addr & 0x3FF == 0x18 {
            return 0; // BSRR
        }
        self.reg(addr)
    }

    pub fn read(&mut self, addr: u64) -> u32 {
        self.mmio_seq += 1;
        match addr {
            a if a == SPI1 + 0x08 => 0x0002 | u32::from(self.rxne),
            a if a == SPI1 + 0x0C => {
                self.rxne = false;
                u32::from(self.spi_rx)
            }
            a if (adc::ADC1..adc::ADC_END).contains(&a) => {
                let now = self.cycles;
                self.adc_sync(now);
                match self.adc.read((a - adc::ADC1) as usize) {
                    Ok(v) => v,
                    Err(e) => {
                        self.fault.get_or_insert(e);
                        self.wake_at = 0;
                        0
                    }
                }
            }
            a if Self::usart_index(a).is_some() => self.usart_read(a),
            a if Self::dma_index(a).is_some() => self.dma_read(a),
            a if (flash::REGS..flash::REGS + 0x400).contains(&a) => {
                self.flash.read(a - flash::REGS, self.cycles)
            }
            a if (IWDG_BASE..IWDG_BASE + 0x400).contains(&a) => {
                match self.iwdg.read(a - IWDG_BASE, self.cycles) {
                    Ok(v) => v,
                    Err(e) => {
                        self.fault.get_or_insert(e);
                        self.wake_at = 0;
                        0
                    }
                }
            }
            a if (WWDG_BASE..WWDG_BASE + 0x400).contains(&a) => {
                self.fault.get_or_insert(iwdg::wwdg_fault(a));
                self.wake_at = 0;
                0
            }
            // LSI is forced on while the IWDG runs.
            a if a == RCC_CSR && self.iwdg.running() => self.reg(a) | 2,
            a if (SYSCFG_BASE..EXTI_BASE + 0x400).contains(&a) => {
                if !(SYSCFG_BASE + 0x30..EXTI_BASE).contains(&a) {
                    self.exti.read(a)
                } else {
                    self.reg(a)
                }
            }
            a => {
                if let Some(port) = Self::port_of(a) {
                    if a & 0x3FF == 0x10 {
                        return self.gpio_idr(port);
                    }
                }
                if let Some(i) = Self::timer_index(a) {
                    let now = self.cycles;
                    return self.timer_at(i).read((a & 0x3FF) as usize, now);
                }
                self.reg(a)
            }
        }
    }

    pub fn write(&mut self, addr: u64, v: u32) {
        self.mmio_seq += 1;
        match addr {
            a if a == SPI1 + 0x0C => self.spi_dr_write(v as u8),
            a if a == SPI1 + 0x08 => {}
            a if (adc::ADC1..adc::ADC_END).contains(&a) => {
                let now = self.cycles;
                self.adc_sync(now);
                let before = self.adc.trigger();
                match self.adc.write((a - adc::ADC1) as usize, v) {
                    Ok(start) => {
                        if self.adc.trigger() != before {
                            // A new trigger source listens from now on.
                            self.adc.last = now;
                        }
                        if start {
                            let cyc = self.cycles_per_adcclk();
                            if let Err(e) = self.adc.start(now, &self.analog, cyc) {
                                self.fault.get_or_insert(e);
                            }
                        }
                        if self.adc.take_regular_request() {
                            let cyc = self.cycles_per_adcclk();
                            if let Err(e) = self.adc.start_regular(now, &self.analog, cyc) {
                                self.fault.get_or_insert(e);
                            }
                        }
                    }
                    Err(e) => {
                        self.fault.get_or_insert(e);
                    }
                }
                self.wake_at = 0;
            }
            a if Self::usart_index(a).is_some() => self.usart_write(a, v),
            a if Self::dma_index(a).is_some() => self.dma_write(a, v),
            a if (IWDG_BASE..IWDG_BASE + 0x400).contains(&a) => {
                if let Err(e) = self.iwdg.write(a - IWDG_BASE, v, self.cycles) {
                    self.fault.get_or_insert(e);
                }
                // A start or a reload may bring the expiry before the engine's next stop.
                self.wake_at = self.wake_at.min(self.iwdg.expires().unwrap_or(u64::MAX));
            }
            a if (WWDG_BASE..WWDG_BASE + 0x400).contains(&a) => {
                self.fault.get_or_insert(iwdg::wwdg_fault(a));
                self.wake_at = 0;
            }
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
            a if a == RCC_CFGR || a == RCC_DCKCFGR => {
                // The timers count at the old clock up to now.
                let now = self.cycles;
                for i in 0..self.timers.len() {
                    self.timer_at(i).sync(now);
                }
                let v = if a == RCC_CFGR {
                    (v & !0xC) | ((v & 3) << 2)
                } else {
                    v
                };
                self.set(a, v);
                self.wake_at = 0;
            }
            a if a == RCC + 0x70 => self.set(a, (v & !2) | ((v & 1) << 1)),
            a if a == RCC_CSR => {
                // LSIRDY follows LSION; the reset flags are read-only, RMVF clears them.
                let flags = if v & CSR_RMVF != 0 {
                    0
                } else {
                    self.reg(a) & CSR_FLAGS
                };
                self.set(a, flags | (v & 1) | ((v & 1) << 1));
            }
            a if a == PWR => {
                self.set(a, v);
                let csr = (self.reg(PWR + 4) & !(3 << 16)) | (v & (3 << 16));
                self.set(PWR + 4, csr | (1 << 14));
            }
            a if (flash::REGS..flash::REGS + 0x400).contains(&a) => {
                if a - flash::REGS == 0x10 {
                    self.flash_stall(); // CR is not writable while BSY: the bus waits
                }
                let now = self.cycles;
                if let Err(e) = self.flash.write(a - flash::REGS, v, now) {
                    self.fault.get_or_insert(e);
                    self.wake_at = 0;
                }
            }
            a if (SYSCFG_BASE..EXTI_BASE + 0x400).contains(&a) => {
                if !(SYSCFG_BASE + 0x30..EXTI_BASE).contains(&a) {
                    // Edges so far count under the old configuration; a newly unmasked
                    // line starts from its pin's present level.
                    self.sample_pins();
                    self.exti.write(a, v);
                    self.sample_pins();
                    self.wake_at = 0;
                } else {
                    self.set(a, v);
                }
            }
            a => {
                if let Some(port) = Self::port_of(a) {
                    match a & 0x3FF {
                        0x18 => {
                            let base = GPIOA + 0x400 * port;
                            let odr = (self.reg(base + 0x14) | (v & 0xFFFF)) & !(v >> 16);
                            return self.write_odr(port, odr);
                        }
                        0x14 => return self.write_odr(port, v),
                        0x10 => return, // IDR is read-only
                        _ => {}
                    }
                }
                if let Some(i) = Self::timer_index(a) {
                    let now = self.cycles;
                    let off = (a & 0x3FF) as usize;
                    let t = self.timer_at(i);
                    let ug_trgo = off == 0x14 && v & 1 != 0 && t.kind.number == 1 && t.mms() == 2;
                    t.write(off, v, now);
                    if off == 0x14 {
                        self.route_trgo(); // EGR.CC1G on a compare-pulse master
                    }
                    if ug_trgo {
                        self.tim1_ug_trgo(now);
                    }
                    // Compare registers change no event; anything else may.
                    if !(0x34..0x44).contains(&off) {
                        self.wake_at = 0;
                    }
                    return;
                }
                self.set(a, v);
            }
        }
    }

    /// Waits for a busy flash (RM0390 §3.5: an access while BSY stalls the bus): the
    /// clock moves to the end of the operation.
    pub fn flash_stall(&mut self) {
        let now = self.cycles;
        if let Some(end) = self.flash.stall_until(now) {
            self.flash.stalled += end - now;
            self.cycles = end;
        }
    }

    /// A CPU read of the flash sectors the model serves.
    pub fn flash_load(&mut self, addr: u64, size: usize) -> u64 {
        self.flash_stall();
        self.flash.load((addr - flash::BASE) as u32, size)
    }

    /// A CPU write to the flash sectors the model serves: programmed, or refused with an
    /// error flag (RM0390 §3.6.4).
    pub fn flash_store(&mut self, addr: u64, size: usize, v: u64) {
        self.flash_stall();
        let now = self.cycles;
        self.flash.store((addr - flash::BASE) as u32, size, v, now);
        self.wake_at = 0;
    }

    /// The U(S)ART whose register page holds `addr`.
    fn usart_index(addr: u64) -> Option<usize> {
        let base = addr & !0x3FF;
        USARTS.iter().position(|u| u.0 == base)
    }

    /// CPU cycles per PCLK of the bus (APB1 or APB2).
    fn pclk_div(&self, apb2: bool) -> u64 {
        let cfgr = self.reg(RCC_CFGR);
        let ppre = if apb2 {
            (cfgr >> 13) & 7
        } else {
            (cfgr >> 10) & 7
        };
        if ppre < 4 {
            1
        } else {
            2 << (ppre - 4)
        }
    }

    /// A U(S)ART register read; a poll of SR that finds nothing new, right after the same
    /// read, moves the clock to the end of the byte in flight (or the board's next stop),
    /// the time the loop would have spun.
    fn usart_read(&mut self, a: u64) -> u32 {
        let Some(i) = Self::usart_index(a) else {
            return 0;
        };
        let div = self.pclk_div(self.usarts[i].apb2);
        let now = self.cycles;
        if a & 0x3FF == 0 {
            let spinning = self.usart_poll.is_some_and(|(seq, at, addr)| {
                addr == a && seq + 1 == self.mmio_seq && now.saturating_sub(at) <= POLL_WINDOW
            });
            if spinning {
                if let Some(end) = self.usarts[i].busy_until() {
                    let to = end.min(self.wake_at).max(now);
                    self.polled += to - now;
                    self.cycles = to;
                }
            }
        }
        let now = self.cycles;
        match self.usarts[i].read(a & 0x3FF, now, div) {
            Ok(v) => {
                self.usart_poll = (a & 0x3FF == 0).then_some((self.mmio_seq, now, a));
                v
            }
            Err(e) => {
                self.fault.get_or_insert(e);
                self.wake_at = 0;
                0
            }
        }
    }

    fn usart_write(&mut self, a: u64, v: u32) {
        let Some(i) = Self::usart_index(a) else {
            return;
        };
        let div = self.pclk_div(self.usarts[i].apb2);
        let now = self.cycles;
        if let Err(e) = self.usarts[i].write(a & 0x3FF, v, now, div) {
            self.fault.get_or_insert(e);
            self.wake_at = 0;
        }
    }

    /// The DMA controller whose page holds `addr`.
    fn dma_index(addr: u64) -> Option<usize> {
        let base = addr & !0x3FF;
        DMAS.iter().position(|d| d.0 == base)
    }

    fn dma_read(&mut self, a: u64) -> u32 {
        self.dma_sync();
        let Some(i) = Self::dma_index(a) else {
            return 0;
        };
        match self.dmas[i].read(a & 0x3FF) {
            Ok(v) => v,
            Err(e) => {
                self.fault.get_or_insert(e);
                self.wake_at = 0;
                0
            }
        }
    }

    fn dma_write(&mut self, a: u64, v: u32) {
        self.dma_sync();
        let Some(i) = Self::dma_index(a) else {
            return;
        };
        match self.dmas[i].write(a & 0x3FF, v) {
            Ok(Some((s, addr, items, size))) => self.dma_fetch = Some((i, s, addr, items, size)),
            Ok(None) => {}
            Err(e) => {
                self.fault.get_or_insert(e);
            }
        }
        self.wake_at = 0;
    }

    /// The engine fetched `bytes` for the stream [`Periph::dma_fetch`] named: the stream
    /// runs from now, on its timer's update events.
    pub fn dma_loaded(&mut self, fetch: (usize, usize, u32, usize, usize), bytes: &[u8]) {
        let (di, si, _, _, size) = fetch;
        let now = self.cycles;
        let d = &self.dmas[di];
        let s = &d.streams[si];
        let n = s.ndtr as usize;
        let par = u64::from(s.par);
        let Some(tn) = d.request_timer(si) else {
            return;
        };
        let Some(ti) = self.timers.iter().position(|t| t.kind.number == tn) else {
            return;
        };
        let base = self.timers[ti].kind.base;
        if !(base..base + 0x400).contains(&par) || n == 0 {
            let e = format!(
                "DMA{} stream {si}: PAR {par:#010x} / NDTR {n}: not modelled (only transfers \
                 into the requesting TIM{tn}'s registers, {base:#010x}..)",
                d.number
            );
            self.fault.get_or_insert(e);
            self.wake_at = 0;
            return;
        }
        let mut values: Vec<u32> = bytes
            .chunks(size)
            .map(|c| c.iter().rev().fold(0u32, |v, b| (v << 8) | u32::from(*b)))
            .collect();
        if values.len() == 1 && n > 1 {
            values = vec![values[0]; n];
        }
        self.timer_at(ti).sync(now);
        let start_updates = self.timers[ti].updates;
        self.dmas[di].streams[si].run = Some(Run {
            tim: ti,
            off: (par - base) as usize,
            values,
            done: 0,
            start_updates,
            start: now,
        });
        self.wake_at = 0;
    }

    /// Brings the running streams up to now: an item per update event of their timer.
    fn dma_sync(&mut self) {
        let now = self.cycles;
        for di in 0..self.dmas.len() {
            for si in 0..8 {
                let Some(mut run) = self.dmas[di].streams[si].run.take() else {
                    continue;
                };
                let t = self.timer_at(run.tim);
                t.sync(now);
                let n = run.values.len();
                if !t.update_dma() {
                    // No requests while UDE is off.
                    run.start_updates = t.updates.saturating_sub(run.done as u64);
                }
                let avail = (t.updates - run.start_updates).min(n as u64) as usize;
                let tim_number = t.kind.number;
                for k in run.done..avail {
                    self.timer_at(run.tim).write(run.off, run.values[k], now);
                }
                let half = run.done < n / 2 && avail >= n / 2;
                run.done = avail;
                let dma = &mut self.dmas[di];
                dma.streams[si].ndtr = (n - avail) as u32;
                if half {
                    dma.flag(si, dma::HTIF);
                }
                if avail == n {
                    dma.flag(si, dma::TCIF);
                    dma.streams[si].cr &= !dma::CR_EN;
                    dma.bursts[si] = Some(DmaBurst {
                        dma: dma.number,
                        stream: si as u8,
                        tim: tim_number,
                        reg: run.off as u64,
                        values: run.values,
                        start: run.start,
                        end: now,
                    });
                } else {
                    dma.streams[si].run = Some(run);
                }
            }
        }
    }

    /// The cycle a running stream with an enabled interrupt raises it.
    fn dma_next_event(&self) -> Option<u64> {
        let mut next: Option<u64> = None;
        for d in &self.dmas {
            for s in &d.streams {
                let Some(run) = &s.run else { continue };
                if s.cr & (dma::CR_TCIE | dma::CR_HTIE) == 0 {
                    continue;
                }
                let t = &self.timers[run.tim];
                if !t.update_dma() {
                    continue;
                }
                let n = run.values.len();
                let left = if s.cr & dma::CR_HTIE != 0 && run.done < n / 2 {
                    n / 2 - run.done
                } else {
                    n - run.done
                };
                if let Some(c) = t.update_cycle(left as u64) {
                    next = Some(next.map_or(c, |x| x.min(c)));
                }
            }
        }
        next
    }

    /// The last finished DMA transfer into timer `tim`'s register at offset `reg`.
    pub fn dma_burst(&self, tim: u8, reg: u64) -> Option<&DmaBurst> {
        self.dmas
            .iter()
            .flat_map(|d| d.bursts.iter().flatten())
            .filter(|b| b.tim == tim && b.reg == reg)
            .max_by_key(|b| b.end)
    }

    /// A read of the SCS page or the DWT.
    ///
    /// Idle polling is skipped: a read of SysTick's CSR that finds COUNTFLAG clear, when
    /// the previous register access was the same read a few cycles before (a delay loop
    /// spinning on `has_wrapped`, as `cortex_m::delay` and the HALs' `SysDelay` do),
    /// moves the clock to SysTick's next wrap, or to the board's next stop if that comes
    /// first — the time the loop would have spun, without emulating its instructions.
    pub fn scs_read(&mut self, addr: u64) -> u32 {
        self.mmio_seq += 1;
        if (DWT_BASE..DWT_BASE + 0x1000).contains(&addr) {
            return self.scs.dwt_read(addr, self.active_cycles());
        }
        let now = self.cycles;
        let v = self.scs.read(addr, now);
        if addr == SYST_CSR {
            if v & (1 << 16) != 0 {
                self.syst_poll = None;
            } else {
                let spinning = self.syst_poll.is_some_and(|(seq, at)| {
                    seq + 1 == self.mmio_seq && now.saturating_sub(at) <= POLL_WINDOW
                });
                if spinning {
                    if let Some(wrap) = self.scs.syst_wrap_after(now) {
                        let to = wrap.min(self.wake_at).max(now);
                        self.polled += to - now;
                        self.cycles = to;
                    }
                }
                self.syst_poll = Some((self.mmio_seq, self.cycles));
            }
        }
        v
    }

    pub fn scs_merge_base(&self, addr: u64) -> u32 {
        if (DWT_BASE..DWT_BASE + 0x1000).contains(&addr) {
            return self.scs.dwt_read(addr, self.active_cycles());
        }
        self.scs.merge_base(addr)
    }

    pub fn scs_write(&mut self, addr: u64, v: u32) {
        self.mmio_seq += 1;
        let active = self.active_cycles();
        if (DWT_BASE..DWT_BASE + 0x1000).contains(&addr) {
            return self.scs.dwt_write(addr, v, active);
        }
        if self.scs.write(addr, v, self.cycles, active) {
            self.wake_at = 0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use oxicat_esc::{Esc, EscConfig};
    use oxicat_pdi::sim::{BusConfig, Lan9252Model};

    const TIM1: u64 = 0x4001_0000;

    fn periph() -> Periph {
        let chip = Lan9252Model::handle(
            Esc::new(EscConfig::lan9252(), vec![0; 128]),
            BusConfig::mhz(22),
        );
        Periph::new(chip.into())
    }

    /// ADC1: one injected channel (IN10, 3 cycles) on TIM1_TRGO rising edges.
    fn listen(p: &mut Periph) {
        p.analog[10] = Some(1.0);
        p.write(adc::ADC1 + 0x38, 10 << 15); // JSQR: JL = 0, JSQ4 = IN10
        p.write(adc::ADC1 + 0x08, 1 | (1 << 16) | (1 << 20)); // ADON, TIM1_TRGO, rising
    }

    #[test]
    fn tim1s_update_event_as_trgo_starts_adc1_at_ug_and_every_rcr_plus_one_half_periods() {
        let mut p = periph();
        p.write(TIM1 + 0x2C, 100); // ARR
        p.write(TIM1 + 0x30, 7); // RCR
        p.write(TIM1 + 0x04, 2 << 4); // CR2.MMS = update
        listen(&mut p);
        assert_eq!(p.adc.sequences, 0);
        p.write(TIM1 + 0x14, 1); // UG: an update event, a TRGO pulse
        assert_eq!(p.adc.sequences, 1, "UG's pulse");
        p.cycles = 1000;
        p.write(TIM1, 1 | (1 << 5)); // CEN, centre-aligned
                                     // 8 over/underflows of 100 ticks at the CPU clock: 1800, 2600, 3400.
        p.cycles = 1799;
        p.sync_all();
        assert_eq!(p.adc.sequences, 1);
        assert_eq!(p.next_event(), Some(1800));
        p.cycles = 3400;
        p.sync_all();
        assert_eq!(p.adc.sequences, 4);
        assert_eq!(p.fault, None);
    }

    #[test]
    fn a_tim1_master_mode_the_model_has_no_edges_for_stops_the_image_naming_it() {
        let mut p = periph();
        p.write(TIM1 + 0x2C, 100);
        p.write(TIM1 + 0x04, 1 << 4); // CR2.MMS = enable
        p.write(TIM1, 1);
        listen(&mut p);
        p.cycles = 500;
        p.sync_all();
        let f = p.fault.clone().expect("a fault");
        assert!(f.contains("MMS = 0b001"), "{f}");
    }
}
