#!/usr/bin/env python3
"""The generator of the golden platform identity (crates/crs-ipc/src/identity_golden.rs).

motion-core (the model library) and the safety monitor (its own reader and hash) each compute
the identity of the golden platform and compare it with MODEL_IDENTITY / PLATFORM_IDENTITY in
that file. This is the third implementation those constants come from: Python's tomllib reads
the file's PLATFORM_TOML, hashlib/struct hash it as the contract states (crs-ipc's module doc):

  model identity    SHA-256 of "crs-model-v1", m (u64), a_1..a_m, b_1..b_m (x, y, z each),
                    k_F,1..m, w_e (6), f_min, f_max, then -1.0 (no pulleys) or r_p,1..m and
                    the swivel axes normalised by sqrt(x*x + y*y + z*z), each component divided;
  platform identity SHA-256 of "crs-platform-v2", the model identity, position min, max (m),
                    rotation min, max (rad = deg * (pi / 180)), linear velocity (m/s), angular
                    velocity (rad/s), linear acceleration (m/s^2), angular acceleration (rad/s^2);

every number as the little-endian bits of an IEEE 754 double.

  python3 tools/identity_golden.py FILE           print the two constants for FILE's TOML
  python3 tools/identity_golden.py --check FILE   exit 1 unless FILE's constants are these
"""
import hashlib
import math
import re
import struct
import sys
import tomllib


def platform_toml(rust_source):
    m = re.search(r'pub const PLATFORM_TOML: &str = r#"(.*?)"#;', rust_source, re.S)
    if not m:
        sys.exit("no `pub const PLATFORM_TOML: &str = r#\"...\"#;` in the file")
    return tomllib.loads(m.group(1))


def f64(h, v):
    h.update(struct.pack("<d", float(v)))


def model_identity(t):
    a = t["geometry"]["frame_anchors_m"]
    b = t["geometry"]["platform_anchors_m"]
    h = hashlib.sha256(b"crs-model-v1")
    h.update(struct.pack("<Q", len(a)))
    for p in a + b:
        for c in p:
            f64(h, c)
    for k in t["elasticity"]["k_f_n"]:
        f64(h, k)
    for w in t["load"]["wrench_n_nm"]:
        f64(h, w)
    f64(h, t["forces"]["f_min_n"])
    f64(h, t["forces"]["f_max_n"])
    pulleys = t.get("pulleys")
    if pulleys is None:
        f64(h, -1.0)
    else:
        for r in pulleys["radius_m"]:
            f64(h, r)
        for x, y, z in pulleys["swivel_axes"]:
            n = math.sqrt(x * x + y * y + z * z)
            for c in (x / n, y / n, z / n):
                f64(h, c)
    return h.digest()


def platform_identity(t, model_id):
    deg = lambda v: v * (math.pi / 180.0)
    w, lim = t["workspace"], t["limits"]
    h = hashlib.sha256(b"crs-platform-v2")
    h.update(model_id)
    for v in w["position_min_m"] + w["position_max_m"]:
        f64(h, v)
    for v in w["rotation_min_deg"] + w["rotation_max_deg"]:
        f64(h, deg(v))
    f64(h, lim["linear_velocity_max_m_per_s"])
    f64(h, deg(lim["angular_velocity_max_deg_per_s"]))
    f64(h, lim["linear_acceleration_max_m_per_s2"])
    f64(h, deg(lim["angular_acceleration_max_deg_per_s2"]))
    return h.digest()


def rust_bytes(d):
    rows = [", ".join(f"0x{b:02x}" for b in d[i:i + 16]) for i in (0, 16)]
    return "\n".join(f"    {r}," for r in rows)


def constant(rust_source, name):
    m = re.search(rf"pub const {name}: [^=]*= [^\[]*\[(.*?)\]", rust_source, re.S)
    if not m:
        sys.exit(f"no constant {name} in the file")
    return bytes(int(x, 16) for x in re.findall(r"0x([0-9a-fA-F]{2})", m.group(1)))


def main():
    args = sys.argv[1:]
    check = args[:1] == ["--check"]
    if check:
        args = args[1:]
    if len(args) != 1:
        sys.exit(__doc__)
    src = open(args[0], encoding="utf-8").read()
    t = platform_toml(src)
    model_id = model_identity(t)
    platform_id = platform_identity(t, model_id)
    if not check:
        print(f"pub const MODEL_IDENTITY: [u8; 32] = [\n{rust_bytes(model_id)}\n];")
        print(f"PLATFORM_IDENTITY bytes:\n{rust_bytes(platform_id)}")
        return
    bad = []
    for name, want in (("MODEL_IDENTITY", model_id), ("PLATFORM_IDENTITY", platform_id)):
        got = constant(src, name)
        print(f"  {name}: file {got.hex()}\n  {' ' * len(name)}  here {want.hex()}")
        if got != want:
            bad.append(name)
    if bad:
        sys.exit(f"IDENTITY-GOLDEN: FAIL ({', '.join(bad)} differ from the generator's)")
    print("IDENTITY-GOLDEN: PASS (both constants are the generator's)")


if __name__ == "__main__":
    main()
