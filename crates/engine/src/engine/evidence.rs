//! Map evidence from the engine's own session (docs/evidence.md#from-a-session): each
//! accepted scan, weighted by the posterior of its epoch once the fixed-lag smoother has seen
//! the epochs after it, for an app to upload and a venue to refit its site from.
//!
//! A scan waits until its epoch is the oldest the smoother holds (the next step would let it
//! go), or until the smoother is about to forget its steps (a restart, a gap bridged,
//! feedback, new habits), or until the app takes the evidence: then one backward sweep
//! (`Engine::smoothed_posteriors`, El Gemayel et al. eq. 8 over the lag) gives its soft label,
//! as `walk_evidence` gives a whole walk's in the survey.

use super::Engine;
use crate::evidence::{most_probable, Evidence, EvidenceOptions, TransmitterKey};
use crate::radio::Scan;
use std::collections::{HashSet, VecDeque};

/// What a session gathered for the map since it started gathering or the last
/// [`Engine::take_evidence`].
#[derive(Clone, Debug, PartialEq)]
pub struct SessionEvidence {
    /// The evidence, counted as one walk.
    pub evidence: Evidence,
    /// Scans added to it.
    pub scans: u64,
    /// Accepted scans left out: their epoch's posterior was gone (a failed sweep) or could
    /// not be added (a sum that would overflow).
    pub scans_dropped: u64,
}

/// A scan's readings by transmitter key and the radios it listened with, as evidence takes
/// them ([`Evidence::add_scan`]).
type KeyedScan = (Vec<(TransmitterKey, f64)>, [bool; 2]);

/// The evidence being gathered, and the accepted scans whose epochs still wait for the
/// smoother.
#[derive(Debug)]
pub(super) struct Gathering {
    evidence: Evidence,
    options: EvidenceOptions,
    /// The site's transmitters: evidence of another refits nothing (`PreparedSurvey::refit`
    /// leaves it out), so it is not written, though the scan still counts for its radio.
    held: HashSet<TransmitterKey>,
    /// Ascending by epoch time.
    waiting: VecDeque<(u64, KeyedScan)>,
    scans: u64,
    dropped: u64,
}

impl Gathering {
    fn new(site: &crate::site::Site, options: EvidenceOptions) -> Self {
        let held = site.radio().transmitters().iter().map(TransmitterKey::of).collect();
        Self { evidence: Evidence::new(site), options, held, waiting: VecDeque::new(), scans: 0, dropped: 0 }
    }

    /// Gathering afresh on `site`, with the same options.
    pub(super) fn restarted(&self, site: &crate::site::Site) -> Self {
        Self::new(site, self.options)
    }
}

impl Engine {
    /// Starts gathering map evidence from this session's scans (docs/evidence.md#from-a-session),
    /// each scan's posterior kept as [`EvidenceOptions::default`] says (its mode), discarding
    /// whatever was being gathered. Nothing is gathered until this is called.
    pub fn start_evidence(&mut self) {
        self.start_evidence_with(EvidenceOptions::default());
    }

    /// [`start_evidence`](Self::start_evidence), keeping of each scan's posterior what `options`
    /// say.
    pub fn start_evidence_with(&mut self, options: EvidenceOptions) {
        self.gathering = Some(Gathering::new(&self.site, options));
    }

    /// Stops gathering and discards what was gathered and not taken.
    pub fn stop_evidence(&mut self) {
        self.gathering = None;
    }

    /// Whether the session is gathering evidence.
    pub fn is_gathering_evidence(&self) -> bool {
        self.gathering.is_some()
    }

    /// The evidence gathered since [`start_evidence`](Self::start_evidence) or the last take,
    /// as one walk; gathering goes on from nothing. The scans whose epochs the smoother still
    /// holds are weighed by the posterior smoothed by the epochs since. `None` when the
    /// session is not gathering.
    pub fn take_evidence(&mut self) -> Option<SessionEvidence> {
        self.settle_evidence(true);
        let fresh = self.gathering.as_ref()?.restarted(&self.site);
        let mut taken = std::mem::replace(self.gathering.as_mut()?, fresh);
        taken.evidence.add_walk();
        Some(SessionEvidence { evidence: taken.evidence, scans: taken.scans, scans_dropped: taken.dropped })
    }

