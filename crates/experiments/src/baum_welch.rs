//! El Gemayel et al. §IV on a synthetic floor: a person with habits walks between 27 rooms and
//! hallway sections; a TDoA system with four anchors around the building's corners and fixed
//! per-cell range biases
//! reports position estimates; the forward algorithm finds the room with the true parameters,
//! and with parameters learned by Baum-Welch run after run, with and without user feedback
//! (Fig. 5).
//!
//! - **Floor.** 27 states as in the paper (its Fig. 1 is Durham Hall, whose plan is not
//!   given): a 27 m × 2 m corridor cut into nine 3 m sections, with nine 3 m × 5 m rooms on
//!   each side, each room opening onto its section. The entrance is the west section.
//! - **Habits** (eq. 1's shape): rooms are kept (stay 0.85-0.97, as eq. 1's office, 0.95) and
//!   left to their section; sections are passed through (stay 0.05-0.2, eq. 1's hallways
//!   0.05-0.1). As in each row of eq. 1, one move dominates: 50-90% of what leaves a section
//!   goes to one neighbour (an adjacent habitual room if there is one, else a random
//!   neighbour), the rest to all neighbours, a quarter of the rooms being habitual and
//!   entered ten times as often as the others. The entrance section is left with 0.9, as eq.
//!   1's state 1. Every walk starts at the entrance (§II-A: where the person enters is known).
//!   The paper: "the further away we are from uniform probabilities ..., the better the
//!   results" (§IV-A; `docs/tuning.md#baum-welch-experiment`).
//! - **Observations** (§II-C, §IV): the true position is uniform in its state; the range
//!   differences to anchors 2-4 (anchor 1 the reference; the anchors `ANCHOR_MARGIN_M`
//!   outside the building's corners) get the fixed bias of the 1 m × 1 m
//!   cell the position is in, U(0, b_max) or exponential, plus white Gaussian noise σ_n; the
//!   position is estimated by least squares (Chan & Ho's linear first step, then Gauss-Newton
//!   on the range differences: the least-squares solution Chan & Ho's second step
//!   approximates).
//! - **True parameters** (§IV (i)): the habits, and per cell the mean and covariance of its
//!   position estimates, measured by Monte Carlo: eq. 7 with one component per cell.
//! - **Learning** (§IV): from the paper's initialisation (allowed transitions from the floor
//!   plan, uniform; means at the cell centres; Σ = 2500 I, eq. 15), each run draws a new walk
//!   of 500 epochs (§IV-C) and runs Baum-Welch to convergence, from the parameters the previous
//!   runs left, on that walk and the earlier ones (Rabiner §V-B's multiple sequences), with
//!   [`FitOptions::default`] (among them a prior of 16 observations on each component's mean,
//!   centred where the run found it, see below). Feedback at rate r gives the true state at r × 500 epochs of the
//!   run chosen at random (§IV-C: "25 out of 500" for 0.05). Fig. 4's curve keeps the true
//!   transitions and learns the emissions only, on the same runs (the paper's were 200 epochs).
//!
//!   Refitting on all walks, not the new one alone, keeps what earlier runs learned; the
//!   mean prior keeps a component the posteriors hardly touch near its cell, since eq. 15's
//!   Σ = 2500 I otherwise lets eq. 11 pull every state's means to the same point
//!   (`docs/tuning.md#baum-welch-experiment`, `docs/tuning.md#baum-welch-options`).
//! - **Score**: the forward algorithm's room accuracy (the most probable state of the filtered
//!   posterior, §III-B) on held-out walks, the same for every row and curve.
//!
//! What it shows: `docs/tuning.md#baum-welch-experiment`; the curves: `waymark simulate --experiment baum-welch`.

use nalgebra::{Matrix2, Matrix3, Point2, Vector2, Vector3};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Exp, Normal};
use serde::Serialize;
use waymark_engine::hmm::learn::{
    fit, forward_backward, Chain, FitOptions, Gaussian, GaussianHmm, GaussianMixtures, Known, LearnError,
    Sequence, SparseTransition,
};

