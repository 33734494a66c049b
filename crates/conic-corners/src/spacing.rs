//! The spacing law along straight grid lines: each corner's position along its line, predicted
//! from the six corners around it, fused with the corner's own estimate.
//!
//! Along a grid line that is straight in space (every line of a flat board, the rulings of a
//! board bent round a cylinder, an elliptic column or an S), the print's corners are evenly
//! spaced, and their images follow a smooth law in the corner's index `u`: a 1-D homography
//! `(a + b u) / (1 + c u)` for a pinhole camera, bent a little by lens distortion. Two laws of
//! four parameters cover that (`Law::Cubic`, the distortion's shape, and `Law::Homography`,
//! `(a + b u + e u²) / (1 + c u)`, strong perspective over large squares). A corner's position
//! along the line is set by the *crossing* curve through it, a different edge for every corner,
//! so its neighbours' positions are independent evidence about it: where the crossing curve is
//! short or extrapolated (foreshortened squares next to a silhouette, the board's outer corners)
//! they know more than the corner does.
//!
//! [`fuse_along_lines`], for every corner and each of its two lines: the run of seven consecutive
//! corners around it (the most centred one that the board holds) must be straight (no corner
//! farther than [`SpacingParams::straightness`] from the run's chord line); the better-fitting law
//! through the six others, weighted by their along-chord variances, predicts the corner's
//! along-chord position `ŝ` with variance `v̂ = φᵀ (JᵀWJ)⁻¹ φ + σ_m²` (`σ_m`, the laws' model
//! error, [`SpacingParams::model_sigma`]). The prediction is a measurement of the corner along
//! the chord's unit tangent `t`, fused by the Kalman update
//! `K = C t / (tᵀ C t + v̂)`, `x ← x + K (ŝ − tᵀ x)`, `C ← C − K tᵀ C`,
//! the row's prediction and the column's in turn (both from the corners as they were: they are
//! independent of each other and of the corner). It is the least-squares position of the corner
//! under the law, with the corner itself among the data.
//!
//! A line can look straight in the image and not be straight in space (a row round a cylinder
//! seen from the plane of its circle): its corners' spacing follows neither law. So the fusion
//! takes a *family* of lines (the rows, or the columns) only where the median χ² of its runs'
//! fits (two degrees of freedom) is below [`SpacingParams::family_chi2`]; a single prediction is
//! skipped where its own fit's χ² is above [`SpacingParams::fit_chi2`] (an outlier among the
//! six) or where it disagrees with the corner by more than [`SpacingParams::gate`] (χ² of one
//! degree of freedom). A corner less sure than [`SpacingParams::max_sigma`] is fused only where
//! its run holds sure corners on both sides of it (the law interpolates).
//!
//! Measured on the curved-board benchmark's renders (`board-accuracy --pairs 12`, board mode,
//! against the same run without it): RMSE flattest curvature bin 0.0060 → 0.0052 px, top bin
//! 0.0131 → 0.0087 px (top over flattest 2.17 → 1.67), all corners 0.0064 → 0.0055 px, stereo
//! reprojection 0.0035 → 0.0029 px; per-axis errors within the reported σ 75.5 → 74.0 %. A
//! prototype gave the same to 10⁻⁴ px for a model σ of 0.002–0.005 px. See BENCHMARKS.md.
//!
//! Coordinates: x right, y down, the centre of the top-left pixel is `(0, 0)`.

use std::collections::HashMap;

use nalgebra::{Matrix2, Matrix4, Vector2, Vector4};

use crate::detect::{Cov, DetectedCorner};
use crate::quadratic_form::{fit_line_tls, worst_sigma};
use crate::segmentation::median_in_place;

/// Corners a law is fitted to: four parameters leave two degrees of freedom.
pub(crate) const LAW_POINTS: usize = 6;

/// Corners of a run in [`fuse_along_lines`]: the corner and the six others.
const RUN: usize = LAW_POINTS + 1;

