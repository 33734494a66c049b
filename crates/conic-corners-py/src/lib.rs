//! `conic_corners._native`: the PyO3 bindings behind the `conic_corners` Python package.
//!
//! The public Python API (`conic_corners.detect`, `conic_corners.refine`, `Board`) lives in
//! `python/conic_corners/__init__.py`, which wraps these functions; everything here validates its
//! input itself, so calling `_native` directly cannot crash the interpreter either.
//!
//! Coordinates: x right, y down, the centre of the top-left pixel is `(0, 0)` (OpenCV's
//! convention), as in the Rust library.
//!
//! Images are copied once into the library's `f32` [`GrayImage`] while the GIL is held (numpy
//! arrays may be strided, so the copy walks them in logical order); the pipeline then runs with
//! the GIL released, so Python threads calling these functions run in parallel.

use conic_corners::board_fit::Path;
use conic_corners::detect::{detect as detect_rs, DetectParams, RefineMode};
use conic_corners::pattern::Pattern;
use conic_corners::refine::{refine as refine_rs, RefineParams, Status};
use conic_corners::GrayImage;
use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{
    Element, IntoPyArray, PyArrayDescrMethods, PyArrayDyn, PyArrayMethods, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// Status code of a corner refined to convergence (both edges seen on both sides).
const CONVERGED: u8 = 2;
/// Status code of a corner refined with less support (one-sided edge, straight-line fallback).
const FALLBACK: u8 = 1;
/// Status code of a corner that could not be refined (the start position is returned).
const FAILED: u8 = 0;

/// Path code of a corner placed by the single-corner refiner.
const PATH_LOCAL: u8 = 0;
/// Path code of a corner placed by the board-wide row and column curves.
const PATH_BOARD: u8 = 1;
/// Path code of a corner placed by the gradient-orthogonality estimate (last resort).
const PATH_GRADIENT: u8 = 2;
/// Path code of a corner placed by the blurred X-junction model fitted to its pixels.
const PATH_JUNCTION: u8 = 3;
/// Path code of a corner placed beside hairline slivers at a silhouette, where the board's
/// boundary line meets the grid line into the board.
const PATH_HAIRLINE: u8 = 4;

fn path_code(p: Path) -> u8 {
    match p {
        Path::Local => PATH_LOCAL,
        Path::Board => PATH_BOARD,
        Path::Gradient => PATH_GRADIENT,
        Path::Junction => PATH_JUNCTION,
        Path::Hairline => PATH_HAIRLINE,
    }
}

fn status_code(s: Status) -> u8 {
    match s {
        Status::Converged => CONVERGED,
        Status::Fallback => FALLBACK,
        Status::Failed => FAILED,
    }
}

/// The pixel values of an image array in logical (row-major, channel-last) order.
enum Pixels {
    U8(Vec<u8>),
    U16(Vec<u16>),
    F32(Vec<f32>),
}

/// The values of `arr`, whose dtype is known to be `T`, in logical order.
fn values_of<T: Element + Copy>(arr: &Bound<'_, PyUntypedArray>) -> PyResult<Vec<T>> {
    let typed = arr
        .cast::<PyArrayDyn<T>>()
        .map_err(|e| PyTypeError::new_err(e.to_string()))?;
    let view = typed
        .try_readonly()
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    // `iter` walks any stride pattern (negative, transposed, sliced) in logical order.
    Ok(view.as_array().iter().copied().collect())
}

/// Copies a numpy image (2-D grey, or H×W×3 / H×W×4 colour; uint8, uint16, float32 or float64)
/// into a [`GrayImage`]. Colour goes through the `image` crate's own luma conversion (Rec. 709
/// weights, its integer arithmetic for 8/16 bit), exactly what the CLI applies to a colour file,
/// alpha is ignored; `bgr` swaps the first and third channels first (OpenCV's channel order).
fn gray_from_numpy(image: &Bound<'_, PyAny>, bgr: bool) -> PyResult<GrayImage> {
    let arr = image.cast::<PyUntypedArray>().map_err(|_| {
        PyTypeError::new_err(format!(
            "image must be a numpy.ndarray, got {}",
            type_name(image)
        ))
    })?;
    // The dtype is checked first: a wrong type is a TypeError whatever the shape.
    let py = arr.py();
    let dtype = arr.dtype();
    let is = |other: Bound<'_, numpy::PyArrayDescr>| dtype.is_equiv_to(&other);
    let read = if is(numpy::dtype::<u8>(py)) {
        |a: &Bound<'_, PyUntypedArray>| values_of::<u8>(a).map(Pixels::U8)
    } else if is(numpy::dtype::<u16>(py)) {
        |a: &Bound<'_, PyUntypedArray>| values_of::<u16>(a).map(Pixels::U16)
    } else if is(numpy::dtype::<f32>(py)) {
        |a: &Bound<'_, PyUntypedArray>| values_of::<f32>(a).map(Pixels::F32)
    } else if is(numpy::dtype::<f64>(py)) {
        |a: &Bound<'_, PyUntypedArray>| {
            values_of::<f64>(a).map(|v| Pixels::F32(v.into_iter().map(|x| x as f32).collect()))
        }
    } else {
        return Err(PyTypeError::new_err(format!(
            "image dtype must be uint8, uint16, float32 or float64 (native byte order), got {}",
            dtype_name(arr)
        )));
    };
    let shape = arr.shape().to_vec();
    let channels = match shape.len() {
        2 => 1,
        3 if shape[2] == 3 || shape[2] == 4 => shape[2],
        3 => {
            return Err(PyValueError::new_err(format!(
                "a 3-D image must be H×W×3 (RGB) or H×W×4 (RGBA), got shape {shape:?}"
            )))
        }
        n => {
            return Err(PyValueError::new_err(format!(
                "image must be 2-D (grey) or 3-D (H×W×3 / H×W×4 colour), got {n}-D shape {shape:?}"
            )))
        }
    };
    let (h, w) = (shape[0], shape[1]);
    if h == 0 || w == 0 {
        return Err(PyValueError::new_err(format!(
            "image is empty (shape {shape:?})"
        )));
    }
    if (h as u64) * (w as u64) > conic_corners::image::MAX_PIXELS {
        return Err(PyValueError::new_err(format!(
            "image is too large ({w}×{h} > {} pixels)",
            conic_corners::image::MAX_PIXELS
        )));
    }
    let pixels = read(arr)?;
    if let Pixels::F32(v) = &pixels {
        if !v.iter().all(|x| x.is_finite()) {
            return Err(PyValueError::new_err(
                "image holds NaN or infinite values (or float64 values beyond float32's range)",
            ));
        }
    }
    let to_value_err = |e: conic_corners::ImageError| PyValueError::new_err(e.to_string());
    if channels == 1 {
        return match pixels {
            Pixels::U8(v) => GrayImage::from_slice(w, h, &v),
            Pixels::U16(v) => GrayImage::from_slice(w, h, &v),
            Pixels::F32(v) => GrayImage::from_vec(w, h, v),
        }
        .map_err(to_value_err);
    }
    GrayImage::from_dynamic(&colour_image(w as u32, h as u32, channels, pixels, bgr))
        .map_err(to_value_err)
}

