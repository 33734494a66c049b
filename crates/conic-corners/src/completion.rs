//! Grid completion: after labelling ([`crate::connectivity`]), the corners a board is missing —
//! because the election rejected them (a scribble or a pen edge beside the junction, a dot, blur)
//! or because the connectivity rule cut their links — are predicted from the labelled grid and
//! added when an unoccluded X-junction is verified at the predicted place.
//!
//! Positions are image coordinates (x right, y down, pixel centres at integers). Labels are the
//! `(row, col)` of [`crate::connectivity::Board`].
//!
//! # Rule ([`complete_boards`])
//!
//! First ([`split_by_phase`]) every board's labels are checked against the checker
//! pattern: in a checkerboard the phase of a corner (which diagonal pair of quadrants is bright)
//! flips from one corner to the next along a grid line, so the phase measured at each corner
//! (the correlation of (b) below, in the frame of its labelled neighbours) times `(−1)^(r+c)` has
//! one sign over a correctly labelled board (on the photos and on every board of the
//! robustness report's 270 scenes, every labelled corner correlated with its board's phase by
//! at least 0.71). Where signs differ, the labels are wrong: the walk stepped over a column of
//! squares foreshortened at an S-shaped board's fold (a 0.3× copy of `curve_4.jpg`: the
//! columns beyond it were all one label off), or two squares at a time through a patch seen
//! between occluders hiding alternate rows (a 1.2-megapixel copy of `marker_real3.jpg`). The
//! board is then split into pieces of one phase connected by label steps of one; pieces of at
//! least [`LabelParams::min_corners`](crate::connectivity::LabelParams) corners over two rows
//! and columns are kept as boards (the corners of the others
//! are then free for the completion of the board they belong to). A corner whose correlation is
//! decided but below `ON_LATTICE` is dropped in the same way (its labelled neighbours are not
//! the ones its edges lead to), and so is a piece whose median correlation is below
//! `TYPICAL_ON_LATTICE`. Where a board's squares are foreshortened to a few pixels or to thin
//! rhombi (a board seen nearly edge-on), the election's edge angles fail and the connectivity
//! can link corners two rows apart: a sheared lattice whose phase is consistent, but whose
//! corners correlate by 0.3–0.72 in its frame. True corners correlate by at least 0.71, and
//! boards by a median of at least 0.93, on the photos, the robustness report and the
//! curved-board benchmark.
//!
//! Then, for every board, repeated for up to [`CompletionParams::rounds`] rounds (new corners
//! support new predictions):
//!
//! 1. **Targets.** Every unlabelled site `t = (r, c)` within the label range grown by one (the
//!    outer ring) with at least one labelled 4-neighbour.
//! 2. **Predictions.** For each labelled neighbour `n = t − e` (`e` one of the four unit label
//!    steps) the step `e` is continued from `n`: along the same grid line (`2p(n) − p(n−e)`, or the
//!    quadratic `3p(n) − 3p(n−e) + p(n−2e)` when three points are known, which follows bending),
//!    and by copying the step `e` of each parallel line beside it (`f ⊥ e`): `p(n) + p(t±f) −
//!    p(t±f−e)`, a parallelogram; when `p(t±f)` is unknown, the step of that line continued to
//!    second order, `p(n) + 2(p(n±f) − p(n±f−e)) − (p(n±f−e) − p(n±f−2e))`, or to first order
//!    when only two of its points are known. A site
//!    between two labelled corners of one line also gets their midpoint. Predictions farther than
//!    `agreement` grid steps from their coordinate-wise median are dropped; at least two must
//!    remain and their mean is the prediction `p̂`.
//! 3. **Verification** in the local grid frame `p + a·u + b·v`, sampled on 84 points with
//!    `0.06 ≤ |a|, |b|` and `|a| + |b| ≤ 0.42` (away from the edges, which blur, and from the
//!    cell centres, where HydraMarker dots sit). `u` and `v` are the column and row steps on
//!    the sample's side of `t` (`a ≥ 0` or `a < 0`, `b ≥ 0` or `b < 0`): each the mean step of
//!    the labelled pairs along that axis whose midpoints lie on that side and nearest to `t`
//!    (Euclidean distance in labels; a side without pairs takes the other side's step). So the
//!    frame follows a board's bending on either side of the site, and it depends only on which
//!    corners are labelled, not on which way the labels run: a photo turned by 90° or 180° gets
//!    the same frames. At a site on the board's boundary (its row or column the first or last),
//!    where the squares beyond may be slivers foreshortened at a silhouette, a failed
//!    verification is retried with the outer side of the frame scaled by 0.5, then 0.25, from
//!    the start of highest quick contrast on a ±0.2-step grid; such a corner must also be
//!    confirmed within 1.5 px by the edge walks of (c) started from it, or by the junction model
//!    ([`crate::junction`]) fitted within a quarter step with at least half the board's contrast.
//!    Where the walks' answer is not confirmed, the gradient estimate is the second candidate,
//!    and only the junction model can confirm it. Where a quarter step exceeds the model's wide
//!    window, the plain model (no sliver edge) fitted within twice its window may confirm too,
//!    if its edges bend by at most `|κ| r ≤ 0.5` across it. Where neither the walks nor the
//!    gradient estimate is confirmed, the junction model started at the searched position places
//!    the corner, if it stays within 1.5 px of it. Where all of this fails at a site on a row or
//!    column the board already holds, the squares beyond may be hairline slivers of a pixel or
//!    two, too narrow for any frame; the boundary line's polarity flips at such a junction
//!    (dark inner square: light beyond; light inner square: the dark sliver beyond), and where
//!    it does (on straight lines either side of the junction), the junction is placed where
//!    those lines meet the grid line into the board (`hairline`); no refiner needs to come
//!    back to it, as [`crate::detect`] places such a corner by that fit where they fail
//!    (`Path::Hairline`). After the rounds, such a line goes on growing by one corner a round.
//!    A site whose full frame leaves the image (a board cut by the image's border) is retried
//!    with the whole frame scaled by 0.5, then 0.25, and confirmed the same way. Nearer the
//!    border than that (on large squares a quarter frame spans 20 px and more), a corner that
//!    the election found within `agreement` steps of `p̂`, with its edges within 15° of the
//!    grid steps and on no board (its grid cells leave the image, so it has no links), stands
//!    in for the verification, and is refined and confirmed the same way.
//!    An X-junction is `m + k·sign(a)·sign(b)`; its *phase* (the sign of
//!    `k`) times `(−1)^(r+c)` is the same all over a board, and is taken from the board's own
//!    corners by majority. A quick test on 5 samples per quadrant within 0.26 step (the quadrant
//!    order of (a) with half its contrast) at `p̂` or one of four points 0.1 step away (the
//!    one of highest contrast) starts a coarse-to-fine search (3 levels of 3 × 3 points, steps 0.1, 0.05, 0.025) for the highest
//!    correlation; there the junction must (a) have every quadrant (median of its samples, robust
//!    to thin strokes) on the right side — the darker of the two expected-bright quadrants exceeds the brighter of the
//!    expected-dark ones by at least `min_contrast_rel` times the board's median; (b) correlate with
//!    the ideal junction of the expected phase (normalized cross-correlation) at least `min_ncc`
//!    over all samples and over the inner ones alone (`|a| + |b| ≤ 0.24`), so a pen or finger
//!    covering the junction or a quadrant fails; and (c) be refined by [`refine_one_among`]
//!    (reach one step, else 0.5, 0.3 or 0.15 step: long edge walks fail where scribbles or an
//!    occluder cut the edges) to a corner that is not [`Status::Failed`], or failing that by the
//!    gradient estimate ([`crate::gradient`]: blurred or foreshortened junctions, as in the
//!    outer ring of a bent board, leave the edge walks nothing to fit) where the junction model
//!    confirms it
//!    (as at a sliver: started there, it stays within 1.5 px with the board's contrast), else by
//!    the junction model started at the search's position, else by the unconfirmed gradient
//!    estimate, within `max_offset` steps of `p̂`. A
//!    site outside the board's current label range, verified in the full frame, grows the
//!    board: it needs a converged (two-sided) answer of [`refine_one_among`] or the junction
//!    model's confirmation, since a border square's outer corner next to an occluder passes (a)
//!    and (b).
//! 4. **Acceptance.** A verified corner more than half a step from every corner of every board
//!    (the offset's length in the site's mean steps `u`, `v`: a sliver's corner lies nearer its
//!    neighbour than half the mean step) is appended to `corners` (angles from `u` and `v`, score
//!    the correlation of (b)) and joins the board with label `t`. At the end labels are shifted
//!    so that their minimum is 0 again and the board is re-sorted by `(row, col)`.
//!
//! The result depends only on the input: a round's sites are verified in parallel, each against
//! the grid as it stood at the round's start, then accepted in label order, and the round's
//! acceptances take effect together at its end.
//!
//! Limitations: a site is completed only next to labelled corners, so a whole missing board
//! region beyond one ring is reached only over several rounds; a junction whose quadrant is
//! covered by an occluder of the same grey as that quadrant passes (a) but usually not (b).

use crate::connectivity::{board_from, line_diff, Board, ConnectivityParams};
use crate::detect::Cov;
use crate::election::Corner;
use crate::gradient::{refine_gradient, GradientParams};
use crate::junction::{refine_junction_at_boundary, JunctionParams};
use crate::quadratic_form::{fit_line_tls, intersect_lines, Line};
use crate::refine::{refine_one_among, RefineParams, Status};
use crate::segmentation::median_in_place;
use crate::GrayImage;
use rayon::prelude::*;
use std::collections::{HashMap, HashSet};
use std::sync::OnceLock;

/// Tuning of [`complete_boards`]; lengths in grid steps (the local square side).
#[derive(Clone, Debug, PartialEq)]
pub struct CompletionParams {
    /// Rounds of prediction and verification (0 disables completion; default 3). After them,
    /// up to 32 more check only hairline slivers (see the module docs): a line of
    /// them grows by one corner a round, as each prediction needs the corner before it. A round
    /// that adds nothing ends either kind.
    pub rounds: usize,
    /// Largest distance of a prediction from the median prediction (default 0.15).
    pub agreement: f64,
    /// Smallest normalized correlation with the ideal junction, over all samples and over the
    /// inner ones (default 0.7; an L-corner scores ≈ 0.58 and fails (a) anyway).
    pub min_ncc: f64,
    /// Smallest quadrant contrast as a fraction of the board's median (default 0.5).
    pub min_contrast_rel: f64,
    /// Largest distance between the refined corner and the prediction (default 0.25).
    pub max_offset: f64,
    /// Refiner settings for the check (c); `reach` and `max_shift` are set from the step.
    pub refine: RefineParams,
    /// The last resort of the check (c) where the refiner fails at every reach (`None`: none);
    /// its `max_shift` is set from the step.
    pub gradient: Option<GradientParams>,
    /// The junction model that confirms a sliver's corner where the edge walks started from it
    /// do not come back to it (`None`: the walks alone).
    pub junction: Option<JunctionParams>,
}

impl Default for CompletionParams {
    fn default() -> Self {
        Self {
            rounds: 3,
            agreement: 0.15,
            min_ncc: 0.7,
            min_contrast_rel: 0.5,
            max_offset: 0.25,
            refine: RefineParams {
                stride: 2,
                ..RefineParams::default()
            },
            gradient: Some(GradientParams::default()),
            junction: Some(JunctionParams::default()),
        }
    }
}

type Label = (i32, i32);
type P = [f64; 2];
/// A verified site: its label, the corner found there, the site's grid steps `(u, v)` and, for
/// a [`hairline`] junction, that fit's covariance.
type Verified = (Label, Corner, (P, P), Option<Cov>);

/// Grid-frame sample offsets `(a, b)` and whether each is inner (`|a| + |b| ≤ 0.24`), grouped by
/// quadrant: `(+,+)`, `(+,−)`, `(−,+)`, `(−,−)`; 21 per quadrant.
fn pattern() -> &'static [(f64, f64, bool); 84] {
    static PATTERN: OnceLock<[(f64, f64, bool); 84]> = OnceLock::new();
    PATTERN.get_or_init(|| {
        let mut out = [(0.0, 0.0, false); 84];
        let mut k = 0;
        for (sa, sb) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
            for i in 1..=6 {
                for j in 1..=(7 - i) {
                    let (a, b) = (0.06 * i as f64, 0.06 * j as f64);
                    out[k] = (sa * a, sb * b, i + j <= 4);
                    k += 1;
                }
            }
        }
        out
    })
}

/// The checker measurements of [`junction`], signed for phase `+1` (quadrants `(+,+)` and
/// `(−,−)` bright).
#[derive(Clone, Copy, Debug)]
struct Junction {
    /// Correlation with `sign(a)·sign(b)` over all samples.
    ncc: f64,
    /// The same over the inner samples.
    ncc_inner: f64,
    /// `min(q₊₊, q₋₋) − max(q₊₋, q₋₊)` of the quadrant medians (phase +1); for phase −1 use
    /// `contrast_neg`.
    contrast_pos: f64,
    /// `min(q₊₋, q₋₊) − max(q₊₊, q₋₋)`.
    contrast_neg: f64,
}

impl Junction {
    /// `(ncc, ncc_inner, contrast)` for the given phase (±1).
    fn phased(&self, phase: f64) -> (f64, f64, f64) {
        let c = if phase > 0.0 {
            self.contrast_pos
        } else {
            self.contrast_neg
        };
        (phase * self.ncc, phase * self.ncc_inner, c)
    }
}

