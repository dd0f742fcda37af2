"""Type stubs of the Python module `regtrack` (the crate's `python` feature)."""

from os import PathLike
from typing import Any, Iterator, Optional, Sequence as Seq, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

Frame = Union[npt.NDArray[np.uint8], npt.NDArray[np.float32]]
"""Grey (H, W) or BGR (H, W, 3) (OpenCV's order), uint8 or float32, any strides. A tracker
with ``channels='rgb'`` reads a BGR frame's three channels (a float one's values rounded into
0..255); every other tracker its grey."""

Corners = Union[npt.ArrayLike, Seq[Seq[float]]]
"""Four points (x, y), shape (4, 2): top-left, top-right, bottom-right, bottom-left."""

class Error(Exception):
    """An error of the library, with the command line's message."""

class Tracker:
    """A registration tracker (search method, appearance model, state space model) or a whole
    tracker (``tracker="kcf"``); keyword arguments set any of its parameters by name."""

    def __init__(
        self,
        sm: Optional[str] = None,
        am: Optional[str] = None,
        ssm: Optional[str] = None,
        *,
        tracker: Optional[str] = None,
        **params: Any,
    ) -> None: ...
    def initialize(self, frame: Frame, corners: Corners) -> None:
        """Starts tracking ``corners`` in ``frame``."""
    def update(
        self, frame: Frame, record: bool = False
    ) -> Tuple[npt.NDArray[np.float64], str]:
        """Tracks one frame: ``(corners (4, 2), status)``; status is ``"tracking"``,
        ``"lost: <reason>"`` or ``"uninitialized"``."""
    def set_corners(self, corners: Corners) -> None:
        """Moves the tracker to ``corners``, keeping its template; resumes a lost tracker."""
    @property
    def corners(self) -> npt.NDArray[np.float64]: ...
    @property
    def status(self) -> str: ...
    @property
    def warped_grid(self) -> Optional[npt.NDArray[np.float64]]:
        """A non-rigid tracker's (``ssm="spline"``, ``"tps"``...) warp as a lattice over its
        target: ``(side, side, 2)`` image points, row by row; ``None`` for the others."""
    @property
    def label(self) -> str: ...
    @property
    def last_update_us(self) -> float:
        """The library's own time in the last initialize or update, microseconds."""
    @property
    def iterations(self) -> Optional[dict[str, npt.NDArray[Any]]]:
        """The last ``update(frame, record=True)``'s iterations: ``level``, ``similarity``,
        ``step``, ``params`` (n, DOF) and ``corners`` (n, 4, 2)."""

class Sequence:
    """A sequence in any layout the command line reads, as ``(frame, ground_truth)`` pairs."""

    def __init__(self, path: Union[str, PathLike[str]], *, colour: bool = False) -> None:
        """With ``colour``, frames are BGR (H, W, 3) uint8 (for ``channels='rgb'``)."""
    @property
    def name(self) -> str: ...
    @property
    def warnings(self) -> list[str]: ...
    @property
    def ground_truth(self) -> npt.NDArray[np.float64]:
        """(n, 4, 2), NaN where a frame is not annotated."""
    def __len__(self) -> int: ...
    def __getitem__(
        self, i: int
    ) -> Tuple[npt.NDArray[np.uint8], Optional[npt.NDArray[np.float64]]]:
        """Frame ``i`` (grey (H, W), or BGR (H, W, 3) with ``colour``) and its corners."""
    def __iter__(
        self,
    ) -> Iterator[Tuple[npt.NDArray[np.uint8], Optional[npt.NDArray[np.float64]]]]: ...

def list_methods() -> dict[str, list[dict[str, Any]]]:
    """Every method by kind (``sm``, ``am``, ``ssm``, ``tracker``): name, aliases, description."""

def list_text() -> str:
    """What ``regtrack list`` prints: every method with its parameters."""

def alignment_error(a: Corners, b: Corners) -> float:
    """The mean distance of the corners of two quads, px."""

def eval(
    dataset: Union[str, PathLike[str]],
    sm: Optional[list[str]] = None,
    am: Optional[list[str]] = None,
    ssm: Optional[list[str]] = None,
    trackers: list[str] = ...,
    seqs: Optional[list[str]] = None,
    out: Optional[Union[str, PathLike[str]]] = None,
    reinit: bool = False,
    gt_ssm: Optional[str] = None,
    error: str = "alignment",
    jobs: int = 0,
    **params: Any,
) -> list[dict[str, Any]]:
    """Evaluates trackers on a dataset (MTF, POT, PlanarTrack, UCSB, VOT, GOT-10k, LaSOT layouts,
    or one sequence) as ``regtrack eval`` does: the summary rows, with the benchmarks' figures
    (``p5``, ``p15``, ``success_h``, ``success_iou``) and ``ALL:<factor>`` rows per challenge
    factor."""

def synth(
    texture: Union[str, PathLike[str]],
    motion: Union[str, PathLike[str]],
    out: Union[str, PathLike[str]],
    name: str,
    **options: Any,
) -> Sequence:
    """Renders a sequence with exact ground truth (MTF layout), as ``regtrack synth`` does."""

class Camera:
    """A live source (``"/dev/video0"``, or ``"lavfi:testsrc=size=320x240:rate=30"``) read by
    ffmpeg, as an iterator of grey uint8 frames (H, W) (with ``colour``, BGR (H, W, 3)), always
    the newest."""

    def __init__(
        self, source: str, size: Tuple[int, int] = (640, 480), *, colour: bool = False
    ) -> None: ...
    @property
    def dropped(self) -> int:
        """Frames the source sent that were never handed out."""
    @property
    def stopped(self) -> Optional[str]:
        """Why the source stopped (None while it runs)."""
    def close(self) -> None: ...
    def __iter__(self) -> Iterator[npt.NDArray[np.uint8]]: ...
    def __next__(self) -> npt.NDArray[np.uint8]: ...

class PatchTracker:
    """Many patches per frame (translation or affine inverse-compositional LK over one shared
    pyramid, in parallel over the cores). Keyword arguments are the many-patch parameters
    (``warp``, ``size``, ``levels``, ``template``, ``min_ncc``, ``fb_max``, ``threads``...;
    ``list_text()`` lists them)."""

    def __init__(self, **params: Any) -> None: ...
    def detect(
        self, frame: Frame, max: int = 1000, region: Optional[Corners] = None
    ) -> npt.NDArray[np.float64]:
        """Shi-Tomasi corners (N, 2) where a whole patch fits (inside ``region`` if given)."""
    def initialize(self, frame: Frame, points: npt.ArrayLike) -> None:
        """Starts a patch centred on each point (N, 2)."""
    def update(
        self, frame: Frame
    ) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
        """Tracks one frame: centres (N, 2) (a lost patch keeps its last good one) and which
        patches are tracking (N,), in the order of the initial points."""
    @property
    def status(self) -> list[str]:
        """``"tracking"`` or ``"lost: <reason>"`` per patch."""
    @property
    def linear(self) -> npt.NDArray[np.float64]:
        """Each patch's linear map (N, 2, 2) (the identity for translation)."""
    @property
    def ncc(self) -> npt.NDArray[np.float64]:
        """Each patch's correlation with its template on the last frame (N,)."""
    @property
    def last_update_us(self) -> float:
        """The library's own time in the last call that took a frame (µs)."""
    def __len__(self) -> int: ...
