"""The console's replay controls on afa.log's Player: play, pause, step, seek and speed on
a real recording of a simulated run, through the adapter and the HTTP endpoint."""

from pathlib import Path

import aiohttp
import pytest

from afa.cli import main
from afa.console import Console, ConsoleOptions

ROOT = Path(__file__).resolve().parents[2]

pytest.importorskip("mcap")


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("replay") / "run.mcap"
    assert main(["run", str(ROOT / "configs" / "raptor.xml"), "--sim", "--fast",
                 "--duration", "4", "--record", str(path)]) == 0
    return path


async def test_the_replay_pane_drives_the_player(recording):
    from afa.log.player import Player

    player = Player(recording, speed=1.0, paused=True)
    console = Console(player.system, ConsoleOptions(port=0), replay=player)
    hub = console.hub
    async with console, player:
        status = (await hub.replay_action("pause"))
        assert status["paused"] is True and status["duration"] > 3.0
        assert status["label"].endswith("run.mcap")
        before = status["position"]
        await hub.replay_action("step")
        await hub.replay_action("step")
        assert hub.replay.status()["position"] > before
        status = await hub.replay_action("seek", 2.0)
        assert status["position"] == pytest.approx(2.0, abs=0.05)
        assert (await hub.replay_action("speed", 4))["speed"] == 4.0
        assert (await hub.replay_action("speed", "max"))["speed"] is None
        assert (await hub.replay_action("play"))["paused"] is False
        async with aiohttp.ClientSession() as http:
            reply = await http.post(f"http://127.0.0.1:{console.port}/api/replay/pause",
                                    json={})
            assert reply.status == 200 and (await reply.json())["replay"]["paused"] is True
            for value in ("later", 10**400):
                async with http.post(f"http://127.0.0.1:{console.port}/api/replay/seek",
                                     json={"value": value}) as bad:
                    assert bad.status == 400 and "needs a number" in (await bad.json())["error"]
        assert player.paused


def test_afa_replay_takes_the_console_options(recording, capsys):
    assert main(["replay", str(recording), "--speed", "max", "--console", "0"]) == 0
    err = capsys.readouterr().err
    assert "afa: console at http://127.0.0.1:" in err
