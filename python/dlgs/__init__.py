"""dlgs: language-embedded dynamic Gaussian splatting video (.dlgs) from Python.

Reading: :func:`open` -> :class:`Reader` (``info``, ``frame``, ``render``, ``query``, ``gop``,
``cameras``, iteration). Writing: :class:`Writer` (one ``write_gop`` per GOP),
:func:`encode_scene` (still scenes). Other splat formats: :func:`read_scene`,
:func:`write_scene`. Metrics: :func:`compare`.

Arrays going in may be any array-like (numpy, CPU torch tensors): they are converted to
C-contiguous float32 (no copy when they already are). Arrays coming out are float32 numpy
arrays that own the decoder's buffers (no copy).

Licence: see ``LICENSE_NOTE`` (the default wheel links FFmpeg/libx265 and is GPL).
"""

from __future__ import annotations

from typing import Any, Callable, Mapping, Optional, Sequence, Union
import os

import numpy as np

from . import _dlgs
from ._dlgs import (  # noqa: F401  (re-exported)
    DlgsError,
    DlgsIoError,
    FormatError,
    InputError,
    LimitError,
    NoHevcDecoderError,
    Reader,
    RequestError,
    HAS_HEVC,
    LICENSE_NOTE,
    __version__,
    compare,
    open,
    read_scene,
)

__all__ = [
    "open", "Reader", "Writer", "encode_scene", "read_scene", "write_scene", "compare",
    "DlgsError", "FormatError", "LimitError", "DlgsIoError", "RequestError", "InputError",
    "NoHevcDecoderError", "HAS_HEVC", "LICENSE_NOTE", "__version__",
]

_GAUSSIAN_KEYS = (
    "positions", "log_scales", "rotations", "opacities", "sh", "lang_features", "lang_opacities",
)


def _f32(a: Any) -> np.ndarray:
    """``a`` as a C-contiguous float32 array (the same array when it already is one)."""
    if hasattr(a, "detach"):  # torch tensors
        a = a.detach().cpu().numpy()
    return np.ascontiguousarray(a, dtype=np.float32)


def _gaussians(d: Optional[Mapping[str, Any]]) -> Optional[dict]:
    if d is None:
        return None
    return {k: _f32(v) for k, v in d.items() if k in _GAUSSIAN_KEYS and v is not None}


def _residual_field(f: Optional[Mapping[str, Any]]) -> Optional[dict]:
    if f is None:
        return None
    out = dict(f)
    out["planes"] = [np.ascontiguousarray(p, dtype=np.uint8) for p in f["planes"]]
    out["gate"] = np.ascontiguousarray(f["gate"], dtype=np.uint8)
    out["mlp"] = {k: _f32(v) for k, v in f["mlp"].items()}
    return out


def write_scene(path: Union[str, os.PathLike], scene: Mapping[str, Any], spz_version: int = 3,
                format: Optional[str] = None) -> int:
    """Write ``scene`` (dict of arrays, as :func:`read_scene` returns) as INRIA PLY (``.ply``),
    SPZ (``.spz``, v3 or v2), antimatter15 ``.splat`` or PlayCanvas SOG (``.sog``, or a path
    named ``meta.json`` for the unbundled files). ``format`` (``"ply"``, ``"spz"``, ``"splat"``,
    ``"sog"``) overrides the extension. Returns the bytes written."""
    return _dlgs.write_scene(path, _gaussians(scene), spz_version, format)


if HAS_HEVC:

    def encode_scene(
        scene: Mapping[str, Any],
        path: Union[str, os.PathLike],
        quality: str = "high",
        zstd_level: int = 9,
        meta: Any = None,
    ) -> int:
        """Encode a still scene (dict of arrays) as ``dlgs encode SCENE -o PATH --no-meta``
        does (``meta`` adds a META chunk). Returns the file's size in bytes."""
        return _dlgs.encode_scene(_gaussians(scene), path, quality, zstd_level, meta)

    class Writer:
        """Write a ``.dlgs`` one GOP at a time from a trained model's arrays.

        With ``gop_count`` each GOP is encoded when written; without it GOPs are kept in
        memory and encoded by :meth:`close` (the header stores the GOP count). The file
        appears at ``path`` on :meth:`close` (``path + ".partial"`` until then). Options are
        those of ``dlgs encode``; the bytes are the CLI's for the same model and options.
        ``progress(done, total)`` is called after each encoded GOP.
        """

        def __init__(
            self,
            path: Union[str, os.PathLike],
            fps: float = 30.0,
            gop_length: int = 1,
            quality: str = "lossless",
            crf: int = 6,
            preset: str = "medium",
            exact_features: bool = False,
            lossless_features: bool = False,
            intra_features: bool = False,
            per_gop_range: bool = False,
            mlp_f16: bool = False,
            zstd_level: int = 9,
            residual_mode: str = "intra",
            deform_model: str = "reference",
            gop_count: Optional[int] = None,
            frame_count: Optional[int] = None,
            meta: Any = None,
            lang_decoder: Optional[Union[str, os.PathLike]] = None,
            negatives: Any = None,
            progress: Optional[Callable[[int, int], Any]] = None,
            fast_start: str = "first",
            quantised_features: Optional[int] = None,
        ) -> None:
            # quantised_features: time features quantised to this many bits (6-12) and coded
            # with zstd (TFEA codec 4, `--quantised-features`), the web player's codec.
            self._w = _dlgs.Writer(
                path, fps, gop_length, quality, crf, preset, exact_features, lossless_features,
                intra_features, per_gop_range, mlp_f16, zstd_level, residual_mode, deform_model,
                gop_count, frame_count, meta, lang_decoder,
                None if negatives is None else _f32(negatives), progress, fast_start,
                quantised_features=quantised_features,
            )

        def write_gop(
            self,
            static: Optional[Mapping[str, Any]] = None,
            dynamic: Optional[Mapping[str, Any]] = None,
            time_features: Any = None,
            decoders: Optional[Mapping[str, Sequence[Any]]] = None,
            scale_offsets: Optional[bool] = None,
            residual_field: Optional[Mapping[str, Any]] = None,
        ) -> None:
            """Append the next GOP: canonical ``static`` and ``dynamic`` sets (dicts of
            arrays), key ``time_features`` (N_dyn, K, 16) and ``decoders`` (role -> list of
            bias-free (out, in) weight matrices; roles deform, cov, opacity, color, lang).
            ``scale_offsets`` defaults to the reference's rule: from GOP 1 on.
            In sequential/parallel scenes a GOP after the first may instead give its binary
            voxel residual field (``residual_field``, as :meth:`Reader.gop` returns it; no
            canonical sets): it is stored as it is (``RNTC``)."""
            dec = None
            if decoders is not None:
                dec = {k: [_f32(w) for w in v] for k, v in decoders.items()}
            tf = None if time_features is None else _f32(time_features)
            self._w.write_gop(_gaussians(static), _gaussians(dynamic), tf, dec, scale_offsets,
                              _residual_field(residual_field))

        def close(self) -> int:
            """Finish the file and move it into place; returns its size in bytes."""
            return self._w.close()

        def __enter__(self) -> "Writer":
            return self

        def __exit__(self, exc_type, exc, tb) -> bool:
            return self._w.__exit__(exc_type, exc, tb)
