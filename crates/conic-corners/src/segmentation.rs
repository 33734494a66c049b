//! Segmentation of an ordered chain of edge samples into pieces that one conic can describe
//! (paper III-E), in two stages:
//!
//! 1. **Discontinuities** (a gap across which the edge jumps, a fold): the absolute second
//!    difference of the sample positions, Gaussian-smoothed along the chain, is high there relative
//!    to the rest of the chain ([`second_difference_splits`]).
//! 2. **Inflections** (the edge is continuous but its inner normal flips, as on an S-shaped surface
//!    or where a marker leaves a cylinder for a flat face): the approximate normal curvature field
//!    (ANCF, eq. 7, [`ancf`]) changes sign along each piece of stage 1.
//!
//! [`segment_chain`] runs both. Chains are points in image coordinates (px, x right, y down),
//! ordered along the edge; they may have gaps (the blurred zone around each board corner is not
//! sampled), which neither stage mistakes for a discontinuity.

use std::ops::Range;

/// Parameters of [`segment_chain`]. `Default` suits sigmoid edge samples taken one per pixel
/// scanline.
#[derive(Clone, Debug, PartialEq)]
pub struct SegmentationParams {
    /// σ (samples) of the Gaussian that smooths the second-difference score.
    pub jump_smoothing: f64,
    /// A discontinuity needs a smoothed score above `jump_relative` robust standard deviations
    /// (1.4826 · MAD) above the chain's median score ...
    pub jump_relative: f64,
    /// ... and above this absolute floor (px), so that noise-free chains do not split on
    /// rounding-level structure.
    pub jump_min: f64,
    /// Largest offset Δ (samples) of the ANCF chords.
    pub ancf_max_offset: usize,
    /// An inflection needs `ancf_min_run` consecutive samples of each sign with `|κ|` above the
    /// larger of `flip_min_curvature` (px⁻¹) and `flip_noise` times the ANCF noise expected from
    /// the sample scatter.
    pub flip_min_curvature: f64,
    /// See `flip_min_curvature`.
    pub flip_noise: f64,
    /// See `flip_min_curvature`.
    pub ancf_min_run: usize,
    /// Pieces shorter than this (samples) are not split further by the ANCF stage.
    pub min_segment: usize,
    /// The ANCF stage sees only samples at least this far (px) from the previous one it kept, so
    /// that its chords, smoothing and runs (all counted in samples) span about the same arc
    /// length whether the edge was sampled on every scanline or on every other one.
    pub flip_spacing: f64,
}

impl Default for SegmentationParams {
    fn default() -> Self {
        Self {
            jump_smoothing: 1.0,
            jump_relative: 10.0,
            jump_min: 0.3,
            ancf_max_offset: 16,
            flip_min_curvature: 6e-4,
            flip_noise: 4.0,
            ancf_min_run: 10,
            min_segment: 24,
            flip_spacing: FLIP_SPACING_PX,
        }
    }
}

/// Default [`SegmentationParams::flip_spacing`]: the spacing of samples on every other scanline
/// (2 px along an edge near an axis, up to 2.8 px along a diagonal), less a margin for the walks'
/// wobble. On every scanline, chords of 16 samples are only 16 px long, and wiggles of the edge
/// at that scale (a print's grain, a JPEG's blocks) pass for bends: board mode on every scanline
/// broke the flat boards' lines of OpenCV's stereo photos into up to five pieces (one on every
/// other scanline), and its neighbour-difference noise there rose from 0.0734 to 0.0757 px; with
/// the spacing, no line of those photos is split and the noise is 0.0746 px.
pub const FLIP_SPACING_PX: f64 = 1.9;

