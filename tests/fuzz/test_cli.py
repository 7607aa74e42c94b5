"""Every ``navkit`` command fed bad paths, an ``--out`` that cannot be a folder, and non-finite or
absurd numbers for each numeric option (found by introspecting the CLI, so options added later are
fuzzed too).

A case passes when the command exits 0 (a valid result) or 2 (a one-line ``error: ...``), never
reaches ``internal error``, prints no traceback, and - when it fails - leaves nothing in ``--out``.
NaN, an infinity or a magnitude beyond 1e9 for any number is always an error.
"""

from __future__ import annotations

import enum
import math
import os
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from navkit import datasets
from navkit.errors import DataNotFoundError

from .conftest import MEMORY_BOUND, record


def _commands() -> dict[str, Any]:
    from typer.main import get_command

    from navkit.cli.main import app

    found: dict[str, Any] = {}

    def walk(c: Any, prefix: list[str]) -> None:
        if hasattr(c, "commands"):
            for name, sub in c.commands.items():
                walk(sub, [*prefix, name])
        else:
            found[" ".join(prefix)] = c

    walk(get_command(app), [])
    return found


def _kind(param: Any) -> str:
    """'path', 'float', 'int', 'bool' or 'other' for a click/typer parameter."""
    ann = getattr(getattr(param, "type_descriptor", None), "annotation", None)
    text = str(ann)
    if ann is bool or getattr(param, "is_flag", False):
        return "bool"
    if isinstance(ann, type) and issubclass(ann, enum.Enum):
        return "other"
    for name in ("float", "int"):
        if ann is (float if name == "float" else int) or text in (
            f"{name} | None",
            f"typing.Optional[{name}]",
        ):
            return name
    if "Path" in text:
        return "path"
    return "other"


COMMANDS = _commands()

#: ``NAVKIT_FUZZ_FULL=1`` (``make fuzz``) adds the cases that mostly end in a full valid run
#: (infinities, 1e300, -1, folders, empty files, deep JSON); ``make test`` runs the fast ones.
FULL = os.environ.get("NAVKIT_FUZZ_FULL") == "1"


# ------------------------------------------------------------------ valid inputs, built once
class Inputs:
    """Small valid inputs for the commands, made with the simulator and navkit's writers."""

    def __init__(self, root: Path, run: Callable[..., Any]) -> None:
        from navkit.geometry import se3_from_rt
        from navkit.io.pathjson import write_path_json
        from navkit.io.trajectory import Trajectory, write_tum
        from navkit.path.approximator import approximate

        self.root = root
        t = np.arange(40) * 0.1
        xy = np.c_[np.linspace(0, 2, 40), 0.3 * np.sin(np.linspace(0, 3, 40))]
        poses = np.stack([se3_from_rt(np.eye(3), [x, y, 0.0]) for x, y in xy])
        self.tum = root / "track.tum"
        write_tum(self.tum, Trajectory(t, poses))
        self.path_json = root / "path.json"
        write_path_json(self.path_json, approximate(xy, timed=False).spline)
        self.stereo = root / "stereo"
        res = run("stereo", "simulate", "rectangle", "--out", self.stereo, "--width", "64")
        assert res.exit_code == 0, res.output
        self.left = sorted((self.stereo / "left").iterdir())[0]
        self.right = sorted((self.stereo / "right").iterdir())[0]
        self.map_json = root / "map" / "map.json"
        res = run("map", "build", self.stereo, "--out", root / "map")
        assert res.exit_code == 0, res.output
        try:
            self.kitti: Path | None = datasets.find("lidar/semantickitti-seq00/000000.bin")
            self.range_image: Path | None = datasets.find(
                "lidar/squeezeseg-kitti-raw/2011_09_26_0001_0000000010.npy"
            )
        except DataNotFoundError:
            self.kitti = self.range_image = None
        self.random_bytes = root / "random.bin"
        self.random_bytes.write_bytes(np.random.default_rng(0).bytes(3000))
        self.not_utf8 = root / "not-utf8.txt"
        self.not_utf8.write_bytes(b"# \xff\xfe\x80 settings\nkey = \xc3(\n")
        self.empty = root / "empty.json"
        self.empty.write_bytes(b"")
        self.deep = root / "deep.json"
        self.deep.write_text("[" * 100_000 + "]" * 100_000)
        self.a_file = root / "a-file"
        self.a_file.write_text("x")

    def base(self, command: str) -> list[Any] | None:
        """Arguments (without --out) of a cheap valid run of ``command``; None: no cheap run."""
        return {
            "path simulate": ["--legs", "2"],
            "path record": [self.tum],
            "path return": [self.path_json, "--runs", "2"],
            "stereo simulate": ["rectangle", "--width", "48"],
            "stereo disparity": [self.left, self.right, "--calib", self.stereo / "calib.yaml"],
            "map build": [self.stereo],
            "map locate": [self.map_json, self.stereo],
            "obstacles detect": None
            if self.kitti is None or self.range_image is None
            else [self.kitti if FULL else self.range_image],
        }.get(command)

    def bad_paths(self) -> list[Path]:
        fast = [self.root / "does-not-exist.txt", self.random_bytes, self.not_utf8]
        return [*fast, self.root, self.empty, self.deep] if FULL else fast


