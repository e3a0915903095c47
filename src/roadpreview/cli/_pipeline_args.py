"""Command-line options shared by the commands that run the pipeline (replay, run).

The choices come from the registries, so a new estimator, back end or lead
finder is offered on the command line without editing this module.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from roadpreview.pipeline.config import PipelineConfig


def add_pipeline_arguments(p: argparse.ArgumentParser) -> None:
    """``--config`` and the ``--finder`` / ``--estimator`` / ``--fusion`` overrides."""
    from roadpreview.fusion import BACKENDS
    from roadpreview.pitch import ESTIMATORS
    from roadpreview.vision import FINDERS

    p.add_argument("--config", type=Path, help="pipeline configuration (TOML)")
    p.add_argument("--finder", choices=sorted(FINDERS), help="override the lead finder")
    p.add_argument("--estimator", choices=sorted(ESTIMATORS), help="override the pitch estimator")
    p.add_argument("--fusion", choices=sorted(BACKENDS), help="override the fusion back end")


def pipeline_config(args: argparse.Namespace) -> PipelineConfig:
    """The configuration file (or the defaults) with the command-line overrides applied."""
    from roadpreview.pipeline.config import PipelineConfig

    config = PipelineConfig.load(args.config) if args.config else PipelineConfig()
    return config.with_overrides(finder=args.finder, estimator=args.estimator, fusion=args.fusion)
