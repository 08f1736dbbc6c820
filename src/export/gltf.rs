//! `--format gltf`: a glTF 2.0 document holding one material (a document with only `asset` and
//! `materials` is valid: glTF 2.0 spec section 5.1, "glTF" requires only `asset`).
//!
//! | fitted | written | source |
//! | --- | --- | --- |
//! | isotropic `alpha` | `roughnessFactor = sqrt(alpha)` (glTF's `alpha = roughness^2`), capped at 1 | glTF 2.0 appendix B.3.3 |
//! | anisotropic `alpha_x`, `alpha_y` | `roughnessFactor = sqrt(min)`, `KHR_materials_anisotropy` with `anisotropyStrength = sqrt((max - min) / (1 - min))` and `anisotropyRotation` 0 (stretch along x) or pi/2: the extension's `alpha_t = mix(roughness^2, 1, strength^2)`, `alpha_b = roughness^2` then gives both alphas exactly (a geometric-mean `roughnessFactor` could not) | KHR_materials_anisotropy, "Anisotropy" |
//! | metal base ([`Base::Metal`]) | `metallicFactor = 1`, `baseColorFactor = F0`: glTF's metal Fresnel is Schlick with `F0 = baseColor`, exact for Schlick fits, and for conductor fits exact at normal incidence | glTF 2.0 appendix B.3.4 |
//! | dielectric base ([`Base::Dielectric`]) | `metallicFactor = 0`, `baseColorFactor = diffuse`, `KHR_materials_ior.ior`, and `KHR_materials_specular.specularColorFactor` = the per-channel tint of `F0` when it is not white | KHR_materials_ior, KHR_materials_specular |
//! | model, height, ndf | glTF's lobe is single-bounce, height-correlated GGX: other choices are stated in `materials[0].extras.bouncefit.notes` | glTF 2.0 appendix B.3.2 |
//!
//! The notes also say when the diffuse albedo under a metal is dropped, and (glTF's dielectric
//! weights the diffuse by `1 - F`) when the diffuse layer is not the fit's plain sum.
//!
//! ## Maps
//!
//! A maps material ([`maps_document`]) is one material whose factors are 1 and whose textures
//! ([`super::maps`]) carry the texels: `baseColorTexture`, `metallicRoughnessTexture` (glTF 2.0
//! section 3.9.2), `normalTexture` (section 3.9.3), and for dielectric texels
//! `KHR_materials_ior` (one index for the map) with `KHR_materials_specular`'s
//! `specularColorTexture`; anisotropic maps add `KHR_materials_anisotropy`'s
//! `anisotropyTexture` (per texel the direction of the larger alpha, x or y, and the strength
//! of the table above; `metallicRoughnessTexture` then holds the smaller alpha's roughness). Samplers are NEAREST / CLAMP_TO_EDGE (section 5.26): the fit's
//! lookup is nearest-texel. A quad mesh of the sample's size (sections 3.7.2, 3.6, one `data:`
//! buffer) carries `TEXCOORD_0` with glTF's top-left origin (section 3.8.2: v = 0 at the
//! sample's +y edge, texel row 0), `NORMAL` +z and `TANGENT` +x (w = 1, so the bitangent is +y,
//! the normal map's green axis). Not carried, and stated in `extras.bouncefit.notes`: multiple
//! scattering (the roughest texel's share), the diffuse sum (glTF layers it), a diffuse albedo
//! under a metal texel.

use super::maps::{MapsConversion, PbrTextures};
use super::roughness::{anisotropy, gltf_roughness};
use super::{Base, Conversion};
use crate::bsdf::Model;
use crate::maps::MaterialMaps;
use crate::material::{FresnelSpec, Material};
use crate::microfacet::{Height, NdfKind};
use base64::{engine::general_purpose::STANDARD as BASE64, Engine};
use serde_json::{json, Map, Value};
use std::path::Path;

