//! `--format materialx`: a MaterialX 1.39 document with two materials for the same fit, one
//! `standard_surface` (Autodesk Standard Surface 1.0.1) and one `open_pbr_surface` (OpenPBR
//! 1.1), with the input names of the nodedefs in the MaterialX library
//! (`libraries/bxdf/standard_surface.mtlx`, `libraries/bxdf/open_pbr_surface.mtlx`).
//!
//! | fitted | `standard_surface` | `open_pbr_surface` |
//! | --- | --- | --- |
//! | metal base | `metalness` 1, `base_color` = F0, `specular_color` = Gulbrandsen edge tint (its metal is Gulbrandsen's artistic conductor: exact for a conductor fit whose tint lies in [0, 1]) | `base_metalness` 1, `base_color` = F0, `specular_color` = F82 tint (its metal is the F82-tint Schlick: exact for a Schlick fit, exact at 0 and 82 degrees for a conductor) |
//! | dielectric base | `metalness` 0, `base_color` = diffuse, `specular_IOR`, `specular_color` = F0 tint | `base_metalness` 0, `base_color` = diffuse, `specular_ior`, `specular_color` = F0 tint |
//! | isotropic `alpha` | `specular_roughness = sqrt(alpha)` | `specular_roughness = sqrt(alpha)` |
//! | anisotropic, `alpha_t >= alpha_b` | `roughness_anisotropy`: `alpha_t = r^2 / sqrt(1 - a)`, `alpha_b = r^2 sqrt(1 - a)`, so `r = (alpha_t alpha_b)^(1/4)`, `specular_anisotropy = 1 - alpha_b / alpha_t` (at most 0.98), `specular_rotation` 0, or 0.25 (90 degrees) when `alpha_y > alpha_x` | `open_pbr_anisotropy`: `alpha_t = r^2 sqrt(2 / (1 + (1 - a)^2))`, `alpha_b = (1 - a) alpha_t`, so `r = ((alpha_t^2 + alpha_b^2) / 2)^(1/4)`, `specular_roughness_anisotropy = 1 - alpha_b / alpha_t`; OpenPBR has no rotation input, the tangent must follow the larger alpha |
//!
//! Both shading models are single-bounce GGX with their own energy handling; the document's
//! comments state what differs from the fit (model, distribution, diffuse layer).
//!
//! ## Maps
//!
//! A maps material ([`maps_document`]) reads the glTF export's textures ([`super::maps`])
//! through `image` nodes (MaterialX 1.39 Standard Nodes: `file` with `colorspace`
//! `srgb_texture` for colour, `raw` for data; `filtertype` "closest", the fit's nearest-texel
//! lookup), `extract` nodes taking roughness (index 1) and metalness (index 2) from the packed
//! texture, and a `normalmap` node (tangent space) into `normal` / `geometry_normal`. MaterialX
//! puts an image's lower left at texture coordinate (0, 0), so the geometry's v must run from
//! the sample's -y edge to +y (stated in the comments). Metal texels have `specular_color` 1:
//! exact Schlick for `open_pbr_surface`, Gulbrandsen's edge tint 1 (not Schlick's curve) for
//! `standard_surface`; multiple scattering is not carried.

use super::maps::{MapsConversion, PbrTextures};
use super::roughness::{
    open_pbr_roughness, standard_surface_roughness, STANDARD_SURFACE_MAX_ANISOTROPY,
};
use super::{number, triple, xml_comment, Base, Conversion};
use crate::bsdf::Model;
use crate::material::FresnelSpec;
use crate::microfacet::fresnel::ior_from_reflectivity_edge_tint;
use std::path::Path;

