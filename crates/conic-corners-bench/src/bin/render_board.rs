//! `render-board`: renders the speed benchmark's board image (issue "Board detection", item 8) as
//! the 8-bit PNG every method of `bench/detect_speed.py` reads, plus its truth as JSON.
//!
//! The scene is `conic_corners::synth::speed_benchmark_scene`, the one
//! `crates/conic-corners/benches/detect.rs` renders: a flat 9×9-inner-corner board seen by a
//! 1920×1200 camera, blur σ = 1 px, noise σ = 1 % of the 0..1 range, stored as `round(255 v)`.
//!
//! Truth JSON: `{"width", "height", "rows", "cols", "noise_seed", "blur", "noise",
//! "corners": [{"row", "col", "x", "y", "visible"}, ...]}`; coordinates x right, y down, the centre
//! of the top-left pixel at (0, 0).

use clap::Parser;
use conic_corners::synth::{speed_benchmark_scene, SPEED_BENCHMARK_NOISE_SEED};
use serde_json::json;
use std::path::PathBuf;

#[derive(Parser)]
#[command(about = "Render the 1920x1200 flat 9x9-corner board of the detection speed benchmark")]
struct Args {
    /// Output PNG (8-bit grey).
    #[arg(long)]
    png: PathBuf,
    /// Output truth JSON.
    #[arg(long)]
    truth: PathBuf,
}

fn main() -> Result<(), String> {
    let args = Args::parse();
    let scene = speed_benchmark_scene();
    let rendered = scene
        .render(SPEED_BENCHMARK_NOISE_SEED)
        .map_err(|e| e.to_string())?;
    let png = rendered.image.to_luma8(0.0, 1.0);
    png.save(&args.png)
        .map_err(|e| format!("cannot write {}: {e}", args.png.display()))?;
    let corners: Vec<_> = rendered
        .corners
        .iter()
        .map(|c| json!({ "row": c.row, "col": c.col, "x": c.x, "y": c.y, "visible": c.visible }))
        .collect();
    let visible = rendered.corners.iter().filter(|c| c.visible).count();
    let truth = json!({
        "width": scene.camera.width, "height": scene.camera.height,
        "rows": scene.rows, "cols": scene.cols,
        "noise_seed": SPEED_BENCHMARK_NOISE_SEED,
        "blur": scene.blur, "noise": scene.noise,
        "corners": corners,
    });
    std::fs::write(&args.truth, format!("{truth}\n"))
        .map_err(|e| format!("cannot write {}: {e}", args.truth.display()))?;
    eprintln!(
        "render-board: {} ({visible} of {} corners visible), {}",
        args.png.display(),
        rendered.corners.len(),
        args.truth.display()
    );
    Ok(())
}
