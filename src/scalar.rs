//! The scalar type every physics kernel is generic over, and the small vector types built on it.
//!
//! The microfacet kernel and the analytic models are written once, generic over [`Real`], and
//! instantiated with `f64` (reference), `f32` (fast paths) and forward-mode dual numbers from
//! `num-dual` (`Dual64`, `DualSVec64<N>`) so the fitter can differentiate them exactly
//! (ENGINEERING-NOTES.md, "Gradients"). glam only holds `f32`/`f64`, hence the own [`Vec3`] and
//! [`Rgb`] here; glam stays in use for camera and scene geometry.

use num_dual::{Dual64, DualNum, DualSVec64};
use std::ops::{Add, Mul, Neg, Sub};

/// A real scalar: `f32`, `f64` or a first-order dual number over `f64`.
///
/// Branches in kernels test the real part ([`Real::re64`]); arithmetic goes through the
/// `DualNum` operators and functions so derivatives propagate.
pub trait Real: DualNum + Copy + Send + Sync {
    /// A constant (no derivative part).
    fn c(x: f64) -> Self;
    /// The real part as `f64`.
    fn re64(self) -> f64;
    /// Complementary error function, accurate in the tails (used by the Beckmann Lambda).
    fn erfc(self) -> Self;

    /// `max(self, lo)` on real parts, keeping the derivative of the chosen operand.
    #[inline]
    fn max_c(self, lo: f64) -> Self {
        if self.re64() > lo {
            self
        } else {
            Self::c(lo)
        }
    }
    /// `min(self, hi)` on real parts, keeping the derivative of the chosen operand.
    #[inline]
    fn min_c(self, hi: f64) -> Self {
        if self.re64() < hi {
            self
        } else {
            Self::c(hi)
        }
    }
    #[inline]
    fn sq(self) -> Self {
        self * self
    }
    /// `exp(-x^2) / sqrt(pi) * 2` chain rule of erfc, shared by the dual implementations.
    #[doc(hidden)]
    #[inline]
    fn erfc_linearised(self) -> Self {
        let x = self.re64();
        let value = libm::erfc(x);
        let slope = -std::f64::consts::FRAC_2_SQRT_PI * (-x * x).exp();
        // A first-order dual is exactly its linearisation about the real part.
        Self::c(value) + (self - Self::c(x)) * Self::c(slope)
    }
}

impl Real for f64 {
    #[inline]
    fn c(x: f64) -> Self {
        x
    }
    #[inline]
    fn re64(self) -> f64 {
        self
    }
    #[inline]
    fn erfc(self) -> Self {
        libm::erfc(self)
    }
}

impl Real for f32 {
    #[inline]
    fn c(x: f64) -> Self {
        x as f32
    }
    #[inline]
    fn re64(self) -> f64 {
        self as f64
    }
    #[inline]
    fn erfc(self) -> Self {
        libm::erfcf(self)
    }
    /// Compared in `f32`, so SIMD lanes need no conversion to `f64`. The same result as the
    /// default: where `lo` is not an `f32`, a value equal to its rounding `lo as f32` is
    /// returned either way.
    #[inline]
    fn max_c(self, lo: f64) -> Self {
        let lo = lo as f32;
        if self > lo {
            self
        } else {
            lo
        }
    }
    /// As [`Real::max_c`] for `f32`.
    #[inline]
    fn min_c(self, hi: f64) -> Self {
        let hi = hi as f32;
        if self < hi {
            self
        } else {
            hi
        }
    }
}

impl Real for Dual64 {
    #[inline]
    fn c(x: f64) -> Self {
        Dual64::from_re(x)
    }
    #[inline]
    fn re64(self) -> f64 {
        self.re
    }
    #[inline]
    fn erfc(self) -> Self {
        self.erfc_linearised()
    }
}

impl<const N: usize> Real for DualSVec64<N> {
    #[inline]
    fn c(x: f64) -> Self {
        DualSVec64::from_re(x)
    }
    #[inline]
    fn re64(self) -> f64 {
        self.re
    }
    #[inline]
    fn erfc(self) -> Self {
        self.erfc_linearised()
    }
}

/// A 3-vector of a [`Real`] scalar: directions and normals in the local shading frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Vec3<T> {
    pub x: T,
    pub y: T,
    pub z: T,
}

