//! Fresnel reflectance at a microfacet, per RGB channel.
//!
//! | kind | parameters | formula |
//! | --- | --- | --- |
//! | `White` | none | `F = 1` (furnace tests) |
//! | `Schlick` | `f0` in [0, 1] per channel | `F0 + (1 - F0)(1 - cos)^5` (Schlick 1994) |
//! | `Conductor` | complex IOR `eta + i k` per channel, relative to the outside medium | exact unpolarised reflectance of a conductor (Born & Wolf sec. 13.4; the same quantity as pbrt-v4 `FrComplex`), written in real arithmetic so it is generic over the scalar type |
//! | `Dielectric` | real relative IOR `eta` | exact unpolarised reflectance with total internal reflection for `eta < 1` |
//!
//! The conductor form: with `c = cos(theta_i)`, `a^2 + b^2 = sqrt((eta^2 - k^2 - sin^2)^2 + 4 eta^2 k^2)`
//! and `a = sqrt((a^2 + b^2 + eta^2 - k^2 - sin^2) / 2)`,
//! `Rs = (a^2 + b^2 + c^2 - 2 a c) / (a^2 + b^2 + c^2 + 2 a c)` and
//! `Rp = Rs (c^2 (a^2 + b^2) + sin^4 - 2 a c sin^2) / (c^2 (a^2 + b^2) + sin^4 + 2 a c sin^2)`.
//! The numerators are evaluated as sums of squares, `(a - c)^2 + b^2` and `(a c - sin^2)^2 +
//! b^2 c^2`, with `b^2 = (a^2 + b^2 - eta^2 + k^2 + sin^2) / 2`: the differences cancel to zero
//! for an index-matched conductor (`eta = 1`, `k = 0`, where `a = c` and `b = 0` exactly), and the stress sweep found the difference
//! form returning -7e-17 there (times a peak `D` of 1e14 at `alpha = 1e-4`).

use crate::scalar::{Real, Rgb};

/// Fresnel model of the microfacets.
#[derive(Clone, Copy, Debug)]
pub enum Fresnel<T> {
    White,
    Schlick { f0: Rgb<T> },
    Conductor { eta: Rgb<T>, k: Rgb<T> },
    Dielectric { eta: T },
}

impl<T: Real> Fresnel<T> {
    /// Reflectance for the cosine between the incident direction and the microfacet normal.
    #[inline]
    pub fn eval(&self, cos_theta: T) -> Rgb<T> {
        let c = cos_theta.max_c(0.0).min_c(1.0);
        match *self {
            Fresnel::White => Rgb::splat(T::one()),
            Fresnel::Schlick { f0 } => {
                let m = T::one() - c;
                let m5 = m.sq().sq() * m;
                f0.map(|f| f + (T::one() - f) * m5)
            }
            Fresnel::Conductor { eta, k } => eta.zip(k, |e, kk| conductor(c, e, kk)),
            Fresnel::Dielectric { eta } => Rgb::splat(dielectric(c, eta)),
        }
    }

    /// Reflectance at normal incidence.
    pub fn f0(&self) -> Rgb<T> {
        self.eval(T::one())
    }
}

/// Exact unpolarised reflectance of a conductor with complex index `eta + i k`.
#[inline]
pub fn conductor<T: Real>(c: T, eta: T, k: T) -> T {
    let c2 = c * c;
    let s2 = T::one() - c2;
    let eta2 = eta * eta;
    let k2 = k * k;
    // eta^2 - k^2 - sin^2, grouped so an index-matched conductor gives exactly c^2.
    let t0 = eta2 - k2 - T::one() + c2;
    // The square roots' arguments are floored at the smallest normal `f64`, not at zero: a
    // dual number's square root at exactly zero has the derivative 0 / 0 (an absorption-free
    // `k = 0` with `eta < 1` below the critical angle gives `a2pb2 + t0 = 0`, and so does a
    // `k` whose `4 eta^2 k^2` rounds away beside `t0^2`). The value moves by 1e-154.
    let a2pb2 = (t0 * t0 + T::c(4.0) * eta2 * k2)
        .max_c(f64::MIN_POSITIVE)
        .sqrt();
    let a = ((a2pb2 + t0) * T::c(0.5)).max_c(f64::MIN_POSITIVE).sqrt();
    let b2 = ((a2pb2 - t0) * T::c(0.5)).max_c(0.0);
    // rs = n1 / d1, rp = rs n2 / d2, and (rs + rp) / 2 = n1 (d2 + n2) / (2 d1 d2): one division.
    let (n1, d1) = ((a - c).sq() + b2, (a + c).sq() + b2);
    let (ac, b2c2) = (a * c, b2 * c2);
    let (n2, d2) = ((ac - s2).sq() + b2c2, (ac + s2).sq() + b2c2);
    n1 * (d2 + n2) / (T::c(2.0) * d1 * d2)
}

