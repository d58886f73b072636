"""Writes an Azure Kinect-style Matroska recording with ffmpeg's muxer (PyAV), for
tests/k4a.rs: relume's reader meets a file it did not write.

The layout is k4arecorder's (Azure-Kinect-Sensor-SDK, src/record/internal/matroska_write.cpp):
tracks named COLOR (MJPG, here as ffmpeg writes it: V_MJPEG) and DEPTH (16-bit big-endian
millimetres, FourCC b16g: ffmpeg writes V_UNCOMPRESSED with that ColourSpace), the
calibration as the attachment calibration.json, tags K4A_DEPTH_MODE and K4A_START_OFFSET_NS.
The calibration's numbers are a real device's (the SDK's TestCalibration.json), the depth
lens as Brown-Conrady and the color lens as Rational 6KT.

The scene is one plane, rendered into the depth camera through its lens (each depth pixel
undistorted by Newton's method with the SDK's forward model, written here from the SDK's
intrinsic_transformation.c) and, as truth, into the color camera: OUT.truth holds each
color pixel's true depth in millimetres (float32, little-endian, row-major) where the
depth camera sees the same point between its pixel centres, its negative within half a pixel
outside them (the edge pixels' own footprint), else 0. Each frame's JPEG is also
written to OUT.color<k>.jpg.

usage: k4a.py OUT FRAMES [--short-depth K] [--no-calibration] [--bgra]
"""

import io
import json
import sys
from fractions import Fraction

import av
import numpy as np
from PIL import Image

DEPTH_SIZE = (320, 288)  # NFOV_2X2BINNED: binned 512x512, crop (96, 90)
DEPTH_MODE = ((512, 512), (96, 90))
COLOR_SIZE = (1280, 720)  # 720P: binned 1280x960, crop (0, 120)
COLOR_MODE = ((1280, 960), (0, 120))
START_OFFSET_NS = 211_000_000
PERIOD_MS = 33

DEPTH_PARAMS = [0.51023387908935547, 0.50027763843536377, 0.493516743183136,
                0.49370375275611877, 0.43608897924423218, 0.0683431550860405,
                0.00436929939314723, 0.77323317527771, 0.14791269600391388,
                0.020083265379071236, 0.0, 0.0, 6.3889012380968779e-5,
                -8.9991714048665017e-5, 1.7389928102493286]
COLOR_PARAMS = [0.50639921426773071, 0.50126415491104126, 0.47318029403686523,
                0.6306186318397522, 0.66883313655853271, -2.7474379539489746,
                1.5316581726074219, 0.54537504911422729, -2.5778603553771973,
                1.4640182256698608, 0.001088816556148231, 0.0010363152250647545,
                -8.56648402987048e-5, 0.00083269347669556737, 1.3999999761581421]
COLOR_R = [0.99999129772186279, 0.00413146335631609, 0.00055089825764298439,
           -0.0041664708405733109, 0.99446302652359009, 0.10500419139862061,
           -0.00011402699601603672, -0.10500557720661163, 0.99447160959243774]
COLOR_T = [-0.0319669172167778, -0.001937559456564486, 0.0042453580535948277]


def camera(params, mode, rational6kt, radius):
    """Pixel intrinsics of a mode, as the SDK's mode_specific_calibration.c derives them."""
    (bw, bh), (ox, oy) = mode
    cx, cy, fx, fy = params[:4]
    return dict(cx=cx * bw - ox - 0.5, cy=cy * bh - oy - 0.5, fx=fx * bw, fy=fy * bh,
                k=params[4:10], cod=params[10:12], p2=params[12], p1=params[13],
                six=rational6kt, radius=radius)


