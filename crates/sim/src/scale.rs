//! Sites of any size, for measuring speed and memory (the benchmarks): one floor
//! of states on the survey's regular grid, densely covered by access points, and scans that
//! hear a fixed number of them.
//!
//! Fingerprints are written from the path-loss model directly rather than fitted from
//! training scans, so a 50 000-state site takes a second to make, not an hour; the engine
//! cannot tell the difference.

use super::{PathLoss, RadioField};
use nalgebra::Point2;
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use serde_json::json;
use waymark_engine::hmm::Transition;
use waymark_engine::radio::{Reading, Scan, TransmitterId};
use waymark_engine::sensors::{MotionScenario, MotionState, MotionUpdate};
use waymark_engine::Site;

/// What a scaled site looks like.
#[derive(Clone, Debug, PartialEq)]
pub struct ScaleConfig {
    /// Number of states.
    pub states: usize,
    /// Seed of the access point placement.
    pub seed: u64,
    /// Grid spacing of the states, m: the survey's default (`SurveyOptions::spacing_m`).
    pub spacing_m: f64,
    /// Spacing of the access point grid, m. 4: with the simulator's path loss (exponent 4,
    /// -45 dBm at 1 m, σ_L 5 dB, clip -100 dBm) a phone then hears about 130 of them above
    /// the clip level (∫ P(heard at d) 2πd dd = 2085 m² per access point), so the strongest
    /// 100 are always there; the Indoor Location Competition mall is that dense (F1: a median
    /// of 190 WiFi readings per scan seen in the last 2 s, 429 with cached ones).
    pub access_point_spacing_m: f64,
    /// A state models an access point whose mean RSSI there is above `clip - k·σ_L`. 1: heard
    /// at least 16% of the time.
    pub model_below_clip_sigmas: f64,
    /// Readings per scan: the strongest this many. 100, a dense mall's.
    pub heard: usize,
}

impl Default for ScaleConfig {
    fn default() -> Self {
        Self {
            states: 10_000,
            seed: 0,
            spacing_m: 2.0,
            access_point_spacing_m: 4.0,
            model_below_clip_sigmas: 1.0,
            heard: 100,
        }
    }
}

/// A generated site (as site-file JSON) and the radio field behind it.
#[derive(Clone, Debug)]
pub struct ScaleSite {
    /// The site file.
    pub json: String,
    /// The access points.
    pub field: RadioField,
    /// Positions of the states, by index.
    pub points: Vec<Point2<f64>>,
    /// Fingerprint entries written (state, access point pairs).
    pub fingerprints: usize,
    heard: usize,
}

