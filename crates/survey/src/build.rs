//! Survey walks → a site file: reference states on a regular spacing over where the surveyors
//! walked, fingerprints fitted from the scans near each (censored Gaussians, Hoang §3), the
//! walkable graph from the floor plan and from where people actually walked, the site's north
//! and the walkers' step length. When the floor plan names its polygons (shops, rooms), the
//! states inside each named polygon become a zone.
//!
//! States never sit on the labelled waypoints: they are grid points, so a method that snaps to
//! the grid gains nothing from the surveyors' habit of revisiting the same waypoints.

use crate::io::ilc::EventOptions;
use crate::io::{FloorPlan, Trace};
use nalgebra::Point2;
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet, HashMap};
use waymark::radio::{FitOptions, Gaussian, Reading, Scan, TransmitterId};
use waymark::site::{BuildOptions, North, Site, SiteBuilder, SiteError, Zone, ZoneKind};

/// How a site is built from survey walks.
#[derive(Clone, Debug, PartialEq)]
pub struct SurveyOptions {
    /// Distance between neighbouring grid states, m. 2 m: the 2-3 m range, at its fine
    /// end because WiFi fingerprints of a mall change over a few metres (the survey scans are
    /// 2 s ≈ 2-3 m apart along a walk, see `scan_interval_median_s`, so a finer grid would
    /// have states with no scan of their own).
    pub spacing_m: f64,
    /// A grid point becomes a state when a survey walk passed within this distance, m. One
    /// spacing: the grid then covers a corridor two to three states wide around each walk.
    pub coverage_m: f64,
    /// Grid points within this distance of a surveyed state (and on the floor, when there is a
    /// plan) that no survey walk covered become [`StateKind::Unsurveyed`](waymark::site::StateKind::Unsurveyed) states with no
    /// fingerprint, joined to the grid: where a walker leaves the surveyed area, the motion
    /// can carry the estimate there instead of pinning it to the map's edge. 0: none.
    pub unsurveyed_margin_m: f64,
    /// A survey scan trains every state within this distance of where it was taken, m.
    /// `waymark survey` and `waymark eval` choose it per site by cross-validation on the
    /// survey walks ([`waymark_eval::real::FINGERPRINT_RADIUS_GRID`]; 8 m on the five
    /// competition floors pooled and on F1 alone); this is the radius used without that
    /// calibration. 5 m: a state then sees about two walking seconds of scans either side of
    /// it, 20-30 scans where a corridor was walked a few times. Measured on the F1 split
    /// (`waymark eval target/ilc/site1/F1 --fingerprint-radius-m R`): single-scan MLE 8.17 /
    /// 6.58 m mean and the fused engine 7.83 / 6.28 m for R = 3 / 5 m.
    pub fingerprint_radius_m: f64,
    /// Whether the floor plan's polygons cut the walkable graph (except where a survey walk
    /// crossed them). Off by default: on the competition's plans, shop and "auxiliary area"
    /// outlines are not where walls are — with them, `waymark eval target/ilc/site1/F1` gave
    /// 6.28 m for the fused engine, without them 5.70 m, and with the true motion fed in,
    /// 7.4 m against 5.4 m. The graph then comes from where people walked (surveyed states
    /// exist only near survey walks, unsurveyed ones around them). Turn on for plans whose
    /// polygons are real walls.
    pub walls: bool,
    /// Readings older than this, ns, were not heard in the scan's own sweep: in training they
    /// count as "not heard" (Android re-reports cached access points for ~30 s). 2 s: one
    /// scan interval, so an entry not refreshed by the latest sweep is out. Measured: the
    /// median gap between consecutive WiFi scans of the 459 survey walks is 1.9-2.3 s across
    /// the five floors (`waymark eval target/ilc/site1/{B1,F1,F2,F3,F4} --json`,
    /// `survey.floors[].scan_interval_median_s`).
    pub max_reading_age_ns: u64,
    /// Censored EM or naive fit, clip level, σ floor and cap.
    pub build: BuildOptions,
    /// Whether the clip level c is measured from the survey: one dB below the weakest WiFi
    /// reading any survey phone reported (the receivers' sensitivity, where censoring
    /// happens; Hoang §3 takes c as the phone's reporting floor). Beacons weaker than that
    /// are clipped to it. Off: `build.fit.clip_dbm` as given.
    pub measure_clip: bool,
    /// Which radios to use.
    pub events: EventOptions,
}

impl Default for SurveyOptions {
    fn default() -> Self {
        Self {
            spacing_m: 2.0,
            coverage_m: 2.0,
            unsurveyed_margin_m: UNSURVEYED_MARGIN_M,
            fingerprint_radius_m: 5.0,
            walls: false,
            max_reading_age_ns: 2_000_000_000,
            build: BuildOptions {
                fit: FitOptions { max_std_db: MAX_STD_DB, ..FitOptions::default() },
                ..BuildOptions::default()
            },
            measure_clip: true,
            events: EventOptions::default(),
        }
    }
}

/// [`SurveyOptions::unsurveyed_margin_m`]'s default, m. Where held-out survey walks went
/// beyond the map the other walks make (the leave-one-walk-out of `waymark eval`), 95% of their
/// epochs were within 10 m of it on the five competition floors (1 790 of 1 880:
/// `calibration.off_map` bands of `waymark eval target/ilc/site1/{B1,F1,F2,F3,F4}`). With it,
/// held-out error 5-10 m beyond the map went from 14.38 to 13.74 m and beyond 10 m from 20.46
/// to 13.40 m on F2, at the same test-walk error (`forward-auto` 5.248 → 5.239 m), for 2.6-2.7
/// times the states and 11-15% more `eval` time (F1 106 → 118 s, F2 33 → 38 s; README, "Beyond
/// the surveyed area").
pub const UNSURVEYED_MARGIN_M: f64 = 10.0;

/// The largest margin a survey takes, m: a bound on bad input, not a tuned value (ten times
/// the default; the unsurveyed states grow with the square of the margin).
pub const MAX_UNSURVEYED_MARGIN_M: f64 = 100.0;

