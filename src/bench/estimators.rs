//! Estimator measurements of `bouncefit bench` (issue #5 item 3): for every model and sample
//! count, time per evaluation and error, on one fixed set of configurations, against `heitz`
//! (Heitz et al. 2016, the reference) measured in the same run.
//!
//! | quantity | definition |
//! | --- | --- |
//! | configuration | GGX, height-correlated; `alpha` in [0.05, 1.5], `wi` and `wo` uniform in solid angle up to 85 deg from the normal (`wi` at azimuth 0, `wo` at any); copper conductor on even indices, white Fresnel on odd ones. Drawn from the Halton sequence in bases 2, 3, 5, 7 (Halton 1960) shifted modulo 1 by a seeded random vector (Cranley & Patterson 1976), so any count covers the 4-d box evenly |
//! | converged value | per configuration and channel, the mean of `reference_samples` evaluations (stochastic models; 1e5 in the full run) or the one value (analytic models) |
//! | `ns_per_eval` | CPU time of the calling thread per `eval` call (one core), over passes through every configuration repeated for at least `timing_seconds`; `ns_per_eval_wall` is the wall time of the same loop |
//! | `rmse` at n | `sqrt(mean(((mean of n evaluations - converged) / converged)^2))` over configurations, channels and `max(4, 256 / n)` repetitions on fresh random numbers; 0 up to rounding for analytic models |
//! | `rmse_vs_heitz` at n | the same error measured against converged `heitz` instead of the model's own value: noise and bias together |
//! | `bias_vs_heitz` | RMS over configurations and channels of `(converged - converged heitz) / converged heitz`; `bias_vs_heitz_mean` is the signed mean; `bias_vs_heitz_noise` the RMS of `sqrt(se^2 + se_heitz^2) / heitz`, what the two converged values' sampling noise alone gives. `heitz` itself is compared with a second, independent converged `heitz` |
//! | `inverse_efficiency_vs_heitz` at n | `(rmse^2 x ns_per_eval) / (rmse_heitz^2 x ns_per_eval_heitz)` at the same n: variance times time (Veach 1997, ch. 2: efficiency is 1 / (variance x time)); below 1 is better than `heitz`. Null for analytic models, whose variance is 0. The `_rough` variant keeps only configurations with alpha >= 0.5, where the position-free papers claim their gains |
//! | `relative_variance`, `inverse_efficiency_vs_heitz_from_reference` | the variance of one evaluation relative to the converged value squared, `samples x se^2 / converged^2`, averaged over configurations and channels, from the converged runs; and the same efficiency ratio computed with it. It does not depend on n and rests on `reference_samples` evaluations per configuration instead of 256, so it is the steadier estimate where rare large samples (heavy tails) make the per-n values jump |
//!
//! Errors are relative so that configurations of very different value weigh alike; a value
//! below [`RELATIVE_FLOOR`] is compared absolutely. Every model draws from its own random
//! streams (`rng_stream(seed, slot * configurations + configuration)`, one slot per model), so
//! its numbers do not depend on which other models run or on the thread count.

use super::cpu_time::thread_seconds;
use crate::albedo::mean_value;

use crate::bsdf::{Brdf, Model};
use crate::material::{FresnelSpec, Material};
use crate::microfacet::{Height, NdfKind};
use crate::random::{rng_stream, Estimate};
use crate::scalar::Vec3;
use rand::Rng as _;
use rayon::prelude::*;
use serde::Serialize;
use std::hint::black_box;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

/// Sample counts of the estimator table (issue #5 item 3).
pub const SAMPLE_COUNTS: [usize; 6] = [1, 2, 4, 8, 16, 64];
/// Roughness range of the configurations.
pub const ALPHA_RANGE: [f64; 2] = [0.05, 1.5];
/// Largest polar angle of `wi` and `wo`, degrees.
pub const MAX_THETA_DEG: f64 = 85.0;
/// Configurations at least this rough form the `_rough` subset.
pub const ROUGH_ALPHA: f64 = 0.5;
/// Copper, the conductor of `datasets/sources/copper-a03.material.json` (RGB eta and k).
pub const COPPER: FresnelSpec = FresnelSpec::Conductor {
    eta: [0.2378, 1.0066, 1.2404],
    k: [3.6264, 2.5823, 2.3929],
};
/// Relative errors divide by at least this (1/sr).
pub const RELATIVE_FLOOR: f64 = 1e-12;
/// Evaluations spent on the repetitions of each sample count (at least
/// [`MIN_REPETITIONS`] repetitions).
const REPETITION_EVALS: usize = 256;
const MIN_REPETITIONS: usize = 4;
/// Stream slot of the independent `heitz` reference (models use slots 1.. by `Model::ALL`).
const REFERENCE_SLOT: u64 = 0;

