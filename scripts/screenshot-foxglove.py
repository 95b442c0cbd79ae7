#!/usr/bin/env python3
"""Screenshot of a real Foxglove-protocol client watching a live episode (docs/img/foxglove-live.png).

Serves a built Lichtblick web app (the `web/.webpack` folder of `yarn web:build:prod`, see
docs/twin/live.md "How the screenshot was taken") on loopback with a layout of its own (a 3D panel
with TF and the LiDAR cloud, both cameras in Image panels, the robot's path as an x-y Plot of
/odom, and /sub_task), replays an oracle episode live at real time
(`kitchen-r replay TRACE --foxglove --foxglove-wait`), opens the app in headless Chromium
connected to it (`?ds=foxglove-websocket&ds.url=ws://...`) and saves the page once the episode's
sim clock reaches --at seconds.

    python3 scripts/screenshot-foxglove.py --client /tmp/lichtblick/dist \
        [--out docs/img/foxglove-live.png] [--trace DIR/dev-0001.trace.json] [--at 58]

Needs Python `playwright` and a Chromium (--chromium, default /usr/bin/chromium); not run in CI.
"""

import argparse
import functools
import http.server
import json
import re
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from playwright.sync_api import sync_playwright

ROOT = Path(__file__).resolve().parent.parent

