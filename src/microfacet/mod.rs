//! The Smith microfacet kernel shared by every model: distributions of normals, Lambda with the
//! full-sphere extension, masking-shadowing, visible-normal sampling and its density, Fresnel.
//!
//! One generic code path serves GGX and Beckmann, isotropic and anisotropic. Both are
//! *stretch-invariant* slope distributions (Heitz 2014, "Understanding the Masking-Shadowing
//! Function in Microfacet-Based BRDFs", sec. 5.3), so everything is computed in the stretched
//! configuration `(ax*x, ay*y, z)` where the roughness is 1, and only three functions differ
//! between the two: the unscaled density ([`ggx::density_stretched`],
//! [`beckmann::density_stretched`]), the projected Lambda `|z| * Lambda` ([`ggx::z_lambda`],
//! [`beckmann::z_lambda`]) and the visible-normal sampler in the stretched frame.
//!
//! | quantity | meaning | reference |
//! | --- | --- | --- |
//! | `D(m)` | normal distribution, `integral D(m) m.z dm = 1` | PHYSICS.md |
//! | `Lambda(w)` | Smith Lambda; `Lambda(w) = -1 - Lambda(-w)` for `w.z < 0` | Heitz et al. 2016 sec. 2; Wang 2022 eq. 4 |
//! | `A(w)` | projected visible area `integral <w,m>+ D(m) dm = w.z (1 + Lambda(w))` | Heitz 2014 eq. 17 |
//! | `G1(w,m)` | `chi+(w.m) |w.z| / A(w)` | PHYSICS.md |
//! | `D_w(m)` | visible normals `<w,m>+ D(m) / A(w)` | Heitz 2018 |
//!
//! Every formula is written in terms of `w.z` and `s = |(ax w.x, ay w.y)|` rather than `tan`,
//! `cot` or `nu`, which keeps it finite at exactly grazing directions (`w.z = 0`) and at
//! normal incidence (`s = 0`).

pub mod beckmann;
pub mod fresnel;
pub mod ggx;

use crate::scalar::{Real, Vec3};
use serde::{Deserialize, Serialize};

pub use fresnel::Fresnel;

/// Which distribution of microfacet normals.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum NdfKind {
    /// Trowbridge-Reitz / GGX.
    #[default]
    Ggx,
    /// Beckmann, with the exact erfc-based Lambda (not Walter's rational approximation).
    Beckmann,
}

impl NdfKind {
    pub fn name(self) -> &'static str {
        match self {
            NdfKind::Ggx => "ggx",
            NdfKind::Beckmann => "beckmann",
        }
    }
}

impl std::str::FromStr for NdfKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "ggx" => Ok(NdfKind::Ggx),
            "beckmann" => Ok(NdfKind::Beckmann),
            _ => Err(format!(
                "unknown distribution '{s}' (expected ggx or beckmann)"
            )),
        }
    }
}

/// Whether masking and shadowing are correlated through the microsurface height.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Height {
    /// `G2 = 1 / (1 + Lambda(wi) + Lambda(wo))` (Heitz 2014 eq. 99).
    #[default]
    Correlated,
    /// `G2 = G1(wi) G1(wo)` (what Mitsuba 3's `roughconductor` uses).
    Uncorrelated,
}

impl Height {
    pub fn name(self) -> &'static str {
        match self {
            Height::Correlated => "correlated",
            Height::Uncorrelated => "uncorrelated",
        }
    }
}

impl std::str::FromStr for Height {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "correlated" => Ok(Height::Correlated),
            "uncorrelated" => Ok(Height::Uncorrelated),
            _ => Err(format!(
                "unknown height model '{s}' (expected correlated or uncorrelated)"
            )),
        }
    }
}

/// An anisotropic Smith microsurface: distribution kind and roughness `alpha` along x and y.
#[derive(Clone, Copy, Debug)]
pub struct Microfacet<T> {
    pub ndf: NdfKind,
    pub ax: T,
    pub ay: T,
}

impl<T: Real> Microfacet<T> {
    pub fn new(ndf: NdfKind, ax: T, ay: T) -> Self {
        Microfacet { ndf, ax, ay }
    }

    /// `s = |(ax w.x, ay w.y)|`: the stretched horizontal length of `w` (`a_w sin(theta)`).
    #[inline]
    fn stretched_horizontal(&self, w: Vec3<T>) -> T {
        ((self.ax * w.x).sq() + (self.ay * w.y).sq()).sqrt()
    }

    /// `|w.z| * Lambda(w_up)`, where `w_up` is `w` mirrored into the upper hemisphere.
    /// Finite and non-negative for every direction, including `w.z = 0`.
    #[inline]
    pub fn z_lambda(&self, w: Vec3<T>) -> T {
        let z = w.z.abs();
        let s = self.stretched_horizontal(w);
        match self.ndf {
            NdfKind::Ggx => ggx::z_lambda(z, s),
            NdfKind::Beckmann => beckmann::z_lambda(z, s),
        }
    }

