//! Point estimation: the one best material of one model for the records.
//!
//! 1. Pyramid (`--pyramid n`): fit at 1/2^(n-1) of the resolution first
//!    ([`ShadingRecords::coarsened`]), each finer level starting from the coarser result.
//! 2. Start ([`start`]): variable projection over roughness ([`projection`]) where the space and
//!    loss allow it, else a roughness scan, or a particle swarm (`--optimizer pso`); plus seeded
//!    random starts (`--starts`).
//! 3. Local search ([`local`]) over all free coordinates of the [`ParamSpace`] from each start:
//!    L-BFGS (More-Thuente) or Nelder-Mead, chosen per model by [`Optimizer::local`]; L-BFGS on
//!    exact dual-number gradients where the model allows, central finite differences otherwise
//!    or on request ([`objective::GradientMethod`]).
//! 4. Report: the material, loss, per-photo losses, every start's result, the optimiser trace,
//!    evaluation counts and timings, in the fit file format of DESIGN.md; the exposure value
//!    (`--fit-exposure`) without its interval, which the Bayesian room adds
//!    (`crate::fit::bayes::exposure`).
//!
//! Nothing here calls into `crate::fit::bayes` (see the table in `crate::fit`).

pub mod corrected;
pub mod exposure;
pub mod local;
pub mod objective;
pub mod params;
pub mod projection;
pub mod start;
pub mod uniformity;

use crate::bsdf::Model;
use crate::error::{Error, Result};
use crate::loss::LossKind;
use crate::material::{FresnelSpec, Material};
use crate::microfacet::fresnel::reflectivity_edge_tint_from_ior;
use crate::progress::Reporting;
use crate::render::batch::Precision;
use crate::render::plan::{PlanSummary, Skips};
use crate::render::render_pixels;
use crate::shading::ShadingRecords;
use argmin::core::Error as ArgminError;
pub use corrected::StochasticFit;
use exposure::{exposed_records, ExposureEstimate};
pub use local::TracePoint;
use local::{LocalOptimizer, Recorder};
use objective::{render_seeds, GradientMethod, Objective};
use params::{ParamSpace, ALPHA_BOUNDS, EXPOSURE_BOUNDS};
use projection::Projection;
use serde::{Deserialize, Serialize};
pub use start::StartMethod;
use std::borrow::Cow;
use std::time::Instant;

/// The optimiser of a fit (`--optimizer`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Optimizer {
    /// Per model: Levenberg-Marquardt where the objective has a Gauss-Newton matrix
    /// ([`objective::Objective::has_gauss_newton`]), Nelder-Mead for `heitz`,
    /// L-BFGS otherwise.
    #[default]
    Auto,
    NelderMead,
    Lbfgs,
    /// Particle swarm over the whole search box, then L-BFGS.
    Pso,
}

impl Optimizer {
    /// The local optimiser this choice runs for `model`. A model whose value is not generic
    /// over the scalar (`heitz`, [`crate::bsdf::registry::Capabilities::generic`]) gets
    /// Nelder-Mead: its explicit-height walks have no pathwise derivative here, and central
    /// differences of its walks at fixed random numbers step over the jumps where a walk
    /// changes its path (on `heitz` photos of copper at alpha 0.8, L-BFGS with central
    /// differences stopped at alpha 0.55 to 0.66 on failed line searches, Nelder-Mead reached
    /// 0.76).
    pub fn local(self, model: Model) -> LocalOptimizer {
        match self {
            Optimizer::NelderMead => LocalOptimizer::NelderMead,
            Optimizer::Auto if !model.capabilities().generic => LocalOptimizer::NelderMead,
            _ => LocalOptimizer::Lbfgs,
        }
    }
}

/// Everything a fit needs besides the photos.
#[derive(Clone, Debug)]
pub struct FitOptions {
    pub space: ParamSpace,
    pub optimizer: Optimizer,
    pub loss: LossKind,
    /// How L-BFGS gets its gradients (exact where the model allows).
    pub gradient: GradientMethod,
    pub max_iters: u64,
    pub seed: u64,
    /// Where the progress of the local searches goes (a sink may stop the fit).
    pub progress: Reporting,
    /// Local searches from this many starts (the global start plus seeded random ones).
    pub starts: usize,
    /// Use variable projection for the start where the space and loss allow it.
    pub projection: bool,
    /// Pyramid levels: 1 fits at full resolution only; n fits at 1/2^(n-1) first.
    pub pyramid: usize,
    /// Work the renders may skip (`--no-skip` switches skips off; see `render::plan`).
    pub skips: Skips,
    /// Arithmetic of the batch kernel's lanes (`--batch-precision`); `None`: the model's
    /// default ([`crate::bsdf::registry::Capabilities::lanes`]).
    pub precision: Option<Precision>,
    /// How `heitz`, `bitterli` and `cui` are fitted (`--stochastic-fit`, [`corrected`]).
    pub stochastic_fit: StochasticFit,
}

