//! Position fixes from other positioning systems (GNSS near entrances, WiFi RTT, UWB) as HMM
//! observations, after El Gemayel et al. §II-C/D: the observation is a position estimate o
//! from some other system, and its probability in state i is a Gaussian around the state's
//! position (eq. 7 with one cell point per state, M_i = 1, mean l_i and Σ = σ²·I). An epoch
//! with a fix is combined with the motion transition exactly as a scan epoch is; only its
//! emission differs. [`crate::habits`] learns the fixes' error (one bias vector and one factor
//! on σ, not the paper's bias per cell: a user's history rarely holds enough fixes per cell),
//! and the engine takes it off each fix before this emission.

use crate::error::InputError;
use crate::site::{Site, MAX_COORDINATE_M};
use nalgebra::Point2;

/// A position from another positioning system.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PositionFix {
    /// When it was measured, ns, on the clock of every other input.
    pub timestamp_ns: u64,
    /// x in the site's metric frame, m (convert latitude and longitude with the site's frame).
    pub x: f64,
    /// y in the site's metric frame, m.
    pub y: f64,
    /// The floor, when the other system knows it (UWB anchors, an RTT access point's floor);
    /// `None` for GNSS. With a floor, states of other floors cannot explain the fix.
    pub floor: Option<usize>,
    /// Radius of the circle holding the true position with probability 0.68, m, as Android's
    /// `Location.getAccuracy()` defines it (`docs/accuracy.md#the-radii`). Must be > 0.
    pub accuracy_m: f64,
}

/// Probability mass inside a fix's `accuracy_m`: 0.68, Android's `Location.getAccuracy()`
/// ("the radius of 68% confidence") and the convention of Waymark's own `accuracy_m`.
pub const FIX_ACCURACY_MASS: f64 = 0.68;

/// Probability of a fix being within its gate of the true position: 0.999. A fix whose nearest
/// state lies beyond the distance that holds 99.9% of its error (3.72 σ, the χ² quantile with
/// two degrees of freedom) says the phone is not on the site, or that the fix is broken;
/// either way it is rejected rather than allowed to drag the posterior to the site's edge.
/// This is the validation gate of target tracking; the value is Waymark's choice, not a
/// paper's or a measurement: high, because a rejected fix is lost, while one accepted from the
/// far tail still has to agree with the motion and the radio to move the estimate much.
pub const FIX_GATE_MASS: f64 = 0.999;

/// Radius of the circle holding `mass` of an isotropic 2-D Gaussian of per-axis σ = 1: the
/// error's length is Rayleigh distributed, P(|e| ≤ r) = 1 − exp(−r²/2σ²), so
/// r = σ·√(−2 ln(1 − mass)).
pub fn rayleigh_radius(mass: f64) -> f64 {
    (-2.0 * (1.0 - mass).ln()).sqrt()
}

/// The per-axis σ of a fix, m: its 68% radius over [`rayleigh_radius`]`(0.68)` = 1.51, plus the
/// quantisation of the states in quadrature. A state stands for the cell around it, and the
/// true position is anywhere in it: a uniform offset over a cell `spacing_m` wide adds
/// spacing²/12 per axis (the same reasoning as Hoang's Σ_v in ARCHITECTURE.md).
pub fn sigma_m(accuracy_m: f64, spacing_m: f64) -> f64 {
    let sigma = accuracy_m / rayleigh_radius(FIX_ACCURACY_MASS);
    (sigma * sigma + spacing_m * spacing_m / 12.0).sqrt()
}

/// A coordinate the engine can compute with: finite and within the site file's bound.
fn coordinate(field: &'static str, value: f64) -> Result<(), InputError> {
    if value.is_finite() && value.abs() <= MAX_COORDINATE_M {
        Ok(())
    } else {
        Err(InputError::InvalidValue { field, value })
    }
}

