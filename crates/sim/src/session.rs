//! A long session on the simulated office, generated one activity at a time so that the
//! generator's memory does not grow with the session: walks chained one after another along
//! the walkable graph, with pauses standing (phone in hand) and stretches with the phone lying
//! on a table, each synthesised as raw 100 Hz accelerometer, gyroscope and magnetometer
//! samples ([`super::imu`]). A [`Feeder`] hands the samples to an engine in app-sized batches
//! up to each epoch and says where the person really was then.
//!
//! The long-run and recovery experiments drive engines with it for hours of simulated time.

use super::imu::{lying_still, synthesize, ImuConfig, ImuTrace};
use super::{Office, Trajectory};
use nalgebra::Point2;
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use waymark_engine::sensors::SensorSample;

/// What a session is made of. These describe the scenario, not the engine: they were chosen so
/// that a day exercises walking, standing and lying still in comparable shares, not tuned to
/// any result (`docs/tuning.md#long-run-session`).
#[derive(Clone, Debug, PartialEq)]
pub struct SessionConfig {
    /// Length of each walk, m, drawn uniformly: 30-250 m (Hoang §6.1's walks are ~200 m; an
    /// office day also has short trips).
    pub walk_length_m: (f64, f64),
    /// Chance of stopping to stand at each vertex of a walk's route (a door, a desk, a chat):
    /// 0.1, a stop every ~10 states (~35 m) on average.
    pub pause_chance: f64,
    /// Length of such a stop, s, uniform: 5-60 s.
    pub pause_s: (f64, f64),
    /// Chance that the phone is put down on a table after a walk: 0.4.
    pub table_chance: f64,
    /// How long it lies there, s, uniform: 1-10 min. Each stretch or walk is one segment in
    /// memory, so this bounds the generator's peak (`docs/tuning.md#long-run-session`).
    pub table_s: (f64, f64),
    /// The phone's inertial sensors (the demo's defaults).
    pub imu: ImuConfig,
}

impl Default for SessionConfig {
    fn default() -> Self {
        Self {
            walk_length_m: (30.0, 250.0),
            pause_chance: 0.1,
            pause_s: (5.0, 60.0),
            table_chance: 0.4,
            table_s: (60.0, 600.0),
            imu: ImuConfig::default(),
        }
    }
}

/// What the person does during a segment.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Activity {
    /// Walking a route (with stops, and standing `standing_s` before and after).
    Walk,
    /// The phone lies still on a table.
    Table,
}

#[derive(Clone, Debug)]
enum Truth {
    Walk(Trajectory),
    Still(Point2<f64>),
}

/// One activity's raw samples and the truth behind them.
#[derive(Clone, Debug)]
pub struct Segment {
    /// What happens.
    pub activity: Activity,
    /// The raw samples (every one within `start_ns ..= end_ns`, give or take the jitter).
    pub imu: ImuTrace,
    /// First instant covered, ns.
    pub start_ns: u64,
    /// Last instant covered, ns.
    pub end_ns: u64,
    /// The state the segment ends at.
    pub end_state: u32,
    truth: Truth,
}

impl Segment {
    /// Where the person is at `t_ns` (clamped to the segment).
    pub fn truth_at(&self, t_ns: u64) -> Point2<f64> {
        match &self.truth {
            Truth::Walk(trajectory) => trajectory.pose_at(t_ns).position,
            Truth::Still(p) => *p,
        }
    }

    /// Whether the person is walking at `t_ns`.
    pub fn walking_at(&self, t_ns: u64) -> bool {
        match &self.truth {
            Truth::Walk(trajectory) => trajectory.pose_at(t_ns).speed_mps > 0.0,
            Truth::Still(_) => false,
        }
    }

    /// Bytes held by the samples.
    pub fn memory_bytes(&self) -> usize {
        let samples = self.imu.accelerometer.capacity()
            + self.imu.gyroscope.capacity()
            + self.imu.magnetometer.capacity();
        samples * std::mem::size_of::<SensorSample>()
            + self.imu.true_step_times_ns.capacity() * 8
            + self.imu.true_heading.capacity() * 16
    }
}

/// Gap between one segment's end and the next one's start, ns: one 100 Hz sample period, so
/// the streams stay strictly increasing across the seam (the sampling jitter is at most 10%
/// of a period).
const SEAM_NS: u64 = 10_000_000;

/// Makes the segments of a session, one at a time.
pub struct SessionGenerator<'a> {
    office: &'a Office,
    config: SessionConfig,
    rng: ChaCha8Rng,
    at: u32,
    next_start_ns: u64,
    walked_last: bool,
}

impl<'a> SessionGenerator<'a> {
    /// A session starting at state `start_state` at `start_ns`, seeded by `seed`.
    pub fn new(
        office: &'a Office,
        config: SessionConfig,
        seed: u64,
        start_state: u32,
        start_ns: u64,
    ) -> Self {
        Self {
            office,
            config,
            rng: ChaCha8Rng::seed_from_u64(seed),
            at: start_state.min(office.points.len().saturating_sub(1) as u32),
            next_start_ns: start_ns,
            walked_last: false,
        }
    }

