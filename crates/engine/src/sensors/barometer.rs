//! The barometer: the phone's height relative to where it was, from air pressure, for the
//! engine's floor changes (docs/accuracy.md#barometer). Only differences over a walk are used:
//! the weather moves the absolute pressure by more than a storey within hours.

use super::clock::refuse_ahead;
use super::BatchReport;
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

/// One barometer reading: Android's `Sensor.TYPE_PRESSURE` (hPa), iOS's `CMAltimeter`
/// pressure (kPa × 10).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PressureSample {
    /// Monotonic time, ns, on the same clock as scans.
    pub timestamp_ns: u64,
    /// Air pressure, hPa.
    pub hpa: f64,
}

/// The readings a phone barometer can give, hPa: the measuring range of the MEMS sensors phones
/// carry (300-1100 hPa, e.g. Bosch BMP388 and ST LPS22HB data sheets). Outside it a reading is
/// not a pressure and is dropped.
pub const PRESSURE_RANGE_HPA: [f64; 2] = [300.0, 1100.0];

/// Height above sea level in the ICAO standard atmosphere for a pressure, m (ICAO Doc 7488:
/// h = 44 330.8 · (1 − (p / 1013.25)^0.190263)). Its differences are height differences to
/// within 1% over a building whatever the weather.
pub fn pressure_height_m(hpa: f64) -> f64 {
    44_330.8 * (1.0 - (hpa / 1013.25).powf(0.190_263))
}

/// Time constant of the low-pass on the height, s: a phone barometer's noise (about 0.1 m RMS
/// per reading at 10-25 Hz) averaged over a second, while a stair climb (0.2-0.5 m/s
/// vertically) is followed within a step or two.
const SMOOTHING_S: f64 = 1.0;

/// A height is current for an epoch this long after the latest reading, ns: Android delivers
/// pressure at 5 Hz or more while registered, iOS's altimeter at about 1 Hz.
const MAX_AGE_NS: u64 = 3_000_000_000;

/// The phone has been at one height when its smoothed height stayed within this range over
/// [`SETTLE_NS`], m: a phone moved from hand to pocket (about 0.5 m) still counts as settled,
/// a stair flight (a storey is at least 2 m) does not.
pub(crate) const SETTLE_RANGE_M: f64 = 0.6;

/// How long the height must stay within [`SETTLE_RANGE_M`] to count as settled, ns: three
/// seconds, a few steps on a landing or a floor.
pub(crate) const SETTLE_NS: u64 = 3_000_000_000;

/// The phone's relative height from its barometer readings, smoothed.
#[derive(Clone, Debug, Default)]
pub(crate) struct Barometer {
    /// The latest reading's time and the smoothed height then, m.
    latest: Option<(u64, f64)>,
    /// Smoothed heights over the last [`SETTLE_NS`] and a little more, oldest first.
    recent: VecDeque<(u64, f64)>,
    /// The time of the previous reading refused as far ahead ([`refuse_ahead`]).
    jump_ns: Option<u64>,
}

impl Barometer {
    /// Takes a batch of readings: a reading that is not finite or not a pressure
    /// ([`PRESSURE_RANGE_HPA`]) is dropped as non-finite, one not after the previous as out of
    /// order, and one more than `bound_ns` after `clock_ns` (the engine's latest time) as
    /// ahead, unless the next confirms the jump.
    pub(crate) fn push(
        &mut self,
        batch: &[PressureSample],
        clock_ns: Option<u64>,
        bound_ns: u64,
    ) -> BatchReport {
        let mut report = BatchReport::default();
        for s in batch {
            let [low, high] = PRESSURE_RANGE_HPA;
            if !s.hpa.is_finite() || !(low..=high).contains(&s.hpa) {
                report.non_finite += 1;
                continue;
            }
            if self.latest.is_some_and(|(t, _)| s.timestamp_ns <= t) {
                report.out_of_order += 1;
                continue;
            }
            let clock = clock_ns.max(self.latest.map(|(t, _)| t));
            if refuse_ahead(s.timestamp_ns, clock, bound_ns, self.jump_ns) {
                self.jump_ns = Some(s.timestamp_ns);
                report.ahead += 1;
                continue;
            }
            self.take(s.timestamp_ns, pressure_height_m(s.hpa));
            report.accepted += 1;
        }
        report
    }

