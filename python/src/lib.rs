//! `bouncefit._native`: the Python package's bindings (PyO3). Every function here parses its
//! options with the command line's own argument types (`bouncefit::commands`) and calls the
//! library pipeline the command calls; the pure-Python `bouncefit` package wraps the results in
//! plain objects. Long work runs with the GIL released.

use bouncefit::capture::atomic_file::write_atomically;
use bouncefit::capture::{Capture, InMemoryPhoto, LinearImage};
use bouncefit::commands::compare::{compare_photo_set, CompareArgs};
use bouncefit::commands::export::{run_export, ExportArgs};
use bouncefit::commands::fit_args::{FitArgs, RealCaptureArgs};
use bouncefit::commands::fit_maps::maps_model;
use bouncefit::commands::inputs::load_any_material;
use bouncefit::error::Error;
use bouncefit::fit::fit_file::FitFile;
use bouncefit::fit::pipeline;
use bouncefit::maps::fit::Uncertainty;
use bouncefit::maps::pipeline::{write_fit_images, MapsSet};
use bouncefit::maps::render::{render_any, render_records};
use bouncefit::maps::MaterialMaps;
use bouncefit::progress::{ProgressSink, Reporting};
use bouncefit::shading::ShadingRecords;
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2, PyReadonlyArray3};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::ffi::CString;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// A library error as the exception of `bouncefit.errors` its kind maps to, with the message
/// the command line prints after `error: `.
fn py_error(err: Error) -> PyErr {
    let class = match err {
        Error::Io { .. } => "FileError",
        Error::Invalid { .. } | Error::Argument { .. } => "InvalidInputError",
    };
    raise(class, err.to_string())
}

/// The exception `class` of `bouncefit.errors` carrying `message` (or the error of making it).
fn raise(class: &str, message: String) -> PyErr {
    Python::attach(|py| {
        py.import("bouncefit.errors")
            .and_then(|m| m.getattr(class))
            .and_then(|exception| exception.call1((message,)))
            .map_or_else(|e| e, PyErr::from_value)
    })
}

/// Parses `argv` (the words after `bouncefit COMMAND`) into `T` exactly as the command line
/// does; a bad option raises `InvalidInputError` with clap's message.
fn parse<T: clap::Args + clap::FromArgMatches>(command: &str, argv: Vec<String>) -> PyResult<T> {
    let matches = T::augment_args(clap::Command::new("bouncefit"))
        .bin_name(format!("bouncefit {command}"))
        .try_get_matches_from(std::iter::once("bouncefit".to_string()).chain(argv))
        .map_err(clap_error)?;
    T::from_arg_matches(&matches).map_err(clap_error)
}

/// clap's first paragraph without its `error: ` prefix (the usage lines are for a terminal).
fn clap_error(err: clap::Error) -> PyErr {
    let text = err.render().to_string();
    let first = text.split("\n\n").next().unwrap_or_default().trim();
    let message = first.strip_prefix("error: ").unwrap_or(first).to_string();
    raise("InvalidInputError", message)
}

/// The Python progress callback `progress(stage, done, total, message)` as the library's
/// progress sink, and the library's warnings as Python warnings (`BouncefitWarning`). The
/// first exception either raises stops the work and is raised in place of its result.
struct Callback {
    function: Option<Py<PyAny>>,
    failure: Mutex<Option<PyErr>>,
}

impl Callback {
    fn new(function: Option<Py<PyAny>>) -> Arc<Self> {
        Arc::new(Callback {
            function,
            failure: Mutex::new(None),
        })
    }

    /// Where the library's progress goes: to the callback, if there is one.
    fn reporting(self: &Arc<Self>) -> Reporting {
        match self.function {
            Some(_) => Reporting::Sink(self.clone()),
            None => Reporting::Off,
        }
    }

    /// Keeps the first exception; `false` from then on.
    fn outcome(&self, result: PyResult<()>) -> bool {
        let mut failure = self.failure.lock().expect("no panic holds the lock");
        if let Err(err) = result {
            failure.get_or_insert(err);
        }
        failure.is_none()
    }

