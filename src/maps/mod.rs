//! Material maps (issue #17, DESIGN.md "Material maps"): a spatially varying material as
//! per-texel parameters on a texel grid laid over the sample rectangle.
//!
//! | map | per texel | used for |
//! | --- | --- | --- |
//! | `diffuse` | Lambertian albedo, linear RGB in [0, 1] | `diffuse` of the uniform material |
//! | `specular` | Schlick F0, linear RGB in [0, 1] | `fresnel` (Schlick) of the uniform material |
//! | `roughness` | microfacet `alpha` > 0 along the sample's x and y (not perceptual roughness; equal for an isotropic texel) | `alpha` |
//! | `normal` | unit shading normal in tangent space (`x` along the sample's +x, `y` along +y, `z` out of the surface) | the frame the BRDF is evaluated in |
//!
//! A parameter without a map takes the material file's uniform value, so a uniform material
//! is the one-texel case ([`MaterialMaps::uniform`]). Texel `(column, row)` covers
//! `u` in `[column, column + 1) / width` and `v` in `[row, row + 1) / height` of the sample's
//! texture coordinates ([`crate::shading::ShadingRecords::uv`]): row 0 at the sample's top
//! edge (+y), as the rows of a rectified photo; lookups take the nearest texel (no filtering),
//! so a texel's records see exactly its parameters and texels are independent in a fit.
//!
//! With a shading normal `n`, the BRDF is evaluated in the frame `(s, t, n)`,
//! `s = normalize(x - (x.n) n)`, `t = n x s`, and the cosine of the incident direction is taken
//! against `n` (the geometric cosine in the records' irradiance is replaced by it): Mitsuba 3's
//! `normalmap` BSDF and glTF's `normalTexture` do the same.
//!
//! The files (JSON plus images) are read and written by [`files`]; [`lobe`] is what one texel
//! evaluates; [`render`] evaluates maps over shading records; [`fit`] fits maps to a photo set; [`pipeline`] runs that fit on a photo set
//! as the commands do (records, held-out photo, exposure, prediction, the fit file's fields).

pub mod compare;
pub mod files;
pub mod fit;
pub mod lobe;
pub mod pipeline;
pub mod render;

use crate::material::{FresnelSpec, Material};
use crate::scalar::{Real, Vec3};

/// The texel grid over the sample rectangle: `width` columns along x, `height` rows along y.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct TexelGrid {
    pub width: usize,
    pub height: usize,
}

impl TexelGrid {
    pub fn len(&self) -> usize {
        self.width * self.height
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The texel (row-major index) holding texture coordinates `uv`; points on the far edges
    /// belong to the last column or row.
    pub fn texel(&self, uv: [f64; 2]) -> usize {
        let index = |t: f64, n: usize| ((t * n as f64).floor().max(0.0) as usize).min(n - 1);
        index(uv[1], self.height) * self.width + index(uv[0], self.width)
    }
}

/// A spatially varying material: `base` names the model, distribution and height model and
/// holds the value of every parameter that has no map.
#[derive(Clone, Debug, PartialEq)]
pub struct MaterialMaps {
    pub base: Material,
    pub grid: TexelGrid,
    /// Per texel Lambertian albedo.
    pub diffuse: Option<Vec<[f64; 3]>>,
    /// Per texel Schlick F0 (replaces `base.fresnel`).
    pub specular: Option<Vec<[f64; 3]>>,
    /// Per texel `[alpha_x, alpha_y]` (equal where the texel is isotropic).
    pub roughness: Option<Vec<[f64; 2]>>,
    /// Per texel unit shading normal, tangent space.
    pub normal: Option<Vec<[f64; 3]>>,
}

impl MaterialMaps {
    /// The one-texel maps of a uniform material.
    pub fn uniform(material: &Material) -> MaterialMaps {
        MaterialMaps {
            base: material.clone(),
            grid: TexelGrid {
                width: 1,
                height: 1,
            },
            diffuse: None,
            specular: None,
            roughness: None,
            normal: None,
        }
    }

    /// The uniform material of texel `t` (its shading normal aside: [`MaterialMaps::normal`]).
    pub fn texel(&self, t: usize) -> Material {
        let mut material = self.base.clone();
        if let Some(diffuse) = &self.diffuse {
            material.diffuse = diffuse[t];
        }
        if let Some(specular) = &self.specular {
            material.fresnel = FresnelSpec::Schlick { f0: specular[t] };
        }
        if let Some(roughness) = &self.roughness {
            material.alpha = roughness[t];
        }
        material
    }

