//! Scene-aware work skipping for repeated renders of the same pixels (issue #5 item 1): a
//! [`RenderPlan`] is built once per objective from the records and the model, and every render
//! of the fit goes through it. Each skip can be switched off (`--no-skip`) for comparison; the
//! `bench` command measures what each one saves and what it changes.
//!
//! | skip (`--no-skip` name) | what is not computed | error it adds |
//! | --- | --- | --- |
//! | pixels that cannot matter (always) | pixels of weight 0 (outside the sample, masked, saturated, non-finite, negative) and sub-samples without irradiance | none: they do not enter the loss |
//! | `repeated` | for the stochastic models, the estimate at a sub-sample whose `(wi, wo)` repeats another's ([`super::repeated`]), when their full value is evaluated per sub-sample (`sparse-multi` off or not applicable) | none in expectation; the repeats share one estimate's noise |
//! | `sparse-multi` | the multiple-bounce term off a grid of anchors ([`super::anchors`]) | at most [`SPARSE_TOLERANCE`] of the RMS radiance, measured on the records with proxy lobes |
//! | `faint-multi` | the multiple-bounce term when its white albedo at the current roughness, `1 - E_avg(alpha)` (Kulla & Conty 2017, eq. 7), is below [`FAINT_TOLERANCE`] | below [`FAINT_TOLERANCE`] of the energy |
//! | `bounce-cap` | for the stochastic models, paths of more than `K` reflections, `K` the fewest whose tail `T(K, alpha)` at the current roughness ([`crate::bsdf::bounce_tails`]: largest over incidences, white Fresnel) is at most [`BOUNCE_TOLERANCE`]; no cap where even 16 leave more | the dropped tail: below [`BOUNCE_TOLERANCE`] of the energy, a bias toward less multiple scattering |
//!
//! `repeated` is kept to the stochastic models because measurement says so: on an exposure
//! bracket of copper-flash (18 photos, every pair repeated once) sharing evaluations made the
//! `single` fit 11% slower (12.2 s against 10.9 s: the lookup and the buffer of dual numbers cost
//! more than a 29 ns evaluation) and `kulla-conty` no faster (28.0 s against 28.7 s), while an
//! estimator costs 300-650 ns per evaluation. With `sparse-multi` on, only the cheap single
//! term is left per sub-sample, so the plan does not look for repeats.
//!
//! `bounce-cap` saves little, by measurement: white walks average 1.2 reflections at alpha 0.3
//! and 2.0-2.2 at alpha 1 (energy-weighted), while the caps are 4-5 and 7-8 reflections there
//! (GGX), so only the rare long walks are cut. On copper at alpha 0.3 and 1.0 the criterion
//! group `bounce_cap` of `benches/estimators.rs` timed capped and free evaluations within
//! +-10% of each other in both directions (a shared 2-core machine; no consistent saving), and
//! fits of `copper-flash` (128x128, alpha near 0.29) by the five estimators moved alpha by
//! 2e-6 to 5e-4 relative (heitz, fitted by Nelder-Mead: 2e-3), at equal time per evaluation
//! within the machine's noise. It is kept because it bounds the work of a
//! walk at large roughness, where tails are long, at a stated cost of 1e-3 of the energy.
//!
//! `sparse-multi` applies to the models whose added term is an additive lobe (`kulla-conty`,
//! `fast-msx` and the stochastic estimators); `turquin` scales the single lobe, so its added
//! term has the single lobe's sharpness and is evaluated exactly. A fit's objective switches
//! `sparse-multi` off for `kulla-conty` and `fast-msx` too: the batch kernel evaluates their
//! lobes at every sub-sample for less than the anchors cost (`crate::render::batch::Lobe::of`).
//! `faint-multi` applies to the energy-conserving models whose multiple scattering is bounded
//! by the energy single scattering loses; `fast-msx` is not (its lobe can exceed it, see
//! docs/models.md), so it keeps its term.

