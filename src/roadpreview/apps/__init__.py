"""The product's compositions of the run loop (`roadpreview.loop.run`): sources ->
pipeline -> sinks.

* `replay`: file sources (video, CAN logs, IMU CSV, a recording folder) into file sinks
  (CAN log, alerts JSONL, frame table, plots, annotated video) and a summary;
* `daemon`: a live camera and CAN bus into bus sinks, with watchdogs and signals;
* `result`: what a replay did (`ReplayResult`), which `summary` writes to summary.json.

The evaluation (`roadpreview.eval.runner`) is one more composition of the same loop.
"""