impl FitOptions {
    /// `fit`'s command-line defaults over `space`, without progress.
    pub fn defaults(space: ParamSpace) -> FitOptions {
        FitOptions {
            space,
            optimizer: Optimizer::Auto,
            loss: LossKind::L2,
            gradient: GradientMethod::Exact,
            max_iters: 200,
            seed: 0,
            progress: Reporting::Off,
            starts: 1,
            projection: true,
            pyramid: 1,
            skips: Skips::all(),
            precision: None,
            stochastic_fit: StochasticFit::Corrected,
        }
    }
}

/// The loss of one photo at the fitted parameters.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PhotoLoss {
    pub image: String,
    pub loss: f64,
    pub pixels: usize,
}

/// One local search of a multi-start fit.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StartResult {
    pub method: StartMethod,
    pub loss: f64,
    pub alpha: [f64; 2],
}

/// One level of a coarse-to-fine fit.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct LevelResult {
    /// Resolution of the first photo at this level.
    pub resolution: [usize; 2],
    pub loss: f64,
    pub evaluations: usize,
    pub seconds: f64,
}

/// The result of fitting one model: the material plus what produced it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ModelFit {
    #[serde(flatten)]
    pub material: Material,
    /// Reflectance at normal incidence implied by the fitted Fresnel.
    pub f0: [f64; 3],
    pub loss: f64,
    pub loss_kind: LossKind,
    pub optimizer: Optimizer,
    /// The gradient L-BFGS used (`None` for Nelder-Mead, which needs none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gradient: Option<GradientMethod>,
    pub iterations: u64,
    /// Objective evaluations, projected solves' renders included.
    pub evaluations: usize,
    pub termination: String,
    pub seconds: f64,
    /// How the first local search started, and from where.
    pub start_method: StartMethod,
    pub start: Material,
    /// Every local search of a multi-start fit (`--starts`), best first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub starts: Vec<StartResult>,
    /// Every level of a coarse-to-fine fit (`--pyramid`), coarsest first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub levels: Vec<LevelResult>,
    pub photos: Vec<PhotoLoss>,
    pub trace: Vec<TracePoint>,
    /// What the renders of the final level skipped (`render::plan`).
    #[serde(default)]
    pub render_plan: PlanSummary,
    /// The fitted exposure (`--fit-exposure`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exposure: Option<ExposureEstimate>,
    /// The defect correction rounds of a stochastic model's fit ([`corrected`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub correction: Option<corrected::Correction>,
    /// The start's profile over roughness (`[alpha, loss]` at every node it evaluated,
    /// [`start::Profile`]): the projected loss, or the scan's squared error, in that method's
    /// own units. Its basins are where the local searches started.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub profile: Vec<[f64; 2]>,
    /// Optima of other basins that explain the photos almost as well ([`Alternative`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub alternatives: Vec<Alternative>,
    /// What the fit may have got wrong: a parameter stopped at its bound, another basin as
    /// good; printed by `fit` and `compare`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
}

impl ModelFit {
    /// One line on the finished fit, as `fit` prints it: loss, alpha (with a corrected
    /// stochastic fit, how far its walks' noise leaves alpha), F0, evaluations and time.
    pub fn summary(&self) -> String {
        let noise = self
            .correction
            .as_ref()
            .and_then(|c| c.alpha_noise)
            .map_or(String::new(), |n| {
                format!(" (walks' noise {:.2}%)", 100.0 * n[0].max(n[1]))
            });
        format!(
            "{}: loss {:.6e}, alpha {:.5} {:.5}{}, F0 {:.4} {:.4} {:.4}, {} evaluations, {:.2} s ({})",
            self.material.model,
            self.loss,
            self.material.alpha[0],
            self.material.alpha[1],
            noise,
            self.f0[0],
            self.f0[1],
            self.f0[2],
            self.evaluations,
            self.seconds,
            self.termination
        )
    }

