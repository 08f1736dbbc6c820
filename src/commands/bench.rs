//! `bouncefit bench`: the measurements of [`crate::bench`] as tables (or, with `--json`,
//! `{"estimators": [...], "jobs": [...], ...}`), and with `-o DIR` a folder holding
//! `bench.json`, `bench.txt` (the tables) and `bench.png` (error against run time).
//!
//! | run | converged values | render job | relight jobs | fit jobs | maps fit jobs |
//! | --- | --- | --- | --- | --- | --- |
//! | full | 100000 samples | 9 photos at 256x256, repeated for 1 s | each of `--relight-models`: a 512x512 sphere under the bundled sky, 64 samples per pixel | each set of `--fit-sets` at full resolution, every model | each set of `--maps-sets`, each of `--maps-models`, texels 64 and the photos' width, up to 4 bases |
//! | `--quick` | 4096 samples | 9 photos at 128x128, once | the same at 128x128, 16 samples per pixel | each set halved 4 times, every model | `single` and `kulla-conty` at texels 32 only, up to 2 bases |
//!
//! The fit jobs use the options of `fit` (the same flags, e.g. `--pixel-samples`,
//! `--max-iters`), and `--seed` seeds everything.

use super::fit_args::{CoarseToFine, FitOptionArgs, MapsArgs};
use super::inputs::print_warning;
use super::output::StagedFolder;
use crate::bench::cpu_time::process_seconds;
use crate::bench::estimators::{self, EstimatorRow, EstimatorSettings, ALPHA_RANGE};
use crate::bench::jobs::{self, JobRow, RenderTiming};
use crate::bench::kernel::{self, KernelRow};
use crate::bench::memory;
use crate::bench::plot::error_against_time;
use crate::bsdf::Model;
use crate::capture::atomic_file::write_atomically;
use crate::error::{Error, Result};
use crate::fit::point::params::FresnelFamily;
use crate::fit::FitOptions;
use crate::maps::fit::check_model;
use crate::maps::pipeline::MapsSet;
use crate::maps::TexelGrid;
use crate::material::Material;
use crate::progress::{Progress, Reporting};
use crate::render::plan::Skips;
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    /// Models to measure (comma-separated); all by default. `heitz` is measured in the
    /// estimator table whatever this says: it is the reference.
    #[arg(long, value_delimiter = ',')]
    pub models: Option<Vec<Model>>,
    /// A reduced run (see the table of `bouncefit::commands::bench`) in under a minute.
    #[arg(long)]
    pub quick: bool,
    /// Configurations of the estimator table.
    #[arg(long, default_value_t = 256, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=65536))]
    pub configs: usize,
    /// Evaluations behind each converged value (default 100000; with --quick 4096).
    #[arg(long, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(16..=100_000_000))]
    pub reference_samples: Option<usize>,
    /// Only the estimator table: no render or fit job.
    #[arg(long)]
    pub no_jobs: bool,
    /// Capture template of the render job.
    #[arg(long, default_value = "datasets/sources/copper-flash.capture.toml")]
    pub render_capture: PathBuf,
    /// Material of the render job (rendered under each model).
    #[arg(long, default_value = "datasets/sources/copper-a03.material.json")]
    pub render_material: PathBuf,
    /// Side of the render job's square photos (default 256; with --quick 128).
    #[arg(long, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=4096))]
    pub render_resolution: Option<usize>,
    /// Models of the relight jobs (the render job's material on a sphere under the bundled
    /// sky); `single` is their baseline.
    #[arg(long, value_delimiter = ',', default_value = "single,kulla-conty")]
    pub relight_models: Vec<Model>,
    /// Side of the relight jobs' square images (default 512; with --quick 128).
    #[arg(long, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=4096))]
    pub relight_size: Option<usize>,
    /// Samples per pixel of the relight jobs (default 64; with --quick 16).
    #[arg(long, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=4096))]
    pub relight_spp: Option<usize>,
    /// Photo sets of the fit jobs (comma-separated), each `PATH` or `PATH:conductor` /
    /// `PATH:schlick` to fit that Fresnel family there (otherwise `--fresnel`'s); a set's
    /// `material.json`, if any, gives the true roughness. By default the rectified flash set and
    /// the pinhole point-light set with conductor Fresnel.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "datasets/copper-flash,datasets/aluminium-pinhole:conductor"
    )]
    pub fit_sets: Vec<FitSet>,
    /// Halve the fit set's resolution this many times first (default 0; with --quick 4).
    #[arg(long, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(0..=8))]
    pub fit_halvings: Option<usize>,
    /// Photo sets of the maps fit jobs (comma-separated); the last photo of each is held out.
    #[arg(long, value_delimiter = ',', default_value = "datasets/two-materials")]
    pub maps_sets: Vec<PathBuf>,
    /// Models of the maps fit jobs (analytic models only; default single,kulla-conty,tabulated;
    /// with --quick single,kulla-conty: tabulated's fit costs about three of single's).
    #[arg(long, value_delimiter = ',')]
    pub maps_models: Option<Vec<Model>>,
    /// Texel grids of the maps fit jobs: square sides, or `full` for the photos' width
    /// (default 64,full; with --quick 32).
    #[arg(long, value_delimiter = ',')]
    pub maps_texels: Option<Vec<TexelSide>>,
    /// No maps fit jobs.
    #[arg(long)]
    pub no_maps: bool,
    #[command(flatten)]
    pub fit: FitOptionArgs,
    /// Print `{"estimators": [...], "jobs": [...], "notes": [...], ...}` instead of tables.
    #[arg(long)]
    pub json: bool,
    /// Folder to write bench.json, bench.txt and bench.png into.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Replace a non-empty output folder.
    #[arg(long)]
    pub force: bool,
    /// No progress display.
    #[arg(long)]
    pub quiet: bool,
}

