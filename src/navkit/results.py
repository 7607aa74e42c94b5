"""The online objects' result contract (``docs/architecture.md``, "Online objects").

Every capability's online object takes one observation per call through one verb,
``update(observation, ...)``, and returns either a typed result (a subclass of :class:`Result`)
or a typed failure (a subclass of :class:`Failure`) that names its reason and, for a motion or a
pose, the degrees of freedom it leaves free: never a status string, a bool or ``None``.

Both bases are field-less mixins: each capability's frozen dataclass declares the fields in its
own order, and ``isinstance(r, Failure)`` (or ``r.ok``) tells the two apart anywhere::

    r = odometry.update(frame)
    if isinstance(r, Failure):
        log.warning("%s (free: %s)", r.reason, ", ".join(r.free_dof))
"""

from __future__ import annotations

import warnings
from typing import ClassVar

__all__ = ["Failure", "Result", "deprecated_alias"]


class Result:
    """Base of an online object's typed result (``ok`` is True)."""

    __slots__ = ()
    ok: ClassVar[bool] = True


class Failure:
    """Base of an online object's typed failure (``ok`` is False).

    Attributes
    ----------
    reason : str
        Why the observation gave no result, in words a log reader understands.
    free_dof : tuple of str
        The degrees of freedom the observation left undetermined (``tx`` ... ``rz``,
        ``x``, ``y``, ``theta``, ...); empty where the failure is not about a pose.
    """

    __slots__ = ()
    ok: ClassVar[bool] = False
    reason: str
    free_dof: tuple[str, ...]


def deprecated_alias(old: str, new: str) -> None:
    """Warn that ``old`` is a deprecated alias of ``new`` (kept for one release)."""
    warnings.warn(
        f"{old} is deprecated and will be removed in the next release; use {new}",
        DeprecationWarning,
        stacklevel=3,
    )
