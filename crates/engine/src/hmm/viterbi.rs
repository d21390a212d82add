//! Viterbi over a bounded window of epochs (HIPE §4.1: the Viterbi algorithm for tracking),
//! in log space, with back-pointers kept for the last `capacity` epochs only, so memory is
//! bounded by capacity × N × 2 bytes (4 beyond 65 536 states) however long the session runs.
//! Most states' best predecessor is the one the floor weight's best path comes from, so an
//! epoch keeps that one once and lists only the others ([`KeptPointers`]).

use super::transition::{viterbi_step, Transition};
use std::collections::VecDeque;

/// The most likely state sequence over the last epochs.
///
/// After [`checkpoint`](Self::checkpoint), [`rollback`](Self::rollback) returns the window to
/// it cheaply: the scores it replaces are swapped aside, not copied, and the epochs it drops
/// are set aside until [`commit`](Self::commit) rather than recycled.
#[derive(Clone)]
pub struct ViterbiWindow {
    capacity: usize,
    /// max over paths of ln p(path, observations), shifted so that its maximum is 0.
    delta: Vec<f64>,
    next: Vec<f64>,
    /// Per epoch in the window (oldest first): timestamp and back-pointers into the previous
    /// epoch (unused for the window's first epoch).
    epochs: VecDeque<(u64, KeptPointers)>,
    spare: Vec<KeptPointers>,
    /// The step's back-pointers for every state, before they are kept.
    back: Option<BackPointers>,
    row: Vec<(u32, f64)>,
    undo: Undo,
}

/// What [`ViterbiWindow::rollback`] needs.
#[derive(Clone)]
struct Undo {
    active: bool,
    /// How many of the checkpoint's epochs are still in the window (its oldest were dropped).
    kept: usize,
    /// The checkpoint's epochs dropped since, oldest first.
    dropped: Vec<(u64, KeptPointers)>,
    /// The checkpoint's scores, once a step replaced them (`delta_saved`).
    delta: Vec<f64>,
    delta_saved: bool,
}

/// One epoch's back-pointers into the epoch before: state indices in 16 bits on a site of at
/// most 65 536 states, half the window's memory at building scale
/// (docs/tuning.md#engine-speed), and in 32 bits beyond.
#[derive(Clone, Debug, PartialEq)]
pub enum BackPointers {
    /// 16-bit state indices.
    Narrow(Vec<u16>),
    /// 32-bit state indices.
    Wide(Vec<u32>),
}

impl BackPointers {
    /// Back-pointers for `n` states, all to state 0.
    pub fn new(n: usize) -> Self {
        if n <= 1 << 16 {
            BackPointers::Narrow(vec![0; n])
        } else {
            BackPointers::Wide(vec![0; n])
        }
    }

    /// The state that state `j`'s best path came from.
    pub fn get(&self, j: usize) -> usize {
        match self {
            BackPointers::Narrow(back) => usize::from(back[j]),
            BackPointers::Wide(back) => back[j] as usize,
        }
    }

    /// Bytes held.
    fn bytes(&self) -> usize {
        match self {
            BackPointers::Narrow(back) => back.capacity() * 2,
            BackPointers::Wide(back) => back.capacity() * 4,
        }
    }
}

/// The value most of `values` hold when one holds more than half of them (Boyer and Moore's
/// majority vote), else one of them; `None` when there are none.
fn majority<T: Copy + PartialEq>(values: &[T]) -> Option<T> {
    let mut vote: Option<(T, usize)> = None;
    for &v in values {
        vote = match vote {
            None | Some((_, 0)) => Some((v, 1)),
            Some((c, k)) if c == v => Some((c, k + 1)),
            Some((c, k)) => Some((c, k - 1)),
        };
    }
    vote.map(|(c, _)| c)
}

/// Keeps `all` as the value most of them hold (returned) and the others, in order, in `kept`,
/// with the bitmap and counts of [`KeptPointers`].
fn keep_listed<T: Copy + PartialEq + Default>(
    all: &[T],
    listed: &mut Vec<u64>,
    before: &mut Vec<u32>,
    kept: &mut Vec<T>,
) -> T {
    let shared = majority(all).unwrap_or_default();
    let words = all.len().div_ceil(64);
    listed.clear();
    before.clear();
    listed.reserve_exact(words);
    before.reserve_exact(words);
    let mut count = 0;
    for chunk in all.chunks(64) {
        let word =
            chunk.iter().enumerate().filter(|&(_, &v)| v != shared).fold(0u64, |w, (bit, _)| w | 1 << bit);
        listed.push(word);
        before.push(count);
        count += word.count_ones();
    }
    kept.clear();
    kept.reserve_exact(count as usize);
    for (chunk, &word) in all.chunks(64).zip(listed.iter()) {
        if word != 0 {
            kept.extend(chunk.iter().copied().filter(|&v| v != shared));
        }
    }
    shared
}

