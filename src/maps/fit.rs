//! Fitting material maps to a photo set (issue #17 item 2, `fit --maps`).
//!
//! A flash photo set shows each texel from a handful of directions near the mirror direction,
//! so a free per-texel fit is ill-posed where no highlight crosses the texel: roughness and F0
//! then trade against each other along the lobe's tail. The fit makes the problem well posed
//! the way Lensch et al. 2003 ("Image-based reconstruction of spatial appearance and
//! geometric detail", section 5: clustering into basis materials) and Nam et al. 2018
//! (section 4.2: basis BRDFs shared by all points) do: texels are grouped into `K` basis
//! materials, and each texel's specular parameters are drawn toward its basis by a Gaussian
//! prior, so a texel the data pin down keeps its own values and a texel they do not takes its
//! basis's.
//!
//! | stage | what | how |
//! | --- | --- | --- |
//! | 1 | each texel alone, weak prior toward a generic material (a metal's F0 where measured conductors' are, [`METAL_F0_LOGIT`]) | Levenberg-Marquardt per texel from three roughness starts (0.05, 0.2, 0.6) |
//! | 2 | noise level | `sigma^2 = sum r^2 / (residuals - parameters)` of stage 1, so the data term is a Gaussian log-likelihood and the prior's units are those of the coordinates |
//! | 3 | `K` basis materials | k-means over the texels' specular coordinates (`ln alpha`, `logit F0`), each coordinate weighted by its Gauss-Newton precision `(J^T J)_jj` (a texel's diagonal Laplace approximation), so poorly seen texels hardly move the bases and are assigned by what is seen of them |
//! | 4 | maps | per-texel maximum a posteriori fit: prior `N(basis, 0.25^2)` on `ln alpha` and `N(basis, 0.5^2)` on `logit F0`, flat-ish `N(0, 3^2)` on `logit diffuse`, `N(0, 0.25^2)` on normal slopes; each texel as either kind (a texel of the basis's other kind takes only its roughness), from the texel's own and its basis's coordinates, then a second round of re-assignment and re-fit from its own; the texels' priors are centred on the precision-weighted means of their basis's texels, and the bases reported are then re-estimated by maximum likelihood on the photos of their texels of their kind together (Gauss-Newton, each texel's own albedo re-fitted with it, texels the basis cannot explain left out, [`pooled_centre`]), since that mean is biased low under noise |
//! | 5 | choice of `K` and of a roughness floor | 1 to `max_bases`, each with each floor of [`ROUGHNESS_FLOORS`] (none, 0.05 to 0.8) laid on the fitted texels' roughness, by the relative error of a photo left out of stages 1-4 (the validation photo), on a quarter of the texels and at their resolution ([`texel_relative_error`]); of the `K` within 2% of the best error, the one with the lowest BIC of its clustering ([`fewest_good_bases`]; blends of two bases (texels all on edges, lying between two bases), bases that do not pay for themselves in that BIC, bases left with under 1% of the texels or covering no 2 x 2 block of them, and bases their texels' photos do not pay for in Schwarz's criterion are dropped, [`Clusters::drop_non_materials`], [`take_negligible_bases_texels`], [`Clusters::drop_empty`]), with their best floor, and refitted on every photo and texel, the floor laid on the result (a cross-validated regulariser, as the smoothing weight of Hastie, Tibshirani & Friedman section 7.10); with [`Normals::Auto`], stage 5 runs without and with normals, and normals are kept only when their best validation error beats the other's by more than 2% |
//!
//! On a grid of more than [`MapsFitOptions::coarsest`] texels (default [`COARSEST_SIDE`]^2),
//! the five stages run on a grid of half the resolution with photos of half the resolution,
//! recursively, and each finer grid refines the texels from the coarser one, choosing the
//! roughness floor anew ([`refine`]): 1024^2 in about a minute and a half on two cores in
//! place of ten.
//!
//! Texels are independent given the bases, so each is a small dense problem (4 to 10
//! coordinates: `ln alpha` (with `anisotropic`, `ln alpha_x` and `ln alpha_y`, each with the
//! prior of `ln alpha`), `logit F0` RGB unless the Fresnel is known, `logit diffuse` RGB,
//! and with `normals` two slopes) solved with exact dual-number Jacobians
//! (`DualSVec64<N>`) through the model's own generic kernel, in parallel over texels and
//! bit-identical for any thread count. A pixel belongs to the texel its centre sees and is
//! predicted with that texel's parameters at every sub-sample; texels no pixel sees take the
//! coordinates of the nearest seen texel.
//!
//! Models: the analytic ones (`single`, `fast-msx`, `kulla-conty`, `turquin`, and `tabulated`,
//! which carries the reference lobe of `heitz`). The stochastic
//! estimators would give each texel a noisy objective from a few dozen records and cost
//! thousands of walks per texel per iteration; they are refused with that reason.

use super::{normal_from_slopes, MaterialMaps, ShadingFrame, TexelGrid};
use crate::bsdf::registry::differentiable;
use crate::bsdf::single::SingleBounce;
use crate::bsdf::tabulated::{LobeDirections, Tabulated};
use crate::bsdf::{BounceCap, Model, ScalarBrdf};

use crate::error::{Error, Result};
use crate::fit::bayes::holdout::relative_error;
use crate::fit::point::params::{logit, sigmoid, ParamSpace};
use crate::material::{FresnelSpec, Material};
use crate::progress::Reporting;
use crate::random::Rng;
use crate::scalar::{Real, Rgb, Vec3};
use crate::shading::ShadingRecords;
use nalgebra::{SMatrix, SVector};
use num_dual::{Dual64, DualSVec64};
use rand::SeedableRng;
use rayon::prelude::*;
use serde::Serialize;
use std::f64::consts::FRAC_1_PI;
use std::time::Instant;

mod refine;

/// Prior standard deviations (coordinate units), see the module table.
const SIGMA_LN_ALPHA: f64 = 0.25;
const SIGMA_LOGIT_F0: f64 = 0.5;
const SIGMA_WEAK: f64 = 3.0;
const SIGMA_SLOPE: f64 = 0.25;
/// A dielectric's F0 (IOR 1.5) and how far from it the prior lets a dielectric go (logit sd
/// 0.3: F0 0.03 to 0.055 at one sd).
const DIELECTRIC_F0: f64 = 0.04;
const SIGMA_DIELECTRIC_F0: f64 = 0.3;
/// A metal's F0 where nothing else is known of it: `logit F0` drawn toward 1.13 (F0 0.76) with
/// sd 1.46, the mean and spread of `logit F0` over the 27 normal-incidence reflectances (450,
/// 550 and 650 nm) of the nine conductors of `../shared/data/conductors_nk.json` (Cu, Au, Ag,
/// Al, Cr, Ni, Ti, Fe, W: 0.41 to 0.99). Before, a metal's F0 was free (logit sd 3 about 0.5),
/// and a dark dielectric fitted as a grey metal of F0 0.13 as well as it fitted as what it is:
/// a rubber band (F0 0.04, albedo 0.05) became such a metal at one pixel per texel and was
/// lost as a basis (docs/maps.md, "A truth these changes were not made on").
const METAL_F0_LOGIT: f64 = 1.13;
const SIGMA_METAL_F0: f64 = 1.46;
/// A metal's diffuse albedo: logit(1e-4) with sd 1, i.e. none.
const METAL_DIFFUSE: f64 = 1e-4;
const SIGMA_METAL_DIFFUSE: f64 = 1.0;
/// Stage 1's roughness prior centre and starts.
const GENERIC_ALPHA: f64 = 0.3;
const ALPHA_STARTS: [f64; 2] = [0.08, 0.4];
/// Levenberg-Marquardt iterations per texel and solve.
const MAX_ITERATIONS: usize = 40;
/// A texel's Levenberg-Marquardt solve stops once the Gauss-Newton model at its point predicts
/// less than this decrease of its cost (twice the negative log posterior) to the model's
/// minimum, the cost counted in units of the larger of the noise variance the solve assumes
/// and the texel's own mean squared residual. A decrease of 1e-3 there is a move of about 0.03
/// posterior standard deviations. Before, a solve went on while a step gained 1e-9 of the
/// cost: on the real yellow_box (`single`, 256^2 texels) a solve took 18 Jacobians, and 43% of
/// the steps came after one that had gained less than 1e-3. Stage 1 measures its cost against
/// 1% of the RMS target (the noise is not yet known), a hundredth of a real capture's
/// residuals, so there the texel's own residual is the scale.
const NEGLIGIBLE_DECREASE: f64 = 1e-3;
/// Rounds of re-assignment and re-fit in stage 4.
const ROUNDS: usize = 2;
/// Potts coupling of the basis labels: the posterior cost (twice the negative log posterior)
/// of each 4-neighbour with another label, and the most sweeps of its minimisation.
const LABEL_COUPLING: f64 = 6.0;
/// The posterior cost of a texel of the other kind than its basis: `2 ln 1000`, a prior
/// probability of 1 in 1000 that a texel of a basis is not of its kind, so a texel leaves its
/// basis's kind only where its own photos say so clearly (a tile's grout beside the glaze).
/// With 1 in 20 (cost 6), texels on the boundaries of the synthetic two-material set switched
/// and its albedo error tripled (0.005 to 0.016 RMS).
const KIND_SWITCH: f64 = 13.8;
const ICM_SWEEPS: usize = 10;
/// The numbers of bases whose validation error is within this fraction of the best are those
/// the validation photo cannot tell apart; [`fewest_good_bases`] chooses among them (as the
/// "one standard error" rule of Hastie, Tibshirani & Friedman, *The Elements of
/// Statistical Learning*, section 7.10: an extra basis that gains less than the noise of the
/// validation error only fits noise; on the synthetic two-material sets the gains past the
/// true count are 0.1-0.5%).
const PARSIMONY: f64 = 0.02;

/// The roughness floors stage 5 tries (steps of sqrt 2 from 0.05 to 0.8; `None` is no
/// floor). Texels sharper than their photos support are the largest error of a maps fit of a
/// real capture: on real_cards-blue (one basis, alpha 0.19), the 3% of texels below alpha
/// 0.08 gave 40% of the held-out photo's squared error, predicting highlights the photo does
/// not have; 92% of them lie within 2 pixels of a saturated pixel of some training photo. A
/// texel's highlight in its few near-mirror photos is where the capture's geometry is least
/// sure (the flash is taken to be at the lens, and is not quite), and a sharp lobe fits that
/// highlight at the wrong angles. The floor is chosen by the validation photo with the number
/// of bases, so a sample that is truly sharp keeps no floor.
const ROUGHNESS_FLOORS: [Option<f64>; 10] = [
    None,
    Some(0.05),
    Some(0.0707),
    Some(0.1),
    Some(0.141),
    Some(0.2),
    Some(0.283),
    Some(0.4),
    Some(0.566),
    Some(0.8),
];

/// Whether a maps fit has a shading normal per texel (`fit --maps --normals[=on|off|auto]`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Normals {
    /// Geometric normal everywhere.
    #[default]
    Off,
    /// A normal per texel.
    On,
    /// Both fitted in stage 5, on the photos other than the validation photo; the maps get
    /// normals when, at its best number of bases, a fit with normals predicts the validation
    /// photo better than one without by more than [`PARSIMONY`] (without a validation photo:
    /// none).
    Auto,
}

/// The side of the largest texel grid the bases are chosen on by default
/// ([`MapsFitOptions::coarsest`]): the grid of the synthetic truths the choice of bases was
/// measured on (docs/maps.md: 16^2 to 128^2 texels).
pub const COARSEST_SIDE: usize = 128;

/// What a maps fit searches.
#[derive(Clone, Debug)]
pub struct MapsFitOptions {
    /// Model, distribution, height model and Fresnel (Schlick F0 per texel, or a known
    /// Fresnel); the diffuse albedo is always fitted.
    pub model: Model,
    pub ndf: crate::microfacet::NdfKind,
    pub height: crate::microfacet::Height,
    pub known_fresnel: Option<FresnelSpec>,
    /// Fit `alpha_x` and `alpha_y` per texel (else one isotropic `alpha`).
    pub anisotropic: bool,
    /// Texel grid over the sample.
    pub grid: TexelGrid,
    /// Fit a shading normal per texel: never, always, or where the validation photo says so.
    pub normals: Normals,
    /// Largest number of basis materials tried.
    pub max_bases: usize,
    /// A photo the fit does not see (index into the records' photos): its pixels are in no
    /// texel's block, as if its loss weights were 0, without a copy of the records.
    pub held_out_photo: Option<usize>,
    /// The photo left out to choose the number of bases (index into the records' photos);
    /// `None` fits `max_bases` bases without a choice.
    pub validation_photo: Option<usize>,
    /// The most texels the bases are chosen on: a finer grid is fitted at half the resolution
    /// (photos and texels) and refined from it ([`refine`]); `None` chooses them on `grid`.
    pub coarsest: Option<usize>,
    /// Where the stages' progress goes (a sink may stop the fit).
    pub progress: Reporting,
}

/// A basis material: the centre of its texels' specular coordinates.
#[derive(Clone, Debug, Serialize)]
pub struct Basis {
    pub kind: Kind,
    /// Roughness of the basis (no lower than the fit's roughness floor); of an anisotropic
    /// basis, `sqrt(alpha_x alpha_y)`.
    pub alpha: f64,
    /// `[alpha_x, alpha_y]` of the basis in an anisotropic fit.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub alpha_xy: Option<[f64; 2]>,
    /// Schlick F0 (absent with a known Fresnel).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub f0: Option<[f64; 3]>,
    /// Share of the texels assigned to it.
    pub share: f64,
}

/// The validation error of one number of bases.
#[derive(Clone, Debug, Serialize)]
pub struct BasisTrial {
    /// The number of bases tried (k-means' `K`).
    pub bases: usize,
    /// The bases left once the texels' labels were chosen: a basis no texel took is dropped
    /// ([`basis_fits`]), so this may be fewer than `bases`.
    pub bases_kept: usize,
    /// The roughness floor with the lowest validation error for this number of bases (`null`:
    /// none).
    pub roughness_floor: Option<f64>,
    /// Relative RMS error of the validation photo: `sqrt(sum (p - t)^2 / sum t^2)`, at that
    /// floor.
    pub validation_error: f64,
    /// The same without a floor.
    pub unfloored_validation_error: f64,
    /// The BIC of k-means' clustering of the texels' own estimates into these bases
    /// (`clustering_bic` in `src/maps/fit.rs`), which chooses among the numbers of bases the
    /// validation photo cannot tell apart.
    pub clustering_bic: f64,
}

/// The two validation errors that choose whether a maps fit has normals ([`Normals::Auto`]).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct NormalsTrial {
    pub without: f64,
    pub with: f64,
}

/// A maps fit: the maps and how they were found.
#[derive(Clone, Debug, Serialize)]
pub struct MapsFit {
    #[serde(skip)]
    pub maps: MaterialMaps,
    pub bases: Vec<Basis>,
    /// Validation error per number of bases (empty without a validation photo).
    pub basis_trials: Vec<BasisTrial>,
    /// The least roughness of any texel, chosen with the bases by the validation photo
    /// (`null`: none, and always without a validation photo).
    pub roughness_floor: Option<f64>,
    /// Whether the maps have a shading normal per texel.
    pub normals: bool,
    /// With `--normals=auto`: the least validation error over the numbers of bases without
    /// and with normals, which decided `normals`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub normals_trial: Option<NormalsTrial>,
    /// The texel grid the bases and their number were chosen at: `grid`, or a coarser one
    /// the texels were refined from ([`MapsFitOptions::coarsest`]).
    pub bases_grid: TexelGrid,
    /// Noise level of the photos, linear radiance units (stage 2).
    pub noise_sigma: f64,
    /// Relative RMS error over the fitted pixels.
    pub train_error: f64,
    /// Texels seen by at least one loss pixel.
    pub texels_seen: usize,
    pub seconds: f64,
    /// The basis (index into `bases`) of every texel, row-major over the texel grid: where
    /// each material lies on the sample (`compare --maps` reports differences per basis).
    #[serde(skip)]
    pub labels: Vec<usize>,
    /// Every texel's posterior standard deviations ([`texel_uncertainty`]).
    #[serde(skip)]
    pub uncertainty: Uncertainty,
}

