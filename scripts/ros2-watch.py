#!/usr/bin/env python3
"""A ROS 2 subscriber without ROS 2: reads the live topics of `kitchen-r eval --ros2` (or
`replay`, `collect`) over DDS with Eclipse Cyclone DDS (`pip install cyclonedds`, the wheel
bundles the C library), typed as a ROS 2 node types them (`sensor_msgs::msg::dds_::Imu_`, ...),
and prints one JSON line per message: topic, stamp (ns), frame_id and a few fields. Used by the
loopback test (tests/e2e/ros2_live.rs) and to check a run by hand (docs/twin/live.md).

    python3 scripts/ros2-watch.py [--domain N] [--seconds S] [--count N] [--qos reliable|best_effort]
                                  [--no-read]

Discovery stays on loopback unless CYCLONEDDS_URI is set: the interface `lo`, no multicast, and
unicast discovery to this host's participants (Peers 127.0.0.1), as `configs/live.toml`'s
`network = "loopback"` does on the publishing side. It prints `ready` on stderr once its
readers exist, and exits 0 when every topic got `--count` messages (the camera `--images`), 1 on
timeout.
"""

import argparse
import json
import os
import sys
import time
from dataclasses import dataclass

LOOPBACK_XML = """<CycloneDDS><Domain Id="any"><General>
<Interfaces><NetworkInterface name="lo"/></Interfaces>
<AllowMulticast>false</AllowMulticast></General>
<Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>30</MaxAutoParticipantIndex>
<Peers><Peer address="127.0.0.1"/></Peers></Discovery></Domain></CycloneDDS>"""

# Cyclone reads its configuration when the first participant is created.
os.environ.setdefault("CYCLONEDDS_URI", LOOPBACK_XML)

# The message classes pass `typename=` to IdlStruct's __init_subclass__, which mypy (reading no
# installed package: mypy.ini) cannot see.
# mypy: disable-error-code="call-arg"
from cyclonedds.core import Policy, Qos  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.idl.types import array, float64, int32, sequence, uint8, uint32  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64
    y: float64
    z: float64


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64
    y: float64
    z: float64
    w: float64


@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Vector3
    orientation: Quaternion


@dataclass
class PoseWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose
    covariance: array[float64, 36]


@dataclass
class Twist(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
    linear: Vector3
    angular: Vector3


@dataclass
class TwistWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::TwistWithCovariance_"):
    twist: Twist
    covariance: array[float64, 36]


@dataclass
class Odometry(IdlStruct, typename="nav_msgs::msg::dds_::Odometry_"):
    header: Header
    child_frame_id: str
    pose: PoseWithCovariance
    twist: TwistWithCovariance


@dataclass
class Imu(IdlStruct, typename="sensor_msgs::msg::dds_::Imu_"):
    header: Header
    orientation: Quaternion
    orientation_covariance: array[float64, 9]
    angular_velocity: Vector3
    angular_velocity_covariance: array[float64, 9]
    linear_acceleration: Vector3
    linear_acceleration_covariance: array[float64, 9]


@dataclass
class Transform(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    translation: Vector3
    rotation: Quaternion


@dataclass
class TransformStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TransformStamped_"):
    header: Header
    child_frame_id: str
    transform: Transform


@dataclass
class TFMessage(IdlStruct, typename="tf2_msgs::msg::dds_::TFMessage_"):
    transforms: sequence[TransformStamped]


@dataclass
class Clock(IdlStruct, typename="rosgraph_msgs::msg::dds_::Clock_"):
    clock: Time


@dataclass
class Image(IdlStruct, typename="sensor_msgs::msg::dds_::Image_"):
    header: Header
    height: uint32
    width: uint32
    encoding: str
    is_bigendian: uint8
    step: uint32
    data: sequence[uint8]


def ns(h: Header) -> int:
    return h.stamp.sec * 1_000_000_000 + h.stamp.nanosec


def describe(topic: str, m) -> dict:
    if isinstance(m, Clock):
        return {"stamp": m.clock.sec * 1_000_000_000 + m.clock.nanosec}
    if isinstance(m, TFMessage):
        t = m.transforms[0]
        return {
            "stamp": ns(t.header),
            "frame_id": t.header.frame_id,
            "child": t.child_frame_id,
            "transforms": len(m.transforms),
        }
    out = {"stamp": ns(m.header), "frame_id": m.header.frame_id}
    if isinstance(m, Odometry):
        out.update(child=m.child_frame_id, x=m.pose.pose.position.x, y=m.pose.pose.position.y)
    elif isinstance(m, Imu):
        out.update(qw=m.orientation.w, wz=m.angular_velocity.z)
    elif isinstance(m, Image):
        out.update(width=m.width, height=m.height, encoding=m.encoding, step=m.step, bytes=len(m.data))
    return out


TOPICS = [
    ("rt/imu", Imu),
    ("rt/odom", Odometry),
    ("rt/tf", TFMessage),
    ("rt/camera/base/image_raw", Image),
    ("rt/clock", Clock),
]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--domain", type=int, default=int(os.environ.get("ROS_DOMAIN_ID", "0") or 0))
    ap.add_argument("--seconds", type=float, default=120.0, help="give up after this long")
    ap.add_argument("--count", type=int, default=3, help="messages wanted of every topic")
    ap.add_argument(
        "--images", type=int, default=1, help="messages wanted of the camera topic (sent at most 30 a wall second)"
    )
    ap.add_argument("--qos", choices=["reliable", "best_effort"], default="reliable")
    ap.add_argument(
        "--no-read",
        action="store_true",
        help="subscribe, then never take a message (a stalled subscriber), for --seconds",
    )
    args = ap.parse_args()
    rel = Policy.Reliability.Reliable(duration(seconds=1)) if args.qos == "reliable" else Policy.Reliability.BestEffort
    qos = Qos(rel, Policy.Durability.Volatile, Policy.History.KeepLast(50))
    dp = DomainParticipant(args.domain)
    readers = [(name, DataReader(dp, Topic(dp, name, ty), qos=qos)) for name, ty in TOPICS]
    print("ready", file=sys.stderr, flush=True)
    if args.no_read:
        time.sleep(args.seconds)
        return 0
    seen = {name: 0 for name, _ in TOPICS}
    want = {name: args.images if ty is Image else args.count for name, ty in TOPICS}
    done = lambda: all(seen[n] >= want[n] for n in seen)  # noqa: E731
    until = time.monotonic() + args.seconds
    while time.monotonic() < until and not done():
        got = False
        for name, r in readers:
            for m in r.take(N=64):
                got = True
                seen[name] += 1
                print(json.dumps({"topic": name.removeprefix("rt"), **describe(name, m)}), flush=True)
        if not got:
            time.sleep(0.01)
    print(json.dumps({"seen": seen}), file=sys.stderr, flush=True)
    return 0 if done() else 1


if __name__ == "__main__":
    sys.exit(main())
