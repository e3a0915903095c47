"""Command-line options shared by the commands that run the pipeline (replay, run).

The choices come from the registries, so a new estimator, back end or lead
finder is offered on the command line without editing this module.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from roadpreview.pipeline.config import PipelineConfig


def add_pipeline_arguments(p: argparse.ArgumentParser) -> None:
    """``--config``, the ``--finder`` / ``--estimator`` / ``--fusion`` overrides and the
    CAN input's ``--dbc`` / ``--mapping``."""
    from roadpreview.fusion import BACKENDS
    from roadpreview.pitch import ESTIMATORS
    from roadpreview.vision import FINDERS

    p.add_argument("--config", type=Path, help="pipeline configuration (TOML)")
    p.add_argument("--finder", choices=sorted(FINDERS), help="override the lead finder")
    p.add_argument("--estimator", choices=sorted(ESTIMATORS), help="override the pitch estimator")
    p.add_argument("--fusion", choices=sorted(BACKENDS), help="override the fusion back end")
    p.add_argument(
        "--dbc", type=Path, help="DBC of another car's CAN input (default: roadpreview.dbc)"
    )
    p.add_argument(
        "--mapping",
        help="input mapping of the CAN signals: a TOML file, or the name of a shipped one"
        " (roadpreview, toyota_rav4, ...; docs/can-interface.md)",
    )


def pipeline_config(args: argparse.Namespace) -> PipelineConfig:
    """The configuration file (or the defaults) with the command-line overrides applied."""
    from roadpreview.pipeline.config import PipelineConfig

    config = PipelineConfig.load(args.config) if args.config else PipelineConfig()
    config = config.with_overrides(finder=args.finder, estimator=args.estimator, fusion=args.fusion)
    dbc, mapping = getattr(args, "dbc", None), getattr(args, "mapping", None)
    if dbc is not None:
        config = replace(config, can=replace(config.can, dbc=str(dbc)))
    if mapping is not None:
        config = replace(config, can=replace(config.can, mapping=str(mapping)))
    return config
