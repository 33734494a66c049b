//! Corner pre-filter (paper III-A): a Hessian saddle score at one Gaussian scale, a conservative
//! non-maximum suppression, and a cut that keeps a manageable number of candidates for the
//! template election ([`crate::election`]).
//!
//! All positions are integer pixel coordinates (pixel centres at integers, x right, y down).

use crate::GrayImage;
use rayon::prelude::*;
use std::borrow::Cow;
use std::sync::OnceLock;

/// Smallest Gaussian scale accepted by [`hessian_score`]; smaller values are raised to it.
pub const MIN_SIGMA: f32 = 0.5;
/// Largest Gaussian scale accepted by [`hessian_score`]; larger values are lowered to it.
pub const MAX_SIGMA: f32 = 32.0;
/// Kernel radius in units of σ. A Gaussian truncated at 3σ loses 0.3 % of its mass; the derivative
/// kernels are corrected for the truncation (see [`Kernels`]), so the score is unbiased.
const RADIUS_SIGMAS: f32 = 3.0;
/// Smallest `sigma` for which [`PrefilterParams::half_resolution`] applies: the half-resolution
/// scale `√(σ² − ¼)/2` is then at least 0.7 half-resolution pixels, enough for the sampled kernels
/// to stay Gaussian-like and for the 2 × 2 average not to alias the saddles away.
pub const MIN_HALF_RESOLUTION_SIGMA: f32 = 1.5;
/// Half-resolution candidates are placed at the best full-resolution pixel among the
/// `RELOCATE_SIDE²` nearest to the centre of their 2 × 2 block (offsets −3..=4): the true peak is
/// within a pixel or two of it, and 8 is one AVX2 vector of `f32`.
const RELOCATE_SIDE: usize = 8;
/// Rows per parallel band of [`hessian_score`]: large enough that the `2r` rows of horizontal
/// pass each band recomputes at its top are a small overhead.
const BAND_ROWS: usize = 64;
/// Columns per strip of a band: the ring of `2r+1` rows of three horizontal passes over one strip
/// (39 rows at σ = 2) stays in the L1 cache while the vertical pass reads it.
const STRIP_COLS: usize = 256;
/// The adaptive cut of [`prefilter`] takes its reference score as the median of this many
/// strongest candidates, so that a few isolated peaks stronger than any corner (glints, a sharp
/// junction in the background) cannot raise the threshold above the board.
const REFERENCE_COUNT: usize = 16;

/// One-sided taps (`k = 0..=r`) of the Gaussian and of its first and second derivatives, in
/// correlation form: `Σ_k K[k]·f(x+k)` with `K[−k] = K[k]` (smoothing, second derivative) or
/// `K[−k] = −K[k]` (first derivative). After truncation to `|k| ≤ r` they are renormalized so
/// that the smoothing kernel sums to 1, the first-derivative kernel gives `f' = 1` on `f = x`,
/// and the second-derivative kernel gives 0 on constants and `f'' = 2` on `f = x²`.
struct Kernels {
    g: Vec<f32>,
    d1: Vec<f32>,
    d2: Vec<f32>,
}

impl Kernels {
    fn new(sigma: f32) -> Self {
        let s = sigma as f64;
        let r = (RADIUS_SIGMAS * sigma).ceil().max(1.0) as usize;
        let gauss: Vec<f64> = (0..=r)
            .map(|k| (-((k * k) as f64) / (2.0 * s * s)).exp())
            .collect();
        // Sums over −r..=r of the symmetric / antisymmetric extensions.
        let sym_sum = |v: &[f64], p: i32| -> f64 {
            v.iter()
                .enumerate()
                .map(|(k, &x)| {
                    let w = if k == 0 { 1.0 } else { 2.0 };
                    w * x * (k as f64).powi(p)
                })
                .sum()
        };
        let g_norm = sym_sum(&gauss, 0);
        let g: Vec<f32> = gauss.iter().map(|&v| (v / g_norm) as f32).collect();
        let d1_raw: Vec<f64> = gauss
            .iter()
            .enumerate()
            .map(|(k, &v)| k as f64 * v)
            .collect();
        let d1_norm = sym_sum(&d1_raw, 1);
        let d1 = d1_raw.iter().map(|&v| (v / d1_norm) as f32).collect();
        let mut d2_raw: Vec<f64> = gauss
            .iter()
            .enumerate()
            .map(|(k, &v)| ((k * k) as f64 / (s * s) - 1.0) * v)
            .collect();
        // Remove the DC leak of the truncated kernel by subtracting a multiple of the Gaussian.
        let leak = sym_sum(&d2_raw, 0) / sym_sum(&gauss, 0);
        for (d, &v) in d2_raw.iter_mut().zip(&gauss) {
            *d -= leak * v;
        }
        let d2_norm = sym_sum(&d2_raw, 2) / 2.0;
        let d2 = d2_raw.iter().map(|&v| (v / d2_norm) as f32).collect();
        Self { g, d1, d2 }
    }

    fn radius(&self) -> usize {
        self.g.len() - 1
    }
}

/// Scratch rows for one band: the clamped-padded input row and a ring of `2r+1` rows of each
/// horizontal pass (smoothing, first and second derivative along x).
struct BandScratch {
    padded: Vec<f32>,
    h0: Vec<f32>,
    h1: Vec<f32>,
    h2: Vec<f32>,
}

/// Lanes processed together by the inner loops: accumulators stay in registers and each tap loads
/// its inputs once, which matters more than the arithmetic here.
const LANES: usize = 16;

