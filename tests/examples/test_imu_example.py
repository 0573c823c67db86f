"""Testing one component as configured, with afa's pytest plugin (docs/testing.md)."""

from pathlib import Path

import pytest

from afa.testing import configured_parameters
from components.imu import ImuParameters
from components.imu.fake import FakeImu
from idl import Imu

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "raptor.xml"


def test_the_imu_section_of_the_configuration():
    parameters = configured_parameters(CONFIG, "3dmgService")
    assert isinstance(parameters, ImuParameters)
    assert parameters.EventName == "Imu" and parameters.Notify


async def test_the_configured_imu_publishes_and_serves_what_its_fake_measures(
        afa_system, virtual_clock):
    fake = FakeImu(virtual_clock)  # level and still, without noise
    system = afa_system(CONFIG, only=["3dmgService"],
                        devices={"3dmgService": fake.factory()})  # key: component name
    events = system.channel.subscribe("Raptor", "Imu", maxsize=100)
    async with system:
        await virtual_clock.advance(2.0)  # two seconds of virtual time, at once
        proxy = await system.resolve(Imu, "Imu")  # the name it serves: its EventName
        latest = await proxy.getImuData()
        await fake.aclose()
    received = []
    while (event := events.get_nowait()) is not None:
        received.append(event.body)
    assert len(received) >= 10  # every 100 ms once the unit streams
    assert latest.accelZ == pytest.approx(-9.80665, abs=0.01)
    assert (latest.roll, latest.pitch) == pytest.approx((0.0, 0.0), abs=1e-3)