/// Rebuilds the colour image the CLI would have decoded from a file, so that the `image` crate's
/// conversion to luma applies unchanged. `pixels` holds `w · h · channels` values.
fn colour_image(w: u32, h: u32, channels: usize, pixels: Pixels, bgr: bool) -> image::DynamicImage {
    use image::{DynamicImage as D, ImageBuffer};
    fn swap<T>(mut v: Vec<T>, channels: usize, bgr: bool) -> Vec<T> {
        if bgr {
            v.chunks_exact_mut(channels).for_each(|p| p.swap(0, 2));
        }
        v
    }
    const SIZE: &str = "buffer length is w·h·channels";
    match (pixels, channels) {
        (Pixels::U8(v), 3) => {
            D::ImageRgb8(ImageBuffer::from_raw(w, h, swap(v, 3, bgr)).expect(SIZE))
        }
        (Pixels::U8(v), _) => {
            D::ImageRgba8(ImageBuffer::from_raw(w, h, swap(v, 4, bgr)).expect(SIZE))
        }
        (Pixels::U16(v), 3) => {
            D::ImageRgb16(ImageBuffer::from_raw(w, h, swap(v, 3, bgr)).expect(SIZE))
        }
        (Pixels::U16(v), _) => {
            D::ImageRgba16(ImageBuffer::from_raw(w, h, swap(v, 4, bgr)).expect(SIZE))
        }
        (Pixels::F32(v), 3) => {
            D::ImageRgb32F(ImageBuffer::from_raw(w, h, swap(v, 3, bgr)).expect(SIZE))
        }
        (Pixels::F32(v), _) => {
            D::ImageRgba32F(ImageBuffer::from_raw(w, h, swap(v, 4, bgr)).expect(SIZE))
        }
    }
}

