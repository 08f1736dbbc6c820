//! The numerical stress sweep behind `bouncefit stress` (issue #6): every model over the corners
//! of its input space, counting the values a fitter cannot survive.
//!
//! | axis | values (full sweep; `--quick` keeps a subset) |
//! | --- | --- |
//! | distribution | GGX, Beckmann |
//! | roughness | isotropic 1e-4 .. 3; anisotropic ratios 10 and 100 (both orientations) |
//! | height | correlated, uncorrelated (models built on `single`) |
//! | Fresnel | white, Schlick copper, conductors eta 0.01 .. 10 with k 0 .. 20, dielectrics eta 0.5 .. 10 |
//! | directions | theta 0 .. 89.99 deg and exactly grazing (z = 0), backscatter, mirror and side azimuths, and just below the horizon |
//! | samples | stochastic models average 1, 2, 4, 8, 16 or 64 estimates, cycling over the queries |
//!
//! For every query the sweep evaluates `f` (single and multiple parts), draws from the sampler
//! and evaluates its density, and counts NaN, infinite and negative numbers among all of them.
//! Below the horizon the models must return zero, not an error: a grazing record of a photo can
//! land there after rounding.
//!
//! Two more measurements per model:
//! - **Energy.** The white-Fresnel directional albedo ([`crate::albedo`]) at every roughness of
//!   the sweep and incidence up to 89.99 deg; a violation is an albedo above `1 + 3 se` (for the
//!   analytic models `se` is the quadrature error estimate, for the stochastic ones the standard
//!   error of the mean; 1e-9 more for rounding, as an estimator whose every sample weighs exactly
//!   1 has `se = 0`).
//! - **Deviation from a high-precision evaluation.** Stochastic models: the mean of the query's
//!   sample count against a reference mean of many more samples (f64) on every
//!   [`REFERENCE_STRIDE`]-th query, as a relative deviation (where the reference is resolved to
//!   2%) and as a z-score against both standard errors, which is what exposes a bias. Analytic
//!   models have no sampling error, so their reference is the same formula in f64 and the
//!   tested value the f32 evaluation: the deviation shows where a formula loses precision.
//!
//! The models a fit renders through the batch kernel (`single`, `turquin`) also run their
//! surfaces through it ([`batch`]): bad numbers in its values and tangents, and its worst
//! deviation from this sweep's scalar kernel.

pub mod batch;

use crate::render::batch::Precision;

use crate::albedo::{directional_albedo, mean_value, Adjoint};

use crate::bsdf::registry::differentiable;
use crate::bsdf::{BounceCap, Brdf, Model};
use crate::material::{FresnelSpec, Material};
use crate::microfacet::{Height, NdfKind};
use crate::random::rng_stream;
use crate::scalar::Vec3;
use rayon::prelude::*;
use serde::Serialize;

/// Every `REFERENCE_STRIDE`-th query of a stochastic model also gets a many-sample reference.
pub const REFERENCE_STRIDE: usize = 16;
/// Sample counts the stochastic queries cycle through.
const SAMPLE_COUNTS: [usize; 6] = [1, 2, 4, 8, 16, 64];
/// Values below this (1/sr) are compared absolutely: f32 underflows long before them and no
/// photo can see them.
const RELATIVE_FLOOR: f64 = 1e-6;

/// Albedo above 1 that is only rounding (sums of weights that are exactly 1).
const ROUNDING: f64 = 1e-9;

/// How much of the sweep to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SweepSize {
    /// Every axis value listed in the module table.
    Full,
    /// A subset of every axis (each corner kept), for a run under a minute.
    Quick,
}

impl SweepSize {
    fn reference_samples(self) -> usize {
        match self {
            SweepSize::Full => 4096,
            SweepSize::Quick => 1024,
        }
    }
    fn albedo_samples(self) -> usize {
        match self {
            SweepSize::Full => 16_384,
            SweepSize::Quick => 4096,
        }
    }
}

/// One material of the sweep, without its model.
#[derive(Clone, Copy, Debug)]
struct Surface {
    ndf: NdfKind,
    height: Height,
    alpha: [f64; 2],
    fresnel: FresnelSpec,
}

