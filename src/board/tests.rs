//! Board description, printing, detection and plane geometry, each against a known truth: a
//! board photographed by a synthetic pinhole camera at a known pose.

use super::detect::detect;
use super::geometry::*;
use super::*;
use nalgebra::{Rotation3, Vector3};

/// A camera at `eye` looking at the board origin, rolled by `roll` radians about its axis.
pub(crate) fn looking_at(eye: [f64; 3], roll: f64) -> Pose {
    let eye = Vector3::from(eye);
    let forward = (-eye).normalize();
    let up_hint = if forward.cross(&Vector3::y()).norm() > 1e-6 {
        Vector3::y()
    } else {
        Vector3::x()
    };
    let right = forward.cross(&up_hint).normalize();
    let down = forward.cross(&right);
    // Rows of the world-to-camera rotation are the camera axes (OpenCV: x right, y down).
    let r =
        nalgebra::Matrix3::from_rows(&[right.transpose(), down.transpose(), forward.transpose()]);
    let rotation =
        Rotation3::from_axis_angle(&Vector3::z_axis(), roll) * Rotation3::from_matrix_unchecked(r);
    Pose {
        rotation,
        translation: -(rotation * eye),
    }
}

/// Greyscale photo of the printed board (white 235, black 20, window 128) by a pinhole camera,
/// `ss` x `ss` samples per pixel: the test's own rasteriser, independent of `print`.
pub(crate) fn photograph(
    board: &Board,
    k: &Intrinsics,
    pose: &Pose,
    size: [usize; 2],
    ss: usize,
) -> Vec<u8> {
    photograph_print(board, |x, y| board.is_black(x, y), k, pose, size, ss)
}

/// [`photograph`] of a print whose reflectance is `is_black` (the board's own, or a print
/// that differs from its file).
fn photograph_print(
    board: &Board,
    is_black: impl Fn(f64, f64) -> Option<bool>,
    k: &Intrinsics,
    pose: &Pose,
    size: [usize; 2],
    ss: usize,
) -> Vec<u8> {
    let shade = |hit: Option<[f64; 2]>| match hit.map(|[x, y]| is_black(x, y)) {
        None => 60.0,
        Some(Some(true)) => 20.0,
        Some(Some(false)) => 235.0,
        Some(None) => 128.0,
    };
    render(board, k, pose, size, ss, shade)
        .into_iter()
        .map(|v| v.round() as u8)
        .collect()
}

/// Per pixel, the mean of `shade` over `ss` x `ss` sub-samples, given the board-plane point
/// each sees (`None` off the printed board or behind the camera).
fn render(
    board: &Board,
    k: &Intrinsics,
    pose: &Pose,
    size: [usize; 2],
    ss: usize,
    shade: impl Fn(Option<[f64; 2]>) -> f64,
) -> Vec<f64> {
    let inverse = pose.rotation.inverse();
    let center = pose.center();
    let e = board.extent();
    let mut out = Vec::with_capacity(size[0] * size[1]);
    for r in 0..size[1] {
        for c in 0..size[0] {
            let mut sum = 0.0;
            for s in 0..ss * ss {
                let px = c as f64 + ((s % ss) as f64 + 0.5) / ss as f64;
                let py = r as f64 + ((s / ss) as f64 + 0.5) / ss as f64;
                let ray = inverse * Vector3::new((px - k.cx) / k.focal, (py - k.cy) / k.focal, 1.0);
                let t = -center.z / ray.z;
                let (x, y) = (center.x + t * ray.x, center.y + t * ray.y);
                let on_board = t > 0.0
                    && x >= e[0] - 1.0
                    && x <= e[1] + 1.0
                    && y >= e[2] - 1.0
                    && y <= e[3] + 1.0;
                sum += shade(on_board.then_some([x, y]));
            }
            out.push(sum / (ss * ss) as f64);
        }
    }
    out
}

fn board() -> Board {
    Board::ring(10.0, 10.0, 1.6, 0.4)
}

