//! The linear map through which an adjusted likelihood is read: `ln L_A(x) = ln L(mode + C (x -
//! mode))` (Chandler & Bate 2007, section 3). [`super::model_error`] makes it; the log posterior
//! ([`super::log_posterior::LogPosterior::with_adjustment`]) reads its likelihood through it.

use serde::{Deserialize, Serialize};

/// Name of the method in the posterior object, without and with the discrepancy term.
const METHOD: [&str; 2] = [
    "photo-clustered sandwich (Chandler & Bate 2007)",
    "photo-clustered sandwich (Chandler & Bate 2007) and fitted discrepancy (Kennedy & O'Hagan 2001)",
];

/// The linear map `x -> mode + C (x - mode)` through which the adjusted likelihood is read.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Adjustment {
    pub mode: Vec<f64>,
    /// `C`, row-major `d x d`.
    pub matrix: Vec<f64>,
    /// Per coordinate: the adjusted posterior standard deviation over the model's (>= 1).
    pub widening: Vec<f64>,
    /// Photos whose scores entered `J`.
    pub photos: usize,
    /// The fitted discrepancy's prior scales (per-photo offset, lobe-shape coefficient): most
    /// likely, then root-mean-square under their posterior; when the term was used.
    pub discrepancy: Option<[[f64; 2]; 2]>,
}

impl Adjustment {
    fn dim(&self) -> usize {
        self.mode.len()
    }

    /// Name of the method that made this adjustment.
    pub fn method(&self) -> &'static str {
        METHOD[usize::from(self.discrepancy.is_some())]
    }

    /// `mode + C (x - mode)`: where the unadjusted likelihood is read.
    pub fn apply(&self, x: &[f64]) -> Vec<f64> {
        let d = self.dim();
        (0..d)
            .map(|i| {
                self.mode[i]
                    + (0..d)
                        .map(|j| self.matrix[i * d + j] * (x[j] - self.mode[j]))
                        .sum::<f64>()
            })
            .collect()
    }

    /// `C^T g`: a gradient at `apply(x)` taken back to `x`.
    pub fn pull_back(&self, g: &[f64]) -> Vec<f64> {
        let d = self.dim();
        (0..d)
            .map(|j| (0..d).map(|i| self.matrix[i * d + j] * g[i]).sum())
            .collect()
    }
}
