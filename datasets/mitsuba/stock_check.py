#!/usr/bin/env python3
"""One sphere rendered by Mitsuba 3's stock volumetric path tracer, for checking `workbench synth pbr`.

The scene of tests/it/pbr.rs `renders_what_mitsuba_stock_volpath_renders`: a homogeneous medium
(σt 2/mm, single-scattering albedo 0.9, 0.96, 0.92, isotropic phase) inside a GGX rough dielectric
sphere (η 1.62, radius 15 mm, centre 200 mm in front of the camera), 80×80 pixels, fx = fy = 300
px, no distortion. Mitsuba's volpath cannot reach a directional light through a dielectric
boundary, so the light is a spherical lamp 5 m away of angular radius 0.15 rad whose irradiance is
1 (radiance 1/(π sin²0.15)); toward (0, −0.8, −0.6) in the OpenCV camera frame. The image is written
as raw little-endian float32 RGB, row-major, top row first: stock_alpha<α>.f32 beside this script.

Needs `pip install mitsuba` (tested with 3.9.1, scalar_rgb; about 2 min for 8192 spp on 2 cores);
neither the build nor the tests need it, they read the committed .f32 files.
Usage: datasets/mitsuba/stock_check.py [--alpha 0.3] [--spp 8192]
"""
import argparse
import math
import os

import numpy as np

try:
    import mitsuba as mi
except ImportError:  # pragma: no cover
    raise SystemExit("stock_check.py: needs Mitsuba 3 (pip install mitsuba)")


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--alpha", type=float, default=0.3)
    p.add_argument("--spp", type=int, default=8192)
    p.add_argument("--variant", default="scalar_rgb")
    a = p.parse_args()
    mi.set_variant(a.variant)
    delta = 0.15
    l = np.array([0.0, -0.8, -0.6])
    l /= np.linalg.norm(l)
    c = np.array([0.0, 0.0, 200.0])
    dist = 5000.0
    lamp = c + dist * l
    radiance = 1.0 / (math.pi * math.sin(delta) ** 2)
    fov = math.degrees(2 * math.atan(40 / 300))
    scene = mi.load_dict({
        "type": "scene",
        "integrator": {"type": "volpath", "max_depth": -1, "rr_depth": 8},
        "sensor": {
            "type": "perspective", "fov": fov, "fov_axis": "x",
            # Looking along +z with image up = −y: the OpenCV camera frame.
            "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 0], target=[0, 0, 1], up=[0, -1, 0]),
            "film": {"type": "hdrfilm", "width": 80, "height": 80, "rfilter": {"type": "box"},
                     "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": a.spp},
        },
        "ball": {
            "type": "sphere", "center": c.tolist(), "radius": 15.0,
            "bsdf": {"type": "roughdielectric", "distribution": "ggx", "alpha": a.alpha,
                     "int_ior": 1.62, "ext_ior": 1.0},
            "interior": {"type": "homogeneous", "sigma_t": 2.0,
                         "albedo": {"type": "rgb", "value": [0.9, 0.96, 0.92]},
                         "phase": {"type": "isotropic"}},
        },
        "lamp": {
            "type": "sphere", "center": lamp.tolist(), "radius": dist * math.sin(delta),
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [radiance] * 3}},
        },
    })
    img = np.array(mi.render(scene))
    out = os.path.join(os.path.dirname(os.path.abspath(__file__)), f"stock_alpha{a.alpha:g}.f32")
    img.astype("<f4").tofile(out)
    print(out, img.shape, img.mean(axis=(0, 1)))


if __name__ == "__main__":
    main()
