//! The radio map: every state's fingerprint, stored by transmitter so that a scan costs
//! O(states + fingerprint entries of the transmitters heard), not O(states × transmitters).
//!
//! Entries are 4-byte words: the step from the previous entry's state, the mean in 0.01 dB
//! above the map's lowest and an index into the map's table of distinct standard deviations
//! (also in 0.01 dB), with field widths fitted to the map (`Layout`), so that a large site's
//! engine keeps within its memory budget (docs/tuning.md#engine-speed). ln p(absent) is
//! computed when a transmitter is heard, by [`LnCdfTable`].

use super::{Gaussian, LnCdfTable, RssiModel, TransmitterId};
mod likelihood;

pub use likelihood::{BeliefMoments, ResolvedScan};

use hashbrown::hash_table::{Entry, HashTable};
use std::hash::{BuildHasher, BuildHasherDefault, DefaultHasher};

/// Resolution of the stored RSSI levels and spreads: 0.01 dB, a hundredth of the 1 dBm step
/// phones report RSSI in, so storing it changes no likelihood a reading can tell apart.
pub const LEVEL_STEP_DB: f64 = 0.01;

/// Largest |mean| of a fingerprint model, dBm: the 0.01 dB steps fit an `i16` (±327.67 dBm).
/// Phones report about -130 to +20 dBm.
pub const MAX_ABS_LEVEL_DBM: f64 = 320.0;

/// Smallest standard deviation of a fingerprint model, dB: one [`LEVEL_STEP_DB`]. Found with
/// the `site_file` fuzz harness: with σ of 1e-300 dB every reading off the mean had a
/// likelihood of exactly 0 at every state, and no state explained any scan. Phones report
/// whole dBm and the survey's fits stop at 1 dB.
pub const MIN_STD_DB: f64 = LEVEL_STEP_DB;

/// Largest standard deviation of a fingerprint model, dB: the steps fit a `u16` (655.35 dB).
/// The survey caps its fits far below.
pub const MAX_STORED_STD_DB: f64 = 650.0;

/// How an entry's fields share its 32-bit word: from the top, the step from the previous
/// entry's state, the mean's 0.01 dB steps above the map's lowest mean, and the spread index,
/// each as wide as the map needs. The mean and the spread need at most 16 bits each; whatever
/// is left holds the step, and an entry whose step does not fit starts a new run with its
/// state written out ([`RadioMap`]'s `runs`). On a surveyed site most entries are one state
/// after the previous one, so runs are rare (docs/tuning.md#engine-speed).
#[derive(Clone, Copy, Debug)]
struct Layout {
    /// The map's lowest mean, in [`LEVEL_STEP_DB`].
    lowest_mean: i32,
    mean_shift: u32,
    mean_mask: u32,
    spread_mask: u32,
    step_shift: u32,
    step_mask: u32,
}

impl Layout {
    /// The narrowest fields for means in `lowest..=highest` steps and `spreads` distinct spreads
    /// (at least one).
    fn fit(lowest: i32, highest: i32, spreads: usize) -> Self {
        let bits = |largest: u32| u32::BITS - largest.leading_zeros();
        let mean_bits = bits((highest - lowest) as u32);
        let spread_bits = bits(spreads.saturating_sub(1) as u32);
        let step_bits = u32::BITS - mean_bits - spread_bits;
        let mask = |width: u32| if width == 0 { 0 } else { u32::MAX >> (u32::BITS - width) };
        Layout {
            lowest_mean: lowest,
            mean_shift: spread_bits,
            mean_mask: mask(mean_bits),
            spread_mask: mask(spread_bits),
            // Shifts stay below 32; a field of no bits reads 0 through its mask.
            step_shift: (mean_bits + spread_bits).min(u32::BITS - 1),
            step_mask: mask(step_bits),
        }
    }

