//! Array organization (paper III-C): which corners are grid neighbours ([`connect`]) and the
//! (row, col) label of every corner of each board ([`label`]).
//!
//! # Connectivity rule ([`connect`])
//!
//! Every corner has four *rays*: the two directions `±(cos θ_f, sin θ_f)` of each of its two edge
//! orientations `θ_f` (`f` = 0, 1 is the *family*). Ray slot `2f + s` is `+` for `s = 0` and `−` for
//! `s = 1`. Positions are in image coordinates (x right, y down).
//!
//! 1. **Candidates.** The corner positions are Delaunay-triangulated (`spade`). The candidates of
//!    corner `i` are its Delaunay neighbours *and their neighbours* (the 2-ring): Delaunay alone can
//!    miss a grid edge when a cell's diagonal is preferred (a square's two diagonals are
//!    co-circular; under perspective or bending the "wrong" one can win), but the missed neighbour
//!    is then always a neighbour of a neighbour.
//! 2. **Paper rule, both ends.** Candidate `j` may sit on ray `(f, s)` of `i` only if the direction
//!    `i → j` is within `theta_edge` of that ray, `j` has an orientation `θ_g` within `theta_edge` of
//!    the line `i j`, and the *other* orientations of the two corners agree within
//!    `max_orientation_change` (grid orientations vary smoothly, so a corner whose second edge
//!    disagrees is not the same grid).
//! 3. **Nearest per ray, mutual.** Each ray keeps its nearest admissible candidate (so at most one
//!    neighbour per side, at most two per family), unless that one lies more than `theta_edge / 2`
//!    off the ray and another admissible candidate at most `ALIGNED_REACH` times farther lies
//!    less than half as far off it (sines of the angles): in a cell foreshortened to a quarter of
//!    its length the short diagonal is both nearer than the grid neighbour and within
//!    `theta_edge` of the long side. The link `i — j` is kept only if `j` also chose `i` on one of
//!    its rays.
//! 4. **Pruning, repeated until nothing changes.** (a) *Quad support*: a link survives only if it is
//!    a side of at least one grid cell, a 4-cycle `i — j — l — k — i` whose sides `i — j` and
//!    `i — k` leave `i` along different families, and which is nearly a parallelogram
//!    (`|p_i + p_l − p_j − p_k| ≤ max_cell_skew ×` mean side: perspective and bending change a
//!    grid only slowly from cell to cell). This removes links to isolated false corners and
//!    links spanning a single missing corner. (b) *Step ratio*: where both rays of one family of a
//!    corner are linked and one link is more than `max_step_ratio` times longer than the other, one
//!    of them jumps over missing corners (e.g. across an occluding band, where the jumping links
//!    support each other's cells) or reaches a false corner off the grid line (false corners can
//!    form a spurious half-size cell with the border). The link that is *confirmed* — its line
//!    continues beyond its far end with a step within the same ratio — is kept and the other is
//!    removed; if both or neither are confirmed, the longer is removed.
//!
//! Consequences: a corner is connected only if it is a corner of at least one grid cell whose four
//! corners were all detected; a board split by an occluding band yields two components (the
//! links across the band are longer than the steps beside it and are cut); [`label`] joins the
//! pieces again when their grids line up across the band (see the labelling rule). The rule assumes the two orientations of a grid corner are more than
//! `2·theta_edge` apart (so a cell's diagonal can never fall in a ray's cone); corners violating
//! this, or with non-finite positions or orientations, get no links.
//!
//! Limitations: a false corner whose orientations match the grid and which lies within about a
//! third of a step of a grid site, or mid-way along a grid line next to another such one, can
//! stand in for the true corner there or add a spurious half-step row: a detector's non-maximum
//! suppression and saddle test are expected to have removed those.
//!
//! # Labelling rule ([`label`])
//!
//! Breadth-first walk of each connected component, seeded at the corner with the most links (ties:
//! higher score, then lower index). Every visited corner carries a *frame*: the (Δrow, Δcol) step
//! of each of its four rays. Walking `i → j` along a ray with step `δ`, `j` gets label
//! `label(i) + δ`; its ray pointing back at `i` gets step `−δ` and the opposite ray `+δ`; its other
//! family gets the perpendicular step of `i`, signed so that rays whose directions have a positive
//! dot product carry the same step. The frame is thus propagated by geometry, so edge families are
//! tracked consistently even when the orientations rotate strongly across a bent or perspective
//! board. **Conflicts:** each corner is labelled once, by the first link that reaches it in
//! breadth-first order; a link that would give a new corner a label already taken in the board is
//! not walked, and links between already labelled corners are never re-walked, so a link that
//! disagrees with the labels (an inconsistent link) is effectively dropped and cannot corrupt the
//! walk; the rest of the component is reached around it. Components with fewer than
//! [`LabelParams::min_corners`] corners are dropped.
//!
//! **Split boards.** An occluder lying across a board cuts it into components. Their labels (in
//! canonical orientation, below) differ by a translation when they belong to one board; grid
//! lines that end at a piece's border are extrapolated across the gap (up to 3 steps) and the
//! pieces are merged when at least two lines land on the other piece with the same label offset
//! and agreeing steps, or (where a bent board folds away from the camera and its lines turn
//! sharply) when two neighbouring lines reach the other piece at their next site and span a
//! parallelogram cell across the gap ([`merge_split_boards`]; `detect` runs it again after the
//! completion has grown the pieces, and then also asks that the checker's phase continue across
//! the gap; pieces whose canonical orientations differ by a quarter turn, as on a board at 45°,
//! are turned into one frame first). Two pieces are left apart when their lines disagree: when
//! another label offset could merge them too, or has at least as many votes.
//!
//! **Canonical orientation.** Let `a` and `b` be the mean unit direction of the rays stepping
//! `+1` along each of the two walk axes. The axis whose mean direction has the larger `|x|`
//! component becomes the *column* axis (rows run along it), signed so that columns increase
//! towards `+x`; the other becomes the *row* axis, signed so that rows increase towards `+y`
//! (down). Exact ties (a board at 45°) pick the axis whose `+x`-pointing direction has `y < 0`
//! (points up-right) as the column axis; a direction with exactly zero deciding component keeps
//! the walk's sign. Labels are then shifted so that the minimum row and column are 0. The result
//! depends only on the input (the same image always gives the same labels), and for a board
//! rotated by less than 45° from upright, labels grow right and down like a matrix.

use crate::election::Corner;
use spade::{DelaunayTriangulation, HasPosition, Point2, Triangulation};
use std::cell::OnceCell;
use std::collections::{HashMap, VecDeque};

/// Tuning of [`connect`] (angles in radians).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConnectivityParams {
    /// θ_edge of the paper: largest angle between a link and the corner edge it follows, checked
    /// at both ends (default 15°).
    pub theta_edge: f64,
    /// Largest difference between the orientations of the *other* edge family at the two ends of
    /// a link (default 25°).
    pub max_orientation_change: f64,
    /// Largest ratio between the lengths of the two collinear links of one family at a corner;
    /// the longer is cut beyond it (default 1.75: a step over one missing corner has ratio ≈ 2,
    /// adjacent cells under strong perspective ≲ 1.5).
    pub max_step_ratio: f64,
    /// Largest skew of a supporting grid cell `i j l k`: `|p_i + p_l − p_j − p_k|` over the mean
    /// side length (0 for a parallelogram; default 0.4, enough for adjacent cells differing by
    /// 1.3× under perspective or bending, while a false corner a third of a step off its grid
    /// site fails).
    pub max_cell_skew: f64,
}

impl Default for ConnectivityParams {
    fn default() -> Self {
        Self {
            theta_edge: 15f64.to_radians(),
            max_orientation_change: 25f64.to_radians(),
            max_step_ratio: 1.75,
            max_cell_skew: 0.4,
        }
    }
}

/// Grid links between corners, indexed like the input slice of [`connect`].
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Graph {
    /// `neighbours[i][2f + s]`: the corner linked to corner `i` along its ray `(f, s)`, i.e. in
    /// direction `(cos θ_f, sin θ_f)` for `s = 0` and the opposite for `s = 1`, with
    /// `θ_f = corners[i].angles[f]`. Links are symmetric: if `j` is in a slot of `i`, `i` is in a
    /// slot of `j`.
    pub neighbours: Vec<[Option<usize>; 4]>,
}

impl Graph {
    /// Every link once, as `(i, j)` with `i < j`, in increasing order of `i` then slot.
    pub fn edges(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.neighbours.iter().enumerate().flat_map(|(i, nb)| {
            nb.iter()
                .filter_map(move |&j| j.filter(|&j| i < j).map(|j| (i, j)))
        })
    }

    /// Number of links of corner `i` (0 when `i` is out of range).
    pub fn degree(&self, i: usize) -> usize {
        self.neighbours
            .get(i)
            .map_or(0, |nb| nb.iter().flatten().count())
    }
}

/// A Delaunay vertex remembering which input corner it is.
struct Site {
    position: Point2<f64>,
    index: usize,
}

impl HasPosition for Site {
    type Scalar = f64;
    fn position(&self) -> Point2<f64> {
        self.position
    }
}

/// Difference between two line orientations modulo π, in `[0, π/2]`.
pub(crate) fn line_diff(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(std::f64::consts::PI);
    d.min(std::f64::consts::PI - d)
}

/// Unit direction of ray `slot` of `c` (see [`Graph::neighbours`]).
fn ray(c: &Corner, slot: usize) -> (f64, f64) {
    let t = c.angles[slot / 2];
    let sign = if slot % 2 == 0 { 1.0 } else { -1.0 };
    (sign * t.cos(), sign * t.sin())
}

fn dist(a: &Corner, b: &Corner) -> f64 {
    (b.x - a.x).hypot(b.y - a.y)
}