/// Corridor sections (and rooms on each side): 9 + 18 = the paper's 27 states (§IV). Durham
/// Hall's dimensions are not given; the sizes below are ordinary offices (3 m × 5 m, 15 m²)
/// off a 2 m corridor, so that a state is a few cells wide and larger than the position
/// errors' bias, as the paper's rooms are in its Fig. 1.
const SECTIONS: usize = 9;
/// Width of a section and of a room, m (see [`SECTIONS`]).
const SECTION_WIDTH_M: f64 = 3.0;
/// Depth of a room, m (see [`SECTIONS`]).
const ROOM_DEPTH_M: f64 = 5.0;
/// Width of the corridor, m (see [`SECTIONS`]).
const CORRIDOR_M: f64 = 2.0;
/// Building size: 27 m × 12 m, 324 cells of 1 m × 1 m (§IV: "The cell size ... was set to
/// 1m × 1m").
const WIDTH_M: f64 = SECTIONS as f64 * SECTION_WIDTH_M;
const DEPTH_M: f64 = 2.0 * ROOM_DEPTH_M + CORRIDOR_M;
/// How far outside each corner of the building its anchor stands, m, in x and in y: 5, a
/// room's depth. §IV: "four anchors were placed on four corners around the building"; the
/// paper gives no distance. On the building's own corners the reference anchor stood in the
/// corner of a room, where range differences biased by up to b_max have no consistent
/// position, and least squares threw estimates far from their state
/// (`docs/tuning.md#baum-welch-experiment`).
const ANCHOR_MARGIN_M: f64 = 5.0;

/// How the per-cell range-difference biases are drawn (§II-C).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub enum Bias {
    /// b ~ U(0, b_max).
    Uniform {
        /// b_max, m.
        max_m: f64,
    },
    /// b ~ exponential with mean b_exp.
    Exponential {
        /// b_exp, m.
        mean_m: f64,
    },
}

/// Parameters of the experiment.
#[derive(Clone, Debug, PartialEq)]
pub struct BaumWelchExperiment {
    /// Seed of the habits, the biases, the walks and the feedback epochs.
    pub seed: u64,
    /// Baum-Welch runs, each on a new walk: 10 (the paper's run counts are plotted only; by
    /// then the feedback curves have levelled off, `docs/tuning.md#baum-welch-experiment`).
    pub runs: usize,
    /// Epochs per run: 500 (§IV-C, learning all parameters).
    pub run_length: usize,
    /// Held-out walks of `run_length` epochs scoring every row: 4, 2000 epochs, a binomial
    /// standard error of at most 1.1 points per accuracy.
    pub test_walks: usize,
    /// Range-difference bias per cell: U(0, 4 m). The paper gives no b_max (Fig. 4's values
    /// are plotted); with 4 m and σ_n = 1 m the estimates alone often miss the true state
    /// while the forward algorithm with the true parameters mostly finds it, the regime in
    /// which the paper's HMM matters (Fig. 3; `docs/tuning.md#baum-welch-experiment`).
    pub bias: Bias,
    /// σ_n, the white noise on each range difference, m: 1 (see `bias`; the paper sweeps
    /// 0-35 m in Fig. 3).
    pub noise_m: f64,
    /// Draws per cell for the true emission's mean and covariance: 200, a standard error of
    /// σ/14 on each mean.
    pub draws_per_cell: usize,
    /// Variance of the initial components, m² (eq. 15: 2500).
    pub initial_variance_m2: f64,
    /// The Baum-Welch options.
    pub options: FitOptions,
    /// The learning curves.
    pub schedules: Vec<Schedule>,
}