impl Surface {
    fn material(&self, model: Model) -> Material {
        Material {
            model,
            ndf: self.ndf,
            height: self.height,
            alpha: self.alpha,
            fresnel: self.fresnel,
            diffuse: [0.0; 3],
        }
    }
}

/// One query: a surface, a pair of directions and a sample count.
#[derive(Clone, Copy, Debug)]
struct Query {
    surface: Surface,
    wi: Vec3<f64>,
    wo: Vec3<f64>,
    samples: usize,
}

impl Query {
    fn describe(&self, model: Model) -> String {
        let s = &self.surface;
        format!(
            "{model} {} {} alpha=({:e}, {:e}) fresnel={} wi=({:.6}, {:.6}, {:.6e}) wo=({:.6}, {:.6}, {:.6e}) samples={}",
            s.ndf.name(),
            s.height.name(),
            s.alpha[0],
            s.alpha[1],
            fresnel_label(&s.fresnel),
            self.wi.x,
            self.wi.y,
            self.wi.z,
            self.wo.x,
            self.wo.y,
            self.wo.z,
            self.samples
        )
    }
}

fn fresnel_label(f: &FresnelSpec) -> String {
    match f {
        FresnelSpec::White => "white".into(),
        FresnelSpec::Schlick { f0 } => format!("schlick:{},{},{}", f0[0], f0[1], f0[2]),
        FresnelSpec::Conductor { eta, k } => format!("conductor:{}:{}", eta[0], k[0]),
        FresnelSpec::Dielectric { eta } => format!("dielectric:{eta}"),
    }
}

/// The result of the sweep for one model (the `--json` contract of issue #6 plus context).
#[derive(Clone, Debug, Serialize)]
pub struct ModelReport {
    pub model: Model,
    /// Queries evaluated (each: one `f`, one sample, one pdf).
    pub queries: usize,
    /// Numbers returned that were NaN, infinite or negative (values, weights, densities).
    pub nan: usize,
    pub inf: usize,
    pub negative: usize,
    /// The first query that produced each kind of bad number, to reproduce it with `brdf`.
    pub first_bad: Option<String>,
    /// White-Fresnel albedos above `1 + 3 se`, out of `energy_checks`.
    pub energy_violations: usize,
    pub energy_checks: usize,
    /// Every violation: `albedo +- se at <surface and incidence>`.
    pub energy_violations_at: Vec<String>,
    /// The largest white-Fresnel albedo seen, with its standard error and where.
    pub max_albedo: f64,
    pub max_albedo_stderr: f64,
    pub max_albedo_at: String,
    /// Share of paths that took a numerical fallback (`bitterli`); zero for the others.
    pub fallback_rate: f64,
    /// Worst relative deviation from the high-precision evaluation (see the module doc).
    pub worst_rel_dev: f64,
    pub worst_rel_dev_at: String,
    /// Stochastic models: worst deviation from the reference in standard errors, and where.
    pub worst_z: Option<f64>,
    pub worst_z_at: Option<String>,
    /// What the deviation compares.
    pub reference: String,
    /// The batch kernel's sweep in each lane precision, for the models it serves
    /// ([`crate::bsdf::registry::Capabilities::batch`]); empty for the others.
    pub batch: Vec<batch::BatchReport>,
    pub seconds: f64,
}

impl ModelReport {
    /// NaN, infinite and negative numbers of the scalar sweep, and the batch kernel's bad
    /// values and non-finite tangents.
    pub fn bad_numbers(&self) -> usize {
        self.nan
            + self.inf
            + self.negative
            + self.batch.iter().map(|b| b.bad_numbers()).sum::<usize>()
    }
}

