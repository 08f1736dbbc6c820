//! Issue #15 item 2: the batch kernel's `f32` lanes measured against its `f64` lanes, on the
//! renders a fit compares and on the fits themselves, for every bundled uniform set and every
//! model of the family. The bounds: `f32` may err by at most 1e-4 relative RMS on a
//! render and move a fit by at most 0.1% in alpha; the tables printed here (run with
//! `--nocapture`) are the figures in `docs/speed.md`.
//!
//! `datasets/two-materials` is a maps set: its fits go through `fit --maps`, which does not use
//! the batch kernel, so it is not measured here.

mod common;

use bouncefit::bench::jobs::fit_records;
use bouncefit::bsdf::Model;
use bouncefit::fit::point::objective::Objective;
use bouncefit::fit::point::params::{FresnelFamily, ParamSpace};
use bouncefit::fit::point::StochasticFit;
use bouncefit::fit::{fit_model, FitOptions};
use bouncefit::loss::LossKind;
use bouncefit::render::batch::Precision;
use common::repo;

/// The bundled uniform sets and the Fresnel family each is fitted with (the pinhole set with
/// conductor Fresnel, as `bench` fits it).
const SETS: [(&str, FresnelFamily); 2] = [
    ("datasets/copper-flash", FresnelFamily::Schlick),
    ("datasets/aluminium-pinhole", FresnelFamily::Conductor),
];

/// Relative RMS difference of `fast` from `reference` over every pixel and channel, and the
/// largest difference of one pixel relative to the render's RMS.
fn differences(reference: &[[f64; 3]], fast: &[[f64; 3]]) -> (f64, f64) {
    let (mut diff2, mut ref2, mut worst) = (0.0, 0.0, 0.0_f64);
    for (r, f) in reference.iter().zip(fast) {
        for c in 0..3 {
            diff2 += (r[c] - f[c]).powi(2);
            ref2 += r[c] * r[c];
            worst = worst.max((r[c] - f[c]).abs());
        }
    }
    let rms = (ref2 / (3 * reference.len()) as f64).sqrt();
    ((diff2 / ref2).sqrt(), worst / rms)
}

#[test]
fn f32_lanes_render_every_model_within_1e_4_of_f64_lanes() {
    println!("| set | model | relative RMS | worst pixel / RMS |");
    for (set, fresnel) in SETS {
        let (records, truth) = fit_records(&repo(set), 4, 0).unwrap();
        let truth = truth.expect("a bundled uniform set names its material");
        for model in Model::ALL {
            let space = ParamSpace {
                fresnel,
                diffuse: true,
                ..ParamSpace::plain(model)
            };
            let mut material = truth.clone();
            material.model = model;
            material.diffuse = [0.02, 0.03, 0.04];
            let x = space.point(&material, 1.0);
            let render = |precision| {
                Objective::new(space, &records, LossKind::L2, 1)
                    .with_precision(precision)
                    .renders(&x)
            };
            let (single, double) = (render(Precision::F32), render(Precision::F64));
            for (fast, reference) in single.iter().zip(&double) {
                let (relative_rms, worst) = differences(reference, fast);
                println!("| {set} | {model} | {relative_rms:.1e} | {worst:.1e} |");
                assert!(
                    relative_rms <= 1e-4,
                    "{set} {model}: relative RMS {relative_rms:e}"
                );
            }
        }
    }
}

#[test]
fn f32_lanes_move_fits_by_less_than_a_thousandth_in_alpha() {
    println!("| set | model | alpha f64 | alpha f32 | relative | largest F0 difference |");
    for (set, fresnel) in SETS {
        // 32x32 photos keep the stochastic fits to seconds; the kernel's rounding does not
        // depend on the resolution.
        let (records, _) = fit_records(&repo(set), 4, 2).unwrap();
        for model in [
            Model::Single,
            Model::Turquin,
            Model::KullaConty,
            Model::Bitterli,
        ] {
            let fit = |precision| {
                let options = FitOptions {
                    precision: Some(precision),
                    // The model's own objective: what the lanes' precision changes.
                    stochastic_fit: StochasticFit::Direct,
                    ..FitOptions::defaults(ParamSpace {
                        fresnel,
                        ..ParamSpace::plain(model)
                    })
                };
                fit_model(&records, &options).unwrap()
            };
            let (single, double) = (fit(Precision::F32), fit(Precision::F64));
            let (a32, a64) = (single.material.alpha[0], double.material.alpha[0]);
            let relative = (a32 - a64).abs() / a64;
            let f0 = (0..3)
                .map(|c| (single.f0[c] - double.f0[c]).abs())
                .fold(0.0, f64::max);
            println!("| {set} | {model} | {a64:.6} | {a32:.6} | {relative:.1e} | {f0:.1e} |");
            assert!(
                relative <= 1e-3,
                "{set} {model}: alpha moved by {relative:e}"
            );
            assert!(f0 <= 1e-3, "{set} {model}: F0 moved by {f0:e}");
        }
    }
}
