"""Other tools' example SSPs and FMUs (tests/data/foreign, origins in its README).

The Reference-FMUs are kept as their C sources; :func:`reference_fmu` packs one into a
source-only FMU (modelDescription.xml and ``sources/``, no binary), which railfmu compiles as
it compiles any FMU that ships sources.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

FOREIGN = Path(__file__).parent / "data" / "foreign"
REFERENCE = FOREIGN / "reference-fmus"
REFERENCE_MODELS = ("BouncingBall", "Dahlquist", "VanDerPol", "Feedthrough", "Stair")

#: every example SSP of the corpus (a folder holding SystemStructure.ssd), by a short name
SSPS = {
    **{f"libcosim/{p.parent.relative_to(FOREIGN / 'libcosim' / 'ssp')}": p.parent
       for p in sorted((FOREIGN / "libcosim" / "ssp").rglob("SystemStructure.ssd"))},
    **{f"omsimulator/{p.parent.name}": p.parent
       for p in sorted((FOREIGN / "omsimulator").glob("*/SystemStructure.ssd"))},
    **{f"vico/{p.parent.relative_to(FOREIGN / 'vico' / 'ssp')}": p.parent
       for p in sorted((FOREIGN / "vico" / "ssp").rglob("SystemStructure.ssd"))},
}


def reference_fmu(model: str, out_dir: Path, fmi_version: int = 2) -> Path:
    """``out_dir/<model>.fmu``: the Reference-FMU ``model`` for FMI ``fmi_version`` (2 or 3) as
    a source-only FMU, its sources compiled as one file (``all.c``) with DISABLE_PREFIX, as the
    Reference-FMUs' own build of their binaries does (without it, the FMI 2 functions get the
    ``<modelIdentifier>_`` prefix of a statically linked source FMU)."""
    src = REFERENCE / model
    out = Path(out_dir) / (f"{model}.fmu" if fmi_version == 2 else f"{model}3.fmu")
    functions = f"fmi{fmi_version}Functions.c"
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr(zipfile.ZipInfo("modelDescription.xml", (2024, 1, 1, 0, 0, 0)),
                   (src / f"FMI{fmi_version}.xml").read_bytes())
        # fixed dates: the same bytes every time, so railfmu's compiled copy is reused
        z.writestr(zipfile.ZipInfo("sources/all.c", (2024, 1, 1, 0, 0, 0)), f"#define FMI_VERSION {fmi_version}\n#define DISABLE_PREFIX\n"
                   f'#include "{functions}"\n#include "model.c"\n#include "cosimulation.c"\n')
        if fmi_version == 3:
            z.writestr(zipfile.ZipInfo("sources/buildDescription.xml", (2024, 1, 1, 0, 0, 0)),
                       (src / "buildDescription.xml").read_bytes())
        for f in (src / "model.c", src / "config.h", REFERENCE / "src" / functions,
                  REFERENCE / "src" / "cosimulation.c", *sorted((REFERENCE / "include").glob("*.h"))):
            z.writestr(zipfile.ZipInfo(f"sources/{f.name}", (2024, 1, 1, 0, 0, 0)), f.read_bytes())
    return out
