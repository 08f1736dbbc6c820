//! Coarser copies of shading records for coarse-to-fine fitting: each level halves every photo's
//! resolution, so a fit can find the basin on a quarter of the work and refine at full size.
//!
//! | quantity of a coarse pixel | from its 2 x 2 block of fine pixels |
//! | --- | --- |
//! | target | mean of the four targets |
//! | weight | mean of the four weights, or 0 if any of them is excluded (its radiance would enter the prediction but not the target) |
//! | sub-samples | the same count `k * k`; coarse cell `(sx, sy)` of a `k x k` grid over the block takes the fine sub-sample nearest to its centre, so the geometry stays exactly that of real pixel footprints |
//!
//! An odd last row or column is dropped. The coarse records evaluate 4x fewer sub-samples.

use super::{PhotoSpan, ShadingRecords};

/// For coarse cell `s` of a `k`-cell axis over a 2-pixel block: (child 0 or 1, its cell).
fn nearest_fine_cell(s: usize, k: usize) -> (usize, usize) {
    let u = 2.0 * (s as f64 + 0.5) / k as f64;
    let child = (u as usize).min(1);
    let local = (((u - child as f64) * k as f64) as usize).min(k - 1);
    (child, local)
}

impl ShadingRecords {
    /// The records at half the resolution of every photo (see the module docs); `None` when
    /// some photo is smaller than 2 x 2.
    pub fn coarsened(&self) -> Option<ShadingRecords> {
        if self.photos.iter().any(|s| s.width < 2 || s.height < 2) {
            return None;
        }
        let spp = self.samples_per_pixel;
        let k = (spp as f64).sqrt().round() as usize;
        let mut out = ShadingRecords {
            samples_per_pixel: spp,
            excluded: self.excluded,
            ..ShadingRecords::default()
        };
        for span in &self.photos {
            let (width, height) = (span.width / 2, span.height / 2);
            out.photos.push(PhotoSpan {
                stem: span.stem.clone(),
                width,
                height,
                first_pixel: out.pixel_count(),
            });
            for y in 0..height {
                for x in 0..width {
                    let children = [(0, 0), (1, 0), (0, 1), (1, 1)]
                        .map(|(dx, dy)| span.first_pixel + (2 * y + dy) * span.width + 2 * x + dx);
                    let weights = children.map(|c| self.weight[c]);
                    let weight = if weights.iter().all(|&w| w > 0.0) {
                        weights.iter().sum::<f64>() / 4.0
                    } else {
                        0.0
                    };
                    let target = [0, 1, 2]
                        .map(|c| children.iter().map(|&p| self.target[p][c]).sum::<f64>() / 4.0);
                    out.target.push(target);
                    out.weight.push(weight);
                    for sy in 0..k {
                        let (cy, ly) = nearest_fine_cell(sy, k);
                        for sx in 0..k {
                            let (cx, lx) = nearest_fine_cell(sx, k);
                            let s = children[cy * 2 + cx] * spp + ly * k + lx;
                            out.wi.push(self.wi[s]);
                            out.wo.push(self.wo[s]);
                            out.irradiance.push(self.irradiance[s]);
                            if let Some(&uv) = self.uv.get(s) {
                                out.uv.push(uv);
                            }
                        }
                    }
                }
            }
        }
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One 4x2 photo with 4 sub-samples per pixel; sub-sample `s` has wi.x = s, pixel p has
    /// target p.
    fn records() -> ShadingRecords {
        let spp = 4;
        let n = 8;
        ShadingRecords {
            photos: vec![PhotoSpan {
                stem: "a".into(),
                width: 4,
                height: 2,
                first_pixel: 0,
            }],
            samples_per_pixel: spp,
            wi: (0..n * spp).map(|s| [s as f64, 0.0, 1.0]).collect(),
            wo: vec![[0.0, 0.0, 1.0]; n * spp],
            irradiance: vec![[1.0; 3]; n * spp],
            target: (0..n).map(|p| [p as f64; 3]).collect(),
            weight: vec![1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.0, 1.0],
            ..ShadingRecords::default()
        }
    }

    #[test]
    fn blocks_average_targets_and_exclude_partly_excluded_blocks() {
        let coarse = records().coarsened().unwrap();
        assert_eq!((coarse.photos[0].width, coarse.photos[0].height), (2, 1));
        // Block 0 = fine pixels 0, 1, 4, 5; block 1 = 2, 3, 6, 7 (pixel 6 excluded).
        assert_eq!(coarse.target, vec![[2.5; 3], [4.5; 3]]);
        assert_eq!(coarse.weight, vec![1.0, 0.0]);
    }

    #[test]
    fn sub_samples_are_the_fine_ones_nearest_each_coarse_cell() {
        // k = 2: coarse cell 0 of an axis sits at block position 0.5, the fine cell 1 of child
        // 0 (at 0.75); coarse cell 1 at 1.5 is fine cell 1 of child 1 (at 1.75).
        assert_eq!(nearest_fine_cell(0, 2), (0, 1));
        assert_eq!(nearest_fine_cell(1, 2), (1, 1));
        let coarse = records().coarsened().unwrap();
        let fine_pixel = |s: usize| coarse.wi[s][0] as usize / 4;
        // Block 0's four coarse sub-samples come from its four children, one each.
        let mut children: Vec<usize> = (0..4).map(fine_pixel).collect();
        children.sort();
        assert_eq!(children, vec![0, 1, 4, 5]);
        // Every sub-sample is a real one of the fine records.
        let fine = records();
        for s in 0..coarse.wi.len() {
            assert!(fine.wi.contains(&coarse.wi[s]));
        }
    }

    #[test]
    fn a_photo_smaller_than_a_block_cannot_be_coarsened() {
        let mut r = records();
        r.photos[0].height = 1;
        assert!(r.coarsened().is_none());
    }
}
