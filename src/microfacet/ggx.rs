//! The GGX (Trowbridge-Reitz) distribution in the stretched configuration (roughness 1).
//!
//! | function | formula | reference |
//! | --- | --- | --- |
//! | density | `1 / (pi (s^2 + z^2)^2)` for a unit normal `(x, y, z)` with `s^2 = x^2 + y^2` stretched | Walter et al. 2007 eq. 33 |
//! | `|z| Lambda` | `(sqrt(z^2 + s^2) - z) / 2 = s^2 / (2 (sqrt(z^2 + s^2) + z))` | Heitz 2014 eq. 86, cancellation-free form |
//! | sampling | visible hemisphere projection, valid for directions below the horizon too | Heitz 2018, "Sampling the GGX Distribution of Visible Normals", listing 1 |

use crate::scalar::{Real, Vec3};
use std::f64::consts::PI;

/// `D * ax * ay` of a unit normal with stretched horizontal length squared `s2` and height `z`.
#[inline]
pub fn density_stretched<T: Real>(s2: T, z: T) -> T {
    (T::c(PI) * (s2 + z * z).sq()).recip()
}

/// `z * Lambda` for an upward direction with height `z >= 0` and stretched horizontal length
/// `s >= 0`. Written without the subtraction `sqrt(1 + 1/nu^2) - 1` so it keeps full relative
/// precision near normal incidence and stays finite at grazing (`z = 0` gives `s / 2`).
#[inline]
pub fn z_lambda<T: Real>(z: T, s: T) -> T {
    if s.re64() <= 0.0 {
        return T::zero();
    }
    s * s / (T::c(2.0) * ((z * z + s * s).sqrt() + z))
}

/// Heitz 2018 listing 1: sample a unit normal of the roughness-1 GGX hemisphere visible from the
/// unit direction `v`. For `v.z < 0` the blend factor `(1 + v.z) / 2` falls below one half and the
/// warped disk becomes the crescent of the hemisphere seen from below, so the same code is exact
/// for directions under the horizon (as Heitz et al. 2016's random walk needs).
pub fn sample_visible_stretched<T: Real>(v: Vec3<T>, u: [f64; 2]) -> Vec3<T> {
    let len2 = v.x * v.x + v.y * v.y;
    let t1 = if len2.re64() > 0.0 {
        let inv = len2.sqrt().recip();
        Vec3::new(-v.y * inv, v.x * inv, T::zero())
    } else {
        Vec3::new(T::one(), T::zero(), T::zero())
    };
    let t2 = v.cross(t1);
    let r = u[0].sqrt();
    let phi = 2.0 * PI * u[1];
    let p1 = T::c(r * phi.cos());
    let p2_disk = T::c(r * phi.sin());
    let s = (T::one() + v.z) * T::c(0.5);
    let p2 = (T::one() - s) * (T::one() - p1 * p1).sqrt() + s * p2_disk;
    let pz = (T::one() - p1 * p1 - p2 * p2).max_c(0.0).sqrt();
    t1 * p1 + t2 * p2 + v * pz
}
