//! The radio map: storage, construction and scoring against the dense eqs. 9-10.

use super::*;
use crate::radio::{Reading, Scan};
use approx::assert_relative_eq;

fn wifi(i: u8) -> TransmitterId {
    TransmitterId::wifi(&format!("00:00:00:00:00:{i:02x}")).unwrap()
}

fn g(mean: f64, std: f64) -> Gaussian {
    Gaussian::new(mean, std).unwrap()
}

fn small_map(model: RssiModel) -> RadioMap {
    // Two states, three transmitters; state 1 never heard transmitter 2.
    let fingerprints = vec![
        (0, 0, g(-60.0, 4.0)),
        (0, 1, g(-80.0, 5.0)),
        (0, 2, g(-95.0, 6.0)),
        (1, 0, g(-75.0, 3.0)),
        (1, 1, g(-65.0, 4.0)),
    ];
    RadioMap::new(model, -100.0, g(-115.0, 5.0), vec![wifi(0), wifi(1), wifi(2)], 2, fingerprints).unwrap()
}

/// The dense product of eq. 9 over every transmitter, as a reference.
fn brute_force(map: &RadioMap, heard: &[(u32, f64)], state: u32) -> f64 {
    let model_of = |t: u32| {
        map.fingerprints().find(|&(s, tx, _)| s == state && tx == t).map_or(map.unheard(), |(_, _, g)| g)
    };
    let scanned = |t: u32| {
        let k = kind(&map.transmitters()[t as usize]);
        heard.iter().any(|h| kind(&map.transmitters()[h.0 as usize]) == k)
    };
    (0..map.transmitters().len() as u32)
        .map(|t| match heard.iter().find(|h| h.0 == t) {
            Some(&(_, rssi)) => map.model().ln_heard(&model_of(t), rssi, -100.0),
            None if scanned(t) => map.model().ln_absent(&model_of(t), -100.0),
            None => 0.0,
        } * map.weights[t as usize])
        .sum()
}

#[test]
fn the_networks_of_one_radio_count_as_one_transmitter() {
    // Transmitters 1 and 2 are one radio: the same model wherever either is modelled.
    let one =
        vec![(0, 0, g(-60.0, 4.0)), (0, 1, g(-80.0, 5.0)), (1, 0, g(-75.0, 3.0)), (1, 1, g(-65.0, 4.0))];
    let two: Vec<_> =
        one.iter().copied().chain(one.iter().filter(|e| e.1 == 1).map(|e| (e.0, 2, e.2))).collect();
    let alone =
        RadioMap::new(RssiModel::CensoredGaussian, -100.0, g(-115.0, 5.0), vec![wifi(0), wifi(1)], 2, one)
            .unwrap();
    let shared = RadioMap::new(
        RssiModel::CensoredGaussian,
        -100.0,
        g(-115.0, 5.0),
        vec![wifi(0), wifi(1), wifi(2)],
        2,
        two,
    )
    .unwrap()
    .with_shared_radios(vec![vec![1, 2]])
    .unwrap();
    for (heard, twice) in [
        (vec![(0, -62.0), (1, -70.0)], vec![(0, -62.0), (1, -70.0), (2, -70.0)]),
        (vec![(0, -62.0)], vec![(0, -62.0)]),
    ] {
        let (mut a, mut b) = (vec![0.0; 2], vec![0.0; 2]);
        assert_relative_eq!(
            alone.ln_likelihood(&heard, &mut a),
            shared.ln_likelihood(&twice, &mut b),
            epsilon = 1e-9
        );
        for s in 0..2 {
            assert_relative_eq!(a[s], b[s], epsilon = 1e-9);
        }
        assert_relative_eq!(alone.radios_heard(&heard), shared.radios_heard(&twice));
    }
    assert_eq!(shared.shared_radios(), [vec![1, 2]]);
}

