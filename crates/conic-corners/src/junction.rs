//! Corner position by a blurred X-junction model fitted to the pixels around it: the refiner for
//! corners whose edges are too short or too crowded for edge sampling (near the silhouette of a
//! strongly bent board, where the squares are sheared into wedges a few pixels wide and every
//! sigmoid window reaches the next edge).
//!
//! **Model.** Two edges cross at `q`. Edge `i` has unit tangent `tᵢ = (cos θᵢ, sin θᵢ)`, unit
//! normal `nᵢ = (−sin θᵢ, cos θᵢ)` and curvature `κᵢ`; the signed distance of a point `x` from it
//! is, to second order,
//!
//! ```text
//! dᵢ(x) = nᵢ·(x − q) − κᵢ/2 · (tᵢ·(x − q))²
//! ```
//!
//! The sharp pattern is `sign(d₁) · sign(d₂)`. Blurred by an isotropic Gaussian of standard
//! deviation `w` (the optics' blur and the pixel's footprint, `w² = σ² + 1/12`), the wedge
//! `{d₁ > 0, d₂ > 0}` becomes the bivariate normal probability `Φ₂(d₁/w, d₂/w; ρ)` with
//! `ρ = n₁·n₂` (the two distances of a Gaussian displacement are correlated by the angle between
//! the normals), and the pattern becomes
//!
//! ```text
//! S(h, k; ρ) = erf(h/√2) · erf(k/√2) + (2/π) ∫₀^{asin ρ} exp(−(h² + k² − 2hk sin φ) / (2 cos² φ)) dφ
//! ```
//!
//! with `h = d₁/w`, `k = d₂/w` (the product of two erf profiles when the edges are orthogonal).
//! Two refinements make it fit real prints and bent boards:
//! - *Curvature under blur.* A curved edge's blurred mid-level moves by `κw²/2` towards its
//!   centre of curvature (the Gaussian's mean of `κu²/2` along the edge), so `dᵢ` gets
//!   `− κᵢw²/2`.
//! - *Print offset.* A print's dot gain erodes one colour's squares by `δ`; eroding a wedge by
//!   a disc is intersecting its two sides moved inwards, so the `+1` side becomes
//!   `Φ₂(h − e, k − e; ρ) + Φ₂(−h − e, −k − e; ρ)` with `e = δ/w` (and `δ < 0` erodes the `−1`
//!   side). The corner stays at the centre between the two wedges' tips, which is where the
//!   board-wide fit puts it too.
//!
//! The pixels are `I(x) = c₀ + gₓ (x − x₀) + g_y (y − y₀) + a S`: two levels (through `c₀`, `a`)
//! and a linear shading. All twelve parameters (`q`, `θ₁`, `θ₂`, `κ₁`, `κ₂`, `w`, `δ` and the four
//! linear ones) are fitted by Levenberg–Marquardt with analytic derivatives
//! (`∂Φ₂/∂h = φ(h) Φ((k − ρh)/√(1 − ρ²))`, `∂Φ₂/∂ρ = φ₂(h, k; ρ)`), the integral by
//! Gauss–Legendre quadrature of 4 to 12 points by the angle between the edges (exact to 3·10⁻⁸
//! for edges at least 12° apart, `GL_RULES`). A fit is refused
//! when the contrast is below ten times the residuals' RMS (no junction in the window).
//!
//! **Window.** The pixels within `radius` of the start, which the caller bounds by the distance
//! to the next junctions: beyond them the pattern is no longer one X. At most `max_radius`
//! (6 px); [`refine_junction_at_boundary`] also tries up to `wide_radius` (10 px) and keeps
//! that answer where the two agree.
//!
//! **Uncertainty.** The covariance of `q` from the Gauss–Newton normal matrix scaled by the
//! residual variance, in the worst direction, times 3: with the curvatures free the
//! position scatters about three times as widely under noise as the linearized covariance says.
//! A biased model (the window reaching another edge) is not in it.
//!
//! Coordinates: x right, y down, the centre of the top-left pixel is `(0, 0)`.

use crate::quadratic_form::worst_sigma;
use crate::GrayImage;
use nalgebra::{SMatrix, SVector};

/// Parameters of [`refine_junction`]. `Default` is what [`crate::detect`] uses.
#[derive(Clone, Debug, PartialEq)]
pub struct JunctionParams {
    /// Largest radius (px) of the disc of pixels fitted; the caller's radius is capped by it.
    pub max_radius: f64,
    /// Largest radius (px) of the second, wider fit of [`refine_junction_at_boundary`], which
    /// replaces the first where they agree (at most `max_radius`: no second fit).
    pub wide_radius: f64,
    /// Smallest radius (px): below it there are too few pixels for eleven parameters.
    pub min_radius: f64,
    /// Largest number of Levenberg–Marquardt iterations.
    pub max_iterations: usize,
    /// Largest accepted distance (px) between the start and the answer.
    pub max_shift: f64,
    /// Smallest accepted angle (degrees) between the two edges.
    pub min_angle_deg: f64,
    /// Radius in units of the image's blur σ that [`JunctionParams::for_blur`] grows
    /// `max_radius` to (and `wide_radius` in proportion) where the blur is known: a disc of 6 px
    /// holds too little of edges blurred by 2 px to pin their angles and curvatures, and the
    /// answer then drifts with the disc (on a photo with σ ≈ 2.2 px, 0.75 px between radii of 6
    /// and 14 px, each fit claiming σ 0.09–0.15 px).
    pub radius_per_blur: f64,
}

impl Default for JunctionParams {
    fn default() -> Self {
        Self {
            max_radius: 6.0,
            wide_radius: 10.0,
            min_radius: 3.0,
            max_iterations: 30,
            max_shift: 1.5,
            min_angle_deg: 12.0,
            radius_per_blur: 4.0,
        }
    }
}

impl JunctionParams {
    /// These parameters for an image blurred by a Gaussian of σ = `blur` px: `max_radius` at
    /// least `radius_per_blur · blur` and `wide_radius` grown by the same factor, both at most
    /// 32 px. Unchanged for a blur that is not finite and positive, or small enough (with the
    /// defaults, σ ≤ 1.5 px).
    pub fn for_blur(&self, blur: f64) -> JunctionParams {
        let scale = self.radius_per_blur * blur / self.max_radius;
        if !(scale.is_finite() && scale > 1.0) {
            return self.clone();
        }
        JunctionParams {
            max_radius: (self.max_radius * scale).min(32.0),
            wide_radius: (self.wide_radius * scale).min(32.0),
            ..self.clone()
        }
    }

    /// Checks the parameters; the message names the offending one.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.min_radius.is_finite()
            && self.min_radius >= 2.0
            && self.max_radius.is_finite()
            && self.max_radius >= self.min_radius
            && self.max_radius <= 32.0)
        {
            return Err(format!(
                "the junction radii must satisfy 2 ≤ min ≤ max ≤ 32 px, got {} and {}",
                self.min_radius, self.max_radius
            ));
        }
        if !(self.wide_radius.is_finite() && self.wide_radius <= 32.0) {
            return Err(format!(
                "the junction's wide radius must be finite and ≤ 32 px, got {}",
                self.wide_radius
            ));
        }
        if !(1..=1000).contains(&self.max_iterations) {
            return Err(format!(
                "the junction iteration limit must be in 1..=1000, got {}",
                self.max_iterations
            ));
        }
        if !(self.max_shift.is_finite() && self.max_shift >= 0.0) {
            return Err(format!(
                "the junction maximum shift must be a finite number ≥ 0, got {}",
                self.max_shift
            ));
        }
        if !(self.min_angle_deg.is_finite() && (1.0..=80.0).contains(&self.min_angle_deg)) {
            return Err(format!(
                "the junction minimum angle must be in 1..=80 degrees, got {}",
                self.min_angle_deg
            ));
        }
        if !(self.radius_per_blur.is_finite() && (0.0..=16.0).contains(&self.radius_per_blur)) {
            return Err(format!(
                "the junction radius per blur must be in 0..=16, got {}",
                self.radius_per_blur
            ));
        }
        Ok(())
    }
}

/// A corner placed by [`refine_junction`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JunctionCorner {
    /// Position (image coordinates).
    pub point: [f64; 2],
    /// Standard deviation (px) of the position in the worst direction (module docs).
    pub sigma: f64,
    /// Covariance (px², image axes) of the position, scaled like `sigma` (its larger
    /// eigenvalue is `sigma²`).
    pub cov: [[f64; 2]; 2],
    /// Tangent angles (radians) of the two edges at the corner.
    pub angles: [f64; 2],
    /// Curvatures (1/px) of the two edges at the corner, signed as in the module docs.
    pub curvatures: [f64; 2],
    /// Fitted blur `w` (px): the Gaussian σ of the optics and the pixel footprint together.
    pub blur: f64,
    /// Fitted erosion `δ` (px) of the wedges on the pattern's `+1` side (negative: they are
    /// dilated): half the offset a print's dot gain puts between the two polarities of an edge.
    pub offset: f64,
    /// Contrast `2|a|` between the two levels (intensity units).
    pub contrast: f64,
    /// RMS of the pixel residuals (intensity units).
    pub rms: f64,
}

/// Number of fitted parameters: `q` (2), `θ` (2), `κ` (2), `w`, `δ`, the sliver's offset
/// (nonlinear, [`NL`]; the offset held at 0 without a sliver), then `c₀`, `gₓ`, `g_y`, `a`.
const NP: usize = 13;
/// Number of nonlinear parameters.
const NL: usize = 9;

/// Index of the sliver's offset among the parameters.
const SLIVER_OFFSET: usize = 8;
type Normal = SMatrix<f64, NP, NP>;
type Vector = SVector<f64, NP>;