fn ncc(sum: f64, sum_sq: f64, signed: f64, n: f64) -> f64 {
    // Σ s·(f − f̄) = Σ s·f because the ±1 template is balanced.
    let var = sum_sq - sum * sum / n;
    if var > 1e-12 {
        signed / (n * var).sqrt()
    } else {
        0.0
    }
}

/// The local grid frame of a junction: a sample `(a, b)` lies at `p + a·u + b·v`, with the `u`
/// of its side of the junction (`u[0]` for `a ≥ 0`, `u[1]` for `a < 0`) and likewise `v`: the
/// steps of the board on either side ([`Grid::frame`]), and at a silhouette the outer side
/// narrowed to a sliver.
#[derive(Clone, Copy, Debug)]
struct Frame {
    u: [P; 2],
    v: [P; 2],
}

impl Frame {
    /// The mean column and row steps `(u, v)` of both sides.
    fn mean(&self) -> (P, P) {
        let mean = |s: [P; 2]| scale(add(s[0], s[1]), 0.5);
        (mean(self.u), mean(self.v))
    }

    fn scaled(&self, s: f64) -> Self {
        Self {
            u: self.u.map(|u| scale(u, s)),
            v: self.v.map(|v| scale(v, s)),
        }
    }

    fn at(&self, p: P, a: f64, b: f64) -> P {
        let u = self.u[usize::from(a < 0.0)];
        let v = self.v[usize::from(b < 0.0)];
        add(p, add(scale(u, a), scale(v, b)))
    }
}

/// Samples the junction model at `p` in `frame`; `None` if a sample leaves the image.
fn junction(image: &GrayImage, p: P, frame: &Frame) -> Option<Junction> {
    let mut q = [[0f32; 21]; 4];
    let (mut s, mut s2, mut sg) = (0.0, 0.0, 0.0);
    let (mut si, mut s2i, mut sgi, mut ni) = (0.0, 0.0, 0.0, 0.0);
    for (k, &(a, b, inner)) in pattern().iter().enumerate() {
        let [x, y] = frame.at(p, a, b);
        let f = image.bilinear(x as f32, y as f32)? as f64;
        q[k / 21][k % 21] = f as f32;
        let sign = a.signum() * b.signum();
        s += f;
        s2 += f * f;
        sg += sign * f;
        if inner {
            si += f;
            s2i += f * f;
            sgi += sign * f;
            ni += 1.0;
        }
    }
    let med = |v: &mut [f32; 21]| -> f64 {
        v.select_nth_unstable_by(10, f32::total_cmp);
        v[10] as f64
    };
    let [pp, pm, mp, mm] = q.each_mut().map(med);
    Some(Junction {
        ncc: ncc(s, s2, sg, 84.0),
        ncc_inner: ncc(si, s2i, sgi, ni),
        contrast_pos: pp.min(mm) - pm.max(mp),
        contrast_neg: pm.min(mp) - pp.max(mm),
    })
}

/// The phased quadrant contrast of [`Junction`] from 5 samples per quadrant (their median), for
/// a quick rejection; the samples lie within 0.26 step of `p`, so that a junction with a thin
/// visible strip beside an occluder still passes.
fn quick_contrast(image: &GrayImage, p: P, frame: &Frame, phase: f64) -> Option<f64> {
    const AB: [(f64, f64); 5] = [
        (0.08, 0.08),
        (0.16, 0.06),
        (0.06, 0.16),
        (0.22, 0.1),
        (0.1, 0.22),
    ];
    let mut q = [0f64; 4];
    for (k, (sa, sb)) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)]
        .into_iter()
        .enumerate()
    {
        let mut f = [0f64; 5];
        for (fi, &(a, b)) in f.iter_mut().zip(&AB) {
            let [x, y] = frame.at(p, sa * a, sb * b);
            *fi = image.bilinear(x as f32, y as f32)? as f64;
        }
        f.sort_unstable_by(f64::total_cmp);
        q[k] = f[2];
    }
    let [pp, pm, mp, mm] = q;
    Some(if phase > 0.0 {
        pp.min(mm) - pm.max(mp)
    } else {
        pm.min(mp) - pp.max(mm)
    })
}

/// The length of the offset `d` in grid steps: `|(a, b)|` where `d = a·u + b·v` (the plain
/// length over the mean step where `u` and `v` are nearly parallel).
fn in_steps(d: P, u: P, v: P) -> f64 {
    let det = u[0] * v[1] - u[1] * v[0];
    if det.abs() <= 1e-6 * norm(u) * norm(v) {
        return norm(d) / (0.5 * (norm(u) + norm(v))).max(f64::MIN_POSITIVE);
    }
    let a = (d[0] * v[1] - d[1] * v[0]) / det;
    let b = (u[0] * d[1] - u[1] * d[0]) / det;
    a.hypot(b)
}

fn add(a: P, b: P) -> P {
    [a[0] + b[0], a[1] + b[1]]
}
fn sub(a: P, b: P) -> P {
    [a[0] - b[0], a[1] - b[1]]
}
fn scale(a: P, s: f64) -> P {
    [a[0] * s, a[1] * s]
}
fn dot(a: P, b: P) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

fn norm(a: P) -> f64 {
    a[0].hypot(a[1])
}

/// The board's positions by label, dense over the label range grown by a margin (every label a
/// completion can reach), `None` outside.
struct Grid {
    r0: i32,
    c0: i32,
    rows: i32,
    cols: i32,
    at: Vec<Option<P>>,
}

impl Grid {
    fn new(labels: &[Label], positions: impl Iterator<Item = P>, margin: i32) -> Self {
        let (r0, r1, c0, c1) = range(labels);
        let (r0, c0) = (r0 - margin, c0 - margin);
        let (rows, cols) = (r1 + margin + 1 - r0, c1 + margin + 1 - c0);
        let mut grid = Self {
            r0,
            c0,
            rows,
            cols,
            at: vec![None; (rows * cols) as usize],
        };
        for (&l, p) in labels.iter().zip(positions) {
            grid.set(l, p);
        }
        grid
    }

    fn index(&self, (r, c): Label) -> Option<usize> {
        let (i, j) = (r - self.r0, c - self.c0);
        ((0..self.rows).contains(&i) && (0..self.cols).contains(&j))
            .then(|| (i * self.cols + j) as usize)
    }

    fn get(&self, t: Label) -> Option<P> {
        self.index(t).and_then(|k| self.at[k])
    }

    fn set(&mut self, t: Label, p: P) {
        if let Some(k) = self.index(t) {
            self.at[k] = Some(p);
        }
    }

    /// The step `p(b) − p(a)` of the labelled pairs `a`, `b = a + e` nearest to `t` whose
    /// midpoint lies on the given side of `t` along `e` (`side` +1 or −1), averaged over the
    /// pairs equally near: no pair is preferred for the order of its labels, so the frame does
    /// not depend on which way the labels run.
    fn side_step(&self, t: Label, e: Label, side: i32) -> Option<P> {
        let mut best: Option<(i32, P, f64)> = None;
        // Midpoints up to 2.5 steps along `e` on either side, and 2 across.
        let alongs = if side > 0 { 0..=2 } else { -3..=-1 };
        for along in alongs {
            for across in -2..=2 {
                let (dr, dc) = if e.0 != 0 {
                    (along, across)
                } else {
                    (across, along)
                };
                let cost = (2 * dr + e.0).pow(2) + (2 * dc + e.1).pow(2);
                if best.is_some_and(|(c, _, _)| c < cost) {
                    continue;
                }
                let a = (t.0 + dr, t.1 + dc);
                if let (Some(pa), Some(pb)) = (self.get(a), self.get((a.0 + e.0, a.1 + e.1))) {
                    best = Some(match best {
                        Some((c, sum, n)) if c == cost => (c, add(sum, sub(pb, pa)), n + 1.0),
                        _ => (cost, sub(pb, pa), 1.0),
                    });
                }
            }
        }
        best.map(|(_, sum, n)| scale(sum, 1.0 / n))
    }

    /// The frame of `t` from the nearest labelled pairs on each side of it (a side without
    /// pairs takes the other's step). On a bent board the two sides' steps turn and shrink with
    /// the edges, which a junction's samples then follow.
    fn frame(&self, t: Label) -> Option<Frame> {
        let sides = |e: Label| -> Option<[P; 2]> {
            match (self.side_step(t, e, 1), self.side_step(t, e, -1)) {
                (Some(a), Some(b)) => Some([a, b]),
                (Some(a), None) | (None, Some(a)) => Some([a, a]),
                (None, None) => None,
            }
        };
        Some(Frame {
            u: sides((0, 1))?,
            v: sides((1, 0))?,
        })
    }

    /// Every prediction of `t` (rule step 2), pushed to `out`.
    fn predictions(&self, t: Label, out: &mut Vec<P>) {
        out.clear();
        let at = |dr: i32, dc: i32| self.get((t.0 + dr, t.1 + dc));
        for e in [(0, 1), (1, 0), (0, -1), (-1, 0)] {
            let Some(n) = at(-e.0, -e.1) else { continue };
            if let Some(n1) = at(-2 * e.0, -2 * e.1) {
                out.push(match at(-3 * e.0, -3 * e.1) {
                    Some(n2) => add(scale(sub(n, n1), 3.0), n2),
                    None => sub(scale(n, 2.0), n1),
                });
            }
            if let Some(o) = at(e.0, e.1) {
                // Each line's midpoint is pushed once, from its lower side.
                if e.0 + e.1 > 0 {
                    out.push(scale(add(n, o), 0.5));
                }
            }
            for f in [(e.1, e.0), (-e.1, -e.0)] {
                let line = |k: i32| at(f.0 - k * e.0, f.1 - k * e.1);
                let step = match (line(0), line(1), line(2), line(3)) {
                    (Some(p0), Some(p1), _, _) => sub(p0, p1),
                    // The step continued along the parallel line: second order when possible.
                    (None, Some(p1), Some(p2), Some(p3)) => {
                        add(scale(sub(p1, p2), 2.0), sub(p3, p2))
                    }
                    (None, Some(p1), Some(p2), None) => sub(p1, p2),
                    _ => continue,
                };
                out.push(add(n, step));
            }
        }
    }
}

/// The mean of the predictions within `tol` of their coordinate-wise median, if at least two.
fn consensus(preds: &mut [P], tol: f64) -> Option<P> {
    if preds.len() < 2 {
        return None;
    }
    let median = |k: usize, v: &mut [P]| {
        v.sort_by(|a, b| a[k].total_cmp(&b[k]));
        let m = v.len() / 2;
        if v.len() % 2 == 1 {
            v[m][k]
        } else {
            0.5 * (v[m - 1][k] + v[m][k])
        }
    };
    let med = [median(0, preds), median(1, preds)];
    let (mut sum, mut n) = ([0.0, 0.0], 0);
    for p in preds.iter().filter(|p| norm(sub(**p, med)) <= tol) {
        sum = add(sum, *p);
        n += 1;
    }
    (n >= 2).then(|| scale(sum, 1.0 / n as f64))
}

/// What a board's own corners look like: the phase and the median phased contrast.
struct Reference {
    phase: f64,
    contrast: f64,
}

fn parity((r, c): Label) -> f64 {
    if (r + c).rem_euclid(2) == 0 {
        1.0
    } else {
        -1.0
    }
}

/// The [`junction`] at the labelled corner `t`, in the frame of its labelled neighbours' steps.
fn labelled_junction(image: &GrayImage, grid: &Grid, t: Label) -> Option<Junction> {
    let (p, frame) = (grid.get(t)?, grid.frame(t)?);
    junction(image, p, &frame)
}

/// The board's phase (majority) and median contrast, measured at every labelled corner: a
/// subset taken in label order would depend on which way the labels run, and so on how the
/// board lies in the image.
fn reference(image: &GrayImage, grid: &Grid, labels: &[Label]) -> Option<Reference> {
    let measured: Vec<(Label, Junction)> = labels
        .iter()
        .filter_map(|&t| Some((t, labelled_junction(image, grid, t)?)))
        .collect();
    let votes: f64 = measured
        .iter()
        .map(|(t, j)| j.ncc.signum() * parity(*t))
        .sum();
    if votes == 0.0 {
        return None;
    }
    let phase = votes.signum();
    let mut contrast: Vec<f64> = measured
        .iter()
        .map(|(t, j)| j.phased(phase * parity(*t)).2)
        .collect();
    if contrast.is_empty() {
        return None;
    }
    let m = contrast.len() / 2;
    contrast.select_nth_unstable_by(m, f64::total_cmp);
    (contrast[m] > 0.0).then_some(Reference {
        phase,
        contrast: contrast[m],
    })
}

/// Reach (a fraction of the link's length) of the samples on either side of a link in
/// [`edge_seen`]: beyond the blur and the 5 px by which the benchmark's tightest curves leave
/// their chords, and inside the squares along the edge where a cell is foreshortened to a third
/// of its length, clear of the dots at their centres. A quarter of the length reached a
/// foreshortened square's dot on `curve_7.jpg`.
const EDGE_REACH: f64 = 1.0 / 6.0;
/// Sample distances per side in [`edge_seen`], evenly spaced up to `EDGE_REACH`.
const EDGE_SIDE_SAMPLES: usize = 4;
/// Smallest contrast across the middle of a link in [`edge_seen`], as a fraction of the smaller
/// one near its ends: under a pen or a finger there is next to none.
const EDGE_MIDDLE_CONTRAST: f64 = 0.35;

