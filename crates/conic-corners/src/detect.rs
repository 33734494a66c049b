//! The whole detection pipeline on one image: Hessian pre-filter → template election → Delaunay
//! connectivity and grid labels → grid completion → subpixel refinement of every labelled corner.
//!
//! Coordinates: x right, y down, the centre of the top-left pixel is `(0, 0)`.

use crate::board_fit::{fit_board_full, BoardFitParams, Path};
use crate::completion::{
    board_phase, complete_boards, edge_seen, split_by_phase, CompletionParams,
};
use crate::connectivity::{
    connect_seen, label_with, merge_split_boards, Board as LabelledBoard, ConnectivityParams,
    Graph, LabelParams,
};
use crate::election::{elect_scales, Corner, ElectionParams};
use crate::gradient::{self, refine_gradient, GradientParams};
use crate::junction::{refine_junction_at_boundary, JunctionParams};
use crate::pattern::{to_pattern, Pattern};
use crate::prefilter::{prefilter_scales, PrefilterParams, Scales};
use crate::quadratic_form::worst_sigma;
use crate::refine::{refine_one_among, RefineParams, Status};
use crate::segmentation::median_mad_in_place;
use crate::spacing::{self, SpacingParams};
use crate::variance_factor::{self, VarianceFactorParams};
use crate::GrayImage;
use nalgebra::{Matrix2, Vector2};
use rayon::prelude::*;
use std::time::Instant;

/// Parameters of [`detect`]: one block per stage. `Default` is what the CLI uses.
#[derive(Clone, Debug)]
pub struct DetectParams {
    /// Pre-filter (III-A). Its `expected_corners` is the optional N of the paper.
    pub prefilter: PrefilterParams,
    /// Final election (III-B).
    pub election: ElectionParams,
    /// Connectivity (III-C).
    pub connectivity: ConnectivityParams,
    /// Labelling (III-C): smallest board kept.
    pub labels: LabelParams,
    /// Grid completion: missing corners predicted from the labelled grid and verified
    /// (`rounds = 0` disables it).
    pub completion: CompletionParams,
    /// Subpixel refinement of each corner; its `reach` is further bounded by the corner's
    /// distance to its farthest grid neighbour.
    pub refine: RefineParams,
    /// How corners are finally placed.
    pub mode: RefineMode,
    /// Board-wide fitting (III-D to III-F along whole grid lines), for [`RefineMode::Board`].
    pub board_fit: BoardFitParams,
    /// The last-resort refiner ([`crate::gradient`]): it places the corners that the local
    /// refiner fails on, where no labelled neighbour is nearer than four window radii (the
    /// window must hold that junction alone). `None` disables it, and those corners keep their
    /// pixel-level position.
    pub gradient: Option<GradientParams>,
    /// The junction-model refiner ([`crate::junction`]): it places the corners whose edge walks
    /// are one-sided or failed, before the gradient estimate is tried, and it is combined by
    /// inverse covariances with the board-wide answers whose σ is above
    /// [`DetectParams::junction_gate`] times their board's median σ, at most 0.1 px (taking the
    /// one with the smaller σ where the two disagree, its covariance widened by half the outer
    /// product of their difference after the spacing fusion). `None` disables it.
    pub junction: Option<JunctionParams>,
    /// A board-wide answer whose σ exceeds this multiple of its board's median σ (at most 0.1 px;
    /// less support than most: curved, short or extrapolated lines) is combined with the junction
    /// model's answer. Default 1.5. Lower is more accurate and slower: at 1.0 (measured at
    /// `56ebd3c`) the curved-board benchmark's corners go 0.0070 → 0.0066 px RMS (flattest
    /// curvature bin 0.0064 → 0.0061, top bin 0.0148 → 0.0143), but `detect` on the speed
    /// benchmark's flat board takes 14.8 → 22.7 ms (at `b03cdf6` half its corners got a junction
    /// fit), on `curve_6.jpg` 99 → 113 ms and on `marker_real2.jpg` 93 → 107 ms (one thread,
    /// median of 7). `∞` combines only the doubtful answers.
    pub junction_gate: f64,
    /// A board-wide answer whose σ exceeds this multiple of the board's median σ (at most 0.1 px)
    /// is doubtful: the corner goes to the local refiner, and to the junction model (failing that,
    /// the gradient estimate) unless the local refiner converges with both edges seen on both
    /// sides. A converged local answer is kept unless the doubtful board-wide answer claims a
    /// smaller σ. The junction model's answer replaces the doubtful board-wide one; a gradient
    /// estimate that agrees with the board-wide answer within its σ is averaged with it, one that
    /// does not replaces it; without a board-wide answer, a one-sided local answer and the junction
    /// model's (or the gradient estimate's) answer compete by σ. It happens at the ends of grid
    /// lines next to a silhouette, where the squares are foreshortened to a few pixels and the
    /// curves are extrapolated. The limit is relative so that it holds at any image scale, blur and
    /// noise. `∞` keeps every board-wide answer. A doubtful board-wide answer that stands (nothing
    /// better places the corner) is reported with status `Fallback`.
    pub max_board_sigma: f64,
    /// Keep the corners that no refiner could place (status `Failed`, at their pixel-level
    /// position). By default they are dropped: on about 900 rendered scenes (occluders, dot
    /// gain, blur, distortion, strong bending) every such corner was a false one, an outer
    /// corner of a border square or a stroke crossing an edge that passed for a junction, or a
    /// junction hidden behind a silhouette; on the real photos there are none.
    pub keep_unrefined: bool,
    /// The a-posteriori variance factor ([`crate::variance_factor`]): every board's covariances
    /// are scaled by how far its corners stray from a smooth grid against what they claim
    /// ([`Board::sigma_scale`]). `None` reports the covariances as the fits gave them.
    pub variance_factor: Option<VarianceFactorParams>,
    /// [`RefineMode::Board`] only: each corner's position along its straight grid lines fused
    /// with what the spacing law of its six neighbours on each line predicts
    /// ([`crate::spacing`]), after the variance factor has scaled the covariances that weigh
    /// them. `None` leaves the corners where the refiners put them.
    pub spacing: Option<SpacingParams>,
    /// The board's inner-corner grid, when known (a calibration target): every board that spans
    /// it is labelled in its frame, `(0, 0)` at a corner of the print that the colours or, failing
    /// them, the image fix ([`crate::pattern`]), so that all views of the board label each
    /// physical corner alike; boards that do not span it (partly hidden, or other boards) are
    /// dropped. `None`: boards of any size, labelled by the image ([`crate::connectivity`]).
    pub pattern: Option<Pattern>,
}

/// How [`detect`] places the corners after the pixel-level detection.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum RefineMode {
    /// Each corner by the single-corner refiner ([`crate::refine`]).
    Local,
    /// Each corner as the intersection of its row and column curves fitted along the whole board
    /// ([`crate::board_fit`]), the local answer where a line has too few samples.
    #[default]
    Board,
}