    /// Calls the callback (with the GIL); `false` once it or a warning has raised.
    fn call(&self, stage: &str, done: u64, total: u64, message: &str) -> bool {
        let Some(function) = &self.function else {
            return self.outcome(Ok(()));
        };
        if !self.outcome(Ok(())) {
            return false;
        }
        let result = Python::attach(|py| {
            function
                .call1(py, (stage, done, total, message))
                .map(|_| ())
        });
        self.outcome(result)
    }

    /// Issues `message` as a `bouncefit.BouncefitWarning`.
    fn warn(&self, message: &str) {
        let result = Python::attach(|py| {
            let category = py.import("bouncefit.errors")?.getattr("BouncefitWarning")?;
            let text = CString::new(message.replace('\0', " ")).expect("no NUL left");
            PyErr::warn(py, &category, &text, 1)
        });
        self.outcome(result);
    }

    /// The work's `result`, or the exception the callback or a warning raised, which stopped it.
    fn result<T>(&self, result: Result<T, Error>) -> PyResult<T> {
        match self.failure.lock().expect("no panic holds the lock").take() {
            Some(err) => Err(err),
            None => result.map_err(py_error),
        }
    }
}

impl ProgressSink for Callback {
    fn update(&self, stage: &str, done: u64, total: u64, message: &str) -> bool {
        self.call(stage, done, total, message)
    }
}

/// One `(height, width, 3)` array per photo of `records` from per-pixel values.
fn photo_arrays<'py>(
    py: Python<'py>,
    records: &ShadingRecords,
    per_pixel: &[[f64; 3]],
) -> PyResult<Bound<'py, PyList>> {
    let arrays = records
        .photos
        .iter()
        .map(|photo| {
            let n = photo.width * photo.height;
            let flat: Vec<f64> = per_pixel[photo.first_pixel..photo.first_pixel + n]
                .iter()
                .flatten()
                .copied()
                .collect();
            PyArray1::from_vec(py, flat).reshape([photo.height, photo.width, 3])
        })
        .collect::<PyResult<Vec<_>>>()?;
    PyList::new(py, arrays)
}

/// A `(height, width, channels)` array of a texel map.
fn map_array<'py, const C: usize>(
    py: Python<'py>,
    maps: &MaterialMaps,
    texels: &[[f64; C]],
) -> PyResult<Bound<'py, PyAny>> {
    let flat: Vec<f64> = texels.iter().flatten().copied().collect();
    Ok(PyArray1::from_vec(py, flat)
        .reshape([maps.grid.height, maps.grid.width, C])?
        .into_any())
}

fn stems(records: &ShadingRecords) -> Vec<String> {
    records.photos.iter().map(|p| p.stem.clone()).collect()
}

/// `--depth` alone, as `load` and `render` take it.
fn real_capture_args(depth: Option<f64>) -> RealCaptureArgs {
    RealCaptureArgs {
        fit_exposure: false,
        fresnel_known: None,
        depth,
        region: None,
        mask: None,
    }
}

/// A photo set held in memory (`PhotoSet.from_arrays`): what the fits open in place of a
/// path.
#[pyclass(frozen, module = "bouncefit._native")]
struct Photos {
    capture: Capture,
}

/// The photo set `capture` (opened from `path`, or `photos` in memory) as `PhotoSet`'s
/// fields: its name, photos and the linear images the fits see.
fn photo_set<'py>(
    py: Python<'py>,
    path: Option<PathBuf>,
    capture: Capture,
    in_memory: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let records = py
        .detach(|| ShadingRecords::build(&capture, 1, true))
        .map_err(py_error)?;
    let out = PyDict::new(py);
    out.set_item("path", path)?;
    out.set_item("name", &capture.name)?;
    out.set_item("units", &capture.units)?;
    out.set_item("sample", [capture.sample.width, capture.sample.height])?;
    out.set_item("depth", capture.depth)?;
    out.set_item("photos", stems(&records))?;
    out.set_item("images", photo_arrays(py, &records, &records.target)?)?;
    out.set_item("warnings", &capture.warnings)?;
    let handle = in_memory.then(|| Photos { capture });
    out.set_item("native", handle)?;
    Ok(out)
}

