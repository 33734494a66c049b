//! Overlay pictures of a detection: grid edges, corners and their labels on the grey image.

use conic_corners::board_fit::BoardFit;
use conic_corners::detect::Detection;
use conic_corners::quadratic_form::Curve;
use conic_corners::GrayImage;
use image::{Rgb, RgbImage};
use imageproc::drawing::{draw_filled_circle_mut, draw_hollow_circle_mut, draw_line_segment_mut};
use std::collections::HashMap;

/// Per-board colours, cycled.
const PALETTE: [[u8; 3]; 6] = [
    [0, 200, 255],
    [255, 120, 0],
    [120, 255, 0],
    [255, 0, 200],
    [255, 230, 0],
    [0, 255, 160],
];

/// Digits as 3×5 bitmaps (rows top to bottom, 3 bits each), so labels need no font file.
const DIGITS: [[u8; 5]; 10] = [
    [7, 5, 5, 5, 7],
    [2, 6, 2, 2, 7],
    [7, 1, 7, 4, 7],
    [7, 1, 7, 1, 7],
    [5, 5, 7, 1, 1],
    [7, 4, 7, 1, 7],
    [7, 4, 7, 5, 7],
    [7, 1, 1, 1, 1],
    [7, 5, 7, 5, 7],
    [7, 5, 7, 1, 7],
];

fn draw_text(img: &mut RgbImage, x: i64, y: i64, text: &str, scale: i64, colour: Rgb<u8>) {
    let mut cx = x;
    for ch in text.chars() {
        let glyph: Option<[u8; 5]> = match ch {
            '0'..='9' => Some(DIGITS[ch as usize - '0' as usize]),
            ',' => Some([0, 0, 0, 2, 4]),
            '-' => Some([0, 0, 7, 0, 0]),
            _ => None,
        };
        if let Some(g) = glyph {
            for (r, bits) in g.iter().enumerate() {
                for c in 0..3 {
                    if bits & (4 >> c) != 0 {
                        for dy in 0..scale {
                            for dx in 0..scale {
                                let (px, py) = (cx + c * scale + dx, y + r as i64 * scale + dy);
                                if px >= 0
                                    && py >= 0
                                    && (px as u32) < img.width()
                                    && (py as u32) < img.height()
                                {
                                    img.put_pixel(px as u32, py as u32, colour);
                                }
                            }
                        }
                    }
                }
            }
        }
        cx += 4 * scale;
    }
}

/// The point of `curve` nearest `p`, by two Newton steps along the gradient (the samples are within
/// a fraction of a pixel of their curve).
fn onto(curve: &Curve, p: [f64; 2]) -> [f64; 2] {
    let conic = curve.as_conic();
    let mut q = p;
    for _ in 0..2 {
        let [gx, gy] = conic.gradient(q[0], q[1]);
        let g2 = gx * gx + gy * gy;
        if g2.is_nan() || g2 <= 0.0 {
            break;
        }
        let f = conic.eval(q[0], q[1]) / g2;
        q = [q[0] - f * gx, q[1] - f * gy];
    }
    q
}

/// Draws the board-wide fit in the style of the paper's Fig. 9: every edge sample as a dot and
/// each fitted segment as its curve over the samples it was fitted to.
pub fn draw_board_fits(out: &mut RgbImage, fits: &[BoardFit]) {
    for fit in fits {
        for line in &fit.lines {
            for s in &line.samples {
                let (x, y) = (s[0].round(), s[1].round());
                if x >= 0.0 && y >= 0.0 && (x as u32) < out.width() && (y as u32) < out.height() {
                    out.put_pixel(x as u32, y as u32, Rgb([255, 220, 0]));
                }
            }
            for seg in &line.segments {
                let Some((curve, ..)) = &seg.fit else {
                    continue;
                };
                let pts: Vec<[f64; 2]> = line.samples[seg.range()]
                    .iter()
                    .map(|&p| onto(curve, p))
                    .collect();
                for w in pts.windows(2) {
                    let (a, b) = (w[0], w[1]);
                    // Samples skip the corners' blurred zones; do not bridge gaps wider than that.
                    if (a[0] - b[0]).hypot(a[1] - b[1]) < 40.0 {
                        draw_line_segment_mut(
                            out,
                            (a[0] as f32, a[1] as f32),
                            (b[0] as f32, b[1] as f32),
                            Rgb([0, 255, 0]),
                        );
                    }
                }
            }
        }
    }
}

/// The grey image (min–max stretched) in colour, with every board's grid edges, its corners, their
/// `row,col` labels and a larger mark on corner (0, 0).
pub fn draw_detection(image: &GrayImage, det: &Detection) -> RgbImage {
    let (lo, hi) = image.min_max();
    let grey = image.to_luma8(lo, hi);
    let mut out = RgbImage::from_fn(grey.width(), grey.height(), |x, y| {
        let v = grey.get_pixel(x, y)[0];
        Rgb([v, v, v])
    });
    // Marks scale with the image so that they stay visible on large photos.
    let unit = ((image.width().max(image.height()) as f32 / 1000.0).ceil() as i32).max(1);
    for (bi, board) in det.boards.iter().enumerate() {
        let colour = Rgb(PALETTE[bi % PALETTE.len()]);
        let at: HashMap<(i32, i32), (f32, f32)> = board
            .corners
            .iter()
            .map(|c| ((c.row, c.col), (c.x as f32, c.y as f32)))
            .collect();
        for c in &board.corners {
            for (dr, dc) in [(0, 1), (1, 0)] {
                if let Some(&q) = at.get(&(c.row + dr, c.col + dc)) {
                    draw_line_segment_mut(&mut out, (c.x as f32, c.y as f32), q, colour);
                }
            }
        }
        for c in &board.corners {
            let p = (c.x.round() as i32, c.y.round() as i32);
            draw_hollow_circle_mut(&mut out, p, 3 * unit, Rgb([255, 0, 0]));
            if (c.row, c.col) == (0, 0) {
                draw_filled_circle_mut(&mut out, p, 5 * unit, Rgb([255, 0, 0]));
            }
            let label = format!("{},{}", c.row, c.col);
            draw_text(
                &mut out,
                p.0 as i64 + 4 * unit as i64,
                p.1 as i64 + 2 * unit as i64,
                &label,
                unit as i64,
                colour,
            );
        }
    }
    out
}