/// Whether `c` can take part in the grid: finite, within the triangulation's coordinate range,
/// with two distinct edge orientations (more than `2·theta_edge` apart, see the module docs).
fn usable(c: &Corner, theta_edge: f64) -> bool {
    const LIMIT: f64 = 1e30;
    c.x.is_finite()
        && c.y.is_finite()
        && c.x.abs() < LIMIT
        && c.y.abs() < LIMIT
        && c.angles.iter().all(|a| a.is_finite())
        && line_diff(c.angles[0], c.angles[1]) > 2.0 * theta_edge
}

/// How much farther than the nearest admissible candidate on a ray a far better aligned one may
/// lie and still be chosen ([`connect`], step 3). A diagonal was 1.15 times nearer than the grid
/// neighbour (cells of 90 × 25 px); at an S's fold, where the chord of a row bends 10° off the
/// ray, the next corner but one lies straighter on and 1.5 times farther.
const ALIGNED_REACH: f64 = 1.3;

/// Links every corner to its grid neighbours (paper III-C, extended; the exact rule is in the
/// [module docs](self)). Positions in image coordinates; the result is indexed like `corners`.
/// Never panics: unusable corners (non-finite, degenerate orientations) and coincident duplicates
/// (all but one) simply get no links. O(n log n) for n corners.
pub fn connect(corners: &[Corner], params: &ConnectivityParams) -> Graph {
    connect_seen(corners, params, |_, _| true)
}

/// [`connect`], where a link between corners `i` and `j` (called with `i < j`) is made only if
/// `seen(i, j)`: the image's evidence that one grid edge runs between them (`detect` passes
/// [`crate::completion::edge_seen`]). A refused link is refused before the pruning of step 4, so
/// the cells it supported go with it.
pub fn connect_seen(
    corners: &[Corner],
    params: &ConnectivityParams,
    seen: impl Fn(usize, usize) -> bool,
) -> Graph {
    let n = corners.len();
    let mut graph = Graph {
        neighbours: vec![[None; 4]; n],
    };
    let theta = params.theta_edge;
    if !(theta > 0.0 && theta < std::f64::consts::FRAC_PI_4) {
        return graph;
    }
    let sites: Vec<Site> = corners
        .iter()
        .enumerate()
        .filter(|(_, c)| usable(c, theta))
        .map(|(index, c)| Site {
            position: Point2::new(c.x, c.y),
            index,
        })
        .collect();
    if sites.len() < 2 {
        return graph;
    }
    let Ok(tri) = DelaunayTriangulation::<Site>::bulk_load(sites) else {
        return graph;
    };

    // Delaunay adjacency in compressed rows.
    let mut start = vec![0usize; n + 1];
    for e in tri.undirected_edges() {
        let [a, b] = e.vertices();
        start[a.data().index + 1] += 1;
        start[b.data().index + 1] += 1;
    }
    for i in 0..n {
        start[i + 1] += start[i];
    }
    let mut fill = start.clone();
    let mut adj = vec![0usize; start[n]];
    for e in tri.undirected_edges() {
        let [a, b] = e.vertices();
        let (i, j) = (a.data().index, b.data().index);
        adj[fill[i]] = j;
        fill[i] += 1;
        adj[fill[j]] = i;
        fill[j] += 1;
    }
    let nbrs = |i: usize| &adj[start[i]..start[i + 1]];

    // Steps 1–3: nearest admissible candidate per ray. Angle tests as dot products with unit
    // edge vectors: two lines are within α of each other iff |cos| of their angle is ≥ cos α.
    let (cos_edge, cos_turn) = (theta.cos(), params.max_orientation_change.cos());
    let units: Vec<[(f64, f64); 2]> = corners.iter().map(|c| [ray(c, 0), ray(c, 2)]).collect();
    let dot = |a: (f64, f64), b: (f64, f64)| a.0 * b.0 + a.1 * b.1;
    let mut pick: Vec<[Option<(usize, f64)>; 4]> = vec![[None; 4]; n];
    let mut cand: Vec<usize> = Vec::new();
    // Admissible candidates of the current corner: (slot, candidate, length, sine of the angle
    // to the ray).
    let mut admissible: Vec<(usize, usize, f64, f64)> = Vec::new();
    for i in 0..n {
        let ci = &corners[i];
        if nbrs(i).is_empty() {
            continue;
        }
        cand.clear();
        for &j in nbrs(i) {
            cand.push(j);
            cand.extend(nbrs(j).iter().copied().filter(|&k| k != i));
        }
        cand.sort_unstable();
        cand.dedup();
        admissible.clear();
        for &j in &cand {
            let cj = &corners[j];
            let d = (cj.x - ci.x, cj.y - ci.y);
            let len = d.0.hypot(d.1);
            if len <= 0.0 {
                continue;
            }
            let at_j = units[j].map(|e| dot(d, e).abs());
            let g = usize::from(at_j[1] > at_j[0]);
            if at_j[g] < cos_edge * len {
                continue;
            }
            for f in 0..2 {
                let along = dot(d, units[i][f]);
                if along.abs() < cos_edge * len
                    || dot(units[i][1 - f], units[j][1 - g]).abs() < cos_turn
                {
                    continue;
                }
                let slot = 2 * f + usize::from(along < 0.0);
                let sine = (1.0 - (along / len).powi(2)).max(0.0).sqrt();
                admissible.push((slot, j, len, sine));
            }
        }
        for (slot, chosen) in pick[i].iter_mut().enumerate() {
            let on_ray = || admissible.iter().filter(|a| a.0 == slot);
            let Some(&(_, j, len, sine)) = on_ray().min_by(|a, b| a.2.total_cmp(&b.2)) else {
                continue;
            };
            // In a cell foreshortened to a quarter of its length, the short diagonal lies 14°
            // from the long side, inside the cone and nearer than the grid neighbour, which
            // then lies on the same ray, far better aligned and not much farther.
            let aligned = (sine > (0.5 * theta).sin())
                .then(|| {
                    on_ray()
                        .filter(|a| a.2 <= ALIGNED_REACH * len && a.3 < 0.5 * sine)
                        .min_by(|a, b| a.3.total_cmp(&b.3))
                })
                .flatten();
            *chosen = Some(aligned.map_or((j, len), |a| (a.1, a.2)));
        }
    }
    for i in 0..n {
        for slot in 0..4 {
            if let Some((j, _)) = pick[i][slot] {
                if pick[j].iter().flatten().any(|&(k, _)| k == i) && seen(i.min(j), i.max(j)) {
                    graph.neighbours[i][slot] = Some(j);
                }
            }
        }
    }

    // Step 4: prune to a fixed point. Each pass removes at least one link, so this terminates.
    let mut doomed: Vec<(usize, usize)> = Vec::new();
    loop {
        doomed.clear();
        for i in 0..n {
            for slot in 0..4 {
                if graph.neighbours[i][slot].is_some()
                    && !has_quad(&graph, corners, params.max_cell_skew, i, slot)
                {
                    doomed.push((i, slot));
                }
            }
        }
        let quad_cut = remove_links(&mut graph, &doomed);
        doomed.clear();
        for (i, ci) in corners.iter().enumerate() {
            for f in 0..2 {
                let (Some(a), Some(b)) =
                    (graph.neighbours[i][2 * f], graph.neighbours[i][2 * f + 1])
                else {
                    continue;
                };
                let (la, lb) = (dist(ci, &corners[a]), dist(ci, &corners[b]));
                if la.max(lb) <= params.max_step_ratio * la.min(lb) {
                    continue;
                }
                let confirmed = |j: usize, len: f64| {
                    continued(&graph, corners, j, i)
                        .is_some_and(|l2| l2.max(len) <= params.max_step_ratio * l2.min(len))
                };
                let drop_a = match (confirmed(a, la), confirmed(b, lb)) {
                    (true, false) => false,
                    (false, true) => true,
                    _ => la > lb,
                };
                doomed.push((i, if drop_a { 2 * f } else { 2 * f + 1 }));
            }
        }
        let ratio_cut = remove_links(&mut graph, &doomed);
        if !quad_cut && !ratio_cut {
            return graph;
        }
    }
}

/// Length of the link that continues the line `from → j` beyond `j` (the other ray of the family of
/// `j` that points back at `from`), if linked.
fn continued(graph: &Graph, corners: &[Corner], j: usize, from: usize) -> Option<f64> {
    let back = graph.neighbours[j].iter().position(|&s| s == Some(from))?;
    let k = graph.neighbours[j][back ^ 1]?;
    Some(dist(&corners[j], &corners[k]))
}

/// Whether link `(i, slot)` is a side of a grid cell `i — j — l — k — i` with `i — k` on the
/// other family of `i` and a skew of at most `max_skew` (see [`ConnectivityParams`]).
fn has_quad(graph: &Graph, corners: &[Corner], max_skew: f64, i: usize, slot: usize) -> bool {
    let nb = &graph.neighbours;
    let p = |a: usize| (corners[a].x, corners[a].y);
    let cell_ok = |j: usize, l: usize, k: usize| cell_skew([p(i), p(j), p(l), p(k)]) <= max_skew;
    let Some(j) = nb[i][slot] else {
        return false;
    };
    let other = 2 * (1 - slot / 2);
    [other, other + 1].iter().any(|&s| {
        nb[i][s].is_some_and(|k| {
            k != j
                && nb[k].iter().flatten().any(|&l| {
                    l != i && l != j && l != k && nb[j].contains(&Some(l)) && cell_ok(j, l, k)
                })
        })
    })
}