/// One epoch's back-pointers as the window keeps them: the value most states share once
/// (`shared`, the state the floor weight's best path comes from; how few have another is
/// measured in docs/tuning.md#engine-speed), and the others in state order, found by a bitmap
/// and a count per 64 states. The same back-pointers as [`BackPointers`], in far less than
/// their N × 2 bytes where few states are listed.
#[derive(Clone, Debug, PartialEq)]
struct KeptPointers {
    shared: u32,
    /// Bit j % 64 of word j / 64: state j's pointer is listed.
    listed: Vec<u64>,
    /// Listed states before each word of `listed`.
    before: Vec<u32>,
    /// The listed pointers, in state order (16 or 32 bits as [`BackPointers`]).
    pointers: BackPointers,
}

impl KeptPointers {
    fn empty(n: usize) -> Self {
        let pointers =
            if n <= 1 << 16 { BackPointers::Narrow(Vec::new()) } else { BackPointers::Wide(Vec::new()) };
        Self { shared: 0, listed: Vec::new(), before: Vec::new(), pointers }
    }

    /// Keeps `back`, reusing this one's buffers.
    fn keep(&mut self, back: &BackPointers) {
        let Self { listed, before, .. } = self;
        self.shared = match (&mut self.pointers, back) {
            (BackPointers::Narrow(kept), BackPointers::Narrow(all)) => {
                u32::from(keep_listed(all, listed, before, kept))
            }
            (BackPointers::Wide(kept), BackPointers::Wide(all)) => keep_listed(all, listed, before, kept),
            (kept, back) => {
                // Built for another site size: take the width of `back` and keep it again.
                *kept = match back {
                    BackPointers::Narrow(_) => BackPointers::Narrow(Vec::new()),
                    BackPointers::Wide(_) => BackPointers::Wide(Vec::new()),
                };
                return self.keep(back);
            }
        };
    }

    /// The state that state `j`'s best path came from.
    fn get(&self, j: usize) -> usize {
        let (word, bit) = (j / 64, j % 64);
        match self.listed.get(word) {
            Some(&w) if w >> bit & 1 == 1 => {
                let below = (w & ((1u64 << bit) - 1)).count_ones();
                self.pointers.get((self.before[word] + below) as usize)
            }
            _ => self.shared as usize,
        }
    }

    /// Bytes held (capacity).
    fn bytes(&self) -> usize {
        self.listed.capacity() * 8 + self.before.capacity() * 4 + self.pointers.bytes()
    }
}

/// The state only: the scratch buffers hold nothing a later step reads.
impl std::fmt::Debug for ViterbiWindow {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ViterbiWindow")
            .field("capacity", &self.capacity)
            .field("delta", &self.delta)
            .field("epochs", &self.epochs)
            .finish_non_exhaustive()
    }
}

impl ViterbiWindow {
    /// A window over `n` states keeping `capacity` (≥ 1) epochs.
    pub fn new(n: usize, capacity: usize) -> Self {
        Self {
            capacity: capacity.max(1),
            delta: vec![0.0; n],
            next: vec![0.0; n],
            epochs: VecDeque::with_capacity(capacity.max(1)),
            spare: Vec::new(),
            back: None,
            row: Vec::new(),
            undo: Undo {
                active: false,
                kept: 0,
                dropped: Vec::new(),
                delta: vec![0.0; n],
                delta_saved: false,
            },
        }
    }

    /// Forgets every epoch.
    pub fn reset(&mut self) {
        while !self.epochs.is_empty() {
            self.drop_oldest();
        }
    }

    fn drop_oldest(&mut self) {
        let Some(oldest) = self.epochs.pop_front() else { return };
        if self.undo.active && self.undo.kept > 0 {
            self.undo.kept -= 1;
            self.undo.dropped.push(oldest);
        } else {
            self.spare.push(oldest.1);
        }
    }

    /// Makes `next` (holding the new scores) the scores; the old ones are kept for `rollback`
    /// if they are the checkpoint's.
    fn replace_delta(&mut self) {
        std::mem::swap(&mut self.delta, &mut self.next);
        if self.undo.active && !self.undo.delta_saved {
            std::mem::swap(&mut self.next, &mut self.undo.delta);
            self.undo.delta_saved = true;
        }
    }

