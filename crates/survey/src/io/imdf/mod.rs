//! IMDF, Apple's Indoor Mapping Data Format 1.0.0 (an OGC community standard): a venue's plan
//! as GeoJSON files in WGS84 (`venue`, `level` with ordinals, `unit` with categories and
//! names, `opening` for doors, `anchor`, `building`, `footprint`, `address`, and
//! `manifest.json`), in a folder or a `.zip` (docs/imdf.md).
//!
//! [`Venue`] is what Waymark reads of it and writes: levels, their outlines, units and
//! openings in longitude/latitude. A level becomes the same [`FloorPlan`] the competition's
//! `geojson_map.json` does ([`Level::floor_plan`]): its outline frames the plan, units are its
//! rooms (zones, of the unit's category), their boundaries its walls, openings its doors.
//! [`Venue::from_plans`] and [`Venue::from_site`] go the other way, for a map SDK.

mod read;
mod write;

pub use write::WriteOptions;

use super::floor_plan::{floor_size, FloorPlan, Polygon, Room};
use geo::ConvexHull;
use nalgebra::Point2;
use std::path::Path;
use waymark_engine::site::{Anchor, LatLon, Site, ZoneKind};

/// A WGS84 position as GeoJSON has it: `[longitude, latitude]`, degrees.
pub type LonLat = [f64; 2];

/// A polygon's rings, the outside first, then its holes; each closed (the last point repeats
/// the first), as GeoJSON has them.
pub type Rings = Vec<Vec<LonLat>>;

/// The IMDF version read and written.
pub const IMDF_VERSION: &str = "1.0.0";

/// A venue: its name and levels.
#[derive(Clone, Debug, PartialEq)]
pub struct Venue {
    /// The venue's name (its `name` label: English, or the first language given).
    pub name: String,
    /// Its levels, by ordinal (then in file order).
    pub levels: Vec<Level>,
}

/// One level (a floor of a building).
#[derive(Clone, Debug, PartialEq)]
pub struct Level {
    /// Its name label ("Ground floor").
    pub name: String,
    /// Its short name label ("F1"): the floor folder a survey matches it to.
    pub short_name: String,
    /// Its IMDF ordinal: 0 at ground level, -1 the first below, 1 the first above.
    pub ordinal: i32,
    /// Its outline: one or more polygons.
    pub outline: Vec<Rings>,
    /// Its units (rooms, walkways, stairs...).
    pub units: Vec<Unit>,
    /// Its openings (doors): polylines along the walls they open.
    pub openings: Vec<Vec<LonLat>>,
}

/// A unit: a room, walkway, staircase...
#[derive(Clone, Debug, PartialEq)]
pub struct Unit {
    /// Its name label; `None` for an unnamed unit (a wall, a column, a walkway).
    pub name: Option<String>,
    /// Its IMDF category (`room`, `walkway`, `stairs`, `elevator`...).
    pub category: String,
    /// Its shape: one or more polygons.
    pub polygons: Vec<Rings>,
}

/// Why an IMDF venue could not be read, written or used.
#[derive(Debug, thiserror::Error)]
pub enum ImdfError {
    /// A file or folder could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// A `.zip` archive could not be read or written.
    #[error("{path}: {message}")]
    Zip {
        /// The archive.
        path: String,
        /// Why.
        message: String,
    },
    /// A required file is missing.
    #[error("the IMDF archive has no {file}")]
    Missing {
        /// Its name (`venue.geojson`...).
        file: &'static str,
    },
    /// A file is not valid IMDF: the file and what is wrong, naming the feature.
    #[error("{file}: {message}")]
    Invalid {
        /// The file's name in the archive.
        file: String,
        /// What is wrong.
        message: String,
    },
    /// A floor has no level of its name (or short name).
    #[error("no level of the venue is called {floor:?} (its levels: {levels})")]
    NoSuchLevel {
        /// The floor's name.
        floor: String,
        /// The levels' short names.
        levels: String,
    },
    /// What was to be written has no place on the Earth: a site without an anchor, a plan
    /// without longitude/latitude.
    #[error("{what} is not geo-referenced: IMDF is in longitude/latitude")]
    NotGeoReferenced {
        /// Which.
        what: String,
    },
}

