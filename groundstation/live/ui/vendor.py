"""The page's map library, Leaflet, vendored from the npm registry at build time (not kept in git).

The package build (``setup.py``'s ``build_py``) and ``./dev setup`` call :func:`fetch`: it downloads the pinned
release's tarball from the npm registry (:data:`TARBALL`), checks it against the registry's ``sha512`` integrity
(:data:`INTEGRITY`, the ``dist.integrity`` of ``npm view leaflet@VERSION``) and unpacks the files the page loads
(:data:`FILES`, the ``images/`` folder and the licence) into ``static/vendor/leaflet/``, from where the page's server
serves them and the wheel ships them: the page fetches nothing from the internet at run time. Without a network,
``SKYFIX_LEAFLET_TGZ`` names the tarball on disk (checked the same way).

Standard library only: ``setup.py`` loads this file before skyfix's dependencies are installed.
``python -m groundstation.live.ui.vendor`` fetches into the source tree (what ``./dev setup`` runs).
"""

from __future__ import annotations

import base64
import hashlib
import io
import os
import sys
import tarfile
import urllib.request
from pathlib import Path

VERSION = "1.9.4"
TARBALL = f"https://registry.npmjs.org/leaflet/-/leaflet-{VERSION}.tgz"
INTEGRITY = "sha512-nxS1ynzJOmOlHp+iL3FyWqK89GtNL8U8rvlMOsQdTTssxZwCXh8N2NB3GDQOL+YR3XnWyZAxwQixURb+FA74PA=="
FILES = ("dist/leaflet.js", "dist/leaflet.css", "LICENSE")  # and dist/images/*
ENV = "SKYFIX_LEAFLET_TGZ"
TIMEOUT_S = 60.0
#: where the page's server finds it (and the wheel ships it): package data of groundstation
DEST = Path(__file__).parent / "static" / "vendor" / "leaflet"


class VendorError(RuntimeError):
    """Leaflet could not be fetched or did not match its integrity; one line saying which and why."""


def check_integrity(data: bytes, integrity: str = INTEGRITY) -> None:
    """VendorError unless ``data``'s SHA-512 is the npm registry's ``integrity`` (``sha512-<base64>``)."""
    algo, _, want = integrity.partition("-")
    got = base64.b64encode(hashlib.new(algo, data).digest()).decode()
    if got != want:
        raise VendorError(
            f"leaflet-{VERSION}.tgz: {algo} {got} is not the registry's integrity {want}"
        )


def download() -> bytes:
    """The tarball's bytes: from ``$SKYFIX_LEAFLET_TGZ`` if set, else from the npm registry."""
    local = os.environ.get(ENV)
    if local:
        try:
            return Path(local).read_bytes()
        except OSError as e:
            raise VendorError(f"{ENV}={local}: {e.strerror or e}") from None
    try:
        with urllib.request.urlopen(TARBALL, timeout=TIMEOUT_S) as response:
            return response.read()
    except OSError as e:
        raise VendorError(
            f"could not fetch {TARBALL}: {getattr(e, 'reason', None) or e} "
            f"(offline: set {ENV} to that tarball)"
        ) from None


def is_present(dest: Path = DEST) -> bool:
    """Whether ``dest`` holds this version's files."""
    return (dest / "VERSION").is_file() and (dest / "VERSION").read_text().strip() == VERSION


def unpack(data: bytes, dest: Path) -> list[Path]:
    """The page's files of the tarball ``data`` written under ``dest``; the paths written."""
    written = []
    with tarfile.open(fileobj=io.BytesIO(data), mode="r:gz") as tar:
        for member in tar.getmembers():
            name = member.name.removeprefix("package/")
            keep = name in FILES or (name.startswith("dist/images/") and name.endswith(".png"))
            if not (keep and member.isfile()):
                continue
            path = dest / name.removeprefix("dist/")
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(tar.extractfile(member).read())
            written.append(path)
    missing = [f for f in FILES if dest / f.removeprefix("dist/") not in written]
    if missing:
        raise VendorError(f"leaflet-{VERSION}.tgz: no {', '.join(missing)} in it")
    (dest / "VERSION").write_text(VERSION + "\n")
    return written


def fetch(dest: Path = DEST) -> bool:
    """Leaflet's page files under ``dest`` (downloaded and checked unless this version is there); True if fetched."""
    if is_present(dest):
        return False
    data = download()
    check_integrity(data, INTEGRITY)
    unpack(data, dest)
    return True


if __name__ == "__main__":
    try:
        fetched = fetch()
    except VendorError as e:
        sys.exit(f"leaflet: {e}")
    print(f"leaflet {VERSION}: {'fetched into' if fetched else 'already in'} {DEST}")
