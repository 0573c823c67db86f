"""Wire codec speed: encode and decode, against the JSON form and the copy floor.

Three bodies: a small event (``GpsIDL``), one laser scan line (``Range3dLaserIDL``, 361
beams), and a 1000 x 1000 terrain map with five layers (``MapArrayEventIDL``, 20 MB).
For each: ``idl.wire`` encode and decode, the JSON form (``to_json`` / ``from_json``,
arrays in base64: the form before the wire codec) and the floor of copying the same array
bytes once. Trials are interleaved (every repeat times every contender, in a rotated
order) and the figure is the median, so the machine's drift lands on every contender.

Targets (issue 10): the big map within 3x of the copy floor; a small event under 20 us
for encode plus decode.

Usage: ``python benchmarks/codec.py [--repeat R] [--json]``
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from idl import (  # noqa: E402
    GpsIDL,
    IDLModel,
    MapArrayEventIDL,
    Range3dLaserIDL,
    TimeIDL,
    wire,
)


def bodies() -> dict[str, IDLModel]:
    rng = np.random.default_rng(0)
    gps = GpsIDL(time=TimeIDL(sec=1126958400, usec=250000), latitude=50.2712345678,
                 longitude=-111.1734567891, elevation=752.5, undulation=-17.25,
                 easting=416_123.5, northing=5_569_876.25, utmZone=12, utmZoneLetter="U",
                 satellitesTracked=9, satellitesUsed=8, horizontalSpeed=2.5, track=359.5,
                 verticalSpeed=-0.125, solutionStatus="SOL_COMPUTED", positionType="PSRDIFF",
                 latitudeStd=0.5, longitudeStd=0.75, elevationStd=1.25)
    points = rng.normal(size=(361, 3)).astype(np.float32)
    laser = Range3dLaserIDL(time=TimeIDL(sec=1), sensorId=11, frame="FrontNoddingSICKLeft:"
                            "AxleCenterFreeEnd", nodAngleStart=-0.7, nodAngleEnd=-0.69,
                            points=points, valid=np.ones(361, dtype=bool))
    n = 1000
    layers = {name: rng.random((n, n), dtype=np.float32)
              for name in ("elevation", "minHeight", "maxHeight", "variance")}
    terrain = MapArrayEventIDL(time=TimeIDL(sec=1), frame="World", mapPose=np.eye(4),
                               initialUTM=np.zeros(3), gridsize=0.2, originX=-100.0,
                               originY=-100.0, rows=n, cols=n,
                               pointCount=rng.integers(0, 50, (n, n), dtype=np.int32), **layers)
    return {"small event (GpsIDL)": gps, "laser scan (361 beams)": laser,
            "map 1000x1000x5 (20 MB)": terrain}


def arrays_of(model: IDLModel) -> list[np.ndarray]:
    return [v for v in (getattr(model, f) for f in type(model).model_fields)
            if isinstance(v, np.ndarray)]


def contenders(model: IDLModel) -> dict[str, Callable[[], object]]:
    frame = wire.encode(model)
    text = model.to_json()
    arrays = arrays_of(model)
    cls = type(model)
    return {
        "wire encode": lambda: wire.encode(model),
        "wire decode": lambda: wire.decode(frame),
        "json encode": lambda: model.to_json(),
        "json decode": lambda: cls.from_json(text),
        "copy floor": lambda: [a.copy() for a in arrays],
    }


def time_one(call: Callable[[], object], budget: float) -> float:
    """Seconds per call: enough calls to fill ``budget`` seconds (at least one)."""
    start = time.perf_counter()
    call()
    once = time.perf_counter() - start
    calls = max(1, min(20_000, int(budget / max(once, 1e-7))))
    start = time.perf_counter()
    for _ in range(calls):
        call()
    return (time.perf_counter() - start) / calls


def measure(repeat: int) -> dict[str, dict[str, float]]:
    results: dict[str, dict[str, float]] = {}
    for body_name, model in bodies().items():
        cases = contenders(model)
        names = list(cases)
        samples: dict[str, list[float]] = {name: [] for name in names}
        for trial in range(repeat):
            for name in names[trial % len(names):] + names[:trial % len(names)]:
                samples[name].append(time_one(cases[name], 0.05) * 1e6)
        row = {name: round(statistics.median(v), 2) for name, v in samples.items()}
        row["wire_bytes"] = len(wire.encode(model))
        row["json_bytes"] = len(model.to_json())
        row["array_bytes"] = sum(a.nbytes for a in arrays_of(model))
        results[body_name] = row
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    results = measure(args.repeat)
    if args.json:
        print(json.dumps(results, indent=2))
        return
    print(f"microseconds per call, median of {args.repeat} interleaved trials")
    header = ["wire encode", "wire decode", "json encode", "json decode", "copy floor"]
    print(f"{'body':26s}" + "".join(f"{h:>13s}" for h in header) + f"{'wire/raw B':>12s}")
    for body, row in results.items():
        size = row["wire_bytes"] / row["array_bytes"] if row["array_bytes"] else float("nan")
        print(f"{body:26s}" + "".join(f"{row[h]:13.1f}" for h in header) + f"{size:12.3f}")
    small = results["small event (GpsIDL)"]
    big = results["map 1000x1000x5 (20 MB)"]
    print(f"small event encode + decode: {small['wire encode'] + small['wire decode']:.1f} us "
          "(target < 20 us)")
    print(f"big map: encode {big['wire encode'] / big['copy floor']:.2f}x, decode "
          f"{big['wire decode'] / big['copy floor']:.2f}x the copy floor (target <= 3x); "
          f"JSON {big['json encode'] / 1000:.0f} ms / {big['json decode'] / 1000:.0f} ms")


if __name__ == "__main__":
    main()
