//! Writing a venue as IMDF 1.0.0, to a folder or a `.zip`: `manifest.json` and the GeoJSON
//! files a map SDK reads (address, venue, building, footprint, level, unit, opening,
//! anchor), each feature with the properties the specification requires. Feature ids are
//! UUIDs (version 5) derived from the venue's name and the feature's place in it, so the same
//! venue is written the same way every time and a map's references to it hold.

use super::{ImdfError, Level, LonLat, Rings, Venue, IMDF_VERSION};
use geo::{ConvexHull, InteriorPoint};
use serde_json::{json, Value};
use std::io::Write;
use std::path::Path;
use uuid::Uuid;

/// What IMDF needs that a plan does not say.
#[derive(Clone, Debug, PartialEq)]
pub struct WriteOptions {
    /// `manifest.json`'s `created`: an ISO 8601 time.
    pub created: String,
    /// The venue's IMDF category (`shoppingcenter`, `businesscampus`, `airport`...).
    pub venue_category: String,
    /// The address's ISO 3166 country code; `ZZ` (unknown) when the plan does not say.
    pub country: String,
}

/// The files, in the order they are written.
const FILES: [&str; 8] = ["address", "venue", "building", "footprint", "level", "unit", "opening", "anchor"];

/// A label object, `{"en": text}`.
fn label(text: &str) -> Value {
    json!({ "en": text })
}

fn polygon_geometry(polygons: &[Rings]) -> Value {
    match polygons {
        [one] => json!({ "type": "Polygon", "coordinates": one }),
        many => json!({ "type": "MultiPolygon", "coordinates": many }),
    }
}

fn geo_polygon(rings: &Rings) -> geo::Polygon<f64> {
    let ring = |r: &Vec<LonLat>| geo::LineString::from(r.iter().map(|p| (p[0], p[1])).collect::<Vec<_>>());
    geo::Polygon::new(ring(&rings[0]), rings[1..].iter().map(ring).collect())
}

/// A point inside the first polygon, for labels (`display_point`).
fn display_point(polygons: &[Rings]) -> Value {
    let Some(p) = polygons.first().map(geo_polygon).and_then(|p| p.interior_point()) else {
        return Value::Null;
    };
    json!({ "type": "Point", "coordinates": [p.x(), p.y()] })
}

fn feature(id: Uuid, feature_type: &str, geometry: Value, properties: Value) -> Value {
    json!({ "id": id.to_string(), "type": "Feature", "feature_type": feature_type, "geometry": geometry, "properties": properties })
}

