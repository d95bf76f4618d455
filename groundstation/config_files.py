"""Reading the TOML files skyfix is configured with: shared by the live service, the offline tools, the fuser and
the simulator (none of them imports another's module for it). A file that cannot be read is a one-line
:class:`~localizer.contract.ConfigError` naming it."""

from __future__ import annotations

import logging
import tomllib
from pathlib import Path

from localizer.calibration import Calibration
from localizer.contract import ConfigError

log = logging.getLogger("skyfix.config")


def read_toml(path) -> dict:
    """A TOML file's contents, or :class:`ConfigError` naming the file."""
    try:
        return tomllib.loads(Path(path).read_text())
    except OSError as e:
        raise ConfigError(
            str(path), "(file)", str(path), f"cannot read: {e.strerror or e}"
        ) from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise ConfigError(str(path), "(file)", str(path), f"malformed TOML: {e}") from None


def load_calibration(path: str) -> Calibration:
    """The calibration tables of a TOML file (session.toml or a calibration-only file); warnings logged."""
    cal = Calibration.from_dict(read_toml(path), source=path)
    for warning in cal.warnings:
        log.warning("%s", warning)
    return cal
