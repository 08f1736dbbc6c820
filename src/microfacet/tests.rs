//! Tests of the microfacet kernel against independent quadrature and by histograms.

use super::*;
use crate::random::Rng;
use num_dual::Dual64;
use rand::{Rng as _, SeedableRng};
use std::f64::consts::PI;

const KINDS: [NdfKind; 2] = [NdfKind::Ggx, NdfKind::Beckmann];

fn unit(theta_deg: f64, phi_deg: f64) -> Vec3<f64> {
    let (t, p) = (theta_deg.to_radians(), phi_deg.to_radians());
    Vec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
}

/// Map of the unit square onto the upper hemisphere that concentrates points where a lobe of
/// roughness `a` lives: `theta = atan(a tan(pi v / 2))`, `phi = 2 pi u`. Returns the direction and
/// the Jacobian `d omega / (du dv)`.
fn warp(a: f64, u: f64, v: f64) -> (Vec3<f64>, f64) {
    let t = (0.5 * PI * v).tan();
    let theta = (a * t).atan();
    let dtheta_dv = a * 0.5 * PI * (1.0 + t * t) / (1.0 + a * a * t * t);
    let phi = 2.0 * PI * u;
    let m = Vec3::new(
        theta.sin() * phi.cos(),
        theta.sin() * phi.sin(),
        theta.cos(),
    );
    (m, theta.sin() * dtheta_dv * 2.0 * PI)
}

fn unwarp(a: f64, m: Vec3<f64>) -> (f64, f64) {
    let theta = m.z.clamp(-1.0, 1.0).acos();
    let v = 2.0 / PI * (theta.tan() / a).atan();
    let u = m.y.atan2(m.x).rem_euclid(2.0 * PI) / (2.0 * PI);
    (u.min(1.0 - 1e-16), v)
}

/// Where the visible normals of `w` live, as `tan(theta_m)`: about `alpha` for `w` above the
/// horizon; from below, only normals steeper than the depression of `w` are visible, so the
/// scale becomes `alpha + |cot theta_w|`.
fn warp_scale(mf: &Microfacet<f64>, w: Vec3<f64>) -> f64 {
    let a = (mf.ax * mf.ay).sqrt();
    if w.z < 0.0 {
        a + w.z.abs() / (1.0 - w.z * w.z).sqrt()
    } else {
        a
    }
}

/// Midpoint rule of `g` over the upper hemisphere with the warp above.
fn integrate_hemisphere(a: f64, nu: usize, nv: usize, g: impl Fn(Vec3<f64>) -> f64) -> f64 {
    let mut sum = 0.0;
    for j in 0..nv {
        let v = (j as f64 + 0.5) / nv as f64;
        for i in 0..nu {
            let u = (i as f64 + 0.5) / nu as f64;
            let (m, jac) = warp(a, u, v);
            sum += g(m) * jac;
        }
    }
    sum / (nu * nv) as f64
}

fn roughness_cases() -> Vec<(f64, f64)> {
    let mut cases: Vec<(f64, f64)> = [0.01, 0.05, 0.2, 0.5, 1.0, 2.0]
        .iter()
        .map(|&a| (a, a))
        .collect();
    cases.extend([(0.05, 0.4), (0.6, 0.1), (1.5, 0.3), (0.02, 0.2)]);
    cases
}

#[test]
fn distribution_is_normalised() {
    for ndf in KINDS {
        for (ax, ay) in roughness_cases() {
            let mf = Microfacet::new(ndf, ax, ay);
            let total = integrate_hemisphere((ax * ay).sqrt(), 400, 3000, |m| mf.d(m) * m.z);
            assert!(
                (total - 1.0).abs() < 1e-3,
                "{ndf:?} ax {ax} ay {ay}: {total}"
            );
        }
    }
}

