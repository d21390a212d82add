//! Synthetic buildings for testing and reproducing Hoang et al. §6.1: an office floor, access
//! points with log-distance path loss and log-normal shadowing, clipping, training scans fitted
//! by the EM, and random walks on the walkable graph; raw inertial samples along them, long
//! sessions, recorded-trace walks and sites of any size. Everything is seeded and deterministic.

#![deny(missing_docs)]
#![deny(rustdoc::broken_intra_doc_links)]

pub mod drift;
pub mod imu;
pub mod recorded;
pub mod scale;
pub mod session;
mod trajectory;

pub use trajectory::{Pose, Trajectory};

use nalgebra::Point2;
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};
use waymark_engine::radio::{FitOptions, Reading, RssiModel, Scan, TransmitterId};
use waymark_engine::site::{BuildOptions, Site, SiteBuilder, ZoneKind};

/// Log-distance path loss: RSSI(d) = `ref_dbm` - 10 · `exponent` · log10(d / 1 m).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathLoss {
    /// RSSI at 1 m, dBm. -45 dBm: a 2.4 GHz access point at ~0 dBm EIRP towards the phone
    /// after the 40 dB free-space loss of the first metre, minus body and antenna losses.
    pub ref_dbm: f64,
    /// Path-loss exponent. 4: the low end of the "obstructed in building" range 4-6
    /// (Rappaport, Wireless Communications, Table 4.2), for an office of walled rooms. With it
    /// a quarter of the (state, access point) pairs are clipped 50-99% of the time, so the
    /// censoring model matters as in Hoang's experiments; at 3.5 almost none are
    /// (`docs/tuning.md#simulated-office`).
    pub exponent: f64,
}

impl PathLoss {
    /// Mean RSSI at `distance_m` (at least 1 m).
    pub fn mean_dbm(&self, distance_m: f64) -> f64 {
        self.ref_dbm - 10.0 * self.exponent * distance_m.max(1.0).log10()
    }
}

/// Parameters of the synthetic office.
#[derive(Clone, Debug, PartialEq)]
pub struct OfficeConfig {
    /// Seed of the building: access point placement and training scans.
    pub seed: u64,
    /// Access points placed uniformly at random over the floor: 15 (Hoang §6.1).
    pub access_points: usize,
    /// Standard deviation of the per-scan log-normal fading, dB: σ_L = 5 (Hoang §6.1).
    pub shadowing_db: f64,
    /// Receiver clip level, dBm: -100 (Hoang §3).
    pub clip_dbm: f64,
    /// Training scans per surveyed state: 300 (Hoang §6.1).
    pub training_scans: usize,
    /// Mean signal strength over distance.
    pub path_loss: PathLoss,
    /// How fingerprints are fitted: the censored EM, or the naive fit for comparison.
    pub model: RssiModel,
}

impl Default for OfficeConfig {
    fn default() -> Self {
        Self {
            seed: 0,
            access_points: 15,
            shadowing_db: 5.0,
            clip_dbm: -100.0,
            training_scans: 300,
            path_loss: PathLoss { ref_dbm: -45.0, exponent: 4.0 },
            model: RssiModel::CensoredGaussian,
        }
    }
}

/// A zone of the simulated office: its name, kind, states, and the rectangle it covers
/// (x min, x max, y min, y max, m), which decides the true zone of a walker.
type OfficeZone = (String, ZoneKind, Vec<u32>, [f64; 4]);

/// The office's state positions, walkable edges and zones.
type OfficePlan = (Vec<Point2<f64>>, Vec<(u32, u32)>, Vec<OfficeZone>);

