//! The batch kernel (issue #15 item 1): the single-bounce term and the diffuse term of every
//! pixel of a fit, and the multiple-bounce term of the models in [`Added`] (Turquin's scale,
//! Kulla & Conty's lobe), evaluated over structure-of-arrays records in SIMD lanes, with the
//! derivatives of the prediction with respect to the kernel's parameters from the same pass.
//!
//! A fit renders the same sub-samples hundreds of times at different parameters, so everything
//! that depends only on the geometry is computed once ([`BatchRecords::new`]): the squared
//! components of the half vector `h = normalize(wi + wo)` and of `wi` and `wo`, their heights,
//! and `wi.h`. An evaluation at roughness `(ax, ay)` and Fresnel `F` is then, per sub-sample
//! (Walter et al. 2007 eq. 20, in the grazing-safe form of [`Microfacet::g2_over_cosines`]):
//!
//! | quantity | formula | derivative carried |
//! | --- | --- | --- |
//! | `D(h)` | `D1(s_h^2, h.z) / (ax ay)`, `s_h^2 = h.x^2/ax^2 + h.y^2/ay^2` (GGX: Walter eq. 33; Beckmann: eq. 25) | `d ln D / d ax = -1/ax + (2 h.x^2 / ax^3) / (s_h^2 + h.z^2)` (GGX), `-1/ax + 2 h.x^2 / (ax^3 h.z^2)` (Beckmann) |
//! | `|w.z| Lambda(w)` | `zL(w.z, s)`, `s^2 = ax^2 w.x^2 + ay^2 w.y^2` ([`ggx::z_lambda`], [`beckmann::z_lambda`]) | `d zL / d s = s / (2 sqrt(z^2 + s^2))` (GGX), `exp(-z^2/s^2) / (2 sqrt(pi))` (Beckmann); `d s / d ax = ax w.x^2 / s` |
//! | `G2 / (wi.z wo.z)` | `1 / den`; correlated `den = wi.z wo.z + wo.z zLi + wi.z zLo`, uncorrelated `(wi.z + zLi)(wo.z + zLo)` | `d den` from `d zLi`, `d zLo` |
//! | `f` | `F(wi.h) D / (4 den)` | `F` is per channel: Schlick `d F / d F0 = 1 - (1 - c)^5`; conductor `d F / d eta`, `d F / d k` by hand in the lanes ([`fresnel::conductor_with_slopes`], checked against `Dual64`) |
//!
//! The roughness derivatives are hand-derived and checked against the dual-number path of the
//! scalar kernel in the tests; the Fresnel values and derivatives come from the scalar kernel
//! itself. Lanes: the record loops are branch-free over the arrays and compiled once per
//! instruction set (AVX-512, AVX2+FMA, SSE2), the widest the CPU has chosen at run time, so the
//! compiler vectorises them. The lanes' arithmetic is [`Precision::F32`] by default (twice the
//! lanes of `f64` per instruction, and several times the square roots and divisions per cycle)
//! or [`Precision::F64`]; pixel sums are `f64` either way. Issue #15 item 2 measures the `f32`
//! path against the `f64` one (`docs/speed.md`, `tests/batch_precision.rs`). The scalar `f64`
//! kernel stays the reference of `brdf`, `albedo`, `stress` and the crosschecks.
//!
//! Pixel sums add the sub-samples of a pixel in index order inside one task, so results are
//! bit-identical for any thread count.

use crate::bsdf::albedo_table::{AlbedoTable, MU_COUNT};
use crate::bsdf::fast_msx::indirect_geometry;
use crate::bsdf::kulla_conty::KullaConty;
use crate::bsdf::registry::BatchLobe;
pub use crate::bsdf::registry::Precision;
use crate::bsdf::single::SingleBounce;
use crate::bsdf::Model;
use crate::microfacet::fresnel::{self, Fresnel};
use crate::microfacet::{beckmann, ggx, Height, Microfacet, NdfKind};
use crate::scalar::{Real, Rgb, Vec3};
use crate::shading::ShadingRecords;
use num_dual::Dual64;
use rayon::prelude::*;
use std::f64::consts::FRAC_1_PI;
use std::mem::MaybeUninit;

/// Pixels per rayon task (as [`super::TASK_PIXELS`]).
const TASK_PIXELS: usize = super::TASK_PIXELS;

/// `1 / (2 sqrt(pi))`: `d zL / d s` of Beckmann is this times `exp(-z^2 / s^2)`.
const HALF_INV_SQRT_PI: f64 = 0.282_094_791_773_878_14;

/// A lane's number type, `f32` or `f64`: the kernel's loops are written once over it.
pub trait LaneFloat: Real + Default + PartialOrd + 'static {
    /// The thread's scratch lanes of this type.
    fn with_lanes<R>(work: impl FnOnce(&mut Lanes<Self>) -> R) -> R;
}

thread_local! {
    /// Each thread's lanes, kept between tasks: a task's arrays are a few hundred kB, which
    /// the allocator would otherwise map and unmap (and the kernel zero) on every render.
    static LANES_F32: std::cell::RefCell<Lanes<f32>> = std::cell::RefCell::new(Lanes::default());
    static LANES_F64: std::cell::RefCell<Lanes<f64>> = std::cell::RefCell::new(Lanes::default());
}

impl LaneFloat for f32 {
    fn with_lanes<R>(work: impl FnOnce(&mut Lanes<f32>) -> R) -> R {
        LANES_F32.with_borrow_mut(work)
    }
}

impl LaneFloat for f64 {
    fn with_lanes<R>(work: impl FnOnce(&mut Lanes<f64>) -> R) -> R {
        LANES_F64.with_borrow_mut(work)
    }
}

/// The per-record arrays of the kept sub-samples, in the lanes' number type.
#[derive(Clone, Debug, Default)]
struct Geometry<F> {
    /// Squared components of the half vector.
    hx2: Vec<F>,
    hy2: Vec<F>,
    hz2: Vec<F>,
    /// `wi.x^2`, `wi.y^2`, `wi.z` (positive).
    ix2: Vec<F>,
    iy2: Vec<F>,
    iz: Vec<F>,
    /// `wo.x^2`, `wo.y^2`, `wo.z` (positive).
    ox2: Vec<F>,
    oy2: Vec<F>,
    oz: Vec<F>,
    /// `wi.h`, the angle the Fresnel term sees.
    cos_d: Vec<F>,
    /// The cells of `wi.z` and `wo.z` on the albedo tables' `mu` grid
    /// ([`AlbedoTable::mu_cell`]): lower node and the weight of the upper one.
    mu_node: [Vec<u32>; 2],
    mu_weight: [Vec<F>; 2],
    /// Irradiance of each record over the pixel's sub-sample count, per channel.
    weight: [Vec<F>; 3],
    /// With Fast-MSX's lobe ([`Added::FastMsx`]), empty otherwise: the squared components of
    /// its tilted normal `m_I` and `G_I / (2 c.v)` ([`indirect_geometry`]; `m_I = n` and 0
    /// where the lobe vanishes).
    indirect: [Vec<F>; 4],
}

impl<F: LaneFloat> Geometry<F> {
    /// One record's values, in the order of [`Geometry::real_lanes_mut`], from its directions
    /// `wi`, `wo` (both above the surface), its half vector `h` and its weight per channel,
    /// computed in `f64` (each is rounded once, when stored); and its two `mu` nodes. The last
    /// four values are Fast-MSX's, computed only when `indirect`.
    fn record_values(
        wi: [f64; 3],
        wo: [f64; 3],
        h: [f64; 3],
        weight: [f64; 3],
        indirect: bool,
    ) -> ([f64; REAL_LANES], [u32; 2]) {
        let (node_i, weight_i) = AlbedoTable::mu_cell(wi[2]);
        let (node_o, weight_o) = AlbedoTable::mu_cell(wo[2]);
        let (m, scale) = if indirect {
            indirect_geometry(Vec3::from_f64(wi), Vec3::from_f64(wo))
                .unwrap_or(([0.0, 0.0, 1.0], 0.0))
        } else {
            ([0.0; 3], 0.0)
        };
        let values = [
            h[0] * h[0],
            h[1] * h[1],
            h[2] * h[2],
            wi[0] * wi[0],
            wi[1] * wi[1],
            wi[2],
            wo[0] * wo[0],
            wo[1] * wo[1],
            wo[2],
            wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2],
            weight_i,
            weight_o,
            weight[0],
            weight[1],
            weight[2],
            m[0] * m[0],
            m[1] * m[1],
            m[2] * m[2],
            scale,
        ];
        (values, [node_i as u32, node_o as u32])
    }

    /// `records` records, every value 0 (the allocator's fresh zeroed pages, not yet touched,
    /// so the threads that fill them fault their own pages in).
    fn zeroed(records: usize, indirect: bool) -> Self {
        let lane = || vec![F::c(0.0); records];
        Geometry {
            hx2: lane(),
            hy2: lane(),
            hz2: lane(),
            ix2: lane(),
            iy2: lane(),
            iz: lane(),
            ox2: lane(),
            oy2: lane(),
            oz: lane(),
            cos_d: lane(),
            mu_node: [(); 2].map(|_| vec![0; records]),
            mu_weight: [(); 2].map(|_| lane()),
            weight: [(); 3].map(|_| lane()),
            indirect: [(); 4].map(|_| if indirect { lane() } else { Vec::new() }),
        }
    }

    /// The real-valued arrays in the order of [`Geometry::record_values`] (Fast-MSX's four only
    /// where they are stored), and the `mu` nodes.
    fn lanes_mut(&mut self) -> (Vec<&mut [F]>, [&mut [u32]; 2]) {
        let mut real: Vec<&mut [F]> = vec![
            &mut self.hx2,
            &mut self.hy2,
            &mut self.hz2,
            &mut self.ix2,
            &mut self.iy2,
            &mut self.iz,
            &mut self.ox2,
            &mut self.oy2,
            &mut self.oz,
            &mut self.cos_d,
        ];
        real.extend(self.mu_weight.iter_mut().map(|v| v.as_mut_slice()));
        real.extend(self.weight.iter_mut().map(|v| v.as_mut_slice()));
        real.extend(
            self.indirect
                .iter_mut()
                .filter(|v| !v.is_empty())
                .map(|v| v.as_mut_slice()),
        );
        let [i, o] = &mut self.mu_node;
        (real, [i, o])
    }

    /// The arrays of the records `r`: `[hx2, hy2, hz2, ix2, iy2, iz, ox2, oy2, oz]`.
    fn directions(&self, r: std::ops::Range<usize>) -> [&[F]; 9] {
        [
            &self.hx2, &self.hy2, &self.hz2, &self.ix2, &self.iy2, &self.iz, &self.ox2, &self.oy2,
            &self.oz,
        ]
        .map(|lane| &lane[r.clone()])
    }
}

