"""Stereo calibration files: Middlebury 2014 ``calib.txt``, KITTI ``P2`` / ``P3``, a generic YAML.

All return a :class:`navkit.sensors.StereoRig` in metres and pixels.

- Middlebury 2014 (``calib.txt``): ``cam0=[f 0 cx; 0 f cy; 0 0 1]``, ``cam1=...``, ``doffs``,
  ``baseline`` (millimetres), ``width``, ``height``, ``ndisp``, ``vmin``, ``vmax``.
- KITTI stereo (``calib_cam_to_cam.txt`` with ``P_rect_02`` / ``P_rect_03``, or the odometry /
  object ``calib.txt`` with ``P2:`` / ``P3:``): 3 x 4 projection matrices of the rectified
  colour cameras; ``baseline = (P2[0, 3] - P3[0, 3]) / f`` (the fourth column is ``-f t_x``).
  The image size comes from ``S_rect_02`` when present, else from ``image_size``.
- Generic YAML (``calib.yaml``): ``K: [fx, 0, cx, 0, fy, cy, 0, 0, 1]`` (or nested rows),
  ``baseline: 0.12`` (metres), ``width``, ``height``, optional ``doffs``.

:func:`read_stereo_calib` picks the reader from the file's content.
"""

from __future__ import annotations

import logging
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from navkit.domains import POSITIVE, POSITIVE_INT, Domain, check_intrinsics
from navkit.errors import DataNotFoundError, FormatError
from navkit.io.atomic import write_text
from navkit.sensors import PinholeCamera, StereoRig

__all__ = [
    "StereoFrames",
    "read_generic_yaml_calib",
    "read_kitti_stereo_calib",
    "read_middlebury_calib",
    "read_stereo_calib",
    "read_stereo_frames",
    "write_generic_yaml_calib",
    "write_stereo_frames",
]

log = logging.getLogger(__name__)

PathLike = str | os.PathLike[str]


def _text(path: PathLike) -> tuple[Path, str]:
    p = Path(path)
    if not p.is_file():
        raise DataNotFoundError(f"{p}: no such calibration file")
    try:
        return p, p.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise FormatError(f"cannot be read: {exc}", source=p) from exc


def _numbers(text: str, p: Path, field: str, count: int | None = None) -> np.ndarray:
    vals = re.findall(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?", text)
    arr = np.array([float(v) for v in vals])
    if count is not None and len(arr) != count:
        raise FormatError(
            f"has {len(arr)} numbers", source=p, field=field, expected=f"{count} numbers"
        )
    if not np.isfinite(arr).all():
        raise FormatError("non-finite value", source=p, field=field, expected="finite numbers")
    return arr


#: Domains of the numeric fields of a Middlebury ``calib.txt`` besides ``cam0`` (whose
#: intrinsics are checked by :func:`navkit.domains.check_intrinsics`).
MIDDLEBURY_DOMAINS = {
    "baseline": POSITIVE,  # millimetres
    "doffs": Domain(note="pixels, either sign"),
    "ndisp": POSITIVE_INT,
    "isint": Domain(integer=True, lo=0, hi=1),
    "vmin": Domain(lo=0.0),
    "vmax": Domain(lo=0.0),
    "dyavg": Domain(),
    "dymax": Domain(),
}


def _field(kv: dict[str, str], key: str, p: Path, default: str | None = None) -> float:
    """The number of ``key`` in a ``key=value`` file, checked against its domain."""
    text = kv.get(key, default)
    try:
        value = float(str(text))
    except ValueError:
        raise FormatError(f"is {text!r}", source=p, field=key, expected="a number") from None
    MIDDLEBURY_DOMAINS.get(key, Domain()).check(value, key, source=p, error=FormatError)
    return value


def read_middlebury_calib(path: PathLike) -> tuple[StereoRig, dict[str, float]]:
    """Read a Middlebury 2014 ``calib.txt``; every numeric field is checked against its domain
    (:data:`MIDDLEBURY_DOMAINS`; ``cam0`` as intrinsics inside the ``width`` x ``height`` image).

    Returns
    -------
    rig : StereoRig
        Baseline converted to metres; ``doffs`` in pixels.
    extra : dict
        ``ndisp``, ``vmin``, ``vmax``, ... as floats (whatever the file holds besides).
    """
    p, text = _text(path)
    kv: dict[str, str] = {}
    for line in text.splitlines():
        if "=" in line:
            k, v = line.split("=", 1)
            kv[k.strip()] = v.strip()
    for key in ("cam0", "baseline", "width", "height"):
        if key not in kv:
            raise FormatError(
                "missing",
                source=p,
                field=key,
                expected="a Middlebury 2014 calib.txt (cam0=[...], baseline=, width=, height=)",
            )
    K = _numbers(kv["cam0"], p, "cam0", 9).reshape(3, 3)
    sizes = {k: _field(kv, k, p) for k in ("width", "height")}
    width, height = check_intrinsics(
        {**sizes, "fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2]},
        source=p,
        error=FormatError,
    )
    baseline_mm = _field(kv, "baseline", p)
    doffs = _field(kv, "doffs", p, "0")
    cam = PinholeCamera(
        float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]), width, height
    )
    rig = StereoRig(cam, baseline_mm / 1000.0, doffs)
    extra = {}
    for k, v in kv.items():
        if k in ("cam0", "cam1"):
            continue
        if k in MIDDLEBURY_DOMAINS:
            extra[k] = _field(kv, k, p)
            continue
        try:
            extra[k] = float(v)
        except ValueError:
            pass
    return rig, extra


