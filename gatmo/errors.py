"""The one exception family of gatmo.

Every error the library raises on bad input is a :class:`GatmoError`. It carries where the
problem is (file, line, field) so that the CLI can print a single line such as::

    run_1.clf:12: FLASER: expected 180 readings, found 179
"""

from __future__ import annotations

from pathlib import Path


class GatmoError(Exception):
    """Base class. ``file``, ``line`` and ``field`` locate the problem when known."""

    def __init__(
        self,
        message: str,
        *,
        file: str | Path | None = None,
        line: int | None = None,
        field: str | None = None,
    ) -> None:
        super().__init__(message)
        self.message = message
        self.file = str(file) if file is not None else None
        self.line = line
        self.field = field

    def where(self) -> str:
        parts = []
        if self.file is not None:
            parts.append(self.file if self.line is None else f"{self.file}:{self.line}")
        if self.field is not None:
            parts.append(self.field)
        return ": ".join(parts)

    def __str__(self) -> str:
        where = self.where()
        return f"{where}: {self.message}" if where else self.message


class FormatError(GatmoError):
    """A file's content does not follow its format (log line, map YAML, bag, TUM, objects.json)."""


class ConfigError(GatmoError):
    """A parameter is unknown, of the wrong type, or out of range."""


class MapError(GatmoError):
    """An occupancy grid or a pose on it is unusable (bad origin, pose outside the map, ...)."""


class DataError(GatmoError):
    """Data is inconsistent (timestamps backwards, beam count changed, stamps don't match)."""


class MissingExtraError(GatmoError):
    """An optional dependency is missing; the message names the extra to install."""

    def __init__(self, module: str, extra: str) -> None:
        super().__init__(
            f"this feature needs the '{module}' package: pip install 'gatmo[{extra}]'", field=module
        )
        self.extra = extra


def require(module: str, extra: str):
    """Import an optional module or raise :class:`MissingExtraError` naming the extra."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise MissingExtraError(module, extra) from exc