impl ScaleSite {
    /// Generates the site.
    pub fn generate(config: &ScaleConfig) -> ScaleSite {
        let n = config.states.max(1);
        let columns = (n as f64).sqrt().ceil() as usize;
        let rows = n.div_ceil(columns);
        let s = config.spacing_m;
        let points: Vec<Point2<f64>> =
            (0..n).map(|k| Point2::new((k % columns) as f64 * s, (k / columns) as f64 * s)).collect();
        let (width, depth) = (columns as f64 * s, rows as f64 * s);

        // Access points on a jittered grid over the floor.
        let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
        let g = config.access_point_spacing_m;
        let (ap_columns, ap_rows) = ((width / g).ceil() as usize, (depth / g).ceil() as usize);
        let access_points: Vec<(TransmitterId, Point2<f64>)> = (0..ap_columns * ap_rows)
            .map(|k| {
                let id = TransmitterId::wifi(&format!(
                    "02:00:00:{:02x}:{:02x}:{:02x}",
                    (k >> 16) & 0xff,
                    (k >> 8) & 0xff,
                    k & 0xff
                ))
                .expect("a well-formed BSSID");
                let at = Point2::new(
                    ((k % ap_columns) as f64 + rng.random_range(0.0..1.0)) * g,
                    ((k / ap_columns) as f64 + rng.random_range(0.0..1.0)) * g,
                );
                (id, at)
            })
            .collect();
        let field = RadioField {
            access_points,
            path_loss: PathLoss { ref_dbm: -45.0, exponent: 4.0 },
            shadowing_db: 5.0,
            clip_dbm: -100.0,
        };

        // Fingerprints: the path-loss mean and σ_L wherever the mean clears the threshold.
        let threshold = field.clip_dbm - config.model_below_clip_sigmas * field.shadowing_db;
        let radius = 10f64.powf((field.path_loss.ref_dbm - threshold) / (10.0 * field.path_loss.exponent));
        let reach = (radius / g).ceil() as i64 + 1;
        let mut fingerprints = 0;
        let states: Vec<serde_json::Value> = points
            .iter()
            .enumerate()
            .map(|(id, p)| {
                let (ci, cj) = ((p.x / g) as i64, (p.y / g) as i64);
                let mut fingerprint = Vec::new();
                for j in (cj - reach).max(0)..(cj + reach + 1).min(ap_rows as i64) {
                    for i in (ci - reach).max(0)..(ci + reach + 1).min(ap_columns as i64) {
                        let tx = j as usize * ap_columns + i as usize;
                        let mean =
                            field.path_loss.mean_dbm(nalgebra::distance(&field.access_points[tx].1, p));
                        if mean > threshold {
                            fingerprint
                                .push(json!({"tx": tx, "mean_dbm": mean, "std_db": field.shadowing_db}));
                        }
                    }
                }
                fingerprints += fingerprint.len();
                json!({"id": id, "floor": 0, "x": p.x, "y": p.y, "fingerprint": fingerprint})
            })
            .collect();
        // The survey's 8-connected grid.
        let mut edges = Vec::new();
        for k in 0..n {
            let (c, r) = (k % columns, k / columns);
            for (dc, dr) in [(1i64, 0i64), (0, 1), (1, 1), (-1, 1)] {
                let (c2, r2) = (c as i64 + dc, r as i64 + dr);
                if c2 < 0 || c2 >= columns as i64 {
                    continue;
                }
                let k2 = r2 as usize * columns + c2 as usize;
                if k2 < n {
                    edges.push(json!({"from": k, "to": k2}));
                }
            }
        }
        let transmitters: Vec<&TransmitterId> = field.access_points.iter().map(|(id, _)| id).collect();
        let file = json!({
            "format_version": waymark_engine::site::FORMAT_VERSION,
            "name": format!("waymark scale test, {n} states"),
            "floors": [{"name": "G"}],
            "radio": {
                "clip_dbm": field.clip_dbm,
                "unheard": {"mean_dbm": threshold - 2.0 * field.shadowing_db, "std_db": field.shadowing_db},
                "transmitters": transmitters,
            },
            "states": states,
            "edges": edges,
        });
        ScaleSite { json: file.to_string(), field, points, fingerprints, heard: config.heard }
    }

    /// A scan at `position`: the strongest `heard` readings of the field's scan there.
    pub fn scan_at(&self, position: Point2<f64>, timestamp_ns: u64, rng: &mut ChaCha8Rng) -> Scan {
        let mut scan = self.field.scan_at(position, timestamp_ns, rng);
        scan.readings.sort_by(|a: &Reading, b: &Reading| b.rssi_dbm.total_cmp(&a.rssi_dbm));
        scan.readings.truncate(self.heard);
        scan
    }
}

/// One epoch of a walk on a scaled site: the scan, the motion since the previous epoch as
/// the tracker would report it, and the truth.
#[derive(Clone, Debug)]
pub struct ScaleEpoch {
    /// The scan.
    pub scan: Scan,
    /// Distance and heading since the previous epoch, with the tracker's typical errors.
    pub motion: MotionUpdate,
    /// Where the phone was.
    pub truth: Point2<f64>,
}

/// Time between epochs, ns: one unthrottled scan interval (`docs/tuning.md#replay-timer`).
pub const SCALE_EPOCH_NS: u64 = 2_000_000_000;

