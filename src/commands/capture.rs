//! `bouncefit board` (write a printable tag board and its BOARD.toml) and `bouncefit capture`
//! (phone photos of a sample in that board -> a photo set; issue #18, [`crate::board::phone`]).

use super::output::StagedFolder;
use crate::board::phone::{self, FocalSource, PhonePhoto};
use crate::board::{print, Board};
use crate::capture::atomic_file::write_atomically;
use crate::capture::camera::{Camera, Pinhole, Rectified};
use crate::capture::image_io::{write_exr, ColorEncoding};
use crate::capture::light::Light;
use crate::capture::{Capture, Photo, Sample};
use crate::error::{Error, Result};
use glam::DVec3;
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug)]
pub struct BoardArgs {
    /// Output folder: board.toml, board.png (at --dpi) and board.svg (true size).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Sample window WIDTH,HEIGHT in cm.
    #[arg(long, default_value = "10,10", value_parser = parse_pair)]
    pub window: [f64; 2],
    /// Side of a tag's black square, cm.
    #[arg(long, default_value_t = 1.6)]
    pub tag_size: f64,
    /// Gap between tags and between the tags and the window, cm.
    #[arg(long, default_value_t = 0.4)]
    pub gap: f64,
    /// Resolution of board.png, dots per inch.
    #[arg(long, default_value_t = 300.0)]
    pub dpi: f64,
    #[arg(long)]
    pub force: bool,
}

#[derive(clap::Args, Debug)]
pub struct CaptureArgs {
    /// Phone photos (JPEG or PNG, sRGB) of the sample lying in the board's window, flash on.
    #[arg(required = true)]
    pub photos: Vec<PathBuf>,
    /// The board description (`bouncefit board` writes one).
    #[arg(long)]
    pub board: PathBuf,
    /// Output photo-set folder (capture.toml, images, masks, capture-report.json).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Rectified image sizes in pixels (the window's longer side): the first is the photo set
    /// in the output folder, each further one a photo set in a subfolder named by its size
    /// (MaterialGAN's pair by default: OUT/ at 256, OUT/1024/).
    #[arg(long, default_value = "256,1024", value_delimiter = ',', num_args = 1..)]
    pub resolution: Vec<usize>,
    /// Keep the original perspective photos with pinhole cameras instead of rectifying.
    #[arg(long)]
    pub perspective: bool,
    /// Focal length in pixels (overrides EXIF; without either it is estimated from the board).
    #[arg(long)]
    pub focal_px: Option<f64>,
    /// The lens: `calibrated` fits the principal point and radial distortion (k1, k2) over all
    /// photos (from 4 photos; the focal length too unless --focal-px), `pinhole` takes a
    /// pinhole at the image centre. `--perspective` always takes the pinhole.
    #[arg(long, value_enum, default_value = "calibrated")]
    pub lens: phone::Lens,
    /// The lens's vignetting: `calibrated` fits `1 + a r^2 + b r^4` on the board's white paper
    /// over all photos (from 4 photos) and divides it out of them; `none` takes the photos as
    /// they are.
    #[arg(long, value_enum, default_value = "calibrated")]
    pub vignetting: phone::VignettingModel,
    /// The flash's position relative to the lens in the camera frame (x right, y down, z
    /// forward), board units.
    #[arg(long, default_value = "0,0,0", value_parser = parse_triple)]
    pub flash_offset: [f64; 3],
    /// Radiant intensity of the flash (RGB, W/sr in board units, the camera's gain included).
    /// Without it each photo's flash is measured on the board's white paper (of albedo
    /// --paper-albedo): its exposure and white balance with it.
    #[arg(long, value_parser = parse_triple)]
    pub flash_intensity: Option<[f64; 3]>,
    /// Albedo of the board's white paper (office paper 0.8-0.9), the reference that puts the
    /// fitted albedos on an absolute scale when the flash is measured on it.
    #[arg(long, default_value_t = 0.8)]
    pub paper_albedo: f64,
    #[arg(long)]
    pub force: bool,
}

fn parse_numbers<const N: usize>(text: &str) -> std::result::Result<[f64; N], String> {
    let values: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>().map_err(|e| format!("'{v}': {e}")))
        .collect::<std::result::Result<_, _>>()?;
    let values: [f64; N] = values
        .try_into()
        .map_err(|_| format!("expected {N} comma-separated numbers, got '{text}'"))?;
    if values.iter().all(|v| v.is_finite()) {
        Ok(values)
    } else {
        Err(format!("'{text}' has a number that is not finite"))
    }
}

