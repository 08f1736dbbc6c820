//! What the zoos (`tests/fit_zoo.rs`, `tests/maps_zoo.rs`) share: a seeded generator, a few
//! vector helpers, measured conductors, the lights a case's manifest holds, and reading
//! environment knobs and photos.

use std::path::{Path, PathBuf};

/// Measured complex IOR (eta, k) at 650, 550 and 450 nm (R, G, B), from
/// ../shared/data/conductors_nk.json: refractiveindex.info's tables of Johnson & Christy,
/// Phys. Rev. B 6, 4370 (1972) for Cu and Au and Phys. Rev. B 9, 5056 (1974) for Ni and Cr, and
/// of Rakic, Appl. Opt. 34, 4755 (1995) for Al. Copied here so the test does not need the file.
pub const CONDUCTORS: [(&str, [f64; 3], [f64; 3]); 5] = [
    ("Cu", [0.2378, 1.0066, 1.2404], [3.6264, 2.5823, 2.3929]),
    ("Au", [0.1556, 0.4241, 1.3831], [3.6024, 2.4721, 1.9155]),
    ("Al", [1.5580, 1.0152, 0.6332], [7.7124, 6.6273, 5.4544]),
    ("Ni", [1.9900, 1.9212, 1.7290], [4.2086, 3.6158, 2.9435]),
    ("Cr", [3.1071, 3.1812, 2.3230], [3.3314, 3.3291, 3.1350]),
];

/// splitmix64 (Steele, Lea & Flood 2014): a tiny, well-mixed generator, enough to draw cases.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xF17_200)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    pub fn log_range(&mut self, lo: f64, hi: f64) -> f64 {
        (lo.ln() + (hi.ln() - lo.ln()) * self.unit()).exp()
    }

    /// Uniform in lo..=hi.
    pub fn int(&mut self, lo: usize, hi: usize) -> usize {
        lo + (self.next_u64() % (hi - lo + 1) as u64) as usize
    }

    pub fn chance(&mut self, p: f64) -> bool {
        self.unit() < p
    }
}

pub type V3 = [f64; 3];

pub fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub fn length(a: V3) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

pub fn normalize(a: V3) -> V3 {
    let l = length(a);
    [a[0] / l, a[1] / l, a[2] / l]
}

/// A point `distance` from the origin, `tilt_deg` off the normal (+z), at azimuth `azimuth`.
pub fn spherical(tilt_deg: f64, azimuth: f64, distance: f64) -> V3 {
    let t = tilt_deg.to_radians();
    [
        distance * t.sin() * azimuth.cos(),
        distance * t.sin() * azimuth.sin(),
        distance * t.cos(),
    ]
}

pub fn toml_v3(v: V3) -> String {
    format!("[{:.4}, {:.4}, {:.4}]", v[0], v[1], v[2])
}

/// The light of one photo of a case, written into its manifest by [`Light::toml`].
#[derive(Clone, Copy)]
pub enum Light {
    Point { position: V3, intensity: f64 },
    Flash { intensity: f64 },
    Directional { direction: V3, irradiance: f64 },
}

impl Light {
    /// The same light `s` times as bright.
    pub fn scaled(self, s: f64) -> Light {
        match self {
            Light::Point {
                position,
                intensity,
            } => Light::Point {
                position,
                intensity: intensity * s,
            },
            Light::Flash { intensity } => Light::Flash {
                intensity: intensity * s,
            },
            Light::Directional {
                direction,
                irradiance,
            } => Light::Directional {
                direction,
                irradiance: irradiance * s,
            },
        }
    }

    /// The manifest's `light = {...}` value.
    pub fn toml(&self) -> String {
        let rgb = |v: f64| format!("[{v:.6e}, {v:.6e}, {v:.6e}]");
        match self {
            Light::Point {
                position,
                intensity,
            } => format!(
                "{{ kind = \"point\", position = {}, intensity = {} }}",
                toml_v3(*position),
                rgb(*intensity)
            ),
            Light::Flash { intensity } => {
                format!("{{ kind = \"flash\", intensity = {} }}", rgb(*intensity))
            }
            Light::Directional {
                direction,
                irradiance,
            } => format!(
                "{{ kind = \"directional\", direction = {}, irradiance = {} }}",
                toml_v3(*direction),
                rgb(*irradiance)
            ),
        }
    }
}

/// With the environment variable `.2` set to `DIR`, copies a case's folder (manifests, photos,
/// fits) to `DIR/<id>` before its temporary folder goes.
pub struct KeepOnDrop(pub PathBuf, pub u64, pub &'static str);

impl Drop for KeepOnDrop {
    fn drop(&mut self) {
        if let Ok(keep) = std::env::var(self.2) {
            let to = Path::new(&keep).join(self.1.to_string());
            let status = std::process::Command::new("cp")
                .arg("-r")
                .arg(&self.0)
                .arg(&to)
                .status();
            if !status.is_ok_and(|s| s.success()) {
                eprintln!(
                    "{}: could not copy {} to {}",
                    self.2,
                    self.0.display(),
                    to.display()
                );
            }
        }
    }
}

/// The largest channel value of a linear EXR image.
pub fn brightest(path: &Path) -> f64 {
    let image = exr::prelude::read_first_rgba_layer_from_file(
        path,
        |_, _| 0.0f32,
        |peak: &mut f32, _, (r, g, b, _): (f32, f32, f32, f32)| *peak = peak.max(r.max(g).max(b)),
    )
    .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    f64::from(image.layer_data.channel_data.pixels)
}

pub fn env_number(key: &str, default: u64) -> u64 {
    std::env::var(key).map_or(default, |v| {
        v.trim()
            .parse()
            .unwrap_or_else(|_| panic!("{key}={v}: not a non-negative integer"))
    })
}

/// `bouncefit synth` of a case: its material and capture into `set`, with relative noise
/// `noise`, `pixel_samples` sub-samples per pixel and the seed `seed`.
pub fn synth_case(
    (material, capture, set): (&Path, &Path, &Path),
    noise: f64,
    pixel_samples: usize,
    seed: u64,
) -> Result<(), String> {
    let (noise, samples, seed) = (
        noise.to_string(),
        pixel_samples.to_string(),
        seed.to_string(),
    );
    let options = [
        "--noise",
        &noise,
        "--pixel-samples",
        &samples,
        "--seed",
        &seed,
    ];
    super::try_synth(material, capture, set, &options)
}
