//! `conic-corners detect`: boards in images, one JSON object (or CSV rows) per image.

use crate::draw::{draw_board_fits, draw_detection};
use crate::RefineOptions;
use clap::Args;
use conic_corners::board_fit::fit_board_with_curves;
use conic_corners::detect::{detect, DetectParams, Detection, RefineMode};
use conic_corners::pattern::Pattern;
use conic_corners::GrayImage;
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use serde_json::json;
use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

#[derive(Args)]
pub struct DetectArgs {
    /// Image files (PNG, JPEG, TIFF, BMP, PNM, WebP, GIF; 8 or 16 bit; colour is converted to grey).
    #[arg(required = true)]
    images: Vec<PathBuf>,
    /// Expected number of corners N (optional): the pre-filter then keeps the best 2N candidates.
    #[arg(long, value_name = "N")]
    corners: Option<i64>,
    /// Scale (px) of the Hessian pre-filter; about a fifth of the smallest square side works.
    #[arg(long, default_value_t = DetectParams::default().prefilter.sigma)]
    sigma: f32,
    /// The board's inner corners, ROWSxCOLS (OpenCV's patternSize (w, h) is hxw): boards that span
    /// it are labelled in its frame, (0, 0) where the print says (the first square dark; if the
    /// colours cannot tell, the corner nearest the image's top-left), so that every view labels
    /// each physical corner alike; other boards are dropped.
    #[arg(long, value_name = "ROWSxCOLS", value_parser = parse_pattern)]
    pattern: Option<Pattern>,
    /// Smallest board (corners) reported.
    #[arg(long, default_value_t = DetectParams::default().labels.min_corners)]
    min_board_corners: usize,
    /// Write the image with corners, grid edges and labels drawn on it (one input image only); in
    /// board mode (the default) also the edge samples and the fitted curves.
    #[arg(long, value_name = "OUT.png", conflicts_with = "draw_dir")]
    draw: Option<PathBuf>,
    /// Write one overlay per input image into DIR (named after the input, as PNG).
    #[arg(long, value_name = "DIR")]
    draw_dir: Option<PathBuf>,
    /// How corners are placed: `local` (single-corner refiner) or `board` (row and column curves
    /// fitted along the whole board, local where a line has too few samples). Corners the local
    /// refiner fails on or sees on one side only, and doubtful board answers, take the junction
    /// model (path `junction`), failing that the gradient estimate (path `gradient`). A corner
    /// beside hairline slivers at a silhouette that none of them places, or places less surely,
    /// keeps the completion's fit there (path `hairline`).
    #[arg(long = "refine", value_name = "MODE", default_value = "board", value_parser = ["local", "board"])]
    mode: String,
    /// Print CSV rows (image,board,row,col,x,y,score,status,path,sigma,cov_xx,cov_xy,cov_yy)
    /// instead of JSON.
    #[arg(long)]
    csv: bool,
    #[command(flatten)]
    refine: RefineOptions,
}

impl DetectArgs {
    fn params(&self) -> Result<DetectParams, String> {
        let mut params = DetectParams::default();
        params.prefilter.expected_corners = match self.corners {
            None => None,
            Some(n) if n >= 1 => Some(n as usize),
            Some(n) => return Err(format!("--corners must be at least 1, got {n}")),
        };
        params.prefilter.sigma = self.sigma;
        if self.min_board_corners < 4 {
            return Err(format!(
                "--min-board-corners must be at least 4, got {}",
                self.min_board_corners
            ));
        }
        params.labels.min_corners = self.min_board_corners;
        params.pattern = self.pattern;
        params.refine = self.refine.to_params(params.refine.clone())?;
        params.share_sampling();
        params.mode = if self.mode == "board" {
            RefineMode::Board
        } else {
            RefineMode::Local
        };
        params.validate()?;
        Ok(params)
    }
}

/// `ROWSxCOLS` (also `X` or `×`), each at least 2.
fn parse_pattern(s: &str) -> Result<Pattern, String> {
    let bad = || format!("expected ROWSxCOLS (inner corners, e.g. 6x9), got {s:?}");
    let (r, c) = s.split_once(['x', 'X', '×']).ok_or_else(bad)?;
    let (rows, cols) = (
        r.trim().parse().map_err(|_| bad())?,
        c.trim().parse().map_err(|_| bad())?,
    );
    let p = Pattern { rows, cols };
    p.validate()?;
    Ok(p)
}

/// JSON object of one image's detection.
pub fn detection_json(path: &Path, image: &GrayImage, det: &Detection) -> serde_json::Value {
    let boards: Vec<_> = det
        .boards
        .iter()
        .map(|b| {
            let corners: Vec<_> = b
                .corners
                .iter()
                .map(|c| {
                    json!({
                        "x": c.x, "y": c.y, "row": c.row, "col": c.col, "score": c.score,
                        "status": c.status, "residual": c.residual, "path": c.path,
                        "sigma": c.sigma, "cov": c.cov,
                    })
                })
                .collect();
            json!({ "rows": b.rows, "cols": b.cols, "sigma_scale": b.sigma_scale, "corners": corners })
        })
        .collect();
    json!({
        "image": { "path": path.display().to_string(), "width": image.width(), "height": image.height() },
        "boards": boards,
        "timing_ms": det.timing,
    })
}

