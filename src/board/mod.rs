//! Printed tag boards for phone captures: the board description (`BOARD.toml`), its tags'
//! module patterns, a printable image of it, marker detection, and the plane geometry that
//! turns detected corners into cameras (issue #18).
//!
//! Board frame = sample frame (DESIGN.md "Photo-set manifest"): the sample window is centred at
//! the origin, `x` right and `y` up as seen in the printed board, normal `+z`, lengths in the
//! board's `units`. A tag is printed upright (its module row 0 toward `+y`), its black square
//! of side `tag_size` centred at `center`; the white quiet zone of one module around it is part
//! of the printed tag (AprilTag's `total_width` of 10 modules for tag36h11, 8 of them black
//! border and data).
//!
//! ```toml
//! family = "tag36h11"
//! units = "cm"
//! tag_size = 1.6            # side of a tag's black square
//! [window]                  # the sample, centred at the origin
//! width = 10.0
//! height = 10.0
//! [[tag]]                   # any number; `bouncefit board` writes a ring of them
//! id = 0
//! center = [-6.5, 6.5]
//! ```

pub mod detect;
pub mod geometry;
pub mod paper;
pub mod phone;
pub mod print;
pub mod tags;

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The tag families a board may use (the detector's and the printer's).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum TagFamilyName {
    /// AprilTag 36h11: 587 codes, minimum Hamming distance 11 (what MaterialGAN's boards use).
    #[serde(rename = "tag36h11")]
    Tag36h11,
}

/// A board's sample window: the rectangle the sample lies in, centred at the origin.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Window {
    pub width: f64,
    pub height: f64,
}

/// One printed tag.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TagPlacement {
    pub id: u16,
    /// Centre of the tag's black square in the board frame.
    pub center: [f64; 2],
}

/// A printed board: tag family and size, sample window, tag positions (module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Board {
    pub family: TagFamilyName,
    pub units: String,
    /// Side of a tag's black square.
    pub tag_size: f64,
    pub window: Window,
    #[serde(rename = "tag")]
    pub tags: Vec<TagPlacement>,
}

impl Board {
    /// A ring of tags around a `width` x `height` window: the tags' black squares of side
    /// `tag_size` sit `gap` outside the window edge and `gap` apart, ids from 0 in reading
    /// order (top row left to right, then down the sides, then the bottom row).
    pub fn ring(width: f64, height: f64, tag_size: f64, gap: f64) -> Board {
        let pitch = tag_size + gap;
        let (hx, hy) = (
            width / 2.0 + gap + tag_size / 2.0,
            height / 2.0 + gap + tag_size / 2.0,
        );
        // Tags along an edge of length 2h (corner to corner centres), evenly spread.
        let count = |h: f64| ((2.0 * h) / pitch).floor().max(1.0) as usize + 1;
        let spread = |h: f64, n: usize, i: usize| -h + 2.0 * h * i as f64 / (n - 1).max(1) as f64;
        let (nx, ny) = (count(hx), count(hy));
        let mut centers = Vec::new();
        centers.extend((0..nx).map(|i| [spread(hx, nx, i), hy]));
        for j in 1..ny - 1 {
            let y = -spread(hy, ny, j);
            centers.push([-hx, y]);
            centers.push([hx, y]);
        }
        centers.extend((0..nx).map(|i| [spread(hx, nx, i), -hy]));
        Board {
            family: TagFamilyName::Tag36h11,
            units: "cm".into(),
            tag_size,
            window: Window { width, height },
            tags: centers
                .into_iter()
                .enumerate()
                .map(|(id, center)| TagPlacement {
                    id: id as u16,
                    center,
                })
                .collect(),
        }
    }

