"""Images: colour / grey images, depth images and PFM float images.

- :func:`read_image` returns **RGB** (not OpenCV's BGR), ``(H, W, 3)`` uint8 (``(H, W, 4)`` RGBA,
  ``(H, W)`` grey); 16-bit files stay uint16.
- :func:`read_depth` turns a 16-bit depth image into metres: ``metres = raw / scale`` (``scale``
  = 1000 for millimetre files such as Kinect / slambook, 5000 for TUM RGB-D); raw 0 -> NaN.
- :func:`read_pfm` / :func:`write_pfm`: the Portable Float Map (Middlebury disparities). The
  sign of the scale line gives the byte order (negative = little-endian); rows are stored
  bottom-up in the file and returned top-down; ``inf`` (Middlebury's "unknown") is kept.
- Writers are atomic (a temporary file with the same suffix replaces the target on success).
"""

from __future__ import annotations

import logging
import os
import re
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import DataNotFoundError, FormatError, InputError
from navkit.io.atomic import atomic_path, atomic_write

__all__ = ["read_depth", "read_image", "read_pfm", "write_depth", "write_image", "write_pfm"]

log = logging.getLogger(__name__)

PathLike = str | os.PathLike[str]


def _existing(path: PathLike) -> Path:
    p = Path(path)
    if not p.is_file():
        raise DataNotFoundError(f"{p}: no such file")
    return p


def _imread(p: Path) -> NDArray[Any]:
    # np.fromfile + imdecode also handles non-ASCII paths, which cv2.imread does not
    data = np.fromfile(p, dtype=np.uint8)
    try:
        img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    except cv2.error:
        img = None
    if img is None:
        raise FormatError(
            "cannot be decoded as an image",
            source=p,
            field="image",
            expected="a PNG, JPEG, PGM/PPM, BMP or TIFF file",
        )
    return img


def read_image(path: PathLike) -> NDArray[Any]:
    """Read an image as RGB(A) or grey, keeping its bit depth.

    Returns
    -------
    (H, W, 3) RGB, (H, W, 4) RGBA or (H, W) grey array
        uint8, or uint16 for 16-bit files.
    """
    p = _existing(path)
    img = _imread(p)
    if img.ndim == 3 and img.shape[2] == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    elif img.ndim == 3 and img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2RGBA)
    return np.ascontiguousarray(img)


def write_image(path: PathLike, image: ArrayLike) -> None:
    """Write an RGB(A) or grey image atomically; the format follows the suffix (``.png``, ...).

    ``image``: ``(H, W)``, ``(H, W, 3)`` RGB or ``(H, W, 4)`` RGBA, uint8 or uint16 (PNG/PGM/TIFF).
    """
    img = np.asarray(image)
    if img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] not in (1, 3, 4)):
        raise InputError(
            f"image has shape {img.shape}",
            source=path,
            field="image",
            expected="(H, W), (H, W, 3) or (H, W, 4)",
        )
    if img.dtype not in (np.uint8, np.uint16):
        raise InputError(
            f"image has dtype {img.dtype}", source=path, field="image", expected="uint8 or uint16"
        )
    if img.ndim == 3 and img.shape[2] == 3:
        img = cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
    elif img.ndim == 3 and img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_RGBA2BGRA)
    suffix = Path(path).suffix.lower()
    with atomic_path(path) as tmp:
        try:
            ok, buf = cv2.imencode(suffix, img)
        except cv2.error:
            ok = False
        if not ok:
            raise InputError(
                f"OpenCV cannot write {img.dtype} {img.shape} images as {suffix!r}",
                source=path,
                field="suffix",
                expected=".png, .jpg, .pgm, .ppm, .bmp or .tiff",
            )
        buf.tofile(tmp)


