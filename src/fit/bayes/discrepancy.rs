//! A model-discrepancy term, linearised at the mode: what the photos say about the model's own
//! error, and what that error leaves unknown about the parameters.
//!
//! Kennedy & O'Hagan 2001 ("Bayesian calibration of computer models", JRSS B 63(3), section 4)
//! write the data as the model plus a discrepancy function plus noise, give the discrepancy a
//! Gaussian-process prior and estimate its scale from the data; Brynjarsdottir & O'Hagan 2014
//! ("Learning about physical parameters: the importance of model discrepancy", Inverse Problems
//! 30, section 3) show that without that term a calibration is confidently wrong, exactly the
//! failure of `fit --mcmc` on photos the model does not reproduce (issue #16 item 4). As
//! Higdon et al. 2008 (JASA 103(482), section 2.2) we expand the discrepancy on a small basis,
//! here relative to the predicted radiance `p`, achromatic:
//!
//! `p_ic(x, beta) = p_ic(x) (1 + sum_k beta_k phi_k(i))`,
//!
//! with two groups of basis functions, each with its own prior scale:
//!
//! - **photo offsets**: `phi_q(i) = 1` on the pixels of photo `q`. A per-photo exposure or light
//!   power error; `beta_q ~ N(0, tau_photo^2)`.
//! - **lobe shape**: Legendre polynomials of degree 0 to [`LOBE_TERMS`]` - 1` in the half
//!   vector's NDF coordinate `s = x / (1 + x)`, `x = tan^2 theta_h / alpha^2` (for GGX
//!   `D = D(0) (1 - s)^2`), orthonormalised under the information weights of the pixels.
//!   Another NDF tail, a pixel filter, a Fresnel or shadowing the model does not have:
//!   `beta_k ~ N(0, tau_lobe^2)`.
//!
//! Near the mode `x0` the predictions are linear in `(x, beta)`, so with the likelihood's
//! residual precisions `lambda` the joint information is `G = A^T Lambda A` over the columns
//! `A = [dp/dx, p phi]` and the residuals `r = t - p(x0)` give `b = A^T Lambda r`. With a flat
//! prior on `x` the marginal likelihood of the scales is, up to a constant,
//!
//! `ln m(tau) = 1/2 b^T (G + P)^-1 b - 1/2 ln det (G + P) + 1/2 ln det P_beta`,
//!
//! `P = diag(0, 1/tau^2)` (the restricted likelihood of Patterson & Thompson 1971: the
//! parameters' own directions carry no evidence on the scales), evaluated on a grid of both
//! scales. The discrepancy's coefficients confounded with a parameter (the basis starts with
//! the parameters' own directions: a scale for F0, a lobe width for alpha; the mean photo
//! offset with an exposure) cannot be seen in the data; their scale is learned from the
//! coefficients that can, and marginalising them widens the parameter: its covariance becomes
//! the `x` block of `(G + P)^-1` instead of `G_xx^-1`, averaged over the scales' posterior
//! ([`marginalise`]).
//! On photos the model reproduces the scales come out near zero and nothing widens.

use super::log_posterior::{central_differences, LogPosterior, FD_STEP};
use nalgebra::{DMatrix, DVector};

/// Lobe-shape basis functions: Legendre polynomials of degree 0 to `LOBE_TERMS - 1`.
pub const LOBE_TERMS: usize = 6;

/// Support of each scale's log-uniform prior (relative radiance), from a floor to
/// [`LARGEST_SCALE`]: by default from [`SMALLEST_SCALE`], under 16-bit quantisation; a user who
/// knows the model is no better than some level states it (`--discrepancy-floor`).
pub const SMALLEST_SCALE: f64 = 1e-5;
pub const LARGEST_SCALE: f64 = 1.0;

/// Steps of the log-spaced grid over each scale's prior support.
const SCALE_STEPS: usize = 100;

