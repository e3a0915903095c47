"""Evaluation on simulated data sets: every method over the same recordings, the paper's
experiments (Fig. 4-7, Table I) and ours, and the report (``roadpreview evaluate``).

* `metrics` and `cv`: balanced accuracy, F-score, ROC / AUC, the F-maximising
  threshold and the grouped, stratified k-fold cross-validation of Table I.
* `methods`: the compared methods (`METHODS`), one line each.
* `runner`: one vision pass per recording shared by every method's pipeline,
  per-method traces cached in the run folder, parallel over recordings.
* `clips`: clip scores (the maximum of s(t) in a window around the crossing), hard
  and tracked flags.
* `plan`: data sets, seeds, resolutions and parameters of the full and quick runs.
* `experiments`: E1-E5; `suite`: one run end to end; `report`: Markdown and console.

Heavy modules are imported on use::

    from roadpreview.eval.plan import EvalPlan
    from roadpreview.eval.suite import run_evaluation

    results = run_evaluation(EvalPlan.quick(), "runs/eval-quick", jobs=2)
"""
