//! Exact gradients against central differences of the same objective (issue "Gradients":
//! agreement to 1e-4 relative at random parameter points), and one hand-derived derivative.

use super::*;
use crate::bsdf::single::SingleBounce;
use crate::bsdf::testing::unit;
use crate::bsdf::Model;
use crate::fit::point::params::FresnelFamily;
use crate::material::Material;
use crate::microfacet::{Height, NdfKind};
use crate::render::{render_model, render_pixels};
use crate::scalar::Vec3;
use num_dual::{Dual64, DualNum};
use rand::{Rng as _, SeedableRng};

/// Three 16 x 16 "photos" with 4 sub-samples per pixel: in-plane and out-of-plane pairs of
/// directions whose half vectors sweep 0 to ~40 degrees around the normal at three azimuths,
/// so every photo holds a highlight and its falloff. Targets are the prediction of `truth`.
fn synthetic_records(truth: &Material) -> ShadingRecords {
    const SIDE: usize = 16;
    const SPP: usize = 4;
    let mut records = ShadingRecords {
        samples_per_pixel: SPP,
        ..ShadingRecords::default()
    };
    for photo in 0..3 {
        let phi = 40.0 * photo as f64;
        records.photos.push(crate::shading::PhotoSpan {
            stem: format!("{photo:03}"),
            width: SIDE,
            height: SIDE,
            first_pixel: photo * SIDE * SIDE,
        });
        for row in 0..SIDE {
            for col in 0..SIDE {
                for s in 0..SPP {
                    let (sx, sy) = ((s % 2) as f64 * 0.5, (s / 2) as f64 * 0.5);
                    let theta_i = 5.0 + 70.0 * (col as f64 + sx) / SIDE as f64;
                    let theta_o = (theta_i + 3.0 * (row as f64 + sy - 8.0)).clamp(2.0, 85.0);
                    let wi = unit(theta_i, phi);
                    let wo = unit(theta_o, phi + 180.0 + 20.0 * (photo as f64 - 1.0));
                    records.wi.push(wi.re());
                    records.wo.push(wo.re());
                    records.irradiance.push([0.9, 1.0, 1.1].map(|e| e * wi.z));
                }
                records.target.push([0.0; 3]);
                records.weight.push(1.0);
            }
        }
    }
    records.target = crate::render::render_all(truth, &records, 7);
    records
}

/// Both the L2 and the log-L1 losses, through [`Loss::gradient`].
const LOSSES: [LossKind; 2] = [LossKind::L2, LossKind::LogL1];

/// Assert exact and central-difference gradients agree: relative 1e-4 on the norm, and per
/// component where the component is above 1e-3 of the norm (smaller ones are compared against
/// 1e-4 of the norm).
fn assert_gradients_agree(what: &str, exact: &[f64], fd: &[f64]) {
    let norm = fd.iter().map(|g| g * g).sum::<f64>().sqrt();
    let exact_norm = exact.iter().map(|g| g * g).sum::<f64>().sqrt();
    assert!(norm > 0.0, "{what}: zero gradient exercises nothing");
    assert!(
        (exact_norm - norm).abs() <= 1e-4 * norm,
        "{what}: |exact| {exact_norm} vs |fd| {norm}\n exact {exact:?}\n fd    {fd:?}"
    );
    for (i, (e, f)) in exact.iter().zip(fd).enumerate() {
        let tolerance = 1e-4 * if f.abs() > 1e-3 * norm { f.abs() } else { norm };
        assert!(
            (e - f).abs() <= tolerance,
            "{what}: component {i}: exact {e} vs fd {f}\n exact {exact:?}\n fd    {fd:?}"
        );
    }
}

/// A random point: ln alpha in ln [0.05, 1], logits in [-2, 2].
fn random_point(space: &ParamSpace, rng: &mut crate::random::Rng) -> Vec<f64> {
    let alphas = if space.anisotropic { 2 } else { 1 };
    (0..space.dim())
        .map(|i| {
            if i < alphas {
                rng.random_range(0.05f64.ln()..0.0)
            } else {
                rng.random_range(-2.0..2.0)
            }
        })
        .collect()
}