/// Per-texel posterior standard deviations of a maps fit, row-major over its texel grid
/// ([`texel_uncertainty`]; docs/maps.md, "Uncertainty").
#[derive(Clone, Debug)]
pub struct Uncertainty {
    pub grid: TexelGrid,
    /// The sd of `ln alpha_x`, `ln alpha_y` and `ln sqrt(alpha_x alpha_y)` (the layout of the
    /// roughness map; one value thrice where isotropic): the relative sd of `alpha`, exact in the
    /// coordinate the posterior is Gaussian in, so `alpha exp(+-2 sd)` is its 95% interval.
    pub roughness: Vec<[f32; 3]>,
    /// The sd of Schlick F0 per channel, from that of `logit F0` by the delta method (`F0 (1 -
    /// F0)` times it); `None` with a known Fresnel.
    pub specular: Option<Vec<[f32; 3]>>,
    /// The sd of the diffuse albedo per channel, from that of `logit albedo` likewise.
    pub diffuse: Vec<[f32; 3]>,
}

/// The pixels of each texel (compressed rows): pixels with loss weight > 0, by the texel their
/// centre sub-sample sees.
struct TexelBlocks {
    offsets: Vec<usize>,
    pixels: Vec<usize>,
    grid: TexelGrid,
    /// Texels on this stride are in the blocks, the others have no pixels.
    stride: usize,
}

impl TexelBlocks {
    /// The blocks of the texels on a grid of `stride` (1: every texel; 2: every other texel
    /// of every other row, the texel sample the choice of `K` works on), without the pixels of
    /// the photos `unseen` (indices into the records' photos).
    fn new(
        records: &ShadingRecords,
        grid: TexelGrid,
        stride: usize,
        unseen: &[usize],
    ) -> TexelBlocks {
        let spp = records.samples_per_pixel;
        let mut counts = vec![0usize; grid.len() + 1];
        let texel_of = |p: usize| grid.texel(records.uv[p * spp + spp / 2]);
        let on_stride = |t: usize| (t % grid.width) % stride == 0 && (t / grid.width) % stride == 0;
        let unseen: Vec<std::ops::Range<usize>> =
            unseen.iter().map(|&i| records.photos[i].pixels()).collect();
        let used: Vec<usize> = (0..records.pixel_count())
            .filter(|&p| {
                records.weight[p] > 0.0
                    && on_stride(texel_of(p))
                    && !unseen.iter().any(|photo| photo.contains(&p))
            })
            .collect();
        for &p in &used {
            counts[texel_of(p) + 1] += 1;
        }
        for t in 0..grid.len() {
            counts[t + 1] += counts[t];
        }
        let mut next = counts.clone();
        let mut pixels = vec![0; used.len()];
        for &p in &used {
            let t = texel_of(p);
            pixels[next[t]] = p;
            next[t] += 1;
        }
        TexelBlocks {
            offsets: counts,
            pixels,
            grid,
            stride,
        }
    }

    fn of(&self, t: usize) -> &[usize] {
        &self.pixels[self.offsets[t]..self.offsets[t + 1]]
    }

    /// The texels some pixel sees, in order.
    fn seen(&self) -> Vec<usize> {
        (0..self.offsets.len() - 1)
            .filter(|&t| !self.of(t).is_empty())
            .collect()
    }

    /// Where the texels of these blocks lie.
    fn layout(&self) -> Layout {
        Layout {
            grid: self.grid,
            stride: self.stride,
        }
    }
}

/// Where texels lie: their grid, and the spacing of the texels in use (1: every texel; 2:
/// stage 5's sample of every other texel of every other row).
#[derive(Clone, Copy)]
struct Layout {
    grid: TexelGrid,
    stride: usize,
}

impl Layout {
    /// The up to four texels a stride away from `t` along the rows and columns.
    fn neighbours(self, t: usize) -> impl Iterator<Item = usize> {
        let (w, h, d) = (self.grid.width, self.grid.height, self.stride);
        let (c, r) = (t % w, t / w);
        [
            (c >= d).then(|| t - d),
            (c + d < w).then(|| t + d),
            (r >= d).then(|| t - d * w),
            (r + d < h).then(|| t + d * w),
        ]
        .into_iter()
        .flatten()
    }
}

/// The per-texel problem: coordinates, prediction and prior.
#[derive(Clone, Copy)]
struct TexelModel<'a> {
    space: ParamSpace,
    normals: bool,
    records: &'a ShadingRecords,
    /// For `tabulated` without normals, the directions of the sub-samples of one texel's
    /// pixels (the first slice), in their order, as its lobe reads them ([`LobeDirections`],
    /// [`crate::bsdf::registry::Capabilities::prepared_directions`]), prepared once for the
    /// evaluations of a solve ([`TexelModel::solve`]); other pixels, and `None`, take the
    /// lobe's own computation of them, which gives the same values to the last bit. Per solve
    /// rather than per fit: for every sub-sample of a 1024^2 photo set they held 1.6 GB.
    lobe_directions: Option<(&'a [usize], &'a [Option<LobeDirections>])>,
}

/// A texel's BRDF at one point of its coordinates.
enum TexelBrdf<'a, T> {
    /// `tabulated`, reading the sub-samples' prepared directions.
    Tabulated(Tabulated<T>, &'a [Option<LobeDirections>]),
    Any(Box<dyn ScalarBrdf<T>>),
}

impl<T: Real> TexelBrdf<'_, T> {
    /// `f` at the texel's sub-sample `s` (in the order of its pixels), whose directions in
    /// the texel's shading frame are `wi`, `wo`.
    fn eval(&self, s: usize, wi: Vec3<T>, wo: Vec3<T>, rng: &mut Rng) -> Rgb<T> {
        match self {
            TexelBrdf::Tabulated(lobe, directions) => {
                let single = lobe.single.eval(wi, wo);
                directions[s].map_or(single, |d| single + lobe.multiple_at(&d))
            }
            TexelBrdf::Any(brdf) => brdf.eval_total(wi, wo, rng),
        }
    }
}

/// A Gaussian prior per coordinate: centre and precision `1 / sigma^2`, for a texel of `kind`.
#[derive(Clone, Debug)]
struct Prior {
    kind: Kind,
    centre: Vec<f64>,
    precision: Vec<f64>,
}

impl Prior {
    /// `2 sum ln sigma_j`: added to the MAP cost, it makes the costs of texels under priors of
    /// different widths comparable (twice the negative log posterior up to a constant).
    fn log_normaliser(&self) -> f64 {
        -self.precision.iter().map(|p| p.ln()).sum::<f64>()
    }
}

/// What a texel is taken to be: the two cases of the metallic workflow (Burley 2012,
/// "Physically-based shading at Disney", section 5.3; glTF 2.0 appendix B): a dielectric
/// (F0 near 0.04, any diffuse albedo) or a metal (coloured F0, no diffuse). Free F0 and albedo
/// together are not identifiable on rough texels under a flash: a rough metal lobe seen from
/// near the mirror direction looks like a weaker lobe plus a diffuse term (rough copper at
/// alpha 0.65 fitted freely came out as F0 0.35 plus albedo 0.67, within the photos' noise).
/// With a known Fresnel there is one case.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Kind {
    Dielectric,
    Metal,
    Known,
}

/// One texel's solution.
#[derive(Clone, Debug)]
struct TexelFit {
    kind: Kind,
    x: Vec<f64>,
    /// Data cost `sum w r^2` (linear radiance units squared) and residual count.
    data_cost: f64,
    residuals: usize,
    /// Diagonal of `J^T J` of the data term.
    precision: Vec<f64>,
}

