//! The paper's synthetic single corner (section IV-A): two circular-arc edges crossing on a plane,
//! seen through a pinhole camera, area-sampled, blurred and made noisy, with exact truth.
//!
//! **Planar pattern.** In plane coordinates `p = (u, v)` with the corner at the origin, edge `i`
//! leaves the corner along `dᵢ = (cos θᵢ, sin θᵢ)` with normal `nᵢ = (−sin θᵢ, cos θᵢ)`, where
//! `θ₁,₂ = rotation ∓ edge_angle / 2`. Its signed function is
//!
//! `fᵢ(p) = nᵢ·p − κᵢ |p|² / 2`,
//!
//! whose zero set is the circle of radius `1/|κᵢ|` tangent to `dᵢ` at the corner, centred at
//! `nᵢ/κᵢ` (the line `nᵢ·p = 0` when `κᵢ = 0`); `|∇fᵢ| = 1` on the edge, so `fᵢ` is a signed distance
//! near it. A point is bright (`intensity`) where `f₁ f₂ < 0` and dark (0) elsewhere: a checker
//! X-junction whose bright sectors are the one between `d₁` and `d₂` (spanning `edge_angle`) and its
//! opposite. The two circles meet again at `m/|m|²`, `m = [n₁; n₂]⁻¹ (κ₁, κ₂) / 2` — with
//! `|κ| ≤ 3·10⁻³` that is hundreds of pixels away, near the image corners at the most.
//!
//! **Camera.** A pinhole camera `K = [[f, 0, c], [0, f, c], [0, 0, 1]]`, `c = (size − 1)/2` (the image
//! centre), looks along +z (x right, y down). The plane is rotated by `tilt` about the in-plane axis
//! `(cos tilt_axis, sin tilt_axis, 0)` through the corner, and the corner sits at
//! `X₀ = ((t − c), f)` in pixel-scaled camera units, `t = c + offset` the truth. So the homography
//! plane → image is `H = K [R e₁ | R e₂ | X₀]`: it maps the corner exactly to `t`, one plane unit
//! is one pixel along the tilt axis at the corner (and `cos tilt` across it), and for `tilt = 0` it
//! is the translation `p ↦ p + t`.
//!
//! **Rendering.** Each pixel is the area average of the pattern over its square, pulled back
//! through `H⁻¹`: pixels whose four corners and centre agree take the centre's value, the others
//! (and a 5×5 block at each junction) average `s × s` sub-samples, one at a jittered position in
//! each cell of an `s × s` grid. The jitter is a fixed hash of pixel and cell, so rendering is
//! deterministic, but it makes the area estimate unbiased: a regular grid quantizes the position of
//! an edge nearly parallel to its rows or columns to multiples of `1/s` — a systematic edge shift up
//! to `1/2s` px (0.03 px at `s = 16`) along the whole edge — where jitter leaves a zero-mean error of
//! at most `0.5/s^1.5` of the contrast per edge pixel, which averages out along the edge. An edge on
//! a cell boundary (e.g. a quarter-pixel offset with `s` a multiple of 4) is still sampled exactly.
//! The blur comes before the pixels, as in a camera: the pattern is area-sampled on cells of
//! `1/m` px (`m` from `blur_cells`: the blur spans two cells), blurred there, and each
//! pixel averages its `m × m` cells (`blur_then_integrate`). Then white Gaussian noise
//! from a seeded ChaCha8 generator.

use super::{add_gaussian_noise, blur_cells, blur_then_integrate, SynthError};
use crate::GrayImage;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;

/// Focal length (pixels) of the default camera: a mid-range industrial lens on the paper's
/// 1920×1200 sensor. The perspective effect of a tilt grows as the focal length shrinks.
pub const DEFAULT_FOCAL_LENGTH: f64 = 1200.0;

/// One synthetic corner: the planar pattern, its pose and the imaging degradations.
///
/// Angles are radians, lengths pixels, intensities on a full scale of 1.0. See the module docs for
/// the exact model. [`Default`] is the paper's 640×640 image with a sharp, noise-free, straight
/// 90° corner facing the camera, exactly at the image centre.
#[derive(Clone, Debug, PartialEq)]
pub struct CornerScene {
    /// Width and height of the square image (pixels).
    pub size: usize,
    /// Focal length of the pinhole camera (pixels, > 0).
    pub focal_length: f64,
    /// Signed curvature `κ` of each edge in the plane (px⁻¹); positive bends towards the edge's
    /// normal `nᵢ`; 0 is a straight edge.
    pub curvature: [f64; 2],
    /// Angle between the two edges at the corner, in `(0, π)`; the bright sector spans it.
    pub edge_angle: f64,
    /// In-plane rotation of the pattern: direction of the bisector of the two edges, from +x
    /// towards +y.
    pub rotation: f64,
    /// Out-of-plane rotation `φ` of the plane, in `(−π/2, π/2)`.
    pub tilt: f64,
    /// Direction of the tilt axis in the plane, from +x towards +y.
    pub tilt_axis: f64,
    /// Bright level `In` (the dark level is 0).
    pub intensity: f64,
    /// Standard deviation of the Gaussian blur applied in the image (pixels, ≥ 0; 0 = none).
    pub blur: f64,
    /// Standard deviation `σn` of the additive Gaussian noise, as a fraction of full scale 1.0.
    pub noise: f64,
    /// Position of the corner relative to the image centre `(size − 1)/2` (pixels).
    pub offset: [f64; 2],
    /// Sub-samples per pixel side on pixels an edge crosses (1..=64); jittered, see the module
    /// docs.
    pub supersample: usize,
}

