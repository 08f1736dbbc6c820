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
//! The scene: the sample is a `rectangle` scaled to the capture's sample (capture units), the
//! camera and light are those of the first photo of the capture the fit file names, else a
//! default flash setup ([`Scene::default_flash`]). A pinhole camera keeps position, look-at, up
//! and vertical field of view (a principal point off centre and `fx != fy` are not kept); a
//! rectified camera becomes a perspective camera at its position looking at the sample centre
//! and framing the sample's height. A flash is a point light at the camera.

use super::{number, triple, xml_comment, Conversion};
use crate::capture::{Camera, Capture, Light};
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
}

#[derive(Clone, Debug, PartialEq)]
pub struct SceneCamera {
    pub origin: DVec3,
    pub target: DVec3,
    pub up: DVec3,
    pub fov_y_deg: f64,
    pub resolution: [usize; 2],
}

impl Scene {
    /// The camera and light of the capture's first photo; `None` for a capture without photos.
    pub fn from_capture(capture: &Capture, path: &str) -> Option<Scene> {
        let photo = capture.photos.first()?;
        let camera = match &photo.camera {
            Camera::Pinhole(c) => SceneCamera {
                origin: c.position,
                target: c.look_at,
                up: c.up,
                fov_y_deg: 2.0 * (c.resolution[1] as f64 / 2.0 / c.fy).atan().to_degrees(),
                resolution: c.resolution,
            },
            Camera::Rectified(c) => SceneCamera {
                origin: c.position,
                target: DVec3::ZERO,
                up: DVec3::Y,
                fov_y_deg: 2.0
                    * (capture.sample.height / 2.0 / c.position.length())
                        .atan()
                        .to_degrees(),
                resolution: c.resolution,
            },
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
        })
    }

    /// The default flash setup: a 10 x 10 sample, a 30 degree camera 30 units above its centre
    /// (128 x 128 pixels), and a point light of intensity 1000 at the camera (the README's
    /// example capture).
    pub fn default_flash(reason: &str) -> Scene {
        Scene {
            source: format!("default flash setup ({reason})"),
            sample: [10.0, 10.0],
            camera: SceneCamera {
                origin: DVec3::new(0.0, 0.0, 30.0),
                target: DVec3::ZERO,
                up: DVec3::Y,
                fov_y_deg: 30.0,
                resolution: [128, 128],
            },
            light: Light::Flash {
                intensity: [1000.0; 3],
            },
        }
    }
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
    let material = &conversion.material;
    let mut notes = Vec::new();
    notes.push(match material.fresnel {
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
    });
    if material.height == Height::Correlated {
        notes.push(
            "the fit used the height-correlated Smith G2 = 1 / (1 + Lambda(wi) + Lambda(wo)); \
             roughconductor uses the uncorrelated G1(wi) G1(wo), slightly darker at grazing angles"
                .to_string(),
        );
    }
    if conversion.has_diffuse() {
        notes.push(
            "blendbsdf with weight 0.5 of the roughconductor and the diffuse, both doubled, \
             is the sum f_specular + diffuse / pi of the fit"
                .to_string(),
        );
    }
    notes.extend(conversion.common_notes());
    notes
}

fn roughconductor(conversion: &Conversion, indent: &str, id: &str, scale: f64) -> String {
    let material = &conversion.material;
    let inner = format!("{indent}    ");
    let mut xml = format!("{indent}<bsdf type=\"roughconductor\"{id}>\n");
    xml += &format!(
        "{inner}<string name=\"distribution\" value=\"{}\"/>\n",
        material.ndf.name()
    );
    if conversion.is_anisotropic() {
        xml += &format!(
            "{inner}<float name=\"alpha_u\" value=\"{}\"/>\n",
            number(material.alpha[0])
        );
        xml += &format!(
            "{inner}<float name=\"alpha_v\" value=\"{}\"/>\n",
            number(material.alpha[1])
        );
    } else {
        xml += &format!(
            "{inner}<float name=\"alpha\" value=\"{}\"/>\n",
            number(material.alpha[0])
        );
    }
    xml += &format!(
        "{inner}<rgb name=\"eta\" value=\"{}\"/>\n",
        triple(conversion.conductor.eta)
    );
    xml += &format!(
        "{inner}<rgb name=\"k\" value=\"{}\"/>\n",
        triple(conversion.conductor.k)
    );
    if scale != 1.0 {
        xml += &format!(
            "{inner}<rgb name=\"specular_reflectance\" value=\"{}\"/>\n",
            triple([scale; 3])
        );
    }
    xml + &format!("{indent}</bsdf>\n")
}

