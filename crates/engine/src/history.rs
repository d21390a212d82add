//! The engine's recent epochs, kept for a later learning pass: Baum-Welch over a user's own
//! walks (El Gemayel et al. §III-A) with the epochs at which the user said where they were
//! (§IV-C: "providing information about the true state ... at random times"). Bounded: the
//! oldest epoch goes when a new one comes and the history is full.

use crate::fix::PositionFix;
use std::collections::VecDeque;

/// What an epoch observed.
#[derive(Clone, Debug, PartialEq)]
pub enum EpochInput {
    /// A radio scan.
    Scan,
    /// Motion only (`advance`).
    Motion,
    /// A position fix from another system.
    Fix(PositionFix),
    /// User feedback alone: the epoch observed nothing but where the user said they were.
    Feedback,
}

/// One epoch of the history.
#[derive(Clone, Debug, PartialEq)]
pub struct EpochRecord {
    /// The epoch's time, ns.
    pub timestamp_ns: u64,
    /// What it observed.
    pub input: EpochInput,
    /// The engine's estimate after it: floor index and (x, y), m; revised by feedback given at
    /// the same time.
    pub floor: usize,
    /// Estimate x, m.
    pub x: f64,
    /// Estimate y, m.
    pub y: f64,
    /// The level the site has no floor for that the epoch reported
    /// ([`Position::unmapped_level`](crate::Position::unmapped_level)).
    pub unmapped_level: Option<i32>,
    /// The estimate's 68% radius, m: the spread of this epoch's observation when the epochs
    /// are learned from ([`crate::habits`]).
    pub accuracy_m: f64,
    /// User feedback: the states (indices, ascending) the user said they were in at this
    /// epoch; `None` without feedback. A learning pass zeroes the forward variable outside
    /// them (§IV-C).
    pub allowed: Option<Vec<u32>>,
}

/// A bounded history of epochs, oldest first.
#[derive(Clone, Debug, PartialEq)]
pub struct History {
    capacity: usize,
    records: VecDeque<EpochRecord>,
}

impl History {
    /// A history of at most `capacity` epochs (0 keeps none).
    pub fn new(capacity: usize) -> Self {
        Self { capacity, records: VecDeque::new() }
    }

    /// Epochs held, oldest first.
    pub fn records(&self) -> &VecDeque<EpochRecord> {
        &self.records
    }

    /// The latest epoch held at `timestamp_ns`.
    pub fn at(&self, timestamp_ns: u64) -> Option<&EpochRecord> {
        let after = self.records.partition_point(|r| r.timestamp_ns <= timestamp_ns);
        after.checked_sub(1).map(|i| &self.records[i]).filter(|r| r.timestamp_ns == timestamp_ns)
    }

    /// Adds the newest epoch, dropping the oldest when full.
    pub fn push(&mut self, record: EpochRecord) {
        if self.capacity == 0 {
            return;
        }
        if self.records.len() == self.capacity {
            self.records.pop_front();
        }
        self.records.push_back(record);
    }

    /// Feedback for the newest epoch, and its revised estimate: its allowed states become
    /// their intersection with `allowed` (sorted), or `allowed` itself when there were none
    /// or nothing is in both (the user corrected themselves: the latest word wins).
    pub fn pin_latest(&mut self, allowed: &[u32], floor: usize, x: f64, y: f64, accuracy_m: f64) {
        let Some(latest) = self.records.back_mut() else { return };
        let both: Vec<u32> = match &latest.allowed {
            Some(before) => before.iter().copied().filter(|s| allowed.binary_search(s).is_ok()).collect(),
            None => Vec::new(),
        };
        latest.allowed = Some(if both.is_empty() { allowed.to_vec() } else { both });
        (latest.floor, latest.x, latest.y, latest.accuracy_m) = (floor, x, y, accuracy_m);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(t: u64) -> EpochRecord {
        EpochRecord {
            timestamp_ns: t,
            input: EpochInput::Scan,
            floor: 0,
            x: 0.0,
            y: 0.0,
            unmapped_level: None,
            accuracy_m: 3.0,
            allowed: None,
        }
    }

    #[test]
    fn an_epoch_is_found_by_its_time_the_latest_of_equal_times() {
        let mut h = History::new(3);
        for (t, level) in [(1, None), (2, Some(-1)), (2, Some(-2)), (4, None)] {
            h.push(EpochRecord { unmapped_level: level, ..record(t) });
        }
        assert_eq!(h.at(2).and_then(|r| r.unmapped_level), Some(-2));
        assert!(h.at(1).is_none(), "dropped when full");
        assert!(h.at(3).is_none() && h.at(5).is_none());
        assert_eq!(h.at(4).map(|r| r.timestamp_ns), Some(4));
    }

    #[test]
    fn keeps_the_newest_epochs_and_their_feedback() {
        let mut h = History::new(3);
        h.pin_latest(&[1], 0, 0.0, 0.0, 1.0); // nothing yet: nothing happens
        for t in 0..5 {
            h.push(record(t));
        }
        let times: Vec<u64> = h.records().iter().map(|r| r.timestamp_ns).collect();
        assert_eq!(times, [2, 3, 4]);
        h.pin_latest(&[1, 2, 3], 0, 1.0, 2.0, 1.0);
        h.pin_latest(&[2, 3, 7], 0, 1.5, 2.0, 1.0);
        assert_eq!(h.records()[2].allowed, Some(vec![2, 3]));
        assert_eq!(h.records()[2].x, 1.5);
        h.pin_latest(&[9], 0, 1.5, 2.0, 1.0);
        assert_eq!(h.records()[2].allowed, Some(vec![9]), "a contradiction: the latest word wins");
        assert_eq!(h.records()[1].allowed, None);
        let mut none = History::new(0);
        none.push(record(1));
        assert!(none.records().is_empty());
    }
}
