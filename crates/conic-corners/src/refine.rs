//! Single-corner subpixel refinement by quadratic-form fitting (paper III-D to III-F applied to one
//! corner): a more accurate drop-in for OpenCV's `cornerSubPix`.
//!
//! From an approximate corner `p₀` (up to ~2 px off):
//!
//! 1. the two edge orientations come from a quadratic surface fit
//!    ([`election::edge_orientations`](crate::election::edge_orientations), eq. 3–4);
//! 2. each of the four edge rays is walked outward, taking one sigmoid edge sample per pixel
//!    scanline ([`edge_sampling::sample_edge`](crate::edge_sampling::sample_edge), eq. 6), each next
//!    sample predicted from the local chord of the previous ones so the walk follows a bending edge;
//!    the walk starts beyond the blurred zone of the junction, stops at the reach, at the image
//!    border, and where the edge changes polarity or contrast (the next corner of a board or an
//!    occluder);
//! 3. one curve per edge is fitted through the samples of both its opposite rays
//!    ([`quadratic_form::fit_edge_curve`](crate::quadratic_form::fit_edge_curve)), with outlier
//!    samples rejected by their distance to a first fit; the two rays have the dark square on
//!    opposite sides, so a print's dot gain offsets them across the edge, and a significant offset
//!    between them near the corner is removed (half from each) before the final fit;
//! 4. the corner is the intersection of the two curves nearest the current estimate (pencil of
//!    conics, eq. 11).
//!
//! A short pilot pass measures the blur (from the sigmoid widths) and a first corner, and a full
//! pass from that corner gives the result. Coordinates: pixel centres at integers, `(0, 0)` is the
//! centre of the top-left pixel.

use crate::edge_sampling::{
    blur_sigma_from_widths, crossing_offset, logistic_width, next_scanline_point,
    profile_half_width, sample_edge_predicted, sample_edge_with, Axis, EdgeSample, SigmoidParams,
};
use crate::election::edge_orientations;
use crate::quadratic_form::{
    corner_covariance, fit_edge_curve, fit_line_tls, intersect_lines, nearest_intersection,
    worst_sigma, Curve, CurveFit, EdgeModel, Line, PositionStats, SAMPLE_BIAS_SIGMA_PX,
};
use crate::segmentation::median_mad_in_place;
use crate::GrayImage;
use rayon::prelude::*;

/// Parameters of [`refine`]. `Default` gives the values used in the benchmarks.
#[derive(Clone, Debug, PartialEq)]
pub struct RefineParams {
    /// Farthest distance (px) from the corner that an edge walk goes. Longer walks average more
    /// samples (the main lever against noise); on a board the walk also stops at the next corner.
    pub reach: f64,
    /// Scanlines between consecutive edge samples (1 = every row or column).
    pub stride: usize,
    /// Gaussian blur σ (px) of the image if known; `None` estimates it from the edge profiles.
    pub blur: Option<f64>,
    /// Fewest samples an edge needs on each of its two rays for a [`Status::Converged`] result.
    pub min_samples: usize,
    /// Largest accepted distance (px) between the start point and the refined corner.
    pub max_shift: f64,
}

impl Default for RefineParams {
    fn default() -> Self {
        Self {
            reach: 100.0,
            stride: 1,
            blur: None,
            min_samples: 5,
            max_shift: 5.0,
        }
    }
}

impl RefineParams {
    /// Checks that every parameter is finite and in range; the message names the offending one.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.reach.is_finite() && self.reach >= 5.0 && self.reach <= 10_000.0) {
            return Err(format!("reach must be in 5..=10000 px, got {}", self.reach));
        }
        if self.stride == 0 || self.stride > 64 {
            return Err(format!("stride must be in 1..=64, got {}", self.stride));
        }
        if let Some(b) = self.blur {
            if !(b.is_finite() && (0.0..=20.0).contains(&b)) {
                return Err(format!("blur must be in 0..=20 px, got {b}"));
            }
        }
        if self.min_samples < 2 || self.min_samples > 1000 {
            return Err(format!(
                "min_samples must be in 2..=1000, got {}",
                self.min_samples
            ));
        }
        if !(self.max_shift.is_finite() && self.max_shift > 0.0) {
            return Err(format!(
                "max_shift must be a positive number, got {}",
                self.max_shift
            ));
        }
        Ok(())
    }
}

/// How a corner was refined.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    /// Both edges fitted from samples on both sides of the corner; the curves intersect.
    Converged,
    /// A result with less support: an edge seen on one side only (image border, occluder) or the
    /// curves replaced by straight lines.
    Fallback,
    /// No result; the returned position is the start point.
    Failed,
}

/// A refined corner.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Refined {
    /// Refined position (image coordinates, pixel centres at integers).
    pub x: f64,
    /// Refined position (image coordinates, pixel centres at integers).
    pub y: f64,
    /// How the position was obtained.
    pub status: Status,
    /// RMS distance (px) of the edge samples to their fitted curves; `None` when failed.
    pub residual: Option<f64>,
    /// Standard deviation (px) of the position in its worst direction, propagated from the
    /// residuals of the two curve fits (as in [`crate::board_fit`]), or where the curves did not
    /// meet and straight lines stood in, of the two line fits with their RMS residual as a model
    /// error; `None` when failed.
    pub sigma: Option<f64>,
    /// Covariance (px², image axes) of the position, from the same fits; `sigma` is the square
    /// root of its larger eigenvalue. `None` when `sigma` is.
    pub cov: Option<[[f64; 2]; 2]>,
    /// Edge samples used by the two curve fits.
    pub samples: usize,
}

/// Refines each approximate corner in `points` (`[x, y]`, image coordinates). Results are in input
/// order; points that are not finite, outside the image or not at a corner come back with
/// [`Status::Failed`] and their start position. Corners are processed in parallel.
pub fn refine(image: &GrayImage, points: &[[f64; 2]], params: &RefineParams) -> Vec<Refined> {
    points
        .par_iter()
        .map(|&p| refine_one(image, p, params))
        .collect()
}

