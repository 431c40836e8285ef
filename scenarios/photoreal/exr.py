"""A small OpenEXR reader: the scanline files Blender writes (half or float channels; NONE, ZIPS or ZIP).

The project's OpenCV wheel is built without its OpenEXR codec (``cv2.imread`` of an ``.exr`` fails even with
``OPENCV_IO_ENABLE_OPENEXR=1``), and the linear radiance must not be clipped or quantised to 8 or 16 bits before
the camera model sees it, so the subset of the format Blender's renders use is read here (OpenEXR file layout:
magic, header attributes, offset table, chunks of scanlines with the channels in alphabetical order).
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np

from ..errors import ImageError

MAGIC = 20000630
#: Pixel types: UINT, HALF, FLOAT.
DTYPES = {0: np.dtype("<u4"), 1: np.dtype("<f2"), 2: np.dtype("<f4")}
#: compression -> scanlines per chunk (only the codecs read here)
LINES = {0: 1, 2: 1, 3: 16}
NAMES = {0: "NONE", 1: "RLE", 2: "ZIPS", 3: "ZIP", 4: "PIZ", 5: "PXR24", 6: "B44", 7: "B44A", 8: "DWAA", 9: "DWAB"}


def _cstring(data: bytes, pos: int) -> tuple[str, int]:
    end = data.index(b"\0", pos)
    return data[pos:end].decode("latin-1"), end + 1


def _header(data: bytes, path) -> tuple[dict, int]:
    magic, version = struct.unpack_from("<ii", data, 0)
    if magic != MAGIC:
        raise ImageError(f"{path}: not an OpenEXR file")
    if version & 0x200 or version & 0x1000 or version & 0x800 and False:
        raise ImageError(f"{path}: tiled or multi-part OpenEXR is not supported (Blender writes scanlines)")
    pos, attrs = 8, {}
    while True:
        name, pos = _cstring(data, pos)
        if not name:
            return attrs, pos
        kind, pos = _cstring(data, pos)
        (size,) = struct.unpack_from("<i", data, pos)
        pos += 4
        attrs[name] = (kind, data[pos:pos + size])
        pos += size


def _channels(raw: bytes) -> list[tuple[str, int]]:
    out, pos = [], 0
    while True:
        name, pos = _cstring(raw, pos)
        if not name:
            return out
        pixel_type, _linear, xs, ys = struct.unpack_from("<iB3xii", raw, pos)
        pos += 16
        if xs != 1 or ys != 1:
            raise ValueError(f"channel {name}: subsampled channels are not supported")
        out.append((name, pixel_type))


def _unzip(block: bytes, size: int) -> bytes:
    """OpenEXR's ZIP(S) block: zlib, then undo the byte predictor and the even/odd byte split."""
    if len(block) >= size:  # stored uncompressed when compression did not help
        return block
    t = np.frombuffer(zlib.decompress(block), np.uint8)
    t = (np.cumsum(t.astype(np.int64) - np.r_[0, np.full(len(t) - 1, 128)]) & 0xFF).astype(np.uint8)
    out = np.empty_like(t)
    half = (len(t) + 1) // 2
    out[0::2], out[1::2] = t[:half], t[half:]
    return out.tobytes()


def read_exr(path: str | Path) -> np.ndarray:
    """Linear BGR radiance of an OpenEXR file, float32, shape (H, W, 3) (R, G, B channels; a layer prefix
    such as ``Image.R`` is ignored).

    Raises
    ------
    ImageError
        Not a readable scanline OpenEXR file with R, G and B, or a codec other than NONE, ZIPS, ZIP.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as err:
        raise ImageError(f"{path}: cannot read: {err.strerror or err}") from None
    try:
        attrs, pos = _header(data, path)
        channels = _channels(attrs["channels"][1])
        compression = attrs["compression"][1][0]
        xmin, ymin, xmax, ymax = struct.unpack("<iiii", attrs["dataWindow"][1])
    except (KeyError, ValueError, struct.error, IndexError) as err:
        raise ImageError(f"{path}: unreadable OpenEXR header ({err})") from None
    if compression not in LINES:
        raise ImageError(f"{path}: OpenEXR compression {NAMES.get(compression, compression)} is not supported "
                         "(NONE, ZIPS, ZIP are)")
    width, height = xmax - xmin + 1, ymax - ymin + 1
    lines = LINES[compression]
    chunks = -(-height // lines)
    offsets = np.frombuffer(data, "<u8", chunks, pos)
    planes = {name: np.zeros((height, width), np.float32) for name, _ in channels}
    row_bytes = sum(DTYPES[t].itemsize for _, t in channels) * width
    try:
        for offset in offsets:
            y, size = struct.unpack_from("<ii", data, int(offset))
            n = min(lines, ymax - y + 1)
            block = data[int(offset) + 8:int(offset) + 8 + size]
            raw = _unzip(block, n * row_bytes) if compression else block
            at = 0
            for row in range(y - ymin, y - ymin + n):
                for name, kind in channels:
                    dtype = DTYPES[kind]
                    planes[name][row] = np.frombuffer(raw, dtype, width, at)
                    at += dtype.itemsize * width
    except (ValueError, struct.error, zlib.error) as err:
        raise ImageError(f"{path}: corrupt OpenEXR data ({err})") from None
    by_suffix = {name.rsplit(".", 1)[-1]: plane for name, plane in planes.items()}
    if not {"R", "G", "B"} <= set(by_suffix):
        raise ImageError(f"{path}: OpenEXR without R, G, B channels (has {', '.join(planes)})")
    return np.dstack([by_suffix["B"], by_suffix["G"], by_suffix["R"]])