/// The office floor of Hoang Fig. 3 in spirit: ten rooms off a long aisle and a staircase
/// hall, 81 surveyed states 3-4.25 m apart (Hoang: 81 regular states, 3-5 m apart). The rooms,
/// the aisle and the hall are its zones.
fn office_plan() -> OfficePlan {
    let mut points = Vec::new();
    let mut edges = Vec::new();
    let mut zones: Vec<OfficeZone> = Vec::new();
    let mut add = |p: Point2<f64>| {
        points.push(p);
        (points.len() - 1) as u32
    };
    // The aisle: y 10-13, x 0-34, 11 states 3.06 m apart.
    let aisle: Vec<u32> = (0..11).map(|k| add(Point2::new(1.7 + 3.06 * k as f64, 11.5))).collect();
    for w in aisle.windows(2) {
        edges.push((w[0], w[1]));
    }
    zones.push(("aisle".into(), ZoneKind::Corridor, aisle.clone(), [0.0, 34.0, 10.0, 13.0]));
    // Ten 6.8 m x 10 m rooms, five on each side, each a 2 x 3 grid; the door is at the cell
    // nearest the aisle.
    for side in [0, 1] {
        let ys = if side == 0 { [9.0, 5.5, 2.0] } else { [14.0, 17.5, 21.0] };
        for room in 0..5 {
            let x0 = 6.8 * room as f64;
            let mut grid = [[0u32; 2]; 3];
            for (r, &y) in ys.iter().enumerate() {
                for (c, dx) in [1.9, 4.9].into_iter().enumerate() {
                    grid[r][c] = add(Point2::new(x0 + dx, y));
                }
            }
            for r in 0..3 {
                edges.push((grid[r][0], grid[r][1]));
                if r + 1 < 3 {
                    edges.push((grid[r][0], grid[r + 1][0]));
                    edges.push((grid[r][1], grid[r + 1][1]));
                }
            }
            let y_range = if side == 0 { [0.0, 10.0] } else { [13.0, 23.0] };
            zones.push((
                format!("room {}", 5 * side + room + 1),
                ZoneKind::Room,
                grid.iter().flatten().copied().collect(),
                [x0, x0 + 6.8, y_range[0], y_range[1]],
            ));
            let door = grid[0][0];
            let nearest = *aisle
                .iter()
                .min_by(|&&a, &&b| {
                    let da = (points_x(a) - (x0 + 1.9)).abs();
                    let db = (points_x(b) - (x0 + 1.9)).abs();
                    da.total_cmp(&db)
                })
                .expect("the aisle has states");
            edges.push((door, nearest));
        }
    }
    // The staircase hall east of the aisle: x 34-40, the full depth, 2 x 5 states.
    let hall_ys = [3.0, 7.25, 11.5, 15.75, 20.0];
    let mut hall = [[0u32; 2]; 5];
    for (r, &y) in hall_ys.iter().enumerate() {
        for (c, x) in [35.5, 38.5].into_iter().enumerate() {
            hall[r][c] = add(Point2::new(x, y));
        }
    }
    for r in 0..5 {
        edges.push((hall[r][0], hall[r][1]));
        if r + 1 < 5 {
            edges.push((hall[r][0], hall[r + 1][0]));
            edges.push((hall[r][1], hall[r + 1][1]));
        }
    }
    edges.push((aisle[10], hall[2][0]));
    zones.push((
        "stair hall".into(),
        ZoneKind::Hall,
        hall.iter().flatten().copied().collect(),
        [34.0, 40.0, 0.0, 23.0],
    ));
    return (points, edges, zones);

    // The aisle's x coordinates, for door placement (states are added in order).
    fn points_x(aisle_index: u32) -> f64 {
        1.7 + 3.06 * aisle_index as f64
    }
}

/// Access points and how their signal reaches the phone.
#[derive(Clone, Debug, PartialEq)]
pub struct RadioField {
    /// Access points and where they are.
    pub access_points: Vec<(TransmitterId, Point2<f64>)>,
    /// Mean signal strength over distance.
    pub path_loss: PathLoss,
    /// σ_L of the per-scan fading, dB.
    pub shadowing_db: f64,
    /// Receiver clip level, dBm.
    pub clip_dbm: f64,
}

impl RadioField {
    /// A scan at `position`: each access point's path loss plus N(0, σ_L²) fading, rounded to
    /// whole dBm as phones report it, and left out when at or below the clip level.
    pub fn scan_at(&self, position: Point2<f64>, timestamp_ns: u64, rng: &mut ChaCha8Rng) -> Scan {
        let fading = Normal::new(0.0, self.shadowing_db).expect("σ_L is finite and not negative");
        let readings = self
            .access_points
            .iter()
            .filter_map(|(id, ap)| {
                let mean = self.path_loss.mean_dbm(nalgebra::distance(ap, &position));
                let rssi = (mean + fading.sample(rng)).round();
                (rssi > self.clip_dbm).then(|| Reading { transmitter: id.clone(), rssi_dbm: rssi, age_ns: 0 })
            })
            .collect();
        Scan { timestamp_ns, readings }
    }
}

/// A generated office: the site fitted from training scans, and the truth behind it.
#[derive(Clone, Debug)]
pub struct Office {
    /// The fitted site, as a survey would produce it.
    pub site: Site,
    /// The access points that made the training and walk scans.
    pub field: RadioField,
    points: Vec<Point2<f64>>,
    adjacency: Vec<Vec<u32>>,
    /// The rectangle of each zone, by zone index.
    zone_areas: Vec<[f64; 4]>,
}

/// One epoch of a simulated walk.
#[derive(Clone, Debug)]
pub struct WalkEpoch {
    /// The scan the phone made.
    pub scan: Scan,
    /// Where the phone really was.
    pub truth: Point2<f64>,
    /// The zone (room, aisle, hall) it was in, an index into the site's zones.
    pub zone: Option<usize>,
}

/// A simulated walk.
#[derive(Clone, Debug)]
pub struct Walk {
    /// Epochs, one per scan.
    pub epochs: Vec<WalkEpoch>,
    /// Distance walked, m.
    pub length_m: f64,
    /// The walker's path over time, for synthesising inertial sensors.
    pub trajectory: Trajectory,
}

