//! A floor plan from the competition's GeoJSON (longitude/latitude) and `floor_info.json`
//! (width and height, m): the floor outline and its rooms (shops), mapped onto the metre
//! frame the waypoints use — the outline's bounding box stretched onto `[0, width] × [0,
//! height]`, x east, y north — and what geo-references it: that box in longitude/latitude,
//! and the floor's number (`floor_num`, -1 for B1) from the outline's properties.
//!
//! A plan is checked as it is read, and refused with the file and the field
//! (docs/surveying.md#floor-plans): sizes must be plausible and agree with the box's extent on
//! the ground, every coordinate a number within longitude/latitude range, every ring a shape
//! with an area that does not cross itself. The competition's five floors pass every check.

use nalgebra::Point2;
use serde_json::Value;
use std::path::Path;
use waymark_engine::site::{Anchor, LatLon, ZoneKind};

/// Smallest floor width or height a plan may give, m. The competition's floors are 176 to
/// 320 m across; a plan smaller than a room is a unit mistake (the width in km, or a
/// denormal: 1e-300 put the site's anchor scale at 3.7e301).
pub const MIN_FLOOR_SIZE_M: f64 = 1.0;

/// Largest floor width or height, m: the longest airport terminals are a few kilometres.
pub const MAX_FLOOR_SIZE_M: f64 = 10_000.0;

/// How many times larger or smaller than the ground extent of its longitude/latitude box a
/// plan's width and height may be: the competition's plans match theirs within 0.5%; a factor
/// of 2 is a plan whose size belongs to another drawing.
pub const MAX_SIZE_MISMATCH: f64 = 2.0;

/// Most corners in one ring: the competition's rings have at most 68. Bounds the time of the
/// self-crossing check, which compares every edge of a ring with every other.
pub const MAX_RING_POINTS: usize = 10_000;

/// A polygon with holes: rings of points, the first the outside. A point is inside when an
/// odd number of rings encloses it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Polygon {
    /// Closed rings (last point joins the first).
    pub rings: Vec<Vec<Point2<f64>>>,
}

impl Polygon {
    /// Whether `p` is inside (even-odd rule).
    pub fn contains(&self, p: Point2<f64>) -> bool {
        let mut inside = false;
        for ring in &self.rings {
            let n = ring.len();
            for i in 0..n {
                let (a, b) = (ring[i], ring[(i + 1) % n]);
                if (a.y > p.y) != (b.y > p.y) && p.x < a.x + (p.y - a.y) / (b.y - a.y) * (b.x - a.x) {
                    inside = !inside;
                }
            }
        }
        inside
    }

    /// The edges of every ring.
    pub fn edges(&self) -> impl Iterator<Item = (Point2<f64>, Point2<f64>)> + '_ {
        self.rings.iter().flat_map(|r| (0..r.len()).map(move |i| (r[i], r[(i + 1) % r.len()])))
    }

    /// Area, m² (outside ring minus holes).
    pub fn area(&self) -> f64 {
        let ring_area = |r: &Vec<Point2<f64>>| {
            (0..r.len())
                .map(|i| r[i].x * r[(i + 1) % r.len()].y - r[(i + 1) % r.len()].x * r[i].y)
                .sum::<f64>()
                / 2.0
        };
        let mut rings = self.rings.iter().map(|r| ring_area(r).abs());
        let outer = rings.next().unwrap_or(0.0);
        outer - rings.sum::<f64>()
    }
}

/// A named area of the floor (a shop, a lift lobby...).
#[derive(Clone, Debug, PartialEq)]
pub struct Room {
    /// The plan's `name` property.
    pub name: String,
    /// Its shape, m.
    pub polygon: Polygon,
}

