//! Maps materials ([`crate::maps`]) in the formats that carry textures: the per-texel facts of
//! the metallic workflow, and the texture files.
//!
//! Each texel is its own uniform material ([`MaterialMaps::texel`]) and gets the base kind of
//! the uniform export ([`super::base`]): a texel with a diffuse albedo (and Schlick `F0 < 1`) is
//! a dielectric (the `Dielectric` texels of `fit --maps`, [`crate::maps::fit::Kind`], whatever
//! their `F0`), any other a metal (the fit's `Metal` texels have no diffuse). The formats share one index of refraction for all dielectric texels (glTF's
//! `KHR_materials_ior` and the shaders' `specular_IOR` are not textures): that of the strongest
//! dielectric `F0` over the map, and each dielectric texel's `F0` is that index's reflectance
//! times its [`TexelFacts::specular_tint`] in [0, 1].
//!
//! | file (in the textures folder) | written for | texel value | encoding |
//! | --- | --- | --- | --- |
//! | `base_color.png` | glTF, MaterialX | metal: `F0`; dielectric: diffuse albedo | 8-bit sRGB (glTF 2.0 section 3.9.2 requires sRGB base colour) |
//! | `metallic_roughness.png` | glTF, MaterialX | G: perceptual roughness `sqrt(alpha)` (capped at 1; anisotropic maps: of the smaller alpha), B: metallic 0 or 1, R: 0 | 16-bit linear (glTF 2.0 section 3.9.2: roughness in G, metalness in B) |
//! | `anisotropy.png` | glTF, anisotropic maps | RG: the direction of the larger alpha in tangent space, `0.5 d + 0.5` (x: (1, 0.5), y: (0.5, 1)); B: `anisotropyStrength` ([`super::roughness::anisotropy`]) | 16-bit linear (`KHR_materials_anisotropy`'s `anisotropyTexture`) |
//! | `standard_surface_roughness.png`, `open_pbr_roughness.png` | MaterialX, anisotropic maps | each shader's `specular_roughness` in R and its anisotropy in G ([`super::materialx`]'s table); B: `specular_rotation` (standard_surface), 0 (open_pbr_surface) | 16-bit linear |
//! | `tangent.png` | MaterialX, anisotropic maps | the direction of the larger alpha, `(1, 0, 0)` (+x) or `(0, 1, 0)` (+y): open_pbr_surface's `geometry_tangent`, which has no rotation input | 16-bit linear |
//! | `specular_color.png` | glTF, MaterialX, when some dielectric `F0` is not grey | dielectric: `F0 / F0(ior)` per channel; metal: 1 | 8-bit sRGB (KHR_materials_specular `specularColorTexture`) |
//! | `normal.png` | glTF, MaterialX, with a normal map | `0.5 n + 0.5`, tangent space, +y towards row 0 | 16-bit linear |
//! | `alpha.exr` (anisotropic maps: `alpha_u.exr`, `alpha_v.exr`), `eta.exr`, `k.exr`, `diffuse.exr`, `normal.exr` | Mitsuba ([`super::mitsuba`]) | `alpha` (along x, along y); the texel's equivalent conductor; twice the diffuse albedo; `0.5 n + 0.5` | float EXR, read raw |
//!
//! Every image has the texel grid's resolution, row 0 at the sample's +y edge, column 0 at its
//! -x edge (the maps' own layout, [`crate::maps::files`]); lookups are nearest-texel in every
//! format, as in `bouncefit render`.

use super::{base, equivalent_conductor, stretch, Base, Conversion, SchlickTintTable};
use crate::capture::image_io::{write_exr, write_png_tonemapped};
use crate::error::Result;
use crate::maps::files::write_png16;
use crate::maps::MaterialMaps;
use crate::material::{FresnelSpec, Material};
use std::path::{Path, PathBuf};

/// One texel in the metallic workflow.
#[derive(Clone, Debug, PartialEq)]
pub struct TexelFacts {
    pub material: Material,
    /// Reflectance at normal incidence.
    pub f0: [f64; 3],
    pub metal: bool,
    /// Dielectric texels: `F0 / F0(ior)` of the map's shared index; metals: white.
    pub specular_tint: [f64; 3],
}

/// The facts every texture-carrying format is written from.
pub struct MapsConversion {
    pub maps: MaterialMaps,
    pub texels: Vec<TexelFacts>,
    /// The index of refraction shared by the dielectric texels (module docs); `None` without
    /// dielectric texels.
    pub dielectric_ior: Option<f64>,
    /// The uniform facts of the roughest texel, whose notes (multi-bounce energy, roughness
    /// range) are the strongest of the map.
    pub roughest: Conversion,
}