/// The σ cap of survey fits, dB: the spread of one access point's RSSI at a fixed place
/// over time is a few dB (Hoang §6.1 simulates σ_L = 5 dB); a column of mostly "not heard"
/// scans otherwise fits σ of 20-60 dB (seen on the competition data before the cap).
pub const MAX_STD_DB: f64 = 8.0;

/// One floor's survey material.
#[derive(Clone, Debug)]
pub struct SurveyFloor<'a> {
    /// The floor's name (`B1`, `F2`...).
    pub name: String,
    /// Its plan, when there is one: with [`SurveyOptions::walls`], its polygons keep the
    /// walkable graph out of shops except where somebody walked in.
    pub plan: Option<&'a FloorPlan>,
    /// Survey walks on this floor.
    pub walks: Vec<&'a Trace>,
}

/// What the survey found, per floor.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct FloorSurvey {
    /// Floor name.
    pub name: String,
    /// Walks with at least two waypoints.
    pub walks: usize,
    /// Scans positioned between waypoints.
    pub scans: usize,
    /// States placed.
    pub states: usize,
    /// Unsurveyed states placed around them ([`SurveyOptions::unsurveyed_margin_m`]).
    pub unsurveyed_states: usize,
    /// Walkable edges.
    pub edges: usize,
    /// Edges kept only because a survey walk went along them (through a door the plan lacks).
    pub walked_edges: usize,
    /// Grid neighbours split by a wall on the plan.
    pub walled_edges: usize,
    /// Plan polygons survey walks went inside, whose outlines are therefore not walls.
    pub open_rooms: usize,
    /// Zones made from the plan's named polygons that hold at least one state.
    pub zones: usize,
    /// States in those zones.
    pub zoned_states: usize,
    /// Median time between consecutive WiFi scans of a walk, s (the phones' scan interval,
    /// which sets the reading-age limit and the timer epoch's period).
    pub scan_interval_median_s: f64,
    /// 99th percentile of the same, s: how long a replay's beacons wait for the next WiFi
    /// scan, and its timer for one, before an epoch goes without it.
    pub scan_interval_p99_s: f64,
}

/// The survey's outcome.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SurveyReport {
    /// Per floor, in site order.
    pub floors: Vec<FloorSurvey>,
    /// Transmitters in the radio map.
    pub transmitters: usize,
}

/// A storey's elevation rank from its name: `B2` → −2, `B1` → −1, `F1`/`1F`/`L1` → 0,
/// `F2` → 1; `None` for names without a level number. Used to order floors and set a
/// nominal elevation (rank × [`STOREY_HEIGHT_M`]).
pub fn floor_rank(name: &str) -> Option<i32> {
    let upper = name.trim().to_uppercase();
    let digits: String = upper.chars().filter(char::is_ascii_digit).collect();
    let n: i32 = digits.parse().ok()?;
    if upper.starts_with('B') || upper.ends_with('B') {
        Some(-n)
    } else {
        Some(n - 1)
    }
}

/// Nominal storey height, m, for the floors' `elevation_m` (display and ordering only: no
/// computation uses it). 5 m: a typical shopping-mall storey.
pub const STOREY_HEIGHT_M: f64 = 5.0;

/// Where a walk went: points every half metre along its waypoint polyline.
fn path_points(trace: &Trace) -> Vec<Point2<f64>> {
    let mut points = Vec::new();
    for w in trace.waypoints.windows(2) {
        let (a, b) = (Point2::new(w[0].x, w[0].y), Point2::new(w[1].x, w[1].y));
        let n = ((b - a).norm() / 0.5).ceil().max(1.0) as usize;
        points.extend((0..n).map(|k| a + (b - a) * (k as f64 / n as f64)));
    }
    if let Some(last) = trace.waypoints.last() {
        points.push(Point2::new(last.x, last.y));
    }
    points
}

/// The walk's scans with the position each was taken at (interpolated between waypoints), and
/// readings older than `max_age_ns` removed.
pub fn positioned_scans(trace: &Trace, options: &SurveyOptions) -> Vec<(Point2<f64>, Scan)> {
    trace
        .scans(&options.events)
        .into_iter()
        .filter_map(|scan| {
            let (x, y) = trace.position_at(scan.timestamp_ns)?;
            let readings: Vec<Reading> =
                scan.readings.into_iter().filter(|r| r.age_ns <= options.max_reading_age_ns).collect();
            Some((Point2::new(x, y), Scan { timestamp_ns: scan.timestamp_ns, readings }))
        })
        .collect()
}

/// Builds a site from survey walks, floors in the order given.
pub fn survey(
    name: &str,
    floors: &[SurveyFloor<'_>],
    north: North,
    options: &SurveyOptions,
) -> Result<(Site, SurveyReport), SiteError> {
    PreparedSurvey::new(name, floors, north, options)?.site(&|_, _| true, None)
}

/// A grid cell, by its indices (the centre is the indices × spacing).
type Cell = (i64, i64);

/// Training scans of a state, as (walk, scan) indices within its floor.
type Training = Vec<(u32, u32)>;

/// One survey walk, read once: where it went and its scans with interned transmitters.
#[derive(Clone, Debug)]
struct PreparedWalk {
    /// Points every half metre along the waypoints; empty for a walk with fewer than two.
    path: Vec<Point2<f64>>,
    /// Positioned scans, stale readings removed, as (transmitter index, RSSI).
    scans: Vec<Vec<(u32, f64)>>,
    /// Times between consecutive WiFi scans, s.
    gaps: Vec<f64>,
    /// The weakest finite WiFi reading, dBm (infinite without one).
    weakest_wifi_dbm: f64,
}

/// A grid cell some survey walk covered.
#[derive(Clone, Debug, Default)]
struct CandidateCell {
    /// Walks (with a path) that passed within the coverage distance.
    covered_by: Vec<u32>,
    /// The scans (walk, scan) within the fingerprint radius, in walk then scan order.
    training: Vec<(u32, u32)>,
    /// The smallest named plan polygon holding the centre.
    room: Option<usize>,
}

#[derive(Clone, Debug)]
struct PreparedFloor<'a> {
    name: String,
    plan: Option<&'a FloorPlan>,
    walks: Vec<PreparedWalk>,
    cells: BTreeMap<Cell, CandidateCell>,
}

