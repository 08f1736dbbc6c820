//! Fitting material parameters to a photo set: start, optimise, report.
//!
//! 1. Start: a coarse scan of roughness (log-spaced, isotropic) with a white Fresnel whose
//!    per-channel scale is solved in closed form; the best scan point gives alpha and F0.
//! 2. Optimise all free coordinates of the [`ParamSpace`] with argmin: Nelder-Mead, or L-BFGS
//!    (More-Thuente line search) on central finite-difference gradients.
//! 3. Report: the material, loss, per-photo losses, the optimiser trace, evaluation counts and
//!    timings, in the fit file format of DESIGN.md.

pub mod holdout;
pub mod objective;
pub mod params;
pub mod selection;

use crate::bsdf::Model;
use crate::error::{Error, Result};
use crate::loss::LossKind;
use crate::material::{FresnelSpec, Material};
use crate::microfacet::fresnel::reflectivity_edge_tint_from_ior;
use crate::progress::Progress;
use crate::render::render_pixels;
use crate::shading::ShadingRecords;
use argmin::core::observers::{Observe, ObserverMode};
use argmin::core::{Error as ArgminError, Executor, State, KV};
use argmin::solver::linesearch::MoreThuenteLineSearch;
use argmin::solver::neldermead::NelderMead;
use argmin::solver::quasinewton::LBFGS;
use objective::Objective;
use params::{FresnelFamily, ParamSpace};
use serde::{Deserialize, Serialize};
use std::sync::{Arc, Mutex};
use std::time::Instant;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Optimizer {
    NelderMead,
    #[default]
    Lbfgs,
}

/// Everything a fit needs besides the photos.
#[derive(Clone, Debug)]
pub struct FitOptions {
    pub space: ParamSpace,
    pub optimizer: Optimizer,
    pub loss: LossKind,
    pub max_iters: u64,
    pub seed: u64,
    /// Show a progress bar (or plain progress lines when stderr is not a terminal).
    pub progress: bool,
}

/// One point of the optimiser trace.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TracePoint {
    pub iteration: u64,
    pub evaluations: usize,
    pub loss: f64,
}

/// The loss of one photo at the fitted parameters.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PhotoLoss {
    pub image: String,
    pub loss: f64,
    pub pixels: usize,
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
    pub iterations: u64,
    pub evaluations: usize,
    pub termination: String,
    pub seconds: f64,
    pub start: Material,
    pub photos: Vec<PhotoLoss>,
    pub trace: Vec<TracePoint>,
}

/// At most this many L-BFGS rounds, each restarted with empty memory from the best point.
const LBFGS_ROUNDS: usize = 4;

/// Roughness values of the coarse start scan: a geometric grid (ratio 1.8) from 0.012 to 2.4
/// that avoids round values, so fits of synthetic sets made at round roughness exercise the
/// optimiser rather than land on a scan node.
const SCAN_ALPHAS: [f64; 10] = [
    0.012, 0.0216, 0.0389, 0.07, 0.126, 0.227, 0.408, 0.735, 1.32, 2.38,
];

/// Start edge tint of conductor fits (Gulbrandsen's g): measured metals lie between 0.85 and
/// 0.99 (Cu, Au, Ag, Al at 450-650 nm), and for F0 above ~0.9 photos constrain g only weakly, so
/// the start is where an unconstrained g should stay.
const START_EDGE_TINT: f64 = 0.9;

/// Start point: the scan alpha whose white-Fresnel prediction, scaled per channel by the
/// least-squares factor `sum p t / sum p^2`, has the lowest squared error.
fn start_material(space: &ParamSpace, records: &ShadingRecords, seed: u64) -> Material {
    let pixels: Vec<usize> = (0..records.pixel_count())
        .filter(|&p| records.weight[p] > 0.0)
        .collect();
    let mut best: Option<(f64, f64, [f64; 3])> = None;
    for alpha in SCAN_ALPHAS {
        let probe = Material {
            model: space.model,
            ndf: space.ndf,
            height: space.height,
            alpha: [alpha; 2],
            fresnel: FresnelSpec::White,
            diffuse: [0.0; 3],
        };
        let predicted = render_pixels(&probe, records, &pixels, seed);
        let mut err = 0.0;
        let mut scale = [0.0; 3];
        for c in 0..3 {
            let (mut pt, mut pp, mut tt) = (0.0, 0.0, 0.0);
            for (k, &p) in pixels.iter().enumerate() {
                let (w, t, q) = (records.weight[p], records.target[p][c], predicted[k][c]);
                pt += w * q * t;
                pp += w * q * q;
                tt += w * t * t;
            }
            scale[c] = if pp > 0.0 { pt / pp } else { 0.0 };
            err += tt - scale[c] * pt;
        }
        if best.is_none_or(|b| err < b.0) {
            best = Some((err, alpha, scale));
        }
    }
    let (_, alpha, scale) = best.expect("the scan has points");
    let f0 = scale.map(|s| s.clamp(0.02, 0.98));
    let fresnel = match space.fresnel {
        FresnelFamily::Schlick => FresnelSpec::Schlick { f0 },
        FresnelFamily::Conductor => {
            let ior = f0.map(|r| {
                crate::microfacet::fresnel::ior_from_reflectivity_edge_tint(r, START_EDGE_TINT)
            });
            FresnelSpec::Conductor {
                eta: ior.map(|p| p.0),
                k: ior.map(|p| p.1),
            }
        }
    };
    let diffuse = if space.diffuse { [0.02; 3] } else { [0.0; 3] };
    Material {
        model: space.model,
        ndf: space.ndf,
        height: space.height,
        alpha: [alpha; 2],
        fresnel,
        diffuse,
    }
}