/// What the run measures, after `--quick` and the defaults are applied.
#[derive(Clone, Debug, Serialize)]
struct Settings {
    quick: bool,
    models: Vec<Model>,
    estimators: EstimatorSettings,
    render: Option<RenderSettings>,
    relight: Option<RelightSettings>,
    fit: Option<FitSettings>,
    maps: Option<MapsSettings>,
}

#[derive(Clone, Debug, Serialize)]
struct RenderSettings {
    capture: PathBuf,
    material: PathBuf,
    resolution: usize,
    min_seconds: f64,
}

#[derive(Clone, Debug, Serialize)]
struct RelightSettings {
    models: Vec<Model>,
    size: usize,
    samples: usize,
}

/// A photo set of the fit jobs and the Fresnel family fitted there (`None`: `--fresnel`'s).
#[derive(Clone, Debug, Serialize)]
pub struct FitSet {
    pub path: PathBuf,
    pub fresnel: Option<FresnelFamily>,
}

impl std::str::FromStr for FitSet {
    type Err = String;
    fn from_str(text: &str) -> std::result::Result<Self, String> {
        let (path, fresnel) = match text.rsplit_once(':') {
            Some((path, family)) => {
                let family = <FresnelFamily as clap::ValueEnum>::from_str(family, true)
                    .map_err(|_| format!("unknown Fresnel family {family:?} after ':' in {text:?} (schlick or conductor)"))?;
                (path, Some(family))
            }
            None => (text, None),
        };
        Ok(FitSet {
            path: PathBuf::from(path),
            fresnel,
        })
    }
}

/// A texel grid side of the maps fit jobs: a number of texels, or the photos' width.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum TexelSide {
    Texels(usize),
    Full,
}

