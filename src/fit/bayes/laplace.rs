//! Laplace approximation of a log density at its mode: a Gaussian `N(mu, H^-1)` with `H` the
//! Hessian of the negative log density, used three ways by the sampler: as the MALA
//! preconditioner, as the map between the coordinates of two models in a between-model move,
//! and as an evidence estimate `ln p(D) ~ ln p(D, mu) + d/2 ln 2 pi - 1/2 ln det H` (MacKay
//! 2003, "Information Theory, Inference, and Learning Algorithms", section 28.1, eq. 28.10).
//!
//! | step | how |
//! | --- | --- |
//! | Hessian | central differences of the gradient, `H_ij = -(g_j(x + h_i e_i) - g_j(x - h_i e_i)) / 2 h_i`, symmetrised |
//! | positive definite | diagonal raised to at least [`PRECISION_FLOOR`], then `+ lambda I` with the smallest `lambda` in {0, 1e-10 max diag, x10, ...} whose Cholesky factor exists |
//! | mode | one Newton step `mu = x + H^-1 g(x)` from the optimiser's point (it minimised the loss, not the posterior, which has the priors' Jacobian terms too), kept if it raises the density |
//! | steps | first pass `h = 1e-4`; second pass at `mu` with `h_i` = half the first pass's posterior sd, clamped to [1e-6, 0.05] |
//!
//! Standard coordinates: `z = R^T (x - mu)` with `H = R R^T`, so `z ~ N(0, I)` under the
//! approximation and `x = mu + R^-T z`.

use super::target::Target;
use crate::fit::cholesky::Cholesky;
use serde::{Deserialize, Serialize};

/// Smallest precision of any coordinate (standard deviation at most 10 in log or logit units,
/// wider than any prior of [`super::log_posterior`]).
pub const PRECISION_FLOOR: f64 = 1e-2;

/// First-pass difference step of the Hessian, in the unbounded coordinates.
const FIRST_STEP: f64 = 1e-4;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Laplace {
    pub mean: Vec<f64>,
    /// Cholesky factor of the (regularised) Hessian of `-ln p` at `mean`.
    pub precision: Cholesky,
    /// `ln p` at `mean`.
    pub log_density: f64,
}

/// Hessian of `-ln p` by central differences of the gradient with per-coordinate steps.
fn hessian(target: &dyn Target, x: &[f64], steps: &[f64]) -> Vec<f64> {
    let d = x.len();
    let mut h = vec![0.0; d * d];
    let mut probe = x.to_vec();
    for i in 0..d {
        probe[i] = x[i] + steps[i];
        let plus = target.gradient(&probe);
        probe[i] = x[i] - steps[i];
        let minus = target.gradient(&probe);
        probe[i] = x[i];
        for j in 0..d {
            h[i * d + j] = -(plus[j] - minus[j]) / (2.0 * steps[i]);
        }
    }
    for i in 0..d {
        for j in 0..i {
            let s = 0.5 * (h[i * d + j] + h[j * d + i]);
            h[i * d + j] = s;
            h[j * d + i] = s;
        }
    }
    h
}

/// Cholesky factor of `h` made positive definite (see the module table).
fn regularised(mut h: Vec<f64>, d: usize) -> Cholesky {
    for v in h.iter_mut() {
        if !v.is_finite() {
            *v = 0.0;
        }
    }
    let largest = (0..d)
        .map(|i| h[i * d + i].abs())
        .fold(PRECISION_FLOOR, f64::max);
    let mut lambda = 0.0;
    loop {
        let mut shifted = h.clone();
        for i in 0..d {
            shifted[i * d + i] = shifted[i * d + i].max(PRECISION_FLOOR) + lambda;
        }
        if let Some(c) = Cholesky::new(&shifted, d) {
            return c;
        }
        lambda = if lambda == 0.0 {
            1e-10 * largest
        } else {
            lambda * 10.0
        };
    }
}

/// Posterior standard deviation of each coordinate under the approximation.
fn standard_deviations(precision: &Cholesky) -> Vec<f64> {
    let d = precision.n;
    (0..d)
        .map(|i| {
            let mut e = vec![0.0; d];
            e[i] = 1.0;
            precision.solve(&e)[i].max(0.0).sqrt()
        })
        .collect()
}

impl Laplace {
    /// The approximation near `start` (the optimiser's answer).
    pub fn at_mode(target: &dyn Target, start: &[f64]) -> Laplace {
        let d = start.len();
        let first = regularised(hessian(target, start, &vec![FIRST_STEP; d]), d);
        let start_density = target.log_density(start);
        let newton: Vec<f64> = start
            .iter()
            .zip(first.solve(&target.gradient(start)))
            .map(|(x, s)| x + s)
            .collect();
        let newton_density = target.log_density(&newton);
        let (mean, log_density) = if newton_density > start_density {
            (newton, newton_density)
        } else {
            (start.to_vec(), start_density)
        };
        let steps: Vec<f64> = standard_deviations(&first)
            .iter()
            .map(|sd| (0.5 * sd).clamp(1e-6, 0.05))
            .collect();
        Laplace {
            precision: regularised(hessian(target, &mean, &steps), d),
            mean,
            log_density,
        }
    }

    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// `z = R^T (x - mu)`.
    pub fn to_standard(&self, x: &[f64]) -> Vec<f64> {
        let centred: Vec<f64> = x.iter().zip(&self.mean).map(|(a, m)| a - m).collect();
        self.precision.transpose_times(&centred)
    }

    /// `x = mu + R^-T z`.
    pub fn from_standard(&self, z: &[f64]) -> Vec<f64> {
        self.precision
            .solve_transpose(z)
            .iter()
            .zip(&self.mean)
            .map(|(a, m)| a + m)
            .collect()
    }

    /// `ln det` of the covariance square root `R^-T` (= -1/2 ln det H).
    pub fn log_det_sqrt_covariance(&self) -> f64 {
        -self.precision.log_det()
    }

    /// Laplace estimate of `ln` of the integral of the density.
    pub fn log_evidence(&self) -> f64 {
        self.log_density
            + 0.5 * self.dim() as f64 * (2.0 * std::f64::consts::PI).ln()
            + self.log_det_sqrt_covariance()
    }

    /// `ln` of this approximation's normal density at `x`, up to the constant `-d/2 ln 2 pi`.
    pub fn log_normal_density(&self, x: &[f64]) -> f64 {
        -0.5 * self.to_standard(x).iter().map(|z| z * z).sum::<f64>()
            - self.log_det_sqrt_covariance()
    }

    /// Index of the approximation in `modes` whose normal density is highest at `x`.
    pub fn nearest(modes: &[Laplace], x: &[f64]) -> usize {
        if modes.len() == 1 {
            return 0;
        }
        (0..modes.len())
            .max_by(|&a, &b| {
                modes[a]
                    .log_normal_density(x)
                    .total_cmp(&modes[b].log_normal_density(x))
            })
            .expect("at least one mode")
    }

    /// Posterior standard deviation of each coordinate.
    pub fn standard_deviations(&self) -> Vec<f64> {
        standard_deviations(&self.precision)
    }
}