/// Indices of the samples of `points` that are at least `spacing` px from the previous kept
/// one, starting with the first.
fn spaced(points: &[[f64; 2]], spacing: f64) -> Vec<usize> {
    let mut kept: Vec<usize> = Vec::with_capacity(points.len());
    let s2 = spacing * spacing;
    for (i, p) in points.iter().enumerate() {
        let far = kept.last().map_or(true, |&j| {
            let q = points[j];
            (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) >= s2
        });
        if far {
            kept.push(i);
        }
    }
    kept
}

/// Absolute second difference of the chain at each interior sample, measured across the chain:
/// `d_i = 2 · dist(P_i, line P_{i−1} P_{i+1})`. For evenly spaced samples this is the normal
/// component of the central difference `P_{i−1} − 2 P_i + P_{i+1}` (κh² on a smooth curve with
/// spacing h); unlike the full second difference it ignores uneven spacing along the chain, so a
/// gap in the sampling (a corner's blurred zone) scores only `κ s₋ s₊` (s± the distances to the
/// neighbours), while a jump across the chain scores about twice the jump. Ends score 0.
fn second_difference_score(points: &[[f64; 2]], out: &mut Vec<f64>) {
    out.clear();
    out.resize(points.len(), 0.0);
    for i in 1..points.len().saturating_sub(1) {
        let (a, p, b) = (points[i - 1], points[i], points[i + 1]);
        let c = [b[0] - a[0], b[1] - a[1]];
        let len = c[0].hypot(c[1]);
        let cross = c[0] * (p[1] - a[1]) - c[1] * (p[0] - a[0]);
        out[i] = if len > 0.0 {
            2.0 * cross.abs() / len
        } else {
            2.0 * (p[0] - a[0]).hypot(p[1] - a[1])
        };
    }
}

/// `v` convolved with a normalized Gaussian of σ `sigma` samples (truncated at 3σ, renormalized
/// at the ends).
fn gaussian_smooth(v: &[f64], sigma: f64) -> Vec<f64> {
    if sigma.is_nan() || sigma <= 0.0 || v.len() < 2 {
        return v.to_vec();
    }
    let r = (3.0 * sigma).ceil() as usize;
    let kernel: Vec<f64> = (0..=r)
        .map(|k| (-0.5 * (k as f64 / sigma).powi(2)).exp())
        .collect();
    let n = v.len();
    // Each output sums its window from left to right, the weights likewise.
    let at = |i: usize| {
        let lo = i.saturating_sub(r);
        let hi = (i + r).min(n - 1);
        let (mut s, mut w) = (0.0, 0.0);
        for (j, &x) in v.iter().enumerate().take(hi + 1).skip(lo) {
            let k = kernel[i.abs_diff(j)];
            s += k * x;
            w += k;
        }
        s / w
    };
    let mut out: Vec<f64> = (0..n)
        .map(|i| if i < r || i + r >= n { at(i) } else { 0.0 })
        .collect();
    if n > 2 * r {
        // Inside, every window is whole: the same sums offset by offset, each a pass over the
        // outputs that the compiler vectorizes (the segmentation's largest cost on long chains
        // before), to the same bits, since each output still adds its terms left to right.
        let full: Vec<f64> = (0..=2 * r).map(|m| kernel[m.abs_diff(r)]).collect();
        let w: f64 = full.iter().fold(0.0, |acc, &k| acc + k);
        let inner = &mut out[r..n - r];
        for (m, &k) in full.iter().enumerate() {
            for (o, &x) in inner.iter_mut().zip(&v[m..]) {
                *o += k * x;
            }
        }
        for o in inner {
            *o /= w;
        }
    }
    out
}

/// Median and MAD (median absolute deviation) of finite values; `(0, 0)` if none.
fn median_mad(v: &[f64]) -> (f64, f64) {
    let mut w: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    median_mad_in_place(&mut w)
}

