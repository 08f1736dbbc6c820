//! The fitted materials under new light, in both comparison reports (docs/relight.md): every
//! model's fit relit on the sphere and on the flat sample under the bundled sky
//! ([`Environment::sky`]), beside the material its glTF export describes
//! ([`crate::export::gltf::described`]) on the same sphere under the same sky, and the
//! difference of the two; for a uniform fit also its lobe ([`crate::lobe`]).
//!
//! | file | content |
//! | --- | --- |
//! | `relit/<model>_sphere.png`, `_sample.png` | the fit relit ([`crate::relight`]), [`SIZE`] pixels wide, [`SAMPLES`] samples per pixel; one exposure for every relit image of the report, so models compare directly |
//! | `relit/<model>_gltf_sphere.png` | the glTF export's material, the same sphere, sky, exposure and random streams |
//! | `relit/<model>_gltf_difference.png` | per pixel `(export - fit) / fit` of the channel sums, on the diverging map of the residuals with full colour at +-[`DIFFERENCE_SCALE`] (blue: the export is darker) |
//! | `relit/<model>_lobe.png` | uniform fits: `f(wi, wo) wo.z` over the projected hemisphere of `wo`, light at [`LOBE_THETA_DEG`] from the normal toward +x, each lobe at its own exposure |
//! | `relit/difference_colour_bar.png` | the difference images' colour bar |
//!
//! The export and the fit are rendered with the same seed, so every pixel draws the same random
//! numbers in both and most of the Monte Carlo noise cancels in their difference (exactly where
//! the two lobes sample the same directions, as a multi-bounce model and `single` of the same
//! roughness do).

use super::images::diverging_colour;
use super::plots::colour_bar;
use crate::bsdf::Model;
use crate::capture::image_io::{display_exposure, write_png_rgb8, write_png_tonemapped};
use crate::error::{Error, Result};
use crate::lobe::{incidence, lobe_picture};
use crate::maps::MaterialMaps;
use crate::material::Material;
use crate::relight::environment::Environment;
use crate::relight::geometry::Geometry;
use crate::relight::{render_under, Frame, Scene};
use serde::Serialize;
use std::path::Path;

/// Width of the relit images in pixels: small, so that the report stays quick to write.
pub const SIZE: usize = 128;
/// Samples per pixel of the relit images.
pub const SAMPLES: usize = 16;
/// Relative difference at full colour in the difference images.
pub const DIFFERENCE_SCALE: f64 = 0.25;
/// Side of the lobe pictures in pixels.
const LOBE_SIZE: usize = 128;
/// Incidence of the lobe pictures, degrees from the normal (as `bouncefit lobe`'s default).
pub const LOBE_THETA_DEG: f64 = 45.0;
/// Evaluations per pixel of a stochastic model's lobe picture.
const LOBE_SAMPLES: usize = 8;
/// The folder of the relit images, relative to the report folder.
const FOLDER: &str = "relit";
/// The difference images' colour bar.
pub const DIFFERENCE_BAR: &str = "relit/difference_colour_bar.png";

/// One model's relit images and how far its glTF export is from it.
#[derive(Clone, Debug, Serialize)]
pub struct RelitRow {
    pub model: Model,
    pub sphere: String,
    pub sample: String,
    pub gltf_sphere: String,
    pub gltf_difference: String,
    /// Mean over the sphere's pixels of `(export - fit) / fit` (channel sums): the export's
    /// loss of brightness, negative when it is darker.
    pub gltf_mean_difference: f64,
    /// Mean of its magnitude.
    pub gltf_mean_abs_difference: f64,
    /// Uniform fits: the lobe picture.
    pub lobe: Option<String>,
}

/// The relit section of a report.
#[derive(Clone, Debug, Serialize)]
pub struct Relit {
    pub environment: &'static str,
    pub size: usize,
    pub samples: usize,
    /// The factor on radiance of every relit image.
    pub exposure: f64,
    pub difference_scale: f64,
    pub difference_colour_bar: String,
    pub rows: Vec<RelitRow>,
}

/// What one model's report row is made from: its fitted maps (a uniform fit as one texel),
/// the maps its glTF export describes, and for a uniform fit the material of the lobe.
pub struct RelitInput {
    pub model: Model,
    pub fitted: MaterialMaps,
    pub gltf: MaterialMaps,
    pub lobe: Option<Material>,
}

/// Renders `material` on `geometry` under `sky` at [`SIZE`] and [`SAMPLES`].
fn relit(material: &MaterialMaps, geometry: Geometry, sky: &Environment) -> Frame {
    let scene = Scene {
        material,
        geometry,
        size: SIZE,
        samples: SAMPLES,
        seed: 0,
    };
    render_under(&scene, sky)
}

/// Per pixel `(export - fit) / fit` of the channel sums; `None` where the fit is black.
fn relative_difference(fit: &Frame, export: &Frame) -> Vec<Option<f64>> {
    fit.rgb
        .iter()
        .zip(&export.rgb)
        .map(|(f, e)| {
            let (f, e): (f64, f64) = (f.iter().sum(), e.iter().sum());
            (f > 0.0).then(|| (e - f) / f)
        })
        .collect()
}