impl Default for DetectParams {
    /// Every stage's defaults, except that edges are sampled on every second scanline
    /// (`refine.stride = board_fit.stride = 2`): this halves the sampling time for about 0.002 px
    /// more error (median 0.004 instead of 0.003 px on the speed benchmark's board with board-wide
    /// fitting, 0.006 instead of 0.004 px with the local refiner).
    fn default() -> Self {
        Self {
            prefilter: PrefilterParams::default(),
            election: ElectionParams::default(),
            connectivity: ConnectivityParams::default(),
            labels: LabelParams::default(),
            completion: CompletionParams::default(),
            refine: RefineParams {
                stride: 2,
                ..RefineParams::default()
            },
            mode: RefineMode::default(),
            board_fit: BoardFitParams {
                stride: 2,
                ..BoardFitParams::default()
            },
            gradient: Some(GradientParams::default()),
            junction: Some(JunctionParams::default()),
            max_board_sigma: 5.0,
            junction_gate: 1.5,
            keep_unrefined: false,
            variance_factor: Some(VarianceFactorParams::default()),
            spacing: Some(SpacingParams::default()),
            pattern: None,
        }
    }
}

impl DetectParams {
    /// Copies the refiner's sampling settings (`stride`, `blur`) into the board-wide fit, so that
    /// one setting controls both kinds of edge walk (the CLI and the Python package do this after
    /// applying the user's options).
    pub fn share_sampling(&mut self) {
        self.board_fit.stride = self.refine.stride;
        self.board_fit.blur = self.refine.blur;
    }

    /// Checks the parameters a user sets; the message names the offending one.
    pub fn validate(&self) -> Result<(), String> {
        if self.prefilter.expected_corners == Some(0) {
            return Err("the expected corner count must be at least 1".into());
        }
        let sigma = self.prefilter.sigma;
        if !(sigma.is_finite() && (0.5..=32.0).contains(&sigma)) {
            return Err(format!(
                "the pre-filter scale sigma must be in 0.5..=32 px, got {sigma}"
            ));
        }
        if self.max_board_sigma.is_nan() || self.max_board_sigma <= 0.0 {
            return Err(format!(
                "the largest board-wide sigma ratio must be positive, got {}",
                self.max_board_sigma
            ));
        }
        if self.junction_gate.is_nan() || self.junction_gate <= 0.0 {
            return Err(format!(
                "the junction gate (a multiple of the board's median sigma) must be positive, got {}",
                self.junction_gate
            ));
        }
        if let Some(g) = &self.gradient {
            g.validate()?;
        }
        if let Some(j) = &self.junction {
            j.validate()?;
        }
        if let Some(p) = &self.pattern {
            p.validate()?;
        }
        self.refine.validate()
    }
}

/// One labelled, refined corner of a board.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DetectedCorner {
    /// Subpixel position (image coordinates).
    pub x: f64,
    /// Subpixel position (image coordinates).
    pub y: f64,
    /// Row on the board: rows increase towards +y (see [`crate::connectivity`]), or in the frame
    /// of [`DetectParams::pattern`] when it is given.
    pub row: i32,
    /// Column on the board: columns increase towards +x, or as `row`.
    pub col: i32,
    /// Template-matching score of the corner (normalized cross-correlation).
    pub score: f64,
    /// How the subpixel position was obtained: `Converged` for board-wide answers and the local
    /// refiner's full answers, `Fallback` for its answers with less support, for the junction
    /// model and the gradient estimate, for a board-wide answer whose σ is above its board's
    /// limit ([`DetectParams::max_board_sigma`]) kept for want of a better one, and for a
    /// board-wide answer taken although it lies farther than the board fit's
    /// `max_shift` from the pixel-level position where no refiner could place the corner (one
    /// that far but as sure as the board answers that need no junction fit, within the local
    /// refiner's `max_shift` and nearer to its own corner than to any other, is `Converged`);
    /// `Failed` keeps the pixel-level position (only with [`DetectParams::keep_unrefined`]).
    pub status: Status,
    /// RMS distance (px) of the edge samples to their curves; `None` when not refined.
    pub residual: Option<f64>,
    /// Which refiner placed the corner.
    pub path: Path,
    /// Standard deviation (px) of the position in its worst direction, propagated from the
    /// residuals of the fits that placed it (board-wide or local curves, the junction model's
    /// pixels, or the gradient estimate, whose σ is conservative); `None` when refinement
    /// failed or the local refiner's
    /// curves did not meet.
    pub sigma: Option<f64>,
    /// Covariance (px², image axes: `[[var x, cov xy], [cov xy, var y]]`) of the position, from
    /// the same fits; `sigma` is the square root of its larger eigenvalue. Where one of the
    /// corner's curves is short or extrapolated, the position is far surer across the other
    /// curve than along it, which `sigma` alone cannot say: weigh a pose or calibration fit with
    /// the inverse covariance. `None` when `sigma` is.
    pub cov: Option<Cov>,
}

/// A board: its labelled corners, sorted by `(row, col)`.
#[derive(Clone, Debug, PartialEq)]
pub struct Board {
    /// `1 + max row`.
    pub rows: usize,
    /// `1 + max col`.
    pub cols: usize,
    /// The corners.
    pub corners: Vec<DetectedCorner>,
    /// The factor by which every corner's σ was scaled ([`crate::variance_factor`]; the
    /// covariances by its square): how far the corners stray from a smooth grid, measured along
    /// its straight lines, against the σ their fits claimed. About 1 on clean renders, 2–3 on
    /// real photos of printed boards. `None` where the board has too few straight runs of six
    /// corners to tell, or [`DetectParams::variance_factor`] is `None`; the σ are then as the
    /// fits gave them.
    pub sigma_scale: Option<f64>,
}

/// Wall-clock time of each stage, milliseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Timing {
    /// Hessian score, non-maximum suppression, candidate selection.
    pub prefilter: f64,
    /// Template election.
    pub election: f64,
    /// Delaunay connectivity and labels.
    pub connectivity: f64,
    /// Grid completion.
    pub completion: f64,
    /// Subpixel refinement of each corner.
    pub refine: f64,
    /// Board-wide fitting ([`RefineMode::Board`] only).
    pub board_fit: f64,
    /// The whole of [`detect`].
    pub total: f64,
}

/// What [`detect`] found: every board (largest first) and the time each stage took.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Detection {
    /// Boards, largest first. Empty when no board is in view.
    pub boards: Vec<Board>,
    /// Stage timings.
    pub timing: Timing,
}

/// Ceiling (px) on the board's typical σ in [`DetectParams::junction_gate`] and
/// [`DetectParams::max_board_sigma`]. Where most of a board's curves are themselves poor (squares
/// of 6–10 px, whose lines' pieces are a square or two long), the median σ of its board-wide
/// answers reached hundreds of pixels, and gates relative to it accepted answers 1 px off
/// without a junction fit. The median is 0.004–0.065 px on the photos and in every cell of the
/// robustness report, so the ceiling leaves them alone.
const TYPICAL_SIGMA_CEILING: f64 = 0.1;

fn ms(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1e3
}

