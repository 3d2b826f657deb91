#!/usr/bin/env python3
"""One sphere of any homogeneous medium rendered by Mitsuba 3's stock volpath, without numpy.

The scene of datasets/mitsuba/stock_check.py (15 mm sphere 200 mm in front of an 80x80 camera,
fx = fy = 300 px; a spherical lamp 5 m away of angular radius 0.15 rad and irradiance 1 toward
(0, -0.8, -0.6)) with the medium and boundary given on the command line. Writes raw little-endian
float32 RGB, row-major, top row first, for tests/it/pbr.rs `volpath_against_mitsuba_at_low_albedo`.
Usage: PYTHONPATH=target/python datasets/mitsuba/medium_check.py <alpha> <spp> <sigma_t> <r,g,b albedo> <eta> <out.f32>
(thin-dark's medium: 0.1 8192 0.5 0.7,0.75,0.8 1.6 /tmp/mi/dark.f32; about 2 min on 2 cores).
"""
import math, struct, sys
import mitsuba as mi
mi.set_variant("scalar_rgb")
alpha = float(sys.argv[1]); spp = int(sys.argv[2]); sigma_t = float(sys.argv[3])
albedo = [float(v) for v in sys.argv[4].split(",")]; eta = float(sys.argv[5]); out = sys.argv[6]
delta = 0.15
l = [0.0, -0.8, -0.6]; n = math.sqrt(sum(v*v for v in l)); l = [v/n for v in l]
c = [0.0, 0.0, 200.0]; dist = 5000.0
lamp = [c[i] + dist*l[i] for i in range(3)]
radiance = 1.0 / (math.pi * math.sin(delta) ** 2)
fov = math.degrees(2 * math.atan(40 / 300))
scene = mi.load_dict({
    "type": "scene",
    "integrator": {"type": "volpath", "max_depth": -1, "rr_depth": 8},
    "sensor": {"type": "perspective", "fov": fov, "fov_axis": "x",
        "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 0], target=[0, 0, 1], up=[0, -1, 0]),
        "film": {"type": "hdrfilm", "width": 80, "height": 80, "rfilter": {"type": "box"}, "pixel_format": "rgb"},
        "sampler": {"type": "independent", "sample_count": spp}},
    "ball": {"type": "sphere", "center": c, "radius": 15.0,
        "bsdf": {"type": "roughdielectric", "distribution": "ggx", "alpha": alpha, "int_ior": eta, "ext_ior": 1.0},
        "interior": {"type": "homogeneous", "sigma_t": sigma_t, "albedo": {"type": "rgb", "value": albedo}, "phase": {"type": "isotropic"}}},
    "lamp": {"type": "sphere", "center": lamp, "radius": dist * math.sin(delta),
        "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [radiance] * 3}}},
})
img = mi.render(scene)
vals = [float(v) for v in mi.TensorXf(img).array]
with open(out, "wb") as f:
    f.write(struct.pack("<%df" % len(vals), *vals))
print(out, len(vals), sum(vals[0::3])/6400, sum(vals[1::3])/6400, sum(vals[2::3])/6400)
