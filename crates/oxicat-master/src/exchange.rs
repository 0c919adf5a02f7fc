//! The cyclic exchange of a free-running segment in O(1) datagrams: the process image in
//! LRWs of up to [`CHUNK`] bytes, all in flight at once, and one BRD of the AL status
//! (0x0130) that every slave ORs its state into — the pattern of SOEM's
//! `ecx_send_processdata` + `ecx_readstate`.
//!
//! ethercrab's `SubDeviceGroup::tx_rx` sends its frames one after the other and fills them
//! with an FPRD of AL status per slave: at 1,000 slaves that is 11 frames in sequence, 14 KB
//! of status reads (1.1 ms of wire time at 100 Mbit/s, more than a 1 kHz cycle) and 11
//! round trips per cycle. Here a cycle is one frame per [`CHUNK`] of process data plus one
//! small frame, sent together.
//!
//! The plan is read from the wire, not from ethercrab's internals: every slave's active
//! FMMUs (0x0600..) give its output (write) and input (read) ranges in the logical address
//! space, and the expected working counter of each LRW follows the ESC's rule (+1 per slave
//! whose read FMMU the datagram touches, +2 per slave whose write FMMU it touches). A
//! segment whose FMMUs do not match the group's process image (an FMMU for something else,
//! sizes that differ) gets no plan, and the run keeps ethercrab's exchange.

use std::future::Future;
use std::pin::Pin;
use std::task::Poll;

use ethercrab::error::Error;
use ethercrab::{Command, MainDevice};
use oxicat_wire::regs;

/// Process-data bytes per LRW: one PDU filling a frame of the master's PDU storage.
pub(crate) const CHUNK: usize = 1100;
/// LRW frames in flight at once (the PDU storage has 16 frames; the BRD takes one).
const IN_FLIGHT: usize = 8;

/// One slave's bytes of one direction: (offset in the image, length), in logical order.
type Pieces = Vec<(usize, usize)>;

/// One LRW of the cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Chunk {
    /// Offset in the image.
    pub(crate) offset: usize,
    /// Bytes.
    pub(crate) len: usize,
    /// Working counter when every slave takes part.
    pub(crate) wkc: u16,
}

/// An active FMMU as the wire shows it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Fmmu {
    /// Logical start address.
    pub(crate) start: u32,
    /// Length in bytes.
    pub(crate) len: u16,
    /// Type register bit 0: read (the slave's inputs).
    pub(crate) read: bool,
    /// Type register bit 1: write (the slave's outputs).
    pub(crate) write: bool,
    /// Logical start bit 0 and end bit 7: whole bytes (what [`overlapped`] can move).
    pub(crate) whole_bytes: bool,
    /// Which of the slave's FMMUs (register block 0x0600 + 16 × index).
    pub(crate) index: u8,
}

impl Fmmu {
    /// Decodes FMMU register block `index` (16 bytes); `None` when it is not active or
    /// maps nothing.
    pub(crate) fn decode(index: u8, b: &[u8]) -> Option<Self> {
        let b: &[u8; 16] = b.get(..16)?.try_into().ok()?;
        let f = Self {
            start: u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            len: u16::from_le_bytes([b[4], b[5]]),
            read: b[11] & 1 != 0,
            write: b[11] & 2 != 0,
            whole_bytes: b[6] & 7 == 0 && b[7] & 7 == 7,
            index,
        };
        (b[12] & 1 != 0 && f.len != 0 && (f.read || f.write)).then_some(f)
    }
}

/// An FMMU to move for [`overlapped`]: the slave, its FMMU index, the logical start it
/// had and the one it gets.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Move {
    pub(crate) slave: usize,
    pub(crate) index: u8,
    pub(crate) from: u32,
    pub(crate) to: u32,
}