/// Refines one corner; see [`refine`].
pub fn refine_one(image: &GrayImage, start: [f64; 2], params: &RefineParams) -> Refined {
    refine_with(image, start, &[], params, &PILOT_GUESSES)
}

/// [`refine_one`] for a corner of a board whose neighbouring corners are near `neighbours`
/// (image coordinates, pixel-level positions suffice). In the measuring pass (not the pilot,
/// whose windows follow a guessed blur) each ray's walk ends before its profile
/// windows reach the crossing edge of a neighbour ahead of it (one within 45° of the ray,
/// that edge taken parallel to the corner's own crossing edge). Without this a walk runs on
/// until its samples change polarity beyond the neighbour, and on a board turned by 45° in
/// its plane the windows of its last samples before that take in the neighbour's crossing
/// edge and pull them 0.3–0.5 px off the edge.
///
/// Where a neighbour has none opposite it (the board's boundary, a missed corner, an
/// occluder), the walk away from it ends likewise at its mirror image through the corner: a
/// board's pattern ends one square beyond its last inner corners. Only roughly (beside a
/// silhouette the outer squares are narrower than the inner ones), so that walk then drops its
/// last samples as one ended by misses does.
///
/// Unlike [`refine_one`], its pilot pass guesses the blur once (2 px, where `params.blur` is not
/// given): a board's corner that it cannot place goes to the junction model or the gradient
/// estimate ([`crate::detect`], [`crate::completion`]). Those place the corners of small or
/// foreshortened squares better than walks with smaller windows: with the smaller guesses in
/// `detect` and the completion, the robustness report's geometric mean RMS was 0.5 % higher,
/// and in the completion alone two more of its corners were more than 1.5 px off.
pub fn refine_one_among(
    image: &GrayImage,
    start: [f64; 2],
    neighbours: &[[f64; 2]],
    params: &RefineParams,
) -> Refined {
    refine_with(image, start, neighbours, params, &PILOT_GUESSES[..1])
}

/// The work of [`refine_one`] and [`refine_one_among`]: `blur_guesses` are the pilot pass's
/// guesses of the blur where `params.blur` is not given (see [`PILOT_GUESSES`]).
fn refine_with(
    image: &GrayImage,
    start: [f64; 2],
    neighbours: &[[f64; 2]],
    params: &RefineParams,
    blur_guesses: &[f64],
) -> Refined {
    let failed = Refined {
        x: start[0],
        y: start[1],
        status: Status::Failed,
        residual: None,
        sigma: None,
        cov: None,
        samples: 0,
    };
    if params.validate().is_err()
        || !start.iter().all(|v| v.is_finite())
        || start[0] < 0.0
        || start[1] < 0.0
        || start[0] > image.width() as f64 - 1.0
        || start[1] > image.height() as f64 - 1.0
    {
        return failed;
    }
    let mut walks = Walks::with_reach(params.reach, params.stride);
    let beyond = mirrored(start, neighbours);
    let ends = Ends {
        neighbours,
        beyond: &beyond,
    };
    // Pilot: short walks with a generous window measure the blur and a first corner. Each
    // direction estimate is tried in turn until one gives a pilot solution; where none does and
    // the blur is unknown, with smaller guesses of it (see [`PILOT_GUESSES`]).
    let known = params.blur.map(|b| [b]);
    let guesses: &[f64] = match &known {
        Some(b) => b,
        None => blur_guesses,
    };
    // Every second scanline is plenty for a first corner and the directions; the blur estimate
    // picks its own profiles.
    let pilot_with = |guess: f64| {
        WalkConfig::pilot(
            guess,
            params.reach.min(20.0 + 6.0 * guess),
            params.stride.max(2),
        )
    };
    // The first guess's first fallback (the start, with the walks' directions) and the
    // directions of its last walks, where no guess gives a solution.
    let (mut found, mut fallback, mut first_last) = (None, None, None);
    'guesses: for &guess in guesses {
        let pilot = pilot_with(guess);
        for directions in direction_candidates(image, start) {
            walks.walk_all(image, start, directions, &Ends::NONE, &pilot);
            match walks.solve(start, params, None) {
                Some(sol) if dist(sol.point, start) <= params.max_shift => {
                    found = Some((sol.point, sol.directions.unwrap_or(directions), guess));
                    break 'guesses;
                }
                _ if guess == guesses[0] => {
                    let d = walks.directions().unwrap_or(directions);
                    fallback = fallback.or(Some((start, d, guess)));
                    first_last = Some(directions);
                }
                _ => {}
            }
        }
    }
    if let (None, Some(directions), true) = (found, first_last, guesses.len() > 1) {
        // The blur estimate below reads the first guess's last walks, as without the others.
        walks.walk_all(
            image,
            start,
            directions,
            &Ends::NONE,
            &pilot_with(guesses[0]),
        );
    }
    let Some((centre, directions, guess)) = found.or(fallback) else {
        return failed;
    };
    // A first corner from a smaller guess than the first is less sure (small windows also fit
    // a sliver's edges beside a silhouette): the measuring pass must confirm it.
    let confirmed = |p: [f64; 2]| guess == guesses[0] || dist(p, centre) <= RETRY_AGREEMENT_PX;
    let pilot = pilot_with(guess);
    let sigma = params
        .blur
        .or_else(|| walks.blur_estimate(image, &pilot))
        .unwrap_or(guess)
        .clamp(0.5, 12.0);
    let full = WalkConfig::measure(sigma, params.reach, params.stride);
    walks.walk_all(image, centre, directions, &ends, &full);
    match walks.solve(centre, params, Some(sigma)) {
        Some(sol) if dist(sol.point, start) <= params.max_shift && confirmed(sol.point) => {
            Refined {
                x: sol.point[0],
                y: sol.point[1],
                status: sol.status,
                residual: Some(sol.residual),
                sigma: sol.cov.map(worst_sigma),
                cov: sol.cov,
                samples: sol.samples,
            }
        }
        _ => failed,
    }
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    // Pixel-scale values: no overflow for hypot's slower scaling to guard against.
    let (dx, dy) = (a[0] - b[0], a[1] - b[1]);
    (dx * dx + dy * dy).sqrt()
}