    /// Remembers the window, so that [`rollback`](Self::rollback) can return to it until
    /// [`commit`](Self::commit).
    pub fn checkpoint(&mut self) {
        self.commit();
        self.undo.active = true;
        self.undo.kept = self.epochs.len();
    }

    /// Forgets the checkpoint.
    pub fn commit(&mut self) {
        for (_, back) in self.undo.dropped.drain(..) {
            self.spare.push(back);
        }
        self.undo.active = false;
        self.undo.delta_saved = false;
    }

    /// Back to the window of the checkpoint, whatever happened since; nothing without one.
    pub fn rollback(&mut self) {
        if !self.undo.active {
            return;
        }
        while self.epochs.len() > self.undo.kept {
            if let Some((_, back)) = self.epochs.pop_back() {
                self.spare.push(back);
            }
        }
        while let Some(epoch) = self.undo.dropped.pop() {
            self.epochs.push_front(epoch);
        }
        if self.undo.delta_saved {
            std::mem::swap(&mut self.delta, &mut self.undo.delta);
        }
        self.undo.active = false;
        self.undo.delta_saved = false;
    }

    /// Epochs held.
    pub fn len(&self) -> usize {
        self.epochs.len()
    }

    /// Whether no epoch is held.
    pub fn is_empty(&self) -> bool {
        self.epochs.is_empty()
    }

    /// Bytes held by back-pointers and scores, for memory accounting.
    pub fn memory_bytes(&self) -> usize {
        let epochs = self.epochs.iter().chain(&self.undo.dropped).map(|e| &e.1);
        epochs.chain(&self.spare).map(KeptPointers::bytes).sum::<usize>()
            + self.back.as_ref().map_or(0, BackPointers::bytes)
            + 3 * self.delta.len() * 8
    }

    /// What [`memory_bytes`](Self::memory_bytes) stays below for `n` states and `capacity`
    /// epochs: every epoch (and one more, while a step runs) listing every state, the step's
    /// own back-pointers and three score vectors.
    pub fn memory_bound_bytes(n: usize, capacity: usize) -> usize {
        let width = if n <= 1 << 16 { 2 } else { 4 };
        let words = n.div_ceil(64);
        (capacity.max(1) + 1) * (n * width + words * (8 + 4)) + n * width + 3 * n * 8
    }

    /// Adds an epoch: `transition` from the previous one (ignored for the first epoch of the
    /// window, which starts from a uniform prior) and the observation's log-likelihoods.
    /// Emissions that are NaN count as impossible.
    pub fn step(&mut self, timestamp_ns: u64, transition: &dyn Transition, ln_emission: &[f64]) {
        let mut row = std::mem::take(&mut self.row);
        self.step_with(timestamp_ns, ln_emission, |delta, out, back| match back {
            BackPointers::Narrow(back) => viterbi_step(transition, delta, out, back, &mut row),
            BackPointers::Wide(back) => viterbi_step(transition, delta, out, back, &mut row),
        });
        self.row = row;
    }

    /// States the window scores.
    pub fn state_count(&self) -> usize {
        self.delta.len()
    }

    /// [`step`](Self::step) with the max-product step given: `expand(delta, out, back)` writes
    /// `out` and `back` from the scores `delta` as [`viterbi_step`] does (not called for the
    /// window's first epoch).
    pub(super) fn step_with(
        &mut self,
        timestamp_ns: u64,
        ln_emission: &[f64],
        expand: impl FnOnce(&[f64], &mut [f64], &mut BackPointers),
    ) {
        let n = self.delta.len();
        let mut kept = self.spare.pop().unwrap_or_else(|| KeptPointers::empty(n));
        if self.epochs.is_empty() {
            self.next.copy_from_slice(ln_emission);
        } else {
            let back = self.back.get_or_insert_with(|| BackPointers::new(n));
            expand(&self.delta, &mut self.next, back);
            for (d, &e) in self.next.iter_mut().zip(ln_emission) {
                *d += e;
            }
            kept.keep(back);
        }
        let max = self.next.iter().copied().filter(|v| !v.is_nan()).fold(f64::NEG_INFINITY, f64::max);
        if !max.is_finite() {
            // Nothing explains the observation: restart the window from it alone.
            self.spare.push(kept);
            self.reset();
            self.next.fill(0.0);
            self.replace_delta();
            return;
        }
        for v in self.next.iter_mut() {
            *v = if v.is_nan() { f64::NEG_INFINITY } else { *v - max };
        }
        self.replace_delta();
        if self.epochs.len() == self.capacity {
            self.drop_oldest();
        }
        self.epochs.push_back((timestamp_ns, kept));
    }

