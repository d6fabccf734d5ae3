"""numpy's random draws, filled by numba kernels that release the GIL (for :class:`sim.ahead.DrawsAhead`).

numba implements ``numpy.random.Generator``'s algorithms (the same ziggurat for normals, the same
53-bit doubles for uniforms) on the same bit generator, so a kernel filling ``out`` with
``gen.standard_normal()`` gives the very values, and leaves the generator in the very state, that
``gen.standard_normal(out.size)`` would (``tests/world/test_ahead.py`` compares them with the installed
numpy and numba: the plain-numpy twin of each kernel is the generator's own method).  numpy's own
fill holds the GIL for much of its work (measured: a Python loop beside it in another thread kept
0.48 of its speed; beside a ``nogil`` numba kernel, 0.84), which would stall the loop's thread.
"""

from __future__ import annotations

from numba import njit


@njit(cache=True, nogil=True)
def fill_standard_normal_kernel(gen, out):
    """``out[:] = gen.standard_normal(out.size)``, value for value."""
    for i in range(out.size):
        out[i] = gen.standard_normal()


@njit(cache=True, nogil=True)
def fill_uniform_kernel(gen, out):
    """``out[:] = gen.random(out.size)`` (uniform on [0, 1)), value for value."""
    for i in range(out.size):
        out[i] = gen.random()
