"""RGB-D inputs: TUM RGB-D folders, a simple ``color/`` + ``depth/`` layout, CAPE calibration.

Layouts
-------
TUM RGB-D (https://cvg.cit.tum.de/data/datasets/rgbd-dataset/file_formats)
    ``rgb.txt`` and ``depth.txt`` (lines ``timestamp path``, ``#`` comments); colour and depth
    are associated by nearest timestamp (at most ``max_dt`` = 0.02 s apart, as TUM's
    ``associate.py``); depth PNG 16-bit with ``depth_scale`` 5000 (metres = raw / 5000). Intrinsics
    from ``camera.yaml`` in the folder if present; else, when the folder's name says which
    Kinect recorded it (``freiburg1`` / ``fr1``, ``freiburg2`` / ``fr2``, ``freiburg3`` /
    ``fr3``), that camera's published calibration (TUM's "file formats" page; fr1 and fr2 lens
    distortion is not modelled); else the TUM ROS defaults (fx = fy = 525, cx = 319.5,
    cy = 239.5).
Simple layout
    ``color/`` and ``depth/`` with images paired by sorted file name (PNG or PGM, equal counts),
    and ``camera.yaml`` with ``fx``, ``fy``, ``cx``, ``cy``, ``depth_scale`` (metres =
    raw / depth_scale) and optionally ``width``, ``height``. Timestamps are the files' numeric
    stems, else their index.
CAPE (Proenca & Gao) ``calib_params.xml``
    OpenCV FileStorage with ``RGB_intrinsic_params``, ``RGB_distortion_coefficients``,
    ``IR_intrinsic_params``, ``IR_distortion_coefficients``, ``Rotation``, ``Translation`` (mm):
    ``X_rgb = R X_ir + T``. Depth (``depth_N.png``, mm) is in the IR camera.
7-Scenes (Shotton et al. 2013; Microsoft's layout, also used by tsdf-fusion-python)
    ``frame-NNNNNN.color.jpg`` (or ``.png``), ``frame-NNNNNN.depth.png`` (16-bit, millimetres,
    0 and 65535 = invalid), ``frame-NNNNNN.pose.txt`` (4 x 4 ``T_world_camera``, the reference:
    KinectFusion tracking) and ``camera-intrinsics.txt`` (3 x 3 ``K`` of the depth camera).
    Frames are recorded at 30 Hz: timestamps are ``N / 30`` s. **Colour and depth are not
    registered** in this dataset (no calibration between the two Kinect cameras is published):
    the reader pairs them pixel for pixel with the depth camera's ``K``, so colour is only
    approximately aligned with depth (docs/planes.md, "7-Scenes").
"""

from __future__ import annotations

import logging
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from navkit.domains import check_intrinsics
from navkit.errors import DataNotFoundError, FormatError, InputError
from navkit.io.textfiles import read_text_file
from navkit.sensors import PinholeCamera, RGBDFrame

__all__ = [
    "CapeCalibration",
    "CapeFrame",
    "RGBDSequence",
    "open_rgbd_sequence",
    "read_camera_yaml",
    "read_cape_calibration",
    "read_cape_frame",
    "read_seven_scenes",
    "read_simple_rgbd",
    "read_tum_rgbd",
]

log = logging.getLogger(__name__)

TUM_DEFAULT = {"fx": 525.0, "fy": 525.0, "cx": 319.5, "cy": 239.5}
TUM_CAMERAS = {
    "fr1": {"fx": 517.3, "fy": 516.5, "cx": 318.6, "cy": 255.3},
    "fr2": {"fx": 520.9, "fy": 521.0, "cx": 325.1, "cy": 249.7},
    "fr3": {"fx": 535.4, "fy": 539.2, "cx": 320.1, "cy": 247.6},
}
"""The TUM RGB-D Kinects' published colour intrinsics (freiburg1/2/3), pixels at 640 x 480."""


def tum_camera(folder: Path) -> dict[str, float]:
    """The intrinsics of the Kinect a TUM folder's name names (``rgbd_dataset_freiburg3_...``,
    ``tum-fr3-...``), else the TUM ROS defaults."""
    name = folder.resolve().name.lower()
    for key, values in TUM_CAMERAS.items():
        n = key[-1]
        if re.search(rf"(freiburg{n}|(^|[^a-z0-9])fr{n})([^0-9]|$)", name):
            return dict(values)
    return dict(TUM_DEFAULT)


