//! `waymark view`: one self-contained HTML page (inline script and style, the data as JSON,
//! nothing fetched) showing a site's floors — the plan when one is given, the HMM's states and
//! walkable graph, the zones — and optionally a walk: the engine's estimate with its 68% circle
//! and the truth when it is known, with play, pause and a time slider; and where the survey's
//! held-out walks were beyond the map (`waymark survey --coverage-out`) (docs/view.md).

use crate::shared::SaltArgs;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use waymark_engine::site::{LatLon, StateKind, PSEUDO_SPACING_M};
use waymark_engine::{Engine, EngineConfig, Site};
use waymark_experiments as experiments;
use waymark_sim as sim;
use waymark_survey::io::{FloorPlan, FloorPlanError, TraceError};
use waymark_survey::replay::{self as replaying, ReplayOptions};

/// The page: markup with `{{style}}`, `{{data}}` and `{{script}}`, each filled once.
const TEMPLATE: &str = include_str!("view/page.html");
const STYLE: &str = include_str!("view/view.css");
const SCRIPT: &str = include_str!("view/view.js");

#[derive(clap::Args)]
pub struct ViewArgs {
    /// The site file (JSON or binary).
    #[arg(long, required_unless_present = "demo", conflicts_with = "demo")]
    site: Option<PathBuf>,
    /// A track as `waymark replay --out track.csv` writes it. Its columns are read by name
    /// (timestamp_ms, floor, x, y, accuracy_m); others are ignored.
    #[arg(long, conflicts_with_all = ["walk", "demo"])]
    track: Option<PathBuf>,
    /// A recorded walk (competition-format text file), replayed through the engine as
    /// `waymark replay` does; its waypoints are the truth.
    #[arg(long, conflicts_with = "demo")]
    walk: Option<PathBuf>,
    /// A floor folder (competition format: `floor_info.json` and `geojson_map.json`) whose
    /// plan is drawn under the site's floor of the same name. Repeat for more floors.
    #[arg(long = "plan", value_name = "FLOOR_DIR", conflicts_with = "demo")]
    plans: Vec<PathBuf>,
    /// Where the survey's held-out walks were beyond the map: the GeoJSON `waymark survey
    /// --coverage-out` writes, drawn on the floors it names. Needs a geo-referenced site.
    #[arg(long, value_name = "GEOJSON", conflicts_with = "demo")]
    coverage: Option<PathBuf>,
    /// The simulated office of `waymark demo`, with its first walk and the truth.
    #[arg(long)]
    demo: bool,
    /// With --demo: seed of the office and its walk [default: 0].
    #[arg(long)]
    seed: Option<u64>,
    /// With --demo: length of the walk, m [default: 200].
    #[arg(long)]
    walk_length_m: Option<f64>,
    /// Where to write the page (HTML).
    #[arg(long)]
    out: PathBuf,
    /// The salt of a site whose transmitter ids are hashed (for --walk).
    #[command(flatten)]
    salt: SaltArgs,
}

