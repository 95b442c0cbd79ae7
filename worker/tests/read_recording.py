"""Reads a Kitchen-R recording with the reference readers and prints a JSON summary.

Usage: read_recording.py FILE.mcap FILE.hdf5
MCAP: decoded with `mcap` + `mcap-ros2-support` (the ROS 2 CDR decoder Foxglove's tooling uses).
HDF5: read with h5py in the ALOHA/ACT layout.
"""
import json
import sys

import h5py
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory


def read_mcap(path):
    counts, first = {}, {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        profile = reader.get_header().profile
        meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        for schema, channel, message, ros_msg in reader.iter_decoded_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic in first:
                continue
            if schema.name == "sensor_msgs/msg/Image":
                first[channel.topic] = {
                    "width": ros_msg.width, "height": ros_msg.height,
                    "encoding": ros_msg.encoding, "bytes": len(ros_msg.data),
                    "frame_id": ros_msg.header.frame_id,
                }
            elif schema.name == "sensor_msgs/msg/PointCloud2":
                first[channel.topic] = {"width": ros_msg.width, "fields": [f.name for f in ros_msg.fields],
                                        "bytes": len(ros_msg.data)}
            elif schema.name == "nav_msgs/msg/Odometry":
                p = ros_msg.pose.pose.position
                first[channel.topic] = {"x": p.x, "y": p.y, "child": ros_msg.child_frame_id}
            elif schema.name == "std_msgs/msg/Float64MultiArray":
                first[channel.topic] = {"data": list(ros_msg.data)}
            elif schema.name == "tf2_msgs/msg/TFMessage":
                first[channel.topic] = {"children": [t.child_frame_id for t in ros_msg.transforms]}
            elif schema.name == "geometry_msgs/msg/Twist":
                first[channel.topic] = {"v": ros_msg.linear.x, "w": ros_msg.angular.z}
            elif schema.name == "sensor_msgs/msg/Imu":
                a, o = ros_msg.linear_acceleration, ros_msg.orientation
                first[channel.topic] = {
                    "frame_id": ros_msg.header.frame_id, "wz": ros_msg.angular_velocity.z,
                    "acc": [a.x, a.y, a.z], "q": [o.w, o.x, o.y, o.z],
                    "cov": [list(ros_msg.orientation_covariance),
                            list(ros_msg.angular_velocity_covariance),
                            list(ros_msg.linear_acceleration_covariance)],
                }
    return {"profile": profile, "counts": counts, "first": first, "metadata": meta}


def read_hdf5(path):
    out = {"shapes": {}, "attrs": {}, "dtypes": {}, "filters": {}, "units": {}}
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset):
                out["shapes"][name] = list(obj.shape)
                out["dtypes"][name] = obj.dtype.str
                out["filters"][name] = {"compression": obj.compression, "shuffle": obj.shuffle,
                                        "chunks": list(obj.chunks) if obj.chunks else None}
                if "unit" in obj.attrs:
                    u = obj.attrs["unit"]
                    out["units"][name] = u.decode() if isinstance(u, bytes) else str(u)
                # Reading every frame proves the filters decode without a plugin.
                obj[...]
        f.visititems(visit)
        for k, v in f.attrs.items():
            out["attrs"][k] = v.decode() if isinstance(v, bytes) else (v.item() if hasattr(v, "item") else v)
        out["action0"] = f["action"][0].tolist()
    return out


if __name__ == "__main__":
    print(json.dumps({"mcap": read_mcap(sys.argv[1]), "hdf5": read_hdf5(sys.argv[2])}))
