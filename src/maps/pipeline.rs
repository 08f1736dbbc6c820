//! The maps fit of a photo set, as `fit --maps`, `compare --maps` and `bench` run it, without the
//! command line: a [`MapsSet`] loads the records once (one centre sub-sample per pixel, so each
//! pixel sees exactly one texel) and checks the options; [`MapsSet::fit`] fits one model's maps
//! ([`super::fit::fit_maps`]) to every photo but the held-out one and predicts every photo;
//! [`MapsSet::fit_file_fields`] are what the maps fit file adds to the maps. Nothing here prints.

use super::fit::{fit_maps, MapsFit, MapsFitOptions, Normals, Uncertainty};
use super::render::render_maps;
use super::{MaterialMaps, TexelGrid};
use crate::bsdf::Model;
use crate::capture::Capture;
use crate::error::{Error, Result};
use crate::fit::bayes::holdout::{check_held_out_photo, gain, HeldOutPhoto};
use crate::fit::pipeline::{load_records, RegionSource};
use crate::fit::point::exposure::{exposed_records, photo_exposed_records};
use crate::fit::point::params::{FresnelFamily, ParamSpace};
use crate::fit::{fit_model, FitOptions};
use crate::loss::LossKind;
use crate::shading::ShadingRecords;
use serde_json::json;
use std::borrow::Cow;
use std::path::{Path, PathBuf};

/// Most refits of the maps under updated photo gains (`--photo-gains`).
const PHOTO_GAIN_ROUNDS: usize = 4;
/// A round whose gains moved by less than this (in `ln`) ends the refits.
const PHOTO_GAIN_SETTLED: f64 = 0.002;

/// Sub-samples per pixel of a maps fit: one, at the pixel's centre, so that each pixel sees
/// exactly one texel.
const PIXEL_SAMPLES: usize = 1;

/// How a photo set is fitted as material maps.
#[derive(Clone, Debug)]
pub struct MapsOptions {
    /// How a uniform fit of the photos runs, for a fitted exposure (`space.exposure`), and what
    /// the maps fits share with it: distribution, heights, anisotropy, known Fresnel, progress
    /// and seed. Each fit takes these with its own model in place of `space.model`.
    pub fit: FitOptions,
    /// The part of the sample to fit; all of it without.
    pub region: Option<RegionSource>,
    /// The texel grid (default: the first photo's width, the height in the sample's
    /// proportions).
    pub texels: Option<TexelGrid>,
    pub normals: Normals,
    /// Most basis materials tried.
    pub bases: usize,
    /// The photo (0-based, capture order) left out of the fit, whose prediction is reported.
    pub holdout_photo: Option<usize>,
    /// The most texels the bases are chosen on ([`MapsFitOptions::coarsest`]).
    pub coarsest: Option<usize>,
    /// Calibrate each training photo's own exposure and white balance (a gain per channel)
    /// with the maps ([`MapsSet::fit`]).
    pub photo_gains: bool,
}

impl MapsOptions {
    /// The uniform fit options of `model`.
    fn uniform(&self, model: Model) -> FitOptions {
        FitOptions {
            space: ParamSpace {
                model,
                ..self.fit.space
            },
            ..self.fit.clone()
        }
    }
}

/// A photo set prepared for maps fits, with what every model's fit of it shares (`fit --maps`
/// fits one model, `compare --maps` several, `bench` times them): the records, the texel grid
/// and the options.
pub struct MapsSet {
    pub capture_path: PathBuf,
    pub capture: Capture,
    /// Records before any fitted exposure.
    pub records: ShadingRecords,
    pub grid: TexelGrid,
    pub options: MapsOptions,
}

/// One model's maps fit of a [`MapsSet`].
pub struct MapsRun<'a> {
    pub model: Model,
    pub fit: MapsFit,
    /// The exposure fitted with `--fit-exposure`.
    pub exposure: Option<f64>,
    /// Each photo's own gain per channel with `--photo-gains` (1 for the held-out photo).
    pub photo_gains: Option<Vec<[f64; 3]>>,
    /// The set's records under that exposure (the set's own without one: at 1024^2 a copy of
    /// the records is a gigabyte).
    pub records: Cow<'a, ShadingRecords>,
    /// The maps' radiance at every pixel of every photo, the held-out one included.
    pub predicted: Vec<[f64; 3]>,
    pub holdout: Option<HeldOutPhoto>,
}