/// Finds every checkerboard-like board in `image`, labels its corners with `(row, col)` and
/// refines them to subpixel accuracy. Parameters are expected to be valid
/// ([`DetectParams::validate`]); an image without a board gives no boards.
pub fn detect(image: &GrayImage, params: &DetectParams) -> Detection {
    let t0 = Instant::now();
    let scales = Scales::new(image);
    let candidates = prefilter_scales(&scales, &params.prefilter);
    let prefilter_ms = ms(t0);
    let t = Instant::now();
    let mut corners = elect_scales(&scales, &candidates, &params.election);
    drop(scales); // the average, a quarter of the image, is not needed further on
    let election_ms = ms(t);
    let t = Instant::now();
    let graph = connect_seen(&corners, &params.connectivity, |i, j| {
        let (a, b) = (&corners[i], &corners[j]);
        edge_seen(image, [a.x, a.y], [b.x, b.y])
    });
    let mut labelled = label_with(&corners, &graph, &params.labels);
    let connectivity_ms = ms(t);
    // Completed corners are appended to `corners` (beyond `graph`'s range) and go through the
    // same refinement as the others.
    let t = Instant::now();
    // Before completion, so that the corners of a piece dropped for its labels are free to be
    // completed into the board they belong to.
    split_by_phase(image, &corners, &mut labelled, params.labels.min_corners);
    let mut hairlines =
        complete_boards(image, &mut corners, &mut labelled, &params.completion).hairlines;
    // Two pieces of a board that a pen or a finger split may line up across the gap along two
    // grid lines (what a merge needs) only once each has been completed up to it.
    let pieces = labelled.len();
    labelled = merge_split_boards(&corners, labelled, |b| board_phase(image, &corners, b));
    if labelled.len() < pieces {
        let again = complete_boards(image, &mut corners, &mut labelled, &params.completion);
        hairlines.extend(again.hairlines);
    }
    let completion_ms = ms(t);
    // Board mode fits the grid lines from the pixel-level corners (the walks measure the edges
    // themselves, and the fit only needs a corner within `max_shift` of the truth), so the local
    // refiner runs only where the board-wide fit falls back.
    let (mut refine_ms, mut board_fit_ms) = (0.0, 0.0);
    let mut boards = Vec::with_capacity(labelled.len());
    for b in &labelled {
        let t = Instant::now();
        let fitted = (params.mode == RefineMode::Board).then(|| {
            let pixel = Board {
                rows: b.rows,
                cols: b.cols,
                corners: b
                    .corners
                    .iter()
                    .zip(&b.labels)
                    .map(|(&i, &(row, col))| pixel_corner(&corners[i], row, col))
                    .collect(),
                sigma_scale: None,
            };
            fit_board_full(image, &pixel, &params.board_fit)
        });
        let half_offset = 0.5 * fitted.as_ref().map_or(0.0, |f| f.polarity_offset());
        // The junction windows grow with the blur where it is known: measured by the
        // board-wide fit, or given.
        let blur = fitted.as_ref().map(|f| f.blur).or(params.refine.blur);
        let junction = params
            .junction
            .as_ref()
            .map(|j| blur.map_or_else(|| j.clone(), |b| j.for_blur(b)));
        let fitted = fitted.map(|f| f.corners);
        // The board's typical σ: a corner far above it is an outlier of its own board, whatever
        // the image's scale, blur and noise.
        let typical_sigma = fitted.as_ref().map_or(f64::INFINITY, |f| {
            let mut s: Vec<f64> = f
                .iter()
                .filter(|c| c.path == Path::Board)
                .map(|c| c.sigma)
                .collect();
            if s.is_empty() {
                f64::INFINITY
            } else {
                median_mad_in_place(&mut s).0.min(TYPICAL_SIGMA_CEILING)
            }
        });
        let sigma_limit = params.max_board_sigma * typical_sigma;
        // As sure as the board answers that need no junction fit.
        let sure_sigma = params.junction_gate.min(params.max_board_sigma) * typical_sigma;
        board_fit_ms += ms(t);
        let t = Instant::now();
        // Each corner, and the difference to a contradicting estimate of it that lost (see
        // [`disputed`]).
        let (mut refined, disputes): (Vec<DetectedCorner>, Vec<Option<[f64; 2]>>) = b
            .corners
            .par_iter()
            .zip(&b.labels)
            .enumerate()
            .map(|(k, (&i, &(row, col)))| {
                let pixel = pixel_corner(&corners[i], row, col);
                // The curves' intersection, also where it lies farther than the board fit's
                // `max_shift` from the pixel-level corner if it is sure enough to need no junction
                // fit: on large squares the election's pixel can be 2–5 px off the junction (a
                // print's dot gain, a dot near it), while the curves, sampled on both sides of
                // the corner, agree with the local refiner's answer to 0.02–0.3 px there.
                let board = fitted.as_ref().and_then(|f| {
                    let f = &f[k];
                    let (point, cov) = match f.too_far {
                        _ if f.path == Path::Board => ([f.x, f.y], f.cov),
                        Some((p, cov))
                            if sure_far(
                                &corners,
                                b,
                                i,
                                p,
                                cov,
                                sure_sigma,
                                params.refine.max_shift,
                            ) =>
                        {
                            (p, cov)
                        }
                        _ => return None,
                    };
                    Some(DetectedCorner {
                        x: point[0],
                        y: point[1],
                        status: Status::Converged,
                        path: Path::Board,
                        sigma: Some(worst_sigma(cov)),
                        cov: Some(cov),
                        ..pixel
                    })
                });
                if let Some(c) = board.filter(|c| c.sigma.is_some_and(|s| s <= sigma_limit)) {
                    return match junction.as_ref() {
                        Some(j)
                            if c.sigma
                                .is_some_and(|s| s > params.junction_gate * typical_sigma) =>
                        {
                            match junction_corner(image, &corners, b, i, c, j, false) {
                                // Where they disagree, the one that claims the smaller σ along
                                // their difference.
                                Some(jc) => match fuse(c, jc) {
                                    Some(f) => (f, None),
                                    None => {
                                        let (won, lost) = if surer_along_difference(&jc, &c) {
                                            (jc, c)
                                        } else {
                                            (c, jc)
                                        };
                                        (won, Some([won.x - lost.x, won.y - lost.y]))
                                    }
                                },
                                None => (c, None),
                            }
                        }
                        _ => (c, None),
                    };
                }
                let neighbours = neighbour_points(&corners, &graph, b, i);
                let mut local =
                    refine_corner(image, &corners[i], row, col, &neighbours, &params.refine);
                // The refiner failed at the pixel-level position, which can be off the junction
                // (a pen stroke through it moves the election's maximum): it gets two more
                // starts, where the board's curves meet (when that was too far from the pixel
                // position to be taken) and where the corner's neighbours put it. Only a
                // converged answer that confirms its start (within the board fit's `max_shift`)
                // counts: one farther off has found another junction. An answer from one side
                // of the junction gets the first start: a print's dot gain bridges a junction,
                // and its maximum can sit at one tip, 2 px from where the curves meet.
                let too_far = fitted.as_ref().and_then(|f| f[k].too_far);
                if local.status == Status::Failed
                    || (local.status == Status::Fallback && too_far.is_some())
                {
                    let predicted = (local.status == Status::Failed)
                        .then(|| neighbour_prediction(&corners, b, (row, col)))
                        .flatten();
                    let mut starts = too_far.map(|(p, _)| p).into_iter().chain(predicted);
                    let confirmed = starts.find_map(|[x, y]| {
                        let start = Corner { x, y, ..corners[i] };
                        let again =
                            refine_corner(image, &start, row, col, &neighbours, &params.refine);
                        (again.status == Status::Converged
                            && (again.x - x).hypot(again.y - y) <= params.board_fit.max_shift
                            && nearest_is_own(&corners, b, i, [again.x, again.y]))
                        .then_some(again)
                    });
                    local = confirmed.unwrap_or(local);
                }
                // A local answer from one side of its junction cannot see the offset between the
                // polarities that a print's dot gain puts into every edge, and is off by about
                // half of it: its σ says so before it is weighed against the other estimates.
                if local.status == Status::Fallback {
                    widen(&mut local, half_offset);
                }
                // A doubtful board-wide answer means short, extrapolated curves, where the
                // local refiner's one-sided answer is no better; failing the gradient
                // estimate, the board-wide answer stands.
                let (weak, last) = match (local.status, board) {
                    (Status::Converged, Some(board))
                        if board.sigma.unwrap_or(f64::INFINITY)
                            <= local.sigma.unwrap_or(f64::INFINITY) =>
                    {
                        (false, board)
                    }
                    (Status::Converged, _) => (false, local),
                    (Status::Fallback, Some(board)) => (true, board),
                    (Status::Fallback, None) => (true, local),
                    (Status::Failed, board) => (true, board.unwrap_or(local)),
                };
                // When nothing else places the corner, the curves' intersection beats the
                // unrefined pixel position, if within the refiner's reach of it.
                let curves = |c: DetectedCorner| match too_far {
                    Some(([x, y], cov))
                        if c.status == Status::Failed
                            && (x - pixel.x).hypot(y - pixel.y) <= params.refine.max_shift =>
                    {
                        DetectedCorner {
                            x,
                            y,
                            status: Status::Fallback,
                            path: Path::Board,
                            sigma: Some(worst_sigma(cov)),
                            cov: Some(cov),
                            ..c
                        }
                    }
                    _ => c,
                };
                // The junction model where the walks failed or saw one side only; a one-sided
                // local answer with no board answer stays if it claims the smaller σ.
                if let Some(j) = junction.as_ref().filter(|_| weak) {
                    if let Some(jc) = junction_corner(image, &corners, b, i, pixel, j, true) {
                        // A board answer (doubtful, but often sure of one direction: the curve
                        // that is not extrapolated) that agrees is combined with it.
                        if let Some(f) = board.and_then(|bc| fuse(bc, jc)) {
                            return (f, None);
                        }
                        let one_sided = last.status == Status::Fallback && board.is_none();
                        let kept = if one_sided && sigma_of(&last) <= sigma_of(&jc) {
                            last
                        } else {
                            jc
                        };
                        return (kept, None);
                    }
                }
                // On the board's boundary (a labelled neighbour missing) a converged answer whose
                // σ is above the board's limit is doubtful too (the walks beyond the corner are
                // short or absent, the curves extrapolated): the junction model's answer replaces
                // it if it claims the smaller σ. Not inside the board: at an S's inflection the
                // model (one curvature per edge) is biased by 0.02–0.03 px where the local
                // refiner is not.
                let boundary = || {
                    [(0, 1), (0, -1), (1, 0), (-1, 0)]
                        .iter()
                        .any(|&(dr, dc)| !b.labels.contains(&(row + dr, col + dc)))
                };
                let doubtful = !weak && last.sigma.is_some_and(|s| s > sigma_limit) && boundary();
                if let Some(j) = junction.as_ref().filter(|_| doubtful) {
                    if let Some(jc) = junction_corner(image, &corners, b, i, pixel, j, true) {
                        if let Some(f) = board.and_then(|bc| fuse(bc, jc)) {
                            return (f, None);
                        }
                        if sigma_of(&jc) < sigma_of(&last) {
                            return (jc, None);
                        }
                    }
                }
                let Some(g) = params.gradient.as_ref().filter(|_| weak) else {
                    return (curves(last), None);
                };
                // The gradient estimate is pulled towards a bridged junction's dark side as a
                // one-sided answer is: its reported σ carries half the polarity offset too. Not
                // in the choice below, where it would tie with the one-sided answer's: the
                // gradient estimate is the nearer one on the 0.2 mm dot-gain cylinder (test
                // `one_sided_answers_are_weighed_with_their_polarity_offset`).
                let offset = |mut c: DetectedCorner| {
                    if c.path == Path::Gradient {
                        widen(&mut c, half_offset);
                    }
                    c
                };
                // Where a labelled neighbour is near (squares of a few pixels, slivers beside a
                // silhouette), the window holds another junction's edges too: the estimate
                // lands between the two (1.5–3 px off at 640 × 480, claiming σ 0.3 px) and is
                // no evidence. Beyond the board's last labelled column the squares narrow
                // further towards the silhouette, so "near" reaches four window radii
                // (`CLEAR_GRADIENT_RADII`).
                let clear = nearest_labelled(&corners, b, &corners[i], (row, col))
                    >= CLEAR_GRADIENT_RADII * g.radius as f64;
                let gradient = clear.then(|| gradient_corner(image, pixel, g)).flatten();
                let placed = curves(offset(match (gradient, board) {
                    // Two independent estimates that agree within the gradient estimate's σ:
                    // their mean. Where they disagree, the doubtful board-wide answer (short,
                    // extrapolated curves) is the likelier to be wrong.
                    (Some(gc), Some(b))
                        if (gc.x - b.x).hypot(gc.y - b.y) <= gc.sigma.unwrap_or(0.0) =>
                    {
                        DetectedCorner {
                            x: 0.5 * (gc.x + b.x),
                            y: 0.5 * (gc.y + b.y),
                            ..gc
                        }
                    }
                    // A one-sided local answer against the gradient estimate: the one that
                    // claims the smaller σ.
                    (Some(gc), None)
                        if last.status == Status::Fallback && sigma_of(&last) <= sigma_of(&gc) =>
                    {
                        last
                    }
                    (gc, _) => gc.unwrap_or(last),
                }));
                (placed, None)
            })
            // A board-wide answer above the board's σ limit that stands for want of a better
            // one (short, extrapolated curves) has less support than its path claims.
            .map(|(c, dispute)| {
                let doubtful = sigma_of(&c) > sigma_limit;
                let status = if c.path == Path::Board && c.status == Status::Converged && doubtful {
                    Status::Fallback
                } else {
                    c.status
                };
                (DetectedCorner { status, ..c }, dispute)
            })
            .unzip();
        // A junction beside hairline slivers where nothing else places it, or places it less
        // surely: the completion's fit, with its covariance.
        for (c, i) in refined.iter_mut().zip(&b.corners) {
            let Some(&cov) = hairlines.get(i) else {
                continue;
            };
            if c.status == Status::Failed || worst_sigma(cov) < sigma_of(c) {
                let at = [corners[*i].x, corners[*i].y];
                *c = fallback_at(*c, at, cov, Path::Hairline);
            }
        }
        refine_ms += ms(t);
        let mut board = Board {
            rows: b.rows,
            cols: b.cols,
            corners: refined,
            sigma_scale: None,
        };
        if let Some(f) = params
            .variance_factor
            .as_ref()
            .and_then(|vf| variance_factor::variance_factor(&board.corners, vf))
        {
            variance_factor::apply(&mut board.corners, f.sigma_scale);
            board.sigma_scale = Some(f.sigma_scale);
        }
        // Local mode keeps its contract, each corner from its own edges alone (on the 12-pair
        // curved-board benchmark the fusion would take its RMSE from 0.0122 to 0.0108 px, still
        // twice board mode's).
        if let (RefineMode::Board, Some(sp)) = (params.mode, &params.spacing) {
            spacing::fuse_along_lines(&mut board.corners, sp);
        }
        // Only now: the spacing fusion does better with the claims of the fits (a disputed
        // corner's wider σ let the spacing law pull it off: cylinder cell of the robustness
        // report 0.0106 → 0.0113 px). Scaled like the rest, so that every covariance the board
        // reports is its `sigma_scale`² times what the board's answers gave.
        let scale = board.sigma_scale.unwrap_or(1.0);
        for (c, d) in board.corners.iter_mut().zip(&disputes) {
            if let Some(d) = d {
                disputed(c, d.map(|v| scale * v));
            }
        }
        // What is left of a board after dropping must still be one (`labels.min_corners`).
        if !params.keep_unrefined {
            drop_unrefined(&mut board);
            if board.corners.len() < params.labels.min_corners.max(1) {
                continue;
            }
        }
        // A board that does not span the pattern cannot be put into its frame.
        if params
            .pattern
            .map_or(true, |p| to_pattern(image, &mut board, p))
        {
            boards.push(board);
        }
    }
    // Completion, dropping and the phase check change the sizes the labelling ordered by (a
    // stable sort: ties keep the labelling's order).
    boards.sort_by_key(|b| std::cmp::Reverse(b.corners.len()));
    Detection {
        boards,
        timing: Timing {
            prefilter: prefilter_ms,
            election: election_ms,
            connectivity: connectivity_ms,
            completion: completion_ms,
            refine: refine_ms,
            board_fit: board_fit_ms,
            total: ms(t0),
        },
    }
}