/// `(roughnessFactor, KHR_materials_anisotropy)`, see the module table.
fn roughness_and_anisotropy(conversion: &Conversion) -> (f64, Option<Value>) {
    let alpha = conversion.material.alpha;
    if !conversion.is_anisotropic() {
        return (gltf_roughness(alpha[0]), None);
    }
    let (roughness, strength, along_y) = anisotropy(alpha);
    let rotation = if along_y {
        std::f64::consts::FRAC_PI_2
    } else {
        0.0
    };
    (
        roughness,
        Some(json!({"anisotropyStrength": strength, "anisotropyRotation": rotation})),
    )
}

fn notes(conversion: &Conversion) -> Vec<String> {
    let material = &conversion.material;
    let mut notes = Vec::new();
    if let FresnelSpec::Conductor { .. } = material.fresnel {
        notes.push(format!(
            "glTF's metal Fresnel is Schlick's with F0 = baseColor: exact at normal incidence; \
             at 82 degrees the fitted conductor reflects {:?} times Schlick's value (F82 tint)",
            conversion.f82_tint
        ));
    }
    if let Base::Dielectric { ior, .. } = conversion.base {
        if ior < 1.0 {
            notes.push(format!(
                "KHR_materials_ior needs ior >= 1: 1/{} (the same F0) is written",
                super::number(ior)
            ));
        }
        notes.push(DIFFUSE_LAYER_NOTE.into());
    }
    notes.extend(conversion.dropped_diffuse_note());
    notes.extend(lobe_notes(conversion));
    notes
}

/// glTF's dielectric is a layer, not the fit's sum.
const DIFFUSE_LAYER_NOTE: &str =
    "glTF weights the diffuse by the specular layer's transmission (1 - F); the fit adds it";

/// The notes on the specular lobe: roughness range, distribution, G2, multi-bounce energy.
fn lobe_notes(conversion: &Conversion) -> Vec<String> {
    let mut notes = conversion.ggx_roughness_notes("glTF");
    if conversion.material.height == Height::Uncorrelated {
        notes.push(
            "glTF's visibility term is the height-correlated Smith G2; the fit used the uncorrelated one"
                .into(),
        );
    }
    notes.extend(conversion.common_notes());
    notes
}

/// The glTF JSON document for `conversion`.
pub fn document(conversion: &Conversion) -> String {
    let (roughness_factor, anisotropy) = roughness_and_anisotropy(conversion);
    let mut extensions = Map::new();
    let (metallic, base_color) = match conversion.base {
        Base::Metal => (1.0, conversion.f0),
        Base::Dielectric { ior, specular_tint } => {
            extensions.insert(
                "KHR_materials_ior".into(),
                json!({"ior": if ior < 1.0 { 1.0 / ior } else { ior }}),
            );
            if specular_tint != [1.0; 3] {
                extensions.insert(
                    "KHR_materials_specular".into(),
                    json!({"specularFactor": 1.0, "specularColorFactor": specular_tint}),
                );
            }
            (0.0, conversion.material.diffuse)
        }
    };
    if let Some(anisotropy) = anisotropy {
        extensions.insert("KHR_materials_anisotropy".into(), anisotropy);
    }
    let material = json!({
        "name": format!("bouncefit {} fit", conversion.material.model.name()),
        "pbrMetallicRoughness": {
            "baseColorFactor": [base_color[0], base_color[1], base_color[2], 1.0],
            "metallicFactor": metallic,
            "roughnessFactor": roughness_factor,
        },
        "extras": {"bouncefit": {
            "material": conversion.material,
            "notes": notes(conversion),
        }},
    });
    finish(material, extensions, json!({}))
}

/// The document holding `material` with its `extensions` (listed in `extensionsUsed`) and the
/// top-level fields of `more` (meshes, textures and the like).
fn finish(mut material: Value, extensions: Map<String, Value>, more: Value) -> String {
    let used: Vec<String> = extensions.keys().cloned().collect();
    if !extensions.is_empty() {
        material["extensions"] = Value::Object(extensions);
    }
    let mut document = json!({
        "asset": {
            "version": "2.0",
            "generator": format!("bouncefit {}", env!("CARGO_PKG_VERSION")),
        },
        "materials": [material],
    });
    if !used.is_empty() {
        document["extensionsUsed"] = json!(used);
    }
    if let (Value::Object(fields), Value::Object(more)) = (&mut document, more) {
        fields.extend(more);
    }
    let mut text = serde_json::to_string_pretty(&document).expect("a JSON value prints");
    text.push('\n');
    text
}

