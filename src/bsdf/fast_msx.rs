//! `fast-msx`: Fast-MSX (Rosales et al. 2023, `papers/rosales2023-fast-msx.md`), the single-bounce
//! BRDF plus an analytic second-bounce lobe from asymmetric V-cavities.
//!
//! | parameter | unit / range | meaning |
//! | --- | --- | --- |
//! | `alpha` (`ax`, `ay`) | > 0 | roughness of both the direct lobe and `D_I` |
//! | `ndf`, `height`, `fresnel` | as `single` | the direct lobe is exactly `single` |
//!
//! Deterministic, analytic, biased (an approximation of multiple scattering, not energy
//! conserving), not reciprocal (`G_I` masks only toward the camera, sec. 4.2.1).
//!
//! **Verdict on its energy (pinned in `published_quirks.rs`):** the lobe gains energy as printed.
//! At GGX alpha 0.3 and normal incidence the single lobe holds 0.877 and the added lobe 0.374
//! (white albedo 1.251); the scale that would fill the real shortfall is 0.33 at alpha 0.3 and
//! 1.31 at alpha 1, so no constant fixes it; the isotropic GGX maximum is 1.78 (alpha 0.3, 89.5
//! degrees). **Difference from the paper:** its direct lobe uses the uncorrelated Smith G2; ours
//! is `single` with the material's height model (default correlated; `--height uncorrelated`
//! gives the paper's lobe), so one material file means the same microsurface in every model.
//!
//! With `l = wi`
//! (light) and `v = wo` (camera):
//! - cavity axis `c = normalize(h + n)` (eq. 9), half opening `theta_m = (pi - acos(v.l)) / 4`
//!   (eq. 5 and 16, as in Algorithm 1);
//! - `G_I = 1 - max(0, sin(theta_vc - theta_m) / sin(theta_vc + theta_m))` (eq. 17, Algorithm 1);
//! - `D_I` = the surface's distribution at a normal tilted by `theta_m` toward the azimuth of
//!   `h` (eq. 18 is GGX at `cos theta_m`; for Beckmann and anisotropic surfaces the kernel's `D`
//!   at that normal is **our extension**, not in the paper);
//! - `F_I = F(wi.h)^2` (eq. 19);
//! - `f_I = D_I G_I F_I / (2 c.v)` (eq. 20), added to `f_single`.
//!
//! The angles depend on the directions only and are computed in `f64`, so dual numbers carry
//! derivatives with respect to roughness and Fresnel without passing through `acos` at 1
//! (the flash geometry `wi = wo`). Sampling: [`super::lobe_mixture`] (the paper uses the visible
//! normals of the direct lobe, sec. 4.4; the mixture adds a cosine lobe so the weight of the
//! broader indirect lobe stays bounded).

use super::lobe_mixture::AddedLobe;
use super::single::SingleBounce;
use super::ScalarBrdf;

use crate::random::Rng;
use crate::scalar::{Real, Rgb, Vec3};
use std::f64::consts::PI;

#[derive(Clone, Copy, Debug)]
pub struct FastMsx<T> {
    pub single: SingleBounce<T>,
}

/// The direction-only part of `f_I` (eq. 16-17, 20) for light `l` and camera `v`: the tilted
/// normal `m_I` at which `D_I` is read (`theta_m` toward the azimuth of `h`) and
/// `G_I / (2 c.v)`; `None` where the lobe vanishes (`G_I <= 0` or `c.v <= 0`). Shared by the
/// scalar lobe and the batch kernel, which prepares it once per record.
pub fn indirect_geometry(l: Vec3<f64>, v: Vec3<f64>) -> Option<([f64; 3], f64)> {
    let h = (l + v).normalize();
    let c = (h + Vec3::new(0.0, 0.0, 1.0)).normalize();
    let cos_vc = c.dot(v).clamp(-1.0, 1.0);
    let theta_vc = cos_vc.acos();
    let theta_m = (PI - v.dot(l).clamp(-1.0, 1.0).acos()) * 0.25;
    let g_i = 1.0 - ((theta_vc - theta_m).sin() / (theta_vc + theta_m).sin()).max(0.0);
    if g_i <= 0.0 || cos_vc <= 0.0 {
        return None;
    }
    let horizontal = (h.x * h.x + h.y * h.y).sqrt();
    let (cos_phi, sin_phi) = if horizontal > 0.0 {
        (h.x / horizontal, h.y / horizontal)
    } else {
        (1.0, 0.0)
    };
    let m_i = [
        theta_m.sin() * cos_phi,
        theta_m.sin() * sin_phi,
        theta_m.cos(),
    ];
    Some((m_i, g_i / (2.0 * cos_vc)))
}

impl<T: Real> FastMsx<T> {
    /// The indirect second-bounce lobe `f_I` (eq. 20), 1/sr.
    pub fn indirect(&self, wi: Vec3<T>, wo: Vec3<T>) -> Rgb<T> {
        let zero = Rgb::splat(T::zero());
        if wi.z.re64() <= 0.0 || wo.z.re64() <= 0.0 {
            return zero;
        }
        let (l, v) = (
            Vec3::<f64>::from_f64(wi.re()),
            Vec3::<f64>::from_f64(wo.re()),
        );
        let Some(geometry) = indirect_geometry(l, v) else {
            return zero;
        };
        self.indirect_from(geometry, l.dot((l + v).normalize()))
    }

    /// [`FastMsx::indirect`] from its direction-only part, `indirect_geometry(l, v)` where it
    /// is `Some`, and `wi.h`: for callers that read the lobe at several roughness values for
    /// one pair of directions (the render plan's proxy lobes).
    pub fn indirect_from(&self, (m_i, scale): ([f64; 3], f64), cos_d: f64) -> Rgb<T> {
        let d_i = self.single.microfacet.d(Vec3::from_f64(m_i));
        let f = self.single.fresnel.eval(T::c(cos_d));
        (f * f).scale(d_i * T::c(scale))
    }

    /// `(f_single, f_I)`.
    pub fn eval_split(&self, wi: Vec3<T>, wo: Vec3<T>) -> (Rgb<T>, Rgb<T>) {
        (self.single.eval(wi, wo), self.indirect(wi, wo))
    }
}

impl<T: Real> ScalarBrdf<T> for FastMsx<T> {
    fn eval_split(&self, wi: Vec3<T>, wo: Vec3<T>, _rng: &mut Rng) -> (Rgb<T>, Rgb<T>) {
        Self::eval_split(self, wi, wo)
    }

    fn eval_multi(&self, wi: Vec3<T>, wo: Vec3<T>, _rng: &mut Rng) -> Rgb<T> {
        self.indirect(wi, wo)
    }
}

impl AddedLobe for FastMsx<f64> {
    fn single_lobe(&self) -> &SingleBounce<f64> {
        &self.single
    }
    fn added_lobe(&self, wi: Vec3<f64>, wo: Vec3<f64>) -> [f64; 3] {
        self.indirect(wi, wo).0
    }
}