/// Removes the listed links (both directions); returns whether anything was removed.
fn remove_links(graph: &mut Graph, links: &[(usize, usize)]) -> bool {
    let mut any = false;
    for &(i, slot) in links {
        if let Some(j) = graph.neighbours[i][slot].take() {
            any = true;
            for s in graph.neighbours[j].iter_mut() {
                if *s == Some(i) {
                    *s = None;
                }
            }
        }
    }
    any
}

/// Tuning of [`label_with`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LabelParams {
    /// Boards (connected, consistently labelled components) with fewer corners are dropped
    /// (default 4, one grid cell).
    pub min_corners: usize,
}

impl Default for LabelParams {
    fn default() -> Self {
        Self { min_corners: 4 }
    }
}

/// One labelled board: a connected component of the grid graph.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Board {
    /// Indices into the corner slice given to [`label`], sorted by `(row, col)`.
    pub corners: Vec<usize>,
    /// `(row, col)` of each entry of `corners`, canonical as described in the
    /// [module docs](self): minimum row and column 0, columns increase towards +x, rows towards
    /// +y. Corners joined by a walked link differ by exactly 1 in exactly one of the two.
    pub labels: Vec<(i32, i32)>,
    /// `1 + max row`.
    pub rows: usize,
    /// `1 + max col`.
    pub cols: usize,
}

/// [`label_with`] with default [`LabelParams`] (boards of at least 4 corners).
pub fn label(corners: &[Corner], graph: &Graph) -> Vec<Board> {
    label_with(corners, graph, &LabelParams::default())
}

/// Splits the linked corners into boards and gives each corner its `(row, col)` label by walking
/// the quad mesh (rule and canonical orientation in the [module docs](self)). Boards are returned
/// largest first (ties: smallest corner index first). Returns no boards when `graph` does not
/// match `corners` in length; links to out-of-range or unusable corners, and one-way links, are
/// ignored.
pub fn label_with(corners: &[Corner], graph: &Graph, params: &LabelParams) -> Vec<Board> {
    let n = corners.len();
    if graph.neighbours.len() != n {
        return Vec::new();
    }
    let link = |i: usize, slot: usize| -> Option<(usize, usize)> {
        let j = graph.neighbours[i][slot].filter(|&j| j < n && j != i)?;
        let back = graph.neighbours[j].iter().position(|&s| s == Some(i))?;
        Some((j, back))
    };
    let valid =
        |c: &Corner| c.x.is_finite() && c.y.is_finite() && c.angles.iter().all(|a| a.is_finite());
    let degree: Vec<usize> = (0..n)
        .map(|i| (0..4).filter(|&s| link(i, s).is_some()).count())
        .collect();

    let mut seeds: Vec<usize> = (0..n)
        .filter(|&i| valid(&corners[i]) && degree[i] > 0)
        .collect();
    seeds.sort_by(|&a, &b| {
        degree[b]
            .cmp(&degree[a])
            .then(corners[b].score.total_cmp(&corners[a].score))
            .then(a.cmp(&b))
    });

    let mut visited = vec![false; n];
    let mut labels = vec![(0i32, 0i32); n];
    let mut steps = vec![[(0i32, 0i32); 4]; n];
    let mut boards = Vec::new();
    let mut queue = VecDeque::new();
    let mut occupied: HashMap<(i32, i32), usize> = HashMap::new();
    let mut members: Vec<usize> = Vec::new();
    for &seed in &seeds {
        if visited[seed] {
            continue;
        }
        members.clear();
        occupied.clear();
        visited[seed] = true;
        labels[seed] = (0, 0);
        steps[seed] = [(0, 1), (0, -1), (1, 0), (-1, 0)];
        occupied.insert((0, 0), seed);
        members.push(seed);
        queue.push_back(seed);
        while let Some(i) = queue.pop_front() {
            for slot in 0..4 {
                let Some((j, back)) = link(i, slot) else {
                    continue;
                };
                if !valid(&corners[j]) {
                    continue;
                }
                let d = steps[i][slot];
                let lj = (labels[i].0 + d.0, labels[i].1 + d.1);
                // Already labelled (here or, through a link dropped there, in an earlier board):
                // nothing to do if consistent, otherwise the link is dropped.
                if visited[j] || occupied.contains_key(&lj) {
                    continue;
                }
                let mut sj = [(0, 0); 4];
                sj[back] = (-d.0, -d.1);
                sj[back ^ 1] = d;
                let perp = 2 * (1 - slot / 2);
                let eps = steps[i][perp];
                let (ux, uy) = ray(&corners[i], perp);
                let og = 2 * (1 - back / 2);
                let (vx, vy) = ray(&corners[j], og);
                let (plus, minus) = if ux * vx + uy * vy >= 0.0 {
                    (og, og + 1)
                } else {
                    (og + 1, og)
                };
                sj[plus] = eps;
                sj[minus] = (-eps.0, -eps.1);
                steps[j] = sj;
                labels[j] = lj;
                visited[j] = true;
                occupied.insert(lj, j);
                members.push(j);
                queue.push_back(j);
            }
        }
        if members.len() >= params.min_corners.max(1) {
            boards.push(canonical_board(corners, &members, &labels, &steps));
        }
    }
    let mut boards = merge_split_boards(corners, boards, |_| None);
    sort_boards(&mut boards);
    boards
}

/// Largest first, ties by smallest corner index.
fn board_order(a: &Board, b: &Board) -> std::cmp::Ordering {
    b.corners.len().cmp(&a.corners.len()).then_with(|| {
        let (ma, mb) = (a.corners.iter().min(), b.corners.iter().min());
        ma.cmp(&mb)
    })
}

/// Sorts boards by [`board_order`].
fn sort_boards(boards: &mut [Board]) {
    boards.sort_by(board_order);
}

/// The label `l` turned by `t` quarter turns: `(r, c) → (−c, r)` per turn.
fn quarter_turn(l: (i32, i32), t: usize) -> (i32, i32) {
    match t % 4 {
        0 => l,
        1 => (-l.1, l.0),
        2 => (-l.0, -l.1),
        _ => (l.1, -l.0),
    }
}

/// The board of `(label, corner)` pairs: labels shifted so that the smallest row and column are
/// 0, sorted by label.
pub(crate) fn board_from(mut all: Vec<((i32, i32), usize)>) -> Board {
    let r0 = all.iter().map(|x| x.0 .0).min().unwrap_or(0);
    let c0 = all.iter().map(|x| x.0 .1).min().unwrap_or(0);
    for x in all.iter_mut() {
        x.0 = (x.0 .0 - r0, x.0 .1 - c0);
    }
    all.sort_unstable();
    Board {
        corners: all.iter().map(|x| x.1).collect(),
        labels: all.iter().map(|x| x.0).collect(),
        rows: all.iter().map(|x| x.0 .0 + 1).max().unwrap_or(0) as usize,
        cols: all.iter().map(|x| x.0 .1 + 1).max().unwrap_or(0) as usize,
    }
}

/// `board` with every label turned by `t` quarter turns ([`quarter_turn`]) ([`board_from`]).
fn turned(board: &Board, t: usize) -> Board {
    board_from(
        board
            .labels
            .iter()
            .zip(&board.corners)
            .map(|(&l, &i)| (quarter_turn(l, t), i))
            .collect(),
    )
}

/// The mean unit image directions of a board's `+col` and `+row` label steps (from the positions
/// of its label neighbours); `None` if it has no step along one of them.
fn label_axes(corners: &[Corner], board: &Board) -> Option<[(f64, f64); 2]> {
    let at: HashMap<(i32, i32), usize> = board
        .labels
        .iter()
        .copied()
        .zip(board.corners.iter().copied())
        .collect();
    let unit = |(x, y): (f64, f64)| {
        let n = x.hypot(y);
        (n > 0.0).then(|| (x / n, y / n))
    };
    let mut sum = [(0.0, 0.0); 2];
    for (&(r, c), &i) in &at {
        for (axis, next) in [(r, c + 1), (r + 1, c)].into_iter().enumerate() {
            if let Some(d) = at
                .get(&next)
                .and_then(|&j| unit((corners[j].x - corners[i].x, corners[j].y - corners[i].y)))
            {
                sum[axis].0 += d.0;
                sum[axis].1 += d.1;
            }
        }
    }
    Some([unit(sum[0])?, unit(sum[1])?])
}

/// The quarter turns ([`quarter_turn`]) that best align a board whose label axes point along
/// `axes` with a board whose axes point along `reference` (both from [`label_axes`]): the turn
/// whose turned `+col` and `+row` steps point most nearly where the reference's labels step.
fn aligning_turns(reference: [(f64, f64); 2], axes: [(f64, f64); 2]) -> usize {
    let image_dir = |(dr, dc): (i32, i32)| {
        let [u, v] = reference;
        (
            dc as f64 * u.0 + dr as f64 * v.0,
            dc as f64 * u.1 + dr as f64 * v.1,
        )
    };
    let score = |t: usize| {
        let (a, b) = (
            image_dir(quarter_turn((0, 1), t)),
            image_dir(quarter_turn((1, 0), t)),
        );
        axes[0].0 * a.0 + axes[0].1 * a.1 + axes[1].0 * b.0 + axes[1].1 * b.1
    };
    (0..4).fold(0, |best, t| if score(t) > score(best) { t } else { best })
}

/// Most grid steps between two pieces of one board that [`merge_split_boards`] bridges (an
/// occluder hiding up to two rows or columns of corners).
const MAX_BRIDGE_STEPS: i32 = 3;
/// Distinct grid lines that must agree on the label offset before two pieces are merged.
const MIN_BRIDGE_VOTES: usize = 2;
/// Tolerance of an extrapolated grid position, in steps: this at one step, plus half of it per
/// further step (perspective and bending change the step slowly along a line).
const BRIDGE_TOLERANCE: f64 = 0.25;

