//! `cui`: multiple scattering on the height-correlated Smith microsurface with the segment term
//! of Cui, Pan, Yang, Zhang, Yan & Wang 2023 ("Multiple-bounce Smith Microfacet BRDFs using the
//! Invariance Principle", SIGGRAPH Asia 2023; supplemental material), on the position-free path
//! integral of Wang et al. 2022.
//!
//! | parameter | unit / range | meaning |
//! | --- | --- | --- |
//! | `alpha` (`ax`, `ay`) | > 0, 1e-4 to 3 tested, anisotropy up to 100 | microfacet roughness |
//! | `ndf` | `ggx`, `beckmann` | distribution of normals |
//! | `fresnel` | white, Schlick, conductor, dielectric (reflection only) | reflectance of a microfacet |
//!
//! | property | value |
//! | --- | --- |
//! | kind | stochastic: `single` exact (height-correlated Walter et al. 2007), `multi` a one-path estimate of paths of two or more bounces |
//! | bias | none: `S_k` is exact for the semi-infinite Smith microsurface, so the model is the same as `bitterli` and Heitz et al. 2016 (supp. eq. 7) |
//! | reciprocal | the BRDF is (the segment term is symmetric under path reversal); the unidirectional `eval` estimator is not symmetric per sample, only in expectation |
//! | height model | correlated only; the material's `height` field is ignored |
//! | `sample` | Alg. 2: unbiased, not exact (weight = product of Fresnel terms times `p_exit / P(exit decisions)`) |
//! | `pdf` | approximate ([`super::position_free::mis_pdf`]) |
//!
//! The path contribution is `f(x) = (prod_{i<k} v_i) S_k(d0, ..., dk)` (supp. eq. 1) with the
//! vertex term `v_i = F D(h_i) / (4 |d_i.z|)` (Wang et al. 2022 eq. 2) and the segment term
//! `S_k = p_exit / prod_{i<k} |Lambda(d_i)|` (supp. eq. 7); a path of `k` bounces contributes
//! `f(x) / wo.z` to the BRDF. `eval` is Alg. 3 (walk from `wi` sampling visible normals,
//! `w *= v / pdf = F |Lambda(d)|`, next-event estimation `w v(d_k -> wo) S_{k+1}` at every vertex
//! after the first), `sample` is Alg. 2 (walk until an upward direction is accepted as the exit
//! with probability `G1(d_k) = 1 / (1 + Lambda(d_k))`, weight `prod v S_k / pdf`).
//!
//! Differences from the supplemental, as printed (the derivation is in [`SegmentTerm`]):
//! - Eq. 2's two-term recursion `S_k = S_1(d0, dk) (S_{k-1}(d0..d_{k-1}) + S_{k-1}(d1..dk))`
//!   misses the terms of the paths whose shallowest vertex is in the middle; the invariance
//!   principle (splitting at the shallowest vertex) gives
//!   `S(d_a..d_b) = (sum_{m=a}^{b-1} S(d_a..d_m) S(d_{m+1}..d_b)) / (sigma_a + sigma_b)`, which
//!   reduces to eq. 2 only when no downward direction follows an upward one. Example (down,
//!   up, down, up): eq. 2 gives 0, the exact value is `1 / ((s0 + s1)(s0 + s3)(s2 + s3))`.
//! - Alg. 1 as printed appends each new downward factor after the stored prefix products,
//!   which is exact only while no downward direction follows an upward one (for down, up, down
//!   it returns `1 / ((so + s0)(s0 + s1))` instead of `1 / ((s0 + s1)(s0 + so)(s2 + so))`).
//!   [`SegmentTerm`] keeps suffix products instead: same cost (O(downward directions) per
//!   bounce), all terms positive, exact.
//! - The printed 3-bounce closed form of sec. 1.2 (final line) disagrees with its own first
//!   line; the first line (Bitterli's form) is right and equals our `S_3`.
//! - Alg. 2 writes the exit probability `G1 = 1 / |Lambda(d_k)|`, which exceeds one for
//!   `Lambda < 1`; we use Smith's distant masking `1 / (1 + Lambda(d_k))`.
//! - Alg. 2 and 3 stop at `maxBounce` (biased); here Russian roulette from the remaining
//!   energy ends the walk of `eval` (as in `bitterli`) and `sample` walks until it exits.

use super::position_free::{
    connect, mis_pdf, scatter, signed_lambda, survival, walk_sample, MAX_WALK_BOUNCES,
};
use super::single::SingleBounce;
use super::{BounceCap, Brdf, BrdfSample, BrdfValue, ScalarBrdf};

