//! `accuracy`: renders the paper's four single-corner tests (noise, blur, perspective, curvature;
//! section IV-A) with fixed seeds, saves every image as the 8-bit PNG the peers will read, and runs
//! conic-corners on exactly those pixels.
//!
//! Writes `OUT/manifest.jsonl` (image, protocol, sweep value, exact truth, Cramér–Rao bound) and
//! `OUT/ours.jsonl` (one line per image and conic-corners variant). `bench/peers.py` adds the
//! peers' results and `bench/report.py` prints the table; `bench/accuracy.sh` runs all three.

use clap::Parser;
use conic_corners::refine::{refine_one, RefineParams, Status};
use conic_corners::synth::{cramer_rao_bound, scene_for, Protocol};
use conic_corners::GrayImage;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde_json::json;
use std::io::Write;
use std::path::PathBuf;

#[derive(Parser)]
#[command(about = "Render the paper's single-corner accuracy protocol and run conic-corners on it")]
struct Args {
    /// Output directory (created).
    #[arg(long)]
    out: PathBuf,
    /// Images per sweep point.
    #[arg(long, default_value_t = 200)]
    per_point: usize,
    /// Base seed; image i of a sweep point uses a seed derived from it, the protocol and the point.
    #[arg(long, default_value_t = 2024)]
    seed: u64,
    /// Protocols to run (noise, blur, perspective, curvature); all by default.
    #[arg(long, value_delimiter = ',')]
    protocols: Vec<String>,
    /// Reach (px) of the refiner's edge walks (default: the library default).
    #[arg(long)]
    reach: Option<f64>,
    /// Scanline stride of the refiner's edge samples (default: the library default).
    #[arg(long)]
    stride: Option<usize>,
    /// Half-window (px) of the Cramér–Rao bound.
    #[arg(long, default_value_t = 50)]
    crb_half_window: usize,
}

fn main() -> Result<(), String> {
    let args = Args::parse();
    let all = Protocol::ALL;
    let protocols: Vec<Protocol> = if args.protocols.is_empty() {
        all.to_vec()
    } else {
        args.protocols
            .iter()
            .map(|name| {
                all.iter()
                    .copied()
                    .find(|p| p.name() == name)
                    .ok_or_else(|| format!("unknown protocol {name}"))
            })
            .collect::<Result<_, _>>()?
    };
    std::fs::create_dir_all(&args.out).map_err(|e| e.to_string())?;
    let mut jobs = Vec::new();
    for (pi, &p) in protocols.iter().enumerate() {
        for (vi, v) in p.sweep_values().into_iter().enumerate() {
            for i in 0..args.per_point {
                let seed = args.seed ^ ((pi as u64) << 48) ^ ((vi as u64) << 32) ^ i as u64;
                jobs.push((p, v, i, seed));
            }
        }
    }
    let defaults = RefineParams::default();
    let params = RefineParams {
        reach: args.reach.unwrap_or(defaults.reach),
        stride: args.stride.unwrap_or(defaults.stride),
        ..defaults
    };
    params.validate()?;
    let results: Vec<(serde_json::Value, Vec<serde_json::Value>)> = jobs
        .par_iter()
        .map(|&(p, v, i, seed)| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let scene = scene_for(p, v, &mut rng);
            let rendered = scene.render(seed).map_err(|e| e.to_string())?;
            let rel = format!("{}/{v}/{i:04}.png", p.name());
            let path = args.out.join(&rel);
            std::fs::create_dir_all(path.parent().expect("has parent"))
                .map_err(|e| e.to_string())?;
            // The peers read the 8-bit file; so do we, from the same pixels.
            let png = rendered.image.to_luma8(0.0, 1.0);
            png.save(&path)
                .map_err(|e| format!("{}: {e}", path.display()))?;
            let pixels =
                GrayImage::from_slice(png.width() as usize, png.height() as usize, png.as_raw())
                    .map_err(|e| e.to_string())?;
            let truth = rendered.truth;
            // `clean` and `scene.noise` share the 0..1 intensity scale.
            let crb = cramer_rao_bound(&rendered.clean, truth, args.crb_half_window, scene.noise);
            let manifest = json!({
                "image": rel, "protocol": p.name(), "value": v, "truth": truth,
                "crb": crb, "seed": seed,
            });
            let angle = rng.gen_range(0.0..std::f64::consts::TAU);
            let radius = rng.gen_range(0.0..2.0f64);
            let starts = [
                ("conic-corners", [truth[0].round(), truth[1].round()]),
                (
                    "conic-corners-start2px",
                    [
                        truth[0] + radius * angle.cos(),
                        truth[1] + radius * angle.sin(),
                    ],
                ),
            ];
            let ours = starts
                .iter()
                .map(|(name, start)| {
                    let r = refine_one(&pixels, *start, &params);
                    json!({
                        "image": rel, "method": name, "x": r.x, "y": r.y,
                        "found": r.status != Status::Failed,
                    })
                })
                .collect();
            Ok((manifest, ours))
        })
        .collect::<Result<_, String>>()?;
    let mut manifest =
        std::fs::File::create(args.out.join("manifest.jsonl")).map_err(|e| e.to_string())?;
    let mut ours = std::fs::File::create(args.out.join("ours.jsonl")).map_err(|e| e.to_string())?;
    for (m, o) in &results {
        writeln!(manifest, "{m}").map_err(|e| e.to_string())?;
        for line in o {
            writeln!(ours, "{line}").map_err(|e| e.to_string())?;
        }
    }
    eprintln!("wrote {} images to {}", results.len(), args.out.display());
    Ok(())
}