#[test]
fn shared_radios_must_name_two_or_more_existing_transmitters_once() {
    let map = || small_map(RssiModel::CensoredGaussian);
    assert!(map().with_shared_radios(vec![vec![0]]).unwrap_err().contains("two or more"));
    assert!(map().with_shared_radios(vec![vec![0, 3]]).unwrap_err().contains("does not exist"));
    assert!(map().with_shared_radios(vec![vec![0, 1], vec![1, 2]]).unwrap_err().contains("in two radios"));
    assert!(map().with_shared_radios(vec![vec![0, 0]]).unwrap_err().contains("in two radios"));
    let plain = map().with_shared_radios(Vec::new()).unwrap();
    assert_eq!(plain.radios_heard(&[(0, -60.0), (1, -70.0)]), 2.0);
}

#[test]
fn silent_states_model_none_of_the_transmitters_heard() {
    let map = small_map(RssiModel::CensoredGaussian);
    let silent = |heard: &[(u32, f64)]| {
        let mut out = vec![0.0; 2];
        map.ln_likelihood(heard, &mut out);
        map.silent_states(heard, &out).collect::<Vec<_>>()
    };
    // State 1 never heard transmitter 2; both model 0 and 1.
    assert_eq!(silent(&[(2, -92.0)]), [false, true]);
    assert_eq!(silent(&[(0, -62.0), (2, -92.0)]), [false, false]);
    // At the clip level a reading changes no state's likelihood: nobody speaks to it.
    assert_eq!(silent(&[(2, -100.0)]), [true, true]);
}

/// With every transmitter a radio of its own, and with 0 and 2 one radio (each weighing
/// one half in the product).
#[test]
fn sparse_likelihood_equals_dense_product() {
    for model in [RssiModel::CensoredGaussian, RssiModel::NaiveGaussian] {
        let grouped = small_map(model).with_shared_radios(vec![vec![0, 2]]).unwrap();
        assert_eq!(grouped.weights, [0.5, 1.0, 0.5]);
        for (map, heard) in [small_map(model), grouped].iter().flat_map(|map| {
            [vec![(0, -62.0), (1, -79.0)], vec![(2, -92.0)], vec![(0, -100.0), (2, -99.0)], vec![]]
                .map(|heard| (map, heard))
        }) {
            let mut out = vec![0.0; 2];
            let unheard = map.ln_likelihood(&heard, &mut out);
            // Each heard transmitter's ln p(absent) comes from the table (≤ 2e-6 off).
            for s in 0..2 {
                assert_relative_eq!(out[s as usize], brute_force(map, &heard, s), epsilon = 1e-5);
            }
            // A state the map has no fingerprint for (there is no state 9).
            assert_relative_eq!(unheard, brute_force(map, &heard, 9), epsilon = 1e-9);
        }
    }
}

#[test]
fn a_beacon_scan_says_nothing_about_access_points() {
    let beacon = TransmitterId::ble_address("e0:78:a3:3d:b5:d6").unwrap();
    let fingerprints = vec![(0, 0, g(-60.0, 4.0)), (1, 1, g(-70.0, 4.0)), (1, 0, g(-90.0, 4.0))];
    let map = RadioMap::new(
        RssiModel::CensoredGaussian,
        -100.0,
        g(-115.0, 5.0),
        vec![wifi(0), beacon],
        2,
        fingerprints,
    )
    .unwrap();
    for heard in [vec![(1, -72.0)], vec![(0, -61.0)], vec![(0, -61.0), (1, -72.0)]] {
        let mut out = vec![0.0; 2];
        let unheard = map.ln_likelihood(&heard, &mut out);
        assert_relative_eq!(unheard, brute_force(&map, &heard, 9), epsilon = 1e-9);
        for s in 0..2 {
            assert_relative_eq!(out[s as usize], brute_force(&map, &heard, s), epsilon = 1e-9);
        }
    }
    // Heard only the beacon: the access point's absence is not evidence.
    let mut out = vec![0.0; 2];
    map.ln_likelihood(&[(1, -72.0)], &mut out);
    let only_beacon = |m: &Gaussian| map.model().ln_heard(m, -72.0, -100.0);
    assert_relative_eq!(out[1], only_beacon(&g(-70.0, 4.0)), epsilon = 1e-12);
}