/// One floor's plan in metres.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FloorPlan {
    /// Width (east-west extent), m.
    pub width_m: f64,
    /// Height (north-south extent), m.
    pub height_m: f64,
    /// The floor's outline (one or more polygons).
    pub outline: Vec<Polygon>,
    /// Rooms inside it.
    pub rooms: Vec<Room>,
    /// The longitude/latitude box stretched onto `[0, width] × [0, height]`: `[[west,
    /// south], [east, north]]`, degrees; `None` for a plan not read from GeoJSON.
    pub lon_lat_box: Option<[[f64; 2]; 2]>,
    /// The floor's logical level: the outline's `floor_num` property (-1 for B1, 1 for F1);
    /// `None` when the plan has none.
    pub level: Option<i32>,
    /// What kind of place each room is, by room index: empty for a plan that does not say
    /// (the competition's; every room is then [`ZoneKind::Room`]), else one per room (IMDF
    /// unit categories, [`crate::io::imdf`]).
    pub room_kinds: Vec<ZoneKind>,
    /// Doors, m: segments of a wall where walking through it is allowed (IMDF openings). A
    /// line that crosses a wall within [`DOOR_REACH_M`] of a door does not cross the wall.
    pub doors: Vec<[Point2<f64>; 2]>,
}

/// How near a wall crossing must be to a door to pass through it, m: an opening is drawn on
/// its wall, give or take the drawing's precision, and about as wide as the doorway.
pub const DOOR_REACH_M: f64 = 0.5;

impl FloorPlan {
    /// The plan's point (x, y), m, as (longitude, latitude): the linear map of the box, as
    /// the competition's frame is defined; `None` without a box.
    pub fn lon_lat(&self, x: f64, y: f64) -> Option<[f64; 2]> {
        let [lo, hi] = self.lon_lat_box?;
        Some([lo[0] + x / self.width_m * (hi[0] - lo[0]), lo[1] + y / self.height_m * (hi[1] - lo[1])])
    }
}

/// Why a floor plan could not be read.
#[derive(Debug, thiserror::Error)]
pub enum FloorPlanError {
    /// A file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// A file is not what it should be.
    #[error("{path}: {message}")]
    Invalid {
        /// The file.
        path: String,
        /// What is wrong.
        message: String,
    },
}

impl FloorPlan {
    /// Reads `floor_info.json` and `geojson_map.json` from a floor folder, when it has either:
    /// `None` when it has neither (a floor without a plan), an error naming the file when one
    /// is missing or either is not a valid plan.
    pub fn read_if_present(floor_dir: &Path) -> Result<Option<FloorPlan>, FloorPlanError> {
        let present = ["floor_info.json", "geojson_map.json"].iter().any(|f| floor_dir.join(f).exists());
        present.then(|| FloorPlan::read(floor_dir)).transpose()
    }

    /// Reads `floor_info.json` and `geojson_map.json` from a floor folder.
    pub fn read(floor_dir: &Path) -> Result<FloorPlan, FloorPlanError> {
        let invalid = |name: &str, message: String| FloorPlanError::Invalid {
            path: floor_dir.join(name).display().to_string(),
            message,
        };
        let read = |name: &str| {
            let path = floor_dir.join(name);
            let text = std::fs::read_to_string(&path)
                .map_err(|source| FloorPlanError::Io { path: path.display().to_string(), source })?;
            serde_json::from_str::<Value>(&text).map_err(|e| invalid(name, e.to_string()))
        };
        let info = read("floor_info.json")?;
        let size =
            |key: &str| floor_size(&info["map_info"][key], key).map_err(|m| invalid("floor_info.json", m));
        let (width_m, height_m) = (size("width")?, size("height")?);
        let geojson = read("geojson_map.json")?;
        let plan = FloorPlan::from_geojson(&geojson, width_m, height_m)
            .map_err(|message| invalid("geojson_map.json", message))?;
        plan.check_size_on_the_ground().map_err(|message| invalid("floor_info.json", message))?;
        Ok(plan)
    }

