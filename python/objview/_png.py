"""A small PNG decoder (standard library + numpy) for the server's RGB views.

It reads non-interlaced 8-bit greyscale, grey+alpha, RGB and RGBA images (all five row filters),
which covers what ``GET /v1/episodes/{id}/observation/rgb.png`` sends (RGB8).  Pillow, when
installed, is used instead (it is faster); this fallback keeps the package's dependencies to
numpy and gymnasium.
"""

from __future__ import annotations

import io
import struct
import zlib
from typing import List, Optional

import numpy as np

_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_CHANNELS = {0: 1, 2: 3, 4: 2, 6: 4}


def decode_png(data: bytes) -> np.ndarray:
    """Decode PNG bytes into a uint8 array of shape (H, W, C) (C = 3 for RGB)."""
    try:  # pragma: no cover - depends on the environment
        from PIL import Image  # type: ignore

        with Image.open(io.BytesIO(data)) as im:
            return np.asarray(im.convert("RGB") if im.mode not in ("RGB", "RGBA") else im)
    except ImportError:
        pass
    return decode_png_builtin(data)


def decode_png_builtin(data: bytes) -> np.ndarray:
    """Decode PNG bytes without Pillow (see the module docstring for what is supported)."""
    if data[:8] != _SIGNATURE:
        raise ValueError("not a PNG file")
    pos = 8
    idat: List[bytes] = []
    width: Optional[int]
    height: Optional[int]
    width = height = depth = ctype = interlace = None
    while pos + 8 <= len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        kind = data[pos + 4 : pos + 8]
        chunk = data[pos + 8 : pos + 8 + length]
        pos += 12 + length
        if kind == b"IHDR":
            width, height, depth, ctype, _, _, interlace = struct.unpack(">IIBBBBB", chunk)
        elif kind == b"IDAT":
            idat.append(chunk)
        elif kind == b"IEND":
            break
    if width is None or height is None:
        raise ValueError("PNG without IHDR")
    if depth != 8 or ctype not in _CHANNELS or interlace != 0:
        raise ValueError(
            f"unsupported PNG (bit depth {depth}, colour type {ctype}, interlace {interlace}); "
            "install Pillow to read it"
        )
    bpp = _CHANNELS[ctype]
    stride = width * bpp
    raw = np.frombuffer(zlib.decompress(b"".join(idat)), dtype=np.uint8)
    if raw.size != height * (stride + 1):
        raise ValueError("PNG image data has the wrong size")
    rows = raw.reshape(height, stride + 1)
    out = np.zeros((height, stride), dtype=np.uint8)
    prev = np.zeros(stride, dtype=np.int32)
    for y in range(height):
        filt = int(rows[y, 0])
        line = rows[y, 1:].astype(np.int32)
        if filt == 0:
            cur = line
        elif filt == 1:  # Sub: cumulative per channel
            cur = np.cumsum(line.reshape(width, bpp), axis=0).reshape(-1) & 0xFF
        elif filt == 2:  # Up
            cur = (line + prev) & 0xFF
        elif filt in (3, 4):  # Average, Paeth: sequential along the row
            cur = line.copy()
            p = prev.tolist()
            c = cur.tolist()
            for i in range(stride):
                a = c[i - bpp] if i >= bpp else 0
                b = p[i]
                if filt == 3:
                    c[i] = (c[i] + ((a + b) >> 1)) & 0xFF
                else:
                    cc = p[i - bpp] if i >= bpp else 0
                    pa, pb, pc = abs(b - cc), abs(a - cc), abs(a + b - 2 * cc)
                    pred = a if (pa <= pb and pa <= pc) else (b if pb <= pc else cc)
                    c[i] = (c[i] + pred) & 0xFF
            cur = np.asarray(c, dtype=np.int32)
        else:
            raise ValueError(f"PNG row filter {filt} is not defined")
        out[y] = cur
        prev = cur
    return out.reshape(height, width, bpp)
