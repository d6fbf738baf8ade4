"""Starts a real Sublevel server for the session.

The binary: $SUBLEVEL_BIN, else the newer of target/release/sublevel and target/debug/sublevel
of this checkout (build one with `cargo build --locked --bin sublevel`). It is started as
`sublevel serve --addr 127.0.0.1:0 --data-dir <tmp> --demo` (loopback only, a fresh store), its
`listening on ADDR` line is read from stdout, and it is terminated at the end of the session.
"""

from __future__ import annotations

import os
import queue
import re
import subprocess
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import List, Optional

import pytest

from sublevel_client import Client

REPO = Path(__file__).resolve().parents[3]
STARTUP_SECONDS = 60.0


def find_binary() -> Path:
    env = os.environ.get("SUBLEVEL_BIN")
    if env:
        p = Path(env)
        if not p.is_absolute() and not p.is_file():
            p = REPO / p  # relative to the repository root, as run-tests.sh is
        if not p.is_file():
            raise FileNotFoundError(f"SUBLEVEL_BIN={env} is not a file")
        return p
    candidates = [REPO / "target" / "release" / "sublevel", REPO / "target" / "debug" / "sublevel"]
    existing = [c for c in candidates if c.is_file()]
    if not existing:
        raise FileNotFoundError(
            "no server binary: build one with `cargo build --locked --bin sublevel` or set SUBLEVEL_BIN"
        )
    return max(existing, key=lambda p: p.stat().st_mtime)


@dataclass
class Server:
    addr: str
    binary: Path
    process: subprocess.Popen
    stdout_lines: List[str] = field(default_factory=list)
    log_path: Optional[Path] = None


@pytest.fixture(scope="session")
def server(tmp_path_factory):
    binary = find_binary()
    tmp = tmp_path_factory.mktemp("sublevel")
    log_path = tmp / "server.log"
    log = open(log_path, "wb")
    proc = subprocess.Popen(
        [str(binary), "serve", "--addr", "127.0.0.1:0", "--data-dir", str(tmp / "data"), "--demo"],
        stdout=subprocess.PIPE,
        stderr=log,
        stdin=subprocess.DEVNULL,
        text=True,
        env={**os.environ, "RUST_LOG": os.environ.get("RUST_LOG", "warn")},
    )
    lines: "queue.Queue[Optional[str]]" = queue.Queue()

    def pump():
        for line in proc.stdout:  # keeps draining after startup so the pipe never fills
            lines.put(line.rstrip("\n"))
        lines.put(None)

    threading.Thread(target=pump, daemon=True).start()
    seen: List[str] = []
    addr = None
    deadline = time.monotonic() + STARTUP_SECONDS
    try:
        while addr is None:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise RuntimeError(f"{binary} printed no `listening on` line within {STARTUP_SECONDS} s")
            try:
                line = lines.get(timeout=remaining)
            except queue.Empty:
                continue
            if line is None:
                raise RuntimeError(f"{binary} exited with {proc.wait()} before listening")
            seen.append(line)
            m = re.match(r"listening on (\S+)", line)
            if m:
                addr = m.group(1)
    except BaseException:
        proc.kill()
        proc.wait()
        log.close()
        tail = log_path.read_text(errors="replace")[-3000:]
        raise RuntimeError(f"server failed to start; stdout: {seen}; log tail:\n{tail}")
    assert addr.startswith("127.0.0.1:"), addr
    yield Server(addr=addr, binary=binary, process=proc, stdout_lines=seen, log_path=log_path)
    proc.terminate()
    try:
        proc.wait(timeout=15)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    log.close()


@pytest.fixture(scope="session")
def client(server):
    c = Client(server.addr, timeout=120.0)
    c.wait_ready(timeout=10.0)
    yield c
    c.close()


@dataclass
class Demo:
    scene: str
    chair: str  # instance ids
    human: str
    chair_body: str
    human_body: str


@pytest.fixture(scope="session")
def demo(client):
    scene = client.find_scene("demo")
    bodies = {b.body_id: b.name for b in client.list_bodies()}
    sc = client.get_scene(scene)
    by_name = {bodies[i.body_id]: i for i in sc.instances}
    return Demo(
        scene=scene,
        chair=by_name["chair_101"].instance_id,
        human=by_name["human_10"].instance_id,
        chair_body=by_name["chair_101"].body_id,
        human_body=by_name["human_10"].body_id,
    )


@pytest.fixture
def restore_demo(client, demo):
    """Restores the demo scene's stored poses after a test that changes them."""
    before = {i.instance_id: i.pose for i in client.get_scene(demo.scene).instances}
    yield demo
    client.set_poses(demo.scene, before)
