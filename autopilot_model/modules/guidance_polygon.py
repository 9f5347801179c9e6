"""Polygon walls of the setpoint generator's envelope (:mod:`.guidance`, step 3 for a polygon P_env).

:class:`PolygonWalls` is a mixin of :class:`~.guidance.SetpointGenerator`: it pre-computes the polygon's
edges once per envelope (:meth:`PolygonWalls._setup_polygon`) and, each step, bounds the horizontal velocity
candidate by the walls within reach (:meth:`PolygonWalls._poly_limit`) and pulls a point that left the
polygon by floating-point residue back onto it (:meth:`PolygonWalls._poly_clamp`). It reads the host's
``dt``, ``_vh``, ``_ah``, ``_ahdt``, ``_reach_h`` and ``_note_clamp`` and sets ``_ae`` (the braking
acceleration toward a wall), ``_edges``, ``_pref``, ``_dref``, ``_dtrue``, ``_near`` and ``_in_poly``.
Pure :mod:`math` on floats in the step; shapely only hands over the oriented polygon.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

from shapely.geometry import Polygon

from .guidance_math import clip_halfplane, nearest_in_convex, project_one, toward, wall_bound

log = logging.getLogger("autopilot_model.modules.guidance")

_INF = math.inf


class PolygonWalls:
    """The polygon part of the envelope step (a mixin of :class:`~.guidance.SetpointGenerator`)."""

    dt: float
    _vh: float
    _ah: float
    _ahdt: float
    _ae: float
    _reach_h: float
    _note_clamp: Callable[[float], None]

    def _setup_polygon(self, poly: Polygon) -> None:
        """Pre-compute the polygon edges for the pure-math per-step queries."""
        if len(poly.interiors):
            raise ValueError("polygon envelopes with holes are not supported")
        coords = list(poly.exterior.coords)[:-1]  # counter-clockwise in (north, east)
        pts = [c for i, c in enumerate(coords) if c != coords[i - 1]]
        m = len(pts)
        convex = []
        kappa = 1.0
        for i in range(m):
            an, ae = pts[i - 1]
            bn, be = pts[i]
            cn, ce = pts[(i + 1) % m]
            en, ee, fn, fe = bn - an, be - ae, cn - bn, ce - be
            cross = en * fe - ee * fn
            # left turn = convex corner. Two walls approached at once need a combined deceleration of
            # a / cos(phi / 2), phi the angle between their normals (the turn angle): brake with less.
            convex.append(cross > 0.0)
            if cross > 0.0:
                turn = math.atan2(cross, en * fn + ee * fe)
                kappa = min(kappa, math.cos(0.5 * turn))
        edges = []
        for i in range(m):
            an, ae = pts[i]
            bn, be = pts[(i + 1) % m]
            en, ee = bn - an, be - ae
            l2 = en * en + ee * ee
            ln = math.sqrt(l2)
            # the region is on the left of each edge: the outward normal is on the right, (ee, -en)
            edges.append((an, ae, en, ee, 1.0 / l2, ee / ln, -en / ln, convex[i], convex[(i + 1) % m]))
        if kappa < 0.3:
            log.warning("polygon envelope has very sharp corners: wall braking uses %.2f of max_accel_h",
                        kappa)
        self._edges = tuple(edges)
        self._ae = self._ah * kappa
        self._pref = (math.inf, math.inf)  # where the constraint distance _dref was measured
        self._dref = -math.inf
        self._dtrue = -math.inf  # distance to the boundary at _pref
        self._near = False  # the walls were evaluated in this step
        self._in_poly = False  # P_d known to be inside the polygon (else: test it)

    def _poly_limit(self, pn: float, pe: float, vn: float, ve: float, cn: float, ce: float,
                    ) -> tuple[float, float, bool]:
        """Bound the horizontal velocity candidate by the polygon walls within reach.

        Each edge gives one constraint ``n . v <= wall_bound(d)``: inside the edge's slab and beyond a convex
        vertex the edge's line (normal, line distance: exact for the convex parts), beyond a reflex vertex
        the vertex itself (radial direction and distance). The constraint distances are 1-Lipschitz in p,
        so far from every wall one distance measurement covers many steps.
        """
        reach = self._reach_h
        v2 = vn * vn + ve * ve
        if v2 > self._vh * self._vh:  # faster than the envelope (after a reset): look further
            vv = math.sqrt(v2) + 1.0
            reach = vv * vv / (2.0 * self._ae) + vv * self.dt + 1.0
        rn, re_ = self._pref
        if math.hypot(pn - rn, pe - re_) + reach < self._dref:
            self._near = False
            return cn, ce, False
        dt = self.dt
        ae = self._ae
        cons = []
        dcon = _INF
        dtrue = _INF
        known = self._in_poly  # P_d stays inside once it is: no crossing-number test needed
        inside = known
        near_n = near_e = 0.0
        for an, aa, en, ee, il2, onn, one, conv_a, conv_b in self._edges:
            wn, we = pn - an, pe - aa
            if not known and (aa > pe) != (aa + ee > pe) and pn < an + (pe - aa) * en / ee:
                inside = not inside  # crossing number (point in polygon)
            t = (wn * en + we * ee) * il2
            sd = wn * onn + we * one  # signed distance to the line, > 0 outside
            if t < 0.0:
                qn, qe, conv = -wn, -we, conv_a  # p -> vertex a
                dist = math.sqrt(qn * qn + qe * qe)
            elif t > 1.0:
                qn, qe, conv = an + en - pn, aa + ee - pe, conv_b  # p -> vertex b
                dist = math.sqrt(qn * qn + qe * qe)
            else:
                qn, qe, conv = -sd * onn, -sd * one, True  # p -> its projection on the edge
                dist = -sd if sd < 0.0 else sd
            if conv and sd <= 0.0:  # the edge's line (exact for the convex parts)
                d, nn, ne = -sd, onn, one
            elif dist > 1e-12:  # toward the nearest point of the edge (a reflex vertex, a far edge)
                d, nn, ne = dist, qn / dist, qe / dist
            else:
                d, nn, ne = 0.0, onn, one
            if dist < dtrue:
                dtrue = dist
                near_n, near_e = onn, one
            if d < dcon:
                dcon = d
            if d < reach:
                cons.append((nn, ne, d))
        self._pref = (pn, pe)
        self._near = True
        self._dtrue = dtrue
        inside = inside or dtrue <= 1e-9  # the boundary belongs to P_env
        self._in_poly = inside
        self._dref = dcon if inside else -_INF
        if not inside:  # outside (after a reset or a new envelope): not further out through the nearest edge
            cons = [(near_n, near_e, 0.0)]
        elif not cons:
            return cn, ce, False
        ok = True
        for i, (nn, ne, d) in enumerate(cons):
            b = wall_bound(d, vn * nn + ve * ne, ae, dt)
            cons[i] = (nn, ne, b)
            if nn * cn + ne * ce > b:
                ok = False
        if ok:
            return cn, ce, False
        ahdt = self._ahdt
        # one wall (sliding along it): project onto its constraint line
        q = project_one(cons, cn, ce)
        s0 = project_one(cons, vn, ve)
        if q is not None and s0 is not None:
            cn, ce = toward(vn, ve, s0[0], s0[1], q[0], q[1], ahdt)
            return cn, ce, True
        # feasible velocity polygon = big square clipped by the half-planes n.v <= b
        big = max(self._vh, math.hypot(vn, ve), math.hypot(cn, ce)) + 1.0
        vp = [(-big, -big), (big, -big), (big, big), (-big, big)]
        for nn, ne, b in cons:
            vp = clip_halfplane(vp, nn, ne, b)
            if not vp:
                break
        if not vp:  # infeasible (cannot happen from an admissible state): brake straight
            sp = math.sqrt(v2)
            if sp <= ahdt:
                return 0.0, 0.0, True
            k = 1.0 - ahdt / sp
            return vn * k, ve * k, True
        qn, qe = nearest_in_convex(vp, cn, ce)
        s0n, s0e = nearest_in_convex(vp, vn, ve)
        cn, ce = toward(vn, ve, s0n, s0e, qn, qe, ahdt)
        return cn, ce, True

    def _inside(self, pn: float, pe: float) -> bool:
        """Point in polygon (crossing number, boundary within 1e-9 m included), pure math."""
        inside = False
        dmin2 = _INF
        for an, ae, en, ee, il2, *_ in self._edges:
            be = ae + ee
            if (ae > pe) != (be > pe) and pn < an + (pe - ae) * en / ee:
                inside = not inside
            wn, we = pn - an, pe - ae
            t = (wn * en + we * ee) * il2
            t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
            wn -= t * en
            we -= t * ee
            d2 = wn * wn + we * we
            if d2 < dmin2:
                dmin2 = d2
        return inside or dmin2 <= 1e-18

    def _poly_clamp(self, pn: float, pe: float, npn: float, npe: float) -> tuple[float, float, bool]:
        """Pull a new point that left the polygon (float residue) back onto its boundary."""
        if not self._in_poly or self._inside(npn, npe):
            return npn, npe, False
        best = _INF
        bn = be = 0.0
        for an, ae, en, ee, il2, onn, one, *_ in self._edges:
            t = ((npn - an) * en + (npe - ae) * ee) * il2
            t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
            qn, qe = an + t * en, ae + t * ee
            dd = math.hypot(qn - npn, qe - npe)
            if dd < best:
                best, bn, be = dd, qn - onn * 1e-12, qe - one * 1e-12
        self._note_clamp(best)
        return bn, be, True
