//! Whole-pipeline tests of [`detect`] on rendered boards with exact truth (flat, cylinder, S-shape,
//! dots, occluder bars, two boards in one image), and on the real photos of
//! `../shared/images/curved-hydramarker` when that folder exists next to the workspace.
//!
//! What is asserted on renders: every visible truth corner has a detected corner within 1 px (a
//! documented number may be missing next to occluders), every detected corner is within 1.5 px of
//! a truth corner, the labels of each board are the truth labels up to one lattice symmetry and a
//! shift (so truth neighbours differ by ±1 on one axis), and the refined positions' RMS error.

use conic_corners::board_fit::Path;
use conic_corners::detect::{detect, Board, DetectParams, DetectedCorner, Detection};
use conic_corners::prefilter::box_downsample;
use conic_corners::refine::Status;
use conic_corners::synth::board::{
    random_board_scene, BoardCorner, BoardScene, Dots, Occluder, PinholeCamera, Surface,
};
use conic_corners::GrayImage;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::collections::HashMap;

/// The common scene: 9 × 9 corners at 1920 × 1200, blur 1 px, noise 1 % of the 0.1–0.9 range.
fn template() -> BoardScene {
    BoardScene {
        blur: 1.0,
        noise: 0.01,
        supersample: 4,
        ..BoardScene::default()
    }
}

/// Detected corners of every board as `(board, x, y, row, col)`.
fn detected(det: &Detection) -> Vec<(usize, f64, f64, i32, i32)> {
    det.boards
        .iter()
        .enumerate()
        .flat_map(|(b, board)| {
            board
                .corners
                .iter()
                .map(move |c| (b, c.x, c.y, c.row, c.col))
        })
        .collect()
}

/// The eight signed permutations of the label axes.
fn symmetries() -> impl Iterator<Item = impl Fn((i32, i32)) -> (i32, i32)> {
    (0..8).map(|k| {
        move |(r, c): (i32, i32)| {
            let (a, b) = if k & 4 != 0 { (c, r) } else { (r, c) };
            (
                if k & 1 != 0 { -a } else { a },
                if k & 2 != 0 { -b } else { b },
            )
        }
    })
}

/// A truth label and the detected label of one corner.
type LabelPair = ((i32, i32), (i32, i32));

/// Maps a pixel centre `(x, y)` of a turned photo back into the upright photo of size `(w, h)`.
type TurnBack = fn(f64, f64, f64, f64) -> (f64, f64);