_IMAGE_SUFFIXES = (".png", ".pgm")


#: YAML's spellings of the special floats (read, then refused by the fields' domains).
_YAML_SPECIAL = {".inf": "inf", "+.inf": "inf", "-.inf": "-inf", ".nan": "nan"}


def read_camera_yaml(path: str | Path) -> dict[str, float]:
    """Flat ``key: value`` YAML of numbers (``fx``, ``fy``, ``cx``, ``cy``, ``depth_scale``, ...).

    The fields' domains (``fx``, ``fy`` > 0, ``depth_scale`` > 0, ``width`` / ``height``
    positive integers, ``cx`` / ``cy`` inside the image) are checked where the camera is made,
    once the image size is known (the file may leave it out).

    Raises
    ------
    FormatError
        On a line that is not ``key: number`` or on a missing ``fx``, ``fy``, ``cx`` or ``cy``.
    """
    p = Path(path)
    if not p.is_file():
        raise DataNotFoundError(f"{p}: camera file not found")
    out: dict[str, float] = {}
    for n, line in enumerate(read_text_file(p, "a camera YAML").splitlines(), 1):
        text = line.split("#", 1)[0].strip()
        if not text or text.startswith("%") or text == "---":
            continue
        m = re.fullmatch(r"([A-Za-z_][\w]*)\s*:\s*(\S+)", text)
        if not m:
            raise FormatError(f"line {n} is {line!r}", source=p, expected="'key: number' lines")
        try:
            out[m.group(1)] = float(_YAML_SPECIAL.get(m.group(2).lower(), m.group(2)))
        except ValueError:
            raise FormatError(
                f"line {n}: {m.group(2)!r} is not a number",
                source=p,
                field=m.group(1),
                expected="a number",
            ) from None
    for key in ("fx", "fy", "cx", "cy"):
        if key not in out:
            raise FormatError("missing", source=p, field=key, expected="fx, fy, cx, cy in pixels")
    return out


def _read_color(path: Path) -> NDArray[np.uint8]:
    from navkit.io.images import read_image

    img = read_image(path)
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    if img.shape[2] == 4:
        img = img[..., :3]
    if img.dtype != np.uint8:
        img = (img.astype(np.float64) / 257.0).round().astype(np.uint8)
    return img


@dataclass(frozen=True)
class RGBDSequence:
    """An RGB-D sequence on disk, read frame by frame.

    Attributes
    ----------
    color_paths, depth_paths : tuple of Path
        Paired images.
    timestamps : (N,) array
        Seconds (or frame indices when the files carry no time).
    camera : PinholeCamera
    depth_scale : float
        ``metres = raw / depth_scale``.
    source : Path
        The folder.
    reference : (N, 4, 4) array or None
        Reference poses ``T_world_camera`` shipped with the sequence (7-Scenes), else None.
    invalid_raw : int or None
        A raw depth value that also means "no measurement" besides 0 (65535 in 7-Scenes).
    """

    color_paths: tuple[Path, ...]
    depth_paths: tuple[Path, ...]
    timestamps: NDArray[np.float64]
    camera: PinholeCamera
    depth_scale: float
    source: Path
    reference: NDArray[np.float64] | None = None
    invalid_raw: int | None = None

    def __len__(self) -> int:
        return len(self.color_paths)

    def frame(self, i: int) -> RGBDFrame:
        """Frame ``i`` (colour RGB uint8, depth metres, NaN invalid)."""
        from navkit.io.images import read_depth

        color = _read_color(self.color_paths[i])
        depth = read_depth(self.depth_paths[i], self.depth_scale)
        if self.invalid_raw is not None:
            depth[depth >= self.invalid_raw / self.depth_scale - 1e-9] = np.nan
        shape = (self.camera.height, self.camera.width)
        for name, arr, p in (
            ("color", color, self.color_paths[i]),
            ("depth", depth, self.depth_paths[i]),
        ):
            if arr.shape[:2] != shape:
                raise FormatError(
                    f"image is {arr.shape[1]} x {arr.shape[0]}",
                    source=p,
                    field=name,
                    expected=f"{shape[1]} x {shape[0]} like the camera",
                )
        return RGBDFrame(color, depth, self.camera, float(self.timestamps[i]))

    def __iter__(self) -> Iterator[RGBDFrame]:
        for i in range(len(self)):
            yield self.frame(i)