fn type_name(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "?".into())
}

fn dtype_name(arr: &Bound<'_, PyUntypedArray>) -> String {
    arr.dtype()
        .str()
        .map(|s| s.to_string())
        .unwrap_or_else(|_| "?".into())
}

/// Reads an optional integer keyword that must be at least `min`.
fn int_at_least(name: &str, value: Option<i64>, min: i64) -> PyResult<Option<usize>> {
    match value {
        Some(v) if v < min => Err(PyValueError::new_err(format!(
            "{name} must be at least {min}, got {v}"
        ))),
        Some(v) => usize::try_from(v)
            .map(Some)
            .map_err(|_| PyValueError::new_err(format!("{name} is too large: {v}"))),
        None => Ok(None),
    }
}

/// Refinement parameters from the keywords, `defaults` for the ones not given, validated.
fn refine_params(
    defaults: RefineParams,
    reach: Option<f64>,
    stride: Option<i64>,
    blur: Option<f64>,
) -> PyResult<RefineParams> {
    let params = RefineParams {
        reach: reach.unwrap_or(defaults.reach),
        stride: int_at_least("stride", stride, 1)?.unwrap_or(defaults.stride),
        blur,
        ..defaults
    };
    params.validate().map_err(PyValueError::new_err)?;
    Ok(params)
}

/// N×2×2 array of the covariances (px²), NaN where a corner has none.
fn covariance_array(covs: impl ExactSizeIterator<Item = Option<[[f64; 2]; 2]>>) -> Array3<f64> {
    let mut out = Array3::<f64>::from_elem((covs.len(), 2, 2), f64::NAN);
    for (i, cov) in covs.enumerate() {
        if let Some(cov) = cov {
            for (r, row) in cov.iter().enumerate() {
                for (k, v) in row.iter().enumerate() {
                    out[[i, r, k]] = *v;
                }
            }
        }
    }
    out
}

