//! The measurements behind `bouncefit bench` (issue #5 item 3): run time beside error for every
//! model, all measured in one run against `heitz` (Heitz et al. 2016), the reference of the
//! multi-bounce models.
//!
//! | part | measures | module |
//! | --- | --- | --- |
//! | estimators | per model and sample count n in {1, 2, 4, 8, 16, 64}, on a fixed set of configurations: time per `eval`, RMS relative error of the n-sample mean against the model's converged value, bias of the converged value against converged `heitz`, inverse efficiency (variance x time) relative to `heitz` | [`estimators`] |
//! | jobs | wall and CPU time of a render of a photo set, and of a fit of each model to a photo set, with the fit's final loss and roughness error | [`jobs`] |
//! | plot | error against time per estimate, log-log, one curve per model | [`plot`] |
//! | CPU clocks | thread and process CPU time, so that a loaded machine can be told from a slow tool | [`cpu_time`] |
//! | memory | peak resident memory of a job | [`memory`] |
//!
//! The criterion benchmarks in `benches/` time the kernels for regressions; this module puts
//! the same models' cost beside their error.

pub mod cpu_time;
pub mod estimators;
pub mod jobs;
pub mod kernel;
pub mod memory;
pub mod plot;