/// `a·b + c`, as one fused instruction when `FUSED` (only used where FMA is enabled: without
/// hardware support a fused multiply-add is a slow library call). Shared with `edge_sampling`.
#[inline(always)]
pub(crate) fn madd<const FUSED: bool>(a: f32, b: f32, c: f32) -> f32 {
    if FUSED {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

/// Horizontal pass over `L` consecutive outputs starting at `x0`.
#[inline(always)]
fn horizontal_chunk<const L: usize, const FUSED: bool>(
    k: &Kernels,
    padded: &[f32],
    x0: usize,
    h0: &mut [f32],
    h1: &mut [f32],
    h2: &mut [f32],
) {
    let r = k.radius();
    let c: &[f32; L] = padded[x0 + r..x0 + r + L].try_into().unwrap();
    let mut a0 = c.map(|v| k.g[0] * v);
    let mut a2 = c.map(|v| k.d2[0] * v);
    let mut a1 = [0f32; L];
    for t in 1..=r {
        let (g, d1, d2) = (k.g[t], k.d1[t], k.d2[t]);
        let right: &[f32; L] = padded[x0 + r + t..x0 + r + t + L].try_into().unwrap();
        let left: &[f32; L] = padded[x0 + r - t..x0 + r - t + L].try_into().unwrap();
        for i in 0..L {
            let (sum, diff) = (right[i] + left[i], right[i] - left[i]);
            a0[i] = madd::<FUSED>(g, sum, a0[i]);
            a1[i] = madd::<FUSED>(d1, diff, a1[i]);
            a2[i] = madd::<FUSED>(d2, sum, a2[i]);
        }
    }
    // Element-wise stores: `copy_from_slice` here becomes a `memcpy` call per chunk.
    let (h0, h1, h2) = (
        &mut h0[x0..x0 + L],
        &mut h1[x0..x0 + L],
        &mut h2[x0..x0 + L],
    );
    for i in 0..L {
        (h0[i], h1[i], h2[i]) = (a0[i], a1[i], a2[i]);
    }
}

/// Horizontal pass of image row `y`, columns `sx0..sx0 + sw` (one strip), into ring slot `slot`
/// of `s` (whose rows are `sw` long).
#[inline(always)]
fn horizontal_row<const FUSED: bool>(
    image: &GrayImage,
    k: &Kernels,
    y: usize,
    (sx0, sw): (usize, usize),
    slot: usize,
    s: &mut BandScratch,
) {
    let w = image.width();
    let r = k.radius();
    let row = image.row(y);
    // Clamp-to-edge padding: a step edge stays a step up to the border.
    let (lo, hi) = (sx0 as isize - r as isize, (sx0 + sw + r) as isize);
    let (in_lo, in_hi) = (lo.max(0) as usize, hi.min(w as isize) as usize);
    let (left, right) = (
        (in_lo as isize - lo) as usize,
        (hi - in_hi as isize) as usize,
    );
    let padded = &mut s.padded[..sw + 2 * r];
    padded[..left].fill(row[0]);
    padded[left..left + in_hi - in_lo].copy_from_slice(&row[in_lo..in_hi]);
    padded[sw + 2 * r - right..].fill(row[w - 1]);
    let h0 = &mut s.h0[slot * sw..(slot + 1) * sw];
    let h1 = &mut s.h1[slot * sw..(slot + 1) * sw];
    let h2 = &mut s.h2[slot * sw..(slot + 1) * sw];
    let body = sw - sw % LANES;
    for x0 in (0..body).step_by(LANES) {
        horizontal_chunk::<LANES, FUSED>(k, padded, x0, h0, h1, h2);
    }
    for x0 in body..sw {
        horizontal_chunk::<1, FUSED>(k, padded, x0, h0, h1, h2);
    }
}

/// Vertical pass and score over `L` consecutive outputs starting at `x0`, for the row whose
/// horizontal passes sit in ring slots `slots[r]` (centre) and `slots[r ± t]`.
#[inline(always)]
fn vertical_chunk<const L: usize, const FUSED: bool>(
    k: &Kernels,
    s: &BandScratch,
    w: usize,
    slots: &[usize],
    x0: usize,
    out: &mut [f32],
) {
    let r = k.radius();
    let at = |buf: &[f32], slot: usize| -> [f32; L] {
        let o = slot * w + x0;
        buf[o..o + L].try_into().unwrap()
    };
    let c0 = at(&s.h0, slots[r]);
    let c2 = at(&s.h2, slots[r]);
    let mut xx = c2.map(|v| k.g[0] * v);
    let mut yy = c0.map(|v| k.d2[0] * v);
    let mut xy = [0f32; L];
    for t in 1..=r {
        let (g, d1, d2) = (k.g[t], k.d1[t], k.d2[t]);
        let (dn, up) = (slots[r + t], slots[r - t]);
        let (h0d, h0u) = (at(&s.h0, dn), at(&s.h0, up));
        let (h1d, h1u) = (at(&s.h1, dn), at(&s.h1, up));
        let (h2d, h2u) = (at(&s.h2, dn), at(&s.h2, up));
        for i in 0..L {
            xx[i] = madd::<FUSED>(g, h2d[i] + h2u[i], xx[i]);
            yy[i] = madd::<FUSED>(d2, h0d[i] + h0u[i], yy[i]);
            xy[i] = madd::<FUSED>(d1, h1d[i] - h1u[i], xy[i]);
        }
    }
    for i in 0..L {
        out[x0 + i] = madd::<FUSED>(xy[i], xy[i], -xx[i] * yy[i]);
    }
}

/// Score rows `y0..y0 + out.len() / width` into `out` (one band), with the widest vector unit
/// the CPU has (the arithmetic is the same, so results agree to rounding).
fn score_band(image: &GrayImage, k: &Kernels, y0: usize, out: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
        // SAFETY: AVX2 and FMA support were just checked at run time.
        unsafe { score_band_avx2(image, k, y0, out) };
        return;
    }
    score_band_generic::<false>(image, k, y0, out);
}

/// [`score_band_generic`] compiled for AVX2 + FMA (8 `f32` lanes instead of SSE2's 4, fused
/// multiply-adds): about 2.5× faster than the baseline x86-64 build.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn score_band_avx2(image: &GrayImage, k: &Kernels, y0: usize, out: &mut [f32]) {
    score_band_generic::<true>(image, k, y0, out);
}

#[inline(always)]
fn score_band_generic<const FUSED: bool>(
    image: &GrayImage,
    k: &Kernels,
    y0: usize,
    out: &mut [f32],
) {
    let (w, h) = (image.width(), image.height());
    let r = k.radius();
    let ring = 2 * r + 1;
    let strip = STRIP_COLS.min(w);
    let mut s = BandScratch {
        padded: vec![0.0; strip + 2 * r],
        h0: vec![0.0; ring * strip],
        h1: vec![0.0; ring * strip],
        h2: vec![0.0; ring * strip],
    };
    // Logical row j (may lie outside the image: clamped) lives in ring slot j mod (2r+1).
    let slot = |j: isize| (j.rem_euclid(ring as isize)) as usize;
    let clamp_row = |j: isize| j.clamp(0, h as isize - 1) as usize;
    let first = y0 as isize - r as isize;
    let mut slots = vec![0usize; ring];
    for sx0 in (0..w).step_by(strip) {
        let sw = strip.min(w - sx0);
        for j in first..first + 2 * r as isize {
            horizontal_row::<FUSED>(image, k, clamp_row(j), (sx0, sw), slot(j), &mut s);
        }
        let body = sw - sw % LANES;
        for (i, out_row) in out.chunks_exact_mut(w).enumerate() {
            let y = (y0 + i) as isize;
            let newest = y + r as isize;
            horizontal_row::<FUSED>(image, k, clamp_row(newest), (sx0, sw), slot(newest), &mut s);
            for (d, sl) in slots.iter_mut().enumerate() {
                *sl = slot(y - r as isize + d as isize);
            }
            let out_strip = &mut out_row[sx0..sx0 + sw];
            for x0 in (0..body).step_by(LANES) {
                vertical_chunk::<LANES, FUSED>(k, &s, sw, &slots, x0, out_strip);
            }
            for x0 in body..sw {
                vertical_chunk::<1, FUSED>(k, &s, sw, &slots, x0, out_strip);
            }
        }
    }
}

/// The Hessian saddle score `S = Gxy² − Gxx·Gyy = −λ₁λ₂` (paper eq. 2) of every pixel.
///
/// `Gxx`, `Gyy`, `Gxy` are the second derivatives of the image smoothed by a Gaussian of standard
/// deviation `sigma` (pixels), computed by separable correlation with sampled Gaussian-derivative
/// kernels of radius `⌈3σ⌉`, the image border extended by clamping. `S > 0` exactly where the
/// Hessian is indefinite (a saddle, as at a checkerboard corner), `S < 0` on blobs and line
/// crossings, and `S ≈ 0` along straight edges and lines (rank-one Hessian). Units are
/// intensity²/px⁴, so `S` scales with the square of the contrast.
///
/// `sigma` is clamped to [`MIN_SIGMA`]..=[`MAX_SIGMA`] (a NaN becomes 2). Rows are processed in
/// bands in parallel on the rayon pool; each band keeps a ring of `2r+1` horizontally filtered rows,
/// so the work is `O(r)` per pixel and the extra memory is `O(r·width)` per band.
pub fn hessian_score(image: &GrayImage, sigma: f32) -> GrayImage {
    let k = Kernels::new(valid_sigma(sigma));
    let (w, h) = (image.width(), image.height());
    let mut out = vec![0f32; w * h];
    out.par_chunks_mut(BAND_ROWS * w)
        .enumerate()
        .for_each(|(b, band)| score_band(image, &k, b * BAND_ROWS, band));
    GrayImage::from_vec(w, h, out).expect("same size as the input image")
}

