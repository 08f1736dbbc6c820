//! `fit --mcmc`: the Bayesian posterior over material parameters and model choice, from MAP
//! starts to summarised draws, with resumable checkpoints.
//!
//! 1. Likelihood data: the records, optionally cut to a seeded random subset of pixels
//!    ([`log_posterior::pixel_subset`]; `--mcmc-pixels`).
//! 2. MAP start: [`fit_point`] (with the exposure's interval, [`with_interval`]) for every candidate on those records; the noise level is given
//!    or estimated from the lowest MAP loss (one level for all candidates).
//! 3. Laplace approximation of each candidate's log posterior at its MAP ([`Laplace`]), and at
//!    every other basin the MAP fit reports as almost as good (its `alternatives`): the modes
//!    the chains jump between.
//! 4. Chains: `chains` product-space chains ([`sampler`]), chain `c` starting in candidate
//!    `c mod candidates`, in its mode `(c / candidates) mod modes`, at a draw from that mode's
//!    Laplace approximation with doubled spread ([`START_DISPERSION`]), `warmup` adaptive
//!    iterations then `samples` kept ones.
//! 5. Summary: the [`Posterior`] object, with both the visit frequencies of the models (and of
//!    the modes) and the Laplace-evidence probabilities.
//!
//! | option | default (CLI) | effect |
//! | --- | --- | --- |
//! | `chains` | 4 | independent chains, run in parallel |
//! | `warmup` | 200 | iterations adapting the step size, discarded |
//! | `samples` | 500 | kept iterations per chain |
//! | `noise_sigma` | estimated | noise level of the likelihood ([`Noise`]) |
//! | `pixels` | 4096 | pixels in the likelihood (0: all) |
//! | `checkpoint` | `<fit file>.mcmc-checkpoint.json` | written atomically every [`CHECKPOINT_SECONDS`] and when stopped |
//! | `resume` | off | continue from the checkpoint: the same draws as an uninterrupted run |
//!
//! The checkpoint holds the MAP fits, the noise level, the Laplace approximations and every
//! chain's state (the sampler's random streams are counter-based, so there is no generator state
//! to save), plus a fingerprint of the candidates, options and likelihood data; resuming with a
//! different fingerprint is refused. Floats survive the JSON round trip exactly (serde_json's
//! `float_roundtrip`).

use super::adjustment::Adjustment;
use super::discrepancy;
use super::exposure::with_interval;
use super::laplace::Laplace;
use super::log_posterior::{self, LogPosterior, Noise, Reading};
use super::model_error::{self, ModelError};
use super::posterior::{
    candidate_label, summarise, DiscrepancyScales, ModelErrorSummary, Posterior, RunFacts,
};
use super::sampler::{self, Candidate, ChainState, Schedule};
use super::target::Target;
use crate::error::{Error, Result};
use crate::fit::point::params::ParamSpace;
use crate::fit::point::{fit_point, FitOptions, ModelFit, Optimizer, DISTINCT_LN_ALPHA};
use crate::shading::ShadingRecords;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;
use std::time::Instant;

/// Standard deviation of the chains' starts relative to the Laplace approximation.
pub const START_DISPERSION: f64 = 2.0;

/// Seconds between checkpoint writes.
pub const CHECKPOINT_SECONDS: f64 = 5.0;

/// Name of the sampler in the posterior object.
pub const SAMPLER: &str = "preconditioned MALA + Laplace-matched between-model jumps";

/// Everything `--mcmc` needs besides the records and the candidates.
#[derive(Clone, Debug)]
pub struct McmcOptions {
    /// How the MAP starts are fitted (its `space` is replaced by each candidate's); its loss is
    /// the likelihood's and its `progress` the sampler's.
    pub map: FitOptions,
    pub schedule: Schedule,
    pub noise_sigma: Option<f64>,
    /// Pixels in the likelihood (0: all).
    pub pixels: usize,
    /// How intervals account for model error ([`model_error`]).
    pub model_error: ModelError,
    /// The least scale of the discrepancy term (`--discrepancy-floor`; default
    /// [`discrepancy::SMALLEST_SCALE`]).
    pub discrepancy_floor: Option<f64>,
    pub checkpoint: Option<PathBuf>,
    pub resume: bool,
    /// Stop (and checkpoint) after this many iterations per chain: for testing resumption.
    pub stop_after: Option<u64>,
    /// Per candidate, coordinates of other basins to approximate as modes besides those its MAP
    /// fit finds (the `alternatives` of a fit on every pixel when the likelihood has a subset).
    pub mode_starts: Vec<Vec<Vec<f64>>>,
}

