//! The radio map: every state's fingerprint, stored by transmitter so that a scan costs
//! O(states + fingerprint entries of the transmitters heard), not O(states × transmitters).
//!
//! Entries are 4-byte words: the step from the previous entry's state, the mean in 0.01 dB
//! above the map's lowest and an index into the map's table of distinct standard deviations
//! (also in 0.01 dB), with field widths fitted to the map (`Layout`), so that a large site's
//! engine keeps within its memory budget (docs/tuning.md#engine-speed). ln p(absent) is
//! computed when a transmitter is heard, by [`LnCdfTable`].

use super::{ln_std_normal_pdf, Gaussian, LnCdfTable, RssiModel, Scan, TransmitterId};
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
/// Fingerprint models are stored to [`LEVEL_STEP_DB`]; [`fingerprints`](Self::fingerprints)
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
    match id {
        TransmitterId::Wifi { .. } | TransmitterId::HashedWifi { .. } => 0,
        TransmitterId::Ble { .. } | TransmitterId::BleAddress { .. } | TransmitterId::HashedBle { .. } => 1,
    }
}

/// A scan matched against the map: what the likelihood uses, and what was left out.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ResolvedScan {
    /// (transmitter index, RSSI dBm), one per transmitter.
    pub observations: Vec<(u32, f64)>,
    /// Readings of transmitters the map does not know (no information about any state).
    pub unknown: usize,
    /// Readings of a transmitter already in the scan; the freshest, then strongest, is kept.
    pub duplicates: usize,
    /// Readings older than the age limit.
    pub stale: usize,
}

impl RadioMap {
    /// Builds a map over `state_count` states from `(state, transmitter, model)` triples,
    /// storing each model to [`LEVEL_STEP_DB`].
    ///
    /// Fails, with a message, on a duplicate transmitter id, an index out of range, a model
    /// outside the stored range ([`MAX_ABS_LEVEL_DBM`], [`MAX_STORED_STD_DB`]) or a transmitter
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