def _camera(values: dict[str, float], size: tuple[int, int], source: Path) -> PinholeCamera:
    """The camera of an RGB-D folder: ``values`` (``camera.yaml`` and any override) with the
    image size ``size`` where they leave it out, every field checked against its domain
    (:func:`navkit.domains.check_intrinsics`); errors name ``camera.yaml`` when the folder has
    one."""
    yaml = source / "camera.yaml"
    where = yaml if yaml.is_file() else source
    full = {"width": size[0], "height": size[1], **values}
    w, h = check_intrinsics(full, source=where, error=FormatError)
    try:
        return PinholeCamera(values["fx"], values["fy"], values["cx"], values["cy"], w, h)
    except InputError as exc:
        raise FormatError(
            exc.message, source=source, field=exc.field, expected=exc.expected
        ) from None


def _image_size(path: Path) -> tuple[int, int]:
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise FormatError("cannot be decoded as an image", source=path, expected="PNG or PGM")
    return img.shape[1], img.shape[0]


def _read_list(path: Path) -> list[tuple[float, str]]:
    if not path.is_file():
        raise DataNotFoundError(f"{path}: not found (a TUM RGB-D folder has rgb.txt and depth.txt)")
    rows = []
    for n, line in enumerate(read_text_file(path, "a TUM RGB-D list").splitlines(), 1):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        parts = text.split()
        try:
            rows.append((float(parts[0]), parts[1]))
        except (ValueError, IndexError):
            raise FormatError(
                f"line {n} is {line!r}", source=path, expected="'timestamp filename'"
            ) from None
    if not rows:
        raise FormatError("no entries", source=path, expected="'timestamp filename' lines")
    return rows


def read_tum_rgbd(
    folder: str | Path,
    camera: dict[str, float] | None = None,
    max_dt: float = 0.02,
    depth_scale: float = 5000.0,
) -> RGBDSequence:
    """A TUM RGB-D folder (see module docstring); ``camera`` overrides intrinsics keys."""
    root = Path(folder)
    rgb = _read_list(root / "rgb.txt")
    dep = _read_list(root / "depth.txt")
    td = np.array([t for t, _ in dep])
    color_paths, depth_paths, stamps = [], [], []
    used: set[int] = set()
    for t, name in rgb:
        k = int(np.argmin(np.abs(td - t)))
        if abs(td[k] - t) <= max_dt and k not in used:
            used.add(k)
            color_paths.append(root / name)
            depth_paths.append(root / dep[k][1])
            stamps.append(t)
    if not color_paths:
        raise FormatError(
            f"no colour / depth pair closer than {max_dt} s",
            source=root / "rgb.txt",
            expected="matching timestamps in rgb.txt and depth.txt",
        )
    values = dict(tum_camera(root), depth_scale=depth_scale)
    if (root / "camera.yaml").is_file():
        values.update(read_camera_yaml(root / "camera.yaml"))
    values.update(camera or {})
    cam = _camera(values, _image_size(color_paths[0]), root)
    return RGBDSequence(
        tuple(color_paths),
        tuple(depth_paths),
        np.array(stamps),
        cam,
        float(values["depth_scale"]),
        root,
    )


