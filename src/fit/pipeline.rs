//! The uniform fit of a photo set, as `fit` and `compare` run it, without the command line
//! ([`run`]):
//!
//! 1. [`load_records`]: the photo set's shading records, restricted to a region, refused when
//!    no pixel can be fitted;
//! 2. `fit_and_sample`: a fit of every candidate model ([`crate::fit::fit_model`]) and, with
//!    [`PipelineOptions::mcmc`], the posterior over them ([`sample_posterior`]);
//! 3. `measure_fits` and `select`: each fit measured by the objective it was fitted on, and
//!    the BIC ranking of the candidates.
//!
//! What it produces is written as a fit file by [`super::fit_file`]. Nothing here prints: the
//! pipeline hands its warnings and each finished fit to its caller.

use super::bayes::holdout::{check_held_out_photo, HeldOutPhoto};
use super::bayes::mcmc::{sample_posterior, McmcOptions, PosteriorRun};
use super::bayes::selection::{GaussianFit, Selection};
use super::point::{measure, Measured};
use super::{fit_model, FitOptions, ModelFit};
use crate::capture::Capture;
use crate::error::{Error, Result};
use crate::progress::Reporting;
use crate::render::render_pixels;
use crate::shading::region::{AppliedRegion, SampleRegion};
use crate::shading::ShadingRecords;
use std::path::{Path, PathBuf};

/// The part of the sample a fit is restricted to (`--region`, `--mask`).
#[derive(Clone, Debug)]
pub enum RegionSource {
    /// A region at hand, e.g. a rectangle.
    Given(SampleRegion),
    /// A mask image ([`SampleRegion::load_mask`]), read after the records so that a photo set
    /// that cannot be read is reported first.
    Mask(PathBuf),
}

impl RegionSource {
    /// The region, reading the mask image if it is one.
    fn load(&self) -> Result<SampleRegion> {
        match self {
            RegionSource::Given(region) => Ok(region.clone()),
            RegionSource::Mask(path) => SampleRegion::load_mask(path),
        }
    }
}

/// How a photo set is fitted by one or more candidate models.
#[derive(Clone, Debug)]
pub struct PipelineOptions {
    /// The fit options of each candidate (its model is `space.model`), in the order of the
    /// fits and of the fit file's candidates.
    pub candidates: Vec<FitOptions>,
    /// Stratified sub-pixel samples per pixel of the records (a perfect square).
    pub pixel_samples: usize,
    /// The part of the sample to fit; all of it without.
    pub region: Option<RegionSource>,
    /// Sample the posterior over the candidates too (`--mcmc`). [`run`] sets its
    /// `mode_starts` from its fits on every pixel.
    pub mcmc: Option<McmcOptions>,
    /// Start the sampler afresh over a checkpoint an interrupted run left (otherwise that
    /// checkpoint is refused unless the sampler resumes it).
    pub replace_checkpoint: bool,
    /// Leave this photo (index in capture order) out of the fits and measure how well the
    /// chosen fit predicts it ([`UniformRun::holdout`], `fit --holdout-photo`).
    pub holdout_photo: Option<usize>,
}

/// The photo set's shading records with targets, `pixel_samples` sub-samples per pixel,
/// restricted to `region` (then also returned), refusing a set with no usable pixel (all
/// excluded, the counts by reason in the message) or whose usable pixels are all black, which
/// no material with positive reflectance can fit. Non-finite and negative pixels left out are
/// told to `warn`.
pub fn load_records(
    capture_path: &Path,
    capture: &Capture,
    pixel_samples: usize,
    region: Option<&RegionSource>,
    warn: &dyn Fn(&str),
) -> Result<(ShadingRecords, Option<AppliedRegion>)> {
    let mut records = ShadingRecords::build(capture, pixel_samples, true)?;
    let region = match region.map(RegionSource::load).transpose()? {
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
        warn(&format!(
            "{}: photos: {} non-finite and {} negative pixels excluded from the fit",
            capture_path.display(),
            e.non_finite,
            e.negative
        ));
    }
    Ok((records, region))
}

