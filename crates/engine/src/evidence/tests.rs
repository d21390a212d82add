use super::*;
use crate::site::{BuildOptions, SiteBuilder};
use nalgebra::Point2;
use proptest::prelude::*;

/// A corridor of `n` states 1 m apart, without fingerprints.
fn corridor(n: u32) -> Site {
    let mut b = SiteBuilder::new("corridor");
    let f = b.floor("G", 0.0);
    let ids: Vec<u32> = (0..n).map(|x| b.state(f, Point2::new(f64::from(x), 0.0), vec![])).collect();
    for w in ids.windows(2) {
        b.edge(w[0], w[1], None);
    }
    b.build(BuildOptions::default()).unwrap()
}

fn key(n: u8) -> TransmitterKey {
    TransmitterKey::of(&TransmitterId::wifi(&format!("aa:bb:cc:dd:ee:{n:02x}")).unwrap())
}

fn beacon(n: u16) -> TransmitterKey {
    TransmitterKey::of(&TransmitterId::ble("fda50693-a4e2-4fb1-afcf-c6eb07647825", 1, n).unwrap())
}

#[test]
fn keys_are_the_salted_hash_where_the_site_has_one() {
    let salt = crate::radio::Salt::new(vec![7u8; 32]).unwrap();
    let id = TransmitterId::wifi("aa:bb:cc:dd:ee:ff").unwrap();
    let hashed = salt.hash(&id);
    let TransmitterId::HashedWifi { hash } = &hashed else { panic!("{hashed:?}") };
    let key = TransmitterKey::of(&hashed);
    assert_eq!(key.hash.to_vec(), crate::radio::hex_decode(hash).unwrap());
    assert!(!key.ble);
    // A raw id keys by the unkeyed SHA-256 of its canonical text, not by the salted hash.
    let raw = TransmitterKey::of(&id);
    assert_ne!(raw, key);
    assert_eq!(raw.hash[..], Sha256::digest(b"wifi:aa:bb:cc:dd:ee:ff")[..16]);
    assert!(
        beacon(3).ble
            && TransmitterKey::of(&salt.hash(&TransmitterId::ble_address("aa:bb:cc:dd:ee:ff").unwrap())).ble
    );
}

#[test]
fn a_scan_adds_its_readings_at_each_state_by_its_probability() {
    let site = corridor(5);
    let mut e = Evidence::new(&site);
    let clip = e.clip_dbm();
    e.add_scan(
        &[(1, 0.75), (2, 0.25)],
        &[(key(1), -60.0), (key(2), clip), (beacon(1), -70.0)],
        [true, false],
    )
    .unwrap();
    e.add_walk();
    assert_eq!(e.scanned(1), [0.75, 0.0]);
    assert_eq!(e.scanned(2), [0.25, 0.0]);
    // Heard above the clip level: key 1 only; a beacon in a WiFi-only scan is not counted.
    assert_eq!(e.heard_entries(), 2);
    let m = e.moments(1, &key(1)).unwrap();
    assert_eq!((m.samples, m.heard, m.heard_mean, m.heard_var), (0.75, 0.75, -60.0, 0.0));
    assert!(e.moments(1, &key(2)).is_none() && e.moments(1, &beacon(1)).is_none());
    // A second scan at state 1 that does not hear key 1: a censored sample of weight 1.
    e.add_scan(&[(1, 1.0)], &[(key(3), -80.0)], [true, true]).unwrap();
    let m = e.moments(1, &key(1)).unwrap();
    assert_eq!((m.samples, m.heard), (1.75, 0.75));
    assert_eq!(e.scanned(1), [1.75, 1.0]);
    assert_eq!(e.walks(), 1);
}

#[test]
fn a_repeated_transmitter_counts_once_at_its_strongest() {
    let site = corridor(2);
    let mut e = Evidence::new(&site);
    e.add_scan(&[(0, 1.0)], &[(key(1), -70.0), (key(1), -65.0)], [true, false]).unwrap();
    let m = e.moments(0, &key(1)).unwrap();
    assert_eq!((m.samples, m.heard, m.heard_mean), (1.0, 1.0, -65.0));
}

