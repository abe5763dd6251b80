"""Type stubs of the compiled module ``dlgs._dlgs`` (the package ``dlgs`` re-exports it)."""

import os
from typing import Any, Callable, Dict, Iterator, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

F32 = npt.NDArray[np.float32]
Frame = Dict[str, F32]
"""Keys: positions (N,3), log_scales (N,3) natural log, rotations (N,4) w,x,y,z not normalised,
opacities (N,) pre-sigmoid, sh (N,coeffs,3) DC first, and with language lang_features (N,L)
and lang_opacities (N,) pre-sigmoid."""
CameraJson = Dict[str, Any]
"""A 3DGS cameras.json entry: width, height, position, rotation (camera-to-world rows), fx, fy."""
Camera = Union[CameraJson, Tuple[Any, Any, float, float, int, int], int]
"""A cameras.json entry, (R, T, fx, fy, W, H) as 3DGS's Camera, or an orbit view index 0..7."""
PathLike = Union[str, os.PathLike]

__version__: str
LICENSE_NOTE: str
HAS_HEVC: bool

class DlgsError(Exception):
    """Base of every dlgs error."""
    kind: str
    """Format, Limit, Io, Request, Input or NoHevcDecoder."""
    name: str
    """The fault's stable name (format faults: BadMagic, Truncated, PayloadCrc, ...)."""
    offset: Optional[int]
    """Byte in the file where the fault was found, when tied to a place."""
    message: str

class FormatError(DlgsError): ...
class LimitError(DlgsError): ...
class DlgsIoError(DlgsError): ...
class RequestError(DlgsError): ...
class InputError(DlgsError): ...
class NoHevcDecoderError(DlgsError): ...

class Reader:
    """An open .dlgs stream. Methods release the GIL while decoding and rendering."""
    @property
    def info(self) -> Dict[str, Any]:
        """version, gop_count, gop_length, key_interval, frame_count, fps, duration, n_static,
        n_dynamic, n_gaussians, sh_degree, lang_levels, lang_dims, lang_width, language,
        time_channels, variant, residual_mode, deform_model."""
    def __len__(self) -> int:
        """Frames in the stream."""
    def __iter__(self) -> Iterator[Tuple[float, Frame]]:
        """(t, frame) for every frame."""
    def frame(self, t: float, camera: Optional[Camera] = None, language: bool = False,
              split: bool = False, cull: bool = False, neural: bool = False
              ) -> Union[Frame, Dict[str, Frame]]:
        """The Gaussians at t seconds (between frames too): static then dynamic in one dict,
        or {"static": ..., "dynamic": ...} with split=True (static arrays shared and
        read-only within a GOP). camera: viewpoint of the view-dependent decoders (None:
        the origin). language: evaluate the language decoder of dynamic Gaussians.
        Scaffold-GS files (info["variant"] == "scaffold"): camera is required (ValueError
        without it); cull: decode only the anchors in the camera's view; neural: the MLP
        outputs (scales, colors RGB, tanh opacities, anchor, offset) instead of the 3DGS
        form (SH DC, log-scales, opacity logits)."""
    def render(self, t: float, camera: Camera, width: Optional[int] = None,
               height: Optional[int] = None, features: bool = False,
               background: Tuple[float, float, float] = (1.0, 1.0, 1.0), cull: bool = True,
               fast: bool = False) -> Union[F32, Tuple[F32, F32]]:
        """HxWx3 linear colour (not clamped); with features=True also the HxWxL language
        feature image; fast=True: the faster compositing of `dlgs render --fast-render`."""
    def query(self, text_embedding: Any, t: float, camera: Camera, width: Optional[int] = None,
              height: Optional[int] = None, negatives: Any = None,
              lang_decoder: Optional[PathLike] = None, threshold: float = 0.4,
              mean_kernel: int = 29, smooth_kernel: int = 7, min_score: float = 0.5,
              level: Optional[int] = None, temperature: float = 10.0, exact: bool = False
              ) -> Union[Dict[str, Any], List[Dict[str, Any]]]:
        """Open-vocabulary query: relevance (levels,H,W), normalised (levels,H,W), scores,
        level (chosen, 0-based), mask (H,W) bool. A (K,D) embedding gives a list of K."""
    def gop(self, g: int) -> Dict[str, Any]:
        """GOP g as Writer.write_gop takes it: static, dynamic, time_features (N_dyn,K,16),
        decoders (role -> [(out,in) weights]), scale_offsets, and residual_field (planes,
        gate, mlp, shapes, bounds, groups, sets) when the GOP is stored as RNTC."""
    def cameras(self, count: int = 8, width: int = 1352, height: int = 1014,
                t: float = 0.0) -> List[CameraJson]:
        """The orbit `dlgs cameras` writes, as cameras.json entries."""
    def time_frame_at(self, times: Sequence[float], language: bool = False) -> List[float]:
        """Seconds of each Rust frame_at(t) (the baseline of the overhead benchmark)."""
    def time_frame_span(self, times: Sequence[float], language: bool = False
                        ) -> Tuple[float, float, List[float]]:
        """As time_frame_at, plus the start and end of the call (seconds on a process-wide
        clock, read with the GIL released)."""

