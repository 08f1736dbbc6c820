//! The lights of a relit sequence, one per frame: an environment (turned about the zenith from
//! frame to frame), a point light circling the sample (a turntable), or the lights of the photo
//! set a fit was made from.

use super::environment::Environment;
use super::shade::{Lighting, Sampling, Turn};
use crate::capture::{Capture, Light};
use crate::error::{Error, Result};
use crate::material::read_json_object;
use glam::DVec3;
use std::f64::consts::TAU;
use std::path::{Path, PathBuf};

pub enum Lights {
    /// `frames` frames of `env`, turned by `360 / frames` degrees about the zenith each.
    Environment {
        env: Environment,
        frames: usize,
        sampling: Sampling,
    },
    /// A point light at `distance` (in sphere radii, > 1) from the origin and `elevation_deg`
    /// above the horizon, at `frames` azimuths `360 k / frames` degrees from `+x` toward `+y`;
    /// its intensity is `distance^2`, so that a surface facing it at the origin receives an
    /// irradiance of 1.
    Turntable {
        frames: usize,
        elevation_deg: f64,
        distance: f64,
    },
    /// The light of each photo of a photo set, in photo order.
    Capture(Capture),
}

impl Lights {
    /// A turntable, checking its numbers (errors name the flag).
    pub fn turntable(frames: usize, elevation_deg: f64, distance: f64) -> Result<Lights> {
        if !(elevation_deg.is_finite() && elevation_deg > 0.0 && elevation_deg <= 90.0) {
            return Err(Error::argument(
                "--elevation",
                format!("{elevation_deg}: expected degrees in (0, 90]"),
            ));
        }
        if !(distance.is_finite() && distance > 1.0) {
            return Err(Error::argument(
                "--distance",
                format!("{distance}: expected a distance > 1 (sphere radii, outside the sphere)"),
            ));
        }
        Ok(Lights::Turntable {
            frames,
            elevation_deg,
            distance,
        })
    }

    /// `(file stem, light)` of every frame.
    pub fn frames(&self) -> Vec<(String, Lighting<'_>)> {
        let name = |k: usize| format!("frame_{k:03}");
        match self {
            Lights::Environment {
                env,
                frames,
                sampling,
            } => (0..*frames)
                .map(|k| {
                    let lighting = Lighting::Environment {
                        env,
                        turn: Turn::by(TAU * k as f64 / *frames as f64),
                        sampling: *sampling,
                    };
                    (name(k), lighting)
                })
                .collect(),
            Lights::Turntable {
                frames,
                elevation_deg,
                distance,
            } => (0..*frames)
                .map(|k| {
                    let (phi, elevation) =
                        (TAU * k as f64 / *frames as f64, elevation_deg.to_radians());
                    let position = DVec3::new(
                        elevation.cos() * phi.cos(),
                        elevation.cos() * phi.sin(),
                        elevation.sin(),
                    ) * *distance;
                    let light = Light::Point {
                        position,
                        intensity: [distance * distance; 3],
                    };
                    (
                        name(k),
                        Lighting::Light {
                            light,
                            camera: DVec3::ZERO,
                        },
                    )
                })
                .collect(),
            Lights::Capture(capture) => capture_lights(capture),
        }
    }
}

/// The photos' lights in the preview's units (the sample's half-width): positions scaled by
/// `2 / width` and intensities by its square, so that the sample receives the irradiance it
/// received in the photo; a flash stays at its photo's camera. The photos' exposures are a
/// camera's gain, not the light's, and are left out.
fn capture_lights(capture: &Capture) -> Vec<(String, Lighting<'static>)> {
    let capture = capture.in_material_frame();
    let scale = 2.0 / capture.sample.width;
    let intensity = |i: [f64; 3]| i.map(|c| c * scale * scale);
    capture
        .photos
        .iter()
        .map(|photo| {
            let light = match &photo.light {
                Light::Point {
                    position,
                    intensity: i,
                } => Light::Point {
                    position: *position * scale,
                    intensity: intensity(*i),
                },
                Light::Flash { intensity: i } => Light::Flash {
                    intensity: intensity(*i),
                },
                directional @ Light::Directional { .. } => directional.clone(),
            };
            let camera = photo.camera.position() * scale;
            (photo.stem(), Lighting::Light { light, camera })
        })
        .collect()
}

/// The photo set a fit file was made from (its `capture` field): the path as recorded, or else
/// relative to the fit file's folder.
pub fn fit_capture(fit: &Path) -> Result<PathBuf> {
    let fields = read_json_object(fit)?;
    let recorded = match fields.get("capture") {
        Some(serde_json::Value::String(path)) => PathBuf::from(path),
        Some(_) => {
            return Err(Error::invalid(
                fit,
                "capture",
                "expected the photo set's path as a string",
            ))
        }
        None => {
            return Err(Error::invalid(
                fit,
                "capture",
                "missing: a material file names no photo set; pass --capture DIR",
            ))
        }
    };
    let beside = fit.parent().unwrap_or(Path::new(".")).join(&recorded);
    [recorded.clone(), beside]
        .into_iter()
        .find(|path| path.exists())
        .ok_or_else(|| {
            Error::invalid(
                fit,
                "capture",
                format!(
                    "photo set {} not found (as recorded, nor beside the fit file); pass \
                     --capture DIR",
                    recorded.display()
                ),
            )
        })
}
