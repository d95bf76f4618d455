"""Parts by name, for the live service and the fuser: one way to plug in a source or an output (as MAVProxy's
modules, BlueOS's services).

A part is a :class:`Worker` (``async run()`` and ``status(now)``); a :class:`Source` also hands each accepted
input to its ``listeners`` (the recorder); a :class:`Sink` takes each fix (``on_fix(fix, info)``); an
:class:`Output` is a worker and a sink. A worker is started by running ``run()`` as a task of the service's
TaskGroup and stopped by cancelling that task, stage by stage (:class:`~groundstation.runtime.workers.Workers`): a
blocked read never holds the stop.

The parts a configuration chooses by name are registered here, one kind each (:data:`KINDS`): ``depth`` and
``uav`` (the live service's inputs: :mod:`groundstation.live.registry`, which adds its sources' package to
:data:`BUILTIN` and defines their inputs) and ``output`` (where a UUV's fixes go, built from an
:class:`OutputInput`: the live service's ``outputs`` and the fuser's).

A part is registered by its module: ``@register("output", "NAME", help="...")`` on a function that builds it.
skyfix's own parts are the modules of :data:`BUILTIN`'s packages (the outputs: :mod:`groundstation.runtime.outputs`);
another distribution's are the modules named by its entry points in the group :data:`ENTRY_POINTS`
(``[project.entry-points."skyfix.parts"]`` in its pyproject.toml: ``NAME = "its_module"``), imported once when
the choices are first asked for. So a new depth source or output is one module and its registration: the
configuration's choices (``depth_source``'s and ``outputs``' values, the flags' ``--help``, the JSON Schema's
enums) are :func:`choices`, and the services build the ones chosen by :func:`part`'s ``build``.

A part has settings of its own: the configuration's table ``[parts.NAME]`` (one UUV) or ``[uuv.parts.NAME]``
(each ``[[uuv]]`` table), handed to it as its input's ``settings`` (:func:`settings`). A part registered with
``settings=T`` (a pydantic dataclass with ``config=CLOSED``) gets a ``T`` checked at start (a bad, missing or
unknown key is a one-line error naming the file, ``parts.NAME.KEY`` and the value); without, the table as
written, read-only.
"""

from __future__ import annotations

import importlib
import importlib.util
import pkgutil
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from importlib.metadata import entry_points
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

from localizer.contract import ConfigError, Invalid, validate

if TYPE_CHECKING:
    import zenoh

    from localizer.fix_gate import FixGate

KINDS = ("depth", "uav", "output")
ENTRY_POINTS = "skyfix.parts"
#: each kind's packages whose modules register skyfix's own parts (the live service adds its sources': depth, uav)
BUILTIN: dict[str, list[str]] = {
    "depth": [],
    "uav": [],
    "output": ["groundstation.runtime.outputs"],
}


@runtime_checkable
class Worker(Protocol):
    """A part the service runs: ``run()`` until cancelled (its start and its stop), ``status(now)`` its section."""

    async def run(self) -> None: ...

    def status(self, now: float) -> dict: ...


@runtime_checkable
class Source(Worker, Protocol):
    """An input: a worker whose ``listeners`` get ``(sample, t_recv)`` of each input it accepted."""

    listeners: list[Callable[..., None]]


@runtime_checkable
class Sink(Protocol):
    """An output: each fix (:class:`~localizer.fix.Fix`) with its frame's info, on the event loop."""

    def on_fix(self, fix: Any, info: Any) -> None: ...


@runtime_checkable
class Output(Worker, Sink, Protocol):
    """Where a UUV's fixes go: ``on_fix`` takes each of them on the event loop (``fix.ok``: a valid fix; else
    ``fix.status`` says why there is none), ``run()`` from its start (open its link) until cancelled (its stop:
    close it, say "no fix" last where the reader needs it), ``status(now)`` its state. Outputs stop last, once the
    pipeline that feeds them has stopped."""


@dataclass(frozen=True)
class OutputInput:
    """What an output is built from: the name it is registered as, the UUV's options (its keys and links: the live
    service's :class:`~groundstation.live.config.UuvConfig`, the fuser's arguments: ``fix_key``, ``gps_input``,
    ``gps_input_signing_key``), the run's (``gps_input_hz``, ``fix_max_age_ms``, ...), the Zenoh session, the
    UUV's safety gates (:class:`~localizer.fix_gate.FixGate`: for the output that sends the fixes to the UUV's
    autopilot; the live service's, which the operator's confirmation and the kept track reach, None when the UUV has
    no ``gps_input``; the fuser's own), and its settings (:func:`settings`). An output that gates the fixes
    otherwise makes a gate of its own (a gate follows one stream of fixes)."""

    name: str
    options: Any
    run: Any
    session: zenoh.Session
    gate: FixGate | None
    settings: Any


