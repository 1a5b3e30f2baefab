"""Your camera, feeding a fairgrasp camera policy on the arm.

Serves the frames a camera policy reads over TCP, in the protocol `fairgrasp deploy
--camera-tcp` and `fairgrasp camera-check` read (docs/deployment.md, "Camera feed"): per
frame one JSON header line, then the pixels as uint8, row by row, channels together.

    pip install opencv-python numpy
    python examples/camera_feed.py --model runs/cam/student --device 0 [--wrist-device 1]
    fairgrasp camera-check --model runs/cam/student --camera-tcp 127.0.0.1:20101
    fairgrasp deploy --model runs/cam/student --camera-tcp 127.0.0.1:20101 ...

The model's `model.json` says which images it reads and their size (`pixel_actor.images`); each
camera frame is converted from OpenCV's BGR to RGB and resized to that size. Mount and aim the
camera as the model's scene camera was (`env.camera.scene` in model.json: the position, the
point it looks at, the field of view), and give its pose in the calibration file's `[camera]`
table, so that the deployment can warn when the two differ. A model that also reads a wrist
camera (`wrist_rgb`) needs that camera too (`--wrist-device`), mounted on the flange as the
model's was (`env.camera.wrist`: its offset in the TCP frame, looking along the tool's z; the
calibration file's `[wrist_camera]`). An ordinary webcam gives no depth:
depth models need a depth camera's own reader. `--synthetic` sends a moving test pattern
instead of a camera (no OpenCV needed), for checking the link.
"""

from __future__ import annotations

import argparse
import json
import socket
import threading
import time
from pathlib import Path

import numpy as np


def views(model: Path) -> list[dict]:
    """The images the model reads, from its model.json."""
    meta = json.loads((Path(model) / "model.json").read_text())
    actor = meta.get("pixel_actor")
    if actor is None:
        raise SystemExit(f"{model} is not a camera policy (its model.json has no pixel_actor)")
    return actor["images"]["views"]


def frame_bytes(name: str, image: np.ndarray, stamp: float) -> bytes:
    """One frame in the feed's protocol: the header line, then the pixels."""
    image = np.ascontiguousarray(image, dtype=np.uint8)
    height, width = image.shape[:2]
    channels = 1 if image.ndim == 2 else image.shape[2]
    header = {"camera": name, "height": height, "width": width, "channels": channels, "stamp": stamp}
    return json.dumps(header).encode() + b"\n" + image.tobytes()


class Feed:
    """Accepts clients on a thread; `send` gives each the same bytes, dropping those that fail."""

    def __init__(self, bind: str, port: int) -> None:
        self.server = socket.create_server((bind, port))
        self.clients: list[socket.socket] = []
        self.lock = threading.Lock()
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        while True:
            conn, _ = self.server.accept()
            conn.settimeout(0.2)
            with self.lock:
                self.clients.append(conn)

    def send(self, data: bytes) -> None:
        with self.lock:
            for conn in list(self.clients):
                try:
                    conn.sendall(data)
                except OSError:
                    self.clients.remove(conn)
                    conn.close()


def camera_frames(device: int):
    """RGB frames from an OpenCV camera."""
    import cv2

    capture = cv2.VideoCapture(device)
    if not capture.isOpened():
        raise SystemExit(f"cannot open camera {device}")
    while True:
        ok, bgr = capture.read()
        if not ok:
            raise SystemExit(f"camera {device} stopped giving frames")
        yield cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def synthetic_frames(row: int = 100):
    """A test pattern with a bright square moving across it at `row` (each camera its own)."""
    t = 0
    while True:
        image = np.full((240, 320, 3), 60, np.uint8)
        x = 20 + (t * 4) % 260
        image[row : row + 40, x : x + 40] = (230, 200, 40)
        t += 1
        yield image


def camera_of(view: dict) -> str:
    """Which camera a view is drawn from: `scene_rgb` -> `scene`, `wrist_rgb` -> `wrist`."""
    return view["name"].split("_")[0]


def sources(wanted: list[dict], args) -> dict:
    """A frame source per camera the model reads: the scene camera from `--device`, the wrist
    camera from `--wrist-device`; refused before any camera opens when one is missing."""
    cameras = sorted({camera_of(v) for v in wanted})
    unknown = [c for c in cameras if c not in ("scene", "wrist")]
    if unknown:
        raise SystemExit(f"the model reads images of camera(s) {unknown}; this example knows scene and wrist")
    if args.synthetic:
        return {c: synthetic_frames(100 if c == "scene" else 20) for c in cameras}
    if "wrist" in cameras and args.wrist_device is None:
        raise SystemExit("the model also reads the wrist camera (wrist_rgb): give its OpenCV index with --wrist-device")
    devices = {"scene": args.device, "wrist": args.wrist_device}
    return {c: camera_frames(devices[c]) for c in cameras}


def resize(image: np.ndarray, width: int, height: int) -> np.ndarray:
    """To the model's size: OpenCV's area filter when present, else nearest pixels."""
    try:
        import cv2

        return cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA)
    except ImportError:
        rows = np.arange(height) * image.shape[0] // height
        cols = np.arange(width) * image.shape[1] // width
        return image[rows][:, cols]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", required=True, help="the camera policy's model directory")
    parser.add_argument("--bind", default="127.0.0.1", help="address to serve on (loopback by default)")
    parser.add_argument("--port", type=int, default=20101, help="TCP port (0: any free one)")
    parser.add_argument("--device", type=int, default=0, help="the scene camera's OpenCV index")
    parser.add_argument("--wrist-device", type=int, default=None,
                        help="the wrist camera's OpenCV index (models that read wrist_rgb)")
    parser.add_argument("--synthetic", action="store_true", help="a moving test pattern, no camera")
    parser.add_argument("--fps", type=float, default=30.0)
    parser.add_argument("--seconds", type=float, default=None, help="stop after this long")
    args = parser.parse_args()

    wanted = views(Path(args.model))
    for view in wanted:
        if view["channels"] != 3:
            raise SystemExit(f"{view['name']}: {view['channels']} channels; this example sends RGB only")
    cameras = sources(wanted, args)
    feed = Feed(args.bind, args.port)
    port = feed.server.getsockname()[1]
    print(f"camera feed on {args.bind}:{port}: " + ", ".join(
        f"{v['name']} {v['height']}x{v['width']}x{v['channels']}" for v in wanted), flush=True)
    started = time.monotonic()
    period = 1.0 / args.fps
    next_due = started
    while args.seconds is None or time.monotonic() - started < args.seconds:
        images = {camera: (next(source), time.monotonic()) for camera, source in cameras.items()}
        parts = []
        for v in wanted:
            image, stamp = images[camera_of(v)]
            parts.append(frame_bytes(v["name"], resize(image, v["width"], v["height"]), stamp))
        data = b"".join(parts)
        feed.send(data)
        next_due += period
        time.sleep(max(0.0, next_due - time.monotonic()))


if __name__ == "__main__":
    main()