impl Default for CornerScene {
    fn default() -> Self {
        Self {
            size: 640,
            focal_length: DEFAULT_FOCAL_LENGTH,
            curvature: [0.0, 0.0],
            edge_angle: PI / 2.0,
            rotation: 0.0,
            tilt: 0.0,
            tilt_axis: 0.0,
            intensity: 1.0,
            blur: 0.0,
            noise: 0.0,
            offset: [0.0, 0.0],
            supersample: 24,
        }
    }
}

/// A rendered corner and its exact truth.
#[derive(Clone, Debug)]
pub struct RenderedCorner {
    /// The observed image: blurred, with noise, not clamped (values around `[0, intensity]`).
    pub image: GrayImage,
    /// The same image without noise.
    pub clean: GrayImage,
    /// The corner's image position (pixel centres at integers), exact to rounding (< 10⁻⁹ px).
    pub truth: [f64; 2],
    /// The pattern and camera, to locate the edges in the image.
    pub geometry: CornerGeometry,
}

/// The geometry of a scene: the planar pattern and the homography to the image.
#[derive(Clone, Debug, PartialEq)]
pub struct CornerGeometry {
    h: [[f64; 3]; 3],
    h_inv: [[f64; 3]; 3],
    tangents: [[f64; 2]; 2],
    normals: [[f64; 2]; 2],
    curvature: [f64; 2],
    truth: [f64; 2],
    intensity: f64,
}

fn mul3(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|r| m[r][0] * v[0] + m[r][1] * v[1] + m[r][2] * v[2])
}

fn invert3(m: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let c = |r: usize, s: usize| {
        let (r1, r2) = ((r + 1) % 3, (r + 2) % 3);
        let (s1, s2) = ((s + 1) % 3, (s + 2) % 3);
        m[r1][s1] * m[r2][s2] - m[r1][s2] * m[r2][s1]
    };
    let det = m[0][0] * c(0, 0) + m[0][1] * c(0, 1) + m[0][2] * c(0, 2);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    // Inverse = adjugate / det; the adjugate is the transposed cofactor matrix.
    Some([0, 1, 2].map(|r| [0, 1, 2].map(|s| c(s, r) / det)))
}

impl CornerGeometry {
    /// The corner's image position.
    pub fn truth(&self) -> [f64; 2] {
        self.truth
    }

    /// The homography from plane coordinates `(u, v, 1)` to homogeneous image coordinates.
    pub fn homography(&self) -> [[f64; 3]; 3] {
        self.h
    }

    /// Image position of plane point `p`, or `None` if it is behind the camera.
    pub fn plane_to_image(&self, p: [f64; 2]) -> Option<[f64; 2]> {
        let q = mul3(&self.h, [p[0], p[1], 1.0]);
        (q[2] > 0.0).then(|| [q[0] / q[2], q[1] / q[2]])
    }

    /// Plane point seen at image position `x`, or `None` beyond the plane's horizon.
    pub fn image_to_plane(&self, x: [f64; 2]) -> Option<[f64; 2]> {
        let q = mul3(&self.h_inv, [x[0], x[1], 1.0]);
        (q[2] > 0.0).then(|| [q[0] / q[2], q[1] / q[2]])
    }

    /// Signed function `fᵢ(p) = nᵢ·p − κᵢ|p|²/2` of edge `edge` (0 or 1) at plane point `p`: zero on
    /// the edge, about the signed distance (plane units) near it.
    pub fn edge_function(&self, edge: usize, p: [f64; 2]) -> f64 {
        let n = self.normals[edge & 1];
        n[0] * p[0] + n[1] * p[1] - 0.5 * self.curvature[edge & 1] * (p[0] * p[0] + p[1] * p[1])
    }

    /// Image position of the point of edge `edge` (0 or 1) at signed arc length `arc` (plane units)
    /// from the corner, or `None` if it is behind the camera. `arc > 0` follows `dᵢ`.
    pub fn edge_point(&self, edge: usize, arc: f64) -> Option<[f64; 2]> {
        let (d, n, k) = (
            self.tangents[edge & 1],
            self.normals[edge & 1],
            self.curvature[edge & 1],
        );
        // p(s) = d sin(κs)/κ + n (1 − cos κs)/κ, written to stay exact as κ → 0.
        let x = k * arc;
        let (along, across) = if x.abs() < 1e-6 {
            (arc * (1.0 - x * x / 6.0), 0.5 * x * arc)
        } else {
            (x.sin() / k, 2.0 * (0.5 * x).sin().powi(2) / k)
        };
        self.plane_to_image([d[0] * along + n[0] * across, d[1] * along + n[1] * across])
    }

    /// Unit tangents of the two edges at the corner, in the image, pointing along `+dᵢ`.
    pub fn edge_tangents(&self) -> [[f64; 2]; 2] {
        // Derivative of x = (H p̃)₀,₁ / (H p̃)₂ at p = 0 applied to dᵢ.
        let h = &self.h;
        let t = self.truth;
        self.tangents.map(|d| {
            let g = [0, 1]
                .map(|r| (h[r][0] - t[r] * h[2][0]) * d[0] + (h[r][1] - t[r] * h[2][1]) * d[1]);
            let len = g[0].hypot(g[1]);
            [g[0] / len, g[1] / len]
        })
    }

    /// Whether the pattern is bright at image position `(x, y)`; beyond the horizon counts as dark.
    #[inline]
    pub fn is_bright(&self, x: f64, y: f64) -> bool {
        let m = &self.h_inv;
        let w = m[2][0] * x + m[2][1] * y + m[2][2];
        if w <= 0.0 {
            return false;
        }
        let u = (m[0][0] * x + m[0][1] * y + m[0][2]) / w;
        let v = (m[1][0] * x + m[1][1] * y + m[1][2]) / w;
        let r = 0.5 * (u * u + v * v);
        let [n1, n2] = self.normals;
        let f1 = n1[0] * u + n1[1] * v - self.curvature[0] * r;
        let f2 = n2[0] * u + n2[1] * v - self.curvature[1] * r;
        f1 * f2 < 0.0
    }

