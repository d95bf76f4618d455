"""Harnesses whose data is known by construction, shared by the tests (``tests/``) and the benches (``bench/``),
which import them from the installed package: fix streams with their truth for the safety gates
(:mod:`.gate_streams`, :mod:`.careful_gates`), a station clock stepped against GNSS time (:mod:`.gnss_clock`),
ArduPilot DataFlash logs written record by record (:mod:`.dataflash_log`), ArduPilot's own judgement of a GPS fed
over MAVLink (:mod:`.ardupilot`), and the live service's and the fuser's harnesses on loopback (:mod:`.live`,
:mod:`.supervisor`, :mod:`.link_scenarios`, :mod:`.fuse_peers`), which run from a checkout."""
