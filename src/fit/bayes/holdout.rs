//! K-fold cross-validation over the photos of a set: how well a model fitted to some photos
//! predicts the others.
//!
//! | step | behaviour |
//! | --- | --- |
//! | folds | photo `i` (capture order) is held out in fold `i mod K`; `2 <= K <= photos` |
//! | training | the model is refitted on the records with the held-out photos' weights set to 0 ([`ShadingRecords::restricted_to_photos`]), same options and seed |
//! | prediction | the fitted material is rendered on the held-out photos' pixels and scored with the fit's loss (its own normalisation over those pixels) |
//! | one photo (`fit --holdout-photo N`, uniform or maps) | the fit leaves photo N out; its prediction's relative RMS error ([`relative_error`]) beside that of the mean of the other photos ([`HeldOutPhoto`]) |
//!
//! A model with more freedom lowers the training loss but gains on held-out photos only if it
//! describes the material better, so held-out error is a ranking that needs no noise model
//! (Hastie, Tibshirani & Friedman, *Elements of Statistical Learning*, section 7.10).

use crate::error::{Error, Result};
use crate::fit::point::objective::render_seeds;
use crate::fit::point::{fit_point, FitOptions};
use crate::loss::{ImageLayout, Loss, LossKind};
use crate::material::Material;
use crate::render::render_pixels;
use crate::shading::{PhotoSpan, ShadingRecords};
use serde::Serialize;

/// The fold in which photo `photo` is held out.
pub fn fold_of(photo: usize, folds: usize) -> usize {
    photo % folds
}

/// Checks a fold count against the number of photos (`--holdout K`).
pub fn check_fold_count(folds: usize, photos: usize) -> Result<()> {
    if folds < 2 || folds > photos {
        return Err(Error::argument(
            "--holdout",
            format!("K must be between 2 and the number of photos ({photos}), got {folds}"),
        ));
    }
    Ok(())
}

/// Loss (of `kind`) of `material` on the weighted pixels of `records`, the pair loss of two
/// renders for a stochastic model (as in fits: one render would add its variance); `None`
/// when no pixel has weight.
pub fn loss_of(
    material: &Material,
    records: &ShadingRecords,
    kind: LossKind,
    seed: u64,
) -> Option<f64> {
    let pixels: Vec<usize> = (0..records.pixel_count())
        .filter(|&p| records.weight[p] > 0.0)
        .collect();
    if pixels.is_empty() {
        return None;
    }
    let target: Vec<[f64; 3]> = pixels.iter().map(|&p| records.target[p]).collect();
    let weight: Vec<f64> = pixels.iter().map(|&p| records.weight[p]).collect();
    let renders: Vec<Vec<[f64; 3]>> =
        render_seeds(material.model.capabilities().stochastic(), seed)
            .into_iter()
            .map(|seed| render_pixels(material, records, &pixels, seed))
            .collect();
    let layout = ImageLayout::new(records, &pixels);
    Some(Loss::new(kind, &target, &weight, &layout).renders_value(&renders))
}

/// Held-out loss of each of `folds` folds for the model of `options`.
pub fn cross_validate(
    records: &ShadingRecords,
    options: &FitOptions,
    folds: usize,
) -> Result<Vec<f64>> {
    check_fold_count(folds, records.photos.len())?;
    (0..folds)
        .map(|fold| {
            let training = records.restricted_to_photos(|i| fold_of(i, folds) != fold);
            let held_out = records.restricted_to_photos(|i| fold_of(i, folds) == fold);
            // Only the point estimate: the exposure's interval would not be used.
            let fit = fit_point(&training, options)?.fit;
            loss_of(
                &fit.material,
                &fit.exposed(&held_out),
                options.loss,
                options.seed,
            )
            .ok_or_else(|| {
                let stems: Vec<&str> = records
                    .photos
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| fold_of(*i, folds) == fold)
                    .map(|(_, p)| p.stem.as_str())
                    .collect();
                Error::argument(
                    "--holdout",
                    format!(
                        "fold {fold} holds out photos {} and none of their pixels enters the loss",
                        stems.join(", ")
                    ),
                )
            })
        })
        .collect()
}

/// Checks `--holdout-photo` against the number of photos.
pub fn check_held_out_photo(photo: Option<usize>, photos: usize) -> Result<()> {
    match photo {
        Some(h) if h >= photos => Err(Error::argument(
            "--holdout-photo",
            format!(
                "photo {h} does not exist; the set has photos 0 to {}",
                photos - 1
            ),
        )),
        _ => Ok(()),
    }
}

