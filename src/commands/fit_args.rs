//! The arguments of `fit`, in the groups `compare` and `bench` share ([`FitOptionArgs`],
//! [`RealCaptureArgs`], [`McmcArgs`], [`MapsArgs`]), and the library options they stand for:
//! [`PipelineOptions`] of a uniform fit, [`MapsOptions`] of a maps fit.

use super::output::check_overwrite;
use crate::bsdf::Model;
use crate::capture::Capture;
use crate::error::Result;
use crate::fit::bayes::mcmc::McmcOptions;
use crate::fit::bayes::model_error::ModelError;
use crate::fit::bayes::sampler::Schedule;
use crate::fit::pipeline::{PipelineOptions, RegionSource};
use crate::fit::point::objective::GradientMethod;
use crate::fit::point::params::{FresnelFamily, ParamSpace};
use crate::fit::point::StochasticFit;
use crate::fit::{FitOptions, Optimizer};
use crate::loss::LossKind;
use crate::maps::fit::{Normals, COARSEST_SIDE};
use crate::maps::pipeline::MapsOptions;
use crate::maps::TexelGrid;
use crate::material::FresnelSpec;
use crate::microfacet::{Height, NdfKind};
use crate::progress::Reporting;
use crate::render::batch::Precision;
use crate::render::plan::{Skip, Skips};
use crate::shading::region::SampleRegion;
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug)]
pub struct FitArgs {
    /// Photo set: a folder with capture.toml, a capture.toml, or a MaterialGAN-format folder.
    pub capture: PathBuf,
    /// Models to fit, comma-separated; the fit file reports the one preferred by BIC (or, with
    /// --mcmc, the most probable).
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
    #[command(flatten)]
    pub mcmc: McmcArgs,
    #[command(flatten)]
    pub map_options: MapsArgs,
}

impl FitArgs {
    /// The fit file `-o` names, or `fits/<capture name>.json`, checked against overwriting.
    pub fn output_path(&self, capture: &Capture) -> Result<PathBuf> {
        let output = self.output_or_default(capture);
        check_overwrite(&output, self.force)?;
        Ok(output)
    }

    /// The fit file `-o` names, or `fits/<capture name>.json`.
    pub fn output_or_default(&self, capture: &Capture) -> PathBuf {
        self.output
            .clone()
            .unwrap_or_else(|| Path::new("fits").join(format!("{}.json", capture.name)))
    }
}

/// How to fit each model: the options `fit` and `compare` share.
#[derive(clap::Args, Debug, Clone)]
pub struct FitOptionArgs {
    /// auto: L-BFGS from a variable-projection start; pso: particle swarm start, then L-BFGS.
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
    /// Work skips to switch off, for comparison (comma-separated: repeated, sparse-multi,
    /// faint-multi, bounce-cap, all); see `bouncefit::render::plan`.
    #[arg(long, value_enum, value_delimiter = ',')]
    pub no_skip: Vec<Skip>,
    /// Arithmetic of the batch kernel's lanes (see docs/speed.md): f32 (the fast path, the
    /// default of single) or f64 (the reference it is measured against, and the default of
    /// the multiple-bounce models, whose fits converge in fewer evaluations with it).
    #[arg(long, value_enum)]
    pub batch_precision: Option<Precision>,
    /// How heitz, bitterli and cui are fitted (see docs/reference.md): corrected (defect
    /// correction on tabulated, then the model's own walks; unbiased at any walk count) or
    /// direct (L-BFGS or Nelder-Mead on the model's own pair loss).
    #[arg(long, value_enum, default_value_t = StochasticFit::Corrected)]
    pub stochastic_fit: StochasticFit,
    #[command(flatten)]
    pub real: RealCaptureArgs,
}

/// Options for real captures (docs/real-captures.md).
#[derive(clap::Args, Debug, Clone)]
pub struct RealCaptureArgs {
    /// Fit one global exposure scale (true / nominal light power) with the material and report
    /// it with its 95% interval; needs --fresnel-known (photos see exposure x reflectance).
    #[arg(long)]
    pub fit_exposure: bool,
    /// Hold the Fresnel at this known value instead of fitting it (syntax of `brdf --fresnel`,
    /// e.g. conductor:0.2378,1.0066,1.2404:3.6264,2.5823,2.3929 for copper).
    #[arg(long, value_parser = parse_fresnel)]
    pub fresnel_known: Option<FresnelSpec>,
    /// The sample's surface lies this far below the plane the cameras and lights were
    /// calibrated on (capture units, e.g. a marker board 0.1 cm above the material); replaces
    /// the manifest's `[sample] depth`.
    #[arg(long, value_parser = parse_depth)]
    pub depth: Option<f64>,
    /// Fit only the pixels that see this rectangle of the sample: x0,y0,x1,y1 in capture
    /// units, origin at the sample's centre, y towards row 0 of a rectified image.
    #[arg(long, value_parser = parse_region, conflicts_with = "mask", allow_hyphen_values = true)]
    pub region: Option<SampleRegion>,
    /// Fit only the pixels that see nonzero pixels of this image, laid over the whole sample
    /// rectangle (row 0 at +y, as a rectified photo).
    #[arg(long)]
    pub mask: Option<PathBuf>,
}

