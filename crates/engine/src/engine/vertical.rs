//! Floor changes from the barometer (docs/accuracy.md#barometer): a motion input for the
//! vertical, as steps and heading are for the plan.
//!
//! The engine keeps an anchor: the phone's height and the posterior mass of each floor at the
//! latest epoch the height had settled. At each epoch the height climbed since the anchor
//! weighs each floor j by how well it fits a move from the anchor's floors f:
//! Σ_f P_anchor(f) · p(Δh | level_j − level_f). The weight multiplies the epoch's emission,
//! as the transition into floor j would (the plan's transition is left as it is: it spreads
//! mass between floors only through its floor weight). When the height has settled again the
//! anchor moves to it, with the posterior's floors.

use super::Engine;
use crate::hmm::Transition;
use crate::sensors::{BatchReport, PressureSample};
use crate::site::{Landings, Site};

/// A storey is at least this high, m: the headroom building codes ask over a stair (2.0 m,
/// e.g. the UK's Approved Document K 1.10, the US IBC 1011.3 2032 mm).
pub(crate) const STOREY_MIN_M: f64 = 2.0;

/// A storey is at most this high, m: beyond it a building is a hall, one floor. 7 m covers the
/// tallest public storeys (museums, stations, malls with their 5-6 m).
pub(crate) const STOREY_MAX_M: f64 = 7.0;

/// The spread of a height the phone climbed against a floor's, m: the phone held higher or
/// lower (a hand to a pocket, about 0.5 m) and the barometer's drift over a minute (below
/// 0.1 hPa, 0.8 m, in still weather).
pub(crate) const CLIMB_SIGMA_M: f64 = 0.5;

/// The share of heights the barometer gets wrong: a door or a ventilation draught moves the
/// pressure by up to a storey's worth for seconds. Such a height is taken as uniform over the
/// building's height ([`Engine::weigh_floors_by_height`]), so that a height no floor explains
/// weighs them all alike and leaves the floor to the radio.
pub(crate) const BAROMETER_OUTLIER_SHARE: f64 = 0.05;

/// The Bayes factor by which the barometer must favour one level over another before it
/// overrules the posterior's floor: 3, the start of "positive" evidence on Kass & Raftery's
/// scale (J. Am. Stat. Assoc. 90(430), 1995, §3.2). The engine reports a level the site lacks
/// only above it, and the anchor does not move onto a floor another fits better by more. Below
/// it the height fits the posterior's floor nearly as well (5.6 m is one tall storey or two
/// low ones) and the radio's floor stands.
pub(crate) const LEVEL_BAYES_FACTOR: f64 = 3.0;

/// Where the phone's height settled, and which floor it was on then.
#[derive(Clone, Debug, Default)]
pub(super) struct FloorAnchor {
    height_m: f64,
    /// Posterior mass per floor.
    floors: Vec<f64>,
}

/// The density of climbing `dh_m` in a move of `k` levels (negative: down): about 0 for the
/// same floor; for another, |Δh| / |k| a storey height between [`STOREY_MIN_M`] and
/// [`STOREY_MAX_M`], uniform, with the climb's spread at the edges, and Δh the sign of k.
pub(crate) fn climb_likelihood(dh_m: f64, k: i32) -> f64 {
    let gauss = |x: f64| {
        (-0.5 * (x / CLIMB_SIGMA_M).powi(2)).exp() / (CLIMB_SIGMA_M * (2.0 * std::f64::consts::PI).sqrt())
    };
    if k == 0 {
        return gauss(dh_m);
    }
    let (low, high) = (f64::from(k.abs()) * STOREY_MIN_M, f64::from(k.abs()) * STOREY_MAX_M);
    let climbed = dh_m * f64::from(k.signum());
    let outside = if climbed < low {
        low - climbed
    } else if climbed > high {
        climbed - high
    } else {
        0.0
    };
    // A uniform over [low, high] convolved with the climb's spread, at its edges a Gaussian's.
    gauss(outside) * CLIMB_SIGMA_M * (2.0 * std::f64::consts::PI).sqrt()
        / (high - low + CLIMB_SIGMA_M * (2.0 * std::f64::consts::PI).sqrt())
}