/// Candidate unit directions of the four rays, best first, each in angular order so that rays `k`
/// and `k + 2` belong to the same edge.
///
/// The quadratic surface fit (eq. 3–4) gives the two edge orientations, but a step corner is not a
/// product of two planes: on an oblique corner its angles are off by up to ~20°. So the rays are
/// first measured where the edges cross rings around `p`: a ring profile (averaged over a few
/// radii, smoothed along the ring) crosses its mid-level exactly four times on a corner, at the ray
/// directions. Rings that do not show four clean crossings (noise, clutter, the border) are
/// skipped; the surface-fit directions come last.
fn direction_candidates(
    image: &GrayImage,
    p: [f64; 2],
) -> impl Iterator<Item = [[f64; 2]; 4]> + '_ {
    let rings = [10.0, 16.0, 6.0]
        .into_iter()
        .filter_map(move |r| ring_directions(image, p, r));
    let surface = [4usize, 7, 11]
        .into_iter()
        .find_map(|h| edge_orientations(image, p[0], p[1], h))
        .map(|[t1, t2]| {
            let (e1, e2) = ([t1.cos(), t1.sin()], [t2.cos(), t2.sin()]);
            [e1, e2, [-e1[0], -e1[1]], [-e2[0], -e2[1]]]
        });
    rings.chain(surface)
}

/// Angular resolution of the ring profile.
const RING_STEPS: usize = 180;

/// The four mid-level crossings of the intensity on a ring of radius `r` around `p`; see
/// [`direction_candidates`].
fn ring_directions(image: &GrayImage, p: [f64; 2], r: f64) -> Option<[[f64; 2]; 4]> {
    let mut ring = [0f32; RING_STEPS];
    // The unit vector turns by a fixed rotation per step (no trigonometry per step; the rounding
    // drift over one turn is ~1e-14).
    let step = std::f64::consts::TAU / RING_STEPS as f64;
    let (rot_c, rot_s) = (step.cos(), step.sin());
    let (mut c, mut s) = (1.0f64, 0.0f64);
    for v in ring.iter_mut() {
        let mut acc = 0.0;
        for dr in [-1.5, -0.5, 0.5, 1.5] {
            let rr = r + dr;
            acc += bilinear(image, (p[0] + rr * c) as f32, (p[1] + rr * s) as f32)?;
        }
        *v = acc;
        (c, s) = (c * rot_c - s * rot_s, s * rot_c + c * rot_s);
    }
    // Circular [1 2 3 2 1] smoothing (±4°).
    let mut smooth = [0f32; RING_STEPS];
    for (i, v) in smooth.iter_mut().enumerate() {
        let at = |k: isize| ring[(i as isize + k).rem_euclid(RING_STEPS as isize) as usize];
        *v = at(-2) + 2.0 * at(-1) + 3.0 * at(0) + 2.0 * at(1) + at(2);
    }
    let (lo, hi) = smooth
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), &v| {
            (l.min(v), h.max(v))
        });
    if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let mid = 0.5 * (lo + hi);
    let mut out = [[0.0; 2]; 4];
    let mut n = 0;
    for i in 0..RING_STEPS {
        let (a, b) = (smooth[i] - mid, smooth[(i + 1) % RING_STEPS] - mid);
        if (a < 0.0) != (b < 0.0) {
            if n == 4 {
                return None;
            }
            let f = (a / (a - b)) as f64;
            let angle = (i as f64 + f) * std::f64::consts::TAU / RING_STEPS as f64;
            out[n] = [angle.cos(), angle.sin()];
            n += 1;
        }
    }
    (n == 4).then_some(out)
}

/// [`GrayImage::bilinear`] with the same arithmetic, minus the library call for `floor` that
/// baseline x86-64 makes: inside the image the coordinates are positive, where truncation is the
/// floor. A ring profile takes 720 samples.
#[inline]
fn bilinear(image: &GrayImage, x: f32, y: f32) -> Option<f32> {
    let (w, h) = (image.width(), image.height());
    if !(x >= 0.0 && y >= 0.0 && x < (w as f32 - 1.0) && y < (h as f32 - 1.0)) {
        // Outside, or on the last row or column: the general rules.
        return image.bilinear(x, y);
    }
    let (x0, y0) = (x as usize, y as usize);
    let (fx, fy) = (x - x0 as f32, y - y0 as f32);
    let (upper, lower) = (image.row(y0), image.row(y0 + 1));
    let (a, b) = (upper[x0], upper[x0 + 1]);
    let (c, d) = (lower[x0], lower[x0 + 1]);
    let top = a + (b - a) * fx;
    let bottom = c + (d - c) * fx;
    Some(top + (bottom - top) * fy)
}

/// How one pass walks its rays.
struct WalkConfig {
    sigma: f64,
    /// Distance from the corner (px) of the first sample.
    start: f64,
    reach: f64,
    stride: usize,
    /// Logistic width across the edge (px) when the blur is known: the sigmoid fits then keep it
    /// fixed, which halves their variance under heavy noise at no bias when it is right.
    normal_width: Option<f64>,
    sigmoid: SigmoidParams,
    /// Whether the sigmoid fits start at the predicted crossing once the walk predicts from a
    /// line ([`sample_edge_predicted`]); only when the fixed width is the measured one.
    predicted_start: bool,
}

impl WalkConfig {
    /// A pilot pass: sigmoid widths fixed at a middling blur guess for robust tracking (a fit with
    /// a wrong width still finds the edge to a few hundredths of a pixel); the blur itself is
    /// measured afterwards by free-width fits at the accepted samples.
    fn pilot(sigma: f64, reach: f64, stride: usize) -> Self {
        Self {
            sigma,
            start: 2.5 * sigma + 3.0,
            reach,
            stride,
            normal_width: Some(logistic_width(sigma)),
            sigmoid: SigmoidParams {
                min_contrast_to_noise: 2.5,
                ..SigmoidParams::default()
            },
            predicted_start: false,
        }
    }

