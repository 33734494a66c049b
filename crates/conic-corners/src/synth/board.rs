//! Whole checkerboards, flat or bent around a surface, seen by a pinhole camera with radial
//! distortion, with the exact image position, visibility and edge curvature of every inner corner.
//!
//! **Sheet.** The printed sheet has coordinates `(u, v)` in millimetres: `u` along the columns
//! (board x), `v` along the rows (board y), origin at the centre of the squares. It holds
//! `(rows + 1) × (cols + 1)` squares of side `s`, so the squares span `|u| ≤ W/2 = (cols + 1)s/2`,
//! `|v| ≤ H/2 = (rows + 1)s/2`; square `(i, j)` (column `i`, row `j`, from the top left) is dark when
//! `i + j` is even. Inner corner `(row, col)` sits at `u = (col + 1)s − W/2`, `v = (row + 1)s − H/2`.
//! A white margin of width `m` surrounds the squares; beyond it there is no sheet (background).
//! Optional dots ([`Dots`]) put a disc of the opposite colour at the centre of some squares.
//!
//! **Surface.** Every [`Surface`] is a generalized cylinder: a plane curve `C(u) = (X(u), Z(u))`,
//! parametrized by arc length, extruded along the board-frame Y axis, so the sheet point `(u, v)`
//! lies at `P = (X(u), v, Z(u))` in the board frame, `C(0) = 0`, `C′(0) = (1, 0)`. Sheet lengths are
//! kept (the paper is bent, not stretched). The front of the sheet faces −Z at `u = 0`; its normal
//! is `n(u) = (Z′(u), 0, −X′(u))`.
//!
//! - flat: `C(u) = (u, 0)`;
//! - cylinder of signed radius `R` (`σ = sign R`, `ρ = |R|`): `C(u) = (ρ sin θ, σρ(1 − cos θ))`,
//!   `θ = u/ρ`: `R > 0` is convex towards the camera, the axis behind the sheet;
//! - elliptic column with semi-axes `a` (along X) and `b` (along Z): `C = (a sin τ, b(1 − cos τ))`
//!   with `τ` the angle whose arc length from `τ = 0` is `u`; the arc length is tabulated by
//!   Gauss–Legendre quadrature and interpolated by cubic Hermite splines (error ~10⁻¹³ mm), inverted
//!   by Newton steps;
//! - S shape of signed radius `R`: the cylinder's arc of sign `σ` for `u ≥ 0` and of sign `−σ` for
//!   `u < 0`, an inflection at the centre (C¹: tangent continuous, curvature jumps from `−σ/ρ` to
//!   `σ/ρ`).
//!
//! **Camera.** The pose maps board-frame points to the camera frame (`x` right, `y` down, `z`
//! forward): `p = R P + T`. The normalized point `(x_n, y_n) = (p_x, p_y)/p_z` is distorted radially,
//! `x_d = x_n (1 + k₁r² + k₂r⁴)`, `r² = x_n² + y_n²`, then `x = f_x x_d + c_x`, `y = f_y y_d + c_y`
//! (pixel centres at integers). The distortion must be monotonic in `r` over the image
//! (`d(r(1 + k₁r² + k₂r⁴))/dr > 0`), else the scene is rejected.
//!
//! **Rendering** is by inverse mapping: each image point is undistorted (Newton's method on the
//! radius, safeguarded by bisection, to machine precision), cast as a ray into the board frame and
//! intersected with the surface in closed form (a line, a circle, an ellipse, or two circles); the
//! nearest hit on the sheet gives the colour, a hit on the back of the sheet or no hit gives the
//! background. The image is area-sampled on cells of `1/m` px (`m` from `blur_cells`: one
//! cell per pixel without blur or at σ ≥ 2 px, up to 4 per side at small blur). A cell takes its
//! centre's colour when its centre and four corners see the same region (the same square and dot
//! state, margin or background), and no occluder edge passes within 0.75 cell of its centre;
//! otherwise it averages about `s/m × s/m` jittered sub-samples, with the jitter of
//! [`corner`](super::corner) (deterministic, unbiased along edges). Regions are convex on the sheet,
//! so only features narrower than half a pixel in the image (dots, far squares) can slip between the
//! five probes. Occluders ([`Occluder`]: opaque bars with round ends, in image coordinates) are drawn
//! over the projected board, before the lighting gain, blur and noise, like objects in the scene.
//! Then the lighting gain `1 + g_x (x − x̄)/width + g_y (y − ȳ)/height` (`x̄, ȳ` the image centre)
//! multiplies every cell, the Gaussian blur is applied to the cells, each pixel takes the mean of
//! its `m × m` cells (the blur comes first, as in a camera: `blur_then_integrate`), and
//! Gaussian noise is added from a seeded ChaCha8 generator. The gain does not move edges of the sharp image; after blur it shifts an edge
//! by about `σ² |∇gain|/gain`, i.e. < 10⁻³ px for realistic gradients, which the truth ignores.
//!
//! **Truth.** Corner positions are forward projections of the exact surface points. A corner is
//! visible when it projects inside the image with [`VISIBILITY_MARGIN`] pixels to spare, the sheet
//! faces the camera there at less than [`MAX_VIEW_ANGLE_DEG`] from the viewing ray, no other part
//! of the sheet hides it, and no occluder comes within [`OCCLUSION_CLEARANCE`] pixels of it.

use super::corner::{check, jitter};
use super::{add_gaussian_noise, blur_cells, blur_then_integrate, SynthError};
use crate::GrayImage;
use nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::f64::consts::PI;

/// A corner closer than this to the image border (pixels) is not visible.
pub const VISIBILITY_MARGIN: f64 = 5.0;
/// A corner where the sheet normal makes a larger angle (degrees) with the ray to the camera is not
/// visible.
pub const MAX_VIEW_ANGLE_DEG: f64 = 75.0;
/// A corner closer than this (pixels) to the edge of an occluder bar is not visible.
pub const OCCLUSION_CLEARANCE: f64 = 3.0;

/// The shape the sheet is bent into; see the module docs for the exact curves. Lengths in mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Surface {
    /// A plane.
    Flat,
    /// Wrapped around a cylinder whose axis runs along the board's v (rows go along the axis,
    /// columns around it); `radius_mm > 0` bulges towards the camera, `< 0` is the inside of a
    /// cylinder. The sheet (squares and margin) may wrap at most half way round on each side.
    Cylinder {
        /// Signed radius (mm, non-zero).
        radius_mm: f64,
    },
    /// Wrapped around a column of elliptic cross-section, semi-axis `a_mm` across the view (board
    /// X) and `b_mm` in depth (board Z), bulging towards the camera; arc length along the ellipse is
    /// board u. At most half the perimeter on each side.
    EllipticColumn {
        /// Semi-axis along board X (mm, > 0).
        a_mm: f64,
        /// Semi-axis along board Z (mm, > 0).
        b_mm: f64,
    },
    /// Two arcs of opposite bending joined at `u = 0` like a wave: for `u ≥ 0` the cylinder arc of
    /// signed radius `radius_mm`, for `u < 0` the arc of radius `−radius_mm`.
    SShape {
        /// Signed radius of the `u ≥ 0` half (mm, non-zero).
        radius_mm: f64,
    },
}

/// A pinhole camera with two-term radial distortion; pixel centres at integers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PinholeCamera {
    /// Image width (pixels, 1..=16384).
    pub width: usize,
    /// Image height (pixels, 1..=16384).
    pub height: usize,
    /// Focal length along x (pixels, > 0).
    pub fx: f64,
    /// Focal length along y (pixels, > 0).
    pub fy: f64,
    /// Principal point x (pixels).
    pub cx: f64,
    /// Principal point y (pixels).
    pub cy: f64,
    /// Radial distortion coefficient of `r²` (normalized coordinates).
    pub k1: f64,
    /// Radial distortion coefficient of `r⁴`.
    pub k2: f64,
}

impl Default for PinholeCamera {
    /// The paper's 1920×1200 sensor behind a 1600 px lens, principal point at the centre, no
    /// distortion.
    fn default() -> Self {
        Self {
            width: 1920,
            height: 1200,
            fx: 1600.0,
            fy: 1600.0,
            cx: 959.5,
            cy: 599.5,
            k1: 0.0,
            k2: 0.0,
        }
    }
}

/// HydraMarker-style dots: a disc of the opposite colour at the centre of some squares.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dots {
    /// Disc radius as a fraction of the square side, in `(0, 0.5)`.
    pub radius: f64,
    /// Probability that a square carries a dot, in `[0, 1]`.
    pub fraction: f64,
    /// Seed of the pattern: squares draw `gen_bool(fraction)` in row-major order from
    /// `ChaCha8Rng::seed_from_u64(seed)`.
    pub seed: u64,
}

/// An opaque bar (a "pen") drawn over the image: all points within `width / 2` of the segment
/// `from`–`to` (image coordinates, pixels) take `intensity`. Later occluders cover earlier ones.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Occluder {
    /// One end of the axis (pixels).
    pub from: [f64; 2],
    /// The other end (pixels).
    pub to: [f64; 2],
    /// Thickness (pixels, > 0).
    pub width: f64,
    /// Grey level of the bar.
    pub intensity: f64,
}

