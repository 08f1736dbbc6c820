//! Statistical tests of the relit previews: the environment sampler against its density, the
//! furnace, the agreement of the two environment estimators, the sphere's mapping, and
//! thread-count independence. Monte Carlo comparisons use fixed seeds and a bound of
//! [`Z`] standard errors (of both sides combined, where both are estimates).

use super::environment::{direction_of, uv_of, Environment};
use super::geometry::{Geometry, SurfacePoint};
use super::lights::Lights;
use super::shade::{Lighting, Sampling, Turn};
use super::{render, Scene};
use crate::albedo::directional_albedo;
use crate::bsdf::Model;
use crate::capture::Light;
use crate::maps::lobe::TexelLobe;
use crate::maps::MaterialMaps;
use crate::material::{FresnelSpec, Material};
use crate::microfacet::{Height, NdfKind};
use crate::random::{rng_stream, Moments};
use crate::scalar::Vec3;
use glam::DVec3;
use rand::Rng as _;
use std::f64::consts::PI;

/// Standard errors a Monte Carlo estimate may lie from its expectation: with the dozens of
/// comparisons below, a false alarm at 4.5 sigma has a probability under 1e-4 per run.
const Z: f64 = 4.5;

fn material(model: Model, alpha: f64, fresnel: FresnelSpec, diffuse: f64) -> Material {
    Material {
        model,
        ndf: NdfKind::Ggx,
        height: Height::Correlated,
        alpha: [alpha; 2],
        fresnel,
        diffuse: [diffuse; 3],
    }
}

const COPPER: FresnelSpec = FresnelSpec::Conductor {
    eta: [0.2378, 1.0066, 1.2404],
    k: [3.6264, 2.5823, 2.3929],
};

/// An environment with structure at several scales: a gradient, a bright spot and a dark
/// band, 32 x 16 texels.
fn patterned_environment() -> Environment {
    let [width, height] = [32, 16];
    let radiance = (0..width * height)
        .map(|t| {
            let (column, row) = (t % width, t / width);
            let spot = if (5..8).contains(&column) && (3..5).contains(&row) {
                20.0
            } else {
                0.0
            };
            let band = if row == 10 { 0.0 } else { 1.0 };
            let base = 0.2 + column as f64 / width as f64;
            [0.0, 1.0, 2.0].map(|c| band * (base + spot) * (1.0 + 0.2 * c))
        })
        .collect();
    Environment::new(width, height, radiance)
}

/// `mean(L) sin(theta)` of each texel, normalised: the probability the sampler should give it,
/// computed here from the definition, not from the sampler's tables.
fn texel_probabilities(env: &Environment, [width, height]: [usize; 2]) -> Vec<f64> {
    let weights: Vec<f64> = (0..width * height)
        .map(|t| {
            let (u, v) = (
                ((t % width) as f64 + 0.5) / width as f64,
                ((t / width) as f64 + 0.5) / height as f64,
            );
            let l = env.radiance(direction_of(2.0 * PI * u, PI * v));
            (l[0] + l[1] + l[2]) / 3.0 * (PI * v).sin()
        })
        .collect();
    let total: f64 = weights.iter().sum();
    weights.iter().map(|w| w / total).collect()
}