impl Default for BaumWelchExperiment {
    fn default() -> Self {
        Self {
            seed: 0,
            runs: 10,
            run_length: 500,
            test_walks: 4,
            bias: Bias::Uniform { max_m: 4.0 },
            noise_m: 1.0,
            draws_per_cell: 200,
            initial_variance_m2: 2500.0,
            options: FitOptions::default(),
            schedules: paper_schedules(),
        }
    }
}

/// One learning curve.
#[derive(Clone, Debug, Serialize)]
pub struct Curve {
    /// Its name, e.g. "feedback 0.05".
    pub name: String,
    /// Feedback rate of each run.
    pub feedback: Vec<f64>,
    /// Room accuracy with the initial parameters, then after each run: `runs + 1` values.
    pub accuracy: Vec<f64>,
    /// Baum-Welch iterations of each run.
    pub iterations: Vec<usize>,
    /// Feedback epochs the model ruled out, at which a walk was restarted, summed over each
    /// run's E-steps.
    pub restarts: Vec<usize>,
}

/// What the experiment measured.
#[derive(Clone, Debug, Serialize)]
pub struct BaumWelchReport {
    /// The seed.
    pub seed: u64,
    /// States (27).
    pub states: usize,
    /// Cells, i.e. mixture components (324).
    pub cells: usize,
    /// Epochs per run.
    pub run_length: usize,
    /// Epochs scored per row.
    pub test_epochs: usize,
    /// The bias model.
    pub bias: Bias,
    /// σ_n, m.
    pub noise_m: f64,
    /// Variance of the initial components, m².
    pub initial_variance_m2: f64,
    /// Share of test epochs whose position estimate lies in the true state (Fig. 3's dashed
    /// curve).
    pub estimate_accuracy: f64,
    /// Room accuracy of the forward algorithm with the true parameters (Fig. 3-5's upper
    /// bound).
    pub true_accuracy: f64,
    /// Learned parameters: the transitions known (Fig. 4); everything learned (Fig. 5) with no
    /// feedback, rates 0.05 and 0.1, decaying from 0.2 to 0.
    pub curves: Vec<Curve>,
}

/// The floor: each state's rectangle and its allowed transitions (itself and its neighbours).
struct Floor {
    rects: Vec<(Point2<f64>, Point2<f64>)>,
    neighbours: Vec<Vec<u32>>,
}

/// States 0-8 the corridor sections west to east (0 the entrance), 9-17 the rooms north of
/// them, 18-26 the rooms south.
fn floor() -> Floor {
    let mut rects = Vec::new();
    let (south, corridor) = (ROOM_DEPTH_M, ROOM_DEPTH_M + CORRIDOR_M);
    for (y0, y1) in [(south, corridor), (corridor, DEPTH_M), (0.0, south)] {
        for k in 0..SECTIONS {
            let x0 = k as f64 * SECTION_WIDTH_M;
            rects.push((Point2::new(x0, y0), Point2::new(x0 + SECTION_WIDTH_M, y1)));
        }
    }
    let mut neighbours = vec![Vec::new(); 3 * SECTIONS];
    for k in 0..SECTIONS {
        let section = &mut neighbours[k];
        section.push(k as u32);
        if k > 0 {
            section.push(k as u32 - 1);
        }
        if k + 1 < SECTIONS {
            section.push(k as u32 + 1);
        }
        section.extend([(SECTIONS + k) as u32, (2 * SECTIONS + k) as u32]);
        for room in [SECTIONS + k, 2 * SECTIONS + k] {
            neighbours[room] = vec![k as u32, room as u32];
        }
    }
    for n in &mut neighbours {
        n.sort_unstable();
    }
    Floor { rects, neighbours }
}

