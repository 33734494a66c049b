//! Final election (paper III-B): the two edge orientations of a candidate from a quadratic surface
//! fit (eq. 3–4), the matching template from a bank (each entry built on first use), and the NCC
//! score (eq. 5); plus [`find_corners`], the whole pixel-level detector (pre-filter then
//! election).
//!
//! Positions are image coordinates (x right, y down, pixel centres at integers).

use crate::prefilter::{prefilter_scales, Candidate, PrefilterParams, Scales};
use crate::GrayImage;
use nalgebra::DMatrix;
use rayon::prelude::*;
use std::collections::HashMap;
use std::f64::consts::PI;
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

/// Row-major 5×N matrix mapping a (2h+1)² window (row-major, offsets −h..h) to the least-squares
/// coefficients (α, β, γ, δ, ε) of `αx² + βxy + γy² + δx + εy + ζ`. The design matrix depends only on the
/// window, so the fit is a few dot products per call.
fn surface_projector(half: usize) -> &'static [Vec<f64>; 5] {
    // One lazily built entry per size: a process that only uses the default window builds one.
    static CACHE: [OnceLock<[Vec<f64>; 5]>; MAX_SURFACE_HALF + 1] =
        [const { OnceLock::new() }; MAX_SURFACE_HALF + 1];
    CACHE[half].get_or_init(|| {
        let h = half;
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
        [0, 1, 2, 3, 4].map(|k| proj.row(k).iter().copied().collect())
    })
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
    if r.is_nan() || r <= 0.0 || m.abs() >= r {
        return None;
    }
    let psi = b.atan2(a);
    let spread = (-m / r).acos();
    let wrap = |t: f64| t.rem_euclid(std::f64::consts::PI);
    let (t1, t2) = (wrap(0.5 * (psi - spread)), wrap(0.5 * (psi + spread)));
    Some(if t1 <= t2 { [t1, t2] } else { [t2, t1] })
}

/// Half-size of the templates: they are `(2·7+1)² = 15 × 15` pixels (paper: `w = h = 15`).
pub const TEMPLATE_HALF: usize = 7;
const TEMPLATE_SIDE: usize = 2 * TEMPLATE_HALF + 1;
const TEMPLATE_LEN: usize = TEMPLATE_SIDE * TEMPLATE_SIDE;
/// Steps of the template bank along each of its two angles (paper Fig. 3: 36 × 36 templates).
pub const TEMPLATE_STEPS: usize = 36;
/// Angular step of the bank, radians (5°): both angles span `[0, π)`.
const STEP: f64 = PI / TEMPLATE_STEPS as f64;
/// Width (pixels) of the soft step across each template edge, `tanh(d / EDGE_SOFTNESS)` with `d` the
/// signed distance to the edge line: a mild blur, as real corners are never sharp.
const EDGE_SOFTNESS: f64 = 1.0;
/// The contrast rule of [`elect`] takes the median amplitude of this many highest-amplitude
/// corners as the reference.
const CONTRAST_REFERENCE_COUNT: usize = 16;
/// Most hill-climbing moves through the bank from the template chosen by the surface fit. A move
/// is 5° on either angle; the fit can be ~25° off on oblique corners (see the tests).
const MAX_CLIMB: usize = 8;

/// Zero-mean, unit-norm 15 × 15 template of bank entry `(e, d)` (edge-angle bin `e`, direction
/// bin `d`, see [`template_angles`]), row-major: the product of two soft steps across its edges.
/// Entries are built on first use: a board only ever needs the few around its own corner angles,
/// and building all 1296 costs several milliseconds per process.
fn template(e: usize, d: usize) -> &'static [f32; TEMPLATE_LEN] {
    static BANK: [OnceLock<[f32; TEMPLATE_LEN]>; TEMPLATE_STEPS * TEMPLATE_STEPS] =
        [const { OnceLock::new() }; TEMPLATE_STEPS * TEMPLATE_STEPS];
    BANK[e * TEMPLATE_STEPS + d].get_or_init(|| {
        let [t1, t2] = template_angles(e, d);
        let ((s1, c1), (s2, c2)) = (t1.sin_cos(), t2.sin_cos());
        let mut t = [0f64; TEMPLATE_LEN];
        for (i, v) in t.iter_mut().enumerate() {
            let x = (i % TEMPLATE_SIDE) as f64 - TEMPLATE_HALF as f64;
            let y = (i / TEMPLATE_SIDE) as f64 - TEMPLATE_HALF as f64;
            let d1 = x * s1 - y * c1;
            let d2 = x * s2 - y * c2;
            *v = (d1 / EDGE_SOFTNESS).tanh() * (d2 / EDGE_SOFTNESS).tanh();
        }
        let mean = t.iter().sum::<f64>() / TEMPLATE_LEN as f64;
        let norm = t.iter().map(|v| (v - mean).powi(2)).sum::<f64>().sqrt();
        t.map(|v| ((v - mean) / norm) as f32)
    })
}

/// Edge orientations `[θ₁, θ₂]` (radians, `θ₁ < θ₂`, not wrapped) of bank entry `(e, d)`: the
/// edge angle `θ₂ − θ₁ = (e + ½)·5°` and the bisector direction `(θ₁ + θ₂)/2 = d·5°`. The bin
/// centres avoid the degenerate edge angles 0 and 180°.
pub fn template_angles(e: usize, d: usize) -> [f64; 2] {
    let spread = (e as f64 + 0.5) * STEP;
    let dir = d as f64 * STEP;
    [dir - 0.5 * spread, dir + 0.5 * spread]
}

/// The bank entry `(e, d)` nearest to edge orientations `angles` (radians in `[0, π)`, as
/// returned by [`edge_orientations`]).
pub fn template_index(angles: [f64; 2]) -> (usize, usize) {
    let (a, b) = (angles[0].min(angles[1]), angles[0].max(angles[1]));
    let spread = (b - a).clamp(0.0, PI);
    let e = ((spread / STEP).floor() as usize).min(TEMPLATE_STEPS - 1);
    let d = ((0.5 * (a + b) / STEP).round() as usize) % TEMPLATE_STEPS;
    (e, d)
}

/// Wraps orientations to `[0, π)` and sorts them.
fn wrap_pair([a, b]: [f64; 2]) -> [f64; 2] {
    let (a, b) = (a.rem_euclid(PI), b.rem_euclid(PI));
    if a <= b {
        [a, b]
    } else {
        [b, a]
    }
}