impl TexelModel<'_> {
    /// The texel's BRDF at the surface of its base coordinates, evaluated at `pixels`.
    fn brdf<T: Real>(&self, single: SingleBounce<T>, pixels: &[usize]) -> TexelBrdf<'_, T> {
        match self.lobe_directions {
            Some((prepared_for, directions)) if std::ptr::eq(prepared_for, pixels) => {
                TexelBrdf::Tabulated(Tabulated::new(single), directions)
            }
            _ => TexelBrdf::Any(
                differentiable(self.space.model, single, BounceCap::NONE)
                    .expect("maps fits take analytic models"),
            ),
        }
    }

    /// Whether a solve prepares its sub-samples' directions ([`TexelModel::lobe_directions`]):
    /// with normals they turn with each texel's slopes.
    fn prepares_directions(&self) -> bool {
        self.space.model.capabilities().prepared_directions && !self.normals
    }

    /// The directions of the sub-samples of `pixels`, in their order, as `tabulated`'s lobe
    /// reads them.
    fn directions_of(&self, pixels: &[usize]) -> Vec<Option<LobeDirections>> {
        let spp = self.records.samples_per_pixel;
        pixels
            .iter()
            .flat_map(|&p| p * spp..(p + 1) * spp)
            .map(|s| LobeDirections::new(self.records.wi[s], self.records.wo[s]))
            .collect()
    }

    fn dim(&self) -> usize {
        self.space.dim() + if self.normals { 2 } else { 0 }
    }

    /// Number of roughness coordinates at the front: `ln alpha`, or `ln alpha_x`, `ln
    /// alpha_y`.
    fn roughness_dim(&self) -> usize {
        if self.space.anisotropic {
            2
        } else {
            1
        }
    }

    /// Number of specular coordinates at the front (the roughness, then `logit F0` RGB unless
    /// the Fresnel is known): what the bases hold.
    fn specular_dim(&self) -> usize {
        self.roughness_dim()
            + if self.space.known_fresnel.is_some() {
                0
            } else {
                3
            }
    }

    /// Predictions of `pixels` at coordinates `x`, at any scalar type.
    fn predict<'s, T: Real>(
        &'s self,
        x: &[T],
        pixels: &'s [usize],
    ) -> impl Iterator<Item = [T; 3]> + 's {
        let lambert = self.space.surface(&x[..self.space.dim()]).diffuse;
        self.predict_parts(x, pixels)
            .map(move |(specular, shading)| {
                [0, 1, 2].map(|c| specular[c] + lambert[c] * T::c(FRAC_1_PI) * shading[c])
            })
    }

    /// Each pixel's prediction split by the diffuse albedo `rho`, which enters it linearly:
    /// `specular + rho / pi * shading` per channel, where `specular` is the sub-sample mean of
    /// `f cos_s / cos * E` and `shading` that of `cos_s / cos * E` (`cos_s / cos` the
    /// foreshortening of the shading normal, 1 without normals). The diffuse coordinates of
    /// `x` are not read, so a Jacobian needs no dual slots for them.
    fn predict_parts<'s, T: Real>(
        &'s self,
        x: &[T],
        pixels: &'s [usize],
    ) -> impl Iterator<Item = ([T; 3], [T; 3])> + 's {
        let base = self.space.dim();
        let surface = self.space.surface(&x[..base]);
        let brdf = self.brdf(surface.single, pixels);
        let frame = self
            .normals
            .then(|| ShadingFrame::new(normal_from_slopes(x[base], x[base + 1])));
        let spp = self.records.samples_per_pixel;
        let mean = T::c(1.0 / spp as f64);
        let mut rng = Rng::seed_from_u64(0);
        pixels.iter().enumerate().map(move |(i, &p)| {
            let (mut specular, mut shading) = ([T::zero(); 3], [T::zero(); 3]);
            for (j, s) in (p * spp..(p + 1) * spp).enumerate() {
                let e = self.records.irradiance[s];
                if e == [0.0; 3] {
                    continue;
                }
                let (wi, wo) = (
                    Vec3::<T>::from_f64(self.records.wi[s]),
                    Vec3::<T>::from_f64(self.records.wo[s]),
                );
                let (wi_l, wo_l, ratio) = match frame {
                    None => (wi, wo, T::one()),
                    Some(frame) => {
                        let (i, o) = (frame.local(wi), frame.local(wo));
                        if i.z.re64() <= 0.0 || o.z.re64() <= 0.0 {
                            continue;
                        }
                        (i, o, i.z / wi.z)
                    }
                };
                let Rgb(f) = brdf.eval(i * spp + j, wi_l, wo_l, &mut rng);
                for c in 0..3 {
                    let weight = ratio * T::c(e[c]);
                    specular[c] += f[c] * weight;
                    shading[c] += weight;
                }
            }
            for c in 0..3 {
                specular[c] *= mean;
                shading[c] *= mean;
            }
            (specular, shading)
        })
    }

    /// The texel's MAP objective `sum w (p - t)^2 / sigma^2 + sum precision (x - centre)^2`
    /// linearised at `x`.
    ///
    /// `N` is [`TexelModel::dim`] and `M = N - 3`: the kernel runs in dual numbers over the
    /// specular coordinates and slopes only (`M` slots), and the diffuse albedo's columns of
    /// the Jacobian come from [`TexelModel::predict_parts`]'s linear split, `d p_c / d rho_c =
    /// shading_c / pi`. That keeps three of the seven (nine with normals) derivative slots out
    /// of every kernel operation.
    fn linearise<const N: usize, const M: usize>(
        &self,
        x: &[f64],
        pixels: &[usize],
        sigma2: f64,
        prior: &Prior,
    ) -> Linearised<N> {
        self.linearise_scaled::<N, M>(x, pixels, sigma2, prior, |_| 1.0)
    }

    /// [`TexelModel::linearise`] with each residual's term of the matrix `w j j^T / sigma^2`
    /// multiplied by `matrix_scale` of the residual's predicted value: with the noise variance
    /// there over `sigma^2`, the matrix is the variance of the score, the middle of the sandwich
    /// covariance ([`texel_uncertainty`]).
    fn linearise_scaled<const N: usize, const M: usize>(
        &self,
        x: &[f64],
        pixels: &[usize],
        sigma2: f64,
        prior: &Prior,
        matrix_scale: impl Fn(f64) -> f64,
    ) -> Linearised<N> {
        let diffuse_at = self.specular_dim();
        let slot = |i: usize| if i < diffuse_at { i } else { i - 3 };
        let coords: [DualSVec64<M>; N] = std::array::from_fn(|i| match i.checked_sub(diffuse_at) {
            Some(c) if c < 3 => DualSVec64::from_re(x[i]),
            _ => DualSVec64::from_re(x[i]).derivative(slot(i)),
        });
        let lambert = [0, 1, 2].map(|c| {
            let rho = sigmoid(Dual64::from_re(x[diffuse_at + c]).derivative());
            (rho.re * FRAC_1_PI, rho.eps * FRAC_1_PI)
        });
        let mut gradient = SVector::<f64, N>::zeros();
        let mut matrix = SMatrix::<f64, N, N>::zeros();
        let mut data_cost = 0.0;
        for ((specular, shading), &p) in self.predict_parts(&coords, pixels).zip(pixels) {
            let w = self.records.weight[p];
            let scale = w / sigma2;
            for c in 0..3 {
                let (l, dl) = lambert[c];
                let predicted = specular[c].re + l * shading[c].re;
                let r = predicted - self.records.target[p][c];
                let in_matrix = matrix_scale(predicted);
                let ds: [f64; M] = specular[c].eps.0.map_or([0.0; M], |d| d.into());
                let dw: [f64; M] = shading[c].eps.0.map_or([0.0; M], |d| d.into());
                let mut j = [0.0; N];
                for (a, ja) in j.iter_mut().enumerate() {
                    *ja = match a.checked_sub(diffuse_at) {
                        Some(d) if d < 3 => {
                            if d == c {
                                dl * shading[c].re
                            } else {
                                0.0
                            }
                        }
                        _ => ds[slot(a)] + l * dw[slot(a)],
                    };
                }
                data_cost += w * r * r;
                for a in 0..N {
                    let ja = scale * j[a];
                    gradient[a] += ja * r;
                    let ja = ja * in_matrix;
                    for b in 0..=a {
                        matrix[(a, b)] += ja * j[b];
                    }
                }
            }
        }
        let data_precision = std::array::from_fn(|a| matrix[(a, a)]);
        let mut cost = data_cost / sigma2;
        for a in 0..N {
            let d = x[a] - prior.centre[a];
            cost += prior.precision[a] * d * d;
            gradient[a] += prior.precision[a] * d;
            matrix[(a, a)] += prior.precision[a];
            for b in 0..a {
                matrix[(b, a)] = matrix[(a, b)];
            }
        }
        Linearised {
            cost,
            gradient,
            matrix,
            data_cost,
            data_precision,
        }
    }

    /// The MAP objective at `x` in `f64`.
    fn cost(&self, x: &[f64], pixels: &[usize], sigma2: f64, prior: &Prior) -> f64 {
        let mut cost = 0.0;
        for (value, &p) in self.predict(x, pixels).zip(pixels) {
            for (v, t) in value.iter().zip(self.records.target[p]) {
                cost += self.records.weight[p] * (v - t).powi(2) / sigma2;
            }
        }
        cost + (0..x.len())
            .map(|a| prior.precision[a] * (x[a] - prior.centre[a]).powi(2))
            .sum::<f64>()
    }

    /// Levenberg-Marquardt (Marquardt's diagonal scaling) from `start`, exact Jacobians.
    fn solve<const N: usize, const M: usize>(
        &self,
        start: Vec<f64>,
        pixels: &[usize],
        sigma2: f64,
        prior: &Prior,
    ) -> TexelFit {
        if pixels.is_empty() {
            return TexelFit {
                kind: prior.kind,
                x: start,
                data_cost: 0.0,
                residuals: 0,
                precision: vec![0.0; N],
            };
        }
        let prepared;
        let model = match self.lobe_directions {
            None if self.prepares_directions() => {
                prepared = self.directions_of(pixels);
                TexelModel {
                    lobe_directions: Some((pixels, &prepared)),
                    ..*self
                }
            }
            _ => *self,
        };
        let mut x = SVector::<f64, N>::from_column_slice(&start);
        let mut damping = 1e-3;
        let mut at = model.linearise::<N, M>(x.as_slice(), pixels, sigma2, prior);
        for _ in 0..MAX_ITERATIONS {
            let noise = (at.data_cost / (3 * pixels.len()) as f64).max(sigma2);
            let settled = predicted_decrease(&at.matrix, &at.gradient)
                .is_some_and(|decrease| decrease * sigma2 / noise < NEGLIGIBLE_DECREASE);
            if settled {
                break;
            }
            let mut improved = false;
            for _ in 0..10 {
                let mut damped = at.matrix;
                for a in 0..N {
                    damped[(a, a)] += damping * at.matrix[(a, a)].max(1e-12);
                }
                let Some(factor) = damped.cholesky() else {
                    damping *= 10.0;
                    continue;
                };
                let trial = x - factor.solve(&at.gradient).map(|s| s.clamp(-2.0, 2.0));
                let trial_cost = model.cost(trial.as_slice(), pixels, sigma2, prior);
                if trial_cost < at.cost {
                    let gain = at.cost - trial_cost;
                    x = trial;
                    at = model.linearise::<N, M>(x.as_slice(), pixels, sigma2, prior);
                    damping = (damping / 3.0).max(1e-9);
                    improved = gain > 1e-9 * at.cost.max(1e-12);
                    break;
                }
                damping *= 4.0;
            }
            if !improved {
                break;
            }
        }
        TexelFit {
            kind: prior.kind,
            x: x.as_slice().to_vec(),
            data_cost: at.data_cost,
            residuals: 3 * pixels.len(),
            precision: at.data_precision.to_vec(),
        }
    }

    /// [`TexelModel::solve`] with `N` = [`TexelModel::dim`].
    fn solve_any(&self, x: Vec<f64>, pixels: &[usize], sigma2: f64, prior: &Prior) -> TexelFit {
        match self.dim() {
            4 => self.solve::<4, 1>(x, pixels, sigma2, prior),
            5 => self.solve::<5, 2>(x, pixels, sigma2, prior),
            6 => self.solve::<6, 3>(x, pixels, sigma2, prior),
            7 => self.solve::<7, 4>(x, pixels, sigma2, prior),
            8 => self.solve::<8, 5>(x, pixels, sigma2, prior),
            9 => self.solve::<9, 6>(x, pixels, sigma2, prior),
            10 => self.solve::<10, 7>(x, pixels, sigma2, prior),
            n => unreachable!("a maps fit has 4 to 10 coordinates, not {n}"),
        }
    }

    /// The cost of `pixels` at `x` under `prior`: `(cost, half gradient, half Gauss-Newton
    /// matrix)`, the matrix row-major `dim x dim`, its residuals' terms scaled by
    /// `matrix_scale` ([`TexelModel::linearise_scaled`]; `|_| 1.0` for the matrix itself).
    fn linearised_any(
        &self,
        x: &[f64],
        pixels: &[usize],
        sigma2: f64,
        prior: &Prior,
        matrix_scale: &dyn Fn(f64) -> f64,
    ) -> (f64, Vec<f64>, Vec<f64>) {
        fn parts<const N: usize>(l: Linearised<N>) -> (f64, Vec<f64>, Vec<f64>) {
            let matrix = l.matrix.transpose();
            (
                l.cost,
                l.gradient.as_slice().to_vec(),
                matrix.as_slice().to_vec(),
            )
        }
        match self.dim() {
            4 => parts(self.linearise_scaled::<4, 1>(x, pixels, sigma2, prior, matrix_scale)),
            5 => parts(self.linearise_scaled::<5, 2>(x, pixels, sigma2, prior, matrix_scale)),
            6 => parts(self.linearise_scaled::<6, 3>(x, pixels, sigma2, prior, matrix_scale)),
            7 => parts(self.linearise_scaled::<7, 4>(x, pixels, sigma2, prior, matrix_scale)),
            8 => parts(self.linearise_scaled::<8, 5>(x, pixels, sigma2, prior, matrix_scale)),
            9 => parts(self.linearise_scaled::<9, 6>(x, pixels, sigma2, prior, matrix_scale)),
            10 => parts(self.linearise_scaled::<10, 7>(x, pixels, sigma2, prior, matrix_scale)),
            n => unreachable!("a maps fit has 4 to 10 coordinates, not {n}"),
        }
    }

    /// The kinds a texel may be.
    fn kinds(&self) -> &'static [Kind] {
        if self.space.known_fresnel.is_some() {
            &[Kind::Known]
        } else {
            &[Kind::Dielectric, Kind::Metal]
        }
    }

    /// The prior of a texel of `kind` whose specular coordinates (the roughness, then `logit
    /// F0` RGB unless known) are drawn toward `specular` with standard deviations `sigma`
    /// (roughness, F0); the diffuse albedo and slopes as in the module table.
    fn prior(&self, kind: Kind, specular: &[f64], sigma: [f64; 2]) -> Prior {
        let dim = self.dim();
        let r = self.roughness_dim();
        let (mut centre, mut sd) = (vec![0.0; dim], vec![SIGMA_WEAK; dim]);
        for j in 0..r {
            (centre[j], sd[j]) = (specular[j], sigma[0]);
        }
        let diffuse_at = match kind {
            Kind::Known => r,
            Kind::Dielectric | Kind::Metal => {
                for c in r..r + 3 {
                    (centre[c], sd[c]) = match kind {
                        Kind::Dielectric => (specular[c], SIGMA_DIELECTRIC_F0.min(sigma[1])),
                        _ => (specular[c], SIGMA_METAL_F0.min(sigma[1])),
                    };
                }
                r + 3
            }
        };
        if kind == Kind::Metal {
            for c in diffuse_at..diffuse_at + 3 {
                (centre[c], sd[c]) = (logit(METAL_DIFFUSE), SIGMA_METAL_DIFFUSE);
            }
        }
        sd[self.space.dim()..].fill(SIGMA_SLOPE);
        Prior {
            kind,
            centre,
            precision: sd.iter().map(|s| 1.0 / (s * s)).collect(),
        }
    }

    /// Stage 1's prior of `kind`: roughness near 0.3 (weakly), a dielectric's F0 near 0.04, a
    /// metal's where measured conductors' are ([`METAL_F0_LOGIT`]).
    fn generic_prior(&self, kind: Kind) -> Prior {
        let roughness = vec![GENERIC_ALPHA.ln(); self.roughness_dim()];
        self.prior(
            kind,
            &self.generic_specular(kind, &roughness),
            [2.0, SIGMA_WEAK],
        )
    }

    /// The specular coordinates a texel of `kind` is drawn toward when nothing else is known
    /// of its F0: the roughness coordinates `roughness`, then a dielectric's F0 (0.04) or a
    /// metal's (0.76).
    fn generic_specular(&self, kind: Kind, roughness: &[f64]) -> Vec<f64> {
        let f0 = match kind {
            Kind::Dielectric => logit(DIELECTRIC_F0),
            _ => METAL_F0_LOGIT,
        };
        let mut specular = roughness.to_vec();
        specular.extend([f0; 3]);
        specular
    }

    /// The prior of a texel of `kind` in a basis of `basis_kind` centred at `centre`: the
    /// basis's roughness always, and its F0 when the texel is of the basis's kind; a texel of
    /// the other kind keeps its kind's own F0 prior (a tile's grout is a dielectric whatever
    /// the glaze next to it is), so the kind is each texel's own choice, not its basis's.
    fn basis_prior(&self, kind: Kind, basis_kind: Kind, centre: &[f64]) -> Prior {
        if kind == basis_kind {
            self.prior(kind, centre, [SIGMA_LN_ALPHA, SIGMA_LOGIT_F0])
        } else {
            let specular = self.generic_specular(kind, &centre[..self.roughness_dim()]);
            self.prior(kind, &specular, [SIGMA_LN_ALPHA, SIGMA_WEAK])
        }
    }

    /// `texel` solved as `kind` under the basis `(kind, centre)`, from its own coordinates moved
    /// to the basis's: `(posterior cost, solution)`, the cost twice the negative log posterior
    /// with the prior's normaliser, and [`KIND_SWITCH`] where the kinds differ (stage 4's first
    /// round, and each texel of a finer grid, [`refine`]).
    fn solve_under_basis(
        &self,
        texel: &TexelFit,
        kind: Kind,
        (basis_kind, centre): (Kind, &[f64]),
        pixels: &[usize],
        sigma2: f64,
    ) -> (f64, TexelFit) {
        let prior = self.basis_prior(kind, basis_kind, centre);
        let fit = self.solve_any(self.moved_to(texel, &prior), pixels, sigma2, &prior);
        let switch = if kind == basis_kind { 0.0 } else { KIND_SWITCH };
        let posterior = self.cost(&fit.x, pixels, sigma2, &prior) + prior.log_normaliser() + switch;
        (posterior, fit)
    }

    /// `texel`'s coordinates with its specular ones moved to `prior`'s centre and, for a metal,
    /// its diffuse albedo to none (for a metal texel becoming a dielectric, to the start's
    /// albedo): where a texel starts when it joins a basis.
    fn moved_to(&self, texel: &TexelFit, prior: &Prior) -> Vec<f64> {
        let mut moved = texel.x.clone();
        let specular = self.specular_dim();
        let diffuse = specular..specular + 3;
        moved[..specular].copy_from_slice(&prior.centre[..specular]);
        match (texel.kind, prior.kind) {
            (_, Kind::Metal) => moved[diffuse.clone()].copy_from_slice(&prior.centre[diffuse]),
            (Kind::Metal, Kind::Dielectric) => {
                let start = self.start(Kind::Dielectric, GENERIC_ALPHA);
                moved[diffuse.clone()].copy_from_slice(&start[diffuse]);
            }
            _ => {}
        }
        moved
    }

    /// A start for a texel of `kind` with roughness `alpha`.
    fn start(&self, kind: Kind, alpha: f64) -> Vec<f64> {
        let (f0, diffuse) = match kind {
            Kind::Metal => (0.7, METAL_DIFFUSE),
            _ => (DIELECTRIC_F0, 0.3),
        };
        let material = Material {
            model: self.space.model,
            ndf: self.space.ndf,
            height: self.space.height,
            alpha: [alpha; 2],
            fresnel: FresnelSpec::Schlick { f0: [f0; 3] },
            diffuse: [diffuse; 3],
        };
        let mut x = self.space.point(&material, 1.0);
        if self.normals {
            x.extend([0.0, 0.0]);
        }
        x
    }
}

/// Refuses the models a maps fit does not take (the stochastic estimators, see the module
/// documentation), with the reason.
pub fn check_model(model: Model) -> Result<()> {
    if model.capabilities().stochastic() {
        let taken: Vec<&str> = Model::ALL
            .iter()
            .filter(|m| !m.capabilities().stochastic())
            .map(|m| m.name())
            .collect();
        let (last, others) = taken.split_last().expect("a deterministic model");
        return Err(Error::argument(
            "--models",
            format!(
                "{model} is stochastic: a maps fit would give each texel a noisy objective from a \
                 few dozen records; maps fits take {} or {last}",
                others.join(", ")
            ),
        ));
    }
    Ok(())
}

/// Fits maps to `records` (built with targets, from a capture: texture coordinates needed).
pub fn fit_maps(records: &ShadingRecords, options: &MapsFitOptions) -> Result<MapsFit> {
    let start = Instant::now();
    check_model(options.model)?;
    if records.uv.len() != records.wi.len() {
        return Err(Error::argument(
            "--maps",
            "a maps fit needs records built from a photo set",
        ));
    }
    let space = ParamSpace {
        diffuse: true,
        known_fresnel: options.known_fresnel,
        ndf: options.ndf,
        height: options.height,
        anisotropic: options.anisotropic,
        ..ParamSpace::plain(options.model)
    };
    let level = fit_level(records, options, space)?;
    let model = TexelModel {
        space,
        normals: level.normals,
        records,
        lobe_directions: None,
    };
    let blocks = TexelBlocks::new(records, options.grid, 1, options.held_out_photo.as_slice());
    let predicted = maps_prediction(&model, &level.texels, None, options.grid, &blocks.pixels);
    let train_error = relative_error(&predicted, records, &blocks.pixels);
    let seen = blocks.seen().len();
    let noise = NoiseLevels::measure(records, &blocks.pixels, &predicted, seen * model.dim());
    drop(predicted);
    let uncertainty = texel_uncertainty(&model, &blocks, &level, &noise);
    Ok(MapsFit {
        maps: to_maps(&model, options, &level.texels),
        bases: floored_bases(level.bases, level.roughness_floor),
        basis_trials: level.basis_trials,
        roughness_floor: level.roughness_floor,
        normals: level.normals,
        normals_trial: level.normals_trial,
        bases_grid: level.bases_grid,
        noise_sigma: level.sigma2.sqrt(),
        train_error,
        texels_seen: (0..options.grid.len())
            .filter(|&t| !blocks.of(t).is_empty())
            .count(),
        seconds: start.elapsed().as_secs_f64(),
        labels: level.labels,
        uncertainty,
    })
}

/// `bases` with no roughness below `floor`.
fn floored_bases(mut bases: Vec<Basis>, floor: Option<f64>) -> Vec<Basis> {
    let floor = floor.unwrap_or(0.0);
    for basis in &mut bases {
        if let Some(xy) = &mut basis.alpha_xy {
            *xy = xy.map(|a| a.max(floor));
            basis.alpha = (xy[0] * xy[1]).sqrt();
        } else {
            basis.alpha = basis.alpha.max(floor);
        }
    }
    bases
}

/// A maps fit at one texel grid: what [`MapsFit`] reports of it, and what a finer grid is
/// refined from ([`refine::refine`]).
struct Level {
    /// Every texel's solution, the roughness floor laid on it and the unseen texels filled.
    texels: Vec<TexelFit>,
    /// The bases, without the roughness floor.
    bases: Vec<Basis>,
    labels: Vec<usize>,
    /// The centres of the texels' priors, one per basis ([`BasisFits::prior_centres`]).
    prior_centres: Vec<Vec<f64>>,
    kinds: Vec<Kind>,
    sigma2: f64,
    basis_trials: Vec<BasisTrial>,
    roughness_floor: Option<f64>,
    normals: bool,
    normals_trial: Option<NormalsTrial>,
    /// The grid the bases were chosen at.
    bases_grid: TexelGrid,
}

