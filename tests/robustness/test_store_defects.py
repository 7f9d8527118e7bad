"""The store's defect families: two writers at once, damaged chunks, attributes and pickle-codec arrays
(found by `info`, refused by every reader, re-simulated on resume, dropped by `info --repair`), litter of
interrupted creations and failed plans.

Each case runs the command line in a subprocess (tests/robustness/harness.py classifies it)."""

import pytest

from tests.robustness.catalog import all_cases, assert_handled, defect_names, good_outcomes

GOOD = good_outcomes(all_cases())


@pytest.mark.parametrize("case", defect_names("store"))
def test_store_defect(case, robustness_results):
    assert_handled(robustness_results[case], GOOD[case])