def distort(c, x, y):
    """The SDK's transformation_project_internal on the z = 1 plane (NaN outside)."""
    k1, k2, k3, k4, k5, k6 = c["k"]
    xp, yp = x - c["cod"][0], y - c["cod"][1]
    rs = xp * xp + yp * yp
    a = 1 + k1 * rs + k2 * rs * rs + k3 * rs ** 3
    b = 1 + k4 * rs + k5 * rs * rs + k6 * rs ** 3
    d = a / b
    cross = xp * yp if c["six"] else 2 * xp * yp
    xd = xp * d + (rs + 2 * xp * xp) * c["p2"] + cross * c["p1"]
    yd = yp * d + (rs + 2 * yp * yp) * c["p1"] + cross * c["p2"]
    out = rs > c["radius"] ** 2
    xd = np.where(out, np.nan, xd + c["cod"][0])
    yd = np.where(out, np.nan, yd + c["cod"][1])
    return xd, yd


def undistort(c, xd, yd):
    """Newton's method with a numerical Jacobian, from the distorted point."""
    x, y = xd.copy(), yd.copy()
    h = 1e-7
    for _ in range(40):
        fx, fy = distort(c, x, y)
        ex, ey = fx - xd, fy - yd
        ax, ay = distort(c, x + h, y)
        bx, by = distort(c, x, y + h)
        j11, j21, j12, j22 = (ax - fx) / h, (ay - fy) / h, (bx - fx) / h, (by - fy) / h
        det = j11 * j22 - j12 * j21
        x = x - (j22 * ex - j12 * ey) / det
        y = y - (j11 * ey - j21 * ex) / det
    fx, fy = distort(c, x, y)
    bad = ~(np.abs(fx - xd) < 1e-9) | ~(np.abs(fy - yd) < 1e-9)
    return np.where(bad, np.nan, x), np.where(bad, np.nan, y)


def rays(c, size):
    u, v = np.meshgrid(np.arange(size[0], dtype=np.float64),
                       np.arange(size[1], dtype=np.float64))
    return undistort(c, (u - c["cx"]) / c["fx"], (v - c["cy"]) / c["fy"])


