"""Ground-truth cloth simulation (Blender through bpy, or NVIDIA Newton): parameters, one sequence, plans.
Running a plan into a dataset store is :mod:`loosefit.simulate` (it builds garments, which drape with this
package's simulator)."""

from loosefit.sim.params import SimParams
from loosefit.sim.quality import QualityGate
from loosefit.sim.sequence import SimResult, simulate_sequence

__all__ = ["SimParams", "QualityGate", "SimResult", "simulate_sequence", "load_plan"]


def __getattr__(name):
    # Plans are read on first use.
    if name == "load_plan":
        from loosefit.sim.plan import load_plan

        return load_plan
    raise AttributeError(name)