/// The 15 × 15 patch centred on pixel `(x, y)`, mean removed, and its norm; `None` if it leaves the
/// image or is flat.
fn centred_patch(image: &GrayImage, x: usize, y: usize) -> Option<([f32; TEMPLATE_LEN], f32)> {
    let h = TEMPLATE_HALF;
    if x < h || y < h || x + h >= image.width() || y + h >= image.height() {
        return None;
    }
    let mut p = [0f32; TEMPLATE_LEN];
    for (r, dst) in p.chunks_exact_mut(TEMPLATE_SIDE).enumerate() {
        dst.copy_from_slice(&image.row(y - h + r)[x - h..=x + h]);
    }
    let mean = p.iter().sum::<f32>() / TEMPLATE_LEN as f32;
    let mut norm2 = 0f32;
    for v in p.iter_mut() {
        *v -= mean;
        norm2 += *v * *v;
    }
    // Relative to the mean, so that a constant patch with rounding noise is still "flat".
    let norm = norm2.sqrt();
    (norm > 1e-4 * (1.0 + mean.abs()) * TEMPLATE_SIDE as f32).then_some((p, norm))
}

/// `Σ a[i]·b[i]` over a patch, in 8 interleaved partial sums: a sequential `f32` sum cannot be
/// vectorized (its rounding order is fixed), this one becomes a few vector multiply-adds.
#[inline(always)]
fn dot(a: &[f32; TEMPLATE_LEN], b: &[f32; TEMPLATE_LEN]) -> f32 {
    const L: usize = 8;
    let mut acc = [0f32; L];
    for (ca, cb) in a.chunks_exact(L).zip(b.chunks_exact(L)) {
        for i in 0..L {
            acc[i] += ca[i] * cb[i];
        }
    }
    let tail = TEMPLATE_LEN - TEMPLATE_LEN % L;
    let rest: f32 = (tail..TEMPLATE_LEN).map(|i| a[i] * b[i]).sum();
    acc.iter().sum::<f32>() + rest
}

/// `|NCC|` (eq. 5) of a centred patch with bank entry `(e, d)`; the sign only tells which pair of
/// opposite sectors is bright, and checkerboards have both kinds of corner.
fn ncc(patch: &[f32; TEMPLATE_LEN], norm: f32, e: usize, d: usize) -> f32 {
    let t = template(e, d);
    (dot(patch, t) / norm).abs()
}

/// Parameters of [`elect`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ElectionParams {
    /// Half-size of the window of the quadratic surface fit ([`edge_orientations`]): the paper's
    /// `n = 7` is `fit_half = 3`. Larger windows are steadier under noise but see neighbouring
    /// corners on small squares.
    pub fit_half: usize,
    /// `T_correlation` (paper: 0.25): a candidate is kept only if its score is within this of the
    /// best score in the image.
    pub t_correlation: f64,
    /// Absolute floor on the score, so that an image without any board yields nothing. An ideal
    /// L-shaped corner (one bright quadrant out of four, as at the outer corners of a board or of
    /// any dark rectangle) scores ≈ 0.58 against the X-shaped templates; X-junctions of a real
    /// board score 0.8–0.98.
    pub min_score: f64,
    /// Two elected corners closer than this (pixels) are the same corner: the better scoring one
    /// is kept.
    pub min_distance: f64,
    /// Smallest edge angle (radians) between the two edges of a corner; templates with an edge
    /// angle below it or above `π − min_edge_angle` are never used. Nearly parallel edges make the
    /// template a thin line, which matches pen strokes and pinstripes better than any corner; a
    /// board seen at up to ~60° obliquity keeps its corner angles above 30°.
    pub min_edge_angle: f64,
    /// Largest misfit of the 3 × 3 centre of the patch to the elected template, as a fraction of
    /// the corner's contrast (see the election rule in [`elect`]). Rejects thin lines and pen
    /// strokes, whose centre is at one extreme of the intensity where a corner is mid-grey.
    pub max_centre_residual: f64,
    /// Smallest normalized correlation of the patch with itself rotated by 180° about the
    /// candidate. An X-junction is point-symmetric (opposite sectors alike; ≥ 0.85 even with the
    /// corner half a pixel off the candidate pixel); a candidate beside a line or stroke, or on a
    /// T- or L-junction, is not.
    pub min_symmetry: f64,
    /// Smallest amplitude of a corner (the gain of its template fitted to the patch, i.e. its
    /// contrast) as a fraction of a typical board corner's, the median of the 16 highest among
    /// the corners that pass the score rule. Printing halftones and paper texture inside the
    /// squares, and thin pen lines crossing an edge, can match a template well at a small fraction
    /// of the board's contrast.
    pub min_contrast_rel: f64,
}

impl Default for ElectionParams {
    fn default() -> Self {
        Self {
            fit_half: 3,
            t_correlation: 0.25,
            min_score: 0.65,
            min_distance: 5.0,
            min_edge_angle: 30f64.to_radians(),
            max_centre_residual: 0.2,
            min_symmetry: 0.6,
            min_contrast_rel: 0.3,
        }
    }
}