/// Median and MAD (median absolute deviation) of `v`, computed in place: `v` is reordered and
/// left holding the absolute deviations. For an even count each is the mean of the two middle
/// values: the upper one alone made outlier tests on a few values depend on their signs (of
/// four polarity jumps, one sign's outlier was caught and the other's not). `(0, 0)` if empty.
pub(crate) fn median_mad_in_place(v: &mut [f64]) -> (f64, f64) {
    if v.is_empty() {
        return (0.0, 0.0);
    }
    let med = median_in_place(v);
    for x in v.iter_mut() {
        *x = (*x - med).abs();
    }
    (med, median_in_place(v))
}

/// Median of non-empty `v` (the mean of the two middle values for an even count); reorders `v`.
pub(crate) fn median_in_place(v: &mut [f64]) -> f64 {
    let (mid, odd) = (v.len() / 2, v.len() % 2 == 1);
    let (below, upper, _) = v.select_nth_unstable_by(mid, f64::total_cmp);
    let upper = *upper;
    if odd {
        return upper;
    }
    let lower = below
        .iter()
        .copied()
        .max_by(f64::total_cmp)
        .unwrap_or(upper);
    0.5 * (lower + upper)
}

/// Stage 1: indices `s` where the chain should be cut into `[.., s)` and `[s, ..)` because it is
/// discontinuous there (a jump across the chain or a fold).
///
/// The score is the across-chain second difference `d_i` (see the module docs: `2 ·` the distance
/// of `P_i` from the chord of its neighbours), smoothed by a Gaussian of σ
/// `params.jump_smoothing` samples. Samples score high when above both `params.jump_min` px and
/// `median + params.jump_relative · 1.4826 · MAD` of the smoothed scores. Each run of high samples
/// gives one cut, after the highest sample of the run when its successor scores higher than its
/// predecessor and before it otherwise (a jump between `P_j` and `P_{j+1}` raises `d_j` and
/// `d_{j+1}` alike). Chains of fewer than 5 points are never cut. Non-finite points are not
/// expected (they would score NaN and be ignored).
pub fn second_difference_splits(points: &[[f64; 2]], params: &SegmentationParams) -> Vec<usize> {
    let mut cuts = Vec::new();
    if points.len() < 5 {
        return cuts;
    }
    let mut raw = Vec::new();
    second_difference_score(points, &mut raw);
    let score = gaussian_smooth(&raw, params.jump_smoothing);
    let (med, mad) = median_mad(&score[1..score.len() - 1]);
    let limit = (med + params.jump_relative * 1.4826 * mad).max(params.jump_min);
    let mut i = 1;
    while i < score.len() - 1 {
        if score[i].is_nan() || score[i] <= limit {
            i += 1;
            continue;
        }
        let start = i;
        while i < score.len() - 1 && score[i] > limit {
            i += 1;
        }
        let peak = (start..i)
            .max_by(|&a, &b| score[a].total_cmp(&score[b]))
            .unwrap_or(start);
        let cut = if score[peak + 1] > score[peak - 1] {
            peak + 1
        } else {
            peak
        };
        if cut > 0 && cut < points.len() && cuts.last() != Some(&cut) {
            cuts.push(cut);
        }
    }
    cuts
}