    /// The measuring pass, with the blur known: fixed sigmoid width, and a lower contrast-to-noise
    /// floor since each sample must also fall near its predicted position.
    fn measure(sigma: f64, reach: f64, stride: usize) -> Self {
        Self {
            normal_width: Some(logistic_width(sigma)),
            sigmoid: SigmoidParams {
                min_contrast_to_noise: 2.0,
                ..SigmoidParams::default()
            },
            predicted_start: true,
            ..Self::pilot(sigma, reach, stride)
        }
    }

    /// Half-width (pixels) of the profile window for an edge of direction `d`: the transition spans
    /// about ±3σ across the edge, stretched by `1/|cos|` on a scanline oblique to the normal.
    fn half_width(&self, d: [f64; 2]) -> usize {
        profile_half_width(self.sigma, d)
    }
}

/// The samples of the four rays of one corner, reused between passes (no allocation per sample).
struct Walks {
    rays: [Vec<EdgeSample>; 4],
    /// Scratch buffer of points handed to the curve fit.
    points: Vec<[f64; 2]>,
    /// Scratch buffer of the points' distances to a first fit.
    distances: Vec<f64>,
}

struct Solution {
    point: [f64; 2],
    /// Covariance (px²) of `point` from the two curve fits (or the lines that stand in for
    /// them).
    cov: Option<[[f64; 2]; 2]>,
    status: Status,
    residual: f64,
    samples: usize,
    /// Ray directions measured from the samples, for the next pass.
    directions: Option<[[f64; 2]; 4]>,
}

impl Walks {
    /// Buffers sized for the longest walk, so that no sample allocates.
    fn with_reach(reach: f64, stride: usize) -> Self {
        // A walk takes at most one sample per scanline, and a ray of length `reach` crosses at
        // most `reach` scanlines.
        let per_ray = (reach / stride as f64).ceil() as usize + 2;
        Self {
            rays: std::array::from_fn(|_| Vec::with_capacity(per_ray)),
            points: Vec::with_capacity(2 * per_ray),
            distances: Vec::with_capacity(4 * per_ray),
        }
    }

    fn walk_all(
        &mut self,
        image: &GrayImage,
        corner: [f64; 2],
        dirs: [[f64; 2]; 4],
        ends: &Ends,
        cfg: &WalkConfig,
    ) {
        for (k, ray) in self.rays.iter_mut().enumerate() {
            // The other edge: the rays at k ± 1.
            let other = dirs[(k + 1) % 4];
            walk_ray(image, corner, dirs[k], other, ends, cfg, ray);
        }
        // A ray that found nothing (its start direction was off, typically beside a narrow
        // sector under strong perspective) is walked again along its edge's other ray, mirrored:
        // the edge is smooth through the corner.
        for k in 0..4 {
            let opposite = &self.rays[(k + 2) % 4];
            if self.rays[k].len() >= 3 || opposite.len() < 6 {
                continue;
            }
            let near = &opposite[..opposite.len().min(PREDICT_SAMPLES)];
            let away = dirs[(k + 2) % 4];
            if let Some((u, _, _)) = local_line(near, away) {
                let other = dirs[(k + 1) % 4];
                let mut ray = std::mem::take(&mut self.rays[k]);
                walk_ray(image, corner, [-u[0], -u[1]], other, ends, cfg, &mut ray);
                self.rays[k] = ray;
            }
        }
    }

    /// Blur σ from the median normal width of free-width sigmoid fits at the samples.
    fn blur_estimate(&self, image: &GrayImage, cfg: &WalkConfig) -> Option<f64> {
        let dirs = self.directions()?;
        let free = SigmoidParams::default();
        let widths: Vec<f64> = self
            .rays
            .iter()
            .zip(dirs)
            .flat_map(|(ray, d)| {
                // Ten widths per ray are plenty for a median; more only cost fits.
                let step = ray.len().div_ceil(10).max(1);
                ray.iter().step_by(step).filter_map(move |s| {
                    let hw = cfg.half_width(d) + 2;
                    sample_edge_with(image, s.point, d, hw, None, &free).map(|f| f.normal_width(d))
                })
            })
            .collect();
        if widths.len() < 8 {
            return None;
        }
        blur_sigma_from_widths(&widths)
    }

    /// Directions of the rays measured from their samples (chord from the first to the last).
    fn directions(&self) -> Option<[[f64; 2]; 4]> {
        let mut out = [[0.0; 2]; 4];
        for (k, ray) in self.rays.iter().enumerate() {
            let (a, b) = (ray.first()?.point, ray.last()?.point);
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let n = (dx * dx + dy * dy).sqrt();
            if n < 2.0 {
                return None;
            }
            out[k] = [dx / n, dy / n];
        }
        Some(out)
    }

