//! Intervals that hold when the model is not exact: the photo-clustered curvature adjustment
//! of the likelihood.
//!
//! The likelihood of [`super::log_posterior`] reads every pixel residual as independent noise.
//! When the model is slightly wrong (another renderer's 0.1% difference, a per-photo exposure
//! error, another NDF tail) the residuals are not independent: they are smooth structure shared
//! by the pixels of a photo, and tens of thousands of pixels then make the posterior far
//! narrower than the parameters' real spread (issue #16: a 95% interval of alpha
//! [0.30004, 0.30055] around a truth of 0.3).
//!
//! Photos are the clusters within which residuals are correlated. With `g_p` the gradient of
//! photo `p`'s log-likelihood at the posterior mode (the photo's score) and `H` the precision of
//! the Laplace approximation, the cluster-robust ("sandwich") covariance of the estimate is
//! `V = H^-1 J H^-1` with `J = P / (P - 1) sum_p (g_p - mean g)(g_p - mean g)^T` (White 1982,
//! "Maximum likelihood estimation of misspecified models", Econometrica 50(1), theorem 3.2;
//! Liang & Zeger 1986, Biometrika 73(1), section 2, for the clustered form and the small-sample
//! factor). Chandler & Bate 2007 ("Inference for clustered data using the independence
//! loglikelihood", Biometrika 94(1), section 3) adjust the log-likelihood so that its curvature
//! at the mode is `V^-1`; Ribatet, Cooley & Davison 2012 (Statistica Sinica 22, section 3.2)
//! sample that adjusted likelihood by MCMC, as done here:
//!
//! `ln L_A(x) = ln L(mode + C (x - mode))`, `C = R^-T S R^T`, `H = R R^T`, `S = M'^-1/2`,
//!
//! where `M = R^-1 J R^-T` is `J` in the coordinates whitened by the model's curvature (the
//! identity when the model is exact, up to the estimate's noise) and `M'` is `M` with its
//! eigenvalues floored at 1. The adjusted curvature is `C^T H C = R M'^-1 R^T`, so the posterior
//! covariance becomes `R^-T M' R^-1`: the sandwich where it is wider than the model's, the
//! model's elsewhere. The floor keeps the adjustment one-sided: with few photos `J` is a noisy
//! estimate (rank at most `P - 1`), and reading its small directions as extra certainty would
//! narrow intervals on exactly the evidence that cannot support it.
//!
//! Clusters only see a model error on which photos or regions disagree. One that every photo
//! shares (another NDF tail, a pixel filter) leaves structure in the residuals instead; with
//! `--model-error discrepancy` (the default) the covariance is also at least the one that a
//! discrepancy term fitted to those residuals implies ([`super::discrepancy`]), composed as
//! the block clusters are.
//!
//! Measured by simulation (`scripts/interval-coverage.sh`, docs/intervals.md): see there for the
//! coverage of each method.

use super::adjustment::Adjustment;
use super::laplace::Laplace;
use super::log_posterior::{central_differences, LogPosterior, FD_STEP};
use nalgebra::{DMatrix, DVector, SymmetricEigen};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Fewest clusters (photos) for which the clustered estimate is made: with two, `J` has rank
/// one and its one direction is the difference of two photos.
pub const MIN_PHOTOS: usize = 3;

/// How `fit --mcmc` accounts for model error (`--model-error`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum ModelError {
    /// The photo-clustered adjustment widened further by a fitted discrepancy term
    /// ([`super::discrepancy`]): the default.
    Discrepancy,
    /// The photo-clustered curvature adjustment alone.
    Photos,
    /// None: intervals assume the model is exact and pixel noise independent.
    None,
}

/// Largest leverage of one photo in the jackknife (the share of the evidence in a direction
/// that it alone carries): caps one photo's Newton step at 10x its sandwich term.
const LEVERAGE_CAP: f64 = 0.9;

