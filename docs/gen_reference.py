"""The docs site's reference pages, generated from the code at every build (mkdocs-gen-files runs this).

Nothing here is copied by hand: every CLI command's ``--help`` comes from the parsers the commands
register (:data:`groundstation.cli.COMMANDS`), every configuration key with its default and unit from the
pydantic contracts' JSON Schemas (:mod:`groundstation.contracts`, :mod:`sim_fixtures.contracts`), the
status words from :data:`localizer.status.STATUSES`, GPS_INPUT field by field from the sink's own
:func:`~groundstation.runtime.gps_input.gps_input_fields`, ``positions.csv``'s columns from
:mod:`groundstation.session.positions` and the benches from their docstrings. A change in the code is a
change in the site; ``mkdocs build --strict`` fails on a broken link.
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import sys
from pathlib import Path

import mkdocs_gen_files

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # a clone's own code, whether or not skyfix is installed

#: Unit of a key by its name's ending (the project names units in keys: ``depth_m``, ``gps_input_hz``).
UNITS = (
    ("_mps2", "m/s²"),
    ("_mps", "m/s"),
    ("_m2", "m²"),
    ("_per_m", "1/m"),
    ("_mbps", "Mbit/s"),
    ("_unix", "s (UNIX)"),
    ("_deg", "°"),
    ("_ms", "ms"),
    ("_us", "µs"),
    ("_hz", "Hz"),
    ("_px", "px"),
    ("_pa", "Pa"),
    ("_s", "s"),
    ("_m", "m"),
    ("_h", "h"),
)


def write(path: str, text: str) -> None:
    """One generated file of the site (``path`` relative to docs/)."""
    with mkdocs_gen_files.open(path, "w") as f:
        f.write(text)


def unit_of(key: str) -> str:
    """The unit a key's name states, or ``""``."""
    return next((u for end, u in UNITS if key.endswith(end)), "")


def cell(text) -> str:
    """A value fit for one Markdown table cell."""
    s = str(text).replace("``", "`").replace("|", "\\|").replace("\n", " ")
    return s.replace("<", "&lt;").replace(">", "&gt;")


def code(value) -> str:
    return "`" + json.dumps(value, ensure_ascii=False).replace("|", "\\|") + "`"


# --- configuration keys from the JSON Schemas ---------------------------------------------------


def resolve(node: dict, defs: dict) -> dict:
    ref = node.get("$ref")
    return defs[ref.rsplit("/", 1)[1]] if ref else node


def type_of(node: dict, defs: dict) -> str:
    """A short type: ``number``, ``string``, one of the enum's words, ``array``, ``table``, ``or null``."""
    node = resolve(node, defs)
    if "anyOf" in node:
        return " or ".join(type_of(n, defs) for n in node["anyOf"])
    if "enum" in node:
        return " \\| ".join(code(v) for v in node["enum"])
    if "const" in node:
        return code(node["const"])
    if node.get("type") == "array":
        items = resolve(node.get("items", {}), defs)
        return "array of tables" if "properties" in items else "array"
    return "table" if "properties" in node else str(node.get("type", "any"))


def sub_table(node: dict, defs: dict) -> tuple[dict, bool] | None:
    """``(schema, is_array)`` of a key that is itself a table or an array of tables, else None."""
    node = resolve(node, defs)
    for n in node.get("anyOf", [node]):
        n = resolve(n, defs)
        if "properties" in n:
            return n, False
        if n.get("type") == "array" and "properties" in resolve(n.get("items", {}), defs):
            return resolve(n["items"], defs), True
    return None


def key_rows(schema: dict, defs: dict) -> list[str]:
    """One table row per key of a schema object: key, type, default, unit, meaning."""
    required = set(schema.get("required", ()))
    rows = []
    for key, node in schema.get("properties", {}).items():
        default = (
            "required" if key in required else code(node["default"]) if "default" in node else ""
        )
        meaning = node.get("description") or resolve(node, defs).get("description", "")
        rows.append(
            f"| `{key}` | {type_of(node, defs)} | {default} | {unit_of(key)} | {cell(meaning)} |"
        )
    return rows


def tables(schema: dict, defs: dict, name: str, level: int) -> list[str]:
    """A schema object as Markdown: its own keys, then each sub-table under its own heading."""
    out = [f"{'#' * level} {name}", ""]
    if schema.get("description"):
        out += [cell(schema["description"]), ""]
    out += ["| key | type | default | unit | meaning |", "|---|---|---|---|---|"]
    out += key_rows(schema, defs) + [""]
    for key, node in schema.get("properties", {}).items():
        sub = sub_table(node, defs)
        if sub:
            table, many = sub
            out += tables(table, defs, f"`[[{key}]]`" if many else f"`[{key}]`", level + 1)
    return out