/// One configuration of the fixed set: a material without its model and a pair of directions.
#[derive(Clone, Copy, Debug)]
pub struct Configuration {
    pub alpha: f64,
    pub fresnel: FresnelSpec,
    pub wi: Vec3<f64>,
    pub wo: Vec3<f64>,
}

impl Configuration {
    pub fn material(&self, model: Model) -> Material {
        Material {
            model,
            ndf: NdfKind::Ggx,
            height: Height::Correlated,
            alpha: [self.alpha; 2],
            fresnel: self.fresnel,
            diffuse: [0.0; 3],
        }
    }

    /// `alpha=.. fresnel=.. wi=(..) wo=(..)`, enough to reproduce it with `bouncefit brdf`.
    pub fn describe(&self) -> String {
        let fresnel = if self.fresnel == FresnelSpec::White {
            "white"
        } else {
            "copper"
        };
        format!(
            "alpha={:.4} fresnel={fresnel} wi=({:.4},{:.4},{:.4}) wo=({:.4},{:.4},{:.4})",
            self.alpha, self.wi.x, self.wi.y, self.wi.z, self.wo.x, self.wo.y, self.wo.z
        )
    }
}

/// Bases of the Halton sequence, one per axis: alpha, `wi` polar, `wo` polar, `wo` azimuth.
const BASES: [u64; 4] = [2, 3, 5, 7];

/// The radical inverse of `k` in `base`: its digits mirrored about the point (van der Corput).
fn radical_inverse(mut k: u64, base: u64) -> f64 {
    let (mut value, mut scale) = (0.0, 1.0 / base as f64);
    while k > 0 {
        value += (k % base) as f64 * scale;
        k /= base;
        scale /= base as f64;
    }
    value
}

/// The `count` configurations of the run seeded by `seed` (see the module table).
pub fn configurations(count: usize, seed: u64) -> Vec<Configuration> {
    let mut rng = rng_stream(seed, u64::MAX);
    let shift: [f64; 4] = std::array::from_fn(|_| rng.random::<f64>());
    let min_cos = MAX_THETA_DEG.to_radians().cos();
    let direction = |u: f64, phi: f64| {
        let z = 1.0 - u * (1.0 - min_cos);
        let r = (1.0 - z * z).max(0.0).sqrt();
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    };
    (0..count)
        .map(|k| {
            let u: [f64; 4] = std::array::from_fn(|i| {
                (shift[i] + radical_inverse(k as u64 + 1, BASES[i])).fract()
            });
            Configuration {
                alpha: ALPHA_RANGE[0] + u[0] * (ALPHA_RANGE[1] - ALPHA_RANGE[0]),
                fresnel: if k % 2 == 0 {
                    COPPER
                } else {
                    FresnelSpec::White
                },
                wi: direction(u[1], 0.0),
                wo: direction(u[2], u[3] * std::f64::consts::TAU),
            }
        })
        .collect()
}

/// How much work the estimator part does.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct EstimatorSettings {
    pub configurations: usize,
    /// Evaluations behind each converged value of a stochastic model.
    pub reference_samples: usize,
    /// Least wall time of each model's timing loop.
    pub timing_seconds: f64,
    pub seed: u64,
}

