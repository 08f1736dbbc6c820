//! The report of `compare --maps` (issue #17 item 3): maps fits of several models to the same
//! photos side by side, their re-renders and residuals, the held-out photo's error, and what
//! each multi-bounce model changes against `single` ([`crate::maps::compare`]).
//!
//! | file | content |
//! | --- | --- |
//! | `report.json` | [`MapsReport`] |
//! | `report.md`, `report.html` | the same pages as the uniform comparison ([`super::Page`]) |
//! | `maps.png` | one row per model (in `--models` order), one column per map ([`MapsImage`]), each texel a square of [`texel_pixels`] pixels (nearest neighbour, about [`MAP_PIXELS`] pixels a map) |
//! | `roughness_colour_bar.png` | the roughness column's colour bar |
//! | `uncertainty.png`, `uncertainty_<column>_bar.png` | per model (row) the per-texel sd of `ln alpha`, F0 and albedo (columns), upscaled as `maps.png`, on viridis up to each column's 99th percentile ([`UncertaintyImage`]), and each column's colour bar |
//! | `<model>-minus-single_alpha.png`, `_diffuse.png` | per texel `alpha` and mean diffuse albedo of `model` minus `single`, on the residuals' diverging map (red: larger in `model`) with full colour at `+-alpha_scale`, `+-diffuse_scale`, upscaled as `maps.png`; `_alpha_bar.png`, `_diffuse_bar.png` their colour bars |
//! | `relit/` | every model's fit under the bundled sky and its glTF export ([`super::relit`]) |
//! | `<model>/fit.json`, `<model>/fit.maps/` | the model's maps fit file, as `fit --maps` writes it |
//! | `<model>/<stem>_target.png`, `_fit.png`, `_residual.png` | per photo, held-out one included ([`super::images`]) |

use super::images::{diverging_colour, magnitude_scale, sequential_colour};
use super::plots::colour_bar;
use super::relit::Relit;
use super::{photo_grid, Page, Table};
use crate::bsdf::Model;
use crate::capture::image_io::{linear_to_srgb, write_png_rgb8};
use crate::error::{Error, Result};
use crate::fit::bayes::holdout::HeldOutPhoto;
use crate::maps::compare::{MapsDifference, TexelDeltas};
use crate::maps::fit::{MapsFit, Uncertainty};
use crate::maps::{MaterialMaps, TexelGrid};
use serde::Serialize;
use std::path::Path;

/// The map comparison image, relative to the report folder.
pub const MAPS_IMAGE: &str = "maps.png";
/// The roughness column's colour bar, relative to the report folder.
pub const ROUGHNESS_BAR: &str = "roughness_colour_bar.png";
/// Pixels of white between the cells of [`MAPS_IMAGE`].
pub const GAP: usize = 4;
/// Width a map is upscaled to, at least (64 texels become 256 pixels).
pub const MAP_PIXELS: usize = 256;

/// Pixels per texel side in the map images: a map [`MAP_PIXELS`] wide or wider, or 1:1 when
/// the grid is wider already.
pub fn texel_pixels(grid: TexelGrid) -> usize {
    MAP_PIXELS.div_ceil(grid.width).max(1)
}
/// Colour of a map a model does not have (e.g. `specular` with a known Fresnel).
const ABSENT: [u8; 3] = [40, 40, 40];

/// One model's line of the maps report.
#[derive(Clone, Debug, Serialize)]
pub struct MapsModelRow {
    pub model: Model,
    /// Wall seconds of the maps fit (as `maps_fit.seconds`).
    pub seconds: f64,
    /// Relative RMS error over the fitted pixels (as `maps_fit.train_error`).
    pub train_error: f64,
    /// The held-out photo's relative error and the naive baseline (`--holdout-photo`).
    pub holdout: Option<HeldOutPhoto>,
    /// The exposure fitted with `--fit-exposure`.
    pub exposure: Option<f64>,
    /// The model's maps fit file, relative to the report folder.
    pub fit_file: String,
    /// The fit's bases, basis trials, noise level, ... as the fit file's `maps_fit`.
    pub maps_fit: MapsFit,
}

