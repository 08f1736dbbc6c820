//! `bouncefit fit DIR`: fit one or more models to a photo set and write the fit file plus a
//! residual image per photo.

use super::images::{display_exposure, write_photo_images};
use super::output::{check_overwrite, StagedFolder};
use crate::bsdf::Model;
use crate::capture::Capture;
use crate::error::{Error, Result};
use crate::fit::params::{FresnelFamily, ParamSpace};
use crate::fit::selection::{GaussianFit, Selection};
use crate::fit::{edge_tint, fit_model, FitOptions, ModelFit, Optimizer};
use crate::loss::LossKind;
use crate::microfacet::{Height, NdfKind};
use crate::render::render_all;
use crate::shading::{ExclusionCounts, ShadingRecords};
use serde::Serialize;
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug)]
pub struct FitArgs {
    /// Photo set: a folder with capture.toml, a capture.toml, or a MaterialGAN-format folder.
    pub capture: PathBuf,
    /// Models to fit, comma-separated; the fit file reports the one preferred by BIC.
    #[arg(long, value_delimiter = ',', default_value = "single")]
    pub models: Vec<Model>,
    #[command(flatten)]
    pub options: FitOptionArgs,
    /// Fit file to write (default fits/<capture name>.json); residual images go to
    /// `<fit file without .json>.residuals/`.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Replace an existing fit file.
    #[arg(long)]
    pub force: bool,
    /// No progress display.
    #[arg(long)]
    pub quiet: bool,
}

/// How to fit each model: the options `fit` and `compare` share.
#[derive(clap::Args, Debug, Clone)]
pub struct FitOptionArgs {
    #[arg(long, value_enum, default_value = "lbfgs")]
    pub optimizer: Optimizer,
    /// Fresnel family to fit.
    #[arg(long, value_enum, default_value = "schlick")]
    pub fresnel: FresnelFamily,
    /// Fit alpha_x and alpha_y separately.
    #[arg(long)]
    pub anisotropic: bool,
    /// Fit a Lambertian diffuse albedo too.
    #[arg(long)]
    pub diffuse: bool,
    #[arg(long, default_value = "ggx")]
    pub ndf: NdfKind,
    /// G2 form (Mitsuba 3 uses uncorrelated).
    #[arg(long, default_value = "correlated")]
    pub height: Height,
    #[arg(long, value_enum, default_value = "l2")]
    pub loss: LossKind,
    /// Stratified sub-pixel samples per pixel (a perfect square).
    #[arg(long, default_value_t = 4)]
    pub pixel_samples: usize,
    #[arg(long, default_value_t = 200)]
    pub max_iters: u64,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

impl FitOptionArgs {
    /// The library options for fitting `model`.
    pub fn fit_options(&self, model: Model, progress: bool) -> FitOptions {
        FitOptions {
            space: ParamSpace {
                model,
                ndf: self.ndf,
                height: self.height,
                anisotropic: self.anisotropic,
                fresnel: self.fresnel,
                diffuse: self.diffuse,
            },
            optimizer: self.optimizer,
            loss: self.loss,
            max_iters: self.max_iters,
            seed: self.seed,
            progress,
        }
    }
}

/// The photo set's shading records with targets, refusing a set with no usable pixel.
pub fn load_records(
    capture_path: &Path,
    capture: &Capture,
    pixel_samples: usize,
) -> Result<ShadingRecords> {
    let records = ShadingRecords::build(capture, pixel_samples, true)?;
    if records.weight.iter().all(|w| *w <= 0.0) {
        return Err(Error::invalid(
            capture_path,
            "photos",
            "every pixel is excluded (masked, saturated, non-finite or outside the sample)",
        ));
    }
    Ok(records)
}

/// Fit every model of `models` to `records`, printing one summary line per model unless `quiet`.
pub fn fit_models(
    records: &ShadingRecords,
    models: &[Model],
    options: &FitOptionArgs,
    quiet: bool,
) -> Result<Vec<ModelFit>> {
    models
        .iter()
        .map(|&model| {
            let fit = fit_model(records, &options.fit_options(model, !quiet))?;
            if !quiet {
                eprintln!("{}: loss {:.6e}, alpha {:.5} {:.5}, F0 {:.4} {:.4} {:.4}, {} evaluations, {:.2} s ({})", model, fit.loss, fit.material.alpha[0], fit.material.alpha[1], fit.f0[0], fit.f0[1], fit.f0[2], fit.evaluations, fit.seconds, fit.termination);
            }
            Ok(fit)
        })
        .collect()
}

/// The BIC ranking of fitted models on the records they were fitted to.
pub fn select(records: &ShadingRecords, fits: &[ModelFit], options: &FitOptionArgs) -> Selection {
    let measured: Vec<GaussianFit> = fits
        .iter()
        .map(|fit| {
            let parameters = options.fit_options(fit.material.model, false).space.dim();
            GaussianFit::measure(&fit.material, records, parameters, options.seed)
        })
        .collect();
    Selection::rank(&measured)
}

/// One line of the candidates table of a multi-model fit.
#[derive(Serialize)]
pub struct Candidate {
    model: Model,
    loss: f64,
    alpha: [f64; 2],
    f0: [f64; 3],
    seconds: f64,
}

/// The fit file: one model's material and fit record, what produced it, and how it ranks
/// among the fitted candidates.
#[derive(Serialize)]
pub struct FitFile<'a> {
    #[serde(flatten)]
    pub fit: &'a ModelFit,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub edge_tint: Option<[f64; 3]>,
    pub capture: String,
    pub capture_name: &'a str,
    pub pixel_samples: usize,
    pub pixels_used: usize,
    pub excluded: ExclusionCounts,
    pub seed: u64,
    pub version: &'static str,
    pub candidates: Vec<Candidate>,
    pub selection: &'a Selection,
}

