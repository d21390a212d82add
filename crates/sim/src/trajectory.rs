//! Where a simulated walker is at any time: a polyline walked at a steady pace, with pauses.

use nalgebra::Point2;

/// The walker at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// Position in the site frame, m.
    pub position: Point2<f64>,
    /// Direction of travel (of the current segment), radians clockwise from the site's +y
    /// axis, in (-π, π].
    pub heading_rad: f64,
    /// 0 while paused, else the walking pace, m/s.
    pub speed_mps: f64,
    /// Path distance walked so far, m.
    pub walked_m: f64,
}

/// A polyline walked at `speed_mps`, stopping for a while at given distances along it.
#[derive(Clone, Debug, PartialEq)]
pub struct Trajectory {
    start_ns: u64,
    speed_mps: f64,
    /// Vertices with the path distance at each.
    route: Vec<(Point2<f64>, f64)>,
    /// (distance along the path where the pause starts, m; its duration, s), sorted.
    pauses: Vec<(f64, f64)>,
}

/// Azimuth of `to - from`, clockwise from +y.
fn azimuth(from: Point2<f64>, to: Point2<f64>) -> f64 {
    waymark_engine::hmm::azimuth(to - from)
}

impl Trajectory {
    /// A walk along `points` starting at `start_ns`, at `speed_mps` (> 0), with `pauses` as
    /// (distance along the path, duration in s). Needs at least two distinct points.
    pub fn new(start_ns: u64, speed_mps: f64, points: &[Point2<f64>], mut pauses: Vec<(f64, f64)>) -> Self {
        let mut route = Vec::with_capacity(points.len());
        let mut walked = 0.0;
        for (k, &p) in points.iter().enumerate() {
            if k > 0 {
                let step = nalgebra::distance(&points[k - 1], &p);
                if step == 0.0 {
                    continue;
                }
                walked += step;
            }
            route.push((p, walked));
        }
        pauses.sort_by(|a, b| a.0.total_cmp(&b.0));
        Self { start_ns, speed_mps, route, pauses }
    }

    /// The route's vertices, each with the time the walker reaches it: where a surveyor
    /// walking this route would tap waypoints.
    pub fn vertices(&self) -> Vec<(u64, Point2<f64>)> {
        self.route
            .iter()
            .map(|&(p, walked)| {
                let paused: f64 = self.pauses.iter().filter(|q| q.0 < walked).map(|q| q.1).sum();
                (self.start_ns + ((walked / self.speed_mps + paused) * 1e9) as u64, p)
            })
            .collect()
    }

    /// When the walk starts, ns.
    pub fn start_ns(&self) -> u64 {
        self.start_ns
    }

    /// Length of the path, m.
    pub fn length_m(&self) -> f64 {
        self.route.last().map_or(0.0, |r| r.1)
    }

    /// When the walk ends, ns.
    pub fn end_ns(&self) -> u64 {
        let paused: f64 = self.pauses.iter().map(|p| p.1).sum();
        self.start_ns + ((self.length_m() / self.speed_mps + paused) * 1e9) as u64
    }

    /// The walking pace, m/s.
    pub fn speed_mps(&self) -> f64 {
        self.speed_mps
    }

    /// Path distance walked at `t_ns` (clamped to the walk), and whether the walker is moving.
    fn walked_at(&self, t_ns: u64) -> (f64, bool) {
        let mut t = t_ns.saturating_sub(self.start_ns) as f64 * 1e-9;
        let mut offset = 0.0;
        for &(at_m, duration_s) in &self.pauses {
            let reach_s = (at_m - offset) / self.speed_mps;
            if t < reach_s {
                break;
            }
            // At the pause: walked up to at_m.
            t -= reach_s;
            offset = at_m;
            if t < duration_s {
                return (at_m.min(self.length_m()), false);
            }
            t -= duration_s;
        }
        let walked = offset + t * self.speed_mps;
        if walked >= self.length_m() {
            (self.length_m(), false)
        } else {
            (walked, true)
        }
    }

    /// The pose at `t_ns` (before the start: the first point; after the end: the last).
    pub fn pose_at(&self, t_ns: u64) -> Pose {
        let (walked, moving) = self.walked_at(t_ns);
        if self.route.len() < 2 {
            let position = self.route.first().map_or(Point2::origin(), |r| r.0);
            return Pose { position, heading_rad: 0.0, speed_mps: 0.0, walked_m: 0.0 };
        }
        let segment = self.route.partition_point(|r| r.1 <= walked).clamp(1, self.route.len() - 1);
        let ((a, sa), (b, sb)) = (self.route[segment - 1], self.route[segment]);
        let position = a + (b - a) * ((walked - sa) / (sb - sa)).clamp(0.0, 1.0);
        Pose {
            position,
            heading_rad: azimuth(a, b),
            speed_mps: if moving { self.speed_mps } else { 0.0 },
            walked_m: walked,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn walks_turns_and_pauses() {
        let points = [Point2::new(0.0, 0.0), Point2::new(0.0, 10.0), Point2::new(10.0, 10.0)];
        let t = Trajectory::new(0, 1.0, &points, vec![(5.0, 2.0)]);
        assert_relative_eq!(t.length_m(), 20.0);
        assert_eq!(t.end_ns(), 22_000_000_000);
        let p = t.pose_at(3_000_000_000);
        assert_relative_eq!(p.position.y, 3.0);
        assert_relative_eq!(p.heading_rad, 0.0);
        // Paused at 5 m from 5 s to 7 s.
        let p = t.pose_at(6_000_000_000);
        assert_relative_eq!(p.position.y, 5.0);
        assert_eq!(p.speed_mps, 0.0);
        let p = t.pose_at(17_000_000_000);
        assert_relative_eq!(p.position.x, 5.0);
        assert_relative_eq!(p.heading_rad, std::f64::consts::FRAC_PI_2);
        assert_eq!(t.pose_at(30_000_000_000).position, Point2::new(10.0, 10.0));
    }
}
