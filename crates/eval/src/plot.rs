//! SVG plots of evaluated walks: the track over the floor plan ([`plot_walk`]) and the error
//! CDF per configuration ([`plot_cdf`]).
//!
//! Text needs no font: without plotters' `ttf` / `ab_glyph` features its "naive" font only
//! estimates text extents for the layout and the SVG backend writes plain `<text>` elements,
//! which the viewer renders with whatever font it has. So nothing here reads a font file or
//! links a system library (fontconfig, freetype).
//!
//! Bad input is skipped, never a panic: points with a non-finite or absurd coordinate (beyond
//! [`MAX_COORDINATE`]) and negative or non-finite errors. Empty inputs still give a valid SVG
//! with axes, title and legend.

use plotters::coord::Shift;
use plotters::prelude::*;
use std::ops::Range;
use std::path::{Path, PathBuf};
use waymark_survey::io::FloorPlan;

/// Coordinates (m) and errors beyond this are treated as bad input and skipped: far outside
/// any building, and large enough that axis arithmetic would lose all precision.
pub const MAX_COORDINATE: f64 = 1e7;

/// Canvas width, px; the walk plot's height follows the plan's aspect ratio.
const WIDTH_PX: u32 = 1000;
/// The CDF plot's height, px.
const CDF_HEIGHT_PX: u32 = 600;
/// Space around the chart and for the axes' labels, px.
const MARGIN_PX: u32 = 15;
const X_LABEL_AREA_PX: u32 = 45;
const Y_LABEL_AREA_PX: u32 = 60;
const TITLE_FONT: (&str, u32) = ("sans-serif", 22);
const LABEL_FONT: (&str, u32) = ("sans-serif", 14);

/// One estimated track to draw over the truth.
#[derive(Clone, Copy, Debug)]
pub struct Track<'a> {
    /// Its legend entry.
    pub label: &'a str,
    /// Positions in the plan's frame, m, in time order.
    pub points: &'a [(f64, f64)],
}

/// Why a plot could not be made.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The SVG file could not be written.
    #[error("cannot write {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// plotters failed to lay out or draw the chart.
    #[error("cannot draw {path}: {message}")]
    Draw {
        /// The file it was for.
        path: PathBuf,
        /// plotters' message.
        message: String,
    },
}

fn usable(v: f64) -> bool {
    v.is_finite() && v.abs() <= MAX_COORDINATE
}

fn good_points(points: &[(f64, f64)]) -> Vec<(f64, f64)> {
    points.iter().copied().filter(|&(x, y)| usable(x) && usable(y)).collect()
}

/// The closed rings of the plan's outline and rooms, bad points dropped, as polylines.
fn plan_rings(plan: &FloorPlan) -> Vec<Vec<(f64, f64)>> {
    plan.outline
        .iter()
        .chain(plan.rooms.iter().map(|r| &r.polygon))
        .flat_map(|polygon| &polygon.rings)
        .filter_map(|ring| {
            let mut points: Vec<(f64, f64)> =
                ring.iter().map(|p| (p.x, p.y)).filter(|&(x, y)| usable(x) && usable(y)).collect();
            if points.len() < 2 {
                return None;
            }
            if points.first() != points.last() {
                points.push(points[0]);
            }
            Some(points)
        })
        .collect()
}

/// The `i`-th track's colour; the truth is black.
fn track_color(i: usize) -> RGBColor {
    // Okabe–Ito, distinguishable with the common colour-vision deficiencies.
    const COLORS: [RGBColor; 7] = [
        RGBColor(230, 159, 0),
        RGBColor(86, 180, 233),
        RGBColor(0, 158, 115),
        RGBColor(213, 94, 0),
        RGBColor(0, 114, 178),
        RGBColor(204, 121, 167),
        RGBColor(240, 228, 66),
    ];
    COLORS[i % COLORS.len()]
}

/// Renders into a string with `draw`, then writes `path`: plotters' own file output would
/// only report a failed write from `Drop`, where it is ignored.
fn render(
    path: &Path,
    size: (u32, u32),
    draw: impl FnOnce(&DrawingArea<SVGBackend, Shift>) -> Result<(), String>,
) -> Result<(), PlotError> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        draw(&root).map_err(|message| PlotError::Draw { path: path.to_owned(), message })?;
        root.present().map_err(|e| PlotError::Draw { path: path.to_owned(), message: e.to_string() })?;
    }
    std::fs::write(path, svg).map_err(|source| PlotError::Io { path: path.to_owned(), source })
}

