//! A picture of a material's lobe: `f(wi, wo) wo.z` over the projected hemisphere of `wo` for
//! one incidence `wi` (orthographic view from above: the disc of radius 1 is the horizon, +x to
//! the right, +y up; outside the disc, zero), as `bouncefit lobe` writes it and the comparison
//! report shows it. The cosine makes equal areas of the picture carry equal projected solid
//! angle, so the picture's bright area is where the reflected energy goes.

use crate::material::Material;
use crate::random::rng_stream;
use crate::scalar::Vec3;
use rayon::prelude::*;

/// The `size` x `size` picture (row-major, row 0 at the top) of `material`'s lobe for light
/// from `wi`, each pixel evaluated at its centre; stochastic models average `pixel_samples`
/// evaluations from the pixel's own stream of `seed`.
pub fn lobe_picture(
    material: &Material,
    wi: Vec3<f64>,
    size: usize,
    pixel_samples: usize,
    seed: u64,
) -> Vec<[f64; 3]> {
    let brdf = material.brdf();
    let per_pixel = if brdf.is_stochastic() {
        pixel_samples.max(1)
    } else {
        1
    };
    let n = size as f64;
    (0..size * size)
        .into_par_iter()
        .map(|p| {
            let (x, y) = ((p % size) as f64 + 0.5, (p / size) as f64 + 0.5);
            let (dx, dy) = (2.0 * x / n - 1.0, 1.0 - 2.0 * y / n);
            let r2 = dx * dx + dy * dy;
            if r2 >= 1.0 {
                return [0.0; 3];
            }
            let wo = Vec3::new(dx, dy, (1.0 - r2).sqrt());
            let mut rng = rng_stream(seed, p as u64);
            let mut sum = [0.0; 3];
            for _ in 0..per_pixel {
                let f = brdf.eval(wi, wo, &mut rng).total();
                (0..3).for_each(|c| sum[c] += f[c] * wo.z);
            }
            sum.map(|s| s / per_pixel as f64)
        })
        .collect()
}

/// The incidence `theta_deg` degrees from the normal in the xz-plane, light toward +x.
pub fn incidence(theta_deg: f64) -> Vec3<f64> {
    let t = theta_deg.to_radians();
    Vec3::new(t.sin(), 0.0, t.cos())
}