/// Drops the corners of `board` that no refiner placed and shifts the labels so that the
/// smallest row and column are 0 again (`rows` and `cols` follow).
fn drop_unrefined(board: &mut Board) {
    board.corners.retain(|c| c.status != Status::Failed);
    let (Some(r0), Some(c0)) = (
        board.corners.iter().map(|c| c.row).min(),
        board.corners.iter().map(|c| c.col).min(),
    ) else {
        (board.rows, board.cols) = (0, 0);
        return;
    };
    for c in &mut board.corners {
        c.row -= r0;
        c.col -= c0;
    }
    let extent = |f: fn(&DetectedCorner) -> i32| {
        board
            .corners
            .iter()
            .map(f)
            .max()
            .map_or(0, |m| m as usize + 1)
    };
    (board.rows, board.cols) = (extent(|c| c.row), extent(|c| c.col));
}

/// Where the labelled neighbours of the corner at `(row, col)` put it: the mean of the midpoints
/// of its opposite neighbours, `(row, col ± 1)` and `(row ± 1, col)`, at their pixel-level
/// positions; `None` when neither pair is on the board. On a bent board a midpoint is off by
/// about `κ s² / 8` (`s` the square's side, `κ` the line's curvature): well within the
/// refiner's reach for a start.
fn neighbour_prediction(
    corners: &[Corner],
    board: &LabelledBoard,
    (row, col): (i32, i32),
) -> Option<[f64; 2]> {
    let at = |label: (i32, i32)| {
        let k = board.labels.iter().position(|&l| l == label)?;
        Some(&corners[board.corners[k]])
    };
    let pairs = [
        ((row, col - 1), (row, col + 1)),
        ((row - 1, col), (row + 1, col)),
    ];
    let (mut sum, mut n) = ([0.0; 2], 0.0);
    for (a, b) in pairs {
        if let (Some(a), Some(b)) = (at(a), at(b)) {
            sum[0] += 0.5 * (a.x + b.x);
            sum[1] += 0.5 * (a.y + b.y);
            n += 1.0;
        }
    }
    (n > 0.0).then(|| [sum[0] / n, sum[1] / n])
}

