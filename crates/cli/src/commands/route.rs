//! `waymark route`: the shortest walkable route on a site file (or the demo's simulated office)
//! from a point to a point or a zone, as legs with turns (docs/routes.md).

use std::process::ExitCode;
use waymark_engine::route::{Destination, FloorPoint, Route};
use waymark_engine::site::Site;
use waymark_sim as sim;

#[derive(clap::Args)]
#[command(group(clap::ArgGroup::new("source").required(true).args(["site", "demo"])))]
#[command(group(clap::ArgGroup::new("target").required(true).args(["to", "zone"])))]
pub struct RouteArgs {
    /// The site file (JSON or binary).
    site: Option<std::path::PathBuf>,
    /// Route on the built-in simulated office of `waymark demo` instead of a site file.
    #[arg(long)]
    demo: bool,
    /// Seed of the demo's office.
    #[arg(long, default_value_t = 0, requires = "demo")]
    seed: u64,
    /// Where from: FLOOR:X,Y, the floor by name or index, x and y in site metres.
    #[arg(long)]
    from: String,
    /// Where to: FLOOR:X,Y.
    #[arg(long)]
    to: Option<String>,
    /// Where to: a zone of the site, by name.
    #[arg(long)]
    zone: Option<String>,
    /// Print one JSON object instead of the legs.
    #[arg(long)]
    json: bool,
}

/// A point given as FLOOR:X,Y, the floor by name (first) or index.
fn parse_point(site: &Site, text: &str) -> Result<FloorPoint, String> {
    let bad = || format!("{text:?} is not FLOOR:X,Y (a floor name or index, then x and y in metres)");
    let (floor, xy) = text.rsplit_once(':').ok_or_else(bad)?;
    let (x, y) = xy.split_once(',').ok_or_else(bad)?;
    let (x, y): (f64, f64) = (x.trim().parse().map_err(|_| bad())?, y.trim().parse().map_err(|_| bad())?);
    let floor =
        site.floors().iter().position(|f| f.name == floor).or_else(|| floor.parse().ok()).ok_or_else(
            || {
                let names: Vec<&str> = site.floors().iter().map(|f| f.name.as_str()).collect();
                format!("no floor {floor:?} (floors: {})", names.join(", "))
            },
        )?;
    Ok(FloorPoint::new(floor, x, y))
}

fn floor_name(site: &Site, floor: usize) -> String {
    site.floors().get(floor).map_or_else(|| floor.to_string(), |f| f.name.clone())
}

fn to_json(site: &Site, route: &Route) -> serde_json::Value {
    let point = |p: &FloorPoint| serde_json::json!({"floor": p.floor, "floor_name": floor_name(site, p.floor), "x": p.x, "y": p.y});
    let legs: Vec<serde_json::Value> = route
        .legs()
        .iter()
        .map(|l| {
            serde_json::json!({
                "floor": l.floor,
                "to_floor": l.to_floor,
                "floor_change": l.is_floor_change(),
                "distance_m": l.distance_m,
                "turn": l.turn.map(|t| t.name()),
                "turn_deg": l.turn_angle_rad.map(f64::to_degrees),
                "start": point(&route.points()[l.first]),
                "end": point(&route.points()[l.last]),
            })
        })
        .collect();
    serde_json::json!({
        "site": site.name(),
        "length_m": route.length_m(),
        "start": point(&route.start()),
        "end": point(&route.end()),
        "start_snap_m": route.start_snap_m(),
        "end_snap_m": route.end_snap_m(),
        "legs": legs,
    })
}

fn print(site: &Site, route: &Route, target: &str) {
    let (start, end) = (route.start(), route.end());
    println!(
        "Route on {:?} from ({:.2}, {:.2}) on {} ({:.2} m from where asked) to {target} at ({:.2}, {:.2}) on {}:",
        site.name(),
        start.x,
        start.y,
        floor_name(site, start.floor),
        route.start_snap_m(),
        end.x,
        end.y,
        floor_name(site, end.floor),
    );
    if route.legs().is_empty() {
        println!("  already there");
    }
    for (k, leg) in route.legs().iter().enumerate() {
        let to = route.points()[leg.last];
        let what = if leg.is_floor_change() {
            format!(
                "change floor from {} to {}, {:.1} m",
                floor_name(site, leg.floor),
                floor_name(site, leg.to_floor),
                leg.distance_m
            )
        } else {
            let turn = match (k, leg.turn) {
                (0, _) => "start".to_owned(),
                (_, None) => "leave the stairs or lift".to_owned(),
                (_, Some(t)) => format!(
                    "turn {} ({:+.0}°)",
                    t.name().replace('_', " "),
                    leg.turn_angle_rad.unwrap_or(0.0).to_degrees()
                ),
            };
            format!("{turn}, walk {:.1} m to ({:.2}, {:.2})", leg.distance_m, to.x, to.y)
        };
        println!("  {:>2}. {what}", k + 1);
    }
    println!("Total {:.1} m in {} legs", route.length_m(), route.legs().len());
}

/// Runs `waymark route`.
pub fn route(args: &RouteArgs) -> ExitCode {
    let site = match &args.site {
        Some(path) => match Site::load(path) {
            Ok(site) => site,
            Err(e) => {
                eprintln!("waymark route: {}: {e}", path.display());
                return ExitCode::FAILURE;
            }
        },
        None => {
            sim::Office::generate(&sim::OfficeConfig { seed: args.seed, ..sim::OfficeConfig::default() }).site
        }
    };
    let planned = parse_point(&site, &args.from).and_then(|from| {
        let (to, target) = match (&args.to, &args.zone) {
            (Some(to), _) => {
                let p = parse_point(&site, to)?;
                (Destination::Point(p), format!("({}, {}) on {}", p.x, p.y, floor_name(&site, p.floor)))
            }
            (None, Some(zone)) => (Destination::Zone(zone.clone()), format!("zone {zone:?}")),
            (None, None) => return Err("give --to or --zone".to_owned()),
        };
        Route::plan(&site, &from, &to).map(|r| (r, target)).map_err(|e| e.to_string())
    });
    match planned {
        Ok((route, target)) => {
            if args.json {
                println!("{}", to_json(&site, &route));
            } else {
                print(&site, &route, &target);
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("waymark route: {e}");
            ExitCode::FAILURE
        }
    }
}