    /// The state the next segment starts at.
    pub fn state(&self) -> u32 {
        self.at
    }

    /// When the next segment starts, ns.
    pub fn next_start_ns(&self) -> u64 {
        self.next_start_ns
    }

    /// Moves the person to `state` before the next segment: the truth jumps ("kidnapped").
    pub fn teleport(&mut self, state: u32) {
        self.at = state.min(self.office.points.len().saturating_sub(1) as u32);
    }

    /// The next segment: a walk, or after a walk possibly a stretch on a table.
    pub fn next_segment(&mut self) -> Segment {
        let (lo, hi) = self.config.table_s;
        if self.walked_last && self.rng.random_range(0.0..1.0) < self.config.table_chance {
            let duration_s = if hi > lo { self.rng.random_range(lo..hi) } else { lo };
            return self.table(duration_s);
        }
        let (lo, hi) = self.config.walk_length_m;
        let length_m = if hi > lo { self.rng.random_range(lo..hi) } else { lo };
        self.walk(length_m)
    }

    /// A walk of about `length_m` from the current state, at a pace drawn as in
    /// [`Office::walk`], with the configured stops.
    pub fn walk(&mut self, length_m: f64) -> Segment {
        let office = self.office;
        let speed = self.rng.random_range(0.8..1.4);
        let mut at = self.at;
        let mut came_from = u32::MAX;
        let mut points = vec![office.points[at as usize]];
        let mut pauses = Vec::new();
        let mut walked = 0.0;
        while walked < length_m.max(1.0) {
            let exits = &office.adjacency[at as usize];
            let options: Vec<u32> =
                exits.iter().copied().filter(|&n| n != came_from || exits.len() == 1).collect();
            let next = options[self.rng.random_range(0..options.len())];
            walked += nalgebra::distance(&office.points[at as usize], &office.points[next as usize]);
            came_from = at;
            at = next;
            points.push(office.points[at as usize]);
            if walked < length_m && self.rng.random_range(0.0..1.0) < self.config.pause_chance {
                let (lo, hi) = self.config.pause_s;
                pauses.push((walked, if hi > lo { self.rng.random_range(lo..hi) } else { lo }));
            }
        }
        let standing_ns = (self.config.imu.standing_s.max(0.0) * 1e9) as u64;
        let trajectory = Trajectory::new(self.next_start_ns + standing_ns, speed, &points, pauses);
        let seed = self.rng.random();
        let imu = synthesize(&trajectory, &self.config.imu, seed);
        let start_ns = self.next_start_ns;
        let end_ns = trajectory.end_ns() + standing_ns;
        self.finish(end_ns, at, true);
        Segment {
            activity: Activity::Walk,
            imu,
            start_ns,
            end_ns,
            end_state: at,
            truth: Truth::Walk(trajectory),
        }
    }

    /// The phone lying on a table at the current state for `duration_s`.
    pub fn table(&mut self, duration_s: f64) -> Segment {
        let seed = self.rng.random();
        let mut imu = lying_still(duration_s, &self.config.imu, seed);
        // `lying_still` starts at 1 s; move it to this segment's start.
        let start_ns = self.next_start_ns;
        let shift = |t: u64| t - 1_000_000_000 + start_ns;
        for stream in [&mut imu.accelerometer, &mut imu.gyroscope, &mut imu.magnetometer] {
            for s in stream.iter_mut() {
                s.timestamp_ns = shift(s.timestamp_ns);
            }
        }
        for h in imu.true_heading.iter_mut() {
            h.0 = shift(h.0);
        }
        let end_ns = start_ns + (duration_s.max(0.0) * 1e9) as u64;
        let at = self.at;
        self.finish(end_ns, at, false);
        let truth = Truth::Still(self.office.points[at as usize]);
        Segment { activity: Activity::Table, imu, start_ns, end_ns, end_state: at, truth }
    }

    fn finish(&mut self, end_ns: u64, at: u32, walked: bool) {
        self.at = at;
        self.next_start_ns = end_ns + SEAM_NS;
        self.walked_last = walked;
    }
}

/// Where a [`Feeder`]'s batches go.
pub trait ImuSink {
    /// A batch of accelerometer samples.
    fn accelerometer(&mut self, batch: &[SensorSample]);
    /// A batch of gyroscope samples.
    fn gyroscope(&mut self, batch: &[SensorSample]);
    /// A batch of magnetometer samples.
    fn magnetometer(&mut self, batch: &[SensorSample]);
}

/// Hands a session's samples to an engine as an app does: each stream in batches of at most
/// `batch` samples, everything up to an epoch before the epoch.
pub struct Feeder<'a> {
    generator: SessionGenerator<'a>,
    current: Segment,
    cursor: [usize; 3],
    batch: usize,
    /// Largest segment held so far, bytes.
    peak_segment_bytes: usize,
}

