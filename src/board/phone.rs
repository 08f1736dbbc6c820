//! From phone photos of a sample lying in a printed board to a photo set (issue #18): detect
//! the tags, fit each photo's homography, find the focal length and the camera poses, put the
//! flash at the lens, check each photo, and resample the sample window.
//!
//! Before any pose, how the board was printed is fitted over all photos ([`fit_print`]): the
//! quarter turn of the tags' patterns (OpenCV's `generateImageMarker` prints the AprilTag
//! reference turned by 180 degrees) and the printed tags' size relative to their spacing (a
//! home print's black squares come out a few percent off: 0.978 on the real board frames of
//! `shared/data/real_board`).
//!
//! What each photo must pass, else it is left out with the reason named:
//! - at least [`MIN_TAGS`] of the board's tags found (too few: out of frame, out of focus);
//! - a reprojection error of the refined pose that agrees with the board and the other photos
//!   ([`reprojection_bound`]: relative to the tags' size in the photo, not a fixed pixel count);
//! - lit by its flash: the unclipped white paper of the tags' quiet zones must follow the
//!   flash's `cos / d^2` falloff ([`paper_flash`] at least [`MIN_FLASH_SHARE`]).
//!
//! The run refuses (exit 2) when fewer than [`MIN_PHOTOS`] photos remain.

use super::detect::{detect, TagCorners};
use super::geometry::{
    calibrate_lens, focal_from_homographies, homography, pose_from_homography, refine_pose,
    transfer_error, Correspondence, Intrinsics, Pose,
};
use super::Board;
use crate::capture::image_io::srgb_to_linear;
use crate::error::{Error, Result};
use nalgebra::{Matrix3, Vector3};
use serde::Serialize;
use std::path::Path;

/// Fewest tags a usable photo shows.
pub const MIN_TAGS: usize = 4;
/// Reprojection error (root mean square, as a share of the tags' black-square side in the
/// photo) that is always accepted: 5%, 2 px for tags of 40 px.
pub const ACCEPTED_RMS_OF_TAG: f64 = 0.05;
/// Above that, a photo is kept while its error is within this factor of the photos' median: a
/// print that is slightly bent or off its size shows in every photo alike, a blurred photo alone.
pub const OUTLIER_FACTOR: f64 = 3.0;
/// Beyond one module (1/8 of the black square) the board file does not describe the print.
pub const MAX_RMS_OF_TAG: f64 = 0.125;
/// Smallest share of the paper's brightness that the flash must explain.
pub const MIN_FLASH_SHARE: f64 = 0.5;
/// Fewest unclipped paper points [`paper_flash`] reads.
pub const MIN_PAPER_POINTS: usize = 8;
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
    /// Reads a photo upright (EXIF orientation applied), linearised from sRGB, with its
    /// clipped pixels and its EXIF focal length; errors name the file.
    pub fn read(path: &Path) -> Result<PhonePhoto> {
        use image::ImageDecoder;
        let reader = image::ImageReader::open(path)
            .map_err(|e| Error::io(path, e))?
            .with_guessed_format()
            .map_err(|e| Error::io(path, e))?;
        let mut decoder = reader
            .into_decoder()
            .map_err(|e| Error::invalid(path, "image", e.to_string()))?;
        let orientation = decoder
            .orientation()
            .unwrap_or(image::metadata::Orientation::NoTransforms);
        let mut image = image::DynamicImage::from_decoder(decoder)
            .map_err(|e| Error::invalid(path, "image", e.to_string()))?;
        image.apply_orientation(orientation);
        let rgb = image.to_rgb8();
        let (width, height) = (rgb.width() as usize, rgb.height() as usize);
        let table: Vec<f32> = (0..=255)
            .map(|v| srgb_to_linear(f64::from(v) / 255.0) as f32)
            .collect();
        let linear = rgb
            .pixels()
            .map(|p| p.0.map(|v| table[usize::from(v)]))
            .collect();
        let clipped = clipped_pixels(&rgb);
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        Ok(PhonePhoto {
            name,
            width,
            height,
            linear,
            clipped,
            exif_focal_px: exif_focal_px(path, width, height),
        })
    }

    /// Divides the vignetting `v` of a lens `k` out of the linear values.
    pub fn devignette(&mut self, k: &Intrinsics, v: Vignetting) {
        let width = self.width;
        for (i, p) in self.linear.iter_mut().enumerate() {
            let factor = v.at_pixel(k, i, width).max(1e-3) as f32;
            *p = p.map(|value| value / factor);
        }
    }

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
    /// Mean side of the detected tags' black squares, pixels.
    pub tag_side_px: Option<f64>,
    /// Root-mean-square reprojection error of the refined pose, pixels.
    pub rms_px: Option<f64>,
    /// The largest error the photo was allowed ([`reprojection_bound`]), pixels.
    pub rms_bound_px: Option<f64>,
    /// Camera centre in the board frame (board units).
    pub camera: Option<[f64; 3]>,
    pub flash_share: Option<f64>,
    /// The flash intensity written for the photo (measured on the paper, or as given).
    pub flash_intensity: Option<[f64; 3]>,
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
    /// The flash as the photo's paper shows it.
    pub paper: PaperFlash,
}