    /// The fitted exposure, 1 when none was fitted.
    pub fn exposure_value(&self) -> f64 {
        self.exposure.map_or(1.0, |e| e.value)
    }

    /// Coordinates of this fit in `space`.
    pub fn point(&self, space: &ParamSpace) -> Vec<f64> {
        space.point(&self.material, self.exposure_value())
    }

    /// `records` as this fit predicts them: irradiance times the fitted exposure.
    pub fn exposed<'r>(&self, records: &'r ShadingRecords) -> Cow<'r, ShadingRecords> {
        exposed_records(records, self.exposure_value())
    }
}

/// Coarse levels stop before a photo's shorter side falls below this many pixels.
const PYRAMID_MIN_SIDE: usize = 16;

/// A point estimate and its coordinates in the fit's [`ParamSpace`], taken where the exposure
/// value was read: the point the Bayesian room expands around.
#[derive(Clone, Debug)]
pub struct PointFit {
    pub fit: ModelFit,
    pub x: Vec<f64>,
}

/// Fit one model (the one in `options.space`) to the records: the point estimate, with the
/// exposure value but no interval (`crate::fit::fit_model` adds it). `heitz`, `bitterli` and
/// `cui` are fitted by defect correction on `tabulated` ([`corrected`]) unless asked otherwise.
pub fn fit_point(records: &ShadingRecords, options: &FitOptions) -> Result<PointFit> {
    if corrected::applies(options) {
        corrected::fit(records, options)
    } else {
        fit_point_direct(records, options)
    }
}

/// [`fit_point`] on the model's own objective: pyramid levels, then the full resolution.
fn fit_point_direct(records: &ShadingRecords, options: &FitOptions) -> Result<PointFit> {
    fit_point_on(&objective_of(records, options), records, options)
}

/// [`fit_point_direct`] with `objective` (`options`' objective over `records`) for the full
/// resolution, so that a caller can fit it again (`corrected`).
fn fit_point_on(
    objective: &Objective,
    records: &ShadingRecords,
    options: &FitOptions,
) -> Result<PointFit> {
    let started = Instant::now();
    let mut coarse: Vec<ShadingRecords> = Vec::new();
    while coarse.len() + 1 < options.pyramid.max(1) {
        let finest = coarse.last().unwrap_or(records);
        match finest.coarsened() {
            Some(c)
                if c.photos
                    .iter()
                    .all(|s| s.width.min(s.height) >= PYRAMID_MIN_SIDE) =>
            {
                coarse.push(c)
            }
            _ => break,
        }
    }
    let mut levels = Vec::new();
    let mut start: Option<Vec<f64>> = None;
    let mut evaluations = 0;
    for level in coarse.iter().rev() {
        let level_started = Instant::now();
        let fit = fit_level(level, options, start.take(), &Reporting::Off)?;
        evaluations += fit.evaluations;
        levels.push(LevelResult {
            resolution: [level.photos[0].width, level.photos[0].height],
            loss: fit.loss,
            evaluations: fit.evaluations,
            seconds: level_started.elapsed().as_secs_f64(),
        });
        start = Some(fit.point(&options.space));
    }
    let level_started = Instant::now();
    let mut fit = fit_level_on(objective, records, options, start, &options.progress)?;
    if !levels.is_empty() {
        levels.push(LevelResult {
            resolution: [records.photos[0].width, records.photos[0].height],
            loss: fit.loss,
            evaluations: fit.evaluations,
            seconds: level_started.elapsed().as_secs_f64(),
        });
    }
    fit.evaluations += evaluations;
    fit.levels = levels;
    let x = fit.point(&options.space);
    fit.exposure = exposure::estimate(options.space, &x);
    fit.seconds = started.elapsed().as_secs_f64();
    Ok(PointFit { fit, x })
}

/// Fit at one resolution: global start (or the given one), local searches, report.
fn fit_level(
    records: &ShadingRecords,
    options: &FitOptions,
    given_start: Option<Vec<f64>>,
    progress: &Reporting,
) -> Result<ModelFit> {
    fit_level_on(
        &objective_of(records, options),
        records,
        options,
        given_start,
        progress,
    )
}

