"""JSON Schema files of every contract, generated from the models: ``groundstation/schemas/*.schema.json``.

``python -m groundstation.contracts`` rewrites them; ``--check`` exits 1 when a checked-in
file differs from what the models say (``tests/test_contracts.py`` does the same).
The TOML contracts' schemas also serve editors: Taplo (VS Code's Even Better TOML)
validates a file that starts with ``#:schema ./calibration.schema.json``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from groundstation.live.config import RunConfig
from groundstation.messages import FixMessage, StatusMessage
from localizer.calibration import Calibration
from localizer.contract import adapter
from sim_fixtures.scenario import Scenario

SCHEMA_DIR = Path(__file__).parent / "schemas"
DRAFT = "https://json-schema.org/draft/2020-12/schema"

#: file stem → (model, title)
CONTRACTS = {
    "fix": (FixMessage, "skyfix fix message (Zenoh, JSON)"),
    "status": (StatusMessage, "skyfix status message (Zenoh, JSON)"),
    "calibration": (Calibration, "skyfix calibration: the session.toml v1 tables (TOML)"),
    "run-config": (RunConfig, "skyfix run options: the --config file (TOML)"),
    "scenario": (Scenario, "skyfix sim scenario (TOML)"),
}


def json_schema(name: str) -> dict:
    """The JSON Schema of contract ``name`` (a key of :data:`CONTRACTS`)."""
    model, title = CONTRACTS[name]
    schema = adapter(model).json_schema(by_alias=True)
    return {"$schema": DRAFT, "$id": f"urn:skyfix:schema:{name}", **schema, "title": title}


def schema_text(name: str) -> str:
    return json.dumps(json_schema(name), indent=2, ensure_ascii=False, sort_keys=True) + "\n"


def path_of(name: str) -> Path:
    return SCHEMA_DIR / f"{name}.schema.json"


def stale() -> list[str]:
    """Contracts whose checked-in schema file differs from the model's."""
    return [n for n in CONTRACTS if not path_of(n).is_file() or path_of(n).read_text() != schema_text(n)]


def main(argv=None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if args == ["--check"]:
        names = stale()
        for n in names:
            print(f"{path_of(n)}: stale; run python -m groundstation.contracts", file=sys.stderr)
        return 1 if names else 0
    SCHEMA_DIR.mkdir(exist_ok=True)
    for n in CONTRACTS:
        path_of(n).write_text(schema_text(n))
        print(path_of(n))
    return 0


if __name__ == "__main__":
    sys.exit(main())
