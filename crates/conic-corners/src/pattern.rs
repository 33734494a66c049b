//! Boards in the frame of a known pattern: the labels a calibration needs.
//!
//! Without a pattern, [`crate::connectivity`] labels a board by the image: columns grow towards
//! +x, rows towards +y, the smallest label 0. That is deterministic, but it follows the camera:
//! turn the board by more than 45° in the image and its physical corner (0, 0) gets another
//! label, so views of one board would pair different corners with one board point. Given the
//! board's inner-corner grid ([`Pattern`], OpenCV's `patternSize` read as rows × cols), a board
//! that spans it is put into the pattern's frame ([`to_pattern`]):
//!
//! 1. **Axes.** Its labels are turned by a quarter turn where its extent is the pattern's
//!    transposed, so that it has `pattern.rows` rows of `pattern.cols` corners. Only turns:
//!    a board seen from its front is never mirrored, and every frame here has the same
//!    handedness as the image's (rows towards +y when columns run towards +x).
//! 2. **Colour.** Of the turns that keep that extent (the half turn, and the quarter turns of a
//!    square pattern), the one whose first square (between corners (0, 0) and (1, 1)) is dark
//!    wins. Where `pattern.rows + pattern.cols` is odd (OpenCV's 9 × 6 and most calibration
//!    boards), a half turn changes that square's colour, so the frame is fixed by the print alone
//!    and every view labels each physical corner alike whatever the camera's roll.
//! 3. **Ties** (both candidates' first squares of one colour: an even sum, or no measurable
//!    colour): the turn whose labels grow most towards the image's bottom-right, that is
//!    `(0, 0)` nearest the top-left, as without a pattern.
//!
//! A board whose extent is not the pattern's (part of the board hidden, or another board) cannot
//! be put into its frame and is dropped by [`crate::detect`]. Missing corners inside the extent do
//! not matter: the extent alone fixes the frame.
//!
//! The colour is measured on the refined corners: each square whose four corners are on the
//! board is sampled at five points (its centre and its four quarter points, bilinear between the
//! corners), the median standing for it (a dot or a highlight in a square moves one sample). Each
//! square votes dark or light against the mean of its side neighbours (so that uneven light,
//! which changes little from one square to the next, does not sway it); the squares of one parity
//! (`(row + col) mod 2`) are dark when at least four fifths of the votes say so, and the colour is
//! unknown otherwise.
//!
//! Coordinates: x right, y down, the centre of the top-left pixel is `(0, 0)`.

use crate::detect::{Board, DetectedCorner};
use crate::segmentation::median_in_place;
use crate::GrayImage;
use std::collections::HashMap;

/// A plain checkerboard's inner-corner grid: `rows` rows of `cols` corners each. OpenCV's
/// `patternSize = (points per row, points per column)` is `Pattern { rows: patternSize.height,
/// cols: patternSize.width }`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Pattern {
    /// Rows of corners (at least 2).
    pub rows: usize,
    /// Corners per row (at least 2).
    pub cols: usize,
}

impl Pattern {
    /// Checks the sizes; the message names the offending one.
    pub fn validate(&self) -> Result<(), String> {
        if self.rows < 2 || self.cols < 2 {
            return Err(format!(
                "a pattern needs at least 2 × 2 inner corners, got {} × {}",
                self.rows, self.cols
            ));
        }
        Ok(())
    }
}

/// Label `(r, c)` of a grid of extent `(rows, cols)` after `quarter` quarter turns (each maps
/// `(r, c)` to `(c, rows − 1 − r)`, a turn with the image's handedness, and the extent to
/// `(cols, rows)`).
fn turn((r, c): (i32, i32), quarter: u8, (rows, cols): (i32, i32)) -> (i32, i32) {
    match quarter % 4 {
        0 => (r, c),
        1 => (c, rows - 1 - r),
        2 => (rows - 1 - r, cols - 1 - c),
        _ => (cols - 1 - c, r),
    }
}

/// The extent `(rows, cols)` after `quarter` quarter turns.
fn turned_extent((rows, cols): (i32, i32), quarter: u8) -> (i32, i32) {
    if quarter % 2 == 0 {
        (rows, cols)
    } else {
        (cols, rows)
    }
}

