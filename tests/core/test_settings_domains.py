"""Every numeric field of the capability packages' settings declares its domain, and the one
validator (:func:`navkit.geometry._validate.check_settings`) refuses the values just outside it
with an error naming the field."""

from __future__ import annotations

import dataclasses
import importlib
import math
import pkgutil

import pytest

from navkit.domains import DOMAIN_KEY, Domain
from navkit.errors import NavkitError

PACKAGES = ("obstacles", "planes", "stereo", "localization", "path")


def _settings_classes() -> list[type]:
    found: dict[str, type] = {}
    for pkg in PACKAGES:  # every module of the package, public surface or not
        package = importlib.import_module(f"navkit.{pkg}")
        for info in pkgutil.iter_modules(package.__path__):
            if info.name.startswith("_kernels"):
                continue  # compiled kernels: no settings, and importing them imports Numba
            module = importlib.import_module(f"navkit.{pkg}.{info.name}")
            for name, obj in vars(module).items():
                if (
                    isinstance(obj, type)
                    and obj.__module__ == module.__name__
                    and dataclasses.is_dataclass(obj)
                    and obj.__dataclass_params__.frozen  # type: ignore[attr-defined]
                    and name.endswith("Settings")
                ):
                    found[f"{obj.__module__}.{obj.__qualname__}"] = obj
    return [found[k] for k in sorted(found)]


def _kind(f: dataclasses.Field) -> str | None:  # type: ignore[type-arg]
    """``"int"``, ``"float"``, ``"tuple[int]"``, ``"tuple[float]"`` or None (not a number)."""
    ann = str(f.type).replace(" ", "").replace("|None", "").replace("None|", "")
    if ann in ("int", "float"):
        return ann
    if ann in ("tuple[int,...]", "tuple[float,...]"):
        return f"tuple[{ann[6:-5]}]"
    return None


CLASSES = _settings_classes()
FIELDS = [
    (cls, f)
    for cls in CLASSES
    for f in dataclasses.fields(cls)
    if _kind(f) is not None and DOMAIN_KEY in f.metadata
]


def test_the_walk_finds_the_settings_classes() -> None:
    names = {cls.__name__ for cls in CLASSES}
    for expected in (
        "ObstacleSettings",
        "DisparitySettings",
        "ExtractionSettings",
        "LocalizerSettings",
        "MatcherSettings",
        "WallMapSettings",
        "ApproximatorSettings",
        "OdometrySettings",
        "DenseSettings",
    ):
        assert expected in names


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c.__name__)
def test_every_numeric_field_declares_a_domain(cls: type) -> None:
    missing = [
        f.name
        for f in dataclasses.fields(cls)
        if _kind(f) is not None and not isinstance(f.metadata.get(DOMAIN_KEY), Domain)
    ]
    assert not missing, f"{cls.__name__}: numeric fields without a declared domain: {missing}"


def _typed(kind: str, v: float, default: object) -> object:
    """``v`` as the field holds it: an int for an int field when whole, one entry of a tuple."""
    if kind in ("int", "tuple[int]") and math.isfinite(v) and float(v).is_integer():
        v = int(v)
    if kind.startswith("tuple"):
        rest = list(default)[1:] if isinstance(default, tuple) else []  # type: ignore[arg-type]
        return (v, *rest)
    return v


@pytest.mark.parametrize(("cls", "f"), FIELDS, ids=[f"{c.__name__}.{f.name}" for c, f in FIELDS])
def test_just_outside_the_domain_is_refused_naming_the_field(
    cls: type,
    f: dataclasses.Field,  # type: ignore[type-arg]
) -> None:
    domain: Domain = f.metadata[DOMAIN_KEY]
    kind = _kind(f)
    assert kind is not None
    _, outside = domain.edges()
    assert outside, f"{cls.__name__}.{f.name}: a domain with no value outside it"
    for v in outside:
        with pytest.raises(NavkitError) as info:
            cls(**{f.name: _typed(kind, v, f.default)})
        assert f.name in str(info.value), (cls.__name__, f.name, v, str(info.value))


@pytest.mark.parametrize(("cls", "f"), FIELDS, ids=[f"{c.__name__}.{f.name}" for c, f in FIELDS])
def test_the_domain_edges_inside_are_accepted(
    cls: type,
    f: dataclasses.Field,  # type: ignore[type-arg]
) -> None:
    """The bounds themselves (and their nearest neighbours inside) are legal settings, unless a
    rule beyond the range refuses them - named here with the rule."""
    domain: Domain = f.metadata[DOMAIN_KEY]
    kind = _kind(f)
    assert kind is not None
    inside, _ = domain.edges()
    for v in inside:
        value = _typed(kind, v, f.default)
        if (cls.__name__, f.name) in _RULES and not _RULES[cls.__name__, f.name](value):
            continue
        cls(**{f.name: value})