    /// Matches a scan's readings to the map's transmitters, dropping (and counting) unknown,
    /// duplicate and, with `max_age_ns`, stale readings. RSSI values must already be finite.
    pub fn resolve(&self, scan: &Scan, max_age_ns: Option<u64>) -> ResolvedScan {
        let mut resolved = ResolvedScan::default();
        let mut found: Vec<(u32, u64, f64)> = Vec::with_capacity(scan.readings.len());
        for reading in &scan.readings {
            if max_age_ns.is_some_and(|max| reading.age_ns > max) {
                resolved.stale += 1;
                continue;
            }
            let id = &reading.transmitter;
            match self.by_id.find(id_hash(id), |&t| self.ids[t as usize] == *id) {
                Some(&t) => found.push((t, reading.age_ns, reading.rssi_dbm)),
                None => resolved.unknown += 1,
            }
        }
        // Freshest first, then strongest, so dedup keeps that one.
        found.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.cmp(&b.1)).then(b.2.total_cmp(&a.2)));
        let before = found.len();
        found.dedup_by_key(|r| r.0);
        resolved.duplicates = before - found.len();
        resolved.observations = found.into_iter().map(|(t, _, rssi)| (t, rssi)).collect();
        resolved
    }

    /// ln p(scan | state) for every state (Hoang eqs. 9-10), written into `out`.
    ///
    /// Eq. 10's "absent" terms cover the transmitters of the radios the scan used — WiFi if it
    /// heard any access point, BLE if it heard any beacon — so a beacon-only scan is not read
    /// as "no access point in range". `out.len()` must equal [`state_count`](Self::state_count).
    ///
    /// Returns ln p(scan) for a state that models none of the transmitters (every reading from
    /// the unheard model): what the scan is worth without a fingerprint.
    pub fn ln_likelihood(&self, observations: &[(u32, f64)], out: &mut [f64]) -> f64 {
        debug_assert_eq!(out.len(), self.state_count());
        let terms = self.scan_terms(observations);
        // As `absent_terms`, a radio at a time.
        match terms.scanned {
            [true, true] => {
                for (o, (w, b)) in out.iter_mut().zip(self.all_absent[0].iter().zip(&self.all_absent[1])) {
                    *o = w + b;
                }
            }
            [true, false] => out.copy_from_slice(&self.all_absent[0]),
            [false, true] => out.copy_from_slice(&self.all_absent[1]),
            [false, false] => out.fill(0.0),
        }
        for &(t, rssi) in observations {
            // What hearing `rssi` changes for a state using the unheard model...
            let unheard_delta = self.unheard_delta(rssi);
            let weight = self.weights[t as usize];
            // ...and, for states that model this transmitter, the difference to their own.
            // A reading at or below the clip level is ln p(absent) for every model: no change.
            if rssi <= self.clip_dbm {
                continue;
            }
            match self.model {
                RssiModel::CensoredGaussian => self.add_censored(t, rssi, unheard_delta, weight, out),
                RssiModel::NaiveGaussian => {
                    for (state, mean, spread) in self.entries(t) {
                        let spread = &self.spreads[spread];
                        let mean = f64::from(mean) * LEVEL_STEP_DB;
                        let (z, z_clip) =
                            ((rssi - mean) * spread.inverse, (self.clip_dbm - mean) * spread.inverse);
                        out[state] += weight * (0.5 * (z_clip * z_clip - z * z) - unheard_delta);
                    }
                }
            }
        }
        for v in out.iter_mut() {
            *v += terms.shared;
        }
        let absent: f64 = (0..2).filter(|&k| terms.scanned[k]).map(|k| self.kind_weights[k]).sum();
        absent * self.unheard_ln_absent + terms.shared
    }

    /// One scan's measurement of the phone's RSSI offset ([`super::DeviceOffset`],
    /// docs/accuracy.md#device-offset): for each reading heard above the clip level, the
    /// reading less the mean μ of the fingerprints of the states that model its transmitter,
    /// weighted by `weights` (where the phone is believed to be, a distribution over states).
    /// A transmitter counts only where the states that model it hold at least half the weight
    /// (elsewhere the belief says little about what it should read), and where that mean, moved
    /// by the current estimate `offset_db`, is two σ or more above the clip level (nearer it,
    /// the phone hears only the readings that came out strong, and their residual is biased
    /// upwards). Returns the mean residual and its variance, the mean over the transmitters
    /// of each reading's variance given the belief (its fingerprints' σ² and the spread of μ
    /// over the believed states): one scan's residuals
    /// share where the phone was believed to be, so they count as one reading, not as many
    /// independent ones (were the belief a few metres off, every transmitter would say so
    /// together); `None` when none counts.
    pub fn offset_residual(
        &self,
        observations: &[(u32, f64)],
        weights: &[f64],
        offset_db: f64,
    ) -> Option<(f64, f64)> {
        let (mut sum, mut variance, mut n) = (0.0, 0.0, 0usize);
        for &(t, rssi) in observations {
            if rssi <= self.clip_dbm {
                continue;
            }
            // Σp, Σp·μ, Σp·μ² and Σp·σ² over the states that model the transmitter.
            let (mut w, mut mean, mut square, mut var) = (0.0, 0.0, 0.0, 0.0);
            // As `entries`, run by run: the nested loops compile to a tighter loop than the
            // flattened iterator (this is as many entries as the scan's likelihood).
            for (first, words) in self.runs(t) {
                let mut state = first as usize;
                for &word in words {
                    let (step, level, spread) = self.layout.decode(word);
                    state += step;
                    let p = weights.get(state).copied().unwrap_or(0.0);
                    if p > 0.0 {
                        let inverse = self.spreads[spread].inverse;
                        let mu = f64::from(level) * LEVEL_STEP_DB;
                        w += p;
                        mean += p * mu;
                        square += p * mu * mu;
                        var += p / (inverse * inverse);
                    }
                }
            }
            if w < 0.5 {
                continue;
            }
            // The reading's variance given the belief: the fingerprints' own σ² and how much μ
            // varies over the believed states (the law of total variance), so that a vague
            // belief measures little.
            let mean = mean / w;
            let var = var / w + (square / w - mean * mean).max(0.0);
            if mean + offset_db - self.clip_dbm < 2.0 * var.sqrt() {
                continue;
            }
            sum += rssi - mean;
            variance += var;
            n += 1;
        }
        (n > 0).then(|| (sum / n as f64, variance / n as f64))
    }

    /// Which states' fingerprints say nothing about a scan, from what
    /// [`ln_likelihood`](Self::ln_likelihood) wrote for it (`ln`): those that model none of
    /// the transmitters heard above the clip level. Such a state explains the scan as a state
    /// with no fingerprint does, give or take its absent terms: its value is exactly its absent
    /// terms plus the terms every state shares, where a state that models a heard transmitter
    /// has that reading's own term added.
    pub fn silent_states<'a>(
        &'a self,
        observations: &[(u32, f64)],
        ln: &'a [f64],
    ) -> impl Iterator<Item = bool> + 'a {
        let terms = self.scan_terms(observations);
        ln.iter()
            .enumerate()
            .map(move |(state, &v)| v == self.absent_terms(terms.scanned, state) + terms.shared)
    }

    /// Adds, at each state that models transmitter `t`, what hearing it at `rssi` changes
    /// against the unheard model: ln φ((r - μ)/σ) - ln σ - ln Φ((c - μ)/σ) - `unheard_delta`,
    /// with (r - μ)/σ = w + (r - c)/σ for w = (c - μ)/σ, times the transmitter's `weight`. Out
    /// of line: on its own the loop keeps its values in registers
    /// (docs/tuning.md#engine-speed).
    #[inline(never)]
    fn add_censored(&self, t: u32, rssi: f64, unheard_delta: f64, weight: f64, out: &mut [f64]) {
        let (layout, table) = (self.layout, LnCdfTable::get());
        let above_clip = rssi - self.clip_dbm;
        let shared = ln_std_normal_pdf(0.0) - unheard_delta;
        for (first, words) in self.runs(t) {
            let mut state = first as usize;
            for &word in words {
                let (step, field, spread) = layout.decode_field(word);
                state += step;
                let spread = &self.spreads[spread];
                let w = spread.clip_at_lowest - f64::from(field) * spread.clip_per_step;
                let z = w + above_clip * spread.inverse;
                out[state] += weight * (shared - 0.5 * z * z - spread.ln - table.ln_cdf(w));
            }
        }
    }

    /// What hearing `rssi` changes for a state that uses the unheard model.
    fn unheard_delta(&self, rssi: f64) -> f64 {
        self.model.ln_heard(&self.unheard, rssi, self.clip_dbm) - self.unheard_ln_absent
    }

    /// The radios a scan used and the sum of its readings' terms at a state with no model of
    /// them, which every state shares.
    fn scan_terms(&self, observations: &[(u32, f64)]) -> ScanTerms {
        let mut terms = ScanTerms { scanned: [false; 2], shared: 0.0 };
        for &(t, rssi) in observations {
            terms.scanned[self.kinds[t as usize] as usize] = true;
            terms.shared += self.weights[t as usize] * self.unheard_delta(rssi);
        }
        terms
    }

    /// ln p(every transmitter of the scanned radios absent | state).
    #[inline]
    fn absent_terms(&self, scanned: [bool; 2], state: usize) -> f64 {
        match scanned {
            [true, true] => self.all_absent[0][state] + self.all_absent[1][state],
            [true, false] => self.all_absent[0][state],
            [false, true] => self.all_absent[1][state],
            [false, false] => 0.0,
        }
    }
}