/// The layout of [`MAPS_IMAGE`]: `rows` (models) by `columns` (maps) cells of the texel grid's
/// size times `texel_pixels`, [`GAP`] pixels apart.
#[derive(Clone, Debug, Serialize)]
pub struct MapsImage {
    pub path: String,
    pub rows: Vec<Model>,
    pub columns: Vec<&'static str>,
    pub cell: [usize; 2],
    /// Pixels per texel side.
    pub texel_pixels: usize,
    pub gap: usize,
    /// Encoding of each map in the image.
    pub encoding: &'static str,
    pub roughness_colour_bar: String,
}

/// A difference's images and their colour scales.
#[derive(Clone, Debug, Serialize)]
pub struct DifferenceImages {
    pub alpha: String,
    pub diffuse: String,
    /// Differences shown at full colour (the 99th percentile of their magnitudes).
    pub alpha_scale: f64,
    pub diffuse_scale: f64,
    pub alpha_colour_bar: String,
    pub diffuse_colour_bar: String,
}

/// What a multi-bounce model changes against `single`, with its images.
#[derive(Clone, Debug, Serialize)]
pub struct DifferenceRow {
    #[serde(flatten)]
    pub difference: MapsDifference,
    pub images: DifferenceImages,
}

/// Everything the maps report says: `report.json`. The fields shared with the uniform
/// comparison ([`super::Report`]) keep its names and meanings.
#[derive(Clone, Debug, Serialize)]
pub struct MapsReport {
    /// Always `"maps"` (the uniform report has no `kind`).
    pub kind: &'static str,
    pub capture: String,
    pub capture_name: String,
    pub photos: Vec<String>,
    pub pixels_used: usize,
    pub texels: [usize; 2],
    pub holdout_photo: Option<usize>,
    pub models: Vec<MapsModelRow>,
    pub maps_image: MapsImage,
    /// The per-texel standard deviations of every model's maps.
    pub uncertainty_image: UncertaintyImage,
    /// Each model other than `single` minus `single` (empty without `single`).
    pub differences: Vec<DifferenceRow>,
    pub relit: Relit,
    pub residual_scale: f64,
    pub verdicts: Vec<String>,
}

/// sRGB code of a linear value in [0, 1].
fn srgb8(v: f64) -> u8 {
    (linear_to_srgb(v.clamp(0.0, 1.0)) * 255.0).round() as u8
}

/// The colour of texel `t` of `map` of `maps`, as [`MapsImage::encoding`] says.
fn map_colour(maps: &MaterialMaps, map: &str, t: usize) -> [u8; 3] {
    match map {
        "diffuse" => maps.diffuse.as_ref().map(|d| d[t].map(srgb8)),
        "specular" => maps.specular.as_ref().map(|s| s[t].map(srgb8)),
        "roughness" => maps
            .roughness
            .as_ref()
            .map(|_| sequential_colour(maps.alpha(t))),
        _ => maps
            .normal
            .as_ref()
            .map(|n| n[t].map(|c| ((0.5 * c + 0.5).clamp(0.0, 1.0) * 255.0).round() as u8)),
    }
    .unwrap_or(ABSENT)
}

/// Writes [`MAPS_IMAGE`] and the roughness colour bar under `root`: a row per `(model, maps)`,
/// a column per map (`normal` only when some model has one); returns its layout.
pub fn write_maps_image(root: &Path, fits: &[(Model, &MaterialMaps)]) -> Result<MapsImage> {
    let grid = fits[0].1.grid;
    let mut columns = vec!["diffuse", "specular", "roughness"];
    if fits.iter().any(|(_, m)| m.normal.is_some()) {
        columns.push("normal");
    }
    let cell = write_cell_grid(
        &root.join(MAPS_IMAGE),
        grid,
        fits.len(),
        columns.len(),
        |r, c| {
            (0..grid.len())
                .map(|t| map_colour(fits[r].1, columns[c], t))
                .collect()
        },
    )?;
    let ticks = [0.0, 0.25, 0.5, 0.75, 1.0].map(|t| (t, format!("{t}")));
    colour_bar(
        &root.join(ROUGHNESS_BAR),
        "roughness alpha (sqrt(alpha_x alpha_y))",
        sequential_colour,
        &ticks,
    )?;
    Ok(MapsImage {
        path: MAPS_IMAGE.into(),
        rows: fits.iter().map(|(m, _)| *m).collect(),
        columns,
        cell,
        texel_pixels: texel_pixels(grid),
        gap: GAP,
        encoding: "each texel a square, nearest neighbour; diffuse and specular (F0): linear value as sRGB; roughness: alpha on viridis (colour bar; anisotropic texels: sqrt(alpha_x alpha_y)), 1 and above yellow; normal: (n + 1) / 2 per channel; dark grey: no such map",
        roughness_colour_bar: ROUGHNESS_BAR.into(),
    })
}