/// The records' arrays in the precision chosen at construction.
#[derive(Clone, Debug)]
enum Stored {
    F32(Geometry<f32>),
    F64(Geometry<f64>),
}

/// The geometry of the sub-samples of a list of pixels, structure of arrays, for the batch
/// kernel. Only the sub-samples that can reflect are kept (irradiance not zero, both directions
/// strictly above the surface); the diffuse term needs only each pixel's irradiance sum.
#[derive(Clone, Debug)]
pub struct BatchRecords {
    /// The slots of each task of [`TASK_PIXELS`] pixels (the last may have fewer).
    blocks: Vec<Block>,
    /// Number of records (slots holding a sub-sample, not padding).
    records: usize,
    stored: Stored,
    /// Per pixel: sum over all its sub-samples of irradiance / (pi spp): the radiance of a
    /// white Lambertian layer.
    lambert: Vec<[f64; 3]>,
}

/// The slots of one task's pixels, record-major: record `k` of the task's pixel `i` (of
/// `pixels`) sits at `first + k * pixels + i`, for `k` below `depth`, the most records any of
/// its pixels has. A pixel with fewer records fills its remaining slots with [`padding`], of
/// weight zero. A pixel's sum is then the sum of `depth` rows, one SIMD add per row for all
/// the task's pixels, in the same order as the pixel's records: the sums are those of adding
/// each pixel's records in index order, to the bit.
#[derive(Clone, Copy, Debug)]
struct Block {
    first: usize,
    pixels: usize,
    depth: usize,
}

impl Block {
    fn slots(&self) -> std::ops::Range<usize> {
        self.first..self.first + self.depth * self.pixels
    }
}

/// Values per record of one evaluation, and what the pixel sums need.
#[derive(Default)]
pub struct Lanes<F> {
    /// `D / (4 den)`: the Fresnel-free part of `f`.
    lobe: Vec<F>,
    /// `d lobe / d ax` and `d lobe / d ay`.
    d_ax: Vec<F>,
    d_ay: Vec<F>,
    /// `F(wi.h)` per channel, and its derivatives by the channel's first and second Fresnel
    /// parameter (see [`PixelTangents`]).
    fresnel: [Vec<F>; 3],
    d_fresnel_a: [Vec<F>; 3],
    d_fresnel_b: [Vec<F>; 3],
    /// Per channel, the record's contribution to `d p_c / d ax` and `d p_c / d ay`.
    by_ax: [Vec<F>; 3],
    by_ay: [Vec<F>; 3],
    /// Per channel, with Turquin's compensation: `F F0 dg/dalpha` (see
    /// [`compensate`]).
    scale_slope: [Vec<F>; 3],
    /// With an added lobe (see [`Added`]): its channel-free part `Q` and `d Q / d ax`,
    /// `d Q / d ay`; with Turquin's scale, `g` and `dg / dalpha` in the first two
    /// ([`compensate`]).
    added: Vec<F>,
    added_ax: Vec<F>,
    added_ay: Vec<F>,
    /// Per pixel of the task and channel, in `f64`, the sums of the rows ([`Block`]) of
    /// `fresnel` (the value) and, with tangents, of `by_ax`, `by_ay`, `d_fresnel_a`,
    /// `d_fresnel_b`, in that order.
    sums: [[Vec<f64>; 3]; 5],
}

/// What the batch kernel evaluates: the single-bounce lobe and a model's multiple-bounce term
/// (`added`).
#[derive(Clone, Copy)]
pub struct Lobe<'a> {
    pub single: &'a SingleBounce<f64>,
    pub added: Added,
}

/// The multiple-bounce term the batch kernel evaluates with the single-bounce lobe, read from
/// the white albedo table of the surface's distribution and height model.
#[derive(Clone, Copy)]
pub enum Added {
    /// None: the model `single`.
    None,
    /// Turquin 2019 eq. 6-7: the single lobe scaled by `1 + F0 (1 - E(mu_o)) / E(mu_o)`.
    Turquin(&'static AlbedoTable),
    /// Kulla & Conty 2017: the lobe `(1 - E(mu_i)) (1 - E(mu_o)) F_ms / (pi (1 - E_avg))`
    /// added to the single lobe ([`kulla_conty_lanes`]).
    KullaConty(&'static AlbedoTable),
    /// Fast-MSX (Rosales et al. 2023 eq. 20): the lobe `D(m_I) G_I F(wi.h)^2 / (2 c.v)` added
    /// to the single lobe ([`fast_msx_lanes`]); the records must carry its geometry
    /// ([`BatchRecords::for_model`]).
    FastMsx,
}

impl<'a> From<&'a SingleBounce<f64>> for Lobe<'a> {
    fn from(single: &'a SingleBounce<f64>) -> Self {
        Lobe {
            single,
            added: Added::None,
        }
    }
}

impl<'a> Lobe<'a> {
    /// The whole value of `model` at `single`'s parameters, when the batch kernel evaluates
    /// it (the model's [`crate::bsdf::registry::Capabilities::batch`]); `None` for the other
    /// models (the render plan gives their multiple-bounce term to the scalar kernel).
    pub fn of(model: Model, single: &'a SingleBounce<f64>) -> Option<Lobe<'a>> {
        let table = || AlbedoTable::get(single.microfacet.ndf, single.height);
        let added = match model.capabilities().batch? {
            BatchLobe::Single => Added::None,
            BatchLobe::Turquin => Added::Turquin(table()),
            BatchLobe::KullaConty => Added::KullaConty(table()),
            BatchLobe::FastMsx => Added::FastMsx,
        };
        Some(Lobe { single, added })
    }
}

/// `(F0, d F0 / d first, d F0 / d second)` per channel of `fresnel`'s parameters (see
/// [`PixelTangents`]): Schlick `F0` itself; a conductor's normal reflectance by `eta` and `k`.
fn f0_with_tangents(fresnel: &Fresnel<f64>) -> [(f64, f64, f64); 3] {
    match *fresnel {
        Fresnel::Schlick { f0 } => f0.0.map(|f| (f, 1.0, 0.0)),
        Fresnel::Conductor { eta, k } => [0, 1, 2].map(|c| {
            let one = Dual64::from_re(1.0);
            let (e, kk) = (Dual64::from_re(eta.0[c]), Dual64::from_re(k.0[c]));
            let by_eta = fresnel::conductor(one, e.derivative(), kk);
            let by_k = fresnel::conductor(one, e, kk.derivative());
            (by_eta.re, by_eta.eps, by_k.eps)
        }),
        Fresnel::White | Fresnel::Dielectric { .. } => fresnel.f0().0.map(|f| (f, 0.0, 0.0)),
    }
}

/// The derivatives of each pixel's prediction with respect to the kernel's parameters, per
/// channel: what the chain rule of a fit needs (`fit::point::objective`).
#[derive(Clone, Debug, Default)]
pub struct PixelTangents {
    /// `d p_c / d ax`, `d p_c / d ay`.
    pub ax: Vec<[f64; 3]>,
    pub ay: Vec<[f64; 3]>,
    /// `d p_c` by the first Fresnel parameter of channel `c` (Schlick `F0_c`, conductor `eta_c`);
    /// zero for a Fresnel without parameters.
    pub fresnel_a: Vec<[f64; 3]>,
    /// `d p_c / d k_c` of a conductor; zero otherwise.
    pub fresnel_b: Vec<[f64; 3]>,
    /// `d p_c / d diffuse_c`: the white Lambertian radiance.
    pub diffuse: Vec<[f64; 3]>,
}

/// [`evaluate_any`] compiled for the instruction sets `features` as the function `name`
/// (x86-64 only; the caller checks the CPU has them).
macro_rules! compiled_for {
    ($name:ident, $features:literal) => {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $features)]
        fn $name<F: LaneFloat>(
            geometry: &Geometry<F>,
            lobe: &Lobe,
            block: Block,
            pixels: Pixels,
            lanes: &mut Lanes<F>,
        ) {
            evaluate_any(geometry, lobe, block, pixels, lanes)
        }
    };
}

impl BatchRecords {
    /// The records of `pixels` (indices into the per-pixel arrays of `records`), with lanes
    /// of the default precision ([`Precision::F32`]).
    pub fn new(records: &ShadingRecords, pixels: &[usize]) -> BatchRecords {
        BatchRecords::with_precision(records, pixels, Precision::default())
    }