/// Writes linear `rgb` of `[width, height]` times `exposure` as an sRGB PNG at `relative`.
fn write_png(
    root: &Path,
    relative: &str,
    rgb: &[[f64; 3]],
    [width, height]: [usize; 2],
    exposure: f64,
) -> Result<()> {
    let rgb: Vec<[f32; 3]> = rgb.iter().map(|v| v.map(|c| c as f32)).collect();
    write_png_tonemapped(&root.join(relative), &rgb, width, height, exposure)
}

/// Renders and writes the relit images of every model of `inputs` under `root` (the report
/// folder); returns the report's section.
pub fn write_relit(root: &Path, inputs: &[RelitInput]) -> Result<Relit> {
    let folder = root.join(FOLDER);
    std::fs::create_dir_all(&folder).map_err(|e| Error::io(&folder, e))?;
    let sky = Environment::sky();
    let frames: Vec<[Frame; 3]> = inputs
        .iter()
        .map(|input| {
            [
                relit(&input.fitted, Geometry::Sphere, &sky),
                relit(&input.fitted, Geometry::Flat, &sky),
                relit(&input.gltf, Geometry::Sphere, &sky),
            ]
        })
        .collect();
    let all: Vec<[f64; 3]> = frames
        .iter()
        .flat_map(|[sphere, sample, _]| sphere.rgb.iter().chain(&sample.rgb).copied())
        .collect();
    let exposure = display_exposure(&all);
    let mut rows = Vec::new();
    for (input, [sphere, sample, gltf]) in inputs.iter().zip(&frames) {
        let model = input.model;
        let path = |what: &str| format!("{FOLDER}/{}_{what}.png", model.name());
        let difference = relative_difference(sphere, gltf);
        let seen: Vec<f64> = difference.iter().flatten().copied().collect();
        let mean = |f: fn(f64) -> f64| seen.iter().map(|&d| f(d)).sum::<f64>() / seen.len() as f64;
        let row = RelitRow {
            model,
            sphere: path("sphere"),
            sample: path("sample"),
            gltf_sphere: path("gltf_sphere"),
            gltf_difference: path("gltf_difference"),
            gltf_mean_difference: mean(|d| d),
            gltf_mean_abs_difference: mean(f64::abs),
            lobe: input.lobe.as_ref().map(|_| path("lobe")),
        };
        for (path, frame) in [
            (&row.sphere, sphere),
            (&row.sample, sample),
            (&row.gltf_sphere, gltf),
        ] {
            write_png(root, path, &frame.rgb, frame.resolution, exposure)?;
        }
        let bytes: Vec<u8> = difference
            .iter()
            .flat_map(|d| d.map_or([0; 3], |d| diverging_colour(d, DIFFERENCE_SCALE)))
            .collect();
        let side = SIZE as u32;
        write_png_rgb8(&root.join(&row.gltf_difference), &bytes, side, side)?;
        if let (Some(material), Some(lobe)) = (&input.lobe, &row.lobe) {
            let values = lobe_picture(
                material,
                incidence(LOBE_THETA_DEG),
                LOBE_SIZE,
                LOBE_SAMPLES,
                0,
            );
            let exposure = display_exposure(&values);
            write_png(root, lobe, &values, [LOBE_SIZE; 2], exposure)?;
        }
        rows.push(row);
    }
    colour_bar(
        &root.join(DIFFERENCE_BAR),
        "(glTF export - fit) / fit",
        |t| diverging_colour(2.0 * t - 1.0, 1.0),
        &[-1.0, -0.4, 0.0, 0.4, 1.0].map(|d| {
            (
                (d + 1.0) / 2.0,
                format!("{:+.0}%", 100.0 * DIFFERENCE_SCALE * d),
            )
        }),
    )?;
    Ok(Relit {
        environment:
            "the bundled sky (docs/relight.md): sun at elevation 35 and azimuth 30 degrees",
        size: SIZE,
        samples: SAMPLES,
        exposure,
        difference_scale: DIFFERENCE_SCALE,
        difference_colour_bar: DIFFERENCE_BAR.into(),
        rows,
    })
}

impl Relit {
    /// What the section shows, one paragraph.
    pub fn description(&self) -> String {
        format!(
            "Each fit under {}, on a sphere and on the flat sample seen from above ({} px, {} \
             samples per pixel, one exposure for all), beside the material its glTF export \
             describes (single-bounce GGX, Schlick F0, roughness capped at 1, no diffuse under a \
             metal) on the same sphere, and their relative difference (blue: the export is \
             darker). No viewer renders a multi-bounce model: the export is what Blender or \
             three.js show.",
            self.environment, self.size, self.samples
        )
    }

    /// Per model: its label and `(caption, relative path)` cells.
    pub fn grid(&self) -> Vec<(String, Vec<(String, String)>)> {
        self.rows
            .iter()
            .map(|row| {
                let mut cells = vec![
                    ("sphere".to_string(), row.sphere.clone()),
                    ("sample".to_string(), row.sample.clone()),
                    ("glTF export, sphere".to_string(), row.gltf_sphere.clone()),
                    (
                        format!(
                            "export - fit: mean {:+.1}%, |mean| {:.1}%",
                            100.0 * row.gltf_mean_difference,
                            100.0 * row.gltf_mean_abs_difference
                        ),
                        row.gltf_difference.clone(),
                    ),
                ];
                if let Some(lobe) = &row.lobe {
                    cells.push((format!("lobe, light at {LOBE_THETA_DEG} deg"), lobe.clone()));
                }
                (row.model.to_string(), cells)
            })
            .collect()
    }
}