/// The per-texel standard deviations side by side: a row per model, a column per quantity.
#[derive(Clone, Debug, Serialize)]
pub struct UncertaintyImage {
    pub path: String,
    pub rows: Vec<Model>,
    /// `roughness` (the sd of `ln alpha`: alpha's relative sd), `specular` (of F0) and
    /// `diffuse` (of the albedo), these two the mean over RGB.
    pub columns: Vec<&'static str>,
    pub cell: [usize; 2],
    /// Per column, the sd shown at full colour (the 99th percentile over all rows' texels).
    pub scales: Vec<f64>,
    /// Per column, the median sd per row (`None`: the model has no such map).
    pub medians: Vec<Vec<Option<f64>>>,
    /// Per column, its colour bar.
    pub colour_bars: Vec<String>,
}

/// The per-texel standard deviations image, relative to the report folder.
pub const UNCERTAINTY_IMAGE: &str = "uncertainty.png";

/// The sd of `column` ([`UncertaintyImage::columns`]) per texel, if the fit has that map.
fn sd_values(uncertainty: &Uncertainty, column: &str) -> Option<Vec<f64>> {
    let mean = |v: &[[f32; 3]]| -> Vec<f64> {
        v.iter()
            .map(|c| c.iter().map(|&x| f64::from(x)).sum::<f64>() / 3.0)
            .collect()
    };
    match column {
        "roughness" => Some(
            uncertainty
                .roughness
                .iter()
                .map(|r| f64::from(r[2]))
                .collect(),
        ),
        "specular" => uncertainty.specular.as_deref().map(mean),
        _ => Some(mean(&uncertainty.diffuse)),
    }
}

/// Writes [`UNCERTAINTY_IMAGE`] and a colour bar per column under `root` (docs/maps.md,
/// "Uncertainty": the sds are the fit's per-texel Gauss-Newton posterior); returns its layout.
pub fn write_uncertainty_image(
    root: &Path,
    fits: &[(Model, &Uncertainty)],
) -> Result<UncertaintyImage> {
    let grid = fits[0].1.grid;
    let columns = vec!["roughness", "specular", "diffuse"];
    let values: Vec<Vec<Option<Vec<f64>>>> = columns
        .iter()
        .map(|c| fits.iter().map(|(_, u)| sd_values(u, c)).collect())
        .collect();
    let scales: Vec<f64> = values
        .iter()
        .map(|rows| magnitude_scale(rows.iter().flatten().flatten().copied()))
        .collect();
    let cell = write_cell_grid(
        &root.join(UNCERTAINTY_IMAGE),
        grid,
        fits.len(),
        columns.len(),
        |r, c| match &values[c][r] {
            Some(v) => v.iter().map(|x| sequential_colour(x / scales[c])).collect(),
            None => vec![ABSENT; grid.len()],
        },
    )?;
    let mut colour_bars = Vec::new();
    for (column, scale) in columns.iter().zip(&scales) {
        let name = format!("uncertainty_{column}_bar.png");
        let ticks = [0.0, 0.5, 1.0].map(|t| (t, format!("{:.3}", t * scale)));
        let caption = match *column {
            "roughness" => "sd of ln alpha (alpha's relative sd)",
            "specular" => "sd of F0 (mean over RGB)",
            _ => "sd of the diffuse albedo (mean over RGB)",
        };
        colour_bar(&root.join(&name), caption, sequential_colour, &ticks)?;
        colour_bars.push(name);
    }
    let medians = values
        .iter()
        .map(|rows| rows.iter().map(|v| v.as_deref().map(median)).collect())
        .collect();
    Ok(UncertaintyImage {
        path: UNCERTAINTY_IMAGE.into(),
        rows: fits.iter().map(|(m, _)| *m).collect(),
        columns,
        cell,
        scales,
        medians,
        colour_bars,
    })
}

