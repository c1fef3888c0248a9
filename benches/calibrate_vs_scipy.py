#!/usr/bin/env python3
"""Times the 62-parameter elastostatic identification (spec eq. 4.38, 6.14) in Rust
(crates/calibrate, example calibrate_bench) next to scipy.optimize.least_squares on the same data
and start point, in one run, and checks both reach the same optimum.

Usage:  python3 benches/calibrate_vs_scipy.py   (from the workspace root; needs numpy, scipy)

The residual is the same as crates/calibrate/src/residual.rs (standard model, linear law):
  rho_w = w_w (sum_i f_i [u_i; b_i x u_i] + w_e)        (6 rows per sample)
  rho_q = w_q (q_i (1 - f_i / k_F,i) - (q_cmd,i + delta_i))  (m rows per sample)
with u_i = (a_i - r - R b_i) / q_i; scipy gets its default 2-point finite-difference Jacobian
(method 'lm', MINPACK) and the same parameter scaling (x_scale = W_pc of eq. 4.42).
"""
import json, subprocess, sys, time, os
import numpy as np
from scipy.optimize import least_squares

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXPORT = "/tmp/calibrate_bench.json"

subprocess.run(["cargo", "run", "--release", "-q", "-p", "calibrate", "--example", "calibrate_bench", "--",
                "--export", EXPORT, "--repeat", "20"], check=True, cwd=ROOT)
d = json.load(open(EXPORT))
m = d["m"]
S = d["samples"]
n = len(S)
qc = np.array([s["q_cmd"] for s in S])                # n x m
X = np.array([s["pose"] for s in S])                  # n x 6
F = np.array([s["forces"] for s in S])                # n x m
off = np.array(d["offsets"])
ww, wq = d["weights"]["wrench"], d["weights"]["length"]
scales = np.array(d["scales"])
p0 = np.array(d["p0"])

def rot(phi):
    sx, cx = np.sin(phi[:, 0]), np.cos(phi[:, 0])
    sy, cy = np.sin(phi[:, 1]), np.cos(phi[:, 1])
    sz, cz = np.sin(phi[:, 2]), np.cos(phi[:, 2])
    R = np.empty((len(phi), 3, 3))
    R[:, 0, 0] = cy * cz; R[:, 0, 1] = -cy * sz; R[:, 0, 2] = sy
    R[:, 1, 0] = cx * sz + sx * sy * cz; R[:, 1, 1] = cx * cz - sx * sy * sz; R[:, 1, 2] = -sx * cy
    R[:, 2, 0] = sx * sz - cx * sy * cz; R[:, 2, 1] = sx * cz + cx * sy * sz; R[:, 2, 2] = cx * cy
    return R

R = rot(X[:, 3:])
r = X[:, :3]

def residual(p):
    a = p[:3 * m].reshape(m, 3)
    b = p[3 * m:6 * m].reshape(m, 3)
    kf = p[6 * m:7 * m]
    we = p[7 * m:7 * m + 6]
    bw = np.einsum("nij,mj->nmi", R, b)                # n x m x 3
    l = a[None, :, :] - r[:, None, :] - bw
    q = np.linalg.norm(l, axis=2)
    u = l / q[:, :, None]
    w = np.concatenate([np.einsum("nm,nmi->ni", F, u),
                        np.einsum("nm,nmi->ni", F, np.cross(bw, u))], axis=1) + we[None, :]
    phi = q * (1.0 - F / kf[None, :])
    rq = wq * (phi - (qc + off[None, :]))
    return np.concatenate([ww * w, rq], axis=1).ravel()

cost0 = 0.5 * residual(p0) @ residual(p0)
runs = []
for _ in range(3):
    t = time.perf_counter()
    sol = least_squares(residual, p0, method="lm", x_scale=scales, xtol=1e-15, ftol=1e-15, gtol=1e-15,
                        max_nfev=100000)
    runs.append(time.perf_counter() - t)
t_scipy = sorted(runs)[len(runs) // 2]
rust = d["rust"]
p_rust = np.array(rust["p_opt"])
cost_rust_here = 0.5 * residual(p_rust) @ residual(p_rust)
dp = np.abs((sol.x - p_rust) / scales).max()
print(f"samples {n}, parameters {len(p0)}, residuals {len(residual(p0))}, start cost {cost0:.6e}")
print(f"scipy least_squares(lm, 2-point FD): cost {sol.cost:.9e}, nfev {sol.nfev}, median {t_scipy*1e3:.1f} ms")
print(f"rust calibrate (analytic J):          cost {rust['cost']:.9e} (numpy residual at rust optimum {cost_rust_here:.9e}), "
      f"{rust['iterations']} iterations, median {rust['median_s']*1e3:.2f} ms over {rust['runs']} runs")
print(f"max |p_scipy - p_rust| / scale = {dp:.2e}")
print(f"speed-up: {t_scipy / rust['median_s']:.1f}x")