@pytest.fixture(scope="module")
def runner() -> Callable[..., Any]:
    from typer.testing import CliRunner

    from navkit.cli.main import app

    cli_runner = CliRunner()

    def run(*args: Any) -> Any:
        return cli_runner.invoke(app, [str(a) for a in args], catch_exceptions=True)

    return run


@pytest.fixture(scope="module")
def inputs(tmp_path_factory: pytest.TempPathFactory, runner: Callable[..., Any]) -> Inputs:
    return Inputs(tmp_path_factory.mktemp("cli-inputs"), runner)


_case_number = [0]


def run_case(
    runner: Callable[..., Any], root: Path, args: list[Any], *, must_fail: bool = False
) -> Any:
    """Run one case with a fresh ``--out``; assert the promises; count it."""
    _case_number[0] += 1
    out = root / f"case-{_case_number[0]}"
    started = not tracemalloc.is_tracing()
    if started:
        tracemalloc.start()
    tracemalloc.reset_peak()
    base = tracemalloc.get_traced_memory()[0]
    try:
        res = runner(*args, "--out", out)
    finally:
        peak = (tracemalloc.get_traced_memory()[1] - base) / 2**20
        if started:
            tracemalloc.stop()
    text = res.output
    ok = (
        res.exit_code in (0, 2)
        and "internal error" not in text
        and "Traceback" not in text
        and (res.exception is None or isinstance(res.exception, SystemExit))
        and peak * 2**20 <= MEMORY_BOUND
        and not (must_fail and res.exit_code == 0)
        and (res.exit_code == 0 or not out.exists() or not any(out.iterdir()))
    )
    record("cli", "valid" if res.exit_code == 0 and ok else ("errors" if ok else "failures"), peak)
    left = sorted(p.name for p in out.iterdir()) if out.exists() else []
    assert ok, (
        f"navkit {' '.join(map(str, args))}: exit {res.exit_code}, exception {res.exception!r}, "
        f"left in --out {left}, peak {peak:.0f} MB\n{text[-2000:]}"
    )
    return res


def _params(command: str, kind: str) -> list[Any]:
    return [p for p in COMMANDS[command].params if _kind(p) == kind]


PATH_CASES = [
    (command, p.name)
    for command in COMMANDS
    for p in COMMANDS[command].params
    if _kind(p) == "path" and p.name != "out"
]


@pytest.mark.parametrize(("command", "param"), PATH_CASES)
def test_bad_paths(command: str, param: str, inputs: Inputs, runner: Any, tmp_path: Path) -> None:
    """Each path argument or option given a missing file, a folder, random bytes, non-UTF-8
    text, an empty file and deeply nested JSON: a clean error or a valid run, nothing left."""
    cmd = COMMANDS[command]
    p = next(q for q in cmd.params if q.name == param)
    base = inputs.base(command)
    for bad in inputs.bad_paths():
        if base is None:  # no cheap valid run: every required argument gets the bad path
            args: list[Any] = []
            for q in cmd.params:
                if q.required and q.name != "out":
                    args += [bad] if q.param_type_name == "argument" else [q.opts[0], bad]
            if p.param_type_name != "argument" and not p.required:
                args += [p.opts[0], bad]
        else:
            args = list(base)
            positional = [q for q in cmd.params if q.param_type_name == "argument"]
            if p.param_type_name == "argument":
                k = positional.index(p)
                args[k] = bad
            elif p.opts[0] in args:
                args[args.index(p.opts[0]) + 1] = bad
            else:
                args += [p.opts[0], bad]
        run_case(runner, tmp_path, [*command.split(), *args])


