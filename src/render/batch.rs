//! The batch kernel (issue #15 item 1): the single-bounce term and the diffuse term of every
//! pixel of a fit, evaluated over structure-of-arrays records in SIMD lanes, with the
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
//! | `f` | `F(wi.h) D / (4 den)` | `F` is per channel: Schlick `d F / d F0 = 1 - (1 - c)^5`; conductor `d F / d eta`, `d F / d k` from two `Dual64` passes of [`fresnel::conductor`] |
//!
//! The roughness derivatives are hand-derived and checked against the dual-number path of the
//! scalar kernel in the tests; the Fresnel values and derivatives come from the scalar kernel
//! itself. Lanes: the record loops are branch-free over the arrays and compiled once per
//! instruction set (AVX-512, AVX2+FMA, SSE2), the widest the CPU has chosen at run time, so the
//! compiler vectorises them; the arithmetic is `f64`, so the path needs no precision study (issue #15
//! item 2: f32 is not used). The scalar `f64` kernel stays the reference of `brdf`, `albedo`,
//! `stress` and the crosschecks.
//!
//! Pixel sums add the sub-samples of a pixel in index order inside one task, so results are
//! bit-identical for any thread count.

use crate::bsdf::albedo_table::AlbedoTable;
use crate::bsdf::single::SingleBounce;
use crate::microfacet::fresnel::{self, Fresnel};
use crate::microfacet::{beckmann, ggx, Height, NdfKind};
use crate::scalar::Real;
use crate::shading::ShadingRecords;
use num_dual::Dual64;
use rayon::prelude::*;
use std::f64::consts::FRAC_1_PI;

/// Pixels per rayon task (as [`super::TASK_PIXELS`]).
const TASK_PIXELS: usize = super::TASK_PIXELS;

/// `1 / (2 sqrt(pi))`: `d zL / d s` of Beckmann is this times `exp(-z^2 / s^2)`.
const HALF_INV_SQRT_PI: f64 = 0.282_094_791_773_878_14;

/// The geometry of the sub-samples of a list of pixels, structure of arrays, for the batch
/// kernel. Only the sub-samples that can reflect are kept (irradiance not zero, both directions
/// strictly above the surface); the diffuse term needs only each pixel's irradiance sum.
#[derive(Clone, Debug, Default)]
pub struct BatchRecords {
    /// Records of pixel `k` (position in the pixel list) are `start[k]..start[k + 1]`.
    start: Vec<usize>,
    /// Squared components of the half vector.
    hx2: Vec<f64>,
    hy2: Vec<f64>,
    hz2: Vec<f64>,
    /// `wi.x^2`, `wi.y^2`, `wi.z` (positive).
    ix2: Vec<f64>,
    iy2: Vec<f64>,
    iz: Vec<f64>,
    /// `wo.x^2`, `wo.y^2`, `wo.z` (positive).
    ox2: Vec<f64>,
    oy2: Vec<f64>,
    oz: Vec<f64>,
    /// `wi.h`, the angle the Fresnel term sees.
    cos_d: Vec<f64>,
    /// Irradiance of each record over the pixel's sub-sample count, per channel.
    weight: [Vec<f64>; 3],
    /// Per pixel: sum over all its sub-samples of irradiance / (pi spp): the radiance of a
    /// white Lambertian layer.
    lambert: Vec<[f64; 3]>,
}

thread_local! {
    /// Each thread's lanes, kept between tasks: a task's arrays are a few hundred kB, which
    /// the allocator would otherwise map and unmap (and the kernel zero) on every render.
    static LANES: std::cell::RefCell<Lanes> = std::cell::RefCell::new(Lanes::default());
}

