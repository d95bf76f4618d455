"""The scenario file's JSON Schema, generated from its model: ``sim_fixtures/schemas/scenario.schema.json``.

``python -m sim_fixtures.contracts`` rewrites it, ``--check`` exits 1 when it is stale
(:class:`groundstation.contracts.Contracts`, as for the groundstation's contracts).
"""

from __future__ import annotations

import sys
from pathlib import Path

from groundstation.contracts import Contracts
from sim_fixtures.scenario import Scenario

SIM_FIXTURES = Contracts(
    {"scenario": (Scenario, "skyfix sim scenario (TOML)")},
    Path(__file__).parent / "schemas",
    "sim_fixtures.contracts",
)

if __name__ == "__main__":
    sys.exit(SIM_FIXTURES.main())
