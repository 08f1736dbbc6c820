//! The render plan against the exact render: each skip changes the prediction by no more than
//! its stated bound, and does skip the work it claims to.

use super::anchors::{fingerprint, Anchors, ProxyLobes, CANDIDATE_STRIDES};
use super::plan::{
    MultiTerm, RenderPlan, Skip, Skips, BOUNCE_TOLERANCE, FAINT_TOLERANCE, SPARSE_TOLERANCE,
};
use super::*;
use crate::bench::jobs::relative_rms_difference;
use crate::bsdf::testing::ggx_material as material;
use crate::bsdf::Model;
use crate::capture::Capture;
use crate::material::{FresnelSpec, Material};
use crate::microfacet::{Height, NdfKind};
use std::path::Path;

/// The pinhole template (9 point lights, the camera 40 degrees off the normal) at `side`
/// pixels, `spp` sub-samples per pixel; `bracket` appends a copy of every photo at a quarter of
/// the exposure, as an exposure bracket would.
fn pinhole_records(side: usize, spp: usize, bracket: bool) -> ShadingRecords {
    let template = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("datasets/sources/aluminium-pinhole.capture.toml");
    let mut capture = Capture::open(&template).unwrap();
    for photo in &mut capture.photos {
        photo.camera = photo.camera.resampled([side, side]);
    }
    if bracket {
        let darker: Vec<_> = capture
            .photos
            .iter()
            .map(|p| crate::capture::Photo {
                exposure: p.exposure / 4.0,
                ..p.clone()
            })
            .collect();
        capture.photos.extend(darker);
    }
    ShadingRecords::build(&capture, spp, false).unwrap()
}

fn copper() -> FresnelSpec {
    FresnelSpec::Conductor {
        eta: [0.2378, 1.0066, 1.2404],
        k: [3.6264, 2.5823, 2.3929],
    }
}

fn lit_pixels(records: &ShadingRecords) -> Vec<usize> {
    (0..records.pixel_count())
        .filter(|&p| records.weight[p] > 0.0)
        .collect()
}

const SPARSE_ONLY: Skips = Skips {
    repeated: false,
    sparse_multi: true,
    faint_multi: false,
    bounce_cap: false,
};

/// The interpolation error grows with the stride (so the choice is a real one), and the plan
/// takes the largest stride within the tolerance.
#[test]
fn the_stride_is_the_largest_within_the_tolerance() {
    let records = pinhole_records(48, 1, false);
    let pixels = lit_pixels(&records);
    let proxies = ProxyLobes::new(&records, &pixels, NdfKind::Ggx, Height::Correlated);
    let errors: Vec<f64> = CANDIDATE_STRIDES
        .iter()
        .map(|&s| proxies.error(&Anchors::new(&records, &pixels, s)))
        .collect();
    assert!(errors[errors.len() - 1] > 4.0 * errors[0], "{errors:?}");
    let kc = material(Model::KullaConty, 0.3, FresnelSpec::White);
    let plan = RenderPlan::for_material(SPARSE_ONLY, &kc, &records, &pixels);
    let stride = plan.anchors.as_ref().map_or(1, |a| a.stride);
    for (&s, &e) in CANDIDATE_STRIDES.iter().zip(&errors) {
        assert_eq!(
            e <= SPARSE_TOLERANCE,
            s <= stride,
            "stride {s}: error {e}, chose {stride}"
        );
    }
}

