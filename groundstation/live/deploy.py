"""``skyfix deploy``: the deployment files shipped with skyfix (the source tree's ``deploy/``), printed or copied.

``skyfix deploy unit`` prints the systemd unit (``skyfix.service``), ``skyfix deploy config [field|calibration]``
the example run configuration or calibration, ``skyfix deploy zenoh [NAME]`` the Zenoh configurations (without a
NAME: their names and first lines), ``skyfix deploy certs`` the script that makes the team's Zenoh certificates;
``skyfix deploy all --out DIR`` copies every file into DIR (field.toml's relative paths then hold). So an
installed wheel needs no source checkout: ``skyfix deploy unit | sudo tee /etc/systemd/system/skyfix.service``.
"""

from __future__ import annotations

import shutil
import sys
from importlib import resources
from importlib.resources.abc import Traversable
from pathlib import Path

#: ``skyfix deploy WORD`` -> the file it prints (``config`` and ``zenoh`` take a name: :data:`CONFIGS`, the
#: Zenoh folder's files)
FILES = {"unit": "skyfix.service", "certs": "make_certs.sh"}
CONFIGS = {"field": "field.toml", "calibration": "calibration.toml"}
ZENOH = "zenoh"


def deploy_files() -> Traversable:
    """The deployment files: the data package ``groundstation.deploy`` of an installed wheel, or the top-level
    ``deploy/`` folder of a source checkout (an editable install, which maps no data package)."""
    try:
        return resources.files("groundstation.deploy")
    except ModuleNotFoundError:
        return Path(__file__).resolve().parents[2] / "deploy"


def zenoh_names(root: Traversable) -> dict[str, Traversable]:
    """The Zenoh files by the name ``skyfix deploy zenoh NAME`` takes (the file's name without ``.json5``)."""
    files = sorted((f for f in root.joinpath(ZENOH).iterdir() if f.is_file()), key=lambda f: f.name)
    return {f.name.removesuffix(".json5"): f for f in files}


def first_line(f: Traversable) -> str:
    """A file's first line without its comment marker (``//`` or ``#``)."""
    lines = f.read_text().splitlines()
    return lines[0].lstrip("/# ").strip() if lines else ""


def copy_all(root: Traversable, out: Path) -> list[Path]:
    """Every deployment file copied into ``out`` (made if missing) under its own relative path; an existing file
    is never overwritten (:class:`FileExistsError` names it, before anything is copied)."""
    pairs = []

    def walk(node: Traversable, rel: Path) -> None:
        for child in sorted(node.iterdir(), key=lambda c: c.name):
            if child.is_dir():
                if child.name != "__pycache__":
                    walk(child, rel / child.name)
            else:
                pairs.append((child, out / rel / child.name))

    walk(root, Path())
    taken = [dst for _, dst in pairs if dst.exists()]
    if taken:
        raise FileExistsError(f"{taken[0]} exists: not overwritten (another --out, or remove it)")
    for src, dst in pairs:
        dst.parent.mkdir(parents=True, exist_ok=True)
        with resources.as_file(src) as path:
            shutil.copy(path, dst)
    return [dst for _, dst in pairs]


def run(args) -> int:
    root = deploy_files()
    if args.what == "all":
        try:
            copied = copy_all(root, Path(args.out))
        except FileExistsError as e:
            print(f"skyfix deploy: error: {e}", file=sys.stderr)
            return 2
        for path in copied:
            print(path)
        return 0
    if args.what == ZENOH:
        names = zenoh_names(root)
        if args.name is None:
            width = max(map(len, names))
            for name, f in names.items():
                print(f"{name:<{width}}  {first_line(f)}")
            return 0
        f = names[args.name]
    elif args.what == "config":
        f = root.joinpath(CONFIGS[args.name or "field"])
    else:
        f = root.joinpath(FILES[args.what])
    sys.stdout.write(f.read_text())
    return 0


def register(subparsers, name: str, help: str | None = None) -> None:
    """Adds the subcommand ``name`` with its one-line ``help`` (both from :data:`groundstation.cli.COMMANDS`)."""
    p = subparsers.add_parser(
        name,
        help=help,
        description="Prints a deployment file shipped with skyfix (redirect it where it goes), or copies them "
        "all into a folder.",
    )
    words = p.add_subparsers(dest="what", required=True, metavar="WHAT")
    words.add_parser("unit", help="the systemd unit: skyfix run --config /etc/skyfix/field.toml")
    words.add_parser("certs", help="the script that makes the team's Zenoh certificates")
    config = words.add_parser(
        "config", help="an example configuration: field (default) or calibration"
    )
    config.add_argument("name", nargs="?", choices=CONFIGS, metavar="field|calibration")
    zenoh = words.add_parser("zenoh", help="a Zenoh configuration by NAME; without NAME: the names")
    zenoh.add_argument("name", nargs="?", choices=list(zenoh_names(deploy_files())), metavar="NAME")
    everything = words.add_parser("all", help="copy every deployment file into --out DIR")
    everything.add_argument("--out", required=True, metavar="DIR", help="folder to copy them into")
    p.set_defaults(func=run)
