//! What an app is told, converted from the core's output once for both FFIs: the position
//! (metres and the site's frame as the core gives them, plus the floor's name and level, WGS84,
//! the zone, degrees for radians, the true bearing), the status events, track points, the fix
//! error and a habit pass. The uniffi records (`uniffi/records.rs`) and the C structs
//! (`c/types.rs`) are filled from these field by field: each only encodes what is absent in
//! its own way (`null` / `nil`, or NaN, -1 and a `has_` flag in C), with no arithmetic or unit
//! conversion of its own, so Kotlin, Swift and C cannot disagree about a value.

use waymark_engine::habits::{FixBias, HabitModel, HabitReport};
use waymark_engine::sensors::{MotionScenario, MotionState};
use waymark_engine::site::Site;
use waymark_engine::{Position, StatusEvent, TrackPoint};

/// A position as an app sees it, borrowing its names from the site.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct AppPosition<'a> {
    /// Time of the epoch, ns.
    pub timestamp_ns: u64,
    /// x in the site's metric frame, m.
    pub x: f64,
    /// y in the site's metric frame, m.
    pub y: f64,
    /// Floor index in the site file.
    pub floor: u32,
    /// The floor's name; empty for an index the site does not have (never, from the engine).
    pub floor_name: &'a str,
    /// The floor's logical level, when the site file gives one; or the level the site has no
    /// floor for where the barometer places the phone ([`Position::unmapped_level`]).
    pub floor_level: Option<i32>,
    /// Whether `floor_level` is such a level: the position stands on `floor`'s plan, the
    /// nearest the map can place the phone.
    pub level_unmapped: bool,
    /// Probability that the floor is right.
    pub floor_probability: f64,
    /// WGS84 latitude, degrees north, on a geo-referenced site.
    pub latitude_deg: Option<f64>,
    /// WGS84 longitude, degrees east, on a geo-referenced site.
    pub longitude_deg: Option<f64>,
    /// The most likely zone's index into the site's zones (at most `i32::MAX` zones:
    /// `site::MAX_ZONES`), when there is one.
    pub zone: Option<i32>,
    /// That zone's name.
    pub zone_name: Option<&'a str>,
    /// Probability of the zone (of no zone when there is none).
    pub zone_probability: f64,
    /// Radius of the 68% circle, m.
    pub accuracy_m: f64,
    /// Radius of the 95% circle, m.
    pub accuracy_95_m: f64,
    /// Direction of travel, degrees clockwise from the site's +y axis, when known.
    pub heading_deg: Option<f64>,
    /// One standard deviation of the heading, degrees, when known.
    pub heading_accuracy_deg: Option<f64>,
    /// Direction of travel, degrees clockwise from true north in [0, 360), when the heading
    /// is known and the site is geo-referenced.
    pub bearing_deg: Option<f64>,
    /// Walking or not.
    pub motion_state: MotionState,
    /// The motion information the epoch had.
    pub scenario: MotionScenario,
    /// Steps since the previous epoch.
    pub steps: u32,
    /// Distance walked since the radio last explained a scan, m.
    pub beyond_radio_m: f64,
}

impl<'a> AppPosition<'a> {
    /// The core's position `p` of an engine on `site`.
    pub(crate) fn new(p: &Position, site: &'a Site) -> Self {
        let geo = site.lat_lon(p.floor, p.x, p.y);
        Self {
            timestamp_ns: p.timestamp_ns,
            x: p.x,
            y: p.y,
            floor: p.floor as u32,
            floor_name: site.floors().get(p.floor).map_or("", |f| f.name.as_str()),
            floor_level: p.level(site),
            level_unmapped: p.unmapped_level.is_some(),
            floor_probability: p.floor_probability,
            latitude_deg: geo.map(|g| g.lat_deg),
            longitude_deg: geo.map(|g| g.lon_deg),
            zone: p.zone.and_then(|z| i32::try_from(z).ok()),
            zone_name: p.zone.and_then(|z| site.zones().get(z)).map(|z| z.name.as_str()),
            zone_probability: p.zone_probability,
            accuracy_m: p.accuracy_m,
            accuracy_95_m: p.accuracy_95_m,
            heading_deg: p.heading_rad.map(f64::to_degrees),
            heading_accuracy_deg: p.heading_accuracy_rad.map(f64::to_degrees),
            bearing_deg: p.heading_rad.and_then(|h| site.bearing_deg(h)),
            motion_state: p.motion_state,
            scenario: p.scenario,
            steps: p.steps,
            beyond_radio_m: p.beyond_radio_m,
        }
    }
}

