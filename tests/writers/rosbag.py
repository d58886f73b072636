"""Writes a ROS 1 bag with Python's `rosbags` (an independent writer) for relume's tests.

    python rosbag.py OUT.bag LAYOUT COMPRESSION FRAMES [EXTRINSIC]

LAYOUT is `ros` (a camera driver's topics: /camera/rgb/image_color, /camera/depth/image,
/camera/rgb/camera_info, /tf) or `realsense` (librealsense's recording layout:
/device_0/sensor_{0,1}/{Depth,Color}_0/image/data, .../info/camera_info, the "Depth Units"
option, each stream's extrinsic to the reference stream under .../tf/0). COMPRESSION is
none, bz2 or lz4. EXTRINSIC (realsense only) is `tx,ty,tz,yaw_deg`: the extrinsic from
the depth (reference) stream to the color stream, as librealsense stores it under
Color_0/tf/0 (p_color = R p_depth + t); without it the two coincide.

Pixels, stamps and poses follow the formulas below; tests/rosbag.rs computes the same
ones and compares them with what relume imported.
"""

import math
import sys
from pathlib import Path

import numpy as np
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

TS = get_typestore(Stores.ROS1_NOETIC)
# The Noetic store lacks tf2_msgs: its one message, as tf2_msgs/msg/TFMessage.msg says.
TS.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
T = TS.types
Header, Time = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]

WIDTH, HEIGHT = 16, 12
FX, FY, CX, CY = 20.5, 21.0, 7.5, 5.75
DEPTH_UNIT_REALSENSE = 0.00025


def stamp_ns(k):
    return 1_000_000_000_000 + k * 33_333_333 + 1_000


def color(k):
    y, x, c = np.mgrid[0:HEIGHT, 0:WIDTH, 0:3]
    return ((k * 31 + x * 7 + y * 13 + c * 50) % 256).astype(np.uint8)


def depth(k):
    y, x = np.mgrid[0:HEIGHT, 0:WIDTH]
    return (1000 + k * 10 + x + y * 3).astype(np.uint16)


def pose(k):
    """World-from-camera: translation, quaternion (x, y, z, w) about y."""
    half = 0.05 * k / 2
    return (0.1 * k, 0.2, -0.05 * k), (0.0, math.sin(half), 0.0, math.cos(half))


def header(ns, frame):
    return Header(seq=0, stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=frame)


def image(ns, frame, encoding, pixels):
    step = pixels.shape[1] * pixels.itemsize * (pixels.shape[2] if pixels.ndim == 3 else 1)
    return T["sensor_msgs/msg/Image"](
        header=header(ns, frame), height=pixels.shape[0], width=pixels.shape[1],
        encoding=encoding, is_bigendian=0, step=step,
        data=np.frombuffer(pixels.tobytes(), dtype=np.uint8))


def camera_info(ns, frame):
    RoI = T["sensor_msgs/msg/RegionOfInterest"]
    return T["sensor_msgs/msg/CameraInfo"](
        header=header(ns, frame), height=HEIGHT, width=WIDTH, distortion_model="plumb_bob",
        D=np.zeros(5), K=np.array([FX, 0, CX, 0, FY, CY, 0, 0, 1.0]),
        R=np.eye(3).flatten(), P=np.array([FX, 0, CX, 0, 0, FY, CY, 0, 0, 0, 1.0, 0]),
        binning_x=0, binning_y=0,
        roi=RoI(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))


def transform(t, q):
    G = T
    return G["geometry_msgs/msg/Transform"](
        translation=G["geometry_msgs/msg/Vector3"](x=t[0], y=t[1], z=t[2]),
        rotation=G["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]))


def main():
    out, layout, compression, frames = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
    extrinsic = [float(v) for v in sys.argv[5].split(",")] if len(sys.argv) > 5 else None
    path = Path(out)
    path.unlink(missing_ok=True)
    writer = Writer(path)
    # Small chunks (a frame or two each), so that tests can damage one and keep the rest.
    writer.chunk_threshold = 2000
    if compression != "none":
        writer.set_compression(getattr(Writer.CompressionFormat, compression.upper()))
    with writer as w:
        def connection(topic, msgtype):
            return w.add_connection(topic, msgtype, typestore=TS)

        def put(conn, ns, msg):
            w.write(conn, ns, TS.serialize_ros1(msg, conn.msgtype))

        if layout == "ros":
            c_img = connection("/camera/rgb/image_color", "sensor_msgs/msg/Image")
            d_img = connection("/camera/depth/image", "sensor_msgs/msg/Image")
            info = connection("/camera/rgb/camera_info", "sensor_msgs/msg/CameraInfo")
            tf = connection("/tf", "tf2_msgs/msg/TFMessage")
            for k in range(frames):
                ns = stamp_ns(k)
                t, q = pose(k)
                stamped = T["geometry_msgs/msg/TransformStamped"](
                    header=header(ns, "world"), child_frame_id="cam", transform=transform(t, q))
                put(tf, ns, T["tf2_msgs/msg/TFMessage"](transforms=[stamped]))
                put(info, ns, camera_info(ns, "cam"))
                put(c_img, ns, image(ns, "cam", "rgb8", color(k)))
                put(d_img, ns + 1_000_000, image(ns + 1_000_000, "cam", "16UC1", depth(k)))
        elif layout == "realsense":
            D, C = "/device_0/sensor_0/Depth_0", "/device_0/sensor_1/Color_0"
            version = connection("/file_version", "std_msgs/msg/UInt32")
            put(version, stamp_ns(0), T["std_msgs/msg/UInt32"](data=3))
            units = connection("/device_0/sensor_0/option/Depth Units/value", "std_msgs/msg/Float32")
            put(units, stamp_ns(0), T["std_msgs/msg/Float32"](data=DEPTH_UNIT_REALSENSE))
            d_tf = connection(D + "/tf/0", "geometry_msgs/msg/Transform")
            put(d_tf, stamp_ns(0), transform((0, 0, 0), (0, 0, 0, 1)))
            c_tf = connection(C + "/tf/0", "geometry_msgs/msg/Transform")
            if extrinsic:
                tx, ty, tz, yaw = extrinsic
                h = math.radians(yaw) / 2
                put(c_tf, stamp_ns(0), transform((tx, ty, tz), (0, math.sin(h), 0, math.cos(h))))
            else:
                put(c_tf, stamp_ns(0), transform((0, 0, 0), (0, 0, 0, 1)))
            d_info = connection(D + "/info/camera_info", "sensor_msgs/msg/CameraInfo")
            c_info = connection(C + "/info/camera_info", "sensor_msgs/msg/CameraInfo")
            put(d_info, stamp_ns(0), camera_info(stamp_ns(0), "0"))
            put(c_info, stamp_ns(0), camera_info(stamp_ns(0), "0"))
            d_img = connection(D + "/image/data", "sensor_msgs/msg/Image")
            c_img = connection(C + "/image/data", "sensor_msgs/msg/Image")
            for k in range(frames):
                ns = stamp_ns(k)
                put(c_img, ns, image(ns, "0", "rgb8", color(k)))
                put(d_img, ns + 1_000_000, image(ns + 1_000_000, "0", "mono16", depth(k)))
        else:
            sys.exit(f"unknown layout {layout}")


if __name__ == "__main__":
    main()
