//! Synthetic test images with exact ground truth, and the Cramér–Rao bound they are judged against.
//!
//! [`corner`] renders the paper's single-corner protocol (section IV-A): an X-junction of two
//! circular-arc edges on a plane seen by a pinhole camera, blurred, integrated over each pixel (the
//! blur comes first, as in a camera) and made noisy, with the corner's image position known
//! exactly. [`board`] renders whole checkerboards, flat or bent around cylinders, elliptic columns
//! and S shapes, with the truth of every inner corner. [`Protocol`] holds the paper's four sweeps
//! (noise, blur, perspective, curvature) and [`scene_for`] draws the other factors as the paper
//! does.
//!
//! All coordinates are image coordinates: x right, y down, the centre of the top-left pixel at
//! (0, 0), pixel `(i, j)` covering `[i − ½, i + ½] × [j − ½, j + ½]`. Intensities are on a full
//! scale of 1.0 (dark level 0); noise levels are fractions of that scale.
//!
//! The module is pure: it builds [`GrayImage`]s and never touches files.

pub mod board;
pub mod corner;

pub use board::{
    random_board_scene, speed_benchmark_scene, BoardCorner, BoardGeometry, BoardScene, Dots,
    Occluder, PinholeCamera, RenderedBoard, Surface, SPEED_BENCHMARK_NOISE_SEED,
};
pub use corner::{scene_for, CornerGeometry, CornerScene, Protocol, RenderedCorner};

use crate::GrayImage;
use rand::Rng;
use rand_distr::{Distribution, Normal};

/// Why a scene cannot be rendered.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SynthError {
    /// A scene parameter is out of its documented range or not finite.
    #[error("invalid scene parameter {name} = {value}: {reason}")]
    InvalidParameter {
        /// Field name.
        name: &'static str,
        /// Offending value.
        value: f64,
        /// The accepted range.
        reason: &'static str,
    },
}

/// Index of `i` reflected into `0..n` about the first and last pixel centres (`dcb|abcd|cba`,
/// OpenCV's `BORDER_REFLECT_101`), folding as often as needed so that any kernel radius works.
fn reflect_101(i: isize, n: usize) -> usize {
    if n == 1 {
        return 0;
    }
    let period = 2 * (n as isize - 1);
    let m = i.rem_euclid(period);
    (if m < n as isize { m } else { period - m }) as usize
}

/// Normalized sampled Gaussian `w_k ∝ exp(−k²/2σ²)`, `k = −r..=r`, `r = ⌈4σ⌉`.
fn gaussian_kernel(sigma: f64) -> Vec<f32> {
    let r = (4.0 * sigma).ceil() as isize;
    let w: Vec<f64> = (-r..=r)
        .map(|k| (-((k * k) as f64) / (2.0 * sigma * sigma)).exp())
        .collect();
    let sum: f64 = w.iter().sum();
    w.iter().map(|v| (v / sum) as f32).collect()
}

/// Gaussian blur with standard deviation `sigma` (pixels), separable, in `f32`.
///
/// The kernel is the sampled Gaussian `exp(−k²/2σ²)` on `k = −⌈4σ⌉..=⌈4σ⌉`, normalized to sum 1,
/// applied along rows then columns; outside pixels are mirrored about the border pixel centres
/// (`BORDER_REFLECT_101`). A constant image stays constant and, away from the borders, the sum of
/// intensities is kept. `sigma ≤ 0` or not finite returns an unchanged copy.
pub fn gaussian_blur(image: &GrayImage, sigma: f64) -> GrayImage {
    if !(sigma > 0.0 && sigma.is_finite()) {
        return image.clone();
    }
    let kernel = gaussian_kernel(sigma);
    let r = (kernel.len() / 2) as isize;
    let (w, h) = (image.width(), image.height());
    let src = image.data();

    // Rows: copy each row into a padded buffer so the inner loop has no index folding.
    let mut tmp = vec![0.0f32; w * h];
    let mut padded = vec![0.0f32; w + 2 * r as usize];
    for y in 0..h {
        let row = &src[y * w..(y + 1) * w];
        for (i, p) in padded.iter_mut().enumerate() {
            *p = row[reflect_101(i as isize - r, w)];
        }
        for (x, out) in tmp[y * w..(y + 1) * w].iter_mut().enumerate() {
            *out = kernel
                .iter()
                .zip(&padded[x..x + kernel.len()])
                .map(|(k, v)| k * v)
                .sum();
        }
    }

    // Columns: accumulate whole source rows into each output row, which keeps memory access
    // sequential.
    let mut out = vec![0.0f32; w * h];
    for y in 0..h {
        let dst = &mut out[y * w..(y + 1) * w];
        for (k, &wk) in kernel.iter().enumerate() {
            let sy = reflect_101(y as isize + k as isize - r, h);
            for (d, s) in dst.iter_mut().zip(&tmp[sy * w..(sy + 1) * w]) {
                *d += wk * s;
            }
        }
    }
    GrayImage::from_vec(w, h, out).expect("same size as the input")
}

