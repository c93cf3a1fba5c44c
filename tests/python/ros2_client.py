#!/usr/bin/env python3
"""An independent ROS 2 client of hvs's bridge, without ROS: eclipse-zenoh (PyPI) for the
transport and rosbags (PyPI) for the CDR and the type hashes.

It connects to the bridge's endpoint (multicast scouting off), lists the ROS 2 graph from the
liveliness tokens, subscribes to every rmw_zenoh data key of the domain, decodes each sample
with rosbags' Jazzy type store, and prints one JSON object with what it found; the Rust test
compares that with what the pipeline publishes in shared memory.
"""

import argparse
import json
import sys
import threading
import time
import zlib

import zenoh
from rosbags.typesys import Stores, get_typestore

TYPES = {
    "sensor_msgs::msg::dds_::Image_": "sensor_msgs/msg/Image",
    "sensor_msgs::msg::dds_::CameraInfo_": "sensor_msgs/msg/CameraInfo",
    "stereo_msgs::msg::dds_::DisparityImage_": "stereo_msgs/msg/DisparityImage",
    "geometry_msgs::msg::dds_::Twist_": "geometry_msgs/msg/Twist",
}


def summary(ros_type, msg):
    """The fields the test checks, per type."""
    if ros_type == "sensor_msgs/msg/Image":
        return {
            "width": msg.width,
            "height": msg.height,
            "encoding": msg.encoding,
            "step": msg.step,
            "frame_id": msg.header.frame_id,
            "stamp_s": msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9,
            "data_len": len(msg.data),
            "data_crc32": zlib.crc32(bytes(msg.data)),
        }
    if ros_type == "sensor_msgs/msg/CameraInfo":
        return {
            "width": msg.width,
            "height": msg.height,
            "k": [float(x) for x in msg.k],
            "p": [float(x) for x in msg.p],
            "distortion_model": msg.distortion_model,
        }
    if ros_type == "stereo_msgs/msg/DisparityImage":
        import numpy as np

        data = np.frombuffer(bytes(msg.image.data), dtype="<f4")
        valid = data[np.isfinite(data)]
        return {
            "width": msg.image.width,
            "height": msg.image.height,
            "encoding": msg.image.encoding,
            "f": float(msg.f),
            "t": float(msg.t),
            "min_disparity": float(msg.min_disparity),
            "max_disparity": float(msg.max_disparity),
            "valid_px": int(valid.size),
            "valid_max": float(valid.max()) if valid.size else 0.0,
        }
    if ros_type == "geometry_msgs/msg/Twist":
        return {"linear_x": msg.linear.x, "angular_z": msg.angular.z}
    return {}


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--connect", required=True, help="the bridge's endpoint, tcp/127.0.0.1:PORT")
    ap.add_argument("--domain", type=int, default=0)
    ap.add_argument("--per-topic", type=int, default=3, help="samples to take per topic")
    ap.add_argument("--timeout", type=float, default=30.0, help="seconds")
    args = ap.parse_args()

    store = get_typestore(Stores.ROS2_JAZZY)
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("connect/endpoints", json.dumps([args.connect]))
    session = zenoh.open(conf)

    lock = threading.Lock()
    topics = {}
    errors = []

    def on_sample(sample):
        key = str(sample.key_expr)
        parts = key.split("/")
        dds_type, type_hash = parts[-2], parts[-1]
        topic = "/" + "/".join(parts[1:-2])
        ros_type = TYPES.get(dds_type)
        with lock:
            entry = topics.setdefault(
                topic,
                {"key": key, "type": ros_type, "dds_type": dds_type, "hash": type_hash, "samples": []},
            )
            if len(entry["samples"]) >= args.per_topic:
                return
        try:
            raw = sample.payload.to_bytes()
            att = sample.attachment.to_bytes() if sample.attachment is not None else b""
            msg = store.deserialize_cdr(raw, ros_type)
            s = summary(ros_type, msg)
            s["cdr_header"] = raw[:4].hex()
            s["attachment_len"] = len(att)
            s["attachment_seq"] = int.from_bytes(att[0:8], "little", signed=True) if len(att) >= 8 else -1
            s["attachment_gid_len"] = att[16] if len(att) > 16 else -1
            with lock:
                entry["samples"].append(s)
        except Exception as e:  # report, do not die: the test names the failure
            with lock:
                errors.append(f"{key}: {type(e).__name__}: {e}")

    sub = session.declare_subscriber(f"{args.domain}/**", on_sample)

    deadline = time.time() + args.timeout
    tokens = []
    while time.time() < deadline:
        tokens = [str(r.ok.key_expr) for r in session.liveliness().get(f"@ros2_lv/{args.domain}/**", timeout=2.0) if r.ok]
        with lock:
            done = len(topics) >= 6 and all(len(t["samples"]) >= args.per_topic for t in topics.values())
        if done and tokens:
            break
        time.sleep(0.2)

    hashes = {ros: store.hash_rihs01(ros) for ros in TYPES.values()}
    sub.undeclare()
    session.close()
    print(json.dumps({"topics": topics, "tokens": sorted(tokens), "rosbags_hashes": hashes, "errors": errors}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
