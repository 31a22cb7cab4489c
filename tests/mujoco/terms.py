"""Prints MuJoCo's own terms for a batch of (model, qpos, qvel) checks, as JSON, for kinloop's tests.

Reads a JSON list of {"model": path, "qpos": [...], "qvel": [...], "steps": n} on stdin (qpos/qvel may be empty: the
model's qpos0 and zero velocity) and writes a JSON list with, per check: the joint layout, the site
positions, the dense mass matrix (mj_fullM), qfrc_bias, qfrc_spring, qfrc_damper, qfrc_actuator (ctrl 0),
the equality rows of the constraint Jacobian (efc_J) and, for connect equalities, Jdot*qvel of the same rows
(mj_jacDot at both anchors), the equality residual at the state, and whether n steps of MuJoCo's own
simulation from qpos0 stay finite. Contacts are disabled: kinloop's scene has no contacts between links.
One process serves a whole batch, so the tests start Python once.
"""

import json
import sys

import mujoco
import numpy as np


def terms(check):
    m = mujoco.MjModel.from_xml_path(check["model"])
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    d = mujoco.MjData(m)
    if check.get("qpos"):
        d.qpos[:] = check["qpos"]
    if check.get("qvel"):
        d.qvel[:] = check["qvel"]
    mujoco.mj_forward(m, d)
    closure = float(np.linalg.norm(d.efc_pos[[i for i in range(d.nefc) if d.efc_type[i] == 0]])) if d.nefc else 0.0
    full = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, full, d.qM)
    rows = [i for i in range(d.nefc) if d.efc_type[i] == mujoco.mjtConstraint.mjCNSTR_EQUALITY]
    jac = np.array(d.efc_J).reshape(d.nefc, m.nv)[rows] if d.nefc else np.zeros((0, m.nv))
    jdot_qdot = []
    for k in range(m.neq):
        if not d.eq_active[k]:
            continue
        if m.eq_type[k] != mujoco.mjtEq.mjEQ_CONNECT or m.eq_objtype[k] != mujoco.mjtObj.mjOBJ_BODY:
            jdot_qdot = None
            break
        b1, b2 = m.eq_obj1id[k], m.eq_obj2id[k]
        p1 = d.xpos[b1] + d.xmat[b1].reshape(3, 3) @ m.eq_data[k][0:3]
        p2 = d.xpos[b2] + d.xmat[b2].reshape(3, 3) @ m.eq_data[k][3:6]
        rate = np.zeros(3)
        for body, point, sign in ((b1, p1, 1.0), (b2, p2, -1.0)):
            jp = np.zeros((3, m.nv))
            mujoco.mj_jacDot(m, d, jp, None, point, body)
            rate += sign * (jp @ d.qvel)
        jdot_qdot.extend(rate.tolist())
    return {
        "nq": m.nq,
        "nv": m.nv,
        "joints": [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(m.njnt)],
        "qpos": d.qpos.tolist(),
        "qvel": d.qvel.tolist(),
        "sites": {
            mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SITE, s): d.site_xpos[s].tolist() for s in range(m.nsite)
        },
        "mass_matrix": full.tolist(),
        "bias": d.qfrc_bias.tolist(),
        "spring": d.qfrc_spring.tolist(),
        "damper": d.qfrc_damper.tolist(),
        "actuator": d.qfrc_actuator.tolist(),
        "constraint_jacobian": jac.tolist(),
        "jdot_qdot": jdot_qdot,
        "body_mass": m.body_mass.tolist(),
        "closure": closure,
        "stepped_finite": stepped_finite(m, check.get("steps", 0)),
    }


def stepped_finite(m, steps):
    """Steps a fresh copy from qpos0 `steps` times; True when the state stays finite."""
    d = mujoco.MjData(m)
    for _ in range(steps):
        mujoco.mj_step(m, d)
    return bool(np.isfinite(d.qpos).all() and np.isfinite(d.qvel).all())


def main():
    checks = json.load(sys.stdin)
    json.dump([terms(c) for c in checks], sys.stdout)


if __name__ == "__main__":
    main()