    /// Weights the newest epoch's scores by `ln_emission` without adding an epoch (feedback
    /// about that epoch). When no state keeps a finite score (the feedback contradicts what the
    /// window holds), the newest epoch's scores restart from `ln_emission` alone; the
    /// back-pointers into earlier epochs stay valid, every state has one. Nothing without an
    /// epoch.
    pub fn pin(&mut self, ln_emission: &[f64]) {
        if self.epochs.is_empty() {
            return;
        }
        for ((n, &d), &e) in self.next.iter_mut().zip(&self.delta).zip(ln_emission) {
            *n = d + e;
        }
        let best = |v: &[f64]| v.iter().copied().filter(|x| !x.is_nan()).fold(f64::NEG_INFINITY, f64::max);
        let mut max = best(&self.next);
        if !max.is_finite() {
            self.next.copy_from_slice(ln_emission);
            max = best(&self.next);
            if !max.is_finite() {
                return;
            }
        }
        for v in self.next.iter_mut() {
            *v = if v.is_nan() { f64::NEG_INFINITY } else { *v - max };
        }
        self.replace_delta();
    }

    /// The most likely path through the window, oldest first, as (timestamp, state).
    pub fn path(&self) -> Vec<(u64, u32)> {
        let Some(mut state) =
            self.delta.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).map(|(i, _)| i as u32)
        else {
            return Vec::new();
        };
        let mut path = Vec::with_capacity(self.epochs.len());
        for (k, (timestamp, back)) in self.epochs.iter().enumerate().rev() {
            path.push((*timestamp, state));
            if k > 0 {
                state = back.get(state as usize) as u32;
            }
        }
        path.reverse();
        path
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::hmm::transition::DenseTransition as Dense;

    #[test]
    fn kept_pointers_give_back_every_pointer() {
        // A fixed LCG: pointers mostly to one state, or spread with no majority at all.
        let mut seed = 11u64;
        let mut next = |m: u64| {
            seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            (seed >> 33) % m
        };
        let mut kept = KeptPointers::empty(300);
        for (n, listed_in) in [(300usize, 10u64), (300, 1), (130, 2), (64, 3), (1, 1), (0, 1)] {
            let all: Vec<u16> =
                (0..n).map(|_| if next(listed_in) == 0 { next(n as u64) as u16 } else { 7 }).collect();
            let back = BackPointers::Narrow(all.clone());
            kept.keep(&back);
            for (j, &p) in all.iter().enumerate() {
                assert_eq!(kept.get(j), usize::from(p), "n {n}, state {j}");
            }
            if listed_in > 2 {
                // Fresh buffers hold the bitmap, the counts and the listed pointers alone.
                let mut fresh = KeptPointers::empty(n);
                fresh.keep(&back);
                let listed = all.iter().filter(|&&p| p != 7).count();
                assert_eq!(fresh.shared, 7);
                assert!(fresh.bytes() < all.len() * 2, "{} bytes for {listed} listed", fresh.bytes());
            }
        }
        // 32-bit pointers, into buffers built for 16-bit ones.
        let wide: Vec<u32> = (0..200).map(|j| if j % 5 == 0 { 70_000 + j } else { 3 }).collect();
        kept.keep(&BackPointers::Wide(wide.clone()));
        assert!((0..200).all(|j| kept.get(j) == wide[j] as usize));
        assert_eq!(majority::<u8>(&[]), None);
        assert_eq!(majority(&[1, 2, 1, 3, 1]), Some(1));
    }

    /// The best path by trying every path.
    fn brute_force(a: &[Vec<f64>], emissions: &[Vec<f64>]) -> Vec<u32> {
        let n = a.len();
        let t_len = emissions.len();
        let mut best = (f64::NEG_INFINITY, Vec::new());
        for code in 0..n.pow(t_len as u32) {
            let path: Vec<usize> = (0..t_len).map(|t| (code / n.pow(t as u32)) % n).collect();
            let mut score = emissions[0][path[0]];
            for t in 1..t_len {
                score += a[path[t - 1]][path[t]].ln() + emissions[t][path[t]];
            }
            if score > best.0 {
                best = (score, path.iter().map(|&s| s as u32).collect());
            }
        }
        best.1
    }