/// Every combination the issue lists for `model`: GGX and Beckmann, Schlick and conductor, with
/// diffuse (and one anisotropic conductor space, the 11-dimensional case), 5 points each.
fn check_model(model: Model) {
    let mut rng = crate::random::Rng::seed_from_u64(11);
    for ndf in [NdfKind::Ggx, NdfKind::Beckmann] {
        for (fresnel, anisotropic) in [
            (FresnelFamily::Schlick, false),
            (FresnelFamily::Conductor, false),
            (FresnelFamily::Conductor, true),
        ] {
            let space = ParamSpace {
                ndf,
                anisotropic,
                fresnel,
                diffuse: true,
                ..ParamSpace::plain(model)
            };
            let truth = space.material(&random_point(&space, &mut rng));
            let records = synthetic_records(&truth);
            for (k, kind) in LOSSES.into_iter().enumerate() {
                let objective =
                    Objective::new(space, &records, kind, 3).with_precision(Precision::F64);
                assert_eq!(objective.gradient_method(), GradientMethod::Exact);
                for point in 0..5 {
                    let x = random_point(&space, &mut rng);
                    let (cost, exact) = objective
                        .exact_cost_and_gradient(&x)
                        .expect("a dual path for this model");
                    let expected_cost = objective.loss(&x) / objective.scale;
                    assert!((cost - expected_cost).abs() <= 1e-12 * expected_cost);
                    let fd = objective.fd_gradient(&x);
                    let what = format!(
                        "{model} {ndf:?} {fresnel:?} anisotropic {anisotropic} loss {k} point {point} x {x:?}"
                    );
                    assert_gradients_agree(&what, &exact, &fd);
                }
            }
        }
    }
}

#[test]
fn single_exact_gradient_matches_finite_differences() {
    check_model(Model::Single);
}

#[test]
fn fast_msx_exact_gradient_matches_finite_differences() {
    check_model(Model::FastMsx);
}

#[test]
fn kulla_conty_exact_gradient_matches_finite_differences() {
    check_model(Model::KullaConty);
}

#[test]
fn tabulated_exact_gradient_matches_finite_differences() {
    check_model(Model::Tabulated);
}

#[test]
fn turquin_exact_gradient_matches_finite_differences() {
    check_model(Model::Turquin);
}

#[test]
fn heitz_falls_back_to_finite_differences() {
    let space = ParamSpace::plain(Model::Heitz);
    let records = ShadingRecords::default();
    let objective = Objective::new(space, &records, LossKind::L2, 0).with_precision(Precision::F64);
    assert_eq!(objective.gradient_method(), GradientMethod::Fd);
    assert!(objective.exact_cost_and_gradient(&[0.0; 4]).is_none());
}