/// Whether the image shows one edge along the segment from `a` to `b` (image coordinates), as
/// between two neighbouring corners of a checkerboard. Across the segment at a point `c` of
/// it, the differences `I(c + r n) − I(c − r n)` are taken at `EDGE_SIDE_SAMPLES` distances `r`
/// up to `EDGE_REACH` of its length (`n` its unit normal). Near both ends (at 20 % and 80 % of
/// the length) the difference largest in magnitude must have one sign; in the middle (35, 50 and
/// 65 %) the largest difference of that sign must reach `EDGE_MIDDLE_CONTRAST` of the smaller
/// end's magnitude, at all three (with two of three, the noisy half-size copy of `curve_4.jpg`
/// kept a corner labelled one row and one column off, as without this check). The largest
/// difference, not a mean: the square beside the edge may be a sliver a few pixels wide at a
/// silhouette, and a grid line curving off its chord leaves the nearest samples on the wrong
/// side. A link that jumps a row hidden under a pen or a finger has
/// no edge in the middle; one that jumps a corner the election missed has the squares swap
/// sides. Samples off the image decide nothing (true), as does a segment shorter than 4 px.
pub fn edge_seen(image: &GrayImage, a: P, b: P) -> bool {
    let d = sub(b, a);
    let len = d[0].hypot(d[1]);
    if len.is_nan() || len < 4.0 {
        return true;
    }
    let n = [-d[1] / len, d[0] / len];
    // The largest differences of either sign at `t`.
    let across = |t: f64| -> Option<(f64, f64)> {
        let c = add(a, scale(d, t));
        let (mut hi, mut lo) = (0.0f64, 0.0f64);
        for k in 1..=EDGE_SIDE_SAMPLES {
            let r = EDGE_REACH * len * k as f64 / EDGE_SIDE_SAMPLES as f64;
            let [px, py] = add(c, scale(n, r));
            let [mx, my] = add(c, scale(n, -r));
            let v = (image.bilinear(px as f32, py as f32)?
                - image.bilinear(mx as f32, my as f32)?) as f64;
            (hi, lo) = (hi.max(v), lo.min(v));
        }
        Some((hi, lo))
    };
    let signed = |(hi, lo): (f64, f64)| if hi >= -lo { hi } else { lo };
    let (Some(e0), Some(e1)) = (across(0.2).map(signed), across(0.8).map(signed)) else {
        return true;
    };
    if e0 * e1 <= 0.0 {
        return false;
    }
    let floor = EDGE_MIDDLE_CONTRAST * e0.abs().min(e1.abs());
    [0.35, 0.5, 0.65]
        .iter()
        .all(|&t| across(t).map_or(true, |(hi, lo)| if e0 > 0.0 { hi } else { -lo } >= floor))
}

/// A corner's phase measurement counts only where its correlation with the ideal junction
/// ([`junction`]) is at least this in magnitude. On the photos and on every board of the
/// robustness report's 270 scenes, every labelled corner correlates with its board's phase by
/// at least 0.71.
const PHASE_DECIDED: f64 = 0.3;

/// Smallest correlation with the ideal junction, in the frame of its labelled neighbours, of a
/// decided corner that stays on its board ([`split_by_phase`]): the completion's own standard
/// for the corners it adds ([`CompletionParams::min_ncc`]'s default).
const ON_LATTICE: f64 = 0.7;

/// Smallest median correlation (as `ON_LATTICE`) of a board's corners. A sheared lattice's
/// corners correlate by 0.6–0.72 in its frame, and some pass `ON_LATTICE`; a board's median
/// is at least 0.93 on the photos, the robustness report and the curved-board benchmark, where
/// 20 of 43 400 corners correlate by less than 0.8.
const TYPICAL_ON_LATTICE: f64 = 0.8;

/// Checks the labels of every board against the checker pattern (first step of the rule in the
/// [module docs](self)). A board where every measured corner agrees, each by at least
/// `ON_LATTICE`, is left alone. Otherwise the corners below it are dropped, the others grouped
/// by phase (the undecided ones join the group of most of their decided 4-neighbours, at least
/// two of them), each
/// group is split into pieces connected by label steps of one, and each piece with at least
/// `min_corners` corners (the labelling's smallest board, [`crate::connectivity::LabelParams`])
/// over two rows and two columns becomes a board of its own (canonical labels, largest first,
/// in place of the board); the rest are dropped. Returns the number of corners dropped.
pub fn split_by_phase(
    image: &GrayImage,
    corners: &[Corner],
    boards: &mut Vec<Board>,
    min_corners: usize,
) -> usize {
    let before: usize = boards.iter().map(|b| b.corners.len()).sum();
    let split: Vec<Board> = boards
        .drain(..)
        .flat_map(|b| split_board(image, corners, b, min_corners))
        .collect();
    *boards = split;
    before - boards.iter().map(|b| b.corners.len()).sum::<usize>()
}

/// Each corner's correlation with the junction of phase +1 in the frame of its labelled
/// neighbours, times its label's parity: one sign all over a correctly labelled board. `None`
/// where the junction cannot be measured.
fn phase_ncc(image: &GrayImage, corners: &[Corner], board: &Board) -> Vec<Option<f64>> {
    let grid = Grid::new(
        &board.labels,
        board.corners.iter().map(|&i| [corners[i].x, corners[i].y]),
        0,
    );
    board
        .labels
        .iter()
        .map(|&t| Some(labelled_junction(image, &grid, t)?.ncc * parity(t)))
        .collect()
}

/// The phase of a board (`board.corners` index `corners`): whether its corners labelled with an
/// even `row + col` correlate positively with the junction of phase +1 (the sign that
/// [`split_by_phase`] checks), by a majority of the corners decided by at least
/// `PHASE_DECIDED`. `None` when no corner is decided, or as many are of either sign.
pub fn board_phase(image: &GrayImage, corners: &[Corner], board: &Board) -> Option<bool> {
    if board.corners.iter().any(|&i| i >= corners.len()) {
        return None;
    }
    let (p, n) = phase_ncc(image, corners, board)
        .into_iter()
        .flatten()
        .filter(|n| n.abs() >= PHASE_DECIDED)
        .fold(
            (0, 0),
            |(p, n), v| if v > 0.0 { (p + 1, n) } else { (p, n + 1) },
        );
    (p != n).then_some(p > n)
}

/// [`split_by_phase`] for one board: its pieces, largest first.
fn split_board(
    image: &GrayImage,
    corners: &[Corner],
    board: Board,
    min_corners: usize,
) -> Vec<Board> {
    if board.corners.iter().any(|&i| i >= corners.len()) {
        return vec![board];
    }
    let ncc = phase_ncc(image, corners, &board);
    let sign: Vec<Option<bool>> = ncc
        .iter()
        .map(|n| n.filter(|n| n.abs() >= PHASE_DECIDED).map(|n| n > 0.0))
        .collect();
    let mut decided = sign.iter().flatten();
    let first = decided.next();
    let one_phase = first.map_or(true, |&f| decided.all(|&s| s == f));
    // A corner beside a wrongly labelled one is measured in a frame bent by it: off the lattice
    // only once the phases agree (the pieces of a split are measured again).
    let off_lattice = |k: usize| {
        one_phase && ncc[k].is_some_and(|n| (PHASE_DECIDED..ON_LATTICE).contains(&n.abs()))
    };
    // Whether the typical correlation of a set of corners is a lattice's (true if none is measured).
    let typical = |members: &mut dyn Iterator<Item = usize>| {
        let mut n: Vec<f64> = members.filter_map(|k| ncc[k].map(f64::abs)).collect();
        n.is_empty() || median_in_place(&mut n) >= TYPICAL_ON_LATTICE
    };
    if one_phase && !(0..ncc.len()).any(off_lattice) {
        return if typical(&mut (0..ncc.len())) {
            vec![board]
        } else {
            Vec::new()
        };
    }
    let index: HashMap<Label, usize> = board
        .labels
        .iter()
        .enumerate()
        .map(|(k, &t)| (t, k))
        .collect();
    let index = &index;
    let neighbours = |t: Label| {
        [(0, 1), (1, 0), (0, -1), (-1, 0)]
            .into_iter()
            .filter_map(move |(dr, dc)| index.get(&(t.0 + dr, t.1 + dc)).copied())
    };
    // Undecided corners take the phase of most of their decided 4-neighbours, at least two of
    // them: a board fails this check because some of its links are wrong, and a corner with
    // one decided neighbour may hang on a wrong link (two rows either side of a pen, linked as
    // neighbours, where the lower row's samples leave the image).
    let phase: Vec<Option<bool>> = (0..sign.len())
        .map(|k| {
            if off_lattice(k) {
                return None;
            }
            sign[k].or_else(|| {
                let (p, n) = neighbours(board.labels[k])
                    .filter(|&j| !off_lattice(j))
                    .filter_map(|j| sign[j])
                    .fold((0, 0), |(p, n), s| if s { (p + 1, n) } else { (p, n + 1) });
                (p.max(n) >= 2 && p != n).then_some(p > n)
            })
        })
        .collect();
    let mut seen = vec![false; sign.len()];
    let mut pieces: Vec<Board> = Vec::new();
    for start in 0..sign.len() {
        let Some(ph) = phase[start] else { continue };
        if seen[start] {
            continue;
        }
        seen[start] = true;
        let mut members = vec![start];
        let mut k = 0;
        while k < members.len() {
            for j in neighbours(board.labels[members[k]]) {
                if !seen[j] && phase[j] == Some(ph) {
                    seen[j] = true;
                    members.push(j);
                }
            }
            k += 1;
        }
        members.sort_unstable();
        let mut piece = Board {
            corners: members.iter().map(|&j| board.corners[j]).collect(),
            labels: members.iter().map(|&j| board.labels[j]).collect(),
            rows: 0,
            cols: 0,
        };
        canonicalize(&mut piece);
        if piece.corners.len() < min_corners.max(1) || piece.rows < 2 || piece.cols < 2 {
            continue;
        }
        if one_phase {
            if typical(&mut members.iter().copied()) {
                pieces.push(piece);
            }
        } else {
            // Each piece lacks the other phase's corners: smaller than the board.
            pieces.extend(split_board(image, corners, piece, min_corners));
        }
    }
    pieces.sort_by_key(|p| std::cmp::Reverse(p.corners.len()));
    pieces
}

/// The search starts of [`verify`], in grid steps from the prediction.
const STARTS: [[f64; 2]; 5] = [[0.0, 0.0], [0.1, 0.0], [-0.1, 0.0], [0.0, 0.1], [0.0, -0.1]];
/// The search starts at a boundary site with slivers beyond it, whose corners bend the
/// prediction farther across the boundary: a grid by 0.1 step, ±0.2 step along `u` (`v`) if
/// the site's outer side is across the columns (rows), ±0.1 otherwise; [`verify`] refines the
/// best of them by 0.05 step.
fn sliver_starts(across_u: bool, across_v: bool) -> impl Iterator<Item = [f64; 2]> {
    let (ku, kv) = (if across_u { 2 } else { 1 }, if across_v { 2 } else { 1 });
    (-ku..=ku).flat_map(move |i| (-kv..=kv).map(move |j| [0.1 * i as f64, 0.1 * j as f64]))
}
/// How far (px) the edge-walk placement of a sliver's corner may move when started from itself
/// (the gradient estimate's own default limit).
const SLIVER_CONFIRM_SHIFT: f64 = 1.5;
/// The refiner's reaches of check (c), in grid steps, longest first.
const REACHES: [f64; 4] = [1.0, 0.5, 0.3, 0.15];
/// The step (grid steps) by which [`verify`] refines the best of the [`sliver_starts`].
const SLIVER_REFINE_STEP: f64 = 0.05;
/// The scales of a sliver's side of the frame tried at a boundary site.
const SLIVER_SCALES: [f64; 2] = [0.5, 0.25];