use crate::microfacet::{Fresnel, Height, Microfacet};
use crate::random::Rng;
use crate::scalar::{Real, Rgb, Vec3};
use rand::Rng as _;

/// The segment term `S_k(d0, ..., d_{k-1}, out)` of a growing path for any exit direction,
/// by dynamic programming (the role of supp. Alg. 1).
///
/// Derivation. Let `H(s) = integral h(z) exp(-s z) dz` be the Laplace transform of the density
/// of the depth of the current collision divided by `prod |Lambda(d_i)|` (so that
/// `S = H(sigma_out)`, supp. eq. 7 and Bitterli & d'Eon eq. 22). Before the first segment
/// `H = 1`. A downward segment of extinction `beta` convolves the depth with an exponential:
/// `H <- H(s) / (s + beta)`. An upward segment of extinction `sigma` gives (Bitterli & d'Eon
/// eq. 11 transformed) `H <- (H(s) - H(sigma)) / (sigma - s)`, a divided difference. Writing
/// `H(s) = sum_r g_r prod_{j=r}^{N} 1 / (s + beta_j)` over the `N` downward extinctions `beta_j`
/// in order, a downward segment appends `beta_{N+1}` and a new term `g_{N+1}` (the constant part
/// of `H`, 1 before the first segment and 0 after), and the Leibniz rule of divided
/// differences, with `(1/(s+b) - 1/(sigma+b)) / (sigma - s) = 1 / ((s+b)(sigma+b))`, gives for
/// an upward segment `g_i <- sum_{r<=i} g_r prod_{j=r}^{i} 1 / (sigma + beta_j)`, a forward
/// accumulation. Every quantity is a sum of positive terms: no cancellation, unlike the
/// hyperexponential form, and `beta_j >= 1` bounds every factor by 1.
#[derive(Clone, Debug, Default)]
pub(crate) struct SegmentTerm<T = f64> {
    beta: Vec<T>,
    g: Vec<T>,
    constant: T,
}

impl<T: Real> SegmentTerm<T> {
    pub(crate) fn new() -> Self {
        SegmentTerm {
            beta: Vec::with_capacity(16),
            g: Vec::with_capacity(16),
            constant: T::one(),
        }
    }

    /// Add a direction by Cui's signed Lambda (`< 0` downward, the extinction is `|s|`).
    pub(crate) fn add(&mut self, s: T) {
        if s.re64() < 0.0 {
            self.beta.push(-s);
            self.g.push(self.constant);
        } else {
            let mut acc = T::zero();
            for (g, beta) in self.g.iter_mut().zip(&self.beta) {
                acc = (acc + *g) / (s + *beta);
                *g = acc;
            }
        }
        self.constant = T::zero();
    }

    /// `H(sigma)`: the segment term of the path so far closed by an upward direction of
    /// extinction `sigma`; with `sigma = 0`, the mass of the depth distribution divided by
    /// `prod |Lambda|`.
    pub(crate) fn eval(&self, sigma: T) -> T {
        let mut acc = T::zero();
        for (g, beta) in self.g.iter().zip(&self.beta) {
            acc = (acc + *g) / (sigma + *beta);
        }
        self.constant + acc
    }
}

/// `S_k(d0, ..., dk)` from Cui's signed Lambdas of the directions; zero unless `d0` is
/// downward and `dk` upward (supp. eq. 2).
#[cfg_attr(not(test), allow(dead_code))]
pub(crate) fn segment_term(lambdas: &[f64]) -> f64 {
    let k = lambdas.len() - 1;
    if lambdas[0] >= 0.0 || lambdas[k] < 0.0 {
        return 0.0;
    }
    let mut s = SegmentTerm::<f64>::new();
    lambdas[..k].iter().for_each(|&l| s.add(l));
    s.eval(lambdas[k])
}

/// The `cui` model (see the module documentation), generic over the scalar: `eval`'s walk
/// takes its random decisions on real parts with a piecewise-constant roulette
/// ([`super::position_free::survival`]), so dual numbers carry unbiased pathwise derivatives.
#[derive(Clone, Copy, Debug)]
pub struct Cui<T = f64> {
    /// Exact single-bounce part, height-correlated.
    pub single: SingleBounce<T>,
    white: SingleBounce<T>,
    cap: BounceCap,
}

impl<T: Real> Cui<T> {
    pub fn new(microfacet: Microfacet<T>, fresnel: Fresnel<T>) -> Self {
        Cui {
            single: SingleBounce {
                microfacet,
                fresnel,
                height: Height::Correlated,
            },
            white: SingleBounce {
                microfacet,
                fresnel: Fresnel::White,
                height: Height::Correlated,
            },
            cap: BounceCap::NONE,
        }
    }

