//! The segment's event queue: every slot's next ESC event and next node wakeup, ordered
//! by (time, ESC event before wakeup, slot), kept up to date entry by entry.
//!
//! An indexed binary heap: each slot has at most one entry per kind, found through its
//! position, so a changed time is a sift up or down (O(log n)) and an unchanged one costs a
//! comparison. There are no stale entries and the heap never holds more than two entries
//! per slot, however often the times move (a firmware's PDI watchdog deadline moves at every
//! main-loop pass).

/// No position: the entry is not in the heap.
const NONE: u32 = u32::MAX;

/// The kind of an entry; at equal times ESC events come before wakeups.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Kind {
    /// The ESC's next event (SYNC edge, watchdog expiry).
    Esc = 0,
    /// The node's next wakeup.
    Wake = 1,
}

/// Pending events of a segment's slots, earliest first.
#[derive(Debug, Default)]
pub(crate) struct EventQueue {
    /// Entry ids (`slot * 2 + kind`) in heap order.
    heap: Vec<u32>,
    /// Position in `heap` of each entry id, or [`NONE`].
    pos: Vec<u32>,
    /// Time of each entry id (meaningful while it is in the heap).
    time: Vec<u64>,
}

impl EventQueue {
    /// Room for slot `slots - 1` (no entries yet).
    pub(crate) fn grow_to(&mut self, slots: usize) {
        self.pos.resize(2 * slots, NONE);
        self.time.resize(2 * slots, 0);
    }

    /// The ordering key of entry `id`: time, then kind, then slot.
    #[inline]
    fn key(&self, id: u32) -> (u64, u32, u32) {
        (self.time[id as usize], id & 1, id >> 1)
    }

    #[inline]
    fn less(&self, a: u32, b: u32) -> bool {
        self.key(a) < self.key(b)
    }

    /// Sets (`Some`) or removes (`None`) the entry of `kind` of `slot`.
    #[inline]
    pub(crate) fn set(&mut self, slot: usize, kind: Kind, t: Option<u64>) {
        let id = (slot * 2 + kind as usize) as u32;
        let p = self.pos[id as usize];
        match t {
            None if p == NONE => {}
            None => self.remove_at(p as usize),
            Some(t) if p == NONE => {
                self.time[id as usize] = t;
                self.heap.push(id);
                self.pos[id as usize] = (self.heap.len() - 1) as u32;
                self.sift_up(self.heap.len() - 1);
            }
            Some(t) => {
                let old = self.time[id as usize];
                if t == old {
                    return;
                }
                self.time[id as usize] = t;
                if t < old {
                    self.sift_up(p as usize);
                } else {
                    self.sift_down(p as usize);
                }
            }
        }
    }

    /// The earliest entry: `(time, slot, kind)`.
    #[inline]
    pub(crate) fn peek(&self) -> Option<(u64, usize, Kind)> {
        let &id = self.heap.first()?;
        let kind = if id & 1 == 0 { Kind::Esc } else { Kind::Wake };
        Some((self.time[id as usize], (id >> 1) as usize, kind))
    }

    fn place(&mut self, i: usize, id: u32) {
        self.heap[i] = id;
        self.pos[id as usize] = i as u32;
    }

    fn remove_at(&mut self, i: usize) {
        let id = self.heap[i];
        self.pos[id as usize] = NONE;
        let last = self.heap.pop().unwrap_or(id);
        if i < self.heap.len() {
            self.place(i, last);
            if i > 0 && self.less(last, self.heap[(i - 1) / 2]) {
                self.sift_up(i);
            } else {
                self.sift_down(i);
            }
        }
    }

    fn sift_up(&mut self, mut i: usize) {
        let id = self.heap[i];
        while i > 0 {
            let parent = (i - 1) / 2;
            let p = self.heap[parent];
            if !self.less(id, p) {
                break;
            }
            self.place(i, p);
            i = parent;
        }
        self.place(i, id);
    }

    fn sift_down(&mut self, mut i: usize) {
        let id = self.heap[i];
        let n = self.heap.len();
        loop {
            let l = 2 * i + 1;
            if l >= n {
                break;
            }
            let r = l + 1;
            let c = if r < n && self.less(self.heap[r], self.heap[l]) {
                r
            } else {
                l
            };
            if !self.less(self.heap[c], id) {
                break;
            }
            self.place(i, self.heap[c]);
            i = c;
        }
        self.place(i, id);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Random sets and removals against a sorted reference: the queue's first entry is
    /// always the reference's least (time, kind, slot).
    #[test]
    fn always_yields_the_least_key() {
        let slots = 37;
        let mut q = EventQueue::default();
        q.grow_to(slots);
        let mut reference = vec![[None::<u64>; 2]; slots];
        let mut x: u64 = 0x2545_F491_4F6C_DD1D;
        let mut rnd = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        for step in 0..20_000 {
            let s = (rnd() % slots as u64) as usize;
            let k = if rnd() % 2 == 0 {
                Kind::Esc
            } else {
                Kind::Wake
            };
            // Few distinct times, so ties between kinds and slots are common.
            let t = (rnd() % 5 != 0).then(|| rnd() % 40);
            q.set(s, k, t);
            reference[s][k as usize] = t;
            let least = reference
                .iter()
                .enumerate()
                .flat_map(|(s, e)| {
                    [(e[0], 0u32), (e[1], 1)]
                        .into_iter()
                        .filter_map(move |(t, k)| t.map(|t| (t, k, s as u32)))
                })
                .min();
            let got = q.peek().map(|(t, s, k)| (t, k as u32, s as u32));
            assert_eq!(got, least, "step {step}");
            let live = reference.iter().flatten().flatten().count();
            assert_eq!(q.heap.len(), live, "one entry per (slot, kind)");
        }
    }
}
