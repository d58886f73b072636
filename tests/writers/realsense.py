"""Records a RealSense `.bag` with librealsense's own recorder (pyrealsense2 2.55, the last
release that writes ROS 1 bags; 2.56 and later write ROS 2 `.db3` files) from a software
device: no camera needed. For relume's tests.

    python realsense.py OUT.bag FRAMES [separate]

Depth (z16, 0.1 mm per unit) sees a wall at 2 m: every pixel 20000 + frame. Color (rgb8)
pixel (x, y) of frame k is (k, x, y). Both 64x48. Without `separate` the two streams share
intrinsics and the depth-to-color extrinsic is the identity; with it, the depth camera has
other intrinsics and sits 1.5 cm to the color camera's right (p_color = p_depth + t,
t = (0.015, 0, 0)). Frame k is stamped 1000 + 33.3 k ms.
"""

import sys

import numpy as np
import pyrealsense2 as rs

W, H = 64, 48


def intrinsics(fx, fy, ppx, ppy):
    k = rs.intrinsics()
    k.width, k.height, k.fx, k.fy, k.ppx, k.ppy = W, H, fx, fy, ppx, ppy
    k.model, k.coeffs = rs.distortion.brown_conrady, [0.0] * 5
    return k


def video_stream(kind, uid, fmt, bpp, k):
    s = rs.video_stream()
    s.type, s.index, s.uid = kind, 0, uid
    s.width, s.height, s.fps, s.bpp, s.fmt, s.intrinsics = W, H, 30, bpp, fmt, k
    return s


def main():
    out, frames = sys.argv[1], int(sys.argv[2])
    separate = len(sys.argv) > 3 and sys.argv[3] == "separate"
    color_k = intrinsics(55.0, 55.5, 32.0, 24.0)
    depth_k = intrinsics(48.0, 48.0, 31.0, 23.0) if separate else color_k
    device = rs.software_device()
    depth_sensor, color_sensor = device.add_sensor("Depth"), device.add_sensor("Color")
    depth_profile = depth_sensor.add_video_stream(
        video_stream(rs.stream.depth, 0, rs.format.z16, 2, depth_k))
    color_profile = color_sensor.add_video_stream(
        video_stream(rs.stream.color, 1, rs.format.rgb8, 3, color_k))
    depth_sensor.add_read_only_option(rs.option.depth_units, 0.0001)
    extrinsic = rs.extrinsics()
    extrinsic.rotation = [1, 0, 0, 0, 1, 0, 0, 0, 1]
    extrinsic.translation = [0.015, 0.0, 0.0] if separate else [0.0, 0.0, 0.0]
    depth_profile.register_extrinsics_to(color_profile, extrinsic)
    recorder = rs.recorder(out, device)
    depth_sensor.open(depth_profile)
    color_sensor.open(color_profile)
    depth_sensor.start(lambda f: None)
    color_sensor.start(lambda f: None)
    for k in range(frames):
        depth = np.full((H, W), 20000 + k, dtype=np.uint16)
        color = np.zeros((H, W, 3), dtype=np.uint8)
        color[..., 0] = k
        color[..., 1] = np.arange(W)[None, :]
        color[..., 2] = np.arange(H)[:, None]
        for sensor, profile, pixels, bpp in (
            (depth_sensor, depth_profile, depth, 2),
            (color_sensor, color_profile, color, 3),
        ):
            f = rs.software_video_frame()
            f.pixels, f.bpp, f.stride = pixels.tobytes(), bpp, W * bpp
            f.timestamp, f.domain = 1000.0 + 33.3 * k, rs.timestamp_domain.hardware_clock
            f.frame_number, f.profile = k, profile.as_video_stream_profile()
            sensor.on_video_frame(f)
    del recorder  # closes the bag


if __name__ == "__main__":
    main()
