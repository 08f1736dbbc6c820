//! Fits of the stochastic models that claim `heitz`'s value (`heitz`, `bitterli`, `cui`) by
//! defect correction on the deterministic `tabulated` model (issue #16 item 2): the models whose
//! row names that surrogate ([`crate::bsdf::registry::Capabilities::surrogate`]).
//!
//! **Why.** Fitted directly, a stochastic model's objective is a random function: the pair
//! loss is unbiased in value at every point, but its minimiser is not. Measured on nine 32x32
//! flash photos rendered by `heitz` (64 walks per pixel, white Fresnel known, alpha 0.9):
//! `bitterli` fitted with one walk per sub-sample and no anchors came out at alpha 0.81 on
//! average over 8 seeds (0.76 to 0.95); L-BFGS, central differences and Nelder-Mead all came out
//! low (means 0.81-0.84), so it is the objective, not the optimiser; the anchors of
//! `sparse-multi`, which stand for 64 pixels on one pixel's walks, took it to 0.55-0.69.
//!
//! **How** (the defect correction principle, Stetter 1978, "The defect correction principle and
//! discretization methods", Numer. Math. 29; used here as in iterated bias correction of
//! simulation-based estimators): `tabulated` is `heitz`'s multiple-bounce lobe tabulated once
//! and interpolated, deterministic with exact derivatives, within 0.5-0.8% RMS of `heitz`.
//!
//! 1. Fit `tabulated` to the photos: `theta_0`.
//! 2. At `theta_k`, estimate the defect `d_k = S(theta_k) - T(theta_k)` at every loss pixel: the
//!    stochastic model's render minus `tabulated`'s, with [`walks_per_pixel`] walks per pixel.
//! 3. Fit `tabulated` to the photos minus `d_k`, from `theta_k`: `theta_{k+1}`.
//! 4. Repeat 2-3 until the last round's move of the prediction puts the fixed point's
//!    within [`SETTLED`] of it ([`settles`]), at most [`MAX_ROUNDS`].
//! 5. Measure the noise the last defect's walks leave in the roughness, by the linear
//!    response of the fit to groups of its streams ([`roughness_noise`]).
//!
//! At the fixed point `T(theta) + d(theta) = S(theta)`: the prediction is the stochastic model's
//! own estimate, so its Fresnel, anisotropy and walk statistics are the model's, not the table's.
//! The defect's walks use the same streams every round (common random numbers), so the iteration
//! is a deterministic map and settles instead of chasing fresh noise. Their noise enters as a
//! fixed offset to the photos, which moves the fit to first order only, symmetrically; the
//! optimiser never sees a random objective. The derivatives are `tabulated`'s, so where the
//! two models' slopes differ the fixed point is the minimiser of the corrected objective, which
//! equals the stochastic model's when the model fits the photos (the residual is noise).
//!
//! A fit that leaves `tabulated`'s table (alpha above [`tabulated::ALPHA_MAX`]) is not corrected
//! further and is reported with `settled: false`: the table no longer stands for the model
//! there, and exact walks at such roughness are long (a defect render at alpha 7.5 ran for more
//! than 10 minutes before the start fix of `start::projected_start` removed that case).
//!
//! Applies to the L2 and relative-L2 losses (the defect is an additive offset to the
//! prediction, which moving the targets represents exactly for L2 and to the noise scale's
//! change for relative L2); `--stochastic-fit direct` fits the model on its own walks, as
//! before, and so do the log-L1 and SSIM losses.

use super::local::ridged_gauss_newton;
use super::objective::Objective;
use super::{fit_level_on, fit_point_on, objective_of, FitOptions, ModelFit, PointFit};
use crate::bsdf::{tabulated, Model};
use crate::error::Result;
use crate::loss::LossKind;
use crate::material::Material;
use crate::progress::Reporting;
use crate::render::render_multi_streams;
use crate::shading::ShadingRecords;
use serde::{Deserialize, Serialize};

