//! The Beckmann distribution in the stretched configuration (roughness 1).
//!
//! | function | formula | reference |
//! | --- | --- | --- |
//! | density | `exp(-s^2 / z^2) / (pi z^4)` for a unit normal, `s` stretched horizontal length | Walter et al. 2007 eq. 25 |
//! | `|z| Lambda` | `s g(nu)`, `nu = z / s`, `g(nu) = exp(-nu^2) / (2 sqrt(pi)) - nu erfc(nu) / 2` | Heitz 2014 eq. 80, exact (not Walter's rational fit) |
//! | sampling | inverse CDF of the visible slope `x` with density `(cot - x)+ exp(-x^2)`, then `y ~ N(0, 1/2)` | Heitz & d'Eon 2014, "Importance Sampling Microfacet-Based BSDFs using the Distribution of Visible Normals", sec. 4, solved here by safeguarded Newton for any `cot`, negative included |
//!
//! `g(nu)` uses `erfc`, never `1 - erf`: the difference of its two terms is about `1/(2 nu^2)` of
//! either, so the relative error stays below `2 nu^2` ulps, and both terms underflow together
//! to zero past `nu ~ 27`.

use crate::scalar::{Real, Vec3};
use std::f64::consts::PI;

const INV_SQRT_PI: f64 = 0.564_189_583_547_756_3;

/// `D * ax * ay` of a unit normal with stretched horizontal length squared `s2` and height `z > 0`.
#[inline]
pub fn density_stretched<T: Real>(s2: T, z: T) -> T {
    let z2 = z * z;
    let q = s2 / z2;
    if q.re64() > 1400.0 {
        // exp(-q) underflows below any representable density long before z^4 does.
        return T::zero();
    }
    (-q).exp() / (T::c(PI) * z2 * z2)
}

/// `z * Lambda` for an upward direction with height `z >= 0` and stretched horizontal length
/// `s >= 0`; equals `s / (2 sqrt(pi))` at grazing and vanishes at normal incidence.
#[inline]
pub fn z_lambda<T: Real>(z: T, s: T) -> T {
    if s.re64() <= 0.0 {
        return T::zero();
    }
    let nu = z / s;
    s * ((-(nu * nu)).exp() * T::c(0.5 * INV_SQRT_PI) - nu * nu.erfc() * T::c(0.5))
}

/// Unnormalised CDF of the visible slope in the standard configuration,
/// `F(x) = integral_{-inf}^{x} (c - t) exp(-t^2) / sqrt(pi) dt = c erfc(-x) / 2 + exp(-x^2) / (2 sqrt(pi))`,
/// valid for `x <= c` and any sign of `c = cot(theta)`.
#[inline]
fn visible_slope_cdf<T: Real>(x: T, c: T) -> T {
    c * (-x).erfc() * T::c(0.5) + (-(x * x)).exp() * T::c(0.5 * INV_SQRT_PI)
}

/// Solve `F(x) = u F(c)` for the visible slope `x <= c` in `f64` (bisection-safeguarded Newton).
/// The start is Jakob's fitted inverse in the `erf` domain (W. Jakob 2014, "An Improved Visible
/// Normal Sampling Routine for the Beckmann Distribution", technical report, ETH Zurich):
/// `erf(x0) = erf(c) - (1 + erf(c)) (1 - u)^p(theta)` with
/// `p = 1 + theta (-0.876 + theta (0.4265 - 0.0594 theta))`, after which Newton needs a few steps.
fn invert_visible_slope_cdf(u: f64, c: f64) -> f64 {
    let target = u * visible_slope_cdf(c, c);
    let mut lo = c.min(0.0) - 9.0;
    let mut hi = c;
    if visible_slope_cdf(lo, c) >= target {
        return lo;
    }
    let theta = std::f64::consts::FRAC_PI_2 - c.atan();
    let power = 1.0 + theta * (-0.876 + theta * (0.4265 - 0.0594 * theta));
    let erf_c = libm::erf(c);
    let guess =
        erfinv((erf_c - (1.0 + erf_c) * (1.0 - u).powf(power)).clamp(-1.0 + 1e-15, 1.0 - 1e-15));
    let mut x = if guess.is_finite() && guess > lo && guess < hi {
        guess
    } else {
        0.5 * (lo.max(-3.0) + c).min(c)
    };
    // The residual cannot get below the rounding of F itself (~1e-16 F(c)); stopping there
    // instead of on the step size saves the bisection steps that rounding noise would trigger.
    let resolution = 1e-14 * visible_slope_cdf(c, c);
    for _ in 0..100 {
        let f = visible_slope_cdf(x, c) - target;
        if f.abs() <= resolution {
            return x;
        }
        if f > 0.0 {
            hi = x;
        } else {
            lo = x;
        }
        let slope = (c - x) * (-x * x).exp() * INV_SQRT_PI;
        let newton = x - f / slope;
        let next = if slope > 0.0 && newton > lo && newton < hi {
            newton
        } else {
            0.5 * (lo + hi)
        };
        if (next - x).abs() <= 1e-13 * (1.0 + x.abs()) {
            return next;
        }
        x = next;
    }
    x
}