impl MapsConversion {
    /// The facts of `maps`.
    pub fn new(maps: &MaterialMaps) -> MapsConversion {
        let materials: Vec<Material> = (0..maps.grid.len()).map(|t| maps.texel(t)).collect();
        let bases: Vec<Base> = materials.iter().map(base).collect();
        let strongest = materials
            .iter()
            .zip(&bases)
            .filter(|(_, b)| matches!(b, Base::Dielectric { .. }))
            .flat_map(|(m, _)| m.fresnel.f0())
            .fold(None, |best: Option<f64>, f| {
                Some(best.map_or(f, |b| b.max(f)))
            });
        let texels = materials
            .into_iter()
            .zip(&bases)
            .map(|(material, b)| {
                let f0 = material.fresnel.f0();
                let metal = *b == Base::Metal;
                let specular_tint = match strongest {
                    Some(s) if !metal && s > 0.0 => f0.map(|f| f / s),
                    _ => [1.0; 3],
                };
                TexelFacts {
                    material,
                    f0,
                    metal,
                    specular_tint,
                }
            })
            .collect::<Vec<_>>();
        let roughest = texels
            .iter()
            .max_by(|a, b| {
                stretch(a.material.alpha)
                    .0
                    .total_cmp(&stretch(b.material.alpha).0)
            })
            .expect("a texel grid has texels");
        MapsConversion {
            maps: maps.clone(),
            dielectric_ior: strongest.map(super::ior_from_f0),
            roughest: Conversion::new(&roughest.material),
            texels,
        }
    }

    pub fn has_diffuse(&self) -> bool {
        self.texels
            .iter()
            .any(|t| t.material.diffuse.iter().any(|&d| d > 0.0))
    }

    /// Whether some dielectric texel's `F0` is not the shared index's reflectance in every
    /// channel (then the formats need a specular colour texture).
    pub fn has_specular_tint(&self) -> bool {
        self.texels.iter().any(|t| t.specular_tint != [1.0; 3])
    }

    pub fn metal_count(&self) -> usize {
        self.texels.iter().filter(|t| t.metal).count()
    }

    /// Notes every texture format states about maps, besides those of the roughest texel.
    pub fn notes(&self) -> Vec<String> {
        let metals = self.metal_count();
        let mut notes = vec![format!(
            "{} texels: {metals} metal (base colour = F0, metallic 1; a diffuse albedo under a \
             metal is dropped), {} dielectric (base colour = diffuse albedo, metallic 0); \
             nearest-texel lookup",
            self.texels.len(),
            self.texels.len() - metals
        )];
        if let Some(ior) = self.dielectric_ior {
            notes.push(format!(
                "dielectric texels share the index of refraction {} (the strongest dielectric \
                 F0 of the map); each texel's F0 is its reflectance times the specular colour \
                 texture",
                super::number(ior)
            ));
        }
        if self.roughest.material.model.capabilities().multi.is_some() {
            notes.push(
                "the multi-bounce note below is that of the roughest texel, which misses the \
                 most energy"
                    .into(),
            );
        }
        notes
    }

    /// The texture files (module table) of the glTF or MaterialX export, written into
    /// `folder` (which must exist).
    pub fn write_pbr_textures(&self, folder: &Path, format: PbrFormat) -> Result<PbrTextures> {
        let colour = |path: PathBuf, of: &dyn Fn(&TexelFacts) -> [f64; 3]| -> Result<PathBuf> {
            let rgb: Vec<[f32; 3]> = self
                .texels
                .iter()
                .map(|t| of(t).map(|v| v as f32))
                .collect();
            write_png_tonemapped(
                &path,
                &rgb,
                self.maps.grid.width,
                self.maps.grid.height,
                1.0,
            )?;
            Ok(path)
        };
        let linear = |path: PathBuf, texels: &[[f64; 3]], encode: fn(f64) -> f64| {
            write_png16(
                &path,
                texels,
                self.maps.grid.width,
                self.maps.grid.height,
                encode,
            )
            .map(|()| path)
        };
        let metallic_roughness: Vec<[f64; 3]> = self
            .texels
            .iter()
            .map(|t| {
                [
                    0.0,
                    super::roughness::anisotropy(t.material.alpha).0,
                    f64::from(u8::from(t.metal)),
                ]
            })
            .collect();
        let anisotropic = self.maps.is_anisotropic();
        let per_texel = |of: &dyn Fn([f64; 2]) -> [f64; 3]| -> Vec<[f64; 3]> {
            self.texels.iter().map(|t| of(t.material.alpha)).collect()
        };
        let gltf_anisotropy = |alpha| {
            let (_, strength, along_y) = super::roughness::anisotropy(alpha);
            if along_y {
                [0.5, 1.0, strength]
            } else {
                [1.0, 0.5, strength]
            }
        };
        let (gltf, materialx) = (
            anisotropic && format == PbrFormat::Gltf,
            anisotropic && format == PbrFormat::Materialx,
        );
        let materialx_texture = |name: &str, of: &dyn Fn([f64; 2]) -> [f64; 3]| {
            materialx
                .then(|| linear(folder.join(name), &per_texel(of), |v| v))
                .transpose()
        };
        Ok(PbrTextures {
            anisotropy: gltf
                .then(|| {
                    linear(
                        folder.join("anisotropy.png"),
                        &per_texel(&gltf_anisotropy),
                        |v| v,
                    )
                })
                .transpose()?,
            standard_surface_roughness: materialx_texture(
                "standard_surface_roughness.png",
                &super::roughness::standard_surface_roughness,
            )?,
            open_pbr_roughness: materialx_texture("open_pbr_roughness.png", &|alpha| {
                let [r, a] = super::roughness::open_pbr_roughness(alpha);
                [r, a, 0.0]
            })?,
            tangent: materialx_texture("tangent.png", &|alpha| {
                if stretch(alpha).2 {
                    [0.0, 1.0, 0.0]
                } else {
                    [1.0, 0.0, 0.0]
                }
            })?,
            base_color: colour(folder.join("base_color.png"), &|t| {
                if t.metal {
                    t.f0
                } else {
                    t.material.diffuse
                }
            })?,
            metallic_roughness: linear(
                folder.join("metallic_roughness.png"),
                &metallic_roughness,
                |v| v,
            )?,
            specular_color: if self.has_specular_tint() {
                Some(colour(folder.join("specular_color.png"), &|t| {
                    t.specular_tint
                })?)
            } else {
                None
            },
            normal: match &self.maps.normal {
                Some(normals) => Some(linear(folder.join("normal.png"), normals, |v| {
                    0.5 * v + 0.5
                })?),
                None => None,
            },
        })
    }

