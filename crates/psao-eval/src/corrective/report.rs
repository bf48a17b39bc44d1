//! Markdown tables of the corrective evaluation ([`super::run`], [`super::seeds`]).

use super::run::{EvalConfig, PathEval, Row};
use super::seeds::{Paired, SeedsReport, METRICS};
use crate::spread::Spread;

/// Column titles of the metrics, in the order of [`METRICS`].
const TITLES: [&str; 6] = [
    "PSNR (dB)",
    "FLIP",
    "non-diffuse PSNR (dB)",
    "non-diffuse FLIP",
    "centre-bias FLIP",
    "saliency-weighted FLIP (the model's own)",
];

fn header(first: &str) -> String {
    let mut s = format!("| {first} | budget / frame | traced / frame |");
    for t in TITLES {
        s += &format!(" {t} |");
    }
    s += " frames worse than base: PSNR / FLIP |\n|---|---|---|";
    s += &"---|".repeat(TITLES.len() + 1);
    s + "\n"
}

/// Digits shown for metric `name`: dB with two decimals, FLIP with four.
fn digits(name: &str) -> usize {
    if name.ends_with("psnr") {
        2
    } else {
        4
    }
}

/// A table of one run's rows (averages over its frames).
pub fn rows_table(rows: &[Row]) -> String {
    let mut s = header("order");
    for r in rows {
        s += &format!("| {} | {} | {:.0} |", r.order, r.budget, r.traced_per_frame);
        for &(name, _) in &METRICS {
            s += &match super::seeds::metric(&r.error, name) {
                Some(v) => format!(" {v:.*} |", digits(name)),
                None => " – |".into(),
            };
        }
        s += &worse(r.worse_psnr_share, r.worse_flip_share);
    }
    s
}

/// The last column: shares of frames worse than the base frame, in percent.
fn worse(psnr: f64, flip: f64) -> String {
    format!(" {:.1} % / {:.1} % |\n", 100.0 * psnr, 100.0 * flip)
}

fn mean_sd(s: &Spread, digits: usize) -> String {
    format!("{:.*} ± {:.*}", digits, s.mean, digits, s.sd)
}

/// A table of the summary over seeds: mean ± sample standard deviation.
pub fn summary_table(report: &SeedsReport) -> String {
    let mut s = header("order");
    for r in &report.summary {
        s += &format!("| {} | {} | {:.0} |", r.order, r.budget, r.traced_per_frame);
        for &(name, _) in &METRICS {
            s += &match r.metrics.iter().find(|(n, _)| n == name) {
                Some((_, v)) => format!(" {} |", mean_sd(v, digits(name))),
                None => " – |".into(),
            };
        }
        s += &worse(r.worse_psnr_share, r.worse_flip_share);
    }
    s
}

/// A table of paired differences: saliency − uniform relative to uniform, per seed.
pub fn paired_table(pairs: &[Paired]) -> String {
    let mut s = String::from(
        "| budget / frame | metric | saliency − uniform (% of uniform, mean ± sd) | min … max | seeds saliency better |\n|---|---|---|---|---|\n",
    );
    for p in pairs {
        let d = &p.difference_pct;
        s += &format!(
            "| {} | {} | {:+.2} ± {:.2} | {:+.2} … {:+.2} | {} of {} |\n",
            p.budget, p.metric, d.mean, d.sd, d.min, d.max, p.a_better, d.n
        );
    }
    s
}

/// What the base frame and the reference are.
fn base_description(config: &EvalConfig) -> String {
    let samples = if config.full_samples {
        "full radiance relative to the base at their pixel"
    } else {
        "the view-dependent part over the base's diffuse share"
    };
    match config.lighting {
        None => format!(
            "base: the AO composite with {} AO rays per point (the reference shades diffuse pixels the same way); samples: {samples}",
            config.ao_spp
        ),
        Some(g) => format!(
            "base: the lit composite with {} paths per point and {} bounces; reference: path-traced diffuse lighting with {} paths per point plus the reflected and refracted paths; samples: {samples}",
            g.base_paths, g.bounces, g.reference_paths,
        ),
    }
}

/// The report of one run along one path.
pub fn path_markdown(scene: &str, config: &EvalConfig, eval: &PathEval) -> String {
    let mut s = format!(
        "# Corrective splatting evaluation\n\nScene `{scene}`, path `{}`, {}×{}, frames {}..{}, {} √5 levels, analysis every {} frames, {}, seed {}.\n\n",
        eval.path, config.width, config.height, eval.frames.start, eval.frames.end, eval.levels,
        config.analyze_every, base_description(config), config.seed
    );
    s += "## Averages over the frames (against the reference)\n\n";
    s += &rows_table(&eval.rows);
    if !eval.convergence.is_empty() {
        s += "\n## Static view (first frame's camera)\n\n| order | budget / frame | non-diffuse pixels | samples traced | bit-identical at the end |\n|---|---|---|---|---|\n";
        for c in &eval.convergence {
            s += &format!(
                "| {} | {} | {} | {} | {} |\n",
                c.order, c.budget, c.non_diffuse_pixels, c.samples_traced, c.bit_identical
            );
        }
        s += "\n![FLIP against samples](convergence.svg)\n";
    }
    s += "\n## Timing\n\n";
    let t = &eval.timing;
    s += &format!(
        "| worker samples/s | threads | aging ms | reprojection + splatting ms | analysis ms | mean cache size | max cache size |\n|---|---|---|---|---|---|---|\n| {:.0} | {} | {:.3} | {:.3} | {:.1} | {:.0} | {} |\n",
        t.worker_samples_per_s, t.threads, t.aging_ms, t.splat_ms, t.analysis_ms, t.mean_cache_size, t.max_cache_size
    );
    s += "\nImages of the middle frame: `base.png`, `corrected.png` (first ordering, largest sample budget), `reference.png`.\n";
    s
}

/// The report of runs over several seeds.
pub fn seeds_markdown(
    scene: &str,
    config: &EvalConfig,
    paths: &str,
    report: &SeedsReport,
) -> String {
    let seeds: Vec<String> = report.runs.iter().map(|r| r.seed.to_string()).collect();
    let mut s = format!(
        "# Corrective splatting evaluation over seeds\n\nScene `{scene}`, {paths}, {}×{}, seeds {}, analysis every {} frames, {}. Each seed's rows are averaged over its paths' frames; the table gives their mean ± sample standard deviation over the seeds.\n\n",
        config.width, config.height, seeds.join(", "), config.analyze_every, base_description(config)
    );
    s += &summary_table(report);
    if !report.saliency_vs_uniform.is_empty() {
        s += "\n## Saliency against uniform ordering, paired by seed\n\n";
        s += &paired_table(&report.saliency_vs_uniform);
    }
    s += "\n## Per seed\n\n";
    for run in &report.runs {
        let names: Vec<&str> = run.paths.iter().map(|p| p.path.as_str()).collect();
        s += &format!("### Seed {} ({})\n\n", run.seed, names.join(", "));
        s += &rows_table(&run.rows);
        s += "\n";
    }
    s
}