fn median(values: &[f64]) -> f64 {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    sorted[sorted.len() / 2]
}

/// Writes an image of `rows` by `columns` cells, [`GAP`] pixels apart on white, each cell the
/// texel `colours(row, column)` of `grid` upscaled as [`texel_pixels`] says; returns the
/// cell's size in pixels.
fn write_cell_grid(
    path: &Path,
    grid: TexelGrid,
    rows: usize,
    columns: usize,
    colours: impl Fn(usize, usize) -> Vec<[u8; 3]>,
) -> Result<[usize; 2]> {
    let k = texel_pixels(grid);
    let cell = [grid.width * k, grid.height * k];
    let width = columns * cell[0] + (columns - 1) * GAP;
    let height = rows * cell[1] + (rows - 1) * GAP;
    let mut bytes = vec![255u8; width * height * 3];
    for row in 0..rows {
        for column in 0..columns {
            let origin = [column * (cell[0] + GAP), row * (cell[1] + GAP)];
            paint_upscaled(&mut bytes, width, origin, grid, k, &colours(row, column));
        }
    }
    write_rgb8(path, &bytes, width, height)?;
    Ok(cell)
}

/// Paints the texel `colours` of `grid` into the RGB `bytes` of an image `width` pixels wide,
/// each texel a `k` x `k` square, the grid's top-left corner at `origin`.
fn paint_upscaled(
    bytes: &mut [u8],
    width: usize,
    origin: [usize; 2],
    grid: TexelGrid,
    k: usize,
    colours: &[[u8; 3]],
) {
    for y in 0..grid.height * k {
        for x in 0..grid.width * k {
            let i = 3 * ((origin[1] + y) * width + origin[0] + x);
            bytes[i..i + 3].copy_from_slice(&colours[(y / k) * grid.width + x / k]);
        }
    }
}

fn write_rgb8(path: &Path, bytes: &[u8], width: usize, height: usize) -> Result<()> {
    let size = |n: usize| u32::try_from(n).map_err(|_| Error::invalid(path, "pixels", "too large"));
    write_png_rgb8(path, bytes, size(width)?, size(height)?)
}

/// Writes the difference images of `difference`, upscaled as [`MAPS_IMAGE`], and their colour
/// bars under `root`, and returns them.
pub fn write_difference_images(
    root: &Path,
    difference: &MapsDifference,
    deltas: &TexelDeltas,
    grid: TexelGrid,
) -> Result<DifferenceImages> {
    let name = |what: &str| format!("{}-minus-single_{what}.png", difference.model);
    let k = texel_pixels(grid);
    let write = |what: &str, values: &[f64]| -> Result<(String, f64)> {
        let scale = magnitude_scale(values.iter().copied());
        let colours: Vec<[u8; 3]> = values.iter().map(|&v| diverging_colour(v, scale)).collect();
        let [width, height] = [grid.width * k, grid.height * k];
        let mut bytes = vec![0u8; width * height * 3];
        paint_upscaled(&mut bytes, width, [0, 0], grid, k, &colours);
        write_rgb8(&root.join(name(what)), &bytes, width, height)?;
        let ticks =
            [-1.0, -0.5, 0.0, 0.5, 1.0].map(|t| ((t + 1.0) / 2.0, format!("{:+.3}", t * scale)));
        colour_bar(
            &root.join(name(&format!("{what}_bar"))),
            &format!("{what}: {} - single", difference.model),
            |t| diverging_colour(2.0 * t - 1.0, 1.0),
            &ticks,
        )?;
        Ok((name(what), scale))
    };
    let (alpha, alpha_scale) = write("alpha", &deltas.alpha)?;
    let (diffuse, diffuse_scale) = write("diffuse", &deltas.diffuse)?;
    Ok(DifferenceImages {
        alpha,
        diffuse,
        alpha_scale,
        diffuse_scale,
        alpha_colour_bar: name("alpha_bar"),
        diffuse_colour_bar: name("diffuse_bar"),
    })
}