/// The overlapped layout of SOEM's `ecx_config_overlap_map`: every slave's inputs on the
/// logical bytes of its outputs, so an LRW carries max(outputs, inputs) bytes per slave
/// instead of their sum (each ESC writes its outputs from the bytes as they arrive and puts
/// its inputs in their place). Slave by slave from the image's first address, each gets
/// max(outputs, inputs) bytes; a direction's FMMUs keep their logical order. Returns the
/// FMMUs as they will be and the moves that make them so; `None` when some FMMU is not
/// whole bytes or maps both ways, or when nothing is mapped.
pub(crate) fn overlapped(fmmus: &[Vec<Fmmu>]) -> Option<(Vec<Vec<Fmmu>>, Vec<Move>)> {
    let mut at = fmmus.iter().flatten().map(|f| f.start).min()?;
    let mut layout = Vec::with_capacity(fmmus.len());
    let mut moves = Vec::new();
    for (slave, fs) in fmmus.iter().enumerate() {
        if fs.iter().any(|f| !f.whole_bytes || (f.read && f.write)) {
            return None;
        }
        let mut placed = fs.clone();
        let mut span = 0u32;
        for write in [true, false] {
            let mut order: Vec<usize> = (0..fs.len()).filter(|&k| fs[k].write == write).collect();
            order.sort_by_key(|&k| fs[k].start);
            let mut off = 0u32;
            for k in order {
                let to = at.checked_add(off)?;
                if to != fs[k].start {
                    moves.push(Move {
                        slave,
                        index: fs[k].index,
                        from: fs[k].start,
                        to,
                    });
                }
                placed[k].start = to;
                off += u32::from(fs[k].len);
            }
            span = span.max(off);
        }
        at = at.checked_add(span)?;
        layout.push(placed);
    }
    Some((layout, moves))
}

/// Where every slave's process data lies in one image and how the image is exchanged.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Plan {
    /// Logical address of the image's first byte.
    pub(crate) start: u32,
    /// The image as sent: the outputs (input bytes that no output shares stay zero).
    pub(crate) image: Vec<u8>,
    /// The image as it came back: the inputs, from the last LRW of each part whose
    /// working counter was the planned one.
    pub(crate) received: Vec<u8>,
    /// Some slave's inputs share its outputs' logical bytes ([`overlapped`]).
    pub(crate) overlapped: bool,
    /// The FMMUs moved for this plan, to be moved back after the run.
    pub(crate) moved: Vec<Move>,
    /// The LRWs of a cycle.
    pub(crate) chunks: Vec<Chunk>,
    /// LRWs sent together: [`IN_FLIGHT`], or 1 when a slave's piece is split over two
    /// LRWs (they must then reach it in order, and ethercrab sends the frames in flight in
    /// the order of its storage slots, not of their making).
    pub(crate) in_flight: usize,
    outputs: Vec<Pieces>,
    inputs: Vec<Pieces>,
}

/// What one exchange saw.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Exchanged {
    /// Sum of the LRWs' working counters.
    pub(crate) working_counter: u16,
    /// Some LRW's working counter was not the planned one (its inputs were not taken).
    pub(crate) wkc_bad: bool,
    /// Every slave answered the BRD and all are in OP (AL status state bits 0x08).
    pub(crate) all_op: bool,
}

