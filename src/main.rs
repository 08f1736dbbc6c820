//! The `bouncefit` command line: argument parsing and exit codes only; the work is in
//! `bouncefit::commands`. Bad input exits with status 2 and one line naming the file and field.

use bouncefit::commands;
use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// Fits allocate render buffers of several MB per evaluation; the system allocator maps and
/// unmaps each one, and the page faults of zeroing them took a quarter of a `single` fit.
/// mimalloc keeps freed memory for reuse.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

#[derive(Parser)]
#[command(
    name = "bouncefit",
    version,
    about = "Fit single- and multi-bounce microfacet materials to photographs of flat samples"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Evaluate a BRDF at one pair of directions.
    Brdf(commands::brdf::BrdfArgs),
    /// Directional albedo of a BRDF at one incidence angle.
    Albedo(commands::brdf::AlbedoArgs),
    /// Picture of a model's lobe and its albedo split by bounce count.
    Lobe(commands::lobe::LobeArgs),
    /// Make a synthetic photo set from a material and a capture manifest.
    Synth(commands::synth::SynthArgs),
    /// Re-render a photo set with a material or fit.
    Render(commands::synth::RenderArgs),
    /// Previews of a fit or material on a sphere or the flat sample under new light.
    Relight(commands::relight::RelightArgs),
    /// Write a printable tag board (PNG, SVG) and its board.toml for phone captures.
    Board(commands::capture::BoardArgs),
    /// Phone photos of a sample in a printed board -> a photo set (rectified or perspective).
    Capture(commands::capture::CaptureArgs),
    /// Fit material parameters to a photo set.
    Fit(commands::fit_args::FitArgs),
    /// Write a fit or material for a renderer (json, mitsuba, gltf, materialx).
    Export(commands::export::ExportArgs),
    /// Fit several models to the same photos and write a comparison report.
    Compare(commands::compare::CompareArgs),
    /// Sweep every model over extreme inputs and count NaN, Inf, negative values and energy gain.
    Stress(commands::stress::StressArgs),
    /// Time and error of every model's estimator against heitz, and render and fit jobs.
    Bench(commands::bench::BenchArgs),
    /// One image operation of the fitter (decode, encode, downsample, blur, ssim) on files.
    Image(commands::image::ImageArgs),
    /// Cameras, sample corners and sample points of a photo set as JSON, with pixel positions.
    Records(commands::records::RecordsArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Brdf(args) => commands::brdf::run_brdf(args),
        Command::Albedo(args) => commands::brdf::run_albedo(args),
        Command::Lobe(args) => commands::lobe::run_lobe(args),
        Command::Synth(args) => commands::synth::run_synth(args),
        Command::Render(args) => commands::synth::run_render(args),
        Command::Relight(args) => commands::relight::run_relight(args),
        Command::Board(args) => commands::capture::run_board(args),
        Command::Capture(args) => commands::capture::run_capture(args),
        Command::Fit(args) => commands::fit::run_fit(args),
        Command::Export(args) => commands::export::run_export(args),
        Command::Compare(args) => commands::compare::run_compare(args),
        Command::Bench(args) => commands::bench::run_bench(args),
        Command::Image(args) => commands::image::run_image(args),
        Command::Records(args) => commands::records::run_records(args),
        // Findings (NaN, Inf, negative values) exit with 1; bad input with 2 as everywhere.
        Command::Stress(args) => match commands::stress::run_stress(args) {
            Ok(false) => return ExitCode::from(1),
            other => other.map(|_clean| ()),
        },
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {err}");
            ExitCode::from(2)
        }
    }
}
