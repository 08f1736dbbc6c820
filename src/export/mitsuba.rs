//! `--format mitsuba`: a complete Mitsuba 3 scene (`<scene version="3.0.0">`) with the fitted
//! BSDF on the flat sample, a camera and a light (Mitsuba 3 plugin reference: `roughconductor`,
//! `blendbsdf`, `diffuse`, `rectangle`, `perspective`, `point`, `directional`, `direct`).
//!
//! | fitted | written | exact? |
//! | --- | --- | --- |
//! | `alpha` | `alpha`, or `alpha_u` / `alpha_v` (u = sample x) | yes |
//! | `ndf` | `distribution` `ggx` / `beckmann` | yes |
//! | conductor Fresnel | `eta`, `k` as `rgb` | yes |
//! | dielectric Fresnel | `eta`, `k = 0` (the same reflectance) | yes |
//! | Schlick / white Fresnel | `eta`, `k` of the conductor with the same `F0` whose Gulbrandsen edge tint is fitted to Schlick's curve (Mitsuba 3 has no Schlick conductor) | `F0` yes, the curve to the stated error |
//! | `height: correlated` | Mitsuba's roughconductor uses the uncorrelated `G1(wi) G1(wo)` | no, stated |
//! | multi-bounce models | the same roughconductor: Mitsuba 3 has no multiple-scattering conductor | no, the missing energy is stated |
//! | `diffuse` | `blendbsdf` with weight 0.5 of the roughconductor and a `diffuse`, both with reflectance doubled, so the sum is `f_spec + diffuse / pi` | yes (RGB variants; spectral variants may clamp reflectances above 1) |
//!
//! The scene: the sample is a `rectangle` scaled to the capture's sample (capture units); the
//! camera and light are those of one photo of a capture (the first photo of the capture the fit
//! file names, or, with `export --scene`, every photo in turn: one scene per photo, since each
//! photo has its own light), else a default flash setup ([`Scene::default_flash`]).
//!
//! | capture | written | exact? |
//! | --- | --- | --- |
//! | pinhole camera | `perspective` with `to_world` look-at (position, look-at, up), `fov` from `fy` on the y axis, `principal_point_offset_x = (W/2 - cx) / W`, `principal_point_offset_y = (H/2 - cy) / H` | yes when `fx = fy` (Mitsuba's pixels are square); otherwise stated |
//! | rectified camera at `P` | `perspective` at `P` looking straight down (`up` = +y), `fov` such that the film spans the sample's height at depth `P.z`, principal point offsets `-P.x / width`, `P.y / height`: the image plane is parallel to the sample, so the plane maps affinely onto the film exactly as the rectified image does, and every pixel sees its point from `P` | yes when the film's aspect equals the sample's; otherwise stated |
//! | pixel footprint | `box` reconstruction filter (the tool averages stratified samples over each pixel) | yes |
//! | point light / flash | `point` emitter at the light (flash: at the camera) with `intensity x exposure` | yes |
//! | directional light | `directional` emitter with `irradiance x exposure` | yes |
//! | integrator | `direct` (the tool renders direct lighting only) | yes |
//!
//! ## Maps
//!
//! A maps material ([`maps_document`]) is the same BSDF with `bitmap` textures (Mitsuba 3
//! plugin reference: `bitmap` with `raw` true and `filter_type` nearest, float EXRs of
//! [`super::maps`]) for `alpha` (or `alpha_u`, `alpha_v` where a texel is anisotropic), `eta`,
//! `k` and the doubled diffuse reflectance, under the
//! `normalmap` BSDF when the maps have normals (it evaluates the nested BSDF in the frame of the
//! texel's normal built from `dp_du` = +x, as [`crate::maps`] does). Every texel, metal or
//! dielectric, is the fit's sum of a Schlick-F0 GGX lobe and a Lambertian albedo, which the
//! `blendbsdf` sum gives exactly, so no metal mask or second BSDF is needed; the Schlick curve
//! becomes each texel's conductor with that F0 ([`super::SchlickTintTable`]), exact at normal
//! incidence (a co-located flash sees only that), within the stated Fresnel difference elsewhere;
//! for dielectric F0 (about 0.04) that absolute difference is large relative to F, so under a
//! light far from the camera dielectric texels render up to about 10% brighter than the fit
//! (measured in `tests/crosscheck/test_export_maps.py`).
//! Mitsuba's `rectangle` has `v = 0` at its -y edge and `bitmap` reads image row 0 at `v = 0`,
//! so each bitmap's `to_uv` flips `v` to put row 0 at +y. Agreement with `bouncefit render`:
//! `tests/crosscheck/test_export_maps.py`.
//!
//! Mitsuba 3's principal point offsets are fractions of the film size: a positive x offset turns
//! the ray through the film centre to image right, a positive y offset to image down (measured
//! with `Sensor::sample_ray`, mitsuba 3.9).