/// `[alpha_x, alpha_y]` of the glTF lobe written for the fitted `alpha` (module table): the
/// smaller alpha is `roughnessFactor^2`, and `KHR_materials_anisotropy` stretches it to
/// `mix(roughnessFactor^2, 1, anisotropyStrength^2)` along its direction; both capped at 1.
fn described_alpha(alpha: [f64; 2]) -> [f64; 2] {
    let (roughness, strength, along_y) = anisotropy(alpha);
    let low = roughness * roughness;
    let high = low + (1.0 - low) * strength * strength;
    if along_y {
        [low, high]
    } else {
        [high, low]
    }
}

/// The material the glTF document of `conversion` describes, as a bouncefit material that the
/// renderers here evaluate, so that what the export loses can be seen (`compare`'s report):
/// glTF's lobe is single-bounce, height-correlated GGX (glTF 2.0 appendix B.3.2) with
/// Schlick's Fresnel (B.3.4), whose F0 is the fitted one for both bases (a metal's
/// `baseColorFactor`; a dielectric's `KHR_materials_ior` reflectance times its
/// `KHR_materials_specular` colour), alpha as [`described_alpha`], and a metal's diffuse albedo
/// is dropped. One difference stays: glTF weights a dielectric's diffuse by `1 - F` (B.3.5,
/// `fresnel_mix`) where this keeps the fit's sum, brighter by at most `F` of the diffuse (about
/// 4% seen head-on).
pub fn described(conversion: &Conversion) -> Material {
    described_texel(
        &conversion.material,
        conversion.f0,
        conversion.base == Base::Metal,
    )
}

/// [`described`] of a material of reflectance `f0` at normal incidence on a `metal` base.
fn described_texel(material: &Material, f0: [f64; 3], metal: bool) -> Material {
    Material {
        model: Model::Single,
        ndf: NdfKind::Ggx,
        height: Height::Correlated,
        alpha: described_alpha(material.alpha),
        fresnel: FresnelSpec::Schlick { f0 },
        diffuse: if metal { [0.0; 3] } else { material.diffuse },
    }
}

/// The maps material the glTF document of a maps fit describes: [`described`] per texel, the
/// normal map as it is.
pub fn described_maps(conversion: &MapsConversion) -> MaterialMaps {
    let texels: Vec<Material> = conversion
        .texels
        .iter()
        .map(|t| described_texel(&t.material, t.f0, t.metal))
        .collect();
    MaterialMaps {
        base: texels[0].clone(),
        grid: conversion.maps.grid,
        diffuse: Some(texels.iter().map(|t| t.diffuse).collect()),
        specular: Some(conversion.texels.iter().map(|t| t.f0).collect()),
        roughness: Some(texels.iter().map(|t| t.alpha).collect()),
        normal: conversion.maps.normal.clone(),
    }
}

/// glTF sampler constants (glTF 2.0 section 5.26, "sampler"): NEAREST and CLAMP_TO_EDGE.
const NEAREST: u32 = 9728;
const CLAMP_TO_EDGE: u32 = 33071;