/// A transition with floor changes: each row keeps `1 − share` of its weights, and moves
/// `share / (F − 1)` of its mass to the state of each other floor nearest the row's state
/// ([`Landings`]). The barometer's weight then tells which floor the phone is on; without
/// this, mass reached another floor only through the floor weight (HIPE eq. 11), many epochs
/// of climbing too late.
pub(super) struct FloorChanges<'a> {
    pub(super) inner: &'a dyn Transition,
    pub(super) site: &'a Site,
    pub(super) landings: &'a Landings,
    /// The probability of changing floor over the epoch.
    pub(super) share: f64,
}

impl Transition for FloorChanges<'_> {
    fn row(&self, i: usize, row: &mut Vec<(u32, f64)>) -> f64 {
        let floor = self.inner.row(i, row);
        let floors = self.site.floors().len();
        let own = self.site.states()[i].floor;
        if floors < 2 {
            return floor;
        }
        // The row's mass: its explicit weights and the floor weight of every state not listed.
        let n = self.site.states().len();
        let total: f64 = row.iter().map(|e| e.1).sum::<f64>() + floor * (n - row.len()) as f64;
        let keep = 1.0 - self.share;
        let moved = self.share / (floors - 1) as f64 * total;
        row.iter_mut().for_each(|e| e.1 *= keep);
        for g in (0..floors).filter(|&g| g != own) {
            let j = self.landings.on(i, g);
            match row.iter_mut().find(|e| e.0 == j) {
                Some(e) => e.1 += moved,
                // Listed now, so it keeps the floor weight it had unlisted.
                None => row.push((j, moved + floor * keep)),
            }
        }
        floor * keep
    }

    fn floor_ratio(&self) -> Option<f64> {
        self.inner.floor_ratio()
    }
}

impl Engine {
    /// Takes a batch of barometer readings (docs/accuracy.md#barometer). Readings that are not
    /// finite or not a pressure, not after the previous, or too far ahead of the engine's
    /// clock are dropped and counted in the report and in
    /// [`InputStats::pressure_dropped`](super::InputStats::pressure_dropped).
    pub fn push_pressure(&mut self, batch: &[PressureSample]) -> BatchReport {
        let clock = self.held.as_ref().map(|h| h.timestamp_ns).or(self.last_epoch_ns);
        let bound_ns = (self.config.motion.max_backlog_s * 1e9) as u64;
        let report = self.barometer.push(batch, clock, bound_ns);
        if report.accepted > 0 && self.landings.is_none() && self.floor_change_rate().is_some() {
            self.landings = Some(self.site.landings());
        }
        self.stats.timestamps_ahead += report.ahead as u64;
        self.stats.pressure_dropped += (report.non_finite + report.out_of_order) as u64;
        report
    }

    /// The probability of a floor change over `dt_s` ([`FloorChanges`]): where the barometer
    /// measures the height now, 1 − exp(−rate · Δt) at the survey's floor-change rate
    /// ([`Calibration::floor_change_rate_hz`](crate::site::Calibration::floor_change_rate_hz)); 0
    /// elsewhere, and on a site without the rate.
    pub(super) fn floor_change(&self, timestamp_ns: u64, dt_s: f64) -> f64 {
        match self.floor_change_rate() {
            Some(rate) if self.landings.is_some() && self.barometer.height_at(timestamp_ns).is_some() => {
                1.0 - (-rate * dt_s).exp()
            }
            _ => 0.0,
        }
    }

    /// The site's floor-change rate, per second, where this engine uses it: the barometer on,
    /// the site's calibration on, two floors or more.
    fn floor_change_rate(&self) -> Option<f64> {
        let on = self.config.barometer && self.config.site_calibration && self.levels.len() >= 2;
        self.site.calibration().floor_change_rate_hz.filter(|_| on)
    }

    /// Adds the log weight of the height climbed since the anchor to each state's emission.
    pub(super) fn weigh_floors_by_height(&mut self, timestamp_ns: u64) {
        if !self.config.barometer || self.levels.len() < 2 {
            return;
        }
        let Some(height) = self.barometer.height_at(timestamp_ns) else {
            // Without a current height the next one may be from anywhere: start again.
            self.floor_anchor = None;
            return;
        };
        let Some(anchor) = &self.floor_anchor else { return };
        let dh = height - anchor.height_m;
        let weights: Vec<f64> = self.levels.iter().map(|&to| self.level_weight(anchor, dh, to)).collect();
        let most = weights.iter().copied().fold(0.0, f64::max);
        if !(most > 0.0 && most.is_finite()) {
            return;
        }
        let ln_weight: Vec<f64> = weights.iter().map(|w| (w / most).ln()).collect();
        for (e, state) in self.ln_emission.iter_mut().zip(self.site.states()) {
            *e += ln_weight[state.floor];
        }
    }

