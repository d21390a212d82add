use super::*;
use crate::io::Waypoint;
use waymark_engine::radio::TransmitterId;
use waymark_engine::site::StateKind;

fn walk(name: &str, from: (f64, f64), to: (f64, f64), seconds: u64) -> Trace {
    let ns = 1_000_000_000u64;
    let ap = |k: u8| TransmitterId::wifi(&format!("aa:bb:cc:dd:ee:{k:02x}")).unwrap();
    let mut trace = Trace { name: name.into(), ..Trace::default() };
    trace.waypoints = vec![
        Waypoint { timestamp_ns: 0, x: from.0, y: from.1, floor: None },
        Waypoint { timestamp_ns: seconds * ns, x: to.0, y: to.1, floor: None },
    ];
    for t in 1..seconds {
        let f = t as f64 / seconds as f64;
        let x = from.0 + f * (to.0 - from.0);
        // Two APs at x = 0 and x = 20 with a 2 dB/m slope, and one stale entry.
        trace.wifi_scans.push(Scan {
            timestamp_ns: t * ns,
            readings: vec![
                Reading { transmitter: ap(1), rssi_dbm: -40.0 - 2.0 * x, age_ns: 0 },
                Reading { transmitter: ap(2), rssi_dbm: -40.0 - 2.0 * (20.0 - x).abs(), age_ns: 0 },
                Reading { transmitter: ap(3), rssi_dbm: -50.0, age_ns: 10 * ns },
            ],
        });
    }
    trace
}

#[test]
fn floor_ranks() {
    assert_eq!(floor_rank("B1"), Some(-1));
    assert_eq!(floor_rank("F1"), Some(0));
    assert_eq!(floor_rank("F4"), Some(3));
    assert_eq!(floor_rank("2F"), Some(1));
    assert_eq!(floor_rank("lobby"), None);
}

#[test]
fn states_sit_on_the_grid_along_the_walks_with_fitted_fingerprints() {
    let walks = [walk("a", (0.0, 1.0), (20.0, 1.0), 20), walk("b", (20.0, 1.0), (0.0, 1.0), 20)];
    let floor = SurveyFloor { name: "F1".into(), plan: None, walks: walks.iter().collect(), geo: None };
    let (site, report) = survey("test", &[floor], North::default(), &SurveyOptions::default()).unwrap();
    assert_eq!(report.floors[0].walks, 2);
    assert_eq!(report.floors[0].scans, 38);
    assert!(site.states().iter().all(|s| (s.position.x / 2.0).fract() == 0.0));
    let surveyed = || site.states().iter().filter(|s| s.kind == StateKind::Surveyed);
    assert!(surveyed().all(|s| (s.position.y - 1.0).abs() <= 2.0));
    // The stale entry is never heard: the map knows only the two fresh APs.
    assert_eq!(report.transmitters, 2);
    // The state at x = 10 m heard AP 1 at about -60 dBm.
    let s10 = site.states().iter().position(|s| s.position == Point2::new(10.0, 0.0)).unwrap();
    let (_, _, g) = site.radio().fingerprints().find(|f| f.0 == s10 as u32 && f.1 == 0).unwrap();
    assert!((g.mean_dbm + 60.0).abs() < 3.0, "{g:?}");
    // A connected strip: every state has a neighbour.
    assert!((0..site.states().len()).all(|i| site.neighbours(i).len() > 0));
}

