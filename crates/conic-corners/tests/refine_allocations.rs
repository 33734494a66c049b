//! The refiner allocates per corner, never per edge sample: the number of heap allocations of a
//! refinement does not grow with the length of the edge walks.

use conic_corners::refine::{refine_one, RefineParams, Status};
use conic_corners::synth::{scene_for, Protocol};
use rand::SeedableRng;
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        System.alloc(layout)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        System.realloc(ptr, layout, new_size)
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn allocations_do_not_grow_with_the_number_of_samples() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let scene = scene_for(Protocol::Noise, 0.03, &mut rng);
    let rendered = scene.render(5).unwrap();
    let start = [rendered.truth[0].round(), rendered.truth[1].round()];
    let count = |reach: f64| {
        let params = RefineParams {
            reach,
            ..RefineParams::default()
        };
        let before = ALLOCATIONS.load(Ordering::Relaxed);
        let r = refine_one(&rendered.image, start, &params);
        let n = ALLOCATIONS.load(Ordering::Relaxed) - before;
        assert_eq!(r.status, Status::Converged);
        (n, r.samples)
    };
    count(100.0); // warm up one-time tables (ring and surface-fit projectors)
    let (short, few) = count(40.0);
    let (long, many) = count(250.0);
    assert!(
        many > 3 * few,
        "the long walk takes more samples ({few} vs {many})"
    );
    assert_eq!(
        short, long,
        "allocations: {short} for {few} samples, {long} for {many}"
    );
}