/// [`fit_level`] on `objective`, `options`' objective over `records`. Its targets may differ
/// from `records`' only for a deterministic model: a stochastic one's start screening and
/// the judging of its searches build their objectives from `records`.
fn fit_level_on(
    objective: &Objective,
    records: &ShadingRecords,
    options: &FitOptions,
    given_start: Option<Vec<f64>>,
    progress: &Reporting,
) -> Result<ModelFit> {
    let space = options.space;
    // Stochastic models: the global start is searched on one render, the local searches use
    // the unbiased pair loss (see `Objective::single_render` and `crate::loss`). A
    // deterministic model's objective already renders once, and the start shares it with its
    // batch records and render plan: building those twice took a fifth of a `single` fit.
    let single_render;
    let screening = if objective.is_paired() {
        single_render = objective_of(records, options).single_render();
        &single_render
    } else {
        objective
    };
    if objective.pixel_count() == 0 {
        return Err(Error::argument(
            "photos",
            "no pixel enters the loss (all masked, saturated, non-finite or outside the sample)",
        ));
    }
    // A library error (a progress sink's stop) passes through the solver as itself.
    let argmin_failed = |e: ArgminError| {
        e.downcast::<Error>()
            .unwrap_or_else(|e| Error::argument("optimizer", e.to_string()))
    };
    let mut projected_renders = 0;
    let (global, start_method, profile) = match given_start {
        Some(x) => (vec![x], StartMethod::Coarser, None),
        None => match (options.optimizer, options.projection) {
            (Optimizer::Pso, _) => (
                vec![start::swarm_start(screening, options.seed).map_err(argmin_failed)?],
                StartMethod::Pso,
                None,
            ),
            (_, true) => match Projection::new(screening) {
                Some(projection) => {
                    let (xs, profile) =
                        start::projected_starts(&projection).map_err(argmin_failed)?;
                    projected_renders = projection.renders();
                    (xs, StartMethod::Projection, Some(profile))
                }
                None => {
                    let (xs, profile) = start::scan_starts(screening);
                    (xs, StartMethod::Scan, Some(profile))
                }
            },
            (_, false) => {
                let (xs, profile) = start::scan_starts(screening);
                (xs, StartMethod::Scan, Some(profile))
            }
        },
    };
    let x0 = global[0].clone();
    let mut starts: Vec<(Vec<f64>, StartMethod)> =
        global.into_iter().map(|x| (x, start_method)).collect();
    if start_method != StartMethod::Coarser {
        starts.extend(
            start::random_points(&space, options.seed, options.starts.saturating_sub(1))
                .into_iter()
                .map(|x| (x, StartMethod::Random)),
        );
    }
    // Each search counts its iterations on from the last one's, up to max_iters each.
    let recorder = Recorder::new(progress.start(
        &format!("fit {}", space.model),
        options.max_iters * starts.len() as u64,
    ));
    let local = match options.optimizer.local(space.model) {
        LocalOptimizer::Lbfgs
            if options.optimizer == Optimizer::Auto && objective.has_gauss_newton() =>
        {
            LocalOptimizer::LevenbergMarquardt
        }
        local => local,
    };
    let mut iterations = 0;
    let mut results = Vec::new();
    for (x, method) in starts {
        // The objective tracks the best point of each search (line-search probes included).
        *objective.best.lock().expect("no panics") = (f64::INFINITY, Vec::new());
        let (i, termination) = local::search(objective, local, x, options.max_iters, &recorder)
            .map_err(argmin_failed)?;
        let (cost, best_x) = objective.best.lock().expect("no panics").clone();
        results.push((cost, best_x, method, termination));
        iterations += i;
    }
    recorder.finish();
    if objective.is_paired() && results.len() > 1 {
        // Each search minimised the pair loss on the same streams and so also chased their
        // noise; rank the results on fresh streams, which that noise does not follow.
        let judge = Objective::new(space, records, options.loss, options.seed.wrapping_add(1))
            .with_skips(options.skips)
            .with_precision(
                options
                    .precision
                    .unwrap_or(space.model.capabilities().lanes),
            );
        for result in &mut results {
            result.0 = judge.loss(&result.1) / judge.loss_from_cost(1.0);
        }
    }
    results.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (_, best_x, _, termination) = results[0].clone();
    let best_x = space.clamp(&best_x);
    let material = space.material(&best_x);
    let photos = photo_losses(objective, records, &best_x);
    let loss = objective.loss(&best_x);
    let alternatives = alternatives(objective, records, &best_x, loss, &results);
    let mut warnings: Vec<String> = space
        .at_bounds(&best_x)
        .into_iter()
        .map(|name| {
            let (what, (lo, hi)) = match name.strip_prefix("ln_") {
                Some(alpha) if alpha.starts_with("alpha") => (alpha.to_string(), ALPHA_BOUNDS),
                _ => ("exposure".to_string(), EXPOSURE_BOUNDS),
            };
            format!(
                "{what} stopped at a bound of its range [{lo}, {hi}]: the photos pull it \
                 further, which the model does not explain (a missing diffuse term, \
                 wrong light positions or intensities?)"
            )
        })
        .collect();
    warnings.extend(alternatives.iter().map(Alternative::warning));
    let screened = if std::ptr::eq(screening, objective) {
        0
    } else {
        screening
            .evaluations
            .load(std::sync::atomic::Ordering::Relaxed)
    };
    let evaluations = objective
        .evaluations
        .load(std::sync::atomic::Ordering::Relaxed)
        + screened
        + projected_renders;
    let trace = recorder.trace.lock().expect("no panics").clone();
    let f0 = material.fresnel.f0();
    let starts = if results.len() > 1 {
        results
            .iter()
            .map(|(cost, x, method, _)| StartResult {
                method: *method,
                loss: objective.loss_from_cost(*cost),
                alpha: space.material(x).alpha,
            })
            .collect()
    } else {
        Vec::new()
    };
    let render_plan = objective.plan_summary(&material);
    Ok(ModelFit {
        material,
        f0,
        loss,
        loss_kind: options.loss,
        optimizer: options.optimizer,
        gradient: (local != LocalOptimizer::NelderMead).then(|| objective.gradient_method()),
        iterations,
        evaluations,
        termination,
        seconds: 0.0,
        start_method,
        start: space.material(&x0),
        starts,
        levels: Vec::new(),
        photos,
        trace,
        render_plan,
        exposure: space.exposure.then(|| ExposureEstimate {
            value: space.exposure(&best_x),
            interval: None,
        }),
        correction: None,
        profile: profile.map_or_else(Vec::new, |p| p.table()),
        alternatives,
        warnings,
    })
}

