#!/usr/bin/env python3
"""Exact wrench feasibility (eq. 3.29) of `crs model forces` against scipy's HiGHS.

For random poses in and around each platform's operating region this script asks
`crs model forces --json` for the structure matrix A^T, w_e, the force limits and its verdicts,
then solves the same max-margin LP with scipy.optimize.linprog (HiGHS, code not written here):

    max t  s.t.  A^T f = -w_e,  f_min + t <= f_i <= f_max - t

and checks: the exact verdict and margin agree with HiGHS; the closed form (eq. 3.41) is never
feasible where HiGHS says infeasible, and its margin never exceeds the exact one.

Usage: python3 tools/feasibility_vs_scipy.py [CRS_BINARY] [POSES_PER_PLATFORM]
Exit status 1 on any disagreement.
"""
import json
import random
import subprocess
import sys

import numpy as np
from scipy.optimize import linprog

crs = sys.argv[1] if len(sys.argv) > 1 else "target/debug/crs"
n_poses = int(sys.argv[2]) if len(sys.argv) > 2 else 40
rng = random.Random(17)
failures = 0
exact_only = 0
total = 0

for platform, lo, hi in [
    ("config/icosahedron.toml", (-1.5, -1.5, 1.25), (1.5, 1.5, 2.75)),
    ("config/helicopter.toml", (-1.5, -1.5, 1.25), (1.5, 1.5, 2.75)),
]:
    for _ in range(n_poses):
        # 60 % larger than the region around its centre, so the border is crossed.
        r = [
            (l + h) / 2 + 0.8 * (h - l) * rng.uniform(-1, 1) for l, h in zip(lo, hi)
        ]
        phi = [rng.uniform(-8, 8) for _ in range(3)]
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
        at = np.array(d["structure_matrix"])
        w = np.array(d["w_e"])
        fmin, fmax = d["f_min_n"], d["f_max_n"]
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

print(f"feasibility vs scipy HiGHS: {total} poses compared, {failures} disagreements, "
      f"{exact_only} feasible only by the exact test")
if total < n_poses or exact_only == 0:
    print("too few poses compared, or the border was never crossed")
    sys.exit(1)
sys.exit(1 if failures else 0)