    /// The word of an entry `step` states after the previous one, if the step fits.
    fn encode(&self, step: u32, mean: i16, spread: u16) -> Option<u32> {
        let mean = (i32::from(mean) - self.lowest_mean) as u32;
        debug_assert!(mean & !self.mean_mask == 0 && u32::from(spread) & !self.spread_mask == 0);
        (step <= self.step_mask).then(|| {
            let step = if self.step_mask == 0 { 0 } else { step << self.step_shift };
            step | mean << self.mean_shift | u32::from(spread)
        })
    }

    /// (step, mean in [`LEVEL_STEP_DB`], spread index) of a word.
    #[inline]
    fn decode(&self, word: u32) -> (usize, i32, usize) {
        let (step, field, spread) = self.decode_field(word);
        (step, self.lowest_mean + field as i32, spread)
    }

    /// (step, mean in [`LEVEL_STEP_DB`] above the lowest, spread index) of a word.
    #[inline]
    fn decode_field(&self, word: u32) -> (usize, u32, usize) {
        let step = (word >> self.step_shift) & self.step_mask;
        let field = (word >> self.mean_shift) & self.mean_mask;
        (step as usize, field, (word & self.spread_mask) as usize)
    }
}

/// A standard deviation that entries share, with what scoring needs of it.
#[derive(Clone, Copy, Debug)]
struct Spread {
    /// σ in [`LEVEL_STEP_DB`] steps.
    steps: u16,
    /// 1/σ, 1/dB.
    inverse: f64,
    /// σ², dB², as 1/(1/σ)².
    variance: f64,
    /// ln σ.
    ln: f64,
    /// w = (c - μ)/σ, the clip level in σ from the mean, is `clip_at_lowest - field ·
    /// clip_per_step` for an entry whose mean field is `field` (μ = the map's lowest mean +
    /// field steps): one multiply-add per entry when a scan is scored.
    clip_at_lowest: f64,
    clip_per_step: f64,
}

/// The hash [`RadioMap`] finds a transmitter by: std's SipHash with its fixed keys, the same
/// on every run.
fn id_hash(id: &TransmitterId) -> u64 {
    BuildHasherDefault::<DefaultHasher>::default().hash_one(id)
}

/// A model's (mean, σ) in [`LEVEL_STEP_DB`] steps, if within the stored range.
pub(crate) fn quantise(g: &Gaussian) -> Option<(i16, u16)> {
    let mean = (g.mean_dbm / LEVEL_STEP_DB).round();
    let std = (g.std_db / LEVEL_STEP_DB).round().max(1.0);
    (g.mean_dbm.abs() <= MAX_ABS_LEVEL_DBM && g.std_db <= MAX_STORED_STD_DB)
        .then_some((mean as i16, std as u16))
}

/// A stored level or spread in dB.
fn level(steps: impl Into<f64>) -> f64 {
    steps.into() / 100.0
}

/// Fingerprints of every state, ready to score scans (Hoang eqs. 9-10).
///
/// Every transmitter of the map enters every state's likelihood: heard ones through their
/// reading, the others as "below the clip level" (eq. 10). A state with no model of a
/// transmitter uses the map's `unheard` model for it (Hoang §3: μ ≪ c, average σ).
/// Fingerprint models are stored to 0.01 dB; [`fingerprints`](Self::fingerprints)
/// returns the stored values.
#[derive(Clone, Debug)]
pub struct RadioMap {
    model: RssiModel,
    clip_dbm: f64,
    unheard: Gaussian,
    unheard_ln_absent: f64,
    ids: Vec<TransmitterId>,
    /// The transmitters' indices by the hash of their ids: a scan's readings are matched in
    /// constant time, and no second copy of an id is held (docs/tuning.md#engine-speed).
    by_id: HashTable<u32>,
    /// The entries' words, by transmitter and, within one, by state.
    words: Vec<u32>,
    /// (first word, its state) of each run of words; a run's later words step on from the
    /// state before. The runs of transmitter `t` are `runs[run_starts[t]..run_starts[t + 1]]`,
    /// and a last run marks where the words end.
    runs: Vec<(u32, u32)>,
    run_starts: Vec<u32>,
    layout: Layout,
    /// The distinct standard deviations of the entries (a few hundred on a real site).
    spreads: Vec<Spread>,
    /// Per radio kind (WiFi, BLE), per state: ln p(every transmitter of that kind absent |
    /// state).
    all_absent: [Vec<f64>; 2],
    /// Radio kind of each transmitter (index into `all_absent`).
    kinds: Vec<u8>,
    /// Groups of two or more transmitters that one radio sends (an access point's several
    /// networks): [`with_shared_radios`](Self::with_shared_radios).
    shared_radios: Vec<Vec<u32>>,
    /// Each transmitter's weight in a scan's likelihood: 1 / the size of its group, 1 alone.
    weights: Vec<f64>,
    /// Per radio kind, the transmitters' summed weights: how many radios of that kind a scan
    /// hearing none of them misses.
    kind_weights: [f64; 2],
}

