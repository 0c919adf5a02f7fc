//! `circbuffer.c` (Listing 4.10): the FRF mode's two 100-entry int16 ring buffers.

/// Entries of each buffer (`RX_BUFFER_SIZE`, `TX_BUFFER_SIZE`).
pub const RING: usize = 100;

/// A ring buffer of `i16` with the manual's overflow rule: a write into a full buffer
/// empties it and sets the overflow flag (data are lost, the counter restarts at 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ring {
    buf: [i16; RING],
    head: usize,
    count: usize,
    /// A write found the buffer full (`rx_buffer_overflow`).
    pub overflow: bool,
}

impl Default for Ring {
    fn default() -> Self {
        Self::new()
    }
}

impl Ring {
    /// An empty buffer.
    pub const fn new() -> Self {
        Self {
            buf: [0; RING],
            head: 0,
            count: 0,
            overflow: false,
        }
    }

    /// Entries queued (`rx_counter` / `tx_counter`).
    pub fn len(&self) -> usize {
        self.count
    }

    /// True when nothing is queued.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Free entries (`rxfree`).
    pub fn free(&self) -> usize {
        RING - self.count
    }

    /// Appends `v`.
    pub fn write(&mut self, v: i16) {
        if self.count >= RING {
            self.count = 0;
            self.overflow = true;
        }
        self.buf[(self.head + self.count) % RING] = v;
        self.count += 1;
    }

    /// Takes the oldest entry (the slot is zeroed as in `rx_buffer_read`).
    pub fn read(&mut self) -> Option<i16> {
        if self.count == 0 {
            return None;
        }
        let v = core::mem::take(&mut self.buf[self.head]);
        self.head = (self.head + 1) % RING;
        self.count -= 1;
        Some(v)
    }

    /// Empties the buffer and clears the overflow flag.
    pub fn clear(&mut self) {
        *self = Self::new();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fifo_and_overflow() {
        let mut r = Ring::new();
        for k in 0..RING as i16 {
            r.write(k);
        }
        assert_eq!(r.free(), 0);
        assert_eq!(r.read(), Some(0));
        r.write(100);
        assert!(!r.overflow);
        r.write(101);
        assert!(r.overflow);
        assert_eq!(r.len(), 1);
        assert_eq!(r.read(), Some(101));
        assert_eq!(r.read(), None);
    }
}
