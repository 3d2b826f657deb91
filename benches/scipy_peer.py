#!/usr/bin/env python3
"""The solve's peer: SciPy's least_squares (method 'trf', analytic Jacobian) on the observations
and the diffuse model workbench fits, written by `cargo bench --bench peer` (benches/peer.rs),
which runs this script in the same run and prints the ratio of the two times.

Model (docs/model.md): L_c = a_c · T(φ; η) · f(θ; σ0_c / r), with f the CDRF's closed form through
the complex error function (the line form; the wrapped form's other images are below 1e-29 at
these blurs), T = 1 − F the exact unpolarised Fresnel transmission, the light from its azimuth a
and elevation e as l = (cos e sin a, −sin e, −cos e cos a). Parameters: ln σ0 (3), ln a (3), η,
a, e. Residuals w_c · (L_c − observed_c). Loss: 'linear' or 'huber' with the f_scale given.

Usage: scipy_peer.py <observations.json> -> prints one JSON line: seconds, parameters, cost,
evaluations.
"""
import json
import sys
import time

import numpy as np
from scipy.optimize import least_squares
from scipy.special import erf

SQRT2 = np.sqrt(2.0)
SQRT2PI = np.sqrt(2.0 * np.pi)


def cdrf(theta, sigma):
    """f, ∂f/∂θ, ∂f/∂σ of the clamped cosine blurred by a Gaussian of width σ (line form)."""
    s2 = sigma * sigma
    a = (theta + np.pi / 2 + 1j * s2) / (sigma * SQRT2)
    b = (theta - np.pi / 2 + 1j * s2) / (sigma * SQRT2)
    z = np.exp(1j * theta - 0.5 * s2) * 0.5 * (erf(a) - erf(b))
    f = z.real
    f_theta = -z.imag

    def g(x):
        return np.exp(-0.5 * (x / sigma) ** 2) / (sigma * SQRT2PI)

    f_tt = -f + g(theta - np.pi / 2) + g(theta + np.pi / 2)
    return f, f_theta, sigma * f_tt


def transmission(c, eta):
    """1 − F(c; η), the exact unpolarised Fresnel transmission, for real or complex η."""
    s2 = 1.0 - c * c
    ct = np.sqrt(1.0 - s2 / (eta * eta))
    rs = (c - eta * ct) / (c + eta * ct)
    rp = (eta * c - ct) / (eta * c + ct)
    return 1.0 - 0.5 * (rs * rs + rp * rp)


def main():
    data = json.load(open(sys.argv[1]))
    obs = np.array(data["observations"])  # n × 13: normal, view, radius, radiance, weight
    n, v, r = obs[:, 0:3], obs[:, 3:6], obs[:, 6]
    y, w = obs[:, 7:10], obs[:, 10:13]
    nv = np.einsum("ij,ij->i", n, v)

    def light(az, el):
        l = np.array([np.cos(el) * np.sin(az), -np.sin(el), -np.cos(el) * np.cos(az)])
        l_az = np.array([np.cos(el) * np.cos(az), 0.0, np.cos(el) * np.sin(az)])
        l_el = np.array([-np.sin(el) * np.sin(az), -np.cos(el), np.sin(el) * np.cos(az)])
        return l, l_az, l_el

    def model(x, jac):
        s0, alb, eta, az, el = np.exp(x[0:3]), np.exp(x[3:6]), x[6], x[7], x[8]
        l, l_az, l_el = light(az, el)
        nl = np.clip(n @ l, -1.0, 1.0)
        theta = np.arccos(nl)
        sin_t = np.maximum(np.sqrt(1.0 - nl * nl), 1e-300)
        t_exit = transmission(nv, eta)
        h = 1e-30
        t_eta = transmission(nv, eta + 1j * h).imag / h
        res = np.empty((len(r), 3))
        cols = np.zeros((len(r), 3, 9))
        for c in range(3):
            f, f_t, f_s = cdrf(theta, s0[c] / r)
            res[:, c] = w[:, c] * (alb[c] * t_exit * f - y[:, c])
            if jac:
                k = w[:, c] * alb[c]
                cols[:, c, c] = k * t_exit * f_s * s0[c] / r
                cols[:, c, 3 + c] = k * t_exit * f
                cols[:, c, 6] = k * t_eta * f
                # ∂θ/∂(az, el) = −(n·∂l)/sin θ.
                cols[:, c, 7] = k * t_exit * f_t * (-(n @ l_az) / sin_t)
                cols[:, c, 8] = k * t_exit * f_t * (-(n @ l_el) / sin_t)
        return res.reshape(-1), cols.reshape(-1, 9)

    x0 = np.array(data["start"])
    evals = [0]

    def fun(x):
        evals[0] += 1
        return model(x, False)[0]

    def jac(x):
        return model(x, True)[1]

    loss = data.get("loss", "linear")
    t = time.perf_counter()
    sol = least_squares(
        fun,
        x0,
        jac=jac,
        method="trf",
        loss=loss,
        f_scale=data.get("f_scale", 1.0),
        x_scale="jac",
        xtol=1e-12,
        ftol=1e-12,
        gtol=1e-12,
    )
    seconds = time.perf_counter() - t
    print(
        json.dumps(
            {
                "seconds": seconds,
                "x": sol.x.tolist(),
                "cost": float(sol.cost),
                "evaluations": evals[0],
                "jacobians": int(sol.njev),
                "status": int(sol.status),
                "scipy": __import__("scipy").__version__,
            }
        )
    )


if __name__ == "__main__":
    main()