/// Index of a transmitter's radio in [`RadioMap`]'s per-kind tables: a WiFi scan says nothing
/// about beacons, and a beacon scan nothing about access points.
fn kind(id: &TransmitterId) -> u8 {
    u8::from(id.is_ble())
}

impl RadioMap {
    /// Builds a map over `state_count` states from `(state, transmitter, model)` triples,
    /// storing each model to 0.01 dB.
    ///
    /// Fails, with a message, on a duplicate transmitter id, an index out of range, a model
    /// outside the stored range (levels within ±320 dBm, spreads up to 650 dB) or a transmitter
    /// modelled twice at one state.
    pub fn new(
        model: RssiModel,
        clip_dbm: f64,
        unheard: Gaussian,
        ids: Vec<TransmitterId>,
        state_count: usize,
        fingerprints: impl IntoIterator<Item = (u32, u32, Gaussian)>,
    ) -> Result<Self, String> {
        let steps = fingerprints.into_iter().map(|(state, tx, g)| {
            let (mean, std) = quantise(&g).ok_or_else(|| {
                format!(
                    "the model of transmitter {tx} at state {state} (mean {} dBm, σ {} dB) is outside \
                     the stored range (mean within ±{MAX_ABS_LEVEL_DBM} dBm, σ at most {MAX_STORED_STD_DB} dB)",
                    g.mean_dbm, g.std_db
                )
            })?;
            Ok((state, tx, mean, std))
        });
        Self::from_steps(model, clip_dbm, unheard, ids, state_count, steps)
    }