/// One row of the estimator table (the `--json` contract of issue #5 plus context).
#[derive(Clone, Debug, Serialize)]
pub struct EstimatorRow {
    pub model: Model,
    pub samples: usize,
    pub stochastic: bool,
    pub ns_per_eval: f64,
    pub ns_per_eval_wall: f64,
    pub rmse: f64,
    /// `rmse` over the configurations with alpha >= 0.5 (`None` when there are none).
    pub rmse_rough: Option<f64>,
    pub rmse_vs_heitz: f64,
    pub bias_vs_heitz: f64,
    pub bias_vs_heitz_mean: f64,
    pub bias_vs_heitz_noise: f64,
    /// The configuration with the largest relative difference from `heitz`, and that difference.
    pub worst_bias_vs_heitz: f64,
    pub worst_bias_at: String,
    pub inverse_efficiency_vs_heitz: Option<f64>,
    pub inverse_efficiency_vs_heitz_rough: Option<f64>,
    pub relative_variance: f64,
    pub relative_variance_rough: Option<f64>,
    pub inverse_efficiency_vs_heitz_from_reference: Option<f64>,
    pub inverse_efficiency_vs_heitz_from_reference_rough: Option<f64>,
}

/// A running mean of squares (for RMS values).
#[derive(Clone, Copy, Debug, Default)]
struct MeanSquare {
    sum: f64,
    count: usize,
}

impl MeanSquare {
    fn add(&mut self, x: f64) {
        self.sum += x * x;
        self.count += 1;
    }
    fn merge(&mut self, other: MeanSquare) {
        self.sum += other.sum;
        self.count += other.count;
    }
    fn mean(&self) -> Option<f64> {
        (self.count > 0).then(|| self.sum / self.count as f64)
    }
}

fn relative(value: f64, reference: f64) -> f64 {
    (value - reference) / reference.abs().max(RELATIVE_FLOOR)
}

/// What one model measured on one configuration.
struct ConfigMeasure {
    converged: Estimate,
    /// Per sample count: squared relative errors against the own converged value and against
    /// converged `heitz`.
    own: [MeanSquare; SAMPLE_COUNTS.len()],
    vs_heitz: [MeanSquare; SAMPLE_COUNTS.len()],
}

fn measure_config(
    brdf: &dyn Brdf,
    config: &Configuration,
    reference_samples: usize,
    heitz: &Estimate,
    rng: &mut crate::random::Rng,
) -> ConfigMeasure {
    let (wi, wo) = (config.wi, config.wo);
    let converged = if brdf.is_stochastic() {
        mean_value(brdf, wi, wo, reference_samples, rng)
    } else {
        Estimate {
            value: brdf.eval(wi, wo, rng).total(),
            stderr: [0.0; 3],
            samples: 1,
        }
    };
    let mut own = [MeanSquare::default(); SAMPLE_COUNTS.len()];
    let mut vs_heitz = own;
    for (k, &n) in SAMPLE_COUNTS.iter().enumerate() {
        for _ in 0..(REPETITION_EVALS / n).max(MIN_REPETITIONS) {
            let mean = mean_value(brdf, wi, wo, n, rng).value;
            for ((m, own_value), heitz_value) in mean.iter().zip(converged.value).zip(heitz.value) {
                own[k].add(relative(*m, own_value));
                vs_heitz[k].add(relative(*m, heitz_value));
            }
        }
    }
    ConfigMeasure {
        converged,
        own,
        vs_heitz,
    }
}

/// Converged values of `model` on every configuration, or the full measurement against
/// `heitz` when given; `progress` counts finished configurations.
fn measure_model(
    model: Model,
    configs: &[Configuration],
    settings: &EstimatorSettings,
    slot: u64,
    heitz: &[Estimate],
    progress: &(impl Fn() + Sync),
) -> Vec<ConfigMeasure> {
    configs
        .par_iter()
        .zip(heitz)
        .enumerate()
        .map(|(i, (config, heitz))| {
            let brdf = config.material(model).brdf();
            let mut rng = rng_stream(settings.seed, slot * configs.len() as u64 + i as u64);
            let m = measure_config(
                brdf.as_ref(),
                config,
                settings.reference_samples,
                heitz,
                &mut rng,
            );
            progress();
            m
        })
        .collect()
}

/// The converged `heitz` values every model is compared with (its own stream slot).
fn heitz_reference(
    configs: &[Configuration],
    settings: &EstimatorSettings,
    progress: &(impl Fn() + Sync),
) -> Vec<Estimate> {
    configs
        .par_iter()
        .enumerate()
        .map(|(i, config)| {
            let brdf = config.material(Model::Heitz).brdf();
            let mut rng = rng_stream(
                settings.seed,
                REFERENCE_SLOT * configs.len() as u64 + i as u64,
            );
            let e = mean_value(
                brdf.as_ref(),
                config.wi,
                config.wo,
                settings.reference_samples,
                &mut rng,
            );
            progress();
            e
        })
        .collect()
}

