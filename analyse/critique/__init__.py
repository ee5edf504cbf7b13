"""The critique loop: show what the calibrated simulation gets wrong, name the cause, extend the
model and measure the gain (docs/design.md, "The critique loop").

- ``twins``: the twin of every lab trial with the calibrated parameters, the discrepancy table;
- ``diagnosis``: per-row values and twin residuals against every covariate, multiple-testing
  correction, effect sizes and practical thresholds;
- ``mechanisms``: the catalogue of candidate mechanisms and their verdicts;
- ``gain``: each extension's discrepancy before and after, on held-out data;
- ``loop``: all of it, :func:`run_critique`; ``cli``: ``demcal critique``.
"""

from demcal.analyse.critique.loop import Critique, run_critique

__all__ = ["Critique", "run_critique"]
