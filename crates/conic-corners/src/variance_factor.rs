//! The a-posteriori variance factor of a board's corner covariances: how far the corners stray
//! from a smooth grid, against the covariances they claim.
//!
//! Every corner's covariance comes from the scatter of its edge samples about their curves. Errors
//! that whole edges share (a print's wobble, JPEG blocks, a texture that a curve's fit absorbs) do
//! not show in that scatter, and on real photos the corners stray about three times as far as they
//! claim (OpenCV's stereo photos, measured against a camera calibration). The grid itself shows
//! them: along a straight grid line, the position of each corner is set by the crossing curve
//! through it, a different edge for every corner, and the positions of consecutive corners follow a
//! smooth law (a 1-D homography for a straight line in space, bent a little by lens distortion).
//! So, as a least-squares adjustment estimates its variance of unit weight from its redundancy,
//! [`variance_factor`] fits such a law (`run_chi2`) to the along-line positions of every run of
//! six consecutive corners on a straight stretch of a row or a column, weighted by the corners'
//! along-line variances, and takes the median of the fits' χ² (two degrees of freedom for six
//! corners) over its median for honest covariances, `2 ln 2`. Each corner's covariance is then
//! scaled by that factor ([`crate::detect::Board::sigma_scale`] is its square root). No corner
//! moves.
//!
//! Measured at `6d6ad23` plus this module (`detect` on the views of `board-accuracy --pairs 12`;
//! per-axis share of the error components within their own σ, 68.3 % for honest ones): the
//! renders' σ scale is 0.57–1.80 per view and the share goes 73.9 → 70.5 % (mean squared
//! Mahalanobis distance 1.66 → 2.06, honest 2); at twice the resolution (`--resolution-scale 2`,
//! 6 pairs) 79.3 → 68.9 % (1.37 → 2.23). On OpenCV's stereo photos the scale is a median 2.6, and
//! the covariance scale that `bench/stereo_calib.py` measures against a camera calibration goes
//! 3.06 → 1.34 (board mode) and 2.2 → 1.23 (local). On the curved photos it is 1.7–2.6, and 8–12
//! on the three `marker_real` photos, whose corners stray from every smooth law by 0.4–0.55 px
//! along their lines (squares of 160–190 px; laws of five and six parameters over seven and eight
//! corners leave as much).

use std::collections::HashMap;

use crate::detect::{Cov, DetectedCorner};
use crate::segmentation::median_in_place;
use crate::spacing::{along, chord, LawFit, LAW_POINTS};

/// Consecutive corners in a run: a cubic fitted to six leaves two degrees of freedom, whose χ²
/// has the median [`MEDIAN_CHI2_2`]. Five would leave one, with a median of 0.45 that a few
/// lucky runs pull down; seven need boards of seven corners a side.
const RUN: usize = LAW_POINTS;

/// Median of a χ² variable with two degrees of freedom, `2 ln 2`.
const MEDIAN_CHI2_2: f64 = 2.0 * std::f64::consts::LN_2;

/// Parameters of [`variance_factor`].
#[derive(Clone, Debug, PartialEq)]
pub struct VarianceFactorParams {
    /// A run counts only if no corner lies farther (px) than this from the chord line through it
    /// (the total-least-squares line). Along a bent line the spacing follows neither law (a row
    /// round a cylinder foreshortens fast near a silhouette): with 1 px instead of 0.3, and the
    /// cubic law alone, the renders' scaled σ put 77 % of the error components within their own
    /// σ instead of 73 %.
    pub straightness: f64,
    /// Fewer runs than this give no factor (the covariances stay as the fits gave them).
    pub min_windows: usize,
}

impl Default for VarianceFactorParams {
    fn default() -> Self {
        Self {
            straightness: 0.3,
            min_windows: 8,
        }
    }
}

/// The estimate of [`variance_factor`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VarianceFactor {
    /// Square root of the variance factor: the factor on every σ.
    pub sigma_scale: f64,
    /// Runs of corners that entered the median.
    pub windows: usize,
}

/// Offset of run position `i` from the run's middle: the laws' variable.
fn centred(i: usize) -> f64 {
    i as f64 - 0.5 * (RUN - 1) as f64
}