fn parse_fresnel(text: &str) -> std::result::Result<FresnelSpec, String> {
    FresnelSpec::parse(text).map_err(|e| e.to_string())
}

pub(crate) fn parse_depth(text: &str) -> std::result::Result<f64, String> {
    let depth: f64 = text
        .parse()
        .map_err(|_| format!("`{text}` is not a number"))?;
    crate::capture::checks::non_negative(depth)
}

fn parse_region(text: &str) -> std::result::Result<SampleRegion, String> {
    SampleRegion::parse_rectangle(text).map_err(|e| e.to_string())
}

impl RealCaptureArgs {
    /// Opens the photo set (printing its warnings) with `--depth` applied.
    pub fn open(&self, path: &Path) -> Result<Capture> {
        Ok(self.applied_to(super::inputs::open_capture(path)?))
    }

    /// The photo set `held` in memory if given, else the one at `path` ([`Self::open`]),
    /// with `--depth` applied.
    pub fn open_or(&self, path: &Path, held: Option<Capture>) -> Result<Capture> {
        match held {
            Some(capture) => Ok(self.applied_to(capture)),
            None => self.open(path),
        }
    }

    /// `capture` with `--depth` applied.
    fn applied_to(&self, mut capture: Capture) -> Capture {
        if let Some(depth) = self.depth {
            capture.depth = depth;
        }
        capture
    }

    /// The region of `--region` or `--mask`, if any.
    fn region(&self) -> Option<RegionSource> {
        match (&self.region, &self.mask) {
            (Some(region), _) => Some(RegionSource::Given(region.clone())),
            (None, Some(mask)) => Some(RegionSource::Mask(mask.clone())),
            (None, None) => None,
        }
    }
}

/// `--mcmc` and its options (see `bouncefit::fit::bayes::mcmc`).
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
    /// How intervals account for model error: `discrepancy` (the default) widens the posterior
    /// to the spread of the photos' own evidence and to a discrepancy term fitted to the
    /// residuals, `photos` to the photos' spread alone, `none` trusts the model exactly.
    #[arg(long, value_enum, default_value_t = ModelError::Discrepancy)]
    pub model_error: ModelError,
    /// The least relative model error to assume, when you know it from outside the photos (for
    /// example 0.01 for a renderer known to differ by about 1%): the discrepancy term's scales
    /// (per-photo offset, lobe coefficient) are at least this. Default 1e-5.
    #[arg(long)]
    pub discrepancy_floor: Option<f64>,
    /// Checkpoint file (default: the output path with extension `.mcmc-checkpoint.json`).
    #[arg(long)]
    pub checkpoint: Option<PathBuf>,
    /// Continue an interrupted run from its checkpoint.
    #[arg(long)]
    pub resume: bool,
    /// Stop after this many iterations per chain, leaving the checkpoint (for tests).
    #[arg(long, hide = true)]
    pub mcmc_stop_after: Option<u64>,
}

/// The options of `fit --maps`.
#[derive(clap::Args, Debug, Clone)]
pub struct MapsArgs {
    /// Fit material maps (per-texel diffuse albedo, specular F0, roughness; see --normals)
    /// instead of one uniform material.
    #[arg(long)]
    pub maps: bool,
    /// Texel grid WIDTHxHEIGHT over the sample (default: the first photo's width, the height
    /// in the sample's proportions).
    #[arg(long, value_parser = parse_texels, requires = "maps")]
    pub texels: Option<TexelGrid>,
    /// Fit a shading normal per texel too: `--normals` (or `=on`), `=off`, or `=auto` to fit
    /// both and keep normals where they predict the validation photo better by more than 2%.
    #[arg(long, value_enum, num_args = 0..=1, require_equals = true,
          default_value = "off", default_missing_value = "on", requires = "maps")]
    pub normals: Normals,
    /// Most basis materials tried; the number is chosen by the error of a validation photo.
    #[arg(long, default_value_t = 4, requires = "maps",
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=12))]
    pub bases: usize,
    /// Leave photo N (0-based, capture order) out of the fit and report the relative error of
    /// its prediction in the fit file (`holdout`); uniform or maps.
    #[arg(long)]
    pub holdout_photo: Option<usize>,
    /// Choose the bases on a grid of at most N x N texels and refine the texels from it to the
    /// full grid, halving the resolution of grid and photos per level (`off`: choose them on
    /// the full grid, several times slower on large grids; docs/maps.md).
    #[arg(long, value_parser = parse_coarse_to_fine, default_value_t = CoarseToFine::default(),
          requires = "maps")]
    pub coarse_to_fine: CoarseToFine,
    /// Calibrate each photo's own exposure and white balance (a gain per channel, around the
    /// set's) with the maps: fit, measure each training photo's gain against the maps, refit
    /// under the gains (twice the time); the fit file lists them under `photo_gains`.
    #[arg(long, requires = "maps")]
    pub photo_gains: bool,
}

/// The largest texel grid side `--coarse-to-fine` chooses the bases on, or none.
#[derive(Clone, Copy, Debug)]
pub struct CoarseToFine(pub Option<usize>);

