//! How uniform a fitted region looks (`--region`, `--mask`): one homogeneous material was
//! fitted to it, so where the sample varies, the photo / prediction ratio varies across it.
//!
//! | quantity | definition |
//! | --- | --- |
//! | blocks | the region's bounding box cut into [`GRID`] x [`GRID`] equal blocks in sample coordinates; a block counts when at least [`MIN_PIXELS`] loss pixels (over all photos) see it |
//! | block ratio | `sum_p w_p sum_c t_pc / sum_p w_p sum_c f_pc` over the block's pixels: photo over fit, an albedo-like ratio that is 1 where the fitted material explains the photos |
//! | `ratio_spread` | standard deviation of the block ratios over their mean (coefficient of variation) |
//! | `ratio_range` | smallest and largest block ratio |
//! | `uniform` | `ratio_spread <` [`UNIFORM_SPREAD`]: the blocks agree to within a few percent of albedo |
//!
//! Pixel noise adds about `noise / sqrt(3 n)` to a block of `n` pixels, far below the threshold
//! for the block sizes counted; a printed pattern or a patch boundary inside the region shows
//! up as blocks tens of percent apart.

use crate::shading::region::AppliedRegion;
use crate::shading::ShadingRecords;
use serde::Serialize;

/// Blocks per side of the region's bounding box.
pub const GRID: usize = 8;

/// Fewest loss pixels that make a block count.
pub const MIN_PIXELS: usize = 16;

/// Largest `ratio_spread` of a region read as uniform.
pub const UNIFORM_SPREAD: f64 = 0.05;

/// The uniformity of a fitted region (see the module table).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Uniformity {
    pub blocks: usize,
    pub ratio_spread: f64,
    pub ratio_range: [f64; 2],
    pub uniform: bool,
}

/// The uniformity of the fit whose prediction of every pixel of `records` is `predicted`,
/// over the region of `applied`; `None` when fewer than two blocks count.
pub fn measure(
    records: &ShadingRecords,
    predicted: &[[f64; 3]],
    applied: &AppliedRegion,
) -> Option<Uniformity> {
    let [x0, y0, x1, y1] = applied.bounds;
    let mut sums = vec![(0.0, 0.0, 0usize); GRID * GRID];
    for (p, point) in applied.points.iter().enumerate() {
        let (Some([x, y]), w) = (point, records.weight[p]) else {
            continue;
        };
        if w <= 0.0 {
            continue;
        }
        let cell = |v: f64, lo: f64, hi: f64| {
            (((v - lo) / (hi - lo) * GRID as f64).floor().max(0.0) as usize).min(GRID - 1)
        };
        let block = &mut sums[cell(*y, y0, y1) * GRID + cell(*x, x0, x1)];
        block.0 += w * records.target[p].iter().sum::<f64>();
        block.1 += w * predicted[p].iter().sum::<f64>();
        block.2 += 1;
    }
    let ratios: Vec<f64> = sums
        .iter()
        .filter(|(_, fit, n)| *n >= MIN_PIXELS && *fit > 0.0)
        .map(|(photo, fit, _)| photo / fit)
        .collect();
    if ratios.len() < 2 {
        return None;
    }
    let n = ratios.len() as f64;
    let mean = ratios.iter().sum::<f64>() / n;
    let variance = ratios.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / (n - 1.0);
    let spread = variance.sqrt() / mean;
    Some(Uniformity {
        blocks: ratios.len(),
        ratio_spread: spread,
        ratio_range: [
            ratios.iter().copied().fold(f64::INFINITY, f64::min),
            ratios.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        ],
        uniform: spread < UNIFORM_SPREAD,
    })
}
