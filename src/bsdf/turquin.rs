//! `turquin`: multiple-scattering compensation of Turquin 2019 ("Practical multiple scattering
//! compensation for microfacet models", eq. 6-7): the single-bounce lobe scaled by
//! `1 + F0 (1 - E(mu_o)) / E(mu_o)`, with the white albedo `E` from [`AlbedoTable`] at the view
//! direction `mu_o = wo.z` and `F0` the normal-incidence reflectance of the material's Fresnel.
//!
//! | parameter | meaning |
//! | --- | --- |
//! | `alpha`, `ndf`, `height`, `fresnel` | as `single`; the tables are read at `sqrt(ax ay)` |
//!
//! Deterministic, analytic (tabulated), not reciprocal (the scale depends on `wo` only). With a
//! white Fresnel the albedo toward a fixed *view* direction is exactly 1 up to table error
//! (`integral f_single cos dwi = E(mu_o)` by reciprocity of `single`); the `albedo` command
//! integrates over `wo` for a fixed `wi`, where it differs from 1. Sampling:
//! [`super::lobe_mixture`].

use super::albedo_table::AlbedoTable;
use super::lobe_mixture::AddedLobe;
use super::single::SingleBounce;
use super::ScalarBrdf;

use crate::random::Rng;
use crate::scalar::{Real, Rgb, Vec3};

#[derive(Clone, Copy)]
pub struct Turquin<T> {
    pub single: SingleBounce<T>,
    table: &'static AlbedoTable,
    alpha: T,
}

impl<T: Real> Turquin<T> {
    pub fn new(single: SingleBounce<T>) -> Self {
        let table = AlbedoTable::get(single.microfacet.ndf, single.height);
        let alpha = (single.microfacet.ax * single.microfacet.ay).sqrt();
        Turquin {
            single,
            table,
            alpha,
        }
    }

    /// `(f_single, f_single F0 (1 - E(mu_o)) / E(mu_o))`.
    pub fn eval_split(&self, wi: Vec3<T>, wo: Vec3<T>) -> (Rgb<T>, Rgb<T>) {
        let single = self.single.eval(wi, wo);
        if wo.z.re64() <= 0.0 {
            return (single, Rgb::splat(T::zero()));
        }
        let e = self.table.e(wo.z.re64(), self.alpha).max_c(1e-6);
        let gain = (T::one() - e).max_c(0.0) / e;
        let f0 = self.single.fresnel.f0();
        (single, single * f0.scale(gain))
    }
}

impl<T: Real> ScalarBrdf<T> for Turquin<T> {
    fn eval_split(&self, wi: Vec3<T>, wo: Vec3<T>, _rng: &mut Rng) -> (Rgb<T>, Rgb<T>) {
        Self::eval_split(self, wi, wo)
    }
}

impl AddedLobe for Turquin<f64> {
    fn single_lobe(&self) -> &SingleBounce<f64> {
        &self.single
    }
    fn added_lobe(&self, wi: Vec3<f64>, wo: Vec3<f64>) -> [f64; 3] {
        self.eval_split(wi, wo).1 .0
    }
}
