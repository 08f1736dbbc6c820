//! The objective of a fit: image loss of the rendered prediction against the photos, as a
//! function of the unbounded coordinates of a [`ParamSpace`], and its gradient.
//!
//! | `--gradient` | how | cost |
//! | --- | --- | --- |
//! | `exact` (default) | one pass of the renderer in forward-mode dual numbers `DualSVec64<N>` (all `N` partial derivatives at once), chained with `d loss / d prediction` ([`Loss::gradient`]); exact for the analytic models, pathwise at fixed random numbers for the position-free stochastic ones | one evaluation at ~`N`-wide arithmetic |
//! | `fd` | central differences at relative step [`FD_STEP`] | `2 N` evaluations |
//!
//! Models whose value is not generic over the scalar (`heitz`) fall back to `fd`.
//!
//! Only pixels with positive weight are rendered. Stochastic models draw from the per-pixel
//! random streams of a fixed seed (common random numbers), so the objective is a deterministic
//! function of the coordinates and differences and line searches see a smooth surface. They are
//! rendered twice, on two independent sets of streams, and scored with the pair loss
//! ([`Loss::pair_value`]): with one render the squared error would include the render's
//! variance and pull the fit towards less multiple scattering.

use super::params::ParamSpace;
use crate::bsdf::registry::{differentiable, F0Dependence};
use crate::bsdf::single::SingleBounce;
use crate::bsdf::tabulated::{LobeDirections, SchlickOrders, Tabulated};
use crate::bsdf::ScalarBrdf;
use crate::fit::point::params::Surface;
use crate::loss::{ImageLayout, Loss, LossKind};
use crate::render::anchors::{Anchors, Corners};
use crate::render::batch::{BatchRecords, Lobe, PixelTangents, Precision};
use crate::render::plan::{MultiTerm, PlanSummary, RenderPlan, Skips};
use crate::render::{add_to, render_material, render_material_streams, render_planned_streams};
use crate::render::{anchor_values, render_model};
use crate::scalar::{Real, Rgb};
use crate::shading::ShadingRecords;
use argmin::core::{CostFunction, Error as ArgminError, Gradient};
use num_dual::{Dual64, DualSVec64};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

/// Relative step of the central differences (in unbounded coordinates): truncation error
/// ~h^2 = 1e-10, rounding error ~eps/h = 1e-11 relative to the cost.
const FD_STEP: f64 = 1e-5;

/// Largest dimension of the dual-number path (anisotropic conductor with diffuse: 2 + 6 + 3).
const MAX_EXACT_DIM: usize = 11;

/// Mixed into the seed for the second render of a stochastic model: its per-pixel streams
/// ([`crate::random::rng_stream`]) are then independent of the first render's.
const SECOND_RENDER_STREAMS: u64 = 0xD1B5_4A32_D192_ED03;

/// Weight of the pull back of a point outside the space's box, in normalised cost units per
/// squared coordinate ([`crate::fit::point::params`]). Outside the box the loss is constant
/// along the coordinates that left it (it is evaluated at the projection), so the pull puts
/// the minimum of a search that presses outward exactly on the bound, whatever its weight;
/// the weight only sets how firmly a solver's next step is turned back.
const OUTSIDE_PULL: f64 = 1.0;

/// Seeds of the renders a loss compares: `[seed]` for a deterministic model, two independent
/// stream sets for a stochastic one (see [`Loss::pair_value`]).
pub fn render_seeds(stochastic: bool, seed: u64) -> Vec<u64> {
    if stochastic {
        vec![seed, seed ^ SECOND_RENDER_STREAMS]
    } else {
        vec![seed]
    }
}

/// How the objective's gradient is computed (see the module table).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum GradientMethod {
    /// Forward-mode dual numbers where the model allows, central differences otherwise.
    #[default]
    Exact,
    /// Central finite differences with common random numbers.
    Fd,
}

pub struct Objective<'a> {
    pub space: ParamSpace,
    records: &'a ShadingRecords,
    /// Indices of the pixels that enter the loss.
    pixels: Vec<usize>,
    target: Vec<[f64; 3]>,
    weight: Vec<f64>,
    layout: ImageLayout,
    kind: LossKind,
    /// Seeds of the renders the loss compares: one for deterministic models, two
    /// (independent streams) for stochastic ones.
    seeds: Vec<u64>,
    gradient: GradientMethod,
    /// Which work skips the renders may use, and the plan built from them on first use.
    skips: Skips,
    plan: OnceLock<RenderPlan>,
    /// The records of the loss pixels for the batch kernel, built on first use, and the
    /// precision of its lanes.
    batch: OnceLock<BatchRecords>,
    precision: Precision,
    stochastic: bool,
    /// The loss is divided by this, so optimiser tolerances are relative (L2: mean target^2).
    scale: f64,
    pub evaluations: Arc<AtomicUsize>,
    /// Lowest cost seen so far and its coordinates: what an interrupted run still reports.
    pub best: Mutex<(f64, Vec<f64>)>,
}

/// What the loss is divided by, so that optimiser tolerances are relative: for L2 the mean
/// squared target, 1 for the other losses.
fn loss_scale(kind: LossKind, target: &[[f64; 3]], weight: &[f64]) -> f64 {
    match kind {
        LossKind::L2 => {
            let wsum: f64 = weight.iter().sum();
            (target
                .iter()
                .zip(weight)
                .map(|(t, w)| w * (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]) / 3.0)
                .sum::<f64>()
                / wsum)
                .max(1e-300)
        }
        LossKind::RelativeL2 | LossKind::LogL1 | LossKind::Ssim => 1.0,
    }
}

impl<'a> Objective<'a> {
    pub fn new(space: ParamSpace, records: &'a ShadingRecords, kind: LossKind, seed: u64) -> Self {
        let pixels: Vec<usize> = (0..records.pixel_count())
            .filter(|&p| records.weight[p] > 0.0)
            .collect();
        let target: Vec<[f64; 3]> = pixels.iter().map(|&p| records.target[p]).collect();
        let weight: Vec<f64> = pixels.iter().map(|&p| records.weight[p]).collect();
        let scale = loss_scale(kind, &target, &weight);
        let layout = ImageLayout::new(records, &pixels);
        let stochastic = space.model.capabilities().stochastic();
        let seeds = render_seeds(stochastic, seed);
        Objective {
            space,
            records,
            pixels,
            target,
            weight,
            layout,
            kind,
            seeds,
            gradient: GradientMethod::Exact,
            skips: Skips::default(),
            plan: OnceLock::new(),
            batch: OnceLock::new(),
            precision: space.model.capabilities().lanes,
            stochastic,
            scale,
            evaluations: Arc::new(AtomicUsize::new(0)),
            best: Mutex::new((f64::INFINITY, Vec::new())),
        }
    }