/// Single bounce, GGX, height-correlated, flash geometry `wi = wo` at angle theta (`h = wi`):
/// `f = F0 D G2 / (4 cos^2)` with `D = a^2 / (pi cos^4 (a^2 + t^2)^2)` and
/// `G2 = 1 / (1 + 2 Lambda) = 1 / sqrt(1 + a^2 t^2)` (`t = tan theta`), so by hand
/// `d ln f / d ln a = 2 - 4 a^2 / (a^2 + t^2) - a^2 t^2 / (1 + a^2 t^2)`.
#[test]
fn single_bounce_derivative_in_ln_alpha_matches_the_hand_derivation() {
    let (theta, alpha, f0) = (35f64, 0.3f64, [0.9, 0.6, 0.5]);
    let w = unit(theta, 70.0);
    let records = ShadingRecords {
        samples_per_pixel: 1,
        wi: vec![w.re()],
        wo: vec![w.re()],
        irradiance: vec![[1.0; 3]],
        target: vec![[0.0; 3]],
        weight: vec![1.0],
        ..ShadingRecords::default()
    };
    let ln_alpha = Dual64::from_re(alpha.ln()).derivative();
    let single = SingleBounce {
        microfacet: crate::microfacet::Microfacet::new(
            NdfKind::Ggx,
            ln_alpha.exp(),
            ln_alpha.exp(),
        ),
        fresnel: crate::microfacet::Fresnel::Schlick {
            f0: crate::scalar::Rgb::from_f64(f0),
        },
        height: Height::Correlated,
    };
    let p = render_model(&single, [Dual64::from_re(0.0); 3], &records, &[0], 0)[0];
    let (a2, t2) = (alpha * alpha, theta.to_radians().tan().powi(2));
    let cos2 = theta.to_radians().cos().powi(2);
    let d = a2 / (std::f64::consts::PI * cos2 * cos2 * (a2 + t2).powi(2));
    let g2 = 1.0 / (1.0 + a2 * t2).sqrt();
    let slope = 2.0 - 4.0 * a2 / (a2 + t2) - a2 * t2 / (1.0 + a2 * t2);
    for c in 0..3 {
        let f = f0[c] * d * g2 / (4.0 * cos2);
        assert!((p[c].re - f).abs() < 1e-12 * f, "{} vs {f}", p[c].re);
        assert!(
            (p[c].eps - f * slope).abs() < 1e-12 * f,
            "channel {c}: dual {} vs hand {}",
            p[c].eps,
            f * slope
        );
    }
    // The value at the same geometry through the f64 model is the same number.
    let plain = SingleBounce {
        microfacet: crate::microfacet::Microfacet::new(NdfKind::Ggx, alpha, alpha),
        fresnel: crate::microfacet::Fresnel::Schlick {
            f0: crate::scalar::Rgb(f0),
        },
        height: Height::Correlated,
    };
    let direct = plain.eval(w, Vec3::from_f64(w.re()));
    assert!((direct.0[0] - p[0].re).abs() < 1e-14 * direct.0[0]);
}

