"""Read and write TOML files with errors that name the file (internal helper)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import tomli_w

from roadpreview.errors import ConfigError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised only on 3.10
    import tomli as tomllib


def load_toml(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file; a missing, unreadable (a folder, no permission), binary or
    malformed file raises `ConfigError` naming it, in one line."""
    path = Path(path)
    try:
        with path.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"{path}: file not found") from None
    except IsADirectoryError:
        raise ConfigError(f"{path}: is a folder, expected a TOML file") from None
    except UnicodeDecodeError as exc:  # TOML is UTF-8 text
        raise ConfigError(f"{path}: not a TOML text file (not UTF-8 at byte {exc.start})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    except OSError as exc:  # permission, a device, an I/O error
        raise ConfigError(f"{path}: cannot be read: {exc.strerror or exc}") from None


def dump_toml(data: dict[str, Any], path: str | Path) -> None:
    """Write ``data`` as TOML to ``path`` (parent folders are created)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("wb") as fh:
        tomli_w.dump(data, fh)