impl Occluder {
    /// Distance (pixels) from image point `(x, y)` to the bar's axis segment.
    fn axis_distance(&self, x: f64, y: f64) -> f64 {
        let (dx, dy) = (self.to[0] - self.from[0], self.to[1] - self.from[1]);
        let (px, py) = (x - self.from[0], y - self.from[1]);
        let len2 = dx * dx + dy * dy;
        let t = if len2 > 0.0 {
            ((px * dx + py * dy) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (px - t * dx).hypot(py - t * dy)
    }
}

/// A checkerboard scene: sheet, surface, camera, pose, appearance and degradations.
///
/// [`Default`] is a flat 9×9-corner board (10×10 squares of 20 mm, 20 mm margin) facing the
/// default camera from 600 mm, sharp and noise-free.
#[derive(Clone, Debug, PartialEq)]
pub struct BoardScene {
    /// Inner corners per column (1..=1000); the board has `rows + 1` rows of squares.
    pub rows: usize,
    /// Inner corners per row (1..=1000); the board has `cols + 1` columns of squares.
    pub cols: usize,
    /// Side of a square (mm, > 0).
    pub square_mm: f64,
    /// Width of the white margin around the squares (mm, ≥ 0).
    pub margin_mm: f64,
    /// The shape the sheet is bent into.
    pub surface: Surface,
    /// The camera.
    pub camera: PinholeCamera,
    /// Board frame → camera frame (mm); see the module docs.
    pub pose: Isometry3<f64>,
    /// Optional dots in the squares.
    pub dots: Option<Dots>,
    /// Grey level of the dark squares.
    pub black: f64,
    /// Grey level of the light squares and of the margin.
    pub white: f64,
    /// Grey level where no sheet is seen (or its back).
    pub background: f64,
    /// Lighting gain slope `(g_x, g_y)`: relative gain change across the image width and height;
    /// `|g_x| + |g_y| < 2` keeps the gain positive.
    pub lighting_gradient: [f64; 2],
    /// Standard deviation of the Gaussian blur (pixels, ≥ 0).
    pub blur: f64,
    /// Standard deviation of the additive Gaussian noise (grey levels, ≥ 0).
    pub noise: f64,
    /// Sub-samples per pixel side on pixels where the colour changes (1..=64).
    pub supersample: usize,
    /// Bars drawn over the image; they hide the corners they come near.
    pub occluders: Vec<Occluder>,
    /// Printing dot gain (mm, |gain| < square/4): every dark square is printed this much larger on
    /// each side (smaller if negative), so the two polarities of a grid line are offset by twice
    /// the gain and squares of one colour overlap (or part) at the corners. The corners' truth stays
    /// the centre of the junction, its point of symmetry.
    pub dot_gain_mm: f64,
}

impl Default for BoardScene {
    fn default() -> Self {
        Self {
            rows: 9,
            cols: 9,
            square_mm: 20.0,
            margin_mm: 20.0,
            surface: Surface::Flat,
            camera: PinholeCamera::default(),
            pose: Isometry3::translation(0.0, 0.0, 600.0),
            dots: None,
            black: 0.1,
            white: 0.9,
            background: 0.5,
            lighting_gradient: [0.0, 0.0],
            blur: 0.0,
            noise: 0.0,
            supersample: 16,
            occluders: Vec::new(),
            dot_gain_mm: 0.0,
        }
    }
}

/// The truth for one inner corner.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoardCorner {
    /// Corner row, `0..rows` from the top of the sheet.
    pub row: usize,
    /// Corner column, `0..cols` from the left of the sheet.
    pub col: usize,
    /// Image x (pixels); NaN when the corner is behind the camera.
    pub x: f64,
    /// Image y (pixels); NaN when the corner is behind the camera.
    pub y: f64,
    /// In the image (with [`VISIBILITY_MARGIN`]), facing the camera (within
    /// [`MAX_VIEW_ANGLE_DEG`]), not hidden by the sheet itself nor by an occluder.
    pub visible: bool,
    /// Signed curvature (px⁻¹) at the corner of the projected row line (`v` fixed, oriented by
    /// increasing column) and of the column line (`u` fixed, oriented by increasing row):
    /// `κ = (x′y″ − y′x″)/|x′|³`, positive when the line turns clockwise on screen (y is down).
    /// NaN when the corner is behind the camera.
    pub curvature: [f64; 2],
}

/// A rendered board and its truth.
#[derive(Clone, Debug)]
pub struct RenderedBoard {
    /// Lit, blurred and noisy image, not clamped.
    pub image: GrayImage,
    /// The same without noise.
    pub clean: GrayImage,
    /// All `rows × cols` inner corners, row-major.
    pub corners: Vec<BoardCorner>,
}

/// Intervals of the elliptic arc-length table on `[0, π]`.
const ELLIPSE_TABLE: usize = 1024;

/// The surface curve `C(u)` in the board's XZ plane.
#[derive(Clone, Debug)]
enum Shape {
    Flat,
    /// Circle arcs of radius `rho`, bending with sign `pos` for `u ≥ 0` and `neg` for `u < 0`.
    Arcs {
        rho: f64,
        pos: f64,
        neg: f64,
    },
    /// Ellipse arcs; `table[k]` is the arc length from `τ = 0` to `τ = kπ/N`.
    Ellipse {
        a: f64,
        b: f64,
        table: Vec<f64>,
    },
}

/// Speed `|C′(τ)|` of the ellipse `(a sin τ, b(1 − cos τ))`.
fn ellipse_speed(a: f64, b: f64, tau: f64) -> f64 {
    let (s, c) = tau.sin_cos();
    (a * c).hypot(b * s)
}

/// Arc lengths of the ellipse at `τ_k = kπ/N`, by 5-point Gauss–Legendre on each interval.
fn ellipse_table(a: f64, b: f64) -> Vec<f64> {
    const NODES: [(f64, f64); 5] = [
        (0.0, 0.568_888_888_888_888_9),
        (-0.538_469_310_105_683_1, 0.478_628_670_499_366_5),
        (0.538_469_310_105_683_1, 0.478_628_670_499_366_5),
        (-0.906_179_845_938_664, 0.236_926_885_056_189_1),
        (0.906_179_845_938_664, 0.236_926_885_056_189_1),
    ];
    let h = PI / ELLIPSE_TABLE as f64;
    let mut table = Vec::with_capacity(ELLIPSE_TABLE + 1);
    let mut s = 0.0;
    table.push(0.0);
    for k in 0..ELLIPSE_TABLE {
        let mid = (k as f64 + 0.5) * h;
        s += NODES
            .iter()
            .map(|&(x, w)| w * 0.5 * h * ellipse_speed(a, b, mid + 0.5 * h * x))
            .sum::<f64>();
        table.push(s);
    }
    table
}

impl Shape {
    /// Arc length of the ellipse from 0 to `tau ∈ [−π, π]`: cubic Hermite interpolation of the
    /// table with the exact speeds as slopes.
    fn ellipse_arc(a: f64, b: f64, table: &[f64], tau: f64) -> f64 {
        let h = PI / ELLIPSE_TABLE as f64;
        let t = tau.abs().min(PI);
        let k = ((t / h) as usize).min(ELLIPSE_TABLE - 1);
        let s = t / h - k as f64;
        let (s2, s3) = (s * s, s * s * s);
        let l0 = ellipse_speed(a, b, k as f64 * h);
        let l1 = ellipse_speed(a, b, (k + 1) as f64 * h);
        let arc = (2.0 * s3 - 3.0 * s2 + 1.0) * table[k]
            + (s3 - 2.0 * s2 + s) * h * l0
            + (3.0 * s2 - 2.0 * s3) * table[k + 1]
            + (s3 - s2) * h * l1;
        arc.copysign(tau)
    }

    /// The ellipse angle whose arc length is `u` (|u| at most half the perimeter).
    fn ellipse_angle(a: f64, b: f64, table: &[f64], u: f64) -> f64 {
        let target = u.abs();
        let h = PI / ELLIPSE_TABLE as f64;
        let k = table
            .partition_point(|&s| s <= target)
            .clamp(1, ELLIPSE_TABLE)
            - 1;
        let span = table[k + 1] - table[k];
        let mut tau = (k as f64 + ((target - table[k]) / span).clamp(0.0, 1.0)) * h;
        // The speed is the Hermite arc's slope to ~10⁻¹⁰, so Newton converges in two or three steps.
        for _ in 0..4 {
            let step = (Self::ellipse_arc(a, b, table, tau) - target) / ellipse_speed(a, b, tau);
            tau = (tau - step).clamp(0.0, PI);
            if step.abs() < 1e-15 {
                break;
            }
        }
        tau.copysign(u)
    }

    /// `C(u)` and the unit front normal `(Z′, −X′)`.
    fn curve(&self, u: f64) -> ([f64; 2], [f64; 2]) {
        match self {
            Shape::Flat => ([u, 0.0], [0.0, -1.0]),
            Shape::Arcs { rho, pos, neg } => {
                let sigma = if u >= 0.0 { *pos } else { *neg };
                let theta = u / rho;
                let (s, c) = theta.sin_cos();
                // 1 − cos θ = 2 sin²(θ/2) keeps Z exact for small θ.
                let vers = 2.0 * (0.5 * theta).sin().powi(2);
                ([rho * s, sigma * rho * vers], [sigma * s, -c])
            }
            Shape::Ellipse { a, b, table } => {
                let tau = Self::ellipse_angle(*a, *b, table, u);
                let (s, c) = tau.sin_cos();
                let vers = 2.0 * (0.5 * tau).sin().powi(2);
                let n = (b * s).hypot(a * c);
                ([a * s, b * vers], [b * s / n, -a * c / n])
            }
        }
    }

    /// Largest `|u|` the shape can carry without overlapping itself.
    fn max_half_length(&self) -> f64 {
        match self {
            Shape::Flat => f64::INFINITY,
            Shape::Arcs { rho, .. } => PI * rho,
            Shape::Ellipse { table, .. } => table[ELLIPSE_TABLE],
        }
    }
}

/// Roots `t` of `A t² + 2B t + C = 0`, ascending, NaN where missing.
fn quadratic_roots(a: f64, b: f64, c: f64) -> [f64; 2] {
    let disc = b * b - a * c;
    if disc.is_nan() || disc < 0.0 || a == 0.0 {
        return [f64::NAN; 2];
    }
    // q = −(B + sign(B)√disc) avoids cancellation; the roots are q/A and C/q.
    let q = -(b + disc.sqrt().copysign(b));
    let (r1, r2) = if q == 0.0 { (0.0, 0.0) } else { (q / a, c / q) };
    [r1.min(r2), r1.max(r2)]
}

/// A ray–sheet intersection: sheet point and the sign of `n·d` (negative: front face).
#[derive(Clone, Copy, Debug)]
struct Hit {
    t: f64,
    u: f64,
    v: f64,
    facing: f64,
}

/// Camera intrinsics, with the radius bounds that make undistortion well posed.
#[derive(Clone, Debug)]
struct Lens {
    cam: PinholeCamera,
    /// Undistorted radius whose distortion reaches the image's farthest point plus a pixel.
    ru_max: f64,
    /// Distorted radius of the image's farthest point plus a pixel.
    rd_max: f64,
    /// End of the range where the distortion is monotonic (may be infinite).
    ru_limit: f64,
}

impl Lens {
    fn distorted_radius(&self, r: f64) -> f64 {
        let q = r * r;
        r * (1.0 + self.cam.k1 * q + self.cam.k2 * q * q)
    }