/// What [`run`] produced from a photo set.
pub struct UniformRun {
    pub records: ShadingRecords,
    /// The region the records are restricted to.
    pub region: Option<AppliedRegion>,
    /// A fit per candidate, in the order of [`PipelineOptions::candidates`].
    pub fits: Vec<ModelFit>,
    /// The posterior run, with [`PipelineOptions::mcmc`].
    pub posterior: Option<PosteriorRun>,
    /// Each fit measured by the objective it was fitted on.
    pub measured: Vec<Measured>,
    /// The BIC ranking of the fits.
    pub selection: Selection,
    /// How well the chosen fit predicts the photo [`PipelineOptions::holdout_photo`] left
    /// out of the fits (the records weigh none of its pixels).
    pub holdout: Option<HeldOutPhoto>,
    /// The sampler's checkpoint file.
    checkpoint: Option<PathBuf>,
}

/// Fits the candidates of `options` to the photo set at `capture_path`: its records
/// ([`load_records`], warnings to `warn`), the fits and the posterior (each fit handed to
/// `fitted` as it is done), each fit measured and the candidates ranked. `None` when the sampler stopped early and left its
/// checkpoint.
pub fn run(
    capture_path: &Path,
    capture: &Capture,
    options: &PipelineOptions,
    warn: &dyn Fn(&str),
    fitted: &dyn Fn(&ModelFit),
) -> Result<Option<UniformRun>> {
    let (all, region) = load_records(
        capture_path,
        capture,
        options.pixel_samples,
        options.region.as_ref(),
        warn,
    )?;
    check_held_out_photo(options.holdout_photo, all.photos.len())?;
    if options.holdout_photo.is_some() && all.photos.len() < 2 {
        return Err(Error::invalid(
            capture_path,
            "photos",
            "a fit with a held-out photo needs at least one more photo to fit",
        ));
    }
    // With a held-out photo, the records of every photo are kept to measure its prediction.
    let (records, held_out) = match options.holdout_photo {
        Some(h) => (all.restricted_to_photos(|i| i != h), Some((h, all))),
        None => (all, None),
    };
    let Some((fits, posterior)) = fit_and_sample(&records, options, fitted)? else {
        return Ok(None);
    };
    let measured = measure_fits(&records, &fits, options);
    let selection = select(&records, &fits, &measured, options);
    let mut run = UniformRun {
        records,
        region,
        fits,
        posterior,
        measured,
        selection,
        holdout: None,
        checkpoint: options.mcmc.as_ref().and_then(|m| m.checkpoint.clone()),
    };
    run.holdout = held_out.map(|(h, all)| {
        let chosen = run.chosen();
        let fit = &run.fits[chosen];
        let seed = options.candidates[chosen].seed;
        HeldOutPhoto::measure(&all, h, |pixels| {
            render_pixels(&fit.material, &fit.exposed(&all), pixels, seed)
        })
    });
    Ok(Some(run))
}

impl UniformRun {
    /// The fit the fit file reports: with a posterior the most probable model, else BIC's
    /// choice.
    pub fn chosen(&self) -> usize {
        match &self.posterior {
            Some(run) => run.most_probable,
            None => self
                .fits
                .iter()
                .position(|f| f.material.model == self.selection.preferred)
                .expect("the preferred model is one of the fits"),
        }
    }

    /// The chosen fit's render of the records, the one its loss measured.
    pub fn prediction(&self) -> &[[f64; 3]] {
        &self.measured[self.chosen()].prediction
    }

    /// Removes the sampler's checkpoint once the outputs it led to are written.
    pub fn remove_checkpoint(&self) -> Result<()> {
        if let (Some(_), Some(checkpoint)) = (&self.posterior, &self.checkpoint) {
            if checkpoint.exists() {
                std::fs::remove_file(checkpoint).map_err(|e| Error::io(checkpoint, e))?;
            }
        }
        Ok(())
    }
}