/// The discrepancy term fitted at a mode.
#[derive(Clone, Debug, PartialEq)]
pub struct Discrepancy {
    /// The most likely prior standard deviations: of a photo's relative offset (`tau_photo`)
    /// and of a lobe-shape coefficient (`tau_lobe`; the information-weighted root-mean-square
    /// relative discrepancy is about `sqrt(LOBE_TERMS)` times this).
    pub most_likely: [f64; 2],
    /// `sqrt(E[tau^2])` of both under their posterior: what the intervals were widened with.
    pub root_mean_square: [f64; 2],
    /// What marginalising the discrepancy adds to the covariance of the coordinates, `d x d`
    /// (positive semi-definite).
    pub added_covariance: DMatrix<f64>,
}

/// Per loss pixel: the NDF coordinate `s = x / (1 + x)`, `x = tan^2 theta_h / alpha^2`, of the
/// half vector, averaged over the lit sub-samples.
fn lobe_coordinates(target: &LogPosterior, alpha: f64) -> Vec<f64> {
    let records = target.objective.records();
    let per_pixel = records.samples_per_pixel;
    target
        .objective
        .pixels()
        .iter()
        .map(|&pixel| {
            let (sum, count) = (pixel * per_pixel..(pixel + 1) * per_pixel)
                .filter(|&k| records.irradiance[k].iter().any(|&e| e > 0.0))
                .map(|k| {
                    let h = [0, 1, 2].map(|c| records.wi[k][c] + records.wo[k][c]);
                    let z2 = h[2] * h[2];
                    let x = (h[0] * h[0] + h[1] * h[1]) / (z2 * alpha * alpha).max(1e-300);
                    x / (1.0 + x)
                })
                .fold((0.0, 0.0), |(s, n), v| (s + v, n + 1.0));
            if count > 0.0 {
                sum / count
            } else {
                0.0
            }
        })
        .collect()
}

/// Legendre polynomials `P_0..P_{n-1}` at `t` in [-1, 1].
fn legendre(t: f64, n: usize) -> Vec<f64> {
    let mut p = vec![1.0, t];
    for k in 1..n.saturating_sub(1) {
        let next = ((2 * k + 1) as f64 * t * p[k] - k as f64 * p[k - 1]) / (k + 1) as f64;
        p.push(next);
    }
    p.truncate(n);
    p
}

/// Share of a candidate basis function that must lie outside the functions already in the
/// basis for it to be kept: a parameter direction closer than this to the earlier ones (F0's
/// channels, which all scale the lobe) is the same direction; a polynomial that the parameter
/// directions nearly explain would enter with a remainder whose coefficient the data barely
/// separate from the parameters, and which then reads small residuals as large discrepancies.
const KEPT_SHARE: [f64; 2] = [0.05, 0.1];

/// The lobe basis, orthonormal under `weights` normalised to sum 1 (so each function's
/// weighted root-mean-square is 1): first the achromatic parameter directions
/// `parameter_directions` (relative changes of the prediction), which the discrepancy shares
/// with the parameters exactly, then Legendre polynomials of `coordinates` with those
/// directions taken out, which the data see apart from the parameters (modified Gram-Schmidt,
/// twice; [`KEPT_SHARE`]). `basis[k][i]`.
fn lobe_basis(
    coordinates: &[f64],
    weights: &[f64],
    parameter_directions: &[Vec<f64>],
) -> Vec<Vec<f64>> {
    let total: f64 = weights.iter().sum();
    let weights: Vec<f64> = weights.iter().map(|w| w / total).collect();
    let lo = coordinates.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = coordinates
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max);
    let half = ((hi - lo) / 2.0).max(1e-12);
    let raw: Vec<Vec<f64>> = coordinates
        .iter()
        .map(|&s| legendre((s - lo) / half - 1.0, LOBE_TERMS))
        .collect();
    let polynomials = (0..LOBE_TERMS).map(|k| raw.iter().map(|p| p[k]).collect::<Vec<f64>>());
    let dot = |a: &[f64], b: &[f64]| -> f64 {
        a.iter()
            .zip(b)
            .zip(&weights)
            .map(|((a, b), w)| a * b * w)
            .sum()
    };
    let candidates = parameter_directions
        .iter()
        .cloned()
        .map(|v| (v, KEPT_SHARE[0]))
        .chain(polynomials.map(|v| (v, KEPT_SHARE[1])));
    let mut basis: Vec<Vec<f64>> = Vec::new();
    for (mut v, kept_share) in candidates {
        let original = dot(&v, &v).sqrt();
        for _ in 0..2 {
            for u in &basis {
                let c = dot(&v, u);
                v.iter_mut().zip(u).for_each(|(v, u)| *v -= c * u);
            }
        }
        let norm = dot(&v, &v).sqrt();
        if norm > kept_share * original && norm > 0.0 {
            basis.push(v.into_iter().map(|v| v / norm).collect());
        }
    }
    basis
}

