"""The version of rangeplan (the distribution that ships ``planner`` and ``app``): the one place it
is written; ``pyproject.toml`` reads it at build time, ``rangeplan --version``, ``GET /ready`` and
the container image's label report it."""

__version__ = "0.2.0"