/// The state whose rectangle holds `p` (the building is tiled by them), if any.
fn state_at(p: &Point2<f64>) -> Option<usize> {
    if !(0.0..WIDTH_M).contains(&p.x) || !(0.0..DEPTH_M).contains(&p.y) {
        return None;
    }
    let k = (p.x / SECTION_WIDTH_M) as usize;
    Some(if p.y < ROOM_DEPTH_M {
        2 * SECTIONS + k
    } else if p.y < ROOM_DEPTH_M + CORRIDOR_M {
        k
    } else {
        SECTIONS + k
    })
}

/// The 1 m cells of a state, as their lower-left corners.
fn cells(rect: &(Point2<f64>, Point2<f64>)) -> Vec<Point2<f64>> {
    let (lo, hi) = rect;
    let mut out = Vec::new();
    let mut y = lo.y;
    while y < hi.y {
        let mut x = lo.x;
        while x < hi.x {
            out.push(Point2::new(x, y));
            x += 1.0;
        }
        y += 1.0;
    }
    out
}

fn cell_index(p: &Point2<f64>) -> usize {
    let cx = (p.x.clamp(0.0, WIDTH_M - 1e-9)) as usize;
    let cy = (p.y.clamp(0.0, DEPTH_M - 1e-9)) as usize;
    cy * WIDTH_M as usize + cx
}

/// The habitual transition matrix (eq. 1's shape; see the module documentation).
fn habits(floor: &Floor, rng: &mut ChaCha8Rng) -> Vec<Vec<(u32, f64)>> {
    let destination: Vec<bool> = (0..2 * SECTIONS).map(|_| rng.random_range(0.0..1.0) < 0.25).collect();
    floor
        .neighbours
        .iter()
        .enumerate()
        .map(|(i, allowed)| {
            let stay = if i >= SECTIONS {
                rng.random_range(0.85..0.97)
            } else if i == 0 {
                0.1
            } else {
                rng.random_range(0.05..0.2)
            };
            let weights: Vec<f64> = allowed
                .iter()
                .map(|&j| {
                    let j = j as usize;
                    match (j == i, j >= SECTIONS) {
                        (true, _) => 0.0,
                        (false, true) if destination[j - SECTIONS] => 1.0,
                        (false, true) => 0.1,
                        (false, false) => rng.random_range(0.2..1.0),
                    }
                })
                .collect();
            let total: f64 = weights.iter().sum();
            // Eq. 1's rows each have one dominant move (0.9, 0.9, 0.75, 0.5): one neighbour,
            // a habitual room if there is one, takes most of what is not a stay.
            let others: Vec<usize> = (0..allowed.len()).filter(|&k| allowed[k] as usize != i).collect();
            let favourite = others
                .iter()
                .copied()
                .find(|&k| weights[k] >= 1.0)
                .unwrap_or_else(|| others[rng.random_range(0..others.len())]);
            let share = rng.random_range(0.5..0.9);
            allowed
                .iter()
                .zip(&weights)
                .enumerate()
                .map(|(k, (&j, &w))| {
                    let p = if j as usize == i {
                        stay
                    } else {
                        (1.0 - stay) * ((1.0 - share) * w / total + if k == favourite { share } else { 0.0 })
                    };
                    (j, p)
                })
                .collect()
        })
        .collect()
}

/// The TDoA system: four anchors around the building's corners (`ANCHOR_MARGIN_M`), anchor 0
/// the reference, and the fixed bias of each cell on the three range differences.
struct Tdoa {
    anchors: [Point2<f64>; 4],
    biases: Vec<[f64; 3]>,
    noise: Normal<f64>,
}

impl Tdoa {
    fn new(bias: Bias, noise_m: f64, rng: &mut ChaCha8Rng) -> Self {
        let g = ANCHOR_MARGIN_M;
        let anchors = [
            Point2::new(-g, -g),
            Point2::new(WIDTH_M + g, -g),
            Point2::new(WIDTH_M + g, DEPTH_M + g),
            Point2::new(-g, DEPTH_M + g),
        ];
        let cells = (WIDTH_M * DEPTH_M) as usize;
        let mut draw = || match bias {
            Bias::Uniform { max_m } => rng.random_range(0.0..1.0) * max_m,
            Bias::Exponential { mean_m } => Exp::new(1.0 / mean_m).map_or(0.0, |e| e.sample(rng)),
        };
        let biases = (0..cells).map(|_| [draw(), draw(), draw()]).collect();
        let noise =
            Normal::new(0.0, noise_m.max(0.0)).unwrap_or_else(|_| Normal::new(0.0, 0.0).expect("σ = 0"));
        Self { anchors, biases, noise }
    }

