import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the CLI: small matrices, no BLAS threads
os.environ.setdefault("OMP_NUM_THREADS", "1")

import pytest  # noqa: E402

from fmus.generate.build import DEFAULT_OUT, build_all  # noqa: E402


@pytest.fixture(scope="session")
def fmu_dir():
    """Every FMU, built into build/fmus as `railfmu build` does (the CLI tests use the same
    folder): rebuilt when any model definition, the generator or the runtime changed
    (fmus.generate.build.definition_key), so a fresh clone builds everything once."""
    build_all(DEFAULT_OUT)
    return DEFAULT_OUT
