"""``python -m tests.bridge.peer ROLE ...``: a bridged peer process for the tests (the
components live in :mod:`tests.bridge.parts`, imported under that name so that both
sides agree on the IDL type and interface names)."""

import asyncio
import sys

from tests.bridge.parts import main

if __name__ == "__main__":
    sys.exit(asyncio.run(main(sys.argv[1:])))