#[test]
fn walls_cut_edges_unless_somebody_walked_through() {
    // A wall at x = 9..11 m (a room polygon) across the strip; walk "a" only goes up to 8 m.
    let room = crate::io::floor_plan::Room {
        name: "shop".into(),
        polygon: crate::io::floor_plan::Polygon {
            rings: vec![vec![
                Point2::new(9.0, -10.0),
                Point2::new(11.0, -10.0),
                Point2::new(11.0, 10.0),
                Point2::new(9.0, 10.0),
            ]],
        },
    };
    let plan = FloorPlan {
        width_m: 40.0,
        height_m: 20.0,
        outline: vec![],
        rooms: vec![room],
        ..FloorPlan::default()
    };
    let walks = [walk("a", (0.0, 0.0), (8.0, 0.0), 8), walk("b", (12.0, 0.0), (20.0, 0.0), 8)];
    let floor =
        SurveyFloor { name: "F1".into(), plan: Some(&plan), walks: walks.iter().collect(), geo: None };
    let (site, report) = survey(
        "test",
        &[floor],
        North::default(),
        &SurveyOptions { walls: true, ..SurveyOptions::default() },
    )
    .unwrap();
    assert!(report.floors[0].walled_edges > 0);
    assert_eq!(report.floors[0].walked_edges, 0);
    let left = site.states().iter().position(|s| s.position == Point2::new(8.0, 0.0)).unwrap();
    assert!(site.neighbours(left).all(|(n, _)| site.states()[n as usize].position.x <= 8.0));
    // Walking through the wall (here, through the whole room) opens it.
    let walks = [walk("c", (0.0, 0.0), (20.0, 0.0), 20)];
    let floor =
        SurveyFloor { name: "F1".into(), plan: Some(&plan), walks: walks.iter().collect(), geo: None };
    let (_, report) = survey(
        "test",
        &[floor],
        North::default(),
        &SurveyOptions { walls: true, ..SurveyOptions::default() },
    )
    .unwrap();
    assert_eq!(report.floors[0].open_rooms, 1);
    assert_eq!(report.floors[0].walled_edges, 0);
}

#[test]
fn named_plan_polygons_become_zones() {
    let rect = |name: &str, x0: f64, x1: f64| crate::io::floor_plan::Room {
        name: name.into(),
        polygon: crate::io::floor_plan::Polygon {
            rings: vec![vec![
                Point2::new(x0, -10.0),
                Point2::new(x1, -10.0),
                Point2::new(x1, 10.0),
                Point2::new(x0, 10.0),
            ]],
        },
    };
    let rooms = vec![
        rect("kiosk", -1.0, 5.0),
        rect("", 5.0, 9.0),
        rect("kiosk", 9.0, 13.0),
        rect("shop", 13.0, 30.0),
        rect("far", 50.0, 60.0),
    ];
    let plan = FloorPlan { width_m: 60.0, height_m: 20.0, outline: vec![], rooms, ..FloorPlan::default() };
    let walks = [walk("a", (0.0, 0.0), (20.0, 0.0), 20)];
    let floor =
        SurveyFloor { name: "F1".into(), plan: Some(&plan), walks: walks.iter().collect(), geo: None };
    // The unsurveyed states around the walk join the polygons they are in, too.
    let options = SurveyOptions { unsurveyed_margin_m: 6.0, ..SurveyOptions::default() };
    let (site, report) = survey("test", &[floor], North::default(), &options).unwrap();
    assert!(site.states().iter().any(|s| s.kind == StateKind::Unsurveyed && s.position.x > 20.0));
    let names: Vec<&str> = site.zones().iter().map(|z| z.name.as_str()).collect();
    assert_eq!(names, ["F1/kiosk #1", "F1/kiosk #2", "F1/shop"], "no zone for the unnamed or empty polygon");
    assert_eq!(report.floors[0].zones, 3);
    for (i, s) in site.states().iter().enumerate() {
        let expected = match s.position.x {
            x if x < -1.0 => None,
            x if x < 5.0 => Some(0),
            x if x < 9.0 => None,
            x if x < 13.0 => Some(1),
            _ => Some(2),
        };
        assert_eq!(site.zone_of(i), expected, "state at {}", s.position);
    }
    let zoned = (0..site.states().len()).filter(|&i| site.zone_of(i).is_some()).count();
    assert_eq!(report.floors[0].zoned_states, zoned);
    // Without a plan, no zones.
    let floor = SurveyFloor { name: "F1".into(), plan: None, walks: walks.iter().collect(), geo: None };
    assert!(survey("test", &[floor], North::default(), &SurveyOptions::default())
        .unwrap()
        .0
        .zones()
        .is_empty());
}