    /// [`RadioMap::new`] from `(state, transmitter, mean, σ)` already in [`LEVEL_STEP_DB`]
    /// steps, as a binary site file stores them, or the error that reading one met: a load
    /// then holds no list of the models besides this map's (docs/tuning.md#engine-speed).
    pub(crate) fn from_steps(
        model: RssiModel,
        clip_dbm: f64,
        unheard: Gaussian,
        ids: Vec<TransmitterId>,
        state_count: usize,
        fingerprints: impl Iterator<Item = Result<(u32, u32, i16, u16), String>>,
    ) -> Result<Self, String> {
        let Ok(count) = u32::try_from(ids.len()) else {
            return Err(format!("{} transmitters are more than a map holds", ids.len()));
        };
        let mut by_id = HashTable::with_capacity(ids.len());
        for (t, id) in (0..count).zip(&ids) {
            match by_id.entry(id_hash(id), |&u: &u32| ids[u as usize] == *id, |&u| id_hash(&ids[u as usize]))
            {
                Entry::Occupied(_) => return Err(format!("transmitter {id} is listed twice")),
                Entry::Vacant(slot) => {
                    slot.insert(t);
                }
            }
        }
        // Quantised first: 12 bytes a model while the map is built, where the f64 triples
        // took 24.
        let (max_mean, max_std) = (MAX_ABS_LEVEL_DBM / LEVEL_STEP_DB, MAX_STORED_STD_DB / LEVEL_STEP_DB);
        let mut quantised = Vec::with_capacity(fingerprints.size_hint().0);
        for entry in fingerprints {
            let (state, tx, mean, std) = entry?;
            if state as usize >= state_count || tx as usize >= ids.len() {
                return Err(format!("fingerprint entry (state {state}, transmitter {tx}) is out of range"));
            }
            if f64::from(mean).abs() > max_mean || !(1.0..=max_std).contains(&f64::from(std)) {
                return Err(format!(
                    "the model of transmitter {tx} at state {state} ({mean}, {std} steps of {LEVEL_STEP_DB} dB) \
                     is outside the stored range"
                ));
            }
            quantised.push((state, tx, mean, std));
        }
        // The table of distinct spreads, indexed by their steps.
        let mut spread_of = vec![u16::MAX; usize::from(u16::MAX) + 1];
        let mut spreads = Vec::new();
        for &(_, _, _, std) in &quantised {
            if spread_of[usize::from(std)] == u16::MAX {
                spread_of[usize::from(std)] = spreads.len() as u16;
                let sigma = level(std);
                spreads.push(Spread {
                    steps: std,
                    inverse: 1.0 / sigma,
                    variance: 1.0 / (sigma.recip() * sigma.recip()),
                    ln: sigma.ln(),
                    clip_at_lowest: 0.0,
                    clip_per_step: 0.0,
                });
            }
        }
        let unheard_ln_absent = model.ln_absent(&unheard, clip_dbm);
        let kinds: Vec<u8> = ids.iter().map(kind).collect();
        // Bucket by transmitter (a counting sort: O(entries), where sorting took a quarter of
        // the load time of a 10 000-state site), keeping the given order within a bucket.
        let mut starts = vec![0usize; ids.len() + 1];
        for &(_, tx, _, _) in &quantised {
            starts[tx as usize + 1] += 1;
        }
        for t in 0..ids.len() {
            starts[t + 1] += starts[t];
        }
        let mut fill = starts.clone();
        let (mut lowest, mut highest) = (i32::MAX, i32::MIN);
        // (state, mean, spread index), bucketed, until the words are written.
        let mut entries = vec![(0u32, 0i16, 0u16); quantised.len()];
        for (state, tx, mean, std) in quantised {
            entries[fill[tx as usize]] = (state, mean, spread_of[usize::from(std)]);
            fill[tx as usize] += 1;
            (lowest, highest) = (lowest.min(i32::from(mean)), highest.max(i32::from(mean)));
        }
        // Site files list entries state by state, so buckets come out sorted; any other
        // order is sorted here. Then a repeated state is a transmitter modelled twice.
        for t in 0..ids.len() {
            let bucket = &mut entries[starts[t]..starts[t + 1]];
            if !bucket.windows(2).all(|w| w[0].0 <= w[1].0) {
                bucket.sort_by_key(|e| e.0);
            }
            if let Some(w) = bucket.windows(2).find(|w| w[0].0 == w[1].0) {
                return Err(format!("state {} models transmitter {} twice", w[0].0, ids[t]));
            }
        }
        let (lowest, highest) = if entries.is_empty() { (0, 0) } else { (lowest, highest) };
        let layout = Layout::fit(lowest, highest, spreads.len());
        for spread in &mut spreads {
            spread.clip_at_lowest = (clip_dbm - level(lowest)) * spread.inverse;
            spread.clip_per_step = LEVEL_STEP_DB * spread.inverse;
        }
        // Words and runs are indexed in 32 bits: 2³² entries would take 16 GB.
        if !u32::try_from(entries.len()).is_ok_and(|n| n < u32::MAX) {
            return Err(format!("{} fingerprint entries are more than a map holds", entries.len()));
        }
        let mut words = Vec::with_capacity(entries.len());
        let (mut runs, mut run_starts) = (Vec::new(), Vec::with_capacity(ids.len() + 1));
        for t in 0..ids.len() {
            run_starts.push(runs.len() as u32);
            let mut previous = None;
            for &(state, mean, spread) in &entries[starts[t]..starts[t + 1]] {
                let step = previous.map_or(0, |p| state - p);
                let word = match previous.and_then(|_| layout.encode(step, mean, spread)) {
                    Some(word) => word,
                    None => {
                        runs.push((words.len() as u32, state));
                        layout.encode(0, mean, spread).expect("a step of 0 always fits")
                    }
                };
                words.push(word);
                previous = Some(state);
            }
        }
        run_starts.push(runs.len() as u32);
        runs.push((words.len() as u32, 0));
        runs.shrink_to_fit();
        let weights = vec![1.0; ids.len()];
        let kind_weights = [0, 1].map(|k| kinds.iter().filter(|&&x| x == k).count() as f64);
        let all_absent = kind_weights.map(|w| vec![unheard_ln_absent * w; state_count]);
        let mut map = Self {
            model,
            clip_dbm,
            unheard,
            unheard_ln_absent,
            ids,
            by_id,
            words,
            runs,
            run_starts,
            layout,
            spreads,
            all_absent,
            kinds,
            shared_radios: Vec::new(),
            weights,
            kind_weights,
        };
        let mut sums = std::mem::take(&mut map.all_absent);
        for t in 0..map.ids.len() {
            map.add_absent_terms(t, 1.0, &mut sums);
        }
        map.all_absent = sums;
        Ok(map)
    }