/// Parts of a photo: the file and its named windows `(x0, y0, width, height)`.
type PhotoParts = (&'static str, &'static [(&'static str, [usize; 4])]);

struct Outcome {
    missing: usize,
    rms: f64,
}

/// Checks `det` against `truth` (all corners; `visible` ones must be found). Panics with `what`
/// on a false corner or inconsistent labels; returns the missing count and the refined RMS.
fn check(what: &str, det: &Detection, truth: &[BoardCorner]) -> Outcome {
    let found = detected(det);
    let near = |x: f64, y: f64, t: &BoardCorner| (t.x - x).hypot(t.y - y);
    // No false corner.
    let mut pairs: Vec<Vec<LabelPair>> = vec![Vec::new(); det.boards.len()];
    for &(b, x, y, row, col) in &found {
        let best = truth
            .iter()
            .filter(|t| t.x.is_finite())
            .min_by(|p, q| near(x, y, p).total_cmp(&near(x, y, q)))
            .expect("truth");
        let d = near(x, y, best);
        assert!(
            d <= 1.5,
            "{what}: false corner at ({x:.1}, {y:.1}), {d:.2} px from truth"
        );
        pairs[b].push(((best.row as i32, best.col as i32), (row, col)));
    }
    // Labels: one symmetry and one shift per board.
    for (b, p) in pairs.iter().enumerate() {
        let ok = symmetries().any(|s| {
            let shift = |&(t, l): &LabelPair| {
                let st = s(t);
                (l.0 - st.0, l.1 - st.1)
            };
            p.iter().all(|q| shift(q) == shift(&p[0]))
        });
        assert!(
            ok,
            "{what}: board {b} labels are not the truth up to a symmetry"
        );
    }
    // Completeness and accuracy.
    let mut missing = 0;
    let mut sq = 0.0;
    let mut n = 0;
    for t in truth.iter().filter(|t| t.visible) {
        let d = found
            .iter()
            .map(|&(_, x, y, _, _)| near(x, y, t))
            .fold(f64::INFINITY, f64::min);
        if d <= 1.0 {
            sq += d * d;
            n += 1;
        } else {
            missing += 1;
        }
    }
    let rms = (sq / n.max(1) as f64).sqrt();
    eprintln!(
        "{what}: {} boards, {} found, {} visible, {missing} missing, RMS {rms:.4} px",
        det.boards.len(),
        found.len(),
        truth.iter().filter(|t| t.visible).count()
    );
    Outcome { missing, rms }
}

fn run(what: &str, scene: &BoardScene, seed: u64) -> (Outcome, Detection) {
    let r = scene.render(seed).expect("valid scene");
    let det = detect(&r.image, &DetectParams::default());
    (check(what, &det, &r.corners), det)
}

/// A 640 × 480 camera (focal length 600 px, no distortion): low-resolution views.
fn vga() -> PinholeCamera {
    PinholeCamera {
        width: 640,
        height: 480,
        fx: 600.0,
        fy: 600.0,
        cx: 319.5,
        cy: 239.5,
        k1: 0.0,
        k2: 0.0,
    }
}

/// A rotation by `degrees` about the board's x axis (its rows' direction): the board seen more
/// obliquely, to add to a random pose.
fn tilt(degrees: f64) -> nalgebra::Isometry3<f64> {
    nalgebra::Isometry3::rotation(nalgebra::Vector3::x() * degrees.to_radians())
}

fn scene(surface: Surface, seed: u64, edit: impl FnOnce(&mut BoardScene)) -> BoardScene {
    let mut t = template();
    edit(&mut t);
    random_board_scene(&mut ChaCha8Rng::seed_from_u64(seed), surface, &t)
}

/// Accuracy bound at blur 1, noise 1 % with the default board-wide fitting: the measured RMS is
/// 0.006–0.018 px on these scenes (0.010–0.057 px with the local refiner alone).
const RMS_BOUND: f64 = 0.04;

#[test]
fn flat_board_random_pose() {
    for seed in [1, 2] {
        let (o, det) = run("flat", &scene(Surface::Flat, seed, |_| ()), seed);
        assert_eq!(o.missing, 0);
        assert_eq!(det.boards.len(), 1);
        assert!(o.rms < RMS_BOUND, "{}", o.rms);
    }
}

/// The template board facing a VGA camera from 545 mm (squares of about 22 px), turned by
/// `degrees` in its own plane.
fn turned_scene(degrees: f64) -> BoardScene {
    let turn = nalgebra::UnitQuaternion::from_axis_angle(
        &nalgebra::Vector3::z_axis(),
        degrees.to_radians(),
    );
    BoardScene {
        camera: vga(),
        pose: nalgebra::Isometry3::from_parts(nalgebra::Translation3::new(0.0, 0.0, 545.0), turn),
        ..template()
    }
}

/// A flat board turned in its own plane, squares of 22 px (640 × 480): the edges cross the
/// scanlines obliquely, and near every junction the crossing edge cuts the profile windows
/// short. The board-wide fit measures the blur on windows clear of the crossing edges: before
/// it did, the cut windows' assumed widths made the blur 2 px at 45° (1 px rendered), and board
/// mode was 0.025 / 0.051 px off at 40° / 45° (0.011–0.014 px at 0–30°). Measured now:
/// 0.011–0.016 px at every angle. The local refiner's walks end before their neighbours'
/// crossing edges, which their windows reach near a junction on a turned board: 0.024–0.035 px
/// (0.026 / 0.033 / 0.053 / 0.040 / 0.033 px at these angles before).
#[test]
fn board_turned_in_its_plane_keeps_its_accuracy() {
    let local = DetectParams {
        mode: conic_corners::detect::RefineMode::Local,
        ..DetectParams::default()
    };
    for (k, degrees) in [0.0f64, 15.0, 30.0, 40.0, 45.0].into_iter().enumerate() {
        let r = turned_scene(degrees)
            .render(30 + k as u64)
            .expect("valid scene");
        for (mode, params) in [("board", DetectParams::default()), ("local", local.clone())] {
            let det = detect(&r.image, &params);
            let o = check(&format!("turned {degrees}°, {mode}"), &det, &r.corners);
            assert_eq!(o.missing, 0, "{degrees}° {mode}");
            let bound = if mode == "board" { 0.02 } else { 0.045 };
            assert!(o.rms < bound, "{degrees}° {mode}: RMS {}", o.rms);
        }
    }
}

#[test]
fn cylinder_wrapped_board() {
    for (seed, radius) in [(3, 60.0), (4, 120.0)] {
        let s = scene(Surface::Cylinder { radius_mm: radius }, seed, |_| ());
        let (o, det) = run("cylinder", &s, seed);
        assert_eq!(o.missing, 0, "radius {radius}");
        assert_eq!(det.boards.len(), 1);
        assert!(o.rms < RMS_BOUND, "{}", o.rms);
    }
}

#[test]
fn s_shaped_board_with_dots() {
    let dots = Some(Dots {
        radius: 0.2,
        fraction: 0.4,
        seed: 7,
    });
    let s = scene(Surface::SShape { radius_mm: 80.0 }, 5, |t| t.dots = dots);
    let (o, det) = run("s-shape + dots", &s, 5);
    assert_eq!(o.missing, 0);
    assert_eq!(det.boards.len(), 1);
    assert!(o.rms < RMS_BOUND, "{}", o.rms);
}

/// A bar across the board through its centre, `turn` radians from the board's row direction.
fn bar_across(s: &BoardScene, turn: f64, width: f64) -> Occluder {
    let c = s.corners().expect("valid");
    let mid = &c[c.len() / 2];
    let a = &c[c.len() / 2 - 1];
    let dir = (mid.y - a.y).atan2(mid.x - a.x) + turn;
    let len = 2000.0;
    Occluder {
        from: [mid.x - len * dir.cos(), mid.y - len * dir.sin()],
        to: [mid.x + len * dir.cos(), mid.y + len * dir.sin()],
        width,
        intensity: 0.15,
    }
}

#[test]
fn occluder_bars_do_not_split_or_mislabel_the_board() {
    // One bar along the columns (hiding one column of corners), then two crossing bars.
    let mut s = scene(Surface::Flat, 6, |_| ());
    let step = {
        let c = s.corners().unwrap();
        (c[1].x - c[0].x).hypot(c[1].y - c[0].y)
    };
    s.occluders = vec![bar_across(&s, std::f64::consts::FRAC_PI_2, 0.5 * step)];
    let (o, det) = run("one bar", &s, 6);
    assert_eq!(
        det.boards.len(),
        1,
        "the pieces beside the bar are one board"
    );
    // Corners right next to a bar edge (beyond the 3 px truth clearance) can be lost: at most 2.
    assert!(o.missing <= 2, "{}", o.missing);
    assert!(o.rms < RMS_BOUND, "{}", o.rms);

    s.occluders.push(bar_across(&s, 0.4, 0.3 * step));
    let (o, det) = run("two bars", &s, 7);
    assert!(det.boards.len() <= 2);
    assert!(o.missing <= 4, "{}", o.missing);
    assert!(o.rms < RMS_BOUND, "{}", o.rms);
}

#[test]
fn two_boards_side_by_side() {
    let mut t = template();
    t.camera.width = 960;
    t.camera.cx = 479.5;
    t.rows = 6;
    t.cols = 5;
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    let left = random_board_scene(&mut rng, Surface::Flat, &t)
        .render(8)
        .unwrap();
    let right = random_board_scene(&mut rng, Surface::Cylinder { radius_mm: 90.0 }, &t)
        .render(9)
        .unwrap();
    let (w, h) = (960, 1200);
    let mut data = vec![0f32; 2 * w * h];
    for y in 0..h {
        data[y * 2 * w..y * 2 * w + w].copy_from_slice(left.image.row(y));
        data[y * 2 * w + w..(y + 1) * 2 * w].copy_from_slice(right.image.row(y));
    }
    let image = GrayImage::from_vec(2 * w, h, data).unwrap();
    let det = detect(&image, &DetectParams::default());
    assert_eq!(det.boards.len(), 2);
    assert!(det.boards[0].corners.len() >= det.boards[1].corners.len());
    // Check each half against its own truth, the other board's corners filtered out by side.
    for (half, truth) in [(0, &left.corners), (1, &right.corners)] {
        let mut sub = Detection {
            boards: det.boards.clone(),
            timing: det.timing,
        };
        for b in sub.boards.iter_mut() {
            b.corners.retain(|c| (c.x >= w as f64) == (half == 1));
            for c in b.corners.iter_mut() {
                c.x -= (half * w) as f64;
            }
        }
        sub.boards.retain(|b| !b.corners.is_empty());
        assert_eq!(sub.boards.len(), 1, "each board stays on its side");
        let o = check(if half == 0 { "left" } else { "right" }, &sub, truth);
        assert_eq!(o.missing, 0);
        assert!(o.rms < RMS_BOUND, "{}", o.rms);
    }
}

/// Convex hull (counter-clockwise in a y-up sense; orientation does not matter below).
fn hull(mut p: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    p.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let cross = |o: (f64, f64), a: (f64, f64), b: (f64, f64)| {
        (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0)
    };
    let mut h: Vec<(f64, f64)> = Vec::new();
    for pass in 0..2 {
        let start = h.len();
        let it: Box<dyn Iterator<Item = &(f64, f64)>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for &q in it {
            while h.len() >= start + 2 && cross(h[h.len() - 2], h[h.len() - 1], q) <= 0.0 {
                h.pop();
            }
            h.push(q);
        }
        h.pop();
    }
    h
}

fn inside(h: &[(f64, f64)], q: (f64, f64)) -> bool {
    h.len() >= 3
        && (0..h.len()).all(|i| {
            let (a, b) = (h[i], h[(i + 1) % h.len()]);
            (b.0 - a.0) * (q.1 - a.1) - (b.1 - a.1) * (q.0 - a.0) > 0.0
        })
}

/// The real photos' directory, `None` (with a note) where it is absent.
fn photos() -> Option<std::path::PathBuf> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/images/curved-hydramarker");
    if !dir.is_dir() {
        eprintln!("skipped: {} not found", dir.display());
        return None;
    }
    Some(dir)
}

#[test]
fn real_photos_when_present() {
    let Some(dir) = photos() else {
        return;
    };
    // Labelled corners achieved (lower bounds); each photo shows one board.
    let expected = [
        ("curve_4.jpg", 110),
        ("curve_5.jpg", 110),
        ("curve_6.jpg", 110),
        ("curve_7.jpg", 110),
        ("curve_8.jpg", 110),
        ("marker_real.jpg", 94),
        ("marker_real2.jpg", 121),
        ("marker_real3.jpg", 87),
    ];
    for (name, at_least) in expected {
        let image = GrayImage::open(dir.join(name)).expect("readable photo");
        // Unplaced corners kept, so that the test below can see them.
        let keep = DetectParams {
            keep_unrefined: true,
            ..DetectParams::default()
        };
        let det = detect(&image, &keep);
        let n: usize = det.boards.iter().map(|b| b.corners.len()).sum();
        eprintln!("{name}: {} boards, {n} corners", det.boards.len());
        assert!(n >= at_least, "{name}: {n} corners, expected ≥ {at_least}");
        assert_eq!(det.boards.len(), 1, "{name}");
        // Every labelled corner is placed: where the refiners fail (pen strokes through the
        // junction), the board's curves still meet.
        let failed: Vec<(i32, i32)> = det.boards[0]
            .corners
            .iter()
            .filter(|c| c.status == Status::Failed)
            .map(|c| (c.row, c.col))
            .collect();
        assert!(failed.is_empty(), "{name}: unplaced corners {failed:?}");
        let corner = |label: (i32, i32)| {
            det.boards[0]
                .corners
                .iter()
                .find(|c| (c.row, c.col) == label)
                .unwrap_or_else(|| panic!("{name}: corner {label:?}"))
        };
        if name == "marker_real2.jpg" {
            // A pen stroke runs through the junction of (6, 8) and pulls the election's maximum
            // 11 px off it; the refiner's second start (from the neighbours) finds the junction.
            // Its centre, read off the pixel rows: the vertical edges at x = 1937.3 above and
            // 1939.6 below (dot gain), the horizontal edge at y = 1458.6.
            let c = corner((6, 8));
            assert_eq!(c.status, Status::Converged, "{c:?}");
            assert!((c.x - 1938.5).hypot(c.y - 1459.0) < 1.5, "{c:?}");
        }
        if name == "curve_4.jpg" {
            // (4, 0) is a board-wide answer beside a sliver at the S's silhouette that claims
            // σ 3 px: nothing better places it, but it is no converged answer.
            let c = corner((4, 0));
            assert!(c.sigma.is_some_and(|s| s > 1.0), "{c:?}");
            assert_eq!(c.status, Status::Fallback, "{c:?}");
        }
        if name == "curve_6.jpg" {
            // Beside a sliver 12 px wide at the S's silhouette. (5, 0): the edge walks from the
            // site end 9 px off its junction, the gradient estimate lands on it and the junction
            // model confirms it; the corner of the dark square above it, read off the pixels, is
            // at about (402, 2019). (6, 0) needs the junction model's wider window to confirm
            // it, and (7, 0) is then predicted and confirmed; on 4× crops their junctions are at
            // about (416, 2186) and (426.3, 2340.5).
            for (label, at) in [
                ((5, 0), [402.0, 2019.0]),
                ((6, 0), [416.0, 2186.0]),
                ((7, 0), [426.3, 2340.5]),
            ] {
                let c = corner(label);
                assert!((c.x - at[0]).hypot(c.y - at[1]) < 2.5, "{c:?}");
            }
        }
        let hulls: Vec<_> = det
            .boards
            .iter()
            .map(|b| hull(b.corners.iter().map(|c| (c.x, c.y)).collect()))
            .collect();
        for (a, ha) in hulls.iter().enumerate() {
            for (b, board) in det.boards.iter().enumerate() {
                assert!(
                    a == b || board.corners.iter().all(|c| !inside(ha, (c.x, c.y))),
                    "{name}: boards {a} and {b} overlap"
                );
            }
        }
    }
}

/// Asserts that `det` holds exactly one board of `shape` (rows and columns in either order) with
/// `count` distinct labels, none of them unplaced.
fn assert_one_board(det: &Detection, shape: [usize; 2], count: usize, what: &str) {
    assert_eq!(det.boards.len(), 1, "{what}");
    let b = &det.boards[0];
    let mut s = [b.rows, b.cols];
    s.sort();
    assert_eq!(s, shape, "{what}");
    let labels: std::collections::HashSet<_> = b.corners.iter().map(|c| (c.row, c.col)).collect();
    assert_eq!(labels.len(), count, "{what}");
    assert!(
        b.corners.iter().all(|c| c.status != Status::Failed),
        "{what}"
    );
}

/// Distance (px) between the two boards' corners of each label of `a` (both boards carry the
/// same labels: one image in two refine modes).
fn label_gaps<'a>(a: &'a Board, b: &'a Board) -> impl Iterator<Item = f64> + 'a {
    a.corners.iter().map(move |c| {
        let o = b
            .corners
            .iter()
            .find(|o| (o.row, o.col) == (c.row, c.col))
            .expect("same labels in both modes");
        (c.x - o.x).hypot(c.y - o.y)
    })
}

/// OpenCV's stereo calibration sample (`examples/opencv-stereo`): 26 JPEG photos, 640 × 480, of
/// a flat board of 9 × 6 inner corners. Every corner is found and labelled in every photo, and
/// the two refine modes agree (measured: median 0.044 px, largest 0.35 px).
/// The calibration check is the Python test `test_opencv_stereo.py`.
#[test]
fn opencv_stereo_sample_every_corner_labelled_and_both_refiners_agree() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/opencv-stereo");
    let mut names: Vec<_> = std::fs::read_dir(&dir)
        .expect("examples/opencv-stereo")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "jpg"))
        .collect();
    names.sort();
    assert_eq!(names.len(), 26);
    let local = DetectParams {
        mode: conic_corners::detect::RefineMode::Local,
        ..DetectParams::default()
    };
    let mut gaps = Vec::new();
    for path in &names {
        let image = GrayImage::open(path).expect("readable photo");
        let board = detect(&image, &DetectParams::default());
        let other = detect(&image, &local);
        for det in [&board, &other] {
            assert_one_board(det, [6, 9], 54, &path.display().to_string());
        }
        gaps.extend(label_gaps(&board.boards[0], &other.boards[0]));
    }
    gaps.sort_by(f64::total_cmp);
    let (median, largest) = (gaps[gaps.len() / 2], gaps[gaps.len() - 1]);
    eprintln!("board against local: median {median:.4} px, largest {largest:.4} px");
    assert!(median < 0.1 && largest < 0.6, "{median} {largest}");
}

/// OpenCV's ChArUco photo (`examples/opencv-charuco`): a printed board of 4 × 6 inner corners
/// with an ArUco marker in every white square. The markers' own corners and edges are no board
/// corners: one board of all 24 junctions. (The Python test `test_opencv_stereo.py` checks the
/// labels against OpenCV's ChArUco detector.)
#[test]
fn charuco_markers_in_the_white_squares_are_no_corners() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/opencv-charuco/choriginal.jpg");
    let image = GrayImage::open(&path).expect("readable photo");
    let det = detect(&image, &DetectParams::default());
    assert_one_board(&det, [4, 6], 24, "choriginal.jpg");
}

