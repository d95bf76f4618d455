"""The contracts' JSON Schema files: current, valid, and in agreement with the models they come from.

jsonschema (an independent validator) checks the shipped TOML files and hand-made bad ones against
the generated schemas, and the models must say the same; fix messages of real fixes validate; and
every status word the code can produce is in the enumeration the fix schema publishes.
"""

from __future__ import annotations

import ast
import copy
import json
import math
import tomllib
from pathlib import Path

import pytest
from jsonschema import Draft202012Validator

from groundstation.contracts import GROUNDSTATION
from groundstation.live.config import RunConfig
from groundstation.messages import FixMessage
from localizer.calibration import Calibration
from localizer.contract import ConfigError, validate
from localizer.fix import Fix
from localizer.status import STATUSES
from sim_fixtures.contracts import SIM_FIXTURES
from sim_fixtures.scenario import scenario_from_dict

ROOT = Path(__file__).resolve().parents[1]
OWNER = {
    name: contracts for contracts in (GROUNDSTATION, SIM_FIXTURES) for name in contracts.models
}


def validator(name: str) -> Draft202012Validator:
    return Draft202012Validator(json.loads(OWNER[name].path_of(name).read_text()))


@pytest.mark.parametrize("contracts", [GROUNDSTATION, SIM_FIXTURES], ids=lambda c: c.module)
def test_schema_files_are_current(contracts):
    assert contracts.stale() == [], (
        f"stale schema files: run `.venv/bin/python -m {contracts.module}` and commit them"
    )


def test_the_groundstation_does_not_import_the_simulator():
    """The layers: sim_fixtures may use groundstation, never the other way (the scenario's contract is its own)."""
    offenders = [
        str(p.relative_to(ROOT))
        for p in (ROOT / "groundstation").rglob("*.py")
        if any(
            isinstance(node, (ast.Import, ast.ImportFrom))
            and any(
                n.startswith("sim_fixtures")
                for n in (
                    [node.module or ""]
                    if isinstance(node, ast.ImportFrom)
                    else [a.name for a in node.names]
                )
            )
            for node in ast.walk(ast.parse(p.read_text()))
        )
    ]
    assert offenders == []


@pytest.mark.parametrize("name", OWNER)
def test_schemas_are_valid_draft_2020_12(name):
    Draft202012Validator.check_schema(json.loads(OWNER[name].schema_text(name)))


SHIPPED = (
    [("scenario", p) for p in sorted((ROOT / "sim_fixtures" / "scenarios").glob("*.toml"))]
    + [
        ("calibration", p)
        for p in sorted((ROOT / "sim_fixtures" / "bundled").glob("*/session.toml"))
    ]
    + [
        ("calibration", ROOT / "deploy" / "calibration.toml"),
        ("run-config", ROOT / "deploy" / "field.toml"),
    ]
)


@pytest.mark.parametrize(
    "name, path", SHIPPED, ids=lambda x: x if isinstance(x, str) else f"{x.parent.name}/{x.name}"
)
def test_shipped_files_validate_against_their_schema(name, path):
    errors = [e.message for e in validator(name).iter_errors(tomllib.loads(path.read_text()))]
    assert not errors, f"{path}: {errors}"


CAL = tomllib.loads((ROOT / "deploy" / "calibration.toml").read_text())


def _set(data: dict, path: str, value) -> dict:
    data = copy.deepcopy(data)
    *tables, key = path.split(".")
    t = data
    for name in tables:
        t = t.setdefault(name, {})
    t[key] = value
    return data


BAD = [  # (contract, data) that both the schema and the model must refuse
    ("calibration", _set(CAL, "camera.fy", -1.0)),
    ("calibration", _set(CAL, "camera.width", 1920.5)),
    ("calibration", _set(CAL, "camera.distortion", [0.1, 0.2])),
    ("calibration", _set(CAL, "mount.attitude_source", "gimbal")),
    ("calibration", _set(CAL, "water.surface_amsl_m", 0.3)),  # both water references
    ("calibration", _set(CAL, "uncertainty.pixel_sigma", 2.0)),  # unknown key in skyfix's own table
    ("calibration", _set(CAL, "timing.depth_hold_s", 0)),
    ("run-config", {"calibration": "c.toml", "gps_input_hz": 4}),
    ("run-config", {"calibration": "c.toml", "tracker": "goturn"}),
    ("run-config", {"calibration": "c.toml", "mavlnk": "x"}),
    ("run-config", {"mavlink": "udpin:0.0.0.0:14550"}),  # no calibration
    ("scenario", {"name": "x", "telemetry": {"attitude_hz": 0}}),
    ("scenario", {"name": "x", "uav": {"gnss_fix_type": 9}}),
    ("scenario", {"name": "x", "mount": {"kind": "gimbal"}}),
    ("scenario", {"seed": 3}),
]
MODELS = {
    "calibration": Calibration.from_dict,
    "run-config": lambda d, s: validate(RunConfig, d, s),
    "scenario": scenario_from_dict,
}