/// `sigma` clamped to [`MIN_SIGMA`]..=[`MAX_SIGMA`], a NaN replaced by 2.
fn valid_sigma(sigma: f32) -> f32 {
    if sigma.is_nan() {
        2.0
    } else {
        sigma.clamp(MIN_SIGMA, MAX_SIGMA)
    }
}

/// Moves half-resolution candidates to full resolution: each one, at half-resolution `(X, Y)`,
/// goes to the pixel of largest [`hessian_score`] (same kernels `k`, so the same values to
/// rounding) among `x, y ∈ 2X−3 ..= 2X+4` (centred on the block centre `2X + ½`) inside the
/// `margin`, if that score is positive. Dispatches to AVX2 + FMA like [`score_band`].
fn relocate(image: &GrayImage, k: &Kernels, coarse: &[Candidate], margin: usize) -> Vec<Candidate> {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
        // SAFETY: AVX2 and FMA support were just checked at run time.
        return unsafe { relocate_avx2(image, k, coarse, margin) };
    }
    relocate_generic::<false>(image, k, coarse, margin)
}

/// [`relocate_generic`] compiled for AVX2 + FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn relocate_avx2(
    image: &GrayImage,
    k: &Kernels,
    coarse: &[Candidate],
    margin: usize,
) -> Vec<Candidate> {
    relocate_generic::<true>(image, k, coarse, margin)
}

/// See [`relocate`]: the `8 × 8` window is filtered as one vector-wide strip of `8 + 2r` rows
/// with the inner loops of [`hessian_score`].
#[inline(always)]
fn relocate_generic<const FUSED: bool>(
    image: &GrayImage,
    k: &Kernels,
    coarse: &[Candidate],
    margin: usize,
) -> Vec<Candidate> {
    const SIDE: usize = RELOCATE_SIDE;
    let (w, h, m) = (image.width(), image.height(), margin);
    let mut out = Vec::with_capacity(coarse.len());
    if w <= 2 * m || h <= 2 * m {
        return out;
    }
    let r = k.radius();
    let span = SIDE + 2 * r;
    let mut s = BandScratch {
        padded: vec![0.0; SIDE + 2 * r],
        h0: vec![0.0; span * SIDE],
        h1: vec![0.0; span * SIDE],
        h2: vec![0.0; span * SIDE],
    };
    let slots: Vec<usize> = (0..span).collect();
    let mut scores = [0f32; SIDE];
    for c in coarse {
        // Window origin; the search region is the window clipped to the margin.
        let (wx, wy) = ((2 * c.x).saturating_sub(3), (2 * c.y).saturating_sub(3));
        let (x0, x1) = (wx.max(m), (wx + SIDE).min(w - m));
        let (y0, y1) = (wy.max(m), (wy + SIDE).min(h - m));
        if x0 >= x1 || y0 >= y1 {
            continue;
        }
        let interior = wx >= r && wx + SIDE + r <= w;
        for j in 0..span {
            let row = image.row((wy + j).saturating_sub(r).min(h - 1));
            // Inside the image the row is read in place (a copy here costs a `memcpy` call per
            // row); near the border it is padded by clamping.
            let src = if interior {
                &row[wx - r..wx + SIDE + r]
            } else {
                for (i, p) in s.padded.iter_mut().enumerate() {
                    *p = row[(wx + i).saturating_sub(r).min(w - 1)];
                }
                &s.padded[..]
            };
            let o = j * SIDE;
            horizontal_chunk::<SIDE, FUSED>(
                k,
                src,
                0,
                &mut s.h0[o..o + SIDE],
                &mut s.h1[o..o + SIDE],
                &mut s.h2[o..o + SIDE],
            );
        }
        let mut best: Option<Candidate> = None;
        for y in y0..y1 {
            let j = y - wy;
            vertical_chunk::<SIDE, FUSED>(k, &s, SIDE, &slots[j..j + 2 * r + 1], 0, &mut scores);
            for x in x0..x1 {
                let v = scores[x - wx];
                if v > best.map_or(0.0, |b| b.score) {
                    best = Some(Candidate { x, y, score: v });
                }
            }
        }
        out.extend(best);
    }
    out
}

/// `image` averaged over `stride × stride` blocks, the incomplete last row and column of blocks
/// dropped: pixel `(X, Y)` of the result has its centre at `(s·X + (s−1)/2, s·Y + (s−1)/2)` in
/// `image`. `None` when `stride` is 0 or larger than the image.
pub fn box_downsample(image: &GrayImage, stride: usize) -> Option<GrayImage> {
    if stride == 0 {
        return None;
    }
    let (w, h) = (image.width() / stride, image.height() / stride);
    let mut out = vec![0f32; w * h];
    let norm = 1.0 / (stride * stride) as f32;
    if stride == 2 {
        // The common case straight from the two rows: no intermediate row to write and re-read.
        for (y, dst) in out.chunks_exact_mut(w.max(1)).enumerate() {
            let (a, b) = (image.row(2 * y), image.row(2 * y + 1));
            for ((d, pa), pb) in dst.iter_mut().zip(a.chunks_exact(2)).zip(b.chunks_exact(2)) {
                *d = ((pa[0] + pa[1]) + (pb[0] + pb[1])) * norm;
            }
        }
        return GrayImage::from_vec(w, h, out).ok();
    }
    // Rows are summed element-wise first (vectorizable), then each run of `stride` columns.
    let mut acc = vec![0f32; w * stride];
    for (y, dst) in out.chunks_exact_mut(w.max(1)).enumerate() {
        acc.fill(0.0);
        for r in 0..stride {
            for (a, &v) in acc.iter_mut().zip(&image.row(y * stride + r)[..w * stride]) {
                *a += v;
            }
        }
        for (d, run) in dst.iter_mut().zip(acc.chunks_exact(stride)) {
            *d = run.iter().sum::<f32>() * norm;
        }
    }
    GrayImage::from_vec(w, h, out).ok()
}

/// A corner candidate: an integer pixel and its Hessian score [`hessian_score`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Candidate {
    /// Column of the pixel (its centre is at image x = `x`).
    pub x: usize,
    /// Row of the pixel (its centre is at image y = `y`).
    pub y: usize,
    /// Saddle score `S` at the pixel (> 0).
    pub score: f32,
}