/// Scores one candidate: the template picked by the surface fit, improved by hill-climbing
/// through neighbouring bank entries (the fit is biased towards 90° on oblique corners). Returns
/// the best `|NCC|`, the corner's amplitude (intensity units) and the template orientations.
fn score_candidate(
    image: &GrayImage,
    c: &Candidate,
    params: &ElectionParams,
) -> Option<(f32, f32, [f64; 2])> {
    let (x, y) = (c.x as f64, c.y as f64);
    let angles = edge_orientations(image, x, y, params.fit_half)?;
    let (patch, norm) = centred_patch(image, c.x, c.y)?;
    // Edge-angle bins whose centre (e + ½)·5° lies in [min_edge_angle, π − min_edge_angle].
    let min_angle = if params.min_edge_angle.is_finite() {
        params.min_edge_angle.clamp(0.0, 0.5 * PI)
    } else {
        0.0
    };
    let e_lo = ((min_angle / STEP - 0.5).ceil().max(0.0) as usize).min(TEMPLATE_STEPS / 2 - 1);
    let e_hi = TEMPLATE_STEPS - 1 - e_lo;
    let (e0, mut d) = template_index(angles);
    let mut e = e0.clamp(e_lo, e_hi);
    let mut best = ncc(&patch, norm, e, d);
    for _ in 0..MAX_CLIMB {
        let mut step = None;
        for de in -1isize..=1 {
            for dd in -1isize..=1 {
                let ne = e as isize + de;
                if (de, dd) == (0, 0) || ne < e_lo as isize || ne > e_hi as isize {
                    continue;
                }
                let nd = (d as isize + dd).rem_euclid(TEMPLATE_STEPS as isize) as usize;
                let s = ncc(&patch, norm, ne as usize, nd);
                if s > best {
                    best = s;
                    step = Some((ne as usize, nd));
                }
            }
        }
        match step {
            Some((ne, nd)) => (e, d) = (ne, nd),
            None => break,
        }
    }
    // NCC of the patch with itself rotated by 180° about the candidate (same pixels, same mean).
    let mut rotated = patch;
    rotated.reverse();
    let symmetry = dot(&patch, &rotated) / (norm * norm);
    let symmetric = symmetry as f64 >= params.min_symmetry;
    // The amplitude of the corner: the least-squares gain of the unit-norm template.
    let amplitude = best * norm;
    (symmetric && centre_is_consistent(&patch, e, d, params.max_centre_residual)).then_some((
        best,
        amplitude,
        wrap_pair(template_angles(e, d)),
    ))
}

/// Whether the 3 × 3 centre of a centred patch matches the template `(e, d)` scaled to the patch.
///
/// With `b = Σ patch·T` the least-squares gain of the zero-mean unit-norm template `T`, the residual
/// `|mean₃ₓ₃(patch) − b·mean₃ₓ₃(T)|` is compared with the corner's contrast `|b|·(max T − min T)`.
/// At an X-junction the centre is the balanced mix of the sectors and the residual is small; a thin
/// line or a stroke, which a narrow-wedge template also matches, has its darkest (or brightest)
/// pixels right at the centre, a residual near half the contrast.
fn centre_is_consistent(patch: &[f32; TEMPLATE_LEN], e: usize, d: usize, max_rel: f64) -> bool {
    let t = template(e, d);
    let b = dot(patch, t);
    let (lo, hi) = t
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), &v| {
            (l.min(v), h.max(v))
        });
    let h = TEMPLATE_HALF;
    let centre = |img: &[f32; TEMPLATE_LEN]| -> f32 {
        (h - 1..=h + 1)
            .flat_map(|r| (h - 1..=h + 1).map(move |c| r * TEMPLATE_SIDE + c))
            .map(|i| img[i])
            .sum::<f32>()
            / 9.0
    };
    let residual = (centre(patch) - b * centre(t)).abs() as f64;
    residual <= max_rel * (b.abs() * (hi - lo)) as f64
}

/// Final election (paper III-B) of pre-filter candidates.
///
/// For each candidate: edge orientations from the quadratic surface fit (eq. 3–4; candidates
/// whose surface is not a saddle are dropped), the nearest template of the 36 × 36 bank (edge
/// angle and bisector direction in 5° steps), then a hill-climb to the neighbouring template with
/// the highest `|NCC|` (eq. 5) against the 15 × 15 patch centred on the candidate; templates with
/// an edge angle under `min_edge_angle` are not used. The patch centre must agree with the template
/// (`max_centre_residual`: at an X-junction the centre is mid-grey; on a line or stroke, which a
/// narrow-wedge template matches too, it is the darkest or brightest part), and the patch must be
/// point-symmetric about the candidate (`min_symmetry`). A candidate is
/// elected when its score is at least `max(best − t_correlation, min_score)`, `best` being the
/// highest score in the image, and its amplitude (contrast) is at least `min_contrast_rel` times
/// that of a typical strong corner; elected corners closer than `min_distance` are merged (the
/// best one stays). Returns corners strongest first, at their integer pixel positions; `angles` are the
/// orientations of the winning template (multiples of 2.5°, wrapped to `[0, π)`).
/// Candidates within 7 px of the border (the template would leave the image) are dropped.
///
/// A coarse pass on the box-downsampled image adds the corners the fine tests reject on large
/// squares (its stride from the grid step of the fine corners, measured again on the coarse
/// corners and the pass redone if they give less than half that stride); when the two passes
/// elect fewer than nine corners together, or the fine pass too few to give a step (every
/// junction bridged by a print's dot gain), or no step and fewer corners than a quarter of the
/// candidates (motion blur along the squares' diagonals averages two quadrants of one colour
/// into every junction's centre, which the centre test takes for a stroke; where perspective
/// turns the corners across a board, it does so on one side of it only), passes at strides
/// 2, 4 and 8 are tried and the one electing the most corners is kept.
pub fn elect(image: &GrayImage, candidates: &[Candidate], params: &ElectionParams) -> Vec<Corner> {
    elect_scales(&Scales::new(image), candidates, params)
}

/// [`elect`] on `scales.image()`, a coarse pass at stride 2 on the average kept in `scales`.
pub fn elect_scales(
    scales: &Scales,
    candidates: &[Candidate],
    params: &ElectionParams,
) -> Vec<Corner> {
    let image = scales.image();
    let fine = elect_at_one_scale(image, candidates, params);
    // With few fine corners the grid step they give may be off by squares (every junction can
    // fail the fine tests at once: a print's dot gain joins the dark squares by a bridge a few
    // pixels wide, and the centre test rejects them all but a few, far apart). If the coarse pass
    // at that step finds too few corners too, or there is no step, the coarse scale that elects
    // the most corners is taken, the finest on a tie.
    let measured = coarse_stride(&fine).map(|stride| {
        let coarse = elect_coarse(scales, stride, stride, params);
        // The coarse corners, denser than the few fine ones, measure the step again: a stride
        // of 16 on 100 px squares, say, whose coarse pass saw 6 px squares and elected a patch
        // of the board, is redone at the stride they give.
        match coarse_stride(&coarse) {
            Some(again) if 2 * again < stride => {
                (again, elect_coarse(scales, again, again, params))
            }
            _ => (stride, coarse),
        }
    });
    // The pre-filter keeps about two candidates per board corner: a fine pass that elects under
    // a quarter of that, with no coarse stride to fill its gaps, failed on most junctions.
    let few = fine.len() < MIN_FINE_CORNERS
        || (measured.is_none() && fine.len() * FEW_FINE_OF_CANDIDATES < candidates.len());
    let (stride, mut all) = match measured {
        Some((stride, coarse)) if fine.len() + coarse.len() >= MIN_FINE_CORNERS => (stride, coarse),
        _ if few => FALLBACK_STRIDES
            .iter()
            .map(|&stride| {
                (
                    stride,
                    elect_coarse(scales, stride, FINEST_SADDLE_STRIDE, params),
                )
            })
            .fold((1, Vec::new()), |best, next| {
                if next.1.len() > best.1.len() {
                    next
                } else {
                    best
                }
            }),
        Some((stride, coarse)) => (stride, coarse),
        None => return fine,
    };
    // A corner found at both scales keeps its fine position (better than a coarse pixel); the
    // coarse pass only adds the corners the fine one rejected.
    let radius = stride as f64 * COARSE_MERGE_PIXELS;
    let grid = CornerGrid::new(&fine, radius);
    all.retain(|c| !grid.any_within(&fine, c.x, c.y, radius));
    all.extend(fine);
    all.sort_by(|a, b| b.score.total_cmp(&a.score).then(a.y.total_cmp(&b.y)));
    deduplicate(all, params.min_distance)
}

