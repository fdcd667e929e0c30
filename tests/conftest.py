import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the CLI: small matrices, no BLAS threads
os.environ.setdefault("OMP_NUM_THREADS", "1")

import pytest  # noqa: E402

from railfmu.fmus.generate.build import build_all, default_out  # noqa: E402


@pytest.fixture(scope="session")
def fmu_dir():
    """Every FMU, built into the per-user cache as `railfmu build` does (the CLI tests use the same
    folder): rebuilt when any model definition, the generator or the runtime changed
    (railfmu.fmus.generate.build.definition_key), so a fresh clone builds everything once."""
    build_all(default_out())
    return default_out()