pub(super) fn parse_pair(text: &str) -> std::result::Result<[f64; 2], String> {
    parse_numbers(text)
}

fn parse_triple(text: &str) -> std::result::Result<[f64; 3], String> {
    parse_numbers(text)
}

pub fn run_board(args: &BoardArgs) -> Result<()> {
    let board = Board::ring(args.window[0], args.window[1], args.tag_size, args.gap);
    board.validate().map_err(|(field, message)| {
        Error::argument(format!("--{}", field.replace('_', "-")), message)
    })?;
    let folder = StagedFolder::new(&args.output, args.force)?;
    let toml_path = folder.path("board.toml");
    write_atomically(&toml_path, |w| {
        std::io::Write::write_all(w, board.to_toml().as_bytes())
            .map_err(|e| Error::io(&toml_path, e))
    })?;
    print::write_png(&board, args.dpi, &folder.path("board.png"))?;
    print::write_svg(&board, &folder.path("board.svg"))?;
    folder.commit()?;
    let e = board.extent();
    eprintln!(
        "wrote a board of {} tags, {:.1} x {:.1} cm printed ({} dpi PNG, true-size SVG), to {}",
        board.tags.len(),
        e[1] - e[0],
        e[3] - e[2],
        args.dpi,
        args.output.display()
    );
    Ok(())
}

/// A mask PNG: 255 where `nonzero`, else 0.
fn write_mask(path: &Path, nonzero: &[bool], width: usize, height: usize) -> Result<()> {
    let bytes = nonzero.iter().map(|&k| if k { 255 } else { 0 }).collect();
    let image = image::GrayImage::from_raw(width as u32, height as u32, bytes).expect("mask size");
    write_atomically(path, |w| {
        image::DynamicImage::ImageLuma8(image)
            .write_to(w, image::ImageFormat::Png)
            .map_err(|e| Error::io(path, e))
    })
}