/// Approximate normal curvature field (paper eq. 7) of an ordered chain: for each point a vector
/// along the inner normal (towards the centre of curvature) whose length estimates the curvature
/// (px⁻¹).
///
/// For `P_i` and each offset `Δ = 1..=max_offset` with `P_{i±Δ}` in the chain, the paper's term is
/// `S(i, Δ) = |c × a| / |c|² · ω_Δ · n_⊥`, with the chord `c = P_{i+Δ} − P_{i−Δ}`, `a = P_i − P_{i−Δ}`,
/// `n_⊥` the unit normal of `c` on the side away from `P_i` (the inner normal) and `ω_Δ` a "flipped"
/// Gaussian `1 − exp(−Δ² / (2 (max_offset/2)²))` that trusts long chords more than short,
/// noise-dominated ones. On a circle of curvature κ, `|c × a| / |c|² = κ |a| |b| / (2 |c|)`
/// (`b = P_{i+Δ} − P_i`), which depends on the spacing; each term is therefore rescaled by
/// `2 |c| / (|a| |b|)` to the Menger curvature `2 |c × a| / (|a| |b| |c|)` — exact on a circle for any
/// spacing, including across a gap — and the field is the ω-weighted mean
/// `ANCF(i) = Σ_Δ ω_Δ κ_M(i, Δ) n_⊥ / Σ_Δ ω_Δ`. Same direction and sign as eq. 7; the magnitude is a
/// curvature. Points with no usable offset (the ends, coincident points) get `[0, 0]`.
pub fn ancf(points: &[[f64; 2]], max_offset: usize) -> Vec<[f64; 2]> {
    let n = points.len();
    let half = (max_offset as f64 / 2.0).max(0.5);
    let xs: Vec<f64> = points.iter().map(|p| p[0]).collect();
    let ys: Vec<f64> = points.iter().map(|p| p[1]).collect();
    let (mut ax, mut ay, mut wsum) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    // Offset by offset, each a pass over the points that the compiler vectorizes; every point
    // still sums its terms in the order of the offsets.
    for d in 1..=max_offset.min(n.saturating_sub(1) / 2) {
        let w = 1.0 - (-0.5 * (d as f64 / half).powi(2)).exp();
        let m = n - 2 * d;
        let (px, qx, rx) = (&xs[..m], &xs[d..d + m], &xs[2 * d..]);
        let (py, qy, ry) = (&ys[..m], &ys[d..d + m], &ys[2 * d..]);
        let (ax, ay, ws) = (&mut ax[d..d + m], &mut ay[d..d + m], &mut wsum[d..d + m]);
        for j in 0..m {
            let c = [rx[j] - px[j], ry[j] - py[j]];
            let a = [qx[j] - px[j], qy[j] - py[j]];
            let b = [rx[j] - qx[j], ry[j] - qy[j]];
            // Squared lengths: image coordinates cannot overflow, and one square root per
            // term instead of three `hypot`s is most of this function's time.
            let (lc2, la2, lb2) = (
                c[0] * c[0] + c[1] * c[1],
                a[0] * a[0] + a[1] * a[1],
                b[0] * b[0] + b[1] * b[1],
            );
            let cross = c[0] * a[1] - c[1] * a[0];
            // Left normal of c is (−c_y, c_x)/|c|; P_i is on the left when cross > 0, so the
            // inner normal points right then. κ n = 2 |c × a| / (|a| |b| |c|) · n.
            let s = if cross > 0.0 { -1.0 } else { 1.0 };
            let k = 2.0 * cross.abs() * s / ((la2 * lb2).sqrt() * lc2);
            // Coincident points give no term (a select, not a branch, to stay vectorized).
            let usable = lc2 > 0.0 && la2 > 0.0 && lb2 > 0.0;
            let (tx, ty, tw) = if usable {
                (w * k * c[1], w * k * c[0], w)
            } else {
                (0.0, 0.0, 0.0)
            };
            ax[j] -= tx;
            ay[j] += ty;
            ws[j] += tw;
        }
    }
    (0..n)
        .map(|i| {
            if wsum[i] > 0.0 {
                [ax[i] / wsum[i], ay[i] / wsum[i]]
            } else {
                [0.0, 0.0]
            }
        })
        .collect()
}