impl MapsReport {
    /// The verdict sentences: which model predicts the held-out photo best, and what each
    /// multi-bounce model changes.
    pub fn verdicts(models: &[MapsModelRow], differences: &[DifferenceRow]) -> Vec<String> {
        let mut out = Vec::new();
        let held: Vec<(Model, &HeldOutPhoto)> = models
            .iter()
            .filter_map(|r| r.holdout.as_ref().map(|h| (r.model, h)))
            .collect();
        match held
            .iter()
            .min_by(|a, b| a.1.relative_error.total_cmp(&b.1.relative_error))
        {
            Some(&(best, h)) => {
                let all: Vec<String> = held
                    .iter()
                    .map(|(m, h)| format!("{m} {:.4}", h.relative_error))
                    .collect();
                out.push(format!(
                    "On the held-out photo {} ({}), {best} predicts best (relative errors: {}; the mean of the other photos: {}).",
                    h.photo,
                    h.stem,
                    all.join(", "),
                    h.mean_photo_error.map_or("n/a".into(), |e| format!("{e:.4}"))
                ));
            }
            None => {
                out.push("Held-out error was not computed (run with --holdout-photo N).".into())
            }
        }
        if differences.is_empty() {
            out.push(
                "No differences against single were computed (add single to --models).".into(),
            );
        }
        out.extend(differences.iter().map(|d| d.difference.summary()));
        out
    }
}

impl Page for MapsReport {
    fn title(&self) -> String {
        format!("Maps comparison: {}", self.capture_name)
    }

    fn settings(&self) -> Vec<(&'static str, String)> {
        vec![
            (
                "photo set",
                format!("{} ({})", self.capture_name, self.capture),
            ),
            ("photos", self.photos.len().to_string()),
            ("pixels in the fit", self.pixels_used.to_string()),
            ("texels", format!("{}x{}", self.texels[0], self.texels[1])),
            (
                "held-out photo",
                self.holdout_photo
                    .map_or("none".into(), |h| format!("{h} ({})", self.photos[h])),
            ),
            (
                "residual colour scale",
                format!(
                    "full red/blue at +-{:.3e} (fit - photo, mean over RGB)",
                    self.residual_scale
                ),
            ),
            ("maps image", self.maps_image.encoding.to_string()),
        ]
    }

    fn verdict_lines(&self) -> &[String] {
        &self.verdicts
    }

    fn tables(&self) -> Vec<Table> {
        let optional = |v: Option<f64>| v.map_or("n/a".to_string(), |v| format!("{v:.4}"));
        let models = Table {
            heading: "Models".into(),
            header: [
                "model",
                "held-out error",
                "with its gain calibrated",
                "mean of other photos",
                "training error",
                "bases (kind alpha share)",
                "exposure",
                "time (s)",
            ]
            .map(String::from)
            .to_vec(),
            rows: self
                .models
                .iter()
                .map(|r| {
                    let bases: Vec<String> = r
                        .maps_fit
                        .bases
                        .iter()
                        .map(|b| format!("{:?} {:.3} {:.0}%", b.kind, b.alpha, 100.0 * b.share))
                        .collect();
                    vec![
                        r.model.to_string(),
                        optional(r.holdout.as_ref().map(|h| h.relative_error)),
                        optional(r.holdout.as_ref().map(|h| h.calibrated_error)),
                        optional(r.holdout.as_ref().and_then(|h| h.mean_photo_error)),
                        format!("{:.4}", r.train_error),
                        bases.join("; ").to_lowercase(),
                        optional(r.exposure),
                        format!("{:.1}", r.seconds),
                    ]
                })
                .collect(),
            note: Some(
                "Errors are relative RMS over pixels and channels, sqrt(sum (fit - photo)^2 / sum photo^2); \
                 with its gain calibrated: after a gain per channel for the held-out photo's own exposure \
                 and white balance, fitted on its pixels (the material untouched); the mean of the other \
                 photos is the naive prediction of the held-out photo."
                    .into(),
            ),
        };
        let mut rows = Vec::new();
        for d in &self.differences {
            let d = &d.difference;
            let cells = |region: String,
                         share: f64,
                         alpha: [f64; 2],
                         s: [&crate::maps::compare::DeltaStats; 3],
                         changed: f64| {
                vec![
                    d.model.to_string(),
                    region,
                    format!("{:.0}%", 100.0 * share),
                    format!("{:.4}", alpha[1]),
                    format!("{:.4}", alpha[0]),
                    format!("{:+.4} [{:+.4}, {:+.4}]", s[0].mean, s[0].p05, s[0].p95),
                    format!("{:.0}%", 100.0 * changed),
                    format!("{:+.4}", s[1].mean),
                    format!("{:+.4}", s[2].mean),
                ]
            };
            for r in &d.regions {
                rows.push(cells(
                    format!("{:?} basis {}", r.kind, r.basis).to_lowercase(),
                    r.share,
                    [r.alpha_model, r.alpha_single],
                    [&r.alpha, &r.diffuse, &r.f0],
                    r.alpha_changed_fraction,
                ));
            }
            let mean_alpha = |m: &MapsModelRow| {
                m.maps_fit.maps.roughness.as_ref().map_or(f64::NAN, |a| {
                    a.iter().map(|[ax, ay]| (ax * ay).sqrt()).sum::<f64>() / a.len() as f64
                })
            };
            let alpha_of = |model: Model| {
                self.models
                    .iter()
                    .find(|m| m.model == model)
                    .map_or(f64::NAN, mean_alpha)
            };
            rows.push(cells(
                "all texels".into(),
                1.0,
                [alpha_of(d.model), alpha_of(d.minus)],
                [&d.alpha, &d.diffuse, &d.f0],
                d.alpha_changed_fraction,
            ));
        }
        let differences = Table {
            heading: "Multi-bounce minus single".into(),
            header: [
                "model",
                "where (bases of the model)",
                "texels",
                "alpha single",
                "alpha model",
                "delta alpha mean [5%, 95%]",
                "|delta alpha| > 0.02",
                "delta diffuse",
                "delta F0",
            ]
            .map(String::from)
            .to_vec(),
            rows,
            note: Some(
                "Per texel, the model's map minus single's (diffuse and F0: mean over RGB); regions are the basis materials of the model's fit."
                    .into(),
            ),
        };
        vec![models, differences]
    }