    /// Whether the plan's width and height are those of its box on the ground, within
    /// [`MAX_SIZE_MISMATCH`]; the error names the field of `floor_info.json`.
    fn check_size_on_the_ground(&self) -> Result<(), String> {
        let Some([lo, hi]) = self.lon_lat_box else { return Ok(()) };
        let at = |lon: f64, lat: f64| LatLon::new(lat, lon).map_err(|e| e.to_string());
        let unit = Anchor::at(at(lo[0], lo[1])?);
        let mid = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
        // Ground metres across the box's middle, as the site's anchor measures them.
        let east_m = unit.to_site(at(hi[0], mid[1])?)[0] - unit.to_site(at(lo[0], mid[1])?)[0];
        let north_m = unit.to_site(at(mid[0], hi[1])?)[1] - unit.to_site(at(mid[0], lo[1])?)[1];
        for (key, size_m, ground_m) in [("width", self.width_m, east_m), ("height", self.height_m, north_m)] {
            let ratio = size_m / ground_m;
            if !(1.0 / MAX_SIZE_MISMATCH..=MAX_SIZE_MISMATCH).contains(&ratio) {
                return Err(format!(
                    "map_info.{key}: {size_m} m, but geojson_map.json's box is {ground_m:.1} m across on the \
                     ground (at most {MAX_SIZE_MISMATCH} times more or less)"
                ));
            }
        }
        Ok(())
    }

    /// Maps a GeoJSON `FeatureCollection` onto `[0, width] × [0, height]`. The feature whose
    /// `type` property is `floor` is the outline (else the union of all features' bounding
    /// box frames the plan and there is no outline). Refused, naming the field, without a
    /// `features` array, or with a polygon that is not valid (`rings`).
    pub fn from_geojson(geojson: &Value, width_m: f64, height_m: f64) -> Result<FloorPlan, String> {
        let features = geojson["features"].as_array().ok_or("no `features` array")?;
        let mut shapes: Vec<(bool, String, Vec<LonLatPolygon>)> = Vec::new();
        let mut level = None;
        for (k, f) in features.iter().enumerate() {
            let is_floor = f["properties"]["type"].as_str() == Some("floor");
            if is_floor && level.is_none() {
                level = f["properties"]["floor_num"].as_i64().and_then(|n| i32::try_from(n).ok());
            }
            let name = f["properties"]["name"].as_str().unwrap_or("").to_owned();
            let coords = &f["geometry"]["coordinates"];
            let at = format!("features[{k}].geometry.coordinates");
            let polygons = match f["geometry"]["type"].as_str() {
                Some("Polygon") => vec![rings(coords, &at)?],
                Some("MultiPolygon") => {
                    let polygons = coords.as_array().ok_or(format!("{at}: not an array of polygons"))?;
                    if polygons.is_empty() {
                        return Err(format!("{at}: a multipolygon without polygons"));
                    }
                    polygons
                        .iter()
                        .enumerate()
                        .map(|(p, polygon)| rings(polygon, &format!("{at}[{p}]")))
                        .collect::<Result<Vec<_>, _>>()?
                }
                _ => continue,
            };
            shapes.push((is_floor, name, polygons));
        }
        let frame: Vec<[f64; 2]> = {
            let floor: Vec<[f64; 2]> =
                shapes.iter().filter(|s| s.0).flat_map(|s| s.2.iter().flatten().flatten().copied()).collect();
            if floor.is_empty() {
                shapes.iter().flat_map(|s| s.2.iter().flatten().flatten().copied()).collect()
            } else {
                floor
            }
        };
        if frame.is_empty() {
            return Err("no polygon to frame the plan".into());
        }
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in &frame {
            for i in 0..2 {
                lo[i] = lo[i].min(p[i]);
                hi[i] = hi[i].max(p[i]);
            }
        }
        if !(hi[0] > lo[0] && hi[1] > lo[1]) {
            return Err("the plan has no extent".into());
        }
        let to_m = |p: &[f64; 2]| {
            Point2::new(
                (p[0] - lo[0]) / (hi[0] - lo[0]) * width_m,
                (p[1] - lo[1]) / (hi[1] - lo[1]) * height_m,
            )
        };
        let to_polygon = |rings: &LonLatPolygon| Polygon {
            rings: rings.iter().map(|r| r.iter().map(to_m).collect()).collect(),
        };
        let mut plan =
            FloorPlan { width_m, height_m, lon_lat_box: Some([lo, hi]), level, ..FloorPlan::default() };
        for (is_floor, name, polygons) in &shapes {
            for p in polygons {
                if *is_floor {
                    plan.outline.push(to_polygon(p));
                } else {
                    plan.rooms.push(Room { name: name.clone(), polygon: to_polygon(p) });
                }
            }
        }
        Ok(plan)
    }