/// Pathwise derivatives of the stochastic models, per pixel. At fixed random numbers the
/// objective of a stochastic model is piecewise smooth: a discrete decision of a walk (a
/// survival `U < q` with the piecewise-constant `q`, a connection that exists or not) flips at
/// isolated parameter values, and a flip moves one pixel by a whole path's contribution. On
/// 3072 sub-pixel walks of several decisions each, some decision flips within a central
/// difference step often enough that the loss-level comparison is dominated by flips, so the
/// comparison is per pixel and channel: central differences at steps `h` and `h / 2` that agree
/// with each other (no flip within the step) must agree with the dual derivative to 1e-4
/// relative; the pixels where they disagree (flips) must be rare. Both the L2 and log-L1
/// losses then follow from [`Loss::gradient`] and [`Loss::pair_gradient`], tested on their
/// own, and the objective's exact gradient is checked to be exactly that chain rule over the
/// derivatives of its two renders.
fn check_pathwise(model: Model) {
    const H: f64 = 1e-6;
    let mut rng = crate::random::Rng::seed_from_u64(23);
    let (mut compared, mut flips) = (0usize, 0usize);
    for ndf in [NdfKind::Ggx, NdfKind::Beckmann] {
        for fresnel in [FresnelFamily::Schlick, FresnelFamily::Conductor] {
            let space = ParamSpace {
                ndf,
                fresnel,
                diffuse: true,
                ..ParamSpace::plain(model)
            };
            let truth = space.material(&random_point(&space, &mut rng));
            let records = synthetic_records(&truth);
            let pixels: Vec<usize> = (0..records.pixel_count()).collect();
            // The exact renderer: the plan's skips have their own tests (render::tests).
            let objective = Objective::new(space, &records, LossKind::L2, 5)
                .with_precision(Precision::F64)
                .with_skips(crate::render::plan::Skips::none());
            assert_eq!(objective.gradient_method(), GradientMethod::Exact);
            for point in 0..5 {
                let x = random_point(&space, &mut rng);
                let predict = |x: &[f64]| render_pixels(&space.material(x), &records, &pixels, 5);
                let base = predict(&x);
                let peak = base.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
                let mut chain = vec![0.0; x.len()];
                // The objective scores the pair loss of two renders; its slope per render.
                let renders = objective.renders(&x);
                assert_eq!(renders.len(), 2, "a stochastic model is rendered twice");
                assert_eq!(renders[0], base);
                let (dloss, dloss_second) = objective
                    .image_loss()
                    .pair_gradient(&renders[0], &renders[1]);
                for i in 0..x.len() {
                    let coords: Vec<Dual64> = x
                        .iter()
                        .enumerate()
                        .map(|(j, &v)| {
                            let d = Dual64::from_re(v);
                            if i == j {
                                d.derivative()
                            } else {
                                d
                            }
                        })
                        .collect();
                    let surface = space.surface(&coords);
                    let brdf = differentiable(model, surface.single, crate::bsdf::BounceCap::NONE)
                        .expect("a dual path");
                    let dual = render_model(brdf.as_ref(), surface.diffuse, &records, &pixels, 5);
                    let second = objective.seeds()[1];
                    let dual_second =
                        render_model(brdf.as_ref(), surface.diffuse, &records, &pixels, second);
                    for (d, slope) in dual_second.iter().zip(&dloss_second) {
                        for c in 0..3 {
                            chain[i] += slope[c] * d[c].eps;
                        }
                    }
                    let central = |h: f64| {
                        let mut probe = x.clone();
                        probe[i] = x[i] + h;
                        let plus = predict(&probe);
                        probe[i] = x[i] - h;
                        let minus = predict(&probe);
                        (plus, minus)
                    };
                    let (plus, minus) = central(H);
                    let (plus2, minus2) = central(H / 2.0);
                    for p in 0..pixels.len() {
                        for c in 0..3 {
                            // Same numbers as the f64 renderer.
                            assert!((dual[p][c].re - base[p][c]).abs() <= 1e-12 * peak);
                            chain[i] += dloss[p][c] * dual[p][c].eps;
                            let fd = (plus[p][c] - minus[p][c]) / (2.0 * H);
                            let fd2 = (plus2[p][c] - minus2[p][c]) / H;
                            // Rounding of the differences: ~1e-16 peak / 1e-6.
                            let floor = 1e-8 * peak;
                            if (fd - fd2).abs() > 1e-4 * fd.abs() + floor {
                                flips += 1;
                                continue;
                            }
                            compared += 1;
                            let e = dual[p][c].eps;
                            assert!(
                                (e - fd).abs() <= 1e-4 * fd.abs() + floor,
                                "{model} {ndf:?} {fresnel:?} point {point} coordinate {i} pixel {p} channel {c}: dual {e} vs fd {fd} (fd at h/2 {fd2}), x {x:?}"
                            );
                        }
                    }
                }
                let (_, exact) = objective.exact_cost_and_gradient(&x).expect("a dual path");
                for (e, c) in exact.iter().zip(&chain) {
                    let c = c / objective.scale;
                    assert!((e - c).abs() <= 1e-9 * c.abs().max(1e-12), "{e} vs {c}");
                }
            }
        }
    }
    // Flips must be the exception (measured: see the report line).
    eprintln!("{model}: {compared} pixel derivatives compared, {flips} flips within the step");
    assert!(
        compared > 50_000 && flips * 200 < compared,
        "{compared} compared, {flips} flips"
    );
}

#[test]
fn wang_pt_pathwise_gradient_matches_finite_differences() {
    check_pathwise(Model::WangPt);
}

#[test]
fn wang_bdpt_pathwise_gradient_matches_finite_differences() {
    check_pathwise(Model::WangBdpt);
}

#[test]
fn bitterli_pathwise_gradient_matches_finite_differences() {
    check_pathwise(Model::Bitterli);
}

#[test]
fn cui_pathwise_gradient_matches_finite_differences() {
    check_pathwise(Model::Cui);
}