/// Factor on the position's Gauss–Newton standard deviation for what noise alone does not
/// explain: the model's error (one curvature per edge, an idealized blur) on real, curved
/// edges. Under noise alone the Gauss–Newton σ is right: over 200 noisy renders each of four
/// junctions (blur 0.8–2 px, noise 1–3 % of full scale, straight and curved edges) the scatter
/// per axis was 0.94–1.02 times it. Against 1 (and 1.5), 1.25 gave the better robustness report
/// (geometric mean 0.0197 px against 0.0201 and 0.0197; baseline cylinder 0.0112 against 0.0143
/// and 0.0123 px) and the better curved-board report (top curvature bin 0.0154 against 0.0156
/// and 0.0168 px): with a factor of 1, junction answers outweighed better board answers on the
/// curved boards. [`JunctionCorner::sigma`] includes it.
const SIGMA_SCALE: f64 = 1.25;

/// Smallest contrast between the two levels, in units of the residuals' RMS: below it the
/// window holds no junction.
const MIN_CONTRAST_TO_NOISE: f64 = 10.0;

/// Most pixels a window may hold (radius 32).
const MAX_PIXELS: usize = 65 * 65;

/// Refines the X-junction near `start` (image coordinates) whose edges run at about `angles`
/// (radians, from +x towards +y) by fitting the blurred junction model of the module docs to the
/// pixels within `radius` (capped to `params`' range) of `start`, from a blur guess `blur` (px,
/// the optics' σ).
///
/// Returns `None` when the parameters are invalid, the window leaves the image, the fit does not
/// converge, the edges come closer than `min_angle_deg`, the blur leaves `[0.3, 6]` px, or the
/// answer lies farther than `max_shift` from `start` or outside the window.
pub fn refine_junction(
    image: &GrayImage,
    start: [f64; 2],
    angles: [f64; 2],
    radius: f64,
    blur: f64,
    params: &JunctionParams,
) -> Option<JunctionCorner> {
    fit_junction(
        image,
        Guess::straight(start, angles, blur)?,
        radius,
        None,
        params,
    )
}

/// A third, straight edge parallel to one of the junction's: the far side of a sliver, a square
/// foreshortened to a few pixels at a silhouette. Beyond it the pattern flips.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sliver {
    /// The junction edge it is parallel to: 0 or 1, in the order of the `angles`.
    pub edge: usize,
    /// Its signed distance (px) from that edge along the edge's normal `(−sin θ, cos θ)`, at
    /// least 0.5 px in magnitude.
    pub offset: f64,
}

/// [`refine_junction`] with a sliver's far edge in the model (see [`Sliver`]): its offset is
/// fitted too, from `sliver.offset`, and kept on that side of the edge, at least 0.5 px from
/// it. Returns `None` also for an edge index other than 0 or 1 or a start offset that is below
/// 0.5 px in magnitude or not finite.
pub fn refine_junction_beside(
    image: &GrayImage,
    start: [f64; 2],
    angles: [f64; 2],
    radius: f64,
    blur: f64,
    sliver: Sliver,
    params: &JunctionParams,
) -> Option<JunctionCorner> {
    if sliver.edge > 1 || !(sliver.offset.is_finite() && sliver.offset.abs() >= 0.5) {
        return None;
    }
    let guess = Guess::straight(start, angles, blur)?;
    fit_junction(image, guess, radius, Some(sliver), params)
}

/// Where a sliver's far edge is first sought, in px beyond the junction's edge: the slivers at
/// a bent board's silhouette are a few pixels wide (the offset is then fitted).
const SLIVER_START: f64 = 3.0;

/// How far (px) the caller's radius must exceed `max_radius` for the wide fit of
/// [`refine_junction_at_boundary`] to be tried.
const WIDEN_MIN_PX: f64 = 0.5;

/// [`refine_junction`] for a corner on a board's boundary, where the squares beyond may be
/// slivers: also [`refine_junction_beside`] with a sliver beyond each edge of `beyond` (an edge
/// index and a vector pointing out of the board across it), started 3 px out; the answer with
/// the smallest σ. An empty `beyond` makes it [`refine_junction`] with the wide fit below. The
/// sliver attempts get the plain fit's `max_iterations`: capped at 12, those that settle later
/// were lost, among them junctions at the photos' silhouettes (`curve_5.jpg` (2, 0) and (3, 0),
/// found from Pillow's decoding of the JPEG but not from ours); in full they cost 2.6 % more
/// instructions on `curve_6.jpg` in either refine mode.
///
/// Where `radius` exceeds `max_radius`, the plain model is fitted again within `radius` capped
/// at `wide_radius`, from the first answer (all its parameters: position, angles, curvatures,
/// blur and print offset), and that answer is kept if it agrees with the first. The wider window has more pixels, but the model (two edges of constant curvature)
/// may not hold over it: an edge's curvature changes near a silhouette, a sliver's far edge or
/// the next junction comes in (where the sliver model won, the plain one then fails or
/// disagrees). The two fits share the first one's pixels, so where the model holds their
/// positions differ by about `√(σ₁² − σ₂²)` (nested estimates); the wide answer is kept if they
/// differ by at most three times that (at least `σ₁/4`). On the curved-board benchmark (32²
/// sub-samples) the top curvature bin went from 0.0176 to 0.0162 px. The wide fit cost 16 ms
/// on `curve_6.jpg` (one thread, with the C library's `exp` and 12 quadrature nodes); at 16 px
/// it gave the same bin (0.0163 px) for 26 ms more.
pub fn refine_junction_at_boundary(
    image: &GrayImage,
    start: [f64; 2],
    angles: [f64; 2],
    radius: f64,
    blur: f64,
    beyond: &[(usize, [f64; 2])],
    params: &JunctionParams,
) -> Option<JunctionCorner> {
    let first = best_at_boundary(image, start, angles, radius, blur, beyond, params)?;
    if !(radius > params.max_radius + WIDEN_MIN_PX && params.wide_radius > params.max_radius) {
        return Some(first);
    }
    let wide_params = JunctionParams {
        max_radius: params.wide_radius,
        ..params.clone()
    };
    let Some(wide) = fit_junction(
        image,
        Guess::from_answer(&first),
        radius,
        None,
        &wide_params,
    ) else {
        return Some(first);
    };
    let d2 = (wide.point[0] - first.point[0]).powi(2) + (wide.point[1] - first.point[1]).powi(2);
    let spread2 = (first.sigma.powi(2) - wide.sigma.powi(2)).max((0.25 * first.sigma).powi(2));
    Some(if d2 <= 9.0 * spread2 { wide } else { first })
}

/// The plain and sliver fits of [`refine_junction_at_boundary`] within one radius: the one
/// with the smallest σ.
fn best_at_boundary(
    image: &GrayImage,
    start: [f64; 2],
    angles: [f64; 2],
    radius: f64,
    blur: f64,
    beyond: &[(usize, [f64; 2])],
    params: &JunctionParams,
) -> Option<JunctionCorner> {
    let slivers = beyond
        .iter()
        .filter(|&&(edge, _)| edge < 2)
        .map(|&(edge, out)| {
            let normal = [-angles[edge].sin(), angles[edge].cos()];
            let sign = (normal[0] * out[0] + normal[1] * out[1]).signum();
            let sliver = Sliver {
                edge,
                offset: sign * SLIVER_START,
            };
            refine_junction_beside(image, start, angles, radius, blur, sliver, params)
        });
    std::iter::once(refine_junction(image, start, angles, radius, blur, params))
        .chain(slivers)
        .flatten()
        .min_by(|a, b| a.sigma.total_cmp(&b.sigma))
}

/// The first values of a fit's nonlinear parameters (image coordinates, radians, px).
#[derive(Clone, Copy, Debug)]
struct Guess {
    point: [f64; 2],
    angles: [f64; 2],
    curvatures: [f64; 2],
    /// The model's `w`: the optics' blur and the pixel's footprint.
    w: f64,
    /// The print offset `δ`.
    offset: f64,
}

impl Guess {
    /// Straight edges and no print offset, from the optics' blur σ = `blur` px; `None` for a
    /// blur that is negative or not finite.
    fn straight(point: [f64; 2], angles: [f64; 2], blur: f64) -> Option<Self> {
        (blur.is_finite() && blur >= 0.0).then(|| Self {
            point,
            angles,
            curvatures: [0.0; 2],
            w: (blur * blur + 1.0 / 12.0).sqrt().max(0.5),
            offset: 0.0,
        })
    }

    /// Every nonlinear parameter of an earlier answer: where a fit over a wider window starts.
    fn from_answer(j: &JunctionCorner) -> Self {
        Self {
            point: j.point,
            angles: j.angles,
            curvatures: j.curvatures,
            w: j.blur,
            offset: j.offset,
        }
    }
}

