//! Pieces shared by the two position-free random walks on the height-correlated Smith
//! microsurface, [`super::bitterli`] and [`super::cui`]: the signed extinction of a direction,
//! one scattering step of the microflake phase function, the connection of a vertex to a fixed
//! exit direction, the approximate density reported for multiple importance sampling, and the
//! Russian roulette rule. Both walks use the flow-of-light convention of the papers:
//! `d0 = -wi`, ..., `dk = wo`.
//!
//! | quantity | formula | reference |
//! | --- | --- | --- |
//! | extinction per unit of optical depth | `sigma(d) = |Lambda(d)|` with the full-sphere Lambda, i.e. `Lambda(d)` upward and `1 + Lambda(-d)` downward | Bitterli & d'Eon 2022 eq. 24-25 (Dupuy et al. 2016) |
//! | signed extinction (Cui's `Lambda_k`) | `+sigma` upward, `-sigma` downward | Cui et al. 2023 supp. Alg. 1 |
//! | phase function | `rho(d -> d') = F((-d).h) D_{-d}(h) / (4 (-d).h) = F D(h) / (4 A(-d))`, `h = normalize(-d + d')` | Heitz et al. 2016 eq. 8; Cui supp. eq. 4 |
//! | vertex term | `v(d -> d') = F D(h) / (4 |d.z|) = rho |Lambda(d)|` | Wang et al. 2022 eq. 2 |
//!
//! `A(w)` is [`Microfacet::projected_area`]; `A(-d) = |d.z| |Lambda(d)|` for every `d`.

use super::roulette::piecewise_constant;
use super::single::SingleBounce;
use super::BrdfSample;
use crate::microfacet::{Fresnel, Microfacet};
use crate::scalar::{Real, Vec3};
use std::f64::consts::FRAC_1_PI;

/// Safety cap on the number of reflections of one walk. A walk on a conservative surface leaves
/// after a few bounces (the optical depth drifts upward), so the cap is never reached in
/// practice; reaching it drops the path (a bias below 1e-12 in every configuration tested).
/// A [`super::BounceCap`] lowers it.
pub(crate) const MAX_WALK_BOUNCES: u32 = 1024;

/// Cui's signed Lambda of a flow direction: `+|Lambda(d)|` upward, `-|Lambda(d)|` downward, where
/// `|Lambda(d)| = A(-d) / |d.z|` is the extinction per unit optical depth along `d`. Infinite for
/// an exactly horizontal `d`.
#[inline]
pub(crate) fn signed_lambda<T: Real>(mf: &Microfacet<T>, d: Vec3<T>) -> T {
    let z = d.z.abs();
    let zl = mf.z_lambda(d);
    if d.z.re64() > 0.0 {
        zl / z
    } else {
        -(z + zl) / z
    }
}

/// One reflection of the walk: the next flow direction, the Fresnel factor of the reflection
/// and the microfacet normal that produced it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Scatter<T> {
    pub d: Vec3<T>,
    pub fresnel: [T; 3],
    pub m: Vec3<T>,
}

/// Sample `d' ~ rho(d -> .) / F` exactly (visible normals of `-d`, which may point below the
/// horizon, then mirror reflection). `rho / pdf = F`; `None` when the normal is not visible
/// (a rounding corner). With dual numbers the direction carries its pathwise derivative.
#[inline]
pub(crate) fn scatter<T: Real>(
    mf: &Microfacet<T>,
    fresnel: &Fresnel<T>,
    d: Vec3<T>,
    u: [f64; 2],
) -> Option<Scatter<T>> {
    let w = -d;
    let m = mf.sample_visible(w, u);
    let c = w.dot(m);
    if c.re64() <= 0.0 || !c.re64().is_finite() {
        return None;
    }
    let next = w.reflect(m).normalize();
    Some(Scatter {
        d: next,
        fresnel: fresnel.eval(c).0,
        m,
    })
}

/// The reflection at a vertex reached along `d` that leaves along the fixed direction `out`:
/// the half vector `h = normalize(-d + out)` and the cosine `(-d).h`, when the reflection exists
/// (`h` above the macro-surface and seen from `-d`).
#[inline]
pub(crate) fn connect<T: Real>(d: Vec3<T>, out: Vec3<T>) -> Option<(Vec3<T>, T)> {
    let sum = out - d;
    let len = sum.length();
    if len.re64().is_nan() || len.re64() <= 1e-300 {
        return None;
    }
    let h = sum * len.recip();
    let c = -d.dot(h);
    if h.z.re64() <= 0.0 || c.re64() <= 0.0 {
        return None;
    }
    Some((h, c))
}

