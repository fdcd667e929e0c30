"""Co-simulation: the resolved system (:mod:`.system`), one FMU through FMPy (:mod:`.slave`),
the master algorithms (:mod:`.masters`; the native fast path in :mod:`.container`) and an FMU as a sigma-point filter's process model
(:mod:`.process_model`)."""
