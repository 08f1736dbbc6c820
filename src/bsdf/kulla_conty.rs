//! `kulla-conty`: energy compensation of Kulla & Conty 2017 ("Revisiting Physically Based
//! Shading at Imageworks", SIGGRAPH course notes, sec. "Multiple scattering microfacet BSDFs
//! with Fresnel"): `single` plus the lobe
//! `f_ms(wi, wo) = (1 - E(mu_i)) (1 - E(mu_o)) / (pi (1 - E_avg)) * F_ms`, with the white albedo
//! `E` and its average `E_avg` from [`AlbedoTable`], and the Fresnel colouring
//! `F_ms = F_avg^2 E_avg / (1 - F_avg (1 - E_avg))`, `F_avg = 2 integral_0^1 F(mu) mu dmu`.
//!
//! | parameter | meaning |
//! | --- | --- |
//! | `alpha`, `ndf`, `height`, `fresnel` | as `single`; the tables are read at `sqrt(ax ay)` |
//!
//! Deterministic, analytic (tabulated), reciprocal (symmetric in `mu_i`, `mu_o`), white furnace
//! exactly 1 by construction up to table error: `integral f_ms cos dwo = 1 - E(mu_i)`.
//! Sampling: [`super::lobe_mixture`].

use super::albedo_table::AlbedoTable;
use super::lobe_mixture::AddedLobe;
use super::single::SingleBounce;
use super::ScalarBrdf;

use crate::microfacet::Fresnel;
use crate::random::Rng;
use crate::scalar::{Real, Rgb, Vec3};

/// 8-point Gauss-Legendre nodes and weights on [0, 1] (for `F_avg`).
const GAUSS_LEGENDRE_8: [(f64, f64); 8] = [
    (0.019_855_071_751_231_856, 0.050_614_268_145_188_13),
    (0.101_666_761_293_186_63, 0.111_190_517_226_687_24),
    (0.237_233_795_041_835_5, 0.156_853_322_938_943_64),
    (0.408_282_678_752_175_1, 0.181_341_891_689_181_07),
    (0.591_717_321_247_825, 0.181_341_891_689_181_07),
    (0.762_766_204_958_164_5, 0.156_853_322_938_943_64),
    (0.898_333_238_706_813_4, 0.111_190_517_226_687_24),
    (0.980_144_928_248_768_1, 0.050_614_268_145_188_13),
];

/// `F_avg = 2 integral_0^1 F(mu) mu dmu` per channel (Kulla & Conty 2017), by 8-point
/// Gauss-Legendre quadrature; shared by `kulla-conty` and `tabulated`.
pub(crate) fn fresnel_average<T: Real>(fresnel: &Fresnel<T>) -> Rgb<T> {
    let mut f_avg = Rgb::splat(T::zero());
    for (x, w) in GAUSS_LEGENDRE_8 {
        f_avg = f_avg + fresnel.eval(T::c(x)).scale(T::c(2.0 * w * x));
    }
    f_avg
}

#[derive(Clone, Copy)]
pub struct KullaConty<T> {
    pub single: SingleBounce<T>,
    table: &'static AlbedoTable,
    alpha: T,
    /// `F_ms / (pi (1 - E_avg))` per channel, fixed for the material.
    lobe_scale: Rgb<T>,
}

impl<T: Real> KullaConty<T> {
    pub fn new(single: SingleBounce<T>) -> Self {
        let table = AlbedoTable::get(single.microfacet.ndf, single.height);
        let alpha = (single.microfacet.ax * single.microfacet.ay).sqrt();
        let e_avg = table.e_avg(alpha);
        let f_avg = fresnel_average(&single.fresnel);
        let lost = (T::one() - e_avg).max_c(0.0);
        let lobe_scale = if lost.re64() < 1e-9 {
            Rgb::splat(T::zero())
        } else {
            f_avg.map(|fa| {
                fa * fa * e_avg / (T::one() - fa * lost) / (T::c(std::f64::consts::PI) * lost)
            })
        };
        KullaConty {
            single,
            table,
            alpha,
            lobe_scale,
        }
    }

    /// `F_ms / (pi (1 - E_avg))` per channel: the lobe is this times
    /// `(1 - E(mu_i)) (1 - E(mu_o))` (Kulla & Conty 2017, the compensation lobe with its Fresnel
    /// colouring); zero when the surface loses no energy.
    pub fn lobe_scale(&self) -> Rgb<T> {
        self.lobe_scale
    }

    /// The white albedo table the lobe reads (at `sqrt(ax ay)`).
    pub fn table(&self) -> &'static AlbedoTable {
        self.table
    }

    /// The compensation lobe `f_ms`, 1/sr.
    pub fn compensation(&self, wi: Vec3<T>, wo: Vec3<T>) -> Rgb<T> {
        if wi.z.re64() <= 0.0 || wo.z.re64() <= 0.0 {
            return Rgb::splat(T::zero());
        }
        let lost_i = (T::one() - self.table.e(wi.z.re64(), self.alpha)).max_c(0.0);
        let lost_o = (T::one() - self.table.e(wo.z.re64(), self.alpha)).max_c(0.0);
        self.lobe_scale.scale(lost_i * lost_o)
    }
}

impl<T: Real> ScalarBrdf<T> for KullaConty<T> {
    fn eval_split(&self, wi: Vec3<T>, wo: Vec3<T>, _rng: &mut Rng) -> (Rgb<T>, Rgb<T>) {
        (self.single.eval(wi, wo), self.compensation(wi, wo))
    }

    fn eval_multi(&self, wi: Vec3<T>, wo: Vec3<T>, _rng: &mut Rng) -> Rgb<T> {
        self.compensation(wi, wo)
    }
}

impl AddedLobe for KullaConty<f64> {
    fn single_lobe(&self) -> &SingleBounce<f64> {
        &self.single
    }
    fn added_lobe(&self, wi: Vec3<f64>, wo: Vec3<f64>) -> [f64; 3] {
        self.compensation(wi, wo).0
    }
}