/// Walks of the stochastic model in each defect estimate, over all loss pixels: the defect's
/// noise moves the fit in proportion to `1 / sqrt(walks)` (a fixed offset of the photos,
/// averaged by the fit over every pixel), so a budget in total walks holds the fit's precision
/// at any image size. Each fit reports the noise it leaves (`Correction::alpha_noise`); with
/// 2^21 walks, measured on 2026-11-28 (`heitz`, docs/fidelity.md): 1e-4 of alpha on
/// `copper-flash`, 2.6e-4 on the pinhole conductor set, 7.5e-4 on 96x96 pinhole photos of
/// gold, 1e-2 on 128x128 flash photos of rough white (alpha 1.2) with F0 free. The spreads
/// over seeds that chose this budget were measured while consecutive seeds shared their
/// streams, and understated the noise (docs/speed.md).
pub const WALK_BUDGET: usize = 1 << 21;

/// Walks per pixel at least and at most (the most: 64, as measured in docs/fidelity.md on
/// nine 32x32 photos, 9216 pixels, where the budget allows 227).
pub const WALKS_PER_PIXEL: (usize, usize) = (4, 64);

/// Walks per pixel of a defect estimate over `pixels` loss pixels.
pub fn walks_per_pixel(pixels: usize) -> usize {
    (WALK_BUDGET / pixels.max(1)).clamp(WALKS_PER_PIXEL.0, WALKS_PER_PIXEL.1)
}

/// Rounds of correction at most.
pub const MAX_ROUNDS: usize = 4;

/// The iteration ends when the fixed point's prediction is within this of the last round's,
/// as [`prediction_change`] measures it (relative RMS over the loss pixels) and [`settles`]
/// bounds it. A move of `ln alpha` by `e` moves a specular photo set's prediction by about
/// `e` (the lobe's peak goes as `1 / alpha^2`, its tails the other way), so the bound holds
/// alpha to about 0.1%; directions the photos do not determine (a conductor's edge tint along
/// its valley) move the prediction by little and do not hold the iteration open. Measured on
/// the 96x96 gold set: rounds moved the edge-tint coordinates by 1.0-1.7 each and the
/// prediction by 4.4e-3 then 1.6e-3; with the rule in coordinates that fit never settled in
/// [`MAX_ROUNDS`] (4.4-5.6 s against 2.6-3.3 s now, alpha within 0.01% of each other).
pub const SETTLED: f64 = 1e-3;

/// Largest contraction of the rounds' map on a well-posed fit: the move of a round over the
/// move of the round before it. The map's derivative is `tabulated`'s pseudo-inverse Jacobian
/// times the defect's Jacobian, and the defect is the small part of the multiple-bounce lobe
/// the table misses, so the map contracts strongly. Measured in coordinates on 32x32 `heitz`
/// photo sets (white, copper and gold at alpha 0.2 to 1.5, Fresnel known) and on the bundled
/// sets, for `heitz`, `bitterli` and `cui`: at most 0.13 (`heitz`, gold, alpha 1.2), typically
/// 0.01 to 0.07, with one exception: `cui` on white alpha 0.9, whose rounds moved by 1.9e-2,
/// 1.1e-3, 2.2e-3 and 1.7e-3. In prediction space: 0.006-0.010 on aluminium-pinhole, 0.36 on
/// the gold set above (its defect changes along the edge-tint valley; the settled fits of
/// seeds 1-4 agreed within 0.01%, on walks those seeds largely shared). Common random numbers keep the walks' streams from round
/// to round, not their paths, which change discontinuously with the coordinates, so near its
/// fixed point the map is defined to about 2e-3 there (0.2% in alpha).
pub const CONTRACTION: f64 = 0.25;

/// Whether a round that moved the prediction by `moved` ([`prediction_change`]) leaves the
/// fixed point within [`SETTLED`]: by the contraction bound the rounds still to come move it by
/// at most `moved c / (1 - c)` in all. With the bound, a round that moved by up to 3e-3
/// settles, which saves the confirming round (a defect render and a refit) that the rule "the
/// last round moved by at most 1e-3" cost most fits.
pub fn settles(moved: f64) -> bool {
    moved * CONTRACTION / (1.0 - CONTRACTION) <= SETTLED
}