/// Writes the photo set of the located photos into `dir`: rectified at `longer` pixels along
/// the window's longer side, or the perspective photos.
fn write_photo_set(
    dir: &Path,
    name: &str,
    board: &Board,
    photos: &[PhonePhoto],
    located: &phone::Located3d,
    args: &CaptureArgs,
    longer: usize,
) -> Result<()> {
    let (w, h) = (board.window.width, board.window.height);
    let resolution = if w >= h {
        [longer, ((longer as f64 * h / w).round() as usize).max(1)]
    } else {
        [((longer as f64 * w / h).round() as usize).max(1), longer]
    };
    let k = located.intrinsics;
    let mut capture_photos = Vec::new();
    for found in &located.photos {
        let photo = &photos[found.index];
        let pose = &found.pose;
        let c = pose.center();
        let flash = phone::flash_position(pose, args.flash_offset);
        let light = Light::Point {
            position: DVec3::new(flash.x, flash.y, flash.z),
            intensity: flash_intensity(args, found),
        };
        let stem = format!("{:02}", capture_photos.len());
        let (camera, rgb, keep, saturated, size) = if args.perspective {
            let inverse = pose.rotation.inverse();
            let forward = inverse * nalgebra::Vector3::z();
            let up = -(inverse * nalgebra::Vector3::y());
            let camera = Camera::Pinhole(Pinhole {
                position: DVec3::new(c.x, c.y, c.z),
                look_at: DVec3::new(c.x + forward.x, c.y + forward.y, c.z + forward.z),
                up: DVec3::new(up.x, up.y, up.z),
                fx: k.focal,
                fy: k.focal,
                cx: k.cx,
                cy: k.cy,
                resolution: [photo.width, photo.height],
            });
            (
                camera,
                photo.linear.clone(),
                vec![true; photo.width * photo.height],
                photo.clipped.clone(),
                [photo.width, photo.height],
            )
        } else {
            // Enough reads per output pixel to average every photo pixel it covers.
            let corners = [
                [-w / 2.0, h / 2.0],
                [w / 2.0, h / 2.0],
                [w / 2.0, -h / 2.0],
                [-w / 2.0, -h / 2.0],
            ];
            let q: Vec<[f64; 2]> = corners
                .iter()
                .filter_map(|&p| pose.project(&k, p))
                .collect();
            let span = q
                .iter()
                .zip(q.iter().cycle().skip(1))
                .map(|(a, b)| (a[0] - b[0]).hypot(a[1] - b[1]))
                .fold(0.0, f64::max);
            let ss = ((span / resolution[0] as f64).ceil() as usize).clamp(2, 16);
            let rectified = phone::rectify(board, photo, &k, pose, resolution, ss);
            let camera = Camera::Rectified(Rectified {
                position: DVec3::new(c.x, c.y, c.z),
                resolution,
            });
            (
                camera,
                rectified.rgb,
                rectified.keep,
                rectified.saturated,
                resolution,
            )
        };
        write_exr(&dir.join(format!("{stem}.exr")), &rgb, size[0], size[1])?;
        let mask = if args.perspective {
            // Pixels that do not see the sample window are outside the sample anyway; a mask
            // is only needed where the photo itself ends.
            None
        } else if keep.iter().all(|&k| k) {
            None
        } else {
            write_mask(
                &dir.join(format!("{stem}_mask.png")),
                &keep,
                size[0],
                size[1],
            )?;
            Some(PathBuf::from(format!("{stem}_mask.png")))
        };
        // Clipped photo pixels carry no radiance: the fit leaves them out (nonzero = saturated).
        let saturated_mask = if saturated.iter().any(|&s| s) {
            let name = format!("{stem}_saturated_mask.png");
            write_mask(&dir.join(&name), &saturated, size[0], size[1])?;
            Some(PathBuf::from(name))
        } else {
            None
        };
        capture_photos.push(Photo {
            image: PathBuf::from(format!("{stem}.exr")),
            camera,
            light,
            exposure: 1.0,
            weight: 1.0,
            mask,
            saturated_mask,
            color: ColorEncoding::Linear,
            pixels: None,
        });
    }
    let capture = Capture {
        name: name.to_owned(),
        units: board.units.clone(),
        root: dir.to_path_buf(),
        sample: Sample {
            width: w,
            height: h,
        },
        color: None,
        depth: 0.0,
        photos: capture_photos,
        warnings: Vec::new(),
    };
    capture.save_manifest(&dir.join("capture.toml"))
}

/// The flash of a located photo: `--flash-intensity`, else as its paper shows it.
fn flash_intensity(args: &CaptureArgs, found: &phone::Located) -> [f64; 3] {
    args.flash_intensity.unwrap_or_else(|| {
        found
            .paper
            .intensity_times_albedo
            .map(|i| i / args.paper_albedo)
    })
}

/// `capture-report.json`: the camera found and what happened to every photo.
fn capture_report(located: &phone::Located3d, args: &CaptureArgs) -> serde_json::Value {
    let k = located.intrinsics;
    serde_json::json!({
        "focal_px": k.focal,
        "focal_source": match located.focal_source { FocalSource::Given => "given", FocalSource::Exif => "exif", FocalSource::Board => "board" },
        "principal_point": [k.cx, k.cy],
        "distortion": k.distortion,
        "vignetting": located.vignetting,
        "print": located.print,
        "photos": located.reports,
        "sources": args.photos,
    })
}

/// Where a refused run's report goes: `OUT.capture-report.json` beside the output folder.
fn refused_report_path(output: &Path) -> PathBuf {
    let mut name = output
        .file_name()
        .map(|n| n.to_os_string())
        .unwrap_or_else(|| "capture".into());
    name.push(".capture-report.json");
    output.with_file_name(name)
}

fn write_report(path: &Path, report: &serde_json::Value) -> Result<()> {
    write_atomically(path, |wr| {
        serde_json::to_writer_pretty(&mut *wr, report).map_err(|e| Error::io(path, e))
    })
}