impl ScaleSite {
    /// `epochs` epochs of walking laps of a 30 m square around the middle of the site at
    /// 1.2 m/s, with 10 cm and 0.1 rad of motion noise.
    pub fn walk(&self, epochs: usize, seed: u64) -> Vec<ScaleEpoch> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let (lo, hi) = self.points.iter().fold(
            (Point2::new(f64::INFINITY, f64::INFINITY), Point2::new(f64::NEG_INFINITY, f64::NEG_INFINITY)),
            |(lo, hi), p| {
                (Point2::new(lo.x.min(p.x), lo.y.min(p.y)), Point2::new(hi.x.max(p.x), hi.y.max(p.y)))
            },
        );
        let centre = Point2::new((lo.x + hi.x) / 2.0, (lo.y + hi.y) / 2.0);
        let half = (15.0f64).min((hi.x - lo.x) / 2.0).min((hi.y - lo.y) / 2.0);
        let lap = 8.0 * half;
        let at = |walked: f64| {
            let s = walked.rem_euclid(lap.max(f64::MIN_POSITIVE)) / (2.0 * half).max(f64::MIN_POSITIVE);
            let (side, f) = (s.floor() as u32 % 4, s.fract() * 2.0 - 1.0);
            let (dx, dy) = match side {
                0 => (f, -1.0),
                1 => (1.0, f),
                2 => (-f, 1.0),
                _ => (-1.0, -f),
            };
            Point2::new(centre.x + dx * half, centre.y + dy * half)
        };
        let speed = 1.2 * SCALE_EPOCH_NS as f64 * 1e-9;
        (0..epochs)
            .map(|k| {
                let t_ns = (k as u64 + 1) * SCALE_EPOCH_NS;
                let (from, truth) = (at(k as f64 * speed), at((k + 1) as f64 * speed));
                let noise = |rng: &mut ChaCha8Rng, s: f64| rng.random_range(-s..s) * 3f64.sqrt();
                let d = [truth.x - from.x + noise(&mut rng, 0.1), truth.y - from.y + noise(&mut rng, 0.1)];
                let distance = d[0].hypot(d[1]);
                let motion = MotionUpdate {
                    start_ns: t_ns - SCALE_EPOCH_NS,
                    end_ns: t_ns,
                    steps: (distance / 0.7).round() as u32,
                    distance_m: Some(distance),
                    distance_sigma_m: 0.1,
                    heading_rad: Some(d[0].atan2(d[1])),
                    heading_sigma_rad: 0.1,
                    displacement_m: Some(d),
                    motion_state: MotionState::Walking,
                    scenario: MotionScenario::DistanceHeading,
                    compass_disturbed: false,
                };
                ScaleEpoch { scan: self.scan_at(truth, t_ns, &mut rng), motion, truth }
            })
            .collect()
    }
}

/// The forward step as a general-purpose HMM library computes it: a dense N × N transition
/// matrix and a dense N × T emission table, O(N² + N·T) per epoch. The reference the sparse
/// engine is timed against (the benchmark's `dense_over_sparse_ratio`).
pub struct DenseForward {
    n: usize,
    transition: Vec<f64>,
    /// Per state and transmitter: (mean, 1/σ, ln(1/(σ√2π)), ln p(absent)).
    emission: Vec<[f64; 4]>,
    transmitters: usize,
    clip_dbm: f64,
    posterior: Vec<f64>,
    predicted: Vec<f64>,
    ln_b: Vec<f64>,
}

impl DenseForward {
    /// Materialises `transition` and the site's radio map densely. Needs 8·N² bytes.
    pub fn new(site: &Site, transition: &dyn Transition) -> Self {
        let n = site.states().len();
        let map = site.radio();
        let transmitters = map.transmitters().len();
        let mut dense = vec![0.0; n * n];
        let mut row = Vec::new();
        for (i, out) in dense.chunks_mut(n).enumerate() {
            row.clear();
            out.fill(transition.row(i, &mut row));
            for &(j, a) in &row {
                out[j as usize] = a;
            }
        }
        let clip_dbm = map.clip_dbm();
        let model = map.model();
        // The same emission as the radio map's: ln p(absent) of fingerprint entries from the
        // table the map scores with, of the unheard model exactly.
        let cell = |g: &waymark_engine::radio::Gaussian, ln_absent: f64| {
            [g.mean_dbm, 1.0 / g.std_db, g.ln_pdf(g.mean_dbm), ln_absent]
        };
        let unheard = map.unheard();
        let mut emission = vec![cell(&unheard, model.ln_absent(&unheard, clip_dbm)); n * transmitters];
        for (state, tx, g) in map.fingerprints() {
            let ln_absent = match model {
                waymark_engine::radio::RssiModel::CensoredGaussian => {
                    waymark_engine::radio::LnCdfTable::get().ln_cdf((clip_dbm - g.mean_dbm) / g.std_db)
                }
                waymark_engine::radio::RssiModel::NaiveGaussian => model.ln_absent(&g, clip_dbm),
            };
            emission[state as usize * transmitters + tx as usize] = cell(&g, ln_absent);
        }
        Self {
            n,
            transition: dense,
            emission,
            transmitters,
            clip_dbm,
            posterior: vec![1.0 / n as f64; n],
            predicted: vec![0.0; n],
            ln_b: vec![0.0; n],
        }
    }