#[test]
fn a_site_without_a_walk_reusing_fits_is_the_survey_without_it() {
    let mut weak = walk("d", (10.0, -4.0), (10.0, 10.0), 14);
    // The weakest WiFi reading of all: leaving "d" out moves the clip level.
    weak.wifi_scans[3].readings.push(Reading {
        transmitter: TransmitterId::wifi("aa:bb:cc:dd:ee:44").unwrap(),
        rssi_dbm: -99.0,
        age_ns: 0,
    });
    let walks = [
        walk("a", (0.0, 1.0), (20.0, 1.0), 20),
        walk("b", (20.0, 1.0), (0.0, 1.0), 20),
        walk("c", (0.0, 7.0), (16.0, 7.0), 16),
        weak,
        walk("e", (22.0, 0.0), (28.0, 0.0), 6),
    ];
    let floors = [
        SurveyFloor { name: "F1".into(), plan: None, walks: walks[..4].iter().collect(), geo: None },
        SurveyFloor {
            name: "F2".into(),
            plan: None,
            walks: vec![&walks[0], &walks[1], &walks[4]],
            geo: None,
        },
    ];
    let options = SurveyOptions::default();
    let prepared = PreparedSurvey::new("test", &floors, North::default(), &options).unwrap();
    let all = prepared.fit(&|_, _| true, None, 2);
    assert_eq!(all.refitted(), all.states());
    let (full, _) = prepared.assemble(&all).unwrap();
    let (direct, _) = survey("test", &floors, North::default(), &options).unwrap();
    assert_eq!(full.to_json(), direct.to_json());
    for (f, out) in [(0, 0), (0, 2), (0, 3), (1, 1), (1, 2)] {
        let keep = |ff: usize, w: usize| !(ff == f && w == out);
        let fits = prepared.fit(&keep, Some(&all), 1);
        let (incremental, _) = prepared.assemble(&fits).unwrap();
        let without: Vec<SurveyFloor> = floors
            .iter()
            .enumerate()
            .map(|(ff, floor)| SurveyFloor {
                walks: floor
                    .walks
                    .iter()
                    .enumerate()
                    .filter(|(w, _)| keep(ff, *w))
                    .map(|(_, t)| *t)
                    .collect(),
                ..floor.clone()
            })
            .collect();
        let (rebuilt, _) = survey("test", &without, North::default(), &options).unwrap();
        assert_eq!(incremental.to_json(), rebuilt.to_json(), "without floor {f} walk {out}");
        assert!(incremental.states().len() <= full.states().len());
        if (f, out) == (0, 3) {
            // The clip level moved: every state is fitted again.
            assert!(incremental.radio().clip_dbm() > full.radio().clip_dbm());
            assert_eq!(fits.refitted(), fits.states());
        } else {
            assert!(fits.refitted() > 0 && fits.refitted() < fits.states(), "{}", fits.refitted());
        }
    }
    // Walk "c" alone covered y = 7 away from "d" (x = 10): its states go with it.
    let fits = prepared.fit(&|f, w| !(f == 0 && w == 2), Some(&all), 1);
    let (without_c, _) = prepared.assemble(&fits).unwrap();
    let high = |site: &Site| {
        let surveyed = |s: &&waymark_engine::site::State| s.kind == StateKind::Surveyed;
        site.states()
            .iter()
            .filter(surveyed)
            .filter(|s| s.floor == 0 && s.position.y > 5.0 && s.position.x < 6.0)
            .count()
    };
    assert!(high(&full) > 0);
    assert_eq!(high(&without_c), 0);
}

