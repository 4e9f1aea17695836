"""TOML configuration loaded into frozen dataclasses.

Each component defines a ``@dataclass(frozen=True)`` with defaults; :func:`load_section`
fills it from one table of a TOML file and rejects unknown keys with a clear message.
"""

from __future__ import annotations

import dataclasses
import os
import sys
from pathlib import Path
from typing import Any, TypeVar

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

T = TypeVar("T")


class ConfigError(ValueError):
    """A configuration file is unreadable or has wrong keys or values."""


def read_toml(path: str | os.PathLike) -> dict[str, Any]:
    """Parse a TOML file; raise ConfigError naming the file on any problem."""
    p = Path(path)
    try:
        with p.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"{p}: file not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{p}: invalid TOML ({exc})") from None
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{p}: not UTF-8 text (byte {exc.start})") from None
    except OSError as exc:
        raise ConfigError(f"{p}: cannot read ({exc.strerror or exc})") from None


def from_dict(cls: type[T], values: dict[str, Any], where: str = "") -> T:
    """Build dataclass ``cls`` from ``values``; unknown keys raise ConfigError."""
    names = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(values) - names)
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {unknown}; known: {sorted(names)}")
    try:
        return cls(**values)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{where}: {exc}") from None


def load_section(cls: type[T], path: str | os.PathLike | None, section: str) -> T:
    """Load table ``[section]`` of TOML file ``path`` into ``cls``; defaults when path is None."""
    if path is None:
        return cls()
    data = read_toml(path)
    return from_dict(cls, data.get(section, {}), f"{path} [{section}]")