/// `ln m(tau)` of the module docs for prior precisions `prior` on the discrepancy coefficients
/// (the last `prior.len()` coordinates of `g`), or `None` when `G + P` is not positive definite.
fn log_marginal(g: &DMatrix<f64>, b: &DVector<f64>, prior: &[f64]) -> Option<f64> {
    let n = g.nrows();
    let first = n - prior.len();
    let mut m = g.clone();
    for (k, p) in prior.iter().enumerate() {
        m[(first + k, first + k)] += p;
    }
    let cholesky = m.cholesky()?;
    let log_det: f64 = cholesky.l().diagonal().iter().map(|v| 2.0 * v.ln()).sum();
    let quadratic = b.dot(&cholesky.solve(b));
    let prior_log_det: f64 = prior.iter().map(|p| p.ln()).sum();
    Some(0.5 * quadratic - 0.5 * log_det + 0.5 * prior_log_det)
}

/// The discrepancy term at `mode`, or `None` for a likelihood that is not a quadratic form
/// of the residuals (`log-l1`) or when the information is singular.
///
/// The scales' prior is log-uniform from `floor` to [`LARGEST_SCALE`].
pub fn at_mode(target: &LogPosterior, mode: &[f64], floor: f64) -> Option<Discrepancy> {
    let d = mode.len();
    let predicted = target.objective.predict(mode);
    let precisions = target.residual_precisions(&predicted)?;
    let targets = target.objective.targets();
    let photo_of: Vec<usize> = target
        .objective
        .layout()
        .place
        .iter()
        .map(|p| p.0)
        .collect();
    let photos: Vec<usize> = {
        let mut p = photo_of.clone();
        p.sort_unstable();
        p.dedup();
        p
    };
    // slopes[3 i + c][j] = d p_ic / d x_j.
    let slopes = central_differences(mode, FD_STEP, |probe| {
        target.objective.predict(probe).concat()
    });
    let information: Vec<f64> = predicted
        .iter()
        .zip(&precisions)
        .map(|(p, l)| (0..3).map(|c| l[c] * p[c] * p[c]).sum())
        .collect();
    let material = target.objective.space.material(mode);
    let alpha = (material.alpha[0] * material.alpha[1]).sqrt();
    // Per coordinate: the information-weighted channel mean of the relative change of the
    // prediction, `sum_c lambda p dp/dx / sum_c lambda p^2`.
    let parameter_directions: Vec<Vec<f64>> = (0..d)
        .map(|j| {
            predicted
                .iter()
                .zip(&precisions)
                .zip(&information)
                .enumerate()
                .map(|(i, ((p, l), w))| {
                    let along: f64 = (0..3).map(|c| l[c] * p[c] * slopes[3 * i + c][j]).sum();
                    if *w > 0.0 {
                        along / w
                    } else {
                        0.0
                    }
                })
                .collect()
        })
        .collect();
    let lobe = lobe_basis(
        &lobe_coordinates(target, alpha),
        &information,
        &parameter_directions,
    );
    let n = d + photos.len() + lobe.len();
    let mut g = DMatrix::<f64>::zeros(n, n);
    let mut b = DVector::<f64>::zeros(n);
    let mut column = vec![0.0; n];
    for (i, ((p, t), l)) in predicted.iter().zip(targets).zip(&precisions).enumerate() {
        let photo = photos.binary_search(&photo_of[i]).expect("listed");
        for c in 0..3 {
            column.iter_mut().for_each(|v| *v = 0.0);
            column[..d].copy_from_slice(&slopes[3 * i + c]);
            column[d + photo] = p[c];
            for (k, phi) in lobe.iter().enumerate() {
                column[d + photos.len() + k] = p[c] * phi[i];
            }
            let r = t[c] - p[c];
            for a in 0..n {
                let la = l[c] * column[a];
                b[a] += la * r;
                for bb in 0..=a {
                    g[(a, bb)] += la * column[bb];
                }
            }
        }
    }
    g.fill_upper_triangle_with_lower_triangle();
    let marginal = marginalise(&g, &b, d, photos.len(), floor)?;
    Some(Discrepancy {
        most_likely: marginal.most_likely,
        root_mean_square: marginal.root_mean_square,
        added_covariance: marginal.added_covariance,
    })
}