    /// [`BatchRecords::new`] with lanes of `precision`.
    pub fn with_precision(
        records: &ShadingRecords,
        pixels: &[usize],
        precision: Precision,
    ) -> BatchRecords {
        BatchRecords::for_model(records, pixels, precision, Model::Single)
    }

    /// [`BatchRecords::with_precision`] with what [`Lobe::of`] `model` needs prepared besides
    /// the single lobe's geometry (Fast-MSX's tilted normals).
    pub fn for_model(
        records: &ShadingRecords,
        pixels: &[usize],
        precision: Precision,
        model: Model,
    ) -> BatchRecords {
        let indirect = model.capabilities().batch == Some(BatchLobe::FastMsx);
        match precision {
            Precision::F32 => {
                let (gathered, geometry) = gather::<f32>(records, pixels, indirect);
                gathered.with(Stored::F32(geometry))
            }
            Precision::F64 => {
                let (gathered, geometry) = gather::<f64>(records, pixels, indirect);
                gathered.with(Stored::F64(geometry))
            }
        }
    }

    /// The precision of the lanes.
    pub fn precision(&self) -> Precision {
        match self.stored {
            Stored::F32(_) => Precision::F32,
            Stored::F64(_) => Precision::F64,
        }
    }

    /// Number of pixels.
    pub fn pixel_count(&self) -> usize {
        self.lambert.len()
    }

    /// Per pixel: the radiance of a white Lambertian layer, the sum over its sub-samples of
    /// irradiance / (pi spp).
    pub fn lambert(&self) -> &[[f64; 3]] {
        &self.lambert
    }

    /// Number of records the kernel evaluates per render.
    pub fn record_count(&self) -> usize {
        self.records
    }

    /// Predicted radiance of every pixel for the single-bounce model `single` plus a
    /// Lambertian layer of albedo `diffuse`: the value of [`super::render_model`] of `single`.
    pub fn render<'a>(&self, lobe: impl Into<Lobe<'a>>, diffuse: [f64; 3]) -> Vec<[f64; 3]> {
        self.run(&lobe.into(), diffuse, false).0
    }

    /// [`BatchRecords::render`] and the derivatives of every pixel with respect to the
    /// parameters of `single` and to `diffuse`, from the same pass.
    pub fn render_with_tangents<'a>(
        &self,
        lobe: impl Into<Lobe<'a>>,
        diffuse: [f64; 3],
    ) -> (Vec<[f64; 3]>, PixelTangents) {
        let (values, tangents) = self.run(&lobe.into(), diffuse, true);
        (values, tangents.expect("asked for"))
    }

    /// The render of the Schlick lobe `single` plus a Lambertian layer of albedo `diffuse` as
    /// an affine function of F0: per pixel and channel, `[value at F0 = 0, slope by F0]`.
    /// Schlick's factor `F0 + (1 - F0)(1 - c)^5` (Schlick 1994 eq. 24) is affine in F0, so two
    /// value passes, at F0 = 0 and F0 = 1, give the slope as their difference (to rounding),
    /// at about half the cost of the pass with tangents (`bench --quick`'s kernel row: two
    /// `f64` value passes 19 ns per record against 35 ns). `single`'s own F0 is not read.
    pub fn render_affine_in_f0(
        &self,
        single: &SingleBounce<f64>,
        diffuse: [f64; 3],
    ) -> Vec<[[f64; 2]; 3]> {
        let at = |f0: f64| SingleBounce {
            fresnel: Fresnel::Schlick { f0: Rgb::splat(f0) },
            ..*single
        };
        let (zero, one) = (at(0.0), at(1.0));
        let (zero, one) = (self.render(&zero, diffuse), self.render(&one, diffuse));
        zero.iter()
            .zip(&one)
            .map(|(a, b)| [0, 1, 2].map(|c| [a[c], b[c] - a[c]]))
            .collect()
    }

    fn run(
        &self,
        lobe: &Lobe,
        diffuse: [f64; 3],
        tangents: bool,
    ) -> (Vec<[f64; 3]>, Option<PixelTangents>) {
        let n = self.pixel_count();
        // Filled by the tasks, every element once (see `write_pixels`), not zeroed first: at
        // one record per pixel, zeroing the output was a tenth of a render.
        let mut values = Vec::with_capacity(n);
        let mut t = tangents.then(|| [(); 4].map(|_| Vec::with_capacity(n)));
        let chunks = values.spare_capacity_mut()[..n]
            .par_chunks_mut(TASK_PIXELS)
            .enumerate();
        match &mut t {
            None => chunks.for_each(|(task, out)| {
                self.task(lobe, diffuse, task, out, None);
            }),
            Some([ax, ay, fa, fb]) => chunks
                .zip(ax.spare_capacity_mut()[..n].par_chunks_mut(TASK_PIXELS))
                .zip(ay.spare_capacity_mut()[..n].par_chunks_mut(TASK_PIXELS))
                .zip(fa.spare_capacity_mut()[..n].par_chunks_mut(TASK_PIXELS))
                .zip(fb.spare_capacity_mut()[..n].par_chunks_mut(TASK_PIXELS))
                .for_each(|(((((task, out), ax), ay), fa), fb)| {
                    self.task(lobe, diffuse, task, out, Some([ax, ay, fa, fb]));
                }),
        }
        // SAFETY: the tasks' chunks cover the first `n` elements, and `write_pixels` wrote
        // every element of its chunk (it checks that its sums are as long as the chunk).
        unsafe { values.set_len(n) };
        let t = t.map(|mut lanes| {
            // SAFETY: as for `values`.
            lanes.iter_mut().for_each(|lane| unsafe { lane.set_len(n) });
            let [ax, ay, fresnel_a, fresnel_b] = lanes;
            PixelTangents {
                ax,
                ay,
                fresnel_a,
                fresnel_b,
                diffuse: self.lambert.clone(),
            }
        });
        (values, t)
    }

    /// Pixels `task * TASK_PIXELS ..` into `out` (and their tangents into `tangents`: by ax,
    /// ay, first and second Fresnel parameter), in the stored precision.
    fn task(
        &self,
        lobe: &Lobe,
        diffuse: [f64; 3],
        task: usize,
        out: &mut [MaybeUninit<[f64; 3]>],
        tangents: Option<[&mut [MaybeUninit<[f64; 3]>]; 4]>,
    ) {
        match &self.stored {
            Stored::F32(geometry) => self.task_in(geometry, lobe, diffuse, task, out, tangents),
            Stored::F64(geometry) => self.task_in(geometry, lobe, diffuse, task, out, tangents),
        }
    }

    fn task_in<F: LaneFloat>(
        &self,
        geometry: &Geometry<F>,
        lobe: &Lobe,
        diffuse: [f64; 3],
        task: usize,
        out: &mut [MaybeUninit<[f64; 3]>],
        tangents: Option<[&mut [MaybeUninit<[f64; 3]>]; 4]>,
    ) {
        let block = self.blocks[task];
        let lambert = &self.lambert[task * TASK_PIXELS..][..out.len()];
        F::with_lanes(|lanes| {
            let pixels = Pixels {
                values: out,
                lambert,
                diffuse,
                tangents,
            };
            evaluate(geometry, lobe, block, pixels, lanes);
        });
    }
}

/// Where [`evaluate`] writes a task's pixels: their values (the Lambertian layer's
/// `diffuse * lambert` added) and, when asked, their tangents (by ax, ay, first and second
/// Fresnel parameter).
struct Pixels<'a> {
    values: &'a mut [MaybeUninit<[f64; 3]>],
    lambert: &'a [[f64; 3]],
    diffuse: [f64; 3],
    tangents: Option<[&'a mut [MaybeUninit<[f64; 3]>]; 4]>,
}

/// Real-valued arrays of a record: [`Geometry::record_values`].
const REAL_LANES: usize = 19;

/// What [`gather`] lays out besides the arrays.
struct Gathered {
    blocks: Vec<Block>,
    records: usize,
    lambert: Vec<[f64; 3]>,
}

impl Gathered {
    fn with(self, stored: Stored) -> BatchRecords {
        BatchRecords {
            blocks: self.blocks,
            records: self.records,
            stored,
            lambert: self.lambert,
        }
    }
}