    /// The barometer's weight of being on level `to` after climbing `dh_m` since `anchor`:
    /// Σ_f P_anchor(f) · p(Δh | to − level_f), mixed with a wrong height uniform over the
    /// heights a move between the site's floors can climb ([`BAROMETER_OUTLIER_SHARE`]).
    fn level_weight(&self, anchor: &FloorAnchor, dh_m: f64, to: i32) -> f64 {
        let span = self.levels.iter().max().zip(self.levels.iter().min()).map_or(1, |(a, b)| (a - b).max(1));
        let outlier = BAROMETER_OUTLIER_SHARE / (2.0 * f64::from(span) * STOREY_MAX_M);
        let explained: f64 = anchor
            .floors
            .iter()
            .zip(&self.levels)
            .map(|(p, &from)| p * climb_likelihood(dh_m, to - from))
            .sum();
        explained * (1.0 - BAROMETER_OUTLIER_SHARE) + outlier
    }

    /// The level the site has no floor for where the barometer places the phone, when it does
    /// (docs/accuracy.md#barometer): the height has settled, and the height climbed since the
    /// anchor fits one of [`Site::unmapped_levels`] better than `floor`'s level by a Bayes
    /// factor above [`LEVEL_BAYES_FACTOR`].
    pub(super) fn unmapped_level(&self, timestamp_ns: u64, floor: usize) -> Option<i32> {
        self.unmapped_level_by(timestamp_ns, floor, LEVEL_BAYES_FACTOR)
    }

    /// The unmapped level the barometer favours over `floor`'s by a Bayes factor above
    /// `factor`, as [`unmapped_level`](Self::unmapped_level).
    fn unmapped_level_by(&self, timestamp_ns: u64, floor: usize, factor: f64) -> Option<i32> {
        if !self.config.barometer || self.unmapped_levels.is_empty() || !self.barometer.settled(timestamp_ns)
        {
            return None;
        }
        let anchor = self.floor_anchor.as_ref()?;
        let dh = self.barometer.height_at(timestamp_ns)? - anchor.height_m;
        let here = self.level_weight(anchor, dh, *self.levels.get(floor)?);
        self.unmapped_levels
            .iter()
            .map(|&level| (level, self.level_weight(anchor, dh, level)))
            .filter(|&(_, w)| w > factor * here)
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(level, _)| level)
    }

    /// Whether the height climbed since `anchor` fits another of the site's floors better than
    /// floor `to` by a Bayes factor above [`LEVEL_BAYES_FACTOR`]: a posterior on `to` is then
    /// against the barometer, on the radio's word or still behind a climb.
    fn refuted(&self, anchor: &FloorAnchor, dh_m: f64, to: usize) -> bool {
        let here = self.level_weight(anchor, dh_m, self.levels[to]);
        self.levels.iter().any(|&level| self.level_weight(anchor, dh_m, level) > LEVEL_BAYES_FACTOR * here)
    }

    /// After the filter's step: where the height has settled, the anchor moves to it with the
    /// posterior's floors. After a climb of half a storey or more it moves only once the
    /// posterior has changed floor the way the phone climbed: a height no floor of the site
    /// explains (a storey nobody surveyed, a mezzanine) or one the radio refuses stays measured
    /// from the last floor that explained one, so that the rest of the climb adds to it. At
    /// any height it does not move onto a floor the height [refutes](Self::refuted).
    pub(super) fn settle_floor_anchor(&mut self, timestamp_ns: u64) {
        if !self.config.barometer || self.levels.len() < 2 || !self.barometer.settled(timestamp_ns) {
            return;
        }
        let Some(height_m) = self.barometer.height_at(timestamp_ns) else { return };
        let mut floors = vec![0.0; self.levels.len()];
        for (p, state) in self.filter.posterior().iter().zip(self.site.states()) {
            floors[state.floor] += p;
        }
        let total: f64 = floors.iter().sum();
        if !(total > 0.0 && total.is_finite()) {
            return;
        }
        floors.iter_mut().for_each(|p| *p /= total);
        if let Some(anchor) = &self.floor_anchor {
            let dh = height_m - anchor.height_m;
            let (from, to) = (most_likely(&anchor.floors), most_likely(&floors));
            let climbed = dh.abs() >= STOREY_MIN_M / 2.0;
            if climbed || from != to {
                let along = (self.levels[to] - self.levels[from]).signum() == dh.signum() as i32;
                // A floor the barometer refutes, or fits worse than a level the site lacks,
                // is no place to measure later climbs from: moving the anchor onto a wrong
                // floor shifts every later height by a storey, keeping it only lets the
                // weather drift in. So is a floor the posterior has not yet left after a climb.
                if (climbed && (from == to || !along))
                    || self.refuted(anchor, dh, to)
                    || self.unmapped_level_by(timestamp_ns, to, 1.0).is_some()
                {
                    return;
                }
            }
        }
        self.floor_anchor = Some(FloorAnchor { height_m, floors });
    }
}