/// [`conductor`] and its derivatives by `eta` and by `k`, `[F, dF/deta, dF/dk]`, derived by
/// hand so that SIMD lanes evaluate them without dual numbers (the batch kernel's gradient
/// pass, [`crate::render::batch`]). With `A = a^2 + b^2`: `dA = d(t0^2 + 4 eta^2 k^2) / (2A)`,
/// `da = (dA + dt0) / (4a)`, `d b^2 = (dA - dt0) / 2`; then the four sums of squares by the
/// chain rule, and `dF = (dn1 (d2 + n2) + n1 (dd2 + dn2)) / (2 d1 d2) - F (dd1 / d1 + dd2 / d2)`.
/// Where [`conductor`] floors a square root's argument, the derivative through it is zero, as a
/// dual number's is.
#[inline(always)]
pub fn conductor_with_slopes<T: Real>(c: T, eta: T, k: T) -> [T; 3] {
    let (zero, one, two) = (T::zero(), T::one(), T::c(2.0));
    let above = |x: T, floor: f64, slope: [T; 2]| {
        if x.re64() > floor {
            slope
        } else {
            [zero; 2]
        }
    };
    let c2 = c * c;
    let s2 = one - c2;
    let (eta2, k2) = (eta * eta, k * k);
    let t0 = eta2 - k2 - one + c2;
    let dt0 = [two * eta, -(two * k)];
    let radicand = t0 * t0 + T::c(4.0) * eta2 * k2;
    let a2pb2 = radicand.max_c(f64::MIN_POSITIVE).sqrt();
    let half_inv = T::c(0.5) / a2pb2;
    let d_a2pb2 = above(
        radicand,
        f64::MIN_POSITIVE,
        [
            (t0 * dt0[0] + T::c(4.0) * eta * k2) * two * half_inv,
            (t0 * dt0[1] + T::c(4.0) * eta2 * k) * two * half_inv,
        ],
    );
    let a_radicand = (a2pb2 + t0) * T::c(0.5);
    let a = a_radicand.max_c(f64::MIN_POSITIVE).sqrt();
    let quarter_inv_a = T::c(0.25) / a;
    let da = above(
        a_radicand,
        f64::MIN_POSITIVE,
        [0, 1].map(|i| (d_a2pb2[i] + dt0[i]) * quarter_inv_a),
    );
    let b2_unclamped = (a2pb2 - t0) * T::c(0.5);
    let b2 = b2_unclamped.max_c(0.0);
    let db2 = above(
        b2_unclamped,
        0.0,
        [0, 1].map(|i| (d_a2pb2[i] - dt0[i]) * T::c(0.5)),
    );
    let (amc, apc) = (a - c, a + c);
    let (n1, d1) = (amc.sq() + b2, apc.sq() + b2);
    let (ac, b2c2) = (a * c, b2 * c2);
    let (acms, acps) = (ac - s2, ac + s2);
    let (n2, d2) = (acms.sq() + b2c2, acps.sq() + b2c2);
    let inv = one / (two * d1 * d2);
    let value = n1 * (d2 + n2) * inv;
    let slope = |i: usize| {
        let dn1 = two * amc * da[i] + db2[i];
        let dd1 = two * apc * da[i] + db2[i];
        let dn2 = two * acms * c * da[i] + c2 * db2[i];
        let dd2 = two * acps * c * da[i] + c2 * db2[i];
        (dn1 * (d2 + n2) + n1 * (dd2 + dn2)) * inv - value * (dd1 * d2 + d1 * dd2) * two * inv
    };
    [value, slope(0), slope(1)]
}

/// Exact unpolarised reflectance of a dielectric interface with relative index `eta`
/// (transmitted over incident medium); 1 under total internal reflection.
#[inline]
pub fn dielectric<T: Real>(c: T, eta: T) -> T {
    let cos_t2 = T::one() - (T::one() - c * c) / (eta * eta);
    if cos_t2.re64() <= 0.0 {
        return T::one();
    }
    let cos_t = cos_t2.sqrt();
    let rs = (c - eta * cos_t) / (c + eta * cos_t);
    let rp = (eta * c - cos_t) / (eta * c + cos_t);
    (rs * rs + rp * rp) * T::c(0.5)
}

/// Normal-incidence reflectance of a conductor, `((eta-1)^2 + k^2) / ((eta+1)^2 + k^2)`.
pub fn conductor_f0(eta: f64, k: f64) -> f64 {
    ((eta - 1.0).powi(2) + k * k) / ((eta + 1.0).powi(2) + k * k)
}