use super::maps::{MapsConversion, MitsubaTextures};
use super::{number, triple, xml_comment, Conversion, SchlickTintTable};
use crate::bsdf::Model;
use crate::capture::{Camera, Capture, Light, Pinhole, Rectified};
use crate::material::FresnelSpec;
use crate::microfacet::Height;
use glam::DVec3;

/// Where the scene's geometry comes from, with the camera and light of one photo.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    /// One sentence for the scene's comment: which capture and photo, or why the default.
    pub source: String,
    /// Sample `[width, height]` in capture units.
    pub sample: [f64; 2],
    pub camera: SceneCamera,
    /// The photo's light; a flash sits at the camera's origin.
    pub light: Light,
    /// The photo's exposure, which scales the light.
    pub exposure: f64,
    /// Approximations of the camera, one sentence each (empty when exact).
    pub notes: Vec<String>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct SceneCamera {
    pub origin: DVec3,
    pub target: DVec3,
    pub up: DVec3,
    pub fov_y_deg: f64,
    /// Mitsuba's `principal_point_offset_x`, `_y`: fractions of the film width and height.
    pub principal_point_offset: [f64; 2],
    pub resolution: [usize; 2],
}

impl Scene {
    /// The camera and light of the capture's first photo; `None` for a capture without photos.
    pub fn from_capture(capture: &Capture, path: &str) -> Option<Scene> {
        Scene::of_photo(capture, path, 0)
    }

    /// The camera, light and exposure of photo `index` of `capture` (read from `path`); `None`
    /// when there is no such photo.
    pub fn of_photo(capture: &Capture, path: &str, index: usize) -> Option<Scene> {
        let photo = capture.photos.get(index)?;
        let (camera, notes) = match &photo.camera {
            Camera::Pinhole(c) => pinhole_camera(c),
            Camera::Rectified(c) => {
                rectified_camera(c, capture.sample.width, capture.sample.height)
            }
        };
        Some(Scene {
            source: format!(
                "camera and light of photo '{}' of the capture '{path}' (units: {})",
                photo.image.display(),
                capture.units
            ),
            sample: [capture.sample.width, capture.sample.height],
            camera,
            light: photo.light.clone(),
            exposure: photo.exposure,
            notes,
        })
    }

    /// The default flash setup: a 10 x 10 sample, a 30 degree camera 30 units above its centre
    /// (128 x 128 pixels), and a point light of intensity 1000 at the camera (the example
    /// capture in docs/files.md).
    pub fn default_flash(reason: &str) -> Scene {
        Scene {
            source: format!("default flash setup ({reason})"),
            sample: [10.0, 10.0],
            camera: SceneCamera {
                origin: DVec3::new(0.0, 0.0, 30.0),
                target: DVec3::ZERO,
                up: DVec3::Y,
                fov_y_deg: 30.0,
                principal_point_offset: [0.0; 2],
                resolution: [128, 128],
            },
            light: Light::Flash {
                intensity: [1000.0; 3],
            },
            exposure: 1.0,
            notes: Vec::new(),
        }
    }
}

/// Relative difference above which two lengths that should match are reported as not matching.
const MISMATCH: f64 = 1e-9;

/// The perspective sensor of a pinhole camera (module table), with a note when `fx != fy`.
fn pinhole_camera(c: &Pinhole) -> (SceneCamera, Vec<String>) {
    let [width, height] = c.resolution.map(|n| n as f64);
    let mut notes = Vec::new();
    if (c.fx - c.fy).abs() > MISMATCH * c.fy {
        notes.push(format!(
            "the camera's fx {} differs from fy {}; Mitsuba's pixels are square, so the image \
             is stretched horizontally by {}",
            number(c.fx),
            number(c.fy),
            number(c.fy / c.fx)
        ));
    }
    let camera = SceneCamera {
        origin: c.position,
        target: c.look_at,
        up: c.up,
        fov_y_deg: 2.0 * (height / 2.0 / c.fy).atan().to_degrees(),
        principal_point_offset: [(width / 2.0 - c.cx) / width, (height / 2.0 - c.cy) / height],
        resolution: c.resolution,
    };
    (camera, notes)
}