impl Plan {
    /// The plan for slaves with these active FMMUs, whose process image (as the group has
    /// it) is `out_len[p]` output and `in_len[p]` input bytes; `None` when the FMMUs are not
    /// exactly those images (each direction of a slave: FMMUs of that one type whose
    /// lengths add up to the image, no FMMU of both types, no logical byte shared by two
    /// slaves or two FMMUs of one direction; a slave's inputs may share its own outputs'
    /// bytes, the [`overlapped`] layout).
    pub(crate) fn new(fmmus: &[Vec<Fmmu>], out_len: &[usize], in_len: &[usize]) -> Option<Self> {
        let all = fmmus.iter().flatten();
        let start = all.clone().map(|f| f.start).min()?;
        let end = all
            .clone()
            .map(|f| u64::from(f.start) + u64::from(f.len))
            .max()?;
        let span = usize::try_from(end - u64::from(start)).ok()?;
        // ethercrab's images are at most MAX_PDI (64 KB); anything far larger is not one.
        if span > 1 << 20 {
            return None;
        }
        let mut outputs = Vec::with_capacity(fmmus.len());
        let mut inputs = Vec::with_capacity(fmmus.len());
        for (p, fs) in fmmus.iter().enumerate() {
            if fs.iter().any(|f| f.read && f.write) {
                return None;
            }
            let pieces = |write: bool| -> Pieces {
                let mut v: Pieces = fs
                    .iter()
                    .filter(|f| f.write == write)
                    .map(|f| ((f.start - start) as usize, usize::from(f.len)))
                    .collect();
                v.sort_unstable();
                v
            };
            let (o, i) = (pieces(true), pieces(false));
            let total = |v: &Pieces| v.iter().map(|&(_, l)| l).sum::<usize>();
            if total(&o) != *out_len.get(p)? || total(&i) != *in_len.get(p)? {
                return None;
            }
            outputs.push(o);
            inputs.push(i);
        }
        // Two FMMUs of one direction on the same logical bytes, or two slaves: not an image.
        for dir in [&outputs, &inputs] {
            let mut v: Vec<(usize, usize)> = dir.iter().flatten().copied().collect();
            v.sort_unstable();
            if v.windows(2).any(|w| w[0].0 + w[0].1 > w[1].0) {
                return None;
            }
        }
        // (offset, length, slave) of every piece, sorted; a piece may overlap only the
        // other direction's pieces of its own slave.
        let mut all: Vec<(usize, usize, usize)> = outputs
            .iter()
            .chain(&inputs)
            .enumerate()
            .flat_map(|(k, v)| v.iter().map(move |&(a, l)| (a, l, k % fmmus.len())))
            .filter(|p| p.1 > 0)
            .collect();
        all.sort_unstable();
        let mut overlapped = false;
        // The slaves' merged pieces (offset, length), sorted and disjoint.
        let mut spans: Vec<(usize, usize)> = Vec::with_capacity(all.len());
        // The open span: start, end, its slave.
        let mut open: Option<(usize, usize, usize)> = None;
        for &(a, l, k) in &all {
            match &mut open {
                Some((_, e, owner)) if a < *e => {
                    if *owner != k {
                        return None;
                    }
                    overlapped = true;
                    *e = (*e).max(a + l);
                }
                _ => {
                    if let Some((s, e, _)) = open.take() {
                        spans.push((s, e - s));
                    }
                    open = Some((a, a + l, k));
                }
            }
        }
        if let Some((s, e, _)) = open {
            spans.push((s, e - s));
        }
        let (bounds, in_order) = chunk_bounds(&spans);
        let chunks = bounds
            .into_iter()
            .map(|(offset, len)| {
                let touches =
                    |v: &Pieces| v.iter().any(|&(a, l)| a < offset + len && offset < a + l);
                let wkc = inputs
                    .iter()
                    .zip(&outputs)
                    .map(|(i, o)| u16::from(touches(i)) + 2 * u16::from(touches(o)))
                    .sum();
                Chunk { offset, len, wkc }
            })
            .collect();
        Some(Self {
            start,
            image: vec![0; span],
            received: vec![0; span],
            overlapped,
            moved: Vec::new(),
            chunks,
            in_flight: if in_order { 1 } else { IN_FLIGHT },
            outputs,
            inputs,
        })
    }

    /// Frames per cycle: the LRWs and the BRD.
    pub(crate) fn frames(&self) -> usize {
        self.chunks.len() + 1
    }

    /// Puts every slave's outputs into the image.
    pub(crate) fn put_outputs(&mut self, outputs: &[Vec<u8>]) {
        for (pieces, data) in self.outputs.iter().zip(outputs) {
            let mut at = 0;
            for &(off, len) in pieces {
                let n = len.min(data.len().saturating_sub(at));
                self.image[off..off + n].copy_from_slice(&data[at..at + n]);
                at += len;
            }
        }
    }

    /// Takes every slave's inputs from the image.
    pub(crate) fn take_inputs(&self, inputs: &mut [Vec<u8>]) {
        for (pieces, data) in self.inputs.iter().zip(inputs) {
            data.clear();
            for &(off, len) in pieces {
                data.extend_from_slice(&self.received[off..off + len]);
            }
        }
    }

