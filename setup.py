"""The one thing pyproject.toml cannot say: the top-level ``deploy/`` folder ships in the wheel as the data
package ``groundstation.deploy`` (``skyfix deploy`` prints its files). Everything else is in pyproject.toml."""

from setuptools import find_namespace_packages, setup

DEPLOY = {"groundstation.deploy": "deploy", "groundstation.deploy.zenoh": "deploy/zenoh"}

setup(
    packages=[
        *find_namespace_packages(
            include=["localizer*", "groundstation*", "sim_fixtures*"], exclude=["*__pycache__*"]
        ),
        *DEPLOY,
    ],
    package_dir=DEPLOY,
)