/// Relative step of the central differences of the photos' scores (their curvature), wide
/// against the scores' own step [`FD_STEP`].
const CURVATURE_STEP: f64 = 1e-3;

/// Side of the grid of blocks each photo is cut into for the block clusters (so 16 blocks a
/// photo, whatever its resolution).
pub const BLOCKS_PER_SIDE: usize = 4;

/// The sandwich `M = R^-1 J R^-T` of clusters with summed scores `scores` (already whitened by
/// `R^-1`), or `None` with fewer than [`MIN_PHOTOS`] clusters.
fn whitened_sandwich(scores: &[Vec<f64>], d: usize) -> Option<DMatrix<f64>> {
    let n = scores.len();
    if n < MIN_PHOTOS {
        return None;
    }
    let mean: Vec<f64> = (0..d)
        .map(|i| scores.iter().map(|g| g[i]).sum::<f64>() / n as f64)
        .collect();
    let factor = n as f64 / (n - 1) as f64;
    Some(DMatrix::from_fn(d, d, |i, j| {
        factor
            * scores
                .iter()
                .map(|g| (g[i] - mean[i]) * (g[j] - mean[j]))
                .sum::<f64>()
    }))
}

/// `f` of a symmetric matrix through its eigenvalues.
fn spectral(m: &DMatrix<f64>, f: impl Fn(f64) -> f64) -> DMatrix<f64> {
    let eigen = SymmetricEigen::new(m.clone());
    let q = &eigen.eigenvectors;
    q * DMatrix::from_diagonal(&eigen.eigenvalues.map(f)) * q.transpose()
}

/// The adjustment at `laplace.mean` from the scores of photos and of blocks within photos, or
/// `None` with fewer than [`MIN_PHOTOS`] photos in the likelihood.
///
/// Photos are the clusters of errors shared by a photo (its exposure, its light, its
/// registration); blocks (a [`BLOCKS_PER_SIDE`]-square grid over each photo) are the clusters
/// of errors shared by a neighbourhood (a lobe shape or pixel filter the model does not have,
/// which photos of one geometry share and so do not disagree on). The adjusted covariance is
/// at least each of the two: `A = floor(M_photos)`, then
/// `M' = A^1/2 floor(A^-1/2 M_blocks A^-1/2) A^1/2`, in the whitened coordinates.
///
/// With `discrepancy` (the least scale of the term), the covariance is also at least the one of
/// the fitted discrepancy term ([`super::discrepancy`]), composed the same way.
pub fn adjust(
    target: &LogPosterior,
    laplace: &Laplace,
    discrepancy: Option<f64>,
) -> Option<Adjustment> {
    let mode = &laplace.mean;
    let d = mode.len();
    let layout = target.objective.layout();
    let records = target.objective.records();
    let block_of = |&(photo, offset): &(usize, usize)| {
        let span = &records.photos[photo];
        (
            photo,
            offset / span.width * BLOCKS_PER_SIDE / span.height,
            offset % span.width * BLOCKS_PER_SIDE / span.width,
        )
    };
    let whiten = |g: Vec<f64>| laplace.precision.solve_lower(&g);
    let scores = pixel_scores(target, mode);
    let photo_scores = cluster_sums(&scores, layout.place.iter().map(|p| p.0));
    let photo_count = photo_scores.len();
    if photo_count < MIN_PHOTOS {
        return None;
    }
    let block_scores = cluster_sums(&scores, layout.place.iter().map(block_of));
    let by_block = whitened_sandwich(&block_scores.into_iter().map(whiten).collect::<Vec<_>>(), d)?;
    let by_photo = photo_jackknife(target, laplace, photo_scores);
    if by_photo
        .iter()
        .chain(by_block.iter())
        .any(|v| !v.is_finite())
    {
        return None;
    }
    let mut adjusted = at_least_both(&DMatrix::identity(d, d), &by_photo);
    adjusted = at_least_both(&adjusted, &by_block);
    let term = discrepancy.and_then(|floor| super::discrepancy::at_mode(target, mode, floor));
    if let Some(term) = &term {
        // R^T V R: the added covariance in the coordinates whitened by the model's curvature.
        let r = DMatrix::from_row_slice(d, d, &laplace.precision.lower);
        let whitened = DMatrix::identity(d, d) + r.transpose() * &term.added_covariance * r;
        adjusted = at_least_both(&adjusted, &whitened);
    }
    let inverse_root = spectral(&adjusted, |l| 1.0 / l.sqrt());
    let root = spectral(&adjusted, f64::sqrt);
    // Columns of C = R^-T S R^T e_j.
    let mut matrix = vec![0.0; d * d];
    for j in 0..d {
        let mut e = vec![0.0; d];
        e[j] = 1.0;
        let s = &inverse_root * DVector::from_vec(laplace.precision.transpose_times(&e));
        let column = laplace.precision.solve_transpose(s.as_slice());
        for i in 0..d {
            matrix[i * d + j] = column[i];
        }
    }
    // sd_i^2 = |R^-1 e_i|^2 (model), |M'^1/2 R^-1 e_i|^2 (adjusted).
    let widening = (0..d)
        .map(|i| {
            let mut e = vec![0.0; d];
            e[i] = 1.0;
            let a = DVector::from_vec(laplace.precision.solve_lower(&e));
            ((&root * &a).norm_squared() / a.norm_squared()).sqrt()
        })
        .collect();
    Some(Adjustment {
        mode: mode.clone(),
        matrix,
        widening,
        photos: photo_count,
        discrepancy: term.map(|t| [t.most_likely, t.root_mean_square]),
    })
}

