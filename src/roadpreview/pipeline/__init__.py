"""The one streaming estimator behind replay, the in-vehicle daemon, the evaluation and
the demo.

`Pipeline.push` takes typed samples (`roadpreview.types`) in time-stamp order and
returns a `FrameResult` per camera frame: trajectory, pitch, fusion mode, detector
output and alerts. It knows no CAN, no files and no clocks; `roadpreview.loop.run`
feeds it from sources and hands its output to sinks.
"""

from roadpreview.pipeline.config import PipelineConfig
from roadpreview.pipeline.pipeline import FrameResult, Pipeline

__all__ = ["FrameResult", "Pipeline", "PipelineConfig"]