/// The pinhole template (9 point lights, a sample edge in view) at 48 x 48 with 4 sub-samples:
/// grid nodes past the sample's edge take the geometry of the nearest pixel that sees it.
pub(crate) fn pinhole_records(truth: &Material) -> ShadingRecords {
    let template = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("datasets/sources/aluminium-pinhole.capture.toml");
    let mut capture = crate::capture::Capture::open(&template).unwrap();
    for photo in &mut capture.photos {
        photo.camera = photo.camera.resampled([48, 48]);
    }
    let mut records = ShadingRecords::build(&capture, 4, false).unwrap();
    records.target = crate::render::render_all(truth, &records, 7);
    records
}

#[test]
fn batch_split_renders_equal_the_generic_render_path() {
    // `kulla-conty` is rendered whole by the batch kernel (no anchors); `tabulated` and
    // `bitterli` through the anchors, with the batch kernel's single term.
    for model in [Model::KullaConty, Model::Tabulated, Model::Bitterli] {
        let space = ParamSpace {
            fresnel: FresnelFamily::Conductor,
            diffuse: true,
            exposure: true,
            ..ParamSpace::plain(model)
        };
        let mut rng = crate::random::Rng::seed_from_u64(5);
        let x = random_point(&space, &mut rng);
        let truth = space.material(&x);
        let records = pinhole_records(&truth);
        let objective =
            Objective::new(space, &records, LossKind::L2, 3).with_precision(Precision::F64);
        let material = space.material(&x);
        let plan = objective.plan();
        let summary = plan.summary(&material);
        let whole = model.capabilities().batch.is_some();
        assert_eq!(
            summary.anchors == 0,
            whole,
            "{model}: anchors where the kernel has no lobe"
        );
        // Every lit pixel has a substitute for a node past the edge (itself, at worst), so no
        // pixel is left to an exact evaluation: a third of them were on pinhole sets before.
        assert_eq!(summary.exact_pixels, 0, "{model}");
        let generic = render_material_streams(
            &material,
            &records,
            objective.pixels(),
            plan,
            objective.seeds(),
        );
        let exposure = space.exposure(&x);
        for (fast, slow) in objective.renders(&x).iter().zip(&generic) {
            let scale = slow.iter().flatten().fold(0.0_f64, |m, v| m.max(v.abs()));
            for (a, b) in fast.iter().zip(slow) {
                for c in 0..3 {
                    assert!(
                        (a[c] - b[c] * exposure).abs() <= 1e-12 * scale,
                        "{model}: {} against {}",
                        a[c],
                        b[c] * exposure
                    );
                }
            }
        }
        // The gradient through the split agrees with central differences where the objective
        // is smooth (the stochastic models' pathwise gradients are checked above, where their
        // jumps are kept out of the differences).
        if !objective.is_stochastic() {
            let (_, exact) = objective.exact_cost_and_gradient(&x).expect("a dual path");
            let fd = objective.fd_gradient(&x);
            assert_gradients_agree(&format!("{model} pinhole"), &exact, &fd);
        }
    }
}

