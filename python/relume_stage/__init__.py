"""Write a relume stage in Python.

A stage is a function ``process(frame, settings) -> dict`` and a call to :func:`run`::

    import relume_stage

    def process(frame, settings):
        return {"scaled": frame.inputs["image"] * settings["gain"]}

    relume_stage.run(process, settings={"gain": 1.0})

relume starts the program once per run and sends it one frame at a time over its
standard input; the replies go back over its standard output (protocol 1,
``docs/external-stages.md`` in relume's repository). :func:`run` speaks the protocol:
the function sees numpy arrays of shape ``(height, width, channels)`` (and poses as
dicts of ``translation`` and ``rotation``) and returns arrays (and poses) of the kinds
its outputs are declared with in the pipeline file. Anything the
program prints goes to standard error, which relume shows prefixed with the stage's
name; standard output belongs to the protocol.
"""

import mmap
import struct
import sys
import time
import traceback

import msgpack
import numpy as np

PROTOCOL = 1
MAGIC = b"RLX1"

# Kind name -> (channels, numpy dtype), as relume sends them.
LAYOUTS = {
    "color": (3, np.dtype("u1")),
    "depth": (1, np.dtype("<f4")),
    "points": (3, np.dtype("<f4")),
    "normals": (3, np.dtype("<f4")),
    "radiance": (3, np.dtype("<f4")),
    "scalar": (1, np.dtype("<f4")),
    "labels": (1, np.dtype("u1")),
}
DTYPE_NAMES = {np.dtype("u1"): "u8", np.dtype("<f4"): "f32"}
NAME_DTYPES = {"u8": np.dtype("u1"), "f32": np.dtype("<f4")}


class _Shared:
    """The shared memory relume offers: inputs are read in place, outputs copied in."""

    def __init__(self, offer):
        with open(offer["path"], "r+b") as f:
            self.map = mmap.mmap(f.fileno(), offer["size"])
        self.size = offer["size"]
        self.output_offset = offer["output_offset"]

    def array(self, offset, shape, dtype):
        count = int(np.prod(shape))
        return np.frombuffer(self.map, dtype=dtype, count=count, offset=offset).reshape(shape)


class Frame:
    """One frame as the stage sees it.

    ``index``: the frame's number in the run; ``stamp_ns``: its time stamp;
    ``transport``: "shm" when the images came through shared memory, else "pipe";
    ``seed``: a number fixed by (run seed, frame, stage name), for random numbers that
    are the same on every run (``numpy.random.default_rng(frame.seed)``); ``inputs``:
    role -> array of shape (height, width, channels) for images, and for a pose (the
    camera-to-world transform) a dict with ``translation`` (metres) and ``rotation`` (a
    unit quaternion x, y, z, w), each a float64 array.
    """

    def __init__(self, index, stamp_ns, seed, inputs, transport="pipe"):
        self.transport = transport
        self.index = index
        self.stamp_ns = stamp_ns
        self.seed = seed
        self.inputs = inputs


class StageError(Exception):
    """Raise it to stop the run with a message naming the stage and frame."""


def _read_exact(stream, n):
    chunks = []
    left = n
    while left:
        chunk = stream.read(left)
        if not chunk:
            raise EOFError
        chunks.append(chunk)
        left -= len(chunk)
    return b"".join(chunks)


def _read_into(stream, array):
    view = memoryview(array).cast("B")
    got = 0
    while got < len(view):
        n = stream.readinto(view[got:])
        if not n:
            raise EOFError
        got += n


def _read_message(stream):
    head = _read_exact(stream, 8)
    if head[:4] != MAGIC:
        raise StageError("relume sent a message without the RLX1 magic")
    (length,) = struct.unpack("<I", head[4:])
    return msgpack.unpackb(_read_exact(stream, length), raw=False)


def _write_message(stream, meta, blobs=()):
    body = msgpack.packb(meta, use_bin_type=True)
    stream.write(MAGIC + struct.pack("<I", len(body)) + body)
    for blob in blobs:
        stream.write(blob)
    stream.flush()


def _typed(name, text, default):
    """A setting's text as the type of its default."""
    if isinstance(default, bool):
        if text in ("true", "false"):
            return text == "true"
        raise StageError(f"setting {name}={text!r}: expected true or false")
    try:
        return type(default)(text)
    except ValueError:
        raise StageError(
            f"setting {name}={text!r}: expected {type(default).__name__}"
        ) from None


def _settings(given, declared):
    unknown = sorted(set(given) - set(declared))
    if unknown:
        known = ", ".join(sorted(declared)) or "none"
        raise StageError(f"unknown setting {unknown[0]!r} (this stage takes: {known})")
    out = dict(declared)
    for name, text in given.items():
        out[name] = _typed(name, text, declared[name])
    return out


def _pose(role, value):
    """A pose output: a dict (or pair) of translation [x, y, z] and rotation [x, y, z, w]."""
    if isinstance(value, dict):
        translation, rotation = value.get("translation"), value.get("rotation")
    else:
        translation, rotation = value
    translation = [float(v) for v in np.asarray(translation, dtype=np.float64).ravel()]
    rotation = [float(v) for v in np.asarray(rotation, dtype=np.float64).ravel()]
    if len(translation) != 3 or len(rotation) != 4:
        raise StageError(
            f"output {role!r} is a pose: a translation of 3 numbers and a rotation of 4"
        )
    return {"role": role, "kind": "pose", "translation": translation, "rotation": rotation}