/// With fewer fine and coarse corners than a 3 × 3 patch of a board, the coarse passes of
/// [`FALLBACK_STRIDES`] are tried.
const MIN_FINE_CORNERS: usize = 9;
/// A fine pass electing fewer corners than the candidates over this, where the fine corners
/// give no coarse stride, is retried at the [`FALLBACK_STRIDES`] too. The pre-filter keeps about
/// two candidates per corner; a board blurred along the diagonal of part of its squares elected
/// a fifth of them (8 left it at that, missing 29 of 81 corners), and so did the photos' copies
/// blurred horizontally over 9 px at half size, which gave two boards of 21–36 corners each (or
/// one of 83) instead of one of 75–90. The photos and the robustness report's scenes elect more.
/// A third, not a quarter: the test's diagonally blurred board elects 31 of 122 candidates when
/// its pixels integrate the blurred pattern (as a camera's do), and `curve_8` at half size blurred
/// over 3 samples along the diagonal gives 99 corners instead of 88, labelled like the photo. The
/// coarse passes then run on 7 of the 157 copies of `photo_variants.py` (1–2 ms each) and on
/// none of the photos, the speed board or the curved-board benchmark's views.
const FEW_FINE_OF_CANDIDATES: usize = 3;
/// Strides of the coarse passes tried when the fine pass elects too few corners.
const FALLBACK_STRIDES: [usize; 3] = [2, 4, 8];

/// Election on the image box-downsampled by `stride`, each corner at its saddle point mapped
/// back to full-resolution coordinates; empty if the downsampled image is under 16 px.
///
/// Each corner then moves to the saddle point near it at half the stride, and so on down to the
/// stride `finest` (where a scale shows no saddle, to the centre of that scale's pixel). Where the
/// fine pass elected nothing, these are the only corners, and a coarse pixel (up to 8 px) is too
/// rough a start for the edge walks; where the fine pass worked, the coarse corners only fill
/// its gaps and keep their coarse saddle point (`finest = stride`).
fn elect_coarse(
    scales: &Scales,
    stride: usize,
    finest: usize,
    params: &ElectionParams,
) -> Vec<Corner> {
    let image = scales.image();
    let Some(coarse) = scales
        .downsampled(stride)
        .filter(|c| c.width().min(c.height()) >= 16)
    else {
        return Vec::new();
    };
    let coarse_candidates = prefilter_scales(&Scales::new(&coarse), &PrefilterParams::default());
    // Full-resolution coordinates of the saddle near the full-resolution point `(x, y)` at
    // stride `s` (whose pixel (u, v) covers the full-resolution centre s·(u, v) + (s−1)/2).
    let saddle_near = |s: usize, x: f64, y: f64| {
        let (sf, offset) = (s as f64, 0.5 * (s as f64 - 1.0));
        let (px, py) = (((x - offset) / sf).round(), ((y - offset) / sf).round());
        if !(px >= 0.0 && py >= 0.0) {
            return None;
        }
        let (u, v) = saddle_at_stride(image, s, px as usize, py as usize)?;
        Some((sf * u + offset, sf * v + offset))
    };
    let mut corners: Vec<Corner> = elect_at_one_scale(&coarse, &coarse_candidates, params)
        .into_iter()
        .filter_map(|c| {
            // `c` is at a pixel of `coarse`: its full-resolution centre, then its saddle.
            let (sf, offset) = (stride as f64, 0.5 * (stride as f64 - 1.0));
            let (x, y) = saddle_near(stride, sf * c.x + offset, sf * c.y + offset)?;
            Some(Corner { x, y, ..c })
        })
        .collect();
    let mut s = stride / 2;
    while s >= finest.max(1) {
        for c in &mut corners {
            if let Some((x, y)) = saddle_near(s, c.x, c.y) {
                (c.x, c.y) = (x, y);
            }
        }
        s /= 2;
    }
    corners
}

/// The finest scale (stride) at which [`elect_coarse`] moves the corners of a coarse-only election
/// to a saddle point. At full resolution a junction whose dark squares a print's dot gain has
/// joined by a bridge of a few pixels is a valley, not a saddle.
const FINEST_SADDLE_STRIDE: usize = 2;

/// Coarse pixels within which a coarse-scale corner and a fine-scale one are the same corner.
const COARSE_MERGE_PIXELS: f64 = 2.5;
/// The coarse pass makes the 15-px template span about this fraction of the grid step.
const COARSE_WINDOW_OF_STEP: f64 = 0.75;
/// Largest stride of the coarse pass.
const MAX_STRIDE: usize = 16;

