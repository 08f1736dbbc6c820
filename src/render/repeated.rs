//! Repeated geometry: sub-samples whose `(wi, wo)` coincide bit for bit share one evaluation of
//! the BRDF (issue #5, "repeated geometry"). A pixel's radiance is `f(wi, wo)` times its own
//! irradiance, so only the direction pair has to match; exposure brackets and repeated shots
//! (same camera, same light, another exposure) repeat every pair of their photo.
//!
//! | quantity | value |
//! | --- | --- |
//! | key | the 6 direction components, bit for bit (no tolerance: the result is exactly the one of the full evaluation for a deterministic model) |
//! | sub-samples considered | those of the loss pixels with nonzero irradiance |
//! | used when | at most [`WORTHWHILE_FRACTION`] of those sub-samples are distinct; otherwise the indirection costs more than it saves |
//! | stochastic models | one estimate per distinct pair, from a stream of its own, shared by every sub-sample that repeats it: each pixel stays unbiased, their errors become correlated |

use std::collections::HashMap;

use crate::shading::ShadingRecords;

/// The largest fraction of distinct pairs for which deduplication is used.
pub const WORTHWHILE_FRACTION: f64 = 0.75;

/// Random streams of the distinct pairs: this bit is set, so they never meet a pixel's stream.
pub const STREAM_FLAG: u64 = 1 << 63;

/// The distinct direction pairs of a pixel list and, per sub-sample, which one it is.
#[derive(Clone, Debug)]
pub struct Repeated {
    /// Per distinct pair: the first sub-sample (global index) that has it.
    pub firsts: Vec<usize>,
    /// Per sub-sample of the list (pixel `k` owns `k * spp .. (k + 1) * spp`): its pair, or
    /// `u32::MAX` when its irradiance is zero (not evaluated).
    pub pair_of: Vec<u32>,
}

impl Repeated {
    /// The distinct pairs of `pixels`, or `None` when they are not few enough to pay
    /// (see [`WORTHWHILE_FRACTION`]).
    pub fn find(records: &ShadingRecords, pixels: &[usize]) -> Option<Repeated> {
        let spp = records.samples_per_pixel;
        let mut index: HashMap<[u64; 6], u32> = HashMap::new();
        let mut firsts = Vec::new();
        let mut pair_of = Vec::with_capacity(pixels.len() * spp);
        let mut lit = 0usize;
        for &p in pixels {
            for s in p * spp..(p + 1) * spp {
                if records.irradiance[s] == [0.0; 3] {
                    pair_of.push(u32::MAX);
                    continue;
                }
                lit += 1;
                let (wi, wo) = (records.wi[s], records.wo[s]);
                let key = [wi[0], wi[1], wi[2], wo[0], wo[1], wo[2]].map(f64::to_bits);
                let pair = *index.entry(key).or_insert_with(|| {
                    firsts.push(s);
                    (firsts.len() - 1) as u32
                });
                pair_of.push(pair);
            }
        }
        let worthwhile = (firsts.len() as f64) <= WORTHWHILE_FRACTION * lit as f64;
        (worthwhile && lit > 0).then_some(Repeated { firsts, pair_of })
    }

    /// Evaluations saved: sub-samples evaluated through a shared pair minus the pairs.
    pub fn saved(&self) -> usize {
        let lit = self.pair_of.iter().filter(|&&p| p != u32::MAX).count();
        lit - self.firsts.len()
    }
}