    /// Fits one curve per edge (rays k and k+2) and intersects them near `near`.
    ///
    ///
    /// With the blur `sigma` known, samples on a curved edge are first corrected for the blur's
    /// curvature bias: a Gaussian blur moves a curved edge's mid-level crossing towards its centre
    /// of curvature by `κσ_t²/2` (σ_t² = σ² + 1/12 with the pixel footprint; 0.045 px for
    /// R = 100 px, σ = 3), so each sample moves back by that much along the fitted curve's normal
    /// and the curve is fitted again. Noise-free, this takes the corner error at κ = 3·10⁻³ from
    /// 0.019 px to 0.003 px.
    fn solve(
        &mut self,
        near: [f64; 2],
        params: &RefineParams,
        sigma: Option<f64>,
    ) -> Option<Solution> {
        let mut curves: [Option<Curve>; 2] = [None, None];
        let mut stats: [Option<PositionStats>; 2] = [None, None];
        let mut lines = [None, None];
        let mut status = Status::Converged;
        let mut sq = 0.0;
        let mut samples = 0;
        for e in 0..2 {
            let (a, b) = (&self.rays[e], &self.rays[e + 2]);
            let both = a.len() >= params.min_samples && b.len() >= params.min_samples;
            if !both {
                status = Status::Fallback;
            }
            if a.len() + b.len() < params.min_samples.max(3) {
                return None;
            }
            self.points.clear();
            self.points
                .extend(a.iter().chain(b.iter()).map(|s| s.point));
            let mut fit = robust_curve_fit(&mut self.points, &mut self.distances)?;
            // The two rays of an edge have the dark square on opposite sides, so a print's dot
            // gain offsets them across the edge by twice the gain; when the offset is
            // significant, both move back to the centre line of the junction and are refitted.
            // A curve through both rays partly absorbs the offset by tilting, so the offset is
            // measured again against each refit and the corrections add up.
            let mut offset = 0.0;
            for _ in 0..OFFSET_ROUNDS {
                let Some(more) = polarity_offset(&fit.curve, a, b, offset, &mut self.distances)
                else {
                    break;
                };
                offset += more;
                let curve = fit.curve;
                self.points.clear();
                self.points.extend(
                    a.iter()
                        .map(|s| move_across(&curve, s.point, -0.5 * offset))
                        .chain(b.iter().map(|s| move_across(&curve, s.point, 0.5 * offset))),
                );
                fit = robust_curve_fit(&mut self.points, &mut self.distances)?;
            }
            if let (Some(sigma), Curve::Conic(q)) = (sigma, &fit.curve) {
                let half_var = 0.5 * (sigma * sigma + 1.0 / 12.0);
                for p in self.points.iter_mut() {
                    let [gx, gy] = q.gradient(p[0], p[1]);
                    let (k, g) = (q.curvature(p[0], p[1]), (gx * gx + gy * gy).sqrt());
                    if k.is_finite() && g > 0.0 {
                        p[0] += k * half_var * gx / g;
                        p[1] += k * half_var * gy / g;
                    }
                }
                fit = fit_edge_curve(&self.points, None)?;
            }
            sq += fit.rms * fit.rms;
            samples += self.points.len();
            lines[e] = fit_line_tls(&self.points, None);
            stats[e] = PositionStats::new(self.points.iter(), &fit.curve, fit.model);
            curves[e] = Some(fit.curve);
        }
        let (c0, c1) = (curves[0].as_ref()?, curves[1].as_ref()?);
        let (point, cov) = match nearest_intersection(c0, c1, near) {
            Some(p) => {
                let cov = match &stats {
                    [Some(s0), Some(s1)] => corner_covariance(
                        c0,
                        s0.variance_at(p),
                        c1,
                        s1.variance_at(p),
                        p,
                        SAMPLE_BIAS_SIGMA_PX,
                    )
                    .map(|c| c.cov),
                    _ => None,
                };
                (p, cov)
            }
            None => {
                status = Status::Fallback;
                let (l0, l1) = (lines[0]?, lines[1]?);
                let p = intersect_lines(&l0, &l1)?;
                (p, self.line_covariance([l0, l1], p))
            }
        };
        Some(Solution {
            point,
            cov,
            status,
            residual: (sq / 2.0).sqrt(),
            samples,
            directions: self.directions(),
        })
    }

    /// Covariance (px²) of the intersection `p` of the straight lines that stand in where the
    /// two curves did not meet, from each line's position variance along its edge's samples.
    /// The lines miss the edges' bending, which the residuals show but their variance at `p`
    /// averages away: the larger of the two lines' RMS residuals enters as a systematic term.
    fn line_covariance(&mut self, lines: [Line; 2], p: [f64; 2]) -> Option<[[f64; 2]; 2]> {
        let mut spread = [(0.0, 0.0); 2];
        for (e, line) in lines.iter().enumerate() {
            self.points.clear();
            self.points.extend(
                self.rays[e]
                    .iter()
                    .chain(&self.rays[e + 2])
                    .map(|s| s.point),
            );
            let curve = Curve::Line(*line);
            let stats = PositionStats::new(self.points.iter(), &curve, EdgeModel::Line)?;
            let sq: f64 = self
                .points
                .iter()
                .map(|q| curve.distance(q[0], q[1]).powi(2))
                .sum();
            spread[e] = (stats.variance_at(p), (sq / self.points.len() as f64).sqrt());
        }
        let model = spread[0].1.max(spread[1].1);
        corner_covariance(
            &Curve::Line(lines[0]),
            spread[0].0,
            &Curve::Line(lines[1]),
            spread[1].0,
            p,
            SAMPLE_BIAS_SIGMA_PX.hypot(model),
        )
        .map(|c| c.cov)
    }
}

/// The offset (px, along the curve's normal) of ray `a`'s samples relative to ray `b`'s near the
/// corner, after `removed` px of it have been taken out (`a` moved by `−removed/2`, `b` by
/// `+removed/2`), when it is significant: the difference of the medians of the signed distances of
/// their first [`JUMP_SAMPLES`] samples to `curve` (fitted through both), significant when it
/// exceeds [`JUMP_SIGNIFICANCE`] standard errors (`1.4826 √(π/2) √((MAD_a² + MAD_b²)/n)`).
/// Medians keep a stray sample from faking an offset. `None` when either ray is shorter.
/// `scratch` is reused.
fn polarity_offset(
    curve: &Curve,
    a: &[EdgeSample],
    b: &[EdgeSample],
    removed: f64,
    scratch: &mut Vec<f64>,
) -> Option<f64> {
    if a.len() < JUMP_SAMPLES || b.len() < JUMP_SAMPLES {
        return None;
    }
    let mut median_mad = |ray: &[EdgeSample], shift: f64| {
        scratch.clear();
        scratch.extend(ray[..JUMP_SAMPLES].iter().map(|s| {
            let p = move_across(curve, s.point, shift);
            curve.distance(p[0], p[1])
        }));
        median_mad_in_place(scratch)
    };
    let (ma, da) = median_mad(a, -0.5 * removed);
    let (mb, db) = median_mad(b, 0.5 * removed);
    let offset = ma - mb;
    let se = 1.4826
        * std::f64::consts::FRAC_PI_2.sqrt()
        * ((da * da + db * db) / JUMP_SAMPLES as f64).sqrt();
    (offset.is_finite() && offset.abs() > JUMP_SIGNIFICANCE * se).then_some(offset)
}