impl std::str::FromStr for TexelSide {
    type Err = String;
    fn from_str(text: &str) -> std::result::Result<Self, String> {
        if text == "full" {
            return Ok(TexelSide::Full);
        }
        match text.parse::<usize>() {
            Ok(n) if (1..=8192).contains(&n) => Ok(TexelSide::Texels(n)),
            _ => Err(format!(
                "`{text}` is neither a texel count from 1 to 8192 nor `full`"
            )),
        }
    }
}

#[derive(Clone, Debug, Serialize)]
struct MapsSettings {
    sets: Vec<PathBuf>,
    models: Vec<Model>,
    texels: Vec<TexelSide>,
    max_bases: usize,
}

#[derive(Clone, Debug, Serialize)]
struct FitSettings {
    sets: Vec<FitSet>,
    halvings: usize,
    pixel_samples: usize,
    max_iters: u64,
}

/// The `--json` document and `bench.json`.
#[derive(Serialize)]
struct BenchReport {
    estimators: Vec<EstimatorRow>,
    /// `single` by the scalar and the batch kernel on the same pairs (`bench::kernel`).
    kernel: KernelRow,
    jobs: Vec<JobRow>,
    settings: Settings,
    notes: Vec<String>,
    wall_seconds: f64,
    /// CPU seconds of the process, all threads (the machine may be shared).
    cpu_seconds: f64,
}

impl BenchArgs {
    fn settings(&self) -> Settings {
        let models = self.models.clone().unwrap_or_else(|| Model::ALL.to_vec());
        let quick = self.quick;
        Settings {
            quick,
            models,
            estimators: EstimatorSettings {
                configurations: self.configs,
                reference_samples: self.reference_samples.unwrap_or(if quick {
                    4096
                } else {
                    100_000
                }),
                timing_seconds: if quick { 0.05 } else { 0.5 },
                seed: self.fit.seed,
            },
            render: (!self.no_jobs).then(|| RenderSettings {
                capture: self.render_capture.clone(),
                material: self.render_material.clone(),
                resolution: self
                    .render_resolution
                    .unwrap_or(if quick { 128 } else { 256 }),
                min_seconds: if quick { 0.0 } else { 1.0 },
            }),
            relight: (!self.no_jobs).then(|| RelightSettings {
                models: self.relight_models.clone(),
                size: self.relight_size.unwrap_or(if quick { 128 } else { 512 }),
                samples: self.relight_spp.unwrap_or(if quick { 16 } else { 64 }),
            }),
            fit: (!self.no_jobs).then(|| FitSettings {
                sets: self.fit_sets.clone(),
                halvings: self.fit_halvings.unwrap_or(if quick { 4 } else { 0 }),
                pixel_samples: self.fit.pixel_samples,
                max_iters: self.fit.max_iters,
            }),
            maps: (!self.no_jobs && !self.no_maps).then(|| MapsSettings {
                sets: self.maps_sets.clone(),
                models: self.maps_models.clone().unwrap_or_else(|| {
                    let mut models = vec![Model::Single, Model::KullaConty];
                    if !quick {
                        models.push(Model::Tabulated);
                    }
                    models
                }),
                texels: self.maps_texels.clone().unwrap_or_else(|| {
                    if quick {
                        vec![TexelSide::Texels(32)]
                    } else {
                        vec![TexelSide::Texels(64), TexelSide::Full]
                    }
                }),
                max_bases: if quick { 2 } else { 4 },
            }),
        }
    }
}

/// A shared progress display (none with `--quiet`).
fn progress(quiet: bool, label: &str, total: usize) -> Option<Mutex<Progress>> {
    (!quiet).then(|| Mutex::new(Progress::new(label, total as u64)))
}

fn finish(progress: &Option<Mutex<Progress>>) {
    if let Some(p) = progress {
        p.lock().expect("no panics while holding the lock").finish();
    }
}