def _output(role, kind, array, height, width):
    channels, dtype = LAYOUTS[kind]
    array = np.asarray(array)
    if array.ndim == 2 and channels == 1:
        array = array[:, :, None]
    if array.dtype != dtype:
        if dtype == np.dtype("u1") and array.dtype.kind == "f":
            raise StageError(
                f"output {role!r} is {array.dtype}: a {kind} image is 8-bit; convert it"
            )
        if dtype == np.dtype("u1") and array.size and (array.min() < 0 or array.max() > 255):
            raise StageError(
                f"output {role!r} holds {array.min()} to {array.max()}: a {kind} image "
                "is 8-bit (0 to 255)"
            )
        array = array.astype(dtype)
    if array.ndim != 3 or array.shape[2] != channels:
        raise StageError(
            f"output {role!r} has shape {array.shape}: a {kind} image is "
            f"(height, width, {channels})"
        )
    array = np.ascontiguousarray(array)
    meta = {
        "role": role,
        "kind": kind,
        "width": int(array.shape[1]),
        "height": int(array.shape[0]),
        "channels": channels,
        "dtype": DTYPE_NAMES[dtype],
    }
    return meta, memoryview(array).cast("B")


def _into_shared(shared, replies):
    """Copies the outputs into the shared memory's output region, where they fit; the
    rest go by pipe."""
    offset = shared.output_offset
    out = []
    for meta, view in replies:
        n = len(view)
        if offset + n <= shared.size:
            shared.map[offset : offset + n] = view
            meta = dict(meta, offset=offset)
            offset += n
            view = b""
        out.append((meta, view))
    return out


def run(process, settings=None):
    """Serves relume's requests until the end of the stream, calling
    ``process(frame, settings)`` for each frame.

    Input arrays may be views of shared memory that the next frame overwrites: copy
    what you keep across frames.

    ``settings``: the stage's own parameters with their defaults (name -> bool, int,
    float or str); the pipeline's ``settings = ["name=value"]`` override them, typed as
    the default is. ``process`` returns a dict role -> array for every declared output.
    """
    declared = dict(settings or {})
    stdin = sys.stdin.buffer
    stdout = sys.stdout.buffer
    # Prints go to standard error: standard output carries the protocol.
    sys.stdout = sys.stderr
    try:
        hello = _read_message(stdin)
    except EOFError:
        return 0
    if hello.get("protocol") != PROTOCOL:
        _write_message(stdout, {"type": "ready", "protocol": PROTOCOL})
        return 1
    try:
        values = _settings(hello.get("settings", {}), declared)
    except StageError as e:
        _write_message(stdout, {"type": "error", "message": str(e)})
        return 1
    outputs = hello.get("outputs", {})
    shared = None
    if hello.get("shm"):
        try:
            shared = _Shared(hello["shm"])
        except OSError as e:
            print(f"relume_stage: shared memory unusable ({e}); using the pipe", file=sys.stderr)
    ready = {"type": "ready", "protocol": PROTOCOL}
    if shared is not None:
        ready["transport"] = "shm"
    _write_message(stdout, ready)
    while True:
        try:
            request = _read_message(stdin)
        except EOFError:
            return 0
        if request["type"] == "end":
            return 0
        inputs = {}
        height = width = 0
        for meta in request["inputs"]:
            channels = meta["channels"]
            height, width = meta["height"], meta["width"]
            shape, dtype = (height, width, channels), NAME_DTYPES[meta["dtype"]]
            if meta.get("offset") is not None:
                # A view of the shared memory: valid until the next frame.
                array = shared.array(meta["offset"], shape, dtype)
            else:
                array = np.empty(shape, dtype=dtype)
                _read_into(stdin, array)
            inputs[meta["role"]] = array
        transport = "shm" if any(m.get("offset") is not None for m in request["inputs"]) else "pipe"
        for value in request.get("values", []):
            inputs[value["role"]] = {
                "translation": np.array(value["translation"], dtype=np.float64),
                "rotation": np.array(value["rotation"], dtype=np.float64),
            }
        frame = Frame(request["index"], request["stamp_ns"], request["seed"], inputs, transport)
        start = time.perf_counter()
        try:
            result = process(frame, values)
            if not isinstance(result, dict):
                raise StageError(f"process returned {type(result).__name__}, not a dict")
            missing = [r for r in outputs if r not in result]
            if missing:
                raise StageError(f"process returned no {missing[0]!r}")
            extra = [r for r in result if r not in outputs]
            if extra:
                raise StageError(f"process returned {extra[0]!r}, which is not a declared output")
            replies = [
                _output(r, outputs[r], result[r], height, width)
                for r in outputs
                if outputs[r] != "pose"
            ]
            poses = [_pose(r, result[r]) for r in outputs if outputs[r] == "pose"]
        except StageError as e:
            _write_message(stdout, {"type": "error", "message": str(e)})
            return 1
        except Exception:
            _write_message(stdout, {"type": "error", "message": traceback.format_exc().rstrip()})
            return 1
        compute_ms = (time.perf_counter() - start) * 1e3
        if shared is not None:
            replies = _into_shared(shared, replies)
        _write_message(
            stdout,
            {
                "type": "frame",
                "index": request["index"],
                "outputs": [m for m, _ in replies],
                "values": poses,
                "compute_ms": compute_ms,
            },
            [b for _, b in replies],
        )