    /// The same map with `radios` as the groups of transmitters that one radio sends: an
    /// access point that serves several networks reports each under its own BSSID, at the
    /// same level from the same antenna, so a scan hears the same reading several times.
    /// Each member then weighs 1 / the group's size in a scan's likelihood, so that the radio
    /// counts once, as eq. 9's product over independent transmitters assumes
    /// (docs/tuning.md#shared-radios). Fails, with a message, on a group of fewer than two, a
    /// transmitter index out of range, or a transmitter in two groups.
    pub fn with_shared_radios(mut self, radios: Vec<Vec<u32>>) -> Result<Self, String> {
        if radios.is_empty() && self.shared_radios.is_empty() {
            return Ok(self);
        }
        let mut weights = vec![1.0; self.ids.len()];
        for (k, radio) in radios.iter().enumerate() {
            if radio.len() < 2 {
                return Err(format!(
                    "radio {k} lists {} transmitters; a shared radio lists two or more",
                    radio.len()
                ));
            }
            for &t in radio {
                match weights.get_mut(t as usize) {
                    None => return Err(format!("radio {k} lists transmitter {t}, which does not exist")),
                    Some(w) if *w != 1.0 => return Err(format!("transmitter {t} is in two radios")),
                    Some(w) => *w = 1.0 / radio.len() as f64,
                }
            }
        }
        // Only the transmitters whose weight changed move the absent sums.
        let mut sums = std::mem::take(&mut self.all_absent);
        let mut kind_change = [0.0; 2];
        for (t, (&new, &old)) in weights.iter().zip(&self.weights).enumerate() {
            if new != old {
                self.add_absent_terms(t, new - old, &mut sums);
                kind_change[usize::from(self.kinds[t])] += new - old;
            }
        }
        for (k, change) in kind_change.into_iter().enumerate() {
            if change != 0.0 {
                sums[k].iter_mut().for_each(|v| *v += self.unheard_ln_absent * change);
                self.kind_weights[k] += change;
            }
        }
        self.all_absent = sums;
        self.weights = weights;
        self.shared_radios = radios;
        Ok(self)
    }

    /// The groups of transmitters that one radio sends ([`with_shared_radios`](Self::with_shared_radios)).
    pub fn shared_radios(&self) -> &[Vec<u32>] {
        &self.shared_radios
    }

    /// How many radios `observations` heard: each transmitter counts its weight, so the
    /// networks of one access point count once.
    pub fn radios_heard(&self, observations: &[(u32, f64)]) -> f64 {
        observations.iter().map(|&(t, _)| self.weights[t as usize]).sum()
    }

