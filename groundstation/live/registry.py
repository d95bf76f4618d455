"""The live service's parts by name: its inputs' (``depth``: the UUV's depth, ``depth_source``, built from a
:class:`DepthInput`; ``uav``: the UAV's telemetry, ``mavlink_backend``, built from a :class:`UavInput`, the modules
of :mod:`groundstation.live.sources`) and the outputs (``outputs``, built from an
:class:`~groundstation.runtime.parts.OutputInput`, shared with the fuser).

The registry itself, the protocols and the outputs are :mod:`groundstation.runtime.parts` (the live service and the
fuser both use them); its names are importable from here too, as plug-ins written for the live service import them
(``from groundstation.live.registry import OutputInput, register``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from groundstation.runtime.parts import (
    ENTRY_POINTS,
    KINDS,
    Output,
    OutputInput,
    Part,
    Sink,
    Source,
    Worker,
    builtin,
    choices,
    described,
    part,
    parts,
    register,
    settings,
)

if TYPE_CHECKING:
    import zenoh

    from groundstation.live.config import RunConfig, UuvConfig
    from localizer.calibration import Calibration
    from localizer.depth import DepthGate
    from localizer.telemetry import Telemetry
    from localizer.thrusters import Thrusters

__all__ = [
    "ENTRY_POINTS",
    "KINDS",
    "DepthInput",
    "Output",
    "OutputInput",
    "Part",
    "Sink",
    "Source",
    "UavInput",
    "Worker",
    "choices",
    "described",
    "part",
    "parts",
    "register",
    "settings",
]

builtin("groundstation.live.sources", "depth", "uav")


@dataclass(frozen=True)
class DepthInput:
    """What a depth source is built from: the UUV's options, the Zenoh session, the UUV's telemetry (the source
    adds each depth to it; a depth added without a source word records ``name``), the gate every sample passes,
    the depth's 1-sigma (m, the calibration's), for a part registered with ``thrusters=True`` the thrusters the fix
    gate reads, the name it is registered as and its settings (:func:`settings`)."""

    options: UuvConfig
    session: zenoh.Session
    tel: Telemetry
    gate: DepthGate
    sigma_m: float
    thrusters: Thrusters | None
    name: str
    settings: Any


@dataclass(frozen=True)
class UavInput:
    """What the UAV's telemetry source is built from: the run's options, the calibration and the telemetry."""

    cfg: RunConfig
    cal: Calibration
    tel: Telemetry