    fn take(&mut self, t_ns: u64, height_m: f64) {
        let smoothed = match self.latest {
            // A gap longer than the age bound starts the smoothing again: the phone may have
            // been carried anywhere in between.
            Some((t, h)) if t_ns - t <= MAX_AGE_NS => {
                let dt_s = (t_ns - t) as f64 * 1e-9;
                h + (1.0 - (-dt_s / SMOOTHING_S).exp()) * (height_m - h)
            }
            _ => {
                self.recent.clear();
                height_m
            }
        };
        self.latest = Some((t_ns, smoothed));
        self.recent.push_back((t_ns, smoothed));
        while self.recent.len() > 2 && self.recent[1].0 + SETTLE_NS <= t_ns {
            self.recent.pop_front();
        }
    }

    /// The smoothed height at `t_ns`, m, when the latest reading is at most [`MAX_AGE_NS`]
    /// before it (or after it, as readings pushed up to an epoch may be).
    pub(crate) fn height_at(&self, t_ns: u64) -> Option<f64> {
        let (t, h) = self.latest?;
        (t_ns.abs_diff(t) <= MAX_AGE_NS).then_some(h)
    }

    /// Whether the height at `t_ns` has stayed within [`SETTLE_RANGE_M`] for [`SETTLE_NS`].
    pub(crate) fn settled(&self, t_ns: u64) -> bool {
        let (Some(&(first, _)), Some((last, _))) = (self.recent.front(), self.latest) else {
            return false;
        };
        if self.height_at(t_ns).is_none() || last - first < SETTLE_NS {
            return false;
        }
        let (low, high) = self
            .recent
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &(_, h)| (lo.min(h), hi.max(h)));
        high - low <= SETTLE_RANGE_M
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: u64 = 1_000_000_000;

    fn readings(from_s: f64, to_s: f64, hpa: impl Fn(f64) -> f64) -> Vec<PressureSample> {
        let n = ((to_s - from_s) * 10.0).round() as usize;
        (0..n)
            .map(|i| {
                let t = from_s + i as f64 * 0.1;
                PressureSample { timestamp_ns: (t * 1e9) as u64, hpa: hpa(t) }
            })
            .collect()
    }

    #[test]
    fn a_storey_of_pressure_is_a_storey_of_height() {
        // 0.37 hPa at 977 hPa: about 3.1 m.
        let dh = pressure_height_m(976.85) - pressure_height_m(977.22);
        assert!((dh - 3.1).abs() < 0.1, "{dh}");
        assert!(pressure_height_m(1013.25).abs() < 1e-9);
    }

    #[test]
    fn the_height_settles_after_a_climb_and_not_during_it() {
        let mut b = Barometer::default();
        let climb = |t: f64| 977.0 - 0.37 * ((t - 10.0) / 10.0).clamp(0.0, 1.0);
        let r = b.push(&readings(0.0, 10.0, climb), None, 10 * S);
        assert_eq!(r.accepted, 100);
        assert!(b.settled(10 * S));
        let h0 = b.height_at(10 * S).unwrap();
        b.push(&readings(10.0, 15.0, climb), None, 10 * S);
        assert!(!b.settled(15 * S), "half way up");
        b.push(&readings(15.0, 26.0, climb), None, 10 * S);
        assert!(b.settled(26 * S));
        let dh = b.height_at(26 * S).unwrap() - h0;
        assert!((dh - 3.1).abs() < 0.15, "{dh}");
        assert_eq!(b.height_at(28 * S), Some(b.height_at(26 * S).unwrap()));
        assert_eq!(b.height_at(40 * S), None, "too old");
    }

    #[test]
    fn readings_that_are_not_pressures_or_out_of_order_are_dropped_and_counted() {
        let mut b = Barometer::default();
        let batch = [
            PressureSample { timestamp_ns: S, hpa: 1000.0 },
            PressureSample { timestamp_ns: 2 * S, hpa: f64::NAN },
            PressureSample { timestamp_ns: 3 * S, hpa: 0.0 },
            PressureSample { timestamp_ns: S, hpa: 1000.0 },
            PressureSample { timestamp_ns: 1_000 * S, hpa: 1000.0 },
            PressureSample { timestamp_ns: 4 * S, hpa: 1000.1 },
        ];
        let r = b.push(&batch, Some(S), 10 * S);
        assert_eq!((r.accepted, r.non_finite, r.out_of_order, r.ahead), (2, 2, 1, 1));
        assert!(b.height_at(4 * S).is_some());
    }
}
