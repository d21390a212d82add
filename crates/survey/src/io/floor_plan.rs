//! A floor plan from the competition's GeoJSON (longitude/latitude) and `floor_info.json`
//! (width and height, m): the floor outline and its rooms (shops), mapped onto the metre
//! frame the waypoints use — the outline's bounding box stretched onto `[0, width] × [0,
//! height]`, x east, y north — and what geo-references it: that box in longitude/latitude,
//! and the floor's number (`floor_num`, -1 for B1) from the outline's properties.

use nalgebra::Point2;
use serde_json::Value;
use std::path::Path;

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
}

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
    /// Reads `floor_info.json` and `geojson_map.json` from a floor folder.
    pub fn read(floor_dir: &Path) -> Result<FloorPlan, FloorPlanError> {
        let read = |name: &str| {
            let path = floor_dir.join(name);
            let text = std::fs::read_to_string(&path)
                .map_err(|source| FloorPlanError::Io { path: path.display().to_string(), source })?;
            serde_json::from_str::<Value>(&text).map_err(|e| FloorPlanError::Invalid {
                path: path.display().to_string(),
                message: e.to_string(),
            })
        };
        let info = read("floor_info.json")?;
        let size = |key: &str| info["map_info"][key].as_f64().filter(|v| v.is_finite() && *v > 0.0);
        let (Some(width_m), Some(height_m)) = (size("width"), size("height")) else {
            return Err(FloorPlanError::Invalid {
                path: floor_dir.join("floor_info.json").display().to_string(),
                message: "map_info.width and map_info.height must be positive numbers".into(),
            });
        };
        let geojson = read("geojson_map.json")?;
        FloorPlan::from_geojson(&geojson, width_m, height_m).map_err(|message| FloorPlanError::Invalid {
            path: floor_dir.join("geojson_map.json").display().to_string(),
            message,
        })
    }

    /// Maps a GeoJSON `FeatureCollection` onto `[0, width] × [0, height]`. The feature whose
    /// `type` property is `floor` is the outline (else the union of all features' bounding
    /// box frames the plan and there is no outline).
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
            let polygons = match f["geometry"]["type"].as_str() {
                Some("Polygon") => vec![rings(coords).ok_or(format!("features[{k}]: bad polygon"))?],
                Some("MultiPolygon") => coords
                    .as_array()
                    .ok_or(format!("features[{k}]: bad multipolygon"))?
                    .iter()
                    .map(rings)
                    .collect::<Option<Vec<_>>>()
                    .ok_or(format!("features[{k}]: bad multipolygon"))?,
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
        self.outline.iter().chain(rooms).flat_map(Polygon::edges).any(|(c, d)| segments_cross(a, b, c, d))
    }
}

/// A polygon's rings of `[lon, lat]` points, as GeoJSON has them.
type LonLatPolygon = Vec<Vec<[f64; 2]>>;

/// GeoJSON polygon rings: `[[[lon, lat], ...], ...]`.
fn rings(value: &Value) -> Option<LonLatPolygon> {
    value
        .as_array()?
        .iter()
        .map(|ring| {
            ring.as_array()?
                .iter()
                .map(|p| {
                    let x = p.get(0)?.as_f64()?;
                    let y = p.get(1)?.as_f64()?;
                    (x.is_finite() && y.is_finite()).then_some([x, y])
                })
                .collect::<Option<Vec<_>>>()
        })
        .collect()
}

/// Whether segments `a`–`b` and `c`–`d` properly intersect (touching at an end counts as not).
fn segments_cross(a: Point2<f64>, b: Point2<f64>, c: Point2<f64>, d: Point2<f64>) -> bool {
    let orient = |p: Point2<f64>, q: Point2<f64>, r: Point2<f64>| (q - p).perp(&(r - p));
    let (d1, d2) = (orient(c, d, a), orient(c, d, b));
    let (d3, d4) = (orient(a, b, c), orient(a, b, d));
    d1 * d2 < 0.0 && d3 * d4 < 0.0
}

#[cfg(test)]
mod tests {
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

    #[test]
    fn malformed_plans_are_errors() {
        assert!(FloorPlan::from_geojson(&serde_json::json!({}), 1.0, 1.0).is_err());
        let bad = serde_json::json!({"features": [{"properties": {}, "geometry": {"type": "Polygon", "coordinates": [[[1.0, "x"]]]}}]});
        assert!(FloorPlan::from_geojson(&bad, 1.0, 1.0).is_err());
        assert!(FloorPlan::read(Path::new("/nonexistent")).is_err());
    }
}