/// Largest reflectivity the Gulbrandsen map takes: its `n_max` diverges at `r = 1`; at 0.9999
/// it is about 4e4, and the conductor's reflectance stays finite in single precision (the
/// batch kernel's `f32` lanes square `eta^2 - k^2` once more). Before the cap, a `single` fit
/// of rough gold rendered by `heitz` pushed red `r` to the sigmoid's `1 - 1e-12`, `eta` to
/// 4e11, and every `f32` pixel to NaN.
pub const MAX_REFLECTIVITY: f64 = 0.9999;

/// Gulbrandsen 2014 ("Artist Friendly Metallic Fresnel", JCGT 3(4), eq. 2-5): the complex index
/// `(eta, k)` with normal reflectivity `r` in [0, 1) (capped at [`MAX_REFLECTIVITY`]) and edge
/// tint `g` in [0, 1].
/// `eta = g n_min + (1 - g) n_max` with `n_min = (1 - r) / (1 + r)`,
/// `n_max = (1 + sqrt r) / (1 - sqrt r)`, and `k = sqrt((r (eta + 1)^2 - (eta - 1)^2) / (1 - r))`.
/// Generic over the scalar, so the fitter differentiates through it exactly.
pub fn ior_from_reflectivity_edge_tint<T: Real>(r: T, g: T) -> (T, T) {
    let one = T::one();
    let r = r.max_c(0.0).min_c(MAX_REFLECTIVITY);
    let g = g.max_c(0.0).min_c(1.0);
    let n_min = (one - r) / (one + r);
    let sr = r.sqrt();
    let n_max = (one + sr) / (one - sr);
    let eta = g * n_min + (one - g) * n_max;
    let k2 = (r * (eta + one).sq() - (eta - one).sq()) / (one - r);
    (eta, k2.max_c(0.0).sqrt())
}