/// A photo set: its name, photos and the linear images the fits see.
#[pyfunction]
#[pyo3(signature = (path, depth=None))]
fn load_photo_set<'py>(
    py: Python<'py>,
    path: PathBuf,
    depth: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let capture = real_capture_args(depth).open(&path).map_err(py_error)?;
    photo_set(py, Some(path), capture, false)
}

/// A photo set from the tables of a manifest (`manifest`: JSON text of what `capture.toml`
/// holds, each photo's `image` its stem) and per photo its linear `(h, w, 3)` image and
/// optional `(h, w)` keep-mask, checked by the manifest reader; errors name `source`.
#[pyfunction]
#[pyo3(signature = (source, manifest, images, masks))]
fn photo_set_from_arrays<'py>(
    py: Python<'py>,
    source: PathBuf,
    manifest: &str,
    images: Vec<PyReadonlyArray3<'py, f32>>,
    masks: Vec<Option<PyReadonlyArray2<'py, bool>>>,
) -> PyResult<Bound<'py, PyDict>> {
    let entries: toml::Table = serde_json::from_str(manifest)
        .map_err(|e| py_error(Error::invalid(&source, "manifest", e.to_string())))?;
    let pixels = images
        .iter()
        .zip(&masks)
        .enumerate()
        .map(|(i, (image, mask))| {
            let image = image.as_array();
            let (height, width, channels) = image.dim();
            if channels != 3 {
                return Err(raise(
                    "InvalidInputError",
                    format!(
                        "images[{i}]: expected a (height, width, 3) array, got {channels} channels"
                    ),
                ));
            }
            let keep = match mask {
                Some(mask) if mask.as_array().dim() != (height, width) => {
                    return Err(raise(
                        "InvalidInputError",
                        format!(
                        "masks[{i}]: its shape {:?} differs from the image's ({height}, {width})",
                        mask.as_array().dim()
                    ),
                    ))
                }
                Some(mask) => Some(mask.as_array().iter().copied().collect()),
                None => None,
            };
            let rgb = image
                .as_standard_layout()
                .as_slice()
                .expect("a standard layout")
                .chunks_exact(3)
                .map(|c| [c[0], c[1], c[2]])
                .collect();
            Ok(InMemoryPhoto {
                name: format!("images[{i}]"),
                image: LinearImage {
                    width,
                    height,
                    rgb,
                    saturated: vec![false; width * height],
                },
                keep,
            })
        })
        .collect::<PyResult<Vec<_>>>()?;
    let capture = Capture::from_tables(&source, entries, pixels).map_err(py_error)?;
    photo_set(py, None, capture, true)
}

/// The photo set a function works on: the one in memory, or the one at `path` opened as the
/// command line does; `--depth` of `real` applied.
fn capture_of(path: &Path, photos: Option<&Photos>, real: &RealCaptureArgs) -> PyResult<Capture> {
    real.open_or(path, photos.map(|p| p.capture.clone()))
        .map_err(py_error)
}

/// What a fit leaves to be written: the uniform fit file's text, or maps and their fields.
#[pyclass(frozen, module = "bouncefit._native")]
struct FitOutput {
    form: Form,
}

enum Form {
    Text(String),
    Maps(
        MaterialMaps,
        Uncertainty,
        serde_json::Map<String, serde_json::Value>,
    ),
}

#[pymethods]
impl FitOutput {
    /// Writes the fit file at `path` as `bouncefit fit -o PATH` does (maps: their images into
    /// `<PATH without .json>.maps/`), atomically; residual images are not written.
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        py.detach(|| match &self.form {
            Form::Text(text) => write_atomically(&path, |w| {
                std::io::Write::write_all(w, text.as_bytes()).map_err(|e| Error::io(&path, e))
            }),
            Form::Maps(maps, uncertainty, fields) => {
                let folder = MaterialMaps::folder_beside(&path);
                std::fs::create_dir_all(&folder).map_err(|e| Error::io(&folder, e))?;
                let (entry, fields) =
                    write_fit_images(maps, uncertainty, &path, &folder, fields.clone())?;
                maps.save_json(&path, entry, fields)
            }
        })
        .map_err(py_error)
    }
}