    /// Keeps an accepted `scan` until its epoch's smoothed posterior is known: its readings
    /// as the radio map resolves them (hashed with the site's salt, readings older than the
    /// reading-age limit left out), of the site's transmitters.
    pub(super) fn keep_scan_for_evidence(&mut self, scan: &Scan) {
        let Some(gathering) = &self.gathering else { return };
        let held = &gathering.held;
        let max_age_ns = self.config.max_reading_age_ns.or(self.site.max_reading_age_ns());
        let scan = match &mut self.id_hasher {
            Some(hasher) => hasher.hash_scan(scan),
            None => scan,
        };
        let mut radios = [false; 2];
        let readings = (scan.readings.iter())
            .filter(|r| max_age_ns.is_none_or(|max| r.age_ns <= max))
            .filter_map(|r| {
                radios[usize::from(r.transmitter.is_ble())] = true;
                let key = TransmitterKey::of(&r.transmitter);
                held.contains(&key).then_some((key, r.rssi_dbm))
            })
            .collect();
        let timestamp_ns = scan.timestamp_ns;
        if let Some(gathering) = &mut self.gathering {
            gathering.waiting.push_back((timestamp_ns, (readings, radios)));
        }
        // Without a smoother the filtered posterior is all there will be.
        if self.config.fixed_lag_epochs == 0 {
            self.settle_evidence(true);
        }
    }

    /// Adds the waiting scans to the evidence, each weighted by its epoch's posterior smoothed
    /// by the epochs the smoother holds after it: every waiting scan with `all` (the smoother
    /// is about to forget its steps, or the evidence is taken), else those whose epochs the
    /// smoother's next step lets go. Call it only where the filter's posterior is that of the
    /// latest epoch and the smoother's steps lead up to it (between epochs, or within one
    /// before the filter steps).
    pub(super) fn settle_evidence(&mut self, all: bool) {
        let Some(gathering) = &self.gathering else { return };
        let Some(&(first, _)) = gathering.waiting.front() else { return };
        let due = if all {
            u64::MAX
        } else {
            match self.smoother.oldest_timestamp() {
                Some(oldest) if self.smoother.is_full() && first <= oldest => oldest,
                _ => return,
            }
        };
        let mut posteriors: Vec<(u64, Vec<(u32, f64)>)> = Vec::new();
        self.smoothed_posteriors(|timestamp_ns, posterior| {
            if timestamp_ns <= due {
                posteriors.push((timestamp_ns, posterior.to_vec()));
            }
        });
        let Some(gathering) = &mut self.gathering else { return };
        let mut kept = Vec::new();
        while gathering.waiting.front().is_some_and(|(t, _)| *t <= due) {
            let Some((timestamp_ns, (readings, radios))) = gathering.waiting.pop_front() else { break };
            let posterior = posteriors.iter().find(|(t, _)| *t == timestamp_ns).map(|(_, p)| p);
            let options = gathering.options;
            let added = posterior.map(|p| {
                most_probable(p, options.mass, options.states, &mut kept);
                gathering.evidence.add_scan(&kept, &readings, radios)
            });
            match added {
                Some(Ok(())) => gathering.scans += 1,
                Some(Err(e)) => {
                    log::debug!("scan left out of the evidence: {e}");
                    gathering.dropped += 1;
                }
                None => gathering.dropped += 1,
            }
        }
    }

    /// Forgets the smoother's steps (a restart, a gap bridged, feedback, new habits), the
    /// scans waiting for them settled first.
    pub(super) fn clear_smoother(&mut self) {
        self.settle_evidence(true);
        self.smoother.clear();
    }
}