/// `(thread CPU ns, wall ns)` per `eval` of `model`, on the calling thread: passes over every
/// configuration until `seconds` of wall time have gone by.
fn time_per_eval(model: Model, configs: &[Configuration], seconds: f64, seed: u64) -> (f64, f64) {
    let brdfs: Vec<Box<dyn Brdf>> = configs.iter().map(|c| c.material(model).brdf()).collect();
    let mut rng = rng_stream(seed, u64::MAX - 1);
    // One untimed pass builds anything computed on first use.
    for (brdf, c) in brdfs.iter().zip(configs) {
        black_box(brdf.eval(c.wi, c.wo, &mut rng));
    }
    let (wall, cpu) = (Instant::now(), thread_seconds());
    let mut evals = 0usize;
    while evals == 0 || wall.elapsed().as_secs_f64() < seconds {
        for (brdf, c) in brdfs.iter().zip(configs) {
            black_box(brdf.eval(black_box(c.wi), black_box(c.wo), &mut rng));
        }
        evals += configs.len();
    }
    let per = |s: f64| s * 1e9 / evals as f64;
    (
        per(thread_seconds() - cpu),
        per(wall.elapsed().as_secs_f64()),
    )
}

/// Everything measured of one model, before the comparison with `heitz`.
struct ModelMeasure {
    model: Model,
    stochastic: bool,
    ns_per_eval: f64,
    ns_per_eval_wall: f64,
    /// Per sample count: mean squared relative error, all configurations and rough ones.
    mse: [f64; SAMPLE_COUNTS.len()],
    mse_rough: [Option<f64>; SAMPLE_COUNTS.len()],
    mse_vs_heitz: [f64; SAMPLE_COUNTS.len()],
    /// Relative variance of one evaluation, all configurations and rough ones.
    variance: f64,
    variance_rough: Option<f64>,
    bias: f64,
    bias_mean: f64,
    bias_noise: f64,
    worst_bias: (f64, usize),
}

fn summarise(
    model: Model,
    configs: &[Configuration],
    per_config: &[ConfigMeasure],
    heitz: &[Estimate],
    timing: (f64, f64),
) -> ModelMeasure {
    let stochastic = !configs.is_empty() && model.capabilities().stochastic();
    let mut mse = [0.0; SAMPLE_COUNTS.len()];
    let mut mse_rough = [None; SAMPLE_COUNTS.len()];
    let mut mse_vs_heitz = [0.0; SAMPLE_COUNTS.len()];
    for k in 0..SAMPLE_COUNTS.len() {
        let [mut all, mut rough, mut vs_heitz] = [MeanSquare::default(); 3];
        for (config, m) in configs.iter().zip(per_config) {
            all.merge(m.own[k]);
            vs_heitz.merge(m.vs_heitz[k]);
            if config.alpha >= ROUGH_ALPHA {
                rough.merge(m.own[k]);
            }
        }
        mse[k] = all.mean().unwrap_or(0.0);
        mse_rough[k] = rough.mean();
        mse_vs_heitz[k] = vs_heitz.mean().unwrap_or(0.0);
    }
    let [mut variance, mut variance_rough] = [MeanSquare::default(); 2];
    for (config, m) in configs.iter().zip(per_config) {
        for c in 0..3 {
            let e = &m.converged;
            let sd = e.stderr[c] * (e.samples as f64).sqrt();
            let relative_sd = if e.samples > 1 {
                sd / e.value[c].abs().max(RELATIVE_FLOOR)
            } else {
                0.0
            };
            variance.add(relative_sd);
            if config.alpha >= ROUGH_ALPHA {
                variance_rough.add(relative_sd);
            }
        }
    }
    let (mut bias, mut noise, mut sum, mut worst) = (
        MeanSquare::default(),
        MeanSquare::default(),
        0.0,
        (0.0f64, 0),
    );
    for (i, (m, h)) in per_config.iter().zip(heitz).enumerate() {
        for c in 0..3 {
            let d = relative(m.converged.value[c], h.value[c]);
            bias.add(d);
            sum += d;
            noise.add(
                m.converged.stderr[c].hypot(h.stderr[c]) / h.value[c].abs().max(RELATIVE_FLOOR),
            );
            if d.abs() > worst.0.abs() {
                worst = (d, i);
            }
        }
    }
    ModelMeasure {
        model,
        stochastic,
        ns_per_eval: timing.0,
        ns_per_eval_wall: timing.1,
        mse,
        mse_rough,
        mse_vs_heitz,
        variance: variance.mean().unwrap_or(0.0),
        variance_rough: variance_rough.mean(),
        bias: bias.mean().unwrap_or(0.0).sqrt(),
        bias_mean: sum / bias.count.max(1) as f64,
        bias_noise: noise.mean().unwrap_or(0.0).sqrt(),
        worst_bias: worst,
    }
}

