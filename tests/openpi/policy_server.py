"""A small policy served by openpi's own server (PyPI openpi-server 0.1.0's WebsocketPolicyServer),
for the end-to-end tests of openpi endpoints (tests/e2e/openpi.rs).

    python3 tests/openpi/policy_server.py --mode hold [--log FILE]

prints `listening ws=127.0.0.1:PORT` once it accepts connections. Modes:
- hold: checks every observation against the default key convention (images uint8 224x224x3,
  state float32 (29,), prompt a string) and answers a (50, 10) float32 chunk that holds the hand
  where the state says it is, plus an extra key; with --log, one JSON line per observation;
- raise: the policy raises, so openpi's server sends the traceback as text and closes;
- shape: answers actions of shape (8, 7);
- hang: the third and later decisions never answer in time (the event loop sleeps);
- close: the second decision closes the connection (the server stays up, the next connects);
- silent: not openpi's server: /healthz answers 200 and connections open, but no metadata comes.

`--tls CERT KEY` serves over TLS (`wss://`, a participant's own certificate: openpi's server is
handed an SSL context) and prints `listening wss=127.0.0.1:PORT`.
"""

import argparse
import asyncio
import http
import json
import functools
import socket
import ssl
import sys
import time
import urllib.request

import numpy as np
from openpi_client import base_policy
from openpi_server import WebsocketPolicyServer

CONVENTION_IMAGES = ("observation/base_image", "observation/gripper_image")


class Policy(base_policy.BasePolicy):
    def __init__(self, mode, log):
        self.mode = mode
        self.log = log
        self.calls = 0

    def infer(self, obs):
        self.calls += 1
        if self.mode == "raise":
            raise RuntimeError("this policy always fails")
        if self.mode == "shape":
            return {"actions": np.zeros((8, 7), np.float32)}
        if self.mode == "hang" and self.calls >= 3:
            time.sleep(3600)
        if self.mode == "close" and self.calls == 2:
            import websockets

            raise websockets.ConnectionClosed(None, None)
        seen = {}
        for k in CONVENTION_IMAGES:
            im = obs[k]
            assert im.dtype == np.uint8 and im.shape == (224, 224, 3), (k, im.dtype, im.shape)
            seen[k] = [list(im.shape), str(im.dtype)]
        state = obs["observation/state"]
        assert state.dtype == np.float32 and state.shape == (29,), (state.dtype, state.shape)
        assert isinstance(obs["prompt"], str)
        if self.log:
            with open(self.log, "a") as f:
                f.write(json.dumps({"keys": sorted(obs), "images": seen, "prompt": obs["prompt"]}) + "\n")
        # STATE_FIELDS: ee_x..ee_qz are 12..18, the gripper 11: hold still where the hand is.
        hold = np.concatenate([[0.0, 0.0], state[12:19], [state[11]]]).astype(np.float32)
        return {"actions": np.tile(hold, (50, 1)), "note": "extra keys are ignored"}


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def healthy(port, cafile=None):
    scheme = "https" if cafile else "http"
    context = ssl.create_default_context(cafile=cafile) if cafile else None
    try:
        with urllib.request.urlopen(f"{scheme}://127.0.0.1:{port}/healthz", timeout=1, context=context) as r:
            return r.status == 200
    except OSError:
        return False


async def silent(port):
    import websockets.asyncio.server as server

    def health(connection, request):
        if request.path == "/healthz":
            return connection.respond(http.HTTPStatus.OK, "OK\n")
        return None

    async def handler(ws):
        await asyncio.sleep(3600)

    async with server.serve(handler, "127.0.0.1", port, process_request=health) as s:
        print(f"listening ws=127.0.0.1:{port}", flush=True)
        await s.serve_forever()


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--mode", default="hold", choices=["hold", "raise", "shape", "hang", "close", "silent"])
    p.add_argument("--log")
    p.add_argument("--tls", nargs=2, metavar=("CERT", "KEY"), help="serve wss:// with this certificate and key (PEM)")
    a = p.parse_args()
    port = free_port()
    if a.mode == "silent":
        asyncio.run(silent(port))
        return
    server = WebsocketPolicyServer(Policy(a.mode, a.log), host="127.0.0.1", port=port, metadata={"policy": a.mode})
    cafile, scheme = None, "ws"
    if a.tls:
        # openpi's server takes no TLS settings: its websockets `serve` is handed the context.
        from openpi_server import websocket_policy_server as wps

        context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
        context.load_cert_chain(*a.tls)
        wps._server.serve = functools.partial(wps._server.serve, ssl=context)
        cafile, scheme = a.tls[0], "wss"

    async def run():
        task = asyncio.create_task(server.run())
        # Ready once its health check answers.
        while not await asyncio.to_thread(healthy, port, cafile):
            await asyncio.sleep(0.05)
        print(f"listening {scheme}=127.0.0.1:{port}", flush=True)
        await task

    asyncio.run(run())


if __name__ == "__main__":
    sys.exit(main())
