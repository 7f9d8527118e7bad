"""Ground-truth cloth simulation (Blender through bpy, or NVIDIA Newton): parameters, one sequence, plans and parallel runs."""

from loosefit.sim.params import SimParams
from loosefit.sim.quality import QualityGate
from loosefit.sim.sequence import SimResult, simulate_sequence

__all__ = ["SimParams", "QualityGate", "SimResult", "simulate_sequence", "run_plan", "simulate_file", "load_plan"]


def __getattr__(name):
    # Plans and runs pull in the dataset store, garment templates and Ray: load them on first use.
    if name in ("run_plan", "simulate_file"):
        from loosefit.sim import runner

        return getattr(runner, name)
    if name == "load_plan":
        from loosefit.sim.plan import load_plan

        return load_plan
    raise AttributeError(name)
