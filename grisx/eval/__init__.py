"""Evaluation layer: image metrics, run-time-against-error studies of toys and renderers, and their plots.

* :mod:`grisx.eval.metrics` — MSE, RMSE, relMSE (ε = 10⁻², reference in the
  denominator), MAPE, HDR-/LDR-FLIP, per-channel variants, bias by
  accumulation, efficiency.
* :mod:`grisx.eval.runner` — toy and render studies writing JSON, CSV and PNG.
* :mod:`grisx.eval.plots` — error against time, image grids with insets,
  (x, t) scanline plots.
* :mod:`grisx.eval.cli` — ``grisx compare`` and ``grisx bench``.
"""
