//! `bouncefit fit DIR`: fit one or more models to a photo set and write the fit file plus a
//! residual image per photo.

use super::images::{display_exposure, write_photo_images};
use super::output::{check_overwrite, StagedFolder};
use crate::bsdf::Model;
use crate::capture::Capture;
use crate::error::{Error, Result};
use crate::fit::mcmc::{sample_posterior, McmcOptions};
use crate::fit::objective::GradientMethod;
use crate::fit::params::{FresnelFamily, ParamSpace};
use crate::fit::posterior::Posterior;
use crate::fit::sampler::Schedule;
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
    /// Models to fit, comma-separated; the fit file reports the one with the lowest loss.
    #[arg(long, value_delimiter = ',', default_value = "single")]
    pub models: Vec<Model>,
    /// auto: L-BFGS, or Nelder-Mead for heitz; pso: particle swarm start, then L-BFGS.
    #[arg(long, value_enum, default_value = "auto")]
    pub optimizer: Optimizer,
    /// Local searches from this many starts: the global start plus seeded random ones.
    #[arg(long, default_value_t = 1, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=64))]
    pub starts: usize,
    /// Start with a joint scan instead of variable projection (which solves Schlick F0 and the
    /// diffuse albedo in closed form at each roughness, for l2 and relative-l2 losses).
    #[arg(long)]
    pub no_projection: bool,
    /// Coarse-to-fine levels: 1 fits at full resolution only, n starts at 1/2^(n-1).
    #[arg(long, default_value_t = 1, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=6))]
    pub pyramid: usize,
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
    /// L-BFGS gradients: exact (dual numbers; pathwise for the position-free stochastic
    /// models) where the model allows, finite differences otherwise (heitz); or always fd.
    #[arg(long, value_enum, default_value = "exact")]
    pub gradient: GradientMethod,
    /// Stratified sub-pixel samples per pixel (a perfect square).
    #[arg(long, default_value_t = 4)]
    pub pixel_samples: usize,
    #[arg(long, default_value_t = 200)]
    pub max_iters: u64,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
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
    #[command(flatten)]
    pub mcmc: McmcArgs,
}

