"""Subpixel checkerboard corners on flat and curved markers, by quadratic-form fitting.

A drop-in for OpenCV's ``findChessboardCorners`` + ``cornerSubPix``::

    import conic_corners as cc

    boards = cc.detect(gray)                       # list of Board, largest first
    b = boards[0]
    obj, img = b.object_points(0.025), b.image_points()
    cv2.calibrateCamera([obj], [img], gray.shape[::-1], None, None)

    refined, status = cc.refine(gray, corners)     # like cv2.cornerSubPix

Coordinates: x right, y down, the centre of the top-left pixel is (0, 0) (OpenCV's convention).

Images: 2-D ``uint8``, ``uint16``, ``float32`` or ``float64`` arrays, or H×W×3 (RGB) / H×W×4
(RGBA) colour of those dtypes, contiguous or not. Colour is converted to grey with the Rec. 709
weights of the Rust ``image`` crate (as the ``conic-corners`` CLI does with a colour file); pass
``bgr=True`` for OpenCV's channel order. The image is copied once; the work runs without the GIL,
so several threads can process images in parallel.

Status codes (``Board.status``, the second result of :func:`refine`): :data:`FAILED` (0, the start
position is returned), :data:`FALLBACK` (1, less support: an edge seen on one side only, or
straight lines instead of curves), :data:`CONVERGED` (2).

Path codes (``Board.paths``): :data:`PATH_LOCAL` (0, placed by the single-corner refiner),
:data:`PATH_BOARD` (1, the intersection of the row and column curves fitted along the whole board,
with a standard deviation in ``Board.sigmas`` like every placed corner), :data:`PATH_GRADIENT` (2, the
gradient-orthogonality estimate of OpenCV's ``cornerSubPix`` kind, the last resort),
:data:`PATH_JUNCTION` (3, a blurred X-junction model fitted to the pixels around the corner) and
:data:`PATH_HAIRLINE` (4, where the board's boundary line meets the grid line into the board, beside
squares foreshortened to hairline slivers at a silhouette, where nothing else places the corner);
:func:`detect` fits board-wide by default and falls back to the local refiner per corner where a grid
line has too few samples, to the junction model where the local refiner fails or sees one side only
(foreshortened squares at a silhouette), and to the gradient estimate where that fails too. A
board-wide answer with less support than most of its board's, or a doubtful one, is combined with
the junction model's by their inverse covariances where the two agree.

Errors: a wrong dtype raises ``TypeError``; a wrong shape, an empty array, non-finite values or an
out-of-range parameter raise ``ValueError``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import List, Optional, Tuple

import numpy as np

from . import _native

__all__ = [
    "Board",
    "detect",
    "refine",
    "FAILED",
    "FALLBACK",
    "CONVERGED",
    "STATUS_NAMES",
    "PATH_LOCAL",
    "PATH_BOARD",
    "PATH_GRADIENT",
    "PATH_JUNCTION",
    "PATH_HAIRLINE",
    "PATH_NAMES",
]

FAILED: int = _native.FAILED
FALLBACK: int = _native.FALLBACK
CONVERGED: int = _native.CONVERGED
#: Status code → name, the names the CLI prints in its JSON ("failed", "fallback", "converged").
STATUS_NAMES: Tuple[str, str, str] = ("failed", "fallback", "converged")
PATH_LOCAL: int = _native.PATH_LOCAL
PATH_BOARD: int = _native.PATH_BOARD
PATH_GRADIENT: int = _native.PATH_GRADIENT
PATH_JUNCTION: int = _native.PATH_JUNCTION
PATH_HAIRLINE: int = _native.PATH_HAIRLINE
#: Path code → name, the names the CLI prints in its JSON.
PATH_NAMES: Tuple[str, str, str, str, str] = ("local", "board", "gradient", "junction", "hairline")


@dataclass(frozen=True, eq=False)
class Board:
    """One detected board: its labelled corners, sorted by (row, col).

    Attributes:
        rows: ``1 + max row``; rows increase towards +y (with ``pattern``: the pattern's rows,
            in the frame of its print).
        cols: ``1 + max col``; columns increase towards +x (with ``pattern``: its columns).
        points: N×2 ``float64`` subpixel positions, x then y (pixel centres at integers).
        ids: N×2 ``int32`` grid labels, row then col, in the order of ``points``.
        scores: N ``float64`` template-matching scores (normalized cross-correlation).
        status: N ``uint8`` status codes (:data:`FALLBACK`, :data:`CONVERGED`); a corner that
            no refiner could place (:data:`FAILED`) is not reported: such corners were false ones.
        residuals: N ``float64`` RMS distances (px) of the edge samples to their fitted curves,
            NaN where the corner was not refined.
        paths: N ``uint8`` path codes: :data:`PATH_BOARD` where the corner is the intersection
            of its board-wide row and column curves, :data:`PATH_LOCAL` where the single-corner
            refiner placed it, :data:`PATH_GRADIENT` where the gradient estimate did.
        sigmas: N ``float64`` standard deviations (px) of the position in its worst direction,
            propagated from the residuals of the fits that placed it (board-wide or local curves,
            or the gradient estimate, whose sigma is conservative); NaN where refinement failed.
        covariances: N×2×2 ``float64`` covariances (px², ``[[xx, xy], [xy, yy]]``) of the
            positions, from the same fits: ``sigmas`` is the square root of each one's larger
            eigenvalue. A corner whose row curve is sure and whose column curve is extrapolated
            is known far better across the row than along it; weigh a pose or calibration fit
            with the inverse covariances to use that. NaN where refinement failed.
        sigma_scale: the factor already applied to every ``sigmas`` value (``covariances`` by
            its square): how far the corners stray from a smooth grid along its straight lines,
            against what their fits claimed (an a-posteriori variance factor). About 1 on clean
            renders, 2–3 on real photos of printed boards, whose edges share errors that the
            fits' residuals do not show. ``None`` where the board has too few straight runs of
            six corners to measure it; the sigmas are then as the fits gave them.

    A board may have holes (occluded corners), so ``len(board)`` can be less than ``rows * cols``.
    """

    rows: int
    cols: int
    points: np.ndarray
    ids: np.ndarray
    scores: np.ndarray
    status: np.ndarray
    residuals: np.ndarray
    paths: np.ndarray
    sigmas: np.ndarray
    covariances: np.ndarray
    sigma_scale: Optional[float] = None

    def __len__(self) -> int:
        return int(self.points.shape[0])

    @property
    def status_names(self) -> List[str]:
        """The status of each corner as a name: "failed", "fallback" or "converged"."""
        return [STATUS_NAMES[s] for s in self.status]

    @property
    def path_names(self) -> List[str]:
        """The path of each corner as a name: "local" or "board"."""
        return [PATH_NAMES[p] for p in self.paths]

    def object_points(self, square_size: float = 1.0) -> np.ndarray:
        """N×3 ``float32`` board coordinates ``(col·s, row·s, 0)`` in the order of ``points``,
        the ``objectPoints`` of ``cv2.calibrateCamera`` / ``cv2.solvePnP``."""
        s = float(square_size)
        if not (np.isfinite(s) and s > 0):
            raise ValueError(f"square_size must be a positive finite number, got {square_size!r}")
        obj = np.zeros((len(self), 3), np.float32)
        obj[:, 0] = self.ids[:, 1] * s
        obj[:, 1] = self.ids[:, 0] * s
        return obj

    def image_points(self) -> np.ndarray:
        """N×1×2 ``float32`` copy of ``points``: OpenCV's layout for ``imagePoints``."""
        return self.points.astype(np.float32).reshape(-1, 1, 2)

    def __repr__(self) -> str:
        return f"Board(rows={self.rows}, cols={self.cols}, corners={len(self)})"