#[test]
fn projected_area_matches_quadrature_above_and_below_the_horizon() {
    // A(w) = integral <w,m>+ D(m) dm checks Lambda, including the full-sphere extension.
    for ndf in KINDS {
        for (ax, ay) in [(0.1f64, 0.1f64), (0.5, 0.5), (1.2, 1.2), (0.2, 0.8)] {
            let mf = Microfacet::new(ndf, ax, ay);
            for w in [
                unit(0.0, 0.0),
                unit(40.0, 30.0),
                unit(80.0, 100.0),
                unit(89.9, 10.0),
                unit(95.0, 45.0),
                unit(130.0, 200.0),
            ] {
                let quad = integrate_hemisphere((ax * ay).sqrt(), 400, 3000, |m| {
                    w.dot(m).max(0.0) * mf.d(m)
                });
                let area = mf.projected_area(w);
                assert!(
                    (quad - area).abs() < 2e-4 * area.max(0.05),
                    "{ndf:?} {ax},{ay} w {w:?}: {quad} vs {area}"
                );
                if w.z.abs() > 1e-3 {
                    let via_lambda = w.z * (1.0 + mf.lambda(w));
                    assert!((via_lambda - area).abs() < 1e-12 * area.max(1.0));
                }
            }
        }
    }
}

#[test]
fn lambda_full_sphere_identity_and_closed_forms() {
    let ggx = Microfacet::new(NdfKind::Ggx, 0.4f64, 0.4);
    let beck = Microfacet::new(NdfKind::Beckmann, 0.4f64, 0.4);
    for theta in [5.0f64, 30.0, 60.0, 85.0] {
        let w = unit(theta, 20.0);
        for mf in [ggx, beck] {
            assert!((mf.lambda(-w) - (-1.0 - mf.lambda(w))).abs() < 1e-12);
        }
        // Textbook forms through nu = 1 / (alpha tan theta).
        let nu: f64 = 1.0 / (0.4 * theta.to_radians().tan());
        let ggx_ref = (-1.0 + (1.0 + 1.0 / (nu * nu)).sqrt()) / 2.0;
        let beck_ref = (libm::erf(nu) - 1.0) / 2.0 + (-nu * nu).exp() / (2.0 * nu * PI.sqrt());
        assert!((ggx.lambda(w) - ggx_ref).abs() < 1e-12 * ggx_ref.max(1e-3));
        assert!(
            (beck.lambda(w) - beck_ref).abs() < 1e-10 * beck_ref.max(1e-3),
            "{} {}",
            beck.lambda(w),
            beck_ref
        );
    }
}

#[test]
fn visible_normal_density_integrates_to_one() {
    for ndf in KINDS {
        for (ax, ay) in [
            (0.05f64, 0.05f64),
            (0.3, 0.3),
            (1.0, 1.0),
            (2.0, 2.0),
            (0.1, 0.6),
        ] {
            let mf = Microfacet::new(ndf, ax, ay);
            for w in [
                unit(0.0, 0.0),
                unit(45.0, 10.0),
                unit(85.0, 70.0),
                unit(100.0, 0.0),
                unit(150.0, 250.0),
            ] {
                if mf.projected_area(w) < 1e-12 {
                    // Nothing is visible in f64 (Beckmann alpha 0.05 from 150 deg: A ~ exp(-1200)).
                    assert_eq!(mf.pdf_visible(w, unit(89.0, 250.0)), 0.0);
                    continue;
                }
                let a = warp_scale(&mf, w);
                let total = integrate_hemisphere(a, 400, 3000, |m| mf.pdf_visible(w, m));
                assert!(
                    (total - 1.0).abs() < 1e-3,
                    "{ndf:?} {ax},{ay} w {w:?}: {total}"
                );
            }
        }
    }
}

/// Upper tail probability bound of a chi-square statistic through the Wilson-Hilferty normal
/// approximation: returns the standard normal deviate of `chi2` with `dof` degrees of freedom.
fn chi_square_z(chi2: f64, dof: f64) -> f64 {
    let k = 2.0 / (9.0 * dof);
    ((chi2 / dof).cbrt() - (1.0 - k)) / k.sqrt()
}