/// The maps fit of `records` on `options.grid`: the five stages of the module table, or, on a
/// grid of more than `options.coarsest` texels, those at half the resolution and the texels
/// refined from them ([`refine`]).
fn fit_level(
    records: &ShadingRecords,
    options: &MapsFitOptions,
    space: ParamSpace,
) -> Result<Level> {
    if let Some((coarse_records, grid)) = refine::coarser(records, options) {
        let coarse_options = MapsFitOptions {
            grid,
            ..options.clone()
        };
        let coarse = fit_level(
            coarse_records.as_ref().unwrap_or(records),
            &coarse_options,
            space,
        )?;
        // The refinement reads only the coarse fit: the coarse photos go before it.
        drop(coarse_records);
        return refine::refine(records, options, space, coarse, grid);
    }
    let candidates: &[bool] = match options.normals {
        Normals::Off => &[false],
        Normals::On => &[true],
        Normals::Auto => &[false, true],
    };
    let model_with = |normals: bool| TexelModel {
        space,
        normals,
        records,
        lobe_directions: None,
    };
    let validation_photo = options
        .validation_photo
        .filter(|_| options.max_bases > 1 || candidates.len() > 1);
    let trials_each = options.max_bases + 1;
    let stage5 = if validation_photo.is_some() {
        candidates.len() * trials_each
    } else {
        0
    };
    let mut progress = options.progress.start("maps fit", (stage5 + 2) as u64);
    let mut step = 0u64;
    let mut tick = |what: &str| {
        step += 1;
        progress.step(step, || what.to_string())
    };

    // Stage 5: the number of bases (and, with `--normals=auto`, whether the texels have
    // normals), by a validation photo.
    let mut basis_trials = Vec::new();
    let (mut bases, mut roughness_floor, mut normals) = (options.max_bases, None, candidates[0]);
    let mut normals_trial = None;
    if let Some(photo) = validation_photo {
        let chosen: Vec<(Vec<BasisTrial>, usize)> = candidates
            .iter()
            .map(|&normals| {
                let trials = validated_bases(&model_with(normals), options, photo, &mut tick)?;
                let chosen = fewest_good_bases(&trials);
                Ok((trials, chosen))
            })
            .collect::<Result<_>>()?;
        // Each family at its best number of bases: whether normals help is a question apart
        // from how many bases each needs.
        let error = |(trials, _): &(Vec<BasisTrial>, usize)| {
            trials
                .iter()
                .map(|t| t.validation_error)
                .fold(f64::INFINITY, f64::min)
        };
        let pick = if chosen.len() == 2 {
            let (without, with) = (error(&chosen[0]), error(&chosen[1]));
            normals_trial = Some(NormalsTrial { without, with });
            usize::from(with * (1.0 + PARSIMONY) < without)
        } else {
            0
        };
        normals = candidates[pick];
        let (trials, k) = chosen.into_iter().nth(pick).expect("a candidate picked");
        (bases, roughness_floor) = (trials[k].bases, trials[k].roughness_floor);
        basis_trials = trials;
    }
    let model = model_with(normals);
    let blocks = TexelBlocks::new(records, options.grid, 1, options.held_out_photo.as_slice());
    let first = independent_texels(&model, &blocks);
    tick("texels alone")?;
    let mut fits = basis_fits(&model, &blocks, &first, bases);
    fits.texels = with_roughness_floor(fits.texels, model.roughness_dim(), roughness_floor);
    fill_unseen(&mut fits.texels, &blocks);
    tick(&format!("{bases} bases"))?;
    progress.finish();
    Ok(Level {
        texels: fits.texels,
        bases: fits.bases,
        labels: fits.labels,
        prior_centres: fits.prior_centres,
        kinds: fits.kinds,
        sigma2: first.sigma2,
        basis_trials,
        roughness_floor,
        normals,
        normals_trial,
        bases_grid: options.grid,
    })
}

/// Stage 5 for one model: fitted on every photo but `photo`, on every other texel of every
/// other row (a quarter of the work; the bases are global, so a texel sample finds them),
/// each number of bases up to `options.max_bases` with the roughness floor that predicts
/// `photo` best.
fn validated_bases(
    model: &TexelModel,
    options: &MapsFitOptions,
    photo: usize,
    tick: &mut impl FnMut(&str) -> Result<()>,
) -> Result<Vec<BasisTrial>> {
    let records = model.records;
    let unseen: Vec<usize> = options.held_out_photo.into_iter().chain([photo]).collect();
    let blocks = TexelBlocks::new(records, options.grid, 2, &unseen);
    let validation = validation_pixels(records, options.grid, photo);
    let normals = if model.normals { ", normals" } else { "" };
    let first = independent_texels(model, &blocks);
    tick(&format!("texels alone (choosing K{normals})"))?;
    (1..=options.max_bases)
        .map(|k| {
            let fits = basis_fits(model, &blocks, &first, k);
            let floor = best_floor(model, &fits.texels, options.grid, &validation);
            let error = floor.error;
            tick(&format!("{k} bases{normals}: validation error {error:.4}"))?;
            Ok(BasisTrial {
                bases: k,
                bases_kept: fits.bases.len(),
                roughness_floor: floor.floor,
                validation_error: error,
                unfloored_validation_error: floor.unfloored_error,
                clustering_bic: fits.clustering_bic,
            })
        })
        .collect()
}

/// The pixels of `photo` that the texel sample of stage 5 sees (every other texel of every
/// other row).
fn validation_pixels(records: &ShadingRecords, grid: TexelGrid, photo: usize) -> Vec<usize> {
    let photo = records.photos[photo].pixels();
    TexelBlocks::new(records, grid, 2, &[])
        .pixels
        .into_iter()
        .filter(|p| photo.contains(p))
        .collect()
}

/// The roughness floor the validation photo chose ([`best_floor`]).
struct FloorChoice {
    floor: Option<f64>,
    /// The relative error of the validation pixels under the floor, and under none.
    error: f64,
    unfloored_error: f64,
}

/// Of [`ROUGHNESS_FLOORS`], the one under which `texels` (fitted without the validation photo)
/// predict the `validation` pixels best ([`texel_relative_error`]).
fn best_floor(
    model: &TexelModel,
    texels: &[TexelFit],
    grid: TexelGrid,
    validation: &[usize],
) -> FloorChoice {
    let error_at = |floor: Option<f64>| {
        let predicted = maps_prediction(model, texels, floor, grid, validation);
        texel_relative_error(&predicted, model.records, validation, grid)
    };
    let errors: Vec<(Option<f64>, f64)> = ROUGHNESS_FLOORS
        .iter()
        .map(|&floor| (floor, error_at(floor)))
        .collect();
    let (floor, error) = *errors
        .iter()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .expect("floors to try");
    FloorChoice {
        floor,
        error,
        // `ROUGHNESS_FLOORS[0]` is no floor.
        unfloored_error: errors[0].1,
    }
}

/// The index of the trial the bases are taken from: among the trials whose validation error
/// is within [`PARSIMONY`] of the best (those the validation photo cannot tell apart), the
/// one with the lowest [`clustering_bic`] (Fraley & Raftery 2002, section 4.1: the number of
/// clusters of the texels' own estimates), and of the trials that keep as many bases as it,
/// the one with the fewest. Where every texel's own photos pin it down, the bases change no
/// prediction of the validation photo: on the three-material truth of docs/maps.md at 64^2
/// every `K` scored 0.0111 and the fewest, one basis, was kept, though the texels fall into
/// three crisp groups.
fn fewest_good_bases(trials: &[BasisTrial]) -> usize {
    let best = trials
        .iter()
        .map(|t| t.validation_error)
        .fold(f64::INFINITY, f64::min);
    let good = |t: &BasisTrial| t.validation_error <= (1.0 + PARSIMONY) * best;
    let chosen = trials
        .iter()
        .filter(|t| good(t))
        .min_by(|a, b| a.clustering_bic.total_cmp(&b.clustering_bic))
        .expect("the best trial is within its own margin");
    trials
        .iter()
        .position(|t| good(t) && t.bases_kept == chosen.bases_kept)
        .expect("the chosen trial is good")
}

/// The decrease of a cost with gradient `2 gradient` and Gauss-Newton matrix `2 matrix` (as
/// [`TexelModel::linearise`] returns them) from its point to the minimum of its quadratic
/// model: `gradient^T matrix^-1 gradient`, or `None` where `matrix` is not positive definite.
fn predicted_decrease<const N: usize>(
    matrix: &SMatrix<f64, N, N>,
    gradient: &SVector<f64, N>,
) -> Option<f64> {
    Some(matrix.cholesky()?.solve(gradient).dot(gradient))
}

/// A texel's MAP objective linearised at a point ([`TexelModel::linearise`]).
struct Linearised<const N: usize> {
    cost: f64,
    /// Half the gradient of `cost`.
    gradient: SVector<f64, N>,
    /// Half the Gauss-Newton matrix of `cost`, the prior's precision included.
    matrix: SMatrix<f64, N, N>,
    /// `sum w r^2` of the data term.
    data_cost: f64,
    /// The diagonal of the data term's half Gauss-Newton matrix `J^T J`.
    data_precision: [f64; N],
}

/// Stages 1 and 2: every texel alone, of either kind, and the noise level.
struct Independent {
    texels: Vec<TexelFit>,
    sigma2: f64,
}

fn independent_texels(model: &TexelModel, blocks: &TexelBlocks) -> Independent {
    let dim = model.dim();
    // The data term's scale before the noise is known: 1% of the RMS target.
    let (mut sum, mut count) = (0.0, 0.0f64);
    for &p in &blocks.pixels {
        sum += model.records.target[p].iter().map(|v| v * v).sum::<f64>();
        count += 3.0;
    }
    let scale2 = (sum / count.max(1.0)).max(1e-30) * 1e-4;
    let texel_count = blocks.offsets.len() - 1;
    let texels: Vec<TexelFit> = (0..texel_count)
        .into_par_iter()
        .map(|t| {
            let pixels = blocks.of(t);
            let mut best: Option<(f64, TexelFit)> = None;
            for &kind in model.kinds() {
                let prior = model.generic_prior(kind);
                for &alpha in &ALPHA_STARTS {
                    let fit = model.solve_any(model.start(kind, alpha), pixels, scale2, &prior);
                    let cost = model.cost(&fit.x, pixels, scale2, &prior);
                    if best.as_ref().is_none_or(|(c, _)| cost < *c) {
                        best = Some((cost, fit));
                    }
                    if pixels.is_empty() {
                        break;
                    }
                }
            }
            best.expect("at least one kind and start").1
        })
        .collect();
    let residuals: usize = texels.iter().map(|f| f.residuals).sum();
    let seen = texels.iter().filter(|f| f.residuals > 0).count();
    let data: f64 = texels.iter().map(|f| f.data_cost).sum();
    let dof = residuals.saturating_sub(seen * dim).max(1);
    Independent {
        texels,
        sigma2: (data / dof as f64).max(1e-30),
    }
}

/// Stages 3 and 4 for `k` bases.
struct BasisFits {
    texels: Vec<TexelFit>,
    bases: Vec<Basis>,
    labels: Vec<usize>,
    /// The centres of the texels' priors: each basis's weighted mean of its texels'
    /// estimates, before the pooled estimate reported in `bases`.
    prior_centres: Vec<Vec<f64>>,
    kinds: Vec<Kind>,
    /// [`clustering_bic`] of k-means' bases over the texels' first estimates.
    clustering_bic: f64,
}

fn basis_fits(
    model: &TexelModel,
    blocks: &TexelBlocks,
    first: &Independent,
    k: usize,
) -> BasisFits {
    let (specular, roughness) = (model.specular_dim(), model.roughness_dim());
    let sigma2 = first.sigma2;
    let mut texels = first.texels.clone();
    let seen = blocks.seen();
    let points = ClusteringPoints::new(&texels, specular, roughness);
    let mut clusters = weighted_kmeans(&texels, &points, (&seen, blocks.layout()), roughness, k);
    let bic = clustering_bic(&points, &seen, &clusters.centres, roughness);
    // Round 0: the texel solved under every basis and as either kind, each from its own
    // coordinates moved to the basis; the labels are then chosen together
    // (`label_smoothing`), each basis's candidate being the texel's better kind.
    let candidates: Vec<Vec<(f64, TexelFit)>> = (0..texels.len())
        .into_par_iter()
        .map(|t| {
            let pixels = blocks.of(t);
            (0..clusters.centres.len())
                .map(|b| {
                    model
                        .kinds()
                        .iter()
                        .map(|&kind| {
                            let basis = (clusters.kinds[b], clusters.centres[b].as_slice());
                            model.solve_under_basis(&texels[t], kind, basis, pixels, sigma2)
                        })
                        .min_by(|a, b| a.0.total_cmp(&b.0))
                        .expect("at least one kind")
                })
                .collect()
        })
        .collect();
    let costs: Vec<Vec<(usize, f64)>> = candidates
        .iter()
        .map(|options| options.iter().map(|o| o.0).enumerate().collect())
        .collect();
    clusters.assignment = label_smoothing(&costs, blocks);
    let sizes = (seen.len(), specular);
    let layout = (blocks, clusters.kinds.as_slice());
    take_negligible_bases_texels(&mut clusters.assignment, &candidates, layout, sizes);
    texels = candidates
        .into_iter()
        .zip(&clusters.assignment)
        .map(|(mut options, &b)| options.swap_remove(b).1)
        .collect();
    clusters.drop_empty(&seen);
    clusters.recentre(&texels, &seen, specular, roughness);
    settle(model, blocks, &mut texels, &mut clusters, sigma2);
    let (bases, prior_centres) = reported_bases(model, blocks, &texels, &clusters, sigma2);
    BasisFits {
        texels,
        bases,
        labels: clusters.assignment,
        prior_centres,
        kinds: clusters.kinds,
        clustering_bic: bic,
    }
}

/// The rounds of stage 4 after the first: every texel solved again under its basis's prior,
/// then each basis re-centred on its texels ([`Clusters::recentre`]).
fn settle(
    model: &TexelModel,
    blocks: &TexelBlocks,
    texels: &mut [TexelFit],
    clusters: &mut Clusters,
    sigma2: f64,
) {
    let seen = blocks.seen();
    for _ in 1..ROUNDS {
        // In place: at 1024^2 a second vector of texels is a few hundred megabytes.
        texels.par_iter_mut().enumerate().for_each(|(t, texel)| {
            let b = clusters.assignment[t];
            let prior = model.basis_prior(texel.kind, clusters.kinds[b], &clusters.centres[b]);
            *texel = model.solve_any(texel.x.clone(), blocks.of(t), sigma2, &prior);
        });
        let (specular, roughness) = (model.specular_dim(), model.roughness_dim());
        clusters.recentre(texels, &seen, specular, roughness);
    }
}

/// The bases reported: pooled maximum-likelihood estimates ([`pooled_centre`]), each with its
/// share of the seen texels; and the centres of the texels' priors, which stay at the weighted
/// means: centred on the pooled estimates they predicted the real captures' held-out photos
/// worse (yellow_box at 128^2: 0.160 against 0.149, docs/maps.md).
fn reported_bases(
    model: &TexelModel,
    blocks: &TexelBlocks,
    texels: &[TexelFit],
    clusters: &Clusters,
    sigma2: f64,
) -> (Vec<Basis>, Vec<Vec<f64>>) {
    let (specular, roughness) = (model.specular_dim(), model.roughness_dim());
    let seen = blocks.seen();
    let mut centres = clusters.centres.clone();
    for (b, centre) in centres.iter_mut().enumerate() {
        let (kind, labels) = (clusters.kinds[b], &clusters.assignment);
        pooled_centre(model, blocks, texels, labels, b, kind, centre, sigma2);
    }
    let total = seen.len().max(1) as f64;
    let bases = centres
        .iter()
        .zip(&clusters.kinds)
        .enumerate()
        .map(|(c, (centre, &kind))| Basis {
            kind,
            alpha: (centre[..roughness].iter().sum::<f64>() / roughness as f64).exp(),
            alpha_xy: (roughness == 2).then(|| [centre[0].exp(), centre[1].exp()]),
            f0: (specular == roughness + 3)
                .then(|| [0, 1, 2].map(|j| sigmoid(centre[roughness + j]))),
            share: seen
                .iter()
                .filter(|&&t| clusters.assignment[t] == c)
                .count() as f64
                / total,
        })
        .collect();
    (bases, clusters.centres.clone())
}

