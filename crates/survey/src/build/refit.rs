//! Fingerprints refitted with map evidence from walks without labels (docs/evidence.md#refitting).

use super::prepare::*;
use super::*;
use waymark_engine::evidence::{Evidence, TransmitterKey};
use waymark_engine::radio::{fit_censored_moments, CensoredMoments, RssiModel};

/// The least evidence that gives a state no survey scan trained fingerprints, in scans: one,
/// as the survey fits a state from one scan of its own (`PreparedSurvey::fit`).
pub const MIN_EVIDENCE_SCANS: f64 = 1.0;

/// A cell's evidence pooled over the states within the fingerprint radius, by the survey's
/// transmitter index.
#[derive(Default)]
struct Pooled {
    /// Scan weight of each radio (WiFi, BLE).
    scans: [f64; 2],
    /// Per transmitter: heard weight, Σ w·(r - c), Σ w·(r - c)², dB.
    heard: BTreeMap<u32, [f64; 3]>,
}

impl PreparedSurvey<'_> {
    /// `fits` (of the walks they kept) refitted with `evidence` gathered on `site`, the site
    /// assembled from them: each state's labelled training scans and the evidence of every
    /// state within the fingerprint radius, pooled as the survey pools its scans, fitted
    /// together by the censored EM, a scan of evidence weighing its posterior probability
    /// (a labelled scan weighs 1). A cell without survey scans of its own, an unsurveyed state,
    /// gets fingerprints from evidence of at least [`MIN_EVIDENCE_SCANS`]. Evidence of
    /// transmitters the survey never read is left out: the site holds ids, evidence hashes.
    /// `Err` when the evidence is of another site or clip level, or the model is not the
    /// censored Gaussian.
    pub fn refit(&self, fits: &SurveyFits, site: &Site, evidence: &Evidence) -> Result<SurveyFits, String> {
        if evidence.key() != Evidence::site_key(site) {
            return Err("the evidence is of another site".into());
        }
        if (evidence.clip_dbm() - fits.clip_dbm).abs() > 0.005 {
            return Err(format!(
                "the evidence's clip level {} dBm is not the fits' {} dBm",
                evidence.clip_dbm(),
                fits.clip_dbm
            ));
        }
        if self.options.build.model != RssiModel::CensoredGaussian {
            return Err("only censored fingerprints are refitted".into());
        }
        let clip = fits.clip_dbm;
        let build = BuildOptions {
            fit: FitOptions { clip_dbm: clip, ..self.options.build.fit },
            ..self.options.build
        };
        let fit = build.stored_fit();
        let index: HashMap<TransmitterKey, u32> =
            self.transmitters.iter().enumerate().map(|(t, id)| (TransmitterKey::of(id), t as u32)).collect();
        let ble = |t: u32| self.transmitters[t as usize].is_ble();
        let s = self.options.spacing_m;
        let cell = |p: Point2<f64>| ((p.x / s).round() as i64, (p.y / s).round() as i64);
        let reach = (self.options.fingerprint_radius_m / s).floor() as i64;
        let mut out = fits.clone();
        for (f, floor) in self.floors.iter().enumerate() {
            // The states of this floor that hold evidence, by cell.
            let mut with_evidence: HashMap<Cell, u32> = HashMap::new();
            let mut cells: Vec<Cell> = Vec::new();
            for (i, state) in site.states().iter().enumerate() {
                if state.floor != f {
                    continue;
                }
                let c = cell(state.position);
                cells.push(c);
                if evidence.scanned(i as u32).iter().any(|&w| w > 0.0) {
                    with_evidence.insert(c, i as u32);
                }
            }
            for c in cells {
                let mut pooled = Pooled::default();
                for dx in -reach..=reach {
                    for dy in -reach..=reach {
                        let d = ((dx * dx + dy * dy) as f64).sqrt() * s;
                        let Some(&state) = with_evidence.get(&(c.0 + dx, c.1 + dy)) else { continue };
                        if d > self.options.fingerprint_radius_m {
                            continue;
                        }
                        let scans = evidence.scanned(state);
                        pooled.scans[0] += scans[0];
                        pooled.scans[1] += scans[1];
                        for (key, _) in evidence.heard_at(state) {
                            let (Some(&t), Some(m)) = (index.get(&key), evidence.moments(state, &key)) else {
                                continue;
                            };
                            let above = m.heard_mean - clip;
                            let sums = pooled.heard.entry(t).or_default();
                            sums[0] += m.heard;
                            sums[1] += m.heard * above;
                            sums[2] += m.heard * (m.heard_var + above * above);
                        }
                    }
                }
                if pooled.scans == [0.0, 0.0] {
                    continue;
                }
                let training: Training = floor
                    .cells
                    .get(&c)
                    .map(|candidate| {
                        candidate
                            .training
                            .iter()
                            .copied()
                            .filter(|&(w, _)| fits.kept[f][w as usize])
                            .collect()
                    })
                    .unwrap_or_default();
                if training.is_empty() && pooled.scans[0].max(pooled.scans[1]) < MIN_EVIDENCE_SCANS {
                    continue;
                }
                // The labelled columns: per transmitter, each training scan's reading (the
                // stronger of two), clipped at the clip level, as `fit_columns` reads them.
                let mut labelled: BTreeMap<u32, Vec<f64>> = BTreeMap::new();
                for (k, &(w, scan)) in training.iter().enumerate() {
                    for &(t, rssi) in &floor.walks[w as usize].scans[scan as usize] {
                        if rssi.is_finite() {
                            let column = labelled.entry(t).or_insert_with(|| vec![clip; training.len()]);
                            column[k] = column[k].max(rssi.max(clip));
                        }
                    }
                }
                let mut heard: Vec<u32> = labelled.keys().chain(pooled.heard.keys()).copied().collect();
                heard.sort_unstable();
                heard.dedup();
                let n = training.len() as f64;
                let models = heard
                    .iter()
                    .filter_map(|&t| {
                        let column = labelled.get(&t);
                        let above = column.into_iter().flatten().filter(|&&r| r > clip).map(|&r| r - clip);
                        let (mut h, mut s1, mut s2) =
                            above.fold((0.0, 0.0, 0.0), |(h, s1, s2), u| (h + 1.0, s1 + u, s2 + u * u));
                        if let Some(e) = pooled.heard.get(&t) {
                            (h, s1, s2) = (h + e[0], s1 + e[1], s2 + e[2]);
                        }
                        let samples = n + pooled.scans[usize::from(ble(t))];
                        let moments = CensoredMoments::from_sums_above_clip(samples, h, s1, s2, clip);
                        fit_censored_moments(&moments, &fit).gaussian.map(|g| (t, g))
                    })
                    .collect();
                let scans = (n + pooled.scans[0].max(pooled.scans[1])).round().max(1.0) as u32;
                out.floors[f].insert(c, CellFit { scans, heard, models });
            }
        }
        Ok(out)
    }
}
