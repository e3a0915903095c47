"""The one streaming pipeline behind replay, the in-vehicle daemon and the demo.

Frames and CAN/IMU samples are pushed in timestamp order; trajectory samples,
pitch, fusion modes, detector output and alerts come out. Nothing inside
knows whether it is fed live or from a log.
"""

from roadpreview.pipeline.config import PipelineConfig
from roadpreview.pipeline.core import FrameResult, Pipeline

__all__ = ["FrameResult", "Pipeline", "PipelineConfig"]