/// Stage 2 on one piece: cut indices (relative to `points`) where the signed ANCF curvature
/// flips between runs of at least `ancf_min_run` samples beyond the threshold.
fn flip_splits(points: &[[f64; 2]], params: &SegmentationParams) -> Vec<usize> {
    let n = points.len();
    let mut cuts = Vec::new();
    if n < params.min_segment.max(2 * params.ancf_min_run).max(5) {
        return cuts;
    }
    // Signed curvature against the piece's overall left normal.
    let (first, last) = (points[0], points[n - 1]);
    let chord = [last[0] - first[0], last[1] - first[1]];
    let len = chord[0].hypot(chord[1]);
    if len.is_nan() || len <= 0.0 {
        return cuts;
    }
    let left = [-chord[1] / len, chord[0] / len];
    let field = ancf(points, params.ancf_max_offset);
    // Near the ends only short, noisy chords exist: no verdict there.
    let edge = params.ancf_max_offset / 2;
    let signed: Vec<f64> = field
        .iter()
        .enumerate()
        .map(|(i, v)| {
            if i < edge || i + edge >= n {
                0.0
            } else {
                v[0] * left[0] + v[1] * left[1]
            }
        })
        .collect();
    let k = gaussian_smooth(&signed, params.ancf_max_offset as f64 / 2.0);
    // Sample scatter across the chain from the second differences (σ_d = √6 σ_p for independent
    // position noise σ_p). The smoothed field then has a noise of about 0.6 σ_p / Δ_max² px⁻¹
    // (measured on straight chains: 0.62, 0.49, 0.38 for Δ_max = 8, 16, 24).
    let mut raw = Vec::new();
    second_difference_score(points, &mut raw);
    let (med, _) = median_mad(&raw[1..n - 1]);
    let sigma_p = med / 0.6745 / 6f64.sqrt();
    let m = params.ancf_max_offset.max(1) as f64;
    let tau = params
        .flip_min_curvature
        .max(params.flip_noise * 0.6 * sigma_p / (m * m));
    // Significant runs: (sign, start, end).
    let mut runs: Vec<(f64, usize, usize)> = Vec::new();
    let mut i = 0;
    while i < n {
        if k[i].abs() <= tau {
            i += 1;
            continue;
        }
        let s = k[i].signum();
        let start = i;
        while i < n && k[i].abs() > tau && k[i].signum() == s {
            i += 1;
        }
        if i - start >= params.ancf_min_run {
            runs.push((s, start, i));
        }
    }
    for w in runs.windows(2) {
        let ((s0, _, e0), (s1, b1, _)) = (w[0], w[1]);
        if s0 == s1 {
            continue;
        }
        // The zero crossing between the two runs nearest the middle of the interval.
        let cut = (e0..=b1)
            .filter(|&j| j > 0 && k[j - 1].signum() != k[j].signum())
            .min_by_key(|&j| j.abs_diff((e0 + b1) / 2))
            .unwrap_or((e0 + b1) / 2);
        if cut > 0 && cut < n {
            cuts.push(cut);
        }
    }
    cuts
}

/// Splits an ordered chain of edge samples into index ranges, each one smooth piece of constant
/// bending direction: first at discontinuities ([`second_difference_splits`]), then each piece at
/// the flips of its ANCF curvature ([`ancf`]) among its samples `flip_spacing` apart. The ranges
/// are in order, disjoint and cover `0..points.len()`; an empty chain gives no range.
pub fn segment_chain(points: &[[f64; 2]], params: &SegmentationParams) -> Vec<Range<usize>> {
    segment_pieces(points, params)
        .into_iter()
        .map(|(r, _)| r)
        .collect()
}

/// Where a piece of [`segment_pieces`] begins.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PieceStart {
    /// At the start of the chain.
    Chain,
    /// After a discontinuity ([`second_difference_splits`]): the edge itself breaks there.
    Discontinuity,
    /// At a flip of the curvature (an inflection): the edge runs on smoothly.
    Inflection,
}

