//! The local phase of a fit: argmin's Nelder-Mead, or L-BFGS with the More-Thuente line search,
//! from a start point over all free coordinates, recording the trace and driving the progress
//! display.
//!
//! | optimiser | settings | why |
//! | --- | --- | --- |
//! | Nelder-Mead | simplex of steps 0.25 in every coordinate, sd tolerance 1e-12 | no gradients: the default for `heitz` (explicit-height walks have no pathwise derivative here) |
//! | L-BFGS | memory 8, gradient tolerance 1e-9, cost tolerance 1e-13, up to [`LBFGS_ROUNDS`] rounds restarted from the best point | smooth objectives with exact or common-random-number gradients |

use super::objective::Objective;
use crate::progress::Progress;
use argmin::core::observers::{Observe, ObserverMode};
use argmin::core::{Error as ArgminError, Executor, State, KV};
use argmin::solver::linesearch::MoreThuenteLineSearch;
use argmin::solver::neldermead::NelderMead;
use argmin::solver::quasinewton::LBFGS;
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

/// At most this many L-BFGS rounds, each restarted with empty memory from the best point.
const LBFGS_ROUNDS: usize = 4;

/// One point of the optimiser trace.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TracePoint {
    /// Iterations of local search so far (over all starts of this fit).
    pub iteration: u64,
    /// Objective evaluations so far.
    pub evaluations: usize,
    /// Best loss so far.
    pub loss: f64,
}

/// The local optimisers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LocalOptimizer {
    NelderMead,
    Lbfgs,
}

/// Shared record of a fit's local searches: the trace and the progress display.
#[derive(Clone)]
pub struct Recorder {
    pub trace: Arc<Mutex<Vec<TracePoint>>>,
    progress: Option<Arc<Mutex<Progress>>>,
    /// Iterations of the searches that already finished.
    offset: Arc<Mutex<u64>>,
}

impl Recorder {
    pub fn new(progress: Option<Progress>) -> Self {
        Recorder {
            trace: Arc::default(),
            progress: progress.map(|p| Arc::new(Mutex::new(p))),
            offset: Arc::default(),
        }
    }

    pub fn finish(&self) {
        if let Some(p) = &self.progress {
            p.lock().expect("no panics while holding the lock").finish();
        }
    }
}

/// The observer of one search run: records into a [`Recorder`].
struct RunObserver {
    recorder: Recorder,
    evaluations: Arc<AtomicUsize>,
    scale: f64,
}

impl<I: State<Float = f64>> Observe<I> for RunObserver {
    fn observe_iter(&mut self, state: &I, _kv: &KV) -> Result<(), ArgminError> {
        let loss = state.get_best_cost() * self.scale;
        let iteration = *self.recorder.offset.lock().expect("no panics") + state.get_iter();
        self.recorder
            .trace
            .lock()
            .expect("no panics while holding the lock")
            .push(TracePoint {
                iteration,
                evaluations: self.evaluations.load(Ordering::Relaxed),
                loss,
            });
        if let Some(p) = &self.recorder.progress {
            p.lock()
                .expect("no panics while holding the lock")
                .update(iteration, || format!("loss {loss:.4e}"));
        }
        Ok(())
    }
}

/// The start simplex of Nelder-Mead at `x`: `x` and a step of 0.25 along each coordinate
/// (a 28% change of alpha, a logit step of F0).
pub fn simplex_around(x: &[f64]) -> Vec<Vec<f64>> {
    let mut simplex = vec![x.to_vec()];
    for i in 0..x.len() {
        let mut v = x.to_vec();
        v[i] += 0.25;
        simplex.push(v);
    }
    simplex
}

/// Run `optimizer` from `x0` for at most `max_iters` iterations; returns (iterations,
/// termination). The answer is the objective's best point (line-search probes included).
pub fn search(
    objective: &Objective,
    optimizer: LocalOptimizer,
    x0: Vec<f64>,
    max_iters: u64,
    recorder: &Recorder,
) -> Result<(u64, String), ArgminError> {
    let observer = || RunObserver {
        recorder: recorder.clone(),
        evaluations: objective.evaluations.clone(),
        scale: objective.loss_from_cost(1.0),
    };
    let (iterations, termination) = match optimizer {
        LocalOptimizer::NelderMead => {
            let solver = NelderMead::new(simplex_around(&x0)).with_sd_tolerance(1e-12)?;
            let res = Executor::new(objective, solver)
                .configure(|s| s.max_iters(max_iters))
                .add_observer(observer(), ObserverMode::Always)
                .run()?;
            *recorder.offset.lock().expect("no panics") += res.state.get_iter();
            (
                res.state.get_iter(),
                res.state.get_termination_status().to_string(),
            )
        }
        LocalOptimizer::Lbfgs => {
            // L-BFGS does not check its curvature pairs: after crossing the many per-pixel kinks
            // of a robust loss its memory can point nowhere useful, the line search returns a
            // zero step and argmin reports convergence with a non-zero gradient (the log-L1 fit
            // of copper-flash stopped with red F0 at 0.982 instead of 0.935). Restart with empty
            // memory from the best point while a restart still lowers the cost.
            let (mut iterations, mut termination) = (0, String::new());
            for round in 0..LBFGS_ROUNDS {
                let (before, start) = {
                    let best = objective.best.lock().expect("no panics");
                    let start = if round == 0 {
                        x0.clone()
                    } else {
                        best.1.clone()
                    };
                    (best.0, start)
                };
                let solver = LBFGS::new(MoreThuenteLineSearch::new(), 8)
                    .with_tolerance_grad(1e-9)?
                    .with_tolerance_cost(1e-13)?;
                let budget = max_iters.saturating_sub(iterations).max(1);
                let res = Executor::new(objective, solver)
                    .configure(|s| s.param(start).max_iters(budget))
                    .add_observer(observer(), ObserverMode::Always)
                    .run()?;
                iterations += res.state.get_iter();
                *recorder.offset.lock().expect("no panics") += res.state.get_iter();
                termination = format!(
                    "{} (round {})",
                    res.state.get_termination_status(),
                    round + 1
                );
                let after = objective.best.lock().expect("no panics").0;
                if (round > 0 && before - after <= 1e-10 * before.abs()) || iterations >= max_iters
                {
                    break;
                }
            }
            (iterations, termination)
        }
    };
    Ok((iterations, termination))
}
