//! WGS84 through the uniffi surface, from Rust (docs/zones.md#latitude-and-longitude): on the
//! simulated office anchored with a rotated, scaled frame, points, routes, zone outlines and
//! geofences in latitude/longitude come back to the metre ones within a centimetre, and bad
//! input is a typed error. The C surface's: bindings/c/test.c; Kotlin's and Swift's GeoTest.

use std::sync::{Arc, OnceLock};
use waymark as api;
use waymark_engine::site::{Anchor, Site};
use waymark_sim::{Office, OfficeConfig};

/// A centimetre, m: what a lat/lon round trip may move a point by (docs/zones.md).
const CM: f64 = 0.01;

fn office() -> &'static Site {
    static SITE: OnceLock<Site> = OnceLock::new();
    SITE.get_or_init(|| Office::generate(&OfficeConfig { training_scans: 5, ..OfficeConfig::default() }).site)
}

fn anchored() -> Arc<api::FfiSite> {
    let anchor = Anchor { lat_deg: 60.17, lon_deg: 24.94, azimuth_rad: 0.4, scale: [1.002, 0.998] };
    let site = office().clone().with_anchor(Some(anchor)).unwrap();
    api::FfiSite::from_bytes(site.to_json().into_bytes()).unwrap()
}

fn metres(site: &api::FfiSite, floor: u32, at: api::FfiLatLon) -> api::FfiFloorPoint {
    site.from_lat_lon(floor, at).unwrap()
}

fn near(a: &api::FfiFloorPoint, b: &api::FfiFloorPoint) -> bool {
    a.floor == b.floor && (a.x - b.x).hypot(a.y - b.y) < CM
}

#[test]
fn points_and_routes_convert_to_lat_lon_and_back_within_a_centimetre() {
    let site = anchored();
    assert!(site.is_geo_referenced());
    for (x, y) in [(0.0, 0.0), (35.5, 11.5), (-20.0, 400.0)] {
        let p = api::FfiFloorPoint { floor: 0, x, y };
        let back = metres(&site, 0, site.to_lat_lon(p).unwrap());
        assert!(near(&back, &p), "{p:?} came back as {back:?}");
    }
    // North of the origin by the frame's rotation: +y points 0.4 rad east of north.
    let up = site.to_lat_lon(api::FfiFloorPoint { floor: 0, x: 0.0, y: 100.0 }).unwrap();
    assert!(up.latitude_deg > 60.17 && up.longitude_deg > 24.94, "{up:?}");
    let route = site
        .route(
            api::FfiFloorPoint { floor: 0, x: 4.9, y: 2.0 },
            api::FfiDestination::Zone { name: "room 10".into() },
        )
        .unwrap();
    let legs = site.route_lat_lon(route.clone()).unwrap();
    assert_eq!(legs.len(), route.legs.len());
    for (geo, leg) in legs.iter().zip(&route.legs) {
        assert_eq!(geo.len(), leg.points.len());
        for (g, p) in geo.iter().zip(&leg.points) {
            let at = api::FfiLatLon { latitude_deg: g.latitude_deg, longitude_deg: g.longitude_deg };
            assert!(near(&metres(&site, g.floor, at), p), "{g:?} vs {p:?}");
        }
    }
}

#[test]
fn zone_outlines_hold_their_zones_states() {
    let site = anchored();
    let outlines = site.zone_outlines().unwrap();
    assert_eq!(outlines.iter().map(|z| z.name.clone()).collect::<Vec<_>>(), site.zone_names());
    for (z, outline) in outlines.iter().enumerate() {
        assert!(outline.outline.len() >= 3, "{outline:?}");
        let ring: Vec<[f64; 2]> = outline
            .outline
            .iter()
            .map(|p| {
                let m = metres(&site, outline.floor, *p);
                [m.x, m.y]
            })
            .collect();
        let fence = waymark_engine::Geofence {
            id: outline.name.clone(),
            floor: outline.floor as usize,
            shape: waymark_engine::GeofenceShape::Polygon { vertices: ring },
        };
        let inside = fence.states_inside(office()).unwrap();
        for s in &office().zones()[z].states {
            assert!(inside.binary_search(s).is_ok(), "{}: state {s} outside its outline", outline.name);
        }
    }
}