/// Parameters of [`prefilter`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PrefilterParams {
    /// Gaussian scale of the Hessian, pixels. The default 2 px responds well to corners whose
    /// squares are ≥ 12 px wide (the score of a corner peaks for σ a fraction of the square size
    /// and the neighbouring corners start to interfere for σ above ~⅙ of it) and to optical blur up
    /// to ~3 px; raise it for very blurred or very large boards.
    pub sigma: f32,
    /// `n_nms` (paper: 3): a candidate must be the maximum of the score in the
    /// `(2·n_nms+1)²` window around it, so two candidates are more than `n_nms` pixels apart
    /// (Chebyshev distance) unless they tie.
    pub nms_radius: usize,
    /// `τ_nms` (paper: 2). The paper calls it "the dimension of the non-maximum suppression"
    /// without further detail; in the conservative block NMS it cites (Neubeck & Van Gool, as used
    /// by Geiger et al.) the extra parameters are a score threshold and a border margin. Scores
    /// here have no absolute scale (they go with contrast²), so the threshold is the adaptive rule
    /// ([`PrefilterParams::min_score_rel`]) and `nms_tau` is the **border margin**: pixels closer
    /// than `nms_tau` to the image border are never candidates (their score is distorted by the
    /// clamped border).
    pub nms_tau: usize,
    /// Number of corners expected in the image, if known. Then, as in the paper, the `2·N`
    /// strongest candidates are kept and `min_score_rel` is ignored.
    pub expected_corners: Option<usize>,
    /// Adaptive cut used when `expected_corners` is `None`: keep candidates whose score is at least
    /// this fraction of the reference score, the median of the 16 strongest candidates (a typical
    /// strong corner when a board is present). The score goes with contrast², so the default 0.01
    /// keeps corners down to 1/10 of the contrast of the strong ones.
    pub min_score_rel: f32,
    /// Hard cap on the number of candidates returned (the strongest are kept), whatever the rule.
    pub max_candidates: usize,
    /// Find the candidates on the image averaged over 2 × 2 blocks, then place each at the best
    /// full-resolution pixel near it (see [`prefilter`]): about 5× faster, and the same corners,
    /// as long as `sigma ≥` [`MIN_HALF_RESOLUTION_SIGMA`] (below it the full-resolution score is
    /// used whatever this says).
    pub half_resolution: bool,
}

impl Default for PrefilterParams {
    fn default() -> Self {
        Self {
            sigma: 2.0,
            nms_radius: 3,
            nms_tau: 2,
            expected_corners: None,
            min_score_rel: 0.05,
            max_candidates: 20_000,
            half_resolution: true,
        }
    }
}

/// The maximum of every `(n+1)²` block of the score inside the border margin, the tiling of
/// [`non_maximum_suppression`]: a candidate can only be a block maximum, so the suppression and
/// the selection of [`prefilter`] look at these (one per `(n+1)²` pixels) instead of every pixel.
struct BlockMaxima<'a> {
    score: &'a [f32],
    /// Image width (row stride of `score`).
    w: usize,
    n: usize,
    margin: usize,
    x_end: usize,
    y_end: usize,
    /// Blocks per row.
    cols: usize,
    /// Maximum of each block, row-major over the blocks; `−∞` when the block holds only NaN.
    vals: Vec<f32>,
}

impl<'a> BlockMaxima<'a> {
    /// `None` when the image is too small for the margin (or too large to index with `u32`).
    fn new(score: &'a GrayImage, n: usize, margin: usize) -> Option<Self> {
        let (w, h) = (score.width(), score.height());
        if w <= 2 * margin || h <= 2 * margin || w.checked_mul(h)? > u32::MAX as usize {
            return None;
        }
        let (x_end, y_end) = (w - margin, h - margin);
        let step = n + 1;
        let (cols, rows) = (
            (x_end - margin).div_ceil(step),
            (y_end - margin).div_ceil(step),
        );
        let data = score.data();
        let mut vals = vec![f32::NEG_INFINITY; cols * rows];
        // Column maxima of one block row first (a vectorizable element-wise max, NaN ignored as
        // by `>`), then the block maxima from them; positions are found only when needed.
        let mut colmax = vec![f32::NEG_INFINITY; x_end - margin];
        for (br, by) in (margin..y_end).step_by(step).enumerate() {
            let by1 = (by + step).min(y_end);
            colmax.fill(f32::NEG_INFINITY);
            for y in by..by1 {
                for (m, &v) in colmax.iter_mut().zip(&data[y * w + margin..y * w + x_end]) {
                    *m = m.max(v);
                }
            }
            for (val, chunk) in vals[br * cols..(br + 1) * cols]
                .iter_mut()
                .zip(colmax.chunks(step))
            {
                *val = chunk.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b));
            }
        }
        Some(Self {
            score: data,
            w,
            n,
            margin,
            x_end,
            y_end,
            cols,
            vals,
        })
    }

    /// Pixel index (`y·w + x`) of the first maximum of block `b` (positive) in row-major order.
    fn locate(&self, b: usize) -> (usize, usize) {
        let (w, step) = (self.w, self.n + 1);
        let bx = self.margin + (b % self.cols) * step;
        let by = self.margin + (b / self.cols) * step;
        let (bx1, by1) = ((bx + step).min(self.x_end), (by + step).min(self.y_end));
        let v = self.vals[b];
        (by..by1)
            .find_map(|y| {
                let row = &self.score[y * w + bx..y * w + bx1];
                row.iter().position(|&s| s == v).map(|i| (bx + i, y))
            })
            .unwrap_or((bx, by))
    }

    /// Whether the maximum of block `b` (positive), at `(mx, my)`, is not beaten: no pixel of its
    /// `(2n+1)²` neighbourhood (clipped to the margin) outside the block is strictly larger. Only
    /// neighbouring blocks whose maximum exceeds it can hold such a pixel; when that maximum (at
    /// `pos(block)`) lies inside the window the answer is immediate, otherwise the block's part of
    /// the window is scanned.
    fn survives(
        &self,
        b: usize,
        (mx, my): (usize, usize),
        pos: impl Fn(usize) -> (usize, usize),
    ) -> bool {
        let (w, n, step, m) = (self.w, self.n, self.n + 1, self.margin);
        let v = self.vals[b];
        let (x0, x1) = (mx.saturating_sub(n).max(m), (mx + n + 1).min(self.x_end));
        let (y0, y1) = (my.saturating_sub(n).max(m), (my + n + 1).min(self.y_end));
        for br in (y0 - m) / step..=(y1 - 1 - m) / step {
            for bc in (x0 - m) / step..=(x1 - 1 - m) / step {
                let nb = br * self.cols + bc;
                if nb == b || self.vals[nb] <= v {
                    continue;
                }
                let (qx, qy) = pos(nb);
                if (x0..x1).contains(&qx) && (y0..y1).contains(&qy) {
                    return false;
                }
                let (bx, by) = (m + bc * step, m + br * step);
                let (cx0, cx1) = (bx.max(x0), (bx + step).min(x1));
                let (cy0, cy1) = (by.max(y0), (by + step).min(y1));
                if (cy0..cy1).any(|y| self.score[y * w + cx0..y * w + cx1].iter().any(|&s| s > v)) {
                    return false;
                }
            }
        }
        true
    }

    /// The candidate at the maximum of block `b` (positive) at `p`, if it survives.
    fn candidate(
        &self,
        b: usize,
        p: (usize, usize),
        pos: impl Fn(usize) -> (usize, usize),
    ) -> Option<Candidate> {
        self.survives(b, p, pos).then_some(Candidate {
            x: p.0,
            y: p.1,
            score: self.vals[b],
        })
    }
}

