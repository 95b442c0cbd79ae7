"""Concurrent decisions through a network in one batch: gRPC Act calls of a served policy, or a
training round's rollout threads, each submit one input and wait; one thread takes up to
`max_batch` waiting inputs, runs them together and hands each caller its output (or the batch's
exception). The camera (camera/model.py) and diffusion-policy (diffusion_policy/serve.py)
baselines batch this way. A batch that arrives whole (an ActBatch call: several episodes'
decisions in one request) joins the same queue through `submit_many`, so two ActBatch calls in
flight at once (workers keep two: contract/src/batch.rs) and any concurrent Acts share one pass
of the network."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any


class RequestBatcher:
    """Runs concurrent `submit(x)` calls through `run(inputs) -> outputs` (one output per input,
    in order) in batches of up to `max_batch`. `lock` is held while a batch runs: hold it to
    change the network's weights between batches."""

    def __init__(self, run: Callable[[list[Any]], list[Any]], max_batch: int = 32):
        self.run = run
        self.max_batch = max_batch
        self.lock = threading.Lock()
        self._cond = threading.Condition()
        self._pending: list[_Request] = []
        threading.Thread(target=self._loop, daemon=True, name="request-batcher").start()

    def submit(self, x: Any) -> Any:
        """`x`'s output, once the batch it joined has run; raises what the batch raised."""
        request = _Request(x)
        with self._cond:
            self._pending.append(request)
            self._cond.notify()
        request.done.wait()
        if request.error is not None:
            raise request.error
        return request.output

    def submit_many(self, xs: list[Any]) -> list[Any]:
        """The outputs of `xs` (one per input, in order), each through the queue as `submit`:
        they run with whatever else is waiting, up to `max_batch` a pass. Raises the first
        exception of a batch they were in."""
        requests = [_Request(x) for x in xs]
        with self._cond:
            self._pending.extend(requests)
            self._cond.notify()
        for r in requests:
            r.done.wait()
        for r in requests:
            if r.error is not None:
                raise r.error
        return [r.output for r in requests]

    def _loop(self) -> None:
        while True:
            with self._cond:
                while not self._pending:
                    self._cond.wait()
                batch, self._pending = self._pending[: self.max_batch], self._pending[self.max_batch :]
            try:
                with self.lock:
                    outputs = self.run([r.input for r in batch])
                for r, y in zip(batch, outputs):
                    r.output = y
            except Exception as e:  # noqa: BLE001 — reported to each waiting caller
                logging.exception("a batch of %d decisions failed", len(batch))
                for r in batch:
                    r.error = e
            for r in batch:
                r.done.set()


class _Request:
    __slots__ = ("input", "output", "error", "done")

    def __init__(self, x: Any):
        self.input = x
        self.output: Any = None
        self.error: Exception | None = None
        self.done = threading.Event()