    /// The position estimate for a person at `x` (eqs. 2-4, §IV steps 1-4).
    fn observe(&self, x: &Point2<f64>, rng: &mut ChaCha8Rng) -> Vector2<f64> {
        let bias = &self.biases[cell_index(x)];
        let d0 = (x - self.anchors[0]).norm();
        let mut r = [0.0; 3];
        for l in 0..3 {
            r[l] = (x - self.anchors[l + 1]).norm() - d0 + bias[l] + self.noise.sample(rng);
        }
        self.locate(&r)
    }

    /// Least squares on the range differences `r` (anchor l + 1 minus anchor 0).
    fn locate(&self, r: &[f64; 3]) -> Vector2<f64> {
        let a = &self.anchors;
        let centre = Vector2::new(WIDTH_M / 2.0, DEPTH_M / 2.0);
        // Chan & Ho's first step: (x_l − x_0) x + (y_l − y_0) y + r_l r_0 = (K_l − K_0 − r_l²) / 2,
        // linear in (x, y, r_0); with three range differences it is square.
        let k = |p: &Point2<f64>| p.coords.norm_squared();
        let m = Matrix3::from_fn(|row, col| match col {
            0 => a[row + 1].x - a[0].x,
            1 => a[row + 1].y - a[0].y,
            _ => r[row],
        });
        let b = Vector3::from_fn(|row, _| 0.5 * (k(&a[row + 1]) - k(&a[0]) - r[row] * r[row]));
        let linear =
            m.lu().solve(&b).map(|s| Vector2::new(s.x, s.y)).filter(|s| s.iter().all(|v| v.is_finite()));
        // Gauss-Newton on Σ_l (|x − a_l| − |x − a_0| − r_l)².
        let mut p = linear.unwrap_or(centre);
        for _ in 0..20 {
            let unit = |q: &Point2<f64>| {
                let d = p - q.coords;
                d / d.norm().max(1e-9)
            };
            let u0 = unit(&a[0]);
            let mut jtj = Matrix2::zeros();
            let mut jtf = Vector2::zeros();
            for l in 0..3 {
                let f = (p - a[l + 1].coords).norm() - (p - a[0].coords).norm() - r[l];
                let j = unit(&a[l + 1]) - u0;
                jtj += j * j.transpose();
                jtf += j * f;
            }
            let Some(step) = jtj.lu().solve(&jtf) else { break };
            p -= step;
            if !p.iter().all(|v| v.is_finite()) || p.norm() > 1e4 {
                return centre;
            }
            if step.norm() < 1e-6 {
                break;
            }
        }
        p
    }
}

/// A walk: true states and positions, and the position estimates.
struct Walk {
    states: Vec<u32>,
    observations: Vec<Vector2<f64>>,
}

fn walk(floor: &Floor, a: &[Vec<(u32, f64)>], tdoa: &Tdoa, len: usize, rng: &mut ChaCha8Rng) -> Walk {
    let mut s = 0usize;
    let (mut states, mut observations) = (Vec::with_capacity(len), Vec::with_capacity(len));
    for _ in 0..len {
        let (lo, hi) = floor.rects[s];
        let x = Point2::new(rng.random_range(lo.x..hi.x), rng.random_range(lo.y..hi.y));
        states.push(s as u32);
        observations.push(tdoa.observe(&x, rng));
        let u: f64 = rng.random_range(0.0..1.0);
        let mut acc = 0.0;
        let row = &a[s];
        s = row.last().map_or(s, |&(j, _)| j as usize);
        for &(j, p) in row {
            acc += p;
            if u < acc {
                s = j as usize;
                break;
            }
        }
    }
    Walk { states, observations }
}

