"""The run loop: a recording's messages, one at a time in time order, through the stages.

Outputs of a run in ``out``:

- ``settings.toml``: the resolved pipeline (written first, so a killed run has it too);
- ``frames.jsonl``: one JSON line per (capability, message) with the stage's per-frame record,
  appended and flushed per source item (a killed run's lines are complete up to its last item);
- ``results.mcap``: every output as ROS 2 messages (:mod:`navkit.io.results_mcap`); during the
  run they go to crash-safe segments in ``.navkit-run/`` that are merged at the end;
- the per-capability files of today's commands (``obstacles/``, ``wall_map/``, ``path/``,
  ``planes/``);
- ``summary.json``: per capability the messages, frames, work per frame and real-time factor
  (its sensor's period from the frames' stamps / its work per frame), and the whole run's.

Checkpoints (``.navkit-run/checkpoint.pkl``, written atomically every ``run.checkpoint_every``
source items): the stages' state (pickled as is: the online objects are plain Python/NumPy),
the pose buffer, the messages waiting for a pose, the statistics, the next source item, the size
of ``frames.jsonl`` and the number of closed result segments. ``resume=True`` restores it,
truncates ``frames.jsonl`` to that size, drops the unfinished segment and continues from the next
item: processing is deterministic, so the final results equal an uninterrupted run's. The
checkpoint is a pickle written by navkit itself into the output folder: only resume runs you made.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os
import pickle
import shutil
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

from navkit.errors import ConfigError, InputError
from navkit.jit import implementation
from navkit.runtime.capabilities import PoseBuffer, StageResult, build_stages, needs_pose, route
from navkit.runtime.messages import Message, Output
from navkit.runtime.pipeline import Pipeline, resolve_pipeline
from navkit.runtime.sources import Source, open_source

__all__ = ["STATE_DIR", "NullLogger", "RunInterrupted", "interrupted_state", "run_recording"]

log = logging.getLogger(__name__)

STATE_DIR = ".navkit-run"
# 4: the published TF tree in the state
CHECKPOINT_VERSION = 4


class RunInterrupted(Exception):
    """Ctrl-C (SIGINT) stopped a run between two source items, after a checkpoint: ``resume=True``
    continues it. ``item``: source items done; ``n_items``: the source's items (0 = unknown)."""

    def __init__(self, out: Path, item: int, n_items: int) -> None:
        self.out, self.item, self.n_items = out, item, n_items
        of = f" of {n_items}" if n_items else ""
        super().__init__(f"interrupted after {item}{of} source items; the run in {out} is saved")


