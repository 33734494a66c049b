//! End-to-end tests of the `conic-corners` binary: outputs, exit codes and messages.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_conic-corners"))
}

fn tmp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("conic-corners-cli-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A blurred, area-sampled checker corner at `(cx, cy)`, edges at 20° and 110°, written as 8-bit PNG.
fn write_corner(path: &Path, cx: f64, cy: f64) {
    let (w, h) = (201u32, 181u32);
    let (t1, t2) = (20f64.to_radians(), 110f64.to_radians());
    let ss = 8;
    let img = image::GrayImage::from_fn(w, h, |x, y| {
        let mut acc = 0.0;
        for i in 0..ss {
            for j in 0..ss {
                let px = x as f64 - 0.5 + (i as f64 + 0.5) / ss as f64 - cx;
                let py = y as f64 - 0.5 + (j as f64 + 0.5) / ss as f64 - cy;
                let a = px * t1.sin() - py * t1.cos();
                let b = px * t2.sin() - py * t2.cos();
                acc += if a * b > 0.0 { 220.0 } else { 30.0 };
            }
        }
        image::Luma([(acc / (ss * ss) as f64).round() as u8])
    });
    let blurred = image::imageops::blur(&img, 1.5);
    blurred.save(path).unwrap();
}

fn stdout_json(out: &Output) -> serde_json::Value {
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("stdout is one JSON object")
}

fn assert_fails(out: &Output, needle: &str) {
    assert!(!out.status.success(), "expected failure, got success");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(needle), "stderr {err:?} lacks {needle:?}");
    assert!(!err.contains("panicked"), "panic: {err}");
}

#[test]
fn refine_prints_corners_in_input_order() {
    let dir = tmp_dir("order");
    let png = dir.join("corner.png");
    write_corner(&png, 100.3, 90.6);
    let out = bin()
        .args([
            "refine",
            png.to_str().unwrap(),
            "--at",
            "101,91",
            "--at",
            "5,5",
        ])
        .output()
        .unwrap();
    let v = stdout_json(&out);
    let corners = v["corners"].as_array().unwrap();
    assert_eq!(corners.len(), 2);
    let (x, y) = (
        corners[0]["x"].as_f64().unwrap(),
        corners[0]["y"].as_f64().unwrap(),
    );
    assert_eq!(corners[0]["status"], "converged");
    // The blur of `image::imageops::blur` is not exactly Gaussian and the file is 8-bit: 0.05 px.
    assert!(
        (x - 100.3).abs() < 0.05 && (y - 90.6).abs() < 0.05,
        "{x} {y}"
    );
    assert_eq!(corners[1]["status"], "failed");
    assert!(corners[1]["residual"].is_null());
}

