"""Pure-math helpers of the setpoint generator (:mod:`.guidance`): braking bounds of the constant-acceleration
model and the small 2-D geometry of the horizontal velocity constraints. Plain :mod:`math` on floats (they run
in the 500 Hz step)."""

from __future__ import annotations

import math

_INF = math.inf


def stop_bound(d: float, s: float, acc: float, dt: float, v_end2: float = 0.0) -> float:
    """Largest speed ``s_new`` toward a point at distance ``d`` for the coming step (current speed ``s``)
    such that, after the trapezoidal move of this step, decelerating at ``acc`` still reaches the point with
    at most the speed ``sqrt(v_end2)``: the discrete form of ``sqrt(v_end^2 + 2 a d)``.

    Solves ``s_new^2 - v_end^2 <= 2 acc (d - (s + s_new) dt / 2)``. When even stopping this step passes the
    point, returns the speed that lands exactly on it (negative: turn back).
    """
    c0 = d - 0.5 * s * dt
    k = v_end2 + 2.0 * acc * c0
    if k >= 0.0:
        adt = acc * dt
        return 0.5 * (math.sqrt(adt * adt + 4.0 * k) - adt)
    return 2.0 * d / dt - s


def wall_bound(d: float, s: float, acc: float, dt: float) -> float:
    """Largest velocity component toward a boundary at distance ``d`` (current component ``s``) that still
    lets P_d stop before it decelerating at ``acc``; never asks for more than a full braking step."""
    sb = s - acc * dt
    if d <= 0.0:  # on or beyond the boundary: never further out, brake as hard as allowed
        return sb if sb > 0.0 else 0.0
    b = stop_bound(d, s, acc, dt)
    return b if b > sb else sb



def toward(vn: float, ve: float, sn: float, se: float, qn: float, qe: float, r: float,
            ) -> tuple[float, float]:
    """From the admissible point ``s`` toward the admissible point ``q``, as far as stays within ``r`` of
    the current velocity ``v`` (the acceleration bound). If ``s`` itself is out of reach (an infeasible
    state), the point at ``r`` from ``v`` toward ``s``."""
    wn, we = sn - vn, se - ve
    w2 = wn * wn + we * we
    r2 = r * r
    if w2 > r2:
        k = r / math.sqrt(w2)
        return vn + k * wn, ve + k * we
    if (qn - vn) ** 2 + (qe - ve) ** 2 <= r2:
        return qn, qe
    en, ee = qn - sn, qe - se
    e2 = en * en + ee * ee  # > 0 here: q is out of reach, s is not
    b = wn * en + we * ee
    disc = b * b - e2 * (w2 - r2)
    t = (-b + math.sqrt(disc if disc > 0.0 else 0.0)) / e2  # |w + t e| = r
    if t < 0.0:
        t = 0.0
    elif t > 1.0:
        t = 1.0
    return sn + t * en, se + t * ee


def project_one(cons: list[tuple[float, float, float]], x: float, y: float) -> tuple[float, float] | None:
    """``(x, y)`` if it satisfies all constraints ``n . v <= b``; its projection onto the line of the only
    violated one if that satisfies the others; else None."""
    viol = None
    for c in cons:
        if c[0] * x + c[1] * y > c[2]:
            if viol is not None:
                return None
            viol = c
    if viol is None:
        return x, y
    nn, ne, b = viol
    k = nn * x + ne * y - b
    x -= k * nn
    y -= k * ne
    for c in cons:
        if c is not viol and c[0] * x + c[1] * y > c[2] + 1e-12:
            return None
    return x, y


def clip_halfplane(poly: list[tuple[float, float]], nn: float, ne: float, b: float,
                    ) -> list[tuple[float, float]]:
    """Sutherland-Hodgman: the part of a convex polygon with ``nn*x + ne*y <= b``."""
    out: list[tuple[float, float]] = []
    m = len(poly)
    for i in range(m):
        xa, ya = poly[i]
        xb, yb = poly[(i + 1) % m]
        fa = nn * xa + ne * ya - b
        fb = nn * xb + ne * yb - b
        if fa <= 0.0:
            out.append((xa, ya))
        if (fa < 0.0 < fb) or (fb < 0.0 < fa):
            t = fa / (fa - fb)
            out.append((xa + t * (xb - xa), ya + t * (yb - ya)))
    return out


def nearest_in_convex(poly: list[tuple[float, float]], x: float, y: float) -> tuple[float, float]:
    """The point of a convex polygon (any orientation) nearest to ``(x, y)``."""
    m = len(poly)
    if m == 1:
        return poly[0]
    sign = 0.0
    inside = True
    best = _INF
    bx = by = 0.0
    for i in range(m):
        xa, ya = poly[i]
        xb, yb = poly[(i + 1) % m]
        ex, ey = xb - xa, yb - ya
        cr = ex * (y - ya) - ey * (x - xa)
        if cr != 0.0:
            if sign == 0.0:
                sign = cr
            elif (cr > 0.0) != (sign > 0.0):
                inside = False
        l2 = ex * ex + ey * ey
        t = 0.0 if l2 == 0.0 else ((x - xa) * ex + (y - ya) * ey) / l2
        t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
        qx, qy = xa + t * ex, ya + t * ey
        d2 = (qx - x) ** 2 + (qy - y) ** 2
        if d2 < best:
            best, bx, by = d2, qx, qy
    if inside and m >= 3:
        return x, y
    return bx, by
