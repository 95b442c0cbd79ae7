#!/usr/bin/env python3
"""Kitchen-R participant policy server (starter kit).

Serves `kitchen_r.policy.v1.Policy` (GetSpec, Reset, Act) and the standard `grpc.health.v1`
health service. The policy here is trivial but valid: it stands still with the gripper open,
holding the hand at a fixed pose in front of the base. Replace `StarterPolicy.decide` with
your model.

Python stubs are generated from the repository's `proto/` at start-up (into a temporary
directory) with grpcio-tools; nothing generated is committed. By hand it is one line:

    python -m grpc_tools.protoc -I ../proto --python_out=_gen --grpc_python_out=_gen \
        ../proto/kitchen_r/policy/v1/policy.proto

Run:  python policy_server.py --listen 0.0.0.0:50051 [--token SECRET] [--history 2] [--execute 4]
      [--privileged]
It prints `listening grpc=HOST:PORT` once it accepts calls.

Contract v1.1 (what a learned policy needs): GetSpec may ask for an observation history (the
last N control steps, 0.1 s apart, in every Act) and for how many actions of each chunk the
worker executes before asking again; every observation carries the hand pose in the base frame
(`robot.ee_pose`), the gripper opening (`robot.gripper`) and the previous action
(`previous_action`, empty at the start of the episode).

Privileged-information track (`--privileged`): GetSpec answers `privileged_observations = true`
and every Act then carries `privileged_observation`: the robot's pose in the scene frame, the
current task's goal in the robot frame (a move's approach pose, the object to pick, the place
target) and key objects' poses in the scene frame; on the test split only what the current
sub-task names. A server accepts such a policy only where its organiser enabled the track
(`control.privileged_track = true`; otherwise registration is refused, naming that key), and
ranks it on the privileged boards, apart from standard policies. `privileged(obs)` below reads it.

Batched decisions (`--max-batch N`, N > 1): GetSpec declares `max_batch`, and a worker running
several episodes against this server sends their pending decisions in one `ActBatch` call (up
to N observations, one chunk back for each, in the same order). By default each observation is
answered by `decide(obs)`, one after the other; a policy that defines
`decide_batch(observations)` (a list of observations in, a list of chunks out, same order) gets
the whole batch instead, for one batched forward pass. Each observation is exactly what its Act
would carry, and an episode's result depends only on the chunk returned for it.
"""

import argparse
import atexit
import logging
import os
import shutil
import signal
import sys
import tempfile
import threading
from concurrent import futures
from pathlib import Path

HERE = Path(__file__).resolve().parent
PROTO_FILE = "kitchen_r/policy/v1/policy.proto"
PROTOCOL_VERSION = 1
HORIZON = 16
ACTION_DIM = 10
# Largest observation accepted: the worker may send images up to 1024x1024 (plus depth).
MAX_MESSAGE_BYTES = 64 * 1024 * 1024
# Contract v1.1 limits (policy.proto): frames per Act, and the largest execution count.
MAX_OBSERVATION_HISTORY = 8


def proto_dir(explicit):
    """The directory holding kitchen_r/policy/v1/policy.proto."""
    for d in [explicit, os.environ.get("KITCHEN_R_PROTO"), HERE.parent / "proto", HERE / "proto"]:
        if d and (Path(d) / PROTO_FILE).is_file():
            return Path(d)
    sys.exit(f"cannot find {PROTO_FILE}: pass --proto-dir or copy the repository's proto/ beside this file")


def load_stubs(proto):
    """Generate the message and service stubs into a fresh temporary directory and import them.

    A directory per process, so servers started side by side never read each other's
    half-written files, and a stub is never older than the proto it came from.
    """
    from grpc_tools import protoc

    out = Path(tempfile.mkdtemp(prefix="kitchen_r_stubs_"))
    atexit.register(shutil.rmtree, out, ignore_errors=True)
    args = ["protoc", f"-I{proto}", f"--python_out={out}", f"--grpc_python_out={out}", str(proto / PROTO_FILE)]
    if protoc.main(args) != 0:
        sys.exit(f"grpc_tools.protoc failed on {proto / PROTO_FILE}")
    sys.path.insert(0, str(out))
    from kitchen_r.policy.v1 import policy_pb2, policy_pb2_grpc

    return policy_pb2, policy_pb2_grpc


