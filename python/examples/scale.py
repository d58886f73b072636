"""An external relume stage in numpy: a float image (depth, radiance, ...) times
`gain`, plus seeded dither of amplitude `dither` (the same on every run: it draws from
the frame's seed). Its pipeline, python/examples/scale.toml, declares the ports:

    [[stage]]
    kind = "external"
    name = "scale"
    inputs = { image = "depth" }
    params = { interpreter = "python3", program = "scale.py",
               input_kinds = ["image=depth"], output_kinds = ["scaled=depth"],
               settings = ["gain=0.5", "dither=0.001"] }
"""

import sys

import numpy as np

import relume_stage

def process(frame, settings):
    image = frame.inputs["image"]
    scaled = image * np.float32(settings["gain"])
    if settings["dither"] > 0:
        rng = np.random.default_rng(frame.seed)
        noise = rng.uniform(-1.0, 1.0, size=image.shape).astype(np.float32)
        scaled += np.float32(settings["dither"]) * noise
    return {"scaled": scaled}


if __name__ == "__main__":
    sys.exit(relume_stage.run(process, settings={"gain": 1.0, "dither": 0.0}))