/// The chosen stride is remembered by the content the choice reads: records that differ only
/// in their targets (the rounds of a corrected fit) share it; a change to any sub-sample's
/// directions or irradiance, a pixel's weight, or the loss pixels is a new key.
#[test]
fn the_stride_memo_keys_on_what_the_choice_reads() {
    let records = pinhole_records(24, 4, false);
    let pixels = lit_pixels(&records);
    let key = |r: &ShadingRecords, p: &[usize]| {
        fingerprint(r, p, NdfKind::Ggx, Height::Correlated, SPARSE_TOLERANCE)
    };
    let base = key(&records, &pixels);
    let mut retargeted = records.clone();
    retargeted.target[pixels[0]][1] += 1.0;
    assert_eq!(key(&retargeted, &pixels), base);
    // The first sub-sample of the last lit pixel (sub-samples off the sample have no
    // irradiance to change).
    let last = pixels[pixels.len() - 1] * records.samples_per_pixel;
    assert!(records.irradiance[last][2] > 0.0);
    let changes: [(&str, Box<dyn Fn(&mut ShadingRecords)>); 4] = [
        ("irradiance", Box::new(|r| r.irradiance[last][2] *= 0.5)),
        ("wi", Box::new(|r| r.wi[last][0] += 1e-12)),
        ("wo", Box::new(|r| r.wo[0][1] -= 1e-12)),
        ("weight", Box::new(|r| r.weight[pixels[1]] *= 2.0)),
    ];
    for (what, change) in changes {
        let mut changed = records.clone();
        change(&mut changed);
        assert_ne!(key(&changed, &pixels), base, "{what}");
    }
    assert_ne!(key(&records, &pixels[1..]), base, "pixels");
    assert_ne!(
        fingerprint(
            &records,
            &pixels,
            NdfKind::Beckmann,
            Height::Correlated,
            SPARSE_TOLERANCE
        ),
        base,
        "ndf"
    );
}

/// The multiple-bounce render of a model is its exact render minus its single lobe's, path
/// for path (the same streams), for stochastic and deterministic models.
#[test]
fn the_multiple_bounce_render_is_the_whole_minus_the_single_lobe() {
    let records = pinhole_records(12, 4, false);
    let pixels = lit_pixels(&records);
    let seeds = [3, 4];
    for model in [Model::Heitz, Model::Bitterli, Model::Tabulated] {
        let m = material(model, 0.6, copper());
        let whole = render_material_streams(&m, &records, &pixels, &RenderPlan::exact(), &seeds);
        let single_lobe = Material {
            model: Model::Single,
            ..m.clone()
        };
        let single = render_material(&single_lobe, &records, &pixels, &RenderPlan::exact(), 0);
        let multi = render_multi_streams(&m, &records, &pixels, &seeds);
        let mut largest = 0.0f64;
        for (whole, multi) in whole.iter().zip(&multi) {
            for ((w, s), m) in whole.iter().zip(&single).zip(multi) {
                for c in 0..3 {
                    assert!(
                        (w[c] - s[c] - m[c]).abs() <= 1e-12 * w[c].max(1e-300),
                        "{model}: {} vs {}",
                        w[c] - s[c],
                        m[c]
                    );
                    largest = largest.max(m[c] / w[c].max(1e-300));
                }
            }
        }
        assert!(largest > 0.05, "{model}: the term is there ({largest})");
    }
}

/// Interpolating the analytic lobes changes the render by less than the tolerance (measured
/// on the same records); pixels next to the sample's edge, whose anchors miss it, are exact.
#[test]
fn sparse_multi_stays_within_its_tolerance_for_the_analytic_lobes() {
    let records = pinhole_records(48, 4, false);
    let pixels = lit_pixels(&records);
    for model in [Model::KullaConty, Model::FastMsx] {
        for alpha in [0.1, 0.35, 1.0] {
            for fresnel in [FresnelSpec::White, copper()] {
                let m = material(model, alpha, fresnel);
                let plan = RenderPlan::for_material(SPARSE_ONLY, &m, &records, &pixels);
                let anchors = plan.anchors.as_ref().expect("a stride meets the tolerance");
                assert!(anchors.stride > 1 && anchors.points.len() < pixels.len() / 2);
                let exact = render_pixels(&m, &records, &pixels, 0);
                let error = relative_rms_difference(
                    &render_material(&m, &records, &pixels, &plan, 0),
                    &exact,
                );
                // The bound is measured at each pixel's reference sub-sample with white
                // Fresnel; sub-sample spread and the Fresnel tint may add a little.
                assert!(
                    error <= 1.5 * SPARSE_TOLERANCE,
                    "{model} alpha {alpha}: {error}"
                );
            }
        }
    }
}