/// Offset of the defect's random streams from the fit's seed.
const DEFECT_STREAMS: u64 = 0x5eed_defe_c7;

/// Odd multiplier (2^64 over the golden ratio) that spreads the fits' seeds over the streams:
/// distinct seeds start their blocks of consecutive streams far apart.
const STREAM_BLOCKS: u64 = 0x9E37_79B9_7F4A_7C15;

/// How a stochastic model that claims `heitz`'s value is fitted (`--stochastic-fit`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum StochasticFit {
    /// Defect correction on `tabulated` (this module).
    #[default]
    Corrected,
    /// L-BFGS (or Nelder-Mead for `heitz`) on the model's own pair loss.
    Direct,
}

/// What the correction did, for the fit file.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Correction {
    /// The deterministic model fitted in every round.
    pub surrogate: Model,
    pub walks_per_pixel: usize,
    /// Roughness after each round, the uncorrected `tabulated` fit first.
    pub alpha_rounds: Vec<[f64; 2]>,
    /// How far each round moved `tabulated`'s prediction ([`prediction_change`]).
    #[serde(default)]
    pub prediction_moves: Vec<f64>,
    /// Whether the last round's move bounds the distance to the fixed point by [`SETTLED`]
    /// ([`settles`]).
    pub settled: bool,
    /// Standard deviation of `ln alpha` (of `ln alpha_x` and `ln alpha_y` when anisotropic)
    /// that the last defect's walks leave in the fit ([`roughness_noise`]): about the relative
    /// standard deviation of alpha. `None` where it is not measured (fewer than two streams of
    /// walks, no Gauss-Newton matrix, or no round ran).
    #[serde(default)]
    pub alpha_noise: Option<[f64; 2]>,
}

/// Whether `options` fit a model by defect correction.
pub fn applies(options: &FitOptions) -> bool {
    options.stochastic_fit == StochasticFit::Corrected
        && options.space.model.capabilities().surrogate.is_some()
        && matches!(options.loss, LossKind::L2 | LossKind::RelativeL2)
}

/// The defect correction fit of `options.space.model` (see the module docs).
pub fn fit(records: &ShadingRecords, options: &FitOptions) -> Result<PointFit> {
    let started = std::time::Instant::now();
    let model = options.space.model;
    let surrogate_model = model
        .capabilities()
        .surrogate
        .expect("a model with a surrogate");
    let surrogate = FitOptions {
        space: super::ParamSpace {
            model: surrogate_model,
            ..options.space
        },
        ..options.clone()
    };
    let (pixels, seeds) = defect_streams(records, options.seed);
    let walks = seeds.len();

    // One objective serves every round: the rounds change only its targets.
    let mut objective = objective_of(records, &surrogate);
    let first = fit_point_on(&objective, records, &surrogate)?;
    let mut evaluations = first.fit.evaluations;
    let mut alpha_rounds = vec![first.fit.material.alpha];
    // The basins the surrogate's start compared: the rounds start from its optimum only.
    let (alternatives, warnings) = (first.fit.alternatives.clone(), first.fit.warnings.clone());
    let (mut fit, mut x) = (first.fit, first.x);
    let mut corrected = records.target.clone();
    let mut settled = false;
    let mut prediction = objective.predict(&x);
    let mut prediction_moves = Vec::new();
    let mut last_defect = None;
    for _ in 0..MAX_ROUNDS {
        if fit.material.alpha.iter().any(|&a| a > tabulated::ALPHA_MAX) {
            break;
        }
        let defect = defect(&fit, model, records, &pixels, &seeds);
        for (&p, d) in pixels.iter().zip(&defect.mean) {
            for c in 0..3 {
                corrected[p][c] = records.target[p][c] - d[c];
            }
        }
        objective.retarget(&corrected);
        let next = fit_level_on(
            &objective,
            records,
            &surrogate,
            Some(x.clone()),
            &Reporting::Off,
        )?;
        evaluations += next.evaluations;
        x = next.point(&surrogate.space);
        let next_prediction = objective.predict(&x);
        let moved = prediction_change(records, &pixels, &prediction, &next_prediction);
        prediction_moves.push(moved);
        alpha_rounds.push(next.material.alpha);
        (fit, prediction) = (next, next_prediction);
        last_defect = Some(defect);
        if settles(moved) {
            settled = true;
            break;
        }
    }

    let alpha_noise = last_defect.and_then(|defect| {
        evaluations += defect.groups.len() + 1;
        roughness_noise(&mut objective, &x, &corrected, &pixels, &defect)
    });

    // Report the model itself: its loss, per-photo losses and plan, on its own objective,
    // built in the memory the surrogate's frees (kept, the new one's pages took 0.3 s to clear).
    drop(objective);
    let own = objective_of(records, options);
    fit.material.model = model;
    fit.loss = own.loss(&x);
    fit.photos = super::photo_losses(&own, records, &x);
    fit.render_plan = own.plan_summary(&fit.material);
    fit.start.model = model;
    fit.evaluations = evaluations + own.evaluations.load(std::sync::atomic::Ordering::Relaxed);
    fit.correction = Some(Correction {
        surrogate: surrogate_model,
        walks_per_pixel: walks * records.samples_per_pixel,
        alpha_rounds,
        prediction_moves,
        settled,
        alpha_noise,
    });
    fit.exposure = super::exposure::estimate(options.space, &x);
    fit.alternatives = alternatives;
    for warning in warnings {
        if !fit.warnings.contains(&warning) {
            fit.warnings.push(warning);
        }
    }
    fit.seconds = started.elapsed().as_secs_f64();
    Ok(PointFit { fit, x })
}