/// Observer that records the trace and drives the progress display.
struct TraceObserver {
    trace: Arc<Mutex<Vec<TracePoint>>>,
    evaluations: Arc<std::sync::atomic::AtomicUsize>,
    progress: Option<Progress>,
    scale: f64,
}

impl<I: State<Float = f64>> Observe<I> for TraceObserver {
    fn observe_iter(&mut self, state: &I, _kv: &KV) -> std::result::Result<(), ArgminError> {
        let loss = state.get_best_cost() * self.scale;
        // argmin's own cost_count is not yet updated when observers run (it read 0): count
        // the objective's evaluations (line-search probes and gradient differences included).
        let evaluations = self.evaluations.load(std::sync::atomic::Ordering::Relaxed);
        self.trace
            .lock()
            .expect("no panics while holding the lock")
            .push(TracePoint {
                iteration: state.get_iter(),
                evaluations,
                loss,
            });
        if let Some(p) = &mut self.progress {
            p.update(state.get_iter(), || format!("loss {loss:.4e}"));
        }
        Ok(())
    }
}

/// Fit one model (the one in `options.space`) to the records.
pub fn fit_model(records: &ShadingRecords, options: &FitOptions) -> Result<ModelFit> {
    let started = Instant::now();
    let space = options.space;
    let objective = Objective::new(space, records, options.loss, options.seed);
    if objective.pixel_count() == 0 {
        return Err(Error::argument(
            "photos",
            "no pixel enters the loss (all masked, saturated, non-finite or outside the sample)",
        ));
    }
    let start = start_material(&space, records, options.seed);
    let x0 = space.point(&start);
    let scale = objective.loss_from_cost(1.0);
    let trace = Arc::new(Mutex::new(Vec::new()));
    let observer = TraceObserver {
        trace: trace.clone(),
        evaluations: objective.evaluations.clone(),
        progress: options
            .progress
            .then(|| Progress::new(&format!("fit {}", space.model), options.max_iters)),
        scale,
    };
    let argmin_failed = |e: ArgminError| Error::argument("optimizer", e.to_string());
    let (iterations, termination) = match options.optimizer {
        Optimizer::NelderMead => {
            let mut simplex = vec![x0.clone()];
            for i in 0..x0.len() {
                let mut v = x0.clone();
                v[i] += 0.25;
                simplex.push(v);
            }
            let solver = NelderMead::new(simplex)
                .with_sd_tolerance(1e-12)
                .map_err(argmin_failed)?;
            let res = Executor::new(&objective, solver)
                .configure(|s| s.max_iters(options.max_iters))
                .add_observer(observer, ObserverMode::Always)
                .run()
                .map_err(argmin_failed)?;
            (
                res.state.get_iter(),
                res.state.get_termination_status().to_string(),
            )
        }
        Optimizer::Lbfgs => {
            // L-BFGS does not check its curvature pairs: after crossing the many per-pixel kinks
            // of a robust loss its memory can point nowhere useful, the line search returns a
            // zero step and argmin reports convergence with a non-zero gradient (the log-L1 fit
            // of copper-flash stopped with red F0 at 0.982 instead of 0.935). Restart with empty
            // memory from the best point while a restart still lowers the cost.
            let mut observer = Some(observer);
            let (mut iterations, mut termination) = (0, String::new());
            for round in 0..LBFGS_ROUNDS {
                let (before, start) = {
                    let best = objective
                        .best
                        .lock()
                        .expect("no panics while holding the lock");
                    (
                        best.0,
                        if round == 0 {
                            x0.clone()
                        } else {
                            best.1.clone()
                        },
                    )
                };
                let linesearch = MoreThuenteLineSearch::new();
                let solver = LBFGS::new(linesearch, 8)
                    .with_tolerance_grad(1e-9)
                    .map_err(argmin_failed)?
                    .with_tolerance_cost(1e-13)
                    .map_err(argmin_failed)?;
                let budget = options.max_iters.saturating_sub(iterations).max(1);
                let executor = Executor::new(&objective, solver)
                    .configure(|s| s.param(start).max_iters(budget));
                let executor = match observer.take() {
                    Some(o) => executor.add_observer(o, ObserverMode::Always),
                    None => executor,
                };
                let res = executor.run().map_err(argmin_failed)?;
                iterations += res.state.get_iter();
                termination = format!(
                    "{} (round {})",
                    res.state.get_termination_status(),
                    round + 1
                );
                let after = objective
                    .best
                    .lock()
                    .expect("no panics while holding the lock")
                    .0;
                if (round > 0 && before - after <= 1e-10 * before.abs())
                    || iterations >= options.max_iters
                {
                    break;
                }
            }
            (iterations, termination)
        }
    };
    // The best point ever evaluated (line-search probes included) is the answer.
    let (_, best_x) = objective
        .best
        .lock()
        .expect("no panics while holding the lock")
        .clone();
    let material = space.material(&best_x);
    let photos = objective
        .loss_per_photo(&best_x)
        .into_iter()
        .map(|(i, loss, pixels)| PhotoLoss {
            image: records.photos[i].stem.clone(),
            loss,
            pixels,
        })
        .collect();
    let loss = objective.loss(&best_x);
    let evaluations = objective
        .evaluations
        .load(std::sync::atomic::Ordering::Relaxed);
    let trace = trace
        .lock()
        .expect("no panics while holding the lock")
        .clone();
    let f0 = material.fresnel.f0();
    Ok(ModelFit {
        material,
        f0,
        loss,
        loss_kind: options.loss,
        optimizer: options.optimizer,
        iterations,
        evaluations,
        termination,
        seconds: started.elapsed().as_secs_f64(),
        start,
        photos,
        trace,
    })
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