/// The corner of `free` nearest `p` within `radius` whose two edge orientations lie within the
/// connectivity's default `θ_edge` of the grid steps `u` and `v`, one each: its position and
/// score.
fn elected_at(free: &[Corner], p: P, (u, v): (P, P), radius: f64) -> Option<(P, f64)> {
    let tolerance = ConnectivityParams::default().theta_edge;
    let line = |d: P| d[1].atan2(d[0]);
    let along = |c: &Corner, k: usize| {
        line_diff(c.angles[k], line(u)) <= tolerance
            && line_diff(c.angles[1 - k], line(v)) <= tolerance
    };
    free.iter()
        .map(|c| (c, norm(sub([c.x, c.y], p))))
        .filter(|&(c, d)| d <= radius && (along(c, 0) || along(c, 1)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(c, _)| ([c.x, c.y], c.score))
}

/// Offsets (grid steps along the boundary line, from the site) of [`hairline`]'s scanlines
/// across that line on either side of the junction.
const HAIRLINE_ALONG: [f64; 5] = [0.12, 0.18, 0.24, 0.3, 0.36];
/// Offsets (grid steps into the board) of [`hairline`]'s scanlines across the grid line that
/// runs into the board from the junction: short of 0.35 step, where a HydraMarker dot may lie
/// (reaching 0.38 step lost three corners of `curve_6.jpg` turned by 180°).
const HAIRLINE_INTO: [f64; 8] = [0.1, 0.13, 0.16, 0.19, 0.22, 0.25, 0.28, 0.31];
/// How far (a share of the contrast) [`hairline`]'s scanlines across the boundary must leave an
/// inner square's level: a sliver of a pixel, blurred, dips only about halfway from the light
/// level to the dark. On a full edge the crossing then lies 0.67 σ of the blur inside the
/// square, on both sides alike (those across the grid line into the board take the middle).
const HAIRLINE_DEPARTURE: f64 = 0.25;
/// Rounds of [`complete_boards`] after [`CompletionParams::rounds`] in which only [`hairline`]
/// sites are checked, at most: one a round along a line of slivers.
const HAIRLINE_ROUNDS: usize = 32;
/// Shortest grid step (px) into the board across [`hairline`]'s boundary line: its inner
/// squares are sampled from 0.1 step in, which must clear the boundary's blur (a couple of
/// pixels). Where a board's columns are foreshortened to a few pixels (19 × 29 corners of 6 mm
/// round a 60 mm cylinder, columns of 6–8 px at its silhouette), any column's lines flip there,
/// and chains of corners 2.6–5.9 px off the truth were added.
const HAIRLINE_MIN_STEP: f64 = 16.0;
/// Largest RMS distance (px) of [`hairline`]'s crossings from their line.
const HAIRLINE_RMS: f64 = 0.5;
/// Largest angle (degrees) between [`hairline`]'s boundary line and the grid's.
const HAIRLINE_ANGLE_DEG: f64 = 15.0;

/// A junction placed by [`hairline`] (image coordinates).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Hairline {
    point: P,
    /// The correlation of the inner squares' samples with their expected levels.
    score: f64,
    /// Covariance (px², image axes) of `point` (see [`hairline`]).
    cov: Cov,
}

/// A junction beside a hairline sliver: the squares beyond a board's boundary line
/// foreshortened at a silhouette to a pixel or two, too narrow for any frame of [`verify`]
/// (`curve_5.jpg`, `curve_7.jpg`, `curve_8.jpg`: the column beyond the board's first one, 1–3 px
/// beside squares of 50–70 px). The boundary line still shows the junction: where its inner
/// square is dark, the outer side is light (the margin, or the light sliver merged with it), and
/// where its inner square is light, the outer side is dark (the dark square's sliver), so the
/// line's polarity flips at the junction. A board's printed border (one margin along both
/// squares) or a silhouette right at the squares' line (one background) does not flip.
///
/// `inward` is the grid step from `p` across the boundary line into the board (at least
/// [`HAIRLINE_MIN_STEP`] long), `along` the steps
/// along the boundary line from `p` to either side, `bright` which of those sides' inner squares
/// is the bright one. The inner squares' levels (medians of 9 samples at 0.15–0.35 step in) must
/// differ by `min_contrast`, and their samples correlate with the expected levels by `min_ncc`.
/// The grid line into the board is found first, through the crossings halfway between the two
/// inner squares' levels on scanlines along the boundary at [`HAIRLINE_INTO`] step inside (on
/// each, the crossing nearest where the line is expected), as a straight line. From where it
/// meets the boundary, on either side, scanlines across the boundary line at
/// [`HAIRLINE_ALONG`] walk outwards from 0.12 step inside, by quarter pixels, to where the
/// level departs from the inner square's by [`HAIRLINE_DEPARTURE`] of the contrast towards the
/// other's (up to 0.12 step + 2 px outside); on the dark square's side the crossing is then
/// taken where the level is halfway to the lightest beyond it. Each side's five crossings must
/// lie on a straight line (RMS ≤ [`HAIRLINE_RMS`]) within [`HAIRLINE_ANGLE_DEG`] of the grid's
/// line, and beyond the light square it must get darker than beyond the dark one by
/// [`HAIRLINE_DEPARTURE`] of the contrast (the flip). The grid line is then fitted again as a
/// parabola `s(a)` (it bends as the surface turns away), its crossings counted from where the
/// straight line met the dark side's line, and the junction is where the parabola meets that
/// line. Returns it with the correlation and its covariance; `None` where any of this fails.
/// Image coordinates.
fn hairline(
    image: &GrayImage,
    p: P,
    inward: P,
    along: [P; 2],
    bright: [bool; 2],
    min_contrast: f64,
    min_ncc: f64,
) -> Option<Hairline> {
    if norm(inward) < HAIRLINE_MIN_STEP {
        return None;
    }
    let at = |q: P| image.bilinear(q[0] as f32, q[1] as f32).map(f64::from);
    let offsets = [0.15, 0.25, 0.35];
    let mut levels = [0.0; 2];
    let (mut sum, mut sum_sq, mut signed, mut n) = (0.0, 0.0, 0.0, 0.0);
    for k in 0..2 {
        let mut side = [0.0; 9];
        for (i, v) in side.iter_mut().enumerate() {
            let q = add(
                add(p, scale(inward, offsets[i / 3])),
                scale(along[k], offsets[i % 3]),
            );
            *v = at(q)?;
            let sign = if bright[k] { 1.0 } else { -1.0 };
            (sum, sum_sq, signed, n) = (sum + *v, sum_sq + *v * *v, signed + sign * *v, n + 1.0);
        }
        levels[k] = median_in_place(&mut side);
    }
    let (hi, lo) = if bright[0] {
        (levels[0], levels[1])
    } else {
        (levels[1], levels[0])
    };
    let score = ncc(sum, sum_sq, signed, n);
    if bright[0] == bright[1] || hi - lo < min_contrast || score < min_ncc {
        return None;
    }
    // Where the level has left the inner square's by `share` of the contrast, walking from
    // `from` along the unit `dir` for up to `length` px, having started in a square as `bright`
    // says: the distance, by linear interpolation.
    let crossing = |from: P, dir: P, length: f64, bright: bool, share: f64| -> Option<f64> {
        let mid = if bright {
            hi - share * (hi - lo)
        } else {
            lo + share * (hi - lo)
        };
        let side = |v: f64| (v > mid) == bright;
        let mut last = at(from)?;
        if !side(last) {
            return None;
        }
        let steps = (length / 0.25).ceil() as usize;
        (1..=steps).find_map(|i| {
            let s = 0.25 * i as f64;
            let v = at(add(from, scale(dir, s)))?;
            let crossed = !side(v);
            let out = crossed.then(|| s - 0.25 * (v - mid) / (v - last));
            last = v;
            out
        })
    };
    // Where the level crosses halfway between the squares' from the `bright` side to the
    // other, walking from `from` along the unit `dir` for `length` px: of all such crossings
    // the one nearest `target` px from `from` (a HydraMarker dot in the square the walk
    // starts in has a crossing of the same sense, farther from where the edge is expected),
    // among those before the scan leaves the image.
    let nearest_crossing = |from: P, dir: P, length: f64, bright: bool, target: f64| {
        let mid = 0.5 * (hi + lo);
        let side = |v: f64| (v > mid) == bright;
        let mut last = at(from)?;
        let steps = (length / 0.25).ceil() as usize;
        let mut best: Option<f64> = None;
        for i in 1..=steps {
            let s = 0.25 * i as f64;
            // The scan may leave the image past the edge (a board cut by the image's border).
            let Some(v) = at(add(from, scale(dir, s))) else {
                break;
            };
            if side(last) && !side(v) {
                let c = s - 0.25 * (v - mid) / (v - last);
                if best.map_or(true, |b| (c - target).abs() < (b - target).abs()) {
                    best = Some(c);
                }
            }
            last = v;
        }
        best
    };
    // The grid line into the board, between the two inner squares, first: the boundary's
    // scanlines are placed from where it meets the boundary, as the prediction may be off by a
    // tenth of a step along it. Towards a silhouette that line bends as the surface turns
    // away, so it is a parabola (a straight line through the same crossings put the junction
    // 1–1.3 px along the boundary from the refiners' answers on the photos).
    let grid = sub(along[0], along[1]);
    let across = scale(grid, 1.0 / norm(grid));
    // The crossings are sought within `reach` steps of `origin` on either side: the first
    // pass starts from the prediction, a tenth of a step off or more, the second from about
    // the junction.
    let row_from = |origin: P, reach: f64| -> Option<RowLine> {
        let base = add(origin, scale(along[1], reach));
        let mut into = [(0.0, 0.0); HAIRLINE_INTO.len()];
        for (c, &a) in into.iter_mut().zip(&HAIRLINE_INTO) {
            let from = add(base, scale(inward, a));
            let s = nearest_crossing(
                from,
                across,
                reach * (norm(along[0]) + norm(along[1])),
                bright[1],
                reach * norm(along[1]),
            )?;
            *c = (a, s);
        }
        let fit = fit_parabola(&into)?;
        Some(RowLine {
            base,
            inward,
            across,
            fit,
        })
    };
    // First a straight line through the parabola at the crossings' offsets, for where the
    // boundary's scanlines go: the prediction may lie a few pixels off across the boundary, its
    // nearest crossings then in the boundary's blur, which a straight line follows less than a
    // parabola extrapolated.
    let first = row_from(p, 0.3)?;
    let points = HAIRLINE_INTO.map(|a| first.at(a));
    let row_line = fit_line_tls(&points, None)?;
    let foot = sub(
        p,
        scale(row_line.normal(), row_line.signed_distance(p[0], p[1])),
    );
    let len_in = norm(inward);
    let out = scale(inward, -1.0 / len_in);
    // Each side of the junction has its own line: at the silhouette the boundary kinks there
    // (a light square beside a dark sliver, a dark one beside the light margin).
    let mut lines = Vec::with_capacity(2);
    let mut rms_of = [0.0; 2];
    // The blur σ (px) seen on the dark side's scanlines: a full step's quarter-contrast
    // crossing lies 0.674 σ inside its halfway one.
    let mut blurs = Vec::with_capacity(HAIRLINE_ALONG.len());
    // The level outside each side's crossings, nearest the other inner square's (the darkest
    // beyond a light square, the lightest beyond a dark one): the median over its scanlines.
    let mut outside = [0.0; 2];
    let length = 0.24 * len_in + 2.0;
    // One scanline at `b` steps along side `k`: its crossing, the extreme level beyond it and,
    // on the dark side, the blur it shows.
    let scan = |k: usize, b: f64| -> Option<(P, f64, Option<f64>)> {
        let from = add(add(foot, scale(along[k], b)), scale(inward, 0.12));
        let s = crossing(from, out, length, bright[k], HAIRLINE_DEPARTURE)?;
        let q = add(from, scale(out, s));
        // Up to the image's border, where a board cut by it ends.
        let fold = if bright[k] { f64::min } else { f64::max };
        let e = (1..=((length - s) / 0.25) as usize)
            .map_while(|i| at(add(q, scale(out, 0.25 * i as f64))))
            .fold(at(q)?, fold);
        if bright[k] {
            return Some((q, e, None));
        }
        // Beside the dark square the outside is a full step to the light side (see above): the
        // edge is where the level is halfway to the lightest beyond, not a quarter of the
        // contrast from the square's (there the crossings lie 0.67 σ of the blur inside, which
        // an acute angle between the two lines turns into 2–3 px along the grid line).
        let half = 0.5 * (e - lo) / (hi - lo);
        let s_half = crossing(from, out, length, false, half)?;
        let blur = (s_half - s).max(0.0) / 0.674;
        Some((add(from, scale(out, s_half)), e, Some(blur)))
    };
    for k in 0..2 {
        // The scanline nearest the junction may run in the grid line's blur where the grid
        // step is oblique to the boundary (`curve_5.jpg`, rows meeting the silhouette at 30°):
        // one scanline of five may fail, and a line through five that fails the RMS test is
        // fitted again without its worst crossing.
        let scans: Vec<(P, f64, Option<f64>)> =
            HAIRLINE_ALONG.iter().filter_map(|&b| scan(k, b)).collect();
        if scans.len() + 1 < HAIRLINE_ALONG.len() {
            return None;
        }
        let side: Vec<P> = scans.iter().map(|s| s.0).collect();
        let mut extremes: Vec<f64> = scans.iter().map(|s| s.1).collect();
        blurs.extend(scans.iter().filter_map(|s| s.2));
        outside[k] = median_in_place(&mut extremes);
        let (line, rms) = line_and_rms(&side)?;
        let (line, rms) = if rms <= HAIRLINE_RMS || side.len() < HAIRLINE_ALONG.len() {
            (line, rms)
        } else {
            let worst = (0..side.len()).max_by(|&i, &j| {
                let d = |q: P| line.signed_distance(q[0], q[1]).abs();
                d(side[i]).total_cmp(&d(side[j]))
            })?;
            let rest: Vec<P> = (0..side.len())
                .filter(|&i| i != worst)
                .map(|i| side[i])
                .collect();
            line_and_rms(&rest)?
        };
        let cos = dot(line.direction(), across).abs();
        if !(rms <= HAIRLINE_RMS && cos >= HAIRLINE_ANGLE_DEG.to_radians().cos()) {
            return None;
        }
        rms_of[k] = rms;
        lines.push(line);
    }
    // The polarity flips: beyond the light square it is darker than beyond the dark one. A
    // background of a grey between the squares' levels departs from both by a quarter of the
    // contrast, but alike on both sides: there the squares' edges meet an occluding contour,
    // not a junction.
    let (light_out, dark_out) = if bright[0] {
        (outside[0], outside[1])
    } else {
        (outside[1], outside[0])
    };
    if dark_out - light_out < HAIRLINE_DEPARTURE * (hi - lo) {
        return None;
    }
    // The junction is on the dark square's side's line: beyond a dark square the light
    // square's sliver or the board's light margin, an edge on the grid line either way. Beyond
    // the light square, the dark square's sliver makes an edge on the grid line too, but where
    // a light margin lies beyond it (the board's last column at a silhouette) the edge is the
    // margin's outer contour, a pixel or two farther out (on a concave cylinder of the
    // curved-board benchmark, the mean of the two sides put the corners 1.9–2.3 px off the
    // truth, claiming σ 0.9 px).
    let dark = usize::from(bright[0]);
    // Where a grid line meets both sides' lines, and its `a` on the dark side's.
    let meet = |row: &RowLine| -> Option<([P; 2], f64)> {
        let (a0, a1) = (row.meet(&lines[0])?, row.meet(&lines[1])?);
        Some(([row.at(a0), row.at(a1)], [a0, a1][dark]))
    };
    // Then the parabola through crossings counted from where the straight line meets the
    // boundary.
    let second = row_from(intersect_lines(&row_line, &lines[dark])?, 0.15)?;
    let (ends, a) = meet(&second)?;
    let z = ends[dark];
    // The covariance of two lines' intersection: the boundary line's offset uncertain by the
    // scatter of its crossings about it (one crossing's: a conservative share of a fit through
    // five) and a third of the blur (the halfway level of a sliver a blur wide or less is not
    // its edge's), the grid line's by the parabola's standard error where it is extrapolated
    // to the boundary and its scatter; each moves the junction along the other line, by more
    // where the two meet at an acute angle. The two sides' disagreement (the kink of a
    // silhouette, or a light margin's width) adds in every direction.
    let blur = median_in_place(&mut blurs);
    let (n_b, t_b) = (lines[dark].normal(), lines[dark].direction());
    let c = second.fit.coefficients;
    let tangent = add(inward, scale(across, c[1] + 2.0 * a * c[2]));
    let n_row = [-tangent[1], tangent[0]];
    let (sin_b, sin_row) = (dot(n_b, tangent), dot(n_row, t_b));
    if sin_b.abs() < 1e-9 || sin_row.abs() < 1e-9 {
        return None;
    }
    let sigma_b = rms_of[dark].hypot(blur / 3.0);
    let sigma_s = second.fit.se0.hypot(second.fit.rms);
    let shift_b = scale(tangent, sigma_b / sin_b);
    let shift_s = scale(t_b, sigma_s * dot(n_row, across) / sin_row);
    let spread = 0.25 * norm(sub(ends[0], ends[1])).powi(2) + rms_of[1 - dark].powi(2);
    let cov = [
        [
            shift_b[0] * shift_b[0] + shift_s[0] * shift_s[0] + spread,
            shift_b[0] * shift_b[1] + shift_s[0] * shift_s[1],
        ],
        [
            shift_b[0] * shift_b[1] + shift_s[0] * shift_s[1],
            shift_b[1] * shift_b[1] + shift_s[1] * shift_s[1] + spread,
        ],
    ];
    Some(Hairline {
        point: z,
        score,
        cov,
    })
}