#[test]
fn bad_scans_are_refused_and_change_nothing() {
    let site = corridor(3);
    let mut e = Evidence::new(&site);
    e.add_scan(&[(0, 1.0)], &[(key(1), -70.0)], [true, false]).unwrap();
    let before = e.clone();
    let wifi = [true, false];
    assert!(matches!(
        e.add_scan(&[(3, 1.0)], &[], wifi),
        Err(EvidenceError::UnknownState { state: 3, states: 3 })
    ));
    assert!(matches!(e.add_scan(&[(0, f64::NAN)], &[], wifi), Err(EvidenceError::InvalidWeight(_))));
    assert!(matches!(e.add_scan(&[(0, -0.1)], &[], wifi), Err(EvidenceError::InvalidWeight(_))));
    assert!(matches!(e.add_scan(&[(0, 0.7), (1, 0.7)], &[], wifi), Err(EvidenceError::InvalidWeight(_))));
    assert!(matches!(
        e.add_scan(&[(0, 1.0)], &[(key(1), f64::INFINITY)], wifi),
        Err(EvidenceError::InvalidReading(_))
    ));
    assert_eq!(e, before);
    // An overflow refuses the whole scan.
    e.scanned.insert(1, [u64::MAX - 1, 0]);
    let before = e.clone();
    assert_eq!(e.add_scan(&[(0, 0.5), (1, 0.5)], &[(key(2), -60.0)], wifi), Err(EvidenceError::Overflow));
    assert_eq!(e, before);
}

#[test]
fn evidence_of_another_site_does_not_merge() {
    let (a, b) = (corridor(3), corridor(4));
    let mut e = Evidence::new(&a);
    let other = Evidence::new(&b);
    assert!(matches!(e.merge(&other), Err(EvidenceError::OtherSite { .. })));
    assert_eq!(Evidence::site_key(&a), Evidence::site_key(&corridor(3)));
}

#[test]
fn bytes_round_trip_and_hostile_bytes_are_typed_errors() {
    let site = corridor(40);
    let mut e = Evidence::new(&site);
    e.add_walk();
    for s in 0..30u32 {
        let readings = [(key(1), -50.0 - f64::from(s)), (key(2), -90.5), (beacon(4), -77.0)];
        e.add_scan(&[(s, 0.6), (s + 1, 0.3), (s + 9, 0.1)], &readings, [true, s % 2 == 0]).unwrap();
    }
    let bytes = e.to_bytes();
    assert_eq!(Evidence::from_bytes(&bytes).unwrap(), e);
    // Cut anywhere: refused.
    for n in 0..bytes.len() {
        assert!(Evidence::from_bytes(&bytes[..n]).is_err(), "cut at {n}");
    }
    // Any one byte changed: refused, by the checksum if nothing else.
    for i in 0..bytes.len() {
        let mut changed = bytes.clone();
        changed[i] ^= 0x5a;
        assert!(Evidence::from_bytes(&changed).is_err(), "byte {i}");
    }
    let mut newer = bytes.clone();
    newer[4..6].copy_from_slice(&(EVIDENCE_FORMAT_VERSION + 1).to_le_bytes());
    assert_eq!(
        Evidence::from_bytes(&newer),
        Err(EvidenceError::NewerFormat {
            found: EVIDENCE_FORMAT_VERSION + 1,
            supported: EVIDENCE_FORMAT_VERSION
        })
    );
    assert!(matches!(Evidence::from_bytes(b"{\"site\": 1}"), Err(EvidenceError::NotEvidence(_))));
    let mut trailing = bytes.clone();
    trailing.insert(bytes.len() - 4, 0);
    assert!(Evidence::from_bytes(&trailing).is_err());
}

#[test]
fn a_walk_minute_of_evidence_is_small() {
    // A minute of scans every 2 s, each hearing 40 access points, its posterior over 20
    // states moving along a corridor: the evidence of the minute in bytes.
    let site = corridor(200);
    let mut e = Evidence::new(&site);
    for scan in 0..30u32 {
        let posterior: Vec<(u32, f64)> = (0..20).map(|k| (scan * 3 + k, 0.05)).collect();
        let readings: Vec<(TransmitterKey, f64)> = (0..40).map(|t| (key(t), -50.0 - f64::from(t))).collect();
        e.add_scan(&posterior, &readings, [true, false]).unwrap();
    }
    let bytes = e.to_bytes().len();
    assert!(bytes < 50_000, "{bytes} bytes for a minute");
}

/// A scan as proptest draws it: (state, weight)s, (transmitter, quarter dBm)s, and whether it
/// listened for BLE too.
type DrawnScan = (Vec<(u32, u8)>, Vec<(u8, i16)>, bool);

