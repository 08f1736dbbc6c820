//! bouncefit: fit single- and multi-bounce microfacet materials to photographs of flat samples.
//!
//! Data flows one way: capture manifest -> shading records -> render -> loss -> optimiser ->
//! fit file -> report / export. Where things live:
//!
//! - [`scalar`]: the scalar trait (f64, f32, dual numbers) and small vector types;
//! - [`microfacet`]: distributions, Lambda, masking, visible normals, Fresnel;
//! - [`bsdf`]: the BRDF trait and one file per model;
//! - [`capture`], [`shading`]: photo sets and the per-pixel records computed from them;
//! - [`export`]: a material for Mitsuba 3, glTF and MaterialX;
//! - [`relight`]: previews of a material under new light (environment, turntable, its photos' lights);
//! - [`stress`]: the numerical stress sweep of every model;
//! - [`bench`]: run time beside error of every model, and of render and fit jobs.

pub mod albedo;
pub mod bench;
pub mod board;
pub mod bsdf;
pub mod capture;
pub mod commands;
pub mod error;
pub mod export;
pub mod fit;
pub mod lobe;
pub mod loss;
pub mod maps;
pub mod material;
pub mod microfacet;
pub mod progress;
pub mod random;
pub mod relight;
pub mod render;
pub mod report;
pub mod scalar;
pub mod shading;
pub mod stress;
