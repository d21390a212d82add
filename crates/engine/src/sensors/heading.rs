//! Heading (Hoang §4): the magnetometer yaw ψ from the rotation matrix built with gravity and
//! the magnetic field (tilt compensation, Android's convention), the gyroscope rate projected
//! on gravity (yaw rate dψ), and a one-dimensional Kalman filter on ψ fusing both, with angle
//! wrapping. Magnetic disturbances are recognised by the field's magnitude and dip straying
//! from the Earth's, and by the compass turning differently from the gyroscope; a disturbed
//! compass is all but ignored.

use super::config::MotionConfig;
use super::filter::{lowpass_alpha, ns_to_s, s_to_ns, wrap_angle};
use nalgebra::Vector3;

/// Azimuth of the phone's +y axis (top edge) projected on the horizontal plane, rad clockwise
/// from magnetic north in (-π, π], from `gravity` (what the accelerometer reads at rest: it
/// points up) and the magnetic `field`, both in the phone's frame.
///
/// This is Android's `SensorManager.getRotationMatrix` followed by `getOrientation`:
/// H = E × A is east, M = A × H is north, and azimuth = atan2(H_y, M_y). A phone flat, screen
/// up, top pointing north reads 0; top pointing east reads +π/2. `None` when the field is
/// (nearly) parallel to gravity or the phone's y axis is (nearly) vertical.
pub fn compass_azimuth(gravity: &Vector3<f64>, field: &Vector3<f64>) -> Option<f64> {
    let (ng, nf) = (gravity.norm(), field.norm());
    if !(ng.is_finite() && nf.is_finite() && ng > 0.0 && nf > 0.0) {
        return None;
    }
    let h = field.cross(gravity);
    let nh = h.norm();
    if nh < 0.05 * ng * nf {
        return None;
    }
    let east = h / nh;
    let up = gravity / ng;
    let north = up.cross(&east);
    if east.y.hypot(north.y) < 0.2 {
        return None;
    }
    Some(east.y.atan2(north.y))
}

/// Rate of change of the azimuth, rad/s (clockwise seen from above is positive), from the
/// gyroscope's `rate` (rad/s, phone frame) projected on the vertical given by `gravity`
/// (Hoang §4: the gyroscope data projected into the world frame). A phone flat on a turntable
/// turning clockwise reads a negative z rate and a positive yaw rate.
pub fn gyro_yaw_rate(gravity: &Vector3<f64>, rate: &Vector3<f64>) -> f64 {
    let n = gravity.norm();
    if n > 0.0 && n.is_finite() {
        -gravity.dot(rate) / n
    } else {
        -rate.z
    }
}

/// Inclination of `field` below the horizontal plane given by `gravity` (which points up),
/// rad: positive when the field points down, as in the northern hemisphere.
pub fn field_dip(gravity: &Vector3<f64>, field: &Vector3<f64>) -> Option<f64> {
    let d = gravity.norm() * field.norm();
    (d > 0.0 && d.is_finite()).then(|| (-gravity.dot(field) / d).clamp(-1.0, 1.0).asin())
}

/// One-dimensional Kalman filter on the azimuth (Hoang §4): predict with the gyroscope's yaw
/// change, update with the compass. F = H = 1; angles are wrapped in the state and innovation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeadingKalman {
    /// Azimuth, rad, in (-π, π].
    pub yaw: f64,
    /// Its variance, rad².
    pub var: f64,
}

#[allow(non_snake_case)]
impl HeadingKalman {
    /// Starts from a first measurement `z` with variance `R`.
    pub fn new(z: f64, R: f64) -> Self {
        Self { yaw: wrap_angle(z), var: R }
    }

    /// Prediction: x⁻ = x + Δψ (gyroscope), P⁻ = P + Q.
    pub fn predict(&mut self, delta_yaw: f64, Q: f64) {
        self.yaw = wrap_angle(self.yaw + delta_yaw);
        self.var += Q;
    }