/// The total-least-squares line through `points` and the RMS of their distances from it.
fn line_and_rms(points: &[P]) -> Option<(Line, f64)> {
    let line = fit_line_tls(points, None)?;
    let rms = (points
        .iter()
        .map(|q| line.signed_distance(q[0], q[1]).powi(2))
        .sum::<f64>()
        / points.len() as f64)
        .sqrt();
    Some((line, rms))
}

/// [`hairline`]'s grid line into the board: `base + a·inward + s(a)·across`, `s` a parabola.
struct RowLine {
    base: P,
    inward: P,
    across: P,
    fit: Parabola,
}

impl RowLine {
    fn at(&self, a: f64) -> P {
        let c = self.fit.coefficients;
        add(
            add(self.base, scale(self.inward, a)),
            scale(self.across, c[0] + a * (c[1] + a * c[2])),
        )
    }

    /// The `a` where it meets `line`, within a quarter step of `a = 0` (Newton from there).
    fn meet(&self, line: &Line) -> Option<f64> {
        let (n, c) = (line.normal(), self.fit.coefficients);
        let dist = |a: f64| {
            let q = self.at(a);
            line.signed_distance(q[0], q[1])
        };
        let mut a = 0.0;
        for _ in 0..8 {
            let slope = dot(n, self.inward) + dot(n, self.across) * (c[1] + 2.0 * a * c[2]);
            if slope.abs() < 1e-9 {
                return None;
            }
            a -= dist(a) / slope;
        }
        (a.abs() <= 0.25 && dist(a).abs() < 1e-6).then_some(a)
    }
}

/// A least-squares parabola `s = c₀ + c₁ a + c₂ a²`.
struct Parabola {
    coefficients: [f64; 3],
    /// RMS of the residuals.
    rms: f64,
    /// Standard error of its value at `a = 0` (residual variance with three parameters fitted).
    se0: f64,
}

/// The least-squares [`Parabola`] through `(a, s)` pairs; `None` with fewer than four pairs or
/// collinear `a`.
fn fit_parabola(points: &[(f64, f64)]) -> Option<Parabola> {
    if points.len() < 4 {
        return None;
    }
    let mut ata = nalgebra::Matrix3::<f64>::zeros();
    let mut atb = nalgebra::Vector3::<f64>::zeros();
    for &(a, s) in points {
        let row = nalgebra::Vector3::new(1.0, a, a * a);
        ata += row * row.transpose();
        atb += row * s;
    }
    let inverse = ata.try_inverse()?;
    let c = inverse * atb;
    let rss: f64 = points
        .iter()
        .map(|&(a, s)| (c[0] + a * (c[1] + a * c[2]) - s).powi(2))
        .sum();
    let n = points.len() as f64;
    Some(Parabola {
        coefficients: [c[0], c[1], c[2]],
        rms: (rss / n).sqrt(),
        se0: (rss / (n - 3.0) * inverse[(0, 0)]).sqrt(),
    })
}

/// What the junction at a site must show: the checker's phase there (±1, the sign of its
/// quadrants), the smallest contrast (from the board's reference) and the smallest correlation
/// (`CompletionParams::min_ncc`).
#[derive(Clone, Copy)]
struct Expected {
    phase: f64,
    min_contrast: f64,
    min_ncc: f64,
}

/// Searches the best junction near `p` (coarse to fine, from the one of `starts` with the highest
/// quick-test contrast, or of its 8 neighbours `refine_step` away if one is higher; 0: none) and
/// applies checks (a), (b). The search moves by the grid steps `(u, v)`; `starts` are offsets in
/// them; the samples are taken in `frame`.
fn verify(
    image: &GrayImage,
    p: P,
    (u, v): (P, P),
    frame: &Frame,
    starts: impl Iterator<Item = [f64; 2]>,
    refine_step: f64,
    Expected {
        phase,
        min_contrast,
        min_ncc,
    }: Expected,
) -> Option<(P, f64)> {
    let score =
        |q: P| -> Option<(f64, f64, f64)> { Some(junction(image, q, frame)?.phased(phase)) };
    let moved = move |q: P, i: f64, j: f64| add(q, add(scale(u, i), scale(v, j)));
    // The 8 points `h` grid steps around `c`.
    let ring = move |c: P, h: f64| {
        (-1..=1)
            .flat_map(|i| (-1..=1).map(move |j| (i, j)))
            .filter(|&ij| ij != (0, 0))
            .map(move |(i, j)| moved(c, h * i as f64, h * j as f64))
    };
    // Cheap rejection first, on 20 samples: near a true junction (within about 0.1 step) the
    // quadrants are already in order with half the contrast required of the result. The search
    // starts from the start of highest contrast, or from a point of its ring that beats it.
    let quick = |q: P| Some((q, quick_contrast(image, q, frame, phase)?));
    let by_contrast = |a: &(P, f64), b: &(P, f64)| a.1.total_cmp(&b.1);
    let coarse = starts
        .map(|[i, j]| moved(p, i, j))
        .filter_map(quick)
        .max_by(by_contrast)?;
    let fine = (refine_step > 0.0)
        .then(|| {
            ring(coarse.0, refine_step)
                .filter_map(quick)
                .max_by(by_contrast)
        })
        .flatten();
    let (start, contrast) = match fine {
        Some(f) if f.1 > coarse.1 => f,
        _ => coarse,
    };
    if contrast < 0.5 * min_contrast {
        return None;
    }
    let (mut best, mut best_s) = (start, score(start)?);
    for h in [0.1, 0.05, 0.025] {
        for q in ring(best, h) {
            if let Some(s) = score(q) {
                if s.0 > best_s.0 {
                    (best, best_s) = (q, s);
                }
            }
        }
    }
    let (n_all, n_inner, contrast) = best_s;
    (n_all >= min_ncc && n_inner >= min_ncc && contrast >= min_contrast).then_some((best, n_all))
}

/// Completes every board (rule in the [module docs](self)): verified corners are appended to
/// `corners` and their indices and labels added to the boards, which stay canonical (minimum
/// label 0, sorted by `(row, col)`, `rows`/`cols` updated). Boards whose indices are out of
/// range of `corners` are left alone.
pub fn complete_boards(
    image: &GrayImage,
    corners: &mut Vec<Corner>,
    boards: &mut [Board],
    params: &CompletionParams,
) -> Completed {
    let mut done = Completed::default();
    for b in 0..boards.len() {
        complete_one(image, corners, boards, b, params, &mut done);
    }
    done
}

/// What [`complete_boards`] added.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Completed {
    /// Number of corners added.
    pub added: usize,
    /// The corners (indices into `corners`) placed beside hairline slivers at a silhouette,
    /// where the boundary line's polarity flips (see the module docs), with the covariance
    /// (px², image axes) of that placement: its two lines' uncertainties (their scatter, the
    /// parabola's extrapolation, a third of the blur for the boundary's edge) carried to their
    /// intersection, and the disagreement of the boundary's two sides.
    pub hairlines: HashMap<usize, Cov>,
}