/// The prediction of a photo left out of a fit (`--holdout-photo`, uniform or maps): the fit
/// file's and the maps comparison's `holdout`.
#[derive(Clone, Debug, Serialize)]
pub struct HeldOutPhoto {
    pub photo: usize,
    pub stem: String,
    /// Relative RMS error of the fit's prediction of the photo ([`relative_error`]).
    pub relative_error: f64,
    /// The same after the photo's own exposure and white balance are calibrated on its pixels
    /// (a gain per channel, by least squares; the material untouched): what is left when the
    /// photo's unrecorded exposure is not counted against the material.
    pub calibrated_error: f64,
    /// That gain per channel (1 where the photo's exposure is as the set says).
    pub calibrated_gain: [f64; 3],
    /// The naive baseline: the relative error of predicting it by the mean of the other photos
    /// at each pixel (`None` when the photos differ in size).
    pub mean_photo_error: Option<f64>,
}

impl HeldOutPhoto {
    /// How well `predict` (the values of pixels of `records`, a fit's prediction) predicts
    /// photo `photo`, which the fit did not see, at its pixels that `records` weigh.
    pub fn measure(
        records: &ShadingRecords,
        photo: usize,
        predict: impl FnOnce(&[usize]) -> Vec<[f64; 3]>,
    ) -> HeldOutPhoto {
        let pixels: Vec<usize> = records.photos[photo]
            .pixels()
            .filter(|&p| records.weight[p] > 0.0)
            .collect();
        let predicted = predict(&pixels);
        let calibrated_gain = gain(&predicted, records, &pixels);
        let calibrated: Vec<[f64; 3]> = predicted
            .iter()
            .map(|v| std::array::from_fn(|c| v[c] * calibrated_gain[c]))
            .collect();
        HeldOutPhoto {
            photo,
            stem: records.photos[photo].stem.clone(),
            relative_error: relative_error(&predicted, records, &pixels),
            calibrated_error: relative_error(&calibrated, records, &pixels),
            calibrated_gain,
            mean_photo_error: mean_photo_error(records, photo),
        }
    }

    /// One line for the user.
    pub fn summary(&self) -> String {
        format!(
            "held-out photo {}: relative error {:.4}, {:.4} with its own gain calibrated ({}) \
             (mean of the other photos: {})",
            self.photo,
            self.relative_error,
            self.calibrated_error,
            self.calibrated_gain.map(|g| format!("{g:.3}")).join(", "),
            self.mean_photo_error
                .map_or("n/a".into(), |e| format!("{e:.4}"))
        )
    }
}

/// Per channel, the gain `g` that minimises `sum w (g p - t)^2` over `pixels`:
/// `sum w p t / sum w p^2` (1 where nothing is predicted).
pub fn gain(predicted: &[[f64; 3]], records: &ShadingRecords, pixels: &[usize]) -> [f64; 3] {
    std::array::from_fn(|c| {
        let (mut pt, mut pp) = (0.0, 0.0);
        for (value, &p) in predicted.iter().zip(pixels) {
            let w = records.weight[p];
            pt += w * value[c] * records.target[p][c];
            pp += w * value[c] * value[c];
        }
        if pp > 0.0 {
            pt / pp
        } else {
            1.0
        }
    })
}

/// `sqrt(sum w (p - t)^2 / sum w t^2)` over `pixels`.
pub fn relative_error(predicted: &[[f64; 3]], records: &ShadingRecords, pixels: &[usize]) -> f64 {
    let (mut error, mut signal) = (0.0, 0.0);
    for (value, &p) in predicted.iter().zip(pixels) {
        let w = records.weight[p];
        for (v, t) in value.iter().zip(records.target[p]) {
            error += w * (v - t).powi(2);
            signal += w * t * t;
        }
    }
    (error / signal.max(1e-300)).sqrt()
}