/// In whitened coordinates, a covariance at least `a` (itself at least the identity) and at
/// least `b`: `a^1/2 floor(a^-1/2 b a^-1/2) a^1/2`, eigenvalues floored at 1.
fn at_least_both(a: &DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    let root = spectral(a, f64::sqrt);
    let inverse_root = spectral(a, |l| 1.0 / l.sqrt());
    let within = spectral(&(&inverse_root * b * &inverse_root), |l| l.max(1.0));
    &root * within * &root
}

/// Sums of `scores` over the clusters named by `keys` (one per score), in key order.
fn cluster_sums<K: Ord>(scores: &[Vec<f64>], keys: impl Iterator<Item = K>) -> Vec<Vec<f64>> {
    let mut sums: BTreeMap<K, Vec<f64>> = BTreeMap::new();
    for (score, key) in scores.iter().zip(keys) {
        let sum = sums.entry(key).or_insert_with(|| vec![0.0; score.len()]);
        sum.iter_mut().zip(score).for_each(|(s, g)| *s += g);
    }
    sums.into_values().collect()
}

/// The delete-one-photo jackknife covariance of the mode, whitened (`R^T V R`), from one Newton
/// step per left-out photo (the linearised jackknife, or CR3 of Bell & McCaffrey 2002, "Bias
/// reduction in standard errors for linear regression with multi-stage samples", Survey
/// Methodology 28(2)): without photo `p` the mode moves by `delta_p = (H - H_p)^-1 g_p`, with
/// `g_p` the photo's score and `H_p` its own curvature (central differences of its score).
/// Unlike the plain sandwich, a photo that carries a large share of the evidence in some
/// direction (leverage `H_p` near `H`) moves the mode by more than `H^-1 g_p`: with nine photos
/// of which a few set a parameter, the sandwich alone was measured to cover F0 in only 64% of
/// sets with per-photo exposure errors. Leverages are capped at [`LEVERAGE_CAP`].
fn photo_jackknife(
    target: &LogPosterior,
    laplace: &Laplace,
    scores: Vec<Vec<f64>>,
) -> DMatrix<f64> {
    let mode = &laplace.mean;
    let d = mode.len();
    let photos = scores.len();
    // curvature[p] row j: d(-score_p)/dx_j, from the photos' scores flattened (photo-major).
    let photo_of = target.objective.layout().place.iter().map(|p| p.0);
    let slopes = central_differences(mode, CURVATURE_STEP, |probe| {
        cluster_sums(&pixel_scores(target, probe), photo_of.clone()).concat()
    });
    let curvature: Vec<DMatrix<f64>> = (0..photos)
        .map(|p| DMatrix::from_fn(d, d, |j, k| -slopes[p * d + k][j]))
        .collect();
    let whiten_columns = |m: &DMatrix<f64>| {
        let mut out = DMatrix::zeros(d, d);
        for k in 0..d {
            let column = laplace.precision.solve_lower(m.column(k).as_slice());
            out.set_column(k, &DVector::from_vec(column));
        }
        out
    };
    let moves: Vec<DVector<f64>> = scores
        .iter()
        .zip(&curvature)
        .map(|(g, h)| {
            // R^-1 H_p R^-T, symmetrised.
            let left = whiten_columns(&h.transpose()).transpose();
            let whitened = whiten_columns(&left);
            let whitened = (&whitened + whitened.transpose()) * 0.5;
            let kept = DMatrix::identity(d, d) - whitened;
            let inverse = spectral(&kept, |l| 1.0 / l.max(1.0 - LEVERAGE_CAP));
            inverse * DVector::from_vec(laplace.precision.solve_lower(g))
        })
        .collect();
    let mean = moves.iter().fold(DVector::zeros(d), |a, m| a + m) / photos as f64;
    let factor = (photos - 1) as f64 / photos as f64;
    moves
        .iter()
        .map(|m| (m - &mean) * (m - &mean).transpose())
        .fold(DMatrix::zeros(d, d), |a, b| a + b)
        * factor
}

