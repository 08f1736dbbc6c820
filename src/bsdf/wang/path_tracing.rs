//! Path tracing with next-event estimation at every vertex (Wang 2022 sec. 4.1, eq. 24-26).

use super::*;

impl<T: Real> Wang<T> {
    /// PT estimate of the >= 2-bounce part of `f(wi, wo)` (eq. 25): a walk from `wi` that goes
    /// on past each segment with (nearly) its continuation probability `e_m`, weighted by
    /// `e_m / q` ([`Wang::survives`]), so the throughput is the product of the Fresnel terms
    /// times those ratios, with a next-event connection to `wo` at every vertex `b_m`, `m >= 1`.
    pub(super) fn multi_pt(&self, wi: Vec3<T>, wo: Vec3<T>, rng: &mut Rng) -> [T; 3] {
        let mf = &self.surface.microfacet;
        let height = self.height();
        let mut sum = [T::zero(); 3];
        let mut beta = [T::one(); 3];
        let Some((mut d, f, _)) = self.scatter(-wi, rng) else {
            return sum;
        };
        scale(&mut beta, f.0);
        let mut prev = -wi;
        for _ in 1..self.most_reflections() {
            let seg = segment(mf, height, prev, d);
            // Next-event estimation at b_m closes a path of m + 1 bounces.
            if let Some((f, d4)) = vertex(&self.surface, -d, wo) {
                let c = d4 * seg.kernel * exit_over_cos(mf, height, d, wo);
                for ((s, b), f) in sum.iter_mut().zip(beta).zip(f.0) {
                    *s += b * f * c;
                }
            }
            let Some(q) = Self::survives(seg.cont, rng) else {
                break;
            };
            let Some((next, f, _)) = self.scatter(d, rng) else {
                break;
            };
            let survival = seg.cont / T::c(q);
            scale(&mut beta, f.0.map(|f| f * survival));
            prev = d;
            d = next;
        }
        sum.map(|v| {
            if v.re64().is_finite() && v.re64() > 0.0 {
                v
            } else {
                T::zero()
            }
        })
    }
}