/// Two optima whose roughness differs by less than this (in `ln alpha`, 5%) are one basin.
pub const DISTINCT_LN_ALPHA: f64 = 0.05;

/// An optimum of another basin whose loss is within this factor of the chosen one's is
/// reported: the photos hardly separate the two (on `heitz` flash photos of gold at alpha 0.8,
/// basins at 0.81 and 1.20 ended 2% apart).
pub const AMBIGUOUS_LOSS_RATIO: f64 = 1.05;

/// Photos named as separating two optima.
const SEPARATING_PHOTOS: usize = 3;

/// A local optimum in another basin than the fit's that explains the photos almost as well
/// ([`AMBIGUOUS_LOSS_RATIO`]): the fit may have chosen the wrong one, and the photos that
/// separate them most say which new photo would tell them apart.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Alternative {
    pub alpha: [f64; 2],
    pub f0: [f64; 3],
    pub loss: f64,
    /// This optimum's loss over the fit's.
    pub loss_ratio: f64,
    /// The photos whose losses differ most between the two optima, with this optimum's loss
    /// over the fit's on each.
    pub separating_photos: Vec<(String, f64)>,
    /// The optimum's coordinates in the fit's space: where `--mcmc` approximates this mode.
    #[serde(skip)]
    pub point: Vec<f64>,
}

impl Alternative {
    /// The line a fit prints and writes to its `warnings`.
    pub fn warning(&self) -> String {
        let photos: Vec<String> = self
            .separating_photos
            .iter()
            .map(|(stem, ratio)| format!("{stem} (x{ratio:.2})"))
            .collect();
        format!(
            "another basin explains the photos almost as well: alpha {:.4} with loss x{:.4} of the fit's; \
             the photos that separate them most are {}; a photo lit near the mirror direction of one \
             lobe and not the other would tell them apart",
            self.alpha[0],
            self.loss_ratio,
            photos.join(", ")
        )
    }
}

