//! Reading an IMDF venue from a folder or a `.zip` of its GeoJSON files, checked as it is
//! read: every file a GeoJSON `FeatureCollection` whose features carry their `feature_type`
//! and a UUID `id`; levels with an integer `ordinal`; units and openings on a level the
//! archive has; positions numbers within longitude/latitude range; every polygon valid as
//! the OGC Simple Features define it (closed rings of three distinct points or more, no
//! self-intersection, holes inside), checked by the `geo` crate. Each failure names the file
//! and the feature.

use super::{ImdfError, Level, LonLat, Rings, Unit, Venue};
use geo::Validation;
use geojson::{Feature, GeoJson};
use serde_json::Value;
use std::collections::HashMap;
use std::io::Read;
use std::path::Path;

/// Largest file an archive may hold, bytes: a venue's units are a few megabytes; more is not
/// a plan (or is a zip bomb).
pub const MAX_FILE_BYTES: u64 = 256 << 20;

/// Where the files are.
enum Source {
    Folder(std::path::PathBuf),
    Zip(std::path::PathBuf, zip::ZipArchive<std::fs::File>),
}

impl Source {
    fn open(path: &Path) -> Result<Source, ImdfError> {
        let shown = path.display().to_string();
        if path.is_dir() {
            return Ok(Source::Folder(path.to_owned()));
        }
        let file =
            std::fs::File::open(path).map_err(|source| ImdfError::Io { path: shown.clone(), source })?;
        let archive =
            zip::ZipArchive::new(file).map_err(|e| ImdfError::Zip { path: shown, message: e.to_string() })?;
        Ok(Source::Zip(path.to_owned(), archive))
    }

    /// The text of `name` (at the archive's top, or in one folder inside it), if it is there.
    fn text(&mut self, name: &str) -> Result<Option<String>, ImdfError> {
        let mut text = String::new();
        match self {
            Source::Folder(dir) => {
                let path = dir.join(name);
                if !path.exists() {
                    return Ok(None);
                }
                let io = |source| ImdfError::Io { path: path.display().to_string(), source };
                let file = std::fs::File::open(&path).map_err(io)?;
                file.take(MAX_FILE_BYTES + 1).read_to_string(&mut text).map_err(io)?;
            }
            Source::Zip(path, archive) => {
                let zip_error = |e: &dyn std::fmt::Display| ImdfError::Zip {
                    path: path.display().to_string(),
                    message: format!("{name}: {e}"),
                };
                let Some(index) = (0..archive.len()).find(|&i| {
                    archive.name_for_index(i).is_some_and(|n| n == name || n.rsplit('/').next() == Some(name))
                }) else {
                    return Ok(None);
                };
                let entry = archive.by_index(index).map_err(|e| zip_error(&e))?;
                entry.take(MAX_FILE_BYTES + 1).read_to_string(&mut text).map_err(|e| zip_error(&e))?;
            }
        }
        if text.len() as u64 > MAX_FILE_BYTES {
            return Err(ImdfError::Invalid {
                file: name.into(),
                message: format!("more than {MAX_FILE_BYTES} bytes"),
            });
        }
        Ok(Some(text))
    }

    /// The features of the GeoJSON `FeatureCollection` in `name`, each checked to be of
    /// `feature_type` and to have a UUID id; `None` when the file is not there.
    fn features(
        &mut self,
        name: &'static str,
        feature_type: &str,
    ) -> Result<Option<Vec<Checked>>, ImdfError> {
        let Some(text) = self.text(name)? else { return Ok(None) };
        let invalid = |message: String| ImdfError::Invalid { file: name.into(), message };
        let collection = match text.parse::<GeoJson>().map_err(|e| invalid(e.to_string()))? {
            GeoJson::FeatureCollection(c) => c,
            _ => return Err(invalid("not a FeatureCollection".into())),
        };
        let mut out = Vec::with_capacity(collection.features.len());
        for (k, feature) in collection.features.into_iter().enumerate() {
            let at = |message: String| invalid(format!("features[{k}]: {message}"));
            let id = match &feature.id {
                Some(geojson::feature::Id::String(id)) => id.clone(),
                _ => return Err(at("no string id".into())),
            };
            uuid::Uuid::parse_str(&id).map_err(|e| at(format!("id {id:?} is not a UUID: {e}")))?;
            let kind =
                feature.foreign_members.as_ref().and_then(|m| m.get("feature_type")).and_then(Value::as_str);
            if kind != Some(feature_type) {
                return Err(at(format!("feature_type is {kind:?}, not {feature_type:?}")));
            }
            out.push(Checked { file: name, at: format!("features[{k}] ({id})"), id, feature });
        }
        Ok(Some(out))
    }
}