fn fit_junction(
    image: &GrayImage,
    guess: Guess,
    radius: f64,
    sliver: Option<Sliver>,
    params: &JunctionParams,
) -> Option<JunctionCorner> {
    let Guess {
        point: start,
        angles,
        ..
    } = guess;
    let values = [
        guess.curvatures[0],
        guess.curvatures[1],
        guess.w,
        guess.offset,
    ];
    if params.validate().is_err()
        || !start
            .iter()
            .chain(&angles)
            .chain(&values)
            .all(|v| v.is_finite())
        || guess.w <= 0.0
    {
        return None;
    }
    let r = if radius.is_finite() {
        radius.clamp(params.min_radius, params.max_radius)
    } else {
        params.max_radius
    };
    let min_sin = params.min_angle_deg.to_radians().sin();
    if angle_sin(angles[0], angles[1]).abs() < min_sin {
        return None;
    }
    let mut pixels = Window::load(image, start, r)?;
    pixels.sliver = sliver;
    let mut p = Vector::zeros();
    p[0] = start[0];
    p[1] = start[1];
    p[2] = angles[0];
    p[3] = angles[1];
    p[4] = guess.curvatures[0];
    p[5] = guess.curvatures[1];
    p[6] = guess.w;
    p[7] = guess.offset;
    p[8] = sliver.map_or(0.0, |s| s.offset);
    pixels.levels(&mut p)?;
    // The normal equations are formed at each trial point with its cost: a step is accepted
    // far more often than not, and then they serve the next iteration (and the covariance).
    let (mut jtj, mut jtr, mut cost) = pixels.normal_equations(&p)?;
    let mut lambda = 1e-3;
    let mut converged = false;
    // An answer farther than `shift_limit` from the start is refused below. A fit that has
    // wandered twice as far, and half the window's radius, does not come back, and would run
    // to `max_iterations`: such fits took about a fifth of the model's iterations on `curve_6`.
    // (Under a 4 px blur, in windows of 16 px, some came back from 3 px and were kept.)
    let shift_limit = params.max_shift.min(r);
    let abandon = (2.0 * shift_limit).max(0.5 * r);
    for _ in 0..params.max_iterations {
        let mut improved = false;
        while lambda < 1e10 {
            let mut a = jtj;
            for i in 0..NP {
                a[(i, i)] += lambda * jtj[(i, i)].max(1e-12);
            }
            let Some(step) = a.cholesky().map(|c| c.solve(&jtr)) else {
                lambda *= 10.0;
                continue;
            };
            let next = p + step;
            // The decrease the normal equations' linear model predicts, 2 sᵀJᵀr − sᵀJᵀJ s, by
            // (JᵀJ + λD) s = Jᵀr. A step that would end the fit by the test below (a move below
            // 10⁻³ px and a relative decrease below 10⁻⁴) is taken without evaluating it: that
            // saves the last of the 5–8 evaluations a converged fit takes on the photos, and
            // where it lands differs from the last evaluated point by less than the tolerance.
            let predicted = || {
                let damping: f64 = (0..NP)
                    .map(|i| lambda * jtj[(i, i)].max(1e-12) * step[i] * step[i])
                    .sum();
                step.dot(&jtr) + damping
            };
            if step[0].hypot(step[1]) < 1e-3 && predicted() < 1e-4 * cost {
                p = next;
                improved = true;
                converged = true;
                break;
            }
            match pixels.normal_equations(&next) {
                Some((j, r, c)) if c <= cost => {
                    if (next[0] - start[0]).hypot(next[1] - start[1]) > abandon {
                        return None;
                    }
                    let moved = step[0].hypot(step[1]);
                    p = next;
                    (jtj, jtr) = (j, r);
                    let relative = (cost - c) / cost.max(1e-300);
                    cost = c;
                    lambda = (lambda * 0.3).max(1e-9);
                    improved = true;
                    converged = moved < 1e-3 && relative < 1e-4;
                    break;
                }
                _ => lambda *= 10.0,
            }
        }
        if !improved {
            // No step lowers the cost: a minimum to the cost's rounding.
            converged = true;
        }
        if converged {
            break;
        }
    }
    if !converged {
        return None;
    }
    let q = [p[0], p[1]];
    let w = p[6];
    if (q[0] - start[0]).hypot(q[1] - start[1]) > shift_limit
        || !(0.3..=6.0).contains(&w)
        || angle_sin(p[2], p[3]).abs() < min_sin
    {
        return None;
    }
    let fitted = if sliver.is_some() { NP } else { NP - 1 };
    let dof = pixels.len().checked_sub(fitted).filter(|&d| d > 0)? as f64;
    let variance = cost / dof;
    // The normal equations hold their lower triangle only (all that Cholesky reads).
    let mut full = jtj;
    full.fill_upper_triangle_with_lower_triangle();
    let inverse = full.try_inverse()?;
    let scale = SIGMA_SCALE * SIGMA_SCALE * variance;
    let (sxx, sxy, syy) = (inverse[(0, 0)], inverse[(0, 1)], inverse[(1, 1)]);
    let cov = [[scale * sxx, scale * sxy], [scale * sxy, scale * syy]];
    let sigma = worst_sigma(cov);
    let rms = (cost / pixels.len() as f64).sqrt();
    let contrast = 2.0 * p[NL + 3].abs();
    // A flat patch fits any geometry with a contrast near zero (and residuals near zero).
    if !(sigma.is_finite()
        && contrast > MIN_CONTRAST_TO_NOISE * rms
        && contrast > 1e-3 * p[NL].abs())
    {
        return None;
    }
    Some(JunctionCorner {
        point: q,
        sigma,
        cov,
        angles: [p[2], p[3]],
        curvatures: [p[4], p[5]],
        blur: w,
        offset: p[7],
        contrast,
        rms,
    })
}

/// `sin(θ₁ − θ₂)`: zero for parallel edges.
fn angle_sin(a: f64, b: f64) -> f64 {
    (a - b).sin()
}

/// The pixels of a disc: offsets from its centre (the start) and values, padded to a multiple
/// of [`PX`] with weight-0 copies of the centre.
struct Window {
    sliver: Option<Sliver>,
    centre: [f64; 2],
    dx: Vec<f64>,
    dy: Vec<f64>,
    value: Vec<f64>,
    /// 1 for the disc's pixels, 0 for the padding.
    weight: Vec<f64>,
    /// Pixels of the disc.
    len: usize,
}

impl Window {
    /// The pixels whose centres lie within `r` of `c`; `None` if the disc leaves the image.
    fn load(image: &GrayImage, c: [f64; 2], r: f64) -> Option<Self> {
        let (w, h) = (image.width() as f64, image.height() as f64);
        let (x0, x1) = ((c[0] - r).ceil(), (c[0] + r).floor());
        let (y0, y1) = ((c[1] - r).ceil(), (c[1] + r).floor());
        if x0 < 0.0 || y0 < 0.0 || x1 > w - 1.0 || y1 > h - 1.0 {
            return None;
        }
        let n = (((x1 - x0 + 1.0) * (y1 - y0 + 1.0)) as usize).min(MAX_PIXELS) + PX;
        let mut win = Self {
            sliver: None,
            centre: c,
            dx: Vec::with_capacity(n),
            dy: Vec::with_capacity(n),
            value: Vec::with_capacity(n),
            weight: Vec::with_capacity(n),
            len: 0,
        };
        let mut y = y0;
        while y <= y1 {
            let row = image.row(y as usize);
            let mut x = x0;
            while x <= x1 {
                let (ex, ey) = (x - c[0], y - c[1]);
                if ex * ex + ey * ey <= r * r {
                    win.dx.push(ex);
                    win.dy.push(ey);
                    win.value.push(row[x as usize] as f64);
                }
                x += 1.0;
            }
            y += 1.0;
        }
        win.len = win.value.len();
        win.weight.resize(win.len, 1.0);
        let padded = win.len.div_ceil(PX) * PX;
        for v in [&mut win.dx, &mut win.dy, &mut win.value, &mut win.weight] {
            v.resize(padded, 0.0);
        }
        (win.len() > 2 * NP).then_some(win)
    }

    fn len(&self) -> usize {
        self.len
    }

    /// The step of [`PX`] pixels from `i`: offsets from the window's centre, values, weights.
    #[inline(always)]
    fn step(&self, i: usize) -> [&Px; 4] {
        fn lanes(v: &[f64], i: usize) -> &Px {
            v[i..i + PX].try_into().expect("padded to whole steps")
        }
        [
            lanes(&self.dx, i),
            lanes(&self.dy, i),
            lanes(&self.value, i),
            lanes(&self.weight, i),
        ]
    }

    /// The offsets from the junction `q = (p₀, p₁)` of the pixels `dx`, `dy`.
    #[inline(always)]
    fn offsets(&self, p: &Vector, dx: &Px, dy: &Px) -> (Px, Px) {
        (
            px(|l| self.centre[0] + dx[l] - p[0]),
            px(|l| self.centre[1] + dy[l] - p[1]),
        )
    }