use super::anchors::Anchors;
use super::repeated::Repeated;
use crate::bsdf::albedo_table::AlbedoTable;
use crate::bsdf::bounce_tails::BounceTails;
use crate::bsdf::single::SingleBounce;
use crate::bsdf::{BounceCap, Model};
use crate::material::Material;
use crate::microfacet::{Height, NdfKind};
use crate::scalar::Real;
use crate::shading::ShadingRecords;
use serde::{Deserialize, Serialize};

/// Largest interpolation error of the sparse multiple-bounce term, relative to the RMS
/// radiance of the loss pixels: adds about `1e-6` of the squared signal to an L2 loss, against
/// `4e-4` for 2% photo noise.
pub const SPARSE_TOLERANCE: f64 = 1e-3;

/// Largest white multiple-scattering albedo that is skipped.
pub const FAINT_TOLERANCE: f64 = 1e-3;

/// Largest fraction of the white albedo carried by the paths the bounce cap drops.
pub const BOUNCE_TOLERANCE: f64 = 1e-3;

/// A skip that `--no-skip` can switch off.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Skip {
    /// One evaluation per distinct `(wi, wo)`.
    Repeated,
    /// The multiple-bounce term on an anchor grid, interpolated.
    SparseMulti,
    /// No multiple-bounce term where its albedo is negligible.
    FaintMulti,
    /// Walks stop after the reflections that carry all but a negligible energy.
    BounceCap,
    /// Every skip above.
    All,
}

/// Which skips are on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Skips {
    pub repeated: bool,
    pub sparse_multi: bool,
    pub faint_multi: bool,
    pub bounce_cap: bool,
}

impl Default for Skips {
    fn default() -> Self {
        Skips::all()
    }
}

impl Skips {
    pub fn all() -> Skips {
        Skips {
            repeated: true,
            sparse_multi: true,
            faint_multi: true,
            bounce_cap: true,
        }
    }

    pub fn none() -> Skips {
        Skips {
            repeated: false,
            sparse_multi: false,
            faint_multi: false,
            bounce_cap: false,
        }
    }

    /// Every skip except those named (the `--no-skip` list).
    pub fn except(off: &[Skip]) -> Skips {
        let mut skips = Skips::all();
        for skip in off {
            match skip {
                Skip::Repeated => skips.repeated = false,
                Skip::SparseMulti => skips.sparse_multi = false,
                Skip::FaintMulti => skips.faint_multi = false,
                Skip::BounceCap => skips.bounce_cap = false,
                Skip::All => skips = Skips::none(),
            }
        }
        skips
    }

    pub fn any(&self) -> bool {
        self.repeated || self.sparse_multi || self.faint_multi || self.bounce_cap
    }
}

/// What a plan found in the records, for fit files and benchmarks.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PlanSummary {
    /// Stride of the anchor grid of the multiple-bounce term (1: evaluated at every sub-sample).
    pub multi_stride: usize,
    /// Anchors evaluated per render.
    pub anchors: usize,
    /// Pixels evaluated exactly because an anchor around them has no geometry (no pixel within
    /// one stride of it sees the sample).
    pub exact_pixels: usize,
    /// BRDF evaluations saved per render by repeated geometry.
    pub repeated_saved: usize,
    /// Roughness below which the multiple-bounce term is skipped (0: never).
    pub faint_below_alpha: f64,
    /// Most reflections per path at the fitted roughness (`None`: no cap).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bounce_cap: Option<u32>,
}

/// How the multiple-bounce term of one render is computed.
pub enum MultiTerm<'a> {
    /// At every sub-sample, with the single term.
    Exact,
    /// On the anchors, interpolated.
    Sparse(&'a Anchors),
    /// Not at all.
    Skipped,
}

/// The skips that apply to one model over one pixel list.
#[derive(Clone)]
pub struct RenderPlan {
    pub skips: Skips,
    pub stochastic: bool,
    pub anchors: Option<Anchors>,
    pub repeated: Option<Repeated>,
    /// Table whose `E_avg` decides `faint-multi`, for the models it applies to.
    faint: Option<&'static AlbedoTable>,
    /// Table whose tails decide `bounce-cap`, for the stochastic models.
    tails: Option<&'static BounceTails>,
}

