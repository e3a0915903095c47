"""Registries, not if-chains: build a component from its config name, imported lazily.

A registry maps a config name to ``(module, class, config class or None)``.
`build` imports the module only when the component is asked for, fills its
config dataclass from the options (errors name the field), and turns a
missing optional dependency into a `MissingDependencyError` that says what to
install (python-can's ``interfaces`` style).
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from typing import Any

from roadpreview.configtools import from_mapping
from roadpreview.errors import ConfigError, MissingDependencyError

Registry = Mapping[str, tuple[str, str, str | None]]


def build(
    registry: Registry,
    name: str,
    *args: Any,
    key: str,
    where: str,
    options: Mapping[str, Any] | None = None,
    config_module: str | None = None,
) -> Any:
    """Instantiate ``registry[name]`` as ``cls(*args, config)`` (or ``cls(*args)``).

    ``key`` names the configuration field that chose ``name`` (for errors),
    ``where`` the table its options come from; ``config_module`` holds the
    config class when it is not in the component's own module.
    """
    options = dict(options or {})
    try:
        module_name, cls_name, cfg_name = registry[name]
    except KeyError:
        raise ConfigError(f"{key} = {name!r}: unknown; choose one of {sorted(registry)}") from None
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:  # an optional dependency of that component is missing
        if exc.name and not exc.name.startswith("roadpreview"):
            raise MissingDependencyError(
                f"{key} = {name!r} needs the package {exc.name!r}: pip install {exc.name}"
            ) from None
        raise
    cls = getattr(module, cls_name)
    if cfg_name is None:
        if options:
            raise ConfigError(f"{key} = {name!r} takes no options, got {sorted(options)}")
        return cls(*args)
    holder = importlib.import_module(config_module) if config_module else module
    config = from_mapping(getattr(holder, cfg_name), options, where=where)
    return cls(*args, config)