impl<'a> FitFile<'a> {
    /// The fit file of `fit`, one of `fits`, all fitted to `records` of `capture`.
    pub fn new(
        fit: &'a ModelFit,
        fits: &[ModelFit],
        selection: &'a Selection,
        capture: (&Path, &'a Capture),
        records: &ShadingRecords,
        options: &FitOptionArgs,
    ) -> FitFile<'a> {
        FitFile {
            fit,
            edge_tint: edge_tint(&fit.material),
            capture: capture.0.display().to_string(),
            capture_name: &capture.1.name,
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
        }
    }

    /// Write the file as pretty JSON, atomically.
    pub fn write(&self, path: &Path) -> Result<()> {
        crate::capture::atomic_file::write_atomically(path, |w| {
            serde_json::to_writer_pretty(&mut *w, self).map_err(|e| Error::io(path, e))
        })
    }
}

pub fn run_fit(args: &FitArgs) -> Result<()> {
    let capture = Capture::open(&args.capture)?;
    super::synth::warn_all(&capture);
    let output = args
        .output
        .clone()
        .unwrap_or_else(|| Path::new("fits").join(format!("{}.json", capture.name)));
    check_overwrite(&output, args.force)?;
    let residual_folder = output.with_extension("residuals");
    let records = load_records(&args.capture, &capture, args.options.pixel_samples)?;
    let fits = fit_models(&records, &args.models, &args.options, args.quiet)?;
    let selection = select(&records, &fits, &args.options);
    if !args.quiet && fits.len() > 1 {
        eprintln!("{}", selection.verdict);
    }
    let best = fits
        .iter()
        .find(|f| f.material.model == selection.preferred)
        .expect("the preferred model is one of the fits");
    let file = FitFile::new(
        best,
        &fits,
        &selection,
        (&args.capture, &capture),
        &records,
        &args.options,
    );

    // Residual images (prediction - photo, linear EXR; |residual| PNG at the photos' exposure).
    let predicted = render_all(&best.material, &records, args.options.seed);
    let residual: Vec<[f64; 3]> = predicted
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
        .collect();
    let folder = StagedFolder::new(&residual_folder, true)?;
    let exposure = display_exposure(&records.target);
    write_photo_images(&folder.path(""), &records, &residual, exposure, "")?;
    if let Some(parent) = output.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
    }
    file.write(&output)?;
    folder.commit()?;
    println!("{}", output.display());
    Ok(())
}