/// Eq. 7 with each cell's measured estimate mean and covariance.
fn true_emission(
    floor: &Floor,
    tdoa: &Tdoa,
    draws: usize,
    rng: &mut ChaCha8Rng,
) -> Result<GaussianMixtures<2>, LearnError> {
    let per_state = floor
        .rects
        .iter()
        .map(|rect| {
            cells(rect)
                .iter()
                .map(|corner| {
                    let samples: Vec<Vector2<f64>> = (0..draws.max(3))
                        .map(|_| {
                            let x = Point2::new(
                                corner.x + rng.random_range(0.0..1.0),
                                corner.y + rng.random_range(0.0..1.0),
                            );
                            tdoa.observe(&x, rng)
                        })
                        .collect();
                    let n = samples.len() as f64;
                    let mean = samples.iter().sum::<Vector2<f64>>() / n;
                    let cov =
                        samples.iter().map(|o| (o - mean) * (o - mean).transpose()).sum::<Matrix2<f64>>()
                            / (n - 1.0);
                    Gaussian::new(mean, cov + Matrix2::identity() * 1e-9)
                })
                .collect::<Result<Vec<_>, _>>()
        })
        .collect::<Result<Vec<_>, _>>()?;
    GaussianMixtures::new(per_state)
}

/// §IV's initialisation: allowed transitions uniform, means at the cell centres, Σ = σ² I
/// (eq. 15: σ² = 2500 m²).
fn initial_model(floor: &Floor, variance: f64) -> Result<GaussianHmm<2>, LearnError> {
    let rows = floor
        .neighbours
        .iter()
        .map(|allowed| allowed.iter().map(|&j| (j, 1.0 / allowed.len() as f64)).collect())
        .collect();
    let per_state = floor
        .rects
        .iter()
        .map(|rect| {
            cells(rect)
                .iter()
                .map(|c| Gaussian::new(Vector2::new(c.x + 0.5, c.y + 0.5), Matrix2::identity() * variance))
                .collect::<Result<Vec<_>, _>>()
        })
        .collect::<Result<Vec<_>, _>>()?;
    GaussianHmm::new(entrance_chain(SparseTransition::from_rows(rows)?)?, GaussianMixtures::new(per_state)?)
}

fn entrance_chain(transition: SparseTransition) -> Result<Chain, LearnError> {
    let mut initial = vec![0.0; transition.states()];
    initial[0] = 1.0;
    Chain::new(initial, transition)
}

/// The forward algorithm's room accuracy on the held-out walks.
fn accuracy(model: &GaussianHmm<2>, tests: &[Walk]) -> Result<f64, LearnError> {
    let (mut hits, mut total) = (0usize, 0usize);
    for test in tests {
        let e = model.log_emissions(&Sequence::new(test.observations.clone()))?;
        let posterior = forward_backward(model.chain(), &e)?;
        for (t, &truth) in test.states.iter().enumerate() {
            let row = posterior.filtered.row(t);
            let best = (0..row.len()).fold(0, |b, i| if row[i] > row[b] { i } else { b });
            hits += usize::from(best == truth as usize);
            total += 1;
        }
    }
    Ok(hits as f64 / total.max(1) as f64)
}

/// Independent seeds for the parts of one experiment.
fn stream(seed: u64, part: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15).wrapping_add(part))
}

/// `count` distinct epochs of `len`, at random.
fn feedback_epochs(len: usize, count: usize, rng: &mut ChaCha8Rng) -> Vec<usize> {
    let mut epochs: Vec<usize> = (0..len).collect();
    let count = count.min(len);
    for k in 0..count {
        let j = rng.random_range(k..len);
        epochs.swap(k, j);
    }
    epochs.truncate(count);
    epochs
}

