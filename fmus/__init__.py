"""Everything FMI/SSP, one sub-package per concern (dependencies point down the list):

* ``native/`` — C: the shared FMI 2.0 Co-Simulation runtime (``runtime/``), the container
  stepping loop, and the hand-written model C (``models/``);
* :mod:`railfmu.fmus.generate` — model definition (:mod:`railfmu.models`) -> modelDescription
  + C -> compiled, packaged and validated ``.fmu`` (``codegen``, ``build``);
* :mod:`railfmu.fmus.cosim` — co-simulation: the resolved
  :class:`~railfmu.fmus.cosim.system.System`, one FMU as a ``Slave``, the masters (Jacobi,
  Gauss-Seidel, container), an FMU as a filter's process model;
* :mod:`railfmu.fmus.ssp` — SSP read / validate / write, with units and parameter bindings;
* :mod:`railfmu.fmus.units` — the FMI unit table (the one-line user error is
  :mod:`railfmu.models.errors`, at the bottom layer).
"""