/// The pixel-level positions of corner `i`'s grid neighbours: its links in the graph, or for a
/// corner added by grid completion (it has no links) its labelled 4-neighbours on the board. The
/// local refiner's walks stop before their crossing edges ([`refine_one_among`]) and go no
/// farther than the farthest of them (a walk would stop at that neighbour anyway, where the edge
/// changes polarity).
fn neighbour_points(
    corners: &[Corner],
    graph: &Graph,
    board: &LabelledBoard,
    i: usize,
) -> Vec<[f64; 2]> {
    let at = |j: usize| [corners[j].x, corners[j].y];
    if let Some(nb) = graph.neighbours.get(i) {
        return nb.iter().flatten().map(|&j| at(j)).collect();
    }
    let Some(k) = board.corners.iter().position(|&j| j == i) else {
        return Vec::new();
    };
    let (r, c) = board.labels[k];
    board
        .corners
        .iter()
        .zip(&board.labels)
        .filter(|(_, &(lr, lc))| (lr - r).abs() + (lc - c).abs() == 1)
        .map(|(&j, _)| at(j))
        .collect()
}

/// Whether `q` (image coordinates) lies nearer the pixel-level position of `corners[i]` than of
/// any other corner of `board`. Where a column is missed (the narrowest columns of an S's ridge
/// seen from afar) the board's curves can meet at the neighbouring corner's junction, a step
/// away, and the refiner started there confirms it: that answer is the neighbour's.
fn nearest_is_own(corners: &[Corner], board: &LabelledBoard, i: usize, q: [f64; 2]) -> bool {
    let d = |j: usize| (corners[j].x - q[0]).hypot(corners[j].y - q[1]);
    let own = d(i);
    board.corners.iter().all(|&j| j == i || d(j) > own)
}

/// Whether the board fit's intersection `p` (covariance `cov`), refused for lying farther than
/// its `max_shift` from the pixel-level corner `i` of `board`, is sure enough to be taken: σ at
/// most `max_sigma`, within `reach` px of the corner and nearer to it than to any other corner of
/// the board (not another junction's).
fn sure_far(
    corners: &[Corner],
    board: &LabelledBoard,
    i: usize,
    p: [f64; 2],
    cov: Cov,
    max_sigma: f64,
    reach: f64,
) -> bool {
    worst_sigma(cov) <= max_sigma
        && (p[0] - corners[i].x).hypot(p[1] - corners[i].y) <= reach
        && nearest_is_own(corners, board, i, p)
}

/// `c` placed by the gradient estimate started from its position, if that converges. Its σ is
/// widened by the estimate's dependence on its window: the same estimate with a window
/// [`WINDOW_CHECK`] times wider (up to the largest valid window) lands `d` px away (or fails
/// within `max_shift`, then `d` is `max_shift`), and the covariance gains `d² I`. On an ideal X-junction the answer does not
/// depend on the window (every gradient is orthogonal to its ray through the junction); edges
/// of other junctions within it (narrow squares beside a silhouette, slivers merged by blur)
/// pull it by an amount that changes with the window, which the sandwich covariance of one
/// window cannot see.
fn gradient_corner(
    image: &GrayImage,
    c: DetectedCorner,
    params: &GradientParams,
) -> Option<DetectedCorner> {
    let g = refine_gradient(image, [c.x, c.y], params)?;
    // Within the parameters' valid ranges, so that a large window of the caller's is not
    // taken for a failed check.
    let wider = GradientParams {
        radius: ((params.radius as f64 * WINDOW_CHECK).ceil() as usize).min(gradient::MAX_RADIUS),
        window_sigma: (params.window_sigma * WINDOW_CHECK).min(gradient::MAX_WINDOW_SIGMA),
        ..params.clone()
    };
    let spread = refine_gradient(image, [c.x, c.y], &wider).map_or(params.max_shift, |w| {
        (w.point[0] - g.point[0]).hypot(w.point[1] - g.point[1])
    });
    let mut placed = fallback_at(c, g.point, g.cov, Path::Gradient);
    widen(&mut placed, spread);
    Some(placed)
}

/// How much wider (radius and Gaussian weight) the second window of [`gradient_corner`]'s
/// consistency check is.
const WINDOW_CHECK: f64 = 1.5;

/// `c` moved to `point` by the fallback refiner `path`, with its covariance (and σ from it).
fn fallback_at(c: DetectedCorner, point: [f64; 2], cov: Cov, path: Path) -> DetectedCorner {
    DetectedCorner {
        x: point[0],
        y: point[1],
        status: Status::Fallback,
        residual: None,
        path,
        sigma: Some(worst_sigma(cov)),
        cov: Some(cov),
        ..c
    }
}