/// Cells per pixel side on which [`blur_then_integrate`] blurs by `sigma` (px): enough that the
/// blur spans two cells (`m σ ≥ 2`), at most 4; 1 without blur.
///
/// Why cells at all: a camera's optics blur the continuous image, and then each pixel integrates
/// it over its square. Blurring the pixels' area averages instead (integrate, then blur) differs
/// by the aliasing of the integrated pattern, which the sampled Gaussian passes where its
/// spectrum is not yet negligible (below a third of a cycle per pixel at σ = 1). At σ = 1.16 px
/// that put 0.3 % of the contrast (RMS, 1.2 % at the most) into the pixels around an
/// X-junction, depending on its sub-pixel phase, and a model of the blurred junction fitted to
/// them was 0.012 px off. On cells of a half pixel or less the blur's spectrum is negligible
/// there.
pub(crate) fn blur_cells(sigma: f64) -> usize {
    if sigma.is_nan() || sigma <= 0.0 {
        1
    } else {
        (2.0 / sigma).ceil().clamp(1.0, 4.0) as usize
    }
}

/// The image a camera records of a pattern whose area averages over cells of `1/m` px are
/// `cells` (`m·w × m·h`, cell `(X, Y)` covering `[X/m − ½, (X+1)/m − ½] × [Y/m − ½, (Y+1)/m − ½]`
/// in pixel coordinates): blurred by a Gaussian of `sigma` px ([`gaussian_blur`] of `m·σ` cells),
/// then each pixel the mean of its `m × m` cells. `m = 1` is [`gaussian_blur`].
pub(crate) fn blur_then_integrate(cells: &GrayImage, m: usize, sigma: f64) -> GrayImage {
    let blurred = gaussian_blur(cells, sigma * m as f64);
    if m <= 1 {
        return blurred;
    }
    let (w, h) = (cells.width() / m, cells.height() / m);
    let src = blurred.data();
    let inv = 1.0 / (m * m) as f32;
    let mut out = vec![0.0f32; w * h];
    for (y, row) in out.chunks_mut(w).enumerate() {
        for j in 0..m {
            let line = &src[(y * m + j) * cells.width()..][..w * m];
            for (o, cell) in row.iter_mut().zip(line.chunks_exact(m)) {
                *o += cell.iter().sum::<f32>();
            }
        }
        for o in row.iter_mut() {
            *o *= inv;
        }
    }
    GrayImage::from_vec(w, h, out).expect("whole pixels")
}

/// Adds independent Gaussian noise `N(0, sigma²)` to every pixel, drawn from `rng` in row-major
/// order (so a seeded generator gives the same noise on every machine). Values are not clamped.
/// `sigma ≤ 0` or not finite leaves the image unchanged and draws nothing.
pub fn add_gaussian_noise<R: Rng + ?Sized>(image: &mut GrayImage, sigma: f64, rng: &mut R) {
    if sigma.is_nan() || sigma <= 0.0 {
        return;
    }
    let Ok(normal) = Normal::new(0.0f64, sigma) else {
        return;
    };
    for v in image.data_mut() {
        *v += normal.sample(rng) as f32;
    }
}