    /// The same objective fitted to other targets (`target` indexed like
    /// `ShadingRecords::target`), with its evaluation count restarted. The batch records and
    /// the render plan depend on the records' geometry, not on their targets, so they are kept:
    /// a defect-corrected fit's rounds (`corrected`) change only the targets, and building them
    /// again cost each round more than its own search.
    pub fn retarget(&mut self, target: &[[f64; 3]]) {
        self.target = self.pixels.iter().map(|&p| target[p]).collect();
        self.scale = loss_scale(self.kind, &self.target, &self.weight);
        self.evaluations.store(0, Ordering::Relaxed);
    }

    /// The same objective on one render only: for a stochastic model its loss then includes
    /// the render's variance, a bias towards less multiple scattering, but regions where the
    /// model is noisy look bad instead of offering the pair loss's noise to exploit. Fits
    /// search their start on this and polish on the pair loss (`fit::fit_level`).
    pub fn single_render(mut self) -> Self {
        self.seeds.truncate(1);
        self
    }

    /// Seeds of the renders the loss compares (see [`Objective::renders`]).
    pub fn seeds(&self) -> &[u64] {
        &self.seeds
    }

    /// Whether the model's value is a Monte Carlo estimate (the objective then has small jumps
    /// where a walk changes its path).
    pub fn is_stochastic(&self) -> bool {
        self.stochastic
    }

    /// Whether the loss compares two renders (a stochastic model).
    pub fn is_paired(&self) -> bool {
        self.seeds.len() == 2
    }

    /// The same objective with gradients computed by `method` (default: exact where available).
    pub fn with_gradient(mut self, method: GradientMethod) -> Self {
        self.gradient = method;
        self.batch = OnceLock::new();
        self
    }

    /// The same objective rendering with only the work skips in `skips` (default: all).
    pub fn with_skips(mut self, skips: Skips) -> Self {
        self.skips = skips;
        self.plan = OnceLock::new();
        self
    }

    /// The same objective with the batch kernel's lanes in `precision` (default `f32`).
    pub fn with_precision(mut self, precision: Precision) -> Self {
        self.precision = precision;
        self.batch = OnceLock::new();
        self
    }

    /// The render plan of this objective's model and pixels, built on first use.
    pub fn plan(&self) -> &RenderPlan {
        self.plan.get_or_init(|| {
            let space = &self.space;
            let model = (space.model, space.ndf, space.height);
            // Where the batch kernel evaluates the model's multiple-bounce term, it does so at
            // every sub-sample in less time than the anchors' scalar evaluations and their
            // interpolation take (docs/speed.md), and exactly: no anchors.
            let mut skips = self.skips;
            skips.sparse_multi &= space.model.capabilities().batch.is_none();
            RenderPlan::new(skips, model, self.records, &self.pixels)
        })
    }

    /// The batch kernel's records of the loss pixels, built on first use. Finite differences
    /// divide the cost's rounding by their step [`FD_STEP`]: `f32` lanes (6e-8 relative) would
    /// leave 6e-3 of noise in such a gradient, so a finite-difference objective gets `f64`
    /// lanes whatever its precision says.
    fn batch(&self) -> &BatchRecords {
        self.batch.get_or_init(|| {
            let precision = match self.gradient_method() {
                GradientMethod::Fd => Precision::F64,
                GradientMethod::Exact => self.precision,
            };
            BatchRecords::for_model(self.records, &self.pixels, precision, self.space.model)
        })
    }