class _StopOnSigint:
    """While open (in the main thread): a first SIGINT asks the loop to stop after the current
    item (:attr:`requested`); a second one interrupts at once (``KeyboardInterrupt``, the last
    periodic checkpoint stays)."""

    def __init__(self) -> None:
        self.requested = False
        self.previous: Any = None

    def _handle(self, _signum: int, _frame: Any) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True
        log.warning("Ctrl-C: stopping after the current item (Ctrl-C again to stop now)")

    def __enter__(self) -> _StopOnSigint:
        import signal
        import threading

        if threading.current_thread() is threading.main_thread():
            self.previous = signal.signal(signal.SIGINT, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        import signal

        if self.previous is not None:
            signal.signal(signal.SIGINT, self.previous)


def interrupted_state(out: str | os.PathLike[str]) -> int | None:
    """The next source item of the checkpoint a killed or interrupted run left in ``out`` (what
    ``--resume`` continues from), or None when there is none."""
    f = Path(out) / STATE_DIR / "checkpoint.pkl"
    if not f.is_file():
        return None
    try:
        with open(f, "rb") as fh:
            data = pickle.load(fh)
        return int(data["state"].next_item)
    except Exception:  # an unreadable checkpoint: --resume will say why
        return None


class NullLogger:
    """A viewer that shows nothing: the run loop always calls a logger (kiss-icp style)."""

    def set_time(self, stamp_ns: int) -> None:
        """Move the viewer's timeline to ``stamp_ns``."""

    def log_output(self, _output: Output) -> None:
        """Show one output."""

    def log_message(self, msg: Message) -> None:
        """Show one input message (points, scans, poses)."""

    def close(self) -> None:
        """Finish (flush a recording)."""


# the message kind that is one frame of each capability's sensor: a colour image and a
# CameraInfo are part of an RGB-D frame, its depth image is the frame
FRAME_KINDS = frozenset({"cloud", "scan", "depth", "pose"})


@dataclasses.dataclass
class _Stats:
    """One capability's work: messages handled, frames among them, seconds of work (handling
    and finishing), first and last frame stamp."""

    n: int = 0
    seconds: float = 0.0
    cpu_seconds: float = 0.0  # CPU time of the loop's thread (a loaded machine's wall time
    # counts the other processes' turns too)
    frames: int = 0
    first_ns: int | None = None
    last_ns: int | None = None

    def add_frame(self, stamp_ns: int) -> None:
        self.frames += 1
        self.first_ns = stamp_ns if self.first_ns is None else min(self.first_ns, stamp_ns)
        self.last_ns = stamp_ns if self.last_ns is None else max(self.last_ns, stamp_ns)

    def figures(self) -> dict[str, Any]:
        """``messages``, ``frames``, ``seconds``, ``ms_per_message``, ``ms_per_frame``,
        ``sensor_period_s`` (mean spacing of the frames' stamps) and ``real_time_factor`` =
        sensor period / work per frame (above 1: the capability keeps up with its sensor; None
        with fewer than two frames or no measurable work)."""
        period = (
            (self.last_ns - self.first_ns) * 1e-9 / (self.frames - 1)
            if self.frames > 1 and self.first_ns is not None and self.last_ns is not None
            else None
        )
        per_frame = self.seconds / self.frames if self.frames else None
        return {
            "messages": self.n,
            "frames": self.frames,
            "seconds": self.seconds,
            "ms_per_message": 1e3 * self.seconds / max(self.n, 1),
            "ms_per_frame": None if per_frame is None else 1e3 * per_frame,
            "cpu_ms_per_frame": 1e3 * self.cpu_seconds / self.frames if self.frames else None,
            "sensor_period_s": period,
            "real_time_factor": period / per_frame if period and per_frame else None,
        }


@dataclasses.dataclass
class _State:
    next_item: int = 0
    frames_bytes: int = 0
    segments: int = 0  # closed result segments
    stages: dict[str, Any] = dataclasses.field(default_factory=dict)
    poses: PoseBuffer = dataclasses.field(default_factory=PoseBuffer)
    pending: deque[Message] = dataclasses.field(default_factory=deque)
    stats: dict[str, _Stats] = dataclasses.field(default_factory=dict)
    first_ns: int | None = None
    last_ns: int | None = None
    n_messages: int = 0
    failures: int = 0
    tf_out: Any = None  # navkit.runtime.tf.TfPublisher: the TF tree written to results.mcap


class _Run:
    def __init__(self, pipe: Pipeline, out: Path, logger: Any, state: _State) -> None:
        from navkit.runtime.segments import SegmentWriter

        self.pipe, self.out, self.logger, self.s = pipe, out, logger, state
        self.state_dir = out / STATE_DIR
        self.seg_dir = self.state_dir / "segments"
        self.seg_dir.mkdir(parents=True, exist_ok=True)
        self.writer = SegmentWriter(self._segment(state.segments))
        self.frames = open(out / "frames.jsonl", "ab")
        self.log_seconds = 0.0
        self.write_seconds = 0.0

    def _segment(self, k: int) -> Path:
        return self.seg_dir / f"segment-{k:05d}.mcap"

    def write(self, outputs: list[Output]) -> None:
        """Write outputs to results.mcap and the viewer; before an output in a frame not yet
        linked to ``map`` the TF tree gets its link (:meth:`TfPublisher.link`), and transforms
        (kind ``tf``) join the published tree."""
        from navkit.io.results_mcap import ROS_TYPES

        tf_out = self.s.tf_out
        t0 = time.perf_counter()
        todo: list[Output] = []
        for o in outputs:
            if o.kind == "tf":
                for child, T in o.data:
                    tf_out.add(o.topic, o.frame_id, child, o.stamp_ns, T)
            else:
                todo += tf_out.link(o.frame_id, o.stamp_ns)
            todo.append(o)
        for o in todo:
            if o.kind in ROS_TYPES:  # textured planes are for the viewer only
                self.writer.write(o.topic, o.kind, o.stamp_ns, o.frame_id, o.data)
        t1 = time.perf_counter()
        for o in todo:
            if o.kind == "pose_cov":
                o = Output(o.topic, "pose", o.stamp_ns, o.frame_id, o.data[0])
            self.logger.log_output(o)
        self.log_seconds += time.perf_counter() - t1
        self.write_seconds += t1 - t0

    def emit(self, res: StageResult, cap: str, msg: Message | None, item: int) -> None:
        self.write(res.outputs)
        if res.record is not None:
            line: dict[str, Any] = {"capability": cap, "item": item}
            if msg is not None:
                line.update(topic=msg.topic, stamp_ns=msg.stamp_ns)
            line.update(res.record)
            self.frames.write((json.dumps(line, default=_jsonable) + "\n").encode())

    def process(self, msg: Message, item: int) -> None:
        for stage in route(self.pipe, self.s.stages, msg):
            t0, c0 = time.perf_counter(), time.thread_time()
            try:
                res = stage.handle(msg, self.s.poses)
            except InputError as exc:  # a bad frame is reported, never written as a result
                self.s.failures += 1
                log.warning("%s: %s at %d ns failed: %s", stage.name, msg.topic, msg.stamp_ns, exc)
                res = StageResult(record={"failed": str(exc)})
            # the capability's work: handling the message and serialising its outputs (the
            # viewer's time excluded, counted apart)
            log0 = self.log_seconds
            self.emit(res, stage.name, msg, item)
            dt = time.perf_counter() - t0
            st = self.s.stats.setdefault(stage.name, _Stats())
            st.n += 1
            st.seconds += dt - (self.log_seconds - log0)
            st.cpu_seconds += time.thread_time() - c0
            if msg.kind in FRAME_KINDS:
                st.add_frame(msg.stamp_ns)

    def ready(self, msg: Message) -> bool:
        poses = self.s.poses
        for topic in needs_pose(self.pipe, self.s.stages, msg):
            latest = poses.latest_stamp(topic)
            if latest is None or latest < msg.stamp_ns:
                return False
            if not poses.tf_ready(topic, msg.stamp_ns, msg.frame_id):
                return False
        return True

    def drain(self, item: int, force: bool = False) -> None:
        p = self.s.pending
        while p and (force or self.ready(p[0]) or len(p) > self.pipe.run.max_pending):
            self.process(p.popleft(), item)

    def feed(self, msg: Message, item: int) -> None:
        s = self.s
        s.n_messages += 1
        s.first_ns = msg.stamp_ns if s.first_ns is None else min(s.first_ns, msg.stamp_ns)
        s.last_ns = msg.stamp_ns if s.last_ns is None else max(s.last_ns, msg.stamp_ns)
        t0 = time.perf_counter()
        self.logger.set_time(msg.stamp_ns)
        self.logger.log_message(msg)
        self.log_seconds += time.perf_counter() - t0
        if msg.kind == "tf":
            s.poses.add_tf(msg)
            # passed through to results.mcap as it came (topic, stamp, frames)
            tf = [(msg.child_frame_id, msg.data)]
            self.write([Output(msg.topic, "tf", msg.stamp_ns, msg.frame_id, tf)])
            self.drain(item)
        elif msg.kind == "pose":
            s.poses.add(msg)
            self.write(
                s.tf_out.pose(msg.topic, msg.stamp_ns, msg.frame_id, msg.child_frame_id, msg.data)
            )
            self.process(msg, item)
            self.drain(item)
        elif not route(self.pipe, s.stages, msg):
            return
        elif s.pending or not self.ready(msg):
            s.pending.append(msg)
            self.drain(item)
        else:
            self.process(msg, item)

    def end_item(self, item: int) -> None:
        self.frames.flush()
        self.writer.flush()
        self.s.next_item = item + 1

    def checkpoint(self) -> None:
        """Close the current segment, make everything durable, save the state, start a segment."""
        from navkit.runtime.segments import SegmentWriter

        self.flush_files()
        self.writer.close()
        self.frames.flush()
        os.fsync(self.frames.fileno())
        self.s.segments += 1
        self.s.frames_bytes = self.frames.tell()
        # not through navkit.io.atomic: the checkpoint is the run's own state, kept when the
        # command is interrupted (an output transaction would roll it back)
        target = self.state_dir / "checkpoint.pkl"
        tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
        with open(tmp, "wb") as fh:
            pickle.dump(
                {"version": CHECKPOINT_VERSION, "pipeline": _pipe_dict(self.pipe), "state": self.s},
                fh,
            )
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, target)
        self.writer = SegmentWriter(self._segment(self.s.segments))

    def flush_files(self) -> None:
        """Wait for the stages' per-frame files (written by their writer threads)."""
        for stage in self.s.stages.values():
            if hasattr(stage, "flush"):
                stage.flush()

    def close(self) -> None:
        try:
            for stage in self.s.stages.values():
                if hasattr(stage, "close"):
                    stage.close()
        finally:
            self.writer.close()
            self.frames.close()


