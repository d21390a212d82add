//! Scoring a scan against the radio map: matching its readings to the map's transmitters and
//! ln p(scan | state) for every state (Hoang eqs. 9-10), with what else a scan tells about the
//! states (the device offset's residual, the states it says nothing about).

use super::{id_hash, RadioMap, LEVEL_STEP_DB};
use crate::radio::{ln_std_normal_pdf, LnCdfTable, RssiModel, Scan};

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
        self.ln_likelihood_and_moments(observations, None, out).0
    }

    /// [`ln_likelihood`](Self::ln_likelihood) of `observations`, and with `belief` = (`raw`,
    /// `weights`) the [`BeliefMoments`] of each of `raw`'s readings heard above the clip level,
    /// as [`offset_residual`](Self::offset_residual) takes them: `raw` lists the same
    /// transmitters in the same order, before the device offset corrected them. A transmitter
    /// both need is walked once for both.
    #[allow(clippy::type_complexity)]
    pub fn ln_likelihood_and_moments(
        &self,
        observations: &[(u32, f64)],
        belief: Option<(&[(u32, f64)], &[f64])>,
        out: &mut [f64],
    ) -> (f64, Vec<Option<BeliefMoments>>) {
        debug_assert_eq!(out.len(), self.state_count());
        let mut moments: Vec<Option<BeliefMoments>> = vec![None; belief.map_or(0, |(raw, _)| raw.len())];
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
        for (k, &(t, rssi)) in observations.iter().enumerate() {
            // The belief's moments of this transmitter, if its raw reading was heard.
            let weights =
                belief.filter(|(raw, _)| raw.get(k).is_some_and(|r| r.0 == t && r.1 > self.clip_dbm));
            let weights = weights.map(|(_, weights)| weights);
            // What hearing `rssi` changes for a state using the unheard model...
            let unheard_delta = self.unheard_delta(rssi);
            let weight = self.weights[t as usize];
            // ...and, for states that model this transmitter, the difference to their own.
            // A reading at or below the clip level is ln p(absent) for every model: no change.
            if rssi <= self.clip_dbm {
                if let Some(weights) = weights {
                    moments[k] = Some(self.belief_moments(t, weights));
                }
                continue;
            }
            match (self.model, weights) {
                (RssiModel::CensoredGaussian, None) => self.add_censored(t, rssi, unheard_delta, weight, out),
                (RssiModel::CensoredGaussian, Some(weights)) => {
                    moments[k] =
                        Some(self.add_censored_and_moments(t, rssi, unheard_delta, weight, out, weights));
                }
                (RssiModel::NaiveGaussian, weights) => {
                    if let Some(weights) = weights {
                        moments[k] = Some(self.belief_moments(t, weights));
                    }
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
        // Raw readings heard that the loop did not walk (none, unless `raw` does not list
        // `observations`' transmitters in order).
        if let Some((raw, weights)) = belief {
            for (m, &(t, rssi)) in moments.iter_mut().zip(raw) {
                if rssi > self.clip_dbm && m.is_none() {
                    *m = Some(self.belief_moments(t, weights));
                }
            }
        }
        let absent: f64 = (0..2).filter(|&k| terms.scanned[k]).map(|k| self.kind_weights[k]).sum();
        (absent * self.unheard_ln_absent + terms.shared, moments)
    }

    /// One scan's measurement of the phone's RSSI offset
    /// (`DeviceOffset`, docs/accuracy.md#device-offset): for each
    /// reading heard above the clip level, the reading less the mean μ of the fingerprints of the
    /// states that model its transmitter, weighted by `weights` (where the phone is believed to be,
    /// a distribution over states). A transmitter counts only where the states that model it hold
    /// at least half the weight (elsewhere the belief says little about what it should read), and
    /// where that mean, moved by the current estimate `offset_db`, is two σ or more above the clip
    /// level (nearer it, the phone hears only the readings that came out strong, and their residual
    /// is biased upwards). Returns the mean residual and its variance, the mean over the
    /// transmitters of each reading's variance given the belief (its fingerprints' σ² and the
    /// spread of μ over the believed states): one scan's residuals share where the phone was
    /// believed to be, so they count as one reading, not as many independent ones (were the belief
    /// a few metres off, every transmitter would say so together); `None` when none counts.
    pub fn offset_residual(
        &self,
        observations: &[(u32, f64)],
        weights: &[f64],
        offset_db: f64,
    ) -> Option<(f64, f64)> {
        let moments: Vec<Option<BeliefMoments>> = observations
            .iter()
            .map(|&(t, rssi)| (rssi > self.clip_dbm).then(|| self.belief_moments(t, weights)))
            .collect();
        self.offset_from_moments(observations, &moments, offset_db)
    }

    /// [`offset_residual`](Self::offset_residual) from the belief's moments of each reading
    /// (`None` for a reading at or below the clip level), as
    /// [`ln_likelihood_and_moments`](Self::ln_likelihood_and_moments) gives them.
    pub fn offset_from_moments(
        &self,
        observations: &[(u32, f64)],
        moments: &[Option<BeliefMoments>],
        offset_db: f64,
    ) -> Option<(f64, f64)> {
        let (mut sum, mut variance, mut n) = (0.0, 0.0, 0usize);
        for (&(_, rssi), m) in observations.iter().zip(moments) {
            let Some(m) = m.filter(|_| rssi > self.clip_dbm) else { continue };
            if m.weight < 0.5 {
                continue;
            }
            // The reading's variance given the belief: the fingerprints' own σ² and how much μ
            // varies over the believed states (the law of total variance), so that a vague
            // belief measures little.
            let mean = m.mean / m.weight;
            let var = m.variance / m.weight + (m.square / m.weight - mean * mean).max(0.0);
            if mean + offset_db - self.clip_dbm < 2.0 * var.sqrt() {
                continue;
            }
            sum += rssi - mean;
            variance += var;
            n += 1;
        }
        (n > 0).then(|| (sum / n as f64, variance / n as f64))
    }

    /// The moments of transmitter `t`'s fingerprints under `weights` (a distribution over
    /// states), over the states that model it.
    fn belief_moments(&self, t: u32, weights: &[f64]) -> BeliefMoments {
        let mut m = BeliefMoments::default();
        // As `entries`, run by run: the nested loops compile to a tighter loop than the
        // flattened iterator (this is as many entries as the scan's likelihood).
        for (first, words) in self.runs(t) {
            let mut state = first as usize;
            for &word in words {
                let (step, field, spread) = self.layout.decode_field(word);
                state += step;
                m.add(
                    weights.get(state).copied().unwrap_or(0.0),
                    self.mean_of_field(field),
                    &self.spreads[spread],
                );
            }
        }
        m
    }

    /// The mean, dBm, of an entry whose mean field is `field`.
    #[inline]
    fn mean_of_field(&self, field: u32) -> f64 {
        f64::from(self.layout.lowest_mean + field as i32) * LEVEL_STEP_DB
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
        self.censored_pass::<false>(t, rssi, (unheard_delta, weight), out, &[]);
    }

    /// [`add_censored`](Self::add_censored) and, in the same walk over the entries,
    /// [`belief_moments`](Self::belief_moments) under `weights`.
    #[inline(never)]
    fn add_censored_and_moments(
        &self,
        t: u32,
        rssi: f64,
        unheard_delta: f64,
        weight: f64,
        out: &mut [f64],
        weights: &[f64],
    ) -> BeliefMoments {
        self.censored_pass::<true>(t, rssi, (unheard_delta, weight), out, weights)
    }

    #[inline(always)]
    fn censored_pass<const MOMENTS: bool>(
        &self,
        t: u32,
        rssi: f64,
        (unheard_delta, weight): (f64, f64),
        out: &mut [f64],
        weights: &[f64],
    ) -> BeliefMoments {
        let (layout, table) = (self.layout, LnCdfTable::get());
        let above_clip = rssi - self.clip_dbm;
        let shared = ln_std_normal_pdf(0.0) - unheard_delta;
        let mut moments = BeliefMoments::default();
        for (first, words) in self.runs(t) {
            let mut state = first as usize;
            for &word in words {
                let (step, field, spread) = layout.decode_field(word);
                state += step;
                let spread = &self.spreads[spread];
                let w = spread.clip_at_lowest - f64::from(field) * spread.clip_per_step;
                let z = w + above_clip * spread.inverse;
                out[state] += weight * (shared - 0.5 * z * z - spread.ln - table.ln_cdf(w));
                if MOMENTS {
                    moments.add(
                        weights.get(state).copied().unwrap_or(0.0),
                        self.mean_of_field(field),
                        spread,
                    );
                }
            }
        }
        moments
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

/// Σp, Σp·μ, Σp·μ² and Σp·σ² over the states that model a transmitter, p a belief over
/// states: what [`RadioMap::offset_from_moments`] needs of a reading.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BeliefMoments {
    weight: f64,
    mean: f64,
    square: f64,
    variance: f64,
}

impl BeliefMoments {
    /// One entry with mean `mu` and `spread`, at a state of belief `p`.
    #[inline(always)]
    fn add(&mut self, p: f64, mu: f64, spread: &super::Spread) {
        if p > 0.0 {
            self.weight += p;
            self.mean += p * mu;
            self.square += p * mu * mu;
            self.variance += p * spread.variance;
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
