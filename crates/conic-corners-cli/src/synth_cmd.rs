//! `conic-corners synth`: one synthetic single-corner image with its exact truth.

use clap::Args;
use conic_corners::synth::{scene_for, CornerScene, Protocol};
use rand::SeedableRng;
use std::path::PathBuf;

#[derive(Args)]
pub struct SynthArgs {
    /// Output image (8-bit PNG; other extensions pick other formats).
    #[arg(long)]
    out: PathBuf,
    /// Draw the scene as the paper's test PROTOCOL does (noise, blur, perspective, curvature) at
    /// sweep value --value; the explicit options below then override single factors.
    #[arg(long)]
    protocol: Option<String>,
    /// Sweep value for --protocol (noise: fraction of full scale, blur: px, perspective: degrees,
    /// curvature: 1/px).
    #[arg(long)]
    value: Option<f64>,
    /// Seed of the scene draw and of the noise.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Image width and height (px).
    #[arg(long)]
    size: Option<usize>,
    /// Curvature of the two edges "K1,K2" (1/px, signed).
    #[arg(long, value_parser = crate::parse_point)]
    curvature: Option<[f64; 2]>,
    /// Angle between the two edges (degrees).
    #[arg(long)]
    edge_angle: Option<f64>,
    /// In-plane rotation (degrees).
    #[arg(long)]
    rotation: Option<f64>,
    /// Out-of-plane rotation φ (degrees).
    #[arg(long)]
    tilt: Option<f64>,
    /// Bright level In (dark is 0, full scale 1).
    #[arg(long)]
    intensity: Option<f64>,
    /// Gaussian blur σ (px).
    #[arg(long)]
    blur: Option<f64>,
    /// Gaussian noise σn (fraction of full scale).
    #[arg(long)]
    noise: Option<f64>,
    /// Corner offset "DX,DY" from the image centre (px).
    #[arg(long, value_parser = crate::parse_point)]
    offset: Option<[f64; 2]>,
}

pub fn run(args: &SynthArgs) -> Result<(), String> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(args.seed);
    let mut scene = match (&args.protocol, args.value) {
        (Some(name), Some(value)) => {
            let p = Protocol::ALL
                .into_iter()
                .find(|p| p.name() == name)
                .ok_or_else(|| {
                    format!("unknown protocol \"{name}\" (noise, blur, perspective, curvature)")
                })?;
            scene_for(p, value, &mut rng)
        }
        (None, None) => CornerScene::default(),
        _ => return Err("--protocol and --value go together".into()),
    };
    let deg = f64::to_radians;
    if let Some(v) = args.size {
        scene.size = v;
    }
    if let Some(v) = args.curvature {
        scene.curvature = v;
    }
    if let Some(v) = args.edge_angle {
        scene.edge_angle = deg(v);
    }
    if let Some(v) = args.rotation {
        scene.rotation = deg(v);
    }
    if let Some(v) = args.tilt {
        scene.tilt = deg(v);
    }
    if let Some(v) = args.intensity {
        scene.intensity = v;
    }
    if let Some(v) = args.blur {
        scene.blur = v;
    }
    if let Some(v) = args.noise {
        scene.noise = v;
    }
    if let Some(v) = args.offset {
        scene.offset = v;
    }
    let rendered = scene.render(args.seed).map_err(|e| e.to_string())?;
    rendered
        .image
        .to_luma8(0.0, 1.0)
        .save(&args.out)
        .map_err(|e| format!("cannot write {}: {e}", args.out.display()))?;
    crate::print_json(&serde_json::json!({
        "image": args.out.display().to_string(),
        "truth": rendered.truth,
        "scene": {
            "size": scene.size, "curvature": scene.curvature,
            "edge_angle_deg": scene.edge_angle.to_degrees(), "rotation_deg": scene.rotation.to_degrees(),
            "tilt_deg": scene.tilt.to_degrees(), "tilt_axis_deg": scene.tilt_axis.to_degrees(),
            "intensity": scene.intensity, "blur": scene.blur, "noise": scene.noise,
        },
    }))
}
