//! From phone photos of a sample lying in a printed board to a photo set (issue #18): detect
//! the tags, fit each photo's homography, find the focal length and the camera poses, put the
//! flash at the lens, check each photo, and resample the sample window.
//!
//! What each photo must pass, else it is left out with the reason named:
//! - at least [`MIN_TAGS`] of the board's tags found (too few: out of frame, out of focus);
//! - reprojection error of the refined pose below [`MAX_RMS_PX`] (a blurred or bent board);
//! - lit by its flash: the white paper of the tags' quiet zones must follow the flash's
//!   `cos / d^2` falloff ([`flash_share`] at least [`MIN_FLASH_SHARE`]).
//!
//! The run refuses (exit 2) when fewer than [`MIN_PHOTOS`] photos remain.

use super::detect::{detect, TagCorners};
use super::geometry::{
    focal_from_homographies, homography, pose_from_homography, refine_pose, Correspondence,
    Intrinsics, Pose,
};
use super::Board;
use nalgebra::{Matrix3, Vector3};
use serde::Serialize;

/// Fewest tags a usable photo shows.
pub const MIN_TAGS: usize = 4;
/// Largest acceptable root-mean-square reprojection error of a photo's pose, pixels.
pub const MAX_RMS_PX: f64 = 2.0;
/// Smallest share of the paper's brightness that the flash must explain.
pub const MIN_FLASH_SHARE: f64 = 0.5;
/// Fewest photos a photo set needs.
pub const MIN_PHOTOS: usize = 3;

/// One photo as the pipeline reads it.
pub struct PhonePhoto {
    pub name: String,
    pub width: usize,
    pub height: usize,
    /// Linear RGB, row-major (the sRGB transfer undone).
    pub linear: Vec<[f32; 3]>,
    /// Pixels with a channel at the top of the file's range (clipped highlights).
    pub clipped: Vec<bool>,
    /// Focal length in pixels from the photo's EXIF, if it has one.
    pub exif_focal_px: Option<f64>,
}

impl PhonePhoto {
    /// 8-bit grey (sRGB-encoded luma) for the detector.
    pub fn grey(&self) -> Vec<u8> {
        self.linear
            .iter()
            .map(|p| {
                let y = 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
                (crate::capture::image_io::linear_to_srgb(f64::from(y)).clamp(0.0, 1.0) * 255.0)
                    .round() as u8
            })
            .collect()
    }
}

/// Where the focal length came from.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum FocalSource {
    Given,
    Exif,
    Board,
}

/// What happened to one photo.
#[derive(Clone, Debug, Serialize)]
pub struct PhotoReport {
    pub name: String,
    pub tags_found: usize,
    /// Root-mean-square reprojection error of the refined pose, pixels.
    pub rms_px: Option<f64>,
    /// Camera centre in the board frame (board units).
    pub camera: Option<[f64; 3]>,
    pub flash_share: Option<f64>,
    /// Why the photo was left out; `None` when it is used.
    pub left_out: Option<String>,
    /// The detected tags: id and corners in image pixels, in the board's corner order.
    pub tags: Vec<(u16, [[f64; 2]; 4])>,
    /// Board plane to image, `image ~ H (x, y, 1)`, rows.
    pub homography: Option<[[f64; 3]; 3]>,
    /// The pose as `cv2.solvePnP` gives it: rotation vector (radians) and translation.
    pub rotation_vector: Option<[f64; 3]>,
    pub translation: Option<[f64; 3]>,
}

/// A photo that passed, with its camera.
pub struct Located {
    pub index: usize,
    pub pose: Pose,
}

/// The result of [`locate`]: intrinsics, the usable photos' poses, and a report of every photo.
pub struct Located3d {
    pub intrinsics: Intrinsics,
    pub focal_source: FocalSource,
    pub photos: Vec<Located>,
    pub reports: Vec<PhotoReport>,
}

fn correspondences(board: &Board, tags: &[TagCorners]) -> Vec<Correspondence> {
    tags.iter()
        .flat_map(|t| {
            let truth = board.corners(t.id).expect("detect keeps board tags only");
            (0..4).map(move |i| Correspondence {
                board: truth[i],
                image: t.corners[i],
            })
        })
        .collect()
}