def keys_without_flag() -> list[str]:
    """The ``skyfix run`` configuration keys that only a ``--config`` file sets."""
    from groundstation.contracts import GROUNDSTATION
    from groundstation.live import config

    parser = argparse.ArgumentParser()
    config.add_arguments(parser)
    flags = {a.dest for a in parser._actions}
    return sorted(set(GROUNDSTATION.json_schema("run-config")["properties"]) - flags)


def configuration_page() -> str:
    from groundstation.contracts import GROUNDSTATION
    from sim_fixtures.contracts import SIM_FIXTURES

    parts = {
        "run-config": (
            GROUNDSTATION,
            "`skyfix run`: the `--config` file and the flags",
            "Each key is also a flag of `skyfix run`, spelled with dashes (`fix_max_age_ms`: "
            "`--fix-max-age-ms`), except "
            + ", ".join(f"`{k}`" for k in keys_without_flag())
            + " (file only); "
            "a flag given on the command line wins over the file.",
        ),
        "calibration": (
            GROUNDSTATION,
            "`session.toml` and `--calibration`: the calibration tables",
            (
                "The tables of a session's `session.toml` (format v1, plus skyfix's own optional tables); "
                "`skyfix run --calibration FILE` reads the same tables."
            ),
        ),
        "scenario": (
            SIM_FIXTURES,
            "`skyfix sim SCENARIO.toml`: a scenario",
            "The scenarios in `sim_fixtures/scenarios/` are examples of every table.",
        ),
    }
    out = [
        "# Configuration keys",
        "",
        (
            "Every key skyfix reads, with its type, its default and its unit, generated at build time from the "
            "pydantic classes that validate them (the same ones that write the [JSON Schemas](schemas.md)). "
            "A wrong value is refused with one line naming the file, the key and the value."
        ),
        "",
    ]
    for name, (contracts, title, intro) in parts.items():
        schema = contracts.json_schema(name)
        out += [f"## {title}", "", intro, ""]
        out += tables(schema, schema.get("$defs", {}), "Top-level keys", 3)
    return "\n".join(out) + "\n"


def schemas_page() -> str:
    from groundstation.contracts import GROUNDSTATION
    from sim_fixtures.contracts import SIM_FIXTURES

    out = [
        "# JSON Schemas",
        "",
        (
            "Every contract is one typed definition (pydantic v2); its JSON Schema (draft 2020-12) is generated "
            "from it and checked in (`python -m groundstation.contracts`, `python -m sim_fixtures.contracts`; "
            "`tests/test_contracts.py` fails when a file is stale). The schemas below are built from the code "
            "with the site. The TOML contracts' schemas also serve editors: with Taplo (VS Code's Even Better "
            "TOML) a first line `#:schema /path/to/calibration.schema.json` checks a file as you type."
        ),
        "",
        "| contract | model | schema |",
        "|---|---|---|",
    ]
    bodies = []
    for contracts in (GROUNDSTATION, SIM_FIXTURES):
        for name, (model, title) in contracts.models.items():
            write(f"reference/schemas/{name}.schema.json", contracts.schema_text(name))
            path = f"{contracts.folder.relative_to(ROOT)}/{name}.schema.json"
            link = f"[{name}.schema.json](schemas/{name}.schema.json)"
            out.append(f"| {title} | `{model.__module__}.{model.__name__}` | {link} (`{path}`) |")
            bodies += [
                f"## {name}",
                "",
                f'??? note "{name}.schema.json"',
                "    ```json",
                *("    " + line for line in contracts.schema_text(name).splitlines()),
                "    ```",
                "",
            ]
    return "\n".join(out + [""] + bodies) + "\n"


# --- messages ---------------------------------------------------------------------------------------


def message_rows(schema: dict, defs: dict, prefix: str = "") -> list[str]:
    """Every key of a message, nested objects as dotted paths."""
    rows = []
    for key, node in schema.get("properties", {}).items():
        path = f"{prefix}{key}"
        meaning = node.get("description") or resolve(node, defs).get("description", "")
        rows.append(f"| `{path}` | {type_of(node, defs)} | {unit_of(key)} | {cell(meaning)} |")
        sub = sub_table(node, defs)
        if sub:
            rows += message_rows(sub[0], defs, f"{path}{'[]' if sub[1] else ''}.")
    return rows


def messages_page() -> str:
    from groundstation.contracts import GROUNDSTATION

    out = [
        "# Messages on Zenoh",
        "",
        (
            "JSON, encoding `application/json`, with a Zenoh timestamp. Each message carries `schema`, its name "
            "and major version; keys may be added within a version, so a consumer ignores keys it does not know. "
            "JSON has no NaN: a number that is not known is `null`. Generated from the message models "
            "(`groundstation/messages.py`); the [JSON Schemas](schemas.md) say the same in full."
        ),
        "",
    ]
    for name in ("fix", "status", "fuse-status"):
        schema = GROUNDSTATION.json_schema(name)
        out += [f"## {schema['title']}", "", cell(schema.get("description", "")), ""]
        out += ["| key | type | unit | meaning |", "|---|---|---|---|"]
        out += message_rows(schema, schema.get("$defs", {})) + [""]
    return "\n".join(out) + "\n"


