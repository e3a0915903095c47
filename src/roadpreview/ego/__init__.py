"""The ego vehicle's own motion as the detector needs it: its vertical acceleration per
camera frame (`EgoVerticalMonitor`), for the road-roughness state and for confirming alerts
when the ego reaches the spot."""

from roadpreview.ego.vertical import EgoVertical, EgoVerticalConfig, EgoVerticalMonitor

__all__ = ["EgoVertical", "EgoVerticalConfig", "EgoVerticalMonitor"]
