//! Final election (paper III-B): the two edge orientations of a candidate from a quadratic surface
//! fit (eq. 3–4), the matching template from a bank built once, and the NCC score (eq. 5).

use crate::GrayImage;
use nalgebra::{DMatrix, DVector};
use std::sync::OnceLock;

/// A corner found at pixel level, with the orientations of its two edges.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Corner {
    /// Position in image coordinates (pixel centres at integers).
    pub x: f64,
    /// Position in image coordinates (pixel centres at integers).
    pub y: f64,
    /// Orientations of the two edges through the corner, radians in `[0, π)`, measured from the
    /// +x axis towards +y (image y points down).
    pub angles: [f64; 2],
    /// Template-matching score (normalized cross-correlation, −1..1).
    pub score: f64,
}

/// Largest half-size accepted by [`edge_orientations`].
pub const MAX_SURFACE_HALF: usize = 32;

/// Row-major 3×N matrix mapping a (2h+1)² window (row-major, offsets −h..h) to the least-squares
/// coefficients (α, β, γ) of `αx² + βxy + γy² + δx + εy + ζ`. The design matrix depends only on the
/// window, so the fit is three dot products per call.
fn surface_projector(half: usize) -> &'static [Vec<f64>; 3] {
    static CACHE: OnceLock<Vec<[Vec<f64>; 3]>> = OnceLock::new();
    let all = CACHE.get_or_init(|| {
        (0..=MAX_SURFACE_HALF)
            .map(|h| {
                let side = 2 * h + 1;
                let n = side * side;
                let mut a = DMatrix::<f64>::zeros(n, 6);
                for (i, (dy, dx)) in (0..side)
                    .flat_map(|r| (0..side).map(move |c| (r, c)))
                    .enumerate()
                {
                    let (x, y) = (dx as f64 - h as f64, dy as f64 - h as f64);
                    let row = [x * x, x * y, y * y, x, y, 1.0];
                    for (j, v) in row.iter().enumerate() {
                        a[(i, j)] = *v;
                    }
                }
                let ata = a.transpose() * &a;
                let proj = ata
                    .try_inverse()
                    .map(|inv| inv * a.transpose())
                    .unwrap_or_else(|| DMatrix::zeros(6, n));
                [0, 1, 2].map(|k| proj.row(k).iter().copied().collect())
            })
            .collect()
    });
    &all[half]
}

/// Orientations `[θ₁, θ₂]` (radians in `[0, π)`) of the two edges of a saddle at `(x, y)`.
///
/// Fits `I ≈ αx² + βxy + γy² + δx + εy + ζ` by least squares on the `(2·half+1)²` pixel window
/// centred on the pixel nearest `(x, y)` (eq. 3). The quadratic part factors as
/// `k(x sinθ₁ − y cosθ₁)(x sinθ₂ − y cosθ₂)` (eq. 4): its zero lines, where
/// `α cos²θ + β cosθ sinθ + γ sin²θ = 0`, are the edges. Writing that as
/// `M + R cos(2θ − ψ) = 0` with `M = (α+γ)/2`, `R = |((α−γ)/2, β/2)|`, `ψ = atan2(β/2, (α−γ)/2)`
/// gives `θ = (ψ ± acos(−M/R)) / 2`. Returns `None` when the window leaves the image, `half` is 0 or
/// above [`MAX_SURFACE_HALF`], or the surface is not a saddle (`|M| ≥ R`).
pub fn edge_orientations(image: &GrayImage, x: f64, y: f64, half: usize) -> Option<[f64; 2]> {
    if half == 0 || half > MAX_SURFACE_HALF || !x.is_finite() || !y.is_finite() {
        return None;
    }
    let (cx, cy) = (x.round() as isize, y.round() as isize);
    let h = half as isize;
    if cx - h < 0
        || cy - h < 0
        || cx + h >= image.width() as isize
        || cy + h >= image.height() as isize
    {
        return None;
    }
    let proj = surface_projector(half);
    let side = 2 * half + 1;
    let (mut alpha, mut beta, mut gamma) = (0.0, 0.0, 0.0);
    for r in 0..side {
        let row = image.row((cy - h) as usize + r);
        let start = (cx - h) as usize;
        for (c, &v) in row[start..start + side].iter().enumerate() {
            let i = r * side + c;
            let v = v as f64;
            alpha += proj[0][i] * v;
            beta += proj[1][i] * v;
            gamma += proj[2][i] * v;
        }
    }
    saddle_orientations(alpha, beta, gamma)
}

