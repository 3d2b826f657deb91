#!/usr/bin/env python3
"""A `workbench export --to mitsuba` file loaded by Mitsuba 3's own parser, read back and rendered.

Loads the exported scene with `mitsuba.load_file`, checks it holds one sphere with a rough
dielectric boundary around a homogeneous medium, and prints what Mitsuba read as one JSON line:
the sphere's radius, the boundary's GGX alpha and interior index, and the medium's extinction
(sigma_t times its scale, per mm) and single-scattering albedo per channel. With --out it then
renders that sphere, as loaded, with the stock volumetric path tracer: the camera at the origin
looking along +z (the OpenCV camera frame: image up is -y), the sphere's centre --distance mm in
front of it, fx = fy = --fx pixels, the image --size pixels square with its centre at
(size - 1)/2 in OpenCV's pixel convention. Mitsuba's volpath cannot reach a directional light
through a dielectric boundary, so the light is a spherical lamp 5 m away of angular radius
0.15 rad and irradiance 1, toward --light (camera frame), as in stock_check.py. The image is
written as raw little-endian float32 RGB, row-major, top row first.

Used by the suite (tests/it/medium.rs, `the_mitsuba_export_renders_as_the_fitted_medium`) with
the Mitsuba that scripts/setup-system.sh installs (3.9.1, scalar_rgb, no numpy needed).
Usage: render_export.py mitsuba.xml [--out image.f32 --distance 350 --fx 168 --size 48
       --spp 256 --seed 0 --light 0,-0.8,-0.6]
"""
import argparse
import json
import math
import struct
import sys

try:
    import mitsuba as mi
except ImportError:  # pragma: no cover
    raise SystemExit("render_export.py: needs Mitsuba 3 (scripts/setup-system.sh installs it)")

# The lamp: angular radius (rad) and distance (mm) from the sphere's centre.
LAMP_RADIUS = 0.15
LAMP_DISTANCE = 5000.0


def the_sphere(scene, path):
    """The one shape of the exported scene, with its boundary and interior medium checked."""
    shapes = scene.shapes()
    if len(shapes) != 1 or shapes[0].class_name() != "Sphere":
        raise SystemExit(f"{path}: expected one sphere, Mitsuba read {len(shapes)} shape(s)")
    ball = shapes[0]
    medium = ball.interior_medium()
    if medium is None or ball.bsdf().class_name() != "RoughDielectric":
        raise SystemExit(f"{path}: the sphere needs a roughdielectric and an interior medium")
    return ball


def what_mitsuba_read(ball):
    """The parameters as Mitsuba holds them (per mm: the scene is in millimetres)."""
    p = mi.traverse(ball)
    key = lambda end: next(k for k in p.keys() if k.endswith(end))
    scale = p[key("scale")]
    sigma_t = [scale * v for v in p[key("sigma_t.value.value")]]
    return {
        "radius_mm": ball.bbox().extents()[0] / 2.0,
        "alpha": p[key("alpha.value")],
        "eta": p[key(".eta")],
        "sigma_t_per_mm": sigma_t,
        "albedo": list(p[key("albedo.value.value")]),
    }


def lamp_scene(ball, distance, fx, size, spp, seed, light):
    """The sphere `ball` (centred at the origin) seen from (0, 0, -distance) along +z, lit by
    the lamp toward `light`."""
    n = math.sqrt(sum(v * v for v in light))
    l = [v / n for v in light]
    lamp = [LAMP_DISTANCE * v for v in l]
    radiance = 1.0 / (math.pi * math.sin(LAMP_RADIUS) ** 2)
    fov = math.degrees(2 * math.atan(size / 2 / fx))
    return mi.load_dict({
        "type": "scene",
        "integrator": {"type": "volpath", "max_depth": -1, "rr_depth": 8},
        "sensor": {
            "type": "perspective", "fov": fov, "fov_axis": "x",
            "to_world": mi.ScalarTransform4f().look_at(
                origin=[0, 0, -distance], target=[0, 0, 0], up=[0, -1, 0]),
            "film": {"type": "hdrfilm", "width": size, "height": size,
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": spp, "seed": seed},
        },
        "ball": ball,
        "lamp": {
            "type": "sphere", "center": lamp, "radius": LAMP_DISTANCE * math.sin(LAMP_RADIUS),
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [radiance] * 3}},
        },
    })


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("scene")
    p.add_argument("--out")
    p.add_argument("--distance", type=float, default=350.0)
    p.add_argument("--fx", type=float, default=168.0)
    p.add_argument("--size", type=int, default=48)
    p.add_argument("--spp", type=int, default=256)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--light", default="0,-0.8,-0.6")
    p.add_argument("--variant", default="scalar_rgb")
    a = p.parse_args()
    mi.set_variant(a.variant)
    try:
        scene = mi.load_file(a.scene)
    except Exception as e:  # Mitsuba's parser: the file and line at fault
        raise SystemExit(f"{a.scene}: Mitsuba cannot load it: {e}")
    ball = the_sphere(scene, a.scene)
    print(json.dumps(what_mitsuba_read(ball)))
    if a.out:
        light = [float(v) for v in a.light.split(",")]
        img = mi.render(lamp_scene(ball, a.distance, a.fx, a.size, a.spp, a.seed, light))
        values = list(img.array)
        with open(a.out, "wb") as f:
            f.write(struct.pack(f"<{len(values)}f", *values))
    sys.stdout.flush()


if __name__ == "__main__":
    main()
