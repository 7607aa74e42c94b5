"""A screenshot of Rerun's web viewer showing a recording (the pictures of ``docs/runtime.md``).

``python -m benchmarks.rerun_screenshot FILE OUT.png [--timeout 300] [--size 1400x900]
[--blueprint FILE.rbl]``

``FILE`` is anything ``rerun`` opens (an ``.rrd``, or ``results.mcap`` read by Rerun's own MCAP
importer). Serves it with ``rerun FILE --serve-web`` and loads the viewer in headless Chromium
(SwiftShader WebGL, a throw-away profile) driven over the DevTools protocol (a minimal WebSocket
client from the standard library). The capture waits for the recording itself, not for a fixed
time, since on a loaded machine the viewer shows its start page for a minute or more before the
data arrives:

1. the viewer's ``WebHandle`` (``window._handle``) has an active recording: its
   ``save_recording()`` encodes it (it throws while there is none, i.e. on the start page), and
   the encoded size has stopped growing over ``--stable`` successive polls (the stream is in);
2. two successive captures of the page are equal (the 3D view has settled after fitting its
   camera to the data) and the picture is not blank.

Nothing is written unless both hold before ``--timeout``: the script then fails with what it was
waiting for (the viewer never loaded, crashed, showed no recording, or kept changing). Both
processes are ended by their own ids.
"""

from __future__ import annotations

import argparse
import base64
import json
import os
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
import urllib.request
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

# what the page says about the viewer: loading (no handle yet), crashed, no recording (the start
# page), or the size of the active recording encoded as .rrd
_STATE_JS = """(() => {
  const h = window._handle;
  if (!h) return {state: "loading"};
  if (h.has_panicked()) return {state: "panicked", detail: String(h.panic_message())};
  try { return {state: "recording", bytes: h.save_recording().length}; }
  catch (e) { return {state: "no recording", detail: String(e)}; }
})()"""

# two captures this close (mean absolute difference, 0-255 grey levels) show the same picture;
# a settled WebGL view redraws to the same pixels, a moving camera or streaming data does not
SAME_PICTURE = 0.5
# a capture whose pixels spread less than this (standard deviation, grey levels) is blank
BLANK_STD = 2.0


class ScreenshotError(RuntimeError):
    """The viewer never showed the recording (the message says what was missing)."""


class _WebSocket:
    """Just enough of RFC 6455 for the DevTools protocol (text frames, client masking)."""

    def __init__(self, url: str) -> None:
        rest = url.split("://", 1)[1]
        hostport, path = rest.split("/", 1)
        host, port = hostport.split(":")
        self.sock = socket.create_connection((host, int(port)), timeout=300)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall(
            (
                f"GET /{path} HTTP/1.1\r\nHost: {hostport}\r\nUpgrade: websocket\r\n"
                f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                "Sec-WebSocket-Version: 13\r\n\r\n"
            ).encode()
        )
        resp = b""
        while b"\r\n\r\n" not in resp:
            resp += self.sock.recv(4096)
        if b" 101 " not in resp.split(b"\r\n", 1)[0]:
            raise ScreenshotError(f"DevTools WebSocket handshake failed: {resp[:200]!r}")
        self.buf = resp.split(b"\r\n\r\n", 1)[1]
        self.next_id = 0

    def _recv_exact(self, n: int) -> bytes:
        while len(self.buf) < n:
            chunk = self.sock.recv(1 << 20)
            if not chunk:
                raise ScreenshotError("the DevTools connection closed (Chromium exited?)")
            self.buf += chunk
        out, self.buf = self.buf[:n], self.buf[n:]
        return out

    def send(self, obj: dict) -> None:
        data = json.dumps(obj).encode()
        head = bytes([0x81])
        n = len(data)
        if n < 126:
            head += bytes([0x80 | n])
        elif n < 1 << 16:
            head += bytes([0x80 | 126]) + struct.pack(">H", n)
        else:
            head += bytes([0x80 | 127]) + struct.pack(">Q", n)
        mask = os.urandom(4)
        self.sock.sendall(head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(data)))

    def recv(self) -> dict:
        payload = b""
        while True:
            b0, b1 = self._recv_exact(2)
            n = b1 & 0x7F
            if n == 126:
                n = struct.unpack(">H", self._recv_exact(2))[0]
            elif n == 127:
                n = struct.unpack(">Q", self._recv_exact(8))[0]
            payload += self._recv_exact(n)
            if b0 & 0x80:
                return json.loads(payload)

    def call(self, method: str, **params: object) -> dict:
        self.next_id += 1
        self.send({"id": self.next_id, "method": method, "params": params})
        while True:
            msg = self.recv()
            if msg.get("id") == self.next_id:
                if "error" in msg:
                    raise ScreenshotError(f"DevTools {method} failed: {msg['error']}")
                return msg


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def parse_size(size: str) -> tuple[int, int]:
    """``"WxH"`` as ``(W, H)`` pixels (each 200-4000)."""
    try:
        w, h = (int(v) for v in size.lower().split("x"))
    except ValueError:
        raise ValueError(
            f"--size {size!r}: expected WIDTHxHEIGHT in pixels, e.g. 1400x900"
        ) from None
    if not (200 <= w <= 4000 and 200 <= h <= 4000):
        raise ValueError(f"--size {size!r}: each side must be 200-4000 pixels")
    return w, h