impl<T: Real> Vec3<T> {
    #[inline]
    pub fn new(x: T, y: T, z: T) -> Self {
        Vec3 { x, y, z }
    }
    /// A constant vector from `f64` components.
    #[inline]
    pub fn from_f64(v: [f64; 3]) -> Self {
        Vec3::new(T::c(v[0]), T::c(v[1]), T::c(v[2]))
    }
    /// Real parts as an `f64` array.
    #[inline]
    pub fn re(self) -> [f64; 3] {
        [self.x.re64(), self.y.re64(), self.z.re64()]
    }
    #[inline]
    pub fn dot(self, o: Self) -> T {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    #[inline]
    pub fn cross(self, o: Self) -> Self {
        Vec3::new(
            self.y * o.z - self.z * o.y,
            self.z * o.x - self.x * o.z,
            self.x * o.y - self.y * o.x,
        )
    }
    #[inline]
    pub fn length_squared(self) -> T {
        self.dot(self)
    }
    #[inline]
    pub fn length(self) -> T {
        self.length_squared().sqrt()
    }
    /// Unit vector in the same direction. The caller guarantees a non-zero length.
    #[inline]
    pub fn normalize(self) -> Self {
        self * self.length().recip()
    }
    /// Mirror reflection of `self` about the unit normal `m` (both pointing away from the surface).
    #[inline]
    pub fn reflect(self, m: Self) -> Self {
        m * (T::c(2.0) * self.dot(m)) - self
    }
}

impl<T: Real> Add for Vec3<T> {
    type Output = Self;
    #[inline]
    fn add(self, o: Self) -> Self {
        Vec3::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}

impl<T: Real> Sub for Vec3<T> {
    type Output = Self;
    #[inline]
    fn sub(self, o: Self) -> Self {
        Vec3::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}

impl<T: Real> Neg for Vec3<T> {
    type Output = Self;
    #[inline]
    fn neg(self) -> Self {
        Vec3::new(-self.x, -self.y, -self.z)
    }
}

impl<T: Real> Mul<T> for Vec3<T> {
    type Output = Self;
    #[inline]
    fn mul(self, s: T) -> Self {
        Vec3::new(self.x * s, self.y * s, self.z * s)
    }
}

/// A linear RGB triple (Rec.709 primaries): reflectances, Fresnel terms, radiance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rgb<T>(pub [T; 3]);

impl<T: Real> Rgb<T> {
    #[inline]
    pub fn splat(v: T) -> Self {
        Rgb([v; 3])
    }
    #[inline]
    pub fn from_f64(v: [f64; 3]) -> Self {
        Rgb(v.map(T::c))
    }
    #[inline]
    pub fn re(self) -> [f64; 3] {
        self.0.map(|v| v.re64())
    }
    /// Apply `f` to each channel.
    #[inline]
    pub fn map(self, f: impl Fn(T) -> T) -> Self {
        Rgb(self.0.map(f))
    }
    /// Combine two triples channel by channel.
    #[inline]
    pub fn zip(self, o: Self, f: impl Fn(T, T) -> T) -> Self {
        Rgb([
            f(self.0[0], o.0[0]),
            f(self.0[1], o.0[1]),
            f(self.0[2], o.0[2]),
        ])
    }
    #[inline]
    pub fn scale(self, s: T) -> Self {
        self.map(|v| v * s)
    }
}

impl<T: Real> Add for Rgb<T> {
    type Output = Self;
    #[inline]
    fn add(self, o: Self) -> Self {
        self.zip(o, |a, b| a + b)
    }
}

impl<T: Real> Mul for Rgb<T> {
    type Output = Self;
    #[inline]
    fn mul(self, o: Self) -> Self {
        self.zip(o, |a, b| a * b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dual_erfc_matches_analytic_derivative() {
        for &x in &[-3.0, -0.5, 0.0, 0.7, 2.5, 6.0] {
            let d = Dual64::from_re(x).derivative().erfc();
            let expected = -std::f64::consts::FRAC_2_SQRT_PI * (-x * x).exp();
            assert!((d.re - libm::erfc(x)).abs() < 1e-15);
            assert!((d.eps - expected).abs() <= 1e-14 * expected.abs().max(1e-300));
            let v: DualSVec64<2> = DualSVec64::from_re(x).derivative(1);
            let e = v.erfc();
            let grad = e.eps.0.expect("derivative part");
            assert!((grad[1] - expected).abs() <= 1e-14 * expected.abs().max(1e-300));
            assert_eq!(grad[0], 0.0);
        }
    }

    #[test]
    fn reflect_is_an_involution_and_preserves_angle() {
        let m = Vec3::<f64>::new(0.3, -0.2, 0.9).normalize();
        let w = Vec3::<f64>::new(-0.5, 0.1, 0.7).normalize();
        let r = w.reflect(m);
        assert!((r.dot(m) - w.dot(m)).abs() < 1e-15);
        let back = r.reflect(m);
        assert!((back - w).length() < 1e-15);
    }
}
