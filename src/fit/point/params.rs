//! The search space of a fit: which material parameters are free, and their maps to unbounded
//! coordinates (ENGINEERING-NOTES.md: argmin has no box constraints).
//!
//! | parameter | coordinate | range of the material value |
//! | --- | --- | --- |
//! | `alpha` (or `alpha_x`, `alpha_y`) | `ln alpha` | (0, inf) |
//! | Schlick `f0` per channel | `logit f0` | (0, 1) |
//! | conductor per channel | `logit r`, `logit g`: Gulbrandsen 2014 reflectivity (= F0) and edge tint | `eta, k` of the family |
//! | `diffuse` per channel | `logit rho` | (0, 1) |
//! | `exposure` (`--fit-exposure`), last | `ln s` | (0, inf) |
//!
//! The unbounded coordinates have a box ([`ParamSpace::bounds`]): roughness in
//! [[`ALPHA_BOUNDS`]] (the range every model is defined and stress-tested on) and the exposure in
//! [[`EXPOSURE_BOUNDS`]]. The objective evaluates a point outside the box at its projection onto
//! the box plus a quadratic pull back ([`ParamSpace::outside`]), so no solver returns a value
//! outside it and a search that presses against a bound stops there and says so.
//!
//! With a known Fresnel (`--fresnel-known`) the Fresnel has no coordinates. The exposure `s`
//! multiplies every prediction (a global light power or camera gain). A flash photo determines
//! only the product of `s` and the reflectance (the Fresnel is seen at normal incidence, and the
//! diffuse albedo scales like `s`), so the exposure is fitted only with a known Fresnel
//! ([`ParamSpace::check`]).
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

/// Roughness range of every fit: the models are defined and tested for alpha in [1e-4, 3]
/// (`tabulated`'s table and the albedo tables end at 3; `bouncefit stress` sweeps 1e-4 to 3).
pub const ALPHA_BOUNDS: (f64, f64) = (1e-4, 3.0);

/// Range of a fitted exposure factor: six orders of magnitude around the manifest's lights.
pub const EXPOSURE_BOUNDS: (f64, f64) = (1e-3, 1e3);

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
    /// The Fresnel held at this value (no Fresnel coordinates) instead of searched in
    /// `fresnel`'s family.
    pub known_fresnel: Option<FresnelSpec>,
    /// Fit a global exposure scale (the last coordinate, `ln_exposure`).
    pub exposure: bool,
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
    /// Factor on every prediction (1 unless the exposure is fitted).
    pub exposure: T,
}

impl ParamSpace {
    /// The simplest space of `model`: GGX, correlated heights, isotropic roughness, Schlick F0,
    /// no diffuse, no known Fresnel, no exposure (the `fit` defaults).
    pub fn plain(model: Model) -> ParamSpace {
        ParamSpace {
            model,
            ndf: NdfKind::Ggx,
            height: Height::Correlated,
            anisotropic: false,
            fresnel: FresnelFamily::Schlick,
            diffuse: false,
            known_fresnel: None,
            exposure: false,
        }
    }

    pub fn dim(&self) -> usize {
        let alpha = if self.anisotropic { 2 } else { 1 };
        let fresnel = match (self.known_fresnel, self.fresnel) {
            (Some(_), _) => 0,
            (None, FresnelFamily::Schlick) => 3,
            (None, FresnelFamily::Conductor) => 6,
        };
        alpha + fresnel + if self.diffuse { 3 } else { 0 } + usize::from(self.exposure)
    }

    /// Refuses a space whose coordinates the photos cannot determine: a fitted exposure with
    /// a searched Fresnel (only their product is seen, see the module docs).
    pub fn check(&self) -> Result<(), String> {
        if self.exposure && self.known_fresnel.is_none() {
            return Err(
                "a fitted exposure needs a known Fresnel (--fresnel-known): the photos \
                 determine only exposure x reflectance"
                    .into(),
            );
        }
        Ok(())
    }