/// `p` moved by `d` px along the unit normal of `curve` at `p` (the direction of positive
/// [`Curve::distance`]); `p` itself where the normal is undefined.
fn move_across(curve: &Curve, p: [f64; 2], d: f64) -> [f64; 2] {
    let n = match curve {
        Curve::Line(l) => l.normal(),
        Curve::Conic(q) => q.gradient(p[0], p[1]),
    };
    // Pixel-scale gradients: no overflow for hypot's slower scaling to guard against.
    let len = (n[0] * n[0] + n[1] * n[1]).sqrt();
    if len > 0.0 && len.is_finite() {
        [p[0] + d * n[0] / len, p[1] + d * n[1] / len]
    } else {
        p
    }
}

/// Fits an edge curve to `points`, drops samples farther than 3.5 robust standard deviations (and
/// at least 0.05 px) from it, and refits. Returns the curve and the RMS distance of the kept
/// samples (`points` keeps only them). `distances` is scratch space.
fn robust_curve_fit(points: &mut Vec<[f64; 2]>, distances: &mut Vec<f64>) -> Option<CurveFit> {
    let first = fit_edge_curve(points, None)?;
    // The distances twice: in point order for the cut, and a copy that the median reorders.
    let n = points.len();
    distances.clear();
    distances.extend(
        points
            .iter()
            .map(|p| first.curve.distance(p[0], p[1]).abs()),
    );
    distances.extend_from_within(..);
    let (in_order, copy) = distances.split_at_mut(n);
    let mad = *copy.select_nth_unstable_by(n / 2, f64::total_cmp).1;
    let limit = (3.5 * 1.4826 * mad).max(0.05);
    // `retain` visits the points once each, in order.
    let mut next = in_order.iter();
    points.retain(|_| next.next().is_some_and(|&d| d <= limit));
    if points.len() == n {
        return Some(first);
    }
    fit_edge_curve(points, None)
}

/// Walks one ray from `corner` along `dir`, appending accepted samples to `out` (cleared first).
///
/// Samples are taken on consecutive scanlines (rows for a steep edge, columns for a flat one),
/// `stride` apart. The next crossing is predicted from the chord over the last ~20 samples, so the
/// walk follows a bending edge. A scanline whose profile window would reach the other edge is
/// skipped. A scanline is a miss when its fit fails, lands far from the prediction, has the wrong
/// polarity, or a contrast outside 0.4–2.5× that of the first samples; the walk ends at the reach,
/// before a window reaches the crossing edge of a neighbour ahead (see [`refine_one_among`]), or
/// after [`MAX_MISSES`] misses in a row — the image border, the next corner of a board (where the
/// edge changes polarity), an occluder — and then drops the samples within the blurred zone of
/// where it ended.
fn walk_ray(
    image: &GrayImage,
    corner: [f64; 2],
    dir: [f64; 2],
    other: [f64; 2],
    ends: &Ends,
    cfg: &WalkConfig,
    out: &mut Vec<EdgeSample>,
) {
    out.clear();
    let mut d = dir;
    let mut anchor = [corner[0] + cfg.start * d[0], corner[1] + cfg.start * d[1]];
    let mut first_scan = true;
    let mut misses = 0;
    let mut polarity = 0.0f64;
    let mut contrast_ref = 0.0f64;
    let mut reached = false;
    let mut tolerance = 1.0 + 0.5 * cfg.sigma;
    // Whether the recent samples scatter little about their line (4 RMS under a pixel).
    let mut clean = false;
    let guard = 2.5 * cfg.sigma + 1.0;
    // A neighbour's crossing edge is taken parallel to `other`; a direction estimate gone wrong
    // (a pen stroke through the junction) can put `other` nearly along the ray, and the ray's
    // own edge would pass for that crossing edge.
    let crossing = (dir[0] * other[1] - dir[1] * other[0]).abs() >= MIN_CROSSING_SIN;
    loop {
        // Scanline geometry follows the current direction.
        let steep = d[1].abs() >= d[0].abs();
        let q = if first_scan {
            anchor
        } else {
            next_scanline_point(anchor, d, cfg.stride)
        };
        first_scan = false;
        anchor = q;
        let t = (q[0] - corner[0]) * dir[0] + (q[1] - corner[1]) * dir[1];
        if t > cfg.reach {
            reached = true;
            break;
        }
        if !q[0].is_finite() || !q[1].is_finite() {
            break;
        }
        // Where the other edge (a straight line through the corner) crosses this scanline.
        let hw = cfg.half_width(d);
        let clash = crossing_offset(q, steep, corner, other);
        if clash.is_some_and(|c| c.abs() <= hw as f64 + guard) {
            continue;
        }
        if crossing {
            let axis = if steep { Axis::X } else { Axis::Y };
            let ahead = |n: &&[f64; 2]| {
                let (dx, dy) = (n[0] - corner[0], n[1] - corner[1]);
                dx * dir[0] + dy * dir[1] > AHEAD_COS * dx.hypot(dy)
            };
            let touches = |n: &[f64; 2]| window_touches(q, axis, hw as f64, *n, other, guard);
            if ends.neighbours.iter().filter(ahead).any(touches) {
                reached = true;
                break;
            }
            if ends.beyond.iter().filter(ahead).any(touches) {
                break;
            }
        }
        let fixed = cfg.normal_width.map(|c| {
            let along = if steep { d[1] } else { d[0] };
            (c / along.abs().max(0.5)) as f32
        });
        let acceptable = |s: &EdgeSample| {
            // Signed contrast across the ray's left normal (−d.y, d.x), whatever the scan axis.
            let along_scan = if s.axis == Axis::X { -d[1] } else { d[0] };
            let a = s.fit.amplitude * along_scan.signum();
            let off = dist(s.point, q);
            let near = off
                <= if out.len() < 6 {
                    0.35 * hw as f64
                } else {
                    tolerance
                };
            let same = polarity == 0.0 || a.signum() == polarity;
            let similar =
                out.len() < 5 || (a.abs() >= 0.4 * contrast_ref && a.abs() <= 2.5 * contrast_ref);
            near && same && similar
        };
        // Once the walk predicts from a line through clean samples, the prediction is a better
        // start for the fit than the profile's own steepest crossing; where that fit fails or is
        // not acceptable, the profile's own start has the last word, so no sample is lost.
        // Under heavy noise a profile's least squares has several minima, and the prediction
        // could pick another one than the steepest crossing does: the walk then keeps to the
        // latter.
        let predicted = (cfg.predicted_start && clean && out.len() >= PREDICTED_START)
            .then(|| sample_edge_predicted(image, q, d, hw, fixed, &cfg.sigmoid))
            .flatten()
            .filter(|s| acceptable(s));
        let accepted = predicted.or_else(|| {
            sample_edge_with(image, q, d, hw, fixed, &cfg.sigmoid).filter(|s| acceptable(s))
        });
        let Some(s) = accepted else {
            misses += 1;
            if misses >= MAX_MISSES {
                break;
            }
            continue;
        };
        misses = 0;
        let along_scan = if s.axis == Axis::X { -d[1] } else { d[0] };
        let a = s.fit.amplitude * along_scan.signum();
        if polarity == 0.0 {
            polarity = a.signum();
        }
        if out.len() < 5 {
            contrast_ref = (contrast_ref * out.len() as f64 + a.abs()) / (out.len() + 1) as f64;
        }
        out.push(s);
        // Predict from a line through the recent samples rather than from the last one, so that
        // one noisy sample neither bends the walk nor shifts the next window.
        let recent = &out[out.len().saturating_sub(PREDICT_SAMPLES)..];
        anchor = s.point;
        if let Some((line_dir, on_line, spread)) = local_line(recent, d) {
            if recent.len() >= 6 {
                d = line_dir;
                anchor = on_line;
                // The line absorbs two degrees of freedom of the scatter.
                let n = recent.len() as f64;
                let scatter = 4.0 * spread * (n / (n - 2.0)).sqrt();
                tolerance = scatter.clamp(1.0, 1.0 + 0.5 * cfg.sigma);
                clean = scatter < 1.0;
            }
        }
    }
    if !reached {
        if let Some(end) = out.last().map(|s| s.point) {
            out.retain(|s| dist(s.point, end) > guard + 2.0);
        }
    }
}

