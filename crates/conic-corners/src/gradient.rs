//! Corner position by gradient orthogonality: the last resort for corners whose edges are too
//! short or too compressed for edge sampling (near the silhouette of a strongly bent board, where
//! the squares are foreshortened to a few pixels across and the edge walks find nothing to fit).
//!
//! Near an X-junction at `q` every edge is, to first order, a line through `q`, so the image
//! gradient `g(p)` at a pixel `p` on an edge is orthogonal to `p − q`. The corner therefore
//! minimizes
//!
//! ```text
//! E(q) = Σₚ w(p) (g(p)ᵀ (q − p))²,   w(p) = exp(−|p − q|² / 2σ_w²),
//! ```
//!
//! whose minimizer solves the 2×2 system `(Σ w g gᵀ) q = Σ w g gᵀ p` (Förstner and Gülch's
//! operator, the principle of OpenCV's `cornerSubPix`). The window is re-centred on the new `q`
//! and the solve repeated until it settles.
//!
//! **Uncertainty.** With residuals `rₚ = g(p)ᵀ(q − p)` at the answer and `A = Σ w g gᵀ`, the
//! sandwich covariance `A⁻¹ (Σ w² r² g gᵀ) A⁻¹` of the weighted least-squares solution counts every
//! misfit as noise: the blurred zone at the junction, where the gradients are not quite orthogonal
//! to `p − q` but cancel by symmetry, makes it conservative (on the curved-board benchmark its
//! median was 0.27 px for errors of a median 0.15 px at foreshortened corners, and 0.16 px for
//! errors of 0.03 px elsewhere).
//!
//! It is less accurate than the quadratic-form fits on long edges (a median of about 0.03 px
//! against 0.008 px on the curved-board benchmark), because the blurred zone at the junction
//! breaks the orthogonality, but it needs nothing beyond a few pixels around the corner. It is
//! also biased where a print's dot gain makes the junction asymmetric: on the `marker_real`
//! photo, whose print offsets the two polarities of a line by about 3 px, it lies a median 1.2 px
//! from the board-wide answers. Hence it is only a last resort.
//!
//! Coordinates: x right, y down, the centre of the top-left pixel is `(0, 0)`.

use crate::quadratic_form::worst_sigma;
use crate::GrayImage;
use nalgebra::Matrix2;

/// Parameters of [`refine_gradient`]. `Default` is what [`crate::detect`] uses.
#[derive(Clone, Debug, PartialEq)]
pub struct GradientParams {
    /// Half-size (px) of the square window of gradients around the current estimate.
    pub radius: usize,
    /// σ_w (px) of the Gaussian weight centred on the current estimate.
    pub window_sigma: f64,
    /// σ (px) of the Gaussian smoothing applied before the central-difference gradients (noise).
    pub smoothing: f64,
    /// Largest number of re-centred solves.
    pub max_iterations: usize,
    /// Largest accepted distance (px) between the start and the answer.
    pub max_shift: f64,
}

impl Default for GradientParams {
    fn default() -> Self {
        Self {
            radius: 6,
            window_sigma: 3.5,
            smoothing: 0.7,
            max_iterations: 20,
            max_shift: 1.5,
        }
    }
}

impl GradientParams {
    /// Checks the parameters; the message names the offending one.
    pub fn validate(&self) -> Result<(), String> {
        if !(1..=MAX_RADIUS).contains(&self.radius) {
            return Err(format!(
                "the gradient window radius must be in 1..={MAX_RADIUS} px, got {}",
                self.radius
            ));
        }
        for (name, v, lo, hi) in [
            ("window sigma", self.window_sigma, 0.1, MAX_WINDOW_SIGMA),
            ("smoothing", self.smoothing, 0.0, 8.0),
            ("maximum shift", self.max_shift, 0.0, 1e6),
        ] {
            if !(v.is_finite() && (lo..=hi).contains(&v)) {
                return Err(format!(
                    "the gradient {name} must be in {lo}..={hi}, got {v}"
                ));
            }
        }
        Ok(())
    }
}

/// Largest [`GradientParams::radius`] (px).
pub(crate) const MAX_RADIUS: usize = 32;
/// Largest [`GradientParams::window_sigma`] (px).
pub(crate) const MAX_WINDOW_SIGMA: f64 = 64.0;