    /// Smith `Lambda(w)` with the full-sphere extension `Lambda(w) = -1 - Lambda(-w)` for
    /// `w.z < 0` (Heitz et al. 2016 sec. 2.2). Infinite at exactly grazing `w`.
    pub fn lambda(&self, w: Vec3<T>) -> T {
        let up = self.z_lambda(w) / w.z.abs();
        if w.z.re64() >= 0.0 {
            up
        } else {
            -T::one() - up
        }
    }

    /// Projected area of the visible microsurface, `A(w) = integral <w,m>+ D(m) dm
    /// = w.z (1 + Lambda(w))`, for any `w` (for `w.z < 0` it equals `|w.z| Lambda(-w)`).
    /// It normalises the visible-normal density and is positive unless `w` is straight down.
    #[inline]
    pub fn projected_area(&self, w: Vec3<T>) -> T {
        w.z.max_c(0.0) + self.z_lambda(w)
    }

    /// Distant masking `G1_dist(w) = |1 / (1 + Lambda(w))| = |w.z| / A(w)`.
    #[inline]
    pub fn g1_dist(&self, w: Vec3<T>) -> T {
        w.z.abs() / self.projected_area(w)
    }

    /// Masking `G1(w, m) = chi+(w.m) G1_dist(w)`.
    pub fn g1(&self, w: Vec3<T>, m: Vec3<T>) -> T {
        if w.dot(m).re64() <= 0.0 {
            return T::zero();
        }
        self.g1_dist(w)
    }

    /// `G2(wi, wo) / (wi.z wo.z)` for a reflection with both directions above the surface, in a
    /// form that stays finite at grazing angles (the `chi+` factors are 1 for the half vector):
    /// correlated `1 / (wi.z wo.z + wo.z zLi + wi.z zLo)`, uncorrelated `1 / (A(wi) A(wo))`,
    /// where `zL = |w.z| Lambda(w)`.
    #[inline]
    pub fn g2_over_cosines(&self, wi: Vec3<T>, wo: Vec3<T>, height: Height) -> T {
        let zli = self.z_lambda(wi);
        let zlo = self.z_lambda(wo);
        let den = match height {
            Height::Correlated => wi.z * wo.z + wo.z * zli + wi.z * zlo,
            Height::Uncorrelated => (wi.z + zli) * (wo.z + zlo),
        };
        den.recip()
    }

    /// Masking-shadowing `G2(wi, wo, m)` for a reflection (both directions above the surface).
    pub fn g2(&self, wi: Vec3<T>, wo: Vec3<T>, m: Vec3<T>, height: Height) -> T {
        if wi.dot(m).re64() <= 0.0
            || wo.dot(m).re64() <= 0.0
            || wi.z.re64() <= 0.0
            || wo.z.re64() <= 0.0
        {
            return T::zero();
        }
        self.g2_over_cosines(wi, wo, height) * wi.z * wo.z
    }

    /// Distribution of normals `D(m)` (1/sr), zero for `m.z <= 0`.
    #[inline]
    pub fn d(&self, m: Vec3<T>) -> T {
        if m.z.re64() <= 0.0 {
            return T::zero();
        }
        let s2 = (m.x / self.ax).sq() + (m.y / self.ay).sq();
        let unscaled = match self.ndf {
            NdfKind::Ggx => ggx::density_stretched(s2, m.z),
            NdfKind::Beckmann => beckmann::density_stretched(s2, m.z),
        };
        unscaled / (self.ax * self.ay)
    }

    /// Density of visible normals `D_w(m) = <w,m>+ D(m) / A(w)` (1/sr) for any `w`, above or
    /// below the horizon; it integrates to 1 over the sphere of `m`.
    #[inline]
    pub fn pdf_visible(&self, w: Vec3<T>, m: Vec3<T>) -> T {
        let cos = w.dot(m);
        let area = self.projected_area(w);
        if cos.re64() <= 0.0 || area.re64() <= 0.0 {
            // area = 0: seen from (nearly) straight below nothing is visible in f64.
            return T::zero();
        }
        cos * self.d(m) / area
    }

    /// Sample a normal from `D_w` exactly, for `w` above or below the horizon, from two uniform
    /// numbers in `[0, 1)`. The result depends smoothly on the roughness, so its dual parts are
    /// the pathwise derivatives at fixed random numbers.
    pub fn sample_visible(&self, w: Vec3<T>, u: [f64; 2]) -> Vec3<T> {
        let stretched = Vec3::new(self.ax * w.x, self.ay * w.y, w.z).normalize();
        let n = match self.ndf {
            NdfKind::Ggx => ggx::sample_visible_stretched(stretched, u),
            NdfKind::Beckmann => beckmann::sample_visible_stretched(stretched, u),
        };
        Vec3::new(self.ax * n.x, self.ay * n.y, n.z.max_c(0.0)).normalize()
    }
}

#[cfg(test)]
mod tests;