/// User feedback over the runs (§IV-C).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub enum Feedback {
    /// The same rate every run.
    Constant(f64),
    /// A rate falling linearly from this one at the first run to 0 at the last (Fig. 5's
    /// "descending feedback").
    Decaying(f64),
}

impl Feedback {
    /// The rate of run `k` of `runs`.
    pub fn rate(&self, k: usize, runs: usize) -> f64 {
        match *self {
            Feedback::Constant(rate) => rate,
            Feedback::Decaying(start) if runs > 1 => start * (1.0 - k as f64 / (runs - 1) as f64),
            Feedback::Decaying(start) => start,
        }
    }
}

/// One learning curve to draw.
#[derive(Clone, Debug, PartialEq)]
pub struct Schedule {
    /// Its name in the table.
    pub name: String,
    /// Keep the true transitions and learn the emissions only (Fig. 4).
    pub transitions_known: bool,
    /// The feedback.
    pub feedback: Feedback,
}

/// The paper's curves: Fig. 4's (transitions known, no feedback), then Fig. 5's (everything
/// learned) with no feedback, rates 0.05 and 0.1, and a rate decaying from 0.2 to 0 (the
/// higher of its two descending curves).
pub fn paper_schedules() -> Vec<Schedule> {
    let schedule =
        |name: &str, transitions_known, feedback| Schedule { name: name.into(), transitions_known, feedback };
    vec![
        schedule("A known", true, Feedback::Constant(0.0)),
        schedule("no feedback", false, Feedback::Constant(0.0)),
        schedule("feedback 0.05", false, Feedback::Constant(0.05)),
        schedule("feedback 0.1", false, Feedback::Constant(0.1)),
        schedule("decaying 0.2→0", false, Feedback::Decaying(0.2)),
    ]
}

