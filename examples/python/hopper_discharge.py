"""Hopper discharge measured from Python: grains in a silo (a cylinder) whose
floor is a plate of fixed spheres with a round orifice, closed by a plug of
fixed spheres while the grains settle. Then the plug is moved away (written
through the positions view) and the grains below the plate, counted every
few steps, give the discharge rate, printed beside Beverloo's law
W = C rho_b sqrt(g) (D - k d)^(5/2) (C = 0.58, k = 1.5, rho_b = 0.6 rho).

    PYTHONPATH=build/python python examples/python/hopper_discharge.py [--quick] [--backend auto]
"""
import argparse
import math

import numpy as np

import marbles


def silo(grains, orifice, duration):
    r_grain, r_plate, radius = 0.004, 0.003, 0.04
    g = np.arange(-radius, radius + 1e-9, 2 * r_plate)
    x, y = np.meshgrid(g, g)
    rho = np.hypot(x, y)
    inside = rho < radius - r_plate
    hole = rho <= orifice / 2 + r_plate
    plate = np.column_stack([x[inside & ~hole], y[inside & ~hole], np.zeros((inside & ~hole).sum())])
    plug = np.column_stack([x[inside & hole], y[inside & hole], np.zeros((inside & hole).sum())])
    height = grains * 4 / 3 * math.pi * r_grain**3 / (0.18 * 0.05**2)  # a loose column, volume fraction 0.18
    return {
        "name": "hopper",
        "time": {"duration": duration, "dt": 2.5e-4},
        "effects": ["gravity", "collisions", "walls", "restitution", "friction"],
        "materials": {"grain": {"density": 2500, "restitution": 0.3, "friction": 0.5}},
        "walls": [{"cylinder": {"base": [0, 0, -1], "axis": [0, 0, 1], "radius": radius, "inside": True}},
                  {"plane": {"point": [0, 0, -0.25], "normal": [0, 0, 1]}}],
        "particles": [
            {"list": {"positions": plate, "radius": r_plate}, "fixed": True},
            {"list": {"positions": plug, "radius": r_plate}, "fixed": True},
            {"random": {"count": grains, "min": [-0.025, -0.025, 0.01], "max": [0.025, 0.025, 0.01 + height],
                        "radius": r_grain, "seed": 2}},
        ],
    }, len(plate), len(plug), r_grain


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer grains, a shorter run")
    parser.add_argument("--backend", default="auto")
    args = parser.parse_args()
    grains, orifice, settle, duration = (300, 0.032, 0.3, 0.6) if args.quick else (800, 0.032, 0.5, 3.5)
    scene, plate, plug, r_grain = silo(grains, orifice, duration)
    sim = marbles.Simulation.from_dict(scene, backend=args.backend)
    fixed = plate + plug
    print(f"{len(sim)} spheres ({plate} in the plate, {plug} in the plug), orifice {1e3 * orifice:.0f} mm, "
          f"{sim.backend}, {sim.precision}")
    sim.run(until=settle)
    # open: the plug drops 20 cm, into the catch space (a device array is written through a host copy)
    x = sim.positions.numpy() if isinstance(sim.positions, marbles.DeviceArray) else np.array(sim.positions)
    x[plate:fixed, 2] = -0.2
    sim.positions = x
    print(f"settled for {settle} s; the plug is out")
    times, out = [], []

    def count(s):
        z = s.positions.numpy()[:, 2] if isinstance(s.positions, marbles.DeviceArray) else s.positions[:, 2]
        times.append(s.time - settle)
        out.append(int((z[fixed:] < -r_grain).sum()))

    sim.run(callback=count, every=20)
    times, out = np.array(times), np.array(out)
    # the steady part: from 20 % to 80 % of the grains out
    steady = (out >= 0.2 * grains) & (out <= 0.8 * grains)
    mass = 2500 * 4 / 3 * math.pi * r_grain**3
    if steady.sum() >= 3:
        rate = np.polyfit(times[steady], out[steady], 1)[0]
        beverloo = 0.58 * (0.6 * 2500) * math.sqrt(9.81) * (orifice - 1.5 * 2 * r_grain) ** 2.5
        print(f"discharge: {rate:.0f} grains/s = {1e3 * rate * mass:.1f} g/s (Beverloo: {1e3 * beverloo:.1f} g/s)")
    else:
        print(f"{out[-1]} of {grains} grains out by t = {sim.time:.2f} s (too few for a steady rate)")
    print(f"largest overlap {100 * sim.summary()['max_overlap']:.2f} % of a radius, "
          f"{sim.summary()['rollbacks']} rollbacks")
    if out[-1] == 0:
        raise SystemExit("no grain came out")


if __name__ == "__main__":
    main()