/// A point of the track as an app sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct AppTrackPoint {
    /// Epoch time, ns.
    pub timestamp_ns: u64,
    /// x in the site's metric frame, m.
    pub x: f64,
    /// y in the site's metric frame, m.
    pub y: f64,
    /// Floor index.
    pub floor: u32,
    /// The level to show, as [`AppPosition::floor_level`]: the level the live position of the
    /// same epoch reported where the site has no floor for it, else the floor's own.
    pub floor_level: Option<i32>,
    /// Whether `floor_level` is a level the site has no floor for.
    pub level_unmapped: bool,
}

impl AppTrackPoint {
    /// The core's track point `p` of an engine on `site`.
    pub(crate) fn new(p: &TrackPoint, site: &Site) -> Self {
        Self {
            timestamp_ns: p.timestamp_ns,
            x: p.x,
            y: p.y,
            floor: p.floor as u32,
            floor_level: p.level(site),
            level_unmapped: p.unmapped_level.is_some(),
        }
    }
}

/// A status change as an app hears it, made when the epoch is staged (`handle.rs`), so each
/// FFI only picks its fields.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum AppStatus {
    /// The motion information available changed.
    ScenarioChanged { timestamp_ns: u64, scenario: MotionScenario },
    /// The person started or stopped walking.
    MotionStateChanged { timestamp_ns: u64, state: MotionState },
    /// A scan heard no transmitter of the site.
    NoSiteCoverage { timestamp_ns: u64 },
    /// Earlier positions were revised by later evidence, oldest first.
    TrackRevised { points: Vec<AppTrackPoint> },
    /// The person entered (`entered`) or left one of the site's zones: its index (as
    /// [`AppPosition::zone`]) and name.
    Zone { timestamp_ns: u64, zone: i32, name: String, entered: bool, probability: f64 },
    /// The person entered or left one of the app's geofences.
    Geofence { timestamp_ns: u64, id: String, entered: bool, probability: f64 },
}

impl AppStatus {
    /// The core's status event of an engine on `site`.
    pub(crate) fn new(event: StatusEvent, site: &Site) -> Self {
        let zone = |timestamp_ns, zone: usize, entered, probability| AppStatus::Zone {
            timestamp_ns,
            zone: i32::try_from(zone).unwrap_or(-1),
            name: site.zones().get(zone).map(|z| z.name.clone()).unwrap_or_default(),
            entered,
            probability,
        };
        match event {
            StatusEvent::ScenarioChanged { timestamp_ns, to, .. } => {
                AppStatus::ScenarioChanged { timestamp_ns, scenario: to }
            }
            StatusEvent::MotionStateChanged { timestamp_ns, to, .. } => {
                AppStatus::MotionStateChanged { timestamp_ns, state: to }
            }
            StatusEvent::ZoneEntered { timestamp_ns, zone: z, probability } => {
                zone(timestamp_ns, z, true, probability)
            }
            StatusEvent::ZoneExited { timestamp_ns, zone: z, probability } => {
                zone(timestamp_ns, z, false, probability)
            }
            StatusEvent::GeofenceEntered { timestamp_ns, id, probability } => {
                AppStatus::Geofence { timestamp_ns, id, entered: true, probability }
            }
            StatusEvent::GeofenceExited { timestamp_ns, id, probability } => {
                AppStatus::Geofence { timestamp_ns, id, entered: false, probability }
            }
        }
    }

    /// The revision of the track points `points` of an engine on `site`.
    pub(crate) fn track_revised(points: &[TrackPoint], site: &Site) -> Self {
        AppStatus::TrackRevised { points: points.iter().map(|p| AppTrackPoint::new(p, site)).collect() }
    }
}