@pytest.mark.parametrize("command", list(COMMANDS))
def test_out_that_is_not_a_folder(command: str, inputs: Inputs, runner: Any) -> None:
    if not any(p.name == "out" for p in COMMANDS[command].params):
        pytest.skip("writes no --out folder")  # navkit compile: Numba's cache only
    base = inputs.base(command)
    if base is None:
        pytest.skip("no cheap valid run of this command")
    for out in (inputs.a_file, inputs.a_file / "sub"):
        res = runner(*command.split(), *base, "--out", out)
        ok = res.exit_code == 2 and "not a folder" in res.output
        record("cli", "errors" if ok else "failures")
        assert ok, res.output
    assert inputs.a_file.read_text() == "x"


NUMBER_CASES = [
    (command, p.name, value)
    for command in COMMANDS
    for kind, values in (
        ("float", ("nan", "inf", "-inf", "1e300") if FULL else ("nan",)),
        ("int", ("-1", "10**12") if FULL else ("10**12",)),
    )
    for p in _params(command, kind)
    if p.name != "seed"
    for value in values
]


@pytest.mark.parametrize(("command", "param", "value"), NUMBER_CASES)
def test_absurd_numbers(
    command: str, param: str, value: str, inputs: Inputs, runner: Any, tmp_path: Path
) -> None:
    """NaN, infinities, 1e300 and 10^12 are always refused; -1 is refused or runs."""
    base = inputs.base(command)
    if base is None:  # no cheap valid run: missing inputs, so only the option checks are reached
        base = []
        for q in COMMANDS[command].params:
            if q.required and q.name != "out":
                missing = inputs.root / "does-not-exist"
                base += [missing] if q.param_type_name == "argument" else [q.opts[0], missing]
    p = next(q for q in COMMANDS[command].params if q.name == param)
    text = str(10**12) if value == "10**12" else value
    must_fail = value != "-1"  # NaN, inf and magnitudes beyond 1e9 are never valid options
    run_case(runner, tmp_path, [*command.split(), *base, p.opts[0], text], must_fail=must_fail)


def test_every_case_is_counted() -> None:
    assert math.isfinite(len(NUMBER_CASES)) and len(PATH_CASES) > 10


def test_second_input_bad_leaves_nothing(inputs: Inputs, runner: Any, tmp_path: Path) -> None:
    """Several inputs: the first input's outputs are written, then the second is bad."""
    if inputs.range_image is None:
        pytest.skip("recorded data absent")
    bad = tmp_path / "bad.npy"
    bad.write_bytes(b"\x93NUMPY")
    res = run_case(runner, tmp_path, ["obstacles", "detect", inputs.range_image, bad])
    assert res.exit_code == 2


# ------------------------------------------------------------------ declared domains
def _numeric_params() -> list[tuple[str, Any]]:
    return [
        (command, p)
        for command in COMMANDS
        for p in COMMANDS[command].params
        if _kind(p) in ("int", "float")
    ]


def test_every_numeric_option_declares_a_domain() -> None:
    """Every numeric option is declared with ``navkit.cli.common.option`` and a Domain."""
    from navkit.cli.common import option_domain, option_name

    missing = [f"{c} {option_name(p)}" for c, p in _numeric_params() if option_domain(p) is None]
    assert not missing, f"numeric options without a declared domain: {missing}"


def _text(value: float, integer: bool) -> str:
    if math.isnan(value):
        return "nan"
    return str(int(value)) if integer else repr(float(value))


def _edge_cases() -> list[tuple[str, str, str, bool]]:
    from navkit.cli.common import option_domain

    cases = []
    for command, p in _numeric_params():
        domain = option_domain(p)
        if domain is None:
            continue
        inside, outside = domain.edges()
        integer = _kind(p) == "int"
        for v in outside:
            if integer and (math.isnan(v) or not float(v).is_integer()):
                continue  # click refuses a non-integer for an int option itself
            cases.append((command, p.name, _text(v, integer), False))
        cases += [(command, p.name, _text(v, integer), True) for v in inside]
    return cases


EDGE_CASES = _edge_cases()