/// The stride of the coarse election pass, or `None` if the board's squares are small enough for
/// the 15-px template. The grid step is the median, over the fine corners, of the distance to the
/// nearest other fine corner lying along one of the corner's edges (within 15°). The stride makes
/// the template span [`COARSE_WINDOW_OF_STEP`] of that step.
///
/// Why: on large squares the 15-px template sees only the junction itself, where printing defects
/// (diagonal squares that do not quite touch) and thin pen lines crossing the corner dominate, and
/// the centre and symmetry tests reject the corner. At the scale of the squares those details are
/// sub-pixel and the corner is a clean X-junction again, while a thin line no longer matches any
/// template.
fn coarse_stride(fine: &[Corner]) -> Option<usize> {
    if fine.len() < 4 {
        return None;
    }
    let cos_edge = 15f64.to_radians().cos();
    // Cells of about one grid step: a board fills its bounding box with one corner per step²
    // (a single row of corners, one per span / count).
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for c in fine {
        (lo[0], lo[1]) = (lo[0].min(c.x), lo[1].min(c.y));
        (hi[0], hi[1]) = (hi[0].max(c.x), hi[1].max(c.y));
    }
    let (span_x, span_y) = (hi[0] - lo[0], hi[1] - lo[1]);
    let n = fine.len() as f64;
    let cell = ((span_x * span_y) / n)
        .sqrt()
        .max(span_x.max(span_y) / n)
        .max(1.0);
    let grid = CornerGrid::new(fine, cell);
    let max_ring = (span_x.max(span_y) / cell).ceil() as i64 + 1;
    let mut steps: Vec<f64> = fine
        .iter()
        .filter_map(|c| {
            let dirs = c.angles.map(|a| (a.cos(), a.sin()));
            let mut best = f64::INFINITY;
            // Corners in ring k of cells are at least (k − 1)·cell away: once the best so far is
            // within k·cell, the rings beyond cannot beat it.
            for k in 0..=max_ring {
                for o in grid.ring(c.x, c.y, k).map(|i| &fine[i]) {
                    let (dx, dy) = (o.x - c.x, o.y - c.y);
                    let d = dx.hypot(dy);
                    let along = dirs
                        .iter()
                        .any(|&(ca, sa)| (dx * ca + dy * sa).abs() >= cos_edge * d);
                    if d > 0.0 && along && d < best {
                        best = d;
                    }
                }
                if best <= k as f64 * cell {
                    break;
                }
            }
            best.is_finite().then_some(best)
        })
        .collect();
    stride_from_steps(&mut steps)
}

/// The coarse stride for the per-corner grid steps `steps` (reordered): the median step, at least
/// four of them, scaled so that a template spans `COARSE_WINDOW_OF_STEP` steps; `None` below 2.
fn stride_from_steps(steps: &mut [f64]) -> Option<usize> {
    if steps.len() < 4 {
        return None;
    }
    let mid = steps.len() / 2;
    let step = *steps.select_nth_unstable_by(mid, f64::total_cmp).1;
    let stride = (COARSE_WINDOW_OF_STEP * step / TEMPLATE_SIDE as f64).floor();
    (stride >= 2.0).then_some((stride as usize).min(MAX_STRIDE))
}

/// Corners binned in square cells of side `cell` (a hash grid), for neighbour queries that look
/// at a few cells instead of every corner.
struct CornerGrid {
    cell: f64,
    bins: HashMap<(i64, i64), Vec<usize>>,
}

impl CornerGrid {
    fn new(corners: &[Corner], cell: f64) -> Self {
        let mut grid = Self {
            cell,
            bins: HashMap::new(),
        };
        for (i, c) in corners.iter().enumerate() {
            let key = grid.key(c.x, c.y);
            grid.bins.entry(key).or_default().push(i);
        }
        grid
    }

    fn key(&self, x: f64, y: f64) -> (i64, i64) {
        (
            (x / self.cell).floor() as i64,
            (y / self.cell).floor() as i64,
        )
    }

    /// Indices of the corners in the cells at Chebyshev distance exactly `k` from the cell of
    /// `(x, y)`.
    fn ring(&self, x: f64, y: f64, k: i64) -> impl Iterator<Item = usize> + '_ {
        let (cx, cy) = self.key(x, y);
        (-k..=k)
            .flat_map(move |dy| (-k..=k).map(move |dx| (dx, dy)))
            .filter(move |&(dx, dy)| dx.abs().max(dy.abs()) == k)
            .filter_map(move |(dx, dy)| self.bins.get(&(cx + dx, cy + dy)))
            .flatten()
            .copied()
    }

    /// Whether some corner of `corners` (the ones binned) lies closer than `radius ≤ cell` to
    /// `(x, y)`.
    fn any_within(&self, corners: &[Corner], x: f64, y: f64, radius: f64) -> bool {
        (0..=1)
            .flat_map(|k| self.ring(x, y, k))
            .any(|i| (corners[i].x - x).hypot(corners[i].y - y) < radius)
    }
}

/// Subpixel saddle point near pixel `(x, y)` of `image` box-downsampled by `s` (its pixel `(u, v)`
/// the mean of the full-resolution block `s·u .. s·u + s` in each axis, as [`crate::prefilter::box_downsample`]
/// makes it, with the same order of summation), in that image's coordinates: the stationary point
/// of the quadratic surface fitted on the 5 × 5 window (`∇(αx² + βxy + γy² + δx + εy) = 0`), if it
/// is a saddle within a pixel of `(x, y)`; otherwise the pixel itself. `None` only if the window
/// leaves the downsampled image. Only the 5 × 5 blocks around the pixel are read, so a few
/// corners refined at several scales cost no downsampled copies of a large image.
fn saddle_at_stride(image: &GrayImage, s: usize, x: usize, y: usize) -> Option<(f64, f64)> {
    const HALF: usize = 2;
    const SIDE: usize = 2 * HALF + 1;
    let (w, h) = (image.width() / s.max(1), image.height() / s.max(1));
    if s == 0 || x < HALF || y < HALF || x + HALF >= w || y + HALF >= h {
        return None;
    }
    let norm = 1.0 / (s * s) as f32;
    let mut patch = [0f32; SIDE * SIDE];
    let mut acc = Vec::new();
    for r in 0..SIDE {
        let (row0, col0) = ((y - HALF + r) * s, (x - HALF) * s);
        let dst = &mut patch[r * SIDE..(r + 1) * SIDE];
        match s {
            1 => dst.copy_from_slice(&image.row(row0)[col0..col0 + SIDE]),
            2 => {
                let (a, b) = (image.row(row0), image.row(row0 + 1));
                for (c, d) in dst.iter_mut().enumerate() {
                    let i = col0 + 2 * c;
                    *d = ((a[i] + a[i + 1]) + (b[i] + b[i + 1])) * norm;
                }
            }
            _ => {
                acc.clear();
                acc.resize(SIDE * s, 0f32);
                for k in 0..s {
                    for (a, &v) in acc.iter_mut().zip(&image.row(row0 + k)[col0..]) {
                        *a += v;
                    }
                }
                for (d, run) in dst.iter_mut().zip(acc.chunks_exact(s)) {
                    *d = run.iter().sum::<f32>() * norm;
                }
            }
        }
    }
    let proj = surface_projector(HALF);
    let mut k = [0f64; 5];
    for (i, &v) in patch.iter().enumerate() {
        for (kk, p) in k.iter_mut().zip(proj.iter()) {
            *kk += p[i] * v as f64;
        }
    }
    let [a, b, g, d, e] = k;
    // [2α β; β 2γ] (u, v)ᵀ = −(δ, ε)ᵀ; a saddle has a negative determinant.
    let det = 4.0 * a * g - b * b;
    let fallback = Some((x as f64, y as f64));
    if det.is_nan() || det >= 0.0 {
        return fallback;
    }
    let u = (-d * 2.0 * g + e * b) / det;
    let v = (-e * 2.0 * a + d * b) / det;
    if u.abs() > 1.0 || v.abs() > 1.0 {
        return fallback;
    }
    Some((x as f64 + u, y as f64 + v))
}