/// Zero-line orientations of the quadratic form `αx² + βxy + γy²`, or `None` if it is not
/// indefinite. See [`edge_orientations`].
pub fn saddle_orientations(alpha: f64, beta: f64, gamma: f64) -> Option<[f64; 2]> {
    let m = 0.5 * (alpha + gamma);
    let (a, b) = (0.5 * (alpha - gamma), 0.5 * beta);
    let r = a.hypot(b);
    if !(r > 0.0) || m.abs() >= r {
        return None;
    }
    let psi = b.atan2(a);
    let spread = (-m / r).acos();
    let wrap = |t: f64| t.rem_euclid(std::f64::consts::PI);
    let (t1, t2) = (wrap(0.5 * (psi - spread)), wrap(0.5 * (psi + spread)));
    Some(if t1 <= t2 { [t1, t2] } else { [t2, t1] })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn angle_diff(a: f64, b: f64) -> f64 {
        let d = (a - b).rem_euclid(PI);
        d.min(PI - d)
    }

    #[test]
    fn recovers_the_zero_lines_of_a_product_of_two_lines() {
        for (t1, t2) in [(0.3, 1.9), (0.0, PI / 2.0), (1.0, 1.4), (2.5, 0.2)] {
            let (s1, c1, s2, c2) = (f64::sin(t1), f64::cos(t1), f64::sin(t2), f64::cos(t2));
            // k(x s1 − y c1)(x s2 − y c2)
            let (alpha, beta, gamma) = (s1 * s2, -(s1 * c2 + c1 * s2), c1 * c2);
            let got = saddle_orientations(2.0 * alpha, 2.0 * beta, 2.0 * gamma).unwrap();
            let want = if t1 < t2 { [t1, t2] } else { [t2, t1] };
            assert!(angle_diff(got[0], want[0]) < 1e-9 && angle_diff(got[1], want[1]) < 1e-9);
        }
        assert!(saddle_orientations(1.0, 0.0, 1.0).is_none());
    }

    fn checker(t1: f64, t2: f64, cx: f64, cy: f64) -> GrayImage {
        let (w, h) = (41, 41);
        let mut data = vec![0f32; w * h];
        for y in 0..h {
            for x in 0..w {
                let (dx, dy) = (x as f64 - cx, y as f64 - cy);
                let a = dx * t1.sin() - dy * t1.cos();
                let b = dx * t2.sin() - dy * t2.cos();
                data[y * w + x] = if a * b > 0.0 { 200.0 } else { 30.0 };
            }
        }
        GrayImage::from_vec(w, h, data).unwrap()
    }

    #[test]
    fn finds_the_edges_of_a_sharp_checker_corner() {
        let img = checker(0.4, 0.4 + PI / 2.0, 20.3, 19.8);
        let got = edge_orientations(&img, 20.3, 19.8, 7).unwrap();
        assert!(angle_diff(got[0], 0.4) < 0.06, "{got:?}");
        assert!(angle_diff(got[1], 0.4 + PI / 2.0) < 0.06, "{got:?}");
        assert!(edge_orientations(&img, 2.0, 20.0, 7).is_none());
    }

    #[test]
    fn oblique_corners_come_out_biased_towards_orthogonal_but_close() {
        // A step corner is not a product of two planes: the fit spreads a 74° corner to ~97°. The
        // template bank tolerates that and the refiner re-measures directions along the edges.
        let img = checker(0.4, 1.7, 20.3, 19.8);
        let got = edge_orientations(&img, 20.3, 19.8, 7).unwrap();
        assert!(angle_diff(got[0], 0.4) < 0.2, "{got:?}");
        assert!(angle_diff(got[1], 1.7) < 0.3, "{got:?}");
    }
}