/// `bouncefit fit PATH ARGV...` without writing files: the fit file's JSON, the chosen fit's
/// prediction and residual per photo, the maps of a maps fit, and a `FitOutput` to save it.
/// `photos` (a set in memory) replaces the set at `path`, which then only names it. `None`
/// when an MCMC run stopped early and left its checkpoint.
#[pyfunction]
#[pyo3(signature = (path, argv, progress=None, photos=None))]
fn fit<'py>(
    py: Python<'py>,
    path: PathBuf,
    argv: Vec<String>,
    progress: Option<Py<PyAny>>,
    photos: Option<Bound<'py, Photos>>,
) -> PyResult<Option<Bound<'py, PyDict>>> {
    let argv = std::iter::once(path.display().to_string()).chain(argv);
    let args: FitArgs = parse("fit", argv.collect())?;
    let callback = Callback::new(progress);
    let capture = capture_of(
        &args.capture,
        photos.as_ref().map(Bound::get),
        &args.options.real,
    )?;
    if args.map_options.maps {
        fit_maps(py, &args, capture, &callback)
    } else {
        fit_uniform(py, &args, capture, &callback)
    }
}

/// The fit file `-o` names (refused over an existing file without `--force`, as `fit` does),
/// else the command line's default, which only names an MCMC run's checkpoint.
fn fit_file_path(args: &FitArgs, capture: &Capture) -> PyResult<PathBuf> {
    match &args.output {
        Some(_) => args.output_path(capture).map_err(py_error),
        None => Ok(args.output_or_default(capture)),
    }
}

fn fit_uniform<'py>(
    py: Python<'py>,
    args: &FitArgs,
    capture: Capture,
    callback: &Arc<Callback>,
) -> PyResult<Option<Bound<'py, PyDict>>> {
    let output = fit_file_path(args, &capture)?;
    let options = args.options.pipeline_options(
        &args.models,
        &args.mcmc,
        &output,
        callback.reporting(),
        args.force,
        args.map_options.holdout_photo,
    );
    let models = options.candidates.len() as u64;
    let fitted = std::sync::atomic::AtomicU64::new(0);
    let done = py.detach(|| {
        pipeline::run(
            &args.capture,
            &capture,
            &options,
            &|warning| callback.warn(warning),
            &|fit| {
                let done = fitted.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                callback.call("fitted", done, models, &fit.summary());
            },
        )
    });
    let Some(done) = callback.result(done)? else {
        return Ok(None);
    };
    let text = FitFile::of_run(&done, (&args.capture, &capture), &options).to_json();
    let predicted = done.prediction();
    let out = PyDict::new(py);
    out.set_item("json", &text)?;
    out.set_item("photos", stems(&done.records))?;
    out.set_item("prediction", photo_arrays(py, &done.records, predicted)?)?;
    let residual = done.records.residuals(predicted.to_vec());
    out.set_item("residuals", photo_arrays(py, &done.records, &residual)?)?;
    out.set_item("maps", py.None())?;
    let saved = FitOutput {
        form: Form::Text(text),
    };
    if args.output.is_some() {
        saved.save(py, output)?;
    }
    out.set_item("output", saved)?;
    Ok(Some(out))
}