    /// Sets the linear parameters `c₀, gₓ, g_y, a` (the last four entries) to their least-squares values
    /// for the geometry in `p`; `None` if the pattern does not vary over the window.
    fn levels(&self, p: &mut Vector) -> Option<()> {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
            // SAFETY: AVX2 and FMA support were just checked at run time.
            return unsafe { self.levels_avx2(p) };
        }
        self.levels_generic(p)
    }

    /// [`Window::levels_generic`] compiled for AVX2 + FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn levels_avx2(&self, p: &mut Vector) -> Option<()> {
        self.levels_generic(p)
    }

    /// [`Window::levels`], [`PX`] pixels per step.
    #[inline(always)]
    fn levels_generic(&self, p: &mut Vector) -> Option<()> {
        let g = Geometry::new(p, self.sliver)?;
        let mut ata = SMatrix::<f64, 4, 4>::zeros();
        let mut atb = SVector::<f64, 4>::zeros();
        for i in (0..self.dx.len()).step_by(PX) {
            let [dx, dy, value, weight] = self.step(i);
            let (ex, ey) = self.offsets(p, dx, dy);
            let s = g.value(&ex, &ey);
            for l in 0..PX {
                let row = SVector::<f64, 4>::new(1.0, dx[l], dy[l], s[l]) * weight[l];
                ata += row * row.transpose();
                atb += row * value[l];
            }
        }
        let sol = ata.cholesky()?.solve(&atb);
        p.fixed_rows_mut::<4>(NL).copy_from(&sol);
        Some(())
    }

    /// `JᵀJ` (its lower triangle), `Jᵀr` and `rᵀr` of the residuals `r = I − model` at `p`;
    /// `None` if the geometry is degenerate or a sum is not finite.
    fn normal_equations(&self, p: &Vector) -> Option<(Normal, Vector, f64)> {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
            // SAFETY: AVX2 and FMA support were just checked at run time.
            return unsafe { self.normal_equations_avx2(p) };
        }
        self.normal_equations_generic(p)
    }

    /// [`Window::normal_equations_generic`] compiled for AVX2 + FMA: a step's four pixels are
    /// one register, where the baseline x86-64 build (SSE2) needs two.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn normal_equations_avx2(&self, p: &Vector) -> Option<(Normal, Vector, f64)> {
        self.normal_equations_generic(p)
    }

    /// [`Window::normal_equations`], [`PX`] pixels per step: the model and its derivatives are
    /// evaluated lane by lane, and each sum keeps one partial sum per lane.
    #[inline(always)]
    fn normal_equations_generic(&self, p: &Vector) -> Option<(Normal, Vector, f64)> {
        if self.sliver.is_some() {
            self.normal_equations_lanes::<true>(p)
        } else {
            self.normal_equations_lanes::<false>(p)
        }
    }

    /// [`Window::normal_equations_generic`] with or without a sliver: without one, the
    /// sliver's offset (parameter 8) has no derivative, and its row and column of `JᵀJ`, a
    /// seventh of the sums, are not summed.
    #[inline(always)]
    fn normal_equations_lanes<const SLIVER: bool>(
        &self,
        p: &Vector,
    ) -> Option<(Normal, Vector, f64)> {
        let g = Geometry::new(p, self.sliver)?;
        let (c0, gx, gy, a) = (p[NL], p[NL + 1], p[NL + 2], p[NL + 3]);
        let mut jtj_lanes = [[0.0; PX]; NP * (NP + 1) / 2];
        let mut jtr_lanes = [[0.0; PX]; NP];
        let mut cost_lanes = [0.0; PX];
        for i in (0..self.dx.len()).step_by(PX) {
            let [dx, dy, value, weight] = self.step(i);
            let (ex, ey) = self.offsets(p, dx, dy);
            let (s, ds) = g.pattern(&ex, &ey);
            // Rows of the Jacobian over all parameters, zero for the padding.
            let mut jac = [[0.0; PX]; NP];
            for (row, d) in jac.iter_mut().zip(&ds) {
                *row = px(|l| a * d[l] * weight[l]);
            }
            jac[NL] = *weight;
            jac[NL + 1] = px(|l| dx[l] * weight[l]);
            jac[NL + 2] = px(|l| dy[l] * weight[l]);
            jac[NL + 3] = px(|l| s[l] * weight[l]);
            let r = px(|l| (value[l] - (c0 + gx * dx[l] + gy * dy[l] + a * s[l])) * weight[l]);
            for l in 0..PX {
                cost_lanes[l] += r[l] * r[l];
            }
            for (sum, row) in jtr_lanes.iter_mut().zip(&jac) {
                for l in 0..PX {
                    sum[l] += r[l] * row[l];
                }
            }
            // `0..row + 1`, not `0..=row`: with an inclusive range the compiler keeps this
            // triangle's loop control (callgrind: 28 M of `curve_6`'s 1082 M instructions in board
            // mode; a flat table of the entries was slower still).
            let mut idx = 0;
            for row in 0..NP {
                for col in 0..row + 1 {
                    if SLIVER || (row != SLIVER_OFFSET && col != SLIVER_OFFSET) {
                        for l in 0..PX {
                            jtj_lanes[idx][l] += jac[row][l] * jac[col][l];
                        }
                    }
                    idx += 1;
                }
            }
        }
        let total = |lanes: &Px| lanes.iter().sum::<f64>();
        let mut jtj = Normal::zeros();
        let mut idx = 0;
        for row in 0..NP {
            for col in 0..=row {
                jtj[(row, col)] = total(&jtj_lanes[idx]);
                idx += 1;
            }
        }
        let jtr = Vector::from_fn(|k, _| total(&jtr_lanes[k]));
        let cost = total(&cost_lanes);
        if !SLIVER {
            // No sliver: its offset stays where it is.
            jtj[(SLIVER_OFFSET, SLIVER_OFFSET)] = 1.0;
        }
        (cost.is_finite() && jtj.iter().all(|v| v.is_finite()) && jtr.iter().all(|v| v.is_finite()))
            .then_some((jtj, jtr, cost))
    }
}

/// Gauss–Legendre rules on `[−1, 1]` (the positive half of the nodes, with their weights) for
/// the integral term of `S` over `[0, asin ρ]`, each with the largest `|asin ρ|` (degrees) it
/// serves: the integrand peaks as the edges become parallel, and over `h, k ∈ [−6, 6]` the
/// largest absolute error of each rule up to its limit is 2·10⁻⁹ (4 points up to 30°),
/// 1.4·10⁻⁹ (8 points, 60°) and 3·10⁻⁸ (12 points, 78°, edges 12° apart). Most corners need the
/// first: their edges meet at 60° or more.
const GL_RULES: [(f64, &[(f64, f64)]); 3] = [
    (
        30.0,
        &[
            (0.339_981_043_584_856_26, 0.652_145_154_862_546_4),
            (0.861_136_311_594_052_6, 0.347_854_845_137_453_57),
        ],
    ),
    (
        60.0,
        &[
            (0.183_434_642_495_649_78, 0.362_683_783_378_361_66),
            (0.525_532_409_916_329, 0.313_706_645_877_886_9),
            (0.796_666_477_413_626_7, 0.222_381_034_453_374_43),
            (0.960_289_856_497_536_2, 0.101_228_536_290_377_06),
        ],
    ),
    (
        90.0,
        &[
            (0.125_233_408_511_468_9, 0.249_147_045_813_402_7),
            (0.367_831_498_998_180_2, 0.233_492_536_538_354_6),
            (0.587_317_954_286_617_5, 0.203_167_426_723_065_73),
            (0.769_902_674_194_304_7, 0.160_078_328_543_346_42),
            (0.904_117_256_370_474_8, 0.106_939_325_995_319_07),
            (0.981_560_634_246_719_2, 0.047_175_336_386_511_41),
        ],
    ),
];

/// Most quadrature nodes of [`GL_RULES`].
const MAX_NODES: usize = 12;

/// The quantities of the geometry shared by all pixels.
struct Geometry {
    t: [[f64; 2]; 2],
    n: [[f64; 2]; 2],
    kappa: [f64; 2],
    /// Erosion `δ` of the wedges of the pattern's `+1` side (px; negative: dilation).
    delta: f64,
    w: f64,
    inv_w: f64,
    rho: f64,
    /// `√(1 − ρ²)`.
    root: f64,
    /// `dρ/dθ₁` (`dρ/dθ₂` is its negative).
    drho: f64,
    /// Quadrature of the integral term on `[0, asin ρ]`: `sin φ_j`, `1/(2 cos² φ_j)` and the
    /// weights over 2π; the first `node_count` are used.
    node_sin: [f64; MAX_NODES],
    node_inv2c2: [f64; MAX_NODES],
    node_weight: [f64; MAX_NODES],
    node_count: usize,
    /// A third edge beyond which the pattern flips, if modelled.
    sliver: Option<Sliver>,
}

impl Geometry {
    /// The geometry of `p`; `sliver` gives the sliver's edge and the side its offset (`p[8]`)
    /// must stay on, at least half a pixel from the edge. `None` for a degenerate geometry.
    fn new(p: &Vector, sliver: Option<Sliver>) -> Option<Self> {
        let (th1, th2, w) = (p[2], p[3], p[6]);
        if !(w.is_finite() && w > 1e-3) {
            return None;
        }
        let sliver = match sliver {
            Some(s) if p[8] * s.offset.signum() >= 0.5 => Some(Sliver {
                edge: s.edge,
                offset: p[8],
            }),
            Some(_) => return None,
            None => None,
        };
        let t = [[th1.cos(), th1.sin()], [th2.cos(), th2.sin()]];
        let n = [[-t[0][1], t[0][0]], [-t[1][1], t[1][0]]];
        let rho = (th1 - th2).cos();
        let root = (1.0 - rho * rho).sqrt();
        if root.is_nan() || root <= 1e-3 {
            return None;
        }
        let half = 0.5 * rho.asin();
        let mut node_sin = [0.0; MAX_NODES];
        let (mut node_inv2c2, mut node_weight) = (node_sin, node_sin);
        let span = rho.asin().abs().to_degrees();
        let rule = GL_RULES
            .iter()
            .find(|r| span <= r.0)
            .map_or(GL_RULES[GL_RULES.len() - 1].1, |r| r.1);
        for (j, &(x, wt)) in rule.iter().enumerate() {
            for (k, sign) in [(2 * j, -1.0), (2 * j + 1, 1.0)] {
                let phi = half * (1.0 + sign * x);
                let c = phi.cos();
                node_sin[k] = phi.sin();
                node_inv2c2[k] = 0.5 / (c * c);
                node_weight[k] = wt * half / (2.0 * PI);
            }
        }
        Some(Self {
            t,
            n,
            kappa: [p[4], p[5]],
            delta: p[7],
            w,
            inv_w: 1.0 / w,
            rho,
            root,
            drho: -(th1 - th2).sin(),
            node_sin,
            node_inv2c2,
            node_weight,
            node_count: 2 * rule.len(),
            sliver,
        })
    }

