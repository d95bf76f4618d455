"""JSON Schema files of every contract, generated from the models: ``groundstation/schemas/*.schema.json``.

``python -m groundstation.contracts`` rewrites them; ``--check`` exits 1 when a checked-in
file differs from what the models say (``tests/test_contracts.py`` does the same).
The TOML contracts' schemas also serve editors: Taplo (VS Code's Even Better TOML)
validates a file that starts with ``#:schema ./calibration.schema.json``.

:class:`Contracts` is a set of models and the folder of their schema files; the
groundstation's are :data:`GROUNDSTATION`. The generated scenarios' contract is
``sim_fixtures``'s own (``sim_fixtures/contracts.py``, the same class): nothing here
imports the simulator.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path

from groundstation.live.config import RunConfig
from groundstation.messages import FixMessage, FuseStatusMessage, StatusMessage
from localizer.calibration import Calibration
from localizer.contract import adapter

DRAFT = "https://json-schema.org/draft/2020-12/schema"


@dataclass(frozen=True)
class Contracts:
    """Models (file stem → (model, title)), the folder of their schema files, and the module that rewrites them."""

    models: dict
    folder: Path
    module: str

    def json_schema(self, name: str) -> dict:
        """The JSON Schema of contract ``name``."""
        model, title = self.models[name]
        schema = adapter(model).json_schema(by_alias=True)
        return {"$schema": DRAFT, "$id": f"urn:skyfix:schema:{name}", **schema, "title": title}

    def schema_text(self, name: str) -> str:
        return (
            json.dumps(self.json_schema(name), indent=2, ensure_ascii=False, sort_keys=True) + "\n"
        )

    def path_of(self, name: str) -> Path:
        return self.folder / f"{name}.schema.json"

    def stale(self) -> list[str]:
        """Contracts whose checked-in schema file differs from the model's."""
        return [
            n
            for n in self.models
            if not self.path_of(n).is_file() or self.path_of(n).read_text() != self.schema_text(n)
        ]

    def main(self, argv=None) -> int:
        """Rewrite the files; ``--check``: exit 1 naming the stale ones."""
        args = sys.argv[1:] if argv is None else argv
        if args == ["--check"]:
            names = self.stale()
            for n in names:
                print(f"{self.path_of(n)}: stale; run python -m {self.module}", file=sys.stderr)
            return 1 if names else 0
        self.folder.mkdir(exist_ok=True)
        for n in self.models:
            self.path_of(n).write_text(self.schema_text(n))
            print(self.path_of(n))
        return 0


GROUNDSTATION = Contracts(
    {
        "fix": (FixMessage, "skyfix fix message (Zenoh, JSON)"),
        "status": (StatusMessage, "skyfix status message (Zenoh, JSON)"),
        "fuse-status": (FuseStatusMessage, "skyfix fuse status message (Zenoh, JSON)"),
        "calibration": (Calibration, "skyfix calibration: the session.toml v1 tables (TOML)"),
        "run-config": (RunConfig, "skyfix run options: the --config file (TOML)"),
    },
    Path(__file__).parent / "schemas",
    "groundstation.contracts",
)


if __name__ == "__main__":
    sys.exit(GROUNDSTATION.main())