#[test]
fn ring_board_validates_and_round_trips_through_toml() {
    let b = board();
    assert!(b.tags.len() >= 16, "{} tags", b.tags.len());
    b.validate().unwrap();
    let back: Board = toml::from_str(&b.to_toml()).unwrap();
    assert_eq!(back, b);
}

#[test]
fn invalid_boards_name_the_field() {
    let mut b = board();
    b.tags[3].center = [0.0, 0.0];
    assert_eq!(b.validate().unwrap_err().0, "tag[3].center");
    let mut b = board();
    b.tags[5].id = b.tags[2].id;
    assert_eq!(b.validate().unwrap_err().0, "tag[5].id");
    let mut b = board();
    b.tag_size = f64::NAN;
    assert_eq!(b.validate().unwrap_err().0, "tag_size");
    let mut b = board();
    b.tags[0].id = 600;
    assert_eq!(b.validate().unwrap_err().0, "tag[0].id");
}

#[test]
fn printed_board_is_read_back_by_the_detector_with_every_tag() {
    let b = board();
    let dpi = 150.0;
    let (w, h, grey) = print::raster(&b, dpi).unwrap();
    let found = detect(&b, w as usize, h as usize, grey).unwrap();
    assert_eq!(found.len(), b.tags.len());
    // The print is a scaled, y-flipped copy of the board frame: corners land where the layout says.
    let dots_per_cm = dpi / 2.54;
    let e = b.extent();
    let margin = 2.0 * b.tag_size / 8.0;
    for t in &found {
        for (seen, truth) in t.corners.iter().zip(b.corners(t.id).unwrap()) {
            let x = (truth[0] - (e[0] - margin)) * dots_per_cm;
            let y = ((e[3] + margin) - truth[1]) * dots_per_cm;
            assert!(
                (seen[0] - x).abs() < 0.75 && (seen[1] - y).abs() < 0.75,
                "tag {} {seen:?} vs {x},{y}",
                t.id
            );
        }
    }
}

#[test]
fn oblique_rolled_photos_give_corners_in_the_boards_order() {
    let b = board();
    let k = Intrinsics::pinhole(700.0, 320.0, 240.0);
    for (eye, roll) in [
        ([4.0, -6.0, 30.0], 0.3),
        ([-8.0, 3.0, 28.0], 2.0),
        ([2.0, 9.0, 26.0], -1.4),
    ] {
        let pose = looking_at(eye, roll);
        let grey = photograph(&b, &k, &pose, [640, 480], 3);
        let found = detect(&b, 640, 480, grey).unwrap();
        assert!(
            found.len() >= b.tags.len() - 2,
            "{} of {} tags at {eye:?}",
            found.len(),
            b.tags.len()
        );
        // A wrong corner order or a half-pixel convention error shows as a bias; a single
        // corner of a ~37 px tag is good to about half a pixel.
        let (mut bias, mut n) = ([0.0; 2], 0.0);
        for t in &found {
            for (seen, truth) in t.corners.iter().zip(b.corners(t.id).unwrap()) {
                let q = pose.project(&k, truth).unwrap();
                let d = ((seen[0] - q[0]).powi(2) + (seen[1] - q[1]).powi(2)).sqrt();
                assert!(d < 1.0, "tag {} corner off by {d:.2} px at {eye:?}", t.id);
                bias = [bias[0] + seen[0] - q[0], bias[1] + seen[1] - q[1]];
                n += 1.0;
            }
        }
        assert!(
            bias.iter().all(|b| (b / n).abs() < 0.1),
            "mean offset {bias:?} / {n}"
        );
    }
}

fn correspondences(
    b: &Board,
    k: &Intrinsics,
    pose: &Pose,
    noise: f64,
    seed: u64,
) -> Vec<Correspondence> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
    b.tags
        .iter()
        .flat_map(|t| b.corners(t.id).unwrap())
        .map(|board| {
            let q = pose.project(k, board).unwrap();
            let jitter = [
                rng.random_range(-noise..=noise),
                rng.random_range(-noise..=noise),
            ];
            Correspondence {
                board,
                image: [q[0] + jitter[0], q[1] + jitter[1]],
            }
        })
        .collect()
}