/// Fits every candidate of `options` to `records`, handing each fit to `fitted` as it is done,
/// and, with `options.mcmc`, samples the posterior over them first (its MAP fits are reused
/// when the likelihood saw every pixel). `None` when the sampler stopped early and left its
/// checkpoint (`stop_after`). A checkpoint left by an earlier run is continued only when the
/// sampler resumes and replaced only with `replace_checkpoint`.
fn fit_and_sample(
    records: &ShadingRecords,
    options: &PipelineOptions,
    fitted: &dyn Fn(&ModelFit),
) -> Result<Option<(Vec<ModelFit>, Option<PosteriorRun>)>> {
    let Some(first) = options.candidates.first() else {
        return Err(Error::argument("--models", "no model given"));
    };
    first
        .space
        .check()
        .map_err(|m| Error::argument("--fit-exposure", m))?;
    let left_by_another_run = options
        .mcmc
        .as_ref()
        .filter(|m| !m.resume && !options.replace_checkpoint)
        .and_then(|m| m.checkpoint.as_ref())
        .filter(|checkpoint| checkpoint.exists());
    if let Some(checkpoint) = left_by_another_run {
        return Err(Error::invalid(
            checkpoint,
            "checkpoint",
            "an interrupted sampler run left this file; pass --resume to continue it or --force to start over",
        ));
    }
    let fit_one = |candidate: &FitOptions| -> Result<ModelFit> {
        let fit = fit_model(records, candidate)?;
        fitted(&fit);
        Ok(fit)
    };
    // On a subset of the pixels the chains' MAP fits may miss a basin that the fits on every
    // pixel find, so those come first and hand the sampler their other basins as modes.
    let loss_pixels = records.weight.iter().filter(|w| **w > 0.0).count();
    let mut fits = match &options.mcmc {
        Some(mcmc) if mcmc.pixels != 0 && mcmc.pixels < loss_pixels && !mcmc.resume => options
            .candidates
            .iter()
            .map(&fit_one)
            .collect::<Result<Vec<_>>>()?,
        _ => Vec::new(),
    };
    let posterior = match &options.mcmc {
        Some(mcmc) => {
            let spaces: Vec<_> = options.candidates.iter().map(|c| c.space).collect();
            let mcmc = McmcOptions {
                mode_starts: fits
                    .iter()
                    .map(|fit| fit.alternatives.iter().map(|a| a.point.clone()).collect())
                    .collect(),
                ..mcmc.clone()
            };
            match sample_posterior(records, &spaces, &mcmc)? {
                Some(run) => Some(run),
                None => return Ok(None),
            }
        }
        None => None,
    };
    if fits.is_empty() {
        if let Some(run) = posterior.as_ref().filter(|run| run.all_pixels) {
            fits = run.maps.clone();
        }
    }
    for candidate in options.candidates.iter().skip(fits.len()) {
        fits.push(fit_one(candidate)?);
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
    Ok(Some((fits, posterior)))
}

/// Each fit measured by the objective it was fitted on ([`measure`]): `fits` in the order of
/// `options.candidates`.
fn measure_fits(
    records: &ShadingRecords,
    fits: &[ModelFit],
    options: &PipelineOptions,
) -> Vec<Measured> {
    fits.iter()
        .zip(&options.candidates)
        .map(|(fit, candidate)| {
            let quiet = FitOptions {
                progress: Reporting::Off,
                ..candidate.clone()
            };
            measure(records, fit, &quiet)
        })
        .collect()
}

/// The BIC ranking of `fits` (in the order of `options.candidates`), from their residuals as
/// `measured` ([`measure_fits`]): the same seed as the fit, so a stochastic model sees the
/// random numbers it was fitted with, and its pair residual.
fn select(
    records: &ShadingRecords,
    fits: &[ModelFit],
    measured: &[Measured],
    options: &PipelineOptions,
) -> Selection {
    let observations = 3 * records.weight.iter().filter(|w| **w > 0.0).count();
    let gaussian: Vec<GaussianFit> = fits
        .iter()
        .zip(measured)
        .zip(&options.candidates)
        .map(|((fit, measured), candidate)| GaussianFit {
            model: fit.material.model,
            mean_squared_residual: measured.l2,
            observations,
            parameters: candidate.space.dim(),
        })
        .collect();
    Selection::rank(&gaussian)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::Model;
    use crate::fit::point::params::ParamSpace;

    /// The pipeline runs without the command line: two candidates fitted to the bundled copper
    /// set, each measured, ranked, and the true model (`single`, alpha 0.3) preferred.
    #[test]
    fn a_fit_of_the_copper_set_runs_without_the_command_line() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets/copper-flash");
        let capture = Capture::open(&path).unwrap();
        let options = PipelineOptions {
            candidates: [Model::Single, Model::KullaConty]
                .map(|model| FitOptions::defaults(ParamSpace::plain(model)))
                .to_vec(),
            pixel_samples: 1,
            region: None,
            mcmc: None,
            replace_checkpoint: false,
            holdout_photo: None,
        };
        let fitted = std::cell::Cell::new(0);
        let warn = |w: &str| panic!("no warning expected: {w}");
        let run = run(&path, &capture, &options, &warn, &|_| {
            fitted.set(fitted.get() + 1)
        })
        .unwrap()
        .expect("no sampler to stop");
        assert_eq!(fitted.get(), 2);
        assert_eq!((run.fits.len(), run.measured.len()), (2, 2));
        assert!(run.region.is_none() && run.posterior.is_none());
        assert_eq!(run.selection.preferred, Model::Single);
        assert!((run.fits[0].material.alpha[0] - 0.3).abs() < 0.01);
    }

    /// `--holdout-photo 8`: the fit is that of the set without photo 8, and its prediction of
    /// photo 8 is measured as the maps fit measures one.
    #[test]
    fn a_held_out_photo_is_left_out_of_the_fit_and_predicted() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets/copper-flash");
        let capture = Capture::open(&path).unwrap();
        let options = |holdout_photo| PipelineOptions {
            candidates: vec![FitOptions::defaults(ParamSpace::plain(Model::Single))],
            pixel_samples: 1,
            region: None,
            mcmc: None,
            replace_checkpoint: false,
            holdout_photo,
        };
        let fit = |capture: &Capture, holdout| {
            run(&path, capture, &options(holdout), &|_| {}, &|_| {})
                .unwrap()
                .expect("no sampler to stop")
        };
        let held_out = fit(&capture, Some(8));
        let mut eight = capture.clone();
        eight.photos.pop();
        let without = fit(&eight, None);
        let (a, b) = (&held_out.fits[0], &without.fits[0]);
        assert_eq!(a.material.alpha, b.material.alpha);
        assert_eq!(a.f0, b.f0);
        assert_eq!(a.loss, b.loss);
        let report = held_out.holdout.as_ref().expect("a held-out photo");
        assert_eq!((report.photo, report.stem.as_str()), (8, "08"));
        // Noise-free photos of the model fitted: the unseen photo is predicted to within the
        // sub-pixel sampling (the fit's 1 sample against the photos' own), far better than by
        // the mean of the others.
        assert!(report.relative_error < 0.02, "{report:?}");
        assert!(report.mean_photo_error.unwrap() > 5.0 * report.relative_error);
        let m = run(&path, &capture, &options(Some(9)), &|_| {}, &|_| {})
            .err()
            .unwrap()
            .to_string();
        assert_eq!(
            m,
            "--holdout-photo: photo 9 does not exist; the set has photos 0 to 8"
        );
    }
}
