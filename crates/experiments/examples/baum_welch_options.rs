//! The measurement behind `FitOptions::default()`: the Baum-Welch experiment
//! ([`waymark_experiments::baum_welch`], El Gemayel §IV) on seeds other than the default, once per variant of one option,
//! printing each curve's room accuracy after the last run, the mean Baum-Welch iterations per
//! run and the CPU-bound wall time.
//!
//! ```sh
//! cargo run --release -p waymark-experiments --example baum_welch_options            # seeds 1 2 3
//! cargo run --release -p waymark-experiments --example baum_welch_options -- 4 5     # other seeds
//! ```

use std::time::Instant;
use waymark_engine::hmm::learn::FitOptions;
use waymark_experiments::baum_welch::{self, BaumWelchExperiment};

fn main() {
    let seeds: Vec<u64> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    let seeds = if seeds.is_empty() { vec![1, 2, 3] } else { seeds };
    let base = FitOptions::default();
    let variants: Vec<(&str, FitOptions)> = vec![
        ("default", base.clone()),
        ("tolerance 1e-4", FitOptions { tolerance: Some(1e-4), ..base.clone() }),
        ("tolerance 1e-2", FitOptions { tolerance: Some(1e-2), ..base.clone() }),
        ("max_iterations 200", FitOptions { max_iterations: 200, ..base.clone() }),
        ("transition_pseudocount 0", FitOptions { transition_pseudocount: 0.0, ..base.clone() }),
        ("transition_pseudocount 1", FitOptions { transition_pseudocount: 1.0, ..base.clone() }),
        ("min_variance 0", FitOptions { min_variance: 0.0, ..base.clone() }),
        ("min_variance 1/3", FitOptions { min_variance: 1.0 / 3.0, ..base.clone() }),
    ];
    for seed in seeds {
        println!("seed {seed}");
        for (name, options) in &variants {
            let started = Instant::now();
            let experiment =
                BaumWelchExperiment { seed, options: options.clone(), ..BaumWelchExperiment::default() };
            match baum_welch::run(&experiment) {
                Ok(report) => {
                    let last: Vec<String> = report
                        .curves
                        .iter()
                        .map(|c| {
                            let its =
                                c.iterations.iter().sum::<usize>() as f64 / c.iterations.len().max(1) as f64;
                            format!(
                                "{} {:.1}% ({its:.0} it)",
                                c.name,
                                100.0 * c.accuracy.last().copied().unwrap_or(0.0)
                            )
                        })
                        .collect();
                    println!(
                        "  {name:<28} true {:.1}%  {}  {:.0} s",
                        100.0 * report.true_accuracy,
                        last.join(", "),
                        started.elapsed().as_secs_f64()
                    );
                }
                Err(e) => println!("  {name:<28} failed: {e}"),
            }
        }
    }
}
