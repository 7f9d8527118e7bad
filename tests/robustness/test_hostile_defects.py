"""The defect families of "interrupts, hostile files and two processes at once" that no other test runs through
the command line: outputs landing on a run folder's own files or inside a dataset store are refused naming the
file, the run or store byte-identical (``--force`` writes; an output beside a run's files is ordinary); a run
folder's lock file that is a symbolic link is refused, never followed.

Each case runs the command line in a subprocess (tests/robustness/harness.py classifies it); the other families of
the brief are measured by benchmarks/robustness.py and tested directly (tests/robustness/cases_hostile.py)."""

import pytest

from tests.robustness.catalog import all_cases, assert_handled, defect_names, good_outcomes

GOOD = good_outcomes(all_cases())


@pytest.mark.parametrize("case", defect_names("hostile"))
def test_hostile_defect(case, robustness_results):
    assert_handled(robustness_results[case], GOOD[case])