/// OpenCV's omnidirectional camera sample (`examples/opencv-omnidir`): a flat board of 6 × 9 inner
/// corners seen through a lens of about 360°, whose grid lines the image bends strongly
/// (`sample.jpg`), and three of OpenCV's rectifications of that photo (cylindrical,
/// longitude-latitude, stereographic), where they bend other ways and the board runs off the
/// image. Every corner inside the image is found and labelled in both modes, and the two
/// refiners agree. In `sample_rec_log.jpg` two rows lie above the image; in `sample_rec_cyl.jpg`
/// three corners of the last row lie below it or on its last rows (one 6 px from the edge, where
/// the lower half of its window is missing). The Python test `test_opencv_omnidir.py` fits one
/// pose to `sample.jpg`'s corners with the camera calibrated from the other views.
#[test]
fn opencv_omnidir_sample_bent_grid_lines_every_corner_inside_labelled() {
    let dir =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/opencv-omnidir");
    let local = DetectParams {
        mode: conic_corners::detect::RefineMode::Local,
        ..DetectParams::default()
    };
    for (name, shape, count) in [
        ("sample.jpg", [6, 9], 54),
        ("sample_rec_cyl.jpg", [6, 9], 51),
        ("sample_rec_log.jpg", [6, 7], 42),
        ("sample_rec_ste.jpg", [6, 9], 54),
    ] {
        let image = GrayImage::open(dir.join(name)).expect("readable photo");
        let board = detect(&image, &DetectParams::default());
        let other = detect(&image, &local);
        for det in [&board, &other] {
            assert_one_board(det, shape, count, name);
        }
        let mut gaps: Vec<f64> = label_gaps(&board.boards[0], &other.boards[0]).collect();
        gaps.sort_by(f64::total_cmp);
        let (median, largest) = (gaps[gaps.len() / 2], gaps[gaps.len() - 1]);
        eprintln!("{name}: board against local: median {median:.4} px, largest {largest:.4} px");
        assert!(median < 0.1, "{name}: {median} {largest}");
        // The rectifications resample the photo, stretching it most near the lens's
        // rim: there the largest gaps are 0.36–1.02 px (`sample_rec_cyl.jpg` (7, 0), (8, 3),
        // (8, 4), smeared junctions where the local refiner falls back to the junction model).
        if name == "sample.jpg" {
            assert!(largest < 0.6, "{name}: {largest}");
        }
    }
}

/// The label offsets (whole minus part, with their counts) of a board found in a part of a
/// photo against the whole photo's board: each corner of `part`, mapped into the photo's pixels
/// by `to_photo`, is matched to the nearest corner of `whole` if that lies within `tolerance` px.
fn label_offsets(
    whole: &Board,
    part: &Board,
    to_photo: impl Fn(f64, f64) -> (f64, f64),
    tolerance: f64,
) -> HashMap<(i32, i32), usize> {
    let mut offsets = HashMap::new();
    for c in &part.corners {
        let (x, y) = to_photo(c.x, c.y);
        let d = |m: &&DetectedCorner| (m.x - x).hypot(m.y - y);
        let m = whole
            .corners
            .iter()
            .min_by(|a, b| d(a).total_cmp(&d(b)))
            .unwrap();
        if d(&m) < tolerance {
            *offsets.entry((m.row - c.row, m.col - c.col)).or_default() += 1;
        }
    }
    offsets
}

/// A photo turned by a quarter or a half turn shows the same corners: nothing in the method
/// depends on which way the board's labels run. Before the completion's frames were taken from
/// both sides of a site alike, `curve_6.jpg` turned by 180° lost 12 of its 105 corners and
/// `curve_4.jpg` 5 of 110 (the sites' frames, and with them which slivers at the silhouette
/// passed, followed the labels' order). A corner of the turned photo, turned back, counts as the
/// same within 3 px; at most two may differ either way (sliver corners whose verification is
/// decided by a fraction of a pixel).
#[test]
fn a_turned_photo_gives_the_same_corners() {
    let Some(dir) = photos() else {
        return;
    };
    let corners = |det: &Detection| -> Vec<(f64, f64)> {
        det.boards
            .iter()
            .flat_map(|b| b.corners.iter().map(|c| (c.x, c.y)))
            .collect()
    };
    let names = [
        "curve_4.jpg",
        "curve_5.jpg",
        "curve_6.jpg",
        "curve_7.jpg",
        "curve_8.jpg",
        "marker_real.jpg",
        "marker_real2.jpg",
        "marker_real3.jpg",
    ];
    for name in names {
        let photo = image::open(dir.join(name)).unwrap();
        let (w, h) = (photo.width() as f64, photo.height() as f64);
        let upright = corners(&detect(
            &GrayImage::from_dynamic(&photo).unwrap(),
            &DetectParams::default(),
        ));
        // Each turn with the map of its pixel centres back into the upright photo.
        let turns: [(&str, image::DynamicImage, TurnBack); 2] = [
            ("180°", photo.rotate180(), |x, y, w, h| {
                (w - 1.0 - x, h - 1.0 - y)
            }),
            ("90°", photo.rotate90(), |x, y, _, h| (y, h - 1.0 - x)),
        ];
        for (turn, image, back) in turns {
            let turned: Vec<(f64, f64)> = corners(&detect(
                &GrayImage::from_dynamic(&image).unwrap(),
                &DetectParams::default(),
            ))
            .into_iter()
            .map(|(x, y)| back(x, y, w, h))
            .collect();
            let unmatched = |a: &[(f64, f64)], b: &[(f64, f64)]| {
                a.iter()
                    .filter(|p| b.iter().all(|q| (p.0 - q.0).hypot(p.1 - q.1) > 3.0))
                    .count()
            };
            let (lost, gained) = (unmatched(&upright, &turned), unmatched(&turned, &upright));
            eprintln!(
                "{name} turned by {turn}: {} corners against {}, {lost} lost, {gained} gained",
                turned.len(),
                upright.len()
            );
            assert!(
                lost <= 2 && gained <= 2,
                "{name} turned by {turn}: {lost} lost, {gained} gained"
            );
        }
    }
}

/// Half of a photo: one board whose labels are the whole photo's up to one translation. Without
/// the rest of the board the pieces on either side of an occluder or a fold meet only there:
/// - `marker_real3.jpg`'s top half: a finger hides two corners of row 1, and the pieces meet
///   along rows 0 and 1 only once the completion has filled row 0;
/// - its right half: a pen hides row 8, and the columns meet across it only once row 7 is
///   completed;
/// - `curve_6.jpg`'s bottom half: the S folds away between columns 5 and 6, where the rows turn
///   by 15–30° within a step (the grid links stop there, and the steps beyond the fold disagree
///   with the extrapolated ones by half a step);
/// - two smaller crops: `curve_4.jpg` at the S's ridge, where the rows turn by 40° within a step
///   (the next column lies 0.35 steps off the straight extrapolation), and `marker_real3.jpg`
///   where one row is visible beyond the pens (its completed corners have no step down);
/// - `marker_real3.jpg` beside an upright pen that hides one column: the piece beyond it links
///   the columns on either side of the pen as neighbours, and must not be merged as a fold;
/// - `marker_real3.jpg` with a pen hiding row 8 and only rows 7 and 9 in view: the two rows are
///   linked as neighbours, and the checker phases disagree; the corners of row 9 whose
///   measurement leaves the image must not follow row 7's phase (no board is right here);
/// - `marker_real3.jpg` with a finger hiding rows 2 and 3 and only rows 1 and 4 in view: the
///   phases agree, but no edge runs under the finger between the rows
///   ([`conic_corners::completion::edge_seen`]).
#[test]
fn parts_of_photos_split_by_an_occluder_or_a_fold_are_labelled_like_the_whole() {
    let Some(dir) = photos() else {
        return;
    };
    // (x0, y0, width, height); 0 for "to the photo's edge".
    let parts: [PhotoParts; 3] = [
        (
            "marker_real3.jpg",
            &[
                ("top half", [0, 0, 0, 1109]),
                ("right half", [1211, 0, 0, 0]),
                ("pens", [755, 1002, 1530, 1024]),
                ("upright pen", [80, 1003, 1019, 954]),
                ("rows either side of a pen", [261, 1389, 1369, 579]),
                ("rows either side of a finger", [1614, 468, 736, 785]),
            ],
        ),
        ("curve_6.jpg", &[("bottom half", [0, 2000, 0, 0])]),
        ("curve_4.jpg", &[("ridge", [98, 734, 381, 545])]),
    ];
    for (name, parts) in parts {
        let photo = GrayImage::open(dir.join(name)).expect("readable photo");
        let whole = detect(&photo, &DetectParams::default());
        assert_eq!(whole.boards.len(), 1, "{name}");
        let (w, h) = (photo.width(), photo.height());
        for &(half, [x0, y0, cw, ch]) in parts {
            let cw = if cw == 0 { w - x0 } else { cw };
            let ch = if ch == 0 { h - y0 } else { ch };
            let data = (y0..y0 + ch)
                .flat_map(|y| photo.row(y)[x0..x0 + cw].iter().copied())
                .collect();
            let crop = GrayImage::from_vec(cw, ch, data).unwrap();
            let det = detect(&crop, &DetectParams::default());
            if half.starts_with("rows either side") {
                // Two rows only, linked as neighbours across the pen (rows 7 and 9) or the
                // finger (rows 1 and 4): no board (each was one, its rows labelled 0 and 1).
                assert!(det.boards.is_empty(), "{name} {half}");
                continue;
            }
            assert_eq!(det.boards.len(), 1, "{name} {half}");
            let offsets = label_offsets(
                &whole.boards[0],
                &det.boards[0],
                |x, y| (x + x0 as f64, y + y0 as f64),
                3.0,
            );
            let n = det.boards[0].corners.len();
            assert_eq!(offsets.len(), 1, "{name} {half}: {offsets:?}");
            // A few crop corners have no counterpart: the whole photo misses (1, 7) of
            // `marker_real3.jpg` at the fingertip, and places (3, 4) beside the pen 8 px away.
            assert!(
                offsets.values().sum::<usize>() * 10 >= n * 9,
                "{name} {half}: {offsets:?} of {n}"
            );
            eprintln!("{name} {half}: {n} corners, label offset {offsets:?}");
        }
    }
}

