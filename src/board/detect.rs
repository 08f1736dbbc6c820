//! Marker detection: the tags of a board in a greyscale photo, with the image positions of each
//! tag's four corners in the board's own corner order, by `kornia-apriltag` (pure Rust; the
//! project's crosschecks hold it to OpenCV's `cv2.aruco` tag36h11 detector).
//!
//! Pixel convention of the project (src/capture/camera.rs): pixel `(c, r)` covers
//! `[c, c+1] x [r, r+1]`. The detector's coordinates are the same (measured: its corners on
//! synthetic photos have a mean offset below 0.01 px from the true projections; `board::tests`).

use super::{Board, TagFamilyName};
use crate::error::{Error, Result};
use kornia_apriltag::family::TagFamilyKind;
use kornia_apriltag::{AprilTagDecoder, DecodeTagsConfig};
use kornia_image::{Image, ImageSize};

/// The four corners of one detected tag in image pixels, in [`Board::corners`]'s order (the
/// tag's own top-left, top-right, bottom-right, bottom-left, whatever the photo's rotation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TagCorners {
    pub id: u16,
    pub corners: [[f64; 2]; 4],
    /// Bits corrected by the decoder (0 for a clean read).
    pub hamming: u8,
}

/// The tags of `board` found in an 8-bit greyscale image (`width` x `height`, row-major),
/// sorted by id; tags not on the board and repeated ids are dropped.
pub fn detect(
    board: &Board,
    width: usize,
    height: usize,
    grey: Vec<u8>,
) -> Result<Vec<TagCorners>> {
    let kind = match board.family {
        TagFamilyName::Tag36h11 => TagFamilyKind::Tag36H11,
    };
    let detector_error = |e: &dyn std::fmt::Display| Error::argument("detector", e.to_string());
    let size = ImageSize { width, height };
    let image = Image::<u8, 1>::new(size, grey).map_err(|e| detector_error(&e))?;
    let config = DecodeTagsConfig::new(vec![kind]).map_err(|e| detector_error(&e))?;
    let mut decoder = AprilTagDecoder::new(config, size).map_err(|e| detector_error(&e))?;
    let detections = decoder.decode(&image).map_err(|e| detector_error(&e))?;
    let mut found: Vec<TagCorners> = detections
        .iter()
        .filter(|d| board.tag(d.id).is_some())
        .map(|d| {
            // The decoded homography maps the tag's own square [-1, 1]^2 (y toward the tag's
            // bottom row) to the image, with the decoded rotation applied.
            let at = |x: f32, y: f32| {
                let p = d.quad.homography_project(x, y);
                [f64::from(p.x), f64::from(p.y)]
            };
            TagCorners {
                id: d.id,
                corners: [at(-1.0, -1.0), at(1.0, -1.0), at(1.0, 1.0), at(-1.0, 1.0)],
                hamming: d.hamming,
            }
        })
        .collect();
    found.sort_by_key(|t| t.id);
    let ids: Vec<u16> = found.iter().map(|t| t.id).collect();
    found.retain(|t| ids.iter().filter(|&&i| i == t.id).count() == 1);
    Ok(found)
}
