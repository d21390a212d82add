//! A recorded walk through the engine exactly as an app feeds it: sensor batches, then the scan
//! they lead up to; a timer epoch when no scan came for a while; optionally with motion
//! information withheld to force one of HIPE's scenarios.

use crate::io::ilc::{Event, EventOptions};
use crate::io::Trace;
use serde::{Deserialize, Serialize};
use waymark_engine::sensors::{MotionScenario, MotionState, MotionTracker, MotionUpdate};
use waymark_engine::{Engine, Position, TrackPoint};

/// Which motion information the engine may use (HIPE Table 1), forced by withholding it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MotionMask {
    /// Whatever the sensors give, scenario picked per epoch.
    #[default]
    Auto,
    /// Distance and heading, as measured (an epoch without a trustworthy heading stays
    /// without one: nothing is invented).
    DistanceHeading,
    /// Steps only: the heading is withheld.
    Distance,
    /// Heading only: the step distance is withheld, and with it everything the step detector
    /// told (HIPE Table 1: a compass, no accelerometer-based motion): the heading is where the
    /// compass points at the epoch's end, not the direction of the epoch's steps, and the
    /// motion state is unknown.
    HeadingSpeed,
    /// Neither: the assumed speed only (no step detector either: the motion state is unknown).
    Speed,
}

impl MotionMask {
    /// `update` with what this mask withholds removed, and the scenario set to what is left.
    /// `compass` is the tracker's trusted heading where the phone points at the update's end
    /// and its σ (`MotionTracker::heading_estimate`), rad: the heading a phone without step
    /// detection has, which [`MotionMask::HeadingSpeed`] uses instead of the steps' direction.
    pub fn apply(self, mut update: MotionUpdate, compass: Option<(f64, f64)>) -> MotionUpdate {
        let scenario = match self {
            MotionMask::Auto => return update,
            MotionMask::DistanceHeading => MotionScenario::DistanceHeading,
            MotionMask::Distance => MotionScenario::Distance,
            MotionMask::HeadingSpeed => MotionScenario::HeadingSpeed,
            MotionMask::Speed => MotionScenario::Speed,
        };
        if matches!(scenario, MotionScenario::Distance | MotionScenario::Speed) {
            update.heading_rad = None;
        }
        if matches!(scenario, MotionScenario::HeadingSpeed | MotionScenario::Speed) {
            // Without step detection there is no distance, no walking or standing still, and no
            // direction of travel from the steps: the tracker's heading of an epoch with steps
            // is their length-weighted mean direction, withheld when they turned too much,
            // which only a step detector knows (`docs/tuning.md#heading-speed-mask`).
            update.distance_m = None;
            update.motion_state = MotionState::Unknown;
            if scenario == MotionScenario::HeadingSpeed {
                (update.heading_rad, update.heading_sigma_rad) = match compass {
                    Some((h, sigma)) => (Some(h), sigma),
                    None => (None, std::f64::consts::PI),
                };
            }
        }
        // The tracker's displacement sums its steps' own headings; it stands only while
        // neither distance nor heading was withheld.
        if update.distance_m.is_none() || update.heading_rad.is_none() {
            update.displacement_m = None;
        }
        // A scenario is only what the measurements support.
        update.scenario = match (update.distance_m.is_some(), update.heading_rad.is_some()) {
            (true, true) => MotionScenario::DistanceHeading,
            (true, false) => MotionScenario::Distance,
            (false, true) => MotionScenario::HeadingSpeed,
            (false, false) => MotionScenario::Speed,
        };
        update
    }
}

/// Time between the scans a throttled replay lets through, ns: Android 9+ lets a foreground
/// app scan 4 times in 2 minutes (Android developers, "Wi-Fi scanning overview",
/// throttling), one scan every 30 s at the steady rate.
pub const ANDROID_THROTTLE_NS: u64 = 30_000_000_000;