pub fn run_bench(args: &BenchArgs) -> Result<()> {
    let (started, cpu) = (Instant::now(), process_seconds());
    let settings = args.settings();
    // Everything that can fail on bad input fails before the long measurements.
    let folder = match &args.output {
        Some(dir) => Some(StagedFolder::new(dir, args.force)?),
        None => None,
    };
    let render_inputs = match &settings.render {
        Some(r) => Some((
            jobs::render_records(&r.capture, [r.resolution; 2])?,
            Material::load(&r.material)?,
        )),
        None => None,
    };
    let fit_inputs = match &settings.fit {
        Some(f) => f
            .sets
            .iter()
            .map(|set| {
                let (records, truth) = jobs::fit_records(&set.path, f.pixel_samples, f.halvings)?;
                Ok((set, records, truth))
            })
            .collect::<Result<Vec<_>>>()?,
        None => Vec::new(),
    };
    let maps_inputs = match &settings.maps {
        Some(m) => {
            for &model in &m.models {
                check_model(model)?;
            }
            m.sets
                .iter()
                .map(|path| maps_set(path, args, m))
                .collect::<Result<Vec<_>>>()?
        }
        None => Vec::new(),
    };

    let units = estimators::work_units(&settings.models, &settings.estimators);
    let bar = progress(args.quiet, "bench estimators", units);
    let estimator_rows = estimators::measure(&settings.models, &settings.estimators, |done, m| {
        if let Some(p) = &bar {
            if let Ok(mut p) = p.try_lock() {
                p.update(done as u64, || m.to_string());
            }
        }
    });
    finish(&bar);
    let kernel_row = kernel::measure(
        settings.estimators.configurations,
        settings.estimators.timing_seconds,
        settings.estimators.seed,
    );

    let mut job_rows = Vec::new();
    if let (Some(r), Some((records, material))) = (&settings.render, &render_inputs) {
        let bar = progress(args.quiet, "bench render", settings.models.len());
        for (i, &model) in settings.models.iter().enumerate() {
            if let Some(p) = &bar {
                p.lock()
                    .expect("no panics")
                    .update(i as u64, || model.to_string());
            }
            let timing = RenderTiming {
                min_seconds: r.min_seconds,
                max_repeats: 20,
            };
            job_rows.extend(jobs::render_jobs(
                records,
                (material, model),
                Skips::except(&args.fit.no_skip),
                timing,
                settings.estimators.seed,
            ));
        }
        finish(&bar);
    }
    if let (Some(r), Some((_, material))) = (&settings.relight, &render_inputs) {
        let first_row = job_rows.len();
        for &model in &r.models {
            if !args.quiet {
                eprintln!("bench: relight {model}");
            }
            job_rows.push(jobs::relight_job(
                (material, model),
                r.size,
                r.samples,
                settings.estimators.seed,
            ));
        }
        jobs::ratios_to_single(&mut job_rows[first_row..]);
    }
    for (set, records, truth) in &fit_inputs {
        let first_row = job_rows.len();
        for &model in &settings.models {
            if !args.quiet {
                let [w, h] = [records.photos[0].width, records.photos[0].height];
                eprintln!(
                    "bench: fit {model} to {} ({} photos of {w}x{h})",
                    set.path.display(),
                    records.photos.len()
                );
            }
            let mut options = args
                .fit
                .fit_options(model, Reporting::terminal_if(!args.quiet));
            if let Some(fresnel) = set.fresnel {
                options.space.fresnel = fresnel;
            }
            for skips in [Skips::none(), options.skips] {
                let options = FitOptions {
                    skips,
                    ..options.clone()
                };
                let mut row = jobs::fit_job(records, truth.as_ref(), &options)?;
                row.set = Some(set.path.display().to_string());
                job_rows.push(row);
            }
        }
        jobs::ratios_to_single(&mut job_rows[first_row..]);
    }
    if let Some(m) = &settings.maps {
        for mut set in maps_inputs {
            let first_row = job_rows.len();
            for &side in &m.texels {
                let width = set.records.photos[0].width;
                let n = match side {
                    TexelSide::Texels(n) => n,
                    TexelSide::Full => width,
                };
                let height = ((n as f64 * set.capture.sample.height / set.capture.sample.width)
                    .round() as usize)
                    .max(1);
                set.grid = TexelGrid { width: n, height };
                for &model in &m.models {
                    if !args.quiet {
                        eprintln!(
                            "bench: maps fit {model} to {} at {n}x{height} texels",
                            set.capture_path.display()
                        );
                    }
                    let peak_measured = memory::reset_peak();
                    let (started, cpu) = (Instant::now(), process_seconds());
                    let run = set.fit(model)?;
                    let seconds = started.elapsed().as_secs_f64();
                    let peak = peak_measured.then(memory::peak_resident_bytes).flatten();
                    let mut row = JobRow::maps_fit(
                        model,
                        &set.records,
                        (set.grid, run.fit.bases.len()),
                        (seconds, process_seconds() - cpu, peak),
                        run.holdout.as_ref(),
                    );
                    row.set = Some(set.capture_path.display().to_string());
                    job_rows.push(row);
                }
            }
            jobs::ratios_to_single(&mut job_rows[first_row..]);
        }
    }

    let report = BenchReport {
        notes: notes(&settings, &estimator_rows, &job_rows),
        estimators: estimator_rows,
        kernel: kernel_row,
        jobs: job_rows,
        settings,
        wall_seconds: started.elapsed().as_secs_f64(),
        cpu_seconds: process_seconds() - cpu,
    };
    let json = serde_json::to_string_pretty(&report)
        .map_err(|e| Error::argument("json", e.to_string()))?;
    let text = tables(&report);
    if let Some(folder) = folder {
        let write_text = |name: &str, content: &str| {
            let path = folder.path(name);
            write_atomically(&path, |w| {
                w.write_all(content.as_bytes())
                    .map_err(|e| Error::io(&path, e))
            })
        };
        write_text("bench.json", &json)?;
        write_text("bench.txt", &text)?;
        error_against_time(&folder.path("bench.png"), &report.estimators)?;
        folder.commit()?;
    }
    if args.json {
        println!("{json}");
    } else {
        print!("{text}");
    }
    Ok(())
}

