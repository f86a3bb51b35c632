"""Record reference motions of physics v1 (pymunk pivot + limit joints, commit 01360ef; running it on a later
commit records that commit's model instead) for the
v1-vs-v2 agreement tests in tests/azimut_env/test_physics_v2.py."""
import dataclasses

import numpy as np

from azimut_env.params import RobotParams
from azimut_env.physics.engine import AzimutPhysics
from estimation import eta_from_twist, steering_from_lambda, wheel_speeds


def sp(geom, tw):
    lam, mu = eta_from_twist(np.asarray(tw, float))
    beta = steering_from_lambda(lam, geom)
    return beta, wheel_speeds(lam, mu, geom, beta=beta)

out = {}
p = RobotParams()
g = p.geometry
# 1, 2: straight and rotation in place, 3 s, twist history
for name, tw in (("straight", (0.6, 0, 0)), ("rotate", (0, 0, 1.2)), ("combined", (0.3, 0.2, 0.5))):
    ph = AzimutPhysics(p)
    b, w = sp(g, tw)
    ph.reset_robot(0, (0, 0, 0), b)
    ph.set_commands(b[None], w[None])
    poses, twists, betas = [], [], []
    for _ in range(150):
        ph.step()
        poses.append(ph.chassis_pose()[0])
        twists.append(ph.chassis_twist()[0])
        betas.append(ph.steering_angles()[0])
    out[name + "_pose"] = np.array(poses)
    out[name + "_twist"] = np.array(twists)
    out[name + "_beta"] = np.array(betas)
# 3: tight circle, stiff spring (x100): steady beta vs motor angles
stiff = dataclasses.replace(p, steering=dataclasses.replace(p.steering, stiffness=6000.0, damping=6.0))
ph = AzimutPhysics(stiff, substeps=40)
b, w = sp(g, (0.0, 1.2, 1.5))
ph.reset_robot(0, (0, 0, 0), b)
ph.set_commands(b[None], w[None])
for _ in range(100):
    ph.step()
out["stiff_circle_beta"] = ph.steering_angles()[0]
out["stiff_circle_motor"] = ph.motor_angles()[0]
out["stiff_circle_twist"] = ph.chassis_twist()[0]
# 4: slow motion, sinusoidal steering commands at 0.1 m/s
ph = AzimutPhysics(p)
b0, w0 = sp(g, (0.1, 0, 0))
ph.reset_robot(0, (0, 0, 0), b0)
betas, motors, cmds = [], [], []
for j in range(200):
    t = j * 0.02
    bc = b0 + 0.4 * np.sin(2 * np.pi * 0.5 * t + np.arange(4))
    ph.set_commands(bc[None], w0[None])
    ph.step()
    betas.append(ph.steering_angles()[0])
    motors.append(ph.motor_angles()[0])
    cmds.append(bc)
out["slow_beta"] = np.array(betas)
out["slow_motor"] = np.array(motors)
out["slow_cmd"] = np.array(cmds)
np.savez_compressed("tests/data/physics_v1_reference.npz", **out)
print({k: v.shape for k, v in out.items()})
print(out["straight_twist"][-1], out["rotate_twist"][-1], out["combined_pose"][-1])
print(np.degrees(out["stiff_circle_motor"] - out["stiff_circle_beta"]))
print(np.degrees(np.abs(out["slow_beta"] - out["slow_motor"]).max()))
