//! Transmitters that one radio sends. An access point that serves several networks reports
//! each under its own BSSID, from the same antenna at the same level, so a scan hears one
//! reading several times over; the radio map counts such a group once
//! ([`waymark_engine::radio::RadioMap::with_shared_radios`]). The survey finds the groups in its own
//! scans, whatever the ids look like (hashed ones too): two transmitters are one radio when
//! they are nearly always heard together and their readings move together.

use std::collections::HashMap;

/// Two transmitters are one radio only when heard together in at least this many scans, so
/// that the difference's spread below rests on that many readings; the pairs measured in
/// docs/tuning.md#shared-radios rest on as many.
const MIN_SCANS_TOGETHER: u32 = 20;
/// ... in at least this share of the scans that hear the more often heard of the two, so that
/// transmitters that merely meet now and then are not joined (docs/tuning.md#shared-radios) ...
const MIN_SHARE_TOGETHER: f64 = 0.8;
/// ... and when the difference of their readings has at most this standard deviation, dB: it
/// lies between the spread of one radio's networks and that of an access point's two bands or
/// of unrelated transmitters (docs/tuning.md#shared-radios).
const MAX_DIFFERENCE_SD_DB: f64 = 3.0;
/// Only readings of a scan this close are paired, dB: three times the spread allowed, so a
/// pair of one radio is paired in nearly every scan while a scan pairs each reading with its
/// neighbours in level only, not with every other reading.
const PAIR_WINDOW_DB: f64 = 3.0 * MAX_DIFFERENCE_SD_DB;

/// The groups of two or more transmitters (indices below `transmitters`) that one radio sends,
/// from `scans` as (transmitter, RSSI) readings, one per transmitter a scan; each group sorted,
/// the groups by their first member.
pub(super) fn shared_radios<'a>(
    scans: impl Iterator<Item = &'a [(u32, f64)]>,
    transmitters: usize,
) -> Vec<Vec<u32>> {
    let mut heard = vec![0u32; transmitters];
    // (a, b), a < b: scans together, Σ (rₐ - r_b), Σ (rₐ - r_b)².
    let mut pairs: HashMap<(u32, u32), (u32, f64, f64)> = HashMap::new();
    let mut sorted: Vec<(u32, f64)> = Vec::new();
    for scan in scans {
        sorted.clear();
        sorted.extend(scan.iter().filter(|r| r.1.is_finite() && (r.0 as usize) < transmitters));
        sorted.sort_by(|x, y| x.1.total_cmp(&y.1));
        for (i, &(a, ra)) in sorted.iter().enumerate() {
            heard[a as usize] += 1;
            for &(b, rb) in sorted[i + 1..].iter().take_while(|r| r.1 - ra <= PAIR_WINDOW_DB) {
                let (key, d) = if a < b { ((a, b), ra - rb) } else { ((b, a), rb - ra) };
                let e = pairs.entry(key).or_insert((0, 0.0, 0.0));
                *e = (e.0 + 1, e.1 + d, e.2 + d * d);
            }
        }
    }
    // Union-find over the pairs that pass.
    let mut parent: Vec<u32> = (0..transmitters as u32).collect();
    fn root(parent: &mut [u32], mut t: u32) -> u32 {
        while parent[t as usize] != t {
            parent[t as usize] = parent[parent[t as usize] as usize];
            t = parent[t as usize];
        }
        t
    }
    let mut joined: Vec<(u32, u32)> = pairs
        .into_iter()
        .filter(|&((a, b), (n, sum, squares))| {
            let more_often = heard[a as usize].max(heard[b as usize]);
            let mean = sum / f64::from(n);
            let variance = (squares / f64::from(n) - mean * mean).max(0.0);
            n >= MIN_SCANS_TOGETHER
                && f64::from(n) >= MIN_SHARE_TOGETHER * f64::from(more_often)
                && variance.sqrt() <= MAX_DIFFERENCE_SD_DB
        })
        .map(|(pair, _)| pair)
        .collect();
    // In order, so the groups do not depend on the hash map's.
    joined.sort_unstable();
    for (a, b) in joined {
        let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
        if ra != rb {
            parent[ra.max(rb) as usize] = ra.min(rb);
        }
    }
    let mut groups: HashMap<u32, Vec<u32>> = HashMap::new();
    for t in 0..transmitters as u32 {
        let r = root(&mut parent, t);
        groups.entry(r).or_default().push(t);
    }
    let mut groups: Vec<Vec<u32>> = groups.into_values().filter(|g| g.len() >= 2).collect();
    groups.sort_unstable();
    groups
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Scans along a walk: transmitters 0 and 1 are one radio (the same level, give or take
    /// 1 dB), 2 is another access point at a level of its own, 3 is heard now and then.
    fn walk() -> Vec<Vec<(u32, f64)>> {
        (0..60)
            .map(|k| {
                let level = -50.0 - f64::from(k % 30);
                let jitter = if k % 2 == 0 { 1.0 } else { -1.0 };
                let mut scan = vec![(0, level), (1, level + jitter), (2, -90.0 + f64::from(k % 30))];
                if k % 3 == 0 {
                    scan.push((3, level + 0.5));
                }
                scan
            })
            .collect()
    }

    #[test]
    fn networks_of_one_radio_are_grouped_and_other_access_points_are_not() {
        let scans = walk();
        let groups = shared_radios(scans.iter().map(Vec::as_slice), 4);
        // 3 follows 0 and 1 closely but is heard in a third of their scans only.
        assert_eq!(groups, vec![vec![0, 1]]);
    }

    #[test]
    fn too_few_scans_together_make_no_group() {
        let scans = walk();
        let groups = shared_radios(scans[..(MIN_SCANS_TOGETHER as usize - 1)].iter().map(Vec::as_slice), 4);
        assert!(groups.is_empty());
    }

    #[test]
    fn out_of_range_and_non_finite_readings_are_ignored() {
        let mut scans = walk();
        for scan in &mut scans {
            scan.push((9, -60.0));
            scan.push((2, f64::NAN));
        }
        assert_eq!(shared_radios(scans.iter().map(Vec::as_slice), 4), vec![vec![0, 1]]);
    }
}