#[test]
fn homography_focal_and_pose_recover_a_known_camera() {
    let b = board();
    let truth_k = Intrinsics::pinhole(1500.0, 960.0, 720.0);
    let eyes = [
        [5.0, -8.0, 30.0],
        [-9.0, 2.0, 27.0],
        [1.0, 10.0, 32.0],
        [7.0, 7.0, 29.0],
    ];
    let poses: Vec<Pose> = eyes
        .iter()
        .enumerate()
        .map(|(i, &e)| looking_at(e, 0.4 * i as f64))
        .collect();
    let sets: Vec<_> = poses
        .iter()
        .enumerate()
        .map(|(i, p)| correspondences(&b, &truth_k, p, 0.3, i as u64))
        .collect();
    let hs: Vec<_> = sets.iter().map(|s| homography(s).unwrap()).collect();
    let focal = focal_from_homographies(&hs, truth_k.cx, truth_k.cy).unwrap();
    assert!((focal / truth_k.focal - 1.0).abs() < 0.01, "focal {focal}");
    let k = Intrinsics { focal, ..truth_k };
    for ((h, set), (truth, eye)) in hs.iter().zip(&sets).zip(poses.iter().zip(eyes)) {
        let pose = refine_pose(pose_from_homography(h, &k).unwrap(), &k, set);
        let c = pose.center();
        let distance = Vector3::from(eye).norm();
        assert!(
            (c - Vector3::from(eye)).norm() < 0.01 * distance,
            "centre {c:?} vs {eye:?}"
        );
        assert!(
            pose.rms_error(&k, set) < 0.6,
            "rms {}",
            pose.rms_error(&k, set)
        );
        assert!(truth.rms_error(&k, set) < 0.6);
    }
}

#[test]
fn degenerate_correspondences_have_no_homography() {
    let line: Vec<Correspondence> = (0..6)
        .map(|i| Correspondence {
            board: [i as f64, 2.0 * i as f64],
            image: [10.0 * i as f64, 3.0],
        })
        .collect();
    assert!(homography(&line).is_none());
    assert!(homography(&line[..3]).is_none());
}

/// The board as a printer that turns every tag by `quarter_turns` clockwise and scales its
/// pattern by `scale` about its centre would print it.
fn misprinted(
    b: &Board,
    quarter_turns: usize,
    scale: f64,
) -> impl Fn(f64, f64) -> Option<bool> + '_ {
    move |x, y| {
        let half = b.outer_size() / 2.0;
        for t in &b.tags {
            let (mut dx, mut dy) = ((x - t.center[0]) / scale, (y - t.center[1]) / scale);
            if dx.abs() < half && dy.abs() < half {
                // Undo the clockwise turns: a counter-clockwise quarter turn each.
                for _ in 0..quarter_turns {
                    (dx, dy) = (-dy, dx);
                }
                return b.is_black(t.center[0] + dx, t.center[1] + dy);
            }
        }
        b.is_black(x, y).map(|_| false)
    }
}

#[test]
fn a_print_with_turned_and_shrunk_tags_is_fitted_from_its_photos() {
    let b = board();
    let k = Intrinsics::pinhole(900.0, 400.0, 300.0);
    let eyes = [([3.0, -5.0, 30.0], 0.2), ([-6.0, 2.0, 28.0], 1.7)];
    for (quarter_turns, scale) in [(0, 1.0), (1, 0.97), (2, 1.0), (3, 1.03)] {
        let print = misprinted(&b, quarter_turns, scale);
        let detected: Vec<_> = eyes
            .iter()
            .map(|&(eye, roll)| {
                let grey = photograph_print(&b, &print, &k, &looking_at(eye, roll), [800, 600], 2);
                detect(&b, 800, 600, grey).unwrap()
            })
            .collect();
        assert!(detected.iter().all(|d| d.len() >= b.tags.len() - 2));
        let fitted = phone::fit_print(&b, &detected);
        assert_eq!(fitted.tag_quarter_turns, quarter_turns);
        // A 45 px tag's corners are good to about 0.3 px: its side to about 1%, over ~40 tags
        // to a few parts in a thousand.
        assert!(
            (fitted.tag_scale - scale).abs() < 0.003,
            "{quarter_turns} turns: scale {} for {scale}",
            fitted.tag_scale
        );
    }
}