/// Detects, calibrates and checks every photo. `focal_px` overrides EXIF and estimation.
/// `flash_offset` is the flash's position in the camera frame (OpenCV axes, board units).
pub fn locate(
    board: &Board,
    photos: &[PhonePhoto],
    focal_px: Option<f64>,
    flash_offset: [f64; 3],
) -> Located3d {
    let mut reports: Vec<PhotoReport> = photos
        .iter()
        .map(|p| PhotoReport {
            name: p.name.clone(),
            tags_found: 0,
            rms_px: None,
            camera: None,
            flash_share: None,
            left_out: None,
            tags: Vec::new(),
            homography: None,
            rotation_vector: None,
            translation: None,
        })
        .collect();
    let mut seen: Vec<(usize, Vec<Correspondence>, Matrix3<f64>)> = Vec::new();
    for (i, photo) in photos.iter().enumerate() {
        let tags = detect(board, photo.width, photo.height, photo.grey()).unwrap_or_default();
        reports[i].tags_found = tags.len();
        reports[i].tags = tags.iter().map(|t| (t.id, t.corners)).collect();
        if tags.len() < MIN_TAGS {
            reports[i].left_out = Some(format!(
                "{} of the board's tags found, {MIN_TAGS} needed (out of frame or out of focus?)",
                tags.len()
            ));
            continue;
        }
        let points = correspondences(board, &tags);
        match homography(&points) {
            Some(h) => {
                reports[i].homography =
                    Some(std::array::from_fn(|r| std::array::from_fn(|c| h[(r, c)])));
                seen.push((i, points, h));
            }
            None => reports[i].left_out = Some("the tags' corners are degenerate".into()),
        }
    }
    let (cx, cy) = photos
        .first()
        .map(|p| (p.width as f64 / 2.0, p.height as f64 / 2.0))
        .unwrap_or((0.0, 0.0));
    let exif = photos.iter().find_map(|p| p.exif_focal_px);
    let (focal, focal_source) = match (focal_px, exif) {
        (Some(f), _) => (f, FocalSource::Given),
        (None, Some(f)) => (f, FocalSource::Exif),
        (None, None) => {
            let hs: Vec<Matrix3<f64>> = seen.iter().map(|s| s.2).collect();
            let f = focal_from_homographies(&hs, cx, cy).unwrap_or(f64::NAN);
            (f, FocalSource::Board)
        }
    };
    let intrinsics = Intrinsics { focal, cx, cy };
    let mut located = Vec::new();
    for (i, points, h) in seen {
        let report = &mut reports[i];
        let Some(pose) = focal
            .is_finite()
            .then(|| pose_from_homography(&h, &intrinsics))
            .flatten()
        else {
            report.left_out = Some(
                "no focal length: give --focal-px (the views are too alike to estimate it)".into(),
            );
            continue;
        };
        let pose = refine_pose(pose, &intrinsics, &points);
        let rms = pose.rms_error(&intrinsics, &points);
        let c = pose.center();
        report.rms_px = Some(rms);
        report.camera = Some([c.x, c.y, c.z]);
        let rv = pose.rotation.scaled_axis();
        report.rotation_vector = Some([rv.x, rv.y, rv.z]);
        report.translation = Some([pose.translation.x, pose.translation.y, pose.translation.z]);
        if rms > MAX_RMS_PX {
            report.left_out = Some(format!(
                "reprojection error {rms:.2} px > {MAX_RMS_PX} px (board blurred or not flat?)"
            ));
            continue;
        }
        let share = flash_share(board, &photos[i], &intrinsics, &pose, flash_offset);
        report.flash_share = share;
        if share.is_none_or(|s| s < MIN_FLASH_SHARE) {
            report.left_out = Some(match share {
                Some(s) => format!("the flash explains {:.0}% of the paper's brightness, {:.0}% needed (flash off?)", 100.0 * s, 100.0 * MIN_FLASH_SHARE),
                None => "too little white paper seen to check the flash".into(),
            });
            continue;
        }
        located.push(Located { index: i, pose });
    }
    Located3d {
        intrinsics,
        focal_source,
        photos: located,
        reports,
    }
}

/// The flash position in the board frame for a camera at `pose`.
pub fn flash_position(pose: &Pose, flash_offset: [f64; 3]) -> Vector3<f64> {
    pose.rotation.inverse() * (Vector3::from(flash_offset) - pose.translation)
}

/// How much of the white paper's brightness a flash at the lens explains: the paper of every
/// board tag's quiet zone (one module around the black square) is read at several points, and
/// its linear luminance `v` is fitted as `v = a g + b` with `g = cos / d^2` of the flash; the
/// share is `a mean(g) / mean(v)`. Ambient light alone gives a share near 0, a flash near 1.
/// `None` when fewer than 8 paper points are in the photo.
pub fn flash_share(
    board: &Board,
    photo: &PhonePhoto,
    k: &Intrinsics,
    pose: &Pose,
    flash_offset: [f64; 3],
) -> Option<f64> {
    let flash = flash_position(pose, flash_offset);
    let module = board.tag_size / super::tags::BLACK_MODULES as f64;
    let reach = board.tag_size / 2.0 + module / 2.0;
    let mut samples = Vec::new();
    for tag in &board.tags {
        for s in -3..=3 {
            let t = s as f64 / 3.0 * (reach - module / 2.0);
            for [dx, dy] in [[t, reach], [t, -reach], [reach, t], [-reach, t]] {
                let (x, y) = (tag.center[0] + dx, tag.center[1] + dy);
                let Some(q) = pose.project(k, [x, y]) else {
                    continue;
                };
                let (c, r) = (q[0].floor(), q[1].floor());
                if c < 0.0 || r < 0.0 || c >= photo.width as f64 || r >= photo.height as f64 {
                    continue;
                }
                let p = photo.linear[r as usize * photo.width + c as usize];
                let v =
                    0.2126 * f64::from(p[0]) + 0.7152 * f64::from(p[1]) + 0.0722 * f64::from(p[2]);
                let to_flash = flash - Vector3::new(x, y, 0.0);
                let d2 = to_flash.norm_squared();
                samples.push((to_flash.z.max(0.0) / d2.sqrt() / d2, v));
            }
        }
    }
    if samples.len() < 8 {
        return None;
    }
    let n = samples.len() as f64;
    let (mg, mv) = samples
        .iter()
        .fold((0.0, 0.0), |(a, b), s| (a + s.0 / n, b + s.1 / n));
    let (sgg, sgv) = samples.iter().fold((0.0, 0.0), |(a, b), s| {
        (a + (s.0 - mg).powi(2), b + (s.0 - mg) * (s.1 - mv))
    });
    if sgg <= 0.0 || mv <= 0.0 {
        return Some(0.0);
    }
    let slope = sgv / sgg;
    Some((slope * mg / mv).clamp(0.0, 1.0))
}