/// Inverse of [`ior_from_reflectivity_edge_tint`]: `r = F0(eta, k)`,
/// `g = (n_max - eta) / (n_max - n_min)`, clamped to [0, 1] for indices outside the family.
pub fn reflectivity_edge_tint_from_ior(eta: f64, k: f64) -> (f64, f64) {
    let r = conductor_f0(eta, k);
    let n_min = (1.0 - r) / (1.0 + r);
    let sr = r.sqrt();
    let n_max = (1.0 + sr) / (1.0 - sr);
    let g = if n_max > n_min {
        (n_max - eta) / (n_max - n_min)
    } else {
        0.0
    };
    (r, g.clamp(0.0, 1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gulbrandsen_round_trip_and_reflectivity() {
        for &(eta, k) in &[
            (0.27, 3.61),
            (0.68, 2.63),
            (1.22, 2.29),
            (1.5, 7.6),
            (0.14, 3.98),
        ] {
            let (r, g) = reflectivity_edge_tint_from_ior(eta, k);
            let (eta2, k2) = ior_from_reflectivity_edge_tint(r, g);
            // The dual derivatives match central differences of the f64 map.
            let (de, dk) = ior_from_reflectivity_edge_tint(
                num_dual::Dual64::from_re(r).derivative(),
                num_dual::Dual64::from_re(g),
            );
            let h = 1e-6;
            let (ep, kp) = ior_from_reflectivity_edge_tint(r + h, g);
            let (em, km) = ior_from_reflectivity_edge_tint(r - h, g);
            assert!((de.eps - (ep - em) / (2.0 * h)).abs() < 1e-5 * de.eps.abs().max(1.0));
            assert!((dk.eps - (kp - km) / (2.0 * h)).abs() < 1e-5 * dk.eps.abs().max(1.0));
            assert!(
                (eta - eta2).abs() < 1e-9 && (k - k2).abs() < 1e-9,
                "{eta},{k} -> {r},{g} -> {eta2},{k2}"
            );
            assert!((conductor(1.0, eta2, k2) - r).abs() < 1e-12);
        }
    }

    /// Reference reflectance through complex arithmetic on the amplitude coefficients
    /// (`cos_t = sqrt(1 - sin^2 / n^2)` with complex `n`): an independent derivation.
    fn conductor_complex(c: f64, eta: f64, k: f64) -> f64 {
        type C = (f64, f64);
        let mul = |a: C, b: C| (a.0 * b.0 - a.1 * b.1, a.0 * b.1 + a.1 * b.0);
        let div = |a: C, b: C| {
            let d = b.0 * b.0 + b.1 * b.1;
            ((a.0 * b.0 + a.1 * b.1) / d, (a.1 * b.0 - a.0 * b.1) / d)
        };
        let sqrt = |a: C| {
            let r = (a.0 * a.0 + a.1 * a.1).sqrt().sqrt();
            let t = a.1.atan2(a.0) / 2.0;
            (r * t.cos(), r * t.sin())
        };
        let n = (eta, k);
        let s2 = 1.0 - c * c;
        let sin2_t = div((s2, 0.0), mul(n, n));
        let cos_t = sqrt((1.0 - sin2_t.0, -sin2_t.1));
        let ci = (c, 0.0);
        let n_ci = mul(n, ci);
        let n_ct = mul(n, cos_t);
        let r_parl = div(
            (n_ci.0 - cos_t.0, n_ci.1 - cos_t.1),
            (n_ci.0 + cos_t.0, n_ci.1 + cos_t.1),
        );
        let r_perp = div(
            (ci.0 - n_ct.0, ci.1 - n_ct.1),
            (ci.0 + n_ct.0, ci.1 + n_ct.1),
        );
        let norm = |a: C| a.0 * a.0 + a.1 * a.1;
        0.5 * (norm(r_parl) + norm(r_perp))
    }

    #[test]
    fn conductor_matches_complex_amplitudes() {
        for &(eta, k) in &[
            (0.2, 3.9),
            (1.1, 2.1),
            (0.05, 0.5),
            (2.5, 0.0),
            (0.27, 2.78),
            (9.0, 20.0),
        ] {
            for i in 0..=20 {
                let c = (i as f64 / 20.0).max(1e-6);
                let a = conductor(c, eta, k);
                let b = conductor_complex(c, eta, k);
                assert!((a - b).abs() < 1e-12, "eta {eta} k {k} cos {c}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn conductor_slopes_equal_its_dual_number_derivatives() {
        use num_dual::Dual64;
        // Metals, a dielectric without absorption below and beyond its critical angle (where
        // `conductor` floors `a`), an index-matched interface, and extreme indices.
        let indices = [
            (0.2, 3.9),
            (1.1, 2.1),
            (0.05, 0.5),
            (2.5, 0.0),
            (0.5, 0.0),
            (1.0, 0.0),
            (0.27, 2.78),
            (9.0, 20.0),
            (1e-3, 1e-3),
            (50.0, 1e-4),
        ];
        for &(eta, k) in &indices {
            for i in 0..=40 {
                let c = (i as f64 / 40.0).max(1e-7);
                let [value, by_eta, by_k] = conductor_with_slopes(c, eta, k);
                let x = Dual64::from_re(c);
                let dual_eta = conductor(x, Dual64::from_re(eta).derivative(), Dual64::from_re(k));
                let dual_k = conductor(x, Dual64::from_re(eta), Dual64::from_re(k).derivative());
                let close = |a: f64, b: f64| (a - b).abs() <= 1e-10 * (1.0 + b.abs());
                assert!(
                    close(value, conductor(c, eta, k)),
                    "eta {eta} k {k} cos {c}"
                );
                assert!(
                    close(by_eta, dual_eta.eps),
                    "eta {eta} k {k} cos {c}: d/deta {by_eta} vs {}",
                    dual_eta.eps
                );
                assert!(
                    close(by_k, dual_k.eps),
                    "eta {eta} k {k} cos {c}: d/dk {by_k} vs {}",
                    dual_k.eps
                );
            }
        }
    }

    #[test]
    fn normal_incidence_is_f0_and_grazing_tends_to_one() {
        for &(eta, k) in &[(0.2, 3.9), (1.5, 0.0), (0.27, 2.78), (3.0, 0.1)] {
            assert!((conductor(1.0, eta, k) - conductor_f0(eta, k)).abs() < 1e-14);
            assert!(1.0 - conductor(1e-7, eta, k) < 1e-5, "eta {eta} k {k}");
        }
        let eta = 1.5f64;
        assert!((dielectric(1.0, eta) - 0.04).abs() < 1e-14);
        assert!(1.0 - dielectric(1e-7, eta) < 1e-5);
        let schlick = Fresnel::Schlick {
            f0: Rgb([0.9f64, 0.5, 0.1]),
        };
        assert_eq!(schlick.eval(1.0).0, [0.9, 0.5, 0.1]);
        assert!(schlick.eval(0.0).0.iter().all(|&v| (v - 1.0).abs() < 1e-15));
    }

    #[test]
    fn dielectric_total_internal_reflection_and_reciprocity_of_indices() {
        // Inside glass (eta = 1/1.5) beyond the critical angle everything reflects.
        let crit = (1.0f64 / 1.5).asin();
        assert_eq!(dielectric((crit + 0.01).cos(), 1.0 / 1.5), 1.0);
        // Stokes relation: reflectance from either side is equal for refracted angle pairs.
        let ci: f64 = 0.8;
        let st = (1.0 - ci * ci).sqrt() / 1.5;
        let ct = (1.0 - st * st).sqrt();
        assert!((dielectric(ci, 1.5) - dielectric(ct, 1.0 / 1.5)).abs() < 1e-14);
    }

    #[test]
    fn conductor_reduces_to_dielectric_without_absorption() {
        for i in 1..=10 {
            let c = i as f64 / 10.0;
            assert!((conductor(c, 1.5, 0.0) - dielectric(c, 1.5)).abs() < 1e-14);
        }
    }
}