/// Parameters of [`fuse_along_lines`].
#[derive(Clone, Debug, PartialEq)]
pub struct SpacingParams {
    /// A run counts only if no corner lies farther (px) than this from its chord line (the
    /// total-least-squares line through the seven).
    pub straightness: f64,
    /// A family of lines (rows, or columns) is used only if the median χ² of its runs' law fits
    /// is at most this. Honest covariances give a median of `2 ln 2 ≈ 1.39`; on the benchmark's
    /// renders the rulings and flat boards' lines gave 0.5–4.6, and image-straight rows round a
    /// cylinder 9 to 10⁴.
    pub family_chi2: f64,
    /// A prediction whose own fit leaves a χ² above this (two degrees of freedom: 13.8 is the
    /// 99.9 % point) is not used: one of the six is an outlier.
    pub fit_chi2: f64,
    /// A prediction that differs from the corner by more than this (squared difference over the
    /// sum of the two variances) is not used.
    pub gate: f64,
    /// The laws' model error σ_m (px) added to every prediction's variance.
    pub model_sigma: f64,
    /// A corner is one of the six a law is fitted to only if its σ along the chord is at most
    /// this (px), and it is fused with an extrapolated law's prediction (no run corner beyond
    /// it) only if so. Larger σ come from curves that meet at a glancing angle or from
    /// fallbacks, where the covariance, a linearisation, is no guide to the error: next to a
    /// cylinder's silhouette such a law, extrapolated one square, moved a corner 2.7 px; and a
    /// corner that claims σ 1.9 px (0.55 px off, beside the slivers of a 60 mm cylinder) was
    /// moved 1.87 px off by a law extrapolated over the sliver corners beside it, which are no
    /// better placed than it. Between sure corners the law holds whatever the corner claims
    /// (the curved-board benchmark's seed 3000, pair 17 left, (3, 0): σ 0.11 px, 0.07 px off).
    pub max_sigma: f64,
}

impl Default for SpacingParams {
    fn default() -> Self {
        Self {
            straightness: 0.3,
            family_chi2: 6.0,
            fit_chi2: 13.8,
            gate: 9.0,
            model_sigma: 0.003,
            max_sigma: 0.1,
        }
    }
}

/// The smooth laws of evenly spaced points on a straight line in space, seen through a camera.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Law {
    /// `a + b u + e u² + d u³`: where lens distortion dominates.
    Cubic,
    /// `(a + b u + e u²) / (1 + c u)`: a 1-D homography (exact for `e = 0`) with one more term
    /// for lens distortion. A cubic misses strong perspective over large squares: on 9 × 9
    /// boards of 90–140 px squares in random poses, the true positions of a run left χ² of 5–27
    /// at the 0.01–0.02 px that those corners claim.
    Homography,
}

/// A law fitted to [`LAW_POINTS`] positions.
#[derive(Clone, Copy, Debug)]
pub(crate) struct LawFit {
    law: Law,
    p: Vector4<f64>,
    /// Inverse of the weighted normal matrix at the solution.
    cov: Matrix4<f64>,
    /// Weighted squared residuals.
    pub chi2: f64,
}

/// Smallest `1 + c u` at a fitted point or a prediction: the homography's pole stays clear.
const MIN_DENOMINATOR: f64 = 0.2;

impl LawFit {
    /// The law's value at `u` and its gradient in the parameters; `None` near the pole.
    fn eval(law: Law, p: &Vector4<f64>, u: f64) -> Option<(f64, Vector4<f64>)> {
        match law {
            Law::Cubic => Some((
                p[0] + u * (p[1] + u * (p[2] + u * p[3])),
                Vector4::new(1.0, u, u * u, u * u * u),
            )),
            Law::Homography => {
                let d = 1.0 + p[3] * u;
                if d < MIN_DENOMINATOR {
                    return None;
                }
                let f = (p[0] + u * (p[1] + u * p[2])) / d;
                Some((f, Vector4::new(1.0 / d, u / d, u * u / d, -u * f / d)))
            }
        }
    }