fn bsdf(conversion: &Conversion) -> String {
    if !conversion.has_diffuse() {
        return roughconductor(conversion, "    ", " id=\"fitted\"", 1.0);
    }
    let doubled = conversion.material.diffuse.map(|d| 2.0 * d);
    format!(
        "    <bsdf type=\"blendbsdf\" id=\"fitted\">\n        <float name=\"weight\" value=\"0.5\"/>\n{}        <bsdf type=\"diffuse\">\n            <rgb name=\"reflectance\" value=\"{}\"/>\n        </bsdf>\n    </bsdf>\n",
        roughconductor(conversion, "        ", "", 2.0),
        triple(doubled)
    )
}

fn sensor(camera: &SceneCamera) -> String {
    format!(
        "    <sensor type=\"perspective\">
        <float name=\"fov\" value=\"{}\"/>
        <string name=\"fov_axis\" value=\"y\"/>
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
        </film>
    </sensor>
",
        number(camera.fov_y_deg),
        xyz(camera.origin),
        xyz(camera.target),
        xyz(camera.up),
        camera.resolution[0],
        camera.resolution[1]
    )
}

fn emitter(light: &Light, camera: &SceneCamera) -> String {
    let point = |position: DVec3, intensity: [f64; 3]| {
        format!(
            "    <emitter type=\"point\">\n        <point name=\"position\" {}/>\n        <rgb name=\"intensity\" value=\"{}\"/>\n    </emitter>\n",
            xyz_attributes(position),
            triple(intensity)
        )
    };
    match *light {
        Light::Point {
            position,
            intensity,
        } => point(position, intensity),
        Light::Flash { intensity } => point(camera.origin, intensity),
        Light::Directional {
            direction,
            irradiance,
        } => format!(
            "    <emitter type=\"directional\">\n        <vector name=\"direction\" {}/>\n        <rgb name=\"irradiance\" value=\"{}\"/>\n    </emitter>\n",
            xyz_attributes(-direction),
            triple(irradiance)
        ),
    }
}

/// The scene XML for `conversion` under `scene`.
pub fn document(conversion: &Conversion, scene: &Scene) -> String {
    let mut xml = String::from("<?xml version=\"1.0\" encoding=\"utf-8\"?>\n");
    xml += &xml_comment(
        "",
        &format!(
            "bouncefit {} export of a '{}' fit; render with mitsuba (any RGB variant)",
            env!("CARGO_PKG_VERSION"),
            conversion.material.model.name()
        ),
    );
    xml += "<scene version=\"3.0.0\">\n";
    xml += "    <integrator type=\"direct\"/>\n";
    xml += &xml_comment("    ", &format!("scene: {}", scene.source));
    for note in notes(conversion) {
        xml += &xml_comment("    ", &note);
    }
    xml += &bsdf(conversion);
    xml += &format!(
        "    <shape type=\"rectangle\">\n        <transform name=\"to_world\">\n            <scale x=\"{}\" y=\"{}\" z=\"1\"/>\n        </transform>\n        <ref id=\"fitted\"/>\n    </shape>\n",
        number(scene.sample[0] / 2.0),
        number(scene.sample[1] / 2.0)
    );
    xml += &sensor(&scene.camera);
    xml += &emitter(&scene.light, &scene.camera);
    xml + "</scene>\n"
}