/// Runs the whole detection pipeline (see `conic_corners.detect` for the documented API).
///
/// Returns one dict per board, largest first, with keys `rows`, `cols`, `points` (N×2 float64,
/// x then y), `ids` (N×2 int32, row then col), `scores` (N float64), `status` (N uint8: 0 failed,
/// 1 fallback, 2 converged), `residuals` (N float64, NaN where not refined), `paths` (N uint8:
/// 0 local, 1 board), `sigmas` (N float64, NaN where refinement failed), `covariances`
/// (N×2×2 float64, px², NaN where refinement failed) and `sigma_scale` (the board's a-posteriori
/// factor on every σ, or `None`).
///
/// `refine` is `"board"` (board-wide curve fitting, the default) or `"local"`.
#[pyfunction]
#[pyo3(signature = (image, corners=None, *, sigma=None, reach=None, blur=None, min_board_corners=None, stride=None, refine="board", bgr=false, pattern=None))]
#[allow(clippy::too_many_arguments)]
fn detect<'py>(
    py: Python<'py>,
    image: &Bound<'py, PyAny>,
    corners: Option<i64>,
    sigma: Option<f64>,
    reach: Option<f64>,
    blur: Option<f64>,
    min_board_corners: Option<i64>,
    stride: Option<i64>,
    refine: &str,
    bgr: bool,
    pattern: Option<(i64, i64)>,
) -> PyResult<Vec<Bound<'py, PyDict>>> {
    let mode = match refine {
        "board" => RefineMode::Board,
        "local" => RefineMode::Local,
        other => {
            return Err(PyValueError::new_err(format!(
                "refine must be \"board\" or \"local\", got {other:?}"
            )))
        }
    };
    let mut params = DetectParams::default();
    params.prefilter.expected_corners = int_at_least("corners", corners, 1)?;
    if let Some(s) = sigma {
        if !(s.is_finite() && (0.5..=32.0).contains(&s)) {
            return Err(PyValueError::new_err(format!(
                "sigma (pre-filter scale) must be in 0.5..=32 px, got {s}"
            )));
        }
        params.prefilter.sigma = s as f32;
    }
    if let Some(m) = int_at_least("min_board_corners", min_board_corners, 4)? {
        params.labels.min_corners = m;
    }
    params.refine = refine_params(params.refine.clone(), reach, stride, blur)?;
    params.share_sampling();
    params.mode = mode;
    params.pattern = match pattern {
        None => None,
        Some((rows, cols)) if rows >= 2 && cols >= 2 => Some(Pattern {
            rows: rows as usize,
            cols: cols as usize,
        }),
        Some((rows, cols)) => {
            return Err(PyValueError::new_err(format!(
                "pattern needs at least 2 x 2 inner corners, got ({rows}, {cols})"
            )))
        }
    };
    params.validate().map_err(PyValueError::new_err)?;
    let gray = gray_from_numpy(image, bgr)?;
    let detection = py.detach(|| detect_rs(&gray, &params));
    detection
        .boards
        .into_iter()
        .map(|board| {
            let n = board.corners.len();
            let mut points = Array2::<f64>::zeros((n, 2));
            let mut ids = Array2::<i32>::zeros((n, 2));
            let mut scores = Array1::<f64>::zeros(n);
            let mut status = Array1::<u8>::zeros(n);
            let mut residuals = Array1::<f64>::zeros(n);
            let mut paths = Array1::<u8>::zeros(n);
            let mut sigmas = Array1::<f64>::zeros(n);
            for (i, c) in board.corners.iter().enumerate() {
                points[[i, 0]] = c.x;
                points[[i, 1]] = c.y;
                ids[[i, 0]] = c.row;
                ids[[i, 1]] = c.col;
                scores[i] = c.score;
                status[i] = status_code(c.status);
                residuals[i] = c.residual.unwrap_or(f64::NAN);
                paths[i] = path_code(c.path);
                sigmas[i] = c.sigma.unwrap_or(f64::NAN);
            }
            let covariances = covariance_array(board.corners.iter().map(|c| c.cov));
            let d = PyDict::new(py);
            d.set_item("rows", board.rows)?;
            d.set_item("cols", board.cols)?;
            d.set_item("points", points.into_pyarray(py))?;
            d.set_item("ids", ids.into_pyarray(py))?;
            d.set_item("scores", scores.into_pyarray(py))?;
            d.set_item("status", status.into_pyarray(py))?;
            d.set_item("residuals", residuals.into_pyarray(py))?;
            d.set_item("paths", paths.into_pyarray(py))?;
            d.set_item("sigmas", sigmas.into_pyarray(py))?;
            d.set_item("covariances", covariances.into_pyarray(py))?;
            d.set_item("sigma_scale", board.sigma_scale)?;
            Ok(d)
        })
        .collect()
}