def _tf_publisher(pipe: Pipeline) -> Any:
    """The TF tree of results.mcap: the pose topics that publish their edges (the reference
    too, unless localization runs: then ``map`` is the localization's)."""
    from navkit.runtime.tf import TfPublisher

    t = pipe.topics
    loc = "localization" in pipe.capabilities
    topics = tuple(
        x for x in (t.odometry, t.pose, t.reference) if x and not (loc and x == t.reference)
    )
    return TfPublisher(topics, link_map=not loc)


def _jsonable(o: Any) -> Any:
    from navkit.io.atomic import to_jsonable

    return to_jsonable(o)


def _pipe_dict(pipe: Pipeline) -> dict[str, Any]:
    return json.loads(json.dumps(dataclasses.asdict(pipe), default=_jsonable))


def _load_checkpoint(out: Path, pipe: Pipeline) -> _State:
    f = out / STATE_DIR / "checkpoint.pkl"
    if not f.is_file():
        raise InputError(
            "has no checkpoint to resume from",
            source=out,
            field="--resume",
            expected=f"the output folder of a killed run (with {STATE_DIR}/checkpoint.pkl)",
        )
    with open(f, "rb") as fh:
        data = pickle.load(fh)
    if data.get("version") != CHECKPOINT_VERSION:
        raise InputError(
            f"checkpoint version {data.get('version')}",
            source=f,
            expected=f"version {CHECKPOINT_VERSION}",
        )
    if data["pipeline"] != _pipe_dict(pipe):
        raise ConfigError(
            "the recording or settings differ from the interrupted run's",
            source=f,
            field="pipeline",
            expected="the same recording, --map and --config as the run being resumed",
        )
    state: _State = data["state"]
    frames = out / "frames.jsonl"
    with open(frames, "r+b") as fh:
        fh.truncate(state.frames_bytes)
    seg_dir = out / STATE_DIR / "segments"
    for seg in seg_dir.glob("segment-*.mcap"):
        if int(seg.stem.split("-")[1]) >= state.segments:
            seg.unlink()  # written after the checkpoint: replayed
    return state