    fn new(cam: PinholeCamera) -> Result<Self, SynthError> {
        let (k1, k2) = (cam.k1, cam.k2);
        // d/dr (r(1 + k₁r² + k₂r⁴)) = 1 + 3k₁q + 5k₂q², q = r²: its smallest positive root ends the
        // monotonic range.
        let q0 = if k2 == 0.0 {
            if k1 < 0.0 {
                -1.0 / (3.0 * k1)
            } else {
                f64::INFINITY
            }
        } else {
            let disc = 9.0 * k1 * k1 - 20.0 * k2;
            if disc < 0.0 {
                f64::INFINITY
            } else {
                let s = disc.sqrt();
                [(-3.0 * k1 - s) / (10.0 * k2), (-3.0 * k1 + s) / (10.0 * k2)]
                    .into_iter()
                    .filter(|&q| q > 0.0)
                    .fold(f64::INFINITY, f64::min)
            }
        };
        let ru_limit = q0.sqrt();
        let (w, h) = (cam.width as f64, cam.height as f64);
        let rd_max = [-1.5, w + 0.5]
            .iter()
            .flat_map(|&x| [-1.5, h + 0.5].map(|y| [x, y]))
            .map(|[x, y]| ((x - cam.cx) / cam.fx).hypot((y - cam.cy) / cam.fy))
            .fold(0.0, f64::max);
        let mut lens = Self {
            cam,
            ru_max: 0.0,
            rd_max,
            ru_limit,
        };
        let mut hi = if ru_limit.is_finite() {
            ru_limit
        } else {
            rd_max.max(1.0)
        };
        while ru_limit.is_infinite() && lens.distorted_radius(hi) < rd_max && hi < 1e6 {
            hi *= 2.0;
        }
        let reach = lens.distorted_radius(hi);
        if reach.is_nan() || reach < rd_max {
            return Err(SynthError::InvalidParameter {
                name: "k1",
                value: k1,
                reason: "the radial distortion (with k2) folds over inside the image",
            });
        }
        let mut lo = 0.0;
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if mid <= lo || mid >= hi {
                break;
            }
            if lens.distorted_radius(mid) < rd_max {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        lens.ru_max = hi;
        Ok(lens)
    }

    /// Image position of camera-frame point `p`, and its undistorted normalized radius.
    fn project(&self, p: [f64; 3]) -> Option<([f64; 2], f64)> {
        if p[2].is_nan() || p[2] <= 0.0 {
            return None;
        }
        let c = &self.cam;
        let (xn, yn) = (p[0] / p[2], p[1] / p[2]);
        let q = xn * xn + yn * yn;
        let d = 1.0 + c.k1 * q + c.k2 * q * q;
        Some(([c.fx * xn * d + c.cx, c.fy * yn * d + c.cy], q.sqrt()))
    }

    /// Normalized undistorted coordinates seen at image point `(x, y)`, or `None` beyond the
    /// image's distortion range.
    #[inline]
    fn unproject(&self, x: f64, y: f64) -> Option<[f64; 2]> {
        let c = &self.cam;
        let (xd, yd) = ((x - c.cx) / c.fx, (y - c.cy) / c.fy);
        if c.k1 == 0.0 && c.k2 == 0.0 {
            return Some([xd, yd]);
        }
        let rd = xd.hypot(yd);
        if rd == 0.0 {
            return Some([0.0, 0.0]);
        }
        if rd > self.rd_max {
            return None;
        }
        // Newton on g(r) = r(1 + k₁r² + k₂r⁴) − r_d, increasing on [0, ru_max]; a step leaving the
        // bracket is replaced by bisection.
        let (mut lo, mut hi) = (0.0, self.ru_max);
        let mut r = rd.min(hi);
        for _ in 0..60 {
            let q = r * r;
            let g = r * (1.0 + c.k1 * q + c.k2 * q * q) - rd;
            if g > 0.0 {
                hi = r;
            } else {
                lo = r;
            }
            let slope = 1.0 + 3.0 * c.k1 * q + 5.0 * c.k2 * q * q;
            let mut next = r - g / slope;
            if !(next > lo && next < hi) {
                next = 0.5 * (lo + hi);
            }
            let done = (next - r).abs() <= 1e-16 * r;
            r = next;
            if done {
                break;
            }
        }
        Some([xd * r / rd, yd * r / rd])
    }
}

/// Region label of a point: background, margin, or `2·cell + dot`.
const BACKGROUND: u32 = u32::MAX;
const MARGIN: u32 = u32::MAX - 1;

/// A validated scene with everything precomputed for ray casting and projection.
#[derive(Clone, Debug)]
pub struct BoardGeometry {
    rows: usize,
    cols: usize,
    square: f64,
    /// Half extent of the squares `(W/2, H/2)`.
    half: [f64; 2],
    /// Half extent of the sheet, squares plus margin.
    sheet_half: [f64; 2],
    shape: Shape,
    lens: Lens,
    /// Board → camera rotation (row-major) and translation.
    rot: [[f64; 3]; 3],
    trans: [f64; 3],
    /// Camera centre in the board frame, `−Rᵀ T`.
    origin: [f64; 3],
    /// Dot radius (mm) and, per square (row-major over `(rows + 1) × (cols + 1)`), whether it has one.
    dot_radius: f64,
    dot_cells: Vec<bool>,
    levels: [f32; 3],
    occluders: Vec<Occluder>,
    /// Dot gain (mm), see [`BoardScene::dot_gain_mm`].
    gain: f64,
}

fn mul3(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|r| m[r][0] * v[0] + m[r][1] * v[1] + m[r][2] * v[2])
}

fn mul3t(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|r| m[0][r] * v[0] + m[1][r] * v[1] + m[2][r] * v[2])
}

impl BoardGeometry {
    /// Sheet position `(u, v)` (mm) of inner corner `(row, col)`.
    pub fn corner_sheet(&self, row: usize, col: usize) -> [f64; 2] {
        [
            (col + 1) as f64 * self.square - self.half[0],
            (row + 1) as f64 * self.square - self.half[1],
        ]
    }

    /// Camera-frame position (mm) of sheet point `p = (u, v)` and the unit front normal there.
    pub fn sheet_to_camera(&self, p: [f64; 2]) -> ([f64; 3], [f64; 3]) {
        let ([x, z], [nx, nz]) = self.shape.curve(p[0]);
        let q = mul3(&self.rot, [x, p[1], z]);
        let n = mul3(&self.rot, [nx, 0.0, nz]);
        ([0, 1, 2].map(|r| q[r] + self.trans[r]), n)
    }

    /// Image position (pixels, with distortion) of sheet point `p = (u, v)`, or `None` if it is
    /// behind the camera. Whether it is actually seen is not checked.
    pub fn sheet_to_image(&self, p: [f64; 2]) -> Option<[f64; 2]> {
        self.lens.project(self.sheet_to_camera(p).0).map(|(x, _)| x)
    }

    /// Sheet point `(u, v)` (mm, margin included) seen at image point `x`, or `None` when the ray
    /// misses the sheet or first meets its back.
    pub fn image_to_sheet(&self, x: [f64; 2]) -> Option<[f64; 2]> {
        let [xn, yn] = self.lens.unproject(x[0], x[1])?;
        let hit = self.intersect(mul3t(&self.rot, [xn, yn, 1.0]))?;
        (hit.facing < 0.0).then_some([hit.u, hit.v])
    }

    /// Nearest intersection of the ray `origin + t d` (`t > 0`, board frame) with the sheet.
    fn intersect(&self, d: [f64; 3]) -> Option<Hit> {
        let o = self.origin;
        let [uh, vh] = self.sheet_half;
        let on_sheet = |t: f64, u: f64| {
            let v = o[1] + t * d[1];
            (t > 0.0 && u.abs() <= uh && v.abs() <= vh).then_some(v)
        };
        match &self.shape {
            Shape::Flat => {
                let t = -o[2] / d[2];
                let u = o[0] + t * d[0];
                let v = on_sheet(t, u)?;
                Some(Hit {
                    t,
                    u,
                    v,
                    facing: -d[2],
                })
            }
            Shape::Arcs { rho, pos, neg } => {
                let mut best: Option<Hit> = None;
                // One circle per distinct bending sign; each serves its half of the sheet.
                let halves: &[(f64, bool)] = if pos == neg {
                    &[(*pos, true)]
                } else {
                    &[(*pos, false), (*neg, false)]
                };
                for &(sigma, both) in halves {
                    let oz = o[2] - sigma * rho;
                    let roots = quadratic_roots(
                        d[0] * d[0] + d[2] * d[2],
                        o[0] * d[0] + oz * d[2],
                        o[0] * o[0] + oz * oz - rho * rho,
                    );
                    for t in roots {
                        let (x, z) = (o[0] + t * d[0], o[2] + t * d[2]);
                        let u = rho * x.atan2(rho - sigma * z);
                        let right_half = both || (u >= 0.0) == (sigma == *pos);
                        if !right_half || best.is_some_and(|b| b.t <= t) {
                            continue;
                        }
                        if let Some(v) = on_sheet(t, u) {
                            let facing = sigma * x * d[0] - (rho - sigma * z) * d[2];
                            best = Some(Hit { t, u, v, facing });
                        }
                    }
                }
                best
            }
            Shape::Ellipse { a, b, table } => {
                let (ia2, ib2) = (1.0 / (a * a), 1.0 / (b * b));
                let oz = o[2] - b;
                let roots = quadratic_roots(
                    d[0] * d[0] * ia2 + d[2] * d[2] * ib2,
                    o[0] * d[0] * ia2 + oz * d[2] * ib2,
                    o[0] * o[0] * ia2 + oz * oz * ib2 - 1.0,
                );
                roots.into_iter().find_map(|t| {
                    let (x, z) = (o[0] + t * d[0], o[2] + t * d[2]);
                    let tau = (x / a).atan2((b - z) / b);
                    let u = Shape::ellipse_arc(*a, *b, table, tau);
                    let v = on_sheet(t, u)?;
                    // Normal ∝ (b sin τ, −a cos τ).
                    let facing = b * (x / a) * d[0] - a * ((b - z) / b) * d[2];
                    Some(Hit { t, u, v, facing })
                })
            }
        }
    }