    /// What the batch kernel renders when it evaluates the whole render at `single`'s
    /// parameters: the single lobe where the plan drops the multiple-bounce term, the model's
    /// whole lobe where the kernel has it ([`Lobe::of`]: `single`, `turquin`, `kulla-conty`,
    /// `fast-msx`)
    /// and the plan asks for it exactly; `None` otherwise (the exact single term still comes
    /// from the batch kernel through [`Objective::batch_shared`]). Every seed's render is
    /// then the same.
    fn batch_lobe<'s>(&self, single: &'s SingleBounce<f64>) -> Option<Lobe<'s>> {
        match self.plan().multi_term(single) {
            MultiTerm::Skipped => Some(single.into()),
            MultiTerm::Exact => Lobe::of(self.space.model, single),
            MultiTerm::Sparse(_) => None,
        }
    }

    /// The single-bounce and diffuse terms of the loss pixels from the batch kernel (and their
    /// tangents when `tangents`), without the single-bounce term at the pixels `anchors` leaves
    /// to an exact evaluation: the part of a render through anchors that no random stream changes
    /// ([`crate::render::render_planned_split`]'s `shared`).
    fn batch_shared(
        &self,
        surface: &Surface<f64>,
        anchors: &Anchors,
        tangents: bool,
    ) -> (Vec<[f64; 3]>, Option<PixelTangents>) {
        let batch = self.batch();
        let (mut values, mut t) = if tangents {
            let (v, t) = batch.render_with_tangents(&surface.single, surface.diffuse);
            (v, Some(t))
        } else {
            (batch.render(&surface.single, surface.diffuse), None)
        };
        // Pixels without anchors keep only the diffuse term here: their specular value is
        // evaluated whole with the multiple-bounce term.
        for (k, corners) in anchors.corners.iter().enumerate() {
            if corners.is_none() {
                values[k] = [0, 1, 2].map(|c| surface.diffuse[c] * batch.lambert()[k][c]);
                if let Some(t) = &mut t {
                    for lane in [&mut t.ax, &mut t.ay, &mut t.fresnel_a, &mut t.fresnel_b] {
                        lane[k] = [0.0; 3];
                    }
                }
            }
        }
        (values, t)
    }

    /// [`Objective::batch_shared`] as an affine function of a Schlick F0, per pixel and channel
    /// `[value at F0 = 0, slope]` ([`BatchRecords::render_affine_in_f0`]): what the projection
    /// needs, from two value passes instead of the pass with tangents.
    fn batch_shared_affine(&self, surface: &Surface<f64>, anchors: &Anchors) -> Vec<[[f64; 2]; 3]> {
        let batch = self.batch();
        let mut parts = batch.render_affine_in_f0(&surface.single, surface.diffuse);
        for (k, corners) in anchors.corners.iter().enumerate() {
            if corners.is_none() {
                parts[k] = [0, 1, 2].map(|c| [surface.diffuse[c] * batch.lambert()[k][c], 0.0]);
            }
        }
        parts
    }

    /// The per-seed part of a render through `anchors` at `seed`, unexposed: the interpolated
    /// multiple-bounce term at the pixels with anchors and the whole specular value (no
    /// diffuse) at the pixels without. The interpolated term is the same at every sub-sample of
    /// a pixel, so its sub-sample sum is `pi lambert_k sum_a w_ka multi_a` with the pixel's
    /// white Lambertian radiance `lambert_k`: linear in the anchors' values, which is what lets
    /// the gradient pass carry derivatives at the anchors only ([`Objective::dual_pass`]).
    fn anchored_part<T: Real, B: ScalarBrdf<T> + ?Sized>(
        &self,
        brdf: &B,
        anchors: &Anchors,
        seed: u64,
    ) -> AnchoredPart<T> {
        let AnchoredValues { multi, exact } = self.anchored_values_of(brdf, anchors, seed);
        let multi_re: Vec<[f64; 3]> = multi.iter().map(|m| m.0.map(|v| v.re64())).collect();
        let mut own: Vec<[f64; 3]> = anchors
            .corners
            .par_iter()
            .zip(self.batch().lambert().par_iter())
            .map(|(corners, lambert)| match corners {
                Some(corners) => interpolate(corners, &multi_re, lambert),
                None => [0.0; 3],
            })
            .collect();
        for (k, value) in &exact {
            own[*k] = value.map(|v| v.re64());
        }
        AnchoredPart { multi, exact, own }
    }

    /// What [`Objective::anchored_part`] interpolates: the multiple-bounce estimate at each
    /// anchor, and the whole specular value at the pixels without anchors.
    fn anchored_values_of<T: Real, B: ScalarBrdf<T> + ?Sized>(
        &self,
        brdf: &B,
        anchors: &Anchors,
        seed: u64,
    ) -> AnchoredValues<T> {
        let spp = self.records.samples_per_pixel;
        let multi = anchor_values(brdf, anchors, self.plan().stochastic, spp, seed);
        let exact_slots: Vec<usize> = (0..anchors.corners.len())
            .filter(|&k| anchors.corners[k].is_none())
            .collect();
        let exact_pixels: Vec<usize> = exact_slots.iter().map(|&k| self.pixels[k]).collect();
        let exact_values = render_model(brdf, [T::zero(); 3], self.records, &exact_pixels, seed);
        AnchoredValues {
            multi,
            exact: exact_slots.into_iter().zip(exact_values).collect(),
        }
    }

    /// [`Objective::anchored_renders`] at `x` before its interpolation: per seed, the anchors'
    /// values and the pixels without anchors, with the anchors and each pixel's white
    /// Lambertian radiance that interpolate them ([`interpolate`]), so that a caller can
    /// combine several points' anchor values before it interpolates once
    /// ([`super::projection`]); and the shared part as an affine function of F0 when `shared`.
    /// `None` where the plan does not interpolate, or where the space fits an exposure (these
    /// parts are unexposed).
    pub fn anchored_values(&self, x: &[f64], shared: bool) -> Option<AnchoredRender<'_>> {
        let surface = self.space.surface(x);
        let MultiTerm::Sparse(anchors) = self.plan().multi_term(&surface.single) else {
            return None;
        };
        if self.space.exposure {
            return None;
        }
        let material = self.space.material(x);
        let single = material.single::<f64>();
        let brdf = material.capped_brdf(self.plan().bounce_cap(&single));
        Some(AnchoredRender {
            anchors,
            lambert: self.batch().lambert(),
            shared: shared.then(|| self.batch_shared_affine(&surface, anchors)),
            streams: self
                .seeds
                .iter()
                .map(|&seed| self.anchored_values_of(brdf.as_ref(), anchors, seed))
                .collect(),
        })
    }

    /// For `tabulated` with a Schlick Fresnel at `x`, where the plan renders its
    /// multiple-bounce term (from anchors or at every sub-sample): the render split so that
    /// the Schlick F0 can vary ([`OrderParts`]), unexposed and without diffuse. `None` for
    /// other models and Fresnels, where the plan skips the term as faint (the prediction is
    /// then the single bounce, affine in F0), or where the space fits an exposure.
    pub fn order_parts(&self, x: &[f64]) -> Option<OrderParts<'_>> {
        if self.space.model.capabilities().f0 != F0Dependence::Orders || self.space.exposure {
            return None;
        }
        let single = self.space.material(x).single::<f64>();
        if !matches!(single.fresnel, crate::microfacet::Fresnel::Schlick { .. }) {
            return None;
        }
        let anchors = match self.plan().multi_term(&single) {
            MultiTerm::Sparse(anchors) => Some(anchors),
            MultiTerm::Exact => None,
            MultiTerm::Skipped => return None,
        };
        let lobe = Tabulated::new(single);
        let orders = lobe.schlick_orders();
        // The channel-free parts at one direction pair, flattened `[g][k]` -> `3 g + k`.
        let parts_at = |wi: [f64; 3], wo: [f64; 3]| -> [f64; ORDER_PARTS] {
            LobeDirections::new(wi, wo).map_or([0.0; ORDER_PARTS], |d| {
                let q = lobe.schlick_orders_at(&d, &orders);
                std::array::from_fn(|j| q[j / 3][j % 3])
            })
        };
        let multi = anchors.map_or_else(Vec::new, |anchors| {
            anchors
                .points
                .par_iter()
                .map(|a| {
                    let q = parts_at(a.wi, a.wo);
                    std::array::from_fn(|i| q[i / 3])
                })
                .collect()
        });
        // The pixels without anchors: their sub-samples summed as `render_model` sums them.
        let spp = self.records.samples_per_pixel;
        let exact_slots: Vec<usize> = (0..self.pixels.len())
            .filter(|&k| anchors.is_none_or(|a| a.corners[k].is_none()))
            .collect();
        let exact = exact_slots
            .par_iter()
            .map(|&k| {
                let p = self.pixels[k];
                let mut sum = [0.0; 3 * ORDER_PARTS];
                for s in p * spp..(p + 1) * spp {
                    let e = self.records.irradiance[s];
                    if e == [0.0; 3] {
                        continue;
                    }
                    let q = parts_at(self.records.wi[s], self.records.wo[s]);
                    for (i, v) in sum.iter_mut().enumerate() {
                        *v += q[i / 3] * e[i % 3];
                    }
                }
                (k, sum.map(|v| v / spp as f64))
            })
            .collect();
        let batch = self.batch();
        Some(OrderParts {
            single: batch.render_affine_in_f0(&single, [0.0; 3]),
            anchors,
            lambert: batch.lambert(),
            multi,
            exact,
            orders,
        })
    }

    /// For `kulla-conty` at `x`, where the batch kernel evaluates its whole lobe: the single
    /// bounce with its derivative by the first Fresnel parameter of each channel, and the
    /// whole render (single bounce and compensation lobe), both unexposed and without diffuse.
    /// The compensation lobe is an image that does not depend on the Fresnel times its colour
    /// `F_ms / (pi (1 - E_avg))` ([`crate::bsdf::kulla_conty::KullaConty::lobe_scale`]), so a
    /// caller can take the image from the difference ([`super::projection`]). `None` for
    /// other models, where the plan skips the lobe as faint, or where the space fits an
    /// exposure.
    pub fn compensation_parts(&self, x: &[f64]) -> Option<CompensationParts> {
        let surface = self.space.surface(x);
        if self.space.model.capabilities().f0 != F0Dependence::Compensated || self.space.exposure {
            return None;
        }
        let MultiTerm::Exact = self.plan().multi_term(&surface.single) else {
            return None;
        };
        let lobe = Lobe::of(self.space.model, &surface.single)?;
        let batch = self.batch();
        Some(CompensationParts {
            single: batch.render_affine_in_f0(&surface.single, [0.0; 3]),
            whole: batch.render(lobe, [0.0; 3]),
        })
    }

    /// What the render plan skips, at the roughness of `material`.
    pub fn plan_summary(&self, material: &crate::material::Material) -> PlanSummary {
        self.plan().summary(material)
    }

    /// Predicted radiance of the loss pixels for `material`, rendered through the plan.
    pub fn render(&self, material: &crate::material::Material, seed: u64) -> Vec<[f64; 3]> {
        render_material(material, self.records, &self.pixels, self.plan(), seed)
    }

    /// The method [`Gradient::gradient`] uses: `Exact` only when requested and the model and
    /// dimension have a dual-number path.
    pub fn gradient_method(&self) -> GradientMethod {
        let dim = self.space.dim();
        let exact = self.gradient == GradientMethod::Exact
            && (1..=MAX_EXACT_DIM).contains(&dim)
            && self.space.model.capabilities().generic;
        if exact {
            GradientMethod::Exact
        } else {
            GradientMethod::Fd
        }
    }

    pub fn pixel_count(&self) -> usize {
        self.pixels.len()
    }

    /// The records this objective compares against.
    pub fn records(&self) -> &'a ShadingRecords {
        self.records
    }

    /// Where each loss pixel sits in its photo.
    pub fn layout(&self) -> &ImageLayout {
        &self.layout
    }

    /// Indices of the record pixels that enter the loss.
    pub fn pixels(&self) -> &[usize] {
        &self.pixels
    }

    /// Seed of the common random numbers (of the first render).
    pub fn seed(&self) -> u64 {
        self.seeds[0]
    }

    /// Targets of the loss pixels.
    pub fn targets(&self) -> &[[f64; 3]] {
        &self.target
    }

    /// Predicted radiance of the loss pixels at coordinates `x` (the first render).
    pub fn predict(&self, x: &[f64]) -> Vec<[f64; 3]> {
        let render = self.render(&self.space.material(x), self.seeds[0]);
        self.exposed(render, self.space.exposure(x))
    }

    /// `render` times the fitted `exposure` (unchanged when the space does not fit one).
    fn exposed<T: Real>(&self, render: Vec<[T; 3]>, exposure: T) -> Vec<[T; 3]> {
        if !self.space.exposure {
            return render;
        }
        render
            .into_iter()
            .map(|p| p.map(|v| v * exposure))
            .collect()
    }

    /// The renders the loss compares at `x`: one, or two on independent streams for a
    /// stochastic model.
    pub fn renders(&self, x: &[f64]) -> Vec<Vec<[f64; 3]>> {
        let surface = self.space.surface(x);
        if let Some(lobe) = self.batch_lobe(&surface.single) {
            let render = self.batch().render(lobe, surface.diffuse);
            return vec![self.exposed(render, surface.exposure); self.seeds.len()];
        }
        if let Some(renders) = self.anchored_renders(x) {
            return renders;
        }
        let material = self.space.material(x);
        let exposure = self.space.exposure(x);
        render_material_streams(
            &material,
            self.records,
            &self.pixels,
            self.plan(),
            &self.seeds,
        )
        .into_iter()
        .map(|render| self.exposed(render, exposure))
        .collect()
    }

    /// [`Objective::renders`] where the plan interpolates the multiple-bounce term from
    /// anchors (as [`crate::render::render_planned_split`] splits a render: the batch kernel's
    /// exact single bounce and diffuse shared by every seed, each seed's interpolated term),
    /// or `None` where it does not at this roughness.
    fn anchored_renders(&self, x: &[f64]) -> Option<Vec<Vec<[f64; 3]>>> {
        let surface = self.space.surface(x);
        let MultiTerm::Sparse(anchors) = self.plan().multi_term(&surface.single) else {
            return None;
        };
        let material = self.space.material(x);
        let single = material.single::<f64>();
        let brdf = material.capped_brdf(self.plan().bounce_cap(&single));
        let shared = self.exposed(
            self.batch_shared(&surface, anchors, false).0,
            surface.exposure,
        );
        Some(
            self.seeds
                .iter()
                .map(|&seed| {
                    let own = self.anchored_part(brdf.as_ref(), anchors, seed).own;
                    let mut own = self.exposed(own, surface.exposure);
                    add_to(&mut own, &shared);
                    own
                })
                .collect(),
        )
    }

    /// The loss bound to this objective's pixels.
    pub fn image_loss(&self) -> Loss<'_> {
        Loss::new(self.kind, &self.target, &self.weight, &self.layout)
    }

    /// The loss (not normalised) at `x`.
    pub fn loss(&self, x: &[f64]) -> f64 {
        self.image_loss().renders_value(&self.renders(x))
    }

    /// Loss per photo at `x`: (photo index, loss, pixel count).
    pub fn loss_per_photo(&self, x: &[f64]) -> Vec<(usize, f64, usize)> {
        let terms = self.image_loss().renders_terms(&self.renders(x));
        let mut per_photo = vec![(0.0, 0.0, 0); self.records.photos.len()];
        for (k, &(photo, _)) in self.layout.place.iter().enumerate() {
            let entry = &mut per_photo[photo];
            entry.0 += terms[k];
            entry.1 += self.weight[k];
            entry.2 += 1;
        }
        per_photo
            .into_iter()
            .enumerate()
            .map(|(i, (sum, wsum, count))| {
                (i, sum / (3.0 * f64::max(wsum, f64::MIN_POSITIVE)), count)
            })
            .collect()
    }

    /// The normalised cost at `x`: the loss at `x` projected onto the space's box, plus the
    /// pull back [`OUTSIDE_PULL`] `|x - clamp(x)|^2` ([`crate::fit::point::params`]).
    fn normalised_cost(&self, x: &[f64]) -> f64 {
        let pull = self.pull(x);
        let inside = if pull > 0.0 {
            self.space.clamp(x)
        } else {
            x.to_vec()
        };
        self.record(x, self.loss(&inside) / self.scale + pull)
    }

    /// The pull back of a point outside the box, in normalised cost units.
    fn pull(&self, x: &[f64]) -> f64 {
        OUTSIDE_PULL * self.space.outside(x).iter().map(|d| d * d).sum::<f64>()
    }

    /// Count an evaluation of the normalised `cost` at `x` and keep the best point.
    fn record(&self, x: &[f64], cost: f64) -> f64 {
        self.evaluations.fetch_add(1, Ordering::Relaxed);
        let cost = if cost.is_finite() { cost } else { f64::MAX };
        let mut best = self.best.lock().expect("no panics while holding the lock");
        if cost < best.0 {
            *best = (cost, x.to_vec());
        }
        cost
    }

    /// Normalised cost and its exact gradient at `x` in one dual-number pass, `None` when the
    /// model or the dimension has no dual path. The one match over the dimension picks the
    /// width of the dual numbers.
    pub fn exact_cost_and_gradient(&self, x: &[f64]) -> Option<(f64, Vec<f64>)> {
        let (cost, gradient, _) = self.exact_pass(x, false)?;
        Some((cost, gradient))
    }

    /// Normalised cost, its gradient and, when `matrix`, its Gauss-Newton matrix (see
    /// [`Objective::gauss_newton`]) at `x`, from the batch kernel's pass with tangents where it
    /// renders the whole prediction and from the dual-number pass otherwise.
    ///
    /// Outside the space's box it is the pass at the projection onto the box with the pull back
    /// [`OUTSIDE_PULL`] `|x - clamp(x)|^2` added: the gradient of `cost(clamp(x)) + pull`, whose
    /// coordinates outside the box see only the pull (and its Gauss-Newton term `2 pull`).
    fn exact_pass(&self, x: &[f64], matrix: bool) -> Option<(f64, Vec<f64>, Option<Vec<f64>>)> {
        let outside = self.space.outside(x);
        if outside.iter().all(|&d| d == 0.0) {
            let (loss, gradient, gauss_newton) = self.exact_pass_inside(x, matrix)?;
            return Some((self.record(x, loss), gradient, gauss_newton));
        }
        let (loss, mut gradient, mut gauss_newton) =
            self.exact_pass_inside(&self.space.clamp(x), matrix)?;
        let n = x.len();
        for (i, &d) in outside.iter().enumerate() {
            if d == 0.0 {
                continue;
            }
            gradient[i] = 2.0 * OUTSIDE_PULL * d;
            if let Some(m) = gauss_newton.as_mut() {
                for j in 0..n {
                    m[i * n + j] = 0.0;
                    m[j * n + i] = 0.0;
                }
                m[i * n + i] = 2.0 * OUTSIDE_PULL;
            }
        }
        Some((self.record(x, loss + self.pull(x)), gradient, gauss_newton))
    }

    /// [`Objective::exact_pass`] at a point inside the box, the cost not yet recorded.
    fn exact_pass_inside(
        &self,
        x: &[f64],
        matrix: bool,
    ) -> Option<(f64, Vec<f64>, Option<Vec<f64>>)> {
        let single_only = self.batch_lobe(&self.space.surface(x).single).is_some();
        let (loss, gradient, gauss_newton) = match x.len() {
            _ if single_only => Some(self.batch_pass(x, matrix)),
            1 => self.dual_pass::<1>(x, matrix),
            2 => self.dual_pass::<2>(x, matrix),
            3 => self.dual_pass::<3>(x, matrix),
            4 => self.dual_pass::<4>(x, matrix),
            5 => self.dual_pass::<5>(x, matrix),
            6 => self.dual_pass::<6>(x, matrix),
            7 => self.dual_pass::<7>(x, matrix),
            8 => self.dual_pass::<8>(x, matrix),
            9 => self.dual_pass::<9>(x, matrix),
            10 => self.dual_pass::<10>(x, matrix),
            11 => self.dual_pass::<11>(x, matrix),
            _ => None,
        }?;
        let normalise = |v: Vec<f64>| v.into_iter().map(|g| g / self.scale).collect::<Vec<_>>();
        Some((
            loss / self.scale,
            normalise(gradient),
            gauss_newton.map(normalise),
        ))
    }

    /// Loss and its gradient at `x` with `N` = `x.len()` dual directions: the coordinates are
    /// seeded with unit derivative vectors, the renderer carries them to every pixel, and the
    /// chain rule sums `d loss / d p . d p / d x` over pixels and channels.
    ///
    /// With `matrix` (a deterministic model and a squared-error loss), also the Gauss-Newton
    /// matrix from each pixel's Jacobian row: the kernel's tangents through the coordinates,
    /// the dual parts of the anchors it interpolates, or its own dual parts.
    fn dual_pass<const N: usize>(
        &self,
        x: &[f64],
        matrix: bool,
    ) -> Option<(f64, Vec<f64>, Option<Vec<f64>>)> {
        let coords: Vec<DualSVec64<N>> = x
            .iter()
            .enumerate()
            .map(|(i, &v)| DualSVec64::from_re(v).derivative(i))
            .collect();
        let surface = self.space.surface(&coords);
        let cap = self.plan().bounce_cap(&surface.single);
        let brdf = differentiable(self.space.model, surface.single, cap)?;
        let at = self.space.surface(x);
        if let MultiTerm::Sparse(anchors) = self.plan().multi_term(&at.single) {
            // The exact single-bounce and diffuse terms from the batch kernel with their
            // tangents; the rest is linear in the anchors' values, so the loss's slopes are
            // carried back to the anchors (an adjoint) and only the anchors and the pixels
            // without anchors are evaluated in dual numbers.
            let (shared, tangents) = self.batch_shared(&at, anchors, true);
            let tangents = tangents.expect("asked for");
            let parts: Vec<AnchoredPart<DualSVec64<N>>> = self
                .seeds
                .iter()
                .map(|&seed| self.anchored_part(brdf.as_ref(), anchors, seed))
                .collect();
            let raws: Vec<Vec<[f64; 3]>> = parts
                .iter()
                .map(|part| {
                    let mut raw = part.own.clone();
                    add_to(&mut raw, &shared);
                    raw
                })
                .collect();
            let values: Vec<Vec<[f64; 3]>> = raws
                .iter()
                .map(|raw| raw.iter().map(|p| p.map(|v| v * at.exposure)).collect())
                .collect();
            let loss = self.image_loss();
            let (value, slopes) = (loss.renders_value(&values), loss.renders_gradient(&values));
            let raw_refs: Vec<&[[f64; 3]]> = raws.iter().map(|r| r.as_slice()).collect();
            let mut gradient = self.batch_gradient(x, &slopes, &raw_refs, &tangents, at.exposure);
            let lambert = self.batch().lambert();
            for (part, slope) in parts.iter().zip(&slopes) {
                let mut at_anchors = vec![[0.0; 3]; part.multi.len()];
                for (k, corners) in anchors.corners.iter().enumerate() {
                    if let Some(corners) = corners {
                        for &(a, w) in corners {
                            for c in 0..3 {
                                at_anchors[a as usize][c] +=
                                    slope[k][c] * at.exposure * PI * lambert[k][c] * w;
                            }
                        }
                    }
                }
                let anchor_duals: Vec<[DualSVec64<N>; 3]> =
                    part.multi.iter().map(|m| m.0).collect();
                add_dual_slopes::<N>(&mut gradient, &[anchor_duals], &[at_anchors]);
                let (slots, exact): (Vec<usize>, Vec<[DualSVec64<N>; 3]>) =
                    part.exact.iter().cloned().unzip();
                let exact_slopes: Vec<[f64; 3]> = slots
                    .iter()
                    .map(|&k| slope[k].map(|d| d * at.exposure))
                    .collect();
                add_dual_slopes::<N>(&mut gradient, &[exact], &[exact_slopes]);
            }
            let gauss_newton = (matrix && parts.len() == 1).then(|| {
                let part = &parts[0];
                let directions = self.coordinate_directions(x);
                let multi: Vec<[[f64; N]; 3]> =
                    part.multi.iter().map(|m| m.0.map(dual_parts)).collect();
                let mut exact: Vec<Option<[[f64; N]; 3]>> = vec![None; raws[0].len()];
                for (k, value) in &part.exact {
                    exact[*k] = Some(value.map(dual_parts));
                }
                let e = at.exposure;
                self.gauss_newton_sum::<N>(|k, c, row| {
                    let t = &tangents;
                    for (i, d) in directions.iter().enumerate() {
                        let d = &d[c];
                        row[i] = e
                            * (t.ax[k][c] * d[0]
                                + t.ay[k][c] * d[1]
                                + t.fresnel_a[k][c] * d[2]
                                + t.fresnel_b[k][c] * d[3]
                                + t.diffuse[k][c] * d[4])
                            + raws[0][k][c] * d[5];
                    }
                    if let Some(corners) = &anchors.corners[k] {
                        for &(a, w) in corners {
                            let s = e * PI * lambert[k][c] * w;
                            for (r, m) in row.iter_mut().zip(&multi[a as usize][c]) {
                                *r += s * m;
                            }
                        }
                    } else if let Some(own) = &exact[k] {
                        for (r, m) in row.iter_mut().zip(&own[c]) {
                            *r += e * m;
                        }
                    }
                })
            });
            return Some((value, gradient, gauss_newton));
        }
        let renders: Vec<Vec<[DualSVec64<N>; 3]>> = render_planned_streams(
            brdf.as_ref(),
            &surface.single,
            surface.diffuse,
            self.records,
            &self.pixels,
            self.plan(),
            &self.seeds,
        )
        .into_iter()
        .map(|render| self.exposed(render, surface.exposure))
        .collect();
        let values: Vec<Vec<[f64; 3]>> = renders
            .iter()
            .map(|r| r.iter().map(|p| p.map(|v| v.re)).collect())
            .collect();
        let loss = self.image_loss();
        let (value, slopes) = (loss.renders_value(&values), loss.renders_gradient(&values));
        let mut gradient = vec![0.0; N];
        add_dual_slopes::<N>(&mut gradient, &renders, &slopes);
        let gauss_newton = (matrix && renders.len() == 1)
            .then(|| self.gauss_newton_sum::<N>(|k, c, row| *row = dual_parts(renders[0][k][c])));
        Some((value, gradient, gauss_newton))
    }

    /// `2 sum_k,c v_kc J_kc J_kc^T` (row-major `N x N`) over the loss pixels `k` and channels
    /// `c`, with the loss's weights `v` ([`Loss::quadratic_weights`]) and the Jacobian rows
    /// `J_kc` that `row` writes. Summed in fixed chunks of pixels, in order, so the sum does
    /// not depend on the thread count.
    fn gauss_newton_sum<const N: usize>(
        &self,
        row: impl Fn(usize, usize, &mut [f64; N]) + Sync,
    ) -> Vec<f64> {
        const CHUNK: usize = 4096;
        let weights = self
            .image_loss()
            .quadratic_weights()
            .expect("a squared-error loss");
        let chunks: Vec<[[f64; N]; N]> = weights
            .par_chunks(CHUNK)
            .enumerate()
            .map(|(chunk, weights)| {
                let mut sum = [[0.0; N]; N];
                let mut r = [0.0; N];
                for (offset, v) in weights.iter().enumerate() {
                    for (c, &v) in v.iter().enumerate() {
                        row(chunk * CHUNK + offset, c, &mut r);
                        for i in 0..N {
                            for j in 0..=i {
                                sum[i][j] += v * r[i] * r[j];
                            }
                        }
                    }
                }
                sum
            })
            .collect();
        let mut matrix = vec![0.0; N * N];
        for sum in &chunks {
            for i in 0..N {
                for j in 0..=i {
                    matrix[i * N + j] += 2.0 * sum[i][j];
                }
            }
        }
        for i in 0..N {
            for j in 0..i {
                matrix[j * N + i] = matrix[i * N + j];
            }
        }
        matrix
    }

    /// Loss and its gradient at `x` where the render is the single-bounce and diffuse terms
    /// only: the batch kernel gives each pixel's derivatives by the kernel's parameters in the
    /// render's own pass, the loss's slopes weight them, and one dual number per coordinate
    /// carries the parameters' derivatives by the coordinates (`ParamSpace::surface`).
    ///
    /// With `matrix`, also the Gauss-Newton matrix: per channel the Gram matrix of the pixels'
    /// tangents by the kernel's parameters (the exposure's tangent is the unexposed value),
    /// weighted by the loss, carried to the coordinates by the parameters' derivatives.
    fn batch_pass(&self, x: &[f64], matrix: bool) -> (f64, Vec<f64>, Option<Vec<f64>>) {
        let surface = self.space.surface(x);
        let lobe = self
            .batch_lobe(&surface.single)
            .expect("called where the kernel serves");
        let (raw, tangents) = self.batch().render_with_tangents(lobe, surface.diffuse);
        let e = surface.exposure;
        let render: Vec<[f64; 3]> = raw.iter().map(|p| p.map(|v| v * e)).collect();
        let renders = vec![render; self.seeds.len()];
        let loss = self.image_loss();
        let (value, slopes) = (
            loss.renders_value(&renders),
            loss.renders_gradient(&renders),
        );
        let raws = vec![raw.as_slice(); slopes.len()];
        let gradient = self.batch_gradient(x, &slopes, &raws, &tangents, e);
        let weights = loss.quadratic_weights().filter(|_| matrix);
        let gauss_newton = weights.map(|weights| {
            let mut gram = [[[0.0; 6]; 6]; 3];
            for (k, v) in weights.iter().enumerate() {
                for c in 0..3 {
                    let u = [
                        e * tangents.ax[k][c],
                        e * tangents.ay[k][c],
                        e * tangents.fresnel_a[k][c],
                        e * tangents.fresnel_b[k][c],
                        e * tangents.diffuse[k][c],
                        raw[k][c],
                    ];
                    for a in 0..6 {
                        for b in 0..=a {
                            gram[c][a][b] += v[c] * u[a] * u[b];
                        }
                    }
                }
            }
            let directions = self.coordinate_directions(x);
            let n = x.len();
            let mut matrix = vec![0.0; n * n];
            for i in 0..n {
                for j in 0..=i {
                    let mut sum = 0.0;
                    for (c, gram) in gram.iter().enumerate() {
                        let (di, dj) = (directions[i][c], directions[j][c]);
                        for a in 0..6 {
                            for b in 0..6 {
                                let g = if b <= a { gram[a][b] } else { gram[b][a] };
                                sum += di[a] * g * dj[b];
                            }
                        }
                    }
                    matrix[i * n + j] = 2.0 * sum;
                    matrix[j * n + i] = matrix[i * n + j];
                }
            }
            matrix
        });
        (value, gradient, gauss_newton)
    }

    /// The gradient by the coordinates `x` of a loss with slopes `slopes` (one per render of
    /// unexposed value `raws`) through a batch-kernel part with tangents `tangents` that every
    /// render contains, and through the exposure: the slopes weight the pixel tangents into derivatives by the kernel's
    /// parameters, and one dual number per coordinate carries those through
    /// `ParamSpace::surface`.
    fn batch_gradient(
        &self,
        x: &[f64],
        slopes: &[Vec<[f64; 3]>],
        raws: &[&[[f64; 3]]],
        tangents: &PixelTangents,
        exposure: f64,
    ) -> Vec<f64> {
        let mut by = KernelSlopes::default();
        for (slope, raw) in slopes.iter().zip(raws) {
            for (k, dl) in slope.iter().enumerate() {
                for c in 0..3 {
                    let d = dl[c] * exposure;
                    by.ax += d * tangents.ax[k][c];
                    by.ay += d * tangents.ay[k][c];
                    by.fresnel_a[c] += d * tangents.fresnel_a[k][c];
                    by.fresnel_b[c] += d * tangents.fresnel_b[k][c];
                    by.diffuse[c] += d * tangents.diffuse[k][c];
                    by.exposure += dl[c] * raw[k][c];
                }
            }
        }
        self.coordinate_surfaces(x)
            .iter()
            .map(|surface| by.along(surface))
            .collect()
    }

    /// The surface at `x` once per coordinate, with that coordinate's unit derivative.
    fn coordinate_surfaces(&self, x: &[f64]) -> Vec<Surface<Dual64>> {
        (0..x.len())
            .map(|i| {
                let coords: Vec<Dual64> = x
                    .iter()
                    .enumerate()
                    .map(|(j, &v)| {
                        let v = Dual64::from_re(v);
                        if i == j {
                            v.derivative()
                        } else {
                            v
                        }
                    })
                    .collect();
                self.space.surface(&coords)
            })
            .collect()
    }

    /// [`kernel_directions`] of each coordinate at `x`.
    fn coordinate_directions(&self, x: &[f64]) -> Vec<[[f64; 6]; 3]> {
        self.coordinate_surfaces(x)
            .iter()
            .map(kernel_directions)
            .collect()
    }

    /// Whether [`Objective::gauss_newton`] serves this objective: a deterministic model with
    /// exact derivatives (the batch kernel's tangents or dual numbers: every analytic model
    /// and `tabulated`), a squared-error loss, and at most [`MAX_EXACT_DIM`] coordinates.
    pub fn has_gauss_newton(&self) -> bool {
        !self.stochastic
            && self.gradient == GradientMethod::Exact
            && matches!(self.kind, LossKind::L2 | LossKind::RelativeL2)
            && self.space.dim() <= MAX_EXACT_DIM
            && self.space.model.capabilities().generic
    }

    /// The normalised cost at `x`, its gradient and its Gauss-Newton matrix `2 J^T V J`
    /// (row-major, `dim x dim`), where `J` is the prediction's Jacobian by the coordinates
    /// and `V` the loss's weights ([`Loss::quadratic_weights`]): the cost's Hessian less the
    /// residuals' curvature terms (Nocedal & Wright 2006, eq. 10.24), from the same pass as
    /// the cost and the gradient ([`Objective::exact_pass`]). `None` where
    /// [`Objective::has_gauss_newton`] does not hold.
    pub fn gauss_newton(&self, x: &[f64]) -> Option<(f64, Vec<f64>, Vec<f64>)> {
        if !self.has_gauss_newton() {
            return None;
        }
        let (cost, gradient, matrix) = self.exact_pass(x, true)?;
        Some((cost, gradient, matrix?))
    }

    /// Undo the normalisation of a cost reported by the optimiser.
    pub fn loss_from_cost(&self, cost: f64) -> f64 {
        cost * self.scale
    }
}