impl<'a> Feeder<'a> {
    /// Starts `generator`'s first segment.
    pub fn new(mut generator: SessionGenerator<'a>, batch: usize) -> Self {
        let current = generator.next_segment();
        let peak_segment_bytes = current.memory_bytes();
        Self { generator, current, cursor: [0; 3], batch: batch.max(1), peak_segment_bytes }
    }

    /// The segment under way.
    pub fn segment(&self) -> &Segment {
        &self.current
    }

    /// The generator (to teleport the person before the next segment).
    pub fn generator_mut(&mut self) -> &mut SessionGenerator<'a> {
        &mut self.generator
    }

    /// Largest segment held so far, bytes: the generator's own buffer.
    pub fn peak_segment_bytes(&self) -> usize {
        self.peak_segment_bytes
    }

    /// Replaces the segment under way, before any of its samples were delivered, with
    /// `segment`; the generator goes on as before. The recovery experiment gives its
    /// reference engine a different history this way: the phone lying where the kidnapped
    /// person is put down, instead of the first walk.
    pub fn replace_segment(&mut self, segment: Segment) {
        debug_assert_eq!(self.cursor, [0; 3], "samples of the segment under way were delivered");
        self.current = segment;
        self.cursor = [0; 3];
        self.peak_segment_bytes = self.peak_segment_bytes.max(self.current.memory_bytes());
    }

    fn advance_segment(&mut self) {
        self.current = self.generator.next_segment();
        self.cursor = [0; 3];
        self.peak_segment_bytes = self.peak_segment_bytes.max(self.current.memory_bytes());
    }

    /// Delivers every sample with a timestamp ≤ `t_ns` to `sink`, moving on to new segments as
    /// needed, and returns where the person is at `t_ns`.
    pub fn feed_until(&mut self, t_ns: u64, sink: &mut dyn ImuSink) -> Point2<f64> {
        loop {
            self.deliver(t_ns, sink);
            if self.current.end_ns >= t_ns || self.generator.next_start_ns > t_ns {
                break;
            }
            self.advance_segment();
        }
        self.current.truth_at(t_ns)
    }

    fn deliver(&mut self, t_ns: u64, sink: &mut dyn ImuSink) {
        let imu = &self.current.imu;
        for (k, stream) in [&imu.accelerometer, &imu.gyroscope, &imu.magnetometer].into_iter().enumerate() {
            let end = stream.partition_point(|s| s.timestamp_ns <= t_ns);
            while self.cursor[k] < end {
                let to = (self.cursor[k] + self.batch).min(end);
                let batch = &stream[self.cursor[k]..to];
                match k {
                    0 => sink.accelerometer(batch),
                    1 => sink.gyroscope(batch),
                    _ => sink.magnetometer(batch),
                }
                self.cursor[k] = to;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::OfficeConfig;

    #[derive(Default)]
    struct Collect {
        last: [Option<u64>; 3],
        counts: [usize; 3],
        largest_batch: usize,
    }

    impl Collect {
        fn take(&mut self, k: usize, batch: &[SensorSample]) {
            for s in batch {
                assert!(self.last[k].is_none_or(|l| s.timestamp_ns > l), "stream {k} not increasing");
                self.last[k] = Some(s.timestamp_ns);
            }
            self.counts[k] += batch.len();
            self.largest_batch = self.largest_batch.max(batch.len());
        }
    }

    impl ImuSink for Collect {
        fn accelerometer(&mut self, batch: &[SensorSample]) {
            self.take(0, batch);
        }
        fn gyroscope(&mut self, batch: &[SensorSample]) {
            self.take(1, batch);
        }
        fn magnetometer(&mut self, batch: &[SensorSample]) {
            self.take(2, batch);
        }
    }

    #[test]
    fn segments_chain_walks_and_tables_with_increasing_timestamps() {
        let office = Office::generate(&OfficeConfig { training_scans: 20, ..OfficeConfig::default() });
        let config =
            SessionConfig { table_s: (20.0, 30.0), walk_length_m: (10.0, 30.0), ..SessionConfig::default() };
        let generator = SessionGenerator::new(&office, config, 5, 0, 1_000_000_000);
        let mut feeder = Feeder::new(generator, 50);
        let mut sink = Collect::default();
        let mut activities = std::collections::HashSet::new();
        let mut t = 1_000_000_000;
        let mut previous: Option<Point2<f64>> = None;
        // 15 simulated minutes, an epoch every 2 s.
        for _ in 0..450 {
            t += 2_000_000_000;
            let truth = feeder.feed_until(t, &mut sink);
            activities.insert(feeder.segment().activity);
            if let Some(p) = previous {
                // Nobody walks faster than 1.4 m/s here: no jumps between epochs.
                assert!(nalgebra::distance(&p, &truth) <= 2.0 * 1.4 + 1e-9, "{p} -> {truth}");
            }
            previous = Some(truth);
        }
        assert_eq!(activities.len(), 2, "walks and tables both happened");
        assert!(sink.largest_batch <= 50);
        // 100 Hz on every stream, give or take the seams.
        for count in sink.counts {
            let expected = 900.0 * 100.0;
            assert!((count as f64 - expected).abs() < 0.01 * expected, "{count}");
        }
    }
}