/// What a scan's readings add to every state alike ([`RadioMap::scan_terms`]).
#[derive(Clone, Copy, Debug)]
struct ScanTerms {
    /// Whether the scan heard WiFi, BLE (the radios whose absent terms count).
    scanned: [bool; 2],
    /// The readings' terms at a state with no model of them.
    shared: f64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::radio::Reading;
    use approx::assert_relative_eq;

    fn wifi(i: u8) -> TransmitterId {
        TransmitterId::wifi(&format!("00:00:00:00:00:{i:02x}")).unwrap()
    }

    fn g(mean: f64, std: f64) -> Gaussian {
        Gaussian::new(mean, std).unwrap()
    }

    fn small_map(model: RssiModel) -> RadioMap {
        // Two states, three transmitters; state 1 never heard transmitter 2.
        let fingerprints = vec![
            (0, 0, g(-60.0, 4.0)),
            (0, 1, g(-80.0, 5.0)),
            (0, 2, g(-95.0, 6.0)),
            (1, 0, g(-75.0, 3.0)),
            (1, 1, g(-65.0, 4.0)),
        ];
        RadioMap::new(model, -100.0, g(-115.0, 5.0), vec![wifi(0), wifi(1), wifi(2)], 2, fingerprints)
            .unwrap()
    }