/// `pi lambert sum_a w_a multi_a`: a pixel's sub-sample sum of the multiple-bounce term
/// interpolated from the anchors `corners` (see [`Objective::anchored_part`]), from any
/// per-anchor quantity that enters linearly, per channel.
pub fn interpolate<const N: usize>(
    corners: &Corners,
    multi: &[[f64; N]],
    lambert: &[f64; 3],
) -> [f64; N] {
    let mut sum = [0.0; N];
    for &(a, w) in corners {
        for (s, m) in sum.iter_mut().zip(&multi[a as usize]) {
            *s += w * m;
        }
    }
    std::array::from_fn(|i| sum[i] * PI * lambert[i % 3])
}

/// One seed's values before the interpolation ([`Objective::anchored_values_of`]).
pub struct AnchoredValues<T> {
    /// The multiple-bounce estimate at each anchor.
    pub multi: Vec<Rgb<T>>,
    /// The pixels without anchors (position in the pixel list) and their specular values.
    pub exact: Vec<(usize, [T; 3])>,
}

/// A render through anchors at one point, per seed, before its interpolation
/// ([`Objective::anchored_values`]).
pub struct AnchoredRender<'o> {
    pub anchors: &'o Anchors,
    /// Per pixel of the list: its white Lambertian radiance.
    pub lambert: &'o [[f64; 3]],
    /// The part every seed shares ([`crate::render::SplitRender::shared`]) as an affine
    /// function of a Schlick F0, `[value at F0 = 0, slope]` per pixel and channel, when asked
    /// for.
    pub shared: Option<Vec<[[f64; 2]; 3]>>,
    /// Per seed: the anchors' values and the pixels without anchors.
    pub streams: Vec<AnchoredValues<f64>>,
}

