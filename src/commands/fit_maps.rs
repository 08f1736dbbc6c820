//! `bouncefit fit DIR --maps`: fit material maps ([`crate::maps::fit`]) and write a maps fit
//! file (`FIT.json` naming `FIT.maps/diffuse.png`, `specular.png`, `roughness.exr`,
//! `normal.png`) plus residual images, every output staged and committed at the end. Pixels are
//! evaluated at their centre (one sub-sample), so each sees exactly one texel.

use super::fit_args::{FitArgs, FitOptionArgs, MapsArgs};
use super::images::{display_exposure, write_photo_images};
use super::inputs::print_warning;
use super::output::StagedFolder;
use crate::bsdf::Model;
use crate::capture::Capture;
use crate::error::{Error, Result};
use crate::fit::fit_model;
use crate::fit::pipeline::load_records;
use crate::fit::point::exposure::exposed_records;
use crate::fit::point::params::FresnelFamily;
use crate::loss::LossKind;
use crate::maps::fit::{fit_maps, relative_error, HeldOutPhoto, MapsFit, MapsFitOptions};
use crate::maps::render::render_maps;
use crate::maps::{MaterialMaps, TexelGrid};
use crate::shading::{PhotoSpan, ShadingRecords};
use serde_json::json;
use std::path::{Path, PathBuf};

pub fn run_maps_fit(args: &FitArgs) -> Result<()> {
    let [model] = args.models.as_slice() else {
        return Err(Error::argument(
            "--models",
            "a maps fit takes one model (compare maps of several with `compare --maps`)",
        ));
    };
    if args.mcmc.mcmc {
        return Err(Error::argument(
            "--mcmc",
            "a maps fit reports maximum a posteriori maps; the posterior sampler is for uniform \
             fits (drop --maps, or --mcmc)",
        ));
    }
    let capture = args.options.real.open(&args.capture)?;
    let output = args.output_path(&capture)?;
    let maps_folder = StagedFolder::new(&MaterialMaps::folder_beside(&output), args.force)?;
    let residual_folder = StagedFolder::new(&output.with_extension("residuals"), args.force)?;
    let set = MapsSet::new(&args.capture, capture, &args.options, &args.map_options)?;
    let run = set.fit(*model, !args.quiet)?;
    if !args.quiet {
        summarise(&run.fit, run.holdout.as_ref());
    }
    let residual = run.records.residuals(&run.predicted);
    let display = display_exposure(&run.records.target);
    write_photo_images(
        &residual_folder.path(""),
        &run.records,
        &residual,
        display,
        "",
    )?;
    let folder_name = MaterialMaps::folder_beside(&output);
    let prefix = folder_name
        .file_name()
        .unwrap_or_default()
        .to_string_lossy();
    let maps_entry = run.fit.maps.write_images(&maps_folder.path(""), &prefix)?;
    maps_folder.commit()?;
    residual_folder.commit()?;
    run.fit
        .maps
        .save_json(&output, maps_entry, set.fit_file_fields(&run))?;
    println!("{}", output.display());
    Ok(())
}

/// A photo set prepared for maps fits, with what every model's fit of it shares (`fit --maps`
/// fits one model, `compare --maps` several, `bench` times them): the records (one centre
/// sub-sample per pixel), the texel grid and the options.
pub struct MapsSet {
    pub capture_path: PathBuf,
    pub capture: Capture,
    /// Records before any fitted exposure.
    pub records: ShadingRecords,
    pub grid: TexelGrid,
    /// The fit options, with one sub-sample per pixel.
    pub options: FitOptionArgs,
    pub maps: MapsArgs,
}

/// One model's maps fit of a [`MapsSet`].
pub struct MapsRun {
    pub model: Model,
    pub fit: MapsFit,
    /// The exposure fitted with `--fit-exposure`.
    pub exposure: Option<f64>,
    /// The set's records under that exposure.
    pub records: ShadingRecords,
    /// The maps' radiance at every pixel of every photo, the held-out one included.
    pub predicted: Vec<[f64; 3]>,
    pub holdout: Option<HeldOutPhoto>,
}

