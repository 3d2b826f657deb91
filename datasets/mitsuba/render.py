#!/usr/bin/env python3
"""Physically based sphere sessions for workbench, rendered with Mitsuba 3's volumetric path tracer.

Each sphere is a homogeneous scattering medium inside a rough dielectric boundary (GGX), lit by a
small, distant spherical lamp (a directional light cannot reach the inside through a dielectric
boundary in Mitsuba's volume path tracer; the source paper's lamp was 1100 mm away) in an
otherwise black room, seen by an ideal pinhole camera (no distortion). One photo per sphere,
the sphere at the same place in every photo (the camera and lamp stay put, spheres are swapped),
like `workbench synth session --layout separate`.

Writes a workbench session folder:
  session.json, intrinsics.json   what workbench reads
  r<radius>.png                   16-bit linear RGB, value = radiance · exposure / full_scale
  scene.json                      the scene (medium, boundary, lamp, camera) and the render's own
                                  noise level per sphere: there is no "true" σ0 for such a render

Noise: every photo is the mean of two renders with different seeds; half their difference gives
the noise of the mean per pixel, reported as a fraction of each sphere's mean radiance.

Needs `pip install mitsuba` (3.x; tested with 3.9.1); neither the build nor the tests need it.
Usage: datasets/mitsuba/render.py OUT_DIR [--spp 3000] [--width 200] [--radii 35 30 25 20 15]
"""
import argparse
import json
import math
import os
import time

import numpy as np

try:
    import mitsuba as mi
except ImportError:  # pragma: no cover
    raise SystemExit("render.py: needs Mitsuba 3 (pip install mitsuba)")

SCHEMA_SCENE = "workbench.mitsuba-scene/1"


def parse():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("out")
    p.add_argument("--radii", type=float, nargs="+", default=[35, 30, 25, 20, 15])
    p.add_argument("--spp", type=int, default=3000, help="samples per pixel of each of the two renders")
    p.add_argument("--width", type=int, default=200)
    p.add_argument("--height", type=int, default=150)
    p.add_argument("--fx", type=float, default=350.0, help="focal length in pixels")
    p.add_argument("--distance", type=float, default=260.0, help="camera to sphere centre, mm")
    p.add_argument("--offset", type=float, nargs=2, default=[12.0, -8.0],
                   help="sphere centre x, y in mm (camera frame)")
    p.add_argument("--light-azimuth", type=float, default=60.0, help="degrees (workbench convention)")
    p.add_argument("--light-elevation", type=float, default=25.0, help="degrees")
    p.add_argument("--lamp-distance", type=float, default=1100.0, help="mm")
    p.add_argument("--lamp-radius", type=float, default=80.0, help="mm")
    p.add_argument("--irradiance", type=float, default=1.0, help="at the sphere centre, radiance units")
    p.add_argument("--sigma-t", type=float, nargs=3, default=[1.0, 1.2, 1.5], help="extinction, 1/mm")
    p.add_argument("--albedo", type=float, nargs=3, default=[0.95, 0.93, 0.90],
                   help="single-scattering albedo of the medium")
    p.add_argument("--ior", type=float, default=1.44)
    p.add_argument("--alpha", type=float, default=0.10, help="GGX roughness of the boundary")
    p.add_argument("--exposure", type=float, default=1.0)
    p.add_argument("--full-scale", type=float, default=1.0, help="radiance that maps to 65535")
    p.add_argument("--variant", default="scalar_rgb")
    return p.parse_args()


def light_direction(az_deg, el_deg):
    a, e = math.radians(az_deg), math.radians(el_deg)
    # workbench's LightAngles: camera frame x right, y down, z forward; l points toward the light.
    return np.array([math.cos(e) * math.sin(a), -math.sin(e), -math.cos(e) * math.cos(a)])