fn complete_one(
    image: &GrayImage,
    corners: &mut Vec<Corner>,
    boards: &mut [Board],
    b: usize,
    params: &CompletionParams,
    done: &mut Completed,
) {
    if boards[b].corners.iter().any(|&i| i >= corners.len()) || boards[b].labels.is_empty() {
        return;
    }
    let margin = params.rounds.min(1000) as i32 + 3;
    let mut grid = Grid::new(
        &boards[b].labels,
        boards[b]
            .corners
            .iter()
            .map(|&i| [corners[i].x, corners[i].y]),
        margin,
    );
    let Some(reference) = reference(image, &grid, &boards[b].labels) else {
        return;
    };
    let min_contrast = params.min_contrast_rel * reference.contrast;
    // Prediction count at each failed site: it is retried only with more support.
    let mut tried: HashMap<Label, usize> = HashMap::new();
    let mut preds = Vec::with_capacity(16);
    let mut added = 0;
    // After the rounds, a column (row) of hairline slivers goes on growing by one corner a
    // round: there each corner is found from the image alone ([`hairline`]), where further
    // rounds of the other checks would add corners placed from corners added before them
    // (under dot gain and blur, 1.6–3.3 px off the truth on the robustness report's 60 mm
    // cylinder).
    let mut hairline_only = false;
    let rounds = if params.rounds == 0 {
        0
    } else {
        params.rounds + HAIRLINE_ROUNDS
    };
    for round in 0..rounds {
        hairline_only |= round >= params.rounds;
        let (r0, r1, c0, c1) = range(&boards[b].labels);
        // The sites to check this round, with their consensus prediction, grid frame and mean
        // step.
        let mut sites: Vec<(Label, P, Frame, f64)> = Vec::new();
        for r in r0 - 1..=r1 + 1 {
            for c in c0 - 1..=c1 + 1 {
                let t = (r, c);
                if grid.get(t).is_some() {
                    continue;
                }
                grid.predictions(t, &mut preds);
                if preds.len() < 2 || tried.get(&t).is_some_and(|&n| n >= preds.len()) {
                    continue;
                }
                tried.insert(t, preds.len());
                let Some(frame) = grid.frame(t) else {
                    continue;
                };
                let (u, v) = frame.mean();
                let step = 0.5 * (norm(u) + norm(v));
                if let Some(p) = consensus(&mut preds, params.agreement * step) {
                    sites.push((t, p, frame, step));
                }
            }
        }
        // The elected corners that no board holds.
        let taken: HashSet<usize> = boards
            .iter()
            .flat_map(|bd| bd.corners.iter().copied())
            .collect();
        let free: Vec<Corner> = (0..corners.len())
            .filter(|i| !taken.contains(i))
            .map(|i| corners[i])
            .collect();
        // The verification (step 3 of the module docs) of each site, in parallel: it reads the
        // image and the grid as it stood at the start of the round, never another site's answer.
        let checked: Vec<Option<Verified>> = sites
            .par_iter()
            .map(|&(t, p, frame, step)| {
                let (u, v) = frame.mean();
                let expected = Expected {
                    phase: reference.phase * parity(t),
                    min_contrast,
                    min_ncc: params.min_ncc,
                };
                // A site on the board's boundary may have slivers beyond it (squares
                // foreshortened at a silhouette): its outer side is sampled in a narrower frame
                // if the full one fails, and searched farther, as the slivers' corners bend the
                // prediction.
                let outer = |k: i32, lo: i32, hi: i32| [k >= hi, k <= lo];
                let (outer_u, outer_v) = (outer(t.1, c0, c1), outer(t.0, r0, r1));
                let sliver = |s: f64| Frame {
                    u: [0, 1].map(|i| scale(frame.u[i], if outer_u[i] { s } else { 1.0 })),
                    v: [0, 1].map(|i| scale(frame.v[i], if outer_v[i] { s } else { 1.0 })),
                };
                let on_boundary = outer_u.iter().chain(&outer_v).any(|&o| o);
                // Every search at this site: the same prediction, grid steps and expectations,
                // in the given frame from the given starts.
                let check =
                    |frame: &Frame, starts: &mut dyn Iterator<Item = [f64; 2]>, refine_step| {
                        verify(image, p, (u, v), frame, starts, refine_step, expected)
                    };
                // Whether the full frame leaves the image, asked by two of the fallbacks below.
                let leaves = std::cell::OnceCell::new();
                let frame_leaves = || *leaves.get_or_init(|| junction(image, p, &frame).is_none());
                let verified = check(&frame, &mut STARTS.into_iter(), 0.0)
                    .map(|(q, score)| (q, score, false))
                    .or_else(|| {
                        // A site near the image's border whose full frame leaves the image: the
                        // whole frame is narrowed instead (a board cut by the border, whose corners
                        // there the election's template cannot reach either).
                        frame_leaves()
                            .then(|| {
                                SLIVER_SCALES.iter().find_map(|&s| {
                                    check(&frame.scaled(s), &mut STARTS.into_iter(), 0.0)
                                })
                            })?
                            .map(|(q, score)| (q, score, true))
                    })
                    .or_else(|| {
                        // Nearer the border than even the narrowed frames reach (on large squares a
                        // quarter frame spans 20 px and more): the election's test, on its 15-px
                        // patch, verified an X-junction there if it elected a corner at the
                        // prediction with its edges along the grid. No board took that corner, as
                        // its grid cells leave the image.
                        frame_leaves()
                            .then(|| elected_at(&free, p, (u, v), params.agreement * step))?
                            .map(|(q, score)| (q, score, true))
                    })
                    .or_else(|| {
                        on_boundary
                            .then(|| {
                                SLIVER_SCALES.iter().find_map(|&s| {
                                    let mut starts = sliver_starts(
                                        outer_u.contains(&true),
                                        outer_v.contains(&true),
                                    );
                                    check(&sliver(s), &mut starts, SLIVER_REFINE_STEP)
                                })
                            })?
                            .map(|(q, score)| (q, score, true))
                    });
                let grows = t.0 < r0 || t.0 > r1 || t.1 < c0 || t.1 > c1;
                // (c) The refiner must place the corner near the prediction. Long walks fail
                // where scribbles or an occluder cut the edges, so shorter reaches are tried
                // before giving up (a search position alone is only good to a few pixels).
                // Blurred or foreshortened junctions (the outer ring of a bent board) leave the
                // edge walks nothing to fit; the gradient estimate, which needs only the
                // junction, is the last resort.
                let refine_at = |k: f64, max_shift: f64| RefineParams {
                    reach: (k * step).clamp(5.0, params.refine.reach.max(5.0)),
                    max_shift,
                    ..params.refine.clone()
                };
                // A sliver's junction is barely resolved, and the gradient estimate is off by
                // pixels there (measured on renders past the truth's visibility limit): the edge
                // walks, started from the corner, must come back to it.
                let confirmed = |z: P| {
                    REACHES.into_iter().any(|k| {
                        refine_one_among(image, z, &[], &refine_at(k, SLIVER_CONFIRM_SHIFT)).status
                            != Status::Failed
                    })
                };
                let angle = |d: P| d[1].atan2(d[0]).rem_euclid(std::f64::consts::PI);
                // The junction model's answer from `z`, fitted within a quarter of the smaller
                // grid step (a sliver's own width, about), if it stays within
                // `SLIVER_CONFIRM_SHIFT` of `z` with the board's contrast: where a sliver is too
                // narrow for the walks, it must place the corner.
                // Where the sliver's far edge lies inside that window, the model has it too: a
                // line parallel to the boundary's grid line, on the outer side.
                let junction_at = |z: P| -> Option<P> {
                    params.junction.as_ref().and_then(|jp| {
                        let radius = 0.25 * norm(u).min(norm(v));
                        // The boundary's grid line is edge 1 (along v) at a column boundary,
                        // edge 0 (along u) at a row boundary.
                        let outward = |outer: [bool; 2], step: P| match outer {
                            [true, false] => Some(step),
                            [false, true] => Some(scale(step, -1.0)),
                            _ => None,
                        };
                        let beyond: Vec<(usize, P)> = [(outer_u, u, 1), (outer_v, v, 0)]
                            .into_iter()
                            .filter_map(|(outer, step, edge)| Some((edge, outward(outer, step)?)))
                            .collect();
                        let angles = [angle(u), angle(v)];
                        let confirms = |jp: &JunctionParams,
                                        beyond: &[(usize, P)],
                                        max_bend: f64| {
                            refine_junction_at_boundary(image, z, angles, radius, 1.0, beyond, jp)
                                .filter(|j| {
                                    norm(sub(j.point, z)) <= SLIVER_CONFIRM_SHIFT
                                        && j.contrast >= min_contrast
                                        && j.curvatures.iter().all(|k| k.abs() <= max_bend)
                                })
                                .map(|j| j.point)
                        };
                        // A junction beside a sliver as wide as the window or wider: the model
                        // may need twice the window (`curve_6.jpg` (6, 0), a 12 px sliver, where
                        // the fit within 6–10 px does not converge). There its edges must bend by
                        // at most a quarter of the window's radius across it (`|κ| r ≤ 0.5`): an
                        // occluder's edge meeting a border square fits the model with edges
                        // bent at a radius of 8 px (a bar across an S-shaped board). The plain
                        // model only: with the sliver fits too, the wider window took 13 ms of
                        // `curve_6`'s completion (28 → 41 ms) and confirmed nothing more.
                        let wider = (2.0 * jp.max_radius).min(32.0);
                        let wider_params = JunctionParams {
                            max_radius: wider,
                            wide_radius: wider,
                            ..jp.clone()
                        };
                        confirms(jp, &beyond, f64::INFINITY).or_else(|| {
                            (radius > jp.wide_radius)
                                .then(|| confirms(&wider_params, &[], 0.5 / wider))
                                .flatten()
                        })
                    })
                };
                let junction_confirms = |z: P| junction_at(z).is_some();
                // The site's answer: a corner at `z` along the grid steps.
                let found = |z: P, score: f64| -> Verified {
                    let corner = Corner {
                        x: z[0],
                        y: z[1],
                        angles: [angle(u), angle(v)],
                        score,
                    };
                    (t, corner, (u, v), None)
                };
                let hairline_site = || -> Option<Verified> {
                    // A boundary line of the board whose squares beyond are hairline slivers:
                    // the corner is where the line's polarity flips (see [`hairline`]). At a
                    // corner of the board both of its lines are tried.
                    if grows {
                        return None;
                    }
                    // The step into the board across a boundary line whose outer side is `outer`
                    // (steps `across` on either side), the steps along it and whether the inner
                    // square on the first side is the bright one.
                    let config = |outer: [bool; 2], across: [P; 2], steps: [P; 2]| {
                        let along = [steps[0], scale(steps[1], -1.0)];
                        match outer {
                            [false, true] => Some((across[0], along, expected.phase > 0.0)),
                            [true, false] => {
                                Some((scale(across[1], -1.0), along, expected.phase < 0.0))
                            }
                            _ => None,
                        }
                    };
                    let Hairline {
                        point: z,
                        score,
                        cov,
                    } = [
                        config(outer_u, frame.u, frame.v),
                        config(outer_v, frame.v, frame.u),
                    ]
                    .into_iter()
                    .flatten()
                    .find_map(|(inward, along, bright)| {
                        hairline(
                            image,
                            p,
                            inward,
                            along,
                            [bright, !bright],
                            min_contrast,
                            params.min_ncc,
                        )
                    })?;
                    if norm(sub(z, p)) > params.max_offset * step {
                        return None;
                    }
                    // No refiner needs to come back to it: `detect` places such a corner where
                    // they fail (`Path::Hairline`). Requiring one lost all but the first
                    // two or three corners down a line of slivers, which the junction model
                    // (one sliver, the pattern flipping beyond it) does not describe where
                    // the light sliver merges with the margin.
                    let (_, corner, steps, _) = found(z, score);
                    Some((t, corner, steps, Some(cov)))
                };
                let regular = || -> Option<Verified> {
                    let (q, score, narrow) = verified?;
                    // A board's refiner (one guess of the blur): where it fails, the gradient
                    // estimate and the junction model below take over, and the walks' smaller
                    // guesses would accept more sites that are no junction.
                    let refined = REACHES.into_iter().find_map(|k| {
                        let r = refine_one_among(
                            image,
                            q,
                            &[],
                            &refine_at(k, params.max_offset * step),
                        );
                        (r.status != Status::Failed).then_some(([r.x, r.y], r.status))
                    });
                    let last_resort = || {
                        let g = GradientParams {
                            max_shift: params.max_offset * step,
                            ..params.gradient.clone()?
                        };
                        refine_gradient(image, q, &g).map(|c| (c.point, Status::Fallback))
                    };
                    let near = |&(z, _): &(P, Status)| norm(sub(z, p)) <= params.max_offset * step;
                    // On a sliver the walks' answer is tried first, then the gradient estimate:
                    // walks that see one side of a sliver's junction can end pixels off it, where
                    // nothing confirms them, while the gradient estimate lands on it (`curve_6.jpg`
                    // (5, 0), a 12 px sliver at the S's silhouette, 9 px). The gradient estimate
                    // needs the junction model: walks that come back to it from 1.5 px are no
                    // evidence when they found no junction themselves (under a 0.3 mm dot gain they
                    // accepted one 2.5 px off the truth). The junction model's own answer from the
                    // position the search verified.
                    let modelled = || junction_at(q).map(|j| (j, Status::Fallback)).filter(near);
                    let (z, status) = if narrow {
                        let gradient = std::iter::once_with(|| last_resort().map(|g| (g, false)));
                        let placed = refined
                            .map(|r| (r, true))
                            .into_iter()
                            .chain(gradient.flatten())
                            .filter(|(c, _)| near(c))
                            .find(|&((z, _), walked)| {
                                (walked && confirmed(z)) || junction_confirms(z)
                            })
                            .map(|(c, _)| c);
                        // Neither places it (a sliver a few pixels wide, blurred into its
                        // neighbours: the walks find no edge, and the gradient estimate lands
                        // pixels off): the junction model started at the junction the search
                        // verified, if it stays there.
                        placed.or_else(modelled)?
                    } else {
                        // Where the walks fail, the gradient estimate if the junction model
                        // confirms it, else the junction model's own answer from the verified
                        // position: beside a silhouette's slivers the gradient estimate lands
                        // pixels off a junction that the model keeps (on a 640 × 480 cylinder
                        // corners 1.5–2 px off, which then misled the predictions of the next
                        // rounds). The unconfirmed gradient estimate is the last resort.
                        match refined {
                            Some(r) => Some(r).filter(near),
                            None => {
                                let g = last_resort().filter(near);
                                g.filter(|&(z, _)| junction_confirms(z))
                                    .or_else(modelled)
                                    .or(g)
                            }
                        }?
                    };
                    // A site beyond the board's outer ring, verified in the full frame, grows the
                    // board: there a border square's outer corner next to an occluder or the
                    // background passes the verification too, and a one-sided walk or the gradient
                    // estimate placed it (110 px from any true corner, claiming σ 0.06 px). Only
                    // edges that go on past the corner on both sides, or the junction model, tell
                    // a junction from it.
                    if grows && !narrow && status != Status::Converged && !junction_confirms(z) {
                        return None;
                    }
                    Some(found(z, score))
                };
                if hairline_only {
                    hairline_site()
                } else {
                    regular().or_else(hairline_site)
                }
            })
            .collect();
        // In site order, the corners clear of every board's corners and of those accepted
        // before them this round: more than half a step away in the site's grid frame, so
        // that a sliver's corner, nearer its neighbour than half the mean step, is no
        // duplicate of it.
        let mut accepted: Vec<(Label, Corner, Option<Cov>)> = Vec::new();
        for (t, z, (u, v), hair) in checked.into_iter().flatten() {
            let clear = |x: f64, y: f64| in_steps([x - z.x, y - z.y], u, v) > 0.5;
            let free = boards
                .iter()
                .flat_map(|bd| bd.corners.iter())
                .all(|&i| clear(corners[i].x, corners[i].y))
                && accepted.iter().all(|(_, a, _)| clear(a.x, a.y));
            if free {
                accepted.push((t, z, hair));
            }
        }
        if accepted.is_empty() {
            if hairline_only {
                break;
            }
            hairline_only = true;
            continue;
        }
        for (t, c, hair) in accepted {
            grid.set(t, [c.x, c.y]);
            if let Some(cov) = hair {
                done.hairlines.insert(corners.len(), cov);
            }
            boards[b].corners.push(corners.len());
            boards[b].labels.push(t);
            corners.push(c);
            added += 1;
        }
    }
    if added > 0 {
        canonicalize(&mut boards[b]);
    }
    done.added += added;
}

/// `(min row, max row, min col, max col)` of non-empty `labels`.
fn range(labels: &[Label]) -> (i32, i32, i32, i32) {
    labels.iter().fold(
        (i32::MAX, i32::MIN, i32::MAX, i32::MIN),
        |(r0, r1, c0, c1), &(r, c)| (r0.min(r), r1.max(r), c0.min(c), c1.max(c)),
    )
}