#[test]
fn environment_sampler_histogram_matches_the_radiance_weighted_density() {
    let env = patterned_environment();
    let size = [32, 16];
    let expected = texel_probabilities(&env, size);
    let n = 400_000;
    let mut counts = vec![0usize; 32 * 16];
    let mut rng = rng_stream(11, 0);
    for _ in 0..n {
        let s = env
            .sample([rng.random(), rng.random()])
            .expect("away from the poles");
        let [u, v] = uv_of(s.direction);
        counts[(v * 16.0) as usize * 32 + (u * 32.0) as usize] += 1;
        // The density reported with a sample is the density function's (up to the rounding of
        // theta -> direction -> theta near the poles).
        let pdf = env.pdf(s.direction);
        assert!((s.pdf / pdf - 1.0).abs() < 1e-6, "{} vs {pdf}", s.pdf);
    }
    // Per bin: binomial sigma sqrt(n p (1 - p)); empty bins (the dark band) stay empty.
    let mut chi2 = 0.0;
    let mut dof = 0;
    for (t, (&count, &p)) in counts.iter().zip(&expected).enumerate() {
        if p == 0.0 {
            assert_eq!(count, 0, "texel {t} has no light but was drawn");
            continue;
        }
        let mean = n as f64 * p;
        let sigma = (mean * (1.0 - p)).sqrt();
        assert!(
            (count as f64 - mean).abs() < Z * sigma,
            "texel {t}: {count} draws, {mean:.1} +- {sigma:.1} expected"
        );
        chi2 += (count as f64 - mean).powi(2) / mean;
        dof += 1;
    }
    // Chi-square of dof - 1 degrees of freedom: mean dof - 1, sd sqrt(2 (dof - 1)).
    let k = (dof - 1) as f64;
    assert!(
        chi2 < k + Z * (2.0 * k).sqrt(),
        "chi2 {chi2:.1}, {dof} bins"
    );
    // The density in solid angle times the texel's solid angle is the texel's probability.
    for (t, &p) in expected.iter().enumerate() {
        let (theta0, theta1) = (PI * (t / 32) as f64 / 16.0, PI * (t / 32 + 1) as f64 / 16.0);
        let centre = direction_of(
            2.0 * PI * ((t % 32) as f64 + 0.5) / 32.0,
            0.5 * (theta0 + theta1),
        );
        // pdf varies as 1 / sin(theta) within the texel: integrate it exactly over the row.
        let sin_centre = (0.5 * (theta0 + theta1)).sin();
        let integral = env.pdf(centre) * sin_centre * 2.0 * PI / 32.0 * (theta1 - theta0);
        assert!(
            (integral - p).abs() < 1e-12 + 1e-9 * p,
            "texel {t}: {integral} vs {p}"
        );
    }
}

#[test]
fn environment_density_integrates_to_one_over_the_sphere() {
    for env in [Environment::sky(), patterned_environment()] {
        // Uniform directions on the sphere: E[4 pi pdf(w)] = integral pdf dw = 1.
        let mut moments = Moments::<1>::default();
        let mut rng = rng_stream(12, 0);
        for _ in 0..1_000_000 {
            let z: f64 = 1.0 - 2.0 * rng.random::<f64>();
            let w = direction_of(2.0 * PI * rng.random::<f64>(), z.acos());
            moments.push([4.0 * PI * env.pdf(w)]);
        }
        let (mean, se) = (moments.mean()[0], moments.standard_error()[0]);
        assert!((mean - 1.0).abs() < Z * se, "{mean} +- {se}");
        assert!(se < 0.05, "too few directions to tell: {se}");
    }
}

/// The sphere's point whose normal is `theta_deg` from the view direction, in the x-z plane.
fn sphere_point(theta_deg: f64) -> SurfacePoint {
    let theta = theta_deg.to_radians();
    let resolution = [1000, 1000];
    let pixel = [(theta.sin() + 1.0) * 500.0, 500.0];
    Geometry::Sphere
        .point(resolution, pixel)
        .expect("inside the disc")
}

/// Mean and standard error of `n` samples of `lighting` at `point` for `maps`' first texel.
fn estimate(
    lighting: &Lighting,
    point: &SurfacePoint,
    maps: &MaterialMaps,
    n: usize,
    seed: u64,
) -> Moments<3> {
    let lobes = TexelLobe::all(maps);
    let mut moments = Moments::default();
    let mut rng = rng_stream(seed, 0);
    for _ in 0..n {
        moments.push(lighting.sample(point, &lobes[0], &mut rng));
    }
    moments
}