class FrameIter:
    def __iter__(self) -> "FrameIter": ...
    def __next__(self) -> Tuple[float, Frame]: ...

class Writer:
    """Use dlgs.Writer (the package's wrapper converts arrays)."""
    def __init__(self, path: PathLike, fps: float, gop_length: int, quality: str, crf: int,
                 preset: str, exact_features: bool, lossless_features: bool,
                 intra_features: bool, per_gop_range: bool, mlp_f16: bool, zstd_level: int,
                 residual_mode: str, deform_model: str, gop_count: Optional[int],
                 frame_count: Optional[int], meta: Any, lang_decoder: Optional[PathLike],
                 negatives: Optional[F32], progress: Optional[Callable[[int, int], Any]],
                 fast_start: str = "first", max_compression: bool = False,
                 quantised_features: Optional[int] = None) -> None: ...
    def write_gop(self, static_set: Optional[Frame] = None, dynamic: Optional[Frame] = None,
                  time_features: Optional[F32] = None,
                  decoders: Optional[Mapping[str, Sequence[F32]]] = None,
                  scale_offsets: Optional[bool] = None,
                  residual_field: Optional[Mapping[str, Any]] = None) -> None: ...
    def close(self) -> int: ...
    def __enter__(self) -> "Writer": ...
    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> bool: ...

def open(source: Union[PathLike, bytes, bytearray, memoryview],
         threads: Optional[int] = None, read_ahead: bool = True) -> Reader:
    """Open a .dlgs file (path) or stream held in memory (bytes-like). threads: this reader's
    own worker threads (default: the process-wide pool, one per core). read_ahead: while
    frames are asked for in time order, decode the next GOP on a background thread (3DGS
    files; the frames are the same bits either way)."""
def read_scene(path: PathLike) -> Frame:
    """Read a PLY, .splat, SPZ or SOG (.sog / meta.json) scene."""
def write_scene(path: PathLike, scene: Frame, spz_version: int = 3,
                format: Optional[str] = None) -> int:
    """Write .ply (with language extras), .spz (v3 or v2) or .splat; returns the bytes."""
def encode_scene(scene: Frame, path: PathLike, quality: str = "high", zstd_level: int = 9,
                 meta: Any = None) -> int:
    """Encode a still scene as `dlgs encode SCENE -o PATH --no-meta`; returns the size."""
def compare(a: PathLike, b: PathLike, cameras: Optional[Sequence[Camera]] = None,
            t: float = 0.0, background: Tuple[float, float, float] = (1.0, 1.0, 1.0)
            ) -> Dict[str, Any]:
    """PSNR / SSIM per view and means of two scene files rendered from the same cameras."""
