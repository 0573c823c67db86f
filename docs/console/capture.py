"""Screenshots of every console view from a simulated autonomous mission (docs/console.md).

Runs the whole Raptor stack of ``configs/raptor.xml`` on a simulated world in virtual
time with the console attached and a headless Chromium watching, pauses the clock after
``--seconds`` simulated seconds, and saves a screenshot of the page and of each pane.

Usage: ``python docs/console/capture.py [--world rock-field] [--seconds 60] [--out DIR]``;
then the Replay pane on a recording of a 20 s run (``--replay-only``: that alone)
(needs ``pip install -e '.[test]'`` for Playwright and Debian's ``chromium``).
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from playwright.async_api import async_playwright  # noqa: E402

from afa import VirtualClock  # noqa: E402
from afa.console import Console, ConsoleOptions  # noqa: E402
from components.simulation import RaptorSimulation  # noqa: E402

FLAGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--enable-unsafe-swiftshader", "--use-angle=swiftshader"]
PANES = {"maps": "maps", "localmap": "local-map", "pose": "pose",
         "scene": "body-frames-and-range-points", "vehicle": "vehicle-and-health"}


def arguments() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--world", default="rock-field")
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "console")
    parser.add_argument("--chromium", default="/usr/bin/chromium")
    parser.add_argument("--replay-only", action="store_true",
                        help="only the Replay pane (on a recording of a 20 s run)")
    return parser.parse_args()


async def main(args: argparse.Namespace) -> None:
    logging.basicConfig(level=logging.ERROR)
    clock = VirtualClock()
    simulation = RaptorSimulation.from_xml(ROOT / "configs" / "raptor.xml",
                                           ROOT / "configs" / "worlds" / f"{args.world}.xml",
                                           clock=clock, seed=args.seed)
    console = Console(simulation.system, ConsoleOptions(port=0, control=True),
                      truth=simulation)
    args.out.mkdir(parents=True, exist_ok=True)
    async with console, async_playwright() as playwright:
        browser = await playwright.chromium.launch(executable_path=args.chromium,
                                                   headless=True, args=FLAGS)
        page = await browser.new_page(viewport={"width": 1500, "height": 1150})
        await page.goto(console.url, timeout=60_000)
        async with simulation:
            start = clock.monotonic()
            while clock.monotonic() - start < args.seconds:
                await asyncio.sleep(0.5)  # the page watches the run as it goes
            # the Launcher while running (its loop shares are averages over the last seconds)
            await page.locator("#pane-launcher").screenshot(path=str(args.out / "launcher.png"))
            clock.pause()
            print(f"paused at t = {simulation.sim_time:.1f} s: {simulation.progress()}")
            await asyncio.sleep(4.0)      # every view drawn from the frozen state
            await page.select_option('[data-control="maps-layer"]', "traverse")
            await asyncio.sleep(1.0)
            await page.screenshot(path=str(args.out / "console.png"), full_page=False)
            for pane, name in PANES.items():
                await page.locator(f"#pane-{pane}").screenshot(path=str(args.out / f"{name}.png"))
            await page.select_option('[data-control="maps-layer"]', "plan")
            await asyncio.sleep(3.0)
            await page.locator("#pane-maps").screenshot(path=str(args.out / "global-map.png"))
            await page.select_option('[data-control="localmap-votes"]', "ObstacleAvoidance")
            await asyncio.sleep(1.0)
            await page.locator("#pane-localmap").screenshot(
                path=str(args.out / "local-map-obstacle-avoidance.png"))
            clock.resume()
        await browser.close()
    print(f"screenshots in {args.out}")


def record(path: Path, seconds: float = 20.0) -> Path:
    """A recording of a short autonomous run (for the Replay pane)."""
    from afa.cli import main as afa_main

    afa_main(["run", str(ROOT / "configs" / "raptor.xml"), "--sim", "--fast",
              "--duration", f"{seconds:g}", "--record", str(path)])
    return path


async def replay_pane(recording: Path, out: Path, chromium: str) -> None:
    """The Replay pane on ``recording``, sought to 10 s (a tall page: nothing over it)."""
    from afa.log.player import Player

    player = Player(recording, speed=1.0, paused=True)
    console = Console(player.system, ConsoleOptions(port=0), replay=player)
    async with console, player, async_playwright() as playwright:
        browser = await playwright.chromium.launch(executable_path=chromium,
                                                   headless=True, args=FLAGS)
        page = await browser.new_page(viewport={"width": 1500, "height": 2400})
        await page.goto(console.url, timeout=60_000)
        status = await console.hub.replay_action("seek", 10.0)
        await console.hub.replay_action("speed", 4)
        await asyncio.sleep(3.0)
        await page.locator("#pane-replay").scroll_into_view_if_needed()
        await page.locator("#pane-replay").screenshot(path=str(out / "replay.png"))
        await browser.close()
    print(f"replay pane at {status['position']:.1f} s of {status['duration']:.1f} s")


if __name__ == "__main__":
    import tempfile

    options = arguments()
    if not options.replay_only:
        asyncio.run(main(options))
    options.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        asyncio.run(replay_pane(record(Path(tmp) / "mission.mcap"), options.out,
                                options.chromium))