@pytest.mark.parametrize("name, data", BAD, ids=[f"{n}-{i}" for i, (n, _) in enumerate(BAD)])
def test_schema_and_model_refuse_the_same(name, data):
    assert list(validator(name).iter_errors(data)), "the schema accepts it"
    with pytest.raises(ConfigError):
        MODELS[name](data, "x.toml")


def _fix(status: str, **kw) -> Fix:
    base = {
        "t_unix": 1_763_800_000.033,
        "status": status,
        "frame": 12,
        "u": 321.5,
        "v": 180.25,
        "confidence": 0.93,
        "depth_m": 1.2,
        "t_gnss": 1_763_800_000.031,
    }
    if status == "ok":
        base.update(
            lat=63.44001,
            lon=10.40002,
            alt_amsl_m=-0.8,
            alt_ellipsoid_m=39.2,
            h_acc_m=0.21,
            v_acc_m=0.31,
            sigma_n_m=0.15,
            sigma_e_m=0.148,
            cov_ne_m2=-0.002,
            north_m=1.3,
            east_m=-0.4,
        )
    return Fix(**{**base, **kw})


@pytest.mark.parametrize("status", STATUSES)
def test_fix_messages_of_every_status_validate(status):
    msg = FixMessage.of(_fix(status, lat=63.4 if status != "ok" else 63.44001))
    data = json.loads(json.dumps(msg.to_json(), allow_nan=False))
    assert not list(validator("fix").iter_errors(data))
    assert data["schema"] == "skyfix.fix/1" and data["status"] == status
    assert (data["lat"] is None) == (status != "ok")


def test_fix_message_carries_every_field_of_the_fix():
    data = FixMessage.of(_fix("ok")).to_json()
    fix = _fix("ok")
    names = {k for k in vars(fix) if k != "t_unix"}
    assert names <= set(data), names - set(data)
    assert (
        data["t"] == fix.t_unix and data["alt_ellipsoid_m"] == 39.2 and data["cov_ne_m2"] == -0.002
    )
    unknown = FixMessage.of(_fix("ok", alt_ellipsoid_m=math.nan, t_gnss=math.nan)).to_json()
    assert (
        unknown["alt_ellipsoid_m"] is None
        and unknown["t_gnss"] is None
        and unknown["alt_amsl_m"] == -0.8
    )


@pytest.mark.parametrize(
    "change",
    [
        {"status": "ok", "lat": None},
        {"status": "lost", "lat": 63.4, "lon": 10.4},
        {"status": "gone"},
        {"h_acc_m": -0.1},
        {"schema": "skyfix.fix/2"},
        {"extra": 1},
        {"lat": 91.0},
    ],
)
def test_the_fix_schema_refuses_what_the_contract_forbids(change):
    data = {**FixMessage.of(_fix("ok")).to_json(), **change}
    assert list(validator("fix").iter_errors(data))


def _status_words_in_code() -> set[str]:
    """String constants the code gives as a status: ``TrackResult("x")``, ``Fix(t, "x")``,
    ``status[...] = "x"``, ``status = np.full(n, "x")``, and ``_mark(status, s, "x")`` (no_x, stale_x)."""
    words = set()

    def consts(
        node,
    ):  # string constants in an expression, but not the parts of an f-string (see _mark)
        if isinstance(node, ast.JoinedStr):
            return set()
        if isinstance(node, ast.Constant):
            return {node.value} if isinstance(node.value, str) else set()
        return set().union(*(consts(child) for child in ast.iter_child_nodes(node)))

    def name_of(node):
        return (
            node.id
            if isinstance(node, ast.Name)
            else node.attr
            if isinstance(node, ast.Attribute)
            else ""
        )

    for path in [*(ROOT / "localizer").rglob("*.py"), *(ROOT / "groundstation").rglob("*.py")]:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call):
                func = name_of(node.func)
                if func == "TrackResult" and node.args:
                    words |= consts(node.args[0])
                elif func == "Fix" and len(node.args) > 1:
                    words |= consts(node.args[1])
                elif func == "_mark" and len(node.args) > 2:
                    words |= {f"{k}_{w}" for w in consts(node.args[2]) for k in ("no", "stale")}
                words |= {
                    consts(k.value).pop()
                    for k in node.keywords
                    if k.arg == "status"
                    and isinstance(k.value, ast.Constant)
                    and func in ("Fix", "TrackResult")
                }
            elif isinstance(node, ast.Assign):
                for target in node.targets:
                    if isinstance(target, ast.Subscript) and "status" in name_of(target.value):
                        words |= consts(node.value)
                    elif (
                        "status" in name_of(target)
                        and isinstance(node.value, ast.Call)
                        and name_of(node.value.func) == "full"
                    ):
                        words |= consts(node.value.args[1])
    return words


def test_every_status_word_the_code_produces_is_enumerated():
    words = _status_words_in_code()
    assert {
        "lost",
        "no_water",
        "bad_pixel",
        "stale_depth",
        "no_gimbal",
        "awaiting_target",
        "before_init",
    } <= words
    assert words <= set(STATUSES), f"add to localizer/status.py: {sorted(words - set(STATUSES))}"
