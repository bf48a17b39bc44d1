//! Results over several seeds: each seed's rows averaged over its paths, then the mean and
//! spread of every metric over the seeds, and paired differences between two orderings.

use psao_scene::{generate_paths, CameraPath, PathGenConfig, Scene};
use serde::Serialize;

use super::metrics::MeanError;
use super::run::{evaluate_path, Budget, EvalConfig, PathEval, Row, Tracers};
use super::EvalError;
use crate::path_caster::TracerCaster;
use crate::spread::{spread, Spread};

/// The camera paths a seed's runs follow.
pub enum Paths<'a> {
    /// The same committed path for every seed.
    Fixed(&'a CameraPath),
    /// `count` paths generated per seed ([`generate_paths`]).
    Generated {
        /// Paths per seed.
        count: usize,
        /// The generator's settings.
        config: PathGenConfig,
    },
}

/// The runs of one seed.
#[derive(Serialize)]
pub struct SeedRun {
    /// The seed (of the paths and of every random choice of the runs).
    pub seed: u64,
    /// One evaluation per path.
    pub paths: Vec<PathEval>,
    /// Their rows averaged over the paths.
    pub rows: Vec<Row>,
}

/// Runs over several seeds with their summary.
#[derive(Serialize)]
pub struct SeedsReport {
    /// Per seed.
    pub runs: Vec<SeedRun>,
    /// Every row's metrics over the seeds.
    pub summary: Vec<SummaryRow>,
    /// The saliency ordering against the uniform one, paired by seed (empty unless both ran).
    pub saliency_vs_uniform: Vec<Paired>,
}

/// Evaluates `config` on `paths` once per seed of `seeds` (the seed replaces `config.seed`).
pub fn evaluate_seeds(
    scene: &Scene,
    tracers: &Tracers,
    paths: &Paths<'_>,
    seeds: &[u64],
    config: &EvalConfig,
    tick: &mut dyn FnMut(),
) -> Result<SeedsReport, EvalError> {
    if seeds.is_empty() {
        return Err(EvalError::Config("at least one seed is needed".into()));
    }
    let mut runs = Vec::new();
    for &seed in seeds {
        let cameras = match paths {
            Paths::Fixed(p) => vec![(*p).clone()],
            Paths::Generated { count, config } => {
                let caster = TracerCaster::new(scene, &tracers.primary);
                generate_paths(scene, &caster, config, *count, seed)?
            }
        };
        let config = EvalConfig {
            seed,
            ..config.clone()
        };
        let evals = cameras
            .iter()
            .map(|p| evaluate_path(scene, tracers, p, &config, tick))
            .collect::<Result<Vec<_>, _>>()?;
        let rows = average_rows(&evals.iter().map(|e| e.rows.clone()).collect::<Vec<_>>());
        runs.push(SeedRun {
            seed,
            paths: evals,
            rows,
        });
    }
    let per_seed: Vec<Vec<Row>> = runs.iter().map(|r| r.rows.clone()).collect();
    Ok(SeedsReport {
        summary: summarize(&per_seed),
        saliency_vs_uniform: paired(&per_seed, "saliency", "uniform"),
        runs,
    })
}

/// The metrics of [`MeanError`] by name, and whether lower is better.
pub const METRICS: [(&str, bool); 6] = [
    ("psnr", false),
    ("flip", true),
    ("nd_psnr", false),
    ("nd_flip", true),
    ("centre_flip", true),
    ("saliency_flip", true),
];

/// The value of metric `name` (one of [`METRICS`]).
pub fn metric(e: &MeanError, name: &str) -> Option<f64> {
    match name {
        "psnr" => Some(e.psnr),
        "flip" => Some(e.flip),
        "nd_psnr" => e.nd_psnr,
        "nd_flip" => e.nd_flip,
        "centre_flip" => Some(e.centre_flip),
        "saliency_flip" => Some(e.saliency_flip),
        _ => None,
    }
}