fn fit_maps<'py>(
    py: Python<'py>,
    args: &FitArgs,
    capture: Capture,
    callback: &Arc<Callback>,
) -> PyResult<Option<Bound<'py, PyDict>>> {
    let model = maps_model(args).map_err(py_error)?;
    let output = fit_file_path(args, &capture)?;
    let options = args
        .options
        .maps_options(model, &args.map_options, callback.reporting());
    let set = py.detach(|| {
        MapsSet::new(&args.capture, capture, options, &|warning| {
            callback.warn(warning)
        })
    });
    let set = callback.result(set)?;
    let run = py.detach(|| set.fit(model));
    let run = callback.result(run)?;
    let fields = set.fit_file_fields(&run);
    let (maps, records) = (&run.fit.maps, &*run.records);
    let residual = records.residuals(run.predicted.clone());
    // Before it is saved the fit names no images: `maps` and `uncertainty` are empty.
    let mut unsaved = fields.clone();
    unsaved.insert("uncertainty".into(), serde_json::json!({}));
    let document = maps.document(serde_json::Value::Object(Default::default()), unsaved);
    let out = PyDict::new(py);
    out.set_item(
        "json",
        serde_json::to_string_pretty(&document).expect("JSON"),
    )?;
    out.set_item("photos", stems(records))?;
    out.set_item("prediction", photo_arrays(py, records, &run.predicted)?)?;
    out.set_item("residuals", photo_arrays(py, records, &residual)?)?;
    let arrays = PyDict::new(py);
    if let Some(texels) = &maps.diffuse {
        arrays.set_item("diffuse", map_array(py, maps, texels)?)?;
    }
    if let Some(texels) = &maps.specular {
        arrays.set_item("specular", map_array(py, maps, texels)?)?;
    }
    if let Some(texels) = &maps.roughness {
        arrays.set_item("roughness", map_array(py, maps, texels)?)?;
    }
    if let Some(texels) = &maps.normal {
        arrays.set_item("normal", map_array(py, maps, texels)?)?;
    }
    out.set_item("maps", arrays)?;
    let saved = FitOutput {
        form: Form::Maps(maps.clone(), run.fit.uncertainty.clone(), fields),
    };
    if args.output.is_some() {
        saved.save(py, output)?;
    }
    out.set_item("output", saved)?;
    Ok(Some(out))
}

/// `bouncefit render --capture CAPTURE --material MATERIAL` without writing files: the linear
/// render of every photo (a fit file's fitted exposure applied). `photos` (a set in memory)
/// replaces the set at `capture`.
#[pyfunction]
#[pyo3(signature = (capture, material, pixel_samples=4, seed=0, depth=None, photos=None))]
fn render<'py>(
    py: Python<'py>,
    capture: PathBuf,
    material: PathBuf,
    pixel_samples: usize,
    seed: u64,
    depth: Option<f64>,
    photos: Option<Bound<'py, Photos>>,
) -> PyResult<Bound<'py, PyList>> {
    let loaded = load_any_material(&material).map_err(py_error)?;
    let real = real_capture_args(depth);
    let opened = capture_of(&capture, photos.as_ref().map(Bound::get), &real)?;
    let (records, pixels) = py
        .detach(|| {
            let records = render_records(&loaded, &material, &opened, pixel_samples)?;
            let pixels = render_any(&loaded, &records, seed)?;
            Ok::<_, Error>((records, pixels))
        })
        .map_err(py_error)?;
    photo_arrays(py, &records, &pixels)
}

/// `bouncefit compare ARGV...` (writes the report folder). `photos` (a set in memory)
/// replaces the set ARGV names.
#[pyfunction]
#[pyo3(signature = (argv, photos=None))]
fn compare(py: Python<'_>, argv: Vec<String>, photos: Option<Bound<'_, Photos>>) -> PyResult<()> {
    let args: CompareArgs = parse("compare", argv)?;
    let held = photos.map(|p| p.get().capture.clone());
    py.detach(|| compare_photo_set(&args, held))
        .map_err(py_error)
}

/// `bouncefit export ARGV...` (writes the exported file).
#[pyfunction]
fn export(py: Python<'_>, argv: Vec<String>) -> PyResult<()> {
    let args: ExportArgs = parse("export", argv)?;
    py.detach(|| run_export(&args)).map_err(py_error)
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(load_photo_set, m)?)?;
    m.add_function(wrap_pyfunction!(photo_set_from_arrays, m)?)?;
    m.add_function(wrap_pyfunction!(fit, m)?)?;
    m.add_function(wrap_pyfunction!(render, m)?)?;
    m.add_function(wrap_pyfunction!(compare, m)?)?;
    m.add_function(wrap_pyfunction!(export, m)?)?;
    m.add_class::<FitOutput>()?;
    m.add_class::<Photos>()?;
    m.add("VERSION", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