/// The learned error of position fixes as an app sees it: one bias per axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct AppFixBias {
    /// Mean error along the site's x axis, m.
    pub bias_x_m: f64,
    /// Mean error along the site's y axis, m.
    pub bias_y_m: f64,
    /// Factor on the fixes' own accuracy.
    pub spread: f64,
}

impl From<FixBias> for AppFixBias {
    fn from(e: FixBias) -> Self {
        Self { bias_x_m: e.bias_m[0], bias_y_m: e.bias_m[1], spread: e.spread }
    }
}

/// What one habit-learning pass did, with the model's totals after it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct AppHabitReport {
    /// Epochs learned from in this pass.
    pub epochs: usize,
    /// Epochs learned from over all passes.
    pub total_epochs: u64,
    /// Moves with a learned count, after the pass.
    pub learned_transitions: usize,
    /// Whether the learned moves weigh on the positions.
    pub applied: bool,
}

impl AppHabitReport {
    /// The pass `report` that left the engine's habits at `model`.
    pub(crate) fn new(report: &HabitReport, model: &HabitModel) -> Self {
        Self {
            epochs: report.epochs,
            total_epochs: model.epochs(),
            learned_transitions: report.learned_transitions,
            applied: model.strength().is_some(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ffi::c::waymark_track_point;
    use crate::ffi::uniffi::FfiTrackPoint;
    use nalgebra::Point2;
    use waymark_engine::radio::{Reading, Scan, TransmitterId};
    use waymark_engine::site::{BuildOptions, SiteBuilder};

    /// Two floors at levels 0 and 2, a state each.
    fn levels_zero_and_two() -> Site {
        let mut b = SiteBuilder::new("levels 0 and 2");
        let floors = [b.floor("G", 0.0), b.floor("2", 6.0)];
        let ap = TransmitterId::wifi("02:00:00:00:00:01").unwrap();
        for (f, &floor) in floors.iter().enumerate() {
            let scans = (0..4)
                .map(|n| Scan {
                    timestamp_ns: n,
                    readings: vec![Reading {
                        transmitter: ap.clone(),
                        rssi_dbm: -50.0 - 20.0 * f as f64,
                        age_ns: 0,
                    }],
                })
                .collect();
            b.state(floor, Point2::new(0.0, 0.0), scans);
            b.floor_geo(floor, Some(2 * f as i32), [0.0, 0.0]);
        }
        b.build(BuildOptions::default()).unwrap()
    }

    #[test]
    fn track_points_carry_the_level_their_epoch_showed() {
        let site = levels_zero_and_two();
        let point = |floor, unmapped_level| TrackPoint {
            timestamp_ns: 7,
            state: 0,
            floor,
            x: 1.0,
            y: 2.0,
            unmapped_level,
        };
        // On floor "2" (level 2); then on the ground floor's plan with the barometer at level 1.
        let mapped = AppTrackPoint::new(&point(1, None), &site);
        assert_eq!((mapped.floor, mapped.floor_level, mapped.level_unmapped), (1, Some(2), false));
        let between = AppTrackPoint::new(&point(0, Some(1)), &site);
        assert_eq!((between.floor, between.floor_level, between.level_unmapped), (0, Some(1), true));
        // As C and uniffi hand them on.
        let c = waymark_track_point::from(between);
        assert!(c.has_floor_level && c.floor_level == 1 && c.level_unmapped && c.floor == 0);
        let u = FfiTrackPoint::from(mapped);
        assert_eq!((u.floor_level, u.level_unmapped), (Some(2), false));
        // A site without levels: none to show.
        let mut plain = SiteBuilder::new("no levels");
        let g = plain.floor("G", 0.0);
        let ap = TransmitterId::wifi("02:00:00:00:00:01").unwrap();
        let scans = vec![Scan {
            timestamp_ns: 0,
            readings: vec![Reading { transmitter: ap, rssi_dbm: -50.0, age_ns: 0 }],
        }];
        plain.state(g, Point2::new(0.0, 0.0), scans);
        let plain = plain.build(BuildOptions::default()).unwrap();
        let c = waymark_track_point::from(AppTrackPoint::new(&point(0, None), &plain));
        assert!(!c.has_floor_level && c.floor_level == 0 && !c.level_unmapped);
    }
}