/// Parts of the S-shaped photos scaled down (a board seen from farther away), across the S's
/// ridge: there the columns narrow to a third of the others' width and the rows drop by half a
/// square per column, and at these scales the corners of the narrowest columns are missed.
/// The pieces on either side then extrapolate their rows across the gap with their own steps,
/// and land one column apart. Each board found must be labelled like the whole photo (two
/// boards are acceptable, wrong labels are not), and no two of its corners may coincide: in the
/// last part, the board's curves for a corner met at its neighbour's junction, and the local
/// refiner started there confirmed it.
#[test]
fn a_ridge_seen_from_afar_is_never_mislabelled() {
    let Some(dir) = photos() else {
        return;
    };
    // (photo, [x0, y0, width, height], scale)
    let parts: [(&str, [u32; 4], f64); 5] = [
        ("curve_5.jpg", [0, 295, 1280, 295], 0.25),
        ("curve_5.jpg", [165, 312, 732, 268], 0.25),
        ("curve_5.jpg", [137, 294, 940, 223], 0.35),
        ("curve_4.jpg", [136, 706, 487, 419], 0.35),
        ("curve_5.jpg", [380, 38, 854, 436], 0.33),
    ];
    for (name, [x0, y0, cw, ch], scale) in parts {
        let path = dir.join(name);
        let whole = detect(&GrayImage::open(&path).unwrap(), &DetectParams::default());
        assert_eq!(whole.boards.len(), 1, "{name}");
        let (w, h) = (
            (cw as f64 * scale).round() as u32,
            (ch as f64 * scale).round() as u32,
        );
        let part = image::open(&path)
            .unwrap()
            .crop_imm(x0, y0, cw, ch)
            .resize_exact(w, h, image::imageops::FilterType::Lanczos3);
        let det = detect(
            &GrayImage::from_dynamic(&part).unwrap(),
            &DetectParams::default(),
        );
        assert!(!det.boards.is_empty(), "{name} {x0} {y0}");
        for board in &det.boards {
            let to_photo = |x: f64, y: f64| {
                (
                    (x + 0.5) / scale - 0.5 + x0 as f64,
                    (y + 0.5) / scale - 0.5 + y0 as f64,
                )
            };
            let offsets = label_offsets(&whole.boards[0], board, to_photo, 3.0 / scale);
            eprintln!(
                "{name} {x0} {y0} ×{scale}: {} corners, {offsets:?}",
                board.corners.len()
            );
            assert_eq!(offsets.len(), 1, "{name} {x0} {y0} ×{scale}: {offsets:?}");
            for (k, a) in board.corners.iter().enumerate() {
                for b in &board.corners[k + 1..] {
                    assert!(
                        (a.x - b.x).hypot(a.y - b.y) > 3.0,
                        "{name} {x0} {y0} ×{scale}: {a:?} and {b:?} coincide"
                    );
                }
            }
        }
    }
}

/// A print's dot gain joins the dark squares by a bridge at every junction: 0.2 mm a side on
/// squares of 90–110 px is a bridge of about 2 px. Every junction fails the fine election's
/// centre test, so before the coarse-only fallback nothing was found; now the board is found
/// whole and the board-wide fit removes the offset between the polarities (measured RMS
/// 0.011–0.013 px on these scenes).
#[test]
fn dot_gain_bridges_do_not_hide_the_board() {
    for seed in [0u64, 5] {
        let t = BoardScene {
            dot_gain_mm: 0.2,
            ..template()
        };
        let s = random_board_scene(
            &mut ChaCha8Rng::seed_from_u64(100 + seed),
            Surface::Flat,
            &t,
        );
        let (o, det) = run(&format!("dot gain, seed {seed}"), &s, seed);
        assert_eq!(det.boards.len(), 1);
        assert_eq!(o.missing, 0);
        assert!(o.rms < RMS_BOUND, "{}", o.rms);
    }
}

/// Under the same dot gain the fine election passes only five junctions, squares apart, on
/// this pose: the grid step between them gave a coarse stride of 16, at which the 100 px squares
/// are 6 px and the coarse pass elected the near half of the board (53 of 81 corners found).
/// The coarse corners measure the step again and the pass is redone at their stride (6).
#[test]
fn a_coarse_stride_from_far_apart_corners_is_measured_again() {
    let s = scene(Surface::Flat, 104, |t| t.dot_gain_mm = 0.2);
    let (o, det) = run("dot gain, far apart fine corners", &s, 4);
    assert_eq!(det.boards.len(), 1);
    assert_eq!(o.missing, 0);
    assert!(o.rms < RMS_BOUND, "{}", o.rms);
}

/// Under the same dot gain the election cannot pass corners 30–40 px from the image's border
/// (bridged at full resolution, beyond the template's reach when coarse), and the completion's
/// verification frame (0.42 of a 200 px step) left the image: one or two corners were missing on
/// each of these poses. The frame is narrowed there.
#[test]
fn corners_near_the_image_border_are_completed() {
    for seed in [1u64, 2, 3] {
        let s = scene(Surface::Flat, 100 + seed, |t| t.dot_gain_mm = 0.2);
        let (o, det) = run(&format!("dot gain, border, seed {seed}"), &s, seed);
        assert_eq!(det.boards.len(), 1);
        assert_eq!(o.missing, 0, "seed {seed}");
        assert!(o.rms < RMS_BOUND, "{}", o.rms);
    }
}

#[test]
fn no_gradient_estimate_between_two_sliver_junctions() {
    // 15 × 21 corners of 8 mm round a 60 mm cylinder at 640 × 480: beside the silhouettes the
    // squares are slivers 2–5 px wide. The gradient estimate's 6 px window held two junctions
    // there, and it placed corners 1.5–3 px off, between them, claiming σ 0.3 px (41 such in
    // the robustness report's cell). `check` refuses any corner more than 1.5 px off.
    for seed in 0..6u64 {
        let s = scene(Surface::Cylinder { radius_mm: 60.0 }, 100 + seed, |t| {
            (t.rows, t.cols, t.square_mm) = (15, 21, 8.0);
            t.camera = vga();
        });
        let (_, det) = run(&format!("640 × 480 cylinder, seed {seed}"), &s, seed);
        assert_eq!(det.boards.len(), 1, "seed {seed}");
    }
}

#[test]
fn no_gradient_estimate_beside_the_slivers_beyond_a_board() {
    // 19 × 29 corners of 6 mm round a 60 mm cylinder at 1920 × 1200: the last labelled column
    // at a silhouette has its line neighbours 13–15 px away, but beyond it, unlabelled, lie
    // slivers of 2–4 px inside the gradient estimate's window. With the estimate allowed at
    // twice the window's radius from a neighbour, these poses had corners 1.5–4.6 px off
    // (claiming σ 0.3–0.5 px), 27 in all. `check` refuses any corner more than 1.5 px off.
    for seed in [1, 2, 5u64] {
        let s = scene(Surface::Cylinder { radius_mm: 60.0 }, 700 + seed, |t| {
            (t.rows, t.cols, t.square_mm) = (19, 29, 6.0);
        });
        let (o, det) = run(&format!("19 × 29 cylinder, seed {seed}"), &s, seed);
        assert_eq!(det.boards.len(), 1, "seed {seed}");
        assert!(o.missing <= 8, "seed {seed}: {} missing", o.missing);
    }
}

#[test]
fn a_board_seen_nearly_edge_on_gives_no_sheared_lattice() {
    // Boards turned nearly edge-on, their squares foreshortened to 4–5 px (15 × 21 corners of
    // 8 mm at 640 × 480) or to rhombi whose edges meet at 20° (tilted 35° further). There the
    // election's edge angles fail, and the connectivity linked corners two rows apart: sheared
    // lattices whose phase is consistent, with 4 and 26 corners mislabelled. In the frame of
    // their labelled neighbours their corners correlate with the ideal junction by 0.6–0.7.
    let edge_on = scene(Surface::Flat, 906, |t| {
        (t.rows, t.cols, t.square_mm, t.camera) = (15, 21, 8.0, vga());
    });
    let mut tilted = scene(Surface::Flat, 908, |_| ());
    tilted.pose *= tilt(35.0);
    // `check` refuses wrong labels and false corners. The edge-on board gives no board at all
    // (as OpenCV's detectors); the tilted one loses the far corners, in their rhombi.
    run("edge-on", &edge_on, 6);
    let (o, _) = run("tilted", &tilted, 8);
    assert!(o.missing <= 12, "{} missing", o.missing);
}

#[test]
fn a_low_resolution_cylinder_keeps_the_columns_beside_its_silhouettes() {
    // 15 × 21 corners of 8 mm round a 60 mm cylinder at 640 × 480: near each silhouette the
    // squares narrow to 5–8 px, where the edge walks find nothing and the completion placed
    // corners by the gradient estimate, 1.5–2 px off, which the junction model does not
    // confirm; the next rounds' predictions then missed the columns beyond. 57 of the 270
    // visible corners were missing, then 19. A sliver's corner lies nearer its neighbour than
    // half the mean grid step (5 px against 11 here), and the completion refused it as a
    // duplicate until the distance was measured in the site's own grid steps: now 12.
    let s = scene(Surface::Cylinder { radius_mm: 60.0 }, 102, |t| {
        (t.rows, t.cols, t.square_mm, t.camera) = (15, 21, 8.0, vga());
    });
    let (o, _) = run("640 × 480 cylinder", &s, 2);
    assert!(o.missing <= 14, "{} missing", o.missing);
    assert!(o.rms < 0.1, "{}", o.rms);
}

#[test]
fn corners_a_few_pixels_inside_the_image_border_are_completed_from_the_election() {
    // Squares of about 250 px cut by the image's border: corners 10–15 px inside it, which the
    // election finds, belong to no complete grid cell and get no links, and the completion's
    // frames, narrowed to a quarter step, still leave the image there.
    for (seed, near) in [
        (1u64, [31.0, 10.0]),
        (2, [1909.0, 1104.0]),
        (3, [15.0, 1020.0]),
    ] {
        let mut s = scene(Surface::Flat, 700 + seed, |_| ());
        s.pose.translation.vector /= 2.2;
        let (o, det) = run(&format!("cut by the border, seed {seed}"), &s, seed);
        assert_eq!((det.boards.len(), o.missing), (1, 0), "seed {seed}");
        assert!(o.rms < RMS_BOUND, "{}", o.rms);
        let d = detected(&det)
            .iter()
            .map(|&(_, x, y, _, _)| (x - near[0]).hypot(y - near[1]))
            .fold(f64::INFINITY, f64::min);
        assert!(d < 1.5, "seed {seed}: nothing near {near:?}");
    }
}

