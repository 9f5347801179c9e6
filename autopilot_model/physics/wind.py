"""Wind with a mean and gusts: first-order Gauss-Markov gust per axis (a Dryden-like low-pass).

The gust state g follows dg = -g/T dt + sigma*sqrt(2 dt/T) dW, so its standard deviation is sigma and
its correlation time T. ``gust_max`` clips each gust component (seed-000-like indoor flights use gusts
up to 1 m/s). Random numbers are drawn in blocks with numpy so the per-step cost is an index.
"""

from __future__ import annotations

import math

import numpy as np


class Wind:
    """NED wind = mean + gusts; writes into the physics' ``wind`` array each step."""

    BLOCK = 4096

    def __init__(self, mean_ned: tuple[float, float, float] = (0.0, 0.0, 0.0), gust_sigma: float = 0.0,
                 gust_max: float = 0.0, tau_s: float = 2.0, vertical_ratio: float = 0.3,
                 seed: int | None = 0) -> None:
        self.mean = tuple(float(v) for v in mean_ned)
        self.sigma = float(gust_sigma)
        self.gust_max = float(gust_max) if gust_max > 0 else math.inf
        self.tau = float(tau_s)
        self.vratio = float(vertical_ratio)
        self.rng = np.random.default_rng(seed)
        self.gust = [0.0, 0.0, 0.0]
        self._buf = self.rng.standard_normal((self.BLOCK, 3))
        self._i = 0

    def step(self, dt: float, out: np.ndarray) -> None:
        if self.sigma > 0.0:
            if self._i >= self.BLOCK:
                self._buf = self.rng.standard_normal((self.BLOCK, 3))
                self._i = 0
            n = self._buf[self._i]
            self._i += 1
            a = dt / self.tau
            s = self.sigma * math.sqrt(2.0 * a)
            g = self.gust
            lim = self.gust_max
            for k in range(3):
                sk = s * (self.vratio if k == 2 else 1.0)
                gk = g[k] - g[k] * a + sk * n[k]
                g[k] = lim if gk > lim else (-lim if gk < -lim else gk)
        out[0] = self.mean[0] + self.gust[0]
        out[1] = self.mean[1] + self.gust[1]
        out[2] = self.mean[2] + self.gust[2]