/// `lo..hi` widened so that it is not empty.
fn span(lo: f64, hi: f64, min_span: f64) -> (f64, f64) {
    if lo.is_nan() || hi.is_nan() || lo > hi {
        return (0.0, min_span);
    }
    let missing = (min_span - (hi - lo)).max(0.0);
    (lo - missing / 2.0, hi + missing / 2.0)
}

/// One walk: the floor plan (outline and rooms, grey; may be `None`), the truth polyline with
/// its waypoints marked (black), and one line per estimated track, with a legend; x and y on
/// the same scale, m.
pub fn plot_walk(
    path: &Path,
    title: &str,
    plan: Option<&FloorPlan>,
    truth: &[(f64, f64)],
    tracks: &[Track],
) -> Result<(), PlotError> {
    let rings = plan.map(plan_rings).unwrap_or_default();
    let truth = good_points(truth);
    let tracks: Vec<(&str, Vec<(f64, f64)>)> =
        tracks.iter().map(|t| (t.label, good_points(t.points))).collect();

    // The frame: the plan's rectangle and everything drawn.
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    let mut include = |(x, y): (f64, f64)| {
        lo = [lo[0].min(x), lo[1].min(y)];
        hi = [hi[0].max(x), hi[1].max(y)];
    };
    if let Some(plan) = plan.filter(|p| usable(p.width_m) && usable(p.height_m)) {
        include((0.0, 0.0));
        include((plan.width_m, plan.height_m));
    }
    rings.iter().flatten().chain(&truth).chain(tracks.iter().flat_map(|t| &t.1)).copied().for_each(include);
    let (x0, x1) = span(lo[0], hi[0], 1.0);
    let (y0, y1) = span(lo[1], hi[1], 1.0);
    // 3% padding so lines on the frame stay visible.
    let pad = 0.03 * (x1 - x0).max(y1 - y0);
    let (x0, x1, y0, y1) = (x0 - pad, x1 + pad, y0 - pad, y1 + pad);

    // The canvas height that makes metres per pixel equal on both axes, within reason; the
    // ranges are then widened to make the scale exactly equal.
    let plot_w = f64::from(WIDTH_PX - 2 * MARGIN_PX - Y_LABEL_AREA_PX);
    let chrome_h = 2 * MARGIN_PX + X_LABEL_AREA_PX + 2 * TITLE_FONT.1;
    let plot_h = (plot_w * (y1 - y0) / (x1 - x0)).clamp(250.0, 1400.0);
    let height = chrome_h + plot_h.round() as u32;

    render(path, (WIDTH_PX, height), |root| {
        let err = |e: &dyn std::fmt::Display| e.to_string();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let area = root.titled(title, TITLE_FONT).map_err(|e| err(&e))?;
        let build = |x: Range<f64>, y: Range<f64>| {
            ChartBuilder::on(&area)
                .margin(MARGIN_PX)
                .x_label_area_size(X_LABEL_AREA_PX)
                .y_label_area_size(Y_LABEL_AREA_PX)
                .build_cartesian_2d(x, y)
                .map_err(|e| err(&e))
        };
        // Building draws nothing: the first build only measures the plotting area.
        let (w_px, h_px) = build(0.0..1.0, 0.0..1.0)?.plotting_area().dim_in_pixel();
        let m_per_px = ((x1 - x0) / f64::from(w_px.max(1))).max((y1 - y0) / f64::from(h_px.max(1)));
        let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
        let (half_w, half_h) = (m_per_px * f64::from(w_px) / 2.0, m_per_px * f64::from(h_px) / 2.0);
        let mut chart = build(cx - half_w..cx + half_w, cy - half_h..cy + half_h)?;
        chart
            .configure_mesh()
            .x_desc("x (m)")
            .y_desc("y (m)")
            .label_style(LABEL_FONT)
            .light_line_style(WHITE)
            .draw()
            .map_err(|e| err(&e))?;

        let wall = RGBColor(150, 150, 150).stroke_width(1);
        chart.draw_series(rings.iter().map(|r| PathElement::new(r.clone(), wall))).map_err(|e| err(&e))?;

        for (i, (label, points)) in tracks.iter().enumerate() {
            let style = track_color(i).stroke_width(2);
            chart
                .draw_series(std::iter::once(PathElement::new(points.clone(), style)))
                .map_err(|e| err(&e))?
                .label(*label)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
        }
        // The truth last, on top.
        let style = BLACK.stroke_width(2);
        chart
            .draw_series(std::iter::once(PathElement::new(truth.clone(), style)))
            .map_err(|e| err(&e))?
            .label("truth")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
        chart.draw_series(truth.iter().map(|&p| Circle::new(p, 4, BLACK.filled()))).map_err(|e| err(&e))?;

        chart
            .configure_series_labels()
            .label_font(LABEL_FONT)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(|e| err(&e))?;
        Ok(())
    })
}