/// Movement (px) of the estimate below which the iteration stops.
const SETTLED_PX: f64 = 1e-3;

/// A corner placed by [`refine_gradient`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GradientCorner {
    /// Position (image coordinates).
    pub point: [f64; 2],
    /// Standard deviation (px) in the worst direction, from the sandwich covariance (module docs).
    pub sigma: f64,
    /// The sandwich covariance of `point` (px², image axes); `sigma` is the square root of its
    /// larger eigenvalue.
    pub cov: [[f64; 2]; 2],
}

/// Refines the corner near `start` (image coordinates) by gradient orthogonality (see the module
/// docs). Returns `None` when the parameters are invalid, the window leaves the image, the
/// gradients do not constrain both directions (a single edge or a flat patch), or the answer
/// lies farther than `max_shift` from `start`.
pub fn refine_gradient(
    image: &GrayImage,
    start: [f64; 2],
    params: &GradientParams,
) -> Option<GradientCorner> {
    if params.validate().is_err() || !start.iter().all(|v| v.is_finite()) {
        return None;
    }
    let mut patch = Patch::new(params);
    let mut q = start;
    let mut centre = None;
    for _ in 0..params.max_iterations.max(1) {
        let c = [q[0].round() as isize, q[1].round() as isize];
        if centre != Some(c) {
            patch.load(image, c)?;
            centre = Some(c);
        }
        let next = patch.solve(q, params.window_sigma)?;
        let step = (next[0] - q[0]).hypot(next[1] - q[1]);
        q = next;
        if (q[0] - start[0]).hypot(q[1] - start[1]) > params.max_shift {
            return None;
        }
        if step < SETTLED_PX {
            break;
        }
    }
    let c = [q[0].round() as isize, q[1].round() as isize];
    if centre != Some(c) {
        patch.load(image, c)?;
    }
    let cov = patch.covariance(q, params.window_sigma)?;
    Some(GradientCorner {
        point: q,
        sigma: worst_sigma(cov),
        cov,
    })
}

/// The smoothed gradients of a `(2r + 1)²` window around an integer centre.
struct Patch {
    radius: usize,
    kernel: Vec<f32>,
    /// Raw pixels, `(2(r + 1 + k) + 1)²` for kernel radius `k`, then the horizontal pass.
    raw: Vec<f32>,
    horizontal: Vec<f32>,
    /// Smoothed pixels, `(2(r + 1) + 1)²`.
    smooth: Vec<f32>,
    gx: Vec<f32>,
    gy: Vec<f32>,
    centre: [isize; 2],
}

impl Patch {
    fn new(params: &GradientParams) -> Self {
        let s = params.smoothing;
        let k = (3.0 * s).ceil() as usize;
        let mut kernel: Vec<f32> = (0..=2 * k)
            .map(|i| {
                let d = i as f64 - k as f64;
                if s > 0.0 {
                    (-d * d / (2.0 * s * s)).exp() as f32
                } else {
                    1.0
                }
            })
            .collect();
        let sum: f32 = kernel.iter().sum();
        kernel.iter_mut().for_each(|v| *v /= sum);
        let r = params.radius;
        let (outer, inner, win) = (2 * (r + 1 + k) + 1, 2 * (r + 1) + 1, 2 * r + 1);
        Self {
            radius: r,
            kernel,
            raw: vec![0.0; outer * outer],
            horizontal: vec![0.0; outer * inner],
            smooth: vec![0.0; inner * inner],
            gx: vec![0.0; win * win],
            gy: vec![0.0; win * win],
            centre: [0, 0],
        }
    }