/// The surfaces of the sweep.
fn surfaces(size: SweepSize, model: Model) -> Vec<Surface> {
    let iso: &[f64] = match size {
        SweepSize::Full => &[1e-4, 1e-3, 1e-2, 0.1, 0.3, 0.7, 1.5, 3.0],
        SweepSize::Quick => &[1e-4, 0.1, 0.7, 3.0],
    };
    let aniso: &[[f64; 2]] = match size {
        SweepSize::Full => &[
            [1e-2, 1e-4],
            [1e-4, 1e-2],
            [0.1, 1e-3],
            [1.0, 0.1],
            [3.0, 0.03],
            [0.03, 3.0],
        ],
        SweepSize::Quick => &[[1e-2, 1e-4], [3.0, 0.03]],
    };
    let fresnels: Vec<FresnelSpec> = {
        let conductor = |eta: f64, k: f64| FresnelSpec::Conductor {
            eta: [eta; 3],
            k: [k; 3],
        };
        let mut all = vec![
            FresnelSpec::White,
            FresnelSpec::Schlick {
                f0: [0.955, 0.638, 0.538],
            },
            conductor(0.01, 0.0),
            conductor(0.01, 20.0),
            conductor(10.0, 0.0),
            conductor(10.0, 20.0),
            FresnelSpec::Dielectric { eta: 1.0001 },
            FresnelSpec::Dielectric { eta: 10.0 },
        ];
        if size == SweepSize::Full {
            all.extend([
                conductor(0.2, 3.6),
                conductor(1.0, 0.0),
                FresnelSpec::Dielectric { eta: 1.5 },
                FresnelSpec::Dielectric { eta: 0.5 },
            ]);
        }
        all
    };
    // `heitz`'s first order is the height-correlated single bounce whatever the setting.
    let heights: &[Height] = if model.capabilities().explicit_heights {
        &[Height::Correlated]
    } else {
        &[Height::Correlated, Height::Uncorrelated]
    };
    let mut out = Vec::new();
    for ndf in [NdfKind::Ggx, NdfKind::Beckmann] {
        for &height in heights {
            for alpha in iso.iter().map(|&a| [a, a]).chain(aniso.iter().copied()) {
                for &fresnel in &fresnels {
                    out.push(Surface {
                        ndf,
                        height,
                        alpha,
                        fresnel,
                    });
                }
            }
        }
    }
    out
}

/// Direction at polar angle `theta_deg` and azimuth `phi_deg`; 90 deg is exactly grazing.
fn direction(theta_deg: f64, phi_deg: f64) -> Vec3<f64> {
    let (st, ct) = if theta_deg == 90.0 {
        (1.0, 0.0)
    } else {
        let t = theta_deg.to_radians();
        (t.sin(), t.cos())
    };
    let p = phi_deg.to_radians();
    Vec3::new(st * p.cos(), st * p.sin(), ct)
}

/// Pairs of directions: `wi` at azimuth 0; `wo` in the backscatter (0), side (90) and mirror
/// (180) azimuths, so equal polar angles give both `wo = wi` and the exact specular peak (and
/// the equal-Lambda case of Bitterli's recurrences); plus both directions just below the horizon.
fn direction_pairs(size: SweepSize) -> Vec<(Vec3<f64>, Vec3<f64>)> {
    let thetas: &[f64] = match size {
        SweepSize::Full => &[0.0, 30.0, 60.0, 80.0, 89.0, 89.99, 90.0],
        SweepSize::Quick => &[0.0, 60.0, 89.99, 90.0],
    };
    let mut pairs = Vec::new();
    for &ti in thetas {
        for &to in thetas {
            for phi in [0.0, 90.0, 180.0] {
                pairs.push((direction(ti, 0.0), direction(to, phi)));
            }
        }
    }
    let below = Vec3::new(0.6, 0.0, -1e-7).normalize();
    let above = direction(45.0, 180.0);
    pairs.push((above, below));
    pairs.push((below, above));
    pairs
}

fn queries(size: SweepSize, model: Model, stochastic: bool) -> Vec<Query> {
    let pairs = direction_pairs(size);
    let mut out = Vec::new();
    for surface in surfaces(size, model) {
        for &(wi, wo) in &pairs {
            let samples = if stochastic {
                SAMPLE_COUNTS[out.len() % SAMPLE_COUNTS.len()]
            } else {
                1
            };
            out.push(Query {
                surface,
                wi,
                wo,
                samples,
            });
        }
    }
    out
}