/// Unsurveyed states fill the floor within the margin of the surveyed ones and nowhere
/// else: no fingerprint, joined to the grid, off the plan's outline never; the JSON site
/// file keeps them; the radio gives each what a state that never heard anything scores.
#[test]
fn unsurveyed_states_fill_the_floor_within_the_margin() {
    use crate::io::floor_plan::Polygon;
    let walks = [walk("a", (0.0, 0.0), (20.0, 0.0), 20)];
    // The floor ends 4 m beyond the walk's end: x from -30 to 24 m, y from -30 to 30 m.
    let outline = Polygon {
        rings: vec![vec![
            Point2::new(-30.0, -30.0),
            Point2::new(24.0, -30.0),
            Point2::new(24.0, 30.0),
            Point2::new(-30.0, 30.0),
        ]],
    };
    let plan = FloorPlan {
        width_m: 54.0,
        height_m: 60.0,
        outline: vec![outline],
        rooms: vec![],
        ..FloorPlan::default()
    };
    let floor =
        SurveyFloor { name: "F1".into(), plan: Some(&plan), walks: walks.iter().collect(), geo: None };
    let options = SurveyOptions { unsurveyed_margin_m: 8.0, ..SurveyOptions::default() };
    let (site, report) = survey("test", std::slice::from_ref(&floor), North::default(), &options).unwrap();
    let (surveyed, unsurveyed): (Vec<_>, Vec<_>) =
        site.states().iter().partition(|s| s.kind == StateKind::Surveyed);
    assert_eq!(report.floors[0].unsurveyed_states, unsurveyed.len());
    assert_eq!(report.floors[0].states, surveyed.len());
    assert!(!unsurveyed.is_empty());
    let distance =
        |p: Point2<f64>| surveyed.iter().map(|s| (s.position - p).norm()).fold(f64::INFINITY, f64::min);
    for s in &unsurveyed {
        assert!(distance(s.position) <= 8.0 + 1e-9 && s.position.x <= 24.0, "{:?}", s.position);
        assert_eq!(s.training_scans, 0);
        assert!(site.neighbours(s.id as usize).len() > 0);
    }
    // West of the walk, where the floor goes on, the margin is filled out to 8 m.
    assert!(unsurveyed.iter().any(|s| s.position == Point2::new(-8.0, 0.0)));
    assert!(site
        .radio()
        .fingerprints()
        .all(|(state, _, _)| site.states()[state as usize].kind == StateKind::Surveyed));
    // A scan's likelihood at an unsurveyed state is the no-fingerprint one.
    let resolved = site.radio().resolve(&walks[0].wifi_scans[5], None);
    let mut ln = vec![0.0; site.states().len()];
    let unheard = site.radio().ln_likelihood(&resolved.observations, &mut ln);
    assert!(unsurveyed.iter().all(|s| (ln[s.id as usize] - unheard).abs() < 1e-9));
    // Kept by the site file.
    let again = Site::from_json(site.to_json().as_bytes()).unwrap();
    assert_eq!(again.states(), site.states());
    // No margin, no unsurveyed states.
    let options = SurveyOptions { unsurveyed_margin_m: 0.0, ..SurveyOptions::default() };
    let (site, _) = survey("test", std::slice::from_ref(&floor), North::default(), &options).unwrap();
    assert!(site.states().iter().all(|s| s.kind == StateKind::Surveyed));
    let options = SurveyOptions { unsurveyed_margin_m: f64::NAN, ..SurveyOptions::default() };
    assert!(survey("test", &[floor], North::default(), &options).is_err());
}

#[test]
fn no_walks_is_a_typed_error() {
    let floor = SurveyFloor { name: "F1".into(), plan: None, walks: vec![], geo: None };
    assert!(survey("x", &[floor], North::default(), &SurveyOptions::default()).is_err());
}

/// The anchor is the first plan's south-west corner, scaled as that plan stretches its box;
/// every floor's origin is its own corner in that frame, and its level its `floor_num`.
#[test]
fn plans_geo_reference_the_site() {
    // 0.001° of longitude at 30°N is 96.49 m on the WGS84 ellipsoid, 0.001° of latitude 110.85 m.
    let plan = |lon: f64, lat: f64, level: i32| FloorPlan {
        width_m: 100.0,
        height_m: 100.0,
        lon_lat_box: Some([[lon, lat], [lon + 0.001, lat + 0.001]]),
        level: Some(level),
        ..FloorPlan::default()
    };
    let (b1, f1) = (plan(120.0, 30.0, -1), plan(120.0005, 30.0, 1));
    let (anchor, floors) = geo_reference(&[Some(&b1), Some(&f1)]);
    let anchor = anchor.expect("two plans with boxes");
    assert_eq!((anchor.lat_deg, anchor.lon_deg, anchor.azimuth_rad), (30.0, 120.0, 0.0));
    assert!((anchor.scale[0] - 0.9649).abs() < 1e-3 && (anchor.scale[1] - 1.1085).abs() < 1e-3, "{anchor:?}");
    assert_eq!((floors[0].0, floors[1].0), (Some(-1), Some(1)));
    assert_eq!(floors[0].1, [0.0, 0.0]);
    // Half the box east: 50 plan metres.
    assert!((floors[1].1[0] - 50.0).abs() < 1e-3 && floors[1].1[1].abs() < 1e-3, "{floors:?}");
    // A floor without a plan, or a plan without a box: levels only.
    let (none, floors) = geo_reference(&[Some(&b1), None]);
    assert!(none.is_none());
    assert_eq!(floors, vec![(Some(-1), [0.0, 0.0]), (None, [0.0, 0.0])]);
    let boxless = FloorPlan { lon_lat_box: None, ..b1.clone() };
    assert!(geo_reference(&[Some(&boxless)]).0.is_none());
}