    /// Reads, smooths (separably) and differentiates the window around `c`; `None` if it leaves
    /// the image.
    fn load(&mut self, image: &GrayImage, c: [isize; 2]) -> Option<()> {
        let r = self.radius as isize;
        let k = (self.kernel.len() / 2) as isize;
        let half = r + 1 + k;
        let (w, h) = (image.width() as isize, image.height() as isize);
        if c[0] - half < 0 || c[1] - half < 0 || c[0] + half >= w || c[1] + half >= h {
            return None;
        }
        let outer = (2 * half + 1) as usize;
        let inner = (2 * (r + 1) + 1) as usize;
        for (j, dst) in self.raw.chunks_exact_mut(outer).enumerate() {
            let y = (c[1] - half) as usize + j;
            let x0 = (c[0] - half) as usize;
            dst.copy_from_slice(&image.row(y)[x0..x0 + outer]);
        }
        // Horizontal pass: all `outer` rows, the `inner` central columns.
        for (src, dst) in self
            .raw
            .chunks_exact(outer)
            .zip(self.horizontal.chunks_exact_mut(inner))
        {
            for (i, d) in dst.iter_mut().enumerate() {
                *d = src[i..i + self.kernel.len()]
                    .iter()
                    .zip(&self.kernel)
                    .map(|(a, b)| a * b)
                    .sum();
            }
        }
        // Vertical pass: the `inner` central rows.
        for (j, dst) in self.smooth.chunks_exact_mut(inner).enumerate() {
            dst.fill(0.0);
            for (t, &kv) in self.kernel.iter().enumerate() {
                let src = &self.horizontal[(j + t) * inner..(j + t + 1) * inner];
                for (d, s) in dst.iter_mut().zip(src) {
                    *d += kv * s;
                }
            }
        }
        let win = 2 * self.radius + 1;
        for j in 0..win {
            for i in 0..win {
                let (x, y) = (i + 1, j + 1);
                let at = |x: usize, y: usize| self.smooth[y * inner + x];
                self.gx[j * win + i] = 0.5 * (at(x + 1, y) - at(x - 1, y));
                self.gy[j * win + i] = 0.5 * (at(x, y + 1) - at(x, y - 1));
            }
        }
        self.centre = c;
        Some(())
    }

    /// Visits every window pixel as `(position, gradient, weight)`, the weight centred on `q`.
    fn each(&self, q: [f64; 2], window_sigma: f64, mut f: impl FnMut([f64; 2], [f64; 2], f64)) {
        let r = self.radius as isize;
        let win = 2 * self.radius + 1;
        let inv = 1.0 / (2.0 * window_sigma * window_sigma);
        for j in 0..win {
            let py = (self.centre[1] + j as isize - r) as f64;
            let dy = py - q[1];
            for i in 0..win {
                let px = (self.centre[0] + i as isize - r) as f64;
                let dx = px - q[0];
                let wgt = (-(dx * dx + dy * dy) * inv).exp();
                let g = [self.gx[j * win + i] as f64, self.gy[j * win + i] as f64];
                f([px, py], g, wgt);
            }
        }
    }

    /// `A = Σ w g gᵀ` as `(axx, axy, ayy)`, or `None` unless both of its eigenvalues are a fair
    /// share of the total: a single straight edge (or a flat patch) leaves the position along it
    /// undetermined.
    fn checked(axx: f64, axy: f64, ayy: f64) -> Option<f64> {
        let det = axx * ayy - axy * axy;
        let trace = axx + ayy;
        (det.is_finite() && trace > 0.0 && det > 1e-4 * trace * trace).then_some(det)
    }

    /// One solve of the normal equations with the Gaussian weight centred on `q`.
    fn solve(&self, q: [f64; 2], window_sigma: f64) -> Option<[f64; 2]> {
        let (mut axx, mut axy, mut ayy, mut bx, mut by) = (0.0f64, 0.0, 0.0, 0.0, 0.0);
        self.each(q, window_sigma, |p, g, w| {
            let (xx, xy, yy) = (w * g[0] * g[0], w * g[0] * g[1], w * g[1] * g[1]);
            axx += xx;
            axy += xy;
            ayy += yy;
            bx += xx * p[0] + xy * p[1];
            by += xy * p[0] + yy * p[1];
        });
        let det = Self::checked(axx, axy, ayy)?;
        Some([(ayy * bx - axy * by) / det, (axx * by - axy * bx) / det])
    }

