"""``loosefit report``: one comparison of every method on a dataset, as HTML and Markdown.

- :mod:`~loosefit.report.predictions`: the held-out sequences of a store and every run's animation of them.
- :mod:`~loosefit.report.figures`: error over time (matplotlib) and error maps on the garment (offscreen render).
- :mod:`~loosefit.report.claims`: the paper-claims and speed tables from ``benchmarks/results``.
- :mod:`~loosefit.report.build`: evaluate, draw and write ``index.html``, ``report.md`` and ``metrics.json``.
"""

from loosefit.report.build import build_report

__all__ = ["build_report"]