/// Each training photo's gain per channel against the maps' `predicted` radiance
/// ([`gain`], by least squares on its pixels), divided by the training photos' geometric mean
/// per channel: the set's exposure stays the scale of the albedos, and a photo's deviation from
/// it (auto-exposure, white balance) is its own. The held-out photo keeps 1: its gain is never
/// fitted with the material.
fn photo_gains_of(
    records: &ShadingRecords,
    predicted: &[[f64; 3]],
    holdout: Option<usize>,
) -> Vec<[f64; 3]> {
    let raw: Vec<Option<[f64; 3]>> = records
        .photos
        .iter()
        .enumerate()
        .map(|(i, photo)| {
            let pixels: Vec<usize> = photo
                .pixels()
                .filter(|&p| records.weight[p] > 0.0)
                .collect();
            let values: Vec<[f64; 3]> = pixels.iter().map(|&p| predicted[p]).collect();
            (Some(i) != holdout && !pixels.is_empty())
                .then(|| gain(&values, records, &pixels))
                .filter(|g| g.iter().all(|v| v.is_finite() && *v > 0.0))
        })
        .collect();
    let fitted: Vec<&[f64; 3]> = raw.iter().flatten().collect();
    let mean: [f64; 3] = std::array::from_fn(|c| {
        let logs: f64 = fitted.iter().map(|g| g[c].ln()).sum();
        (logs / fitted.len().max(1) as f64).exp()
    });
    raw.iter()
        .map(|g| g.map_or([1.0; 3], |g| std::array::from_fn(|c| g[c] / mean[c])))
        .collect()
}

/// Refuses the fit options that would change what maps are fitted but that a maps fit has no
/// use for: it fits Schlick F0 per texel (or the known Fresnel) by its own weighted squared
/// error ([`crate::maps::fit`]). Before, it ignored them without a word.
fn check_options(options: &FitOptions) -> Result<()> {
    if options.space.fresnel != FresnelFamily::Schlick && options.space.known_fresnel.is_none() {
        return Err(Error::argument(
            "--fresnel",
            "a maps fit takes Schlick F0 per texel; for maps of a known conductor give \
             --fresnel-known conductor:ETA:K",
        ));
    }
    if options.loss != LossKind::L2 {
        return Err(Error::argument(
            "--loss",
            "a maps fit minimises the weighted squared error (l2); the other losses are for \
             uniform fits",
        ));
    }
    Ok(())
}

impl MapsSet {
    /// Loads the records of `capture` (telling `warn` what [`load_records`] warns of) and
    /// checks the options against it (the held-out photo exists, enough photos remain to
    /// fit); nothing is fitted yet.
    pub fn new(
        capture_path: &Path,
        capture: Capture,
        options: MapsOptions,
        warn: &dyn Fn(&str),
    ) -> Result<MapsSet> {
        check_options(&options.fit)?;
        let grid = options.texels.unwrap_or_else(|| {
            let width = capture.photos[0].camera.resolution()[0];
            let height = (width as f64 * capture.sample.height / capture.sample.width).round();
            TexelGrid {
                width,
                height: (height as usize).max(1),
            }
        });
        let (records, _) = load_records(
            capture_path,
            &capture,
            PIXEL_SAMPLES,
            options.region.as_ref(),
            warn,
        )?;
        let photos = records.photos.len();
        check_held_out_photo(options.holdout_photo, photos)?;
        if photos < 2 + usize::from(options.holdout_photo.is_some()) {
            return Err(Error::invalid(
                capture_path,
                "photos",
                "a maps fit needs at least two photos to fit (and one more to hold out)",
            ));
        }
        Ok(MapsSet {
            capture_path: capture_path.to_path_buf(),
            capture,
            records,
            grid,
            options,
        })
    }

