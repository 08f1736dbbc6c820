//! The search space of a fit: which material parameters are free, and their maps to unbounded
//! coordinates (ENGINEERING-NOTES.md: argmin has no box constraints).
//!
//! | parameter | coordinate | range of the material value |
//! | --- | --- | --- |
//! | `alpha` (or `alpha_x`, `alpha_y`) | `ln alpha` | (0, inf) |
//! | Schlick `f0` per channel | `logit f0` | (0, 1) |
//! | conductor per channel | `logit r`, `logit g`: Gulbrandsen 2014 reflectivity (= F0) and edge tint | `eta, k` of the family |
//! | `diffuse` per channel | `logit rho` | (0, 1) |
//!
//! The conductor is searched in (r, g) rather than (eta, k) because the data constrain F0 = r
//! directly (a co-located flash sees the Fresnel term only at normal incidence), while eta and k
//! alone are strongly correlated; g is then pinned by whatever range of angles the photos span.

use crate::bsdf::single::SingleBounce;
use crate::bsdf::Model;
use crate::material::{FresnelSpec, Material};
use crate::microfacet::fresnel::{
    ior_from_reflectivity_edge_tint, reflectivity_edge_tint_from_ior,
};
use crate::microfacet::{Fresnel, Height, Microfacet, NdfKind};
use crate::scalar::{Real, Rgb};
use serde::{Deserialize, Serialize};

/// Which Fresnel family a fit searches.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum FresnelFamily {
    /// RGB F0 with Schlick's approximation.
    #[default]
    Schlick,
    /// Exact conductor with RGB complex IOR.
    Conductor,
}

/// The free parameters of a fit and the fixed choices around them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParamSpace {
    pub model: Model,
    pub ndf: NdfKind,
    pub height: Height,
    pub anisotropic: bool,
    pub fresnel: FresnelFamily,
    pub diffuse: bool,
}

/// Logistic function, kept away from exactly 0 and 1; generic so coordinates may carry
/// derivatives (the clamp keeps the derivative of the unclamped branch).
pub fn sigmoid<T: Real>(x: T) -> T {
    (T::one() + (-x).exp())
        .recip()
        .max_c(1e-12)
        .min_c(1.0 - 1e-12)
}

/// Inverse of [`sigmoid`] for `p` in (0, 1).
pub fn logit(p: f64) -> f64 {
    let p = p.clamp(1e-12, 1.0 - 1e-12);
    (p / (1.0 - p)).ln()
}

/// The material at a point of a [`ParamSpace`] in the kernel's generic pieces: what both the
/// f64 renderer and the dual-number gradient evaluate.
#[derive(Clone, Copy, Debug)]
pub struct Surface<T> {
    /// Roughness, Fresnel and height model of the specular part.
    pub single: SingleBounce<T>,
    /// Lambertian albedo per channel.
    pub diffuse: [T; 3],
}

impl ParamSpace {
    pub fn dim(&self) -> usize {
        let alpha = if self.anisotropic { 2 } else { 1 };
        let fresnel = match self.fresnel {
            FresnelFamily::Schlick => 3,
            FresnelFamily::Conductor => 6,
        };
        alpha + fresnel + if self.diffuse { 3 } else { 0 }
    }

    /// Coordinate names, in order, for traces and reports.
    pub fn names(&self) -> Vec<String> {
        let mut names = if self.anisotropic {
            vec!["ln_alpha_x".to_string(), "ln_alpha_y".into()]
        } else {
            vec!["ln_alpha".to_string()]
        };
        let rgb = |p: &str| ["r", "g", "b"].map(|c| format!("{p}_{c}"));
        match self.fresnel {
            FresnelFamily::Schlick => names.extend(rgb("logit_f0")),
            FresnelFamily::Conductor => {
                names.extend(rgb("logit_reflectivity"));
                names.extend(rgb("logit_edge_tint"));
            }
        }
        if self.diffuse {
            names.extend(rgb("logit_diffuse"));
        }
        names
    }

