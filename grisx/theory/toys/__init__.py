"""Toy problems with exact answers: where every estimator in grisx is verified first.

Each problem is a :class:`~grisx.theory.toys.base.ToyProblem` with named
methods and parameters; :func:`run_toy` runs one and returns an
:class:`~grisx.theory.toys.base.Estimate`. The same registry backs
``grisx toy list`` and ``grisx toy run``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from grisx.errors import UnknownNameError
from grisx.theory.toys.base import Estimate, Method, Param, ToyProblem
from grisx.theory.toys.chromatic_cv import ChromaticCV
from grisx.theory.toys.conditional_paths import FinalGather, JointUCW, SuffixReuse
from grisx.theory.toys.f1_f2 import F1F2
from grisx.theory.toys.gradient_row import GradientRow
from grisx.theory.toys.gris_shift import GRISShift
from grisx.theory.toys.reconnection_flatland import ReconnectionFlatland
from grisx.theory.toys.ris_1d import RIS1D
from grisx.theory.toys.sms_toy import SMSToy

__all__ = ["PROBLEMS", "get_problem", "run_toy", "Estimate", "Method", "Param", "ToyProblem"]

PROBLEMS: dict[str, ToyProblem] = {
    p.name: p
    for p in (
        RIS1D(),
        GRISShift(),
        ReconnectionFlatland(),
        SMSToy(),
        JointUCW(),
        SuffixReuse(),
        FinalGather(),
        ChromaticCV(),
        F1F2(),
        GradientRow(),
    )
}


def get_problem(name: str) -> ToyProblem:
    """The toy problem called ``name`` (see ``grisx toy list``)."""
    try:
        return PROBLEMS[name]
    except KeyError:
        raise UnknownNameError("toy problem", name, sorted(PROBLEMS)) from None


def run_toy(
    name: str,
    method: str,
    trials: int = 100_000,
    seed: int = 0,
    params: Mapping[str, Any] | None = None,
    device: str = "cpu",
    return_samples: bool = False,
    return_values: bool = False,
    progress: Callable[[int, int], None] | None = None,
) -> Estimate:
    """Run toy ``name`` with ``method``; see :meth:`ToyProblem.run`."""
    return get_problem(name).run(method, trials=trials, seed=seed, params=params, device=device,
                                 return_samples=return_samples, return_values=return_values, progress=progress)
