"""MAVSDK (v4 native binding) against the model over loopback UDP, as it would fly an ArduCopter.

Connect, health (global position and home OK), arm, take-off, goto_location, offboard (position and
velocity), land. One SITL process (lockstep at 10x) for the module; every wait has a deadline.
"""

from __future__ import annotations

import asyncio
import functools
import math
from collections.abc import Awaitable, Callable
from typing import Any

import pytest

mavsdk_asyncio = pytest.importorskip("mavsdk.asyncio")
from mavsdk.asyncio import Configuration, Mavsdk  # noqa: E402
from mavsdk.asyncio.plugins.action import ActionAsync  # noqa: E402
from mavsdk.asyncio.plugins.offboard import OffboardAsync  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync  # noqa: E402
from mavsdk.component_type import ComponentType  # noqa: E402
from mavsdk.plugins.offboard import PositionNedYaw, VelocityNedYaw  # noqa: E402

from harness.timing import wall as sitl_wall  # noqa: E402

pytestmark = pytest.mark.integration

wall = functools.partial(sitl_wall, base_s=10.0)  # more slack: MAVSDK discovers and retries on its own


async def until(pred: Callable[[], Awaitable[Any]], timeout_s: float, what: str) -> Any:
    async def loop() -> Any:
        while True:
            r = await pred()
            if r:
                return r
            await asyncio.sleep(0.02)
    try:
        return await asyncio.wait_for(loop(), timeout_s)
    except TimeoutError:
        raise AssertionError(f"timed out after {timeout_s} s waiting for {what}") from None


def test_mavsdk_flight(sitl_port: int) -> None:
    asyncio.run(_flight(sitl_port))


async def _flight(port: int) -> None:
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as sdk:
        await sdk.add_any_connection(f"udpout://127.0.0.1:{port}")
        system = await sdk.first_autopilot(timeout_s=20.0)
        assert system is not None, "MAVSDK found no autopilot"
        telemetry = TelemetryAsync(system)
        action = ActionAsync(system)
        offboard = OffboardAsync(system)

        async def healthy() -> bool:
            h = await telemetry.health()
            return h.is_global_position_ok and h.is_home_position_ok
        await until(healthy, wall(40), "health: global position and home OK")

        async def rel_alt() -> float:
            return (await telemetry.position()).relative_altitude_m

        await action.set_takeoff_altitude(6.0)
        await action.arm()
        await until(telemetry.armed, wall(5), "armed")
        await action.takeoff()
        await until(lambda: _gt(rel_alt(), 5.5), wall(30), "take-off to 6 m")
        await until(telemetry.in_air, wall(10), "in air")

        home = await telemetry.home()
        lat = home.latitude_deg + 15.0 / 111_320.0
        await action.goto_location(lat, home.longitude_deg, home.absolute_altitude_m + 8.0, 0.0)

        async def near_goto() -> bool:
            p = await telemetry.position()
            dn = (p.latitude_deg - lat) * 111_320.0
            de = (p.longitude_deg - home.longitude_deg) * 111_320.0 * math.cos(math.radians(lat))
            return math.hypot(dn, de) < 1.5 and abs(p.relative_altitude_m - 8.0) < 1.0
        await until(near_goto, wall(40), "goto_location")

        async def ned() -> tuple[float, float, float]:
            pv = await telemetry.position_velocity_ned()
            return pv.position.north_m, pv.position.east_m, pv.position.down_m

        n0, e0, d0 = await ned()
        await offboard.set_position_ned(PositionNedYaw(n0, e0, d0, 0.0))
        await offboard.start()
        target = (n0 - 10.0, e0 + 5.0, d0)
        await offboard.set_position_ned(PositionNedYaw(*target, 0.0))

        async def at_target() -> bool:
            return math.dist(await ned(), target) < 1.2
        await until(at_target, wall(40), "offboard position")

        await offboard.set_velocity_ned(VelocityNedYaw(0.0, -2.0, 0.0, 0.0))
        e_start = (await ned())[1]

        async def moved_west() -> bool:
            return (await ned())[1] < e_start - 6.0
        await until(moved_west, wall(20), "offboard velocity")
        await offboard.stop()

        await action.land()

        async def landed() -> bool:
            return not await telemetry.in_air()
        await until(landed, wall(80), "landing")
        await until(lambda: _not(telemetry.armed()), wall(10), "disarmed after landing")


async def _gt(v: Awaitable[float], x: float) -> bool:
    return (await v) > x


async def _not(v: Awaitable[bool]) -> bool:
    return not await v


