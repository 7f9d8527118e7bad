"""The input defect families: pickles that run code, overrides and YAML duplicate keys silently
ignored, unwritable outputs, corrupt .npz files, garments too small to be one, bad numbers accepted,
temp-file litter after a resumed training.

Each case runs the command line in a subprocess (tests/robustness/harness.py classifies it)."""

import pytest

from tests.robustness.catalog import all_cases, assert_handled, defect_names, good_outcomes

GOOD = good_outcomes(all_cases())


@pytest.mark.parametrize("case", defect_names("inputs"))
def test_inputs_defect(case, robustness_results):
    assert_handled(robustness_results[case], GOOD[case])