/// χ² of one run `p[i]` (image coordinates) with covariances `c[i]`, `i = 0..RUN`: the
/// along-chord positions' residuals from the better of the two smooth laws of
/// [`crate::spacing`] in the run position (each has four parameters, two degrees of freedom on
/// six corners), over their along-chord variances. Taking the better of two is biased low a
/// little where both hold; on the curved-board benchmark's renders the scaled covariances then
/// put 70.5 % of the error components within their own σ (a cubic alone: 73.3 %, the homography
/// alone 76.3 %, where 68.3 % is honest). `None` where the run is not straight within
/// `straightness` px or a variance is not positive.
fn run_chi2(p: &[[f64; 2]; RUN], c: &[Cov; RUN], straightness: f64) -> Option<f64> {
    let (origin, t) = chord(p, straightness)?;
    let mut s = [0.0; RUN];
    let mut w = [0.0; RUN];
    for (i, (q, cov)) in p.iter().zip(c).enumerate() {
        let v = along(cov, t);
        if !(v > 0.0 && v.is_finite()) {
            return None;
        }
        s[i] = t[0] * (q[0] - origin[0]) + t[1] * (q[1] - origin[1]);
        w[i] = 1.0 / v;
    }
    Some(LawFit::best(&std::array::from_fn(centred), &s, &w)?.chi2)
}

/// The a-posteriori variance factor of `corners` (one board, labelled): the median χ² of the
/// weighted fits (`run_chi2`) to the along-line positions of every straight run of six consecutive
/// corners on a row or a column (all with a covariance), over `2 ln 2`, its median for honest
/// covariances. `None` with fewer than `params.min_windows` runs (a small or strongly bent board)
/// or a zero median (exact synthetic positions).
pub fn variance_factor(
    corners: &[DetectedCorner],
    params: &VarianceFactorParams,
) -> Option<VarianceFactor> {
    let at: HashMap<(i32, i32), usize> = corners
        .iter()
        .enumerate()
        .filter(|(_, c)| c.cov.is_some())
        .map(|(i, c)| ((c.row, c.col), i))
        .collect();
    let mut chi2 = Vec::new();
    for c in corners.iter().filter(|c| c.cov.is_some()) {
        for (dr, dc) in [(0, 1), (1, 0)] {
            let mut p = [[0.0; 2]; RUN];
            let mut cov = [[[0.0; 2]; 2]; RUN];
            let complete = (0..RUN).all(|k| {
                let key = (c.row + dr * k as i32, c.col + dc * k as i32);
                at.get(&key).is_some_and(|&j| {
                    p[k] = [corners[j].x, corners[j].y];
                    cov[k] = corners[j].cov.unwrap_or_default();
                    true
                })
            });
            if let Some(x) = complete
                .then(|| run_chi2(&p, &cov, params.straightness))
                .flatten()
            {
                chi2.push(x);
            }
        }
    }
    if chi2.len() < params.min_windows.max(1) {
        return None;
    }
    let n = chi2.len();
    let median = median_in_place(&mut chi2);
    let sigma_scale = (median / MEDIAN_CHI2_2).sqrt();
    (sigma_scale > 0.0 && sigma_scale.is_finite()).then_some(VarianceFactor {
        sigma_scale,
        windows: n,
    })
}