/// Farthest (in steps) a grid line's next site may lie from its straight extrapolation when the
/// line turns at a fold between two pieces (`turning` in [`merge_split_boards`]): a line turning
/// by 40° within a step, where an S-shaped surface's ridge hides the surface beyond it.
const TURN_REACH: f64 = 0.5;

/// Largest ratio between the steps on either side of a fold (`turning` in
/// [`merge_split_boards`]): 1.33 where `curve_6.jpg`'s S folds away, 2 where a link of the far
/// piece jumps a column hidden behind a pen.
const TURN_STEP_RATIO: f64 = 1.5;

/// A label `(row, col)`, a label offset between two pieces, or a step along an axis.
type Label = (i32, i32);

/// [`merge_split_boards`]' votes: per other piece and label offset, the lines that landed there.
type Votes = HashMap<(usize, Label), usize>;

/// A line's hit at the next site of another piece whose steps disagree: (other piece, label
/// offset, label, axis, this piece's corner, the other's corner).
type Turning = (usize, Label, Label, Label, usize, usize);

/// The steps of a board's grid line at label `l` (position `p`) along the label axis `e`: to the
/// next corner and from the previous one, `None` when it has neither.
fn step_at(
    map: &HashMap<(i32, i32), usize>,
    l: (i32, i32),
    e: (i32, i32),
    p: (f64, f64),
    pos: &impl Fn(usize) -> (f64, f64),
) -> Option<[Option<(f64, f64)>; 2]> {
    let ahead = map.get(&(l.0 + e.0, l.1 + e.1)).map(|&n| {
        let q = pos(n);
        (q.0 - p.0, q.1 - p.1)
    });
    let behind = map.get(&(l.0 - e.0, l.1 - e.1)).map(|&n| {
        let q = pos(n);
        (p.0 - q.0, p.1 - q.1)
    });
    (ahead.is_some() || behind.is_some()).then_some([ahead, behind])
}

/// Skew of the cell `p0 p1 p2 p3` (corners in order around it): `|p0 + p2 − p1 − p3|` over its
/// mean side, 0 for a parallelogram.
fn cell_skew(p: [(f64, f64); 4]) -> f64 {
    let side = |a: (f64, f64), b: (f64, f64)| (b.0 - a.0).hypot(b.1 - a.1);
    let mean = 0.25 * (side(p[0], p[1]) + side(p[1], p[2]) + side(p[2], p[3]) + side(p[3], p[0]));
    let d = (
        p[0].0 + p[2].0 - p[1].0 - p[3].0,
        p[0].1 + p[2].1 - p[1].1 - p[3].1,
    );
    d.0.hypot(d.1) / mean
}

/// Joins the pieces of one board that an occluder (a pen lying across it) split into several
/// components. [`label_with`] applies it to the walked components; run it again once the pieces
/// have grown (by [`crate::completion::complete_boards`]): a piece that met another across a
/// gap along one grid line may meet it along two after completion. `boards` must be canonical
/// (as [`label_with`] returns them), indexing `corners`; the result is sorted like
/// [`label_with`]'s.
///
/// At every corner of a board with a labelled predecessor along a grid axis but no successor,
/// the grid line is extrapolated `k = 1 …` `MAX_BRIDGE_STEPS` steps with the last step
/// `p_i − p_prev`. If a corner of another board lies within the tolerance of a prediction (the
/// first one that hits anything), and that board's own step there along the same axis agrees with
/// the extrapolated step (within 30 % of the step), it votes for merging that board with the label
/// offset that puts the hit corner `k` steps further. Where the hit corner has no step of its own
/// along that axis (a completed row beyond a pen), its step along the other axis must agree with
/// the extrapolating corner's instead. Pieces of one board differ by a translation of labels
/// once in one orientation: each board is first turned by the quarter turns that best align its
/// label steps with the largest board's (canonical orientations may differ on a board at 45°),
/// and turned back at the end. A hit at the next site (`k = 1`)
/// whose steps disagree, or up to `TURN_REACH` steps from the prediction, still votes when the
/// far piece's steps there are within `TURN_STEP_RATIO` of the extrapolated one, the
/// neighbouring grid line also hits the same board at its next site with the same offset, and the
/// cell the two links span across the gap is no more skewed than [`connect`] lets a supporting
/// cell be (`max_cell_skew` of the default [`ConnectivityParams`]): a grid line turning sharply
/// where a bent board folds away from the camera. A board is merged into another when at least
/// `MIN_BRIDGE_VOTES` grid lines agree, no label would be taken twice, the two boards'
/// phases (`phase`, see [`crate::completion::board_phase`]; `None` where unknown) agree across
/// the offset, and no other offset between the same two boards has `MIN_BRIDGE_VOTES` votes
/// (counted from both boards) and either as many as this one or a merge of its own (no label
/// taken twice, phases agreeing). The last guard is for a fold seen at a low resolution: its
/// narrowest columns are missed, the lines from either side extrapolate across the gap with
/// different steps, and they land one column apart. Repeated until nothing changes.
pub fn merge_split_boards(
    corners: &[Corner],
    mut boards: Vec<Board>,
    phase: impl Fn(&Board) -> Option<bool>,
) -> Vec<Board> {
    const AXES: [(i32, i32); 4] = [(0, 1), (0, -1), (1, 0), (-1, 0)];
    let pos = |i: usize| (corners[i].x, corners[i].y);
    let max_skew = ConnectivityParams::default().max_cell_skew;
    // Each piece's canonical orientation takes the axis nearer the image's x as its columns: on a
    // board turned by about 45°, two pieces may take different axes. Each piece is turned into
    // the frame of the largest for the votes, and back at the end.
    sort_boards(&mut boards);
    let reference = boards.first().and_then(|b| label_axes(corners, b));
    let mut turns: Vec<usize> = boards
        .iter_mut()
        .map(|b| {
            let t = reference
                .zip(label_axes(corners, b))
                .map_or(0, |(r, a)| aligning_turns(r, a));
            if t != 0 {
                *b = turned(b, t);
            }
            t
        })
        .collect();
    loop {
        let mut paired: Vec<(Board, usize)> = boards.into_iter().zip(turns).collect();
        paired.sort_by(|x, y| board_order(&x.0, &y.0));
        (boards, turns) = paired.into_iter().unzip();
        let maps: Vec<HashMap<(i32, i32), usize>> = boards
            .iter()
            .map(|b| {
                b.labels
                    .iter()
                    .copied()
                    .zip(b.corners.iter().copied())
                    .collect()
            })
            .collect();
        let others: Vec<(usize, usize, (i32, i32))> = boards
            .iter()
            .enumerate()
            .flat_map(|(b, bd)| {
                bd.corners
                    .iter()
                    .zip(&bd.labels)
                    .map(move |(&i, &l)| (b, i, l))
            })
            .collect();
        let mut tallies: Vec<Votes> = Vec::new();
        for (a, board) in boards.iter().enumerate() {
            let mut votes = Votes::new();
            let mut turning: Vec<Turning> = Vec::new();
            for (&i, &l) in board.corners.iter().zip(&board.labels) {
                for d in AXES {
                    if maps[a].contains_key(&(l.0 + d.0, l.1 + d.1)) {
                        continue;
                    }
                    let Some(&prev) = maps[a].get(&(l.0 - d.0, l.1 - d.1)) else {
                        continue;
                    };
                    let (pi, pp) = (pos(i), pos(prev));
                    let v = (pi.0 - pp.0, pi.1 - pp.1);
                    let step = v.0.hypot(v.1);
                    if step.is_nan() || step <= 0.0 {
                        continue;
                    }
                    for k in 1..=MAX_BRIDGE_STEPS {
                        let q = (pi.0 + k as f64 * v.0, pi.1 + k as f64 * v.1);
                        let tol = BRIDGE_TOLERANCE * step * (1.0 + 0.5 * (k - 1) as f64);
                        let reach = if k == 1 { TURN_REACH * step } else { tol };
                        let hit = others
                            .iter()
                            .map(|&(b, j, lj)| {
                                let pj = pos(j);
                                ((pj.0 - q.0).hypot(pj.1 - q.1), b, j, lj)
                            })
                            .filter(|t| t.0 < reach)
                            .min_by(|x, y| x.0.total_cmp(&y.0));
                        let Some((dist, b, j, lj)) = hit else {
                            continue;
                        };
                        let off = (l.0 + k * d.0 - lj.0, l.1 + k * d.1 - lj.1);
                        let pj = pos(j);
                        let along = step_at(&maps[b], lj, d, pj, &pos);
                        // A fold turns the line but keeps its step: a far piece stepping twice
                        // as far has a link that jumps a column hidden behind a pen.
                        let turns = b != a
                            && k == 1
                            && along.iter().flatten().flatten().all(|w| {
                                let r = w.0.hypot(w.1) / step;
                                r < TURN_STEP_RATIO && r * TURN_STEP_RATIO > 1.0
                            });
                        if dist >= tol {
                            // Only a fold bends the line that far within a step.
                            if turns {
                                turning.push((b, off, l, d, i, j));
                            }
                            continue;
                        }
                        if b != a {
                            let close = |w: (f64, f64), to: (f64, f64)| {
                                (w.0 - to.0).hypot(w.1 - to.1) < 0.3 * to.0.hypot(to.1)
                            };
                            // A piece with no step of its own along the line (one row of it
                            // visible beyond a pen) is compared across the line instead.
                            let e = (d.1, d.0);
                            let agrees = match along {
                                Some(w) => w.iter().flatten().any(|&w| close(w, v)),
                                None => {
                                    let across = |m: &HashMap<_, _>, l, p| {
                                        step_at(m, l, e, p, &pos)?.into_iter().flatten().next()
                                    };
                                    across(&maps[a], l, pi)
                                        .zip(across(&maps[b], lj, pj))
                                        .is_some_and(|(wa, wb)| close(wb, wa))
                                }
                            };
                            if agrees {
                                *votes.entry((b, off)).or_default() += 1;
                            } else if turns {
                                turning.push((b, off, l, d, i, j));
                            }
                        }
                        break;
                    }
                }
            }
            // Where a bent board folds away from the camera its grid lines turn sharply at the
            // gap, and the step of the far piece disagrees with the extrapolated one. Two
            // neighbouring lines that each meet the far piece at the next site span a grid cell
            // across the gap: both vote when it is nearly a parallelogram (as in `connect`).
            for h in &turning {
                let cell = turning.iter().any(|g| {
                    let dl = (g.2 .0 - h.2 .0, g.2 .1 - h.2 .1);
                    (g.0, g.1, g.3) == (h.0, h.1, h.3)
                        && dl.0.abs() + dl.1.abs() == 1
                        && dl.0 * h.3 .0 + dl.1 * h.3 .1 == 0
                        && cell_skew([pos(h.4), pos(h.5), pos(g.5), pos(g.4)]) <= max_skew
                });
                if cell {
                    *votes.entry((h.0, h.1)).or_default() += 1;
                }
            }
            tallies.push(votes);
        }
        let phases: Vec<OnceCell<Option<bool>>> = boards.iter().map(|_| OnceCell::new()).collect();
        let phase_of = |b: usize| *phases[b].get_or_init(|| phase(&boards[b]));
        let mut merge: Option<(usize, usize, (i32, i32))> = None;
        for (a, votes) in tallies.iter().enumerate() {
            let free = |b: usize, off: (i32, i32)| {
                boards[b]
                    .labels
                    .iter()
                    .all(|l| !maps[a].contains_key(&(l.0 + off.0, l.1 + off.1)))
            };
            // The checker's phase continues across the gap.
            let in_phase = |b: usize, off: (i32, i32)| {
                let odd = (off.0 + off.1).rem_euclid(2) == 1;
                match (phase_of(a), phase_of(b)) {
                    (Some(pa), Some(pb)) => pa == (pb != odd),
                    _ => true,
                }
            };
            // Votes of the pieces `a` and `b`, from either side, per offset of `b` into `a`.
            let pair = |b: usize| -> HashMap<(i32, i32), usize> {
                let mut t: HashMap<(i32, i32), usize> = HashMap::new();
                for (&(c, o), &n) in votes {
                    if c == b {
                        *t.entry(o).or_default() += n;
                    }
                }
                for (&(c, o), &n) in &tallies[b] {
                    if c == a {
                        *t.entry((-o.0, -o.1)).or_default() += n;
                    }
                }
                t
            };
            let mut ranked: Vec<_> = votes.iter().map(|(&k, &n)| (k, n)).collect();
            ranked.sort_by(|x, y| y.1.cmp(&x.1).then(x.0.cmp(&y.0)));
            merge = ranked
                .into_iter()
                .filter(|&(_, n)| n >= MIN_BRIDGE_VOTES)
                .find(|&((b, off), _)| {
                    // Where the lines disagree on how many steps the gap hides (a fold's narrow
                    // columns, missed at a low resolution), neither placement is trusted.
                    let t = pair(b);
                    let pro = t.get(&off).copied().unwrap_or(0);
                    let rival = t.iter().any(|(&o, &m)| {
                        o != off
                            && m >= MIN_BRIDGE_VOTES
                            && (m >= pro || free(b, o) && in_phase(b, o))
                    });
                    free(b, off) && in_phase(b, off) && !rival
                })
                .map(|((b, off), _)| (a, b, off));
            if merge.is_some() {
                break;
            }
        }
        let Some((a, b, off)) = merge else {
            return boards
                .into_iter()
                .zip(turns)
                .map(|(board, t)| if t == 0 { board } else { turned(&board, 4 - t) })
                .collect();
        };
        let piece = boards.swap_remove(b);
        turns.swap_remove(b);
        let a = if a == boards.len() { b } else { a };
        let own = boards[a]
            .labels
            .iter()
            .copied()
            .zip(boards[a].corners.iter().copied());
        let moved = (piece.labels.iter())
            .zip(&piece.corners)
            .map(|(l, &i)| ((l.0 + off.0, l.1 + off.1), i));
        boards[a] = board_from(own.chain(moved).collect());
    }
}