/// Channel-free parts of `tabulated`'s multiple-bounce lobe at one direction pair: per order
/// group (2, 3, >= 4) the three coefficients of a quadratic in a Schlick F0
/// ([`Tabulated::schlick_orders_at`]).
pub const ORDER_PARTS: usize = 9;

/// A `tabulated` render split so that its Schlick F0 can vary ([`Objective::order_parts`]):
/// a channel with F0 `f` renders `A + B f + sum_g inner_g(f) (q_g0 + q_g1 f + q_g2 f^2)`.
pub struct OrderParts<'o> {
    /// The single bounce at every loss pixel, affine in F0: `[A, B]` per channel.
    pub single: Vec<[[f64; 2]; 3]>,
    /// The anchors the multiple-bounce term is interpolated from, or `None` where every pixel
    /// is evaluated exactly.
    pub anchors: Option<&'o Anchors>,
    /// Per loss pixel: its white Lambertian radiance, by which [`interpolate`] scales the
    /// anchors.
    pub lambert: &'o [[f64; 3]],
    /// Per anchor: the parts at its geometry, part `j` of channel `c` at `3 j + c` (the same
    /// for every channel), laid out for [`interpolate`].
    pub multi: Vec<[f64; 3 * ORDER_PARTS]>,
    /// The pixels without anchors (position in the pixel list) in increasing order, with their
    /// parts summed over their sub-samples and weighted by each channel's irradiance, laid out
    /// as `multi`.
    pub exact: Vec<(usize, [f64; 3 * ORDER_PARTS])>,
    /// The inner factors, which do not depend on the pixel.
    pub orders: SchlickOrders,
}