def read_simple_rgbd(folder: str | Path, camera: dict[str, float] | None = None) -> RGBDSequence:
    """The simple layout ``color/``, ``depth/``, ``camera.yaml`` (see module docstring).

    ``camera`` supplies or overrides intrinsics keys (e.g. when ``camera.yaml`` is absent).
    """
    root = Path(folder)
    lists = []
    for sub in ("color", "depth"):
        d = root / sub
        if not d.is_dir():
            raise DataNotFoundError(
                f"{d}: folder not found (the simple layout has color/ and depth/)"
            )
        files = sorted(
            (p for p in d.iterdir() if p.suffix.lower() in _IMAGE_SUFFIXES),
            key=lambda p: (float(p.stem) if _is_number(p.stem) else float("inf"), p.name),
        )
        if not files:
            raise FormatError("no PNG or PGM images", source=d, expected="images named by frame")
        lists.append(files)
    if len(lists[0]) != len(lists[1]):
        raise FormatError(
            f"{len(lists[0])} colour images but {len(lists[1])} depth images",
            source=root,
            expected="one depth image per colour image",
        )
    values: dict[str, float] = {}
    if (root / "camera.yaml").is_file():
        values.update(read_camera_yaml(root / "camera.yaml"))
    values.update(camera or {})
    for key in ("fx", "fy", "cx", "cy", "depth_scale"):
        if key not in values:
            raise FormatError(
                "missing",
                source=root / "camera.yaml",
                field=key,
                expected="fx, fy, cx, cy (pixels) and depth_scale (raw units per metre)",
            )
    stems = [p.stem for p in lists[0]]
    stamps = (
        np.array([float(s) for s in stems])
        if all(_is_number(s) for s in stems)
        else np.arange(len(stems), dtype=np.float64)
    )
    cam = _camera(values, _image_size(lists[0][0]), root)
    return RGBDSequence(
        tuple(lists[0]), tuple(lists[1]), stamps, cam, float(values["depth_scale"]), root
    )


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def open_rgbd_sequence(path: str | Path, camera: dict[str, float] | None = None) -> RGBDSequence:
    """A TUM RGB-D folder (has ``rgb.txt``) or the simple layout (has ``color/``)."""
    root = Path(path)
    if not root.is_dir():
        raise DataNotFoundError(f"{root}: not a folder")
    if (root / "rgb.txt").is_file():
        return read_tum_rgbd(root, camera)
    if (root / "color").is_dir():
        return read_simple_rgbd(root, camera)
    if any(root.glob("frame-*.depth.png")):
        return read_seven_scenes(root, camera)
    raise InputError(
        "neither rgb.txt, color/ nor frame-NNNNNN.depth.png files found",
        source=root,
        expected="a TUM RGB-D folder, color/ + depth/ + camera.yaml, or a 7-Scenes folder",
    )


_SEVEN_SCENES = re.compile(r"^frame-(\d+)\.depth\.png$")


def read_pose_matrix(path: str | Path) -> NDArray[np.float64]:
    """A 4 x 4 pose matrix written as 4 lines of 4 numbers (7-Scenes ``frame-N.pose.txt``).

    Raises
    ------
    FormatError
        When the file is not 16 finite numbers whose last row is ``0 0 0 1``.
    """
    p = Path(path)
    if not p.is_file():
        raise DataNotFoundError(f"{p}: pose file not found")
    try:
        M = np.loadtxt(p, ndmin=2)
    except ValueError as exc:
        raise FormatError(f"not numeric ({exc})", source=p, expected="4 x 4 numbers") from None
    if M.shape != (4, 4) or not np.all(np.isfinite(M)) or not np.allclose(M[3], [0, 0, 0, 1]):
        raise FormatError(
            f"holds a {M.shape} table",
            source=p,
            field="pose",
            expected="a 4 x 4 rigid transform (last row 0 0 0 1)",
        )
    return M


