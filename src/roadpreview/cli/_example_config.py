"""The documented example configuration (``data/roadpreview.example.toml``), generated from
the configuration classes so that every field carries its help, unit and range.

Regenerate after adding a field::

    PYTHONPATH=src python -m roadpreview.cli._example_config > data/roadpreview.example.toml
"""

from __future__ import annotations

HEADER = """\
roadpreview pipeline configuration: every setting at its default, with what it does,
its unit and its allowed range. Give it to the commands that run the pipeline with
--config FILE (roadpreview replay, run, evaluate); a key left out keeps its default,
an unknown key is an error naming it.
Generated from the configuration classes (src/roadpreview/*/config.py); regenerate with
  PYTHONPATH=src python -m roadpreview.cli._example_config > data/roadpreview.example.toml"""


def example_config_text() -> str:
    """The example configuration file's text: `PipelineConfig` at its defaults."""
    from roadpreview.configtools import commented_toml
    from roadpreview.pipeline.config import PipelineConfig

    return commented_toml(PipelineConfig(), header=HEADER)


if __name__ == "__main__":  # pragma: no cover
    print(example_config_text(), end="")