def read_kitti_stereo_calib(path: PathLike, image_size: tuple[int, int] | None = None) -> StereoRig:
    """Read KITTI rectified projections ``P2`` / ``P3`` (or ``P_rect_02`` / ``P_rect_03``).

    Parameters
    ----------
    image_size : (width, height), optional
        Needed when the file has no ``S_rect_02``.
    """
    p, text = _text(path)
    rows: dict[str, str] = {}
    for line in text.splitlines():
        if ":" in line:
            k, v = line.split(":", 1)
            rows[k.strip()] = v
    names = [("P2", "P3"), ("P_rect_02", "P_rect_03")]
    pair = next((n for n in names if n[0] in rows and n[1] in rows), None)
    if pair is None:
        raise FormatError(
            "no P2/P3 (or P_rect_02/P_rect_03) lines",
            source=p,
            field="P2",
            expected="KITTI calibration with 3x4 rectified projection matrices",
        )
    P2 = _numbers(rows[pair[0]], p, pair[0], 12).reshape(3, 4)
    P3 = _numbers(rows[pair[1]], p, pair[1], 12).reshape(3, 4)
    f = P2[0, 0]
    if not f > 0:
        raise FormatError(f"focal length {f}", source=p, field=pair[0], expected="positive fx")
    baseline = (P2[0, 3] - P3[0, 3]) / f
    if "S_rect_02" in rows:
        w, h = _numbers(rows["S_rect_02"], p, "S_rect_02", 2)
        size = (int(w), int(h))
    elif image_size is not None:
        size = (int(image_size[0]), int(image_size[1]))
    else:
        raise FormatError(
            "no image size",
            source=p,
            field="S_rect_02",
            expected="S_rect_02 in the file, or image_size=(width, height)",
        )
    check_intrinsics(
        {
            "width": size[0],
            "height": size[1],
            "fx": f,
            "fy": P2[1, 1],
            "cx": P2[0, 2],
            "cy": P2[1, 2],
        },
        source=p,
        error=FormatError,
    )
    cam = PinholeCamera(
        float(f), float(P2[1, 1]), float(P2[0, 2]), float(P2[1, 2]), size[0], size[1]
    )
    doffs = P3[0, 2] - P2[0, 2]
    return StereoRig(cam, float(baseline), float(doffs))


def _yaml_value(raw: str) -> object:
    raw = raw.strip()
    if raw.startswith("["):
        return _numbers(raw, Path("?"), "list").tolist()
    try:
        return float(raw)
    except ValueError:
        return raw.strip("'\"")