/// The logical level (as a building numbers its floors, with no floor 0: -1 for the first
/// basement, 1 for the ground floor, as the competition's `floor_num`) of an IMDF ordinal.
pub fn level_of_ordinal(ordinal: i32) -> i32 {
    if ordinal >= 0 {
        ordinal.saturating_add(1)
    } else {
        ordinal
    }
}

/// The IMDF ordinal of a logical level: the inverse of [`level_of_ordinal`] (a level 0, which
/// that numbering has not, is taken as the ground floor).
pub fn ordinal_of_level(level: i32) -> i32 {
    if level >= 1 {
        level - 1
    } else {
        level
    }
}

/// The zone kind of an IMDF unit category (IMDF 1.0.0, "Unit Categories").
pub fn zone_kind(category: &str) -> ZoneKind {
    match category {
        "walkway" | "walkway.island" | "footbridge" | "movingwalkway" => ZoneKind::Corridor,
        "lobby" | "unenclosedarea" | "opentobelow" | "platform" | "waitingroom" | "terrace" => ZoneKind::Hall,
        "stairs" | "steps" | "escalator" | "ramp" => ZoneKind::Stairs,
        "elevator" => ZoneKind::Lift,
        "unspecified" | "nonpublic" | "structure" | "column" | "brick" | "concrete" | "drywall" | "glass"
        | "wood" | "road" | "parking" | "vegetation" => ZoneKind::Other,
        _ => ZoneKind::Room,
    }
}

/// The IMDF unit category written for a zone kind; an entrance, which IMDF marks with an
/// opening rather than a unit, is `unspecified`.
pub fn unit_category(kind: ZoneKind) -> &'static str {
    match kind {
        ZoneKind::Room => "room",
        ZoneKind::Corridor => "walkway",
        ZoneKind::Hall => "lobby",
        ZoneKind::Stairs => "stairs",
        ZoneKind::Lift => "elevator",
        ZoneKind::Entrance | ZoneKind::Other => "unspecified",
    }
}

/// `[[west, south], [east, north]]` of the points.
fn bounding_box<'a>(points: impl Iterator<Item = &'a LonLat>) -> Option<[LonLat; 2]> {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in points {
        for i in 0..2 {
            lo[i] = lo[i].min(p[i]);
            hi[i] = hi[i].max(p[i]);
        }
    }
    (hi[0] > lo[0] && hi[1] > lo[1]).then_some([lo, hi])
}

/// East-west and south-north ground metres across the middle of a longitude/latitude box.
fn ground_size([lo, hi]: [LonLat; 2]) -> Option<[f64; 2]> {
    let at = |lon: f64, lat: f64| LatLon::new(lat, lon).ok();
    let unit = Anchor::at(at(lo[0], lo[1])?);
    let mid = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
    let east = unit.to_site(at(hi[0], mid[1])?)[0] - unit.to_site(at(lo[0], mid[1])?)[0];
    let north = unit.to_site(at(mid[0], hi[1])?)[1] - unit.to_site(at(mid[0], lo[1])?)[1];
    Some([east, north])
}

/// A ring closed: its first point repeated at the end when it is not there.
fn closed(mut ring: Vec<LonLat>) -> Vec<LonLat> {
    if ring.first() != ring.last() {
        if let Some(&first) = ring.first() {
            ring.push(first);
        }
    }
    ring
}