/// Values per record of one evaluation, and what the pixel sums need.
#[derive(Default)]
struct Lanes {
    /// `D / (4 den)`: the Fresnel-free part of `f`.
    lobe: Vec<f64>,
    /// `d lobe / d ax` and `d lobe / d ay`.
    d_ax: Vec<f64>,
    d_ay: Vec<f64>,
    /// `F(wi.h)` per channel, and its derivatives by the channel's first and second Fresnel
    /// parameter (see [`PixelTangents`]).
    fresnel: [Vec<f64>; 3],
    d_fresnel_a: [Vec<f64>; 3],
    d_fresnel_b: [Vec<f64>; 3],
    /// Per channel, the record's contribution to `d p_c / d ax` and `d p_c / d ay`.
    by_ax: [Vec<f64>; 3],
    by_ay: [Vec<f64>; 3],
    /// Per channel, with Turquin's compensation: `F F0 dg/dalpha` (see
    /// [`BatchRecords::compensate`]).
    scale_slope: [Vec<f64>; 3],
}

/// What the batch kernel evaluates: the single-bounce lobe, optionally scaled by Turquin's
/// compensation `1 + F0 (1 - E(mu_o)) / E(mu_o)` with the white albedo table `turquin`.
#[derive(Clone, Copy)]
pub struct Lobe<'a> {
    pub single: &'a SingleBounce<f64>,
    pub turquin: Option<&'static AlbedoTable>,
}

impl<'a> From<&'a SingleBounce<f64>> for Lobe<'a> {
    fn from(single: &'a SingleBounce<f64>) -> Self {
        Lobe {
            single,
            turquin: None,
        }
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

/// `BatchRecords::fill_lanes_any` compiled for the instruction sets `features` as the method
/// `name` (x86-64 only; the caller checks the CPU has them).
macro_rules! compiled_for {
    ($name:ident, $features:literal) => {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $features)]
        fn $name(
            &self,
            lobe: &Lobe,
            range: std::ops::Range<usize>,
            tangents: bool,
            lanes: &mut Lanes,
        ) {
            self.fill_lanes_any(lobe, range, tangents, lanes)
        }
    };
}

