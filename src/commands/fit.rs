//! `bouncefit fit DIR`: fit one or more models to a photo set and write the fit file plus a
//! residual image per photo. The arguments are in [`super::fit_args`]; `compare` shares
//! [`fit_and_sample`] too.

use super::fit_args::{FitArgs, FitOptionArgs, McmcArgs};
use super::images::{display_exposure, write_photo_images};
use super::output::StagedFolder;
use crate::bsdf::Model;
use crate::capture::Capture;
use crate::error::{Error, Result};
use crate::fit::bayes::mcmc::{sample_posterior, PosteriorRun};
use crate::fit::bayes::posterior::Posterior;
use crate::fit::bayes::selection::{GaussianFit, Selection};
use crate::fit::point::params::ParamSpace;
use crate::fit::point::uniformity::{self, Uniformity};
use crate::fit::point::{measure, Measured};
use crate::fit::{edge_tint, fit_model, ModelFit};
use crate::shading::region::{AppliedRegion, SampleRegion};
use crate::shading::{ExclusionCounts, ShadingRecords};
use serde::Serialize;
use std::path::{Path, PathBuf};

fn is_zero(value: &f64) -> bool {
    *value == 0.0
}

/// The `region` entry of a fit file: which part of the sample was fitted and how uniform it
/// looks under the fit ([`crate::fit::point::uniformity`]).
#[derive(Serialize)]
pub struct RegionReport {
    #[serde(skip_serializing_if = "Option::is_none")]
    rectangle: Option<[f64; 4]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    mask: Option<String>,
    /// Loss pixels left out because they see the sample outside the region.
    pixels_excluded: usize,
    uniformity: Option<Uniformity>,
}

impl RegionReport {
    /// The report of `applied` for a fit that predicts `predicted` for every pixel.
    pub fn new(
        applied: &AppliedRegion,
        records: &ShadingRecords,
        predicted: &[[f64; 3]],
    ) -> RegionReport {
        let (rectangle, mask) = match &applied.region {
            SampleRegion::Rectangle(r) => (Some(*r), None),
            SampleRegion::Mask { path, .. } => (None, Some(path.display().to_string())),
        };
        RegionReport {
            rectangle,
            mask,
            pixels_excluded: applied.excluded,
            uniformity: uniformity::measure(records, predicted, applied),
        }
    }

    /// One line for stderr.
    pub fn summary(&self) -> String {
        match &self.uniformity {
            Some(u) => format!(
                "region: block ratio photo/fit spread {:.3} over {} blocks (range {:.3}..{:.3}): {}",
                u.ratio_spread,
                u.blocks,
                u.ratio_range[0],
                u.ratio_range[1],
                if u.uniform { "looks uniform" } else { "not uniform" }
            ),
            None => "region: too few pixels per block to judge uniformity".into(),
        }
    }
}

/// The photo set's shading records with targets, restricted to `--region` or `--mask` (then
/// also returned), refusing a set with no usable pixel (all excluded, the counts by reason in
/// the message) or whose usable pixels are all black, which no material with positive
/// reflectance can fit.
pub fn load_records(
    capture_path: &Path,
    capture: &Capture,
    options: &FitOptionArgs,
) -> Result<(ShadingRecords, Option<AppliedRegion>)> {
    let mut records = ShadingRecords::build(capture, options.pixel_samples, true)?;
    let region = match options.real.region()? {
        Some(region) if records.weight.iter().any(|w| *w > 0.0) => {
            Some(region.apply(capture, &mut records)?)
        }
        _ => None,
    };
    let usable = || {
        records
            .target
            .iter()
            .zip(&records.weight)
            .filter(|(_, w)| **w > 0.0)
    };
    if usable().next().is_none() {
        let e = records.excluded;
        return Err(Error::invalid(
            capture_path,
            "photos",
            format!(
                "every pixel is excluded ({} outside the sample, {} masked, {} saturated, \
                 {} non-finite, {} negative); expected photos with usable pixels: check the \
                 cameras, the masks, and retake saturated photos at a lower exposure",
                e.outside_sample, e.masked, e.saturated, e.non_finite, e.negative
            ),
        ));
    }
    if usable().all(|(t, _)| t.iter().all(|c| *c == 0.0)) {
        return Err(Error::invalid(
            capture_path,
            "photos",
            "every usable pixel is black (0 in every channel); expected photos of the lit \
             sample: check the images, their exposure and the lights",
        ));
    }
    let e = records.excluded;
    if e.non_finite + e.negative > 0 {
        eprintln!(
            "warning: {}: photos: {} non-finite and {} negative pixels excluded from the fit",
            capture_path.display(),
            e.non_finite,
            e.negative
        );
    }
    Ok((records, region))
}

