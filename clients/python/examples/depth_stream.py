"""A depth camera streaming into a scene, as a sensor bridge does it: full 640 x 480 frames sent
as point-cloud obstacles, each replacing the last, with the round trip timed.

Against a running server (``cargo run --release -- serve --demo``, default address
127.0.0.1:50051): creates a scene, then sends ``--frames`` depth frames (uint16 millimeters,
deprojected by the server through the pinhole intrinsics) at ``--rate`` Hz (0: back to back).
Each frame is synthetic and has a depth at every pixel: a camera 1.2 m from a wall, looking at it
square on, with a 40 cm box 40 cm in front of the wall and Gaussian depth noise of ``--noise``
meters drawn anew per frame. The server keeps one point per 2 cm voxel (the default filter) as
a ball of 1 cm.

    python clients/python/examples/depth_stream.py [--addr HOST:PORT] [--frames 300] [--rate 30]

Prints the median and p95 of the round trip (the call as this client sees it) and of the
server's own time on the frame, and the points kept; the scene is deleted at the end.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from sublevel_client import DEFAULT_ADDR, Client

WIDTH, HEIGHT = 640, 480
FX = FY = 554.0
CX, CY = (WIDTH - 1) / 2, (HEIGHT - 1) / 2
# The camera at (-1.2, 0, 1) in the world, looking along +x at a wall in the plane x = 0: the
# optical frame (z forward, x right, y down) as a pose [w, x, y, z, tx, ty, tz].
SENSOR = [0.5, -0.5, 0.5, -0.5, -1.2, 0.0, 1.0]


def depth_frame(rng: np.random.Generator, noise: float) -> np.ndarray:
    """One (H, W) uint16 frame in millimeters: the wall at 1.2 m, the box's face at 0.8 m."""
    u = np.arange(WIDTH)[None, :]
    v = np.arange(HEIGHT)[:, None]
    depth = np.full((HEIGHT, WIDTH), 1.2)
    # The box's front face, 0.4 m square, at 0.8 m: pixels whose ray meets it.
    x, y = (u - CX) / FX * 0.8, (v - CY) / FY * 0.8
    face = (np.abs(x) <= 0.2) & (np.abs(y) <= 0.2)
    depth = np.where(face, 0.8, depth)
    depth = depth + rng.normal(0.0, noise, depth.shape)
    return np.round(depth * 1e3).astype(np.uint16)


def percentile(samples: list[float], q: float) -> float:
    s = sorted(samples)
    return s[min(len(s) - 1, int(q * len(s)))]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--addr", default=DEFAULT_ADDR)
    parser.add_argument("--frames", type=int, default=300, help="frames timed (after 10 warm-up frames)")
    parser.add_argument("--rate", type=float, default=30.0, help="frames per second (0: back to back)")
    parser.add_argument("--noise", type=float, default=0.002, help="depth noise, meters")
    args = parser.parse_args()

    rng = np.random.default_rng(1)
    frames = [depth_frame(rng, args.noise) for _ in range(4)]
    client = Client(args.addr)
    client.wait_ready()
    scene = client.create_scene(f"depth-stream-{time.time_ns()}")
    try:
        trips, server, kept = [], [], []
        period = 1.0 / args.rate if args.rate > 0 else 0.0
        for k in range(args.frames + 10):
            t0 = time.perf_counter()
            r = client.update_point_cloud(
                scene, "camera", depth=frames[k % len(frames)], fx=FX, fy=FY, cx=CX, cy=CY, sensor_pose=SENSOR
            )
            trip = time.perf_counter() - t0
            if k >= 10:
                trips.append(trip)
                server.append(r.seconds)
                kept.append(r.counts.kept)
            if period > trip:
                time.sleep(period - trip)
        print(f"{args.frames} frames of {WIDTH} x {HEIGHT} (uint16 mm, every pixel valid) at {args.rate:g} Hz")
        print(f"  round trip     median {statistics.median(trips) * 1e3:7.2f} ms  p95 {percentile(trips, 0.95) * 1e3:7.2f} ms")
        print(f"  server seconds median {statistics.median(server) * 1e3:7.2f} ms  p95 {percentile(server, 0.95) * 1e3:7.2f} ms")
        print(f"  points kept    median {statistics.median(kept):.0f} of {WIDTH * HEIGHT}")
    finally:
        client.delete_scene(scene)
        client.close()


if __name__ == "__main__":
    main()