impl BatchRecords {
    /// The records of `pixels` (indices into the per-pixel arrays of `records`).
    pub fn new(records: &ShadingRecords, pixels: &[usize]) -> BatchRecords {
        let spp = records.samples_per_pixel;
        let mut batch = BatchRecords {
            start: Vec::with_capacity(pixels.len() + 1),
            lambert: Vec::with_capacity(pixels.len()),
            ..BatchRecords::default()
        };
        batch.start.push(0);
        let norm = 1.0 / spp as f64;
        for &p in pixels {
            let mut lambert = [0.0; 3];
            for s in p * spp..(p + 1) * spp {
                let e = records.irradiance[s];
                if e == [0.0; 3] {
                    continue;
                }
                for c in 0..3 {
                    lambert[c] += e[c] * FRAC_1_PI;
                }
                let (wi, wo) = (records.wi[s], records.wo[s]);
                if wi[2] <= 0.0 || wo[2] <= 0.0 {
                    continue;
                }
                let sum = [wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]];
                let len = (sum[0] * sum[0] + sum[1] * sum[1] + sum[2] * sum[2]).sqrt();
                let h = sum.map(|v| v / len);
                batch.hx2.push(h[0] * h[0]);
                batch.hy2.push(h[1] * h[1]);
                batch.hz2.push(h[2] * h[2]);
                batch.ix2.push(wi[0] * wi[0]);
                batch.iy2.push(wi[1] * wi[1]);
                batch.iz.push(wi[2]);
                batch.ox2.push(wo[0] * wo[0]);
                batch.oy2.push(wo[1] * wo[1]);
                batch.oz.push(wo[2]);
                batch.cos_d.push(wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2]);
                for (lane, e) in batch.weight.iter_mut().zip(e) {
                    lane.push(e * norm);
                }
            }
            batch.lambert.push(lambert.map(|v| v * norm));
            batch.start.push(batch.hx2.len());
        }
        batch
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
        self.hx2.len()
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

    fn run(
        &self,
        lobe: &Lobe,
        diffuse: [f64; 3],
        tangents: bool,
    ) -> (Vec<[f64; 3]>, Option<PixelTangents>) {
        let n = self.pixel_count();
        let mut values = vec![[0.0; 3]; n];
        let mut t = tangents.then(|| PixelTangents {
            ax: vec![[0.0; 3]; n],
            ay: vec![[0.0; 3]; n],
            fresnel_a: vec![[0.0; 3]; n],
            fresnel_b: vec![[0.0; 3]; n],
            diffuse: self.lambert.clone(),
        });
        let chunks = values.par_chunks_mut(TASK_PIXELS).enumerate();
        match &mut t {
            None => chunks.for_each(|(task, out)| {
                self.task(lobe, diffuse, task, out, None);
            }),
            Some(t) => chunks
                .zip(t.ax.par_chunks_mut(TASK_PIXELS))
                .zip(t.ay.par_chunks_mut(TASK_PIXELS))
                .zip(t.fresnel_a.par_chunks_mut(TASK_PIXELS))
                .zip(t.fresnel_b.par_chunks_mut(TASK_PIXELS))
                .for_each(|(((((task, out), ax), ay), fa), fb)| {
                    self.task(lobe, diffuse, task, out, Some([ax, ay, fa, fb]));
                }),
        }
        (values, t)
    }

    /// Pixels `task * TASK_PIXELS ..` into `out` (and their tangents into `tangents`: by ax,
    /// ay, first and second Fresnel parameter).
    fn task(
        &self,
        lobe: &Lobe,
        diffuse: [f64; 3],
        task: usize,
        out: &mut [[f64; 3]],
        tangents: Option<[&mut [[f64; 3]]; 4]>,
    ) {
        let first = task * TASK_PIXELS;
        let range = self.start[first]..self.start[first + out.len()];
        LANES.with_borrow_mut(|lanes| {
            self.fill_lanes(lobe, range.clone(), tangents.is_some(), lanes);
            self.sum_pixels(lanes, diffuse, first, range, out, tangents);
        });
    }

    /// Each pixel of `out` (the first is pixel `first`) from the lanes of `range`.
    fn sum_pixels(
        &self,
        lanes: &Lanes,
        diffuse: [f64; 3],
        first: usize,
        range: std::ops::Range<usize>,
        out: &mut [[f64; 3]],
        mut tangents: Option<[&mut [[f64; 3]]; 4]>,
    ) {
        // After `fill_lanes`, every lane array holds the record's weighted contribution, so a
        // pixel's value is the sum of its records' lanes, added in index order.
        let offsets = &self.start[first..=first + out.len()];
        for (i, value) in out.iter_mut().enumerate() {
            let k = first + i;
            let records = offsets[i] - range.start..offsets[i + 1] - range.start;
            let sum = |lane: &[f64]| -> f64 { lane[records.clone()].iter().sum() };
            for c in 0..3 {
                value[c] = sum(&lanes.fresnel[c]) + diffuse[c] * self.lambert[k][c];
            }
            if let Some([ax, ay, fa, fb]) = &mut tangents {
                for c in 0..3 {
                    ax[i][c] = sum(&lanes.by_ax[c]);
                    ay[i][c] = sum(&lanes.by_ay[c]);
                    fa[i][c] = sum(&lanes.d_fresnel_a[c]);
                    fb[i][c] = sum(&lanes.d_fresnel_b[c]);
                }
            }
        }
    }

    /// [`Lanes`] for the records in `range`, in the widest SIMD instruction set the CPU has
    /// (checked at run time; the loops are compiled once per set).
    fn fill_lanes(
        &self,
        lobe: &Lobe,
        range: std::ops::Range<usize>,
        tangents: bool,
        lanes: &mut Lanes,
    ) {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx512f") {
                // SAFETY: the CPU has the features the function is compiled for.
                return unsafe { self.fill_lanes_avx512(lobe, range, tangents, lanes) };
            }
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                // SAFETY: as above.
                return unsafe { self.fill_lanes_avx2(lobe, range, tangents, lanes) };
            }
        }
        self.fill_lanes_any(lobe, range, tangents, lanes)
    }

    compiled_for!(fill_lanes_avx512, "avx512f,avx2,fma");
    compiled_for!(fill_lanes_avx2, "avx2,fma");

    /// The lanes' loops, inlined into each instruction-set variant of [`Self::fill_lanes`].
    #[inline(always)]
    fn fill_lanes_any(
        &self,
        lobe: &Lobe,
        range: std::ops::Range<usize>,
        tangents: bool,
        lanes: &mut Lanes,
    ) {
        let single = lobe.single;
        self.lobes(single, range.clone(), tangents, lanes);
        fresnels(&single.fresnel, &self.cos_d[range.clone()], tangents, lanes);
        let n = range.len();
        // d alpha / d ax and d alpha / d ay of Turquin's alpha = sqrt(ax ay) (zero without it).
        let mut dalpha = [0.0; 2];
        if let Some(table) = lobe.turquin {
            self.compensate(single, table, range.clone(), tangents, lanes);
            let (ax, ay) = (single.microfacet.ax, single.microfacet.ay);
            let alpha = (ax * ay).sqrt();
            dalpha = [alpha / (2.0 * ax), alpha / (2.0 * ay)];
        }
        let lobe_scaled = lobe.turquin.is_some();
        // Weight by the irradiance: `fresnel` becomes the record's contribution `w F lobe`,
        // the Fresnel derivatives `w lobe dF`, and `by_ax`, `by_ay` get `w F d lobe`.
        for c in 0..3 {
            let w = &self.weight[c][range.clone()];
            let lobe = &lanes.lobe[..n];
            if tangents {
                lanes.by_ax[c].resize(n, 0.0);
                lanes.by_ay[c].resize(n, 0.0);
                let (f, a, b) = (
                    &lanes.fresnel[c][..n],
                    &mut lanes.d_fresnel_a[c][..n],
                    &mut lanes.d_fresnel_b[c][..n],
                );
                let (by_ax, by_ay) = (&mut lanes.by_ax[c][..n], &mut lanes.by_ay[c][..n]);
                let (d_ax, d_ay) = (&lanes.d_ax[..n], &lanes.d_ay[..n]);
                for l in 0..n {
                    let (wl, wf) = (w[l] * lobe[l], w[l] * f[l]);
                    a[l] *= wl;
                    b[l] *= wl;
                    by_ax[l] = wf * d_ax[l];
                    by_ay[l] = wf * d_ay[l];
                }
                if lobe_scaled {
                    let slope = &lanes.scale_slope[c][..n];
                    for l in 0..n {
                        let wl = w[l] * lobe[l] * slope[l];
                        by_ax[l] += wl * dalpha[0];
                        by_ay[l] += wl * dalpha[1];
                    }
                }
            }
            for (f, (&w, &lobe)) in lanes.fresnel[c][..n].iter_mut().zip(w.iter().zip(lobe)) {
                *f *= w * lobe;
            }
        }
    }

    /// Turquin 2019 eq. 6-7 ([`crate::bsdf::turquin`]): scale the lanes by
    /// `S_c = 1 + F0_c g(mu_o, alpha)`, `g = (1 - E) / E` with the white albedo `E` of `table`
    /// at `mu_o = wo.z` and `alpha = sqrt(ax ay)`, before the weighting step: `F` becomes
    /// `F S` (so the contribution is `w F S lobe`), `dF` becomes `dF S + F g dF0`, and
    /// `scale_slope` gets `F F0 dg/dalpha`, the part of `d (F S lobe) / d alpha` the lobe's own
    /// derivative misses (the weighting step adds it times `w lobe dalpha/da`).
    fn compensate(
        &self,
        single: &SingleBounce<f64>,
        table: &AlbedoTable,
        range: std::ops::Range<usize>,
        tangents: bool,
        lanes: &mut Lanes,
    ) {
        let n = range.len();
        let mf = &single.microfacet;
        let alpha = Dual64::from_re((mf.ax * mf.ay).sqrt()).derivative();
        let f0 = f0_with_tangents(&single.fresnel);
        let oz = &self.oz[range];
        for c in 0..3 {
            lanes.scale_slope[c].resize(n, 0.0);
        }
        for (l, &mu) in oz.iter().enumerate() {
            let e = table.e(mu, alpha).max_c(1e-6);
            let g = (Dual64::from_re(1.0) - e).max_c(0.0) / e;
            for (c, &(f0, df0_a, df0_b)) in f0.iter().enumerate() {
                let f = lanes.fresnel[c][l];
                let scale = 1.0 + f0 * g.re;
                if tangents {
                    let (a, b) = (&mut lanes.d_fresnel_a[c][l], &mut lanes.d_fresnel_b[c][l]);
                    *a = *a * scale + f * g.re * df0_a;
                    *b = *b * scale + f * g.re * df0_b;
                    lanes.scale_slope[c][l] = f * f0 * g.eps;
                }
                lanes.fresnel[c][l] = f * scale;
            }
        }
    }

    /// The Fresnel-free lobe `D / (4 den)` of the records in `range`, and its roughness
    /// derivatives when `tangents`.
    #[inline(always)]
    fn lobes(
        &self,
        single: &SingleBounce<f64>,
        range: std::ops::Range<usize>,
        tangents: bool,
        lanes: &mut Lanes,
    ) {
        let n = range.len();
        lanes.lobe.resize(n, 0.0);
        if tangents {
            lanes.d_ax.resize(n, 0.0);
            lanes.d_ay.resize(n, 0.0);
        }
        match (single.microfacet.ndf, tangents) {
            (NdfKind::Ggx, false) => self.ggx_lobes::<false>(single, range, lanes),
            (NdfKind::Ggx, true) => self.ggx_lobes::<true>(single, range, lanes),
            (NdfKind::Beckmann, _) => self.any_lobes(single, range, tangents, lanes),
        }
    }

    /// The geometry arrays of the records `r`: `[hx2, hy2, hz2, ix2, iy2, iz, ox2, oy2, oz]`.
    fn geometry(&self, r: std::ops::Range<usize>) -> [&[f64]; 9] {
        [
            &self.hx2, &self.hy2, &self.hz2, &self.ix2, &self.iy2, &self.iz, &self.ox2, &self.oy2,
            &self.oz,
        ]
        .map(|lane| &lane[r.clone()])
    }

    /// [`BatchRecords::lobes`] for GGX: one branch-free loop over the record arrays, which the
    /// compiler turns into SIMD lanes. `|w.z| Lambda = s^2 / (2 (sqrt(z^2 + s^2) + z))` as in
    /// [`ggx::z_lambda`] (no square root of `s^2` needed, and `d zL / d ax = ax w.x^2 /
    /// (2 sqrt(z^2 + s^2))`); `d ln D / d ax = -1/ax + 4 h.x^2 / (ax^3 (s_h^2 + h.z^2))`.
    #[inline(always)]
    fn ggx_lobes<const TANGENTS: bool>(
        &self,
        single: &SingleBounce<f64>,
        range: std::ops::Range<usize>,
        lanes: &mut Lanes,
    ) {
        let mf = &single.microfacet;
        let (ax, ay) = (mf.ax, mf.ay);
        let (ax2, ay2) = (ax * ax, ay * ay);
        let (inv_ax2, inv_ay2) = (1.0 / ax2, 1.0 / ay2);
        let norm = 0.25 / (std::f64::consts::PI * ax * ay);
        let correlated = single.height == Height::Correlated;
        let r = range;
        let n = r.len();
        let [hx2, hy2, hz2, ix2, iy2, iz, ox2, oy2, oz] = self.geometry(r);
        let lobe = &mut lanes.lobe[..n];
        let tangent_len = if TANGENTS { n } else { 0 };
        let (d_ax, d_ay) = (
            &mut lanes.d_ax[..tangent_len],
            &mut lanes.d_ay[..tangent_len],
        );
        for l in 0..n {
            let t = hx2[l] * inv_ax2 + hy2[l] * inv_ay2 + hz2[l];
            let d = norm / (t * t);
            let (si2, so2) = (ax2 * ix2[l] + ay2 * iy2[l], ax2 * ox2[l] + ay2 * oy2[l]);
            let (zi, zo) = (iz[l], oz[l]);
            let (ri, ro) = ((zi * zi + si2).sqrt(), (zo * zo + so2).sqrt());
            let (zli, zlo) = (si2 / (2.0 * (ri + zi)), so2 / (2.0 * (ro + zo)));
            let (ai, ao) = (zi + zli, zo + zlo);
            let den = if correlated {
                zi * zo + zo * zli + zi * zlo
            } else {
                ai * ao
            };
            let value = d / den;
            lobe[l] = value;
            if TANGENTS {
                let (hi, ho) = (0.5 / ri, 0.5 / ro);
                let by = |a: f64, h2: f64, i2: f64, o2: f64| {
                    let dln_d = (4.0 * h2 / (a * a * t) - 1.0) / a;
                    let (dzli, dzlo) = (a * i2 * hi, a * o2 * ho);
                    let d_den = if correlated {
                        zo * dzli + zi * dzlo
                    } else {
                        dzli * ao + ai * dzlo
                    };
                    value * (dln_d - d_den / den)
                };
                d_ax[l] = by(ax, hx2[l], ix2[l], ox2[l]);
                d_ay[l] = by(ay, hy2[l], iy2[l], oy2[l]);
            }
        }
    }

    /// [`BatchRecords::lobes`] for any distribution, through the scalar kernel's functions
    /// ([`beckmann::density_stretched`], [`beckmann::z_lambda`]); Beckmann's `exp` and `erfc`
    /// have no SIMD form here, so this loop runs a lane at a time.
    fn any_lobes(
        &self,
        single: &SingleBounce<f64>,
        range: std::ops::Range<usize>,
        tangents: bool,
        lanes: &mut Lanes,
    ) {
        let mf = &single.microfacet;
        let (ax, ay) = (mf.ax, mf.ay);
        let (ax2, ay2) = (ax * ax, ay * ay);
        let (inv_ax2, inv_ay2) = (1.0 / ax2, 1.0 / ay2);
        let norm = 0.25 / (ax * ay);
        let n = range.len();
        let ndf = mf.ndf;
        let height = single.height;
        let r = range;
        let [hx2, hy2, hz2, ix2, iy2, iz, ox2, oy2, oz] = self.geometry(r);
        for l in 0..n {
            let s2h = hx2[l] * inv_ax2 + hy2[l] * inv_ay2;
            let d1 = match ndf {
                NdfKind::Ggx => ggx::density_stretched(s2h, hz2[l].sqrt()),
                NdfKind::Beckmann => beckmann::density_stretched(s2h, hz2[l].sqrt()),
            };
            let si = (ax2 * ix2[l] + ay2 * iy2[l]).sqrt();
            let so = (ax2 * ox2[l] + ay2 * oy2[l]).sqrt();
            let (zli, zlo) = match ndf {
                NdfKind::Ggx => (ggx::z_lambda(iz[l], si), ggx::z_lambda(oz[l], so)),
                NdfKind::Beckmann => (beckmann::z_lambda(iz[l], si), beckmann::z_lambda(oz[l], so)),
            };
            let den = match height {
                Height::Correlated => iz[l] * oz[l] + oz[l] * zli + iz[l] * zlo,
                Height::Uncorrelated => (iz[l] + zli) * (oz[l] + zlo),
            };
            let lobe = d1 * norm / den;
            lanes.lobe[l] = lobe;
            if !tangents {
                continue;
            }
            // d ln D1 / d (s_h^2), then the chain through s_h^2 = hx2/ax^2 + hy2/ay^2.
            let dln_d1 = match ndf {
                NdfKind::Ggx => -2.0 / (s2h + hz2[l]),
                NdfKind::Beckmann => -1.0 / hz2[l],
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
            let (gi, go) = (dzl_ds(iz[l], si), dzl_ds(oz[l], so));
            // d s / d a = a w_a^2 / s (zero where s = 0, where gi, go are zero too).
            let (ri, ro) = (
                if si > 0.0 { 1.0 / si } else { 0.0 },
                if so > 0.0 { 1.0 / so } else { 0.0 },
            );
            let d_den = |dzli: f64, dzlo: f64| match height {
                Height::Correlated => oz[l] * dzli + iz[l] * dzlo,
                Height::Uncorrelated => dzli * (oz[l] + zlo) + (iz[l] + zli) * dzlo,
            };
            let dln_lobe = |a: f64, h2: f64, i2: f64, o2: f64| {
                let dln_d = -1.0 / a + dln_d1 * (-2.0 * h2 / (a * a * a));
                let dzli = gi * a * i2 * ri;
                let dzlo = go * a * o2 * ro;
                dln_d - d_den(dzli, dzlo) / den
            };
            lanes.d_ax[l] = lobe * dln_lobe(ax, hx2[l], ix2[l], ox2[l]);
            lanes.d_ay[l] = lobe * dln_lobe(ay, hy2[l], iy2[l], oy2[l]);
        }
    }
}