#[test]
fn one_sided_answers_at_bridged_junctions_restart_where_the_curves_meet() {
    // Under a 0.2 mm dot gain the pixel-level maximum of one corner sits at a tip of its bridged
    // junction, 2 px from where the board's curves meet (beyond the board fit's `max_shift`),
    // and the local refiner started there sees one side only, 1.45 px off. Restarted where the
    // curves meet, it converges on the junction.
    let t = BoardScene {
        dot_gain_mm: 0.2,
        ..template()
    };
    let s = random_board_scene(&mut ChaCha8Rng::seed_from_u64(104), Surface::Flat, &t);
    let r = s.render(4).expect("valid scene");
    let det = detect(&r.image, &DetectParams::default());
    assert_eq!(det.boards.len(), 1);
    let visible: Vec<&BoardCorner> = r.corners.iter().filter(|c| c.visible).collect();
    let errors: Vec<f64> = det.boards[0]
        .corners
        .iter()
        .filter_map(|c| {
            let d = visible
                .iter()
                .map(|t| (t.x - c.x).hypot(t.y - c.y))
                .fold(f64::INFINITY, f64::min);
            (d <= 3.0).then_some(d)
        })
        .collect();
    assert!(errors.len() >= 50, "{}", errors.len());
    // A half-offset answer would lie 1–2 px off; the rest are within a few tenths.
    let worst = errors.iter().cloned().fold(0.0, f64::max);
    assert!(worst < 0.5, "{worst}");
}

#[test]
fn one_sided_answers_are_weighed_with_their_polarity_offset() {
    // Under a 0.2 mm dot gain on the 60 mm cylinder, the local refiner sees corner (4, 0) from
    // one side only. Compared by the σ of its fit alone it beat the junction model's answer,
    // and was reported 1.58 px off, with σ 0.91 px once half the polarity offset was added.
    // Weighed with that offset from the start, the junction answer is taken.
    let s = scene(Surface::Cylinder { radius_mm: 60.0 }, 101, |t| {
        t.dot_gain_mm = 0.2
    });
    let r = s.render(1).expect("valid scene");
    let det = detect(&r.image, &DetectParams::default());
    assert_eq!(det.boards.len(), 1);
    let visible: Vec<&BoardCorner> = r.corners.iter().filter(|c| c.visible).collect();
    for c in &det.boards[0].corners {
        let d = visible
            .iter()
            .map(|t| (t.x - c.x).hypot(t.y - c.y))
            .fold(f64::INFINITY, f64::min);
        assert!(
            d < 1.0,
            "({}, {}) {d:.2} px off, {:?}",
            c.row,
            c.col,
            c.path
        );
    }
}

/// Under a 0.3 mm dot gain (a print that offsets the two polarities of every line by about
/// 3 px) the outer column of this pose is placed from one side of its bridged junctions, 3–4 px
/// off. The gradient estimate, pulled to the dark side as a one-sided answer is, claimed σ
/// 0.18–0.20 px for 4 px; its reported σ now carries half the polarity offset, and no answer
/// claims less than a third of its error.
#[test]
fn answers_beside_bridged_junctions_claim_the_polarity_offset() {
    let s = scene(Surface::Flat, 103, |t| t.dot_gain_mm = 0.3);
    let r = s.render(3).expect("valid scene");
    let det = detect(&r.image, &DetectParams::default());
    assert_eq!(det.boards.len(), 1);
    for c in &det.boards[0].corners {
        let d = r
            .corners
            .iter()
            .filter(|t| t.x.is_finite())
            .map(|t| (t.x - c.x).hypot(t.y - c.y))
            .fold(f64::INFINITY, f64::min);
        let sigma = c.sigma.unwrap_or(f64::INFINITY);
        assert!(
            d <= 1.0 || 3.0 * sigma >= d,
            "({}, {}) {d:.2} px off with σ {sigma:.3} px, {:?}",
            c.row,
            c.col,
            c.path
        );
    }
}

#[test]
fn junction_windows_grow_with_the_blur() {
    // A board wrapped round a cylinder under a 4 px blur: a 6 px junction window holds too
    // little of the edges, and its answers at the boundary corners were up to 1 px off while
    // claiming σ 0.07–0.09 px. The windows now grow with the measured blur.
    for seed in [3u64, 5] {
        let s = scene(Surface::Cylinder { radius_mm: 60.0 }, 100 + seed, |t| {
            t.blur = 4.0
        });
        let (o, det) = run(&format!("blur 4 px, seed {seed}"), &s, seed);
        eprintln!("seed {seed}: {} missing, RMS {:.4} px", o.missing, o.rms);
        assert_eq!(det.boards.len(), 1);
        assert!(o.rms < 0.2, "{}", o.rms);
    }
}

#[test]
fn a_board_whose_junctions_are_all_bridged_is_found() {
    // A 0.3 mm dot gain on an S-shaped board: the fine election rejects all but four bridged
    // junctions, squares apart, and the coarse pass at the grid step they give (stride 16)
    // elects none; the fallback strides find the board.
    let s = scene(Surface::SShape { radius_mm: 80.0 }, 704, |t| {
        t.dot_gain_mm = 0.3
    });
    let (o, det) = run("bridged junctions", &s, 4);
    eprintln!("{} missing, RMS {:.4} px", o.missing, o.rms);
    assert_eq!(det.boards.len(), 1);
    assert!(o.missing <= 1, "{}", o.missing);
    assert!(o.rms < RMS_BOUND, "{}", o.rms);
}

#[test]
fn tiny_squares_whose_board_fit_is_poor_get_junction_answers() {
    // A 7 × 9 board at 640 × 480 with squares of 7–13 px: most of its lines' pieces are a square
    // or two long, and the median σ of the board-wide answers was 730 px. Gates relative to it
    // kept board answers 1.1–1.4 px off (σ 0.6 px) without a junction fit, and others with
    // σ of hundreds of pixels.
    let mut s = scene(Surface::Flat, 704, |t| {
        (t.rows, t.cols, t.camera, t.blur) = (7, 9, vga(), 0.8)
    });
    s.pose.translation.vector *= 2.5;
    let r = s.render(4).expect("valid scene");
    let det = detect(&r.image, &DetectParams::default());
    let o = check("tiny squares", &det, &r.corners);
    assert_eq!((det.boards.len(), o.missing), (1, 0));
    for c in &det.boards[0].corners {
        let d = r
            .corners
            .iter()
            .map(|t| (t.x - c.x).hypot(t.y - c.y))
            .fold(f64::INFINITY, f64::min);
        let sigma = c.sigma.expect("refined");
        eprintln!(
            "({}, {}) {:?} {d:.3} px off, σ {sigma:.3}",
            c.row, c.col, c.path
        );
        assert!(
            d < 0.5 && sigma < 1.0,
            "({}, {}) {d} px off, σ {sigma}",
            c.row,
            c.col
        );
    }
    assert!(o.rms < 0.06, "{}", o.rms);
}

#[test]
fn an_outer_corner_cut_by_a_stroke_is_not_completed() {
    // A bar's edge passes through the outer corner of a border square: the completion's
    // quadrant test takes it for a junction, but no refiner places it from both sides (two of
    // its four edges are the bar's). Kept, it would be labelled as the board's next corner, 90 px
    // from every true one. The completion refuses it (before, it was added and then dropped as
    // unplaced), so it is absent even when unplaced corners are kept.
    let mut s = scene(Surface::Flat, 903, |_| ());
    s.occluders = vec![Occluder {
        from: [700.0, 0.0],
        to: [1200.0, 1200.0],
        width: 40.0,
        intensity: 0.3,
    }];
    let r = s.render(3).expect("valid scene");
    let kept = detect(
        &r.image,
        &DetectParams {
            keep_unrefined: true,
            ..DetectParams::default()
        },
    );
    check(
        "stroke through an outer corner, unplaced kept",
        &kept,
        &r.corners,
    );
    let det = detect(&r.image, &DetectParams::default());
    let o = check("stroke through an outer corner", &det, &r.corners);
    assert_eq!(o.missing, 0);
    assert_eq!(det.boards.len(), 1);
    let b = &det.boards[0];
    assert_eq!(b.corners.len(), kept.boards[0].corners.len());
    assert_eq!(b.corners.iter().map(|c| c.row).min(), Some(0));
    assert_eq!(b.corners.iter().map(|c| c.col).min(), Some(0));
    assert!(b.corners.iter().all(|c| c.status != Status::Failed));
}

#[test]
fn an_outer_corner_beside_an_occluder_does_not_grow_the_board() {
    // The bar runs 10 px beyond a border square of a bent board: the square's outer corner
    // (the square against the bar's gray) passes the completion's verification in the full frame
    // and a one-sided walk placed it, as the next ring's corner, 110 px from every true corner.
    // Growing the board takes a two-sided answer or the junction model's.
    bar_pose(
        "bar beside a border square",
        Surface::Cylinder { radius_mm: 60.0 },
        3,
    );
}

#[test]
fn an_occluder_s_edge_beside_a_border_square_is_no_sliver_junction() {
    // On this pose the bar crosses the S-shaped board's first row; beside it, the completion's
    // sliver search finds a border square's corner against the bar's edge, which no walk
    // places. The junction model's wider window (for slivers wider than its usual window) fits
    // it with an edge bent at a radius of 8 px, which a grid line of a board is not; it must
    // not confirm it (it was completed as (0, 0), 89 px from every true corner).
    bar_pose(
        "bar beside a border square of an S",
        Surface::SShape { radius_mm: 80.0 },
        5,
    );
}

#[test]
fn every_corner_reports_its_uncertainty() {
    // On this pose the local refiner's curves for the corner beside the bar's edge at a sliver
    // (truth (8, 7), past the visibility limit) do not meet, and straight lines stand in: its σ
    // was missing. It now comes from the lines' fits, with their residuals as a model error.
    let s = scene(Surface::Cylinder { radius_mm: 60.0 }, 102, |t| {
        t.occluders = vec![report_bar()]
    });
    let det = detect(
        &s.render(2).expect("valid scene").image,
        &DetectParams::default(),
    );
    assert!(!det.boards.is_empty());
    for c in det.boards.iter().flat_map(|b| &b.corners) {
        assert!(c.sigma.is_some_and(|s| s.is_finite() && s > 0.0), "{c:?}");
    }
}