    /// Weighted least-squares fit of `law` to the positions `s` at `u` (weights `w`, the inverse
    /// variances): linear for the cubic; for the homography solved linearly in `s (1 + c u)` and
    /// refined by six Gauss–Newton steps. `None` where the normal equations are singular or the
    /// pole comes near the points.
    pub(crate) fn fit(
        law: Law,
        u: &[f64; LAW_POINTS],
        s: &[f64; LAW_POINTS],
        w: &[f64; LAW_POINTS],
    ) -> Option<Self> {
        let normal = |rows: &[Vector4<f64>; LAW_POINTS], values: &[f64; LAW_POINTS]| {
            let (mut ata, mut atb) = (Matrix4::<f64>::zeros(), Vector4::<f64>::zeros());
            for ((r, v), w) in rows.iter().zip(values).zip(w) {
                ata += *w * r * r.transpose();
                atb += *w * *v * r;
            }
            let ch = ata.cholesky()?;
            Some((ch.solve(&atb), ch.inverse()))
        };
        let mut p = match law {
            Law::Cubic => Vector4::zeros(),
            Law::Homography => {
                let linear =
                    std::array::from_fn(|i| Vector4::new(1.0, u[i], u[i] * u[i], -u[i] * s[i]));
                normal(&linear, s)?.0
            }
        };
        let steps = if law == Law::Cubic { 1 } else { 6 };
        let mut cov = Matrix4::zeros();
        for _ in 0..steps {
            let mut rows = [Vector4::zeros(); LAW_POINTS];
            let mut r = [0.0; LAW_POINTS];
            for i in 0..LAW_POINTS {
                let (f, g) = Self::eval(law, &p, u[i])?;
                rows[i] = g;
                r[i] = s[i] - f;
            }
            let (dp, c) = normal(&rows, &r)?;
            p += dp;
            cov = c;
        }
        let mut chi2 = 0.0;
        for i in 0..LAW_POINTS {
            chi2 += w[i] * (s[i] - Self::eval(law, &p, u[i])?.0).powi(2);
        }
        chi2.is_finite().then_some(Self { law, p, cov, chi2 })
    }

    /// The law's value at `u` and its variance from the fit; `None` near the pole.
    pub(crate) fn predict(&self, u: f64) -> Option<(f64, f64)> {
        let (f, g) = Self::eval(self.law, &self.p, u)?;
        Some((f, (g.transpose() * self.cov * g)[0]))
    }

    /// The better-fitting (smaller χ²) of the two laws; `None` if neither fits.
    pub(crate) fn best(
        u: &[f64; LAW_POINTS],
        s: &[f64; LAW_POINTS],
        w: &[f64; LAW_POINTS],
    ) -> Option<Self> {
        [Law::Cubic, Law::Homography]
            .into_iter()
            .filter_map(|law| Self::fit(law, u, s, w))
            .min_by(|a, b| a.chi2.total_cmp(&b.chi2))
    }
}

/// The chord of `points`: a point on it and its unit tangent, if every point lies within
/// `straightness` px of the total-least-squares line.
pub(crate) fn chord(points: &[[f64; 2]], straightness: f64) -> Option<([f64; 2], [f64; 2])> {
    let [a, b, c] = fit_line_tls(points, None)?.coefficients();
    if points
        .iter()
        .any(|q| (a * q[0] + b * q[1] + c).abs() > straightness)
    {
        return None;
    }
    // The foot of the origin on the line: the laws' constant terms absorb the origin anyway.
    Some(([-a * c, -b * c], [-b, a]))
}

/// Variance of `cov` along the unit vector `t`.
pub(crate) fn along(cov: &Cov, t: [f64; 2]) -> f64 {
    t[0] * t[0] * cov[0][0] + 2.0 * t[0] * t[1] * cov[0][1] + t[1] * t[1] * cov[1][1]
}

/// A prediction of one corner's position along a unit direction.
#[derive(Clone, Copy, Debug)]
struct Prediction {
    corner: usize,
    /// Unit tangent of the run's chord.
    t: [f64; 2],
    /// Predicted `tᵀ x` and its variance (the model error included).
    value: f64,
    variance: f64,
    /// χ² of the law's fit to the six others.
    chi2: f64,
    /// Whether the run holds corners on both sides of this one (the law interpolates).
    inside: bool,
}