pub fn run_capture(args: &CaptureArgs) -> Result<()> {
    let board = Board::load(&args.board)?;
    if let Some(n) = args.resolution.iter().find(|n| !(8..=8192).contains(*n)) {
        return Err(Error::argument(
            "--resolution",
            format!("must be 8 to 8192, got {n}"),
        ));
    }
    if args.resolution.is_empty() {
        return Err(Error::argument("--resolution", "give at least one size"));
    }
    if !(args.paper_albedo > 0.0 && args.paper_albedo <= 1.0) {
        return Err(Error::argument(
            "--paper-albedo",
            format!("must be in (0, 1], got {}", args.paper_albedo),
        ));
    }
    if let Some(f) = args.focal_px.filter(|f| !(f.is_finite() && *f > 0.0)) {
        return Err(Error::argument(
            "--focal-px",
            format!("must be a positive length, got {f}"),
        ));
    }
    let mut photos: Vec<PhonePhoto> = args
        .photos
        .iter()
        .map(|p| PhonePhoto::read(p))
        .collect::<Result<_>>()?;
    if let Some(p) = photos
        .iter()
        .find(|p| (p.width, p.height) != (photos[0].width, photos[0].height))
    {
        return Err(Error::invalid(
            &args.photos[photos.iter().position(|q| std::ptr::eq(q, p)).unwrap()],
            "size",
            format!(
                "{}x{}, but the first photo is {}x{}: one phone, one resolution",
                p.width, p.height, photos[0].width, photos[0].height
            ),
        ));
    }
    // A perspective set keeps the photos as they are, which a pinhole camera must then describe.
    let lens = if args.perspective {
        phone::Lens::Pinhole
    } else {
        args.lens
    };
    let located = phone::locate(
        &board,
        &mut photos,
        phone::LocateOptions {
            focal_px: args.focal_px,
            flash_offset: args.flash_offset,
            lens,
            vignetting: args.vignetting,
        },
    );
    let print = located.print;
    if print.tag_quarter_turns != 0 {
        eprintln!(
            "the tags are printed turned by {} degrees clockwise against {} (OpenCV's \
             generateImageMarker turns them by 180): read as printed",
            90 * print.tag_quarter_turns,
            args.board.display()
        );
    }
    // Small tags (20 px) read about 1% small by the detector alone; a print off by more shows.
    if (print.tag_scale - 1.0).abs() > 0.01 {
        eprintln!(
            "the tags' black squares measure {:.3} of the tag_size in {}: used as measured",
            print.tag_scale,
            args.board.display()
        );
    }
    for r in &located.reports {
        match &r.left_out {
            Some(why) => eprintln!("{}: left out: {why}", r.name),
            None => eprintln!(
                "{}: {} tags, reprojection {:.2} px",
                r.name,
                r.tags_found,
                r.rms_px.unwrap_or(f64::NAN)
            ),
        }
    }
    let mut located = located;
    for found in &located.photos {
        located.reports[found.index].flash_intensity = Some(flash_intensity(args, found));
    }
    let report = capture_report(&located, args);
    // A refused run writes no photo set, only its report beside the output folder, so that the
    // tags, poses and reasons can be looked at; a later run that succeeds removes it.
    let refused_report = refused_report_path(&args.output);
    if located.photos.len() < phone::MIN_PHOTOS {
        write_report(&refused_report, &report)?;
        return Err(Error::argument(
            "photos",
            format!(
                "{} of {} photos usable, {} needed (see the reasons above; the capture report \
                 is {})",
                located.photos.len(),
                photos.len(),
                phone::MIN_PHOTOS,
                refused_report.display()
            ),
        ));
    }
    let folder = StagedFolder::new(&args.output, args.force)?;
    let name = args
        .output
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "capture".into());
    let sizes: &[usize] = if args.perspective {
        &args.resolution[..1]
    } else {
        &args.resolution
    };
    for (i, &longer) in sizes.iter().enumerate() {
        let dir = if i == 0 {
            folder.path("")
        } else {
            folder.path(&longer.to_string())
        };
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&args.output, e))?;
        write_photo_set(&dir, &name, &board, &photos, &located, args, longer)?;
    }
    write_report(&folder.path("capture-report.json"), &report)?;
    folder.commit()?;
    if refused_report.exists() {
        std::fs::remove_file(&refused_report).map_err(|e| Error::io(&refused_report, e))?;
    }
    let k = located.intrinsics;
    eprintln!(
        "wrote {} of {} photos ({}) to {}; focal {:.1} px ({:?})",
        located.photos.len(),
        photos.len(),
        if args.perspective {
            "perspective".to_string()
        } else {
            format!("rectified at {:?} px", sizes)
        },
        args.output.display(),
        k.focal,
        located.focal_source
    );
    Ok(())
}