#[test]
fn furnace_outgoing_radiance_is_the_directional_albedo() {
    // A constant environment of radiance L: L_o(wo) = L integral f(wi, wo) cos dwi, the
    // albedo of the (reciprocal) models at wo, plus the diffuse albedo.
    let radiance = 2.0;
    let env = Environment::constant([radiance; 3]);
    let white_conductor = FresnelSpec::Schlick { f0: [1.0; 3] };
    let cases = [
        (material(Model::Single, 0.5, COPPER, 0.3), 0.0),
        (material(Model::Single, 0.5, COPPER, 0.3), 60.0),
        (material(Model::Single, 0.1, white_conductor, 0.0), 30.0),
        (material(Model::Heitz, 1.0, white_conductor, 0.0), 0.0),
        (material(Model::Heitz, 1.0, white_conductor, 0.0), 70.0),
        (material(Model::KullaConty, 0.7, COPPER, 0.0), 45.0),
    ];
    for (k, (material, theta)) in cases.iter().enumerate() {
        let point = if *theta == 0.0 {
            Geometry::Flat
                .point([8, 8], [4.0, 4.0])
                .expect("on the sample")
        } else {
            sphere_point(*theta)
        };
        let wo = point.frame.local(super::geometry::VIEW);
        assert!((wo.z - theta.to_radians().cos()).abs() < 1e-12);
        let albedo = directional_albedo(material.brdf().as_ref(), wo, 1 << 16, 5);
        let lighting = Lighting::Environment {
            env: &env,
            turn: Turn::by(0.7),
            sampling: Sampling::Mis,
        };
        let maps = MaterialMaps::uniform(material);
        let relit = estimate(&lighting, &point, &maps, 40_000, k as u64).estimate();
        for c in 0..3 {
            let expected = radiance * (albedo.value[c] + material.diffuse[c]);
            let sigma = (relit.stderr[c].powi(2) + (radiance * albedo.stderr[c]).powi(2)).sqrt();
            let got = relit.value[c];
            assert!(
                (got - expected).abs() < Z * sigma.max(1e-12),
                "case {k} ({} theta {theta}) channel {c}: {got} vs {expected} +- {sigma}",
                material.model
            );
        }
        if material.model == Model::Heitz {
            // A white multiple-bounce conductor reflects all it receives.
            let sigma = relit.stderr[0];
            assert!((relit.value[0] / radiance - 1.0).abs() < Z * sigma / radiance + 1e-3);
        }
    }
}

#[test]
fn mis_and_environment_sampling_agree_on_a_patterned_sky() {
    let env = Environment::sky();
    let mut tilted = MaterialMaps::uniform(&material(Model::Single, 0.25, COPPER, 0.2));
    tilted.normal = Some(vec![Vec3::new(0.3, -0.2, 1.0).normalize().re()]);
    let cases = [
        (
            MaterialMaps::uniform(&material(Model::Single, 0.25, COPPER, 0.2)),
            35.0,
        ),
        (
            MaterialMaps::uniform(&material(Model::Bitterli, 0.6, COPPER, 0.0)),
            50.0,
        ),
        (tilted, 20.0),
    ];
    for (k, (maps, theta)) in cases.iter().enumerate() {
        let point = sphere_point(*theta);
        let [mis, light] = [Sampling::Mis, Sampling::Light].map(|sampling| {
            let lighting = Lighting::Environment {
                env: &env,
                turn: Turn::by(2.0),
                sampling,
            };
            estimate(&lighting, &point, maps, 60_000, 100 + k as u64).estimate()
        });
        for c in 0..3 {
            let sigma = (mis.stderr[c].powi(2) + light.stderr[c].powi(2)).sqrt();
            assert!(
                (mis.value[c] - light.value[c]).abs() < Z * sigma,
                "case {k} channel {c}: MIS {} vs light {} +- {sigma}",
                mis.value[c],
                light.value[c]
            );
            assert!(sigma < 0.02 * light.value[c], "case {k}: too noisy to tell");
        }
    }
}

#[test]
fn a_point_light_above_the_flat_sample_gives_f_times_its_irradiance() {
    let material = material(Model::Single, 0.3, COPPER, 0.1);
    let maps = MaterialMaps::uniform(&material);
    let lights = Lights::turntable(1, 90.0, 5.0).unwrap();
    let frames = lights.frames();
    let Lighting::Light { light, .. } = &frames[0].1 else {
        panic!("a turntable frame has a point light")
    };
    assert!((light.perpendicular(DVec3::ZERO, DVec3::ZERO).irradiance[0] - 1.0).abs() < 1e-12);
    let point = Geometry::Flat.point([9, 9], [4.5, 4.5]).unwrap();
    let got = estimate(&frames[0].1, &point, &maps, 2, 0).mean();
    let z = Vec3::new(0.0, 0.0, 1.0);
    let f = material.single::<f64>().eval(z, z).0;
    for c in 0..3 {
        let expected = f[c] + 0.1 / PI;
        assert!(
            (got[c] / expected - 1.0).abs() < 1e-12,
            "{got:?} vs {expected}"
        );
    }
    // Lights below the sample's plane do not reach it.
    let below = Lighting::Light {
        light: Light::Directional {
            direction: DVec3::new(0.0, 0.3, -1.0),
            irradiance: [1.0; 3],
        },
        camera: DVec3::ZERO,
    };
    assert_eq!(estimate(&below, &point, &maps, 2, 0).mean(), [0.0; 3]);
}