/// The predictions along one family of lines (`step` from a corner to the next on its line):
/// for every corner with a covariance whose straight run of seven the board holds.
fn family(
    corners: &[DetectedCorner],
    at: &HashMap<(i32, i32), usize>,
    step: (i32, i32),
    params: &SpacingParams,
) -> Vec<Prediction> {
    let mut out = Vec::new();
    for (i, c) in corners.iter().enumerate() {
        if !at.contains_key(&(c.row, c.col)) {
            continue;
        }
        let member = |k: i32| at.get(&(c.row + step.0 * k, c.col + step.1 * k)).copied();
        // The most centred complete run: starts tried from the middle outwards.
        let half = (RUN / 2) as i32;
        let Some(start) = [0, 1, -1, 2, -2, 3, -3]
            .into_iter()
            .map(|d| d - half)
            .find(|&s| (s..s + RUN as i32).all(|k| member(k).is_some()))
        else {
            continue;
        };
        let run: [usize; RUN] = std::array::from_fn(|k| member(start + k as i32).unwrap_or(i));
        let points = run.map(|j| [corners[j].x, corners[j].y]);
        let Some((origin, t)) = chord(&points, params.straightness) else {
            continue;
        };
        let mut u = [0.0; LAW_POINTS];
        let mut s = [0.0; LAW_POINTS];
        let mut w = [0.0; LAW_POINTS];
        let mut n = 0;
        for (k, &j) in run.iter().enumerate() {
            if j == i {
                continue;
            }
            let v = corners[j].cov.map_or(f64::NAN, |m| along(&m, t));
            if !(v > 0.0 && v <= params.max_sigma * params.max_sigma) {
                break;
            }
            // Run positions about the run's middle keep the laws' parameters well scaled.
            u[n] = k as f64 - half as f64;
            s[n] = t[0] * (points[k][0] - origin[0]) + t[1] * (points[k][1] - origin[1]);
            w[n] = 1.0 / v;
            n += 1;
        }
        if n < LAW_POINTS {
            continue;
        }
        let u0 = -(start + half) as f64;
        let Some(fit) = LawFit::best(&u, &s, &w) else {
            continue;
        };
        if let Some((value, variance)) = fit.predict(u0) {
            let offset = t[0] * origin[0] + t[1] * origin[1];
            out.push(Prediction {
                corner: i,
                t,
                value: value + offset,
                variance: variance + params.model_sigma * params.model_sigma,
                chi2: fit.chi2,
                inside: u0.abs() < half as f64,
            });
        }
    }
    out
}