    /// The surface at coordinates `x`, at any scalar type.
    pub fn surface<T: Real>(&self, x: &[T]) -> Surface<T> {
        debug_assert_eq!(x.len(), self.dim());
        let (ax, ay, rest) = if self.anisotropic {
            (x[0].exp(), x[1].exp(), &x[2..])
        } else {
            let a = x[0].exp();
            (a, a, &x[1..])
        };
        let (fresnel, rest) = match self.fresnel {
            FresnelFamily::Schlick => (
                Fresnel::Schlick {
                    f0: Rgb([0, 1, 2].map(|c| sigmoid(rest[c]))),
                },
                &rest[3..],
            ),
            FresnelFamily::Conductor => {
                let ior = [0, 1, 2].map(|c| {
                    ior_from_reflectivity_edge_tint(sigmoid(rest[c]), sigmoid(rest[3 + c]))
                });
                (
                    Fresnel::Conductor {
                        eta: Rgb(ior.map(|p| p.0)),
                        k: Rgb(ior.map(|p| p.1)),
                    },
                    &rest[6..],
                )
            }
        };
        let diffuse = if self.diffuse {
            [0, 1, 2].map(|c| sigmoid(rest[c]))
        } else {
            [T::zero(); 3]
        };
        Surface {
            single: SingleBounce {
                microfacet: Microfacet::new(self.ndf, ax, ay),
                fresnel,
                height: self.height,
            },
            diffuse,
        }
    }

    /// The material at coordinates `x`.
    pub fn material(&self, x: &[f64]) -> Material {
        let Surface { single, diffuse } = self.surface(x);
        let fresnel = match single.fresnel {
            Fresnel::Schlick { f0 } => FresnelSpec::Schlick { f0: f0.0 },
            Fresnel::Conductor { eta, k } => FresnelSpec::Conductor { eta: eta.0, k: k.0 },
            Fresnel::White | Fresnel::Dielectric { .. } => {
                unreachable!("a fit searches Schlick or conductor Fresnel")
            }
        };
        Material {
            model: self.model,
            ndf: self.ndf,
            height: self.height,
            alpha: [single.microfacet.ax, single.microfacet.ay],
            fresnel,
            diffuse,
        }
    }

    /// Coordinates of a material (its Fresnel converted to this space's family through F0).
    pub fn point(&self, m: &Material) -> Vec<f64> {
        let mut x = if self.anisotropic {
            vec![m.alpha[0].ln(), m.alpha[1].ln()]
        } else {
            vec![(m.alpha[0] * m.alpha[1]).sqrt().ln()]
        };
        match (self.fresnel, m.fresnel) {
            (FresnelFamily::Conductor, FresnelSpec::Conductor { eta, k }) => {
                let rg = [0, 1, 2].map(|c| reflectivity_edge_tint_from_ior(eta[c], k[c]));
                x.extend(rg.map(|p| logit(p.0)));
                x.extend(rg.map(|p| logit(p.1)));
            }
            (FresnelFamily::Conductor, other) => {
                x.extend(other.f0().map(logit));
                x.extend([logit(0.5); 3]);
            }
            (FresnelFamily::Schlick, other) => x.extend(other.f0().map(logit)),
        }
        if self.diffuse {
            x.extend(m.diffuse.map(|d| logit(d.max(1e-3))));
        }
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coordinates_round_trip() {
        for (anisotropic, fresnel, diffuse) in [
            (false, FresnelFamily::Schlick, false),
            (true, FresnelFamily::Conductor, true),
            (false, FresnelFamily::Conductor, false),
        ] {
            let space = ParamSpace {
                model: Model::Single,
                ndf: NdfKind::Ggx,
                height: Height::Correlated,
                anisotropic,
                fresnel,
                diffuse,
            };
            let x: Vec<f64> = (0..space.dim()).map(|i| 0.3 * i as f64 - 1.0).collect();
            let m = space.material(&x);
            m.validate().unwrap();
            let y = space.point(&m);
            assert_eq!(space.names().len(), space.dim());
            for (a, b) in x.iter().zip(&y) {
                assert!((a - b).abs() < 1e-8, "{x:?} vs {y:?}");
            }
        }
    }
}
