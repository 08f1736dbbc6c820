//! `single`: the single-bounce microfacet BRDF of Walter et al. 2007 ("Microfacet Models for
//! Refraction through Rough Surfaces", eq. 20), with Smith masking-shadowing.
//!
//! | parameter | unit / range | meaning |
//! | --- | --- | --- |
//! | `alpha` (`ax`, `ay`) | > 0, 1e-4 to 3 tested | microfacet roughness (not perceptual roughness: `alpha = r^2`) |
//! | `ndf` | `ggx`, `beckmann` | distribution of normals |
//! | `height` | `correlated`, `uncorrelated` | G2 form (Mitsuba 3 uses uncorrelated) |
//! | `fresnel` | white, Schlick, conductor, dielectric | reflectance of a microfacet |
//!
//! Deterministic and analytic; reciprocal; loses the energy of paths with two or more bounces
//! (white albedo below 1, falling with roughness). `f = F(wi.h) D(h) G2 / (4 wi.z wo.z)` with
//! `h = normalize(wi + wo)`, evaluated as `F D / (4 (G2 / (wi.z wo.z))^-1)` through
//! [`Microfacet::g2_over_cosines`] so it stays finite at grazing angles. Sampling draws `h` from
//! the visible normals of `wi` (Heitz 2018), with weight `F G2 / G1(wi)`.

use super::{Brdf, BrdfSample, BrdfValue, ScalarBrdf};

use crate::microfacet::{Fresnel, Height, Microfacet};
use crate::random::Rng;
use crate::scalar::{Real, Rgb, Vec3};

/// The single-bounce model, generic over the scalar so the fitter can differentiate it.
#[derive(Clone, Copy, Debug)]
pub struct SingleBounce<T> {
    pub microfacet: Microfacet<T>,
    pub fresnel: Fresnel<T>,
    pub height: Height,
}

impl<T: Real> SingleBounce<T> {
    /// `f(wi, wo)` in 1/sr; zero unless both directions are strictly above the surface.
    #[inline]
    pub fn eval(&self, wi: Vec3<T>, wo: Vec3<T>) -> Rgb<T> {
        if wi.z.re64() <= 0.0 || wo.z.re64() <= 0.0 {
            return Rgb::splat(T::zero());
        }
        let h = (wi + wo).normalize();
        let scalar = self.microfacet.d(h)
            * self.microfacet.g2_over_cosines(wi, wo, self.height)
            * T::c(0.25);
        self.fresnel.eval(wi.dot(h)).scale(scalar)
    }

    /// Draw `wo` by reflecting `wi` about a visible normal; returns `(wo, F G2 / G1(wi))`.
    pub fn sample_weighted(&self, wi: Vec3<T>, u: [f64; 2]) -> Option<(Vec3<T>, Rgb<T>)> {
        if wi.z.re64() <= 0.0 {
            return None;
        }
        let m = self.microfacet.sample_visible(wi, u);
        let wo = wi.reflect(m);
        if wo.z.re64() <= 0.0 {
            return None;
        }
        // G2 / G1(wi) = (G2 / (wi.z wo.z)) * wo.z * A(wi).
        let ratio = self.microfacet.g2_over_cosines(wi, wo, self.height)
            * wo.z
            * self.microfacet.projected_area(wi);
        Some((wo, self.fresnel.eval(wi.dot(m)).scale(ratio)))
    }

    /// Density of the sampled `wo`: `D_wi(h) / (4 wo.h)`.
    pub fn pdf(&self, wi: Vec3<T>, wo: Vec3<T>) -> T {
        if wi.z.re64() <= 0.0 || wo.z.re64() <= 0.0 {
            return T::zero();
        }
        let h = (wi + wo).normalize();
        self.microfacet.pdf_visible(wi, h) / (T::c(4.0) * wo.dot(h))
    }
}

impl<T: Real> ScalarBrdf<T> for SingleBounce<T> {
    #[inline]
    fn eval_split(&self, wi: Vec3<T>, wo: Vec3<T>, _rng: &mut Rng) -> (Rgb<T>, Rgb<T>) {
        (self.eval(wi, wo), Rgb::splat(T::zero()))
    }

    #[inline]
    fn eval_total(&self, wi: Vec3<T>, wo: Vec3<T>, _rng: &mut Rng) -> Rgb<T> {
        self.eval(wi, wo)
    }
}

impl Brdf for SingleBounce<f64> {
    fn eval(&self, wi: Vec3<f64>, wo: Vec3<f64>, _rng: &mut Rng) -> BrdfValue {
        BrdfValue {
            single: SingleBounce::eval(self, wi, wo).0,
            multi: [0.0; 3],
        }
    }

    fn sample(&self, wi: Vec3<f64>, u: [f64; 2], _rng: &mut Rng) -> Option<BrdfSample> {
        let (wo, weight) = self.sample_weighted(wi, u)?;
        Some(BrdfSample {
            wo,
            weight: weight.0,
            pdf: SingleBounce::pdf(self, wi, wo),
            bounces: 1,
        })
    }

    fn pdf(&self, wi: Vec3<f64>, wo: Vec3<f64>) -> f64 {
        SingleBounce::pdf(self, wi, wo)
    }

    /// `F G2 / G1(wi)` in [0, 1], continuous in `u` (PHYSICS.md "single").
    fn smooth_sample_weight(&self) -> bool {
        true
    }
}