/// Positive local maxima of `score` by block non-maximum suppression (Neubeck & Van Gool): the
/// image is tiled in `(n+1)²` blocks, the maximum of each block is found (the first in row-major
/// order on a tie), then accepted if no pixel of its `(2n+1)²` neighbourhood outside the block is
/// strictly larger. Ties are kept ("conservative"), so a plateau can yield several candidates.
/// Pixels within `margin` of the border are ignored. Candidates come in row-major block order.
pub fn non_maximum_suppression(score: &GrayImage, n: usize, margin: usize) -> Vec<Candidate> {
    let Some(blocks) = BlockMaxima::new(score, n, margin) else {
        return Vec::new();
    };
    // Every positive block is checked here, and most are a neighbour of several: locate once.
    let pos: Vec<(u32, u32)> = (0..blocks.vals.len())
        .map(|b| {
            let (x, y) = if blocks.vals[b] > 0.0 {
                blocks.locate(b)
            } else {
                (0, 0)
            };
            (x as u32, y as u32)
        })
        .collect();
    let at = |b: usize| (pos[b].0 as usize, pos[b].1 as usize);
    (0..blocks.vals.len())
        .filter(|&b| blocks.vals[b] > 0.0)
        .filter_map(|b| blocks.candidate(b, at(b), at))
        .collect()
}

/// Visits the positive block maxima in decreasing score order (ties: row-major block order) until
/// `visit` returns `false`, sorting lazily: the next few strongest are selected and sorted in
/// geometrically growing rounds, so stopping after the first hundreds costs a linear selection
/// rather than a full sort. `floor` (updated by `visit`) lets later rounds drop weaker blocks
/// before selecting.
fn visit_descending(
    vals: &[f32],
    first_round: usize,
    mut visit: impl FnMut(usize, &mut f32) -> bool,
) {
    let mut order: Vec<u32> = (0..vals.len() as u32)
        .filter(|&b| vals[b as usize] > 0.0)
        .collect();
    let cmp = |a: &u32, b: &u32| {
        vals[*b as usize]
            .total_cmp(&vals[*a as usize])
            .then(a.cmp(b))
    };
    let mut floor = 0.0f32;
    let mut round = first_round.max(1);
    while !order.is_empty() {
        if floor > 0.0 {
            order.retain(|&b| vals[b as usize] >= floor);
        }
        let take = round.min(order.len());
        if take < order.len() {
            order.select_nth_unstable_by(take - 1, cmp);
        }
        order[..take].sort_unstable_by(cmp);
        for &b in &order[..take] {
            if !visit(b as usize, &mut floor) {
                return;
            }
        }
        order.drain(..take);
        round = round.saturating_mul(4);
    }
}

/// Corner candidates of `image`, strongest first (equal scores in row-major block order):
/// [`hessian_score`] at `params.sigma`, then [`non_maximum_suppression`], then the cut.
///
/// The cut keeps the `2N` strongest when `params.expected_corners = Some(N)` (paper III-A).
/// Otherwise it is adaptive, so that the user need not know `N`: with `S_ref` the median score of
/// the 16 strongest candidates, candidates with `S ≥ min_score_rel · S_ref` are kept. Noise and
/// texture give many weak saddles and straight edges give none, so on a board image this keeps
/// all corners and a few hundred distractors at most, which the template election rejects.
/// At most `params.max_candidates` are returned. An image too small for the margin gives none.
///
/// The result is that of sorting the whole suppression output, but only the block maxima that
/// can make the cut are checked: they are visited strongest first, and the visit stops once the
/// count is reached or the scores fall below the adaptive threshold.
///
/// With [`PrefilterParams::half_resolution`] (the default) and `sigma ≥`
/// [`MIN_HALF_RESOLUTION_SIGMA`], all of this runs on the image averaged over 2 × 2 blocks at the
/// equivalent scale, and each candidate is then moved to the best full-resolution pixel within
/// 3–4 px of its block: positions and scores are full-resolution ones, a quarter of the pixels
/// are filtered with kernels half as long. Two candidates may then be closer than `nms_radius`
/// (they come from different blocks); the election merges such duplicates.
pub fn prefilter(image: &GrayImage, params: &PrefilterParams) -> Vec<Candidate> {
    prefilter_scales(&Scales::new(image), params)
}

/// [`prefilter`] of `scales.image()`, its 2 × 2 average taken from (and left in) `scales`.
pub fn prefilter_scales(scales: &Scales, params: &PrefilterParams) -> Vec<Candidate> {
    let (image, sigma) = (scales.image(), valid_sigma(params.sigma));
    if params.half_resolution && sigma >= MIN_HALF_RESOLUTION_SIGMA {
        if let Some(half) = scales.downsampled(2).filter(|h| h.width() * h.height() > 0) {
            return prefilter_half_resolution(image, &half, sigma, params);
        }
    }
    select_from_score(&hessian_score(image, sigma), params)
}

/// An image and its 2 × 2 box average ([`box_downsample`] at stride 2), the average computed on
/// first use and then kept: the pre-filter works on it, and so does the election's coarse pass
/// when its stride is 2. On a large image the average is memory-bound (it reads the whole
/// image) and cost the speed benchmark's 1920 × 1200 board about a tenth of `detect`'s time when
/// it was computed twice.
pub struct Scales<'a> {
    image: &'a GrayImage,
    half: OnceLock<Option<GrayImage>>,
}

impl<'a> Scales<'a> {
    /// `image`, its average not computed yet.
    pub fn new(image: &'a GrayImage) -> Self {
        Self {
            image,
            half: OnceLock::new(),
        }
    }

    /// The full-resolution image.
    pub fn image(&self) -> &'a GrayImage {
        self.image
    }

    /// [`box_downsample`] of the image at `stride`; the stride-2 average is computed once.
    pub fn downsampled(&self, stride: usize) -> Option<Cow<'_, GrayImage>> {
        if stride == 2 {
            let half = self.half.get_or_init(|| box_downsample(self.image, 2));
            half.as_ref().map(Cow::Borrowed)
        } else {
            box_downsample(self.image, stride).map(Cow::Owned)
        }
    }
}

/// The half-resolution path of [`prefilter`] ([`PrefilterParams::half_resolution`]).
///
/// The 2 × 2 average is a blur of variance ¼ px² followed by sampling every 2 px, so the Hessian
/// score of `half` at scale `σ_h = √(σ² − ¼)/2` (half-resolution pixels) is, up to a constant
/// factor, the full-resolution score at `σ` sampled at the block centres. The suppression works
/// on half the distances (radius and margin rounded up) and the cut is the same rule. Each
/// survivor at half-resolution `(X, Y)` is then placed at the pixel of largest full-resolution
/// score among `x, y ∈ 2X−3 ..= 2X+4` (the true peak is within a pixel or two of the block centre
/// `2X + ½`), inside the margin ([`relocate`]); candidates landing on the same pixel are merged. Scores are the
/// full-resolution ones, order is decreasing score (ties: row-major).
fn prefilter_half_resolution(
    image: &GrayImage,
    half: &GrayImage,
    sigma: f32,
    params: &PrefilterParams,
) -> Vec<Candidate> {
    let sigma_half = ((sigma * sigma - 0.25).sqrt() * 0.5).max(MIN_SIGMA);
    let half_params = PrefilterParams {
        nms_radius: params.nms_radius.div_ceil(2),
        nms_tau: params.nms_tau.div_ceil(2),
        ..*params
    };
    let mut coarse = select_from_score(&hessian_score(half, sigma_half), &half_params);
    // Row-major order: the windows of successive candidates then share image rows and pages.
    coarse.sort_unstable_by_key(|c| (c.y, c.x));
    let mut out = relocate(image, &Kernels::new(sigma), &coarse, params.nms_tau);
    out.sort_unstable_by_key(|c| (c.y, c.x));
    out.dedup_by(|a, b| (a.x, a.y) == (b.x, b.y));
    out.sort_by(|a, b| {
        b.score
            .total_cmp(&a.score)
            .then((a.y, a.x).cmp(&(b.y, b.x)))
    });
    out
}

