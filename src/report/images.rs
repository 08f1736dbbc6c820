//! Per-photo images of a report: the photo, a model's fit of it, and the signed residual.
//!
//! | image | encoding |
//! | --- | --- |
//! | `_target.png`, `_fit.png` | linear radiance times one exposure shared by all photos and models (so target and fit compare directly), clamped, sRGB |
//! | `_residual.png` | `fit - target`, mean over RGB, on a diverging map: blue below the photo, light grey at zero, red above; full colour at +-`scale`, shared by all photos and models; pixels outside the loss are dark grey |
//!
//! The diverging map interpolates linearly between the end and middle colours of Moreland's
//! cool-warm map (Moreland 2009, "Diverging Color Maps for Scientific Visualization"); the
//! sequential map of magnitudes (roughness) is viridis (van der Walt & Smith 2015, matplotlib),
//! interpolated linearly between nine of its colours.

use crate::bsdf::Model;
use crate::capture::image_io::{write_png_rgb8, write_png_tonemapped};
use crate::error::{Error, Result};
use crate::shading::ShadingRecords;
use std::path::Path;

/// sRGB colour of the residual `-scale`.
const BELOW: [f64; 3] = [59.0, 76.0, 192.0];
/// sRGB colour of a zero residual.
const ZERO: [f64; 3] = [221.0, 221.0, 221.0];
/// sRGB colour of the residual `+scale`.
const ABOVE: [f64; 3] = [180.0, 4.0, 38.0];
/// sRGB colour of pixels that do not enter the loss.
const EXCLUDED: [u8; 3] = [40, 40, 40];
/// Share of residual magnitudes below the full-colour scale.
const RESIDUAL_QUANTILE: f64 = 0.99;

/// Signed residual of a pixel as the images show it: mean over channels of `fit - target`.
fn signed_residual(fit: [f64; 3], target: [f64; 3]) -> f64 {
    (0..3).map(|c| fit[c] - target[c]).sum::<f64>() / 3.0
}

/// sRGB colours of viridis at `t = 0, 1/8, ..., 1`.
const VIRIDIS: [[f64; 3]; 9] = [
    [68.0, 1.0, 84.0],
    [71.0, 45.0, 123.0],
    [59.0, 82.0, 139.0],
    [44.0, 114.0, 142.0],
    [33.0, 145.0, 140.0],
    [40.0, 174.0, 128.0],
    [94.0, 201.0, 98.0],
    [173.0, 220.0, 48.0],
    [253.0, 231.0, 37.0],
];

/// Colour of `t` in [0, 1] (clamped; NaN as 0) on the sequential map (module docs).
pub fn sequential_colour(t: f64) -> [u8; 3] {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let x = t * (VIRIDIS.len() - 1) as f64;
    let i = (x.floor() as usize).min(VIRIDIS.len() - 2);
    let s = x - i as f64;
    [0, 1, 2].map(|c| (VIRIDIS[i][c] + s * (VIRIDIS[i + 1][c] - VIRIDIS[i][c])).round() as u8)
}

/// Colour of residual `r` on the diverging map with full colour at `+-scale`.
pub fn diverging_colour(r: f64, scale: f64) -> [u8; 3] {
    let t = if r.is_finite() {
        (r / scale).clamp(-1.0, 1.0)
    } else {
        0.0
    };
    let end = if t < 0.0 { BELOW } else { ABOVE };
    let s = t.abs();
    [0, 1, 2].map(|c| (ZERO[c] + s * (end[c] - ZERO[c])).round() as u8)
}

/// The residual magnitude at [`RESIDUAL_QUANTILE`] over the loss pixels of all `predictions`
/// (one per model): the full-colour scale of every residual image. 1 when all residuals vanish.
pub fn residual_scale(records: &ShadingRecords, predictions: &[Vec<[f64; 3]>]) -> f64 {
    magnitude_scale(predictions.iter().flat_map(|predicted| {
        predicted
            .iter()
            .zip(&records.target)
            .zip(&records.weight)
            .filter(|(_, w)| **w > 0.0)
            .map(|((p, t), _)| signed_residual(*p, *t))
    }))
}

