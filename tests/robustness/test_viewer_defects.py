"""The viewer defect families: malformed HTTP requests, foreign Host headers, directory listings and
clients that go away (raw sockets against a running `loosefit view`), and the warning when a motion
leaves the training range (`animate`, `view RUN:MOTION`).

Each case runs the command line in a subprocess (tests/robustness/harness.py classifies it)."""

import pytest

from tests.robustness.catalog import all_cases, assert_handled, defect_names, good_outcomes

GOOD = good_outcomes(all_cases())


@pytest.mark.parametrize("case", defect_names("viewer"))
def test_viewer_defect(case, robustness_results):
    assert_handled(robustness_results[case], GOOD[case])