def status_words_page() -> str:
    from localizer.status import STATUSES

    rows = [f"| `{word}` | {cell(meaning)} |" for word, meaning in STATUSES.items()]
    return (
        "\n".join(
            [
                "# Status words",
                "",
                (
                    "Every frame's fix carries `ok` or why there is no position; the fix message, `positions.csv`, the "
                    "exports and the reports use the same words. Generated from `localizer/status.py`, the one list "
                    "(a test checks the code produces no other)."
                ),
                "",
                "| status | meaning |",
                "|---|---|",
                *rows,
            ]
        )
        + "\n"
    )


# --- GPS_INPUT from the sink's code -------------------------------------------------------------------


def gps_input_page() -> str:
    from groundstation.mavlink.ids import GPS_COMPID, SKYFIX_SYSID
    from groundstation.mavlink.ingest import mavutil
    from groundstation.runtime import gps_input as sink
    from localizer.fix import Fix

    t = 1_763_800_000.033
    fix = Fix(t_unix=t, t_gnss=t - 0.002, status="ok", lat=63.4400123, lon=10.4000456)
    fix.alt_amsl_m, fix.h_acc_m, fix.v_acc_m = -1.21, 0.21, 0.31
    valid = sink.gps_input_fields(fix, t + 0.05, max_age_s=0.5)
    none = sink.gps_input_fields(None, t + 0.05, max_age_s=0.5)
    msg = mavutil().mavlink.MAVLink_gps_input_message
    units = msg.fieldunits_by_name
    types = dict(zip(msg.fieldnames, msg.fieldtypes))
    rows = [
        f"| `{f}` | {types.get(f, '')} | {units.get(f, '')} | {code(valid[f])} | {code(none[f])} |"
        for f in msg.fieldnames
    ]
    flags = [
        f"`{n}` = {getattr(sink, n)}"
        for n in dir(sink)
        if n.startswith("IGNORE_") and n != "IGNORE_ALL"
    ]
    doc = (sink.__doc__ or "").replace("``", "`")
    return (
        "\n".join(
            [
                "# GPS_INPUT field by field",
                "",
                (
                    f"skyfix sends MAVLink `GPS_INPUT` from system {SKYFIX_SYSID}, component {GPS_COMPID}. The table is "
                    "made at build time by the sink's own `gps_input_fields` "
                    f"(`{sink.__name__.replace('.', '/')}.py`) for an example fix (exposure "
                    f"`t_gnss` = {t - 0.002:.3f}, `h_acc_m` 0.21, `v_acc_m` 0.31, sent 50 ms later) and for no fix."
                ),
                "",
                "| field | MAVLink type | unit | a valid fix | no fix |",
                "|---|---|---|---|---|",
                *rows,
                "",
                "`ignore_flags` bits: "
                + ", ".join(sorted(flags, key=lambda s: int(s.rsplit(" ", 1)[1])))
                + ".",
                "",
                "## The rules, from the sink's docstring",
                "",
                doc,
            ]
        )
        + "\n"
    )


# --- the CLI ------------------------------------------------------------------------------------------


def parsers() -> list[tuple[str, argparse.ArgumentParser]]:
    """``(command line, parser)`` of every subcommand and sub-subcommand, in ``skyfix --help``'s order."""
    import importlib

    from groundstation.cli import COMMANDS

    root = argparse.ArgumentParser(prog="skyfix")
    sub = root.add_subparsers(dest="command")
    for name, module, help_line in COMMANDS:
        importlib.import_module(module).register(sub, name, help_line)
    out = []
    todo = list(sub.choices.items())
    while todo:
        name, parser = todo.pop(0)
        out.append((parser.prog, parser))
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                todo[:0] = list(action.choices.items())
    return out


def cli_page() -> str:
    from groundstation.cli import COMMANDS

    os.environ["COLUMNS"] = "100"  # argparse wraps the help at the terminal's width: make it fixed
    out = [
        "# Command line",
        "",
        (
            "Every `skyfix` command's `--help`, generated at build time from the parsers the commands register "
            "(`groundstation/cli.py`'s `COMMANDS`). Bad input gives exit code 2 and one line naming the file, "
            "the key and the value. `skyfix --version` prints the installed version."
        ),
        "",
        "| command | what it does |",
        "|---|---|",
        *(
            f"| [`skyfix {name}`](#skyfix-{name}) | {cell(help_line)} |"
            for name, _, help_line in COMMANDS
        ),
        "",
    ]
    for prog, parser in parsers():
        out += [f"## `{prog}`", "", "```text", parser.format_help().rstrip(), "```", ""]
    return "\n".join(out) + "\n"