    /// The float EXR textures of the Mitsuba export (module table), written into `folder`.
    pub fn write_mitsuba_textures(&self, folder: &Path) -> Result<MitsubaTextures> {
        let exr = |name: &str, of: &dyn Fn(usize) -> [f64; 3]| -> Result<PathBuf> {
            let path = folder.join(name);
            let rgb: Vec<[f32; 3]> = (0..self.texels.len())
                .map(|t| of(t).map(|v| v as f32))
                .collect();
            write_exr(&path, &rgb, self.maps.grid.width, self.maps.grid.height)?;
            Ok(path)
        };
        let conductors: Vec<([f64; 3], [f64; 3])> = self
            .texels
            .iter()
            .map(|t| texel_conductor(&t.material.fresnel))
            .collect();
        let texel = |t: usize| &self.texels[t].material;
        let alpha = if self.maps.is_anisotropic() {
            vec![
                ("alpha_u", exr("alpha_u.exr", &|t| [texel(t).alpha[0]; 3])?),
                ("alpha_v", exr("alpha_v.exr", &|t| [texel(t).alpha[1]; 3])?),
            ]
        } else {
            vec![("alpha", exr("alpha.exr", &|t| [texel(t).alpha[0]; 3])?)]
        };
        Ok(MitsubaTextures {
            alpha,
            eta: exr("eta.exr", &|t| conductors[t].0)?,
            k: exr("k.exr", &|t| conductors[t].1)?,
            diffuse: match self.has_diffuse() {
                true => Some(exr("diffuse.exr", &|t| texel(t).diffuse.map(|d| 2.0 * d))?),
                false => None,
            },
            normal: match &self.maps.normal {
                Some(normals) => Some(exr("normal.exr", &|t| normals[t].map(|v| 0.5 * v + 0.5))?),
                None => None,
            },
        })
    }
}

/// The equivalent conductor `(eta, k)` of one texel's Fresnel: exact for conductor and
/// dielectric Fresnel, [`SchlickTintTable`] for Schlick and white.
fn texel_conductor(fresnel: &FresnelSpec) -> ([f64; 3], [f64; 3]) {
    let schlick = |f0: [f64; 3]| {
        let table = SchlickTintTable::get();
        let pairs = f0.map(|f| table.conductor(f));
        (pairs.map(|p| p.0), pairs.map(|p| p.1))
    };
    match *fresnel {
        FresnelSpec::Schlick { f0 } => schlick(f0),
        FresnelSpec::White => schlick([1.0; 3]),
        FresnelSpec::Conductor { .. } | FresnelSpec::Dielectric { .. } => {
            let exact = equivalent_conductor(fresnel);
            (exact.eta, exact.k)
        }
    }
}

/// The format [`MapsConversion::write_pbr_textures`] writes for: the formats share the
/// metallic workflow's textures and differ in how they carry anisotropy.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PbrFormat {
    Gltf,
    Materialx,
}

/// The files [`MapsConversion::write_pbr_textures`] wrote; the anisotropy textures only for
/// anisotropic maps, each for its format.
pub struct PbrTextures {
    pub base_color: PathBuf,
    pub metallic_roughness: PathBuf,
    pub specular_color: Option<PathBuf>,
    pub normal: Option<PathBuf>,
    pub anisotropy: Option<PathBuf>,
    pub standard_surface_roughness: Option<PathBuf>,
    pub open_pbr_roughness: Option<PathBuf>,
    pub tangent: Option<PathBuf>,
}

/// The files [`MapsConversion::write_mitsuba_textures`] wrote.
pub struct MitsubaTextures {
    /// `alpha`, or `alpha_u` and `alpha_v`, with their files.
    pub alpha: Vec<(&'static str, PathBuf)>,
    pub eta: PathBuf,
    pub k: PathBuf,
    pub diffuse: Option<PathBuf>,
    pub normal: Option<PathBuf>,
}