#[test]
fn likelihood_by_hand() {
    // State 0 hears transmitter 0 at -60 exactly at its mean; 1 and 2 are absent.
    let map = small_map(RssiModel::CensoredGaussian);
    let mut out = vec![0.0; 2];
    map.ln_likelihood(&[(0, -60.0)], &mut out);
    let ln_pdf_at_mean = -(4.0 * (2.0 * std::f64::consts::PI).sqrt()).ln();
    // Transmitter 1 below -100 with μ -80, σ 5: Φ(-4); transmitter 2 with μ -95, σ 6: Φ(-5/6).
    let expected = ln_pdf_at_mean + 3.167_124_183_311_992e-5f64.ln() + 0.202_328_380_963_643_03f64.ln();
    // Transmitter 0's ln p(absent) is tabled (≤ 2e-6 off).
    assert_relative_eq!(out[0], expected, epsilon = 1e-5);
}

#[test]
fn layouts_fit_the_map_and_round_trip() {
    // Means over the whole i16 range and 65 536 spreads leave no bits for the step.
    let full = Layout::fit(-32_767, 32_767, 65_536);
    assert_eq!(full.step_mask, 0);
    assert_eq!(full.encode(1, 5, 7), None);
    let word = full.encode(0, -32_767, 65_535).unwrap();
    assert_eq!(full.decode(word), (0, -32_767, 65_535));
    // One mean and one spread: the step has every bit.
    let single = Layout::fit(-6000, -6000, 1);
    let word = single.encode(u32::MAX, -6000, 0).unwrap();
    assert_eq!(single.decode(word), (u32::MAX as usize, -6000, 0));
    let mall = Layout::fit(-11_250, -3_943, 697);
    assert_eq!(mall.step_mask, 511);
    let word = mall.encode(511, -3_943, 696).unwrap();
    assert_eq!(mall.decode(word), (511, -3_943, 696));
    assert_eq!(mall.encode(512, -3_943, 696), None);
}

/// Means far apart and many spreads leave a few bits of step, so entries far apart in
/// state start runs: the map still returns every model and scores as the dense product.
#[test]
fn entries_far_apart_start_runs() {
    let states = 3000;
    // 503 spreads (9 bits) and means 600 dB apart (16 bits) leave 7 bits of step.
    let fingerprints: Vec<(u32, u32, Gaussian)> = (0..states)
        .filter(|s| (s % 3 == 0 && *s < 1500) || [2000, 2500, 2999].contains(s))
        .flat_map(|s| {
            let mean = if s % 2 == 0 { -300.0 + f64::from(s % 50) } else { 300.0 - f64::from(s % 13) };
            let std = 1.0 + 0.01 * f64::from(s / 3);
            [(s, 0, g(mean, std)), (s, 1, g(mean / 3.0, std))]
        })
        .collect();
    let map = RadioMap::new(
        RssiModel::CensoredGaussian,
        -100.0,
        g(-115.0, 5.0),
        vec![wifi(0), wifi(1)],
        states as usize,
        fingerprints.clone(),
    )
    .unwrap();
    assert_eq!(map.layout.step_mask, 127);
    // Per transmitter, the first entry and the three after a gap of 500.
    assert_eq!(map.runs.len(), 2 * 4 + 1);
    let mut stored: Vec<(u32, u32, Gaussian)> = map.fingerprints().collect();
    stored.sort_by_key(|e| (e.0, e.1));
    assert_eq!(stored.len(), fingerprints.len());
    for (a, b) in stored.iter().zip(&fingerprints) {
        assert_eq!((a.0, a.1), (b.0, b.1));
        assert_relative_eq!(a.2.mean_dbm, b.2.mean_dbm, epsilon = 0.005);
        assert_relative_eq!(a.2.std_db, b.2.std_db, epsilon = 0.005);
    }
    let heard = [(0, -90.0), (1, -40.0)];
    let mut out = vec![0.0; states as usize];
    map.ln_likelihood(&heard, &mut out);
    for s in [0, 3, 4, 1497, 2000, 2500, 2999] {
        assert_relative_eq!(out[s as usize], brute_force(&map, &heard, s), epsilon = 1e-5);
    }
}

