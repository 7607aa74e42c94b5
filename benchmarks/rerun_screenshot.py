"""A screenshot of Rerun's web viewer showing an ``.rrd`` (the pictures of ``docs/runtime.md``).

``python -m benchmarks.rerun_screenshot FILE.rrd OUT.png [--wait 90] [--size 1400x900]``

Serves the file with ``rerun FILE.rrd --serve-web`` and loads the viewer in headless Chromium
(SwiftShader WebGL) driven over the DevTools protocol (a minimal WebSocket client from the
standard library): navigate, wait ``--wait`` seconds of real time (the WebAssembly viewer
compiles and the recording streams in; a loaded machine needs a minute or more), capture. Both
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
import time
import urllib.request
from pathlib import Path


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
            raise RuntimeError(f"WebSocket handshake failed: {resp[:200]!r}")
        self.buf = resp.split(b"\r\n\r\n", 1)[1]
        self.next_id = 0

    def _recv_exact(self, n: int) -> bytes:
        while len(self.buf) < n:
            chunk = self.sock.recv(1 << 20)
            if not chunk:
                raise RuntimeError("DevTools connection closed")
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
                return msg


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def screenshot(rrd: Path, png: Path, wait_s: float = 90.0, size: str = "1400x900") -> None:
    """Serve ``rrd`` in Rerun's web viewer and save a screenshot of it to ``png``."""
    web, grpc, cdp = _free_port(), _free_port(), _free_port()
    rerun = subprocess.Popen(
        [
            *(sys.executable, "-m", "rerun", str(rrd), "--serve-web", "--hide-welcome-screen"),
            *("--web-viewer-port", str(web), "--port", str(grpc)),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    w, h = size.split("x")
    chrome = subprocess.Popen(
        [
            *(shutil.which("chromium") or "chromium", "--headless=new", "--no-sandbox"),
            *("--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist"),
            *(f"--window-size={w},{h}", f"--remote-debugging-port={cdp}", "about:blank"),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        time.sleep(5)
        pages = json.loads(urllib.request.urlopen(f"http://127.0.0.1:{cdp}/json").read())
        page = next(p for p in pages if p.get("type") == "page")
        ws = _WebSocket(page["webSocketDebuggerUrl"])
        ws.call("Page.enable")
        url = (
            f"http://127.0.0.1:{web}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc}%2Fproxy"
            "&renderer=webgl"
        )
        ws.call("Page.navigate", url=url)
        time.sleep(wait_s)
        shot = ws.call("Page.captureScreenshot", format="png")
        png.write_bytes(base64.b64decode(shot["result"]["data"]))
    finally:
        for proc in (chrome, rerun):
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.rerun_screenshot")
    ap.add_argument("rrd", type=Path)
    ap.add_argument("png", type=Path)
    ap.add_argument("--wait", type=float, default=90.0, help="seconds before the capture")
    ap.add_argument("--size", default="1400x900")
    a = ap.parse_args(argv)
    screenshot(a.rrd, a.png, a.wait, a.size)


if __name__ == "__main__":
    main()