#[test]
fn an_over_exposed_paper_is_checked_on_its_unclipped_points() {
    let b = board();
    let k = Intrinsics::pinhole(700.0, 400.0, 300.0);
    let pose = looking_at([7.0, -6.0, 20.0], 0.3);
    let center = pose.center();
    // Paper (0.8) and toner (0.04) lit by a flash at the lens: radiance albedo cos / d^2, times
    // a gain that over-exposes most of the paper, as a phone's auto-exposure does on a dark sample.
    let radiance = |gain: f64| {
        render(&b, &k, &pose, [800, 600], 2, |hit| {
            let Some([x, y]) = hit else { return 0.02 };
            let albedo = match b.is_black(x, y) {
                Some(true) => 0.04,
                Some(false) => 0.8,
                None => 0.1,
            };
            let to_flash = center - Vector3::new(x, y, 0.0);
            gain * albedo * to_flash.z / to_flash.norm().powi(3)
        })
    };
    let photo = |gain: f64, flag_clipped: bool| {
        let linear: Vec<f64> = radiance(gain);
        let clipped = linear.iter().map(|&v| flag_clipped && v >= 1.0).collect();
        phone::PhonePhoto {
            name: "over".into(),
            width: 800,
            height: 600,
            linear: linear.iter().map(|&v| [v.min(1.0) as f32; 3]).collect(),
            clipped,
            exif_focal_px: None,
        }
    };
    let share =
        |p: &phone::PhonePhoto| phone::paper_flash(&b, p, &k, &pose, [0.0; 3]).map(|f| f.share);
    // Exposed right, the flash explains the paper, and its intensity times the paper's albedo
    // is what lit it: pi x gain x 0.8 (L = rho / pi I cos / d^2).
    assert!(share(&photo(300.0, true)).unwrap() > 0.9);
    let intensity = |p: &phone::PhonePhoto| {
        phone::paper_flash(&b, p, &k, &pose, [0.0; 3])
            .unwrap()
            .intensity_times_albedo
    };
    for (gain, flagged) in [(300.0, true), (900.0, true)] {
        let truth = std::f64::consts::PI * gain * 0.8;
        let got = intensity(&photo(gain, flagged));
        assert!(
            got.iter().all(|i| (i / truth - 1.0).abs() < 0.02),
            "{got:?} vs {truth}"
        );
    }
    // Over-exposed: read with its clipped points the paper looks flat, as if the flash were off.
    // (At 900 the far paper is at 0.55, the near at 1.6; measured 0.99 unclipped, 0.09 through.)
    let (over, over_unflagged) = (photo(900.0, true), photo(900.0, false));
    let clipped_paper = 1.0 - share(&over_unflagged).unwrap();
    assert!(
        clipped_paper > 0.5,
        "share read through the clipping {}",
        1.0 - clipped_paper
    );
    assert!(share(&over).unwrap() > 0.9, "{:?}", share(&over));
    // All of it clipped: nothing left to check, and the reason says so.
    let why = share(&photo(1e5, true)).unwrap_err();
    assert!(
        why.contains("clipped") && why.contains("over-exposed"),
        "{why}"
    );
}