/// The [`Block`]s, the Lambertian sums and the arrays of the records of `pixels`. Two parallel
/// passes over the tasks' pixels: the first counts each task's records and finds its depth, the
/// second writes the records (and the padding) straight into their slots in the final arrays.
fn gather<F: LaneFloat>(
    records: &ShadingRecords,
    pixels: &[usize],
    indirect: bool,
) -> (Gathered, Geometry<F>) {
    let tasks: Vec<&[usize]> = pixels.chunks(TASK_PIXELS).collect();
    let counts: Vec<(usize, usize)> = tasks
        .par_iter()
        .map(|task| {
            let stored_of = |&p: &usize| sub_samples(records, p).filter(|&s| stored(records, s));
            let depth = task.iter().map(|p| stored_of(p).count()).max();
            let count = task.iter().map(|p| stored_of(p).count()).sum();
            (depth.unwrap_or(0), count)
        })
        .collect();
    let mut blocks = Vec::with_capacity(tasks.len());
    let mut first = 0;
    for (task, &(depth, _)) in tasks.iter().zip(&counts) {
        blocks.push(Block {
            first,
            pixels: task.len(),
            depth,
        });
        first += depth * task.len();
    }
    let slots: Vec<usize> = blocks.iter().map(|b| b.depth * b.pixels).collect();
    let mut geometry = Geometry::<F>::zeroed(first, indirect);
    let (real, [node_i, node_o]) = geometry.lanes_mut();
    // Per task: its part of every array.
    let mut real: Vec<std::vec::IntoIter<&mut [F]>> = real
        .into_iter()
        .map(|lane| split_by_counts(lane, &slots).into_iter())
        .collect();
    let mut nodes = [node_i, node_o].map(|lane| split_by_counts(lane, &slots).into_iter());
    let parts: Vec<(Vec<&mut [F]>, [&mut [u32]; 2])> = slots
        .iter()
        .map(|_| {
            let real = real
                .iter_mut()
                .map(|lane| lane.next().expect("a part per task"));
            let [i, o] = &mut nodes;
            let nodes = [i.next(), o.next()].map(|n| n.expect("a part per task"));
            (real.collect(), nodes)
        })
        .collect();
    let norm = 1.0 / records.samples_per_pixel as f64;
    let padding = padding(indirect);
    let lambert: Vec<Vec<[f64; 3]>> = tasks
        .into_par_iter()
        .zip(parts)
        .map(|(task, (mut real, [node_i, node_o]))| {
            let width = task.len();
            let depth = node_i.len() / width.max(1);
            let mut write = |slot: usize, (values, nodes): &([f64; REAL_LANES], [u32; 2])| {
                for (lane, &value) in real.iter_mut().zip(values) {
                    lane[slot] = F::c(value);
                }
                (node_i[slot], node_o[slot]) = (nodes[0], nodes[1]);
            };
            task.iter()
                .enumerate()
                .map(|(i, &p)| {
                    let mut lambert = [0.0; 3];
                    let mut k = 0;
                    for s in sub_samples(records, p) {
                        let e = records.irradiance[s];
                        for c in 0..3 {
                            lambert[c] += e[c] * FRAC_1_PI;
                        }
                        if !stored(records, s) {
                            continue;
                        }
                        let (wi, wo) = (records.wi[s], records.wo[s]);
                        let sum = [wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]];
                        let len = (sum[0] * sum[0] + sum[1] * sum[1] + sum[2] * sum[2]).sqrt();
                        let h = sum.map(|v| v / len);
                        let weight = e.map(|e| e * norm);
                        let record = Geometry::<F>::record_values(wi, wo, h, weight, indirect);
                        write(k * width + i, &record);
                        k += 1;
                    }
                    for k in k..depth {
                        write(k * width + i, &padding);
                    }
                    lambert.map(|v| v * norm)
                })
                .collect()
        })
        .collect();
    let gathered = Gathered {
        blocks,
        records: counts.iter().map(|&(_, count)| count).sum(),
        lambert: lambert.concat(),
    };
    (gathered, geometry)
}

/// The record of a slot no sub-sample fills ([`Block`]): both directions and the half vector
/// along the normal, where every lobe is finite for any roughness, and weight zero, so that
/// it adds exactly zero to its pixel's sums.
fn padding(indirect: bool) -> ([f64; REAL_LANES], [u32; 2]) {
    let normal = [0.0, 0.0, 1.0];
    Geometry::<f64>::record_values(normal, normal, normal, [0.0; 3], indirect)
}

/// The sub-samples of pixel `p`.
fn sub_samples(records: &ShadingRecords, p: usize) -> std::ops::Range<usize> {
    let spp = records.samples_per_pixel;
    p * spp..(p + 1) * spp
}

/// Whether sub-sample `s` is a record of the batch: lit, with both directions above the
/// surface. Every sub-sample adds its irradiance to its pixel's Lambertian sum.
fn stored(records: &ShadingRecords, s: usize) -> bool {
    records.irradiance[s] != [0.0; 3] && records.wi[s][2] > 0.0 && records.wo[s][2] > 0.0
}

/// `slice` cut into consecutive parts of `counts` elements.
fn split_by_counts<'a, T>(mut slice: &'a mut [T], counts: &[usize]) -> Vec<&'a mut [T]> {
    counts
        .iter()
        .map(|&n| {
            let (part, rest) = std::mem::take(&mut slice).split_at_mut(n);
            slice = rest;
            part
        })
        .collect()
}

/// [`Lanes`] for the slots of `block`, and their pixel sums into `pixels`, in the widest SIMD
/// instruction set the CPU has (checked at run time; the loops are compiled once per set).
fn evaluate<F: LaneFloat>(
    geometry: &Geometry<F>,
    lobe: &Lobe,
    block: Block,
    pixels: Pixels,
    lanes: &mut Lanes<F>,
) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: the CPU has the features the function is compiled for.
            return unsafe { evaluate_avx512(geometry, lobe, block, pixels, lanes) };
        }
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: as above.
            return unsafe { evaluate_avx2(geometry, lobe, block, pixels, lanes) };
        }
    }
    evaluate_any(geometry, lobe, block, pixels, lanes)
}

compiled_for!(evaluate_avx512, "avx512f,avx2,fma");
compiled_for!(evaluate_avx2, "avx2,fma");

/// [`evaluate`]'s loops, inlined into each instruction-set variant.
#[inline(always)]
fn evaluate_any<F: LaneFloat>(
    geometry: &Geometry<F>,
    lobe: &Lobe,
    block: Block,
    pixels: Pixels,
    lanes: &mut Lanes<F>,
) {
    let tangents = pixels.tangents.is_some();
    fill_lanes_any(geometry, lobe, block.slots(), tangents, lanes);
    let Lanes {
        fresnel,
        by_ax,
        by_ay,
        d_fresnel_a,
        d_fresnel_b,
        sums,
        ..
    } = lanes;
    let quantities = if tangents { 5 } else { 1 };
    let lanes = [fresnel, by_ax, by_ay, d_fresnel_a, d_fresnel_b];
    for (lane, sums) in lanes.into_iter().zip(sums.iter_mut()).take(quantities) {
        for (lane, sums) in lane.iter().zip(sums) {
            row_sums(&lane[..block.depth * block.pixels], block.pixels, sums);
        }
    }
    write_pixels(sums, pixels);
}

/// The pixels' values and tangents from [`Lanes::sums`]: every element of `pixels`' slices
/// is written ([`BatchRecords::run`] relies on it).
#[inline(always)]
fn write_pixels(sums: &[[Vec<f64>; 3]; 5], pixels: Pixels) {
    let [value, rest @ ..] = sums;
    let (d, [v0, v1, v2]) = (pixels.diffuse, value);
    let n = pixels.values.len();
    assert!([v0, v1, v2].iter().all(|v| v.len() == n), "a sum per pixel");
    if d == [0.0; 3] {
        // Without a diffuse layer, the Lambertian sums (as large as the values) are not read.
        for (((out, a), b), c) in pixels.values.iter_mut().zip(v0).zip(v1).zip(v2) {
            out.write([*a, *b, *c]);
        }
    } else {
        let values = pixels.values.iter_mut().zip(pixels.lambert);
        for ((((out, l), a), b), c) in values.zip(v0).zip(v1).zip(v2) {
            out.write([a + d[0] * l[0], b + d[1] * l[1], c + d[2] * l[2]]);
        }
    }
    for ([a, b, c], out) in rest.iter().zip(pixels.tangents.into_iter().flatten()) {
        assert!(
            out.len() == n && [a, b, c].iter().all(|v| v.len() == n),
            "a sum per pixel"
        );
        for (((out, a), b), c) in out.iter_mut().zip(a).zip(b).zip(c) {
            out.write([*a, *b, *c]);
        }
    }
}

/// `sums[i]`: the sum in `f64` of `lane[k * pixels + i]` over the rows `k`, added in row order
/// (a pixel's records in index order; see [`Block`]).
#[inline(always)]
fn row_sums<F: LaneFloat>(lane: &[F], pixels: usize, sums: &mut Vec<f64>) {
    sums.clear();
    sums.resize(pixels, 0.0);
    for row in lane.chunks_exact(pixels.max(1)) {
        for (sum, value) in sums.iter_mut().zip(row) {
            *sum += value.re64();
        }
    }
}

/// The lanes' loops of [`evaluate_any`].
#[inline(always)]
fn fill_lanes_any<F: LaneFloat>(
    geometry: &Geometry<F>,
    lobe: &Lobe,
    range: std::ops::Range<usize>,
    tangents: bool,
    lanes: &mut Lanes<F>,
) {
    let single = lobe.single;
    let fused =
        !tangents && matches!(lobe.added, Added::None) && single.microfacet.ndf == NdfKind::Ggx;
    match single.fresnel {
        Fresnel::Schlick { f0 } if fused => {
            let schlick = SchlickLanes(f0.0.map(F::c));
            return fused_lanes(geometry, GgxLobe::new(single), schlick, range, lanes);
        }
        Fresnel::Conductor { eta, k } if fused => {
            let conductor = ConductorLanes {
                eta: eta.0.map(F::c),
                k: k.0.map(F::c),
            };
            return fused_lanes(geometry, GgxLobe::new(single), conductor, range, lanes);
        }
        _ => {}
    }
    lobes(geometry, single, range.clone(), tangents, lanes);
    fresnels(
        &single.fresnel,
        &geometry.cos_d[range.clone()],
        tangents,
        lanes,
    );
    let (ax, ay) = (single.microfacet.ax, single.microfacet.ay);
    // d alpha / d ax and d alpha / d ay of the tables' roughness alpha = sqrt(ax ay).
    let alpha = (ax * ay).sqrt();
    let dalpha = [F::c(alpha / (2.0 * ax)), F::c(alpha / (2.0 * ay))];
    let mut colours = None;
    match lobe.added {
        Added::None => {}
        Added::Turquin(table) if tangents => {
            compensate::<F, true>(geometry, single, table, range.clone(), lanes)
        }
        Added::Turquin(table) => {
            compensate::<F, false>(geometry, single, table, range.clone(), lanes)
        }
        Added::KullaConty(table) => {
            colours = Some(kulla_conty_lanes(
                table,
                single,
                geometry,
                range.clone(),
                tangents,
                lanes,
            ))
        }
        Added::FastMsx => fast_msx_lanes(geometry, single, range.clone(), tangents, lanes),
    }
    let scaled = matches!(lobe.added, Added::Turquin(_));
    let squared = matches!(lobe.added, Added::FastMsx);
    for c in 0..3 {
        let w = &geometry.weight[c][range.clone()];
        match (colours, squared) {
            (Some(colours), _) => weigh::<F, true, false>(w, c, None, colours[c], tangents, lanes),
            (None, true) => weigh::<F, false, true>(w, c, None, [F::zero(); 5], tangents, lanes),
            (None, false) => weigh::<F, false, false>(
                w,
                c,
                scaled.then_some(dalpha),
                [F::zero(); 5],
                tangents,
                lanes,
            ),
        }
    }
}