/// Where the prediction meets the photos the residuals' curvature terms vanish, so the
/// Gauss-Newton matrix is the cost's Hessian: against central differences of the exact
/// gradient (step 1e-4, truncation about 1e-8 of the Hessian) at the truth of synthetic
/// photos, for every model the batch kernel serves and `tabulated` (dual numbers through the
/// render plan's anchors), both losses of squared errors, GGX and
/// Beckmann, a Schlick space with diffuse, a conductor space, and an anisotropic space with a
/// known Fresnel and a fitted exposure (every kernel parameter and the exposure's tangent).
/// Measured: within 2e-7 of the largest entry. Away from the truth the two differ by the
/// residuals' terms, and the gradient is the exact path's.
#[test]
fn gauss_newton_matrix_is_the_hessian_at_a_perfect_fit() {
    let mut rng = crate::random::Rng::seed_from_u64(23);
    let known = crate::material::FresnelSpec::Schlick {
        f0: [0.9, 0.6, 0.5],
    };
    for model in [
        Model::Single,
        Model::Turquin,
        Model::KullaConty,
        Model::FastMsx,
        Model::Tabulated,
    ] {
        for ndf in [NdfKind::Ggx, NdfKind::Beckmann] {
            for space in [
                ParamSpace {
                    diffuse: true,
                    ..ParamSpace::plain(model)
                },
                ParamSpace {
                    fresnel: FresnelFamily::Conductor,
                    ..ParamSpace::plain(model)
                },
                ParamSpace {
                    anisotropic: true,
                    known_fresnel: Some(known),
                    exposure: true,
                    ..ParamSpace::plain(model)
                },
            ] {
                let space = ParamSpace { ndf, ..space };
                let mut x = random_point(&space, &mut rng);
                if space.exposure {
                    // The photos are rendered at exposure 1 (the material has none).
                    *x.last_mut().expect("the exposure's coordinate") = 0.0;
                }
                let records = synthetic_records(&space.material(&x));
                for kind in [LossKind::L2, LossKind::RelativeL2] {
                    let objective =
                        Objective::new(space, &records, kind, 3).with_precision(Precision::F64);
                    assert!(objective.has_gauss_newton());
                    let (cost, gradient, matrix) = objective.gauss_newton(&x).expect("served");
                    let (exact_cost, exact_gradient) =
                        objective.exact_cost_and_gradient(&x).expect("exact");
                    assert_eq!((cost, &gradient), (exact_cost, &exact_gradient));
                    let what = format!("{model} {ndf:?} {kind:?} {space:?}");
                    assert_gauss_newton_is_the_hessian(&objective, &x, &matrix, &what);
                }
            }
        }
    }
}

/// Central differences of the exact gradient at `x` (step 1e-4) equal `matrix` within 1e-5 of
/// its largest entry.
fn assert_gauss_newton_is_the_hessian(
    objective: &Objective,
    x: &[f64],
    matrix: &[f64],
    what: &str,
) {
    let x = x.to_vec();
    let n = x.len();
    let h = 1e-4;
    let mut hessian = vec![0.0; n * n];
    for j in 0..n {
        let mut probe = x.clone();
        probe[j] = x[j] + h;
        let plus = objective.exact_cost_and_gradient(&probe).unwrap().1;
        probe[j] = x[j] - h;
        let minus = objective.exact_cost_and_gradient(&probe).unwrap().1;
        for i in 0..n {
            hessian[i * n + j] = (plus[i] - minus[i]) / (2.0 * h);
        }
    }
    let largest = hessian.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let worst = hessian
        .iter()
        .zip(matrix)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    assert!(
        worst <= 1e-5 * largest,
        "{what}: Gauss-Newton {matrix:?} against \
         Hessian {hessian:?}"
    );
}

/// The same through the render plan's anchors: `tabulated` on 48x48 pinhole photos of a
/// conductor, which the plan renders through anchors, with photos equal to the objective's
/// own prediction at the point (the anchors' interpolation is then part of the truth).
#[test]
fn gauss_newton_matrix_through_anchors_is_the_hessian_at_a_perfect_fit() {
    let space = ParamSpace {
        fresnel: FresnelFamily::Conductor,
        ..ParamSpace::plain(Model::Tabulated)
    };
    let x = [0.6f64.ln(), 2.0, 1.5, 1.0, 0.5, 0.2, -0.5];
    let mut records = pinhole_records(&space.material(&x));
    let objective = Objective::new(space, &records, LossKind::L2, 3).with_precision(Precision::F64);
    let summary = objective.plan_summary(&space.material(&x));
    assert!(summary.anchors > 0, "{summary:?}");
    let predicted = objective.predict(&x);
    let pixels = objective.pixels().to_vec();
    for (&p, value) in pixels.iter().zip(predicted) {
        records.target[p] = value;
    }
    let objective = Objective::new(space, &records, LossKind::L2, 3).with_precision(Precision::F64);
    let (cost, _, matrix) = objective.gauss_newton(&x).expect("served");
    assert!(cost < 1e-20, "cost {cost:e}");
    assert_gauss_newton_is_the_hessian(&objective, &x, &matrix, "tabulated through anchors");
}
