"""Checks a Kitchen-R LeRobotDataset v3.0 export with outside readers and prints a JSON summary.

Usage: read_lerobot.py ROOT

Reads every file with pyarrow/pandas (what LeRobot itself uses underneath) and checks what
LeRobot v3.0 requires of it (lerobot/datasets/utils.py, dataset_metadata.py, dataset_reader.py):
meta/info.json keys and features, meta/tasks.parquet indexed by task, meta/episodes/*.parquet
consistent with the data, data/*.parquet columns and dtypes, contiguous indices, stats.json, and
the videos: decoded with PyAV when it is installed (frame count, size and timestamps), else
their ISO-BMFF structure. Exits non-zero with the first violation.
"""
import json
import struct
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

REQUIRED_INFO = ["codebase_version", "fps", "features", "total_episodes", "total_frames",
                 "total_tasks", "chunks_size", "data_path", "video_path", "splits",
                 "data_files_size_in_mb", "video_files_size_in_mb", "robot_type"]
DEFAULT_FEATURES = {"timestamp": "float32", "frame_index": "int64", "episode_index": "int64",
                    "index": "int64", "task_index": "int64"}
STATS = ["min", "max", "mean", "std", "count", "q01", "q10", "q50", "q90", "q99"]


def check(cond, message):
    if not cond:
        print(f"LeRobot check failed: {message}", file=sys.stderr)
        sys.exit(1)


def concat(paths):
    return pd.concat([pd.read_parquet(p) for p in paths], ignore_index=True)


# The decoder configuration box and the PyAV decoder names of each `video.codec` we write.
CODECS = {
    "h264": (b"avcC", ("h264",)),
    "av1": (b"av1C", ("libdav1d", "av1", "libaom-av1")),
}


def mp4_boxes(path, config_box):
    """Top-level boxes, the sample count of the first track (stsz), and whether the decoder
    configuration box is there."""
    b = path.read_bytes()
    top, at = [], 0
    while at + 8 <= len(b):
        size, kind = struct.unpack(">I4s", b[at:at + 8])
        top.append(kind.decode())
        check(size >= 8, f"{path}: bad box size")
        at += size
    i = b.find(b"stsz")
    count = struct.unpack(">I", b[i + 12:i + 16])[0]
    return top, count, b.find(config_box) > 0