/// Weight channel `c` of every record by its irradiance `w`: the lanes become the record's
/// contribution to the pixel sums. With the single lobe `L`, its Fresnel `F` and, when
/// `ADDED`, an added lobe `Q Phi` of channel-free part `Q` ([`Lanes::added`]) and colour
/// `colour = [Phi, dPhi/dax, dPhi/day, dPhi/da, dPhi/db]`:
/// `fresnel` becomes `w (F L + Q Phi)`, the Fresnel derivatives `w (L dF + Q dPhi)`, and
/// `by_ax` gets `w (F dL/dax + Phi dQ/dax + Q dPhi/dax)` (`by_ay` alike). With Turquin's scale
/// (`scaled`: `d alpha / d ax`, `d alpha / d ay`) `by_ax` also gets
/// `w L scale_slope dalpha/dax` (see [`compensate`]). When `SQUARED`, the added lobe is
/// `Q F^2` (Fast-MSX's, [`fast_msx_lanes`]): `fresnel` becomes `w F (L + Q F)`, the Fresnel
/// derivatives `w dF (L + 2 Q F)` and `by_ax` `w F (dL/dax + F dQ/dax)`.
#[inline(always)]
fn weigh<F: LaneFloat, const ADDED: bool, const SQUARED: bool>(
    w: &[F],
    c: usize,
    scaled: Option<[F; 2]>,
    colour: [F; 5],
    tangents: bool,
    lanes: &mut Lanes<F>,
) {
    let n = w.len();
    let [phi, phi_ax, phi_ay, phi_a, phi_b] = colour;
    let added_len = if ADDED || SQUARED { n } else { 0 };
    let q = &lanes.added[..added_len];
    let lobe = &lanes.lobe[..n];
    if tangents {
        lanes.by_ax[c].resize(n, F::zero());
        lanes.by_ay[c].resize(n, F::zero());
        let (f, a, b) = (
            &lanes.fresnel[c][..n],
            &mut lanes.d_fresnel_a[c][..n],
            &mut lanes.d_fresnel_b[c][..n],
        );
        let (by_ax, by_ay) = (&mut lanes.by_ax[c][..n], &mut lanes.by_ay[c][..n]);
        let (d_ax, d_ay) = (&lanes.d_ax[..n], &lanes.d_ay[..n]);
        let (q_ax, q_ay) = (&lanes.added_ax[..added_len], &lanes.added_ay[..added_len]);
        for l in 0..n {
            let (wl, wf) = (w[l] * lobe[l], w[l] * f[l]);
            if SQUARED {
                let slope = wl + F::c(2.0) * wf * q[l];
                a[l] *= slope;
                b[l] *= slope;
                by_ax[l] = wf * (d_ax[l] + f[l] * q_ax[l]);
                by_ay[l] = wf * (d_ay[l] + f[l] * q_ay[l]);
                continue;
            }
            a[l] *= wl;
            b[l] *= wl;
            by_ax[l] = wf * d_ax[l];
            by_ay[l] = wf * d_ay[l];
            if ADDED {
                let wq = w[l] * q[l];
                a[l] += wq * phi_a;
                b[l] += wq * phi_b;
                by_ax[l] += w[l] * (phi * q_ax[l] + q[l] * phi_ax);
                by_ay[l] += w[l] * (phi * q_ay[l] + q[l] * phi_ay);
            }
        }
        if let Some(dalpha) = scaled {
            let slope = &lanes.scale_slope[c][..n];
            for l in 0..n {
                let wl = w[l] * lobe[l] * slope[l];
                by_ax[l] += wl * dalpha[0];
                by_ay[l] += wl * dalpha[1];
            }
        }
    }
    let f = &mut lanes.fresnel[c][..n];
    for l in 0..n {
        if SQUARED {
            f[l] *= w[l] * (lobe[l] + q[l] * f[l]);
            continue;
        }
        f[l] *= w[l] * lobe[l];
        if ADDED {
            f[l] += w[l] * q[l] * phi;
        }
    }
}

/// `1 / (k + 1)!` for `k = 0..12`: the Taylor coefficients of `(e^y - 1) / y`.
const EXPM1_TAYLOR: [f64; 12] = {
    let mut out = [0.0; 12];
    let mut factorial = 1.0;
    let mut k = 0;
    while k < 12 {
        factorial *= (k + 1) as f64;
        out[k] = 1.0 / factorial;
        k += 1;
    }
    out
};

/// `e^x - 1` for `|x| <= 8`, branch-free in the lanes' type: the Taylor series of `e^y - 1` to
/// degree 12 at `y = x / 32` (`|y| <= 1/4`: truncation below `1e-16` of the value), then five
/// doublings `e^(2y) - 1 = m (m + 2)`. Unlike `1 - e^x` by a subtraction, this keeps the
/// relative accuracy of `1 - E` where the albedo `E` is near 1. The albedo tables hold
/// `ln E` in `[-3.7, 1e-3]` (checked by a test).
#[inline(always)]
fn expm1<F: LaneFloat>(x: F) -> F {
    let y = x * F::c(1.0 / 32.0);
    let mut p = F::c(EXPM1_TAYLOR[11]);
    for k in (0..11).rev() {
        p = p * y + F::c(EXPM1_TAYLOR[k]);
    }
    let mut m = p * y;
    for _ in 0..5 {
        m = m * (m + F::c(2.0));
    }
    m
}

/// `single` in dual numbers, no derivative seeded.
fn lifted(single: &SingleBounce<f64>) -> SingleBounce<Dual64> {
    let lift = Dual64::from_re;
    SingleBounce {
        microfacet: Microfacet::new(
            single.microfacet.ndf,
            lift(single.microfacet.ax),
            lift(single.microfacet.ay),
        ),
        fresnel: match single.fresnel {
            Fresnel::White => Fresnel::White,
            Fresnel::Schlick { f0 } => Fresnel::Schlick {
                f0: Rgb(f0.0.map(lift)),
            },
            Fresnel::Conductor { eta, k } => Fresnel::Conductor {
                eta: Rgb(eta.0.map(lift)),
                k: Rgb(k.0.map(lift)),
            },
            Fresnel::Dielectric { eta } => Fresnel::Dielectric { eta: lift(eta) },
        },
        height: single.height,
    }
}

/// The kernel's parameters (see [`PixelTangents`]), each with a unit derivative in one of the
/// four copies of `single` in dual numbers: `ax`, `ay`, every channel's first Fresnel parameter,
/// every channel's second. Channel `c` of a value depends only on channel `c`'s Fresnel
/// parameters, so one seed serves all three channels.
pub fn seeded(single: &SingleBounce<f64>) -> [SingleBounce<Dual64>; 4] {
    let mut out = [lifted(single); 4];
    out[0].microfacet.ax = out[0].microfacet.ax.derivative();
    out[1].microfacet.ay = out[1].microfacet.ay.derivative();
    for (s, second) in [(2, false), (3, true)] {
        match &mut out[s].fresnel {
            Fresnel::Schlick { f0 } if !second => *f0 = f0.map(|v| v.derivative()),
            Fresnel::Conductor { eta, .. } if !second => *eta = eta.map(|v| v.derivative()),
            Fresnel::Conductor { k, .. } if second => *k = k.map(|v| v.derivative()),
            _ => {}
        }
    }
    out
}

