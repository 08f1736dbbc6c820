//! Plots of a report, drawn with plotters into an RGB buffer and written as PNG.
//!
//! | plot | x | y |
//! | --- | --- | --- |
//! | loss curves | loss evaluations | best loss so far, log scale; one line per model |
//! | posterior | model | posterior mean (dot) and 95% interval (bar); one panel per parameter |
//!
//! Text uses DejaVu Sans, bundled in `assets/fonts/` (licence beside it) and registered with
//! plotters' `ab_glyph` backend, so plotting needs no system fontconfig or freetype.

use super::{ModelRow, Posterior};
use crate::bsdf::Model;
use crate::capture::image_io::write_png_rgb8;
use crate::error::{Error, Result};
use plotters::prelude::*;
use std::collections::BTreeSet;
use std::path::Path;
use std::sync::Once;

const FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");
const WIDTH: u32 = 900;
const HEIGHT: u32 = 540;

/// Register the bundled font as plotters' sans-serif family (once per process).
fn register_font() {
    static REGISTER: Once = Once::new();
    REGISTER.call_once(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, FONT)
            .unwrap_or_else(|_| panic!("the bundled DejaVu Sans is a valid font"));
    });
}

/// Draw into a `WIDTH x HEIGHT` white canvas with `draw` and write it to `path` as PNG.
pub(crate) fn draw_png(
    path: &Path,
    draw: impl FnOnce(
        &DrawingArea<BitMapBackend, plotters::coord::Shift>,
    ) -> std::result::Result<(), Box<dyn std::error::Error>>,
) -> Result<()> {
    draw_png_sized(path, (WIDTH, HEIGHT), draw)
}

/// Draw into a white canvas of `(width, height)` with `draw` and write it to `path` as PNG.
fn draw_png_sized(
    path: &Path,
    (width, height): (u32, u32),
    draw: impl FnOnce(
        &DrawingArea<BitMapBackend, plotters::coord::Shift>,
    ) -> std::result::Result<(), Box<dyn std::error::Error>>,
) -> Result<()> {
    register_font();
    let mut buffer = vec![0u8; (width * height * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| Error::io(path, e))?;
        draw(&root).map_err(|e| Error::io(path, e))?;
        root.present().map_err(|e| Error::io(path, e))?;
    }
    write_png_rgb8(path, &buffer, width, height)
}

/// Size of a colour bar image.
pub const COLOUR_BAR: (u32, u32) = (384, 64);

/// A horizontal colour bar: `colour(t)` for `t` from 0 at the left to 1 at the right, tick
/// marks with their labels at `(t, label)` of `ticks`, and `caption` above.
pub fn colour_bar(
    path: &Path,
    caption: &str,
    colour: impl Fn(f64) -> [u8; 3],
    ticks: &[(f64, String)],
) -> Result<()> {
    let (width, _) = COLOUR_BAR;
    let (left, right, top, bottom) = (16i32, width as i32 - 16, 22i32, 40i32);
    draw_png_sized(path, COLOUR_BAR, |root| {
        let font: TextStyle = ("sans-serif", 14).into_font().into();
        root.draw(&Text::new(caption.to_string(), (left, 3), font.clone()))?;
        for x in left..right {
            let [r, g, b] = colour(f64::from(x - left) / f64::from(right - left - 1));
            root.draw(&Rectangle::new(
                [(x, top), (x + 1, bottom)],
                RGBColor(r, g, b).filled(),
            ))?;
        }
        for (t, label) in ticks {
            let x = left + (t * f64::from(right - left - 1)).round() as i32;
            root.draw(&PathElement::new(vec![(x, bottom), (x, bottom + 4)], BLACK))?;
            let (text_width, _) = root.estimate_text_size(label, &font)?;
            let at = (x - text_width as i32 / 2).clamp(0, width as i32 - text_width as i32);
            root.draw(&Text::new(label.clone(), (at, bottom + 6), font.clone()))?;
        }
        Ok(())
    })
}

/// Loss against evaluations for every model (the optimiser traces), log y.
pub fn loss_curves(path: &Path, rows: &[ModelRow]) -> Result<()> {
    let points: Vec<(f64, f64)> = rows
        .iter()
        .flat_map(|r| &r.trace)
        .map(|t| (t.evaluations as f64, t.loss))
        .filter(|(_, loss)| loss.is_finite() && *loss > 0.0)
        .collect();
    let x_max = points.iter().map(|p| p.0).fold(1.0, f64::max);
    let y_min = points.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
    let y_max = points.iter().map(|p| p.1).fold(0.0, f64::max);
    let (y_min, y_max) = if points.is_empty() {
        (1e-3, 1.0)
    } else {
        (y_min / 1.5, y_max * 1.5)
    };
    draw_png(path, |root| {
        let mut chart = ChartBuilder::on(root)
            .caption("Loss during each fit", ("sans-serif", 22))
            .margin(14)
            .x_label_area_size(44)
            .y_label_area_size(84)
            .build_cartesian_2d(0.0..x_max * 1.02, (y_min..y_max).log_scale())?;
        chart
            .configure_mesh()
            .x_desc("loss evaluations")
            .y_desc("loss (best so far)")
            .y_label_formatter(&|v| format!("{v:.1e}"))
            .draw()?;
        for (i, row) in rows.iter().enumerate() {
            let colour = Palette99::pick(i).to_rgba();
            let line: Vec<(f64, f64)> = row
                .trace
                .iter()
                .map(|t| (t.evaluations as f64, t.loss))
                .filter(|(_, loss)| loss.is_finite() && *loss > 0.0)
                .collect();
            chart
                .draw_series(LineSeries::new(line, colour.stroke_width(2)))?
                .label(row.model.name())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
                });
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 16))
            .draw()?;
        Ok(())
    })
}