/// One state's fitted fingerprint.
#[derive(Clone, Debug, PartialEq)]
struct CellFit {
    /// Training scans.
    scans: u32,
    /// Every transmitter (index into the survey's) read in those scans, sorted.
    heard: Vec<u32>,
    /// Model per transmitter heard with a finite RSSI, sorted.
    models: Vec<(u32, Gaussian)>,
}

/// The fingerprints of one site built by [`PreparedSurvey`], kept to be reused: a site built
/// from a subset of the walks refits only the states whose training scans changed.
#[derive(Clone, Debug)]
pub struct SurveyFits {
    /// The clip level they were fitted at, dBm.
    clip_dbm: f64,
    /// The walks they were fitted from, per floor.
    kept: Vec<Vec<bool>>,
    /// Per floor, per state cell.
    floors: Vec<BTreeMap<Cell, CellFit>>,
    /// States fitted afresh (the rest were reused).
    refitted: usize,
}

impl SurveyFits {
    /// States whose fingerprints were fitted afresh rather than reused.
    pub fn refitted(&self) -> usize {
        self.refitted
    }

    /// States.
    pub fn states(&self) -> usize {
        self.floors.iter().map(BTreeMap::len).sum()
    }
}

/// Survey walks read once (positions, transmitters interned, the grid cells each walk covers
/// and trains) so that sites from any subset of the walks are cheap: the leave-one-walk-out
/// of the survey's calibration builds one site per walk. [`survey`] is
/// `PreparedSurvey::new(..)?.site(all walks, None)`.
///
/// A site from a subset equals, fingerprints and all, the site [`survey`] builds from those
/// walks alone: states, edges and zones are recomputed from the subset's walks, and each
/// state's fingerprints are refitted unless its training scans (and the clip level) are the
/// ones the reused [`SurveyFits`] were fitted from, in which case the fit would be the same.
#[derive(Clone, Debug)]
pub struct PreparedSurvey<'a> {
    name: String,
    north: North,
    options: SurveyOptions,
    /// Every transmitter read in a positioned scan, sorted (the radio map's order).
    transmitters: Vec<TransmitterId>,
    floors: Vec<PreparedFloor<'a>>,
}

impl<'a> PreparedSurvey<'a> {
    /// Reads the walks of `floors`.
    pub fn new(
        name: &str,
        floors: &[SurveyFloor<'a>],
        north: North,
        options: &SurveyOptions,
    ) -> Result<PreparedSurvey<'a>, SiteError> {
        let invalid = |path: &str, message: String| SiteError::Invalid { path: path.into(), message };
        if !(options.spacing_m > 0.0
            && options.coverage_m >= 0.0
            && options.fingerprint_radius_m > 0.0
            && (0.0..=MAX_UNSURVEYED_MARGIN_M).contains(&options.unsurveyed_margin_m))
        {
            return Err(invalid(
                "survey",
                format!(
                    "spacing and radii must be positive, the unsurveyed margin 0-{MAX_UNSURVEYED_MARGIN_M} m"
                ),
            ));
        }
        let s = options.spacing_m;
        let cell = |p: Point2<f64>| ((p.x / s).round() as i64, (p.y / s).round() as i64);
        let centre = |c: Cell| Point2::new(c.0 as f64 * s, c.1 as f64 * s);
        // Transmitters interned once, in first-seen order, then renumbered in sorted order.
        let mut interned: HashMap<TransmitterId, u32> = HashMap::new();
        let mut prepared = Vec::with_capacity(floors.len());
        for floor in floors {
            let mut walks = Vec::with_capacity(floor.walks.len());
            for walk in &floor.walks {
                let scans = positioned_scans(walk, options)
                    .into_iter()
                    .map(|(p, scan)| {
                        let readings = scan
                            .readings
                            .into_iter()
                            .map(|r| {
                                let next = interned.len() as u32;
                                (*interned.entry(r.transmitter).or_insert(next), r.rssi_dbm)
                            })
                            .collect::<Vec<_>>();
                        (p, readings)
                    })
                    .collect::<Vec<_>>();
                let gaps = walk
                    .wifi_scans
                    .windows(2)
                    .map(|p| (p[1].timestamp_ns - p[0].timestamp_ns) as f64 * 1e-9)
                    .collect();
                let weakest_wifi_dbm = walk
                    .wifi_scans
                    .iter()
                    .flat_map(|scan| &scan.readings)
                    .filter(|r| matches!(r.transmitter, TransmitterId::Wifi { .. }) && r.rssi_dbm.is_finite())
                    .map(|r| r.rssi_dbm)
                    .fold(f64::INFINITY, f64::min);
                let path = if walk.waypoints.len() >= 2 { path_points(walk) } else { Vec::new() };
                walks.push((path, scans, gaps, weakest_wifi_dbm));
            }
            prepared.push(walks);
        }
        let mut transmitters: Vec<(TransmitterId, u32)> = interned.into_iter().collect();
        transmitters.sort_unstable();
        let mut renumber = vec![0u32; transmitters.len()];
        for (k, (_, old)) in transmitters.iter().enumerate() {
            renumber[*old as usize] = k as u32;
        }
        let transmitters: Vec<TransmitterId> = transmitters.into_iter().map(|(id, _)| id).collect();
        let mut out = Vec::with_capacity(floors.len());
        for (floor, walks) in floors.iter().zip(prepared) {
            // Grid cells near where people walked, and the walks that cover each.
            let reach = (options.coverage_m / s).ceil() as i64;
            let mut cells: BTreeMap<Cell, CandidateCell> = BTreeMap::new();
            for (w, (path, ..)) in walks.iter().enumerate() {
                for &p in path {
                    let (ci, cj) = cell(p);
                    for di in -reach..=reach {
                        for dj in -reach..=reach {
                            let c = (ci + di, cj + dj);
                            if (centre(c) - p).norm() <= options.coverage_m {
                                let covered = &mut cells.entry(c).or_default().covered_by;
                                if covered.last() != Some(&(w as u32)) {
                                    covered.push(w as u32);
                                }
                            }
                        }
                    }
                }
            }
            // Scans train every covered cell within the fingerprint radius.
            let r = (options.fingerprint_radius_m / s).ceil() as i64;
            let mut prepared_walks = Vec::with_capacity(walks.len());
            for (w, (path, scans, gaps, weakest_wifi_dbm)) in walks.into_iter().enumerate() {
                let mut interned_scans = Vec::with_capacity(scans.len());
                for (k, (p, readings)) in scans.into_iter().enumerate() {
                    let (ci, cj) = cell(p);
                    for di in -r..=r {
                        for dj in -r..=r {
                            let c = (ci + di, cj + dj);
                            if let Some(candidate) = cells.get_mut(&c) {
                                if (centre(c) - p).norm() <= options.fingerprint_radius_m {
                                    candidate.training.push((w as u32, k as u32));
                                }
                            }
                        }
                    }
                    interned_scans
                        .push(readings.into_iter().map(|(t, rssi)| (renumber[t as usize], rssi)).collect());
                }
                prepared_walks.push(PreparedWalk { path, scans: interned_scans, gaps, weakest_wifi_dbm });
            }
            if let Some(plan) = floor.plan {
                for (&c, candidate) in cells.iter_mut() {
                    candidate.room = named_room(plan, centre(c));
                }
            }
            out.push(PreparedFloor {
                name: floor.name.clone(),
                plan: floor.plan,
                walks: prepared_walks,
                cells,
            });
        }
        Ok(PreparedSurvey {
            name: name.to_owned(),
            north,
            options: options.clone(),
            transmitters,
            floors: out,
        })
    }