LAYOUT = {
    "configById": {
        "3D!kr": {
            "followTf": "base_link",
            "followMode": "follow-position",
            "cameraState": {
                "distance": 9,
                "perspective": True,
                "phi": 55,
                "thetaOffset": 35,
                "target": [0, 0, 0],
                "targetOffset": [0, 0, 0],
                "targetOrientation": [0, 0, 0, 1],
                "fovy": 45,
                "near": 0.05,
                "far": 5000,
            },
            "scene": {"transforms": {"labelSize": 0.12, "axisScale": 0.6}},
            "topics": {
                "/lidar/points": {
                    "visible": True,
                    "pointSize": 6,
                    "colorField": "z",  # set, or the panel picks a colour map on its own
                    "colorMode": "flat",
                    "flatColor": "#ff3d00ff",
                }
            },
            "layers": {
                "grid": {
                    "visible": True,
                    "frameLocked": True,
                    "label": "Grid",
                    "instanceId": "grid",
                    "layerId": "foxglove.Grid",
                    "size": 20,
                    "divisions": 20,
                    "lineWidth": 1,
                    "color": "#248eff",
                    "position": [0, 0, 0],
                    "rotation": [0, 0, 0],
                    "order": 1,
                }
            },
        },
        "Image!base": {"imageMode": {"imageTopic": "/camera/base/image_raw"}},
        "Image!gripper": {"imageMode": {"imageTopic": "/camera/gripper/image_raw"}},
        "Plot!path": {
            "lichtblickPanelTitle": "robot path: /odom y against x (m)",
            "paths": [
                {
                    "value": "/odom.pose.pose.position.y",
                    "enabled": True,
                    "timestampMethod": "receiveTime",
                }
            ],
            "xAxisVal": "custom",
            "xAxisPath": {"value": "/odom.pose.pose.position.x", "enabled": True},
            "showLegend": False,
            "showXAxisLabels": True,
            "showYAxisLabels": True,
            "isSynced": False,
        },
        "RawMessages!task": {"topicPath": "/sub_task", "expansion": "all"},
    },
    "globalVariables": {},
    "userNodes": {},
    "playbackConfig": {"speed": 1},
    "layout": {
        "direction": "row",
        "splitPercentage": 48,
        "first": "3D!kr",
        "second": {
            "direction": "column",
            "splitPercentage": 55,
            "first": {"direction": "row", "first": "Image!base", "second": "Image!gripper"},
            "second": {
                "direction": "row",
                "first": "Plot!path",
                "second": "RawMessages!task",
                "splitPercentage": 62,
            },
        },
    },
}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def serve_client(client: Path) -> int:
    """Serve the built app, its index.html with LAYOUT as the default layout (the hook
    Lichtblick's own Docker image fills from default-layout.json)."""
    placeholder = "/*LICHTBLICK_SUITE_DEFAULT_LAYOUT_PLACEHOLDER*/"
    index = (client / "index.html").read_text()
    if placeholder not in index:
        sys.exit(f"{client}/index.html has no {placeholder}: not a Lichtblick web build")
    index_bytes = index.replace(placeholder, json.dumps(LAYOUT)).encode()

    class Handler(http.server.SimpleHTTPRequestHandler):
        def log_message(self, *args):
            pass

        def do_GET(self):
            if self.path.split("?")[0] in ("/", "/index.html"):
                self.send_response(200)
                self.send_header("Content-Type", "text/html")
                self.send_header("Content-Length", str(len(index_bytes)))
                self.end_headers()
                self.wfile.write(index_bytes)
            else:
                super().do_GET()

    port = free_port()
    handler = functools.partial(Handler, directory=str(client))
    srv = http.server.ThreadingHTTPServer(("127.0.0.1", port), handler)
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    return port


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--client", type=Path, required=True, help="built Lichtblick web app folder")
    ap.add_argument("--out", type=Path, default=ROOT / "docs/img/foxglove-live.png")
    ap.add_argument("--trace", type=Path, help="episode trace [default: eval the first dev instruction]")
    ap.add_argument("--at", type=float, default=58.0, help="sim second to take the screenshot at")
    ap.add_argument("--bin", type=Path, default=ROOT / "target/release/kitchen-r")
    ap.add_argument("--chromium", default="/usr/bin/chromium")
    ap.add_argument("--size", default="256x256", help="camera resolution of the replay")
    args = ap.parse_args()

    tmp = tempfile.TemporaryDirectory()
    trace = args.trace
    if trace is None:
        subprocess.run(
            [str(args.bin), "eval", "--episodes", "1", "--jobs", "1", "--trace", tmp.name],
            cwd=ROOT,
            check=True,
            stdout=subprocess.DEVNULL,
        )
        trace = next(Path(tmp.name).glob("*.trace.json"))

    http_port = serve_client(args.client.resolve())
    ws_port = free_port()
    log = open(Path(tmp.name) / "replay.log", "w+")
    replay = subprocess.Popen(
        [
            str(args.bin),
            "replay",
            str(trace),
            "--foxglove",
            f"127.0.0.1:{ws_port}",
            "--foxglove-wait",
            "--size",
            args.size,
        ],
        cwd=ROOT,
        stdout=log,
        stderr=subprocess.STDOUT,
    )
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(
                executable_path=args.chromium,
                headless=True,
                # WebGL for the 3D and Image panels without a GPU
                args=["--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist"],
            )
            page = browser.new_page(viewport={"width": 1280, "height": 720})
            page.goto(f"http://127.0.0.1:{http_port}/?ds=foxglove-websocket&ds.url=ws://127.0.0.1:{ws_port}")
            page.locator('[data-testid="sidebar-close-left"]').click(timeout=60_000)
            # The replay starts when the app connects and runs at real time: wait on its clock,
            # shown in the app bar as "ws://... kitchen-r / <sim seconds>".
            deadline = time.time() + args.at + 120
            while time.time() < deadline:
                clock = re.search(r"kitchen-r\s*/\s*(\d+\.\d+)", page.locator("body").inner_text())
                if clock and float(clock[1]) >= args.at:
                    break
                if replay.poll() is not None:
                    sys.exit("the replay ended before --at")
                time.sleep(0.2)
            else:
                sys.exit("the episode's clock never reached --at")
            time.sleep(0.5)  # let the panels draw the last frames
            args.out.parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(args.out))
            browser.close()
    finally:
        replay.kill()
        replay.wait()
        log.seek(0)
        sys.stderr.write(log.read())
    print(f"wrote {args.out} ({args.out.stat().st_size // 1024} KiB)")


if __name__ == "__main__":
    main()