/// The empirical CDF of `errors` as a staircase: at each sorted error the share rises by
/// 1/n. Negative and non-finite errors are skipped.
fn ecdf(errors: &[f64]) -> Vec<(f64, f64)> {
    let mut sorted: Vec<f64> = errors.iter().copied().filter(|&e| usable(e) && e >= 0.0).collect();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len() as f64;
    let mut points = Vec::with_capacity(2 * sorted.len());
    for (i, &e) in sorted.iter().enumerate() {
        points.push((e, i as f64 / n));
        points.push((e, (i + 1) as f64 / n));
    }
    points
}

/// The error CDF per configuration: x = error (m), y = share of epochs with an error ≤ x,
/// one line per `(label, errors)` curve, with a legend.
pub fn plot_cdf(path: &Path, title: &str, curves: &[(&str, &[f64])]) -> Result<(), PlotError> {
    let curves: Vec<(&str, Vec<(f64, f64)>)> = curves.iter().map(|(label, e)| (*label, ecdf(e))).collect();
    let max_error = curves.iter().flat_map(|c| &c.1).map(|p| p.0).fold(0.0, f64::max);
    let x_max = (max_error * 1.05).max(0.1);

    render(path, (WIDTH_PX, CDF_HEIGHT_PX), |root| {
        let err = |e: &dyn std::fmt::Display| e.to_string();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let area = root.titled(title, TITLE_FONT).map_err(|e| err(&e))?;
        let mut chart = ChartBuilder::on(&area)
            .margin(MARGIN_PX)
            .x_label_area_size(X_LABEL_AREA_PX)
            .y_label_area_size(Y_LABEL_AREA_PX)
            .build_cartesian_2d(0.0..x_max, 0.0..1.0)
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc("error (m)")
            .y_desc("share of epochs with error ≤ x")
            .label_style(LABEL_FONT)
            .light_line_style(WHITE)
            .draw()
            .map_err(|e| err(&e))?;
        for (i, (label, points)) in curves.iter().enumerate() {
            // Each staircase runs on to the right edge, where every curve has reached 1.
            let mut points = points.clone();
            if let Some(&(_, share)) = points.last() {
                points.push((x_max, share));
            }
            let style = track_color(i).stroke_width(2);
            chart
                .draw_series(std::iter::once(PathElement::new(points, style)))
                .map_err(|e| err(&e))?
                .label(*label)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
        }
        chart
            .configure_series_labels()
            .label_font(LABEL_FONT)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::LowerRight)
            .draw()
            .map_err(|e| err(&e))?;
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fresh directory under the system's temp dir.
    fn temp_dir(name: &str) -> PathBuf {
        use std::sync::atomic::{AtomicU32, Ordering};
        static NEXT: AtomicU32 = AtomicU32::new(0);
        let unique = format!(
            "waymark-plot-{name}-{}-{}-{}",
            std::process::id(),
            NEXT.fetch_add(1, Ordering::Relaxed),
            std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos())
        );
        let dir = std::env::temp_dir().join(unique);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// Checks `svg` is well-formed XML with an `<svg>` root (tags balanced, attributes
    /// quoted) and returns each element's name, in document order.
    fn svg_elements(svg: &str) -> Vec<String> {
        let mut stack: Vec<String> = Vec::new();
        let mut elements = Vec::new();
        let mut rest = svg;
        while let Some(start) = rest.find('<') {
            let end = rest[start..].find('>').expect("unterminated tag") + start;
            let tag = &rest[start + 1..end];
            rest = &rest[end + 1..];
            if tag.starts_with('?') || tag.starts_with('!') {
                continue;
            }
            assert_eq!(tag.matches('"').count() % 2, 0, "unbalanced quotes in <{tag}>");
            if let Some(name) = tag.strip_prefix('/') {
                assert_eq!(stack.pop().as_deref(), Some(name.trim()), "mismatched </{name}>");
                continue;
            }
            let name: String = tag.chars().take_while(|c| !c.is_whitespace() && *c != '/').collect();
            assert!(!name.is_empty(), "empty tag");
            if elements.is_empty() {
                assert_eq!(name, "svg", "the root element must be <svg>");
            } else {
                assert!(!stack.is_empty(), "<{name}> after the root closed");
            }
            elements.push(name.clone());
            if !tag.ends_with('/') {
                stack.push(name);
            }
        }
        assert!(stack.is_empty(), "unclosed {stack:?}");
        assert!(!elements.is_empty(), "no <svg> root");
        elements
    }

    fn count(elements: &[String], name: &str) -> usize {
        elements.iter().filter(|e| *e == name).count()
    }

    /// The text of every `<text>` element.
    fn texts(svg: &str) -> Vec<String> {
        svg.split("<text")
            .skip(1)
            .map(|t| t[t.find('>').unwrap() + 1..t.find("</text>").unwrap()].trim().to_owned())
            .collect()
    }

    /// The `<polyline>`s with this attribute, such as `stroke-width="2"` (the data lines and
    /// their legend marks; the axes and ticks are 1 px) or the plan's grey.
    fn polylines(svg: &str, attribute: &str) -> usize {
        svg.split('<').filter(|tag| tag.starts_with("polyline ") && tag.contains(attribute)).count()
    }

    const DATA: &str = "stroke-width=\"2\"";
    const WALL: &str = "stroke=\"#969696\"";

    fn square_plan() -> FloorPlan {
        use nalgebra::Point2;
        use waymark_survey::io::floor_plan::{Polygon, Room};
        let square = |x0: f64, y0: f64, s: f64| Polygon {
            rings: vec![vec![
                Point2::new(x0, y0),
                Point2::new(x0 + s, y0),
                Point2::new(x0 + s, y0 + s),
                Point2::new(x0, y0 + s),
            ]],
        };
        FloorPlan {
            width_m: 40.0,
            height_m: 40.0,
            outline: vec![square(0.0, 0.0, 40.0)],
            rooms: vec![
                Room { name: "shop".into(), polygon: square(0.0, 0.0, 10.0) },
                Room { name: "broken".into(), polygon: square(f64::NAN, f64::NAN, 10.0) },
            ],
            ..FloorPlan::default()
        }
    }

    #[test]
    fn walk_plot_has_the_plan_the_truth_the_tracks_and_the_legend() {
        let dir = temp_dir("walk");
        let file = dir.join("walk.svg");
        let truth = [(5.0, 5.0), (f64::NAN, 3.0), (30.0, 5.0), (30.0, 30.0)];
        let hmm = [(5.5, 5.0), (29.0, 6.0), (f64::INFINITY, 0.0), (31.0, 29.0)];
        let raw = [(6.0, 4.0), (1e300, 1.0), (28.0, 7.0)];
        let tracks = [Track { label: "hmm", points: &hmm }, Track { label: "radio only", points: &raw }];
        plot_walk(&file, "walk 7", Some(&square_plan()), &truth, &tracks).unwrap();
        let svg = std::fs::read_to_string(&file).unwrap();
        let elements = svg_elements(&svg);
        // Two plan rings (the NaN room is dropped), truth and two tracks, three legend marks.
        assert_eq!(polylines(&svg, WALL), 2);
        assert_eq!(polylines(&svg, DATA), 3 + 3);
        assert_eq!(count(&elements, "circle"), 3, "one mark per good waypoint");
        let texts = texts(&svg);
        for label in ["walk 7", "truth", "hmm", "radio only", "x (m)", "y (m)"] {
            assert!(texts.iter().any(|t| t == label), "no text {label:?} in {texts:?}");
        }
        assert!(!svg.contains("NaN") && !svg.contains("inf"), "bad points leaked into the SVG");
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn walk_plot_keeps_one_scale_on_both_axes() {
        let dir = temp_dir("scale");
        let file = dir.join("wide.svg");
        // 100 m by 10 m: a wide, short canvas.
        plot_walk(&file, "wide", None, &[(0.0, 0.0), (100.0, 10.0)], &[]).unwrap();
        let svg = std::fs::read_to_string(&file).unwrap();
        let line = svg
            .lines()
            .find(|l| l.contains("<polyline") && l.contains("stroke=\"#000000\"") && l.contains(DATA))
            .unwrap();
        let points: Vec<(f64, f64)> = line
            .split("points=\"")
            .nth(1)
            .unwrap()
            .split('"')
            .next()
            .unwrap()
            .split_whitespace()
            .map(|p| {
                let (x, y) = p.split_once(',').unwrap();
                (x.parse().unwrap(), y.parse().unwrap())
            })
            .collect();
        let (dx, dy) = (points[1].0 - points[0].0, points[0].1 - points[1].1);
        assert!((dx / dy - 10.0).abs() < 0.5, "{dx} px by {dy} px for 100 m by 10 m");
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn empty_and_degenerate_inputs_still_make_valid_files() {
        let dir = temp_dir("empty");
        let empty = Track { label: "nothing", points: &[] };
        plot_walk(&dir.join("a.svg"), "", None, &[], &[empty]).unwrap();
        plot_walk(&dir.join("b.svg"), "one point", None, &[(3.0, 3.0)], &[]).unwrap();
        plot_walk(&dir.join("c.svg"), "nan", Some(&FloorPlan::default()), &[(f64::NAN, f64::NAN)], &[])
            .unwrap();
        plot_cdf(&dir.join("d.svg"), "cdf", &[("none", &[]), ("bad", &[f64::NAN, -1.0])]).unwrap();
        plot_cdf(&dir.join("e.svg"), "zeros", &[("zero", &[0.0, 0.0])]).unwrap();
        for name in ["a", "b", "c", "d", "e"] {
            let svg = std::fs::read_to_string(dir.join(format!("{name}.svg"))).unwrap();
            svg_elements(&svg);
            assert!(!svg.contains("NaN"), "{name}.svg has NaN");
        }
        let a = texts(&std::fs::read_to_string(dir.join("a.svg")).unwrap());
        assert!(a.iter().any(|t| t == "nothing") && a.iter().any(|t| t == "truth"));
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn cdf_plot_has_one_line_and_one_legend_entry_per_curve() {
        let dir = temp_dir("cdf");
        let file = dir.join("cdf.svg");
        let a = [1.0, 2.0, 3.0, f64::NAN];
        let b = [0.5, 4.0];
        let c: Vec<f64> = (0..1000).map(|i| f64::from(i) / 100.0).collect();
        plot_cdf(&file, "errors", &[("reach", &a), ("hoang", &b), ("hipe", &c)]).unwrap();
        let svg = std::fs::read_to_string(&file).unwrap();
        svg_elements(&svg);
        assert_eq!(polylines(&svg, DATA), 3 + 3);
        let texts = texts(&svg);
        for label in ["errors", "reach", "hoang", "hipe", "error (m)"] {
            assert!(texts.iter().any(|t| t == label), "no text {label:?} in {texts:?}");
        }
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn ecdf_is_a_staircase_to_one() {
        let points = ecdf(&[2.0, 1.0, f64::NAN, -3.0]);
        assert_eq!(points, vec![(1.0, 0.0), (1.0, 0.5), (2.0, 0.5), (2.0, 1.0)]);
        assert!(ecdf(&[]).is_empty());
    }

    #[test]
    fn unwritable_path_is_an_io_error() {
        let dir = temp_dir("io");
        let result = plot_cdf(&dir.join("missing").join("x.svg"), "x", &[]);
        assert!(matches!(result, Err(PlotError::Io { .. })), "{result:?}");
        std::fs::remove_dir_all(dir).ok();
    }
}