/// The loss pixels of `records` and the seeds of a defect estimate over them: one stream of
/// `samples_per_pixel` walks per seed, [`walks_per_pixel`] walks per pixel in all, the same
/// streams in every round (common random numbers), and no stream shared with another seed's.
fn defect_streams(records: &ShadingRecords, seed: u64) -> (Vec<usize>, Vec<u64>) {
    let pixels: Vec<usize> = (0..records.pixel_count())
        .filter(|&p| records.weight[p] > 0.0)
        .collect();
    let walks = walks_per_pixel(pixels.len()).div_ceil(records.samples_per_pixel.max(1));
    // The fit's seed picks a block of consecutive streams far from any other seed's: with
    // `seed + w` the fits of seeds 1 and 2 shared all their streams but one.
    let first = (seed ^ DEFECT_STREAMS).wrapping_mul(STREAM_BLOCKS);
    let seeds = (0..walks as u64).map(|w| first.wrapping_add(w)).collect();
    (pixels, seeds)
}

/// How far a round moved the prediction: the RMS of `after - before` over the loss `pixels`
/// (weighted as the loss weights them, every channel), relative to the photos' RMS there.
/// Coordinates the photos do not determine (a conductor's edge tint along its valley) move
/// the prediction by nothing, and the rounds' noise in them does not keep the iteration going.
pub fn prediction_change(
    records: &ShadingRecords,
    pixels: &[usize],
    before: &[[f64; 3]],
    after: &[[f64; 3]],
) -> f64 {
    let (mut moved, mut photos) = (0.0, 0.0);
    for ((&p, b), a) in pixels.iter().zip(before).zip(after) {
        let w = records.weight[p];
        for c in 0..3 {
            moved += w * (a[c] - b[c]).powi(2);
            photos += w * records.target[p][c].powi(2);
        }
    }
    (moved / photos.max(f64::MIN_POSITIVE)).sqrt()
}

/// Streams of walks of a defect estimate are dealt into at most this many groups, whose spread
/// measures the estimate's noise ([`roughness_noise`]): 8 groups give its standard deviation
/// to about 25% (7 degrees of freedom), for one gradient pass each.
pub const NOISE_GROUPS: usize = 8;

/// A defect estimate ([`defect`]): its mean over every stream, and the means of the groups of
/// streams dealt round-robin into [`NOISE_GROUPS`], with their stream counts.
struct Defect {
    mean: Vec<[f64; 3]>,
    groups: Vec<(usize, Vec<[f64; 3]>)>,
}

