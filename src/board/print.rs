//! A printable image of a board: PNG at a stated resolution (dots per inch) or SVG in the
//! board's units, white paper, black modules, and a thin grey outline of the sample window.

use super::Board;
use crate::capture::atomic_file::write_atomically;
use crate::error::{Error, Result};
use std::io::Write;
use std::path::Path;

/// Centimetres per inch.
const CM_PER_INCH: f64 = 2.54;

/// Margin of white paper around the printed extent, in tag quiet-zone widths.
const MARGIN_MODULES: f64 = 2.0;

fn unit_in_cm(board: &Board) -> Result<f64> {
    match board.units.as_str() {
        "cm" => Ok(1.0),
        "mm" => Ok(0.1),
        "m" => Ok(100.0),
        "in" => Ok(CM_PER_INCH),
        other => Err(Error::argument(
            "units",
            format!("unknown unit '{other}' (cm, mm, m or in)"),
        )),
    }
}

/// The page rectangle `[x_min, x_max, y_min, y_max]` in board units: the extent plus a margin.
fn page(board: &Board) -> [f64; 4] {
    let m = MARGIN_MODULES * board.tag_size / super::tags::BLACK_MODULES as f64;
    let e = board.extent();
    [e[0] - m, e[1] + m, e[2] - m, e[3] + m]
}

/// Grey value (0 black, 255 white) of the board at `(x, y)`; the window outline is mid grey.
fn shade(board: &Board, x: f64, y: f64, line: f64) -> u8 {
    match board.is_black(x, y) {
        Some(true) => 0,
        Some(false) => 255,
        None => {
            let (hx, hy) = (board.window.width / 2.0, board.window.height / 2.0);
            if hx - x.abs() < line || hy - y.abs() < line {
                128
            } else {
                255
            }
        }
    }
}

/// Rasterises the board at `dpi` dots per inch: `(width, height, grey pixels row-major)`.
pub fn raster(board: &Board, dpi: f64) -> Result<(u32, u32, Vec<u8>)> {
    let units_per_dot = CM_PER_INCH / dpi / unit_in_cm(board)?;
    let p = page(board);
    let (w, h) = (
        ((p[1] - p[0]) / units_per_dot).ceil() as u32,
        ((p[3] - p[2]) / units_per_dot).ceil() as u32,
    );
    if !(1..=30_000).contains(&w) || !(1..=30_000).contains(&h) {
        return Err(Error::argument(
            "--dpi",
            format!("gives a {w} x {h} image; choose another"),
        ));
    }
    let line = units_per_dot;
    let mut pixels = Vec::with_capacity((w * h) as usize);
    for r in 0..h {
        for c in 0..w {
            let x = p[0] + (c as f64 + 0.5) * units_per_dot;
            let y = p[3] - (r as f64 + 0.5) * units_per_dot;
            pixels.push(shade(board, x, y, line));
        }
    }
    Ok((w, h, pixels))
}

/// Writes the board as a greyscale PNG at `dpi`, atomically.
pub fn write_png(board: &Board, dpi: f64, path: &Path) -> Result<()> {
    let (w, h, pixels) = raster(board, dpi)?;
    let image = image::GrayImage::from_raw(w, h, pixels).expect("raster size matches");
    write_atomically(path, |out| {
        image::DynamicImage::ImageLuma8(image)
            .write_to(out, image::ImageFormat::Png)
            .map_err(|e| Error::io(path, e))
    })
}

/// Writes the board as SVG in its own units (so it prints at true size), atomically.
pub fn write_svg(board: &Board, path: &Path) -> Result<()> {
    let p = page(board);
    let (w, h) = (p[1] - p[0], p[3] - p[2]);
    let module = board.tag_size / super::tags::BLACK_MODULES as f64;
    let half = board.outer_size() / 2.0;
    let mut svg = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}{u}\" height=\"{h}{u}\" viewBox=\"0 0 {w} {h}\">\n\
         <rect width=\"{w}\" height=\"{h}\" fill=\"white\"/>\n",
        u = board.units
    );
    let to_page = |x: f64, y: f64| (x - p[0], p[3] - y);
    let (wx, wy) = to_page(-board.window.width / 2.0, board.window.height / 2.0);
    svg += &format!(
        "<rect x=\"{wx}\" y=\"{wy}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"grey\" stroke-width=\"{}\"/>\n",
        board.window.width, board.window.height, module / 4.0
    );
    for t in &board.tags {
        let (x0, y0) = to_page(t.center[0] - half, t.center[1] + half);
        for row in 0..super::tags::TOTAL_MODULES {
            for col in 0..super::tags::TOTAL_MODULES {
                if super::tags::is_black(board.family, t.id, row, col) {
                    svg += &format!(
                        "<rect x=\"{}\" y=\"{}\" width=\"{module}\" height=\"{module}\"/>\n",
                        x0 + col as f64 * module,
                        y0 + row as f64 * module
                    );
                }
            }
        }
    }
    svg += "</svg>\n";
    write_atomically(path, |out| {
        out.write_all(svg.as_bytes())
            .map_err(|e| Error::io(path, e))
    })
}