/// [`elect`] at the image's own resolution (the paper's election).
fn elect_at_one_scale(
    image: &GrayImage,
    candidates: &[Candidate],
    params: &ElectionParams,
) -> Vec<Corner> {
    let mut scored: Vec<(Corner, f32)> = candidates
        .par_iter()
        .filter_map(|c| {
            let (score, amplitude, angles) = score_candidate(image, c, params)?;
            let corner = Corner {
                x: c.x as f64,
                y: c.y as f64,
                angles,
                score: score as f64,
            };
            Some((corner, amplitude))
        })
        .collect();
    let best = scored.iter().map(|c| c.0.score).fold(0.0, f64::max);
    let threshold = (best - params.t_correlation).max(params.min_score);
    scored.retain(|c| c.0.score >= threshold);
    // Contrast rule: the median amplitude of the strongest few is a typical board corner.
    scored.sort_by(|a, b| b.1.total_cmp(&a.1));
    let top = &scored[..scored.len().min(CONTRAST_REFERENCE_COUNT)];
    let reference = top.get(top.len() / 2).map_or(0.0, |c| c.1) as f64;
    let min_amplitude = params.min_contrast_rel * reference;
    let mut scored: Vec<Corner> = scored
        .into_iter()
        .filter(|c| c.1 as f64 >= min_amplitude)
        .map(|c| c.0)
        .collect();
    scored.sort_by(|a, b| b.score.total_cmp(&a.score).then(a.y.total_cmp(&b.y)));
    deduplicate(scored, params.min_distance)
}

/// Greedy merge of corners (sorted best first) closer than `radius`, with a hash grid of cell
/// `radius` so that each corner is compared with its 3 × 3 cells only.
fn deduplicate(sorted: Vec<Corner>, radius: f64) -> Vec<Corner> {
    if radius.is_nan() || radius <= 0.0 {
        return sorted;
    }
    let cell = |v: f64| (v / radius).floor() as i64;
    let mut grid: HashMap<(i64, i64), Vec<usize>> = Default::default();
    let mut kept: Vec<Corner> = Vec::with_capacity(sorted.len());
    for c in sorted {
        let (cx, cy) = (cell(c.x), cell(c.y));
        let clash = (-1..=1).any(|dy| {
            (-1..=1).any(|dx| {
                grid.get(&(cx + dx, cy + dy)).is_some_and(|ids| {
                    ids.iter()
                        .any(|&i| (kept[i].x - c.x).hypot(kept[i].y - c.y) < radius)
                })
            })
        });
        if !clash {
            grid.entry((cx, cy)).or_default().push(kept.len());
            kept.push(c);
        }
    }
    kept
}