/// Counts of bad numbers over a set of queries, with the first offending query.
#[derive(Clone, Debug, Default)]
struct Tally {
    nan: usize,
    inf: usize,
    negative: usize,
    first_bad: Option<String>,
    /// Worst relative deviation and where (index of the query).
    worst_rel_dev: (f64, usize),
    worst_z: (f64, usize),
    fallbacks: u64,
    paths: u64,
}

impl Tally {
    /// Count `v` and remember `what` if it is the first bad number.
    fn check(&mut self, v: f64, what: impl FnOnce() -> String) {
        let bad = if v.is_nan() {
            self.nan += 1;
            true
        } else if v.is_infinite() {
            self.inf += 1;
            true
        } else if v < 0.0 {
            self.negative += 1;
            true
        } else {
            false
        };
        if bad && self.first_bad.is_none() {
            self.first_bad = Some(format!("{} = {v:e}", what()));
        }
    }

    fn merge(mut self, other: Tally) -> Tally {
        self.nan += other.nan;
        self.inf += other.inf;
        self.negative += other.negative;
        self.first_bad = self.first_bad.or(other.first_bad);
        if other.worst_rel_dev.0 > self.worst_rel_dev.0 {
            self.worst_rel_dev = other.worst_rel_dev;
        }
        if other.worst_z.0 > self.worst_z.0 {
            self.worst_z = other.worst_z;
        }
        self.fallbacks += other.fallbacks;
        self.paths += other.paths;
        self
    }
}

fn relative_deviation(value: f64, reference: f64) -> f64 {
    (value - reference).abs() / reference.abs().max(RELATIVE_FLOOR)
}

/// Evaluate one query of `model` and tally what it returns.
#[allow(clippy::needless_range_loop)] // the channel loop reads three parallel arrays
fn run_query(model: Model, size: SweepSize, index: usize, q: &Query, seed: u64) -> Tally {
    let material = q.surface.material(model);
    let brdf = material.brdf();
    let mut rng = rng_stream(seed, index as u64);
    let mut tally = Tally::default();
    let describe = || q.describe(model);

    let mut sum = [0.0; 3];
    for _ in 0..q.samples {
        let v = brdf.eval(q.wi, q.wo, &mut rng);
        for c in 0..3 {
            tally.check(v.single[c], || format!("{} f_single[{c}]", describe()));
            tally.check(v.multi[c], || format!("{} f_multi[{c}]", describe()));
            sum[c] += v.single[c] + v.multi[c];
        }
    }
    let value = sum.map(|s| s / q.samples as f64);

    let pdf = brdf.pdf(q.wi, q.wo);
    tally.check(pdf, || format!("{} pdf", describe()));
    if q.wi.z > 0.0 {
        let u = [0.5 + 0.49 * (index as f64 * 0.618_034).fract(), 0.999_999];
        for u in [u, [1.0 - u[0], 1e-9]] {
            if let Some(s) = brdf.sample(q.wi, u, &mut rng) {
                for c in 0..3 {
                    tally.check(s.weight[c], || {
                        format!("{} sample{u:?} weight[{c}]", describe())
                    });
                }
                tally.check(s.pdf, || format!("{} sample{u:?} pdf", describe()));
                tally.check(s.wo.z, || format!("{} sample{u:?} wo.z", describe()));
            }
        }
    }

    if brdf.is_stochastic() {
        if index % REFERENCE_STRIDE == 0 {
            let reference = mean_value(
                brdf.as_ref(),
                q.wi,
                q.wo,
                size.reference_samples(),
                &mut rng,
            );
            let (reference, ref_se) = (reference.value, reference.stderr);
            let estimate = mean_value(brdf.as_ref(), q.wi, q.wo, 64, &mut rng);
            let (mean, se) = (estimate.value, estimate.stderr);
            for c in 0..3 {
                if ref_se[c] <= 0.02 * reference[c].abs() {
                    let dev = relative_deviation(mean[c], reference[c]);
                    if dev > tally.worst_rel_dev.0 {
                        tally.worst_rel_dev = (dev, index);
                    }
                }
                let combined = (se[c] * se[c] + ref_se[c] * ref_se[c]).sqrt();
                if combined > 0.0 && combined.is_finite() {
                    let z = (mean[c] - reference[c]).abs() / combined;
                    if z > tally.worst_z.0 {
                        tally.worst_z = (z, index);
                    }
                }
            }
        }
        if let Some((fallbacks, paths)) = brdf.fallback_stats() {
            tally.fallbacks += fallbacks;
            tally.paths += paths;
        }
    } else if let Some(low) =
        differentiable::<f32>(model, material.single::<f32>(), BounceCap::NONE)
    {
        let to32 = |w: Vec3<f64>| Vec3::new(w.x as f32, w.y as f32, w.z as f32);
        let v32 = low.eval_total(to32(q.wi), to32(q.wo), &mut rng).0;
        for c in 0..3 {
            let dev = relative_deviation(f64::from(v32[c]), value[c]);
            if dev > tally.worst_rel_dev.0 {
                tally.worst_rel_dev = (dev, index);
            }
        }
    }
    tally
}

