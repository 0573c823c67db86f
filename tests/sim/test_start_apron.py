"""A vehicle put down closer to a wall than it can turn (decision 0045): the whole stack
in the simulator, in virtual time.

The bumper starts 2.6 m from a 19 m wall, the goal lies past its nearer end, and
nothing has seen the ground behind or beside the vehicle. Obstacle Detection halts it;
the first back-out turns it part of the way; the next ones swing the nose away from the
wall and so reverse over unseen ground beside the spot where it was put down. With a
start apron only as wide as the body (two disc radii either side) those were blocked
and the vehicle stood there until the mission's time ran out.
"""

import pytest

# the rear axle at east -20 heading east: the bumper (2.45 m ahead) at -17.55, the
# wall's face at -14.98
WORLD = """<?xml version="1.0" encoding="UTF-8"?>
<world name="put-down-at-a-wall">
  <origin latitude="45.3" longitude="-75.9" elevation="100.0"/>
  <terrain width="90" depth="60" resolution="0.1" roughness="0.03" seed="71"/>
  <obstacle type="box" east="-14.68" north="1.4" length="19.2" width="0.6" height="1.5"
            heading="0"/>
  <vehicle east="-20.0" north="0.0" heading="90"/>
  <mission patrol="false"><waypoint east="25.0" north="-5.7"/></mission>
</world>
"""


@pytest.mark.timeout(600)
async def test_a_vehicle_put_down_close_to_a_wall_turns_away_over_its_start_apron(simulate):
    simulation = simulate(WORLD)
    async with simulation:
        await simulation.run_mission()
        summary = {**simulation.summary(), **simulation.course_reference()}
        backouts = simulation.system.components["arcArbiter"].statistics()["backouts"]
    assert summary["mission_complete"], summary
    assert summary["collisions"] == []
    assert backouts >= 1  # it did have to back out
    # the oracle's course starts at the vehicle's pose and does not count the turn
    # away from the wall; a vehicle that turned and drove on is well within 1.25x
    assert summary["path_ratio"] <= 1.25
