import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the CLI: small matrices, no BLAS threads
os.environ.setdefault("OMP_NUM_THREADS", "1")

import pytest  # noqa: E402

from fmus.build import build_all  # noqa: E402


@pytest.fixture(scope="session")
def fmu_dir(tmp_path_factory):
    """Every FMU, freshly built for this test session."""
    out = tmp_path_factory.mktemp("fmus")
    build_all(out, force=True)
    return out
