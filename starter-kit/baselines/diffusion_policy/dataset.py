"""The LeRobot v3.0 export of `kitchen-r collect --format lerobot`, decoded once into memory.

Layout read (see record/src/lerobot/mod.rs): `meta/info.json` (fps, features), `meta/tasks.parquet`
(task sentence -> task_index), `meta/episodes/chunk-*/file-*.parquet` (per episode: its rows
`dataset_from_index..dataset_to_index` and, per camera, the video file and the episode's
`from_timestamp`/`to_timestamp` in it), `meta/stats.json` (normalisation), `data/chunk-*/file-*.parquet`
(`observation.state`, `action`, `task_index`, `episode_index`, `index`) and H.264 or AV1 videos
`videos/observation.images.<cam>/chunk-*/file-*.mp4` (decoded with PyAV, in a process pool).

A training sample at row k of a task (see features.py for the timing): observation rows
(k-1, k), padded at the task's start with the frame the task started from, the task's sentence,
and the actions of rows k+1 .. k+16, padded at the task's end with its last action (the policy is
asked again after the task ends, by then for the next sentence).
"""

import json
import mmap
import multiprocessing as mp
import os
import time
from pathlib import Path

import numpy as np

from .features import CAMERAS, HORIZON, build_vocab, encode_sentence, odometry_features, resize_rgb

N_OBS = 2


def _parquets(root, sub):
    files = sorted((root / sub).glob("chunk-*/file-*.parquet"))
    if not files:
        raise SystemExit(
            f"{root / sub}: no chunk-*/file-*.parquet; is {root} a `kitchen-r collect --format lerobot` export?"
        )
    return files


def find_root(path):
    """Accept the collect output directory or its `lerobot/` subdirectory."""
    p = Path(path)
    for cand in (p, p / "lerobot"):
        if (cand / "meta" / "info.json").is_file():
            return cand
    raise SystemExit(
        f"{path}: no meta/info.json (pass the LeRobot export, e.g. OUT/lerobot of `kitchen-r collect --format lerobot`)"
    )


# Shared images of the decode pool: set in the parent before forking, written by the workers.
_SHARED: dict[str, np.ndarray] = {}


def _decode_file(job):
    """Decode one video file and write the wanted frames into the shared image array."""
    import av

    cam, path, segments, size, fps = job
    buf = _SHARED[cam]
    # segments: (first file frame, count, first destination row)
    want = {}
    for first, count, dest in segments:
        for j in range(count):
            want[first + j] = dest + j
    done = 0
    lo, hi = min(want), max(want)
    with av.open(str(path)) as c:
        s = c.streams.video[0]
        # A process per core already: one decoding thread each, not a thread per core each.
        s.codec_context.thread_count = 1
        # One episode per job and a process per core: seek to the key frame before the
        # episode's first frame instead of decoding the file from its start.
        if lo > 0:
            c.seek(int(lo / fps / s.time_base), stream=s, backward=True, any_frame=False)
        for frame in c.decode(s):
            i = int(round(float(frame.pts * s.time_base) * fps))
            if i > hi:
                break
            row = want.get(i)
            if row is None:
                continue
            buf[row] = resize_rgb(frame.to_ndarray(format="rgb24"), size)
            done += 1
    if done != len(want):
        raise RuntimeError(f"{path}: decoded {done} of {len(want)} wanted frames")
    return cam, len(want)


def _shared_array(shape):
    """A uint8 array in anonymous shared memory: forked workers write into it, no /dev/shm needed."""
    n = int(np.prod(shape))
    m = mmap.mmap(-1, max(n, 1), flags=mmap.MAP_SHARED | mmap.MAP_ANONYMOUS)
    return np.frombuffer(m, dtype=np.uint8, count=n).reshape(shape)