/// A finished run: the posterior and the MAP fits it started from.
pub struct PosteriorRun {
    pub posterior: Posterior,
    /// MAP fit of each candidate on the likelihood's pixels.
    pub maps: Vec<ModelFit>,
    /// Index of the candidate with the most draws.
    pub most_probable: usize,
    /// Whether the likelihood used every loss pixel (then `maps` are the full-data fits).
    pub all_pixels: bool,
}

/// What the chains start from; computed once and kept in the checkpoint.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct Setup {
    maps: Vec<ModelFit>,
    noise: Noise,
    /// Laplace approximations of each candidate at its modes, the MAP's first.
    modes: Vec<Vec<Laplace>>,
    /// Model-error adjustment of each candidate's likelihood.
    adjustments: Vec<Option<Adjustment>>,
    map_seconds: f64,
}

#[derive(Serialize, Deserialize)]
struct Checkpoint {
    fingerprint: String,
    setup: Setup,
    chains: Vec<ChainState>,
    /// Sampling seconds spent before this checkpoint.
    seconds: f64,
}

/// FNV-1a over the likelihood data and the options that shape the run.
fn fingerprint(
    records: &ShadingRecords,
    candidates: &[ParamSpace],
    options: &McmcOptions,
) -> String {
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |bits: u64| {
        for byte in bits.to_le_bytes() {
            hash = (hash ^ byte as u64).wrapping_mul(0x0100_0000_01b3);
        }
    };
    for (t, w) in records.target.iter().zip(&records.weight) {
        t.iter().for_each(|v| eat(v.to_bits()));
        eat(w.to_bits());
    }
    for s in &records.irradiance {
        s.iter().for_each(|v| eat(v.to_bits()));
    }
    let map = &options.map;
    format!(
        "{hash:016x} {candidates:?} {:?} {:?} {} {} {} {} {:?} {:?} {} {:?} {:?}",
        map.loss,
        map.optimizer,
        map.max_iters,
        map.starts,
        map.projection,
        map.pyramid,
        options.schedule,
        options.noise_sigma,
        options.pixels,
        options.model_error,
        options.discrepancy_floor
    )
}

fn validate(candidates: &[ParamSpace], options: &McmcOptions) -> Result<()> {
    let first = candidates
        .first()
        .ok_or_else(|| Error::argument("--models", "no candidate model"))?;
    if candidates
        .iter()
        .any(|c| c.anisotropic != first.anisotropic || c.fresnel != first.fresnel)
    {
        return Err(Error::argument(
            "--models",
            "MCMC candidates must share the roughness and Fresnel parameters",
        ));
    }
    if options.schedule.chains == 0 {
        return Err(Error::argument("--chains", "must be at least 1"));
    }
    if options.schedule.samples < 8 {
        // Split chains need 4 draws per half for the ESS.
        return Err(Error::argument("--mcmc-samples", "must be at least 8"));
    }
    if let Some(s) = options.noise_sigma {
        if !(s.is_finite() && s > 0.0) {
            return Err(Error::argument(
                "--noise-sigma",
                format!("must be a finite number > 0, got {s}"),
            ));
        }
    }
    if let Some(floor) = options.discrepancy_floor {
        if options.model_error != ModelError::Discrepancy {
            return Err(Error::argument(
                "--discrepancy-floor",
                "applies only with --model-error discrepancy",
            ));
        }
        if !(discrepancy::SMALLEST_SCALE..discrepancy::LARGEST_SCALE).contains(&floor) {
            return Err(Error::argument(
                "--discrepancy-floor",
                format!(
                    "must be in [{}, {}), got {floor}",
                    discrepancy::SMALLEST_SCALE,
                    discrepancy::LARGEST_SCALE
                ),
            ));
        }
    }
    if Reading::of(options.map.loss).is_none() {
        return Err(Error::argument(
            "--loss",
            "ssim is not the likelihood of any noise; use l2, relative-l2 or log-l1 with --mcmc",
        ));
    }
    if options.resume && options.checkpoint.is_none() {
        return Err(Error::argument("--resume", "needs a checkpoint file"));
    }
    Ok(())
}

fn load_checkpoint(path: &PathBuf, fingerprint: &str) -> Result<Checkpoint> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let checkpoint: Checkpoint = serde_json::from_str(&text)
        .map_err(|e| Error::invalid(path, "checkpoint", e.to_string()))?;
    if checkpoint.fingerprint != fingerprint {
        return Err(Error::invalid(
            path,
            "fingerprint",
            "the checkpoint belongs to another photo set, candidate list or MCMC options",
        ));
    }
    Ok(checkpoint)
}

fn save_checkpoint(path: &PathBuf, checkpoint: &Checkpoint) -> Result<()> {
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
    }
    crate::capture::atomic_file::write_atomically(path, |w| {
        serde_json::to_writer(&mut *w, checkpoint).map_err(|e| Error::io(path, e))
    })
}