/// Whether the profile window of half-width `hw` (px) about `q` along the scanline `axis`
/// straddles the straight line through `point` with unit direction `dir`, or comes within
/// `guard` (px, across that line) of it. Distances across the line, not along the scanline: a
/// window on a scanline nearly parallel to the line runs beside it for its whole length.
fn window_touches(
    q: [f64; 2],
    axis: Axis,
    hw: f64,
    point: [f64; 2],
    dir: [f64; 2],
    guard: f64,
) -> bool {
    let across = |p: [f64; 2]| (p[0] - point[0]) * dir[1] - (p[1] - point[1]) * dir[0];
    let (a, b) = match axis {
        Axis::X => (across([q[0] - hw, q[1]]), across([q[0] + hw, q[1]])),
        Axis::Y => (across([q[0], q[1] - hw]), across([q[0], q[1] + hw])),
    };
    a * b <= 0.0 || a.abs().min(b.abs()) <= guard
}

/// Samples behind the prediction of the next one.
const PREDICT_SAMPLES: usize = 24;

/// The pilot pass's guesses of the blur σ (px) when it is not given, tried in turn until one
/// gives a first corner. A guess of 2 px makes windows of ±9 px across the edge (±13 px along
/// the scanline at 45°), which on squares of about 20 px turned in their plane leave the walks
/// between the junction's blurred zone and the next corner one or two samples each.
const PILOT_GUESSES: [f64; 3] = [2.0, 1.0, 0.5];

/// Largest distance (px) between the first corner of a pilot pass with a smaller guess than the
/// first and the measuring pass's answer. Beside a silhouette of a 50 mm cylinder, a pilot with
/// 1 px windows found a corner on a sliver's edges that the measuring pass put 2 px away and
/// 2.7 px from the truth; on turned 20 px squares the two passes agree within 0.3 px.
const RETRY_AGREEMENT_PX: f64 = 1.0;

/// Where a board corner's walks end: before the crossing edges of its `neighbours`, and of the
/// points `beyond` the board's boundary (see [`refine_one_among`]).
struct Ends<'a> {
    neighbours: &'a [[f64; 2]],
    beyond: &'a [[f64; 2]],
}

impl Ends<'_> {
    /// For the pilot pass, whose windows follow a guessed blur: at a guess of 2 px they are
    /// ±13 px wide on a board turned by 45°, and with its walks ended before the neighbours'
    /// crossing edges a 30 px square left them one sample each. Ended by the polarity change
    /// beyond a neighbour instead, they keep enough for a first corner and the blur.
    const NONE: Ends<'static> = Ends {
        neighbours: &[],
        beyond: &[],
    };
}

/// The mirror images through `corner` of the `neighbours` that have none on the opposite side
/// of it (steps within about 45° of opposite: on a bent or foreshortened board the two steps
/// along one grid line are a few degrees from opposite, those along different lines at least
/// 45° away from it).
fn mirrored(corner: [f64; 2], neighbours: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let step = |p: &[f64; 2]| [p[0] - corner[0], p[1] - corner[1]];
    let opposed = |a: [f64; 2], b: [f64; 2]| {
        a[0] * b[0] + a[1] * b[1] < -AHEAD_COS * a[0].hypot(a[1]) * b[0].hypot(b[1])
    };
    neighbours
        .iter()
        .map(step)
        .filter(|&a| !neighbours.iter().any(|m| opposed(a, step(m))))
        .map(|a| [corner[0] - a[0], corner[1] - a[1]])
        .collect()
}

/// A neighbour lies ahead of a ray when the ray points within about 45° of it: the neighbour
/// along the ray's edge lies within a few degrees of it even on a bent board. One along the
/// corner's other edge may pass as ahead under strong foreshortening, but its crossing edge is
/// then the corner's own, whose scanlines are skipped before this test.
const AHEAD_COS: f64 = 0.7;