    /// Update with a compass azimuth `z` of variance `R`: innovation y = wrap(z − x⁻),
    /// S = P⁻ + R, K = P⁻/S, x = wrap(x⁻ + K y), P = (1 − K) P⁻. Returns the innovation.
    pub fn update(&mut self, z: f64, R: f64) -> f64 {
        let y = wrap_angle(z - self.yaw);
        let S = self.var + R;
        let K = self.var / S;
        self.yaw = wrap_angle(self.yaw + K * y);
        self.var *= 1.0 - K;
        debug_assert!(self.var >= 0.0);
        y
    }
}

/// Running median of a scalar with exponential forgetting (a decaying histogram): a robust
/// estimate of the undisturbed field, since most of a walk is away from steel.
#[derive(Clone, Debug)]
pub struct RunningMedian {
    lo: f64,
    width: f64,
    bins: Vec<f64>,
    total: f64,
    /// Weight of the next sample; grows as exp(t/τ), rescaled when large.
    weight: f64,
    tau_s: f64,
    last_ns: Option<u64>,
    /// Seconds of data seen.
    seen_s: f64,
    cached: Option<f64>,
    dirty: u32,
}

impl RunningMedian {
    /// A histogram of `bins` bins from `lo` to `hi`, forgetting with time constant `tau_s`.
    pub fn new(lo: f64, hi: f64, bins: usize, tau_s: f64) -> Self {
        Self {
            lo,
            width: (hi - lo) / bins as f64,
            bins: vec![0.0; bins],
            total: 0.0,
            weight: 1.0,
            tau_s,
            last_ns: None,
            seen_s: 0.0,
            cached: None,
            dirty: 0,
        }
    }

    /// Adds a value at `t_ns`; `max_dt_s` caps how much time one sample can account for.
    pub fn push(&mut self, t_ns: u64, x: f64, max_dt_s: f64) {
        let dt = self.last_ns.map_or(0.0, |l| ns_to_s(t_ns.saturating_sub(l)));
        self.last_ns = Some(t_ns);
        self.seen_s += dt.min(max_dt_s);
        self.weight *= (dt.min(10.0 * self.tau_s) / self.tau_s).exp();
        if self.weight > 1e100 {
            let scale = 1.0 / self.weight;
            self.bins.iter_mut().for_each(|b| *b *= scale);
            self.total *= scale;
            self.weight = 1.0;
        }
        let k = ((x - self.lo) / self.width).floor();
        let k = if k.is_nan() { 0 } else { k.clamp(0.0, (self.bins.len() - 1) as f64) as usize };
        self.bins[k] += self.weight;
        self.total += self.weight;
        self.dirty += 1;
    }

    /// Seconds of data seen.
    pub fn seen_s(&self) -> f64 {
        self.seen_s
    }

    /// The weighted median (refreshed every 16 samples).
    pub fn median(&mut self) -> Option<f64> {
        if self.total <= 0.0 {
            return None;
        }
        if self.cached.is_none() || self.dirty >= 16 {
            self.dirty = 0;
            let half = self.total / 2.0;
            let mut acc = 0.0;
            let mut m = self.lo + self.width * self.bins.len() as f64;
            for (k, &b) in self.bins.iter().enumerate() {
                if acc + b >= half && b > 0.0 {
                    m = self.lo + self.width * (k as f64 + (half - acc) / b);
                    break;
                }
                acc += b;
            }
            self.cached = Some(m);
        }
        self.cached
    }
}

/// What the heading filter knows at one instant.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HeadingState {
    /// Magnetic azimuth of the phone and its total standard deviation (filter and floor),
    /// rad; `None` before any compass sample.
    pub magnetic: Option<(f64, f64)>,
    /// Gyroscope-integrated azimuth, arbitrary origin, rad; `None` without a gyroscope.
    pub relative: Option<f64>,
}