    /// Fits maps of `model` to the photos (all but the held-out one) and predicts every photo.
    pub fn fit(&self, model: Model) -> Result<MapsRun<'_>> {
        let options = &self.options;
        let uniform = options.uniform(model);
        // A fitted exposure comes from the uniform fit of the same photos (with the known
        // Fresnel): the maps' per-texel albedo would absorb it otherwise.
        let exposure = if uniform.space.exposure {
            uniform
                .space
                .check()
                .map_err(|m| Error::argument("--fit-exposure", m))?;
            let fit = fit_model(&self.records, &uniform)?;
            Some(fit.exposure.as_ref().map_or(1.0, |e| e.value))
        } else {
            None
        };
        let mut records = exposed_records(&self.records, exposure.unwrap_or(1.0));
        let photos = records.photos.len();
        let holdout = options.holdout_photo;
        let validation_photo = (0..photos).rev().find(|&i| Some(i) != holdout);
        let maps_options = MapsFitOptions {
            model,
            ndf: uniform.space.ndf,
            height: uniform.space.height,
            known_fresnel: uniform.space.known_fresnel,
            anisotropic: uniform.space.anisotropic,
            grid: self.grid,
            normals: options.normals,
            max_bases: options.bases,
            held_out_photo: holdout,
            validation_photo,
            coarsest: options.coarsest,
            progress: uniform.progress.clone(),
        };
        let mut fit = fit_maps(&records, &maps_options)?;
        let all: Vec<usize> = (0..records.pixel_count()).collect();
        let mut predicted = render_maps(&fit.maps, &records, &all, uniform.seed)?;
        let mut photo_gains = None;
        if options.photo_gains {
            // Maps and gains in turn: each refit's maps absorb less of the photos' exposures,
            // so the gains settle in a few rounds (on auto-exposed synthetic photos within 1%
            // after three).
            let unexposed = records.clone().into_owned();
            let mut gains = vec![[1.0; 3]; photos];
            for _ in 0..PHOTO_GAIN_ROUNDS {
                let step = photo_gains_of(&records, &predicted, holdout);
                gains = gains
                    .iter()
                    .zip(&step)
                    .map(|(g, s)| std::array::from_fn(|c| g[c] * s[c]))
                    .collect();
                records = Cow::Owned(photo_exposed_records(&unexposed, &gains));
                fit = fit_maps(&records, &maps_options)?;
                predicted = render_maps(&fit.maps, &records, &all, uniform.seed)?;
                let settled = step
                    .iter()
                    .flatten()
                    .all(|s| s.ln().abs() < PHOTO_GAIN_SETTLED);
                if settled {
                    break;
                }
            }
            photo_gains = Some(gains);
        }
        let holdout = holdout.map(|h| {
            HeldOutPhoto::measure(&records, h, |pixels| {
                pixels.iter().map(|&p| predicted[p]).collect()
            })
        });
        Ok(MapsRun {
            model,
            fit,
            exposure,
            photo_gains,
            records,
            predicted,
            holdout,
        })
    }

    /// Writes the images of `run`'s fit file `path` into `folder` (the maps folder beside it,
    /// [`MaterialMaps::folder_beside`], or where that is staged): the maps and their
    /// uncertainty. Returns the fit file's `maps` object and its other fields
    /// ([`MapsSet::fit_file_fields`] and `uncertainty`), naming the images as the fit file sees
    /// them.
    pub fn write_fit_images(
        &self,
        run: &MapsRun,
        path: &Path,
        folder: &Path,
    ) -> Result<(
        serde_json::Value,
        serde_json::Map<String, serde_json::Value>,
    )> {
        let fields = self.fit_file_fields(run);
        write_fit_images(&run.fit.maps, &run.fit.uncertainty, path, folder, fields)
    }

    /// The fields a maps fit file adds to the material (`maps_fit`, `texels`, `holdout`,
    /// `exposure`, the capture's).
    pub fn fit_file_fields(&self, run: &MapsRun) -> serde_json::Map<String, serde_json::Value> {
        let grid = self.grid;
        let mut extra = serde_json::Map::new();
        extra.insert(
            "maps_fit".into(),
            serde_json::to_value(&run.fit).expect("serialisable"),
        );
        extra.insert("texels".into(), json!([grid.width, grid.height]));
        if let Some(report) = &run.holdout {
            extra.insert(
                "holdout".into(),
                serde_json::to_value(report).expect("serialisable"),
            );
        }
        if let Some(exposure) = run.exposure {
            extra.insert("exposure".into(), json!({"value": exposure}));
        }
        if let Some(gains) = &run.photo_gains {
            let photos: Vec<_> = run
                .records
                .photos
                .iter()
                .zip(gains)
                .map(|(photo, gain)| json!({"stem": photo.stem, "gain": gain}))
                .collect();
            extra.insert("photo_gains".into(), json!(photos));
        }
        extra.insert(
            "capture".into(),
            json!(self.capture_path.display().to_string()),
        );
        extra.insert("capture_name".into(), json!(self.capture.name));
        extra.insert("pixel_samples".into(), json!(PIXEL_SAMPLES));
        extra.insert(
            "excluded".into(),
            serde_json::to_value(run.records.excluded).expect("serialisable"),
        );
        extra.insert("seed".into(), json!(self.options.fit.seed));
        extra.insert("version".into(), json!(env!("CARGO_PKG_VERSION")));
        extra
    }
}

/// Writes `maps` and their `uncertainty` into `folder` under the names the fit file `path`
/// gives them ([`MaterialMaps::folder_beside`]): the fit file's `maps` object, and `fields` with
/// `uncertainty` added.
pub fn write_fit_images(
    maps: &MaterialMaps,
    uncertainty: &Uncertainty,
    path: &Path,
    folder: &Path,
    mut fields: serde_json::Map<String, serde_json::Value>,
) -> Result<(
    serde_json::Value,
    serde_json::Map<String, serde_json::Value>,
)> {
    let beside = MaterialMaps::folder_beside(path);
    let prefix = beside.file_name().unwrap_or_default().to_string_lossy();
    let entry = maps.write_images(folder, &prefix)?;
    fields.insert(
        "uncertainty".into(),
        uncertainty.write_images(folder, &prefix)?,
    );
    Ok((entry, fields))
}
