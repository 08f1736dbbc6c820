//! Distant lighting from every direction: a latitude-longitude radiance map, importance
//! sampled in proportion to its radiance.
//!
//! Directions are in the frame of the flat sample (PHYSICS.md "Conventions"): `z` up, the
//! sample's normal. A texel `(column, row)` of a `width` x `height` map covers `u = phi / 2 pi`
//! in `[column, column + 1) / width` and `v = theta / pi` in `[row, row + 1) / height`, with
//! `theta` the angle from `+z` and `phi` the azimuth from `+x` toward `+y`: row 0 is the zenith,
//! the middle row the horizon, the bottom row the nadir, as an equirectangular image is usually
//! drawn. Radiance is constant over a texel (nearest lookup), so the sampling density below is
//! exactly proportional to the radiance it is used with.
//!
//! Sampling (Pharr, Jakob & Humphreys, "Physically Based Rendering", 3rd ed., sec. 14.2.4, and
//! 4th ed. sec. 12.5.2 "Image Infinite Lights"): the piecewise-constant 2D distribution
//! ([`super::distribution`]) of `mean(L) sin(theta)` over the texels, where `theta` is the
//! texel row's centre (the `sin` is the solid angle a texel row covers); a point `(u, v)` of
//! density `p(u, v)` maps to the direction of density `p(u, v) / (2 pi^2 sin theta)` in solid
//! angle. The mean of the three channels is positive wherever any channel is, so every
//! direction that carries light has a positive density.

use super::distribution::Distribution2D;
use crate::capture::image_io::{load_image, write_exr, ColorEncoding};
use crate::error::{Error, Result};
use crate::maps::TexelGrid;
use crate::scalar::Vec3;
use std::f64::consts::{PI, TAU};
use std::path::Path;

/// A latitude-longitude radiance map (linear RGB, W / (m^2 sr), or any consistent unit).
#[derive(Clone, Debug)]
pub struct Environment {
    grid: TexelGrid,
    /// Row-major radiance, row 0 at the zenith.
    radiance: Vec<[f64; 3]>,
    distribution: Distribution2D,
}

/// A direction drawn from an environment.
#[derive(Clone, Copy, Debug)]
pub struct EnvironmentSample {
    pub direction: Vec3<f64>,
    pub radiance: [f64; 3],
    /// Density in solid angle (1/sr).
    pub pdf: f64,
}

/// The bundled sky's parameters ([`Environment::sky`]).
const SKY_SIZE: [usize; 2] = [256, 128];
const SUN_ELEVATION_DEG: f64 = 35.0;
const SUN_AZIMUTH_DEG: f64 = 30.0;
/// Angular radius of the sun disc: ten times the real sun's, so that the disc covers a few
/// texels of the map and a highlight on a smooth sample is a disc, not a point.
const SUN_RADIUS_DEG: f64 = 2.5;
/// Irradiance of the sun on a plane facing it.
const SUN_IRRADIANCE: [f64; 3] = [6.0, 5.6, 5.0];
const ZENITH: [f64; 3] = [0.18, 0.32, 0.75];
const HORIZON: [f64; 3] = [0.75, 0.82, 0.95];
const GROUND: [f64; 3] = [0.12, 0.10, 0.08];

impl Environment {
    /// The map of `radiance` (row-major, `width` x `height`, finite and non-negative).
    pub fn new(width: usize, height: usize, radiance: Vec<[f64; 3]>) -> Environment {
        assert_eq!(radiance.len(), width * height, "one value per texel");
        let weights: Vec<f64> = radiance
            .iter()
            .enumerate()
            .map(|(t, l)| {
                let theta = PI * ((t / width) as f64 + 0.5) / height as f64;
                (l[0] + l[1] + l[2]) / 3.0 * theta.sin()
            })
            .collect();
        Environment {
            grid: TexelGrid { width, height },
            distribution: Distribution2D::new(&weights, width, height),
            radiance,
        }
    }

    /// The same radiance `rgb` from every direction (a furnace).
    pub fn constant(rgb: [f64; 3]) -> Environment {
        let [width, height] = [16, 8];
        Environment::new(width, height, vec![rgb; width * height])
    }