    /// Region label of sheet point `(u, v)`.
    fn sheet_label(&self, u: f64, v: f64) -> u32 {
        let (fu, fv) = (u + self.half[0], v + self.half[1]);
        if fu < 0.0 || fv < 0.0 || fu > 2.0 * self.half[0] || fv > 2.0 * self.half[1] {
            return MARGIN;
        }
        let i = ((fu / self.square) as usize).min(self.cols);
        let j = ((fv / self.square) as usize).min(self.rows);
        let (i, j) = self.gained_cell(i, j, fu, fv);
        let cell = j * (self.cols + 1) + i;
        let dot = !self.dot_cells.is_empty() && self.dot_cells[cell] && {
            let du = fu - (i as f64 + 0.5) * self.square;
            let dv = fv - (j as f64 + 0.5) * self.square;
            du * du + dv * dv < self.dot_radius * self.dot_radius
        };
        ((cell as u32) << 1) | dot as u32
    }

    /// The square whose ink covers sheet point `(fu, fv)` (mm from the top-left of the squares)
    /// of square `(i, j)` under dot gain: a point within `gain` of a side of a light square takes
    /// the dark neighbour across that side (all four are dark); with negative gain a point within
    /// `|gain|` of a side of a dark square takes the light neighbour. Sides on the board's outline
    /// have no neighbour and stay put.
    fn gained_cell(&self, i: usize, j: usize, fu: f64, fv: f64) -> (usize, usize) {
        let g = self.gain.abs();
        if g == 0.0 || ((i + j) % 2 == 0) == (self.gain > 0.0) {
            return (i, j);
        }
        let du = fu - i as f64 * self.square;
        let dv = fv - j as f64 * self.square;
        let sides = [
            (du, i > 0, (i.wrapping_sub(1), j)),
            (self.square - du, i < self.cols, (i + 1, j)),
            (dv, j > 0, (i, j.wrapping_sub(1))),
            (self.square - dv, j < self.rows, (i, j + 1)),
        ];
        sides
            .into_iter()
            .filter(|&(d, inside, _)| inside && d < g)
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map_or((i, j), |(_, _, n)| n)
    }

    /// Region label seen at image point `(x, y)`.
    #[inline]
    fn label(&self, x: f64, y: f64) -> u32 {
        let Some([xn, yn]) = self.lens.unproject(x, y) else {
            return BACKGROUND;
        };
        match self.intersect(mul3t(&self.rot, [xn, yn, 1.0])) {
            Some(hit) if hit.facing < 0.0 => self.sheet_label(hit.u, hit.v),
            _ => BACKGROUND,
        }
    }

    /// Grey level of a region: `[black, white, background]`.
    #[inline]
    fn level(&self, label: u32) -> f32 {
        let [black, white, background] = self.levels;
        match label {
            BACKGROUND => background,
            MARGIN => white,
            l => {
                let cell = (l >> 1) as usize;
                let (i, j) = (cell % (self.cols + 1), cell / (self.cols + 1));
                if ((i + j) % 2 == 0) != (l & 1 == 1) {
                    black
                } else {
                    white
                }
            }
        }
    }

    /// Grey level at image point `(x, y)`, occluders included.
    #[inline]
    fn sample(&self, x: f64, y: f64) -> f32 {
        match self
            .occluders
            .iter()
            .rev()
            .find(|o| o.axis_distance(x, y) <= 0.5 * o.width)
        {
            Some(o) => o.intensity as f32,
            None => self.level(self.label(x, y)),
        }
    }

    /// Signed curvature (px⁻¹) of the image of the sheet line through `p` along `dir` (unit, in
    /// the sheet): first and second derivatives by central differences with steps `h` and `h/2`
    /// (mm), combined by Richardson extrapolation (`(4D(h/2) − D(h))/3`, error `O(h⁴)`).
    fn line_curvature(&self, p: [f64; 2], dir: [f64; 2], h: f64) -> f64 {
        let at = |k: f64| self.sheet_to_image([p[0] + k * h * dir[0], p[1] + k * h * dir[1]]);
        let (Some(a), Some(b), Some(c), Some(d), Some(e)) =
            (at(-1.0), at(-0.5), at(0.0), at(0.5), at(1.0))
        else {
            return f64::NAN;
        };
        let d1 = [0, 1].map(|r| (4.0 * (d[r] - b[r]) / h - (e[r] - a[r]) / (2.0 * h)) / 3.0);
        let d2 = [0, 1].map(|r| {
            let fine = (d[r] - 2.0 * c[r] + b[r]) * 4.0 / (h * h);
            let coarse = (e[r] - 2.0 * c[r] + a[r]) / (h * h);
            (4.0 * fine - coarse) / 3.0
        });
        (d1[0] * d2[1] - d1[1] * d2[0]) / d1[0].hypot(d1[1]).powi(3)
    }

    /// The truth for inner corner `(row, col)`; see [`BoardCorner`].
    pub fn corner(&self, row: usize, col: usize) -> BoardCorner {
        let sheet = self.corner_sheet(row, col);
        let (p, n) = self.sheet_to_camera(sheet);
        let missing = BoardCorner {
            row,
            col,
            x: f64::NAN,
            y: f64::NAN,
            visible: false,
            curvature: [f64::NAN; 2],
        };
        let Some(([x, y], ru)) = self.lens.project(p) else {
            return missing;
        };
        let cam = &self.lens.cam;
        let m = VISIBILITY_MARGIN;
        let in_image = ru < self.lens.ru_limit
            && (m..=cam.width as f64 - 1.0 - m).contains(&x)
            && (m..=cam.height as f64 - 1.0 - m).contains(&y);
        let dist = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        let cos_view = -(n[0] * p[0] + n[1] * p[1] + n[2] * p[2]) / dist;
        let facing = cos_view > MAX_VIEW_ANGLE_DEG.to_radians().cos();
        // The first sheet point on the ray to the corner must be the corner itself.
        let first = self.intersect(mul3t(&self.rot, [p[0] / p[2], p[1] / p[2], 1.0]));
        let tol = 1e-6 * self.square;
        let unhidden = first.is_some_and(|h| {
            h.facing < 0.0 && (h.u - sheet[0]).abs() < tol && (h.v - sheet[1]).abs() < tol
        });
        let clear = self
            .occluders
            .iter()
            .all(|o| o.axis_distance(x, y) > 0.5 * o.width + OCCLUSION_CLEARANCE);
        // Steps of about 2 px: rounding (~10⁻¹² px⁻¹) and truncation (~(2/R)⁴ relative, R the
        // radius of curvature in px) both stay negligible.
        let h = 2.0 * p[2] / cam.fx.max(cam.fy);
        BoardCorner {
            row,
            col,
            x,
            y,
            visible: in_image && facing && unhidden && clear,
            curvature: [
                self.line_curvature(sheet, [1.0, 0.0], h),
                self.line_curvature(sheet, [0.0, 1.0], h),
            ],
        }
    }

    /// The truth for every inner corner, row-major.
    pub fn corners(&self) -> Vec<BoardCorner> {
        (0..self.rows)
            .flat_map(|r| (0..self.cols).map(move |c| (r, c)))
            .map(|(r, c)| self.corner(r, c))
            .collect()
    }

    /// The area-sampled image of sheet and occluders, before lighting, blur and noise, on cells of
    /// `1/m` px (`m = 1`: the pixels), each with about `s/m` sub-samples per side where an edge
    /// may cross it.
    fn area_sample(&self, s: usize, m: usize) -> GrayImage {
        let (w, h) = (self.lens.cam.width * m, self.lens.cam.height * m);
        let (s, unit) = (s.div_ceil(m), 1.0 / m as f64);
        let at = |i: usize| (i as f64 + 0.5) * unit - 0.5;
        // Labels of the (w+1)×(h+1) cell corners, shared by neighbouring cells.
        let side = w + 1;
        let mut corners = vec![0u32; side * (h + 1)];
        corners
            .par_chunks_mut(side)
            .enumerate()
            .for_each(|(j, row)| {
                for (i, l) in row.iter_mut().enumerate() {
                    *l = self.label(i as f64 * unit - 0.5, j as f64 * unit - 0.5);
                }
            });
        let step = unit / s as f64;
        let inv = 1.0 / (s * s) as f32;
        let mut data = vec![0.0f32; w * h];
        data.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            let yf = at(y);
            for (x, out) in row.iter_mut().enumerate() {
                let xf = at(x);
                // A bar edge within 0.75 cell (> half the cell's diagonal) may cross the cell.
                let mut mixed = false;
                let mut cover = None;
                for o in &self.occluders {
                    let d = o.axis_distance(xf, yf) - 0.5 * o.width;
                    if d.abs() <= 0.75 * unit {
                        mixed = true;
                    } else if d < 0.0 {
                        cover = Some(o.intensity as f32);
                    }
                }
                if let (false, Some(c)) = (mixed, cover) {
                    *out = c;
                    continue;
                }
                let centre = self.label(xf, yf);
                let k = y * side + x;
                let uniform = !mixed
                    && corners[k] == centre
                    && corners[k + 1] == centre
                    && corners[k + side] == centre
                    && corners[k + side + 1] == centre;
                *out = if uniform {
                    self.level(centre)
                } else {
                    let key = ((y * w + x) * s * s) as u64;
                    let mut sum = 0.0f32;
                    for b in 0..s {
                        for a in 0..s {
                            let (jx, jy) = jitter(key + (b * s + a) as u64);
                            let sx = xf - 0.5 * unit + (a as f64 + jx) * step;
                            let sy = yf - 0.5 * unit + (b as f64 + jy) * step;
                            sum += self.sample(sx, sy);
                        }
                    }
                    sum * inv
                };
            }
        });
        GrayImage::from_vec(w, h, data).expect("size validated")
    }
}

