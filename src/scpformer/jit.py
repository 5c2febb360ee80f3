"""The one numba setting of the project's compiled kernels.

``compiled`` is ``numba.njit`` with

* ``error_model="numpy"``: a float division by zero gives ``inf`` or ``nan``, as in numpy,
  instead of Python's ``ZeroDivisionError``. The SCP loops evaluate candidates far from the
  linearization point (a mass of zero, say) and must see a non-finite cost to reject them,
  as they did with the numpy dynamics; the truth propagation must see a collapsing step.
* ``cache=True``: compiled once per machine and kept next to the sources (numba's cache),
  so later processes load a kernel in well under a second.
"""

from numba import njit

compiled = njit(cache=True, error_model="numpy")
