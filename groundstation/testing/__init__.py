"""Harnesses whose data is known by construction, shared by the tests (``tests/``) and the benches (``bench/``),
which import them from the installed package: fix streams with their truth for the safety gates
(:mod:`.gate_streams`), ArduPilot DataFlash logs written record by record (:mod:`.dataflash_log`) and ArduPilot's
own judgement of a GPS fed over MAVLink (:mod:`.ardupilot`)."""
