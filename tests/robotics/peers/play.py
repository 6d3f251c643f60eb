"""A robot's camera and LiDAR played from a bag over DDS (our transport): ``/tf_static`` once (transient
local), then per frame CameraInfo, image and scan at 10 Hz, round and round until the timeout.

``python play.py BAG IMAGE_TOPIC POINTS_TOPIC CAMERA_INFO_TOPIC TIMEOUT_S``
"""

from __future__ import annotations

import sys
import time

from semattnet.robotics.bags import open_bag
from semattnet.robotics.bags.decode import msg_stamp_ns
from semattnet.robotics.ros.dds import DdsTransport
from semattnet.robotics.ros.transport import SENSOR_QOS, TF_STATIC_QOS


def main(bag: str, image: str, points: str, info: str, timeout: float) -> int:
    with open_bag(bag) as reader:
        msgs = [(c.topic, c.msgtype, reader.deserialize(raw, c.msgtype)) for c, _, raw in reader.messages()]
    transport = DdsTransport(0, loopback=True)
    pubs = {
        topic: transport.advertise(topic, msgtype, TF_STATIC_QOS if topic == "/tf_static" else SENSOR_QOS)
        for topic, msgtype, _ in msgs
    }
    for topic, _, msg in msgs:
        if topic == "/tf_static":
            pubs[topic].publish(msg)
    order = {info: 0, image: 1, points: 2}
    frames = sorted((m for m in msgs if m[0] in order), key=lambda m: (msg_stamp_ns(m[2].header.stamp), order[m[0]]))
    end = time.monotonic() + timeout
    try:
        while time.monotonic() < end:
            for topic, _, msg in frames:
                pubs[topic].publish(msg)
                if topic == points:
                    time.sleep(0.1)
    finally:
        transport.close()
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:5], float(sys.argv[5])))