    /// Reads and validates a `BOARD.toml`; errors name the file and the field.
    pub fn load(path: &Path) -> Result<Board> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        let board: Board = toml::from_str(&text)
            .map_err(|e| Error::invalid(path, "board", e.message().to_string()))?;
        board
            .validate()
            .map_err(|(field, message)| Error::invalid(path, field, message))?;
        Ok(board)
    }

    /// The board as `BOARD.toml` text.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).expect("a board serialises")
    }

    /// `(field, message)` of the first problem: sizes positive and finite, ids unique and in
    /// the family, tags clear of the window and of each other.
    pub fn validate(&self) -> std::result::Result<(), (String, String)> {
        let positive = |field: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err((
                    field.to_string(),
                    format!("must be a positive length, got {v}"),
                ))
            }
        };
        positive("tag_size", self.tag_size)?;
        positive("window.width", self.window.width)?;
        positive("window.height", self.window.height)?;
        if self.tags.len() < 4 {
            return Err((
                "tag".into(),
                format!("a board needs at least 4 tags, has {}", self.tags.len()),
            ));
        }
        let codes = tags::code_count(self.family);
        let half = self.outer_size() / 2.0;
        for (i, tag) in self.tags.iter().enumerate() {
            let field = format!("tag[{i}]");
            if usize::from(tag.id) >= codes {
                return Err((
                    format!("{field}.id"),
                    format!("{} is not a tag36h11 code (0..{})", tag.id, codes - 1),
                ));
            }
            if !tag.center.iter().all(|c| c.is_finite()) {
                return Err((format!("{field}.center"), "must be finite".into()));
            }
            let clear_x = tag.center[0].abs() - half >= self.window.width / 2.0;
            let clear_y = tag.center[1].abs() - half >= self.window.height / 2.0;
            if !(clear_x || clear_y) {
                return Err((
                    format!("{field}.center"),
                    "the tag overlaps the sample window".into(),
                ));
            }
            for (j, other) in self.tags[..i].iter().enumerate() {
                if other.id == tag.id {
                    return Err((
                        format!("{field}.id"),
                        format!("id {} is also tag[{j}]'s", tag.id),
                    ));
                }
                let apart = (0..2).any(|a| (other.center[a] - tag.center[a]).abs() >= 2.0 * half);
                if !apart {
                    return Err((format!("{field}.center"), format!("overlaps tag[{j}]")));
                }
            }
        }
        Ok(())
    }

    /// Side of a printed tag including its white quiet zone.
    pub fn outer_size(&self) -> f64 {
        self.tag_size * tags::TOTAL_MODULES as f64 / tags::BLACK_MODULES as f64
    }

    /// The placement of tag `id`, if the board has it.
    pub fn tag(&self, id: u16) -> Option<&TagPlacement> {
        self.tags.iter().find(|t| t.id == id)
    }

    /// The corners of tag `id`'s black square in the board frame, in the detector's order
    /// ([`detect::TagCorners`]): the tag's own top-left, top-right, bottom-right, bottom-left.
    pub fn corners(&self, id: u16) -> Option<[[f64; 2]; 4]> {
        let [x, y] = self.tag(id)?.center;
        let h = self.tag_size / 2.0;
        Some([
            [x - h, y + h],
            [x + h, y + h],
            [x + h, y - h],
            [x - h, y - h],
        ])
    }

    /// The printed extent `[x_min, x_max, y_min, y_max]`: every tag's quiet zone and the window.
    pub fn extent(&self) -> [f64; 4] {
        let half = self.outer_size() / 2.0;
        let mut e = [
            -self.window.width / 2.0,
            self.window.width / 2.0,
            -self.window.height / 2.0,
            self.window.height / 2.0,
        ];
        for t in &self.tags {
            e[0] = e[0].min(t.center[0] - half);
            e[1] = e[1].max(t.center[0] + half);
            e[2] = e[2].min(t.center[1] - half);
            e[3] = e[3].max(t.center[1] + half);
        }
        e
    }

    /// Points of the white paper, a module apart, that lie at least one module (1/8 of a tag's
    /// black square) from any black module, from the window and from the printed extent's
    /// edge: where a photo reads the paper alone, whatever its blur.
    pub fn paper_points(&self) -> Vec<[f64; 2]> {
        let module = self.tag_size / tags::BLACK_MODULES as f64;
        let [x0, x1, y0, y1] = self.extent();
        let (nx, ny) = (((x1 - x0) / module) as usize, ((y1 - y0) / module) as usize);
        let white = |x: f64, y: f64| {
            x >= x0 && x <= x1 && y >= y0 && y <= y1 && self.is_black(x, y) == Some(false)
        };
        (0..=ny)
            .flat_map(|j| (0..=nx).map(move |i| [x0 + i as f64 * module, y0 + j as f64 * module]))
            .filter(|&[x, y]| {
                (-1..=1).all(|dj| {
                    (-1..=1).all(|di| white(x + di as f64 * module, y + dj as f64 * module))
                })
            })
            .collect()
    }

    /// Printed reflectance at board point `(x, y)`: `Some(true)` on a black module, `Some(false)`
    /// on white paper (quiet zones and the paper between tags), `None` inside the window.
    pub fn is_black(&self, x: f64, y: f64) -> Option<bool> {
        if x.abs() < self.window.width / 2.0 && y.abs() < self.window.height / 2.0 {
            return None;
        }
        let module = self.tag_size / tags::BLACK_MODULES as f64;
        let half = self.outer_size() / 2.0;
        for t in &self.tags {
            let (u, v) = (x - (t.center[0] - half), (t.center[1] + half) - y);
            if u >= 0.0 && v >= 0.0 && u < 2.0 * half && v < 2.0 * half {
                let (col, row) = ((u / module) as usize, (v / module) as usize);
                return Some(tags::is_black(self.family, t.id, row, col));
            }
        }
        Some(false)
    }
}

#[cfg(test)]
mod tests;