/// A stochastic model's sparse render has the exact render's expectation: the means of 400
/// independent renders of each agree within 4 standard errors plus the interpolation bound.
#[test]
fn sparse_multi_keeps_a_stochastic_render_unbiased() {
    let records = pinhole_records(16, 1, false);
    let pixels = lit_pixels(&records);
    let m = material(Model::Bitterli, 0.5, FresnelSpec::White);
    let plan = RenderPlan::for_material(SPARSE_ONLY, &m, &records, &pixels);
    assert!(plan.anchors.is_some());
    let total = |image: Vec<[f64; 3]>| image.iter().map(|v| v[0]).sum::<f64>();
    let runs = 400;
    let stats = |render: &dyn Fn(u64) -> Vec<[f64; 3]>| {
        let values: Vec<f64> = (0..runs).map(|seed| total(render(seed))).collect();
        let mean = values.iter().sum::<f64>() / runs as f64;
        let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (runs - 1) as f64;
        (mean, (var / runs as f64).sqrt())
    };
    let (sparse, se_sparse) = stats(&|seed| render_material(&m, &records, &pixels, &plan, seed));
    let (exact, se_exact) = stats(&|seed| render_pixels(&m, &records, &pixels, seed));
    let bound = 4.0 * se_sparse.hypot(se_exact) + SPARSE_TOLERANCE * exact;
    assert!(
        (sparse - exact).abs() <= bound,
        "{sparse} vs {exact} (+- {bound})"
    );
    assert!(se_exact > 0.0 && se_sparse > 0.0);
}

/// An exposure bracket repeats every direction pair: for a stochastic model evaluated in full
/// the plan finds each pair once and saves exactly the bracket's evaluations; for an analytic
/// model, or when the multiple-bounce term is sparse, it does not look (measured slower).
#[test]
fn repeated_geometry_is_shared_only_where_it_pays() {
    let records = pinhole_records(24, 4, true);
    let pixels = lit_pixels(&records);
    let repeats = Skips {
        repeated: true,
        sparse_multi: false,
        faint_multi: false,
        bounce_cap: false,
    };
    let walk = material(Model::Bitterli, 0.3, copper());
    let plan = RenderPlan::for_material(repeats, &walk, &records, &pixels);
    let repeated = plan.repeated.as_ref().expect("the bracket repeats");
    let lit = records
        .irradiance
        .iter()
        .filter(|e| **e != [0.0; 3])
        .count();
    assert_eq!(repeated.saved(), lit / 2);
    let analytic = material(Model::KullaConty, 0.3, copper());
    let plan = RenderPlan::for_material(repeats, &analytic, &records, &pixels);
    assert!(plan.repeated.is_none());
    let plan = RenderPlan::for_material(Skips::all(), &walk, &records, &pixels);
    assert!(plan.anchors.is_some() && plan.repeated.is_none());
    // Without the bracket nothing repeats, and the plan does not pay for the indirection.
    let single_set = pinhole_records(24, 4, false);
    let plan = RenderPlan::for_material(repeats, &walk, &single_set, &lit_pixels(&single_set));
    assert!(plan.repeated.is_none());
}

/// With a stochastic model the two exposures share one estimate per pair: their predictions
/// are exactly in the ratio of the exposures.
#[test]
fn repeated_geometry_shares_a_stochastic_estimate() {
    let records = pinhole_records(12, 1, true);
    let all: Vec<usize> = (0..records.pixel_count()).collect();
    let m = material(Model::Bitterli, 0.5, FresnelSpec::White);
    let repeats = Skips {
        repeated: true,
        sparse_multi: false,
        faint_multi: false,
        bounce_cap: false,
    };
    let plan = RenderPlan::for_material(repeats, &m, &records, &all);
    assert!(plan.repeated.is_some());
    let image = render_material(&m, &records, &all, &plan, 3);
    let half = all.len() / 2;
    for (p, (bright, dark)) in image[..half].iter().zip(&image[half..]).enumerate() {
        for (b, d) in bright.iter().zip(dark) {
            assert!((d * 4.0 - b).abs() <= 1e-12 * b.abs(), "{p}: {b} {d}");
        }
    }
}

