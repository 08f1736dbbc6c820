//! The objective of a fit: image loss of the rendered prediction against the photos, as a
//! function of the unbounded coordinates of a [`ParamSpace`], with central finite-difference
//! gradients at a relative step.
//!
//! Only pixels with positive weight are rendered. Stochastic models draw from the per-pixel
//! random streams of a fixed seed (common random numbers), so the objective is a deterministic
//! function of the coordinates and differences and line searches see a smooth surface.

use super::params::ParamSpace;
use crate::loss::{Loss, LossKind};
use crate::render::render_pixels;
use crate::shading::ShadingRecords;
use argmin::core::{CostFunction, Error as ArgminError, Gradient};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

/// Relative step of the central differences (in unbounded coordinates): truncation error
/// ~h^2 = 1e-10, rounding error ~eps/h = 1e-11 relative to the cost.
const FD_STEP: f64 = 1e-5;

pub struct Objective<'a> {
    pub space: ParamSpace,
    records: &'a ShadingRecords,
    /// Indices of the pixels that enter the loss.
    pixels: Vec<usize>,
    target: Vec<[f64; 3]>,
    weight: Vec<f64>,
    kind: LossKind,
    seed: u64,
    /// The loss is divided by this, so optimiser tolerances are relative (L2: mean target^2).
    scale: f64,
    /// Loss evaluations so far (shared with the trace observer).
    pub evaluations: Arc<AtomicUsize>,
    /// Lowest cost seen so far and its coordinates: what an interrupted run still reports.
    pub best: Mutex<(f64, Vec<f64>)>,
}

impl<'a> Objective<'a> {
    pub fn new(space: ParamSpace, records: &'a ShadingRecords, kind: LossKind, seed: u64) -> Self {
        let pixels: Vec<usize> = (0..records.pixel_count())
            .filter(|&p| records.weight[p] > 0.0)
            .collect();
        let target: Vec<[f64; 3]> = pixels.iter().map(|&p| records.target[p]).collect();
        let weight: Vec<f64> = pixels.iter().map(|&p| records.weight[p]).collect();
        let scale = match kind {
            LossKind::L2 => {
                let wsum: f64 = weight.iter().sum();
                (target
                    .iter()
                    .zip(&weight)
                    .map(|(t, w)| w * (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]) / 3.0)
                    .sum::<f64>()
                    / wsum)
                    .max(1e-300)
            }
            LossKind::LogL1 => 1.0,
        };
        Objective {
            space,
            records,
            pixels,
            target,
            weight,
            kind,
            seed,
            scale,
            evaluations: Arc::new(AtomicUsize::new(0)),
            best: Mutex::new((f64::INFINITY, Vec::new())),
        }
    }

    pub fn pixel_count(&self) -> usize {
        self.pixels.len()
    }

    /// Predicted radiance of the loss pixels at coordinates `x`.
    pub fn predict(&self, x: &[f64]) -> Vec<[f64; 3]> {
        render_pixels(
            &self.space.material(x),
            self.records,
            &self.pixels,
            self.seed,
        )
    }

    /// The loss (not normalised) at `x`.
    pub fn loss(&self, x: &[f64]) -> f64 {
        Loss::new(self.kind, &self.target, &self.weight).value(&self.predict(x))
    }

    /// Loss per photo at `x`: (photo index, loss, pixel count).
    pub fn loss_per_photo(&self, x: &[f64]) -> Vec<(usize, f64, usize)> {
        let predicted = self.predict(x);
        let loss = Loss::new(self.kind, &self.target, &self.weight);
        self.records
            .photos
            .iter()
            .enumerate()
            .map(|(i, photo)| {
                let range = photo.first_pixel..photo.first_pixel + photo.width * photo.height;
                let (mut sum, mut wsum, mut count) = (0.0, 0.0, 0);
                for (k, &p) in self.pixels.iter().enumerate() {
                    if range.contains(&p) {
                        sum += self.weight[k] * loss.pixel(predicted[k], k);
                        wsum += self.weight[k];
                        count += 1;
                    }
                }
                (i, sum / (3.0 * wsum.max(f64::MIN_POSITIVE)), count)
            })
            .collect()
    }

    fn normalised_cost(&self, x: &[f64]) -> f64 {
        self.evaluations.fetch_add(1, Ordering::Relaxed);
        let cost = self.loss(x) / self.scale;
        let cost = if cost.is_finite() { cost } else { f64::MAX };
        let mut best = self.best.lock().expect("no panics while holding the lock");
        if cost < best.0 {
            *best = (cost, x.to_vec());
        }
        cost
    }

    /// Undo the normalisation of a cost reported by the optimiser.
    pub fn loss_from_cost(&self, cost: f64) -> f64 {
        cost * self.scale
    }
}

impl CostFunction for &Objective<'_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, x: &Vec<f64>) -> Result<f64, ArgminError> {
        Ok(self.normalised_cost(x))
    }
}

impl Gradient for &Objective<'_> {
    type Param = Vec<f64>;
    type Gradient = Vec<f64>;
    /// Central differences with step `FD_STEP * max(1, |x_i|)`.
    fn gradient(&self, x: &Vec<f64>) -> Result<Vec<f64>, ArgminError> {
        let mut probe = x.clone();
        Ok((0..x.len())
            .map(|i| {
                let h = FD_STEP * x[i].abs().max(1.0);
                probe[i] = x[i] + h;
                let plus = self.normalised_cost(&probe);
                probe[i] = x[i] - h;
                let minus = self.normalised_cost(&probe);
                probe[i] = x[i];
                (plus - minus) / (2.0 * h)
            })
            .collect())
    }
}
