//! The radio map: every state's fingerprint, stored by transmitter so that a scan costs
//! O(states + fingerprint entries of the transmitters heard), not O(states × transmitters).
//!
//! Entries are 8 bytes: the state, the mean in 0.01 dB and an index into the map's table of
//! distinct standard deviations (also in 0.01 dB), so that a large site's engine keeps within
//! its memory budget (docs/tuning.md#engine-speed). ln p(absent) is computed when a
//! transmitter is heard, by [`LnCdfTable`].

use super::{ln_std_normal_pdf, Gaussian, LnCdfTable, RssiModel, Scan, TransmitterId};
use std::collections::HashMap;

/// Resolution of the stored RSSI levels and spreads: 0.01 dB, a hundredth of the 1 dBm step
/// phones report RSSI in, so storing it changes no likelihood a reading can tell apart.
pub const LEVEL_STEP_DB: f64 = 0.01;

/// Largest |mean| of a fingerprint model, dBm: the 0.01 dB steps are stored in an `i16`
/// (±327.67 dBm). Phones report about -130 to +20 dBm.
pub const MAX_ABS_LEVEL_DBM: f64 = 320.0;

/// Smallest standard deviation of a fingerprint model, dB: one [`LEVEL_STEP_DB`]. Found with
/// the `site_file` fuzz harness: with σ of 1e-300 dB every reading off the mean had a
/// likelihood of exactly 0 at every state, and no state explained any scan. Phones report
/// whole dBm and the survey's fits stop at 1 dB.
pub const MIN_STD_DB: f64 = LEVEL_STEP_DB;

/// Largest standard deviation of a fingerprint model, dB: the steps are stored in a `u16`
/// (655.35 dB). The survey caps its fits far below.
pub const MAX_STORED_STD_DB: f64 = 650.0;

/// One transmitter's model at one state: 8 bytes.
#[derive(Clone, Copy, Debug)]
struct Entry {
    state: u32,
    /// Mean, in [`LEVEL_STEP_DB`].
    mean: i16,
    /// Index into [`RadioMap::spreads`].
    spread: u16,
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
}

