//! Survey walks → a site file: reference states on a regular spacing over where the surveyors
//! walked, fingerprints fitted from the scans near each (censored Gaussians, Hoang §3), the
//! walkable graph from the floor plan and from where people actually walked, the site's north
//! and the walkers' step length. When the floor plan names its polygons (shops, rooms), the
//! states inside each named polygon become a zone.
//!
//! States never sit on the labelled waypoints: they are grid points, so a method that snaps to
//! the grid gains nothing from the surveyors' habit of revisiting the same waypoints.

pub mod motion;

pub use motion::{calibrate_motion, MotionCalibration};

use crate::io::ilc::EventOptions;
use crate::io::{FloorPlan, Trace};
use crate::radio::{FitOptions, Reading, Scan, TransmitterId};
use crate::site::{BuildOptions, North, Site, SiteBuilder, SiteError, Zone, ZoneKind};
use nalgebra::Point2;
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet, HashMap};

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
    /// A survey scan trains every state within this distance of where it was taken, m. 5 m:
    /// a state then sees about two walking seconds of scans either side of it, 20-30 scans
    /// where a corridor was walked a few times. Measured on the F1 split (`waymark eval
    /// target/ilc/site1/F1 --fingerprint-radius-m R`): single-scan MLE 8.17 / 6.58 m mean and
    /// the fused engine 7.83 / 6.28 m for R = 3 / 5 m; the other four floors were not used to
    /// choose it.
    pub fingerprint_radius_m: f64,
    /// Whether the floor plan's polygons cut the walkable graph (except where a survey walk
    /// crossed them). Off by default: on the competition's plans, shop and "auxiliary area"
    /// outlines are not where walls are — with them, `waymark eval target/ilc/site1/F1` gave
    /// 6.28 m for the fused engine, without them 5.70 m, and with the true motion fed in,
    /// 7.4 m against 5.4 m. The graph then comes from where people walked (states exist only
    /// near survey walks). Turn on for plans whose polygons are real walls.
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
    let invalid = |path: &str, message: String| SiteError::Invalid { path: path.into(), message };
    if !(options.spacing_m > 0.0 && options.coverage_m >= 0.0 && options.fingerprint_radius_m > 0.0) {
        return Err(invalid("survey", "spacing and radii must be positive".into()));
    }
    let s = options.spacing_m;
    let mut build = options.build;
    if options.measure_clip {
        let weakest = floors
            .iter()
            .flat_map(|f| &f.walks)
            .flat_map(|w| &w.wifi_scans)
            .flat_map(|scan| &scan.readings)
            .filter(|r| matches!(r.transmitter, TransmitterId::Wifi { .. }) && r.rssi_dbm.is_finite())
            .map(|r| r.rssi_dbm)
            .fold(f64::INFINITY, f64::min);
        if weakest.is_finite() {
            build.fit.clip_dbm = weakest - 1.0;
        }
    }
    let mut builder = SiteBuilder::new(name);
    builder.north(north);
    let mut reports = Vec::new();
    let mut zones: Vec<Zone> = Vec::new();
    for floor in floors {
        let index = builder.floor(
            &floor.name,
            floor_rank(&floor.name).unwrap_or(reports.len() as i32) as f64 * STOREY_HEIGHT_M,
        );
        let mut report = FloorSurvey { name: floor.name.clone(), ..FloorSurvey::default() };
        // Grid cells near where people walked.
        let cell = |p: Point2<f64>| ((p.x / s).round() as i64, (p.y / s).round() as i64);
        let centre = |c: (i64, i64)| Point2::new(c.0 as f64 * s, c.1 as f64 * s);
        let reach = (options.coverage_m / s).ceil() as i64;
        let mut cells: BTreeSet<(i64, i64)> = BTreeSet::new();
        let mut paths = Vec::new();
        for walk in floor.walks.iter().filter(|w| w.waypoints.len() >= 2) {
            report.walks += 1;
            let points = path_points(walk);
            for &p in &points {
                let (ci, cj) = cell(p);
                for di in -reach..=reach {
                    for dj in -reach..=reach {
                        let c = (ci + di, cj + dj);
                        if (centre(c) - p).norm() <= options.coverage_m {
                            cells.insert(c);
                        }
                    }
                }
            }
            paths.push(points);
        }
        let mut gaps: Vec<f64> = floor
            .walks
            .iter()
            .flat_map(|w| {
                w.wifi_scans.windows(2).map(|p| (p[1].timestamp_ns - p[0].timestamp_ns) as f64 * 1e-9)
            })
            .collect();
        gaps.sort_by(f64::total_cmp);
        report.scan_interval_median_s = gaps.get(gaps.len() / 2).copied().unwrap_or(f64::NAN);
        // Scans train every cell within the fingerprint radius.
        let mut training: HashMap<(i64, i64), Vec<Scan>> = HashMap::new();
        let r = (options.fingerprint_radius_m / s).ceil() as i64;
        for walk in &floor.walks {
            for (p, scan) in positioned_scans(walk, options) {
                report.scans += 1;
                let (ci, cj) = cell(p);
                for di in -r..=r {
                    for dj in -r..=r {
                        let c = (ci + di, cj + dj);
                        if cells.contains(&c) && (centre(c) - p).norm() <= options.fingerprint_radius_m {
                            training.entry(c).or_default().push(scan.clone());
                        }
                    }
                }
            }
        }
        // A state without a scan of its own would be "nowhere" to the radio: leave it out.
        let mut ids: BTreeMap<(i64, i64), u32> = BTreeMap::new();
        for c in cells {
            if let Some(scans) = training.remove(&c) {
                ids.insert(c, builder.state(index, centre(c), scans));
            }
        }
        report.states = ids.len();
        if let Some(plan) = floor.plan {
            let made = plan_zones(&floor.name, plan, ids.iter().map(|(&c, &id)| (centre(c), id)));
            report.zones = made.len();
            report.zoned_states = made.iter().map(|z| z.states.len()).sum();
            zones.extend(made);
        }
        // A plan polygon that survey walks went inside is open space, not a room with walls:
        // plans label atria, decorative and "auxiliary" areas as polygons too.
        let mut open: Vec<usize> = floor
            .plan
            .filter(|_| options.walls)
            .map(|plan| {
                (0..plan.rooms.len())
                    .filter(|&r| paths.iter().flatten().any(|&p| plan.rooms[r].polygon.contains(p)))
                    .collect()
            })
            .unwrap_or_default();
        open.sort_unstable();
        report.open_rooms = open.len();
        // Edges: grid neighbours (8-connected) joined unless a wall separates them, or
        // whenever a survey walk stepped from one to the other.
        let mut walked: BTreeSet<((i64, i64), (i64, i64))> = BTreeSet::new();
        for points in &paths {
            for w in points.windows(2) {
                let (a, b) = (cell(w[0]), cell(w[1]));
                if a != b && (a.0 - b.0).abs() <= 1 && (a.1 - b.1).abs() <= 1 {
                    walked.insert((a.min(b), a.max(b)));
                }
            }
        }
        for (&a, &ia) in &ids {
            for (di, dj) in [(1, 0), (0, 1), (1, 1), (1, -1)] {
                let b = (a.0 + di, a.1 + dj);
                let Some(&ib) = ids.get(&b) else { continue };
                let on_walk = walked.contains(&(a.min(b), a.max(b)));
                let walled = options.walls
                    && floor.plan.is_some_and(|plan| plan.crosses_wall_except(centre(a), centre(b), &open));
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
    // Builder ids are state indices.
    let site = builder.build(build)?.with_zones(zones)?;
    let transmitters = site.radio().transmitters().len();
    Ok((site, SurveyReport { floors: reports, transmitters }))
}

/// Zones from a floor plan's named polygons: each state (position, index) joins the smallest
/// named polygon holding it. A zone is called `floor/name`, with ` #k` after the name when the
/// plan has several polygons of that name (k counts them in plan order), so names are unique
/// in the site. Polygons holding no state make no zone.
fn plan_zones(floor: &str, plan: &FloorPlan, states: impl Iterator<Item = (Point2<f64>, u32)>) -> Vec<Zone> {
    let mut members: BTreeMap<usize, Vec<u32>> = BTreeMap::new();
    for (p, id) in states {
        if let Some(room) = plan.room_at(p).filter(|&r| !plan.rooms[r].name.trim().is_empty()) {
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
    use crate::radio::TransmitterId;

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
        assert!(site.states().iter().all(|s| (s.position.y - 1.0).abs() <= 2.0));
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
        let (site, report) = survey("test", &[floor], North::default(), &SurveyOptions::default()).unwrap();
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
    fn no_walks_is_a_typed_error() {
        let floor = SurveyFloor { name: "F1".into(), plan: None, walks: vec![] };
        assert!(survey("x", &[floor], North::default(), &SurveyOptions::default()).is_err());
    }
}