    /// Plane points where the two edges meet: the corner and, for curved edges, the second
    /// crossing of the circles `m/|m|²`, `m = [n₁; n₂]⁻¹ (κ₁, κ₂) / 2`.
    fn junctions(&self) -> [Option<[f64; 2]>; 2] {
        let [n1, n2] = self.normals;
        let det = n1[0] * n2[1] - n1[1] * n2[0];
        let (k1, k2) = (0.5 * self.curvature[0], 0.5 * self.curvature[1]);
        let m = [
            (n2[1] * k1 - n1[1] * k2) / det,
            (n1[0] * k2 - n2[0] * k1) / det,
        ];
        let m2 = m[0] * m[0] + m[1] * m[1];
        let second = (m2 > 0.0 && m2.is_finite()).then(|| [m[0] / m2, m[1] / m2]);
        [Some([0.0, 0.0]), second]
    }
}

pub(super) fn check(
    name: &'static str,
    value: f64,
    ok: bool,
    reason: &'static str,
) -> Result<(), SynthError> {
    if ok && value.is_finite() {
        Ok(())
    } else {
        Err(SynthError::InvalidParameter {
            name,
            value,
            reason,
        })
    }
}

impl CornerScene {
    /// Checks every parameter against its documented range.
    pub fn validate(&self) -> Result<(), SynthError> {
        let size = self.size as f64;
        check("size", size, (1..=16_384).contains(&self.size), "1..=16384")?;
        let ss = self.supersample as f64;
        check(
            "supersample",
            ss,
            (1..=64).contains(&self.supersample),
            "1..=64",
        )?;
        check(
            "focal_length",
            self.focal_length,
            self.focal_length > 0.0,
            "> 0",
        )?;
        for k in self.curvature {
            check("curvature", k, true, "finite")?;
        }
        let a = self.edge_angle;
        check("edge_angle", a, a > 0.0 && a < PI, "in (0, π)")?;
        check("rotation", self.rotation, true, "finite")?;
        let t = self.tilt;
        check("tilt", t, t.abs() < 0.5 * PI, "in (−π/2, π/2)")?;
        check("tilt_axis", self.tilt_axis, true, "finite")?;
        check("intensity", self.intensity, true, "finite")?;
        check("blur", self.blur, self.blur >= 0.0, ">= 0")?;
        check("noise", self.noise, self.noise >= 0.0, ">= 0")?;
        for o in self.offset {
            check("offset", o, true, "finite")?;
        }
        Ok(())
    }

    /// The corner's image position `(size − 1)/2 + offset`.
    pub fn truth(&self) -> [f64; 2] {
        let c = (self.size as f64 - 1.0) / 2.0;
        [c + self.offset[0], c + self.offset[1]]
    }

    /// The pattern and the plane → image homography (see the module docs).
    pub fn geometry(&self) -> Result<CornerGeometry, SynthError> {
        self.validate()?;
        let f = self.focal_length;
        let c = (self.size as f64 - 1.0) / 2.0;
        let truth = self.truth();
        // Rodrigues rotation by `tilt` about a = (cos ψ, sin ψ, 0); only its first two columns are
        // needed: R e_j = e_j cos φ + (a × e_j) sin φ + a (a·e_j)(1 − cos φ).
        let (sp, cp) = self.tilt.sin_cos();
        let (sa, ca) = self.tilt_axis.sin_cos();
        let a = [ca, sa, 0.0];
        let col = |j: usize| {
            let e = [(j == 0) as u8 as f64, (j == 1) as u8 as f64, 0.0];
            let cross = [
                a[1] * e[2] - a[2] * e[1],
                a[2] * e[0] - a[0] * e[2],
                a[0] * e[1] - a[1] * e[0],
            ];
            [0, 1, 2].map(|r| e[r] * cp + cross[r] * sp + a[r] * a[j] * (1.0 - cp))
        };
        let (r1, r2) = (col(0), col(1));
        let x0 = [truth[0] - c, truth[1] - c, f];
        // H = K [r1 r2 X₀], K = [[f, 0, c], [0, f, c], [0, 0, 1]].
        let k = |v: [f64; 3]| [f * v[0] + c * v[2], f * v[1] + c * v[2], v[2]];
        let (h1, h2, h3) = (k(r1), k(r2), k(x0));
        let h = [0, 1, 2].map(|r| [h1[r], h2[r], h3[r]]);
        let h_inv = invert3(&h).ok_or(SynthError::InvalidParameter {
            name: "tilt",
            value: self.tilt,
            reason: "the plane is seen edge-on",
        })?;
        let theta = [
            self.rotation - 0.5 * self.edge_angle,
            self.rotation + 0.5 * self.edge_angle,
        ];
        let tangents = theta.map(|t| [t.cos(), t.sin()]);
        let normals = tangents.map(|d| [-d[1], d[0]]);
        Ok(CornerGeometry {
            h,
            h_inv,
            tangents,
            normals,
            curvature: self.curvature,
            truth,
            intensity: self.intensity,
        })
    }

    /// The area-sampled pattern before blur and noise.
    pub fn render_sharp(&self) -> Result<GrayImage, SynthError> {
        let g = self.geometry()?;
        Ok(area_sample(&g, self.size, self.supersample, 1))
    }