def _available_memory():
    """MemAvailable in bytes (0 when unknown)."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


class LeRobotExport:
    """Rows, tasks and decoded images of (the first `max_episodes` episodes of) an export."""

    def __init__(self, path, image_size=96, max_episodes=None, workers=None, episodes=None, odometry=True, log=print):
        import pyarrow.parquet as pq

        t0 = time.time()
        root = find_root(path)
        self.root = root
        self.info = json.loads((root / "meta" / "info.json").read_text())
        self.fps = float(self.info["fps"])
        self.stats = json.loads((root / "meta" / "stats.json").read_text())
        for cam in CAMERAS:
            if f"observation.images.{cam}" not in self.info["features"]:
                raise SystemExit(f"{root}: no observation.images.{cam}; collect with --cameras base,gripper")
        tasks = pq.read_table(root / "meta" / "tasks.parquet").to_pydict()
        sentence_of = dict(zip(tasks["task_index"], tasks["task"] if "task" in tasks else tasks["__index_level_0__"]))
        eps = []
        for f in _parquets(root, "meta/episodes"):
            eps.extend(pq.read_table(f).to_pylist())
        eps.sort(key=lambda e: e["episode_index"])
        if episodes is not None:
            keep = set(episodes)
            eps = [e for e in eps if e["episode_index"] in keep]
        if max_episodes:
            eps = eps[:max_episodes]
        if not eps:
            raise SystemExit(f"{root}: no episodes selected")

        cols = ["index", "episode_index", "task_index", "observation.state", "action"]
        if odometry:
            cols.append("observation.base_pose")
        parts = [pq.read_table(f, columns=cols) for f in _parquets(root, "data")]
        index = np.concatenate([p.column("index").to_numpy() for p in parts])
        order = np.argsort(index, kind="stable")
        index = index[order]

        def vec(name):
            # Fixed-size-list columns: their flat values, reshaped (no per-row Python objects).
            chunks = [c for p in parts for c in p.column(name).chunks]
            a = np.concatenate([c.flatten().to_numpy(zero_copy_only=False) for c in chunks])
            return a.reshape(len(index), -1)[order].astype(np.float32)

        all_state, all_action = vec("observation.state"), vec("action")
        if odometry:
            # (x, y, yaw) -> (x, y, cos yaw, sin yaw), by the rule serving uses.
            pose = vec("observation.base_pose")
            odo = np.stack(odometry_features(pose[:, 0], pose[:, 1], pose[:, 2]), axis=1)
            all_state = np.concatenate([all_state, odo.astype(np.float32)], axis=1)
        all_task = np.concatenate([p.column("task_index").to_numpy() for p in parts])[order]

        # The decoded images stay in memory: keep to what fits (most of the available memory).
        budget = _available_memory() * 0.7
        per_frame = 2 * image_size * image_size * 3
        need = sum(int(e["length"]) for e in eps) * per_frame
        if budget and need > budget:
            kept, total = [], 0
            for e in eps:
                if (total + int(e["length"])) * per_frame > budget:
                    break
                kept.append(e)
                total += int(e["length"])
            log(
                f"the images of {len(eps)} episodes need {need / 1e9:.0f} GB, {budget / 1e9:.0f} GB may be used: "
                f"training on the first {len(kept)}"
            )
            eps = kept

        # Rows of the selected episodes, contiguous in episode order.
        pos_of = {int(v): i for i, v in enumerate(index)} if not np.array_equal(index, np.arange(len(index))) else None
        rows, starts = [], []
        total = 0
        for e in eps:
            lo, hi = int(e["dataset_from_index"]), int(e["dataset_to_index"])
            idx = np.arange(lo, hi) if pos_of is None else np.array([pos_of[i] for i in range(lo, hi)])
            rows.append(idx)
            starts.append(total)
            total += hi - lo
        rows = np.concatenate(rows)
        self.state = all_state[rows]
        self.action = all_action[rows]
        task_ids = all_task[rows]
        self.episodes = eps
        self.ep_start = np.array(starts + [total])
        self.frames = total
        sentences = sorted({sentence_of[int(t)] for t in np.unique(task_ids)})
        self.vocab = build_vocab(sentences)
        vi = {w: i for i, w in enumerate(self.vocab)}
        self.task_words = {int(t): encode_sentence(sentence_of[int(t)], vi) for t in np.unique(task_ids)}
        self.task_ids = task_ids
        self.sentence_of = sentence_of
        self.image_size = image_size
        log(
            f"dataset {root}: {len(eps)} episodes, {total} frames, {len(sentences)} sub-task sentences, "
            f"vocabulary {len(self.vocab)}"
        )

        # Decode the videos (one job per camera and file) into shared memory.
        self.images = {}
        jobs = []
        for cam in CAMERAS:
            key = f"observation.images.{cam}"
            self.images[cam] = _shared_array((total, image_size, image_size, 3))
            _SHARED[cam] = self.images[cam]
            by_file = {}
            for e, dest in zip(eps, starts):
                ck, fi = e[f"videos/{key}/chunk_index"], e[f"videos/{key}/file_index"]
                first = int(round(e[f"videos/{key}/from_timestamp"] * self.fps))
                by_file.setdefault((ck, fi), []).append((first, int(e["length"]), dest))
            for (ck, fi), segs in sorted(by_file.items()):
                path = root / self.info["video_path"].format(video_key=key, chunk_index=ck, file_index=fi)
                # A job per episode: a file holds many episodes, and the cores should share them.
                jobs.extend((cam, path, [seg], image_size, self.fps) for seg in segs)
        workers = max(1, min(workers or os.cpu_count() or 1, len(jobs)))
        gb = 2 * total * image_size * image_size * 3 / 1e9
        log(f"decoding {len(jobs)} episode videos with {workers} processes into {gb:.1f} GB of memory")
        if workers == 1:
            for j in jobs:
                _decode_file(j)
        else:
            with mp.get_context("fork").Pool(workers) as pool:
                for _ in pool.imap_unordered(_decode_file, jobs):
                    pass
        log(f"dataset ready in {time.time() - t0:.1f} s")
        self._index_samples()

    def retokenise(self, vocab):
        """Encode the sub-task sentences with another vocabulary (a checkpoint's, to fine-tune it)."""
        vi = {w: i for i, w in enumerate(vocab)}
        self.vocab = list(vocab)
        self.task_words = {t: encode_sentence(self.sentence_of[t], vi) for t in self.task_words}

    def _index_samples(self):
        """Per sample: the row it is asked at, its history row, its task's last row and task."""
        ks, prevs, ends, tasks = [], [], [], []
        for e in range(len(self.episodes)):
            lo, hi = self.ep_start[e], self.ep_start[e + 1]
            t = self.task_ids[lo:hi]
            cuts = np.flatnonzero(np.diff(t)) + 1
            bounds = np.concatenate([[0], cuts, [hi - lo]])
            for s, en in zip(bounds[:-1], bounds[1:]):
                # The policy is first asked at the state the task starts from: the previous
                # task's last row (at the episode's start the first row stands in for it).
                first = max(s - 1, 0)
                k = np.arange(first, en - 1)
                if len(k) == 0:
                    continue
                ks.append(lo + k)
                prevs.append(lo + np.maximum(k - 1, first))
                ends.append(np.full(len(k), lo + en - 1))
                tasks.append(np.full(len(k), t[s]))
        self.s_k = np.concatenate(ks)
        self.s_prev = np.concatenate(prevs)
        self.s_end = np.concatenate(ends)
        self.s_task = np.concatenate(tasks)

    def __len__(self):
        return len(self.s_k)

    def batch(self, which):
        """Samples `which` (indices) as numpy arrays: images per camera (B, 2, S, S, 3) uint8,
        states (B, 2, 10), words (B, MAX_WORDS), actions (B, 16, 10)."""
        k, prev, end = self.s_k[which], self.s_prev[which], self.s_end[which]
        obs = np.stack([prev, k], axis=1)
        act = np.minimum(k[:, None] + 1 + np.arange(HORIZON)[None, :], end[:, None])
        words = np.array([self.task_words[int(t)] for t in self.s_task[which]], dtype=np.int64)
        return {
            "images": {cam: self.images[cam][obs] for cam in CAMERAS},
            "state": self.state[obs],
            "words": words,
            "action": self.action[act],
        }