impl RenderPlan {
    /// A plan that skips nothing: renders as [`super::render_model`] does.
    pub fn exact() -> RenderPlan {
        RenderPlan {
            skips: Skips::none(),
            stochastic: false,
            anchors: None,
            repeated: None,
            faint: None,
            tails: None,
        }
    }

    /// The plan of `model` (with `ndf`, `height`) over `pixels` of `records`.
    pub fn new(
        skips: Skips,
        (model, ndf, height): (Model, NdfKind, Height),
        records: &ShadingRecords,
        pixels: &[usize],
    ) -> RenderPlan {
        let capabilities = model.capabilities();
        let stochastic = capabilities.stochastic();
        let multi = capabilities.multi;
        let sparse_model = multi.is_some_and(|m| m.smooth);
        let faint_model = multi.is_some_and(|m| m.within_lost_energy);
        let anchors = (skips.sparse_multi && sparse_model)
            .then(|| Anchors::choose(records, pixels, ndf, height, SPARSE_TOLERANCE))
            .flatten();
        let repeated = (skips.repeated && stochastic && anchors.is_none())
            .then(|| Repeated::find(records, pixels))
            .flatten();
        RenderPlan {
            skips,
            stochastic,
            anchors,
            repeated,
            faint: (skips.faint_multi && faint_model).then(|| AlbedoTable::get(ndf, height)),
            tails: skips
                .bounce_cap
                .then(|| BounceTails::get(model, ndf, height))
                .flatten(),
        }
    }

    /// The plan of `material`'s model over `pixels` of `records`.
    pub fn for_material(
        skips: Skips,
        material: &Material,
        records: &ShadingRecords,
        pixels: &[usize],
    ) -> RenderPlan {
        let kind = (material.model, material.ndf, material.height);
        RenderPlan::new(skips, kind, records, pixels)
    }

    /// The multiple-bounce treatment of a render at the roughness of `single`.
    pub fn multi_term<T: Real>(&self, single: &SingleBounce<T>) -> MultiTerm<'_> {
        if let Some(table) = self.faint {
            let mf = &single.microfacet;
            let alpha = (mf.ax.re64() * mf.ay.re64()).sqrt();
            if 1.0 - table.e_avg(alpha) < FAINT_TOLERANCE {
                return MultiTerm::Skipped;
            }
        }
        match &self.anchors {
            Some(anchors) => MultiTerm::Sparse(anchors),
            None => MultiTerm::Exact,
        }
    }

    /// The bounce cap of a render at the roughness of `single`: the fewest reflections whose
    /// tail is within [`BOUNCE_TOLERANCE`] at `max(ax, ay)` (the larger roughness has the
    /// longer tail), or none.
    pub fn bounce_cap<T: Real>(&self, single: &SingleBounce<T>) -> BounceCap {
        self.tails.map_or(BounceCap::NONE, |tails| {
            let mf = &single.microfacet;
            tails.cap(mf.ax.re64().max(mf.ay.re64()), BOUNCE_TOLERANCE)
        })
    }

    /// What the plan skips, with the bounce cap at the roughness of `material`.
    pub fn summary(&self, material: &Material) -> PlanSummary {
        PlanSummary {
            bounce_cap: self.bounce_cap(&material.single::<f64>()).get(),
            multi_stride: self.anchors.as_ref().map_or(1, |a| a.stride),
            anchors: self.anchors.as_ref().map_or(0, |a| a.points.len()),
            exact_pixels: self.anchors.as_ref().map_or(0, |a| a.exact_pixels()),
            repeated_saved: self.repeated.as_ref().map_or(0, |r| r.saved()),
            faint_below_alpha: self.faint.map_or(0.0, faint_threshold),
        }
    }
}

/// The roughness below which `1 - E_avg(alpha) < FAINT_TOLERANCE` (bisection in log alpha;
/// `E_avg` falls with roughness).
fn faint_threshold(table: &AlbedoTable) -> f64 {
    let faint = |alpha: f64| 1.0 - table.e_avg(alpha) < FAINT_TOLERANCE;
    let (mut lo, mut hi) = (1e-4f64, 3.0f64);
    if !faint(lo) {
        return 0.0;
    }
    for _ in 0..60 {
        let mid = (lo * hi).sqrt();
        if faint(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}
