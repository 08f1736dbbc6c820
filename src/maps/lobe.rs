//! What one texel of a material evaluates, as every renderer of maps sees it: the specular
//! model of the texel's uniform material, its diffuse albedo / pi, and the frame of its shading
//! normal (module docs of [`super`]). Directions come in tangent space (`z` the geometric
//! normal, `x` along the sample's +x); [`TexelLobe::local`] turns them into the shading frame.

use super::{MaterialMaps, ShadingFrame};
use crate::bsdf::single::SingleBounce;
use crate::bsdf::Brdf;
use crate::random::Rng;
use crate::scalar::Vec3;
use rayon::prelude::*;
use std::f64::consts::FRAC_1_PI;

pub struct TexelLobe {
    pub brdf: Box<dyn Brdf>,
    /// The single-bounce lobe of the texel's material (its sampler has an exact density).
    pub single: SingleBounce<f64>,
    lambert: [f64; 3],
    frame: Option<ShadingFrame<f64>>,
}

impl TexelLobe {
    /// The lobes of every texel of `maps`, in texel order.
    pub fn all(maps: &MaterialMaps) -> Vec<TexelLobe> {
        TexelLobe::of_texels(maps, 0..maps.grid.len())
    }

    /// The lobes of the texels `texels` of `maps`, in texel order.
    pub fn of_texels(maps: &MaterialMaps, texels: std::ops::Range<usize>) -> Vec<TexelLobe> {
        texels
            .into_par_iter()
            .map(|t| {
                let material = maps.texel(t);
                TexelLobe {
                    brdf: material.brdf(),
                    single: material.single(),
                    lambert: material.diffuse.map(|d| d * FRAC_1_PI),
                    frame: maps.normal(t).map(|n| ShadingFrame::new(Vec3::from_f64(n))),
                }
            })
            .collect()
    }

    /// A tangent-space direction in the texel's shading frame (unchanged without a normal map).
    pub fn shading(&self, w: Vec3<f64>) -> Vec3<f64> {
        match &self.frame {
            None => w,
            Some(frame) => frame.local(w),
        }
    }

    /// The inverse of [`TexelLobe::shading`].
    pub fn tangent(&self, w: Vec3<f64>) -> Vec3<f64> {
        match &self.frame {
            None => w,
            Some(frame) => frame.tangent(w),
        }
    }

    /// Tangent-space `wi`, `wo` in the texel's shading frame; `None` when a normal map puts
    /// either below the shading normal's horizon.
    pub fn local(&self, wi: Vec3<f64>, wo: Vec3<f64>) -> Option<(Vec3<f64>, Vec3<f64>)> {
        let (i, o) = (self.shading(wi), self.shading(wo));
        (self.frame.is_none() || (i.z > 0.0 && o.z > 0.0)).then_some((i, o))
    }

    /// `f(wi, wo) + diffuse / pi` at shading-frame directions, `f` from the model's own `eval`
    /// (a Monte Carlo estimate drawn from `rng` for the stochastic models).
    pub fn value(&self, wi: Vec3<f64>, wo: Vec3<f64>, rng: &mut Rng) -> [f64; 3] {
        let f = self.brdf.eval(wi, wo, rng).total();
        std::array::from_fn(|c| f[c] + self.lambert[c])
    }
}