/// How a walk is replayed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReplayOptions {
    /// Batching and radios.
    pub events: EventOptions,
    /// A motion-only epoch when this long has passed without an epoch, ns (an app's timer).
    /// 2 s: one scan interval of an unthrottled Android phone (the competition walks'
    /// medians are 1.9-2.3 s by floor, `SurveyReport`'s `scan_interval_median_s`), so epochs
    /// keep coming at a scan's pace when scans stop (Android 9+ throttles to 4 scans in 2
    /// minutes). Not longer: a gap beyond the walking-distance table's reach is bridged by the
    /// speed bound alone, without the motion (`docs/tuning.md#replay-timer`).
    pub timer_ns: Option<u64>,
    /// Scans closer than this to the previous one kept are dropped, ns: `Some(30 s)` replays
    /// a foreground app under Android 9+'s throttling.
    pub min_scan_interval_ns: Option<u64>,
    /// Motion withheld.
    pub mask: MotionMask,
    /// Give the walk's waypoints to the engine as user feedback
    /// ([`Engine::confirm_position`]): a surveyor confirming where they are. Only for walks
    /// the engine may learn from (survey walks), never for walks that are scored.
    pub feedback: Option<WaypointFeedback>,
    /// Ask the engine for the fixed-lag estimate after each epoch ([`Replay::fixed_lag`]); off
    /// where only the live positions are scored, as the smoothing costs an estimate per epoch.
    pub fixed_lag: bool,
    /// Also give each live position with each M of Hoang eq. 4 in this list
    /// ([`Replay::by_estimate_states`]); empty for none.
    pub estimate_states_grid: &'static [usize],
}

/// Waypoints as feedback: the walk's floor in the site, and the radius of the circle confirmed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WaypointFeedback {
    /// Index of the walk's floor in the site.
    pub floor: usize,
    /// Radius confirmed around each waypoint, m.
    pub radius_m: f64,
}

impl Default for ReplayOptions {
    fn default() -> Self {
        Self {
            events: EventOptions::default(),
            timer_ns: Some(2_000_000_000),
            min_scan_interval_ns: None,
            mask: MotionMask::Auto,
            feedback: None,
            fixed_lag: true,
            estimate_states_grid: &[],
        }
    }
}

/// What the engine said during a walk.
#[derive(Clone, Debug, Default)]
pub struct Replay {
    /// Every epoch's live position, in time order.
    pub positions: Vec<Position>,
    /// The fixed-lag estimate available after each epoch (older than that epoch by the lag).
    pub fixed_lag: Vec<TrackPoint>,
    /// The Viterbi path at the end of the walk (as long as the engine's track window).
    pub track: Vec<TrackPoint>,
    /// Scans the engine rejected (no known transmitter, ...).
    pub rejected_scans: usize,
    /// Per M of [`ReplayOptions::estimate_states_grid`], `positions` with that M's (x, y).
    pub by_estimate_states: Vec<Vec<Position>>,
}

impl Replay {
    /// Adds the engine's latest position, and its (x, y) with each M of `grid`.
    fn publish(&mut self, engine: &Engine, position: Position, grid: &[usize]) {
        for (k, [x, y]) in engine.positions_by_states(grid).into_iter().enumerate() {
            self.by_estimate_states[k].push(Position { x, y, ..position.clone() });
        }
        self.positions.push(position);
    }
}

/// What one call of a replay was, for [`replay_observed`]'s observer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Call {
    /// A sensor batch, or a scan the throttle dropped: no epoch.
    Sensors,
    /// A scan pushed to the engine.
    Scan {
        /// Whether the epoch published a position.
        published: bool,
    },
    /// A timer epoch.
    Timer {
        /// Whether the epoch published a position.
        published: bool,
    },
}

/// Feeds `trace` to `engine` as an app would.
pub fn replay(engine: &mut Engine, trace: &Trace, options: &ReplayOptions) -> Replay {
    replay_observed(engine, trace, options, &mut |_| {})
}

