//! Value checks shared by the manifest reader and the importers. Each returns the message for
//! the user; the caller attaches the file and the field path (`Error::invalid`).

use glam::DVec3;

/// A length, angle or factor that must be finite and strictly positive.
pub(crate) fn positive(value: f64) -> Result<f64, String> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(format!("must be finite and positive, got {value}"))
    }
}

/// A length or offset that must be finite and zero or positive.
pub(crate) fn non_negative(value: f64) -> Result<f64, String> {
    if value.is_finite() && value >= 0.0 {
        Ok(value)
    } else {
        Err(format!("must be finite and zero or positive, got {value}"))
    }
}

/// A vector whose components must all be finite.
pub(crate) fn finite(v: [f64; 3]) -> Result<DVec3, String> {
    if v.iter().all(|c| c.is_finite()) {
        Ok(DVec3::from_array(v))
    } else {
        Err(format!("components must be finite, got {v:?}"))
    }
}

/// A camera or light position: finite and strictly above the sample plane z = 0 (the sample
/// is lit and seen from its +z side, PHYSICS.md "Conventions").
pub(crate) fn above_sample_plane(v: [f64; 3]) -> Result<DVec3, String> {
    let p = finite(v)?;
    if p.z > 0.0 {
        Ok(p)
    } else {
        Err(format!(
            "must be above the sample plane (z > 0), got z = {}",
            p.z
        ))
    }
}

/// An RGB light power (intensity or irradiance): finite, non-negative, not all zero.
pub(crate) fn light_power(rgb: [f64; 3]) -> Result<[f64; 3], String> {
    if rgb.iter().any(|c| !c.is_finite() || *c < 0.0) {
        Err(format!(
            "must be finite and non-negative per channel, got {rgb:?}"
        ))
    } else if rgb.iter().all(|c| *c == 0.0) {
        Err("is zero in every channel: the photo would be black".to_string())
    } else {
        Ok(rgb)
    }
}

/// An image resolution `[width, height]` in pixels, both positive.
pub(crate) fn resolution(r: [usize; 2]) -> Result<[usize; 2], String> {
    if r[0] > 0 && r[1] > 0 {
        Ok(r)
    } else {
        Err(format!("must be positive, got {r:?}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accept_good_values_and_reject_bad_ones() {
        assert_eq!(positive(2.0), Ok(2.0));
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(positive(bad).is_err(), "{bad}");
        }
        assert_eq!(
            above_sample_plane([1.0, 2.0, 3.0]),
            Ok(DVec3::new(1.0, 2.0, 3.0))
        );
        assert!(above_sample_plane([1.0, 2.0, 0.0]).is_err());
        assert!(above_sample_plane([1.0, 2.0, -3.0]).is_err());
        assert!(above_sample_plane([f64::NAN, 2.0, 3.0]).is_err());
        assert_eq!(light_power([0.0, 1.0, 0.0]), Ok([0.0, 1.0, 0.0]));
        assert!(light_power([0.0, 0.0, 0.0]).unwrap_err().contains("zero"));
        assert!(light_power([1.0, -1.0, 1.0])
            .unwrap_err()
            .contains("non-negative"));
        assert!(light_power([1.0, f64::INFINITY, 1.0]).is_err());
        assert_eq!(resolution([3, 4]), Ok([3, 4]));
        assert!(resolution([0, 4]).is_err() && resolution([4, 0]).is_err());
    }
}