def run_recording(
    recording: str | os.PathLike[str] | Source,
    out: str | os.PathLike[str],
    config: dict[str, Any] | None = None,
    *,
    map_path: str | os.PathLike[str] | None = None,
    resume: bool = False,
    logger: Any = None,
    on_progress: Callable[[float, float], None] | None = None,
    intrinsics: tuple[float, float, float, float] | None = None,
    depth_scale: float = 1000.0,
    config_source: str = "--config",
) -> dict[str, Any]:
    """Stream a recording through the online capabilities; returns the summary.

    Parameters
    ----------
    recording : path or Source
        Any input of :func:`navkit.runtime.sources.open_source`, or a source object (anything
        with the :class:`~navkit.runtime.sources.Source` interface, e.g. a simulator).
    out : path
        Output folder (see the module docstring for what is written).
    config : dict, optional
        The ``--config`` TOML as a dict (:mod:`navkit.runtime.pipeline`).
    map_path : path, optional
        ``map.json`` of a wall map: laser scans are localized in it.
    resume : bool
        Continue a killed run from its last checkpoint.
    logger : optional
        A viewer (:class:`NullLogger` interface, e.g. :class:`navkit.viz.rerun_logger.RerunLogger`).
    on_progress : callable, optional
        Called as ``on_progress(seconds of recording done, recording duration)`` after each item.
    intrinsics, depth_scale
        For RGB-D folders without intrinsics, and 16-bit depth units per metre.

    Raises
    ------
    InputError, ConfigError, FormatError, DataNotFoundError
        Unreadable recording, bad settings, ``resume`` without a checkpoint or with other settings.
    """
    from navkit.io.atomic import write_json, write_text
    from navkit.io.results_mcap import merge_mcap

    out = Path(out)
    logger = logger or NullLogger()
    if isinstance(recording, str | os.PathLike):
        source: Source = open_source(recording, intrinsics=intrinsics, depth_scale=depth_scale)
    else:
        source = recording
    pipe = resolve_pipeline(
        source.name,
        source.topics,
        config,
        config_source=config_source,
        map_path=str(map_path) if map_path else "",
    )
    out.mkdir(parents=True, exist_ok=True)
    if resume:
        state = _load_checkpoint(out, pipe)
        log.info("resuming %s at item %d", source.name, state.next_item)
    else:
        shutil.rmtree(out / STATE_DIR, ignore_errors=True)
        (out / "frames.jsonl").unlink(missing_ok=True)
        (out / "results.mcap").unlink(missing_ok=True)
        state = _State(stages=build_stages(pipe, out), tf_out=_tf_publisher(pipe))
        state.poses.published = state.tf_out.tree
    write_text(out / "settings.toml", _settings_toml(pipe))
    run = _Run(pipe, out, logger, state)
    duration = max((source.end_ns - source.start_ns) * 1e-9, 0.0)
    t_start = time.perf_counter()
    every = max(pipe.run.checkpoint_every, 1)
    item = state.next_item - 1
    try:
        with _StopOnSigint() as stop:
            for item, msgs in source.messages(skip=state.next_item):
                if pipe.run.max_items and item >= pipe.run.max_items:
                    item -= 1
                    break
                for msg in msgs:
                    run.feed(msg, item)
                run.end_item(item)
                if on_progress is not None and state.last_ns is not None:
                    on_progress((state.last_ns - source.start_ns) * 1e-9, duration)
                if stop.requested:
                    run.checkpoint()
                    raise RunInterrupted(out, item + 1, source.n_items)
                if (item + 1) % every == 0:
                    run.checkpoint()
        run.drain(item, force=True)
        end_ns = state.last_ns or 0
        finals = {}
        for name, stage in state.stages.items():
            t0 = time.perf_counter()
            res = stage.finish(out, end_ns)
            state.stats.setdefault(name, _Stats()).seconds += time.perf_counter() - t0
            run.emit(StageResult(res.outputs, None), name, None, item)
            finals[name] = res.record or {}
    finally:
        run.close()
        logger.close()
    wall = time.perf_counter() - t_start
    segments = sorted((out / STATE_DIR / "segments").glob("segment-*.mcap"))
    n_results = merge_mcap(segments, out / "results.mcap")
    shutil.rmtree(out / STATE_DIR, ignore_errors=True)
    # recording duration: first to last stamp plus one mean item period (3 frames at 10 Hz
    # are 0.3 s of recording, not 0.2 s)
    n_items = max(item + 1, 1)
    span = ((state.last_ns or 0) - (state.first_ns or 0)) * 1e-9
    span = span * n_items / (n_items - 1) if n_items > 1 else span
    caps: dict[str, Any] = {}
    for name, st in state.stats.items():
        caps[name] = {**st.figures(), **finals.get(name, {})}
    summary = {
        "recording": source.name,
        "capabilities": caps,
        "messages": state.n_messages,
        "failed_frames": state.failures,
        "recording_seconds": span,
        "processing_seconds_this_session": wall,
        "real_time_factor_this_session": span / wall if wall > 0 and not resume else None,
        "viewer_seconds_this_session": run.log_seconds,
        "results_mcap_messages": n_results,
        "resumed": resume,
        "topics": dataclasses.asdict(pipe.topics),
    }
    from navkit import __version__

    head = {"navkit_version": __version__, "kernels": implementation()}
    write_json(out / "summary.json", {**head, **summary})
    return summary


def _settings_toml(pipe: Pipeline) -> str:
    import tomli_w

    def clean(v: Any) -> Any:
        if isinstance(v, dict):
            return {k: clean(x) for k, x in v.items() if x is not None}
        if isinstance(v, list | tuple):
            return [clean(x) for x in v if x is not None]
        return v

    return tomli_w.dumps(clean(_pipe_dict(pipe)))
