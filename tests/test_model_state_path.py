"""The 500 Hz control chain reads the state interface, not the estimator (seed 002 Sec. 3.1).

Seed 002 Sec. 3.1 and Fig. 2: the estimation filters push their result to one blackboard, the state
interface, and every other component reads it from there. The controller's kernel reads the interface's
read-only state vector; a state written into the interface is what the controller flies on, whatever the
estimator's own working array holds.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from autopilot_model.airframe import load_airframe
from autopilot_model.flights import takeoff
from autopilot_model.state import SV_ACC, SV_POS, SV_QUAT, SV_SIZE, StateInterface, euler_to_quat
from autopilot_model.vehicle import Vehicle


def _hovering(profile: str = "perfect") -> Vehicle:
    v = Vehicle(load_airframe(), sensors=profile, seed=1)
    takeoff(v, 10.0)
    v.run_for(2.0)
    return v


def _scheduled(v: Vehicle, name: str) -> Callable[[], object]:
    """The callable the main loop calls for the periodic function ``name``."""
    fns = [p.fn for p in v.start().schedule.periodic if p.name == name]
    assert len(fns) == 1 and fns[0] is not None
    return fns[0]


def _control_once(v: Vehicle) -> np.ndarray:
    """Run the scheduled control function once from the controller's current state; return its output
    and put the controller's state back as it was."""
    c = v.control
    saved = (c.integ.copy(), c.prev.copy(), c.filt.copy(), c.out.copy())
    _scheduled(v, "control.periodic")()
    out = c.out.copy()
    c.integ[:], c.prev[:], c.filt[:], c.out[:] = saved
    return out


def test_the_controller_flies_on_what_the_state_interface_holds() -> None:
    v = _hovering()
    st = v.state
    base = _control_once(v)
    n, e, d = st.position_ned
    # the blackboard says the vehicle is 3 m above where it is: the controller must cut the thrust
    st.set_position_ned((n, e, d - 3.0))
    high = _control_once(v)
    assert high[0] < base[0] - 0.5, (base[0], high[0])
    # the estimator's working array is not read: corrupting it changes nothing
    saved = v.estimator.est.copy()
    v.estimator.est[0:3] += 50.0
    v.estimator.est[3:6] = 20.0
    try:
        assert np.array_equal(_control_once(v), high)
    finally:
        v.estimator.est[:] = saved
    # an attitude written as Euler angles reaches the controller's kernel too (converted once)
    roll, pitch, yaw = st.euler
    conversions = st.conversions["quat"]
    st.set_euler((roll + 0.3, pitch, yaw))
    tilted = _control_once(v)
    assert st.conversions["quat"] == conversions + 1
    assert abs(tilted[1] - high[1]) > 0.05  # a roll torque against the written roll
    assert tilted[1] < high[1]


def test_the_estimate_is_published_into_the_blackboard_every_iteration() -> None:
    v = _hovering("outdoor")
    loop = v.start()
    for _ in range(7):
        v.step()
        st = v.state
        # published during the iteration that just ended (ins runs every iteration at 500 Hz)
        assert st.time_us == v.clock.now_us - loop.period_us
        assert np.array_equal(st.vector[:13], v.estimator.est)
        assert np.array_equal(st.vector[SV_ACC:SV_ACC + 3], v.estimator.acc)
        assert st.position_ned == tuple(v.estimator.est[0:3].tolist())
        assert st.quat == tuple(v.estimator.est[6:10].tolist())


def test_the_state_vector_is_a_read_only_view_of_one_array() -> None:
    s = StateInterface(origin=(47.0, 8.0, 400.0))
    vec = s.vector
    assert vec.shape == (SV_SIZE,) and not vec.flags.writeable
    with pytest.raises(ValueError, match="read-only"):
        vec[0] = 1.0
    assert s.vector is vec  # the same view every time: no copy per read
    # a validated write shows in the view after the next read, in the vector's own formats
    s.set_position_geodetic((47.0, 8.0, 410.0))
    s.set_euler((0.0, 0.0, 0.5))
    before = dict(s.conversions)
    for _ in range(50):
        out = s.vector
    assert out is vec
    assert np.allclose(vec[SV_POS:SV_POS + 3], (0.0, 0.0, -10.0), atol=1e-6)
    assert np.allclose(vec[SV_QUAT:SV_QUAT + 4], euler_to_quat((0.0, 0.0, 0.5)))
    assert s.conversions["ned"] == before["ned"] + 1 and s.conversions["quat"] == before["quat"] + 1
    # the writer's path: fill the buffer, publish; the tuple formats come from the vector, once
    buf = s.estimate_buffer()
    buf[:] = 0.0
    buf[SV_POS:SV_POS + 3] = (1.0, 2.0, -3.0)
    buf[SV_QUAT:SV_QUAT + 4] = euler_to_quat((0.1, 0.0, 0.0))
    s.publish(1234)
    assert s.time_us == 1234 and s.position_ned == (1.0, 2.0, -3.0) and s.alt_rel == 3.0
    euler_before = s.conversions["euler"]
    for _ in range(50):
        roll = s.euler[0]
    assert roll == pytest.approx(0.1) and s.conversions["euler"] == euler_before + 1