/// One ordering and budget over the seeds.
#[derive(Clone, Debug, Serialize)]
pub struct SummaryRow {
    /// Ordering (`base` for the base frame).
    pub order: String,
    /// Budget per frame.
    pub budget: Budget,
    /// Samples traced per frame (mean over the seeds).
    pub traced_per_frame: f64,
    /// Share of frames with a lower PSNR than the base frame (mean over the seeds).
    pub worse_psnr_share: f64,
    /// Share of frames with a higher FLIP than the base frame (mean over the seeds).
    pub worse_flip_share: f64,
    /// Each metric of [`METRICS`] with its spread over the seeds (metrics no seed has are
    /// left out).
    pub metrics: Vec<(String, Spread)>,
}

/// The mean of `value` of row `i` over `runs` (each a list of rows in one order).
fn mean_of(runs: &[Vec<Row>], i: usize, value: fn(&Row) -> f64) -> f64 {
    runs.iter().map(|r| value(&r[i])).sum::<f64>() / runs.len().max(1) as f64
}

/// Averages rows of the same ordering and budget over paths (`paths[p]` are path `p`'s rows,
/// all in the same order); non-diffuse metrics over the paths that have them.
pub fn average_rows(paths: &[Vec<Row>]) -> Vec<Row> {
    let Some(first) = paths.first() else {
        return Vec::new();
    };
    (0..first.len())
        .map(|i| {
            let rows: Vec<&MeanError> = paths.iter().map(|p| &p[i].error).collect();
            let avg = |f: fn(&MeanError) -> Option<f64>| {
                let v: Vec<f64> = rows.iter().filter_map(|e| f(e)).collect();
                spread(&v).map(|s| s.mean)
            };
            Row {
                order: first[i].order.clone(),
                budget: first[i].budget,
                traced_per_frame: mean_of(paths, i, |r| r.traced_per_frame),
                worse_psnr_share: mean_of(paths, i, |r| r.worse_psnr_share),
                worse_flip_share: mean_of(paths, i, |r| r.worse_flip_share),
                error: MeanError {
                    psnr: avg(|e| Some(e.psnr)).unwrap_or(0.0),
                    flip: avg(|e| Some(e.flip)).unwrap_or(0.0),
                    nd_psnr: avg(|e| e.nd_psnr),
                    nd_flip: avg(|e| e.nd_flip),
                    saliency_flip: avg(|e| Some(e.saliency_flip)).unwrap_or(0.0),
                    centre_flip: avg(|e| Some(e.centre_flip)).unwrap_or(0.0),
                },
            }
        })
        .collect()
}

/// The spread over seeds of every row (`per_seed[s]`: seed `s`'s rows, all in one order).
pub fn summarize(per_seed: &[Vec<Row>]) -> Vec<SummaryRow> {
    let Some(first) = per_seed.first() else {
        return Vec::new();
    };
    (0..first.len())
        .map(|i| SummaryRow {
            order: first[i].order.clone(),
            budget: first[i].budget,
            traced_per_frame: mean_of(per_seed, i, |r| r.traced_per_frame),
            worse_psnr_share: mean_of(per_seed, i, |r| r.worse_psnr_share),
            worse_flip_share: mean_of(per_seed, i, |r| r.worse_flip_share),
            metrics: METRICS
                .iter()
                .filter_map(|&(name, _)| {
                    let v: Vec<f64> = per_seed
                        .iter()
                        .filter_map(|rows| metric(&rows[i].error, name))
                        .collect();
                    spread(&v).map(|s| (name.to_string(), s))
                })
                .collect(),
        })
        .collect()
}

/// Ordering `a` against ordering `b` on one metric at one budget, paired by seed.
#[derive(Clone, Debug, Serialize)]
pub struct Paired {
    /// Budget per frame.
    pub budget: Budget,
    /// Metric name.
    pub metric: String,
    /// `a − b` per seed, relative to `b`, in percent.
    pub difference_pct: Spread,
    /// Seeds on which `a` is better than `b`.
    pub a_better: usize,
}