/// The result of [`locate`]: intrinsics, the usable photos' poses, and a report of every photo.
pub struct Located3d {
    pub intrinsics: Intrinsics,
    /// The vignetting taken out of the photos ([`Vignetting::NONE`] without).
    pub vignetting: Vignetting,
    pub focal_source: FocalSource,
    pub print: Print,
    pub photos: Vec<Located>,
    pub reports: Vec<PhotoReport>,
}

/// How the board was printed, as the photos show it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Print {
    /// Clockwise quarter turns (as printed) of every tag's pattern against the board file's
    /// upright tags: 0, or 2 for OpenCV's `generateImageMarker` tags.
    pub tag_quarter_turns: usize,
    /// Side of the printed black squares over the board file's `tag_size`, the tags' centres
    /// kept where the file puts them.
    pub tag_scale: f64,
}

impl Print {
    pub const AS_FILED: Print = Print {
        tag_quarter_turns: 0,
        tag_scale: 1.0,
    };
}

/// Board point of each detected corner under `print`: a tag turned by `q` clockwise quarter
/// turns shows its own top-left corner at the file's corner `q` (top-left, top-right, ...).
fn correspondences(board: &Board, tags: &[TagCorners], print: Print) -> Vec<Correspondence> {
    tags.iter()
        .flat_map(|t| {
            let truth = board.corners(t.id).expect("detect keeps board tags only");
            let [cx, cy] = board.tag(t.id).expect("a board tag").center;
            (0..4).map(move |i| {
                let [x, y] = truth[(i + print.tag_quarter_turns) % 4];
                Correspondence {
                    board: [
                        cx + print.tag_scale * (x - cx),
                        cy + print.tag_scale * (y - cy),
                    ],
                    image: t.corners[i],
                }
            })
        })
        .collect()
}

/// The print that best explains every photo's tags: the quarter turn with the least total
/// homography transfer error, then the tag scale in [0.8, 1.2] by golden-section search on the
/// same error. Photos with fewer than [`MIN_TAGS`] tags take no part.
pub fn fit_print(board: &Board, detected: &[Vec<TagCorners>]) -> Print {
    let error = |print: Print| -> f64 {
        detected
            .iter()
            .filter(|tags| tags.len() >= MIN_TAGS)
            .map(|tags| {
                let points = correspondences(board, tags, print);
                homography(&points).map_or(f64::INFINITY, |h| transfer_error(&h, &points))
            })
            .sum()
    };
    let tag_quarter_turns = (0..4)
        .min_by(|&a, &b| {
            let at = |q| {
                error(Print {
                    tag_quarter_turns: q,
                    tag_scale: 1.0,
                })
            };
            at(a).total_cmp(&at(b))
        })
        .unwrap_or(0);
    let at_scale = |tag_scale| {
        error(Print {
            tag_quarter_turns,
            tag_scale,
        })
    };
    let golden = (5f64.sqrt() - 1.0) / 2.0;
    let (mut lo, mut hi) = (0.8, 1.2);
    while hi - lo > 1e-5 {
        let (a, b) = (hi - golden * (hi - lo), lo + golden * (hi - lo));
        if at_scale(a) <= at_scale(b) {
            hi = b;
        } else {
            lo = a;
        }
    }
    Print {
        tag_quarter_turns,
        tag_scale: (lo + hi) / 2.0,
    }
}