/// The parts of a `kulla-conty` render ([`Objective::compensation_parts`]), per loss pixel.
pub struct CompensationParts {
    /// The single bounce as an affine function of a Schlick F0: `[value at F0 = 0, slope]`
    /// per channel.
    pub single: Vec<[[f64; 2]; 3]>,
    /// Single bounce and compensation lobe, at the F0 of the point asked for.
    pub whole: Vec<[f64; 3]>,
}

/// One seed's part of a render through anchors ([`Objective::anchored_part`]).
struct AnchoredPart<T> {
    /// The multiple-bounce estimate at each anchor.
    multi: Vec<Rgb<T>>,
    /// The pixels without anchors (position in the pixel list) and their specular values.
    exact: Vec<(usize, [T; 3])>,
    /// The part at every pixel, in `f64`.
    own: Vec<[f64; 3]>,
}

/// The derivative part of a dual number as an array (zero where it has none).
fn dual_parts<const N: usize>(v: DualSVec64<N>) -> [f64; N] {
    let mut parts = [0.0; N];
    if let Some(d) = &v.eps.0 {
        parts.copy_from_slice(d.as_slice());
    }
    parts
}

/// `gradient += sum over renders, pixels and channels of slope * d render / d x`, the
/// derivatives being the dual parts of `renders`.
fn add_dual_slopes<const N: usize>(
    gradient: &mut [f64],
    renders: &[Vec<[DualSVec64<N>; 3]>],
    slopes: &[Vec<[f64; 3]>],
) {
    for (render, slope) in renders.iter().zip(slopes) {
        for (p, dl) in render.iter().zip(slope) {
            for c in 0..3 {
                if let Some(dp) = &p[c].eps.0 {
                    gradient
                        .iter_mut()
                        .zip(dp.iter())
                        .for_each(|(g, d)| *g += dl[c] * d);
                }
            }
        }
    }
}