/// Kulla & Conty 2017 ("Revisiting Physically Based Shading at Imageworks", the compensation
/// lobe with Fresnel; [`crate::bsdf::kulla_conty`]): `f_ms = s_c Q` with the channel-free
/// `Q = (1 - E(mu_i)) (1 - E(mu_o))` per record and `s_c = F_ms / (pi (1 - E_avg))` per channel.
/// Fills [`Lanes::added`] with `Q` (and its derivatives by `ax`, `ay` when `tangents`) and
/// returns each channel's colour `[s, ds/dax, ds/day, ds/da, ds/db]` for [`weigh`].
///
/// `E` at `alpha = sqrt(ax ay)`: the table's `ln E` row at `alpha` is computed once in
/// `Dual64` ([`AlbedoTable::ln_e_row`], carrying `d ln E / d alpha`); each record interpolates
/// it at its precomputed `mu` cells and takes `1 - E = -expm1(ln E)` ([`expm1`]), clamped
/// at 0 as the scalar model clamps, with `d (1 - E) / d alpha = -E d ln E / d alpha`. The
/// colours come from the scalar model itself ([`KullaConty::lobe_scale`]) in `f64` and, for
/// their derivatives, in `Dual64`.
#[inline(always)]
fn kulla_conty_lanes<F: LaneFloat>(
    table: &AlbedoTable,
    single: &SingleBounce<f64>,
    geometry: &Geometry<F>,
    range: std::ops::Range<usize>,
    tangents: bool,
    lanes: &mut Lanes<F>,
) -> [[F; 5]; 3] {
    let value = KullaConty::new(*single).lobe_scale().0;
    let slopes = if tangents {
        seeded(single).map(|s| KullaConty::new(s).lobe_scale().0.map(|v| v.eps))
    } else {
        [[0.0; 3]; 4]
    };
    let n = range.len();
    lanes.added.resize(n, F::zero());
    if tangents {
        lanes.added_ax.resize(n, F::zero());
        lanes.added_ay.resize(n, F::zero());
        kulla_conty_records::<F, true>(geometry, single, table, range, lanes);
    } else {
        kulla_conty_records::<F, false>(geometry, single, table, range, lanes);
    }
    [0, 1, 2].map(|c| {
        [
            value[c],
            slopes[0][c],
            slopes[1][c],
            slopes[2][c],
            slopes[3][c],
        ]
        .map(F::c)
    })
}

/// The `ln E` row of `table` at `alpha = sqrt(ax ay)` and its `alpha` derivative
/// ([`AlbedoTable::ln_e_row`] in `Dual64`), padded to 64 nodes so that an index masked by 63
/// needs no bounds check; and `alpha`.
fn ln_e_rows<F: LaneFloat>(table: &AlbedoTable, ax: f64, ay: f64) -> (([F; 64], [F; 64]), f64) {
    let alpha = Dual64::from_re((ax * ay).sqrt()).derivative();
    let row = table.ln_e_row(alpha);
    let (mut ln_e, mut d_ln_e) = ([F::zero(); 64], [F::zero(); 64]);
    for (j, v) in row.iter().enumerate().take(MU_COUNT) {
        ln_e[j] = F::c(v.re);
        d_ln_e[j] = F::c(v.eps);
    }
    ((ln_e, d_ln_e), alpha.re)
}

/// `(1 - E, d (1 - E) / d alpha)` at the `mu` cell `(node, u)` from the `ln E` row and its
/// slope `rows` (see [`kulla_conty_lanes`]); the slope only when `TANGENTS`.
#[inline(always)]
fn lost_energy<F: LaneFloat, const TANGENTS: bool>(
    (ln_e, d_ln_e): (&[F; 64], &[F; 64]),
    node: u32,
    u: F,
) -> (F, F) {
    let (zero, one) = (F::zero(), F::one());
    let (lo, hi) = (node as usize & 63, (node as usize + 1) & 63);
    let lost = zero - expm1(ln_e[lo] * (one - u) + ln_e[hi] * u);
    let slope = if TANGENTS {
        (lost - one) * (d_ln_e[lo] * (one - u) + d_ln_e[hi] * u)
    } else {
        zero
    };
    if lost > zero {
        (lost, slope)
    } else {
        (zero, zero)
    }
}

/// The per-record loop of [`kulla_conty_lanes`]: `Q` and, when `TANGENTS`, `dQ/dax`, `dQ/day`.
#[inline(always)]
fn kulla_conty_records<F: LaneFloat, const TANGENTS: bool>(
    geometry: &Geometry<F>,
    single: &SingleBounce<f64>,
    table: &AlbedoTable,
    range: std::ops::Range<usize>,
    lanes: &mut Lanes<F>,
) {
    let (ax, ay) = (single.microfacet.ax, single.microfacet.ay);
    let ((ln_e, d_ln_e), alpha) = ln_e_rows::<F>(table, ax, ay);
    let dalpha = [alpha / (2.0 * ax), alpha / (2.0 * ay)].map(F::c);
    let n = range.len();
    let nodes = [0, 1].map(|side| &geometry.mu_node[side][range.clone()]);
    let weights = [0, 1].map(|side| &geometry.mu_weight[side][range.clone()]);
    let q = &mut lanes.added[..n];
    let tangent_len = if TANGENTS { n } else { 0 };
    let (q_ax, q_ay) = (
        &mut lanes.added_ax[..tangent_len],
        &mut lanes.added_ay[..tangent_len],
    );
    let rows = (&ln_e, &d_ln_e);
    for l in 0..n {
        let (li, dli) = lost_energy::<F, TANGENTS>(rows, nodes[0][l], weights[0][l]);
        let (lo, dlo) = lost_energy::<F, TANGENTS>(rows, nodes[1][l], weights[1][l]);
        q[l] = li * lo;
        if TANGENTS {
            let d = dli * lo + li * dlo;
            q_ax[l] = d * dalpha[0];
            q_ay[l] = d * dalpha[1];
        }
    }
}

/// Fast-MSX (Rosales et al. 2023, [`crate::bsdf::fast_msx`]): its lobe is `Q F(wi.h)^2` with
/// the channel-free `Q = D(m_I) G_I / (2 c.v)` (eq. 18-20), whose direction-only parts were
/// prepared with the geometry ([`indirect_geometry`]). Fills [`Lanes::added`] with `Q` and,
/// when `tangents`, `dQ/dax = Q d ln D(m_I) / d ax` (`dQ/day` alike) with the same `d ln D`
/// as the single lobe's half vector (see [`ggx_lobes`], [`any_lobes`]); [`weigh`] squares the
/// Fresnel. GGX in the lanes, Beckmann a record at a time through
/// [`beckmann::density_stretched`].
fn fast_msx_lanes<F: LaneFloat>(
    geometry: &Geometry<F>,
    single: &SingleBounce<f64>,
    range: std::ops::Range<usize>,
    tangents: bool,
    lanes: &mut Lanes<F>,
) {
    let n = range.len();
    let mf = &single.microfacet;
    let (ax, ay) = (mf.ax, mf.ay);
    let [mx2, my2, mz2, scale] = [0, 1, 2, 3].map(|k| &geometry.indirect[k][range.clone()]);
    lanes.added.resize(n, F::zero());
    let tangent_len = if tangents { n } else { 0 };
    lanes
        .added_ax
        .resize(tangent_len.max(lanes.added_ax.len()), F::zero());
    lanes
        .added_ay
        .resize(tangent_len.max(lanes.added_ay.len()), F::zero());
    let q = &mut lanes.added[..n];
    let (q_ax, q_ay) = (
        &mut lanes.added_ax[..tangent_len],
        &mut lanes.added_ay[..tangent_len],
    );
    match mf.ndf {
        NdfKind::Ggx => {
            let k = F::c(1.0 / (std::f64::consts::PI * ax * ay));
            let (inv_ax2, inv_ay2) = (F::c(1.0 / (ax * ax)), F::c(1.0 / (ay * ay)));
            let (inv_ax, inv_ay) = (F::c(1.0 / ax), F::c(1.0 / ay));
            let (four_ax3, four_ay3) = (F::c(4.0 / (ax * ax * ax)), F::c(4.0 / (ay * ay * ay)));
            for l in 0..n {
                let t = mx2[l] * inv_ax2 + my2[l] * inv_ay2 + mz2[l];
                let inv_t = F::one() / t;
                let value = scale[l] * k * inv_t * inv_t;
                q[l] = value;
                if tangents {
                    q_ax[l] = value * (four_ax3 * mx2[l] * inv_t - inv_ax);
                    q_ay[l] = value * (four_ay3 * my2[l] * inv_t - inv_ay);
                }
            }
        }
        NdfKind::Beckmann => {
            for l in 0..n {
                let [mx2, my2, mz2, scale] = [mx2[l], my2[l], mz2[l], scale[l]].map(|v| v.re64());
                let d = beckmann::density_stretched(mx2 / (ax * ax) + my2 / (ay * ay), mz2.sqrt());
                let value = scale * d / (ax * ay);
                q[l] = F::c(value);
                if tangents {
                    // d ln D / d a = -1/a + 2 m_a^2 / (a^3 m_z^2).
                    let by = |a: f64, m2: f64| value * (2.0 * m2 / (a * a * a * mz2) - 1.0 / a);
                    q_ax[l] = F::c(by(ax, mx2));
                    q_ay[l] = F::c(by(ay, my2));
                }
            }
        }
    }
}