/// What [`fit_and_sample`] produced: a fit per model and, with `--mcmc`, the posterior run.
pub struct Fits {
    pub fits: Vec<ModelFit>,
    pub posterior: Option<PosteriorRun>,
    /// The sampler's checkpoint file (`--checkpoint`, or next to the output).
    checkpoint: PathBuf,
}

impl Fits {
    /// Removes the sampler's checkpoint once the outputs it led to are written.
    pub fn remove_checkpoint(&self) -> Result<()> {
        if self.posterior.is_some() && self.checkpoint.exists() {
            std::fs::remove_file(&self.checkpoint).map_err(|e| Error::io(&self.checkpoint, e))?;
        }
        Ok(())
    }
}

/// Fits every model of `models` to `records` and, with `--mcmc`, samples the posterior over
/// them first (its MAP fits are reused when the likelihood saw every pixel). The sampler's
/// checkpoint defaults to `output` with extension `.mcmc-checkpoint.json`. `None` when the
/// sampler stopped early and left its checkpoint (hidden `--mcmc-stop-after`). A checkpoint
/// left by an earlier run is continued only with `--resume` and replaced only with `force`.
pub fn fit_and_sample(
    records: &ShadingRecords,
    models: &[Model],
    options: &FitOptionArgs,
    mcmc: &McmcArgs,
    output: &Path,
    quiet: bool,
    force: bool,
) -> Result<Option<Fits>> {
    if models.is_empty() {
        return Err(Error::argument("--models", "no model given"));
    }
    options
        .space(models[0])
        .check()
        .map_err(|m| Error::argument("--fit-exposure", m))?;
    let checkpoint = mcmc
        .checkpoint
        .clone()
        .unwrap_or_else(|| output.with_extension("mcmc-checkpoint.json"));
    if mcmc.mcmc && !mcmc.resume && !force && checkpoint.exists() {
        return Err(Error::invalid(
            &checkpoint,
            "checkpoint",
            "an interrupted sampler run left this file; pass --resume to continue it or --force to start over",
        ));
    }
    let fit_and_print = |model: Model| -> Result<ModelFit> {
        let fit = fit_model(records, &options.fit_options(model, !quiet))?;
        if !quiet {
            // A corrected stochastic fit also says how far its walks' noise leaves alpha.
            let noise = fit
                .correction
                .as_ref()
                .and_then(|c| c.alpha_noise)
                .map_or(String::new(), |n| {
                    format!(" (walks' noise {:.2}%)", 100.0 * n[0].max(n[1]))
                });
            eprintln!("{}: loss {:.6e}, alpha {:.5} {:.5}{}, F0 {:.4} {:.4} {:.4}, {} evaluations, {:.2} s ({})", model, fit.loss, fit.material.alpha[0], fit.material.alpha[1], noise, fit.f0[0], fit.f0[1], fit.f0[2], fit.evaluations, fit.seconds, fit.termination);
        }
        Ok(fit)
    };
    // On a subset of the pixels the chains' MAP fits may miss a basin that the fits on every
    // pixel find, so those come first and hand the sampler their other basins as modes.
    let loss_pixels = records.weight.iter().filter(|w| **w > 0.0).count();
    let subset = mcmc.mcmc_pixels != 0 && mcmc.mcmc_pixels < loss_pixels;
    let mut fits = if mcmc.mcmc && subset && !mcmc.resume {
        models
            .iter()
            .map(|&model| fit_and_print(model))
            .collect::<Result<Vec<_>>>()?
    } else {
        Vec::new()
    };
    let posterior = if mcmc.mcmc {
        let spaces: Vec<ParamSpace> = models.iter().map(|&m| options.space(m)).collect();
        let mut mcmc_options = options.mcmc_options(mcmc, models, checkpoint.clone());
        mcmc_options.map.progress = !quiet;
        mcmc_options.mode_starts = fits
            .iter()
            .map(|fit| fit.alternatives.iter().map(|a| a.point.clone()).collect())
            .collect();
        match sample_posterior(records, &spaces, &mcmc_options)? {
            Some(run) => Some(run),
            None => {
                eprintln!(
                    "stopped; the sampler state is in {} (continue with --resume)",
                    checkpoint.display()
                );
                return Ok(None);
            }
        }
    } else {
        None
    };
    if fits.is_empty() {
        if let Some(run) = posterior.as_ref().filter(|run| run.all_pixels) {
            fits = run.maps.clone();
        }
    }
    for &model in models.iter().skip(fits.len()) {
        fits.push(fit_and_print(model)?);
    }
    if let Some(run) = &posterior {
        for fit in &mut fits {
            let model = fit.material.model.name();
            let modes: Vec<_> = run
                .posterior
                .modes
                .iter()
                .filter(|m| m.model.split('+').next() == Some(model))
                .collect();
            if modes.len() > 1 {
                // The chains jumped between the basins: say how the draws split.
                let shares: Vec<String> = modes
                    .iter()
                    .map(|m| {
                        format!(
                            "alpha {:.4} (probability {:.3}, Laplace {:.3})",
                            m.alpha[0], m.probability, m.laplace_probability
                        )
                    })
                    .collect();
                fit.warnings.push(format!(
                    "--mcmc: the posterior has {} modes, {}; the intervals pool them",
                    modes.len(),
                    shares.join(", ")
                ));
            } else if let Some(other) = fit.alternatives.first() {
                // The chains explore the MAP's basin only: say so where another basin is as good.
                fit.warnings.push(format!(
                    "--mcmc: the chains start in the basin of alpha {:.4} and the intervals \
                     describe that basin only; the posterior has another mode near alpha {:.4} \
                     (loss x{:.4})",
                    fit.material.alpha[0], other.alpha[0], other.loss_ratio
                ));
            }
        }
    }
    Ok(Some(Fits {
        fits,
        posterior,
        checkpoint,
    }))
}

