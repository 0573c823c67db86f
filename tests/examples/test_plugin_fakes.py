"""Every shipped fake works on the pytest plugin's ``virtual_clock`` through
``afa_system`` (docs/testing.md), as a user's first test would use them."""

from pathlib import Path

import pytest

from afa import VirtualClock
from components.gps_sokkia.fake import FakeGps
from components.imu.fake import FakeImu
from components.mpc555.fake import FakeMpc555
from components.nodding_laser.fake import FakeNodLaser

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "raptor.xml"
FAKES = {  # the fake, and the components (device keys) it serves
    "gps": (FakeGps, ["GpsSokkiaService"]),
    "imu": (FakeImu, ["3dmgService"]),
    "mpc555": (FakeMpc555, ["RaptorOdometryService", "RaptorService"]),
    "laser": (FakeNodLaser, ["NodLaserService"]),
}


@pytest.mark.parametrize("kind", sorted(FAKES))
async def test_each_fake_on_the_plugins_clock_brings_its_driver_up(kind, afa_system,
                                                                    virtual_clock):
    fake_type, names = FAKES[kind]
    fake = fake_type(virtual_clock)
    system = afa_system(CONFIG, only=names, devices={name: fake.factory() for name in names})
    async with system:
        await virtual_clock.advance(5.0)
        health = system.health()
    await fake.aclose()
    assert all(h.healthy and h.failures == 0 for h in health.values()), health


def test_a_gps_fake_on_a_clock_before_the_gps_epoch_says_so():
    """GPS time begins on 1980-01-06: a receiver cannot report an earlier date."""
    with pytest.raises(ValueError, match="before the GPS epoch"):
        FakeGps(VirtualClock(start=0.0))


def test_a_misspelt_component_name_in_only_is_suggested(afa_system):
    """`only=[...]` names Launcher entries; a typo gets a suggestion and the list."""
    from afa.errors import ConfigError

    with pytest.raises(ConfigError, match=r"no Launcher entry named '3dmgServce' \(did you "
                                          r"mean '3dmgService'\?\); the entries are "
                                          r"NodLaserService, .*GpsSokkiaService"):
        afa_system(CONFIG, only=["3dmgServce"])