/// Cramér–Rao lower bound on the RMS error (pixels) of any unbiased estimate of a 2-D shift of the
/// noise-free image `clean`, observed with white Gaussian noise of standard deviation `noise_sigma`
/// (same units as the intensities) over the `(2·half_window + 1)²` pixels centred on the pixel
/// nearest `center`.
///
/// For `I(x − t) + n`, the Fisher information of `t` is `F = Σ ∇I ∇Iᵀ / σ²` (gradients by central
/// differences `(I(x+1) − I(x−1)) / 2`), and `E|t̂ − t|² ≥ trace(F⁻¹)`; the function returns
/// `sqrt(trace F⁻¹) = sqrt(trace F / det F)`. This is the bound of an estimator that knows the
/// image up to its position — a floor no corner detector reaches, useful as a scale for errors.
///
/// Returns `None` when `noise_sigma` is not positive and finite, `center` is not finite, the window
/// (plus one pixel for the differences) leaves the image, or `F` is singular or nearly so
/// (`det F ≤ 10⁻¹² (trace F)²`, e.g. a single straight edge, which fixes only one direction).
pub fn cramer_rao_bound(
    clean: &GrayImage,
    center: [f64; 2],
    half_window: usize,
    noise_sigma: f64,
) -> Option<f64> {
    let finite = noise_sigma.is_finite() && center[0].is_finite() && center[1].is_finite();
    if !finite || noise_sigma <= 0.0 {
        return None;
    }
    let (cx, cy) = (center[0].round(), center[1].round());
    let h = half_window as f64;
    let (w, ht) = (clean.width() as f64, clean.height() as f64);
    if cx - h < 1.0 || cy - h < 1.0 || cx + h > w - 2.0 || cy + h > ht - 2.0 {
        return None;
    }
    let (cx, cy) = (cx as usize, cy as usize);
    let (mut fxx, mut fxy, mut fyy) = (0.0f64, 0.0f64, 0.0f64);
    for y in cy - half_window..=cy + half_window {
        for x in cx - half_window..=cx + half_window {
            let gx = 0.5 * (clean.get(x + 1, y) as f64 - clean.get(x - 1, y) as f64);
            let gy = 0.5 * (clean.get(x, y + 1) as f64 - clean.get(x, y - 1) as f64);
            fxx += gx * gx;
            fxy += gx * gy;
            fyy += gy * gy;
        }
    }
    let s2 = noise_sigma * noise_sigma;
    let (fxx, fxy, fyy) = (fxx / s2, fxy / s2, fyy / s2);
    let trace = fxx + fyy;
    let det = fxx * fyy - fxy * fxy;
    if trace.is_nan() || trace <= 0.0 || det <= 1e-12 * trace * trace {
        return None;
    }
    Some((trace / det).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn image_from(w: usize, h: usize, f: impl Fn(usize, usize) -> f32) -> GrayImage {
        let data = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| f(x, y));
        GrayImage::from_vec(w, h, data.collect()).unwrap()
    }

    #[test]
    fn reflect_101_folds_any_index() {
        let got: Vec<usize> = (-6..10).map(|i| reflect_101(i, 4)).collect();
        assert_eq!(got, [0, 1, 2, 3, 2, 1, 0, 1, 2, 3, 2, 1, 0, 1, 2, 3]);
        assert_eq!(reflect_101(-5, 1), 0);
    }

    #[test]
    fn blur_keeps_constants_sums_and_symmetry() {
        let flat = GrayImage::filled(7, 5, 0.25).unwrap();
        // Radius 40 is far wider than the image: folding must still give the constant.
        for v in gaussian_blur(&flat, 10.0).data() {
            assert!((v - 0.25).abs() < 1e-6);
        }
        // A blob far from the borders keeps its total intensity and its mirror symmetry.
        let blob = image_from(61, 61, |x, y| {
            let (dx, dy) = (x as f32 - 30.0, y as f32 - 30.0);
            if dx.abs() <= 3.0 && dy.abs() <= 1.0 {
                1.0
            } else {
                0.0
            }
        });
        let out = gaussian_blur(&blob, 2.5);
        let (s0, s1): (f32, f32) = (blob.data().iter().sum(), out.data().iter().sum());
        assert!((s0 - s1).abs() < 1e-4, "{s0} vs {s1}");
        for y in 0..61 {
            for x in 0..61 {
                assert!((out.get(x, y) - out.get(60 - x, y)).abs() < 1e-6);
                assert!((out.get(x, y) - out.get(x, 60 - y)).abs() < 1e-6);
            }
        }
        // The centre value of a blurred impulse is the kernel's peak squared.
        let k = gaussian_kernel(2.5);
        let impulse = image_from(41, 41, |x, y| (x == 20 && y == 20) as u8 as f32);
        let peak = gaussian_blur(&impulse, 2.5).get(20, 20);
        assert!((peak - k[k.len() / 2].powi(2)).abs() < 1e-7);
        // No blur requested: unchanged.
        assert_eq!(gaussian_blur(&blob, 0.0), blob);
        assert_eq!(gaussian_blur(&blob, f64::NAN), blob);
    }

    #[test]
    fn noise_is_seeded_and_has_the_requested_spread() {
        let base = GrayImage::filled(200, 200, 0.5).unwrap();
        let noisy = |seed| {
            let mut img = base.clone();
            add_gaussian_noise(&mut img, 0.05, &mut ChaCha8Rng::seed_from_u64(seed));
            img
        };
        assert_eq!(noisy(3), noisy(3));
        assert_ne!(noisy(3), noisy(4));
        let img = noisy(3);
        let n = img.data().len() as f64;
        let mean = img.data().iter().map(|&v| v as f64).sum::<f64>() / n;
        let var = img
            .data()
            .iter()
            .map(|&v| (v as f64 - mean).powi(2))
            .sum::<f64>()
            / n;
        // 40 000 samples: mean within ~4 standard errors, std within ~1 %.
        assert!((mean - 0.5).abs() < 0.001, "{mean}");
        assert!((var.sqrt() - 0.05).abs() < 0.0008, "{}", var.sqrt());
        let mut same = base.clone();
        add_gaussian_noise(&mut same, -1.0, &mut ChaCha8Rng::seed_from_u64(0));
        add_gaussian_noise(&mut same, f64::NAN, &mut ChaCha8Rng::seed_from_u64(0));
        assert_eq!(same, base);
    }

    #[test]
    fn crb_matches_hand_computation_on_a_paraboloid() {
        // I = a·dx² + b·dy² around (20, 20): central differences are exact, ∇I = (2a dx, 2b dy),
        // F = diag(4a² Σdx², 4b² Σdy²)/σ² with Σdx² = (2h+1)·h(h+1)(2h+1)/3, cross term zero.
        let (a, b, h, sigma) = (0.01f64, 0.02f64, 5usize, 0.03f64);
        let img = image_from(41, 41, |x, y| {
            let (dx, dy) = (x as f64 - 20.0, y as f64 - 20.0);
            (a * dx * dx + b * dy * dy) as f32
        });
        let hf = h as f64;
        let sum_d2 = (2.0 * hf + 1.0) * hf * (hf + 1.0) * (2.0 * hf + 1.0) / 3.0;
        let fxx = 4.0 * a * a * sum_d2 / (sigma * sigma);
        let fyy = 4.0 * b * b * sum_d2 / (sigma * sigma);
        let expected = (1.0 / fxx + 1.0 / fyy).sqrt();
        let got = cramer_rao_bound(&img, [20.2, 19.7], h, sigma).unwrap();
        assert!(
            (got - expected).abs() < 1e-4 * expected,
            "{got} vs {expected}"
        );
        // Linear in σ.
        let got2 = cramer_rao_bound(&img, [20.0, 20.0], h, 2.0 * sigma).unwrap();
        assert!((got2 - 2.0 * expected).abs() < 1e-4 * expected);
    }

    #[test]
    fn crb_rejects_edges_flat_patches_and_bad_input() {
        // A straight edge fixes only its normal direction: singular information.
        let edge = image_from(30, 30, |x, _| ((x as f32 - 14.5) / 2.0).tanh());
        assert_eq!(cramer_rao_bound(&edge, [15.0, 15.0], 5, 0.01), None);
        let flat = GrayImage::filled(30, 30, 1.0).unwrap();
        assert_eq!(cramer_rao_bound(&flat, [15.0, 15.0], 5, 0.01), None);
        // A corner is well posed.
        let corner = image_from(30, 30, |x, y| {
            let s = ((x as f32 - 14.5) / 2.0).tanh() * ((y as f32 - 14.5) / 2.0).tanh();
            0.5 + 0.5 * s
        });
        assert!(cramer_rao_bound(&corner, [15.0, 15.0], 5, 0.01).is_some());
        assert_eq!(cramer_rao_bound(&corner, [15.0, 15.0], 5, 0.0), None);
        assert_eq!(cramer_rao_bound(&corner, [15.0, 15.0], 5, f64::NAN), None);
        assert_eq!(cramer_rao_bound(&corner, [f64::NAN, 15.0], 5, 0.01), None);
        // Window plus difference stencil must fit: centre 5 with h = 5 needs pixel −1.
        assert_eq!(cramer_rao_bound(&corner, [5.0, 15.0], 5, 0.01), None);
        assert!(cramer_rao_bound(&corner, [6.0, 15.0], 5, 0.01).is_some());
        assert_eq!(cramer_rao_bound(&corner, [24.0, 15.0], 5, 0.01), None);
        assert!(cramer_rao_bound(&corner, [23.0, 15.0], 5, 0.01).is_some());
    }
}
