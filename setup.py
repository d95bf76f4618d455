"""The two things pyproject.toml cannot say: the top-level ``deploy/`` folder ships in the wheel as the data
package ``groundstation.deploy`` (``skyfix deploy`` prints its files); and the build fetches the page's map
library, Leaflet, from the npm registry (pinned version, its sha512 integrity checked:
``groundstation/live/ui/vendor.py``) into the package data it ships. Everything else is in pyproject.toml."""

import importlib.util
from pathlib import Path

from setuptools import find_namespace_packages, setup
from setuptools.command.build_py import build_py

DEPLOY = {"groundstation.deploy": "deploy", "groundstation.deploy.zenoh": "deploy/zenoh"}


class BuildWithLeaflet(build_py):
    """``build_py`` after fetching Leaflet into ``groundstation/live/ui/static/vendor/`` (unless it is there)."""

    def run(self):
        path = Path(__file__).parent / "groundstation" / "live" / "ui" / "vendor.py"
        spec = importlib.util.spec_from_file_location("skyfix_vendor", path)
        vendor = importlib.util.module_from_spec(spec)
        # standard library only: skyfix's dependencies are not installed yet
        spec.loader.exec_module(vendor)
        vendor.fetch()
        super().run()


setup(
    packages=[
        *find_namespace_packages(
            include=["localizer*", "groundstation*", "sim_fixtures*"], exclude=["*__pycache__*"]
        ),
        *DEPLOY,
    ],
    package_dir=DEPLOY,
    cmdclass={"build_py": BuildWithLeaflet},
)