class StarterPolicy:
    """Stand still, gripper open, hand at a fixed pose in the base frame.

    An action is (v, omega, x, y, z, qw, qx, qy, qz, g): base forward velocity (m/s) and yaw
    rate (rad/s), the end-effector target in the base frame (metres, unit quaternion) and the
    gripper command in [0, 1] (1 = open). A chunk is 16 of them.
    """

    HOLD = [0.0, 0.0, 0.35, 0.0, 0.95, 0.0, 1.0, 0.0, 0.0, 1.0]

    def __init__(self):
        self.sub_task = {}
        self.lock = threading.Lock()

    def reset(self, episode_id, task_index, sub_task):
        with self.lock:
            self.sub_task[episode_id] = sub_task

    def decide(self, obs):
        """Return HORIZON actions of ACTION_DIM values for one observation.

        `obs.images[i]` has `camera`, `width`, `height`, `encoding` and `data` (RAW_RGB8:
        width*height*3 bytes, row-major from the top-left pixel); `obs.robot` has odometry, arm
        joints, the hand pose and the gripper; `obs.sub_task` is the sentence to carry out.
        `frames(obs)` gives the observation history oldest first, `state(frame)` the paper's
        robot state of one frame: what a learned model would be conditioned on.
        """
        _states = [state(f) for f in frames(obs)]  # a model would read these and the images
        _world = privileged(obs)  # None unless this policy asked for privileged observations
        return [list(self.HOLD) for _ in range(HORIZON)]

    # Batched decisions (--max-batch > 1): define `decide_batch(self, observations)` returning one
    # chunk per observation, in order, to run a batch through a model at once; without it the
    # server calls `decide` for each observation.


def frames(obs):
    """The frames of one Act, oldest first: `obs.history` (the steps before, as many as
    GetSpec's observation_history asked for minus one, padded with the task's first frame at
    its start) then the observation itself. Each has `step`, `sim_time`, `images`, `depth`,
    `robot` and `previous_action`."""
    return list(obs.history) + [obs]


def state(frame):
    """The robot state of one frame: hand pose in the base frame (x, y, z, qw, qx, qy, qz),
    gripper opening in [0, 1], and the previous action (10 values; zeros at the start of the
    episode, where the worker sends it empty)."""
    hand = list(frame.robot.ee_pose) or [0.0] * 7
    previous = list(frame.previous_action) or [0.0] * ACTION_DIM
    return hand + [frame.robot.gripper] + previous


def privileged(obs):
    """The privileged track's observation as plain values, or None on the standard track:
    {"base": (x, y, yaw) in the scene frame, "goal": (kind, object, values) in the robot frame
    (kind "approach": x, y, yaw; "pick": the object's pose x, y, z, qw, qx, qy, qz; "place": the
    target x, y, z), "objects": {name: pose in the scene frame}}."""
    if not obs.HasField("privileged_observation"):
        return None
    p = obs.privileged_observation
    kind = p.goal.WhichOneof("goal")
    if kind == "approach":
        goal = ("approach", "", (p.goal.approach.x, p.goal.approach.y, p.goal.approach.yaw))
    elif kind == "pick":
        goal = ("pick", p.goal.pick.object, tuple(p.goal.pick.pose))
    elif kind == "place":
        goal = ("place", p.goal.place.object, tuple(p.goal.place.target))
    else:
        goal = None
    return {
        "base": (p.base_x, p.base_y, p.base_yaw),
        "goal": goal,
        "objects": {o.name: tuple(o.pose) for o in p.objects},
    }


