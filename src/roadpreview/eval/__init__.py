"""Evaluation on labelled clips: the paper's Table I (balanced accuracy, F-score, AUC), ROC."""