/// Refuses the fit options that would change what maps are fitted but that a maps fit has no
/// use for: it fits Schlick F0 per texel (or the known Fresnel) by its own weighted squared
/// error ([`crate::maps::fit`]). Before, it ignored them without a word.
fn check_options(options: &FitOptionArgs) -> Result<()> {
    if options.fresnel != FresnelFamily::Schlick && options.real.fresnel_known.is_none() {
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
    /// Loads the records of `capture` and checks the maps options against it (the held-out
    /// photo exists, enough photos remain to fit); nothing is fitted yet.
    pub fn new(
        capture_path: &Path,
        capture: Capture,
        options: &FitOptionArgs,
        maps: &MapsArgs,
    ) -> Result<MapsSet> {
        check_options(options)?;
        // One sub-sample per pixel, its centre: each pixel then sees exactly one texel.
        let options = FitOptionArgs {
            pixel_samples: 1,
            ..options.clone()
        };
        let grid = maps.texels.unwrap_or_else(|| {
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
            options.pixel_samples,
            options.real.region().as_ref(),
            &print_warning,
        )?;
        let photos = records.photos.len();
        if let Some(h) = maps.holdout_photo.filter(|&h| h >= photos) {
            return Err(Error::argument(
                "--holdout-photo",
                format!(
                    "photo {h} does not exist; the set has photos 0 to {}",
                    photos - 1
                ),
            ));
        }
        if photos < 2 + usize::from(maps.holdout_photo.is_some()) {
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
            maps: maps.clone(),
        })
    }

    /// Fits maps of `model` to the photos (all but the held-out one) and predicts every photo.
    pub fn fit(&self, model: Model, progress: bool) -> Result<MapsRun> {
        let options = &self.options;
        // A fitted exposure comes from the uniform fit of the same photos (with the known
        // Fresnel): the maps' per-texel albedo would absorb it otherwise.
        let exposure = if options.real.fit_exposure {
            options
                .space(model)
                .check()
                .map_err(|m| Error::argument("--fit-exposure", m))?;
            let uniform = fit_model(&self.records, &options.fit_options(model, progress))?;
            Some(uniform.exposure.as_ref().map_or(1.0, |e| e.value))
        } else {
            None
        };
        let records = exposed_records(&self.records, exposure.unwrap_or(1.0)).into_owned();
        let photos = records.photos.len();
        let holdout = self.maps.holdout_photo;
        let training = match holdout {
            Some(h) => records.restricted_to_photos(|i| i != h),
            None => records.clone(),
        };
        let validation_photo = (0..photos).rev().find(|&i| Some(i) != holdout);
        let fit = fit_maps(
            &training,
            &MapsFitOptions {
                model,
                ndf: options.ndf,
                height: options.height,
                known_fresnel: options.real.fresnel_known,
                anisotropic: options.anisotropic,
                grid: self.grid,
                normals: self.maps.normals,
                max_bases: self.maps.bases,
                validation_photo,
                progress,
            },
        )?;
        let all: Vec<usize> = (0..records.pixel_count()).collect();
        let predicted = render_maps(&fit.maps, &records, &all, options.seed)?;
        let holdout = holdout.map(|h| {
            let pixels: Vec<usize> = records.photos[h]
                .pixels()
                .filter(|&p| records.weight[p] > 0.0)
                .collect();
            let values: Vec<[f64; 3]> = pixels.iter().map(|&p| predicted[p]).collect();
            HeldOutPhoto {
                photo: h,
                stem: records.photos[h].stem.clone(),
                relative_error: relative_error(&values, &records, &pixels),
                mean_photo_error: mean_photo_error(&records, h),
            }
        });
        Ok(MapsRun {
            model,
            fit,
            exposure,
            records,
            predicted,
            holdout,
        })
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
        extra.insert(
            "capture".into(),
            json!(self.capture_path.display().to_string()),
        );
        extra.insert("capture_name".into(), json!(self.capture.name));
        extra.insert("pixel_samples".into(), json!(self.options.pixel_samples));
        extra.insert(
            "excluded".into(),
            serde_json::to_value(run.records.excluded).expect("serialisable"),
        );
        extra.insert("seed".into(), json!(self.options.seed));
        extra.insert("version".into(), json!(env!("CARGO_PKG_VERSION")));
        extra
    }
}

/// The naive baseline of a held-out photo: the relative error of predicting it by the mean of
/// the other photos at the same pixel (rectified photos of one size; `null` otherwise), over
/// the pixels usable in all of them.
pub fn mean_photo_error(records: &ShadingRecords, held_out: usize) -> Option<f64> {
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

/// One line per stage for stderr.
fn summarise(fit: &MapsFit, holdout: Option<&HeldOutPhoto>) {
    for trial in &fit.basis_trials {
        eprintln!(
            "{} bases: validation photo relative error {:.4} (roughness floor {}; {:.4} without)",
            trial.bases,
            trial.validation_error,
            trial
                .roughness_floor
                .map_or("none".into(), |f| format!("{f}")),
            trial.unfloored_validation_error
        );
    }
    let bases: Vec<String> = fit
        .bases
        .iter()
        .map(|b| format!("alpha {:.3} ({:.0}%)", b.alpha, 100.0 * b.share))
        .collect();
    eprintln!(
        "maps {}: {} bases [{}], training relative error {:.4}, {:.1} s",
        fit.texels_seen,
        fit.bases.len(),
        bases.join(", "),
        fit.train_error,
        fit.seconds
    );
    if let Some(h) = holdout {
        eprintln!(
            "held-out photo {}: relative error {:.4} (mean of the other photos: {})",
            h.photo,
            h.relative_error,
            h.mean_photo_error
                .map_or("n/a".into(), |e| format!("{e:.4}"))
        );
    }
}