#[test]
fn resolve_drops_unknown_duplicate_and_stale() {
    let map = small_map(RssiModel::CensoredGaussian);
    let reading = |t: u8, rssi: f64, age_ns: u64| Reading { transmitter: wifi(t), rssi_dbm: rssi, age_ns };
    let scan = Scan {
        timestamp_ns: 1,
        readings: vec![
            reading(0, -70.0, 5),
            reading(0, -65.0, 0),
            reading(9, -50.0, 0),
            reading(1, -80.0, 10_000_000_000),
        ],
    };
    let r = map.resolve(&scan, Some(1_000_000_000));
    assert_eq!(r.observations, vec![(0, -65.0)]);
    assert_eq!((r.unknown, r.duplicates, r.stale), (1, 1, 1));
}

/// Transmitters listed in any order are found by their own index, and a reading of one the
/// map does not list is counted as unknown.
#[test]
fn resolve_finds_transmitters_listed_out_of_order() {
    let ble = TransmitterId::BleAddress { mac: "00:00:00:00:00:03".into() };
    let ids = vec![wifi(9), ble.clone(), wifi(2), wifi(5), wifi(0)];
    let map = RadioMap::new(RssiModel::CensoredGaussian, -100.0, g(-115.0, 5.0), ids.clone(), 1, []).unwrap();
    let readings: Vec<Reading> = (ids.iter().chain([&wifi(3)]))
        .enumerate()
        .map(|(k, id)| Reading { transmitter: id.clone(), rssi_dbm: -50.0 - k as f64, age_ns: 0 })
        .collect();
    let r = map.resolve(&Scan { timestamp_ns: 1, readings }, None);
    assert_eq!(r.observations, [(0, -50.0), (1, -51.0), (2, -52.0), (3, -53.0), (4, -54.0)]);
    assert_eq!((r.unknown, r.duplicates, r.stale), (1, 0, 0));
}

#[test]
fn rejects_bad_tables() {
    let dup =
        RadioMap::new(RssiModel::CensoredGaussian, -100.0, g(-115.0, 5.0), vec![wifi(0), wifi(0)], 1, []);
    assert!(dup.unwrap_err().contains("twice"));
    let oob = RadioMap::new(
        RssiModel::CensoredGaussian,
        -100.0,
        g(-115.0, 5.0),
        vec![wifi(0)],
        1,
        [(3, 0, g(-1.0, 1.0))],
    );
    assert!(oob.unwrap_err().contains("out of range"));
}

#[test]
fn the_offset_measured_with_the_likelihood_is_the_offset_measured_apart() {
    for model in [RssiModel::CensoredGaussian, RssiModel::NaiveGaussian] {
        let map = small_map(model);
        let belief = [0.7, 0.3];
        // Raw readings, and as a device offset of +3 dB corrected them: the one at -98 dBm
        // falls to the clip level, the one at -101 dBm (not heard raw) stays below it.
        let raw = [(0, -62.0), (1, -79.0), (2, -98.0), (1, -101.0)];
        let corrected: Vec<(u32, f64)> = raw.iter().map(|&(t, rssi)| (t, rssi - 3.0)).collect();
        for offset_db in [-4.0, 0.0, 3.0] {
            let mut apart = vec![0.0; 2];
            let unheard_apart = map.ln_likelihood(&corrected, &mut apart);
            let mut together = vec![0.0; 2];
            let (unheard, moments) =
                map.ln_likelihood_and_moments(&corrected, Some((&raw[..], &belief[..])), &mut together);
            assert_eq!((together, unheard), (apart, unheard_apart));
            // One per raw reading, for those heard above the clip level.
            assert_eq!(moments.iter().map(Option::is_some).collect::<Vec<_>>(), [true, true, true, false]);
            let measured = map.offset_from_moments(&raw, &moments, offset_db);
            assert_eq!(measured, map.offset_residual(&raw, &belief, offset_db));
            assert!(measured.is_some());
        }
        // Raw readings that do not follow the corrected ones are still measured.
        let mut out = vec![0.0; 2];
        let (_, moments) =
            map.ln_likelihood_and_moments(&corrected[..1], Some((&raw[..], &belief[..])), &mut out);
        assert_eq!(map.offset_from_moments(&raw, &moments, 0.0), map.offset_residual(&raw, &belief, 0.0));
    }
}
