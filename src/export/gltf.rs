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

use super::{Base, Conversion};
use crate::material::FresnelSpec;
use crate::microfacet::Height;
use serde_json::{json, Map, Value};

/// glTF's roughness range is [0, 1].
fn roughness(alpha: f64) -> f64 {
    alpha.sqrt().min(1.0)
}

/// `(roughnessFactor, KHR_materials_anisotropy)`, see the module table.
fn roughness_and_anisotropy(conversion: &Conversion) -> (f64, Option<Value>) {
    let [ax, ay] = conversion.material.alpha;
    if !conversion.is_anisotropic() {
        return (roughness(ax), None);
    }
    let (low, high) = (ax.min(ay), ax.max(ay).min(1.0));
    let strength = ((high - low) / (1.0 - low)).max(0.0).sqrt();
    let rotation = if ax >= ay {
        0.0
    } else {
        std::f64::consts::FRAC_PI_2
    };
    (
        roughness(low),
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
    notes.extend(conversion.ggx_roughness_notes("glTF"));
    if material.height == Height::Uncorrelated {
        notes.push(
            "glTF's visibility term is the height-correlated Smith G2; the fit used the uncorrelated one"
                .into(),
        );
    }
    if let Base::Dielectric { ior, .. } = conversion.base {
        if ior < 1.0 {
            notes.push(format!(
                "KHR_materials_ior needs ior >= 1: 1/{} (the same F0) is written",
                super::number(ior)
            ));
        }
        notes.push(
            "glTF weights the diffuse by the specular layer's transmission (1 - F); the fit adds it"
                .into(),
        );
    }
    notes.extend(conversion.dropped_diffuse_note());
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
    let mut material = json!({
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
    let mut text = serde_json::to_string_pretty(&document).expect("a JSON value prints");
    text.push('\n');
    text
}