/// The optima of the local searches `results` (cost, coordinates, ...) in other basins than
/// `best_x` (loss `loss`) within [`AMBIGUOUS_LOSS_RATIO`] of it, one per basin, lowest first.
fn alternatives(
    objective: &Objective,
    records: &ShadingRecords,
    best_x: &[f64],
    loss: f64,
    results: &[(f64, Vec<f64>, StartMethod, String)],
) -> Vec<Alternative> {
    let space = objective.space;
    let ln_alpha = |x: &[f64]| space.clamp(x)[0];
    let mut seen = vec![ln_alpha(best_x)];
    let mut found = Vec::new();
    for (_, x, _, _) in results {
        let x = space.clamp(x);
        if seen
            .iter()
            .any(|&a| (ln_alpha(&x) - a).abs() < DISTINCT_LN_ALPHA)
        {
            continue;
        }
        seen.push(ln_alpha(&x));
        let other = objective.loss(&x);
        if other > AMBIGUOUS_LOSS_RATIO * loss {
            continue;
        }
        let ours = photo_losses(objective, records, best_x);
        let theirs = photo_losses(objective, records, &x);
        let mut ratios: Vec<(String, f64)> = ours
            .iter()
            .zip(&theirs)
            .filter(|(a, _)| a.loss > 0.0)
            .map(|(a, b)| (a.image.clone(), b.loss / a.loss))
            .collect();
        ratios.sort_by(|a, b| b.1.ln().abs().total_cmp(&a.1.ln().abs()));
        ratios.truncate(SEPARATING_PHOTOS);
        let material = space.material(&x);
        found.push(Alternative {
            alpha: material.alpha,
            f0: material.fresnel.f0(),
            loss: other,
            loss_ratio: other / loss,
            separating_photos: ratios,
            point: x,
        });
    }
    found
}

/// The objective `options` minimise over `records`.
fn objective_of<'a>(records: &'a ShadingRecords, options: &FitOptions) -> Objective<'a> {
    Objective::new(options.space, records, options.loss, options.seed)
        .with_gradient(options.gradient)
        .with_skips(options.skips)
        .with_precision(
            options
                .precision
                .unwrap_or(options.space.model.capabilities().lanes),
        )
}

/// Each photo's loss at `x`.
fn photo_losses(objective: &Objective, records: &ShadingRecords, x: &[f64]) -> Vec<PhotoLoss> {
    objective
        .loss_per_photo(x)
        .into_iter()
        .map(|(i, loss, pixels)| PhotoLoss {
            image: records.photos[i].stem.clone(),
            loss,
            pixels,
        })
        .collect()
}

/// A fit measured by the objective it was fitted on ([`measure`]).
pub struct Measured {
    /// The L2 loss (`rss / n` over the loss pixels and channels); for a stochastic model the
    /// pair loss of its two renders, free of the render's variance ([`crate::loss`]).
    pub l2: f64,
    /// The prediction at every pixel of the records, zero at the pixels outside the loss.
    pub prediction: Vec<[f64; 3]>,
}

/// `fit` (of `options`' model, over `records`) measured by its own objective at the fit's
/// seed: what the model selection's BIC reads and what the residual images show.
///
/// A deterministic model is rendered through the objective's render plan, as during the fit:
/// `tabulated`'s multiple-bounce term is interpolated from the anchors. Evaluating it at every
/// sub-sample instead, once for the BIC and once for the residual images, was a fifth of a
/// `tabulated` fit of `datasets/copper-flash`; its mean squared residual moves by 0.13%
/// (1.2306e-4 against 1.2290e-4).
///
/// A stochastic model is rendered at every sub-sample, on the objective's two streams. Its
/// pair residual through the anchors is a noisier estimate: each anchor's few walks are shared
/// by the pixels around it. On `datasets/copper-flash` (`heitz`, seeds 0-3) it read
/// 1.7e-4, 1.7e-4, 0.7e-4 and 1.6e-4 against 1.1e-4, 0.7e-4, 0.9e-4 and 1.1e-4 at every
/// sub-sample, where `tabulated`, which matches `heitz` within 0.5%, reads 1.23e-4.
pub fn measure(records: &ShadingRecords, fit: &ModelFit, options: &FitOptions) -> Measured {
    let objective = objective_of(
        records,
        &FitOptions {
            loss: LossKind::L2,
            ..options.clone()
        },
    );
    let renders = if objective.is_paired() {
        let exposed = fit.exposed(records);
        render_seeds(true, options.seed)
            .into_iter()
            .map(|seed| render_pixels(&fit.material, &exposed, objective.pixels(), seed))
            .collect()
    } else {
        objective.renders(&fit.point(&options.space))
    };
    let mut prediction = vec![[0.0; 3]; records.pixel_count()];
    for (&p, value) in objective.pixels().iter().zip(&renders[0]) {
        prediction[p] = *value;
    }
    Measured {
        l2: objective.image_loss().renders_value(&renders),
        prediction,
    }
}