/// [`segment_chain`] with the reason each piece begins where it does.
pub fn segment_pieces(
    points: &[[f64; 2]],
    params: &SegmentationParams,
) -> Vec<(Range<usize>, PieceStart)> {
    if points.is_empty() {
        return Vec::new();
    }
    let mut bounds = vec![0];
    bounds.extend(second_difference_splits(points, params));
    bounds.push(points.len());
    let mut out = Vec::new();
    for w in bounds.windows(2) {
        let (a, b) = (w[0], w[1]);
        if a >= b {
            continue;
        }
        let (mut start, mut kind) = (
            a,
            if a == 0 {
                PieceStart::Chain
            } else {
                PieceStart::Discontinuity
            },
        );
        let kept = spaced(&points[a..b], params.flip_spacing);
        let thinned: Vec<[f64; 2]> = kept.iter().map(|&i| points[a + i]).collect();
        for cut in flip_splits(&thinned, params) {
            out.push((start..a + kept[cut], kind));
            (start, kind) = (a + kept[cut], PieceStart::Inflection);
        }
        out.push((start..b, kind));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    fn noisy(points: Vec<[f64; 2]>, sigma: f64, seed: u64) -> Vec<[f64; 2]> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let n = Normal::new(0.0, sigma).unwrap();
        points
            .into_iter()
            .map(|p| [p[0] + n.sample(&mut rng), p[1] + n.sample(&mut rng)])
            .collect()
    }

    #[test]
    fn median_and_mad_do_not_depend_on_the_outliers_sign() {
        assert_eq!(median_mad_in_place(&mut []), (0.0, 0.0));
        assert_eq!(median_mad_in_place(&mut [3.0, 1.0, 2.0]), (2.0, 1.0));
        // Four values: the median and the MAD are the means of the two middle ones.
        assert_eq!(median_mad_in_place(&mut [4.0, 1.0, 3.0, 2.0]), (2.5, 1.0));
        // Four polarity jumps of about 4 px with one outlier: mirrored, the same spread.
        let (m_hi, mad_hi) = median_mad_in_place(&mut [4.0, 4.2, 3.8, 9.0]);
        let (m_lo, mad_lo) = median_mad_in_place(&mut [4.0, 4.2, 3.8, -1.0]);
        assert!((m_hi - 4.1).abs() < 1e-12 && (m_lo - 3.9).abs() < 1e-12);
        assert!((mad_hi - mad_lo).abs() < 1e-12, "{mad_hi} {mad_lo}");
    }

    /// Arc of radius r, one sample per unit of x (like row scanlines of a mostly horizontal edge),
    /// bending by `sign`, from x0 to x1.
    fn arc(r: f64, sign: f64, x0: f64, x1: f64) -> Vec<[f64; 2]> {
        let mut v = Vec::new();
        let mut x = x0;
        while x <= x1 {
            v.push([x, sign * (r - (r * r - x * x).sqrt())]);
            x += 1.0;
        }
        v
    }

    /// S curve: y = sgn(x) (R − √(R² − x²)), inflection at x = 0, with gaps of 12 samples every
    /// 60 (the corners' blurred zones).
    fn s_curve(r: f64) -> (Vec<[f64; 2]>, usize) {
        let mut v: Vec<[f64; 2]> = Vec::new();
        let mut inflection = 0;
        for i in -150..=150 {
            if (i + 150) % 60 < 12 {
                continue;
            }
            let x = i as f64 + 0.3;
            if x > 0.0 && inflection == 0 {
                inflection = v.len();
            }
            v.push([x, x.signum() * (r - (r * r - x * x).sqrt())]);
        }
        (v, inflection)
    }

    #[test]
    fn gaussian_smooth_is_the_window_sums() {
        // Every output, inside and at the ends, is its window's weighted sum left to right
        // divided by the weights' sum: the same bits as written out sample by sample.
        let v: Vec<f64> = (0..200)
            .map(|i| ((i * 37) % 23) as f64 * 0.1 - 1.0)
            .collect();
        for (n, sigma) in [(200, 8.0f64), (200, 1.5), (30, 8.0), (17, 3.0), (2, 0.7)] {
            let v = &v[..n];
            let r = (3.0 * sigma).ceil() as usize;
            let smooth = gaussian_smooth(v, sigma);
            for (i, &got) in smooth.iter().enumerate() {
                let (mut s, mut w) = (0.0, 0.0);
                for (j, &x) in v.iter().enumerate() {
                    if j + r >= i && j <= i + r {
                        let d = i.abs_diff(j) as f64 / sigma;
                        let k = (-0.5 * d.powi(2)).exp();
                        s += k * x;
                        w += k;
                    }
                }
                assert_eq!(got.to_bits(), (s / w).to_bits(), "n {n} σ {sigma} i {i}");
            }
        }
    }

    #[test]
    fn ancf_measures_curvature_and_points_inward() {
        let pts = arc(200.0, 1.0, -60.0, 60.0);
        let f = ancf(&pts, 16);
        let mid = f[60];
        // Centre of curvature at (0, 200): inner normal +y.
        assert!((mid[1] - 1.0 / 200.0).abs() < 1e-4, "{mid:?}");
        assert!(mid[0].abs() < 1e-6);
        assert_eq!(f[0], [0.0, 0.0]);
        // Across a gap, still exact.
        let mut gappy = pts.clone();
        gappy.drain(50..60);
        let g = ancf(&gappy, 16);
        assert!((g[50][1] - 1.0 / 200.0).abs() < 2e-4, "{:?}", g[50]);
    }

    #[test]
    fn s_curve_splits_at_the_inflection() {
        for r in [170.0, 250.0, 400.0] {
            let (clean, infl) = s_curve(r);
            let pts = noisy(clean, 0.03, 7);
            let segs = segment_chain(&pts, &SegmentationParams::default());
            assert_eq!(segs.len(), 2, "r = {r}: {segs:?}");
            let cut = segs[0].end;
            assert!(
                cut.abs_diff(infl) <= 4,
                "r = {r}: cut at {cut}, inflection at {infl}"
            );
            let kinds: Vec<_> = segment_pieces(&pts, &SegmentationParams::default())
                .into_iter()
                .map(|(_, k)| k)
                .collect();
            assert_eq!(kinds, [PieceStart::Chain, PieceStart::Inflection]);
        }
    }

    #[test]
    fn jump_splits_at_the_jump() {
        let mut pts = arc(300.0, 1.0, -80.0, 80.0);
        for p in &mut pts[100..] {
            p[1] += 2.0;
        }
        let pts = noisy(pts, 0.03, 3);
        let cuts = second_difference_splits(&pts, &SegmentationParams::default());
        assert_eq!(cuts, vec![100]);
        let segs = segment_chain(&pts, &SegmentationParams::default());
        assert_eq!(segs, vec![0..100, 100..pts.len()]);
        assert_eq!(
            segment_pieces(&pts, &SegmentationParams::default()),
            [
                (0..100, PieceStart::Chain),
                (100..pts.len(), PieceStart::Discontinuity)
            ]
        );
    }

    #[test]
    fn fold_splits_near_the_kink() {
        // Two straight pieces meeting at 60° (the crease of a box).
        let mut pts: Vec<[f64; 2]> = (0..80).map(|i| [i as f64, 0.0]).collect();
        let (c, s) = (60f64.to_radians().cos(), 60f64.to_radians().sin());
        pts.extend((1..80).map(|i| [79.0 + i as f64 * c, i as f64 * s]));
        let segs = segment_chain(&noisy(pts, 0.02, 5), &SegmentationParams::default());
        assert_eq!(segs.len(), 2, "{segs:?}");
        assert!(segs[0].end.abs_diff(80) <= 2, "{segs:?}");
    }

    #[test]
    fn straight_and_single_arcs_do_not_split() {
        let params = SegmentationParams::default();
        for seed in 0..20 {
            let line: Vec<[f64; 2]> = (0..400).map(|i| [0.3 * i as f64, i as f64]).collect();
            let line = noisy(line, 0.05, seed);
            assert_eq!(segment_chain(&line, &params), vec![0..400], "seed {seed}");
            for r in [100.0, 1000.0] {
                let a = noisy(arc(r, -1.0, -90.0, 90.0), 0.05, seed);
                assert_eq!(segment_chain(&a, &params).len(), 1, "seed {seed}, r {r}");
            }
        }
        // With gaps too.
        let (s, _) = s_curve(300.0);
        let right: Vec<[f64; 2]> = s.into_iter().filter(|p| p[0] > 0.0).collect();
        assert_eq!(segment_chain(&right, &params).len(), 1);
    }

    #[test]
    fn a_chain_on_every_scanline_splits_where_one_on_every_other_does() {
        // A straight edge whose samples follow a texture: three wiggles of 0.08 px at wavelengths
        // of 20–40 px (a print's grain, a JPEG's blocks) and noise of 0.02 px, sampled every
        // pixel and every 2 px.
        let wiggly = |step: f64, seed: u64| -> Vec<[f64; 2]> {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let waves: Vec<(f64, f64)> = (0..3)
                .map(|_| {
                    (
                        rng.gen_range(20.0..40.0),
                        rng.gen_range(0.0..std::f64::consts::TAU),
                    )
                })
                .collect();
            (0..)
                .map(|i| i as f64 * step)
                .take_while(|&t| t < 300.0)
                .map(|t| {
                    let w: f64 = waves
                        .iter()
                        .map(|(l, ph)| 0.08 * (std::f64::consts::TAU * t / l + ph).sin())
                        .sum();
                    [t, 100.0 + w]
                })
                .collect()
        };
        let params = SegmentationParams::default();
        let every = SegmentationParams {
            flip_spacing: 0.0,
            ..params.clone()
        };
        let mut split_when_every = 0;
        for seed in 0..20 {
            let (dense, sparse) = (
                noisy(wiggly(1.0, seed), 0.02, seed),
                noisy(wiggly(2.0, seed), 0.02, seed),
            );
            assert_eq!(segment_chain(&sparse, &params).len(), 1, "seed {seed}");
            assert_eq!(segment_chain(&dense, &params).len(), 1, "seed {seed}");
            split_when_every += usize::from(segment_chain(&dense, &every).len() > 1);
        }
        // Without the spacing, 16-sample chords see the wiggles as bends.
        assert!(split_when_every >= 10, "{split_when_every}");
        // A real inflection is found at the same place on every scanline and on every other one.
        let (clean, infl) = s_curve(250.0);
        let dense = noisy(clean, 0.03, 5);
        let sparse: Vec<[f64; 2]> = dense.iter().copied().step_by(2).collect();
        let (d, s) = (
            segment_chain(&dense, &params),
            segment_chain(&sparse, &params),
        );
        assert!(d.len() == 2 && s.len() == 2, "{d:?} {s:?}");
        assert!(d[0].end.abs_diff(infl) <= 4, "{d:?}, inflection at {infl}");
        assert!(d[0].end.abs_diff(2 * s[0].end) <= 4, "{d:?} {s:?}");
    }

    #[test]
    fn degenerate_chains_do_not_panic() {
        let p = SegmentationParams::default();
        assert!(segment_chain(&[], &p).is_empty());
        assert_eq!(segment_chain(&[[1.0, 1.0]], &p), vec![0..1]);
        assert_eq!(segment_chain(&[[1.0, 1.0]; 50], &p), vec![0..50]);
        assert_eq!(segment_chain(&[[0.0, 0.0], [1.0, 0.0]], &p), vec![0..2]);
        assert_eq!(ancf(&[[2.0, 2.0]; 5], 3), vec![[0.0, 0.0]; 5]);
        let nan = vec![[f64::NAN, 0.0]; 30];
        let segs = segment_chain(&nan, &p);
        assert_eq!(segs.first().map(|r| r.start), Some(0));
        assert_eq!(segs.last().map(|r| r.end), Some(30));
    }
}