    /// One epoch: predict, weight by the emission of `observations` (transmitter index, dBm;
    /// every transmitter not listed is absent), normalise; returns the most probable state.
    pub fn step(&mut self, observations: &[(u32, f64)]) -> usize {
        let n = self.n;
        // The textbook matrix-vector product: pred_j = Σ_i post_i a_ij.
        self.predicted.fill(0.0);
        for (i, row) in self.transition.chunks(n).enumerate() {
            let p = self.posterior[i];
            for (out, &a) in self.predicted.iter_mut().zip(row) {
                *out += p * a;
            }
        }
        let mut heard = vec![None; self.transmitters];
        for &(t, rssi) in observations {
            heard[t as usize] = Some(rssi);
        }
        for (s, b) in self.ln_b.iter_mut().enumerate() {
            let cells = &self.emission[s * self.transmitters..(s + 1) * self.transmitters];
            *b = cells
                .iter()
                .zip(&heard)
                .map(|(c, h)| match *h {
                    Some(x) if x > self.clip_dbm => {
                        let z = (x - c[0]) * c[1];
                        c[2] - 0.5 * z * z
                    }
                    _ => c[3],
                })
                .sum();
        }
        let max = self.ln_b.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let mut total = 0.0;
        for (post, (&p, &b)) in self.posterior.iter_mut().zip(self.predicted.iter().zip(&self.ln_b)) {
            *post = p * (b - max).exp();
            total += *post;
        }
        for post in self.posterior.iter_mut() {
            *post /= total;
        }
        (0..n).max_by(|&a, &b| self.posterior[a].total_cmp(&self.posterior[b])).unwrap_or(0)
    }

    /// The current posterior.
    pub fn posterior(&self) -> &[f64] {
        &self.posterior
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use waymark_engine::Site;

    #[test]
    fn a_scaled_site_loads_and_its_scans_hear_the_configured_count() {
        let config = ScaleConfig { states: 2500, ..ScaleConfig::default() };
        let scaled = ScaleSite::generate(&config);
        let site = Site::from_json(scaled.json.as_bytes()).unwrap();
        assert_eq!(site.states().len(), 2500);
        assert_eq!(scaled.points.len(), 2500);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let scan = scaled.scan_at(scaled.points[1275], 1, &mut rng);
        assert_eq!(scan.readings.len(), 100);
        let resolved = site.radio().resolve(&scan, None);
        assert_eq!(resolved.observations.len(), 100);
    }

    #[test]
    fn the_dense_reference_equals_the_engine_filter() {
        use waymark_engine::hmm::{ForwardFilter, UniformReach};
        use waymark_engine::site::ReachTable;
        let scaled = ScaleSite::generate(&ScaleConfig { states: 200, ..ScaleConfig::default() });
        let site = Site::from_json(scaled.json.as_bytes()).unwrap();
        let table = ReachTable::build(&site, 9.0);
        let transition = UniformReach { table: &table, rho_m: 6.0, ratio: 200_000.0 };
        let mut dense = DenseForward::new(&site, &transition);
        let mut sparse = ForwardFilter::new(site.states().len());
        let mut ln_b = vec![0.0; site.states().len()];
        for epoch in &scaled.walk(5, 3) {
            let observations = site.radio().resolve(&epoch.scan, None).observations;
            dense.step(&observations);
            site.radio().ln_likelihood(&observations, &mut ln_b);
            // Both predict at every epoch, the first one included.
            sparse.step(Some(&transition), &ln_b).unwrap();
            for (a, b) in dense.posterior().iter().zip(sparse.posterior()) {
                assert!((a - b).abs() < 1e-9, "{a} vs {b}");
            }
        }
    }
}
