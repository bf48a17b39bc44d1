//! The static-view convergence plot (error against samples traced, one line per ordering).

use anyhow::Result;
use plotters::prelude::*;
use std::path::Path;

/// One ordering's curve: (samples traced, FLIP).
pub struct Curve {
    pub label: String,
    pub points: Vec<(f64, f64)>,
}

fn plot_err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow::anyhow!("plotting failed: {e:?}")
}

/// Writes the curves into an SVG file.
pub fn convergence_plot(file: &Path, curves: &[Curve]) -> Result<()> {
    let all = curves.iter().flat_map(|c| c.points.iter());
    let (x_max, y_max) = all.fold((1.0f64, 1e-6f64), |(x, y), p| (x.max(p.0), y.max(p.1)));
    let root = SVGBackend::new(file, (720, 420)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "Static view: FLIP against samples traced",
            ("sans-serif", 18),
        )
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(56)
        .build_cartesian_2d(0.0..x_max, 0.0..y_max * 1.05)
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .x_desc("samples traced")
        .y_desc("mean FLIP")
        .draw()
        .map_err(plot_err)?;
    for (i, c) in curves.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        chart
            .draw_series(LineSeries::new(c.points.clone(), color.stroke_width(2)))
            .map_err(plot_err)?
            .label(c.label.clone())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], color));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(plot_err)?;
    root.present().map_err(plot_err)
}
