//! The segment's event queue: every slot's next ESC event and next node wakeup, ordered
//! by (time, ESC event before wakeup, slot), kept up to date entry by entry.
//!
//! An indexed binary heap: each slot has at most one entry per kind, found through its
//! position, so a changed time is a sift up or down (O(log n)) and an unchanged one costs a
//! comparison, and the heap never holds more than two entries per slot however often the
//! times move. [`EventQueue::lower`] lets the segment leave an entry earlier than its time
//! (checked when it comes first), so a time that only moves later (a firmware's PDI
//! watchdog deadline, at every main-loop pass) costs no sift.

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
    /// `(time, kind << 31 | slot)` in heap order: the key itself, so a sift compares in
    /// place (no look-up per comparison); its order is time, then kind, then slot.
    heap: Vec<(u64, u32)>,
    /// Position in `heap` of each entry id (`slot * 2 + kind`), or [`NONE`].
    pos: Vec<u32>,
}

/// The second half of an entry's key: its kind, then its slot.
#[inline]
fn rank(slot: usize, kind: Kind) -> u32 {
    (kind as u32) << 31 | slot as u32
}

/// The entry id of a key's second half.
#[inline]
fn id_of(rank: u32) -> usize {
    ((rank & 0x7FFF_FFFF) * 2 + (rank >> 31)) as usize
}

impl EventQueue {
    /// Room for slots `0 .. slots` (no entries yet).
    pub(crate) fn grow_to(&mut self, slots: usize) {
        self.pos.resize(2 * slots, NONE);
    }

    /// Sets (`Some`) or removes (`None`) the entry of `kind` of `slot`.
    #[inline]
    pub(crate) fn set(&mut self, slot: usize, kind: Kind, t: Option<u64>) {
        let id = slot * 2 + kind as usize;
        let p = self.pos[id];
        match t {
            None if p == NONE => {}
            None => self.remove_at(p as usize),
            Some(t) if p == NONE => {
                self.heap.push((t, rank(slot, kind)));
                self.sift_up(self.heap.len() - 1);
            }
            Some(t) => {
                let p = p as usize;
                let old = self.heap[p].0;
                if t == old {
                    return;
                }
                self.heap[p].0 = t;
                if t < old {
                    self.sift_up(p);
                } else {
                    self.sift_down(p);
                }
            }
        }
    }

    /// Queues the entry of `kind` of `slot` at `t` if it is not queued or queued later; an
    /// entry queued earlier, or `t == None`, is left as it is (the caller checks an entry
    /// when it comes first).
    #[inline]
    pub(crate) fn lower(&mut self, slot: usize, kind: Kind, t: Option<u64>) {
        if let Some(t) = t {
            if self.time(slot, kind).is_none_or(|q| t < q) {
                self.set(slot, kind, Some(t));
            }
        }
    }

    /// Time of the entry of `kind` of `slot`, if it is queued.
    #[inline]
    pub(crate) fn time(&self, slot: usize, kind: Kind) -> Option<u64> {
        let p = self.pos[slot * 2 + kind as usize];
        (p != NONE).then(|| self.heap[p as usize].0)
    }

    /// The earliest entry: `(time, slot, kind)`.
    #[inline]
    pub(crate) fn peek(&self) -> Option<(u64, usize, Kind)> {
        let &(t, r) = self.heap.first()?;
        let kind = if r >> 31 == 0 { Kind::Esc } else { Kind::Wake };
        Some((t, (r & 0x7FFF_FFFF) as usize, kind))
    }

    #[inline]
    fn place(&mut self, i: usize, e: (u64, u32)) {
        self.heap[i] = e;
        self.pos[id_of(e.1)] = i as u32;
    }

    fn remove_at(&mut self, i: usize) {
        let e = self.heap[i];
        self.pos[id_of(e.1)] = NONE;
        let last = self.heap.pop().unwrap_or(e);
        if i < self.heap.len() {
            self.place(i, last);
            if i > 0 && last < self.heap[(i - 1) / 2] {
                self.sift_up(i);
            } else {
                self.sift_down(i);
            }
        }
    }

    fn sift_up(&mut self, mut i: usize) {
        let e = self.heap[i];
        while i > 0 {
            let parent = (i - 1) / 2;
            let p = self.heap[parent];
            if e >= p {
                break;
            }
            self.place(i, p);
            i = parent;
        }
        self.place(i, e);
    }

    fn sift_down(&mut self, mut i: usize) {
        let e = self.heap[i];
        let n = self.heap.len();
        loop {
            let l = 2 * i + 1;
            if l >= n {
                break;
            }
            let r = l + 1;
            let c = if r < n && self.heap[r] < self.heap[l] {
                r
            } else {
                l
            };
            let ce = self.heap[c];
            if ce >= e {
                break;
            }
            self.place(i, ce);
            i = c;
        }
        self.place(i, e);
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
            for (s, e) in reference.iter().enumerate() {
                assert_eq!(q.time(s, Kind::Esc), e[0]);
                assert_eq!(q.time(s, Kind::Wake), e[1]);
            }
            let live = reference.iter().flatten().flatten().count();
            assert_eq!(q.heap.len(), live, "one entry per (slot, kind)");
        }
    }
}