/// White-Fresnel albedo at every roughness of the sweep and incidence up to 89.99 deg:
/// `(albedo, se, where)` per check, over `wo` (or over `wi`, see
/// [`crate::bsdf::registry::Capabilities::conserves_toward_view`]).
fn energy(model: Model, size: SweepSize, seed: u64) -> Vec<(f64, f64, String)> {
    let thetas = [0.0, 45.0, 80.0, 89.0, 89.99];
    let cases: Vec<(Surface, f64)> = surfaces(size, model)
        .into_iter()
        .filter(|s| s.fresnel == FresnelSpec::White)
        .flat_map(|s| thetas.map(|t| (s, t)))
        .collect();
    cases
        .par_iter()
        .enumerate()
        .map(|(i, (surface, theta))| {
            let brdf = surface.material(model).brdf();
            let adjoint;
            let integrand: &dyn Brdf = if model.capabilities().conserves_toward_view {
                adjoint = Adjoint(brdf.as_ref());
                &adjoint
            } else {
                brdf.as_ref()
            };
            let est = directional_albedo(
                integrand,
                direction(*theta, 0.0),
                size.albedo_samples(),
                seed ^ (i as u64).wrapping_mul(0x9E37_79B9),
            );
            let at = format!(
                "{} {} alpha=({:e}, {:e}) theta_{}={theta}",
                surface.ndf.name(),
                surface.height.name(),
                surface.alpha[0],
                surface.alpha[1],
                if model.capabilities().conserves_toward_view {
                    "o"
                } else {
                    "i"
                }
            );
            (est.value[0], est.stderr[0], at)
        })
        .collect()
}

/// Run the sweep for `model`; `progress` is called with the number of queries done.
pub fn stress_model(
    model: Model,
    size: SweepSize,
    seed: u64,
    progress: impl Fn(usize) + Sync,
) -> ModelReport {
    let start = std::time::Instant::now();
    let stochastic = model.capabilities().stochastic();
    let qs = queries(size, model, stochastic);
    let done = std::sync::atomic::AtomicUsize::new(0);
    let tallies: Vec<Tally> = qs
        .par_iter()
        .enumerate()
        .map(|(i, q)| {
            let t = run_query(model, size, i, q, seed);
            let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            if n % 256 == 0 {
                progress(n);
            }
            t
        })
        .collect();
    let tally = tallies.into_iter().fold(Tally::default(), Tally::merge);
    let energy = energy(model, size, seed);
    let (max_albedo, max_albedo_stderr, max_albedo_at) = energy
        .iter()
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .cloned()
        .unwrap_or_default();
    let energy_violations_at: Vec<String> = energy
        .iter()
        .filter(|(e, se, _)| *e > 1.0 + 3.0 * se + ROUNDING)
        .map(|(e, se, at)| format!("{e:.5} +- {se:.1e} at {at}"))
        .collect();
    ModelReport {
        model,
        queries: qs.len(),
        nan: tally.nan,
        inf: tally.inf,
        negative: tally.negative,
        first_bad: tally.first_bad,
        energy_violations: energy_violations_at.len(),
        energy_checks: energy.len(),
        energy_violations_at,
        max_albedo,
        max_albedo_stderr,
        max_albedo_at,
        fallback_rate: if tally.paths > 0 {
            tally.fallbacks as f64 / tally.paths as f64
        } else {
            0.0
        },
        worst_rel_dev: tally.worst_rel_dev.0,
        worst_rel_dev_at: qs[tally.worst_rel_dev.1].describe(model),
        worst_z: stochastic.then_some(tally.worst_z.0),
        worst_z_at: stochastic.then(|| qs[tally.worst_z.1].describe(model)),
        reference: if stochastic {
            format!("64 samples vs {} samples, f64", size.reference_samples())
        } else {
            "f32 vs f64, same formula".into()
        },
        batch: if model.capabilities().batch.is_some() {
            [Precision::F32, Precision::F64]
                .map(|precision| batch::sweep(model, size, precision))
                .to_vec()
        } else {
            Vec::new()
        },
        seconds: start.elapsed().as_secs_f64(),
    }
}