impl Level {
    /// The level as a floor plan in metres: its outline's longitude/latitude box (its units'
    /// when it has no outline) stretched onto `[0, width] × [0, height]`, x east, y north, as
    /// the competition frames a plan. `size_m` is the frame's width and height: a floor
    /// folder's `floor_info.json`, which its walks' waypoints are measured in; `None`, the
    /// box's size on the ground (a frame in metres). Units are rooms, of their categories'
    /// kinds (an unnamed unit is a room with an empty name: a wall, never a zone); openings
    /// are doors; the level is [`level_of_ordinal`].
    pub fn floor_plan(&self, size_m: Option<[f64; 2]>) -> Result<FloorPlan, ImdfError> {
        let invalid = |message: String| ImdfError::Invalid { file: "level.geojson".into(), message };
        let outline_points = self.outline.iter().flatten().flatten();
        let unit_points = self.units.iter().flat_map(|u| u.polygons.iter().flatten().flatten());
        let frame =
            if self.outline.is_empty() { bounding_box(unit_points) } else { bounding_box(outline_points) };
        let Some([lo, hi]) = frame else {
            return Err(invalid(format!("level {:?} has no extent", self.short_name)));
        };
        let [width_m, height_m] = match size_m {
            Some(size) => size,
            None => ground_size([lo, hi])
                .ok_or_else(|| invalid(format!("level {:?}: its box has no size", self.short_name)))?,
        };
        let to_m = |p: &LonLat| {
            Point2::new(
                (p[0] - lo[0]) / (hi[0] - lo[0]) * width_m,
                (p[1] - lo[1]) / (hi[1] - lo[1]) * height_m,
            )
        };
        let polygon =
            |rings: &Rings| Polygon { rings: rings.iter().map(|r| r.iter().map(to_m).collect()).collect() };
        let mut plan = FloorPlan {
            width_m,
            height_m,
            outline: self.outline.iter().map(polygon).collect(),
            lon_lat_box: Some([lo, hi]),
            level: Some(level_of_ordinal(self.ordinal)),
            ..FloorPlan::default()
        };
        for unit in &self.units {
            for p in &unit.polygons {
                plan.rooms.push(Room { name: unit.name.clone().unwrap_or_default(), polygon: polygon(p) });
                plan.room_kinds.push(zone_kind(&unit.category));
            }
        }
        plan.doors = self
            .openings
            .iter()
            .flat_map(|line| line.windows(2).map(|w| [to_m(&w[0]), to_m(&w[1])]))
            .collect();
        Ok(plan)
    }
}

impl Venue {
    /// The level a floor folder called `floor` stands for: the one whose short name, or name,
    /// is `floor` (ignoring ASCII case).
    pub fn level_for_floor(&self, floor: &str) -> Result<&Level, ImdfError> {
        let find = |f: fn(&Level) -> &str| self.levels.iter().find(|l| f(l).eq_ignore_ascii_case(floor));
        find(|l| &l.short_name).or_else(|| find(|l| &l.name)).ok_or_else(|| ImdfError::NoSuchLevel {
            floor: floor.to_owned(),
            levels: self.levels.iter().map(|l| l.short_name.as_str()).collect::<Vec<_>>().join(", "),
        })
    }

    /// The plan of the floor folder `floor_dir` (named as one of the levels): its level's
    /// [`floor_plan`](Level::floor_plan), framed by the folder's `floor_info.json` when it
    /// has one (the competition's walks are measured in that frame).
    pub fn plan_for_floor(&self, floor_dir: &Path) -> Result<FloorPlan, ImdfError> {
        let name = floor_dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let level = self.level_for_floor(&name)?;
        let info = floor_dir.join("floor_info.json");
        let size = if info.exists() {
            let path = info.display().to_string();
            let text = std::fs::read_to_string(&info)
                .map_err(|source| ImdfError::Io { path: path.clone(), source })?;
            let invalid = |message: String| ImdfError::Invalid { file: path.clone(), message };
            let value: serde_json::Value = serde_json::from_str(&text).map_err(|e| invalid(e.to_string()))?;
            let size = |key: &str| floor_size(&value["map_info"][key], key).map_err(invalid);
            Some([size("width")?, size("height")?])
        } else {
            None
        };
        level.floor_plan(size)
    }