def detect(
    image: np.ndarray,
    corners: Optional[int] = None,
    *,
    sigma: Optional[float] = None,
    reach: Optional[float] = None,
    blur: Optional[float] = None,
    min_board_corners: Optional[int] = None,
    stride: Optional[int] = None,
    refine: str = "board",
    bgr: bool = False,
    pattern: Optional[Tuple[int, int]] = None,
) -> List[Board]:
    """Finds every checkerboard(-like) board in ``image`` and refines its corners.

    Args:
        image: grey (H×W) or colour (H×W×3 / H×W×4) ``uint8``/``uint16``/``float32``/``float64``.
        corners: expected number of corners N (> 0) if known: the 2·N strongest candidates are
            kept. ``None`` uses an adaptive threshold.
        sigma: scale (px) of the Hessian pre-filter, in 0.5..=32 (default 2; raise it for very
            blurred or very large squares).
        reach: farthest distance (px) an edge walk goes from a corner, 5..=10000 (default 100;
            on a board it also stops at the next corner).
        blur: Gaussian blur σ (px) of the image if known, 0..=20; estimated when ``None``.
        min_board_corners: smallest board kept, ≥ 4 (default 4).
        stride: scanlines between consecutive edge samples, 1..=64 (default 2 here, as in the
            CLI's ``detect``; 1 gains the last thousandths of a pixel at ~1.6× the time).
        refine: how corners are placed (the CLI's ``--refine``): ``"board"`` (default) fits the
            row and column curves along the whole board and intersects them, the more accurate;
            ``"local"`` refines each corner on its own, as
            :func:`refine` does.
        bgr: colour images are in OpenCV's B, G, R order.
        pattern: ``(rows, cols)`` of the board's inner corners, each ≥ 2, when known (a
            calibration target; OpenCV's ``patternSize=(w, h)`` is ``(h, w)`` here): boards that
            span it are labelled in its frame, ``(0, 0)`` where the print says (the first square
            dark; if the colours cannot tell, the corner nearest the image's top-left), so that
            every view labels each physical corner alike; other boards are dropped (the CLI's
            ``--pattern ROWSxCOLS``).

    Returns:
        The boards, largest first; empty when no board is in view. Equal to the CLI's output on
        the same image and parameters.

    Raises:
        TypeError: unsupported dtype, or ``image`` not an array.
        ValueError: bad shape, empty or non-finite image, parameter out of range, ``refine`` not
            ``"board"`` or ``"local"``.
    """
    raw = _native.detect(
        _as_array(image),
        corners,
        sigma=sigma,
        reach=reach,
        blur=blur,
        min_board_corners=min_board_corners,
        stride=stride,
        refine=refine,
        bgr=bgr,
        pattern=pattern,
    )
    return [Board(**b) for b in raw]