    /// Texel `t`'s roughness as one number: `sqrt(alpha_x alpha_y)`, at which the albedo
    /// tables read an anisotropic surface (`alpha` where isotropic).
    pub fn alpha(&self, t: usize) -> f64 {
        let [ax, ay] = self.texel(t).alpha;
        (ax * ay).sqrt()
    }

    /// Whether some texel's roughness differs along x and y.
    pub fn is_anisotropic(&self) -> bool {
        match &self.roughness {
            Some(roughness) => roughness.iter().any(|[ax, ay]| ax != ay),
            None => self.base.alpha[0] != self.base.alpha[1],
        }
    }

    /// The shading normal of texel `t`, if the material has a normal map.
    pub fn normal(&self, t: usize) -> Option<[f64; 3]> {
        self.normal.as_ref().map(|n| n[t])
    }
}

/// A material file's content: uniform, or maps.
#[derive(Clone, Debug, PartialEq)]
pub enum AnyMaterial {
    Uniform(Material),
    Maps(MaterialMaps),
}

impl AnyMaterial {
    /// The material's model, distribution, height model and uniform values.
    pub fn base(&self) -> &Material {
        match self {
            AnyMaterial::Uniform(material) => material,
            AnyMaterial::Maps(maps) => &maps.base,
        }
    }
}

/// The shading frame `(s, t, n)` of the unit normal `n` (see the module docs), built once for
/// all the directions a texel sees.
#[derive(Clone, Copy, Debug)]
pub struct ShadingFrame<T> {
    s: Vec3<T>,
    t: Vec3<T>,
    n: Vec3<T>,
}

impl<T: Real> ShadingFrame<T> {
    pub fn new(n: Vec3<T>) -> ShadingFrame<T> {
        let x = Vec3::new(T::one(), T::zero(), T::zero());
        let s = (x - n * n.x).normalize();
        ShadingFrame {
            s,
            t: n.cross(s),
            n,
        }
    }

    /// `w` (tangent space, `z` the geometric normal) in the frame: `(w.s, w.t, w.n)`.
    pub fn local(&self, w: Vec3<T>) -> Vec3<T> {
        Vec3::new(w.dot(self.s), w.dot(self.t), w.dot(self.n))
    }

    /// The inverse of [`ShadingFrame::local`]: `w.x s + w.y t + w.z n`.
    pub fn tangent(&self, w: Vec3<T>) -> Vec3<T> {
        self.s * w.x + self.t * w.y + self.n * w.z
    }
}

/// The unit normal of tangent-space slopes `(p, q)`: `normalize(-p, -q, 1)`, the normal of the
/// height field `z = p x + q y`; every slope gives a normal above the surface.
pub fn normal_from_slopes<T: Real>(p: T, q: T) -> Vec3<T> {
    Vec3::new(-p, -q, T::one()).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texel_lookup_puts_row_zero_at_the_top_and_clamps_edges() {
        let grid = TexelGrid {
            width: 4,
            height: 2,
        };
        assert_eq!(grid.texel([0.0, 0.0]), 0);
        assert_eq!(grid.texel([0.99, 0.01]), 3);
        assert_eq!(grid.texel([0.26, 0.51]), 5);
        assert_eq!(
            grid.texel([1.0, 1.0]),
            7,
            "far edges belong to the last texel"
        );
        assert_eq!(grid.texel([-1e-12, 0.5]), 4);
    }

    #[test]
    fn shading_frame_is_orthonormal_and_identity_for_the_geometric_normal() {
        let w = Vec3::<f64>::new(0.3, -0.2, 0.9).normalize();
        let same = ShadingFrame::new(Vec3::new(0.0, 0.0, 1.0)).local(w);
        assert!((same.x - w.x).abs() < 1e-15 && (same.y - w.y).abs() < 1e-15);
        let n = normal_from_slopes(0.4f64, -0.7);
        for w in [w, Vec3::<f64>::new(-0.5, 0.1, 0.3).normalize()] {
            let local = ShadingFrame::new(n).local(w);
            assert!(
                (local.length() - 1.0).abs() < 1e-14,
                "rotation keeps length"
            );
            assert!(
                (local.z - w.dot(n)).abs() < 1e-15,
                "z is the cosine against n"
            );
        }
        let tilted = ShadingFrame::new(n).local(n);
        assert!((tilted.z - 1.0).abs() < 1e-14 && tilted.x.abs() < 1e-14);
    }
}