    /// A venue from floor plans in longitude/latitude (the competition's, or IMDF's), one
    /// level per `(floor name, plan)`: the name is the level's name and short name, the
    /// plan's level its ordinal ([`ordinal_of_level`]; the floor's index without one), its
    /// outline the level's (its box without one), rooms units, doors openings.
    pub fn from_plans(name: &str, floors: &[(String, &FloorPlan)]) -> Result<Venue, ImdfError> {
        let mut levels = Vec::with_capacity(floors.len());
        for (index, (floor, plan)) in floors.iter().enumerate() {
            let not_geo = || ImdfError::NotGeoReferenced { what: format!("the plan of floor {floor}") };
            let [lo, hi] = plan.lon_lat_box.ok_or_else(not_geo)?;
            let at = |p: &Point2<f64>| plan.lon_lat(p.x, p.y).ok_or_else(not_geo);
            let rings = |polygon: &Polygon| -> Result<Rings, ImdfError> {
                polygon
                    .rings
                    .iter()
                    .map(|r| Ok(closed(r.iter().map(at).collect::<Result<_, _>>()?)))
                    .collect()
            };
            let outline = if plan.outline.is_empty() {
                vec![vec![vec![lo, [hi[0], lo[1]], hi, [lo[0], hi[1]], lo]]]
            } else {
                plan.outline.iter().map(rings).collect::<Result<_, _>>()?
            };
            let units = (plan.rooms.iter().enumerate())
                .map(|(r, room)| {
                    Ok(Unit {
                        name: Some(room.name.clone()).filter(|n| !n.trim().is_empty()),
                        category: unit_category(plan.room_kind(r)).to_owned(),
                        polygons: vec![rings(&room.polygon)?],
                    })
                })
                .collect::<Result<_, ImdfError>>()?;
            let openings = (plan.doors.iter())
                .map(|[p, q]| Ok(vec![at(p)?, at(q)?]))
                .collect::<Result<_, ImdfError>>()?;
            levels.push(Level {
                name: floor.clone(),
                short_name: floor.clone(),
                ordinal: plan.level.map_or(index as i32, ordinal_of_level),
                outline,
                units,
                openings,
            });
        }
        Ok(Venue { name: name.to_owned(), levels })
    }

    /// A venue from a geo-referenced site, for a map SDK: a level per floor (its outline the
    /// convex hull of the places of the floor, as [`Site::zone_outline`] draws a zone's), a unit
    /// per zone (its outline, its kind's category). A site knows no doors, so there are no
    /// openings.
    pub fn from_site(site: &Site) -> Result<Venue, ImdfError> {
        let not_geo = || ImdfError::NotGeoReferenced { what: format!("site {:?}", site.name()) };
        site.lat_lon(0, 0.0, 0.0).ok_or_else(not_geo)?;
        let to_lon_lat = |floor: usize, p: [f64; 2]| {
            site.lat_lon(floor, p[0], p[1]).map(|g| [g.lon_deg, g.lat_deg]).ok_or_else(not_geo)
        };
        let half = site.spacing_m().max(0.1) / 2.0;
        let mut levels = Vec::with_capacity(site.floors().len());
        for (f, floor) in site.floors().iter().enumerate() {
            let corners: Vec<geo::Point<f64>> = (site.states().iter())
                .filter(|s| s.floor == f)
                .flat_map(|s| {
                    [(-half, -half), (half, -half), (half, half), (-half, half)]
                        .map(|(dx, dy)| geo::Point::new(s.position.x + dx, s.position.y + dy))
                })
                .collect();
            let hull = geo::MultiPoint::from(corners).convex_hull();
            let ring: Vec<LonLat> =
                hull.exterior().coords().map(|c| to_lon_lat(f, [c.x, c.y])).collect::<Result<_, _>>()?;
            let mut units = Vec::new();
            for (z, zone) in site.zones().iter().enumerate() {
                let Some((zf, outline)) = site.zone_outline(z) else { continue };
                if zf != f {
                    continue;
                }
                let ring = outline.iter().map(|&p| to_lon_lat(f, p)).collect::<Result<Vec<_>, _>>()?;
                units.push(Unit {
                    name: Some(zone.name.clone()),
                    category: unit_category(zone.kind).to_owned(),
                    polygons: vec![vec![closed(ring)]],
                });
            }
            levels.push(Level {
                name: floor.name.clone(),
                short_name: floor.name.clone(),
                ordinal: floor.level.map_or(f as i32, ordinal_of_level),
                outline: if ring.len() >= 4 { vec![vec![closed(ring)]] } else { Vec::new() },
                units,
                openings: Vec::new(),
            });
        }
        Ok(Venue { name: site.name().to_owned(), levels })
    }
}

/// Gives each floor its plan from the IMDF venue at `path` ([`Venue::plan_for_floor`]), in
/// place of what its folder held: the floor folders of a survey or an evaluation.
pub fn plans_from_imdf(path: &Path, floors: &mut [crate::calibrate::FloorData]) -> Result<(), ImdfError> {
    let venue = Venue::read(path)?;
    for floor in floors {
        floor.plan = Some(venue.plan_for_floor(&floor.dir)?);
    }
    Ok(())
}

#[cfg(test)]
mod tests;