    /// `S` at the offsets `e = x − q` of [`PX`] pixels (`ex`, `ey`) and its derivatives over
    /// `(qₓ, q_y, θ₁, θ₂, κ₁, κ₂, w, δ, s)`, lane by lane: every step is a loop over the pixels,
    /// which the compiler turns into vector instructions.
    #[inline(always)]
    fn pattern(&self, ex: &Px, ey: &Px) -> (Px, [Px; NL]) {
        let iw = self.inv_w;
        let (u0, v0, h) = self.edge_coordinates(0, ex, ey);
        let (u1, v1, k) = self.edge_coordinates(1, ex, ey);
        // δ ≥ 0 erodes the wedges of the +1 side, {d₁ > δ, d₂ > δ} and {d₁ < −δ, d₂ < −δ};
        // δ < 0 those of the −1 side, which are the +1 side's of the pattern with d₂ and S
        // negated (`sg`).
        let sg = if self.delta >= 0.0 { 1.0 } else { -1.0 };
        let e = self.delta.abs() * iw;
        let a = self.wedge(&px(|l| h[l] - e), &px(|l| sg * k[l] - e), sg);
        let b = self.wedge(&px(|l| -h[l] - e), &px(|l| -sg * k[l] - e), sg);
        let mut s = px(|l| sg * (2.0 * (a.value[l] + b.value[l]) - 1.0));
        let mut ds_dh = px(|l| sg * 2.0 * (a.dh[l] - b.dh[l]));
        let mut ds_dk = px(|l| 2.0 * (a.dk[l] - b.dk[l]));
        // ∂S/∂δ; e = |δ|/w.
        let ds_ddelta = px(|l| -2.0 * (a.dh[l] + a.dk[l] + b.dh[l] + b.dk[l]) * iw);
        let mut ds_drho = px(|l| 2.0 * (a.drho[l] + b.drho[l]));
        // ∂S/∂w beyond the paths through h and k, and ∂S/∂s (the sliver's offset).
        let (mut ds_dw, mut ds_ds) = ([0.0; PX], [0.0; PX]);
        if let Some(sliver) = self.sliver {
            let t = self.sliver_term([&h, &k], sliver);
            let (dh_i, dk_j) = (t.dh, t.dk);
            let (along_h, along_k) = if sliver.edge == 0 {
                (&dh_i, &dk_j)
            } else {
                (&dk_j, &dh_i)
            };
            for l in 0..PX {
                s[l] += t.value[l];
                ds_dh[l] += along_h[l];
                ds_dk[l] += along_k[l];
                ds_drho[l] += t.drho[l];
                // u = ±(hᵢ − s/w): the offset's own dependence on w, and ∂S/∂s.
                ds_dw[l] = dh_i[l] * sliver.offset * iw * iw;
                ds_ds[l] = -dh_i[l] * iw;
            }
        }
        // d(dᵢ)/d(qₓ, q_y, θᵢ, κᵢ) times ∂S/∂hᵢ / w: the chain through each edge's distance.
        let (k0, k1) = (self.kappa[0], self.kappa[1]);
        let (t0, t1, n0, n1) = (self.t[0], self.t[1], self.n[0], self.n[1]);
        let ww = self.w * self.w;
        let out = [
            px(|l| {
                (ds_dh[l] * (-n0[0] + k0 * u0[l] * t0[0])
                    + ds_dk[l] * (-n1[0] + k1 * u1[l] * t1[0]))
                    * iw
            }),
            px(|l| {
                (ds_dh[l] * (-n0[1] + k0 * u0[l] * t0[1])
                    + ds_dk[l] * (-n1[1] + k1 * u1[l] * t1[1]))
                    * iw
            }),
            px(|l| ds_dh[l] * (-u0[l] - k0 * u0[l] * v0[l]) * iw + ds_drho[l] * self.drho),
            px(|l| ds_dk[l] * (-u1[l] - k1 * u1[l] * v1[l]) * iw - ds_drho[l] * self.drho),
            px(|l| ds_dh[l] * (-0.5 * (u0[l] * u0[l] + ww)) * iw),
            px(|l| ds_dk[l] * (-0.5 * (u1[l] * u1[l] + ww)) * iw),
            // h = D/w − κw/2 with D the distance: ∂h/∂w = −h/w − κ; ∂e/∂w = −e/w.
            px(|l| {
                -ds_dh[l] * (h[l] * iw + k0)
                    - ds_dk[l] * (k[l] * iw + k1)
                    - ds_ddelta[l] * self.delta * iw
                    + ds_dw[l]
            }),
            ds_ddelta,
            ds_ds,
        ];
        (s, out)
    }
}

/// A blurred wedge `Φ₂(h, k; ρ)` and its derivatives, for [`PX`] pixels.
struct Wedge {
    value: Px,
    dh: Px,
    dk: Px,
    drho: Px,
}

impl Geometry {
    /// `Φ₂(h, k; ρ) = Φ(h) Φ(k) + (1/2π) ∫₀^{asin ρ} exp(−(h² + k² − 2hk sin φ) / (2 cos² φ)) dφ`
    /// (the integral by the quadrature in `nodes`), with `∂/∂h = φ(h) Φ((k − ρh)/√(1 − ρ²))`
    /// and `∂/∂ρ = φ₂(h, k; ρ)`.
    #[inline(always)]
    fn wedge(&self, h: &Px, k: &Px, sg: f64) -> Wedge {
        let (rho, root) = (sg * self.rho, self.root);
        let (inv_root, inv_2r2) = (1.0 / root, 0.5 / (root * root));
        // Loops, not closures: LLVM would not inline closures this large into the vector build.
        let mut w = Wedge {
            value: self.wedge_value(h, k, sg),
            dh: [0.0; PX],
            dk: [0.0; PX],
            drho: [0.0; PX],
        };
        for l in 0..PX {
            w.dh[l] = pdf(h[l]) * cdf((k[l] - rho * h[l]) * inv_root);
            w.dk[l] = pdf(k[l]) * cdf((h[l] - rho * k[l]) * inv_root);
            let q = h[l] * h[l] + k[l] * k[l] - 2.0 * h[l] * k[l] * rho;
            w.drho[l] = exp(-q * inv_2r2) * (inv_root / (2.0 * PI));
        }
        w
    }

    /// `Φ₂(h, k; sg ρ)` alone (see [`Geometry::wedge`]): negating ρ mirrors the quadrature's
    /// nodes.
    #[inline(always)]
    fn wedge_value(&self, h: &Px, k: &Px, sg: f64) -> Px {
        let hh = px(|l| h[l] * h[l] + k[l] * k[l]);
        let hk2 = px(|l| 2.0 * h[l] * k[l] * sg);
        let mut sum = [0.0; PX];
        for j in 0..self.node_count {
            let (wt, sin, c) = (self.node_weight[j], self.node_sin[j], self.node_inv2c2[j]);
            for l in 0..PX {
                sum[l] += wt * exp(-(hh[l] - hk2[l] * sin) * c);
            }
        }
        for l in 0..PX {
            sum[l] = cdf(h[l]) * cdf(k[l]) + sg * sum[l];
        }
        sum
    }

    /// `S` at the offsets `(ex, ey)` without its derivatives.
    #[inline(always)]
    fn value(&self, ex: &Px, ey: &Px) -> Px {
        let (_, _, h) = self.edge_coordinates(0, ex, ey);
        let (_, _, k) = self.edge_coordinates(1, ex, ey);
        let sg = if self.delta >= 0.0 { 1.0 } else { -1.0 };
        let d = self.delta.abs() * self.inv_w;
        let a = self.wedge_value(&px(|l| h[l] - d), &px(|l| sg * k[l] - d), sg);
        let b = self.wedge_value(&px(|l| -h[l] - d), &px(|l| -sg * k[l] - d), sg);
        let x = px(|l| sg * (2.0 * (a[l] + b[l]) - 1.0));
        match self.sliver {
            Some(sliver) => {
                let t = self.sliver_value([&h, &k], sliver);
                px(|l| x[l] + t[l])
            }
            None => x,
        }
    }

    /// The sliver's term of `S` (see [`Sliver`]): the pattern flips beyond a line parallel to
    /// edge `i` at offset `s`, so `S` gains `−2 E[X 1_R]` with `R = {±(dᵢ − s) > 0}` (the sign
    /// of `s`); in `R` the blurred `sign(dᵢ)` is `±1` exactly, which leaves
    /// `∓2 (2 Φ₂(u, k_j; ±ρ) − Φ(u))`, `u = ±(hᵢ − s/w)`.
    #[inline(always)]
    fn sliver_value(&self, hk: [&Px; 2], sliver: Sliver) -> Px {
        let sgn = sliver.offset.signum();
        let (hi, kj) = (hk[sliver.edge], hk[1 - sliver.edge]);
        let u = px(|l| sgn * (hi[l] - sliver.offset * self.inv_w));
        let mut w = self.wedge_value(&u, kj, sgn);
        for l in 0..PX {
            w[l] = -2.0 * sgn * (2.0 * w[l] - cdf(u[l]));
        }
        w
    }

    /// [`Geometry::sliver_value`] with its derivatives over `hᵢ`, `k_j` and `ρ`.
    #[inline(always)]
    fn sliver_term(&self, hk: [&Px; 2], sliver: Sliver) -> Wedge {
        let sgn = sliver.offset.signum();
        let (hi, kj) = (hk[sliver.edge], hk[1 - sliver.edge]);
        let u = px(|l| sgn * (hi[l] - sliver.offset * self.inv_w));
        let mut w = self.wedge(&u, kj, sgn);
        for (l, &ul) in u.iter().enumerate() {
            w.value[l] = -2.0 * sgn * (2.0 * w.value[l] - cdf(ul));
            // ∂u/∂hᵢ = ±1 cancels the leading sign.
            w.dh[l] = -2.0 * (2.0 * w.dh[l] - pdf(ul));
            w.dk[l] *= -4.0 * sgn;
            // ∂(±ρ)/∂ρ = ±1.
            w.drho[l] *= -4.0;
        }
        w
    }

    /// The coordinates of `e = x − q` along and across edge `i`, `(u, v)`, and its scaled
    /// distance from the edge `h = (v − κu²/2)/w − κw/2`: the blur moves a curved edge's
    /// mid-level by `κw²/2` towards its centre of curvature (the Gaussian's mean of `κu²/2`
    /// along the edge).
    #[inline(always)]
    fn edge_coordinates(&self, i: usize, ex: &Px, ey: &Px) -> (Px, Px, Px) {
        let ([tx, ty], [nx, ny], kappa) = (self.t[i], self.n[i], self.kappa[i]);
        let u = px(|l| tx * ex[l] + ty * ey[l]);
        let v = px(|l| nx * ex[l] + ny * ey[l]);
        let h = px(|l| (v[l] - 0.5 * kappa * u[l] * u[l]) * self.inv_w - 0.5 * kappa * self.w);
        (u, v, h)
    }
}

/// Pixels per step of the model's evaluation: four `f64` lanes fill an AVX2 register.
const PX: usize = 4;

/// One value per pixel of a step.
type Px = [f64; PX];

/// The lanes `f(0), …, f(PX − 1)`: a plain loop, which is inlined into the vector builds where
/// `std::array::from_fn` was not.
#[inline(always)]
fn px(f: impl Fn(usize) -> f64) -> Px {
    let mut out = [0.0; PX];
    for (l, o) in out.iter_mut().enumerate() {
        *o = f(l);
    }
    out
}

/// The standard normal distribution function.
#[inline(always)]
fn cdf(x: f64) -> f64 {
    0.5 * (1.0 + erf(x * FRAC_1_SQRT_2))
}

use std::f64::consts::{FRAC_1_SQRT_2, PI};

