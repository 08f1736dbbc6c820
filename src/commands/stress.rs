//! `bouncefit stress`: the numerical stress sweep of [`crate::stress`] over the chosen models, as
//! a table or (`--json`) as `{"models": [...]}`. The exit status is 1 when any model returned a
//! NaN, infinite or negative number (the batch kernel's values included, and its non-finite
//! tangents), so CI and scripts can gate on it.

use crate::bsdf::Model;
use crate::error::Result;
use crate::progress::Progress;
use crate::stress::{query_count, stress_model, ModelReport, SweepSize};
use serde_json::json;

#[derive(clap::Args, Debug)]
pub struct StressArgs {
    /// Models to sweep (comma-separated); all by default.
    #[arg(long, value_delimiter = ',')]
    pub models: Option<Vec<Model>>,
    /// A reduced sweep (every corner, fewer interior values) that runs in under a minute.
    #[arg(long)]
    pub quick: bool,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Print `{"models": [{"model", "queries", "nan", "inf", "negative", ...}]}`.
    #[arg(long)]
    pub json: bool,
    /// No progress display.
    #[arg(long)]
    pub quiet: bool,
}

/// Run the sweep; `Ok(false)` when a NaN, infinite or negative number was found.
pub fn run_stress(args: &StressArgs) -> Result<bool> {
    let models = args.models.clone().unwrap_or_else(|| Model::ALL.to_vec());
    let size = if args.quick {
        SweepSize::Quick
    } else {
        SweepSize::Full
    };
    let total: usize = models.iter().map(|&m| query_count(m, size)).sum();
    let progress =
        (!args.quiet).then(|| std::sync::Mutex::new(Progress::new("stress", total as u64)));
    let mut reports = Vec::new();
    let mut offset = 0;
    for &model in &models {
        let report = stress_model(model, size, args.seed, |done| {
            if let Some(p) = &progress {
                if let Ok(mut p) = p.try_lock() {
                    p.update((offset + done) as u64, || model.to_string());
                }
            }
        });
        offset += report.queries;
        reports.push(report);
    }
    if let Some(p) = &progress {
        p.lock().expect("no panics while holding the lock").finish();
    }
    if args.json {
        println!("{}", json!({ "models": reports }));
    } else {
        print!("{}", table(&reports));
    }
    let clean = reports.iter().all(|r| r.bad_numbers() == 0);
    if !clean {
        eprintln!(
            "stress: NaN, infinite or negative values found (see the first bad numbers above)"
        );
    }
    Ok(clean)
}

/// The human-readable table, with where each problem first appeared.
fn table(reports: &[ModelReport]) -> String {
    let mut out = format!(
        "{:<12} {:>8} {:>5} {:>5} {:>5} {:>9} {:>9} {:>9} {:>11} {:>7} {:>8}\n",
        "model",
        "queries",
        "nan",
        "inf",
        "neg",
        "energy>1",
        "max E",
        "fallback",
        "worst dev",
        "worst z",
        "seconds"
    );
    for r in reports {
        out += &format!(
            "{:<12} {:>8} {:>5} {:>5} {:>5} {:>5}/{:<3} {:>9.5} {:>9.2e} {:>11.3e} {:>7} {:>8.1}\n",
            r.model.name(),
            r.queries,
            r.nan,
            r.inf,
            r.negative,
            r.energy_violations,
            r.energy_checks,
            r.max_albedo,
            r.fallback_rate,
            r.worst_rel_dev,
            r.worst_z.map_or("-".to_string(), |z| format!("{z:.2}")),
            r.seconds
        );
    }
    for r in reports {
        if let Some(bad) = &r.first_bad {
            out += &format!("{}: first bad number: {bad}\n", r.model);
        }
        for b in &r.batch {
            out += &format!(
                "{}: batch kernel ({:?} lanes): {} evaluations ({} of {} configurations above the horizon), nan {} inf {} neg {}, non-finite tangents {}/{}; worst deviation from the scalar kernel {:.3e} at {}\n",
                r.model,
                b.precision,
                b.evaluations,
                b.records,
                b.configurations,
                b.nan,
                b.inf,
                b.negative,
                b.tangent_nonfinite,
                b.tangents,
                b.worst_rel_dev,
                b.worst_rel_dev_at
            );
            if let Some(bad) = &b.first_bad {
                out += &format!("{}: batch kernel: first bad number: {bad}\n", r.model);
            }
            if let Some(bad) = &b.first_bad_tangent {
                out += &format!(
                    "{}: batch kernel: first non-finite tangent: {bad}\n",
                    r.model
                );
            }
        }
        for v in &r.energy_violations_at {
            out += &format!("{}: white albedo above 1 + 3 se: {v}\n", r.model);
        }
        if let (Some(z), Some(at)) = (r.worst_z, &r.worst_z_at) {
            out += &format!("{}: worst z {z:.2} at {at}\n", r.model);
        }
        out += &format!(
            "{}: worst deviation ({}) at {}; max albedo {:.5} +- {:.1e} at {}\n",
            r.model,
            r.reference,
            r.worst_rel_dev_at,
            r.max_albedo,
            r.max_albedo_stderr,
            r.max_albedo_at
        );
    }
    out
}