/// Below the roughness where `1 - E_avg` falls under the tolerance the multiple-bounce term is
/// skipped (the render is the single model's, bit for bit); above it, it is not.
#[test]
fn faint_multi_is_skipped_only_where_its_albedo_is_below_the_tolerance() {
    let records = pinhole_records(16, 1, false);
    let pixels = lit_pixels(&records);
    let faint = Skips {
        repeated: false,
        sparse_multi: false,
        faint_multi: true,
        bounce_cap: false,
    };
    let kc = material(Model::KullaConty, 0.3, copper());
    let plan = RenderPlan::for_material(faint, &kc, &records, &pixels);
    let threshold = plan.summary(&kc).faint_below_alpha;
    let table = crate::bsdf::albedo_table::AlbedoTable::get(NdfKind::Ggx, Height::Correlated);
    let lost = |alpha: f64| 1.0 - table.e_avg(alpha);
    assert!(lost(threshold) < FAINT_TOLERANCE && lost(threshold * 1.01) >= FAINT_TOLERANCE);
    let below = material(Model::KullaConty, 0.9 * threshold, copper());
    assert!(matches!(
        plan.multi_term(&below.single::<f64>()),
        MultiTerm::Skipped
    ));
    let single = Material {
        model: Model::Single,
        ..below.clone()
    };
    assert_eq!(
        render_material(&below, &records, &pixels, &plan, 0),
        render_pixels(&single, &records, &pixels, 0)
    );
    let above = material(Model::KullaConty, 1.1 * threshold, copper());
    assert!(matches!(
        plan.multi_term(&above.single::<f64>()),
        MultiTerm::Exact
    ));
    // fast-msx's lobe is not bounded by the energy single scattering loses: never skipped.
    let fast = material(Model::FastMsx, 0.9 * threshold, copper());
    let plan = RenderPlan::for_material(faint, &fast, &records, &pixels);
    assert!(matches!(
        plan.multi_term(&fast.single::<f64>()),
        MultiTerm::Exact
    ));
}

/// Dual numbers flow through the interpolation: the derivative in `ln alpha` of a sparse render
/// equals the central difference of the `f64` sparse render at the same random numbers.
#[test]
fn sparse_renders_differentiate_exactly() {
    use num_dual::{Dual64, DualNum};
    let records = pinhole_records(16, 1, false);
    let pixels = lit_pixels(&records);
    for model in [Model::KullaConty, Model::Bitterli] {
        let m = material(model, 0.4, copper());
        let plan = RenderPlan::for_material(SPARSE_ONLY, &m, &records, &pixels);
        assert!(plan.anchors.is_some());
        let at = |ln_alpha: f64| {
            let alpha = ln_alpha.exp();
            let m = Material {
                alpha: [alpha, alpha],
                ..m.clone()
            };
            render_material(&m, &records, &pixels, &plan, 9)
        };
        let ln_alpha = Dual64::from_re(0.4f64.ln()).derivative();
        let alpha = ln_alpha.exp();
        let mut single = m.single::<Dual64>();
        single.microfacet.ax = alpha;
        single.microfacet.ay = alpha;
        let brdf =
            crate::bsdf::registry::differentiable(model, single, crate::bsdf::BounceCap::NONE)
                .unwrap();
        let zero = [Dual64::from_re(0.0); 3];
        let dual = render_planned(brdf.as_ref(), &single, zero, &records, &pixels, &plan, 9);
        let h = 1e-5;
        let (plus, minus) = (at(0.4f64.ln() + h), at(0.4f64.ln() - h));
        let (mut diff, mut norm) = (0.0, 0.0);
        for k in 0..pixels.len() {
            for c in 0..3 {
                let central = (plus[k][c] - minus[k][c]) / (2.0 * h);
                diff += (dual[k][c].eps - central).powi(2);
                norm += central * central;
            }
        }
        assert!(
            norm > 0.0 && (diff / norm).sqrt() < 1e-4,
            "{model}: {}",
            (diff / norm).sqrt()
        );
    }
}