/// The least share of the seen texels a basis holds once the labels are chosen; below it, the
/// basis is not a material ([`take_negligible_bases_texels`]). The smallest material of the
/// synthetic truths covers 12.5% of the sample; the groups k-means found that the labels left
/// with under 1% were texels of another basis fitted as the other kind or sharper: 0.1% of
/// `datasets/two-materials` with `kulla-conty` at 128^2 (copper texels fitted as dielectrics),
/// 0.2% with `single` at 32^2.
const NEGLIGIBLE_SHARE: f64 = 0.01;

/// Gives each texel labelled with a basis that is not a material the kept basis under which
/// its posterior (`candidates`, as in [`basis_fits`]) is least; the emptied bases are then
/// dropped with the empty ones ([`Clusters::drop_empty`]). A basis is not a material when it
/// holds under [`NEGLIGIBLE_SHARE`] of the `seen` texels, covers no area
/// ([`covers_an_area`]), or its texels' photos do not pay for it: the sum over its texels of
/// how much more their posterior costs (twice the negative log posterior) under the best
/// other basis of its kind (`kinds`) is under `(specular + 1) ln seen`, the price of its
/// `specular` coordinates and
/// its mixing proportion in Schwarz's criterion (Schwarz 1978, "Estimating the dimension of a
/// model", Annals of Statistics 6). The clustering's own criterion ([`clustering_bic`]) reads
/// the texels' first estimates, where a few texels a second optimum holds (a dark rough
/// dielectric fitted as a sharp one whose highlight no photo shows) form a tight group: in the
/// maps zoo (`tests/maps_zoo.rs`) such bases of 2-3% of the texels gained their photos 9-35
/// against a price of 38, and every basis of a material over 1000. A basis of a kind no
/// other basis has is a material of its own: a texel takes only the roughness of a basis of
/// the other kind, so a metal disc beside a dielectric of nearly its roughness (0.303 and
/// 0.325) gained nothing over it and was lost.
fn take_negligible_bases_texels(
    labels: &mut [usize],
    candidates: &[Vec<(f64, TexelFit)>],
    (blocks, kinds): (&TexelBlocks, &[Kind]),
    (seen, specular): (usize, usize),
) {
    let k = candidates.first().map_or(0, Vec::len);
    let mut counts = vec![0usize; k];
    let mut gains = vec![0.0; k];
    for (&label, options) in labels.iter().zip(candidates) {
        // Seen texels only: an unseen one has no residuals.
        if options[label].1.residuals == 0 {
            continue;
        }
        counts[label] += 1;
        let other = (0..k)
            .filter(|&b| b != label && kinds[b] == kinds[label])
            .map(|b| options[b].0)
            .fold(f64::INFINITY, f64::min);
        gains[label] += other - options[label].0;
    }
    let price = (specular + 1) as f64 * (seen.max(1) as f64).ln();
    let kept: Vec<bool> = (0..k)
        .map(|b| {
            counts[b] as f64 >= NEGLIGIBLE_SHARE * seen as f64
                && gains[b] >= price
                && covers_an_area(labels, blocks, b)
        })
        .collect();
    if !kept.iter().any(|&k| k) {
        return;
    }
    for (label, options) in labels.iter_mut().zip(candidates) {
        if !kept[*label] {
            *label = (0..k)
                .filter(|&b| kept[b])
                .min_by(|&a, &b| options[a].0.total_cmp(&options[b].0))
                .expect("a basis kept");
        }
    }
}

/// Whether some 2 x 2 block of seen texels is all labelled `basis`. The texels astride the
/// edge between two materials, each holding some of both, form a line one texel wide (a
/// staircase along a slanted edge), which holds no such block; a material at least two texels
/// wide does. On the untuned truth of docs/maps.md at 32^2 (256^2 photos), the texels along a
/// copper square's edge beside a glossy ceramic (1.1% of them) were fitted as a sharp metal of
/// F0 0.96 and kept as a fourth basis: the validation photo preferred it (error 0.0051 against
/// 0.0056), as it prefers any basis that fits mixed texels better. On stage 5's texel sample
/// (every other texel of every other row) a line and a band three texels wide look alike, so
/// there every basis covers an area and the rule waits for the fit on every texel: the
/// untuned truth's rubber band, three texels wide at 16^2, was dropped there.
fn covers_an_area(labels: &[usize], blocks: &TexelBlocks, basis: usize) -> bool {
    if blocks.stride > 1 {
        return true;
    }
    let w = blocks.grid.width;
    let own = |t: usize| labels[t] == basis && !blocks.of(t).is_empty();
    (0..blocks.grid.height.saturating_sub(1)).any(|r| {
        (0..w - 1).any(|c| {
            let t = r * w + c;
            own(t) && own(t + 1) && own(t + w) && own(t + w + 1)
        })
    })
}

/// Gauss-Newton steps of [`pooled_centre`] at most, each backtracking at most
/// `POOLED_HALVINGS` times.
const POOLED_STEPS: usize = 10;
const POOLED_HALVINGS: usize = 6;

/// The cost per residual, as a multiple of the median over a basis's texels, above which
/// [`pooled_centre`] leaves a texel out. With the noise level right, a texel's cost is a
/// chi-square with as many degrees of freedom as residuals (3 per pixel of each photo, 30 or
/// more with 10 photos), which exceeds 4 times its median with a probability below 1e-6; a
/// wrong noise level scales every texel's cost alike. The texels astride the edge of the
/// untuned truth's rubber band (docs/maps.md) cost 500-1000 times the median at 64^2, and
/// the worst 5% of the texels held 92% of the pooled cost: a maximum-likelihood estimate over
/// all of them is theirs.
const OUTLIER_RATIO: f64 = 4.0;

/// [`pooled_centre`] stops after a step below this in every coordinate (`ln alpha`, `logit
/// F0`): 1e-4 relative in alpha.
const POOLED_TOLERANCE: f64 = 1e-4;

/// Basis `b`'s specular coordinates `centre` re-estimated by maximum likelihood from the
/// photos of its texels of its own `kind` together ([`OUTLIER_RATIO`] leaves out those it
/// cannot explain): every texel at the basis's specular coordinates, each with its own
/// diffuse albedo (and slopes), all solved together by Gauss-Newton steps from the
/// precision-weighted mean of their estimates ([`Clusters::recentre`]). Each step eliminates
/// every texel's own coordinates by its Schur complement (the reduced camera system of bundle
/// adjustment: Triggs et al. 2000, "Bundle adjustment: a modern synthesis", section 6.1).
///
/// The weighted mean is biased under noise: a texel fitted sharper than the truth has a
/// larger derivative in `ln alpha`, so more precision, and pulls the mean down (docs/maps.md,
/// "Noisy photos"). The texels' own albedos are biased too, by their prior: the noise level
/// of stage 2 is the texels' pooled misfit, and where texels astride edges hold most of it
/// (10 times the noise on the untuned truth of docs/maps.md), the albedo's weak prior weighs
/// against a dark texel's few photos. A rubber band (alpha 0.5, albedo 0.05) came out at
/// 0.466-0.486 held at those albedos and at 0.456-0.478 re-fitted under that prior (16^2 to
/// 128^2, 96^2 photos); re-fitted without a prior on a dielectric's albedo, at 0.499.
#[allow(clippy::too_many_arguments)]
fn pooled_centre(
    model: &TexelModel,
    blocks: &TexelBlocks,
    texels: &[TexelFit],
    assignment: &[usize],
    b: usize,
    kind: Kind,
    centre: &mut [f64],
    sigma2: f64,
) {
    use nalgebra::{DMatrix, DVector};
    let (s, dim) = (model.specular_dim(), model.dim());
    let members: Vec<usize> = (0..texels.len())
        .filter(|&t| assignment[t] == b && texels[t].kind == kind && !blocks.of(t).is_empty())
        .collect();
    if members.is_empty() {
        return;
    }
    // No prior on the shared coordinates, nor on a dielectric's albedo (1e-6, which keeps a
    // saturated albedo's block invertible); a metal's albedo stays none and the slopes near
    // the normal, as their kinds define them.
    let mut prior = model.basis_prior(kind, kind, centre);
    prior.precision[..s].fill(0.0);
    if kind != Kind::Metal {
        prior.precision[s..s + 3].fill(1e-6);
    }
    let own = dim - s;
    // One texel's cost, the shared coordinates' reduced half gradient and half Gauss-Newton
    // matrix, and the pieces that give its own step from the shared one.
    struct Reduced {
        cost: f64,
        gradient: DVector<f64>,
        matrix: DMatrix<f64>,
        /// `M_nn^-1 g_n` and `M_nn^-1 M_ns`.
        own_step: DVector<f64>,
        own_coupling: DMatrix<f64>,
    }
    let reduce = |x: &[f64], t: usize| -> Option<Reduced> {
        let (cost, g, m) = model.linearised_any(x, blocks.of(t), sigma2, &prior, &|_| 1.0);
        let m = DMatrix::from_row_slice(dim, dim, &m);
        let g = DVector::from_vec(g);
        let factor = m.view((s, s), (own, own)).into_owned().cholesky()?;
        let own_step = factor.solve(&g.rows(s, own).into_owned());
        let own_coupling = factor.solve(&m.view((s, 0), (own, s)).into_owned());
        Some(Reduced {
            cost,
            gradient: g.rows(0, s) - m.view((0, s), (s, own)) * &own_step,
            matrix: m.view((0, 0), (s, s)) - m.view((0, s), (s, own)) * &own_coupling,
            own_step,
            own_coupling,
        })
    };
    // What a texel's own step needs, `own (1 + s)` numbers a member: at 1024^2 a basis holds
    // half a million texels, and their `Reduced` parts, kept whole, were most of the fit's
    // peak memory.
    let stride = own * (1 + s);
    // The own step of member `i` from the shared step.
    let own_step_of = |own_parts: &[f64], i: usize, step: &DVector<f64>| -> DVector<f64> {
        let part = &own_parts[i * stride..(i + 1) * stride];
        let own_step = nalgebra::DVectorView::from_slice(&part[..own], own);
        let own_coupling = nalgebra::DMatrixView::from_slice(&part[own..], own, s);
        own_step - own_coupling * step
    };
    // Every member at `shared` with its own coordinates `xs`, summed in order (the same for
    // any thread count), a block of members at a time: the costs, the sums and each member's
    // own parts; `None` where a texel's own block is not positive definite.
    const BLOCK: usize = 1 << 14;
    let pooled = |members: &[usize],
                  xs: &[Vec<f64>]|
     -> Option<(f64, DVector<f64>, DMatrix<f64>, Vec<f64>, Vec<f64>)> {
        let mut sums = (0.0, DVector::zeros(s), DMatrix::zeros(s, s));
        let mut costs = Vec::with_capacity(members.len());
        let mut own_parts = Vec::with_capacity(members.len() * stride);
        for (members, xs) in members.chunks(BLOCK).zip(xs.chunks(BLOCK)) {
            let parts: Option<Vec<Reduced>> = members
                .par_iter()
                .zip(xs)
                .map(|(&t, x)| reduce(x, t))
                .collect();
            for part in &parts? {
                sums.0 += part.cost;
                sums.1 += &part.gradient;
                sums.2 += &part.matrix;
                costs.push(part.cost);
                own_parts.extend(part.own_step.iter().chain(part.own_coupling.iter()));
            }
        }
        Some((sums.0, sums.1, sums.2, costs, own_parts))
    };
    let at_centre = |members: &[usize]| -> Vec<Vec<f64>> {
        members
            .iter()
            .map(|&t| {
                let mut x = texels[t].x.clone();
                x[..s].copy_from_slice(&centre[..s]);
                x
            })
            .collect()
    };
    let mut xs = at_centre(&members);
    let Some(first) = pooled(&members, &xs) else {
        return;
    };
    // Texels the basis cannot explain (astride an edge, holding another material too) are
    // left out: their cost per residual at the start is over `OUTLIER_RATIO` times the
    // members' median.
    let per_residual: Vec<f64> = first
        .3
        .iter()
        .zip(&members)
        .map(|(cost, &t)| cost / texels[t].residuals.max(1) as f64)
        .collect();
    drop(first);
    let mut sorted = per_residual.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    let inliers: Vec<usize> = members
        .iter()
        .zip(&per_residual)
        .filter(|&(_, &c)| c <= OUTLIER_RATIO * median)
        .map(|(&t, _)| t)
        .collect();
    let members = inliers;
    xs = at_centre(&members);
    let Some(mut at) = pooled(&members, &xs) else {
        return;
    };
    for _ in 0..POOLED_STEPS {
        let Some(factor) = at.2.clone().cholesky() else {
            return;
        };
        let step = factor.solve(&at.1).map(|v: f64| v.clamp(-1.0, 1.0));
        let mut scale = 1.0;
        let accepted = (0..POOLED_HALVINGS).find_map(|_| {
            let trial: Vec<Vec<f64>> = xs
                .iter()
                .enumerate()
                .map(|(i, x)| {
                    let own_step = own_step_of(&at.4, i, &step);
                    let mut next = x.clone();
                    for i in 0..s {
                        next[i] -= scale * step[i];
                    }
                    for i in 0..own {
                        next[s + i] -= scale * own_step[i].clamp(-1.0, 1.0);
                    }
                    next
                })
                .collect();
            scale *= 0.5;
            let next = pooled(&members, &trial)?;
            (next.0 < at.0).then_some((trial, next))
        });
        let Some((trial, next)) = accepted else {
            return;
        };
        centre[..s].copy_from_slice(&trial[0][..s]);
        xs = trial;
        at = next;
        if step.amax() < POOLED_TOLERANCE {
            return;
        }
    }
}

/// Labels of the texels from each texel's posterior cost under each basis it may take
/// (`candidates`: `(basis, cost)`, the cost twice the negative log posterior) and a Potts prior
/// on neighbouring labels (a material region is rarely one texel): `LABEL_COUPLING` per
/// 4-neighbour of another basis, minimised by iterated conditional modes (Besag 1986, "On the
/// statistical analysis of dirty pictures", section 2.5) in red-black order, so the result does
/// not depend on the thread count. Unseen texels take no part (they are filled afterwards).
fn label_smoothing(candidates: &[Vec<(usize, f64)>], blocks: &TexelBlocks) -> Vec<usize> {
    let least = |t: usize, energy: &dyn Fn(usize, f64) -> f64| {
        candidates[t]
            .iter()
            .min_by(|a, b| energy(a.0, a.1).total_cmp(&energy(b.0, b.1)))
            .expect("a basis for every texel")
            .0
    };
    let mut labels: Vec<usize> = (0..candidates.len())
        .map(|t| least(t, &|_, cost| cost))
        .collect();
    let seen = |t: usize| !blocks.of(t).is_empty();
    let width = blocks.grid.width;
    for _ in 0..ICM_SWEEPS {
        let mut changed = false;
        for parity in 0..2 {
            let next: Vec<usize> = (0..candidates.len())
                .into_par_iter()
                .map(|t| {
                    let (c, r) = (t % width / blocks.stride, t / width / blocks.stride);
                    if !seen(t) || (c + r) % 2 != parity || candidates[t].len() == 1 {
                        return labels[t];
                    }
                    least(t, &|l, cost| {
                        let disagree = blocks
                            .layout()
                            .neighbours(t)
                            .filter(|&n| seen(n) && labels[n] != l)
                            .count();
                        cost + LABEL_COUPLING * disagree as f64
                    })
                })
                .collect();
            changed |= next != labels;
            labels = next;
        }
        if !changed {
            break;
        }
    }
    labels
}

/// The bases of a clustering: centres of the specular coordinates, each basis's kind, and each
/// texel's basis.
struct Clusters {
    centres: Vec<Vec<f64>>,
    kinds: Vec<Kind>,
    assignment: Vec<usize>,
}