    /// The dense product of eq. 9 over every transmitter, as a reference.
    fn brute_force(map: &RadioMap, heard: &[(u32, f64)], state: u32) -> f64 {
        let model_of = |t: u32| {
            map.fingerprints().find(|&(s, tx, _)| s == state && tx == t).map_or(map.unheard(), |(_, _, g)| g)
        };
        let scanned = |t: u32| {
            let k = kind(&map.transmitters()[t as usize]);
            heard.iter().any(|h| kind(&map.transmitters()[h.0 as usize]) == k)
        };
        (0..map.transmitters().len() as u32)
            .map(|t| match heard.iter().find(|h| h.0 == t) {
                Some(&(_, rssi)) => map.model().ln_heard(&model_of(t), rssi, -100.0),
                None if scanned(t) => map.model().ln_absent(&model_of(t), -100.0),
                None => 0.0,
            } * map.weights[t as usize])
            .sum()
    }

    #[test]
    fn the_networks_of_one_radio_count_as_one_transmitter() {
        // Transmitters 1 and 2 are one radio: the same model wherever either is modelled.
        let one =
            vec![(0, 0, g(-60.0, 4.0)), (0, 1, g(-80.0, 5.0)), (1, 0, g(-75.0, 3.0)), (1, 1, g(-65.0, 4.0))];
        let two: Vec<_> =
            one.iter().copied().chain(one.iter().filter(|e| e.1 == 1).map(|e| (e.0, 2, e.2))).collect();
        let alone = RadioMap::new(
            RssiModel::CensoredGaussian,
            -100.0,
            g(-115.0, 5.0),
            vec![wifi(0), wifi(1)],
            2,
            one,
        )
        .unwrap();
        let shared = RadioMap::new(
            RssiModel::CensoredGaussian,
            -100.0,
            g(-115.0, 5.0),
            vec![wifi(0), wifi(1), wifi(2)],
            2,
            two,
        )
        .unwrap()
        .with_shared_radios(vec![vec![1, 2]])
        .unwrap();
        for (heard, twice) in [
            (vec![(0, -62.0), (1, -70.0)], vec![(0, -62.0), (1, -70.0), (2, -70.0)]),
            (vec![(0, -62.0)], vec![(0, -62.0)]),
        ] {
            let (mut a, mut b) = (vec![0.0; 2], vec![0.0; 2]);
            assert_relative_eq!(
                alone.ln_likelihood(&heard, &mut a),
                shared.ln_likelihood(&twice, &mut b),
                epsilon = 1e-9
            );
            for s in 0..2 {
                assert_relative_eq!(a[s], b[s], epsilon = 1e-9);
            }
            assert_relative_eq!(alone.radios_heard(&heard), shared.radios_heard(&twice));
        }
        assert_eq!(shared.shared_radios(), [vec![1, 2]]);
    }

    #[test]
    fn shared_radios_must_name_two_or_more_existing_transmitters_once() {
        let map = || small_map(RssiModel::CensoredGaussian);
        assert!(map().with_shared_radios(vec![vec![0]]).unwrap_err().contains("two or more"));
        assert!(map().with_shared_radios(vec![vec![0, 3]]).unwrap_err().contains("does not exist"));
        assert!(map()
            .with_shared_radios(vec![vec![0, 1], vec![1, 2]])
            .unwrap_err()
            .contains("in two radios"));
        assert!(map().with_shared_radios(vec![vec![0, 0]]).unwrap_err().contains("in two radios"));
        let plain = map().with_shared_radios(Vec::new()).unwrap();
        assert_eq!(plain.radios_heard(&[(0, -60.0), (1, -70.0)]), 2.0);
    }

    #[test]
    fn silent_states_model_none_of_the_transmitters_heard() {
        let map = small_map(RssiModel::CensoredGaussian);
        let silent = |heard: &[(u32, f64)]| {
            let mut out = vec![0.0; 2];
            map.ln_likelihood(heard, &mut out);
            map.silent_states(heard, &out).collect::<Vec<_>>()
        };
        // State 1 never heard transmitter 2; both model 0 and 1.
        assert_eq!(silent(&[(2, -92.0)]), [false, true]);
        assert_eq!(silent(&[(0, -62.0), (2, -92.0)]), [false, false]);
        // At the clip level a reading changes no state's likelihood: nobody speaks to it.
        assert_eq!(silent(&[(2, -100.0)]), [true, true]);
    }

