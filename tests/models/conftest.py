"""Model tests run with one torch thread: graph layers' scatter operations are far slower with two here."""

import pytest
import torch


@pytest.fixture(autouse=True)
def one_thread():
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def central_difference(loss, parameter, k: int, h: float = 1e-6) -> float:
    """``d loss / d parameter.view(-1)[k]`` by central differences: ``loss()`` (a float) evaluated with that entry
    moved by ``+h`` and ``-h``, the entry put back."""
    import torch

    flat = parameter.data.view(-1)
    keep = float(flat[k])
    with torch.no_grad():
        flat[k] = keep + h
        up = loss()
        flat[k] = keep - h
        down = loss()
        flat[k] = keep
    return (up - down) / (2 * h)