#[test]
fn sphere_pixels_map_to_normals_and_texture_coordinates_and_back() {
    let resolution = [64, 64];
    let mut rng = rng_stream(3, 0);
    let mut inside = 0;
    for _ in 0..2000 {
        let pixel = [64.0 * rng.random::<f64>(), 64.0 * rng.random::<f64>()];
        let (x, y) = (pixel[0] / 32.0 - 1.0, 1.0 - pixel[1] / 32.0);
        let Some(point) = Geometry::Sphere.point(resolution, pixel) else {
            assert!(x * x + y * y >= 1.0, "{pixel:?} is inside the disc");
            continue;
        };
        inside += 1;
        let n: Vec3<f64> = Vec3::from_f64(point.position.to_array());
        assert!((n.length() - 1.0).abs() < 1e-12, "on the unit sphere");
        // Back to the pixel: the orthographic projection of the normal.
        let back = [(n.x + 1.0) * 32.0, (1.0 - n.y) * 32.0];
        assert!((back[0] - pixel[0]).abs() < 1e-9 && (back[1] - pixel[1]).abs() < 1e-9);
        assert!(n.z >= 0.0, "the camera sees the front hemisphere");
        // The stated mapping: u = (x + 1) / 2, v = (1 - y) / 2.
        assert!((point.uv[0] - (n.x + 1.0) / 2.0).abs() < 1e-12);
        assert!((point.uv[1] - (1.0 - n.y) / 2.0).abs() < 1e-12);
        // The frame: z is the normal, x the sample's +x projected, and it is a rotation.
        let local = point.frame.local(n);
        assert!((local.z - 1.0).abs() < 1e-12 && local.x.abs() < 1e-12);
        let s = point.frame.tangent(Vec3::new(1.0, 0.0, 0.0));
        assert!(s.x > 0.0 && s.dot(n).abs() < 1e-12);
        let w = Vec3::new(0.2, -0.5, 0.7).normalize();
        let round = point.frame.tangent(point.frame.local(w));
        assert!((round - w).length() < 1e-12);
    }
    assert!(inside > 1400, "pi / 4 of the pixels: {inside}");
}

fn sphere_scene(material: &MaterialMaps, size: usize) -> Scene<'_> {
    Scene {
        material,
        geometry: Geometry::Sphere,
        size,
        samples: 4,
        seed: 9,
    }
}

#[test]
fn silhouette_pixels_are_background_and_no_pixel_is_nan() {
    let maps = MaterialMaps::uniform(&material(Model::Single, 0.05, COPPER, 0.2));
    let env = Environment::sky();
    let lights = Lights::Environment {
        env,
        frames: 2,
        sampling: Sampling::Mis,
    };
    let frames = render(&sphere_scene(&maps, 24), &lights.frames());
    assert_eq!(frames.len(), 2);
    for frame in &frames {
        assert_eq!(frame.resolution, [24, 24]);
        for (p, value) in frame.rgb.iter().enumerate() {
            assert!(
                value.iter().all(|v| v.is_finite() && *v >= 0.0),
                "{value:?}"
            );
            // Pixels whose square lies wholly outside the disc see only background.
            let (column, row) = ((p % 24) as f64, (p / 24) as f64);
            let nearest = |a: f64| (12.0f64.clamp(a, a + 1.0) - 12.0) / 12.0;
            let (x, y) = (nearest(column), nearest(row));
            if x * x + y * y >= 1.0 {
                assert_eq!(*value, [0.0; 3], "pixel {p} is outside the sphere");
            }
        }
        assert!(
            frame.rgb[12 * 24 + 12].iter().all(|v| *v > 0.0),
            "the centre is lit"
        );
    }
    assert_ne!(frames[0].rgb, frames[1].rgb, "the environment turned");
}

#[test]
fn frames_are_bit_identical_on_one_and_two_threads() {
    let maps = MaterialMaps::uniform(&material(Model::Heitz, 0.6, COPPER, 0.0));
    let lights = Lights::Environment {
        env: Environment::sky(),
        frames: 1,
        sampling: Sampling::Mis,
    };
    let frames = lights.frames();
    let on = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| render(&sphere_scene(&maps, 16), &frames))
    };
    let (one, two) = (on(1), on(2));
    let bits = |frames: &[super::Frame]| -> Vec<u64> {
        frames[0]
            .rgb
            .iter()
            .flatten()
            .map(|v| v.to_bits())
            .collect()
    };
    assert_eq!(bits(&one), bits(&two));
}