/// `c`'s uncertainty widened by an independent error of `s` px in every direction (its
/// covariance plus `s² I`, so σ becomes `√(σ² + s²)`).
fn widen(c: &mut DetectedCorner, s: f64) {
    c.sigma = c.sigma.map(|v| v.hypot(s));
    if let Some(cov) = c.cov.as_mut() {
        cov[0][0] += s * s;
        cov[1][1] += s * s;
    }
}

/// `c`, kept over an estimate of the same corner `d` px away that contradicts it (beyond what
/// their covariances allow): one of the two is wrong and nothing says which. As the expected
/// square error of a choice that is wrong half the time, `c`'s covariance gains half the outer
/// product `d dᵀ` (σ along `d` at least `|d| / √2`). On the mirrored photos (`curve_8.jpg`
/// (9, 9)) the junction model and the board-wide answer, claiming 0.11 and 0.16 px, lay 1.8 px
/// apart.
fn disputed(c: &mut DetectedCorner, d: [f64; 2]) {
    if let Some(cov) = c.cov.as_mut() {
        for (i, row) in cov.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v += 0.5 * d[i] * d[j];
            }
        }
        c.sigma = Some(worst_sigma(*cov));
    }
}

/// Smallest distance from a corner to its nearest labelled 8-neighbour, in gradient-window
/// radii, at which the gradient estimate is used. On a 19 × 29 board bent around a 60 mm
/// cylinder (1920 × 1200), its estimates at the last labelled column, 13–15 px from their
/// neighbours and beside unlabelled slivers of 2–4 px, were 1.5–4.6 px off, claiming σ 0.3–0.5
/// px; on the resized copies of the photos (`bench/photo_variants.py`), those within 12–24 px
/// of a neighbour were a median 1.5 px from the full-size answers.
const CLEAR_GRADIENT_RADII: f64 = 4.0;

/// A corner's σ, infinite where it has none (refinement failed).
fn sigma_of(c: &DetectedCorner) -> f64 {
    c.sigma.unwrap_or(f64::INFINITY)
}

/// Whether `a` claims a smaller variance than `b` along the direction of their difference (by
/// their worst-direction σ where that is undefined). Where two estimates disagree it is along
/// that direction, and each may know it well or poorly whatever its worst direction: a corner
/// beside a silhouette is poorly placed by its board answer along the foreshortened curve and
/// well across it.
fn surer_along_difference(a: &DetectedCorner, b: &DetectedCorner) -> bool {
    let d = [a.x - b.x, a.y - b.y];
    let along = |c: &DetectedCorner| {
        c.cov.map(|m| {
            d[0] * d[0] * m[0][0] + d[0] * d[1] * (m[0][1] + m[1][0]) + d[1] * d[1] * m[1][1]
        })
    };
    match (along(a), along(b)) {
        (Some(va), Some(vb)) if va.is_finite() && vb.is_finite() && d[0].hypot(d[1]) > 0.0 => {
            va < vb
        }
        _ => sigma_of(a) < sigma_of(b),
    }
}

/// A 2×2 covariance (px², image axes).
pub type Cov = [[f64; 2]; 2];

/// The board-wide answer `c` combined with the junction model's answer `j`, by their
/// covariances: two estimates of mostly independent data (the curves' samples along whole
/// grid lines, the pixels within a few pixels of the junction), weighted by their inverse
/// covariances, so that each contributes along the direction it knows best. `None` if they
/// disagree: the Mahalanobis distance of their difference above the 99 % point of χ²₂, or a
/// covariance that cannot be inverted or is missing.
fn fuse(c: DetectedCorner, j: DetectedCorner) -> Option<DetectedCorner> {
    let m = |a: Cov| Matrix2::new(a[0][0], a[0][1], a[1][0], a[1][1]);
    let (cc, cj) = (m(c.cov?), m(j.cov?));
    let (pc, pj) = (Vector2::new(c.x, c.y), Vector2::new(j.x, j.y));
    let d = pc - pj;
    let q = d.dot(&((cc + cj).try_inverse()? * d));
    if q.is_nan() || q > CHI2_2_99 {
        return None;
    }
    let (ic, ij) = (cc.try_inverse()?, cj.try_inverse()?);
    let p = (ic + ij).try_inverse()?;
    let x = p * (ic * pc + ij * pj);
    let xy = 0.5 * (p[(0, 1)] + p[(1, 0)]);
    let cov = [[p[(0, 0)], xy], [xy, p[(1, 1)]]];
    (x.iter().all(|v| v.is_finite())).then(|| DetectedCorner {
        x: x[0],
        y: x[1],
        sigma: Some(worst_sigma(cov)),
        cov: Some(cov),
        ..c
    })
}

/// The 99 % point of the χ² distribution with two degrees of freedom.
const CHI2_2_99: f64 = 9.21;

/// `c` (the pixel-level corner `i` of `board`) placed by the junction model fitted from its
/// position, with the edge directions and the window's radius taken from its labelled
/// neighbours: the window reaches half-way to the nearest of its eight neighbours, where the
/// next junction begins. With `slivers`, an edge with no neighbour beyond it may have a sliver
/// there ([`refine_junction_at_boundary`]): the fallbacks, not the averaging into board
/// answers, which would pay for it on every boundary corner.
fn junction_corner(
    image: &GrayImage,
    corners: &[Corner],
    board: &LabelledBoard,
    i: usize,
    c: DetectedCorner,
    params: &JunctionParams,
    slivers: bool,
) -> Option<DetectedCorner> {
    let at = |dr: i32, dc: i32| {
        let k = board
            .labels
            .iter()
            .position(|&l| l == (c.row + dr, c.col + dc))?;
        Some(&corners[board.corners[k]])
    };
    let own = &corners[i];
    // The direction through the two neighbours on a line, or from the one there is.
    let direction = |(dr, dc): (i32, i32)| -> Option<f64> {
        let (a, b) = (at(-dr, -dc).unwrap_or(own), at(dr, dc).unwrap_or(own));
        let (dx, dy) = (b.x - a.x, b.y - a.y);
        (dx != 0.0 || dy != 0.0).then(|| dy.atan2(dx))
    };
    let angles = match (direction((0, 1)), direction((1, 0))) {
        (Some(u), Some(v)) => [u, v],
        _ => own.angles,
    };
    let nearest = nearest_labelled(corners, board, own, (c.row, c.col));
    // The edges with no neighbour beyond them, pointing out of the board: slivers may lie
    // there.
    let beyond: Vec<(usize, [f64; 2])> = [((0, 1), 1), ((0, -1), 1), ((1, 0), 0), ((-1, 0), 0)]
        .into_iter()
        .filter(|_| slivers)
        .filter(|&((dr, dc), _)| at(dr, dc).is_none())
        .filter_map(|((dr, dc), edge)| {
            let inner = at(-dr, -dc)?;
            Some((edge, [own.x - inner.x, own.y - inner.y]))
        })
        .collect();
    let j = refine_junction_at_boundary(
        image,
        [c.x, c.y],
        angles,
        0.5 * nearest,
        1.0,
        &beyond,
        params,
    )?;
    Some(fallback_at(c, j.point, j.cov, Path::Junction))
}

