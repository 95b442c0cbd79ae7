#!/usr/bin/env python3
"""A Foxglove WebSocket viewer without a screen: connects to a live view (`kitchen-r eval
--foxglove`), subscribes to every advertised topic (or those named) and reads until the server
closes, then prints messages and bytes per topic. Used to measure what publishing costs an
episode when someone watches everything (docs/twin/live.md).

    python3 scripts/foxglove-watch.py ws://127.0.0.1:8765 [TOPIC ...]
"""

import asyncio
import json
import struct
import sys
from collections import Counter

import websockets


async def watch(url: str, only: list[str]) -> None:
    counts: Counter = Counter()
    sizes: Counter = Counter()
    topics: dict[int, str] = {}
    next_sub = 0
    async with websockets.connect(url, subprotocols=["foxglove.websocket.v1"], max_size=None) as ws:
        try:
            async for m in ws:
                if isinstance(m, str):
                    msg = json.loads(m)
                    if msg["op"] != "advertise":
                        continue
                    subs = []
                    for c in msg["channels"]:
                        if only and c["topic"] not in only:
                            continue
                        topics[next_sub] = c["topic"]
                        subs.append({"id": next_sub, "channelId": c["id"]})
                        next_sub += 1
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
                elif m[0] == 1:
                    (sub,) = struct.unpack_from("<I", m, 1)
                    counts[topics[sub]] += 1
                    sizes[topics[sub]] += len(m) - 13
        except websockets.ConnectionClosed:
            pass
    for t in sorted(counts):
        print(f"{t:28} {counts[t]:7} messages {sizes[t] / 1e6:9.1f} MB")


if __name__ == "__main__":
    asyncio.run(watch(sys.argv[1], sys.argv[2:]))