/// Why no page was written.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    /// The site file could not be loaded.
    #[error("{path}: {source}")]
    Site { path: String, source: waymark_engine::SiteError },
    /// A floor plan could not be read.
    #[error(transparent)]
    Plan(#[from] FloorPlanError),
    /// A walk could not be read.
    #[error(transparent)]
    Walk(#[from] TraceError),
    /// A plan folder or a track row names a floor the site does not have.
    #[error("{source_name}: the site has no floor {floor:?} (its floors: {floors})")]
    UnknownFloor { source_name: String, floor: String, floors: String },
    /// A file could not be read.
    #[error("cannot read {path}: {source}")]
    Read { path: String, source: std::io::Error },
    /// The page could not be written.
    #[error("cannot write {path}: {source}")]
    Write { path: String, source: std::io::Error },
    /// A track CSV is malformed.
    #[error("{path}, line {line}: {message}")]
    Track { path: String, line: usize, message: String },
    /// A coverage file is malformed or does not fit the site.
    #[error("{path}: {message}")]
    Coverage { path: String, message: String },
    /// The salt could not be read.
    #[error("{0}")]
    Salt(String),
    /// The engine refused the site or its configuration.
    #[error(transparent)]
    Engine(#[from] waymark_engine::Error),
    /// A command-line value is out of range.
    #[error("{0}")]
    Argument(String),
    /// The data could not be turned into JSON.
    #[error("cannot encode the page's data: {0}")]
    Encode(#[from] serde_json::Error),
}

pub fn view(args: &ViewArgs) -> ExitCode {
    match write_view(args) {
        Ok(summary) => {
            eprintln!("{summary}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("waymark view: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Builds the page `args` ask for and writes it; returns a line saying what was written.
fn write_view(args: &ViewArgs) -> Result<String, ViewError> {
    let (site, track) = if args.demo {
        let (site, track) = demo(args.seed.unwrap_or(0), args.walk_length_m.unwrap_or(200.0))?;
        (site, Some(track))
    } else if args.seed.is_some() || args.walk_length_m.is_some() {
        return Err(ViewError::Argument("--seed and --walk-length-m go with --demo".into()));
    } else {
        let Some(path) = &args.site else {
            return Err(ViewError::Argument("give --site FILE or --demo".into()));
        };
        let site = Arc::new(
            Site::load(path)
                .map_err(|source| ViewError::Site { path: path.display().to_string(), source })?,
        );
        let track = match (&args.track, &args.walk) {
            (Some(csv), _) => Some(read_track_csv(csv, &site)?),
            (None, Some(walk)) => {
                let salt = args.salt.salt().map_err(ViewError::Salt)?.map(|(salt, _)| salt);
                Some(replay_walk(&site, walk, salt)?)
            }
            (None, None) => None,
        };
        (site, track)
    };
    let mut plans = vec![None; site.floors().len()];
    for dir in &args.plans {
        let name = dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let floor = floor_index(&site, &name, &dir.display().to_string())?;
        plans[floor] = Some(FloorPlan::read(dir)?);
    }
    let coverage = match &args.coverage {
        Some(path) => read_coverage(path, &site)?,
        None => Vec::new(),
    };
    let mut data = page_data(&site, &plans, track.as_ref());
    for p in &coverage {
        data.floors[p.floor].coverage.extend([cm(p.x), cm(p.y), cm(p.beyond_map_m)]);
    }
    let html = render(&data)?;
    std::fs::write(&args.out, &html)
        .map_err(|source| ViewError::Write { path: args.out.display().to_string(), source })?;
    Ok(format!(
        "{} floors, {} states{}{}; {} bytes written to {}",
        site.floors().len(),
        site.states().len(),
        track.map_or(String::new(), |t| format!(", {} epochs of {}", t.epochs.len(), t.source)),
        if args.coverage.is_some() {
            format!(", {} held-out epochs beyond the map", coverage.len())
        } else {
            String::new()
        },
        html.len(),
        args.out.display()
    ))
}

/// One epoch of a walk as the page shows it.
#[derive(Clone, Debug, PartialEq)]
struct Epoch {
    timestamp_ms: u64,
    floor: usize,
    x: f64,
    y: f64,
    accuracy_m: f64,
    /// Floor index, x and y of the truth, when known.
    truth: Option<(usize, f64, f64)>,
}

/// A walk: where its epochs came from, and the epochs in time order.
#[derive(Clone, Debug, PartialEq)]
struct Track {
    source: String,
    epochs: Vec<Epoch>,
}

/// The simulated office of `waymark demo` (its default experiment) and its first walk, tracked
/// as `waymark demo` tracks it.
fn demo(seed: u64, walk_length_m: f64) -> Result<(Arc<Site>, Track), ViewError> {
    if !(walk_length_m.is_finite() && walk_length_m > 0.0) {
        return Err(ViewError::Argument(format!("--walk-length-m must be positive, got {walk_length_m}")));
    }
    let mut experiment = experiments::Experiment::default();
    experiment.office.seed = seed;
    let office = sim::Office::generate(&experiment.office);
    let site = Arc::new(if experiment.pseudo_states {
        office.site.with_pseudo_states(PSEUDO_SPACING_M)
    } else {
        office.site.clone()
    });
    let walk_seed = experiments::walk_seed(seed, 0);
    let walk = office.walk(walk_seed, walk_length_m);
    let imu = sim::imu::synthesize(&walk.trajectory, &experiment.imu, walk_seed);
    let tracked = experiments::track_walk(&site, &experiment.engine, experiment.sensors, &walk, &imu, 0)?;
    let epochs = tracked
        .points
        .iter()
        .map(|p| Epoch {
            timestamp_ms: p.position.timestamp_ns / 1_000_000,
            floor: p.position.floor,
            x: p.position.x,
            y: p.position.y,
            accuracy_m: p.position.accuracy_m,
            truth: Some((0, p.truth.x, p.truth.y)),
        })
        .collect();
    let source = format!("a simulated walk of {:.0} m (seed {seed})", walk.length_m);
    Ok((site, Track { source, epochs }))
}

/// Replays a recorded walk with the engine `waymark replay` builds (stale readings dropped at
/// the age limit the site's survey applied, the site's calibrated γ). Its waypoints, linear
/// between them, are the truth on the floor they give (GetSensorData) or else on the site
/// floor its header names.
fn replay_walk(
    site: &Arc<Site>,
    path: &Path,
    site_salt: Option<waymark_engine::Salt>,
) -> Result<Track, ViewError> {
    let trace = waymark_survey::io::read_walk(path, site)?;
    let config = EngineConfig { rssi_weight: None, site_salt, ..EngineConfig::default() };
    let mut engine = Engine::new(Arc::clone(site), config)?;
    let replay = replaying::replay(&mut engine, &trace, &ReplayOptions::default());
    // The floor its waypoints give (a GetSensorData walk's), else the one its header names.
    let own_floors = trace.waypoints.iter().any(|w| w.floor.is_some());
    let header_floor =
        trace.floor_name.as_deref().and_then(|name| site.floors().iter().position(|f| f.name == name));
    let truth_floor = |t: u64| if own_floors { trace.floor_at(t) } else { header_floor };
    if !own_floors && header_floor.is_none() {
        eprintln!(
            "waymark view: {}: its floor ({}) is not one of the site's; the truth is left out",
            path.display(),
            trace.floor_name.as_deref().unwrap_or("not named in the header")
        );
    }
    let epochs = replay
        .positions
        .iter()
        .map(|p| Epoch {
            timestamp_ms: p.timestamp_ns / 1_000_000,
            floor: p.floor,
            x: p.x,
            y: p.y,
            accuracy_m: p.accuracy_m,
            truth: truth_floor(p.timestamp_ns)
                .filter(|&f| f < site.floors().len())
                .and_then(|f| trace.position_at(p.timestamp_ns).map(|(x, y)| (f, x, y))),
        })
        .collect();
    Ok(Track { source: format!("walk {}", trace.name), epochs })
}

/// The index of the site's floor called `name`.
fn floor_index(site: &Site, name: &str, source_name: &str) -> Result<usize, ViewError> {
    site.floors().iter().position(|f| f.name == name).ok_or_else(|| ViewError::UnknownFloor {
        source_name: source_name.to_owned(),
        floor: name.to_owned(),
        floors: site.floors().iter().map(|f| f.name.as_str()).collect::<Vec<_>>().join(", "),
    })
}

/// The fields of one CSV line; a field in double quotes may hold commas and `""`.
fn csv_fields(line: &str) -> Vec<String> {
    let mut fields = Vec::new();
    let mut field = String::new();
    let mut quoted = false;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                chars.next();
                field.push('"');
            }
            ('"', _) => quoted = !quoted,
            (',', false) => fields.push(std::mem::take(&mut field)),
            (c, _) => field.push(c),
        }
    }
    fields.push(field);
    fields
}

/// Reads a track CSV (`waymark replay --out track.csv`): the columns timestamp_ms, floor (the
/// site's floor name), x, y and accuracy_m, found by header name; other columns are ignored.
fn read_track_csv(path: &Path, site: &Site) -> Result<Track, ViewError> {
    let text = std::fs::read_to_string(path)
        .map_err(|source| ViewError::Read { path: path.display().to_string(), source })?;
    parse_track_csv(&text, &path.display().to_string(), site)
}

fn parse_track_csv(text: &str, path: &str, site: &Site) -> Result<Track, ViewError> {
    let bad = |line: usize, message: String| ViewError::Track { path: path.to_owned(), line, message };
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim_end_matches('\r')));
    let header = match lines.next() {
        Some((_, h)) if !h.trim().is_empty() => csv_fields(h),
        _ => return Err(bad(1, "no header line".into())),
    };
    let column = |name: &str| {
        header.iter().position(|h| h.trim() == name).ok_or_else(|| {
            bad(1, format!("no `{name}` column (needs timestamp_ms, floor, x, y, accuracy_m)"))
        })
    };
    let [t_col, floor_col, x_col, y_col, accuracy_col] =
        [column("timestamp_ms")?, column("floor")?, column("x")?, column("y")?, column("accuracy_m")?];
    let mut epochs: Vec<Epoch> = Vec::new();
    for (line, text) in lines.filter(|(_, l)| !l.trim().is_empty()) {
        let fields = csv_fields(text);
        if fields.len() != header.len() {
            return Err(bad(line, format!("{} fields, the header has {}", fields.len(), header.len())));
        }
        let number = |col: usize| {
            let field = fields[col].trim();
            field.parse::<f64>().ok().filter(|v| v.is_finite()).ok_or_else(|| {
                bad(line, format!("`{}` is not a finite number: {field:?}", header[col].trim()))
            })
        };
        let timestamp_ms = fields[t_col]
            .trim()
            .parse::<u64>()
            .map_err(|_| bad(line, format!("timestamp_ms is not a whole number: {:?}", fields[t_col])))?;
        if epochs.last().is_some_and(|e| timestamp_ms < e.timestamp_ms) {
            return Err(bad(line, "timestamp_ms goes back in time".into()));
        }
        let floor = floor_index(site, fields[floor_col].trim(), &format!("{path}, line {line}"))?;
        let accuracy_m = number(accuracy_col)?;
        if accuracy_m < 0.0 {
            return Err(bad(line, format!("accuracy_m is negative: {accuracy_m}")));
        }
        epochs.push(Epoch {
            timestamp_ms,
            floor,
            x: number(x_col)?,
            y: number(y_col)?,
            accuracy_m,
            truth: None,
        });
    }
    if epochs.is_empty() {
        return Err(bad(1, "no epochs after the header".into()));
    }
    let name = Path::new(path).file_name().map_or(path.to_owned(), |n| n.to_string_lossy().into_owned());
    Ok(Track { source: format!("track {name}"), epochs })
}

/// One held-out survey epoch beyond the map, from a coverage file.
#[derive(Clone, Debug, PartialEq)]
struct CoverageDot {
    floor: usize,
    x: f64,
    y: f64,
    beyond_map_m: f64,
}

/// Reads a coverage file (`waymark survey --coverage-out`): a GeoJSON FeatureCollection of
/// points in WGS84 longitude/latitude, each naming its floor and how far beyond the map it was.
fn read_coverage(path: &Path, site: &Site) -> Result<Vec<CoverageDot>, ViewError> {
    let text = std::fs::read_to_string(path)
        .map_err(|source| ViewError::Read { path: path.display().to_string(), source })?;
    parse_coverage(&text, &path.display().to_string(), site)
}

fn parse_coverage(text: &str, path: &str, site: &Site) -> Result<Vec<CoverageDot>, ViewError> {
    let bad = |message: String| ViewError::Coverage { path: path.to_owned(), message };
    if site.anchor().is_none() {
        return Err(bad(
            "the site is not geo-referenced (no anchor), so WGS84 points have no place on it".into()
        ));
    }
    let collection = match text.parse::<geojson::GeoJson>() {
        Ok(geojson::GeoJson::FeatureCollection(c)) => c,
        Ok(_) => return Err(bad("not a GeoJSON FeatureCollection".into())),
        Err(e) => return Err(bad(format!("not GeoJSON: {e}"))),
    };
    let mut dots = Vec::with_capacity(collection.features.len());
    for (k, feature) in collection.features.iter().enumerate() {
        let at = |message: &str| bad(format!("feature {k}: {message}"));
        let [lon, lat] = match feature.geometry.as_ref().map(|g| &g.value) {
            Some(geojson::Value::Point(p)) if p.len() >= 2 => [p[0], p[1]],
            _ => return Err(at("not a Point")),
        };
        let name = feature.property("floor").and_then(|v| v.as_str()).ok_or_else(|| at("no `floor` name"))?;
        let floor = floor_index(site, name, &format!("{path}, feature {k}"))?;
        let beyond_map_m = feature
            .property("beyond_map_m")
            .and_then(|v| v.as_f64())
            .filter(|b| b.is_finite() && *b >= 0.0)
            .ok_or_else(|| at("`beyond_map_m` is not a distance"))?;
        let point = LatLon::new(lat, lon)
            .and_then(|p| site.site_point(Some(floor), p))
            .map_err(|e| at(&e.to_string()))?;
        dots.push(CoverageDot { floor, x: point.x, y: point.y, beyond_map_m });
    }
    Ok(dots)
}

/// What the page's script reads, as JSON. Coordinates are metres in the site's frame, rounded
/// to centimetres; per-state arrays are flat, for size.
#[derive(Serialize)]
struct PageData {
    title: String,
    /// The site's state spacing, m: the size of the cell a state stands for.
    spacing_m: f64,
    floors: Vec<FloorView>,
    zones: Vec<ZoneView>,
    track: Option<TrackView>,
}

#[derive(Serialize)]
struct FloorView {
    name: String,
    /// x0, y0, x1, y1, ... of the floor's states.
    states: Vec<f64>,
    /// Per state: 0 surveyed, 1 pseudo, 2 unsurveyed.
    kinds: Vec<u8>,
    /// Per state: its zone's index into `zones`, or -1.
    zones: Vec<i64>,
    /// Pairs of indices into this floor's states: the walkable graph on the floor.
    edges: Vec<u32>,
    /// This floor's states with an edge to another floor (stairs, lifts).
    connectors: Vec<u32>,
    /// x0, y0, beyond0, x1, ...: held-out survey epochs beyond the map and how far, m.
    coverage: Vec<f64>,
    plan: Option<PlanView>,
}

#[derive(Serialize)]
struct PlanView {
    /// Polygons, each rings of x0, y0, x1, y1, ... (the first ring the outside).
    outline: Vec<Vec<Vec<f64>>>,
    rooms: Vec<Vec<Vec<f64>>>,
}

#[derive(Serialize)]
struct ZoneView {
    name: String,
    kind: waymark_engine::ZoneKind,
}

#[derive(Serialize)]
struct TrackView {
    source: String,
    /// Per epoch: seconds since the first, floor index, x, y, 68% radius, then the truth's
    /// floor index, x and y, or three nulls.
    epochs: Vec<[Option<f64>; 8]>,
}

fn cm(v: f64) -> f64 {
    (v * 100.0).round() / 100.0
}

fn page_data(site: &Site, plans: &[Option<FloorPlan>], track: Option<&Track>) -> PageData {
    // Each state's index among its floor's states.
    let mut local = vec![0u32; site.states().len()];
    let mut floors: Vec<FloorView> = site
        .floors()
        .iter()
        .map(|f| FloorView {
            name: f.name.clone(),
            states: Vec::new(),
            kinds: Vec::new(),
            zones: Vec::new(),
            edges: Vec::new(),
            connectors: Vec::new(),
            coverage: Vec::new(),
            plan: None,
        })
        .collect();
    for (i, s) in site.states().iter().enumerate() {
        let f = &mut floors[s.floor];
        local[i] = f.kinds.len() as u32;
        f.states.extend([cm(s.position.x), cm(s.position.y)]);
        f.kinds.push(match s.kind {
            StateKind::Surveyed => 0,
            StateKind::Pseudo => 1,
            StateKind::Unsurveyed => 2,
        });
        f.zones.push(site.zone_of(i).map_or(-1, |z| z as i64));
    }
    for e in site.edges() {
        let (a, b) = (e.a as usize, e.b as usize);
        let (fa, fb) = (site.states()[a].floor, site.states()[b].floor);
        if fa == fb {
            floors[fa].edges.extend([local[a], local[b]]);
        } else {
            floors[fa].connectors.push(local[a]);
            floors[fb].connectors.push(local[b]);
        }
    }
    for f in &mut floors {
        f.connectors.sort_unstable();
        f.connectors.dedup();
    }
    let rings = |p: &waymark_survey::io::floor_plan::Polygon| -> Vec<Vec<f64>> {
        p.rings.iter().map(|r| r.iter().flat_map(|q| [cm(q.x), cm(q.y)]).collect()).collect()
    };
    for (f, plan) in floors.iter_mut().zip(plans) {
        f.plan = plan.as_ref().map(|p| PlanView {
            outline: p.outline.iter().map(rings).collect(),
            rooms: p.rooms.iter().map(|r| rings(&r.polygon)).collect(),
        });
    }
    let track = track.map(|t| {
        let t0 = t.epochs.first().map_or(0, |e| e.timestamp_ms);
        let epochs = t
            .epochs
            .iter()
            .map(|e| {
                let (tf, tx, ty) = match e.truth {
                    Some((f, x, y)) => (Some(f as f64), Some(cm(x)), Some(cm(y))),
                    None => (None, None, None),
                };
                [
                    Some((e.timestamp_ms - t0) as f64 / 1000.0),
                    Some(e.floor as f64),
                    Some(cm(e.x)),
                    Some(cm(e.y)),
                    Some(cm(e.accuracy_m)),
                    tf,
                    tx,
                    ty,
                ]
            })
            .collect();
        TrackView { source: t.source.clone(), epochs }
    });
    PageData {
        title: site.name().to_owned(),
        spacing_m: site.spacing_m(),
        floors,
        zones: site.zones().iter().map(|z| ZoneView { name: z.name.clone(), kind: z.kind }).collect(),
        track,
    }
}

/// The page: the template with the style, the data and the script inlined. The JSON's `<`,
/// `>` and `&` are escaped (`\u003c`...), so no name in it can close the script element.
fn render(data: &PageData) -> Result<String, serde_json::Error> {
    let json =
        serde_json::to_string(data)?.replace('<', "\\u003c").replace('>', "\\u003e").replace('&', "\\u0026");
    Ok(TEMPLATE
        .replacen("{{style}}", STYLE, 1)
        .replacen("{{script}}", SCRIPT, 1)
        .replacen("{{data}}", &json, 1))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point2;
    use waymark_engine::site::{Anchor, BuildOptions, SiteBuilder, TrainingScan};
    use waymark_engine::ZoneKind;

    /// Two floors of two states, a stair edge between them, one zone per floor.
    fn site() -> Site {
        let mut b = SiteBuilder::new("two <floors> & more");
        let ground = b.floor("G", 0.0);
        let first = b.floor("1", 4.0);
        let scans = || -> Vec<TrainingScan> { Vec::new() };
        let a = b.state(ground, Point2::new(0.0, 0.0), scans());
        let c = b.state(ground, Point2::new(3.0, 0.0), scans());
        let d = b.state(first, Point2::new(3.0, 0.0), scans());
        let e = b.state(first, Point2::new(3.0, 3.0), scans());
        b.edge(a, c, None);
        b.edge(c, d, Some(5.0));
        b.edge(d, e, None);
        b.zone("hall </script>", ZoneKind::Hall, vec![a, c]);
        b.zone("office", ZoneKind::Room, vec![d, e]);
        b.build(BuildOptions::default()).expect("a valid site")
    }

    #[test]
    fn the_template_has_each_slot_once_and_the_script_cannot_close_its_element() {
        for slot in ["{{style}}", "{{data}}", "{{script}}"] {
            assert_eq!(TEMPLATE.matches(slot).count(), 1, "{slot}");
        }
        assert!(!SCRIPT.to_lowercase().contains("</script"));
        assert!(!STYLE.to_lowercase().contains("</style"));
    }

    #[test]
    fn states_edges_connectors_and_zones_go_to_their_floors() {
        let site = site();
        let data = page_data(&site, &[None, None], None);
        assert_eq!(data.floors.len(), 2);
        let (g, f) = (&data.floors[0], &data.floors[1]);
        assert_eq!(
            (g.states.as_slice(), f.states.as_slice()),
            (&[0.0, 0.0, 3.0, 0.0][..], &[3.0, 0.0, 3.0, 3.0][..])
        );
        assert_eq!((g.edges.as_slice(), f.edges.as_slice()), (&[0, 1][..], &[0, 1][..]));
        assert_eq!((g.connectors.as_slice(), f.connectors.as_slice()), (&[1][..], &[0][..]));
        assert_eq!((g.zones.as_slice(), f.zones.as_slice()), (&[0, 0][..], &[1, 1][..]));
        assert_eq!(data.zones[1].name, "office");
    }

    #[test]
    fn names_in_the_data_cannot_break_out_of_the_page() {
        let html = render(&page_data(&site(), &[None, None], None)).unwrap();
        assert!(!html.contains("hall </script>"));
        assert!(html.contains("hall \\u003c/script\\u003e"));
        assert_eq!(html.to_lowercase().matches("</script>").count(), 2, "the data and the script elements");
    }

    #[test]
    fn a_track_csv_is_read_by_column_name_and_unknown_columns_are_ignored() {
        let site = site();
        let csv = "lat,timestamp_ms,x,floor,y,accuracy_m,scenario\n\
                   30.1,1000,1.5,G,0.25,2.5,DistanceHeading\n\
                   30.2,2500,3,\"1\",3,1.75,\"a, b\"\n";
        let track = parse_track_csv(csv, "t.csv", &site).unwrap();
        assert_eq!(track.epochs.len(), 2);
        assert_eq!(
            track.epochs[1],
            Epoch { timestamp_ms: 2500, floor: 1, x: 3.0, y: 3.0, accuracy_m: 1.75, truth: None }
        );
        let data = page_data(&site, &[None, None], Some(&track));
        let epochs = data.track.unwrap().epochs;
        assert_eq!(epochs[1][..5], [Some(1.5), Some(1.0), Some(3.0), Some(3.0), Some(1.75)]);
    }

    fn anchored() -> Site {
        let anchor = Anchor { lat_deg: 30.19, lon_deg: 120.08, azimuth_rad: 0.3, scale: [1.0, 1.0] };
        site().with_anchor(Some(anchor)).expect("a valid anchor")
    }

    /// A coverage feature as `waymark survey --coverage-out` writes it.
    fn dot(site: &Site, floor: usize, x: f64, y: f64, beyond_map_m: f64) -> serde_json::Value {
        let at = site.lat_lon(floor, x, y).expect("an anchored site");
        serde_json::json!({
            "type": "Feature",
            "geometry": { "type": "Point", "coordinates": [at.lon_deg, at.lat_deg] },
            "properties": { "floor": site.floors()[floor].name, "level": null, "walk": "w1",
                            "beyond_map_m": beyond_map_m, "error_m": 9.5 },
        })
    }

    fn collection(features: Vec<serde_json::Value>) -> String {
        serde_json::json!({ "type": "FeatureCollection", "features": features }).to_string()
    }

    #[test]
    fn coverage_points_land_on_their_floors_in_the_site_frame() {
        let site = anchored();
        let text = collection(vec![dot(&site, 0, 12.5, -3.25, 4.0), dot(&site, 1, 0.5, 40.0, 0.75)]);
        let dots = parse_coverage(&text, "c.geojson", &site).unwrap();
        assert_eq!(dots.len(), 2);
        for (d, (floor, x, y, beyond)) in dots.iter().zip([(0, 12.5, -3.25, 4.0), (1, 0.5, 40.0, 0.75)]) {
            assert_eq!((d.floor, d.beyond_map_m), (floor, beyond));
            assert!((d.x - x).abs() < 1e-6 && (d.y - y).abs() < 1e-6, "{d:?}");
        }
        assert!(parse_coverage(&collection(Vec::new()), "c.geojson", &site).unwrap().is_empty());
    }

    #[test]
    fn a_bad_coverage_file_is_an_error_naming_the_feature() {
        let site = anchored();
        let good = dot(&site, 0, 1.0, 1.0, 2.0);
        let with = |edit: &dyn Fn(&mut serde_json::Value)| {
            let mut f = good.clone();
            edit(&mut f);
            collection(vec![good.clone(), f])
        };
        for (text, needle) in [
            ("{".to_string(), "not GeoJSON"),
            (r#"{"type": "Feature", "geometry": null, "properties": {}}"#.to_string(), "FeatureCollection"),
            (r#"{"type": "FeatureCollection"}"#.to_string(), "not GeoJSON"),
            (
                with(&|f| {
                    f["geometry"] = serde_json::json!({"type": "LineString", "coordinates": [[0, 0], [1, 1]]})
                }),
                "feature 1: not a Point",
            ),
            (
                with(&|f| f["geometry"]["coordinates"] = serde_json::json!([120.0, 95.0])),
                "feature 1: invalid latitude",
            ),
            (with(&|f| f["properties"]["beyond_map_m"] = (-1.0).into()), "feature 1: `beyond_map_m`"),
            (with(&|f| f["properties"]["floor"] = serde_json::Value::Null), "feature 1: no `floor`"),
        ] {
            match parse_coverage(&text, "c.geojson", &site) {
                Err(ViewError::Coverage { message, .. }) => {
                    assert!(message.contains(needle), "{text}: {message}")
                }
                other => panic!("{text}: {other:?}"),
            }
        }
        match parse_coverage(&with(&|f| f["properties"]["floor"] = "B7".into()), "c.geojson", &site) {
            Err(ViewError::UnknownFloor { floor, source_name, .. }) => {
                assert_eq!((floor.as_str(), source_name.as_str()), ("B7", "c.geojson, feature 1"))
            }
            other => panic!("{other:?}"),
        }
        let text = collection(vec![good.clone()]);
        match parse_coverage(&text, "c.geojson", &self::site()) {
            Err(ViewError::Coverage { message, .. }) => {
                assert!(message.contains("not geo-referenced"), "{message}")
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_bad_track_csv_is_an_error_with_its_line() {
        let site = site();
        let header = "timestamp_ms,floor,x,y,accuracy_m\n";
        for (csv, line, needle) in [
            ("", 1, "no header"),
            ("timestamp_ms,floor,x,y\n1,G,0,0\n", 1, "accuracy_m"),
            (header, 1, "no epochs"),
            (&format!("{header}1,G,0,0\n"), 2, "4 fields"),
            (&format!("{header}1,G,0,NaN,1\n"), 2, "finite"),
            (&format!("{header}-1,G,0,0,1\n"), 2, "whole number"),
            (&format!("{header}5,G,0,0,1\n4,G,0,0,1\n"), 3, "back in time"),
            (&format!("{header}1,G,0,0,-1\n"), 2, "negative"),
        ] {
            match parse_track_csv(csv, "t.csv", &site) {
                Err(ViewError::Track { line: l, message, .. }) => {
                    assert_eq!(l, line, "{csv:?}: {message}");
                    assert!(message.contains(needle), "{csv:?}: {message}");
                }
                other => panic!("{csv:?}: {other:?}"),
            }
        }
        match parse_track_csv(&format!("{header}1,B7,0,0,1\n"), "t.csv", &site) {
            Err(ViewError::UnknownFloor { floor, floors, .. }) => {
                assert_eq!((floor.as_str(), floors.as_str()), ("B7", "G, 1"))
            }
            other => panic!("{other:?}"),
        }
    }
}
