//! bouncefit: fit single- and multi-bounce microfacet materials to photographs of flat samples.
//!
//! Data flows one way: capture manifest -> shading records -> render -> loss -> optimiser ->
//! fit file -> report / export.

pub mod capture;
pub mod error;
pub mod shading;