/// Smallest sine of the angle between a ray and the other edge for the walk to stop at its
/// neighbours' crossing edges (see [`walk_ray`]): 20°, below the 30° between a corner's edges
/// that the election's templates and the connectivity need, so that only a direction estimate
/// gone wrong is refused.
const MIN_CROSSING_SIN: f64 = 0.34;

/// Samples a walk has before its sigmoid fits start at the predicted crossing
/// ([`sample_edge_predicted`]): from then on the prediction follows a line through them.
const PREDICTED_START: usize = 6;

/// Samples of each ray, nearest the corner first, that measure the offset between an edge's two
/// rays ([`polarity_offset`]).
const JUMP_SAMPLES: usize = 12;

/// An offset between an edge's two rays is removed when it exceeds this many standard errors: on a
/// clean print it then stays untouched in all but a few corners in a thousand.
const JUMP_SIGNIFICANCE: f64 = 3.0;

/// Rounds of offset measurement and refit per edge, each on a significant offset: a curve through
/// both rays absorbs part of the offset by tilting, so one round leaves some of it.
const OFFSET_ROUNDS: usize = 4;

/// Least-squares line through the sample points: its unit direction (oriented like `d`), the
/// projection of the last sample onto it, and the RMS distance of the samples to it.
fn local_line(samples: &[EdgeSample], d: [f64; 2]) -> Option<([f64; 2], [f64; 2], f64)> {
    let n = samples.len() as f64;
    if samples.len() < 2 {
        return None;
    }
    let (mut mx, mut my) = (0.0, 0.0);
    for s in samples {
        mx += s.point[0];
        my += s.point[1];
    }
    let (mx, my) = (mx / n, my / n);
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for s in samples {
        let (dx, dy) = (s.point[0] - mx, s.point[1] - my);
        sxx += dx * dx;
        sxy += dx * dy;
        syy += dy * dy;
    }
    // Principal axis of the scatter matrix, at angle θ with tan 2θ = 2 sxy / (sxx − syy): from
    // (cos 2θ, sin 2θ) by the half-angle formulas, without trigonometric calls.
    let r = (4.0 * sxy * sxy + (sxx - syy) * (sxx - syy)).sqrt();
    let cos2 = if r > 0.0 { (sxx - syy) / r } else { 1.0 };
    let (cos, sin) = (
        (0.5 * (1.0 + cos2)).max(0.0).sqrt(),
        (0.5 * (1.0 - cos2)).max(0.0).sqrt(),
    );
    let mut u = [cos, if sxy < 0.0 { -sin } else { sin }];
    if u[0] * d[0] + u[1] * d[1] < 0.0 {
        u = [-u[0], -u[1]];
    }
    let last = samples.last()?.point;
    let t = (last[0] - mx) * u[0] + (last[1] - my) * u[1];
    let across = (sxx * u[1] * u[1] - 2.0 * sxy * u[0] * u[1] + syy * u[0] * u[0]).max(0.0);
    Some((u, [mx + t * u[0], my + t * u[1]], (across / n).sqrt()))
}

/// Consecutive missed scanlines that end a walk.
const MAX_MISSES: usize = 6;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_neighbour_with_none_opposite_is_mirrored_through_the_corner() {
        let c = [5.0, 5.0];
        // Left and right on one (bent) grid line, and one below with none above.
        let nb = [[15.0, 5.0], [-4.0, 8.0], [5.0, 15.0]];
        let m = mirrored(c, &nb);
        assert_eq!(m.len(), 1);
        assert!((m[0][0] - 5.0).abs() < 1e-12 && (m[0][1] + 5.0).abs() < 1e-12);
        // Complete sets have no mirrors; a lone corner has none either.
        assert!(mirrored(c, &[[15.0, 5.0], [-5.0, 5.0], [5.0, 15.0], [5.0, -5.0]]).is_empty());
        assert!(mirrored(c, &[]).is_empty());
    }

    #[test]
    fn a_window_touches_a_line_by_its_distance_across_it() {
        let (p, down) = ([0.0, 0.0], [0.0, 1.0]);
        // A row window: its ends are 7 and 13 px right of the vertical line.
        assert!(!window_touches([10.0, 5.0], Axis::X, 3.0, p, down, 2.0));
        assert!(window_touches([10.0, 5.0], Axis::X, 3.0, p, down, 7.0));
        // One that straddles it.
        assert!(window_touches([1.0, 5.0], Axis::X, 3.0, p, down, 0.5));
        // A column window parallel to the line, 1.5 px beside it over its whole length (where
        // the scanline never crosses the line).
        assert!(window_touches([1.5, 5.0], Axis::Y, 20.0, p, down, 2.0));
        assert!(!window_touches([3.0, 5.0], Axis::Y, 20.0, p, down, 2.0));
        // A 45° line: the row window at (10, 0) reaches x = 7, 7 / √2 ≈ 4.95 px across it.
        let diag = [
            std::f64::consts::FRAC_1_SQRT_2,
            std::f64::consts::FRAC_1_SQRT_2,
        ];
        assert!(!window_touches([10.0, 0.0], Axis::X, 3.0, p, diag, 4.9));
        assert!(window_touches([10.0, 0.0], Axis::X, 3.0, p, diag, 5.0));
    }

    #[test]
    fn ring_bilinear_matches_the_image() {
        let (w, h) = (13, 9);
        let data: Vec<f32> = (0..w * h).map(|i| ((i * 37) % 101) as f32 * 0.7).collect();
        let img = GrayImage::from_vec(w, h, data).unwrap();
        for k in 0..4000 {
            let (x, y) = (k as f32 * 0.0131 - 2.0, (k % 97) as f32 * 0.113 - 1.0);
            assert_eq!(bilinear(&img, x, y), img.bilinear(x, y), "{x} {y}");
        }
        for (x, y) in [
            (12.0, 3.0),
            (3.0, 8.0),
            (12.0, 8.0),
            (f32::NAN, 1.0),
            (13.5, 1.0),
        ] {
            assert_eq!(bilinear(&img, x, y), img.bilinear(x, y), "{x} {y}");
        }
    }
}