def read_depth(path: PathLike, scale: float, *, allow_8bit: bool = False) -> NDArray[np.float64]:
    """Read a depth image in metres.

    Parameters
    ----------
    path : str or path
        A single-channel 16-bit PNG / PGM (or 8-bit, or a float TIFF).
    scale : float
        Raw units per metre: ``metres = raw / scale`` (1000 for millimetres, 5000 for TUM).
    allow_8bit : bool
        Accept an 8-bit image as depth. Off by default: an 8-bit PNG is almost always a
        visualisation of depth (or a grey image), and read in millimetres it would put every
        point within 0.255 m without a word.

    Raises
    ------
    FormatError
        A multi-channel image, or an 8-bit one unless ``allow_8bit``.

    Returns
    -------
    (H, W) float64
        Depth along the optical axis in metres, NaN where the raw value is 0 (no measurement).
    """
    if not (np.isfinite(scale) and scale > 0):
        raise InputError(f"scale {scale!r}", field="scale", expected="a finite positive number")
    p = _existing(path)
    raw = _imread(p)
    if raw.ndim != 2:
        raise FormatError(
            f"depth image has shape {raw.shape}",
            source=p,
            field="depth",
            expected="a single-channel image",
        )
    if raw.dtype.itemsize == 1 and not allow_8bit:
        raise FormatError(
            "is an 8-bit image (a depth visualisation or a grey image?)",
            source=p,
            field="depth",
            expected="a 16-bit depth image (or allow_8bit=True for 8-bit depth)",
        )
    depth = raw.astype(np.float64) / float(scale)
    depth[(raw == 0) | ~np.isfinite(depth)] = np.nan
    return depth


def write_depth(path: PathLike, depth_m: ArrayLike, scale: float = 1000.0) -> None:
    """Write metres as a 16-bit depth PNG/PGM (``raw = round(depth * scale)``, NaN -> 0), atomically."""
    if not scale > 0:
        raise InputError(f"scale {scale!r}", field="scale", expected="a positive number")
    d = np.asarray(depth_m, dtype=np.float64)
    if d.ndim != 2:
        raise InputError(
            f"depth has shape {d.shape}", source=path, field="depth", expected="(H, W)"
        )
    raw = np.round(np.where(np.isfinite(d), d, 0.0) * scale)
    if raw.min(initial=0) < 0 or raw.max(initial=0) > 65535:
        raise InputError(
            f"depth spans [{np.nanmin(d)}, {np.nanmax(d)}] m",
            source=path,
            field="depth",
            expected=f"0 .. {65535 / scale:g} m at scale {scale:g}",
        )
    write_image(path, raw.astype(np.uint16))


_PFM_HEADER = re.compile(rb"^(P[Ff])\s+(\d+)\s+(\d+)\s+([-+0-9.eEinfINF]+)\s")


def read_pfm(path: PathLike) -> NDArray[np.float32]:
    """Read a Portable Float Map.

    Returns
    -------
    (H, W) or (H, W, 3) float32
        Rows top-down (the file stores them bottom-up); ``inf`` kept. The magnitude of the scale
        line is not applied (Middlebury uses it only for the byte order).
    """
    p = _existing(path)
    buf = p.read_bytes()
    m = _PFM_HEADER.match(buf[:256])
    if not m:
        raise FormatError(
            "bad header",
            source=p,
            field="header",
            expected="'PF' or 'Pf', width height, scale (negative = little-endian)",
        )
    channels = 3 if m.group(1) == b"PF" else 1
    width, height = int(m.group(2)), int(m.group(3))
    try:
        scale = float(m.group(4))
    except ValueError:
        raise FormatError("scale is not a number", source=p, field="scale") from None
    if scale == 0 or not np.isfinite(scale):
        raise FormatError(f"scale {scale}", source=p, field="scale", expected="a non-zero number")
    dtype = "<f4" if scale < 0 else ">f4"
    count = width * height * channels
    body = buf[m.end() :]
    if len(body) < 4 * count:
        raise FormatError(
            f"data truncated: {len(body)} bytes",
            source=p,
            field="data",
            expected=f"{4 * count} bytes ({width} x {height} x {channels} float32)",
        )
    data = np.frombuffer(body, dtype=dtype, count=count).astype(np.float32)
    shape = (height, width) if channels == 1 else (height, width, 3)
    return np.ascontiguousarray(data.reshape(shape)[::-1])


def write_pfm(path: PathLike, image: ArrayLike, *, little_endian: bool = True) -> None:
    """Write a ``(H, W)`` or ``(H, W, 3)`` float image as PFM (rows bottom-up), atomically."""
    img = np.asarray(image, dtype=np.float32)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if not (img.ndim == 2 or (img.ndim == 3 and img.shape[2] == 3)):
        raise InputError(
            f"image has shape {img.shape}",
            source=path,
            field="image",
            expected="(H, W) or (H, W, 3)",
        )
    kind = "Pf" if img.ndim == 2 else "PF"
    h, w = img.shape[:2]
    with atomic_write(path, "wb") as fh:
        fh.write(f"{kind}\n{w} {h}\n{-1.0 if little_endian else 1.0}\n".encode("ascii"))
        fh.write(
            np.ascontiguousarray(img[::-1]).astype("<f4" if little_endian else ">f4").tobytes()
        )