/// Refines approximate corners (see `conic_corners.refine` for the documented API).
///
/// `points` is an N×2 or N×1×2 float32/float64 array; returns `(refined, status, residuals,
/// covariances)`: `refined` has the shape and dtype of `points`, `status` is N uint8 (0 failed,
/// 1 fallback, 2 converged), `residuals` N float64 and `covariances` N×2×2 float64 (px², NaN
/// where failed).
#[pyfunction]
#[pyo3(signature = (image, points, *, reach=None, stride=None, blur=None, bgr=false))]
#[allow(clippy::type_complexity)]
fn refine<'py>(
    py: Python<'py>,
    image: &Bound<'py, PyAny>,
    points: &Bound<'py, PyAny>,
    reach: Option<f64>,
    stride: Option<i64>,
    blur: Option<f64>,
    bgr: bool,
) -> PyResult<(
    Bound<'py, PyAny>,
    Bound<'py, PyAny>,
    Bound<'py, PyAny>,
    Bound<'py, PyAny>,
)> {
    let params = refine_params(RefineParams::default(), reach, stride, blur)?;
    let arr = points.cast::<PyUntypedArray>().map_err(|_| {
        PyTypeError::new_err(format!(
            "points must be a numpy.ndarray, got {}",
            type_name(points)
        ))
    })?;
    let dtype = arr.dtype();
    let is_f32 = dtype.is_equiv_to(&numpy::dtype::<f32>(py));
    if !(is_f32 || dtype.is_equiv_to(&numpy::dtype::<f64>(py))) {
        return Err(PyTypeError::new_err(format!(
            "points dtype must be float32 or float64, got {}",
            dtype_name(arr)
        )));
    }
    let shape = arr.shape().to_vec();
    if !matches!(shape.as_slice(), [_, 2] | [_, 1, 2]) {
        return Err(PyValueError::new_err(format!(
            "points must be N×2 or N×1×2, got shape {shape:?}"
        )));
    }
    if shape[0] == 0 {
        return Err(PyValueError::new_err(
            "points is empty (no corner to refine)",
        ));
    }
    let starts: Vec<f64> = if is_f32 {
        values_of::<f32>(arr)?.into_iter().map(f64::from).collect()
    } else {
        values_of::<f64>(arr)?
    };
    let starts: Vec<[f64; 2]> = starts.chunks_exact(2).map(|p| [p[0], p[1]]).collect();
    if let Some(i) = starts.iter().position(|p| !p.iter().all(|v| v.is_finite())) {
        return Err(PyValueError::new_err(format!(
            "point {i} is not finite: {:?}",
            starts[i]
        )));
    }
    let gray = gray_from_numpy(image, bgr)?;
    let refined = py.detach(|| refine_rs(&gray, &starts, &params));
    let flat: Vec<f64> = refined.iter().flat_map(|r| [r.x, r.y]).collect();
    let status: Vec<u8> = refined.iter().map(|r| status_code(r.status)).collect();
    let residuals: Vec<f64> = refined
        .iter()
        .map(|r| r.residual.unwrap_or(f64::NAN))
        .collect();
    let covariances = covariance_array(refined.iter().map(|r| r.cov));
    let out = if is_f32 {
        let v: Vec<f32> = flat.iter().map(|&x| x as f32).collect();
        v.into_pyarray(py).reshape(shape.as_slice())?.into_any()
    } else {
        flat.into_pyarray(py).reshape(shape.as_slice())?.into_any()
    };
    Ok((
        out,
        status.into_pyarray(py).into_any(),
        residuals.into_pyarray(py).into_any(),
        covariances.into_pyarray(py).into_any(),
    ))
}

/// The compiled core of the `conic_corners` package.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(detect, m)?)?;
    m.add_function(wrap_pyfunction!(refine, m)?)?;
    m.add("FAILED", FAILED)?;
    m.add("FALLBACK", FALLBACK)?;
    m.add("CONVERGED", CONVERGED)?;
    m.add("PATH_LOCAL", PATH_LOCAL)?;
    m.add("PATH_BOARD", PATH_BOARD)?;
    m.add("PATH_GRADIENT", PATH_GRADIENT)?;
    m.add("PATH_JUNCTION", PATH_JUNCTION)?;
    m.add("PATH_HAIRLINE", PATH_HAIRLINE)?;
    Ok(())
}
