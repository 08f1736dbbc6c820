//! Fits of the stochastic models that claim `heitz`'s value (`heitz`, `bitterli`, `cui`) by
//! defect correction on the deterministic `tabulated` model (issue #16 item 2).
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

use super::{fit_level_on, fit_point_on, objective_of, FitOptions, ModelFit, PointFit};
use crate::bsdf::{tabulated, Model};
use crate::error::Result;
use crate::loss::LossKind;
use crate::material::Material;
use crate::render::render_multi_streams;
use crate::shading::ShadingRecords;
use serde::{Deserialize, Serialize};

/// Walks of the stochastic model in each defect estimate, over all loss pixels: the defect's
/// noise moves the fit in proportion to `1 / sqrt(walks)` (a fixed offset of the photos,
/// averaged by the fit over every pixel), so a budget in total walks holds the fit's precision
/// at any image size. Measured over seeds 1-4 on 2026-11-28 (docs/speed.md): with 2^21 walks
/// alpha spread over 0.003-0.03% (`bitterli`, `heitz`, `cui` on the bundled sets; `bitterli`
/// on a 96x96 pinhole set of gold rendered by `heitz`), with 2^19 over 0.01-0.07% for 0.5-0.9x
/// the fit's time; the intervals do not count the defect's noise, so the budget stays.
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
/// the gold set above (its defect changes along the edge-tint valley; the settled fits' alpha
/// stayed within 0.01% across seeds). Common random numbers keep the walks' streams from round
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
}

/// Whether `options` fit a model by defect correction.
pub fn applies(options: &FitOptions) -> bool {
    options.stochastic_fit == StochasticFit::Corrected
        && matches!(
            options.space.model,
            Model::Heitz | Model::Bitterli | Model::Cui
        )
        && matches!(options.loss, LossKind::L2 | LossKind::RelativeL2)
}

/// The defect correction fit of `options.space.model` (see the module docs).
pub fn fit(records: &ShadingRecords, options: &FitOptions) -> Result<PointFit> {
    let started = std::time::Instant::now();
    let model = options.space.model;
    let surrogate = FitOptions {
        space: super::ParamSpace {
            model: Model::Tabulated,
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
    let (mut fit, mut x) = (first.fit, first.x);
    let mut corrected = records.target.clone();
    let mut settled = false;
    let mut prediction = objective.predict(&x);
    let mut prediction_moves = Vec::new();
    for _ in 0..MAX_ROUNDS {
        if fit.material.alpha.iter().any(|&a| a > tabulated::ALPHA_MAX) {
            break;
        }
        let defect = defect(&fit, model, records, &pixels, &seeds);
        for (&p, d) in pixels.iter().zip(&defect) {
            for c in 0..3 {
                corrected[p][c] = records.target[p][c] - d[c];
            }
        }
        objective.retarget(&corrected);
        let next = fit_level_on(&objective, records, &surrogate, Some(x.clone()), false)?;
        evaluations += next.evaluations;
        x = next.point(&surrogate.space);
        let next_prediction = objective.predict(&x);
        let moved = prediction_change(records, &pixels, &prediction, &next_prediction);
        prediction_moves.push(moved);
        alpha_rounds.push(next.material.alpha);
        (fit, prediction) = (next, next_prediction);
        if settles(moved) {
            settled = true;
            break;
        }
    }

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
        surrogate: Model::Tabulated,
        walks_per_pixel: walks * records.samples_per_pixel,
        alpha_rounds,
        prediction_moves,
        settled,
    });
    fit.exposure = super::exposure::estimate(options.space, &x);
    fit.seconds = started.elapsed().as_secs_f64();
    Ok(PointFit { fit, x })
}

/// The loss pixels of `records` and the seeds of a defect estimate over them: one stream of
/// `samples_per_pixel` walks per seed, [`walks_per_pixel`] walks per pixel in all, the same
/// streams in every round (common random numbers).
fn defect_streams(records: &ShadingRecords, seed: u64) -> (Vec<usize>, Vec<u64>) {
    let pixels: Vec<usize> = (0..records.pixel_count())
        .filter(|&p| records.weight[p] > 0.0)
        .collect();
    let walks = walks_per_pixel(pixels.len()).div_ceil(records.samples_per_pixel.max(1));
    let seeds = (0..walks as u64)
        .map(|w| seed.wrapping_add(DEFECT_STREAMS).wrapping_add(w))
        .collect();
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
) -> Vec<[f64; 3]> {
    let exposed = fit.exposed(records);
    let stochastic = Material {
        model,
        ..fit.material.clone()
    };
    let renders = render_multi_streams(&stochastic, &exposed, pixels, seeds);
    let surrogate = render_multi_streams(&fit.material, &exposed, pixels, &[0]).remove(0);
    let scale = 1.0 / seeds.len() as f64;
    surrogate
        .iter()
        .enumerate()
        .map(|(i, t)| {
            [0, 1, 2].map(|c| renders.iter().map(|r| r[i][c]).sum::<f64>() * scale - t[c])
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::point::objective::tests::pinhole_records;
    use crate::fit::point::params::ParamSpace;
    use crate::material::FresnelSpec;

    /// The stopping rule ([`settles`]) assumes that each round moves the prediction by at
    /// most [`CONTRACTION`] of the move before it, so that a settled fit is within [`SETTLED`]
    /// of the rounds' fixed point. On `heitz` photos of rough copper (known Fresnel, the
    /// pinhole template at 48 x 48): every recorded round contracts by at most `CONTRACTION`,
    /// in the prediction and in `ln alpha`, including one more round from the settled point on
    /// the same walks, which moves the prediction and `ln alpha` by at most `SETTLED`. A rule
    /// that stopped early, or rounds that did not contract, fail here. Measured: the one round
    /// moved the prediction by 2.3e-3 and `ln alpha` by 4.9e-3 and settled; one more moved
    /// them by 1.6e-5 and 3.4e-5; alpha came out 0.8925 (the photos' walks are noisy at 4
    /// sub-samples).
    #[test]
    fn one_more_round_after_settling_stays_within_the_bound() {
        let copper = FresnelSpec::Schlick {
            f0: [0.955, 0.638, 0.538],
        };
        let space = ParamSpace {
            known_fresnel: Some(copper),
            ..ParamSpace::plain(Model::Heitz)
        };
        let truth = space.material(&[0.9f64.ln()]);
        let records = pinhole_records(&truth);
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
        for (&p, d) in pixels.iter().zip(&defect) {
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
            false,
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