impl BoardScene {
    /// Checks every parameter against its documented range (the surface and distortion included).
    pub fn validate(&self) -> Result<(), SynthError> {
        self.geometry().map(|_| ())
    }

    fn check_params(&self) -> Result<(), SynthError> {
        let count = |n: usize| (1..=1000).contains(&n);
        check("rows", self.rows as f64, count(self.rows), "1..=1000")?;
        check("cols", self.cols as f64, count(self.cols), "1..=1000")?;
        check("square_mm", self.square_mm, self.square_mm > 0.0, "> 0")?;
        check("margin_mm", self.margin_mm, self.margin_mm >= 0.0, ">= 0")?;
        let c = &self.camera;
        let side = |n: usize| (1..=16_384).contains(&n);
        check("width", c.width as f64, side(c.width), "1..=16384")?;
        check("height", c.height as f64, side(c.height), "1..=16384")?;
        check("fx", c.fx, c.fx > 0.0, "> 0")?;
        check("fy", c.fy, c.fy > 0.0, "> 0")?;
        for (name, v) in [("cx", c.cx), ("cy", c.cy), ("k1", c.k1), ("k2", c.k2)] {
            check(name, v, true, "finite")?;
        }
        let t = &self.pose.translation.vector;
        let q = self.pose.rotation.coords;
        for v in t.iter().chain(q.iter()) {
            check("pose", *v, true, "finite")?;
        }
        match self.surface {
            Surface::Flat => {}
            Surface::Cylinder { radius_mm: r } | Surface::SShape { radius_mm: r } => {
                check("radius_mm", r, r != 0.0, "non-zero")?;
            }
            Surface::EllipticColumn { a_mm, b_mm } => {
                check("a_mm", a_mm, a_mm > 0.0, "> 0")?;
                check("b_mm", b_mm, b_mm > 0.0, "> 0")?;
            }
        }
        if let Some(d) = &self.dots {
            check(
                "dots.radius",
                d.radius,
                d.radius > 0.0 && d.radius < 0.5,
                "in (0, 0.5)",
            )?;
            let f = d.fraction;
            check("dots.fraction", f, (0.0..=1.0).contains(&f), "in [0, 1]")?;
        }
        for (name, v) in [
            ("black", self.black),
            ("white", self.white),
            ("background", self.background),
        ] {
            check(name, v, true, "finite")?;
        }
        let [gx, gy] = self.lighting_gradient;
        check(
            "lighting_gradient",
            gx,
            gx.abs() + gy.abs() < 2.0,
            "|gx| + |gy| < 2",
        )?;
        check(
            "lighting_gradient",
            gy,
            gx.abs() + gy.abs() < 2.0,
            "|gx| + |gy| < 2",
        )?;
        check("blur", self.blur, self.blur >= 0.0, ">= 0")?;
        check("noise", self.noise, self.noise >= 0.0, ">= 0")?;
        let ss = self.supersample;
        check("supersample", ss as f64, (1..=64).contains(&ss), "1..=64")?;
        let g = self.dot_gain_mm;
        check(
            "dot_gain_mm",
            g,
            g.abs() < 0.25 * self.square_mm,
            "|gain| < square/4",
        )?;
        for o in &self.occluders {
            check("occluder.width", o.width, o.width > 0.0, "> 0")?;
            for v in [o.from[0], o.from[1], o.to[0], o.to[1], o.intensity] {
                check("occluder", v, true, "finite")?;
            }
        }
        Ok(())
    }

    /// The validated, precomputed geometry: projection, ray casting and per-corner truth.
    pub fn geometry(&self) -> Result<BoardGeometry, SynthError> {
        self.check_params()?;
        let shape = match self.surface {
            Surface::Flat => Shape::Flat,
            Surface::Cylinder { radius_mm: r } => Shape::Arcs {
                rho: r.abs(),
                pos: r.signum(),
                neg: r.signum(),
            },
            Surface::SShape { radius_mm: r } => Shape::Arcs {
                rho: r.abs(),
                pos: r.signum(),
                neg: -r.signum(),
            },
            Surface::EllipticColumn { a_mm, b_mm } => Shape::Ellipse {
                a: a_mm,
                b: b_mm,
                table: ellipse_table(a_mm, b_mm),
            },
        };
        let half = [
            0.5 * (self.cols + 1) as f64 * self.square_mm,
            0.5 * (self.rows + 1) as f64 * self.square_mm,
        ];
        let sheet_half = half.map(|h| h + self.margin_mm);
        let limit = shape.max_half_length();
        check(
            "square_mm",
            sheet_half[0],
            sheet_half[0] <= limit,
            "the sheet (squares and margin) wraps more than half way round the surface",
        )?;
        let lens = Lens::new(self.camera)?;
        let m = self.pose.rotation.to_rotation_matrix();
        let m = m.matrix();
        let rot = [0, 1, 2].map(|r| [0, 1, 2].map(|c| m[(r, c)]));
        let t = self.pose.translation.vector;
        let trans = [t.x, t.y, t.z];
        let origin = mul3t(&rot, trans).map(|v| -v);
        let cells = (self.rows + 1) * (self.cols + 1);
        let (dot_radius, dot_cells) = match &self.dots {
            Some(d) => {
                let mut rng = ChaCha8Rng::seed_from_u64(d.seed);
                let cells = (0..cells).map(|_| rng.gen_bool(d.fraction)).collect();
                (d.radius * self.square_mm, cells)
            }
            None => (0.0, Vec::new()),
        };
        Ok(BoardGeometry {
            rows: self.rows,
            cols: self.cols,
            square: self.square_mm,
            half,
            sheet_half,
            shape,
            lens,
            rot,
            trans,
            origin,
            dot_radius,
            dot_cells,
            levels: [self.black, self.white, self.background].map(|v| v as f32),
            occluders: self.occluders.clone(),
            gain: self.dot_gain_mm,
        })
    }

    /// The truth for every inner corner, row-major (see [`BoardCorner`]).
    pub fn corners(&self) -> Result<Vec<BoardCorner>, SynthError> {
        Ok(self.geometry()?.corners())
    }

    /// The area-sampled, lit image before blur and noise.
    pub fn render_sharp(&self) -> Result<GrayImage, SynthError> {
        let g = self.geometry()?;
        Ok(self.sharp(&g, 1))
    }

    /// [`BoardGeometry::area_sample`] on cells of `1/m` px, lit.
    fn sharp(&self, g: &BoardGeometry, m: usize) -> GrayImage {
        let mut img = g.area_sample(self.supersample, m);
        let [gx, gy] = self.lighting_gradient;
        if gx != 0.0 || gy != 0.0 {
            let (w, h) = (g.lens.cam.width as f64, g.lens.cam.height as f64);
            let (mx, my) = (0.5 * (w - 1.0), 0.5 * (h - 1.0));
            let unit = 1.0 / m as f64;
            let cells = img.width();
            for (y, row) in img.data_mut().chunks_mut(cells).enumerate() {
                let gain_y = gy * ((y as f64 + 0.5) * unit - 0.5 - my) / h;
                for (x, v) in row.iter_mut().enumerate() {
                    let gain_x = gx * ((x as f64 + 0.5) * unit - 0.5 - mx) / w;
                    *v *= (1.0 + gain_x + gain_y) as f32;
                }
            }
        }
        img
    }

    /// Renders the scene (area sampling, occluders and lighting on cells of `1/m` px, blur, each
    /// pixel the mean of its cells, then noise drawn from `ChaCha8Rng::seed_from_u64(seed)`; see
    /// `blur_then_integrate` for why the blur comes first) with the truth of every
    /// corner.
    pub fn render(&self, seed: u64) -> Result<RenderedBoard, SynthError> {
        let g = self.geometry()?;
        let m = blur_cells(self.blur);
        let clean = blur_then_integrate(&self.sharp(&g, m), m, self.blur);
        let mut image = clean.clone();
        add_gaussian_noise(&mut image, self.noise, &mut ChaCha8Rng::seed_from_u64(seed));
        Ok(RenderedBoard {
            image,
            clean,
            corners: g.corners(),
        })
    }
}

/// Width (mm) across the view of the squares once bent: the chord of the visible part.
fn bent_width(surface: Surface, half: f64) -> f64 {
    let arc_chord = |rho: f64| 2.0 * rho * (half / rho).min(0.5 * PI).sin();
    match surface {
        Surface::Flat => 2.0 * half,
        Surface::Cylinder { radius_mm } | Surface::SShape { radius_mm } => {
            arc_chord(radius_mm.abs())
        }
        Surface::EllipticColumn { a_mm, b_mm } => {
            let table = ellipse_table(a_mm, b_mm);
            let half = half.min(table[ELLIPSE_TABLE]);
            2.0 * a_mm
                * Shape::ellipse_angle(a_mm, b_mm, &table, half)
                    .min(0.5 * PI)
                    .sin()
        }
    }
}

/// The scene of the detection speed benchmark (`cargo bench --bench detect`, `render-board`): a
/// flat 9×9-corner board at 1920×1200, blur 1 px, noise 1 %, in a fixed random pose (all 81
/// corners visible). Render it with seed [`SPEED_BENCHMARK_NOISE_SEED`].
pub fn speed_benchmark_scene() -> BoardScene {
    use rand::SeedableRng;
    let template = BoardScene {
        blur: 1.0,
        noise: 0.01,
        ..BoardScene::default()
    };
    random_board_scene(
        &mut rand_chacha::ChaCha8Rng::seed_from_u64(8),
        Surface::Flat,
        &template,
    )
}