/// The index of the largest mass.
fn most_likely(masses: &[f64]) -> usize {
    masses.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).map_or(0, |(i, _)| i)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::site::{BuildOptions, SiteBuilder};
    use nalgebra::Point2;

    #[test]
    fn a_climb_of_a_storey_favours_the_floor_above_and_none_the_same() {
        let same = climb_likelihood(0.1, 0);
        assert!(same > 10.0 * climb_likelihood(0.1, 1));
        let up = climb_likelihood(3.1, 1);
        assert!(up > 100.0 * climb_likelihood(3.1, 0), "{up}");
        assert!(up > 100.0 * climb_likelihood(3.1, -1), "the wrong way");
        assert!(up > 5.0 * climb_likelihood(3.1, 2), "two storeys are at least 4 m");
        // 5.6 m fits one tall storey or two low ones.
        let (one, two) = (climb_likelihood(-5.6, -1), climb_likelihood(-5.6, -2));
        assert!(one > 0.0 && two > 0.0 && (one / two - 2.0).abs() < 0.5, "{one} {two}");
    }

    /// Row i: half its mass on itself, the rest spread evenly over the other states.
    struct Stay(usize);

    impl Transition for Stay {
        fn row(&self, i: usize, row: &mut Vec<(u32, f64)>) -> f64 {
            row.push((i as u32, 0.5));
            0.5 / (self.0 - 1) as f64
        }
    }

    #[test]
    fn floor_changes_move_their_share_to_the_landing_and_keep_the_rows_mass() {
        let mut b = SiteBuilder::new("three floors");
        let floors = [b.floor("0", 0.0), b.floor("1", 4.0), b.floor("2", 8.0)];
        let ids: Vec<Vec<u32>> = (floors.iter())
            .map(|&f| (0..3).map(|k| b.state(f, Point2::new(5.0 * k as f64, 0.0), vec![])).collect())
            .collect();
        for floor in &ids {
            b.edge(floor[0], floor[1], None);
            b.edge(floor[1], floor[2], None);
        }
        let site = b.build(BuildOptions::default()).unwrap();
        let n = site.states().len();
        let landings = site.landings();
        let share = 0.01;
        let changes = FloorChanges { inner: &Stay(n), site: &site, landings: &landings, share };
        let mut row = Vec::new();
        let i = ids[0][1] as usize;
        let floor = changes.row(i, &mut row);
        let mass: f64 = row.iter().map(|e| e.1).sum::<f64>() + floor * (n - row.len()) as f64;
        assert!((mass - 1.0).abs() < 1e-12, "{mass}");
        let weight = |j: u32| row.iter().find(|e| e.0 == j).map(|e| e.1);
        assert_eq!(weight(i as u32), Some(0.5 * (1.0 - share)));
        // Half the share to each other floor, at the state above and below, which also keeps
        // the floor weight it had unlisted.
        for up in [ids[1][1], ids[2][1]] {
            let expected = share / 2.0 + floor;
            assert!((weight(up).unwrap() - expected).abs() < 1e-15);
        }
        assert_eq!(row.len(), 3);
        assert_eq!(floor, 0.5 / (n - 1) as f64 * (1.0 - share));
    }
}
