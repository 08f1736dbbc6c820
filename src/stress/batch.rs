//! The stress sweep through the batch kernel ([`crate::render::batch`], issue #15): every
//! configuration the kernel serves, at the sweep's corners, checked for bad numbers and against
//! the scalar `f64` reference.
//!
//! | axis | values |
//! | --- | --- |
//! | model | `single`, `turquin` (the single lobe scaled by Turquin's compensation), `kulla-conty` (plus its compensation lobe) and `fast-msx` (plus its second-bounce lobe): the models a fit renders through the kernel ([`Lobe::of`]) |
//! | surface | the sweep's surfaces of the model: GGX and Beckmann, both height models, every roughness (isotropic and anisotropic) and every Fresnel |
//! | directions | the sweep's pairs, plus its below-horizon pairs mirrored to `z = +1e-7`: the kernel drops every pair with a direction at or below the horizon, so these are its grazing-most records |
//!
//! Each surface's pairs (one pixel each, unit irradiance, no diffuse layer) go through
//! [`BatchRecords::render`] and [`BatchRecords::render_with_tangents`], once per lane
//! precision ([`Precision`]). The values of both must
//! be finite and non-negative and are compared with the scalar kernel's render of the same
//! material and pairs ([`crate::render::render_pixels`]) as a relative difference (absolute below
//! 1e-6 1/sr, as the f32 deviation of the sweep); the tangents (by `ax`, `ay`, both Fresnel
//! parameters and the diffuse albedo) need only be finite: a tangent may be negative.

use super::{direction_pairs, relative_deviation, Query, SweepSize, Tally};
use crate::bsdf::Model;
use crate::render::batch::{BatchRecords, Lobe, Precision};
use crate::render::render_pixels;
use crate::scalar::Vec3;
use crate::shading::ShadingRecords;
use rayon::prelude::*;
use serde::Serialize;

/// Height of the just-above-horizon directions (the sweep's below-horizon ones, mirrored).
const JUST_ABOVE: f64 = 1e-7;

/// The batch kernel's part of a model's stress report (`batch` in `--json`).
#[derive(Clone, Debug, Serialize)]
pub struct BatchReport {
    /// The lanes' precision.
    pub precision: Precision,
    /// Surfaces times direction pairs: the configurations evaluated.
    pub configurations: usize,
    /// Of those, the ones the kernel evaluates (both directions strictly above the surface);
    /// the others it leaves at zero, as the scalar kernel returns there.
    pub records: usize,
    /// Pixel values returned: every configuration through both `render` and
    /// `render_with_tangents`.
    pub evaluations: usize,
    /// Values that were NaN, infinite or negative.
    pub nan: usize,
    pub inf: usize,
    pub negative: usize,
    /// The first configuration that returned a bad value.
    pub first_bad: Option<String>,
    /// Tangent numbers that were NaN or infinite, out of `tangents`.
    pub tangent_nonfinite: usize,
    pub tangents: usize,
    /// The first configuration that returned a non-finite tangent.
    pub first_bad_tangent: Option<String>,
    /// Worst relative difference of a batch value from the scalar `f64` kernel's, and where.
    pub worst_rel_dev: f64,
    pub worst_rel_dev_at: String,
}

impl BatchReport {
    /// NaN, infinite and negative values, and non-finite tangents.
    pub fn bad_numbers(&self) -> usize {
        self.nan + self.inf + self.negative + self.tangent_nonfinite
    }
}

/// What the batch kernel evaluates for `model` (one it serves: [`crate::bsdf::registry::Capabilities::batch`]) at `single`'s parameters.
fn lobe(model: Model, single: &crate::bsdf::single::SingleBounce<f64>) -> Lobe<'_> {
    Lobe::of(model, single).expect("a model the batch kernel serves")
}

/// The sweep's direction pairs plus its below-horizon ones mirrored just above it.
fn pairs(size: SweepSize) -> Vec<(Vec3<f64>, Vec3<f64>)> {
    let mut pairs = direction_pairs(size);
    let lift = |w: Vec3<f64>| {
        if w.z < 0.0 {
            Vec3::new(w.x, w.y, JUST_ABOVE).normalize()
        } else {
            w
        }
    };
    let mirrored: Vec<_> = pairs
        .iter()
        .filter(|(wi, wo)| wi.z < 0.0 || wo.z < 0.0)
        .map(|&(wi, wo)| (lift(wi), lift(wo)))
        .collect();
    pairs.extend(mirrored);
    pairs
}