/// Per loss pixel: the gradient of its part of `ln L` at `x`, by central differences.
fn pixel_scores(target: &LogPosterior, x: &[f64]) -> Vec<Vec<f64>> {
    central_differences(x, FD_STEP, |probe| target.pixel_log_likelihoods(probe))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pull_back_is_the_adjoint_of_the_map() {
        // <C^T g, v> = <g, C v> for the linear part of `apply`.
        let a = Adjustment {
            mode: vec![0.5, -1.0, 2.0],
            matrix: vec![2.0, 0.3, -0.1, 0.0, 1.5, 0.7, -0.4, 0.2, 3.0],
            widening: vec![1.0; 3],
            photos: 9,
            discrepancy: None,
        };
        let v = [0.3, -0.8, 1.1];
        let g = [1.7, 0.4, -0.6];
        let x: Vec<f64> = a.mode.iter().zip(v).map(|(m, v)| m + v).collect();
        let moved: Vec<f64> = a
            .apply(&x)
            .iter()
            .zip(&a.mode)
            .map(|(y, m)| y - m)
            .collect();
        let lhs: f64 = a.pull_back(&g).iter().zip(v).map(|(p, v)| p * v).sum();
        let rhs: f64 = g.iter().zip(&moved).map(|(g, m)| g * m).sum();
        assert!((lhs - rhs).abs() < 1e-12, "{lhs} {rhs}");
        assert_eq!(a.apply(&a.mode), a.mode);
    }

    #[test]
    fn the_sandwich_of_identical_clusters_is_zero_and_of_too_few_is_none() {
        let same = vec![vec![1.0, 2.0]; 5];
        let m = whitened_sandwich(&same, 2).unwrap();
        assert!(m.iter().all(|v| v.abs() < 1e-15));
        assert!(whitened_sandwich(&same[..2], 2).is_none());
        // Two clusters of +-1 along the first axis among five: J = 5/4 * 2 * 1 in (0, 0).
        let mut spread = vec![vec![0.0, 0.0]; 5];
        spread[0][0] = 1.0;
        spread[1][0] = -1.0;
        let m = whitened_sandwich(&spread, 2).unwrap();
        assert!((m[(0, 0)] - 2.5).abs() < 1e-12 && m[(1, 1)].abs() < 1e-15);
    }
}
