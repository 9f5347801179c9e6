"""A simulated battery: capacity, open-circuit voltage falling with the charge used, internal resistance.

The current is the motors' electrical power (shaft power / efficiency) plus an avionics load, divided
by the terminal voltage. Safety (battery failsafe) and telemetry (SYS_STATUS, BATTERY_STATUS) read it.
"""

from __future__ import annotations


class Battery:
    """State of one battery pack; ``step`` is called by the world at a low rate."""

    def __init__(self, cells: int = 4, capacity_mah: float = 5000.0, r_internal: float = 0.02,
                 efficiency: float = 0.7, idle_current_a: float = 0.5) -> None:
        self.cells = cells
        self.capacity_mah = capacity_mah
        self.r_internal = r_internal
        self.efficiency = efficiency
        self.idle_current = idle_current_a
        self.consumed_mah = 0.0
        self.current_a = 0.0
        self.voltage = self.open_circuit_voltage()

    def open_circuit_voltage(self) -> float:
        """Per-cell LiPo curve from 4.2 V (full) to 3.3 V (empty), piecewise linear, times cells."""
        soc = max(0.0, 1.0 - self.consumed_mah / self.capacity_mah) if self.capacity_mah > 0 else 0.0
        if soc > 0.9:
            cell = 4.05 + (soc - 0.9) * 1.5
        elif soc > 0.2:
            cell = 3.7 + (soc - 0.2) * 0.5
        else:
            cell = 3.3 + soc * 2.0
        return cell * self.cells

    @property
    def remaining_pct(self) -> int:
        if self.capacity_mah <= 0:
            return 0
        return max(0, min(100, round(100.0 * (1.0 - self.consumed_mah / self.capacity_mah))))

    def step(self, dt: float, shaft_power_w: float) -> None:
        ocv = self.open_circuit_voltage()
        power = shaft_power_w / self.efficiency
        # terminal voltage V = ocv - I R and I = P / V + idle -> one fixed-point refinement suffices
        current = power / max(ocv, 1.0) + self.idle_current
        voltage = ocv - current * self.r_internal
        current = power / max(voltage, 1.0) + self.idle_current
        self.current_a = current
        self.voltage = ocv - current * self.r_internal
        self.consumed_mah += current * dt / 3.6

    def set_capacity(self, capacity_mah: float) -> None:
        self.capacity_mah = capacity_mah