/// `S - T` at `pixels`: the stochastic `model`'s render at `fit`'s material, the mean over
/// `seeds`, minus `tabulated`'s (the surrogate `fit` is of), both exact at every sub-sample and
/// with `fit`'s exposure. The two share the single-bounce lobe exactly (every stochastic model
/// evaluates it in closed form and samples only the longer paths), so the defect is the
/// difference of their multiple-bounce terms, without the cancelled lobe's rounding.
fn defect(
    fit: &ModelFit,
    model: Model,
    records: &ShadingRecords,
    pixels: &[usize],
    seeds: &[u64],
) -> Defect {
    let exposed = fit.exposed(records);
    let stochastic = Material {
        model,
        ..fit.material.clone()
    };
    let renders = render_multi_streams(&stochastic, &exposed, pixels, seeds);
    let surrogate = render_multi_streams(&fit.material, &exposed, pixels, &[0]).remove(0);
    let mean_of = |streams: &[&Vec<[f64; 3]>]| -> Vec<[f64; 3]> {
        let scale = 1.0 / streams.len() as f64;
        surrogate
            .iter()
            .enumerate()
            .map(|(i, t)| {
                [0, 1, 2].map(|c| streams.iter().map(|r| r[i][c]).sum::<f64>() * scale - t[c])
            })
            .collect()
    };
    let count = NOISE_GROUPS.min(renders.len());
    let groups = (0..count)
        .map(|g| {
            let members: Vec<&Vec<[f64; 3]>> = renders.iter().skip(g).step_by(count).collect();
            (members.len(), mean_of(&members))
        })
        .collect();
    Defect {
        mean: mean_of(&renders.iter().collect::<Vec<_>>()),
        groups,
    }
}