@pytest.mark.parametrize(("command", "param", "value", "inside"), EDGE_CASES)
def test_domain_edges(
    command: str, param: str, value: str, inside: bool, inputs: Inputs, runner: Any, tmp_path: Path
) -> None:
    """Each numeric option at the edges of its declared domain: just outside is a one-line
    ``error:`` (exit 2) naming the option and the domain, before any input is read; just inside
    is accepted by the domain check (the command itself is not run: that is the other tests')."""
    from navkit.cli.common import option_domain, option_name

    p = next(q for q in COMMANDS[command].params if q.name == param)
    domain = option_domain(p)
    number = int(value) if _kind(p) == "int" and value != "nan" else float(value)
    if inside:
        assert domain.contains(number), (command, param, value, domain.describe())
        return
    args = inputs.base(command)  # the domain check comes first: the inputs are never read
    if args is None:
        args = []
        for q in COMMANDS[command].params:
            if q.required and q.name != "out":
                missing = inputs.root / "does-not-exist"
                args += [missing] if q.param_type_name == "argument" else [q.opts[0], missing]
    out = tmp_path / "out"
    res = runner(*command.split(), *args, p.opts[0], value, "--out", out)
    lines = res.output.strip().splitlines()
    ok = (
        res.exit_code == 2
        and len(lines) == 1
        and lines[0].startswith(f"error: {option_name(p)}: ")
        and domain.describe() in lines[0]
        and not (out.exists() and any(out.iterdir()))
    )
    record("cli", "errors" if ok else "failures")
    assert ok, f"navkit {command} {p.opts[0]} {value}: exit {res.exit_code}\n{res.output}"


@pytest.mark.parametrize(
    ("args", "option", "expected"),
    [
        (["obstacles", "detect", "x", "--sensor-height", "-1e9"], "--sensor-height", "> 0"),
        (["obstacles", "detect", "x", "--rings", "0"], "--rings", "an integer >= 1"),
        (["obstacles", "detect", "x", "--rings", "-1"], "--rings", "an integer >= 1"),
        (["obstacles", "detect", "x", "--resolution", "0"], "--resolution", "> 0"),
        (["obstacles", "detect", "x", "--extent", "0"], "--extent", "> 0"),
        (["stereo", "disparity", "l", "r", "--calib", "c", "--num-disparities", "-16"],
         "--num-disparities", "multiple of 16"),
        (["stereo", "disparity", "l", "r", "--calib", "c", "--max-depth", "-1"],
         "--max-depth", "> 0"),
        (["planes", "extract", "x", "--nu", "0"], "--nu", "> 0"),
    ],
)  # fmt: skip
def test_held_out_domain_cases(
    args: list[str], option: str, expected: str, runner: Any, tmp_path: Path
) -> None:
    """The options a held-out fuzz run found accepted outside their domain."""
    res = runner(*args, "--out", tmp_path / "out")
    assert res.exit_code == 2, res.output
    line = res.output.strip()
    assert "\n" not in line and line.startswith(f"error: {option}: ") and expected in line


def test_trajectory_beyond_the_magnitude_bound(runner: Any, tmp_path: Path) -> None:
    """A speed of 1e308 in an odometry log (it overflowed the spline fit's sums) and a TUM
    position beyond 1e9 m: clean errors naming the file and the field."""
    odo = tmp_path / "odo.txt"
    odo.write_text("0 1e308 0\n1 1e308 0\n2 1e308 0.1\n3 1 0\n")
    res = runner("path", "record", odo, "--format", "odometry", "--out", tmp_path / "a")
    assert res.exit_code == 2 and "internal error" not in res.output, res.output
    assert "odo.txt" in res.output and "'v[0]'" in res.output
    tum = tmp_path / "far.tum"
    tum.write_text("".join(f"{i} {i * 1e299} 0 0 0 0 0 1\n" for i in range(5)))
    res = runner("path", "record", tum, "--out", tmp_path / "b")
    assert res.exit_code == 2 and "far.tum" in res.output and "position" in res.output, res.output