def make_servicer(
    pb2,
    pb2_grpc,
    policy,
    token,
    history=1,
    execute=0,
    name="starter-kit stand-still 0.2",
    max_concurrency=4,
    privileged=False,
    cameras=(("base", 128, 128), ("gripper", 128, 128)),
    max_batch=0,
):
    import grpc

    def chunk_message(chunk, context):
        if len(chunk) != HORIZON or any(len(a) != ACTION_DIM for a in chunk):
            context.abort(grpc.StatusCode.INTERNAL, "policy produced a chunk of the wrong shape")
        return pb2.ActionChunk(values=[v for a in chunk for v in a])

    class Servicer(pb2_grpc.PolicyServicer):
        def _authorise(self, context):
            if token is None:
                return
            got = dict(context.invocation_metadata()).get("authorization")
            if got != f"Bearer {token}":
                context.abort(grpc.StatusCode.UNAUTHENTICATED, "missing or wrong bearer token")

        def GetSpec(self, request, context):
            self._authorise(context)
            if request.protocol_version != PROTOCOL_VERSION:
                logging.warning("worker speaks protocol %d, this server %d", request.protocol_version, PROTOCOL_VERSION)
            cams = [
                pb2.CameraRequest(
                    name=c[0],
                    width=c[1],
                    height=c[2],
                    encoding=pb2.IMAGE_ENCODING_RAW_RGB8,
                    depth=bool(c[3]) if len(c) > 3 else False,
                )
                for c in cameras
            ]
            return pb2.PolicySpec(
                protocol_version=PROTOCOL_VERSION,
                cameras=cams,
                horizon=HORIZON,
                action_dim=ACTION_DIM,
                max_concurrency=max_concurrency,
                name=name,
                # v1.1: frames per Act (1..8), and actions executed per chunk (0 = the
                # organiser's default, announced in request.actions_executed_per_chunk; else
                # between request.min_actions_executed_per_chunk and 16).
                observation_history=history,
                actions_executed_per_chunk=execute,
                # Privileged track: True asks for `privileged_observation` in every Act (the
                # server says whether it runs the track in request.privileged_track).
                privileged_observations=privileged,
                # Batched decisions: up to this many observations per ActBatch (0/1: Acts only).
                max_batch=max_batch,
            )

        def Reset(self, request, context):
            self._authorise(context)
            policy.reset(request.episode_id, request.task_index, request.sub_task)
            return pb2.ResetResponse()

        def Act(self, request, context):
            self._authorise(context)
            return chunk_message(policy.decide(request), context)

        def ActBatch(self, request, context):
            """Batched decisions: one chunk per observation, in order; through the policy's
            `decide_batch` when it has one, else `decide` for each."""
            self._authorise(context)
            observations = list(request.observations)
            if len(observations) > max(1, max_batch):
                context.abort(
                    grpc.StatusCode.INVALID_ARGUMENT,
                    f"ActBatch carries {len(observations)} observations, more than max_batch {max(1, max_batch)}",
                )
            batch = getattr(policy, "decide_batch", None)
            chunks = batch(observations) if batch is not None else [policy.decide(o) for o in observations]
            if len(chunks) != len(observations):
                context.abort(
                    grpc.StatusCode.INTERNAL,
                    f"policy produced {len(chunks)} chunks for {len(observations)} observations",
                )
            return pb2.ActionChunkBatch(chunks=[chunk_message(c, context) for c in chunks])

    return Servicer()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--listen", default="127.0.0.1:50051", help="HOST:PORT; port 0 picks a free port")
    ap.add_argument("--token", default=os.environ.get("POLICY_TOKEN"), help="require this bearer token")
    ap.add_argument("--proto-dir", default=None, help="directory with kitchen_r/policy/v1/policy.proto")
    ap.add_argument("--threads", type=int, default=8)
    ap.add_argument("--history", type=int, default=2, help="frames per Act, 1..8 (contract v1.1)")
    ap.add_argument(
        "--execute", type=int, default=0, help="actions executed per chunk; 0 = the organiser's default (v1.1)"
    )
    ap.add_argument(
        "--privileged",
        action="store_true",
        help="ask for privileged observations (the privileged track; ranked apart, needs the organiser's "
        "control.privileged_track = true)",
    )
    ap.add_argument(
        "--max-batch",
        type=int,
        default=0,
        help="batched decisions: declare max_batch in GetSpec, so workers send up to N episodes' decisions "
        "in one ActBatch call; 0 or 1 = Acts only",
    )
    args = ap.parse_args()
    if not 1 <= args.history <= MAX_OBSERVATION_HISTORY:
        sys.exit(f"--history must be between 1 and {MAX_OBSERVATION_HISTORY}")
    if not 0 <= args.execute <= HORIZON:
        sys.exit(f"--execute must be between 0 and {HORIZON}")
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(message)s")
    serve(
        args.listen,
        args.token,
        args.proto_dir,
        args.threads,
        StarterPolicy(),
        args.history,
        args.execute,
        privileged=args.privileged,
        max_batch=args.max_batch,
    )