/// Derivatives of a loss by the parameters of the batch kernel (see
/// [`crate::render::batch::PixelTangents`]) and by the exposure.
#[derive(Default)]
struct KernelSlopes {
    ax: f64,
    ay: f64,
    fresnel_a: [f64; 3],
    fresnel_b: [f64; 3],
    diffuse: [f64; 3],
    exposure: f64,
}

impl KernelSlopes {
    /// The loss's derivative along the direction whose effect on the parameters is the
    /// derivative part of `surface`.
    fn along(&self, surface: &Surface<Dual64>) -> f64 {
        let d = kernel_directions(surface);
        let mut sum = self.ax * d[0][0] + self.ay * d[0][1] + self.exposure * d[0][5];
        for (c, d) in d.iter().enumerate() {
            sum += self.fresnel_a[c] * d[2] + self.fresnel_b[c] * d[3] + self.diffuse[c] * d[4];
        }
        sum
    }
}

/// Per channel, the derivative parts of the batch kernel's parameters that act on it, in
/// the order of [`PixelTangents`]: `[ax, ay, fresnel_a_c, fresnel_b_c, diffuse_c, exposure]`
/// (the roughness and the exposure are the same in every channel).
fn kernel_directions(surface: &Surface<Dual64>) -> [[f64; 6]; 3] {
    use crate::microfacet::Fresnel;
    let mf = &surface.single.microfacet;
    let (a, b) = match surface.single.fresnel {
        Fresnel::Schlick { f0 } => (f0.0.map(|v| v.eps), [0.0; 3]),
        Fresnel::Conductor { eta, k } => (eta.0.map(|v| v.eps), k.0.map(|v| v.eps)),
        Fresnel::White | Fresnel::Dielectric { .. } => ([0.0; 3], [0.0; 3]),
    };
    [0, 1, 2].map(|c| {
        [
            mf.ax.eps,
            mf.ay.eps,
            a[c],
            b[c],
            surface.diffuse[c].eps,
            surface.exposure.eps,
        ]
    })
}