/// The standard normal density.
#[inline(always)]
fn pdf(x: f64) -> f64 {
    const INV_SQRT_2PI: f64 = 0.398_942_280_401_432_7;
    INV_SQRT_2PI * exp(-0.5 * x * x)
}

/// Largest `|x|` [`exp`] takes before clamping; `e^{−700}` is as good as 0 for every use here.
const EXP_CLAMP: f64 = 700.0;

/// `1/d!` for `d = 0..=9`.
const INV_FACTORIALS: [f64; 10] = {
    let mut out = [1.0; 10];
    let mut d = 1;
    while d < 10 {
        out[d] = out[d - 1] / d as f64;
        d += 1;
    }
    out
};

/// `e^x` for `x` clamped to `±`[`EXP_CLAMP`], relative error below 10⁻¹¹ (tested): Cody–Waite
/// reduction `x = k ln 2 + r`, `|r| ≤ ln 2 / 2`, a degree-9 Taylor polynomial for `e^r`
/// (truncation `r¹⁰/10! < 7·10⁻¹²`, far below the error function's 10⁻⁷) and `2^k` built in the exponent bits. Branch-free, unlike
/// the C library's, so that the quadrature's loop over its nodes vectorizes: the junction fit
/// spends most of its time here.
#[inline(always)]
fn exp(x: f64) -> f64 {
    // Adding 1.5·2⁵² rounds to an integer, which then sits in the low mantissa bits.
    const SHIFTER: f64 = 6_755_399_441_055_744.0;
    const LN2_HI: f64 = 0.693_147_180_369_123_8; // 32 significant bits: k · LN2_HI is exact.
    const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;
    let x = x.clamp(-EXP_CLAMP, EXP_CLAMP);
    let t = x * std::f64::consts::LOG2_E + SHIFTER;
    let k = t - SHIFTER;
    let r = (x - k * LN2_HI) - k * LN2_LO;
    let mut poly = INV_FACTORIALS[9];
    for &c in INV_FACTORIALS[..9].iter().rev() {
        poly = poly * r + c;
    }
    // t's bits are those of SHIFTER plus k; shifting k + 1023 into the exponent field gives 2^k.
    let biased = t
        .to_bits()
        .wrapping_sub(SHIFTER.to_bits())
        .wrapping_add(1023);
    poly * f64::from_bits(biased << 52)
}

