"""filter.oidn: Intel Open Image Denoise (pyoidn, `pip install pyoidn`) on the four
irradiance layers of a differential renderer, in place of paper 001's axis-aligned
filter (pipeline: mixed-reality-oidn.toml beside this file).

Each layer (E_R and E_RV, direct and indirect) is denoised on its own by OIDN's "RT"
filter in HDR mode with the G-buffer's world normals as a clean guide. The albedo guide
is white: the layers are irradiance, which carries no surface texture (OIDN takes a
normal guide only beside an albedo). Pixels without a surface (no normal) or without
an estimate (NaN) are passed through, and kept out of the network's input.
"""

import sys

import numpy as np
import pyoidn

import relume_stage

LAYERS = ["e_r_dir", "e_r_ind", "e_rv_dir", "e_rv_ind"]


def process(frame, settings):
    normal = frame.inputs["world_normal"]
    valid = np.any(normal != 0, axis=2, keepdims=True)
    normal = np.ascontiguousarray(np.clip(normal, -1.0, 1.0))
    albedo = np.ones_like(normal)
    out = {}
    for layer in LAYERS:
        given = frame.inputs[layer]
        # Pixels without an estimate (NaN) must not spread through the network.
        known = valid & np.isfinite(given).all(axis=2, keepdims=True)
        noisy = np.ascontiguousarray(np.where(known, np.maximum(given, 0.0), 0.0))
        clean = pyoidn.denoise(
            noisy, albedo, normal, hdr=True, clean_aux=True, quality=settings["quality"]
        )
        out["filtered_" + layer] = np.where(known, clean, given)
    return out


if __name__ == "__main__":
    sys.exit(relume_stage.run(process, settings={"quality": "high"}))