/// The standard deviation of the fit's roughness coordinates that the noise of `defect` leaves
/// at its fixed point `x`, by linear response. The fit minimises the loss against the photos
/// minus the defect (`corrected`, indexed like the records' targets), so an error `e` of the
/// defect moves it by `dx = -H^-1 (g(e) - g(0))`, with `H` the Gauss-Newton matrix at `x` and
/// `g(e)` the gradient against the photos minus `defect + e`. Each group of `n_r` streams
/// (of `S`) deviates from the mean by `e_r`; `sum_r n_r e_r e_r^T / (R - 1)` estimates one
/// stream's covariance, so the mean's effect has covariance
/// `sum_r n_r dx_r dx_r^T / ((R - 1) S)`. The defect's noise is a fixed offset of the photos
/// (the streams are kept from round to round), so this is the spread of fits with other
/// seeds, not of this fit's rounds.
fn roughness_noise(
    objective: &mut Objective,
    x: &[f64],
    corrected: &[[f64; 3]],
    pixels: &[usize],
    defect: &Defect,
) -> Option<[f64; 2]> {
    let groups = defect.groups.len();
    if groups < 2 {
        return None;
    }
    let n = x.len();
    let (_, base, matrix) = objective.gauss_newton(x)?;
    let factor = ridged_gauss_newton(&matrix, n)?;
    let roughness = if objective.space.anisotropic { 2 } else { 1 };
    let streams: usize = defect.groups.iter().map(|g| g.0).sum();
    let mut variance = [0.0; 2];
    let mut shifted = corrected.to_vec();
    for (members, group) in &defect.groups {
        for ((&p, g), m) in pixels.iter().zip(group).zip(&defect.mean) {
            for c in 0..3 {
                shifted[p][c] = corrected[p][c] - (g[c] - m[c]);
            }
        }
        objective.retarget(&shifted);
        let (_, gradient) = objective.exact_cost_and_gradient(x)?;
        let change: Vec<f64> = gradient.iter().zip(&base).map(|(g, b)| g - b).collect();
        let dx = factor.solve(&change);
        for (v, d) in variance.iter_mut().zip(&dx).take(roughness) {
            *v += *members as f64 * d * d;
        }
    }
    objective.retarget(corrected);
    let norm = ((groups - 1) * streams) as f64;
    let sd = variance.map(|v| (v / norm).sqrt());
    Some([sd[0], if roughness == 2 { sd[1] } else { sd[0] }])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::point::objective::tests::pinhole_records;
    use crate::fit::point::params::ParamSpace;
    use crate::material::FresnelSpec;

    /// `heitz`'s photos of rough copper (alpha 0.9) on the pinhole template at 48 x 48, and the
    /// space that fits `heitz` to them with the Fresnel known.
    fn rough_copper() -> (ParamSpace, ShadingRecords) {
        let copper = FresnelSpec::Schlick {
            f0: [0.955, 0.638, 0.538],
        };
        let space = ParamSpace {
            known_fresnel: Some(copper),
            ..ParamSpace::plain(Model::Heitz)
        };
        let records = pinhole_records(&space.material(&[0.9f64.ln()]));
        (space, records)
    }

    /// The stopping rule ([`settles`]) assumes that each round moves the prediction by at
    /// most [`CONTRACTION`] of the move before it, so that a settled fit is within [`SETTLED`]
    /// of the rounds' fixed point. On `heitz` photos of rough copper (known Fresnel, the
    /// pinhole template at 48 x 48): every recorded round contracts by at most `CONTRACTION`,
    /// in the prediction and in `ln alpha`, including one more round from the settled point on
    /// the same walks, which moves the prediction and `ln alpha` by at most `SETTLED`. A rule
    /// that stopped early, or rounds that did not contract, fail here. Measured: the one round
    /// moved the prediction by 1.8e-3 and `ln alpha` by 3.8e-3 and settled; one more did not
    /// move the fit (from the settled point Levenberg-Marquardt predicted a negligible gain;
    /// on the walks of before 2026-11-28 it moved them by 1.6e-5 and 3.4e-5); alpha came out
    /// 0.8934 (the photos' walks are noisy at 4 sub-samples).
    #[test]
    fn one_more_round_after_settling_stays_within_the_bound() {
        let (space, records) = rough_copper();
        let options = FitOptions::defaults(space);
        let fitted = fit(&records, &options).unwrap();
        let correction = fitted.fit.correction.clone().expect("a corrected fit");
        assert!(correction.settled, "{:?}", correction.alpha_rounds);
        let ln_alphas: Vec<f64> = correction.alpha_rounds.iter().map(|a| a[0].ln()).collect();
        let mut moves: Vec<f64> = ln_alphas.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
        let mut predicted = correction.prediction_moves.clone();
        assert_eq!(predicted.len(), moves.len());

        // One more round, as `fit` runs them, from the settled point.
        let surrogate = FitOptions {
            space: ParamSpace {
                model: Model::Tabulated,
                ..space
            },
            ..options.clone()
        };
        let mut last = fitted.fit.clone();
        last.material.model = Model::Tabulated;
        let (pixels, seeds) = defect_streams(&records, options.seed);
        let defect = defect(&last, Model::Heitz, &records, &pixels, &seeds);
        let mut corrected = records.target.clone();
        for (&p, d) in pixels.iter().zip(&defect.mean) {
            for c in 0..3 {
                corrected[p][c] = records.target[p][c] - d[c];
            }
        }
        let mut objective = objective_of(&records, &surrogate);
        let before = objective.predict(&fitted.x);
        objective.retarget(&corrected);
        let next = fit_level_on(
            &objective,
            &records,
            &surrogate,
            Some(fitted.x.clone()),
            &Reporting::Off,
        )
        .unwrap();
        let after = objective.predict(&next.point(&surrogate.space));
        let moved = prediction_change(&records, &pixels, &before, &after);
        let moved_alpha = (next.material.alpha[0].ln() - ln_alphas[ln_alphas.len() - 1]).abs();
        assert!(
            moved <= SETTLED && moved_alpha <= SETTLED,
            "one more round moved the prediction by {moved:e}, ln alpha by {moved_alpha:e} \
             after rounds {predicted:?}, {moves:?}"
        );
        predicted.push(moved);
        moves.push(moved_alpha);
        for (what, moves) in [("the prediction", &predicted), ("ln alpha", &moves)] {
            for pair in moves.windows(2) {
                assert!(
                    pair[1] <= CONTRACTION * pair[0],
                    "rounds moved {what} by {moves:?}: not contracting by {CONTRACTION}"
                );
            }
        }
        assert!(
            (fitted.fit.material.alpha[0] / 0.9 - 1.0).abs() < 0.02,
            "alpha {}",
            fitted.fit.material.alpha[0]
        );
    }

    /// The noise a fit reports ([`roughness_noise`]) is the spread of the fits of other seeds:
    /// `heitz` fitted to its own photos of rough copper (known Fresnel, the pinhole template at
    /// 48 x 48: 64 walks per pixel in 16 streams, dealt into 8 groups) with seeds 1 to 8. The
    /// sample standard deviation of `ln alpha` over 8 fits is within 0.48-1.48 of the truth at
    /// 95% (7 degrees of freedom), and the reported values' RMS within about 10% of it (8 fits
    /// of 7 degrees of freedom each): their ratio must lie in [0.45, 2.0]. A response without
    /// the `1 / S` of the streams' mean (reported 4x too large) or without the groups' sizes
    /// fails. Measured: spread 1.04e-3, reported 9.5e-4, ratio 1.09. (`cui` measured 1.78:
    /// its walks change their paths discontinuously with the coordinates, so its rounds' fixed
    /// point jitters by about 1e-3 on top of the walks' noise, see [`CONTRACTION`].)
    #[test]
    fn the_reported_noise_is_the_spread_over_seeds() {
        let (space, records) = rough_copper();
        let fits: Vec<(f64, f64)> = (1..=8)
            .map(|seed| {
                let options = FitOptions {
                    seed,
                    ..FitOptions::defaults(space)
                };
                let fitted = fit(&records, &options).unwrap().fit;
                let noise = fitted.correction.and_then(|c| c.alpha_noise);
                let noise = noise.expect("a measured noise")[0];
                (fitted.material.alpha[0].ln(), noise)
            })
            .collect();
        let n = fits.len() as f64;
        let mean = fits.iter().map(|f| f.0).sum::<f64>() / n;
        let spread = (fits.iter().map(|f| (f.0 - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        let reported = (fits.iter().map(|f| f.1 * f.1).sum::<f64>() / n).sqrt();
        let ratio = spread / reported;
        eprintln!("spread {spread:e}, reported {reported:e}, ratio {ratio}");
        assert!(
            (0.45..=2.0).contains(&ratio),
            "spread {spread:e} over reported {reported:e}: {ratio} ({fits:?})"
        );
    }

    /// The change is relative to the photos: a prediction equal to the photos scaled by
    /// `1 + e` moved by `e` from them; pixels count by their loss weight.
    #[test]
    fn prediction_change_is_relative_rms_of_the_weighted_pixels() {
        let space = ParamSpace::plain(Model::Single);
        let mut records = pinhole_records(&space.material(&[0.3f64.ln(), 0.0, 0.0, 0.0]));
        let pixels: Vec<usize> = (0..records.pixel_count())
            .filter(|&p| records.weight[p] > 0.0)
            .collect();
        let photos: Vec<[f64; 3]> = pixels.iter().map(|&p| records.target[p]).collect();
        let scaled: Vec<[f64; 3]> = photos.iter().map(|v| v.map(|c| c * 1.01)).collect();
        let moved = prediction_change(&records, &pixels, &photos, &scaled);
        assert!((moved - 0.01).abs() < 1e-12, "{moved}");
        assert_eq!(prediction_change(&records, &pixels, &photos, &photos), 0.0);

        // Doubling every weight changes nothing; moving one pixel only counts by its weight.
        for p in &pixels {
            records.weight[*p] *= 2.0;
        }
        let again = prediction_change(&records, &pixels, &photos, &scaled);
        assert!((again - moved).abs() < 1e-12);
        let k = pixels.len() / 2;
        let mut one = photos.clone();
        one[k] = one[k].map(|c| c + 1.0);
        let light = prediction_change(&records, &pixels, &photos, &one);
        records.weight[pixels[k]] *= 4.0;
        let heavy = prediction_change(&records, &pixels, &photos, &one);
        assert!(heavy > 1.5 * light, "{light} {heavy}");
    }
}