# --- session files and benches ------------------------------------------------------------------------


def positions_page() -> str:
    from groundstation.contracts import GROUNDSTATION
    from groundstation.session.positions import COLUMNS, SPEC_COLUMNS

    fix = GROUNDSTATION.json_schema("fix")["properties"]
    rows = []
    for col in COLUMNS:
        name = "t" if col == "t" else col
        meaning = fix.get(name, {}).get("description", "")
        origin = "session format v1" if col in SPEC_COLUMNS else "skyfix"
        rows.append(f"| `{col}` | {unit_of(col)} | {origin} | {cell(meaning)} |")
    return (
        "\n".join(
            [
                "# positions.csv columns",
                "",
                (
                    "Written by `skyfix process`, `skyfix evaluate` and a recording as it goes: the session format's six "
                    "columns first, then skyfix's, with the fix message's names and meanings (generated from "
                    "`groundstation/session/positions.py` and the fix message model). Empty cells where a value is "
                    "unknown; `lat`/`lon` are empty unless `status` is `ok`. See [the session format](session-format.md)."
                ),
                "",
                "| column | unit | from | meaning |",
                "|---|---|---|---|",
                *rows,
            ]
        )
        + "\n"
    )


def first_paragraph(doc: str | None) -> str:
    return " ".join((doc or "").strip().split("\n\n")[0].split())


def bench_results(stem: str) -> list[str]:
    """The result files a bench wrote (``bench/results/STEM.*``), its text ones shown folded."""
    out = []
    for path in sorted((ROOT / "bench" / "results").glob(f"{stem}.*")):
        out.append(f'??? note "bench/results/{path.name}"')
        if path.suffix == ".txt":
            text = path.read_text(encoding="utf-8").rstrip()
            out += ["    ```text", *("    " + line for line in text.splitlines()), "    ```", ""]
        else:
            out += [f"    `{path.name}`: {path.stat().st_size} bytes, for programs to read.", ""]
    return out


def benches_page() -> str:
    out = [
        "# Benches: where the numbers are",
        "",
        (
            "Measured numbers are not written into these pages' prose: they change with the code and the machine. "
            "Each bench prints its numbers and writes them to `bench/results/`; run one with "
            "`.venv/bin/python bench/NAME.py --help` to see its options. Below, each bench's own docstring and, "
            "where this copy of the project has them, the result files it last wrote (on the machine and at the "
            "commit that ran it: run the bench again to measure yours)."
        ),
        "",
    ]
    for path in sorted((ROOT / "bench").glob("*.py")):
        doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8")))
        out += [f"## `bench/{path.name}`", "", cell(first_paragraph(doc)) or "(no docstring)", ""]
        out += bench_results(path.stem)
    return "\n".join(out) + "\n"


def rates_page() -> str:
    from groundstation.live.sources import rates

    uav = {**rates.NEEDED_HZ, "the gimbal's message": rates.GIMBAL_HZ}
    uav["DISTANCE_SENSOR (once a downward one has come)"] = rates.RANGEFINDER_HZ
    uuv = {"its depth sensor's SCALED_PRESSURE, GLOBAL_POSITION_INT": rates.DEPTH_HZ}
    uuv["SERVO_OUTPUT_RAW (the thrusters)"] = rates.THRUSTERS_HZ
    rows = [f"| the UAV | {m} | {hz:g} |" for m, hz in uav.items()]
    rows += [f"| the UUV (ArduSub) | {m} | {hz:g} |" for m, hz in uuv.items()]
    doc = (rates.__doc__ or "").replace("``", "`").replace(":data:", "")
    return (
        "\n".join(
            [
                "# Telemetry rates",
                "",
                (
                    "What skyfix needs from each autopilot and asks for when it arrives slower (generated from "
                    "`groundstation/live/sources/rates.py`)."
                ),
                "",
                "| autopilot | message | Hz |",
                "|---|---|---|",
                *rows,
                "",
                doc,
            ]
        )
        + "\n"
    )


PAGES = {
    "reference/cli.md": cli_page,
    "reference/configuration.md": configuration_page,
    "reference/schemas.md": schemas_page,
    "reference/messages.md": messages_page,
    "reference/status-words.md": status_words_page,
    "reference/gps-input.md": gps_input_page,
    "reference/positions-csv.md": positions_page,
    "reference/benches.md": benches_page,
    "reference/telemetry-rates.md": rates_page,
}

for page, make in PAGES.items():
    write(page, make())