impl Clusters {
    /// Drops the bases no seen texel is labelled with, and renumbers the labels (an unseen
    /// texel of a dropped basis takes the first basis kept; it is filled from its neighbours
    /// afterwards). k-means finds a basis for any tight group of texels, however small; the
    /// labels, chosen with the Potts prior, can leave it without a texel (a few texels of
    /// `datasets/two-materials`' copper that `single` took for a metal, 0.5% of them at 48^2,
    /// each surrounded by copper taken for a dielectric). A basis without texels has no
    /// estimate; kept, it was reported with a share of 0 and counted as a basis in the choice
    /// of `K`.
    fn drop_empty(&mut self, seen: &[usize]) {
        let mut used = vec![false; self.centres.len()];
        for &t in seen {
            used[self.assignment[t]] = true;
        }
        if used.iter().all(|&u| u) || !used.iter().any(|&u| u) {
            return;
        }
        let mut renumbered = vec![0; used.len()];
        let mut next = 0;
        for (b, &u) in used.iter().enumerate() {
            if u {
                renumbered[b] = next;
                next += 1;
            }
        }
        for label in &mut self.assignment {
            *label = if used[*label] { renumbered[*label] } else { 0 };
        }
        fn keep<T>(values: &mut Vec<T>, used: &[bool]) {
            let mut b = 0;
            values.retain(|_| {
                b += 1;
                used[b - 1]
            });
        }
        keep(&mut self.centres, &used);
        keep(&mut self.kinds, &used);
    }

    /// Each centre becomes the precision-weighted mean of its texels' first `dim` coordinates,
    /// taken where they are clustered ([`clustering_coordinate`]: F0 itself, not `logit F0`);
    /// once the bases have kinds, a basis's F0 is that of its texels of its own kind only (the
    /// first `roughness` coordinates come from all its texels).
    fn recentre(&mut self, texels: &[TexelFit], seen: &[usize], dim: usize, roughness: usize) {
        let data =
            |t: usize, j: usize| clustering_coordinate(&texels[t], j, roughness, Weight::Data);
        self.recentre_over(texels, seen, dim, roughness, &data);
    }

    /// [`Clusters::recentre`] over the texels `members` only, texel `t`'s coordinate `j` and
    /// its weight given by `coordinate(t, j)` (Lloyd's iteration reads them from its
    /// [`ClusteringPoints`]).
    fn recentre_over(
        &mut self,
        texels: &[TexelFit],
        members: &[usize],
        dim: usize,
        roughness: usize,
        coordinate: &dyn Fn(usize, usize) -> (f64, f64),
    ) {
        let k = self.centres.len();
        let mut sums = vec![vec![0.0; dim]; k];
        let mut weights = vec![vec![0.0; dim]; k];
        for &t in members {
            let c = self.assignment[t];
            let own_kind = self.kinds.get(c).is_none_or(|&kind| kind == texels[t].kind);
            for j in 0..if own_kind { dim } else { roughness } {
                let (value, w) = coordinate(t, j);
                sums[c][j] += w * value;
                weights[c][j] += w;
            }
        }
        for c in 0..k {
            for j in 0..dim {
                if weights[c][j] > 0.0 {
                    let mean = sums[c][j] / weights[c][j];
                    self.centres[c][j] = if j < roughness { mean } else { logit(mean) };
                }
            }
        }
    }

    /// Lloyd's iteration on the truncated cost of [`weighted_kmeans`]: every texel goes to its
    /// nearest centre, and each centre becomes the mean of its texels within
    /// [`OUTLIER_COST`] of it, until no label changes.
    fn lloyd(
        &mut self,
        texels: &[TexelFit],
        points: &ClusteringPoints,
        seen: &[usize],
        roughness: usize,
    ) {
        let dim = points.dim;
        for _ in 0..LLOYD_ITERATIONS {
            let centres: Vec<Vec<f64>> = self
                .centres
                .iter()
                .map(|c| centre_values(c, roughness))
                .collect();
            let nearest: Vec<(usize, f64)> = (0..texels.len())
                .into_par_iter()
                .map(|t| {
                    centres
                        .iter()
                        .map(|c| points.distance(t, c))
                        .enumerate()
                        .min_by(|a, b| a.1.total_cmp(&b.1))
                        .expect("k >= 1")
                })
                .collect();
            let next: Vec<usize> = nearest.iter().map(|&(c, _)| c).collect();
            let changed = next != self.assignment;
            self.assignment = next;
            let inliers: Vec<usize> = seen
                .iter()
                .copied()
                .filter(|&t| nearest[t].1 < OUTLIER_COST)
                .collect();
            let marginal = |t: usize, j: usize| points.pairs[t * dim + j];
            self.recentre_over(texels, &inliers, dim, roughness, &marginal);
            if !changed {
                break;
            }
        }
    }
}

impl Clusters {
    /// Drops, one at a time, the bases that are not materials, each time giving their texels to
    /// the nearest remaining basis and re-running [`Clusters::lloyd`]:
    ///
    /// - a blend of two other bases ([`Clusters::is_blend`]): the texels astride a material
    ///   edge, whose photos mix two materials. No one material predicts them, so the
    ///   validation photo favours a basis of their own (on the three-material truth of
    ///   docs/maps.md at 32^2, 0.0069 against 0.0107), but it is not a material of the sample;
    /// - a basis whose removal lowers [`clustering_bic`]: one that does not pay for its
    ///   centre and mixing proportion in the clustering likelihood. As a texel costs at most
    ///   [`OUTLIER_COST`] and a basis `(dim + 1) ln n` of the BIC, a basis of fewer than
    ///   `(dim + 1) ln n / OUTLIER_COST` texels (1.7 of the 256 texels stage 5 samples at 32^2
    ///   with F0) is always dropped, and a larger one is kept only if its texels are well
    ///   apart from every other basis. `datasets/two-materials` with `single` at 32^2 kept a
    ///   basis of under 0.5% of its texels (a few copper texels fitted sharper than the rest).
    ///
    /// Returns the texels of the bases dropped.
    fn drop_non_materials(
        &mut self,
        texels: &[TexelFit],
        points: &ClusteringPoints,
        (seen, layout): (&[usize], Layout),
        roughness: usize,
    ) -> Vec<usize> {
        let mut dropped = Vec::new();
        while self.centres.len() > 1 {
            let k = self.centres.len();
            let bic = clustering_bic(points, seen, &self.centres, roughness);
            let without = |c: usize| {
                let mut centres = self.centres.clone();
                centres.remove(c);
                clustering_bic(points, seen, &centres, roughness)
            };
            let drop = (0..k)
                .find(|&c| self.is_blend(texels, (seen, layout), c, roughness))
                .or_else(|| {
                    (0..k)
                        .map(|c| (c, without(c)))
                        .filter(|&(_, b)| b < bic)
                        .min_by(|a, b| a.1.total_cmp(&b.1))
                        .map(|(c, _)| c)
                });
            let Some(c) = drop else { break };
            dropped.extend(seen.iter().filter(|&&t| self.assignment[t] == c));
            self.centres.remove(c);
            self.lloyd(texels, points, seen, roughness);
        }
        dropped
    }

    /// Whether basis `c` is a blend of two other bases `a` and `b`, in the coordinates of
    /// [`clustering_coordinate`], with `s` the spread (standard deviation) of `c`'s texels
    /// about its centre in each coordinate: (1) its centre lies within its spread of the
    /// segment from `a`'s centre to `b`'s (squared distance, each coordinate in units of `s`,
    /// at most [`OUTLIER_COST`], as a texel is an inlier of a basis), strictly between the
    /// two, and (2) its texels are spread along the segment (their positions on it, projected
    /// in the same units, have a standard deviation of at least [`BLEND_SPREAD`] of its
    /// length). A texel astride an edge mixes the two materials in whatever proportion the
    /// edge cuts it, so its estimate lies between theirs (a pixel is nearly linear in F0), at
    /// a place that varies from texel to texel; the texels of a material lying between two
    /// others in these coordinates (a dielectric of middling roughness) sit at one place,
    /// spread by their noise alone. And (0), on the texel grid (`layout`), nearly all of `c`'s
    /// texels are on an edge, beside a texel of another basis ([`BLEND_EDGE_SHARE`]), as a line
    /// astride an edge is and a material covering an area is not.
    fn is_blend(
        &self,
        texels: &[TexelFit],
        (seen, layout): (&[usize], Layout),
        c: usize,
        roughness: usize,
    ) -> bool {
        let indices: Vec<usize> = seen
            .iter()
            .copied()
            .filter(|&t| self.assignment[t] == c)
            .collect();
        if indices.len() < 2 || self.edge_share(&indices, (seen, layout)) < BLEND_EDGE_SHARE {
            return false;
        }
        let members: Vec<Vec<f64>> = indices
            .iter()
            .map(|&t| clustering_values(&texels[t], self.centres[c].len(), roughness))
            .collect();
        let centre = centre_values(&self.centres[c], roughness);
        let dim = centre.len();
        let spread: Vec<f64> = (0..dim)
            .map(|j| {
                let var = members
                    .iter()
                    .map(|v| (v[j] - centre[j]).powi(2))
                    .sum::<f64>()
                    / members.len() as f64;
                var.max(1e-18)
            })
            .collect();
        let dot = |x: &[f64], y: &[f64]| (0..dim).map(|j| x[j] * y[j] / spread[j]).sum::<f64>();
        let others: Vec<usize> = (0..self.centres.len()).filter(|&o| o != c).collect();
        others.iter().enumerate().any(|(i, &a)| {
            others[i + 1..].iter().any(|&b| {
                let start = centre_values(&self.centres[a], roughness);
                let end = centre_values(&self.centres[b], roughness);
                let along: Vec<f64> = (0..dim).map(|j| end[j] - start[j]).collect();
                let length2 = dot(&along, &along);
                let position = |v: &[f64]| {
                    let from: Vec<f64> = (0..dim).map(|j| v[j] - start[j]).collect();
                    dot(&from, &along) / length2
                };
                let u = position(&centre);
                let off: Vec<f64> = (0..dim)
                    .map(|j| centre[j] - start[j] - u * along[j])
                    .collect();
                let positions: Vec<f64> = members.iter().map(|v| position(v)).collect();
                let mean = positions.iter().sum::<f64>() / positions.len() as f64;
                let sd = (positions.iter().map(|p| (p - mean).powi(2)).sum::<f64>()
                    / positions.len() as f64)
                    .sqrt();
                length2 > 0.0
                    && 0.0 < u
                    && u < 1.0
                    && dot(&off, &off) <= OUTLIER_COST
                    && sd >= BLEND_SPREAD
            })
        })
    }

    /// The share of the texels `members` (of one basis) that have a seen neighbour
    /// ([`Layout::neighbours`]) of another basis.
    fn edge_share(&self, members: &[usize], (seen, layout): (&[usize], Layout)) -> f64 {
        let mut is_seen = vec![false; self.assignment.len()];
        for &t in seen {
            is_seen[t] = true;
        }
        let on_edge = members
            .iter()
            .filter(|&&t| {
                layout
                    .neighbours(t)
                    .any(|n| is_seen[n] && self.assignment[n] != self.assignment[t])
            })
            .count();
        on_edge as f64 / members.len().max(1) as f64
    }
}

/// The least share of a basis's texels beside a texel of another basis for the basis to be
/// taken for a blend ([`Clusters::is_blend`]). The texels astride an edge form a line one or
/// two texels wide, each beside a material it mixes: nearly all of them are on an edge (87%
/// and 93% of two such bases of the maps zoo, `tests/maps_zoo.rs`, on stage 5's sample of
/// every other texel and on every texel; k-means labels a few inside). A material that covers
/// an area has texels inside it: there a band of 17% of the sample had 25% of its texels
/// inside, a background of 47% 64%. Before, a material lying between two others in roughness
/// was dropped as their blend whatever its extent: that background (alpha 0.116, between
/// 0.047 and 0.414) went, and with it every basis but one.
const BLEND_EDGE_SHARE: f64 = 0.8;

/// The least spread along the segment between two bases, as a fraction of its length, of the
/// texels of a basis taken for a blend of the two ([`Clusters::is_blend`]): texels whose mixing
/// fractions spread evenly over a quarter of the range have a standard deviation of
/// `0.25 / sqrt 12 = 0.072` of it.
const BLEND_SPREAD: f64 = 0.07;

/// The BIC of a clustering of the texels `seen` about `centres` (Fraley & Raftery 2002,
/// "Model-based clustering, discriminant analysis, and density estimation", JASA 97, section
/// 4.1): `-2` times the classification log-likelihood of the mixture that [`weighted_kmeans`]'
/// truncated cost approximates (each texel's squared distance from its nearest centre in the
/// marginal precision of [`ClusteringPoints::distance`], at most [`OUTLIER_COST`], and `-2 n_c ln
/// (n_c / n)` for the mixing proportions) plus `(K dim + K - 1) ln n` for the centres and
/// proportions. The variances are the texels' own (data and basis prior), not estimated, so
/// they add no parameters. Lower is better.
fn clustering_bic(
    points: &ClusteringPoints,
    seen: &[usize],
    centres: &[Vec<f64>],
    roughness: usize,
) -> f64 {
    let k = centres.len();
    let centres: Vec<Vec<f64>> = centres
        .iter()
        .map(|c| centre_values(c, roughness))
        .collect();
    let mut counts = vec![0usize; k];
    let mut cost = 0.0;
    for &t in seen {
        let (c, d) = centres
            .iter()
            .map(|centre| points.distance(t, centre))
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .expect("k >= 1");
        counts[c] += 1;
        cost += d.min(OUTLIER_COST);
    }
    let n = seen.len().max(1) as f64;
    let mixing: f64 = counts
        .iter()
        .filter(|&&m| m > 0)
        .map(|&m| -2.0 * m as f64 * (m as f64 / n).ln())
        .sum();
    let dim = centres.first().map_or(0, Vec::len);
    cost + mixing + ((k * dim + k - 1) as f64) * n.ln()
}

/// A texel's first `dim` specular coordinates where they are clustered
/// ([`clustering_coordinate`]).
fn clustering_values(texel: &TexelFit, dim: usize, roughness: usize) -> Vec<f64> {
    (0..dim)
        .map(|j| clustering_coordinate(texel, j, roughness, Weight::Marginal).0)
        .collect()
}

/// A basis's centre (roughness coordinates and `logit F0`) in the coordinates of
/// [`clustering_coordinate`].
fn centre_values(centre: &[f64], roughness: usize) -> Vec<f64> {
    centre
        .iter()
        .enumerate()
        .map(|(j, &c)| if j < roughness { c } else { sigmoid(c) })
        .collect()
}

/// Candidates in a row whose basis [`weighted_kmeans`] drops as no material
/// ([`Clusters::drop_non_materials`]) before it stops adding bases. Where the texels hold
/// fewer materials than the `k` asked for, every candidate failed in turn, each with a run of
/// Lloyd's iteration: 233 tries and 11 s of the 42 s of CPU time of yellow_box's maps fit at
/// 256^2. In 30 maps fits (the synthetic truths of docs/maps.md at 16^2 to 256^2 texels, the
/// three real captures), 356 of the 363 bases kept came at the first try, 6 after one to three
/// failed ones, and one, the fourth basis of real_cards-blue's trial of four (not the number
/// chosen), after 46.
const FAILED_CANDIDATES: usize = 8;
/// Lloyd iterations of [`weighted_kmeans`] at most, after each basis is added.
const LLOYD_ITERATIONS: usize = 50;
/// Texels tried as the next centre of [`weighted_kmeans`] at most (evenly spaced over the
/// seen texels), so a step costs `CANDIDATES` passes over the texels at any grid.
const CANDIDATES: usize = 256;
/// The most a texel costs [`weighted_kmeans`]: the 99.7% point of a chi-square with 4 degrees
/// of freedom (one roughness and three F0 coordinates, each in units of its marginal standard
/// deviation). A texel further than this from every centre is counted as an outlier, not
/// averaged into a basis.
const OUTLIER_COST: f64 = 16.0;

/// How a texel's coordinates are weighted where the bases are averaged.
#[derive(Clone, Copy)]
enum Weight {
    /// By the data precision `(J^T J)_jj` alone (stage 4's means, around which the texels'
    /// priors are centred).
    Data,
    /// By the precision of the texel's estimate about its basis's centre, the data's
    /// variance plus the basis prior's (`SIGMA_LN_ALPHA`, `SIGMA_LOGIT_F0`): the weight of a
    /// Gaussian mixture over the texels' estimates (k-means).
    Marginal,
}