/// Edge tint of each channel of a conductor fit, for reports (`None` for other Fresnel kinds).
pub fn edge_tint(material: &Material) -> Option<[f64; 3]> {
    match material.fresnel {
        FresnelSpec::Conductor { eta, k } => {
            Some([0, 1, 2].map(|c| reflectivity_edge_tint_from_ior(eta[c], k[c]).1))
        }
        _ => None,
    }
}

/// The model names a fit file may list as candidates.
pub fn model_names(models: &[Model]) -> Vec<&'static str> {
    models.iter().map(|m| m.name()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::point::objective::tests::pinhole_records;
    use crate::microfacet::{Height, NdfKind};

    fn material(alpha: [f64; 2], f0: [f64; 3]) -> Material {
        Material {
            model: Model::Single,
            ndf: NdfKind::Ggx,
            height: Height::Correlated,
            alpha,
            fresnel: FresnelSpec::Schlick { f0 },
            diffuse: [0.0; 3],
        }
    }

    /// Photos of a `single` surface rougher than any fit may return (alpha 6): every
    /// optimiser presses the roughness outward, and every one stops on the bound 3 and says
    /// so. Before the box, Levenberg-Marquardt returned the photos' 6.
    #[test]
    fn a_search_that_presses_past_the_roughness_bound_stops_on_it_and_says_so() {
        let truth = material([6.0; 2], [0.9, 0.7, 0.5]);
        let records = pinhole_records(&truth);
        for optimizer in [Optimizer::Auto, Optimizer::Lbfgs, Optimizer::NelderMead] {
            let options = FitOptions {
                optimizer,
                ..FitOptions::defaults(ParamSpace::plain(Model::Single))
            };
            let fit = fit_point(&records, &options).unwrap().fit;
            for a in fit.material.alpha {
                assert!(
                    a <= ALPHA_BOUNDS.1 && a > ALPHA_BOUNDS.1 * (1.0 - 1e-6),
                    "{optimizer:?}: {a}"
                );
            }
            assert!(
                fit.warnings
                    .iter()
                    .any(|w| w.contains("alpha stopped at a bound")),
                "{optimizer:?}: {:?}",
                fit.warnings
            );
        }
    }

    /// Outside the box the objective is the loss at the projection plus the pull back, with
    /// the pull's gradient and Gauss-Newton term in the coordinates that left the box.
    #[test]
    fn outside_the_box_the_objective_is_the_projection_plus_the_pull() {
        let truth = material([0.4; 2], [0.9, 0.7, 0.5]);
        let records = pinhole_records(&truth);
        let space = ParamSpace::plain(Model::Single);
        let objective = objective_of(&records, &FitOptions::defaults(space));
        let inside = vec![ALPHA_BOUNDS.1.ln(), 0.3, 0.2, 0.1];
        let outside = vec![ALPHA_BOUNDS.1.ln() + 0.7, 0.3, 0.2, 0.1];
        let (c_in, g_in, m_in) = objective.gauss_newton(&inside).unwrap();
        let (c_out, g_out, m_out) = objective.gauss_newton(&outside).unwrap();
        assert!((c_out - (c_in + 0.49)).abs() < 1e-12 * c_out.max(1.0));
        assert!((g_out[0] - 1.4).abs() < 1e-12);
        assert_eq!(&g_out[1..], &g_in[1..]);
        let n = 4;
        assert_eq!(m_out[0], 2.0);
        for j in 1..n {
            assert_eq!((m_out[j], m_out[j * n]), (0.0, 0.0));
            for i in 1..n {
                assert_eq!(m_out[i * n + j], m_in[i * n + j]);
            }
        }
        assert_eq!(space.material(&outside).alpha, [ALPHA_BOUNDS.1; 2]);
        assert_eq!(space.at_bounds(&outside), vec!["ln_alpha".to_string()]);
        assert!(space.at_bounds(&[0.0, 0.3, 0.2, 0.1]).is_empty());
    }
}
