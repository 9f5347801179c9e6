"""One simulated vehicle: the autopilot model and the world it flies in (seed 002 Fig. 2 and 4).

Assembly: airframe YAML -> parameters, physics (world), sensors, estimator, state interface, setpoint
generator (guidance), cascaded PID (control), mixer (actuators), navigator, battery monitor; the module
library YAML -> a static schedule (two-pass topological sort, task groups, prescalers and offsets) run by
the main loop at ``main_loop_hz`` (500 Hz by default) on one :class:`~taskflight_common.clock.SimClock`.
The world
steps once per iteration after the autopilot's functions, so the autopilot sees the world one period late,
as a real one does.

Every step comes from the schedule (seed 002 Sec. 3.2): the world and the clock advance by the main loop
period; each periodic function (estimator, setpoint generator, controller, navigator, the position,
barometer and compass corrections) steps by the period times its prescaler. Nothing assumes 500 Hz.

The module resolver, not this code, chooses the position source: the sensor profile
(``sensors=`` or the airframe's ``sensors``) is a module of the library that depends on ``gps`` or
``mocap`` (both provide ``@position_source`` and conflict, seed 002 Sec. 3.2 and Fig. 3); the vehicle adds
it to the selection and reads back which source the resolution loaded and the period of its function
(its prescaler: 10 Hz GPS, 100 Hz motion capture in the bundled library). A selection with both is
refused by the resolver's conflict check.

The control chain reads the state interface (seed 002 Sec. 3.1, Fig. 2): the estimator writes its
checked estimate into the interface's array (:meth:`~autopilot_model.state.StateInterface.
estimate_buffer`) and publishes it; the controller's kernel reads the read-only view
:attr:`~autopilot_model.state.StateInterface.vector`, the pilot modes and the navigator read the same
blackboard. Nothing on the control path reads the estimator's working array.

This class is also the small Python API that tests use to command the model; the MAVLink
endpoint's wiring (:mod:`autopilot_model.mavlink.wiring`) registers its module functions with
:meth:`Vehicle.register`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from pathlib import Path

from autopilot_model.airframe import CONFIG_DIR, Airframe, load_airframe
from autopilot_model.modules.actuators import Mixer
from autopilot_model.modules.control import CascadedController
from autopilot_model.modules.estimation import Estimator
from autopilot_model.modules.guidance import Envelope, SetpointGenerator
from autopilot_model.modules.navigation import LANDED_ON_GROUND, Navigator
from autopilot_model.modules.rangefinder import RangeFinder
from autopilot_model.modules.sensors import PROFILES, Barometer, Compass, Imu, PositionSensor
from autopilot_model.params import ParamStore
from autopilot_model.physics.battery import Battery
from autopilot_model.physics.quadrotor import P_GROUND, PX, PY, Quadrotor
from autopilot_model.physics.wind import Wind
from autopilot_model.quatmath import quat_yaw
from autopilot_model.scheduler.errors import SchedulerError
from autopilot_model.scheduler.mainloop import MainLoop
from autopilot_model.scheduler.schedule import Schedule, build_schedule
from autopilot_model.scheduler.spec import load_modules
from autopilot_model.state import StateInterface
from taskflight_common.clock import SimClock

log = logging.getLogger(__name__)

DEFAULT_MODULES = CONFIG_DIR / "modules.yaml"
# ArduPilot SITL's default home (CMAC, Canberra): lat, lon, alt AMSL, heading
DEFAULT_HOME = (-35.363261, 149.165230, 584.0, 353.0)
BATTERY_FILTER_TAU_S = 0.4
"""Time constant (s) of the battery monitor's voltage filter."""