    /// What kind of place room `room` is ([`room_kinds`](Self::room_kinds)).
    pub fn room_kind(&self, room: usize) -> ZoneKind {
        self.room_kinds.get(room).copied().unwrap_or_default()
    }

    /// The smallest room containing `p`, by index; `None` in the corridors.
    pub fn room_at(&self, p: Point2<f64>) -> Option<usize> {
        self.rooms
            .iter()
            .enumerate()
            .filter(|(_, r)| r.polygon.contains(p))
            .min_by(|a, b| a.1.polygon.area().total_cmp(&b.1.polygon.area()))
            .map(|(i, _)| i)
    }

    /// Whether `p` is on the floor (inside the outline; everywhere if there is none).
    pub fn on_floor(&self, p: Point2<f64>) -> bool {
        self.outline.is_empty() || self.outline.iter().any(|o| o.contains(p))
    }

    /// Whether the straight line `a`–`b` crosses a wall: the outline's or a room's edge.
    pub fn crosses_wall(&self, a: Point2<f64>, b: Point2<f64>) -> bool {
        self.crosses_wall_except(a, b, &[])
    }

    /// [`crosses_wall`](Self::crosses_wall) ignoring the rooms whose indices are in `open`
    /// (sorted): areas known to be walked through, whose plan outline is not a wall.
    pub fn crosses_wall_except(&self, a: Point2<f64>, b: Point2<f64>, open: &[usize]) -> bool {
        let rooms = self
            .rooms
            .iter()
            .enumerate()
            .filter(|(i, _)| open.binary_search(i).is_err())
            .map(|(_, r)| &r.polygon);
        self.outline
            .iter()
            .chain(rooms)
            .flat_map(Polygon::edges)
            .any(|(c, d)| segments_cross(a, b, c, d) && !self.through_a_door(a, b, c, d))
    }

    /// Whether `a`–`b` crosses the wall `c`–`d` at a door: where the lines meet is within
    /// [`DOOR_REACH_M`] of one.
    fn through_a_door(&self, a: Point2<f64>, b: Point2<f64>, c: Point2<f64>, d: Point2<f64>) -> bool {
        if self.doors.is_empty() {
            return false;
        }
        let (r, s) = (b - a, d - c);
        let denominator = r.perp(&s);
        if denominator == 0.0 {
            return false;
        }
        let at = a + r * ((c - a).perp(&s) / denominator);
        self.doors.iter().any(|[p, q]| {
            let pq = q - p;
            let t = if pq.norm_squared() > 0.0 {
                ((at - p).dot(&pq) / pq.norm_squared()).clamp(0.0, 1.0)
            } else {
                0.0
            };
            (p + pq * t - at).norm() <= DOOR_REACH_M
        })
    }
}

/// A polygon's rings of `[lon, lat]` points, as GeoJSON has them.
type LonLatPolygon = Vec<Vec<[f64; 2]>>;

/// A floor size of `floor_info.json`'s `map_info` (`key`), m: a number within
/// [`MIN_FLOOR_SIZE_M`, `MAX_FLOOR_SIZE_M`].
pub(crate) fn floor_size(value: &Value, key: &str) -> Result<f64, String> {
    let size = value.as_f64().ok_or(format!("map_info.{key}: must be a number, found {value}"))?;
    if !(MIN_FLOOR_SIZE_M..=MAX_FLOOR_SIZE_M).contains(&size) {
        return Err(format!(
            "map_info.{key}: {value} m is not a floor's size (from {MIN_FLOOR_SIZE_M} to {MAX_FLOOR_SIZE_M} m)"
        ));
    }
    Ok(size)
}