def same_picture(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two captures show the same picture (see :data:`SAME_PICTURE`)."""
    if a.shape != b.shape:
        return False
    return float(np.abs(a.astype(np.int16) - b.astype(np.int16)).mean()) < SAME_PICTURE


def is_blank(img: np.ndarray) -> bool:
    """Whether a capture is one flat colour (see :data:`BLANK_STD`)."""
    return float(img.std()) < BLANK_STD


@dataclass
class _Viewer:
    ws: _WebSocket

    def state(self) -> dict:
        r = self.ws.call("Runtime.evaluate", expression=_STATE_JS, returnByValue=True)
        res = r["result"]
        if "exceptionDetails" in res:
            return {"state": "loading", "detail": str(res["exceptionDetails"])[:200]}
        return dict(res["result"].get("value") or {"state": "loading"})

    def capture(self) -> tuple[bytes, np.ndarray]:
        shot = self.ws.call("Page.captureScreenshot", format="png")
        png = base64.b64decode(shot["result"]["data"])
        img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_GRAYSCALE)
        return png, img


def wait_for_recording(
    viewer: _Viewer, deadline: float, poll_s: float, stable: int
) -> tuple[bytes, dict]:
    """Poll until the recording is in and drawn (see the module docstring); the PNG and the
    last state. Raises :class:`ScreenshotError` at ``deadline``."""
    sizes: list[int] = []
    last: dict = {"state": "loading"}
    while time.monotonic() < deadline:
        last = viewer.state()
        if last["state"] == "panicked":
            raise ScreenshotError(f"the Rerun viewer crashed: {last.get('detail', '')}")
        if last["state"] == "recording":
            sizes.append(int(last["bytes"]))
            if len(sizes) > stable and len(set(sizes[-stable - 1 :])) == 1:
                break
        else:
            sizes.clear()
        time.sleep(poll_s)
    else:
        raise ScreenshotError(_never(last, sizes))
    prev: np.ndarray | None = None
    while time.monotonic() < deadline:
        png, img = viewer.capture()
        if prev is not None and same_picture(prev, img) and not is_blank(img):
            return png, last
        prev = img
        time.sleep(poll_s)
    raise ScreenshotError(
        "the recording is loaded but the picture kept changing or stayed blank until the timeout"
    )


def _never(last: dict, sizes: list[int]) -> str:
    if last["state"] == "loading":
        return "the Rerun web viewer never finished loading (no WebHandle) before the timeout"
    if last["state"] == "no recording":
        return (
            "the viewer showed its start page until the timeout: no recording arrived "
            f"({last.get('detail', '')})"
        )
    return f"the recording was still growing at the timeout (encoded sizes {sizes[-4:]})"


def screenshot(
    path: Path,
    png: Path,
    timeout_s: float = 300.0,
    size: str = "1400x900",
    blueprint: Path | None = None,
    poll_s: float = 3.0,
    stable: int = 2,
) -> dict:
    """Serve ``path`` in Rerun's web viewer and save a screenshot of it to ``png`` once the
    recording is shown (see the module docstring); returns the viewer's last state."""
    w, h = parse_size(size)
    for p, what in ((path, "the recording"), (blueprint, "--blueprint")):
        if p is not None and not Path(p).is_file():
            raise FileNotFoundError(f"{what} {p}: no such file")
    if not png.parent.is_dir():
        raise FileNotFoundError(f"{png.parent}: no such folder for the screenshot")
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        raise ScreenshotError("chromium is not on PATH (apt-get install chromium)")
    web, grpc, cdp = _free_port(), _free_port(), _free_port()
    files = [str(path)] + ([str(blueprint)] if blueprint is not None else [])
    profile = tempfile.mkdtemp(prefix="rerun-shot-")
    rerun = subprocess.Popen(
        [
            *(sys.executable, "-m", "rerun", *files, "--serve-web"),
            *("--web-viewer-port", str(web), "--port", str(grpc)),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    chrome = subprocess.Popen(
        [
            *(chromium, "--headless=new", "--no-sandbox", f"--user-data-dir={profile}"),
            *("--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist"),
            *(f"--window-size={w},{h}", f"--remote-debugging-port={cdp}", "about:blank"),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + timeout_s
    try:
        page = None
        while page is None:
            try:
                pages = json.loads(urllib.request.urlopen(f"http://127.0.0.1:{cdp}/json").read())
                page = next(p for p in pages if p.get("type") == "page")
            except (OSError, StopIteration):
                if time.monotonic() > deadline or chrome.poll() is not None:
                    raise ScreenshotError("Chromium's DevTools endpoint never came up") from None
                time.sleep(1.0)
        ws = _WebSocket(page["webSocketDebuggerUrl"])
        ws.call("Page.enable")
        ws.call(
            "Emulation.setDeviceMetricsOverride",
            width=w,
            height=h,
            deviceScaleFactor=1,
            mobile=False,
        )
        url = (
            f"http://127.0.0.1:{web}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc}%2Fproxy"
            "&renderer=webgl&persist=0&hide_welcome_screen"
        )
        ws.call("Page.navigate", url=url)
        data, state = wait_for_recording(_Viewer(ws), deadline, poll_s, stable)
        png.write_bytes(data)
        return state
    finally:
        for proc in (chrome, rerun):
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
        shutil.rmtree(profile, ignore_errors=True)


def eye_blueprint(eye: str, rbl: Path, application_id: str = "navkit") -> Path:
    """navkit's blueprint with the camera placed by ``eye`` (``"X,Y,Z,TX,TY,TZ"``), saved to
    ``rbl`` for the recordings of ``application_id`` (the Rerun logger's)."""
    try:
        v = [float(x) for x in eye.split(",")]
    except ValueError:
        v = []
    if len(v) != 6 or not np.all(np.isfinite(v)):
        raise ValueError(f"--eye {eye!r}: expected six numbers X,Y,Z,TX,TY,TZ (metres)")
    from navkit.viz.rerun_logger import blueprint

    blueprint(eye=v[:3], look_at=v[3:]).save(application_id, str(rbl))
    return rbl


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.rerun_screenshot")
    ap.add_argument("path", type=Path, help="an .rrd, or an .mcap for Rerun's MCAP importer")
    ap.add_argument("png", type=Path)
    ap.add_argument("--timeout", type=float, default=300.0, help="seconds before giving up")
    ap.add_argument("--size", default="1400x900", help="WIDTHxHEIGHT of the page, pixels")
    ap.add_argument("--blueprint", type=Path, default=None, help="an .rbl served beside it")
    ap.add_argument(
        "--eye",
        default=None,
        help="X,Y,Z,TX,TY,TZ: the camera at X,Y,Z looking at TX,TY,TZ (metres in map), through "
        "navkit's blueprint (navkit.viz.rerun_logger.blueprint) served beside the recording",
    )
    a = ap.parse_args(argv)
    t0 = time.monotonic()
    try:
        with tempfile.TemporaryDirectory(prefix="rerun-shot-") as tmp:
            bp = a.blueprint
            if a.eye is not None:
                bp = eye_blueprint(a.eye, Path(tmp) / "eye.rbl")
            state = screenshot(a.path, a.png, a.timeout, a.size, bp)
    except (ScreenshotError, FileNotFoundError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(
        f"{a.png}: the recording ({state['bytes']} bytes encoded) after "
        f"{time.monotonic() - t0:.0f} s"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