/// Posterior mean and 95% interval of every parameter, one panel per parameter, models along x.
pub fn posterior_intervals(path: &Path, posteriors: &[(Model, &Posterior)]) -> Result<()> {
    let names: Vec<&String> = posteriors
        .iter()
        .flat_map(|(_, p)| p.params.keys())
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    let columns = names.len().clamp(1, 3);
    let panel_rows = names.len().div_ceil(columns).max(1);
    draw_png(path, |root| {
        let panels = root.split_evenly((panel_rows, columns));
        for (panel, name) in panels.iter().zip(&names) {
            let summaries: Vec<(usize, f64, [f64; 2])> = posteriors
                .iter()
                .enumerate()
                .filter_map(|(i, (_, p))| p.params.get(*name).map(|s| (i, s.mean, s.ci95)))
                .collect();
            let lo = summaries
                .iter()
                .map(|s| s.2[0])
                .fold(f64::INFINITY, f64::min);
            let hi = summaries
                .iter()
                .map(|s| s.2[1])
                .fold(-f64::INFINITY, f64::max);
            let pad = ((hi - lo) * 0.15).max(1e-6 * hi.abs().max(1e-12));
            let mut chart = ChartBuilder::on(panel)
                .caption(name.as_str(), ("sans-serif", 18))
                .margin(10)
                .x_label_area_size(30)
                .y_label_area_size(64)
                .build_cartesian_2d(-0.5..posteriors.len() as f64 - 0.5, lo - pad..hi + pad)?;
            chart
                .configure_mesh()
                .disable_x_mesh()
                .x_labels(posteriors.len())
                .x_label_formatter(&|x| {
                    let i = x.round();
                    if (x - i).abs() < 1e-9 && i >= 0.0 && (i as usize) < posteriors.len() {
                        posteriors[i as usize].0.name().to_string()
                    } else {
                        String::new()
                    }
                })
                .draw()?;
            for (i, mean, ci) in summaries {
                let colour = Palette99::pick(i).to_rgba();
                let x = i as f64;
                chart.draw_series(std::iter::once(PathElement::new(
                    vec![(x, ci[0]), (x, ci[1])],
                    colour.stroke_width(3),
                )))?;
                chart.draw_series(std::iter::once(Circle::new((x, mean), 5, colour.filled())))?;
            }
        }
        Ok(())
    })
}

/// Share of pixels that are neither white nor grey (a plotted series is coloured): what the
/// plot tests look for.
#[cfg(test)]
pub(crate) fn coloured_share(img: &image::RgbImage) -> f64 {
    let coloured = img
        .pixels()
        .filter(|p| {
            let [r, g, b] = p.0.map(i32::from);
            (r - g).abs().max((g - b).abs()).max((r - b).abs()) > 60
        })
        .count();
    coloured as f64 / (img.width() * img.height()) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::ParamPosterior;

    /// Decoded RGB pixels of a PNG.
    fn pixels(path: &Path) -> image::RgbImage {
        image::open(path).unwrap().to_rgb8()
    }

    #[test]
    fn posterior_plot_draws_a_coloured_interval_per_model_and_parameter() {
        let dir = tempfile::tempdir().unwrap();
        let posterior = |alpha: f64| Posterior {
            params: [
                (
                    "alpha".to_string(),
                    ParamPosterior {
                        mean: alpha,
                        ci95: [alpha - 0.01, alpha + 0.01],
                    },
                ),
                (
                    "f0_r".to_string(),
                    ParamPosterior {
                        mean: 0.9,
                        ci95: [0.88, 0.92],
                    },
                ),
            ]
            .into(),
            models: [("single".to_string(), 0.3), ("heitz".to_string(), 0.7)].into(),
            rhat_max: 1.01,
            ess_min: 400.0,
            samples: 2000,
        };
        let (a, b) = (posterior(0.45), posterior(0.5));
        let path = dir.path().join("posterior.png");
        posterior_intervals(&path, &[(Model::Single, &a), (Model::Heitz, &b)]).unwrap();
        let img = pixels(&path);
        assert_eq!((img.width(), img.height()), (WIDTH, HEIGHT));
        let share = coloured_share(&img);
        assert!(share > 1e-4, "no coloured marks drawn ({share})");
        // Text is drawn with the bundled font: some pixels are black-ish (labels, axes).
        assert!(img.pixels().any(|p| p.0.iter().all(|&c| c < 60)));
    }

    #[test]
    fn an_empty_trace_still_gives_a_plot() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("loss.png");
        loss_curves(&path, &[]).unwrap();
        let img = pixels(&path);
        assert_eq!(coloured_share(&img), 0.0);
    }
}