def main():
    out, frames = sys.argv[1], int(sys.argv[2])
    args = sys.argv[3:]
    short_depth = int(args[args.index("--short-depth") + 1]) if "--short-depth" in args else -1
    bgra = "--bgra" in args

    depth = camera(DEPTH_PARAMS, DEPTH_MODE, False, 1.7389928082607931)
    color = camera(COLOR_PARAMS, COLOR_MODE, True, 1.7)  # MetricRadius 0: the SDK's 1.7

    # The plane n . X = dist in the depth camera's frame: a wall 1.6 m ahead, tilted.
    n = np.array([0.15, -0.25, 1.0])
    n /= np.linalg.norm(n)
    dist = 1.6
    rx, ry = rays(depth, DEPTH_SIZE)
    z = dist / (n[0] * rx + n[1] * ry + n[2])
    depth_mm = np.where(np.isfinite(z) & (z > 0), np.round(z * 1000.0), 0).astype(np.uint16)

    # Truth in the color view: the plane in the color frame, X_c = R X_d + t.
    r = np.array(COLOR_R).reshape(3, 3)
    t = np.array(COLOR_T)
    nc = r @ n
    dist_c = dist + nc @ t
    cx_, cy_ = rays(color, COLOR_SIZE)
    zc = dist_c / (nc[0] * cx_ + nc[1] * cy_ + nc[2])
    # Seen by the depth camera inside its pixel centres' hull.
    pts = np.stack([cx_ * zc, cy_ * zc, zc], axis=-1) - t
    pd = pts @ r  # R^T (X_c - t)
    xd, yd = distort(depth, pd[..., 0] / pd[..., 2], pd[..., 1] / pd[..., 2])
    u = xd * depth["fx"] + depth["cx"]
    v = yd * depth["fy"] + depth["cy"]
    seen = (u >= 0) & (u <= DEPTH_SIZE[0] - 1) & (v >= 0) & (v <= DEPTH_SIZE[1] - 1)
    # Between the outermost pixel centres and the image's edge: seen by the edge pixels,
    # not between four of them (negative truth: depth may or may not be registered there).
    fringe = ~seen & (u >= -0.5) & (u <= DEPTH_SIZE[0] - 0.5) & (v >= -0.5) & (v <= DEPTH_SIZE[1] - 0.5)
    truth = np.where(seen & np.isfinite(zc), zc * 1000.0, 0.0)
    truth = np.where(fringe & np.isfinite(zc), -zc * 1000.0, truth).astype("<f4")
    truth.tofile(out + ".truth")

    def cam_json(params, location, purpose, model, radius, rot, trans, sensor):
        return {
            "Intrinsics": {"ModelParameterCount": 15, "ModelParameters": params,
                           "ModelType": model},
            "Location": location, "Purpose": purpose, "MetricRadius": radius,
            "Rt": {"Rotation": rot, "Translation": trans},
            "SensorHeight": sensor[1], "SensorWidth": sensor[0],
            "Shutter": "CALIBRATION_ShutterTypeUndefined",
            "ThermalAdjustmentParams": {"Params": [0] * 12},
        }

    calibration = {"CalibrationInformation": {"Cameras": [
        cam_json(DEPTH_PARAMS, "CALIBRATION_CameraLocationD0", "CALIBRATION_CameraPurposeDepth",
                 "CALIBRATION_LensDistortionModelBrownConrady", 1.7389928082607931,
                 [1, 0, 0, 0, 1, 0, 0, 0, 1], [0, 0, 0], (1024, 1024)),
        cam_json(COLOR_PARAMS, "CALIBRATION_CameraLocationPV0",
                 "CALIBRATION_CameraPurposePhotoVideo",
                 "CALIBRATION_LensDistortionModelRational6KT", 0, COLOR_R, COLOR_T, (4096, 3072)),
    ], "InertialSensors": [], "Metadata": {"SerialId": "000000000000"}}}

    container = av.open(out, "w", format="matroska",
                        container_options={"allow_raw_vfw": "1", "strict": "experimental"})
    if bgra:
        c = container.add_stream("rawvideo", rate=30)
        c.pix_fmt = "bgra"
        c.codec_context.codec_tag = "BGRA"
    else:
        c = container.add_stream("mjpeg", rate=30)
        c.pix_fmt = "yuvj420p"
    c.width, c.height = COLOR_SIZE
    c.metadata["title"] = "COLOR"
    d = container.add_stream("rawvideo", rate=30)
    d.width, d.height = DEPTH_SIZE
    d.pix_fmt = "gray16be"
    d.codec_context.codec_tag = "b16g"
    d.metadata["title"] = "DEPTH"
    if "--no-calibration" not in args:
        container.add_attachment("calibration.json", "application/octet-stream",
                                 json.dumps(calibration).encode())
    container.metadata["K4A_DEPTH_MODE"] = "NFOV_2X2BINNED"
    container.metadata["K4A_COLOR_MODE"] = "MJPG_720P"
    container.metadata["K4A_START_OFFSET_NS"] = str(START_OFFSET_NS)

    yy, xx = np.mgrid[0:COLOR_SIZE[1], 0:COLOR_SIZE[0]]
    for k in range(frames):
        rgb = np.stack([(xx * 3 + k * 20) % 256, (yy * 2) % 256,
                        ((xx // 40 + yy // 40) % 2) * 200 + 20], axis=-1).astype(np.uint8)
        if bgra:
            payload = rgb[..., ::-1]
            payload = np.concatenate([payload, np.full(payload.shape[:2] + (1,), 255, np.uint8)],
                                     axis=-1).tobytes()
            np.save(out + f".color{k}.npy", rgb)
        else:
            buf = io.BytesIO()
            Image.fromarray(rgb).save(buf, "JPEG", quality=90)
            payload = buf.getvalue()
            with open(out + f".color{k}.jpg", "wb") as f:
                f.write(payload)
        depth_bytes = depth_mm.astype(">u2").tobytes()
        if k == short_depth:
            depth_bytes = depth_bytes[: len(depth_bytes) // 2]
        for stream, data in ((c, payload), (d, depth_bytes)):
            packet = av.Packet(data)
            packet.stream = stream
            packet.pts = packet.dts = k * PERIOD_MS
            packet.time_base = Fraction(1, 1000)
            container.mux(packet)
    container.close()


if __name__ == "__main__":
    main()