/// Runs the experiment.
pub fn run(config: &BaumWelchExperiment) -> Result<BaumWelchReport, LearnError> {
    let positive = |name: &str, v: f64, strict: bool| {
        if v.is_finite() && (v > 0.0 || (!strict && v == 0.0)) {
            Ok(())
        } else {
            Err(LearnError::Unsupported(format!(
                "{name} must be {}, not {v}",
                if strict { "positive" } else { "≥ 0" }
            )))
        }
    };
    positive("the initial variance", config.initial_variance_m2, true)?;
    positive("σ_n", config.noise_m, false)?;
    let bias = match config.bias {
        Bias::Uniform { max_m } => max_m,
        Bias::Exponential { mean_m } => mean_m,
    };
    positive("the bias", bias, false)?;
    if config.runs == 0 || config.run_length == 0 || config.test_walks == 0 {
        return Err(LearnError::Unsupported("runs, run length and test walks must be at least 1".into()));
    }
    let floor = floor();
    let a = habits(&floor, &mut stream(config.seed, 0));
    let tdoa = Tdoa::new(config.bias, config.noise_m, &mut stream(config.seed, 1));
    let truth = GaussianHmm::new(
        entrance_chain(SparseTransition::from_rows(a.clone())?)?,
        true_emission(&floor, &tdoa, config.draws_per_cell, &mut stream(config.seed, 2))?,
    )?;
    let mut test_rng = stream(config.seed, 3);
    let tests: Vec<Walk> =
        (0..config.test_walks).map(|_| walk(&floor, &a, &tdoa, config.run_length, &mut test_rng)).collect();
    let test_epochs = tests.iter().map(|w| w.states.len()).sum::<usize>();
    let in_state = tests
        .iter()
        .flat_map(|w| w.states.iter().zip(&w.observations))
        .filter(|(&s, o)| state_at(&Point2::from(**o)) == Some(s as usize))
        .count();
    let mut run_rng = stream(config.seed, 4);
    let training: Vec<Walk> =
        (0..config.runs).map(|_| walk(&floor, &a, &tdoa, config.run_length, &mut run_rng)).collect();
    let start = initial_model(&floor, config.initial_variance_m2)?;
    // Fig. 4: the true transitions, the emissions initialised as §IV says.
    let known_a = GaussianHmm::new(truth.chain().clone(), start.emission().clone())?;
    let mut curves = Vec::new();
    for schedule in &config.schedules {
        // Seeded by the curve's name, so that a curve draws the same feedback epochs in any
        // company (crates/engine/tests/baum_welch.rs runs two of the CLI's five).
        let tag = schedule
            .name
            .bytes()
            .fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3));
        let mut feedback_rng = stream(config.seed, tag);
        let a_known = schedule.transitions_known;
        let mut model = if a_known { known_a.clone() } else { start.clone() };
        let options = FitOptions { learn_transitions: !a_known, ..config.options.clone() };
        let (name, feedback) = (
            schedule.name.clone(),
            (0..config.runs).map(|k| schedule.feedback.rate(k, config.runs)).collect(),
        );
        let mut curve = Curve {
            name,
            feedback,
            accuracy: vec![accuracy(&model, &tests)?],
            iterations: Vec::new(),
            restarts: Vec::new(),
        };
        let mut sequences = Vec::with_capacity(training.len());
        for (run, data) in training.iter().enumerate() {
            let count = (curve.feedback[run] * data.states.len() as f64).round() as usize;
            let known = feedback_epochs(data.states.len(), count, &mut feedback_rng)
                .into_iter()
                .map(|t| Known { epoch: t, states: vec![data.states[t]] })
                .collect();
            sequences.push(Sequence { observations: data.observations.clone(), known });
            let (learned, report) = fit(&model, &sequences, &options)?;
            model = learned;
            curve.iterations.push(report.iterations);
            curve.restarts.push(report.restarts);
            curve.accuracy.push(accuracy(&model, &tests)?);
        }
        curves.push(curve);
    }
    Ok(BaumWelchReport {
        seed: config.seed,
        states: floor.rects.len(),
        cells: floor.rects.iter().map(|r| cells(r).len()).sum(),
        run_length: config.run_length,
        test_epochs,
        bias: config.bias,
        noise_m: config.noise_m,
        initial_variance_m2: config.initial_variance_m2,
        estimate_accuracy: in_state as f64 / test_epochs.max(1) as f64,
        true_accuracy: accuracy(&truth, &tests)?,
        curves,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_floor_is_tiled_by_its_states() {
        let f = floor();
        assert_eq!(f.rects.len(), 27);
        assert_eq!(f.rects.iter().map(|r| cells(r).len()).sum::<usize>(), 324);
        for (i, rect) in f.rects.iter().enumerate() {
            for c in cells(rect) {
                assert_eq!(state_at(&Point2::new(c.x + 0.5, c.y + 0.5)), Some(i));
            }
            assert!(f.neighbours[i].contains(&(i as u32)));
            for &j in &f.neighbours[i] {
                assert!(f.neighbours[j as usize].contains(&(i as u32)), "{i} {j}");
            }
        }
        let a = habits(&f, &mut stream(0, 0));
        for row in &a {
            assert!((row.iter().map(|r| r.1).sum::<f64>() - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn least_squares_recovers_noise_free_positions() {
        let tdoa = Tdoa::new(Bias::Uniform { max_m: 0.0 }, 0.0, &mut stream(0, 1));
        let mut rng = stream(0, 9);
        for p in
            [Point2::new(1.5, 2.5), Point2::new(13.0, 6.0), Point2::new(26.5, 11.5), Point2::new(20.2, 0.4)]
        {
            let o = tdoa.observe(&p, &mut rng);
            assert!((o - p.coords).norm() < 1e-6, "{p} -> {o}");
        }
    }
}
