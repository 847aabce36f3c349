#!/usr/bin/env python3
"""Writes the data of the example models (standard library only, independent of sysid).

kinetics/data.csv      A -> B -> C, k1 = 0.8, k2 = 0.3, A(0) = 1: B(t) in closed form,
                       every 0.5 on [0, 15], plus Gaussian noise sigma = 0.01 (seed 1).
short-period/data.csv  alpha' = Za alpha + q + Zd de, q' = Ma alpha + Mq q + Md de with
                       Za = -1.2, Ma = -4.5, Mq = -1.8, Zd = -0.15, Md = -8 and an elevator
                       doublet (+0.05 rad on [1, 2) s, -0.05 on [2, 3) s); classical RK4 with
                       h = 0.001 (error ~1e-14); every 0.05 s on [0, 10]; noise sigma = 0.002
                       on alpha and 0.005 on q (seed 2); the de column holds the input.
falling-body/data.csv  Goodman (1966), Table I.

Run from the repository root: python3 examples/generate.py
"""
import math
import os
import random

HERE = os.path.dirname(os.path.abspath(__file__))


def write(path, header, rows):
    with open(os.path.join(HERE, path), "w") as f:
        f.write(",".join(header) + "\n")
        for row in rows:
            f.write(",".join(repr(v) if isinstance(v, float) else str(v) for v in row) + "\n")


def kinetics():
    k1, k2 = 0.8, 0.3
    rng = random.Random(1)
    rows = []
    for i in range(31):
        t = 0.5 * i
        b = k1 / (k2 - k1) * (math.exp(-k1 * t) - math.exp(-k2 * t))
        rows.append((t, round(b + rng.gauss(0.0, 0.01), 6)))
    write("kinetics/data.csv", ["t", "B"], rows)


def doublet(t):
    if 1.0 <= t < 2.0:
        return 0.05
    if 2.0 <= t < 3.0:
        return -0.05
    return 0.0


def short_period():
    za, ma, mq, zd, md = -1.2, -4.5, -1.8, -0.15, -8.0

    def f(a, q, de):
        return za * a + q + zd * de, ma * a + mq * q + md * de

    rng = random.Random(2)
    h = 0.001
    a = q = 0.0
    rows = []
    for m in range(201):
        t = 0.05 * m
        rows.append((round(t, 10), round(a + rng.gauss(0.0, 0.002), 7), round(q + rng.gauss(0.0, 0.005), 7), doublet(t)))
        # Integrate to the next sample; the doublet's jumps fall on multiples of h.
        for s in range(50):
            tt = t + s * h
            de = doublet(tt + 0.5 * h)  # constant on each step: no step crosses a jump
            k1 = f(a, q, de)
            k2 = f(a + 0.5 * h * k1[0], q + 0.5 * h * k1[1], de)
            k3 = f(a + 0.5 * h * k2[0], q + 0.5 * h * k2[1], de)
            k4 = f(a + h * k3[0], q + h * k3[1], de)
            a += h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            q += h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
    write("short-period/data.csv", ["t", "alpha", "q", "de"], rows)


def falling_body():
    write("falling-body/data.csv", ["t", "y"], [(0, 0), (1, 15), (2, 65), (3, 145)])


if __name__ == "__main__":
    kinetics()
    short_period()
    falling_body()