def read_seven_scenes(
    folder: str | Path,
    camera: dict[str, float] | None = None,
    depth_scale: float = 1000.0,
    rate_hz: float = 30.0,
) -> RGBDSequence:
    """A 7-Scenes folder (see module docstring) with its poses as ``reference``.

    Parameters
    ----------
    folder : path
    camera : dict, optional
        ``fx, fy, cx, cy`` (pixels) and ``depth_scale`` overriding ``camera-intrinsics.txt``
        (which is required when ``camera`` does not give all four intrinsics).
    depth_scale : float
        Raw depth units per metre (7-Scenes: millimetres).
    rate_hz : float
        Frame rate giving the timestamps ``N / rate_hz``.
    """
    root = Path(folder)
    frames = sorted(
        (int(m.group(1)), p)
        for p in root.iterdir()
        if (m := _SEVEN_SCENES.match(p.name)) is not None
    )
    if not frames:
        raise DataNotFoundError(f"{root}: no frame-NNNNNN.depth.png files (7-Scenes layout)")
    color_paths, depth_paths = [], []
    for n, dp in frames:
        stem = dp.name[: -len(".depth.png")]
        cp = next(
            (
                root / f"{stem}.color{e}"
                for e in (".jpg", ".png")
                if (root / f"{stem}.color{e}").is_file()
            ),
            None,
        )
        if cp is None:
            raise DataNotFoundError(f"{root / stem}.color.jpg: not found (colour of frame {n})")
        color_paths.append(cp)
        depth_paths.append(dp)
    values: dict[str, float] = {"depth_scale": depth_scale}
    kfile = root / "camera-intrinsics.txt"
    given = camera or {}
    if not all(k in given for k in ("fx", "fy", "cx", "cy")):
        if not kfile.is_file():
            raise DataNotFoundError(
                f"{kfile}: not found; give the intrinsics instead (--intrinsics FX,FY,CX,CY)"
            )
        try:
            K = np.loadtxt(kfile, ndmin=2)
        except ValueError as exc:
            raise FormatError(f"not numeric ({exc})", source=kfile, expected="a 3 x 3 K") from None
        if K.shape != (3, 3):
            raise FormatError(
                f"holds a {K.shape} table", source=kfile, field="K", expected="a 3 x 3 matrix"
            )
        values.update(fx=float(K[0, 0]), fy=float(K[1, 1]), cx=float(K[0, 2]), cy=float(K[1, 2]))
    values.update(given)
    poses = [root / f"{dp.name[: -len('.depth.png')]}.pose.txt" for _, dp in frames]
    reference = None
    if all(p.is_file() for p in poses):
        reference = np.stack([read_pose_matrix(p) for p in poses])
        # 7-Scenes rotations are not orthonormal (det 0.99985, R^T R off by 1.4e-4 on the
        # shared frames): a relative rotation error computed from them would read ~1 deg for
        # an exact estimate. Projected onto SO(3) (nearest rotation, SVD).
        U, _, Vt = np.linalg.svd(reference[:, :3, :3])
        D = np.ones((len(reference), 3))
        D[:, 2] = np.sign(np.linalg.det(U @ Vt))
        reference[:, :3, :3] = (U * D[:, None, :]) @ Vt
    elif any(p.is_file() for p in poses):
        log.warning("%s: some frames have no pose.txt; no reference poses", root)
    cam = _camera(values, _image_size(depth_paths[0]), root)
    stamps = np.array([n for n, _ in frames], dtype=np.float64) / rate_hz
    return RGBDSequence(
        tuple(color_paths),
        tuple(depth_paths),
        stamps,
        cam,
        float(values["depth_scale"]),
        root,
        reference=reference,
        invalid_raw=65535,
    )


# ------------------------------------------------------------------------------------------------
# CAPE calibration and frames


@dataclass(frozen=True)
class CapeCalibration:
    """Calibration of an RGB camera and an IR depth camera (CAPE's ``calib_params.xml``).

    Attributes
    ----------
    K_rgb, K_ir : (3, 3) arrays
    dist_rgb, dist_ir : (5,) arrays
        OpenCV distortion ``k1 k2 p1 p2 k3``.
    T_rgb_ir : (4, 4) array
        ``X_rgb = R X_ir + T`` with ``T`` converted to metres.
    """

    K_rgb: NDArray[np.float64]
    dist_rgb: NDArray[np.float64]
    K_ir: NDArray[np.float64]
    dist_ir: NDArray[np.float64]
    T_rgb_ir: NDArray[np.float64]


