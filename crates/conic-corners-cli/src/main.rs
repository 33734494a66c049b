//! `conic-corners`: command-line front end. JSON on stdout (one object per image), diagnostics on
//! stderr, a non-zero exit code with a clear message on unusable input.

use clap::{Args, Parser, Subcommand};
use conic_corners::refine::{refine, RefineParams, Refined};
use conic_corners::GrayImage;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

mod detect_cmd;
mod draw;
mod synth_cmd;

#[derive(Parser)]
#[command(
    name = "conic-corners",
    version,
    about = "Subpixel checkerboard corners by quadratic-form fitting"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Find checkerboard-like boards, label every corner with its (row, col) and refine it.
    ///
    /// Prints one JSON object per image (one per line). Coordinates: x right, y down, the centre
    /// of the top-left pixel is (0, 0).
    Detect(detect_cmd::DetectArgs),
    /// Refine approximate corner positions to subpixel accuracy (a drop-in for cornerSubPix).
    ///
    /// Coordinates: x right, y down, the centre of the top-left pixel is (0, 0).
    Refine(RefineArgs),
    /// Render a synthetic single-corner image with exact ground truth.
    Synth(synth_cmd::SynthArgs),
}

#[derive(Args)]
struct RefineArgs {
    /// Image file (PNG, JPEG, TIFF, BMP, PNM, WebP, GIF; 8 or 16 bit; colour is converted to grey).
    image: PathBuf,
    /// An approximate corner "X,Y" (repeatable).
    #[arg(long = "at", value_name = "X,Y", value_parser = parse_point)]
    at: Vec<[f64; 2]>,
    /// A JSON file holding an array of [x, y] approximate corners.
    #[arg(long, value_name = "FILE")]
    points: Option<PathBuf>,
    #[command(flatten)]
    params: RefineOptions,
}

/// The refiner's tuning knobs, shared by every command that refines.
#[derive(Args, Clone)]
pub struct RefineOptions {
    /// Farthest distance (px) an edge walk goes from the corner [refine: 100; detect: 100, and
    /// never beyond the corner's farthest grid neighbour].
    #[arg(long)]
    reach: Option<f64>,
    /// Scanlines between consecutive edge samples [refine: 1; detect: 2, set 1 for the last
    /// thousandths of a pixel at about 1.6× the refinement time; in detect's board-wide fit,
    /// edges of short squares are sampled on every scanline anyway].
    #[arg(long)]
    stride: Option<usize>,
    /// Gaussian blur σ of the image in px, if known (estimated otherwise).
    #[arg(long)]
    blur: Option<f64>,
}

impl RefineOptions {
    /// `defaults` with the options given on the command line applied, validated.
    fn to_params(&self, defaults: RefineParams) -> Result<RefineParams, String> {
        let params = RefineParams {
            reach: self.reach.unwrap_or(defaults.reach),
            stride: self.stride.unwrap_or(defaults.stride),
            blur: self.blur.or(defaults.blur),
            ..defaults
        };
        params.validate()?;
        Ok(params)
    }
}

pub fn parse_point(s: &str) -> Result<[f64; 2], String> {
    let mut it = s.split(',').map(|v| v.trim().parse::<f64>());
    match (it.next(), it.next(), it.next()) {
        (Some(Ok(x)), Some(Ok(y)), None) if x.is_finite() && y.is_finite() => Ok([x, y]),
        _ => Err(format!("expected two finite numbers \"X,Y\", got \"{s}\"")),
    }
}

#[derive(Serialize)]
struct CornerOut {
    x: f64,
    y: f64,
    status: conic_corners::refine::Status,
    residual: Option<f64>,
    sigma: Option<f64>,
    cov: Option<[[f64; 2]; 2]>,
}

impl From<Refined> for CornerOut {
    fn from(r: Refined) -> Self {
        Self {
            x: r.x,
            y: r.y,
            status: r.status,
            residual: r.residual,
            sigma: r.sigma,
            cov: r.cov,
        }
    }
}

/// Reads an image, naming the file in the error.
pub fn open_image(path: &Path) -> Result<GrayImage, String> {
    GrayImage::open(path).map_err(|e| e.to_string())
}

fn read_points(path: &Path) -> Result<Vec<[f64; 2]>, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    let points: Vec<[f64; 2]> = serde_json::from_str(&text).map_err(|e| {
        format!(
            "{}: expected a JSON array of [x, y] pairs: {e}",
            path.display()
        )
    })?;
    if let Some(i) = points.iter().position(|p| !p.iter().all(|v| v.is_finite())) {
        return Err(format!("{}: point {i} is not finite", path.display()));
    }
    Ok(points)
}

fn run_refine(args: &RefineArgs) -> Result<(), String> {
    let params = args.params.to_params(RefineParams::default())?;
    let mut points = args.at.clone();
    if let Some(file) = &args.points {
        points.extend(read_points(file)?);
    }
    if points.is_empty() {
        return Err("no points given: use --at X,Y or --points FILE".into());
    }
    let image = open_image(&args.image)?;
    let corners: Vec<CornerOut> = refine(&image, &points, &params)
        .into_iter()
        .map(Into::into)
        .collect();
    let failed = corners
        .iter()
        .filter(|c| c.status == conic_corners::refine::Status::Failed)
        .count();
    if failed > 0 {
        eprintln!("{failed} of {} corners could not be refined", corners.len());
    }
    print_json(&serde_json::json!({ "corners": corners }))
}

/// Prints one JSON object on a line of its own.
pub fn print_json(value: &impl Serialize) -> Result<(), String> {
    let line = serde_json::to_string(value).map_err(|e| e.to_string())?;
    println!("{line}");
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Detect(args) => detect_cmd::run(args),
        Command::Refine(args) => run_refine(args),
        Command::Synth(args) => synth_cmd::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("error: {message}");
            ExitCode::FAILURE
        }
    }
}