/// Sensor fusion for heading: gravity direction, gyroscope integration, compass with
/// disturbance detection, and the Kalman filter.
#[derive(Clone, Debug)]
pub struct HeadingTracker {
    gravity_tau_s: f64,
    compass_var: f64,
    correlation_s: f64,
    q_gyro: f64,
    q_free: f64,
    floor_var: f64,
    field_tolerance: f64,
    dip_tolerance: f64,
    disagreement: f64,
    hold_ns: u64,
    disturbed_factor: f64,
    max_gap_ns: u64,
    reference: Option<(f64, f64)>,
    /// Gravity's direction in the phone frame (low-passed accelerometer, turned by the gyro).
    gravity: Option<Vector3<f64>>,
    last_accel_ns: Option<u64>,
    last_gyro: Option<(u64, f64)>,
    last_mag_ns: Option<u64>,
    kf: Option<HeadingKalman>,
    kf_ns: u64,
    relative: Option<f64>,
    magnitude: RunningMedian,
    dip: RunningMedian,
    /// Compass-minus-gyro heading, low-passed as a unit vector, and its recent history.
    difference: Option<(f64, f64)>,
    history: [(u64, f64); 32],
    history_len: usize,
    history_head: usize,
    disturbed_until_ns: Option<u64>,
    last_disturbed: bool,
}

/// The field reference is learned from this much data before it is used, s.
const REFERENCE_LEARN_S: f64 = 5.0;
/// The Earth's field at the surface is 22-67 µT (World Magnetic Model): outside, disturbed.
const EARTH_FIELD_RANGE_UT: (f64, f64) = (22.0, 67.0);
/// Time constant of the compass-minus-gyro low-pass, s.
const DIFFERENCE_TAU_S: f64 = 0.25;
/// The compass and gyro turn-over-time are compared over this span, ns.
const DISAGREEMENT_SPAN_NS: u64 = 1_000_000_000;

impl HeadingTracker {
    /// A tracker configured from `config`.
    pub fn new(config: &MotionConfig) -> Self {
        Self {
            gravity_tau_s: config.gravity_lowpass_s,
            compass_var: config.compass_sigma_rad.powi(2),
            correlation_s: config.compass_correlation_s,
            q_gyro: config.gyro_heading_noise.powi(2),
            q_free: config.free_heading_noise.powi(2),
            floor_var: config.heading_sigma_floor_rad.powi(2),
            field_tolerance: config.field_tolerance_ut,
            dip_tolerance: config.dip_tolerance_rad,
            disagreement: config.disagreement_rad,
            hold_ns: s_to_ns(config.disturbance_hold_s),
            disturbed_factor: config.disturbed_variance_factor,
            max_gap_ns: s_to_ns(config.max_gap_s),
            reference: config.earth_field.map(|f| (f.magnitude_ut, f.dip_rad)),
            gravity: None,
            last_accel_ns: None,
            last_gyro: None,
            last_mag_ns: None,
            kf: None,
            kf_ns: 0,
            relative: None,
            magnitude: RunningMedian::new(0.0, 128.0, 256, 120.0),
            dip: RunningMedian::new(-std::f64::consts::FRAC_PI_2, std::f64::consts::FRAC_PI_2, 360, 120.0),
            difference: None,
            history: [(0, 0.0); 32],
            history_len: 0,
            history_head: 0,
            disturbed_until_ns: None,
            last_disturbed: false,
        }
    }

    fn gyro_alive(&self, t_ns: u64) -> bool {
        self.last_gyro.is_some_and(|(t, _)| t_ns.saturating_sub(t) <= self.max_gap_ns)
    }

    /// Whether the magnetometer has delivered within the gap limit before `t_ns`.
    pub fn compass_alive(&self, t_ns: u64) -> bool {
        self.last_mag_ns.is_some_and(|t| t_ns.saturating_sub(t) <= self.max_gap_ns)
    }