/// Russian roulette from the energy still in the surface (Bitterli & d'Eon 2022 sec. 6.1.3):
/// survive with probability `min(1, max(throughput) * mass)`, where `mass` is the probability
/// that the next collision happens, rounded down to four significant bits so that it is
/// piecewise constant in the parameters ([`super::roulette`]: unbiased pathwise derivatives).
/// With white Fresnel this kills a walk with nearly the conditional probability that the
/// analog photon had left, so the surviving weight stays near 1. Takes real parts: the
/// decision is fixed by the random numbers.
#[inline]
pub(crate) fn survival(throughput: [f64; 3], mass: f64) -> f64 {
    let t = throughput[0].max(throughput[1]).max(throughput[2]);
    piecewise_constant(t * mass)
}

/// Density reported with a sampled direction for multiple importance sampling (approximate):
/// the exact density of the single-bounce paths of the exact walk (`f_single(F = 1) wo.z`) plus
/// a cosine lobe carrying a heuristic estimate of the energy of longer paths,
/// `1 - (1 - l0)(1 - lg)` with `l0 = 0.4 a^2 / (1 + a^2)` (normal incidence, `a^2 = ax ay`) and
/// `lg = Lambda(wi) / (1 + 2 Lambda(wi))` (grazing). It is positive wherever a walk can leave,
/// cheap, and deterministic; it is not the exact density of the multiple-bounce sampler (which
/// has no closed form). Balance-heuristic weights built on it still sum to one, so MIS stays
/// unbiased.
pub(crate) fn mis_pdf(white_single: &SingleBounce<f64>, wi: Vec3<f64>, wo: Vec3<f64>) -> f64 {
    if wi.z <= 0.0 || wo.z <= 0.0 {
        return 0.0;
    }
    let mf = &white_single.microfacet;
    let single = white_single.eval(wi, wo).0[0] * wo.z;
    let a2 = mf.ax * mf.ay;
    let l0 = 0.4 * a2 / (1.0 + a2);
    let lam = mf.z_lambda(wi) / wi.z;
    let lg = if lam.is_finite() {
        lam / (1.0 + 2.0 * lam)
    } else {
        0.5
    };
    let multi = 1.0 - (1.0 - l0) * (1.0 - lg);
    let p = single + multi * wo.z * FRAC_1_PI;
    if p.is_finite() {
        p
    } else {
        0.0
    }
}