/// Each fit measured by the objective it was fitted on ([`measure`]), in the order of `fits`.
pub fn measure_fits(
    records: &ShadingRecords,
    fits: &[ModelFit],
    options: &FitOptionArgs,
) -> Vec<Measured> {
    fits.iter()
        .map(|fit| {
            measure(
                records,
                fit,
                &options.fit_options(fit.material.model, false),
            )
        })
        .collect()
}

/// The BIC ranking of `fits`, from their residuals as `measured` ([`measure_fits`]): the same
/// seed as the fit, so a stochastic model sees the random numbers it was fitted with, and
/// its pair residual.
pub fn select(
    records: &ShadingRecords,
    fits: &[ModelFit],
    measured: &[Measured],
    options: &FitOptionArgs,
) -> Selection {
    let observations = 3 * records.weight.iter().filter(|w| **w > 0.0).count();
    let gaussian: Vec<GaussianFit> = fits
        .iter()
        .zip(measured)
        .map(|(fit, measured)| GaussianFit {
            model: fit.material.model,
            mean_squared_residual: measured.l2,
            observations,
            parameters: options.space(fit.material.model).dim(),
        })
        .collect();
    Selection::rank(&gaussian)
}

/// One line of the candidates table of a multi-model fit.
#[derive(Serialize)]
struct Candidate {
    model: Model,
    loss: f64,
    alpha: [f64; 2],
    f0: [f64; 3],
    seconds: f64,
}

/// The fit file: the chosen model's material and fit record, and what produced it.
#[derive(Serialize)]
pub struct FitFile<'a> {
    #[serde(flatten)]
    fit: &'a ModelFit,
    #[serde(skip_serializing_if = "Option::is_none")]
    edge_tint: Option<[f64; 3]>,
    capture: String,
    capture_name: &'a str,
    /// `--depth` or the manifest's `[sample] depth`, when not 0.
    #[serde(skip_serializing_if = "is_zero")]
    depth: f64,
    pixel_samples: usize,
    pixels_used: usize,
    excluded: ExclusionCounts,
    seed: u64,
    version: &'static str,
    candidates: Vec<Candidate>,
    selection: &'a Selection,
    #[serde(skip_serializing_if = "Option::is_none")]
    posterior: Option<&'a Posterior>,
    #[serde(skip_serializing_if = "Option::is_none")]
    region: Option<RegionReport>,
}