/// The magnitude at [`RESIDUAL_QUANTILE`] of the finite non-zero `values`: the full-colour
/// scale of a diverging image of them. 1 when all vanish.
pub fn magnitude_scale(values: impl Iterator<Item = f64>) -> f64 {
    let mut magnitudes: Vec<f64> = values
        .map(f64::abs)
        .filter(|r| r.is_finite() && *r > 0.0)
        .collect();
    if magnitudes.is_empty() {
        return 1.0;
    }
    let k = ((magnitudes.len() as f64 * RESIDUAL_QUANTILE) as usize).min(magnitudes.len() - 1);
    let (_, q, _) = magnitudes.select_nth_unstable_by(k, |a, b| a.total_cmp(b));
    *q
}

/// Write `<model>/<stem>_target.png`, `_fit.png` and `_residual.png` for every photo under
/// `root` (the report folder); `predicted` holds the model's radiance for every pixel.
pub fn write_model_images(
    root: &Path,
    model: Model,
    records: &ShadingRecords,
    predicted: &[[f64; 3]],
    exposure: f64,
    scale: f64,
) -> Result<()> {
    let as_f32 = |values: &[[f64; 3]]| -> Vec<[f32; 3]> {
        values.iter().map(|v| v.map(|c| c as f32)).collect()
    };
    for photo in &records.photos {
        let pixels = photo.pixels();
        let path = |kind: &str| root.join(super::photo_image(model, &photo.stem, kind));
        for (kind, values) in [
            ("target", &records.target[pixels.clone()]),
            ("fit", &predicted[pixels.clone()]),
        ] {
            write_png_tonemapped(
                &path(kind),
                &as_f32(values),
                photo.width,
                photo.height,
                exposure,
            )?;
        }
        let residual: Vec<u8> = pixels
            .flat_map(|p| {
                if records.weight[p] > 0.0 {
                    diverging_colour(signed_residual(predicted[p], records.target[p]), scale)
                } else {
                    EXCLUDED
                }
            })
            .collect();
        let residual_path = path("residual");
        let size = |n: usize| {
            u32::try_from(n).map_err(|_| Error::invalid(&residual_path, "pixels", "too large"))
        };
        write_png_rgb8(
            &residual_path,
            &residual,
            size(photo.width)?,
            size(photo.height)?,
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn diverging_map_is_grey_at_zero_and_saturates_at_the_scale() {
        assert_eq!(diverging_colour(0.0, 2.0), [221, 221, 221]);
        assert_eq!(diverging_colour(2.0, 2.0), [180, 4, 38]);
        assert_eq!(diverging_colour(50.0, 2.0), [180, 4, 38]);
        assert_eq!(diverging_colour(-2.0, 2.0), [59, 76, 192]);
        assert_eq!(diverging_colour(f64::NAN, 2.0), [221, 221, 221]);
        // Monotone toward red in the red channel minus the blue channel.
        let redness = |r: f64| {
            let c = diverging_colour(r, 1.0);
            i32::from(c[0]) - i32::from(c[2])
        };
        assert!(redness(-1.0) < redness(-0.5) && redness(-0.5) < redness(0.0));
        assert!(redness(0.0) < redness(0.5) && redness(0.5) < redness(1.0));
    }

    #[test]
    fn sequential_map_runs_from_dark_purple_to_yellow_and_brightens() {
        assert_eq!(sequential_colour(0.0), [68, 1, 84]);
        assert_eq!(sequential_colour(1.0), [253, 231, 37]);
        assert_eq!(sequential_colour(7.0), [253, 231, 37]);
        assert_eq!(sequential_colour(f64::NAN), [68, 1, 84]);
        assert_eq!(sequential_colour(0.5), [33, 145, 140]);
        let green = |t: f64| sequential_colour(t)[1];
        let steps: Vec<u8> = (0..=20).map(|k| green(k as f64 / 20.0)).collect();
        assert!(steps.windows(2).all(|w| w[0] < w[1]), "{steps:?}");
    }
}