/// The glTF document of a maps material: the material with its textures (URIs
/// `<prefix>/<file>`, see [`super::maps`]) on a quad the sample's size, `sample` = `[width,
/// height]`, in the plane z = 0 facing +z (module docs, "Maps").
pub fn maps_document(
    conversion: &MapsConversion,
    textures: &PbrTextures,
    prefix: &str,
    sample: [f64; 2],
) -> String {
    let mut images = Vec::new();
    let mut texture = |path: &Path| {
        let name = path.file_name().unwrap_or_default().to_string_lossy();
        images.push(json!({"uri": format!("{prefix}/{name}")}));
        json!({"index": images.len() - 1})
    };
    let mut material = json!({
        "name": format!("bouncefit {} maps", conversion.maps.base.model.name()),
        "pbrMetallicRoughness": {
            "baseColorTexture": texture(&textures.base_color),
            "metallicRoughnessTexture": texture(&textures.metallic_roughness),
            "metallicFactor": 1.0,
            "roughnessFactor": 1.0,
        },
    });
    if let Some(normal) = &textures.normal {
        material["normalTexture"] = texture(normal);
    }
    let mut extensions = Map::new();
    if let Some(ior) = conversion.dielectric_ior {
        extensions.insert("KHR_materials_ior".into(), json!({ "ior": ior }));
    }
    if let Some(specular) = &textures.specular_color {
        extensions.insert(
            "KHR_materials_specular".into(),
            json!({"specularFactor": 1.0, "specularColorTexture": texture(specular)}),
        );
    }
    if let Some(anisotropy) = &textures.anisotropy {
        extensions.insert(
            "KHR_materials_anisotropy".into(),
            json!({"anisotropyStrength": 1.0, "anisotropyRotation": 0.0,
                   "anisotropyTexture": texture(anisotropy)}),
        );
    }
    let mut notes = conversion.notes();
    notes.push(
        "the quad's TEXCOORD_0 runs u from 0 at the sample's -x edge to 1 at +x, and v from 0 \
         at the +y edge (texel row 0) to 1 at -y; its TANGENT is +x, so the normal texture's \
         green channel points to +y"
            .into(),
    );
    if conversion.dielectric_ior.is_some() {
        notes.push(DIFFUSE_LAYER_NOTE.into());
    }
    notes.extend(lobe_notes(&conversion.roughest));
    material["extras"] = json!({"bouncefit": {
        "material": conversion.maps.base,
        "texels": [conversion.maps.grid.width, conversion.maps.grid.height],
        "notes": notes,
    }});
    let count = images.len();
    let mut more = quad(sample);
    more["images"] = json!(images);
    more["samplers"] = json!([{
        "magFilter": NEAREST, "minFilter": NEAREST,
        "wrapS": CLAMP_TO_EDGE, "wrapT": CLAMP_TO_EDGE,
    }]);
    more["textures"] = json!((0..count)
        .map(|i| json!({"sampler": 0, "source": i}))
        .collect::<Vec<_>>());
    finish(material, extensions, more)
}