    /// The bundled outdoor light, made here (no file): a sky brightening from blue at the
    /// zenith to white at the horizon with a glow around the sun, a sun disc of angular radius
    /// 2.5 deg at elevation 35 deg and azimuth 30 deg (from +x toward +y) giving an
    /// irradiance of about 6 on a plane facing it, and a dark ground below the horizon;
    /// 256 x 128 texels.
    pub fn sky() -> Environment {
        let [width, height] = SKY_SIZE;
        let sun = direction_of(
            SUN_AZIMUTH_DEG.to_radians(),
            (90.0 - SUN_ELEVATION_DEG).to_radians(),
        );
        let sun_radius = SUN_RADIUS_DEG.to_radians();
        // A disc of radiance L and angular radius r gives the irradiance L pi sin^2 r.
        let sun_radiance = SUN_IRRADIANCE.map(|e| e / (PI * sun_radius.sin().powi(2)));
        let radiance = (0..width * height)
            .map(|t| {
                let uv = [
                    ((t % width) as f64 + 0.5) / width as f64,
                    ((t / width) as f64 + 0.5) / height as f64,
                ];
                let w = direction_of(TAU * uv[0], PI * uv[1]);
                let to_sun = w.dot(sun).clamp(-1.0, 1.0).acos();
                if to_sun < sun_radius {
                    sun_radiance
                } else if w.z < 0.0 {
                    GROUND
                } else {
                    let up = w.z.sqrt();
                    let glow = 0.6 * (-to_sun / 0.3).exp();
                    std::array::from_fn(|c| HORIZON[c] + (ZENITH[c] - HORIZON[c]) * up + glow)
                }
            })
            .collect();
        Environment::new(width, height, radiance)
    }

    /// `sky` (the bundled sky), `white` (radiance 1 from everywhere) or a lat-long EXR file.
    pub fn named_or_file(text: &str) -> Result<Environment> {
        match text {
            "sky" => Ok(Environment::sky()),
            "white" => Ok(Environment::constant([1.0; 3])),
            file => Environment::load(Path::new(file)),
        }
    }

    /// Reads a lat-long EXR (linear radiance, row 0 at the zenith); errors name the file and
    /// the texel.
    pub fn load(path: &Path) -> Result<Environment> {
        if !path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
        {
            return Err(Error::invalid(
                path,
                "file type",
                "expected a latitude-longitude .exr environment map (or `sky`, `white`)",
            ));
        }
        let image = load_image(path, ColorEncoding::Linear)?;
        if image.rgb.is_empty() {
            return Err(Error::invalid(path, "resolution", "the map has no texels"));
        }
        let mut radiance = Vec::with_capacity(image.rgb.len());
        for (t, value) in image.rgb.iter().enumerate() {
            let rgb = value.map(f64::from);
            if !rgb.iter().all(|v| v.is_finite() && *v >= 0.0) {
                return Err(Error::invalid(
                    path,
                    format!("texel ({}, {})", t % image.width, t / image.width),
                    format!("radiance {rgb:?}: expected finite values >= 0"),
                ));
            }
            radiance.push(rgb);
        }
        Ok(Environment::new(image.width, image.height, radiance))
    }

    /// Writes the map as a lat-long EXR in the convention [`Environment::load`] reads (linear
    /// f32 RGB, row 0 at the zenith), so that another renderer can be lit by the same light.
    pub fn write(&self, path: &Path) -> Result<()> {
        let rgb: Vec<[f32; 3]> = self.radiance.iter().map(|v| v.map(|c| c as f32)).collect();
        write_exr(path, &rgb, self.grid.width, self.grid.height)
    }

    /// Radiance arriving from the unit direction `w`.
    pub fn radiance(&self, w: Vec3<f64>) -> [f64; 3] {
        self.radiance[self.texel(uv_of(w))]
    }

    /// Density in solid angle with which [`Environment::sample`] draws `w`.
    pub fn pdf(&self, w: Vec3<f64>) -> f64 {
        let uv = uv_of(w);
        let sin_theta = (PI * uv[1]).sin();
        if sin_theta <= 0.0 {
            return 0.0;
        }
        self.distribution.pdf(uv) / (2.0 * PI * PI * sin_theta)
    }

    /// A direction drawn from the uniform numbers `xi` with density proportional to
    /// `mean(L) sin theta` per texel; `None` at the poles (density infinite, probability 0).
    pub fn sample(&self, xi: [f64; 2]) -> Option<EnvironmentSample> {
        let (uv, pdf_uv) = self.distribution.sample(xi);
        let theta = PI * uv[1];
        let sin_theta = theta.sin();
        if pdf_uv <= 0.0 || sin_theta <= 0.0 {
            return None;
        }
        Some(EnvironmentSample {
            direction: direction_of(TAU * uv[0], theta),
            radiance: self.radiance[self.texel(uv)],
            pdf: pdf_uv / (2.0 * PI * PI * sin_theta),
        })
    }

    fn texel(&self, uv: [f64; 2]) -> usize {
        self.grid.texel(uv)
    }
}

/// The unit direction of azimuth `phi` (from +x toward +y) and polar angle `theta` (from +z).
pub fn direction_of(phi: f64, theta: f64) -> Vec3<f64> {
    let sin_theta = theta.sin();
    Vec3::new(sin_theta * phi.cos(), sin_theta * phi.sin(), theta.cos())
}

/// `(u, v) = (phi / 2 pi, theta / pi)` of the unit direction `w`, each in `[0, 1]`.
pub fn uv_of(w: Vec3<f64>) -> [f64; 2] {
    let phi = w.y.atan2(w.x);
    let phi = if phi < 0.0 { phi + TAU } else { phi };
    [phi / TAU, w.z.clamp(-1.0, 1.0).acos() / PI]
}
