"""
The compiled stepping loop's fixed arguments, unboxed as one (``step_loop.advance_packed``).

A call from Python into compiled code unboxes every array argument, about 75 ns each: the
planar loop's ~45 arrays (the kernel's 28 model arrays, ``Model._kernel_args``; a
linearization's A, h phi_1, h phi_2 and its 12 energy matrices) made up ~3.6 us of its ~9 us
cost per call on the stage (one engine step: 2.4 us). Those arrays change only with the
linearization, so they are handed over once per linearization as a Numba structure reference
(``numba.experimental.structref``), which a call unboxes as one object: on the stage
``Simulation.step(1)`` takes 9.8-10.0 us against 11.7-11.8 us, ``step(10)`` 32.0-32.6 us
against 34.4-34.6 us (three interleaved runs, best of 7 x 2000 calls each; the steps' own cost
2.5 us). ``test_kernel_pack`` pins the same results to the bit. The structure holds the same
arrays (no copies), which are never changed in place; one per linearization (~3 us to make).
"""
from __future__ import annotations

import numpy as np
from numba import types
from numba.experimental import structref

from flexure_sim.engine import jit as kernel_cache
from flexure_sim.engine.jit import njit


@structref.register
class LoopArgsType(types.StructRef):
    """Numba type of `LoopArgs`."""

    def preprocess_fields(self, fields):
        """Return ``fields`` with literal types widened (an int field takes any int)."""
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class LoopArgs(structref.StructRefProxy):
    """
    A linearization's A, h phi_1(hA), h phi_2(hA), energy matrices and the model's arguments.

    Fields ``A``, ``phi1``, ``phi2``, ``emats`` (``Linearization``) and ``args``
    (``Model.kernel_args``).
    """

    def __reduce__(self):
        """Pickle as the arrays (a `Simulation` goes to Dask workers whole)."""
        return _rebuild, _fields(self)

    @property
    def A(self) -> np.ndarray:
        """Return the Jacobian A."""
        return _fields(self)[0]

    @property
    def phi1(self) -> np.ndarray:
        """Return h phi_1(hA)."""
        return _fields(self)[1]

    @property
    def phi2(self) -> np.ndarray:
        """Return h phi_2(hA)."""
        return _fields(self)[2]

    @property
    def emats(self) -> tuple:
        """Return the energy matrices (``step_energy.energy_matrices``; ``NO_ENERGY``)."""
        return _fields(self)[3]

    @property
    def args(self) -> tuple:
        """Return the model's kernel arguments (``Model.kernel_args``)."""
        return _fields(self)[4]


structref.define_proxy(LoopArgs, LoopArgsType, ["A", "phi1", "phi2", "emats", "args"])


@njit(cache=True)
def loop_args(A, phi1, phi2, emats, args):
    """Return the `LoopArgs` of a linearization's matrices and the model's kernel arguments."""
    return LoopArgs(A, phi1, phi2, emats, args)


@njit(cache=True)
def _fields(packed):
    return packed.A, packed.phi1, packed.phi2, packed.emats, packed.args


def _rebuild(*fields):
    """Unpickle a `LoopArgs` (a plain function: pickle names it)."""
    return loop_args(*fields)


kernel_cache.revalidate(kernel_cache.dispatchers_of(globals()), __file__)
