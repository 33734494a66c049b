//! Speed of the single-corner refiner: `cargo bench -p conic-corners --bench refine`.
//!
//! One corner of the paper's noise test (σn 3 %, blur 3 px, κ ≈ 1.2·10⁻³, φ ≈ 10°), refined from
//! the truth rounded to the nearest pixel, with the default parameters and with shorter or sparser
//! walks (every second scanline), which trade accuracy for speed (see BENCHMARKS.md).

use conic_corners::refine::{refine_one, RefineParams};
use conic_corners::synth::{scene_for, Protocol};
use criterion::{black_box, criterion_group, criterion_main, Criterion};
use rand::SeedableRng;

fn bench_refine(c: &mut Criterion) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let scene = scene_for(Protocol::Noise, 0.03, &mut rng);
    let rendered = scene.render(7).expect("valid scene");
    let start = [rendered.truth[0].round(), rendered.truth[1].round()];
    let mut group = c.benchmark_group("refine_one");
    for (reach, stride) in [(100.0, 1), (50.0, 1), (25.0, 1), (50.0, 2), (25.0, 2)] {
        let params = RefineParams {
            reach,
            stride,
            ..RefineParams::default()
        };
        let name = match stride {
            1 => format!("reach{reach}"),
            _ => format!("reach{reach}_stride{stride}"),
        };
        group.bench_function(name, |b| {
            b.iter(|| refine_one(black_box(&rendered.image), black_box(start), &params))
        });
    }
    group.finish();
}

criterion_group!(benches, bench_refine);
criterion_main!(benches);