def refine(
    image: np.ndarray,
    points: np.ndarray,
    *,
    reach: Optional[float] = None,
    stride: Optional[int] = None,
    blur: Optional[float] = None,
    bgr: bool = False,
    return_residuals: bool = False,
    return_covariances: bool = False,
):
    """Refines approximate corner positions (up to ~2 px off) to subpixel accuracy.

    A drop-in for ``cv2.cornerSubPix``: ``points`` may be N×2 or N×1×2, ``float32`` or
    ``float64``; the refined points come back in the same shape and dtype (a new array; the input
    is not modified).

    Args:
        image: grey (H×W) or colour (H×W×3 / H×W×4) ``uint8``/``uint16``/``float32``/``float64``.
        points: approximate corners, x then y.
        reach: farthest distance (px) an edge walk goes from a corner, 5..=10000 (default 100).
        stride: scanlines between consecutive edge samples, 1..=64 (default 1).
        blur: Gaussian blur σ (px) of the image if known, 0..=20; estimated when ``None``.
        bgr: colour images are in OpenCV's B, G, R order.
        return_residuals: also return the N ``float64`` RMS fit residuals (px, NaN where failed).
        return_covariances: also return the N×2×2 ``float64`` covariances (px²,
            ``[[xx, xy], [xy, yy]]``) of the refined positions, propagated from the fits (the
            square root of the larger eigenvalue is the CLI's ``sigma``); NaN where failed.

    Returns:
        ``(refined, status)``, followed by ``residuals`` and then ``covariances`` when asked
        for: ``status`` is an N ``uint8`` array of codes: 0 :data:`FAILED` (the start position
        is returned: not at a corner, outside the image, …), 1 :data:`FALLBACK`, 2
        :data:`CONVERGED`.

    Raises:
        TypeError: unsupported dtype (image, or points not float32/float64).
        ValueError: bad shape, empty image or points, NaN/inf points, parameter out of range.
    """
    refined, status, residuals, covariances = _native.refine(
        _as_array(image),
        _as_array(points),
        reach=reach,
        stride=stride,
        blur=blur,
        bgr=bgr,
    )
    out = (refined, status)
    if return_residuals:
        out += (residuals,)
    if return_covariances:
        out += (covariances,)
    return out


def _as_array(a) -> np.ndarray:
    """Lists and other array-likes become arrays (their dtype is then checked by the core)."""
    if isinstance(a, np.ndarray):
        return a
    try:
        return np.asarray(a)
    except Exception as e:  # ragged lists and the like
        raise ValueError(f"cannot convert {type(a).__name__} to an array: {e}") from e
