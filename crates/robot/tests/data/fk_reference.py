"""Reference link poses from pinocchio's forward kinematics, for the kinematics tests.

    python fk_reference.py ROBOT.urdf OUT.json [--configs N] [--seed S]

Writes {"robot", "joints": [the moving, non-mimic joints in URDF order], "configs": [[value per
joint]], "links": {link: [[tx, ty, tz, R00, R01, R02, R10, ..., R22] per config]}}. Joint values
are uniform within the limits (continuous joints in [-2π, 2π], to test wrapping). A mimic joint
(not followed by pinocchio's URDF parser, which reads it as an independent joint) is set to
multiplier · source + offset, as the URDF defines it. Made with pin 4.1.0 (PyPI).
"""
import json
import sys
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin


def main():
    urdf, out = sys.argv[1], sys.argv[2]
    n = int(sys.argv[sys.argv.index("--configs") + 1]) if "--configs" in sys.argv else 20
    seed = int(sys.argv[sys.argv.index("--seed") + 1]) if "--seed" in sys.argv else 7
    root = ET.parse(urdf).getroot()
    joints, mimic, limits = [], {}, {}
    for j in root.findall("joint"):
        kind = j.get("type")
        if kind == "fixed":
            continue
        name = j.get("name")
        m = j.find("mimic")
        if m is not None:
            mimic[name] = (m.get("joint"), float(m.get("multiplier", 1)), float(m.get("offset", 0)))
            continue
        joints.append(name)
        lim = j.find("limit")
        if kind == "continuous":
            limits[name] = (-2 * np.pi, 2 * np.pi)
        else:
            limits[name] = (float(lim.get("lower")), float(lim.get("upper")))
    model = pin.buildModelFromUrdf(urdf)
    data = model.createData()
    rng = np.random.default_rng(seed)
    configs, links = [], {}
    for _ in range(n):
        values = {name: float(rng.uniform(*limits[name])) for name in joints}
        for name, (src, mult, off) in mimic.items():
            values[name] = mult * values[src] + off
        q = pin.neutral(model)
        for jid in range(1, model.njoints):
            name = model.names[jid]
            idx, nq = model.idx_qs[jid], model.nqs[jid]
            if nq == 1:
                q[idx] = values[name]
            elif nq == 2:  # continuous: (cos, sin)
                q[idx], q[idx + 1] = np.cos(values[name]), np.sin(values[name])
        pin.framesForwardKinematics(model, data, q)
        configs.append([values[name] for name in joints])
        for fid, frame in enumerate(model.frames):
            if frame.type != pin.FrameType.BODY:
                continue
            m = data.oMf[fid]
            links.setdefault(frame.name, []).append(list(m.translation) + list(m.rotation.reshape(-1)))
    json.dump({"robot": root.get("name"), "joints": joints, "configs": configs, "links": links}, open(out, "w"))


main()