/// A texel's specular coordinate `j` where the bases are clustered and averaged, and its
/// `weight` there: the roughness coordinates as fitted (`ln alpha`); in place of `logit F0`,
/// F0 itself, with precision `(J^T J)_jj / (F0 (1 - F0))^2` and the prior's sd
/// `SIGMA_LOGIT_F0 F0 (1 - F0)` (the logit's, carried over at the texel's F0). A pixel is
/// nearly linear in Schlick's F0, so its precision there stays finite as F0 nears 1, where
/// `logit F0`'s falls as `(F0 (1 - F0))^2`: gold with red F0 1.0 had its saturated texels
/// weigh nothing in a basis's mean, which the mixed texels of the ellipse's edge then took to
/// red F0 0.48 (docs/maps.md, "A truth the change was not made on").
fn clustering_coordinate(
    texel: &TexelFit,
    j: usize,
    roughness: usize,
    weight: Weight,
) -> (f64, f64) {
    let (x, precision) = (texel.x[j], texel.precision[j]);
    let (value, precision, sd) = if j < roughness {
        (x, precision, SIGMA_LN_ALPHA)
    } else {
        // dF0 / dlogit F0 = F0 (1 - F0), in a form that does not round to 0 at large |x|.
        let e = (-x.abs()).exp();
        let slope = e / (1.0 + e).powi(2);
        (
            sigmoid(x),
            precision / (slope * slope).max(1e-300),
            SIGMA_LOGIT_F0 * slope,
        )
    };
    let w = match weight {
        Weight::Data => precision,
        Weight::Marginal => 1.0 / (1.0 / precision + sd * sd),
    };
    (value, w.max(1e-9))
}

/// Every texel's first `dim` coordinates where the bases are clustered, each with its marginal
/// precision ([`clustering_coordinate`] with [`Weight::Marginal`]), computed once for a
/// k-means. Computed in every distance instead (an exponential per F0 coordinate of the texel
/// and of the centre), they took 81% of a `single` maps fit of yellow_box at 256^2: global
/// k-means measures every texel against 256 candidate centres for each basis it adds.
struct ClusteringPoints {
    dim: usize,
    /// `(value, precision)` of texel `t`'s coordinate `j` at `t * dim + j`.
    pairs: Vec<(f64, f64)>,
}

impl ClusteringPoints {
    fn new(texels: &[TexelFit], dim: usize, roughness: usize) -> ClusteringPoints {
        ClusteringPoints {
            dim,
            pairs: texels
                .iter()
                .flat_map(|texel| {
                    (0..dim)
                        .map(move |j| clustering_coordinate(texel, j, roughness, Weight::Marginal))
                })
                .collect(),
        }
    }

    /// The squared distance of texel `t` from a centre given in the clustering coordinates
    /// ([`centre_values`]), each coordinate weighted by the texel's marginal precision.
    fn distance(&self, t: usize, centre: &[f64]) -> f64 {
        self.pairs[t * self.dim..(t + 1) * self.dim]
            .iter()
            .zip(centre)
            .map(|(&(value, w), &c)| w * (value - c).powi(2))
            .sum()
    }
}

/// Weighted k-means with outliers: centres of `dim` leading coordinates, each texel costing
/// its squared distance from the nearest centre, each coordinate weighted by the precision of
/// the texel's estimate about its basis ([`Weight::Marginal`]), and at most [`OUTLIER_COST`]:
/// the hard-assignment form of a Gaussian mixture with a uniform noise component (Banfield &
/// Raftery 1993, "Model-based Gaussian and non-Gaussian clustering", Biometrics 49, section
/// 4), as in trimmed k-means (Cuesta-Albertos, Gordaliza & Matran 1997, Annals of Statistics
/// 25). The centres are added one at a time, each at the texel that most lowers that cost
/// given the centres so far, then Lloyd's iteration ([`Clusters::lloyd`]): the fast global
/// k-means of Likas, Vlassis & Verbeek 2003 ("The global k-means clustering algorithm",
/// Pattern Recognition 36, section 2.1: the candidate with the largest bound on the cost it
/// removes), over at most [`CANDIDATES`] texels. Deterministic, so the bases do not depend on
/// the thread count.
///
/// Before, the start took the texel farthest from the centres so far and every texel counted
/// in full by its data precision, which finds far, small groups before near, large ones: on a
/// three-material truth the third basis went to the mixed texels of a gold ellipse's edge (F0
/// between the gold's and the paint's, and seen sharply) and not to a ceramic stripe of 13%
/// of the texels (docs/maps.md). A basis is of the kind most of its texels are. The first
/// `roughness` coordinates are the roughness ([`Clusters::recentre`]).
fn weighted_kmeans(
    texels: &[TexelFit],
    points: &ClusteringPoints,
    (seen, layout): (&[usize], Layout),
    roughness: usize,
    k: usize,
) -> Clusters {
    let dim = points.dim;
    let mut clusters = Clusters {
        centres: Vec::new(),
        kinds: Vec::new(),
        assignment: vec![0; texels.len()],
    };
    let mut candidates: Vec<usize> = seen
        .iter()
        .copied()
        .step_by(seen.len().div_ceil(CANDIDATES).max(1))
        .collect();
    let mut failed = 0;
    while clusters.centres.len() < k {
        let cost = |t: usize, centre: &[f64]| points.distance(t, centre).min(OUTLIER_COST);
        let centres: Vec<Vec<f64>> = clusters
            .centres
            .iter()
            .map(|c| centre_values(c, roughness))
            .collect();
        let nearest: Vec<f64> = seen
            .par_iter()
            .map(|&t| {
                centres
                    .iter()
                    .map(|c| cost(t, c))
                    .fold(OUTLIER_COST, f64::min)
            })
            .collect();
        let gains: Vec<f64> = candidates
            .par_iter()
            .map(|&n| {
                let centre = centre_values(&texels[n].x[..dim], roughness);
                seen.iter()
                    .zip(&nearest)
                    .map(|(&t, &d)| (d - cost(t, &centre)).max(0.0))
                    .sum()
            })
            .collect();
        let best = match (0..candidates.len()).max_by(|&a, &b| gains[a].total_cmp(&gains[b])) {
            Some(i) => candidates.swap_remove(i),
            None if clusters.centres.is_empty() => seen.first().copied().unwrap_or(0),
            None => break,
        };
        let before = clusters.centres.len();
        clusters.centres.push(texels[best].x[..dim].to_vec());
        clusters.lloyd(texels, points, seen, roughness);
        // The texels of a basis that is no material are no candidate for the next centre, so
        // the next goes to a material (at 16^2 the edge texels of the three-material truth
        // came before the ceramic).
        let dropped = clusters.drop_non_materials(texels, points, (seen, layout), roughness);
        candidates.retain(|t| !dropped.contains(t));
        failed = if clusters.centres.len() > before {
            0
        } else {
            failed + 1
        };
        if failed == FAILED_CANDIDATES {
            break;
        }
    }
    let assignment = &clusters.assignment;
    let kinds = (0..clusters.centres.len())
        .map(|c| {
            let members = seen.iter().filter(|&&t| assignment[t] == c);
            let metals = members
                .clone()
                .filter(|&&t| texels[t].kind == Kind::Metal)
                .count();
            match members.clone().next().map(|&t| texels[t].kind) {
                Some(Kind::Known) => Kind::Known,
                None => texels[0].kind,
                Some(_) if 2 * metals > members.count() => Kind::Metal,
                Some(_) => Kind::Dielectric,
            }
        })
        .collect();
    clusters.kinds = kinds;
    clusters
}

/// Lays a roughness floor on texel coordinates `x`: no roughness below `floor` along any axis
/// (the first `roughness` coordinates are `ln alpha`, or `ln alpha_x` and `ln alpha_y`); the
/// other coordinates are kept as fitted.
fn lay_roughness_floor(x: &mut [f64], roughness: usize, floor: Option<f64>) {
    if let Some(floor) = floor {
        for x in &mut x[..roughness] {
            *x = x.max(floor.ln());
        }
    }
}

/// [`lay_roughness_floor`] on every texel, in place (at 1024^2 a copy of the texels is a few
/// hundred megabytes).
fn with_roughness_floor(
    mut texels: Vec<TexelFit>,
    roughness: usize,
    floor: Option<f64>,
) -> Vec<TexelFit> {
    for texel in &mut texels {
        lay_roughness_floor(&mut texel.x, roughness, floor);
    }
    texels
}

/// Texels no pixel sees take the coordinates of the nearest seen texel in index order
/// (outward in both directions along the row-major order: enough for the thin unseen borders
/// of rectified photo sets).
fn fill_unseen(texels: &mut [TexelFit], blocks: &TexelBlocks) {
    let count = texels.len();
    let seen: Vec<usize> = (0..count).filter(|&t| !blocks.of(t).is_empty()).collect();
    if seen.is_empty() {
        return;
    }
    for t in 0..count {
        if blocks.of(t).is_empty() {
            let after = seen.partition_point(|&s| s < t);
            let nearest = [after.checked_sub(1), (after < seen.len()).then_some(after)]
                .into_iter()
                .flatten()
                .map(|i| seen[i])
                .min_by_key(|&s| s.abs_diff(t))
                .expect("some texel is seen");
            texels[t].x = texels[nearest].x.clone();
        }
    }
}

/// The photos' noise variance as a function of the radiance, measured from a fit's residuals:
/// the noise level function of Liu, Szeliski, Kang, Zitnick & Freeman 2008 ("Automatic
/// estimation and removal of noise from a single image", PAMI 30(2), section 3), per bin of
/// predicted radiance. A camera's noise grows with the signal (photon shot noise), and
/// `synth --noise` is relative; the one noise level the texels are solved under (stage 2) is an
/// average over the sample, too high for a dark texel's pixels and too low for a highlight's.
struct NoiseLevels {
    /// `(mean predicted radiance, noise variance)` per bin, by increasing radiance.
    bins: Vec<(f64, f64)>,
}

/// The noise level function's bins: half a stop of predicted radiance each, below the
/// brightest prediction, down to [`NOISE_BINS`] of them (the last takes everything darker);
/// a bin holds at least [`NOISE_BIN_RESIDUALS`] residuals, or its residuals join the next
/// darker bin.
const NOISE_BINS: usize = 40;
const NOISE_BIN_RESIDUALS: usize = 64;

impl NoiseLevels {
    /// The bins of the weighted squared residuals of `predicted` (the values of `pixels`), each
    /// mean scaled by `residuals / (residuals - parameters)` as stage 2 scales its one level.
    fn measure(
        records: &ShadingRecords,
        pixels: &[usize],
        predicted: &[[f64; 3]],
        parameters: usize,
    ) -> NoiseLevels {
        let brightest = predicted.iter().flatten().fold(0.0f64, |m, &v| m.max(v));
        // Per bin: count, sum of predictions, sum of weighted squared residuals.
        let mut sums = vec![(0usize, 0.0, 0.0); NOISE_BINS];
        for (value, &p) in predicted.iter().zip(pixels) {
            for (v, t) in value.iter().zip(records.target[p]) {
                let stops = 2.0 * (brightest / v).log2();
                let bin = if stops.is_finite() {
                    stops as usize
                } else {
                    NOISE_BINS
                };
                let sum = &mut sums[bin.min(NOISE_BINS - 1)];
                *sum = (
                    sum.0 + 1,
                    sum.1 + v,
                    sum.2 + records.weight[p] * (v - t).powi(2),
                );
            }
        }
        let residuals = 3 * pixels.len();
        let dof = residuals as f64 / residuals.saturating_sub(parameters).max(1) as f64;
        let mut merged: Vec<(usize, f64, f64)> = Vec::new();
        let mut pending = (0usize, 0.0, 0.0);
        for (count, value, squares) in sums {
            pending = (pending.0 + count, pending.1 + value, pending.2 + squares);
            if pending.0 >= NOISE_BIN_RESIDUALS {
                merged.push(std::mem::take(&mut pending));
            }
        }
        // The darkest few residuals join the darkest full bin.
        match merged.last_mut() {
            Some(last) => *last = (last.0 + pending.0, last.1 + pending.1, last.2 + pending.2),
            None if pending.0 > 0 => merged.push(pending),
            None => {}
        }
        let mut bins: Vec<(f64, f64)> = (merged.iter())
            .map(|&(count, value, squares)| (value / count as f64, dof * squares / count as f64))
            .collect();
        bins.reverse();
        NoiseLevels { bins }
    }

    /// The noise variance at predicted radiance `value`: linear between the bins' means, the
    /// end bins' beyond them; `fallback` without bins.
    fn variance(&self, value: f64, fallback: f64) -> f64 {
        let after = self.bins.partition_point(|&(v, _)| v < value);
        match (after.checked_sub(1), self.bins.get(after)) {
            (Some(i), Some(&(v1, s1))) => {
                let (v0, s0) = self.bins[i];
                s0 + (s1 - s0) * (value - v0) / (v1 - v0)
            }
            (Some(i), None) => self.bins[i].1,
            (None, Some(&(_, s))) => s,
            (None, None) => fallback,
        }
    }
}

/// Every texel's posterior standard deviations by the Laplace approximation (Bishop 2006,
/// *Pattern Recognition and Machine Learning*, section 4.4) with the photos' noise as
/// [`NoiseLevels`] measures it. A texel's value `x` minimises its negative log posterior,
/// whose Hessian is half the Gauss-Newton matrix [`TexelModel::linearise`] forms, `H = J^T W J
/// / sigma^2 + P` (Nocedal & Wright 2006, *Numerical Optimization*, section 10.3: `J^T J` in
/// place of the Hessian of a least-squares term), with `sigma^2` the noise level the texel was
/// solved under and `P` the precision of its prior under its basis (stage 4's; a texel of the
/// basis's other kind takes only the basis's roughness). Linearised, `x - x_true = H^-1 (J^T W
/// e / sigma^2 + P (c - x_true))` for noise `e` and prior centre `c`, whose covariance is the
/// sandwich `H^-1 B H^-1` (White 1980, "A heteroskedasticity-consistent covariance matrix
/// estimator", Econometrica 48(4)) with `B = J^T W S W J / sigma^4 + P`, `S` the noise
/// variance of each residual, a truth drawn from the prior contributing `P`. Where the noise
/// is `sigma^2` throughout, `B = H` and this is `H^-1`, the Laplace covariance itself; with the
/// one `sigma^2`, the sd of the bright metals of docs/maps.md's truths came out half their
/// errors, and a dark rubber's eight times them.
///
/// Evaluated once more per texel at the values in the maps, the roughness floor laid, rather
/// than kept from the solves: a few floats a texel, not a matrix. A texel no pixel sees has
/// its prior's sd. Not included: the choice of the bases, of the noise level and of the floor,
/// and errors of the capture's geometry.
fn texel_uncertainty(
    model: &TexelModel,
    blocks: &TexelBlocks,
    level: &Level,
    noise: &NoiseLevels,
) -> Uncertainty {
    let (dim, roughness, specular) = (model.dim(), model.roughness_dim(), model.specular_dim());
    let fresnel = specular > roughness;
    let sigma2 = level.sigma2;
    let sds: Vec<[[f32; 3]; 3]> = (level.texels.par_iter().enumerate())
        .map(|(t, texel)| {
            let b = level.labels[t];
            let prior = model.basis_prior(texel.kind, level.kinds[b], &level.prior_centres[b]);
            let matrix = |scale: &dyn Fn(f64) -> f64| {
                let (_, _, m) = model.linearised_any(&texel.x, blocks.of(t), sigma2, &prior, scale);
                nalgebra::DMatrix::from_row_slice(dim, dim, &m)
            };
            let inverse = matrix(&|_| 1.0)
                .cholesky()
                .expect("the prior's precision makes the Gauss-Newton matrix positive definite")
                .inverse();
            let score = matrix(&|value| noise.variance(value, sigma2) / sigma2);
            let covariance = &inverse * score * &inverse;
            // The delta method: the sd of `sigmoid(x)` is `sigmoid'(x) sd(x)`.
            let bounded = |first: usize| {
                [0, 1, 2].map(|c| {
                    let (x, v) = (texel.x[first + c], covariance[(first + c, first + c)]);
                    let p = sigmoid(x);
                    (p * (1.0 - p) * v.sqrt()) as f32
                })
            };
            let alpha = if roughness == 2 {
                let mean = 0.25 * (covariance.view((0, 0), (2, 2)).sum());
                [covariance[(0, 0)], covariance[(1, 1)], mean]
            } else {
                [covariance[(0, 0)]; 3]
            };
            [
                alpha.map(|v| v.sqrt() as f32),
                if fresnel {
                    bounded(roughness)
                } else {
                    [0.0; 3]
                },
                bounded(specular),
            ]
        })
        .collect();
    Uncertainty {
        grid: blocks.grid,
        roughness: sds.iter().map(|s| s[0]).collect(),
        specular: fresnel.then(|| sds.iter().map(|s| s[1]).collect()),
        diffuse: sds.iter().map(|s| s[2]).collect(),
    }
}