/// Paired differences of ordering `a` against `b` for every budget and metric.
pub fn paired(per_seed: &[Vec<Row>], a: &str, b: &str) -> Vec<Paired> {
    let Some(first) = per_seed.first() else {
        return Vec::new();
    };
    let find = |rows: &[Row], order: &str, budget: Budget| {
        rows.iter()
            .find(|r| r.order == order && r.budget == budget)
            .map(|r| r.error)
    };
    let mut out = Vec::new();
    for budget in first.iter().filter(|r| r.order == a).map(|r| r.budget) {
        for &(name, lower_better) in &METRICS {
            let pairs: Vec<(f64, f64)> = per_seed
                .iter()
                .filter_map(|rows| {
                    let x = metric(&find(rows, a, budget)?, name)?;
                    let y = metric(&find(rows, b, budget)?, name)?;
                    Some((x, y))
                })
                .collect();
            let diffs: Vec<f64> = pairs
                .iter()
                .map(|&(x, y)| 100.0 * (x - y) / y.abs().max(1e-12))
                .collect();
            let Some(difference_pct) = spread(&diffs) else {
                continue;
            };
            out.push(Paired {
                budget,
                metric: name.into(),
                difference_pct,
                a_better: pairs
                    .iter()
                    .filter(|&&(x, y)| if lower_better { x < y } else { x > y })
                    .count(),
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(order: &str, budget: usize, flip: f64, nd: Option<f64>) -> Row {
        Row {
            order: order.into(),
            budget: Budget::Samples(budget),
            traced_per_frame: budget as f64,
            worse_psnr_share: 0.0,
            worse_flip_share: 0.0,
            error: MeanError {
                psnr: 30.0 + 10.0 * flip,
                flip,
                nd_psnr: nd.map(|v| 20.0 + v),
                nd_flip: nd,
                saliency_flip: flip,
                centre_flip: flip,
            },
        }
    }

    #[test]
    fn paths_average_and_seeds_spread() {
        let seed1 = average_rows(&[
            vec![row("saliency", 10, 0.2, None)],
            vec![row("saliency", 10, 0.4, Some(0.5))],
        ]);
        assert!((seed1[0].error.flip - 0.3).abs() < 1e-12);
        assert_eq!(seed1[0].error.nd_flip, Some(0.5));
        let seed2 = vec![row("saliency", 10, 0.5, None)];
        let summary = summarize(&[seed1, seed2]);
        let flip = &summary[0]
            .metrics
            .iter()
            .find(|(n, _)| n == "flip")
            .unwrap()
            .1;
        assert!((flip.mean - 0.4).abs() < 1e-12 && flip.n == 2);
        let nd = &summary[0]
            .metrics
            .iter()
            .find(|(n, _)| n == "nd_flip")
            .unwrap()
            .1;
        assert_eq!(nd.n, 1);
    }

    #[test]
    fn pairs_count_the_seeds_each_ordering_wins() {
        let seeds = vec![
            vec![
                row("saliency", 10, 0.1, None),
                row("uniform", 10, 0.2, None),
            ],
            vec![
                row("saliency", 10, 0.3, None),
                row("uniform", 10, 0.2, None),
            ],
            vec![
                row("saliency", 10, 0.1, None),
                row("uniform", 10, 0.4, None),
            ],
        ];
        let p = paired(&seeds, "saliency", "uniform");
        let flip = p.iter().find(|p| p.metric == "flip").unwrap();
        assert_eq!((flip.budget, flip.a_better), (Budget::Samples(10), 2));
        assert!((flip.difference_pct.mean - (-50.0 + 50.0 - 75.0) / 3.0).abs() < 1e-9);
        // PSNR: higher is better, so the same seeds win.
        assert_eq!(p.iter().find(|p| p.metric == "psnr").unwrap().a_better, 1);
    }
}