@dataclass(frozen=True)
class Part:
    """A registered part: its kind and name, the function that builds it, its one-line help; ``thrusters``: it
    reads the UUV's thruster outputs too (the fix gate's second source of motion); ``needs``: the module it
    imports when it runs and the pip requirement that brings it (an optional extra); ``section``: an output's
    status section of its own (else its status is the status's ``outputs.NAME``); ``settings``: the type of its
    table ``[parts.NAME]`` (None: the table as written). An output's ``build`` may return None: nothing to send for
    this UUV (``gps_input`` without a link)."""

    kind: str
    name: str
    build: Callable[[Any], Worker | None]
    help: str
    thrusters: bool = False
    needs: tuple[str, str] | None = None
    section: str | None = None
    settings: type | None = None

    def missing(self) -> str | None:
        """What to install when the module it needs is missing (one line), else None."""
        if self.needs and importlib.util.find_spec(self.needs[0]) is None:
            return f"needs {self.needs[0]}: pip install '{self.needs[1]}'"
        return None


_parts: dict[str, dict[str, Part]] = {kind: {} for kind in KINDS}
_imported: set[str] = set()  # the BUILTIN packages imported
_loaded = False  # the entry points


def register(
    kind: str,
    name: str,
    help: str,
    thrusters: bool = False,
    needs: tuple[str, str] | None = None,
    section: str | None = None,
    settings: type | None = None,
) -> Callable:
    """Decorator: the function builds the part ``name`` of ``kind`` (from a :class:`~groundstation.live.registry.DepthInput`,
    :class:`~groundstation.live.registry.UavInput` or :class:`OutputInput`; its settings of type ``settings``). A name taken twice is an error
    naming both modules."""
    if kind not in KINDS:
        raise ValueError(f"part kind {kind!r}: expected one of {', '.join(KINDS)}")

    def decorate(build: Callable) -> Callable:
        taken = _parts[kind].get(name)
        if taken is not None and taken.build is not build:
            raise ValueError(
                f"{kind} part {name!r} registered twice: {taken.build.__module__} and {build.__module__}"
            )
        _parts[kind][name] = Part(kind, name, build, help, thrusters, needs, section, settings)
        return build

    return decorate


def builtin(package: str, *kinds: str) -> None:
    """``package``'s modules register skyfix's own parts of ``kinds`` (imported when those are first asked for)."""
    for kind in kinds:
        if package not in BUILTIN[kind]:
            BUILTIN[kind].append(package)


def _load(kind: str) -> None:
    """Import the modules that register parts of ``kind``: skyfix's own (each package once; all kinds' the first
    time, so that they come before another distribution's), then the entry points' (once)."""
    global _loaded
    for k in (kind,) if _loaded else KINDS:
        for name in BUILTIN[k]:
            if name not in _imported:
                _imported.add(name)
                package = importlib.import_module(name)
                for module in pkgutil.iter_modules(package.__path__, f"{name}."):
                    importlib.import_module(module.name)
    if _loaded:
        return
    _loaded = True
    for ep in entry_points(group=ENTRY_POINTS):
        try:
            ep.load()
        except Exception as e:  # another distribution's module: one line naming it
            raise ConfigError(
                f"entry point {ENTRY_POINTS}", ep.name, ep.value, f"cannot import: {e}"
            ) from e


def parts(kind: str) -> dict[str, Part]:
    """The registered parts of ``kind`` by name, in registration order."""
    _load(kind)
    return dict(_parts[kind])


def choices(kind: str) -> tuple[str, ...]:
    """The names a configuration may choose for ``kind``."""
    return tuple(parts(kind))


def part(kind: str, name: str) -> Part:
    """The part registered as ``name`` (the configuration has checked the name is one of :func:`choices`)."""
    return parts(kind)[name]


def described(kind: str) -> str:
    """Each part's name and help, for a configuration key's description: ``name: help; name: help``."""
    return "; ".join(f"{p.name}: {p.help}" for p in parts(kind).values())


def settings(part: Part, table: Mapping[str, Any]) -> Any:
    """The part's settings from its table in the configuration (``[parts.NAME]``, empty when there is none): a
    ``part.settings`` checked, else the table as written, read-only. A bad key or value raises
    :class:`~localizer.contract.Invalid` naming ``parts.NAME.KEY`` and the value (the configuration's check)."""
    if part.settings is None:
        return MappingProxyType(dict(table))
    try:
        return validate(part.settings, dict(table), "parts")
    except ConfigError as e:
        raise Invalid(f"parts.{part.name}.{e.key}", e.value, e.why) from None
