//! Whatever sits behind an ESC's PDI (firmware, later) and receives its events at their
//! virtual times.

/// An event an ESC delivers to the PDI side.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EscEvent {
    /// SYNC0 rising edge.
    Sync0,
    /// SYNC1 rising edge.
    Sync1,
    /// The PDI interrupt line went active (AL event request & mask became non-zero).
    Irq,
    /// The process-data watchdog expired.
    PdWatchdog,
    /// The PDI watchdog expired.
    PdiWatchdog,
}

/// The PDI-side party attached to one ESC (firmware, a plant probe, a test hook).
///
/// `E` is the ESC type, [`oxicat_esc::Esc`] unless a test uses a stand-in.
pub trait Node<E = oxicat_esc::Esc>: Send {
    /// `ev` happened on `esc` at virtual time `t` (ns); the node may access the ESC's PDI side.
    fn on_event(&mut self, esc: &mut E, ev: EscEvent, t: u64);

    /// Virtual time (ns) at which the node wants to run on its own (firmware timers, the main
    /// loop), independent of ESC events; `None` (the default) for never. After
    /// [`on_wakeup`](Self::on_wakeup) at `t` the segment only honours a later time.
    fn next_wakeup(&self) -> Option<u64> {
        None
    }

    /// Virtual time reached the time [`next_wakeup`](Self::next_wakeup) asked for.
    fn on_wakeup(&mut self, _esc: &mut E, _t: u64) {}
}

impl<E, F> Node<E> for F
where
    F: FnMut(&mut E, EscEvent, u64) + Send,
{
    fn on_event(&mut self, esc: &mut E, ev: EscEvent, t: u64) {
        self(esc, ev, t)
    }
}

/// A board shared between its segment node and the outside (tests, tools): one mutex, a
/// poisoned lock still gives the board (a panicking test must not hide its state).
pub struct Shared<T>(std::sync::Arc<std::sync::Mutex<T>>);

impl<T> Shared<T> {
    /// Shares `board`.
    pub fn new(board: T) -> Self {
        Self(std::sync::Arc::new(std::sync::Mutex::new(board)))
    }

    /// Locks the board (do not hold it while the segment runs).
    pub fn lock(&self) -> std::sync::MutexGuard<'_, T> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Whether this is the board's last handle (no other can be made from nothing, so
    /// it stays the last).
    pub(crate) fn is_last(&self) -> bool {
        std::sync::Arc::strong_count(&self.0) == 1
    }

    /// The board itself if this is its last handle, else the handle back.
    pub(crate) fn into_last(self) -> Result<T, Self> {
        std::sync::Arc::try_unwrap(self.0)
            .map(|m| m.into_inner().unwrap_or_else(|e| e.into_inner()))
            .map_err(Self)
    }
}

impl<T> Clone for Shared<T> {
    fn clone(&self) -> Self {
        Self(self.0.clone())
    }
}