#[test]
fn a_lat_lon_geofence_is_the_metre_one() {
    let site = anchored();
    let square = [(30.0, 8.0), (40.0, 8.0), (40.0, 15.0), (30.0, 15.0)];
    let mut ring: Vec<api::FfiLatLon> = square
        .iter()
        .map(|&(x, y)| site.to_lat_lon(api::FfiFloorPoint { floor: 0, x, y }).unwrap())
        .collect();
    ring.push(ring[0]);
    let fence = site.geofence_from_lat_lon("hall".into(), 0, ring.clone()).unwrap();
    let api::FfiGeofenceShape::Polygon { vertices } = &fence.shape else { panic!("{fence:?}") };
    assert_eq!(vertices.len(), 4, "the closing vertex is dropped");
    for (v, (x, y)) in vertices.iter().zip(square) {
        assert!((v.x - x).hypot(v.y - y) < CM, "{v:?} vs ({x}, {y})");
    }
    for (g, want) in site.geofence_lat_lon(fence.clone()).unwrap().iter().zip(&ring) {
        assert!(near(&metres(&site, 0, *g), &metres(&site, 0, *want)));
    }
    // A circle's outline is a polygon on it.
    let circle = api::FfiGeofence {
        id: "c".into(),
        floor: 0,
        shape: api::FfiGeofenceShape::Circle { x: 35.0, y: 11.0, radius_m: 3.0 },
    };
    let outline = site.geofence_lat_lon(circle).unwrap();
    assert_eq!(outline.len(), waymark_engine::geofence::CIRCLE_OUTLINE_VERTICES);
    for p in outline {
        let m = metres(&site, 0, p);
        assert!(((m.x - 35.0).hypot(m.y - 11.0) - 3.0).abs() < CM, "{m:?}");
    }
    // The engine takes it, and holds the same states as the metre one.
    let engine = api::PositioningEngine::with_site(site.clone(), api::EngineOptions::default()).unwrap();
    engine.add_geofence(fence).unwrap();
    let in_metres = api::FfiGeofence {
        id: "metres".into(),
        floor: 0,
        shape: api::FfiGeofenceShape::Polygon {
            vertices: square.iter().map(|&(x, y)| api::SitePoint { x, y }).collect(),
        },
    };
    let (a, b) = (waymark_engine::Geofence::from(engine.geofences().unwrap()[0].clone()), in_metres);
    assert_eq!(
        a.states_inside(office()).unwrap(),
        waymark_engine::Geofence::from(b).states_inside(office()).unwrap()
    );
}

#[test]
fn bad_lat_lon_input_is_a_typed_error() {
    let site = anchored();
    let at = |x: f64, y: f64| site.to_lat_lon(api::FfiFloorPoint { floor: 0, x, y }).unwrap();
    let bowtie = vec![at(30.0, 8.0), at(40.0, 15.0), at(40.0, 8.0), at(30.0, 15.0)];
    assert!(matches!(
        site.geofence_from_lat_lon("b".into(), 0, bowtie),
        Err(api::FfiGeoError::InvalidGeofence { reason }) if reason.contains("self-intersection")
    ));
    let nan = api::FfiLatLon { latitude_deg: f64::NAN, longitude_deg: 24.94 };
    assert!(matches!(
        site.geofence_from_lat_lon("n".into(), 0, vec![at(30.0, 8.0), nan, at(40.0, 8.0)]),
        Err(api::FfiGeoError::InvalidGeofence { .. })
    ));
    assert!(matches!(site.from_lat_lon(0, nan), Err(api::FfiGeoError::InvalidCoordinate { .. })));
    assert!(matches!(site.from_lat_lon(9, at(0.0, 0.0)), Err(api::FfiGeoError::InvalidCoordinate { .. })));
    let bad = api::FfiFloorPoint { floor: 0, x: f64::INFINITY, y: 0.0 };
    assert!(matches!(site.to_lat_lon(bad), Err(api::FfiGeoError::InvalidCoordinate { .. })));
    assert!(matches!(
        site.geofence_from_lat_lon("far".into(), 0, vec![at(500.0, 500.0), at(510.0, 500.0), at(510.0, 510.0)]),
        Err(api::FfiGeoError::InvalidGeofence { reason }) if reason.contains("no state")
    ));
    let plain = api::FfiSite::from_bytes(office().to_json().into_bytes()).unwrap();
    assert!(!plain.is_geo_referenced());
    assert_eq!(
        plain.to_lat_lon(api::FfiFloorPoint { floor: 0, x: 1.0, y: 1.0 }),
        Err(api::FfiGeoError::NotGeoReferenced)
    );
    assert_eq!(plain.zone_outlines(), Err(api::FfiGeoError::NotGeoReferenced));
    assert_eq!(
        plain.geofence_from_lat_lon("p".into(), 0, vec![at(30.0, 8.0), at(40.0, 8.0), at(40.0, 15.0)]),
        Err(api::FfiGeoError::NotGeoReferenced)
    );
}