/// The parity `(row + col) mod 2` of the board's dark squares (the square between corners
/// `(r, c)` and `(r + 1, c + 1)` having parity `(r + c) mod 2`); `None` when the colours are not
/// clear (see the module docs).
pub fn dark_parity(image: &GrayImage, board: &Board) -> Option<i32> {
    let at: HashMap<(i32, i32), [f64; 2]> = board
        .corners
        .iter()
        .map(|c| ((c.row, c.col), [c.x, c.y]))
        .collect();
    let mut squares: HashMap<(i32, i32), f64> = HashMap::new();
    for (&(r, c), &p00) in &at {
        let (Some(&p01), Some(&p10), Some(&p11)) = (
            at.get(&(r, c + 1)),
            at.get(&(r + 1, c)),
            at.get(&(r + 1, c + 1)),
        ) else {
            continue;
        };
        // Bilinear between the four corners: (u, v) = (0, 0) at p00, (1, 0) at p01.
        let point = |u: f64, v: f64| {
            [0, 1].map(|k| {
                (1.0 - v) * ((1.0 - u) * p00[k] + u * p01[k])
                    + v * ((1.0 - u) * p10[k] + u * p11[k])
            })
        };
        let mut samples = [0.0f64; 5];
        let mut n = 0;
        for (u, v) in [(0.5, 0.5), (0.3, 0.3), (0.7, 0.3), (0.3, 0.7), (0.7, 0.7)] {
            let q = point(u, v);
            if let Some(g) = image.bilinear(q[0] as f32, q[1] as f32) {
                samples[n] = f64::from(g);
                n += 1;
            }
        }
        if n > 0 {
            squares.insert((r, c), median_in_place(&mut samples[..n]));
        }
    }
    // Each square against its side neighbours, which have the other colour: a vote that uneven
    // light does not sway (it changes little from one square to the next).
    let (mut votes, mut even_dark) = (0usize, 0usize);
    for (&(r, c), &g) in &squares {
        let (sum, n) = [(0, 1), (0, -1), (1, 0), (-1, 0)]
            .iter()
            .filter_map(|(dr, dc)| squares.get(&(r + dr, c + dc)))
            .fold((0.0, 0usize), |(s, n), &h| (s + h, n + 1));
        if n == 0 {
            continue;
        }
        let d = g - sum / n as f64;
        if d == 0.0 {
            continue;
        }
        votes += 1;
        even_dark += usize::from((d < 0.0) == ((r + c).rem_euclid(2) == 0));
    }
    let share = even_dark as f64 / votes.max(1) as f64;
    if votes == 0 {
        None
    } else if share >= CLEAR_SHARE {
        Some(0)
    } else if share <= 1.0 - CLEAR_SHARE {
        Some(1)
    } else {
        None
    }
}

/// Share of the squares that must agree on which parity is dark.
const CLEAR_SHARE: f64 = 0.8;