/// A typed input value of a MaterialX node.
#[derive(Clone, Debug, PartialEq)]
enum Input {
    Float(f64),
    Color3([f64; 3]),
    /// The output of the node named `.1`, of type `.0`.
    Node(&'static str, String),
}

fn inputs_xml(node: &str, name: &str, inputs: &[(&str, Input)]) -> String {
    let mut xml = format!("  <{node} name=\"{name}\" type=\"surfaceshader\">\n");
    for (input, value) in inputs {
        let (kind, attribute, text) = match value {
            Input::Float(x) => ("float", "value", number(*x)),
            Input::Color3(c) => ("color3", "value", triple(*c)),
            Input::Node(kind, node) => (*kind, "nodename", node.clone()),
        };
        xml += &format!("    <input name=\"{input}\" type=\"{kind}\" {attribute}=\"{text}\" />\n");
    }
    xml + &format!("  </{node}>\n")
}

fn material_xml(name: &str, shader: &str) -> String {
    format!(
        "  <surfacematerial name=\"{name}\" type=\"material\">\n    <input name=\"surfaceshader\" type=\"surfaceshader\" nodename=\"{shader}\" />\n  </surfacematerial>\n"
    )
}

/// The input names in which the two shaders differ for the same meaning.
struct ShaderNames {
    base_weight: &'static str,
    metalness: &'static str,
    specular_weight: &'static str,
    ior: &'static str,
}

/// The inputs both shaders share up to their names; `metal_specular_color` is the shader's own
/// metal edge colour, `anisotropic` gives its roughness inputs from an anisotropic `alpha`.
fn shader_inputs(
    conversion: &Conversion,
    names: ShaderNames,
    metal_specular_color: [f64; 3],
    anisotropic: impl Fn([f64; 2]) -> Vec<(&'static str, Input)>,
) -> Vec<(&'static str, Input)> {
    let (metalness, base_color, specular_color, ior) = match conversion.base {
        Base::Metal => (1.0, conversion.f0, metal_specular_color, None),
        Base::Dielectric { ior, specular_tint } => {
            (0.0, conversion.material.diffuse, specular_tint, Some(ior))
        }
    };
    let mut inputs = vec![
        (names.base_weight, Input::Float(1.0)),
        ("base_color", Input::Color3(base_color)),
        (names.metalness, Input::Float(metalness)),
        (names.specular_weight, Input::Float(1.0)),
        ("specular_color", Input::Color3(specular_color)),
    ];
    if let Some(ior) = ior {
        inputs.push((names.ior, Input::Float(ior)));
    }
    let alpha = conversion.material.alpha;
    if conversion.is_anisotropic() {
        inputs.extend(anisotropic(alpha));
    } else {
        inputs.push(("specular_roughness", Input::Float(alpha[0].sqrt())));
    }
    inputs
}

const STANDARD_SURFACE_NAMES: ShaderNames = ShaderNames {
    base_weight: "base",
    metalness: "metalness",
    specular_weight: "specular",
    ior: "specular_IOR",
};

const OPEN_PBR_NAMES: ShaderNames = ShaderNames {
    base_weight: "base_weight",
    metalness: "base_metalness",
    specular_weight: "specular_weight",
    ior: "specular_ior",
};

fn standard_surface(conversion: &Conversion) -> Vec<(&'static str, Input)> {
    shader_inputs(
        conversion,
        STANDARD_SURFACE_NAMES,
        conversion.edge_tint,
        |alpha| {
            let [r, a, rotation] = standard_surface_roughness(alpha);
            vec![
                ("specular_roughness", Input::Float(r)),
                ("specular_anisotropy", Input::Float(a)),
                ("specular_rotation", Input::Float(rotation)),
            ]
        },
    )
}

fn open_pbr_surface(conversion: &Conversion) -> Vec<(&'static str, Input)> {
    shader_inputs(conversion, OPEN_PBR_NAMES, conversion.f82_tint, |alpha| {
        let [r, a] = open_pbr_roughness(alpha);
        vec![
            ("specular_roughness", Input::Float(r)),
            ("specular_roughness_anisotropy", Input::Float(a)),
        ]
    })
}

fn notes(conversion: &Conversion) -> Vec<String> {
    let material = &conversion.material;
    let mut notes = Vec::new();
    if conversion.base == Base::Metal {
        let (eta, k) = (conversion.conductor.eta, conversion.conductor.k);
        let tint_error = (0..3)
            .map(|c| {
                let (e, kk) =
                    ior_from_reflectivity_edge_tint(conversion.f0[c], conversion.edge_tint[c]);
                (e - eta[c]).abs().max((kk - k[c]).abs())
            })
            .fold(0.0, f64::max);
        let conductor_source = match material.fresnel {
            FresnelSpec::Conductor { .. } => "the fitted conductor".to_string(),
            _ => format!(
                "the conductor with the fitted F0 closest to Schlick's curve (largest Fresnel difference {})",
                number(conversion.conductor.max_error)
            ),
        };
        notes.push(format!(
            "standard_surface: base_color and specular_color are Gulbrandsen's reflectivity and \
             edge tint of {conductor_source}; they give back its eta, k to {}",
            number(tint_error)
        ));
        notes.push(match material.fresnel {
            FresnelSpec::Conductor { .. } => "open_pbr_surface: specular_color is the F82 tint, \
                 the conductor's reflectance at cos = 1/7 over Schlick's; the F82-tint curve \
                 matches the conductor at 0 and 82 degrees"
                .to_string(),
            _ => "open_pbr_surface: specular_color 1 makes its F82-tint Fresnel Schlick's exactly"
                .to_string(),
        });
    }
    if conversion.is_anisotropic() {
        let [ax, ay] = material.alpha;
        let (high, low, along_y) = (ax.max(ay), ax.min(ay), ay > ax);
        if 1.0 - low / high > STANDARD_SURFACE_MAX_ANISOTROPY {
            notes.push(format!(
                "standard_surface clamps its anisotropy at {STANDARD_SURFACE_MAX_ANISOTROPY}: \
                 the fitted ratio alpha_b / alpha_t = {} is not reached",
                number(low / high)
            ));
        }
        if along_y {
            notes.push(
                "open_pbr_surface has no rotation input: the larger roughness is along y, so \
                 geometry_tangent must point along the sample's y axis"
                    .into(),
            );
        }
    }
    if let Base::Dielectric { .. } = conversion.base {
        notes.push(
            "both shaders layer the diffuse under the specular (weighted by its transmission); \
             the fit adds them"
                .into(),
        );
    }
    notes.extend(conversion.dropped_diffuse_note());
    notes.extend(shared_notes(conversion));
    notes
}

/// The notes on the roughness range, distribution and multi-bounce energy.
fn shared_notes(conversion: &Conversion) -> Vec<String> {
    let mut notes = conversion.ggx_roughness_notes("standard_surface and open_pbr_surface");
    notes.extend(conversion.common_notes());
    notes
}

/// The `.mtlx` document for `conversion`.
pub fn document(conversion: &Conversion) -> String {
    header(conversion.material.model, &notes(conversion))
        + &shaders(&standard_surface(conversion), &open_pbr_surface(conversion))
}

/// The document's opening and its comments, up to the first node.
fn header(model: Model, notes: &[String]) -> String {
    let mut xml = String::from("<?xml version=\"1.0\"?>\n<materialx version=\"1.39\">\n");
    xml += &xml_comment(
        "  ",
        &format!(
            "bouncefit {} export of a '{}' fit: the same material as standard_surface and as open_pbr_surface",
            env!("CARGO_PKG_VERSION"),
            model.name()
        ),
    );
    for note in notes {
        xml += &xml_comment("  ", note);
    }
    xml
}

/// The two shaders with these inputs, their materials, and the document's end.
fn shaders(standard_surface: &[(&str, Input)], open_pbr_surface: &[(&str, Input)]) -> String {
    let mut xml = inputs_xml(
        "standard_surface",
        "SR_bouncefit_standard_surface",
        standard_surface,
    );
    xml += &material_xml(
        "M_bouncefit_standard_surface",
        "SR_bouncefit_standard_surface",
    );
    xml += &inputs_xml(
        "open_pbr_surface",
        "SR_bouncefit_open_pbr_surface",
        open_pbr_surface,
    );
    xml += &material_xml(
        "M_bouncefit_open_pbr_surface",
        "SR_bouncefit_open_pbr_surface",
    );
    xml + "</materialx>\n"
}

/// The image, extract and normalmap nodes (MaterialX 1.39 Standard Nodes: `image` with
/// `filtertype` "closest", `extract`, `normalmap`) reading the textures of
/// [`MapsConversion::write_pbr_textures`] (files `<prefix>/<name>`), and the inputs they feed,
/// by meaning: base colour, metalness, roughness, specular colour, normal.
struct MapNodes {
    xml: String,
    base_color: Input,
    metalness: Input,
    roughness: Input,
    specular_color: Input,
    normal: Option<Input>,
    /// Anisotropic maps: each shader's roughness inputs (name, node), and open_pbr_surface's
    /// tangent.
    standard_surface_roughness: Vec<(&'static str, Input)>,
    open_pbr_roughness: Vec<(&'static str, Input)>,
    tangent: Option<Input>,
}

fn map_nodes(textures: &PbrTextures, prefix: &str) -> MapNodes {
    let mut xml = String::new();
    let mut image = |node: &str, kind: &'static str, path: &Path, colorspace: &str| {
        let name = path.file_name().unwrap_or_default().to_string_lossy();
        xml += &format!(
            "  <image name=\"{node}\" type=\"{kind}\">\n    <input name=\"file\" type=\"filename\" value=\"{prefix}/{name}\" colorspace=\"{colorspace}\" />\n    <input name=\"filtertype\" type=\"string\" value=\"closest\" />\n  </image>\n"
        );
        Input::Node(kind, node.to_string())
    };
    let base_color = image(
        "base_color_image",
        "color3",
        &textures.base_color,
        "srgb_texture",
    );
    let metallic_roughness = image(
        "metallic_roughness_image",
        "vector3",
        &textures.metallic_roughness,
        "raw",
    );
    let specular_color = match &textures.specular_color {
        Some(path) => image("specular_color_image", "color3", path, "srgb_texture"),
        None => Input::Color3([1.0; 3]),
    };
    // The data textures a maps material may lack: raw `vector3` images.
    let mut data = |node: &str, path: &Option<std::path::PathBuf>| {
        path.as_deref()
            .map(|path| image(node, "vector3", path, "raw"))
    };
    let normal_image = data("normal_image", &textures.normal);
    let standard_image = data(
        "standard_surface_roughness_image",
        &textures.standard_surface_roughness,
    );
    let open_pbr_image = data("open_pbr_roughness_image", &textures.open_pbr_roughness);
    let tangent = data("tangent_image", &textures.tangent);
    let Input::Node(_, packed) = metallic_roughness else {
        unreachable!("an image is a node")
    };
    let mut node = |name: &str, kind: &'static str, inputs: &[(&str, Input)], extra: &str| {
        xml += &format!(
            "  <{kind} name=\"{name}\" type=\"{}\">\n",
            if kind == "normalmap" {
                "vector3"
            } else {
                "float"
            }
        );
        for (input, value) in inputs {
            let Input::Node(kind, from) = value else {
                unreachable!("map nodes take node outputs")
            };
            xml += &format!("    <input name=\"{input}\" type=\"{kind}\" nodename=\"{from}\" />\n");
        }
        xml += extra;
        xml += &format!("  </{kind}>\n");
        Input::Node(
            if kind == "normalmap" {
                "vector3"
            } else {
                "float"
            },
            name.to_string(),
        )
    };
    let packed = Input::Node("vector3", packed);
    let index = |i: u8| format!("    <input name=\"index\" type=\"integer\" value=\"{i}\" />\n");
    let roughness = node("roughness", "extract", &[("in", packed.clone())], &index(1));
    let metalness = node("metalness", "extract", &[("in", packed)], &index(2));
    let normal = normal_image.map(|from| node("normal", "normalmap", &[("in", from)], ""));
    let mut extracted = |image: Option<Input>, inputs: &[(&'static str, &str)]| match image {
        Some(packed) => inputs
            .iter()
            .enumerate()
            .map(|(i, &(input, name))| {
                let index = index(i as u8);
                (
                    input,
                    node(name, "extract", &[("in", packed.clone())], &index),
                )
            })
            .collect(),
        None => Vec::new(),
    };
    let standard_surface_roughness = extracted(
        standard_image,
        &[
            ("specular_roughness", "standard_surface_roughness"),
            ("specular_anisotropy", "standard_surface_anisotropy"),
            ("specular_rotation", "standard_surface_rotation"),
        ],
    );
    let open_pbr_roughness = extracted(
        open_pbr_image,
        &[
            ("specular_roughness", "open_pbr_roughness"),
            ("specular_roughness_anisotropy", "open_pbr_anisotropy"),
        ],
    );
    MapNodes {
        xml,
        base_color,
        metalness,
        roughness,
        specular_color,
        normal,
        standard_surface_roughness,
        open_pbr_roughness,
        tangent,
    }
}

/// The `.mtlx` document of a maps material: image nodes (module docs, "Maps") feeding a
/// `standard_surface` and an `open_pbr_surface`.
pub fn maps_document(conversion: &MapsConversion, textures: &PbrTextures, prefix: &str) -> String {
    let nodes = map_nodes(textures, prefix);
    let shader =
        |names: ShaderNames, normal: &'static str, anisotropic: &[(&'static str, Input)]| {
            let mut inputs = vec![
                (names.base_weight, Input::Float(1.0)),
                ("base_color", nodes.base_color.clone()),
                (names.metalness, nodes.metalness.clone()),
                (names.specular_weight, Input::Float(1.0)),
                ("specular_color", nodes.specular_color.clone()),
            ];
            if anisotropic.is_empty() {
                inputs.push(("specular_roughness", nodes.roughness.clone()));
            } else {
                inputs.extend(anisotropic.iter().cloned());
            }
            if let Some(ior) = conversion.dielectric_ior {
                inputs.push((names.ior, Input::Float(ior)));
            }
            if let Some(n) = &nodes.normal {
                inputs.push((normal, n.clone()));
            }
            inputs
        };
    let mut notes = conversion.notes();
    notes.push(
        "the images' row 0 is the sample's +y edge: MaterialX puts an image's lower left at \
         texture coordinate (0, 0), so the geometry's v must run from 0 at the sample's -y \
         edge to 1 at +y, u from 0 at -x to 1 at +x"
            .into(),
    );
    if conversion.metal_count() > 0 {
        notes.push(
            "metal texels have specular_color 1: open_pbr_surface's F82-tint Fresnel is then \
             Schlick's exactly; standard_surface's is Gulbrandsen's conductor with edge tint 1, \
             not the Schlick curve"
                .into(),
        );
    }
    if nodes.tangent.is_some() {
        notes.push(
            "anisotropic texels: standard_surface turns its anisotropy by specular_rotation \
             (0: along the geometry's tangent, which must be the sample's +x; 0.25: along +y); \
             open_pbr_surface, which has no rotation, reads geometry_tangent from \
             tangent.png (+x or +y, world space of a sample in the z = 0 plane)"
                .into(),
        );
    }
    notes.extend(shared_notes(&conversion.roughest));
    let mut xml = header(conversion.maps.base.model, &notes);
    xml += &nodes.xml;
    let mut open_pbr = shader(OPEN_PBR_NAMES, "geometry_normal", &nodes.open_pbr_roughness);
    if let Some(tangent) = &nodes.tangent {
        open_pbr.push(("geometry_tangent", tangent.clone()));
    }
    xml + &shaders(
        &shader(
            STANDARD_SURFACE_NAMES,
            "normal",
            &nodes.standard_surface_roughness,
        ),
        &open_pbr,
    )
}