/// Map evidence refits the labelled fingerprints (docs/evidence.md#refitting): none changes
/// nothing; evidence at a surveyed state pulls its fit by its weight against the labelled
/// scans'; an unsurveyed state with enough evidence gets fingerprints of its own; evidence of
/// another site is refused.
#[test]
fn evidence_refits_the_labelled_fingerprints() {
    use waymark_engine::evidence::{Evidence, TransmitterKey};
    let walks = [walk("a", (0.0, 1.0), (20.0, 1.0), 20)];
    let floors = [SurveyFloor { name: "F1".into(), plan: None, walks: walks.iter().collect(), geo: None }];
    let options = SurveyOptions::default();
    let prepared = PreparedSurvey::new("test", &floors, North::default(), &options).unwrap();
    let fits = prepared.fit(&|_, _| true, None, 1);
    let (site, _) = prepared.assemble(&fits).unwrap();
    let none = Evidence::new(&site);
    let (same, _) = prepared.assemble(&prepared.refit(&fits, &site, &none).unwrap()).unwrap();
    assert_eq!(same.to_json(), site.to_json());
    let ap1 = TransmitterKey::of(&TransmitterId::wifi("aa:bb:cc:dd:ee:01").unwrap());
    let at = |site: &Site, x: f64, y: f64| site.states().iter().position(|s| s.position == Point2::new(x, y));
    let model = |site: &Site, state: usize| {
        site.radio().fingerprints().find(|f| f.0 == state as u32 && f.1 == 0).map(|(_, _, g)| g)
    };
    let s10 = at(&site, 10.0, 0.0).unwrap();
    let before = model(&site, s10).unwrap();
    // As many scans of evidence at x = 10 as the labelled scans the state pools, 10 dB stronger.
    let labelled = site.states()[s10].training_scans;
    let mut e = Evidence::new(&site);
    for _ in 0..labelled {
        e.add_scan(&[(s10 as u32, 1.0)], &[(ap1, before.mean_dbm + 10.0)], [true, false]).unwrap();
    }
    let (refitted, _) = prepared.assemble(&prepared.refit(&fits, &site, &e).unwrap()).unwrap();
    let after = model(&refitted, at(&refitted, 10.0, 0.0).unwrap()).unwrap();
    assert!((after.mean_dbm - (before.mean_dbm + 5.0)).abs() < 1.0, "{before:?} → {after:?}");
    // An unsurveyed state beyond the walk's end, with two scans of evidence: fingerprinted.
    let beyond = site
        .states()
        .iter()
        .position(|s| s.kind == StateKind::Unsurveyed && s.position.x > 21.0)
        .expect("an unsurveyed state past x = 21 m");
    assert!(model(&site, beyond).is_none());
    let mut e = Evidence::new(&site);
    for _ in 0..2 {
        e.add_scan(&[(beyond as u32, 1.0)], &[(ap1, -75.0)], [true, false]).unwrap();
    }
    let (refitted, _) = prepared.assemble(&prepared.refit(&fits, &site, &e).unwrap()).unwrap();
    let p = site.states()[beyond].position;
    let now = at(&refitted, p.x, p.y).unwrap();
    assert_eq!(refitted.states()[now].kind, StateKind::Surveyed);
    assert!(
        model(&refitted, now).is_some_and(|g| (g.mean_dbm + 75.0).abs() < 0.5),
        "{:?}",
        model(&refitted, now)
    );
    // Evidence of another site.
    let (other, _) = survey(
        "other",
        &[SurveyFloor { walks: vec![&walks[0], &walks[0]], ..floors[0].clone() }],
        North::default(),
        &SurveyOptions { spacing_m: 1.0, coverage_m: 1.0, ..options.clone() },
    )
    .unwrap();
    assert!(prepared.refit(&fits, &site, &Evidence::new(&other)).is_err());
}