/// Puts `board` into the frame of `pattern` (see the module docs): turns its labels so that it
/// has `pattern.rows` rows of `pattern.cols` corners, its first square dark where the colours
/// tell, and re-sorts its corners by `(row, col)`. Returns `false`, leaving the board as it was,
/// when its extent is not the pattern's either way round. Positions, σ and covariances are
/// untouched (image coordinates).
pub fn to_pattern(image: &GrayImage, board: &mut Board, pattern: Pattern) -> bool {
    let extent = (board.rows as i32, board.cols as i32);
    let want = (pattern.rows as i32, pattern.cols as i32);
    let fits = |q: &u8| turned_extent(extent, *q) == want;
    if !(0..4u8).any(|q| fits(&q)) {
        return false;
    }
    let dark = dark_parity(image, board);
    // Does the turn's first square lie on a dark square? Its corners (0, 0) and (1, 1) come
    // from two diagonal corners of one square in the old labels, whose smaller row and column
    // name that square.
    let first_dark = |q: u8| -> bool {
        let back = (4 - q) % 4;
        let (a, b) = (turn((0, 0), back, want), turn((1, 1), back, want));
        dark == Some((a.0.min(b.0) + a.1.min(b.1)).rem_euclid(2))
    };
    let n = board.corners.len() as f64;
    let (mx, my) = board
        .corners
        .iter()
        .fold((0.0, 0.0), |(x, y), c| (x + c.x / n, y + c.y / n));
    // How much the turned labels grow towards the image's bottom-right.
    let growth = |q: u8| -> f64 {
        board
            .corners
            .iter()
            .map(|c| {
                let (r, k) = turn((c.row, c.col), q, extent);
                f64::from(r + k) * (c.x - mx + c.y - my)
            })
            .sum()
    };
    // The dark first square, then the growth; ties to the fewest turns.
    let best = (0..4u8)
        .filter(fits)
        .map(|q| (first_dark(q), growth(q), q))
        .max_by(|a, b| {
            (a.0, a.1)
                .partial_cmp(&(b.0, b.1))
                .unwrap_or(std::cmp::Ordering::Equal)
                .then(b.2.cmp(&a.2))
        })
        .map_or(0, |k| k.2);
    for c in &mut board.corners {
        (c.row, c.col) = turn((c.row, c.col), best, extent);
    }
    board
        .corners
        .sort_by_key(|c: &DetectedCorner| (c.row, c.col));
    (board.rows, board.cols) = (pattern.rows, pattern.cols);
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::board_fit::Path;
    use crate::refine::Status;

    fn corner(row: i32, col: i32, x: f64, y: f64) -> DetectedCorner {
        DetectedCorner {
            x,
            y,
            row,
            col,
            score: 1.0,
            status: Status::Converged,
            residual: None,
            path: Path::Board,
            sigma: None,
            cov: None,
        }
    }

    /// An image of `rows × cols` inner corners, squares of `side` px, the first square (between
    /// the first two rows and columns of corners) dark iff `first_dark`, and the board whose
    /// labels run along the image axes.
    fn checker(rows: usize, cols: usize, side: f64, first_dark: bool) -> (GrayImage, Board) {
        let (w, h) = ((cols + 1) as f64 * side, (rows + 1) as f64 * side);
        let mut data = Vec::new();
        for y in 0..h as usize {
            for x in 0..w as usize {
                let (i, j) = ((y as f64 / side) as usize, (x as f64 / side) as usize);
                let dark = ((i + j) % 2 == 0) == first_dark;
                data.push(if dark { 0.1 } else { 0.9 });
            }
        }
        let image = GrayImage::from_vec(w as usize, h as usize, data).unwrap();
        let corners = (0..rows as i32)
            .flat_map(|r| (0..cols as i32).map(move |c| (r, c)))
            .map(|(r, c)| {
                let p = |k: i32| (k + 1) as f64 * side - 0.5;
                corner(r, c, p(c), p(r))
            })
            .collect();
        (
            image,
            Board {
                rows,
                cols,
                corners,
                sigma_scale: None,
            },
        )
    }

    /// The board with its labels turned by `quarter` quarter turns (as a camera rolled the
    /// other way would have labelled it) and sorted.
    fn relabelled(board: &Board, quarter: u8) -> Board {
        let extent = (board.rows as i32, board.cols as i32);
        let mut b = board.clone();
        for c in &mut b.corners {
            (c.row, c.col) = turn((c.row, c.col), quarter, extent);
        }
        b.corners.sort_by_key(|c| (c.row, c.col));
        (b.rows, b.cols) = {
            let (r, c) = turned_extent(extent, quarter);
            (r as usize, c as usize)
        };
        b
    }

    fn label_of(board: &Board, x: f64, y: f64) -> (i32, i32) {
        let c = board
            .corners
            .iter()
            .find(|c| (c.x - x).abs() < 1e-9 && (c.y - y).abs() < 1e-9)
            .unwrap();
        (c.row, c.col)
    }

    #[test]
    fn turns_keep_the_handedness_and_invert() {
        let extent = (3, 5);
        for q in 0..4u8 {
            let e = turned_extent(extent, q);
            for (r, c) in [(0, 0), (0, 1), (1, 0), (2, 4)] {
                let t = turn((r, c), q, extent);
                assert!(
                    (0..e.0).contains(&t.0) && (0..e.1).contains(&t.1),
                    "{q} {t:?}"
                );
                assert_eq!(turn(t, (4 - q) % 4, e), (r, c));
            }
            // The steps along a row and down a column stay a right-handed pair.
            let (o, a, b) = (
                turn((1, 1), q, extent),
                turn((1, 2), q, extent),
                turn((2, 1), q, extent),
            );
            let (u, v) = ((a.0 - o.0, a.1 - o.1), (b.0 - o.0, b.1 - o.1));
            assert_eq!(u.1 * v.0 - u.0 * v.1, 1, "quarter turns {q}");
        }
    }

    #[test]
    fn the_dark_squares_parity_is_measured() {
        for first_dark in [true, false] {
            let (image, board) = checker(4, 5, 12.0, first_dark);
            assert_eq!(
                dark_parity(&image, &board),
                Some(if first_dark { 0 } else { 1 })
            );
        }
        // Light falling off tenfold across the board: its light squares on the dim side are
        // darker than its dark squares on the bright side.
        let (mut image, board) = checker(4, 9, 12.0, true);
        let w = image.width();
        for (i, g) in image.data_mut().iter_mut().enumerate() {
            *g *= 1.0 - 0.9 * (i % w) as f32 / w as f32;
        }
        assert_eq!(dark_parity(&image, &board), Some(0));
        // A flat image has no colours to tell.
        let (_, board) = checker(4, 5, 12.0, true);
        let flat = GrayImage::filled(72, 60, 0.5).unwrap();
        assert_eq!(dark_parity(&flat, &board), None);
    }

    /// A 6 × 9 board (odd sum): every relabelling by the camera gives back one frame, with its
    /// first square dark: the physical corner at each position gets the same label.
    #[test]
    fn an_odd_pattern_is_labelled_alike_whatever_the_turn() {
        for first_dark in [true, false] {
            let (image, board) = checker(6, 9, 10.0, first_dark);
            let pattern = Pattern { rows: 6, cols: 9 };
            let mut reference = None;
            for q in 0..4u8 {
                let mut b = relabelled(&board, q);
                assert!(to_pattern(&image, &mut b, pattern));
                assert_eq!((b.rows, b.cols), (6, 9));
                assert_eq!(dark_parity(&image, &b), Some(0), "first square dark");
                let labels: Vec<(i32, i32)> = board
                    .corners
                    .iter()
                    .map(|c| label_of(&b, c.x, c.y))
                    .collect();
                match &reference {
                    None => reference = Some(labels),
                    Some(r) => assert_eq!(&labels, r, "quarter turns {q}"),
                }
                assert!(b
                    .corners
                    .windows(2)
                    .all(|w| (w[0].row, w[0].col) < (w[1].row, w[1].col)));
            }
        }
    }

    /// A 5 × 7 board (even sum): both half turns have a first square of one colour; the frame
    /// puts (0, 0) nearest the image's top-left.
    #[test]
    fn an_even_pattern_starts_at_the_top_left() {
        let (image, board) = checker(5, 7, 10.0, true);
        for q in 0..4u8 {
            let mut b = relabelled(&board, q);
            assert!(to_pattern(&image, &mut b, Pattern { rows: 5, cols: 7 }));
            assert_eq!(b.corners[0].row, 0);
            assert_eq!(
                (b.corners[0].x, b.corners[0].y),
                (9.5, 9.5),
                "quarter turns {q}"
            );
        }
    }

    /// A square pattern of odd side: the quarter turns change the first square's colour, so a
    /// dark first square leaves the half turn to the image.
    #[test]
    fn a_square_pattern_takes_a_dark_first_square() {
        let (image, board) = checker(7, 7, 10.0, false);
        for q in 0..4u8 {
            let mut b = relabelled(&board, q);
            assert!(to_pattern(&image, &mut b, Pattern { rows: 7, cols: 7 }));
            assert_eq!(dark_parity(&image, &b), Some(0), "quarter turns {q}");
        }
    }

    #[test]
    fn a_board_of_another_extent_is_left_alone() {
        let (image, board) = checker(6, 9, 10.0, true);
        let mut b = board.clone();
        assert!(!to_pattern(&image, &mut b, Pattern { rows: 6, cols: 8 }));
        assert_eq!(b, board);
        // Missing corners inside the extent do not matter.
        let mut b = board.clone();
        b.corners
            .retain(|c| (c.row, c.col) != (2, 3) && (c.row, c.col) != (0, 0));
        assert!(to_pattern(&image, &mut b, Pattern { rows: 9, cols: 6 }));
        assert_eq!((b.rows, b.cols), (9, 6));
        assert_eq!(b.corners.len(), 52);
        assert!(Pattern { rows: 1, cols: 9 }.validate().is_err());
        assert!(Pattern { rows: 2, cols: 2 }.validate().is_ok());
    }
}