/// The error function, absolute error below 1.2·10⁻⁷ (Numerical Recipes' `erfc` Chebyshev fit,
/// `erfc(x) = t exp(−x² − 1.26551223 + t P(t))`, `t = 1/(1 + |x|/2)`).
#[inline(always)]
pub(crate) fn erf(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let poly = -1.265_512_23
        + t * (1.000_023_68
            + t * (0.374_091_96
                + t * (0.096_784_18
                    + t * (-0.186_288_06
                        + t * (0.278_868_07
                            + t * (-1.135_203_98
                                + t * (1.488_515_87 + t * (-0.822_152_23 + t * 0.170_872_77))))))));
    let erfc = t * exp(-z * z + poly);
    // erf(−x) = −erf(x), as a sign copy rather than a branch, so that it vectorizes.
    (1.0 - erfc).copysign(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::gaussian_blur;

    /// [`Geometry::value`] at one offset `e`.
    fn value_at(g: &Geometry, e: [f64; 2]) -> f64 {
        g.value(&[e[0]; PX], &[e[1]; PX])[0]
    }

    /// [`Geometry::pattern`] at one offset `e`.
    fn pattern_at(g: &Geometry, e: [f64; 2]) -> (f64, [f64; NL]) {
        let (s, ds) = g.pattern(&[e[0]; PX], &[e[1]; PX]);
        (s[0], ds.map(|d| d[0]))
    }

    /// A 41×41 X-junction at `q` (levels 0.2 and 0.8) whose edges leave at `angles` with
    /// curvatures `kappa`, its bright wedges eroded by `delta`: the sharp pattern on a grid 8×
    /// finer than the pixels, blurred there by `blur` px and averaged over each pixel's 8 × 8
    /// sub-pixels (a continuous blur, then the pixel's footprint).
    fn render_x(
        q: [f64; 2],
        angles: [f64; 2],
        kappa: [f64; 2],
        delta: f64,
        blur: f64,
    ) -> GrayImage {
        render_x_beside(q, angles, kappa, delta, blur, None)
    }

    /// [`render_x`] with the pattern flipped beyond a sliver's far edge.
    fn render_x_beside(
        q: [f64; 2],
        angles: [f64; 2],
        kappa: [f64; 2],
        delta: f64,
        blur: f64,
        sliver: Option<Sliver>,
    ) -> GrayImage {
        let (n, sub) = (41, 8);
        let t = angles.map(|a| [a.cos(), a.sin()]);
        let fine = n * sub;
        let mut data = vec![0f32; fine * fine];
        for (k, v) in data.iter_mut().enumerate() {
            let ex = (k % fine) as f64 / sub as f64 - 0.5 + 0.5 / sub as f64 - q[0];
            let ey = (k / fine) as f64 / sub as f64 - 0.5 + 0.5 / sub as f64 - q[1];
            let d = |i: usize| {
                let u = t[i][0] * ex + t[i][1] * ey;
                let v = -t[i][1] * ex + t[i][0] * ey;
                v - 0.5 * kappa[i] * u * u
            };
            let (a, b) = (d(0), d(1));
            let mut bright = (a > delta && b > delta) || (a < -delta && b < -delta);
            if let Some(Sliver { edge, offset }) = sliver {
                if offset.signum() * (d(edge) - offset) > 0.0 {
                    bright = !bright;
                }
            }
            *v = if bright { 0.8 } else { 0.2 };
        }
        let blurred = gaussian_blur(
            &GrayImage::from_vec(fine, fine, data).unwrap(),
            blur * sub as f64,
        );
        let mut pixels = vec![0f32; n * n];
        for (k, v) in blurred.data().iter().enumerate() {
            pixels[(k / fine / sub) * n + (k % fine) / sub] += v / (sub * sub) as f32;
        }
        GrayImage::from_vec(n, n, pixels).unwrap()
    }

    fn fit(image: &GrayImage, angles: [f64; 2]) -> JunctionCorner {
        let guess = [angles[0] + 0.05, angles[1] - 0.05];
        refine_junction(
            image,
            [20.0, 20.0],
            guess,
            7.0,
            1.0,
            &JunctionParams::default(),
        )
        .unwrap()
    }

    #[test]
    fn fast_exp_is_accurate_and_clamped() {
        let mut worst: f64 = 0.0;
        for i in -139_999..=139_999 {
            let x = i as f64 * 0.005 + 0.001_234;
            worst = worst.max((exp(x) / x.exp() - 1.0).abs());
        }
        assert!(worst < 1e-11, "{worst}");
        assert_eq!(exp(0.0), 1.0);
        assert_eq!(exp(-1e300), exp(-EXP_CLAMP));
        assert!(exp(f64::NEG_INFINITY) > 0.0 && exp(f64::NEG_INFINITY) < 1e-300);
        assert!(exp(1e300).is_finite());
    }

    #[test]
    fn quadrature_rules_meet_their_documented_error() {
        // Φ₂'s integral term against a composite rule (12 points on each of 16 pieces), with
        // the edges 90° − span apart, just inside and outside each rule's limit.
        let reference = |h: f64, k: f64, span: f64| {
            let pieces = 16;
            let width = span / pieces as f64;
            let mut sum = 0.0;
            for piece in 0..pieces {
                for &(x, wt) in GL_RULES[2].1 {
                    for sign in [-1.0, 1.0] {
                        let phi = width * (piece as f64 + 0.5 + 0.5 * sign * x);
                        let c = phi.cos();
                        let e = (h * h + k * k - 2.0 * h * k * phi.sin()) / (2.0 * c * c);
                        sum += 0.5 * width * wt * (-e).exp();
                    }
                }
            }
            sum / (2.0 * PI)
        };
        for span_deg in [10.0, 29.0, 31.0, 59.0, 61.0, 78.0f64] {
            let mut p = Vector::zeros();
            p[3] = std::f64::consts::FRAC_PI_2 - span_deg.to_radians();
            p[6] = 1.0;
            let g = Geometry::new(&p, None).unwrap();
            let mut worst: f64 = 0.0;
            for i in -12..=12 {
                for j in -12..=12 {
                    let (h, k) = (0.5 * i as f64, 0.5 * j as f64);
                    let ours = g.wedge_value(&[h; PX], &[k; PX], 1.0)[0] - cdf(h) * cdf(k);
                    worst = worst.max((ours - reference(h, k, span_deg.to_radians())).abs());
                }
            }
            assert!(worst < 3e-8, "span {span_deg}°: {worst}");
        }
    }

    #[test]
    fn recovers_straight_and_curved_junctions() {
        // Crossing angles of 90°, 46° and 26°; curvatures up to 0.03 px⁻¹ (a radius of 33 px).
        // The errors are below 0.005 px on straight edges crossing at 46° or more, up to
        // 0.026 px on the curved 26° wedge at blur 0.7.
        for (angles, kappa) in [
            ([0.3, 1.87], [0.0, 0.0]),
            ([0.2, 1.0], [0.0, 0.0]),
            ([0.35, 0.8], [0.0, 0.0]),
            ([0.3, 1.87], [0.03, -0.02]),
            ([0.35, 0.8], [0.02, 0.01]),
        ] {
            for blur in [0.7, 1.2] {
                let q = [20.3, 19.8];
                let j = fit(&render_x(q, angles, kappa, 0.0, blur), angles);
                let err = (j.point[0] - q[0]).hypot(j.point[1] - q[1]);
                let case = format!("{angles:?} {kappa:?} blur {blur}: {j:?}");
                assert!(err < 0.03, "{case}: {err}");
                assert!(
                    (j.blur - (blur * blur + 1.0 / 12.0).sqrt()).abs() < 0.05,
                    "{case}"
                );
                for i in 0..2 {
                    assert!((j.curvatures[i] - kappa[i]).abs() < 2e-3, "{case}");
                    assert!((j.angles[i] - angles[i]).sin().abs() < 0.01, "{case}");
                }
                assert!(
                    j.offset.abs() < 0.05 && (j.contrast - 0.6).abs() < 0.02,
                    "{case}"
                );
            }
        }
    }

    #[test]
    fn recovers_a_print_offset() {
        // A print's dot gain erodes the bright squares: each edge's two halves are 2δ apart,
        // and the corner is the centre between the bright wedges' tips.
        for delta in [0.6, -0.4] {
            let (q, angles) = ([19.6, 20.4], [0.4, 1.8]);
            let j = fit(&render_x(q, angles, [0.0, 0.0], delta, 1.0), angles);
            let err = (j.point[0] - q[0]).hypot(j.point[1] - q[1]);
            assert!(err < 0.02, "δ {delta}: {j:?}");
            // The fitted polarity may be either: the eroded side is the bright or the dark one.
            let signed = if j.contrast > 0.0 {
                j.offset
            } else {
                -j.offset
            };
            assert!(
                (signed.abs() - delta.abs()).abs() < 0.05,
                "δ {delta}: {j:?}"
            );
        }
    }

    #[test]
    fn a_sliver_beside_the_junction_is_modelled() {
        // A 2.5 or 3 px sliver beyond the second edge, inside the 6 px window: the plain model
        // is refused, the model with the sliver's far edge places the corner.
        let (q, angles) = ([20.3, 19.8], [0.25, 1.75]);
        let params = JunctionParams::default();
        // The offset is fitted: it starts a pixel off.
        for (offset, start) in [(2.5, 3.5), (-3.0, -2.0)] {
            let truth = Sliver { edge: 1, offset };
            let sliver = Sliver {
                edge: 1,
                offset: start,
            };
            let image = render_x_beside(q, angles, [0.0, 0.0], 0.0, 1.0, Some(truth));
            let err = |j: Option<JunctionCorner>| {
                j.map_or(f64::INFINITY, |j| {
                    (j.point[0] - q[0]).hypot(j.point[1] - q[1])
                })
            };
            let plain = err(refine_junction(
                &image,
                [20.0, 20.0],
                angles,
                6.0,
                1.0,
                &params,
            ));
            let beside =
                refine_junction_beside(&image, [20.0, 20.0], angles, 6.0, 1.0, sliver, &params);
            let e = err(beside);
            assert!(e < 0.03, "offset {offset}: {beside:?}");
            assert!(
                plain > 3.0 * e,
                "offset {offset}: plain {plain}, beside {e}"
            );
        }
        // On a board's boundary the sliver is sought beyond the edge, on the side away from the
        // board: given that side, the 2.5 px sliver is found from its 3 px start.
        let truth = Sliver {
            edge: 1,
            offset: 2.5,
        };
        let image = render_x_beside(q, angles, [0.0, 0.0], 0.0, 1.0, Some(truth));
        let normal = [-angles[1].sin(), angles[1].cos()];
        let j = refine_junction_at_boundary(
            &image,
            [20.0, 20.0],
            angles,
            6.0,
            1.0,
            &[(1, normal)],
            &params,
        )
        .unwrap();
        assert!((j.point[0] - q[0]).hypot(j.point[1] - q[1]) < 0.03, "{j:?}");
        // Without an edge to look beyond, it is the plain model.
        let plain = render_x(q, angles, [0.0, 0.0], 0.0, 1.0);
        assert_eq!(
            refine_junction_at_boundary(&plain, [20.0, 20.0], angles, 6.0, 1.0, &[], &params),
            refine_junction(&plain, [20.0, 20.0], angles, 6.0, 1.0, &params)
        );
        // Invalid slivers are refused.
        let image = render_x(q, angles, [0.0, 0.0], 0.0, 1.0);
        for sliver in [
            Sliver {
                edge: 2,
                offset: 2.0,
            },
            Sliver {
                edge: 0,
                offset: 0.0,
            },
        ] {
            assert!(refine_junction_beside(
                &image,
                [20.0, 20.0],
                angles,
                6.0,
                1.0,
                sliver,
                &params
            )
            .is_none());
        }
    }

    #[test]
    fn noise_stays_within_the_reported_sigma() {
        use rand::SeedableRng;
        let (q, angles) = ([20.2, 20.1], [0.5, 2.0]);
        let clean = render_x(q, angles, [0.0, 0.0], 0.0, 1.0);
        let mut errors = Vec::new();
        for seed in 0..40 {
            let mut image = clean.clone();
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            crate::synth::add_gaussian_noise(&mut image, 0.02, &mut rng);
            let j = fit(&image, angles);
            errors.push(((j.point[0] - q[0]).hypot(j.point[1] - q[1]), j.sigma));
        }
        // σ is the worst direction's: the 2-D error is within 2σ nearly always, never beyond 3σ.
        let within = errors.iter().filter(|(e, s)| e <= &(2.0 * s)).count();
        assert!(within >= 36, "{errors:?}");
        assert!(errors.iter().all(|(e, s)| *e < 3.0 * s), "{errors:?}");
    }

    /// The covariance is the inverse of the whole (symmetric) normal matrix: under noise alone
    /// the scatter of the position matches the Gauss–Newton σ per axis (scaled back by
    /// [`SIGMA_SCALE`]), for straight and curved edges.
    #[test]
    fn gauss_newton_sigma_matches_the_scatter_under_noise() {
        use rand::SeedableRng;
        let q = [20.2, 20.1];
        for (angles, kappa, blur, noise) in [
            ([0.5, 2.0], [0.0, 0.0], 1.0, 0.02),
            ([0.3, 1.4], [0.02, -0.01], 1.5, 0.03),
        ] {
            let clean = render_x(q, angles, kappa, 0.0, blur);
            let (mut err2, mut var, mut n) = ([0.0; 2], [0.0; 2], 0.0);
            for seed in 0..100 {
                let mut image = clean.clone();
                let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
                crate::synth::add_gaussian_noise(&mut image, noise, &mut rng);
                let p = JunctionParams::default();
                let Some(j) = refine_junction(&image, [20.0, 20.0], angles, 6.0, 1.0, &p) else {
                    continue;
                };
                for k in 0..2 {
                    err2[k] += (j.point[k] - q[k]).powi(2);
                    var[k] += j.cov[k][k] / (SIGMA_SCALE * SIGMA_SCALE);
                }
                n += 1.0;
            }
            assert!(n >= 95.0, "{n} fits");
            for k in 0..2 {
                let ratio = (err2[k] / var[k]).sqrt();
                assert!((0.8..1.25).contains(&ratio), "{angles:?} axis {k}: {ratio}");
            }
        }
    }

    #[test]
    fn the_wide_fit_is_kept_where_it_agrees() {
        use rand::SeedableRng;
        let (q, angles) = ([20.2, 20.1], [0.5, 2.0]);
        let params = JunctionParams::default();
        let err = |j: &JunctionCorner| (j.point[0] - q[0]).hypot(j.point[1] - q[1]);
        // A lone junction under noise: the wide window (radius 10 instead of 6) has 2.8 times
        // the pixels; its answer is kept, and its squared errors sum to 0.4 times the first's.
        let clean = render_x(q, angles, [0.0, 0.0], 0.0, 1.0);
        let (mut first, mut wide) = (0.0, 0.0);
        for seed in 0..20 {
            let mut image = clean.clone();
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            crate::synth::add_gaussian_noise(&mut image, 0.03, &mut rng);
            let f = refine_junction(&image, [20.0, 20.0], angles, 16.0, 1.0, &params).unwrap();
            let w =
                refine_junction_at_boundary(&image, [20.0, 20.0], angles, 16.0, 1.0, &[], &params)
                    .unwrap();
            assert!(w.sigma < 0.9 * f.sigma, "seed {seed}: {f:?} {w:?}");
            first += err(&f).powi(2);
            wide += err(&w).powi(2);
        }
        assert!(
            wide < 0.5 * first,
            "squared errors: first {first}, wide {wide}"
        );
        // A sliver's far edge 9.5 px beside the junction, at the rim of the wide window, where
        // the plain model does not hold: the wide fit converges 0.04 px off with a σ of
        // 0.09 px, and the first answer stays.
        let sliver = Sliver {
            edge: 0,
            offset: 9.5,
        };
        let image = render_x_beside(q, angles, [0.0, 0.0], 0.0, 1.0, Some(sliver));
        let f = refine_junction(&image, [20.0, 20.0], angles, 16.0, 1.0, &params).unwrap();
        let w = refine_junction_at_boundary(&image, [20.0, 20.0], angles, 16.0, 1.0, &[], &params)
            .unwrap();
        assert!(err(&f) < 0.01, "{f:?}");
        assert_eq!(w.point, f.point, "{w:?}");
        // Without the wide radius the function is the first fit.
        let narrow = JunctionParams {
            wide_radius: 0.0,
            ..params
        };
        let n = refine_junction_at_boundary(&clean, [20.0, 20.0], angles, 16.0, 1.0, &[], &narrow)
            .unwrap();
        let f = refine_junction(&clean, [20.0, 20.0], angles, 16.0, 1.0, &narrow).unwrap();
        assert_eq!(n.point, f.point);
    }

    #[test]
    fn the_wide_fit_starts_from_every_parameter_of_the_first() {
        // Curved edges, a print offset and noise: started from the first answer's curvatures,
        // blur and offset, the wide fit reaches the minimum that a start from straight edges
        // reaches.
        use rand::SeedableRng;
        let (q, angles) = ([20.3, 19.8], [0.4, 1.9]);
        let mut image = render_x(q, angles, [0.02, -0.03], 0.4, 1.2);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        crate::synth::add_gaussian_noise(&mut image, 0.02, &mut rng);
        let params = JunctionParams::default();
        let wide = JunctionParams {
            max_radius: params.wide_radius,
            ..params.clone()
        };
        let first = refine_junction(&image, [20.0, 20.0], angles, 16.0, 1.0, &params).unwrap();
        let warm = fit_junction(&image, Guess::from_answer(&first), 16.0, None, &wide).unwrap();
        let cold = fit_junction(
            &image,
            Guess::straight(first.point, first.angles, 1.0).unwrap(),
            16.0,
            None,
            &wide,
        )
        .unwrap();
        let apart = (warm.point[0] - cold.point[0]).hypot(warm.point[1] - cold.point[1]);
        assert!(apart < 1e-3, "{warm:?} {cold:?}");
        assert!(
            (warm.offset - cold.offset).abs() < 1e-3,
            "{warm:?} {cold:?}"
        );
        assert!(
            (q[0] - warm.point[0]).hypot(q[1] - warm.point[1]) < 0.05,
            "{warm:?}"
        );
    }

    #[test]
    fn the_pattern_is_a_product_of_erfs_for_orthogonal_straight_edges() {
        let mut p = Vector::zeros();
        p[3] = std::f64::consts::FRAC_PI_2;
        p[6] = 1.3;
        let g = Geometry::new(&p, None).unwrap();
        for e in [[0.4, -0.9], [2.0, 1.5], [-3.0, 0.2], [0.0, 0.0]] {
            let (h, k) = (e[1] / 1.3, -e[0] / 1.3);
            let product = erf(h * FRAC_1_SQRT_2) * erf(k * FRAC_1_SQRT_2);
            assert!((value_at(&g, e) - product).abs() < 1e-7, "{e:?}");
            assert!((pattern_at(&g, e).0 - product).abs() < 1e-7, "{e:?}");
        }
    }

    #[test]
    fn the_quadrature_is_exact_for_edges_twelve_degrees_apart() {
        for angle in [90f64, 45.0, 20.0, 12.0] {
            let mut p = Vector::zeros();
            p[3] = angle.to_radians();
            p[6] = 1.0;
            let g = Geometry::new(&p, None).unwrap();
            let alpha = g.rho.asin();
            for (h, k) in [
                (0.0, 0.0),
                (1.0, -0.5),
                (-2.0, 1.5),
                (2.5, 2.5),
                (-1.0, -3.0),
            ] {
                // Midpoint rule on 20000 intervals.
                let m = 20_000;
                let dphi = alpha / m as f64;
                let integral: f64 = (0..m)
                    .map(|j| {
                        let phi = (j as f64 + 0.5) * dphi;
                        let c = phi.cos();
                        (-(h * h + k * k - 2.0 * h * k * phi.sin()) / (2.0 * c * c)).exp() * dphi
                    })
                    .sum();
                let exact = cdf(h) * cdf(k) + integral / (2.0 * PI);
                let err = (g.wedge_value(&[h; PX], &[k; PX], 1.0)[0] - exact).abs();
                assert!(err < 2e-7, "{angle}° ({h}, {k}): {err}");
            }
        }
    }

    #[test]
    fn normal_equations_agree_across_builds_and_padding() {
        let img = render_x([20.3, 19.6], [0.4, 1.9], [0.01, -0.02], 0.3, 1.2);
        let p0 = Vector::from_row_slice(&[
            20.1, 19.8, 0.38, 1.93, 0.005, -0.01, 1.3, 0.2, 0.0, 120.0, 0.1, -0.2, 70.0,
        ]);
        let sliver = Sliver {
            edge: 1,
            offset: -2.5,
        };
        // Radii whose discs leave 0 to 3 pixels of padding in the last step.
        for (r, sliver) in [
            (5.0, None),
            (6.3, Some(sliver)),
            (7.1, None),
            (4.4, Some(sliver)),
        ] {
            let mut win = Window::load(&img, [20.0, 20.0], r).unwrap();
            win.sliver = sliver;
            let mut p = p0;
            p[8] = sliver.map_or(0.0, |s| s.offset);
            // Pixel by pixel, from the one-offset pattern.
            let g = Geometry::new(&p, sliver).unwrap();
            let (mut jtj, mut jtr, mut cost) = (Normal::zeros(), Vector::zeros(), 0.0);
            for i in 0..win.len() {
                let e = [
                    win.centre[0] + win.dx[i] - p[0],
                    win.centre[1] + win.dy[i] - p[1],
                ];
                let (s, ds) = pattern_at(&g, e);
                let mut jac = Vector::zeros();
                for k in 0..NL {
                    jac[k] = p[NL + 3] * ds[k];
                }
                jac[NL] = 1.0;
                jac[NL + 1] = win.dx[i];
                jac[NL + 2] = win.dy[i];
                jac[NL + 3] = s;
                let model = p[NL] + p[NL + 1] * win.dx[i] + p[NL + 2] * win.dy[i] + p[NL + 3] * s;
                let res = win.value[i] - model;
                jtj.syger(1.0, &jac, &jac, 1.0);
                jtr.axpy(res, &jac, 1.0);
                cost += res * res;
            }
            if sliver.is_none() {
                jtj[(8, 8)] = 1.0;
            }
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * (1.0 + a.abs().max(b.abs()));
            let mut builds = vec![win.normal_equations_generic(&p).unwrap()];
            #[cfg(target_arch = "x86_64")]
            if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
                builds.push(unsafe { win.normal_equations_avx2(&p) }.unwrap());
            }
            for (a, b, c) in builds {
                assert!(close(c, cost), "r = {r}: cost {c} vs {cost}");
                assert!(
                    a.iter().zip(jtj.iter()).all(|(x, y)| close(*x, *y)),
                    "r = {r}"
                );
                assert!(
                    b.iter().zip(jtr.iter()).all(|(x, y)| close(*x, *y)),
                    "r = {r}"
                );
            }
        }
    }

    #[test]
    fn analytic_derivatives_match_differences() {
        let p0 = Vector::from_row_slice(&[
            10.2, 9.7, 0.3, 1.1, 0.02, -0.015, 1.2, 0.4, 0.0, 0.5, 0.0, 0.0, 0.3,
        ]);
        let slivers = [
            None,
            Some(Sliver {
                edge: 0,
                offset: 1.7,
            }),
            Some(Sliver {
                edge: 1,
                offset: -2.2,
            }),
        ];
        for (sliver, x) in slivers
            .into_iter()
            .zip([[11.5, 9.0], [10.9, 11.0], [8.6, 10.4]])
        {
            let mut p = p0;
            p[8] = sliver.map_or(0.0, |s| s.offset);
            let g = Geometry::new(&p, sliver).unwrap();
            let at = |p: &Vector| {
                value_at(
                    &Geometry::new(p, sliver).unwrap(),
                    [x[0] - p[0], x[1] - p[1]],
                )
            };
            let (s, ds) = pattern_at(&g, [x[0] - p[0], x[1] - p[1]]);
            assert!((s - at(&p)).abs() < 1e-12, "{sliver:?}");
            for k in 0..NL {
                let h = 1e-6;
                let (mut up, mut down) = (p, p);
                up[k] += h;
                down[k] -= h;
                let numeric = (at(&up) - at(&down)) / (2.0 * h);
                // The differences of the approximate erf (error 1.2·10⁻⁷) limit the agreement.
                assert!(
                    (ds[k] - numeric).abs() < 1e-5,
                    "{sliver:?} parameter {k}: {} vs {numeric}",
                    ds[k]
                );
            }
        }
    }

    #[test]
    fn windows_grow_with_the_blur() {
        let p = JunctionParams::default();
        // Up to σ = 1.5 px the default radii hold.
        assert_eq!(p.for_blur(1.5), p);
        assert_eq!(p.for_blur(f64::NAN), p);
        assert_eq!(p.for_blur(-2.0), p);
        let q = p.for_blur(3.0);
        assert!((q.max_radius - 12.0).abs() < 1e-12, "{}", q.max_radius);
        assert!((q.wide_radius - 20.0).abs() < 1e-12, "{}", q.wide_radius);
        assert!(q.validate().is_ok());
        let r = p.for_blur(20.0);
        assert_eq!((r.max_radius, r.wide_radius), (32.0, 32.0));
        assert!(r.validate().is_ok());
        let bad = JunctionParams {
            radius_per_blur: f64::INFINITY,
            ..p
        };
        assert!(bad.validate().unwrap_err().contains("radius per blur"));
    }

    #[test]
    fn bad_input_gives_none() {
        let angles = [0.3, 1.87];
        let image = render_x([20.3, 19.8], angles, [0.0, 0.0], 0.0, 1.0);
        let params = JunctionParams::default();
        let run = |start: [f64; 2], angles: [f64; 2], params: &JunctionParams| {
            refine_junction(&image, start, angles, 7.0, 1.0, params)
        };
        assert!(run([20.0, 20.0], angles, &params).is_some());
        // The window leaves the image.
        assert!(run([3.0, 20.0], angles, &params).is_none());
        // Non-finite input.
        assert!(run([f64::NAN, 20.0], angles, &params).is_none());
        assert!(run([20.0, 20.0], [0.3, f64::INFINITY], &params).is_none());
        // Parallel edges.
        assert!(run([20.0, 20.0], [0.3, 0.3 + PI], &params).is_none());
        // Invalid parameters.
        let bad = JunctionParams {
            min_radius: 1.0,
            ..params.clone()
        };
        assert!(bad.validate().unwrap_err().contains("radii"));
        assert!(run([20.0, 20.0], angles, &bad).is_none());
        for wide_radius in [f64::NAN, 40.0] {
            let bad = JunctionParams {
                wide_radius,
                ..params.clone()
            };
            assert!(bad.validate().unwrap_err().contains("wide radius"));
            assert!(run([20.0, 20.0], angles, &bad).is_none());
        }
        // A flat patch and a single straight edge have no junction.
        let flat = GrayImage::filled(41, 41, 0.5).unwrap();
        assert!(refine_junction(&flat, [20.0, 20.0], angles, 7.0, 1.0, &params).is_none());
        let data = (0..41 * 41)
            .map(|k| if k % 41 < 20 { 0.2 } else { 0.8 })
            .collect();
        let edge = GrayImage::from_vec(41, 41, data).unwrap();
        let j = refine_junction(&edge, [20.0, 20.0], angles, 7.0, 1.0, &params);
        assert!(j.is_none(), "{j:?}");
    }
}
