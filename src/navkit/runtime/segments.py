"""The run's results segment written by a thread beside the loop.

A :class:`SegmentWriter` writes the outputs of ``navkit run`` to one unchunked segment of
``results.mcap`` (:class:`~navkit.io.results_mcap.ResultsWriter` with ``chunked=False``). The
loop hands it each output; a writer thread serialises the large ones and writes every record,
in the order handed over, while the loop goes on with the next message. Decision: a thread, as
the large outputs' work is NumPy casts and copies and the file's write calls, which run
without Python's GIL (the classified cloud: a 2 MB record built and written per KITTI frame);
the small outputs (poses, TF, grids) are serialised by the loop at once, so the thread never
reads an array the loop may still change.

- Order: records reach the file in the order :meth:`SegmentWriter.write` was called.
- :meth:`SegmentWriter.flush` asks the thread to hand everything queued so far to the OS once
  it is written (the loop does not wait); :meth:`SegmentWriter.close` waits for every record,
  writes the summary and footer, and raises the first error the thread hit
  (:class:`~navkit.errors.InputError` naming the segment). A killed run loses at most the
  records still queued (at most ``maxsize`` outputs); ``--resume`` replays from the last
  checkpoint, whose segments are closed.
- At most ``maxsize`` outputs are queued: a loop faster than the disk waits (bounded memory).
"""

from __future__ import annotations

import queue
import threading
from pathlib import Path
from typing import Any

__all__ = ["SegmentWriter"]

# serialised by the thread: their data are fresh arrays of the frame, never changed afterwards
_DEFERRED = frozenset({"classified_cloud", "markers"})


class SegmentWriter:
    """One results segment written by a thread (see the module docstring)."""

    def __init__(self, path: Path, maxsize: int = 32) -> None:
        from navkit.io.results_mcap import ResultsWriter

        self.path = Path(path)
        self._w = ResultsWriter(self.path, chunked=False)
        self._jobs: queue.Queue[Any] = queue.Queue(maxsize=maxsize)
        self._error: BaseException | None = None
        self.n_messages = 0
        self._thread = threading.Thread(target=self._serve, name="navkit-results", daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        w = self._w
        while True:
            job = self._jobs.get()
            try:
                if job is None:
                    return
                if self._error is not None:
                    continue  # after an error: drain the queue, write nothing more
                if job[0] == "flush":
                    w.flush()
                elif job[0] == "raw":
                    _, topic, msgtype, stamp_ns, raw = job
                    w.write_raw(topic, msgtype, stamp_ns, raw)
                else:
                    _, topic, kind, stamp_ns, frame_id, data = job
                    w.write(topic, kind, stamp_ns, frame_id, data)
            except BaseException as exc:  # raised in the loop's thread at the next call
                self._error = exc
            finally:
                self._jobs.task_done()

    def _check(self) -> None:
        if self._error is not None:
            from navkit.errors import InputError

            exc, self._error = self._error, None
            raise InputError(
                f"could not be written: {type(exc).__name__}: {exc}",
                source=self.path,
                expected="a writable output folder",
            ) from exc

    def write(self, topic: str, kind: str, stamp_ns: int, frame_id: str, data: Any) -> None:
        """Queue one output (:class:`~navkit.runtime.messages.Output`'s fields); an unknown
        kind is an error here, in the loop."""
        self._check()
        if kind in _DEFERRED:
            self._jobs.put(("out", topic, kind, stamp_ns, frame_id, data))
        else:
            msgtype, raw = self._w.serialize(kind, stamp_ns, frame_id, data)
            self._jobs.put(("raw", topic, msgtype, stamp_ns, raw))
        self.n_messages += 1

    def flush(self) -> None:
        """Hand every record queued so far to the OS once written (does not wait)."""
        self._check()
        self._jobs.put(("flush",))

    def close(self) -> None:
        """Wait for every queued record, write the summary and footer, close the file; raise
        the first error the thread hit."""
        if self._thread.is_alive():
            self._jobs.put(None)
            self._thread.join()
        try:
            self._check()
        finally:
            self._w.close()