/// A photo set of the maps fit jobs, its last photo held out, at most `m.max_bases` bases.
fn maps_set(path: &Path, args: &BenchArgs, m: &MapsSettings) -> Result<MapsSet> {
    let capture = args.fit.real.open(path)?;
    let last = capture.photos.len().saturating_sub(1);
    let maps = MapsArgs {
        maps: true,
        texels: None,
        normals: crate::maps::fit::Normals::Off,
        bases: m.max_bases,
        holdout_photo: Some(last),
        coarse_to_fine: CoarseToFine::default(),
        photo_gains: false,
    };
    // Each maps fit takes the options of the first model with its own model.
    let options = args
        .fit
        .maps_options(m.models[0], &maps, Reporting::terminal_if(!args.quiet));
    MapsSet::new(path, capture, options, &print_warning)
}

/// What the numbers mean and what this run left out.
fn notes(settings: &Settings, estimators: &[EstimatorRow], jobs: &[JobRow]) -> Vec<String> {
    let e = &settings.estimators;
    let mut notes = vec![
        format!(
            "estimators: {} configurations (GGX, alpha {}..{}, wi and wo up to {} deg, copper and white Fresnel); converged values of stochastic models from {} samples{}",
            e.configurations,
            ALPHA_RANGE[0],
            ALPHA_RANGE[1],
            estimators::MAX_THETA_DEG,
            e.reference_samples,
            if settings.quick { " (--quick: the full run uses 100000)" } else { "" }
        ),
        "ns_per_eval: CPU time of one thread per eval call; ns_per_eval_wall: wall time of the same loop (larger when the machine is shared)".into(),
        "rmse, rmse_vs_heitz, bias_vs_heitz: RMS over configurations and channels of relative errors; inverse_efficiency_vs_heitz (ineff) = (rmse^2 x ns_per_eval) / heitz's at the same n, below 1 is better; _rough (>=.5): alpha >= 0.5 only".into(),
        "relative_variance (rel var): variance of one evaluation over the converged value squared, from the converged runs; inverse_efficiency_vs_heitz_from_reference (second table's ineff) is the efficiency ratio computed with it: the same quantity as ineff, steadier where rare large samples make the per-n values jump".into(),
        "heitz is measured whatever --models says (the reference); its bias_vs_heitz compares two independent converged heitz values and should be about bias_vs_heitz_noise".into(),
    ];
    let analytic: Vec<&str> = Model::ALL
        .iter()
        .filter(|m| estimators.iter().any(|r| r.model == **m && !r.stochastic))
        .map(|m| m.name())
        .collect();
    if !analytic.is_empty() {
        notes.push(format!(
            "{} are deterministic: rmse is 0 up to rounding, and inverse_efficiency_vs_heitz is null (variance 0: the efficiency is infinite); their error is bias_vs_heitz",
            analytic.join(", ")
        ));
    }
    if let Some(r) = &settings.render {
        let skipped = jobs
            .iter()
            .find(|j| j.skip && j.job == jobs::JobKind::Render)
            .map_or(0, |j| j.skipped_pixels);
        notes.push(format!(
            "render: {} rendered at {}x{}, 1 sample per pixel, median of repeats over at least {} s; skip=true renders only pixels that can enter a loss ({skipped} pixels skipped here) through the render plan a fit uses (every skip --no-skip leaves on) (stride: anchor stride of the multiple-bounce term; err: RMS difference from the exact render, relative)",
            r.capture.display(),
            r.resolution,
            r.resolution,
            r.min_seconds
        ));
    }
    if let (Some(r), Some(render)) = (&settings.relight, &settings.render) {
        notes.push(format!(
            "relight: {} under each of {} on the unit sphere under the bundled sky, {}x{} pixels, {} samples per pixel (two directions each, MIS), one frame, in memory (no files); /single: over the single relight of this run",
            render.material.display(),
            r.models.iter().map(|m| m.name()).collect::<Vec<_>>().join(", "),
            r.size,
            r.size,
            r.samples
        ));
    }
    if let Some(f) = &settings.fit {
        notes.push(format!(
            "fit: {} halved {} times, {} samples per pixel, at most {} iterations; skip=false is --no-skip all (pixels of weight 0 are never rendered), skip=true every skip of render::plan that --no-skip leaves on; alpha_rel_error is signed, against the set's material.json (the model that made the photos may differ from the fitted one); seconds_vs_single (/single) is the fit's time over the single fit of the same set and skip",
            f.sets
                .iter()
                .map(|s| match s.fresnel {
                    Some(family) => format!("{} ({family:?} Fresnel)", s.path.display()),
                    None => s.path.display().to_string(),
                })
                .collect::<Vec<_>>()
                .join(" and "),
            f.halvings,
            f.pixel_samples,
            f.max_iters
        ));
    }
    if let Some(m) = &settings.maps {
        notes.push(format!(
            "maps-fit: {} with {} at texels {}, up to {} bases, the last photo of each set held out; seconds: wall time of the fit and the prediction of every photo (cpu: all threads); held-out: relative RMS error of the held-out photo, baseline: that of predicting it by the mean of the other photos; /single: over the single maps fit of the same set and texels",
            m.sets
                .iter()
                .map(|s| s.display().to_string())
                .collect::<Vec<_>>()
                .join(" and "),
            m.models
                .iter()
                .map(|m| m.name())
                .collect::<Vec<_>>()
                .join(", "),
            m.texels
                .iter()
                .map(|t| match t {
                    TexelSide::Texels(n) => n.to_string(),
                    TexelSide::Full => "full (the photos' width)".into(),
                })
                .collect::<Vec<_>>()
                .join(", "),
            m.max_bases
        ));
    }
    notes
}

