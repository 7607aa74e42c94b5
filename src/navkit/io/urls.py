"""Inputs named by fsspec URLs (``file://``, ``memory://``, ``s3://``, ``gs://``, ``https://``...).

navkit's readers take local paths (NumPy, OpenCV and the format parsers read files). An input
given as a URL is read through `fsspec <https://filesystem-spec.readthedocs.io>`_ into a private
temporary file that keeps the URL's file name, the reader reads that, and the copy is deleted
when the reader is done (:func:`local_copy`). Plain paths go to the readers unchanged, with no
copy and no fsspec import. An error raised while reading names the URL, not the copy.

fsspec comes with Dask (``pip install 'navkit[cluster]'``); other protocols need their own
fsspec package (``s3fs``, ``gcsfs``, ``aiohttp``), which fsspec names when it is missing.

Decision: a copy rather than a file object, so every reader keeps one code path (and the
memory-mapped and ``np.fromfile`` readers keep working); an input is one scan, frame, log or
trajectory, so the copy is small next to the work done on it.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from navkit.errors import ConfigError, DataNotFoundError, InputError, NavkitError, require_module

__all__ = ["expand_url", "input_identity", "is_url", "local_copy", "url_name"]

_URL = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]+://")


def is_url(source: str | os.PathLike[str]) -> bool:
    """True for ``scheme://...`` (two or more letters: a Windows drive is a path, not a URL)."""
    return isinstance(source, str) and _URL.match(source) is not None


def url_name(source: str | os.PathLike[str]) -> str:
    """The last component of a path or URL (query and fragment dropped)."""
    text = str(source).split("?", 1)[0].split("#", 1)[0].rstrip("/")
    return text.rsplit("/", 1)[-1]


def _filesystem(url: str) -> tuple[Any, str]:
    fsspec = require_module("fsspec", "cluster", f"reading {url}")
    try:
        return fsspec.core.url_to_fs(url)  # type: ignore[no-any-return]
    except (ImportError, ValueError) as exc:  # unknown protocol, or its package missing
        raise ConfigError(
            f"cannot open the URL ({exc})",
            source=url,
            expected="a local path or a URL of a protocol fsspec can open "
            "(file://, memory://; s3:// needs s3fs, gs:// gcsfs, http(s):// aiohttp)",
        ) from None


@contextlib.contextmanager
def local_copy(source: str | os.PathLike[str], siblings: Sequence[str] = ()) -> Iterator[Path]:
    """A local path to read ``source`` from: the path itself, or a temporary copy of a URL.

    ``siblings``: names of files beside a URL's file that its reader opens too (a ``map.json``'s
    ``map.yaml`` and ``map.pgm``); those that exist are copied into the same private folder.

    Raises
    ------
    DataNotFoundError
        The URL names no file.
    OptionalDependencyError
        ``source`` is a URL and fsspec is not installed.
    """
    if not is_url(source):
        yield Path(source)
        return
    url = str(source)
    fs, path = _filesystem(url)
    tmp = Path(tempfile.mkdtemp(prefix="navkit-url-"))
    local = tmp / (url_name(url) or "input")
    try:
        try:
            with fs.open(path, "rb") as src, open(local, "wb") as dst:
                shutil.copyfileobj(src, dst, 1 << 20)
        except (FileNotFoundError, IsADirectoryError):
            raise DataNotFoundError(f"{url}: no such file") from None
        except OSError as exc:
            raise InputError(f"cannot be read ({exc})", source=url) from None
        folder = path.rsplit("/", 1)[0] if "/" in path else ""
        for name in siblings:
            other = f"{folder}/{name}" if folder else name
            if "/" in name or not fs.isfile(other):
                continue
            with fs.open(other, "rb") as src, open(tmp / name, "wb") as dst:
                shutil.copyfileobj(src, dst, 1 << 20)
        try:
            yield local
        except InputError as exc:  # the error names the URL, not the private copy
            if exc.source is not None and str(local) in exc.source:
                exc.source = exc.source.replace(str(local), url)
                exc.args = (exc._render(),)
            raise
        except NavkitError as exc:
            text = str(exc)
            if str(local) in text:
                raise type(exc)(text.replace(str(local), url)) from exc
            raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def input_identity(source: str | os.PathLike[str]) -> Any:
    """What a batch hashes for an input (see :func:`navkit.batch.settings_hash`): a path as it
    is (hashed with its size and modification time), a URL with its size and modification time
    or checksum as its file system reports them."""
    if not is_url(source):
        return Path(source)
    url = str(source)
    try:
        fs, path = _filesystem(url)
        info = fs.info(path)
    except (NavkitError, OSError):
        return [url]
    stamp = next(
        (info[k] for k in ("mtime", "LastModified", "last_modified", "created", "ETag", "etag")
         if info.get(k) is not None),
        None,
    )  # fmt: skip
    return [url, info.get("size"), str(stamp)]


def expand_url(url: str, suffixes: tuple[str, ...] = ()) -> list[str]:
    """The files a URL names: itself, the matches of a glob (``memory://in/*.bin``) or the files
    of a folder ending in one of ``suffixes``, sorted, each as a full URL.

    Raises
    ------
    DataNotFoundError
        Nothing matches.
    """
    fs, path = _filesystem(url)
    protocol = url.split("://", 1)[0]

    def full(p: str) -> str:
        return fs.unstrip_protocol(p) if hasattr(fs, "unstrip_protocol") else f"{protocol}://{p}"

    try:
        if any(c in path for c in "*?["):
            found = [full(p) for p in sorted(fs.glob(path)) if fs.isfile(p)]
        elif fs.isdir(path):
            found = [
                full(p)
                for p in sorted(fs.ls(path, detail=False))
                if fs.isfile(p) and p.lower().endswith(tuple(suffixes))
            ]
        elif fs.isfile(path):
            found = [url]
        else:
            found = []
    except OSError as exc:
        raise InputError(f"cannot be listed ({exc})", source=url) from None
    if not found:
        raise DataNotFoundError(
            f"{url}: no such file, folder or matching glob"
            + (f" (files ending in {', '.join(suffixes)})" if suffixes else "")
        )
    return found