/// The perspective sensor that sees exactly a rectified image (module table), with a note when
/// the film's aspect differs from the sample's.
fn rectified_camera(c: &Rectified, width: f64, height: f64) -> (SceneCamera, Vec<String>) {
    let [columns, rows] = c.resolution.map(|n| n as f64);
    let mut notes = Vec::new();
    let (film_aspect, sample_aspect) = (columns / rows, width / height);
    if (film_aspect - sample_aspect).abs() > MISMATCH * sample_aspect {
        notes.push(format!(
            "the rectified image's aspect {} differs from the sample's {}; Mitsuba's pixels are \
             square, so the film spans the sample's height but not exactly its width",
            number(film_aspect),
            number(sample_aspect)
        ));
    }
    let p = c.position;
    let camera = SceneCamera {
        origin: p,
        target: p - DVec3::Z,
        up: DVec3::Y,
        fov_y_deg: 2.0 * (height / 2.0 / p.z).atan().to_degrees(),
        principal_point_offset: [-p.x / width, p.y / height],
        resolution: c.resolution,
    };
    (camera, notes)
}

fn xyz(v: DVec3) -> String {
    format!("{}, {}, {}", number(v.x), number(v.y), number(v.z))
}

fn xyz_attributes(v: DVec3) -> String {
    format!(
        "x=\"{}\" y=\"{}\" z=\"{}\"",
        number(v.x),
        number(v.y),
        number(v.z)
    )
}

/// What the scene states about the BSDF, one sentence each.
fn notes(conversion: &Conversion) -> Vec<String> {
    let mut notes = vec![fresnel_note(conversion)];
    notes.extend(lobe_notes(conversion, conversion.has_diffuse()));
    notes
}

/// Where `eta` and `k` come from.
fn fresnel_note(conversion: &Conversion) -> String {
    match conversion.material.fresnel {
        FresnelSpec::Conductor { .. } => "eta and k are the fitted complex index of refraction".to_string(),
        FresnelSpec::Dielectric { eta } => format!(
            "the fitted dielectric Fresnel (eta {}) is the conductor eta + 0i, whose reflectance is the same",
            number(eta)
        ),
        FresnelSpec::Schlick { .. } | FresnelSpec::White => format!(
            "Mitsuba 3 has no Schlick conductor: eta and k are the conductor with the fitted F0 {} \
             (Gulbrandsen 2014 reflectivity) whose edge tint is fitted to Schlick's curve; \
             largest Fresnel difference over all angles {}",
            triple(conversion.f0),
            number(conversion.conductor.max_error)
        ),
    }
}

/// The notes on G2, the diffuse sum (`has_diffuse`) and the multi-bounce energy.
fn lobe_notes(conversion: &Conversion, has_diffuse: bool) -> Vec<String> {
    let mut notes = Vec::new();
    if conversion.material.height == Height::Correlated {
        notes.push(
            "the fit used the height-correlated Smith G2 = 1 / (1 + Lambda(wi) + Lambda(wo)); \
             roughconductor uses the uncorrelated G1(wi) G1(wo), slightly darker at grazing angles"
                .to_string(),
        );
    }
    if has_diffuse {
        notes.push(
            "blendbsdf with weight 0.5 of the roughconductor and the diffuse, both doubled, \
             is the sum f_specular + diffuse / pi of the fit"
                .to_string(),
        );
    }
    notes.extend(conversion.common_notes());
    notes
}

/// A BSDF parameter: a constant, or a texture file (Mitsuba 3 `bitmap`).
enum Param {
    Float(f64),
    Rgb([f64; 3]),
    /// A float EXR of the texel grid, read raw (no colour conversion), nearest texel, with the
    /// image's row 0 at the sample's +y edge: Mitsuba's `rectangle` has `v = 0` at its -y edge
    /// and `bitmap` puts the image's row 0 at `v = 0`, so `to_uv` flips `v`.
    Bitmap(String),
}

fn param(indent: &str, name: &str, value: &Param) -> String {
    match value {
        Param::Float(x) => format!(
            "{indent}<float name=\"{name}\" value=\"{}\"/>\n",
            number(*x)
        ),
        Param::Rgb(v) => format!("{indent}<rgb name=\"{name}\" value=\"{}\"/>\n", triple(*v)),
        Param::Bitmap(file) => format!(
            "{indent}<texture type=\"bitmap\" name=\"{name}\">
{indent}    <string name=\"filename\" value=\"{file}\"/>
{indent}    <boolean name=\"raw\" value=\"true\"/>
{indent}    <string name=\"filter_type\" value=\"nearest\"/>
{indent}    <transform name=\"to_uv\">
{indent}        <scale x=\"1\" y=\"-1\"/>
{indent}        <translate x=\"0\" y=\"1\"/>
{indent}    </transform>
{indent}</texture>\n"
        ),
    }
}