    /// Renders the scene: area sampling, blur [`blur`](Self::blur), then noise
    /// [`noise`](Self::noise) drawn from `ChaCha8Rng::seed_from_u64(seed)`, so a `(scene, seed)` pair
    /// gives the same noise on every machine (and the same image up to the last bit of the
    /// platform's `sin`/`cos`, which only matters for sub-samples lying exactly on an edge).
    pub fn render(&self, seed: u64) -> Result<RenderedCorner, SynthError> {
        let geometry = self.geometry()?;
        let m = blur_cells(self.blur);
        let cells = area_sample(&geometry, self.size, self.supersample, m);
        let clean = blur_then_integrate(&cells, m, self.blur);
        let mut image = clean.clone();
        add_gaussian_noise(&mut image, self.noise, &mut ChaCha8Rng::seed_from_u64(seed));
        Ok(RenderedCorner {
            image,
            clean,
            truth: geometry.truth,
            geometry,
        })
    }
}

/// Two uniform numbers in `[0, 1)` (24 bits each) from SplitMix64 of `key`: a fixed,
/// platform-independent jitter for sub-sample `key`.
#[inline]
pub(super) fn jitter(key: u64) -> (f64, f64) {
    let mut z = key.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    let unit = 1.0 / (1u64 << 24) as f64;
    (
        (z >> 40) as f64 * unit,
        ((z >> 16) & 0xFF_FFFF) as f64 * unit,
    )
}

/// Area averages of the pattern over cells of `1/m` px, `m·size` per side (`m = 1`: the pixels;
/// see the module docs for when sub-sampling is used).
fn area_sample(g: &CornerGeometry, size: usize, s: usize, m: usize) -> GrayImage {
    // Cells of 1/m px (see `blur_then_integrate`), each with about s/m sub-samples per side.
    let (cells, s, unit) = (size * m, s.div_ceil(m), 1.0 / m as f64);
    let at = |i: usize| (i as f64 + 0.5) * unit - 0.5;
    // Colours of the (cells+1)² cell corners, shared by neighbouring cells.
    let side = cells + 1;
    let mut corners = vec![false; side * side];
    for j in 0..side {
        for i in 0..side {
            corners[j * side + i] = g.is_bright(i as f64 * unit - 0.5, j as f64 * unit - 0.5);
        }
    }
    // Where both edges meet, a narrow sector can slip between the five probes of a pixel.
    let forced: Vec<[f64; 2]> = g
        .junctions()
        .iter()
        .flatten()
        .filter_map(|&p| g.plane_to_image(p))
        .collect();
    let step = unit / s as f64;
    let bright = g.intensity as f32;
    let scale = bright / (s * s) as f32;
    let mut data = vec![0.0f32; cells * cells];
    for y in 0..cells {
        for x in 0..cells {
            let (xf, yf) = (at(x), at(y));
            let centre = g.is_bright(xf, yf);
            let uniform = corners[y * side + x] == centre
                && corners[y * side + x + 1] == centre
                && corners[(y + 1) * side + x] == centre
                && corners[(y + 1) * side + x + 1] == centre;
            let near_junction = forced
                .iter()
                .any(|p| (p[0] - xf).abs() <= 2.0 && (p[1] - yf).abs() <= 2.0);
            data[y * cells + x] = if uniform && !near_junction {
                if centre {
                    bright
                } else {
                    0.0
                }
            } else {
                let mut count = 0u32;
                let key = ((y * cells + x) * s * s) as u64;
                for b in 0..s {
                    for a in 0..s {
                        let (jx, jy) = jitter(key + (b * s + a) as u64);
                        let sx = xf - 0.5 * unit + (a as f64 + jx) * step;
                        let sy = yf - 0.5 * unit + (b as f64 + jy) * step;
                        count += g.is_bright(sx, sy) as u32;
                    }
                }
                count as f32 * scale
            };
        }
    }
    GrayImage::from_vec(cells, cells, data).expect("size validated")
}

/// The paper's four synthetic tests (section IV-A): one factor swept, the others drawn at random.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Protocol {
    /// Noise test: `σn` swept, blur 3 px.
    Noise,
    /// Blur test: blur `σ` swept, `σn` = 3 %.
    Blur,
    /// Perspective test: out-of-plane rotation `φ` swept (degrees), `σn` = 3 %, blur 3 px.
    Perspective,
    /// Curvature test: `|κ|` of both edges swept, `σn` = 3 %, blur 3 px.
    Curvature,
}

impl Protocol {
    /// The four tests in the paper's order.
    pub const ALL: [Protocol; 4] = [
        Protocol::Noise,
        Protocol::Blur,
        Protocol::Perspective,
        Protocol::Curvature,
    ];

    /// Short lower-case name (`noise`, `blur`, `perspective`, `curvature`).
    pub fn name(self) -> &'static str {
        match self {
            Protocol::Noise => "noise",
            Protocol::Blur => "blur",
            Protocol::Perspective => "perspective",
            Protocol::Curvature => "curvature",
        }
    }

    /// Unit of the swept value: fraction of full scale, pixels, degrees, or px⁻¹.
    pub fn unit(self) -> &'static str {
        match self {
            Protocol::Noise => "fraction of full scale",
            Protocol::Blur => "px",
            Protocol::Perspective => "deg",
            Protocol::Curvature => "1/px",
        }
    }

    /// The swept values, covering the paper's ranges: `σn` 0–15 %, blur 1–5 px, `φ` 0–60°
    /// (degrees), `κ` 5·10⁻⁴–3·10⁻³ px⁻¹.
    pub fn sweep_values(self) -> Vec<f64> {
        match self {
            Protocol::Noise => vec![0.0, 0.01, 0.03, 0.05, 0.075, 0.10, 0.125, 0.15],
            Protocol::Blur => vec![1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 4.5, 5.0],
            Protocol::Perspective => vec![0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0],
            Protocol::Curvature => vec![5e-4, 1e-3, 1.5e-3, 2e-3, 2.5e-3, 3e-3],
        }
    }
}