    /// With every transmitter a radio of its own, and with 0 and 2 one radio (each weighing
    /// one half in the product).
    #[test]
    fn sparse_likelihood_equals_dense_product() {
        for model in [RssiModel::CensoredGaussian, RssiModel::NaiveGaussian] {
            let grouped = small_map(model).with_shared_radios(vec![vec![0, 2]]).unwrap();
            assert_eq!(grouped.weights, [0.5, 1.0, 0.5]);
            for (map, heard) in [small_map(model), grouped].iter().flat_map(|map| {
                [vec![(0, -62.0), (1, -79.0)], vec![(2, -92.0)], vec![(0, -100.0), (2, -99.0)], vec![]]
                    .map(|heard| (map, heard))
            }) {
                let mut out = vec![0.0; 2];
                let unheard = map.ln_likelihood(&heard, &mut out);
                // Each heard transmitter's ln p(absent) comes from the table (≤ 2e-6 off).
                for s in 0..2 {
                    assert_relative_eq!(out[s as usize], brute_force(map, &heard, s), epsilon = 1e-5);
                }
                // A state the map has no fingerprint for (there is no state 9).
                assert_relative_eq!(unheard, brute_force(map, &heard, 9), epsilon = 1e-9);
            }
        }
    }

    #[test]
    fn a_beacon_scan_says_nothing_about_access_points() {
        let beacon = TransmitterId::ble_address("e0:78:a3:3d:b5:d6").unwrap();
        let fingerprints = vec![(0, 0, g(-60.0, 4.0)), (1, 1, g(-70.0, 4.0)), (1, 0, g(-90.0, 4.0))];
        let map = RadioMap::new(
            RssiModel::CensoredGaussian,
            -100.0,
            g(-115.0, 5.0),
            vec![wifi(0), beacon],
            2,
            fingerprints,
        )
        .unwrap();
        for heard in [vec![(1, -72.0)], vec![(0, -61.0)], vec![(0, -61.0), (1, -72.0)]] {
            let mut out = vec![0.0; 2];
            let unheard = map.ln_likelihood(&heard, &mut out);
            assert_relative_eq!(unheard, brute_force(&map, &heard, 9), epsilon = 1e-9);
            for s in 0..2 {
                assert_relative_eq!(out[s as usize], brute_force(&map, &heard, s), epsilon = 1e-9);
            }
        }
        // Heard only the beacon: the access point's absence is not evidence.
        let mut out = vec![0.0; 2];
        map.ln_likelihood(&[(1, -72.0)], &mut out);
        let only_beacon = |m: &Gaussian| map.model().ln_heard(m, -72.0, -100.0);
        assert_relative_eq!(out[1], only_beacon(&g(-70.0, 4.0)), epsilon = 1e-12);
    }

    #[test]
    fn likelihood_by_hand() {
        // State 0 hears transmitter 0 at -60 exactly at its mean; 1 and 2 are absent.
        let map = small_map(RssiModel::CensoredGaussian);
        let mut out = vec![0.0; 2];
        map.ln_likelihood(&[(0, -60.0)], &mut out);
        let ln_pdf_at_mean = -(4.0 * (2.0 * std::f64::consts::PI).sqrt()).ln();
        // Transmitter 1 below -100 with μ -80, σ 5: Φ(-4); transmitter 2 with μ -95, σ 6: Φ(-5/6).
        let expected = ln_pdf_at_mean + 3.167_124_183_311_992e-5f64.ln() + 0.202_328_380_963_643_03f64.ln();
        // Transmitter 0's ln p(absent) is tabled (≤ 2e-6 off).
        assert_relative_eq!(out[0], expected, epsilon = 1e-5);
    }

    #[test]
    fn layouts_fit_the_map_and_round_trip() {
        // Means over the whole i16 range and 65 536 spreads leave no bits for the step.
        let full = Layout::fit(-32_767, 32_767, 65_536);
        assert_eq!(full.step_mask, 0);
        assert_eq!(full.encode(1, 5, 7), None);
        let word = full.encode(0, -32_767, 65_535).unwrap();
        assert_eq!(full.decode(word), (0, -32_767, 65_535));
        // One mean and one spread: the step has every bit.
        let single = Layout::fit(-6000, -6000, 1);
        let word = single.encode(u32::MAX, -6000, 0).unwrap();
        assert_eq!(single.decode(word), (u32::MAX as usize, -6000, 0));
        let mall = Layout::fit(-11_250, -3_943, 697);
        assert_eq!(mall.step_mask, 511);
        let word = mall.encode(511, -3_943, 696).unwrap();
        assert_eq!(mall.decode(word), (511, -3_943, 696));
        assert_eq!(mall.encode(512, -3_943, 696), None);
    }