    /// The sandwich covariance of the answer `q` (module docs).
    fn covariance(&self, q: [f64; 2], window_sigma: f64) -> Option<[[f64; 2]; 2]> {
        let (mut a, mut b) = ([0.0f64; 3], [0.0f64; 3]);
        self.each(q, window_sigma, |p, g, w| {
            let r = g[0] * (q[0] - p[0]) + g[1] * (q[1] - p[1]);
            let (xx, xy, yy) = (g[0] * g[0], g[0] * g[1], g[1] * g[1]);
            let v = w * w * r * r;
            a[0] += w * xx;
            a[1] += w * xy;
            a[2] += w * yy;
            b[0] += v * xx;
            b[1] += v * xy;
            b[2] += v * yy;
        });
        Self::checked(a[0], a[1], a[2])?;
        let ai = Matrix2::new(a[0], a[1], a[1], a[2]).try_inverse()?;
        let c = ai * Matrix2::new(b[0], b[1], b[1], b[2]) * ai;
        // Symmetric to the last bit: the product's two off-diagonal sums round differently.
        let xy = 0.5 * (c[(0, 1)] + c[(1, 0)]);
        let cov = [[c[(0, 0)], xy], [xy, c[(1, 1)]]];
        cov.iter().flatten().all(|v| v.is_finite()).then_some(cov)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::CornerScene;

    /// An X-junction `offset` px from the centre of an 81×81 image, its edges `edge_angle` apart,
    /// area-sampled, blurred and noisy; returns the image and the exact corner.
    fn junction(offset: [f64; 2], edge_angle: f64, blur: f64, noise: f64) -> (GrayImage, [f64; 2]) {
        let scene = CornerScene {
            size: 81,
            offset,
            edge_angle,
            rotation: 0.4,
            blur,
            noise,
            ..CornerScene::default()
        };
        let r = scene.render(3).expect("valid scene");
        (r.image, r.truth)
    }

    /// The junction is point-symmetric about the corner, so the continuous estimate is exact; the
    /// pixel grid breaks that symmetry off pixel centres and leaves a bias of about 0.02 px on a
    /// right-angled junction and 0.035 px on a sheared one (34°), noise-free.
    #[test]
    fn recovers_junctions() {
        let right = std::f64::consts::FRAC_PI_2;
        for (offset, angle, blur, noise, tol) in [
            ([0.0, 0.0], right, 1.0, 0.0, 0.01),
            ([0.3, -0.25], right, 1.0, 0.0, 0.03),
            ([-0.5, 0.5], 0.6, 1.2, 0.0, 0.045),
            ([0.2, 0.4], right, 1.0, 0.01, 0.05),
        ] {
            let (img, truth) = junction(offset, angle, blur, noise);
            let start = [truth[0] + 0.8, truth[1] - 0.6];
            let c = refine_gradient(&img, start, &GradientParams::default()).expect("converges");
            let q = c.point;
            let e = (q[0] - truth[0]).hypot(q[1] - truth[1]);
            assert!(e < tol, "{offset:?}, angle {angle}: off by {e} px");
            // Conservative: the blurred junction's misfit counts as noise.
            assert!(
                c.sigma.is_finite() && c.sigma >= e,
                "sigma {} for {e} px",
                c.sigma
            );
        }
    }

    #[test]
    fn rejects_bad_input() {
        let (img, _) = junction([0.0, 0.0], std::f64::consts::FRAC_PI_2, 1.0, 0.0);
        let p = GradientParams::default();
        // Window leaves the image.
        assert!(refine_gradient(&img, [2.0, 40.0], &p).is_none());
        assert!(refine_gradient(&img, [f64::NAN, 40.0], &p).is_none());
        let bad = GradientParams {
            radius: 0,
            ..p.clone()
        };
        assert!(refine_gradient(&img, [40.0, 40.0], &bad).is_none());
        // A flat image and a single straight edge do not fix a point.
        let flat = GrayImage::filled(80, 80, 0.5).unwrap();
        assert!(refine_gradient(&flat, [40.0, 40.0], &p).is_none());
        let edge = GrayImage::from_vec(
            80,
            80,
            (0..80 * 80)
                .map(|i| if i % 80 < 40 { 0.2 } else { 0.8 })
                .collect(),
        )
        .unwrap();
        assert!(refine_gradient(&edge, [40.0, 40.0], &p).is_none());
    }
}