/// MAP fits, noise level and Laplace approximations of the candidates.
fn prepare(
    records: &ShadingRecords,
    candidates: &[ParamSpace],
    options: &McmcOptions,
) -> Result<Setup> {
    let started = Instant::now();
    let maps = candidates
        .iter()
        .map(|&space| {
            // The chains need a MAP inside the coordinates' range. Levenberg-Marquardt, the
            // point fit's default for deterministic models, minimises exactly along directions
            // the photos hardly see: on Mitsuba's render of aluminium-pinhole (conductor,
            // uncorrelated heights) it took the edge tints to 5e-5, their sigmoid's flat
            // bound, for a loss 7e-5 lower, and the chains then did not mix (alpha's
            // effective sample size 7.9, R-hat 1.50, against 647 and 1.004 from L-BFGS's
            // MAP, which stays near the start's 0.9). So the MAP keeps L-BFGS there.
            let optimizer = match options.map.optimizer {
                Optimizer::Auto if space.model.capabilities().generic => Optimizer::Lbfgs,
                chosen => chosen,
            };
            let map = FitOptions {
                space,
                optimizer,
                ..options.map.clone()
            };
            Ok(with_interval(fit_point(records, &map)?, records, &map))
        })
        .collect::<Result<Vec<_>>>()?;
    let map_seconds = started.elapsed().as_secs_f64();
    let reading = Reading::of(options.map.loss).expect("validated");
    let noise = match options.noise_sigma {
        Some(sigma) => Noise {
            reading,
            sigma,
            estimated: false,
        },
        None => Noise::estimate(
            reading,
            options.map.loss,
            maps.iter().map(|m| m.loss).fold(f64::INFINITY, f64::min),
            log_posterior::rms_target(records),
        ),
    };
    let target = |space: ParamSpace, adjustment: Option<Adjustment>| {
        LogPosterior::new(
            space,
            records,
            options.map.loss,
            options.schedule.seed,
            noise,
        )
        .with_adjustment(adjustment)
    };
    // Each basin the MAP fit found as almost as good is a mode, unless its approximation's
    // mean falls in a basin already held.
    let at_modes = |target: &LogPosterior, starts: &[Vec<f64>]| {
        let mut modes: Vec<Laplace> = Vec::new();
        for start in starts {
            let mode = Laplace::at_mode(target, start);
            if modes
                .iter()
                .all(|m| (m.mean[0] - mode.mean[0]).abs() >= DISTINCT_LN_ALPHA)
            {
                modes.push(mode);
            }
        }
        modes
    };
    let starts: Vec<Vec<Vec<f64>>> = candidates
        .iter()
        .zip(&maps)
        .enumerate()
        .map(|(index, (space, map))| {
            let given = options.mode_starts.get(index).into_iter().flatten();
            std::iter::once(map.point(space))
                .chain(map.alternatives.iter().map(|a| a.point.clone()))
                .chain(given.cloned())
                .filter(|x| x.len() == space.dim())
                .collect()
        })
        .collect();
    let mut modes: Vec<Vec<Laplace>> = candidates
        .iter()
        .zip(&starts)
        .map(|(&space, starts)| at_modes(&target(space, None), starts))
        .collect();
    let discrepancy_floor = (options.model_error == ModelError::Discrepancy).then(|| {
        options
            .discrepancy_floor
            .unwrap_or(discrepancy::SMALLEST_SCALE)
    });
    let adjustments: Vec<Option<Adjustment>> = match options.model_error {
        ModelError::None => vec![None; candidates.len()],
        ModelError::Photos | ModelError::Discrepancy => candidates
            .iter()
            .zip(&modes)
            .map(|(&space, m)| model_error::adjust(&target(space, None), &m[0], discrepancy_floor))
            .collect(),
    };
    for ((m, &space), adjustment) in modes.iter_mut().zip(candidates).zip(&adjustments) {
        if adjustment.is_some() {
            let means: Vec<Vec<f64>> = m.iter().map(|l| l.mean.clone()).collect();
            *m = at_modes(&target(space, adjustment.clone()), &means);
        }
    }
    Ok(Setup {
        maps,
        noise,
        modes,
        adjustments,
        map_seconds,
    })
}

