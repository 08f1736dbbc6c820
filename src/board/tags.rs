//! Module patterns of the printed tags, from the detector crate's own code tables, so that what
//! `bouncefit board` prints is exactly what `kornia-apriltag` decodes.
//!
//! A tag36h11 tag is a 10 x 10 grid of modules: a one-module white quiet zone, a one-module black
//! border and a 6 x 6 data area. Data bit `i` of code `c` (most significant first) is white when
//! set and sits at module `(bit_y[i] + 1, bit_x[i] + 1)` (row, column; row 0 at the top), as in
//! the AprilTag reference implementation's `apriltag_to_image` (Olson 2011; Wang & Olson 2016).

use super::TagFamilyName;
use kornia_apriltag::family::TagFamily;
use std::sync::OnceLock;

/// Modules across a printed tag, quiet zone included.
pub const TOTAL_MODULES: usize = 10;
/// Modules across the black square (border and data): the detector's corners are its corners.
pub const BLACK_MODULES: usize = 8;

fn tag36h11() -> &'static TagFamily {
    static FAMILY: OnceLock<TagFamily> = OnceLock::new();
    FAMILY.get_or_init(|| TagFamily::tag36_h11().expect("the crate's tag36h11 table is valid"))
}

/// How many codes the family has (valid ids are `0..code_count`).
pub fn code_count(family: TagFamilyName) -> usize {
    match family {
        TagFamilyName::Tag36h11 => tag36h11().code_data.len(),
    }
}

/// Whether module `(row, col)` of the printed tag `id` is black (`row`, `col` in
/// `0..TOTAL_MODULES`, row 0 at the tag's top).
pub fn is_black(family: TagFamilyName, id: u16, row: usize, col: usize) -> bool {
    let fam = match family {
        TagFamilyName::Tag36h11 => tag36h11(),
    };
    let last = TOTAL_MODULES - 1;
    if row == 0 || col == 0 || row == last || col == last {
        return false; // quiet zone
    }
    let code = fam.code_data[usize::from(id)] as u64;
    let bits = fam.nbits;
    for i in 0..bits {
        let (x, y) = (fam.bit_x[i] as usize + 1, fam.bit_y[i] as usize + 1);
        if (x, y) == (col, row) {
            return code & (1u64 << (bits - i - 1)) == 0;
        }
    }
    true // black border
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_data_module_is_one_bit_and_the_border_is_black() {
        let fam = tag36h11();
        let mut seen = [[0; TOTAL_MODULES]; TOTAL_MODULES];
        for i in 0..fam.nbits {
            seen[fam.bit_y[i] as usize + 1][fam.bit_x[i] as usize + 1] += 1;
        }
        for (row, counts) in seen.iter().enumerate() {
            for (col, &n) in counts.iter().enumerate() {
                let data = (2..8).contains(&row) && (2..8).contains(&col);
                assert_eq!(n, usize::from(data), "module ({row}, {col})");
                if !data && (1..9).contains(&row) && (1..9).contains(&col) {
                    assert!(is_black(TagFamilyName::Tag36h11, 7, row, col));
                }
            }
        }
    }
}