/// Histogram `n` sampled normals in a `bins_u x bins_v` grid of the warped square and compare
/// with the density integrated over each bin. Bins expecting fewer than 5 counts are pooled.
fn chi_square_of_sampler(mf: Microfacet<f64>, w: Vec3<f64>, seed: u64) -> f64 {
    let (bins_u, bins_v, n) = (32usize, 24usize, 400_000usize);
    let a = warp_scale(&mf, w);
    let mut observed = vec![0.0; bins_u * bins_v];
    let mut rng = Rng::seed_from_u64(seed);
    for _ in 0..n {
        let m = mf.sample_visible(w, [rng.random(), rng.random()]);
        assert!(m.z >= 0.0 && (m.length() - 1.0).abs() < 1e-9);
        assert!(
            mf.pdf_visible(w, m) > 0.0,
            "sampled an invisible normal {m:?} for {w:?}"
        );
        let (u, v) = unwarp(a, m);
        let (i, j) = (
            (u * bins_u as f64) as usize,
            ((v * bins_v as f64) as usize).min(bins_v - 1),
        );
        observed[j * bins_u + i] += 1.0;
    }
    let mut expected = vec![0.0; bins_u * bins_v];
    let bin_mass = |i: usize, j: usize, sub: usize| {
        let mut s = 0.0;
        for q in 0..sub {
            for p in 0..sub {
                let u = (i as f64 + (p as f64 + 0.5) / sub as f64) / bins_u as f64;
                let v = (j as f64 + (q as f64 + 0.5) / sub as f64) / bins_v as f64;
                let (m, jac) = warp(a, u, v);
                s += mf.pdf_visible(w, m) * jac;
            }
        }
        s / (sub * sub * bins_u * bins_v) as f64
    };
    let coarse: Vec<f64> = (0..bins_u * bins_v)
        .map(|k| bin_mass(k % bins_u, k / bins_u, 12))
        .collect();
    for j in 0..bins_v {
        for i in 0..bins_u {
            // Bins holding much of the mass need their integral to better than 1/sqrt(count);
            // bins on the edge of the visible region may hold a sliver the coarse grid misses.
            let k = j * bins_u + i;
            let neighbours = [
                (i + bins_u - 1) % bins_u + j * bins_u,
                (i + 1) % bins_u + j * bins_u,
                k.saturating_sub(bins_u),
                (k + bins_u).min(bins_u * bins_v - 1),
            ];
            let on_edge = neighbours
                .iter()
                .any(|&q| (coarse[q] > 0.0) != (coarse[k] > 0.0));
            let mass = if coarse[k] > 0.01 || on_edge {
                bin_mass(i, j, 160)
            } else {
                coarse[k]
            };
            expected[k] = mass * n as f64;
        }
    }
    let (mut chi2, mut dof, mut pool_o, mut pool_e) = (0.0, 0.0, 0.0, 0.0);
    for (o, e) in observed.iter().zip(&expected) {
        if *e < 5.0 {
            pool_o += o;
            pool_e += e;
        } else {
            chi2 += (o - e).powi(2) / e;
            dof += 1.0;
        }
    }
    if pool_e > 0.0 {
        chi2 += (pool_o - pool_e).powi(2) / pool_e.max(5.0);
        dof += 1.0;
    }
    chi_square_z(chi2, dof - 1.0)
}

#[test]
fn visible_normal_sampler_matches_its_density() {
    let mut seed = 7;
    for ndf in KINDS {
        for (ax, ay) in [(0.08, 0.08), (0.4, 0.4), (1.3, 1.3), (0.15, 0.7)] {
            for w in [
                unit(0.0, 0.0),
                unit(35.0, 60.0),
                unit(80.0, 200.0),
                unit(120.0, 30.0),
                unit(170.0, 300.0),
            ] {
                seed += 1;
                let mf = Microfacet::new(ndf, ax, ay);
                if mf.projected_area(w) < 1e-12 {
                    continue; // nothing visible in f64 (Beckmann 0.08 from 170 deg: A ~ exp(-5000))
                }
                let z = chi_square_of_sampler(mf, w, seed);
                // 40 tests: z < 4.0 keeps the family-wise false alarm rate near 1e-3.
                assert!(z < 4.0, "{ndf:?} {ax},{ay} w {w:?}: chi-square z = {z:.2}");
            }
        }
    }
}