/// `F(cos)` per channel for every record's `cos = wi.h`, and when `tangents` its derivatives
/// by the Fresnel's parameters (see [`PixelTangents`]): one branch-free loop per Fresnel kind,
/// through the scalar kernel's own functions.
#[inline(always)]
fn fresnels(fresnel: &Fresnel<f64>, cos: &[f64], tangents: bool, lanes: &mut Lanes) {
    let n = cos.len();
    for c in 0..3 {
        lanes.fresnel[c].resize(n, 0.0);
        if tangents {
            lanes.d_fresnel_a[c].resize(n, 0.0);
            lanes.d_fresnel_b[c].resize(n, 0.0);
        }
    }
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
                    *v = fresnel.eval(cos).0[c];
                }
                by_a.fill(0.0);
                by_b.fill(0.0);
            }
            Fresnel::Schlick { f0 } => {
                let f0 = f0.0[c];
                for (v, &cos) in value.iter_mut().zip(cos) {
                    let m = 1.0 - cos.clamp(0.0, 1.0);
                    *v = f0 + (1.0 - f0) * (m * m * m * m * m);
                }
                for (d, &cos) in by_a.iter_mut().zip(cos) {
                    let m = 1.0 - cos.clamp(0.0, 1.0);
                    *d = 1.0 - m * m * m * m * m;
                }
                by_b.fill(0.0);
            }
            Fresnel::Conductor { eta, k } => {
                let (e, kk) = (eta.0[c], k.0[c]);
                if tangents {
                    let (e_seed, k_seed) = (Dual64::from_re(e), Dual64::from_re(kk));
                    for (((v, a), b), &cos) in value.iter_mut().zip(by_a).zip(by_b).zip(cos) {
                        let x = Dual64::from_re(cos.clamp(0.0, 1.0));
                        let by_eta = fresnel::conductor(x, e_seed.derivative(), k_seed);
                        let by_k = fresnel::conductor(x, e_seed, k_seed.derivative());
                        *v = by_eta.re;
                        *a = by_eta.eps;
                        *b = by_k.eps;
                    }
                } else {
                    for (v, &cos) in value.iter_mut().zip(cos) {
                        *v = fresnel::conductor(cos.clamp(0.0, 1.0), e, kk);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests;
