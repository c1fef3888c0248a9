#!/usr/bin/env python3
"""Exact wrench feasibility (eq. 3.29) of `crs model forces` against scipy's HiGHS, on a
structure matrix built here.

For random poses in and around each platform's operating region this script builds the
structure matrix A^T from the platform TOML alone, in numpy (eq. 2.2, 2.4, 2.30: no number of
the code's own matrix is used):

    R = R_x(phi_x) R_y(phi_y) R_z(phi_z),  l_i = a_i - r - R b_i,  u_i = l_i / |l_i|,
    column i of A^T = [u_i ; (R b_i) x u_i]

with w_e, f_min, f_max from the same file, and solves the max-margin LP with
scipy.optimize.linprog (HiGHS, code not written here):

    max t  s.t.  A^T f = -w_e,  f_min + t <= f_i <= f_max - t

It checks: `crs model forces --json`'s structure matrix equals this one (to 1e-9); its exact
verdict and margin agree with HiGHS on this matrix; the closed form (eq. 3.41) is never
feasible where HiGHS says infeasible, and its margin never exceeds the exact one.

Usage: python3 tools/feasibility_vs_scipy.py [CRS_BINARY] [POSES_PER_PLATFORM]
Exit status 1 on any disagreement.
"""
import json
import random
import subprocess
import sys
import tomllib

import numpy as np
from scipy.optimize import linprog

crs = sys.argv[1] if len(sys.argv) > 1 else "target/debug/crs"
n_poses = int(sys.argv[2]) if len(sys.argv) > 2 else 40
rng = random.Random(17)
failures = 0
exact_only = 0
total = 0


def rotation(phi_deg):
    """R = R_x R_y R_z (eq. 2.2), angles in degrees."""
    x, y, z = np.radians(phi_deg)
    rx = np.array([[1, 0, 0], [0, np.cos(x), -np.sin(x)], [0, np.sin(x), np.cos(x)]])
    ry = np.array([[np.cos(y), 0, np.sin(y)], [0, 1, 0], [-np.sin(y), 0, np.cos(y)]])
    rz = np.array([[np.cos(z), -np.sin(z), 0], [np.sin(z), np.cos(z), 0], [0, 0, 1]])
    return rx @ ry @ rz


def structure_matrix(pf, r, phi_deg):
    """A^T (6 x m) of the standard model (eq. 2.4, 2.30) from the platform TOML."""
    a = np.array(pf["geometry"]["frame_anchors_m"], dtype=float)
    b = np.array(pf["geometry"]["platform_anchors_m"], dtype=float)
    rot = rotation(phi_deg)
    cols = []
    for ai, bi in zip(a, b):
        rb = rot @ bi
        l = ai - np.asarray(r) - rb
        u = l / np.linalg.norm(l)
        cols.append(np.concatenate([u, np.cross(rb, u)]))
    return np.array(cols).T


max_matrix_diff = 0.0
for platform, lo, hi in [
    ("config/icosahedron.toml", (-1.5, -1.5, 1.25), (1.5, 1.5, 2.75)),
    ("config/helicopter.toml", (-1.5, -1.5, 1.25), (1.5, 1.5, 2.75)),
]:
    with open(platform, "rb") as fh:
        pf = tomllib.load(fh)
    if "pulleys" in pf:
        sys.exit(f"{platform}: has [pulleys]; this script builds the standard model's matrix only")
    w = np.array(pf["load"]["wrench_n_nm"], dtype=float)
    fmin, fmax = float(pf["forces"]["f_min_n"]), float(pf["forces"]["f_max_n"])
    for _ in range(n_poses):
        # 60 % larger than the region around its centre, so the border is crossed.
        r = [
            (l + h) / 2 + 0.8 * (h - l) * rng.uniform(-1, 1) for l, h in zip(lo, hi)
        ]
        phi = [rng.uniform(-8, 8) for _ in range(3)]
        # The pose as crs is told it (6 decimals), so both matrices are of the same pose.
        r = [float(f"{v:.6f}") for v in r]
        phi = [float(f"{v:.6f}") for v in phi]
        out = subprocess.run(
            [
                crs, "model", "forces", "--json", "--platform", platform,
                "--position-m", ",".join(f"{v:.6f}" for v in r),
                "--rotation-deg", ",".join(f"{v:.6f}" for v in phi),
            ],
            capture_output=True, text=True,
        )
        if out.returncode != 0:
            # A pose the model cannot evaluate (e.g. singular) is reported, not compared.
            print(f"  {platform} {r}: crs refused: {out.stderr.strip()}")
            continue
        d = json.loads(out.stdout)
        at = structure_matrix(pf, r, phi)
        # The code's matrix, limits and load must be this file's (compared, not used).
        diff = float(np.abs(np.array(d["structure_matrix"]) - at).max())
        max_matrix_diff = max(max_matrix_diff, diff)
        if diff > 1e-9 or list(d["w_e"]) != list(w) or (d["f_min_n"], d["f_max_n"]) != (fmin, fmax):
            print(f"  FAIL {platform} r={r} phi={phi}: crs's structure matrix differs by {diff:.3e} "
                  f"(or w_e / force limits differ from the file)")
            failures += 1
            continue
        n, m = at.shape
        s = fmax - fmin
        # Variables (f_1..f_m, t) scaled by s; maximize t = minimize -t.
        c = np.zeros(m + 1)
        c[-1] = -1.0
        a_eq = np.hstack([at, np.zeros((n, 1))])
        b_eq = -w / s
        a_ub = np.vstack([
            np.hstack([-np.eye(m), np.ones((m, 1))]),   # -f + t <= -f_min
            np.hstack([np.eye(m), np.ones((m, 1))]),    #  f + t <=  f_max
        ])
        b_ub = np.concatenate([-np.full(m, fmin / s), np.full(m, fmax / s)])
        res = linprog(c, A_ub=a_ub, b_ub=b_ub, A_eq=a_eq, b_eq=b_eq,
                      bounds=[(None, None)] * m + [(-1e3, 0.5)], method="highs")
        if res.status != 0:
            print(f"  FAIL {platform} {r}: HiGHS status {res.status}: {res.message}")
            failures += 1
            continue
        t_ref = res.x[-1] * s
        ex = d["exact"]
        total += 1
        ok = abs(ex["margin_n"] - t_ref) <= 1e-4 * s and ex["feasible"] == (t_ref >= -1e-6 * s)
        ok &= not (d["feasible"] and t_ref < -1e-6 * s)
        ok &= d["margin_n"] <= t_ref + 1e-6 * s
        if ex["feasible"] and not d["feasible"]:
            exact_only += 1
        if not ok:
            failures += 1
            print(f"  FAIL {platform} r={r} phi={phi}: crs exact {ex['margin_n']:.3f} N "
                  f"({ex['feasible']}), closed form {d['margin_n']:.3f} N ({d['feasible']}), "
                  f"HiGHS {t_ref:.3f} N")

print(f"feasibility vs scipy HiGHS on a numpy structure matrix from the platform files: "
      f"{total} poses compared, {failures} disagreements, {exact_only} feasible only by the "
      f"exact test; crs's matrix within {max_matrix_diff:.1e} of numpy's")
if total < n_poses or exact_only == 0:
    print("too few poses compared, or the border was never crossed")
    sys.exit(1)
sys.exit(1 if failures else 0)