    /// Means far apart and many spreads leave a few bits of step, so entries far apart in
    /// state start runs: the map still returns every model and scores as the dense product.
    #[test]
    fn entries_far_apart_start_runs() {
        let states = 3000;
        // 503 spreads (9 bits) and means 600 dB apart (16 bits) leave 7 bits of step.
        let fingerprints: Vec<(u32, u32, Gaussian)> = (0..states)
            .filter(|s| (s % 3 == 0 && *s < 1500) || [2000, 2500, 2999].contains(s))
            .flat_map(|s| {
                let mean = if s % 2 == 0 { -300.0 + f64::from(s % 50) } else { 300.0 - f64::from(s % 13) };
                let std = 1.0 + 0.01 * f64::from(s / 3);
                [(s, 0, g(mean, std)), (s, 1, g(mean / 3.0, std))]
            })
            .collect();
        let map = RadioMap::new(
            RssiModel::CensoredGaussian,
            -100.0,
            g(-115.0, 5.0),
            vec![wifi(0), wifi(1)],
            states as usize,
            fingerprints.clone(),
        )
        .unwrap();
        assert_eq!(map.layout.step_mask, 127);
        // Per transmitter, the first entry and the three after a gap of 500.
        assert_eq!(map.runs.len(), 2 * 4 + 1);
        let mut stored: Vec<(u32, u32, Gaussian)> = map.fingerprints().collect();
        stored.sort_by_key(|e| (e.0, e.1));
        assert_eq!(stored.len(), fingerprints.len());
        for (a, b) in stored.iter().zip(&fingerprints) {
            assert_eq!((a.0, a.1), (b.0, b.1));
            assert_relative_eq!(a.2.mean_dbm, b.2.mean_dbm, epsilon = 0.005);
            assert_relative_eq!(a.2.std_db, b.2.std_db, epsilon = 0.005);
        }
        let heard = [(0, -90.0), (1, -40.0)];
        let mut out = vec![0.0; states as usize];
        map.ln_likelihood(&heard, &mut out);
        for s in [0, 3, 4, 1497, 2000, 2500, 2999] {
            assert_relative_eq!(out[s as usize], brute_force(&map, &heard, s), epsilon = 1e-5);
        }
    }

    #[test]
    fn resolve_drops_unknown_duplicate_and_stale() {
        let map = small_map(RssiModel::CensoredGaussian);
        let reading =
            |t: u8, rssi: f64, age_ns: u64| Reading { transmitter: wifi(t), rssi_dbm: rssi, age_ns };
        let scan = Scan {
            timestamp_ns: 1,
            readings: vec![
                reading(0, -70.0, 5),
                reading(0, -65.0, 0),
                reading(9, -50.0, 0),
                reading(1, -80.0, 10_000_000_000),
            ],
        };
        let r = map.resolve(&scan, Some(1_000_000_000));
        assert_eq!(r.observations, vec![(0, -65.0)]);
        assert_eq!((r.unknown, r.duplicates, r.stale), (1, 1, 1));
    }

    /// Transmitters listed in any order are found by their own index, and a reading of one the
    /// map does not list is counted as unknown.
    #[test]
    fn resolve_finds_transmitters_listed_out_of_order() {
        let ble = TransmitterId::BleAddress { mac: "00:00:00:00:00:03".into() };
        let ids = vec![wifi(9), ble.clone(), wifi(2), wifi(5), wifi(0)];
        let map =
            RadioMap::new(RssiModel::CensoredGaussian, -100.0, g(-115.0, 5.0), ids.clone(), 1, []).unwrap();
        let readings: Vec<Reading> = (ids.iter().chain([&wifi(3)]))
            .enumerate()
            .map(|(k, id)| Reading { transmitter: id.clone(), rssi_dbm: -50.0 - k as f64, age_ns: 0 })
            .collect();
        let r = map.resolve(&Scan { timestamp_ns: 1, readings }, None);
        assert_eq!(r.observations, [(0, -50.0), (1, -51.0), (2, -52.0), (3, -53.0), (4, -54.0)]);
        assert_eq!((r.unknown, r.duplicates, r.stale), (1, 0, 0));
    }

    #[test]
    fn rejects_bad_tables() {
        let dup =
            RadioMap::new(RssiModel::CensoredGaussian, -100.0, g(-115.0, 5.0), vec![wifi(0), wifi(0)], 1, []);
        assert!(dup.unwrap_err().contains("twice"));
        let oob = RadioMap::new(
            RssiModel::CensoredGaussian,
            -100.0,
            g(-115.0, 5.0),
            vec![wifi(0)],
            1,
            [(3, 0, g(-1.0, 1.0))],
        );
        assert!(oob.unwrap_err().contains("out of range"));
    }
}
