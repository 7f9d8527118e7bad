"""Defects the matrix found outside the three fixes' files, fixed with it: a refused ``prepare`` that left
the prepared rig marked unfinished, unwritable ``report`` / ``demo`` outputs found only after the work
(tracebacks), ``export-rig --threads -1`` (a traceback).

Each case runs the command line in a subprocess (tests/robustness/harness.py classifies it)."""

import pytest

from tests.robustness.catalog import all_cases, assert_handled, defect_names, good_outcomes

GOOD = good_outcomes(all_cases())


@pytest.mark.parametrize("case", defect_names(""))
def test_other_defect(case, robustness_results):
    assert_handled(robustness_results[case], GOOD[case])