/// A feature of a file, with where it is for messages.
struct Checked {
    file: &'static str,
    at: String,
    id: String,
    feature: Feature,
}

impl Checked {
    fn invalid(&self, message: impl std::fmt::Display) -> ImdfError {
        ImdfError::Invalid { file: self.file.into(), message: format!("{}: {message}", self.at) }
    }

    fn property(&self, key: &str) -> Option<&Value> {
        self.feature.properties.as_ref().and_then(|p| p.get(key)).filter(|v| !v.is_null())
    }

    /// A label property (`{"en": "..."}`): English, else the first language; `None` when null.
    fn label(&self, key: &str) -> Result<Option<String>, ImdfError> {
        let Some(value) = self.property(key) else { return Ok(None) };
        let labels = value.as_object().ok_or_else(|| self.invalid(format!("{key} is not a label object")))?;
        let text = labels.get("en").or_else(|| labels.values().next()).and_then(Value::as_str);
        Ok(text.map(str::to_owned))
    }

    /// A string property that must be there.
    fn string(&self, key: &str) -> Result<String, ImdfError> {
        self.property(key)
            .and_then(Value::as_str)
            .map(str::to_owned)
            .ok_or_else(|| self.invalid(format!("no {key} string")))
    }

    /// The polygons of a `Polygon` or `MultiPolygon` geometry, each checked.
    fn polygons(&self) -> Result<Vec<Rings>, ImdfError> {
        let polygons = match self.feature.geometry.as_ref().map(|g| &g.value) {
            Some(geojson::Value::Polygon(p)) => vec![p],
            Some(geojson::Value::MultiPolygon(ps)) => ps.iter().collect(),
            other => {
                return Err(self
                    .invalid(format!("geometry must be a Polygon or MultiPolygon, found {}", kind(other))))
            }
        };
        if polygons.is_empty() {
            return Err(self.invalid("a MultiPolygon without polygons"));
        }
        polygons
            .into_iter()
            .enumerate()
            .map(|(p, rings)| {
                let rings: Rings = (rings.iter().enumerate())
                    .map(|(r, ring)| self.positions(ring, &format!("polygon {p}, ring {r}")))
                    .collect::<Result<_, _>>()?;
                if rings.is_empty() {
                    return Err(self.invalid(format!("polygon {p} has no rings")));
                }
                let ring = |r: &Vec<LonLat>| {
                    geo::LineString::from(r.iter().map(|p| (p[0], p[1])).collect::<Vec<_>>())
                };
                let polygon = geo::Polygon::new(ring(&rings[0]), rings[1..].iter().map(ring).collect());
                polygon.check_validation().map_err(|e| self.invalid(format!("polygon {p}: {e}")))?;
                Ok(rings)
            })
            .collect()
    }

    /// Positions `[lon, lat]`, each two or three numbers within range.
    fn positions(&self, points: &[Vec<f64>], what: &str) -> Result<Vec<LonLat>, ImdfError> {
        (points.iter().enumerate())
            .map(|(k, p)| match p.as_slice() {
                [lon, lat] | [lon, lat, _] if lon.abs() <= 180.0 && lat.abs() <= 90.0 => Ok([*lon, *lat]),
                _ => Err(self.invalid(format!("{what}, position {k}: {p:?} is not a longitude/latitude"))),
            })
            .collect()
    }
}

