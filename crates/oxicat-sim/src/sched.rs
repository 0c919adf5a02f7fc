//! The segment's event queue: every slot's next ESC event and next node wakeup, ordered
//! by (time, ESC event before wakeup, slot), kept up to date entry by entry.
//!
//! Two layouts with the same answers. Up to [`SMALL_SLOTS`] slots (the trot's four legs, a
//! demo bench) each entry's time sits in a fixed array with a bit per live entry, and the
//! earliest is found by a pass over the times (a free entry holds `u64::MAX`), remembered
//! until the entry it names moves later or goes: setting an entry costs a store and a comparison, a look at the
//! first entry between changes nothing. More slots use an indexed binary heap: each slot
//! has at most one entry per kind, found through its position, so a changed time is a sift
//! up or down (O(log n)) and an unchanged one costs a comparison, and the heap never holds
//! more than two entries per slot however often the times move. [`EventQueue::lower`] lets
//! the segment leave an entry earlier than its time (checked when it comes first), so a
//! time that only moves later (a firmware's PDI watchdog deadline, at every main-loop pass)
//! costs no sift.
//!
//! Beside the heap, wakeups have a ring kept in key order by appending: a wakeup whose key
//! is not below the ring's last goes to its back, any other to the heap, and the first
//! entry is the lesser of the two fronts. Many equal-period wakeups (256 firmware hosts'
//! main loops every 50 µs, on one grid) each move from the front to the back, in O(1),
//! where the heap sifted each from its root to its bottom: that sift was the first item
//! of a `perf` profile of 128 and 256 served demo devices.

/// Most slots the array layout takes (two entries each, one bit per entry in a `u32`);
/// more switch the queue to the heap.
pub(crate) const SMALL_SLOTS: usize = 8;

/// Entries of the array layout, at `kind * SMALL_SLOTS + slot`: in the order of the
/// tie-break, so that of equal times the lowest index comes first.
const SMALL_IDS: usize = 2 * SMALL_SLOTS;

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

/// The array layout: the time of the entry at index `x` (`kind * SMALL_SLOTS + slot`) in
/// `t[x]` while bit `x` of `live` is set, `u64::MAX` while it is not (so that a pass for
/// the least time needs no look at `live`).
#[derive(Debug, Clone, Copy)]
struct Small {
    t: [u64; SMALL_IDS],
    live: u32,
    /// Slots in use (`0 .. n`).
    n: usize,
    /// The index of the earliest live entry ([`NONE`]: none), unless `stale`.
    best: u32,
    /// `best` must be found again (the entry it named moved later or went).
    stale: bool,
}

impl Default for Small {
    fn default() -> Self {
        Self {
            t: [u64::MAX; SMALL_IDS],
            live: 0,
            n: 0,
            best: NONE,
            stale: false,
        }
    }
}

impl Small {
    /// The index of the entry of `kind` of `slot`.
    #[inline]
    fn index(slot: usize, kind: Kind) -> u32 {
        (kind as usize * SMALL_SLOTS + slot) as u32
    }

    /// The slot and kind of the entry at index `x` (the inverse of [`Small::index`]).
    #[inline]
    fn entry(x: u32) -> (usize, Kind) {
        let x = x as usize;
        let kind = if x < SMALL_SLOTS {
            Kind::Esc
        } else {
            Kind::Wake
        };
        (x % SMALL_SLOTS, kind)
    }

    #[inline]
    fn set(&mut self, x: u32, t: Option<u64>) {
        let bit = 1u32 << x;
        let was = self.live & bit != 0;
        let Some(t) = t else {
            self.live &= !bit;
            self.t[x as usize] = u64::MAX;
            if was && self.best == x {
                self.stale = true;
            }
            return;
        };
        let old = self.t[x as usize];
        if was && old == t {
            return;
        }
        self.t[x as usize] = t;
        self.live |= bit;
        if self.stale {
            return;
        }
        if self.best == x {
            // Earlier: still the first; later: another may be now.
            if t > old {
                self.stale = true;
            }
        } else if self.best == NONE || {
            let bt = self.t[self.best as usize];
            t < bt || (t == bt && x < self.best)
        } {
            self.best = x;
        }
    }

