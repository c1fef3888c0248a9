#!/usr/bin/env python3
"""Reference responses of the motion cueing's transfer functions computed with scipy.signal
(an implementation not written here), for crates/motion-cueing/tests/scipy_reference.rs.

    python3 tools/cueing-scipy-reference.py > crates/motion-cueing/tests/data/scipy_reference.json

Each case: a continuous transfer function (numerator, denominator, descending powers of s),
discretised with a zero-order hold at dt (scipy.signal.tf2ss, cont2discrete with method 'zoh')
and simulated (scipy.signal.dlsim) for an input sequence; the test runs motion_cueing::lti::Lti
on the same input and compares every sample. The parameters are those of config/cueing.toml.
"""
import json
import numpy as np
import scipy
from scipy import signal

DT = 1e-3
N = 20000  # 20 s


def hp3(wn, zeta, wb):
    # (s^2 + 2 zeta wn s + wn^2)(s + wb)
    return list(np.polymul([1.0, 2 * zeta * wn, wn * wn], [1.0, wb]))


def case(name, num, den, u):
    # State space (scipy's own realisation, not the crate's canonical form), then ZOH.
    a, b, c, d = signal.tf2ss(num, den)
    ad, bd, cd, dd, dt = signal.cont2discrete((a, b, c, d), DT, method="zoh")
    _, y, _ = signal.dlsim((ad, bd, cd, dd, dt), u)
    return {"name": name, "num": list(map(float, num)), "den": list(map(float, den)),
            "dt": DT, "input": "u", "y": [float(v) for v in np.squeeze(y)[::50]], "every": 50}


t = np.arange(N) * DT
step = np.where(t >= 1.0, 1.0, 0.0)
ramp = np.clip((t - 1.0) / 0.5, 0.0, 1.0)  # 0 -> 1 over 0.5 s
sine = np.where(t >= 1.0, np.sin(2 * np.pi * 0.33 * (t - 1.0)), 0.0)
inputs = {"step": step, "ramp": ramp, "sine": sine}
cases = []
for uname, u in inputs.items():
    # Translational channel, position output: s / ((s^2 + 2 zeta wn s + wn^2)(s + wb)).
    c = case("translation-position-" + uname, [1.0, 0.0], hp3(2.0, 1.0, 0.5), u)
    c["input"] = uname
    cases.append(c)
    # Rotational channel, angle output: s^2 / den.
    c = case("rotation-angle-" + uname, [1.0, 0.0, 0.0], hp3(1.0, 1.0, 0.3), u)
    c["input"] = uname
    cases.append(c)
    # Tilt low-pass wn^2 / (s^2 + 2 zeta wn s + wn^2).
    c = case("tilt-low-pass-" + uname, [4.0], [1.0, 4.0, 4.0], u)
    c["input"] = uname
    cases.append(c)
    # Otolith (tau_a s + 1) / ((tau_L s + 1)(tau_S s + 1)), 10 / 5 / 0.016 s.
    c = case("otolith-" + uname, [10.0, 1.0], list(np.polymul([5.0, 1.0], [0.016, 1.0])), u)
    c["input"] = uname
    cases.append(c)
    # Canals tau_a tau_L s^2 (tau_lead s + 1) / ((tau_a s + 1)(tau_L s + 1)(tau_S s + 1)).
    k = 80.0 * 5.73
    den = np.polymul(np.polymul([80.0, 1.0], [5.73, 1.0]), [0.005, 1.0])
    c = case("canal-" + uname, [k * 0.06, k, 0.0, 0.0], list(den), u)
    c["input"] = uname
    cases.append(c)
print(json.dumps({"generator": "tools/cueing-scipy-reference.py", "scipy": scipy.__version__,
                  "numpy": np.__version__, "samples": N, "cases": cases}))