/// [`replay`], telling `observer` after each call the app makes (a sensor batch, a scan, a
/// timer epoch; with [`ReplayOptions::fixed_lag`], the fixed-lag estimate is part of the
/// epoch's call): what a timing program needs to put a cost on each published position.
pub fn replay_observed(
    engine: &mut Engine,
    trace: &Trace,
    options: &ReplayOptions,
    observer: &mut dyn FnMut(Call),
) -> Replay {
    let mut out = Replay {
        by_estimate_states: vec![Vec::new(); options.estimate_states_grid.len()],
        ..Replay::default()
    };
    // Forced scenarios run their own tracker on the same configuration and hand the engine
    // the masked motion; `Auto` lets the engine's tracker do it.
    let mut tracker = match options.mask {
        MotionMask::Auto => None,
        _ => MotionTracker::new(engine.config().motion_for(engine.site())).ok(),
    };
    let mut last_epoch: Option<u64> = None;
    let mut last_scan: Option<u64> = None;
    let mut waypoints = trace.waypoints.iter().peekable();
    for event in trace.events(&options.events) {
        let t = event.timestamp_ns();
        if let Some(feedback) = options.feedback {
            // Waypoints up to this event's time, confirmed in order (once an epoch exists).
            while let Some(w) = waypoints.next_if(|w| w.timestamp_ns < t) {
                if last_epoch.is_some_and(|l| w.timestamp_ns >= l) {
                    if let Ok(waymark_engine::Epoch { position: p, .. }) =
                        engine.confirm_position(w.timestamp_ns, w.x, w.y, feedback.floor, feedback.radius_m)
                    {
                        if last_epoch != Some(p.timestamp_ns) {
                            last_epoch = Some(p.timestamp_ns);
                            out.publish(engine, p, options.estimate_states_grid);
                        }
                    }
                }
            }
        }
        let scan = matches!(event, Event::Scan(_));
        let result = match event {
            Event::Accelerometer(batch) => {
                engine.push_accelerometer(&batch);
                tracker.as_mut().map(|k| k.push_accelerometer(&batch));
                None
            }
            Event::Gyroscope(batch) => {
                engine.push_gyroscope(&batch);
                tracker.as_mut().map(|k| k.push_gyroscope(&batch));
                None
            }
            Event::Magnetometer(batch) => {
                engine.push_magnetometer(&batch);
                tracker.as_mut().map(|k| k.push_magnetometer(&batch));
                None
            }
            Event::Pressure(batch) => {
                engine.push_pressure(&batch);
                None
            }
            Event::Scan(scan) => {
                if options.min_scan_interval_ns.is_some_and(|gap| last_scan.is_some_and(|l| t < l + gap)) {
                    None
                } else {
                    last_scan = Some(t);
                    let r = match tracker.as_mut() {
                        Some(k) if last_epoch.is_none_or(|l| t > l) => {
                            let motion = masked(options.mask, k, t);
                            engine.push_scan_with_motion(&scan, &motion)
                        }
                        _ => engine.push_scan(&scan),
                    };
                    if r.is_err() {
                        out.rejected_scans += 1;
                    }
                    Some(r)
                }
            }
        };
        // A scan the throttle dropped is a sensor-less call; a timer epoch may follow it.
        let pushed_scan = scan && result.is_some();
        let result = result.or_else(|| {
            let due = options.timer_ns.is_some_and(|gap| last_epoch.is_some_and(|l| t >= l + gap));
            due.then(|| match tracker.as_mut() {
                Some(k) => {
                    let motion = masked(options.mask, k, t);
                    engine.advance_with_motion(t, &motion)
                }
                None => engine.advance(t),
            })
        });
        let call = match (pushed_scan, result.is_some()) {
            (true, _) => Call::Scan { published: matches!(result, Some(Ok(_))) },
            (false, true) => Call::Timer { published: matches!(result, Some(Ok(_))) },
            (false, false) => Call::Sensors,
        };
        if let Some(Ok(waymark_engine::Epoch { position, .. })) = result {
            last_epoch = Some(position.timestamp_ns);
            out.publish(engine, position, options.estimate_states_grid);
            if options.fixed_lag {
                push_smoothed(&mut out.fixed_lag, engine.fixed_lag_position());
            }
        }
        observer(call);
    }
    if options.fixed_lag {
        // The walk ends: the epochs the lag has not reached yet get their estimates smoothed
        // by what there is, as an app flushing at the end of a session would.
        for lag in (0..engine.config().fixed_lag_epochs).rev() {
            push_smoothed(&mut out.fixed_lag, engine.smoothed_position(lag));
        }
    }
    out.track = engine.track();
    out
}