/// Fuses every corner of one labelled board (those with a covariance) with its row's and its
/// column's spacing-law predictions (see the module docs), updating position, covariance and σ.
/// Returns how many predictions were fused. Corners without a covariance are left as they are
/// and predict nothing.
pub fn fuse_along_lines(corners: &mut [DetectedCorner], params: &SpacingParams) -> usize {
    let at: HashMap<(i32, i32), usize> = corners
        .iter()
        .enumerate()
        .filter(|(_, c)| c.cov.is_some() && c.x.is_finite() && c.y.is_finite())
        .map(|(i, c)| ((c.row, c.col), i))
        .collect();
    let mut taken = Vec::new();
    for step in [(0, 1), (1, 0)] {
        let predictions = family(corners, &at, step, params);
        let mut chi2: Vec<f64> = predictions.iter().map(|p| p.chi2).collect();
        if chi2.is_empty() || median_in_place(&mut chi2) > params.family_chi2 {
            continue;
        }
        taken.extend(
            predictions
                .into_iter()
                .filter(|p| p.chi2 <= params.fit_chi2),
        );
    }
    let mut fused = 0;
    for p in taken {
        let c = &mut corners[p.corner];
        let Some(cov) = c.cov else { continue };
        let m = Matrix2::new(cov[0][0], cov[0][1], cov[1][0], cov[1][1]);
        let t = Vector2::new(p.t[0], p.t[1]);
        let own = t.dot(&Vector2::new(c.x, c.y));
        let v = (t.transpose() * m * t)[0];
        let innovation = p.value - own;
        if v.is_nan()
            || v <= 0.0
            || (v > params.max_sigma * params.max_sigma && !p.inside)
            || innovation * innovation > params.gate * (v + p.variance)
        {
            continue;
        }
        let k = m * t / (v + p.variance);
        let updated = m - k * (t.transpose() * m);
        let updated = 0.5 * (updated + updated.transpose());
        let new_cov = [
            [updated[(0, 0)], updated[(0, 1)]],
            [updated[(1, 0)], updated[(1, 1)]],
        ];
        if !(new_cov[0][0] > 0.0 && new_cov[1][1] > 0.0) {
            continue;
        }
        c.x += k[0] * innovation;
        c.y += k[1] * innovation;
        c.cov = Some(new_cov);
        c.sigma = Some(worst_sigma(new_cov));
        fused += 1;
    }
    fused
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::variance_factor::tests::grid;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    const U: [f64; LAW_POINTS] = [-3.0, -2.0, -1.0, 1.0, 2.0, 3.0];

    #[test]
    fn each_law_follows_its_geometry_and_predicts_the_missing_point() {
        let w = [1e4; LAW_POINTS];
        // Strong perspective: squares of 150 px shrinking by a fifth per square.
        let persp = |u: f64| 150.0 * u / (1.0 + 0.2 * u);
        let s = U.map(persp);
        let h = LawFit::fit(Law::Homography, &U, &s, &w).unwrap();
        assert!(h.chi2 < 1e-9, "{h:?}");
        let (value, variance) = h.predict(0.0).unwrap();
        assert!((value - persp(0.0)).abs() < 1e-6, "{value}");
        // Six points of σ 0.01 px predict the seventh to about that.
        assert!(variance > 0.0 && variance < 1e-4, "{variance}");
        let cubic = LawFit::fit(Law::Cubic, &U, &s, &w).unwrap();
        assert!(cubic.chi2 > 10.0, "{cubic:?}");
        assert_eq!(LawFit::best(&U, &s, &w).unwrap().law, Law::Homography);
        // A barrel distortion's along-line displacement, cubic in the position: the cubic holds.
        let barrel = |u: f64| {
            let x = 100.0 * u - 50.0;
            x * (1.0 - 4e-7 * x * x)
        };
        let c = LawFit::fit(Law::Cubic, &U, &U.map(barrel), &w).unwrap();
        assert!(c.chi2 < 1e-9);
        assert!((c.predict(0.0).unwrap().0 - barrel(0.0)).abs() < 1e-9);
        // No law through a point at the homography's pole.
        assert!(LawFit::fit(Law::Homography, &U, &U.map(|u| 1.0 / (1.0 + 0.4 * u)), &w).is_none());
    }

    /// RMS position error of `corners` against the exact grid, over one column.
    fn column_rms(corners: &[DetectedCorner], exact: &[DetectedCorner], col: i32) -> f64 {
        let e: Vec<f64> = corners
            .iter()
            .zip(exact)
            .filter(|(c, _)| c.col == col)
            .map(|(c, t)| (c.x - t.x).powi(2) + (c.y - t.y).powi(2))
            .collect();
        (e.iter().sum::<f64>() / e.len() as f64).sqrt()
    }

    #[test]
    fn a_poorly_placed_column_is_pulled_onto_its_rows_laws_with_an_honest_sigma() {
        // A 9 × 12 grid in perspective and distortion. Column 1's own curve is poorly measured
        // (short, extrapolated next to a silhouette), so its corners are poor across the column,
        // along the rows (σ 0.02 px in x); the rest are good (σ 0.003 px). Every corner's error
        // is drawn from its covariance.
        let exact = grid(9, 12, 0.0, 0.003, 0);
        let mut errors = (Vec::new(), Vec::new());
        let mut within = 0;
        let mut count = 0;
        for seed in 0..20 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let unit = Normal::new(0.0, 1.0).unwrap();
            let mut noisy = exact.clone();
            for (c, t) in noisy.iter_mut().zip(&exact) {
                let across = if c.col == 1 { 0.02 } else { 0.003 };
                c.x = t.x + across * unit.sample(&mut rng);
                c.y = t.y + 0.003 * unit.sample(&mut rng);
                c.cov = Some([[across * across, 0.0], [0.0, 0.003f64.powi(2)]]);
                c.sigma = Some(across);
            }
            let before = column_rms(&noisy, &exact, 1);
            assert!(fuse_along_lines(&mut noisy, &SpacingParams::default()) > 100);
            errors.0.push(before);
            errors.1.push(column_rms(&noisy, &exact, 1));
            for (c, t) in noisy.iter().zip(&exact).filter(|(c, _)| c.col == 1) {
                let cov = c.cov.unwrap();
                within += usize::from((c.x - t.x).abs() <= cov[0][0].sqrt());
                count += 1;
            }
        }
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        // Each row's six good neighbours place the column's corner far better than its own σ.
        assert!(mean(&errors.1) < 0.4 * mean(&errors.0), "{errors:?}");
        // The fused σ across the column is honest: about 68 % of the errors within it.
        let share = within as f64 / count as f64;
        assert!((0.55..0.85).contains(&share), "{share}");
    }

    #[test]
    fn an_unsure_corner_takes_the_law_between_its_neighbours_but_not_beyond_them() {
        // A 7 × 9 grid (the curved-board benchmark's boards). Two corners claim σ 0.15 px and
        // are 0.3 px off along their columns: (3, 0) has three sure corners on either side along
        // its column, (6, 8) is the end of its column and of its row.
        let exact = grid(7, 9, 0.0, 0.003, 0);
        let mut corners = exact.clone();
        let at = |r, c| exact.iter().position(|k| (k.row, k.col) == (r, c)).unwrap();
        let (inside, end) = (at(3, 0), at(6, 8));
        for &k in &[inside, end] {
            corners[k].y += 0.3;
            corners[k].cov = Some([[0.0225, 0.0], [0.0, 0.0225]]);
            corners[k].sigma = Some(0.15);
        }
        fuse_along_lines(&mut corners, &SpacingParams::default());
        // The column's direction at (3, 0).
        let (a, b) = (&exact[at(2, 0)], &exact[at(4, 0)]);
        let t = {
            let (dx, dy) = (b.x - a.x, b.y - a.y);
            let n = dx.hypot(dy);
            [dx / n, dy / n]
        };
        let offset =
            |k: usize| t[0] * (corners[k].x - exact[k].x) + t[1] * (corners[k].y - exact[k].y);
        // The law of its six sure neighbours places the inner one along its column (0.29 px of
        // the 0.3 px offset lie along it; the row, ending at it, is not used), and its variance
        // along the column says so.
        assert!(offset(inside).abs() < 0.005, "{}", offset(inside));
        let cov = corners[inside].cov.unwrap();
        assert!(along(&cov, t) < 0.01 * 0.01, "{cov:?}");
        // A law extrapolated past the last sure corner knows no better than the corner itself.
        assert_eq!(
            (corners[end].x, corners[end].y),
            (exact[end].x, exact[end].y + 0.3)
        );
    }

    #[test]
    fn image_straight_lines_whose_spacing_follows_no_law_are_left_alone() {
        // Rows round a cylinder seen from the plane of their circles: straight in the image, the
        // corners at R sin θ, foreshortened towards the silhouette. Columns are too short for a
        // run, so nothing is fused.
        let mut corners = grid(4, 12, 0.0, 0.003, 0);
        for c in &mut corners {
            c.x = 600.0 * (0.15 * c.col as f64 - 0.8).sin();
            c.y = 50.0 * c.row as f64;
        }
        let before = corners.clone();
        assert_eq!(fuse_along_lines(&mut corners, &SpacingParams::default()), 0);
        assert_eq!(corners, before);
    }

    #[test]
    fn an_outlier_moves_neither_itself_nor_its_neighbours() {
        let exact = grid(9, 12, 0.0, 0.003, 0);
        let mut corners = exact.clone();
        let k = corners
            .iter()
            .position(|c| (c.row, c.col) == (4, 5))
            .unwrap();
        corners[k].x += 0.5;
        // A corner without a covariance predicts nothing and is not moved.
        let bare = corners
            .iter()
            .position(|c| (c.row, c.col) == (2, 9))
            .unwrap();
        corners[bare].cov = None;
        corners[bare].y += 0.2;
        fuse_along_lines(&mut corners, &SpacingParams::default());
        assert!((corners[k].x - exact[k].x - 0.5).abs() < 1e-9);
        assert_eq!(corners[bare].y, exact[bare].y + 0.2);
        for (i, (c, t)) in corners.iter().zip(&exact).enumerate() {
            if i != k && i != bare {
                assert!((c.x - t.x).hypot(c.y - t.y) < 0.002, "{c:?}");
            }
        }
    }

    #[test]
    fn boards_too_small_for_a_run_are_unchanged() {
        let mut corners = grid(6, 6, 0.01, 0.01, 1);
        let before = corners.clone();
        assert_eq!(fuse_along_lines(&mut corners, &SpacingParams::default()), 0);
        assert_eq!(corners, before);
        assert_eq!(fuse_along_lines(&mut [], &SpacingParams::default()), 0);
    }
}