/// [`walk`] along x after the radio changed: AP 1 `shift_db` stronger, AP 2 gone unless `ap2`.
fn changed_walk(name: &str, shift_db: f64, ap2: bool) -> Trace {
    let mut trace = walk(name, (0.0, 1.0), (20.0, 1.0), 20);
    let ap = |k: u8| TransmitterId::wifi(&format!("aa:bb:cc:dd:ee:{k:02x}")).unwrap();
    for scan in &mut trace.wifi_scans {
        scan.readings.retain(|r| ap2 || r.transmitter != ap(2));
        for r in &mut scan.readings {
            if r.transmitter == ap(1) {
                r.rssi_dbm += shift_db;
            }
        }
    }
    trace
}

#[test]
fn newer_walks_replace_a_contradicted_fingerprint_and_keep_a_confirmed_one() {
    let walks = [
        walk("a", (0.0, 1.0), (20.0, 1.0), 20),
        changed_walk("b", 20.0, true),
        changed_walk("c", 0.0, false),
    ];
    let options = SurveyOptions::default();
    let survey_of = |kept: &[usize]| {
        let floors = [SurveyFloor {
            name: "F1".into(),
            plan: None,
            walks: kept.iter().map(|&k| &walks[k]).collect(),
            geo: None,
        }];
        let prepared = PreparedSurvey::new("test", &floors, North::default(), &options).unwrap();
        let fits = prepared.fit(&|_, _| true, None, 1);
        // Walk 0 is the labelled survey, the rest came after the radio changed.
        let (replaced, counts) = prepared.replace_contradicted(&fits, &|_, w| w > 0, &REPLACE_RULE);
        let site = |fits: &SurveyFits| prepared.assemble(fits).unwrap().0;
        (site(&fits), site(&replaced), counts)
    };
    let model = |site: &Site, ap: u32| {
        let s10 = site.states().iter().position(|s| s.position == Point2::new(10.0, 0.0)).unwrap();
        site.radio().fingerprints().find(|f| f.0 == s10 as u32 && f.1 == ap).map(|(_, _, g)| g)
    };
    // AP 1, 20 dB stronger in the newer walk: the pooled fit sits between the two, the replaced
    // one is the newer walk's own (-60 + 20 dBm at x = 10 m). AP 2 agrees: the pooled fit stays.
    let (pooled, replaced, counts) = survey_of(&[0, 1]);
    let (p1, r1) = (model(&pooled, 0).unwrap(), model(&replaced, 0).unwrap());
    assert!((p1.mean_dbm + 50.0).abs() < 3.0, "{p1:?}");
    assert!((r1.mean_dbm + 40.0).abs() < 3.0, "{r1:?}");
    assert_eq!(model(&pooled, 1), model(&replaced, 1));
    assert!(counts.replaced > 0 && counts.replaced < counts.tested, "{counts:?}");
    assert_eq!((counts.dropped, counts.vanished), (0, 0));
    // AP 2 never heard by the newer walk: gone from every state; AP 1 agrees and stays.
    let (pooled, replaced, counts) = survey_of(&[0, 2]);
    assert!(model(&pooled, 1).is_some());
    assert!(replaced.radio().fingerprints().all(|f| f.1 != 1));
    assert_eq!(model(&pooled, 0), model(&replaced, 0));
    assert_eq!(counts.vanished, 1);
    // The same walk again is no contradiction.
    let (pooled, replaced, counts) = survey_of(&[0, 0]);
    assert_eq!(pooled.to_json(), replaced.to_json());
    assert_eq!((counts.replaced, counts.vanished), (0, 0));
}