/// A random 640×640 scene of `protocol` with its swept factor set to `value` (in the unit of
/// [`Protocol::unit`]; degrees for the perspective test), the others drawn as in the paper:
///
/// | factor | noise | blur | perspective | curvature |
/// |---|---|---|---|---|
/// | `σn` | value | 0.03 | 0.03 | 0.03 |
/// | blur (px) | 3 | value | 3 | 3 |
/// | `φ` | U(0°, 15°) | U(0°, 15°) | value | U(0°, 15°) |
/// | `|κᵢ|` (px⁻¹) | U(1, 1.5)·10⁻³ | U(1, 1.5)·10⁻³ | U(1, 1.5)·10⁻³ | value |
///
/// and in all tests `In ~ U(0.5, 1)`, a random sign for each `κᵢ`, rotation `~ U(0, 2π)`, tilt axis
/// `~ U(0, π)`, offset `~ U(−0.5, 0.5)²`. The paper does not give the angle between the edges; it is
/// drawn `~ U(60°, 120°)`. Every factor is drawn, in a fixed order, whatever the protocol, so the same
/// generator state gives the same scene for every swept value (common random numbers).
pub fn scene_for<R: Rng + ?Sized>(protocol: Protocol, value: f64, rng: &mut R) -> CornerScene {
    let rotation = rng.gen_range(0.0..2.0 * PI);
    let tilt_axis = rng.gen_range(0.0..PI);
    let offset = [rng.gen_range(-0.5..0.5), rng.gen_range(-0.5..0.5)];
    let edge_angle = rng.gen_range(60f64..120.0).to_radians();
    let intensity = rng.gen_range(0.5..1.0);
    let signs = [rng.gen_bool(0.5), rng.gen_bool(0.5)].map(|neg| if neg { -1.0 } else { 1.0 });
    let magnitudes: [f64; 2] = [rng.gen_range(1e-3..1.5e-3), rng.gen_range(1e-3..1.5e-3)];
    let tilt = rng.gen_range(0f64..15.0).to_radians();
    let mut scene = CornerScene {
        curvature: [signs[0] * magnitudes[0], signs[1] * magnitudes[1]],
        edge_angle,
        rotation,
        tilt,
        tilt_axis,
        intensity,
        blur: 3.0,
        noise: 0.03,
        offset,
        ..CornerScene::default()
    };
    match protocol {
        Protocol::Noise => scene.noise = value,
        Protocol::Blur => scene.blur = value,
        Protocol::Perspective => scene.tilt = value.to_radians(),
        Protocol::Curvature => scene.curvature = [signs[0] * value, signs[1] * value],
    }
    scene
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::cramer_rao_bound;
    use proptest::prelude::*;

    /// Exact bright area of pixel `(i, j)` for the axis-aligned corner at `t` whose bright
    /// quadrants are lower-right (x > tx, y > ty, between d₁ = +x and d₂ = +y) and upper-left.
    fn axis_corner_area(i: usize, j: usize, t: [f64; 2]) -> f64 {
        let overlap = |lo: f64, hi: f64, a: f64, b: f64| (hi.min(b) - lo.max(a)).max(0.0);
        let (x0, y0) = (i as f64 - 0.5, j as f64 - 0.5);
        let left = overlap(x0, x0 + 1.0, f64::NEG_INFINITY, t[0]);
        let right = 1.0 - left;
        let below = overlap(y0, y0 + 1.0, t[1], f64::INFINITY);
        let above = 1.0 - below;
        right * below + left * above
    }

    fn axis_scene(offset: [f64; 2], supersample: usize) -> CornerScene {
        // Bisector at 45° with a 90° edge angle: edges along +x (θ₁ = 0) and +y (θ₂ = π/2).
        CornerScene {
            size: 32,
            rotation: PI / 4.0,
            intensity: 0.8,
            offset,
            supersample,
            ..CornerScene::default()
        }
    }

    #[test]
    fn straight_axis_aligned_corner_has_exact_pixel_areas() {
        // Quarter-pixel offsets fall between the sub-samples of s = 16: exact areas.
        for offset in [[0.0, 0.0], [0.5, 0.25], [-0.25, 0.5], [0.5, 0.5]] {
            let scene = axis_scene(offset, 16);
            let img = scene.render_sharp().unwrap();
            let t = scene.truth();
            for j in 0..32 {
                for i in 0..32 {
                    let want = 0.8 * axis_corner_area(i, j, t);
                    let got = img.get(i, j) as f64;
                    assert!(
                        (got - want).abs() < 1e-6,
                        "{offset:?} ({i},{j}) {got} {want}"
                    );
                }
            }
        }
        // Pixel cut in half by the vertical edge, and the four-quadrant pixel at the truth.
        let img = axis_scene([0.5, 0.5], 16).render_sharp().unwrap();
        assert!((img.get(16, 5) - 0.4).abs() < 1e-6);
        assert!((img.get(16, 16) - 0.4).abs() < 1e-6);
        assert!((img.get(3, 3) - 0.8).abs() < 1e-6 && img.get(3, 28) == 0.0);
        assert!((img.get(28, 28) - 0.8).abs() < 1e-6 && img.get(28, 3) == 0.0);
        // Generic offsets: the sub-sampling error is at most 1/s of the contrast per edge.
        let scene = axis_scene([0.3, -0.17], 16);
        let (img, t) = (scene.render_sharp().unwrap(), scene.truth());
        for j in 0..32 {
            for i in 0..32 {
                let want = 0.8 * axis_corner_area(i, j, t);
                assert!((img.get(i, j) as f64 - want).abs() <= 0.8 * 2.0 / 16.0 + 1e-6);
            }
        }
        // … and unbiased along an edge: a regular 16×16 grid would put the vertical edge at 0.3125
        // of pixel column 16 (error 0.0125 on every pixel); jitter averages to the exact 0.3.
        let rows: Vec<usize> = (0..32).filter(|&j| (j as f64 - t[1]).abs() > 2.0).collect();
        let mean_err = rows
            .iter()
            .map(|&j| img.get(16, j) as f64 - 0.8 * axis_corner_area(16, j, t))
            .sum::<f64>()
            / (0.8 * rows.len() as f64);
        assert!(mean_err.abs() < 0.004, "{mean_err}");
    }

    #[test]
    fn blurred_axis_corner_is_the_pixel_integral_of_the_blurred_pattern() {
        // The axis-aligned corner blurred by a Gaussian is separable, `0.8 (Fx Fy + (1−Fx)(1−Fy))`
        // with `F = Φ((u − t)/σ)`, and so is its integral over a pixel: exact values to compare a
        // camera's pixels with (blur, then integrate). A sampled Gaussian on cells of 1/m px misses
        // a 1-D step by at most 0.35 % of its height at any phase (`m σ ≥ 2`; 0.5 % here, where
        // two edges meet); blurring the pixels' areas instead (m = 1) missed a step by up to 6 %
        // at σ = 0.6 px, 2.8 % at 0.8 and 1.4 % at 1.2. Half-pixel offsets keep the sub-samples
        // exact for every cell size.
        use crate::junction::erf;
        use std::f64::consts::SQRT_2;
        // ∫ Φ(u/σ) du over [a, b], from ∫ Φ(z) dz = z Φ(z) + φ(z).
        let integral = |a: f64, b: f64, s: f64| {
            let prim = |u: f64| {
                let z = u / s;
                s * (z * 0.5 * (1.0 + erf(z / SQRT_2)) + (-0.5 * z * z).exp() / (2.0 * PI).sqrt())
            };
            prim(b) - prim(a)
        };
        for sigma in [0.6, 0.8, 1.2, 2.5] {
            for offset in [[0.0, 0.0], [0.5, 0.5], [-0.5, 0.0]] {
                let scene = CornerScene {
                    blur: sigma,
                    noise: 0.0,
                    ..axis_scene(offset, 16)
                };
                let t = scene.truth();
                let img = scene.render(0).unwrap().image;
                let mut worst = 0.0f64;
                for j in 8..24 {
                    for i in 8..24 {
                        let fx = integral(i as f64 - 0.5 - t[0], i as f64 + 0.5 - t[0], sigma);
                        let fy = integral(j as f64 - 0.5 - t[1], j as f64 + 0.5 - t[1], sigma);
                        let want = 0.8 * (fx * fy + (1.0 - fx) * (1.0 - fy));
                        worst = worst.max((img.get(i, j) as f64 - want).abs());
                    }
                }
                assert!(worst < 0.006 * 0.8, "σ {sigma} offset {offset:?}: {worst}");
            }
        }
    }

    #[test]
    fn homography_is_a_translation_without_tilt() {
        let scene = CornerScene {
            offset: [0.3, -0.2],
            ..CornerScene::default()
        };
        let g = scene.geometry().unwrap();
        let x = g.plane_to_image([12.0, -7.0]).unwrap();
        assert!((x[0] - (319.5 + 0.3 + 12.0)).abs() < 1e-9);
        assert!((x[1] - (319.5 - 0.2 - 7.0)).abs() < 1e-9);
        // Edge tangents keep the edge angle.
        let [t1, t2] = g.edge_tangents();
        let angle = (t1[0] * t2[0] + t1[1] * t2[1]).acos();
        assert!((angle - PI / 2.0).abs() < 1e-12);
    }

    fn tilted_scene(seed: u64) -> CornerScene {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        CornerScene {
            blur: 0.0,
            noise: 0.0,
            tilt: 50f64.to_radians(),
            curvature: [2.5e-3, -3e-3],
            ..scene_for(Protocol::Perspective, 50.0, &mut rng)
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        #[test]
        fn truth_maps_back_to_the_planar_corner(seed in 0u64..1_000_000, proto in 0usize..4) {
            let p = Protocol::ALL[proto];
            let values = p.sweep_values();
            let value = values[seed as usize % values.len()];
            let scene = scene_for(p, value, &mut ChaCha8Rng::seed_from_u64(seed));
            let g = scene.geometry().unwrap();
            let t = scene.truth();
            let back = g.image_to_plane(t).unwrap();
            prop_assert!(back[0].abs() < 1e-9 && back[1].abs() < 1e-9, "{back:?}");
            let fwd = g.plane_to_image([0.0, 0.0]).unwrap();
            prop_assert!((fwd[0] - t[0]).abs() < 1e-9 && (fwd[1] - t[1]).abs() < 1e-9);
            for e in 0..2 {
                let p0 = g.edge_point(e, 0.0).unwrap();
                prop_assert!((p0[0] - t[0]).abs() < 1e-9 && (p0[1] - t[1]).abs() < 1e-9);
                // Edge points satisfy the edge equation.
                let q = g.image_to_plane(g.edge_point(e, 137.0).unwrap()).unwrap();
                prop_assert!(g.edge_function(e, q).abs() < 1e-9);
            }
            // Truth is where the scene says it is.
            prop_assert!((t[0] - 319.5).abs() <= 0.5 && (t[1] - 319.5).abs() <= 0.5);
        }
    }

    #[test]
    fn rendered_edges_of_a_tilted_curved_scene_pass_through_the_truth() {
        for seed in 0..3 {
            let scene = tilted_scene(seed);
            let img = scene.render_sharp().unwrap();
            let g = scene.geometry().unwrap();
            let inten = scene.intensity as f32;
            let mut checked = 0;
            // Pixels whose centre lies on an edge (|f| < 0.01 plane units, ≤ 0.02 px at 50° tilt)
            // and away from the other edge are half bright, within curvature and sampling error.
            for y in 0..scene.size {
                for x in 0..scene.size {
                    let Some(q) = g.image_to_plane([x as f64, y as f64]) else {
                        continue;
                    };
                    let (f0, f1) = (g.edge_function(0, q), g.edge_function(1, q));
                    if (f0.abs() < 0.01 && f1.abs() > 4.0) || (f1.abs() < 0.01 && f0.abs() > 4.0) {
                        let v = img.get(x, y);
                        assert!((v - 0.5 * inten).abs() < 0.06 * inten, "({x},{y}) {v}");
                        checked += 1;
                    }
                }
            }
            assert!(checked > 20, "only {checked} on-edge pixels");
            // Around the truth, the four sectors alternate: probe along the sector bisectors.
            let t = g.truth();
            let [t1, t2] = g.edge_tangents();
            let mut colours = Vec::new();
            for (a, b) in [(1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0)] {
                let d = [a * t1[0] + b * t2[0], a * t1[1] + b * t2[1]];
                let n = d[0].hypot(d[1]);
                let p = [t[0] + 6.0 * d[0] / n, t[1] + 6.0 * d[1] / n];
                let v = img.get(p[0].round() as usize, p[1].round() as usize);
                assert!(v == 0.0 || v == inten, "{v}");
                colours.push(v > 0.0);
            }
            assert!(colours[0] != colours[1] && colours[1] != colours[2]);
            assert!(colours[2] != colours[3] && colours[0] == colours[2]);
            // The sector between +d₁ and +d₂ is the bright one, whatever the tilt.
            assert!(colours[0]);
        }
    }

    #[test]
    fn second_junction_of_the_circles_lies_on_both_edges() {
        let scene = CornerScene {
            curvature: [0.02, -0.015],
            edge_angle: 1.2,
            rotation: 0.4,
            ..CornerScene::default()
        };
        let g = scene.geometry().unwrap();
        let [first, second] = g.junctions();
        assert_eq!(first, Some([0.0, 0.0]));
        let p = second.unwrap();
        assert!(p[0].hypot(p[1]) > 1.0);
        assert!(g.edge_function(0, p).abs() < 1e-9 && g.edge_function(1, p).abs() < 1e-9);
        let straight = CornerScene::default().geometry().unwrap();
        assert_eq!(straight.junctions()[1], None);
        // Near the second junction the pixels are still exact areas in [0, In].
        let img = scene.render_sharp().unwrap();
        let (lo, hi) = img.min_max();
        assert!(lo >= 0.0 && hi <= 1.0);
    }

    #[test]
    fn blur_preserves_mean_and_symmetry_of_a_centred_corner() {
        // Corner on a pixel corner at the exact centre: the pattern is invariant under a half turn
        // and turns into its complement under a mirror, and the blurred image must be too.
        let scene = CornerScene {
            size: 64,
            rotation: PI / 4.0,
            blur: 2.5,
            ..CornerScene::default()
        };
        let sharp = scene.render_sharp().unwrap();
        let r = scene.render(1).unwrap();
        let n = scene.size;
        let mean = |img: &GrayImage| img.data().iter().map(|&v| v as f64).sum::<f64>();
        assert!((mean(&sharp) - mean(&r.clean)).abs() / (n * n) as f64 <= 1e-6);
        for y in 0..n {
            for x in 0..n {
                let v = r.clean.get(x, y);
                assert!((v - r.clean.get(n - 1 - x, n - 1 - y)).abs() < 1e-5);
                assert!((v + r.clean.get(n - 1 - x, y) - 1.0).abs() < 1e-5);
            }
        }
        // Blur softens: the pixels next to the corner are no longer pure.
        assert!(r.clean.get(31, 31) > 0.3 && r.clean.get(31, 31) < 0.7);
        assert_eq!(r.clean, r.image, "noise 0 adds nothing");
    }

    #[test]
    fn same_seed_same_image_other_seed_other_noise() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let scene = CornerScene {
            size: 96,
            ..scene_for(Protocol::Noise, 0.05, &mut rng)
        };
        let a = scene.render(7).unwrap();
        let b = scene.render(7).unwrap();
        let c = scene.render(8).unwrap();
        assert_eq!(a.image, b.image);
        assert_eq!(a.clean, c.clean);
        assert_ne!(a.image, c.image);
        // The noise has the requested spread.
        let diffs: Vec<f64> = a
            .image
            .data()
            .iter()
            .zip(a.clean.data())
            .map(|(&u, &v)| (u - v) as f64)
            .collect();
        let rms = (diffs.iter().map(|d| d * d).sum::<f64>() / diffs.len() as f64).sqrt();
        assert!((rms - 0.05).abs() < 0.002, "{rms}");
    }

    #[test]
    fn steep_tilt_shows_a_dark_sky_beyond_the_horizon() {
        let scene = CornerScene {
            size: 200,
            focal_length: 100.0,
            tilt: 80f64.to_radians(),
            tilt_axis: 0.0,
            ..CornerScene::default()
        };
        let img = scene.render_sharp().unwrap();
        let g = scene.geometry().unwrap();
        let sky = (0..200)
            .flat_map(|y| (0..200).map(move |x| (x, y)))
            .filter(|&(x, y)| g.image_to_plane([x as f64, y as f64]).is_none())
            .collect::<Vec<_>>();
        assert!(!sky.is_empty());
        assert!(sky.iter().all(|&(x, y)| img.get(x, y) == 0.0));
    }

    #[test]
    fn bad_parameters_are_rejected() {
        let ok = CornerScene::default();
        let bad = [
            CornerScene {
                size: 0,
                ..ok.clone()
            },
            CornerScene {
                supersample: 0,
                ..ok.clone()
            },
            CornerScene {
                supersample: 65,
                ..ok.clone()
            },
            CornerScene {
                focal_length: 0.0,
                ..ok.clone()
            },
            CornerScene {
                curvature: [f64::NAN, 0.0],
                ..ok.clone()
            },
            CornerScene {
                edge_angle: 0.0,
                ..ok.clone()
            },
            CornerScene {
                edge_angle: PI,
                ..ok.clone()
            },
            CornerScene {
                tilt: PI / 2.0,
                ..ok.clone()
            },
            CornerScene {
                rotation: f64::INFINITY,
                ..ok.clone()
            },
            CornerScene {
                blur: -1.0,
                ..ok.clone()
            },
            CornerScene {
                noise: f64::NAN,
                ..ok.clone()
            },
            CornerScene {
                intensity: f64::NAN,
                ..ok.clone()
            },
            CornerScene {
                offset: [0.0, f64::INFINITY],
                ..ok.clone()
            },
        ];
        for scene in bad {
            assert!(matches!(
                scene.render(0),
                Err(SynthError::InvalidParameter { .. })
            ));
        }
        assert!(ok.validate().is_ok());
    }

    #[test]
    fn protocols_draw_the_papers_factors() {
        for p in Protocol::ALL {
            let values = p.sweep_values();
            assert!(values.windows(2).all(|w| w[0] < w[1]));
            for (i, &value) in values.iter().enumerate() {
                for seed in 0..50u64 {
                    let s = scene_for(
                        p,
                        value,
                        &mut ChaCha8Rng::seed_from_u64(seed * 31 + i as u64),
                    );
                    assert!(s.validate().is_ok());
                    let deg = s.tilt.to_degrees();
                    let k = s.curvature.map(f64::abs);
                    assert!((0.5..1.0).contains(&s.intensity));
                    assert!((60.0..120.0).contains(&s.edge_angle.to_degrees()));
                    assert!(s.offset.iter().all(|o| (-0.5..0.5).contains(o)));
                    assert!((0.0..2.0 * PI).contains(&s.rotation));
                    assert!((0.0..PI).contains(&s.tilt_axis));
                    let in_k = |k: f64| (1e-3..1.5e-3).contains(&k);
                    match p {
                        Protocol::Noise => {
                            assert_eq!((s.noise, s.blur), (value, 3.0));
                            assert!(deg < 15.0 && k.iter().all(|&k| in_k(k)));
                        }
                        Protocol::Blur => {
                            assert_eq!((s.noise, s.blur), (0.03, value));
                            assert!(deg < 15.0 && k.iter().all(|&k| in_k(k)));
                        }
                        Protocol::Perspective => {
                            assert_eq!((s.noise, s.blur), (0.03, 3.0));
                            assert!((deg - value).abs() < 1e-9 && k.iter().all(|&k| in_k(k)));
                        }
                        Protocol::Curvature => {
                            assert_eq!((s.noise, s.blur), (0.03, 3.0));
                            assert!(deg < 15.0 && k == [value, value]);
                        }
                    }
                }
            }
        }
        // Both curvature signs occur.
        let signs: Vec<bool> = (0..40)
            .map(|s| scene_for(Protocol::Curvature, 1e-3, &mut ChaCha8Rng::seed_from_u64(s)))
            .map(|s| s.curvature[0] > 0.0)
            .collect();
        assert!(signs.contains(&true) && signs.contains(&false));
        // Common random numbers: one generator state, only the swept factor changes.
        let a = scene_for(Protocol::Noise, 0.01, &mut ChaCha8Rng::seed_from_u64(5));
        let b = scene_for(Protocol::Noise, 0.15, &mut ChaCha8Rng::seed_from_u64(5));
        assert_eq!(CornerScene { noise: 0.15, ..a }, b);
    }

    #[test]
    fn crb_of_protocol_scenes_scales_with_noise() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let scene = scene_for(Protocol::Blur, 3.0, &mut rng);
        let r = scene.render(0).unwrap();
        let b1 = cramer_rao_bound(&r.clean, r.truth, 7, 0.03).unwrap();
        let b2 = cramer_rao_bound(&r.clean, r.truth, 7, 0.06).unwrap();
        assert!((b2 / b1 - 2.0).abs() < 1e-9);
        // A blurred step of contrast In ≥ 0.5 seen at 3 % noise over 15×15 pixels: a few
        // hundredths of a pixel.
        assert!(b1 > 0.003 && b1 < 0.1, "{b1}");
    }

    /// Render time of one protocol image; run with `--ignored --nocapture` in an optimized profile.
    #[test]
    #[ignore]
    fn render_timing() {
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let scenes: Vec<CornerScene> = (0..20)
            .map(|_| scene_for(Protocol::Noise, 0.05, &mut rng))
            .collect();
        for ss in [8, 16, 24, 32] {
            let start = std::time::Instant::now();
            for (i, s) in scenes.iter().enumerate() {
                let s = CornerScene {
                    supersample: ss,
                    ..s.clone()
                };
                std::hint::black_box(s.render(i as u64).unwrap());
            }
            let ms = start.elapsed().as_secs_f64() * 1e3 / scenes.len() as f64;
            println!("supersample {ss}: {ms:.1} ms per 640×640 image (blur 3, noise)");
        }
    }
}