impl CostFunction for &Objective<'_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, x: &Vec<f64>) -> Result<f64, ArgminError> {
        Ok(self.normalised_cost(x))
    }
}

impl Gradient for &Objective<'_> {
    type Param = Vec<f64>;
    type Gradient = Vec<f64>;
    /// Exact (dual numbers) when [`Objective::gradient_method`] says so, otherwise central
    /// differences with step `FD_STEP * max(1, |x_i|)`.
    fn gradient(&self, x: &Vec<f64>) -> Result<Vec<f64>, ArgminError> {
        if self.gradient == GradientMethod::Exact {
            if let Some((_, gradient)) = self.exact_cost_and_gradient(x) {
                return Ok(gradient);
            }
        }
        Ok(self.fd_gradient(x))
    }
}

impl Objective<'_> {
    /// Central differences of the normalised cost with step `FD_STEP * max(1, |x_i|)`, at the
    /// same random numbers for both probes.
    pub fn fd_gradient(&self, x: &[f64]) -> Vec<f64> {
        let mut probe = x.to_vec();
        (0..x.len())
            .map(|i| {
                let h = FD_STEP * x[i].abs().max(1.0);
                probe[i] = x[i] + h;
                let plus = self.normalised_cost(&probe);
                probe[i] = x[i] - h;
                let minus = self.normalised_cost(&probe);
                probe[i] = x[i];
                (plus - minus) / (2.0 * h)
            })
            .collect()
    }
}

#[cfg(test)]
pub(crate) mod tests;