fn csv_rows(path: &Path, det: &Detection) -> String {
    let mut out = String::new();
    for (bi, b) in det.boards.iter().enumerate() {
        for c in &b.corners {
            let status = serde_json::to_value(c.status).expect("status serializes");
            let how = serde_json::to_value(c.path).expect("path serializes");
            // Empty sigma and covariance fields where the corner has none (refinement failed).
            let sigma = c.sigma.map_or(String::new(), |v| format!("{v:.6}"));
            let cov = c.cov.map_or(",,".to_string(), |m| {
                format!("{:.6e},{:.6e},{:.6e}", m[0][0], m[0][1], m[1][1])
            });
            out.push_str(&format!(
                "{},{bi},{},{},{:.6},{:.6},{:.4},{},{},{sigma},{cov}\n",
                csv_field(&path.display().to_string()),
                c.row,
                c.col,
                c.x,
                c.y,
                c.score,
                status.as_str().unwrap_or(""),
                how.as_str().unwrap_or("")
            ));
        }
    }
    out
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn overlay_path(args: &DetectArgs, input: &Path) -> Option<PathBuf> {
    if let Some(p) = &args.draw {
        return Some(p.clone());
    }
    let dir = args.draw_dir.as_ref()?;
    let stem = input
        .file_stem()
        .map_or("image".into(), |s| s.to_string_lossy().into_owned());
    Some(dir.join(format!("{stem}.png")))
}

fn process(args: &DetectArgs, params: &DetectParams, path: &Path) -> Result<String, String> {
    let image = GrayImage::open(path).map_err(|e| e.to_string())?;
    let det = detect(&image, params);
    if let Some(out) = overlay_path(args, path) {
        let mut picture = draw_detection(&image, &det);
        if params.mode == RefineMode::Board {
            // The curves are recomputed for the picture only; `detect` keeps just the corners.
            let fits: Vec<_> = det
                .boards
                .iter()
                .map(|b| fit_board_with_curves(&image, b, &params.board_fit))
                .collect();
            draw_board_fits(&mut picture, &fits);
        }
        picture
            .save(&out)
            .map_err(|e| format!("cannot write {}: {e}", out.display()))?;
    }
    Ok(if args.csv {
        csv_rows(path, &det)
    } else {
        format!("{}\n", detection_json(path, &image, &det))
    })
}

pub fn run(args: &DetectArgs) -> Result<(), String> {
    let params = args.params()?;
    if args.draw.is_some() && args.images.len() > 1 {
        return Err("--draw takes one image; use --draw-dir DIR for several".into());
    }
    if let Some(dir) = &args.draw_dir {
        std::fs::create_dir_all(dir)
            .map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    }
    let bar = (args.images.len() > 1 && std::io::stderr().is_terminal()).then(|| {
        let bar = ProgressBar::new(args.images.len() as u64);
        bar.set_style(
            ProgressStyle::with_template("{bar:40} {pos}/{len} images {elapsed}<{eta}")
                .expect("valid template"),
        );
        bar
    });
    if args.csv {
        println!("image,board,row,col,x,y,score,status,path,sigma,cov_xx,cov_xy,cov_yy");
    }
    // Results are printed in input order as soon as every earlier image is done.
    let next = Mutex::new((
        0usize,
        vec![None::<Result<String, String>>; args.images.len()],
    ));
    let failures = Mutex::new(0usize);
    args.images.par_iter().enumerate().for_each(|(i, path)| {
        let result = process(args, &params, path);
        let mut guard = next.lock().expect("no panics while holding the lock");
        guard.1[i] = Some(result);
        let stdout = std::io::stdout();
        let mut out = stdout.lock();
        while guard.0 < guard.1.len() {
            let k = guard.0;
            let Some(done) = guard.1[k].take() else { break };
            match done {
                Ok(text) => {
                    let _ = out.write_all(text.as_bytes());
                }
                Err(message) => {
                    *failures.lock().expect("no panics while holding the lock") += 1;
                    match &bar {
                        Some(bar) => bar.println(format!("error: {message}")),
                        None => eprintln!("error: {message}"),
                    }
                }
            }
            guard.0 += 1;
        }
        let _ = out.flush();
        if let Some(bar) = &bar {
            bar.inc(1);
        }
    });
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
    let failed = failures.into_inner().expect("lock not poisoned");
    if failed > 0 {
        Err(format!(
            "{failed} of {} images could not be processed",
            args.images.len()
        ))
    } else {
        Ok(())
    }
}