/// Shifts labels to a minimum of 0, sorts by `(row, col)` and sets `rows`, `cols`.
fn canonicalize(board: &mut Board) {
    let pairs = board
        .labels
        .iter()
        .copied()
        .zip(board.corners.iter().copied());
    *board = board_from(pairs.collect());
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::connectivity::{connect, label, ConnectivityParams};
    use crate::election::find_corners;
    use crate::prefilter::PrefilterParams;
    use crate::synth::board::{BoardCorner, BoardScene, Dots, Occluder, Surface};
    use crate::synth::{speed_benchmark_scene, SPEED_BENCHMARK_NOISE_SEED};

    /// A 160 × 120 image of `f(x, y)` (image coordinates), averaged over 4 × 4 subpixels.
    fn paint(f: impl Fn(f64, f64) -> f32) -> GrayImage {
        let (w, h) = (160, 120);
        let mut data = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                let mut sum = 0.0;
                for k in 0..16 {
                    let (dx, dy) = ((k % 4) as f64 * 0.25 - 0.375, (k / 4) as f64 * 0.25 - 0.375);
                    sum += f(x as f64 + dx, y as f64 + dy);
                }
                data.push(sum / 16.0);
            }
        }
        GrayImage::from_vec(w, h, data).unwrap()
    }

    /// A checkerboard of 30 px squares with corners at (15 + 30 i, 15 + 30 j).
    fn checker(x: f64, y: f64) -> f32 {
        let (i, j) = (
            ((x - 15.0) / 30.0).floor() as i64,
            ((y - 15.0) / 30.0).floor() as i64,
        );
        if (i + j).rem_euclid(2) == 0 {
            0.9
        } else {
            0.1
        }
    }

    #[test]
    fn an_edge_is_seen_between_neighbours_only() {
        let board = paint(checker);
        assert!(edge_seen(&board, [45.0, 45.0], [75.0, 45.0]));
        assert!(edge_seen(&board, [75.0, 75.0], [75.0, 45.0]));
        // Two steps along a line: the squares swap sides at the corner in between.
        assert!(!edge_seen(&board, [45.0, 45.0], [105.0, 45.0]));
        // A cell's diagonal runs through the squares, along no edge.
        assert!(!edge_seen(&board, [45.0, 45.0], [75.0, 75.0]));
        // A grey band (a pen) across the middle of the link.
        let pen = paint(|x, y| {
            if (54.0..66.0).contains(&x) {
                0.3
            } else {
                checker(x, y)
            }
        });
        assert!(!edge_seen(&pen, [45.0, 45.0], [75.0, 45.0]));
        // The same band 9 px beside a link.
        assert!(edge_seen(&pen, [75.0, 45.0], [75.0, 75.0]));
    }

    #[test]
    fn an_edge_beside_a_sliver_or_bending_off_its_chord_is_seen() {
        // A dark sliver 4 px wide beside a light square, the background light beyond it (a
        // silhouette): the farther samples on the sliver's side are the background's.
        let sliver = paint(|x, _| match x {
            x if x < 40.0 => 0.8,
            x if x < 44.0 => 0.1,
            _ => 0.9,
        });
        assert!(edge_seen(&sliver, [44.0, 20.0], [44.0, 80.0]));
        // An edge bowing 5 px off the chord between its corners, as the tightest curves of the
        // curved-board benchmark: dark below the arc, light above.
        let arc = paint(|x, y| {
            let u = (x - 60.0) / 30.0;
            if y > 45.0 - 5.0 * (1.0 - u * u) {
                0.1
            } else {
                0.9
            }
        });
        assert!(edge_seen(&arc, [30.0, 45.0], [90.0, 45.0]));
    }

    /// The elected corners and the labelled boards of a rendered scene.
    fn labelled(
        scene: &BoardScene,
        seed: u64,
    ) -> (GrayImage, Vec<BoardCorner>, Vec<Corner>, Vec<Board>) {
        let r = scene.render(seed).expect("valid scene");
        let corners = find_corners(&r.image, &PrefilterParams::default(), &Default::default());
        let graph = connect(&corners, &ConnectivityParams::default());
        let boards = label(&corners, &graph);
        (r.image, r.corners, corners, boards)
    }

    fn nearest_truth(truth: &[BoardCorner], x: f64, y: f64) -> (f64, usize, usize) {
        truth
            .iter()
            .filter(|t| t.x.is_finite())
            .map(|t| ((t.x - x).hypot(t.y - y), t.row, t.col))
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .expect("truth")
    }

    /// The truth `(row, col)` of every board corner, checked to be within 1.5 px of the truth.
    fn truth_labels(
        board: &Board,
        corners: &[Corner],
        truth: &[BoardCorner],
    ) -> Vec<(Label, Label)> {
        board
            .corners
            .iter()
            .zip(&board.labels)
            .map(|(&i, &l)| {
                let (d, r, c) = nearest_truth(truth, corners[i].x, corners[i].y);
                assert!(d < 1.5, "corner {l:?} is {d:.2} px from the truth");
                ((r as i32, c as i32), l)
            })
            .collect()
    }

    /// Whether the label map truth → board is one affine lattice map (a symmetry and a shift).
    fn consistent(pairs: &[(Label, Label)]) -> bool {
        (0..8).any(|k| {
            let map = |(r, c): Label| {
                let (a, b) = if k & 4 != 0 { (c, r) } else { (r, c) };
                (
                    if k & 1 != 0 { -a } else { a },
                    if k & 2 != 0 { -b } else { b },
                )
            };
            let shift = |&(t, l): &(Label, Label)| {
                let m = map(t);
                (l.0 - m.0, l.1 - m.1)
            };
            pairs.iter().all(|p| shift(p) == shift(&pairs[0]))
        })
    }

    fn scene(surface: Surface) -> BoardScene {
        let mut s = speed_benchmark_scene();
        s.surface = surface;
        s
    }

    /// Removes the corners of the board at the given positions (by index into its list).
    fn remove(board: &mut Board, keep: impl Fn(Label) -> bool) -> usize {
        let before = board.corners.len();
        let (c, l): (Vec<usize>, Vec<Label>) = board
            .corners
            .iter()
            .zip(&board.labels)
            .filter(|(_, &l)| keep(l))
            .map(|(&i, &l)| (i, l))
            .unzip();
        board.corners = c;
        board.labels = l;
        before - board.corners.len()
    }

    #[test]
    fn removed_corners_come_back_with_their_labels() {
        for (surface, seed) in [
            (Surface::Flat, SPEED_BENCHMARK_NOISE_SEED),
            (Surface::SShape { radius_mm: 80.0 }, 3),
        ] {
            let (image, truth, mut corners, mut boards) = labelled(&scene(surface), seed);
            assert_eq!(boards.len(), 1);
            let full = boards[0].corners.len();
            let (rows, cols) = (boards[0].rows as i32, boards[0].cols as i32);
            // An inner block, one whole column, a board corner and one outer-ring row.
            let removed = remove(&mut boards[0], |(r, c)| {
                !((3..=4).contains(&r) && (3..=5).contains(&c))
                    && c != 1
                    && (r, c) != (rows - 1, cols - 1)
                    && r != 0
            });
            let added = complete_boards(
                &image,
                &mut corners,
                &mut boards,
                &CompletionParams::default(),
            )
            .added;
            assert_eq!(added, removed, "{surface:?}");
            assert_eq!(boards[0].corners.len(), full);
            assert_eq!(
                (boards[0].rows, boards[0].cols),
                (rows as usize, cols as usize)
            );
            assert!(
                consistent(&truth_labels(&boards[0], &corners, &truth)),
                "{surface:?}"
            );
        }
    }

    #[test]
    fn nothing_is_added_to_a_complete_board() {
        let (image, _, mut corners, mut boards) =
            labelled(&speed_benchmark_scene(), SPEED_BENCHMARK_NOISE_SEED);
        let before = boards.clone();
        let added = complete_boards(
            &image,
            &mut corners,
            &mut boards,
            &CompletionParams::default(),
        )
        .added;
        assert_eq!(added, 0);
        assert_eq!(boards, before);
    }

    #[test]
    fn an_occluder_over_corners_completes_nothing_there() {
        // A dark bar and a bright one, each hiding a column of corners; with dots.
        for intensity in [0.15, 0.85] {
            let mut s = scene(Surface::Flat);
            s.dots = Some(Dots {
                radius: 0.2,
                fraction: 0.4,
                seed: 7,
            });
            let c = s.corners().expect("valid");
            let at = |r: usize, k: usize| c.iter().find(|t| t.row == r && t.col == k).unwrap();
            let (a, b) = (at(0, 4), at(s.rows - 1, 4));
            let (dx, dy) = (b.x - a.x, b.y - a.y);
            let len = dx.hypot(dy);
            let step = (at(0, 5).x - a.x).hypot(at(0, 5).y - a.y);
            s.occluders = vec![Occluder {
                from: [a.x - dx / len * 3.0 * step, a.y - dy / len * 3.0 * step],
                to: [b.x + dx / len * 3.0 * step, b.y + dy / len * 3.0 * step],
                width: 0.4 * step,
                intensity,
            }];
            let (image, truth, mut corners, mut boards) = labelled(&s, 11);
            let n0: usize = boards.iter().map(|b| b.corners.len()).sum();
            complete_boards(
                &image,
                &mut corners,
                &mut boards,
                &CompletionParams::default(),
            );
            let n1: usize = boards.iter().map(|b| b.corners.len()).sum();
            for b in &boards {
                for &i in &b.corners {
                    let (d, _, col) = nearest_truth(&truth, corners[i].x, corners[i].y);
                    assert!(d < 1.5, "false corner {d:.2} px from the truth");
                    assert_ne!(col, 4, "a corner under the bar was completed");
                }
                assert!(consistent(&truth_labels(b, &corners, &truth)));
            }
            eprintln!("bar {intensity}: {n0} → {n1} corners");
        }
    }

    #[test]
    fn bad_input_is_left_alone() {
        let image = GrayImage::from_vec(32, 32, vec![0.5; 32 * 32]).unwrap();
        let mut corners = vec![Corner {
            x: 10.0,
            y: 10.0,
            angles: [0.0, 1.5],
            score: 0.9,
        }];
        let mut boards = vec![Board {
            corners: vec![0, 5],
            labels: vec![(0, 0), (0, 1)],
            rows: 1,
            cols: 2,
        }];
        let before = boards.clone();
        assert_eq!(
            complete_boards(
                &image,
                &mut corners,
                &mut boards,
                &CompletionParams::default()
            )
            .added,
            0
        );
        assert_eq!(boards, before);
        // A flat image around a tiny "board": no reference, nothing added.
        boards[0].corners = vec![0, 0];
        assert_eq!(
            complete_boards(
                &image,
                &mut corners,
                &mut boards,
                &CompletionParams::default()
            )
            .added,
            0
        );
        assert_eq!(corners.len(), 1);
    }

    /// A checkerboard whose square sides are `xs`, `ys` (pixel-centre coordinates), on white
    /// paper, anti-aliased by 8 × 8 supersampling.
    fn ruled_board(width: usize, height: usize, xs: &[f64], ys: &[f64]) -> GrayImage {
        let cell = |v: f64, edges: &[f64]| edges.iter().filter(|&&e| v >= e).count();
        let mut data = vec![0f32; width * height];
        for (k, f) in data.iter_mut().enumerate() {
            let (x, y) = ((k % width) as f64, (k / width) as f64);
            let mut sum = 0.0;
            for i in 0..8 {
                for j in 0..8 {
                    let (sx, sy) = (
                        x + (i as f64 + 0.5) / 8.0 - 0.5,
                        y + (j as f64 + 0.5) / 8.0 - 0.5,
                    );
                    let (cx, cy) = (cell(sx, xs), cell(sy, ys));
                    let inside = (1..xs.len()).contains(&cx) && (1..ys.len()).contains(&cy);
                    sum += if inside && (cx + cy) % 2 == 0 {
                        40.0
                    } else {
                        210.0
                    };
                }
            }
            *f = sum / 64.0;
        }
        GrayImage::from_vec(width, height, data).expect("valid size")
    }

    /// A board whose first column of squares is `sliver` px wide, as at a cylinder's
    /// silhouette (the rest are 40 px), blurred by `blur`. Whatever of the sliver corners the
    /// election finds is taken off the labelled board (photos defeat it where renders may not),
    /// and completion runs with `params`: returns how many corners it added and the largest
    /// distance of a board corner from its truth.
    fn sliver_case(sliver: f64, blur: f64, params: &CompletionParams) -> (usize, f64) {
        let xs = [20.0, 20.0 + sliver, 68.0, 108.0, 148.0, 188.0, 228.0, 268.0];
        let ys = [20.0, 60.0, 100.0, 140.0, 180.0, 220.0, 260.0];
        let image = crate::synth::gaussian_blur(&ruled_board(290, 280, &xs, &ys), blur);
        let mut corners = find_corners(&image, &PrefilterParams::default(), &Default::default());
        let graph = connect(&corners, &ConnectivityParams::default());
        let mut boards = label(&corners, &graph);
        assert_eq!(boards.len(), 1);
        let on_sliver = |p: &Corner| (p.x - xs[1]).abs() < 2.0;
        let sliver_labels: Vec<Label> = boards[0]
            .corners
            .iter()
            .zip(&boards[0].labels)
            .filter(|(&i, _)| on_sliver(&corners[i]))
            .map(|(_, &l)| l)
            .collect();
        remove(&mut boards[0], |l| !sliver_labels.contains(&l));
        let before = boards[0].corners.len();
        let added = complete_boards(&image, &mut corners, &mut boards, params).added;
        assert_eq!(boards[0].corners.len(), before + added);
        let worst = boards[0]
            .corners
            .iter()
            .zip(&boards[0].labels)
            .map(|(&i, &l)| {
                let (x, y) = (xs[l.1 as usize + 1], ys[l.0 as usize + 1]);
                (corners[i].x - x).hypot(corners[i].y - y)
            })
            .fold(0.0, f64::max);
        (added, worst)
    }

    #[test]
    fn sliver_squares_at_a_silhouette_get_their_corners() {
        // One per sliver corner, each on its junction.
        let (added, worst) = sliver_case(3.0, 1.5, &CompletionParams::default());
        assert_eq!(added, 5);
        assert!(worst < 1.0, "{worst}");
        // A sliver of 2 px: with only the walks' and the gradient estimate's answers as
        // candidates, two of its corners stayed out (three added, the worst 0.01 px off).
        let (added, worst) = sliver_case(2.0, 0.8, &CompletionParams::default());
        assert_eq!(added, 5);
        assert!(worst < 0.5, "{worst}");
    }

    #[test]
    fn a_column_of_hairline_slivers_grows_from_its_first_corners() {
        // Slivers of 1 and 1.5 px beside squares of 40–48 px: no frame of the search sees them,
        // and the election finds none of their corners. Given the first two (as the photos'
        // other checks find them where the sliver is wider), the rest are found one a round,
        // where the boundary line's polarity flips.
        for (sliver, blur) in [(1.0, 0.8), (1.5, 1.0)] {
            let xs = [20.0, 20.0 + sliver, 68.0, 108.0, 148.0, 188.0, 228.0, 268.0];
            let ys = [20.0, 60.0, 100.0, 140.0, 180.0, 220.0, 260.0];
            let image = crate::synth::gaussian_blur(&ruled_board(290, 280, &xs, &ys), blur);
            let mut corners =
                find_corners(&image, &PrefilterParams::default(), &Default::default());
            let graph = connect(&corners, &ConnectivityParams::default());
            let mut boards = label(&corners, &graph);
            assert_eq!(boards.len(), 1);
            // The board's labels at the first full column (x = 68) and first row (y = 60).
            let at = |x: f64, y: f64| {
                let i = boards[0]
                    .corners
                    .iter()
                    .position(|&i| (corners[i].x - x).hypot(corners[i].y - y) < 1.0)
                    .expect("a labelled corner");
                boards[0].labels[i]
            };
            let (origin, next) = (at(68.0, 60.0), at(68.0, 100.0));
            let (dr, dc) = (next.0 - origin.0, next.1 - origin.1);
            assert!(dr.abs() + dc.abs() == 1, "{origin:?} {next:?}");
            // One step across the columns, away from x = 108.
            let beyond = {
                let l = at(108.0, 60.0);
                (origin.0 - (l.0 - origin.0), origin.1 - (l.1 - origin.1))
            };
            for k in 0..2 {
                boards[0].corners.push(corners.len());
                boards[0]
                    .labels
                    .push((beyond.0 + k * dr, beyond.1 + k * dc));
                let (x, y) = (xs[1], ys[1 + k as usize]);
                corners.push(Corner {
                    x,
                    y,
                    angles: [0.0, std::f64::consts::FRAC_PI_2],
                    score: 1.0,
                });
            }
            let done = complete_boards(&image, &mut corners, &mut boards, &Default::default());
            let added = done.added;
            // Each added one is a hairline fit whose covariance owns up to its error.
            assert_eq!(done.hairlines.len(), 3, "{sliver} px");
            for (&i, &cov) in &done.hairlines {
                let truth = ys
                    .iter()
                    .map(|&y| [xs[1], y])
                    .min_by(|a, b| {
                        let d = |t: &[f64; 2]| (corners[i].x - t[0]).hypot(corners[i].y - t[1]);
                        d(a).total_cmp(&d(b))
                    })
                    .expect("rows");
                let error = (corners[i].x - truth[0]).hypot(corners[i].y - truth[1]);
                let sigma = crate::quadratic_form::worst_sigma(cov);
                assert!(
                    error < 3.0 * sigma,
                    "{sliver} px: {error} px off, σ {sigma}"
                );
            }
            let on_sliver: Vec<f64> = boards[0]
                .corners
                .iter()
                .filter(|&&i| (corners[i].x - xs[1]).abs() < 2.0)
                .map(|&i| {
                    let y = ys
                        .iter()
                        .map(|&y| (corners[i].y - y).abs())
                        .fold(f64::INFINITY, f64::min);
                    (corners[i].x - xs[1]).hypot(y)
                })
                .collect();
            // The three other corners of the sliver column, each within half a pixel.
            assert_eq!((added, on_sliver.len()), (3, 5), "{sliver} px");
            assert!(
                on_sliver.iter().all(|&d| d < 0.5),
                "{sliver} px: {on_sliver:?}"
            );
        }
    }

    #[test]
    fn hairline_needs_the_boundary_line_s_polarity_to_flip() {
        // The grid line x = 40 with squares of 40 px to its right (rows split at y = 60) and,
        // to its left, either a dark sliver of 1.5 px beside the light square and the light
        // margin beyond (a junction), or the margin alone (a printed border: no junction).
        let board = |sliver: bool| {
            let image = paint(|x, y| {
                let light_square = y >= 60.0;
                if x >= 40.0 {
                    if light_square {
                        200.0
                    } else {
                        30.0
                    }
                } else if sliver && light_square && x >= 38.5 {
                    30.0
                } else {
                    210.0
                }
            });
            crate::synth::gaussian_blur(&image, 0.9)
        };
        // The site predicted 1.5 px off the junction (40, 60); steps of 40 px; the square
        // below the row line (side 0) is the bright one.
        let (p, inward, along) = ([41.0, 61.0], [40.0, 0.0], [[0.0, 40.0], [0.0, -40.0]]);
        let found = hairline(&board(true), p, inward, along, [true, false], 80.0, 0.7);
        let Hairline {
            point: z,
            score,
            cov,
        } = found.expect("a junction beside the sliver");
        // On the dark square's side the boundary is where the level is halfway to the light
        // beyond; the light side's quarter-contrast crossings lie 0.67 σ inside, which the
        // covariance owns up to, as it does to a third of the blur.
        assert!(
            (z[0] - 40.0).abs() < 0.1 && (z[1] - 60.0).abs() < 0.1,
            "{z:?}"
        );
        let sigma = crate::quadratic_form::worst_sigma(cov);
        assert!((0.3..0.6).contains(&sigma), "{sigma}");
        assert!(score > 0.9, "{score}");
        assert!(hairline(&board(false), p, inward, along, [true, false], 80.0, 0.7).is_none());
        // The expected colours the other way round: no junction of this phase.
        assert!(hairline(&board(true), p, inward, along, [false, true], 80.0, 0.7).is_none());
    }

    /// A board walked two rows per step (as across alternate rows hidden by occluders) is
    /// dropped; a board whose right half is one column off becomes two correctly labelled
    /// boards; in a correct board, a corner whose label is off by one column is dropped alone.
    #[test]
    fn labels_that_contradict_the_checker_pattern_are_split_off() {
        let (image, truth, corners, boards) =
            labelled(&speed_benchmark_scene(), SPEED_BENCHMARK_NOISE_SEED);
        assert_eq!(boards.len(), 1);
        let whole = boards[0].clone();
        let truth_of = |i: usize| {
            let (d, r, c) = nearest_truth(&truth, corners[i].x, corners[i].y);
            assert!(d < 1.5);
            (r as i32, c as i32)
        };
        let relabelled = |f: &dyn Fn(Label) -> Option<Label>| {
            let (mut idx, mut labels) = (Vec::new(), Vec::new());
            for &i in &whole.corners {
                if let Some(l) = f(truth_of(i)) {
                    idx.push(i);
                    labels.push(l);
                }
            }
            let mut b = Board {
                corners: idx,
                labels,
                rows: 0,
                cols: 0,
            };
            canonicalize(&mut b);
            b
        };
        let mut kept = vec![whole.clone()];
        assert_eq!(split_by_phase(&image, &corners, &mut kept, 4), 0);
        assert_eq!(kept, std::slice::from_ref(&whole));

        // True rows 0, 2, 4 and 6 labelled 0..3.
        let mut skipping = vec![relabelled(&|(r, c)| (r % 2 == 0).then_some((r / 2, c)))];
        let n = skipping[0].corners.len();
        assert!(n >= 30);
        assert_eq!(split_by_phase(&image, &corners, &mut skipping, 4), n);
        assert!(skipping.is_empty());

        // Columns from 5 on one label too far right.
        let mut halves = vec![relabelled(&|(r, c)| Some((r, c + i32::from(c >= 5))))];
        assert_eq!(split_by_phase(&image, &corners, &mut halves, 4), 0);
        assert_eq!(halves.len(), 2);
        assert_eq!(
            halves.iter().map(|b| b.corners.len()).sum::<usize>(),
            whole.corners.len()
        );
        for b in &halves {
            assert!(consistent(&truth_labels(b, &corners, &truth)));
        }

        // An inner corner given its right-hand neighbour's label, which is then unused.
        let mut shifted = whole.clone();
        let k = shifted.labels.iter().position(|&l| l == (4, 4)).unwrap();
        let right = shifted.labels.iter().position(|&l| l == (4, 5)).unwrap();
        shifted.labels[k] = (4, 5);
        shifted.labels.remove(right);
        shifted.corners.remove(right);
        let mut boards = vec![shifted];
        assert_eq!(split_by_phase(&image, &corners, &mut boards, 4), 1);
        assert_eq!(boards.len(), 1);
        assert!(!boards[0].labels.contains(&(4, 5)));
        assert_eq!(boards[0].corners.len(), whole.corners.len() - 2);
    }

    proptest::proptest! {
        /// The frame of a site does not depend on which way the labels run: the same corners
        /// labelled backwards along both axes, or with rows and columns swapped, give the same
        /// frame, its sides exchanged and its steps turned accordingly.
        #[test]
        fn a_frame_does_not_depend_on_the_labels_order(
            bend in -0.6f64..0.6,
            shear in -0.3f64..0.3,
            holes in proptest::collection::vec(proptest::bool::weighted(0.3), 49),
            site in (0i32..7, 0i32..7),
        ) {
            let n = 7;
            let position = |(r, c): Label| -> P {
                let (r, c) = (r as f64, c as f64);
                [30.0 * c + bend * c * c + shear * 30.0 * r, 30.0 * r - bend * r * c]
            };
            let kept: Vec<Label> = (0..n * n)
                .filter(|&k| !holes[k as usize])
                .map(|k| (k / n, k % n))
                .collect();
            let grid = |map: &dyn Fn(Label) -> Label| {
                let labels: Vec<Label> = kept.iter().map(|&t| map(t)).collect();
                Grid::new(&labels, kept.iter().map(|&t| position(t)), 3)
            };
            let reversed = |(r, c): Label| (n - 1 - r, n - 1 - c);
            let swapped = |(r, c): Label| (c, r);
            let close = |a: P, b: P| (a[0] - b[0]).abs() < 1e-9 && (a[1] - b[1]).abs() < 1e-9;
            let Some(f) = grid(&|t| t).frame(site) else {
                return Ok(());
            };
            let g = grid(&reversed).frame(reversed(site)).unwrap();
            for i in 0..2 {
                proptest::prop_assert!(close(g.u[i], scale(f.u[1 - i], -1.0)), "{:?} {:?}", f, g);
                proptest::prop_assert!(close(g.v[i], scale(f.v[1 - i], -1.0)), "{:?} {:?}", f, g);
            }
            let h = grid(&swapped).frame(swapped(site)).unwrap();
            proptest::prop_assert!(close(h.u[0], f.v[0]) && close(h.u[1], f.v[1]), "{:?} {:?}", f, h);
            proptest::prop_assert!(close(h.v[0], f.u[0]) && close(h.v[1], f.u[1]), "{:?} {:?}", f, h);
        }
    }

    #[test]
    fn offsets_are_measured_in_the_grid_steps() {
        // Steps of 7 px across the columns and 15 px along them, sheared.
        let (u, v) = ([7.0, 1.0], [-4.0, 15.0]);
        let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
        assert!(close(in_steps(scale(u, 0.7), u, v), 0.7));
        assert!(close(
            in_steps(add(scale(u, 0.3), scale(v, -0.4)), u, v),
            0.5
        ));
        // Nearly parallel steps: the plain length over the mean step.
        assert!(close(in_steps([5.0, 0.0], [10.0, 0.0], [10.0, 1e-9]), 0.5));
    }

    #[test]
    fn consensus_needs_two_agreeing_predictions() {
        assert_eq!(consensus(&mut [[0.0, 0.0]], 1.0), None);
        assert_eq!(consensus(&mut [[0.0, 0.0], [5.0, 0.0]], 1.0), None);
        let p = consensus(&mut [[0.0, 0.0], [0.5, 0.0], [9.0, 9.0]], 1.0).unwrap();
        assert!((p[0] - 0.25).abs() < 1e-12 && p[1] == 0.0);
    }
}