/// A model's (mean, σ) in [`LEVEL_STEP_DB`] steps, if within the stored range.
fn quantise(g: &Gaussian) -> Option<(i16, u16)> {
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
    index: HashMap<TransmitterId, u32>,
    /// Entries of transmitter `t` are `entries[starts[t]..starts[t + 1]]`.
    starts: Vec<usize>,
    entries: Vec<Entry>,
    /// The distinct standard deviations of the entries (a few hundred on a real site).
    spreads: Vec<Spread>,
    /// Per radio kind (WiFi, BLE), per state: ln p(every transmitter of that kind absent |
    /// state).
    all_absent: [Vec<f64>; 2],
    /// Radio kind of each transmitter (index into `all_absent`).
    kinds: Vec<u8>,
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
        let mut index = HashMap::with_capacity(ids.len());
        for (i, id) in ids.iter().enumerate() {
            if index.insert(id.clone(), i as u32).is_some() {
                return Err(format!("transmitter {id} is listed twice"));
            }
        }
        // Quantised first: 16 bytes a triple while the map is built, where the f64 triples
        // took 24.
        let mut quantised = Vec::new();
        for (state, tx, g) in fingerprints {
            if state as usize >= state_count || tx as usize >= ids.len() {
                return Err(format!("fingerprint entry (state {state}, transmitter {tx}) is out of range"));
            }
            let (mean, std) = quantise(&g).ok_or_else(|| {
                format!(
                    "the model of transmitter {tx} at state {state} (mean {} dBm, σ {} dB) is outside \
                     the stored range (mean within ±{MAX_ABS_LEVEL_DBM} dBm, σ at most {MAX_STORED_STD_DB} dB)",
                    g.mean_dbm, g.std_db
                )
            })?;
            quantised.push((state, tx, mean, std));
        }
        // The table of distinct spreads, indexed by their steps.
        let mut spread_of = vec![u16::MAX; usize::from(u16::MAX) + 1];
        let mut spreads = Vec::new();
        for &(_, _, _, std) in &quantised {
            if spread_of[usize::from(std)] == u16::MAX {
                spread_of[usize::from(std)] = spreads.len() as u16;
                let sigma = level(std);
                spreads.push(Spread { steps: std, inverse: 1.0 / sigma, ln: sigma.ln() });
            }
        }
        let unheard_ln_absent = model.ln_absent(&unheard, clip_dbm);
        let kinds: Vec<u8> = ids.iter().map(kind).collect();
        let mut all_absent = [0u8, 1].map(|k| {
            let count = kinds.iter().filter(|&&x| x == k).count();
            vec![unheard_ln_absent * count as f64; state_count]
        });
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
        let table = LnCdfTable::get();
        let mut entries = vec![Entry { state: 0, mean: 0, spread: 0 }; quantised.len()];
        for (state, tx, mean, std) in quantised {
            // ln p(absent) by the table, as scoring takes it: the exact ln Φ per entry was
            // half the load time of a 10 000-state site.
            let (mean_dbm, std_db) = (level(mean), level(std));
            let ln_absent = match model {
                RssiModel::CensoredGaussian => table.ln_cdf((clip_dbm - mean_dbm) / std_db),
                RssiModel::NaiveGaussian => model.ln_absent(&Gaussian { mean_dbm, std_db }, clip_dbm),
            };
            all_absent[kinds[tx as usize] as usize][state as usize] += ln_absent - unheard_ln_absent;
            entries[fill[tx as usize]] = Entry { state, mean, spread: spread_of[usize::from(std)] };
            fill[tx as usize] += 1;
        }
        // Site files list entries state by state, so buckets come out sorted; any other
        // order is sorted here. Then a repeated state is a transmitter modelled twice.
        for t in 0..ids.len() {
            let bucket = &mut entries[starts[t]..starts[t + 1]];
            if !bucket.windows(2).all(|w| w[0].state <= w[1].state) {
                bucket.sort_by_key(|e| e.state);
            }
            if let Some(w) = bucket.windows(2).find(|w| w[0].state == w[1].state) {
                return Err(format!("state {} models transmitter {} twice", w[0].state, ids[t]));
            }
        }
        Ok(Self {
            model,
            clip_dbm,
            unheard,
            unheard_ln_absent,
            ids,
            index,
            starts,
            entries,
            spreads,
            all_absent,
            kinds,
        })
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
            self.entries[self.starts[t]..self.starts[t + 1]]
                .iter()
                .map(move |e| (e.state, t as u32, self.gaussian(e)))
        })
    }

    /// The stored model of an entry.
    fn gaussian(&self, e: &Entry) -> Gaussian {
        Gaussian { mean_dbm: level(e.mean), std_db: level(self.spreads[usize::from(e.spread)].steps) }
    }

    /// Heap bytes of the fingerprint entries and their tables (what grows with the site).
    pub fn memory_bytes(&self) -> usize {
        self.entries.capacity() * std::mem::size_of::<Entry>()
            + self.spreads.capacity() * std::mem::size_of::<Spread>()
            + self.starts.capacity() * std::mem::size_of::<usize>()
            + self.all_absent.iter().map(|v| v.capacity() * 8).sum::<usize>()
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
            match self.index.get(&reading.transmitter) {
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
        let mut scanned = [false; 2];
        for &(t, _) in observations {
            scanned[self.kinds[t as usize] as usize] = true;
        }
        match scanned {
            [true, true] => {
                for (o, (w, b)) in out.iter_mut().zip(self.all_absent[0].iter().zip(&self.all_absent[1])) {
                    *o = w + b;
                }
            }
            [true, false] => out.copy_from_slice(&self.all_absent[0]),
            [false, true] => out.copy_from_slice(&self.all_absent[1]),
            [false, false] => out.fill(0.0),
        }
        let mut shared = 0.0;
        for &(t, rssi) in observations {
            // What hearing `rssi` changes for a state using the unheard model...
            let unheard_delta =
                self.model.ln_heard(&self.unheard, rssi, self.clip_dbm) - self.unheard_ln_absent;
            shared += unheard_delta;
            // ...and, for states that model this transmitter, the difference to their own.
            // A reading at or below the clip level is ln p(absent) for every model: no change.
            if rssi <= self.clip_dbm {
                continue;
            }
            let entries = &self.entries[self.starts[t as usize]..self.starts[t as usize + 1]];
            match self.model {
                RssiModel::CensoredGaussian => {
                    let table = LnCdfTable::get();
                    for e in entries {
                        let spread = &self.spreads[usize::from(e.spread)];
                        let mean = f64::from(e.mean) * LEVEL_STEP_DB;
                        let heard = ln_std_normal_pdf((rssi - mean) * spread.inverse) - spread.ln;
                        let absent = table.ln_cdf((self.clip_dbm - mean) * spread.inverse);
                        out[e.state as usize] += heard - absent - unheard_delta;
                    }
                }
                RssiModel::NaiveGaussian => {
                    for e in entries {
                        let spread = &self.spreads[usize::from(e.spread)];
                        let mean = f64::from(e.mean) * LEVEL_STEP_DB;
                        let (z, z_clip) =
                            ((rssi - mean) * spread.inverse, (self.clip_dbm - mean) * spread.inverse);
                        out[e.state as usize] += 0.5 * (z_clip * z_clip - z * z) - unheard_delta;
                    }
                }
            }
        }
        for v in out.iter_mut() {
            *v += shared;
        }
        let absent = self.kinds.iter().filter(|&&k| scanned[usize::from(k)]).count();
        absent as f64 * self.unheard_ln_absent + shared
    }
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
            })
            .sum()
    }

    #[test]
    fn sparse_likelihood_equals_dense_product() {
        for model in [RssiModel::CensoredGaussian, RssiModel::NaiveGaussian] {
            let map = small_map(model);
            for heard in
                [vec![(0, -62.0), (1, -79.0)], vec![(2, -92.0)], vec![(0, -100.0), (2, -99.0)], vec![]]
            {
                let mut out = vec![0.0; 2];
                let unheard = map.ln_likelihood(&heard, &mut out);
                // Each heard transmitter's ln p(absent) comes from the table (≤ 2e-6 off).
                for s in 0..2 {
                    assert_relative_eq!(out[s as usize], brute_force(&map, &heard, s), epsilon = 1e-5);
                }
                // A state the map has no fingerprint for (there is no state 9).
                assert_relative_eq!(unheard, brute_force(&map, &heard, 9), epsilon = 1e-9);
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