    /// Whether the last magnetometer sample was judged disturbed.
    pub fn disturbed(&self) -> bool {
        self.last_disturbed
    }

    fn up(&self) -> Vector3<f64> {
        self.gravity.unwrap_or(Vector3::new(0.0, 0.0, 1.0))
    }

    /// Grows the filter's variance up to `t_ns`.
    fn grow(&mut self, t_ns: u64) {
        let dt = ns_to_s(t_ns.saturating_sub(self.kf_ns));
        let q = if self.gyro_alive(t_ns) { self.q_gyro } else { self.q_free };
        if let Some(kf) = &mut self.kf {
            // Bounded: beyond a full turn of uncertainty nothing more is lost.
            kf.predict(0.0, q * dt);
            kf.var = kf.var.min(100.0);
        }
        self.kf_ns = self.kf_ns.max(t_ns);
    }

    /// An accelerometer sample: gravity's direction by a first-order low-pass.
    pub fn on_accelerometer(&mut self, t_ns: u64, a: Vector3<f64>) {
        let dt = self.last_accel_ns.map(|l| t_ns.saturating_sub(l));
        self.last_accel_ns = Some(t_ns);
        match (&mut self.gravity, dt) {
            (Some(g), Some(dt)) if dt <= self.max_gap_ns => {
                *g += (a - *g) * lowpass_alpha(ns_to_s(dt), self.gravity_tau_s);
            }
            _ => self.gravity = Some(a),
        }
    }

    /// A gyroscope sample: turns gravity, integrates the yaw rate, predicts the filter.
    pub fn on_gyroscope(&mut self, t_ns: u64, w: Vector3<f64>) {
        let rate = gyro_yaw_rate(&self.up(), &w);
        let previous = self.last_gyro.filter(|&(t, _)| t_ns.saturating_sub(t) <= self.max_gap_ns);
        if let Some((t0, rate0)) = previous {
            let dt = ns_to_s(t_ns - t0);
            // A vector fixed in the world turns the other way in the phone: ġ = g × ω.
            if let Some(g) = &mut self.gravity {
                *g += g.cross(&w) * dt;
            }
            let delta = 0.5 * (rate0 + rate) * dt;
            self.relative = Some(wrap_angle(self.relative.unwrap_or(0.0) + delta));
            if let Some(kf) = &mut self.kf {
                kf.predict(delta, self.q_gyro * ns_to_s(t_ns.saturating_sub(self.kf_ns)));
            }
            self.kf_ns = self.kf_ns.max(t_ns);
        } else {
            self.relative.get_or_insert(0.0);
            self.grow(t_ns);
            self.difference = None;
            self.history_len = 0;
        }
        self.last_gyro = Some((t_ns, rate));
    }

