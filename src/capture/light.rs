//! Light models of the photo-set manifest and the irradiance factor they give a surface point
//! (PHYSICS.md "Conventions", radiance of a pixel).

use glam::DVec3;

/// A photo's light. Serialises as the manifest's `light = { kind = ..., ... }` table.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum Light {
    /// Isotropic point light (`kind = "point"`).
    Point {
        /// Position, above the sample plane.
        position: DVec3,
        /// Radiant intensity, RGB, W/sr.
        intensity: [f64; 3],
    },
    /// Distant light (`kind = "directional"`).
    Directional {
        /// Toward the light, pointing above the sample plane; need not be unit length.
        direction: DVec3,
        /// RGB irradiance measured perpendicular to the beam.
        irradiance: [f64; 3],
    },
    /// Point light at the camera centre (`kind = "flash"`).
    Flash {
        /// Radiant intensity, RGB, W/sr.
        intensity: [f64; 3],
    },
}

/// Light arriving at one surface point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Incident {
    /// Unit direction from the surface point toward the light (local frame = world frame).
    pub wi: DVec3,
    /// The factor that turns `f` (1/sr) into radiance: `I * max(wi.z, 0) / d^2` for a point
    /// light or flash, `E * max(wi.z, 0)` for a directional light (exposure not included).
    pub irradiance: [f64; 3],
}

impl Light {
    /// Light arriving at surface point `x` (on z = 0) when the camera centre is `camera`
    /// (the flash's position).
    pub fn incident(&self, camera: DVec3, x: DVec3) -> Incident {
        self.incident_with_cosine(camera, x, |wi| wi.z)
    }

    /// Light arriving at any point `x` measured on a plane perpendicular to the light's
    /// direction (`I / d^2` or `E`): the surface's cosine is left to the caller, whose surface
    /// need not be the plane z = 0.
    pub fn perpendicular(&self, camera: DVec3, x: DVec3) -> Incident {
        self.incident_with_cosine(camera, x, |_| 1.0)
    }

    /// [`Light::incident`] with the surface's cosine `cosine(wi)` (clamped at 0).
    fn incident_with_cosine(
        &self,
        camera: DVec3,
        x: DVec3,
        cosine: impl Fn(DVec3) -> f64,
    ) -> Incident {
        let from_point = |position: DVec3, intensity: [f64; 3]| {
            let to_light = position - x;
            let distance_squared = to_light.length_squared();
            let wi = to_light / distance_squared.sqrt();
            let factor = cosine(wi).max(0.0) / distance_squared;
            Incident {
                wi,
                irradiance: intensity.map(|c| c * factor),
            }
        };
        match *self {
            Light::Point {
                position,
                intensity,
            } => from_point(position, intensity),
            Light::Flash { intensity } => from_point(camera, intensity),
            Light::Directional {
                direction,
                irradiance,
            } => {
                let wi = direction.normalize();
                let factor = cosine(wi).max(0.0);
                Incident {
                    wi,
                    irradiance: irradiance.map(|c| c * factor),
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_light_follows_inverse_square_and_cosine() {
        let light = Light::Point {
            position: DVec3::new(3.0, 0.0, 4.0),
            intensity: [50.0, 25.0, 0.0],
        };
        let at = light.incident(DVec3::new(0.0, 0.0, 100.0), DVec3::ZERO);
        assert!((at.wi - DVec3::new(0.6, 0.0, 0.8)).length() < 1e-15);
        // I * cos / d^2 = 50 * 0.8 / 25.
        assert!((at.irradiance[0] - 1.6).abs() < 1e-14 && (at.irradiance[1] - 0.8).abs() < 1e-14);
        assert_eq!(at.irradiance[2], 0.0);
    }

    #[test]
    fn flash_sits_at_the_camera() {
        let flash = Light::Flash {
            intensity: [9.0; 3],
        };
        let camera = DVec3::new(0.0, 0.0, 3.0);
        let at = flash.incident(camera, DVec3::ZERO);
        assert_eq!(at.wi, DVec3::Z);
        assert_eq!(at.irradiance, [1.0; 3]);
        let point = Light::Point {
            position: camera,
            intensity: [9.0; 3],
        };
        let x = DVec3::new(1.0, -2.0, 0.0);
        assert_eq!(flash.incident(camera, x), point.incident(camera, x));
    }

    #[test]
    fn directional_light_is_normalised_and_cosine_weighted() {
        let light = Light::Directional {
            direction: DVec3::new(0.0, 3.0, 4.0),
            irradiance: [2.0; 3],
        };
        let at = light.incident(DVec3::Z, DVec3::new(5.0, 5.0, 0.0));
        assert!((at.wi - DVec3::new(0.0, 0.6, 0.8)).length() < 1e-15);
        assert!((at.irradiance[0] - 1.6).abs() < 1e-15);
    }
}
