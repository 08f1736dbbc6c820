//! Point estimation: one best material for the records.

pub mod exposure;
pub mod local;
pub mod objective;
pub mod params;
pub mod projection;
pub mod start;
pub mod uniformity;