    /// A magnetometer sample: disturbance test, then the compass update. Returns whether the
    /// compass is disturbed.
    pub fn on_magnetometer(&mut self, t_ns: u64, m: Vector3<f64>) -> bool {
        let dt_s = self.last_mag_ns.map_or(self.correlation_s, |l| ns_to_s(t_ns.saturating_sub(l)));
        self.last_mag_ns = Some(t_ns);
        let up = self.up();
        let magnitude = m.norm();
        let dip = field_dip(&up, &m);
        let max_dt = ns_to_s(self.max_gap_ns);
        self.magnitude.push(t_ns, magnitude, max_dt);
        if let Some(d) = dip {
            self.dip.push(t_ns, d, max_dt);
        }
        let reference = self.reference.or_else(|| {
            (self.magnitude.seen_s() >= REFERENCE_LEARN_S && self.dip.seen_s() >= REFERENCE_LEARN_S)
                .then(|| Some((self.magnitude.median()?, self.dip.median()?)))
                .flatten()
        });
        let mut flagged = match reference {
            Some((f0, i0)) => {
                (magnitude - f0).abs() > self.field_tolerance
                    || dip.is_some_and(|d| (d - i0).abs() > self.dip_tolerance)
            }
            None => !(EARTH_FIELD_RANGE_UT.0..=EARTH_FIELD_RANGE_UT.1).contains(&magnitude),
        };
        let z = compass_azimuth(&up, &m);
        if let (Some(z), Some(rel), true) = (z, self.relative, self.gyro_alive(t_ns)) {
            flagged |= self.disagrees(t_ns, wrap_angle(z - rel), dt_s);
        }
        if flagged {
            self.disturbed_until_ns = Some(t_ns.saturating_add(self.hold_ns));
        }
        let disturbed = self.disturbed_until_ns.is_some_and(|u| t_ns <= u);
        self.last_disturbed = disturbed;
        if let Some(z) = z {
            // Samples closer than the correlation time share their information.
            let mut r = self.compass_var * self.correlation_s / dt_s.clamp(1e-3, self.correlation_s);
            if disturbed {
                r *= self.disturbed_factor;
            }
            match &mut self.kf {
                Some(_) => {
                    self.grow(t_ns);
                    if let Some(kf) = &mut self.kf {
                        kf.update(z, r);
                    }
                }
                None => {
                    let var =
                        if disturbed { self.compass_var * self.disturbed_factor } else { self.compass_var };
                    self.kf = Some(HeadingKalman::new(z, var));
                    self.kf_ns = t_ns;
                }
            }
        }
        disturbed
    }

    /// Tracks compass-minus-gyro; true when it moved by more than the tolerance in a second.
    fn disagrees(&mut self, t_ns: u64, d: f64, dt_s: f64) -> bool {
        let (c, s) = match self.difference {
            Some((c, s)) => {
                let a = lowpass_alpha(dt_s, DIFFERENCE_TAU_S);
                (c + a * (d.cos() - c), s + a * (d.sin() - s))
            }
            None => (d.cos(), d.sin()),
        };
        self.difference = Some((c, s));
        let now = s.atan2(c);
        // Record at most every 100 ms.
        let newest = (self.history_head + self.history.len() - 1) % self.history.len();
        if self.history_len == 0 || t_ns.saturating_sub(self.history[newest].0) >= 100_000_000 {
            self.history[self.history_head] = (t_ns, now);
            self.history_head = (self.history_head + 1) % self.history.len();
            self.history_len = (self.history_len + 1).min(self.history.len());
        }
        // The newest record at least a span old.
        let then = (1..=self.history_len)
            .map(|k| self.history[(self.history_head + self.history.len() - k) % self.history.len()])
            .find(|&(t, _)| t_ns.saturating_sub(t) >= DISAGREEMENT_SPAN_NS);
        then.is_some_and(|(_, old)| wrap_angle(now - old).abs() > self.disagreement)
    }