    /// One exchange: the LRWs (at most [`Plan::in_flight`] at once) and, with the first of them,
    /// the BRD of AL status, which `slaves` ESCs must answer. An LRW whose working counter
    /// is not the planned one leaves its part of the image as it was. Errors other than a
    /// working counter (a frame that did not come back) end the exchange.
    pub(crate) async fn exchange(
        &mut self,
        md: &MainDevice<'_>,
        slaves: u16,
    ) -> Result<Exchanged, Error> {
        let mut seen = Exchanged {
            working_counter: 0,
            wkc_bad: false,
            all_op: true,
        };
        let mut status = Some(
            Command::brd(regs::AL_STATUS)
                .with_wkc(slaves)
                .receive::<u16>(md),
        );
        for batch in self.chunks.chunks(self.in_flight) {
            let image = &self.image;
            let lrws = batch.iter().map(|c| {
                Command::lrw(self.start + c.offset as u32)
                    .with_wkc(c.wkc)
                    .send_receive_slice(md, &image[c.offset..c.offset + c.len])
            });
            let lrws = join_all(lrws);
            let (replies, st) = match status.take() {
                Some(s) => {
                    let (r, st) = futures_lite::future::zip(lrws, s).await;
                    (r, Some(st))
                }
                None => (lrws.await, None),
            };
            for (c, r) in batch.iter().zip(replies) {
                match r {
                    Ok(data) => {
                        seen.working_counter = seen.working_counter.wrapping_add(c.wkc);
                        let n = data.len().min(c.len);
                        self.received[c.offset..c.offset + n].copy_from_slice(&data[..n]);
                    }
                    Err(Error::WorkingCounter { received, .. }) => {
                        seen.working_counter = seen.working_counter.wrapping_add(received);
                        seen.wkc_bad = true;
                    }
                    Err(e) => return Err(e),
                }
            }
            match st {
                // AL status state bits only (0x0F): what ethercrab's per-slave check
                // compared; the error flag is looked at when something else is wrong.
                Some(Ok(or)) => seen.all_op = or & 0x0F == 0x08,
                Some(Err(Error::WorkingCounter { .. })) => seen.all_op = false,
                Some(Err(e)) => return Err(e),
                None => {}
            }
        }
        Ok(seen)
    }
}

/// The LRWs (offset, length) that carry `pieces` (offset, length in the image; sorted, not
/// overlapping): as few as fit [`CHUNK`] bytes each, a new one started before a piece that
/// would cross the limit, so that no slave's piece (an FMMU onto one SyncManager) is split
/// over two LRWs — a 3-buffer SyncManager is written or read as one access, first byte to
/// last, and LRWs in flight together can reach the slaves in any order. The flag: some
/// piece is longer than [`CHUNK`] and is split after all (its LRWs must then be sent one
/// after the other).
pub(crate) fn chunk_bounds(pieces: &[(usize, usize)]) -> (Vec<(usize, usize)>, bool) {
    let mut out = Vec::new();
    let mut split = false;
    // The open chunk: [start, end).
    let mut open: Option<(usize, usize)> = None;
    for &(a, l) in pieces.iter().filter(|p| p.1 > 0) {
        let e = a + l;
        if let Some((s, end)) = open {
            if e - s <= CHUNK {
                open = Some((s, e.max(end)));
                continue;
            }
            out.push((s, end - s));
        }
        let mut a = a;
        while e - a > CHUNK {
            split = true;
            out.push((a, CHUNK));
            a += CHUNK;
        }
        open = Some((a, e));
    }
    if let Some((s, end)) = open {
        out.push((s, end - s));
    }
    (out, split)
}

/// Frames per cycle of ethercrab's `tx_rx` for an image of `pdi_len` bytes and `slaves`
/// slaves: its loop, frame by frame (an LRW of what fits, then FPRDs of AL status, 14
/// bytes each and at most 129 a frame, while there is room).
pub(crate) fn ethercrab_frames(pdi_len: usize, slaves: usize) -> usize {
    // PDU bytes of a frame of the master's storage; each PDU has 12 bytes of header + WKC.
    const BUF: usize = CHUNK + 12;
    let (mut sent, mut checks, mut frames) = (0, 0, 0);
    while sent < pdi_len || checks < slaves {
        let mut used = 0;
        if sent < pdi_len {
            let take = (pdi_len - sent).min(BUF - 12);
            sent += take;
            used += take + 12;
        }
        let mut k = 0;
        while used + 14 <= BUF && checks < slaves && k <= 128 {
            checks += 1;
            k += 1;
            used += 14;
        }
        frames += 1;
    }
    frames
}