/// The sample of a walk that left along `wo` with `weight` after `bounces` reflections, with the
/// MIS density of [`mis_pdf`]; `None` when it left below the horizon or with a non-finite weight.
pub(crate) fn walk_sample(
    white_single: &SingleBounce<f64>,
    wi: Vec3<f64>,
    path: Option<(Vec3<f64>, [f64; 3], u32)>,
) -> Option<BrdfSample> {
    let (wo, weight, bounces) = path?;
    if wo.z <= 0.0 || !weight.iter().all(|w| w.is_finite()) {
        return None;
    }
    Some(BrdfSample {
        wo,
        weight,
        pdf: mis_pdf(white_single, wi, wo),
        bounces,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::testing::unit;
    use crate::microfacet::NdfKind;

    #[test]
    fn signed_lambda_is_the_full_sphere_extinction() {
        for ndf in [NdfKind::Ggx, NdfKind::Beckmann] {
            let mf = Microfacet::new(ndf, 0.4, 0.7);
            for (t, p) in [(10.0, 20.0), (45.0, 200.0), (80.0, 300.0), (0.0, 0.0)] {
                let up = unit(t, p);
                let down = -up;
                assert!((signed_lambda(&mf, up) - mf.lambda(up)).abs() < 1e-14);
                // Downward: |Lambda(d)| = 1 + Lambda(-d) (Heitz et al. 2016 sec. 2.2).
                assert!((signed_lambda(&mf, down) + 1.0 + mf.lambda(up)).abs() < 1e-13);
                assert!((signed_lambda(&mf, down).abs() - mf.lambda(down).abs()).abs() < 1e-13);
                // A(-d) = |d.z| |Lambda(d)|.
                for d in [up, down] {
                    let a = mf.projected_area(-d);
                    assert!((a - d.z.abs() * signed_lambda(&mf, d).abs()).abs() < 1e-13);
                }
            }
        }
    }
}

/// Test helpers shared by the `bitterli` and `cui` test modules.
#[cfg(test)]
pub(crate) mod checks {
    use crate::bsdf::single::SingleBounce;
    use crate::bsdf::testing::{albedo_by_eval, albedo_by_sampling, unit};
    use crate::bsdf::Brdf;
    use crate::microfacet::{Fresnel, Height, Microfacet, NdfKind};
    use crate::random::Estimate;

    /// One row of the white furnace table.
    #[derive(Debug)]
    pub struct FurnaceRow {
        pub ndf: NdfKind,
        pub alpha: f64,
        pub theta: f64,
        pub by_sampling: Estimate,
        pub by_eval: Estimate,
    }

    /// Standard error aimed at by [`furnace`] (the assertion allows 3e-3).
    const TARGET_STDERR: f64 = 2.7e-3;

    /// White furnace over the configurations of the issue: both NDFs, alpha in
    /// {0.1, 0.3, 0.6, 1.0, 1.5}, incidence 0, 30, 60, 80 degrees. `make` builds the model.
    /// The estimate by evaluation uses `n_eval` evaluations, and when its standard error is
    /// above [`TARGET_STDERR`] it is replaced by an independent run sized from the measured
    /// variance (the harness's one-sample MIS of the guide and the cosine lobe has a per-sample
    /// standard deviation near 1 at alpha 0.1 and 1.5, whatever the model).
    pub fn furnace(
        make: &dyn Fn(Microfacet<f64>) -> Box<dyn Brdf>,
        n_sampling: usize,
        n_eval: usize,
        seed: u64,
    ) -> Vec<FurnaceRow> {
        let mut rows = Vec::new();
        for ndf in [NdfKind::Ggx, NdfKind::Beckmann] {
            for alpha in [0.1, 0.3, 0.6, 1.0, 1.5] {
                let mf = Microfacet::new(ndf, alpha, alpha);
                let model = make(mf);
                let guide = SingleBounce {
                    microfacet: mf,
                    fresnel: Fresnel::White,
                    height: Height::Correlated,
                };
                for theta in [0.0, 30.0, 60.0, 80.0] {
                    let wi = unit(theta, 25.0);
                    let k = rows.len() as u64;
                    let mut by_eval = albedo_by_eval(&*model, &guide, wi, n_eval, seed + 3 * k);
                    // Heavy tails (cui at low roughness) can under-report the variance of the
                    // first run: size again from each new measurement, up to three times.
                    let mut n = n_eval;
                    for retry in 0..3u64 {
                        let se = by_eval.stderr[0];
                        if se <= TARGET_STDERR {
                            break;
                        }
                        n = (n as f64 * 1.3 * (se / TARGET_STDERR).powi(2)).ceil() as usize;
                        by_eval =
                            albedo_by_eval(&*model, &guide, wi, n, seed + 3 * k + 1 + 1000 * retry);
                    }
                    rows.push(FurnaceRow {
                        ndf,
                        alpha,
                        theta,
                        by_sampling: albedo_by_sampling(&*model, wi, n_sampling, seed + 3 * k + 2),
                        by_eval,
                    });
                }
            }
        }
        rows
    }

    /// Print the table and assert: every estimate within 1% of 1 and within 3 of its standard
    /// errors, with a standard error of at most 0.3%.
    pub fn assert_furnace(name: &str, rows: &[FurnaceRow]) {
        eprintln!("{name} white furnace (mean +- standard error, channel 0)");
        eprintln!("| ndf | alpha | theta | by sampling | by eval | evaluations |");
        eprintln!("| --- | --- | --- | --- | --- | --- |");
        for r in rows {
            eprintln!(
                "| {} | {} | {} | {:.5} +- {:.5} | {:.5} +- {:.5} | {} |",
                r.ndf.name(),
                r.alpha,
                r.theta,
                r.by_sampling.value[0],
                r.by_sampling.stderr[0],
                r.by_eval.value[0],
                r.by_eval.stderr[0],
                r.by_eval.samples
            );
        }
        for r in rows {
            for (how, e) in [("sampling", &r.by_sampling), ("eval", &r.by_eval)] {
                let (v, se) = (e.value[0], e.stderr[0]);
                assert!(
                    (v - 1.0).abs() < 0.01 && (v - 1.0).abs() <= 3.0 * se.max(1e-12) && se <= 3e-3,
                    "{name} {:?} alpha {} theta {} by {how}: {v} +- {se}",
                    r.ndf,
                    r.alpha,
                    r.theta
                );
            }
        }
    }
}