/// What the BSDF is built from: the roughconductor's parameters, the diffuse albedo (doubled,
/// see the module table) and the normal map.
struct Lobe {
    distribution: &'static str,
    alpha: Vec<(&'static str, Param)>,
    eta: Param,
    k: Param,
    doubled_diffuse: Option<Param>,
    normal: Option<Param>,
}

impl Lobe {
    fn uniform(conversion: &Conversion) -> Lobe {
        let [ax, ay] = conversion.material.alpha;
        Lobe {
            distribution: conversion.material.ndf.name(),
            alpha: if conversion.is_anisotropic() {
                vec![("alpha_u", Param::Float(ax)), ("alpha_v", Param::Float(ay))]
            } else {
                vec![("alpha", Param::Float(ax))]
            },
            eta: Param::Rgb(conversion.conductor.eta),
            k: Param::Rgb(conversion.conductor.k),
            doubled_diffuse: conversion
                .has_diffuse()
                .then(|| Param::Rgb(conversion.material.diffuse.map(|d| 2.0 * d))),
            normal: None,
        }
    }

    fn maps(conversion: &MapsConversion, textures: &MitsubaTextures, prefix: &str) -> Lobe {
        let file = |path: &std::path::Path| {
            let name = path.file_name().unwrap_or_default().to_string_lossy();
            Param::Bitmap(format!("{prefix}/{name}"))
        };
        Lobe {
            distribution: conversion.maps.base.ndf.name(),
            alpha: textures
                .alpha
                .iter()
                .map(|(name, path)| (*name, file(path)))
                .collect(),
            eta: file(&textures.eta),
            k: file(&textures.k),
            doubled_diffuse: textures.diffuse.as_deref().map(file),
            normal: textures.normal.as_deref().map(file),
        }
    }
}

fn roughconductor(lobe: &Lobe, indent: &str, id: &str, scale: f64) -> String {
    let inner = format!("{indent}    ");
    let mut xml = format!("{indent}<bsdf type=\"roughconductor\"{id}>\n");
    xml += &format!(
        "{inner}<string name=\"distribution\" value=\"{}\"/>\n",
        lobe.distribution
    );
    for (name, value) in &lobe.alpha {
        xml += &param(&inner, name, value);
    }
    xml += &param(&inner, "eta", &lobe.eta);
    xml += &param(&inner, "k", &lobe.k);
    if scale != 1.0 {
        xml += &param(&inner, "specular_reflectance", &Param::Float(scale));
    }
    xml + &format!("{indent}</bsdf>\n")
}

/// The roughconductor, summed with the diffuse through `blendbsdf`, under Mitsuba's
/// `normalmap` BSDF when there is a normal map; the outermost BSDF has the id `fitted`.
fn bsdf(lobe: &Lobe) -> String {
    let (indent, id) = match lobe.normal {
        Some(_) => ("        ", ""),
        None => ("    ", " id=\"fitted\""),
    };
    let inner = match &lobe.doubled_diffuse {
        None => roughconductor(lobe, indent, id, 1.0),
        Some(diffuse) => format!(
            "{indent}<bsdf type=\"blendbsdf\"{id}>\n{indent}    <float name=\"weight\" value=\"0.5\"/>\n{}{indent}    <bsdf type=\"diffuse\">\n{}{indent}    </bsdf>\n{indent}</bsdf>\n",
            roughconductor(lobe, &format!("{indent}    "), "", 2.0),
            param(&format!("{indent}        "), "reflectance", diffuse)
        ),
    };
    match &lobe.normal {
        None => inner,
        Some(normal) => format!(
            "    <bsdf type=\"normalmap\" id=\"fitted\">\n{}{inner}    </bsdf>\n",
            param("        ", "normalmap", normal)
        ),
    }
}

fn sensor(camera: &SceneCamera) -> String {
    format!(
        "    <sensor type=\"perspective\">
        <float name=\"fov\" value=\"{}\"/>
        <string name=\"fov_axis\" value=\"y\"/>
        <float name=\"principal_point_offset_x\" value=\"{}\"/>
        <float name=\"principal_point_offset_y\" value=\"{}\"/>
        <transform name=\"to_world\">
            <lookat origin=\"{}\" target=\"{}\" up=\"{}\"/>
        </transform>
        <sampler type=\"independent\">
            <integer name=\"sample_count\" value=\"64\"/>
        </sampler>
        <film type=\"hdrfilm\">
            <integer name=\"width\" value=\"{}\"/>
            <integer name=\"height\" value=\"{}\"/>
            <string name=\"pixel_format\" value=\"rgb\"/>
            <rfilter type=\"box\"/>
        </film>
    </sensor>
",
        number(camera.fov_y_deg),
        number(camera.principal_point_offset[0]),
        number(camera.principal_point_offset[1]),
        xyz(camera.origin),
        xyz(camera.target),
        xyz(camera.up),
        camera.resolution[0],
        camera.resolution[1]
    )
}

/// The emitter of `scene`'s light, its power scaled by the photo's exposure.
fn emitter(scene: &Scene) -> String {
    let scaled = |power: [f64; 3]| power.map(|v| v * scene.exposure);
    let point = |position: DVec3, intensity: [f64; 3]| {
        format!(
            "    <emitter type=\"point\">\n        <point name=\"position\" {}/>\n        <rgb name=\"intensity\" value=\"{}\"/>\n    </emitter>\n",
            xyz_attributes(position),
            triple(scaled(intensity))
        )
    };
    match scene.light {
        Light::Point {
            position,
            intensity,
        } => point(position, intensity),
        Light::Flash { intensity } => point(scene.camera.origin, intensity),
        Light::Directional {
            direction,
            irradiance,
        } => format!(
            "    <emitter type=\"directional\">\n        <vector name=\"direction\" {}/>\n        <rgb name=\"irradiance\" value=\"{}\"/>\n    </emitter>\n",
            xyz_attributes(-direction),
            triple(scaled(irradiance))
        ),
    }
}

/// The scene XML for `conversion` under `scene`.
pub fn document(conversion: &Conversion, scene: &Scene) -> String {
    scene_document(
        conversion.material.model,
        notes(conversion),
        &bsdf(&Lobe::uniform(conversion)),
        scene,
    )
}

/// The scene XML for a maps material under `scene`, its textures named `<prefix>/<file>`
/// relative to the scene file (module docs, "Maps").
pub fn maps_document(
    conversion: &MapsConversion,
    textures: &MitsubaTextures,
    prefix: &str,
    scene: &Scene,
) -> String {
    let mut all = conversion.notes();
    all.push(match conversion.roughest.material.fresnel {
        FresnelSpec::Schlick { .. } | FresnelSpec::White => format!(
            "Mitsuba 3 has no Schlick conductor: every texel's eta and k are the conductor with \
             its F0 whose edge tint follows Schlick's curve (tabulated over F0; largest Fresnel \
             difference {})",
            number(SchlickTintTable::get().max_error)
        ),
        _ => fresnel_note(&conversion.roughest),
    });
    all.extend(lobe_notes(&conversion.roughest, conversion.has_diffuse()));
    scene_document(
        conversion.maps.base.model,
        all,
        &bsdf(&Lobe::maps(conversion, textures, prefix)),
        scene,
    )
}

fn scene_document(model: Model, notes: Vec<String>, bsdf: &str, scene: &Scene) -> String {
    let mut xml = String::from("<?xml version=\"1.0\" encoding=\"utf-8\"?>\n");
    xml += &xml_comment(
        "",
        &format!(
            "bouncefit {} export of a '{}' fit; render with mitsuba (any RGB variant)",
            env!("CARGO_PKG_VERSION"),
            model.name()
        ),
    );
    xml += "<scene version=\"3.0.0\">\n";
    xml += "    <integrator type=\"direct\"/>\n";
    xml += &xml_comment("    ", &format!("scene: {}", scene.source));
    if scene.exposure != 1.0 {
        xml += &xml_comment(
            "    ",
            &format!(
                "the light's power is multiplied by the photo's exposure {}",
                number(scene.exposure)
            ),
        );
    }
    for note in scene.notes.iter().cloned().chain(notes) {
        xml += &xml_comment("    ", &note);
    }
    xml += bsdf;
    xml += &format!(
        "    <shape type=\"rectangle\">\n        <transform name=\"to_world\">\n            <scale x=\"{}\" y=\"{}\" z=\"1\"/>\n        </transform>\n        <ref id=\"fitted\"/>\n    </shape>\n",
        number(scene.sample[0] / 2.0),
        number(scene.sample[1] / 2.0)
    );
    xml += &sensor(&scene.camera);
    xml += &emitter(scene);
    xml + "</scene>\n"
}