/// Bad numbers and deviations over some configurations; query indices are
/// `surface index * pairs + pair index`.
#[derive(Clone, Debug, Default)]
struct BatchTally {
    values: Tally,
    tangent_nonfinite: usize,
    first_bad_tangent: Option<String>,
}

impl BatchTally {
    /// Check the batch `values` of one surface (from `call`) and compare them with `scalar`.
    fn values(
        &mut self,
        call: &str,
        values: &[[f64; 3]],
        scalar: &[[f64; 3]],
        first_index: usize,
        describe: impl Fn(usize) -> String,
    ) {
        for (k, (v, s)) in values.iter().zip(scalar).enumerate() {
            for c in 0..3 {
                self.values
                    .check(v[c], || format!("{} {call} f[{c}]", describe(k)));
                let dev = relative_deviation(v[c], s[c]);
                if dev > self.values.worst_rel_dev.0 {
                    self.values.worst_rel_dev = (dev, first_index + k);
                }
            }
        }
    }

    /// Count the non-finite numbers of one tangent lane.
    fn tangent(&mut self, name: &str, lane: &[[f64; 3]], describe: impl Fn(usize) -> String) {
        for (k, t) in lane.iter().enumerate() {
            for (c, t) in t.iter().enumerate() {
                if !t.is_finite() {
                    self.tangent_nonfinite += 1;
                    self.first_bad_tangent
                        .get_or_insert_with(|| format!("{} d/d{name}[{c}] = {t:e}", describe(k)));
                }
            }
        }
    }

    fn merge(self, other: BatchTally) -> BatchTally {
        BatchTally {
            values: self.values.merge(other.values),
            tangent_nonfinite: self.tangent_nonfinite + other.tangent_nonfinite,
            first_bad_tangent: self.first_bad_tangent.or(other.first_bad_tangent),
        }
    }
}