/// The suppression and cut of [`prefilter`] applied to a score image.
fn select_from_score(score: &GrayImage, params: &PrefilterParams) -> Vec<Candidate> {
    let Some(blocks) = BlockMaxima::new(score, params.nms_radius, params.nms_tau) else {
        return Vec::new();
    };
    let rel = if params.min_score_rel.is_finite() {
        params.min_score_rel.max(0.0)
    } else {
        0.0
    };
    let cap = params.max_candidates;
    let wanted = params
        .expected_corners
        .map(|n| n.saturating_mul(2).min(cap));
    let mut cands: Vec<Candidate> = Vec::new();
    // Adaptive threshold, known once the reference candidates are found.
    let mut threshold: Option<f32> = None;
    let first_round = 4 * wanted
        .unwrap_or(REFERENCE_COUNT)
        .clamp(REFERENCE_COUNT, 4096);
    visit_descending(&blocks.vals, first_round, |b, floor| {
        let v = blocks.vals[b];
        match (wanted, threshold) {
            (Some(k), _) if cands.len() >= k => return false,
            (None, Some(t)) if v < t || cands.len() >= cap => return false,
            _ => {}
        }
        if let Some(c) = blocks.candidate(b, blocks.locate(b), |nb| blocks.locate(nb)) {
            cands.push(c);
            if wanted.is_none() && cands.len() == REFERENCE_COUNT {
                let t = rel * cands[REFERENCE_COUNT / 2].score;
                threshold = Some(t);
                *floor = t;
            }
        }
        true
    });
    let keep = match wanted {
        Some(k) => k,
        None => {
            let refs = &cands[..cands.len().min(REFERENCE_COUNT)];
            let reference = refs.get(refs.len() / 2).map_or(0.0, |c| c.score);
            let t = threshold.unwrap_or(rel * reference);
            cands.partition_point(|c| c.score >= t)
        }
    };
    cands.truncate(keep.min(cap));
    cands
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Correlation with the full two-sided kernels, the slow obvious way.
    fn apply(v: &[f32], k: &[f32], odd: bool, x: usize) -> f32 {
        let r = k.len() as isize - 1;
        let mut s = 0.0;
        for t in -r..=r {
            let xi = (x as isize + t).clamp(0, v.len() as isize - 1) as usize;
            let kk = k[t.unsigned_abs()];
            s += if odd && t < 0 { -kk } else { kk } * v[xi];
        }
        s
    }

    #[test]
    fn kernels_differentiate_polynomials_exactly() {
        for sigma in [0.5f32, 1.0, 2.0, 3.7] {
            let k = Kernels::new(sigma);
            let v: Vec<f32> = (0..80).map(|x| x as f32).collect();
            let v2: Vec<f32> = (0..80).map(|x| 0.01 * (x as f32 - 37.0).powi(2)).collect();
            let ones = vec![5.0f32; 80];
            assert!((apply(&ones, &k.g, false, 40) - 5.0).abs() < 1e-4);
            assert!((apply(&v, &k.d1, true, 40) - 1.0).abs() < 1e-4);
            assert!(apply(&ones, &k.d2, false, 40).abs() < 1e-4);
            assert!((apply(&v2, &k.d2, false, 40) - 0.02).abs() < 1e-5);
        }
    }

    #[test]
    fn score_of_a_quadratic_saddle_is_its_determinant() {
        // I = a x² + b xy + c y²: Gxx = 2a, Gyy = 2c, Gxy = b, S = b² − 4ac everywhere
        // away from the border.
        let (a, b, c) = (0.3f32, 0.5, -0.2);
        let (w, h) = (60, 50);
        let data = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32 - 30.0, (i / w) as f32 - 25.0);
                a * x * x + b * x * y + c * y * y
            })
            .collect();
        let img = GrayImage::from_vec(w, h, data).unwrap();
        let s = hessian_score(&img, 2.0);
        let want = b * b - 4.0 * a * c;
        for (x, y) in [(30, 25), (10, 10), (45, 38)] {
            assert!((s.get(x, y) - want).abs() < 1e-3 * want, "{}", s.get(x, y));
        }
    }

    #[test]
    fn straight_edges_score_nothing_and_blobs_score_negative() {
        let (w, h) = (64, 64);
        let mut data = vec![0f32; w * h];
        for y in 0..h {
            for x in 0..w {
                // an oblique straight edge on the left half, a disc on the right half
                let edge = (x as f32 * 0.6 + y as f32 * 0.8) > 30.0 && x < 28;
                let disc = (x as f32 - 46.0).powi(2) + (y as f32 - 32.0).powi(2) < 25.0;
                data[y * w + x] = if edge || disc { 200.0 } else { 20.0 };
            }
        }
        let img = GrayImage::from_vec(w, h, data).unwrap();
        let s = hessian_score(&img, 2.0);
        assert!(s.get(46, 32) < 0.0);
        // On an edge away from its ends the Hessian is rank one up to pixelization.
        let on_edge = s.get(12, 28).abs();
        let saddle_scale = 10.0 * 180.0f32.powi(2) / (2.0f32.powi(4) * 100.0);
        assert!(on_edge < 0.05 * saddle_scale, "{on_edge}");
    }

    #[test]
    fn parallel_bands_match_a_single_band() {
        let (w, h) = (37, 150);
        let data = (0..w * h)
            .map(|i| ((i * 7919) % 251) as f32)
            .collect::<Vec<_>>();
        let img = GrayImage::from_vec(w, h, data).unwrap();
        let banded = hessian_score(&img, 1.5);
        let k = Kernels::new(1.5);
        let mut single = vec![0f32; w * h];
        score_band(&img, &k, 0, &mut single);
        assert_eq!(banded.data(), &single[..]);
    }

    #[test]
    fn strips_match_a_direct_separable_correlation() {
        // Wider than two strips, the last one narrower than the kernel radius.
        let (w, h) = (2 * STRIP_COLS + 3, 23);
        let data: Vec<f32> = (0..w * h).map(|i| ((i * 7919) % 251) as f32).collect();
        let img = GrayImage::from_vec(w, h, data.clone()).unwrap();
        for sigma in [1.0f32, 3.0] {
            let k = Kernels::new(sigma);
            let s = hessian_score(&img, sigma);
            // Horizontal passes, then vertical passes on their columns, all with clamping.
            let pass = |src: &[f32], kern: &[f32], odd: bool| -> Vec<f32> {
                (0..w * h)
                    .map(|i| apply(&src[i / w * w..(i / w + 1) * w], kern, odd, i % w))
                    .collect()
            };
            let vert = |src: &[f32], kern: &[f32], odd: bool, x: usize, y: usize| -> f32 {
                let col: Vec<f32> = (0..h).map(|yy| src[yy * w + x]).collect();
                apply(&col, kern, odd, y)
            };
            let (hg, hd1, hd2) = (
                pass(&data, &k.g, false),
                pass(&data, &k.d1, true),
                pass(&data, &k.d2, false),
            );
            for y in [0, 5, h - 1] {
                for x in [0, 1, STRIP_COLS - 1, STRIP_COLS, 2 * STRIP_COLS + 1, w - 1] {
                    let gxx = vert(&hd2, &k.g, false, x, y);
                    let gyy = vert(&hg, &k.d2, false, x, y);
                    let gxy = vert(&hd1, &k.d1, true, x, y);
                    let want = gxy * gxy - gxx * gyy;
                    let scale = gxx.abs().max(gyy.abs()).max(gxy.abs()).powi(2).max(1.0);
                    assert!(
                        (s.get(x, y) - want).abs() < 1e-4 * scale,
                        "{x} {y} {} {want}",
                        s.get(x, y)
                    );
                }
            }
        }
    }

    #[test]
    fn tiny_and_degenerate_inputs_do_not_panic() {
        let one = GrayImage::filled(1, 1, 3.0).unwrap();
        assert!(hessian_score(&one, 2.0).get(0, 0).abs() < 1e-9);
        let thin = GrayImage::from_vec(5, 2, (0..10).map(|v| v as f32).collect()).unwrap();
        for sigma in [f32::NAN, -1.0, 0.0, 1e9] {
            let s = hessian_score(&thin, sigma);
            assert!(s.data().iter().all(|v| v.is_finite()));
        }
        assert!(prefilter(&one, &PrefilterParams::default()).is_empty());
        let flat = GrayImage::filled(40, 40, 7.0).unwrap();
        assert!(prefilter(&flat, &PrefilterParams::default()).is_empty());
        let p = PrefilterParams {
            min_score_rel: f32::NAN,
            expected_corners: Some(usize::MAX),
            ..Default::default()
        };
        assert!(prefilter(&flat, &p).is_empty());
    }

    #[test]
    fn nms_keeps_isolated_maxima_and_respects_radius_and_margin() {
        let (w, h) = (30, 30);
        let mut data = vec![0f32; w * h];
        let peaks = [
            (5, 5, 3.0),
            (7, 6, 2.0),
            (20, 8, 1.0),
            (1, 15, 9.0),
            (15, 25, 4.0),
        ];
        for &(x, y, v) in &peaks {
            data[y * w + x] = v;
        }
        let img = GrayImage::from_vec(w, h, data).unwrap();
        let mut got: Vec<_> = non_maximum_suppression(&img, 3, 2)
            .into_iter()
            .map(|c| (c.x, c.y))
            .collect();
        got.sort_unstable();
        // (7, 6) is within 3 px of the stronger (5, 5); (1, 15) is inside the margin.
        assert_eq!(got, vec![(5, 5), (15, 25), (20, 8)]);
    }

    /// The block suppression pixel by pixel, as first written: the reference for the fast path.
    fn reference_nms(score: &GrayImage, n: usize, margin: usize) -> Vec<Candidate> {
        let (w, h) = (score.width(), score.height());
        let mut out = Vec::new();
        if w <= 2 * margin || h <= 2 * margin {
            return out;
        }
        let (x_end, y_end) = (w - margin, h - margin);
        let step = n + 1;
        for by in (margin..y_end).step_by(step) {
            for bx in (margin..x_end).step_by(step) {
                let (bx1, by1) = ((bx + step).min(x_end), (by + step).min(y_end));
                let (mut mx, mut my, mut mv) = (bx, by, f32::NEG_INFINITY);
                for y in by..by1 {
                    for x in bx..bx1 {
                        if score.get(x, y) > mv {
                            (mx, my, mv) = (x, y, score.get(x, y));
                        }
                    }
                }
                if mv.is_nan() || mv <= 0.0 {
                    continue;
                }
                let in_block =
                    |x: usize, y: usize| (bx..bx1).contains(&x) && (by..by1).contains(&y);
                let beaten = (my.saturating_sub(n).max(margin)..(my + n + 1).min(y_end)).any(|y| {
                    (mx.saturating_sub(n).max(margin)..(mx + n + 1).min(x_end))
                        .any(|x| score.get(x, y) > mv && !in_block(x, y))
                });
                if !beaten {
                    out.push(Candidate {
                        x: mx,
                        y: my,
                        score: mv,
                    });
                }
            }
        }
        out
    }

    /// [`prefilter`]'s selection done the obvious way: suppress everywhere, stable sort, cut.
    fn reference_select(score: &GrayImage, p: &PrefilterParams) -> Vec<Candidate> {
        let mut cands = reference_nms(score, p.nms_radius, p.nms_tau);
        cands.sort_by(|a, b| b.score.total_cmp(&a.score));
        let keep = match p.expected_corners {
            Some(n) => n.saturating_mul(2),
            None => {
                let refs = &cands[..cands.len().min(REFERENCE_COUNT)];
                let reference = refs.get(refs.len() / 2).map_or(0.0, |c| c.score);
                let rel = if p.min_score_rel.is_finite() {
                    p.min_score_rel.max(0.0)
                } else {
                    0.0
                };
                cands.partition_point(|c| c.score >= rel * reference)
            }
        };
        cands.truncate(keep.min(p.max_candidates));
        cands
    }

    /// A rotated checkerboard with noise: the score image of a real-like scene.
    fn board_like(w: usize, h: usize, seed: u64) -> GrayImage {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let (angle, square) = (rng.gen_range(0.0..1.5f32), rng.gen_range(9.0..20.0f32));
        let (c, s) = (angle.cos(), angle.sin());
        let data = (0..w * h)
            .map(|i| {
                let (x, y) = (
                    (i % w) as f32 - w as f32 / 2.0,
                    (i / w) as f32 - h as f32 / 2.0,
                );
                let (u, v) = ((c * x + s * y) / square, (-s * x + c * y) / square);
                let inside = u.abs() < 4.0 && v.abs() < 3.0;
                let dark = inside && (u.floor() as i32 + v.floor() as i32) % 2 == 0;
                (if dark { 30.0 } else { 220.0 }) + rng.gen_range(-8.0..8.0)
            })
            .collect();
        GrayImage::from_vec(w, h, data).unwrap()
    }

    /// Selection from a score image through the fast path (the part of [`prefilter`] after the
    /// Hessian), for comparison with [`reference_select`].
    fn fast_select(score: &GrayImage, p: &PrefilterParams) -> Vec<Candidate> {
        select_from_score(score, p)
    }

    fn all_params() -> Vec<PrefilterParams> {
        let d = PrefilterParams::default();
        let mut v = vec![d];
        for n in [1, 2, 3, 5] {
            for tau in [0, 2, 7] {
                v.push(PrefilterParams {
                    nms_radius: n,
                    nms_tau: tau,
                    ..d
                });
            }
        }
        for rel in [0.0, 0.01, 0.3, 1.0, 2.0, f32::NAN] {
            v.push(PrefilterParams {
                min_score_rel: rel,
                ..d
            });
        }
        for cap in [0, 1, 5, 15, 16, 17, 40] {
            v.push(PrefilterParams {
                max_candidates: cap,
                ..d
            });
            v.push(PrefilterParams {
                max_candidates: cap,
                min_score_rel: 0.0,
                ..d
            });
        }
        for n in [0, 1, 7, 40, 100_000, usize::MAX] {
            v.push(PrefilterParams {
                expected_corners: Some(n),
                ..d
            });
        }
        v
    }

    /// The fast suppression and selection equal the reference ones for every parameter set.
    fn assert_matches_reference(score: &GrayImage) {
        for p in all_params() {
            let (n, tau) = (p.nms_radius, p.nms_tau);
            assert_eq!(
                non_maximum_suppression(score, n, tau),
                reference_nms(score, n, tau)
            );
            assert_eq!(fast_select(score, &p), reference_select(score, &p), "{p:?}");
        }
    }

    #[test]
    fn fast_nms_and_selection_match_the_reference_on_board_like_scores() {
        for seed in 0..4 {
            let score = hessian_score(&board_like(173, 131, seed), 2.0);
            assert_matches_reference(&score);
        }
    }

    #[test]
    fn fast_nms_and_selection_match_the_reference_with_ties_and_nan() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for _ in 0..40 {
            let (w, h) = (rng.gen_range(1..60), rng.gen_range(1..60));
            // Few distinct levels: plateaus and tied maxima everywhere; some NaN and negatives.
            let data = (0..w * h)
                .map(|_| match rng.gen_range(0..20) {
                    0 => f32::NAN,
                    1 => f32::INFINITY,
                    k => (k as f32 - 6.0).max(-1.0) * 0.5,
                })
                .collect();
            let score = GrayImage::from_vec(w, h, data).unwrap();
            assert_matches_reference(&score);
        }
    }

    #[test]
    fn box_downsample_averages_whole_blocks() {
        let img = GrayImage::from_vec(5, 3, (0..15).map(|v| v as f32).collect()).unwrap();
        let half = box_downsample(&img, 2).unwrap();
        assert_eq!((half.width(), half.height()), (2, 1));
        // Blocks {0, 1, 5, 6} and {2, 3, 7, 8}; the last column and row are dropped.
        assert_eq!(half.data(), &[3.0, 5.0]);
        let third = box_downsample(&img, 3).unwrap();
        assert_eq!(third.data(), &[6.0]);
        assert_eq!(box_downsample(&img, 1).unwrap(), img);
        assert!(box_downsample(&img, 0).is_none());
        assert!(box_downsample(&img, 4).is_none());
    }

    #[test]
    fn scales_keep_one_half_resolution_average() {
        let img = board_like(61, 47, 4);
        let scales = Scales::new(&img);
        let (a, b) = (
            scales.downsampled(2).unwrap(),
            scales.downsampled(2).unwrap(),
        );
        assert!(
            std::ptr::eq(&*a, &*b),
            "the stride-2 average is computed once"
        );
        assert_eq!(*a, box_downsample(&img, 2).unwrap());
        assert_eq!(
            *scales.downsampled(3).unwrap(),
            box_downsample(&img, 3).unwrap()
        );
        assert!(scales.downsampled(0).is_none() && scales.downsampled(62).is_none());
        let params = PrefilterParams::default();
        assert_eq!(prefilter_scales(&scales, &params), prefilter(&img, &params));
    }

    #[test]
    fn relocation_picks_the_full_resolution_maximum_of_its_window() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for (seed, sigma) in [(0u64, 2.0f32), (1, 1.5), (2, 3.0)] {
            let image = board_like(97, 83, seed);
            let full = hessian_score(&image, sigma);
            let k = Kernels::new(sigma);
            // Half-resolution positions everywhere, the borders included.
            let coarse: Vec<Candidate> = (0..300)
                .map(|_| Candidate {
                    x: rng.gen_range(0..48),
                    y: rng.gen_range(0..41),
                    score: 1.0,
                })
                .collect();
            for margin in [0, 2, 5] {
                let got = relocate(&image, &k, &coarse, margin);
                let want: Vec<Candidate> = coarse
                    .iter()
                    .filter_map(|c| {
                        let (wx, wy) = ((2 * c.x).saturating_sub(3), (2 * c.y).saturating_sub(3));
                        let mut best: Option<Candidate> = None;
                        for y in wy.max(margin)..(wy + 8).min(83 - margin) {
                            for x in wx.max(margin)..(wx + 8).min(97 - margin) {
                                let v = full.get(x, y);
                                if v > best.map_or(0.0, |b| b.score) {
                                    best = Some(Candidate { x, y, score: v });
                                }
                            }
                        }
                        best
                    })
                    .collect();
                assert_eq!(got, want, "seed {seed} margin {margin}");
            }
        }
    }

    #[test]
    fn half_resolution_finds_the_corners_of_the_full_resolution_score() {
        for seed in 0..8 {
            // Squares of 9 to 20 px: down to 4.5 px at half resolution.
            let image = board_like(200, 150, 20 + seed);
            let full_p = PrefilterParams {
                half_resolution: false,
                ..Default::default()
            };
            let full = prefilter(&image, &full_p);
            let half = prefilter(&image, &PrefilterParams::default());
            assert!(half.windows(2).all(|p| p[0].score >= p[1].score));
            let strong = 0.25 * full[full.len().min(16) / 2].score;
            for f in full.iter().filter(|f| f.score >= strong) {
                assert!(
                    half.iter()
                        .any(|h| (h.x, h.y) == (f.x, f.y) && h.score == f.score),
                    "seed {seed}: {f:?} not found at half resolution"
                );
            }
        }
        // Below the smallest scale the full-resolution path is taken.
        let image = board_like(120, 90, 5);
        let p = PrefilterParams {
            sigma: 1.0,
            ..Default::default()
        };
        let full = PrefilterParams {
            half_resolution: false,
            ..p
        };
        assert_eq!(prefilter(&image, &p), prefilter(&image, &full));
    }

    #[test]
    fn half_resolution_survives_tiny_images() {
        for (w, h) in [(1, 1), (2, 2), (3, 3), (2, 50), (50, 2), (9, 4), (17, 17)] {
            let data = (0..w * h).map(|i| ((i * 7919) % 251) as f32).collect();
            let image = GrayImage::from_vec(w, h, data).unwrap();
            for tau in [0, 2, 10] {
                let p = PrefilterParams {
                    nms_tau: tau,
                    min_score_rel: 0.0,
                    ..Default::default()
                };
                for c in prefilter(&image, &p) {
                    assert!(c.x >= tau && c.y >= tau && c.x + tau < w && c.y + tau < h);
                    assert!(c.score > 0.0);
                }
            }
        }
    }

    #[test]
    fn prefilter_is_the_selection_of_the_hessian_score() {
        let image = board_like(200, 150, 11);
        let p = PrefilterParams {
            half_resolution: false,
            ..Default::default()
        };
        let got = prefilter(&image, &p);
        assert_eq!(got, reference_select(&hessian_score(&image, p.sigma), &p));
        // A 8×6 board has 7×5 inner corners; all of them must be there.
        assert!(got.len() >= 35, "{}", got.len());
    }
}