/// `--mcmc` and its options (see `bouncefit::fit::mcmc`).
#[derive(clap::Args, Debug)]
pub struct McmcArgs {
    /// Sample the Bayesian posterior over parameters and models; the fit file gains `posterior`.
    #[arg(long)]
    pub mcmc: bool,
    /// Independent chains.
    #[arg(long, default_value_t = 4)]
    pub chains: usize,
    /// Kept iterations per chain.
    #[arg(long, default_value_t = 500)]
    pub mcmc_samples: u64,
    /// Warm-up iterations per chain (step-size adaptation, discarded).
    #[arg(long, default_value_t = 200)]
    pub mcmc_warmup: u64,
    /// Pixels in the likelihood, a seeded random subset (0: all); intervals widen by about
    /// sqrt(all pixels / this).
    #[arg(long, default_value_t = 4096)]
    pub mcmc_pixels: usize,
    /// Noise level of the likelihood in loss units (default: estimated from the best MAP loss).
    #[arg(long)]
    pub noise_sigma: Option<f64>,
    /// Checkpoint file (default `<fit file>.mcmc-checkpoint.json`).
    #[arg(long)]
    pub checkpoint: Option<PathBuf>,
    /// Continue an interrupted run from its checkpoint.
    #[arg(long)]
    pub resume: bool,
    /// Stop after this many iterations per chain, leaving the checkpoint (for tests).
    #[arg(long, hide = true)]
    pub mcmc_stop_after: Option<u64>,
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

/// The fit file: the best model's material and fit record, and what produced it.
#[derive(Serialize)]
struct FitFile<'a> {
    #[serde(flatten)]
    best: &'a ModelFit,
    #[serde(skip_serializing_if = "Option::is_none")]
    edge_tint: Option<[f64; 3]>,
    capture: String,
    capture_name: &'a str,
    pixel_samples: usize,
    pixels_used: usize,
    excluded: ExclusionCounts,
    seed: u64,
    version: &'static str,
    candidates: Vec<Candidate>,
    #[serde(skip_serializing_if = "Option::is_none")]
    posterior: Option<&'a Posterior>,
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
    let records = ShadingRecords::build(&capture, args.pixel_samples, true)?;
    let pixels_used = records.weight.iter().filter(|w| **w > 0.0).count();
    if pixels_used == 0 {
        return Err(Error::invalid(
            &args.capture,
            "photos",
            "every pixel is excluded (masked, saturated, non-finite or outside the sample)",
        ));
    }
    let spaces: Vec<ParamSpace> = args
        .models
        .iter()
        .map(|&model| ParamSpace {
            model,
            ndf: args.ndf,
            height: args.height,
            anisotropic: args.anisotropic,
            fresnel: args.fresnel,
            diffuse: args.diffuse,
        })
        .collect();
    if spaces.is_empty() {
        return Err(Error::argument("--models", "no model given"));
    }
    let checkpoint = args
        .mcmc
        .checkpoint
        .clone()
        .unwrap_or_else(|| output.with_extension("mcmc-checkpoint.json"));
    let run = if args.mcmc.mcmc {
        match sample_posterior(
            &records,
            &spaces,
            &mcmc_options(args, &spaces, checkpoint.clone()),
        )? {
            Some(run) => Some(run),
            None => {
                eprintln!(
                    "stopped; the sampler state is in {} (continue with --resume)",
                    checkpoint.display()
                );
                return Ok(());
            }
        }
    } else {
        None
    };
    let mut fits = match &run {
        Some(run) if run.all_pixels => run.maps.clone(),
        _ => Vec::new(),
    };
    for &space in spaces.iter().skip(fits.len()) {
        let model = space.model;
        let fit = fit_model(&records, &fit_options(args, space))?;
        if !args.quiet {
            eprintln!("{}: loss {:.6e}, alpha {:.5} {:.5}, F0 {:.4} {:.4} {:.4}, {} evaluations, {:.2} s ({})", model, fit.loss, fit.material.alpha[0], fit.material.alpha[1], fit.f0[0], fit.f0[1], fit.f0[2], fit.evaluations, fit.seconds, fit.termination);
        }
        fits.push(fit);
    }
    // With a posterior the fit file reports the most probable model, else the lowest loss.
    let best = match &run {
        Some(run) => &fits[run.most_probable],
        None => fits
            .iter()
            .min_by(|a, b| a.loss.total_cmp(&b.loss))
            .expect("at least one model"),
    };
    let candidates = fits
        .iter()
        .map(|f| Candidate {
            model: f.material.model,
            loss: f.loss,
            alpha: f.material.alpha,
            f0: f.f0,
            seconds: f.seconds,
        })
        .collect();
    let file = FitFile {
        best,
        edge_tint: edge_tint(&best.material),
        capture: args.capture.display().to_string(),
        capture_name: &capture.name,
        pixel_samples: args.pixel_samples,
        pixels_used,
        excluded: records.excluded,
        seed: args.seed,
        version: env!("CARGO_PKG_VERSION"),
        candidates,
        posterior: run.as_ref().map(|r| &r.posterior),
    };

    // Residual images (prediction - photo, linear EXR; |residual| PNG at the photos' exposure).
    let predicted = render_all(&best.material, &records, args.seed);
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
    crate::capture::atomic_file::write_atomically(&output, |w| {
        serde_json::to_writer_pretty(&mut *w, &file).map_err(|e| Error::io(&output, e))
    })?;
    folder.commit()?;
    if run.is_some() && checkpoint.exists() {
        std::fs::remove_file(&checkpoint).map_err(|e| Error::io(&checkpoint, e))?;
    }
    println!("{}", output.display());
    Ok(())
}

fn fit_options(args: &FitArgs, space: ParamSpace) -> FitOptions {
    FitOptions {
        space,
        optimizer: args.optimizer,
        loss: args.loss,
        gradient: args.gradient,
        max_iters: args.max_iters,
        seed: args.seed,
        progress: !args.quiet,
        starts: args.starts,
        projection: !args.no_projection,
        pyramid: args.pyramid,
    }
}

fn mcmc_options(args: &FitArgs, spaces: &[ParamSpace], checkpoint: PathBuf) -> McmcOptions {
    McmcOptions {
        map: fit_options(args, spaces[0]),
        schedule: Schedule {
            chains: args.mcmc.chains,
            warmup: args.mcmc.mcmc_warmup,
            samples: args.mcmc.mcmc_samples,
            seed: args.seed,
        },
        noise_sigma: args.mcmc.noise_sigma,
        pixels: args.mcmc.mcmc_pixels,
        checkpoint: Some(checkpoint),
        resume: args.mcmc.resume,
        stop_after: args.mcmc.mcmc_stop_after,
    }
}
