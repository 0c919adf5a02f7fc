//! The seam between a board image and the plant it drives: a [`BoardPlant`] runs on the
//! board's thread in lockstep with the CPU. Every `period_ns` of the board's clock it is
//! called with the board stopped at that instant: it reads the image's outputs (PWM duty,
//! pins), advances its physics over the coming period and schedules what its sensors do
//! during that period as [`Stimulus`](crate::Stimulus)es at their own times (an encoder
//! edge, a capture edge, an input level), which the board applies between instructions
//! when its clock gets there. The plant thus sees the outputs held over a period (as an
//! amplifier behind a PWM filter does) and the image sees every sensor event at its time.

use crate::{Board, EmuError};

/// A plant on a board's pins (see the module docs).
pub trait BoardPlant: Send {
    /// The plant step \[ns\] (> 0).
    fn period_ns(&self) -> u64;

    /// The board's clock is at `t_ns`: read the outputs, advance to `t_ns + period_ns()`,
    /// schedule the sensor events in between ([`Board::schedule`]).
    fn step(&mut self, board: &mut Board, t_ns: u64);
}

/// Runs `board` to `t_ns` with `plant` stepped at every multiple of its period on the way;
/// `next_step_ns` is the time of the plant's next step (starts at 0, kept by the caller).
pub fn run_with_plant(
    board: &mut Board,
    plant: &mut dyn BoardPlant,
    next_step_ns: &mut u64,
    t_ns: u64,
) -> Result<(), EmuError> {
    while *next_step_ns <= t_ns {
        board.run_to_ns(*next_step_ns)?;
        plant.step(board, *next_step_ns);
        *next_step_ns += plant.period_ns().max(1);
    }
    board.run_to_ns(t_ns)
}