#[test]
fn refine_reads_points_from_a_json_file() {
    let dir = tmp_dir("points");
    let png = dir.join("corner.png");
    write_corner(&png, 100.3, 90.6);
    let pts = dir.join("points.json");
    std::fs::write(&pts, "[[99.0, 91.5], [100.0, 90.0]]").unwrap();
    let out = bin()
        .args([
            "refine",
            png.to_str().unwrap(),
            "--points",
            pts.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let v = stdout_json(&out);
    for c in v["corners"].as_array().unwrap() {
        assert_eq!(c["status"], "converged");
        assert!((c["x"].as_f64().unwrap() - 100.3).abs() < 0.05);
    }
}

#[test]
fn bad_input_gives_a_clear_error_and_nonzero_exit() {
    let dir = tmp_dir("bad");
    let png = dir.join("corner.png");
    write_corner(&png, 100.3, 90.6);
    let p = png.to_str().unwrap();
    // Missing file.
    assert_fails(
        &bin()
            .args(["refine", "/no/such/file.png", "--at", "1,1"])
            .output()
            .unwrap(),
        "/no/such/file.png",
    );
    // Not an image.
    let txt = dir.join("notes.png");
    std::fs::write(&txt, "not an image").unwrap();
    assert_fails(
        &bin()
            .args(["refine", txt.to_str().unwrap(), "--at", "1,1"])
            .output()
            .unwrap(),
        "notes.png",
    );
    // Truncated PNG.
    let bytes = std::fs::read(&png).unwrap();
    let cut = dir.join("cut.png");
    std::fs::write(&cut, &bytes[..bytes.len() / 3]).unwrap();
    assert_fails(
        &bin()
            .args(["refine", cut.to_str().unwrap(), "--at", "1,1"])
            .output()
            .unwrap(),
        "cut.png",
    );
    // Empty file.
    let empty = dir.join("empty.png");
    std::fs::write(&empty, b"").unwrap();
    assert_fails(
        &bin()
            .args(["refine", empty.to_str().unwrap(), "--at", "1,1"])
            .output()
            .unwrap(),
        "empty.png",
    );
    // No points, malformed points, NaN points.
    assert_fails(&bin().args(["refine", p]).output().unwrap(), "no points");
    assert_fails(
        &bin().args(["refine", p, "--at", "1;2"]).output().unwrap(),
        "X,Y",
    );
    assert_fails(
        &bin().args(["refine", p, "--at", "NaN,2"]).output().unwrap(),
        "finite",
    );
    let bad = dir.join("bad.json");
    std::fs::write(&bad, "{\"x\": 1}").unwrap();
    assert_fails(
        &bin()
            .args(["refine", p, "--points", bad.to_str().unwrap()])
            .output()
            .unwrap(),
        "array",
    );
    // Absurd parameters.
    assert_fails(
        &bin()
            .args(["refine", p, "--at", "1,1", "--reach=-3"])
            .output()
            .unwrap(),
        "reach",
    );
    assert_fails(
        &bin()
            .args(["refine", p, "--at", "1,1", "--stride", "0"])
            .output()
            .unwrap(),
        "stride",
    );
    assert_fails(
        &bin()
            .args(["refine", p, "--at", "1,1", "--blur", "inf"])
            .output()
            .unwrap(),
        "blur",
    );
}

#[test]
fn degenerate_images_fail_per_point_without_panicking() {
    let dir = tmp_dir("degenerate");
    for (name, w, h, v) in [("one.png", 1u32, 1u32, 0u8), ("flat.png", 64, 64, 128)] {
        let path = dir.join(name);
        image::GrayImage::from_pixel(w, h, image::Luma([v]))
            .save(&path)
            .unwrap();
        let out = bin()
            .args([
                "refine",
                path.to_str().unwrap(),
                "--at",
                "0,0",
                "--at",
                "30,30",
            ])
            .output()
            .unwrap();
        let v = stdout_json(&out);
        for c in v["corners"].as_array().unwrap() {
            assert_eq!(c["status"], "failed");
        }
    }
}

#[test]
fn colour_and_sixteen_bit_images_are_read_as_grey() {
    let dir = tmp_dir("formats");
    let png = dir.join("corner.png");
    write_corner(&png, 100.3, 90.6);
    let grey = image::open(&png).unwrap();
    let rgb = dir.join("rgb.png");
    grey.to_rgb8().save(&rgb).unwrap();
    let deep = dir.join("deep.png");
    grey.to_luma16().save(&deep).unwrap();
    for path in [rgb, deep] {
        let out = bin()
            .args(["refine", path.to_str().unwrap(), "--at", "101,91"])
            .output()
            .unwrap();
        let v = stdout_json(&out);
        assert_eq!(v["corners"][0]["status"], "converged", "{}", path.display());
        let sigma = v["corners"][0]["sigma"]
            .as_f64()
            .expect("a converged corner has a sigma");
        assert!(sigma > 0.0 && sigma < 0.1, "{sigma}");
        let var_x = v["corners"][0]["cov"][0][0].as_f64().expect("a covariance");
        assert!(
            var_x > 0.0 && var_x <= sigma * sigma * (1.0 + 1e-9),
            "{var_x}"
        );
        assert!((v["corners"][0]["x"].as_f64().unwrap() - 100.3).abs() < 0.05);
    }
}

/// A 7×8-corner flat board seen slightly obliquely by an 800×600 camera, as an 8-bit PNG; returns
/// the visible truth corners.
fn write_board(path: &Path) -> Vec<conic_corners::synth::board::BoardCorner> {
    use conic_corners::synth::board::{BoardScene, PinholeCamera};
    let scene = BoardScene {
        rows: 7,
        cols: 8,
        camera: PinholeCamera {
            width: 800,
            height: 600,
            fx: 700.0,
            fy: 700.0,
            cx: 399.5,
            cy: 299.5,
            k1: 0.0,
            k2: 0.0,
        },
        pose: nalgebra::Isometry3::new(
            nalgebra::Vector3::new(10.0, -5.0, 520.0),
            nalgebra::Vector3::new(0.25, -0.2, 0.1),
        ),
        blur: 1.0,
        noise: 0.01,
        ..BoardScene::default()
    };
    let rendered = scene.render(3).unwrap();
    rendered.image.to_luma8(0.0, 1.0).save(path).unwrap();
    rendered.corners.into_iter().filter(|c| c.visible).collect()
}

/// A detected corner (JSON) lies within 0.1 px of a truth corner.
fn assert_near_truth(c: &serde_json::Value, truth: &[conic_corners::synth::board::BoardCorner]) {
    let (x, y) = (c["x"].as_f64().unwrap(), c["y"].as_f64().unwrap());
    let err = truth
        .iter()
        .map(|t| (t.x - x).hypot(t.y - y))
        .fold(f64::INFINITY, f64::min);
    assert!(err < 0.1, "corner {c} is {err} px from the truth");
}

#[test]
fn detect_finds_and_labels_a_rendered_board() {
    let dir = tmp_dir("detect");
    let png = dir.join("board.png");
    let truth = write_board(&png);
    let overlay = dir.join("overlay.png");
    let out = bin()
        .args([
            "detect",
            png.to_str().unwrap(),
            "--draw",
            overlay.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let v = stdout_json(&out);
    assert_eq!(v["image"]["width"], 800);
    let boards = v["boards"].as_array().unwrap();
    assert_eq!(boards.len(), 1, "{v}");
    let corners = boards[0]["corners"].as_array().unwrap();
    assert_eq!(corners.len(), truth.len());
    for c in corners {
        assert_near_truth(c, &truth);
    }
    assert!(image::open(&overlay).is_ok());
    // CSV: a header and one row per corner.
    let out = bin()
        .args(["detect", png.to_str().unwrap(), "--csv"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.starts_with("image,board,row,col,x,y,score,status,path,sigma,cov_xx,cov_xy,cov_yy\n")
    );
    assert_eq!(text.lines().count(), 1 + truth.len());
    for row in text.lines().skip(1) {
        let f: Vec<&str> = row.split(',').collect();
        assert_eq!(f.len(), 13, "{row}");
        assert!(
            ["board", "local", "junction", "gradient"].contains(&f[8]),
            "{row}"
        );
        let sigma: f64 = f[9].parse().expect("a placed corner has a sigma");
        assert!(sigma > 0.0 && sigma < 1.0, "{row}");
        // σ is the worst direction's: no variance along an axis exceeds σ² (σ printed to 1e-6).
        let cov: Vec<f64> = f[10..]
            .iter()
            .map(|v| v.parse().expect("covariance"))
            .collect();
        assert!(cov[0] > 0.0 && cov[2] > 0.0, "{row}");
        assert!(cov[0].max(cov[2]) <= (sigma + 5e-7).powi(2), "{row}");
    }
}

#[test]
fn detect_reports_no_board_as_an_empty_list() {
    let dir = tmp_dir("noboard");
    let path = dir.join("grey.png");
    image::GrayImage::from_fn(320, 240, |x, y| {
        image::Luma([((x * 7 + y * 3) % 256) as u8])
    })
    .save(&path)
    .unwrap();
    let v = stdout_json(
        &bin()
            .args(["detect", path.to_str().unwrap()])
            .output()
            .unwrap(),
    );
    assert_eq!(v["boards"].as_array().unwrap().len(), 0);
}

#[test]
fn detect_batch_skips_bad_files_and_fails_at_the_end() {
    let dir = tmp_dir("batch");
    let good = dir.join("board.png");
    write_board(&good);
    let bad = dir.join("broken.jpg");
    std::fs::write(&bad, b"\xff\xd8\xff garbage").unwrap();
    let out = bin()
        .args([
            "detect",
            good.to_str().unwrap(),
            bad.to_str().unwrap(),
            good.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert_eq!(
        stdout.lines().count(),
        2,
        "the two good images are still reported"
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("broken.jpg") && err.contains("1 of 3"),
        "{err}"
    );
    assert!(!err.contains("panicked"));
}

#[test]
fn detect_rejects_absurd_parameters() {
    let dir = tmp_dir("detect-params");
    let good = dir.join("board.png");
    write_board(&good);
    let g = good.to_str().unwrap();
    assert_fails(
        &bin()
            .args(["detect", g, "--corners", "0"])
            .output()
            .unwrap(),
        "--corners",
    );
    assert_fails(
        &bin().args(["detect", g, "--corners=-5"]).output().unwrap(),
        "--corners",
    );
    assert_fails(
        &bin().args(["detect", g, "--sigma", "0"]).output().unwrap(),
        "sigma",
    );
    assert_fails(
        &bin()
            .args(["detect", g, g, "--draw", "x.png"])
            .output()
            .unwrap(),
        "--draw-dir",
    );
    assert_fails(
        &bin().args(["detect", "/no/such.png"]).output().unwrap(),
        "/no/such.png",
    );
}

/// `--pattern ROWSxCOLS`: the board in the print's frame (the renderer's truth labels, whose
/// first square is dark), turned where the pattern is given the other way round; no board for
/// another pattern; a clear error for a malformed one.
#[test]
fn detect_labels_a_known_pattern_in_its_frame() {
    let dir = tmp_dir("detect-pattern");
    let png = dir.join("board.png");
    let truth = write_board(&png);
    let p = png.to_str().unwrap();
    let run = |pattern: &str| {
        stdout_json(
            &bin()
                .args(["detect", p, "--pattern", pattern])
                .output()
                .unwrap(),
        )
    };
    let label_of = |c: &serde_json::Value| {
        let (x, y) = (c["x"].as_f64().unwrap(), c["y"].as_f64().unwrap());
        let t = truth
            .iter()
            .min_by(|a, b| {
                (a.x - x)
                    .hypot(a.y - y)
                    .total_cmp(&(b.x - x).hypot(b.y - y))
            })
            .unwrap();
        (t.row as i64, t.col as i64)
    };
    let label = |c: &serde_json::Value| (c["row"].as_i64().unwrap(), c["col"].as_i64().unwrap());
    let v = run("7x8");
    let b = &v["boards"][0];
    assert_eq!(
        (b["rows"].as_u64(), b["cols"].as_u64()),
        (Some(7), Some(8)),
        "{v}"
    );
    let corners = b["corners"].as_array().unwrap();
    assert_eq!(corners.len(), truth.len());
    for c in corners {
        assert_eq!(label(c), label_of(c), "{c}");
    }
    // 8 rows of 7: the same board a quarter turn on, still dark at the first square.
    let v = run("8X7");
    let b = &v["boards"][0];
    assert_eq!(
        (b["rows"].as_u64(), b["cols"].as_u64()),
        (Some(8), Some(7)),
        "{v}"
    );
    for c in b["corners"].as_array().unwrap() {
        let (r, k) = label_of(c);
        assert!([(k, 6 - r), (7 - k, r)].contains(&label(c)), "{c}");
    }
    assert_eq!(run("6x8")["boards"], serde_json::json!([]));
    for bad in ["1x8", "7", "7by8", "x8", "-7x8"] {
        assert_fails(
            &bin()
                .args(["detect", p, &format!("--pattern={bad}")])
                .output()
                .unwrap(),
            "pattern",
        );
    }
}

#[test]
fn detect_board_mode_reports_paths_and_draws_the_curves() {
    let dir = tmp_dir("board-mode");
    let png = dir.join("board.png");
    let truth = write_board(&png);
    let overlay = dir.join("curves.png");
    let out = bin()
        .args([
            "detect",
            png.to_str().unwrap(),
            "--refine",
            "board",
            "--draw",
            overlay.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let v = stdout_json(&out);
    let corners = v["boards"][0]["corners"].as_array().unwrap();
    assert_eq!(corners.len(), truth.len());
    let board_path = corners.iter().filter(|c| c["path"] == "board").count();
    assert!(
        board_path * 2 > corners.len(),
        "{board_path} of {} on the board path",
        corners.len()
    );
    for c in corners {
        assert_near_truth(c, &truth);
        if c["path"] == "board" {
            assert!(c["sigma"].as_f64().unwrap() > 0.0);
        }
        // The covariance, `[[xx, xy], [xy, yy]]` in px², wherever there is a σ.
        let cov = &c["cov"];
        assert_eq!(cov[0][1], cov[1][0], "{c}");
        assert!(cov[0][0].as_f64().unwrap() > 0.0 && cov[1][1].as_f64().unwrap() > 0.0);
    }
    assert!(v["timing_ms"]["board_fit"].as_f64().is_some());
    assert!(image::open(&overlay).is_ok());
    assert_fails(
        &bin()
            .args(["detect", png.to_str().unwrap(), "--refine", "global"])
            .output()
            .unwrap(),
        "global",
    );
}
