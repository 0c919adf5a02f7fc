//! The motor amplifier outputs and the LEDs of the leg-node board.

use oxicat_devices::demo::Leds;
use oxicat_devices::laelaps::{Joint, PwmCommand, PwmOut};
use stm32f4xx_hal::{
    gpio::{Output, Pin},
    pac,
    timer::{PwmChannel, PwmHzManager},
};

/// Two amplifier inputs: TIM1 CH1 (PA8) + DIR PC10 for the knee, TIM1 CH2 (PA9) + DIR PC11
/// for the hip; edge-aligned PWM at 20 kHz, active high, duty from the PIV output.
pub struct BoardPwm {
    /// Keeps TIM1 running (its period; the channels hold the compare registers).
    pub timer: PwmHzManager<pac::TIM1>,
    pub knee: PwmChannel<pac::TIM1, 0>,
    pub hip: PwmChannel<pac::TIM1, 1>,
    pub knee_dir: Pin<'C', 10, Output>,
    pub hip_dir: Pin<'C', 11, Output>,
}

impl PwmOut for BoardPwm {
    fn set(&mut self, joint: Joint, cmd: PwmCommand) {
        let max = self.timer.get_max_duty();
        // NaN reads as 0 (`as` saturates and maps NaN to 0).
        let duty = (cmd.duty.clamp(0.0, 1.0) * f32::from(max) + 0.5) as u16;
        let duty = duty.min(max);
        // DIRx = 1 for u < 0 (the thesis' DIR GPIOs). The new compare value is preloaded
        // and takes effect at the next PWM period; the direction pin at once.
        match joint {
            Joint::Knee => {
                self.knee_dir.set_state(cmd.reverse.into());
                self.knee.set_duty(duty);
            }
            Joint::Hip => {
                self.hip_dir.set_state(cmd.reverse.into());
                self.hip.set_duty(duty);
            }
        }
    }
}

/// Motor outputs off from any context (panic, fault): TIM1 main output disabled and both
/// compares zeroed. AOE is cleared first, or the next update event would set MOE again.
pub fn pwm_emergency_off() {
    // SAFETY: single register writes that only ever stop the outputs; racing with the
    // owner of TIM1 can at worst leave them stopped.
    let tim1 = unsafe { &*pac::TIM1::ptr() };
    tim1.bdtr()
        .modify(|_, w| w.aoe().clear_bit().moe().clear_bit());
    tim1.ccr1().write(|w| unsafe { w.bits(0) });
    tim1.ccr2().write(|w| unsafe { w.bits(0) });
}

/// LaunchPad-style LEDs on PC8 (blue) and PC9 (red), active high.
pub struct BoardLeds {
    pub blue: Pin<'C', 8, Output>,
    pub red: Pin<'C', 9, Output>,
}

impl Leds for BoardLeds {
    fn set(&mut self, blue: bool, red: bool) {
        self.blue.set_state(blue.into());
        self.red.set_state(red.into());
    }
}