    /// Adds to `sums` (per radio kind, per state: ln p(every transmitter of that kind absent |
    /// state)) `factor` times what transmitter `t` changes there against the unheard model, at
    /// each state that models it. By the table, as scoring takes it: the exact ln Φ per entry
    /// was half the load time of a 10 000-state site.
    fn add_absent_terms(&self, t: usize, factor: f64, sums: &mut [Vec<f64>; 2]) {
        let table = LnCdfTable::get();
        let sum = &mut sums[usize::from(self.kinds[t])];
        for (state, mean, spread) in self.entries(t as u32) {
            let (mean_dbm, std_db) = (level(mean), level(self.spreads[spread].steps));
            let ln_absent = match self.model {
                RssiModel::CensoredGaussian => table.ln_cdf((self.clip_dbm - mean_dbm) / std_db),
                RssiModel::NaiveGaussian => {
                    self.model.ln_absent(&Gaussian { mean_dbm, std_db }, self.clip_dbm)
                }
            };
            sum[state] += factor * (ln_absent - self.unheard_ln_absent);
        }
    }

    /// The likelihood model.
    pub fn model(&self) -> RssiModel {
        self.model
    }

    /// Receiver clip level c, dBm.
    pub fn clip_dbm(&self) -> f64 {
        self.clip_dbm
    }

    /// The model of a transmitter at a state that never heard it.
    pub fn unheard(&self) -> Gaussian {
        self.unheard
    }

    /// Transmitters, by index.
    pub fn transmitters(&self) -> &[TransmitterId] {
        &self.ids
    }

    /// Number of states the map covers.
    pub fn state_count(&self) -> usize {
        self.all_absent[0].len()
    }

    /// Every `(state, transmitter, model)` of the map, by transmitter.
    pub fn fingerprints(&self) -> impl Iterator<Item = (u32, u32, Gaussian)> + '_ {
        (0..self.ids.len()).flat_map(move |t| {
            self.entries(t as u32).map(move |(state, mean, spread)| {
                let std_db = level(self.spreads[spread].steps);
                (state as u32, t as u32, Gaussian { mean_dbm: level(mean), std_db })
            })
        })
    }

    /// The entries of transmitter `t` as (state, mean in [`LEVEL_STEP_DB`], spread index), by
    /// state.
    fn entries(&self, t: u32) -> impl Iterator<Item = (usize, i32, usize)> + '_ {
        self.runs(t).flat_map(move |(first, words)| {
            let mut state = first as usize;
            words.iter().map(move |&word| {
                let (step, mean, spread) = self.layout.decode(word);
                state += step;
                (state, mean, spread)
            })
        })
    }

    /// The runs of transmitter `t`: (the state of the first word, whose step is 0, the words).
    #[inline]
    fn runs(&self, t: u32) -> impl Iterator<Item = (u32, &[u32])> + '_ {
        let runs =
            &self.runs[self.run_starts[t as usize] as usize..=self.run_starts[t as usize + 1] as usize];
        runs.windows(2).map(|run| (run[0].1, &self.words[run[0].0 as usize..run[1].0 as usize]))
    }

    /// Heap bytes of the fingerprint entries and their tables (what grows with the site).
    pub fn memory_bytes(&self) -> usize {
        self.words.capacity() * std::mem::size_of::<u32>()
            + self.runs.capacity() * std::mem::size_of::<(u32, u32)>()
            + self.run_starts.capacity() * std::mem::size_of::<u32>()
            + self.by_id.allocation_size()
            + self.spreads.capacity() * std::mem::size_of::<Spread>()
            + self.all_absent.iter().map(|v| v.capacity() * 8).sum::<usize>()
            + self.weights.capacity() * 8
            + self.shared_radios.iter().map(|r| r.capacity() * 4).sum::<usize>()
    }
}

#[cfg(test)]
mod tests;
