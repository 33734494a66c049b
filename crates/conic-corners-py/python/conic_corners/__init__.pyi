"""Type stub of conic_corners: subpixel checkerboard corners (numpy arrays in and out).

Coordinates: x right, y down, the centre of the top-left pixel is (0, 0) (OpenCV's convention).
"""

from typing import List, Literal, Optional, Tuple, overload

import numpy as np
import numpy.typing as npt

FAILED: int
"""Status 0: no result, the start position is returned."""
FALLBACK: int
"""Status 1: a result with less support (one-sided edge, straight lines)."""
CONVERGED: int
"""Status 2: both edges fitted on both sides of the corner."""
STATUS_NAMES: Tuple[str, str, str]
"""Status code -> name ("failed", "fallback", "converged")."""
PATH_LOCAL: int
"""Path 0: placed by the single-corner refiner."""
PATH_BOARD: int
"""Path 1: intersection of the board-wide row and column curves."""
PATH_GRADIENT: int
"""Path 2: placed by the gradient-orthogonality estimate (last resort)."""
PATH_JUNCTION: int
"""Path 3: placed by the blurred X-junction model fitted to its pixels."""
PATH_HAIRLINE: int
"""Path 4: placed where the board's boundary line meets the grid line into it, beside hairline slivers at a silhouette."""
PATH_NAMES: Tuple[str, str, str, str, str]
"""Path code -> name ("local", "board", "gradient", "junction", "hairline")."""

class Board:
    """One detected board: its labelled corners sorted by (row, col)."""

    rows: int
    cols: int
    points: npt.NDArray[np.float64]
    """N×2 subpixel positions, x then y."""
    ids: npt.NDArray[np.int32]
    """N×2 grid labels, row then col."""
    scores: npt.NDArray[np.float64]
    """N template-matching scores."""
    status: npt.NDArray[np.uint8]
    """N status codes (FAILED, FALLBACK, CONVERGED)."""
    residuals: npt.NDArray[np.float64]
    """N RMS fit residuals in px, NaN where not refined."""
    paths: npt.NDArray[np.uint8]
    """N path codes (PATH_LOCAL, PATH_BOARD, PATH_GRADIENT, PATH_JUNCTION, PATH_HAIRLINE)."""
    sigmas: npt.NDArray[np.float64]
    """N standard deviations (px, worst direction) of the positions, NaN where refinement failed."""
    covariances: npt.NDArray[np.float64]
    """N×2×2 covariances (px²) of the positions, NaN where refinement failed."""
    sigma_scale: Optional[float]
    """Factor already applied to every sigma (a-posteriori, from the grid's smoothness), or None."""
    def __init__(
        self,
        rows: int,
        cols: int,
        points: npt.NDArray[np.float64],
        ids: npt.NDArray[np.int32],
        scores: npt.NDArray[np.float64],
        status: npt.NDArray[np.uint8],
        residuals: npt.NDArray[np.float64],
        paths: npt.NDArray[np.uint8],
        sigmas: npt.NDArray[np.float64],
        covariances: npt.NDArray[np.float64],
        sigma_scale: Optional[float] = None,
    ) -> None: ...
    def __len__(self) -> int: ...
    @property
    def status_names(self) -> List[str]: ...
    @property
    def path_names(self) -> List[str]: ...
    def object_points(self, square_size: float = 1.0) -> npt.NDArray[np.float32]:
        """N×3 (col·s, row·s, 0) in the order of points, for cv2.calibrateCamera."""
    def image_points(self) -> npt.NDArray[np.float32]:
        """N×1×2 float32 copy of points (OpenCV's imagePoints layout)."""

def detect(
    image: npt.ArrayLike,
    corners: Optional[int] = None,
    *,
    sigma: Optional[float] = None,
    reach: Optional[float] = None,
    blur: Optional[float] = None,
    min_board_corners: Optional[int] = None,
    stride: Optional[int] = None,
    refine: Literal["board", "local"] = "board",
    bgr: bool = False,
    pattern: Optional[Tuple[int, int]] = None,
) -> List[Board]:
    """Finds every board in a grey or colour image; boards largest first."""

@overload
def refine(
    image: npt.ArrayLike,
    points: npt.NDArray[np.floating],
    *,
    reach: Optional[float] = None,
    stride: Optional[int] = None,
    blur: Optional[float] = None,
    bgr: bool = False,
    return_residuals: Literal[False] = False,
    return_covariances: Literal[False] = False,
) -> Tuple[npt.NDArray[np.floating], npt.NDArray[np.uint8]]:
    """Refines N×2 / N×1×2 float32/float64 points; returns (points like the input, status)."""
@overload
def refine(
    image: npt.ArrayLike,
    points: npt.NDArray[np.floating],
    *,
    reach: Optional[float] = None,
    stride: Optional[int] = None,
    blur: Optional[float] = None,
    bgr: bool = False,
    return_residuals: Literal[True],
    return_covariances: Literal[False] = False,
) -> Tuple[npt.NDArray[np.floating], npt.NDArray[np.uint8], npt.NDArray[np.float64]]:
    """Refines points; returns (points like the input, status, residuals)."""
@overload
def refine(
    image: npt.ArrayLike,
    points: npt.NDArray[np.floating],
    *,
    reach: Optional[float] = None,
    stride: Optional[int] = None,
    blur: Optional[float] = None,
    bgr: bool = False,
    return_residuals: Literal[False] = False,
    return_covariances: Literal[True],
) -> Tuple[npt.NDArray[np.floating], npt.NDArray[np.uint8], npt.NDArray[np.float64]]:
    """Refines points; returns (points like the input, status, N×2×2 covariances in px²)."""
@overload
def refine(
    image: npt.ArrayLike,
    points: npt.NDArray[np.floating],
    *,
    reach: Optional[float] = None,
    stride: Optional[int] = None,
    blur: Optional[float] = None,
    bgr: bool = False,
    return_residuals: Literal[True],
    return_covariances: Literal[True],
) -> Tuple[
    npt.NDArray[np.floating], npt.NDArray[np.uint8], npt.NDArray[np.float64], npt.NDArray[np.float64]
]:
    """Refines points; returns (points like the input, status, residuals, covariances)."""