/// Mean side in pixels of the detected tags' black squares.
fn tag_side_px(tags: &[TagCorners]) -> f64 {
    let sides: f64 = tags
        .iter()
        .map(|t| {
            (0..4)
                .map(|i| {
                    let (a, b) = (t.corners[i], t.corners[(i + 1) % 4]);
                    (a[0] - b[0]).hypot(a[1] - b[1])
                })
                .sum::<f64>()
                / 4.0
        })
        .sum();
    sides / tags.len().max(1) as f64
}

/// The largest reprojection error (pixels) a photo whose tags are `side_px` wide may have when
/// the photos' median error is `median_px`: [`ACCEPTED_RMS_OF_TAG`] of the side always, up to
/// [`OUTLIER_FACTOR`] times the median (a print off its size or slightly bent shows in every
/// photo), never beyond [`MAX_RMS_OF_TAG`] of the side.
pub fn reprojection_bound(side_px: f64, median_px: f64) -> f64 {
    (ACCEPTED_RMS_OF_TAG * side_px)
        .max(OUTLIER_FACTOR * median_px)
        .min(MAX_RMS_OF_TAG * side_px)
}

/// The camera model `capture` fits.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Lens {
    /// A pinhole at the image centre.
    Pinhole,
    /// Principal point and radial distortion `k1`, `k2` fitted over all photos
    /// ([`calibrate_lens`]), from at least [`MIN_LENS_PHOTOS`] photos, and kept when they pay
    /// for themselves in the corners' reprojection ([`pays_for_itself`]).
    Calibrated,
}

/// Whether `capture` fits the lens's vignetting.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum VignettingModel {
    /// None: the photos as they are.
    None,
    /// Fitted on the white paper of the photos ([`fit_vignetting`]) and divided out of them,
    /// from at least [`MIN_LENS_PHOTOS`] photos.
    Calibrated,
}

/// How [`locate`] calibrates the photos.
#[derive(Clone, Copy, Debug)]
pub struct LocateOptions {
    /// The focal length in pixels: overrides EXIF and estimation.
    pub focal_px: Option<f64>,
    /// The flash's position in the camera frame (OpenCV axes, board units).
    pub flash_offset: [f64; 3],
    pub lens: Lens,
    pub vignetting: VignettingModel,
}

/// Parameters a calibrated lens adds to a pinhole: principal point, k1, k2.
const LENS_PARAMETERS: usize = 4;

/// Whether `parameters` more that took a sum of `n` squared residuals from `before` to `after`
/// pay for themselves by Schwarz's criterion: the decrease, in units of the residuals' variance
/// after (`after / n`), must exceed `parameters ln n`. A fit to noise alone gains about
/// `parameters`.
pub fn pays_for_itself(before: f64, after: f64, n: usize, parameters: usize) -> bool {
    let variance = after / n.max(1) as f64;
    variance > 0.0 && (before - after) / variance > parameters as f64 * (n.max(2) as f64).ln()
}

/// Fewest photos a lens is calibrated from.
pub const MIN_LENS_PHOTOS: usize = 4;