/// Noise seed of [`speed_benchmark_scene`].
pub const SPEED_BENCHMARK_NOISE_SEED: u64 = 8;

/// A random view of a board bent into `surface`, other parameters from `template`: the board
/// covers `U(30 %, 80 %)` of the image width (its bent chord, seen fronto-parallel), is turned in
/// its plane by `U(−30°, 30°)`, tilted by `U(0°, 50°)` about a random axis in the image plane, and
/// its centre lands uniformly where that fronto-parallel extent stays inside the image. Up to 50
/// poses are drawn and the first with ≥ 90 % visible corners is returned (else the one with most).
/// An invalid template (or surface) is returned with the first pose drawn; rendering it then
/// reports the error.
pub fn random_board_scene<R: Rng + ?Sized>(
    rng: &mut R,
    surface: Surface,
    template: &BoardScene,
) -> BoardScene {
    let cam = template.camera;
    let (w, h) = (cam.width as f64, cam.height as f64);
    let half_w = 0.5 * (template.cols + 1) as f64 * template.square_mm;
    let aspect = (template.rows + 1) as f64 / (template.cols + 1) as f64;
    let chord = bent_width(surface, half_w);
    let lens = Lens::new(cam).ok();
    let mut best: Option<(usize, BoardScene)> = None;
    for _ in 0..50 {
        let cover = rng.gen_range(0.3..0.8);
        let spin = rng.gen_range(-30f64..30.0).to_radians();
        let tilt = rng.gen_range(0f64..50.0).to_radians();
        let axis_dir = rng.gen_range(0.0..PI);
        let width_px = cover * w;
        let height_px = width_px * aspect * 2.0 * half_w / chord;
        let room_x = 0.5 * (w - width_px).max(0.0);
        let room_y = 0.5 * (h - height_px).max(0.0);
        let px = cam.cx + rng.gen_range(-1.0..=1.0) * room_x;
        let py = cam.cy + rng.gen_range(-1.0..=1.0) * room_y;
        let depth = cam.fx * chord / width_px;
        let [xn, yn] = lens
            .as_ref()
            .and_then(|l| l.unproject(px, py))
            .unwrap_or([(px - cam.cx) / cam.fx, (py - cam.cy) / cam.fy]);
        let axis = Unit::new_normalize(Vector3::new(axis_dir.cos(), axis_dir.sin(), 0.0));
        let rotation = UnitQuaternion::from_axis_angle(&axis, tilt)
            * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), spin);
        let scene = BoardScene {
            surface,
            pose: Isometry3::from_parts(Translation3::new(xn * depth, yn * depth, depth), rotation),
            ..template.clone()
        };
        let Ok(corners) = scene.corners() else {
            return scene;
        };
        let seen = corners.iter().filter(|c| c.visible).count();
        if 10 * seen >= 9 * corners.len() {
            return scene;
        }
        if best.as_ref().map_or(true, |(n, _)| seen > *n) {
            best = Some((seen, scene));
        }
    }
    best.expect("at least one pose drawn").1
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small_camera() -> PinholeCamera {
        PinholeCamera {
            width: 640,
            height: 480,
            fx: 800.0,
            fy: 800.0,
            cx: 319.5,
            cy: 239.5,
            k1: 0.0,
            k2: 0.0,
        }
    }

    fn small_scene(surface: Surface, pose: Isometry3<f64>) -> BoardScene {
        BoardScene {
            rows: 5,
            cols: 7,
            square_mm: 10.0,
            margin_mm: 10.0,
            surface,
            camera: small_camera(),
            pose,
            ..BoardScene::default()
        }
    }

    fn tilted(axis: [f64; 3], deg: f64, t: [f64; 3]) -> Isometry3<f64> {
        let axis = Unit::new_normalize(Vector3::new(axis[0], axis[1], axis[2]));
        Isometry3::from_parts(
            Translation3::new(t[0], t[1], t[2]),
            UnitQuaternion::from_axis_angle(&axis, deg.to_radians()),
        )
    }

    /// Bilinear value of `img` at `(x, y)`.
    fn bilinear(img: &GrayImage, x: f64, y: f64) -> f64 {
        let (x0, y0) = (x.floor(), y.floor());
        let (tx, ty) = (x - x0, y - y0);
        let (i, j) = (x0 as usize, y0 as usize);
        let g = |a: usize, b: usize| img.get(a, b) as f64;
        (1.0 - ty) * ((1.0 - tx) * g(i, j) + tx * g(i + 1, j))
            + ty * ((1.0 - tx) * g(i, j + 1) + tx * g(i + 1, j + 1))
    }

    #[test]
    fn flat_fronto_parallel_board_is_an_exact_grid_with_the_right_colours() {
        let scene = BoardScene {
            lighting_gradient: [0.3, -0.2],
            ..small_scene(Surface::Flat, Isometry3::translation(3.0, -2.0, 400.0))
        };
        let g = scene.geometry().unwrap();
        for c in g.corners() {
            let u = (c.col + 1) as f64 * 10.0 - 40.0;
            let v = (c.row + 1) as f64 * 10.0 - 30.0;
            assert!((c.x - (319.5 + 2.0 * (u + 3.0))).abs() < 1e-9, "{c:?}");
            assert!((c.y - (239.5 + 2.0 * (v - 2.0))).abs() < 1e-9, "{c:?}");
            assert!(c.visible);
            assert!(c.curvature.iter().all(|k| k.abs() < 1e-9), "{c:?}");
        }
        // Square centres (20 px squares) are pure colours times the lighting gain.
        let img = scene.render_sharp().unwrap();
        let gain = |x: usize, y: usize| {
            1.0 + 0.3 * (x as f64 - 319.5) / 640.0 - 0.2 * (y as f64 - 239.5) / 480.0
        };
        let at = |p: [f64; 2]| {
            let q = g.sheet_to_image(p).unwrap();
            let (x, y) = (q[0].round() as usize, q[1].round() as usize);
            img.get(x, y) as f64 / gain(x, y)
        };
        for j in 0..6 {
            for i in 0..8 {
                let p = [
                    (i as f64 + 0.5) * 10.0 - 40.0,
                    (j as f64 + 0.5) * 10.0 - 30.0,
                ];
                let want = if (i + j) % 2 == 0 { 0.1 } else { 0.9 };
                assert!((at(p) - want).abs() < 1e-6, "square ({i}, {j})");
            }
        }
        // Margin is white, beyond it the background.
        assert!((at([-45.0, 0.0]) - 0.9).abs() < 1e-6);
        assert!((at([0.0, 35.0]) - 0.9).abs() < 1e-6);
        assert!((at([0.0, 55.0]) - 0.5).abs() < 1e-6);
        assert!((img.get(0, 0) as f64 / gain(0, 0) - 0.5).abs() < 1e-6);
    }

    #[test]
    fn dot_gain_grows_the_dark_squares_and_keeps_the_outline() {
        // 2 px per mm, 10 mm squares, gain ±1 mm: the sides of a dark square move by ±2 px.
        let colour = |gain: f64, p: [f64; 2]| {
            let scene = BoardScene {
                dot_gain_mm: gain,
                ..small_scene(Surface::Flat, Isometry3::translation(0.0, 0.0, 400.0))
            };
            let g = scene.geometry().unwrap();
            let img = scene.render_sharp().unwrap();
            let q = g.sheet_to_image(p).unwrap();
            img.get(q[0].round() as usize, q[1].round() as usize) as f64
        };
        // Square (1, 1) is dark (i + j even), its neighbour (2, 1) light; their common side is
        // at u = 20 − 40 = −20 mm, v from −20 to −10 mm.
        for (du, gain, want) in [
            (-0.5, 0.0, 0.1),
            (0.5, 0.0, 0.9),
            (0.5, 1.0, 0.1),
            (1.5, 1.0, 0.9),
            (-0.5, -1.0, 0.9),
            (-1.5, -1.0, 0.1),
        ] {
            let got = colour(gain, [-20.0 + du, -15.0]);
            assert!((got - want).abs() < 1e-6, "du {du} gain {gain}: {got}");
        }
        // The outline of the squares does not grow into the margin (square (0, 0) is dark).
        // (The pixel touches the outline: its area-sampled value is white to 1e-5.)
        assert!((colour(1.0, [-40.5, -25.0]) - 0.9).abs() < 1e-4);
        let bad = BoardScene {
            dot_gain_mm: 3.0,
            ..small_scene(Surface::Flat, Isometry3::translation(0.0, 0.0, 400.0))
        };
        assert!(bad.validate().is_err());
    }

    #[test]
    fn dots_take_the_opposite_colour_at_square_centres() {
        let scene = BoardScene {
            dots: Some(Dots {
                radius: 0.25,
                fraction: 0.5,
                seed: 9,
            }),
            ..small_scene(Surface::Flat, Isometry3::translation(0.0, 0.0, 400.0))
        };
        let g = scene.geometry().unwrap();
        let img = scene.render_sharp().unwrap();
        let at = |p: [f64; 2]| {
            let q = g.sheet_to_image(p).unwrap();
            img.get(q[0].round() as usize, q[1].round() as usize) as f64
        };
        let mut dots = 0;
        for j in 0..6 {
            for i in 0..8 {
                let centre = [
                    (i as f64 + 0.5) * 10.0 - 40.0,
                    (j as f64 + 0.5) * 10.0 - 30.0,
                ];
                let square = if (i + j) % 2 == 0 { 0.1 } else { 0.9 };
                // 0.4 of a side from the centre is outside a 0.25-side dot.
                assert!((at([centre[0] + 4.0, centre[1]]) - square).abs() < 1e-6);
                let has = g.dot_cells[j * 8 + i];
                let want = if has { 1.0 - square } else { square };
                assert!((at(centre) - want).abs() < 1e-6, "square ({i}, {j})");
                dots += has as usize;
            }
        }
        assert!(dots > 8 && dots < 40, "{dots}");
        // The pattern follows the seed.
        let other = BoardScene {
            dots: Some(Dots {
                seed: 10,
                ..scene.dots.unwrap()
            }),
            ..scene.clone()
        };
        assert_ne!(other.geometry().unwrap().dot_cells, g.dot_cells);
        assert_eq!(scene.geometry().unwrap().dot_cells, g.dot_cells);
    }

    /// For every visible corner, the blurred image is at mid-grey on the four edges leaving it, at
    /// 0.3 and 0.5 of a square from it: the rendered edges cross at the truth.
    fn check_edges_cross_at_truth(scene: &BoardScene) -> usize {
        let scene = BoardScene {
            blur: 1.2,
            ..scene.clone()
        };
        let r = scene.render(0).unwrap();
        let g = scene.geometry().unwrap();
        let (mid, contrast) = (0.5 * (scene.black + scene.white), scene.white - scene.black);
        let (w, h) = (scene.camera.width as f64, scene.camera.height as f64);
        let mut checked = 0;
        let mut worst = 0.0f64;
        for c in r.corners.iter().filter(|c| c.visible) {
            let p = g.corner_sheet(c.row, c.col);
            for dir in [[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]] {
                for f in [0.3, 0.5] {
                    let d = f * scene.square_mm;
                    let q = [p[0] + d * dir[0], p[1] + d * dir[1]];
                    let x = g.sheet_to_image(q).unwrap();
                    // Only edge points seen head-on enough to be 4σ from everything else.
                    let back = g.image_to_sheet(x);
                    let seen =
                        back.is_some_and(|b| (b[0] - q[0]).abs() + (b[1] - q[1]).abs() < 1e-6);
                    let dist = (x[0] - c.x).hypot(x[1] - c.y);
                    if !seen
                        || dist < 5.0
                        || x[0] < 8.0
                        || x[1] < 8.0
                        || x[0] > w - 9.0
                        || x[1] > h - 9.0
                    {
                        continue;
                    }
                    let v = bilinear(&r.clean, x[0], x[1]);
                    worst = worst.max((v - mid).abs() / contrast);
                    checked += 1;
                }
            }
        }
        assert!(worst < 0.012, "worst deviation {worst} of the contrast");
        checked
    }

    #[test]
    fn rendered_edges_cross_at_the_truth_on_flat_and_curved_boards() {
        let flat = small_scene(
            Surface::Flat,
            tilted([1.0, 0.3, 0.0], 35.0, [5.0, 8.0, 300.0]),
        );
        assert!(check_edges_cross_at_truth(&flat) > 100);
        let cyl = small_scene(
            Surface::Cylinder { radius_mm: 40.0 },
            tilted([0.2, 1.0, 0.1], 20.0, [0.0, -5.0, 280.0]),
        );
        assert!(check_edges_cross_at_truth(&cyl) > 100);
        let ell = small_scene(
            Surface::EllipticColumn {
                a_mm: 50.0,
                b_mm: 30.0,
            },
            tilted([1.0, 0.0, 0.3], -25.0, [-6.0, 0.0, 300.0]),
        );
        assert!(check_edges_cross_at_truth(&ell) > 100);
        let s = small_scene(
            Surface::SShape { radius_mm: 35.0 },
            tilted([0.0, 1.0, 0.0], 15.0, [0.0, 0.0, 300.0]),
        );
        assert!(check_edges_cross_at_truth(&s) > 100);
        let distorted = BoardScene {
            camera: PinholeCamera {
                k1: -0.25,
                k2: 0.08,
                ..small_camera()
            },
            ..small_scene(
                Surface::Cylinder { radius_mm: -60.0 },
                tilted([1.0, 1.0, 0.0], 20.0, [10.0, 0.0, 250.0]),
            )
        };
        assert!(check_edges_cross_at_truth(&distorted) > 100);
    }

    #[test]
    fn cylinder_columns_follow_the_analytic_projection_and_curvature() {
        // Fronto-parallel cylinder, axis vertical, 500 mm from the camera: u = Rθ maps to
        // x = c + f R sinθ / (D + R(1 − cosθ)), y = c + f v / (D + R(1 − cosθ)).
        let (r, d, f) = (100.0, 500.0, 800.0);
        let scene = BoardScene {
            cols: 9,
            square_mm: 15.0,
            ..small_scene(
                Surface::Cylinder { radius_mm: r },
                Isometry3::translation(0.0, 0.0, d),
            )
        };
        let corners = scene.corners().unwrap();
        for c in &corners {
            let u = (c.col + 1) as f64 * 15.0 - 75.0;
            let v = (c.row + 1) as f64 * 15.0 - 45.0;
            let th = u / r;
            let depth = d + r * (1.0 - th.cos());
            assert!(
                (c.x - (319.5 + f * r * th.sin() / depth)).abs() < 1e-9,
                "{c:?}"
            );
            assert!((c.y - (239.5 + f * v / depth)).abs() < 1e-9, "{c:?}");
            // Columns run along the axis: straight lines. Rows bend by −Y/(f R) at θ = 0.
            assert!(c.curvature[1].abs() < 1e-9, "{c:?}");
            if c.col == 4 {
                let want = -v / (f * r);
                assert!(
                    (c.curvature[0] - want).abs() < 1e-6 * want.abs().max(1e-4),
                    "{c:?} {want}"
                );
            }
            if v != 0.0 {
                assert!(c.curvature[0].abs() > 1e-4, "{c:?}");
            }
        }
        // Column spacing shrinks towards the limbs, symmetrically.
        let xs: Vec<f64> = corners.iter().filter(|c| c.row == 2).map(|c| c.x).collect();
        let gaps: Vec<f64> = xs.windows(2).map(|w| w[1] - w[0]).collect();
        for i in 0..3 {
            assert!(
                gaps[i] < gaps[i + 1] && gaps[7 - i] < gaps[6 - i],
                "{gaps:?}"
            );
        }
        for i in 0..4 {
            assert!((gaps[i] - gaps[7 - i]).abs() < 1e-9);
        }
        // A circular elliptic column is the same cylinder (numerical arc length).
        let ell = BoardScene {
            surface: Surface::EllipticColumn { a_mm: r, b_mm: r },
            ..scene.clone()
        };
        for (a, b) in ell.corners().unwrap().iter().zip(&corners) {
            assert!(
                (a.x - b.x).abs() < 1e-8 && (a.y - b.y).abs() < 1e-8,
                "{a:?} {b:?}"
            );
        }
        let (ia, ib) = (ell.render_sharp().unwrap(), scene.render_sharp().unwrap());
        let diff: f64 = ia
            .data()
            .iter()
            .zip(ib.data())
            .map(|(p, q)| (p - q).abs() as f64)
            .sum();
        assert!(diff / (ia.data().len() as f64) < 1e-4, "{diff}");
    }

    #[test]
    fn s_shape_bends_rows_both_ways() {
        let scene = small_scene(
            Surface::SShape { radius_mm: 50.0 },
            Isometry3::translation(0.0, 0.0, 400.0),
        );
        let corners = scene.corners().unwrap();
        // Top row (v = −20 mm, above the eye): convex half (u > 0) turns clockwise, concave
        // half (u < 0) anticlockwise, each about ∓Y/(fR) near the inflection.
        let top: Vec<&BoardCorner> = corners.iter().filter(|c| c.row == 0).collect();
        let k = 20.0 / (800.0 * 50.0);
        assert!((top[4].curvature[0] - k).abs() < 0.1 * k, "{:?}", top[4]);
        assert!((top[2].curvature[0] + k).abs() < 0.1 * k, "{:?}", top[2]);
        assert!(top.iter().all(|c| c.visible));
    }

    #[test]
    fn corners_out_of_view_on_the_limbs_or_under_a_pen_are_hidden() {
        // Board partly outside the image.
        let scene = small_scene(Surface::Flat, Isometry3::translation(-130.0, 95.0, 400.0));
        let corners = scene.corners().unwrap();
        for c in &corners {
            let inside = (5.0..=634.0).contains(&c.x) && (5.0..=474.0).contains(&c.y);
            assert_eq!(c.visible, inside, "{c:?}");
        }
        assert!(corners.iter().any(|c| c.visible) && corners.iter().any(|c| !c.visible));

        // A small cylinder: the view angle exceeds 75° towards the limbs.
        let (r, d) = (50.0, 300.0);
        let scene = BoardScene {
            cols: 15,
            ..small_scene(
                Surface::Cylinder { radius_mm: r },
                Isometry3::translation(0.0, 0.0, d),
            )
        };
        let corners = scene.corners().unwrap();
        let limit = 75f64.to_radians().cos();
        let mut hidden = 0;
        for c in &corners {
            let th = ((c.col + 1) as f64 * 10.0 - 80.0) / r;
            let v = (c.row + 1) as f64 * 10.0 - 30.0;
            let p = [r * th.sin(), v, d + r * (1.0 - th.cos())];
            let cos_view =
                ((d + r) * th.cos() - r) / (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            assert_eq!(c.visible, cos_view > limit, "{c:?} {cos_view}");
            hidden += !c.visible as usize;
        }
        assert_eq!(hidden, 4 * 5, "two columns on each side");

        // A pen across the board hides the corners within its half width + 3 px.
        let pen = Occluder {
            from: [100.0, 150.0],
            to: [500.0, 330.0],
            width: 12.0,
            intensity: 0.3,
        };
        let scene = BoardScene {
            occluders: vec![pen],
            ..small_scene(Surface::Flat, Isometry3::translation(0.0, 0.0, 400.0))
        };
        let corners = scene.corners().unwrap();
        let mut under = 0;
        for c in &corners {
            let dist = pen.axis_distance(c.x, c.y);
            assert_eq!(c.visible, dist > 9.0, "{c:?} {dist}");
            under += (dist <= 9.0) as usize;
        }
        assert!(under >= 4, "{under}");
        let img = scene.render_sharp().unwrap();
        assert!((img.get(300, 240) - 0.3).abs() < 1e-6);
        // Half-covered pixels on the bar's edge are mixtures.
        let edge = img.get(300, 246);
        assert!(edge > 0.1 && edge < 0.9 && edge != 0.3, "{edge}");
    }

    #[test]
    fn sheet_and_image_round_trip_through_distortion() {
        let scene = BoardScene {
            camera: PinholeCamera {
                k1: -0.3,
                k2: 0.1,
                ..small_camera()
            },
            ..small_scene(
                Surface::EllipticColumn {
                    a_mm: 60.0,
                    b_mm: 90.0,
                },
                tilted([0.3, 1.0, 0.2], 30.0, [20.0, -10.0, 260.0]),
            )
        };
        let g = scene.geometry().unwrap();
        let mut n = 0;
        for c in g.corners().iter().filter(|c| c.visible) {
            let back = g.image_to_sheet([c.x, c.y]).unwrap();
            let want = g.corner_sheet(c.row, c.col);
            assert!((back[0] - want[0]).abs() < 1e-7 && (back[1] - want[1]).abs() < 1e-7);
            n += 1;
        }
        assert!(n > 20, "{n}");
        // Distortion bends a flat board's lines: for the fronto-parallel row y_n = Y through the
        // principal point's column, x = f t d, y = f Y d with d = 1 + k₁q + k₂q², q = t² + Y², so at
        // t = 0: κ = y″/x′² = Y (2k₁ + 4k₂Y²) / (f d²). The column x_n = 0 is radial: straight.
        let (k1, k2, f, depth) = (-0.3, 0.1, 800.0, 150.0);
        let flat = BoardScene {
            camera: scene.camera,
            ..small_scene(Surface::Flat, Isometry3::translation(0.0, 0.0, depth))
        };
        for c in flat.corners().unwrap().iter().filter(|c| c.col == 3) {
            let y = ((c.row + 1) as f64 * 10.0 - 30.0) / depth;
            let d = 1.0 + k1 * y * y + k2 * y.powi(4);
            let want = y * (2.0 * k1 + 4.0 * k2 * y * y) / (f * d * d);
            assert!((c.curvature[0] - want).abs() < 1e-9, "{c:?} {want}");
            assert!(c.curvature[1].abs() < 1e-9, "{c:?}");
        }
    }

    #[test]
    fn renders_are_deterministic_per_seed() {
        let scene = BoardScene {
            blur: 1.0,
            noise: 0.03,
            dots: Some(Dots {
                radius: 0.2,
                fraction: 0.4,
                seed: 1,
            }),
            ..small_scene(
                Surface::Cylinder { radius_mm: 60.0 },
                tilted([1.0, 0.0, 0.0], 20.0, [0.0, 0.0, 300.0]),
            )
        };
        let a = scene.render(5).unwrap();
        let b = scene.render(5).unwrap();
        let c = scene.render(6).unwrap();
        assert_eq!(a.image, b.image);
        assert_eq!(a.corners, b.corners);
        assert_eq!(a.clean, c.clean);
        assert_ne!(a.image, c.image);
        let n = a.image.data().len() as f64;
        let rms = (a
            .image
            .data()
            .iter()
            .zip(c.clean.data())
            .map(|(p, q)| ((p - q) as f64).powi(2))
            .sum::<f64>()
            / n)
            .sqrt();
        assert!((rms - 0.03).abs() < 0.001, "{rms}");
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let s1 = random_board_scene(&mut rng, Surface::Flat, &scene);
        let s2 = random_board_scene(&mut ChaCha8Rng::seed_from_u64(3), Surface::Flat, &scene);
        assert_eq!(s1, s2);
    }

    #[test]
    fn random_scenes_show_most_of_the_board() {
        let template = BoardScene {
            rows: 9,
            cols: 9,
            ..small_scene(Surface::Flat, Isometry3::identity())
        };
        let surfaces = [
            Surface::Flat,
            Surface::Cylinder { radius_mm: 80.0 },
            Surface::EllipticColumn {
                a_mm: 70.0,
                b_mm: 120.0,
            },
            Surface::SShape { radius_mm: 90.0 },
        ];
        let mut rng = ChaCha8Rng::seed_from_u64(17);
        for surface in surfaces {
            for _ in 0..8 {
                let scene = random_board_scene(&mut rng, surface, &template);
                let corners = scene.corners().unwrap();
                let seen: Vec<&BoardCorner> = corners.iter().filter(|c| c.visible).collect();
                assert!(seen.len() >= 70, "{surface:?}: {} of 81", seen.len());
                let (lo, hi) = seen.iter().fold((f64::MAX, f64::MIN), |(lo, hi), c| {
                    (lo.min(c.x), hi.max(c.x))
                });
                let span = (hi - lo) / 640.0;
                assert!(span > 0.1 && span < 0.95, "{surface:?}: span {span}");
                let tilt = scene.pose.rotation.angle();
                assert!(tilt < 60f64.to_radians(), "{tilt}");
            }
        }
    }

    #[test]
    fn bad_parameters_are_rejected() {
        let ok = small_scene(Surface::Flat, Isometry3::translation(0.0, 0.0, 400.0));
        assert!(ok.validate().is_ok());
        let cam = |f: fn(&mut PinholeCamera)| {
            let mut c = small_camera();
            f(&mut c);
            BoardScene {
                camera: c,
                ..ok.clone()
            }
        };
        let bad = [
            BoardScene {
                rows: 0,
                ..ok.clone()
            },
            BoardScene {
                cols: 5000,
                ..ok.clone()
            },
            BoardScene {
                square_mm: 0.0,
                ..ok.clone()
            },
            BoardScene {
                margin_mm: -1.0,
                ..ok.clone()
            },
            BoardScene {
                surface: Surface::Cylinder { radius_mm: 0.0 },
                ..ok.clone()
            },
            // 50 mm of sheet each side on a 15 mm cylinder wraps more than half way.
            BoardScene {
                surface: Surface::Cylinder { radius_mm: 15.0 },
                ..ok.clone()
            },
            BoardScene {
                surface: Surface::SShape {
                    radius_mm: f64::NAN,
                },
                ..ok.clone()
            },
            BoardScene {
                surface: Surface::EllipticColumn {
                    a_mm: 50.0,
                    b_mm: -1.0,
                },
                ..ok.clone()
            },
            BoardScene {
                surface: Surface::EllipticColumn {
                    a_mm: 20.0,
                    b_mm: 10.0,
                },
                ..ok.clone()
            },
            cam(|c| c.width = 0),
            cam(|c| c.fx = 0.0),
            cam(|c| c.cy = f64::INFINITY),
            // r(1 − r²) peaks at r = 0.58: the corners of a 640×480 image at f = 400 lie beyond.
            cam(|c| {
                c.fx = 400.0;
                c.fy = 400.0;
                c.k1 = -1.0;
            }),
            BoardScene {
                pose: Isometry3::translation(f64::NAN, 0.0, 1.0),
                ..ok.clone()
            },
            BoardScene {
                dots: Some(Dots {
                    radius: 0.5,
                    fraction: 0.5,
                    seed: 0,
                }),
                ..ok.clone()
            },
            BoardScene {
                dots: Some(Dots {
                    radius: 0.2,
                    fraction: 1.5,
                    seed: 0,
                }),
                ..ok.clone()
            },
            BoardScene {
                black: f64::NAN,
                ..ok.clone()
            },
            BoardScene {
                lighting_gradient: [1.5, -0.6],
                ..ok.clone()
            },
            BoardScene {
                blur: -0.1,
                ..ok.clone()
            },
            BoardScene {
                noise: f64::INFINITY,
                ..ok.clone()
            },
            BoardScene {
                supersample: 0,
                ..ok.clone()
            },
            BoardScene {
                occluders: vec![Occluder {
                    from: [0.0, 0.0],
                    to: [1.0, 1.0],
                    width: 0.0,
                    intensity: 0.0,
                }],
                ..ok.clone()
            },
        ];
        for scene in bad {
            assert!(
                matches!(scene.render(0), Err(SynthError::InvalidParameter { .. })),
                "{scene:?}"
            );
            assert!(scene.corners().is_err());
        }
        // A board behind the camera renders background and reports NaN, invisible corners.
        let behind = BoardScene {
            pose: Isometry3::translation(0.0, 0.0, -400.0),
            ..ok.clone()
        };
        let r = behind.render(0).unwrap();
        assert!(r.image.data().iter().all(|&v| v == 0.5));
        assert!(r
            .corners
            .iter()
            .all(|c| !c.visible && c.x.is_nan() && c.curvature[0].is_nan()));
        // Seen edge-on: no crash, nothing visible.
        let edge_on = BoardScene {
            pose: tilted([0.0, 1.0, 0.0], 90.0, [0.0, 0.0, 400.0]),
            ..ok.clone()
        };
        assert!(edge_on.corners().unwrap().iter().all(|c| !c.visible));
        assert!(edge_on.render(0).is_ok());
    }

    /// Render time of a 1920×1200 board; run with `--ignored --nocapture` in an optimized profile.
    #[test]
    #[ignore]
    fn render_timing() {
        let template = BoardScene {
            blur: 1.0,
            noise: 0.02,
            dots: Some(Dots {
                radius: 0.15,
                fraction: 0.5,
                seed: 0,
            }),
            ..BoardScene::default()
        };
        let surfaces = [
            Surface::Flat,
            Surface::Cylinder { radius_mm: 150.0 },
            Surface::EllipticColumn {
                a_mm: 120.0,
                b_mm: 200.0,
            },
            Surface::SShape { radius_mm: 150.0 },
        ];
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        for surface in surfaces {
            for ss in [8, 16] {
                let scene = BoardScene {
                    supersample: ss,
                    ..random_board_scene(&mut rng, surface, &template)
                };
                let start = std::time::Instant::now();
                let n = 3;
                for seed in 0..n {
                    std::hint::black_box(scene.render(seed).unwrap());
                }
                let ms = start.elapsed().as_secs_f64() * 1e3 / n as f64;
                println!("{surface:?} supersample {ss}: {ms:.0} ms per 1920×1200 image");
            }
        }
    }
}