/// Every corner's covariance goes with its σ: symmetric, positive definite, its larger
/// eigenvalue σ². Scenes that take every path: board answers, the junction model and the
/// gradient estimate beside a bar and at silhouettes, one-sided and gradient answers widened by
/// half the polarity offset under a dot gain of 0.3 mm. Boundary corners know one direction far better than the
/// other, which σ alone (the worse one) hides.
#[test]
fn every_corner_s_covariance_goes_with_its_sigma() {
    let scenes = [
        (
            scene(Surface::Cylinder { radius_mm: 60.0 }, 102, |t| {
                t.occluders = vec![report_bar()]
            }),
            2,
        ),
        (scene(Surface::Flat, 103, |t| t.dot_gain_mm = 0.3), 3),
    ];
    let mut paths = Vec::new();
    let mut elongated = 0;
    for (s, noise_seed) in &scenes {
        let det = detect(
            &s.render(*noise_seed).expect("valid scene").image,
            &DetectParams::default(),
        );
        for c in det.boards.iter().flat_map(|b| &b.corners) {
            let (sigma, cov) = (c.sigma.expect("σ"), c.cov.expect("covariance"));
            let (a, b, d) = (cov[0][0], cov[0][1], cov[1][1]);
            assert_eq!(cov[0][1], cov[1][0], "{c:?}");
            assert!(a > 0.0 && d > 0.0 && a * d - b * b > 0.0, "{c:?}");
            let half = 0.5 * (a + d);
            let spread = (0.25 * (a - d).powi(2) + b * b).sqrt();
            let (large, small) = (half + spread, half - spread);
            assert!(
                (large.sqrt() - sigma).abs() <= 1e-9 * sigma,
                "σ {sigma} against {}: {c:?}",
                large.sqrt()
            );
            elongated += usize::from(large > 16.0 * small);
            if !paths.contains(&c.path) {
                paths.push(c.path);
            }
        }
    }
    assert!(paths.len() >= 3, "{paths:?}");
    assert!(elongated > 0);
}

/// The spacing law along straight grid lines ([`conic_corners::spacing`]) on curved and flat
/// renders: it lowers the total squared error, moves no corner by more than a few of its own σ,
/// and leaves the σ honest (about 68 % of the error components within their own σ).
#[test]
fn the_spacing_law_lowers_the_error_and_keeps_the_sigma_honest() {
    let off = DetectParams {
        spacing: None,
        ..DetectParams::default()
    };
    let (mut sq, mut sq_off, mut within, mut total, mut moved) = (0.0, 0.0, 0, 0, 0);
    for (surface, seed) in [
        (Surface::Flat, 51),
        (Surface::Cylinder { radius_mm: 60.0 }, 52),
        (Surface::Cylinder { radius_mm: 120.0 }, 53),
        (
            Surface::EllipticColumn {
                a_mm: 50.0,
                b_mm: 90.0,
            },
            54,
        ),
        (Surface::SShape { radius_mm: 90.0 }, 55),
    ] {
        let r = scene(surface, seed, |_| ())
            .render(seed)
            .expect("valid scene");
        let (det, bare) = (
            detect(&r.image, &DetectParams::default()),
            detect(&r.image, &off),
        );
        check(&format!("{surface:?}"), &det, &r.corners);
        let (b, u) = (&det.boards[0], &bare.boards[0]);
        for (c, d) in b.corners.iter().zip(&u.corners) {
            assert_eq!((c.row, c.col), (d.row, d.col));
            let step = (c.x - d.x).hypot(c.y - d.y);
            let sigma = d.sigma.expect("σ");
            assert!(
                step <= 4.0 * sigma,
                "{surface:?} ({}, {}): {step} against σ {sigma}",
                c.row,
                c.col
            );
            moved += usize::from(step > 1e-4);
            let Some(t) = r
                .corners
                .iter()
                .find(|t| (t.x - c.x).hypot(t.y - c.y) < 1.5)
            else {
                continue;
            };
            sq += (c.x - t.x).powi(2) + (c.y - t.y).powi(2);
            sq_off += (d.x - t.x).powi(2) + (d.y - t.y).powi(2);
            let cov = c.cov.expect("covariance");
            for (axis, e) in [(0, c.x - t.x), (1, c.y - t.y)] {
                within += usize::from(e.abs() <= cov[axis][axis].sqrt());
                total += 1;
            }
        }
    }
    eprintln!("moved {moved}, squared error {sq_off:.5} -> {sq:.5}, within σ {within} of {total}");
    assert!(moved > 100, "{moved}");
    assert!(sq < 0.9 * sq_off, "{sq} {sq_off}");
    let share = within as f64 / total as f64;
    assert!((0.6..0.8).contains(&share), "{share}");
}

/// The board's a-posteriori variance factor ([`conic_corners::variance_factor`]). It scales σ
/// and covariance and moves no corner. On renders, whose fits' σ are about honest, the share of
/// error components within their own σ stays near 68 % (measured over these six views: 72.0 % with
/// the fits' σ, 68.2 % scaled); on OpenCV's stereo photos, whose σ a camera calibration found three
/// times too small (`bench/stereo_calib.py`: covariance scale 3.06, 1.34 after), it is a median
/// 2.6.
#[test]
fn the_sigma_scale_keeps_honest_renders_and_widens_the_photos() {
    // The spacing fusion, which the scaled covariances weigh, is off in both runs.
    let scaled = DetectParams {
        spacing: None,
        ..DetectParams::default()
    };
    let raw = DetectParams {
        variance_factor: None,
        ..scaled.clone()
    };
    let (mut within, mut within_raw, mut total) = (0, 0, 0);
    for (surface, seed) in [
        (Surface::Flat, 41),
        (Surface::Flat, 42),
        (Surface::Cylinder { radius_mm: 80.0 }, 43),
        (Surface::Cylinder { radius_mm: 80.0 }, 44),
        (Surface::SShape { radius_mm: 90.0 }, 45),
        (Surface::SShape { radius_mm: 90.0 }, 46),
    ] {
        let r = scene(surface, seed, |_| ())
            .render(seed)
            .expect("valid scene");
        let (det, bare) = (detect(&r.image, &scaled), detect(&r.image, &raw));
        assert_eq!(det.boards.len(), 1, "{surface:?} {seed}");
        let (b, u) = (&det.boards[0], &bare.boards[0]);
        assert_eq!(u.sigma_scale, None);
        let scale = b.sigma_scale.expect("a 9 × 9 board has straight runs");
        assert!((0.4..2.0).contains(&scale), "{surface:?} {seed}: {scale}");
        for (c, d) in b.corners.iter().zip(&u.corners) {
            assert_eq!((c.x, c.y, c.row, c.col), (d.x, d.y, d.row, d.col));
            let (s, t) = (c.sigma.expect("σ"), d.sigma.expect("σ"));
            assert!((s - scale * t).abs() <= 1e-12 * s, "{s} {t} {scale}");
            let Some(truth) = r
                .corners
                .iter()
                .find(|t| (t.x - c.x).hypot(t.y - c.y) < 1.5)
            else {
                continue;
            };
            let (cov, cov_raw) = (c.cov.expect("covariance"), d.cov.expect("covariance"));
            for (axis, e) in [(0, c.x - truth.x), (1, c.y - truth.y)] {
                within += usize::from(e.abs() <= cov[axis][axis].sqrt());
                within_raw += usize::from(e.abs() <= cov_raw[axis][axis].sqrt());
                total += 1;
            }
        }
    }
    let (share, share_raw) = (
        within as f64 / total as f64,
        within_raw as f64 / total as f64,
    );
    eprintln!("within their own σ: {share:.3} (fits alone {share_raw:.3}) of {total}");
    assert!(
        (0.58..0.8).contains(&share),
        "{share} ({share_raw} unscaled)"
    );

    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/opencv-stereo");
    let mut scales: Vec<f64> = std::fs::read_dir(&dir)
        .expect("examples/opencv-stereo")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "jpg"))
        .filter_map(|p| {
            let image = GrayImage::open(&p).expect("readable photo");
            detect(&image, &DetectParams::default()).boards[0].sigma_scale
        })
        .collect();
    // Where the lens bows every run of six corners by more than 0.3 px, there is no factor.
    assert!(scales.len() >= 18, "{scales:?}");
    scales.sort_by(f64::total_cmp);
    let median = scales[scales.len() / 2];
    eprintln!(
        "stereo photos: median σ scale {median:.2} over {}",
        scales.len()
    );
    assert!((2.0..4.0).contains(&median), "{scales:?}");
}

/// The robustness report's bar across the image: 40 px wide, gray 0.3.
fn report_bar() -> Occluder {
    Occluder {
        from: [700.0, 0.0],
        to: [1200.0, 1200.0],
        width: 40.0,
        intensity: 0.3,
    }
}

/// The robustness report's pose `seed` on `surface` with its bar: one board, no false corner,
/// at most two visible corners missed, the others accurate.
fn bar_pose(what: &str, surface: Surface, seed: u64) {
    let s = scene(surface, 100 + seed, |t| t.occluders = vec![report_bar()]);
    let (o, det) = run(what, &s, seed);
    assert_eq!(det.boards.len(), 1);
    assert!(o.missing <= 2, "{}", o.missing);
    assert!(o.rms < RMS_BOUND, "{}", o.rms);
}

/// Distance (px) from `(x, y)` to the nearest true corner (only the visible ones if
/// `visible_only`); infinite if there is none.
fn nearest_truth(truth: &[BoardCorner], x: f64, y: f64, visible_only: bool) -> f64 {
    truth
        .iter()
        .filter(|t| t.x.is_finite() && (t.visible || !visible_only))
        .map(|t| (t.x - x).hypot(t.y - y))
        .fold(f64::INFINITY, f64::min)
}