/// Sample the posterior over `candidates` given `records`; `None` when stopped early by
/// `stop_after` (the checkpoint then holds the state).
pub fn sample_posterior(
    records: &ShadingRecords,
    candidates: &[ParamSpace],
    options: &McmcOptions,
) -> Result<Option<PosteriorRun>> {
    validate(candidates, options)?;
    let schedule = options.schedule;
    let data = log_posterior::pixel_subset(records, options.pixels, schedule.seed);
    let pixels = data.weight.iter().filter(|w| **w > 0.0).count();
    if pixels == 0 {
        return Err(Error::argument("photos", "no pixel enters the likelihood"));
    }
    let all_pixels = pixels == records.weight.iter().filter(|w| **w > 0.0).count();
    let fingerprint = fingerprint(&data, candidates, options);
    let resumed = match (&options.checkpoint, options.resume) {
        (Some(path), true) => Some(load_checkpoint(path, &fingerprint)?),
        _ => None,
    };
    let (setup, states, spent) = match resumed {
        Some(c) => (c.setup, Some(c.chains), c.seconds),
        None => (prepare(&data, candidates, options)?, None, 0.0),
    };
    let started = Instant::now();
    let targets: Vec<LogPosterior> = candidates
        .iter()
        .zip(&setup.adjustments)
        .map(|(&space, adjustment)| {
            LogPosterior::new(space, &data, options.map.loss, schedule.seed, setup.noise)
                .with_adjustment(adjustment.clone())
        })
        .collect();
    let chain_candidates: Vec<Candidate> = targets
        .iter()
        .zip(&setup.modes)
        .map(|(target, modes)| Candidate {
            target: target as &dyn Target,
            modes: modes.clone(),
        })
        .collect();
    let mut states = states.unwrap_or_else(|| {
        (0..schedule.chains)
            .map(|c| sampler::start(&chain_candidates, c, schedule.seed, START_DISPERSION))
            .collect()
    });
    let checkpoint = |states: &[ChainState], elapsed: f64| -> Result<()> {
        match &options.checkpoint {
            Some(path) => save_checkpoint(
                path,
                &Checkpoint {
                    fingerprint: fingerprint.clone(),
                    setup: setup.clone(),
                    chains: states.to_vec(),
                    seconds: spent + elapsed,
                },
            ),
            None => Ok(()),
        }
    };
    let mut progress = options.map.progress.start("mcmc", schedule.total());
    let mut last_write = Instant::now();
    let mut write_error = None;
    let mut stop = None;
    sampler::run(
        &chain_candidates,
        &mut states,
        &schedule,
        options.stop_after.unwrap_or(u64::MAX),
        |states| {
            let rate = || {
                let mean = states.iter().map(|s| s.step[s.model]).sum::<f64>();
                format!("mean step {:.3}", mean / states.len() as f64)
            };
            if let Err(e) = progress.step(states[0].iterations, rate) {
                stop = Some(e);
                return false;
            }
            if last_write.elapsed().as_secs_f64() >= CHECKPOINT_SECONDS {
                last_write = Instant::now();
                if let Err(e) = checkpoint(states, started.elapsed().as_secs_f64()) {
                    write_error = Some(e);
                    return false;
                }
            }
            true
        },
    );
    progress.finish();
    if let Some(e) = write_error {
        return Err(e);
    }
    // Stopped by the progress sink: the checkpoint keeps the chains for `--resume`.
    if let Some(e) = stop {
        checkpoint(&states, started.elapsed().as_secs_f64())?;
        return Err(e);
    }
    let seconds = spent + started.elapsed().as_secs_f64();
    if states.iter().any(|s| s.iterations < schedule.total()) {
        checkpoint(&states, started.elapsed().as_secs_f64())?;
        return Ok(None);
    }
    let posterior = summarise(
        candidates,
        &states,
        RunFacts {
            sampler: SAMPLER,
            warmup: schedule.warmup,
            kept: schedule.samples,
            noise: setup.noise,
            model_error: candidates
                .iter()
                .zip(&setup.adjustments)
                .enumerate()
                .filter_map(|(index, (space, adjustment))| {
                    let a = adjustment.as_ref()?;
                    Some((
                        candidate_label(candidates, index),
                        ModelErrorSummary {
                            method: a.method().to_string(),
                            photos: a.photos,
                            widening: space.names().into_iter().zip(a.widening.clone()).collect(),
                            discrepancy: a.discrepancy.map(|[likely, rms]| DiscrepancyScales {
                                photo: likely[0],
                                lobe: likely[1],
                                photo_rms: rms[0],
                                lobe_rms: rms[1],
                            }),
                        },
                    ))
                })
                .collect(),
            pixels,
            modes: setup.modes.clone(),
            map_seconds: setup.map_seconds,
            seconds,
        },
    );
    let mut visits = vec![0usize; candidates.len()];
    for draw in states.iter().flat_map(|s| &s.draws) {
        visits[draw.model] += 1;
    }
    let most_probable = (0..candidates.len())
        .max_by_key(|&i| visits[i])
        .expect("at least one candidate");
    Ok(Some(PosteriorRun {
        posterior,
        maps: setup.maps,
        most_probable,
        all_pixels,
    }))
}