/// Run every surface of `model`'s sweep (a model the kernel serves) through the batch
/// kernel with lanes of `precision`; see the module doc.
pub fn sweep(model: Model, size: SweepSize, precision: Precision) -> BatchReport {
    let pairs = pairs(size);
    let raw: Vec<_> = pairs
        .iter()
        .map(|(wi, wo)| ([wi.x, wi.y, wi.z], [wo.x, wo.y, wo.z]))
        .collect();
    let records = ShadingRecords::of_pairs("stress", &raw);
    let all: Vec<usize> = (0..pairs.len()).collect();
    let batch = BatchRecords::for_model(&records, &all, precision, model);
    let surfaces = super::surfaces(size, model);
    let query = |index: usize| Query {
        surface: surfaces[index / pairs.len()],
        wi: pairs[index % pairs.len()].0,
        wo: pairs[index % pairs.len()].1,
        samples: 1,
    };
    let tally = surfaces
        .par_iter()
        .enumerate()
        .map(|(s, surface)| {
            let first = s * pairs.len();
            let describe = |k: usize| query(first + k).describe(model);
            let material = surface.material(model);
            let single = material.single::<f64>();
            let scalar = render_pixels(&material, &records, &all, 0);
            let mut tally = BatchTally::default();
            let values = batch.render(lobe(model, &single), material.diffuse);
            tally.values("render", &values, &scalar, first, describe);
            let (values, t) = batch.render_with_tangents(lobe(model, &single), material.diffuse);
            tally.values("render_with_tangents", &values, &scalar, first, describe);
            for (name, lane) in [
                ("ax", &t.ax),
                ("ay", &t.ay),
                ("fresnel_a", &t.fresnel_a),
                ("fresnel_b", &t.fresnel_b),
                ("diffuse", &t.diffuse),
            ] {
                tally.tangent(name, lane, describe);
            }
            tally
        })
        .reduce(BatchTally::default, BatchTally::merge);
    let configurations = surfaces.len() * pairs.len();
    let BatchTally {
        values,
        tangent_nonfinite,
        first_bad_tangent,
    } = tally;
    BatchReport {
        precision,
        configurations,
        records: surfaces.len() * batch.record_count(),
        evaluations: 2 * configurations,
        nan: values.nan,
        inf: values.inf,
        negative: values.negative,
        first_bad: values.first_bad,
        tangent_nonfinite,
        tangents: 5 * 3 * configurations,
        first_bad_tangent,
        worst_rel_dev: values.worst_rel_dev.0,
        worst_rel_dev_at: query(values.worst_rel_dev.1).describe(model),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::Material;

    /// Agreement each lane precision must reach with the scalar kernel. `f64` lanes evaluate
    /// one formula arranged differently, so they differ by rounding: 4e-15 at most over the
    /// quick sweep. The exception is the edge of total internal reflection of a dielectric
    /// with `eta < 1` (the full sweep's `eta = 0.5` at `wi.h = cos 30 deg`), where `F` has a
    /// square-root kink and one ulp of `wi.h` moves it by about `sqrt(ulp)`: 8.9e-8 measured
    /// there; the `f64` tolerance is ten times that. `f32` lanes carry about 30 roundings of
    /// 6e-8 (2e-6, the bound of `render::batch`'s tests) except in the conductor formula when
    /// `k >> eta`: `a^2 = (sqrt(t0^2 + 4 eta^2 k^2) + t0) / 2` subtracts two numbers near
    /// `k^2`, and the sweep's `eta = 0.01`, `k = 20` at grazing `wo` differs by 6.9e-6; the
    /// `f32` tolerance is three times that, and 1/5 of the 1e-4 bound on a render. A
    /// wrong fast path (roughnesses swapped, the other height model or distribution, a Fresnel
    /// term missing) errs by 1e-3 or more.
    const TOLERANCES: [(Precision, f64); 2] = [(Precision::F64, 1e-6), (Precision::F32, 2e-5)];

    #[test]
    fn batch_values_pass_the_quick_sweep() {
        for (precision, tolerance) in TOLERANCES {
            for model in [Model::Single, Model::Turquin, Model::FastMsx] {
                let r = sweep(model, SweepSize::Quick, precision);
                assert_eq!(r.evaluations, 2 * r.configurations);
                assert!(r.records > 0 && r.records < r.configurations);
                assert_eq!(r.bad_numbers(), 0, "{model}: {:?}", r.first_bad);
                assert!(
                    r.worst_rel_dev < tolerance,
                    "{precision:?} {model}: {} at {}",
                    r.worst_rel_dev,
                    r.worst_rel_dev_at
                );
            }
        }
    }

    /// The tangents are finite everywhere, including conductors with `k = 0` and `eta < 1`,
    /// whose Fresnel derivatives were NaN until `fresnel::conductor` floored its square roots.
    #[test]
    fn batch_tangents_are_finite_over_the_quick_sweep() {
        for (precision, _) in TOLERANCES {
            for model in [Model::Single, Model::Turquin, Model::FastMsx] {
                let r = sweep(model, SweepSize::Quick, precision);
                assert_eq!(r.tangent_nonfinite, 0, "{model}: {:?}", r.first_bad_tangent);
            }
        }
    }

    /// The comparison catches a wrong fast path: an anisotropic surface rendered by the kernel
    /// with its roughnesses swapped deviates from the scalar render far beyond [`TOLERANCE`].
    #[test]
    fn the_comparison_catches_swapped_roughnesses() {
        let raw: Vec<_> = pairs(SweepSize::Quick)
            .iter()
            .map(|(wi, wo)| ([wi.x, wi.y, wi.z], [wo.x, wo.y, wo.z]))
            .collect();
        let records = ShadingRecords::of_pairs("stress", &raw);
        let all: Vec<usize> = (0..raw.len()).collect();
        let surface = super::super::surfaces(SweepSize::Quick, Model::Single)
            .into_iter()
            .find(|s| s.alpha[0] != s.alpha[1])
            .expect("an anisotropic surface");
        let material = surface.material(Model::Single);
        let scalar = render_pixels(&material, &records, &all, 0);
        let swapped = Material {
            alpha: [material.alpha[1], material.alpha[0]],
            ..material
        }
        .single::<f64>();
        let values =
            BatchRecords::with_precision(&records, &all, Precision::F64).render(&swapped, [0.0; 3]);
        let mut tally = BatchTally::default();
        tally.values("render", &values, &scalar, 0, |k| k.to_string());
        assert!(
            tally.values.worst_rel_dev.0 > 1e-3,
            "{:?}",
            tally.values.worst_rel_dev
        );
    }
}