def test_mask_of_another_size(inputs: Inputs, runner: Any, tmp_path: Path) -> None:
    """``--gt`` / ``--mask`` of another size than the images: an error naming the file, before
    any output (it was a NumPy broadcast error, an internal error)."""
    import cv2

    from navkit.io.images import write_pfm

    h, w = cv2.imread(str(inputs.left), cv2.IMREAD_UNCHANGED).shape[:2]
    gt = tmp_path / "gt.pfm"
    write_pfm(gt, np.full((h, w), 5.0, np.float32))
    mask = tmp_path / "mask.png"
    cv2.imwrite(str(mask), np.full((h + 3, w), 255, np.uint8))
    base = [inputs.left, inputs.right, "--calib", inputs.stereo / "calib.yaml", "--gt", gt]
    res = run_case(runner, tmp_path, ["stereo", "disparity", *base, "--mask", mask])
    assert res.exit_code == 2 and "--mask" in res.output and "mask.png" in res.output
    write_pfm(gt, np.full((h, w + 1), 5.0, np.float32))
    res = run_case(runner, tmp_path, ["stereo", "disparity", *base])
    assert res.exit_code == 2 and "--gt" in res.output


def _rgbd_folder(root: Path, camera: str) -> Path:
    import cv2

    (root / "color").mkdir(parents=True)
    (root / "depth").mkdir()
    cv2.imwrite(str(root / "color" / "0.png"), np.full((8, 10, 3), 100, np.uint8))
    cv2.imwrite(str(root / "depth" / "0.png"), np.full((8, 10), 1500, np.uint16))
    (root / "camera.yaml").write_text(camera)
    return root


CAMERA = "fx: 5\nfy: 5\ncx: 4.5\ncy: 3.5\ndepth_scale: 1000\n"


@pytest.mark.parametrize(
    ("change", "field", "expected"),
    [
        ("depth_scale: 0", "depth_scale", "> 0"),
        ("depth_scale: -1000", "depth_scale", "> 0"),
        ("depth_scale: .nan", "depth_scale", "> 0"),
        ("cx: 10.5", "cx", "in [0, 10]"),
        ("cx: -1", "cx", "in [0, 10]"),
        ("cy: 9", "cy", "in [0, 8]"),
        ("width: .inf", "width", "an integer in [1, 100000]"),
        ("width: .nan", "width", "an integer in [1, 100000]"),
        ("height: 0", "height", "an integer in [1, 100000]"),
        ("fx: 0", "fx", "> 0"),
    ],
)
def test_camera_yaml_domains(
    change: str, field: str, expected: str, runner: Any, tmp_path: Path
) -> None:
    """camera.yaml fields outside their domains (``width: .inf`` was an internal error)."""
    key = change.split(":")[0]
    text = "".join(line + "\n" for line in CAMERA.splitlines() if not line.startswith(key + ":"))
    folder = _rgbd_folder(tmp_path / "seq", text + change + "\n")
    res = run_case(runner, tmp_path, ["planes", "extract", folder])
    line = res.output.strip()
    assert res.exit_code == 2 and "\n" not in line, res.output
    assert "camera.yaml" in line and f"'{field}'" in line and expected in line, line


@pytest.mark.parametrize(
    ("change", "field"),
    [("doffs=nan", "doffs"), ("ndisp=-16", "ndisp"), ("ndisp=12.5", "ndisp"),
     ("width=inf", "width"), ("baseline=0", "baseline")],
)  # fmt: skip
def test_middlebury_calib_domains(
    change: str, field: str, inputs: Inputs, runner: Any, tmp_path: Path
) -> None:
    """A Middlebury calib.txt with a field outside its domain: an error naming it."""
    import cv2

    h, w = cv2.imread(str(inputs.left), cv2.IMREAD_UNCHANGED).shape[:2]
    fields = {
        "cam0": f"[40 0 {w / 2}; 0 40 {h / 2}; 0 0 1]",
        "cam1": f"[40 0 {w / 2}; 0 40 {h / 2}; 0 0 1]",
        "doffs": "0", "baseline": "200", "width": str(w), "height": str(h), "ndisp": "32",
    }  # fmt: skip
    key, value = change.split("=")
    fields[key] = value
    calib = tmp_path / "calib.txt"
    calib.write_text("".join(f"{k}={v}\n" for k, v in fields.items()))
    args = ["stereo", "disparity", inputs.left, inputs.right, "--calib", calib]
    res = run_case(runner, tmp_path, args)
    assert res.exit_code == 2 and "calib.txt" in res.output and f"'{field}'" in res.output