def main(root):
    root = Path(root)
    info = json.loads((root / "meta/info.json").read_text())
    for k in REQUIRED_INFO:
        check(k in info, f"info.json lacks {k}")
    check(info["codebase_version"] == "v3.0", "codebase_version")
    fps = info["fps"]
    feats = info["features"]
    for k, dtype in DEFAULT_FEATURES.items():
        check(feats.get(k, {}).get("dtype") == dtype and feats[k]["shape"] == [1], f"feature {k}")
    for k in ["observation.state", "action"]:
        check(feats[k]["dtype"] == "float32" and len(feats[k]["names"]) == feats[k]["shape"][0], k)
    video_keys = [k for k, f in feats.items() if f["dtype"] == "video"]
    check(video_keys and all(k.startswith("observation.images.") for k in video_keys), "video keys")
    for k in video_keys:
        f = feats[k]
        check(f["names"] == ["height", "width", "channels"] and f["shape"][2] == 3, f"{k} shape")
        check(f["info"]["video.codec"] in CODECS and f["info"]["video.fps"] == fps, f"{k} info")

    tasks = pd.read_parquet(root / "meta/tasks.parquet")
    check(tasks.index.name == "task", "tasks.parquet is indexed by task")
    check(list(tasks["task_index"]) == list(range(len(tasks))), "task_index 0..T-1")
    check(str(tasks["task_index"].dtype) == "int64", "task_index dtype")
    check(len(tasks) == info["total_tasks"], "total_tasks")

    ep_paths = sorted((root / "meta/episodes").glob("*/*.parquet"))
    eps = concat(ep_paths)
    n = info["total_episodes"]
    check(list(eps["episode_index"]) == list(range(n)), "episode_index 0..N-1 in file order")
    required = ["tasks", "length", "data/chunk_index", "data/file_index", "dataset_from_index",
                "dataset_to_index", "meta/episodes/chunk_index", "meta/episodes/file_index"]
    for k in video_keys:
        required += [f"videos/{k}/{c}" for c in
                     ["chunk_index", "file_index", "from_timestamp", "to_timestamp"]]
    for f in [k for k in feats if feats[k]["dtype"] != "string"]:
        required += [f"stats/{f}/{s}" for s in STATS]
    for c in required:
        check(c in eps.columns, f"episodes metadata lacks {c}")

    data_paths = sorted((root / "data").glob("*/*.parquet"))
    schema = pq.read_schema(data_paths[0])
    for k, f in feats.items():
        if f["dtype"] == "video":
            check(k not in schema.names, f"video {k} is not a data column")
            continue
        t = schema.field(k).type
        if f["shape"] == [1]:
            check(t == pa.from_numpy_dtype(np.dtype(f["dtype"])), f"{k}: {t}")
        else:
            check(pa.types.is_list(t) or pa.types.is_fixed_size_list(t), f"{k}: {t}")
            check(t.value_type == pa.from_numpy_dtype(np.dtype(f["dtype"])), f"{k} item type")
    data = concat(data_paths)
    check(len(data) == info["total_frames"], "total_frames")
    check(list(data["index"]) == list(range(len(data))), "index contiguous 0..F-1")
    for k in ["observation.state", "action"]:
        check(all(len(v) == feats[k]["shape"][0] for v in data[k]), f"{k} rows")
    check(data["task_index"].between(0, len(tasks) - 1).all(), "task_index in tasks")

    for _, ep in eps.iterrows():
        e = int(ep["episode_index"])
        rows = data[data["episode_index"] == e]
        lo, hi = int(ep["dataset_from_index"]), int(ep["dataset_to_index"])
        check(len(rows) == ep["length"] == hi - lo, f"episode {e} length")
        check(list(rows["index"]) == list(range(lo, hi)), f"episode {e} index range")
        check(list(rows["frame_index"]) == list(range(hi - lo)), f"episode {e} frame_index")
        check(np.allclose(rows["timestamp"], rows["frame_index"] / fps, atol=1e-4), "timestamps")
        ep_tasks = set(tasks.index[rows["task_index"]])
        check(ep_tasks == set(ep["tasks"]), f"episode {e} tasks {ep_tasks} vs {list(ep['tasks'])}")
        path = root / info["data_path"].format(chunk_index=ep["data/chunk_index"],
                                               file_index=ep["data/file_index"])
        check(e in set(pd.read_parquet(path, columns=["episode_index"])["episode_index"]),
              f"episode {e} is in its data file")

    stats = json.loads((root / "meta/stats.json").read_text())
    for k, f in feats.items():
        for s in STATS:
            check(s in stats.get(k, {}), f"stats.json {k}/{s}")
        shape = [3, 1, 1] if f["dtype"] == "video" else f["shape"]
        check(list(np.array(stats[k]["mean"]).shape) == shape, f"stats {k} shape")
    check(stats["index"]["count"] == [len(data)], "stats count")

    try:
        import av
    except ImportError:
        av = None
    videos = {}
    for k in video_keys:
        files = eps.groupby([f"videos/{k}/chunk_index", f"videos/{k}/file_index"])
        for (c, fi), group in files:
            path = root / info["video_path"].format(video_key=k, chunk_index=c, file_index=fi)
            check(path.is_file(), f"{path} missing")
            frames = int(group["length"].sum())
            end = float(group[f"videos/{k}/to_timestamp"].max())
            check(abs(end - frames / fps) < 1e-6, f"{path}: episodes span {end} s")
            config_box, decoders = CODECS[feats[k]["info"]["video.codec"]]
            top, count, has_config = mp4_boxes(path, config_box)
            check(top == ["ftyp", "moov", "mdat"] and has_config and count == frames, f"{path}: {top}")
            decoded = None
            if av is not None:
                with av.open(str(path)) as container:
                    stream = container.streams.video[0]
                    check(stream.codec_context.name in decoders, f"codec {stream.codec_context.name}")
                    times, shape = [], None
                    for frame in container.decode(stream):
                        times.append(frame.time)
                        shape = shape or frame.to_ndarray(format="rgb24").shape
                decoded = len(times)
                check(decoded == frames, f"{path}: decoded {decoded} of {frames} frames")
                check(np.allclose(times, np.arange(frames) / fps, atol=1e-6), "frame times")
                check(list(shape) == feats[k]["shape"], f"{path}: frames of {shape}")
            videos[str(path.relative_to(root))] = {"frames": frames, "decoded": decoded}

    loaded = load_like_lerobot(feats, data_paths, ep_paths)
    check(loaded is None or loaded == (len(data), n), f"datasets loaded {loaded}")

    print(json.dumps({
        "episodes": n, "frames": len(data), "tasks": list(tasks.index), "videos": videos,
        "data_files": len(data_paths), "episode_files": len(ep_paths),
        "decoder": None if av is None else av.__version__,
        "hf_datasets": loaded is not None,
    }))


def load_like_lerobot(feats, data_paths, ep_paths):
    """LeRobot's own load path where Hugging Face `datasets` is installed: the data files cast
    to the features of info.json (`get_hf_features_from_features`) and the episodes metadata,
    both through `Dataset.from_parquet` (`load_nested_dataset`). (frames, episodes) or None."""
    try:
        import datasets
    except ImportError:
        return None
    datasets.disable_progress_bars()
    seq = getattr(datasets, "Sequence", None) or datasets.List
    features = {}
    for k, f in feats.items():
        if f["dtype"] == "video":
            continue
        value = datasets.Value(dtype=f["dtype"])
        features[k] = value if f["shape"] == [1] else seq(feature=value, length=f["shape"][0])
    with tempfile.TemporaryDirectory() as cache:
        data = datasets.Dataset.from_parquet([str(p) for p in data_paths],
                                             features=datasets.Features(features), cache_dir=cache)
        data = data.with_format("numpy")
        last = data[len(data) - 1]
        check(last["observation.state"].shape == (feats["observation.state"]["shape"][0],),
              "observation.state through datasets")
        check(int(last["index"]) == len(data) - 1, "last index through datasets")
        eps = datasets.Dataset.from_parquet([str(p) for p in ep_paths], cache_dir=cache)
        eps = eps.select_columns([c for c in eps.column_names if not c.startswith("stats/")])
        check(eps[len(eps) - 1]["dataset_to_index"] == len(data), "episodes through datasets")
        return len(data), len(eps)


if __name__ == "__main__":
    main(sys.argv[1])