    /// Walks on floor `floor` (in the order given).
    pub fn walk_count(&self, floor: usize) -> usize {
        self.floors.get(floor).map_or(0, |f| f.walks.len())
    }

    /// The clip level of a site from the walks `keep` keeps, dBm.
    fn clip_dbm(&self, keep: &dyn Fn(usize, usize) -> bool) -> f64 {
        if !self.options.measure_clip {
            return self.options.build.fit.clip_dbm;
        }
        let weakest = self
            .floors
            .iter()
            .enumerate()
            .flat_map(|(f, floor)| floor.walks.iter().enumerate().filter(move |(w, _)| keep(f, *w)))
            .map(|(_, w)| w.weakest_wifi_dbm)
            .fold(f64::INFINITY, f64::min);
        if weakest.is_finite() {
            weakest - 1.0
        } else {
            self.options.build.fit.clip_dbm
        }
    }

    /// Fits the states of the site from the walks `keep(floor, walk)` keeps, reusing from
    /// `reuse` every state whose training scans are the same; the fits of states that need one
    /// run on `threads` threads.
    pub fn fit(
        &self,
        keep: &dyn Fn(usize, usize) -> bool,
        reuse: Option<&SurveyFits>,
        threads: usize,
    ) -> SurveyFits {
        let clip_dbm = self.clip_dbm(keep);
        let kept: Vec<Vec<bool>> = self
            .floors
            .iter()
            .enumerate()
            .map(|(f, floor)| (0..floor.walks.len()).map(|w| keep(f, w)).collect())
            .collect();
        let reuse = reuse.filter(|r| r.clip_dbm == clip_dbm && r.kept.len() == kept.len());
        let build =
            BuildOptions { fit: FitOptions { clip_dbm, ..self.options.build.fit }, ..self.options.build };
        let fit = build.stored_fit();
        let mut floors: Vec<BTreeMap<Cell, CellFit>> = vec![BTreeMap::new(); self.floors.len()];
        // Cells to fit: (floor, cell, kept training scans).
        let mut todo: Vec<(usize, Cell, Training)> = Vec::new();
        for (f, floor) in self.floors.iter().enumerate() {
            let kept = &kept[f];
            for (&c, candidate) in &floor.cells {
                if !candidate.covered_by.iter().any(|&w| kept[w as usize]) {
                    continue;
                }
                let training: Training =
                    candidate.training.iter().copied().filter(|&(w, _)| kept[w as usize]).collect();
                // A state without a scan of its own would be "nowhere" to the radio: left out.
                if training.is_empty() {
                    continue;
                }
                // The same scans as the reused fit: every scan it had is still kept.
                let same = reuse.and_then(|r| {
                    let was = &r.kept[f];
                    let unchanged = was.len() == kept.len()
                        && candidate.training.iter().all(|&(w, _)| was[w as usize] == kept[w as usize]);
                    unchanged.then(|| r.floors[f].get(&c)).flatten()
                });
                match same {
                    Some(cached) => {
                        floors[f].insert(c, cached.clone());
                    }
                    None => todo.push((f, c, training)),
                }
            }
        }
        let fit_cell = |f: usize, training: &[(u32, u32)]| -> CellFit {
            let walks = &self.floors[f].walks;
            let mut readings = Vec::new();
            for (k, &(w, scan)) in training.iter().enumerate() {
                readings.extend(
                    walks[w as usize].scans[scan as usize].iter().map(|&(t, rssi)| (t, k as u32, rssi)),
                );
            }
            let mut heard: Vec<u32> = readings.iter().map(|r| r.0).collect();
            heard.sort_unstable();
            heard.dedup();
            let models = waymark::site::fit_columns(readings, training.len(), build.model, &fit);
            CellFit { scans: training.len() as u32, heard, models }
        };
        let threads = threads.max(1).min(todo.len().max(1));
        let chunk = todo.len().div_ceil(threads).max(1);
        let fitted: Vec<(usize, Cell, CellFit)> = if threads == 1 {
            todo.iter().map(|(f, c, t)| (*f, *c, fit_cell(*f, t))).collect()
        } else {
            std::thread::scope(|scope| {
                let workers: Vec<_> = todo
                    .chunks(chunk)
                    .map(|part| {
                        let fit_cell = &fit_cell;
                        scope.spawn(move || {
                            part.iter().map(|(f, c, t)| (*f, *c, fit_cell(*f, t))).collect::<Vec<_>>()
                        })
                    })
                    .collect();
                workers
                    .into_iter()
                    .flat_map(|w| w.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
                    .collect()
            })
        };
        let refitted = fitted.len();
        for (f, c, cell_fit) in fitted {
            floors[f].insert(c, cell_fit);
        }
        SurveyFits { clip_dbm, kept, floors, refitted }
    }

    /// The site from the walks `keep(floor, walk)` keeps (walk indices as given to
    /// [`new`](Self::new)), reusing the fingerprints of `reuse` where they are the same.
    pub fn site(
        &self,
        keep: &dyn Fn(usize, usize) -> bool,
        reuse: Option<&SurveyFits>,
    ) -> Result<(Site, SurveyReport), SiteError> {
        let threads =
            if reuse.is_some() { 1 } else { std::thread::available_parallelism().map_or(1, |n| n.get()) };
        let fits = self.fit(keep, reuse, threads);
        self.assemble(&fits)
    }

    /// The site from fitted states.
    pub fn assemble(&self, fits: &SurveyFits) -> Result<(Site, SurveyReport), SiteError> {
        let options = &self.options;
        let s = options.spacing_m;
        let centre = |c: Cell| Point2::new(c.0 as f64 * s, c.1 as f64 * s);
        let cell = |p: Point2<f64>| ((p.x / s).round() as i64, (p.y / s).round() as i64);
        // The transmitters these states read, renumbered in order.
        let mut local = vec![u32::MAX; self.transmitters.len()];
        for cell_fit in fits.floors.iter().flat_map(|f| f.values()) {
            for &t in &cell_fit.heard {
                local[t as usize] = 0;
            }
        }
        let mut ids = Vec::new();
        for (t, slot) in local.iter_mut().enumerate() {
            if *slot == 0 {
                *slot = ids.len() as u32;
                ids.push(self.transmitters[t].clone());
            }
        }
        let mut builder = SiteBuilder::new(&self.name);
        builder.north(self.north);
        let mut triples = Vec::new();
        let mut reports = Vec::new();
        let mut zones: Vec<Zone> = Vec::new();
        for (f, (floor, kept)) in self.floors.iter().zip(&fits.kept).enumerate() {
            let index = builder.floor(
                &floor.name,
                floor_rank(&floor.name).unwrap_or(reports.len() as i32) as f64 * STOREY_HEIGHT_M,
            );
            let mut report = FloorSurvey { name: floor.name.clone(), ..FloorSurvey::default() };
            let walks: Vec<&PreparedWalk> =
                floor.walks.iter().zip(kept).filter(|(_, &k)| k).map(|(w, _)| w).collect();
            report.walks = walks.iter().filter(|w| !w.path.is_empty()).count();
            report.scans = walks.iter().map(|w| w.scans.len()).sum();
            let mut gaps: Vec<f64> = walks.iter().flat_map(|w| w.gaps.iter().copied()).collect();
            gaps.sort_by(f64::total_cmp);
            report.scan_interval_median_s = gaps.get(gaps.len() / 2).copied().unwrap_or(f64::NAN);
            report.scan_interval_p99_s = gaps.get(gaps.len() * 99 / 100).copied().unwrap_or(f64::NAN);
            let mut ids_of: BTreeMap<Cell, u32> = BTreeMap::new();
            for (&c, cell_fit) in &fits.floors[f] {
                let id = builder.fitted_state(index, centre(c), cell_fit.scans);
                triples.extend(cell_fit.models.iter().map(|&(t, g)| (id, local[t as usize], g)));
                ids_of.insert(c, id);
            }
            report.states = ids_of.len();
            // Walkable space around the map that no walk covered: unsurveyed states.
            let margin = (options.unsurveyed_margin_m / s).floor() as i64;
            let mut rooms_of: BTreeMap<Cell, Option<usize>> =
                ids_of.keys().map(|c| (*c, floor.cells[c].room)).collect();
            if margin > 0 {
                let mut extra: BTreeSet<Cell> = BTreeSet::new();
                for &(ci, cj) in ids_of.keys() {
                    for di in -margin..=margin {
                        for dj in -margin..=margin {
                            let c = (ci + di, cj + dj);
                            if (di * di + dj * dj) as f64 * s * s <= options.unsurveyed_margin_m.powi(2)
                                && !ids_of.contains_key(&c)
                            {
                                extra.insert(c);
                            }
                        }
                    }
                }
                for c in extra {
                    if floor.plan.is_some_and(|plan| !plan.on_floor(centre(c))) {
                        continue;
                    }
                    let room = match floor.cells.get(&c) {
                        Some(candidate) => candidate.room,
                        None => floor.plan.and_then(|plan| named_room(plan, centre(c))),
                    };
                    ids_of.insert(c, builder.unsurveyed_state(index, centre(c)));
                    rooms_of.insert(c, room);
                    report.unsurveyed_states += 1;
                }
            }
            if let Some(plan) = floor.plan {
                let made = plan_zones(&floor.name, plan, ids_of.iter().map(|(c, &id)| (rooms_of[c], id)));
                report.zones = made.len();
                report.zoned_states = made.iter().map(|z| z.states.len()).sum();
                zones.extend(made);
            }
            let paths: Vec<&Vec<Point2<f64>>> =
                walks.iter().map(|w| &w.path).filter(|p| !p.is_empty()).collect();
            // A plan polygon that survey walks went inside is open space, not a room with
            // walls: plans label atria, decorative and "auxiliary" areas as polygons too.
            let mut open: Vec<usize> = floor
                .plan
                .filter(|_| options.walls)
                .map(|plan| {
                    (0..plan.rooms.len())
                        .filter(|&r| {
                            paths.iter().copied().flatten().any(|&p| plan.rooms[r].polygon.contains(p))
                        })
                        .collect()
                })
                .unwrap_or_default();
            open.sort_unstable();
            report.open_rooms = open.len();
            // Edges: grid neighbours (8-connected) joined unless a wall separates them, or
            // whenever a survey walk stepped from one to the other.
            let mut walked: BTreeSet<(Cell, Cell)> = BTreeSet::new();
            for points in &paths {
                for w in points.windows(2) {
                    let (a, b) = (cell(w[0]), cell(w[1]));
                    if a != b && (a.0 - b.0).abs() <= 1 && (a.1 - b.1).abs() <= 1 {
                        walked.insert((a.min(b), a.max(b)));
                    }
                }
            }
            for (&a, &ia) in &ids_of {
                for (di, dj) in [(1, 0), (0, 1), (1, 1), (1, -1)] {
                    let b = (a.0 + di, a.1 + dj);
                    let Some(&ib) = ids_of.get(&b) else { continue };
                    let on_walk = walked.contains(&(a.min(b), a.max(b)));
                    let walled = options.walls
                        && floor
                            .plan
                            .is_some_and(|plan| plan.crosses_wall_except(centre(a), centre(b), &open));
                    if walled {
                        report.walled_edges += 1;
                    }
                    if !walled || on_walk {
                        if walled {
                            report.walked_edges += 1;
                        }
                        builder.edge(ia, ib, None);
                        report.edges += 1;
                    }
                }
            }
            reports.push(report);
        }
        let build = BuildOptions {
            fit: FitOptions { clip_dbm: fits.clip_dbm, ..options.build.fit },
            ..options.build
        };
        // Builder ids are state indices.
        let site = builder.build_fitted(build, ids, triples)?.with_zones(zones)?;
        let transmitters = site.radio().transmitters().len();
        Ok((site, SurveyReport { floors: reports, transmitters }))
    }
}

/// The smallest named polygon of `plan` holding `p`: the room a state there belongs to.
fn named_room(plan: &FloorPlan, p: Point2<f64>) -> Option<usize> {
    plan.room_at(p).filter(|&r| !plan.rooms[r].name.trim().is_empty())
}

/// Zones from a floor plan's named polygons: each state (its smallest named polygon, index)
/// joins that polygon. A zone is called `floor/name`, with ` #k` after the name when the
/// plan has several polygons of that name (k counts them in plan order), so names are unique
/// in the site. Polygons holding no state make no zone.
fn plan_zones(
    floor: &str,
    plan: &FloorPlan,
    states: impl Iterator<Item = (Option<usize>, u32)>,
) -> Vec<Zone> {
    let mut members: BTreeMap<usize, Vec<u32>> = BTreeMap::new();
    for (room, id) in states {
        if let Some(room) = room {
            members.entry(room).or_default().push(id);
        }
    }
    members
        .into_iter()
        .map(|(room, states)| {
            let name = &plan.rooms[room].name;
            let same = plan.rooms.iter().filter(|r| &r.name == name).count();
            let name = if same > 1 {
                let k = plan.rooms[..room].iter().filter(|r| &r.name == name).count() + 1;
                format!("{floor}/{name} #{k}")
            } else {
                format!("{floor}/{name}")
            };
            Zone { name, kind: ZoneKind::Room, states }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::Waypoint;
    use waymark::radio::TransmitterId;
    use waymark::site::StateKind;

    fn walk(name: &str, from: (f64, f64), to: (f64, f64), seconds: u64) -> Trace {
        let ns = 1_000_000_000u64;
        let ap = |k: u8| TransmitterId::wifi(&format!("aa:bb:cc:dd:ee:{k:02x}")).unwrap();
        let mut trace = Trace { name: name.into(), ..Trace::default() };
        trace.waypoints = vec![
            Waypoint { timestamp_ns: 0, x: from.0, y: from.1 },
            Waypoint { timestamp_ns: seconds * ns, x: to.0, y: to.1 },
        ];
        for t in 1..seconds {
            let f = t as f64 / seconds as f64;
            let x = from.0 + f * (to.0 - from.0);
            // Two APs at x = 0 and x = 20 with a 2 dB/m slope, and one stale entry.
            trace.wifi_scans.push(Scan {
                timestamp_ns: t * ns,
                readings: vec![
                    Reading { transmitter: ap(1), rssi_dbm: -40.0 - 2.0 * x, age_ns: 0 },
                    Reading { transmitter: ap(2), rssi_dbm: -40.0 - 2.0 * (20.0 - x).abs(), age_ns: 0 },
                    Reading { transmitter: ap(3), rssi_dbm: -50.0, age_ns: 10 * ns },
                ],
            });
        }
        trace
    }

    #[test]
    fn floor_ranks() {
        assert_eq!(floor_rank("B1"), Some(-1));
        assert_eq!(floor_rank("F1"), Some(0));
        assert_eq!(floor_rank("F4"), Some(3));
        assert_eq!(floor_rank("2F"), Some(1));
        assert_eq!(floor_rank("lobby"), None);
    }

    #[test]
    fn states_sit_on_the_grid_along_the_walks_with_fitted_fingerprints() {
        let walks = [walk("a", (0.0, 1.0), (20.0, 1.0), 20), walk("b", (20.0, 1.0), (0.0, 1.0), 20)];
        let floor = SurveyFloor { name: "F1".into(), plan: None, walks: walks.iter().collect() };
        let (site, report) = survey("test", &[floor], North::default(), &SurveyOptions::default()).unwrap();
        assert_eq!(report.floors[0].walks, 2);
        assert_eq!(report.floors[0].scans, 38);
        assert!(site.states().iter().all(|s| (s.position.x / 2.0).fract() == 0.0));
        let surveyed = || site.states().iter().filter(|s| s.kind == StateKind::Surveyed);
        assert!(surveyed().all(|s| (s.position.y - 1.0).abs() <= 2.0));
        // The stale entry is never heard: the map knows only the two fresh APs.
        assert_eq!(report.transmitters, 2);
        // The state at x = 10 m heard AP 1 at about -60 dBm.
        let s10 = site.states().iter().position(|s| s.position == Point2::new(10.0, 0.0)).unwrap();
        let (_, _, g) = site.radio().fingerprints().find(|f| f.0 == s10 as u32 && f.1 == 0).unwrap();
        assert!((g.mean_dbm + 60.0).abs() < 3.0, "{g:?}");
        // A connected strip: every state has a neighbour.
        assert!((0..site.states().len()).all(|i| !site.neighbours(i).is_empty()));
    }

    #[test]
    fn walls_cut_edges_unless_somebody_walked_through() {
        // A wall at x = 9..11 m (a room polygon) across the strip; walk "a" only goes up to 8 m.
        let room = crate::io::floor_plan::Room {
            name: "shop".into(),
            polygon: crate::io::floor_plan::Polygon {
                rings: vec![vec![
                    Point2::new(9.0, -10.0),
                    Point2::new(11.0, -10.0),
                    Point2::new(11.0, 10.0),
                    Point2::new(9.0, 10.0),
                ]],
            },
        };
        let plan = FloorPlan { width_m: 40.0, height_m: 20.0, outline: vec![], rooms: vec![room] };
        let walks = [walk("a", (0.0, 0.0), (8.0, 0.0), 8), walk("b", (12.0, 0.0), (20.0, 0.0), 8)];
        let floor = SurveyFloor { name: "F1".into(), plan: Some(&plan), walks: walks.iter().collect() };
        let (site, report) = survey(
            "test",
            &[floor],
            North::default(),
            &SurveyOptions { walls: true, ..SurveyOptions::default() },
        )
        .unwrap();
        assert!(report.floors[0].walled_edges > 0);
        assert_eq!(report.floors[0].walked_edges, 0);
        let left = site.states().iter().position(|s| s.position == Point2::new(8.0, 0.0)).unwrap();
        assert!(site.neighbours(left).iter().all(|&(n, _)| site.states()[n as usize].position.x <= 8.0));
        // Walking through the wall (here, through the whole room) opens it.
        let walks = [walk("c", (0.0, 0.0), (20.0, 0.0), 20)];
        let floor = SurveyFloor { name: "F1".into(), plan: Some(&plan), walks: walks.iter().collect() };
        let (_, report) = survey(
            "test",
            &[floor],
            North::default(),
            &SurveyOptions { walls: true, ..SurveyOptions::default() },
        )
        .unwrap();
        assert_eq!(report.floors[0].open_rooms, 1);
        assert_eq!(report.floors[0].walled_edges, 0);
    }

    #[test]
    fn named_plan_polygons_become_zones() {
        let rect = |name: &str, x0: f64, x1: f64| crate::io::floor_plan::Room {
            name: name.into(),
            polygon: crate::io::floor_plan::Polygon {
                rings: vec![vec![
                    Point2::new(x0, -10.0),
                    Point2::new(x1, -10.0),
                    Point2::new(x1, 10.0),
                    Point2::new(x0, 10.0),
                ]],
            },
        };
        let rooms = vec![
            rect("kiosk", -1.0, 5.0),
            rect("", 5.0, 9.0),
            rect("kiosk", 9.0, 13.0),
            rect("shop", 13.0, 30.0),
            rect("far", 50.0, 60.0),
        ];
        let plan = FloorPlan { width_m: 60.0, height_m: 20.0, outline: vec![], rooms };
        let walks = [walk("a", (0.0, 0.0), (20.0, 0.0), 20)];
        let floor = SurveyFloor { name: "F1".into(), plan: Some(&plan), walks: walks.iter().collect() };
        // The unsurveyed states around the walk join the polygons they are in, too.
        let options = SurveyOptions { unsurveyed_margin_m: 6.0, ..SurveyOptions::default() };
        let (site, report) = survey("test", &[floor], North::default(), &options).unwrap();
        assert!(site.states().iter().any(|s| s.kind == StateKind::Unsurveyed && s.position.x > 20.0));
        let names: Vec<&str> = site.zones().iter().map(|z| z.name.as_str()).collect();
        assert_eq!(
            names,
            ["F1/kiosk #1", "F1/kiosk #2", "F1/shop"],
            "no zone for the unnamed or empty polygon"
        );
        assert_eq!(report.floors[0].zones, 3);
        for (i, s) in site.states().iter().enumerate() {
            let expected = match s.position.x {
                x if x < -1.0 => None,
                x if x < 5.0 => Some(0),
                x if x < 9.0 => None,
                x if x < 13.0 => Some(1),
                _ => Some(2),
            };
            assert_eq!(site.zone_of(i), expected, "state at {}", s.position);
        }
        let zoned = (0..site.states().len()).filter(|&i| site.zone_of(i).is_some()).count();
        assert_eq!(report.floors[0].zoned_states, zoned);
        // Without a plan, no zones.
        let floor = SurveyFloor { name: "F1".into(), plan: None, walks: walks.iter().collect() };
        assert!(survey("test", &[floor], North::default(), &SurveyOptions::default())
            .unwrap()
            .0
            .zones()
            .is_empty());
    }

    #[test]
    fn a_site_without_a_walk_reusing_fits_is_the_survey_without_it() {
        let mut weak = walk("d", (10.0, -4.0), (10.0, 10.0), 14);
        // The weakest WiFi reading of all: leaving "d" out moves the clip level.
        weak.wifi_scans[3].readings.push(Reading {
            transmitter: TransmitterId::wifi("aa:bb:cc:dd:ee:44").unwrap(),
            rssi_dbm: -99.0,
            age_ns: 0,
        });
        let walks = [
            walk("a", (0.0, 1.0), (20.0, 1.0), 20),
            walk("b", (20.0, 1.0), (0.0, 1.0), 20),
            walk("c", (0.0, 7.0), (16.0, 7.0), 16),
            weak,
            walk("e", (22.0, 0.0), (28.0, 0.0), 6),
        ];
        let floors = [
            SurveyFloor { name: "F1".into(), plan: None, walks: walks[..4].iter().collect() },
            SurveyFloor { name: "F2".into(), plan: None, walks: vec![&walks[0], &walks[1], &walks[4]] },
        ];
        let options = SurveyOptions::default();
        let prepared = PreparedSurvey::new("test", &floors, North::default(), &options).unwrap();
        let all = prepared.fit(&|_, _| true, None, 2);
        assert_eq!(all.refitted(), all.states());
        let (full, _) = prepared.assemble(&all).unwrap();
        let (direct, _) = survey("test", &floors, North::default(), &options).unwrap();
        assert_eq!(full.to_json(), direct.to_json());
        for (f, out) in [(0, 0), (0, 2), (0, 3), (1, 1), (1, 2)] {
            let keep = |ff: usize, w: usize| !(ff == f && w == out);
            let fits = prepared.fit(&keep, Some(&all), 1);
            let (incremental, _) = prepared.assemble(&fits).unwrap();
            let without: Vec<SurveyFloor> = floors
                .iter()
                .enumerate()
                .map(|(ff, floor)| SurveyFloor {
                    walks: floor
                        .walks
                        .iter()
                        .enumerate()
                        .filter(|(w, _)| keep(ff, *w))
                        .map(|(_, t)| *t)
                        .collect(),
                    ..floor.clone()
                })
                .collect();
            let (rebuilt, _) = survey("test", &without, North::default(), &options).unwrap();
            assert_eq!(incremental.to_json(), rebuilt.to_json(), "without floor {f} walk {out}");
            assert!(incremental.states().len() <= full.states().len());
            if (f, out) == (0, 3) {
                // The clip level moved: every state is fitted again.
                assert!(incremental.radio().clip_dbm() > full.radio().clip_dbm());
                assert_eq!(fits.refitted(), fits.states());
            } else {
                assert!(fits.refitted() > 0 && fits.refitted() < fits.states(), "{}", fits.refitted());
            }
        }
        // Walk "c" alone covered y = 7 away from "d" (x = 10): its states go with it.
        let fits = prepared.fit(&|f, w| !(f == 0 && w == 2), Some(&all), 1);
        let (without_c, _) = prepared.assemble(&fits).unwrap();
        let high = |site: &Site| {
            let surveyed = |s: &&waymark::site::State| s.kind == StateKind::Surveyed;
            site.states()
                .iter()
                .filter(surveyed)
                .filter(|s| s.floor == 0 && s.position.y > 5.0 && s.position.x < 6.0)
                .count()
        };
        assert!(high(&full) > 0);
        assert_eq!(high(&without_c), 0);
    }

    /// Unsurveyed states fill the floor within the margin of the surveyed ones and nowhere
    /// else: no fingerprint, joined to the grid, off the plan's outline never; the JSON site
    /// file keeps them; the radio gives each what a state that never heard anything scores.
    #[test]
    fn unsurveyed_states_fill_the_floor_within_the_margin() {
        use crate::io::floor_plan::Polygon;
        let walks = [walk("a", (0.0, 0.0), (20.0, 0.0), 20)];
        // The floor ends 4 m beyond the walk's end: x from -30 to 24 m, y from -30 to 30 m.
        let outline = Polygon {
            rings: vec![vec![
                Point2::new(-30.0, -30.0),
                Point2::new(24.0, -30.0),
                Point2::new(24.0, 30.0),
                Point2::new(-30.0, 30.0),
            ]],
        };
        let plan = FloorPlan { width_m: 54.0, height_m: 60.0, outline: vec![outline], rooms: vec![] };
        let floor = SurveyFloor { name: "F1".into(), plan: Some(&plan), walks: walks.iter().collect() };
        let options = SurveyOptions { unsurveyed_margin_m: 8.0, ..SurveyOptions::default() };
        let (site, report) =
            survey("test", std::slice::from_ref(&floor), North::default(), &options).unwrap();
        let (surveyed, unsurveyed): (Vec<_>, Vec<_>) =
            site.states().iter().partition(|s| s.kind == StateKind::Surveyed);
        assert_eq!(report.floors[0].unsurveyed_states, unsurveyed.len());
        assert_eq!(report.floors[0].states, surveyed.len());
        assert!(!unsurveyed.is_empty());
        let distance =
            |p: Point2<f64>| surveyed.iter().map(|s| (s.position - p).norm()).fold(f64::INFINITY, f64::min);
        for s in &unsurveyed {
            assert!(distance(s.position) <= 8.0 + 1e-9 && s.position.x <= 24.0, "{:?}", s.position);
            assert_eq!(s.training_scans, 0);
            assert!(!site.neighbours(s.id as usize).is_empty());
        }
        // West of the walk, where the floor goes on, the margin is filled out to 8 m.
        assert!(unsurveyed.iter().any(|s| s.position == Point2::new(-8.0, 0.0)));
        assert!(site
            .radio()
            .fingerprints()
            .all(|(state, _, _)| site.states()[state as usize].kind == StateKind::Surveyed));
        // A scan's likelihood at an unsurveyed state is the no-fingerprint one.
        let resolved = site.radio().resolve(&walks[0].wifi_scans[5], None);
        let mut ln = vec![0.0; site.states().len()];
        let unheard = site.radio().ln_likelihood(&resolved.observations, &mut ln);
        assert!(unsurveyed.iter().all(|s| (ln[s.id as usize] - unheard).abs() < 1e-9));
        // Kept by the site file.
        let again = Site::from_json(site.to_json().as_bytes()).unwrap();
        assert_eq!(again.states(), site.states());
        // No margin, no unsurveyed states.
        let options = SurveyOptions { unsurveyed_margin_m: 0.0, ..SurveyOptions::default() };
        let (site, _) = survey("test", std::slice::from_ref(&floor), North::default(), &options).unwrap();
        assert!(site.states().iter().all(|s| s.kind == StateKind::Surveyed));
        let options = SurveyOptions { unsurveyed_margin_m: f64::NAN, ..SurveyOptions::default() };
        assert!(survey("test", &[floor], North::default(), &options).is_err());
    }

    #[test]
    fn no_walks_is_a_typed_error() {
        let floor = SurveyFloor { name: "F1".into(), plan: None, walks: vec![] };
        assert!(survey("x", &[floor], North::default(), &SurveyOptions::default()).is_err());
    }
}