/// A distance argument (an accuracy, a radius): finite, > 0, and within the site file's bound.
fn length(field: &'static str, value: f64) -> Result<(), InputError> {
    if value.is_finite() && value > 0.0 && value <= MAX_COORDINATE_M {
        Ok(())
    } else {
        Err(InputError::InvalidValue { field, value })
    }
}

fn check_floor(site: &Site, floor: usize) -> Result<(), InputError> {
    let floors = site.floors().len();
    if floor < floors {
        Ok(())
    } else {
        Err(InputError::UnknownFloor { floor, floors })
    }
}

/// Checks `fix` and writes ln p(fix | state) for every state into `out` (the Gaussian's
/// normalising constant left out: it is the same for every state). Fails, writing nothing
/// that matters, when a value is invalid or the fix is beyond its gate of every state.
pub fn ln_likelihood(site: &Site, fix: &PositionFix, out: &mut [f64]) -> Result<(), InputError> {
    coordinate("x", fix.x)?;
    coordinate("y", fix.y)?;
    length("accuracy_m", fix.accuracy_m)?;
    if let Some(floor) = fix.floor {
        check_floor(site, floor)?;
    }
    let sigma = sigma_m(fix.accuracy_m, site.spacing_m());
    let at = Point2::new(fix.x, fix.y);
    let mut nearest = f64::INFINITY;
    for (e, s) in out.iter_mut().zip(site.states()) {
        if fix.floor.is_some_and(|f| f != s.floor) {
            *e = f64::NEG_INFINITY;
            continue;
        }
        let d = nalgebra::distance(&s.position, &at);
        nearest = nearest.min(d);
        *e = -0.5 * (d / sigma).powi(2);
    }
    let limit_m = sigma * rayleigh_radius(FIX_GATE_MASS);
    if nearest > limit_m {
        return Err(InputError::OutsideSite { distance_m: nearest, limit_m });
    }
    Ok(())
}