    fn figures(&self) -> Vec<(String, String)> {
        let rows: Vec<String> = self.maps_image.rows.iter().map(|m| m.to_string()).collect();
        let mut figures = vec![(
            format!(
                "Maps: rows {}; columns {}",
                rows.join(", "),
                self.maps_image.columns.join(", ")
            ),
            self.maps_image.path.clone(),
        )];
        figures.push((
            "Roughness colour bar".into(),
            self.maps_image.roughness_colour_bar.clone(),
        ));
        let u = &self.uncertainty_image;
        figures.push((
            format!(
                "Per-texel standard deviations (the fit's Gauss-Newton posterior): rows {}; columns {}",
                rows.join(", "),
                u.columns.join(", ")
            ),
            u.path.clone(),
        ));
        for (c, column) in u.columns.iter().enumerate() {
            let medians: Vec<String> = u
                .rows
                .iter()
                .zip(&u.medians[c])
                .map(|(m, v)| v.map_or(format!("{m} n/a"), |v| format!("{m} {v:.4}")))
                .collect();
            figures.push((
                format!(
                    "{column} sd colour bar (full colour at {:.4}; median per model: {})",
                    u.scales[c],
                    medians.join(", ")
                ),
                u.colour_bars[c].clone(),
            ));
        }
        for d in &self.differences {
            let (images, model) = (&d.images, d.difference.model);
            figures.push((
                format!(
                    "{model} minus single: alpha (red: rougher in {model}; full colour at +-{:.3})",
                    images.alpha_scale
                ),
                images.alpha.clone(),
            ));
            figures.push((
                format!("{model} minus single: alpha colour bar"),
                images.alpha_colour_bar.clone(),
            ));
            figures.push((
                format!(
                    "{model} minus single: diffuse albedo (full colour at +-{:.3})",
                    images.diffuse_scale
                ),
                images.diffuse.clone(),
            ));
            figures.push((
                format!("{model} minus single: diffuse colour bar"),
                images.diffuse_colour_bar.clone(),
            ));
        }
        figures
    }

    fn relit(&self) -> &Relit {
        &self.relit
    }

    fn image_grid(&self) -> Vec<(String, Vec<(String, String)>)> {
        let models: Vec<Model> = self.models.iter().map(|r| r.model).collect();
        photo_grid(&self.photos, &models)
    }
}
