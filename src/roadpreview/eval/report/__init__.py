"""The evaluation report, from ``results.json`` (`roadpreview.eval.suite.EvalResults`):
the Markdown document of ``roadpreview evaluate --report PATH`` and the console summary.

* `markdown`: the document (`write_report`, `render`): how to regenerate, the methods,
  the data sets, one section per experiment, the run time; figures copied next to it
  into ``eval/`` and linked relatively;
* `experiments`: the sections of E1-E5 (the paper's Fig. 4-7 and Table I, then ours);
* `product`: the section of E6, the product at its operating point;
* `console`: Table I as plain text and the headline figures;
* `tables`: what they share: cell formats, labels, Table I's rows.

The report only reads the numbers; the experiments and their figures are run by
`roadpreview.eval.suite`.
"""