def receive_limit(max_batch):
    """The largest request this server accepts: `max_batch` one-Act observations, at most the
    2 GiB - 1 a gRPC channel argument holds."""
    return min(MAX_MESSAGE_BYTES * max(1, max_batch), 2**31 - 1)


def serve(
    listen,
    token,
    proto,
    threads,
    policy,
    history,
    execute,
    name=None,
    max_concurrency=4,
    privileged=False,
    cameras=None,
    max_batch=0,
):
    """Serve `policy` (an object with `reset(episode_id, task_index, sub_task)` and
    `decide(obs)`, as StarterPolicy, and optionally `decide_batch(observations)`) with the health
    service until interrupted; prints `listening grpc=HOST:PORT` once it accepts calls. Learned
    policies (baselines/) reuse this. `max_batch` > 1 declares batched decisions (ActBatch).
    `cameras`: `(name, width, height[, depth])` per camera GetSpec asks for (default both at 128x128, no depth;
    an empty list means the server's default cameras, so a policy that reads none asks for one
    small image)."""
    import grpc
    from grpc_health.v1 import health, health_pb2, health_pb2_grpc

    pb2, pb2_grpc = load_stubs(proto_dir(proto))
    opts = [
        # A batch carries up to max_batch observations, each up to the one-Act size; gRPC takes
        # a 32-bit length, which 64 MiB x 32 observations would overflow.
        ("grpc.max_receive_message_length", receive_limit(max_batch)),
        ("grpc.max_send_message_length", MAX_MESSAGE_BYTES),
    ]
    server = grpc.server(futures.ThreadPoolExecutor(max_workers=threads), options=opts)
    extra = {"name": name} if name else {}
    if cameras is not None:
        extra["cameras"] = cameras
    servicer = make_servicer(
        pb2,
        pb2_grpc,
        policy,
        token,
        history,
        execute,
        max_concurrency=max_concurrency,
        privileged=privileged,
        max_batch=max_batch,
        **extra,
    )
    pb2_grpc.add_PolicyServicer_to_server(servicer, server)
    h = health.HealthServicer()
    for service in ("", "kitchen_r.policy.v1.Policy"):
        h.set(service, health_pb2.HealthCheckResponse.SERVING)
    health_pb2_grpc.add_HealthServicer_to_server(h, server)
    port = server.add_insecure_port(listen)
    if port == 0:
        sys.exit(f"cannot listen on {listen}")
    server.start()
    # Stop cleanly on SIGTERM too (containers, `kill`), so the stub directory is removed.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    host = listen.rsplit(":", 1)[0]
    print(f"listening grpc={host}:{port}", flush=True)
    try:
        server.wait_for_termination()
    except KeyboardInterrupt:
        server.stop(grace=1.0)


if __name__ == "__main__":
    main()