/// Polls every future of `futs` until all are ready; their outputs in order.
async fn join_all<F: Future>(futs: impl Iterator<Item = F>) -> Vec<F::Output> {
    /// A future still running, or its output.
    enum Slot<F: Future> {
        Running(Pin<Box<F>>),
        Done(F::Output),
    }
    let mut slots: Vec<Slot<F>> = futs.map(|f| Slot::Running(Box::pin(f))).collect();
    std::future::poll_fn(|cx| {
        let mut pending = false;
        for s in slots.iter_mut() {
            if let Slot::Running(f) = s {
                match f.as_mut().poll(cx) {
                    Poll::Ready(v) => *s = Slot::Done(v),
                    Poll::Pending => pending = true,
                }
            }
        }
        if pending {
            Poll::Pending
        } else {
            Poll::Ready(())
        }
    })
    .await;
    slots
        .into_iter()
        .filter_map(|s| match s {
            Slot::Done(v) => Some(v),
            Slot::Running(_) => None,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fmmu(start: u32, len: u16, write: bool) -> Fmmu {
        Fmmu {
            start,
            len,
            read: !write,
            write,
            whole_bytes: true,
            index: u8::from(!write),
        }
    }

    #[test]
    fn an_fmmu_block_decodes_when_active() {
        let mut b = [0u8; 16];
        b[..4].copy_from_slice(&0x0001_0020u32.to_le_bytes());
        b[4..6].copy_from_slice(&24u16.to_le_bytes());
        b[11] = 2;
        assert_eq!(Fmmu::decode(3, &b), None, "not active");
        b[12] = 1;
        let want = Fmmu {
            start: 0x0001_0020,
            len: 24,
            read: false,
            write: true,
            whole_bytes: false,
            index: 3,
        };
        assert_eq!(
            Fmmu::decode(3, &b),
            Some(want),
            "end bit 0: not whole bytes"
        );
        b[7] = 7;
        assert_eq!(
            Fmmu::decode(3, &b),
            Some(Fmmu {
                whole_bytes: true,
                ..want
            })
        );
        b[11] = 0;
        assert_eq!(Fmmu::decode(3, &b), None, "no type");
        assert_eq!(Fmmu::decode(3, &b[..15]), None, "short");
    }

    #[test]
    fn outputs_and_inputs_go_where_the_fmmus_say() {
        // Slave 0: 2 output bytes at 0, 1 input byte at 4; slave 1: 1 output at 2, 2 inputs
        // at 5, split over two FMMUs given out of order.
        let fm = vec![
            vec![fmmu(0x100, 2, true), fmmu(0x104, 1, false)],
            vec![
                fmmu(0x106, 1, false),
                fmmu(0x102, 1, true),
                fmmu(0x105, 1, false),
            ],
        ];
        let mut plan = Plan::new(&fm, &[2, 1], &[1, 2]).unwrap();
        assert_eq!(plan.start, 0x100);
        assert_eq!(plan.image.len(), 7);
        assert_eq!(
            plan.chunks,
            vec![Chunk {
                offset: 0,
                len: 7,
                wkc: 6
            }]
        );
        assert!(!plan.overlapped);
        plan.put_outputs(&[vec![1, 2], vec![3]]);
        assert_eq!(plan.image, [1, 2, 3, 0, 0, 0, 0]);
        plan.received[4..].copy_from_slice(&[7, 8, 9]);
        let mut inputs = vec![vec![0xEE; 5], Vec::new()];
        plan.take_inputs(&mut inputs);
        assert_eq!(inputs, vec![vec![7], vec![8, 9]]);
    }

    #[test]
    fn the_working_counter_of_each_lrw_counts_the_slaves_it_touches() {
        // 3 slaves, 400 output bytes each then 300 input bytes each.
        let fm: Vec<Vec<Fmmu>> = (0..3u32)
            .map(|p| vec![fmmu(p * 400, 400, true), fmmu(1200 + p * 300, 300, false)])
            .collect();
        let plan = Plan::new(&fm, &[400; 3], &[300; 3]).unwrap();
        let got: Vec<(usize, usize, u16)> = plan
            .chunks
            .iter()
            .map(|c| (c.offset, c.len, c.wkc))
            .collect();
        // Writes of slaves 0, 1; slave 2's write and the reads of 0, 1; the read of 2.
        assert_eq!(got, vec![(0, 800, 4), (800, 1000, 4), (1800, 300, 1)]);
        assert_eq!(plan.in_flight, IN_FLIGHT);
        // A slave's image longer than an LRW: split, and sent in order.
        let big = vec![vec![fmmu(0, 3000, true), fmmu(3000, 2, false)]];
        let plan = Plan::new(&big, &[3000], &[2]).unwrap();
        assert_eq!(plan.in_flight, 1);
        assert_eq!(
            plan.chunks.iter().map(|c| c.wkc).collect::<Vec<_>>(),
            vec![2, 2, 3]
        );
    }

    #[test]
    fn no_piece_is_split_over_two_lrws_unless_it_is_longer_than_one() {
        // 60 demo nodes: 24 output bytes each, then 22 input bytes each.
        let pieces: Vec<(usize, usize)> = (0..60)
            .map(|p| (p * 24, 24))
            .chain((0..60).map(|p| (1440 + p * 22, 22)))
            .collect();
        let (chunks, split) = chunk_bounds(&pieces);
        assert!(!split);
        // 45 nodes' outputs (1,080 B) fit the first; then 15 outputs and 33 inputs; the rest.
        assert_eq!(chunks, vec![(0, 1080), (1080, 1086), (2166, 594)]);
        for &(a, l) in &pieces {
            let n = chunks
                .iter()
                .filter(|&&(o, cl)| a < o + cl && o < a + l)
                .count();
            assert_eq!(n, 1, "piece at {a} in one LRW");
            assert!(chunks.iter().any(|&(o, cl)| o <= a && a + l <= o + cl));
        }
        // A gap between pieces that do not fit together is not sent.
        assert_eq!(
            chunk_bounds(&[(0, 1000), (1500, 200)]),
            (vec![(0, 1000), (1500, 200)], false)
        );
        assert_eq!(chunk_bounds(&[(0, 10), (20, 10)]), (vec![(0, 30)], false));
        // A piece longer than a chunk is split, and said so.
        assert_eq!(
            chunk_bounds(&[(0, 10), (10, 2500)]),
            (vec![(0, 10), (10, 1100), (1110, 1100), (2210, 300)], true)
        );
        assert_eq!(chunk_bounds(&[]), (vec![], false));
    }

    #[test]
    fn ethercrab_frames_follow_its_tx_rx_loop() {
        // One frame: 24 bytes of image and 2 status reads.
        assert_eq!(ethercrab_frames(24, 2), 1);
        // 1,000 EL2008s: the LRW and 7 status reads, then 79 reads a frame.
        assert_eq!(ethercrab_frames(1000, 1000), 1 + 993usize.div_ceil(79));
        // An image of 2,200 bytes: two full LRW frames, the reads after them.
        assert_eq!(ethercrab_frames(2200, 10), 3);
        assert_eq!(ethercrab_frames(0, 0), 0);
        // No more than 129 reads in one frame, even with room (none here: 79 fit).
        assert_eq!(ethercrab_frames(0, 130), 2);
    }

    #[test]
    fn fmmus_that_are_not_the_image_give_no_plan() {
        let good = vec![vec![fmmu(0, 2, true), fmmu(2, 1, false)]];
        assert!(Plan::new(&good, &[2], &[1]).is_some());
        assert!(Plan::new(&good, &[3], &[1]).is_none(), "sizes differ");
        let both = vec![vec![Fmmu {
            read: true,
            ..fmmu(0, 2, true)
        }]];
        assert!(Plan::new(&both, &[2], &[2]).is_none(), "one FMMU both ways");
        assert!(Plan::new(&[vec![]], &[0], &[0]).is_none(), "nothing mapped");
        let overlap = vec![vec![fmmu(0, 2, true)], vec![fmmu(1, 1, false)]];
        assert!(
            Plan::new(&overlap, &[2, 0], &[0, 1]).is_none(),
            "shared bytes"
        );
        // A slave's long output piece reaching over a short input piece of its own into
        // the next slave's bytes.
        let reach = vec![
            vec![fmmu(0, 4, true), fmmu(0, 1, false)],
            vec![fmmu(2, 1, false)],
        ];
        assert!(
            Plan::new(&reach, &[4, 0], &[1, 1]).is_none(),
            "reaches over"
        );
        let same_dir = vec![vec![fmmu(0, 2, true), fmmu(1, 2, true)]];
        assert!(Plan::new(&same_dir, &[4], &[0]).is_none(), "two outputs");
        let far = vec![vec![fmmu(0, 1, true), fmmu(0x1000_0000, 1, false)]];
        assert!(Plan::new(&far, &[1], &[1]).is_none(), "not one image");
    }
    #[test]
    fn the_overlapped_layout_puts_each_slaves_inputs_on_its_outputs() {
        // ethercrab's layout of three demo-like slaves: each 3 output bytes then 2 input
        // bytes (slave 1 with no inputs, slave 2's outputs in two FMMUs).
        let fm = vec![
            vec![fmmu(0x100, 3, true), fmmu(0x103, 2, false)],
            vec![fmmu(0x105, 3, true)],
            vec![
                Fmmu {
                    index: 2,
                    ..fmmu(0x10A, 2, true)
                },
                fmmu(0x10C, 4, false),
                fmmu(0x108, 2, true),
            ],
        ];
        let (layout, moves) = overlapped(&fm).unwrap();
        // Slave 0 at 0x100 (3 bytes), slave 1 at 0x103 (3), slave 2 at 0x106 (4).
        let starts: Vec<Vec<u32>> = layout
            .iter()
            .map(|v| v.iter().map(|f| f.start).collect())
            .collect();
        assert_eq!(
            starts,
            vec![vec![0x100, 0x100], vec![0x103], vec![0x108, 0x106, 0x106]]
        );
        assert_eq!(
            moves,
            vec![
                Move {
                    slave: 0,
                    index: 1,
                    from: 0x103,
                    to: 0x100
                },
                Move {
                    slave: 1,
                    index: 0,
                    from: 0x105,
                    to: 0x103
                },
                Move {
                    slave: 2,
                    index: 0,
                    from: 0x108,
                    to: 0x106
                },
                Move {
                    slave: 2,
                    index: 2,
                    from: 0x10A,
                    to: 0x108
                },
                Move {
                    slave: 2,
                    index: 1,
                    from: 0x10C,
                    to: 0x106
                },
            ]
        );
        let mut plan = Plan::new(&layout, &[3, 3, 4], &[2, 0, 4]).unwrap();
        assert!(plan.overlapped);
        assert_eq!(plan.image.len(), 10, "3 + 3 + 4, not 18");
        // Both directions of slaves 0 and 2, the outputs of slave 1: 3 + 2 + 3.
        assert_eq!(
            plan.chunks,
            vec![Chunk {
                offset: 0,
                len: 10,
                wkc: 8
            }]
        );
        plan.put_outputs(&[vec![1, 2, 3], vec![4, 5, 6], vec![7, 8, 9, 10]]);
        assert_eq!(plan.image, [1, 2, 3, 4, 5, 6, 7, 8, 9, 10]);
        // What the ESCs send back: slave 0's inputs on its first two bytes, slave 1's
        // outputs as they were, slave 2's inputs over its outputs.
        plan.received
            .copy_from_slice(&[21, 22, 3, 4, 5, 6, 41, 42, 43, 44]);
        let mut inputs = vec![Vec::new(); 3];
        plan.take_inputs(&mut inputs);
        assert_eq!(inputs, vec![vec![21, 22], vec![], vec![41, 42, 43, 44]]);
        // The outputs sent are not what came back.
        assert_eq!(plan.image, [1, 2, 3, 4, 5, 6, 7, 8, 9, 10]);
        // Already overlapped: nothing to move.
        let (again, none) = overlapped(&layout).unwrap();
        assert_eq!(again, layout);
        assert!(none.is_empty());
    }

    #[test]
    fn fmmus_of_bits_or_both_ways_are_not_overlapped() {
        let bits = vec![vec![
            fmmu(0, 1, true),
            Fmmu {
                whole_bytes: false,
                ..fmmu(1, 1, false)
            },
        ]];
        assert!(overlapped(&bits).is_none());
        let both = vec![vec![Fmmu {
            read: true,
            ..fmmu(0, 2, true)
        }]];
        assert!(overlapped(&both).is_none());
        assert!(overlapped(&[vec![], vec![]]).is_none(), "nothing mapped");
    }
}