/// Turquin 2019 eq. 6-7 ([`crate::bsdf::turquin`]): scale the lanes by
/// `S_c = 1 + F0_c g(mu_o, alpha)`, `g = (1 - E) / E` with the white albedo `E` of `table`
/// at `mu_o = wo.z` and `alpha = sqrt(ax ay)`, before the weighting step: `F` becomes
/// `F S` (so the contribution is `w F S lobe`), `dF` becomes `dF S + F g dF0`, and
/// `scale_slope` gets `F F0 dg/dalpha`, the part of `d (F S lobe) / d alpha` the lobe's own
/// derivative misses (the weighting step adds it times `w lobe dalpha/da`).
///
/// `1 - E` and its `alpha` derivative come from the `ln E` row at `alpha`, as for Kulla &
/// Conty's lobe ([`lost_energy`]); then `g = (1 - E) / E` and `dg/dalpha = d(1 - E)/dalpha /
/// E^2`. The tables hold `E >= 0.02`, so the scalar model's floor of `E` at 1e-6 never binds.
/// The per-record values go to [`Lanes::added`] (`g`) and [`Lanes::added_ax`] (`dg/dalpha`),
/// which `turquin` has no other use for.
#[inline(always)]
fn compensate<F: LaneFloat, const TANGENTS: bool>(
    geometry: &Geometry<F>,
    single: &SingleBounce<f64>,
    table: &AlbedoTable,
    range: std::ops::Range<usize>,
    lanes: &mut Lanes<F>,
) {
    let n = range.len();
    let mf = &single.microfacet;
    let (rows, _) = ln_e_rows::<F>(table, mf.ax, mf.ay);
    let nodes = &geometry.mu_node[1][range.clone()];
    let weights = &geometry.mu_weight[1][range];
    lanes.added.resize(n, F::zero());
    lanes.added_ax.resize(n, F::zero());
    let (g, dg) = (&mut lanes.added[..n], &mut lanes.added_ax[..n]);
    let one = F::one();
    for l in 0..n {
        let (lost, slope) = lost_energy::<F, TANGENTS>((&rows.0, &rows.1), nodes[l], weights[l]);
        let inv_e = one / (one - lost);
        g[l] = lost * inv_e;
        dg[l] = slope * inv_e * inv_e;
    }
    let (g, dg) = (&lanes.added[..n], &lanes.added_ax[..n]);
    for (c, (f0, df0_a, df0_b)) in f0_with_tangents(&single.fresnel).into_iter().enumerate() {
        let (f0, df0_a, df0_b) = (F::c(f0), F::c(df0_a), F::c(df0_b));
        let fresnel = &mut lanes.fresnel[c][..n];
        if TANGENTS {
            lanes.scale_slope[c].resize(n, F::zero());
            let (a, b) = (
                &mut lanes.d_fresnel_a[c][..n],
                &mut lanes.d_fresnel_b[c][..n],
            );
            let slope = &mut lanes.scale_slope[c][..n];
            for l in 0..n {
                let (f, scale) = (fresnel[l], one + f0 * g[l]);
                a[l] = a[l] * scale + f * g[l] * df0_a;
                b[l] = b[l] * scale + f * g[l] * df0_b;
                slope[l] = f * f0 * dg[l];
            }
        }
        for l in 0..n {
            fresnel[l] *= one + f0 * g[l];
        }
    }
}

/// The Fresnel-free lobe `D / (4 den)` of the records in `range`, and its roughness
/// derivatives when `tangents`.
#[inline(always)]
fn lobes<F: LaneFloat>(
    geometry: &Geometry<F>,
    single: &SingleBounce<f64>,
    range: std::ops::Range<usize>,
    tangents: bool,
    lanes: &mut Lanes<F>,
) {
    let n = range.len();
    lanes.lobe.resize(n, F::zero());
    if tangents {
        lanes.d_ax.resize(n, F::zero());
        lanes.d_ay.resize(n, F::zero());
    }
    match (single.microfacet.ndf, tangents) {
        (NdfKind::Ggx, false) => ggx_lobes::<F, false>(geometry, single, range, lanes),
        (NdfKind::Ggx, true) => ggx_lobes::<F, true>(geometry, single, range, lanes),
        (NdfKind::Beckmann, _) => any_lobes(geometry, single, range, tangents, lanes),
    }
}

/// [`lobes`] for GGX: one branch-free loop over the record arrays, which the compiler turns
/// into SIMD lanes, with one division per record (three with tangents).
///
/// With `r = sqrt(z^2 + s^2)`, `|w.z| Lambda = (r - z) / 2` ([`ggx::z_lambda`]), so the
/// denominators of `G2 / (wi.z wo.z)` factor without a subtraction: correlated
/// `wi.z wo.z + wo.z zLi + wi.z zLo = (wo.z r_i + wi.z r_o) / 2` (the form of Heitz 2014
/// eq. 99 that real-time renderers use), uncorrelated `(wi.z + zLi)(wo.z + zLo) =
/// (r_i + wi.z)(r_o + wo.z) / 4`. With `t = s_h^2 + h.z^2` the lobe is
/// `D / (4 den) = K / (t^2 q)`: `q = wo.z r_i + wi.z r_o` and `K = 1 / (2 pi ax ay)`
/// (correlated), `q = (r_i + wi.z)(r_o + wo.z)` and `K = 1 / (pi ax ay)` (uncorrelated).
/// Derivatives: `d ln D / d ax = 4 h.x^2 / (ax^3 t) - 1 / ax`, `d r / d ax = ax w.x^2 / r`,
/// and `d ln lobe = d ln D - d ln q`; `1/t` and `1/q` come from the one division
/// `1 / (t^2 q)`.
#[inline(always)]
fn ggx_lobes<F: LaneFloat, const TANGENTS: bool>(
    geometry: &Geometry<F>,
    single: &SingleBounce<f64>,
    range: std::ops::Range<usize>,
    lanes: &mut Lanes<F>,
) {
    let ggx = GgxLobe::<F>::new(single);
    let n = range.len();
    let [hx2, hy2, hz2, ix2, iy2, iz, ox2, oy2, oz] = geometry.directions(range);
    let lobe = &mut lanes.lobe[..n];
    let tangent_len = if TANGENTS { n } else { 0 };
    let (d_ax, d_ay) = (
        &mut lanes.d_ax[..tangent_len],
        &mut lanes.d_ay[..tangent_len],
    );
    for l in 0..n {
        let directions = [
            hx2[l], hy2[l], hz2[l], ix2[l], iy2[l], iz[l], ox2[l], oy2[l], oz[l],
        ];
        let [value, by_ax, by_ay] = ggx.at::<TANGENTS>(directions);
        lobe[l] = value;
        if TANGENTS {
            d_ax[l] = by_ax;
            d_ay[l] = by_ay;
        }
    }
}

/// GGX's lobe at one roughness and height model, in the lanes' type: the constants of
/// [`ggx_lobes`]'s formulas, and one record's lobe from them.
#[derive(Clone, Copy)]
struct GgxLobe<F> {
    correlated: bool,
    /// `K`: `1 / (2 pi ax ay)` (correlated) or `1 / (pi ax ay)` (uncorrelated).
    k: F,
    ax2: F,
    ay2: F,
    inv_ax2: F,
    inv_ay2: F,
    /// `[a, 1/a, 4/a^3]` of each axis, for `d ln D / d a`.
    x_consts: [F; 3],
    y_consts: [F; 3],
}

impl<F: LaneFloat> GgxLobe<F> {
    fn new(single: &SingleBounce<f64>) -> Self {
        let (ax, ay) = (single.microfacet.ax, single.microfacet.ay);
        let correlated = single.height == Height::Correlated;
        GgxLobe {
            correlated,
            k: F::c(if correlated { 0.5 } else { 1.0 } / (std::f64::consts::PI * ax * ay)),
            ax2: F::c(ax * ax),
            ay2: F::c(ay * ay),
            inv_ax2: F::c(1.0 / (ax * ax)),
            inv_ay2: F::c(1.0 / (ay * ay)),
            x_consts: [ax, 1.0 / ax, 4.0 / (ax * ax * ax)].map(F::c),
            y_consts: [ay, 1.0 / ay, 4.0 / (ay * ay * ay)].map(F::c),
        }
    }

    /// `[lobe, d lobe / d ax, d lobe / d ay]` of the record whose direction values are
    /// `directions` (in the order of [`Geometry::directions`]); the derivatives are zero
    /// unless `TANGENTS`.
    #[inline(always)]
    fn at<const TANGENTS: bool>(&self, directions: [F; 9]) -> [F; 3] {
        let [hx2, hy2, hz2, ix2, iy2, zi, ox2, oy2, zo] = directions;
        let one = F::one();
        let t = hx2 * self.inv_ax2 + hy2 * self.inv_ay2 + hz2;
        let ri = (zi * zi + self.ax2 * ix2 + self.ay2 * iy2).sqrt();
        let ro = (zo * zo + self.ax2 * ox2 + self.ay2 * oy2).sqrt();
        let (ai, ao) = (ri + zi, ro + zo);
        let q = if self.correlated {
            zo * ri + zi * ro
        } else {
            ai * ao
        };
        let inv = one / (t * t * q);
        let value = self.k * inv;
        if !TANGENTS {
            return [value, F::zero(), F::zero()];
        }
        let (inv_t, inv_q) = (t * q * inv, t * t * inv);
        let (inv_ri, inv_ro) = (one / ri, one / ro);
        let by = |[a, inv_a, four_inv_a3]: [F; 3], h2: F, i2: F, o2: F| {
            let dln_d = four_inv_a3 * h2 * inv_t - inv_a;
            let (dri, dro) = (a * i2 * inv_ri, a * o2 * inv_ro);
            let dq = if self.correlated {
                zo * dri + zi * dro
            } else {
                dri * ao + ai * dro
            };
            value * (dln_d - dq * inv_q)
        };
        [
            value,
            by(self.x_consts, hx2, ix2, ox2),
            by(self.y_consts, hy2, iy2, oy2),
        ]
    }
}

