"""The torch thread-count context."""

import pytest
import torch

from loosefit.threads import torch_threads


def test_sets_then_restores_the_thread_count_even_on_error():
    before = torch.get_num_threads()
    other = 1 if before != 1 else 2
    with torch_threads(other):
        assert torch.get_num_threads() == other
    assert torch.get_num_threads() == before
    with pytest.raises(RuntimeError):
        with torch_threads(other):
            raise RuntimeError("inside")
    assert torch.get_num_threads() == before
    for leave in (None, 0):  # leave the setting as it is
        with torch_threads(leave):
            assert torch.get_num_threads() == before