/// The models measured: `models` in their order, with `heitz` first when it is not among them
/// (it is the reference of every ratio).
pub fn measured_models(models: &[Model]) -> Vec<Model> {
    let mut out: Vec<Model> = Vec::new();
    if !models.contains(&Model::Heitz) {
        out.push(Model::Heitz);
    }
    for &m in models {
        if !out.contains(&m) {
            out.push(m);
        }
    }
    out
}

/// Units of work [`measure`] reports through its progress callback.
pub fn work_units(models: &[Model], settings: &EstimatorSettings) -> usize {
    (measured_models(models).len() + 1) * settings.configurations
}

/// Measure every model of [`measured_models`]: rows by model, then by sample count.
/// `progress` is called with the number of finished units ([`work_units`]) and the model.
pub fn measure(
    models: &[Model],
    settings: &EstimatorSettings,
    progress: impl Fn(usize, Model) + Sync,
) -> Vec<EstimatorRow> {
    let configs = configurations(settings.configurations, settings.seed);
    let done = AtomicUsize::new(0);
    let tick = |model| progress(done.fetch_add(1, Ordering::Relaxed) + 1, model);
    let heitz = heitz_reference(&configs, settings, &|| tick(Model::Heitz));
    let measures: Vec<ModelMeasure> = measured_models(models)
        .into_iter()
        .map(|model| {
            let slot = 1 + Model::ALL.iter().position(|&m| m == model).unwrap_or(0) as u64;
            let per_config =
                measure_model(model, &configs, settings, slot, &heitz, &|| tick(model));
            let timing = time_per_eval(model, &configs, settings.timing_seconds, settings.seed);
            summarise(model, &configs, &per_config, &heitz, timing)
        })
        .collect();
    let reference = measures
        .iter()
        .find(|m| m.model == Model::Heitz)
        .expect("measured_models always holds heitz");
    let ratio = |mse: Option<f64>, ns: f64, heitz_mse: Option<f64>| match (mse, heitz_mse) {
        (Some(m), Some(h)) if h > 0.0 => Some(m * ns / (h * reference.ns_per_eval)),
        _ => None,
    };
    let mut rows = Vec::new();
    for m in &measures {
        for (k, &samples) in SAMPLE_COUNTS.iter().enumerate() {
            let efficiency = |mse, heitz_mse| {
                if m.stochastic {
                    ratio(mse, m.ns_per_eval, heitz_mse)
                } else {
                    None
                }
            };
            rows.push(EstimatorRow {
                model: m.model,
                samples,
                stochastic: m.stochastic,
                ns_per_eval: m.ns_per_eval,
                ns_per_eval_wall: m.ns_per_eval_wall,
                rmse: m.mse[k].sqrt(),
                rmse_rough: m.mse_rough[k].map(f64::sqrt),
                rmse_vs_heitz: m.mse_vs_heitz[k].sqrt(),
                bias_vs_heitz: m.bias,
                bias_vs_heitz_mean: m.bias_mean,
                bias_vs_heitz_noise: m.bias_noise,
                worst_bias_vs_heitz: m.worst_bias.0,
                worst_bias_at: configs
                    .get(m.worst_bias.1)
                    .map(Configuration::describe)
                    .unwrap_or_default(),
                inverse_efficiency_vs_heitz: efficiency(Some(m.mse[k]), Some(reference.mse[k])),
                inverse_efficiency_vs_heitz_rough: efficiency(
                    m.mse_rough[k],
                    reference.mse_rough[k],
                ),
                relative_variance: m.variance,
                relative_variance_rough: m.variance_rough,
                inverse_efficiency_vs_heitz_from_reference: efficiency(
                    Some(m.variance),
                    Some(reference.variance),
                ),
                inverse_efficiency_vs_heitz_from_reference_rough: efficiency(
                    m.variance_rough,
                    reference.variance_rough,
                ),
            });
        }
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The configurations stay inside the promised box and fill it evenly: along each axis the
    /// count below any cut stays within 6 of its share (the one-dimensional discrepancy, about
    /// 14 points for 256 independent uniform draws, and under 6 with probability ~0.001); they
    /// alternate the two Fresnels and depend on the seed.
    #[test]
    fn configurations_cover_the_box_evenly() {
        let configs = configurations(256, 3);
        let min_z = MAX_THETA_DEG.to_radians().cos();
        let mut axes: [Vec<f64>; 4] = Default::default();
        for c in &configs {
            assert!((ALPHA_RANGE[0]..=ALPHA_RANGE[1]).contains(&c.alpha));
            for w in [c.wi, c.wo] {
                assert!((w.length() - 1.0).abs() < 1e-12 && w.z >= min_z - 1e-12);
            }
            assert_eq!(c.wi.y, 0.0);
            axes[0].push((c.alpha - ALPHA_RANGE[0]) / (ALPHA_RANGE[1] - ALPHA_RANGE[0]));
            axes[1].push((1.0 - c.wi.z) / (1.0 - min_z));
            axes[2].push((1.0 - c.wo.z) / (1.0 - min_z));
            axes[3].push(
                c.wo.y.atan2(c.wo.x).rem_euclid(std::f64::consts::TAU) / std::f64::consts::TAU,
            );
        }
        for (axis, mut u) in axes.into_iter().enumerate() {
            u.sort_by(f64::total_cmp);
            let discrepancy = u
                .iter()
                .enumerate()
                .map(|(j, x)| {
                    (j as f64 - 256.0 * x)
                        .abs()
                        .max((j as f64 + 1.0 - 256.0 * x).abs())
                })
                .fold(0.0, f64::max);
            assert!(discrepancy < 6.0, "axis {axis}: {discrepancy}");
        }
        let copper = configs.iter().filter(|c| c.fresnel == COPPER).count();
        assert_eq!(copper, 128);
        assert_ne!(configurations(4, 4)[0].alpha, configurations(4, 3)[0].alpha);
    }

    /// On a few configurations: `single` is deterministic (rmse 0 up to rounding, no
    /// efficiency), a stochastic model's rmse falls like 1/sqrt(n), and `kulla-conty`, which
    /// tabulates the energy `heitz` simulates, stays closer to `heitz` than `single` does.
    #[test]
    fn deterministic_and_stochastic_models_behave_as_their_kind() {
        let settings = EstimatorSettings {
            configurations: 12,
            reference_samples: 4096,
            timing_seconds: 0.0,
            seed: 5,
        };
        let rows = measure(&[Model::Single, Model::KullaConty], &settings, |_, _| {});
        let row = |model, samples| {
            rows.iter()
                .find(|r| r.model == model && r.samples == samples)
                .unwrap()
        };
        assert_eq!(rows.len(), 3 * SAMPLE_COUNTS.len(), "heitz is added");
        for n in SAMPLE_COUNTS {
            let single = row(Model::Single, n);
            assert!(single.rmse < 1e-13 && single.inverse_efficiency_vs_heitz.is_none());
            assert!(single.ns_per_eval > 0.0);
        }
        let (h1, h64) = (row(Model::Heitz, 1).rmse, row(Model::Heitz, 64).rmse);
        // 1/sqrt(64) = 1/8 in expectation; the rmse of 4 repetitions x 12 x 3 values at n = 64
        // is itself uncertain by about 1/sqrt(2 x 144) = 6%, heavy tails aside.
        assert!(h64 < h1 / 5.0 && h64 > h1 / 12.0, "{h1} {h64}");
        assert_eq!(row(Model::Heitz, 4).inverse_efficiency_vs_heitz, Some(1.0));
        assert!(
            row(Model::KullaConty, 1).bias_vs_heitz < row(Model::Single, 1).bias_vs_heitz,
            "{} {}",
            row(Model::KullaConty, 1).bias_vs_heitz,
            row(Model::Single, 1).bias_vs_heitz
        );
    }
}