/// Detects, calibrates and checks every photo; the vignetting it finds is taken out of the
/// photos in place ([`PhonePhoto::devignette`]).
pub fn locate(board: &Board, photos: &mut [PhonePhoto], options: LocateOptions) -> Located3d {
    let LocateOptions { focal_px, lens, .. } = options;
    let mut reports: Vec<PhotoReport> = photos
        .iter()
        .map(|p| PhotoReport {
            name: p.name.clone(),
            tags_found: 0,
            tag_side_px: None,
            rms_px: None,
            rms_bound_px: None,
            camera: None,
            flash_share: None,
            flash_intensity: None,
            left_out: None,
            tags: Vec::new(),
            homography: None,
            rotation_vector: None,
            translation: None,
        })
        .collect();
    let detected: Vec<Vec<TagCorners>> = photos
        .iter()
        .map(|photo| detect(board, photo.width, photo.height, photo.grey()).unwrap_or_default())
        .collect();
    let print = fit_print(board, &detected);
    let mut seen: Vec<(usize, Vec<Correspondence>, Matrix3<f64>)> = Vec::new();
    for (i, tags) in detected.iter().enumerate() {
        reports[i].tags_found = tags.len();
        reports[i].tags = tags.iter().map(|t| (t.id, t.corners)).collect();
        if tags.len() < MIN_TAGS {
            reports[i].left_out = Some(format!(
                "{} of the board's tags found, {MIN_TAGS} needed (out of frame or out of focus?)",
                tags.len()
            ));
            continue;
        }
        reports[i].tag_side_px = Some(tag_side_px(tags));
        let points = correspondences(board, tags, print);
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
    let mut intrinsics = Intrinsics::pinhole(focal, cx, cy);
    let mut posed = Vec::new();
    for (i, points, h) in seen {
        let Some(pose) = focal
            .is_finite()
            .then(|| pose_from_homography(&h, &intrinsics))
            .flatten()
        else {
            reports[i].left_out = Some(
                "no focal length: give --focal-px (the views are too alike to estimate it)".into(),
            );
            continue;
        };
        posed.push((i, refine_pose(pose, &intrinsics, &points), points));
    }
    // The lens from the photos whose pinhole poses fit the board to within a module.
    let fitting: Vec<(Pose, &[Correspondence])> = posed
        .iter()
        .filter(|(i, pose, points)| {
            let side = reports[*i].tag_side_px.unwrap_or(0.0);
            pose.rms_error(&intrinsics, points) <= MAX_RMS_OF_TAG * side
        })
        .map(|(_, pose, points)| (*pose, points.as_slice()))
        .collect();
    if lens == Lens::Calibrated && fitting.len() >= MIN_LENS_PHOTOS {
        let size = photos.first().map_or([0, 0], |p| [p.width, p.height]);
        let fixed_focal = focal_source == FocalSource::Given;
        let (lens, poses) = calibrate_lens(intrinsics, fixed_focal, size, &fitting);
        // Kept only when it explains the corners better than the pinhole by more than their
        // noise would: a lens fitted to the noise would only move the cameras.
        let squared = |k: &Intrinsics, poses: &mut dyn Iterator<Item = &Pose>| -> f64 {
            poses
                .zip(&fitting)
                .map(|(pose, (_, points))| pose.rms_error(k, points).powi(2) * points.len() as f64)
                .sum()
        };
        let before = squared(&intrinsics, &mut fitting.iter().map(|f| &f.0));
        let after = squared(&lens, &mut poses.iter());
        let residuals = 2 * fitting.iter().map(|f| f.1.len()).sum::<usize>();
        if pays_for_itself(before, after, residuals, LENS_PARAMETERS) {
            intrinsics = lens;
            for (_, pose, points) in &mut posed {
                *pose = refine_pose(*pose, &intrinsics, points);
            }
        }
    }
    let posed: Vec<(usize, Pose, f64)> = posed
        .into_iter()
        .map(|(i, pose, points)| {
            let rms = pose.rms_error(&intrinsics, &points);
            let report = &mut reports[i];
            let c = pose.center();
            report.rms_px = Some(rms);
            report.camera = Some([c.x, c.y, c.z]);
            let rv = pose.rotation.scaled_axis();
            report.rotation_vector = Some([rv.x, rv.y, rv.z]);
            report.translation = Some([pose.translation.x, pose.translation.y, pose.translation.z]);
            (i, pose, rms)
        })
        .collect();
    let mut errors: Vec<f64> = posed.iter().map(|p| p.2).collect();
    errors.sort_by(f64::total_cmp);
    let median_px = errors.get(errors.len() / 2).copied().unwrap_or(0.0);
    let mut geometric = Vec::new();
    for (i, pose, rms) in posed {
        let report = &mut reports[i];
        let side = report.tag_side_px.unwrap_or(0.0);
        let bound = reprojection_bound(side, median_px);
        report.rms_bound_px = Some(bound);
        if rms > bound {
            report.left_out = Some(if bound >= MAX_RMS_OF_TAG * side {
                format!(
                    "reprojection error {rms:.2} px > {bound:.2} px, one module of the tags' \
                     {side:.0} px side: the board file does not describe this print (another \
                     layout or tag size?)"
                )
            } else {
                format!(
                    "reprojection error {rms:.2} px > {bound:.2} px ({:.0}% of the tags' \
                     {side:.0} px side, or {OUTLIER_FACTOR}x the photos' median {median_px:.2} \
                     px): board blurred or moved in this photo?",
                    100.0 * ACCEPTED_RMS_OF_TAG
                )
            });
            continue;
        }
        geometric.push((i, pose));
    }
    // The vignetting from the paper of the photos that pass, then taken out of every photo.
    let flash_offset = options.flash_offset;
    let paper = |photos: &[PhonePhoto], i: usize, pose: &Pose| {
        paper_flash(board, &photos[i], &intrinsics, pose, flash_offset)
    };
    let mut vignetting = Vignetting::NONE;
    if options.vignetting == VignettingModel::Calibrated {
        let lit: Vec<Vec<PaperRead>> = geometric
            .iter()
            .filter(|(i, pose)| paper(photos, *i, pose).is_ok_and(|p| p.share >= MIN_FLASH_SHARE))
            .map(|(i, pose)| paper_reads(board, &photos[*i], &intrinsics, pose, flash_offset).0)
            .collect();
        if lit.len() >= MIN_LENS_PHOTOS {
            vignetting = fit_vignetting(&lit);
            photos
                .iter_mut()
                .for_each(|photo| photo.devignette(&intrinsics, vignetting));
        }
    }
    let mut located = Vec::new();
    for (i, pose) in geometric {
        let report = &mut reports[i];
        let measured = paper(photos, i, &pose);
        report.flash_share = measured.as_ref().ok().map(|p| p.share);
        match measured {
            Ok(paper) if paper.share >= MIN_FLASH_SHARE => located.push(Located {
                index: i,
                pose,
                paper,
            }),
            Ok(PaperFlash { share: s, .. }) => {
                report.left_out = Some(format!(
                    "the flash explains {:.0}% of the paper's brightness, {:.0}% needed (flash \
                     off?)",
                    100.0 * s,
                    100.0 * MIN_FLASH_SHARE
                ))
            }
            Err(why) => report.left_out = Some(why),
        }
    }
    Located3d {
        intrinsics,
        vignetting,
        focal_source,
        print,
        photos: located,
        reports,
    }
}

/// The flash position in the board frame for a camera at `pose`.
pub fn flash_position(pose: &Pose, flash_offset: [f64; 3]) -> Vector3<f64> {
    pose.rotation.inverse() * (Vector3::from(flash_offset) - pose.translation)
}

/// One read of the board's white paper.
#[derive(Clone, Copy, Debug)]
pub struct PaperRead {
    /// The flash's `cos / d^2` at the paper point.
    pub falloff: f64,
    /// The photo's linear RGB there.
    pub rgb: [f64; 3],
    /// The pixel's squared normalised distance from the principal point (as the lens's `r^2`).
    pub radius2: f64,
}

/// The photo's unclipped reads of the paper points ([`Board::paper_points`]) it sees, and how
/// many it sees clipped or not.
pub fn paper_reads(
    board: &Board,
    photo: &PhonePhoto,
    k: &Intrinsics,
    pose: &Pose,
    flash_offset: [f64; 3],
) -> (Vec<PaperRead>, usize) {
    let flash = flash_position(pose, flash_offset);
    let (mut reads, mut seen) = (Vec::new(), 0);
    for [x, y] in board.paper_points() {
        let Some(q) = pose.project(k, [x, y]) else {
            continue;
        };
        let (c, r) = (q[0].floor(), q[1].floor());
        if c < 0.0 || r < 0.0 || c >= photo.width as f64 || r >= photo.height as f64 {
            continue;
        }
        let index = r as usize * photo.width + c as usize;
        seen += 1;
        if photo.clipped[index] {
            continue;
        }
        let to_flash = flash - Vector3::new(x, y, 0.0);
        let d2 = to_flash.norm_squared();
        reads.push(PaperRead {
            falloff: to_flash.z.max(0.0) / d2.sqrt() / d2,
            rgb: photo.linear[index].map(f64::from),
            radius2: k.radius2(c + 0.5, r + 0.5),
        });
    }
    (reads, seen)
}

/// The lens's relative illumination `1 + a r^2 + b r^4` of the normalised image radius
/// (vignetting; `r` as the distortion's), `[a, b]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Vignetting(pub [f64; 2]);

impl Vignetting {
    pub const NONE: Vignetting = Vignetting([0.0; 2]);

    pub fn factor(&self, radius2: f64) -> f64 {
        1.0 + radius2 * (self.0[0] + self.0[1] * radius2)
    }

    /// The factor at the centre of pixel `i` of an image `width` pixels wide, seen by lens `k`.
    pub fn at_pixel(&self, k: &Intrinsics, i: usize, width: usize) -> f64 {
        let (c, r) = ((i % width) as f64 + 0.5, (i / width) as f64 + 0.5);
        self.factor(k.radius2(c, r))
    }
}

/// Standard deviation of the prior on each vignetting coefficient, against a paper read's
/// relative noise of 1%.
const VIGNETTING_PRIOR: f64 = 0.5;
const PAPER_READ_NOISE: f64 = 0.01;

/// The vignetting the paper of several photos shows: every photo's paper is `v_c = s_c
/// falloff V(r^2)`, with its own `s_c` (its flash, exposure and white balance, fitted in
/// closed form) and `V` shared ([`Vignetting`]), fitted by Levenberg-Marquardt on the reads'
/// relative residuals, and kept when it pays for itself ([`pays_for_itself`]). The
/// flash's falloff across the board and the lens's across the image differ as soon as the
/// board is seen at different places in the frame.
pub fn fit_vignetting(photos: &[Vec<PaperRead>]) -> Vignetting {
    let residuals = |p: &[f64]| -> Option<Vec<f64>> {
        let v = Vignetting([p[0], p[1]]);
        let mut r = Vec::new();
        for reads in photos {
            let model: Vec<f64> = reads
                .iter()
                .map(|x| x.falloff * v.factor(x.radius2))
                .collect();
            let mm: f64 = model.iter().map(|m| m * m).sum();
            for c in 0..3 {
                let mv: f64 = reads.iter().zip(&model).map(|(x, m)| m * x.rgb[c]).sum();
                let scale = mv / mm.max(f64::MIN_POSITIVE);
                let mean = reads.iter().map(|x| x.rgb[c]).sum::<f64>() / reads.len() as f64;
                for (x, m) in reads.iter().zip(&model) {
                    r.push((x.rgb[c] - scale * m) / mean.max(f64::MIN_POSITIVE));
                }
            }
        }
        r.push(p[0] * PAPER_READ_NOISE / VIGNETTING_PRIOR);
        r.push(p[1] * PAPER_READ_NOISE / VIGNETTING_PRIOR);
        Some(r)
    };
    let p = super::geometry::levenberg_marquardt(vec![0.0, 0.0], &[1e-6, 1e-6], residuals);
    // Kept only when it explains the paper better than none by more than its noise would: a
    // vignetting fitted to the noise would only bend the photos where no paper was seen.
    let cost = |p: &[f64]| residuals(p).map_or(f64::INFINITY, |r| r.iter().map(|v| v * v).sum());
    let reads = 3 * photos.iter().map(Vec::len).sum::<usize>();
    if pays_for_itself(cost(&[0.0, 0.0]), cost(&p), reads, 2) {
        Vignetting([p[0], p[1]])
    } else {
        Vignetting::NONE
    }
}

/// The flash as the board's white paper shows it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PaperFlash {
    /// Share of the paper's brightness that the flash's falloff explains (0: ambient light
    /// alone, 1: the flash alone).
    pub share: f64,
    /// Per channel, the flash's radiant intensity times the camera's gain over the paper's
    /// albedo: `pi L / (rho cos / d^2)` fitted through the origin. Divided by the paper's
    /// albedo it is the light that renders this photo's pixel values (exposure and white
    /// balance included).
    pub intensity_times_albedo: [f64; 3],
}