    /// The heading state at `t_ns` (after every sample up to it was processed).
    pub fn state(&self, t_ns: u64) -> HeadingState {
        let q = if self.gyro_alive(t_ns) { self.q_gyro } else { self.q_free };
        let magnetic = self.kf.map(|kf| {
            let var = (kf.var + q * ns_to_s(t_ns.saturating_sub(self.kf_ns))).min(100.0);
            (kf.yaw, (var + self.floor_var).sqrt())
        });
        HeadingState { magnetic, relative: self.relative.filter(|_| self.last_gyro.is_some()) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use nalgebra::{Rotation3, Unit};
    use std::f64::consts::{FRAC_PI_2, PI};

    /// Earth field in the world frame (x east, y north, z up): 50 µT, dip 65°.
    fn earth() -> Vector3<f64> {
        let dip = 65f64.to_radians();
        Vector3::new(0.0, 50.0 * dip.cos(), -50.0 * dip.sin())
    }

    /// What the phone reads for an attitude: azimuth ψ (clockwise from north) of its y axis,
    /// then pitch about its x axis, then roll about its y axis.
    fn readings(azimuth: f64, pitch: f64, roll: f64) -> (Vector3<f64>, Vector3<f64>) {
        let r = Rotation3::from_axis_angle(&Vector3::z_axis(), -azimuth)
            * Rotation3::from_axis_angle(&Vector3::x_axis(), pitch)
            * Rotation3::from_axis_angle(&Vector3::y_axis(), roll);
        let g_world = Vector3::new(0.0, 0.0, 9.81);
        (r.inverse() * g_world, r.inverse() * earth())
    }

    #[test]
    fn flat_phone_follows_android_convention() {
        // Flat, top to north: gravity +z, field has +y and -z.
        let (g, m) = readings(0.0, 0.0, 0.0);
        assert_relative_eq!(g, Vector3::new(0.0, 0.0, 9.81), epsilon = 1e-9);
        assert_relative_eq!(compass_azimuth(&g, &m).unwrap(), 0.0, epsilon = 1e-12);
        // Top to the east: +90°; to the west: -90°; south: ±180°.
        let (g, m) = readings(FRAC_PI_2, 0.0, 0.0);
        assert!(m.x < -1.0, "north is to the phone's left: {m}");
        assert_relative_eq!(compass_azimuth(&g, &m).unwrap(), FRAC_PI_2, epsilon = 1e-12);
        let (g, m) = readings(-FRAC_PI_2, 0.0, 0.0);
        assert_relative_eq!(compass_azimuth(&g, &m).unwrap(), -FRAC_PI_2, epsilon = 1e-12);
        let (g, m) = readings(PI, 0.0, 0.0);
        assert_relative_eq!(compass_azimuth(&g, &m).unwrap().abs(), PI, epsilon = 1e-12);
    }

    /// Tilt compensation: the azimuth is right whatever the pitch and roll, while the naive
    /// atan2 of the raw field's x and y is not.
    #[test]
    fn tilt_compensation_on_known_attitudes() {
        for &azimuth in &[0.3, 1.2, -2.5, 3.0] {
            for &(pitch, roll) in &[(0.3, 0.0), (0.0, -0.4), (0.5, 0.5), (-0.7, 0.2)] {
                let (g, m) = readings(azimuth, pitch, roll);
                let z = compass_azimuth(&g, &m).unwrap();
                assert_relative_eq!(wrap_angle(z - azimuth), 0.0, epsilon = 1e-9);
                assert_relative_eq!(field_dip(&g, &m).unwrap(), 65f64.to_radians(), epsilon = 1e-9);
            }
        }
        let (_, m) = readings(0.3, 0.5, 0.5);
        let naive = (-m.x).atan2(m.y);
        assert!(wrap_angle(naive - 0.3).abs() > 0.1, "tilt matters: {naive}");
        // A phone standing on its bottom edge has no azimuth of its y axis.
        let (g, m) = readings(0.3, FRAC_PI_2, 0.0);
        assert!(compass_azimuth(&g, &m).is_none());
    }

    /// The yaw rate is the gyroscope rate about gravity, with the azimuth's sign.
    #[test]
    fn yaw_rate_is_the_rate_about_gravity() {
        // Flat, turning clockwise seen from above at 1 rad/s: z rate -1.
        let g = Vector3::new(0.0, 0.0, 9.81);
        assert_relative_eq!(gyro_yaw_rate(&g, &Vector3::new(0.0, 0.0, -1.0)), 1.0);
        // Tilted 40° about x: the same world rotation shows up on y and z.
        let tilt = Rotation3::from_axis_angle(&Vector3::x_axis(), 40f64.to_radians());
        let g_phone = tilt.inverse() * g;
        let w_phone = tilt.inverse() * Vector3::new(0.0, 0.0, -1.0);
        assert!(w_phone.y.abs() > 0.5);
        assert_relative_eq!(gyro_yaw_rate(&g_phone, &w_phone), 1.0, epsilon = 1e-12);
        // A rotation about a horizontal axis is no yaw.
        let axis = Unit::new_normalize(Vector3::new(1.0, 0.0, 0.0));
        assert_relative_eq!(gyro_yaw_rate(&g, &axis.into_inner()), 0.0);
    }

    /// A hand-computed update: P⁻ = 0.04, R = 0.01, z − x = 0.1 → K = 0.8, x += 0.08,
    /// P = 0.008. Across ±π the innovation takes the short way.
    #[test]
    fn kalman_update_by_hand() {
        let mut kf = HeadingKalman::new(0.5, 0.03);
        kf.predict(0.0, 0.01);
        assert_relative_eq!(kf.var, 0.04, epsilon = 1e-15);
        let y = kf.update(0.6, 0.01);
        assert_relative_eq!(y, 0.1, epsilon = 1e-12);
        assert_relative_eq!(kf.yaw, 0.58, epsilon = 1e-12);
        assert_relative_eq!(kf.var, 0.008, epsilon = 1e-12);

        let mut kf = HeadingKalman::new(PI - 0.05, 0.04);
        let y = kf.update(-PI + 0.05, 0.04);
        assert_relative_eq!(y, 0.1, epsilon = 1e-12);
        assert_relative_eq!(kf.yaw, PI, epsilon = 1e-12);
        kf.predict(0.2, 0.0);
        assert_relative_eq!(kf.yaw, -PI + 0.2, epsilon = 1e-12);
    }

    #[test]
    fn running_median_ignores_a_minority_and_forgets() {
        let mut m = RunningMedian::new(0.0, 128.0, 256, 10.0);
        for k in 0..1000u64 {
            let x = if k % 5 == 0 { 90.0 } else { 50.0 + (k % 3) as f64 * 0.1 };
            m.push(k * 10_000_000, x, 0.5);
        }
        let median = m.median().unwrap();
        assert!((median - 50.1).abs() < 0.5, "{median}");
        assert_relative_eq!(m.seen_s(), 9.99, epsilon = 1e-9);
        // A new field for a long time replaces the old one.
        for k in 1000..7000u64 {
            m.push(k * 10_000_000, 30.0, 0.5);
        }
        assert!((m.median().unwrap() - 30.0).abs() < 0.5);
    }

    /// The tracker in a clean field, phone flat and turning, with and without a gyroscope; and
    /// a strong extra field is flagged.
    #[test]
    fn tracker_fuses_and_flags_disturbances() {
        let config = MotionConfig::default();
        let mut h = HeadingTracker::new(&config);
        // 20 s at 50 Hz turning at 0.2 rad/s.
        for k in 0..1000u64 {
            let t = k * 20_000_000;
            let azimuth = wrap_angle(0.2 * t as f64 * 1e-9);
            let (g, m) = readings(azimuth, 0.05, -0.05);
            h.on_accelerometer(t, g);
            h.on_gyroscope(t, Vector3::new(0.0, 0.0, -0.2));
            assert!(!h.on_magnetometer(t, m), "clean field flagged at {t}");
            if k > 50 {
                let (yaw, sigma) = h.state(t).magnetic.unwrap();
                assert!(wrap_angle(yaw - azimuth).abs() < 0.03, "{yaw} vs {azimuth}");
                assert!(sigma < 10f64.to_radians());
            }
        }
        // 20 µT east: the magnitude or the compass/gyro disagreement gives it away.
        let t0 = 20_000_000_000;
        let mut flagged = false;
        for k in 0..100u64 {
            let t = t0 + k * 20_000_000;
            let (g, m) = readings(0.0, 0.05, -0.05);
            h.on_accelerometer(t, g);
            h.on_gyroscope(t, Vector3::zeros());
            flagged |= h.on_magnetometer(t, m + Vector3::new(20.0, 0.0, 0.0));
        }
        assert!(flagged);
    }
}
