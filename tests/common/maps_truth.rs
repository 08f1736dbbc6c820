//! Maps truths of the maps tests (`tests/maps.rs`, `tests/maps_zoo.rs`).

use bouncefit::bsdf::Model;
use bouncefit::maps::{MaterialMaps, TexelGrid};
use bouncefit::material::{FresnelSpec, Material};

/// One material of a maps truth: Schlick F0, isotropic alpha and diffuse albedo.
pub type TexelMaterial = ([f64; 3], f64, [f64; 3]);

/// `model` maps of `side` x `side` texels, each texel the material that `material` gives at its
/// centre `(u, v)` in [0, 1]^2 (v along the rows).
pub fn maps_of_materials(
    model: Model,
    side: usize,
    material: impl Fn(f64, f64) -> TexelMaterial,
) -> MaterialMaps {
    let grid = TexelGrid {
        width: side,
        height: side,
    };
    let at: Vec<TexelMaterial> = (0..grid.len())
        .map(|t| {
            material(
                ((t % side) as f64 + 0.5) / side as f64,
                ((t / side) as f64 + 0.5) / side as f64,
            )
        })
        .collect();
    MaterialMaps {
        grid,
        diffuse: Some(at.iter().map(|m| m.2).collect()),
        specular: Some(at.iter().map(|m| m.0).collect()),
        roughness: Some(at.iter().map(|m| [m.1; 2]).collect()),
        normal: None,
        base: Material {
            model,
            ndf: Default::default(),
            height: Default::default(),
            alpha: [0.3; 2],
            fresnel: FresnelSpec::Schlick { f0: [0.04; 3] },
            diffuse: [0.0; 3],
        },
    }
}