impl<'a> FitFile<'a> {
    /// The fit file of `fit`, one of `fits`, all fitted to `records` of `capture`.
    pub fn new(
        fit: &'a ModelFit,
        fits: &[ModelFit],
        selection: &'a Selection,
        posterior: Option<&'a Posterior>,
        capture: (&Path, &'a Capture),
        records: &ShadingRecords,
        options: &FitOptionArgs,
    ) -> FitFile<'a> {
        FitFile {
            fit,
            edge_tint: edge_tint(&fit.material),
            capture: capture.0.display().to_string(),
            capture_name: &capture.1.name,
            depth: capture.1.depth,
            pixel_samples: options.pixel_samples,
            pixels_used: records.weight.iter().filter(|w| **w > 0.0).count(),
            excluded: records.excluded,
            seed: options.seed,
            version: env!("CARGO_PKG_VERSION"),
            candidates: fits
                .iter()
                .map(|f| Candidate {
                    model: f.material.model,
                    loss: f.loss,
                    alpha: f.material.alpha,
                    f0: f.f0,
                    seconds: f.seconds,
                })
                .collect(),
            selection,
            posterior,
            region: None,
        }
    }

    /// The same file with a `region` entry.
    pub fn with_region(mut self, region: Option<RegionReport>) -> Self {
        self.region = region;
        self
    }

    /// Write the file as pretty JSON, atomically.
    pub fn write(&self, path: &Path) -> Result<()> {
        crate::capture::atomic_file::write_atomically(path, |w| {
            serde_json::to_writer_pretty(&mut *w, self).map_err(|e| Error::io(path, e))
        })
    }
}

/// Prediction minus photo at every loss pixel, 0 elsewhere: what the residual images show.
pub fn residuals(predicted: &[[f64; 3]], records: &ShadingRecords) -> Vec<[f64; 3]> {
    predicted
        .iter()
        .zip(&records.target)
        .zip(&records.weight)
        .map(|((p, t), w)| {
            if *w > 0.0 {
                [0, 1, 2].map(|c| p[c] - t[c])
            } else {
                [0.0; 3]
            }
        })
        .collect()
}

pub fn run_fit(args: &FitArgs) -> Result<()> {
    if args.map_options.maps {
        return super::fit_maps::run_maps_fit(args);
    }
    let capture = args.options.real.open(&args.capture)?;
    let output = args.output_path(&capture)?;
    let residual_folder = StagedFolder::new(&output.with_extension("residuals"), args.force)?;
    let (records, region) = load_records(&args.capture, &capture, &args.options)?;
    let Some(done) = fit_and_sample(
        &records,
        &args.models,
        &args.options,
        &args.mcmc,
        &output,
        args.quiet,
        args.force,
    )?
    else {
        return Ok(());
    };
    let (fits, posterior) = (&done.fits, &done.posterior);
    // Whatever a fit may have got wrong is said even with --quiet.
    for fit in fits {
        for warning in &fit.warnings {
            eprintln!("warning: {}: {warning}", fit.material.model);
        }
    }
    let measured = measure_fits(&records, fits, &args.options);
    let selection = select(&records, fits, &measured, &args.options);
    if !args.quiet && fits.len() > 1 {
        eprintln!("{}", selection.verdict);
    }
    // With a posterior the fit file reports the most probable model, else BIC's choice.
    let best = match posterior {
        Some(run) => run.most_probable,
        None => fits
            .iter()
            .position(|f| f.material.model == selection.preferred)
            .expect("the preferred model is one of the fits"),
    };
    // Residual images (prediction - photo, linear EXR; |residual| PNG at the photos' exposure),
    // from the render the fit's loss measured.
    let predicted = &measured[best].prediction;
    let best = &fits[best];
    let region = region.map(|applied| RegionReport::new(&applied, &records, predicted));
    if let (Some(region), false) = (&region, args.quiet) {
        eprintln!("{}", region.summary());
    }
    let file = FitFile::new(
        best,
        fits,
        &selection,
        posterior.as_ref().map(|r| &r.posterior),
        (&args.capture, &capture),
        &records,
        &args.options,
    )
    .with_region(region);
    let residual = residuals(predicted, &records);
    let exposure = display_exposure(&records.target);
    write_photo_images(&residual_folder.path(""), &records, &residual, exposure, "")?;
    file.write(&output)?;
    residual_folder.commit()?;
    done.remove_checkpoint()?;
    println!("{}", output.display());
    Ok(())
}