/// Scales the σ and covariance of every corner by `sigma_scale` (σ) and its square (covariance).
pub fn apply(corners: &mut [DetectedCorner], sigma_scale: f64) {
    let v = sigma_scale * sigma_scale;
    for c in corners {
        c.sigma = c.sigma.map(|s| s * sigma_scale);
        c.cov = c.cov.map(|m| m.map(|r| r.map(|x| x * v)));
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::board_fit::Path;
    use crate::refine::Status;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    /// A `rows × cols` grid seen in perspective (a homography) with a barrel distortion, its
    /// corners moved by isotropic noise of `noise` px and claiming σ `claimed` px.
    pub(crate) fn grid(
        rows: i32,
        cols: i32,
        noise: f64,
        claimed: f64,
        seed: u64,
    ) -> Vec<DetectedCorner> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let n = Normal::new(0.0, noise.max(1e-300)).unwrap();
        let mut out = Vec::new();
        for row in 0..rows {
            for col in 0..cols {
                let (u, v) = (col as f64 * 40.0, row as f64 * 40.0);
                let w = 1.0 + 0.0004 * u + 0.0002 * v;
                let (x, y) = ((300.0 + 1.1 * u + 0.2 * v) / w, (200.0 + 0.1 * u + v) / w);
                let (dx, dy) = (x - 640.0, y - 480.0);
                let k = 1.0 - 1e-8 * (dx * dx + dy * dy);
                let e = if noise > 0.0 {
                    [n.sample(&mut rng), n.sample(&mut rng)]
                } else {
                    [0.0, 0.0]
                };
                out.push(DetectedCorner {
                    x: 640.0 + k * dx + e[0],
                    y: 480.0 + k * dy + e[1],
                    row,
                    col,
                    score: 1.0,
                    status: Status::Converged,
                    residual: Some(0.01),
                    path: Path::Board,
                    sigma: Some(claimed),
                    cov: Some([[claimed * claimed, 0.0], [0.0, claimed * claimed]]),
                });
            }
        }
        out
    }

    #[test]
    fn the_factor_recovers_how_far_the_claimed_sigma_is_off() {
        let params = VarianceFactorParams::default();
        for (claimed, truth) in [(0.01, 1.0), (0.01 / 3.0, 3.0), (0.03, 1.0 / 3.0)] {
            let mut scales = Vec::new();
            for seed in 0..20 {
                let f = variance_factor(&grid(9, 12, 0.01, claimed, seed), &params).unwrap();
                assert!(f.windows >= 100, "{f:?}");
                scales.push(f.sigma_scale);
            }
            let mean = scales.iter().sum::<f64>() / scales.len() as f64;
            assert!(
                (mean / truth - 1.0).abs() < 0.1,
                "claimed {claimed}: {scales:?}"
            );
            // One board's estimate, from ~150 overlapping runs, is within a quarter.
            assert!(
                scales.iter().all(|s| (s / truth - 1.0).abs() < 0.25),
                "{scales:?}"
            );
        }
    }

    #[test]
    fn a_straight_run_in_strong_perspective_has_no_chi2() {
        // Squares of 150 px shrinking by a fifth per square, claiming σ 0.01 px: the homography
        // law holds (the cubic alone would not, see `crate::spacing`'s tests).
        let s: [f64; RUN] = std::array::from_fn(|i| 150.0 * i as f64 / (1.0 + 0.2 * i as f64));
        assert!(run_chi2(
            &std::array::from_fn(|i| [s[i], 0.5 * s[i]]),
            &[[[1e-4, 0.0], [0.0, 1e-4]]; RUN],
            0.3
        )
        .is_some_and(|x| x < 1e-9));
    }

    #[test]
    fn scaling_is_the_square_root_on_sigma_and_the_factor_on_the_covariance() {
        let mut g = grid(6, 6, 0.01, 0.01, 1);
        apply(&mut g, 3.0);
        assert!((g[0].sigma.unwrap() - 0.03).abs() < 1e-12);
        assert!((g[0].cov.unwrap()[1][1] - 9e-4).abs() < 1e-12);
    }

    #[test]
    fn small_bent_or_exact_boards_give_no_factor() {
        let params = VarianceFactorParams::default();
        // 5 × 5 corners: no run of six.
        assert_eq!(variance_factor(&grid(5, 5, 0.01, 0.01, 2), &params), None);
        // Exact positions: what is left is the cubic's model error over six corners of a grid in
        // strong perspective and distortion, a small fraction of a σ of 0.01 px.
        let exact = variance_factor(&grid(9, 12, 0.0, 0.01, 2), &params);
        assert!(exact.map_or(true, |f| f.sigma_scale < 0.1), "{exact:?}");
        // Rows bent into arcs of radius 300 px and columns too short for a run: no straight run.
        let mut bent = Vec::new();
        for row in 0..4 {
            for col in 0..12 {
                let a = col as f64 * 0.12;
                let r = 300.0 + 40.0 * row as f64;
                let mut c = grid(1, 1, 0.0, 0.01, 0)[0];
                (c.x, c.y, c.row, c.col) = (r * a.sin(), -r * a.cos(), row, col);
                bent.push(c);
            }
        }
        assert_eq!(variance_factor(&bent, &params), None);
        // Corners with no covariance do not count.
        let mut bare = grid(9, 12, 0.01, 0.01, 3);
        for c in &mut bare {
            c.cov = None;
        }
        assert_eq!(variance_factor(&bare, &params), None);
    }
}
