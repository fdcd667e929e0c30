"""SSP 1.0: read and validate ``.ssd``/``.ssv``/``.ssm``/``.ssp`` into a
:class:`railfmu.fmus.cosim.system.System` (:mod:`.reader`, with :mod:`.params` for bindings and
mappings, :mod:`.units` for unit conversion, :mod:`.xmltools` for XML and the schemas), and
write a self-contained ``.ssp`` back (:mod:`.writer`)."""

from railfmu.fmus.ssp.reader import list_variants, read_system, study_name, validate_ssp
from railfmu.fmus.ssp.writer import write_ssp

__all__ = ["list_variants", "read_system", "study_name", "validate_ssp", "write_ssp"]
