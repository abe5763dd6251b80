"""A minimal PNG reader (8-bit RGB, non-interlaced: what `dlgs render` writes), so the tests
compare the CLI's images without an imaging dependency."""

import struct
import zlib

import numpy as np


def read_png_rgb8(path) -> np.ndarray:
    """An 8-bit RGB PNG as (H, W, 3) uint8."""
    return read_png8(path, 3)


def read_png8(path, channels: int) -> np.ndarray:
    """An 8-bit PNG with `channels` (1 gray, 3 RGB) as (H, W, channels) uint8."""
    data = open(path, "rb").read()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
    pos, idat, w = 8, b"", None
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            w, h, depth, ctype, _, _, interlace = struct.unpack(">IIBBBBB", body)
            want = {1: 0, 3: 2}[channels]
            assert (depth, ctype, interlace) == (8, want, 0), "8-bit gray or RGB, not interlaced"
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    raw = zlib.decompress(idat)
    bpp, stride = channels, w * channels
    out = np.zeros((h, stride), np.uint8)
    prev = np.zeros(stride, np.int32)
    for y in range(h):
        f = raw[y * (stride + 1)]
        line = np.frombuffer(raw, np.uint8, stride, y * (stride + 1) + 1).astype(np.int32)
        cur = np.zeros(stride, np.int32)
        if f == 0:
            cur = line
        elif f == 2:
            cur = (line + prev) & 255
        else:
            for x in range(stride):
                a = cur[x - bpp] if x >= bpp else 0
                b = prev[x]
                c = prev[x - bpp] if x >= bpp else 0
                if f == 1:
                    p = a
                elif f == 3:
                    p = (a + b) // 2
                else:  # Paeth
                    pa, pb, pc = abs(b - c), abs(a - c), abs(a + b - 2 * c)
                    p = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
                cur[x] = (line[x] + p) & 255
        out[y] = cur
        prev = cur
    return out.reshape(h, w, channels)


def quantise(rgb: np.ndarray) -> np.ndarray:
    """The CLI's float -> 8-bit mapping (`image_out::save_rgb_png`)."""
    return (np.clip(rgb, 0.0, 1.0) * np.float32(255.0) + np.float32(0.5)).astype(np.uint8)
