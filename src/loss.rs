//! Image losses on linear radiance, over the weighted pixels of a photo set.
//!
//! | loss | per pixel and channel | use |
//! | --- | --- | --- |
//! | `l2` | `(p - t)^2` | Gaussian noise of constant level; the default |
//! | `log-l1` | `rho(ln(1 + p/s) - ln(1 + t/s))`, `s` = mean target radiance, `rho(x) = sqrt(x^2 + d^2) - d` with `d = 1e-3` | highlights and dark regions on an equal footing (robust to outliers) |
//!
//! `rho` is the pseudo-Huber (Charbonnier) form of `|x|`: equal to it within `d` = 0.1% of
//! relative radiance, and differentiable at the optimum, where the kink of `|x|` stalls
//! gradient-based solvers (plain L1 left the red F0 of the copper set at 0.982 instead of 0.935).
//!
//! Both are weighted means (`sum w loss / (3 sum w)`), so their values compare across photo sets
//! of different sizes.

use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum LossKind {
    #[default]
    L2,
    LogL1,
}

/// Width `d` of the pseudo-Huber smoothing of the log-L1 loss, in log units.
const LOG_L1_SMOOTHING: f64 = 1e-3;

/// A loss bound to the targets and weights of the pixels it compares.
pub struct Loss<'a> {
    pub kind: LossKind,
    pub target: &'a [[f64; 3]],
    pub weight: &'a [f64],
    /// Radiance scale of `log-l1` (mean target radiance).
    scale: f64,
}

impl<'a> Loss<'a> {
    pub fn new(kind: LossKind, target: &'a [[f64; 3]], weight: &'a [f64]) -> Self {
        let wsum: f64 = weight.iter().sum();
        let mean = target
            .iter()
            .zip(weight)
            .map(|(t, w)| w * (t[0] + t[1] + t[2]) / 3.0)
            .sum::<f64>()
            / wsum.max(f64::MIN_POSITIVE);
        Loss {
            kind,
            target,
            weight,
            scale: mean.max(1e-12),
        }
    }

    /// Per-pixel loss of one prediction (summed over channels, unweighted).
    pub fn pixel(&self, predicted: [f64; 3], index: usize) -> f64 {
        let t = self.target[index];
        (0..3)
            .map(|c| match self.kind {
                LossKind::L2 => (predicted[c] - t[c]).powi(2),
                LossKind::LogL1 => {
                    let x =
                        (predicted[c] / self.scale).ln_1p() - (t[c].max(0.0) / self.scale).ln_1p();
                    (x * x + LOG_L1_SMOOTHING * LOG_L1_SMOOTHING).sqrt() - LOG_L1_SMOOTHING
                }
            })
            .sum()
    }

    /// Derivative of [`Loss::pixel`] with respect to each channel of the prediction.
    fn pixel_gradient(&self, predicted: [f64; 3], index: usize) -> [f64; 3] {
        let t = self.target[index];
        [0, 1, 2].map(|c| match self.kind {
            LossKind::L2 => 2.0 * (predicted[c] - t[c]),
            LossKind::LogL1 => {
                let x = (predicted[c] / self.scale).ln_1p() - (t[c].max(0.0) / self.scale).ln_1p();
                // d rho / d x = x / sqrt(x^2 + d^2); d x / d p = 1 / (s + p).
                x / (x * x + LOG_L1_SMOOTHING * LOG_L1_SMOOTHING).sqrt()
                    / (self.scale + predicted[c])
            }
        })
    }

    /// `d value / d predicted` per pixel and channel, with the weighting of [`Loss::value`]
    /// (zero for pixels of zero weight): the first factor of the chain rule of exact gradients.
    pub fn gradient(&self, predicted: &[[f64; 3]]) -> Vec<[f64; 3]> {
        let wsum: f64 = self.weight.iter().filter(|w| **w > 0.0).sum();
        let norm = 1.0 / (3.0 * wsum.max(f64::MIN_POSITIVE));
        predicted
            .iter()
            .zip(self.weight)
            .enumerate()
            .map(|(i, (p, w))| {
                if *w > 0.0 {
                    self.pixel_gradient(*p, i).map(|g| w * norm * g)
                } else {
                    [0.0; 3]
                }
            })
            .collect()
    }

    /// Weighted mean loss of a full prediction (same length as the targets).
    pub fn value(&self, predicted: &[[f64; 3]]) -> f64 {
        let (mut sum, mut wsum) = (0.0, 0.0);
        for (i, (p, w)) in predicted.iter().zip(self.weight).enumerate() {
            if *w > 0.0 {
                sum += w * self.pixel(*p, i);
                wsum += w;
            }
        }
        sum / (3.0 * wsum.max(f64::MIN_POSITIVE))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn losses_vanish_at_the_target_and_grow_away_from_it() {
        let target = vec![[0.5, 1.0, 2.0], [0.1, 0.2, 0.3]];
        let weight = vec![1.0, 1.0];
        for kind in [LossKind::L2, LossKind::LogL1] {
            let loss = Loss::new(kind, &target, &weight);
            assert_eq!(loss.value(&target), 0.0);
            let near: Vec<_> = target.iter().map(|t| t.map(|v| v * 1.01)).collect();
            let far: Vec<_> = target.iter().map(|t| t.map(|v| v * 1.5)).collect();
            assert!(loss.value(&near) > 0.0 && loss.value(&near) < loss.value(&far));
        }
        // Zero-weight pixels do not count.
        let loss = Loss::new(LossKind::L2, &target, &[1.0, 0.0]);
        assert_eq!(loss.gradient(&[target[0], [9.0; 3]]), vec![[0.0; 3]; 2]);
        let loss = Loss::new(LossKind::L2, &target, &[1.0, 0.0]);
        assert_eq!(loss.value(&[target[0], [9.0; 3]]), 0.0);
    }

    #[test]
    fn gradient_matches_central_differences_of_the_value() {
        let target = vec![[0.5, 1.0, 2.0], [0.1, 0.2, 0.3], [0.05, 0.0, 4.0]];
        let weight = vec![1.0, 0.5, 2.0];
        let predicted = vec![[0.6, 0.9, 2.5], [0.1, 0.35, 0.2], [0.01, 0.02, 3.0]];
        for kind in [LossKind::L2, LossKind::LogL1] {
            let loss = Loss::new(kind, &target, &weight);
            let gradient = loss.gradient(&predicted);
            for i in 0..predicted.len() {
                for c in 0..3 {
                    let h = 1e-6 * predicted[i][c].max(1e-3);
                    let mut probe = predicted.clone();
                    probe[i][c] += h;
                    let plus = loss.value(&probe);
                    probe[i][c] -= 2.0 * h;
                    let minus = loss.value(&probe);
                    let fd = (plus - minus) / (2.0 * h);
                    assert!(
                        (gradient[i][c] - fd).abs() <= 1e-6 * fd.abs().max(1e-3),
                        "{kind:?} pixel {i} channel {c}: {} vs {fd}",
                        gradient[i][c]
                    );
                }
            }
        }
    }
}
