//! `--format json`: the material in the material-file format (DESIGN.md "Material / fit file"),
//! without the fit's bookkeeping, plus the derived colours renderers ask for.
//!
//! | field | value |
//! | --- | --- |
//! | `model`, `ndf`, `height`, `alpha`, `fresnel`, `diffuse` | the fitted material, as [`Material::load`](crate::material::Material::load) reads it back |
//! | `f0` | reflectance at normal incidence (Gulbrandsen's reflectivity `r`) |
//! | `edge_tint` | conductors only: Gulbrandsen's edge tint `g` (JCGT 3(4) 2014, eq. 2-5) |

use super::Conversion;
use crate::material::FresnelSpec;

/// The JSON document for `conversion`.
pub fn document(conversion: &Conversion) -> String {
    // A material is plain data (no maps, finite numbers): serialising it cannot fail.
    let mut value =
        serde_json::to_value(&conversion.material).expect("a material serialises to JSON");
    let fields = value
        .as_object_mut()
        .expect("a material serialises as a JSON object");
    fields.insert("f0".into(), conversion.f0.into());
    if let FresnelSpec::Conductor { .. } = conversion.material.fresnel {
        fields.insert("edge_tint".into(), conversion.edge_tint.into());
    }
    let mut text = serde_json::to_string_pretty(&value).expect("a JSON value prints");
    text.push('\n');
    text
}
