//! Speed of the whole pipeline (`detect`: pre-filter, election, connectivity, refinement) on one
//! core: `cargo bench -p conic-corners --bench detect`.
//!
//! Images:
//! - `board`: the speed benchmark's 1920×1200 flat 9×9-inner-corner board (the scene of
//!   `render-board` in `conic-corners-bench`: pose drawn by `random_board_scene` from seed 8,
//!   blur σ = 1 px, noise 1 %), quantized to 8 bits as its PNG is;
//! - `curve_6`: the 2248×4000 photo of a bent HydraMarker,
//!   `../shared/images/curved-hydramarker/curve_6.jpg` from the workspace root (skipped with a
//!   message when missing).
//!
//! Each image is also timed with the junction model disabled (`*_without_junction`).
//!
//! Every case runs inside a one-thread rayon pool, so the numbers are single-core whatever
//! `RAYON_NUM_THREADS` says. Target (issue "Board detection", item 8): ≤ 15 ms on `board`.
//!
//! The `stages` group times the pre-filter of `board` (default: at half resolution; and the
//! full-resolution path with its Hessian score alone, for comparison) and the election on its
//! candidates: `cargo bench -p conic-corners --bench detect -- stages`.

use conic_corners::detect::{detect, DetectParams};
use conic_corners::election::elect;
use conic_corners::prefilter::{hessian_score, prefilter, PrefilterParams};
use conic_corners::synth::{speed_benchmark_scene, SPEED_BENCHMARK_NOISE_SEED};
use conic_corners::GrayImage;
use criterion::{black_box, criterion_group, criterion_main, Criterion};
use std::path::Path;
use std::time::Duration;

fn board_image() -> GrayImage {
    let rendered = speed_benchmark_scene()
        .render(SPEED_BENCHMARK_NOISE_SEED)
        .expect("valid scene");
    // The same pixels as the PNG the peers read.
    let png = rendered.image.to_luma8(0.0, 1.0);
    GrayImage::from_slice(png.width() as usize, png.height() as usize, png.as_raw())
        .expect("non-empty image")
}

fn bench_detect(c: &mut Criterion) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("one-thread pool");
    let curve = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/images/curved-hydramarker/curve_6.jpg");
    let mut images = vec![("board", board_image())];
    match GrayImage::open(&curve) {
        Ok(img) => images.push(("curve_6", img)),
        Err(e) => eprintln!("detect bench: skipping curve_6 ({e})"),
    }
    let default = DetectParams::default();
    let without_junction = DetectParams {
        junction: None,
        ..DetectParams::default()
    };
    let mut group = c.benchmark_group("detect");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(5));
    for (name, image) in &images {
        let found: usize = detect(image, &default)
            .boards
            .iter()
            .map(|b| b.corners.len())
            .sum();
        eprintln!(
            "detect bench: {name} {}x{}, {found} corners",
            image.width(),
            image.height()
        );
        group.bench_function(*name, |b| {
            b.iter(|| pool.install(|| detect(black_box(image), &default)))
        });
        // The junction model's share of the time, in the same run.
        group.bench_function(format!("{name}_without_junction"), |b| {
            b.iter(|| pool.install(|| detect(black_box(image), &without_junction)))
        });
    }
    group.finish();
}

fn bench_stages(c: &mut Criterion) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("one-thread pool");
    let image = board_image();
    let p = DetectParams::default();
    let full_resolution = PrefilterParams {
        half_resolution: false,
        ..p.prefilter
    };
    let candidates = prefilter(&image, &p.prefilter);
    let mut group = c.benchmark_group("stages");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3));
    group.bench_function("prefilter", |b| {
        b.iter(|| pool.install(|| prefilter(black_box(&image), &p.prefilter)))
    });
    group.bench_function("prefilter_full_resolution", |b| {
        b.iter(|| pool.install(|| prefilter(black_box(&image), &full_resolution)))
    });
    group.bench_function("hessian_score", |b| {
        b.iter(|| pool.install(|| hessian_score(black_box(&image), p.prefilter.sigma)))
    });
    group.bench_function(format!("elect_{}_candidates", candidates.len()), |b| {
        b.iter(|| pool.install(|| elect(black_box(&image), &candidates, &p.election)))
    });
    group.finish();
}

criterion_group!(benches, bench_detect, bench_stages);
criterion_main!(benches);
