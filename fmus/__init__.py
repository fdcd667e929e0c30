"""Everything FMI/SSP, one sub-package per concern (dependencies point down the list):

* :mod:`fmus.native`   — C: the shared FMI 2.0 Co-Simulation runtime (``runtime/``), the
  container stepping loop, and the hand-written model C (``models/``);
* :mod:`fmus.generate` — model definition (``models/``) -> modelDescription + C -> compiled,
  packaged and validated ``.fmu`` (``codegen``, ``build``);
* :mod:`fmus.cosim`    — co-simulation: the resolved :class:`~fmus.cosim.system.System`, one
  FMU as a ``Slave``, the masters (Jacobi, Gauss-Seidel, container), recorders;
* :mod:`fmus.ssp`      — SSP read / validate / write, with units and parameter bindings;
* :mod:`fmus.units` and :mod:`fmus.errors` — the FMI unit table and the one-line user error.
"""