    #[inline]
    fn time(&self, x: u32) -> Option<u64> {
        (self.live & (1 << x) != 0).then(|| self.t[x as usize])
    }

    /// The index of the earliest live entry, or [`NONE`].
    #[inline]
    fn first(&mut self) -> u32 {
        if self.stale {
            self.stale = false;
            // In index order, so a strictly earlier time is the only reason to move on.
            let (esc, wake) = self.t.split_at(SMALL_SLOTS);
            let mut best = NONE;
            let mut bt = u64::MAX;
            for (x, &t) in esc[..self.n].iter().enumerate() {
                if t < bt {
                    bt = t;
                    best = x as u32;
                }
            }
            for (x, &t) in wake[..self.n].iter().enumerate() {
                if t < bt {
                    bt = t;
                    best = (SMALL_SLOTS + x) as u32;
                }
            }
            if best == NONE && self.live != 0 {
                // Every live entry at `u64::MAX`: the lowest index.
                best = self.live.trailing_zeros();
            }
            self.best = best;
        }
        self.best
    }
}

/// Pending events of a segment's slots, earliest first.
#[derive(Debug, Default)]
pub(crate) struct EventQueue {
    /// The array layout, while the queue has room for at most [`SMALL_SLOTS`] slots (then
    /// `heap` and `pos` stay empty).
    small: Option<Small>,
    /// Room for this many slots.
    slots: usize,
    /// `(time, kind << 31 | slot)` in heap order: the key itself, so a sift compares in
    /// place (no look-up per comparison); its order is time, then kind, then slot.
    heap: Vec<(u64, u32)>,
    /// Position in `heap` of each entry id (`slot * 2 + kind`), or [`NONE`].
    pos: Vec<u32>,
    /// Wakeups queued in key order, `(time, slot)`: the periodic ones (a firmware host's
    /// main loop every 50 µs, all hosts on one grid) each go from the front to the back
    /// at the same distance, so they stay sorted by being appended — O(1) instead of a
    /// sift from the heap's root to its bottom. A wakeup whose key is below the back's
    /// goes to the heap. An entry here is live while `ring_t` of its slot holds its time;
    /// one that moved or went is left (stale) and dropped when it reaches an end.
    ring: std::collections::VecDeque<(u64, u32)>,
    /// The time of each slot's wakeup while it lives in `ring`.
    ring_t: Vec<Option<u64>>,
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
        if self.slots == 0 && slots <= SMALL_SLOTS && self.small.is_none() {
            self.small = Some(Small::default());
        }
        self.slots = self.slots.max(slots);
        if self.slots <= SMALL_SLOTS {
            if let Some(small) = self.small.as_mut() {
                small.n = self.slots;
            }
            return;
        }
        self.pos.resize(2 * self.slots, NONE);
        self.ring_t.resize(self.slots, None);
        if let Some(small) = self.small.take() {
            // Outgrown: the live entries move to the heap.
            let mut m = small.live;
            while m != 0 {
                let x = m.trailing_zeros();
                m &= m - 1;
                let (slot, kind) = Small::entry(x);
                self.set(slot, kind, Some(small.t[x as usize]));
            }
        }
    }

    /// Sets (`Some`) or removes (`None`) the entry of `kind` of `slot`.
    #[inline]
    pub(crate) fn set(&mut self, slot: usize, kind: Kind, t: Option<u64>) {
        if let Some(small) = self.small.as_mut() {
            debug_assert!(slot < self.slots, "slot {slot} of {}", self.slots);
            return small.set(Small::index(slot, kind), t);
        }
        if kind == Kind::Wake {
            return self.set_wake(slot, t);
        }
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

    /// [`set`](Self::set) of a wakeup in the heap layout: to the back of the ring when
    /// its key is not below the back's, else to the heap.
    #[inline]
    fn set_wake(&mut self, slot: usize, t: Option<u64>) {
        let id = slot * 2 + Kind::Wake as usize;
        let p = self.pos[id];
        if let Some(old) = self.ring_t[slot] {
            if t == Some(old) {
                return;
            }
            self.ring_t[slot] = None;
        } else if p != NONE {
            if t == Some(self.heap[p as usize].0) {
                return;
            }
            self.remove_at(p as usize);
        }
        let Some(t) = t else {
            return;
        };
        // Stale entries at the back do not hold the order up.
        while let Some(&(bt, bs)) = self.ring.back() {
            if self.ring_t[bs as usize] == Some(bt) {
                break;
            }
            self.ring.pop_back();
        }
        let key = (t, slot as u32);
        if self.ring.back().is_none_or(|&b| key >= b) {
            if self.ring.len() >= 2 * self.slots + 16 {
                // Stale entries in the middle: drop them, so the ring holds at most
                // about two entries per slot.
                let ring_t = &self.ring_t;
                self.ring
                    .retain(|&(rt, rs)| ring_t[rs as usize] == Some(rt));
            }
            self.ring.push_back(key);
            self.ring_t[slot] = Some(t);
        } else {
            self.heap.push((t, rank(slot, Kind::Wake)));
            self.sift_up(self.heap.len() - 1);
        }
    }

    /// The ring's first live entry (stale ones at its front dropped).
    #[inline]
    fn ring_first(&mut self) -> Option<(u64, u32)> {
        while let Some(&(t, s)) = self.ring.front() {
            if self.ring_t[s as usize] == Some(t) {
                return Some((t, s));
            }
            self.ring.pop_front();
        }
        None
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
        if let Some(small) = &self.small {
            debug_assert!(slot < self.slots, "slot {slot} of {}", self.slots);
            return small.time(Small::index(slot, kind));
        }
        if kind == Kind::Wake {
            if let Some(t) = self.ring_t[slot] {
                return Some(t);
            }
        }
        let p = self.pos[slot * 2 + kind as usize];
        (p != NONE).then(|| self.heap[p as usize].0)
    }

    /// The earliest entry: `(time, slot, kind)`.
    #[inline]
    pub(crate) fn peek(&mut self) -> Option<(u64, usize, Kind)> {
        if let Some(small) = self.small.as_mut() {
            let x = small.first();
            if x == NONE {
                return None;
            }
            let (slot, kind) = Small::entry(x);
            return Some((small.t[x as usize], slot, kind));
        }
        let ring = self.ring_first();
        let heap = self.heap.first().copied();
        let (t, r) = match (heap, ring) {
            (Some(h), Some((rt, rs))) => {
                let r = (rt, rank(rs as usize, Kind::Wake));
                if r < h {
                    r
                } else {
                    h
                }
            }
            (Some(h), None) => h,
            (None, Some((rt, rs))) => (rt, rank(rs as usize, Kind::Wake)),
            (None, None) => return None,
        };
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

    /// Random sets and removals against a sorted reference, in both layouts (4, 8 slots:
    /// arrays; 9, 37: heap) and across the switch (3 slots grown to 20 half way, with
    /// entries live): the queue's first entry is always the reference's least
    /// (time, kind, slot).
    #[test]
    fn always_yields_the_least_key() {
        for (start, end, near) in [
            (37, 37, false),
            (4, 4, false),
            (SMALL_SLOTS, SMALL_SLOTS, false),
            (9, 9, false),
            (3, 20, false),
            (37, 37, true),
            (3, 20, true),
        ] {
            let mut q = EventQueue::default();
            q.grow_to(start);
            assert_eq!(q.small.is_some(), start <= SMALL_SLOTS);
            let mut slots = start;
            let mut reference = vec![[None::<u64>; 2]; end];
            let mut x: u64 = 0x2545_F491_4F6C_DD1D;
            let mut rnd = || {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                x
            };
            for step in 0..20_000 {
                if step == 10_000 && end > slots {
                    slots = end;
                    q.grow_to(slots);
                    assert!(q.small.is_none(), "{end} slots take the heap");
                }
                let s = (rnd() % slots as u64) as usize;
                let k = if rnd() % 2 == 0 {
                    Kind::Esc
                } else {
                    Kind::Wake
                };
                // Few distinct times, so ties between kinds and slots are common.
                // Now and then the end of time (the array layout's mark of no entry).
                // `near`: mostly at or a little after the least queued time, as time
                // moving on gives them (most wakeups append to the ring, some do not).
                let base = if near {
                    q.peek().map_or(0, |(t, _, _)| t.min(1 << 40))
                } else {
                    0
                };
                let t = (rnd() % 5 != 0).then(|| {
                    if rnd() % 11 == 0 {
                        u64::MAX
                    } else if near && rnd() % 8 != 0 {
                        base + rnd() % 40
                    } else {
                        (base + rnd() % 40).saturating_sub(rnd() % 40)
                    }
                });
                if rnd() % 3 == 0 {
                    q.lower(s, k, t);
                    if let Some(t) = t {
                        let r = &mut reference[s][k as usize];
                        *r = Some(r.map_or(t, |r| r.min(t)));
                    }
                } else {
                    q.set(s, k, t);
                    reference[s][k as usize] = t;
                }
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
                assert_eq!(got, least, "{start}..{end} slots, near {near}, step {step}");
                for (s, e) in reference.iter().enumerate().take(slots) {
                    assert_eq!(q.time(s, Kind::Esc), e[0]);
                    assert_eq!(q.time(s, Kind::Wake), e[1]);
                }
                if q.small.is_none() {
                    let live = reference.iter().flatten().flatten().count();
                    let in_ring = q.ring_t.iter().flatten().count();
                    assert_eq!(q.heap.len() + in_ring, live, "one entry per (slot, kind)");
                    assert!(
                        q.ring.len() <= 2 * q.slots + 16,
                        "stale entries are dropped"
                    );
                }
            }
        }
    }

    /// Many wakeups of one period, as firmware hosts' main loops: each taken at the front
    /// goes to the back of the ring, in (time, slot) order, and none to the heap.
    #[test]
    fn equal_period_wakeups_append_to_the_ring() {
        let n = 300;
        let mut q = EventQueue::default();
        q.grow_to(n);
        for s in 0..n {
            q.set(s, Kind::Wake, Some(1_000));
            // An ESC event far ahead of each, as a firmware's watchdog deadline.
            q.set(s, Kind::Esc, Some(1_000_000 + s as u64));
        }
        let mut last = (0, 0);
        for k in 0..20 * n {
            let Some((t, s, kind)) = q.peek() else {
                panic!("an entry per slot");
            };
            assert_eq!(kind, Kind::Wake);
            assert!((t, s) > last || k == 0, "{:?} after {last:?}", (t, s));
            assert_eq!(t, 1_000 + (k / n) as u64 * 50_000);
            assert_eq!(s, k % n);
            last = (t, s);
            q.set(s, Kind::Wake, Some(t + 50_000));
            assert_eq!(q.heap.len(), n, "only the ESC events are in the heap");
            assert!(q.ring.len() <= 2 * n + 16);
        }
        // A wakeup moved earlier than the back goes to the heap and still comes first.
        q.set(7, Kind::Wake, Some(10));
        assert_eq!(q.peek(), Some((10, 7, Kind::Wake)));
        assert_eq!(q.time(7, Kind::Wake), Some(10));
        q.set(7, Kind::Wake, None);
        assert_eq!(q.time(7, Kind::Wake), None);
        assert_ne!(q.peek().map(|e| e.1), Some(7));
    }
}