/// The naive baseline of a held-out photo: the relative error of predicting it by the mean of
/// the other photos at the same pixel (rectified photos of one size; `null` otherwise), over
/// the pixels usable in all of them.
fn mean_photo_error(records: &ShadingRecords, held_out: usize) -> Option<f64> {
    let span = &records.photos[held_out];
    let others: Vec<&PhotoSpan> = (0..records.photos.len())
        .filter(|&i| i != held_out)
        .map(|i| &records.photos[i])
        .collect();
    if others
        .iter()
        .any(|o| (o.width, o.height) != (span.width, span.height))
    {
        return None;
    }
    let (mut error, mut signal) = (0.0, 0.0);
    for i in 0..span.width * span.height {
        let p = span.first_pixel + i;
        if records.weight[p] == 0.0
            || others
                .iter()
                .any(|o| records.weight[o.first_pixel + i] == 0.0)
        {
            continue;
        }
        for c in 0..3 {
            let mean = others
                .iter()
                .map(|o| records.target[o.first_pixel + i][c])
                .sum::<f64>()
                / others.len() as f64;
            error += (mean - records.target[p][c]).powi(2);
            signal += records.target[p][c].powi(2);
        }
    }
    (signal > 0.0).then(|| (error / signal).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shading::PhotoSpan;

    /// Records of `photos` photos of 2x1 pixels, every pixel weighted.
    fn records(photos: usize) -> ShadingRecords {
        ShadingRecords {
            photos: (0..photos)
                .map(|i| PhotoSpan {
                    stem: format!("{i:02}"),
                    width: 2,
                    height: 1,
                    first_pixel: 2 * i,
                })
                .collect(),
            samples_per_pixel: 1,
            wi: vec![[0.0, 0.0, 1.0]; 2 * photos],
            wo: vec![[0.0, 0.0, 1.0]; 2 * photos],
            irradiance: vec![[1.0; 3]; 2 * photos],
            target: vec![[0.5; 3]; 2 * photos],
            weight: vec![1.0; 2 * photos],
            ..ShadingRecords::default()
        }
    }

    #[test]
    fn every_photo_is_held_out_exactly_once_and_folds_are_balanced() {
        for photos in 2..12 {
            for folds in 2..=photos {
                let mut held_out = vec![0; photos];
                let mut sizes = vec![0; folds];
                for (fold, size) in sizes.iter_mut().enumerate() {
                    for (photo, count) in held_out.iter_mut().enumerate() {
                        if fold_of(photo, folds) == fold {
                            *count += 1;
                            *size += 1;
                        }
                    }
                }
                assert!(held_out.iter().all(|&c| c == 1));
                let (min, max) = (sizes.iter().min().unwrap(), sizes.iter().max().unwrap());
                assert!(
                    max - min <= 1 && *min >= 1,
                    "{photos} photos, {folds} folds"
                );
            }
        }
    }

    #[test]
    fn fold_counts_outside_two_to_photos_are_errors() {
        assert!(check_fold_count(1, 9).is_err());
        assert!(check_fold_count(10, 9).is_err());
        assert!(check_fold_count(2, 9).is_ok() && check_fold_count(9, 9).is_ok());
    }

    #[test]
    fn restriction_zeroes_exactly_the_excluded_photos() {
        let all = records(5);
        let kept = all.restricted_to_photos(|i| fold_of(i, 3) != 1);
        for (i, photo) in all.photos.iter().enumerate() {
            let expected = if i % 3 == 1 { 0.0 } else { 1.0 };
            assert!(kept.weight[photo.pixels()].iter().all(|&w| w == expected));
        }
        // Everything but the weights is untouched.
        assert_eq!(kept.target, all.target);
        assert_eq!(kept.irradiance, all.irradiance);
    }

    #[test]
    fn held_out_loss_counts_only_the_held_out_pixels() {
        let mut all = records(3);
        // Photo 1 is much brighter: its pixels dominate the loss of any prediction.
        all.target[2] = [5.0; 3];
        all.target[3] = [5.0; 3];
        let material = Material {
            model: crate::bsdf::Model::Single,
            ndf: crate::microfacet::NdfKind::Ggx,
            height: crate::microfacet::Height::Correlated,
            alpha: [0.3; 2],
            fresnel: crate::material::FresnelSpec::White,
            diffuse: [0.0; 3],
        };
        let full = loss_of(&material, &all, LossKind::L2, 0).unwrap();
        let photo1 = loss_of(
            &material,
            &all.restricted_to_photos(|i| i == 1),
            LossKind::L2,
            0,
        )
        .unwrap();
        let others = loss_of(
            &material,
            &all.restricted_to_photos(|i| i != 1),
            LossKind::L2,
            0,
        )
        .unwrap();
        // The full loss is the pixel-weighted mean of the two parts (2 and 4 pixels).
        assert!((full - (2.0 * photo1 + 4.0 * others) / 6.0).abs() < 1e-12 * full);
        assert!(photo1 > 10.0 * others);
        assert!(loss_of(
            &material,
            &all.restricted_to_photos(|_| false),
            LossKind::L2,
            0
        )
        .is_none());
    }

    #[test]
    fn a_held_out_photos_own_gain_is_calibrated_and_the_material_error_remains() {
        let records = records(3);
        // A prediction whose only fault is the photo's exposure and white balance.
        let exposure_only = HeldOutPhoto::measure(&records, 1, |pixels| {
            pixels.iter().map(|_| [0.5 / 1.2, 0.5 / 0.9, 0.5]).collect()
        });
        let g = exposure_only.calibrated_gain;
        assert!((g[0] - 1.2).abs() < 1e-12 && (g[1] - 0.9).abs() < 1e-12 && g[2] == 1.0);
        assert!(exposure_only.relative_error > 0.1);
        assert!(exposure_only.calibrated_error < 1e-12);
        // A prediction wrong in shape keeps an error no gain removes: pixels at 0.4 and 0.6 for
        // 0.5 err by 0.2 uncalibrated, and by 0.1961 at the best gain 0.5 / 0.52.
        let shape = HeldOutPhoto::measure(&records, 1, |pixels| {
            pixels
                .iter()
                .map(|&p| [if p % 2 == 0 { 0.4 } else { 0.6 }; 3])
                .collect()
        });
        assert!((shape.calibrated_gain[0] - 0.5 / 0.52).abs() < 1e-12);
        assert!((shape.relative_error - 0.2).abs() < 1e-12, "{shape:?}");
        assert!((shape.calibrated_error - 0.1961).abs() < 1e-4, "{shape:?}");
    }
}
