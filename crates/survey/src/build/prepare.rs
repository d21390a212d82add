//! The survey walks read once: positions, interned transmitters and the grid cells each
//! walk covers and trains.

use super::*;

/// A grid cell, by its indices (the centre is the indices × spacing).
pub(super) type Cell = (i64, i64);

/// Training scans of a state, as (walk, scan) indices within its floor.
pub(super) type Training = Vec<(u32, u32)>;

/// One survey walk, read once: where it went and its scans with interned transmitters.
#[derive(Clone, Debug)]
pub(super) struct PreparedWalk {
    /// Points every half metre along the waypoints; empty for a walk with fewer than two.
    pub(super) path: Vec<Point2<f64>>,
    /// Positioned scans, stale readings removed, as (transmitter index, RSSI).
    pub(super) scans: Vec<Vec<(u32, f64)>>,
    /// Times between consecutive WiFi scans, s.
    pub(super) gaps: Vec<f64>,
    /// The weakest finite WiFi reading, dBm (infinite without one).
    pub(super) weakest_wifi_dbm: f64,
}

/// A grid cell some survey walk covered.
#[derive(Clone, Debug, Default)]
pub(super) struct CandidateCell {
    /// Walks (with a path) that passed within the coverage distance.
    pub(super) covered_by: Vec<u32>,
    /// The scans (walk, scan) within the fingerprint radius, in walk then scan order.
    pub(super) training: Vec<(u32, u32)>,
    /// The smallest named plan polygon holding the centre.
    pub(super) room: Option<usize>,
}

/// Where a cell's centre lies on its floor's plan: what an unsurveyed state there needs.
/// Looked up once per survey rather than once per site built from it.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct PlanCell {
    /// Inside the plan's outline (always, without a plan).
    pub(super) on_floor: bool,
    /// The smallest named plan polygon holding the centre.
    pub(super) room: Option<usize>,
}

impl PlanCell {
    /// Where `p` lies on `plan`.
    fn at(plan: &FloorPlan, p: Point2<f64>) -> PlanCell {
        PlanCell { on_floor: plan.on_floor(p), room: named_room(plan, p) }
    }
}

#[derive(Clone, Debug)]
pub(super) struct PreparedFloor<'a> {
    pub(super) name: String,
    pub(super) plan: Option<&'a FloorPlan>,
    pub(super) geo: Option<WalkedGeo>,
    pub(super) walks: Vec<PreparedWalk>,
    pub(super) cells: BTreeMap<Cell, CandidateCell>,
    /// With a plan: each candidate cell and each cell within the unsurveyed margin of one,
    /// where it lies on the plan (every cell a site from these walks can hold). Empty without
    /// a plan.
    pub(super) plan_cells: HashMap<Cell, PlanCell>,
}

/// One state's fitted fingerprint.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct CellFit {
    /// Training scans.
    pub(super) scans: u32,
    /// Every transmitter (index into the survey's) read in those scans, sorted.
    pub(super) heard: Vec<u32>,
    /// Model per transmitter heard with a finite RSSI, sorted.
    pub(super) models: Vec<(u32, Gaussian)>,
}

/// The fingerprints of one site built by [`PreparedSurvey`], kept to be reused: a site built
/// from a subset of the walks refits only the states whose training scans changed.
#[derive(Clone, Debug)]
pub struct SurveyFits {
    /// The clip level they were fitted at, dBm.
    pub(super) clip_dbm: f64,
    /// The walks they were fitted from, per floor.
    pub(super) kept: Vec<Vec<bool>>,
    /// Per floor, per state cell.
    pub(super) floors: Vec<BTreeMap<Cell, CellFit>>,
    /// States fitted afresh (the rest were reused).
    pub(super) refitted: usize,
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
    pub(super) name: String,
    pub(super) north: North,
    pub(super) options: SurveyOptions,
    /// Every transmitter read in a positioned scan, sorted (the radio map's order).
    pub(super) transmitters: Vec<TransmitterId>,
    /// Groups of `transmitters` that one radio sends, found in every walk's scans (a
    /// property of the hardware, so a site of some of the walks keeps them).
    pub(super) shared_radios: Vec<Vec<u32>>,
    pub(super) floors: Vec<PreparedFloor<'a>>,
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
            // Each candidate cell and its margin (the cell itself among them) on the plan.
            let mut plan_cells = HashMap::new();
            if let Some(plan) = floor.plan {
                for (&c, candidate) in cells.iter_mut() {
                    for m in margin_cells(c, options) {
                        plan_cells.entry(m).or_insert_with(|| PlanCell::at(plan, centre(m)));
                    }
                    candidate.room = plan_cells[&c].room;
                }
            }
            out.push(PreparedFloor {
                name: floor.name.clone(),
                plan: floor.plan,
                geo: floor.geo,
                walks: prepared_walks,
                cells,
                plan_cells,
            });
        }
        let shared_radios = super::radios::shared_radios(
            out.iter().flat_map(|f| &f.walks).flat_map(|w| &w.scans).map(Vec::as_slice),
            transmitters.len(),
        );
        Ok(PreparedSurvey {
            name: name.to_owned(),
            north,
            options: options.clone(),
            transmitters,
            shared_radios,
            floors: out,
        })
    }

    /// Walks on floor `floor` (in the order given).
    pub fn walk_count(&self, floor: usize) -> usize {
        self.floors.get(floor).map_or(0, |f| f.walks.len())
    }
}

/// The cells within the unsurveyed margin of cell `c` (`c` itself included), where a site
/// whose state is at `c` puts unsurveyed states.
pub(super) fn margin_cells(c: Cell, options: &SurveyOptions) -> impl Iterator<Item = Cell> + '_ {
    let s = options.spacing_m;
    let margin = (options.unsurveyed_margin_m / s).floor() as i64;
    (-margin..=margin)
        .flat_map(move |di| (-margin..=margin).map(move |dj| (di, dj)))
        .filter(move |&(di, dj)| (di * di + dj * dj) as f64 * s * s <= options.unsurveyed_margin_m.powi(2))
        .map(move |(di, dj)| (c.0 + di, c.1 + dj))
}

/// The smallest named polygon of `plan` holding `p`: the room a state there belongs to.
pub(super) fn named_room(plan: &FloorPlan, p: Point2<f64>) -> Option<usize> {
    plan.room_at(p).filter(|&r| !plan.rooms[r].name.trim().is_empty())
}