/// The renders of the pair loss share their seed-free work and still equal separate renders:
/// for a stochastic model with sparse anchors (and a diffuse layer) each stream matches
/// `render_planned` of its seed to rounding, the two streams differ (their estimates are
/// independent), and where the multiple-bounce term is skipped both streams are the same render.
#[test]
fn streams_share_the_exact_terms_and_match_separate_renders() {
    let records = pinhole_records(16, 4, false);
    let pixels = lit_pixels(&records);
    let seeds = [4, 4 ^ 0xD1B5_4A32_D192_ED03];
    let rms = |a: &[[f64; 3]]| {
        (a.iter().flatten().map(|v| v * v).sum::<f64>() / (3 * a.len()) as f64).sqrt()
    };
    for (alpha, skips) in [
        (0.5, SPARSE_ONLY),
        (0.5, Skips::none()),
        (0.005, Skips::all()),
    ] {
        let m = Material {
            diffuse: [0.05, 0.1, 0.2],
            ..material(Model::Bitterli, alpha, copper())
        };
        let plan = RenderPlan::for_material(skips, &m, &records, &pixels);
        let shared = render_material_streams(&m, &records, &pixels, &plan, &seeds);
        let single = m.single::<f64>();
        let brdf = m.capped_brdf(plan.bounce_cap(&single));
        for (render, &seed) in shared.iter().zip(&seeds) {
            let alone = render_planned(
                brdf.as_ref(),
                &single,
                m.diffuse,
                &records,
                &pixels,
                &plan,
                seed,
            );
            let worst = render
                .iter()
                .flatten()
                .zip(alone.iter().flatten())
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(worst <= 1e-13 * rms(&alone), "alpha {alpha}: {worst:e}");
        }
        let skipped = matches!(plan.multi_term(&single), MultiTerm::Skipped);
        assert_eq!(skipped, alpha < 0.01);
        assert_eq!(shared[0] == shared[1], skipped, "alpha {alpha}");
    }
}

/// `bounce-cap`: switched off by name (`--no-skip`), a plan renders the uncapped model bit for
/// bit; on, at roughness 1 (cap 7-8 reflections), it lowers the image by a fraction between 0
/// and [`BOUNCE_TOLERANCE`] of its value (mean over 6 seeds, each render against the uncapped
/// one on the same streams, within 4 standard errors of that mean; on these 2304 pixels few
/// walks pass the cap, so the drop is often exactly 0); the cap grows with roughness.
#[test]
fn bounce_cap_lowers_a_render_by_at_most_its_tolerance() {
    let records = pinhole_records(16, 1, false);
    let pixels = lit_pixels(&records);
    let off = Skips::except(&[
        Skip::Repeated,
        Skip::SparseMulti,
        Skip::FaintMulti,
        Skip::BounceCap,
    ]);
    let only_cap = Skips {
        bounce_cap: true,
        ..off
    };
    for model in [Model::Bitterli, Model::WangBdpt] {
        let m = material(model, 1.0, copper());
        let plan = RenderPlan::for_material(off, &m, &records, &pixels);
        assert_eq!(
            render_material(&m, &records, &pixels, &plan, 4),
            render_pixels(&m, &records, &pixels, 4)
        );
        let plan = RenderPlan::for_material(only_cap, &m, &records, &pixels);
        let caps: Vec<u32> = [0.05, 0.3, 1.0, 2.0]
            .map(|alpha| {
                let cap = plan.bounce_cap(&material(model, alpha, copper()).single::<f64>());
                cap.get().unwrap_or(u32::MAX)
            })
            .to_vec();
        assert!(
            caps.windows(2).all(|w| w[0] <= w[1]) && caps[0] < caps[2],
            "{caps:?}"
        );
        let drops: Vec<f64> = (0..6)
            .map(|seed| {
                let capped = render_material(&m, &records, &pixels, &plan, seed);
                let free = render_pixels(&m, &records, &pixels, seed);
                let sum = |image: &[[f64; 3]]| image.iter().flatten().sum::<f64>();
                1.0 - sum(&capped) / sum(&free)
            })
            .collect();
        let mean = drops.iter().sum::<f64>() / drops.len() as f64;
        eprintln!("{model}: image lowered by {drops:?}");
        let var = drops.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / (drops.len() - 1) as f64;
        let se = (var / drops.len() as f64).sqrt();
        assert!(
            mean >= -4.0 * se && mean <= BOUNCE_TOLERANCE + 4.0 * se,
            "{model}: dropped {mean} +- {se} of the image ({drops:?}), cap {:?}",
            plan.bounce_cap(&m.single::<f64>())
        );
    }
}
