"""The rigs the tests and the benches run Taskflight on (not part of the installed product).

Each module is one rig or stand-in, defined once and imported as ``harness.<module>`` (the benches too,
run as ``python -m bench.<name>`` from the repository root):

* :mod:`harness.timing`: ``wait_for`` and ``wall``, deadlines in wall time for a model sped up;
* :mod:`harness.model`: the bundled autopilot model in its own process (``SitlProcess``);
* :mod:`harness.fleet`: a fleet of models in one process on free instance numbers;
* :mod:`harness.observer`: the ground-station observer (``Gcs``, a pymavlink ground station);
* :mod:`harness.wire_tap`: a UDP relay that decodes what the companion puts on the wire;
* :mod:`harness.arducopter`: ArduPilot's own copter SITL; :mod:`harness.autopilot`: either autopilot
  with its wire tap and observer (``start_autopilot``, ``AUTOPILOTS``);
* :mod:`harness.fake_autopilot`: a scripted fake ArduCopter for the companion's link;
* :mod:`harness.mavproxy`: MAVProxy on the model (its output waited on, or typed into);
* :mod:`harness.kinematic`: the model's modules on the point-mass stand-in
  (:mod:`companion.flight.simulate`); :mod:`harness.flight_sim`: the companion's queue on it;
  :mod:`harness.behaviors`: the executive layer on it; :mod:`harness.square`: the model's square flight;
* :mod:`harness.flight_session`: a companion in the test process flying either autopilot;
* :mod:`harness.team`: a team of companions on a fleet (``TeamRig``); :mod:`harness.ground`: the ground
  service in-process, as a process, and on a team (``GroundRig``); :mod:`harness.up`: ``taskflight up``
  (``UpRig``); :mod:`harness.ui`: the headless browser;
* :mod:`harness.differential`: the ground-station scenarios flown on both autopilots.

The pytest fixtures built on them are in ``tests/conftest.py``.
"""

from __future__ import annotations

from pathlib import Path

#: the repository's root folder
ROOT = Path(__file__).resolve().parents[1]