impl Default for CoarseToFine {
    fn default() -> Self {
        CoarseToFine(Some(COARSEST_SIDE))
    }
}

impl std::fmt::Display for CoarseToFine {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        match self.0 {
            Some(side) => write!(f, "{side}"),
            None => write!(f, "off"),
        }
    }
}

fn parse_coarse_to_fine(text: &str) -> std::result::Result<CoarseToFine, String> {
    if text == "off" {
        return Ok(CoarseToFine(None));
    }
    match text.parse::<usize>() {
        Ok(side) if (8..=8192).contains(&side) => Ok(CoarseToFine(Some(side))),
        _ => Err(format!(
            "`{text}`: expected `off` or a grid side from 8 to 8192 texels"
        )),
    }
}

fn parse_texels(text: &str) -> std::result::Result<TexelGrid, String> {
    let parts: Vec<&str> = text.split(['x', 'X']).collect();
    let [w, h] = parts.as_slice() else {
        return Err(format!("`{text}`: expected WIDTHxHEIGHT, e.g. 256x256"));
    };
    let number = |s: &str| {
        s.trim()
            .parse::<usize>()
            .ok()
            .filter(|&n| (1..=8192).contains(&n))
            .ok_or_else(|| format!("`{text}`: sizes must be whole numbers from 1 to 8192"))
    };
    Ok(TexelGrid {
        width: number(w)?,
        height: number(h)?,
    })
}

impl FitOptionArgs {
    /// The parameter space of `model` under these options.
    fn space(&self, model: Model) -> ParamSpace {
        ParamSpace {
            model,
            ndf: self.ndf,
            height: self.height,
            anisotropic: self.anisotropic,
            fresnel: self.fresnel,
            diffuse: self.diffuse,
            known_fresnel: self.real.fresnel_known,
            exposure: self.real.fit_exposure,
        }
    }

    /// The library options for fitting `model`.
    pub fn fit_options(&self, model: Model, progress: Reporting) -> FitOptions {
        FitOptions {
            space: self.space(model),
            optimizer: self.optimizer,
            loss: self.loss,
            gradient: self.gradient,
            max_iters: self.max_iters,
            seed: self.seed,
            progress,
            starts: self.starts,
            projection: !self.no_projection,
            pyramid: self.pyramid,
            skips: Skips::except(&self.no_skip),
            precision: self.batch_precision,
            stochastic_fit: self.stochastic_fit,
        }
    }

    /// The library options of a uniform fit of `models` (`fit`, `compare`) and, with `--mcmc`,
    /// of the posterior over them, its checkpoint by default `output` with extension
    /// `.mcmc-checkpoint.json`; `force` replaces a checkpoint an interrupted run left.
    pub fn pipeline_options(
        &self,
        models: &[Model],
        mcmc: &McmcArgs,
        output: &Path,
        progress: Reporting,
        force: bool,
        holdout_photo: Option<usize>,
    ) -> PipelineOptions {
        let candidates: Vec<FitOptions> = models
            .iter()
            .map(|&model| self.fit_options(model, progress.clone()))
            .collect();
        let mcmc = match candidates.first() {
            Some(first) if mcmc.mcmc => Some(self.mcmc_options(mcmc, first.clone(), output)),
            _ => None,
        };
        PipelineOptions {
            candidates,
            pixel_samples: self.pixel_samples,
            region: self.real.region(),
            mcmc,
            replace_checkpoint: force,
            holdout_photo,
        }
    }

    /// The library options of `--mcmc`, its MAP starts fitted with `map` (each candidate's
    /// space in place of its own).
    fn mcmc_options(&self, mcmc: &McmcArgs, map: FitOptions, output: &Path) -> McmcOptions {
        McmcOptions {
            map,
            schedule: Schedule {
                chains: mcmc.chains,
                warmup: mcmc.mcmc_warmup,
                samples: mcmc.mcmc_samples,
                seed: self.seed,
            },
            noise_sigma: mcmc.noise_sigma,
            pixels: mcmc.mcmc_pixels,
            model_error: mcmc.model_error,
            discrepancy_floor: mcmc.discrepancy_floor,
            checkpoint: Some(
                mcmc.checkpoint
                    .clone()
                    .unwrap_or_else(|| output.with_extension("mcmc-checkpoint.json")),
            ),
            resume: mcmc.resume,
            stop_after: mcmc.mcmc_stop_after,
            mode_starts: Vec::new(),
        }
    }

    /// The library options of a maps fit with these options and `maps`; `model` is the one the
    /// uniform fit options name (a maps fit of another model takes them with its own).
    pub fn maps_options(&self, model: Model, maps: &MapsArgs, progress: Reporting) -> MapsOptions {
        MapsOptions {
            fit: self.fit_options(model, progress),
            region: self.real.region(),
            texels: maps.texels,
            normals: maps.normals,
            bases: maps.bases,
            holdout_photo: maps.holdout_photo,
            coarsest: maps.coarse_to_fine.0.map(|side| side * side),
            photo_gains: maps.photo_gains,
        }
    }
}