/// The flash as the board's white paper shows it: the paper at least a module from any black
/// module, the window and the board's edge ([`Board::paper_points`]) is read. Its linear
/// luminance `v` is fitted as `v = a g + b` with `g = cos / d^2` of the flash, and the share is
/// `a mean(g) / mean(v)`; each channel's `v_c = (rho / pi) I_c g` through the origin gives the
/// intensity (Lambertian paper: `L = rho / pi E`). Clipped pixels are not read: an
/// over-exposed paper is flat where the flash is brightest. The reason, when fewer than
/// [`MIN_PAPER_POINTS`] unclipped paper points are in the photo.
pub fn paper_flash(
    board: &Board,
    photo: &PhonePhoto,
    k: &Intrinsics,
    pose: &Pose,
    flash_offset: [f64; 3],
) -> Result<PaperFlash, String> {
    let (reads, seen) = paper_reads(board, photo, k, pose, flash_offset);
    if reads.len() < MIN_PAPER_POINTS {
        return Err(if seen >= MIN_PAPER_POINTS {
            format!(
                "the white paper is clipped at {} of its {seen} points read: too little left to \
                 check the flash (over-exposed?)",
                seen - reads.len()
            )
        } else {
            "too little white paper seen to check the flash".into()
        });
    }
    let samples: Vec<(f64, [f64; 3])> = reads.iter().map(|r| (r.falloff, r.rgb)).collect();
    let luminance = |p: &[f64; 3]| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
    let n = samples.len() as f64;
    let (mg, mv) = samples.iter().fold((0.0, 0.0), |(a, b), s| {
        (a + s.0 / n, b + luminance(&s.1) / n)
    });
    let (sgg, sgv) = samples.iter().fold((0.0, 0.0), |(a, b), s| {
        (
            a + (s.0 - mg).powi(2),
            b + (s.0 - mg) * (luminance(&s.1) - mv),
        )
    });
    let share = if sgg <= 0.0 || mv <= 0.0 {
        0.0
    } else {
        (sgv / sgg * mg / mv).clamp(0.0, 1.0)
    };
    let g2: f64 = samples.iter().map(|s| s.0 * s.0).sum();
    let intensity_times_albedo = std::array::from_fn(|c| {
        let gv: f64 = samples.iter().map(|s| s.0 * s.1[c]).sum();
        std::f64::consts::PI * gv / g2.max(f64::MIN_POSITIVE)
    });
    Ok(PaperFlash {
        share,
        intensity_times_albedo,
    })
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

/// The four pixels (row-major indices of a `size` image) and weights of a bilinear read at image
/// position `q` (pixel centres at half-integers); `None` outside the pixel centres' hull.
fn bilinear_taps(size: [usize; 2], q: [f64; 2]) -> Option<[(usize, f64); 4]> {
    let [w, h] = size;
    let (x, y) = (q[0] - 0.5, q[1] - 0.5);
    if !(x >= 0.0 && y >= 0.0 && x <= (w - 1) as f64 && y <= (h - 1) as f64) {
        return None;
    }
    let (x0, y0) = (x.floor() as usize, y.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let (fx, fy) = (x - x0 as f64, y - y0 as f64);
    Some([
        (y0 * w + x0, (1.0 - fx) * (1.0 - fy)),
        (y0 * w + x1, fx * (1.0 - fy)),
        (y1 * w + x0, (1.0 - fx) * fy),
        (y1 * w + x1, fx * fy),
    ])
}

/// The bilinear read of `taps` of an RGB image whose pixel `i` is `at(i)`.
fn read(taps: &[(usize, f64); 4], at: impl Fn(usize) -> [f64; 3]) -> [f64; 3] {
    taps.iter().fold([0.0; 3], |sum, &(i, weight)| {
        let v = at(i);
        std::array::from_fn(|c| sum[c] + weight * v[c])
    })
}

/// Bilinear read of the linear photo at image position `q`, and whether one of the four pixels
/// read is clipped; `None` outside the photo.
fn bilinear(photo: &PhonePhoto, q: [f64; 2]) -> Option<([f64; 3], bool)> {
    let taps = bilinear_taps([photo.width, photo.height], q)?;
    let value = read(&taps, |i| photo.linear[i].map(f64::from));
    Some((value, taps.iter().any(|&(i, _)| photo.clipped[i])))
}

/// What a lens with radial distortion `[k1, k2]` ([`Intrinsics::pixel`]) makes of a pinhole
/// image `rgb` (`size` pixels, focal `focal`, principal point `principal`): each pixel reads the
/// pinhole image, bilinearly, where its undistorted ray lands (the distortion inverted by
/// fixed-point iteration); black where that is outside. `synth --distortion` uses it to make
/// the photos `capture` calibrates a lens from.
pub fn distorted(
    rgb: &[[f64; 3]],
    size: [usize; 2],
    focal: f64,
    principal: [f64; 2],
    distortion: [f64; 2],
) -> Vec<[f64; 3]> {
    let [w, h] = size;
    (0..w * h)
        .map(|i| {
            let xd = ((i % w) as f64 + 0.5 - principal[0]) / focal;
            let yd = ((i / w) as f64 + 0.5 - principal[1]) / focal;
            let (mut x, mut y) = (xd, yd);
            for _ in 0..20 {
                let r2 = x * x + y * y;
                let s = 1.0 + r2 * (distortion[0] + distortion[1] * r2);
                (x, y) = (xd / s, yd / s);
            }
            let q = [x * focal + principal[0], y * focal + principal[1]];
            bilinear_taps(size, q).map_or([0.0; 3], |taps| read(&taps, |j| rgb[j]))
        })
        .collect()
}

/// Focal length in pixels from EXIF `FocalLengthIn35mmFilm` (35 mm equivalent: the full frame's
/// 43.27 mm diagonal spans the image diagonal), if present.
fn exif_focal_px(path: &Path, width: usize, height: usize) -> Option<f64> {
    let file = std::fs::File::open(path).ok()?;
    let exif = exif::Reader::new()
        .read_from_container(&mut std::io::BufReader::new(file))
        .ok()?;
    let field = exif.get_field(exif::Tag::FocalLengthIn35mmFilm, exif::In::PRIMARY)?;
    let f35 = f64::from(field.value.get_uint(0)?);
    let diagonal_px = ((width * width + height * height) as f64).sqrt();
    (f35 > 0.0).then(|| f35 * diagonal_px / 36.0f64.hypot(24.0))
}

/// Smallest 8-bit value treated as clipped: JPEG's block transform rings around a clipped
/// highlight, so values just below 255 next to it are not radiance either.
const CLIPPED_FROM: u8 = 250;

/// Pixels within one pixel of a channel at or above [`CLIPPED_FROM`].
fn clipped_pixels(rgb: &image::RgbImage) -> Vec<bool> {
    let (w, h) = (rgb.width() as usize, rgb.height() as usize);
    let high: Vec<bool> = rgb
        .pixels()
        .map(|p| p.0.iter().any(|&v| v >= CLIPPED_FROM))
        .collect();
    (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            (y.saturating_sub(1)..(y + 2).min(h))
                .any(|yy| (x.saturating_sub(1)..(x + 2).min(w)).any(|xx| high[yy * w + xx]))
        })
        .collect()
}