def read_generic_yaml_calib(path: PathLike, image_size: tuple[int, int] | None = None) -> StereoRig:
    """Read the generic YAML calibration (``K``, ``baseline`` metres, ``width``, ``height``, ``doffs``).

    ``width`` / ``height`` may be left out when ``image_size`` ``(width, height)`` is given (the
    images of the pair); when both are there they must agree.
    """
    p, text = _text(path)
    data: dict[str, object] = {}
    key = None
    for line in text.splitlines():
        line = line.split("#", 1)[0].rstrip()
        if not line.strip():
            continue
        if not line.startswith((" ", "\t", "-")) and ":" in line:
            key, val = line.split(":", 1)
            key = key.strip()
            data[key] = val
        elif key is not None:
            data[key] = str(data[key]) + " " + line  # continuation (nested rows)
    need_keys = (
        ("K", "baseline") if image_size is not None else ("K", "baseline", "width", "height")
    )
    for need in need_keys:
        if need not in data:
            raise FormatError(
                "missing",
                source=p,
                field=need,
                expected="K (9 numbers), baseline (m), width, height (or the images' size)",
            )
    K = _numbers(str(data["K"]), p, "K", 9).reshape(3, 3)
    try:
        baseline = float(str(data["baseline"]).strip())
        doffs = float(str(data.get("doffs", "0")).strip() or 0)
        size = [int(float(str(data[k]))) if k in data else None for k in ("width", "height")]
    except (ValueError, OverflowError) as exc:
        raise FormatError(
            f"{exc}", source=p, field="baseline/width/height", expected="numbers"
        ) from None
    if image_size is not None:
        for k, (given, actual) in enumerate(zip(size, image_size, strict=True)):
            name = ("width", "height")[k]
            if given is not None and given != actual:
                raise FormatError(
                    f"is {given} but the images are {image_size[0]} x {image_size[1]}",
                    source=p,
                    field=name,
                    expected=f"{actual} (or leave it out)",
                )
        size = [int(image_size[0]), int(image_size[1])]
    width, height = int(size[0] or 0), int(size[1] or 0)
    if not (np.isfinite(K).all() and K[0, 0] > 0 and K[1, 1] > 0):
        raise FormatError(f"{K.ravel().tolist()}", source=p, field="K", expected="fx, fy > 0")
    if not (np.isfinite(baseline) and baseline > 0 and np.isfinite(doffs)):
        raise FormatError(
            f"baseline {baseline}, doffs {doffs}",
            source=p,
            field="baseline",
            expected="a finite baseline > 0 (m) and a finite doffs",
        )
    check_intrinsics(
        {
            "width": width,
            "height": height,
            "fx": K[0, 0],
            "fy": K[1, 1],
            "cx": K[0, 2],
            "cy": K[1, 2],
        },
        source=p,
        error=FormatError,
    )
    return StereoRig(
        PinholeCamera(
            float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]), width, height
        ),
        baseline,
        doffs,
    )


def write_generic_yaml_calib(path: PathLike, rig: StereoRig) -> None:
    """Write a rig as the generic YAML calibration (atomically)."""
    c = rig.camera
    write_text(
        path,
        "# navkit stereo calibration: rectified pair, K of the left camera (pixels), baseline (m)\n"
        f"K: [{float(c.fx)!r}, 0.0, {float(c.cx)!r}, 0.0, {float(c.fy)!r}, {float(c.cy)!r}, 0.0, 0.0, 1.0]\n"
        f"baseline: {float(rig.baseline)!r}\n"
        f"doffs: {float(rig.doffs)!r}\n"
        f"width: {c.width}\n"
        f"height: {c.height}\n",
    )