    /// The same model with paths of more than `cap` reflections dropped.
    pub fn with_bounce_cap(self, cap: BounceCap) -> Self {
        Cui { cap, ..self }
    }

    /// Alg. 3 without its first term: an estimate of `f_multi(wi, wo) wo.z`.
    fn walk(&self, wi: Vec3<T>, wo: Vec3<T>, rng: &mut Rng) -> [T; 3] {
        let mf = &self.single.microfacet;
        let fresnel = &self.single.fresnel;
        let mut sum = [T::zero(); 3];
        let d0 = -wi;
        let s0 = signed_lambda(mf, d0);
        let so = signed_lambda(mf, wo);
        if !s0.re64().is_finite() || !so.re64().is_finite() {
            return sum;
        }
        let mut seg = SegmentTerm::new();
        seg.add(s0);
        // w = prod F, lambdas = prod |Lambda(d_t)| over the vertices left so far: together
        // prod v / pdf of the sampled steps.
        let (mut d, mut s_d, mut w, mut lambdas) = (d0, s0, [T::one(); 3], T::one());
        // Step `k` reaches vertex `k`, whose connection closes paths of `k + 1` reflections.
        for _ in 1..self.cap.limit(MAX_WALK_BOUNCES) {
            let u = [rng.random::<f64>(), rng.random::<f64>()];
            let Some(step) = scatter(mf, fresnel, d, u) else {
                break;
            };
            let s = signed_lambda(mf, step.d);
            if !s.re64().is_finite() {
                break;
            }
            (0..3).for_each(|c| w[c] *= step.fresnel[c]);
            lambdas *= s_d.abs();
            (d, s_d) = (step.d, s);
            seg.add(s);
            if let Some((h, c)) = connect(d, wo) {
                let v = mf.d(h) / (T::c(4.0) * d.z.abs());
                let common = lambdas * v * seg.eval(so);
                if common.re64() > 0.0 && common.re64().is_finite() {
                    let f = fresnel.eval(c).0;
                    (0..3).for_each(|ch| sum[ch] += w[ch] * f[ch] * common);
                }
            }
            // Russian roulette from the energy left: mass = prod_{t<=i} |Lambda(d_t)| H(0).
            let mass = lambdas * s.abs() * seg.eval(T::zero());
            let q = survival(w.map(|x| x.re64()), mass.re64());
            if q <= 0.0 {
                break;
            }
            if q < 1.0 {
                if rng.random::<f64>() >= q {
                    break;
                }
                (0..3).for_each(|ch| w[ch] /= T::c(q));
            }
        }
        sum
    }

    /// The multiple-bounce part of `f(wi, wo)`; zero unless both directions are above the
    /// surface.
    fn multiple(&self, wi: Vec3<T>, wo: Vec3<T>, rng: &mut Rng) -> Rgb<T> {
        if wi.z.re64() <= 0.0 || wo.z.re64() <= 0.0 {
            return Rgb::splat(T::zero());
        }
        let multi = self.walk(wi, wo, rng).map(|v| {
            let f = v / wo.z;
            if f.re64().is_finite() {
                f
            } else {
                T::zero()
            }
        });
        Rgb(multi)
    }
}

impl<T: Real> ScalarBrdf<T> for Cui<T> {
    /// The exact single bounce and [`Cui::multiple`].
    fn eval_split(&self, wi: Vec3<T>, wo: Vec3<T>, rng: &mut Rng) -> (Rgb<T>, Rgb<T>) {
        (self.single.eval(wi, wo), self.multiple(wi, wo, rng))
    }

    fn eval_multi(&self, wi: Vec3<T>, wo: Vec3<T>, rng: &mut Rng) -> Rgb<T> {
        self.multiple(wi, wo, rng)
    }
}