    /// The box of the coordinates, `(lower, upper)` per coordinate: `ln alpha` within
    /// [`ALPHA_BOUNDS`], `ln exposure` within [`EXPOSURE_BOUNDS`], the logits unbounded (their
    /// sigmoids already keep F0, edge tint and albedo in (0, 1)).
    pub fn bounds(&self) -> Vec<(f64, f64)> {
        let roughness = (ALPHA_BOUNDS.0.ln(), ALPHA_BOUNDS.1.ln());
        let mut bounds = vec![(f64::NEG_INFINITY, f64::INFINITY); self.dim()];
        bounds[0] = roughness;
        if self.anisotropic {
            bounds[1] = roughness;
        }
        if self.exposure {
            bounds[self.dim() - 1] = (EXPOSURE_BOUNDS.0.ln(), EXPOSURE_BOUNDS.1.ln());
        }
        bounds
    }

    /// `x` projected onto the box [`ParamSpace::bounds`].
    pub fn clamp(&self, x: &[f64]) -> Vec<f64> {
        x.iter()
            .zip(self.bounds())
            .map(|(&v, (lo, hi))| v.clamp(lo, hi))
            .collect()
    }

    /// How far each coordinate of `x` lies outside the box: `x - clamp(x)`, zero inside.
    pub fn outside(&self, x: &[f64]) -> Vec<f64> {
        x.iter().zip(self.clamp(x)).map(|(v, c)| v - c).collect()
    }

    /// The names of the coordinates of `x` that lie on (or beyond) a bound of the box, within
    /// 1e-6 (a quasi-Newton search approaches the kink of the pulled-back cost from inside).
    pub fn at_bounds(&self, x: &[f64]) -> Vec<String> {
        let names = self.names();
        x.iter()
            .zip(self.bounds())
            .zip(names)
            .filter(|((&v, (lo, hi)), _)| v <= lo + 1e-6 || v >= hi - 1e-6)
            .map(|(_, name)| name)
            .collect()
    }

    /// The exposure at coordinates `x` (projected onto the box): `exp` of the last coordinate,
    /// or 1 when not fitted.
    pub fn exposure(&self, x: &[f64]) -> f64 {
        (self.surface(&self.clamp(x)).exposure).clamp(EXPOSURE_BOUNDS.0, EXPOSURE_BOUNDS.1)
    }