/// Distance from `own` (label `(row, col)`) to its nearest labelled 8-neighbour on `board`
/// (infinite if it has none).
fn nearest_labelled(
    corners: &[Corner],
    board: &LabelledBoard,
    own: &Corner,
    (row, col): (i32, i32),
) -> f64 {
    board
        .corners
        .iter()
        .zip(&board.labels)
        .filter(|(_, &(r, c))| (r - row).abs() <= 1 && (c - col).abs() <= 1 && (r, c) != (row, col))
        .map(|(&j, _)| (corners[j].x - own.x).hypot(corners[j].y - own.y))
        .fold(f64::INFINITY, f64::min)
}

/// A labelled corner at its pixel-level (elected) position, not yet refined.
fn pixel_corner(c: &Corner, row: i32, col: i32) -> DetectedCorner {
    DetectedCorner {
        x: c.x,
        y: c.y,
        row,
        col,
        score: c.score,
        status: Status::Failed,
        residual: None,
        path: Path::Local,
        sigma: None,
        cov: None,
    }
}

fn refine_corner(
    image: &GrayImage,
    c: &Corner,
    row: i32,
    col: i32,
    neighbours: &[[f64; 2]],
    params: &RefineParams,
) -> DetectedCorner {
    let reach = neighbours
        .iter()
        .map(|n| (n[0] - c.x).hypot(n[1] - c.y))
        .max_by(f64::total_cmp);
    let params = RefineParams {
        reach: reach.map_or(params.reach, |r| r.clamp(5.0, params.reach)),
        ..params.clone()
    };
    let r = refine_one_among(image, [c.x, c.y], neighbours, &params);
    DetectedCorner {
        x: r.x,
        y: r.y,
        status: r.status,
        residual: r.residual,
        sigma: r.sigma,
        cov: r.cov,
        ..pixel_corner(c, row, col)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A converged board answer at `(x, y)` with covariance `cov`.
    fn at(x: f64, y: f64, cov: Cov) -> DetectedCorner {
        DetectedCorner {
            x,
            y,
            row: 0,
            col: 0,
            score: 1.0,
            status: Status::Converged,
            residual: None,
            path: Path::Board,
            sigma: Some(worst_sigma(cov)),
            cov: Some(cov),
        }
    }

    #[test]
    fn a_disputed_corner_owns_up_to_the_estimate_it_beat() {
        // Two estimates 0.6 px apart along (0.6, 0.8), each claiming σ 0.1 px: the winner's
        // variance along their difference grows by half its square, across it not at all.
        let mut c = at(10.0, 20.0, [[0.01, 0.0], [0.0, 0.01]]);
        let d = [0.36, 0.48];
        disputed(&mut c, d);
        let cov = c.cov.unwrap();
        let along = |u: [f64; 2]| {
            u[0] * u[0] * cov[0][0] + 2.0 * u[0] * u[1] * cov[0][1] + u[1] * u[1] * cov[1][1]
        };
        assert!((along([0.6, 0.8]) - (0.01 + 0.5 * 0.36)).abs() < 1e-12);
        assert!((along([0.8, -0.6]) - 0.01).abs() < 1e-12);
        assert!((c.sigma.unwrap() - 0.19f64.sqrt()).abs() < 1e-12);
        assert_eq!((c.x, c.y), (10.0, 20.0));
        // Without a covariance there is nothing to widen.
        let mut bare = DetectedCorner {
            cov: None,
            sigma: None,
            ..c
        };
        disputed(&mut bare, d);
        assert_eq!((bare.cov, bare.sigma), (None, None));
    }

    #[test]
    fn fusion_takes_each_direction_from_the_estimate_that_knows_it() {
        // The board answer is sure of y (its row curve) and not of x (an extrapolated column
        // curve); the junction model the other way round.
        let board = at(10.3, 20.0, [[0.09, 0.0], [0.0, 1e-4]]);
        let junction = at(10.0, 20.02, [[1e-4, 0.0], [0.0, 0.01]]);
        let f = fuse(board, junction).unwrap();
        assert!(
            (f.x - 10.0).abs() < 1e-3 && (f.y - 20.0).abs() < 3e-4,
            "{f:?}"
        );
        assert_eq!(f.path, Path::Board);
        // The fused σ is below both of the inputs' σ in their weak directions.
        assert!(f.sigma.unwrap() < 0.011, "{f:?}");
        // Correlated covariances: the same answer whichever is first.
        let (a, b) = (
            at(5.0, 5.0, [[0.01, 0.004], [0.004, 0.005]]),
            at(5.05, 4.98, [[0.003, -0.001], [-0.001, 0.008]]),
        );
        let (ab, ba) = (fuse(a, b).unwrap(), fuse(b, a).unwrap());
        assert!((ab.x - ba.x).abs() < 1e-12 && (ab.y - ba.y).abs() < 1e-12);
        // Disagreeing: 1 px apart where both claim 0.1 px. Singular: refused.
        assert!(fuse(
            at(0.0, 0.0, [[0.01, 0.0], [0.0, 0.01]]),
            at(1.0, 0.0, [[0.01, 0.0], [0.0, 0.01]])
        )
        .is_none());
        assert!(fuse(at(10.0, 20.02, [[0.0, 0.0], [0.0, 0.01]]), junction).is_none());
        // Without a covariance: refused.
        assert!(fuse(DetectedCorner { cov: None, ..board }, junction).is_none());
    }

    #[test]
    fn a_disagreement_goes_to_the_estimate_surer_along_it() {
        // As at a boundary corner beside a silhouette: the board answer knows x to 0.007 px and
        // y to 0.015, the junction model both to 0.011; they differ by 0.074 px in x. The
        // worst-direction σ would take the junction model's answer.
        let board = at(169.160, 325.643, [[4.9e-5, 0.0], [0.0, 2.3e-4]]);
        let junction = at(169.234, 325.642, [[1.2e-4, 0.0], [0.0, 1.2e-4]]);
        assert!(fuse(board, junction).is_none());
        assert!(sigma_of(&junction) < sigma_of(&board));
        assert!(surer_along_difference(&board, &junction));
        assert!(!surer_along_difference(&junction, &board));
        // Apart along y, the junction model is the surer.
        let below = at(169.160, 325.75, [[1.2e-4, 0.0], [0.0, 1.2e-4]]);
        assert!(surer_along_difference(&below, &board));
        // Without covariances, or at the same point: by the worst-direction σ.
        let bare = |c: DetectedCorner| DetectedCorner { cov: None, ..c };
        assert!(surer_along_difference(&bare(junction), &bare(board)));
        assert!(surer_along_difference(
            &at(169.160, 325.643, [[1e-4, 0.0], [0.0, 1e-4]]),
            &board
        ));
    }

    #[test]
    fn dropping_unplaced_corners_keeps_labels_canonical() {
        let corner = |row, col, status| DetectedCorner {
            x: col as f64,
            y: row as f64,
            row,
            col,
            score: 1.0,
            status,
            residual: None,
            path: Path::Local,
            sigma: None,
            cov: None,
        };
        let mut board = Board {
            rows: 3,
            cols: 3,
            corners: vec![
                corner(0, 0, Status::Failed),
                corner(1, 1, Status::Converged),
                corner(1, 2, Status::Fallback),
                corner(2, 1, Status::Converged),
                corner(2, 2, Status::Failed),
            ],
            sigma_scale: None,
        };
        drop_unrefined(&mut board);
        let labels: Vec<(i32, i32)> = board.corners.iter().map(|c| (c.row, c.col)).collect();
        assert_eq!(labels, [(0, 0), (0, 1), (1, 0)]);
        assert_eq!((board.rows, board.cols), (2, 2));
        board.corners[0].status = Status::Failed;
        board.corners[1].status = Status::Failed;
        board.corners[2].status = Status::Failed;
        drop_unrefined(&mut board);
        assert!(board.corners.is_empty());
        assert_eq!((board.rows, board.cols), (0, 0));
    }

    #[test]
    fn neighbours_predict_a_corner_from_opposite_pairs() {
        let corner = |x: f64, y: f64| Corner {
            x,
            y,
            angles: [0.0, std::f64::consts::FRAC_PI_2],
            score: 1.0,
        };
        // (1, 1) sits between (1, 0) and (1, 2), and between (0, 1) and (2, 1).
        let corners = vec![
            corner(10.0, 20.0),
            corner(30.0, 22.0),
            corner(20.0, 10.0),
            corner(20.0, 31.0),
            corner(99.0, 99.0),
        ];
        let board = LabelledBoard {
            corners: vec![2, 0, 4, 1, 3],
            labels: vec![(0, 1), (1, 0), (1, 1), (1, 2), (2, 1)],
            rows: 3,
            cols: 3,
        };
        let p = neighbour_prediction(&corners, &board, (1, 1)).unwrap();
        assert!(
            (p[0] - 20.0).abs() < 1e-12 && (p[1] - 20.75).abs() < 1e-12,
            "{p:?}"
        );
        // No complete pair: nothing. One pair only: its midpoint.
        assert_eq!(neighbour_prediction(&corners, &board, (1, 0)), None);
        let row_only = LabelledBoard {
            corners: vec![0, 4, 1],
            labels: vec![(1, 0), (1, 1), (1, 2)],
            rows: 1,
            cols: 3,
        };
        assert_eq!(
            neighbour_prediction(&corners, &row_only, (1, 1)),
            Some([20.0, 21.0])
        );
        assert_eq!(neighbour_prediction(&corners, &row_only, (1, 0)), None);
    }

    #[test]
    fn a_far_intersection_is_taken_only_when_sure_near_and_its_own() {
        let corner = |x: f64, y: f64| Corner {
            x,
            y,
            angles: [0.0, std::f64::consts::FRAC_PI_2],
            score: 1.0,
        };
        // Two neighbours 10 px apart on a row.
        let corners = vec![corner(10.0, 10.0), corner(20.0, 10.0)];
        let board = LabelledBoard {
            corners: vec![0, 1],
            labels: vec![(0, 0), (0, 1)],
            rows: 1,
            cols: 2,
        };
        let cov = |s: f64| [[s * s, 0.0], [0.0, 0.25 * s * s]];
        let sure = |p: [f64; 2], s: f64| sure_far(&corners, &board, 0, p, cov(s), 0.05, 5.0);
        // 3 px off the pixel-level corner, σ 0.04 px: taken.
        assert!(sure([13.0, 10.0], 0.04));
        // Less sure than the limit (the worst direction counts).
        assert!(!sure([13.0, 10.0], 0.06));
        // Beyond the local refiner's reach.
        assert!(!sure([10.0, 15.5], 0.04));
        // Nearer to the neighbour than to its own pixel-level corner: another junction.
        assert!(!sure([15.5, 10.0], 0.04));
    }

    #[test]
    fn validate_names_the_bad_parameter() {
        assert!(DetectParams::default().validate().is_ok());
        let cases: [(DetectParams, &str); 6] = [
            (
                DetectParams {
                    max_board_sigma: f64::NAN,
                    ..DetectParams::default()
                },
                "sigma ratio",
            ),
            (
                DetectParams {
                    junction_gate: f64::NAN,
                    ..DetectParams::default()
                },
                "junction gate",
            ),
            (
                DetectParams {
                    junction_gate: -1.0,
                    ..DetectParams::default()
                },
                "junction gate",
            ),
            (
                DetectParams {
                    max_board_sigma: 0.0,
                    ..DetectParams::default()
                },
                "sigma ratio",
            ),
            (
                DetectParams {
                    gradient: Some(GradientParams {
                        radius: 0,
                        ..GradientParams::default()
                    }),
                    ..DetectParams::default()
                },
                "gradient window radius",
            ),
            (
                DetectParams {
                    gradient: Some(GradientParams {
                        window_sigma: f64::INFINITY,
                        ..GradientParams::default()
                    }),
                    ..DetectParams::default()
                },
                "gradient window sigma",
            ),
        ];
        for (params, name) in cases {
            let e = params.validate().expect_err(name);
            assert!(e.contains(name), "{e}");
        }
        // Disabling the last resort and the doubt check is valid.
        let off = DetectParams {
            gradient: None,
            max_board_sigma: f64::INFINITY,
            ..DetectParams::default()
        };
        assert!(off.validate().is_ok());
    }

    /// A junction at (20, 20) (edges at x = 20 and y = 20), blurred by 2.5 px, dark above-left
    /// and below-right, rendered in closed form (products of the blurred steps). With `narrow`
    /// = `Some(w)`, the squares right of it are `w` px wide and a grey background follows, as
    /// beside a cylinder's silhouette.
    fn junction_beside(narrow: Option<f64>) -> GrayImage {
        let s = (2.5f64 * 2.5 + 1.0 / 12.0).sqrt();
        // The blurred share of [t < a] at t.
        let below =
            |t: f64, a: f64| 0.5 * (1.0 + crate::junction::erf((a - t) / (s * 2f64.sqrt())));
        let end = narrow.map_or(f64::INFINITY, |w| 20.0 + w);
        let data = (0..41 * 41)
            .map(|k| {
                let (x, y) = ((k % 41) as f64, (k / 41) as f64);
                let (left, mid) = (below(x, 20.0), below(x, end) - below(x, 20.0));
                let top = below(y, 20.0);
                let checker =
                    left * (0.1 * top + 0.9 * (1.0 - top)) + mid * (0.9 * top + 0.1 * (1.0 - top));
                (checker + 0.5 * (1.0 - below(x, end))) as f32
            })
            .collect();
        GrayImage::from_vec(41, 41, data).expect("valid size")
    }

    /// Beside squares 5–8 px wide and a silhouette, the gradient estimate is pulled 0.4–1.3 px
    /// off the junction while its window's covariance claims σ 0.24 px; the wider window lands
    /// elsewhere, and the σ reported covers the error within 2σ. On a clean junction both
    /// windows agree and σ is the window's own.
    #[test]
    fn the_gradient_estimate_beside_narrow_squares_owns_up_to_its_window_bias() {
        let params = GradientParams::default();
        let start = Corner {
            x: 20.0,
            y: 20.0,
            angles: [0.0, 0.0],
            score: 1.0,
        };
        let start = pixel_corner(&start, 0, 0);
        let error = |c: &DetectedCorner| (c.x - 20.0).hypot(c.y - 20.0);
        let own = |image: &GrayImage| {
            refine_gradient(image, [20.0, 20.0], &params)
                .expect("converges")
                .sigma
        };
        let clean_image = junction_beside(None);
        let clean = gradient_corner(&clean_image, start, &params).expect("converges");
        assert!(error(&clean) < 0.01, "{clean:?}");
        assert!(
            clean.sigma.is_some_and(|s| s <= 1.01 * own(&clean_image)),
            "{clean:?}"
        );
        for w in [5.0, 6.0, 7.0, 8.0] {
            let image = junction_beside(Some(w));
            let c = gradient_corner(&image, start, &params).expect("converges");
            assert!(c.sigma.is_some_and(|s| error(&c) < 2.0 * s), "{w}: {c:?}");
            if w == 5.0 {
                assert!(error(&c) > 4.0 * own(&image), "{c:?}");
            }
        }
    }
}