/// GeoJSON polygon rings, `[[[lon, lat], ...], ...]`, at the JSON path `at`: at least one
/// ring; each of numeric longitudes and latitudes in range, at least three corners enclosing
/// an area, at most [`MAX_RING_POINTS`], and no two of its edges crossing.
fn rings(value: &Value, at: &str) -> Result<LonLatPolygon, String> {
    let rings = value.as_array().ok_or(format!("{at}: not an array of rings"))?;
    if rings.is_empty() {
        return Err(format!("{at}: a polygon without rings"));
    }
    let ring = |(r, ring): (usize, &Value)| {
        let at = format!("{at}[{r}]");
        let points = ring.as_array().ok_or(format!("{at}: not an array of points"))?;
        if points.len() > MAX_RING_POINTS {
            return Err(format!("{at}: {} corners, more than {MAX_RING_POINTS}", points.len()));
        }
        let ring = (points.iter().enumerate())
            .map(|(k, p)| lon_lat(p, &format!("{at}[{k}]")))
            .collect::<Result<Vec<[f64; 2]>, String>>()?;
        if ring_area(&ring) == 0.0 {
            return Err(format!("{at}: a ring needs three corners or more, enclosing an area"));
        }
        if let Some((i, j)) = self_crossing(&ring) {
            return Err(format!("{at}: the ring crosses itself (its edges from corners {i} and {j})"));
        }
        Ok(ring)
    };
    rings.iter().enumerate().map(ring).collect()
}

/// A GeoJSON position `[lon, lat]` at `at`: numbers, longitude within ±180° and latitude
/// within ±90°.
fn lon_lat(p: &Value, at: &str) -> Result<[f64; 2], String> {
    let coordinate = |i: usize, name: &str, limit: f64| {
        let v = p.get(i).and_then(Value::as_f64).ok_or(format!("{at}[{i}]: the {name} must be a number"))?;
        if v.abs() > limit {
            return Err(format!("{at}[{i}]: the {name} {v} is beyond ±{limit}°"));
        }
        Ok(v)
    };
    Ok([coordinate(0, "longitude", 180.0)?, coordinate(1, "latitude", 90.0)?])
}

/// Twice the signed area of a closed ring (shoelace formula), in its own units.
fn ring_area(ring: &[[f64; 2]]) -> f64 {
    let n = ring.len();
    (0..n).map(|i| ring[i][0] * ring[(i + 1) % n][1] - ring[(i + 1) % n][0] * ring[i][1]).sum()
}

/// The first two edges of a ring (by their first corners) that properly cross: a
/// self-intersecting outline, whose inside the even-odd rule makes up. Quadratic in the
/// corners, which [`MAX_RING_POINTS`] bounds.
fn self_crossing(ring: &[[f64; 2]]) -> Option<(usize, usize)> {
    let n = ring.len();
    let p = |i: usize| Point2::new(ring[i % n][0], ring[i % n][1]);
    (0..n).find_map(|i| {
        // Edges beside i share a corner with it: touching there is no crossing.
        (i + 2..n)
            .filter(|&j| (j + 1) % n != i)
            .find(|&j| segments_cross(p(i), p(i + 1), p(j), p(j + 1)))
            .map(|j| (i, j))
    })
}