def read_stereo_calib(path: PathLike, image_size: tuple[int, int] | None = None) -> StereoRig:
    """Read any of the three calibration formats (chosen by content).

    Raises
    ------
    FormatError
        If the file matches none of them.
    """
    p, text = _text(path)
    if re.search(r"^\s*cam0\s*=", text, re.M):
        return read_middlebury_calib(p)[0]
    if re.search(r"^\s*(P2|P_rect_02)\s*:", text, re.M):
        return read_kitti_stereo_calib(p, image_size)
    if re.search(r"^\s*K\s*:", text, re.M):
        return read_generic_yaml_calib(p, image_size)
    raise FormatError(
        "unknown calibration format",
        source=p,
        field="calib",
        expected="Middlebury calib.txt (cam0=), KITTI (P2:/P3:) or YAML (K:, baseline:)",
    )


# --------------------------------------------------------------------------- frame folders
@dataclass(frozen=True)
class StereoFrames:
    """A folder of rectified stereo frames with poses.

    Layout::

        calib.yaml | calib.txt     the rig (any format :func:`read_stereo_calib` reads)
        poses.tum                  T_world_left per frame (TUM: t tx ty tz qx qy qz qw), in order
        left/*.png, right/*.png    the images, paired in sorted order

    Attributes
    ----------
    rig : StereoRig
    timestamps : (K,) array
    poses : (K, 4, 4) array
        ``T_world_left`` (OpenCV optical frame of the left camera).
    left, right : list of Path
    """

    rig: StereoRig
    timestamps: np.ndarray
    poses: np.ndarray
    left: list[Path]
    right: list[Path]

    def __len__(self) -> int:
        return len(self.left)


def read_stereo_frames(folder: PathLike) -> StereoFrames:
    """Read a stereo frame folder (see :class:`StereoFrames`).

    Raises
    ------
    DataNotFoundError
        If the folder, its calibration or its poses are missing.
    FormatError
        If image and pose counts differ.
    """
    from navkit.io.trajectory import read_tum

    root = Path(folder)
    if not root.is_dir():
        raise DataNotFoundError(f"{root}: no such folder of stereo frames")
    calib = next(
        (root / n for n in ("calib.yaml", "calib.yml", "calib.txt") if (root / n).is_file()), None
    )
    if calib is None:
        raise DataNotFoundError(f"{root}: no calib.yaml / calib.txt")
    poses_file = root / "poses.tum"
    if not poses_file.is_file():
        raise DataNotFoundError(f"{root}: no poses.tum (T_world_left per frame, TUM format)")
    suffixes = (".png", ".jpg", ".jpeg", ".ppm", ".pgm", ".bmp", ".tif", ".tiff")
    left = sorted(p for p in (root / "left").glob("*") if p.suffix.lower() in suffixes)
    right = sorted(p for p in (root / "right").glob("*") if p.suffix.lower() in suffixes)
    traj = read_tum(poses_file)
    if not (len(left) == len(right) == len(traj)) or not left:
        raise FormatError(
            f"{len(left)} left, {len(right)} right images and {len(traj)} poses",
            source=root,
            field="left/right/poses.tum",
            expected="the same non-zero number of each",
        )
    return StereoFrames(read_stereo_calib(calib), traj.timestamps, traj.poses, left, right)


def write_stereo_frames(
    folder: PathLike,
    rig: StereoRig,
    lefts: list[np.ndarray],
    rights: list[np.ndarray],
    poses: np.ndarray,
    timestamps: np.ndarray | None = None,
) -> None:
    """Write a stereo frame folder (see :class:`StereoFrames`); every file atomically."""
    from navkit.io.images import write_image
    from navkit.io.trajectory import Trajectory, write_tum

    root = Path(folder)
    root.mkdir(parents=True, exist_ok=True)
    write_generic_yaml_calib(root / "calib.yaml", rig)
    for k, (a, b) in enumerate(zip(lefts, rights, strict=True)):
        write_image(root / "left" / f"{k:06d}.png", a)
        write_image(root / "right" / f"{k:06d}.png", b)
    t = (
        np.arange(len(lefts), dtype=np.float64)
        if timestamps is None
        else np.asarray(timestamps, dtype=np.float64)
    )
    write_tum(root / "poses.tum", Trajectory(t, np.asarray(poses, dtype=np.float64)))