fn kind(value: Option<&geojson::Value>) -> &'static str {
    match value {
        None => "none",
        Some(v) => v.type_name(),
    }
}

impl Venue {
    /// Reads a venue from an IMDF folder or `.zip`: `venue.geojson`, `level.geojson` and
    /// `unit.geojson` must be there; `opening.geojson` and `anchor.geojson` are read when they
    /// are; the other files are not needed. Levels come sorted by ordinal.
    pub fn read(path: &Path) -> Result<Venue, ImdfError> {
        let mut source = Source::open(path)?;
        let venues =
            source.features("venue.geojson", "venue")?.ok_or(ImdfError::Missing { file: "venue.geojson" })?;
        let [venue] = venues.as_slice() else {
            return Err(ImdfError::Invalid {
                file: "venue.geojson".into(),
                message: format!("{} venues; an archive holds one", venues.len()),
            });
        };
        venue.polygons()?;
        let name = venue.label("name")?.unwrap_or_default();
        let mut levels: Vec<(String, Level)> = Vec::new();
        for f in
            source.features("level.geojson", "level")?.ok_or(ImdfError::Missing { file: "level.geojson" })?
        {
            let ordinal = f
                .property("ordinal")
                .and_then(Value::as_i64)
                .and_then(|o| i32::try_from(o).ok())
                .ok_or_else(|| f.invalid("no integer ordinal"))?;
            let label = f.label("name")?.unwrap_or_default();
            let short_name = f.label("short_name")?.unwrap_or_else(|| label.clone());
            let level = Level {
                name: label,
                short_name,
                ordinal,
                outline: f.polygons()?,
                units: Vec::new(),
                openings: Vec::new(),
            };
            levels.push((f.id, level));
        }
        let index: HashMap<String, usize> =
            levels.iter().enumerate().map(|(i, (id, _))| (id.clone(), i)).collect();
        let level_of = |f: &Checked| -> Result<usize, ImdfError> {
            let id = f.string("level_id")?;
            index
                .get(&id)
                .copied()
                .ok_or_else(|| f.invalid(format!("level_id {id} is no level of the archive")))
        };
        let mut units: HashMap<String, ()> = HashMap::new();
        for f in
            source.features("unit.geojson", "unit")?.ok_or(ImdfError::Missing { file: "unit.geojson" })?
        {
            let level = level_of(&f)?;
            let unit =
                Unit { name: f.label("name")?, category: f.string("category")?, polygons: f.polygons()? };
            levels[level].1.units.push(unit);
            units.insert(f.id.clone(), ());
        }
        for f in source.features("opening.geojson", "opening")?.unwrap_or_default() {
            let level = level_of(&f)?;
            let line = match f.feature.geometry.as_ref().map(|g| &g.value) {
                Some(geojson::Value::LineString(points)) => f.positions(points, "line")?,
                other => {
                    return Err(f.invalid(format!("geometry must be a LineString, found {}", kind(other))))
                }
            };
            if line.len() < 2 {
                return Err(f.invalid("an opening needs two positions or more"));
            }
            levels[level].1.openings.push(line);
        }
        for f in source.features("anchor.geojson", "anchor")?.unwrap_or_default() {
            match f.feature.geometry.as_ref().map(|g| &g.value) {
                Some(geojson::Value::Point(p)) => {
                    f.positions(std::slice::from_ref(p), "point")?;
                }
                other => return Err(f.invalid(format!("geometry must be a Point, found {}", kind(other)))),
            }
            if let Some(unit) = f.property("unit_id").and_then(Value::as_str) {
                if !units.contains_key(unit) {
                    return Err(f.invalid(format!("unit_id {unit} is no unit of the archive")));
                }
            }
        }
        let mut levels: Vec<Level> = levels.into_iter().map(|(_, l)| l).collect();
        levels.sort_by_key(|l| l.ordinal);
        Ok(Venue { name, levels })
    }
}