/// Whether segments `a`–`b` and `c`–`d` properly intersect (touching at an end counts as not).
fn segments_cross(a: Point2<f64>, b: Point2<f64>, c: Point2<f64>, d: Point2<f64>) -> bool {
    let orient = |p: Point2<f64>, q: Point2<f64>, r: Point2<f64>| (q - p).perp(&(r - p));
    let (d1, d2) = (orient(c, d, a), orient(c, d, b));
    let (d3, d4) = (orient(a, b, c), orient(a, b, d));
    d1 * d2 < 0.0 && d3 * d4 < 0.0
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    fn plan() -> FloorPlan {
        let geojson = serde_json::json!({
            "type": "FeatureCollection",
            "features": [
                {"type": "Feature", "properties": {"type": "floor", "name": "F1", "floor_num": 1},
                 "geometry": {"type": "MultiPolygon", "coordinates": [[[[120.0, 30.0], [120.001, 30.0], [120.001, 30.001], [120.0, 30.001], [120.0, 30.0]]]]}},
                {"type": "Feature", "properties": {"name": "shop"},
                 "geometry": {"type": "Polygon", "coordinates": [[[120.0, 30.0], [120.0005, 30.0], [120.0005, 30.0005], [120.0, 30.0005]]]}},
                {"type": "Feature", "properties": {"name": "point"}, "geometry": {"type": "Point", "coordinates": [120.0, 30.0]}}
            ]
        });
        FloorPlan::from_geojson(&geojson, 100.0, 110.0).unwrap()
    }

    #[test]
    fn maps_lon_lat_onto_the_metre_frame() {
        let p = plan();
        assert_eq!(p.outline.len(), 1);
        assert_eq!(p.rooms.len(), 1);
        let corner = p.rooms[0].polygon.rings[0][2];
        assert!((corner.x - 50.0).abs() < 1e-6 && (corner.y - 55.0).abs() < 1e-6);
        assert!((p.rooms[0].polygon.area() - 50.0 * 55.0).abs() < 1e-3);
        assert_eq!(p.lon_lat_box, Some([[120.0, 30.0], [120.001, 30.001]]));
        let [lon, lat] = p.lon_lat(50.0, 110.0).unwrap();
        assert!((lon - 120.0005).abs() < 1e-12 && (lat - 30.001).abs() < 1e-12);
    }

    #[test]
    fn the_level_is_the_outlines_floor_num() {
        assert_eq!(plan().level, Some(1));
        let mut geojson = serde_json::json!({"features": [
            {"properties": {"type": "floor", "floor_num": -1},
             "geometry": {"type": "Polygon", "coordinates": [[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]]}}
        ]});
        assert_eq!(FloorPlan::from_geojson(&geojson, 1.0, 1.0).unwrap().level, Some(-1));
        geojson["features"][0]["properties"] = serde_json::json!({"type": "floor"});
        assert_eq!(FloorPlan::from_geojson(&geojson, 1.0, 1.0).unwrap().level, None);
    }

    #[test]
    fn rooms_and_walls() {
        let p = plan();
        assert_eq!(p.room_at(Point2::new(10.0, 10.0)), Some(0));
        assert_eq!(p.room_at(Point2::new(80.0, 80.0)), None);
        assert!(p.on_floor(Point2::new(80.0, 80.0)));
        assert!(!p.on_floor(Point2::new(180.0, 80.0)));
        assert!(p.crosses_wall(Point2::new(10.0, 10.0), Point2::new(80.0, 10.0)));
        assert!(!p.crosses_wall(Point2::new(60.0, 10.0), Point2::new(80.0, 90.0)));
    }

    /// A floor folder holding `info` as `floor_info.json` and `geojson` as `geojson_map.json`
    /// (each left out when `None`).
    pub(crate) fn floor_dir(info: Option<&str>, geojson: Option<&str>) -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        for (name, text) in [("floor_info.json", info), ("geojson_map.json", geojson)] {
            if let Some(text) = text {
                std::fs::write(dir.path().join(name), text).unwrap();
            }
        }
        dir
    }

    /// A plan of 0.001° × 0.001° at 30° N, 96.5 m × 111 m on the ground, with the given
    /// outline coordinates, and its `floor_info.json` with the given width.
    pub(crate) fn plan_files(outline: &str, width: &str) -> (String, String) {
        let info = format!(r#"{{"map_info": {{"width": {width}, "height": 110}}}}"#);
        let geojson = format!(
            r#"{{"type": "FeatureCollection", "features": [
                {{"type": "Feature", "properties": {{"type": "floor"}},
                  "geometry": {{"type": "Polygon", "coordinates": {outline}}}}}]}}"#
        );
        (info, geojson)
    }

    const SQUARE: &str =
        "[[[120.0, 30.0], [120.001, 30.0], [120.001, 30.001], [120.0, 30.001], [120.0, 30.0]]]";

    /// Every plan `waymark survey` built a site without walls from, or with an absurd anchor
    /// (issue 60, item 8), is refused naming the file and the field.
    #[test]
    fn invalid_plans_are_refused_with_the_file_and_field() {
        let (info, good) = plan_files(SQUARE, "100");
        let dir = floor_dir(Some(&info), Some(&good));
        assert_eq!(FloorPlan::read(dir.path()).unwrap().outline.len(), 1);
        let bowtie = "[[[120.0, 30.0], [120.001, 30.001], [120.001, 30.0], [120.0, 30.0005], [120.0, 30.0]]]";
        let cases = [
            (
                SQUARE,
                "100",
                Some(r#"{"type": "FeatureCollection"}"#),
                "geojson_map.json",
                "no `features` array",
            ),
            (
                "[]",
                "100",
                None,
                "geojson_map.json",
                "features[0].geometry.coordinates: a polygon without rings",
            ),
            ("[[]]", "100", None, "geojson_map.json", "coordinates[0]: a ring needs three corners"),
            (
                r#"[[["120.0", 30.0], [120.001, 30.0], [120.001, 30.001]]]"#,
                "100",
                None,
                "geojson_map.json",
                "coordinates[0][0][0]: the longitude must be a number",
            ),
            (
                "[[[120.0, 30.0], [120.001, 30.0], [120.001, 95.0]]]",
                "100",
                None,
                "geojson_map.json",
                "coordinates[0][2][1]: the latitude 95 is beyond ±90°",
            ),
            (bowtie, "100", None, "geojson_map.json", "coordinates[0]: the ring crosses itself"),
            (SQUARE, "1e-300", None, "floor_info.json", "map_info.width: 1e-300 m is not a floor's size"),
            (SQUARE, "1e300", None, "floor_info.json", "map_info.width: 1e+300 m is not a floor's size"),
            (SQUARE, "\"100\"", None, "floor_info.json", "map_info.width: must be a number"),
            (
                SQUARE,
                "1000",
                None,
                "floor_info.json",
                "map_info.width: 1000 m, but geojson_map.json's box is 96.5 m",
            ),
        ];
        for (outline, width, geojson, file, expected) in cases {
            let (info, plan) = plan_files(outline, width);
            let dir = floor_dir(Some(&info), Some(geojson.unwrap_or(&plan)));
            match FloorPlan::read(dir.path()) {
                Err(FloorPlanError::Invalid { path, message }) => {
                    assert!(path.ends_with(file), "{outline} {width}: {path}");
                    assert!(message.contains(expected), "{outline} {width}: {message}");
                }
                other => panic!("{outline} {width}: {other:?}"),
            }
        }
    }

    /// A floor without a plan has none; a floor with half of one is refused, naming the file
    /// that is missing.
    #[test]
    fn a_plan_is_optional_but_never_half_there() {
        assert!(FloorPlan::read_if_present(floor_dir(None, None).path()).unwrap().is_none());
        let (info, geojson) = plan_files(SQUARE, "100");
        let whole = floor_dir(Some(&info), Some(&geojson));
        assert!(FloorPlan::read_if_present(whole.path()).unwrap().is_some());
        match FloorPlan::read_if_present(floor_dir(Some(&info), None).path()) {
            Err(FloorPlanError::Io { path, .. }) => assert!(path.ends_with("geojson_map.json"), "{path}"),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn malformed_plans_are_errors() {
        assert!(FloorPlan::from_geojson(&serde_json::json!({}), 1.0, 1.0).is_err());
        let bad = serde_json::json!({"features": [{"properties": {}, "geometry": {"type": "Polygon", "coordinates": [[[1.0, "x"]]]}}]});
        assert!(FloorPlan::from_geojson(&bad, 1.0, 1.0).is_err());
        assert!(FloorPlan::read(Path::new("/nonexistent")).is_err());
    }
}
