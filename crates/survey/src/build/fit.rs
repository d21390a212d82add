//! Fingerprints fitted per state from its training scans, reused where they are unchanged.

use super::prepare::*;
use super::*;

impl PreparedSurvey<'_> {
    /// The clip level of a site from the walks `keep` keeps, dBm.
    fn clip_dbm(&self, keep: &dyn Fn(usize, usize) -> bool) -> f64 {
        if !self.options.measure_clip {
            return self.options.build.fit.clip_dbm;
        }
        let weakest = self
            .floors
            .iter()
            .enumerate()
            .flat_map(|(f, floor)| floor.walks.iter().enumerate().filter(move |(w, _)| keep(f, *w)))
            .map(|(_, w)| w.weakest_wifi_dbm)
            .fold(f64::INFINITY, f64::min);
        if weakest.is_finite() {
            weakest - 1.0
        } else {
            self.options.build.fit.clip_dbm
        }
    }

    /// Fits the states of the site from the walks `keep(floor, walk)` keeps, reusing from
    /// `reuse` every state whose training scans are the same; the fits of states that need one
    /// run on `threads` threads.
    pub fn fit(
        &self,
        keep: &dyn Fn(usize, usize) -> bool,
        reuse: Option<&SurveyFits>,
        threads: usize,
    ) -> SurveyFits {
        let clip_dbm = self.clip_dbm(keep);
        let kept: Vec<Vec<bool>> = self
            .floors
            .iter()
            .enumerate()
            .map(|(f, floor)| (0..floor.walks.len()).map(|w| keep(f, w)).collect())
            .collect();
        let reuse = reuse.filter(|r| r.clip_dbm == clip_dbm && r.kept.len() == kept.len());
        let build =
            BuildOptions { fit: FitOptions { clip_dbm, ..self.options.build.fit }, ..self.options.build };
        let fit = build.stored_fit();
        let mut floors: Vec<BTreeMap<Cell, CellFit>> = vec![BTreeMap::new(); self.floors.len()];
        // Cells to fit: (floor, cell, kept training scans).
        let mut todo: Vec<(usize, Cell, Training)> = Vec::new();
        for (f, floor) in self.floors.iter().enumerate() {
            let kept = &kept[f];
            for (&c, candidate) in &floor.cells {
                if !candidate.covered_by.iter().any(|&w| kept[w as usize]) {
                    continue;
                }
                let training: Training =
                    candidate.training.iter().copied().filter(|&(w, _)| kept[w as usize]).collect();
                // A state without a scan of its own would be "nowhere" to the radio: left out.
                if training.is_empty() {
                    continue;
                }
                // The same scans as the reused fit: every scan it had is still kept.
                let same = reuse.and_then(|r| {
                    let was = &r.kept[f];
                    let unchanged = was.len() == kept.len()
                        && candidate.training.iter().all(|&(w, _)| was[w as usize] == kept[w as usize]);
                    unchanged.then(|| r.floors[f].get(&c)).flatten()
                });
                match same {
                    Some(cached) => {
                        floors[f].insert(c, cached.clone());
                    }
                    None => todo.push((f, c, training)),
                }
            }
        }
        let fit_cell = |f: usize, training: &[(u32, u32)]| -> CellFit {
            let walks = &self.floors[f].walks;
            let mut readings = Vec::new();
            for (k, &(w, scan)) in training.iter().enumerate() {
                readings.extend(
                    walks[w as usize].scans[scan as usize].iter().map(|&(t, rssi)| (t, k as u32, rssi)),
                );
            }
            let mut heard: Vec<u32> = readings.iter().map(|r| r.0).collect();
            heard.sort_unstable();
            heard.dedup();
            let models = waymark_engine::site::fit_columns(readings, training.len(), build.model, &fit);
            CellFit { scans: training.len() as u32, heard, models }
        };
        let threads = threads.max(1).min(todo.len().max(1));
        let chunk = todo.len().div_ceil(threads).max(1);
        let fitted: Vec<(usize, Cell, CellFit)> = if threads == 1 {
            todo.iter().map(|(f, c, t)| (*f, *c, fit_cell(*f, t))).collect()
        } else {
            std::thread::scope(|scope| {
                let workers: Vec<_> = todo
                    .chunks(chunk)
                    .map(|part| {
                        let fit_cell = &fit_cell;
                        scope.spawn(move || {
                            part.iter().map(|(f, c, t)| (*f, *c, fit_cell(*f, t))).collect::<Vec<_>>()
                        })
                    })
                    .collect();
                workers
                    .into_iter()
                    .flat_map(|w| w.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
                    .collect()
            })
        };
        let refitted = fitted.len();
        for (f, c, cell_fit) in fitted {
            floors[f].insert(c, cell_fit);
        }
        SurveyFits { clip_dbm, kept, floors, refitted }
    }
}