def read_cape_calibration(path: str | Path) -> CapeCalibration:
    """Read CAPE's OpenCV FileStorage calibration (translation in mm -> metres)."""
    p = Path(path)
    if not p.is_file():
        raise DataNotFoundError(f"{p}: calibration file not found")
    try:
        fs = cv2.FileStorage(str(p), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError):  # OpenCV raises SystemError on unparsable text
        raise FormatError(
            "not an OpenCV FileStorage file",
            source=p,
            expected="XML/YAML written by cv::FileStorage",
        ) from None
    if not fs.isOpened():
        raise FormatError(
            "cannot be opened", source=p, expected="XML/YAML written by cv::FileStorage"
        )

    def mat(name: str, shape: tuple[int, ...]) -> NDArray[np.float64]:
        m = fs.getNode(name).mat()
        if m is None:
            raise FormatError(
                "missing", source=p, field=name, expected=f"an opencv-matrix of shape {shape}"
            )
        m = np.asarray(m, dtype=np.float64)
        if m.size != int(np.prod(shape)) or not np.all(np.isfinite(m)):
            raise FormatError(
                f"has shape {m.shape}", source=p, field=name, expected=f"{shape} finite values"
            )
        return np.asarray(m.reshape(shape), dtype=np.float64)

    try:
        K_rgb = mat("RGB_intrinsic_params", (3, 3))
        d_rgb = mat("RGB_distortion_coefficients", (5,))
        K_ir = mat("IR_intrinsic_params", (3, 3))
        d_ir = mat("IR_distortion_coefficients", (5,))
        R = mat("Rotation", (3, 3))
        T = mat("Translation", (3,)) / 1000.0
    finally:
        fs.release()
    if abs(np.linalg.det(R) - 1) > 1e-3:
        raise FormatError(
            f"determinant {np.linalg.det(R):.4f}", source=p, field="Rotation", expected="a rotation"
        )
    Tm = np.eye(4)
    Tm[:3, :3], Tm[:3, 3] = R, T
    return CapeCalibration(K_rgb, d_rgb, K_ir, d_ir, Tm)


@dataclass(frozen=True)
class CapeFrame:
    """A CAPE frame as a range image plus a separately calibrated camera.

    Attributes
    ----------
    points : (H, W, 3) array
        IR-camera-frame points (undistorted rays x depth), metres, NaN invalid.
    color : (H, W, 3) uint8
        RGB image, undistorted (so ``camera`` is an exact pinhole).
    camera : PinholeCamera
        RGB intrinsics.
    T_camera_sensor : (4, 4) array
        IR -> RGB.
    color_registered : (H, W, 3) uint8
        The colour of each depth pixel (its point projected into the RGB image; black where
        the point is invalid or outside the image).
    ir_camera : PinholeCamera
        IR intrinsics (the points' rays are undistorted, so this pinhole reprojects them).
    """

    points: NDArray[np.float64]
    color: NDArray[np.uint8]
    camera: PinholeCamera
    T_camera_sensor: NDArray[np.float64]
    color_registered: NDArray[np.uint8]
    ir_camera: PinholeCamera


def read_cape_frame(folder: str | Path, index: int = 0, depth_scale: float = 1000.0) -> CapeFrame:
    """``rgb_<index>.png`` + ``depth_<index>.png`` + ``calib_params.xml`` of a CAPE sequence folder."""
    from navkit.io.images import read_depth

    root = Path(folder)
    cal = read_cape_calibration(root / "calib_params.xml")
    depth = read_depth(root / f"depth_{index}.png", depth_scale)
    color = _read_color(root / f"rgb_{index}.png")
    H, W = depth.shape
    u, v = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    pix = np.stack([u, v], axis=-1).reshape(-1, 1, 2)
    rays = cv2.undistortPoints(pix, cal.K_ir, cal.dist_ir).reshape(H, W, 2)
    points = np.concatenate([rays, np.ones((H, W, 1))], axis=2) * depth[..., None]
    h, w = color.shape[:2]
    und = cv2.undistort(color, cal.K_rgb, cal.dist_rgb)
    K = cal.K_rgb
    cam = PinholeCamera(K[0, 0], K[1, 1], K[0, 2], K[1, 2], w, h)
    X = points.reshape(-1, 3) @ cal.T_rgb_ir[:3, :3].T + cal.T_rgb_ir[:3, 3]
    with np.errstate(invalid="ignore", divide="ignore"):
        pu = cam.fx * X[:, 0] / X[:, 2] + cam.cx
        pv = cam.fy * X[:, 1] / X[:, 2] + cam.cy
    ok = np.isfinite(pu) & np.isfinite(pv) & (X[:, 2] > 0)
    mu = np.where(ok, pu, -1e6).astype(np.float32).reshape(H, W)
    mv = np.where(ok, pv, -1e6).astype(np.float32).reshape(H, W)
    reg = cv2.remap(und, mu, mv, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    Ki = cal.K_ir
    ir = PinholeCamera(Ki[0, 0], Ki[1, 1], Ki[0, 2], Ki[1, 2], W, H)
    return CapeFrame(
        points, np.asarray(und, np.uint8), cam, cal.T_rgb_ir, np.asarray(reg, np.uint8), ir
    )
