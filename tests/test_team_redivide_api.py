"""``POST /api/tasks/{id}/redivide`` on the ground service (seed 003 Sec. II: a border patrol or area scan
redivided among N vehicles): the pieces are replaced, bad requests change nothing."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from harness.ground import InProcessGround
from harness.team import geo

pytestmark = pytest.mark.integration

BORDER = [list(geo(0, 0, 5)), list(geo(0, 100, 5)), list(geo(50, 100, 5))]


@pytest.fixture(scope="module")
def ground(tmp_path_factory: pytest.TempPathFactory) -> Iterator[InProcessGround]:
    g = InProcessGround(tmp_path_factory.mktemp("ground"))
    yield g
    g.close()


def test_redivide_route(ground: InProcessGround) -> None:
    with ground.http() as c:
        r = c.post("/api/tasks", json={"type": "border_patrol", "points": BORDER, "vehicles": 3,
                                       "force": True})
        assert r.status_code == 201, r.text
        group, old = r.json()["group"], r.json()["ids"]
        r = c.post(f"/api/tasks/{group}/redivide", json={"vehicles": 2})
        assert r.status_code == 200, r.text
        new = r.json()["ids"]
        assert r.json() == {"group": group, "ids": new, "vehicles": 2} and not set(new) & set(old)
        states = {t["id"]: t["state"] for t in c.get("/api/tasks").json()["tasks"]}
        assert {states[i] for i in old} == {"cancelled"} and {states[i] for i in new} == {"unassigned"}
        before = c.get("/api/tasks").json()
        assert c.post(f"/api/tasks/{new[0]}/redivide", json={"vehicles": 2}).status_code == 409  # a piece
        assert c.post(f"/api/tasks/{group}/redivide", json={"vehicles": 0}).status_code == 400
        assert c.get("/api/tasks").json() == before
        r = c.post(f"/api/tasks/{group}/redivide")  # no vehicles in this ground's team: N = 1
        assert r.status_code == 200 and r.json()["vehicles"] == 1