/// Applies the canonical orientation (module docs) to one walked component.
fn canonical_board(
    corners: &[Corner],
    members: &[usize],
    labels: &[(i32, i32)],
    steps: &[[(i32, i32); 4]],
) -> Board {
    // Mean unit direction of the +col (index 0) and +row (index 1) walk axes.
    let mut mean = [(0.0f64, 0.0f64); 2];
    for &i in members {
        for (slot, step) in steps[i].iter().enumerate() {
            let axis = match step {
                (0, 1) => 0,
                (1, 0) => 1,
                _ => continue,
            };
            let (x, y) = ray(&corners[i], slot);
            mean[axis].0 += x;
            mean[axis].1 += y;
        }
    }
    let norm = |(x, y): (f64, f64)| {
        let l = x.hypot(y);
        if l > 0.0 {
            (x / l, y / l)
        } else {
            (0.0, 0.0)
        }
    };
    let (a, b) = (norm(mean[0]), norm(mean[1]));
    // Direction flipped to point towards +x (the vector itself if x is exactly 0).
    let to_plus_x = |(x, y): (f64, f64)| if x < 0.0 { (-x, -y) } else { (x, y) };
    let col_is_a = match a.0.abs().total_cmp(&b.0.abs()) {
        std::cmp::Ordering::Greater => true,
        std::cmp::Ordering::Less => false,
        std::cmp::Ordering::Equal => to_plus_x(a).1 < 0.0 || to_plus_x(b).1 >= 0.0,
    };
    let (col_dir, row_dir) = if col_is_a { (a, b) } else { (b, a) };
    let col_sign = if col_dir.0 < 0.0 { -1 } else { 1 };
    let row_sign = if row_dir.1 < 0.0 { -1 } else { 1 };
    board_from(
        members
            .iter()
            .map(|&i| {
                let (r, c) = labels[i];
                let (along_col, along_row) = if col_is_a { (c, r) } else { (r, c) };
                ((row_sign * along_row, col_sign * along_col), i)
            })
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use rand::seq::SliceRandom;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};

    type Map<'a> = &'a dyn Fn(f64, f64) -> (f64, f64);

    /// Corners of a `rows × cols` grid with truth `(row, col)`: board point `(col, row)` (in grid
    /// steps) mapped to the image by `map`, plus uniform position noise `±pos_noise` px and
    /// orientation noise `±ang_noise` rad. Orientations are the exact tangents of the mapped grid
    /// lines (numerical Jacobian), in random order.
    fn grid(
        rows: i32,
        cols: i32,
        map: Map,
        rng: &mut ChaCha8Rng,
        pos_noise: f64,
        ang_noise: f64,
    ) -> (Vec<Corner>, Vec<Option<(i32, i32)>>) {
        let mut corners = Vec::new();
        let mut truth = Vec::new();
        let h = 1e-4;
        for r in 0..rows {
            for c in 0..cols {
                let (u, v) = (c as f64, r as f64);
                let (x, y) = map(u, v);
                let du = map(u + h, v);
                let dv = map(u, v + h);
                let mut angles = [
                    (du.1 - y).atan2(du.0 - x) + rng.gen_range(-1.0..=1.0) * ang_noise,
                    (dv.1 - y).atan2(dv.0 - x) + rng.gen_range(-1.0..=1.0) * ang_noise,
                ]
                .map(|a| a.rem_euclid(PI));
                if rng.gen_bool(0.5) {
                    angles.swap(0, 1);
                }
                corners.push(Corner {
                    x: x + rng.gen_range(-1.0..=1.0) * pos_noise,
                    y: y + rng.gen_range(-1.0..=1.0) * pos_noise,
                    angles,
                    score: 0.9,
                });
                truth.push(Some((r, c)));
            }
        }
        (corners, truth)
    }

    /// `(u, v)` in grid steps → image: scale by `step`, rotate by `theta`, shift to (400, 300).
    fn rigid(theta: f64, step: f64) -> impl Fn(f64, f64) -> (f64, f64) {
        let (s, c) = theta.sin_cos();
        move |u, v| {
            let (x, y) = (u * step, v * step);
            (400.0 + c * x - s * y, 300.0 + s * x + c * y)
        }
    }

    /// Canonical labels expected for a board whose truth axes are rotated by `theta` in the
    /// image (no mirror): `k` quarter turns of `(r, c) → (c, −r)`, then the minimum shift over the
    /// given corners.
    fn expected(truth: &[(i32, i32)], theta: f64) -> Vec<(i32, i32)> {
        let k = (theta / FRAC_PI_2).round().rem_euclid(4.0) as usize;
        let turned: Vec<(i32, i32)> = truth
            .iter()
            .map(|&(mut r, mut c)| {
                for _ in 0..k {
                    (r, c) = (c, -r);
                }
                (r, c)
            })
            .collect();
        let r0 = turned.iter().map(|t| t.0).min().unwrap();
        let c0 = turned.iter().map(|t| t.1).min().unwrap();
        turned.iter().map(|&(r, c)| (r - r0, c - c0)).collect()
    }

    /// Checks the board's labels against the truth rotated by `theta` (exact canonical labels).
    fn assert_exact(board: &Board, truth: &[Option<(i32, i32)>], theta: f64) {
        let t: Vec<(i32, i32)> = board
            .corners
            .iter()
            .map(|&i| truth[i].expect("outlier labelled"))
            .collect();
        assert_eq!(board.labels, expected(&t, theta));
        assert_eq!(
            board.rows as i32,
            board.labels.iter().map(|l| l.0).max().unwrap() + 1
        );
        assert_eq!(
            board.cols as i32,
            board.labels.iter().map(|l| l.1).max().unwrap() + 1
        );
    }

    /// Whether the labels are the truth up to a lattice symmetry (signed axis permutation) and a
    /// shift; also checks that true neighbours differ by exactly ±1 on one axis.
    fn lattice_iso(board: &Board, truth: &[Option<(i32, i32)>]) -> bool {
        let t: Vec<(i32, i32)> = board.corners.iter().map(|&i| truth[i].unwrap()).collect();
        for a in 0..t.len() {
            for b in 0..t.len() {
                let dt = (t[b].0 - t[a].0, t[b].1 - t[a].1);
                if dt.0.abs() + dt.1.abs() == 1 {
                    let dl = (
                        board.labels[b].0 - board.labels[a].0,
                        board.labels[b].1 - board.labels[a].1,
                    );
                    if dl.0.abs() + dl.1.abs() != 1 {
                        return false;
                    }
                }
            }
        }
        let mats = [
            [1, 0, 0, 1],
            [0, 1, -1, 0],
            [-1, 0, 0, -1],
            [0, -1, 1, 0],
            [1, 0, 0, -1],
            [-1, 0, 0, 1],
            [0, 1, 1, 0],
            [0, -1, -1, 0],
        ];
        mats.iter().any(|m| {
            (0..t.len()).all(|i| {
                let dt = (t[i].0 - t[0].0, t[i].1 - t[0].1);
                let dl = (
                    board.labels[i].0 - board.labels[0].0,
                    board.labels[i].1 - board.labels[0].1,
                );
                dl == (m[0] * dt.0 + m[1] * dt.1, m[2] * dt.0 + m[3] * dt.1)
            })
        })
    }

    /// Links are symmetric, at most four per corner, and (when `truth` is given) join true
    /// neighbours only.
    fn assert_graph_sane(graph: &Graph, truth: &[Option<(i32, i32)>]) {
        for (i, nb) in graph.neighbours.iter().enumerate() {
            for j in nb.iter().flatten() {
                assert!(
                    graph.neighbours[*j].contains(&Some(i)),
                    "one-way link {i}→{j}"
                );
                let (a, b) = (truth[i].unwrap(), truth[*j].unwrap());
                assert_eq!((a.0 - b.0).abs() + (a.1 - b.1).abs(), 1, "link {a:?}–{b:?}");
            }
        }
    }

    fn run(corners: &[Corner]) -> (Graph, Vec<Board>) {
        let g = connect(corners, &ConnectivityParams::default());
        let b = label(corners, &g);
        (g, b)
    }

    /// A rotation angle at least 10° away from the 45° ambiguities.
    fn clear_angle(rng: &mut ChaCha8Rng) -> f64 {
        let k = rng.gen_range(0..4) as f64;
        k * FRAC_PI_2 + rng.gen_range(-35f64..35.0).to_radians()
    }

    #[test]
    fn exact_axis_aligned_grid() {
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let (c, t) = grid(6, 9, &rigid(0.0, 20.0), &mut rng, 0.0, 0.0);
        let (g, b) = run(&c);
        assert_graph_sane(&g, &t);
        assert_eq!(g.edges().count(), 6 * 8 + 5 * 9);
        assert_eq!(b.len(), 1);
        assert_eq!((b[0].rows, b[0].cols), (6, 9));
        assert_exact(&b[0], &t, 0.0);
        // Matrix order: the first corner is the top-left one, the last the bottom-right one.
        assert_eq!(b[0].corners[0], 0);
        assert_eq!(*b[0].corners.last().unwrap(), 53);
    }

    #[test]
    fn rotated_jittered_grids_get_exact_labels() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for _ in 0..30 {
            let theta = clear_angle(&mut rng);
            let (c, t) = grid(8, 11, &rigid(theta, 25.0), &mut rng, 0.4, 3f64.to_radians());
            let (g, b) = run(&c);
            assert_graph_sane(&g, &t);
            assert_eq!(b.len(), 1);
            assert_eq!(b[0].corners.len(), 88, "theta {theta}");
            assert_exact(&b[0], &t, theta);
        }
    }

    /// Plane tilted by `alpha` about its vertical axis and `beta` about its horizontal one, seen by
    /// a pinhole camera (focal `f` px) at distance `d` steps, then rotated in-plane by `theta`.
    fn perspective(
        alpha: f64,
        beta: f64,
        d: f64,
        f: f64,
        theta: f64,
    ) -> impl Fn(f64, f64) -> (f64, f64) {
        let (sa, ca) = alpha.sin_cos();
        let (sb, cb) = beta.sin_cos();
        let (st, ct) = theta.sin_cos();
        move |u, v| {
            let (u, v) = (u - 5.0, v - 3.5);
            // Rotation about y (alpha) then about x (beta).
            let (x1, z1) = (u * ca, u * sa);
            let (y2, z2) = (v * cb - z1 * sb, v * sb + z1 * cb);
            let z = d + z2;
            let (px, py) = (f * x1 / z, f * y2 / z);
            (500.0 + ct * px - st * py, 400.0 + st * px + ct * py)
        }
    }

    #[test]
    fn strong_perspective_grid() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        for _ in 0..20 {
            let theta = clear_angle(&mut rng);
            let alpha = 60f64.to_radians();
            let d = 10.0 * alpha.sin();
            let map = perspective(alpha, 10f64.to_radians(), d, 400.0, theta);
            let (c, t) = grid(8, 11, &map, &mut rng, 0.1, 2f64.to_radians());
            // Vertical steps (along v) shrink ≥ 2.9× from the near to the far column.
            let step = |col: usize| {
                let (a, b) = (&c[col], &c[11 + col]);
                (a.x - b.x).hypot(a.y - b.y)
            };
            assert!(step(0) / step(10) > 2.9 || step(10) / step(0) > 2.9);
            let (g, b) = run(&c);
            assert_graph_sane(&g, &t);
            assert_eq!(b.len(), 1);
            assert_eq!(b[0].corners.len(), 88, "theta {theta}");
            assert_exact(&b[0], &t, theta);
        }
    }

    #[test]
    fn cylinder_wrapped_grid() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for _ in 0..20 {
            let theta = clear_angle(&mut rng);
            let rot = rigid(theta, 30.0);
            // 12 columns spread over ±1.1 rad of a cylinder of radius 5 steps.
            let map = move |u: f64, v: f64| rot(5.0 * ((u - 5.5) / 5.0).sin(), v);
            let (c, t) = grid(8, 12, &map, &mut rng, 0.3, 3f64.to_radians());
            let (g, b) = run(&c);
            assert_graph_sane(&g, &t);
            assert_eq!(b.len(), 1);
            assert_eq!(b[0].corners.len(), 96, "theta {theta}");
            assert_exact(&b[0], &t, theta);
        }
    }

    #[test]
    fn arc_bent_grid_directions_turn_60_degrees() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        for _ in 0..20 {
            let theta = clear_angle(&mut rng);
            let rot = rigid(theta, 25.0);
            // Columns along an arc of 60° total; rows along radii (radius 10.5 … 3.5 steps).
            let rb = 11.0 / (PI / 3.0);
            let map = move |u: f64, v: f64| {
                let phi = (u - 5.5) / rb;
                let r = rb - v;
                rot(r * phi.sin(), rb - r * phi.cos())
            };
            let (c, t) = grid(8, 12, &map, &mut rng, 0.3, 3f64.to_radians());
            let tangent = |u: f64| {
                let (a, b) = (map(u, 0.0), map(u + 1e-4, 0.0));
                (b.1 - a.1).atan2(b.0 - a.0)
            };
            let turn = line_diff(tangent(0.0), tangent(11.0));
            assert!(turn.to_degrees() > 50.0, "turn {}", turn.to_degrees());
            let (g, b) = run(&c);
            assert_graph_sane(&g, &t);
            assert_eq!(b.len(), 1);
            assert_eq!(b[0].corners.len(), 96, "theta {theta}");
            assert_exact(&b[0], &t, theta);
        }
    }

    fn remove(
        c: &mut Vec<Corner>,
        t: &mut Vec<Option<(i32, i32)>>,
        drop: impl Fn((i32, i32)) -> bool,
    ) {
        let keep: Vec<bool> = t.iter().map(|l| !drop(l.unwrap())).collect();
        let mut k = keep.iter();
        c.retain(|_| *k.next().unwrap());
        t.retain(|l| !drop(l.unwrap()));
    }

    #[test]
    fn holes_are_walked_around() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let theta = 0.3;
        let (mut c, mut t) = grid(9, 10, &rigid(theta, 25.0), &mut rng, 0.3, 2f64.to_radians());
        // One single hole and one 2×2 hole.
        remove(&mut c, &mut t, |(r, col)| {
            (r, col) == (2, 2) || ((5..7).contains(&r) && (5..7).contains(&col))
        });
        let (g, b) = run(&c);
        assert_graph_sane(&g, &t);
        assert_eq!(b.len(), 1);
        assert_eq!(b[0].corners.len(), 90 - 5);
        assert_exact(&b[0], &t, theta);
    }

    #[test]
    fn ten_percent_random_corners_missing() {
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        for _ in 0..20 {
            let theta = clear_angle(&mut rng);
            let (c0, t0) = grid(
                10,
                12,
                &rigid(theta, 25.0),
                &mut rng,
                0.3,
                2f64.to_radians(),
            );
            let mut idx: Vec<usize> = (0..c0.len()).collect();
            idx.shuffle(&mut rng);
            idx.truncate(c0.len() * 9 / 10);
            idx.sort_unstable();
            let c: Vec<Corner> = idx.iter().map(|&i| c0[i]).collect();
            let t: Vec<_> = idx.iter().map(|&i| t0[i]).collect();
            let (g, b) = run(&c);
            assert_graph_sane(&g, &t);
            assert!(!b.is_empty());
            let labelled: usize = b.iter().map(|b| b.corners.len()).sum();
            // A corner is kept only if one of its cells is complete; nearly all are.
            // The rule keeps exactly the corners of complete cells (all four corners present).
            let present: std::collections::HashSet<(i32, i32)> =
                t.iter().flatten().copied().collect();
            let in_cell = |&(r, c): &(i32, i32)| {
                [(1, 1), (1, -1), (-1, 1), (-1, -1)]
                    .iter()
                    .any(|&(dr, dc)| {
                        [(r + dr, c), (r, c + dc), (r + dr, c + dc)]
                            .iter()
                            .all(|p| present.contains(p))
                    })
            };
            let expected_count = present.iter().filter(|p| in_cell(p)).count();
            assert_eq!(labelled, expected_count);
            assert!(labelled * 100 >= c.len() * 85, "{labelled} of {}", c.len());
            for board in &b {
                assert_exact(board, &t, theta);
            }
        }
    }

    #[test]
    fn board_split_by_an_occluding_band_is_merged() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let theta = -0.2;
        let (mut c, mut t) = grid(
            10,
            10,
            &rigid(theta, 25.0),
            &mut rng,
            0.3,
            2f64.to_radians(),
        );
        remove(&mut c, &mut t, |(r, _)| r == 4);
        let (g, b) = run(&c);
        assert_graph_sane(&g, &t);
        // The two pieces line up across the band: they are merged back into one board.
        assert_eq!(b.len(), 1);
        assert_eq!(b[0].corners.len(), 90);
        assert_exact(&b[0], &t, theta);
    }

    #[test]
    fn a_board_folding_away_from_the_camera_is_merged_across_the_fold() {
        // The rows turn from +h to −h within a step around u = c, like the grid lines where an
        // S-shaped surface folds away. h = 15°, c = 4.8: the links from column 4 to 5 lie 16.7°
        // from the edges at column 5, outside θ_edge, so the grid splits there; the steps
        // beyond the fold disagree with the extrapolated ones by half a step, but the cells
        // across it are parallelograms. h = 22°, c = 4.5 (a ridge): the links lie 21.7° from
        // both ends, and column 5 lies 0.375 steps from the straight extrapolation of the rows.
        for (h, c) in [(15f64, 4.8), (22.0, 4.5)] {
            let step = 30.0;
            let heading = move |u: f64| (h - h * ((u - c) / 0.2).tanh()).to_radians();
            let fold = move |u: f64, v: f64| {
                let n = (u * 400.0).ceil().max(1.0) as usize;
                let du = u / n as f64;
                let (mut x, mut y) = (100.0, 100.0 + v * step);
                for k in 0..n {
                    let (s, c) = heading((k as f64 + 0.5) * du).sin_cos();
                    x += c * du * step;
                    y += s * du * step;
                }
                (x, y)
            };
            let mut rng = ChaCha8Rng::seed_from_u64(11);
            let (c, t) = grid(6, 10, &fold, &mut rng, 0.0, 0.0);
            let g = connect(&c, &ConnectivityParams::default());
            assert_graph_sane(&g, &t);
            let across = |i: usize| {
                g.neighbours[i]
                    .iter()
                    .flatten()
                    .any(|&j| t[i].unwrap().1 == 4 && t[j].unwrap().1 == 5)
            };
            assert!(!(0..c.len()).any(across), "{h}°: the fold is linked");
            let b = label(&c, &g);
            assert_eq!(b.len(), 1, "{h}°");
            assert_eq!(b[0].corners.len(), 60, "{h}°");
            assert_exact(&b[0], &t, 0.0);
        }
    }

    #[test]
    fn a_piece_whose_links_jump_a_hidden_column_is_not_merged_as_a_fold() {
        // A pen hides column 3: the far piece holds columns 2 and 4, linked as neighbours (the
        // cells spanning the pen support each other). Column 1 reaches column 2 at the next site
        // with a step half the far piece's, which a fold does not do.
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let (c, t) = grid(4, 6, &rigid(0.05, 40.0), &mut rng, 0.3, 0.0);
        let board = |cols: &[i32]| {
            let mut v: Vec<((i32, i32), usize)> = (0..c.len())
                .filter_map(|i| {
                    let (r, k) = t[i].unwrap();
                    let slot = cols.iter().position(|&x| x == k)?;
                    Some(((r, slot as i32), i))
                })
                .collect();
            v.sort_unstable();
            Board {
                corners: v.iter().map(|x| x.1).collect(),
                labels: v.iter().map(|x| x.0).collect(),
                rows: 4,
                cols: cols.len(),
            }
        };
        let b = merge_split_boards(&c, vec![board(&[0, 1]), board(&[2, 4])], |_| None);
        assert_eq!(b.len(), 2);
    }

    #[test]
    fn pieces_whose_lines_disagree_on_the_gap_merge_only_where_the_phase_decides() {
        // Two pieces of 6 × 3 corners: the left one steps 20 px, the right one 24 px and starts
        // 35 px beyond the left one's last column. Each left row reaches the right piece two
        // steps on (a column hidden between them); each right row reaches the left piece two
        // steps on too, which puts no column between them. Both placements fit.
        let piece = |x0: f64, step: f64, first: usize| {
            let corners: Vec<Corner> = (0..6)
                .flat_map(|r| {
                    (0..3).map(move |k| Corner {
                        x: x0 + step * k as f64,
                        y: 20.0 * r as f64,
                        angles: [0.0, FRAC_PI_2],
                        score: 1.0,
                    })
                })
                .collect();
            let board = Board {
                corners: (first..first + 18).collect(),
                labels: (0..6).flat_map(|r| (0..3).map(move |k| (r, k))).collect(),
                rows: 6,
                cols: 3,
            };
            (corners, board)
        };
        let (mut c, left) = piece(0.0, 20.0, 0);
        let (right_corners, right) = piece(75.0, 24.0, 18);
        c.extend(right_corners);
        let b = merge_split_boards(&c, vec![left.clone(), right.clone()], |_| None);
        assert_eq!(b.len(), 2, "merged although the lines disagree");
        // Pieces of opposite phases: only adjacent columns keep the checker across the gap.
        let b = merge_split_boards(&c, vec![left.clone(), right.clone()], |b| {
            Some(b.corners[0] == 0)
        });
        assert_eq!(b.len(), 1);
        let col = |i: usize| b[0].labels[b[0].corners.iter().position(|&j| j == i).unwrap()].1;
        assert_eq!((col(2), col(18)), (2, 3));
        // Pieces of one phase: a hidden column would keep it, but fewer lines say so.
        let b = merge_split_boards(&c, vec![left, right], |_| Some(true));
        assert_eq!(b.len(), 2);
    }

    #[test]
    fn a_piece_with_one_row_beyond_a_band_is_compared_across_its_columns() {
        // Rows 0–4 (columns 1–5) above a band hiding row 5; below it row 6 (columns 0–2) and
        // row 7 (columns 0–1), as a completion leaves them. Column 1 meets the lower piece with
        // its own step down; column 2 meets (6, 2), which has no step down, and is compared by
        // the rows' step instead.
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (c, t) = grid(8, 6, &rigid(0.1, 25.0), &mut rng, 0.3, 0.0);
        let piece = |keep: &dyn Fn(i32, i32) -> bool| {
            let mut v: Vec<((i32, i32), usize)> = (0..c.len())
                .filter_map(|i| t[i].filter(|&(r, k)| keep(r, k)).map(|l| (l, i)))
                .collect();
            v.sort_unstable();
            let (r0, c0) = (
                v.iter().map(|x| x.0 .0).min().unwrap(),
                v.iter().map(|x| x.0 .1).min().unwrap(),
            );
            let labels: Vec<(i32, i32)> = v.iter().map(|x| (x.0 .0 - r0, x.0 .1 - c0)).collect();
            Board {
                corners: v.iter().map(|x| x.1).collect(),
                rows: labels.iter().map(|l| l.0 + 1).max().unwrap() as usize,
                cols: labels.iter().map(|l| l.1 + 1).max().unwrap() as usize,
                labels,
            }
        };
        let upper = piece(&|r, k| r <= 4 && k >= 1);
        let lower = piece(&|r, k| (r == 6 && k <= 2) || (r == 7 && k <= 1));
        let b = merge_split_boards(&c, vec![upper, lower], |_| None);
        assert_eq!(b.len(), 1);
        assert_eq!(b[0].corners.len(), 30);
        assert_exact(&b[0], &t, 0.1);
    }

    #[test]
    fn pieces_of_a_board_at_45_degrees_are_merged_whatever_axes_they_take() {
        // At 45° each piece's canonical orientation takes whichever axis its corners' edge
        // angles (1.7° of noise) tilt nearer the image's x as its columns: the two pieces either
        // side of a hidden row differ by a quarter turn in some of these grids (seed 0 among
        // them).
        for seed in 0..12 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let (mut c, mut t) = grid(9, 9, &rigid(FRAC_PI_4, 25.0), &mut rng, 0.3, 0.03);
            remove(&mut c, &mut t, |(r, _)| r == 4);
            let g = connect(&c, &ConnectivityParams::default());
            let pieces = label(&c, &g);
            assert_eq!(pieces.len(), 1, "seed {seed}");
            let b = &pieces[0];
            assert_eq!(b.corners.len(), 72, "seed {seed}");
            // Labels are the truth up to one quarter turn and one translation.
            let fits = (0..4).any(|k| {
                let off = |i: usize| {
                    let (r, c) = quarter_turn(t[b.corners[i]].unwrap(), k);
                    (b.labels[i].0 - r, b.labels[i].1 - c)
                };
                (0..b.corners.len()).all(|i| off(i) == off(0))
            });
            assert!(fits, "seed {seed}: labels off the grid");
        }
    }

    #[test]
    fn oblique_occluding_band() {
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        for _ in 0..10 {
            let theta = clear_angle(&mut rng);
            let (mut c, mut t) = grid(
                10,
                12,
                &rigid(theta, 25.0),
                &mut rng,
                0.3,
                2f64.to_radians(),
            );
            // A band 1.5 steps wide crossing at ~30° to the rows.
            remove(&mut c, &mut t, |(r, col)| {
                ((r as f64 - 5.0) - 0.55 * (col as f64 - 6.0)).abs() < 0.8
            });
            let (g, b) = run(&c);
            assert_graph_sane(&g, &t);
            let labelled: usize = b.iter().map(|b| b.corners.len()).sum();
            assert!(labelled * 100 >= c.len() * 85, "{labelled} of {}", c.len());
            for board in &b {
                assert_exact(board, &t, theta);
            }
        }
    }

    #[test]
    fn two_grids_give_two_boards() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let (mut c, mut t) = grid(6, 7, &rigid(0.2, 20.0), &mut rng, 0.3, 2f64.to_radians());
        let far = rigid(2.0, 30.0);
        let (c2, t2) = grid(
            5,
            8,
            &|u, v| {
                let p = far(u, v);
                (p.0 + 700.0, p.1 + 100.0)
            },
            &mut rng,
            0.3,
            2f64.to_radians(),
        );
        let n1 = c.len();
        c.extend(c2);
        t.extend(t2);
        let (_, b) = run(&c);
        assert_eq!(b.len(), 2);
        assert_eq!((b[0].corners.len(), b[1].corners.len()), (42, 40));
        assert!(b[0].corners.iter().all(|&i| i < n1));
        assert!(b[1].corners.iter().all(|&i| i >= n1));
        assert_exact(&b[0], &t, 0.2);
        assert_exact(&b[1], &t, 2.0);
    }

    #[test]
    fn outliers_stay_unlabelled() {
        let mut rng = ChaCha8Rng::seed_from_u64(10);
        for round in 0..20 {
            let theta = clear_angle(&mut rng);
            let map = rigid(theta, 25.0);
            let (mut c, mut t) = grid(10, 10, &map, &mut rng, 0.3, 2f64.to_radians());
            let n = c.len();
            for _ in 0..80 {
                let (u, v, angles) = if round % 2 == 0 {
                    // Random orientations, anywhere on and around the board.
                    let (u, v) = (rng.gen_range(-2.0..11.0), rng.gen_range(-2.0..11.0));
                    (u, v, [rng.gen_range(0.0..PI), rng.gen_range(0.0..PI)])
                } else {
                    // Orientations of the grid, inside its cells (off its lines).
                    let (u, v) = (rng.gen_range(0.0..9.0f64), rng.gen_range(0.0..9.0f64));
                    if (u - u.round()).abs() < 0.25 || (v - v.round()).abs() < 0.25 {
                        continue;
                    }
                    let a = [theta, theta + FRAC_PI_2]
                        .map(|a| (a + rng.gen_range(-0.05..0.05)).rem_euclid(PI));
                    (u, v, a)
                };
                // A detector's non-maximum suppression keeps false corners off true ones.
                if (u - u.round()).hypot(v - v.round()) < 0.35 {
                    continue;
                }
                let (x, y) = map(u, v);
                c.push(Corner {
                    x,
                    y,
                    angles,
                    score: 0.8,
                });
                t.push(None);
            }
            let (_, b) = run(&c);
            let labelled: usize = b.iter().map(|b| b.corners.len()).sum();
            assert!(labelled * 100 >= n * 85, "round {round}: {labelled} of {n}");
            for board in &b {
                assert!(
                    board.corners.iter().all(|&i| i < n),
                    "round {round}: outlier labelled"
                );
                assert_exact(board, &t, theta);
            }
        }
    }

    #[test]
    fn bad_inputs_give_no_boards() {
        let p = ConnectivityParams::default();
        assert!(label(&[], &connect(&[], &p)).is_empty());
        let one = [Corner {
            x: 1.0,
            y: 2.0,
            angles: [0.0, 1.5],
            score: 1.0,
        }];
        let g = connect(&one, &p);
        assert_eq!(g.neighbours, vec![[None; 4]]);
        assert!(label(&one, &g).is_empty());
        // Non-finite, coincident, degenerate-orientation and collinear corners.
        let mut bad = vec![
            Corner {
                x: f64::NAN,
                y: 0.0,
                angles: [0.0, 1.5],
                score: 1.0,
            },
            Corner {
                x: 0.0,
                y: f64::INFINITY,
                angles: [0.0, 1.5],
                score: 1.0,
            },
            Corner {
                x: 5.0,
                y: 5.0,
                angles: [f64::NAN, 1.5],
                score: 1.0,
            },
            Corner {
                x: 9.0,
                y: 9.0,
                angles: [0.3, 0.35],
                score: f64::NAN,
            },
        ];
        for k in 0..6 {
            bad.push(Corner {
                x: 10.0 * k as f64,
                y: 0.0,
                angles: [0.0, FRAC_PI_2],
                score: 1.0,
            });
            bad.push(Corner {
                x: 10.0 * k as f64,
                y: 0.0,
                angles: [0.0, FRAC_PI_2],
                score: 1.0,
            });
        }
        let g = connect(&bad, &p);
        assert_eq!(g.edges().count(), 0, "a single line has no cells");
        assert!(label(&bad, &g).is_empty());
        // A graph that does not match the corners, or points out of range.
        assert!(label(&one, &Graph::default()).is_empty());
        let wild = Graph {
            neighbours: vec![[Some(7), Some(0), None, None]],
        };
        assert!(label(&one, &wild).is_empty());
        // Absurd parameters.
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let (c, _) = grid(4, 4, &rigid(0.0, 20.0), &mut rng, 0.0, 0.0);
        let nan = ConnectivityParams {
            theta_edge: f64::NAN,
            ..p
        };
        assert_eq!(connect(&c, &nan).edges().count(), 0);
    }

    #[test]
    fn duplicated_corners_do_not_break_the_grid() {
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        let (mut c, mut t) = grid(5, 6, &rigid(0.1, 20.0), &mut rng, 0.2, 0.02);
        c.push(c[8]);
        t.push(t[8]);
        let (_, b) = run(&c);
        assert_eq!(b.len(), 1);
        assert_eq!(b[0].corners.len(), 30);
        assert_exact(&b[0], &t, 0.1);
    }

    #[test]
    fn min_corners_parameter() {
        let mut rng = ChaCha8Rng::seed_from_u64(13);
        let (c, t) = grid(2, 2, &rigid(0.0, 20.0), &mut rng, 0.0, 0.0);
        let g = connect(&c, &ConnectivityParams::default());
        let b = label(&c, &g);
        assert_eq!(b.len(), 1);
        assert_exact(&b[0], &t, 0.0);
        assert!(label_with(&c, &g, &LabelParams { min_corners: 5 }).is_empty());
    }

    #[test]
    fn labels_do_not_depend_on_input_order() {
        let mut rng = ChaCha8Rng::seed_from_u64(14);
        // Exactly 45°: the tie rule must still give one answer for one input.
        for theta in [PI / 4.0, 1.0, 3.0 * PI / 4.0] {
            let (c, t) = grid(7, 9, &rigid(theta, 25.0), &mut rng, 0.3, 2f64.to_radians());
            let (_, b) = run(&c);
            assert_eq!(b.len(), 1);
            assert!(lattice_iso(&b[0], &t));
            assert_eq!(run(&c).1, b);
            let by_truth = |c: &[Corner], t: &[Option<(i32, i32)>], b: &Board| {
                let mut v: Vec<_> = b
                    .corners
                    .iter()
                    .zip(&b.labels)
                    .map(|(&i, &l)| (t[i], l))
                    .collect();
                v.sort_unstable();
                let _ = c;
                v
            };
            let mut perm: Vec<usize> = (0..c.len()).collect();
            perm.shuffle(&mut rng);
            let cp: Vec<Corner> = perm.iter().map(|&i| c[i]).collect();
            let tp: Vec<_> = perm.iter().map(|&i| t[i]).collect();
            let (_, bp) = run(&cp);
            assert_eq!(by_truth(&cp, &tp, &bp[0]), by_truth(&c, &t, &b[0]));
        }
    }

    #[test]
    fn five_hundred_corners_under_perspective_form_one_board() {
        let mut rng = ChaCha8Rng::seed_from_u64(15);
        let (c, _) = grid(
            20,
            25,
            &perspective(0.7, 0.2, 30.0, 1500.0, 0.3),
            &mut rng,
            0.2,
            0.03,
        );
        // Speed is the criterion benchmark's business (`cargo bench`); this checks the answer.
        let boards = label(&c, &connect(&c, &ConnectivityParams::default()));
        assert_eq!(boards.len(), 1);
        assert_eq!(boards[0].corners.len(), 500);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        #[test]
        fn true_neighbours_differ_by_one(
            theta in 0.0..(2.0 * PI),
            alpha in 0.0f64..0.9,
            beta in -0.5f64..0.5,
            seed in any::<u64>(),
        ) {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let map = perspective(alpha, beta, 14.0, 600.0, theta);
            let (c, t) = grid(8, 11, &map, &mut rng, 0.2, 2f64.to_radians());
            let (g, b) = run(&c);
            assert_graph_sane(&g, &t);
            prop_assert_eq!(b.len(), 1);
            prop_assert_eq!(b[0].corners.len(), 88);
            prop_assert!(lattice_iso(&b[0], &t));
        }
    }
}