/// Inverse error function: Giles 2010 ("Approximating the erfinv function", single-precision
/// polynomials) polished by two Newton steps on `libm::erf`.
fn erfinv(y: f64) -> f64 {
    let w = -((1.0 - y) * (1.0 + y)).ln();
    let mut x = if w < 5.0 {
        let w = w - 2.5;
        let mut p = 2.810_226_36e-08;
        for c in [
            3.432_739_39e-07,
            -3.523_387_7e-06,
            -4.391_506_54e-06,
            2.185_808_7e-04,
            -1.253_725_03e-03,
            -4.177_681_64e-03,
            2.466_407_27e-01,
            1.501_409_41,
        ] {
            p = c + p * w;
        }
        p * y
    } else {
        let w = w.sqrt() - 3.0;
        let mut p = -2.002_142_57e-04;
        for c in [
            1.009_505_58e-04,
            1.349_343_22e-03,
            -3.673_428_44e-03,
            5.739_507_73e-03,
            -7.622_461_3e-03,
            9.438_870_47e-03,
            1.001_674_06,
            2.832_976_82,
        ] {
            p = c + p * w;
        }
        p * y
    };
    for _ in 0..2 {
        let err = libm::erf(x) - y;
        x -= err / (std::f64::consts::FRAC_2_SQRT_PI * (-x * x).exp());
    }
    x
}

/// Sample a unit normal of the roughness-1 Beckmann surface visible from the unit direction `v`
/// (any `v.z`), following Heitz & d'Eon 2014: the slope along the projected direction has
/// density proportional to `(cot(theta) - x)+ exp(-x^2)`, the orthogonal slope is an
/// independent `N(0, 1/2)`. The CDF is inverted in `f64`, then one Newton step in `T` carries
/// the exact derivative `dx/dc` of the implicit solution to dual numbers.
pub fn sample_visible_stretched<T: Real>(v: Vec3<T>, u: [f64; 2]) -> Vec3<T> {
    let sin_theta = (v.x * v.x + v.y * v.y).sqrt();
    let y_open = (2.0 * u[1] - 1.0).clamp(-1.0 + f64::EPSILON, 1.0 - f64::EPSILON);
    let slope_y = T::c(erfinv(y_open));
    let (slope_x, cos_phi, sin_phi) = if sin_theta.re64() < 1e-9 {
        if v.z.re64() < 0.0 {
            // Straight down: no normal is visible (A(w) = 0); a ray leaving straight up never
            // meets the microsurface again, so random walks never ask for this case.
            return Vec3::new(T::zero(), T::zero(), T::one());
        }
        // Normal incidence: every slope is equally visible up to the density itself.
        let u0 = u[0].max(f64::MIN_POSITIVE);
        let x = (2.0 * u0 - 1.0).clamp(-1.0 + f64::EPSILON, 1.0 - f64::EPSILON);
        (T::c(erfinv(x)), T::one(), T::zero())
    } else {
        let c = v.z / sin_theta;
        let x0 = invert_visible_slope_cdf(u[0], c.re64());
        let density = (c.re64() - x0) * (-x0 * x0).exp() * INV_SQRT_PI;
        // Implicit function theorem: dx = -(dF(x0; c) - u dF(c; c)) / F'(x0). Only the derivative
        // part of the Newton correction is kept; the real part stays the safeguarded root, since
        // near u = 1 the density vanishes and a rounding-sized residual would step past c.
        let x = if density > 1e-300 {
            let residual = visible_slope_cdf(T::c(x0), c) - T::c(u[0]) * visible_slope_cdf(c, c);
            let correction = -residual / T::c(density);
            T::c(x0) + (correction - T::c(correction.re64()))
        } else {
            T::c(x0)
        };
        (x, v.x / sin_theta, v.y / sin_theta)
    };
    let sx = cos_phi * slope_x - sin_phi * slope_y;
    let sy = sin_phi * slope_x + cos_phi * slope_y;
    Vec3::new(-sx, -sy, T::one()).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn erfinv_inverts_erf() {
        for &y in &[-0.999999, -0.9, -0.3, 0.0, 0.2, 0.75, 0.99999] {
            assert!((libm::erf(erfinv(y)) - y).abs() < 1e-14, "y = {y}");
        }
    }

    #[test]
    fn visible_slope_cdf_total_is_projected_area() {
        // F(c) = c (1 + Lambda(c)) for any cot c: the normalisation of the visible slopes.
        for &c in &[-2.0f64, -0.3, 0.1, 1.0, 4.0] {
            let z_lambda: f64 = z_lambda(c.abs(), 1.0);
            let area = c.max(0.0) + z_lambda;
            assert!((visible_slope_cdf(c, c) - area).abs() < 1e-14, "c = {c}");
        }
    }

    #[test]
    fn slope_inversion_hits_its_target() {
        for &c in &[-3.0, -0.5, 0.0, 0.4, 2.0, 8.0] {
            for &u in &[1e-9, 0.01, 0.3, 0.5, 0.97, 0.999999] {
                let x = invert_visible_slope_cdf(u, c);
                let got = visible_slope_cdf(x, c) / visible_slope_cdf(c, c);
                assert!(
                    (got - u).abs() < 1e-10 * u.max(1e-3),
                    "c = {c}, u = {u}: {got}"
                );
            }
        }
    }
}