/// Detection across imaging conditions, as a table (not a pass/fail test):
/// `cargo test --release -p conic-corners --test detect_boards robustness_report -- --ignored
/// --nocapture`. Six random poses per cell, 9×9 corners on 20 mm squares (about 90–140 px)
/// unless the condition says otherwise, blur 1 px, noise 1 %. A detection is "off" when it lies
/// more than 1.5 px from every true corner, visible or not; "found" counts the visible corners
/// with a detection within 1.5 px, and the RMS is over those.
#[test]
#[ignore]
fn robustness_report() {
    type Edit = fn(&mut BoardScene);
    let conditions: [(&str, Edit); 17] = [
        ("baseline", |_| ()),
        ("dot gain 0.1 mm", |t| t.dot_gain_mm = 0.1),
        ("dot gain 0.2 mm", |t| t.dot_gain_mm = 0.2),
        ("dot gain 0.3 mm", |t| t.dot_gain_mm = 0.3),
        ("blur 2.5 px", |t| t.blur = 2.5),
        ("blur 4 px", |t| t.blur = 4.0),
        ("noise 5 %", |t| t.noise = 0.05),
        ("noise 10 %", |t| t.noise = 0.10),
        ("contrast 0.4–0.6", |t| (t.black, t.white) = (0.4, 0.6)),
        ("dark (0.02–0.15)", |t| {
            (t.black, t.white, t.background) = (0.02, 0.15, 0.08)
        }),
        ("uneven light", |t| t.lighting_gradient = [0.6, -0.5]),
        ("squares 3.5 mm", |t| (t.square_mm, t.cols) = (3.5, 11)),
        ("15×21 corners, 8 mm", |t| {
            (t.rows, t.cols, t.square_mm) = (15, 21, 8.0)
        }),
        ("19×29 corners, 6 mm", |t| {
            (t.rows, t.cols, t.square_mm) = (19, 29, 6.0)
        }),
        ("radial distortion k₁ −0.25", |t| t.camera.k1 = -0.25),
        ("640×480, 15×21 corners, 8 mm", |t| {
            (t.rows, t.cols, t.square_mm) = (15, 21, 8.0);
            t.camera = vga();
        }),
        ("bar across the board", |t| t.occluders = vec![report_bar()]),
    ];
    // Conditions that change the random pose or the rendered image.
    type Posed = fn(&mut BoardScene);
    type Degraded = fn(GrayImage) -> GrayImage;
    let after: [(&str, Posed, Degraded); 2] = [
        ("tilted 35° further", |s| s.pose *= tilt(35.0), |i| i),
        (
            "diagonal motion blur 8 px",
            |_| (),
            |i| diagonal_motion_blur(&i, 4, std::f64::consts::FRAC_1_SQRT_2),
        ),
    ];
    let all = conditions
        .into_iter()
        .map(|(n, e)| (n, e, (|_| ()) as Posed, (|i| i) as Degraded))
        .chain(
            after
                .into_iter()
                .map(|(n, p, d)| (n, (|_| ()) as Edit, p, d)),
        );
    let surfaces = [
        ("flat", Surface::Flat),
        ("cylinder 60", Surface::Cylinder { radius_mm: 60.0 }),
        ("S 80", Surface::SShape { radius_mm: 80.0 }),
    ];
    println!("| condition | surface | visible | found | off | no board | RMS px |");
    println!("|---|---|---|---|---|---|---|");
    for (condition, edit, pose, degrade) in all {
        for (name, surface) in surfaces {
            let (mut visible, mut found, mut off, mut none, mut sq) = (0, 0, 0, 0, 0.0);
            for seed in 0..6u64 {
                let mut t = template();
                edit(&mut t);
                let mut s =
                    random_board_scene(&mut ChaCha8Rng::seed_from_u64(100 + seed), surface, &t);
                pose(&mut s);
                let r = s.render(seed).expect("valid scene");
                let det = detect(&degrade(r.image), &DetectParams::default());
                none += usize::from(det.boards.is_empty());
                let nearest = |x, y, visible_only| nearest_truth(&r.corners, x, y, visible_only);
                visible += r.corners.iter().filter(|t| t.visible).count();
                for c in det.boards.iter().flat_map(|b| &b.corners) {
                    off += usize::from(nearest(c.x, c.y, false) > 1.5);
                    let d = nearest(c.x, c.y, true);
                    if d <= 1.5 {
                        found += 1;
                        sq += d * d;
                    }
                }
            }
            let rms = (sq / found.max(1) as f64).sqrt();
            println!("| {condition} | {name} | {visible} | {found} | {off} | {none} | {rms:.4} |");
        }
    }
}

/// How honest each detected corner's σ is beyond the robustness report's conditions, at strong
/// bends (a table, not a pass/fail test): `cargo test --release -p conic-corners --test
/// detect_boards honesty_report -- --ignored --nocapture`. Five random poses per cell (seeds
/// 500–504), 9 × 9 corners on 20 mm squares unless the condition says otherwise, blur 1 px, noise
/// 1 %. "Found", "off" and the RMS as in `robustness_report`; "wrong σ" counts detections more
/// than 0.3 px and more than 3σ from every true corner, by the path that placed them (b board,
/// l local, j junction, g gradient).
#[test]
#[ignore]
fn honesty_report() {
    type Edit = fn(&mut BoardScene);
    let conditions: [(&str, Edit); 11] = [
        ("inverted polarity", |t| {
            (t.black, t.white, t.background) = (0.85, 0.1, 0.5)
        }),
        ("no margin", |t| t.margin_mm = 0.0),
        ("dark background", |t| t.background = 0.03),
        ("white background", |t| t.background = 0.95),
        ("blur 3 px, noise 5 %", |t| (t.blur, t.noise) = (3.0, 0.05)),
        ("4×6 corners", |t| (t.rows, t.cols) = (4, 6)),
        ("2×3 corners", |t| (t.rows, t.cols) = (2, 3)),
        ("7×10 corners", |t| (t.rows, t.cols) = (7, 10)),
        ("640×480", |t| t.camera = vga()),
        ("640×480, 6×8 corners, blur 2 px", |t| {
            t.camera = vga();
            (t.rows, t.cols, t.blur) = (6, 8, 2.0);
        }),
        ("barrel distortion k₁ 0.3", |t| t.camera.k1 = 0.3),
    ];
    let surfaces = [
        ("flat", Surface::Flat),
        ("cylinder 45", Surface::Cylinder { radius_mm: 45.0 }),
        (
            "column 60×35",
            Surface::EllipticColumn {
                a_mm: 60.0,
                b_mm: 35.0,
            },
        ),
        ("S 80", Surface::SShape { radius_mm: 80.0 }),
    ];
    println!("| condition | surface | visible | found | off | RMS px | wrong σ (b, l, j, g, h) |");
    println!("|---|---|---|---|---|---|---|");
    for (condition, edit) in conditions {
        for (name, surface) in surfaces {
            let (mut visible, mut found, mut off, mut sq) = (0, 0, 0, 0.0);
            let mut wrong = [0usize; 5];
            for seed in 0..5u64 {
                let mut t = template();
                edit(&mut t);
                let s = random_board_scene(&mut ChaCha8Rng::seed_from_u64(500 + seed), surface, &t);
                let r = s.render(seed).expect("valid scene");
                let det = detect(&r.image, &DetectParams::default());
                visible += r.corners.iter().filter(|t| t.visible).count();
                let nearest = |x, y, visible_only| nearest_truth(&r.corners, x, y, visible_only);
                for c in det.boards.iter().flat_map(|b| &b.corners) {
                    let any = nearest(c.x, c.y, false);
                    off += usize::from(any > 1.5);
                    if any > 0.3 && any > 3.0 * c.sigma.unwrap_or(0.0) {
                        wrong[match c.path {
                            Path::Board => 0,
                            Path::Local => 1,
                            Path::Junction => 2,
                            Path::Gradient => 3,
                            Path::Hairline => 4,
                        }] += 1;
                    }
                    let d = nearest(c.x, c.y, true);
                    if d <= 1.5 {
                        found += 1;
                        sq += d * d;
                    }
                }
            }
            let rms = (sq / found.max(1) as f64).sqrt();
            let [b, l, j, g, h] = wrong;
            println!(
                "| {condition} | {name} | {visible} | {found} | {off} | {rms:.4} | {} ({b}, {l}, {j}, {g}, {h}) |",
                b + l + j + g + h
            );
        }
    }
}

/// `refine`, the drop-in for `cornerSubPix`, on the turned boards of the test above (22 px
/// squares), from the true corners rounded to the pixel grid. Its pilot pass first guesses a
/// blur of 2 px, whose windows (±13 px along the scanline at 45°) leave one or two samples per
/// walk between a junction's blurred zone and the next corner; it then tries 1 and 0.5 px.
/// Before, it placed 81, 81, 0 and 0 of the 81 corners at 0 / 15 / 30 / 45°; now 81, 81, 79
/// and 58, at 0.034 / 0.032 / 0.036 / 0.081 px RMS (at 45° the walks keep a few samples each).
#[test]
fn refine_places_the_corners_of_small_turned_squares() {
    use conic_corners::refine::{refine, RefineParams};
    for (k, degrees) in [0.0f64, 15.0, 30.0, 45.0].into_iter().enumerate() {
        let r = turned_scene(degrees)
            .render(40 + k as u64)
            .expect("valid scene");
        let truth: Vec<[f64; 2]> = r
            .corners
            .iter()
            .filter(|c| c.visible)
            .map(|c| [c.x, c.y])
            .collect();
        let starts: Vec<[f64; 2]> = truth.iter().map(|p| [p[0].round(), p[1].round()]).collect();
        let refined = refine(&r.image, &starts, &RefineParams::default());
        let errors: Vec<f64> = refined
            .iter()
            .zip(&truth)
            .filter(|(q, _)| q.status != Status::Failed)
            .map(|(q, t)| (q.x - t[0]).hypot(q.y - t[1]))
            .collect();
        let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len().max(1) as f64).sqrt();
        eprintln!(
            "turned {degrees}°: {} of {} placed, RMS {rms:.4} px, worst {:.4} px",
            errors.len(),
            truth.len(),
            errors.iter().fold(0.0f64, |a, &b| a.max(b))
        );
        let (least, bound) = match k {
            0 | 1 => (81, 0.045),
            2 => (75, 0.045),
            _ => (50, 0.1),
        };
        assert!(errors.len() >= least, "{degrees}°: {} placed", errors.len());
        assert!(rms < bound, "{degrees}°: RMS {rms}");
        assert!(errors.iter().all(|&e| e < 0.25), "{degrees}°: {errors:?}");
    }
}

/// Grid completion restores the corners the election rejects: with a nearly strict score rule
/// (`t_correlation` 0.015) the election drops about a fifth of the corners of a bent board with
/// dots; completion brings them back at their labels, and only them.
#[test]
fn completion_restores_corners_the_election_rejects() {
    let dots = Some(Dots {
        radius: 0.2,
        fraction: 0.4,
        seed: 7,
    });
    let s = scene(Surface::SShape { radius_mm: 80.0 }, 5, |t| t.dots = dots);
    let r = s.render(5).unwrap();
    let mut p = DetectParams::default();
    p.election.t_correlation = 0.015;
    p.completion.rounds = 0;
    let without = check("strict election", &detect(&r.image, &p), &r.corners);
    assert!(without.missing >= 10, "{}", without.missing);
    p.completion.rounds = 3;
    let det = detect(&r.image, &p);
    let with = check("strict election + completion", &det, &r.corners);
    assert_eq!(with.missing, 0);
    assert_eq!(det.boards.len(), 1);
    assert!(with.rms < RMS_BOUND, "{}", with.rms);
}