/// Evidence from a few drawn scans, each one's weights scaled to sum to at most 1.
fn evidence_of(scans: &[DrawnScan]) -> Evidence {
    let site = corridor(16);
    let mut e = Evidence::new(&site);
    for (posterior, readings, ble) in scans {
        let total: f64 = posterior.iter().map(|&(_, w)| f64::from(w)).sum::<f64>().max(1.0);
        let posterior: Vec<(u32, f64)> =
            posterior.iter().map(|&(s, w)| (s % 16, f64::from(w) / total)).collect();
        let readings: Vec<(TransmitterKey, f64)> = readings
            .iter()
            .map(|&(t, r)| (if t % 3 == 0 { beacon(u16::from(t)) } else { key(t) }, f64::from(r) / 4.0))
            .collect();
        e.add_scan(&posterior, &readings, [true, *ble]).unwrap();
    }
    e.add_walk();
    e
}

fn scans() -> impl Strategy<Value = Vec<DrawnScan>> {
    let scan = (
        prop::collection::vec((0u32..16, 0u8..=255), 0..6),
        prop::collection::vec((0u8..12, -480i16..-120), 0..8),
        any::<bool>(),
    );
    prop::collection::vec(scan, 0..6)
}

proptest! {
    /// Merging is associative and commutative exactly: the same bytes in any order.
    #[test]
    fn merging_is_associative_and_commutative(a in scans(), b in scans(), c in scans()) {
        let (a, b, c) = (evidence_of(&a), evidence_of(&b), evidence_of(&c));
        let mut ab_c = a.clone();
        ab_c.merge(&b).unwrap();
        ab_c.merge(&c).unwrap();
        let mut bc = b.clone();
        bc.merge(&c).unwrap();
        let mut a_bc = a.clone();
        a_bc.merge(&bc).unwrap();
        let mut cba = c.clone();
        cba.merge(&b).unwrap();
        cba.merge(&a).unwrap();
        prop_assert_eq!(ab_c.to_bytes(), a_bc.to_bytes());
        prop_assert_eq!(ab_c.to_bytes(), cba.to_bytes());
        prop_assert_eq!(ab_c.walks(), 3);
        prop_assert_eq!(Evidence::from_bytes(&ab_c.to_bytes()).unwrap(), ab_c);
    }

    /// A walk's scans added one by one are the merge of the scans' own evidence.
    #[test]
    fn adding_scans_is_merging_them(a in scans(), b in scans()) {
        let mut both = a.clone();
        both.extend(b.iter().cloned());
        let mut merged = evidence_of(&a);
        merged.merge(&evidence_of(&b)).unwrap();
        let mut whole = evidence_of(&both);
        whole.add_walk();
        prop_assert_eq!(whole, merged);
    }

    /// Any bytes at all: evidence or a typed error, never a panic.
    #[test]
    fn any_bytes_are_evidence_or_an_error(bytes in prop::collection::vec(any::<u8>(), 0..200)) {
        let mut with_magic = b"WMEV\x01\x00".to_vec();
        with_magic.extend_from_slice(&bytes);
        let _ = Evidence::from_bytes(&bytes);
        let _ = Evidence::from_bytes(&with_magic);
    }
}

#[test]
fn a_scan_keeps_its_most_probable_states_at_their_probabilities() {
    let posterior = [(7, 0.1), (3, 0.4), (9, 0.2), (1, 0.2), (4, 0.1)];
    let mut kept = Vec::new();
    // The mode alone, at its probability.
    most_probable(&posterior, 1.0, 1, &mut kept);
    assert_eq!(kept, [(3, 0.4)]);
    // Two states: a tie at 0.2 goes to the lower state, on every machine.
    most_probable(&posterior, 1.0, 2, &mut kept);
    assert_eq!(kept, [(3, 0.4), (1, 0.2)]);
    // The fewest holding 70% of the mass, however many states that takes.
    most_probable(&posterior, 0.7, 0, &mut kept);
    assert_eq!(kept, [(3, 0.4), (1, 0.2), (9, 0.2)]);
    // No limit: the posterior as it is.
    most_probable(&posterior, 1.0, 0, &mut kept);
    assert_eq!(kept, posterior);
    most_probable(&[], 1.0, 1, &mut kept);
    assert!(kept.is_empty());
}
