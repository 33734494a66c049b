//! # conic-corners
//!
//! Finds checkerboard and checkerboard-like markers in images and localizes every corner to a small
//! fraction of a pixel, on flat markers and on markers bent around curved objects, following
//! *Accurate Detection and Localization of Curved Checkerboard-Like Marker Based on Quadratic Form*.
//!
//! One module per pipeline stage:
//!
//! | stage | module |
//! |---|---|
//! | Hessian pre-filter (III-A) | [`prefilter`] |
//! | template final election (III-B) | [`election`] |
//! | Delaunay connectivity and grid labels (III-C) | [`connectivity`] |
//! | completion of the labelled grid (missing corners verified) | [`completion`] |
//! | sigmoid subpixel edge sampling (III-D) | [`edge_sampling`] |
//! | sample-chain segmentation (III-E) | [`segmentation`] |
//! | conic / line fitting and intersection (III-F) | [`quadratic_form`] |
//! | the same along whole grid lines (III-D to III-F) | [`board_fit`] |
//! | blurred X-junction model fitted to the pixels (short, crowded edges) | [`junction`] |
//! | last-resort gradient-orthogonality refinement | [`gradient`] |
//! | a-posteriori variance factor of a board's covariances | [`variance_factor`] |
//! | spacing law along straight grid lines, fused into each corner | [`spacing`] |
//! | labels in the frame of a known pattern (calibration) | [`pattern`] |
//!
//! [`detect`] runs the whole pipeline on an image.
//! [`refine`] combines edge sampling and quadratic-form fitting into a single-corner refiner (a more
//! accurate drop-in for OpenCV's `cornerSubPix`); [`synth`] renders test images with exact truth.
//!
//! **Coordinates** everywhere: x to the right, y down, the centre of the top-left pixel is (0, 0)
//! (OpenCV's convention). Pixel `(i, j)` covers `[i - 0.5, i + 0.5] × [j - 0.5, j + 0.5]`.

pub mod board_fit;
pub mod completion;
pub mod connectivity;
pub mod detect;
pub mod edge_sampling;
pub mod election;
pub mod gradient;
pub mod image;
pub mod junction;
pub mod pattern;
pub mod prefilter;
pub mod quadratic_form;
pub mod refine;
pub mod segmentation;
pub mod spacing;
pub mod synth;
pub mod variance_factor;

pub use crate::image::{GrayImage, ImageError};