/// Hoang §6.1: "movement vectors and RSSI measurements are generated every 1.5 s".
pub const EPOCH_NS: u64 = 1_500_000_000;

/// Width and depth of the office, m.
const OFFICE_SIZE_M: (f64, f64) = (40.0, 23.0);

impl Office {
    /// Generates the office: places access points and fits every state from its training scans.
    pub fn generate(config: &OfficeConfig) -> Office {
        let (points, edges, zones) = office_plan();
        let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
        let access_points = (0..config.access_points)
            .map(|k| {
                let id = TransmitterId::wifi(&format!("02:00:00:00:{:02x}:{:02x}", k / 256, k % 256))
                    .expect("a well-formed BSSID");
                let at = Point2::new(
                    rng.random_range(0.0..OFFICE_SIZE_M.0),
                    rng.random_range(0.0..OFFICE_SIZE_M.1),
                );
                (id, at)
            })
            .collect();
        let field = RadioField {
            access_points,
            path_loss: config.path_loss,
            shadowing_db: config.shadowing_db,
            clip_dbm: config.clip_dbm,
        };
        let mut builder = SiteBuilder::new("waymark simulated office");
        let floor = builder.floor("office", 0.0);
        // The survey records the site's orientation: +y is true north here, and the Earth
        // field the simulated phones sense has the default declination.
        builder.north(waymark_engine::site::North {
            site_rotation_rad: 0.0,
            declination_rad: imu::DEFAULT_DECLINATION_RAD,
        });
        for &p in &points {
            let scans =
                (0..config.training_scans as u64).map(|k| field.scan_at(p, k * EPOCH_NS, &mut rng)).collect();
            builder.state(floor, p, scans);
        }
        let mut adjacency = vec![Vec::new(); points.len()];
        for &(a, b) in &edges {
            builder.edge(a, b, None);
            adjacency[a as usize].push(b);
            adjacency[b as usize].push(a);
        }
        for (name, kind, states, _) in &zones {
            builder.zone(name, *kind, states.clone());
        }
        let zone_areas = zones.iter().map(|z| z.3).collect();
        let options = BuildOptions {
            model: config.model,
            fit: FitOptions { clip_dbm: config.clip_dbm, ..FitOptions::default() },
        };
        let site = builder.build(options).expect("the office plan is a valid site");
        Office { site, field, points, adjacency, zone_areas }
    }

    /// The zone whose area holds `p` (the first, on a shared wall), by zone index.
    pub fn zone_at(&self, p: Point2<f64>) -> Option<usize> {
        self.zone_areas.iter().position(|a| p.x >= a[0] && p.x <= a[1] && p.y >= a[2] && p.y <= a[3])
    }

    /// Surveyed state positions, by state index.
    pub fn points(&self) -> &[Point2<f64>] {
        &self.points
    }

    /// The surveyed states one walkable edge away from `state`, in the order the plan adds them.
    pub fn neighbours(&self, state: u32) -> &[u32] {
        &self.adjacency[state as usize]
    }

    /// A random walk of about `length_m` on the walkable graph (Hoang §6.1: "random walk on
    /// the HMM graph ... of about 200 m"), at a steady pace drawn from 0.8-1.4 m/s (up to the
    /// comfortable gait speed of adults, 1.3-1.46 m/s in Bohannon 1997, and down to an office
    /// stroll), a scan every 1.5 s. At each state the walker takes a random edge other than the one it came by.
    pub fn walk(&self, seed: u64, length_m: f64) -> Walk {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let speed = rng.random_range(0.8..1.4);
        let mut at = rng.random_range(0..self.points.len()) as u32;
        let mut came_from = u32::MAX;
        // The route as a polyline through states, with the distance walked at each vertex.
        let mut route = vec![(self.points[at as usize], 0.0)];
        let mut walked = 0.0;
        while walked < length_m {
            let exits = &self.adjacency[at as usize];
            let options: Vec<u32> =
                exits.iter().copied().filter(|&n| n != came_from || exits.len() == 1).collect();
            let next = options[rng.random_range(0..options.len())];
            walked += nalgebra::distance(&self.points[at as usize], &self.points[next as usize]);
            came_from = at;
            at = next;
            route.push((self.points[at as usize], walked));
        }
        let points: Vec<Point2<f64>> = route.iter().map(|r| r.0).collect();
        let trajectory = Trajectory::new(1_000_000_000, speed, &points, Vec::new());
        let epochs = (0..)
            .map(|k| trajectory.start_ns() + k * EPOCH_NS)
            .take_while(|&t_ns| t_ns <= trajectory.end_ns())
            .map(|t_ns| {
                let truth = trajectory.pose_at(t_ns).position;
                WalkEpoch {
                    scan: self.field.scan_at(truth, t_ns, &mut rng),
                    truth,
                    zone: self.zone_at(truth),
                }
            })
            .collect();
        Walk { epochs, length_m: walked, trajectory }
    }
}