#[test]
fn bundle_adjustment_recovers_a_distorted_off_centre_lens() {
    let b = board();
    let truth = Intrinsics {
        focal: 1500.0,
        cx: 979.0,
        cy: 706.0,
        distortion: [-0.05, 0.01],
    };
    let eyes = [
        [5.0, -8.0, 30.0],
        [-9.0, 2.0, 27.0],
        [1.0, 10.0, 32.0],
        [7.0, 7.0, 29.0],
        [-6.0, -6.0, 26.0],
        [0.0, 0.0, 24.0],
    ];
    let poses: Vec<Pose> = eyes
        .iter()
        .enumerate()
        .map(|(i, &e)| looking_at(e, 0.5 * i as f64))
        .collect();
    // Corners good to +-0.2 px, as the detector gives them.
    let sets: Vec<_> = poses
        .iter()
        .enumerate()
        .map(|(i, p)| correspondences(&b, &truth, p, 0.2, 10 + i as u64))
        .collect();
    // What capture starts from: a pinhole at the image centre with the board's focal length.
    let hs: Vec<_> = sets.iter().map(|s| homography(s).unwrap()).collect();
    let focal = focal_from_homographies(&hs, 960.0, 720.0).unwrap();
    let start = Intrinsics::pinhole(focal, 960.0, 720.0);
    let posed: Vec<Pose> = hs
        .iter()
        .zip(&sets)
        .map(|(h, s)| refine_pose(pose_from_homography(h, &start).unwrap(), &start, s))
        .collect();
    let pinhole_rms = posed
        .iter()
        .zip(&sets)
        .map(|(p, s)| p.rms_error(&start, s))
        .fold(0.0, f64::max);
    let photos: Vec<(Pose, &[Correspondence])> = posed
        .iter()
        .zip(&sets)
        .map(|(p, s)| (*p, s.as_slice()))
        .collect();
    let (k, refined) = calibrate_lens(start, false, [1920, 1440], &photos);
    assert!(
        (k.cx - truth.cx).abs() < 2.0 && (k.cy - truth.cy).abs() < 2.0,
        "principal point {}, {}",
        k.cx,
        k.cy
    );
    assert!(
        (k.focal / truth.focal - 1.0).abs() < 0.005,
        "focal {}",
        k.focal
    );
    // The distortion curve where the corners are (r^2 up to about 0.15 here).
    let curve = |k: &Intrinsics, r2: f64| r2 * (k.distortion[0] + k.distortion[1] * r2);
    for r2 in [0.02, 0.08, 0.15] {
        let (got, want) = (curve(&k, r2), curve(&truth, r2));
        assert!(
            (got - want).abs() < 0.002,
            "distortion at r^2 {r2}: {got} vs {want}"
        );
    }
    // Every photo's corners then reproject to their noise (uniform +-0.2 px: 0.16 px RMS).
    for (pose, set) in refined.iter().zip(&sets) {
        let rms = pose.rms_error(&k, set);
        assert!(
            rms < 0.25 && rms < pinhole_rms,
            "rms {rms} (pinhole {pinhole_rms})"
        );
    }
}

#[test]
fn a_lens_the_views_cannot_determine_stays_near_a_centred_pinhole() {
    // Four photos straight down from one height: the principal point trades against the
    // translation and the distortion against nothing the corners show; the priors hold them.
    let b = board();
    let truth = Intrinsics::pinhole(1200.0, 800.0, 600.0);
    let photos: Vec<(Pose, Vec<Correspondence>)> = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]
        .iter()
        .enumerate()
        .map(|(i, [x, y])| {
            let pose = looking_at([*x, *y, 30.0], 0.0);
            (pose, correspondences(&b, &truth, &pose, 0.2, 40 + i as u64))
        })
        .collect();
    let views: Vec<(Pose, &[Correspondence])> =
        photos.iter().map(|(p, s)| (*p, s.as_slice())).collect();
    let (k, poses) = calibrate_lens(truth, true, [1600, 1200], &views);
    assert_eq!(k.focal, truth.focal);
    assert!(k.cx.is_finite() && k.cy.is_finite() && poses.iter().all(|p| p.center().z > 0.0));
    assert!(
        (k.cx - 800.0).abs() < 0.05 * 1600.0 && (k.cy - 600.0).abs() < 0.05 * 1600.0,
        "{k:?}"
    );
    assert!(
        k.distortion.iter().all(|d| d.abs() < 0.2),
        "{:?}",
        k.distortion
    );
}