/// The maps of per-texel coordinates. Their base material (the fit file's top-level `alpha`,
/// `fresnel`, `diffuse`) is the texels' median of each component: what the material is where
/// most of it lies, not any one texel (every texel's own values are in the maps).
fn to_maps(model: &TexelModel, options: &MapsFitOptions, texels: &[TexelFit]) -> MaterialMaps {
    let base_dim = model.space.dim();
    let materials: Vec<Material> = texels
        .iter()
        .map(|f| model.space.material(&f.x[..base_dim]))
        .collect();
    let median = |value: &dyn Fn(&Material) -> f64| {
        let mut values: Vec<f64> = materials.iter().map(value).collect();
        values.sort_by(f64::total_cmp);
        values[values.len() / 2]
    };
    let mut base = materials[0].clone();
    base.alpha = std::array::from_fn(|i| median(&|m| m.alpha[i]));
    base.diffuse = std::array::from_fn(|i| median(&|m| m.diffuse[i]));
    if options.known_fresnel.is_none() {
        base.fresnel = FresnelSpec::Schlick {
            f0: std::array::from_fn(|i| median(&|m| m.fresnel.f0()[i])),
        };
    }
    MaterialMaps {
        grid: options.grid,
        diffuse: Some(materials.iter().map(|m| m.diffuse).collect()),
        specular: options
            .known_fresnel
            .is_none()
            .then(|| materials.iter().map(|m| m.fresnel.f0()).collect()),
        roughness: Some(materials.iter().map(|m| m.alpha).collect()),
        normal: model.normals.then(|| {
            texels
                .iter()
                .map(|f| normal_from_slopes(f.x[base_dim], f.x[base_dim + 1]).re())
                .collect()
        }),
        base,
    }
}

/// Predictions of `pixels` (of any photo) with per-texel coordinates under `roughness_floor`
/// ([`lay_roughness_floor`]), each pixel by the texel its centre sees.
fn maps_prediction(
    model: &TexelModel,
    texels: &[TexelFit],
    roughness_floor: Option<f64>,
    grid: TexelGrid,
    pixels: &[usize],
) -> Vec<[f64; 3]> {
    let spp = model.records.samples_per_pixel;
    pixels
        .par_iter()
        .map(|&p| {
            let t = grid.texel(model.records.uv[p * spp + spp / 2]);
            let mut x = texels[t].x.clone();
            lay_roughness_floor(&mut x, model.roughness_dim(), roughness_floor);
            model
                .predict(&x, &[p])
                .next()
                .expect("one pixel, one prediction")
        })
        .collect()
}

/// [`relative_error`] at the resolution of the texel grid: each texel's pixels are summed
/// (weighted, per channel) before prediction and photo are compared, `sqrt(sum_t (P_t -
/// T_t)^2 / sum_t T_t^2)`. Maps hold one material per texel, so the detail within a texel (a
/// material edge crossing it, an albedo gradient) is an error no number of bases and no
/// roughness floor changes, and neither is the photo's noise: per pixel, on
/// `datasets/two-materials` at 16^2 texels (8 x 8 pixels each), they made 0.100 of the
/// validation photo's 0.101, and the copper basis's gain came to 0.6% (docs/maps.md, "The
/// number of bases"). With one pixel per texel this is [`relative_error`].
fn texel_relative_error(
    predicted: &[[f64; 3]],
    records: &ShadingRecords,
    pixels: &[usize],
    grid: TexelGrid,
) -> f64 {
    let spp = records.samples_per_pixel;
    let mut sums = std::collections::BTreeMap::<usize, [[f64; 3]; 2]>::new();
    for (value, &p) in predicted.iter().zip(pixels) {
        let w = records.weight[p];
        let sum = sums
            .entry(grid.texel(records.uv[p * spp + spp / 2]))
            .or_insert([[0.0; 3]; 2]);
        for c in 0..3 {
            sum[0][c] += w * value[c];
            sum[1][c] += w * records.target[p][c];
        }
    }
    let (mut error, mut signal) = (0.0, 0.0);
    for [p, t] in sums.values() {
        for c in 0..3 {
            error += (p[c] - t[c]).powi(2);
            signal += t[c] * t[c];
        }
    }
    (error / signal.max(1e-300)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tabulated_texels_read_prepared_directions_as_the_lobe_computes_them() {
        // Pairs from the normal to grazing, both sides of the azimuth grid, and one below
        // the horizon (the lobe is 0 there); targets so that the residuals are not zero.
        let pairs: Vec<([f64; 3], [f64; 3])> = [
            (0.0, 0.0, 0.3, 0.0),
            (0.2, 0.5, 0.25, 0.7),
            (1.1, 2.9, 1.2, -3.0),
            (1.5, 0.1, 1.55, 3.1),
            (0.8, 1.0, 1.7, 2.0),
            (0.6, 0.0, 0.9, 1.6),
        ]
        .iter()
        .map(|&(ti, pi, to, po): &(f64, f64, f64, f64)| {
            let at = |t: f64, p: f64| [t.sin() * p.cos(), t.sin() * p.sin(), t.cos()];
            (at(ti, pi), at(to, po))
        })
        .collect();
        // Two pixels of three sub-samples each, so that a sub-sample's index is not its
        // pixel's.
        let mut records = ShadingRecords::of_pairs("pairs", &pairs);
        records.samples_per_pixel = 3;
        records.target = vec![[0.05, 0.1, 0.2], [0.3, 0.2, 0.1]];
        records.weight = vec![1.0; 2];
        let space = ParamSpace {
            diffuse: true,
            ..ParamSpace::plain(Model::Tabulated)
        };
        let generic = TexelModel {
            space,
            normals: false,
            records: &records,
            lobe_directions: None,
        };
        assert!(generic.prepares_directions());
        let pixels = [0, 1];
        let directions = generic.directions_of(&pixels);
        let prepared = TexelModel {
            lobe_directions: Some((&pixels, &directions)),
            ..generic
        };
        let prior = generic.generic_prior(Kind::Metal);
        for x in [
            vec![0.3f64.ln(), 0.5, -0.2, 1.0, -2.0, 0.0, 1.0],
            vec![1.4f64.ln(), 2.0, 1.0, 0.0, 0.5, -1.0, -3.0],
        ] {
            let (a, b) = (
                prepared.linearise::<7, 4>(&x, &pixels, 0.01, &prior),
                generic.linearise::<7, 4>(&x, &pixels, 0.01, &prior),
            );
            assert!(a.cost > 0.0);
            assert_eq!(a.cost, b.cost);
            assert_eq!(a.gradient, b.gradient);
            assert_eq!(a.matrix, b.matrix);
            let values: Vec<[f64; 3]> = prepared.predict(&x, &pixels).collect();
            let reference: Vec<[f64; 3]> = generic.predict(&x, &pixels).collect();
            assert_eq!(values, reference);
        }
    }

    #[test]
    fn predicted_decrease_is_the_quadratic_models_drop_to_its_minimum() {
        // cost(x) = 2 g.x + x^T M x, in the halved gradient and matrix `linearise` returns:
        // its minimum is at -M^-1 g, and the decrease from 0 to there is g^T M^-1 g.
        let matrix = [4.0, 1.0, 0.5, 1.0, 3.0, -0.2, 0.5, -0.2, 2.0];
        let gradient = [0.3, -1.2, 0.7];
        let cost = |x: &[f64]| {
            let quadratic: f64 = (0..3)
                .map(|a| (0..3).map(|b| x[a] * matrix[a * 3 + b] * x[b]).sum::<f64>())
                .sum();
            2.0 * (0..3).map(|a| gradient[a] * x[a]).sum::<f64>() + quadratic
        };
        let m = SMatrix::<f64, 3, 3>::from_row_slice(&matrix);
        let g = SVector::<f64, 3>::from_column_slice(&gradient);
        let inverse = m.try_inverse().expect("invertible");
        let minimum: Vec<f64> = (-(inverse * g)).as_slice().to_vec();
        let decrease = predicted_decrease(&m, &g).expect("positive definite");
        assert!(
            (decrease - (cost(&[0.0; 3]) - cost(&minimum))).abs() < 1e-12,
            "{decrease}"
        );
        // No step from the minimum lowers the cost.
        for a in 0..3 {
            let mut x = minimum.clone();
            x[a] += 1e-3;
            assert!(cost(&x) > cost(&minimum));
        }
        assert_eq!(
            predicted_decrease(
                &SMatrix::<f64, 2, 2>::new(1.0, 2.0, 2.0, 1.0),
                &SVector::<f64, 2>::new(1.0, 0.0)
            ),
            None
        );
    }

    /// A texel's estimate: alpha, F0, and their data precisions, 400 in `ln alpha` and 1e5 in
    /// F0 itself (so `1e5 (F0 (1 - F0))^2` in `logit F0`).
    fn estimate(kind: Kind, alpha: f64, f0: [f64; 3]) -> TexelFit {
        TexelFit {
            kind,
            x: [alpha.ln()].into_iter().chain(f0.map(logit)).collect(),
            data_cost: 0.0,
            residuals: 1,
            precision: [400.0]
                .into_iter()
                .chain(f0.map(|f| 1e5 * (f * (1.0 - f)).powi(2)))
                .collect(),
        }
    }

    /// Weighted k-means of every texel of `texels`, laid in one row in their order, with `k`
    /// bases: each basis's kind, alpha and red F0, by alpha.
    fn kmeans_bases(texels: &[TexelFit], k: usize) -> Vec<(Kind, f64, f64)> {
        let seen: Vec<usize> = (0..texels.len()).collect();
        let points = ClusteringPoints::new(texels, 4, 1);
        let row = Layout {
            grid: TexelGrid {
                width: texels.len(),
                height: 1,
            },
            stride: 1,
        };
        let clusters = weighted_kmeans(texels, &points, (&seen, row), 1, k);
        let mut found: Vec<(Kind, f64, f64)> = clusters
            .centres
            .iter()
            .zip(&clusters.kinds)
            .map(|(c, &kind)| (kind, c[0].exp(), sigmoid(c[1])))
            .collect();
        found.sort_by(|a, b| a.1.total_cmp(&b.1));
        found
    }

    /// Whether `found` ([`kmeans_bases`]) is `truth` (kind, alpha, red F0): alpha within 3%,
    /// red F0 within 0.01.
    fn assert_bases(found: &[(Kind, f64, f64)], truth: &[(Kind, f64, f64)]) {
        assert_eq!(found.len(), truth.len(), "{found:?}");
        for ((kind, alpha, red), (true_kind, true_alpha, true_red)) in found.iter().zip(truth) {
            assert_eq!(kind, true_kind, "{found:?}");
            assert!((alpha / true_alpha - 1.0).abs() < 0.03, "{found:?}");
            assert!((red - true_red).abs() < 0.01, "{found:?}");
        }
    }

    /// Texel estimates like those of the three-material truth of docs/maps.md at 32^2: a
    /// glossy paint (alpha 0.15) and a ceramic stripe (0.35, 13% of the texels) with a
    /// dielectric's F0, a gold whose red F0 is saturated (its `logit F0` hardly seen), and the
    /// mixed texels of the gold's edge (2%), from 10% to 60% gold, alpha and F0 between the
    /// two and sharply seen.
    fn three_materials_and_an_edge() -> Vec<TexelFit> {
        let gold_f0 = [0.9995, 0.78, 0.34];
        (0..1000)
            .map(|t| {
                let wobble = 1.0 + 0.01 * ((t * 37 % 11) as f64 - 5.0) / 5.0;
                match t % 100 {
                    0..66 => estimate(Kind::Dielectric, 0.15 * wobble, [0.04 * wobble; 3]),
                    66..79 => estimate(Kind::Dielectric, 0.35 * wobble, [0.04 * wobble; 3]),
                    79..98 => estimate(Kind::Metal, 0.4 * wobble, gold_f0),
                    m => {
                        let gold = 0.1 + 0.5 * (t / 100) as f64 / 9.0 + 0.05 * (m - 98) as f64;
                        let f0 = gold_f0.map(|g| gold * g + (1.0 - gold) * 0.04);
                        let alpha = (gold * 0.4f64.ln() + (1.0 - gold) * 0.15f64.ln()).exp();
                        estimate(Kind::Dielectric, alpha, f0)
                    }
                }
            })
            .collect()
    }

    const THREE_MATERIALS: [(Kind, f64, f64); 3] = [
        (Kind::Dielectric, 0.15, 0.04),
        (Kind::Dielectric, 0.35, 0.04),
        (Kind::Metal, 0.4, 0.9995),
    ];

    /// k-means with three bases finds the three materials of [`three_materials_and_an_edge`],
    /// and the gold keeps its red F0. Before, the farthest-point start gave the third basis to
    /// the edge texels, and the mean in `logit F0` took the gold's red F0 to the edge texels'.
    #[test]
    fn kmeans_finds_a_near_large_group_before_far_mixed_texels_and_keeps_a_saturated_f0() {
        assert_bases(
            &kmeans_bases(&three_materials_and_an_edge(), 3),
            &THREE_MATERIALS,
        );
    }

    /// Asked for four bases, k-means drops the one the edge texels of
    /// [`three_materials_and_an_edge`] would take (a blend of the paint and the gold); of three
    /// dielectrics on one line in these coordinates (alpha 0.15, 0.3 and 0.6, F0 0.04), it keeps
    /// the middle one, whose texels sit at one place, and drops a basis of 0.2% of the texels.
    /// One pixel per texel on a `width` x `height` grid, every texel seen.
    fn one_pixel_texels(width: usize, height: usize) -> TexelBlocks {
        TexelBlocks {
            offsets: (0..=width * height).collect(),
            pixels: (0..width * height).collect(),
            grid: TexelGrid { width, height },
            stride: 1,
        }
    }

    #[test]
    fn a_line_of_texels_astride_an_edge_covers_no_area_and_a_band_two_wide_does() {
        let (w, h) = (8, 6);
        let blocks = one_pixel_texels(w, h);
        // Basis 0 everywhere but on basis 1's staircase (a slanted edge's mixed texels) and
        // basis 2's band two texels wide.
        let mut labels = vec![0; w * h];
        for r in 0..h {
            labels[r * w + r] = 1;
            labels[r * w + r.saturating_sub(1)] = 1;
            labels[r * w + 6] = 2;
            labels[r * w + 7] = 2;
        }
        assert!(!covers_an_area(&labels, &blocks, 1));
        assert!(covers_an_area(&labels, &blocks, 2));
        assert!(covers_an_area(&labels, &blocks, 0));
        // An unseen texel breaks a block: the band with one texel unseen in every other row.
        let mut sparse = one_pixel_texels(w, h);
        sparse.offsets = (0..=w * h)
            .map(|t| t - (0..t).filter(|&u| u % w == 7 && (u / w) % 2 == 0).count())
            .collect();
        sparse.pixels.truncate(*sparse.offsets.last().unwrap());
        assert!(!covers_an_area(&labels, &sparse, 2));
    }

    #[test]
    fn kmeans_drops_blends_and_negligible_bases_but_keeps_a_material_between_two() {
        assert_bases(
            &kmeans_bases(&three_materials_and_an_edge(), 4),
            &THREE_MATERIALS,
        );
        let texels: Vec<TexelFit> = (0..1000)
            .map(|t| {
                let wobble = 1.0 + 0.01 * ((t * 37 % 11) as f64 - 5.0) / 5.0;
                let alpha = match t % 500 {
                    0..300 => 0.15,
                    300..425 => 0.3,
                    425..499 => 0.6,
                    _ => return estimate(Kind::Metal, 0.3, [0.5; 3]),
                };
                estimate(Kind::Dielectric, alpha * wobble, [0.04 * wobble; 3])
            })
            .collect();
        let truth = [0.15, 0.3, 0.6].map(|alpha| (Kind::Dielectric, alpha, 0.04));
        assert_bases(&kmeans_bases(&texels, 4), &truth);
    }
}
