//! The site from fitted states: the grid, the walkable graph, unsurveyed states and zones.

use super::prepare::*;
use super::*;

impl PreparedSurvey<'_> {
    /// The site from the walks `keep(floor, walk)` keeps (walk indices as given to
    /// [`new`](Self::new)), reusing the fingerprints of `reuse` where they are the same.
    pub fn site(
        &self,
        keep: &dyn Fn(usize, usize) -> bool,
        reuse: Option<&SurveyFits>,
    ) -> Result<(Site, SurveyReport), SiteError> {
        let threads =
            if reuse.is_some() { 1 } else { std::thread::available_parallelism().map_or(1, |n| n.get()) };
        let fits = self.fit(keep, reuse, threads);
        self.assemble(&fits)
    }

    /// The site from fitted states.
    pub fn assemble(&self, fits: &SurveyFits) -> Result<(Site, SurveyReport), SiteError> {
        let options = &self.options;
        let s = options.spacing_m;
        let centre = |c: Cell| Point2::new(c.0 as f64 * s, c.1 as f64 * s);
        let cell = |p: Point2<f64>| ((p.x / s).round() as i64, (p.y / s).round() as i64);
        // The transmitters these states read, renumbered in order.
        let mut local = vec![u32::MAX; self.transmitters.len()];
        for cell_fit in fits.floors.iter().flat_map(|f| f.values()) {
            for &t in &cell_fit.heard {
                local[t as usize] = 0;
            }
        }
        let mut ids = Vec::new();
        for (t, slot) in local.iter_mut().enumerate() {
            if *slot == 0 {
                *slot = ids.len() as u32;
                ids.push(self.transmitters[t].clone());
            }
        }
        let mut builder = SiteBuilder::new(&self.name);
        builder.north(self.north);
        let mut triples = Vec::new();
        let mut reports = Vec::new();
        let mut zones: Vec<Zone> = Vec::new();
        for (f, (floor, kept)) in self.floors.iter().zip(&fits.kept).enumerate() {
            let index = builder.floor(
                &floor.name,
                floor.geo.map(|g| g.level).or_else(|| floor_rank(&floor.name)).unwrap_or(reports.len() as i32)
                    as f64
                    * STOREY_HEIGHT_M,
            );
            let mut report = FloorSurvey { name: floor.name.clone(), ..FloorSurvey::default() };
            let walks: Vec<&PreparedWalk> =
                floor.walks.iter().zip(kept).filter(|(_, &k)| k).map(|(w, _)| w).collect();
            report.walks = walks.iter().filter(|w| !w.path.is_empty()).count();
            report.scans = walks.iter().map(|w| w.scans.len()).sum();
            let mut gaps: Vec<f64> = walks.iter().flat_map(|w| w.gaps.iter().copied()).collect();
            gaps.sort_by(f64::total_cmp);
            report.scan_interval_median_s = gaps.get(gaps.len() / 2).copied().unwrap_or(f64::NAN);
            report.scan_interval_p99_s = gaps.get(gaps.len() * 99 / 100).copied().unwrap_or(f64::NAN);
            // A state's room: its candidate cell's, or where a cell only evidence fitted (an
            // unsurveyed state refitted, `PreparedSurvey::refit`) lies on the plan.
            let room_of = |c: &Cell| match floor.cells.get(c) {
                Some(candidate) => candidate.room,
                None => floor.plan.and(floor.plan_cells.get(c)).and_then(|p| p.room),
            };
            let mut ids_of: BTreeMap<Cell, u32> = BTreeMap::new();
            for (&c, cell_fit) in &fits.floors[f] {
                let id = builder.fitted_state(index, centre(c), cell_fit.scans);
                triples.extend(cell_fit.models.iter().map(|&(t, g)| (id, local[t as usize], g)));
                ids_of.insert(c, id);
            }
            report.states = ids_of.len();
            // Walkable space around the map that no walk covered: unsurveyed states.
            let margin = (options.unsurveyed_margin_m / s).floor() as i64;
            let mut rooms_of: BTreeMap<Cell, Option<usize>> =
                ids_of.keys().map(|c| (*c, room_of(c))).collect();
            if margin > 0 {
                let mut extra: BTreeSet<Cell> = BTreeSet::new();
                for &c in ids_of.keys() {
                    extra.extend(margin_cells(c, options).filter(|m| !ids_of.contains_key(m)));
                }
                for c in extra {
                    // Where the cell lies on the plan, as the survey looked it up: a state's
                    // cell is a candidate, so its margin is there.
                    let on_plan = floor.plan.and(floor.plan_cells.get(&c));
                    // Off the plan, or beyond the cells it was looked up for (the margin of
                    // a state only evidence fitted): not added.
                    if on_plan.is_some_and(|p| !p.on_floor) || (floor.plan.is_some() && on_plan.is_none()) {
                        continue;
                    }
                    let room = on_plan.and_then(|p| p.room);
                    ids_of.insert(c, builder.unsurveyed_state(index, centre(c)));
                    rooms_of.insert(c, room);
                    report.unsurveyed_states += 1;
                }
            }
            if let Some(plan) = floor.plan {
                let made = plan_zones(&floor.name, plan, ids_of.iter().map(|(c, &id)| (rooms_of[c], id)));
                report.zones = made.len();
                report.zoned_states = made.iter().map(|z| z.states.len()).sum();
                zones.extend(made);
            }
            let paths: Vec<&Vec<Point2<f64>>> =
                walks.iter().map(|w| &w.path).filter(|p| !p.is_empty()).collect();
            // A plan polygon that survey walks went inside is open space, not a room with
            // walls: plans label atria, decorative and "auxiliary" areas as polygons too.
            let mut open: Vec<usize> = floor
                .plan
                .filter(|_| options.walls)
                .map(|plan| {
                    (0..plan.rooms.len())
                        .filter(|&r| {
                            paths.iter().copied().flatten().any(|&p| plan.rooms[r].polygon.contains(p))
                        })
                        .collect()
                })
                .unwrap_or_default();
            open.sort_unstable();
            report.open_rooms = open.len();
            // Edges: grid neighbours (8-connected) joined unless a wall separates them, or
            // whenever a survey walk stepped from one to the other.
            let mut walked: BTreeSet<(Cell, Cell)> = BTreeSet::new();
            for points in &paths {
                for w in points.windows(2) {
                    let (a, b) = (cell(w[0]), cell(w[1]));
                    if a != b && (a.0 - b.0).abs() <= 1 && (a.1 - b.1).abs() <= 1 {
                        walked.insert((a.min(b), a.max(b)));
                    }
                }
            }
            for (&a, &ia) in &ids_of {
                for (di, dj) in [(1, 0), (0, 1), (1, 1), (1, -1)] {
                    let b = (a.0 + di, a.1 + dj);
                    let Some(&ib) = ids_of.get(&b) else { continue };
                    let on_walk = walked.contains(&(a.min(b), a.max(b)));
                    let walled = options.walls
                        && floor
                            .plan
                            .is_some_and(|plan| plan.crosses_wall_except(centre(a), centre(b), &open));
                    if walled {
                        report.walled_edges += 1;
                    }
                    if !walled || on_walk {
                        if walled {
                            report.walked_edges += 1;
                        }
                        builder.edge(ia, ib, None);
                        report.edges += 1;
                    }
                }
            }
            reports.push(report);
        }
        let plans: Vec<Option<&FloorPlan>> = self.floors.iter().map(|f| f.plan).collect();
        let walked: Vec<Option<WalkedGeo>> = self.floors.iter().map(|f| f.geo).collect();
        let (anchor, floors) = geo_reference_or_walked(&plans, &walked);
        for (f, (level, origin_m)) in floors.into_iter().enumerate() {
            builder.floor_geo(f, level, origin_m);
        }
        if let Some(anchor) = anchor {
            builder.anchor(anchor);
        }
        let build = BuildOptions {
            fit: FitOptions { clip_dbm: fits.clip_dbm, ..options.build.fit },
            ..options.build
        };
        // Builder ids are state indices. The site keeps the reading-age limit its fingerprints
        // were fitted with, for the engines on it to apply.
        // The shared radios among the transmitters these states read.
        let radios: Vec<Vec<u32>> = (self.shared_radios.iter())
            .map(|g| g.iter().map(|&t| local[t as usize]).filter(|&t| t != u32::MAX).collect::<Vec<_>>())
            .filter(|g| g.len() >= 2)
            .collect();
        let site = builder
            .build_fitted(build, ids, triples)?
            .with_shared_radios(radios)?
            .with_zones(zones)?
            .with_max_reading_age_ns(Some(options.max_reading_age_ns));
        let transmitters = site.radio().transmitters().len();
        let shared_radios = site.radio().shared_radios().len();
        Ok((site, SurveyReport { floors: reports, transmitters, shared_radios }))
    }
}

/// Zones from a floor plan's named polygons, of their rooms' kinds: each state (its smallest named polygon, index)
/// joins that polygon. A zone is called `floor/name`, with ` #k` after the name when the
/// plan has several polygons of that name (k counts them in plan order), so names are unique
/// in the site. Polygons holding no state make no zone.
fn plan_zones(
    floor: &str,
    plan: &FloorPlan,
    states: impl Iterator<Item = (Option<usize>, u32)>,
) -> Vec<Zone> {
    let mut members: BTreeMap<usize, Vec<u32>> = BTreeMap::new();
    for (room, id) in states {
        if let Some(room) = room {
            members.entry(room).or_default().push(id);
        }
    }
    members
        .into_iter()
        .map(|(room, states)| {
            let name = &plan.rooms[room].name;
            let same = plan.rooms.iter().filter(|r| &r.name == name).count();
            let name = if same > 1 {
                let k = plan.rooms[..room].iter().filter(|r| &r.name == name).count() + 1;
                format!("{floor}/{name} #{k}")
            } else {
                format!("{floor}/{name}")
            };
            Zone { name, kind: plan.room_kind(room), states }
        })
        .collect()
}