/// The discrepancy's scales and what it does to the coordinates, from [`marginalise`].
struct Marginal {
    /// The scales that maximise `ln m(tau)`: per-photo offset, lobe coefficient.
    most_likely: [f64; 2],
    /// `sqrt(E[tau^2])` of each scale under its posterior.
    root_mean_square: [f64; 2],
    /// The covariance of the first `d` coordinates averaged over the scales' posterior, less
    /// the model's own.
    added_covariance: DMatrix<f64>,
}

/// Relative weight below which a grid point of the scales' posterior is left out of the average.
const NEGLIGIBLE_WEIGHT: f64 = 1e-9;

/// The discrepancy marginalised for the information `g` and score `b` over `d` coordinates, then
/// `photos` photo offsets, then the lobe coefficients. The scales are not plugged in at their
/// most likely values but averaged over their posterior on the grid, under a log-uniform prior
/// from `floor` to [`LARGEST_SCALE`]: with a handful of visible coefficients a point estimate of a variance
/// understates how large it may be (Gelman 2006, "Prior distributions for variance parameters in
/// hierarchical models", Bayesian Analysis 1(3), section 5). The coordinates' covariance is that
/// of the mixture: the mean of each grid point's covariance plus the spread of its means.
fn marginalise(
    g: &DMatrix<f64>,
    b: &DVector<f64>,
    d: usize,
    photos: usize,
    floor: f64,
) -> Option<Marginal> {
    let lobe = g.nrows() - d - photos;
    let prior = |photo_scale: f64, lobe_scale: f64| -> Vec<f64> {
        let mut p = vec![1.0 / (photo_scale * photo_scale); photos];
        p.resize(photos + lobe, 1.0 / (lobe_scale * lobe_scale));
        p
    };
    let grid: Vec<f64> = (0..=SCALE_STEPS)
        .map(|k| {
            let f = k as f64 / SCALE_STEPS as f64;
            floor * (LARGEST_SCALE / floor).powf(f)
        })
        .collect();
    let points: Vec<(f64, [f64; 2])> = grid
        .iter()
        .flat_map(|&p| grid.iter().map(move |&l| [p, l]))
        .filter_map(|[p, l]| Some((log_marginal(g, b, &prior(p, l))?, [p, l])))
        .collect();
    let (top, most_likely) = points.iter().copied().max_by(|a, c| a.0.total_cmp(&c.0))?;
    let mut total = 0.0;
    let mut mean_square = [0.0; 2];
    let mut second_moment = DMatrix::<f64>::zeros(d, d);
    let mut mean = DVector::<f64>::zeros(d);
    for (value, scales) in points {
        let weight = (value - top).exp();
        if weight < NEGLIGIBLE_WEIGHT {
            continue;
        }
        let mut joint = g.clone();
        for (k, p) in prior(scales[0], scales[1]).iter().enumerate() {
            joint[(d + k, d + k)] += p;
        }
        let cholesky = joint.cholesky()?;
        let shift = cholesky.solve(b).rows(0, d).into_owned();
        let covariance = cholesky.inverse().view((0, 0), (d, d)).into_owned();
        total += weight;
        mean_square = [0, 1].map(|k| mean_square[k] + weight * scales[k] * scales[k]);
        second_moment += weight * (covariance + &shift * shift.transpose());
        mean += weight * shift;
    }
    mean /= total;
    let mixture = second_moment / total - &mean * mean.transpose();
    let model_only = g.view((0, 0), (d, d)).into_owned().cholesky()?.inverse();
    Some(Marginal {
        most_likely,
        root_mean_square: mean_square.map(|m| (m / total).sqrt()),
        added_covariance: mixture - model_only,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_distr::StandardNormal;

    const PHOTOS: usize = 9;
    const PIXELS_PER_PHOTO: usize = 200;

    /// `(G, b)` of a linear model with one coordinate whose column is constant (as F0 scales a
    /// lobe), [`PHOTOS`] photo offsets and [`LOBE_TERMS`] Legendre coefficients of a pixel
    /// coordinate (the first constant too), the data drawn with the true coordinate 0, offsets
    /// and coefficients of standard deviations `photo_scale` and `lobe_scale`, and noise `noise`.
    fn simulated(
        seed: u64,
        photo_scale: f64,
        lobe_scale: f64,
        noise: f64,
    ) -> (DMatrix<f64>, DVector<f64>) {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
        let mut normal = move || rng.sample::<f64, _>(StandardNormal);
        let offsets: Vec<f64> = (0..PHOTOS).map(|_| photo_scale * normal()).collect();
        let coefficients: Vec<f64> = (0..LOBE_TERMS).map(|_| lobe_scale * normal()).collect();
        let n = 1 + PHOTOS + LOBE_TERMS;
        let mut g = DMatrix::zeros(n, n);
        let mut b = DVector::zeros(n);
        let precision = 1.0 / (noise * noise);
        for photo in 0..PHOTOS {
            for pixel in 0..PIXELS_PER_PHOTO {
                let u = (pixel as f64 + 0.5 + 0.3 * photo as f64) / PIXELS_PER_PHOTO as f64;
                let lobe = legendre(2.0 * u.min(1.0) - 1.0, LOBE_TERMS);
                let mut column = DVector::zeros(n);
                column[0] = 1.0;
                column[1 + photo] = 1.0;
                for (k, v) in lobe.iter().enumerate() {
                    column[1 + PHOTOS + k] = *v;
                }
                let model_error: f64 = offsets[photo]
                    + lobe
                        .iter()
                        .zip(&coefficients)
                        .map(|(p, c)| p * c)
                        .sum::<f64>();
                let r = model_error + noise * normal();
                g += precision * &column * column.transpose();
                b += precision * r * &column;
            }
        }
        (g, b)
    }

    #[test]
    fn the_fitted_scales_recover_the_simulated_ones_on_average() {
        // Restricted maximum likelihood of a variance from the 5 identifiable lobe contrasts
        // (8 photo contrasts) has a relative standard deviation of about sqrt(2/5) (sqrt(2/8))
        // per set, so the mean of 40 sets is within 3.5 standard errors: 0.35 (0.28).
        let (photo_scale, lobe_scale) = (0.01, 0.02);
        let sets = 40;
        let (mut photo, mut lobe) = (0.0, 0.0);
        for seed in 0..sets {
            let (g, b) = simulated(seed, photo_scale, lobe_scale, 1e-3);
            let [p, l] = marginalise(&g, &b, 1, PHOTOS, SMALLEST_SCALE)
                .unwrap()
                .most_likely;
            photo += (p / photo_scale).powi(2) / sets as f64;
            lobe += (l / lobe_scale).powi(2) / sets as f64;
        }
        assert!((photo - 1.0).abs() < 0.28, "photo variance ratio {photo}");
        assert!((lobe - 1.0).abs() < 0.35, "lobe variance ratio {lobe}");
    }

    #[test]
    fn a_confounded_discrepancy_adds_its_prior_variance_to_the_coordinate() {
        // The constant column is the degree-0 lobe term and the mean of the photo offsets: its
        // variance grows by E[tau_lobe^2] + E[tau_photo^2] / PHOTOS (the photos' contrasts are
        // seen, their mean is not), up to the noise's share and the spread of the means.
        let (g, b) = simulated(7, 0.01, 0.02, 1e-3);
        let marginal = marginalise(&g, &b, 1, PHOTOS, SMALLEST_SCALE).unwrap();
        let [p, l] = marginal.root_mean_square;
        let expected = l * l + p * p / PHOTOS as f64;
        let added = marginal.added_covariance[(0, 0)];
        assert!((added / expected - 1.0).abs() < 0.05, "{added} {expected}");
    }

    #[test]
    fn a_stated_floor_widens_even_photos_without_a_discrepancy() {
        // Pure noise, but the user states that the model errs by at least 1% per function:
        // the constant's variance grows by at least the floor's square (the lobe's degree-0
        // term; the photo offsets' mean adds a ninth of it again).
        let floor = 0.01;
        let (g, b) = simulated(3, 0.0, 0.0, 1e-3);
        let marginal = marginalise(&g, &b, 1, PHOTOS, floor).unwrap();
        assert!(marginal.root_mean_square.iter().all(|&s| s >= floor));
        let added = marginal.added_covariance[(0, 0)];
        assert!(added >= floor * floor, "{added}");
        assert!(added < 10.0 * floor * floor, "{added}");
    }

    #[test]
    fn without_a_discrepancy_the_coordinate_barely_widens() {
        // Pure noise: the fitted scales are at the noise's own level and the constant's
        // standard deviation grows by less than the bound of 3x on sets without
        // mismatch, in the median of 20 sets.
        let mut widening: Vec<f64> = (0..20)
            .map(|seed| {
                let (g, b) = simulated(100 + seed, 0.0, 0.0, 1e-3);
                let added = marginalise(&g, &b, 1, PHOTOS, SMALLEST_SCALE)
                    .unwrap()
                    .added_covariance;
                let model = g
                    .view((0, 0), (1, 1))
                    .into_owned()
                    .cholesky()
                    .unwrap()
                    .inverse();
                (1.0 + added[(0, 0)] / model[(0, 0)]).sqrt()
            })
            .collect();
        widening.sort_by(f64::total_cmp);
        eprintln!("{widening:?}");
        assert!(widening[10] < 3.0, "{widening:?}");
    }

    #[test]
    fn the_lobe_basis_is_orthonormal_and_starts_with_the_parameter_directions() {
        let s: Vec<f64> = (0..200).map(|i| (i as f64 / 199.0).powi(2) * 0.3).collect();
        let raw: Vec<f64> = s.iter().map(|s| (1.0 - s).powi(4)).collect();
        let total: f64 = raw.iter().sum();
        let w: Vec<f64> = raw.iter().map(|w| w / total).collect();
        let dot = |u: &[f64], v: &[f64]| -> f64 {
            u.iter().zip(v).zip(&w).map(|((u, v), w)| u * v * w).sum()
        };
        let check = |basis: &[Vec<f64>]| {
            for (a, u) in basis.iter().enumerate() {
                for (c, v) in basis.iter().enumerate() {
                    let expected = if a == c { 1.0 } else { 0.0 };
                    assert!((dot(u, v) - expected).abs() < 1e-9, "{a} {c} {}", dot(u, v));
                }
            }
        };
        let plain = lobe_basis(&s, &raw, &[]);
        assert_eq!(plain.len(), LOBE_TERMS);
        check(&plain);
        // A scale (constant) and GGX's ln-alpha direction (-2 + 4 s, linear) span the first two
        // Legendre polynomials, which are then dropped; the twice-repeated scale is kept once.
        let constant = vec![1.0; s.len()];
        let ln_alpha: Vec<f64> = s.iter().map(|s| -2.0 + 4.0 * s).collect();
        let with = lobe_basis(
            &s,
            &raw,
            &[constant.clone(), constant.clone(), ln_alpha.clone()],
        );
        assert_eq!(with.len(), LOBE_TERMS);
        check(&with);
        let norm = dot(&constant, &constant).sqrt();
        assert!(with[0]
            .iter()
            .zip(&constant)
            .all(|(b, c)| (b - c / norm).abs() < 1e-12));
        // ln alpha lies in the span of the first two functions.
        let spanned = dot(&ln_alpha, &with[0]).powi(2) + dot(&ln_alpha, &with[1]).powi(2);
        assert!(
            (spanned / dot(&ln_alpha, &ln_alpha) - 1.0).abs() < 1e-9,
            "{spanned}"
        );
    }

    #[test]
    fn legendre_polynomials_follow_their_recurrence() {
        let t = 0.3;
        let p = legendre(t, 4);
        assert_eq!(p.len(), 4);
        assert!((p[2] - 0.5 * (3.0 * t * t - 1.0)).abs() < 1e-15);
        assert!((p[3] - 0.5 * (5.0 * t * t * t - 3.0 * t)).abs() < 1e-15);
    }
}