/// Pixel-level checkerboard corners of `image`: [`crate::prefilter::prefilter`] then [`elect`].
/// Positions are integer pixels (the corner lies within about a pixel); refine them with
/// [`crate::refine`].
pub fn find_corners(
    image: &GrayImage,
    prefilter_params: &PrefilterParams,
    election_params: &ElectionParams,
) -> Vec<Corner> {
    let scales = Scales::new(image);
    let candidates = prefilter_scales(&scales, prefilter_params);
    elect_scales(&scales, &candidates, election_params)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::prefilter::prefilter;

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

    // ---- election -------------------------------------------------------------------------

    #[test]
    fn template_index_inverts_template_angles() {
        for e in 0..TEMPLATE_STEPS {
            for d in 0..TEMPLATE_STEPS {
                let [a, b] = template_angles(e, d);
                // Angles straddling 0 wrap; the bank entry is found back when they do not.
                if a >= 0.0 && b < PI {
                    assert_eq!(template_index([a, b]), (e, d));
                }
            }
        }
        for t in (0..TEMPLATE_STEPS * TEMPLATE_STEPS)
            .step_by(97)
            .map(|i| template(i / TEMPLATE_STEPS, i % TEMPLATE_STEPS))
        {
            assert!(t.iter().sum::<f32>().abs() < 1e-4);
            assert!((t.iter().map(|v| v * v).sum::<f32>() - 1.0).abs() < 1e-4);
        }
    }

    /// Separable Gaussian blur with clamped borders (test helper).
    fn blur(img: &GrayImage, sigma: f64) -> GrayImage {
        let r = (3.0 * sigma).ceil() as isize;
        let k: Vec<f32> = (-r..=r)
            .map(|t| (-(t * t) as f64 / (2.0 * sigma * sigma)).exp() as f32)
            .collect();
        let ks: f32 = k.iter().sum();
        let (w, h) = (img.width() as isize, img.height() as isize);
        let pass = |src: &[f32], horizontal: bool| -> Vec<f32> {
            let mut out = vec![0f32; src.len()];
            for y in 0..h {
                for x in 0..w {
                    let mut acc = 0.0;
                    for (i, kv) in k.iter().enumerate() {
                        let t = i as isize - r;
                        let (sx, sy) = if horizontal {
                            ((x + t).clamp(0, w - 1), y)
                        } else {
                            (x, (y + t).clamp(0, h - 1))
                        };
                        acc += kv * src[(sy * w + sx) as usize];
                    }
                    out[(y * w + x) as usize] = acc / ks;
                }
            }
            out
        };
        let tmp = pass(img.data(), true);
        GrayImage::from_vec(img.width(), img.height(), pass(&tmp, false)).unwrap()
    }

    /// Distance from `p` to segment `a`–`b`.
    fn seg_dist(p: (f64, f64), a: (f64, f64), b: (f64, f64)) -> f64 {
        let (vx, vy) = (b.0 - a.0, b.1 - a.1);
        let t = (((p.0 - a.0) * vx + (p.1 - a.1) * vy) / (vx * vx + vy * vy)).clamp(0.0, 1.0);
        (p.0 - a.0 - t * vx).hypot(p.1 - a.1 - t * vy)
    }

    /// A 380 × 280 scene: optionally a rotated 11 × 6-square board (18 px squares, white quiet
    /// zone, a dot in every third square as in HydraMarker), and always a field of 2 px pinstripes,
    /// a pinstripe grid, a dark rectangle, a few random pen strokes, blur σ = 1 and noise σ = 4.
    /// Returns the image and the 50 inner board corners.
    fn scene(with_board: bool, seed: u64) -> (GrayImage, Vec<(f64, f64)>) {
        use rand::{Rng, SeedableRng};
        use rand_distr::{Distribution, Normal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let (w, h) = (380usize, 280usize);
        let (sq, cols, rows) = (18.0, 11usize, 6usize);
        let (ox, oy, rot) = (70.0, 30.0, 0.3f64);
        let (c, s) = (rot.cos(), rot.sin());
        let to_board = |x: f64, y: f64| {
            let (dx, dy) = (x - ox, y - oy);
            (c * dx + s * dy, -s * dx + c * dy)
        };
        let strokes: Vec<Vec<(f64, f64)>> = (0..4)
            .map(|_| {
                let mut p = (rng.gen_range(250.0..370.0), rng.gen_range(180.0..270.0));
                let mut heading: f64 = rng.gen_range(0.0..2.0 * PI);
                (0..12)
                    .map(|_| {
                        heading += rng.gen_range(-0.6..0.6);
                        p = (p.0 + 6.0 * heading.cos(), p.1 + 6.0 * heading.sin());
                        p
                    })
                    .collect()
            })
            .collect();
        let shade = |x: f64, y: f64| -> f64 {
            let (u, v) = to_board(x, y);
            let (bw, bh) = (cols as f64 * sq, rows as f64 * sq);
            if with_board && u > -9.0 && v > -9.0 && u < bw + 9.0 && v < bh + 9.0 {
                if u < 0.0 || v < 0.0 || u >= bw || v >= bh {
                    return 235.0; // quiet zone
                }
                let (i, j) = ((u / sq).floor(), (v / sq).floor());
                let dark = (i + j) as i64 % 2 == 0;
                let (cu, cv) = ((i + 0.5) * sq, (j + 0.5) * sq);
                let dot =
                    (i as i64 * 7 + j as i64 * 3) % 3 == 0 && (u - cu).hypot(v - cv) < 0.22 * sq;
                return if dark != dot { 30.0 } else { 220.0 };
            }
            // pinstripes: vertical 2 px lines every 6 px
            if (300.0..370.0).contains(&x) && (15.0..150.0).contains(&y) {
                return if (x - 300.0).rem_euclid(6.0) < 2.0 {
                    40.0
                } else {
                    200.0
                };
            }
            // pinstripe grid: 2 px lines every 9 px both ways
            if (15.0..120.0).contains(&x) && (200.0..270.0).contains(&y) {
                let on = (x - 15.0).rem_euclid(9.0) < 2.0 || (y - 200.0).rem_euclid(9.0) < 2.0;
                return if on { 50.0 } else { 210.0 };
            }
            // a dark rectangle (four L corners)
            if (140.0..200.0).contains(&x) && (215.0..255.0).contains(&y) {
                return 45.0;
            }
            for st in &strokes {
                if st.windows(2).any(|ab| seg_dist((x, y), ab[0], ab[1]) < 1.3) {
                    return 35.0;
                }
            }
            150.0
        };
        let mut data = vec![0f32; w * h];
        for y in 0..h {
            for x in 0..w {
                let mut acc = 0.0;
                for sy in 0..3 {
                    for sx in 0..3 {
                        let (px, py) = (
                            x as f64 + (sx as f64 - 1.0) / 3.0,
                            y as f64 + (sy as f64 - 1.0) / 3.0,
                        );
                        acc += shade(px, py);
                    }
                }
                data[y * w + x] = (acc / 9.0) as f32;
            }
        }
        let img = blur(&GrayImage::from_vec(w, h, data).unwrap(), 1.0);
        let noise = Normal::new(0.0, 4.0).unwrap();
        let noisy: Vec<f32> = img
            .data()
            .iter()
            .map(|&v| v + noise.sample(&mut rng) as f32)
            .collect();
        let truth = if with_board {
            (1..rows)
                .flat_map(|j| (1..cols).map(move |i| (i as f64 * sq, j as f64 * sq)))
                .map(|(u, v)| (ox + c * u - s * v, oy + s * u + c * v))
                .collect()
        } else {
            Vec::new()
        };
        (GrayImage::from_vec(w, h, noisy).unwrap(), truth)
    }

    fn nearest(p: (f64, f64), set: &[(f64, f64)]) -> f64 {
        set.iter()
            .map(|q| (p.0 - q.0).hypot(p.1 - q.1))
            .fold(f64::INFINITY, f64::min)
    }

    #[test]
    fn finds_every_board_corner_and_nothing_else() {
        for seed in [1, 2, 3] {
            let (img, truth) = scene(true, seed);
            assert_eq!(truth.len(), 50);
            let cands = prefilter(&img, &PrefilterParams::default());
            assert!(cands.len() < 500, "{} candidates", cands.len());
            let cand_pts: Vec<_> = cands.iter().map(|c| (c.x as f64, c.y as f64)).collect();
            for &t in &truth {
                assert!(
                    nearest(t, &cand_pts) <= 1.5,
                    "seed {seed}: {t:?} not a candidate"
                );
            }
            let corners = find_corners(
                &img,
                &PrefilterParams::default(),
                &ElectionParams::default(),
            );
            let found: Vec<_> = corners.iter().map(|c| (c.x, c.y)).collect();
            for &t in &truth {
                assert!(nearest(t, &found) <= 1.5, "seed {seed}: missed {t:?}");
            }
            for c in &corners {
                assert!(
                    nearest((c.x, c.y), &truth) <= 1.5,
                    "seed {seed}: false corner {c:?}"
                );
                assert!(c.score >= 0.65 && c.score <= 1.0);
            }
            assert_eq!(corners.len(), truth.len(), "seed {seed}");
            // The elected templates follow the board: edges at 0.3 rad and 0.3 + π/2.
            for c in &corners {
                let ok = |a: f64| angle_diff(a, 0.3) < 0.12 || angle_diff(a, 0.3 + PI / 2.0) < 0.12;
                assert!(ok(c.angles[0]) && ok(c.angles[1]), "{c:?}");
            }
        }
    }

    #[test]
    fn the_paper_rule_with_known_corner_count_agrees() {
        let (img, truth) = scene(true, 4);
        let pre = PrefilterParams {
            expected_corners: Some(50),
            ..Default::default()
        };
        let corners = find_corners(&img, &pre, &ElectionParams::default());
        assert_eq!(corners.len(), truth.len());
    }

    #[test]
    fn distractors_alone_yield_nothing() {
        for seed in [5, 6] {
            let (img, _) = scene(false, seed);
            let corners = find_corners(
                &img,
                &PrefilterParams::default(),
                &ElectionParams::default(),
            );
            assert!(corners.is_empty(), "{corners:?}");
        }
        let flat = GrayImage::filled(64, 64, 100.0).unwrap();
        assert!(find_corners(
            &flat,
            &PrefilterParams::default(),
            &ElectionParams::default()
        )
        .is_empty());
    }

    #[test]
    fn oblique_corner_is_elected_with_its_true_edges() {
        // A 65° X-junction: the surface fit says ~90°, the hill-climb finds the right template.
        let (t1, t2) = (0.4, 0.4 + 65f64.to_radians());
        let img = blur(&checker(t1, t2, 20.0, 20.0), 0.8);
        let cand = [Candidate {
            x: 20,
            y: 20,
            score: 1.0,
        }];
        let got = elect(&img, &cand, &ElectionParams::default());
        assert_eq!(got.len(), 1);
        assert!(got[0].score > 0.9, "{:?}", got[0]);
        assert!(angle_diff(got[0].angles[0], t1) < 0.07, "{:?}", got[0]);
        assert!(angle_diff(got[0].angles[1], t2) < 0.07, "{:?}", got[0]);
    }

    /// [`coarse_stride`] by its definition, every pair of corners compared.
    fn reference_stride(fine: &[Corner]) -> Option<usize> {
        let cos_edge = 15f64.to_radians().cos();
        let mut steps: Vec<f64> = fine
            .iter()
            .filter_map(|c| {
                fine.iter()
                    .filter_map(|o| {
                        let (dx, dy) = (o.x - c.x, o.y - c.y);
                        let d = dx.hypot(dy);
                        let along = c
                            .angles
                            .iter()
                            .any(|a| (dx * a.cos() + dy * a.sin()).abs() >= cos_edge * d);
                        (d > 0.0 && along).then_some(d)
                    })
                    .min_by(f64::total_cmp)
            })
            .collect();
        stride_from_steps(&mut steps)
    }

    #[test]
    fn coarse_stride_follows_its_definition() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let corner = |x: f64, y: f64, a: f64| Corner {
            x,
            y,
            angles: wrap_pair([a, a + 0.5 * PI]),
            score: 0.9,
        };
        for _ in 0..30 {
            // A rotated grid with a random step, holes, jitter and a few strays.
            let (step, rot) = (rng.gen_range(8.0..120.0), rng.gen_range(0.0..PI));
            let (c, s) = (f64::cos(rot), f64::sin(rot));
            let mut fine: Vec<Corner> = (0..rng.gen_range(0..15))
                .flat_map(|i| (0..12).map(move |j| (i as f64, j as f64)))
                .filter(|_| rng.gen_bool(0.8))
                .map(|(i, j)| {
                    let (u, v) = (i * step, j * step);
                    corner(500.0 + c * u - s * v, 400.0 + s * u + c * v, rot)
                })
                .collect();
            for _ in 0..rng.gen_range(0..5) {
                let a = rng.gen_range(0.0..PI);
                fine.push(corner(
                    rng.gen_range(0.0..2000.0),
                    rng.gen_range(0.0..2000.0),
                    a,
                ));
            }
            assert_eq!(
                coarse_stride(&fine),
                reference_stride(&fine),
                "{step} {rot}"
            );
        }
        // One row of corners, and all at one point: no panic, same answer.
        let row: Vec<Corner> = (0..50).map(|i| corner(i as f64 * 60.0, 5.0, 0.0)).collect();
        assert_eq!(coarse_stride(&row), reference_stride(&row));
        assert_eq!(coarse_stride(&row), Some(3));
        let point = vec![corner(3.0, 3.0, 0.2); 6];
        assert_eq!(coarse_stride(&point), None);
    }

    #[test]
    fn border_and_bad_candidates_are_dropped_without_panic() {
        let img = checker(0.4, 0.4 + PI / 2.0, 20.3, 19.8);
        let cands = [
            Candidate {
                x: 3,
                y: 20,
                score: 1.0,
            },
            Candidate {
                x: 40,
                y: 40,
                score: 1.0,
            },
            Candidate {
                x: 1000,
                y: 5,
                score: 1.0,
            },
            Candidate {
                x: 20,
                y: 20,
                score: 1.0,
            },
            Candidate {
                x: 21,
                y: 20,
                score: 1.0,
            },
        ];
        let got = elect(&img, &cands, &ElectionParams::default());
        assert_eq!(got.len(), 1, "{got:?}");
        let tiny = GrayImage::filled(3, 2, 1.0).unwrap();
        assert!(elect(&tiny, &cands, &ElectionParams::default()).is_empty());
        let silly = ElectionParams {
            fit_half: 1000,
            min_distance: f64::NAN,
            t_correlation: f64::NAN,
            min_score: f64::NAN,
            min_edge_angle: f64::NAN,
            max_centre_residual: f64::NAN,
            min_symmetry: f64::NAN,
            min_contrast_rel: f64::NAN,
        };
        assert!(elect(&img, &cands, &silly).is_empty());
    }
}