fn optional(v: Option<f64>, precision: usize) -> String {
    v.map_or("-".into(), |v| format!("{v:.precision$e}"))
}

/// The estimator tables (by sample count, then by model), the job table, the notes and the
/// run's time.
fn tables(report: &BenchReport) -> String {
    let mut out = format!(
        "{:<12} {:>3} {:>10} {:>9} {:>9} {:>9} {:>9} {:>9}\n",
        "model", "n", "ns/estim.", "rmse", "rmse>=.5", "vs heitz", "ineff", "ineff>=.5"
    );
    for r in &report.estimators {
        out += &format!(
            "{:<12} {:>3} {:>10.0} {:>9.2e} {:>9} {:>9.2e} {:>9} {:>9}\n",
            r.model.name(),
            r.samples,
            r.samples as f64 * r.ns_per_eval,
            r.rmse,
            optional(r.rmse_rough, 2),
            r.rmse_vs_heitz,
            optional(r.inverse_efficiency_vs_heitz, 2),
            optional(r.inverse_efficiency_vs_heitz_rough, 2),
        );
    }
    out += &format!(
        "\n{:<12} {:>8} {:>8} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>8}\n",
        "model",
        "ns/eval",
        "wall ns",
        "rel var",
        "var>=.5",
        "ineff",
        "ineff>=.5",
        "bias",
        "mean",
        "+-noise"
    );
    let mut per_model: Vec<&EstimatorRow> = report.estimators.iter().collect();
    per_model.dedup_by_key(|r| r.model);
    for r in &per_model {
        out += &format!(
            "{:<12} {:>8.0} {:>8.0} {:>9.2e} {:>9} {:>9} {:>9} {:>9.2e} {:>+9.2e} {:>8.1e}\n",
            r.model.name(),
            r.ns_per_eval,
            r.ns_per_eval_wall,
            r.relative_variance,
            optional(r.relative_variance_rough, 2),
            optional(r.inverse_efficiency_vs_heitz_from_reference, 2),
            optional(r.inverse_efficiency_vs_heitz_from_reference_rough, 2),
            r.bias_vs_heitz,
            r.bias_vs_heitz_mean,
            r.bias_vs_heitz_noise,
        );
    }
    for r in &per_model {
        out += &format!(
            "{}: largest difference from heitz {:+.3} at {}\n",
            r.model, r.worst_bias_vs_heitz, r.worst_bias_at
        );
    }
    let k = &report.kernel;
    out += &format!(
        "\nkernel: single (GGX copper, alpha 0.3) over {} pairs, one thread: scalar {:.1} ns/eval, batch {:.2} ns/eval with f32 lanes ({:.1}x), {:.2} with f64 lanes, {:.2} with f32 lanes and 4 pairs to a pixel as a fit lays them out; preparing the batch's geometry once: {:.1} ns/pair; kulla-conty in the batch kernel: {:.2} ns/eval with f32 lanes ({:.2}x single), {:.2} with f64 lanes ({:.2}x); fast-msx: {:.2} ({:.2}x), {:.2} ({:.2}x); single with its derivatives (what a fit evaluates): {:.2} with f32 lanes, {:.2} with f64 lanes\n",
        k.pairs, k.scalar_ns_per_eval, k.batch_ns_per_eval, k.speedup, k.batch_f64_ns_per_eval, k.batch_fit_layout_ns_per_eval, k.batch_prepare_ns_per_eval,
        k.kulla_conty_ns_per_eval, k.kulla_conty_ns_per_eval / k.batch_ns_per_eval,
        k.kulla_conty_f64_ns_per_eval, k.kulla_conty_f64_ns_per_eval / k.batch_f64_ns_per_eval,
        k.fast_msx_ns_per_eval, k.fast_msx_ns_per_eval / k.batch_ns_per_eval,
        k.fast_msx_f64_ns_per_eval, k.fast_msx_f64_ns_per_eval / k.batch_f64_ns_per_eval,
        k.tangents_ns_per_eval, k.tangents_f64_ns_per_eval
    );
    if report.jobs.iter().any(|j| j.job != jobs::JobKind::MapsFit) {
        out += &format!(
            "\n{:<7} {:<12} {:>5} {:>9} {:>9} {:>4} {:>9} {:>8} {:>7} {:>6} {:>8} {:>10} {:>7} {:>9} {:>6} {:>7}\n",
            "job",
            "model",
            "skip",
            "seconds",
            "cpu s",
            "runs",
            "size",
            "pixels",
            "skipped",
            "stride",
            "err",
            "loss",
            "alpha",
            "alpha err",
            "evals",
            "/single"
        );
        for j in report
            .jobs
            .iter()
            .filter(|j| j.job != jobs::JobKind::MapsFit)
        {
            out += &format!(
                "{:<7} {:<12} {:>5} {:>9.4} {:>9.3} {:>4} {:>9} {:>8} {:>7} {:>6} {:>8} {:>10} {:>7} {:>9} {:>6} {:>7}\n",
                j.job.name(),
                j.model.name(),
                j.skip,
                j.seconds,
                j.cpu_seconds,
                j.repeats,
                format!("{}x{}x{}", j.photos, j.resolution[0], j.resolution[1]),
                j.pixels,
                j.skipped_pixels,
                j.plan.as_ref().map_or("-".into(), |p| p.multi_stride.to_string()),
                optional(j.rel_error_vs_exact, 1),
                optional(j.loss, 3),
                j.alpha.map_or("-".into(), |a| format!("{a:.4}")),
                j.alpha_rel_error.map_or("-".into(), |e| format!("{:+.2}%", 100.0 * e)),
                j.evaluations.map_or("-".into(), |e| e.to_string()),
                j.seconds_vs_single.map_or("-".into(), |r| format!("{r:.2}x")),
            );
        }
    }
    let maps: Vec<&JobRow> = report
        .jobs
        .iter()
        .filter(|j| j.job == jobs::JobKind::MapsFit)
        .collect();
    if !maps.is_empty() {
        out += &format!(
            "\n{:<8} {:<12} {:>11} {:>9} {:>9} {:>9} {:>8} {:>7} {:>5} {:>9} {:>9}  {}\n",
            "job",
            "model",
            "texels",
            "seconds",
            "cpu s",
            "texels/s",
            "peak MB",
            "/single",
            "bases",
            "held-out",
            "baseline",
            "set"
        );
        for j in maps {
            let [w, h] = j.texels.unwrap_or_default();
            out += &format!(
                "{:<8} {:<12} {:>11} {:>9.2} {:>9.2} {:>9} {:>8} {:>7} {:>5} {:>9} {:>9}  {}\n",
                j.job.name(),
                j.model.name(),
                format!("{w}x{h}"),
                j.seconds,
                j.cpu_seconds,
                j.texels_per_second
                    .map_or("-".into(), |r| format!("{r:.0}")),
                j.peak_memory_mb.map_or("-".into(), |m| format!("{m:.0}")),
                j.seconds_vs_single
                    .map_or("-".into(), |r| format!("{r:.2}x")),
                j.bases.map_or("-".into(), |b| b.to_string()),
                j.held_out_error.map_or("-".into(), |e| format!("{e:.4}")),
                j.held_out_baseline
                    .map_or("-".into(), |e| format!("{e:.4}")),
                j.set.as_deref().unwrap_or("-"),
            );
        }
    }
    out += "\n";
    for n in &report.notes {
        out += &format!("note: {n}\n");
    }
    out += &format!(
        "wall {:.1} s, CPU {:.1} s (all threads)\n",
        report.wall_seconds, report.cpu_seconds
    );
    out
}