/// Photo pixels next to the window's edge whose reads may blend in the paper around it.
const EDGE_PIXELS: f64 = 2.0;

/// A rectified photo: linear RGB, and per pixel whether every read fell inside the photo and
/// at least [`EDGE_PIXELS`] photo pixels inside the window, so that no paper blends in
/// (`keep`), and whether any read touched a clipped photo pixel (`saturated`).
pub struct Rectified {
    pub rgb: Vec<[f32; 3]>,
    pub keep: Vec<bool>,
    pub saturated: Vec<bool>,
}

/// The sample window resampled to `resolution` pixels as a rectified photo (pixel (c, r)
/// covers the window's `[c, c+1] x [r, r+1]` / resolution, row 0 at `+y`), each pixel the mean
/// of `ss` x `ss` bilinear reads of the linear photo.
pub fn rectify(
    board: &Board,
    photo: &PhonePhoto,
    k: &Intrinsics,
    pose: &Pose,
    resolution: [usize; 2],
    ss: usize,
) -> Rectified {
    let (w, h) = (board.window.width, board.window.height);
    let n = resolution[0] * resolution[1];
    let mut out = Rectified {
        rgb: Vec::with_capacity(n),
        keep: Vec::with_capacity(n),
        saturated: Vec::with_capacity(n),
    };
    let center = pose.center();
    for r in 0..resolution[1] {
        for c in 0..resolution[0] {
            let mut sum = [0.0f64; 3];
            let (mut inside, mut saturated) = (true, false);
            for s in 0..ss * ss {
                let u = (c as f64 + ((s % ss) as f64 + 0.5) / ss as f64) / resolution[0] as f64;
                let v = (r as f64 + ((s / ss) as f64 + 0.5) / ss as f64) / resolution[1] as f64;
                let point = [(u - 0.5) * w, (0.5 - v) * h];
                // Board length of one photo pixel there (at least; oblique views see more).
                let pixel = (center - Vector3::new(point[0], point[1], 0.0)).norm() / k.focal;
                let margin = (w / 2.0 - point[0].abs()).min(h / 2.0 - point[1].abs());
                inside &= margin >= EDGE_PIXELS * pixel;
                match pose.project(k, point).and_then(|q| bilinear(photo, q)) {
                    Some((value, clipped)) => {
                        (0..3).for_each(|i| sum[i] += value[i]);
                        saturated |= clipped;
                    }
                    None => inside = false,
                }
            }
            let n = (ss * ss) as f64;
            out.rgb.push(sum.map(|v| (v / n) as f32));
            out.keep.push(inside);
            out.saturated.push(saturated);
        }
    }
    out
}

/// Bilinear read of the linear photo at image position `q` (pixel centres at half-integers),
/// and whether one of the four pixels read is clipped; `None` outside the photo.
fn bilinear(photo: &PhonePhoto, q: [f64; 2]) -> Option<([f64; 3], bool)> {
    let (x, y) = (q[0] - 0.5, q[1] - 0.5);
    if x < 0.0 || y < 0.0 || x > (photo.width - 1) as f64 || y > (photo.height - 1) as f64 {
        return None;
    }
    let (x0, y0) = (x.floor() as usize, y.floor() as usize);
    let (x1, y1) = (
        (x0 + 1).min(photo.width - 1),
        (y0 + 1).min(photo.height - 1),
    );
    let (fx, fy) = (x - x0 as f64, y - y0 as f64);
    let at = |xx: usize, yy: usize| photo.linear[yy * photo.width + xx].map(f64::from);
    let (a, b, c, d) = (at(x0, y0), at(x1, y0), at(x0, y1), at(x1, y1));
    let clipped = [(x0, y0), (x1, y0), (x0, y1), (x1, y1)]
        .iter()
        .any(|&(xx, yy)| photo.clipped[yy * photo.width + xx]);
    let value = std::array::from_fn(|i| {
        (a[i] * (1.0 - fx) + b[i] * fx) * (1.0 - fy) + (c[i] * (1.0 - fx) + d[i] * fx) * fy
    });
    Some((value, clipped))
}