/// The states on `floor` within `radius_m` of (x, y), ascending: what a confirmed position
/// pins the posterior to. Fails when a value is invalid or no state is that close.
pub fn states_within(
    site: &Site,
    x: f64,
    y: f64,
    floor: usize,
    radius_m: f64,
) -> Result<Vec<u32>, InputError> {
    coordinate("x", x)?;
    coordinate("y", y)?;
    length("radius_m", radius_m)?;
    check_floor(site, floor)?;
    let at = Point2::new(x, y);
    let mut nearest = f64::INFINITY;
    let mut states = Vec::new();
    for (i, s) in site.states().iter().enumerate().filter(|(_, s)| s.floor == floor) {
        let d = nalgebra::distance(&s.position, &at);
        nearest = nearest.min(d);
        if d <= radius_m {
            states.push(i as u32);
        }
    }
    if states.is_empty() {
        return Err(InputError::OutsideSite { distance_m: nearest, limit_m: radius_m });
    }
    Ok(states)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::site::{BuildOptions, SiteBuilder};
    use approx::assert_relative_eq;

    fn two_floors() -> Site {
        let mut b = SiteBuilder::new("two floors");
        for (name, elevation) in [("G", 0.0), ("1", 4.0)] {
            let f = b.floor(name, elevation);
            let ids: Vec<u32> =
                (0..4).map(|k| b.state(f, Point2::new(4.0 * k as f64, 0.0), vec![])).collect();
            for w in ids.windows(2) {
                b.edge(w[0], w[1], None);
            }
        }
        b.edge(0, 4, Some(6.0));
        b.build(BuildOptions::default()).unwrap()
    }

    #[test]
    fn the_68_percent_radius_holds_68_percent() {
        // 1 - exp(-r²/2) at r = 1.5096.
        assert_relative_eq!(rayleigh_radius(0.68), 1.5096, epsilon = 1e-4);
        assert_relative_eq!(1.0 - (-rayleigh_radius(0.68).powi(2) / 2.0).exp(), 0.68, epsilon = 1e-12);
        assert_relative_eq!(rayleigh_radius(0.999), 3.7169, epsilon = 1e-4);
        // A 3 m fix on a 4 m grid: (3 / 1.5096)² + 16 / 12.
        assert_relative_eq!(sigma_m(3.0, 4.0).powi(2), (3.0 / 1.5096f64).powi(2) + 4.0 / 3.0, epsilon = 1e-3);
    }

    #[test]
    fn a_fix_is_a_gaussian_around_each_state() {
        let site = two_floors();
        let mut out = vec![0.0; 8];
        let fix = PositionFix { timestamp_ns: 1, x: 4.0, y: 0.0, floor: None, accuracy_m: 2.0 };
        ln_likelihood(&site, &fix, &mut out).unwrap();
        let sigma = sigma_m(2.0, 4.0);
        assert_eq!(out[1], 0.0);
        assert_relative_eq!(out[2], -0.5 * (4.0 / sigma).powi(2), epsilon = 1e-12);
        assert_eq!(out[1], out[5], "no floor: both floors alike");
        ln_likelihood(&site, &PositionFix { floor: Some(1), ..fix }, &mut out).unwrap();
        assert!(out[..4].iter().all(|&e| e == f64::NEG_INFINITY));
        assert_eq!(out[5], 0.0);
    }

    #[test]
    fn bad_and_faraway_fixes_are_typed_errors() {
        let site = two_floors();
        let mut out = vec![0.0; 8];
        let fix = PositionFix { timestamp_ns: 1, x: 4.0, y: 0.0, floor: None, accuracy_m: 2.0 };
        let err = |f: PositionFix| ln_likelihood(&site, &f, &mut [0.0; 8]).unwrap_err();
        for (bad, field) in [
            (PositionFix { x: f64::NAN, ..fix }, "x"),
            (PositionFix { y: f64::INFINITY, ..fix }, "y"),
            (PositionFix { y: 1e300, ..fix }, "y"),
            (PositionFix { accuracy_m: 0.0, ..fix }, "accuracy_m"),
            (PositionFix { accuracy_m: -1.0, ..fix }, "accuracy_m"),
            (PositionFix { accuracy_m: f64::NAN, ..fix }, "accuracy_m"),
            (PositionFix { accuracy_m: 1e300, ..fix }, "accuracy_m"),
        ] {
            assert!(matches!(err(bad), InputError::InvalidValue { field: f, .. } if f == field), "{bad:?}");
        }
        assert_eq!(
            err(PositionFix { floor: Some(2), ..fix }),
            InputError::UnknownFloor { floor: 2, floors: 2 }
        );
        // 100 m off a site whose states span 12 m: beyond 3.7 σ of a 5 m fix, within that of a
        // 100 m one.
        let far = PositionFix { x: 112.0, accuracy_m: 5.0, ..fix };
        assert!(matches!(err(far), InputError::OutsideSite { distance_m, .. } if distance_m == 100.0));
        ln_likelihood(&site, &PositionFix { accuracy_m: 100.0, ..far }, &mut out).unwrap();
    }

    #[test]
    fn a_confirmed_position_pins_the_states_within_its_radius() {
        let site = two_floors();
        assert_eq!(states_within(&site, 5.0, 0.0, 0, 3.5).unwrap(), vec![1, 2]);
        assert_eq!(states_within(&site, 5.0, 0.0, 1, 1.5).unwrap(), vec![5]);
        assert_eq!(
            states_within(&site, 6.0, 0.0, 0, 1.0).unwrap_err(),
            InputError::OutsideSite { distance_m: 2.0, limit_m: 1.0 }
        );
        assert!(matches!(states_within(&site, 0.0, 0.0, 0, 0.0), Err(InputError::InvalidValue { .. })));
        assert!(matches!(states_within(&site, 0.0, f64::NAN, 0, 1.0), Err(InputError::InvalidValue { .. })));
        assert!(matches!(states_within(&site, 0.0, 0.0, 9, 1.0), Err(InputError::UnknownFloor { .. })));
    }
}