    /// Coordinate names, in order, for traces and reports.
    pub fn names(&self) -> Vec<String> {
        let mut names = if self.anisotropic {
            vec!["ln_alpha_x".to_string(), "ln_alpha_y".into()]
        } else {
            vec!["ln_alpha".to_string()]
        };
        let rgb = |p: &str| ["r", "g", "b"].map(|c| format!("{p}_{c}"));
        match (self.known_fresnel, self.fresnel) {
            (Some(_), _) => {}
            (None, FresnelFamily::Schlick) => names.extend(rgb("logit_f0")),
            (None, FresnelFamily::Conductor) => {
                names.extend(rgb("logit_reflectivity"));
                names.extend(rgb("logit_edge_tint"));
            }
        }
        if self.diffuse {
            names.extend(rgb("logit_diffuse"));
        }
        if self.exposure {
            names.push("ln_exposure".into());
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
        let (fresnel, rest) = match (self.known_fresnel, self.fresnel) {
            (Some(known), _) => (known.to_fresnel(), rest),
            (None, FresnelFamily::Schlick) => (
                Fresnel::Schlick {
                    f0: Rgb([0, 1, 2].map(|c| sigmoid(rest[c]))),
                },
                &rest[3..],
            ),
            (None, FresnelFamily::Conductor) => {
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
        let (diffuse, rest) = if self.diffuse {
            ([0, 1, 2].map(|c| sigmoid(rest[c])), &rest[3..])
        } else {
            ([T::zero(); 3], rest)
        };
        let exposure = if self.exposure {
            rest[0].exp()
        } else {
            T::one()
        };
        Surface {
            single: SingleBounce {
                microfacet: Microfacet::new(self.ndf, ax, ay),
                fresnel,
                height: self.height,
            },
            diffuse,
            exposure,
        }
    }

    /// The material at coordinates `x`, projected onto the box: no fit reports a value
    /// outside it.
    pub fn material(&self, x: &[f64]) -> Material {
        let Surface {
            single, diffuse, ..
        } = self.surface(&self.clamp(x));
        let fresnel = match (self.known_fresnel, single.fresnel) {
            (Some(known), _) => known,
            (None, Fresnel::Schlick { f0 }) => FresnelSpec::Schlick { f0: f0.0 },
            (None, Fresnel::Conductor { eta, k }) => FresnelSpec::Conductor { eta: eta.0, k: k.0 },
            (None, Fresnel::White | Fresnel::Dielectric { .. }) => {
                unreachable!("a fit searches Schlick or conductor Fresnel")
            }
        };
        Material {
            model: self.model,
            ndf: self.ndf,
            height: self.height,
            // exp(ln 3) rounds to 3 + 4e-16: the bounds themselves are the values reported.
            alpha: [single.microfacet.ax, single.microfacet.ay]
                .map(|a| a.clamp(ALPHA_BOUNDS.0, ALPHA_BOUNDS.1)),
            fresnel,
            diffuse,
        }
    }

    /// Coordinates of a material (its Fresnel converted to this space's family through F0)
    /// under `exposure` (ignored when the space does not fit it).
    pub fn point(&self, m: &Material, exposure: f64) -> Vec<f64> {
        let mut x = if self.anisotropic {
            vec![m.alpha[0].ln(), m.alpha[1].ln()]
        } else {
            vec![(m.alpha[0] * m.alpha[1]).sqrt().ln()]
        };
        match (self.known_fresnel, self.fresnel, m.fresnel) {
            (Some(_), _, _) => {}
            (None, FresnelFamily::Conductor, FresnelSpec::Conductor { eta, k }) => {
                let rg = [0, 1, 2].map(|c| reflectivity_edge_tint_from_ior(eta[c], k[c]));
                x.extend(rg.map(|p| logit(p.0)));
                x.extend(rg.map(|p| logit(p.1)));
            }
            (None, FresnelFamily::Conductor, other) => {
                x.extend(other.f0().map(logit));
                x.extend([logit(0.5); 3]);
            }
            (None, FresnelFamily::Schlick, other) => x.extend(other.f0().map(logit)),
        }
        if self.diffuse {
            x.extend(m.diffuse.map(|d| logit(d.max(1e-3))));
        }
        if self.exposure {
            x.push(exposure.ln());
        }
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coordinates_round_trip() {
        let copper = FresnelSpec::Conductor {
            eta: [0.2, 0.9, 1.1],
            k: [3.9, 2.4, 2.1],
        };
        for (anisotropic, fresnel, diffuse, known_fresnel, exposure) in [
            (false, FresnelFamily::Schlick, false, None, false),
            (true, FresnelFamily::Conductor, true, None, false),
            (false, FresnelFamily::Conductor, false, None, false),
            (false, FresnelFamily::Schlick, false, Some(copper), true),
            (true, FresnelFamily::Schlick, true, Some(copper), true),
        ] {
            let space = ParamSpace {
                anisotropic,
                fresnel,
                diffuse,
                known_fresnel,
                exposure,
                ..ParamSpace::plain(Model::Single)
            };
            space.check().unwrap();
            let x: Vec<f64> = (0..space.dim()).map(|i| 0.3 * i as f64 - 1.0).collect();
            let m = space.material(&x);
            m.validate().unwrap();
            if let Some(known) = known_fresnel {
                assert_eq!(m.fresnel, known);
            }
            let s = space.exposure(&x);
            assert_eq!(s, if exposure { x[x.len() - 1].exp() } else { 1.0 });
            let y = space.point(&m, s);
            assert_eq!(space.names().len(), space.dim());
            for (a, b) in x.iter().zip(&y) {
                assert!((a - b).abs() < 1e-8, "{x:?} vs {y:?}");
            }
        }
    }

    #[test]
    fn exposure_with_a_searched_fresnel_is_refused() {
        let space = ParamSpace {
            exposure: true,
            ..ParamSpace::plain(Model::Single)
        };
        assert!(space.check().unwrap_err().contains("--fresnel-known"));
    }
}