impl Venue {
    /// Writes the venue as IMDF to `out`: a `.zip` when its name ends so, else a folder
    /// (made if need be; files of the same names are replaced).
    pub fn write(&self, out: &Path, options: &WriteOptions) -> Result<(), ImdfError> {
        let files = self.files(options);
        let io = |path: &Path| {
            let path = path.display().to_string();
            move |source| ImdfError::Io { path, source }
        };
        let text = |v: &Value| serde_json::to_string_pretty(v).expect("JSON values serialise");
        if out.extension().is_some_and(|e| e.eq_ignore_ascii_case("zip")) {
            let zip_error = |e: &dyn std::fmt::Display| ImdfError::Zip {
                path: out.display().to_string(),
                message: e.to_string(),
            };
            let file = std::fs::File::create(out).map_err(io(out))?;
            let mut zip = zip::ZipWriter::new(file);
            let deflated =
                zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated);
            for (name, value) in &files {
                zip.start_file(name.as_str(), deflated).map_err(|e| zip_error(&e))?;
                zip.write_all(text(value).as_bytes()).map_err(io(out))?;
            }
            zip.finish().map_err(|e| zip_error(&e))?;
        } else {
            std::fs::create_dir_all(out).map_err(io(out))?;
            for (name, value) in &files {
                let path = out.join(name);
                std::fs::write(&path, text(value)).map_err(io(&path))?;
            }
        }
        Ok(())
    }

    /// The files of the archive, by name.
    fn files(&self, options: &WriteOptions) -> Vec<(String, Value)> {
        let namespace = Uuid::new_v5(&Uuid::NAMESPACE_URL, b"https://github.com/waymark/imdf");
        let id = |key: &str| Uuid::new_v5(&namespace, format!("{}\u{0}{key}", self.name).as_bytes());
        let (address, venue, building) = (id("address"), id("venue"), id("building"));
        let mut features: Vec<Vec<Value>> = vec![Vec::new(); FILES.len()];
        let all: Vec<geo::Point<f64>> = (self.levels.iter())
            .flat_map(|l| l.outline.iter().flatten().flatten())
            .map(|p| geo::Point::new(p[0], p[1]))
            .collect();
        let hull = geo::MultiPoint::from(all).convex_hull();
        let outline: Vec<Rings> = vec![vec![hull.exterior().coords().map(|c| [c.x, c.y]).collect()]];
        let centre = display_point(&outline);
        features[0].push(feature(
            address,
            "address",
            Value::Null,
            json!({ "address": self.name, "unit": null, "locality": self.name, "province": null,
                    "country": options.country, "postal_code": null, "postal_code_ext": null,
                    "postal_code_vanity": null }),
        ));
        features[1].push(feature(
            venue,
            "venue",
            polygon_geometry(&outline),
            json!({ "category": options.venue_category, "restriction": null, "name": label(&self.name),
                    "alt_name": null, "hours": null, "phone": null, "website": null,
                    "display_point": centre, "address_id": address.to_string() }),
        ));
        features[2].push(feature(
            building,
            "building",
            Value::Null,
            json!({ "name": label(&self.name), "alt_name": null, "category": "unspecified", "restriction": null,
                    "display_point": centre, "address_id": address.to_string() }),
        ));
        features[3].push(feature(
            id("footprint"),
            "footprint",
            polygon_geometry(&outline),
            json!({ "category": "ground", "name": null, "building_ids": [building.to_string()] }),
        ));
        for (l, level) in self.levels.iter().enumerate() {
            let level_id = id(&format!("level/{l}"));
            features[4].push(self.level(level, level_id, building));
            for (u, unit) in level.units.iter().enumerate() {
                let unit_id = id(&format!("level/{l}/unit/{u}"));
                let point = display_point(&unit.polygons);
                features[5].push(feature(
                    unit_id,
                    "unit",
                    polygon_geometry(&unit.polygons),
                    json!({ "category": unit.category, "restriction": null, "accessibility": null,
                            "name": unit.name.as_deref().map(label), "alt_name": null,
                            "display_point": point, "level_id": level_id.to_string() }),
                ));
                if !point.is_null() {
                    features[7].push(feature(
                        id(&format!("level/{l}/unit/{u}/anchor")),
                        "anchor",
                        point,
                        json!({ "address_id": null, "unit_id": unit_id.to_string() }),
                    ));
                }
            }
            for (o, line) in level.openings.iter().enumerate() {
                features[6].push(feature(
                    id(&format!("level/{l}/opening/{o}")),
                    "opening",
                    json!({ "type": "LineString", "coordinates": line }),
                    json!({ "category": "pedestrian", "accessibility": null, "access_control": null,
                            "door": null, "name": null, "alt_name": null, "display_point": null,
                            "level_id": level_id.to_string() }),
                ));
            }
        }
        let manifest = json!({
            "version": IMDF_VERSION,
            "created": options.created,
            "generated_by": { "name": "waymark", "version": env!("CARGO_PKG_VERSION") },
            "language": "en",
            "extensions": null,
        });
        std::iter::once(("manifest.json".to_owned(), manifest))
            .chain(FILES.iter().zip(features).map(|(name, features)| {
                (format!("{name}.geojson"), json!({ "type": "FeatureCollection", "features": features }))
            }))
            .collect()
    }

    fn level(&self, level: &Level, id: Uuid, building: Uuid) -> Value {
        feature(
            id,
            "level",
            polygon_geometry(&level.outline),
            json!({ "category": "unspecified", "restriction": null, "outdoor": false, "ordinal": level.ordinal,
                    "name": label(&level.name), "short_name": label(&level.short_name),
                    "display_point": display_point(&level.outline), "address_id": null,
                    "building_ids": [building.to_string()] }),
        )
    }
}
