//! On-CPU time of the single-corner refiner, immune to other processes sharing the cores (the
//! criterion bench measures wall time): `cargo test --release -p conic-corners --test
//! refine_timing -- --ignored --nocapture`.

use conic_corners::refine::{refine_one, RefineParams, Status};
use conic_corners::synth::{scene_for, Protocol};
use rand::SeedableRng;

/// On-CPU nanoseconds of this thread (Linux `schedstat`), NaN elsewhere.
fn cpu_ns() -> f64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse::<f64>().ok())
        .unwrap_or(f64::NAN)
}

#[test]
#[ignore]
fn refine_cpu_time_per_corner() {
    // The bench's corner (σn 3 %, blur 3 px) and a few more of the noise protocol.
    let scenes: Vec<_> = [(0.03, 7u64), (0.0, 1), (0.1, 2), (0.03, 3)]
        .into_iter()
        .map(|(noise, seed)| {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let r = scene_for(Protocol::Noise, noise, &mut rng)
                .render(seed)
                .unwrap();
            let start = [r.truth[0].round(), r.truth[1].round()];
            (r.image, start)
        })
        .collect();
    for reach in [100.0, 50.0, 25.0] {
        let params = RefineParams {
            reach,
            ..RefineParams::default()
        };
        for (k, (image, start)) in scenes.iter().enumerate() {
            let reps = 200;
            let c0 = cpu_ns();
            let mut ok = 0;
            for _ in 0..reps {
                let r = refine_one(std::hint::black_box(image), *start, &params);
                ok += (r.status != Status::Failed) as u32;
            }
            let us = (cpu_ns() - c0) / reps as f64 / 1e3;
            eprintln!(
                "reach {reach:>3}: scene {k}: {us:7.1} µs CPU per corner ({ok}/{reps} found)"
            );
        }
    }
}