    #[test]
    fn matches_brute_force_and_forgets_beyond_the_window() {
        let a = vec![vec![0.6, 0.3, 0.1], vec![0.2, 0.5, 0.3], vec![0.1, 0.1, 0.8]];
        let emissions = [
            vec![-0.1, -2.0, -3.0],
            vec![-1.5, -0.4, -2.0],
            vec![-2.0, -1.9, -0.3],
            vec![-0.2, -2.5, -0.9],
            vec![-3.0, -0.1, -1.0],
        ];
        let dense = Dense(a.clone());
        let mut window = ViterbiWindow::new(3, 10);
        for (t, e) in emissions.iter().enumerate() {
            window.step(t as u64, &dense, e);
            let expected = brute_force(&a, &emissions[..=t]);
            let got: Vec<u32> = window.path().iter().map(|p| p.1).collect();
            assert_eq!(got, expected, "after epoch {t}");
        }
        let mut short = ViterbiWindow::new(3, 2);
        for (t, e) in emissions.iter().enumerate() {
            short.step(t as u64, &dense, e);
        }
        assert_eq!(short.len(), 2);
        assert_eq!(short.path().iter().map(|p| p.0).collect::<Vec<_>>(), vec![3, 4]);
    }

    #[test]
    fn pinning_the_newest_epoch_is_adding_to_its_emission() {
        let a = vec![vec![0.6, 0.3, 0.1], vec![0.2, 0.5, 0.3], vec![0.1, 0.1, 0.8]];
        let mut emissions = vec![vec![-0.1, -2.0, -3.0], vec![-1.5, -0.4, -2.0], vec![-2.0, -1.9, -0.3]];
        let dense = Dense(a.clone());
        let mut window = ViterbiWindow::new(3, 10);
        for (t, e) in emissions.iter().enumerate() {
            window.step(t as u64, &dense, e);
        }
        let pin = [f64::NEG_INFINITY, 0.0, f64::NEG_INFINITY];
        window.pin(&pin);
        emissions[2][0] = -1e6;
        emissions[2][2] = -1e6;
        let got: Vec<u32> = window.path().iter().map(|p| p.1).collect();
        assert_eq!(got, brute_force(&a, &emissions));
        assert_eq!(got[2], 1);
        // A contradicting pin restarts the newest scores from it.
        window.pin(&[0.0, f64::NEG_INFINITY, f64::NEG_INFINITY]);
        assert_eq!(window.path().last().map(|p| p.1), Some(0));
        assert_eq!(window.len(), 3);
        let mut empty = ViterbiWindow::new(3, 2);
        empty.pin(&pin);
        assert!(empty.path().is_empty());
    }

    #[test]
    fn rollback_returns_to_the_checkpoint_and_commit_keeps_the_step() {
        let dense = Dense(vec![vec![0.6, 0.3, 0.1], vec![0.2, 0.5, 0.3], vec![0.1, 0.1, 0.8]]);
        let emissions = [[-0.1, -2.0, -3.0], [-1.5, -0.4, -2.0], [-2.0, -1.9, -0.3], [-0.2, -2.5, -0.9]];
        let mut window = ViterbiWindow::new(3, 2);
        window.step(0, &dense, &emissions[0]);
        window.step(1, &dense, &emissions[1]);
        let before = format!("{window:?}");
        // A step into the full window drops its oldest epoch.
        window.checkpoint();
        window.step(2, &dense, &emissions[2]);
        assert_ne!(format!("{window:?}"), before);
        window.rollback();
        assert_eq!(format!("{window:?}"), before);
        // Nothing explains the observation: the window restarts; undone too.
        window.checkpoint();
        window.step(2, &dense, &[f64::NEG_INFINITY; 3]);
        assert!(window.is_empty());
        window.rollback();
        assert_eq!(format!("{window:?}"), before);
        assert_eq!(window.path().iter().map(|p| p.0).collect::<Vec<_>>(), vec![0, 1]);
        // Committed, the step stays, and the window goes on as one that never saved anything.
        let mut twin = window.clone();
        window.checkpoint();
        window.step(2, &dense, &emissions[2]);
        window.commit();
        window.rollback();
        for (t, e) in emissions.iter().enumerate().skip(2) {
            if t > 2 {
                window.step(t as u64, &dense, e);
            }
            twin.step(t as u64, &dense, e);
        }
        assert_eq!(format!("{window:?}"), format!("{twin:?}"));
        // As many epochs' buffers held (their sizes follow what each epoch listed).
        let buffers = |w: &ViterbiWindow| w.epochs.len() + w.spare.len() + w.undo.dropped.len();
        assert_eq!(buffers(&window), buffers(&twin));
        assert!(
            window.memory_bytes() <= ViterbiWindow::memory_bound_bytes(window.state_count(), window.capacity)
        );
    }
}