def scene(a, radius, seed):
    T = mi.ScalarTransform4f
    centre = np.array([a.offset[0], a.offset[1], a.distance])
    l = light_direction(a.light_azimuth, a.light_elevation)
    lamp = centre + a.lamp_distance * l
    # Irradiance of a uniformly emitting sphere of radiance L at distance D: E = L · π (R/D)².
    lamp_radiance = a.irradiance / (math.pi * (a.lamp_radius / a.lamp_distance) ** 2)
    fov = math.degrees(2 * math.atan(a.width / 2 / a.fx))
    return {
        "type": "scene",
        "integrator": {"type": "volpath", "max_depth": -1, "rr_depth": 64},
        "sensor": {
            "type": "perspective",
            "fov_axis": "x",
            "fov": fov,
            # Mitsuba's world frame is the camera frame of workbench (x right, y down, z forward).
            "to_world": T().look_at(origin=[0, 0, 0], target=[0, 0, 1], up=[0, -1, 0]),
            "film": {"type": "hdrfilm", "width": a.width, "height": a.height,
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": a.spp, "seed": seed},
        },
        "ball": {
            "type": "sphere",
            "center": centre.tolist(),
            "radius": radius,
            "bsdf": {"type": "roughdielectric", "distribution": "ggx", "alpha": a.alpha,
                     "int_ior": a.ior, "ext_ior": 1.0},
            "interior": {"type": "homogeneous",
                         "albedo": {"type": "rgb", "value": a.albedo},
                         # RGB values must lie in [0, 1]: the largest goes into the scale.
                         "sigma_t": {"type": "rgb", "value": [v / max(a.sigma_t) for v in a.sigma_t]},
                         "scale": max(a.sigma_t)},
        },
        "lamp": {
            "type": "sphere",
            "center": lamp.tolist(),
            "radius": a.lamp_radius,
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": lamp_radiance}},
        },
    }


def write_json(path, value):
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        json.dump(value, f, indent=2)
        f.write("\n")
    os.replace(tmp, path)


def write_png16(path, rgb):
    import cv2  # OpenCV's Python bindings write 16-bit PNG; BGR order

    tmp = path + ".tmp.png"
    cv2.imwrite(tmp, np.ascontiguousarray(rgb[..., ::-1]))
    os.replace(tmp, path)


def main():
    a = parse()
    mi.set_variant(a.variant)
    os.makedirs(a.out, exist_ok=True)
    images, noise = [], []
    t0 = time.time()
    for k, r in enumerate(a.radii):
        renders = [np.array(mi.render(mi.load_dict(scene(a, r, 2 * k + s))))[..., :3] for s in (1, 2)]
        mean = 0.5 * (renders[0] + renders[1])
        half_diff = 0.5 * (renders[0] - renders[1])
        # Pixels of the sphere: its projected disc (pinhole, exact cone).
        c = np.array([a.offset[0], a.offset[1], a.distance])
        ys, xs = np.mgrid[0:a.height, 0:a.width]
        cx, cy = (a.width - 1) / 2, (a.height - 1) / 2
        d = np.stack([(xs - cx) / a.fx, (ys - cy) / a.fx, np.ones_like(xs, float)], -1)
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        cos_to_c = d @ (c / np.linalg.norm(c))
        inside = cos_to_c > math.cos(math.asin(r / np.linalg.norm(c))) + 1e-4
        level = float(np.sqrt((half_diff[inside] ** 2).mean()) / mean[inside].mean())
        noise.append({"radius_mm": r, "rel_noise": level, "mean_radiance": float(mean[inside].mean())})
        scaled = np.clip(mean * a.exposure / a.full_scale, 0, 1)
        name = f"r{r:g}.png"
        write_png16(os.path.join(a.out, name), np.round(scaled * 65535).astype(np.uint16))
        images.append({"file": name, "spheres": [{"radius_mm": r}], "exposure": a.exposure})
        print(f"{name}: {time.time() - t0:.0f} s, noise {100 * level:.2f}% of the mean", flush=True)
    cx, cy = (a.width - 1) / 2, (a.height - 1) / 2
    write_json(os.path.join(a.out, "intrinsics.json"), {
        "schema": "workbench.intrinsics/1", "image_size": [a.width, a.height],
        "fx": a.fx, "fy": a.fx, "cx": cx, "cy": cy,
        "distortion": {"k1": 0.0, "k2": 0.0, "p1": 0.0, "p2": 0.0, "k3": 0.0},
        "rms_px": None, "std": None, "views": [], "source": "Mitsuba pinhole camera (exact)"})
    write_json(os.path.join(a.out, "session.json"), {
        "schema": "workbench.session/1", "material": "Mitsuba homogeneous medium",
        "intrinsics": "intrinsics.json", "images": images})
    l = light_direction(a.light_azimuth, a.light_elevation)
    write_json(os.path.join(a.out, "scene.json"), {
        "schema": SCHEMA_SCENE, "kind": "mitsuba volpath",
        "mitsuba": mi.__version__, "variant": a.variant, "spp": 2 * a.spp,
        "light_direction": l.tolist(), "light_azimuth_deg": a.light_azimuth,
        "light_elevation_deg": a.light_elevation,
        "lamp": {"distance_mm": a.lamp_distance, "radius_mm": a.lamp_radius,
                 "angular_radius_deg": math.degrees(math.asin(a.lamp_radius / a.lamp_distance)),
                 "irradiance": a.irradiance},
        "medium": {"sigma_t_per_mm": a.sigma_t, "albedo": a.albedo},
        "boundary": {"ior": a.ior, "ggx_alpha": a.alpha},
        "sphere_center_mm": [a.offset[0], a.offset[1], a.distance],
        "camera": {"fx": a.fx, "width": a.width, "height": a.height},
        "exposure": a.exposure, "full_scale": a.full_scale,
        "noise": noise, "seconds": time.time() - t0})


if __name__ == "__main__":
    main()