/// The number of queries [`stress_model`] runs for `model` (for a progress bar).
pub fn query_count(model: Model, size: SweepSize) -> usize {
    surfaces(size, model).len() * direction_pairs(size).len()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tally_counts_each_kind_of_bad_number_and_keeps_the_first() {
        let mut t = Tally::default();
        for (k, v) in [1.0, f64::NAN, -0.0, f64::INFINITY, -1e-300, f64::NAN, 0.0]
            .into_iter()
            .enumerate()
        {
            t.check(v, || format!("value {k}"));
        }
        assert_eq!((t.nan, t.inf, t.negative), (2, 1, 1));
        assert_eq!(t.first_bad.as_deref(), Some("value 1 = NaN"));
        let merged = Tally::default().merge(t.clone()).merge(t);
        assert_eq!((merged.nan, merged.inf, merged.negative), (4, 2, 2));
    }

    /// The sweep reaches every corner it promises: exactly grazing and below-horizon pairs, the
    /// roughness ends, and an anisotropy ratio of 100.
    #[test]
    fn sweep_covers_the_corners() {
        let pairs = direction_pairs(SweepSize::Quick);
        assert!(pairs.iter().any(|(wi, wo)| wi.z == 0.0 && wo.z == 0.0));
        assert!(pairs.iter().any(|(_, wo)| wo.z < 0.0) && pairs.iter().any(|(wi, _)| wi.z < 0.0));
        let alphas: Vec<[f64; 2]> = surfaces(SweepSize::Quick, Model::Single)
            .iter()
            .map(|s| s.alpha)
            .collect();
        assert!(alphas.contains(&[1e-4, 1e-4]) && alphas.contains(&[3.0, 3.0]));
        assert!(alphas.iter().any(|a| (a[0] / a[1] - 100.0).abs() < 1e-9));
        assert_eq!(
            query_count(Model::Single, SweepSize::Quick),
            queries(SweepSize::Quick, Model::Single, false).len()
        );
    }

    /// `single` is finite, non-negative and gains no energy beyond quadrature error anywhere in the
    /// quick sweep, and
    /// its f32 evaluation stays within 1% of f64.
    #[test]
    fn single_passes_the_quick_sweep() {
        let r = stress_model(Model::Single, SweepSize::Quick, 1, |_| {});
        assert_eq!((r.nan, r.inf, r.negative), (0, 0, 0), "{:?}", r.first_bad);
        assert_eq!(r.energy_violations, 0, "{:?}", r.energy_violations_at);
        // Near-mirror surfaces keep almost all the energy; the upper bound is the count above.
        assert!(r.max_albedo > 0.99, "{}", r.max_albedo);
        assert!(
            r.worst_rel_dev < 1e-2,
            "{} at {}",
            r.worst_rel_dev,
            r.worst_rel_dev_at
        );
    }
}