class Vehicle:
    """An autopilot model instance with its world; see the module docstring."""

    def __init__(self, airframe: Airframe, modules_file: str | Path = DEFAULT_MODULES,
                 home: Sequence[float] = DEFAULT_HOME, speedup: float = 0.0, instance: int = 0,
                 sensors: str | None = None, use_truth: bool = False, seed: int | None = 0,
                 offset_heuristic: str = "optimised", extra_select: Sequence[str] = (),
                 params_file: str | Path | None = None, spin_s: float = 0.0) -> None:
        self.airframe = airframe
        self.instance = instance
        self.home = (float(home[0]), float(home[1]), float(home[2]))
        self.home_heading_deg = float(home[3]) if len(home) > 3 else 0.0
        self.clock = SimClock(speedup, spin_s=spin_s)
        self.params = ParamStore()
        if params_file is not None:
            # before any piece declares (and copies) its parameters: the saved values are the flown
            # ones from the start, as ArduCopter's AP_Param::load_all before the libraries initialise
            self.params.attach_file(params_file)
        self._functions: dict[str, Callable[[], object]] = {}
        self.loop: MainLoop | None = None
        self._extra_select = list(extra_select)
        self._modules_file = Path(modules_file)
        self._heuristic = offset_heuristic
        af = airframe

        # --- world
        self.world = Quadrotor(af.mass, af.inertia, af.arm_length, af.k_t, af.k_q, af.motor_tau,
                               af.max_speed, af.drag_linear, af.drag_quadratic, af.drag_rotational)
        self.terrain = af.terrain
        """The ground (:mod:`autopilot_model.terrain`): ground contact and the range finder."""
        self.world.place(down=-self.terrain.height(0.0, 0.0), yaw=math.radians(self.home_heading_deg))
        self.world.prm[P_GROUND] = -self.terrain.height(0.0, 0.0)
        self.wind = Wind(af.wind_mean, af.gust_sigma, af.gust_max, af.gust_tau, seed=seed)
        self.battery = Battery(af.battery_cells, af.battery_capacity_mah, af.battery_r)
        # the main loop rate of the module library; the steps are set again from the built schedule
        # (period times prescaler) in start()
        self._config = load_modules(self._modules_file)
        self.main_hz = self._config.main_loop_hz
        self.dt = self._config.period_us / 1e6
        """The physics step (s): one main loop period."""
        self.nav_dt = self.dt
        """The navigator's step (s): its prescaler times the period (set in :meth:`start`)."""
        self.steps: dict[str, float] = {}
        """Step (s) of every periodic function of the schedule, by name (set in :meth:`start`)."""
        self._battery_acc = 0.0
        self.battery_voltage = 0.0

        # --- sensors and estimation
        profile = sensors or af.sensors
        if profile not in PROFILES:
            raise ValueError(f"unknown sensor profile '{profile}' (one of {', '.join(PROFILES)})")
        self.sensor_profile = profile
        noise = PROFILES[profile]
        s = None if seed is None else seed * 7919 + 11
        self.imu = Imu(self.world, noise, s)
        self.gps = PositionSensor(self.world, noise, None if s is None else s + 1)
        """The position source (GPS or motion capture, as the resolver chose: ``gps.module``)."""
        self.baro = Barometer(self.world, noise, None if s is None else s + 2)
        self.compass = Compass(self.world, noise, None if s is None else s + 3)
        self.rangefinder = RangeFinder(self.world, self.terrain, self.params, profile != "perfect",
                                       None if s is None else s + 4)
        """The downward range finder (RNGFND1_*; off unless RNGFND1_TYPE is set, as ArduCopter)."""
        self.state = StateInterface(origin=self.home)
        self.estimator = Estimator(self.imu, self.gps, self.baro, self.compass, self.dt, self.world,
                                   use_truth, out=self.state.estimate_buffer())

        # --- guidance, control, actuators
        env = af.envelope
        self.envelope = Envelope(
            box=env.get("box"), polygon=env.get("polygon"),
            alt_floor=env["alt_floor"], alt_ceiling=env["alt_ceiling"],
            max_speed_h=env["max_speed_h"], max_speed_up=env["max_speed_up"],
            max_speed_down=env["max_speed_down"], max_accel_h=env["max_accel_h"],
            max_accel_v=env["max_accel_v"], max_yaw_rate=math.radians(env["max_yaw_rate"]))
        self.guidance = SetpointGenerator(self.envelope, self.dt)
        self.guidance.reset((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), math.radians(self.home_heading_deg))
        self.control = CascadedController(self.params, af.mass, af.inertia, 4 * af.thrust_max, self.dt)
        for name, value in af.gains.items():
            if name not in self.params:
                raise ValueError(f"{af.source}: gains.{name}: unknown control parameter")
            self.params.set_default(name, value)  # the airframe's defaults; a saved value wins
        self.mixer = Mixer(self.world.mx, self.world.my, self.world.spin, af.torque_ratio, af.thrust_max,
                           af.spin_armed)
        self.nav = Navigator(self)
        self.lean: tuple[float, float, float | None] | None = None
        """The pilot's lean as accelerations (north, east, down or None: P_d's), set by the pilot modes
        (:mod:`autopilot_model.modules.pilot_modes`); None: the controller follows P_d."""

        # --- module functions (the registry the schedule binds to)
        self.register("imu.periodic", self.imu.periodic)
        self.register("gps.periodic", self._position_periodic)
        self.register("mocap.periodic", self._position_periodic)
        self.register("baro.periodic", self.baro.periodic)
        self.register("compass.periodic", self.compass.periodic)
        self.register("ins.periodic", self._ins_periodic)
        self.register("guidance.periodic", self.guidance.update)
        self.register("nav.periodic", self._nav_periodic)
        self.register("control.periodic", self._control_periodic)
        self.register("mixer.periodic", self._mixer_periodic)
        self.register("battery.periodic", self._battery_periodic)

    # --- construction helpers ----------------------------------------------------------------------
    @classmethod
    def from_files(cls, airframe: str | Path | None = None, modules: str | Path | None = None,
                   **kwargs: object) -> Vehicle:
        """Build from an airframe YAML (default: the bundled Quad X) and a module library YAML."""
        af = load_airframe(airframe)
        return cls(af, modules or DEFAULT_MODULES, **kwargs)  # type: ignore[arg-type]

    def register(self, name: str, fn: Callable[[], object]) -> None:
        """Make a module function available to the schedule (before :meth:`start`)."""
        if self.loop is not None:
            raise RuntimeError(f"cannot register {name}: the main loop is already built")
        self._functions[name] = fn

    def select(self, *modules: str) -> None:
        """Add modules to the airframe's selection (the MAVLink endpoint adds its own)."""
        if self.loop is not None:
            raise RuntimeError("cannot select modules: the main loop is already built")
        self._extra_select.extend(modules)

    def selection(self, config_select: Sequence[str]) -> list[str]:
        """The modules handed to the resolver: the library's selection, the sensor profile's module (which
        brings its position source) and the modules added with :meth:`select`."""
        sel = list(config_select)
        for m in (self.sensor_profile, *self._extra_select):
            if m not in sel:
                sel.append(m)
        return sel

    def start(self) -> MainLoop:
        """Resolve the modules, build the static schedule and run the init functions."""
        if self.loop is None:
            config = self._config
            schedule = build_schedule(config, self._functions, select=self.selection(config.select),
                                      heuristic=self._heuristic)
            source = self._position_source_of(schedule)  # checked before anything is changed
            self._set_steps(schedule)
            self._set_position_source(*source)
            self.loop = MainLoop(schedule, self.clock, self._world_step)
            self.loop.run_init()
        return self.loop

    def _set_steps(self, schedule: Schedule) -> None:
        """Give every periodic function its step from the schedule: the main loop period times its
        prescaler; the world (physics, wind, battery) steps one period, as the clock advances."""
        self.main_hz = schedule.main_loop_hz
        period = schedule.period_us / 1e6
        self.dt = period
        steps = self.steps = {p.name: p.prescaler * period for p in schedule.periodic}
        est = self.estimator
        est.dt = steps.get("ins.periodic", est.dt)
        self.guidance.set_dt(steps.get("guidance.periodic", self.guidance.dt))
        self.control.dt = steps.get("control.periodic", self.control.dt)
        self.nav_dt = steps.get("nav.periodic", self.nav_dt)

    @staticmethod
    def _position_source_of(schedule: Schedule) -> tuple[str, str]:
        """The module the resolver loaded for ``@position_source`` and its periodic function's name."""
        providers = schedule.resolution.provided.get("@position_source", ())
        if len(providers) != 1:
            raise SchedulerError(f"exactly one module must provide '@position_source', the resolution "
                                 f"loaded {len(providers)}: {', '.join(providers) or 'none'}")
        module = providers[0]
        fns = [p.name for p in schedule.periodic if p.module == module]
        if len(fns) != 1:
            raise SchedulerError(f"position source module '{module}' must have exactly one periodic "
                                 f"function (its sample rate), it has {len(fns)}")
        return module, fns[0]

    def _set_position_source(self, module: str, function: str) -> None:
        """Hand the position source the resolver loaded and the step of its function to the sensor and
        the estimator (with the barometer's and compass's steps; NaN for one not scheduled: its
        correction never runs)."""
        dt = self.steps[function]
        self.gps.configure(module, dt)
        est = self.estimator
        est.set_position_source(module)
        est.set_periods(dt, self.steps.get("baro.periodic", math.nan),
                        self.steps.get("compass.periodic", math.nan))
        log.debug("position source: %s every %.3f s", module, dt)

    @property
    def position_source(self) -> str:
        """The module providing ``@position_source`` in the resolved schedule (``gps`` or ``mocap``)."""
        self.start()
        return self.gps.module

    def step_of(self, name: str) -> float:
        """The step (s) of the periodic function ``name`` in the schedule: period times prescaler."""
        self.start()
        try:
            return self.steps[name]
        except KeyError:
            raise KeyError(f"'{name}' is not a periodic function of the schedule") from None

    # --- module functions ---------------------------------------------------------------------------
    def _position_periodic(self) -> None:
        """``gps.periodic`` or ``mocap.periodic``: called by the schedule at the source's rate."""
        self.gps.periodic(self.clock.now())

    def _ins_periodic(self) -> None:
        """The estimator's update; it wrote the checked estimate into the state interface's array,
        published here (seed 002 Sec. 3.1: INS -> state interface)."""
        est = self.estimator
        est.on_ground = self.nav.landed_state == 1 and not self.nav.spooled
        est.periodic(self.clock.now())
        if est.initialised:
            self.state.publish(self.clock.now_us)

    def _nav_periodic(self) -> None:
        self.nav.periodic(self.nav_dt)

    def _control_periodic(self) -> None:
        if not (self.nav.armed and self.nav.spooled):
            self.control.reset()
            return
        g = self.guidance
        e = self.state.vector  # the blackboard's read-only view (seed 002 Sec. 3.1), not the estimator's
        lean = self.lean
        if lean is None:
            self.control.step(e, g.p, g.v, g.a, g.yaw, g.yaw_rate)
            return
        # the pilot's lean angles (pilot_modes): a horizontal acceleration with no horizontal feedback,
        # and in STABILIZE the collective as a vertical acceleration with no vertical feedback either
        an, ae, ad = lean
        if ad is None:
            self.control.step(e, (e[0], e[1], g.p[2]), (e[3], e[4], g.v[2]), (an, ae, g.a[2]), g.yaw,
                              g.yaw_rate)
        else:
            self.control.step(e, (e[0], e[1], e[2]), (e[3], e[4], e[5]), (an, ae, ad), g.yaw, g.yaw_rate)

    def _mixer_periodic(self) -> None:
        self.mixer.step(self.control.out, self.nav.armed, self.nav.spooled, self.world.cmd)

    def _battery_periodic(self) -> None:
        """Battery monitor (core group, 10 Hz in the bundled library): the voltage low-pass filtered with
        a 0.4 s time constant, its weight from the function's step in the schedule (0.2 at 10 Hz)."""
        b = self.battery
        if self.battery_voltage <= 0:
            self.battery_voltage = b.voltage
            return
        dt = self.steps.get("battery.periodic", self.dt)
        alpha = dt / (dt + BATTERY_FILTER_TAU_S)
        self.battery_voltage += (b.voltage - self.battery_voltage) * alpha

    def _world_step(self) -> None:
        self.wind.step(self.dt, self.world.wind)
        if not self.terrain.flat:
            x = self.world.x
            self.world.prm[P_GROUND] = -self.terrain.height(float(x[PX]), float(x[PY]))
        self.world.step(self.dt)
        self._battery_acc += self.dt
        if self._battery_acc >= 0.1:
            self.battery.step(self._battery_acc, self.world.electrical_power())
            self._battery_acc = 0.0

    # --- helpers used by the navigator -------------------------------------------------------------
    def guidance_reset_here(self) -> None:
        """Re-initialise P_d at the estimated state (on arming, take-off and after landing)."""
        e = self.state.vector
        yaw = float(quat_yaw(e[6], e[7], e[8], e[9]))
        on_ground = self.nav.landed_state == LANDED_ON_GROUND
        vel = (0.0, 0.0, 0.0) if on_ground else (float(e[3]), float(e[4]), float(e[5]))
        self.guidance.reset((float(e[0]), float(e[1]), min(float(e[2]), 0.0) if on_ground else float(e[2])),
                            vel, yaw)

    def state_alt_estimate(self) -> float:
        """Estimated down position (m, NED), from the state interface."""
        return float(self.state.vector[2])

    # --- running ---------------------------------------------------------------------------------------
    def step(self, n: int = 1) -> None:
        loop = self.start()
        for _ in range(n):
            loop.step()

    def run_for(self, seconds: float) -> None:
        """Run the main loop for ``seconds`` of simulated time."""
        self.step(max(1, round(seconds * self.main_hz)))

    def run_until(self, predicate: Callable[[], bool], timeout_s: float, check_every_s: float = 0.02) -> bool:
        """Run until ``predicate()`` is true (checked every ``check_every_s`` simulated seconds) or the
        simulated timeout elapses; returns whether the predicate became true."""
        loop = self.start()
        n_check = max(1, round(check_every_s * self.main_hz))
        end = self.clock.now() + timeout_s
        while self.clock.now() < end:
            for _ in range(n_check):
                loop.step()
            if predicate():
                return True
        return bool(predicate())

    def run_realtime(self, duration_s: float | None = None, stop: object = None) -> None:
        loop = self.start()
        loop.run(duration_s, stop)  # type: ignore[arg-type]

    # --- truth read-outs (tests and the bench) --------------------------------------------------------
    def wait_estimator(self, timeout_s: float = 5.0) -> bool:
        return self.run_until(lambda: self.estimator.healthy, timeout_s)