impl Cui<f64> {
    /// Alg. 2: returns the exit direction, the weight and the number of bounces.
    fn sample_walk(
        &self,
        wi: Vec3<f64>,
        u_first: [f64; 2],
        rng: &mut Rng,
    ) -> Option<(Vec3<f64>, [f64; 3], u32)> {
        let mf = &self.single.microfacet;
        let fresnel = &self.single.fresnel;
        let d0 = -wi;
        let s0 = signed_lambda(mf, d0);
        if !s0.is_finite() {
            return None;
        }
        let mut seg = SegmentTerm::new();
        seg.add(s0);
        // w = prod F; ratio = prod |Lambda(d_t)| / P(exit decisions so far).
        let (mut d, mut s_d, mut w, mut ratio) = (d0, s0, [1.0; 3], 1.0);
        for bounce in 1..=self.cap.limit(MAX_WALK_BOUNCES) {
            let u = if bounce == 1 {
                u_first
            } else {
                [rng.random(), rng.random()]
            };
            let u_exit: f64 = rng.random();
            let step = scatter(mf, fresnel, d, u)?;
            let s = signed_lambda(mf, step.d);
            if !s.is_finite() {
                return None;
            }
            (0..3).for_each(|c| w[c] *= step.fresnel[c]);
            ratio *= s_d.abs();
            if s >= 0.0 {
                let g1 = 1.0 / (1.0 + s);
                if u_exit < g1 {
                    let weight = ratio * seg.eval(s) / g1;
                    return Some((step.d, w.map(|x| x * weight), bounce));
                }
                ratio /= 1.0 - g1;
            }
            seg.add(s);
            (d, s_d) = (step.d, s);
        }
        None
    }
}

impl Brdf for Cui<f64> {
    fn eval(&self, wi: Vec3<f64>, wo: Vec3<f64>, rng: &mut Rng) -> BrdfValue {
        self.eval_split(wi, wo, rng).into()
    }

    fn eval_multi(&self, wi: Vec3<f64>, wo: Vec3<f64>, rng: &mut Rng) -> [f64; 3] {
        self.multiple(wi, wo, rng).0
    }

    fn sample(&self, wi: Vec3<f64>, u: [f64; 2], rng: &mut Rng) -> Option<BrdfSample> {
        if wi.z <= 0.0 {
            return None;
        }
        walk_sample(&self.white, wi, self.sample_walk(wi, u, rng))
    }

    fn pdf(&self, wi: Vec3<f64>, wo: Vec3<f64>) -> f64 {
        mis_pdf(&self.white, wi, wo)
    }

    fn is_stochastic(&self) -> bool {
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::position_free::checks::{assert_furnace, furnace};
    use crate::bsdf::testing::assert_finite_sweep;

    #[test]
    fn white_furnace() {
        let rows = furnace(
            &|mf| Box::new(Cui::new(mf, Fresnel::White)),
            100_000,
            100_000,
            11,
        );
        assert_furnace("cui", &rows);
    }

    #[test]
    fn segment_term_dp_matches_the_invariance_recursion() {
        // S(a..b) = (sum_{m=a}^{b-1} S(a..m) S(m+1..b)) / (sigma_a + sigma_b), S(a..a) = 1,
        // zero unless d_a is downward and d_b upward: the interval recursion, O(k^3).
        fn by_intervals(l: &[f64]) -> f64 {
            let n = l.len();
            let mut s = vec![vec![0.0; n]; n];
            for (a, row) in s.iter_mut().enumerate() {
                row[a] = 1.0;
            }
            for len in 1..n {
                for a in 0..n - len {
                    let b = a + len;
                    if l[a] >= 0.0 || l[b] < 0.0 {
                        continue;
                    }
                    let sum: f64 = (a..b).map(|m| s[a][m] * s[m + 1][b]).sum();
                    s[a][b] = sum / (l[a].abs() + l[b]);
                }
            }
            s[0][n - 1]
        }
        let mut rng = crate::random::rng_stream(3, 0);
        use rand::Rng as _;
        for k in 1..=8 {
            for _ in 0..300 {
                let l: Vec<f64> = (0..=k)
                    .map(|i| {
                        let x = rng.random_range(0.05..4.0);
                        if i == 0 || (i < k && rng.random::<bool>()) {
                            -1.0 - x
                        } else {
                            x
                        }
                    })
                    .collect();
                let (dp, iv) = (segment_term(&l), by_intervals(&l));
                assert!((dp - iv).abs() <= 1e-13 * iv, "{l:?}: {dp} vs {iv}");
            }
        }
        // Supp. Alg. 1 as printed gives 1/((so+s0)(s0+s1)) for down, up, down, up.
        let (s0, s1, s2, so) = (1.5, 0.7, 2.5, 0.3);
        let exact = 1.0 / ((s0 + s1) * (s0 + so) * (s2 + so));
        assert!((segment_term(&[-s0, s1, -s2, so]) - exact).abs() < 1e-15);
        assert!((1.0 / ((so + s0) * (s0 + s1)) - exact).abs() > 0.1 * exact);
    }

    #[test]
    fn survives_the_finite_sweep() {
        assert_finite_sweep(
            |rng| {
                let (mf, fresnel) = crate::bsdf::testing::random_surface(rng);
                Box::new(Cui::new(mf, fresnel.to_fresnel()))
            },
            1_000_000,
            13,
        );
    }
}
