"""Synthetic sessions with ground truth: scenarios, the renderer, the telemetry writer, bundled fixtures.

``skyfix sim SCENARIO.toml --out DIR`` (:mod:`sim_fixtures.cli`) writes a session
in format v1; ``python -m sim_fixtures.bundle`` regenerates ``bundled/``;
``bench/sim.py`` measures the generator's speed.
"""