/// [`lobes`] for any distribution, through the scalar kernel's functions
/// ([`beckmann::density_stretched`], [`beckmann::z_lambda`]) in `f64`; Beckmann's `exp` and
/// `erfc` have no SIMD form here, so this loop runs a lane at a time.
fn any_lobes<F: LaneFloat>(
    geometry: &Geometry<F>,
    single: &SingleBounce<f64>,
    range: std::ops::Range<usize>,
    tangents: bool,
    lanes: &mut Lanes<F>,
) {
    let mf = &single.microfacet;
    let (ax, ay) = (mf.ax, mf.ay);
    let (ax2, ay2) = (ax * ax, ay * ay);
    let (inv_ax2, inv_ay2) = (1.0 / ax2, 1.0 / ay2);
    let norm = 0.25 / (ax * ay);
    let n = range.len();
    let ndf = mf.ndf;
    let height = single.height;
    let arrays = geometry.directions(range);
    for l in 0..n {
        let [hx2, hy2, hz2, ix2, iy2, iz, ox2, oy2, oz] = arrays.map(|lane| lane[l].re64());
        let s2h = hx2 * inv_ax2 + hy2 * inv_ay2;
        let d1 = match ndf {
            NdfKind::Ggx => ggx::density_stretched(s2h, hz2.sqrt()),
            NdfKind::Beckmann => beckmann::density_stretched(s2h, hz2.sqrt()),
        };
        let si = (ax2 * ix2 + ay2 * iy2).sqrt();
        let so = (ax2 * ox2 + ay2 * oy2).sqrt();
        let (zli, zlo) = match ndf {
            NdfKind::Ggx => (ggx::z_lambda(iz, si), ggx::z_lambda(oz, so)),
            NdfKind::Beckmann => (beckmann::z_lambda(iz, si), beckmann::z_lambda(oz, so)),
        };
        let den = match height {
            Height::Correlated => iz * oz + oz * zli + iz * zlo,
            Height::Uncorrelated => (iz + zli) * (oz + zlo),
        };
        let lobe = d1 * norm / den;
        lanes.lobe[l] = F::c(lobe);
        if !tangents {
            continue;
        }
        // d ln D1 / d (s_h^2), then the chain through s_h^2 = hx2/ax^2 + hy2/ay^2.
        let dln_d1 = match ndf {
            NdfKind::Ggx => -2.0 / (s2h + hz2),
            NdfKind::Beckmann => -1.0 / hz2,
        };
        let dzl_ds = |z: f64, s: f64| -> f64 {
            if s <= 0.0 {
                return 0.0;
            }
            match ndf {
                NdfKind::Ggx => s / (2.0 * (z * z + s * s).sqrt()),
                NdfKind::Beckmann => HALF_INV_SQRT_PI * (-(z * z) / (s * s)).exp(),
            }
        };
        let (gi, go) = (dzl_ds(iz, si), dzl_ds(oz, so));
        // d s / d a = a w_a^2 / s (zero where s = 0, where gi, go are zero too).
        let (ri, ro) = (
            if si > 0.0 { 1.0 / si } else { 0.0 },
            if so > 0.0 { 1.0 / so } else { 0.0 },
        );
        let d_den = |dzli: f64, dzlo: f64| match height {
            Height::Correlated => oz * dzli + iz * dzlo,
            Height::Uncorrelated => dzli * (oz + zlo) + (iz + zli) * dzlo,
        };
        let dln_lobe = |a: f64, h2: f64, i2: f64, o2: f64| {
            let dln_d = -1.0 / a + dln_d1 * (-2.0 * h2 / (a * a * a));
            let dzli = gi * a * i2 * ri;
            let dzlo = go * a * o2 * ro;
            dln_d - d_den(dzli, dzlo) / den
        };
        lanes.d_ax[l] = F::c(lobe * dln_lobe(ax, hx2, ix2, ox2));
        lanes.d_ay[l] = F::c(lobe * dln_lobe(ay, hy2, iy2, oy2));
    }
}

/// `F(cos)` per channel for every record's `cos = wi.h`, and when `tangents` its derivatives
/// by the Fresnel's parameters (see [`PixelTangents`]): one branch-free loop per Fresnel kind,
/// through the scalar kernel's own functions, in the lanes' precision (the conductor's
/// derivatives by [`fresnel::conductor_with_slopes`]).
#[inline(always)]
fn fresnels<F: LaneFloat>(fresnel: &Fresnel<f64>, cos: &[F], tangents: bool, lanes: &mut Lanes<F>) {
    let n = cos.len();
    for c in 0..3 {
        lanes.fresnel[c].resize(n, F::zero());
        if tangents {
            lanes.d_fresnel_a[c].resize(n, F::zero());
            lanes.d_fresnel_b[c].resize(n, F::zero());
        }
    }
    let (zero, one) = (F::zero(), F::one());
    for c in 0..3 {
        let value = &mut lanes.fresnel[c][..n];
        let (by_a, by_b) = if tangents {
            (
                &mut lanes.d_fresnel_a[c][..n],
                &mut lanes.d_fresnel_b[c][..n],
            )
        } else {
            (&mut [][..], &mut [][..])
        };
        match *fresnel {
            Fresnel::White | Fresnel::Dielectric { .. } => {
                for (v, &cos) in value.iter_mut().zip(cos) {
                    *v = F::c(fresnel.eval(cos.re64()).0[c]);
                }
                by_a.fill(zero);
                by_b.fill(zero);
            }
            Fresnel::Schlick { f0 } => {
                let schlick = SchlickLanes(f0.0.map(F::c));
                for (v, &cos) in value.iter_mut().zip(cos) {
                    *v = schlick.at(c, cos);
                }
                for (d, &cos) in by_a.iter_mut().zip(cos) {
                    let m = one - unit(cos);
                    *d = one - m * m * m * m * m;
                }
                by_b.fill(zero);
            }
            Fresnel::Conductor { eta, k } => {
                let (e, kk) = (eta.0[c], k.0[c]);
                if tangents {
                    // In `f64` whatever the lanes: with `f32` arithmetic here, a `single` fit
                    // of `aluminium-pinhole` took 109 evaluations against 67.
                    for (((v, a), b), &cos) in value.iter_mut().zip(by_a).zip(by_b).zip(cos) {
                        let slopes = fresnel::conductor_with_slopes(unit(cos).re64(), e, kk);
                        [*v, *a, *b] = slopes.map(F::c);
                    }
                } else {
                    let conductor = ConductorLanes {
                        eta: eta.0.map(F::c),
                        k: k.0.map(F::c),
                    };
                    for (v, &cos) in value.iter_mut().zip(cos) {
                        *v = conductor.at(c, cos);
                    }
                }
            }
        }
    }
}

/// `cos` clamped to `[0, 1]`, the range the Fresnel terms take.
#[inline(always)]
fn unit<F: LaneFloat>(cos: F) -> F {
    let (zero, one) = (F::zero(), F::one());
    if cos < zero {
        zero
    } else if cos > one {
        one
    } else {
        cos
    }
}

/// A Fresnel term with parameters per channel, evaluated in the lanes' type: what the value
/// passes ([`fresnels`], [`fused_values`]) share.
trait LaneFresnel<F>: Copy {
    /// `F(cos)` of channel `c`.
    fn at(&self, c: usize, cos: F) -> F;
}

/// Schlick's `F0 + (1 - F0)(1 - cos)^5` (Schlick 1994 eq. 24), `F0` per channel.
#[derive(Clone, Copy)]
struct SchlickLanes<F>([F; 3]);

impl<F: LaneFloat> LaneFresnel<F> for SchlickLanes<F> {
    #[inline(always)]
    fn at(&self, c: usize, cos: F) -> F {
        let (one, f0) = (F::one(), self.0[c]);
        let m = one - unit(cos);
        f0 + (one - f0) * (m * m * m * m * m)
    }
}

/// A conductor's Fresnel, [`fresnel::conductor`], `eta` and `k` per channel.
#[derive(Clone, Copy)]
struct ConductorLanes<F> {
    eta: [F; 3],
    k: [F; 3],
}

impl<F: LaneFloat> LaneFresnel<F> for ConductorLanes<F> {
    #[inline(always)]
    fn at(&self, c: usize, cos: F) -> F {
        fresnel::conductor(unit(cos), self.eta[c], self.k[c])
    }
}

/// The lanes of the value of `single` alone (GGX; no added lobe, no tangents) in one loop:
/// each record's lobe ([`GgxLobe::at`]), its Fresnel per channel and its weight, the same
/// arithmetic as [`lobes`], [`fresnels`] and [`weigh`] in turn, to the bit, without storing the
/// lanes between them. Separate passes kept the square roots and divisions of the lobe and
/// of the Fresnel from overlapping with the rest of the work.
#[inline(always)]
fn fused_lanes<F: LaneFloat, R: LaneFresnel<F>>(
    geometry: &Geometry<F>,
    ggx: GgxLobe<F>,
    fresnel: R,
    range: std::ops::Range<usize>,
    lanes: &mut Lanes<F>,
) {
    let n = range.len();
    let [hx2, hy2, hz2, ix2, iy2, iz, ox2, oy2, oz] = geometry.directions(range.clone());
    let cos = &geometry.cos_d[range.clone()];
    let [w0, w1, w2] = [0, 1, 2].map(|c| &geometry.weight[c][range.clone()]);
    for lane in &mut lanes.fresnel {
        lane.resize(n, F::zero());
    }
    let [f0, f1, f2] = &mut lanes.fresnel;
    let (f0, f1, f2) = (&mut f0[..n], &mut f1[..n], &mut f2[..n]);
    for l in 0..n {
        let directions = [
            hx2[l], hy2[l], hz2[l], ix2[l], iy2[l], iz[l], ox2[l], oy2[l], oz[l],
        ];
        let [lobe, _, _] = ggx.at::<false>(directions);
        f0[l] = fresnel.at(0, cos[l]) * (w0[l] * lobe);
        f1[l] = fresnel.at(1, cos[l]) * (w1[l] * lobe);
        f2[l] = fresnel.at(2, cos[l]) * (w2[l] * lobe);
    }
}

#[cfg(test)]
mod tests;