#[test]
fn chi_square_rejects_a_wrong_sampler() {
    // The test above must be able to fail: sampling alpha 0.4 but checking against alpha 0.44.
    let sampled = Microfacet::new(NdfKind::Ggx, 0.4, 0.4);
    let claimed = Microfacet::new(NdfKind::Ggx, 0.44, 0.44);
    let w = unit(35.0, 60.0);
    let (bins, n) = (20usize, 200_000usize);
    let mut rng = Rng::seed_from_u64(3);
    let mut obs = vec![0.0; bins];
    for _ in 0..n {
        let m = sampled.sample_visible(w, [rng.random(), rng.random()]);
        let (_, v) = unwarp(0.4, m);
        obs[((v * bins as f64) as usize).min(bins - 1)] += 1.0;
    }
    let mut chi2 = 0.0;
    for (j, o) in obs.iter().enumerate() {
        let e = integrate_hemisphere(0.4, 64, 64, |m| {
            let (_, v) = unwarp(0.4, m);
            if ((v * bins as f64) as usize).min(bins - 1) == j {
                claimed.pdf_visible(w, m)
            } else {
                0.0
            }
        }) * n as f64;
        chi2 += (o - e).powi(2) / e.max(1.0);
    }
    assert!(chi_square_z(chi2, bins as f64 - 1.0) > 10.0);
}

#[test]
fn dual_numbers_give_the_derivative_of_the_kernel() {
    // d/d alpha of D, Lambda, the visible-normal pdf and of a sampled normal, against central
    // differences of the f64 kernel.
    for ndf in KINDS {
        let wi = unit(50.0, 30.0);
        let m = unit(20.0, 200.0);
        let u = [0.37, 0.81];
        let alpha = 0.35;
        let h = 1e-6;
        let f = |a: f64| {
            let mf = Microfacet::new(ndf, a, a * 0.7);
            (
                mf.d(m),
                mf.lambda(wi),
                mf.pdf_visible(wi, m),
                mf.sample_visible(wi, u).x,
            )
        };
        let (p, q) = (f(alpha + h), f(alpha - h));
        let fd = [
            (p.0 - q.0) / (2.0 * h),
            (p.1 - q.1) / (2.0 * h),
            (p.2 - q.2) / (2.0 * h),
            (p.3 - q.3) / (2.0 * h),
        ];
        let a = Dual64::from_re(alpha).derivative();
        let mf = Microfacet::new(ndf, a, a * Dual64::from_re(0.7));
        let wi_d = Vec3::from_f64(wi.re());
        let m_d = Vec3::from_f64(m.re());
        let exact = [
            mf.d(m_d).eps,
            mf.lambda(wi_d).eps,
            mf.pdf_visible(wi_d, m_d).eps,
            mf.sample_visible(wi_d, u).x.eps,
        ];
        for (e, d) in exact.iter().zip(fd) {
            assert!(
                (e - d).abs() < 1e-6 * d.abs().max(1.0),
                "{ndf:?}: dual {exact:?} vs fd {fd:?}"
            );
        }
    }
}

#[test]
fn f32_kernel_agrees_with_f64() {
    for ndf in KINDS {
        let mf64 = Microfacet::new(ndf, 0.3, 0.5);
        let mf32 = Microfacet::new(ndf, 0.3f32, 0.5f32);
        for (wi, m) in [
            (unit(10.0, 5.0), unit(5.0, 100.0)),
            (unit(75.0, 40.0), unit(30.0, 220.0)),
        ] {
            let w32 = Vec3::new(wi.x as f32, wi.y as f32, wi.z as f32);
            let m32 = Vec3::new(m.x as f32, m.y as f32, m.z as f32);
            let rel = |a: f32, b: f64| ((a as f64 - b) / b).abs();
            assert!(rel(mf32.d(m32), mf64.d(m)) < 1e-5);
            assert!(rel(mf32.projected_area(w32), mf64.projected_area(wi)) < 1e-5);
        }
    }
}

#[test]
fn kernel_is_finite_at_grazing_and_extreme_roughness() {
    for ndf in KINDS {
        for a in [1e-4, 1e-2, 1.0, 3.0] {
            let mf = Microfacet::new(ndf, a, a);
            for w in [
                Vec3::new(1.0, 0.0, 0.0),
                unit(89.999, 10.0),
                unit(0.0, 0.0),
                unit(90.001, 0.0),
            ] {
                let area = mf.projected_area(w);
                assert!(
                    area.is_finite() && area > 0.0,
                    "{ndf:?} a {a} w {w:?}: {area}"
                );
                let m = mf.sample_visible(w, [0.3, 0.6]);
                assert!(m.re().iter().all(|v| v.is_finite()));
                assert!(mf.d(m).is_finite() && mf.pdf_visible(w, m).is_finite());
            }
        }
    }
}