/// The sample as a two-triangle quad (glTF 2.0 sections 3.7.2 "Meshes", 3.6 "Buffers"): one
/// buffer in a `data:` URI holding positions, normals, tangents, texture coordinates (f32)
/// and indices (u16), a node and a scene; the primitive uses material 0.
fn quad(sample: [f64; 2]) -> Value {
    let (x, y) = ((sample[0] / 2.0) as f32, (sample[1] / 2.0) as f32);
    // Counter-clockwise seen from +z (glTF front faces); v = 0 at the +y edge.
    let corners = [
        (-x, -y, 0.0, 1.0),
        (x, -y, 1.0, 1.0),
        (x, y, 1.0, 0.0),
        (-x, y, 0.0, 0.0),
    ];
    let attributes: [(&str, &str, Vec<f32>); 4] = [
        (
            "POSITION",
            "VEC3",
            corners.iter().flat_map(|c| [c.0, c.1, 0.0]).collect(),
        ),
        (
            "NORMAL",
            "VEC3",
            corners.iter().flat_map(|_| [0.0, 0.0, 1.0]).collect(),
        ),
        (
            "TANGENT",
            "VEC4",
            corners.iter().flat_map(|_| [1.0, 0.0, 0.0, 1.0]).collect(),
        ),
        (
            "TEXCOORD_0",
            "VEC2",
            corners.iter().flat_map(|c| [c.2, c.3]).collect(),
        ),
    ];
    let mut bytes = Vec::new();
    let (mut views, mut accessors, mut primitive) = (Vec::new(), Vec::new(), Map::new());
    for (name, kind, values) in &attributes {
        let components = values.len() / corners.len();
        views.push(json!({"buffer": 0, "byteOffset": bytes.len(), "byteLength": 4 * values.len(), "target": 34962}));
        let mut accessor = json!({"bufferView": views.len() - 1, "componentType": 5126, "count": corners.len(), "type": kind});
        if *name == "POSITION" {
            let column = |c: usize| values.iter().skip(c).step_by(components).cloned();
            accessor["min"] = json!((0..3)
                .map(|c| column(c).fold(f32::MAX, f32::min))
                .collect::<Vec<_>>());
            accessor["max"] = json!((0..3)
                .map(|c| column(c).fold(f32::MIN, f32::max))
                .collect::<Vec<_>>());
        }
        bytes.extend(values.iter().flat_map(|v| v.to_le_bytes()));
        accessors.push(accessor);
        primitive.insert((*name).into(), json!(accessors.len() - 1));
    }
    let indices: [u16; 6] = [0, 1, 2, 0, 2, 3];
    views.push(json!({"buffer": 0, "byteOffset": bytes.len(), "byteLength": 2 * indices.len(), "target": 34963}));
    bytes.extend(indices.iter().flat_map(|i| i.to_le_bytes()));
    accessors.push(json!({"bufferView": views.len() - 1, "componentType": 5123, "count": indices.len(), "type": "SCALAR"}));
    json!({
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "sample", "mesh": 0}],
        "meshes": [{"name": "sample", "primitives": [{
            "attributes": primitive,
            "indices": accessors.len() - 1,
            "material": 0,
        }]}],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{
            "byteLength": bytes.len(),
            "uri": format!("data:application/octet-stream;base64,{}", BASE64.encode(&bytes)),
        }],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn conversion(alpha: [f64; 2], fresnel: FresnelSpec, diffuse: [f64; 3]) -> Conversion {
        Conversion::new(&Material {
            model: Model::KullaConty,
            ndf: NdfKind::Beckmann,
            height: Height::Uncorrelated,
            alpha,
            fresnel,
            diffuse,
        })
    }

    /// What glTF describes: single-bounce correlated GGX, the fitted F0 as Schlick's, the
    /// alphas that roughnessFactor and KHR_materials_anisotropy give back (capped at 1), and
    /// a metal's diffuse dropped while a dielectric keeps it.
    #[test]
    fn described_material_is_what_the_document_carries() {
        let copper = FresnelSpec::Conductor {
            eta: [0.27, 0.68, 1.3],
            k: [3.6, 2.6, 2.3],
        };
        let metal = described(&conversion([0.3, 0.3], copper, [0.2; 3]));
        assert_eq!(
            (metal.model, metal.ndf, metal.height),
            (Model::Single, NdfKind::Ggx, Height::Correlated)
        );
        assert_eq!(metal.fresnel, FresnelSpec::Schlick { f0: copper.f0() });
        assert_eq!(metal.diffuse, [0.0; 3]);
        let close = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).abs() + (a[1] - b[1]).abs() < 1e-12;
        assert!(close(metal.alpha, [0.3, 0.3]), "{:?}", metal.alpha);
        let stretched = described(&conversion([0.2, 0.6], copper, [0.0; 3]));
        assert!(close(stretched.alpha, [0.2, 0.6]), "{:?}", stretched.alpha);
        let capped = described(&conversion([1.5, 0.5], copper, [0.0; 3]));
        assert!(close(capped.alpha, [1.0, 0.5]), "{:?}", capped.alpha);
        let plastic = FresnelSpec::Schlick { f0: [0.04; 3] };
        let dielectric = described(&conversion([0.3, 0.3], plastic, [0.6, 0.2, 0.1]));
        assert_eq!(dielectric.diffuse, [0.6, 0.2, 0.1]);
        assert_eq!(dielectric.fresnel, plastic);
    }
}
