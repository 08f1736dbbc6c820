//! The run-time-versus-error plot of `bouncefit bench` (PNG, through the report's plotters
//! canvas and bundled font, [`crate::report::plots`]).
//!
//! | panel | x (log) | y (log) | curves |
//! | --- | --- | --- | --- |
//! | left | CPU time of one n-sample estimate, `n x ns_per_eval` | `rmse`: error against the model's own converged value | one per stochastic model, a point per sample count (analytic models have rmse 0, which a log axis cannot show) |
//! | right | the same | `rmse_vs_heitz`: error against converged `heitz`, noise and bias together | the stochastic models as on the left, each analytic model as one cross at its time per evaluation |

use super::estimators::EstimatorRow;
use crate::bsdf::Model;
use crate::error::Result;
use crate::report::plots::draw_png;
use plotters::prelude::*;
use std::path::Path;

/// One model's points: (ns per estimate, error), in sample-count order.
fn series(rows: &[EstimatorRow], model: Model, error: fn(&EstimatorRow) -> f64) -> Vec<(f64, f64)> {
    rows.iter()
        .filter(|r| r.model == model)
        .map(|r| (r.samples as f64 * r.ns_per_eval, error(r)))
        .filter(|&(x, y)| x > 0.0 && y > 0.0 && x.is_finite() && y.is_finite())
        .collect()
}

/// A model's points in a panel, and whether it is stochastic (a curve) or not (one cross).
struct Series {
    model: Model,
    stochastic: bool,
    points: Vec<(f64, f64)>,
}

/// A log axis range around `values` (a decade when there are none).
fn log_range(values: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
    let (lo, hi) = values.fold((f64::INFINITY, 0.0f64), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    if lo.is_finite() && hi > 0.0 {
        lo / 1.6..hi * 1.6
    } else {
        0.1..1.0
    }
}

/// Draw the two panels of the module table into `path`.
pub fn error_against_time(path: &Path, rows: &[EstimatorRow]) -> Result<()> {
    let mut models: Vec<Model> = Vec::new();
    for r in rows {
        if !models.contains(&r.model) {
            models.push(r.model);
        }
    }
    let colour = |model: Model| {
        Palette99::pick(Model::ALL.iter().position(|&m| m == model).unwrap_or(0)).to_rgba()
    };
    type Error = fn(&EstimatorRow) -> f64;
    let panels: [(&str, Error, bool); 2] = [
        ("error vs own converged value", |r| r.rmse, false),
        ("error vs converged heitz", |r| r.rmse_vs_heitz, true),
    ];
    draw_png(path, |root| {
        for (area, (title, error, with_analytic)) in root.split_evenly((1, 2)).iter().zip(panels) {
            let shown: Vec<Series> = models
                .iter()
                .filter_map(|&m| {
                    let stochastic = rows.iter().any(|r| r.model == m && r.stochastic);
                    let mut points = series(rows, m, error);
                    if !stochastic {
                        points.truncate(1);
                    }
                    (stochastic || with_analytic).then_some(Series {
                        model: m,
                        stochastic,
                        points,
                    })
                })
                .collect();
            let all = || shown.iter().flat_map(|s| s.points.iter().copied());
            let mut chart = ChartBuilder::on(area)
                .caption(title, ("sans-serif", 18))
                .margin(10)
                .x_label_area_size(40)
                .y_label_area_size(64)
                .build_cartesian_2d(
                    log_range(all().map(|p| p.0)).log_scale(),
                    log_range(all().map(|p| p.1)).log_scale(),
                )?;
            chart
                .configure_mesh()
                .x_desc("ns per estimate (n x ns per eval, one core)")
                .y_desc("RMS relative error")
                .x_label_formatter(&|v| format!("{v:.0e}"))
                .y_label_formatter(&|v| format!("{v:.0e}"))
                .draw()?;
            for Series {
                model,
                stochastic,
                points,
            } in shown
            {
                let c = colour(model);
                let drawn = if stochastic {
                    chart.draw_series(LineSeries::new(points.clone(), c.stroke_width(2)))?;
                    chart.draw_series(points.iter().map(|&p| Circle::new(p, 3, c.filled())))?
                } else {
                    chart
                        .draw_series(points.iter().map(|&p| Cross::new(p, 6, c.stroke_width(2))))?
                };
                drawn.label(model.name()).legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 16, y)], c.stroke_width(2))
                });
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::LowerLeft)
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .label_font(("sans-serif", 13))
                .draw()?;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::plots::coloured_share;

    fn row(model: Model, samples: usize, stochastic: bool, rmse: f64) -> EstimatorRow {
        EstimatorRow {
            model,
            samples,
            stochastic,
            ns_per_eval: 100.0,
            ns_per_eval_wall: 120.0,
            rmse,
            rmse_rough: None,
            rmse_vs_heitz: rmse + 0.01,
            bias_vs_heitz: 0.01,
            bias_vs_heitz_mean: 0.0,
            bias_vs_heitz_noise: 0.0,
            worst_bias_vs_heitz: 0.0,
            worst_bias_at: String::new(),
            inverse_efficiency_vs_heitz: None,
            inverse_efficiency_vs_heitz_rough: None,
            relative_variance: rmse * rmse,
            relative_variance_rough: None,
            inverse_efficiency_vs_heitz_from_reference: None,
            inverse_efficiency_vs_heitz_from_reference_rough: None,
        }
    }

    /// A stochastic curve and an analytic cross are drawn in colour; a table with nothing a
    /// log axis can show still gives a picture.
    #[test]
    fn draws_curves_and_survives_an_empty_table() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bench.png");
        let rows: Vec<EstimatorRow> = [1, 4, 16]
            .iter()
            .map(|&n| row(Model::Heitz, n, true, 0.5 / (n as f64).sqrt()))
            .chain([row(Model::Single, 1, false, 0.0)])
            .collect();
        error_against_time(&path, &rows).unwrap();
        let share = coloured_share(&image::open(&path).unwrap().to_rgb8());
        assert!(share > 5e-4, "coloured share {share}");
        error_against_time(&path, &[row(Model::Single, 1, false, 0.0)]).unwrap();
    }
}