/// Adds a smoothed point: one for the epoch of the last replaces it (smoothed by more epochs,
/// as the first epochs are until the track holds the whole lag), an older one is dropped.
fn push_smoothed(points: &mut Vec<TrackPoint>, point: Option<TrackPoint>) {
    let Some(point) = point else { return };
    match points.last_mut() {
        Some(last) if last.timestamp_ns == point.timestamp_ns => *last = point,
        Some(last) if last.timestamp_ns > point.timestamp_ns => {}
        _ => points.push(point),
    }
}

/// The motion `tracker` measured up to `t`, with what `mask` withholds removed.
fn masked(mask: MotionMask, tracker: &mut MotionTracker, t: u64) -> MotionUpdate {
    let update = tracker.update(t);
    let h = tracker.heading_estimate();
    let compass = h.heading_rad.filter(|_| h.trusted).map(|heading| (heading, h.sigma_rad));
    mask.apply(update, compass)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Where the compass points at the end of the update, and its σ, rad.
    const COMPASS: Option<(f64, f64)> = Some((0.9, 0.2));

    fn walking() -> MotionUpdate {
        MotionUpdate {
            distance_m: Some(2.0),
            heading_rad: Some(0.5),
            heading_sigma_rad: 0.1,
            motion_state: MotionState::Walking,
            displacement_m: Some([0.9, 1.8]),
            scenario: MotionScenario::DistanceHeading,
            ..MotionUpdate::default()
        }
    }

    #[test]
    fn masks_withhold_what_they_name_and_keep_the_rest() {
        assert_eq!(MotionMask::Auto.apply(walking(), COMPASS), walking());
        assert_eq!(
            MotionMask::DistanceHeading.apply(walking(), COMPASS),
            walking(),
            "the tracker's displacement stays"
        );
        let d = MotionMask::Distance.apply(walking(), COMPASS);
        assert_eq!(
            (d.distance_m, d.heading_rad, d.displacement_m, d.scenario),
            (Some(2.0), None, None, MotionScenario::Distance)
        );
        // Heading only: where the compass points, not the steps' direction, and no motion
        // state; without a trusted compass heading that is the assumed speed alone.
        let h = MotionMask::HeadingSpeed.apply(walking(), COMPASS);
        assert_eq!(
            (h.distance_m, h.heading_rad, h.heading_sigma_rad, h.displacement_m, h.scenario),
            (None, Some(0.9), 0.2, None, MotionScenario::HeadingSpeed)
        );
        assert_eq!(h.motion_state, MotionState::Unknown);
        let blind = MotionMask::HeadingSpeed.apply(walking(), None);
        assert_eq!((blind.heading_rad, blind.scenario), (None, MotionScenario::Speed));
        let s = MotionMask::Speed.apply(walking(), COMPASS);
        assert_eq!((s.distance_m, s.heading_rad, s.scenario), (None, None, MotionScenario::Speed));
        assert_eq!(s.motion_state, MotionState::Unknown);
        // With steps, the motion state stays.
        assert_eq!(MotionMask::Distance.apply(walking(), COMPASS).motion_state, MotionState::Walking);
        // Forcing distance-heading cannot invent a heading the tracker did not trust.
        let no_heading = MotionUpdate {
            heading_rad: None,
            displacement_m: None,
            scenario: MotionScenario::Distance,
            ..walking()
        };
        assert_eq!(MotionMask::DistanceHeading.apply(no_heading, COMPASS).scenario, MotionScenario::Distance);
    }
}