/// Boards wrapped far round thin cylinders, so that the outer columns are foreshortened to a few
/// pixels next to the silhouette: there the local refiner fails and some board-wide answers are
/// doubtful (short, extrapolated curves). Those corners take the junction model, and with it
/// disabled the gradient estimate (averaged with the board-wide answer where the two agree). On a
/// fixed family of scenes, every corner either places is within 0.5 px of the truth, each lowers
/// the total squared error against the pipeline with neither, and the junction model lowers it
/// further than the gradient estimate.
#[test]
fn fallbacks_at_foreshortened_silhouettes() {
    use conic_corners::board_fit::Path;
    let neither = DetectParams {
        gradient: None,
        junction: None,
        max_board_sigma: f64::INFINITY,
        ..DetectParams::default()
    };
    let gradient_only = DetectParams {
        junction: None,
        ..DetectParams::default()
    };
    let (mut sq, mut used) = ([0.0; 3], [0; 3]);
    for seed in 20..26u64 {
        for (radius_mm, square_mm) in [(45.0, 13.0), (50.0, 15.0)] {
            let s = scene(Surface::Cylinder { radius_mm }, seed, |t| {
                t.square_mm = square_mm;
                t.rows = 7;
                t.cols = 9;
            });
            let r = s.render(seed).expect("valid scene");
            let what = format!("seed {seed}, radius {radius_mm}");
            let base = check(&what, &detect(&r.image, &neither), &r.corners);
            sq[0] += base.rms * base.rms;
            let with_gradient = detect(&r.image, &gradient_only);
            let with_both = detect(&r.image, &DetectParams::default());
            let before: HashMap<(i32, i32), [f64; 2]> = with_gradient
                .boards
                .iter()
                .flat_map(|b| &b.corners)
                .map(|c| ((c.row, c.col), [c.x, c.y]))
                .collect();
            for (k, det) in [&with_gradient, &with_both].into_iter().enumerate() {
                let o = check(&what, det, &r.corners);
                assert!(o.missing <= base.missing, "{what}");
                sq[k + 1] += o.rms * o.rms;
                for c in det.boards.iter().flat_map(|b| &b.corners) {
                    // The gradient estimate's corners; the junction model's, placed by it alone
                    // or combined with a board-wide answer (which keeps the board path).
                    let touched = match k {
                        0 => c.path == Path::Gradient,
                        _ => {
                            c.path == Path::Junction
                                || before.get(&(c.row, c.col)) != Some(&[c.x, c.y])
                        }
                    };
                    if !touched {
                        continue;
                    }
                    let path = ["gradient", "junction"][k];
                    used[k + 1] += 1;
                    let e = r
                        .corners
                        .iter()
                        .filter(|t| t.x.is_finite())
                        .map(|t| (t.x - c.x).hypot(t.y - c.y))
                        .fold(f64::INFINITY, f64::min);
                    assert!(
                        e < 0.5,
                        "{what}: {path} corner ({}, {}) {e} px off",
                        c.row,
                        c.col
                    );
                }
            }
        }
    }
    eprintln!("corners placed by the gradient estimate / placed or combined by the junction model: {used:?}; summed RMS² with neither, gradient, junction: {sq:?} px²");
    assert!(
        used[1] >= 5 && used[2] >= 5,
        "the scenes must exercise both paths ({used:?})"
    );
    assert!(sq[2] < sq[1] && sq[1] < sq[0], "{sq:?}");
}

#[test]
fn one_sided_local_answers_yield_to_a_surer_gradient_estimate() {
    // The robustness report's baseline on the 60 mm cylinder, pose 2: at the silhouette the
    // board-wide fit gives (0, 0) no answer and the local refiner sees one side of it only
    // (σ 0.86 px, 1.19 px off); the gradient estimate claims σ 0.35 and is 0.27 px off.
    let s = scene(Surface::Cylinder { radius_mm: 60.0 }, 102, |_| ());
    let r = s.render(2).expect("valid scene");
    let det = detect(&r.image, &DetectParams::default());
    let mut matched = 0;
    for c in det.boards.iter().flat_map(|b| &b.corners) {
        let e = r
            .corners
            .iter()
            .filter(|t| t.visible)
            .map(|t| (t.x - c.x).hypot(t.y - c.y))
            .fold(f64::INFINITY, f64::min);
        if e <= 1.5 {
            matched += 1;
            assert!(
                e < 0.5,
                "({}, {}) {e:.3} px off, {:?}",
                c.row,
                c.col,
                c.path
            );
        }
    }
    assert!(matched >= 60, "{matched} corners matched");
}

/// The image `img` blurred by a box of `2·half + 1` samples along its diagonal (x and y together,
/// `step` px in each per sample, rounded to whole pixels), as a camera moving diagonally during
/// the exposure would.
fn diagonal_motion_blur(img: &GrayImage, half: isize, step: f64) -> GrayImage {
    let (w, h) = (img.width(), img.height());
    let mut data = vec![0f32; w * h];
    for y in 0..h {
        for x in 0..w {
            let (mut sum, mut n) = (0.0, 0.0);
            for k in -half..=half {
                let d = (k as f64 * step).round() as isize;
                if let Some(v) = img.get_checked(x as isize + d, y as isize + d) {
                    sum += v;
                    n += 1.0;
                }
            }
            data[y * w + x] = sum / n;
        }
    }
    GrayImage::from_vec(w, h, data).unwrap()
}

#[test]
fn a_cell_foreshortened_to_a_quarter_links_no_diagonal() {
    // Tilted 50° further, the far squares are 90 × 25 px: a cell's short diagonal lies 14° from
    // the long side, within the connectivity's cone and 1.15 times nearer than the grid
    // neighbour, and one corner was labelled two rows off.
    let mut s = scene(Surface::Flat, 911, |_| ());
    s.pose *= tilt(-50.0);
    let (o, _) = run("tilted 50°", &s, 11);
    assert!(o.missing <= 2, "{} missing", o.missing);
}

/// A render blurred along the image diagonal (9 samples over 8 px): the board's perspective
/// turns its corners' edges, and on one side of it the blur runs inside a quadrant, whose colour
/// then fills the junction's centre. The fine election rejected those 29 of 81 corners (a fifth
/// of the candidates elected, so the coarse passes were not tried), and the board lost three
/// columns.
#[test]
fn diagonal_motion_blur_over_part_of_a_board_keeps_every_column() {
    let s = scene(Surface::Flat, 906, |_| ());
    let r = s.render(6).expect("valid scene");
    let blurred = diagonal_motion_blur(&r.image, 4, std::f64::consts::FRAC_1_SQRT_2);
    let o = check(
        "motion",
        &detect(&blurred, &DetectParams::default()),
        &r.corners,
    );
    assert!(o.missing <= 2, "{} missing", o.missing);
}

/// The bundled photo at half size with motion blur along the squares' diagonals (5 samples,
/// 7 px): each junction's centre averages two quadrants of one colour, and the fine election's
/// tests reject all but a dozen junctions, too few and too scattered to give a coarse stride.
/// The coarse passes, where the blur is a few pixels less, still find the board.
#[test]
fn diagonal_motion_blur_on_the_bundled_photo_keeps_the_board() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/curve_4.jpg");
    let full = GrayImage::open(path).unwrap();
    let half = box_downsample(&full, 2).unwrap();
    let blurred = diagonal_motion_blur(&half, 2, 1.0);
    let det = detect(&blurred, &DetectParams::default());
    let sizes: Vec<usize> = det.boards.iter().map(|b| b.corners.len()).collect();
    eprintln!("boards: {sizes:?}");
    assert!(sizes.first().is_some_and(|&n| n >= 80), "{sizes:?}");
    // Every corner is one of the sharp photo's (a half-size pixel covers two full ones:
    // x_half = (x − 0.5)/2) with the same label up to one shift. The refiners model isotropic
    // blur, so under this blur some answers move by pixels (up to 4.4 px, at the S's fold and on
    // the bottom row, where the blur runs along an edge); most stay within a pixel.
    let sharp = detect(&full, &DetectParams::default());
    let mut shifts = std::collections::HashSet::new();
    let mut within_px = 0;
    for c in &det.boards[0].corners {
        let (d, s) = sharp.boards[0]
            .corners
            .iter()
            .map(|t| {
                let (x, y) = ((t.x - 0.5) / 2.0, (t.y - 0.5) / 2.0);
                ((x - c.x).hypot(y - c.y), (t.row - c.row, t.col - c.col))
            })
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .unwrap();
        assert!(
            d <= 5.0,
            "({}, {}) is {d:.2} px from the sharp corner",
            c.row,
            c.col
        );
        within_px += usize::from(d <= 1.0);
        shifts.insert(s);
    }
    let n = det.boards[0].corners.len();
    assert!(10 * within_px >= 9 * n, "{within_px} of {n} within 1 px");
    assert_eq!(shifts.len(), 1, "{shifts:?}");
}

/// A 6 × 9 calibration board (the sum odd, so its print fixes its frame) facing the camera,
/// tilted by 25° and rolled by `degrees` about the optical axis, flat or on a 200 mm cylinder.
fn rolled_pattern_scene(degrees: f64, surface: Surface) -> BoardScene {
    let roll = nalgebra::UnitQuaternion::from_axis_angle(
        &nalgebra::Vector3::z_axis(),
        degrees.to_radians(),
    );
    BoardScene {
        rows: 6,
        cols: 9,
        surface,
        pose: nalgebra::Isometry3::from_parts(nalgebra::Translation3::new(0.0, 0.0, 600.0), roll)
            * tilt(25.0),
        ..template()
    }
}

/// With the pattern given, every view labels each physical corner as the print does (the
/// renderer's truth labels, whose first square is dark), whatever the camera's roll; without
/// it, the labels follow the image, and a board rolled by more than 45° is labelled otherwise.
#[test]
fn a_known_pattern_labels_every_view_like_the_print() {
    use conic_corners::pattern::Pattern;
    let pattern = DetectParams {
        pattern: Some(Pattern { rows: 6, cols: 9 }),
        ..DetectParams::default()
    };
    for surface in [Surface::Flat, Surface::Cylinder { radius_mm: 200.0 }] {
        for degrees in [0.0, 70.0, 160.0, 250.0, 330.0] {
            let what = format!("{surface:?} rolled {degrees}°");
            let r = rolled_pattern_scene(degrees, surface)
                .render(3)
                .expect("valid scene");
            assert!(r.corners.iter().all(|t| t.visible), "{what}");
            let truth_label = |x: f64, y: f64| {
                let t = r
                    .corners
                    .iter()
                    .min_by(|a, b| {
                        (a.x - x)
                            .hypot(a.y - y)
                            .total_cmp(&(b.x - x).hypot(b.y - y))
                    })
                    .expect("truth");
                assert!((t.x - x).hypot(t.y - y) < 0.5, "{what}: false corner");
                (t.row as i32, t.col as i32)
            };
            let det = detect(&r.image, &pattern);
            assert_eq!(det.boards.len(), 1, "{what}");
            let b = &det.boards[0];
            assert_eq!((b.rows, b.cols, b.corners.len()), (6, 9, 54), "{what}");
            for c in &b.corners {
                assert_eq!((c.row, c.col), truth_label(c.x, c.y), "{what}");
            }
            let plain = detect(&r.image, &DetectParams::default());
            let same = plain.boards[0]
                .corners
                .iter()
                .all(|c| (c.row, c.col) == truth_label(c.x, c.y));
            assert_eq!(same, degrees == 0.0 || degrees == 330.0, "{what}");
            // Another pattern: no board spans it.
            let other = DetectParams {
                pattern: Some(Pattern { rows: 6, cols: 8 }),
                ..DetectParams::default()
            };
            assert!(detect(&r.image, &other).boards.is_empty(), "{what}");
        }
    }
}