#: Rules beyond a field's range (explicit checks in ``__post_init__``): which in-range values
#: they refuse on default settings.
_RULES = {
    # OpenCV's windows are odd
    ("DisparitySettings", "block_size"): lambda v: v % 2 == 1,
    ("DisparitySettings", "subpixel_window"): lambda v: v % 2 == 1,
    # a depth range needs min_depth < max_depth (inf by default)
    ("DenseSettings", "min_depth"): lambda v: True,
    # a height band needs min_height < max_height (0.3 .. 2 m by default)
    ("FloorplanSettings", "min_height"): lambda v: v < 2.0,
    ("FloorplanSettings", "max_height"): lambda v: v > 0.3,
    # a tile's overlap must hold the widest opening window (48 m >= 18 m by default)
    ("UnorganisedSettings", "max_object_m"): lambda v: v <= 48.0,
    ("UnorganisedSettings", "overlap_m"): lambda v: v >= 18.0,
}


def test_rules_beyond_ranges_name_the_field_and_the_rule() -> None:
    from navkit.planes.dense import DenseSettings
    from navkit.stereo import DisparitySettings

    with pytest.raises(NavkitError, match=r"block_size.*odd"):
        DisparitySettings(block_size=4)
    with pytest.raises(NavkitError, match=r"block_size.*odd and in \[5, 51\]"):
        DisparitySettings(matcher="bm", block_size=3)
    with pytest.raises(NavkitError, match=r"subpixel_window.*odd"):
        DisparitySettings(subpixel_window=8)
    with pytest.raises(NavkitError, match=r"max_depth.*min_depth < max_depth"):
        DenseSettings(min_depth=2.0, max_depth=1.0)
    from navkit.obstacles.unorganised_settings import UnorganisedSettings

    with pytest.raises(NavkitError, match=r"UnorganisedSettings.*overlap_m.*>= max_object_m"):
        UnorganisedSettings(max_object_m=30.0, overlap_m=20.0)
    assert UnorganisedSettings(max_object_m=20.0, overlap_m=20.0).overlap_m == 20.0


def test_an_error_names_the_domain() -> None:
    from navkit.obstacles import ObstacleSettings

    with pytest.raises(NavkitError, match=r"c0_deg.*is 90.0.*a number in \(0, 90\)"):
        ObstacleSettings(c0_deg=90.0)
    # "inf disables": a declared allow_inf
    assert math.isinf(ObstacleSettings(jump_range_ratio=math.inf).jump_range_ratio)
    # the class, the field, the value, the range and the unit
    from navkit.obstacles import ObstacleMapperSettings
    from navkit.path import ReturnTripSettings
    from navkit.path.control import PathFollowerSettings

    with pytest.raises(
        NavkitError, match=r"ObstacleMapperSettings.*min_ratio.*is 1.5.*\[0, 1\] \(a fraction\)"
    ):
        ObstacleMapperSettings(min_ratio=1.5)
    with pytest.raises(NavkitError, match=r"PathFollowerSettings.*v_max.*is 0.*> 0 \(m/s\)"):
        PathFollowerSettings(v_max=0.0)
    assert math.isinf(ReturnTripSettings(wait=math.inf).wait)  # "wait for ever"
    with pytest.raises(NavkitError, match=r"ReturnTripSettings.*controller"):
        ReturnTripSettings(controller={"delta": 0.3})  # type: ignore[arg-type]


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c.__name__)
def test_the_defaults_lie_in_their_domains_and_pickle(cls: type) -> None:
    """Every class builds with its defaults (each in its declared domain) and survives a pickle
    round trip (worker processes get their settings pickled), field by field."""
    import pickle

    obj = cls()
    for f in dataclasses.fields(cls):
        domain = f.metadata.get(DOMAIN_KEY)
        value = getattr(obj, f.name)
        if isinstance(domain, Domain) and value is not None and not isinstance(value, tuple):
            assert domain.contains(value), (cls.__name__, f.name, value)
    back = pickle.loads(pickle.dumps(obj))
    assert type(back) is cls
    for f in dataclasses.fields(cls):
        assert repr(getattr(back, f.name)) == repr(getattr(obj, f.name)), (cls.__name__, f.name)
